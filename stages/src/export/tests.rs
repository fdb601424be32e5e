use approx::assert_abs_diff_eq;

use super::mass::unit_density;
use super::*;
use crate::check::geometry::convex_hull;
use crate::shared_glb;

fn cube_parts(half: f64, offset: [f64; 3]) -> (Vec<[f64; 3]>, Vec<[u32; 3]>) {
    let mut points = Vec::new();
    for x in [-half, half] {
        for y in [-half, half] {
            for z in [-half, half] {
                points.push([x + offset[0], y + offset[1], z + offset[2]]);
            }
        }
    }
    convex_hull(&points)
}

#[test]
fn a_cube_has_the_volume_centre_and_inertia_of_a_solid_cube() {
    let parts = vec![cube_parts(0.05, [0.1, 0.0, 0.0])];
    let unit = unit_density(&parts);
    assert_abs_diff_eq!(unit.volume_m3, 0.001, epsilon = 1e-12);
    let m = unit.with_mass(2.0, [0.1; 3], [1.0; 3]);
    assert_abs_diff_eq!(m.center_m[0], 0.1, epsilon = 1e-9);
    // A solid cube of side a: m a² / 6 about each axis through its centre.
    for k in 0..3 {
        assert_abs_diff_eq!(m.inertia_kg_m2[k], 2.0 * 0.01 / 6.0, epsilon = 1e-9);
        assert_abs_diff_eq!(m.inertia_kg_m2[3 + k], 0.0, epsilon = 1e-9);
    }
    assert!(!m.fallback_box);
}

#[test]
fn two_cubes_sum_their_volumes_and_shift_the_centre() {
    let parts = vec![
        cube_parts(0.05, [0.0, 0.0, 0.0]),
        cube_parts(0.05, [0.2, 0.0, 0.0]),
    ];
    let unit = unit_density(&parts);
    assert_abs_diff_eq!(unit.volume_m3, 0.002, epsilon = 1e-12);
    let m = unit.with_mass(1.0, [0.3, 0.1, 0.1], [1.0; 3]);
    assert_abs_diff_eq!(m.center_m[0], 0.1, epsilon = 1e-9);
    // Parallel axes: each cube 0.5 kg at 0.1 m from the centre adds 0.5 · 0.01 about y and z.
    assert_abs_diff_eq!(m.inertia_kg_m2[0], 0.01 / 6.0, epsilon = 1e-9);
    assert_abs_diff_eq!(m.inertia_kg_m2[1], 0.01 / 6.0 + 0.01, epsilon = 1e-9);
}

#[test]
fn numbers_are_fixed_and_never_negative_zero() {
    assert_eq!(obj::fixed(-0.0000001), "0.000000");
    assert_eq!(obj::fixed(-1.5), "-1.500000");
    assert_eq!(obj::sci(0.0), "0");
    assert_eq!(obj::sci(1.25e-7), "1.25000000e-7");
}

fn layout(restricted: Option<[f64; 4]>) -> DatasetLayout {
    let mut text = serde_json::json!({
        "schema": "mesa.layout/1",
        "item_placement_zone": [0.0, 100.0, 0.0, 60.0],
        "objects": []
    });
    if let Some(r) = restricted {
        text["restricted_zone"] = serde_json::json!(r);
    }
    serde_json::from_value(text).expect("a layout")
}

#[test]
fn the_table_top_is_at_zero_and_a_sink_is_a_hole_over_a_basin() {
    let config = ExportConfig::default();
    let plain = table_boxes(&layout(None), &config);
    assert_eq!(plain.len(), 1);
    let top = plain[0];
    assert_abs_diff_eq!(top.center_m[2] + top.half_size_m[2], 0.0, epsilon = 1e-12);
    assert_abs_diff_eq!(
        top.half_size_m[0],
        0.5 + config.table_margin_m,
        epsilon = 1e-12
    );

    let sink = table_boxes(&layout(Some([40.0, 60.0, 20.0, 40.0])), &config);
    assert_eq!(sink.len(), 5);
    // No top box covers the hole's centre (0.5, 0.3); the floor lies under it.
    for b in &sink {
        let covers = (0..2).all(|k| (b.center_m[k] - [0.5, 0.3][k]).abs() < b.half_size_m[k]);
        if b.name == "sink_floor" {
            assert!(covers);
            assert_abs_diff_eq!(
                b.center_m[2] + b.half_size_m[2],
                -config.sink_depth_m,
                epsilon = 1e-12
            );
        } else {
            assert!(!covers, "{} covers the sink", b.name);
        }
    }
}

#[test]
fn bad_settings_are_named_with_their_key() {
    let config = ExportConfig {
        density_kg_m3: 0.0,
        condim: 5,
        ..ExportConfig::default()
    };
    let problems = config.problems();
    assert_eq!(problems.len(), 2, "{problems:?}");
    assert!(problems[0].starts_with("[export] density_kg_m3"));
    assert!(problems[1].starts_with("[export] condim"));
    assert!(ExportConfig::default().problems().is_empty());
}

#[test]
fn a_part_a_tenth_of_a_millimetre_thin_is_kept_and_thickened() {
    let mut points = Vec::new();
    for x in [0.0, 0.12] {
        for y in [0.0, 0.0001] {
            for z in [0.0, 0.0026] {
                points.push([x, y, z]);
            }
        }
    }
    let (hull, triangles) = solid_part(&points, 0.0005).expect("a hull");
    assert_eq!(triangles.len(), 12);
    let unit = unit_density(&[(hull, triangles)]);
    // Made 0.5 mm thick about its middle.
    assert_abs_diff_eq!(unit.volume_m3, 0.12 * 0.0005 * 0.0026, epsilon = 1e-12);
    // A thick enough part keeps its own volume, turned or not.
    let (hull, triangles) = solid_part(&points, 0.00005).expect("a hull");
    assert_abs_diff_eq!(
        unit_density(&[(hull, triangles)]).volume_m3,
        0.12 * 0.0001 * 0.0026,
        epsilon = 1e-12
    );
}

#[test]
fn a_flat_polygon_part_is_thickened_and_a_segment_is_left_out() {
    // A slanted square: flat along no table axis.
    let square = [
        [0.0, 0.0, 0.0],
        [0.01, 0.0, 0.01],
        [0.0, 0.01, 0.0],
        [0.01, 0.01, 0.01],
    ];
    let (hull, triangles) = solid_part(&square, 0.0005).expect("a hull");
    assert_abs_diff_eq!(
        unit_density(&[(hull, triangles)]).volume_m3,
        0.01 * 0.01 * 2f64.sqrt() * 0.0005,
        epsilon = 1e-12
    );
    let segment = [[0.0, 0.0, 0.0], [0.01, 0.0, 0.0], [0.005, 0.0, 0.0]];
    assert!(solid_part(&segment, 0.0005).is_none());
}

#[test]
fn usd_prim_names_are_identifiers_and_unique() {
    let mut taken = std::collections::BTreeSet::new();
    assert_eq!(usd::prim_name("mug_0", &mut taken), "mug_0");
    assert_eq!(usd::prim_name("mug-0", &mut taken), "mug_0_1");
    assert_eq!(usd::prim_name("3d_print", &mut taken), "_3d_print");
    assert_eq!(usd::prim_name("table", &mut taken), "table_object");
}

#[test]
fn principal_axes_diagonalise_the_inertia() {
    // A tensor with a product of inertia: its principal axes turn it diagonal.
    let inertia = [2.0, 3.0, 4.0, 0.5, 0.0, 0.0];
    let (d, q) = usd::principal_inertia(inertia);
    let r = crate::mesh::quat_to_matrix([q[1], q[2], q[3], q[0]]);
    let m = [[2.0, 0.5, 0.0], [0.5, 3.0, 0.0], [0.0, 0.0, 4.0]];
    // Rᵀ M R = diag(d).
    for a in 0..3 {
        for b in 0..3 {
            let v: f64 = (0..3)
                .flat_map(|i| (0..3).map(move |j| (i, j)))
                .map(|(i, j)| r[i][a] * m[i][j] * r[j][b])
                .sum();
            let expected = if a == b { d[a] } else { 0.0 };
            assert_abs_diff_eq!(v, expected, epsilon = 1e-9);
        }
    }
    assert_abs_diff_eq!(d.iter().sum::<f64>(), 9.0, epsilon = 1e-9);
}

#[test]
fn the_formats_must_name_something_once() {
    assert!(ExportConfig::default().problems().is_empty());
    let none = ExportConfig {
        formats: Vec::new(),
        ..ExportConfig::default()
    };
    assert!(none
        .problems()
        .iter()
        .any(|p| p.contains("formats: is empty")));
    let twice = ExportConfig {
        formats: vec![ExportFormat::Usd, ExportFormat::Usd],
        ..ExportConfig::default()
    };
    assert!(twice.problems().iter().any(|p| p.contains("twice")));
}

/// Two unit squares side by side: the left one (vertices 0..4) in a textured material, the
/// right one (vertices 2..6, sharing an edge) in a plain red one.
fn two_material_mesh() -> VisualMesh {
    let positions_m = vec![
        [0.0, 0.0, 0.0],
        [0.0, 1.0, 0.0],
        [1.0, 0.0, 0.0],
        [1.0, 1.0, 0.0],
        [2.0, 0.0, 0.0],
        [2.0, 1.0, 0.0],
    ];
    let triangles = vec![[0, 2, 3], [0, 3, 1], [2, 4, 5], [2, 5, 3]];
    // glTF's v points down the image: the top row of the image is v = 0.
    let uvs = vec![
        [0.0, 1.0],
        [0.0, 0.0],
        [0.25, 1.0],
        [0.25, 0.1],
        [9.0, 9.0],
        [9.0, 9.0],
    ];
    VisualMesh {
        positions_m,
        triangles,
        uvs,
        materials: vec![
            VisualMaterial {
                name: "label".to_owned(),
                rgba_linear: [1.0; 4],
                texture: Some(0),
                triangles: vec![0, 1],
            },
            VisualMaterial {
                name: "red plastic".to_owned(),
                rgba_linear: [0.5, 0.0, 0.0, 0.25],
                texture: None,
                triangles: vec![2, 3],
            },
        ],
        textures: vec![VisualTexture {
            image: 3,
            png: std::sync::Arc::new(b"not read here".to_vec()),
        }],
        texture_warnings: Vec::new(),
    }
}

#[test]
fn a_textured_material_obj_flips_v_and_holds_only_its_vertices() {
    let mesh = two_material_mesh();
    let text = obj::material_obj_text("left", &mesh, 0, "a.visual.mtl", "visual_000");
    let lines: Vec<&str> = text.lines().collect();
    assert_eq!(
        lines[..3],
        ["# left", "mtllib a.visual.mtl", "usemtl visual_000"]
    );
    let count = |prefix: &str| lines.iter().filter(|l| l.starts_with(prefix)).count();
    assert_eq!((count("v "), count("vt "), count("f ")), (4, 4, 2));
    // OBJ's v points up the image: v_obj = 1 - v_gltf.
    assert!(lines.contains(&"vt 0.000000 0.000000"), "{text}");
    assert!(lines.contains(&"vt 0.250000 0.900000"), "{text}");
    assert!(!lines.contains(&"vt 0.250000 0.100000"), "{text}");
    // Position and texture coordinate share their index.
    assert!(lines.contains(&"f 1/1 3/3 4/4"), "{text}");
    assert!(lines.contains(&"f 1/1 4/4 2/2"), "{text}");
}

#[test]
fn a_plain_material_obj_has_no_texture_coordinates_and_renumbers_its_vertices() {
    let mesh = two_material_mesh();
    let text = obj::material_obj_text("right", &mesh, 1, "a.visual.mtl", "visual_001");
    assert!(!text.contains("\nvt "), "{text}");
    assert!(text.contains("usemtl visual_001\n"), "{text}");
    // Vertices 2, 3, 4, 5 of the mesh become 1..4, in that order.
    let vertices: Vec<&str> = text.lines().filter(|l| l.starts_with("v ")).collect();
    assert_eq!(
        vertices,
        [
            "v 1.000000 0.000000 0.000000",
            "v 1.000000 1.000000 0.000000",
            "v 2.000000 0.000000 0.000000",
            "v 2.000000 1.000000 0.000000"
        ]
    );
    assert!(text.ends_with("f 1 3 4\nf 1 4 2\n"), "{text}");
    // Every triangle is in one material's file.
    let part0 = mesh.material_mesh(0);
    let part1 = mesh.material_mesh(1);
    assert_eq!(part0.triangles.len() + part1.triangles.len(), 4);
    assert!(part1.uvs.is_empty());
}

#[test]
fn a_material_of_one_triangle_gets_a_fourth_vertex_that_draws_nothing() {
    // MuJoCo refuses meshes of fewer than 4 vertices.
    let mut mesh = two_material_mesh();
    mesh.materials[0].triangles = vec![0];
    mesh.materials[1].triangles = vec![1, 2, 3];
    let text = obj::material_obj_text("one", &mesh, 0, "a.visual.mtl", "visual_000");
    let lines: Vec<&str> = text.lines().collect();
    let count = |prefix: &str| lines.iter().filter(|l| l.starts_with(prefix)).count();
    assert_eq!(
        (count("v "), count("vt "), count("f ")),
        (4, 4, 1),
        "{text}"
    );
    // The centroid of vertices 0, 2, 3 and of their texture coordinates (v flipped).
    assert_eq!(lines[6], "v 0.666667 0.333333 0.000000", "{text}");
    assert_eq!(lines[10], "vt 0.166667 0.300000", "{text}");
    assert!(text.ends_with("f 1/1 2/2 3/3\n"), "{text}");
}

#[test]
fn the_mtl_gives_the_srgb_colour_the_alpha_and_the_image() {
    let mesh = two_material_mesh();
    let materials: Vec<obj::MtlMaterial> = mesh
        .materials
        .iter()
        .enumerate()
        .map(|(k, m)| obj::MtlMaterial {
            name: mjcf::visual_name(k),
            rgba_srgb: m.rgba_srgb(),
            map_kd: m.texture.map(|_| "../../textures/u_3.png".to_owned()),
        })
        .collect();
    let text = obj::mtl_text("a", &materials);
    assert!(
        text.contains(
            "newmtl visual_000\nKd 1.0000 1.0000 1.0000\nmap_Kd ../../textures/u_3.png\n"
        ),
        "{text}"
    );
    // Linear 0.5 is sRGB 0.7354; alpha as is.
    assert!(
        text.contains("newmtl visual_001\nKd 0.7354 0.0000 0.0000\nd 0.2500\n"),
        "{text}"
    );
}

fn png_of(width: u32, height: u32) -> Vec<u8> {
    crate::image_io::encode_gray8(width, height, &vec![7; (width * height) as usize])
        .expect("encodes")
}

#[test]
fn a_png_is_kept_a_jpeg_becomes_png_and_the_rest_are_refused_with_why() {
    let png = png_of(4, 2);
    assert_eq!(visual::texture_png(&png).expect("a PNG"), png);
    let mut jpeg = Vec::new();
    image::DynamicImage::ImageRgb8(image::RgbImage::from_pixel(5, 3, image::Rgb([200, 20, 20])))
        .write_to(
            &mut std::io::Cursor::new(&mut jpeg),
            image::ImageFormat::Jpeg,
        )
        .expect("a JPEG");
    let converted = visual::texture_png(&jpeg).expect("converted");
    let decoded = crate::image_io::decode_png(&converted).expect("a PNG");
    assert_eq!((decoded.width, decoded.height), (5, 3));
    assert_eq!(
        visual::texture_png(&jpeg).expect("again"),
        converted,
        "deterministic"
    );
    let webp = b"RIFF\x1a\x00\x00\x00WEBPVP8L\x0d\x00\x00\x00\x2f\x00\x00\x00\x10\x07\x10\x11\x11\x88\x88\xfe\x07\x00";
    let why = visual::texture_png(webp).expect_err("not PNG or JPEG");
    assert!(why.contains("neither PNG nor JPEG"), "{why}");
    let why = visual::texture_png(&png[..png.len() - 20]).expect_err("truncated");
    assert!(why.contains("PNG cannot be decoded"), "{why}");
    // A side above the bound is refused from the header, before decoding.
    let wide = png_of(visual::MAX_TEXTURE_SIDE_PX + 1, 1);
    let why = visual::texture_png(&wide).expect_err("too wide");
    assert!(why.contains("8193 × 1 pixels"), "{why}");
    assert!(visual::texture_png(&png_of(visual::MAX_TEXTURE_SIDE_PX, 1)).is_ok());
}

fn unit_geometry() -> AssetGeometry {
    serde_json::from_value(serde_json::json!({
        "bounds_min_m": [0.0, 0.0, 0.0],
        "bounds_max_m": [0.0, 0.0, 0.0],
        "size_m": [0.0, 0.0, 0.0],
        "gltf_extents_m": [0.0, 0.0, 0.0],
        "front_yaw_deg": 0.0,
        "triangles": 0,
        "vertices": 0,
        "primitives": 0,
        "mesh_instances": 0,
        "materials": [],
        "textured_materials": 0,
        "textures": 0,
        "images": [],
        "draco": false,
        "skinned": false
    }))
    .expect("a geometry")
}

fn visual_of(name: &str) -> VisualMesh {
    let (mesh, surface) = crate::glb_read::read_glb_surface(&shared_glb(name)).expect("reads");
    VisualMesh::from_glb_surface(&mesh, &surface, &unit_geometry())
}

#[test]
fn real_glbs_split_by_material_with_their_png_and_jpeg_textures() {
    // Duck: one material, its texture a PNG kept as it is.
    let duck = visual_of("Duck.glb");
    assert_eq!(duck.materials.len(), 1);
    assert_eq!(duck.textures.len(), 1);
    assert_eq!(duck.materials[0].texture, Some(0));
    assert_eq!(duck.uvs.len(), duck.positions_m.len());
    assert!(
        duck.texture_warnings.is_empty(),
        "{:?}",
        duck.texture_warnings
    );
    // AlphaBlendModeTest: its JPEG texture (images[2]) re-encoded as PNG, PNG ones kept.
    let alpha = visual_of("AlphaBlendModeTest.glb");
    assert!(alpha.materials.len() > 1);
    assert!(alpha.textures.len() >= 2, "{:?}", alpha.texture_warnings);
    for t in &alpha.textures {
        assert!(t.png.starts_with(b"\x89PNG\r\n\x1a\n"), "image {}", t.image);
    }
    // Every triangle is in exactly one material.
    let mut all: Vec<u32> = alpha
        .materials
        .iter()
        .flat_map(|m| m.triangles.iter().copied())
        .collect();
    all.sort_unstable();
    assert_eq!(all, (0..alpha.triangles.len() as u32).collect::<Vec<_>>());
    // An untextured, material-less file: one grey material.
    let shapes = visual_of("ShapeCollection.glb");
    assert_eq!(shapes.materials.len(), 1);
    assert_eq!(shapes.materials[0].name, "default");
    assert!(shapes.uvs.is_empty() && shapes.textures.is_empty());
}

#[test]
fn an_unusable_image_leaves_its_material_the_colour_with_a_warning() {
    let bytes = shared_glb("Duck.glb");
    let (mesh, mut surface) = crate::glb_read::read_glb_surface(&bytes).expect("reads");
    surface.images[0].bytes = Some(b"GIF89a not a texture".to_vec());
    let duck = VisualMesh::from_glb_surface(&mesh, &surface, &unit_geometry());
    assert_eq!(duck.materials.len(), 1);
    assert_eq!(duck.materials[0].texture, None);
    assert!(duck.textures.is_empty() && duck.uvs.is_empty());
    assert_eq!(
        duck.texture_warnings.len(),
        1,
        "{:?}",
        duck.texture_warnings
    );
    assert!(
        duck.texture_warnings[0].starts_with("images[0] (image/png): "),
        "{:?}",
        duck.texture_warnings
    );
}

/// A cube asset of side 0.1 m drawn with [`two_material_mesh`]'s materials.
fn textured_request_files(visual: &VisualMesh, shape: &AssetShape) -> SceneExport {
    let layout = layout(None);
    let object = |instance: &'static str, x: f64| ExportObject {
        instance,
        uid: "asset_a",
        pose: Pose {
            position_m: [x, 0.3, 0.05],
            rotation_xyzw: [0.0, 0.0, 0.0, 1.0],
            scale: [1.0; 3],
        },
        shape,
        visual: Some(visual),
        annotated_mass_kg: None,
    };
    export_scene(
        &ExportRequest {
            scene_id: "s",
            layout_file: "coarse/layout.json",
            layout_sha256: "0",
            layout: &layout,
            objects: vec![object("a_0", 0.2), object("a_1", 0.6)],
            skipped: Vec::new(),
            with_table: true,
        },
        &ExportConfig::default(),
    )
    .expect("exports")
}

#[test]
fn a_scene_writes_each_image_once_and_a_material_per_object_and_format() {
    let mut visual = two_material_mesh();
    visual.textures[0].png = std::sync::Arc::new(png_of(2, 2));
    let (points, _) = cube_parts(0.05, [0.0; 3]);
    let shape = AssetShape::from_parts("asset_a", vec![points], [0.1; 3]);
    let out = textured_request_files(&visual, &shape);
    let textures: Vec<&String> = out
        .files
        .keys()
        .filter(|f| f.starts_with("sim/textures/"))
        .collect();
    assert_eq!(textures, ["sim/textures/asset_a_3.png"]);
    for o in &out.manifest.objects {
        assert_eq!(o.visual_materials, 2);
        assert_eq!(o.textures, ["sim/textures/asset_a_3.png"]);
    }
    let xml = String::from_utf8(out.files["sim/mjcf/scene.xml"].clone()).expect("utf-8");
    assert_eq!(xml.matches("<texture ").count(), 1, "{xml}");
    assert!(xml.contains("texturedir=\"../textures\""));
    assert!(xml.contains(
        "<material name=\"a_1/visual_000\" rgba=\"1.0000 1.0000 1.0000 1.0000\" \
         texture=\"asset_a_3\"/>"
    ));
    assert!(xml.contains(
        "<geom name=\"a_0/visual_001\" class=\"visual\" mesh=\"a_0/visual_001\" \
         material=\"a_0/visual_001\"/>"
    ));
    // Every mesh and material a geom names is declared.
    for geom in xml.split("<geom ").skip(1) {
        for key in ["mesh", "material"] {
            if let Some(rest) = geom
                .split('>')
                .next()
                .and_then(|g| g.split(&format!(" {key}=\"")).nth(1))
            {
                let name = rest.split('"').next().expect("a name");
                assert!(
                    xml.contains(&format!("<{key} name=\"{name}\"")),
                    "{key} {name} is named by a geom but not declared"
                );
            }
        }
    }
    assert_eq!(xml.matches("class=\"visual\" mesh=").count(), 4, "{xml}");
    for f in [
        "sim/mjcf/meshes/a_0.visual_000.obj",
        "sim/mjcf/meshes/a_0.visual_001.obj",
        "sim/mjcf/meshes/a_0.visual.mtl",
    ] {
        assert!(out.files.contains_key(f), "{f}");
    }
    let urdf = String::from_utf8(out.files["sim/urdf/a_0.urdf"].clone()).expect("utf-8");
    assert_eq!(urdf.matches("<visual ").count(), 2, "{urdf}");
    assert!(urdf.contains("<texture filename=\"../textures/asset_a_3.png\"/>"));
    let usda = String::from_utf8(out.files["sim/usd/scene.usda"].clone()).expect("utf-8");
    // Materials per asset: the two objects share them.
    assert_eq!(usda.matches("def Material ").count(), 3, "{usda}");
    assert_eq!(usda.matches("info:id = \"UsdUVTexture\"").count(), 1);
    assert_eq!(usda.matches("texCoord2f[] primvars:st").count(), 2);
    assert!(usda.contains("asset inputs:file = @../textures/asset_a_3.png@"));
    assert!(usda.contains("(0.250000, 0.900000)"), "the v flip in USD");
    // The same inputs, the same bytes.
    let again = textured_request_files(&visual, &shape);
    assert!(again.files == out.files);
}
