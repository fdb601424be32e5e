//! `mesa demo`: a complete synthetic dataset workspace (SPEC section 3) with ground truth.
//!
//! [`write_demo`] writes an asset library (procedural GLB assets at real sizes, Y up, front
//! +Z, with a MesaTask/objathor `annotations.json`) and scenes over the six table types. Each
//! scene is composed from recipes (single objects, stacks, containers with contents), every
//! object dropped until it rests on the table or on what is under it, then photographed from
//! a frontal-top camera by the CPU rasterizer: the photo, the depth (a 16-bit millimetre PNG
//! from a sensor model, or float32 metres from a depth-estimator model, with noise, holes and
//! mixed pixels at edges), the masks (a label PNG or one PNG per instance), `camera.json`
//! (intrinsics, or only a field of view) and `instances.json` are the inputs of the pipeline;
//! `truth/layout.json`, `truth/instances.json` and `truth/scene.json` are the answers.
//!
//! Everything is a function of the seed and the scene id: scenes are made in parallel, each
//! from its own generator, and the output is byte-identical whatever the thread count.

pub mod annotator;
mod assets;
mod npy;
mod room;
mod scene;
mod sensor;
mod settle;
mod shapes;
mod textures;

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

use mesa_schemas::artifacts::{
    CameraJson, InstanceEntry, InstancesJson, TruthCamera, TruthDepth, TruthInstance,
    TruthInstances, TruthMasks, TruthScene, TruthTable, TRUTH_INSTANCES_SCHEMA, TRUTH_SCENE_SCHEMA,
};
use mesa_schemas::layout::{DatasetLayout, LayoutObject, Provenance, LAYOUT_SCHEMA};
use mesa_schemas::rotation::{tilt_deg_from_quat_xyzw, yaw_deg_from_quat_xyzw};
use rand::seq::SliceRandom;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;
use sha2::{Digest, Sha256};
use thiserror::Error;

use self::assets::Library;
use self::scene::{compose, make_table, Placed, Table, TableType};
use self::sensor::{choose_camera, dilate, estimator_depth, sensor_depth, CameraSetup, DepthStats};
use crate::glb_write::GlbWriteError;
use crate::image_io::{encode_gray16, encode_gray8, encode_rgb8, ImageError};
use crate::mesh::{normalize3, quat_normalize, Aabb};
use crate::raster::{render_shaded_supersampled, visibility, DirectionalLight, DrawItem, Lighting};

/// Options of [`write_demo`].
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct DemoOptions {
    /// Number of scenes; they cycle through the six table types.
    pub scenes: usize,
    /// The seed every random choice derives from (with the scene id).
    pub seed: u64,
    /// Replace an earlier `mesa demo` output made with other options in the same directory
    /// (never anything else; one made with the same options is rewritten in place anyway).
    pub overwrite: bool,
    /// Make depth maps and masks realistic (noise, holes, mixed pixels, overlapping instance
    /// masks); off, they are exact, which tests use to check the geometry.
    pub depth_noise: bool,
}

impl Default for DemoOptions {
    fn default() -> Self {
        Self {
            scenes: 20,
            seed: 7,
            overwrite: false,
            depth_noise: true,
        }
    }
}

impl DemoOptions {
    /// These options with `scenes` scenes.
    pub fn with_scenes(mut self, scenes: usize) -> Self {
        self.scenes = scenes;
        self
    }
    /// These options with another seed.
    pub fn with_seed(mut self, seed: u64) -> Self {
        self.seed = seed;
        self
    }
    /// These options, replacing an earlier demo output or not.
    pub fn with_overwrite(mut self, overwrite: bool) -> Self {
        self.overwrite = overwrite;
        self
    }
    /// These options with or without depth noise.
    pub fn with_depth_noise(mut self, depth_noise: bool) -> Self {
        self.depth_noise = depth_noise;
        self
    }
}

/// What [`write_demo`] wrote.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct DemoSummary {
    /// The workspace.
    pub dir: PathBuf,
    /// GLB files in `assets/library/`.
    pub assets: usize,
    /// Of those, the ones scenes use.
    pub scene_assets: usize,
    /// Categories of the assets scenes use.
    pub categories: usize,
    /// The scenes, in the order they were numbered.
    pub scenes: Vec<DemoScene>,
}

/// One scene written by [`write_demo`].
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct DemoScene {
    /// Like `office_table`.
    pub table_type: String,
    /// Like `office_table_0001`.
    pub scene_id: String,
    /// Objects on the table (instances besides the table).
    pub objects: usize,
    /// `input/depth.png` or `input/depth.npy`.
    pub depth_file: String,
    /// `input/masks.png` or `input/masks/`.
    pub masks: String,
}

/// Why the demo could not be written.
#[derive(Debug, Error)]
pub enum DemoError {
    /// Bad options.
    #[error("{0}")]
    Options(String),
    /// The directory holds something else, or a demo made with other options.
    #[error(
        "{}: the directory is not empty (expected a new or empty directory, or an earlier \
         `mesa demo` output with the same options; to replace a demo made with other options, \
         pass --force)",
        dir.display()
    )]
    NotEmpty {
        /// The directory.
        dir: PathBuf,
    },
    /// Asked to replace a directory `mesa demo` did not write.
    #[error(
        "{}: not an earlier `mesa demo` output (no .mesa/demo.json), so it is left as it is \
         (choose a new or empty directory)",
        dir.display()
    )]
    NotADemo {
        /// The directory.
        dir: PathBuf,
    },
    /// A file could not be written.
    #[error("{}: {source}", path.display())]
    Io {
        /// The file or directory.
        path: PathBuf,
        /// The cause.
        source: std::io::Error,
    },
    /// An asset could not be encoded.
    #[error("asset {asset}: {source}")]
    Glb {
        /// The asset key.
        asset: String,
        /// The cause.
        source: GlbWriteError,
    },
    /// An image could not be encoded.
    #[error("{}: {source}", path.display())]
    Image {
        /// The file.
        path: PathBuf,
        /// The cause.
        source: ImageError,
    },
    /// A JSON file could not be serialised.
    #[error("{}: {source}", path.display())]
    Json {
        /// The file.
        path: PathBuf,
        /// The cause.
        source: serde_json::Error,
    },
    /// No valid scene came out of the generator.
    #[error("scene {scene_id}: no scene with at least {min_objects} visible objects after {attempts} attempts")]
    Scene {
        /// The scene id.
        scene_id: String,
        /// Objects a scene needs.
        min_objects: usize,
        /// Attempts made.
        attempts: usize,
    },
}

/// Fewest objects in a scene (MesaTask scenes have about 15).
const MIN_OBJECTS: usize = 5;
/// Objects seen by fewer pixels are taken out of the scene.
const MIN_VISIBLE_PX: u64 = 40;
/// Internal instance id of the table while rendering.
const TABLE_ITEM: u32 = u32::MAX - 1;
/// Supersampling of the photo.
const PHOTO_SUPERSAMPLING: u32 = 2;

/// Writes a demo workspace into `dir`: created if needed; it must be empty or hold an earlier
/// demo (written with the same options, or any options when `options.overwrite` is set).
pub fn write_demo(dir: &Path, options: &DemoOptions) -> Result<DemoSummary, DemoError> {
    if options.scenes == 0 || options.scenes > 9999 {
        return Err(DemoError::Options(format!(
            "--scenes {}: expected between 1 and 9999 scenes",
            options.scenes
        )));
    }
    prepare_dir(dir, options)?;
    // The record first: a run that fails or is killed half-way leaves a folder that a rerun
    // with the same options completes in place.
    write_json(&dir.join(".mesa/demo.json"), &marker(options))?;
    let library = Library::build().map_err(|(asset, source)| DemoError::Glb {
        asset: asset.to_owned(),
        source,
    })?;

    // The asset library and its annotations.
    library.assets.par_iter().try_for_each(|a| {
        write_file(
            &dir.join("assets/library").join(format!("{}.glb", a.uid)),
            &a.glb,
        )
    })?;
    let annotations: BTreeMap<&str, serde_json::Value> = library
        .assets
        .iter()
        .map(|a| (a.uid.as_str(), a.annotation()))
        .collect();
    write_json(&dir.join("assets/annotations.json"), &annotations)?;

    // The scenes, each from its own generator.
    let scenes = (0..options.scenes)
        .into_par_iter()
        .map(|index| {
            let out = make_scene(&library, index, options)?;
            let folder = dir
                .join("scenes")
                .join(&out.summary.table_type)
                .join(&out.summary.scene_id);
            for (relative, bytes) in &out.files {
                write_file(&folder.join(relative), bytes)?;
            }
            Ok(out.summary)
        })
        .collect::<Result<Vec<_>, DemoError>>()?;

    write_file(
        &dir.join("mesa.toml"),
        b"# mesa configuration of this dataset workspace (written by `mesa demo`).\n\
          # Every key has a default; `mesa run --print-config` shows the resolved values.\n\
          \n\
          # The packs are edited by the demo's simulated annotator (from truth/), between\n\
          # `mesa pack` and `mesa ingest`; a real dataset has a person do it (\"human\").\n\
          [annotate]\n\
          annotator = \"simulated\"\n",
    )?;

    let scene_assets: Vec<_> = library.assets.iter().filter(|a| a.def.in_scenes).collect();
    let categories: BTreeSet<&str> = scene_assets.iter().map(|a| a.def.category).collect();
    Ok(DemoSummary {
        dir: dir.to_path_buf(),
        assets: library.assets.len(),
        scene_assets: scene_assets.len(),
        categories: categories.len(),
        scenes,
    })
}

fn io_error(path: &Path) -> impl FnOnce(std::io::Error) -> DemoError + '_ {
    move |source| DemoError::Io {
        path: path.to_path_buf(),
        source,
    }
}

/// The record of the options a demo folder was written with (`.mesa/demo.json`).
fn marker(options: &DemoOptions) -> serde_json::Value {
    serde_json::json!({
        "generator": "mesa demo",
        "mesa_version": env!("CARGO_PKG_VERSION"),
        "seed": options.seed,
        "scenes": options.scenes,
        "depth_noise": options.depth_noise,
    })
}

/// Makes `dir` ready: created when missing; an empty folder, or an earlier demo written with
/// the same options (rewritten in place: the same bytes, and later stages' outputs stay valid),
/// is used as it is; an earlier demo with other options is cleared when `overwrite` is set;
/// anything else is refused.
fn prepare_dir(dir: &Path, options: &DemoOptions) -> Result<(), DemoError> {
    if !dir.exists() {
        return std::fs::create_dir_all(dir).map_err(io_error(dir));
    }
    let mut entries = std::fs::read_dir(dir).map_err(io_error(dir))?;
    if entries.next().is_none() {
        return Ok(());
    }
    let marker_path = dir.join(".mesa/demo.json");
    let Ok(previous) = std::fs::read(&marker_path) else {
        return Err(if options.overwrite {
            DemoError::NotADemo {
                dir: dir.to_path_buf(),
            }
        } else {
            DemoError::NotEmpty {
                dir: dir.to_path_buf(),
            }
        });
    };
    if previous == json_bytes(&marker_path, &marker(options))? {
        return Ok(());
    }
    if !options.overwrite {
        return Err(DemoError::NotEmpty {
            dir: dir.to_path_buf(),
        });
    }
    // Only what the demo wrote; whatever later stages added under scenes/ goes with it.
    for name in ["assets", "scenes", "mesa.toml", ".mesa/demo.json"] {
        let path = dir.join(name);
        if path.is_dir() {
            std::fs::remove_dir_all(&path).map_err(io_error(&path))?;
        } else if path.exists() {
            std::fs::remove_file(&path).map_err(io_error(&path))?;
        }
    }
    Ok(())
}

/// Writes a file atomically: a temporary file beside it, then a rename.
fn write_file(path: &Path, bytes: &[u8]) -> Result<(), DemoError> {
    if let Some(parent) = path.parent() {
        std::fs::create_dir_all(parent).map_err(io_error(parent))?;
    }
    let mut tmp = path.as_os_str().to_owned();
    tmp.push(".mesa-tmp-demo");
    let tmp = PathBuf::from(tmp);
    std::fs::write(&tmp, bytes).map_err(io_error(&tmp))?;
    std::fs::rename(&tmp, path).map_err(io_error(path))
}

fn json_bytes<T: serde::Serialize + ?Sized>(path: &Path, value: &T) -> Result<Vec<u8>, DemoError> {
    mesa_schemas::json::to_sorted_pretty(value).map_err(|source| DemoError::Json {
        path: path.to_path_buf(),
        source,
    })
}

fn write_json<T: serde::Serialize + ?Sized>(path: &Path, value: &T) -> Result<(), DemoError> {
    write_file(path, &json_bytes(path, value)?)
}

/// The generator of one scene: a function of the seed and the scene id only.
fn scene_rng(seed: u64, scene_id: &str) -> ChaCha8Rng {
    let digest = Sha256::digest(format!("mesa-demo/scene/{seed}/{scene_id}").as_bytes());
    let mut key = [0u8; 32];
    key.copy_from_slice(&digest);
    ChaCha8Rng::from_seed(key)
}

/// How a scene's inputs are written, chosen from its number so that any six consecutive
/// scenes use every form.
#[derive(Debug, Clone, Copy)]
struct Forms {
    depth_png: bool,
    label_masks: bool,
    label_bits: u8,
    intrinsics: bool,
}

impl Forms {
    fn of(index: usize) -> Self {
        let round = index / 6;
        Self {
            depth_png: (index + round) % 2 == 0,
            label_masks: (index / 2 + round) % 2 == 0,
            label_bits: if (index / 4 + round) % 2 == 0 { 8 } else { 16 },
            intrinsics: (index + round) % 3 != 2,
        }
    }
}

struct SceneOutput {
    files: Vec<(PathBuf, Vec<u8>)>,
    summary: DemoScene,
}

fn object_bounds(library: &Library, objects: &[Placed]) -> Vec<Aabb> {
    objects
        .iter()
        .map(|o| {
            let a = &library.assets[o.asset];
            a.baked_table_axes
                .iter()
                .filter_map(|(m, _)| m.transformed(&o.world_from_asset(a)).bounds())
                .reduce(|x, y| x.union(&y))
                .unwrap_or(Aabb::from_point(o.position_m))
        })
        .collect()
}

/// The draw list: objects (instance = index + 1), then the table (TABLE_ITEM), then the
/// background (0).
fn draw_items<'a>(
    library: &'a Library,
    objects: &[Placed],
    room: &'a [room::RoomPart],
) -> Vec<DrawItem<'a>> {
    let mut items = Vec::new();
    for (i, o) in objects.iter().enumerate() {
        let a = &library.assets[o.asset];
        let world_from_mesh = o.world_from_asset(a);
        for (mesh, material) in &a.baked_table_axes {
            items.push(DrawItem {
                mesh,
                world_from_mesh,
                material: &a.surface_materials[*material],
                instance: i as u32 + 1,
                casts_shadow: true,
                vertex_colors: None,
                closed_within: None,
            });
        }
    }
    for part in room {
        items.push(DrawItem {
            mesh: &part.mesh,
            world_from_mesh: crate::mesh::Affine3::IDENTITY,
            material: &part.material,
            instance: if part.is_table { TABLE_ITEM } else { 0 },
            casts_shadow: part.is_table,
            vertex_colors: None,
            closed_within: None,
        });
    }
    items
}

/// Removes `gone` and everything resting on them (directly or not), renumbering supports.
fn remove_objects(objects: &mut Vec<Placed>, gone: &BTreeSet<usize>) {
    let mut removed = gone.clone();
    loop {
        let more: Vec<usize> = (0..objects.len())
            .filter(|i| {
                !removed.contains(i) && objects[*i].support.is_some_and(|s| removed.contains(&s))
            })
            .collect();
        if more.is_empty() {
            break;
        }
        removed.extend(more);
    }
    let mut new_index = vec![None; objects.len()];
    let mut kept = Vec::new();
    for (i, o) in objects.iter().enumerate() {
        if !removed.contains(&i) {
            new_index[i] = Some(kept.len());
            kept.push(o.clone());
        }
    }
    for o in &mut kept {
        o.support = o.support.and_then(|s| new_index[s]);
    }
    *objects = kept;
}

const NUMBER_WORDS: [&str; 11] = [
    "no", "a", "two", "three", "four", "five", "six", "seven", "eight", "nine", "ten",
];

/// "A light oak office desk with a laptop, two books and a mug."
fn environment(table: &Table, labels: &[&str]) -> String {
    let mut counts: Vec<(&str, usize)> = Vec::new();
    for label in labels {
        match counts.iter_mut().find(|(l, _)| l == label) {
            Some((_, n)) => *n += 1,
            None => counts.push((label, 1)),
        }
    }
    let items: Vec<String> = counts
        .iter()
        .map(|(label, n)| {
            let word = NUMBER_WORDS.get(*n).copied().unwrap_or("many");
            if *n == 1 {
                let article = if label.starts_with(['a', 'e', 'i', 'o', 'u']) {
                    "an"
                } else {
                    "a"
                };
                format!("{article} {label}")
            } else if label.ends_with('s') || label.ends_with("sh") || label.ends_with('x') {
                format!("{word} {label}es")
            } else {
                format!("{word} {label}s")
            }
        })
        .collect();
    let list = match items.len() {
        0 => String::new(),
        1 => items[0].clone(),
        n => format!("{} and {}", items[..n - 1].join(", "), items[n - 1]),
    };
    let article = if table.description.starts_with(['a', 'e', 'i', 'o', 'u']) {
        "An"
    } else {
        "A"
    };
    format!("{article} {} with {list}.", table.description)
}

fn round_to(v: f64, step: f64) -> f64 {
    (v / step).round() * step
}

fn make_scene(
    library: &Library,
    index: usize,
    options: &DemoOptions,
) -> Result<SceneOutput, DemoError> {
    let table_type = TableType::ALL[index % TableType::ALL.len()];
    let scene_id = format!(
        "{}_{:04}",
        table_type.name(),
        index / TableType::ALL.len() + 1
    );
    let forms = Forms::of(index);
    let mut rng = scene_rng(options.seed, &scene_id);
    const ATTEMPTS: usize = 12;
    for _ in 0..ATTEMPTS {
        let table = make_table(table_type, &mut rng);
        let Some(mut objects) = compose(library, &table, &mut rng, MIN_OBJECTS) else {
            continue;
        };
        let room = room::build(&table);
        let camera = choose_camera(
            &table,
            &object_bounds(library, &objects),
            forms.intrinsics,
            &mut rng,
        );
        let camera_from_table = camera
            .table_from_camera
            .inverse()
            .unwrap_or_else(|| unreachable!("a camera pose is a rotation and a translation"));
        // Leave out what the camera barely sees, with what rests on it.
        let (vis, visible_px) = loop {
            let items = draw_items(library, &objects, &room);
            let vis = visibility(&camera.intrinsics, &camera_from_table, &items);
            let mut px = vec![0u64; objects.len()];
            for &item in &vis.item {
                if item != u32::MAX {
                    let instance = items[item as usize].instance;
                    if instance != 0 && instance != TABLE_ITEM {
                        px[instance as usize - 1] += 1;
                    }
                }
            }
            let hidden: BTreeSet<usize> = (0..objects.len())
                .filter(|&i| px[i] < MIN_VISIBLE_PX)
                .collect();
            if hidden.is_empty() {
                break (vis, px);
            }
            remove_objects(&mut objects, &hidden);
        };
        if objects.len() < MIN_OBJECTS {
            continue;
        }
        return build_outputs(
            library, &scene_id, table, objects, room, camera, vis, visible_px, forms, options,
            &mut rng,
        );
    }
    Err(DemoError::Scene {
        scene_id,
        min_objects: MIN_OBJECTS,
        attempts: ATTEMPTS,
    })
}

#[allow(clippy::too_many_arguments)]
fn build_outputs(
    library: &Library,
    scene_id: &str,
    table: Table,
    objects: Vec<Placed>,
    room: Vec<room::RoomPart>,
    camera: CameraSetup,
    vis: crate::raster::VisibilityBuffer,
    visible_px: Vec<u64>,
    forms: Forms,
    options: &DemoOptions,
    rng: &mut ChaCha8Rng,
) -> Result<SceneOutput, DemoError> {
    let (width, height) = (
        camera.intrinsics.width as usize,
        camera.intrinsics.height as usize,
    );
    let camera_from_table = camera
        .table_from_camera
        .inverse()
        .unwrap_or_else(|| unreachable!("a camera pose is a rotation and a translation"));
    let items = draw_items(library, &objects, &room);
    let mut files: Vec<(PathBuf, Vec<u8>)> = Vec::new();

    // Mask ids: a shuffled 1..=n+1, the table among them.
    let n = objects.len();
    let mut ids: Vec<u32> = (1..=n as u32 + 1).collect();
    ids.shuffle(rng);
    let table_id = ids[n];
    let object_ids = &ids[..n];

    // Instance names: category and index, in placement order.
    let mut per_category: BTreeMap<&str, usize> = BTreeMap::new();
    let names: Vec<String> = objects
        .iter()
        .map(|o| {
            let category = library.assets[o.asset].def.category;
            let k = per_category.entry(category).or_insert(0);
            *k += 1;
            format!("{category}_{}", *k - 1)
        })
        .collect();

    // The photo.
    let mut light_dir = [
        -0.45 + rng.random_range(-0.2..0.2),
        -0.55 + rng.random_range(-0.2..0.2),
        0.85,
    ];
    light_dir = normalize3(light_dir);
    let mut shadow_region = Aabb::from_points([
        [-0.3, -0.3, -table.height_m],
        [table.width_m + 0.3, table.depth_m + 0.3, 0.0],
    ])
    .unwrap_or_else(|| unreachable!("two points"));
    for b in object_bounds(library, &objects) {
        shadow_region = shadow_region.union(&b);
    }
    let lighting = Lighting {
        up_world: [0.0, 0.0, 1.0],
        sky_color: [0.36, 0.36, 0.4],
        ground_color: [0.15, 0.14, 0.13],
        lights: vec![
            DirectionalLight {
                toward_light_world: light_dir,
                color: [0.92, 0.9, 0.85],
                casts_shadow: true,
            },
            DirectionalLight {
                toward_light_world: normalize3([0.6, -0.35, 0.5]),
                color: [0.16, 0.16, 0.18],
                casts_shadow: false,
            },
        ],
        shadow_region: Some(shadow_region),
        shadow_map_px: 1024,
        background_srgb: [255, 255, 255],
    };
    let rgb = render_shaded_supersampled(
        &camera.intrinsics,
        &camera_from_table,
        &items,
        &lighting,
        PHOTO_SUPERSAMPLING,
    );
    let image_path = PathBuf::from("input/image.png");
    let png =
        encode_rgb8(width as u32, height as u32, &rgb).map_err(|source| DemoError::Image {
            path: image_path.clone(),
            source,
        })?;
    files.push((image_path, png));

    // Depth.
    let (depth_file, stats): (String, DepthStats) = if forms.depth_png {
        let (mm, stats) = sensor_depth(&vis.depth_m, width, height, options.depth_noise, rng);
        let path = PathBuf::from("input/depth.png");
        let png =
            encode_gray16(width as u32, height as u32, &mm).map_err(|source| DemoError::Image {
                path: path.clone(),
                source,
            })?;
        files.push((path, png));
        ("input/depth.png".to_owned(), stats)
    } else {
        let (m, stats) = estimator_depth(&vis.depth_m, width, height, options.depth_noise, rng);
        files.push((
            PathBuf::from("input/depth.npy"),
            npy::npy_f32(height, width, &m),
        ));
        ("input/depth.npy".to_owned(), stats)
    };

    // Masks.
    let label_of = |item: u32| -> u32 {
        if item == u32::MAX {
            return 0;
        }
        match items[item as usize].instance {
            0 => 0,
            TABLE_ITEM => table_id,
            i => object_ids[i as usize - 1],
        }
    };
    let labels: Vec<u32> = vis.item.iter().map(|&i| label_of(i)).collect();
    let dilation = if options.depth_noise { 1 } else { 0 };
    let (masks_summary, bit_depth) = if forms.label_masks {
        let path = PathBuf::from("input/masks.png");
        let png = if forms.label_bits == 8 {
            let v: Vec<u8> = labels.iter().map(|&l| l as u8).collect();
            encode_gray8(width as u32, height as u32, &v)
        } else {
            let v: Vec<u16> = labels.iter().map(|&l| l as u16).collect();
            encode_gray16(width as u32, height as u32, &v)
        }
        .map_err(|source| DemoError::Image {
            path: path.clone(),
            source,
        })?;
        files.push((path, png));
        ("input/masks.png".to_owned(), forms.label_bits)
    } else {
        for &id in &ids {
            let mask: Vec<bool> = labels.iter().map(|&l| l == id).collect();
            let grown = dilate(&mask, width, height, dilation);
            let v: Vec<u8> = grown.iter().map(|&b| if b { 255 } else { 0 }).collect();
            let path = PathBuf::from(format!("input/masks/{id}.png"));
            let png = encode_gray8(width as u32, height as u32, &v).map_err(|source| {
                DemoError::Image {
                    path: path.clone(),
                    source,
                }
            })?;
            files.push((path, png));
        }
        ("input/masks/".to_owned(), 8)
    };
    let table_px = labels.iter().filter(|&&l| l == table_id).count() as u64;

    // camera.json
    let k = &camera.intrinsics;
    let camera_json = if camera.intrinsics_in_json {
        CameraJson::Intrinsics {
            width: k.width,
            height: k.height,
            fx: k.fx,
            fy: k.fy,
            cx: k.cx,
            cy: k.cy,
            depth_calibration: None,
        }
    } else {
        CameraJson::Fov {
            width: k.width,
            height: k.height,
            fov_x_deg: k.fov_x_deg(),
            depth_calibration: None,
        }
    };
    files.push((
        PathBuf::from("input/camera.json"),
        json_bytes(Path::new("input/camera.json"), &camera_json)?,
    ));

    // instances.json, by id.
    let mut entries: Vec<InstanceEntry> = objects
        .iter()
        .zip(object_ids)
        .map(|(o, &id)| InstanceEntry {
            id,
            label: library.assets[o.asset].def.label.to_owned(),
            description: o.description.clone(),
            support: false,
            rle: None,
            embedding: None,
        })
        .collect();
    entries.push(InstanceEntry {
        id: table_id,
        label: table.label.to_owned(),
        description: table.description.clone(),
        support: true,
        rle: None,
        embedding: None,
    });
    entries.sort_by_key(|e| e.id);
    files.push((
        PathBuf::from("input/instances.json"),
        json_bytes(
            Path::new("input/instances.json"),
            &InstancesJson { instances: entries },
        )?,
    ));

    // truth/layout.json
    let mut layout_objects: Vec<LayoutObject> = objects
        .iter()
        .zip(&names)
        .zip(object_ids)
        .map(|((o, name), &id)| {
            let a = &library.assets[o.asset];
            let size = a.bounds_table_axes.size();
            let rotation = quat_normalize(o.rotation_xyzw);
            let pure_yaw = tilt_deg_from_quat_xyzw(rotation) < 1e-6;
            LayoutObject {
                instance: name.clone(),
                retrieved_uid: a.uid.clone(),
                position_cm: o.position_m.map(|v| round_to(v * 100.0, 1e-4)).into(),
                rotation: rotation.into(),
                size_cm: size.map(|v| round_to(v * o.scale * 100.0, 1e-4)).into(),
                scale_factor: [o.scale; 3].into(),
                category: Some(a.def.category.to_owned()),
                description: Some(o.description.clone()),
                z_rotation_deg: pure_yaw.then(|| round_to(yaw_deg_from_quat_xyzw(rotation), 1e-6)),
                provenance: Some(Provenance {
                    stage: "demo".to_owned(),
                    source_instance: Some(id),
                    notes: Vec::new(),
                }),
                extra: BTreeMap::new(),
            }
        })
        .collect();
    layout_objects.sort_by(|a, b| {
        let area = |o: &LayoutObject| o.size_cm.0[0] * o.size_cm.0[1];
        area(b)
            .total_cmp(&area(a))
            .then_with(|| a.instance.cmp(&b.instance))
    });
    let zone_cm = [
        0.0,
        round_to(table.width_m * 100.0, 1e-4),
        0.0,
        round_to(table.depth_m * 100.0, 1e-4),
    ];
    let restricted_cm = table
        .sink
        .map(|s| s.zone_m.map(|v| round_to(v * 100.0, 1e-4)));
    let layout = DatasetLayout {
        schema: LAYOUT_SCHEMA.to_owned(),
        zone_cm: zone_cm.into(),
        restricted_zone_cm: restricted_cm.map(Into::into),
        objects: layout_objects,
        extra: BTreeMap::new(),
    };
    files.push((
        PathBuf::from("truth/layout.json"),
        json_bytes(Path::new("truth/layout.json"), &layout)?,
    ));

    // truth/instances.json
    let mut truth_instances: Vec<TruthInstance> = objects
        .iter()
        .enumerate()
        .map(|(i, o)| {
            let a = &library.assets[o.asset];
            TruthInstance {
                id: object_ids[i],
                label: a.def.label.to_owned(),
                support: false,
                instance: Some(names[i].clone()),
                uid: Some(a.uid.clone()),
                category: Some(a.def.category.to_owned()),
                rests_on: o.support.map(|s| names[s].clone()),
                visible_px: visible_px[i],
            }
        })
        .collect();
    truth_instances.push(TruthInstance {
        id: table_id,
        label: table.label.to_owned(),
        support: true,
        instance: None,
        uid: None,
        category: None,
        rests_on: None,
        visible_px: table_px,
    });
    truth_instances.sort_by_key(|t| t.id);
    let truth_instances = TruthInstances {
        schema: TRUTH_INSTANCES_SCHEMA.to_owned(),
        scene_id: scene_id.to_owned(),
        instances: truth_instances,
    };
    files.push((
        PathBuf::from("truth/instances.json"),
        json_bytes(Path::new("truth/instances.json"), &truth_instances)?,
    ));

    // truth/scene.json
    let labels_in_order: Vec<&str> = {
        let mut order: Vec<usize> = (0..n).collect();
        // Larger things first, as a description would.
        order.sort_by(|&a, &b| {
            let s = |i: usize| {
                let x = library.assets[objects[i].asset].bounds_table_axes.size();
                x[0] * x[1]
            };
            s(b).total_cmp(&s(a)).then(a.cmp(&b))
        });
        order
            .iter()
            .map(|&i| library.assets[objects[i].asset].def.label)
            .collect()
    };
    let truth_scene = TruthScene {
        schema: TRUTH_SCENE_SCHEMA.to_owned(),
        scene_id: scene_id.to_owned(),
        table_type: table.kind.name().to_owned(),
        seed: options.seed,
        environment: environment(&table, &labels_in_order),
        camera: TruthCamera {
            width: k.width,
            height: k.height,
            fx: k.fx,
            fy: k.fy,
            cx: k.cx,
            cy: k.cy,
            fov_x_deg: k.fov_x_deg(),
            camera_json: if camera.intrinsics_in_json {
                "intrinsics"
            } else {
                "fov"
            }
            .to_owned(),
            pitch_deg: camera.pitch_deg,
        },
        table_from_camera: camera.table_from_camera.to_rows_4x4(),
        table: TruthTable {
            label: table.label.to_owned(),
            description: table.description.clone(),
            height_m: table.height_m,
            top_thickness_m: table.thickness_m,
            zone_cm: zone_cm.into(),
            restricted_zone_cm: restricted_cm.map(Into::into),
            wall_gap_m: table.wall_gap_m,
        },
        depth: TruthDepth {
            file: depth_file.clone(),
            model: stats.model.to_owned(),
            scale: stats.scale,
            sigma_constant_m: stats.sigma_constant_m,
            sigma_linear: stats.sigma_linear,
            sigma_quadratic_per_m: stats.sigma_quadratic_per_m,
            smooth_error_relative: stats.smooth_error_relative,
            quantization_m: stats.quantization_m,
            valid_px: stats.valid_px,
            invalid_px: stats.invalid_px,
            mixed_px: stats.mixed_px,
        },
        masks: TruthMasks {
            form: if forms.label_masks {
                "label_png"
            } else {
                "instance_pngs"
            }
            .to_owned(),
            bit_depth,
            dilation_px: if forms.label_masks {
                0
            } else {
                dilation as u32
            },
            min_visible_px: MIN_VISIBLE_PX as u32,
        },
    };
    files.push((
        PathBuf::from("truth/scene.json"),
        json_bytes(Path::new("truth/scene.json"), &truth_scene)?,
    ));

    Ok(SceneOutput {
        files,
        summary: DemoScene {
            table_type: table.kind.name().to_owned(),
            scene_id: scene_id.to_owned(),
            objects: n,
            depth_file,
            masks: masks_summary,
        },
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn any_six_consecutive_scenes_use_every_input_form() {
        for start in [0, 6, 12] {
            let forms: Vec<Forms> = (start..start + 6).map(Forms::of).collect();
            assert!(forms.iter().any(|f| f.depth_png) && forms.iter().any(|f| !f.depth_png));
            assert!(forms.iter().any(|f| f.label_masks) && forms.iter().any(|f| !f.label_masks));
            assert!(forms.iter().any(|f| f.intrinsics) && forms.iter().any(|f| !f.intrinsics));
            assert!(forms.iter().any(|f| f.label_masks && f.label_bits == 16));
            assert!(forms.iter().any(|f| f.label_masks && f.label_bits == 8));
        }
        // Each table type gets both depth forms over two rounds.
        for t in 0..6 {
            assert_ne!(Forms::of(t).depth_png, Forms::of(t + 6).depth_png);
        }
    }

    #[test]
    fn environment_sentences_read_naturally() {
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        let mut table = make_table(TableType::OfficeTable, &mut rng);
        table.description = "light oak office desk".to_owned();
        assert_eq!(
            environment(&table, &["laptop", "book", "book", "mug", "glass"]),
            "A light oak office desk with a laptop, two books, a mug and a glass."
        );
        table.description = "oak desk".to_owned();
        assert_eq!(
            environment(&table, &["apple", "glass", "glass"]),
            "An oak desk with an apple and two glasses."
        );
    }

    #[test]
    fn removing_a_support_removes_what_rests_on_it() {
        let p = |support| Placed {
            asset: 0,
            scale: 1.0,
            rotation_xyzw: [0.0, 0.0, 0.0, 1.0],
            position_m: [0.0; 3],
            support,
            description: String::new(),
        };
        let mut objects = vec![p(None), p(Some(0)), p(Some(1)), p(None), p(Some(3))];
        remove_objects(&mut objects, &BTreeSet::from([1]));
        assert_eq!(objects.len(), 3);
        assert_eq!(objects[2].support, Some(1));
    }
}
