//! Asset annotations: `assets/annotations.json` in the MesaTask `Asset_annotation.json` /
//! objathor form (SPEC 5.2), a JSON object keyed by asset uid.
//!
//! Fields read per asset (all optional; unknown fields are ignored):
//!
//! | field | meaning | default |
//! |---|---|---|
//! | `category` | the asset's category, like `mug` | none |
//! | `description` | the text retrieval compares queries with | none |
//! | `onTable` | the asset may stand on a table | true |
//! | `mark_deletion` | the asset was marked for deletion | false |
//! | `is_composite` | the asset is a group of objects | false |
//! | `isContainer` (or objathor `receptacle`) | the asset can hold other objects | unknown |
//! | `frontView` | objathor: index of the thumbnail view that shows the front | none |
//! | `materials` | material names | empty |
//! | `mass` | mass in kg | none |
//! | bbox | extents in the asset's glTF frame (Y up: y = height), see [`BboxExtents`] | none |
//!
//! The bbox is read from any of the forms MesaTask's retrieval accepts: `"bbox": {"x", "y",
//! "z"}` extents, `"bbox": {"size": {"x", "y", "z"}}`, `"bbox": {"min": {...}, "max": {...}}`,
//! or top-level `"min_point"` / `"max_point"` (each corner an `{"x", "y", "z"}` object or an
//! `[x, y, z]` array). Booleans written by Python tools as `0` / `1` or `"True"` / `"False"`
//! are accepted. Every error names the uid and the field.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use mesa_schemas::json::{nonfinite_token, parse_lenient};
use mesa_schemas::validate::{describe, path_key};
use serde_json::{Map, Value};
use thiserror::Error;

/// Bounding-box extents of an asset in its glTF frame (metres, +Y up): `y` is the height.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BboxExtents {
    /// Extent along glTF X (the table frame's width).
    pub x: f64,
    /// Extent along glTF Y (the height).
    pub y: f64,
    /// Extent along glTF Z (the table frame's depth).
    pub z: f64,
}

impl BboxExtents {
    /// The extents as a table-frame size `[width, depth, height]` = `[x, z, y]`, as MesaTask's
    /// retrieval compares them with a target size.
    pub fn size_table_frame(&self) -> [f64; 3] {
        [self.x, self.z, self.y]
    }
}

/// The annotation of one asset.
#[derive(Debug, Clone, PartialEq)]
pub struct AssetAnnotation {
    /// The asset's category, like `mug`.
    pub category: Option<String>,
    /// The asset's description.
    pub description: Option<String>,
    /// `onTable`: whether the asset may stand on a table (default true).
    pub on_table: bool,
    /// `mark_deletion`: the asset was marked for deletion.
    pub mark_deletion: bool,
    /// `is_composite`: the asset is a group of objects.
    pub is_composite: bool,
    /// `isContainer` (or objathor `receptacle`); `None` when the annotation does not say.
    pub is_container: Option<bool>,
    /// objathor `frontView`: the index of the thumbnail view that shows the asset's front.
    pub front_view: Option<u32>,
    /// Material names.
    pub materials: Vec<String>,
    /// Mass in kg.
    pub mass_kg: Option<f64>,
    /// Bounding-box extents in the glTF frame.
    pub bbox: Option<BboxExtents>,
}

impl Default for AssetAnnotation {
    fn default() -> Self {
        Self {
            category: None,
            description: None,
            on_table: true,
            mark_deletion: false,
            is_composite: false,
            is_container: None,
            front_view: None,
            materials: Vec::new(),
            mass_kg: None,
            bbox: None,
        }
    }
}

impl AssetAnnotation {
    /// Why retrieval must not choose this asset (MesaTask's filter), if it must not.
    pub fn rejection(&self) -> Option<&'static str> {
        if !self.on_table {
            Some("onTable false")
        } else if self.mark_deletion {
            Some("mark_deletion")
        } else if self.is_composite {
            Some("is_composite")
        } else {
            None
        }
    }

    /// Reads one asset's annotation; errors name `uid` and the field.
    pub fn from_value(uid: &str, value: &Value) -> Result<Self, AnnotationError> {
        let Some(fields) = value.as_object() else {
            return Err(AnnotationError::field(
                uid,
                "",
                describe(value),
                "an annotation object",
            ));
        };
        let reader = Fields { uid, fields };
        let is_container = match reader.boolean("isContainer")? {
            Some(flag) => Some(flag),
            None => reader.boolean("receptacle")?,
        };
        Ok(Self {
            category: reader.string("category")?,
            description: reader.string("description")?,
            on_table: reader.boolean("onTable")?.unwrap_or(true),
            mark_deletion: reader.boolean("mark_deletion")?.unwrap_or(false),
            is_composite: reader.boolean("is_composite")?.unwrap_or(false),
            is_container,
            front_view: reader.index("frontView")?,
            materials: reader.strings("materials")?,
            mass_kg: reader.non_negative("mass")?,
            bbox: reader.bbox()?,
        })
    }
}

/// All annotations of an asset library, by uid.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Annotations {
    by_uid: BTreeMap<String, AssetAnnotation>,
}

impl Annotations {
    /// Reads `annotations.json`; errors start with the file's path.
    pub fn read(path: &Path) -> Result<Self, AnnotationError> {
        let text = std::fs::read_to_string(path).map_err(|source| AnnotationError::Io {
            path: path.to_owned(),
            source,
        })?;
        Self::parse(&text).map_err(|e| AnnotationError::InFile {
            path: path.to_owned(),
            source: Box::new(e),
        })
    }

    /// Parses the text of an annotations file (`NaN` and `Infinity` are reported at their
    /// field, not as syntax errors).
    pub fn parse(text: &str) -> Result<Self, AnnotationError> {
        let value = parse_lenient(text).map_err(AnnotationError::Syntax)?;
        Self::from_value(&value)
    }

    /// Reads an annotations document already parsed.
    pub fn from_value(value: &Value) -> Result<Self, AnnotationError> {
        let Some(entries) = value.as_object() else {
            return Err(AnnotationError::NotAnObject {
                found: describe(value),
            });
        };
        let by_uid = entries
            .iter()
            .map(|(uid, entry)| Ok((uid.clone(), AssetAnnotation::from_value(uid, entry)?)))
            .collect::<Result<_, AnnotationError>>()?;
        Ok(Self { by_uid })
    }

    /// The annotation of an asset.
    pub fn get(&self, uid: &str) -> Option<&AssetAnnotation> {
        self.by_uid.get(uid)
    }

    /// Number of annotated assets.
    pub fn len(&self) -> usize {
        self.by_uid.len()
    }

    /// True when no asset is annotated.
    pub fn is_empty(&self) -> bool {
        self.by_uid.is_empty()
    }

    /// The annotations by uid, in uid order.
    pub fn iter(&self) -> impl Iterator<Item = (&str, &AssetAnnotation)> {
        self.by_uid.iter().map(|(uid, a)| (uid.as_str(), a))
    }

    /// Adds or replaces an annotation.
    pub fn insert(&mut self, uid: impl Into<String>, annotation: AssetAnnotation) {
        self.by_uid.insert(uid.into(), annotation);
    }
}

/// Why annotations could not be read.
#[derive(Debug, Error)]
pub enum AnnotationError {
    /// The file could not be read.
    #[error("{}: cannot read: {source}", path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// The I/O error.
        source: std::io::Error,
    },
    /// A problem inside a file.
    #[error("{}: {source}", path.display())]
    InFile {
        /// The file.
        path: PathBuf,
        /// The problem.
        source: Box<AnnotationError>,
    },
    /// The text is not JSON.
    #[error("$: is not valid JSON: {0} (expected a JSON object keyed by asset uid)")]
    Syntax(serde_json::Error),
    /// The document is not an object.
    #[error("$: {found} (expected a JSON object keyed by asset uid)")]
    NotAnObject {
        /// What it is.
        found: String,
    },
    /// A field of one asset's annotation is unusable.
    #[error("{}: {problem} (expected {expected})", field_path(uid, field))]
    Field {
        /// The asset uid.
        uid: String,
        /// The field path inside the annotation, like `bbox.min.x` (empty: the whole entry).
        field: String,
        /// What is wrong.
        problem: String,
        /// What is expected.
        expected: &'static str,
    },
}

impl AnnotationError {
    fn field(uid: &str, field: &str, problem: impl Into<String>, expected: &'static str) -> Self {
        Self::Field {
            uid: uid.to_owned(),
            field: field.to_owned(),
            problem: problem.into(),
            expected,
        }
    }
}

fn field_path(uid: &str, field: &str) -> String {
    let mut path = path_key("$", uid);
    for part in field.split('.').filter(|p| !p.is_empty()) {
        if part.bytes().all(|b| b.is_ascii_digit()) {
            path = format!("{path}[{part}]");
        } else {
            path = path_key(&path, part);
        }
    }
    path
}

/// Typed access to one annotation's fields, with errors naming the uid and field.
struct Fields<'a> {
    uid: &'a str,
    fields: &'a Map<String, Value>,
}

impl Fields<'_> {
    /// The value of a field, `None` when absent or null.
    fn get(&self, key: &str) -> Option<&Value> {
        self.fields.get(key).filter(|v| !v.is_null())
    }

    fn error(&self, field: &str, value: &Value, expected: &'static str) -> AnnotationError {
        AnnotationError::field(self.uid, field, describe_value(value), expected)
    }

    fn string(&self, key: &str) -> Result<Option<String>, AnnotationError> {
        match self.get(key) {
            None => Ok(None),
            Some(Value::String(s)) if nonfinite_token(&Value::String(s.clone())).is_none() => {
                Ok(Some(s.clone()))
            }
            Some(other) => Err(self.error(key, other, "a string")),
        }
    }

    fn boolean(&self, key: &str) -> Result<Option<bool>, AnnotationError> {
        let Some(value) = self.get(key) else {
            return Ok(None);
        };
        let flag = match value {
            Value::Bool(b) => Some(*b),
            Value::Number(n) if n.as_f64() == Some(0.0) => Some(false),
            Value::Number(n) if n.as_f64() == Some(1.0) => Some(true),
            Value::String(s) if s.eq_ignore_ascii_case("true") => Some(true),
            Value::String(s) if s.eq_ignore_ascii_case("false") => Some(false),
            _ => None,
        };
        flag.map(Some)
            .ok_or_else(|| self.error(key, value, "true or false (or 1 / 0)"))
    }

    fn strings(&self, key: &str) -> Result<Vec<String>, AnnotationError> {
        match self.get(key) {
            None => Ok(Vec::new()),
            Some(Value::String(s)) => Ok(vec![s.clone()]),
            Some(Value::Array(items)) => items
                .iter()
                .enumerate()
                .map(|(i, item)| match item {
                    Value::String(s) if nonfinite_token(item).is_none() => Ok(s.clone()),
                    other => Err(self.error(&format!("{key}.{i}"), other, "a string")),
                })
                .collect(),
            Some(other) => Err(self.error(key, other, "a list of strings")),
        }
    }

    fn non_negative(&self, key: &str) -> Result<Option<f64>, AnnotationError> {
        match self.get(key) {
            None => Ok(None),
            Some(value) => number(value)
                .filter(|v| *v >= 0.0)
                .map(Some)
                .ok_or_else(|| self.error(key, value, "a finite number >= 0")),
        }
    }

    fn index(&self, key: &str) -> Result<Option<u32>, AnnotationError> {
        match self.get(key) {
            None => Ok(None),
            Some(value) => number(value)
                .filter(|v| *v >= 0.0 && v.fract() == 0.0 && *v <= f64::from(u32::MAX))
                // Checked just above: a whole number in u32's range.
                .map(|v| Some(v as u32))
                .ok_or_else(|| self.error(key, value, "a whole number >= 0")),
        }
    }

    fn bbox(&self) -> Result<Option<BboxExtents>, AnnotationError> {
        if let Some(bbox) = self.get("bbox") {
            let Some(parts) = bbox.as_object() else {
                return Err(self.error(
                    "bbox",
                    bbox,
                    "an object: {\"x\", \"y\", \"z\"}, {\"size\": ...} or {\"min\", \"max\"}",
                ));
            };
            let inner = Fields {
                uid: self.uid,
                fields: parts,
            };
            let extents = if parts.contains_key("x") {
                inner.vector_of_object(parts, "bbox")?
            } else if let Some(size) = inner.get("size") {
                inner.vector(size, "bbox.size")?
            } else if inner.get("min").is_some() || inner.get("max").is_some() {
                inner.extents_between("min", "max", "bbox.")?
            } else {
                return Err(AnnotationError::field(
                    self.uid,
                    "bbox",
                    format!(
                        "has none of x/y/z, size, min/max (keys: {})",
                        key_list(parts)
                    ),
                    "{\"x\", \"y\", \"z\"}, {\"size\": ...} or {\"min\", \"max\"}",
                ));
            };
            return self.checked_extents(extents, "bbox").map(Some);
        }
        if self.get("min_point").is_some() || self.get("max_point").is_some() {
            let extents = self.extents_between("min_point", "max_point", "")?;
            return self.checked_extents(extents, "max_point").map(Some);
        }
        Ok(None)
    }

    /// `max - min` of two corners `<prefix><min>` and `<prefix><max>` of these fields.
    fn extents_between(
        &self,
        min: &str,
        max: &str,
        prefix: &str,
    ) -> Result<[f64; 3], AnnotationError> {
        let corner = |key: &str| {
            let path = format!("{prefix}{key}");
            match self.get(key) {
                Some(value) => self.vector(value, &path),
                None => Err(AnnotationError::field(
                    self.uid,
                    &path,
                    "is missing",
                    "both corners of the box",
                )),
            }
        };
        let (lo, hi) = (corner(min)?, corner(max)?);
        Ok([hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]])
    }

    /// Three numbers from an `{"x", "y", "z"}` object or an `[x, y, z]` array.
    fn vector(&self, value: &Value, path: &str) -> Result<[f64; 3], AnnotationError> {
        match value {
            Value::Object(parts) => self.vector_of_object(parts, path),
            Value::Array(items) if items.len() == 3 => {
                let mut out = [0.0; 3];
                for (i, item) in items.iter().enumerate() {
                    out[i] = number(item).ok_or_else(|| {
                        self.error(&format!("{path}.{i}"), item, "a finite number")
                    })?;
                }
                Ok(out)
            }
            other => Err(self.error(path, other, "{\"x\", \"y\", \"z\"} or [x, y, z]")),
        }
    }

    fn vector_of_object(
        &self,
        parts: &Map<String, Value>,
        path: &str,
    ) -> Result<[f64; 3], AnnotationError> {
        let mut out = [0.0; 3];
        for (slot, axis) in out.iter_mut().zip(["x", "y", "z"]) {
            let field = format!("{path}.{axis}");
            let value = parts.get(axis).ok_or_else(|| {
                AnnotationError::field(self.uid, &field, "is missing", "a finite number")
            })?;
            *slot = number(value).ok_or_else(|| self.error(&field, value, "a finite number"))?;
        }
        Ok(out)
    }

    fn checked_extents(
        &self,
        extents: [f64; 3],
        field: &str,
    ) -> Result<BboxExtents, AnnotationError> {
        if let Some(axis) = extents.iter().position(|e| !(e.is_finite() && *e >= 0.0)) {
            return Err(AnnotationError::field(
                self.uid,
                field,
                format!(
                    "gives a negative extent {} along {}",
                    extents[axis],
                    ["x", "y", "z"][axis]
                ),
                "max >= min on every axis",
            ));
        }
        Ok(BboxExtents {
            x: extents[0],
            y: extents[1],
            z: extents[2],
        })
    }
}

/// A finite number, or `None` (also for the `NaN` / `Infinity` stand-ins of the lenient
/// reader).
fn number(value: &Value) -> Option<f64> {
    value.as_f64().filter(|v| v.is_finite())
}

/// Like [`describe`], but names the non-finite stand-ins as what the file said.
fn describe_value(value: &Value) -> String {
    match nonfinite_token(value) {
        Some(token) => format!("is {token}"),
        None => describe(value),
    }
}

fn key_list(parts: &Map<String, Value>) -> String {
    parts
        .keys()
        .map(String::as_str)
        .collect::<Vec<_>>()
        .join(", ")
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_abs_diff_eq;

    fn one(entry: &str) -> Result<AssetAnnotation, AnnotationError> {
        let text = format!("{{\"uid_1\": {entry}}}");
        Annotations::parse(&text).map(|a| a.get("uid_1").cloned().expect("uid_1 is there"))
    }

    fn error_text(entry: &str) -> String {
        match one(entry) {
            Ok(a) => panic!("expected an error, got {a:?}"),
            Err(e) => e.to_string(),
        }
    }

    fn extents(a: &AssetAnnotation) -> [f64; 3] {
        let b = a.bbox.expect("a bbox");
        [b.x, b.y, b.z]
    }

    #[test]
    fn an_empty_annotation_has_the_defaults() {
        let a = one("{}").expect("parses");
        assert_eq!(a, AssetAnnotation::default());
        assert!(a.on_table);
        assert_eq!(a.rejection(), None);
    }

    #[test]
    fn every_field_is_read() {
        let a = one(
            r#"{"category": "mug", "description": "a white mug", "onTable": true,
                "mark_deletion": false, "is_composite": false, "isContainer": true,
                "frontView": 2, "materials": ["ceramic", "glaze"], "mass": 0.35,
                "bbox": {"x": 0.1, "y": 0.12, "z": 0.08}, "thumbnail": "ignored"}"#,
        )
        .expect("parses");
        assert_eq!(a.category.as_deref(), Some("mug"));
        assert_eq!(a.description.as_deref(), Some("a white mug"));
        assert_eq!(a.is_container, Some(true));
        assert_eq!(a.front_view, Some(2));
        assert_eq!(a.materials, ["ceramic", "glaze"]);
        assert_eq!(a.mass_kg, Some(0.35));
        assert_eq!(extents(&a), [0.1, 0.12, 0.08]);
        assert_eq!(a.bbox.expect("bbox").size_table_frame(), [0.1, 0.08, 0.12]);
    }

    #[test]
    fn bbox_as_size() {
        let a = one(r#"{"bbox": {"size": {"x": 2, "y": 3, "z": 4}}}"#).expect("parses");
        assert_eq!(extents(&a), [2.0, 3.0, 4.0]);
        let a = one(r#"{"bbox": {"size": [2, 3, 4]}}"#).expect("parses");
        assert_eq!(extents(&a), [2.0, 3.0, 4.0]);
    }

    #[test]
    fn bbox_as_min_max() {
        let a = one(
            r#"{"bbox": {"min": {"x": -1, "y": 0, "z": -0.5}, "max": {"x": 1, "y": 2.5, "z": 0.5}}}"#,
        )
        .expect("parses");
        assert_eq!(extents(&a), [2.0, 2.5, 1.0]);
    }

    #[test]
    fn bbox_as_min_point_max_point() {
        let a = one(r#"{"min_point": [-0.1, 0.0, -0.2], "max_point": [0.1, 0.3, 0.2]}"#)
            .expect("parses");
        let [x, y, z] = extents(&a);
        assert_abs_diff_eq!(x, 0.2, epsilon = 1e-12);
        assert_abs_diff_eq!(y, 0.3, epsilon = 1e-12);
        assert_abs_diff_eq!(z, 0.4, epsilon = 1e-12);
    }

    #[test]
    fn receptacle_is_a_synonym_and_is_container_wins() {
        assert_eq!(
            one(r#"{"receptacle": true}"#).expect("parses").is_container,
            Some(true)
        );
        assert_eq!(
            one(r#"{"receptacle": true, "isContainer": false}"#)
                .expect("parses")
                .is_container,
            Some(false)
        );
        assert_eq!(
            one(r#"{"isContainer": null}"#)
                .expect("parses")
                .is_container,
            None
        );
    }

    #[test]
    fn python_booleans_are_accepted() {
        let a = one(r#"{"onTable": 0, "mark_deletion": "True", "is_composite": "false"}"#)
            .expect("parses");
        assert!(!a.on_table);
        assert!(a.mark_deletion);
        assert!(!a.is_composite);
        assert_eq!(a.rejection(), Some("onTable false"));
    }

    #[test]
    fn the_retrieval_filter_reasons() {
        let mut a = AssetAnnotation {
            mark_deletion: true,
            ..AssetAnnotation::default()
        };
        assert_eq!(a.rejection(), Some("mark_deletion"));
        a.mark_deletion = false;
        a.is_composite = true;
        assert_eq!(a.rejection(), Some("is_composite"));
    }

    #[test]
    fn errors_name_the_uid_and_the_field() {
        assert_eq!(
            error_text(r#"{"isContainer": "yes"}"#),
            "$.uid_1.isContainer: is a string \"yes\" (expected true or false (or 1 / 0))"
        );
        assert_eq!(
            error_text(r#"{"mass": -2}"#),
            "$.uid_1.mass: is the number -2 (expected a finite number >= 0)"
        );
        assert_eq!(
            error_text(r#"{"mass": NaN}"#),
            "$.uid_1.mass: is NaN (expected a finite number >= 0)"
        );
        assert_eq!(
            error_text(r#"{"bbox": {"min": {"x": 0, "y": 0, "z": 0}}}"#),
            "$.uid_1.bbox.max: is missing (expected both corners of the box)"
        );
        assert_eq!(
            error_text(r#"{"bbox": {"x": 1, "y": 2}}"#),
            "$.uid_1.bbox.z: is missing (expected a finite number)"
        );
        assert_eq!(
            error_text(r#"{"min_point": [1, 0, 0], "max_point": [0, 1, 1]}"#),
            "$.uid_1.max_point: gives a negative extent -1 along x (expected max >= min on every axis)"
        );
        assert_eq!(
            error_text(r#"{"bbox": {"width": 1}}"#),
            "$.uid_1.bbox: has none of x/y/z, size, min/max (keys: width) (expected {\"x\", \"y\", \"z\"}, {\"size\": ...} or {\"min\", \"max\"})"
        );
        assert_eq!(
            error_text(r#"{"materials": ["wood", 3]}"#),
            "$.uid_1.materials[1]: is the number 3 (expected a string)"
        );
        assert_eq!(
            error_text(r#"{"frontView": 1.5}"#),
            "$.uid_1.frontView: is the number 1.5 (expected a whole number >= 0)"
        );
        assert_eq!(
            error_text("[]"),
            "$.uid_1: is an array of 0 items (expected an annotation object)"
        );
    }

    #[test]
    fn uids_that_are_not_identifiers_are_quoted() {
        let e = Annotations::parse(r#"{"a b/c": {"mass": "heavy"}}"#).expect_err("bad mass");
        assert!(e.to_string().starts_with("$[\"a b/c\"].mass: "), "{e}");
    }

    #[test]
    fn the_document_must_be_an_object() {
        let e = Annotations::parse("[1, 2]").expect_err("an array");
        assert!(e.to_string().starts_with("$: is an array"), "{e}");
        let e = Annotations::parse("{").expect_err("syntax");
        assert!(e.to_string().starts_with("$: is not valid JSON"), "{e}");
    }

    #[test]
    fn read_prefixes_the_path() {
        let dir = tempfile::tempdir().expect("temp dir");
        let path = dir.path().join("annotations.json");
        std::fs::write(&path, r#"{"u": {"onTable": "maybe"}}"#).expect("write");
        let e = Annotations::read(&path).expect_err("bad onTable");
        assert!(
            e.to_string()
                .starts_with(&format!("{}: $.u.onTable: ", path.display())),
            "{e}"
        );
        std::fs::write(&path, r#"{"u": {"isContainer": 1}, "v": {}}"#).expect("write");
        let a = Annotations::read(&path).expect("reads");
        assert_eq!(a.len(), 2);
        assert_eq!(a.get("u").and_then(|a| a.is_container), Some(true));
        assert_eq!(a.iter().map(|(uid, _)| uid).collect::<Vec<_>>(), ["u", "v"]);
        let missing = Annotations::read(&dir.path().join("absent.json")).expect_err("absent");
        assert!(
            missing.to_string().contains("absent.json: cannot read"),
            "{missing}"
        );
    }
}
