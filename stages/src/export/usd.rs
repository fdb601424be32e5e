//! The USD writer: `scene.usda` as text. `upAxis = "Z"`, `metersPerUnit = 1`, a
//! `PhysicsScene`; each object an `Xform` with `PhysicsRigidBodyAPI` and `PhysicsMassAPI`
//! (mass, centre of mass, diagonal inertia and its principal axes), its visual meshes (one per
//! material, with `primvars:st` when textured) each bound to a `UsdPreviewSurface` material
//! of `/World/Looks` (one per asset material; a `UsdUVTexture` reading `../textures/` for a
//! textured one), and its convex parts as `Mesh` prims with `PhysicsCollisionAPI` and
//! `PhysicsMeshCollisionAPI` (approximation `convexHull`, purpose `guide`); the table static
//! `Cube` colliders (collision without a rigid body).

use std::collections::{BTreeMap, BTreeSet};
use std::fmt::Write as _;

use nalgebra::{Matrix3, Rotation3, SymmetricEigen, UnitQuaternion};

use super::mjcf::visual_name;
use super::obj::{channel, fixed, sci};
use super::visual::{texture_file, VisualMaterial};
use super::{BodyModel, TableBox};

/// The material of meshes drawn grey (no glTF material, or convex parts drawn instead).
const DEFAULT_MATERIAL: &str = "/World/Looks/ObjectMaterial";

/// A USD prim name for an instance: `-` becomes `_`, a leading digit gets a `_` before it,
/// and a name already taken gets `_<n>` after it. The instance itself is kept in the prim's
/// `mesa:instance` attribute.
pub fn prim_name(instance: &str, taken: &mut BTreeSet<String>) -> String {
    let mut name: String = instance
        .chars()
        .map(|c| if c.is_ascii_alphanumeric() { c } else { '_' })
        .collect();
    if !name.starts_with(|c: char| c.is_ascii_alphabetic() || c == '_') {
        name.insert(0, '_');
    }
    // Names the writer uses itself.
    for reserved in ["table", "Looks", "PhysicsScene"] {
        if name == reserved {
            name.push_str("_object");
        }
    }
    let mut candidate = name.clone();
    let mut n = 1;
    while taken.contains(&candidate) {
        candidate = format!("{name}_{n}");
        n += 1;
    }
    taken.insert(candidate.clone());
    candidate
}

/// Diagonal inertia and the rotation of its principal axes, quaternion [w, x, y, z].
pub fn principal_inertia(inertia: [f64; 6]) -> ([f64; 3], [f64; 4]) {
    let [ixx, iyy, izz, ixy, ixz, iyz] = inertia;
    let m = Matrix3::new(ixx, ixy, ixz, ixy, iyy, iyz, ixz, iyz, izz);
    let eigen = SymmetricEigen::new(m);
    let mut axes = eigen.eigenvectors;
    if axes.determinant() < 0.0 {
        let flipped = -axes.column(2);
        axes.set_column(2, &flipped);
    }
    let q = UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(axes));
    let d = eigen.eigenvalues;
    ([d[0], d[1], d[2]], [q.w, q.i, q.j, q.k])
}

fn mesh_body(out: &mut String, indent: &str, points: &[[f64; 3]], triangles: &[[u32; 3]]) {
    let _ = write!(out, "{indent}int[] faceVertexCounts = [");
    for (i, _) in triangles.iter().enumerate() {
        out.push_str(if i == 0 { "3" } else { ", 3" });
    }
    let _ = write!(out, "]\n{indent}int[] faceVertexIndices = [");
    for (i, t) in triangles.iter().enumerate() {
        let sep = if i == 0 { "" } else { ", " };
        let _ = write!(out, "{sep}{}, {}, {}", t[0], t[1], t[2]);
    }
    let _ = write!(out, "]\n{indent}point3f[] points = [");
    for (i, p) in points.iter().enumerate() {
        let sep = if i == 0 { "" } else { ", " };
        let _ = write!(
            out,
            "{sep}({}, {}, {})",
            fixed(p[0]),
            fixed(p[1]),
            fixed(p[2])
        );
    }
    let _ = writeln!(out, "]\n{indent}uniform token subdivisionScheme = \"none\"");
}

fn tuple3(v: [f64; 3]) -> String {
    format!("({}, {}, {})", fixed(v[0]), fixed(v[1]), fixed(v[2]))
}

fn tuple3_sci(v: [f64; 3]) -> String {
    format!("({}, {}, {})", sci(v[0]), sci(v[1]), sci(v[2]))
}

/// An object's visual meshes under an `Xform "visual"`, each bound to its material
/// (`looks[k]`, a prim path).
fn visual(out: &mut String, body: &BodyModel, looks: &[String]) {
    out.push_str("        def Xform \"visual\"\n        {\n");
    for (k, look) in looks.iter().enumerate() {
        let part = body.visual.material_mesh(k);
        let _ = write!(
            out,
            "{}            def Mesh \"{}\" (\n                prepend apiSchemas = \
             [\"MaterialBindingAPI\"]\n            )\n            {{\n",
            if k == 0 { "" } else { "\n" },
            visual_name(k)
        );
        mesh_body(out, "                ", &part.positions_m, &part.triangles);
        if !part.uvs.is_empty() {
            // USD's st has v pointing up the image, as OBJ's; glTF's points down.
            out.push_str("                texCoord2f[] primvars:st = [");
            for (i, [u, v]) in part.uvs.iter().enumerate() {
                let sep = if i == 0 { "" } else { ", " };
                let _ = write!(
                    out,
                    "{sep}({}, {})",
                    fixed(f64::from(*u)),
                    fixed(1.0 - f64::from(*v))
                );
            }
            out.push_str(
                "] (\n                    interpolation = \"vertex\"\n                )\n",
            );
        }
        let _ = writeln!(
            out,
            "                rel material:binding = <{look}>\n            }}"
        );
    }
    out.push_str("        }\n");
}

/// Whether a material is the grey one of meshes without a glTF material.
fn is_grey(m: &VisualMaterial) -> bool {
    let grey = VisualMaterial::grey(Vec::new());
    m.texture.is_none() && m.name == grey.name && m.rgba_linear == grey.rgba_linear
}

/// A `UsdPreviewSurface` material of a glTF base colour: `diffuseColor` (linear) and
/// `opacity` when translucent; for a texture, a `UsdUVTexture` (sRGB, repeating, scaled by the
/// colour factor) read at `st` feeds `diffuseColor`.
fn material_prim(out: &mut String, path: &str, name: &str, m: &VisualMaterial, file: Option<&str>) {
    let c = m.rgba_linear;
    let _ = write!(
        out,
        "\n        def Material \"{name}\"\n        {{\n            token \
         outputs:surface.connect = <{path}/Shader.outputs:surface>\n\n            def Shader \
         \"Shader\"\n            {{\n                uniform token info:id = \
         \"UsdPreviewSurface\"\n"
    );
    match file {
        Some(_) => {
            let _ = writeln!(
                out,
                "                color3f inputs:diffuseColor.connect = \
                 <{path}/Texture.outputs:rgb>"
            );
        }
        None => {
            let _ = writeln!(
                out,
                "                color3f inputs:diffuseColor = ({}, {}, {})",
                channel(c[0]),
                channel(c[1]),
                channel(c[2])
            );
        }
    }
    if c[3] < 1.0 {
        let _ = writeln!(
            out,
            "                float inputs:opacity = {}",
            channel(c[3])
        );
    }
    out.push_str(
        "                float inputs:roughness = 0.6\n                token \
         outputs:surface\n            }\n",
    );
    if let Some(file) = file {
        let scale = if c[..3] == [1.0; 3] {
            String::new()
        } else {
            format!(
                "                float4 inputs:scale = ({}, {}, {}, 1)\n",
                channel(c[0]),
                channel(c[1]),
                channel(c[2])
            )
        };
        let _ = write!(
            out,
            "\n            def Shader \"Texture\"\n            {{\n                uniform token \
             info:id = \"UsdUVTexture\"\n                asset inputs:file = @{file}@\n{scale}\
             \x20               token inputs:sourceColorSpace = \"sRGB\"\n                float2 \
             inputs:st.connect = <{path}/PrimvarReader.outputs:result>\n                token \
             inputs:wrapS = \"repeat\"\n                token inputs:wrapT = \"repeat\"\n\
             \x20               float3 outputs:rgb\n            }}\n\n            def Shader \
             \"PrimvarReader\"\n            {{\n                uniform token info:id = \
             \"UsdPrimvarReader_float2\"\n                string inputs:varname = \"st\"\n\
             \x20               float2 outputs:result\n            }}\n"
        );
    }
    out.push_str("        }\n");
}

/// `scene.usda` of a scene.
pub fn write_usda(scene_id: &str, table: &[TableBox], bodies: &[BodyModel]) -> String {
    let mut out = String::new();
    let _ = write!(
        out,
        "#usda 1.0\n(\n    defaultPrim = \"World\"\n    doc = \"mesa export of {scene_id}: \
         metres, z up, the table top at z = 0\"\n    metersPerUnit = 1\n    upAxis = \"Z\"\n)\n\n\
         def Xform \"World\"\n{{\n    def PhysicsScene \"PhysicsScene\"\n    {{\n        \
         vector3f physics:gravityDirection = (0, 0, -1)\n        float \
         physics:gravityMagnitude = 9.81\n    }}\n\n    def Scope \"Looks\"\n    {{\n        \
         def Material \"ObjectMaterial\"\n        {{\n            token outputs:surface.connect \
         = </World/Looks/ObjectMaterial/Shader.outputs:surface>\n\n            def Shader \
         \"Shader\"\n            {{\n                uniform token info:id = \
         \"UsdPreviewSurface\"\n                color3f inputs:diffuseColor = (0.8, 0.8, 0.8)\n\
         \x20               float inputs:roughness = 0.6\n                token \
         outputs:surface\n            }}\n        }}\n"
    );
    // One material per asset material (objects of one asset share them), by first use.
    let mut taken: BTreeSet<String> = ["ObjectMaterial".to_owned()].into();
    let mut asset_looks: BTreeMap<&str, Vec<String>> = BTreeMap::new();
    let mut body_looks = Vec::with_capacity(bodies.len());
    for body in bodies {
        let uid = body.record.uid.as_str();
        if !asset_looks.contains_key(uid) {
            let v = &body.visual;
            let mut paths = Vec::with_capacity(v.materials.len());
            for (k, m) in v.materials.iter().enumerate() {
                if is_grey(m) {
                    paths.push(DEFAULT_MATERIAL.to_owned());
                    continue;
                }
                let name = prim_name(&format!("{uid}_{}", visual_name(k)), &mut taken);
                let path = format!("/World/Looks/{name}");
                let file = m
                    .texture
                    .map(|t| format!("../textures/{}", texture_file(uid, v.textures[t].image)));
                material_prim(&mut out, &path, &name, m, file.as_deref());
                paths.push(path);
            }
            asset_looks.insert(uid, paths);
        }
        body_looks.push(asset_looks[uid].clone());
    }
    out.push_str("    }\n\n    def Xform \"table\"\n    {\n");
    for b in table {
        let size = b.half_size_m.map(|h| 2.0 * h);
        let _ = write!(
            out,
            "        def Cube \"{}\" (\n            prepend apiSchemas = \
             [\"PhysicsCollisionAPI\"]\n        )\n        {{\n            double size = 1\n\
             \x20           double3 xformOp:translate = {}\n            float3 xformOp:scale = \
             {}\n            uniform token[] xformOpOrder = [\"xformOp:translate\", \
             \"xformOp:scale\"]\n        }}\n",
            b.name,
            tuple3(b.center_m),
            tuple3(size)
        );
    }
    out.push_str("    }\n");
    let mut taken = BTreeSet::new();
    for (body, looks) in bodies.iter().zip(&body_looks) {
        let name = prim_name(&body.instance, &mut taken);
        let q = body.pose.rotation_xyzw;
        let m = &body.mass;
        let (diagonal, axes) = principal_inertia(m.inertia_kg_m2);
        let _ = write!(
            out,
            "\n    def Xform \"{name}\" (\n        prepend apiSchemas = \
             [\"PhysicsRigidBodyAPI\", \"PhysicsMassAPI\"]\n    )\n    {{\n        string \
             mesa:instance = \"{}\"\n        double3 xformOp:translate = {}\n        quatd \
             xformOp:orient = ({}, {}, {}, {})\n        uniform token[] xformOpOrder = \
             [\"xformOp:translate\", \"xformOp:orient\"]\n        float physics:mass = {}\n\
             \x20       point3f physics:centerOfMass = {}\n        float3 \
             physics:diagonalInertia = {}\n        quatf physics:principalAxes = ({}, {}, {}, \
             {})\n\n",
            body.instance,
            tuple3(body.pose.position_m),
            fixed(q[3]),
            fixed(q[0]),
            fixed(q[1]),
            fixed(q[2]),
            sci(m.mass_kg),
            tuple3(m.center_m),
            tuple3_sci(diagonal),
            fixed(axes[0]),
            fixed(axes[1]),
            fixed(axes[2]),
            fixed(axes[3])
        );
        visual(&mut out, body, looks);
        for (k, (points, triangles)) in body.parts.iter().enumerate() {
            let _ = write!(
                out,
                "\n        def Mesh \"part_{k:03}\" (\n            prepend apiSchemas = \
                 [\"PhysicsCollisionAPI\", \"PhysicsMeshCollisionAPI\"]\n        )\n        \
                 {{\n            uniform token physics:approximation = \"convexHull\"\n\
                 \x20           uniform token purpose = \"guide\"\n"
            );
            mesh_body(&mut out, "            ", points, triangles);
            out.push_str("        }\n");
        }
        out.push_str("    }\n");
    }
    out.push_str("}\n");
    out
}
