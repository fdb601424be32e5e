//! Writes the mesh `mesa assets` decomposes for a GLB — every placed triangle, in metres, in
//! the asset's table-aligned frame (glTF `(X, Y, Z)` → `(X, -Z, Y)`, no front-alignment yaw:
//! what an asset without annotation gets) — as a binary little-endian PLY, so that a bench can
//! measure collision parts against exactly that mesh (Draco, quantised and skinned files
//! included): `cargo run --release -p mesa-stages --example table_mesh -- IN.glb OUT.ply`.

use std::io::Write;
use std::process::ExitCode;

use mesa_stages::assets::table_aligned_from_gltf;
use mesa_stages::glb_read::read_glb;

fn main() -> ExitCode {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let [input, output] = args.as_slice() else {
        eprintln!("usage: table_mesh IN.glb OUT.ply");
        return ExitCode::from(2);
    };
    let bytes = match std::fs::read(input) {
        Ok(b) => b,
        Err(e) => {
            eprintln!("{input}: cannot read: {e}");
            return ExitCode::FAILURE;
        }
    };
    let mesh = match read_glb(&bytes) {
        Ok(m) => m,
        Err(e) => {
            eprintln!("{input}: {e}");
            return ExitCode::FAILURE;
        }
    };
    let mut ply = format!(
        "ply\nformat binary_little_endian 1.0\ncomment table-aligned frame, metres\nelement \
         vertex {}\nproperty double x\nproperty double y\nproperty double z\nelement face {}\n\
         property list uchar uint vertex_indices\nend_header\n",
        mesh.positions_m.len(),
        mesh.triangles.len()
    )
    .into_bytes();
    for p in &mesh.positions_m {
        for v in table_aligned_from_gltf(*p, 0.0) {
            ply.extend_from_slice(&v.to_le_bytes());
        }
    }
    for t in &mesh.triangles {
        ply.push(3);
        for i in t {
            ply.extend_from_slice(&i.to_le_bytes());
        }
    }
    let written = std::fs::File::create(output).and_then(|mut f| f.write_all(&ply));
    if let Err(e) = written {
        eprintln!("{output}: cannot write: {e}");
        return ExitCode::FAILURE;
    }
    ExitCode::SUCCESS
}
