//! Reading and writing JSON the way mesa needs it.
//!
//! Reading is lenient about one thing only: Python's `json.dump` writes `NaN`, `Infinity` and
//! `-Infinity`, which strict JSON parsers reject with a syntax error that hides the real problem.
//! [`parse_lenient`] turns those tokens into a sentinel string so that validation can report
//! "is NaN (expected a finite number)" at the exact JSON path. Writing always produces sorted
//! keys (serde_json's map is a `BTreeMap` in this build; a test pins it), two-space indentation
//! and a trailing newline, so the same value always gives the same bytes.

use serde::Serialize;
use serde_json::Value;

/// Prefix of the string that stands in for a non-finite number read from a file.
pub const NONFINITE_PREFIX: &str = "\u{1}mesa:nonfinite:";

/// If `value` is the stand-in for a non-finite number, its spelling in the file (`NaN`, ...).
pub fn nonfinite_token(value: &Value) -> Option<&str> {
    value.as_str()?.strip_prefix(NONFINITE_PREFIX)
}

/// A value as a message shows it: a non-finite stand-in as the file spelled it, with why it
/// is refused (never the internal sentinel), anything else as JSON.
pub fn describe_value(value: &Value) -> String {
    match nonfinite_token(value) {
        Some(token) => format!("{token}, which is not a number JSON allows"),
        None => value.to_string(),
    }
}

/// The problem with JSON text that starts with a UTF-8 byte order mark (some Windows editors
/// write one). It is refused, not skipped, in every JSON reader, so a file mesa accepts is one
/// any strict reader downstream accepts too.
pub const BOM_PROBLEM: &str =
    "starts with a UTF-8 byte order mark (expected JSON text; save the file without one)";

/// Whether `text` starts with a UTF-8 byte order mark (see [`BOM_PROBLEM`]).
pub fn starts_with_bom(text: &str) -> bool {
    text.starts_with('\u{feff}')
}

/// Parses JSON text, accepting the non-finite tokens `NaN`, `Infinity` and `-Infinity` outside
/// strings (they become sentinel strings, see [`nonfinite_token`]). Text that starts with a
/// byte order mark is refused with [`BOM_PROBLEM`], an object with a key twice as
/// [`check_unique_keys`] says.
pub fn parse_lenient(text: &str) -> Result<Value, serde_json::Error> {
    if starts_with_bom(text) {
        return Err(<serde_json::Error as serde::de::Error>::custom(BOM_PROBLEM));
    }
    match parse_unique(text) {
        Ok(value) => Ok(value),
        Err(strict_error) => {
            let Some(rewritten) = rewrite_nonfinite(text) else {
                return Err(strict_error);
            };
            // The sentinels change columns, not lines: the line of a duplicate stays right.
            parse_unique(&rewritten)
        }
    }
}

/// Refuses JSON text in which an object has the same key twice: serde_json would silently
/// keep the last value. The error names the key, its JSON path and (from serde_json) its line
/// and column: `duplicate key "size" in $.objects[1] (a JSON object holds each key once; keep
/// one of them) at line 9 column 14`. Every reader of outside JSON calls it (through
/// [`parse_lenient`] or directly). Bounded like a parse: one pass, serde_json's nesting limit,
/// memory for the keys of the objects open along one path.
pub fn check_unique_keys(text: &str) -> Result<(), serde_json::Error> {
    parse_unique(text).map(drop)
}

/// Parses JSON text into a [`Value`] in one pass, refusing an object with a key twice as
/// [`check_unique_keys`] says (serde_json's own `Value` keeps the last of them). The JSON path
/// of each value is a chain of borrowed segments, written out only into an error.
pub fn parse_unique(text: &str) -> Result<Value, serde_json::Error> {
    use serde::de::DeserializeSeed as _;
    let mut deserializer = serde_json::Deserializer::from_str(text);
    let value = UniqueValue {
        path: &PathSeg::Root,
    }
    .deserialize(&mut deserializer)?;
    deserializer.end()?;
    Ok(value)
}

/// Where a value is in the document, from the root: rendered `$.objects[1].size`.
enum PathSeg<'p> {
    Root,
    Key(&'p PathSeg<'p>, &'p str),
    Index(&'p PathSeg<'p>, usize),
}

impl PathSeg<'_> {
    fn render(&self) -> String {
        match self {
            PathSeg::Root => "$".to_owned(),
            PathSeg::Key(parent, key) => key_path(&parent.render(), key),
            PathSeg::Index(parent, i) => format!("{}[{i}]", parent.render()),
        }
    }
}

/// `path.key`, or `path["key"]` for a key that is not an identifier (as
/// `validate::path_key`, which this module cannot import: validate imports it).
fn key_path(path: &str, key: &str) -> String {
    let plain = !key.is_empty()
        && key.chars().all(|c| c.is_ascii_alphanumeric() || c == '_')
        && !key.starts_with(|c: char| c.is_ascii_digit());
    if plain {
        format!("{path}.{key}")
    } else {
        format!("{path}[{}]", Value::String(key.to_owned()))
    }
}

/// A visitor that builds any JSON value as serde_json's `Value` does, and fails on a repeated
/// key.
struct UniqueValue<'p> {
    path: &'p PathSeg<'p>,
}

impl<'de> serde::de::DeserializeSeed<'de> for UniqueValue<'_> {
    type Value = Value;

    fn deserialize<D: serde::Deserializer<'de>>(self, deserializer: D) -> Result<Value, D::Error> {
        deserializer.deserialize_any(self)
    }
}

impl<'de> serde::de::Visitor<'de> for UniqueValue<'_> {
    type Value = Value;

    fn expecting(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("a JSON value")
    }

    fn visit_bool<E>(self, v: bool) -> Result<Value, E> {
        Ok(Value::Bool(v))
    }

    fn visit_i64<E>(self, v: i64) -> Result<Value, E> {
        Ok(Value::Number(v.into()))
    }

    fn visit_u64<E>(self, v: u64) -> Result<Value, E> {
        Ok(Value::Number(v.into()))
    }

    fn visit_f64<E>(self, v: f64) -> Result<Value, E> {
        Ok(serde_json::Number::from_f64(v).map_or(Value::Null, Value::Number))
    }

    fn visit_str<E>(self, v: &str) -> Result<Value, E> {
        Ok(Value::String(v.to_owned()))
    }

    fn visit_string<E>(self, v: String) -> Result<Value, E> {
        Ok(Value::String(v))
    }

    fn visit_unit<E>(self) -> Result<Value, E> {
        Ok(Value::Null)
    }

    fn visit_none<E>(self) -> Result<Value, E> {
        Ok(Value::Null)
    }

    fn visit_seq<A: serde::de::SeqAccess<'de>>(self, mut seq: A) -> Result<Value, A::Error> {
        let mut items = Vec::with_capacity(seq.size_hint().unwrap_or(0));
        loop {
            let path = PathSeg::Index(self.path, items.len());
            match seq.next_element_seed(UniqueValue { path: &path })? {
                Some(item) => items.push(item),
                None => return Ok(Value::Array(items)),
            }
        }
    }

    fn visit_map<A: serde::de::MapAccess<'de>>(self, mut map: A) -> Result<Value, A::Error> {
        let mut object = serde_json::Map::new();
        while let Some(key) = map.next_key::<String>()? {
            // One search of the map for both the check and the insert.
            let slot = match object.entry(key) {
                serde_json::map::Entry::Vacant(slot) => slot,
                serde_json::map::Entry::Occupied(taken) => {
                    return Err(serde::de::Error::custom(format!(
                        "duplicate key {} in {} (a JSON object holds each key once; keep one \
                         of them)",
                        Value::String(taken.key().clone()),
                        self.path.render()
                    )));
                }
            };
            let path = PathSeg::Key(self.path, slot.key());
            let value = map.next_value_seed(UniqueValue { path: &path })?;
            slot.insert(value);
        }
        Ok(Value::Object(object))
    }
}

/// Replaces bare non-finite tokens with sentinel strings; `None` when there are none.
fn rewrite_nonfinite(text: &str) -> Option<String> {
    const TOKENS: [&str; 3] = ["-Infinity", "Infinity", "NaN"];
    let bytes = text.as_bytes();
    let mut out = String::with_capacity(text.len() + 32);
    let mut in_string = false;
    let mut escaped = false;
    let mut changed = false;
    let mut i = 0;
    while i < bytes.len() {
        let c = bytes[i];
        if in_string {
            if escaped {
                escaped = false;
            } else if c == b'\\' {
                escaped = true;
            } else if c == b'"' {
                in_string = false;
            }
        } else if c == b'"' {
            in_string = true;
        } else if let Some(token) = TOKENS.iter().find(|t| text[i..].starts_with(**t)) {
            // The prefix starts with a control character, which must be escaped in JSON text.
            out.push_str("\"\\u0001");
            out.push_str(&NONFINITE_PREFIX[1..]);
            out.push_str(token);
            out.push('"');
            i += token.len();
            changed = true;
            continue;
        }
        // Copy one UTF-8 character.
        let len = utf8_len(c);
        out.push_str(&text[i..i + len]);
        i += len;
    }
    changed.then_some(out)
}

fn utf8_len(first: u8) -> usize {
    match first {
        0x00..=0x7f => 1,
        0xc0..=0xdf => 2,
        0xe0..=0xef => 3,
        _ => 4,
    }
}

/// Serialises `value` with sorted keys, two-space indentation and a trailing newline: the bytes
/// of `serde_json::to_vec_pretty(&serde_json::to_value(value)?)` and a newline, written without
/// the `Value` tree (the `sorted_writer` module).
pub fn to_sorted_pretty<T: Serialize + ?Sized>(value: &T) -> Result<Vec<u8>, serde_json::Error> {
    let mut bytes = crate::sorted_writer::write_sorted(value, true)?;
    bytes.push(b'\n');
    Ok(bytes)
}

/// Serialises `value` on one line with sorted keys (for JSON Lines), without a newline: the
/// text of `serde_json::to_string(&serde_json::to_value(value)?)`.
pub fn to_sorted_line<T: Serialize + ?Sized>(value: &T) -> Result<String, serde_json::Error> {
    let bytes = crate::sorted_writer::write_sorted(value, false)?;
    // serde_json writes only UTF-8 (strings are &str, escapes are ASCII).
    String::from_utf8(bytes).map_err(<serde_json::Error as serde::ser::Error>::custom)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_key_twice_is_refused_with_its_path_and_position() {
        let text = "{\"objects\": [\n  {\"instance\": \"mug_0\"},\n  {\"size\": [1, 2, 3], \"size\": [4, 5, 6]}\n]}";
        let e = parse_lenient(text).expect_err("duplicate");
        assert_eq!(
            e.to_string(),
            "duplicate key \"size\" in $.objects[1] (a JSON object holds each key once; keep \
             one of them) at line 3 column 28"
        );
        // With a non-finite token too (the lenient path).
        let e = parse_lenient("{\"a\": NaN,\n \"a\": 1}").expect_err("duplicate");
        assert!(e.to_string().starts_with("duplicate key \"a\" in $"), "{e}");
        assert_eq!(e.line(), 2);
        // Control: the same keys in different objects, and plain values, pass; serde_json
        // alone keeps the last value silently.
        let fine = "{\"a\": {\"x\": 1}, \"b\": {\"x\": [true, null, \"s\", -1, 2.5]}}";
        assert!(parse_lenient(fine).is_ok());
        let last: Value = serde_json::from_str("{\"a\": 1, \"a\": 2}").expect("serde_json");
        assert_eq!(last["a"], 2);
        // Deep nesting stays bounded by serde_json's recursion limit, an error not a crash.
        let deep = format!("{}{}", "[".repeat(100_000), "]".repeat(100_000));
        assert!(check_unique_keys(&deep).is_err());
    }

    #[test]
    fn nonfinite_tokens_become_sentinels_outside_strings_only() {
        let value = parse_lenient(r#"{"a": NaN, "b": [-Infinity, Infinity], "c": "NaN \" NaN"}"#)
            .expect("lenient parse");
        assert_eq!(nonfinite_token(&value["a"]), Some("NaN"));
        assert_eq!(nonfinite_token(&value["b"][0]), Some("-Infinity"));
        assert_eq!(nonfinite_token(&value["b"][1]), Some("Infinity"));
        assert_eq!(value["c"], "NaN \" NaN");
    }

    #[test]
    fn messages_show_nonfinite_values_as_the_file_spelled_them() {
        let value = parse_lenient(r#"{"a": NaN, "b": 2}"#).expect("lenient parse");
        assert_eq!(
            describe_value(&value["a"]),
            "NaN, which is not a number JSON allows"
        );
        assert_eq!(describe_value(&value["b"]), "2");
    }

    #[test]
    fn a_byte_order_mark_is_refused_with_its_name() {
        let e = parse_lenient("\u{feff}{\"a\": 1}").expect_err("refused");
        assert!(e.to_string().contains("byte order mark"), "{e}");
        assert!(
            parse_lenient("{\"a\": \"\u{feff}\"}").is_ok(),
            "inside a string is fine"
        );
    }

    #[test]
    fn syntax_errors_stay_errors() {
        assert!(parse_lenient(r#"{"a": NaN,}"#).is_err());
        assert!(parse_lenient(r#"{"a": Nan}"#).is_err());
    }

    #[test]
    fn output_keys_are_sorted() {
        #[derive(Serialize)]
        struct S {
            zeta: u8,
            alpha: u8,
        }
        let text = String::from_utf8(to_sorted_pretty(&S { zeta: 1, alpha: 2 }).expect("ser"))
            .expect("utf8");
        assert!(text.find("alpha").expect("alpha") < text.find("zeta").expect("zeta"));
        assert!(text.ends_with("}\n"));
    }
}
