//! The USD writer: `scene.usda` as text. `upAxis = "Z"`, `metersPerUnit = 1`, a
//! `PhysicsScene`; each object an `Xform` with `PhysicsRigidBodyAPI` and `PhysicsMassAPI`
//! (mass, centre of mass, diagonal inertia and its principal axes), its visual mesh bound to a
//! material, and its convex parts as `Mesh` prims with `PhysicsCollisionAPI` and
//! `PhysicsMeshCollisionAPI` (approximation `convexHull`, purpose `guide`); the table static
//! `Cube` colliders (collision without a rigid body).

use std::collections::BTreeSet;
use std::fmt::Write as _;

use nalgebra::{Matrix3, Rotation3, SymmetricEigen, UnitQuaternion};

use super::obj::{fixed, sci};
use super::{BodyModel, TableBox, VisualMesh};

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

fn visual(out: &mut String, mesh: &VisualMesh) {
    out.push_str(
        "        def Mesh \"visual\" (\n            prepend apiSchemas = \
         [\"MaterialBindingAPI\"]\n        )\n        {\n",
    );
    mesh_body(out, "            ", &mesh.positions_m, &mesh.triangles);
    out.push_str("            rel material:binding = </World/Looks/ObjectMaterial>\n        }\n");
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
         outputs:surface\n            }}\n        }}\n    }}\n\n    def Xform \"table\"\n    \
         {{\n"
    );
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
    for body in bodies {
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
        visual(&mut out, &body.visual);
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
