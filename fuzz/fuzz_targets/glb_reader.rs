//! The GLB reader on arbitrary bytes: the asset reader (`read_glb`, what `mesa assets` runs on
//! every library file) and the document API `mesa ingest` and `mesa pack` use (world
//! matrices, local primitives with their attributes, placed primitives, images). Every input
//! must give a value or an error, never a panic, a hang or an allocation beyond the limits.
#![no_main]

use libfuzzer_sys::fuzz_target;
use mesa_stages::glb_read::{open_glb, read_glb};

mod common;
use common::let_draco_panics_unwind;

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
