//! `README.txt` of an annotator pack: written for a person who knows Blender but not mesa.

use std::fmt::Write as _;

/// What the README says about one scene.
pub struct ReadmeFacts<'a> {
    /// The scene id.
    pub scene_id: &'a str,
    /// The GLB file name.
    pub glb: &'a str,
    /// Whether `reference.png` is in the pack.
    pub reference: bool,
    /// `(instance, category, description, has_snapshot)` per object.
    pub objects: &'a [(String, String, Option<String>, bool)],
    /// The table top, cm: width (x) and depth (y).
    pub table_cm: [f64; 2],
    /// Whether the scene has a restricted zone (a sink).
    pub restricted_zone: bool,
}

/// The README text.
pub fn readme_text(facts: &ReadmeFacts<'_>) -> String {
    let mut t = String::new();
    let scene = facts.scene_id;
    let glb = facts.glb;
    let _ = writeln!(t, "Annotation pack for scene {scene}");
    let _ = writeln!(t, "{}", "=".repeat(26 + scene.len()));
    let _ = writeln!(
        t,
        "
This folder holds a 3D tabletop scene that a program built from one photo. Positions,
sizes and turns are only estimates: your job is to make the 3D scene match the photo.
It takes 10 to 20 minutes. Send back one file: the edited scene as {glb}
(same file name), exported from Blender as described at the end.

What is in this folder
----------------------
  {glb}    the scene (glTF Binary): the table top, the objects, and a 1.70 m
                       tall robot figure (H1_reference) for scale"
    );
    if facts.reference {
        let _ = writeln!(
            t,
            "  reference.png        the photo the scene should look like"
        );
    }
    let _ = writeln!(
        t,
        "  snapshots/           one crop of the photo per object, named after the object
  index.json           the same list of objects, for the program
  README.txt           this file

The objects ({n})
-----------",
        n = facts.objects.len()
    );
    for (instance, category, description, snapshot) in facts.objects {
        let mut line = format!("  {instance:<24} {category}");
        if let Some(d) = description {
            line.push_str(&format!(": {d}"));
        }
        if !snapshot {
            line.push_str(" (no snapshot)");
        }
        let _ = writeln!(t, "{line}");
    }
    let _ = writeln!(
        t,
        "
How to open it
--------------
Blender 3.6 or later (4.3 is what we test with): File > New > General, delete the default
cube, camera and light (select all with A, then X), then File > Import > glTF 2.0
(.glb/.gltf) and choose {glb}. Keep the import options as they are.

What you see
------------
- Blender's axes are the table's: X runs left to right along the front edge, Y runs away from
  you (the photographer stood at -Y looking toward +Y), Z is up. The front view (numpad 1)
  looks along +Y, as the camera of the photo did. The table top is the box named \"table\"; its
  upper face is at Z = 0 and its front-left corner is at X = 0, Y = 0. It is {w:.1} cm wide
  (X) and {d:.1} cm deep (Y).",
        w = facts.table_cm[0],
        d = facts.table_cm[1]
    );
    if facts.restricted_zone {
        let _ = writeln!(
            t,
            "- The red translucent patch named \"restricted_zone\" is the sink: nothing may stand
  in it."
        );
    }
    let _ = writeln!(
        t,
        "- Each object is one Blender object named exactly after it (like mug_0), with its origin
  at the centre of its bounding box. Units are metres.
- H1_reference is a 1.70 m tall robot standing on the floor beside the front-left corner of
  the table: use it to judge whether the objects have a sensible real-world size.

What to fix
-----------
Compare with reference.png and the snapshots, then, object by object (Object Mode):
- Move (G) objects to where they are in the photo. Objects stand on the table or on what is
  under them: no object should float or sink into another.
- Turn (R Z) objects about the vertical axis so that they face the way they do in the photo.
  A tilted object (a pen leaning in a cup) may be turned about other axes too.
- Scale (S) objects whose size is wrong. Scaling along one axis (S X, S Y, S Z) is fine when
  the shape's proportions are wrong, e.g. a book that should be thinner.
- Delete (X) objects that are there twice (the same thing detected twice in the photo) and
  objects that are not in the photo at all.
- If an object of the photo is missing but another object of the same kind is in the scene,
  duplicate that one (Shift+D) and move the copy into place. Blender names the copy like
  mug_0.001; keep that name, the program gives it a proper one.
- If the table top is too small or too large for the objects, you may move or scale the
  \"table\" object; positions are read relative to the table.
- If the photo shows a sink (or another area where nothing may stand) and the scene has no
  \"restricted_zone\" object, add one: Add > Mesh > Cube, scale it flat over that area, and
  name it restricted_zone. If it has one, move and scale it to fit.

What not to do
--------------
- Do not rename objects, and do not join or separate them.
- Do not apply transforms (Ctrl+A) and do not edit meshes (Tab / Edit Mode): the program reads
  each object's location, rotation and scale, and its mesh must stay as it is.
- Do not parent objects to one another, and do not add other objects (no new meshes but the
  restricted_zone box, no imported models, no empties, cameras or lights).
- Leave H1_reference exactly as it is (do not move, scale or delete it). If you scale the
  whole scene, scale the figure with it: the program measures the figure to undo that.
- Do not delete the \"table\".

How to send it back
-------------------
File > Export > glTF 2.0 (.glb/.gltf), with:
- Format: glTF Binary (.glb)
- Include > Limit to: nothing ticked (export the whole scene)
- Include > Data > Custom Properties: ticked (if you forget it, it still works)
- Transform > +Y Up: ticked (the default)
- Data > Mesh > Apply Modifiers: may stay as it is; Compression (Draco): either way
Save it as {glb} and send that one file back.
"
    );
    t
}
