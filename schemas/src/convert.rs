//! Conversion between the dataset layout and the LLM layout (SPEC section 4).
//!
//! Lossless for pure-yaw objects in the fields both forms share; everything the target form
//! has no place for is reported in the returned notes, never dropped silently.

use std::collections::BTreeMap;

use crate::layout::{DatasetLayout, LayoutObject, Provenance, LAYOUT_SCHEMA};
use crate::llm::{LlmLayout, LlmObject};
// Kept here for the public path; it lives below both layout forms so llm needs nothing here.
pub use crate::order::sort_by_footprint;
use crate::rotation::{
    normalize_deg, quat_xyzw_from_yaw_deg, tilt_deg_from_quat_xyzw, yaw_deg_from_quat_xyzw,
};
use crate::units::{QuatXyzw, ScaleFactor};

/// Tilts below this many degrees are numerical noise, not a tilt.
pub const TILT_EPSILON_DEG: f64 = 1e-6;

/// A layout converted, with what the conversion could not carry over.
#[derive(Debug, Clone, PartialEq)]
pub struct Converted<T> {
    /// The converted layout.
    pub layout: T,
    /// One line per loss or assumption, naming the object when there is one.
    pub warnings: Vec<String>,
}

/// The category of an instance name: the name without its trailing `_<n>` (`desk_lamp_0` →
/// `desk_lamp`).
pub fn category_of_instance(instance: &str) -> &str {
    match instance.rsplit_once('_') {
        Some((stem, index)) if !index.is_empty() && index.bytes().all(|b| b.is_ascii_digit()) => {
            stem
        }
        _ => instance,
    }
}

/// The yaw of a dataset object in degrees: its `z_rotation` when that agrees with `rotation`
/// (so the value round-trips exactly), else the twist of `rotation` about +z.
pub fn yaw_deg_of(object: &LayoutObject) -> f64 {
    let from_quat = yaw_deg_from_quat_xyzw(object.rotation.0);
    match object.z_rotation_deg {
        Some(yaw) if normalize_deg(yaw - from_quat).abs() < 1e-6 => yaw,
        _ => from_quat,
    }
}

/// Dataset form → LLM form, objects in the input's order (call
/// [`LlmLayout::sort_objects`] for the published order).
pub fn llm_from_dataset(layout: &DatasetLayout) -> Converted<LlmLayout> {
    let mut warnings = Vec::new();
    let mut objects = Vec::with_capacity(layout.objects.len());
    for object in &layout.objects {
        let tilt = tilt_deg_from_quat_xyzw(object.rotation.0);
        let yaw = yaw_deg_of(object);
        if tilt > TILT_EPSILON_DEG {
            warnings.push(format!(
                "{}: rotation is tilted by {tilt:.3}° (roll/pitch); the LLM form keeps only its \
                 yaw {yaw:.3}°",
                object.instance
            ));
        }
        if object.description.is_none() {
            warnings.push(format!(
                "{}: no description; the LLM form gets an empty one",
                object.instance
            ));
        }
        objects.push(LlmObject {
            instance: object.instance.clone(),
            size_cm: object.size_cm,
            position_cm: object.position_cm,
            z_rotation_deg: yaw,
            description: object.description.clone().unwrap_or_default(),
        });
    }
    if !layout.objects.is_empty() {
        warnings.push(
            "dropped per-object fields the LLM form has no place for: retrieved_uid, \
             scale_factor, category, provenance"
                .to_owned(),
        );
    }
    Converted {
        layout: LlmLayout {
            zone_cm: layout.zone_cm,
            sink_zone_cm: layout.restricted_zone_cm,
            objects,
        },
        warnings,
    }
}

/// LLM form → dataset form, objects in the input's order. No asset is known, so `retrieved_uid` is left empty and
/// `scale_factor` is `[1, 1, 1]` (run `mesa retrieve` / `mesa place` to fill them).
pub fn dataset_from_llm(layout: &LlmLayout) -> Converted<DatasetLayout> {
    let objects: Vec<LayoutObject> = layout
        .objects
        .iter()
        .map(|object| LayoutObject {
            instance: object.instance.clone(),
            retrieved_uid: String::new(),
            position_cm: object.position_cm,
            rotation: QuatXyzw(quat_xyzw_from_yaw_deg(object.z_rotation_deg)),
            size_cm: object.size_cm,
            scale_factor: ScaleFactor([1.0; 3]),
            category: Some(category_of_instance(&object.instance).to_owned()),
            description: Some(object.description.clone()),
            z_rotation_deg: Some(object.z_rotation_deg),
            provenance: Some(Provenance {
                stage: "convert".to_owned(),
                source_instance: None,
                notes: Vec::new(),
            }),
            extra: BTreeMap::new(),
        })
        .collect();
    let mut warnings = Vec::new();
    if !objects.is_empty() {
        warnings.push(format!(
            "{} objects have no asset yet: retrieved_uid is empty and scale_factor is [1, 1, 1] \
             (run `mesa retrieve` and `mesa place`)",
            objects.len()
        ));
    }
    Converted {
        layout: DatasetLayout {
            schema: LAYOUT_SCHEMA.to_owned(),
            zone_cm: layout.zone_cm,
            restricted_zone_cm: layout.sink_zone_cm,
            objects,
            extra: BTreeMap::new(),
        },
        warnings,
    }
}

impl DatasetLayout {
    /// Sorts objects by descending footprint w·d, ties by instance name; whether it changed.
    pub fn sort_objects(&mut self) -> bool {
        sort_by_footprint(&mut self.objects, |o| (&o.instance, o.size_cm.0))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::units::{PositionCm, SizeCm, ZoneCm};
    use proptest::prelude::*;

    #[test]
    fn categories_strip_only_a_numeric_suffix() {
        assert_eq!(category_of_instance("desk_lamp_0"), "desk_lamp");
        assert_eq!(category_of_instance("pen_10"), "pen");
        assert_eq!(category_of_instance("tray"), "tray");
        assert_eq!(category_of_instance("plate_a"), "plate_a");
    }

    fn object() -> impl Strategy<Value = LlmObject> {
        (
            "[a-z]{1,8}_[0-9]{1,2}",
            prop::array::uniform3(0.1f64..200.0),
            prop::array::uniform3(-50.0f64..250.0),
            -720.0f64..720.0,
            ".{0,20}",
        )
            .prop_map(|(instance, size, position, yaw, description)| LlmObject {
                instance,
                size_cm: SizeCm(size),
                position_cm: PositionCm(position),
                z_rotation_deg: yaw,
                description,
            })
    }

    proptest! {
        #[test]
        fn pure_yaw_layouts_round_trip_exactly(objects in prop::collection::vec(object(), 0..12)) {
            let llm = LlmLayout {
                zone_cm: ZoneCm([0.0, 120.0, 0.0, 80.0]),
                sink_zone_cm: None,
                objects,
            };
            let dataset = dataset_from_llm(&llm).layout;
            let back = llm_from_dataset(&dataset);
            prop_assert!(back.warnings.iter().all(|w| !w.contains("tilted")));
            prop_assert_eq!(back.layout, llm);
        }
    }

    #[test]
    fn tilted_objects_warn_with_their_name() {
        let mut dataset = dataset_from_llm(&LlmLayout {
            zone_cm: ZoneCm([0.0, 100.0, 0.0, 50.0]),
            sink_zone_cm: None,
            objects: vec![LlmObject {
                instance: "book_3".into(),
                size_cm: SizeCm([20.0, 15.0, 3.0]),
                position_cm: PositionCm([10.0, 10.0, 1.5]),
                z_rotation_deg: 0.0,
                description: "a book".into(),
            }],
        })
        .layout;
        let h = std::f64::consts::FRAC_1_SQRT_2;
        dataset.objects[0].rotation = QuatXyzw([h, 0.0, 0.0, h]);
        let converted = llm_from_dataset(&dataset);
        assert!(converted
            .warnings
            .iter()
            .any(|w| w.starts_with("book_3: rotation is tilted by 90.000°")));
    }
}
