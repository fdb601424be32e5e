//! mesa-stages: the stages of the mesa pipeline as pure library functions (no CLI types, no
//! global state, every random choice seeded from the scene id and the configured seed), and
//! the shared pieces they need.
//!
//! - [`lift`]: depth and masks to point clouds, the table frame and boxes (SPEC 5.1).
//! - [`annotations`]: the asset annotations (`assets/annotations.json`, SPEC 5.2).
//! - [`glb_read`]: library assets (GLB) read into triangles, Draco included (SPEC 5.2).
//! - [`assets`]: what `mesa assets` learns from each library asset (SPEC 5.2).
//! - [`text`]: the built-in lexical text encoder of retrieval.
//! - [`retrieve`]: an asset per instance by text and size, MesaTask's recipe (SPEC 5.2).
//! - [`place`]: isometric placement into the lifted boxes, the coarse layout (SPEC 5.3).
//! - [`pack`]: the annotator pack, a scene GLB for Blender with the photo and snapshots
//!   (SPEC 5.4).
//! - [`ingest`]: the edited scene read back into the refined layout (SPEC 5.5).
//! - [`gltf_frames`]: table frame ↔ glTF node transforms.
//! - [`graph`]: the rule-based scene graph (SPEC 5.7, `SCENE_GRAPH.md`).
//! - [`demo`]: `mesa demo`, a synthetic dataset workspace with ground truth.
//! - [`mesh`]: triangle meshes, transforms, bounds and frame conversions.
//! - [`glb_write`]: writing GLB files (embedded PNG textures, materials, node hierarchies).
//! - [`raster`]: a CPU z-buffer rasterizer (depth in metres, instance ids, shaded colour).
//! - [`image_io`]: PNG encoding and decoding.
//! - [`tasks`]: task instructions and reasoning texts, from a chat model or the built-in
//!   template writer (SPEC 5.8).
//! - [`records`]: SFT and DPO training records, the corruptions, the split (SPEC 5.9).
//! - [`render`]: pictures of layouts and assets on the CPU, with camera files (SPEC 5.10).
//! - [`report`]: dataset statistics, SVG plots and the HTML page of a dataset (SPEC 5.10).
//! - [`release`]: the MesaTask-10K tree's files (SPEC 5.10).
//! - [`seeding`]: seeded random generators per scene and purpose.
//! - [`import_mesatask`]: the released MesaTask-10K read into a dataset (layouts, annotations).
//! - [`pickle`]: MesaTask's `sbert_text_features.pkl` read (safely, no code run) and written.
//! - [`paths`]: where every artifact of a dataset lives (the one owner of those paths).

pub mod annotate;
pub mod annotations;
pub mod assets;
pub mod check;
pub mod demo;
pub mod eval;
pub mod export;
pub mod glb_read;
pub mod glb_write;
pub mod gltf_frames;
pub mod graph;
pub mod image_io;
pub mod import_mesatask;
pub mod ingest;
pub mod lift;
pub mod mesh;
pub mod pack;
pub mod paths;
pub mod pickle;
mod pieces;
pub mod place;
pub mod raster;
pub mod records;
pub mod release;
pub mod render;
pub mod report;
pub mod retrieve;
pub mod seeding;
pub mod tasks;
pub mod text;
mod tri_tree;

/// Bytes as lowercase hex.
///
/// Two digits a byte from a table into one buffer: every done marker carries the digests of a
/// scene's inputs and outputs, and a `format!` a byte (a string made and dropped for each) was
/// a tenth of the runner's own work in a cheap stage (`mesa graph`: 85,000 instructions a
/// scene for three digests).
pub fn hex(bytes: &[u8]) -> String {
    const DIGITS: &[u8; 16] = b"0123456789abcdef";
    let mut out = String::with_capacity(2 * bytes.len());
    for &b in bytes {
        out.push(char::from(DIGITS[usize::from(b >> 4)]));
        out.push(char::from(DIGITS[usize::from(b & 15)]));
    }
    out
}

/// SHA-256 of bytes, as lowercase hex (the digests of markers, packs and imports).
pub fn sha256_hex(bytes: &[u8]) -> String {
    use sha2::{Digest, Sha256};
    hex(&Sha256::digest(bytes))
}

/// Tests' access to a real GLB of `../shared/realdata/glb` (or of `$MESA_SHARED/realdata/glb`).
#[cfg(test)]
pub(crate) fn shared_glb(name: &str) -> Vec<u8> {
    let shared = std::env::var_os("MESA_SHARED")
        .map(std::path::PathBuf::from)
        .unwrap_or_else(|| {
            std::path::PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../shared")
        });
    let path = shared.join("realdata/glb").join(name);
    std::fs::read(&path).unwrap_or_else(|e| {
        panic!(
            "{}: {e} (../shared beside the repository, or MESA_SHARED)",
            path.display()
        )
    })
}

#[cfg(test)]
mod tests {
    #[test]
    fn hex_gives_two_lowercase_digits_a_byte_as_format_does() {
        let every: Vec<u8> = (0..=255).collect();
        let by_format: String = every.iter().map(|b| format!("{b:02x}")).collect();
        assert_eq!(super::hex(&every), by_format);
        assert_eq!(super::hex(&[]), "");
    }
}
