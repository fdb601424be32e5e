//! The rule-based scene graph (SPEC 5.7): nodes `is at` / `face to`, edges `in`, `above` and
//! the four horizontal relations, and the optional `are equally spaced along`, exactly as
//! `SCENE_GRAPH.md` states them (the rules were fitted to the authors' published records).
//!
//! The extraction is a pure function of a layout and one container flag per object:
//!
//! ```
//! use mesa_stages::graph::{extract_graph, keyword_containers, GraphOptions, GraphScene, SceneObject};
//!
//! let scene = GraphScene {
//!     zone_cm: [0.0, 100.0, 0.0, 60.0],
//!     objects: vec![
//!         SceneObject::new("bowl_0", [30.0, 30.0, 4.0], [20.0, 20.0, 8.0], 0.0),
//!         SceneObject::new("apple_0", [30.0, 30.0, 5.0], [6.0, 6.0, 6.0], 0.0),
//!         SceneObject::new("mug_0", [60.0, 30.0, 5.0], [8.0, 8.0, 10.0], 90.0),
//!     ],
//! };
//! let options = GraphOptions::default();
//! let containers = keyword_containers(&scene, &options);
//! let graph = extract_graph(&scene, &containers, &options)?;
//! assert_eq!(
//!     graph.triplet_lines(),
//!     [
//!         "(bowl_0, is at, center)",
//!         "(bowl_0, face to, front)",
//!         "(apple_0, is at, center)",
//!         "(apple_0, face to, front)",
//!         "(mug_0, is at, center)",
//!         "(mug_0, face to, right)",
//!         "(apple_0, in, bowl_0)",
//!         "(bowl_0, left of, mug_0)",
//!     ]
//! );
//! # Ok::<(), mesa_stages::graph::GraphError>(())
//! ```
//!
//! All lengths are in the layout's units (cm) in the table frame (SPEC section 2); "layout
//! order" is the order of `objects` in the layout file. Geometry is computed in `f64` relative
//! to the subject's centre, so that translating a whole scene together with its zone changes
//! no decision.
//!
//! ## Cost
//!
//! The rules are stated over all pairs, but `in` and `above` need the two footprints to
//! overlap and a horizontal pair needs the object among the subject's 5 nearest: above
//! `ALL_PAIRS_UP_TO_OBJECTS` objects, a uniform grid over the footprints' boxes (`BoxGrid`)
//! and one over the centres (`CentreGrid`, searched ring by ring outward) test only pairs
//! that can be related, so a table-like layout of n objects costs about n log n. A table's
//! dozen or two objects are cheaper to test pair by pair, without building grids: each
//! subject keeps its 5 nearest by insertion, and the distance limit is decided on squared
//! distances (`Within`). A footprint's corners (a sine and a cosine) are made only for an
//! object whose circle around its footprint meets another's in a pair the rules test for `in`
//! or `above`, and two footprints are clipped only when the boxes around them overlap by the
//! rule's threshold. The graph borrows the scene's names, so it allocates no strings; a
//! table's working lists are kept from one scene to the next on a thread (`Scratch`); its
//! text is written in one buffer by fixed-width copies (`crate::pieces`). A word-for-word
//! version of the rules is kept as the test oracle (property tests check both searches give
//! its output). `are equally spaced along` (off by default) is about triples: its output
//! alone can grow with n², and its search stays quadratic in n.

use std::cell::{OnceCell, RefCell};
use std::collections::BTreeMap;
use std::fmt;

use mesa_schemas::artifacts::{GraphArtifact, GraphEdge, GraphNode, GraphSpacing, GRAPH_SCHEMA};
use mesa_schemas::convert::{category_of_instance, yaw_deg_of, TILT_EPSILON_DEG};
use mesa_schemas::graph_json::{write_graph_json, EdgeRef, NodeRef, SpacingRef};
use mesa_schemas::layout_file::AnyLayout;
use mesa_schemas::rotation::tilt_deg_from_quat_xyzw;
use mesa_schemas::{DatasetLayout, LlmLayout, Problem};
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};
use thiserror::Error;

use crate::annotations::Annotations;
use crate::pieces::{Fixed, Text};

// ---------------------------------------------------------------------------------------------
// Thresholds (SCENE_GRAPH.md). They are fixed: the published records were made with them.

/// `is at`: the x band is `left` when the zone fraction fx is below this.
pub const LEFT_BAND_BELOW: f64 = 0.20;
/// `is at`: the x band is `right` when fx is above this.
pub const RIGHT_BAND_ABOVE: f64 = 0.80;
/// `is at`: the y band is `front` when the zone fraction fy is below this.
pub const FRONT_BAND_BELOW: f64 = 0.15;
/// `is at`: the y band is `back` when fy is above this.
pub const BACK_BAND_ABOVE: f64 = 0.85;
/// `in`: the least share of the subject's footprint inside the container's footprint.
pub const CONTAINMENT_MIN_FOOTPRINT_SHARE: f64 = 0.9;
/// `in`: the least vertical overlap, as a share of the smaller height.
pub const CONTAINMENT_MIN_Z_SHARE: f64 = 0.5;
/// `above`: the subject's bottom may sink this far (cm) below the other's top.
pub const ABOVE_Z_TOLERANCE_CM: f64 = 1.0;
/// `above`: the least share of the subject's footprint over the other's footprint.
pub const ABOVE_MIN_FOOTPRINT_SHARE: f64 = 0.5;
/// Horizontal relations: an object is raised when its bottom is above this height (cm).
pub const RAISED_Z_MIN_CM: f64 = 0.5;
/// Horizontal relations: neighbours farther (3-D centre distance) than this share of the
/// zone's larger side are dropped.
pub const NEIGHBOUR_MAX_DISTANCE_SHARE: f64 = 0.4;
/// Horizontal relations: the number of nearest neighbours each subject considers.
pub const NEIGHBOURS_PER_SUBJECT: usize = 5;
/// `are equally spaced along`: the gaps may differ by this share of the larger gap.
pub const SPACING_MAX_GAP_DIFFERENCE_SHARE: f64 = 0.10;
/// `are equally spaced along`: the most the three may spread across the axis (cm).
pub const SPACING_MAX_SPREAD_CM: f64 = 2.0;

/// The default container keywords: a category is a container when it is, or ends with, one of
/// them (a tray is not a container).
pub const DEFAULT_CONTAINER_KEYWORDS: [&str; 16] = [
    "bowl",
    "basket",
    "box",
    "bin",
    "bucket",
    "cup",
    "mug",
    "pot",
    "pan",
    "jar",
    "vase",
    "holder",
    "container",
    "caddy",
    "crate",
    "organizer",
];

// ---------------------------------------------------------------------------------------------
// Configuration and options.

/// The `[graph]` section of `mesa.toml`.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(default, deny_unknown_fields)]
pub struct GraphConfig {
    /// Categories that count as containers for objects whose asset has no annotation (or whose
    /// annotation says nothing): a category (the instance name without its `_<n>` suffix) is a
    /// container when it is, or ends with, one of these words, case-insensitively. Asset
    /// annotations (`isContainer`, or objathor's `receptacle`) take precedence.
    pub container_keywords: Vec<String>,
    /// Also write the optional relation `(a, b, c, are equally spaced along, x|y)`, which the
    /// published records never contain.
    pub equally_spaced: bool,
}

impl Default for GraphConfig {
    fn default() -> Self {
        Self {
            container_keywords: DEFAULT_CONTAINER_KEYWORDS
                .iter()
                .map(|k| (*k).to_owned())
                .collect(),
            equally_spaced: false,
        }
    }
}

/// Options of [`extract_graph`].
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct GraphOptions {
    /// Lower-case container keywords for [`keyword_containers`].
    pub container_keywords: Vec<String>,
    /// Whether to emit `are equally spaced along` triples.
    pub equally_spaced: bool,
}

impl Default for GraphOptions {
    fn default() -> Self {
        Self::from(&GraphConfig::default())
    }
}

impl From<&GraphConfig> for GraphOptions {
    fn from(config: &GraphConfig) -> Self {
        Self {
            container_keywords: Vec::new(),
            equally_spaced: config.equally_spaced,
        }
        .with_container_keywords(config.container_keywords.iter().map(String::as_str))
    }
}

impl GraphOptions {
    /// Replaces the container keywords (trimmed, lower-cased, empty ones dropped).
    pub fn with_container_keywords<'a>(
        mut self,
        keywords: impl IntoIterator<Item = &'a str>,
    ) -> Self {
        self.container_keywords = keywords
            .into_iter()
            .map(|k| k.trim().to_lowercase())
            .filter(|k| !k.is_empty())
            .collect();
        self
    }

    /// Turns the optional `are equally spaced along` relation on or off.
    pub fn with_equally_spaced(mut self, equally_spaced: bool) -> Self {
        self.equally_spaced = equally_spaced;
        self
    }
}

/// Whether an instance is a container by the keyword rule: its category (the name without the
/// `_<n>` suffix) is, or ends with, one of the keywords, case-insensitively. An empty keyword
/// matches nothing.
pub fn is_keyword_container(instance: &str, keywords: &[String]) -> bool {
    let category = category_of_instance(instance).to_lowercase();
    keywords
        .iter()
        .any(|k| !k.is_empty() && category.ends_with(k.to_lowercase().as_str()))
}

/// The keyword rule's container flag of every object, in layout order.
pub fn keyword_containers(scene: &GraphScene, options: &GraphOptions) -> Vec<bool> {
    scene
        .objects
        .iter()
        .map(|o| is_keyword_container(&o.instance, &options.container_keywords))
        .collect()
}

/// Container flags of a scene's objects, with the objects the keyword rule had to decide.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ContainerFlags {
    /// One flag per object, in layout order.
    pub flags: Vec<bool>,
    /// The objects without a usable annotation, each with why (`mug_0 (no retrieved_uid)`);
    /// the keyword rule decided for them.
    pub by_keyword: Vec<String>,
}

/// The container flag of every object: the asset annotation's `isContainer` (or objathor
/// `receptacle`) of its `retrieved_uid` when there is one, else the keyword rule (SCENE_GRAPH.md).
/// `retrieved_uids` is in layout order (empty strings for objects without an asset).
pub fn annotated_containers(
    scene: &GraphScene,
    retrieved_uids: &[String],
    annotations: Option<&Annotations>,
    options: &GraphOptions,
) -> ContainerFlags {
    let mut by_keyword = Vec::new();
    let flags = scene
        .objects
        .iter()
        .enumerate()
        .map(|(i, object)| {
            let uid = retrieved_uids.get(i).map(String::as_str).unwrap_or("");
            let why = match annotations {
                _ if uid.is_empty() => "no retrieved_uid".to_owned(),
                None => "no annotations file".to_owned(),
                Some(annotations) => match annotations.get(uid) {
                    None => format!("asset {uid} is not annotated"),
                    Some(annotation) => match annotation.is_container {
                        Some(flag) => return flag,
                        None => format!("the annotation of {uid} has no isContainer"),
                    },
                },
            };
            by_keyword.push(format!("{} ({why})", object.instance));
            is_keyword_container(&object.instance, &options.container_keywords)
        })
        .collect();
    ContainerFlags { flags, by_keyword }
}

// ---------------------------------------------------------------------------------------------
// Input.

/// What the graph needs of one object.
#[derive(Debug, Clone, PartialEq)]
pub struct SceneObject {
    /// Instance name, like `mug_0`.
    pub instance: String,
    /// Centre of the bounding box [x, y, z] in cm, table frame.
    pub position_cm: [f64; 3],
    /// [width, depth, height] in cm before rotation.
    pub size_cm: [f64; 3],
    /// Yaw in degrees, counter-clockwise seen from above; 0 faces the observer (-y).
    pub yaw_deg: f64,
}

impl SceneObject {
    /// An object from its parts.
    pub fn new(
        instance: impl Into<String>,
        position_cm: [f64; 3],
        size_cm: [f64; 3],
        yaw_deg: f64,
    ) -> Self {
        Self {
            instance: instance.into(),
            position_cm,
            size_cm,
            yaw_deg,
        }
    }
}

/// A layout as the graph sees it: the placement zone and the objects in layout order.
#[derive(Debug, Clone, PartialEq)]
pub struct GraphScene {
    /// The item placement zone [x_min, x_max, y_min, y_max] in cm.
    pub zone_cm: [f64; 4],
    /// The objects, in the order of the layout file.
    pub objects: Vec<SceneObject>,
}

impl GraphScene {
    /// The scene of an LLM layout (objects in the file's order).
    pub fn from_llm(layout: &LlmLayout) -> Self {
        Self {
            zone_cm: layout.zone_cm.0,
            objects: layout
                .objects
                .iter()
                .map(|o| {
                    SceneObject::new(&o.instance, o.position_cm.0, o.size_cm.0, o.z_rotation_deg)
                })
                .collect(),
        }
    }

    /// The scene of a dataset layout, objects in the file's order (not re-sorted, unlike
    /// [`mesa_schemas::convert::llm_from_dataset`]). A tilted object contributes the yaw of
    /// its rotation, as the LLM form would keep it.
    pub fn from_dataset(layout: &DatasetLayout) -> Self {
        Self {
            zone_cm: layout.zone_cm.0,
            objects: layout
                .objects
                .iter()
                .map(|o| SceneObject::new(&o.instance, o.position_cm.0, o.size_cm.0, yaw_deg_of(o)))
                .collect(),
        }
    }

    /// Checks what the rules need: a finite, non-empty zone; non-empty unique instance names;
    /// finite positions and yaws; finite positive sizes.
    pub fn check(&self) -> Result<(), GraphError> {
        let [x_min, x_max, y_min, y_max] = self.zone_cm;
        if self.zone_cm.iter().any(|v| !v.is_finite()) {
            return Err(GraphError::Zone {
                problem: format!("has a non-finite bound [{x_min}, {x_max}, {y_min}, {y_max}]"),
            });
        }
        // SCENE_GRAPH.md gives a fraction of 0.5 when W or D is 0 (kept in `zone_fraction`);
        // issue 8 makes an empty zone an error instead, so that rule is never reached here.
        if x_max <= x_min || y_max <= y_min {
            return Err(GraphError::Zone {
                problem: format!("is empty [{x_min}, {x_max}, {y_min}, {y_max}]"),
            });
        }
        // Whether any name may repeat, by comparing short summaries of them (see
        // `name_summary`); only then are first indices kept (the map costs more than the
        // rest of the checks).
        let repeats = summaries_repeat(&self.objects);
        let mut first_index: BTreeMap<&str, usize> = BTreeMap::new();
        for (index, object) in self.objects.iter().enumerate() {
            // `trim().is_empty()`, deciding at the first character that is not white space.
            if object.instance.chars().all(char::is_whitespace) {
                return Err(GraphError::EmptyInstance { index });
            }
            if repeats {
                if let Some(&first) = first_index.get(object.instance.as_str()) {
                    return Err(GraphError::DuplicateInstance {
                        index,
                        instance: object.instance.clone(),
                        first,
                    });
                }
                first_index.insert(&object.instance, index);
            }
            let number = |field: String, value: f64, expected: &'static str| GraphError::Number {
                index,
                instance: object.instance.clone(),
                field,
                value,
                expected,
            };
            for (axis, value) in object.position_cm.iter().enumerate() {
                if !value.is_finite() {
                    return Err(number(
                        format!("position[{axis}]"),
                        *value,
                        "a finite number (cm)",
                    ));
                }
            }
            for (axis, value) in object.size_cm.iter().enumerate() {
                if !(value.is_finite() && *value > 0.0) {
                    return Err(number(
                        format!("size[{axis}]"),
                        *value,
                        "a finite number > 0 (cm)",
                    ));
                }
            }
            if !object.yaw_deg.is_finite() {
                return Err(number(
                    "z_rotation".to_owned(),
                    object.yaw_deg,
                    "a finite number (degrees)",
                ));
            }
        }
        Ok(())
    }
}

/// Whether two of the objects' names have the same [`NameSummary`] (which two names that
/// are equal do). A table's summaries are compared pair by pair on the stack, without a
/// branch per pair (a sort's comparisons are a coin toss for the branch predictor); more
/// are sorted.
fn summaries_repeat(objects: &[SceneObject]) -> bool {
    let mut on_stack = [0; ALL_PAIRS_UP_TO_OBJECTS];
    if objects.len() <= on_stack.len() {
        let summaries = &mut on_stack[..objects.len()];
        for (summary, object) in summaries.iter_mut().zip(objects) {
            *summary = name_summary(&object.instance);
        }
        let mut repeats = false;
        for (i, &a) in summaries.iter().enumerate() {
            for &b in &summaries[i + 1..] {
                repeats |= a == b;
            }
        }
        repeats
    } else {
        let mut sorted: Vec<NameSummary> =
            objects.iter().map(|o| name_summary(&o.instance)).collect();
        sorted.sort_unstable();
        sorted.windows(2).any(|pair| pair[0] == pair[1])
    }
}

/// A 64-bit summary of a name: equal names have equal summaries. It mixes the name's
/// length with its first and last 8 bytes, so different names rarely share one (a shared one
/// only sends the check to the exact search by name). A summary compares in one instruction
/// where a string comparison calls `memcmp`.
type NameSummary = u64;

/// The [`NameSummary`] of `name`.
fn name_summary(name: &str) -> NameSummary {
    let bytes = name.as_bytes();
    let (head, tail) = match (bytes.first_chunk::<8>(), bytes.last_chunk::<8>()) {
        (Some(head), Some(tail)) => (u64::from_le_bytes(*head), u64::from_le_bytes(*tail)),
        // Shorter than 8 bytes: the whole name, byte by byte (no call to `memcpy`).
        _ => {
            let word = bytes
                .iter()
                .rev()
                .fold(0u64, |word, &byte| word << 8 | u64::from(byte));
            (word, 0)
        }
    };
    // Multiply-xorshift rounds (the constants of splitmix64).
    let mix = |h: u64| {
        let h = (h ^ (h >> 31)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        (h ^ (h >> 29)).wrapping_mul(0x94d0_49bb_1331_11eb)
    };
    mix(mix(mix(bytes.len() as u64 ^ head) ^ tail))
}

/// Why a layout has no scene graph.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum GraphError {
    /// The placement zone is not a finite, non-empty rectangle.
    #[error(
        "item_placement_zone: {problem} (expected finite [x_min, x_max, y_min, y_max] with \
         x_min < x_max and y_min < y_max)"
    )]
    Zone {
        /// What is wrong with it.
        problem: String,
    },
    /// An object has an empty instance name.
    #[error("objects[{index}].instance: is empty (expected a name like `mug_0`)")]
    EmptyInstance {
        /// Index of the object in the layout.
        index: usize,
    },
    /// Two objects share an instance name.
    #[error(
        "objects[{index}].instance: duplicate instance \"{instance}\" (also objects[{first}]) \
         (expected unique instance names; rename one, like `{instance}_dup`)"
    )]
    DuplicateInstance {
        /// Index of the second object.
        index: usize,
        /// The shared name.
        instance: String,
        /// Index of the first object with that name.
        first: usize,
    },
    /// A number of an object is not usable.
    #[error("objects[{index}].{field} ({instance}): is {value} (expected {expected})")]
    Number {
        /// Index of the object in the layout.
        index: usize,
        /// Its instance name.
        instance: String,
        /// The field, like `size[2]`.
        field: String,
        /// The value found.
        value: f64,
        /// What the rules need.
        expected: &'static str,
    },
    /// The container flags do not match the objects.
    #[error("container flags: {flags} flags for {objects} objects (expected one per object, in layout order)")]
    ContainerFlags {
        /// Number of flags given.
        flags: usize,
        /// Number of objects.
        objects: usize,
    },
}

// ---------------------------------------------------------------------------------------------
// Reading a layout file of any form.

pub use mesa_schemas::layout_file::{layout_form_of, LayoutForm};

/// A layout file read for the graph.
#[derive(Debug, Clone, PartialEq)]
pub struct LoadedLayout {
    /// The scene, objects in the file's order.
    pub scene: GraphScene,
    /// What the file was recognised as.
    pub form: LayoutForm,
    /// The `retrieved_uid` of each object (dataset layouts only; empty strings otherwise).
    pub retrieved_uids: Vec<String>,
    /// What the graph leaves out, one line per object (a tilted object counts by its yaw).
    pub warnings: Vec<String>,
}

/// Why a layout file could not be read for the graph: every problem, with its JSON path.
#[derive(Debug, Clone, PartialEq, Error)]
#[error("{}", render_problems(.problems))]
pub struct LayoutReadError {
    /// The problems, each `<json path>: <problem> (expected ...)`.
    pub problems: Vec<Problem>,
}

fn render_problems(problems: &[Problem]) -> String {
    problems
        .iter()
        .map(ToString::to_string)
        .collect::<Vec<_>>()
        .join("; ")
}

/// Reads the text of a dataset layout, an LLM layout or a published record (recognised by
/// shape, see [`layout_form_of`]), validates it, and returns the scene with objects in the
/// file's order. Problems name the JSON path and, for objects, the instance.
pub fn read_layout_text(text: &str) -> Result<LoadedLayout, LayoutReadError> {
    let read = mesa_schemas::layout_file::read_layout_text(text)
        .map_err(|problems| LayoutReadError { problems })?;
    Ok(match read.layout {
        AnyLayout::Llm(layout) => LoadedLayout {
            retrieved_uids: vec![String::new(); layout.objects.len()],
            scene: GraphScene::from_llm(&layout),
            form: read.form,
            warnings: Vec::new(),
        },
        AnyLayout::Dataset(layout) => {
            let warnings = layout
                .objects
                .iter()
                .filter_map(|o| {
                    let tilt_deg = tilt_deg_from_quat_xyzw(o.rotation.0);
                    (tilt_deg > TILT_EPSILON_DEG).then(|| {
                        format!(
                            "{}: rotation is tilted by {tilt_deg:.3}°; the graph uses its \
                             footprint turned by its yaw {:.3}° only",
                            o.instance,
                            yaw_deg_of(o)
                        )
                    })
                })
                .collect();
            LoadedLayout {
                retrieved_uids: layout
                    .objects
                    .iter()
                    .map(|o| o.retrieved_uid.clone())
                    .collect(),
                scene: GraphScene::from_dataset(&layout),
                form: read.form,
                warnings,
            }
        }
    })
}

// ---------------------------------------------------------------------------------------------
// Output.

/// The x band of a position in the zone.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum XBand {
    /// fx < 0.20.
    Left,
    /// 0.20 ≤ fx ≤ 0.80.
    Middle,
    /// fx > 0.80.
    Right,
}

/// The y band of a position in the zone.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum YBand {
    /// fy < 0.15 (near the observer).
    Front,
    /// 0.15 ≤ fy ≤ 0.85.
    Middle,
    /// fy > 0.85.
    Back,
}

/// A cell of the nine-grid: the value of `is at`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct GridCell {
    /// Front, middle or back.
    pub y: YBand,
    /// Left, middle or right.
    pub x: XBand,
}

impl GridCell {
    /// The cell of zone fractions (fx, fy).
    pub fn from_fractions(fx: f64, fy: f64) -> Self {
        let x = if fx < LEFT_BAND_BELOW {
            XBand::Left
        } else if fx > RIGHT_BAND_ABOVE {
            XBand::Right
        } else {
            XBand::Middle
        };
        let y = if fy < FRONT_BAND_BELOW {
            YBand::Front
        } else if fy > BACK_BAND_ABOVE {
            YBand::Back
        } else {
            YBand::Middle
        };
        Self { y, x }
    }

    /// What follows the subject in its `is at` line: `, is at, <label>)`.
    fn is_at_tail(self) -> &'static str {
        let end = self.is_at_line_end().text();
        &end[..end.len() - 1]
    }

    /// What follows the subject in its line of `graph.txt`: `, is at, <label>)\n`.
    fn is_at_line_end(self) -> &'static Fixed {
        const ENDS: [Fixed; 9] = [
            Fixed::new(", is at, front_left)\n"),
            Fixed::new(", is at, front_middle)\n"),
            Fixed::new(", is at, front_right)\n"),
            Fixed::new(", is at, middle_left)\n"),
            Fixed::new(", is at, center)\n"),
            Fixed::new(", is at, middle_right)\n"),
            Fixed::new(", is at, back_left)\n"),
            Fixed::new(", is at, back_middle)\n"),
            Fixed::new(", is at, back_right)\n"),
        ];
        let row = match self.y {
            YBand::Front => 0,
            YBand::Middle => 3,
            YBand::Back => 6,
        };
        let column = match self.x {
            XBand::Left => 0,
            XBand::Middle => 1,
            XBand::Right => 2,
        };
        &ENDS[row + column]
    }

    /// `<y band>_<x band>`, or `center` for the middle cell.
    pub fn label(self) -> &'static str {
        match (self.y, self.x) {
            (YBand::Front, XBand::Left) => "front_left",
            (YBand::Front, XBand::Middle) => "front_middle",
            (YBand::Front, XBand::Right) => "front_right",
            (YBand::Middle, XBand::Left) => "middle_left",
            (YBand::Middle, XBand::Middle) => "center",
            (YBand::Middle, XBand::Right) => "middle_right",
            (YBand::Back, XBand::Left) => "back_left",
            (YBand::Back, XBand::Middle) => "back_middle",
            (YBand::Back, XBand::Right) => "back_right",
        }
    }
}

impl fmt::Display for GridCell {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.label())
    }
}

/// The fraction of `value` across `[min, min + extent]`; 0.5 when the extent is 0.
pub fn zone_fraction(value: f64, min: f64, extent: f64) -> f64 {
    if extent == 0.0 {
        0.5
    } else {
        (value - min) / extent
    }
}

/// One of the eight directions of `face to`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Facing {
    /// Toward the observer (-y), yaw 0.
    Front,
    /// Yaw 45.
    FrontRight,
    /// Toward +x, yaw 90.
    Right,
    /// Yaw 135.
    BackRight,
    /// Toward +y, yaw 180.
    Back,
    /// Yaw -135.
    BackLeft,
    /// Toward -x, yaw -90.
    Left,
    /// Yaw -45.
    FrontLeft,
}

impl Facing {
    /// The eight directions, counter-clockwise from the front.
    pub const ALL: [Facing; 8] = [
        Facing::Front,
        Facing::FrontRight,
        Facing::Right,
        Facing::BackRight,
        Facing::Back,
        Facing::BackLeft,
        Facing::Left,
        Facing::FrontLeft,
    ];

    /// The sector of a yaw: 45° sectors centred on the directions.
    ///
    /// As `((a + 22.5) / 45).floor().rem_euclid(8)` with `a = (yaw + 180).rem_euclid(360) -
    /// 180`, to the bit, without a call to `fmod` or `floor` for the usual yaws: a yaw in
    /// [-180, 180) is already in the range `rem_euclid` returns, and `(a + 22.5) / 45` lies in
    /// [-3.5, 4.5], where the floor and the remainder are integer operations. A NaN yaw is
    /// `Front`, as before.
    pub fn from_yaw_deg(yaw_deg: f64) -> Self {
        let turned = yaw_deg + 180.0;
        let a = if (0.0..360.0).contains(&turned) {
            turned
        } else {
            turned.rem_euclid(360.0)
        } - 180.0;
        let sector = (a + 22.5) / 45.0;
        // The floor of `sector` (a NaN casts to 0, as `NaN as usize` did).
        let truncated = sector as i64;
        let floor = truncated - i64::from((truncated as f64) > sector);
        Self::ALL[floor.rem_euclid(8) as usize]
    }

    /// What follows the subject in its `face to` line: `, face to, <label>)`.
    fn face_to_tail(self) -> &'static str {
        let end = self.face_to_line_end().text();
        &end[..end.len() - 1]
    }

    /// What follows the subject in its line of `graph.txt`: `, face to, <label>)\n`.
    fn face_to_line_end(self) -> &'static Fixed {
        const ENDS: [Fixed; 8] = [
            Fixed::new(", face to, front)\n"),
            Fixed::new(", face to, front_right)\n"),
            Fixed::new(", face to, right)\n"),
            Fixed::new(", face to, back_right)\n"),
            Fixed::new(", face to, back)\n"),
            Fixed::new(", face to, back_left)\n"),
            Fixed::new(", face to, left)\n"),
            Fixed::new(", face to, front_left)\n"),
        ];
        &ENDS[self as usize]
    }

    /// The label, like `front_right`.
    pub fn label(self) -> &'static str {
        match self {
            Self::Front => "front",
            Self::FrontRight => "front_right",
            Self::Right => "right",
            Self::BackRight => "back_right",
            Self::Back => "back",
            Self::BackLeft => "back_left",
            Self::Left => "left",
            Self::FrontLeft => "front_left",
        }
    }
}

impl fmt::Display for Facing {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.label())
    }
}

/// A relation between two objects.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Relation {
    /// Containment.
    In,
    /// The subject rests over the object.
    Above,
    /// dx < 0 dominates.
    LeftOf,
    /// dx > 0 dominates.
    RightOf,
    /// dy ≤ 0 dominates (or ties).
    InFrontOf,
    /// dy > 0 dominates (or ties).
    Behind,
}

impl Relation {
    /// The relation as written in a triplet.
    pub fn label(self) -> &'static str {
        match self {
            Self::In => "in",
            Self::Above => "above",
            Self::LeftOf => "left of",
            Self::RightOf => "right of",
            Self::InFrontOf => "in front of",
            Self::Behind => "behind",
        }
    }

    /// What stands between the subject and the object in a line: `, <label>, `.
    fn between(self) -> &'static Fixed {
        const BETWEEN: [Fixed; 6] = [
            Fixed::new(", in, "),
            Fixed::new(", above, "),
            Fixed::new(", left of, "),
            Fixed::new(", right of, "),
            Fixed::new(", in front of, "),
            Fixed::new(", behind, "),
        ];
        &BETWEEN[self as usize]
    }

    /// The horizontal relation of a subject to an object from their centre offsets
    /// dx = x_s - x_o, dy = y_s - y_o: x decides only when |dx| > |dy|.
    pub fn horizontal(dx_cm: f64, dy_cm: f64) -> Self {
        if dx_cm.abs() > dy_cm.abs() {
            if dx_cm > 0.0 {
                Self::RightOf
            } else {
                Self::LeftOf
            }
        } else if dy_cm > 0.0 {
            Self::Behind
        } else {
            Self::InFrontOf
        }
    }
}

impl fmt::Display for Relation {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.label())
    }
}

/// The numbers that decided an edge.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Evidence {
    /// Why the subject is in the container.
    Containment {
        /// Share of the subject's footprint inside the container's.
        footprint_share: f64,
        /// Vertical overlap over the smaller height.
        z_share: f64,
        /// The subject's footprint area w·d in cm².
        subject_area_cm2: f64,
        /// The container's footprint area in cm².
        container_area_cm2: f64,
    },
    /// Why the subject is above the object.
    Support {
        /// Share of the subject's footprint over the object's.
        footprint_share: f64,
        /// The subject's bottom minus the object's top, in cm (≥ -1).
        z_gap_cm: f64,
    },
    /// Why the pair is related horizontally.
    Proximity {
        /// x_s - x_o in cm.
        dx_cm: f64,
        /// y_s - y_o in cm.
        dy_cm: f64,
        /// Centre distance in the plane, cm.
        distance_2d_cm: f64,
        /// Centre distance in space, cm.
        distance_3d_cm: f64,
        /// The distance limit 0.4·max(W, D), cm.
        max_distance_cm: f64,
        /// Position of the object among the subject's kept neighbours, from 1.
        rank: usize,
    },
}

impl Evidence {
    /// The numbers by name, as `graph.json` stores them.
    pub fn numbers(&self) -> BTreeMap<String, f64> {
        self.sorted_numbers()
            .map(|(k, v)| (k.to_owned(), v))
            .collect()
    }

    /// Each number with its name, the names in byte order (the order of [`Self::numbers`]'s
    /// map and of `graph.json`): what [`SceneGraph::to_json`] writes.
    pub fn sorted_numbers(&self) -> impl Iterator<Item = (&'static str, f64)> {
        let (items, len): ([(&'static str, f64); 6], usize) = match *self {
            Self::Containment {
                footprint_share,
                z_share,
                subject_area_cm2,
                container_area_cm2,
            } => (
                [
                    ("container_area_cm2", container_area_cm2),
                    ("footprint_share", footprint_share),
                    ("subject_area_cm2", subject_area_cm2),
                    ("z_share", z_share),
                    ("", 0.0),
                    ("", 0.0),
                ],
                4,
            ),
            Self::Support {
                footprint_share,
                z_gap_cm,
            } => (
                [
                    ("footprint_share", footprint_share),
                    ("z_gap_cm", z_gap_cm),
                    ("", 0.0),
                    ("", 0.0),
                    ("", 0.0),
                    ("", 0.0),
                ],
                2,
            ),
            Self::Proximity {
                dx_cm,
                dy_cm,
                distance_2d_cm,
                distance_3d_cm,
                max_distance_cm,
                rank,
            } => (
                [
                    ("distance_2d_cm", distance_2d_cm),
                    ("distance_3d_cm", distance_3d_cm),
                    ("dx_cm", dx_cm),
                    ("dy_cm", dy_cm),
                    ("max_distance_cm", max_distance_cm),
                    ("rank", rank as f64),
                ],
                6,
            ),
        };
        items.into_iter().take(len)
    }
}

/// A node: where an object is, where it faces, and the numbers behind them. The names of
/// nodes and edges borrow the scene's: a graph allocates no string of its own.
#[derive(Debug, Clone, PartialEq)]
pub struct Node<'a> {
    /// The instance.
    pub instance: &'a str,
    /// The nine-grid cell.
    pub is_at: GridCell,
    /// The facing direction.
    pub face_to: Facing,
    /// (fx, fy): the centre's fractions across the zone.
    pub zone_fraction: [f64; 2],
    /// Whether the object counted as a container.
    pub container: bool,
}

/// An edge `(subject, relation, object)`.
#[derive(Debug, Clone, PartialEq)]
pub struct Edge<'a> {
    /// Subject instance.
    pub subject: &'a str,
    /// The relation.
    pub relation: Relation,
    /// Object instance.
    pub object: &'a str,
    /// The numbers that decided it.
    pub evidence: Evidence,
    /// The layout indices of the subject and the object: where [`SceneGraph::to_text`] finds
    /// their names among the nodes' (it checks that they are the same).
    indices: [usize; 2],
}

impl Edge<'_> {
    /// `(subject, relation, object)`.
    pub fn triplet(&self) -> String {
        let mut line = String::new();
        self.push_triplet(&mut line);
        line
    }

    fn push_triplet(&self, out: &mut String) {
        push_fields(out, &[self.subject, self.relation.label(), self.object]);
    }
}

/// Appends `(a, b, …)`: the fields between parentheses, separated by a comma and a space.
fn push_fields(out: &mut String, fields: &[&str]) {
    out.push('(');
    for (i, field) in fields.iter().enumerate() {
        if i > 0 {
            out.push_str(", ");
        }
        out.push_str(field);
    }
    out.push(')');
}

/// An axis of the table frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Axis {
    /// Left to right.
    X,
    /// Front to back.
    Y,
}

impl Axis {
    /// `x` or `y`.
    pub fn label(self) -> &'static str {
        match self {
            Self::X => "x",
            Self::Y => "y",
        }
    }
}

/// Three objects equally spaced along an axis.
#[derive(Debug, Clone, PartialEq)]
pub struct EquallySpaced<'a> {
    /// The instances by increasing coordinate.
    pub instances: [&'a str; 3],
    /// The axis.
    pub axis: Axis,
    /// The gaps b - a and c - b along the axis, cm.
    pub gaps_cm: [f64; 2],
    /// The spread (max - min) of the other coordinate, cm.
    pub spread_cm: f64,
}

impl EquallySpaced<'_> {
    /// The gaps and the spread by name, the names in byte order (as `graph.json` holds them).
    pub fn numbers(&self) -> [(&'static str, f64); 3] {
        [
            ("gap_1_cm", self.gaps_cm[0]),
            ("gap_2_cm", self.gaps_cm[1]),
            ("spread_cm", self.spread_cm),
        ]
    }

    /// `(a, b, c, are equally spaced along, x)`.
    pub fn triplet(&self) -> String {
        let mut line = String::new();
        self.push_triplet(&mut line);
        line
    }

    fn push_triplet(&self, out: &mut String) {
        let [a, b, c] = self.instances;
        push_fields(
            out,
            &[a, b, c, "are equally spaced along", self.axis.label()],
        );
    }
}

/// A scene graph: nodes in layout order, edges in output order.
#[derive(Debug, Clone, PartialEq)]
pub struct SceneGraph<'a> {
    /// One node per object, in layout order.
    pub nodes: Vec<Node<'a>>,
    /// `in` edges, then `above` edges, then horizontal edges, as SCENE_GRAPH.md orders them.
    pub edges: Vec<Edge<'a>>,
    /// `are equally spaced along` triples (empty unless that option is on).
    pub equally_spaced: Vec<EquallySpaced<'a>>,
}

impl SceneGraph<'_> {
    /// The triplet lines: per node `is at` then `face to`, then the edges, then the
    /// equally-spaced triples.
    pub fn triplet_lines(&self) -> Vec<String> {
        let mut lines = Vec::with_capacity(2 * self.nodes.len() + self.edges.len());
        for node in &self.nodes {
            lines.push(format!("({}{}", node.instance, node.is_at.is_at_tail()));
            lines.push(format!("({}{}", node.instance, node.face_to.face_to_tail()));
        }
        lines.extend(self.edges.iter().map(Edge::triplet));
        lines.extend(self.equally_spaced.iter().map(EquallySpaced::triplet));
        lines
    }

    /// `graph.txt`: the triplet lines, each ending with a newline.
    ///
    /// The lines of [`Self::triplet_lines`], written by fixed-width copies (see
    /// `crate::pieces`): each node's name, behind its `(`, is written in full once, in its
    /// `is at` line, and copied from there after; an edge's names are found by its layout
    /// indices. An edge whose names are not those of the nodes at its indices (a graph edited
    /// by hand), and the equally-spaced triples, are written piece by piece instead.
    pub fn to_text(&self) -> String {
        const LINE_START: Fixed = Fixed::new("(");
        const LINE_END: Fixed = Fixed::new(")\n");
        // About 40 bytes a line; one growth at most for long names.
        let lines = 2 * self.nodes.len() + self.edges.len() + self.equally_spaced.len();
        let mut text = Text::with_capacity(40 * lines);
        // Where each node's `(` and name lie in the text, after their first line's start.
        let mut names = Vec::with_capacity(self.nodes.len());
        for node in &self.nodes {
            let mark = text.mark();
            text.fixed(&LINE_START);
            text.str(node.instance);
            let name = text.since(mark);
            text.fixed(node.is_at.is_at_line_end());
            text.repeat(name);
            text.fixed(node.face_to.face_to_line_end());
            names.push(name);
        }
        let mut line = String::new();
        for edge in &self.edges {
            let [s, o] = edge.indices;
            let named = |i: usize, name: &str| {
                self.nodes
                    .get(i)
                    .is_some_and(|node| std::ptr::eq(node.instance, name))
            };
            if named(s, edge.subject) && named(o, edge.object) {
                text.repeat(names[s]);
                text.fixed(edge.relation.between());
                text.repeat(names[o].skip(LINE_START.text().len()));
                text.fixed(&LINE_END);
            } else {
                line.clear();
                edge.push_triplet(&mut line);
                line.push('\n');
                text.str(&line);
            }
        }
        for spacing in &self.equally_spaced {
            line.clear();
            spacing.push_triplet(&mut line);
            line.push('\n');
            text.str(&line);
        }
        text.into_string()
    }

    /// The bytes of `graph.json` (`mesa.graph/1`) of a scene: those of
    /// [`GraphArtifact::to_pretty_json`] on [`Self::to_artifact`], written from the graph's
    /// own parts without making the artifact's strings and maps.
    pub fn to_json(&self, scene_id: &str, layout: &str) -> Vec<u8> {
        write_graph_json(
            GRAPH_SCHEMA,
            scene_id,
            layout,
            self.nodes.iter().map(|n| NodeRef {
                instance: n.instance,
                is_at: n.is_at.label(),
                face_to: n.face_to.label(),
                container: n.container,
            }),
            self.edges.iter().map(|e| EdgeRef {
                subject: e.subject,
                relation: e.relation.label(),
                object: e.object,
                numbers: e.evidence.sorted_numbers(),
            }),
            self.equally_spaced.iter().map(|s| SpacingRef {
                instances: s.instances,
                axis: s.axis.label(),
                numbers: s.numbers(),
            }),
        )
    }

    /// `graph.json` (`mesa.graph/1`) of a scene; `layout` is the layout file relative to the
    /// scene folder.
    pub fn to_artifact(&self, scene_id: &str, layout: &str) -> GraphArtifact {
        GraphArtifact {
            schema: GRAPH_SCHEMA.to_owned(),
            scene_id: scene_id.to_owned(),
            layout: layout.to_owned(),
            nodes: self
                .nodes
                .iter()
                .map(|n| GraphNode {
                    instance: n.instance.to_owned(),
                    is_at: n.is_at.label().to_owned(),
                    face_to: n.face_to.label().to_owned(),
                    container: n.container,
                })
                .collect(),
            edges: self
                .edges
                .iter()
                .map(|e| GraphEdge {
                    subject: e.subject.to_owned(),
                    relation: e.relation.label().to_owned(),
                    object: e.object.to_owned(),
                    numbers: e.evidence.numbers(),
                })
                .collect(),
            equally_spaced: self
                .equally_spaced
                .iter()
                .map(|s| GraphSpacing {
                    instances: s.instances.map(str::to_owned),
                    axis: s.axis.label().to_owned(),
                    numbers: s
                        .numbers()
                        .into_iter()
                        .map(|(k, v)| (k.to_owned(), v))
                        .collect(),
                })
                .collect(),
        }
    }
}

// ---------------------------------------------------------------------------------------------
// Geometry.

/// Sine and cosine of an angle in degrees, exact at multiples of 90° (so axis-aligned
/// footprints stay exactly axis-aligned).
pub fn sin_cos_deg(angle_deg: f64) -> (f64, f64) {
    let a = angle_deg.rem_euclid(360.0);
    if a == 0.0 {
        (0.0, 1.0)
    } else if a == 90.0 {
        (1.0, 0.0)
    } else if a == 180.0 {
        (0.0, -1.0)
    } else if a == 270.0 {
        (-1.0, 0.0)
    } else {
        a.to_radians().sin_cos()
    }
}

/// A footprint rectangle centred at the origin: its corners counter-clockwise.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Footprint {
    /// Corner offsets from the centre, counter-clockwise, in cm.
    pub corners_cm: [[f64; 2]; 4],
    /// Half extents of the axis-aligned box around the corners, in cm.
    pub half_extent_cm: [f64; 2],
    /// True when the rectangle's sides are parallel to the axes (yaw a multiple of 90°).
    pub axis_aligned: bool,
    /// w·d in cm².
    pub area_cm2: f64,
}

impl Footprint {
    /// The w×d rectangle rotated by `yaw_deg` counter-clockwise.
    pub fn new(width_cm: f64, depth_cm: f64, yaw_deg: f64) -> Self {
        let (s, c) = sin_cos_deg(yaw_deg);
        let (hw, hd) = (width_cm / 2.0, depth_cm / 2.0);
        let rotate = |u: f64, v: f64| [c * u - s * v, s * u + c * v];
        let corners_cm = [
            rotate(-hw, -hd),
            rotate(hw, -hd),
            rotate(hw, hd),
            rotate(-hw, hd),
        ];
        let axis_aligned = s == 0.0 || c == 0.0;
        let half_extent_cm = if axis_aligned {
            if c == 0.0 {
                [hd, hw]
            } else {
                [hw, hd]
            }
        } else {
            let hx = corners_cm.iter().map(|p| p[0].abs()).fold(0.0, f64::max);
            let hy = corners_cm.iter().map(|p| p[1].abs()).fold(0.0, f64::max);
            [hx, hy]
        };
        Self {
            corners_cm,
            half_extent_cm,
            axis_aligned,
            area_cm2: width_cm * depth_cm,
        }
    }
}

/// The area (cm²) of the intersection of two footprints whose centres are `offset_cm` apart
/// (centre of `b` minus centre of `a`): exact for axis-aligned pairs, else by clipping `a`
/// against `b` (Sutherland–Hodgman; both are convex).
pub fn intersection_area_footprints(a: &Footprint, b: &Footprint, offset_cm: [f64; 2]) -> f64 {
    let [dx, dy] = offset_cm;
    if dx.abs() >= a.half_extent_cm[0] + b.half_extent_cm[0]
        || dy.abs() >= a.half_extent_cm[1] + b.half_extent_cm[1]
    {
        return 0.0;
    }
    if a.axis_aligned && b.axis_aligned {
        return box_overlap_area(a, b, offset_cm);
    }
    let clip: [[f64; 2]; 4] = b.corners_cm.map(|[x, y]| [x + dx, y + dy]);
    // Clipped back and forth between two polygons, so that no polygon is copied.
    let mut polygon = Polygon::from_slice(&a.corners_cm);
    let mut clipped = Polygon::from_slice(&[]);
    for i in 0..4 {
        polygon.clip_half_plane(clip[i], clip[(i + 1) % 4], &mut clipped);
        if clipped.len < 3 {
            return 0.0;
        }
        std::mem::swap(&mut polygon, &mut clipped);
    }
    polygon.area()
}

/// The area (cm²) of the overlap of the axis-aligned boxes around two footprints whose centres
/// are `offset_cm` apart: the footprints' intersection when both are axis-aligned, and a bound
/// on it otherwise.
fn box_overlap_area(a: &Footprint, b: &Footprint, offset_cm: [f64; 2]) -> f64 {
    let [dx, dy] = offset_cm;
    let [ax, ay] = a.half_extent_cm;
    let [bx, by] = b.half_extent_cm;
    let ox = ax.min(dx + bx) - (-ax).max(dx - bx);
    let oy = ay.min(dy + by) - (-ay).max(dy - by);
    ox.max(0.0) * oy.max(0.0)
}

/// A convex polygon of at most 8 vertices (a quadrilateral clipped by 4 half-planes gains at
/// most one vertex per cut), kept on the stack.
#[derive(Clone, Copy)]
struct Polygon {
    points: [[f64; 2]; 8],
    len: usize,
}

impl Polygon {
    fn from_slice(points: &[[f64; 2]]) -> Self {
        let mut polygon = Self {
            points: [[0.0; 2]; 8],
            len: 0,
        };
        for p in points {
            polygon.push(*p);
        }
        polygon
    }

    fn push(&mut self, p: [f64; 2]) {
        // A convex 4-gon clipped by 4 half-planes has at most 8 vertices; rounding cannot add
        // more, but never index past the end whatever happens.
        if self.len < self.points.len() {
            self.points[self.len] = p;
            self.len += 1;
        }
    }

    /// Sets `out` to the part left of the directed line a → b (counter-clockwise clip edge).
    fn clip_half_plane(&self, a: [f64; 2], b: [f64; 2], out: &mut Self) {
        let side = |p: [f64; 2]| (b[0] - a[0]) * (p[1] - a[1]) - (b[1] - a[1]) * (p[0] - a[0]);
        out.len = 0;
        for i in 0..self.len {
            let p = self.points[i];
            let q = self.points[(i + 1) % self.len];
            let (sp, sq) = (side(p), side(q));
            if sp >= 0.0 {
                out.push(p);
            }
            if (sp >= 0.0) != (sq >= 0.0) {
                let t = sp / (sp - sq);
                out.push([p[0] + t * (q[0] - p[0]), p[1] + t * (q[1] - p[1])]);
            }
        }
    }

    fn area(&self) -> f64 {
        let mut twice = 0.0;
        for i in 0..self.len {
            let p = self.points[i];
            let q = self.points[(i + 1) % self.len];
            twice += p[0] * q[1] - q[0] * p[1];
        }
        (twice / 2.0).abs()
    }
}

/// The derived geometry of one object. The footprint's corners take a sine and a cosine, and
/// most pairs are too far apart for their footprints to meet (the circles around them do not),
/// so it is made the first time a pair needs it.
struct Solid {
    x: f64,
    y: f64,
    z: f64,
    z_min: f64,
    z_max: f64,
    height: f64,
    /// w·d in cm² (the footprint's `area_cm2`).
    area_cm2: f64,
    /// Half the footprint's diagonal: its corners are this far from the centre, whatever the
    /// yaw.
    half_diagonal_cm: f64,
    size_cm: [f64; 2],
    yaw_deg: f64,
    footprint: OnceCell<Footprint>,
}

impl Solid {
    fn new(object: &SceneObject) -> Self {
        let [x, y, z] = object.position_cm;
        let [w, d, h] = object.size_cm;
        Self {
            x,
            y,
            z,
            z_min: z - h / 2.0,
            z_max: z + h / 2.0,
            height: h,
            area_cm2: w * d,
            half_diagonal_cm: (w * w + d * d).sqrt() / 2.0,
            size_cm: [w, d],
            yaw_deg: object.yaw_deg,
            footprint: OnceCell::new(),
        }
    }

    fn footprint(&self) -> &Footprint {
        self.footprint
            .get_or_init(|| Footprint::new(self.size_cm[0], self.size_cm[1], self.yaw_deg))
    }

    fn area(&self) -> f64 {
        self.area_cm2
    }

    /// Share of this object's footprint inside `other`'s, when it is at least `least` (> 0).
    ///
    /// Two shortcuts settle most pairs that fall short, each with a margin of a relative 1e-9,
    /// far more than the rounding of the corners and of the clipping:
    /// - the circles around the footprints are apart: the rectangles cannot meet, and neither
    ///   footprint is made;
    /// - the boxes around two footprints that are not both axis-aligned overlap by less than
    ///   `least` of this one's area: their intersection, inside that overlap, is smaller
    ///   still, and it is not clipped (on the demo's tables, half of the pairs whose circles
    ///   meet).
    fn footprint_share_in(&self, other: &Solid, least: f64) -> Option<f64> {
        if !self.circles_meet(other) {
            return None;
        }
        let offset_cm = [other.x - self.x, other.y - self.y];
        let (a, b) = (self.footprint(), other.footprint());
        let floor = least * self.area() * (1.0 - 1e-9);
        if !(a.axis_aligned && b.axis_aligned) && box_overlap_area(a, b, offset_cm) < floor {
            return None;
        }
        let share = intersection_area_footprints(a, b, offset_cm) / self.area();
        (share >= least).then_some(share)
    }

    /// Whether the circles around the two footprints meet, or are apart by a relative 1e-9 at
    /// most (far more than the corners' rounding): if not, the footprints cannot meet.
    #[inline(always)]
    fn circles_meet(&self, other: &Solid) -> bool {
        let (dx, dy) = (other.x - self.x, other.y - self.y);
        let reach = self.half_diagonal_cm + other.half_diagonal_cm;
        dx * dx + dy * dy <= reach * reach * (1.0 + 1e-9)
    }

    fn z_overlap(&self, other: &Solid) -> f64 {
        (self.z_max.min(other.z_max) - self.z_min.max(other.z_min)).max(0.0)
    }
}

// ---------------------------------------------------------------------------------------------
// The extraction.

/// Up to this many objects, the pairs that may be related are found by testing every pair: a
/// table holds a dozen or two objects, and building the grids costs more than the tests they
/// save. Measured on random table-like layouts (15 objects per 120 × 70 cm, 2026-11-28): the
/// pairwise search takes 0.4× the grids' time at 10 objects, 0.85× at 60, 1.0× at 80, 1.3× at
/// 120. Above it, the grids. Both give the same graph (property tests compare them with the
/// rules word for word on up to 160 objects).
const ALL_PAIRS_UP_TO_OBJECTS: usize = 64;

/// Extracts the scene graph of `scene`, with `containers[i]` saying whether object i is a
/// container (see [`keyword_containers`] for the keyword rule). The graph's names borrow the
/// scene's.
pub fn extract_graph<'a>(
    scene: &'a GraphScene,
    containers: &[bool],
    options: &GraphOptions,
) -> Result<SceneGraph<'a>, GraphError> {
    if scene.objects.len() > ALL_PAIRS_UP_TO_OBJECTS {
        // Lists as large as this scene's are not kept for the next one.
        return extract(
            scene,
            containers,
            options,
            PairSearch::Grid,
            &mut Scratch::default(),
        );
    }
    SCRATCH.with(|cell| match cell.try_borrow_mut() {
        Ok(mut scratch) => extract(
            scene,
            containers,
            options,
            PairSearch::AllPairs,
            &mut scratch,
        ),
        // Never, as `extract` calls no one who extracts, but a fresh set of lists would do.
        Err(_) => extract(
            scene,
            containers,
            options,
            PairSearch::AllPairs,
            &mut Scratch::default(),
        ),
    })
}

thread_local! {
    /// The lists of the last table-sized scene extracted on this thread, for the next one.
    static SCRATCH: RefCell<Scratch> = RefCell::new(Scratch::default());
}

/// The working lists of an extraction, kept from one table-sized scene to the next on a
/// thread ([`extract_graph`]): a table's graph takes a dozen lists of a few dozen items, and
/// allocating and freeing them took a tenth of its time (2026-12-07). Each user clears what it
/// takes; nothing is read that the same extraction did not write.
#[derive(Default)]
struct Scratch {
    solids: Vec<Solid>,
    /// The candidates of one subject (`Overlaps`).
    near: Vec<usize>,
    /// The containers, in layout order.
    listed: Vec<usize>,
    container_of: Vec<Option<(usize, Evidence)>>,
    free: Vec<usize>,
    is_free: Vec<bool>,
    pairs: PairScratch,
}

/// The working lists of the horizontal pairs' search.
#[derive(Default)]
struct PairScratch {
    /// The subjects in visiting order, and the raised flag of every object
    /// ([`visiting_order`]).
    visit: Vec<usize>,
    raised: Vec<bool>,
    /// Whether a pair was written, either way round (n × n).
    emitted: Vec<bool>,
    /// The free objects' centres.
    centres: Vec<[f64; 3]>,
    /// A subject's candidates near enough in space, with their plane distance.
    near: Vec<(f64, usize)>,
    /// The pairs in visiting order, then grouped by subject ([`group_by_subject`]).
    pairs: Vec<Pair>,
    grouped: Vec<Pair>,
}

/// How the pairs that may be related are found.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum PairSearch {
    /// Grids over footprints and centres: only pairs that can be related are tested.
    Grid,
    /// Every pair: for small scenes, and the grids' test oracle.
    AllPairs,
    /// Every pair, the neighbours ranked word for word as SCENE_GRAPH.md states it, and every
    /// free object searched for what it is above: the test oracle of the other two.
    #[cfg(test)]
    Literal,
}

impl PairSearch {
    /// Whether this is the rules word for word, without the shortcuts of the other searches.
    fn is_literal(self) -> bool {
        #[cfg(test)]
        return self == Self::Literal;
        #[cfg(not(test))]
        false
    }
}

/// The objects whose footprints may overlap a given object's.
enum Overlaps {
    /// Every object.
    All,
    /// Those whose footprint boxes overlap in a grid.
    Grid(BoxGrid),
}

impl Overlaps {
    /// In layout order, every container whose footprint may overlap that of `s` (a superset of
    /// those that do, which may hold `s` itself and objects that are no containers):
    /// `containers` lists them all, in layout order; `buffer` holds the list when it is made.
    fn containers_of<'b>(
        &'b self,
        solids: &[Solid],
        s: usize,
        containers: &'b [usize],
        buffer: &'b mut Vec<usize>,
    ) -> &'b [usize] {
        match self {
            Self::All => containers,
            Self::Grid(grid) => {
                buffer.clear();
                grid.overlapping(solids, s, buffer);
                buffer
            }
        }
    }

    /// In layout order, every `free` object (`is_free` their flags) whose footprint may
    /// overlap that of `s` (a superset of those that do, which may hold `s` itself).
    fn free_of<'b>(
        &'b self,
        solids: &[Solid],
        s: usize,
        free: &'b [usize],
        is_free: &[bool],
        buffer: &'b mut Vec<usize>,
    ) -> &'b [usize] {
        match self {
            Self::All => free,
            Self::Grid(grid) => {
                buffer.clear();
                grid.overlapping(solids, s, buffer);
                buffer.retain(|&o| is_free[o]);
                buffer
            }
        }
    }
}

fn extract<'a>(
    scene: &'a GraphScene,
    containers: &[bool],
    options: &GraphOptions,
    search: PairSearch,
    scratch: &mut Scratch,
) -> Result<SceneGraph<'a>, GraphError> {
    scene.check()?;
    if containers.len() != scene.objects.len() {
        return Err(GraphError::ContainerFlags {
            flags: containers.len(),
            objects: scene.objects.len(),
        });
    }
    let Scratch {
        solids,
        near,
        listed,
        container_of,
        free,
        is_free,
        pairs: pair_scratch,
    } = scratch;
    solids.clear();
    solids.extend(scene.objects.iter().map(Solid::new));
    let solids = &solids[..];
    let name = |i: usize| scene.objects[i].instance.as_str();
    let [x_min, x_max, y_min, y_max] = scene.zone_cm;
    let (width, depth) = (x_max - x_min, y_max - y_min);

    let nodes = scene
        .objects
        .iter()
        .zip(containers)
        .map(|(object, &container)| {
            let fx = zone_fraction(object.position_cm[0], x_min, width);
            let fy = zone_fraction(object.position_cm[1], y_min, depth);
            Node {
                instance: object.instance.as_str(),
                is_at: GridCell::from_fractions(fx, fy),
                face_to: Facing::from_yaw_deg(object.yaw_deg),
                zone_fraction: [fx, fy],
                container,
            }
        })
        .collect();

    let overlaps = match search {
        PairSearch::Grid => Overlaps::Grid(BoxGrid::new(solids)),
        PairSearch::AllPairs => Overlaps::All,
        #[cfg(test)]
        PairSearch::Literal => Overlaps::All,
    };
    containment(solids, containers, &overlaps, near, listed, container_of);
    let mut edges = Vec::with_capacity((NEIGHBOURS_PER_SUBJECT + 1) * solids.len());
    for (s, found) in container_of.iter().enumerate() {
        if let Some((c, evidence)) = found {
            edges.push(Edge {
                subject: name(s),
                relation: Relation::In,
                object: name(*c),
                evidence: *evidence,
                indices: [s, *c],
            });
        }
    }
    // Objects that take part in the other relations, in layout order.
    free.clear();
    free.extend((0..solids.len()).filter(|&i| container_of[i].is_none()));
    is_free.clear();
    is_free.extend(container_of.iter().map(Option::is_none));
    let (free, is_free) = (&free[..], &is_free[..]);
    // The lowest `z_max - ABOVE_Z_TOLERANCE_CM` of the free objects, as `support_of` computes
    // it: an object whose bottom is not above it would have every candidate rejected there,
    // so it is not searched (most objects stand on the table).
    let lowest_reach = free
        .iter()
        .map(|&o| solids[o].z_max - ABOVE_Z_TOLERANCE_CM)
        .fold(f64::INFINITY, f64::min);
    for &s in free {
        if solids[s].z_min <= lowest_reach && !search.is_literal() {
            continue;
        }
        let near = overlaps.free_of(solids, s, free, is_free, near);
        if let Some((o, evidence)) = support_of(s, solids, near) {
            edges.push(Edge {
                subject: name(s),
                relation: Relation::Above,
                object: name(o),
                evidence,
                indices: [s, o],
            });
        }
    }
    let max_distance_cm = NEIGHBOUR_MAX_DISTANCE_SHARE * width.max(depth);
    let pairs = match search {
        PairSearch::Grid => nearest_pairs(solids, free, max_distance_cm, pair_scratch),
        PairSearch::AllPairs => horizontal_pairs(solids, free, max_distance_cm, pair_scratch),
        #[cfg(test)]
        PairSearch::Literal => {
            pair_scratch.grouped = literal_pairs(solids, free, max_distance_cm);
            &pair_scratch.grouped
        }
    };
    edges.extend(pairs.iter().map(|&(s, o, rank)| {
        let (relation, evidence) = proximity(s, o, solids, max_distance_cm, rank);
        Edge {
            subject: name(s),
            relation,
            object: name(o),
            evidence,
            indices: [s, o],
        }
    }));
    let equally_spaced = if options.equally_spaced {
        spacings(solids, free, &scene.objects)
    } else {
        Vec::new()
    };
    Ok(SceneGraph {
        nodes,
        edges,
        equally_spaced,
    })
}

/// Whether `c` may contain `s` by the thresholds alone; with the numbers when it may.
#[inline(always)]
fn containment_evidence(
    s: usize,
    c: usize,
    solids: &[Solid],
    containers: &[bool],
) -> Option<Evidence> {
    let (ss, sc) = (&solids[s], &solids[c]);
    // The cheap conditions at once, without a jump for each (each one alone is a coin toss
    // for the branch predictor): with the circles around the footprints, which meet for few
    // pairs, the one jump left is nearly always the same way. Sizes and positions are finite
    // (`GraphScene::check`), so each comparison is the negation of the rule's.
    let plausible = (s != c)
        & containers[c]
        & (sc.area() >= ss.area())
        & (ss.z > sc.z_min)
        & ss.circles_meet(sc);
    if !plausible {
        return None;
    }
    let z_share = ss.z_overlap(sc) / ss.height.min(sc.height);
    if z_share < CONTAINMENT_MIN_Z_SHARE {
        return None;
    }
    let footprint_share = ss.footprint_share_in(sc, CONTAINMENT_MIN_FOOTPRINT_SHARE)?;
    Some(Evidence::Containment {
        footprint_share,
        z_share,
        subject_area_cm2: ss.area(),
        container_area_cm2: sc.area(),
    })
}

/// The container of each object, if any: the qualifying container with the smallest footprint
/// (ties: earlier in layout order).
///
/// SCENE_GRAPH.md leaves one case open: two containers of equal footprint can each qualify as
/// the other's container (two identical cups stacked), which would write the pair twice. Then
/// only the upper one (higher centre; on equal centres the later in layout order) is in the
/// lower one. This also rules out longer cycles, so containment is a forest.
///
/// `overlaps` lists, in layout order, every object that may contain a given one (a superset of
/// those whose footprint overlaps it); `near` is a buffer.
fn containment(
    solids: &[Solid],
    containers: &[bool],
    overlaps: &Overlaps,
    near: &mut Vec<usize>,
    listed: &mut Vec<usize>,
    container_of: &mut Vec<Option<(usize, Evidence)>>,
) {
    listed.clear();
    listed.extend((0..solids.len()).filter(|&c| containers[c]));
    container_of.clear();
    container_of.extend((0..solids.len()).map(|s| {
        let mut best: Option<(usize, Evidence)> = None;
        for &c in overlaps.containers_of(solids, s, listed, near) {
            let Some(evidence) = containment_evidence(s, c, solids, containers) else {
                continue;
            };
            let s_is_lower = (solids[s].z, s) < (solids[c].z, c);
            if s_is_lower && containment_evidence(c, s, solids, containers).is_some() {
                continue;
            }
            // Strictly smaller wins, so the earliest of equal areas stays.
            if best.is_none_or(|(b, _)| solids[c].area() < solids[b].area()) {
                best = Some((c, evidence));
            }
        }
        best
    }));
}

/// What `s` is above, if anything: of the qualifying objects, the one with the highest top
/// (ties: earlier in layout order). `free` is in layout order and holds at least every free
/// object whose footprint overlaps that of `s`.
fn support_of(s: usize, solids: &[Solid], free: &[usize]) -> Option<(usize, Evidence)> {
    let ss = &solids[s];
    let mut best: Option<(usize, Evidence)> = None;
    for &o in free {
        let so = &solids[o];
        if o == s || ss.z_min <= so.z_max - ABOVE_Z_TOLERANCE_CM || ss.z <= so.z {
            continue;
        }
        let Some(footprint_share) = ss.footprint_share_in(so, ABOVE_MIN_FOOTPRINT_SHARE) else {
            continue;
        };
        if best.is_none_or(|(b, _)| so.z_max > solids[b].z_max) {
            best = Some((
                o,
                Evidence::Support {
                    footprint_share,
                    z_gap_cm: ss.z_min - so.z_max,
                },
            ));
        }
    }
    best
}

/// A horizontal pair: subject, object, and the object's rank among the subject's kept
/// neighbours (from 0).
type Pair = (usize, usize, usize);

/// The subjects in the order the horizontal rule visits them: the free objects that are not
/// raised in layout order, then the raised ones; with the raised flag of every object.
fn visiting_order(
    solids: &[Solid],
    free: &[usize],
    visit: &mut Vec<usize>,
    raised: &mut Vec<bool>,
) {
    raised.clear();
    raised.extend(solids.iter().map(|s| s.z_min > RAISED_Z_MIN_CM));
    visit.clear();
    visit.extend(
        free.iter()
            .filter(|&&i| !raised[i])
            .chain(free.iter().filter(|&&i| raised[i])),
    );
}

/// The relation of the pair (s, o), of rank `rank` (from 0) among the kept neighbours of
/// `s`, and the numbers behind it.
fn proximity(
    s: usize,
    o: usize,
    solids: &[Solid],
    max_distance_cm: f64,
    rank: usize,
) -> (Relation, Evidence) {
    let (ss, so) = (&solids[s], &solids[o]);
    let (dx_cm, dy_cm) = (ss.x - so.x, ss.y - so.y);
    (
        Relation::horizontal(dx_cm, dy_cm),
        Evidence::Proximity {
            dx_cm,
            dy_cm,
            distance_2d_cm: (dx_cm * dx_cm + dy_cm * dy_cm).sqrt(),
            distance_3d_cm: distance_3d(ss, so),
            max_distance_cm,
            rank: rank + 1,
        },
    )
}

/// The horizontal pairs ("keep closest pairs, remove duals"), grouped by subject in layout
/// order, each group in the order its pairs were chosen: each subject looks at every other
/// object, as the rules state it. Used for small scenes, and as the test oracle of
/// [`nearest_pairs`].
///
/// The rules rank all objects by plane distance, drop those too far in space and keep the
/// first 5: the same as keeping the 5 nearest of those near enough in space, which is what is
/// done here, by insertion into a list of 5 (ties: layout order, as a stable ranking gives).
fn horizontal_pairs<'p>(
    solids: &[Solid],
    free: &[usize],
    max_distance_cm: f64,
    scratch: &'p mut PairScratch,
) -> &'p [Pair] {
    let n = solids.len();
    let PairScratch {
        visit,
        raised,
        emitted,
        centres,
        near,
        pairs,
        grouped,
    } = scratch;
    visiting_order(solids, free, visit, raised);
    emitted.clear();
    emitted.resize(n * n, false);
    pairs.clear();
    let within = Within::new(max_distance_cm);
    centres.clear();
    centres.extend(
        free.iter()
            .map(|&o| [solids[o].x, solids[o].y, solids[o].z]),
    );
    // The candidates near enough in space, in layout order, with their plane distance: on
    // the demo's tables, 7.4 of a subject's 13 others, so the ranking below looks at about
    // half as many as it would over every free object.
    near.clear();
    near.resize(free.len(), (f64::INFINITY, 0usize));
    // Where the pairs of the raised subjects begin.
    let mut raised_from = 0;
    for &s in visit.iter() {
        let ss = &solids[s];
        // Without a jump per candidate: whether a pair is near enough is no better than a coin
        // toss for the branch predictor. Each candidate is written to the next free place, which
        // moves on only when the candidate is near enough. Only pairs within a rounding of the
        // limit take the square root, after the loop.
        // The squared distances to a centre: in the plane, and in space.
        let squared = |centre: &[f64; 3]| {
            let (dx, dy, dz) = (ss.x - centre[0], ss.y - centre[1], ss.z - centre[2]);
            let d2 = dx * dx + dy * dy;
            (d2, d2 + dz * dz)
        };
        let mut borderline = false;
        let mut count = 0;
        for (centre, &o) in centres.iter().zip(free) {
            let (d2, squared) = squared(centre);
            let inside = (squared < within.surely_in) & (o != s);
            borderline |= (squared >= within.surely_in) & (squared <= within.surely_out);
            near[count] = (d2, o);
            count += usize::from(inside);
        }
        if borderline {
            count = 0;
            for (centre, &o) in centres.iter().zip(free) {
                let (d2, squared) = squared(centre);
                if o != s && within.holds_squared(squared) {
                    near[count] = (d2, o);
                    count += 1;
                }
            }
        }
        // The nearest so far by increasing plane distance; an infinite distance is a free slot.
        // `near` is in layout order: an object goes after every kept one at the same distance.
        let mut kept = [(f64::INFINITY, 0usize); NEIGHBOURS_PER_SUBJECT];
        for &(key, o) in &near[..count] {
            keep_nearest(&mut kept, key, o);
        }
        let count = kept.iter().take_while(|(d2, _)| d2.is_finite()).count();
        for (rank, &(_, o)) in kept[..count].iter().enumerate() {
            if (raised[s] && !raised[o]) || emitted[s * n + o] {
                continue;
            }
            emitted[s * n + o] = true;
            emitted[o * n + s] = true;
            pairs.push((s, o, rank));
        }
        if !raised[s] {
            raised_from = pairs.len();
        }
    }
    group_by_subject(pairs, raised_from, grouped)
}

/// The pairs grouped by subject in layout order, each group in the order its pairs were
/// chosen. `pairs` holds each subject's pairs together, in the order [`visiting_order`] visits
/// the subjects: those of the subjects that are not raised, in layout order, then from
/// `raised_from` on those of the raised ones, in layout order. A merge of the two runs is what
/// a stable sort by subject gives, without sorting.
fn group_by_subject<'p>(
    pairs: &'p [Pair],
    raised_from: usize,
    grouped: &'p mut Vec<Pair>,
) -> &'p [Pair] {
    if raised_from == 0 || raised_from == pairs.len() {
        return pairs;
    }
    let (low, high) = pairs.split_at(raised_from);
    grouped.clear();
    let (mut i, mut j) = (0, 0);
    while i < low.len() && j < high.len() {
        // A subject is raised or not: its pairs are all in one run.
        if high[j].0 < low[i].0 {
            grouped.push(high[j]);
            j += 1;
        } else {
            grouped.push(low[i]);
            i += 1;
        }
    }
    grouped.extend_from_slice(&low[i..]);
    grouped.extend_from_slice(&high[j..]);
    grouped
}

/// Inserts `(key, o)` into `kept`, sorted by increasing key, after every entry of an equal
/// key; the last entry drops out. An infinite key changes nothing. Each slot is chosen by
/// comparisons alone, without a jump (see [`horizontal_pairs`]).
#[inline(always)]
fn keep_nearest(kept: &mut [(f64, usize); NEIGHBOURS_PER_SUBJECT], key: f64, o: usize) {
    let old = *kept;
    for j in 0..NEIGHBOURS_PER_SUBJECT {
        // Slots before the new entry's keep theirs; those after it take their predecessor's.
        let stays = old[j].0 <= key;
        let shifts = j > 0 && old[j - 1].0 > key;
        let from = if shifts { old[j - 1] } else { (key, o) };
        kept[j] = if stays { old[j] } else { from };
    }
}

/// The horizontal pairs word for word as SCENE_GRAPH.md states them: each subject ranks every
/// other candidate by plane distance (a stable sort: ties in layout order), drops those whose
/// distance in space exceeds the limit (by the square root), keeps the first 5. The oracle of
/// [`horizontal_pairs`] and [`nearest_pairs`].
#[cfg(test)]
fn literal_pairs(solids: &[Solid], free: &[usize], max_distance_cm: f64) -> Vec<Pair> {
    let n = solids.len();
    let raised: Vec<bool> = solids.iter().map(|s| s.z_min > RAISED_Z_MIN_CM).collect();
    let visit = free
        .iter()
        .filter(|&&i| !raised[i])
        .chain(free.iter().filter(|&&i| raised[i]));
    let mut emitted = vec![false; n * n];
    let mut blocks: Vec<Vec<Pair>> = vec![Vec::new(); n];
    for &s in visit {
        let ss = &solids[s];
        let mut ranked: Vec<(f64, usize)> = free
            .iter()
            .filter(|&&o| o != s)
            .map(|&o| {
                let (dx, dy) = (ss.x - solids[o].x, ss.y - solids[o].y);
                (dx * dx + dy * dy, o)
            })
            .collect();
        ranked.sort_by(|a, b| a.0.total_cmp(&b.0));
        let kept = ranked
            .iter()
            .filter(|&&(_, o)| distance_3d(ss, &solids[o]) <= max_distance_cm)
            .take(NEIGHBOURS_PER_SUBJECT);
        for (rank, &(_, o)) in kept.enumerate() {
            if (raised[s] && !raised[o]) || emitted[s * n + o] {
                continue;
            }
            emitted[s * n + o] = true;
            emitted[o * n + s] = true;
            blocks[s].push((s, o, rank));
        }
    }
    blocks.into_iter().flatten().collect()
}

/// [`horizontal_pairs`] without ranking every object: each subject's neighbours are searched
/// ring by ring outward in a grid of the centres until the 5 nearest within the distance limit
/// are certain (no unseen centre can come before them), or the rings pass the limit.
fn nearest_pairs<'p>(
    solids: &[Solid],
    free: &[usize],
    max_distance_cm: f64,
    scratch: &'p mut PairScratch,
) -> &'p [Pair] {
    let PairScratch {
        visit,
        raised,
        near: found,
        pairs,
        grouped,
        ..
    } = scratch;
    visiting_order(solids, free, visit, raised);
    let grid = CentreGrid::new(solids, free);
    let mut emitted: std::collections::HashSet<(usize, usize)> = std::collections::HashSet::new();
    pairs.clear();
    let mut raised_from = 0;
    for &s in visit.iter() {
        let ss = &solids[s];
        found.clear();
        let (cx, cy) = grid.cell_of(ss.x, ss.y);
        for ring in 0.. {
            grid.ring(cx, cy, ring, |cell| {
                for &o in cell {
                    let o = o as usize;
                    if o == s || distance_3d(ss, &solids[o]) > max_distance_cm {
                        continue;
                    }
                    let (dx, dy) = (ss.x - solids[o].x, ss.y - solids[o].y);
                    found.push((dx * dx + dy * dy, o));
                }
            });
            // Ties on distance go to layout order, as in the oracle's stable sort.
            found.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
            // Every centre not yet seen is at least this far (one ring of margin for the
            // subject's own place in its cell, and a hair for rounding).
            let unseen_cm = ring as f64 * grid.cell_cm * (1.0 - 1e-9);
            let certain = found.len() >= NEIGHBOURS_PER_SUBJECT
                && found[NEIGHBOURS_PER_SUBJECT - 1].0.sqrt() < unseen_cm;
            if certain || unseen_cm > max_distance_cm || ring + 1 >= grid.rings() {
                break;
            }
        }
        for (rank, &(_, o)) in found.iter().take(NEIGHBOURS_PER_SUBJECT).enumerate() {
            if (raised[s] && !raised[o]) || !emitted.insert((s.min(o), s.max(o))) {
                continue;
            }
            pairs.push((s, o, rank));
        }
        if !raised[s] {
            raised_from = pairs.len();
        }
    }
    group_by_subject(pairs, raised_from, grouped)
}

/// The bounds of a set of 2-D boxes and a uniform grid over them of about `cells_per_item`
/// cells per item, no cell smaller than `min_cell_cm`.
fn grid_shape(
    lo: [f64; 2],
    hi: [f64; 2],
    items: usize,
    cells_per_item: f64,
    min_cell_cm: f64,
) -> (f64, [usize; 2]) {
    let extent = [(hi[0] - lo[0]).max(0.0), (hi[1] - lo[1]).max(0.0)];
    let wanted = (items as f64 * cells_per_item).max(1.0);
    let mut cell = (extent[0] * extent[1] / wanted).sqrt().max(min_cell_cm);
    // A long thin spread: cells as wide as the spread is thin would be too many.
    cell = cell.max(extent[0].max(extent[1]) / wanted);
    if !(cell.is_finite() && cell > 0.0) {
        cell = 1.0;
    }
    let dims = extent.map(|e| ((e / cell).floor() as usize + 1).min(1 << 20));
    (cell, dims)
}

/// A uniform grid over the footprints' axis-aligned boxes: the objects whose boxes overlap a
/// given one share a cell with it.
struct BoxGrid {
    lo: [f64; 2],
    cell_cm: f64,
    dims: [usize; 2],
    cells: Vec<Vec<u32>>,
}

impl BoxGrid {
    /// The box of an object, a hair larger, so that rounding never loses an overlap.
    fn bounds(solid: &Solid) -> ([f64; 2], [f64; 2]) {
        let [hx, hy] = solid.footprint().half_extent_cm;
        let pad = |c: f64, h: f64| h + 1e-9 * (c.abs() + h) + 1e-12;
        let (px, py) = (pad(solid.x, hx), pad(solid.y, hy));
        ([solid.x - px, solid.y - py], [solid.x + px, solid.y + py])
    }

    fn new(solids: &[Solid]) -> Self {
        let mut lo = [f64::INFINITY; 2];
        let mut hi = [f64::NEG_INFINITY; 2];
        let mut side_sum = 0.0;
        for solid in solids {
            let (a, b) = Self::bounds(solid);
            for k in 0..2 {
                lo[k] = lo[k].min(a[k]);
                hi[k] = hi[k].max(b[k]);
                side_sum += b[k] - a[k];
            }
        }
        if solids.is_empty() {
            lo = [0.0; 2];
            hi = [0.0; 2];
        }
        // Cells about as large as a typical box: each box in a few cells.
        let mean_side = side_sum / (2 * solids.len()).max(1) as f64;
        let (cell_cm, dims) = grid_shape(lo, hi, solids.len(), 4.0, mean_side);
        let mut grid = Self {
            lo,
            cell_cm,
            dims,
            cells: vec![Vec::new(); dims[0] * dims[1]],
        };
        for (i, solid) in solids.iter().enumerate() {
            let ([x0, y0], [x1, y1]) = grid.cell_range(solid);
            for y in y0..=y1 {
                for x in x0..=x1 {
                    grid.cells[y * dims[0] + x].push(i as u32);
                }
            }
        }
        grid
    }

    fn index(&self, v: f64, axis: usize) -> usize {
        let i = ((v - self.lo[axis]) / self.cell_cm).floor();
        if i.is_nan() || i < 0.0 {
            0
        } else {
            (i as usize).min(self.dims[axis] - 1)
        }
    }

    fn cell_range(&self, solid: &Solid) -> ([usize; 2], [usize; 2]) {
        let (a, b) = Self::bounds(solid);
        (
            [self.index(a[0], 0), self.index(a[1], 1)],
            [self.index(b[0], 0), self.index(b[1], 1)],
        )
    }

    /// Appends to `out` the objects (other than `s`) whose boxes overlap that of `s`, in
    /// layout order; `out` is empty on entry.
    fn overlapping(&self, solids: &[Solid], s: usize, out: &mut Vec<usize>) {
        let ([x0, y0], [x1, y1]) = self.cell_range(&solids[s]);
        let (a, b) = Self::bounds(&solids[s]);
        for y in y0..=y1 {
            for x in x0..=x1 {
                for &o in &self.cells[y * self.dims[0] + x] {
                    let o = o as usize;
                    if o == s {
                        continue;
                    }
                    let (c, d) = Self::bounds(&solids[o]);
                    if a[0] <= d[0] && c[0] <= b[0] && a[1] <= d[1] && c[1] <= b[1] {
                        out.push(o);
                    }
                }
            }
        }
        out.sort_unstable();
        out.dedup();
    }
}

/// A uniform grid over the centres of the free objects, about two to a cell.
struct CentreGrid {
    lo: [f64; 2],
    cell_cm: f64,
    dims: [usize; 2],
    cells: Vec<Vec<u32>>,
}

impl CentreGrid {
    fn new(solids: &[Solid], free: &[usize]) -> Self {
        let mut lo = [f64::INFINITY; 2];
        let mut hi = [f64::NEG_INFINITY; 2];
        for &i in free {
            let p = [solids[i].x, solids[i].y];
            for k in 0..2 {
                lo[k] = lo[k].min(p[k]);
                hi[k] = hi[k].max(p[k]);
            }
        }
        if free.is_empty() {
            lo = [0.0; 2];
            hi = [0.0; 2];
        }
        let spread = (hi[0] - lo[0]).max(hi[1] - lo[1]);
        let (cell_cm, dims) = grid_shape(lo, hi, free.len(), 0.5, spread * 1e-9);
        let mut grid = Self {
            lo,
            cell_cm,
            dims,
            cells: vec![Vec::new(); dims[0] * dims[1]],
        };
        for &i in free {
            let (x, y) = grid.cell_of(solids[i].x, solids[i].y);
            grid.cells[y * dims[0] + x].push(i as u32);
        }
        grid
    }

    fn cell_of(&self, x: f64, y: f64) -> (usize, usize) {
        let index = |v: f64, axis: usize| {
            let i = ((v - self.lo[axis]) / self.cell_cm).floor();
            if i.is_nan() || i < 0.0 {
                0
            } else {
                (i as usize).min(self.dims[axis] - 1)
            }
        };
        (index(x, 0), index(y, 1))
    }

    /// Rings 0 to this minus one from any cell cover every cell.
    fn rings(&self) -> usize {
        self.dims[0].max(self.dims[1])
    }

    /// Calls `f` with each cell at Chebyshev distance `ring` from `(cx, cy)`.
    fn ring(&self, cx: usize, cy: usize, ring: usize, mut f: impl FnMut(&[u32])) {
        let [w, h] = self.dims.map(|d| d as i64);
        let (cx, cy, r) = (cx as i64, cy as i64, ring as i64);
        let mut visit = |x: i64, y: i64| {
            if (0..w).contains(&x) && (0..h).contains(&y) {
                f(&self.cells[(y * w + x) as usize]);
            }
        };
        if r == 0 {
            visit(cx, cy);
            return;
        }
        for x in (cx - r).max(-1)..=(cx + r).min(w) {
            visit(x, cy - r);
            visit(x, cy + r);
        }
        for y in (cy - r + 1).max(-1)..=(cy + r - 1).min(h) {
            visit(cx - r, y);
            visit(cx + r, y);
        }
    }
}

fn distance_3d(a: &Solid, b: &Solid) -> f64 {
    let (dx, dy, dz) = (a.x - b.x, a.y - b.y, a.z - b.z);
    (dx * dx + dy * dy + dz * dz).sqrt()
}

/// The distance limit of horizontal pairs, `distance_3d(a, b) <= limit`, decided on squared
/// distances where they are clear of the limit by a relative 1e-12 (far more than their
/// rounding), and by the square root itself near it: the same answers, without a square root
/// for almost every pair.
struct Within {
    limit: f64,
    surely_in: f64,
    surely_out: f64,
}

impl Within {
    fn new(limit: f64) -> Self {
        let squared = limit * limit;
        Self {
            limit,
            surely_in: squared * (1.0 - 1e-12),
            surely_out: squared * (1.0 + 1e-12),
        }
    }

    #[cfg(test)]
    fn holds(&self, a: &Solid, b: &Solid) -> bool {
        let (dx, dy, dz) = (a.x - b.x, a.y - b.y, a.z - b.z);
        self.holds_squared(dx * dx + dy * dy + dz * dz)
    }

    /// Whether a squared distance is within the limit.
    fn holds_squared(&self, squared: f64) -> bool {
        if squared < self.surely_in {
            true
        } else if squared > self.surely_out {
            false
        } else {
            squared.sqrt() <= self.limit
        }
    }
}

/// The optional `are equally spaced along` triples, along x then y.
fn spacings<'a>(
    solids: &[Solid],
    free: &[usize],
    objects: &'a [SceneObject],
) -> Vec<EquallySpaced<'a>> {
    let name = |i: usize| objects[i].instance.as_str();
    let mut out = Vec::new();
    for axis in [Axis::X, Axis::Y] {
        let along = |i: usize| match axis {
            Axis::X => solids[i].x,
            Axis::Y => solids[i].y,
        };
        let across = |i: usize| match axis {
            Axis::X => solids[i].y,
            Axis::Y => solids[i].x,
        };
        let mut sorted = free.to_vec();
        sorted.sort_by(|&a, &b| along(a).total_cmp(&along(b)));
        for i in 0..sorted.len() {
            for j in i + 1..sorted.len() {
                for k in j + 1..sorted.len() {
                    let (a, b, c) = (sorted[i], sorted[j], sorted[k]);
                    let g1 = along(b) - along(a);
                    let g2 = along(c) - along(b);
                    if g1 <= 0.0 || g2 <= 0.0 {
                        continue;
                    }
                    if (g1 - g2).abs() > SPACING_MAX_GAP_DIFFERENCE_SHARE * g1.max(g2) {
                        continue;
                    }
                    let values = [across(a), across(b), across(c)];
                    let spread = values.iter().copied().fold(f64::NEG_INFINITY, f64::max)
                        - values.iter().copied().fold(f64::INFINITY, f64::min);
                    if spread > SPACING_MAX_SPREAD_CM {
                        continue;
                    }
                    out.push(EquallySpaced {
                        instances: [name(a), name(b), name(c)],
                        axis,
                        gaps_cm: [g1, g2],
                        spread_cm: spread,
                    });
                }
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_abs_diff_eq;
    use proptest::prelude::*;

    fn obj(instance: &str, position_cm: [f64; 3], size_cm: [f64; 3], yaw_deg: f64) -> SceneObject {
        SceneObject::new(instance, position_cm, size_cm, yaw_deg)
    }

    fn scene(zone_cm: [f64; 4], objects: Vec<SceneObject>) -> GraphScene {
        GraphScene { zone_cm, objects }
    }

    /// The graph with the keyword container rule.
    fn graph_of<'a>(scene: &'a GraphScene, options: &GraphOptions) -> SceneGraph<'a> {
        extract_graph(scene, &keyword_containers(scene, options), options).expect("valid scene")
    }

    /// The edge lines only (no `is at` / `face to`).
    fn edges(scene: &GraphScene) -> Vec<String> {
        graph_of(scene, &GraphOptions::default())
            .edges
            .iter()
            .map(Edge::triplet)
            .collect()
    }

    fn lines(scene: &GraphScene) -> Vec<String> {
        graph_of(scene, &GraphOptions::default()).triplet_lines()
    }

    // --- nodes ---------------------------------------------------------------------------

    #[test]
    fn is_at_uses_20_and_15_percent_bands_with_edges_in_the_middle() {
        let cases = [
            ([10.0, 10.0], "front_left"),
            ([50.0, 10.0], "front_middle"),
            ([90.0, 10.0], "front_right"),
            ([10.0, 50.0], "middle_left"),
            ([50.0, 50.0], "center"),
            ([90.0, 50.0], "middle_right"),
            ([10.0, 90.0], "back_left"),
            ([50.0, 90.0], "back_middle"),
            ([90.0, 90.0], "back_right"),
            // Exactly on a band edge: the middle band (the bounds are strict).
            ([20.0, 15.0], "center"),
            ([80.0, 85.0], "center"),
            ([19.999, 85.001], "back_left"),
            ([80.001, 14.999], "front_right"),
        ];
        let objects = cases
            .iter()
            .enumerate()
            .map(|(i, ([x, y], _))| obj(&format!("o_{i}"), [*x, *y, 0.5], [1.0, 1.0, 1.0], 0.0))
            .collect();
        let layout = scene([0.0, 100.0, 0.0, 100.0], objects);
        let graph = graph_of(&layout, &GraphOptions::default());
        for (node, (_, label)) in graph.nodes.iter().zip(cases) {
            assert_eq!(
                node.is_at.label(),
                label,
                "{}: {:?}",
                node.instance,
                node.zone_fraction
            );
        }
    }

    #[test]
    fn is_at_is_relative_to_the_zone_origin() {
        // fx = (120 - 100) / 100 = 0.2: the middle band, not left.
        let s = scene(
            [100.0, 200.0, 50.0, 150.0],
            vec![obj("cup_0", [120.0, 64.0, 5.0], [8.0, 8.0, 10.0], 0.0)],
        );
        assert_eq!(lines(&s)[0], "(cup_0, is at, front_middle)");
        assert_eq!(zone_fraction(3.0, 1.0, 0.0), 0.5);
        assert_eq!(zone_fraction(3.0, 1.0, 4.0), 0.5);
    }

    #[test]
    fn face_to_sectors_are_centred_on_the_directions() {
        let cases = [
            (0.0, "front"),
            (22.4999, "front"),
            (22.5, "front_right"),
            (45.0, "front_right"),
            (67.5, "right"),
            (90.0, "right"),
            (135.0, "back_right"),
            (157.4, "back_right"),
            (157.5, "back"),
            (180.0, "back"),
            (-180.0, "back"),
            (-157.5, "back_left"),
            (-157.6, "back"),
            (-135.0, "back_left"),
            (-90.0, "left"),
            (-45.0, "front_left"),
            (-22.5, "front"),
            (-22.5001, "front_left"),
            (270.0, "left"),
            (360.0, "front"),
            (810.0, "right"),
            (-337.5, "front_right"),
            (72.2, "right"),
        ];
        for (yaw, label) in cases {
            assert_eq!(Facing::from_yaw_deg(yaw).label(), label, "yaw {yaw}");
        }
    }

    /// The rule as SCENE_GRAPH.md writes it, in floating point throughout.
    fn literal_facing(yaw_deg: f64) -> Facing {
        let a = (yaw_deg + 180.0).rem_euclid(360.0) - 180.0;
        let k = ((a + 22.5) / 45.0).floor().rem_euclid(8.0);
        Facing::ALL[(k as usize) % 8]
    }

    #[test]
    fn face_to_is_the_literal_rule_at_every_sector_edge() {
        let mut yaws = vec![
            f64::NAN,
            f64::INFINITY,
            f64::NEG_INFINITY,
            1e300,
            -1e300,
            -1e-300,
        ];
        for k in -40..=40 {
            let edge = 22.5 * f64::from(k);
            let (mut below, mut above) = (edge, edge);
            for _ in 0..4 {
                yaws.extend([below, above]);
                below = below.next_down();
                above = above.next_up();
            }
        }
        // And a sweep, every 1/64 of a degree over three turns.
        yaws.extend((-34_560..34_560).map(|i| f64::from(i) / 64.0));
        for yaw in yaws {
            assert_eq!(Facing::from_yaw_deg(yaw), literal_facing(yaw), "yaw {yaw}");
        }
    }

    // --- horizontal labels -----------------------------------------------------------------

    #[test]
    fn horizontal_label_ties_go_to_y() {
        assert_eq!(Relation::horizontal(3.0, 2.0), Relation::RightOf);
        assert_eq!(Relation::horizontal(-3.0, 2.0), Relation::LeftOf);
        assert_eq!(Relation::horizontal(2.0, 3.0), Relation::Behind);
        assert_eq!(Relation::horizontal(2.0, -3.0), Relation::InFrontOf);
        // |dx| = |dy|: y decides.
        assert_eq!(Relation::horizontal(3.0, 3.0), Relation::Behind);
        assert_eq!(Relation::horizontal(3.0, -3.0), Relation::InFrontOf);
        assert_eq!(Relation::horizontal(-3.0, 3.0), Relation::Behind);
        // Same centre: in front of.
        assert_eq!(Relation::horizontal(0.0, 0.0), Relation::InFrontOf);
    }

    #[test]
    fn diagonal_neighbours_are_front_or_behind() {
        // dx = dy = -10 for a (first in layout, so the subject).
        let s = scene(
            [0.0, 100.0, 0.0, 100.0],
            vec![
                obj("book_0", [40.0, 40.0, 1.0], [4.0, 4.0, 2.0], 0.0),
                obj("book_1", [50.0, 50.0, 1.0], [4.0, 4.0, 2.0], 0.0),
                obj("book_2", [30.0, 50.0, 1.0], [4.0, 4.0, 2.0], 0.0),
            ],
        );
        // book_0 → book_1 (14.1), book_2 (14.1, dx = 10, dy = -10): both in front of.
        // book_1 → book_2: dx = 20, dy = 0.
        assert_eq!(
            edges(&s),
            [
                "(book_0, in front of, book_1)",
                "(book_0, in front of, book_2)",
                "(book_1, right of, book_2)",
            ]
        );
    }

    /// The merge of the two runs of subjects gives what a stable sort by subject gives, each
    /// subject's pairs in the order they were chosen. The control: the runs as they come are
    /// not grouped by subject, so the merge has work to do.
    #[test]
    fn pairs_are_grouped_by_subject_as_a_stable_sort_groups_them() {
        // Not raised: subjects 0, 2, 5; raised: 1, 3, 6 (ranks tell the pairs apart).
        let low = [(0, 4, 0), (0, 2, 1), (2, 7, 0), (5, 1, 0), (5, 0, 2)];
        let high = [(1, 3, 0), (3, 6, 0), (3, 1, 1), (6, 3, 2)];
        for (low, high) in [
            (&low[..], &high[..]),
            (&low[..], &[][..]),
            (&[][..], &high[..]),
        ] {
            let pairs: Vec<Pair> = low.iter().chain(high).copied().collect();
            let mut sorted = pairs.clone();
            sorted.sort_by_key(|pair| pair.0);
            assert_eq!(group_by_subject(&pairs, low.len(), &mut Vec::new()), sorted);
            if !low.is_empty() && !high.is_empty() {
                assert_ne!(pairs, sorted, "the control: the runs need merging");
            }
        }
    }

    // --- footprint geometry ----------------------------------------------------------------

    #[test]
    fn intersection_of_axis_aligned_rectangles_is_exact() {
        let a = Footprint::new(10.0, 10.0, 0.0);
        let b = Footprint::new(10.0, 10.0, 90.0);
        assert_eq!(intersection_area_footprints(&a, &a, [0.0, 0.0]), 100.0);
        assert_eq!(intersection_area_footprints(&a, &b, [6.0, 0.0]), 40.0);
        assert_eq!(intersection_area_footprints(&a, &a, [10.0, 0.0]), 0.0);
        let long = Footprint::new(20.0, 4.0, 90.0);
        assert_eq!(long.half_extent_cm, [2.0, 10.0]);
        assert!(long.axis_aligned);
        assert_eq!(intersection_area_footprints(&a, &long, [0.0, 0.0]), 40.0);
    }

    #[test]
    fn intersection_of_a_square_and_its_45_degree_turn_is_the_octagon() {
        let a = Footprint::new(1.0, 1.0, 0.0);
        let b = Footprint::new(1.0, 1.0, 45.0);
        let octagon = 2.0 * (2f64.sqrt() - 1.0);
        assert_abs_diff_eq!(
            intersection_area_footprints(&a, &b, [0.0, 0.0]),
            octagon,
            epsilon = 1e-12
        );
        assert_abs_diff_eq!(
            intersection_area_footprints(&b, &a, [0.0, 0.0]),
            octagon,
            epsilon = 1e-12
        );
    }

    #[test]
    fn a_diagonal_strip_covers_the_centre_band_of_a_square() {
        // A 40×4 board turned 45° under a 6×6 square centred on it: the square minus two
        // corner triangles with legs 6 - 2√2, area 24√2 - 8.
        let board = Footprint::new(40.0, 4.0, 45.0);
        let square = Footprint::new(6.0, 6.0, 0.0);
        let expected = 24.0 * 2f64.sqrt() - 8.0;
        assert_abs_diff_eq!(
            intersection_area_footprints(&square, &board, [0.0, 0.0]),
            expected,
            epsilon = 1e-9
        );
        // Far off the diagonal but inside the board's bounding box: the AABBs overlap, the
        // rectangles do not.
        assert!(board.half_extent_cm[0] > 15.0);
        assert_eq!(
            intersection_area_footprints(&square, &board, [12.0, -12.0]),
            0.0
        );
    }

    #[test]
    fn a_rotated_footprint_whose_box_overlaps_supports_nothing() {
        // The board's bounding box reaches (38, 62), its rectangle does not: no `above`.
        let board = obj("board_0", [50.0, 50.0, 1.0], [40.0, 4.0, 2.0], 45.0);
        let corner = obj("cube_0", [38.0, 62.0, 4.0], [6.0, 6.0, 4.0], 0.0);
        let s = scene([0.0, 100.0, 0.0, 100.0], vec![board.clone(), corner]);
        // cube_0 is raised (z_min 2) and board_0 is not: board_0 visits first; dx = -12 and
        // dy = 12 tie, so y decides.
        assert_eq!(edges(&s), ["(board_0, in front of, cube_0)"]);
        // The same cube centred on the board: 72% of it is over the board.
        let centred = obj("cube_0", [50.0, 50.0, 4.0], [6.0, 6.0, 4.0], 0.0);
        let s = scene([0.0, 100.0, 0.0, 100.0], vec![board, centred]);
        assert_eq!(
            edges(&s),
            ["(cube_0, above, board_0)", "(board_0, in front of, cube_0)"]
        );
        let graph = graph_of(&s, &GraphOptions::default());
        let Evidence::Support {
            footprint_share,
            z_gap_cm,
        } = graph.edges[0].evidence
        else {
            panic!("support evidence expected");
        };
        assert_abs_diff_eq!(
            footprint_share,
            (24.0 * 2f64.sqrt() - 8.0) / 36.0,
            epsilon = 1e-9
        );
        assert_eq!(z_gap_cm, 0.0);
    }

    #[test]
    fn the_distance_limit_on_squares_answers_as_the_square_root() {
        let solid = |x: f64, y: f64, z: f64| Solid::new(&obj("a_0", [x, y, z], [1.0; 3], 0.0));
        let origin = solid(0.0, 0.0, 0.0);
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(11);
        let (mut checked, mut naive_wrong) = (0, 0);
        for _ in 0..20_000 {
            // A limit, and a point at that distance give or take a few units in the last place.
            let limit: f64 = rng.random_range(0.01..500.0);
            let direction = [
                rng.random_range(-1.0..1.0f64),
                rng.random_range(-1.0..1.0f64),
                rng.random_range(-1.0..1.0f64),
            ];
            let norm = direction.iter().map(|v| v * v).sum::<f64>().sqrt();
            let ulps = rng.random_range(-4i64..=4);
            let scale = f64::from_bits((limit / norm).to_bits().wrapping_add_signed(ulps));
            let point = solid(
                direction[0] * scale,
                direction[1] * scale,
                direction[2] * scale,
            );
            let exact = distance_3d(&point, &origin) <= limit;
            assert_eq!(
                Within::new(limit).holds(&point, &origin),
                exact,
                "{limit} {scale}"
            );
            let (dx, dy, dz) = (point.x, point.y, point.z);
            naive_wrong += usize::from((dx * dx + dy * dy + dz * dz <= limit * limit) != exact);
            checked += 1;
        }
        // Control: comparing squares without the square root near the limit gets some wrong.
        assert!(naive_wrong > 0, "{naive_wrong} of {checked}");
        // Far from the limit, no square root is needed and the answer is plain.
        let within = Within::new(10.0);
        assert!(within.holds(&solid(3.0, 4.0, 0.0), &origin));
        assert!(within.holds(&solid(6.0, 8.0, 0.0), &origin));
        assert!(!within.holds(&solid(6.0, 8.0, 0.001), &origin));
    }

    #[test]
    fn exact_turns_have_exact_sines() {
        assert_eq!(sin_cos_deg(90.0), (1.0, 0.0));
        assert_eq!(sin_cos_deg(-90.0), (-1.0, 0.0));
        assert_eq!(sin_cos_deg(540.0), (0.0, -1.0));
        let (s, c) = sin_cos_deg(30.0);
        assert_abs_diff_eq!(s, 0.5, epsilon = 1e-15);
        assert_abs_diff_eq!(c, 3f64.sqrt() / 2.0, epsilon = 1e-15);
    }

    // --- containment -----------------------------------------------------------------------

    #[test]
    fn fruit_in_a_bowl_on_a_tray() {
        let s = scene(
            [0.0, 100.0, 0.0, 60.0],
            vec![
                obj("tray_0", [50.0, 30.0, 1.0], [40.0, 30.0, 2.0], 0.0),
                obj("bowl_0", [55.0, 32.0, 6.0], [20.0, 20.0, 8.0], 0.0),
                obj("apple_0", [57.0, 32.0, 6.0], [6.0, 6.0, 6.0], 0.0),
            ],
        );
        // apple_0 in bowl_0: footprint fully inside, z overlap 6 of 6, centre 6 > bowl bottom 2.
        // A tray is not a container, so the bowl is above it (bottom 2 > top 2 - 1).
        // Horizontal: the tray (not raised) keeps the bowl (raised: bottom 2 > 0.5); the apple
        // takes part in nothing else.
        assert_eq!(
            lines(&s),
            [
                "(tray_0, is at, center)",
                "(tray_0, face to, front)",
                "(bowl_0, is at, center)",
                "(bowl_0, face to, front)",
                "(apple_0, is at, center)",
                "(apple_0, face to, front)",
                "(apple_0, in, bowl_0)",
                "(bowl_0, above, tray_0)",
                "(tray_0, left of, bowl_0)",
            ]
        );
        let graph = graph_of(&s, &GraphOptions::default());
        assert_eq!(
            graph.edges[0].evidence,
            Evidence::Containment {
                footprint_share: 1.0,
                z_share: 1.0,
                subject_area_cm2: 36.0,
                container_area_cm2: 400.0,
            }
        );
        assert!(graph.nodes[1].container && !graph.nodes[0].container);
    }

    #[test]
    fn the_smallest_qualifying_container_wins_and_nests() {
        let s = scene(
            [0.0, 100.0, 0.0, 100.0],
            vec![
                obj("box_0", [50.0, 50.0, 10.0], [60.0, 60.0, 20.0], 0.0),
                obj("bowl_0", [50.0, 50.0, 5.0], [30.0, 30.0, 10.0], 0.0),
                obj("apple_0", [50.0, 50.0, 4.0], [6.0, 6.0, 6.0], 0.0),
            ],
        );
        // The apple qualifies for both; the bowl is smaller. The bowl is in the box. Nothing
        // is left for the other relations.
        assert_eq!(edges(&s), ["(bowl_0, in, box_0)", "(apple_0, in, bowl_0)"]);
    }

    #[test]
    fn equal_containers_tie_on_layout_order() {
        let s = scene(
            [0.0, 100.0, 0.0, 100.0],
            vec![
                obj("bin_1", [50.0, 50.0, 5.0], [20.0, 20.0, 10.0], 0.0),
                obj("bin_0", [51.0, 50.0, 5.0], [20.0, 20.0, 10.0], 0.0),
                obj("pen_0", [50.0, 50.0, 4.0], [1.0, 12.0, 1.0], 0.0),
            ],
        );
        // The bins hold each other too, by the thresholds, at equal centre heights: the later
        // one in layout order (bin_0) is in the earlier one.
        assert_eq!(edges(&s), ["(bin_0, in, bin_1)", "(pen_0, in, bin_1)"]);
    }

    #[test]
    fn two_identical_cups_stacked_give_one_in() {
        let s = scene(
            [0.0, 100.0, 0.0, 100.0],
            vec![
                obj("cup_0", [30.0, 30.0, 5.0], [8.0, 8.0, 10.0], 0.0),
                obj("cup_1", [30.0, 30.0, 7.0], [8.0, 8.0, 10.0], 0.0),
            ],
        );
        // Each qualifies as the other's container; the upper one is in the lower one.
        assert_eq!(edges(&s), ["(cup_1, in, cup_0)"]);
        let flipped = scene(s.zone_cm, vec![s.objects[1].clone(), s.objects[0].clone()]);
        assert_eq!(edges(&flipped), ["(cup_1, in, cup_0)"]);
    }

    #[test]
    fn containment_thresholds_are_inclusive() {
        let bin = obj("bin_0", [50.0, 50.0, 5.0], [20.0, 20.0, 10.0], 0.0);
        // Footprint: x [51, 61] against [40, 60]: 9 × 10 = 90 of 100 = 0.9 exactly.
        let at_90 = obj("block_0", [56.0, 50.0, 5.0], [10.0, 10.0, 4.0], 0.0);
        let s = scene([0.0, 100.0, 0.0, 100.0], vec![bin.clone(), at_90]);
        assert_eq!(edges(&s), ["(block_0, in, bin_0)"]);
        // 8.5 of 10: 0.85, not in; the block's centre is only 6.5 away: a horizontal pair.
        let at_85 = obj("block_0", [56.5, 50.0, 5.0], [10.0, 10.0, 4.0], 0.0);
        let s = scene([0.0, 100.0, 0.0, 100.0], vec![bin.clone(), at_85]);
        assert_eq!(edges(&s), ["(bin_0, left of, block_0)"]);
        // z: [8, 12] against [0, 10]: 2 of min(4, 10) = 0.5 exactly.
        let z_half = obj("block_0", [50.0, 50.0, 10.0], [10.0, 10.0, 4.0], 0.0);
        let s = scene([0.0, 100.0, 0.0, 100.0], vec![bin.clone(), z_half]);
        assert_eq!(edges(&s), ["(block_0, in, bin_0)"]);
        // [8.5, 12.5]: 0.375, not in; nor above (bottom 8.5 is not above 10 - 1); raised, so
        // the bin (table level) writes the pair.
        let z_less = obj("block_0", [50.0, 50.0, 10.5], [10.0, 10.0, 4.0], 0.0);
        let s = scene([0.0, 100.0, 0.0, 100.0], vec![bin, z_less]);
        assert_eq!(edges(&s), ["(bin_0, in front of, block_0)"]);
    }

    #[test]
    fn containment_needs_a_container_as_large_and_a_centre_above_its_bottom() {
        // A cup smaller than the plate on it holds nothing; the plate, mostly overhanging (64
        // of 400), is not above it either. The raised plate comes after the cup.
        let s = scene(
            [0.0, 100.0, 0.0, 100.0],
            vec![
                obj("plate_0", [50.0, 50.0, 10.5], [20.0, 20.0, 1.0], 0.0),
                obj("cup_0", [50.0, 50.0, 5.0], [8.0, 8.0, 10.0], 0.0),
            ],
        );
        assert_eq!(edges(&s), ["(cup_0, in front of, plate_0)"]);
        // An 8 × 8 plate on it: its whole footprint is over the cup.
        let s = scene(
            s.zone_cm,
            vec![
                obj("plate_0", [50.0, 50.0, 10.5], [8.0, 8.0, 1.0], 0.0),
                s.objects[1].clone(),
            ],
        );
        assert_eq!(
            edges(&s),
            ["(plate_0, above, cup_0)", "(cup_0, in front of, plate_0)"]
        );
        // A tall rod through a raised bin: centre 10 is not above the bin's bottom 10.
        let s = scene(
            [0.0, 100.0, 0.0, 100.0],
            vec![
                obj("bin_0", [50.0, 50.0, 15.0], [20.0, 20.0, 10.0], 0.0),
                obj("rod_0", [50.0, 50.0, 10.0], [2.0, 2.0, 20.0], 0.0),
            ],
        );
        assert_eq!(edges(&s), ["(rod_0, in front of, bin_0)"]);
        // Raise the rod by 0.5: centre 10.5 > 10, overlap 9.5 of 10.
        let s = scene(
            s.zone_cm,
            vec![
                s.objects[0].clone(),
                obj("rod_0", [50.0, 50.0, 10.5], [2.0, 2.0, 20.0], 0.0),
            ],
        );
        assert_eq!(edges(&s), ["(rod_0, in, bin_0)"]);
    }

    #[test]
    fn explicit_flags_override_keywords() {
        let s = scene(
            [0.0, 100.0, 0.0, 100.0],
            vec![
                obj("tray_0", [50.0, 50.0, 2.0], [40.0, 30.0, 4.0], 0.0),
                obj("apple_0", [50.0, 50.0, 3.0], [6.0, 6.0, 6.0], 0.0),
            ],
        );
        // By keywords a tray holds nothing; the apple (bottom 0) is not above it either.
        assert_eq!(edges(&s), ["(tray_0, in front of, apple_0)"]);
        let options = GraphOptions::default();
        let graph = extract_graph(&s, &[true, false], &options).expect("valid");
        assert_eq!(
            graph.edges.iter().map(Edge::triplet).collect::<Vec<_>>(),
            ["(apple_0, in, tray_0)"]
        );
    }

    #[test]
    fn annotations_decide_containers_and_keywords_fill_in() {
        use crate::annotations::AssetAnnotation;
        let s = scene(
            [0.0, 100.0, 0.0, 100.0],
            vec![
                obj("tray_0", [50.0, 50.0, 2.0], [40.0, 30.0, 4.0], 0.0),
                obj("bowl_0", [20.0, 50.0, 4.0], [12.0, 12.0, 8.0], 0.0),
                obj("mug_0", [80.0, 50.0, 5.0], [8.0, 8.0, 10.0], 0.0),
                obj("cup_0", [80.0, 20.0, 5.0], [8.0, 8.0, 10.0], 0.0),
                obj("box_0", [20.0, 20.0, 5.0], [8.0, 8.0, 10.0], 0.0),
            ],
        );
        let mut annotations = Annotations::default();
        let flag = |is_container| AssetAnnotation {
            is_container,
            ..AssetAnnotation::default()
        };
        annotations.insert("tray-uid", flag(Some(true)));
        annotations.insert("bowl-uid", flag(Some(false)));
        annotations.insert("mug-uid", flag(None));
        let uids: Vec<String> = ["tray-uid", "bowl-uid", "mug-uid", "", "box-uid"]
            .map(String::from)
            .to_vec();
        let options = GraphOptions::default();
        let flags = annotated_containers(&s, &uids, Some(&annotations), &options);
        // The annotation overrides the keywords both ways; the rest fall back to them.
        assert_eq!(flags.flags, [true, false, true, true, true]);
        assert_eq!(
            flags.by_keyword,
            [
                "mug_0 (the annotation of mug-uid has no isContainer)",
                "cup_0 (no retrieved_uid)",
                "box_0 (asset box-uid is not annotated)",
            ]
        );
        let none = annotated_containers(&s, &uids, None, &options);
        assert_eq!(none.flags, keyword_containers(&s, &options));
        assert_eq!(none.by_keyword[0], "tray_0 (no annotations file)");
    }

    #[test]
    fn keyword_rule_matches_whole_categories_and_suffixes() {
        let keywords = GraphOptions::default().container_keywords;
        for yes in [
            "bowl_0",
            "fruit_bowl_1",
            "teacup_2",
            "Mug_0",
            "pencil_holder_3",
            "bowl",
            "storage_box_10",
        ] {
            assert!(is_keyword_container(yes, &keywords), "{yes}");
        }
        for no in ["tray_0", "cupboard_0", "plate_1", "bowl_lid_0", "pen_0"] {
            assert!(!is_keyword_container(no, &keywords), "{no}");
        }
        let none = GraphOptions::default().with_container_keywords([]);
        assert!(!is_keyword_container("bowl_0", &none.container_keywords));
        let custom = GraphOptions::default().with_container_keywords([" Tray ", ""]);
        assert_eq!(custom.container_keywords, ["tray"]);
        assert!(is_keyword_container(
            "serving_tray_0",
            &custom.container_keywords
        ));
    }

    // --- above -----------------------------------------------------------------------------

    #[test]
    fn two_plates_stacked_and_a_third_on_top() {
        let s = scene(
            [0.0, 100.0, 0.0, 100.0],
            vec![
                obj("plate_0", [30.0, 30.0, 1.0], [25.0, 25.0, 2.0], 0.0),
                obj("plate_1", [30.0, 30.0, 3.0], [25.0, 25.0, 2.0], 0.0),
                obj("plate_2", [30.0, 30.0, 5.0], [25.0, 25.0, 2.0], 0.0),
            ],
        );
        // plate_2 qualifies over plate_0 (top 2) and plate_1 (top 4): the highest top wins.
        // Horizontal: plate_0 (table level) keeps both at distance 0 (layout order); plate_1
        // (raised) then writes the last pair.
        assert_eq!(
            edges(&s),
            [
                "(plate_1, above, plate_0)",
                "(plate_2, above, plate_1)",
                "(plate_0, in front of, plate_1)",
                "(plate_0, in front of, plate_2)",
                "(plate_1, in front of, plate_2)",
            ]
        );
    }

    #[test]
    fn above_thresholds_and_ties() {
        // A 30×10 board straddling two books: exactly half of it over each. Equal tops: the
        // earlier book in layout order.
        let book_0 = obj("book_0", [40.0, 50.0, 2.0], [20.0, 20.0, 4.0], 0.0);
        let book_1 = obj("book_1", [60.0, 50.0, 2.0], [20.0, 20.0, 4.0], 0.0);
        let board = obj("board_0", [50.0, 50.0, 4.5], [30.0, 10.0, 1.0], 0.0);
        let s = scene(
            [0.0, 100.0, 0.0, 100.0],
            vec![book_0.clone(), book_1, board.clone()],
        );
        assert_eq!(edges(&s)[0], "(board_0, above, book_0)");
        // book_1 taller (top 4.5): the highest top wins although the board sinks 0.5 into it.
        let tall = obj("book_1", [60.0, 50.0, 2.25], [20.0, 20.0, 4.5], 0.0);
        let s = scene([0.0, 100.0, 0.0, 100.0], vec![book_0.clone(), tall, board]);
        assert_eq!(edges(&s)[0], "(board_0, above, book_1)");
        // Sinking exactly 1 cm is too much; 0.999 is not.
        let sunk = obj("board_0", [40.0, 50.0, 3.5], [30.0, 10.0, 1.0], 0.0);
        let s = scene([0.0, 100.0, 0.0, 100.0], vec![book_0.clone(), sunk]);
        assert!(!edges(&s).iter().any(|e| e.contains("above")));
        let barely = obj("board_0", [40.0, 50.0, 3.501], [30.0, 10.0, 1.0], 0.0);
        let s = scene([0.0, 100.0, 0.0, 100.0], vec![book_0, barely]);
        assert_eq!(edges(&s)[0], "(board_0, above, book_0)");
    }

    // --- horizontal ------------------------------------------------------------------------

    #[test]
    fn more_than_five_neighbours() {
        // Zone 25 × 25: the distance limit is 10. All objects at table level, 1 cm cubes-ish.
        let at = |name: &str, x: f64, y: f64| obj(name, [x, y, 1.0], [1.0, 1.0, 2.0], 0.0);
        let s = scene(
            [0.0, 25.0, 0.0, 25.0],
            vec![
                at("hub", 12.0, 12.0),
                at("n1", 12.0, 16.0),
                at("n2", 7.0, 12.0),
                at("n3", 12.0, 6.0),
                at("n4", 19.0, 12.0),
                at("n5", 12.0, 20.0),
                at("n6", 21.0, 12.0),
            ],
        );
        // hub: n1 4, n2 5, n3 6, n4 7, n5 8 kept; n6 (9) is sixth.
        // n1: hub 4 = n5 4 (layout order), n2 6.4, n4 8.06, n6 9.85 kept; n3 (10) sixth.
        // n2: hub 5, n1 6.4, n3 7.81, n5 9.43 (n4 12, n6 14 too far).
        // n3: hub 6, n2 7.81, n4 9.22, n1 10 (exactly the limit: kept).
        // n4: n6 2, hub 7, n1 8.06, n3 9.22. n5: all written already.
        // n6: n4 2, hub 9 (not yet written: hub dropped n6), n1 9.85.
        assert_eq!(
            edges(&s),
            [
                "(hub, in front of, n1)",
                "(hub, right of, n2)",
                "(hub, behind, n3)",
                "(hub, left of, n4)",
                "(hub, in front of, n5)",
                "(n1, in front of, n5)",
                "(n1, right of, n2)",
                "(n1, left of, n4)",
                "(n1, left of, n6)",
                "(n2, behind, n3)",
                "(n2, in front of, n5)",
                "(n3, left of, n4)",
                "(n3, in front of, n1)",
                "(n4, left of, n6)",
                "(n6, right of, hub)",
            ]
        );
        let graph = graph_of(&s, &GraphOptions::default());
        let Evidence::Proximity {
            rank,
            distance_3d_cm,
            max_distance_cm,
            ..
        } = graph.edges[12].evidence
        else {
            panic!("proximity evidence expected");
        };
        assert_eq!((rank, distance_3d_cm, max_distance_cm), (4, 10.0, 10.0));
    }

    #[test]
    fn raised_subjects_are_visited_last() {
        // phone_0 lies on book_0; glasses_0 on mug_0. Layout order puts phone_0 before
        // mug_0, but table-level objects visit first, so mug_0 writes their pair.
        let s = scene(
            [0.0, 100.0, 0.0, 100.0],
            vec![
                obj("book_0", [50.0, 50.0, 1.5], [30.0, 20.0, 3.0], 0.0),
                obj("phone_0", [52.0, 50.0, 3.5], [7.0, 14.0, 1.0], 0.0),
                obj("mug_0", [70.0, 50.0, 5.0], [8.0, 8.0, 10.0], 0.0),
                obj("glasses_0", [70.0, 50.0, 12.0], [12.0, 5.0, 4.0], 0.0),
                obj("pen_0", [50.0, 72.0, 0.5], [1.0, 14.0, 1.0], 0.0),
            ],
        );
        // glasses_0 over mug_0: 8 × 5 of 12 × 5 = 0.67, bottom 10 > top 10 - 1.
        // book_0: phone 2, mug 20 = glasses 20 (layout order), pen 22.
        // mug_0: glasses 0, phone 18, book (written), pen 29.7 (dx 20 < dy 22: in front of).
        // pen_0: book (written), phone 22.1, mug (written), glasses 29.7.
        // phone_0 (raised): book, mug skipped; glasses raised: written; pen skipped.
        assert_eq!(
            edges(&s),
            [
                "(phone_0, above, book_0)",
                "(glasses_0, above, mug_0)",
                "(book_0, left of, phone_0)",
                "(book_0, left of, mug_0)",
                "(book_0, left of, glasses_0)",
                "(book_0, in front of, pen_0)",
                "(phone_0, left of, glasses_0)",
                "(mug_0, in front of, glasses_0)",
                "(mug_0, right of, phone_0)",
                "(mug_0, in front of, pen_0)",
                "(pen_0, behind, phone_0)",
                "(pen_0, behind, glasses_0)",
            ]
        );
    }

    #[test]
    fn a_raised_subject_skips_table_level_neighbours() {
        // x sits among five nearer table-level neighbours, none of which keeps remote_0 in its
        // five; remote_0 is raised (bottom 1), so it may not write pairs to them itself.
        let at = |name: &str, x: f64, z: f64| obj(name, [x, 10.0, z], [1.0, 1.0, 1.0], 0.0);
        let table_level = || {
            vec![
                at("x", 10.0, 0.5),
                at("a", 9.0, 0.5),
                at("b", 8.0, 0.5),
                at("c", 7.0, 0.5),
                at("d", 6.0, 0.5),
                at("e", 5.0, 0.5),
            ]
        };
        let expected_table_level = [
            "(x, right of, a)",
            "(x, right of, b)",
            "(x, right of, c)",
            "(x, right of, d)",
            "(x, right of, e)",
            "(a, right of, b)",
            "(a, right of, c)",
            "(a, right of, d)",
            "(a, right of, e)",
            "(b, right of, c)",
            "(b, right of, d)",
            "(b, right of, e)",
            "(c, right of, d)",
            "(c, right of, e)",
            "(d, right of, e)",
        ];
        let mut objects = table_level();
        objects.push(at("remote_0", 16.0, 1.5));
        let s = scene([0.0, 25.0, 0.0, 25.0], objects);
        assert_eq!(edges(&s), expected_table_level);
        // Lowered to the table, remote_0 writes its five: x 6, a 7, b 8, c 9, d 10 (the limit).
        let mut objects = table_level();
        objects.push(at("remote_0", 16.0, 0.5));
        let s = scene([0.0, 25.0, 0.0, 25.0], objects);
        let mut expected: Vec<String> = expected_table_level
            .iter()
            .map(|e| (*e).to_owned())
            .collect();
        for o in ["x", "a", "b", "c", "d"] {
            expected.push(format!("(remote_0, right of, {o})"));
        }
        assert_eq!(edges(&s), expected);
    }

    #[test]
    fn the_distance_limit_is_in_space_and_inclusive() {
        // Zone 100 × 50: limit 40. The pen is 40 from the cup in the plane but, 4.5 lower,
        // 40.25 away in space: not related. The clock hangs 31 over the cup, entirely over
        // it: above it, at any height.
        let lamp = obj("lamp_0", [20.0, 25.0, 20.0], [10.0, 10.0, 40.0], 0.0);
        let cup = obj("cup_0", [50.0, 25.0, 5.0], [8.0, 8.0, 10.0], 0.0);
        let clock = obj("clock_0", [50.0, 25.0, 35.0], [8.0, 2.0, 8.0], 0.0);
        let s = scene(
            [0.0, 100.0, 0.0, 50.0],
            vec![
                lamp.clone(),
                cup.clone(),
                clock.clone(),
                obj("pen_0", [90.0, 25.0, 0.5], [1.0, 10.0, 1.0], 0.0),
            ],
        );
        let expected = [
            "(clock_0, above, cup_0)",
            "(lamp_0, left of, cup_0)",
            "(lamp_0, left of, clock_0)",
            "(cup_0, in front of, clock_0)",
        ];
        assert_eq!(edges(&s), expected);
        // At the cup's height the pen is exactly 40 away: related.
        let s = scene(
            s.zone_cm,
            vec![
                lamp,
                cup,
                clock,
                obj("pen_0", [90.0, 25.0, 5.0], [1.0, 10.0, 10.0], 0.0),
            ],
        );
        let mut with_pen: Vec<&str> = expected.to_vec();
        with_pen.push("(cup_0, left of, pen_0)");
        assert_eq!(edges(&s), with_pen);
    }

    // --- output order and forms --------------------------------------------------------------

    #[test]
    fn dataset_layouts_keep_the_file_order() {
        use mesa_schemas::convert::dataset_from_llm;
        let llm = LlmLayout {
            zone_cm: [0.0, 100.0, 0.0, 100.0].into(),
            sink_zone_cm: None,
            objects: vec![
                mesa_schemas::LlmObject {
                    instance: "pen_0".into(),
                    size_cm: [1.0, 14.0, 1.0].into(),
                    position_cm: [10.0, 50.0, 0.5].into(),
                    z_rotation_deg: -90.0,
                    description: String::new(),
                },
                mesa_schemas::LlmObject {
                    instance: "book_0".into(),
                    size_cm: [20.0, 30.0, 3.0].into(),
                    position_cm: [30.0, 50.0, 1.5].into(),
                    z_rotation_deg: 180.0,
                    description: String::new(),
                },
            ],
        };
        let mut dataset = dataset_from_llm(&llm).layout;
        // Put the pen (the smaller footprint) first, as a file may, whatever the conversion did.
        dataset.objects.sort_by(|a, b| b.instance.cmp(&a.instance));
        let s = GraphScene::from_dataset(&dataset);
        assert_eq!(s, GraphScene::from_llm(&llm));
        assert_eq!(
            lines(&s),
            [
                "(pen_0, is at, middle_left)",
                "(pen_0, face to, left)",
                "(book_0, is at, center)",
                "(book_0, face to, back)",
                "(pen_0, left of, book_0)",
            ]
        );
    }

    #[test]
    fn text_and_artifact_forms() {
        let s = scene(
            [0.0, 100.0, 0.0, 100.0],
            vec![
                obj("bowl_0", [30.0, 30.0, 4.0], [20.0, 20.0, 8.0], 0.0),
                obj("apple_0", [30.0, 30.0, 5.0], [6.0, 6.0, 6.0], 0.0),
                obj("mug_0", [60.0, 30.0, 5.0], [8.0, 8.0, 10.0], 90.0),
            ],
        );
        let graph = graph_of(&s, &GraphOptions::default());
        let text = graph.to_text();
        assert!(text.ends_with("(bowl_0, left of, mug_0)\n"));
        assert_eq!(text.lines().count(), 8);
        let artifact = graph.to_artifact("office_table_0001", "qa/layout.json");
        assert_eq!(artifact.schema, GRAPH_SCHEMA);
        assert_eq!(artifact.nodes[2].face_to, "right");
        assert!(artifact.nodes[0].container);
        assert_eq!(artifact.edges[0].relation, "in");
        assert_eq!(artifact.edges[1].numbers["dx_cm"], -30.0);
        assert_eq!(artifact.edges[1].numbers["rank"], 1.0);
        assert!(artifact.equally_spaced.is_empty());
        let json = serde_json::to_value(&artifact).expect("serialises");
        assert!(json.get("equally_spaced").is_none());
        let problems = mesa_schemas::Kind::by_name("graph")
            .expect("graph kind")
            .validate_value(&json);
        assert!(problems.is_empty(), "{problems:?}");
        assert_eq!(
            SceneGraph {
                nodes: vec![],
                edges: vec![],
                equally_spaced: vec![]
            }
            .to_text(),
            ""
        );
    }

    /// `to_json` writes the bytes of the artifact's writer, and `sorted_numbers` gives each
    /// kind of evidence's numbers in the map's order, on a scene with every kind of edge and an
    /// equally-spaced triple; a changed number changes the bytes (so the comparison can fail).
    #[test]
    fn the_json_written_from_the_graph_is_the_artifacts() {
        let s = scene(
            [0.0, 100.0, 0.0, 100.0],
            vec![
                obj("bowl_0", [30.0, 30.0, 4.0], [20.0, 20.0, 8.0], 0.0),
                obj("apple_0", [30.0, 30.0, 5.0], [6.0, 6.0, 6.0], 0.0),
                obj("book_0", [60.0, 30.0, 1.0], [12.0, 16.0, 2.0], 30.0),
                obj("pen_0", [60.0, 30.0, 2.5], [1.0, 10.0, 1.0], 0.0),
                obj("cup_0", [10.0, 70.0, 5.0], [6.0, 6.0, 10.0], 0.0),
                obj("cup_1", [20.0, 70.0, 5.0], [6.0, 6.0, 10.0], 0.0),
                obj("cup_2", [30.0, 70.0, 5.0], [6.0, 6.0, 10.0], 0.0),
            ],
        );
        let options = GraphOptions::default().with_equally_spaced(true);
        let mut graph = graph_of(&s, &options);
        let kinds: Vec<&str> = graph
            .edges
            .iter()
            .map(|e| match e.evidence {
                Evidence::Containment { .. } => "in",
                Evidence::Support { .. } => "above",
                Evidence::Proximity { .. } => "near",
            })
            .collect();
        for kind in ["in", "above", "near"] {
            assert!(kinds.contains(&kind), "{kind} missing from {kinds:?}");
        }
        assert!(!graph.equally_spaced.is_empty());
        for edge in &graph.edges {
            // The names in strictly increasing byte order, as the artifact's map holds them.
            let names: Vec<&str> = edge.evidence.sorted_numbers().map(|(k, _)| k).collect();
            assert!(names.windows(2).all(|w| w[0] < w[1]), "{names:?}");
            assert_eq!(names.len(), edge.evidence.numbers().len());
        }
        let json = graph.to_json("office_table_0001", "qa/layout.json");
        let artifact = graph.to_artifact("office_table_0001", "qa/layout.json");
        assert_eq!(json, artifact.to_pretty_json());
        if let Evidence::Proximity { dx_cm, .. } =
            &mut graph.edges.last_mut().expect("edges").evidence
        {
            *dx_cm += 1e-9;
        }
        assert_ne!(graph.to_json("office_table_0001", "qa/layout.json"), json);
    }

    // --- equally spaced --------------------------------------------------------------------

    #[test]
    fn equally_spaced_is_optional_and_uses_its_tolerances() {
        let at = |name: &str, x: f64, y: f64| obj(name, [x, y, 0.5], [2.0, 2.0, 1.0], 0.0);
        let s = scene(
            [0.0, 100.0, 0.0, 100.0],
            vec![
                at("a", 10.0, 50.0),
                at("b", 20.0, 51.0),
                at("c", 31.0, 52.0),
                at("d", 43.0, 50.0),
                at("e", 43.0, 60.0),
            ],
        );
        assert!(graph_of(&s, &GraphOptions::default())
            .equally_spaced
            .is_empty());
        let graph = graph_of(&s, &GraphOptions::default().with_equally_spaced(true));
        let triples: Vec<String> = graph
            .equally_spaced
            .iter()
            .map(EquallySpaced::triplet)
            .collect();
        // Along x: a b c (gaps 10, 11: |1| ≤ 1.1; spread 2 ≤ 2); b c d (11, 12: 1 ≤ 1.2; spread
        // 2); a b d (10, 23) no; c d e (12, 0): a zero gap. Along y: a d e... gaps 0 no;
        // a b e? sorted y: a 50, d 50, b 51, c 52, e 60: (a, b, c) 1, 1 but spread along x 21.
        assert_eq!(
            triples,
            [
                "(a, b, c, are equally spaced along, x)",
                "(b, c, d, are equally spaced along, x)",
            ]
        );
        assert_eq!(graph.equally_spaced[0].gaps_cm, [10.0, 11.0]);
        assert_eq!(graph.equally_spaced[0].spread_cm, 2.0);
        assert_eq!(
            graph.triplet_lines().last().map(String::as_str),
            Some(triples[1].as_str())
        );
        // Gaps 10 and 12: 2 > 1.2.
        let s = scene(
            s.zone_cm,
            vec![
                at("a", 10.0, 50.0),
                at("b", 20.0, 50.0),
                at("c", 32.0, 50.0),
            ],
        );
        assert!(
            graph_of(&s, &GraphOptions::default().with_equally_spaced(true))
                .equally_spaced
                .is_empty()
        );
    }

    #[test]
    fn a_large_random_layout_gives_the_all_pairs_output() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(20);
        let count = 3000;
        // A table-like density: 15 objects per 120 × 70 cm, a fifth stacked on another one.
        let scale = (count as f64 / 15.0).sqrt();
        let (width, depth) = (120.0 * scale, 70.0 * scale);
        let mut objects: Vec<SceneObject> = Vec::with_capacity(count);
        for i in 0..count {
            let size = [
                rng.random_range(3.0..40.0),
                rng.random_range(3.0..40.0),
                rng.random_range(1.0..30.0),
            ];
            let yaw = if rng.random_bool(0.3) {
                rng.random_range(-180.0..180.0)
            } else {
                0.0
            };
            let mut position = [
                rng.random_range(0.0..width),
                rng.random_range(0.0..depth),
                size[2] / 2.0,
            ];
            if i > 0 && rng.random_bool(0.2) {
                let base = &objects[rng.random_range(0..i)];
                position = [
                    base.position_cm[0] + rng.random_range(-3.0..3.0),
                    base.position_cm[1] + rng.random_range(-3.0..3.0),
                    base.position_cm[2] + rng.random_range(0.0..base.size_cm[2]),
                ];
            }
            let category = CATEGORIES[rng.random_range(0..CATEGORIES.len())];
            objects.push(SceneObject::new(
                format!("{category}_{i}"),
                position,
                size,
                yaw,
            ));
        }
        let s = scene([0.0, width, 0.0, depth], objects);
        let options = GraphOptions::default();
        let flags = keyword_containers(&s, &options);
        let fast = extract(
            &s,
            &flags,
            &options,
            PairSearch::Grid,
            &mut Scratch::default(),
        )
        .expect("valid");
        let oracle = extract(
            &s,
            &flags,
            &options,
            PairSearch::Literal,
            &mut Scratch::default(),
        )
        .expect("valid");
        assert!(fast.edges.len() > count, "{}", fast.edges.len());
        assert!(fast.edges.iter().any(|e| e.relation == Relation::In));
        assert!(fast.edges.iter().any(|e| e.relation == Relation::Above));
        assert_eq!(fast, oracle);
        let all_pairs = extract(
            &s,
            &flags,
            &options,
            PairSearch::AllPairs,
            &mut Scratch::default(),
        )
        .expect("valid");
        assert_eq!(all_pairs, oracle);
    }

    #[test]
    fn equally_spaced_along_y_skips_contained_objects() {
        let s = scene(
            [0.0, 100.0, 0.0, 100.0],
            vec![
                obj("box_0", [50.0, 50.0, 5.0], [12.0, 12.0, 10.0], 0.0),
                obj("tin_0", [50.0, 30.0, 2.0], [4.0, 4.0, 4.0], 0.0),
                obj("tin_1", [51.0, 70.0, 2.0], [4.0, 4.0, 4.0], 0.0),
                obj("tin_2", [50.0, 50.0, 2.0], [4.0, 4.0, 4.0], 0.0),
            ],
        );
        // tin_2 is in box_0, so only box_0 is in the middle.
        let graph = graph_of(&s, &GraphOptions::default().with_equally_spaced(true));
        let triples: Vec<String> = graph
            .equally_spaced
            .iter()
            .map(EquallySpaced::triplet)
            .collect();
        assert_eq!(
            triples,
            ["(tin_0, box_0, tin_1, are equally spaced along, y)"]
        );
        assert_eq!(graph.edges[0].triplet(), "(tin_2, in, box_0)");
    }

    // --- malformed layouts -----------------------------------------------------------------

    fn error_of(s: &GraphScene) -> String {
        let options = GraphOptions::default();
        match extract_graph(s, &keyword_containers(s, &options), &options) {
            Ok(_) => panic!("expected an error"),
            Err(e) => e.to_string(),
        }
    }

    #[test]
    fn duplicate_names_are_found_at_every_length_and_only_whole_names_count() {
        let at = |name: &str, x: f64| obj(name, [x, 10.0, 5.0], [4.0, 4.0, 10.0], 0.0);
        let long = "ceramic_coffee_mug_with_handle_0";
        let names = ["a", "ab", "mug_0", "bowl_12", "plate_01", "tea_cup_3", long];
        for (i, name) in names.iter().enumerate() {
            let mut objects: Vec<SceneObject> = names
                .iter()
                .enumerate()
                .map(|(j, n)| at(n, 5.0 * j as f64))
                .collect();
            assert!(
                scene([0.0, 100.0, 0.0, 100.0], objects.clone())
                    .check()
                    .is_ok(),
                "{names:?}"
            );
            objects.push(at(name, 90.0));
            assert_eq!(
                error_of(&scene([0.0, 100.0, 0.0, 100.0], objects)),
                format!(
                    "objects[{}].instance: duplicate instance \"{name}\" (also objects[{i}]) \
                     (expected unique instance names; rename one, like `{name}_dup`)",
                    names.len()
                )
            );
        }
        // The same length and first and last 8 bytes, a different middle: not duplicates.
        let twin = "ceramic_coffee_cup_with_handle_0";
        let twins = scene([0.0, 100.0, 0.0, 100.0], vec![at(long, 1.0), at(twin, 2.0)]);
        assert!(twins.check().is_ok());
        // Names that differ only past a zero byte, or only in length, are different names.
        let zeros = scene(
            [0.0, 100.0, 0.0, 100.0],
            vec![
                at("a", 1.0),
                at("a\0", 2.0),
                at("a\0\0", 3.0),
                at("\0a", 4.0),
            ],
        );
        assert!(zeros.check().is_ok());
    }

    /// Scenes of more objects than a table holds have their names' summaries sorted instead
    /// of compared pair by pair: both ways find a duplicate wherever it is, and only then.
    #[test]
    fn duplicate_names_are_found_in_scenes_of_any_size() {
        for n in [
            3,
            ALL_PAIRS_UP_TO_OBJECTS - 1,
            ALL_PAIRS_UP_TO_OBJECTS,
            ALL_PAIRS_UP_TO_OBJECTS + 1,
            150,
        ] {
            let objects: Vec<SceneObject> = (0..n)
                .map(|i| {
                    obj(
                        &format!("cup_{i}"),
                        [i as f64, 10.0, 5.0],
                        [1.0, 1.0, 1.0],
                        0.0,
                    )
                })
                .collect();
            let zone = [0.0, 200.0, 0.0, 100.0];
            assert!(scene(zone, objects.clone()).check().is_ok(), "{n} objects");
            for (first, second) in [(0, n - 1), (n / 2, n / 2 + 1), (n - 2, n - 1)] {
                let mut with = objects.clone();
                with[second].instance = with[first].instance.clone();
                let name = &with[first].instance;
                assert_eq!(
                    error_of(&scene(zone, with.clone())),
                    format!(
                        "objects[{second}].instance: duplicate instance \"{name}\" (also \
                         objects[{first}]) (expected unique instance names; rename one, like \
                         `{name}_dup`)"
                    ),
                    "{n} objects"
                );
            }
        }
    }

    /// A node's line is written with its tail in one piece, and an edge's relation with its
    /// separators: the pieces are the labels'.
    #[test]
    fn line_pieces_are_the_labels() {
        for y in [YBand::Front, YBand::Middle, YBand::Back] {
            for x in [XBand::Left, XBand::Middle, XBand::Right] {
                let cell = GridCell { y, x };
                assert_eq!(cell.is_at_tail(), format!(", is at, {})", cell.label()));
                assert_eq!(
                    cell.is_at_line_end().text(),
                    format!(", is at, {})\n", cell.label())
                );
            }
        }
        for facing in Facing::ALL {
            assert_eq!(
                facing.face_to_tail(),
                format!(", face to, {})", facing.label())
            );
            assert_eq!(
                facing.face_to_line_end().text(),
                format!(", face to, {})\n", facing.label())
            );
        }
        for relation in [
            Relation::In,
            Relation::Above,
            Relation::LeftOf,
            Relation::RightOf,
            Relation::InFrontOf,
            Relation::Behind,
        ] {
            assert_eq!(
                relation.between().text(),
                format!(", {}, ", relation.label())
            );
        }
    }

    proptest! {
        /// An extraction's lists kept from scene to scene change nothing: two scenes extracted
        /// one after the other with the same lists, each both ways round (the larger first,
        /// then the smaller, which finds longer lists than it fills), give what fresh lists
        /// give, with every kind of search.
        #[test]
        fn kept_lists_change_nothing(
            a in arb_scene(),
            b in arb_scene(),
            equally_spaced in any::<bool>(),
        ) {
            let options = GraphOptions::default().with_equally_spaced(equally_spaced);
            let searches = [PairSearch::AllPairs, PairSearch::Grid, PairSearch::Literal];
            for search in searches {
                let mut kept = Scratch::default();
                for s in [&a, &b, &a] {
                    let flags = keyword_containers(s, &options);
                    let fresh = extract(s, &flags, &options, search, &mut Scratch::default());
                    let reused = extract(s, &flags, &options, search, &mut kept);
                    prop_assert_eq!(reused, fresh);
                }
            }
        }
    }

    /// The triplet lines, each ending with a newline: what `to_text` writes, piece by piece.
    fn text_of_lines(graph: &SceneGraph) -> String {
        graph
            .triplet_lines()
            .into_iter()
            .map(|line| line + "\n")
            .collect()
    }

    proptest! {
        /// `to_text` is the triplet lines, each ending with a newline, whatever the names:
        /// empty of letters, a few bytes, around and beyond the 32-byte copies, not ASCII. A
        /// graph whose edges were edited to name other strings (or names of other nodes)
        /// than those at their indices is written as edited.
        #[test]
        fn text_is_the_triplet_lines(
            s in arb_scene(),
            names in prop::collection::vec("[a-zé_ 0-9(),]{0,70}", 14),
            equally_spaced in any::<bool>(),
            edit in any::<prop::sample::Index>(),
        ) {
            let mut s = s;
            for (i, object) in s.objects.iter_mut().enumerate() {
                // Unique, and never blank (the check refuses blank names).
                object.instance = format!("{}#{i}", names[i]);
            }
            let options = GraphOptions::default().with_equally_spaced(equally_spaced);
            let flags = keyword_containers(&s, &options);
            let graph = extract_graph(&s, &flags, &options).expect("valid");
            prop_assert_eq!(graph.to_text(), text_of_lines(&graph));
            if !graph.edges.is_empty() {
                let edited_name = "edited, by hand".to_owned();
                let mut edited = graph.clone();
                let i = edit.index(edited.edges.len());
                edited.edges[i].subject = &edited_name;
                let other = edited.nodes[edit.index(edited.nodes.len())].instance;
                edited.edges[i].object = other;
                let text = edited.to_text();
                prop_assert_eq!(&text, &text_of_lines(&edited));
                prop_assert!(text.contains("(edited, by hand, "));
            }
        }
    }

    #[test]
    fn malformed_layouts_are_errors_naming_object_and_field() {
        let good = || obj("cup_0", [10.0, 10.0, 5.0], [8.0, 8.0, 10.0], 0.0);
        let with = |o: SceneObject| scene([0.0, 100.0, 0.0, 100.0], vec![good(), o]);
        assert_eq!(
            error_of(&with(obj("pen_0", [1.0, 2.0, 3.0], [1.0, 0.0, 1.0], 0.0))),
            "objects[1].size[1] (pen_0): is 0 (expected a finite number > 0 (cm))"
        );
        assert_eq!(
            error_of(&with(obj("pen_0", [1.0, 2.0, 3.0], [-1.0, 1.0, 1.0], 0.0))),
            "objects[1].size[0] (pen_0): is -1 (expected a finite number > 0 (cm))"
        );
        assert_eq!(
            error_of(&with(obj(
                "pen_0",
                [1.0, f64::NAN, 3.0],
                [1.0, 1.0, 1.0],
                0.0
            ))),
            "objects[1].position[1] (pen_0): is NaN (expected a finite number (cm))"
        );
        assert_eq!(
            error_of(&with(obj(
                "pen_0",
                [1.0, 2.0, 3.0],
                [1.0, 1.0, f64::INFINITY],
                0.0
            ))),
            "objects[1].size[2] (pen_0): is inf (expected a finite number > 0 (cm))"
        );
        assert_eq!(
            error_of(&with(obj(
                "pen_0",
                [1.0, 2.0, 3.0],
                [1.0, 1.0, 1.0],
                f64::NAN
            ))),
            "objects[1].z_rotation (pen_0): is NaN (expected a finite number (degrees))"
        );
        assert_eq!(
            error_of(&with(good())),
            "objects[1].instance: duplicate instance \"cup_0\" (also objects[0]) (expected unique \
             instance names; rename one, like `cup_0_dup`)"
        );
        assert_eq!(
            error_of(&with(obj(" ", [1.0, 2.0, 3.0], [1.0, 1.0, 1.0], 0.0))),
            "objects[1].instance: is empty (expected a name like `mug_0`)"
        );
        assert_eq!(
            error_of(&scene([0.0, 0.0, 0.0, 50.0], vec![good()])),
            "item_placement_zone: is empty [0, 0, 0, 50] (expected finite [x_min, x_max, y_min, \
             y_max] with x_min < x_max and y_min < y_max)"
        );
        assert!(error_of(&scene([0.0, f64::NAN, 0.0, 50.0], vec![]))
            .starts_with("item_placement_zone: has a non-finite bound [0, NaN, 0, 50]"));
        let s = with(obj("pen_0", [1.0, 2.0, 3.0], [1.0, 1.0, 1.0], 0.0));
        assert_eq!(
            extract_graph(&s, &[true], &GraphOptions::default())
                .expect_err("one flag")
                .to_string(),
            "container flags: 1 flags for 2 objects (expected one per object, in layout order)"
        );
        // An empty layout is fine: no lines.
        let empty = scene([0.0, 10.0, 0.0, 10.0], vec![]);
        assert!(lines(&empty).is_empty());
    }

    #[test]
    fn layout_files_of_every_form_are_read() {
        let llm = r#"{"item_placement_zone": [0, 100, 0, 50], "objects": [
            {"instance": "mug_0", "size": [8, 8, 10], "position": [20, 25, 5], "z_rotation": 90,
             "description": "a mug"}]}"#;
        let loaded = read_layout_text(llm).expect("an LLM layout");
        assert_eq!(loaded.form, LayoutForm::Llm);
        assert_eq!(loaded.scene.objects[0].yaw_deg, 90.0);
        let record = serde_json::json!({
            "prompt_instructions": "p", "input_task_description": "{}", "reasoning_paragraph": "r",
            "scene_graph": ["(mug_0, is at, center)"], "scene_layout_json": llm,
        });
        let loaded = read_layout_text(&record.to_string()).expect("a record");
        assert_eq!(loaded.form, LayoutForm::GalleryRecord);
        assert_eq!(loaded.scene.objects[0].instance, "mug_0");
        let dataset = r#"{"schema": "mesa.layout/1", "item_placement_zone": [0, 100, 0, 50],
            "objects": [{"instance": "mug_0", "retrieved_uid": "abc", "position": [20, 25, 5],
            "rotation": [0, 0, 0.7071067811865476, 0.7071067811865476], "size": [8, 8, 10],
            "scale_factor": [1, 1, 1]}]}"#;
        let loaded = read_layout_text(dataset).expect("a dataset layout");
        assert_eq!(loaded.form, LayoutForm::Dataset);
        assert_eq!(loaded.retrieved_uids, ["abc"]);
        assert!(loaded.warnings.is_empty());
        assert_abs_diff_eq!(loaded.scene.objects[0].yaw_deg, 90.0, epsilon = 1e-9);
        // A mug lying on its side (90° about x): its yaw is 0, and the reader says so.
        let tilted = dataset.replace(
            "[0, 0, 0.7071067811865476, 0.7071067811865476]",
            "[0.7071067811865476, 0, 0, 0.7071067811865476]",
        );
        let loaded = read_layout_text(&tilted).expect("a tilted dataset layout");
        assert_eq!(
            loaded.warnings,
            [
                "mug_0: rotation is tilted by 90.000°; the graph uses its footprint turned by its \
              yaw 0.000° only"
            ]
        );
        // Shapes: an empty layout with a sink is an LLM layout, without one a dataset layout.
        let empty_llm = serde_json::json!({
            "item_placement_zone": [0, 1, 0, 1], "sink_zone": [0, 1, 0, 1], "objects": []
        });
        assert_eq!(layout_form_of(&empty_llm), LayoutForm::Llm);
        let empty = serde_json::json!({"item_placement_zone": [0, 1, 0, 1], "objects": []});
        assert_eq!(layout_form_of(&empty), LayoutForm::Dataset);
    }

    #[test]
    fn layout_file_problems_name_the_object() {
        let nan = r#"{"item_placement_zone": [0, 100, 0, 50], "objects": [
            {"instance": "mug_0", "size": [8, 8, 10], "position": [20, NaN, 5], "z_rotation": 0}]}"#;
        let e = read_layout_text(nan).expect_err("NaN");
        assert_eq!(
            e.to_string(),
            "$.objects[0].position[1]: mug_0: is NaN (expected a finite number)"
        );
        let negative = r#"{"item_placement_zone": [0, 100, 0, 50], "objects": [
            {"instance": "mug_0", "size": [8, -8, 10], "position": [20, 2, 5], "z_rotation": 0}]}"#;
        let e = read_layout_text(negative).expect_err("negative size");
        assert!(
            e.to_string().starts_with("$.objects[0].size[1]: mug_0: "),
            "{e}"
        );
        let duplicate = r#"{"item_placement_zone": [0, 100, 0, 50], "objects": [
            {"instance": "mug_0", "size": [8, 8, 10], "position": [20, 2, 5], "z_rotation": 0},
            {"instance": "mug_0", "size": [8, 8, 10], "position": [40, 2, 5], "z_rotation": 0}]}"#;
        let e = read_layout_text(duplicate).expect_err("duplicate");
        assert!(
            e.to_string().contains("duplicate instance \"mug_0\""),
            "{e}"
        );
        let record = serde_json::json!({
            "prompt_instructions": "p", "input_task_description": "{}", "reasoning_paragraph": "r",
            "scene_graph": [], "scene_layout_json": negative,
        });
        let e = read_layout_text(&record.to_string()).expect_err("negative size in a record");
        assert!(e.to_string().contains("mug_0"), "{e}");
        assert!(read_layout_text("[1]")
            .expect_err("an array")
            .to_string()
            .starts_with("$: is an array"));
        assert!(read_layout_text("{")
            .expect_err("syntax")
            .to_string()
            .starts_with("$: is not valid JSON"));
    }

    // --- properties ------------------------------------------------------------------------

    const CATEGORIES: [&str; 8] = [
        "bowl", "cup", "plate", "apple", "tray", "book", "box", "pen",
    ];

    /// Random scenes on a quarter-centimetre grid (so that translations by whole centimetres
    /// are exact in f64), with containers, rotations, shared coordinates and, for about a
    /// third of the objects, a place on or in an earlier object (to exercise `in` and
    /// `above`).
    fn arb_scene() -> impl Strategy<Value = GraphScene> {
        arb_scene_of(14, [400, 240], [100.0, 60.0])
    }

    /// Larger layouts for the grid-versus-oracle test: many objects, spread over a zone or
    /// crowded into a corner (ties of distance), the zone as large as the spread or smaller
    /// (the distance limit then cuts).
    fn arb_large_scene() -> impl Strategy<Value = GraphScene> {
        prop_oneof![
            arb_scene_of(160, [4000, 2400], [1000.0, 600.0]),
            arb_scene_of(160, [4000, 2400], [100.0, 60.0]),
            arb_scene_of(160, [40, 24], [100.0, 60.0]),
            arb_scene_of(60, [400, 8], [100.0, 60.0]),
        ]
    }

    /// Up to `max_objects` objects, centres on a quarter-centimetre lattice of `span`
    /// quarters, in a zone of `zone` cm.
    fn arb_scene_of(
        max_objects: usize,
        span: [i32; 2],
        zone: [f64; 2],
    ) -> impl Strategy<Value = GraphScene> {
        let object = (
            0usize..CATEGORIES.len(),
            (0i32..=span[0], 0i32..=span[1], 0i32..=20),
            prop::array::uniform3(1i32..=120),
            prop_oneof![Just(0.0), Just(90.0), Just(45.0), -180.0f64..180.0],
            prop_oneof![2 => Just(None), 1 => (any::<prop::sample::Index>(), -8i32..=8, -8i32..=8, 0i32..=16).prop_map(Some)],
        );
        prop::collection::vec(object, 0..max_objects).prop_map(move |objects| {
            let mut out: Vec<SceneObject> = Vec::with_capacity(objects.len());
            for (i, (category, (x, y, lift), size, yaw, stack)) in objects.into_iter().enumerate() {
                let size = size.map(|s| f64::from(s) / 4.0);
                let quarter = |v: i32| f64::from(v) / 4.0;
                let mut position = [quarter(x), quarter(y), size[2] / 2.0 + quarter(lift)];
                if let (Some((base, dx, dy, up)), false) = (stack, out.is_empty()) {
                    let base = &out[base.index(out.len())];
                    let base_bottom = base.position_cm[2] - base.size_cm[2] / 2.0;
                    position = [
                        base.position_cm[0] + quarter(dx),
                        base.position_cm[1] + quarter(dy),
                        base_bottom + quarter(up) + size[2] / 2.0,
                    ];
                }
                out.push(SceneObject::new(
                    format!("{}_{i}", CATEGORIES[category]),
                    position,
                    size,
                    yaw,
                ));
            }
            out.sort_by(|a, b| {
                let (fa, fb) = (a.size_cm[0] * a.size_cm[1], b.size_cm[0] * b.size_cm[1]);
                fb.total_cmp(&fa).then_with(|| a.instance.cmp(&b.instance))
            });
            GraphScene {
                zone_cm: [0.0, zone[0], 0.0, zone[1]],
                objects: out,
            }
        })
    }

    fn parse_triplet(line: &str) -> Vec<String> {
        line.trim_start_matches('(')
            .trim_end_matches(')')
            .split(", ")
            .map(str::to_owned)
            .collect()
    }

    /// Any yaw, or one a little off the axes (where the boxes around a footprint are
    /// tightest, so the boxes' overlap comes nearest a pair's share of it), or on them.
    fn a_yaw() -> impl Strategy<Value = f64> {
        prop_oneof![
            -180.0f64..180.0,
            -3.0f64..3.0,
            87.0f64..93.0,
            Just(0.0),
            Just(90.0),
        ]
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(512))]

        #[test]
        fn the_grid_search_gives_the_all_pairs_output(
            s in arb_large_scene(),
            equally_spaced in any::<bool>(),
        ) {
            let options = GraphOptions::default().with_equally_spaced(equally_spaced);
            let flags = keyword_containers(&s, &options);
            let oracle = extract(&s, &flags, &options, PairSearch::Literal, &mut Scratch::default()).expect("valid");
            let fast = extract(&s, &flags, &options, PairSearch::Grid, &mut Scratch::default()).expect("valid");
            prop_assert_eq!(&fast, &oracle);
            let all_pairs = extract(&s, &flags, &options, PairSearch::AllPairs, &mut Scratch::default()).expect("valid");
            prop_assert_eq!(&all_pairs, &oracle);
            // What callers get: the all-pairs search for a table's few objects, else the grids.
            let chosen = extract_graph(&s, &flags, &options).expect("valid");
            prop_assert_eq!(&chosen, &oracle);
        }

        #[test]
        fn small_scenes_give_the_literal_output(
            s in arb_scene(),
            equally_spaced in any::<bool>(),
        ) {
            let options = GraphOptions::default().with_equally_spaced(equally_spaced);
            let flags = keyword_containers(&s, &options);
            let oracle = extract(&s, &flags, &options, PairSearch::Literal, &mut Scratch::default()).expect("valid");
            prop_assert_eq!(extract_graph(&s, &flags, &options).expect("valid"), oracle);
        }

        #[test]
        fn the_json_written_from_a_graph_is_the_artifacts(
            s in arb_scene(),
            equally_spaced in any::<bool>(),
            scene_id in "[a-z_0-9\"\\\\\u{1}é]{0,10}",
        ) {
            let options = GraphOptions::default().with_equally_spaced(equally_spaced);
            let graph = graph_of(&s, &options);
            prop_assert_eq!(
                graph.to_json(&scene_id, "refined/layout.json"),
                graph.to_artifact(&scene_id, "refined/layout.json").to_pretty_json()
            );
        }

        #[test]
        fn translating_scene_and_zone_changes_nothing(
            s in arb_scene(),
            tx in -500i32..500,
            ty in -500i32..500,
        ) {
            let options = GraphOptions::default().with_equally_spaced(true);
            let before = graph_of(&s, &options).triplet_lines();
            let (tx, ty) = (f64::from(tx), f64::from(ty));
            let mut moved = s.clone();
            moved.zone_cm = [s.zone_cm[0] + tx, s.zone_cm[1] + tx, s.zone_cm[2] + ty, s.zone_cm[3] + ty];
            for o in &mut moved.objects {
                o.position_cm[0] += tx;
                o.position_cm[1] += ty;
            }
            prop_assert_eq!(before, graph_of(&moved, &options).triplet_lines());
        }

        #[test]
        fn graph_invariants_hold(s in arb_scene()) {
            let options = GraphOptions::default().with_equally_spaced(true);
            let graph = graph_of(&s, &options);
            let lines = graph.triplet_lines();
            let mut is_at: BTreeMap<String, usize> = BTreeMap::new();
            let mut face_to: BTreeMap<String, usize> = BTreeMap::new();
            let mut contained: BTreeMap<String, usize> = BTreeMap::new();
            // A pair may carry both `above` and a horizontal relation (the rules allow it, and
            // the published records have it: 001 writes `bowl_0 above tray_0` and `tray_0 left
            // of bowl_0`), but never twice within one class: containment, vertical, horizontal.
            let mut pairs = std::collections::BTreeSet::new();
            let mut triplets = std::collections::BTreeSet::new();
            let mut others: Vec<Vec<String>> = Vec::new();
            for line in &lines {
                let parts = parse_triplet(line);
                match parts[1].as_str() {
                    "is at" => *is_at.entry(parts[0].clone()).or_default() += 1,
                    "face to" => *face_to.entry(parts[0].clone()).or_default() += 1,
                    "in" => *contained.entry(parts[0].clone()).or_default() += 1,
                    _ => {}
                }
                prop_assert!(triplets.insert(line.clone()), "line written twice: {}", line);
                if parts.len() == 3 && parts[1] != "is at" && parts[1] != "face to" {
                    let class = match parts[1].as_str() {
                        "in" => "containment",
                        "above" => "vertical",
                        _ => "horizontal",
                    };
                    let pair = if parts[0] < parts[2] {
                        (class, parts[0].clone(), parts[2].clone())
                    } else {
                        (class, parts[2].clone(), parts[0].clone())
                    };
                    prop_assert!(pairs.insert(pair), "pair written twice: {}", line);
                    prop_assert_ne!(&parts[0], &parts[2]);
                    if parts[1] != "in" {
                        others.push(parts);
                    }
                } else if parts.len() == 5 {
                    others.push(parts[..3].to_vec());
                }
            }
            for o in &s.objects {
                prop_assert_eq!(is_at.get(&o.instance), Some(&1));
                prop_assert_eq!(face_to.get(&o.instance), Some(&1));
            }
            prop_assert_eq!(is_at.len(), s.objects.len());
            prop_assert!(contained.values().all(|&n| n == 1));
            for parts in &others {
                for name in parts.iter().filter(|p| contained.contains_key(*p)) {
                    prop_assert!(false, "contained {} appears in {:?}", name, parts);
                }
            }
            // Each subject has at most one `above`, and the horizontal block of a subject has at
            // most five edges.
            let mut above: BTreeMap<&str, usize> = BTreeMap::new();
            let mut horizontal: BTreeMap<&str, usize> = BTreeMap::new();
            for edge in &graph.edges {
                match edge.relation {
                    Relation::Above => *above.entry(edge.subject).or_default() += 1,
                    Relation::In => {}
                    _ => *horizontal.entry(edge.subject).or_default() += 1,
                }
            }
            prop_assert!(above.values().all(|&n| n == 1));
            prop_assert!(horizontal.values().all(|&n| n <= NEIGHBOURS_PER_SUBJECT));
        }

        #[test]
        fn intersection_is_symmetric_and_bounded(
            w1 in 0.5f64..50.0, d1 in 0.5f64..50.0, t1 in -180.0f64..180.0,
            w2 in 0.5f64..50.0, d2 in 0.5f64..50.0, t2 in -180.0f64..180.0,
            dx in -40.0f64..40.0, dy in -40.0f64..40.0,
        ) {
            let a = Footprint::new(w1, d1, t1);
            let b = Footprint::new(w2, d2, t2);
            let ab = intersection_area_footprints(&a, &b, [dx, dy]);
            let ba = intersection_area_footprints(&b, &a, [-dx, -dy]);
            let tolerance = 1e-9 * (w1 * d1 + w2 * d2);
            prop_assert!((ab - ba).abs() <= tolerance, "{} vs {}", ab, ba);
            prop_assert!(ab >= 0.0);
            prop_assert!(ab <= a.area_cm2.min(b.area_cm2) + tolerance);
            // A footprint with itself: its full area.
            let aa = intersection_area_footprints(&a, &a, [0.0, 0.0]);
            prop_assert!((aa - a.area_cm2).abs() <= tolerance);
        }

        /// The share a pair's rule sees is the share of the two footprints, whether the
        /// circles or the boxes around them settled it or the footprints were clipped: the same
        /// bits when it is at least the threshold, and none otherwise (and no overlap at all
        /// when the circles were apart). The offsets are drawn around the distance where the
        /// circles touch, where a rectangle's corner may reach its circle (`k` scales that
        /// distance), and from there inward, where the share crosses the rules' thresholds.
        #[test]
        fn a_share_settled_by_circles_or_boxes_is_the_footprints(
            w1 in 0.5f64..50.0, d1 in 0.5f64..50.0, t1 in a_yaw(),
            w2 in 0.5f64..50.0, d2 in 0.5f64..50.0, t2 in a_yaw(),
            direction in -180.0f64..180.0,
            k in prop_oneof![0.0f64..1.2, 1.0 - 1e-3..1.0 + 1e-3, 1.0 - 1e-6..1.0 + 1e-6, Just(1.0)],
            corner_to_corner in any::<bool>(),
            least in prop_oneof![
                Just(ABOVE_MIN_FOOTPRINT_SHARE),
                Just(CONTAINMENT_MIN_FOOTPRINT_SHARE),
                1e-6f64..1.0,
            ],
        ) {
            let solid = |w: f64, d: f64, yaw: f64, x: f64, y: f64| {
                Solid::new(&SceneObject::new("o", [x, y, 5.0], [w, d, 10.0], yaw))
            };
            let (sin, cos) = direction.to_radians().sin_cos();
            // Corner to corner: each rectangle turned so that a corner points at the other.
            let diagonal = |w: f64, d: f64| d.atan2(w).to_degrees();
            let (t1, t2) = if corner_to_corner {
                (direction - diagonal(w1, d1), direction + 180.0 - diagonal(w2, d2))
            } else {
                (t1, t2)
            };
            let a = solid(w1, d1, t1, 10.0, 20.0);
            let touching = a.half_diagonal_cm + solid(w2, d2, t2, 0.0, 0.0).half_diagonal_cm;
            let b = solid(w2, d2, t2, 10.0 + k * touching * cos, 20.0 + k * touching * sin);
            let offset = [b.x - a.x, b.y - a.y];
            let direct = intersection_area_footprints(
                &Footprint::new(w1, d1, t1),
                &Footprint::new(w2, d2, t2),
                offset,
            ) / a.area();
            let share = a.footprint_share_in(&b, least);
            if direct >= least {
                prop_assert_eq!(share.map(f64::to_bits), Some(direct.to_bits()));
            } else {
                prop_assert_eq!(share, None);
            }
            if a.footprint.get().is_none() {
                prop_assert!(direct <= 1e-9, "the circles were apart, the footprints meet: {}", direct);
            }
        }
    }

    /// Where the boxes around two footprints are tightest (both turned a hair off the axes),
    /// their overlap exceeds the footprints' intersection by a relative 1e-8 or less: a share
    /// exactly at the threshold is still clipped and kept, however near the box bound comes.
    /// (A bound of 1.000001 times the boxes' overlap would drop these pairs.)
    #[test]
    fn a_share_at_the_threshold_passes_the_tightest_boxes() {
        for yaw in [1e-9, 1e-7, 1e-6, -1e-6, 90.0 + 1e-6] {
            for offset in [[1.0, 0.0], [0.5, 0.5], [0.0, 2.5], [-3.0, 1.0]] {
                let solid = |x: f64, y: f64| {
                    Solid::new(&SceneObject::new("o", [x, y, 5.0], [10.0, 10.0, 10.0], yaw))
                };
                let (a, b) = (solid(0.0, 0.0), solid(offset[0], offset[1]));
                let footprint = Footprint::new(10.0, 10.0, yaw);
                assert!(!footprint.axis_aligned);
                let direct = intersection_area_footprints(&footprint, &footprint, offset) / 100.0;
                let boxes = box_overlap_area(&footprint, &footprint, offset) / 100.0;
                assert!(
                    boxes >= direct && boxes - direct < 1e-7,
                    "{yaw}: {boxes} {direct}"
                );
                assert_eq!(
                    a.footprint_share_in(&b, direct),
                    Some(direct),
                    "{yaw} {offset:?}"
                );
                let above = direct + 1e-12;
                assert_eq!(a.footprint_share_in(&b, above), None, "{yaw} {offset:?}");
            }
        }
    }

    /// The control of the property above: circles smaller than the footprints' (the largest
    /// circle inside each) would call apart two squares that overlap corner into corner.
    #[test]
    fn circles_inside_the_footprints_would_miss_an_overlap() {
        let square = |x: f64, y: f64| {
            Solid::new(&SceneObject::new("o", [x, y, 5.0], [10.0, 10.0, 10.0], 0.0))
        };
        let (a, b) = (square(0.0, 0.0), square(9.0, 9.0));
        // The two squares share a 1 × 1 corner; the centres are 12.7 apart.
        assert_eq!(a.footprint_share_in(&b, 0.01), Some(0.01));
        let mut inside = square(9.0, 9.0);
        inside.half_diagonal_cm = 5.0;
        let mut a_inside = square(0.0, 0.0);
        a_inside.half_diagonal_cm = 5.0;
        assert_eq!(
            a_inside.footprint_share_in(&inside, 0.01),
            None,
            "the control misses it"
        );
        // Apart by a hair more than the circles allow: settled without a footprint.
        let far = square(14.15, 0.0);
        let near = square(0.0, 0.0);
        assert_eq!(near.footprint_share_in(&far, 1e-6), None);
        assert!(near.footprint.get().is_none() && far.footprint.get().is_none());
    }
}
