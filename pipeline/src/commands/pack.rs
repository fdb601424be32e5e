//! `mesa pack`: the runner adapter of [`mesa_stages::pack`]: `coarse/layout.json`, the asset
//! library and the photo and masks → `pack/` (the scene GLB, `reference.png`, snapshots,
//! `index.json`, `README.txt`, optionally a zip).

use mesa_stages::paths::scene::{
    refined_glb, COARSE_LAYOUT, IMAGE, INSTANCES, LIFT, MASKS_DIR, MASKS_PNG, PACK_INDEX,
};
use std::collections::BTreeMap;
use std::sync::Arc;

use anyhow::{anyhow, bail, Context as _};
use mesa_schemas::annotation::PackIndexArtifact;
use mesa_schemas::artifacts::{AssetIndexArtifact, LiftArtifact};
use mesa_schemas::layout::DatasetLayout;
use mesa_stages::lift::inputs::{read_instances, read_masks, read_png, PngLimit};
use mesa_stages::pack::snapshot::Photo;
use mesa_stages::pack::{pack_scene, AssetSource, PackRequest};

use crate::cli::{Global, SceneArgs};
use crate::dataset_cache::DatasetCache;
use crate::fsio::read_json;
use crate::fsio::sha256_hex;
use crate::runner::{digest_of, Scene, SceneOutput, SceneStage, StageContext};
use mesa_stages::paths::dataset::INDEX;
use std::process::ExitCode;

/// `mesa pack`: the runner flags.
pub type Args = SceneArgs;

/// Runs `mesa pack`.
pub fn run(args: Args, global: Global) -> anyhow::Result<ExitCode> {
    args.resolve(global)?.run(&PackStage::new())
}

/// The `pack` stage.
#[derive(Default)]
pub struct PackStage {
    indexes: DatasetCache<AssetIndexArtifact>,
}

impl PackStage {
    /// A stage with nothing loaded yet.
    pub fn new() -> Self {
        Self::default()
    }

    fn index(&self, ctx: &StageContext<'_>) -> anyhow::Result<Arc<AssetIndexArtifact>> {
        self.indexes.get_or_load(ctx.dataset, || {
            read_json(&ctx.dataset.join(INDEX), "run `mesa assets` to write it")
        })
    }
}

fn read_layout(scene: &Scene) -> anyhow::Result<(DatasetLayout, Vec<u8>)> {
    let path = scene.path(COARSE_LAYOUT);
    if !path.exists() {
        bail!("{}: no layout (run `mesa place`)", path.display());
    }
    // The one layout reader: bounded, validated (instance names, duplicate keys included).
    crate::layouts::read_dataset_layout_bytes(&path, "pack")
}

/// The mask files of a scene that exist, relative to the scene folder.
fn mask_files(scene: &Scene) -> Vec<String> {
    let mut out = Vec::new();
    if scene.path(MASKS_PNG).is_file() {
        out.push(MASKS_PNG.to_owned());
    }
    if let Ok(entries) = std::fs::read_dir(scene.path(MASKS_DIR)) {
        let mut names: Vec<String> = entries
            .filter_map(|e| e.ok())
            .map(|e| e.file_name().to_string_lossy().into_owned())
            .filter(|n| n.ends_with(".png"))
            .collect();
        names.sort();
        out.extend(names.into_iter().map(|n| format!("{MASKS_DIR}/{n}")));
    }
    out
}

impl SceneStage for PackStage {
    fn name(&self) -> &'static str {
        "pack"
    }

    fn before_refined(&self) -> bool {
        true
    }

    fn inputs(&self, ctx: &StageContext<'_>, scene: &Scene) -> anyhow::Result<Vec<String>> {
        let mut inputs = vec![scene.rel(COARSE_LAYOUT), INDEX.to_owned()];
        // The assets the layout places (a missing layout is reported by the runner).
        if let Ok((layout, _)) = read_layout(scene) {
            let index = self.index(ctx)?;
            let mut uids: Vec<&str> = layout
                .objects
                .iter()
                .map(|o| o.retrieved_uid.as_str())
                .collect();
            uids.sort_unstable();
            uids.dedup();
            for uid in uids {
                let record = index.assets.get(uid).ok_or_else(|| {
                    anyhow!(
                        "{}: asset {uid} is not in {INDEX} (rerun `mesa assets`, then `mesa \
                         retrieve` and `mesa place`)",
                        scene.path(COARSE_LAYOUT).display()
                    )
                })?;
                inputs.push(record.file.clone());
            }
        }
        for rel in [IMAGE, INSTANCES, LIFT] {
            if scene.path(rel).is_file() {
                inputs.push(scene.rel(rel));
            }
        }
        inputs.extend(mask_files(scene).iter().map(|rel| scene.rel(rel)));
        Ok(inputs)
    }

    fn config_digest(&self, ctx: &StageContext<'_>) -> String {
        digest_of(&ctx.config.pack)
    }

    fn run(&self, ctx: &StageContext<'_>, scene: &Scene) -> anyhow::Result<SceneOutput> {
        let (layout, layout_bytes) = read_layout(scene)?;
        // An annotator's file made from an earlier pack must not be paired with a new one.
        let refined = scene.path(&refined_glb(&scene.scene_id));
        let index_path = scene.path(PACK_INDEX);
        if refined.is_file() && index_path.is_file() {
            let previous: PackIndexArtifact =
                read_json(&index_path, "the pack's index; delete pack/ to re-pack")?;
            if previous.layout_sha256 != sha256_hex(&layout_bytes) {
                bail!(
                    "{}: the annotator's file was made from the pack of an earlier {COARSE_LAYOUT}; \
                     re-packing now would pair it with a scene it was not made from (move {} \
                     away to re-pack and send the new pack, or restore the earlier layout)",
                    refined.display(),
                    refined.display()
                );
            }
        }
        let index = self.index(ctx)?;
        let mut bytes = BTreeMap::new();
        for object in &layout.objects {
            let uid = &object.retrieved_uid;
            if bytes.contains_key(uid) {
                continue;
            }
            let record = index
                .assets
                .get(uid)
                .ok_or_else(|| anyhow!("{}: asset {uid} is not in {INDEX}", object.instance))?;
            let path = ctx.dataset.join(&record.file);
            let glb =
                std::fs::read(&path).with_context(|| format!("{}: cannot read", path.display()))?;
            let front_yaw_deg = record.geometry.as_ref().map_or(0.0, |g| g.front_yaw_deg);
            bytes.insert(uid.clone(), (glb, front_yaw_deg));
        }
        let assets: BTreeMap<String, AssetSource<'_>> = bytes
            .iter()
            .map(|(uid, (glb, yaw))| {
                (
                    uid.clone(),
                    AssetSource {
                        glb,
                        front_yaw_deg: *yaw,
                    },
                )
            })
            .collect();

        // The photo and the instance masks, for the snapshots.
        let mut out = SceneOutput::new();
        let input = scene.path("input");
        let photo_path = input.join("image.png");
        let photo = if photo_path.is_file() {
            let png = std::fs::read(&photo_path)
                .with_context(|| format!("{}: cannot read", photo_path.display()))?;
            let image = read_png(
                &photo_path,
                PngLimit::MaxPixels(ctx.config.lift.max_image_pixels),
            )?
            .into_rgb8();
            let (width, height) = (image.width() as usize, image.height() as usize);
            Some((
                png,
                Photo {
                    width,
                    height,
                    rgb: image.pixels().map(|p| p.0).collect(),
                },
            ))
        } else {
            None
        };
        let mut masks = BTreeMap::new();
        if let Some((_, photo)) = &photo {
            match instance_masks(scene, photo.width, photo.height, &layout) {
                Ok(found) => masks = found,
                Err(e) => out.warn(format!("no snapshots: {e:#}")),
            }
        }
        let layout_rel = COARSE_LAYOUT;
        let packed = pack_scene(
            &PackRequest {
                scene_id: &scene.scene_id,
                table_type: &scene.table_type,
                layout: &layout,
                layout_rel,
                layout_bytes: &layout_bytes,
                assets: &assets,
                photo: photo.as_ref().map(|(png, p)| (png.as_slice(), p)),
                masks: &masks,
            },
            &ctx.config.pack,
        )?;
        for (rel, bytes) in packed.files {
            out.add_file(format!("pack/{rel}"), bytes);
        }
        for warning in packed.warnings {
            out.warn(warning);
        }
        Ok(out)
    }
}

/// Mask pixels by instance: the instance's mask id from `coarse/lift.json` (else its
/// provenance), its pixels from the scene's masks.
fn instance_masks(
    scene: &Scene,
    width: usize,
    height: usize,
    layout: &DatasetLayout,
) -> anyhow::Result<BTreeMap<String, Vec<u32>>> {
    let input = scene.path("input");
    let instances = read_instances(&input.join("instances.json"))?;
    let masks = read_masks(&input, &instances, width, height)?;
    let lift: Option<LiftArtifact> = read_json(&scene.path(LIFT), "mesa lift").ok();
    let mut out = BTreeMap::new();
    for object in &layout.objects {
        let from_lift = lift.as_ref().and_then(|l| {
            l.instances
                .iter()
                .find(|i| i.instance == object.instance)
                .map(|i| i.mask_id)
        });
        let id = from_lift.or(object.provenance.as_ref().and_then(|p| p.source_instance));
        if let Some(pixels) = id.and_then(|id| masks.pixels.get(&id)) {
            out.insert(object.instance.clone(), pixels.clone());
        }
    }
    Ok(out)
}
