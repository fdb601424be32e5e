//! Fixed-length number arrays with their units and constraints in the type.
//!
//! Each is `#[serde(transparent)]` over an array, and its JSON Schema states the length, that
//! every item is a number, and (for sizes and scales) that it is positive, so that
//! `mesa validate` reports "has 2 items (expected 3 ...)" or "is -3 (expected > 0)" from the
//! schema alone.

use std::borrow::Cow;

use schemars::{json_schema, JsonSchema, Schema, SchemaGenerator};
use serde::{Deserialize, Serialize};

use crate::Problem;

macro_rules! number_array {
    ($(#[$doc:meta])* $name:ident, $len:literal, $desc:literal, $item:tt) => {
        $(#[$doc])*
        #[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
        #[serde(transparent)]
        pub struct $name(pub [f64; $len]);

        impl JsonSchema for $name {
            fn schema_name() -> Cow<'static, str> {
                stringify!($name).into()
            }
            fn json_schema(_: &mut SchemaGenerator) -> Schema {
                json_schema!({
                    "type": "array",
                    "description": $desc,
                    "items": $item,
                    "minItems": $len,
                    "maxItems": $len
                })
            }
        }

        impl From<[f64; $len]> for $name {
            fn from(value: [f64; $len]) -> Self {
                Self(value)
            }
        }
    };
}

number_array!(
    /// `[x_min, x_max, y_min, y_max]` in cm (note the order).
    ZoneCm, 4, "[x_min, x_max, y_min, y_max] in cm", {"type": "number"}
);
number_array!(
    /// `[x, y, z]` in cm, table frame.
    PositionCm, 3, "[x, y, z] in cm, table frame", {"type": "number"}
);
number_array!(
    /// `[width, depth, height]` in cm, object frame (before rotation); all positive.
    SizeCm, 3, "[width, depth, height] in cm before rotation, each > 0",
    {"type": "number", "exclusiveMinimum": 0}
);
number_array!(
    /// A quaternion `[x, y, z, w]`.
    QuatXyzw, 4, "a unit quaternion [x, y, z, w]", {"type": "number"}
);
number_array!(
    /// The asset's scale per axis `[sx, sy, sz]`; all positive.
    ScaleFactor, 3, "[sx, sy, sz], each > 0", {"type": "number", "exclusiveMinimum": 0}
);

impl ZoneCm {
    /// Width (x extent) in cm.
    pub fn width_cm(&self) -> f64 {
        self.0[1] - self.0[0]
    }
    /// Depth (y extent) in cm.
    pub fn depth_cm(&self) -> f64 {
        self.0[3] - self.0[2]
    }
}

/// Reports a zone whose maxima are not above its minima (and, for the placement zone, whose
/// minima are not 0 as the table frame requires).
pub(crate) fn check_zone(zone: &ZoneCm, at: &str, placement: bool, out: &mut Vec<Problem>) {
    let [x_min, x_max, y_min, y_max] = zone.0;
    if x_max <= x_min || y_max <= y_min {
        out.push(Problem::new(
            at,
            format!("empty zone [{x_min}, {x_max}, {y_min}, {y_max}]"),
            "x_min < x_max and y_min < y_max (order [x_min, x_max, y_min, y_max])",
        ));
    }
    if placement && (x_min != 0.0 || y_min != 0.0) {
        out.push(Problem::new(
            at,
            format!("zone starts at ({x_min}, {y_min})"),
            "x_min = y_min = 0: the table frame's origin is the zone's proximal-left corner",
        ));
    }
}
