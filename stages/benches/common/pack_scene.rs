//! The pack bench's scene, shared by `benches/pack.rs` and `examples/pack_timing.rs`: the
//! demo's office_table_0003 (seed 7), its true layout cut to its first 15 objects (13 assets,
//! textured and not, with node hierarchies), with the photo and the instance masks (so the
//! snapshots are made too), the assets' GLBs read into memory.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use mesa_schemas::layout::DatasetLayout;
use mesa_stages::demo::{write_demo, DemoOptions};
use mesa_stages::lift::inputs::{read_instances, read_masks};
use mesa_stages::pack::snapshot::Photo;
use mesa_stages::pack::{AssetSource, PackRequest};

/// The scene, under the dataset folder.
pub const SCENE: &str = "scenes/office_table/office_table_0003";

/// Reads a JSON file.
pub fn read<T: serde::de::DeserializeOwned>(path: &Path) -> T {
    serde_json::from_slice(&std::fs::read(path).expect("read")).expect("json")
}

/// The scene's inputs to `pack_scene`, owned.
pub struct PackScene {
    /// The demo dataset (removed on drop).
    pub dir: tempfile::TempDir,
    /// The scene folder.
    pub scene: PathBuf,
    /// The layout, 15 objects.
    pub layout: DatasetLayout,
    layout_bytes: Vec<u8>,
    glbs: BTreeMap<String, Vec<u8>>,
    png: Vec<u8>,
    photo: Photo,
    masks: BTreeMap<String, Vec<u32>>,
}

impl PackScene {
    /// Writes the demo and reads the scene.
    pub fn new() -> Self {
        let dir = tempfile::tempdir().expect("tempdir");
        write_demo(
            dir.path(),
            &DemoOptions::default().with_scenes(20).with_seed(7),
        )
        .expect("demo");
        let scene = dir.path().join(SCENE);
        let mut layout: DatasetLayout = read(&scene.join("truth/layout.json"));
        layout.objects.truncate(15);
        let layout_bytes = mesa_schemas::json::to_sorted_pretty(&layout).expect("json");
        let glbs = layout
            .objects
            .iter()
            .map(|o| {
                let path = dir
                    .path()
                    .join(format!("assets/library/{}.glb", o.retrieved_uid));
                (o.retrieved_uid.clone(), std::fs::read(path).expect("asset"))
            })
            .collect();
        let png = std::fs::read(scene.join("input/image.png")).expect("photo");
        let image = image::load_from_memory(&png).expect("png").into_rgb8();
        let photo = Photo {
            width: image.width() as usize,
            height: image.height() as usize,
            rgb: image.pixels().map(|p| p.0).collect(),
        };
        let instances = read_instances(&scene.join("input/instances.json")).expect("instances");
        let all_masks =
            read_masks(&scene.join("input"), &instances, photo.width, photo.height).expect("masks");
        let masks = layout
            .objects
            .iter()
            .filter_map(|o| {
                let id = o.provenance.as_ref()?.source_instance?;
                Some((o.instance.clone(), all_masks.pixels.get(&id)?.clone()))
            })
            .collect();
        Self {
            dir,
            scene,
            layout,
            layout_bytes,
            glbs,
            png,
            photo,
            masks,
        }
    }

    /// The assets, by uid, as `pack_scene` takes them.
    pub fn assets(&self) -> BTreeMap<String, AssetSource<'_>> {
        AssetSource::facing_front(&self.glbs)
    }

    /// The pack request of the scene.
    pub fn request<'a>(&'a self, assets: &'a BTreeMap<String, AssetSource<'a>>) -> PackRequest<'a> {
        PackRequest {
            scene_id: "office_table_0003",
            table_type: "office_table",
            layout: &self.layout,
            layout_rel: "coarse/layout.json",
            layout_bytes: &self.layout_bytes,
            assets,
            photo: Some((&self.png, &self.photo)),
            masks: &self.masks,
        }
    }
}
