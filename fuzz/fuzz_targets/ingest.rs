//! `mesa ingest` on arbitrary edited-scene bytes, against a real pack: the scene folder named
//! by `MESA_FUZZ_SCENE` (a scene after `mesa pack`: `pack/<scene_id>.glb`, `pack/index.json`
//! and its coarse layout; `fuzz/run.sh` makes one from `mesa demo`). Every input must give a
//! refined layout or an error, never a panic.
#![no_main]

use std::path::PathBuf;
use std::sync::OnceLock;

use libfuzzer_sys::fuzz_target;
use mesa_schemas::annotation::PackIndexArtifact;
use mesa_schemas::layout::DatasetLayout;
use mesa_stages::ingest::{ingest_scene, IngestConfig, IngestRequest};

struct Pack {
    glb: Vec<u8>,
    index: PackIndexArtifact,
    baseline: DatasetLayout,
}

fn pack() -> &'static Pack {
    static PACK: OnceLock<Pack> = OnceLock::new();
    PACK.get_or_init(|| {
        let scene = PathBuf::from(
            std::env::var_os("MESA_FUZZ_SCENE")
                .expect("MESA_FUZZ_SCENE: a packed scene folder (fuzz/run.sh sets it)"),
        );
        let index: PackIndexArtifact = serde_json::from_slice(
            &std::fs::read(scene.join("pack/index.json")).expect("pack/index.json"),
        )
        .expect("index");
        let glb = std::fs::read(scene.join("pack").join(&index.glb)).expect("the pack GLB");
        let baseline = serde_json::from_slice(
            &std::fs::read(scene.join(&index.layout)).expect("the layout"),
        )
        .expect("layout");
        Pack {
            glb,
            index,
            baseline,
        }
    })
}

/// Panics inside the Draco decoder (an alpha, third-party) are caught by mesa, which turns them
/// into a `draco` error (`stages/src/glb_read/draco.rs`); libFuzzer's hook would abort on them
/// before they unwind. Every other panic still aborts: it is a bug.
fn let_draco_panics_unwind() {
    let abort = std::panic::take_hook();
    std::panic::set_hook(Box::new(move |info| {
        let in_draco = info
            .location()
            .is_some_and(|l| l.file().contains("/draco-oxide-"));
        if !in_draco {
            abort(info);
        }
    }));
}

fuzz_target!(init: let_draco_panics_unwind(), |data: &[u8]| {
    let pack = pack();
    for allow_unknown_nodes in [false, true] {
        let _ = ingest_scene(
            &IngestRequest {
                scene_id: &pack.index.scene_id,
                refined_glb: data,
                refined_rel: "refined/fuzz.glb",
                pack_glb: &pack.glb,
                index: &pack.index,
                baseline: &pack.baseline,
            },
            &IngestConfig {
                allow_unknown_nodes,
                ..IngestConfig::default()
            },
        );
    }
});
