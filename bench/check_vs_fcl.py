"""Times trimesh's CollisionManager (python-fcl) on the convex parts `mesa check` uses.

Usage: check_vs_fcl.py DATASET LAYOUT [REPEATS]

Each object of LAYOUT (a dataset layout) becomes one FCL BVH mesh: the convex hulls of its
asset's collision parts (assets/index/shapes/<uid>.json), scaled by its scale_factor along the
asset's axes, in the object's frame; its rotation and position are the FCL transform. Built
once (the cached shapes), then each repeat sets every object's transform and asks:

- collisions: `in_collision_internal(return_names=True, return_data=True)` (every colliding
  pair with its contacts and depths), what `mesa check` finds as colliding pairs;
- distance: `min_distance_internal(return_names=True)` (FCL has no all-pairs distance query;
  one call is a lower bound of the cost of MesaTask's 5 cm rule).

- scene from the cache: what checking one scene takes with FCL when the assets' parts are
  cached unscaled (as `mesa check` has them): each object's mesh scaled (scale factors differ
  per scene, so FCL's BVHs are built per scene), added, then the collision query. This is
  the counterpart of mesa's bench, which places every part and checks each iteration.

Prints one JSON object: objects, triangles, and the median seconds of each.

Needs: python -m venv /work/venv-check && /work/venv-check/bin/pip install trimesh numpy scipy
python-fcl (trimesh's convex hull uses scipy).
"""

import json
import os
import statistics
import sys
import time

import numpy as np
import trimesh


def quat_matrix(q):
    x, y, z, w = q
    n = (x * x + y * y + z * z + w * w) ** 0.5
    x, y, z, w = x / n, y / n, z / n, w / n
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


def main():
    dataset, layout_path = sys.argv[1], sys.argv[2]
    repeats = int(sys.argv[3]) if len(sys.argv) > 3 else 200
    index = json.load(open(os.path.join(dataset, "assets/index/assets.json")))["assets"]
    layout = json.load(open(layout_path))
    # The cache: each asset's convex parts as one mesh, unscaled, centred on its box (what
    # `mesa assets` caches, made once per asset).
    cached = {}
    for obj in layout["objects"]:
        uid = obj["retrieved_uid"]
        if uid in cached:
            continue
        record = index[uid]
        shapes = json.load(open(os.path.join(dataset, record["shapes"]["file"])))
        lo = np.array(record["geometry"]["bounds_min_m"])
        hi = np.array(record["geometry"]["bounds_max_m"])
        centre = (lo + hi) / 2
        parts = [
            trimesh.convex.convex_hull(np.array(part["points_m"]) - centre)
            for part in shapes["parts"]
            if len(part["points_m"]) >= 4
        ]
        cached[uid] = trimesh.util.concatenate(parts)

    def transform_of(obj):
        transform = np.eye(4)
        transform[:3, :3] = quat_matrix(obj["rotation"])
        transform[:3, 3] = np.array(obj["position"]) / 100.0
        return transform

    def build():
        """One scene from the cache: each object's mesh scaled by its scale_factor (a scale
        differs per scene, so FCL's BVH is built per scene), added at its transform."""
        manager = trimesh.collision.CollisionManager()
        for obj in layout["objects"]:
            mesh = cached[obj["retrieved_uid"]]
            scaled = trimesh.Trimesh(
                vertices=mesh.vertices * np.array(obj["scale_factor"]),
                faces=mesh.faces,
                process=False,
            )
            manager.add_object(obj["instance"], scaled, transform=transform_of(obj))
        return manager

    manager = build()
    transforms = {obj["instance"]: transform_of(obj) for obj in layout["objects"]}
    triangles = sum(len(cached[obj["retrieved_uid"]].faces) for obj in layout["objects"])

    def timed(query):
        times = []
        for _ in range(repeats):
            start = time.perf_counter()
            for name, transform in transforms.items():
                manager.set_transform(name, transform)
            result = query()
            times.append(time.perf_counter() - start)
        return statistics.median(times), result

    collide_s, (hit, pairs, _contacts) = timed(
        lambda: manager.in_collision_internal(return_names=True, return_data=True)
    )
    distance_s, _ = timed(lambda: manager.min_distance_internal(return_names=True))
    scene_times = []
    for _ in range(max(repeats // 10, 5)):
        start = time.perf_counter()
        build().in_collision_internal(return_names=True, return_data=True)
        scene_times.append(time.perf_counter() - start)
    print(
        json.dumps(
            {
                "objects": len(transforms),
                "triangles": triangles,
                "fcl_colliding_pairs": len(pairs),
                "fcl_collisions_s": collide_s,
                "fcl_min_distance_s": distance_s,
                "fcl_scene_from_cache_s": statistics.median(scene_times),
            }
        )
    )


if __name__ == "__main__":
    main()
