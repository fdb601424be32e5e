"""Drives Blender (4.3, as a Python module or an executable) on mesa annotator packs.

Usage (a Python with `bpy`, or `blender --background --factory-startup --python-exit-code 1
--python scripts/blender_pack.py -- ...`):

    blender_pack.py inspect PACK.glb
        Imports the pack as an annotator does (File > Import > glTF 2.0, default options) and
        prints one JSON line per object: name, type, rotation mode, location, rotation
        (quaternion w, x, y, z), scale, dimensions (all in Blender's world, metres), and its
        custom properties.

    blender_pack.py edit PACK.glb EDITS.json OUT.glb [--extras]
        Imports the pack, makes the edits a person makes in Object Mode, prints the objects as
        `inspect` does (after the edits), and exports the scene with Blender's default glTF
        options (glTF Binary; with --extras, "Custom Properties" ticked).

EDITS.json is a list of operations applied in order:
    {"op": "move", "name": N, "by": [dx, dy, dz]}            G: location += by
    {"op": "rotate_z", "name": N, "deg": A}                  R Z A: a turn about world +Z
    {"op": "rotate", "name": N, "axis": [x, y, z], "deg": A} a turn about a world axis
    {"op": "scale", "name": N, "by": [sx, sy, sz]}           S (S X, S Y, S Z): local scale *= by
    {"op": "set", "name": N, "location": [..], "rotation_wxyz": [..], "scale": [..]}
    {"op": "delete", "name": N}                              X
    {"op": "duplicate", "name": N, "as": NEW}                Shift+D (Blender names the copy
                                                             N.001; the script checks it is NEW)
    {"op": "add_box", "name": N, "location": [..], "size": [..]}
                                                             Add > Mesh > Cube, sized, renamed
Blender's world is the table frame (x right, y away from the observer, z up), because its glTF
importer turns glTF's +Y up into its +Z up.
"""
import json
import os
import sys

import bpy
from mathutils import Quaternion, Vector


def describe(obj):
    return {
        "name": obj.name,
        "type": obj.type,
        "rotation_mode": obj.rotation_mode,
        "location": list(obj.location),
        "rotation_wxyz": list(obj.rotation_quaternion),
        "scale": list(obj.scale),
        "dimensions": list(obj.dimensions),
        "mesh": obj.data.name if obj.type == "MESH" else None,
        "parent": obj.parent.name if obj.parent else None,
        "properties": sorted(k for k in obj.keys() if not k.startswith("_")),
    }


def import_pack(path):
    bpy.ops.wm.read_factory_settings(use_empty=True)
    bpy.ops.import_scene.gltf(filepath=path)


def select_only(obj):
    bpy.ops.object.select_all(action="DESELECT")
    obj.select_set(True)
    bpy.context.view_layer.objects.active = obj


def apply(op):
    kind = op["op"]
    if kind == "add_box":
        bpy.ops.mesh.primitive_cube_add(size=1.0, location=op["location"])
        obj = bpy.context.active_object
        obj.scale = op["size"]
        # Sized in Edit Mode: the size is in the mesh, the object's scale stays 1.
        bpy.ops.object.transform_apply(location=False, rotation=False, scale=True)
        obj.name = op["name"]
        return
    obj = bpy.data.objects[op["name"]]
    obj.rotation_mode = "QUATERNION"
    if kind == "move":
        obj.location = obj.location + Vector(op["by"])
    elif kind == "rotate_z":
        turn = Quaternion((0.0, 0.0, 1.0), op["deg"] * 3.141592653589793 / 180.0)
        obj.rotation_quaternion = turn @ obj.rotation_quaternion
    elif kind == "rotate":
        turn = Quaternion(Vector(op["axis"]).normalized(), op["deg"] * 3.141592653589793 / 180.0)
        obj.rotation_quaternion = turn @ obj.rotation_quaternion
    elif kind == "scale":
        obj.scale = [s * b for s, b in zip(obj.scale, op["by"])]
    elif kind == "set":
        obj.location = op["location"]
        obj.rotation_quaternion = Quaternion(op["rotation_wxyz"])
        obj.scale = op["scale"]
    elif kind == "delete":
        bpy.data.objects.remove(obj, do_unlink=True)
    elif kind == "duplicate":
        select_only(obj)
        bpy.ops.object.duplicate(linked=False)
        copy = bpy.context.active_object
        if copy.name != op["as"]:
            raise SystemExit(f"Blender named the copy of {op['name']} {copy.name}, not {op['as']}")
    else:
        raise SystemExit(f"unknown operation {kind}")


def main(argv):
    if len(argv) >= 2 and argv[0] == "inspect":
        import_pack(argv[1])
    elif len(argv) >= 4 and argv[0] == "edit":
        import_pack(argv[1])
        with open(argv[2]) as f:
            for op in json.load(f):
                apply(op)
        bpy.context.view_layer.update()
    else:
        print(__doc__, file=sys.stderr)
        return 2
    for obj in sorted(bpy.context.scene.objects, key=lambda o: o.name):
        print(json.dumps(describe(obj)), flush=True)
    if argv[0] == "edit":
        bpy.ops.export_scene.gltf(
            filepath=argv[3], export_format="GLB", export_extras="--extras" in argv
        )
    return 0


if __name__ == "__main__":
    inside_blender = "--" in sys.argv
    args = sys.argv[sys.argv.index("--") + 1:] if inside_blender else sys.argv[1:]
    code = main(args)
    if not inside_blender:
        # The bpy module (4.x) can crash while the interpreter tears it down after
        # read_factory_settings; every result is printed by now, so leave without teardown.
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(code)
    if code:
        raise SystemExit(code)
