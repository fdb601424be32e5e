//! `json::to_sorted_pretty` and `json::to_sorted_line` write, byte for byte, what serde_json
//! writes through its `Value` tree (`to_value` then `to_vec_pretty` / `to_string`), on every
//! shape of serde's data model and on random documents. Controls: serde_json's direct writer
//! (struct fields in declaration order, an f32 not widened) differs from that reference on the
//! same values, so the comparison can fail.

use std::collections::{BTreeMap, HashMap};

use mesa_schemas::json::{to_sorted_line, to_sorted_pretty};
use proptest::prelude::*;
use serde::ser::{SerializeMap, Serializer};
use serde::Serialize;
use serde_json::{Map, Value};

/// The reference: serde_json through `Value`.
fn by_value<T: Serialize + ?Sized>(value: &T) -> Result<(Vec<u8>, String), String> {
    let tree = serde_json::to_value(value).map_err(|e| e.to_string())?;
    let mut pretty = serde_json::to_vec_pretty(&tree).map_err(|e| e.to_string())?;
    pretty.push(b'\n');
    let line = serde_json::to_string(&tree).map_err(|e| e.to_string())?;
    Ok((pretty, line))
}

fn direct<T: Serialize + ?Sized>(value: &T) -> Result<(Vec<u8>, String), String> {
    let pretty = to_sorted_pretty(value).map_err(|e| e.to_string())?;
    let line = to_sorted_line(value).map_err(|e| e.to_string())?;
    Ok((pretty, line))
}

#[track_caller]
fn same<T: Serialize + ?Sized>(value: &T) {
    match (by_value(value), direct(value)) {
        (Ok(reference), Ok(written)) => {
            assert_eq!(
                String::from_utf8_lossy(&written.0),
                String::from_utf8_lossy(&reference.0),
                "pretty"
            );
            assert_eq!(written.1, reference.1, "one line");
        }
        (Err(_), Err(_)) => {}
        (reference, written) => panic!("reference {reference:?}, written {written:?}"),
    }
}

#[derive(Serialize)]
struct Unit;

#[derive(Serialize)]
struct Empty {}

#[derive(Serialize)]
struct Newtype(f32);

#[derive(Serialize)]
struct Pair(u8, &'static str);

#[derive(Serialize)]
#[allow(dead_code)]
enum Shape {
    Point,
    Circle(f64),
    Segment(f32, f32),
    Box { zeta: u8, alpha: Option<u8> },
    Wrapped(Inner),
    EmptyStruct {},
    EmptyTuple(),
}

#[derive(Serialize)]
#[serde(tag = "type")]
enum Tagged {
    Mug { size: f32, name: &'static str },
}

#[derive(Serialize)]
#[serde(tag = "t", content = "c")]
enum Adjacent {
    Value { b: u8, a: u8 },
}

#[derive(Serialize)]
#[serde(untagged)]
enum Untagged {
    Number(i64),
    Record { y: i8, x: i8 },
}

#[derive(Serialize, Clone)]
struct Inner {
    z: Vec<f32>,
    b: BTreeMap<String, Value>,
    #[serde(skip_serializing_if = "Option::is_none")]
    skipped: Option<u8>,
    a: (),
}

#[derive(Serialize)]
struct Flattened {
    zz: u8,
    #[serde(flatten)]
    rest: BTreeMap<String, u8>,
    aa: u8,
}

/// A map that writes a key twice (a `Value` keeps the later value).
struct Twice;

impl Serialize for Twice {
    fn serialize<S: Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        let mut map = serializer.serialize_map(None)?;
        map.serialize_entry("b", &1)?;
        map.serialize_entry("a", &[2, 3])?;
        map.serialize_entry("b", &"later")?;
        map.serialize_entry("c", &Empty {})?;
        map.serialize_entry("a", &Unit)?;
        map.end()
    }
}

/// A map of its entries in the order given (any key type, repeats kept).
struct InOrder<K, V>(Vec<(K, V)>);

impl<K: Serialize, V: Serialize> Serialize for InOrder<K, V> {
    fn serialize<S: Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        let mut map = serializer.serialize_map(Some(self.0.len()))?;
        for (k, v) in &self.0 {
            map.serialize_entry(k, v)?;
        }
        map.end()
    }
}

/// Raw bytes (`serialize_bytes`: an array of numbers in a `Value`).
struct Bytes(&'static [u8]);

impl Serialize for Bytes {
    fn serialize<S: Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        serializer.serialize_bytes(self.0)
    }
}

#[derive(Serialize, PartialEq, Eq, PartialOrd, Ord, Hash)]
enum KeyKind {
    Left,
    Right,
}

/// Nested lists of maps.
type Nested = Vec<Vec<Vec<BTreeMap<String, Vec<u8>>>>>;

#[derive(Serialize)]
struct Everything {
    strings: Vec<&'static str>,
    floats32: Vec<f32>,
    floats64: Vec<f64>,
    ints: (i8, i16, i32, i64, u8, u16, u32, u64),
    wide: (i128, u128),
    chars: [char; 3],
    options: (Option<u8>, Option<Inner>),
    units: (Unit, (), Empty, Newtype, Pair),
    shapes: Vec<Shape>,
    tagged: Tagged,
    adjacent: Adjacent,
    untagged: Vec<Untagged>,
    flattened: Flattened,
    twice: Twice,
    bytes: Bytes,
    int_keys: BTreeMap<i32, bool>,
    bool_keys: BTreeMap<bool, u8>,
    char_keys: BTreeMap<char, u8>,
    variant_keys: BTreeMap<KeyKind, u8>,
    hashed: HashMap<String, u32>,
    nested: Nested,
    empty_map: BTreeMap<String, u8>,
    empty_vec: Vec<u8>,
    value: Value,
}

fn everything() -> Everything {
    let inner = Inner {
        z: vec![0.1, 1.0 / 3.0, f32::MIN_POSITIVE, 1e-45, -0.0],
        b: [
            ("\u{7f}".to_owned(), Value::Null),
            ("é".to_owned(), Value::from(1.5)),
            ("A".to_owned(), serde_json::json!({"y": [], "x": {}})),
        ]
        .into_iter()
        .collect(),
        skipped: None,
        a: (),
    };
    Everything {
        strings: vec![
            "",
            "plain",
            "quote \" backslash \\ slash /",
            "\u{0}\u{1}\u{8}\u{c}\n\r\t\u{1f}\u{7f}",
            "é ü 🦀 \u{2028}\u{2029}",
        ],
        floats32: vec![
            0.1,
            -2.5,
            f32::NAN,
            f32::INFINITY,
            f32::NEG_INFINITY,
            f32::MAX,
            16_777_217.0,
            -0.0,
        ],
        floats64: vec![
            0.1,
            1e300,
            5e-324,
            f64::NAN,
            f64::NEG_INFINITY,
            -0.0,
            1e21,
            123.0,
        ],
        ints: (
            i8::MIN,
            i16::MIN,
            i32::MIN,
            i64::MIN,
            u8::MAX,
            u16::MAX,
            u32::MAX,
            u64::MAX,
        ),
        wide: (i128::from(i64::MIN), u128::from(u64::MAX)),
        chars: ['a', '"', '\u{1}'],
        options: (None, Some(inner.clone())),
        units: (Unit, (), Empty {}, Newtype(0.3), Pair(7, "seven")),
        shapes: vec![
            Shape::Point,
            Shape::Circle(2.0),
            Shape::Segment(0.1, f32::NAN),
            Shape::Box {
                zeta: 1,
                alpha: None,
            },
            Shape::Wrapped(inner),
            Shape::EmptyStruct {},
            Shape::EmptyTuple(),
        ],
        tagged: Tagged::Mug {
            size: 0.7,
            name: "mug",
        },
        adjacent: Adjacent::Value { b: 2, a: 1 },
        untagged: vec![Untagged::Number(-3), Untagged::Record { y: 1, x: 2 }],
        flattened: Flattened {
            zz: 1,
            rest: [("mm".to_owned(), 2), ("ab".to_owned(), 3)].into(),
            aa: 4,
        },
        twice: Twice,
        bytes: Bytes(&[0, 1, 255]),
        int_keys: [(-10, true), (2, false), (10, true)].into(),
        bool_keys: [(true, 1), (false, 0)].into(),
        char_keys: [('b', 1), ('a', 2)].into(),
        variant_keys: [(KeyKind::Right, 1), (KeyKind::Left, 2)].into(),
        hashed: (0..40).map(|i| (format!("key{i}"), i)).collect(),
        nested: vec![
            vec![vec![], vec![[("k".to_owned(), vec![1])].into()]],
            vec![],
        ],
        empty_map: BTreeMap::new(),
        empty_vec: Vec::new(),
        value: serde_json::json!({"b": [1, {"d": null, "c": true}], "a": "x"}),
    }
}

#[test]
fn every_shape_of_the_data_model_is_written_as_the_value_tree_writes_it() {
    same(&everything());
    for shape in [
        Shape::Point,
        Shape::Circle(-1.0),
        Shape::EmptyStruct {},
        Shape::EmptyTuple(),
    ] {
        same(&shape);
    }
    same(&Twice);
    same(&Unit);
    same(&Empty {});
    same(&Bytes(&[]));
    same(&f32::NAN);
    same(&0.1f32);
    same("top-level string");
    same(&Vec::<u8>::new());
    // Both refuse what a `Value` cannot hold.
    same(&(u128::MAX, 1));
    same(&i128::MIN);
    let mut bad_keys = BTreeMap::new();
    bad_keys.insert(vec![1u8], 1u8);
    assert!(to_sorted_pretty(&bad_keys).is_err());
    assert!(by_value(&bad_keys).is_err());
    same(&InOrder(vec![(1.5, 1), (-0.25, 2), (1e21, 3)]));
    assert!(to_sorted_pretty(&InOrder(vec![(f64::NAN, 1u8)])).is_err());
}

#[test]
fn the_comparison_sees_unsorted_fields_and_unwidened_floats() {
    // Control: serde_json's own writer keeps declaration order and writes an f32 as an f32.
    let reference = by_value(&everything()).expect("reference").0;
    let mut unsorted = serde_json::to_vec_pretty(&everything()).expect("direct");
    unsorted.push(b'\n');
    assert_ne!(unsorted, reference);
    assert_eq!(serde_json::to_string(&0.1f32).expect("f32"), "0.1");
    assert_eq!(
        to_sorted_line(&0.1f32).expect("f32"),
        "0.10000000149011612",
        "widened as a Value stores it"
    );
}

fn arb_key() -> impl Strategy<Value = String> {
    prop_oneof![
        "[a-c]{0,3}",
        "[a-zA-Z_][a-zA-Z0-9_]{0,6}",
        "\\PC{0,4}",
        Just("\u{0}\"\\".to_owned()),
    ]
}

fn arb_value() -> impl Strategy<Value = Value> {
    let leaf = prop_oneof![
        Just(Value::Null),
        any::<bool>().prop_map(Value::Bool),
        any::<i64>().prop_map(Value::from),
        any::<u64>().prop_map(Value::from),
        any::<f64>().prop_map(Value::from),
        any::<f32>().prop_map(Value::from),
        "\\PC{0,8}".prop_map(Value::String),
    ];
    leaf.prop_recursive(4, 64, 6, |inner| {
        prop_oneof![
            prop::collection::vec(inner.clone(), 0..6).prop_map(Value::Array),
            prop::collection::vec((arb_key(), inner), 0..6)
                .prop_map(|entries| Value::Object(entries.into_iter().collect::<Map<_, _>>())),
        ]
    })
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(512))]

    #[test]
    fn random_documents_are_written_as_the_value_tree_writes_them(value in arb_value()) {
        let reference = by_value(&value).expect("reference");
        let written = direct(&value).expect("written");
        prop_assert_eq!(written.0, reference.0);
        prop_assert_eq!(written.1, reference.1);
    }

    /// Maps given in any order (a `HashMap`, entries in the order they come) come out sorted.
    #[test]
    fn maps_in_any_order_come_out_sorted(
        entries in prop::collection::vec((arb_key(), any::<i32>()), 0..12),
    ) {
        let value = InOrder(entries);
        prop_assert_eq!(direct(&value).expect("written"), by_value(&value).expect("reference"));
    }
}
