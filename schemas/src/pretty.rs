//! serde_json's pretty layout (two-space indentation, `": "` between key and value) written by
//! hand, for the files mesa writes many of and whose shape is fixed: `graph/graph.json`
//! ([`crate::graph_json`]) and the run markers ([`crate::artifacts::RunMarker::to_pretty_json`]).
//! Each writer puts its own constants (keys, newlines, indentation) between the values this
//! writes: strings (escaped by serde_json's writer when they hold what JSON escapes), numbers
//! (spelled by `zmij`, as serde_json spells them) and lists and maps of those.

/// serde_json's pretty layout, by hand: what the writers of `graph.json` and of the run
/// markers put between their constants.
pub(crate) struct Pretty {
    out: Vec<u8>,
    /// Where the last numbers spelled by `zmij` were written in `out`: their bits, start and
    /// length. A graph repeats some (every proximity edge of a scene has the same
    /// `max_distance_cm`), and copying an earlier spelling costs a fifth of making it.
    spelled: [(u64, usize, usize); 2],
}

impl Pretty {
    /// An empty writer with room for `capacity` bytes.
    pub(crate) fn with_capacity(capacity: usize) -> Self {
        Self {
            out: Vec::with_capacity(capacity),
            // No number has the bits of a NaN that `f64` arithmetic does not make.
            spelled: [(u64::MAX, 0, 0); 2],
        }
    }

    /// The bytes written.
    pub(crate) fn into_bytes(self) -> Vec<u8> {
        self.out
    }

    /// Bytes of the layout (a constant at every call, so the copy has a known length).
    #[inline(always)]
    pub(crate) fn raw(&mut self, bytes: &[u8]) {
        self.out.extend_from_slice(bytes);
    }

    /// The items of a top-level array (its `[` written), each an object at depth 2 written by
    /// `item` from its `{` to its `}`; then the `]`.
    #[inline(always)]
    pub(crate) fn items<T>(
        &mut self,
        items: impl ExactSizeIterator<Item = T>,
        item: impl Fn(&mut Self, T),
    ) {
        if items.len() == 0 {
            self.out.push(b']');
            return;
        }
        for (i, value) in items.enumerate() {
            if i > 0 {
                self.out.push(b',');
            }
            self.raw(b"\n    ");
            item(self, value);
        }
        self.raw(b"\n  ]");
    }

    /// The members of a map of numbers at depth 3 (its `{` written), given in key order; then
    /// the `}`.
    #[inline(always)]
    pub(crate) fn numbers<'k>(&mut self, numbers: impl IntoIterator<Item = (&'k str, f64)>) {
        let mut any = false;
        for (key, x) in numbers {
            if any {
                self.out.push(b',');
            }
            self.raw(b"\n        ");
            self.string(key);
            self.raw(b": ");
            self.number(x);
            any = true;
        }
        if any {
            self.raw(b"\n      }");
        } else {
            self.out.push(b'}');
        }
    }

    /// A map of strings, the value of a member at depth 1 (its key written), entries in the
    /// map's order: `{}` when empty, else one entry a line at depth 2.
    pub(crate) fn string_map(&mut self, map: &std::collections::BTreeMap<String, String>) {
        if map.is_empty() {
            self.raw(b"{}");
            return;
        }
        self.out.push(b'{');
        for (i, (key, value)) in map.iter().enumerate() {
            if i > 0 {
                self.out.push(b',');
            }
            self.raw(b"\n    ");
            self.string(key);
            self.raw(b": ");
            self.string(value);
        }
        self.raw(b"\n  }");
    }

    /// A list of strings, the value of a member at depth 1 (its key written): `[]` when
    /// empty, else one item a line at depth 2.
    pub(crate) fn string_list(&mut self, list: &[String]) {
        if list.is_empty() {
            self.raw(b"[]");
            return;
        }
        self.out.push(b'[');
        for (i, item) in list.iter().enumerate() {
            if i > 0 {
                self.out.push(b',');
            }
            self.raw(b"\n    ");
            self.string(item);
        }
        self.raw(b"\n  ]");
    }

    #[inline(always)]
    pub(crate) fn string(&mut self, text: &str) {
        // What JSON escapes: quotes, backslashes and control characters. Names and labels
        // rarely hold any; those that do go through serde_json's writer.
        if needs_escape(text.as_bytes()) {
            // Writing to a Vec cannot fail, and a str always serialises.
            serde_json::to_writer(&mut self.out, text).expect("a string serialises");
        } else {
            self.out.reserve(text.len() + 2);
            self.out.push(b'"');
            self.out.extend_from_slice(text.as_bytes());
            self.out.push(b'"');
        }
    }

    pub(crate) fn number(&mut self, x: f64) {
        if !x.is_finite() {
            // As a serde_json `Value` holds it.
            self.out.extend_from_slice(b"null");
            return;
        }
        // The whole numbers 0 to 9 (ranks), as zmij spells them: the digit and `.0`.
        if x.to_bits() <= 9f64.to_bits() && f64::from(x as u8) == x {
            self.out.extend_from_slice(&[b'0' + x as u8, b'.', b'0']);
            return;
        }
        let bits = x.to_bits();
        if let Some(&(_, start, len)) = self.spelled.iter().find(|s| s.0 == bits) {
            self.out.extend_from_within(start..start + len);
            return;
        }
        // serde_json's own spelling of an f64 (its `write_f64`).
        let start = self.out.len();
        self.out
            .extend_from_slice(zmij::Buffer::new().format_finite(x).as_bytes());
        self.spelled = [(bits, start, self.out.len() - start), self.spelled[0]];
    }
}

/// Whether `bytes` hold a quote, a backslash or a control character (below 0x20): what JSON
/// escapes. Eight bytes at a time, the last word overlapping the one before it when the
/// length is not a multiple of eight (names are 5 to 30 bytes; a byte at a time took a
/// quarter of the writer's time).
#[inline]
pub(crate) fn needs_escape(bytes: &[u8]) -> bool {
    const ONES: u64 = 0x0101_0101_0101_0101;
    let special = |word: u64| {
        let zero = |w: u64| w.wrapping_sub(ONES) & !w & ONES.wrapping_mul(0x80);
        // The high bit of a byte is flagged only when that byte, or one below it, is what
        // is looked for (a borrow runs upwards only): the word is flagged exactly when it
        // holds one.
        zero(word ^ ONES.wrapping_mul(u64::from(b'"')))
            | zero(word ^ ONES.wrapping_mul(u64::from(b'\\')))
            | (word.wrapping_sub(ONES.wrapping_mul(0x20)) & !word & ONES.wrapping_mul(0x80))
    };
    let word = |chunk: &[u8]| {
        let mut eight = [0u8; 8];
        eight.copy_from_slice(chunk);
        u64::from_le_bytes(eight)
    };
    if bytes.len() < 8 {
        return bytes.iter().any(|&b| b < 0x20 || b == b'"' || b == b'\\');
    }
    let mut chunks = bytes.chunks_exact(8);
    if chunks.by_ref().any(|chunk| special(word(chunk)) != 0) {
        return true;
    }
    !chunks.remainder().is_empty() && special(word(&bytes[bytes.len() - 8..])) != 0
}

#[cfg(test)]
pub(crate) mod tests {
    use proptest::prelude::*;

    use super::*;
    use crate::artifacts::{MarkerStatus, RunMarker};
    use crate::json::to_sorted_pretty;

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(4000))]
        /// The word-at-a-time check finds what a byte-at-a-time one finds, wherever the byte
        /// sits (first, last, in the overlap of the last two words) and whatever surrounds it
        /// (bytes above 0x7f, which the word's arithmetic must not take for small ones).
        #[test]
        fn needs_escape_is_the_byte_rule(
            body in proptest::collection::vec(
                prop_oneof![32u8..127, 128u8..=255, Just(b'"'), Just(b'\\'), 0u8..32],
                0..40,
            )
        ) {
            let bytewise = body.iter().any(|&b| b < 0x20 || b == b'"' || b == b'\\');
            prop_assert_eq!(needs_escape(&body), bytewise);
        }
    }

    /// Strings with what JSON escapes (quotes, backslashes, control characters) and what it
    /// does not (non-ASCII, `/`, DEL): the names and values of both writers' tests.
    pub(crate) fn text() -> impl Strategy<Value = String> {
        prop_oneof![
            "[a-z_/.0-9]{0,24}",
            proptest::collection::vec(
                prop_oneof![
                    Just('"'),
                    Just('\\'),
                    Just('\n'),
                    Just('\u{1}'),
                    Just('\u{1f}'),
                    Just('\u{7f}'),
                    Just('/'),
                    Just('é'),
                    Just('😀'),
                    Just('a'),
                ],
                0..6
            )
            .prop_map(|chars| chars.into_iter().collect()),
        ]
    }

    fn marker() -> impl Strategy<Value = RunMarker> {
        let map = || proptest::collection::btree_map(text(), text(), 0..4);
        let list = || proptest::collection::vec(text(), 0..3);
        (
            (text(), text(), text(), any::<bool>(), text(), text()),
            (map(), map(), list(), list()),
        )
            .prop_map(
                |(
                    (schema, stage, scene, done, mesa_version, config_digest),
                    (inputs, outputs, warnings, error),
                )| RunMarker {
                    schema,
                    stage,
                    scene,
                    status: if done {
                        MarkerStatus::Done
                    } else {
                        MarkerStatus::Failed
                    },
                    mesa_version,
                    config_digest,
                    inputs,
                    outputs,
                    warnings,
                    error,
                },
            )
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(2000))]
        /// A marker written by hand has the bytes of serde's sorted writer: every key, empty
        /// and full maps and lists, strings that need escaping.
        #[test]
        fn marker_bytes_are_those_of_the_sorted_serde_path(marker in marker()) {
            let expected = to_sorted_pretty(&marker).expect("serialises");
            prop_assert_eq!(
                String::from_utf8(marker.to_pretty_json()).expect("UTF-8"),
                String::from_utf8(expected).expect("UTF-8")
            );
        }
    }

    /// Control: markers that differ in one value or in the order of two entries give other
    /// bytes, so the property above can fail.
    #[test]
    fn a_changed_marker_gives_other_bytes() {
        let marker = RunMarker {
            schema: "mesa.marker/1".into(),
            stage: "graph".into(),
            scene: "t/s".into(),
            status: MarkerStatus::Done,
            mesa_version: "0.1.0".into(),
            config_digest: "c".into(),
            inputs: [
                ("a".to_owned(), "1".to_owned()),
                ("b".to_owned(), "2".to_owned()),
            ]
            .into(),
            outputs: Default::default(),
            warnings: vec!["w".into()],
            error: Vec::new(),
        };
        let bytes = marker.to_pretty_json();
        assert_eq!(bytes, to_sorted_pretty(&marker).expect("serialises"));
        let text = String::from_utf8(bytes.clone()).expect("UTF-8");
        assert!(text.contains("\"outputs\": {},\n  \"scene\""), "{text}");
        let mut failed = marker.clone();
        failed.status = MarkerStatus::Failed;
        assert_ne!(failed.to_pretty_json(), bytes);
        let swapped = text.replace(
            "\"a\": \"1\",\n    \"b\": \"2\"",
            "\"b\": \"2\",\n    \"a\": \"1\"",
        );
        assert_ne!(swapped.as_bytes(), &bytes[..]);
    }

    /// Control: a quote, a backslash or a control byte in any place of names of every length
    /// up to 24 is found, and plain names of those lengths pass.
    #[test]
    fn needs_escape_finds_each_special_byte_in_each_place() {
        for len in 1..=24 {
            let plain = vec![b'a'; len];
            assert!(!needs_escape(&plain), "{len}");
            for at in 0..len {
                for special in [b'"', b'\\', 0x00, 0x1f, b'\n'] {
                    let mut name = plain.clone();
                    name[at] = special;
                    assert!(needs_escape(&name), "{len} {at} {special}");
                }
                let mut high = plain.clone();
                high[at] = 0xff;
                assert!(!needs_escape(&high), "{len} {at}");
            }
        }
    }
}
