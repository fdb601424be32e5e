#!/usr/bin/env python3
"""Loads GLB files with trimesh and checks each against its annotation.

Usage: check_glb_trimesh.py ANNOTATIONS.json FILE.glb...

For every file (named <uid>.glb): trimesh must load it as a scene with triangles, and the
scene's bounds (node transforms applied, glTF frame) must match the annotation's bbox extents
within 2 mm. Prints one JSON line per file and exits 1 when any file fails (2 on bad usage).
"""
import json
import pathlib
import sys

import numpy as np
import trimesh


def extents(entry):
    """The (x, y, z) extents of an annotation in any bbox form MesaTask's reader accepts."""
    corner = lambda c: np.array([c["x"], c["y"], c["z"]] if isinstance(c, dict) else c, float)
    bbox = entry.get("bbox")
    if bbox is None:
        return corner(entry["max_point"]) - corner(entry["min_point"])
    if "x" in bbox:
        return corner(bbox)
    if "size" in bbox:
        return corner(bbox["size"])
    return corner(bbox["max"]) - corner(bbox["min"])


def main(argv):
    if len(argv) < 2:
        print(__doc__, file=sys.stderr)
        return 2
    annotations = json.loads(pathlib.Path(argv[0]).read_text())
    failed = False
    for name in argv[1:]:
        path = pathlib.Path(name)
        line = {"file": str(path)}
        try:
            scene = trimesh.load(str(path), force="scene")
            triangles = sum(len(g.faces) for g in scene.geometry.values())
            ext = scene.bounds[1] - scene.bounds[0]
            expected = extents(annotations[path.stem])
            line.update(
                geometries=len(scene.geometry),
                triangles=int(triangles),
                extents_m=[round(float(v), 5) for v in ext],
                expected_m=[round(float(v), 5) for v in expected],
            )
            problems = []
            if triangles == 0:
                problems.append("no triangles")
            if not np.allclose(ext, expected, atol=2e-3):
                problems.append("bounds differ from the annotation's bbox")
            line["ok"] = not problems
            if problems:
                line["problems"] = problems
        except Exception as e:  # report every file, not only the first failure
            line.update(ok=False, problems=[f"{type(e).__name__}: {e}"])
        failed |= not line["ok"]
        print(json.dumps(line), flush=True)
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
