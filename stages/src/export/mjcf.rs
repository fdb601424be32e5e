//! The MJCF writer: `scene.xml` and `meshes/*.obj` (with the visual meshes' `.mtl`),
//! hand-written in a fixed order and number format. Textures are those of `../textures/`.

use std::collections::BTreeSet;
use std::fmt::Write as _;

use super::obj::{
    fixed, fixed3, material_obj_text, mtl_text, obj_text, rgba_text, sci, MtlMaterial,
};
use super::visual::texture_file;
use super::{BodyModel, ExportConfig, TableBox};

/// The file name of an object's visual mesh of material `k` in `meshes/` (instances hold no
/// `.`).
pub fn visual_file(instance: &str, k: usize) -> String {
    format!("{instance}.visual_{k:03}.obj")
}

/// The file name of an object's visual materials (MTL) in `meshes/`.
pub fn visual_mtl_file(instance: &str) -> String {
    format!("{instance}.visual.mtl")
}

/// The name of an object's visual material `k` (its MJCF material, URDF material and MTL
/// `newmtl` are named so, the last without the instance).
pub fn visual_name(k: usize) -> String {
    format!("visual_{k:03}")
}

/// The MJCF texture name of an asset's image.
pub fn texture_name(uid: &str, image: usize) -> String {
    format!("{uid}_{image}")
}

/// An object's visual meshes (one OBJ per material) and their MTL, named in `meshes/`.
pub fn visual_files(body: &BodyModel) -> Vec<(String, Vec<u8>)> {
    let name = &body.instance;
    let v = &body.visual;
    let mut files = Vec::with_capacity(v.materials.len() + 1);
    let mut mtl = Vec::with_capacity(v.materials.len());
    for (k, m) in v.materials.iter().enumerate() {
        mtl.push(MtlMaterial {
            name: visual_name(k),
            rgba_srgb: m.rgba_srgb(),
            map_kd: m.texture.map(|t| {
                format!(
                    "../../textures/{}",
                    texture_file(&body.record.uid, v.textures[t].image)
                )
            }),
        });
        files.push((
            format!("meshes/{}", visual_file(name, k)),
            material_obj_text(
                &format!(
                    "{name}: visual mesh of material {k} ({}), body frame, metres",
                    comment_safe(&m.name)
                ),
                v,
                k,
                &visual_mtl_file(name),
                &visual_name(k),
            )
            .into_bytes(),
        ));
    }
    files.push((
        format!("meshes/{}", visual_mtl_file(name)),
        mtl_text(
            &format!(
                "{name}: visual materials (glTF base colour, sRGB; images in ../../textures/)"
            ),
            &mtl,
        )
        .into_bytes(),
    ));
    files
}

/// A name from a GLB made safe for a one-line comment.
fn comment_safe(text: &str) -> String {
    text.chars()
        .map(|c| if c.is_control() { ' ' } else { c })
        .collect()
}

/// The file name of an object's convex part `k` in `meshes/`.
pub fn part_file(instance: &str, k: usize) -> String {
    format!("{instance}.part_{k:03}.obj")
}

/// The MJCF files of a scene, relative to the MJCF folder: `scene.xml` and `meshes/*.obj`.
pub fn write_mjcf(
    scene_id: &str,
    table: &[TableBox],
    bodies: &[BodyModel],
    config: &ExportConfig,
) -> Vec<(String, Vec<u8>)> {
    let mut files = Vec::new();
    let mut xml = String::new();
    let _ = writeln!(
        xml,
        "<mujoco model=\"{scene_id}\">\n  <!-- mesa export: metres, z up, the table frame of \
         the layout; the table top is z = 0 -->\n  <compiler angle=\"radian\" \
         meshdir=\"meshes\" texturedir=\"../textures\" autolimits=\"true\"/>\n  <option timestep=\"{}\" gravity=\"0 0 \
         -9.81\"/>",
        fixed(config.timestep_s)
    );
    let friction = format!(
        "{} {} {}",
        fixed(config.friction_sliding),
        fixed(config.friction_torsional),
        fixed(config.friction_rolling)
    );
    let solref = format!(
        "{} {}",
        fixed(config.solref_timeconst_s),
        fixed(config.solref_dampratio)
    );
    let _ = writeln!(
        xml,
        "  <default>\n    <geom friction=\"{friction}\" solref=\"{solref}\" condim=\"{}\"/>\n    \
         <default class=\"visual\">\n      <geom type=\"mesh\" contype=\"0\" conaffinity=\"0\" \
         group=\"1\"/>\n    </default>\n    <default \
         class=\"collision\">\n      <geom type=\"mesh\" group=\"3\" rgba=\"0.2 0.6 0.9 \
         0.5\"/>\n    </default>\n  </default>",
        config.condim
    );
    xml.push_str("  <asset>\n");
    let mut textures = BTreeSet::new();
    for body in bodies {
        for t in &body.visual.textures {
            textures.insert((body.record.uid.as_str(), t.image));
        }
    }
    for (uid, image) in textures {
        let _ = writeln!(
            xml,
            "    <texture name=\"{}\" type=\"2d\" file=\"{}\"/>",
            texture_name(uid, image),
            texture_file(uid, image)
        );
    }
    for body in bodies {
        let name = &body.instance;
        let v = &body.visual;
        for (k, m) in v.materials.iter().enumerate() {
            let texture = m.texture.map_or(String::new(), |t| {
                format!(
                    " texture=\"{}\"",
                    texture_name(&body.record.uid, v.textures[t].image)
                )
            });
            let _ = writeln!(
                xml,
                "    <material name=\"{name}/{}\" rgba=\"{}\"{texture}/>",
                visual_name(k),
                rgba_text(m.rgba_srgb())
            );
            // A visual mesh may be open or self-intersecting: its inertia (unused: the body
            // has an explicit one) is that of its surface.
            let _ = writeln!(
                xml,
                "    <mesh name=\"{name}/{}\" file=\"{}\" inertia=\"shell\"/>",
                visual_name(k),
                visual_file(name, k)
            );
        }
        files.extend(visual_files(body));
        for (k, (points, triangles)) in body.parts.iter().enumerate() {
            let _ = writeln!(
                xml,
                "    <mesh name=\"{name}/part_{k:03}\" file=\"{}\"/>",
                part_file(name, k)
            );
            files.push((
                format!("meshes/{}", part_file(name, k)),
                obj_text(
                    &format!("{name}: convex part {k}, body frame, metres"),
                    points,
                    triangles,
                )
                .into_bytes(),
            ));
        }
    }
    xml.push_str("  </asset>\n  <worldbody>\n");
    xml.push_str("    <light name=\"sun\" pos=\"0 0 3\" dir=\"0 0 -1\" directional=\"true\"/>\n");
    for b in table {
        let _ = writeln!(
            xml,
            "    <geom name=\"{}\" type=\"box\" pos=\"{}\" size=\"{}\" rgba=\"0.55 0.4 0.3 1\"/>",
            b.name,
            fixed3(b.center_m),
            fixed3(b.half_size_m)
        );
    }
    for body in bodies {
        let name = &body.instance;
        let q = body.pose.rotation_xyzw;
        let m = &body.mass;
        let i = m.inertia_kg_m2;
        let _ = writeln!(
            xml,
            "    <body name=\"{name}\" pos=\"{}\" quat=\"{} {} {} {}\">\n      <freejoint \
             name=\"{name}/free\"/>\n      <inertial pos=\"{}\" mass=\"{}\" fullinertia=\"{} {} \
             {} {} {} {}\"/>",
            fixed3(body.pose.position_m),
            fixed(q[3]),
            fixed(q[0]),
            fixed(q[1]),
            fixed(q[2]),
            fixed3(m.center_m),
            sci(m.mass_kg),
            sci(i[0]),
            sci(i[1]),
            sci(i[2]),
            sci(i[3]),
            sci(i[4]),
            sci(i[5])
        );
        for k in 0..body.visual.materials.len() {
            let v = visual_name(k);
            let _ = writeln!(
                xml,
                "      <geom name=\"{name}/{v}\" class=\"visual\" mesh=\"{name}/{v}\" \
                 material=\"{name}/{v}\"/>"
            );
        }
        for k in 0..body.parts.len() {
            let _ = writeln!(
                xml,
                "      <geom name=\"{name}/part_{k:03}\" class=\"collision\" \
                 mesh=\"{name}/part_{k:03}\"/>"
            );
        }
        xml.push_str("    </body>\n");
    }
    xml.push_str("  </worldbody>\n</mujoco>\n");
    files.push(("scene.xml".to_owned(), xml.into_bytes()));
    files
}
