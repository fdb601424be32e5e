//! The quick reader of dataset layouts: a layout as mesa writes it, read straight into its type
//! in one pass of the text, without the generic [`Value`](serde_json::Value) and the JSON
//! Schema walk of [`read_layout_text`](crate::layout_file::read_layout_text).
//!
//! **Why.** Every stage after `place` reads a layout per scene, and the general reader spent
//! 41 µs on a 10 KB demo layout: most of it building a `Value` (a map and a string per key,
//! 30 µs alone) and walking the schema with JSON paths (13 µs alone), then 2.6 µs converting to
//! the type. Read straight into the type, the same layout takes 16 µs (criterion,
//! `schemas/benches/layout.rs`: 22 against 58.5 µs on a 12.6 KB layout). The graph stage,
//! whose own work is 5 µs a scene, spent a quarter of its time here.
//!
//! **It only ever accepts what the general reader accepts, with the same result.** It declines
//! (returns `None`, and the general reader runs and reports every problem with its JSON path)
//! at anything outside the plain shape:
//! - a key it does not know, at the top or in an object (the general reader keeps those in
//!   `extra`), or a key written twice, or a key with an escape in it;
//! - a value of another type than the field's (`null` for a required field, a string for a
//!   number, an array of the wrong length), or `NaN` or `Infinity`;
//! - a `schema` other than [`LAYOUT_SCHEMA`];
//! - a string that carries the marker of a rewritten non-finite number
//!   ([`NONFINITE_PREFIX`]);
//! - what the schema bounds (a size or scale factor not above 0) or the semantic checks
//!   ([`DatasetLayout::problems`]) refuse;
//! - trailing text after the document.
//!
//! What remains is a document that the schema accepts, with no key for `extra`; serde_json
//! reads its numbers and strings through the same code whether into a `Value` or into the
//! type, so the values are the same bits. `tests::accepts_only_what_the_general_reader_accepts`
//! checks it on thousands of generated and mutated layouts.

use std::fmt;

use serde::de::{self, DeserializeSeed, Deserializer, MapAccess, SeqAccess, Visitor};

use crate::json::NONFINITE_PREFIX;
use crate::layout::{DatasetLayout, LayoutObject, Provenance, LAYOUT_SCHEMA};
use crate::units::{PositionCm, QuatXyzw, ScaleFactor, SizeCm, ZoneCm};

/// `text` read as a dataset layout when it has the plain shape (module docs) and is valid;
/// `None` when the general reader must decide.
pub fn read_plain_dataset_layout(text: &str) -> Option<DatasetLayout> {
    let mut deserializer = serde_json::Deserializer::from_str(text);
    let layout = deserializer.deserialize_map(LayoutVisitor).ok()?;
    deserializer.end().ok()?;
    (within_schema_bounds(&layout) && layout.problems().is_empty()).then_some(layout)
}

/// The bounds of the JSON Schema that the type does not carry: sizes and scale factors above 0,
/// and no string that the lenient parser's non-finite marker could have produced (instance
/// names are left to [`DatasetLayout::problems`], whose name rule refuses the marker, and the
/// `schema` is checked as it is read).
fn within_schema_bounds(layout: &DatasetLayout) -> bool {
    let marked = |s: &str| s.starts_with(NONFINITE_PREFIX);
    layout.objects.iter().all(|o| {
        let provenance_marked = o
            .provenance
            .as_ref()
            .is_some_and(|p| marked(&p.stage) || p.notes.iter().any(|n| marked(n)));
        o.size_cm.0.iter().all(|&v| v > 0.0)
            && o.scale_factor.0.iter().all(|&v| v > 0.0)
            && !marked(&o.retrieved_uid)
            && !o.category.as_deref().is_some_and(marked)
            && !o.description.as_deref().is_some_and(marked)
            && !provenance_marked
    })
}

/// Declines the plain reading (the message is never shown).
fn decline<E: de::Error>() -> E {
    E::custom("not a plain layout")
}

/// Sets a field read once; a second time declines (a key written twice).
fn once<T, E: de::Error>(slot: &mut Option<T>, value: T) -> Result<(), E> {
    if slot.is_some() {
        return Err(decline());
    }
    *slot = Some(value);
    Ok(())
}

struct LayoutVisitor;

impl<'de> Visitor<'de> for LayoutVisitor {
    type Value = DatasetLayout;

    fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
        f.write_str("a dataset layout")
    }

    fn visit_map<A: MapAccess<'de>>(self, mut map: A) -> Result<DatasetLayout, A::Error> {
        let mut schema = None;
        let mut zone = None;
        let mut restricted = None;
        let mut objects = None;
        // A key with an escape cannot be borrowed, and fails here: declined.
        while let Some(key) = map.next_key::<&str>()? {
            match key {
                "schema" => {
                    let value: String = map.next_value()?;
                    if value != LAYOUT_SCHEMA {
                        return Err(decline());
                    }
                    once(&mut schema, value)?;
                }
                "item_placement_zone" => once(&mut zone, map.next_value::<ZoneCm>()?)?,
                "restricted_zone" => {
                    once(&mut restricted, map.next_value::<Option<ZoneCm>>()?)?;
                }
                "objects" => once(&mut objects, map.next_value_seed(ObjectsSeed)?)?,
                _ => return Err(decline()),
            }
        }
        Ok(DatasetLayout {
            schema: schema.unwrap_or_else(|| LAYOUT_SCHEMA.to_owned()),
            zone_cm: zone.ok_or_else(decline)?,
            restricted_zone_cm: restricted.flatten(),
            objects: objects.ok_or_else(decline)?,
            extra: Default::default(),
        })
    }
}

struct ObjectsSeed;

impl<'de> DeserializeSeed<'de> for ObjectsSeed {
    type Value = Vec<LayoutObject>;

    fn deserialize<D: Deserializer<'de>>(self, deserializer: D) -> Result<Self::Value, D::Error> {
        deserializer.deserialize_seq(self)
    }
}

impl<'de> Visitor<'de> for ObjectsSeed {
    type Value = Vec<LayoutObject>;

    fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
        f.write_str("a list of layout objects")
    }

    fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<Self::Value, A::Error> {
        let mut objects = Vec::with_capacity(seq.size_hint().unwrap_or(16).min(256));
        while let Some(object) = seq.next_element_seed(ObjectSeed)? {
            objects.push(object);
        }
        Ok(objects)
    }
}

struct ObjectSeed;

impl<'de> DeserializeSeed<'de> for ObjectSeed {
    type Value = LayoutObject;

    fn deserialize<D: Deserializer<'de>>(self, deserializer: D) -> Result<Self::Value, D::Error> {
        deserializer.deserialize_map(self)
    }
}

impl<'de> Visitor<'de> for ObjectSeed {
    type Value = LayoutObject;

    fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
        f.write_str("a layout object")
    }

    fn visit_map<A: MapAccess<'de>>(self, mut map: A) -> Result<LayoutObject, A::Error> {
        let mut instance = None;
        let mut retrieved_uid = None;
        let mut position = None;
        let mut rotation = None;
        let mut size = None;
        let mut scale_factor = None;
        let mut category = None;
        let mut description = None;
        let mut z_rotation = None;
        let mut provenance = None;
        while let Some(key) = map.next_key::<&str>()? {
            match key {
                "instance" => once(&mut instance, map.next_value::<String>()?)?,
                "retrieved_uid" => once(&mut retrieved_uid, map.next_value::<String>()?)?,
                "position" => once(&mut position, map.next_value::<PositionCm>()?)?,
                "rotation" => once(&mut rotation, map.next_value::<QuatXyzw>()?)?,
                "size" => once(&mut size, map.next_value::<SizeCm>()?)?,
                "scale_factor" => once(&mut scale_factor, map.next_value::<ScaleFactor>()?)?,
                "category" => once(&mut category, map.next_value::<Option<String>>()?)?,
                "description" => once(&mut description, map.next_value::<Option<String>>()?)?,
                "z_rotation" => once(&mut z_rotation, map.next_value::<Option<f64>>()?)?,
                "provenance" => once(&mut provenance, map.next_value_seed(ProvenanceSeed)?)?,
                _ => return Err(decline()),
            }
        }
        Ok(LayoutObject {
            instance: instance.ok_or_else(decline)?,
            retrieved_uid: retrieved_uid.ok_or_else(decline)?,
            position_cm: position.ok_or_else(decline)?,
            rotation: rotation.ok_or_else(decline)?,
            size_cm: size.ok_or_else(decline)?,
            scale_factor: scale_factor.ok_or_else(decline)?,
            category: category.flatten(),
            description: description.flatten(),
            z_rotation_deg: z_rotation.flatten(),
            provenance: provenance.flatten(),
            extra: Default::default(),
        })
    }
}

/// A provenance object, or `null`. Read as a map only: serde's derived reader would also take
/// an array for a struct, which the schema refuses.
struct ProvenanceSeed;

impl<'de> DeserializeSeed<'de> for ProvenanceSeed {
    type Value = Option<Provenance>;

    fn deserialize<D: Deserializer<'de>>(self, deserializer: D) -> Result<Self::Value, D::Error> {
        deserializer.deserialize_option(self)
    }
}

impl<'de> Visitor<'de> for ProvenanceSeed {
    type Value = Option<Provenance>;

    fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
        f.write_str("a provenance object or null")
    }

    fn visit_none<E: de::Error>(self) -> Result<Self::Value, E> {
        Ok(None)
    }

    fn visit_some<D: Deserializer<'de>>(self, deserializer: D) -> Result<Self::Value, D::Error> {
        deserializer.deserialize_map(ProvenanceVisitor).map(Some)
    }
}

struct ProvenanceVisitor;

impl<'de> Visitor<'de> for ProvenanceVisitor {
    type Value = Provenance;

    fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
        f.write_str("a provenance object")
    }

    fn visit_map<A: MapAccess<'de>>(self, mut map: A) -> Result<Provenance, A::Error> {
        let mut stage = None;
        let mut source_instance = None;
        let mut notes = None;
        while let Some(key) = map.next_key::<&str>()? {
            match key {
                "stage" => once(&mut stage, map.next_value::<String>()?)?,
                "source_instance" => {
                    once(&mut source_instance, map.next_value::<Option<u32>>()?)?;
                }
                "notes" => once(&mut notes, map.next_value::<Vec<String>>()?)?,
                _ => return Err(decline()),
            }
        }
        Ok(Provenance {
            stage: stage.ok_or_else(decline)?,
            source_instance: source_instance.flatten(),
            notes: notes.unwrap_or_default(),
        })
    }
}

#[cfg(test)]
mod tests {
    use proptest::prelude::*;
    use serde_json::{json, Value};

    use super::*;
    use crate::layout_file::{read_layout_text, read_layout_text_general, AnyLayout, ReadLayout};

    /// A small generator (splitmix64): each case is one seed, so a failure names its seed.
    struct Rng(u64);

    impl Rng {
        fn next(&mut self) -> u64 {
            self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
            let mut z = self.0;
            z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
            z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
            z ^ (z >> 31)
        }

        fn below(&mut self, n: usize) -> usize {
            (self.next() % n as u64) as usize
        }

        fn chance(&mut self, percent: u64) -> bool {
            self.next() % 100 < percent
        }

        /// A number as layouts hold them: full-precision decimals, whole numbers, tiny ones.
        fn number(&mut self, lo: f64, hi: f64) -> f64 {
            let unit = (self.next() >> 11) as f64 / (1u64 << 53) as f64;
            match self.below(10) {
                0 => (lo + unit * (hi - lo)).round(),
                1 => (lo + unit * (hi - lo)) * 1e-7,
                _ => lo + unit * (hi - lo),
            }
        }
    }

    /// A valid dataset layout as mesa writes it, with some optional fields left out.
    fn layout(rng: &mut Rng) -> Value {
        let count = rng.below(6);
        let objects: Vec<Value> = (0..count)
            .map(|i| {
                let yaw = rng.number(-180.0, 180.0);
                let half = yaw.to_radians() / 2.0;
                let mut object = json!({
                    "instance": format!("thing_{i}"),
                    "retrieved_uid": format!("{:032x}", rng.next()),
                    "position": [rng.number(0.0, 100.0), rng.number(0.0, 60.0), rng.number(0.0, 20.0)],
                    "rotation": [0.0, 0.0, half.sin(), half.cos()],
                    "size": [rng.number(0.5, 30.0), rng.number(0.5, 30.0), rng.number(0.5, 30.0)],
                    "scale_factor": [rng.number(0.5, 2.0), rng.number(0.5, 2.0), rng.number(0.5, 2.0)],
                });
                let map = object.as_object_mut().expect("object");
                if rng.chance(70) {
                    map.insert("category".into(), json!("thing"));
                }
                if rng.chance(70) {
                    map.insert("description".into(), json!("a \"quoted\" thing, été"));
                }
                if rng.chance(70) {
                    map.insert("z_rotation".into(), json!(yaw));
                }
                if rng.chance(60) {
                    map.insert(
                        "provenance".into(),
                        json!({"stage": "place", "source_instance": i, "notes": ["a note"]}),
                    );
                }
                object
            })
            .collect();
        let mut layout = json!({
            "item_placement_zone": [0.0, rng.number(50.0, 150.0), 0.0, rng.number(40.0, 80.0)],
            "objects": objects,
        });
        if rng.chance(80) {
            layout["schema"] = json!(LAYOUT_SCHEMA);
        }
        if rng.chance(50) {
            layout["restricted_zone"] = json!([10.0, 20.0, 10.0, 20.0]);
        }
        layout
    }

    /// Values that some field may be changed to: every type, bounds, specials.
    fn odd_value(rng: &mut Rng) -> Value {
        let values = [
            json!(null),
            json!(0),
            json!(0.0),
            json!(-1.5),
            json!(-0.0),
            json!(7),
            json!(u64::MAX),
            json!(1e308),
            json!(5e-324),
            json!("1"),
            json!(""),
            json!("\u{1}mesa:nonfinite:nan"),
            json!("bad name"),
            json!("thing_0"),
            json!("x".repeat(65)),
            json!([1.0, 2.0]),
            json!([1.0, 2.0, 3.0]),
            json!([0.0, 1.0, 1.0]),
            json!([1.0, 1.0, -2.0]),
            json!([0.0, 0.0, 0.0, 1.0]),
            json!([0.0, 0.0, 0.0, 2.0]),
            json!([30.0, 10.0, 0.0, 10.0]),
            json!({"stage": "x"}),
            json!(["place", 1, []]),
            json!({"stage": "x", "other": 1}),
            json!({"stage": "x", "source_instance": -1}),
            json!({"stage": "x", "source_instance": 4_294_967_296u64}),
            json!({"stage": "x", "source_instance": 2.0}),
            json!({}),
            json!(true),
        ];
        values[rng.below(values.len())].clone()
    }

    const OBJECT_KEYS: [&str; 11] = [
        "instance",
        "retrieved_uid",
        "position",
        "rotation",
        "size",
        "scale_factor",
        "category",
        "description",
        "z_rotation",
        "provenance",
        "unknown_key",
    ];
    const TOP_KEYS: [&str; 5] = [
        "schema",
        "item_placement_zone",
        "restricted_zone",
        "objects",
        "unknown_key",
    ];

    /// One change to the document: a key removed, added, or given an odd value.
    fn mutate(rng: &mut Rng, layout: &mut Value) {
        let objects = layout["objects"].as_array().map_or(0, Vec::len);
        let (target, keys): (&mut Value, &[&str]) = if objects > 0 && rng.chance(75) {
            (&mut layout["objects"][rng.below(objects)], &OBJECT_KEYS)
        } else {
            (layout, &TOP_KEYS)
        };
        let key = keys[rng.below(keys.len())];
        // An object already changed into something else stays as it is.
        let Some(map) = target.as_object_mut() else {
            return;
        };
        if rng.chance(25) {
            map.remove(key);
        } else if let Some(Value::Array(items)) = map.get_mut(key).filter(|_| rng.chance(50)) {
            // One element of a list of numbers made odd: its bounds and types.
            let specials = [
                json!(0.0),
                json!(-0.0),
                json!(-3.5),
                json!(5e-324),
                json!(1e308),
                json!("2"),
                json!(null),
                json!(4),
            ];
            if !items.is_empty() {
                let i = rng.below(items.len());
                items[i] = specials[rng.below(specials.len())].clone();
            }
        } else {
            map.insert(key.to_owned(), odd_value(rng));
        }
    }

    /// Changes made to the text: a key twice, a non-finite token, an escaped key, a byte-order
    /// mark, text after the document, an object written as something else.
    fn mutate_text(rng: &mut Rng, text: &str) -> String {
        // A valid value for each key, to write the key twice.
        const TWICE: [(&str, &str); 17] = [
            ("schema", "\"mesa.layout/1\""),
            ("item_placement_zone", "[0,10,0,10]"),
            ("restricted_zone", "[1,2,1,2]"),
            ("objects", "[]"),
            ("instance", "\"dup_0\""),
            ("retrieved_uid", "\"u\""),
            ("position", "[1,1,1]"),
            ("rotation", "[0,0,0,1]"),
            ("size", "[1,1,1]"),
            ("scale_factor", "[1,1,1]"),
            ("category", "\"c\""),
            ("description", "\"d\""),
            ("z_rotation", "0"),
            ("provenance", "{\"stage\":\"x\"}"),
            ("stage", "\"x\""),
            ("source_instance", "1"),
            ("notes", "[]"),
        ];
        match rng.below(11) {
            8 => number_spelled_oddly(rng, text),
            9 => {
                // A string value with an escape, a raw control character or a bad escape.
                let odd = ["\\u00e9t\\u00e9", "\\n", "\u{1}", "\\x", "\\ud800", "\\/"];
                let odd = odd[rng.below(odd.len())];
                text.replacen(": \"", &format!(": \"{odd}"), 1).replacen(
                    ":\"",
                    &format!(":\"{odd}"),
                    1,
                )
            }
            10 => text.replacen("null", ["nul", "nulll", "Null"][rng.below(3)], 1),
            0 | 1 => {
                // Among the keys the text has.
                let present: Vec<&(&str, &str)> = TWICE
                    .iter()
                    .filter(|(key, _)| text.contains(&format!("\"{key}\":")))
                    .collect();
                let Some(&&(key, value)) = present.get(rng.below(present.len().max(1))) else {
                    return text.to_owned();
                };
                let at = format!("\"{key}\":");
                text.replacen(&at, &format!("{at}{value},{at}"), 1)
            }
            2 => text.replacen(',', ",\"z_rotation\":NaN,", 1),
            3 => text.replacen("\"instance\"", "\"inst\\u0061nce\"", 1),
            4 => format!("\u{feff}{text}"),
            5 => format!("{text} x"),
            6 => format!("{text}\n  "),
            _ => text.replacen("1", "Infinity", 1),
        }
    }

    /// One number of the text spelled another way: each form JSON allows for a value, the
    /// limits of f64, and forms JSON refuses.
    fn number_spelled_oddly(rng: &mut Rng, text: &str) -> String {
        const SPELLINGS: [&str; 24] = [
            "1E2",
            "1e+2",
            "25e-1",
            "-0",
            "-0.0",
            "0e999999999999999999",
            "1e-400",
            "1e400",
            "01",
            "1.",
            ".5",
            "+1",
            "-",
            "1e",
            "12345678901234567890123",
            "9007199254740993",
            "-9223372036854775809",
            "0.30000000000000004",
            "2.2250738585072011e-308",
            "4.9e-324",
            "1.7976931348623157e308",
            "1.7976931348623159e308",
            "7.0000000000000000000000000000000000000000000001",
            "3",
        ];
        let bytes = text.as_bytes();
        let starts: Vec<usize> = (1..bytes.len())
            .filter(|&i| {
                (bytes[i].is_ascii_digit() || bytes[i] == b'-')
                    && matches!(bytes[i - 1], b' ' | b'[' | b',' | b':' | b'\n')
            })
            .collect();
        let Some(&start) = starts.get(rng.below(starts.len().max(1))) else {
            return text.to_owned();
        };
        let end = start
            + bytes[start..]
                .iter()
                .position(|b| !b"0123456789.eE+-".contains(b))
                .unwrap_or(bytes.len() - start);
        let spelling = SPELLINGS[rng.below(SPELLINGS.len())];
        format!("{}{spelling}{}", &text[..start], &text[end..])
    }

    fn canonical(read: &Result<ReadLayout, Vec<crate::Problem>>) -> String {
        match read {
            Ok(ReadLayout {
                form,
                layout: AnyLayout::Dataset(layout),
            }) => format!("{form:?} {}", serde_json::to_string(layout).expect("json")),
            other => format!("{other:?}"),
        }
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(4000))]

        /// Whatever the quick reader accepts, the general reader accepts with the same layout
        /// (compared as JSON, so that -0.0 and 0.0 differ); and `read_layout_text` gives the
        /// general reader's result, problems included, on every document. The control: an
        /// unchanged layout is always taken by the quick reader, and a share of the changed
        /// ones is not (counted in `the_quick_reader_declines_each_change_the_schema_refuses`).
        #[test]
        fn accepts_only_what_the_general_reader_accepts(seed in any::<u64>()) {
            let mut rng = Rng(seed);
            let mut document = layout(&mut rng);
            let changes = rng.below(4);
            for _ in 0..changes {
                mutate(&mut rng, &mut document);
            }
            let mut text = if rng.chance(50) {
                serde_json::to_string_pretty(&document).expect("json")
            } else {
                serde_json::to_string(&document).expect("json")
            };
            let text_changed = rng.chance(40);
            if text_changed {
                text = mutate_text(&mut rng, &text);
            }
            let general = read_layout_text_general(&text);
            if let Some(quick) = read_plain_dataset_layout(&text) {
                let quick = Ok(ReadLayout { form: LayoutForm::Dataset, layout: AnyLayout::Dataset(quick) });
                prop_assert_eq!(canonical(&quick), canonical(&general), "{}", text);
            } else if changes == 0 && !text_changed {
                prop_assert!(false, "an unchanged layout was declined: {}", text);
            }
            prop_assert_eq!(canonical(&read_layout_text(&text)), canonical(&general));
        }
    }

    use crate::layout_file::LayoutForm;

    /// Each change that the general reader refuses, the quick reader declines; the control is
    /// the same document unchanged, which both accept.
    #[test]
    fn the_quick_reader_declines_each_change_the_schema_refuses() {
        let base = r#"{"schema": "mesa.layout/1", "item_placement_zone": [0, 100, 0, 50],
            "objects": [{"instance": "mug_0", "retrieved_uid": "u", "position": [1, 2, 3],
            "rotation": [0, 0, 0, 1], "size": [8, 8, 10], "scale_factor": [1, 1, 1],
            "provenance": {"stage": "place", "source_instance": 3}}]}"#;
        assert!(read_layout_text_general(base).is_ok());
        assert!(read_plain_dataset_layout(base).is_some());
        let refused = [
            ("[8, 8, 10]", "[8, 0, 10]"),
            ("[8, 8, 10]", "[8, -8, 10]"),
            ("\"scale_factor\": [1, 1, 1]", "\"scale_factor\": [1, 0, 1]"),
            ("[0, 0, 0, 1]", "[0, 0, 0, 2]"),
            ("[0, 100, 0, 50]", "[100, 0, 0, 50]"),
            ("\"mug_0\"", "\"mug 0\""),
            ("\"mug_0\"", "\"\\u0001mesa:nonfinite:nan\""),
            ("\"mesa.layout/1\"", "\"mesa.layout/2\""),
            ("[1, 2, 3]", "[1, 2]"),
            ("[1, 2, 3]", "[1, 2, \"3\"]"),
            ("\"retrieved_uid\": \"u\",", ""),
            ("\"place\"", "null"),
            ("\"source_instance\": 3", "\"source_instance\": -3"),
            (
                "{\"stage\": \"place\", \"source_instance\": 3}",
                "[\"place\", 3, []]",
            ),
            (
                "\"size\": [8, 8, 10]",
                "\"size\": [8, 8, 10], \"size\": [8, 8, 10]",
            ),
        ];
        for (from, to) in refused {
            let text = base.replacen(from, to, 1);
            assert_ne!(text, base, "{from}");
            assert!(read_layout_text_general(&text).is_err(), "{text}");
            assert!(read_plain_dataset_layout(&text).is_none(), "{text}");
        }
        // Accepted by both, but with a key for `extra`: declined, the general reader keeps it.
        let extra = base.replacen("\"objects\"", "\"other_tool\": 1, \"objects\"", 1);
        assert!(read_plain_dataset_layout(&extra).is_none());
        let kept = read_layout_text(&extra).expect("valid");
        let AnyLayout::Dataset(layout) = kept.layout else {
            panic!("a dataset layout")
        };
        assert_eq!(layout.extra.get("other_tool"), Some(&json!(1)));
    }
}
