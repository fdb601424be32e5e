//! The GLB reader on arbitrary bytes: the asset reader (`read_glb`, what `mesa assets` runs on
//! every library file) and the document API `mesa ingest` and `mesa pack` use (world
//! matrices, local primitives with their attributes, placed primitives, images). Every input
//! must give a value or an error, never a panic, a hang or an allocation beyond the limits.
#![no_main]

use libfuzzer_sys::fuzz_target;
use mesa_stages::glb_read::{open_glb, read_glb};

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
    let _ = read_glb(data);
    if let Ok(document) = open_glb(data) {
        let _ = document.world_matrices();
        let _ = document.placed_primitives(true);
        for mesh in 0..document.root().meshes.len().min(16) {
            let _ = document.mesh_primitives(mesh, true);
        }
        for image in 0..document.root().images.len().min(16) {
            let _ = document.image(image);
        }
    }
});
