//! Synthetic layouts for the records benchmarks: scenes of 12 to 18 objects of everyday
//! categories, sizes in realistic ranges, placed without overlap (small items sometimes inside a
//! bowl, box or tray), yaws of 0, ±90 or 180 degrees, written as dataset layouts sorted by
//! footprint, as mesa writes them. Seeded: the same arguments give the same files.

use std::path::Path;

use mesa_schemas::rotation::quat_xyzw_from_yaw_deg;
use mesa_schemas::units::{PositionCm, QuatXyzw, ScaleFactor, SizeCm, ZoneCm};
use mesa_schemas::{DatasetLayout, LayoutObject, LAYOUT_SCHEMA};
use rand::{Rng, SeedableRng};

/// A category: width, depth and height ranges in cm, whether it holds small items.
struct Category(&'static str, [f64; 2], [f64; 2], [f64; 2], bool);

/// An object placed so far.
struct Placed {
    instance: String,
    position: [f64; 3],
    size: [f64; 3],
    yaw: f64,
    holds: bool,
}

const CATEGORIES: [Category; 20] = [
    Category("laptop", [30.0, 38.0], [20.0, 26.0], [1.5, 2.5], false),
    Category("monitor", [45.0, 60.0], [15.0, 22.0], [35.0, 50.0], false),
    Category("keyboard", [38.0, 45.0], [12.0, 16.0], [2.0, 4.0], false),
    Category("mouse", [6.0, 7.0], [10.0, 12.0], [3.0, 4.0], false),
    Category("mug", [8.0, 10.0], [8.0, 10.0], [9.0, 11.0], false),
    Category("bowl", [14.0, 22.0], [14.0, 22.0], [6.0, 9.0], true),
    Category("plate", [20.0, 27.0], [20.0, 27.0], [2.0, 3.0], false),
    Category("book", [15.0, 22.0], [20.0, 28.0], [2.0, 5.0], false),
    Category("desk_lamp", [12.0, 18.0], [12.0, 18.0], [30.0, 50.0], false),
    Category("plant", [12.0, 20.0], [12.0, 20.0], [20.0, 40.0], false),
    Category("bottle", [6.0, 9.0], [6.0, 9.0], [20.0, 30.0], false),
    Category("cup", [7.0, 9.0], [7.0, 9.0], [9.0, 12.0], false),
    Category("pen", [1.0, 1.5], [13.0, 15.0], [1.0, 1.5], false),
    Category("phone", [7.0, 8.0], [14.0, 16.0], [0.8, 1.0], false),
    Category("tray", [30.0, 45.0], [20.0, 30.0], [3.0, 5.0], true),
    Category("apple", [7.0, 8.0], [7.0, 8.0], [7.0, 8.0], false),
    Category("vase", [10.0, 14.0], [10.0, 14.0], [20.0, 30.0], false),
    Category("storage_box", [15.0, 25.0], [10.0, 20.0], [8.0, 15.0], true),
    Category("towel", [25.0, 35.0], [15.0, 25.0], [3.0, 6.0], false),
    Category("jar", [9.0, 12.0], [9.0, 12.0], [12.0, 18.0], false),
];

const TABLE_TYPES: [&str; 6] = [
    "bathroom_vanity",
    "coffee_table",
    "dining_table",
    "dressing_table",
    "kitchen_counter",
    "office_table",
];

/// Half extents of a footprint turned by a multiple of 90 degrees.
fn half_extents(size: [f64; 3], yaw_deg: f64) -> [f64; 2] {
    if (yaw_deg.abs() - 90.0).abs() < 1e-9 {
        [size[1] / 2.0, size[0] / 2.0]
    } else {
        [size[0] / 2.0, size[1] / 2.0]
    }
}

/// One synthetic layout.
pub fn layout(rng: &mut rand_chacha::ChaCha8Rng) -> DatasetLayout {
    let width = rng.random_range(80.0..200.0f64).round();
    let depth = rng.random_range(40.0..90.0f64).round();
    let count = rng.random_range(12..=18);
    let mut placed: Vec<Placed> = Vec::new();
    let mut counts = std::collections::BTreeMap::<&str, usize>::new();
    for _ in 0..count * 4 {
        if placed.len() == count {
            break;
        }
        let Category(category, w, d, h, holds) = CATEGORIES[rng.random_range(0..CATEGORIES.len())];
        let size = [
            rng.random_range(w[0]..=w[1]),
            rng.random_range(d[0]..=d[1]),
            rng.random_range(h[0]..=h[1]),
        ];
        let yaw = [0.0, 90.0, -90.0, 180.0][rng.random_range(0..4)];
        let small = size[0] * size[1] < 120.0;
        // Small items go into a container now and then.
        let container = placed
            .iter()
            .find(|p| p.holds && p.size[0].min(p.size[1]) > size[0].max(size[1]) + 2.0)
            .map(|p| (p.position, p.size));
        let position = match container {
            Some((at, outer)) if small && rng.random_bool(0.4) => {
                Some([at[0], at[1], at[2] - outer[2] / 2.0 + 1.0 + size[2] / 2.0])
            }
            _ => {
                let half = half_extents(size, yaw);
                if 2.0 * half[0] >= width || 2.0 * half[1] >= depth {
                    continue;
                }
                (0..30).find_map(|_| {
                    let x = rng.random_range(half[0]..width - half[0]);
                    let y = rng.random_range(half[1]..depth - half[1]);
                    let free = placed.iter().all(|p| {
                        let other = half_extents(p.size, p.yaw);
                        (x - p.position[0]).abs() >= half[0] + other[0] + 0.5
                            || (y - p.position[1]).abs() >= half[1] + other[1] + 0.5
                    });
                    free.then_some([x, y, size[2] / 2.0])
                })
            }
        };
        let Some(position) = position else { continue };
        let index = counts.entry(category).or_default();
        let instance = format!("{category}_{index}");
        *index += 1;
        placed.push(Placed {
            instance,
            position,
            size,
            yaw,
            holds,
        });
    }
    let round = |v: f64| (v * 10.0).round() / 10.0;
    let mut objects: Vec<LayoutObject> = placed
        .into_iter()
        .map(
            |Placed {
                 instance,
                 position,
                 size,
                 yaw,
                 ..
             }| {
                let category = mesa_schemas::convert::category_of_instance(&instance).to_owned();
                LayoutObject {
                    retrieved_uid: format!("synthetic-{category}"),
                    position_cm: PositionCm(position.map(round)),
                    rotation: QuatXyzw(quat_xyzw_from_yaw_deg(yaw)),
                    size_cm: SizeCm(size.map(round)),
                    scale_factor: ScaleFactor([1.0; 3]),
                    description: Some(format!("a {}", category.replace('_', " "))),
                    category: Some(category),
                    z_rotation_deg: Some(yaw),
                    provenance: None,
                    extra: Default::default(),
                    instance,
                }
            },
        )
        .collect();
    objects.sort_by(|a, b| {
        let fa = a.size_cm.0[0] * a.size_cm.0[1];
        let fb = b.size_cm.0[0] * b.size_cm.0[1];
        fb.total_cmp(&fa).then_with(|| a.instance.cmp(&b.instance))
    });
    DatasetLayout {
        schema: LAYOUT_SCHEMA.to_owned(),
        zone_cm: ZoneCm([0.0, width, 0.0, depth]),
        restricted_zone_cm: None,
        objects,
        extra: Default::default(),
    }
}

/// Writes `scenes` layouts (`refined/layout.json`, as annotated and ingested) into `dir`, spread over the six table types.
pub fn write_layouts(dir: &Path, scenes: usize, seed: u64) -> std::io::Result<()> {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    for k in 0..scenes {
        let table = TABLE_TYPES[k % TABLE_TYPES.len()];
        let path = dir.join(format!("scenes/{table}/{table}_{k:05}/refined/layout.json"));
        std::fs::create_dir_all(path.parent().expect("a parent folder"))?;
        let bytes = mesa_schemas::json::to_sorted_pretty(&layout(&mut rng))
            .map_err(std::io::Error::other)?;
        std::fs::write(path, bytes)?;
    }
    Ok(())
}

/// A dataset ready for `mesa records`: synthetic layouts, their scene graphs and template tasks
/// (written through the same stages `mesa graph` and `mesa tasks` run).
pub fn write_dataset(dir: &Path, scenes: usize, seed: u64) -> anyhow::Result<()> {
    use mesa_pipeline::config::{Config, ProgressMode};
    use mesa_pipeline::runner::{run_stage, RunOptions, StageContext};
    write_layouts(dir, scenes, seed)?;
    let config = Config::default();
    let ctx = StageContext {
        dataset: dir,
        config: &config,
    };
    let options = RunOptions {
        progress: ProgressMode::Off,
        ..RunOptions::from_config(&config)
    };
    for stage in [
        &mesa_pipeline::commands::graph::GraphStage::new()
            as &dyn mesa_pipeline::runner::SceneStage,
        &mesa_pipeline::commands::tasks::TasksStage::new(),
    ] {
        let summary = run_stage(stage, &ctx, &options)?;
        anyhow::ensure!(
            summary.success(),
            "{}: {:?}",
            summary.stage,
            summary.failed.first()
        );
    }
    Ok(())
}
