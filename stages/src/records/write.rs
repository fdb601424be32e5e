//! Writing the record files: a JSON array streamed one record per line (so 50,000 records
//! never sit in memory together), JSON Lines, and LLaMA-Factory's `dataset_info.json`.
//!
//! Records keep the field order their readers document (`instruction, input, output`;
//! `prompt, chosen, rejected`), not sorted keys: they are official formats.

use std::collections::BTreeMap;
use std::io::{self, Write};

use mesa_schemas::artifacts::DatasetInfoEntry;
use serde::Serialize;

/// A JSON array written one element per line: `[`, elements separated by `,` and a line
/// break, `]` and a final line break.
#[derive(Debug)]
pub struct JsonArrayWriter<W: Write> {
    out: W,
    count: u64,
}

impl<W: Write> JsonArrayWriter<W> {
    /// Starts the array.
    pub fn new(mut out: W) -> io::Result<Self> {
        out.write_all(b"[")?;
        Ok(Self { out, count: 0 })
    }

    /// Appends one element.
    pub fn push<T: Serialize>(&mut self, value: &T) -> io::Result<()> {
        self.out
            .write_all(if self.count == 0 { b"\n" } else { b",\n" })?;
        serde_json::to_writer(&mut self.out, value).map_err(io::Error::other)?;
        self.count += 1;
        Ok(())
    }

    /// Appends one element already serialised as JSON text (one line, no trailing break).
    pub fn push_raw(&mut self, json: &str) -> io::Result<()> {
        self.out
            .write_all(if self.count == 0 { b"\n" } else { b",\n" })?;
        self.out.write_all(json.as_bytes())?;
        self.count += 1;
        Ok(())
    }

    /// Elements written so far.
    pub fn count(&self) -> u64 {
        self.count
    }

    /// Closes the array and gives the writer back.
    pub fn finish(mut self) -> io::Result<W> {
        self.out
            .write_all(if self.count == 0 { b"]\n" } else { b"\n]\n" })?;
        Ok(self.out)
    }
}

/// JSON Lines: one compact JSON document per line.
#[derive(Debug)]
pub struct JsonLinesWriter<W: Write> {
    out: W,
    count: u64,
}

impl<W: Write> JsonLinesWriter<W> {
    /// A writer over `out`.
    pub fn new(out: W) -> Self {
        Self { out, count: 0 }
    }

    /// Appends one line.
    pub fn push<T: Serialize>(&mut self, value: &T) -> io::Result<()> {
        serde_json::to_writer(&mut self.out, value).map_err(io::Error::other)?;
        self.out.write_all(b"\n")?;
        self.count += 1;
        Ok(())
    }

    /// Appends one line already serialised as JSON text (no line break in it).
    pub fn push_raw(&mut self, json: &str) -> io::Result<()> {
        self.out.write_all(json.as_bytes())?;
        self.out.write_all(b"\n")?;
        self.count += 1;
        Ok(())
    }

    /// Lines written so far.
    pub fn count(&self) -> u64 {
        self.count
    }

    /// Gives the writer back.
    pub fn finish(self) -> W {
        self.out
    }
}

/// The record files, relative to `records/`.
pub const SFT_FILE: &str = "sft.json";
/// Held-out SFT records.
pub const TEST_FILE: &str = "test.json";
/// DPO pairs in alpaca preference form.
pub const DPO_FILE: &str = "dpo.json";
/// TRL conversational SFT.
pub const TRL_SFT_FILE: &str = "trl_sft.jsonl";
/// TRL conversational held-out records.
pub const TRL_TEST_FILE: &str = "trl_test.jsonl";
/// TRL conversational preference pairs.
pub const TRL_DPO_FILE: &str = "trl_dpo.jsonl";

fn columns(pairs: &[(&str, &str)]) -> Option<BTreeMap<String, String>> {
    Some(
        pairs
            .iter()
            .map(|(k, v)| ((*k).to_owned(), (*v).to_owned()))
            .collect(),
    )
}

/// LLaMA-Factory's `dataset_info.json` for the record files: `mesa_sft`, `mesa_test`
/// (alpaca), `mesa_dpo` (alpaca, `"ranking": true`), `mesa_sft_trl`, `mesa_test_trl` (the TRL
/// files read as sharegpt with OpenAI-style role/content tags).
///
/// `trl_dpo.jsonl` has no entry: LLaMA-Factory's sharegpt preference format holds one message
/// in `chosen` and `rejected` where TRL holds a list of messages, and `mesa_dpo` carries the
/// same pairs.
pub fn dataset_info() -> BTreeMap<String, DatasetInfoEntry> {
    let alpaca_sft = |file: &str| DatasetInfoEntry {
        file_name: file.to_owned(),
        formatting: Some("alpaca".to_owned()),
        ranking: None,
        columns: columns(&[
            ("prompt", "instruction"),
            ("query", "input"),
            ("response", "output"),
        ]),
        tags: None,
    };
    let sharegpt = |file: &str| DatasetInfoEntry {
        file_name: file.to_owned(),
        formatting: Some("sharegpt".to_owned()),
        ranking: None,
        columns: columns(&[("messages", "messages")]),
        tags: columns(&[
            ("role_tag", "role"),
            ("content_tag", "content"),
            ("user_tag", "user"),
            ("assistant_tag", "assistant"),
            ("system_tag", "system"),
        ]),
    };
    BTreeMap::from([
        ("mesa_sft".to_owned(), alpaca_sft(SFT_FILE)),
        ("mesa_test".to_owned(), alpaca_sft(TEST_FILE)),
        (
            "mesa_dpo".to_owned(),
            DatasetInfoEntry {
                file_name: DPO_FILE.to_owned(),
                formatting: Some("alpaca".to_owned()),
                ranking: Some(true),
                columns: columns(&[
                    ("prompt", "instruction"),
                    ("query", "input"),
                    ("chosen", "chosen"),
                    ("rejected", "rejected"),
                ]),
                tags: None,
            },
        ),
        ("mesa_sft_trl".to_owned(), sharegpt(TRL_SFT_FILE)),
        ("mesa_test_trl".to_owned(), sharegpt(TRL_TEST_FILE)),
    ])
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn arrays_are_valid_json_empty_or_not() {
        let empty = JsonArrayWriter::new(Vec::new())
            .expect("w")
            .finish()
            .expect("f");
        assert_eq!(empty, b"[]\n");
        let mut w = JsonArrayWriter::new(Vec::new()).expect("w");
        w.push(&serde_json::json!({"a": "é"})).expect("push");
        w.push(&serde_json::json!({"a": 2})).expect("push");
        let bytes = w.finish().expect("finish");
        assert_eq!(
            String::from_utf8(bytes.clone()).expect("utf8"),
            "[\n{\"a\":\"é\"},\n{\"a\":2}\n]\n"
        );
        let back: Vec<serde_json::Value> = serde_json::from_slice(&bytes).expect("parses");
        assert_eq!(back.len(), 2);
    }
}
