#!/usr/bin/env python3
"""Times the official way of building a scene GLB against `mesa pack`, on the same scene.

The official approach is MesaTask's `dataset/reconstruct_blender.py`: in Blender, for every
object of a layout, import the asset's GLB, apply its transforms, put the origin at the centre
of the bounding box, join its meshes, scale it per axis to the layout size, set the layout
rotation and position, name it; add the table; export the scene as GLB. This script does those
steps with bpy (Blender 4.3, the version MesaTask pins) for the bench scene of
`stages/benches/pack.rs`: the demo's office_table_0003 (seed 7), its true layout cut to its
first 15 objects. Draco compression, which MesaTask turns on, is off: the bpy wheel has no
Draco library (and mesa packs without Draco too).

mesa is timed the same way, by `stages/examples/pack_timing.rs --serve` (`pack_scene` on the
same scene, the assets' GLBs in memory, snapshots and README included, on one thread): one
warm-up run each, then `--repeat` turns, each running Blender's reconstruction untimed for 0.3 s
at least (one run) and then once timed, then the same of mesa's (bench/timing.py's
`alternated`), so both sides see the same moments of the machine. Both sides print their min
and median, and the ratio of each, with the load average and the CPU.

Needs a Python with bpy 4.3 and numpy<2: the one scripts/test.sh installs into .venv-blender
(`python3 -m venv .venv-blender && .venv-blender/bin/pip install "bpy==4.3.0" "numpy<2"`):
    .venv-blender/bin/python bench/compare_blender_pack.py [--repeat 5] [--target DIR]
(`--target` is the cargo target directory, default target/ or $CARGO_TARGET_DIR; the script
builds mesa and the example in release mode.)
"""
import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

import bpy
from mathutils import Quaternion, Vector

sys.dont_write_bytecode = True  # no __pycache__ left in bench/
sys.path.insert(0, str(Path(__file__).resolve().parent))
from timing import Served, alternated  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
SCENE = "scenes/office_table/office_table_0003"


def clear():
    bpy.ops.wm.read_factory_settings(use_empty=True)


def local_size(obj):
    lo = Vector((float("inf"),) * 3)
    hi = Vector((float("-inf"),) * 3)
    for v in obj.data.vertices:
        lo = Vector(map(min, lo, v.co))
        hi = Vector(map(max, hi, v.co))
    return hi - lo


def place(obj_data, library):
    """One object as the official reconstruction places it."""
    before = set(bpy.context.scene.objects)
    bpy.ops.import_scene.gltf(filepath=str(library / f"{obj_data['retrieved_uid']}.glb"))
    meshes = [o for o in set(bpy.context.scene.objects) - before if o.type == "MESH"]
    bpy.ops.object.select_all(action="DESELECT")
    for o in meshes:
        o.select_set(True)
    bpy.context.view_layer.objects.active = meshes[0]
    bpy.ops.object.transform_apply(location=True, rotation=True, scale=True)
    lo = Vector((float("inf"),) * 3)
    hi = Vector((float("-inf"),) * 3)
    for o in meshes:
        for corner in o.bound_box:
            w = o.matrix_world @ Vector(corner)
            lo = Vector(map(min, lo, w))
            hi = Vector(map(max, hi, w))
    bpy.context.scene.cursor.location = (lo + hi) / 2
    bpy.ops.object.origin_set(type="ORIGIN_CURSOR", center="MEDIAN")
    bpy.context.scene.cursor.location = (0, 0, 0)
    if len(meshes) > 1:
        bpy.ops.object.join()
    obj = bpy.context.object
    size = local_size(obj)
    target = [v / 100.0 for v in obj_data["size"]]
    obj.scale = [t / s if s > 1e-6 else 1.0 for t, s in zip(target, size)]
    x, y, z, w = obj_data["rotation"]
    obj.rotation_mode = "QUATERNION"
    obj.rotation_quaternion = Quaternion((w, x, y, z))
    obj.location = [v / 100.0 for v in obj_data["position"]]
    obj.name = obj_data["instance"]


def reconstruct(layout, library, out):
    clear()
    x0, x1, y0, y1 = [v / 100.0 for v in layout["item_placement_zone"]]
    bpy.ops.mesh.primitive_cube_add(size=1.0, location=((x0 + x1) / 2, (y0 + y1) / 2, -0.005))
    table = bpy.context.active_object
    table.scale = (x1 - x0, y1 - y0, 0.01)
    table.name = "table"
    for obj_data in layout["objects"]:
        place(obj_data, library)
    bpy.ops.export_scene.gltf(filepath=str(out), export_format="GLB", export_apply=True,
                              export_lights=False, export_cameras=False, export_extras=False)


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--repeat", type=int, default=5)
    parser.add_argument("--target", default=os.environ.get("CARGO_TARGET_DIR", str(ROOT / "target")))
    args = parser.parse_args()
    target = Path(args.target)
    mesa = target / "release/mesa"
    env = dict(os.environ, CARGO_TARGET_DIR=str(target))
    subprocess.run(["cargo", "build", "--release", "-q"], cwd=ROOT, check=True, env=env)
    subprocess.run(["cargo", "build", "--release", "-q", "-p", "mesa-stages", "--example",
                    "pack_timing"], cwd=ROOT, check=True, env=env)
    load_before = os.getloadavg()[0]
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        subprocess.run([str(mesa), "demo", str(work / "demo"), "--scenes", "20", "--seed", "7", "-q"],
                       check=True)
        layout = json.loads((work / "demo" / SCENE / "truth/layout.json").read_text())
        layout["objects"] = layout["objects"][:15]
        library = work / "demo/assets/library"
        assets = len({o["retrieved_uid"] for o in layout["objects"]})
        # A warm-up run, as on mesa's side (the example warms up before it serves).
        reconstruct(layout, library, work / "scene.glb")
        served = Served([target / "release/examples/pack_timing", "--serve"], "runs_s")
        times, mesa_times = alternated(lambda: reconstruct(layout, library, work / "scene.glb"),
                                       served, args.repeat)
        served.finish()
        size = (work / "scene.glb").stat().st_size
    load_after = os.getloadavg()[0]
    cpu = next((line.split(":", 1)[1].strip() for line in open("/proc/cpuinfo")
                if line.startswith("model name")), "unknown CPU")
    print(f"{cpu}, {os.cpu_count()} CPUs, load average {load_before:.2f} before, "
          f"{load_after:.2f} after; {args.repeat} timed runs a side in turns, each after 0.3 s of "
          f"untimed ones")
    print(f"Blender (bpy {bpy.app.version_string}), MesaTask's reconstruction, 15 objects "
          f"({assets} assets), GLB {size / 1e6:.2f} MB: min {min(times) * 1000:.1f} ms, "
          f"median {statistics.median(times) * 1000:.1f} ms")
    print(f"mesa pack_scene, 15 objects, snapshots and README included: "
          f"min {min(mesa_times) * 1000:.2f} ms, median {statistics.median(mesa_times) * 1000:.2f} ms")
    print(f"ratio (Blender / mesa): {min(times) / min(mesa_times):.0f}x on the minima, "
          f"{statistics.median(times) / statistics.median(mesa_times):.0f}x on the medians")
    sys.stdout.flush()
    os._exit(0)


if __name__ == "__main__":
    main()
