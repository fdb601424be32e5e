#!/usr/bin/env python3
"""Loads scenes written by `mesa export` in a simulator and measures how still they stay.

Usage: sim_export.py mujoco SECONDS SCENE_DIR...   (each SCENE_DIR holds sim/export.json)
Output: JSON on standard output,
    {scene_dir: {"loaded": bool, "error": str|null, "bodies": [names],
                 "colliders": {instance: count}, "objects": {instance: {"moved_cm": float,
                 "fell": bool}}}}

MuJoCo: sim/mjcf/scene.xml is loaded with `MjModel.from_xml_path`; every body's collision geoms
(group 3) are counted; the scene is stepped for SECONDS of simulated time at the file's
timestep. An object's displacement is the largest distance any vertex of its convex parts
(the OBJ files of sim/mjcf/meshes, body frame) moved; it fell when its centre of mass ended
more than 5 cm below the table top (z = 0). Also per object: the final height of its centre of
mass ("final_z_cm") and how far its origin drifted in the plane ("final_xy_offset_cm").
"""

import json
import os
import sys

import numpy as np


def obj_vertices(path):
    out = []
    with open(path) as f:
        for line in f:
            if line.startswith("v "):
                out.append([float(v) for v in line.split()[1:4]])
    return np.asarray(out, dtype=float).reshape(-1, 3)


def part_points(mesh_dir, instance, count):
    pts = [obj_vertices(os.path.join(mesh_dir, f"{instance}.part_{k:03d}.obj")) for k in range(count)]
    return np.vstack(pts) if pts else np.zeros((1, 3))


def moved(local, p0, r0, p1, r1):
    a = local @ r0.T + p0
    b = local @ r1.T + p1
    return float(np.max(np.linalg.norm(b - a, axis=1)))


def run_mujoco(scene_dir, seconds):
    import mujoco

    manifest = json.load(open(os.path.join(scene_dir, "sim", "export.json")))
    xml = os.path.join(scene_dir, "sim", "mjcf", "scene.xml")
    try:
        model = mujoco.MjModel.from_xml_path(xml)
    except Exception as e:  # noqa: BLE001 - reported to the Rust test
        return {"loaded": False, "error": str(e)}
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    bodies = [model.body(i).name for i in range(1, model.nbody)]
    colliders = {}
    for g in range(model.ngeom):
        if model.geom_group[g] == 3 and model.geom_contype[g] != 0:
            name = model.body(model.geom_bodyid[g]).name
            colliders[name] = colliders.get(name, 0) + 1
    mesh_dir = os.path.join(scene_dir, "sim", "mjcf", "meshes")
    start = {}
    for o in manifest["objects"]:
        b = model.body(o["instance"]).id
        local = part_points(mesh_dir, o["instance"], o["collision_parts"])
        start[o["instance"]] = (b, local, data.xpos[b].copy(), data.xmat[b].reshape(3, 3).copy())
    steps = int(round(seconds / model.opt.timestep))
    for _ in range(steps):
        mujoco.mj_step(model, data)
    objects, final_z, final_xy = {}, {}, {}
    for name, (b, local, p0, r0) in start.items():
        final_z[name] = 100.0 * float(data.xipos[b][2])
        final_xy[name] = 100.0 * float(np.linalg.norm(data.xpos[b][:2] - p0[:2]))
        p1, r1 = data.xpos[b].copy(), data.xmat[b].reshape(3, 3).copy()
        objects[name] = {
            "moved_cm": 100.0 * moved(local, p0, r0, p1, r1),
            "fell": bool(data.xipos[b][2] < -0.05),
        }
    return {
        "loaded": True,
        "error": None,
        "bodies": bodies,
        "colliders": colliders,
        "objects": objects,
        "final_z_cm": final_z,
        "final_xy_offset_cm": final_xy,
    }


def main():
    sim, seconds, dirs = sys.argv[1], float(sys.argv[2]), sys.argv[3:]
    runner = {"mujoco": run_mujoco}[sim]
    json.dump({d: runner(d, seconds) for d in dirs}, sys.stdout)


if __name__ == "__main__":
    main()
