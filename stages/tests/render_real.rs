//! Assets of many exporters made ready to draw (`realdata/glb/`, see `realdata/SOURCES.md`
//! part B): the surface reader gives the same triangles as the geometry reader, with the
//! textures, vertex colours and materials each file has (embedded PNG and JPEG, Draco-compressed
//! attributes, specular-glossiness, unlit), and a drawn view shows them.
//!
//! `MESA_RENDER_DUMP=DIR` writes the views to DIR, to look at.

use std::path::PathBuf;

use mesa_stages::assets::table_aligned_from_gltf;
use mesa_stages::glb_read::{read_glb, read_glb_surface};
use mesa_stages::mesh::Aabb;
use mesa_stages::render::{load_render_asset, render_asset_view, RenderConfig};

fn glb(name: &str) -> Vec<u8> {
    let shared = std::env::var_os("MESA_SHARED")
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../shared"));
    let path = shared.join("realdata/glb").join(name);
    std::fs::read(&path).unwrap_or_else(|e| {
        panic!(
            "{}: {e} (../shared beside the repository, or MESA_SHARED)",
            path.display()
        )
    })
}

/// (file, parts with vertex colours, Draco)
const FILES: [(&str, usize, bool); 8] = [
    ("BoxTextured.glb", 0, false),
    ("Duck.glb", 0, false),
    ("BoxVertexColors.glb", 1, false),
    ("Box_Draco.glb", 0, true),
    ("laptop_blender_draco.glb", 0, true),
    ("CesiumMilkTruck.glb", 0, false),
    ("AlphaBlendModeTest.glb", 0, false),
    ("cakeBirthday.glb", 0, false),
];

#[test]
fn surfaces_keep_the_geometry_readers_triangles_and_find_every_texture() {
    for (file, coloured, draco) in FILES {
        let bytes = glb(file);
        let mesh = read_glb(&bytes).expect("reads");
        let (with_surface, surface) = read_glb_surface(&bytes).expect("reads");
        assert_eq!(with_surface.positions_m, mesh.positions_m, "{file}");
        assert_eq!(with_surface.triangles, mesh.triangles, "{file}");
        assert_eq!(surface.normals.len(), mesh.positions_m.len(), "{file}");
        assert_eq!(surface.uvs.len(), mesh.positions_m.len(), "{file}");
        let covered: u32 = surface.primitives.iter().map(|p| p.triangles).sum();
        assert_eq!(covered as usize, mesh.triangles.len(), "{file}");
        assert_eq!(mesh.info.draco, draco, "{file}");
        for n in &surface.normals {
            let len = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
            assert!(
                len == 0.0 || (len - 1.0).abs() < 1e-4,
                "{file}: normal {n:?}"
            );
        }

        let asset = load_render_asset(&bytes, 0.0, 256).expect("loads");
        let expected = Aabb::from_points(
            mesh.positions_m
                .iter()
                .map(|p| table_aligned_from_gltf(*p, 0.0)),
        )
        .expect("bounds");
        assert_eq!(asset.bounds, expected, "{file}");
        let parts_textured = asset
            .parts
            .iter()
            .filter(|p| p.material.texture.is_some())
            .count();
        // One part per material used; textured as the geometry reader's material list says.
        let used: std::collections::BTreeSet<Option<usize>> =
            surface.primitives.iter().map(|p| p.material).collect();
        let textured = used
            .iter()
            .filter(|m| m.is_some_and(|m| mesh.info.materials[m].textured))
            .count();
        assert_eq!(asset.parts.len(), used.len(), "{file}: parts");
        assert_eq!(parts_textured, textured, "{file}: textured parts");
        let parts_coloured = asset
            .parts
            .iter()
            .filter(|p| p.vertex_colors.is_some())
            .count();
        assert_eq!(
            parts_coloured, coloured,
            "{file}: parts with vertex colours"
        );
        for part in &asset.parts {
            if let Some(texture) = &part.material.texture {
                assert!(texture.width <= 256 && texture.height <= 256, "{file}");
                assert_eq!(part.mesh.uvs.len(), part.mesh.positions.len(), "{file}");
            }
        }
    }
}

#[test]
fn alpha_modes_are_drawn_opaque_with_a_warning() {
    let asset = load_render_asset(&glb("AlphaBlendModeTest.glb"), 0.0, 256).expect("loads");
    assert!(
        asset.warnings.iter().any(|w| w.contains("drawn opaque")),
        "{:?}",
        asset.warnings
    );
}

#[test]
fn a_textured_asset_shows_its_texture_in_every_view() {
    let config = RenderConfig {
        width_px: 128,
        height_px: 128,
        ..RenderConfig::default()
    };
    let dump = std::env::var_os("MESA_RENDER_DUMP").map(PathBuf::from);
    // (file, whether texture or vertex colours make it many-coloured): the Draco laptop has
    // plain materials only.
    for (file, colourful) in [
        ("BoxTextured.glb", true),
        ("Duck.glb", true),
        ("BoxVertexColors.glb", true),
        ("CesiumMilkTruck.glb", true),
        ("laptop_blender_draco.glb", false),
    ] {
        let asset = load_render_asset(&glb(file), 0.0, 1024).expect("loads");
        for k in 0..8 {
            let view = render_asset_view(file, &asset, k, &config).expect("renders");
            let covered: Vec<&[u8]> = view
                .picture
                .rgba
                .chunks_exact(4)
                .filter(|p| p[3] == 255)
                .collect();
            // The asset fills much of the picture (its bounding sphere fills 90 %).
            assert!(
                covered.len() > 128 * 128 / 10,
                "{file} view {k}: {} px",
                covered.len()
            );
            // Texture or vertex colours: many different colours, not one shaded tint.
            let mut colours: Vec<[u8; 3]> = covered
                .iter()
                .map(|p| [p[0] / 16, p[1] / 16, p[2] / 16])
                .collect();
            colours.sort_unstable();
            colours.dedup();
            if colourful {
                assert!(
                    colours.len() > 12,
                    "{file} view {k}: {} colours",
                    colours.len()
                );
            }
            if let Some(dir) = &dump {
                std::fs::create_dir_all(dir).expect("dump dir");
                std::fs::write(dir.join(format!("{file}_{}.png", view.name)), &view.png)
                    .expect("dump");
            }
        }
    }
}

proptest::proptest! {
    #![proptest_config(proptest::prelude::ProptestConfig::with_cases(256))]
    /// Damaged textured files (bytes changed, the end cut off) are loaded or rejected, never a
    /// panic; what loads has one normal, texture coordinate and colour per vertex.
    #[test]
    fn damaged_textured_files_load_or_are_rejected(
        flips in proptest::collection::vec((proptest::prelude::any::<proptest::sample::Index>(), proptest::prelude::any::<u8>()), 0..6),
        keep in 0.0f64..=1.0,
        file in proptest::sample::select(vec!["BoxTextured.glb", "BoxVertexColors.glb", "Box_Draco.glb"]),
    ) {
        let mut bytes = glb(file);
        for (at, value) in flips {
            let i = at.index(bytes.len());
            bytes[i] = value;
        }
        let len = ((bytes.len() as f64) * keep).round() as usize;
        bytes.truncate(len.max(1));
        if let Ok((mesh, surface)) = read_glb_surface(&bytes) {
            proptest::prop_assert_eq!(surface.normals.len(), mesh.positions_m.len());
            proptest::prop_assert_eq!(surface.uvs.len(), mesh.positions_m.len());
            proptest::prop_assert_eq!(surface.colors.len(), mesh.positions_m.len());
            let asset = load_render_asset(&bytes, 0.0, 64);
            proptest::prop_assert!(asset.is_ok());
        }
    }
}
