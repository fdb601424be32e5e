//! The URDF writer: one URDF per object (a single free link) and one for the table, with
//! `scene.json` giving each URDF's pose (URDF is a tree: a scene of free objects is a set of
//! URDFs). The meshes are the MJCF's (`../mjcf/meshes/`): the two formats share them.

use std::fmt::Write as _;

use mesa_schemas::artifacts::{UrdfPlacement, UrdfSceneArtifact, URDF_SCENE_SCHEMA};

use super::mjcf::{part_file, visual_file, visual_name};
use super::obj::{fixed, fixed3, rgba_text, sci};
use super::visual::texture_file;
use super::{BodyModel, ExportConfig, TableBox};

/// The table's URDF file name.
pub const TABLE_URDF: &str = "table.urdf";

/// The URDF file name of an object.
pub fn urdf_file(instance: &str) -> String {
    format!("{instance}.urdf")
}

fn contact(config: &ExportConfig) -> String {
    format!(
        "    <contact>\n      <lateral_friction value=\"{}\"/>\n      <spinning_friction \
         value=\"{}\"/>\n      <rolling_friction value=\"{}\"/>\n    </contact>\n",
        fixed(config.friction_sliding),
        fixed(config.friction_torsional),
        fixed(config.friction_rolling)
    )
}

/// The URDF of one object: a link named its instance, origin at its body frame.
pub fn object_urdf(body: &BodyModel, config: &ExportConfig) -> String {
    let name = &body.instance;
    let m = &body.mass;
    let i = m.inertia_kg_m2;
    let mut out = String::new();
    let _ = write!(
        out,
        "<?xml version=\"1.0\"?>\n<!-- mesa export: metres, z up; the link frame is the \
         object's bounding-box centre, placed by scene.json -->\n<robot name=\"{name}\">\n  \
         <link name=\"{name}\">\n{}    <inertial>\n      <origin xyz=\"{}\" rpy=\"0 0 \
         0\"/>\n      <mass value=\"{}\"/>\n      <inertia ixx=\"{}\" iyy=\"{}\" izz=\"{}\" \
         ixy=\"{}\" ixz=\"{}\" iyz=\"{}\"/>\n    </inertial>\n",
        contact(config),
        fixed3(m.center_m),
        sci(m.mass_kg),
        sci(i[0]),
        sci(i[1]),
        sci(i[2]),
        sci(i[3]),
        sci(i[4]),
        sci(i[5]),
    );
    let v = &body.visual;
    for (k, m) in v.materials.iter().enumerate() {
        // The texture also reaches PyBullet through the OBJ's MTL (`map_Kd`).
        let texture = m.texture.map_or(String::new(), |t| {
            format!(
                "<texture filename=\"../textures/{}\"/>",
                texture_file(&body.record.uid, v.textures[t].image)
            )
        });
        let _ = writeln!(
            out,
            "    <visual name=\"{0}\">\n      <geometry><mesh \
             filename=\"../mjcf/meshes/{1}\"/></geometry>\n      <material \
             name=\"{name}/{0}\"><color rgba=\"{2}\"/>{texture}</material>\n    </visual>",
            visual_name(k),
            visual_file(name, k),
            rgba_text(m.rgba_srgb())
        );
    }
    for k in 0..body.parts.len() {
        let _ = writeln!(
            out,
            "    <collision name=\"part_{k:03}\">\n      <geometry><mesh \
             filename=\"../mjcf/meshes/{}\"/></geometry>\n    </collision>",
            part_file(name, k)
        );
    }
    out.push_str("  </link>\n</robot>\n");
    out
}

/// The table's URDF: one static link (mass 0; load it with a fixed base) of boxes.
pub fn table_urdf(table: &[TableBox], config: &ExportConfig) -> String {
    let mut out = format!(
        "<?xml version=\"1.0\"?>\n<!-- mesa export: the table, its top at z = 0; load with a \
         fixed base at the origin -->\n<robot name=\"table\">\n  <link name=\"table\">\n{}    \
         <inertial>\n      <mass value=\"0\"/>\n      <inertia ixx=\"0\" iyy=\"0\" izz=\"0\" \
         ixy=\"0\" ixz=\"0\" iyz=\"0\"/>\n    </inertial>\n",
        contact(config)
    );
    for b in table {
        let size = b.half_size_m.map(|h| 2.0 * h);
        for element in ["visual", "collision"] {
            let _ = writeln!(
                out,
                "    <{element} name=\"{}\">\n      <origin xyz=\"{}\" rpy=\"0 0 0\"/>\n      \
                 <geometry><box size=\"{}\"/></geometry>\n    </{element}>",
                b.name,
                fixed3(b.center_m),
                fixed3(size)
            );
        }
    }
    out.push_str("  </link>\n</robot>\n");
    out
}

/// The URDF files of a scene, relative to the URDF folder: one per object, the table, and
/// `scene.json`.
pub fn write_urdf(
    scene_id: &str,
    table: &[TableBox],
    bodies: &[BodyModel],
    config: &ExportConfig,
) -> Result<Vec<(String, Vec<u8>)>, serde_json::Error> {
    let mut files = Vec::new();
    if !table.is_empty() {
        files.push((
            TABLE_URDF.to_owned(),
            table_urdf(table, config).into_bytes(),
        ));
    }
    let mut objects = Vec::new();
    for body in bodies {
        files.push((
            urdf_file(&body.instance),
            object_urdf(body, config).into_bytes(),
        ));
        objects.push(UrdfPlacement {
            instance: body.instance.clone(),
            urdf: urdf_file(&body.instance),
            position_m: body.pose.position_m,
            orientation_xyzw: body.pose.rotation_xyzw,
            fixed_base: false,
        });
    }
    let scene = UrdfSceneArtifact {
        schema: URDF_SCENE_SCHEMA.to_owned(),
        scene_id: scene_id.to_owned(),
        table: (!table.is_empty()).then(|| UrdfPlacement {
            instance: "table".to_owned(),
            urdf: TABLE_URDF.to_owned(),
            position_m: [0.0; 3],
            orientation_xyzw: [0.0, 0.0, 0.0, 1.0],
            fixed_base: true,
        }),
        objects,
        timestep_s: Some(config.timestep_s),
    };
    files.push((
        "scene.json".to_owned(),
        mesa_schemas::json::to_sorted_pretty(&scene)?,
    ));
    Ok(files)
}
