"""Imports GLB files with Blender's glTF importer and checks each against its annotation.

Usage (either):
    blender --background --factory-startup --python-exit-code 1 \
        --python scripts/check_glb_blender.py -- ANNOTATIONS.json FILE.glb...
    python scripts/check_glb_blender.py ANNOTATIONS.json FILE.glb...   (a Python with `bpy`)

For every file (named <uid>.glb): the import must give mesh objects, every embedded image must
decode, and the world bounds of all vertices must match the annotation's bbox within 2 mm.
Blender converts glTF's +Y up to its +Z up on import (Blender (x, y, z) = glTF (x, -z, y)), so
Blender's extents (x, y, z) are the glTF extents (x, z, y). Prints one JSON line per file and
exits 1 when any file fails.
"""
import json
import os
import pathlib
import sys

import bpy
from mathutils import Vector


def extents(entry):
    """The glTF (x, y, z) extents of an annotation in any bbox form MesaTask's reader accepts."""
    corner = lambda c: [c["x"], c["y"], c["z"]] if isinstance(c, dict) else list(c)
    bbox = entry.get("bbox")
    if bbox is None:
        lo, hi = corner(entry["min_point"]), corner(entry["max_point"])
        return [h - l for l, h in zip(lo, hi)]
    if "x" in bbox:
        return corner(bbox)
    if "size" in bbox:
        return corner(bbox["size"])
    lo, hi = corner(bbox["min"]), corner(bbox["max"])
    return [h - l for l, h in zip(lo, hi)]


def check(path, expected):
    bpy.ops.wm.read_factory_settings(use_empty=True)
    bpy.ops.import_scene.gltf(filepath=str(path))
    meshes = [o for o in bpy.context.scene.objects if o.type == "MESH"]
    problems = []
    if not meshes:
        problems.append("no mesh object")
    lo = Vector((float("inf"),) * 3)
    hi = Vector((float("-inf"),) * 3)
    vertices = 0
    for obj in meshes:
        for v in obj.data.vertices:
            w = obj.matrix_world @ v.co
            lo = Vector(map(min, lo, w))
            hi = Vector(map(max, hi, w))
            vertices += 1
    images = [img for img in bpy.data.images if img.source == "FILE" or img.packed_file]
    broken = [img.name for img in images if not img.has_data and img.size[0] == 0]
    if broken:
        problems.append(f"images that do not decode: {broken}")
    size_blender = hi - lo if meshes else Vector((0, 0, 0))
    size_gltf = [size_blender.x, size_blender.z, size_blender.y]
    if meshes and any(abs(a - b) > 2e-3 for a, b in zip(size_gltf, expected)):
        problems.append("bounds differ from the annotation's bbox")
    return {
        "file": str(path),
        "objects": len(meshes),
        "vertices": vertices,
        "images": len(images),
        "extents_m": [round(v, 5) for v in size_gltf],
        "expected_m": [round(v, 5) for v in expected],
        "ok": not problems,
        **({"problems": problems} if problems else {}),
    }


def main(argv):
    if len(argv) < 2:
        print(__doc__, file=sys.stderr)
        return 2
    annotations = json.loads(pathlib.Path(argv[0]).read_text())
    failed = False
    for name in argv[1:]:
        path = pathlib.Path(name)
        try:
            line = check(path, extents(annotations[path.stem]))
        except Exception as e:  # report every file, not only the first failure
            line = {"file": str(path), "ok": False, "problems": [f"{type(e).__name__}: {e}"]}
        failed |= not line["ok"]
        print(json.dumps(line), flush=True)
    return 1 if failed else 0


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
        # Blender keeps running after a script returns; an exception makes
        # --python-exit-code take effect.
        raise SystemExit(code)
