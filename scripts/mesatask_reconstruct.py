"""Places a MesaTask-10K release the way MesaTask's own reconstruction does, in Blender 4.3,
and measures how far each object lands from where its layout says.

Usage (a Python with `bpy`):

    mesatask_reconstruct.py RELEASE_DIR [--scenes GLOB]

For every `RELEASE_DIR/Layout_info/<table_type>/<scene_id>/layout.json`, in an empty scene,
as `dataset/reconstruct_blender.py` of InternRobotics/MesaTask does it (re-implemented here
from its documented steps, not copied):
  - the table: `Assets_library/3cc47c3f78d34985bf4314de2f8196dd.glb` imported, its meshes'
    transforms applied and joined, scaled to the placement zone, 0.01 units thick, top at z = 0;
    the sink (`sink_cube.glb`) likewise over `restricted_zone`, 0.005 thick;
  - each object with a `retrieved_uid` and a three-number `scale_factor`: `<uid>.glb` imported
    (glTF importer defaults), the transforms of the imported *mesh* objects applied (an empty
    parent keeps its own), the origin moved to the centre of their joint bounding box, the
    meshes joined, the joined object's scale set to `size` over its local vertex extents, its
    rotation to the `rotation` quaternion (x, y, z, w) and its location to `position`.
Units are the layout's (centimetres), used as Blender units, as MesaTask does.

Then, per object, its evaluated world vertices taken back into the layout's object frame
(minus `position`, turned by the inverse of `rotation`) must fill the box of half-extents
`size / 2`: the error is the largest distance of a face of their bounding box from the face the
layout gives. For the table, its world bounding box against the zone. Prints one JSON line per
object: {"scene", "instance", "uid", "error_cm"} (`error_cm` null with `problem` when the
object could not be placed), then a summary line {"objects", "placed", "max_error_cm"}.
"""
import fnmatch
import json
import math
import os
import sys

import bpy
from mathutils import Quaternion, Vector

TABLE_UID = "3cc47c3f78d34985bf4314de2f8196dd"
SINK_UID = "sink_cube"


def empty_scene():
    bpy.ops.wm.read_factory_settings(use_empty=True)


def import_meshes(path):
    before = set(bpy.context.scene.objects)
    bpy.ops.import_scene.gltf(filepath=path)
    new = [o for o in bpy.context.scene.objects if o not in before]
    return [o for o in new if o.type == "MESH"]


def select(objects):
    bpy.ops.object.select_all(action="DESELECT")
    for o in objects:
        o.select_set(True)
    bpy.context.view_layer.objects.active = objects[0]


def world_bounds(objects):
    lo = Vector((math.inf,) * 3)
    hi = Vector((-math.inf,) * 3)
    for o in objects:
        for corner in o.bound_box:
            w = o.matrix_world @ Vector(corner)
            for a in range(3):
                lo[a] = min(lo[a], w[a])
                hi[a] = max(hi[a], w[a])
    return lo, hi


def local_extents(obj):
    co = [v.co for v in obj.data.vertices]
    return Vector(
        tuple(max(c[a] for c in co) - min(c[a] for c in co) for a in range(3))
    )


def place_zone(path, zone, thickness):
    """The table or sink step; returns the error of its world box against the zone."""
    meshes = import_meshes(path)
    if not meshes:
        return None, f"{os.path.basename(path)}: no mesh"
    select(meshes)
    bpy.ops.object.transform_apply(location=True, rotation=True, scale=True)
    if len(meshes) > 1:
        bpy.ops.object.join()
    obj = bpy.context.view_layer.objects.active
    bpy.ops.object.origin_set(type="ORIGIN_GEOMETRY", center="BOUNDS")
    obj.location = (0, 0, 0)
    obj.rotation_euler = (0, 0, 0)
    obj.scale = (1, 1, 1)
    dims = local_extents(obj)
    x0, x1, y0, y1 = zone
    target = (x1 - x0, y1 - y0, thickness)
    obj.scale = tuple(target[a] / dims[a] for a in range(3))
    obj.location = ((x0 + x1) / 2, (y0 + y1) / 2, -thickness / 2)
    bpy.context.view_layer.update()
    lo, hi = world_bounds([obj])
    expected_lo = (x0, y0, -thickness)
    expected_hi = (x1, y1, 0.0)
    error = max(
        max(abs(lo[a] - expected_lo[a]), abs(hi[a] - expected_hi[a])) for a in range(3)
    )
    return error, None


def place_object(path, position, rotation_xyzw, size):
    meshes = import_meshes(path)
    if not meshes:
        return None, "no mesh in the GLB"
    select(meshes)
    bpy.ops.object.transform_apply(location=True, rotation=True, scale=True)
    lo, hi = world_bounds(meshes)
    bpy.context.scene.cursor.location = (lo + hi) / 2
    bpy.ops.object.origin_set(type="ORIGIN_CURSOR", center="MEDIAN")
    bpy.context.scene.cursor.location = (0, 0, 0)
    bpy.ops.object.join()
    obj = bpy.context.view_layer.objects.active
    dims = local_extents(obj)
    if any(d < 1e-6 for d in dims):
        scale = Vector((1, 1, 1))
    else:
        scale = Vector(tuple(size[a] / dims[a] for a in range(3)))
    obj.scale = scale
    x, y, z, w = rotation_xyzw
    q = Quaternion((w, x, y, z))
    if q.magnitude > 1e-6:
        q.normalize()
    obj.rotation_mode = "QUATERNION"
    obj.rotation_quaternion = q
    obj.location = Vector(position)
    bpy.context.view_layer.update()
    # Back into the layout's object frame.
    inverse = q.inverted()
    lo = [math.inf] * 3
    hi = [-math.inf] * 3
    for v in obj.data.vertices:
        p = inverse @ (obj.matrix_world @ v.co - Vector(position))
        for a in range(3):
            lo[a] = min(lo[a], p[a])
            hi[a] = max(hi[a], p[a])
    error = max(max(abs(lo[a] + size[a] / 2), abs(hi[a] - size[a] / 2)) for a in range(3))
    return error, None


def main(argv):
    release = argv[0]
    pattern = None
    if len(argv) >= 3 and argv[1] == "--scenes":
        pattern = argv[2]
    library = os.path.join(release, "Assets_library")
    layouts = []
    root = os.path.join(release, "Layout_info")
    for table_type in sorted(os.listdir(root)):
        for scene_id in sorted(os.listdir(os.path.join(root, table_type))):
            key = f"{table_type}/{scene_id}"
            if pattern and not (fnmatch.fnmatch(key, pattern) or fnmatch.fnmatch(scene_id, pattern)):
                continue
            layouts.append((key, os.path.join(root, table_type, scene_id, "layout.json")))
    objects = placed = 0
    worst = 0.0
    for key, path in layouts:
        with open(path) as f:
            layout = json.load(f)
        empty_scene()
        zones = [("table", TABLE_UID, layout.get("item_placement_zone"), 0.01)]
        if layout.get("restricted_zone"):
            zones.append(("sink", SINK_UID, layout["restricted_zone"], 0.005))
        for name, uid, zone, thickness in zones:
            glb = os.path.join(library, f"{uid}.glb")
            record = {"scene": key, "instance": name, "uid": uid}
            objects += 1
            if not os.path.exists(glb):
                record.update(error_cm=None, problem=f"Assets_library/{uid}.glb is missing")
            else:
                error, problem = place_zone(glb, zone, thickness)
                record.update(error_cm=error, problem=problem)
                if error is not None:
                    placed += 1
                    worst = max(worst, error)
            print(json.dumps(record), flush=True)
        for o in layout.get("objects", []):
            uid = o.get("retrieved_uid")
            scale_factor = o.get("scale_factor")
            if not uid or not isinstance(scale_factor, list) or len(scale_factor) != 3:
                continue  # MesaTask's reader skips these
            objects += 1
            record = {"scene": key, "instance": o.get("instance"), "uid": uid}
            glb = os.path.join(library, f"{uid}.glb")
            if not os.path.exists(glb):
                record.update(error_cm=None, problem="no GLB in Assets_library")
            else:
                rotation = o.get("rotation") or [0.0, 0.0, 0.0, 1.0]
                error, problem = place_object(glb, o["position"], rotation, o["size"])
                record.update(error_cm=error, problem=problem)
                if error is not None:
                    placed += 1
                    worst = max(worst, error)
            print(json.dumps(record), flush=True)
    print(json.dumps({"objects": objects, "placed": placed, "max_error_cm": worst}), flush=True)


if __name__ == "__main__":
    argv = sys.argv[1:]
    if "--" in argv:
        argv = argv[argv.index("--") + 1 :]
    main(argv)
