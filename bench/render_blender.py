"""Renders the view `mesa render` drew, with Blender, and times it.

Run by bench/compare_blender.sh with Blender as a Python module (bpy 4.3, the virtualenv
scripts/test.sh makes: .venv-blender, `pip install "bpy==4.3.0" "numpy<2"`):

    python bench/render_blender.py SCENE_DIR LIBRARY_DIR LAYOUT OUT.png [--engine WORKBENCH] [--repeat 5]

The scene is built as MesaTask's reader builds it (dataset/reconstruct_blender.py): each asset
imported from its GLB (Blender's glTF importer shows the table frame itself), its meshes joined
with their origin at their bounding-box centre, scaled per axis to the layout's `size`, turned
by `rotation` (x, y, z, w), moved to `position`; in metres, as mesa renders. The table is a
slab over the placement zone; the camera is `render/front_camera.json` (OpenCV, table frame)
turned into Blender's (looking along -z, y up); one sun light where mesa's main light is, a
grey world for ambient light. Timing: the first render (shaders compiled) and the median of
`--repeat` more, each `bpy.ops.render.render` alone (import and scene set-up not counted), wall
and CPU time (all threads of the process). Prints one JSON line.

With `--alternate COMMAND`, COMMAND (mesa's stages/examples/render_timing.rs with `--serve`,
as bench/compare_blender.sh gives it) is started beside Blender, and the two take turns: each
turn runs each side untimed for 0.3 s at least (one render of Blender's, some thirty of
mesa's) and then once timed (bench/timing.py's `alternated`), so both sides see the same
moments of the machine. The JSON line
then also holds mesa's timed runs (`alternate_runs_s`) and the seconds of each of Blender's
timed renders are those of the turns.
"""
import argparse
import json
import math
import shlex
import statistics
import sys
import time
from pathlib import Path

import bpy
from mathutils import Matrix, Quaternion, Vector


def parse():
    argv = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else sys.argv[1:]
    p = argparse.ArgumentParser()
    p.add_argument("scene", type=Path)
    p.add_argument("library", type=Path)
    p.add_argument("layout")
    p.add_argument("out", type=Path)
    p.add_argument("--engine", default="WORKBENCH", choices=["WORKBENCH", "EEVEE", "CYCLES"])
    p.add_argument("--repeat", type=int, default=5)
    p.add_argument("--alternate", metavar="COMMAND",
                   help="a timing example run with --serve, to take turns with (see above)")
    return p.parse_args(argv)


def clear():
    bpy.ops.wm.read_factory_settings(use_empty=True)


def place(obj_data, library):
    before = set(bpy.context.scene.objects)
    bpy.ops.import_scene.gltf(filepath=str(library / f"{obj_data['retrieved_uid']}.glb"))
    meshes = [o for o in set(bpy.context.scene.objects) - before if o.type == "MESH"]
    bpy.ops.object.select_all(action="DESELECT")
    for o in meshes:
        o.select_set(True)
    bpy.context.view_layer.objects.active = meshes[0]
    bpy.ops.object.transform_apply(location=True, rotation=True, scale=True)
    lo = Vector((math.inf,) * 3)
    hi = Vector((-math.inf,) * 3)
    for o in meshes:
        for v in o.data.vertices:
            p = o.matrix_world @ v.co
            lo = Vector(map(min, lo, p))
            hi = Vector(map(max, hi, p))
    centre = (lo + hi) / 2
    if len(meshes) > 1:
        bpy.ops.object.join()
    obj = bpy.context.view_layer.objects.active
    obj.data.transform(Matrix.Translation(-centre))
    obj.matrix_world = Matrix.Identity(4)
    extent = hi - lo
    size = [s / 100.0 for s in obj_data["size"]]
    obj.scale = [size[k] / extent[k] if extent[k] > 1e-9 else 1.0 for k in range(3)]
    x, y, z, w = obj_data["rotation"]
    obj.rotation_mode = "QUATERNION"
    obj.rotation_quaternion = Quaternion((w, x, y, z))
    obj.location = [p / 100.0 for p in obj_data["position"]]


def table(zone):
    x0, x1, y0, y1 = [v / 100.0 for v in zone]
    bpy.ops.mesh.primitive_cube_add(size=1.0, location=((x0 + x1) / 2, (y0 + y1) / 2, -0.015))
    slab = bpy.context.active_object
    slab.scale = (x1 - x0, y1 - y0, 0.03)
    material = bpy.data.materials.new("table")
    material.diffuse_color = (0.45, 0.25, 0.12, 1.0)
    slab.data.materials.append(material)


def camera(cam):
    data = bpy.data.cameras.new("mesa")
    data.sensor_fit = "HORIZONTAL"
    data.sensor_width = 36.0
    data.lens = cam["fx"] * 36.0 / cam["width"]
    # mesa samples pixel u at u: its principal point (W - 1) / 2 is half a pixel left of
    # Blender's image centre W / 2.
    data.shift_x = (cam["cx"] - cam["width"] / 2.0 + 0.5) / cam["width"]
    data.shift_y = -(cam["cy"] - cam["height"] / 2.0 + 0.5) / cam["width"]
    obj = bpy.data.objects.new("mesa", data)
    bpy.context.scene.collection.objects.link(obj)
    m = Matrix(cam["table_from_camera"])
    # OpenCV camera axes (x right, y down, z forward) to Blender's (x right, y up, -z forward).
    obj.matrix_world = m @ Matrix.Diagonal((1.0, -1.0, -1.0, 1.0))
    bpy.context.scene.camera = obj


def lights():
    sun = bpy.data.lights.new("sun", type="SUN")
    sun.energy = 3.0
    obj = bpy.data.objects.new("sun", sun)
    bpy.context.scene.collection.objects.link(obj)
    toward = Vector((0.8, -0.8, 1.2)).normalized()
    obj.rotation_euler = (-toward).to_track_quat("-Z", "Y").to_euler()
    world = bpy.data.worlds.new("world")
    world.color = (0.4, 0.4, 0.42)
    bpy.context.scene.world = world


def main():
    args = parse()
    cam = json.loads((args.scene / "render" / "front_camera.json").read_text())
    layout = json.loads((args.scene / args.layout).read_text())
    clear()
    setup = time.perf_counter()
    for obj in layout["objects"]:
        place(obj, args.library)
    table(layout["item_placement_zone"])
    camera(cam)
    lights()
    scene = bpy.context.scene
    engine = {"WORKBENCH": "BLENDER_WORKBENCH", "EEVEE": "BLENDER_EEVEE_NEXT", "CYCLES": "CYCLES"}
    scene.render.engine = engine[args.engine]
    if args.engine == "WORKBENCH":
        shading = scene.display.shading
        shading.light = "STUDIO"
        shading.color_type = "TEXTURE"
        shading.show_shadows = True
        scene.display.render_aa = "8"
    elif args.engine == "CYCLES":
        scene.cycles.device = "CPU"
        scene.cycles.samples = 16
    scene.render.resolution_x = cam["width"]
    scene.render.resolution_y = cam["height"]
    scene.render.resolution_percentage = 100
    scene.render.film_transparent = True
    scene.render.image_settings.file_format = "PNG"
    scene.render.image_settings.color_mode = "RGBA"
    scene.render.filepath = str(args.out)
    setup = time.perf_counter() - setup
    times = []
    cpu = []

    def render():
        t, c = time.perf_counter(), time.process_time()
        bpy.ops.render.render(write_still=True)
        times.append(time.perf_counter() - t)
        cpu.append(time.process_time() - c)

    render()  # the first render compiles the shaders
    alternate = None
    if args.alternate:
        sys.dont_write_bytecode = True  # no __pycache__ left in bench/
        sys.path.insert(0, str(Path(__file__).resolve().parent))
        from timing import Served, alternated
        served = Served(shlex.split(args.alternate), "runs_s")
        # One untimed render a turn (a render is longer than the warm-up time), taken out of
        # the lists after.
        _, alternate = alternated(render, served, args.repeat)
        served.finish()
        times = times[:1] + times[2::2]
        cpu = cpu[:1] + cpu[2::2]
        assert len(times) == 1 + args.repeat, "a turn rendered more than twice with Blender"
    else:
        for _ in range(args.repeat):
            render()
    triangles = sum(len(p.vertices) - 2 for o in scene.objects if o.type == "MESH" for p in o.data.polygons)
    print(json.dumps({
        "engine": scene.render.engine,
        "objects": len(layout["objects"]),
        "triangles": triangles,
        "width": cam["width"],
        "height": cam["height"],
        "setup_s": round(setup, 3),
        "first_render_s": round(times[0], 4),
        "median_render_s": round(statistics.median(times[1:]), 4) if args.repeat else None,
        "renders_s": [round(t, 4) for t in times],
        "median_render_cpu_s": round(statistics.median(cpu[1:]), 4) if args.repeat else None,
        **({"alternate_runs_s": alternate} if alternate is not None else {}),
    }))


main()
