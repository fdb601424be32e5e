#!/usr/bin/env python3
"""A MuJoCo drop test of placed scenes: does a simulator keep the objects where the layout put
them?

Input: JSON on standard input,
    {"seconds": 2.0, "density": 500.0,
     "scenes": [{"key": str, "table": [x_min, x_max, y_min, y_max],
                 "objects": [{"name": str, "parts": [[[x, y, z], ...], ...]}]}]}
with every part a convex point set in the table frame (metres, z up, the table top at z = 0).
Output: JSON on standard output, {key: {name: {"moved_cm": float, "fell": bool}}}.

Each object is a free body whose collision geoms are its convex parts (MuJoCo collides on each
mesh's convex hull, so a part list keeps a cup hollow); mass from a uniform density. The
table is a static box whose top is z = 0, 0.5 m larger than the given extent on every side.
After `seconds` of simulated time (2 ms steps, MuJoCo's default soft contacts and friction),
each object's displacement is the largest distance any of its parts' points moved; it fell
when it ended more than 5 cm below the table top. Flat parts (no volume) are left out: MuJoCo
cannot give them an inertia.
"""

import json
import sys

import mujoco
import numpy as np


def volume_ok(points):
    p = np.asarray(points)
    if len(p) < 4:
        return False
    centred = p - p.mean(axis=0)
    return np.linalg.matrix_rank(centred, tol=1e-6) == 3


def scene_xml(scene, density):
    assets, bodies = [], []
    kept = []
    for i, obj in enumerate(scene["objects"]):
        parts = [np.asarray(p, dtype=float) for p in obj["parts"] if volume_ok(p)]
        if not parts:
            continue
        origin = np.vstack(parts).mean(axis=0)
        geoms = []
        for j, part in enumerate(parts):
            name = f"m{i}_{j}"
            vertices = " ".join(f"{v:.7f}" for v in (part - origin).ravel())
            assets.append(f'<mesh name="{name}" vertex="{vertices}"/>')
            geoms.append(f'<geom type="mesh" mesh="{name}" density="{density}"/>')
        bodies.append(
            f'<body name="b{i}" pos="{origin[0]:.7f} {origin[1]:.7f} {origin[2]:.7f}">'
            f"<freejoint/>{''.join(geoms)}</body>"
        )
        kept.append((obj["name"], i, origin, parts))
    x0, x1, y0, y1 = scene["table"]
    cx, cy = (x0 + x1) / 2, (y0 + y1) / 2
    hx, hy = (x1 - x0) / 2 + 0.5, (y1 - y0) / 2 + 0.5
    xml = f"""<mujoco>
  <option timestep="0.002" gravity="0 0 -9.81"/>
  <size memory="512M"/>
  <asset>{''.join(assets)}</asset>
  <worldbody>
    <geom name="table" type="box" pos="{cx} {cy} -0.025" size="{hx} {hy} 0.025"/>
    {''.join(bodies)}
  </worldbody>
</mujoco>"""
    return xml, kept


def drop(scene, seconds, density):
    xml, kept = scene_xml(scene, density)
    model = mujoco.MjModel.from_xml_string(xml)
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    start = {}
    for name, i, origin, parts in kept:
        body = model.body(f"b{i}").id
        local = np.vstack(parts) - origin
        start[name] = (body, local, data.xpos[body].copy(), data.xmat[body].reshape(3, 3).copy())
    steps = int(round(seconds / model.opt.timestep))
    for _ in range(steps):
        mujoco.mj_step(model, data)
    out = {}
    for name, (body, local, pos0, rot0) in start.items():
        before = local @ rot0.T + pos0
        after = local @ data.xmat[body].reshape(3, 3).T + data.xpos[body]
        moved = float(np.linalg.norm(after - before, axis=1).max())
        out[name] = {"moved_cm": moved * 100.0, "fell": bool(after[:, 2].max() < -0.05)}
    return out


def main():
    job = json.load(sys.stdin)
    seconds = job.get("seconds", 2.0)
    density = job.get("density", 500.0)
    out = {s["key"]: drop(s, seconds, density) for s in job["scenes"]}
    json.dump(out, sys.stdout, indent=1, sort_keys=True)


if __name__ == "__main__":
    main()
