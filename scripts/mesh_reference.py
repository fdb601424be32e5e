#!/usr/bin/env python3
"""The exact-mesh reference for `mesa check`: colliding pairs, penetration depth brackets and
falls, computed on the placed triangle meshes of a scene, never on mesa's convex parts.

Input: a JSON job on standard input,
    {"scenes": [{"key": str, "glb": path, "instances": [str, ...]}, ...],
     "tolerance_mm": float}
where each GLB places every object as a node named after its instance (`mesa pack` writes
such a scene, glTF Y-up). Output: JSON on standard output,
    {key: {"pairs": [{"a", "b", "intersect", "contained", "lo_mm", "hi_mm"}],
           "gaps_mm": {instance: gap}}}

- Two objects *touch or overlap* when their triangles intersect (FCL on the meshes' BVHs) or
  one lies inside the other (its points have winding number 1 for the other's surface).
- The penetration depth is bracketed. Lower bound: the deepest point of one object inside
  the other (vertices and 2,000 surface samples; any translation that separates them moves
  that point at least its distance to the other's surface). Upper bound: the shortest of the
  translations found along 226 directions (the 26 of a cube's faces, edges
  and corners, and 200 spread evenly) (and their refinement) after which the meshes
  neither intersect nor contain one another (verified with FCL and winding numbers).
- The fall of an object: how far it could drop straight down before its mesh meets the table
  top (z = 0) or another mesh: rays down from its vertices and samples onto the others, rays
  up from theirs onto it, and its lowest point over the table; 0 when some of its points lie
  inside another object or its surface crosses the other's (a rim or a thin wall that no
  point is inside). Only the meshes that reach below its lowest point count: one that stands
  on it or is sunk into its top holds nothing up.

Pairs whose bounding boxes are farther apart than the tolerance are left out (they are
separated). Everything is deterministic (fixed sampling seed).
"""

import json
import sys

import fcl
import numpy as np
import trimesh

SAMPLES = 2000
DIRECTIONS = np.array(
    [
        [x, y, z]
        for x in (-1, 0, 1)
        for y in (-1, 0, 1)
        for z in (-1, 0, 1)
        if (x, y, z) != (0, 0, 0)
    ],
    dtype=float,
)
DIRECTIONS /= np.linalg.norm(DIRECTIONS, axis=1)[:, None]
# And 200 more, evenly spread (a Fibonacci sphere).
_k = np.arange(200) + 0.5
_z = 1 - 2 * _k / 200
_phi = np.pi * (1 + 5**0.5) * _k
DIRECTIONS = np.vstack(
    [DIRECTIONS, np.column_stack([np.sqrt(1 - _z**2) * np.cos(_phi), np.sqrt(1 - _z**2) * np.sin(_phi), _z])]
)


def load_objects(glb, instances):
    """The placed mesh of every instance, in the table frame (z up, metres)."""
    scene = trimesh.load(glb, force="scene", process=False)
    parents = scene.graph.transforms.parents
    wanted = set(instances)
    pieces = {name: [] for name in instances}
    for node in scene.graph.nodes_geometry:
        owner = node
        while owner is not None and owner not in wanted:
            owner = parents.get(owner)
        if owner is None:
            continue
        transform, geometry = scene.graph.get(node)
        mesh = scene.geometry[geometry]
        if not isinstance(mesh, trimesh.Trimesh) or len(mesh.faces) == 0:
            continue
        v = trimesh.transform_points(mesh.vertices, transform)
        v = np.column_stack([v[:, 0], -v[:, 2], v[:, 1]])
        pieces[owner].append((v, np.asarray(mesh.faces)))
    out = {}
    for name, parts in pieces.items():
        if not parts:
            raise SystemExit(f"{glb}: no mesh under the node {name!r}")
        vertices, faces, offset = [], [], 0
        for v, f in parts:
            vertices.append(v)
            faces.append(f + offset)
            offset += len(v)
        mesh = trimesh.Trimesh(np.vstack(vertices), np.vstack(faces), process=False)
        out[name] = Object(mesh)
    return out


class Object:
    def __init__(self, mesh):
        self.mesh = mesh
        self.bounds = mesh.bounds
        rng = np.random.default_rng(7)
        samples = sample_surface(mesh, SAMPLES, rng)
        self.points = np.vstack([mesh.vertices, samples])
        self.triangles = mesh.vertices[mesh.faces]
        model = fcl.BVHModel()
        model.beginModel(len(mesh.vertices), len(mesh.faces))
        model.addSubModel(mesh.vertices, mesh.faces.astype(np.int32))
        model.endModel()
        self.model = model

    def fcl_object(self, shift):
        return fcl.CollisionObject(self.model, fcl.Transform(np.asarray(shift, dtype=float)))


def sample_surface(mesh, count, rng):
    areas = mesh.area_faces
    if areas.sum() <= 0:
        return np.zeros((0, 3))
    faces = rng.choice(len(areas), size=count, p=areas / areas.sum())
    r = rng.random((count, 2))
    flip = r.sum(axis=1) > 1
    r[flip] = 1 - r[flip]
    t = mesh.vertices[mesh.faces[faces]]
    return t[:, 0] + r[:, :1] * (t[:, 1] - t[:, 0]) + r[:, 1:] * (t[:, 2] - t[:, 0])


def inside(points, other):
    """Which points lie inside `other` (winding number above one half); only points within
    its bounding box are measured."""
    out = np.zeros(len(points), dtype=bool)
    near = np.all((points >= other.bounds[0]) & (points <= other.bounds[1]), axis=1)
    if near.any():
        out[near] = winding(points[near], other.triangles) > 0.5
    return out


def winding(points, triangles, chunk=64):
    """Generalized winding numbers of points for a triangle soup (1 inside a closed surface,
    0 outside; robust to several closed pieces and small cracks)."""
    out = np.zeros(len(points))
    for s in range(0, len(points), chunk):
        p = points[s : s + chunk]
        a = triangles[None, :, 0, :] - p[:, None, :]
        b = triangles[None, :, 1, :] - p[:, None, :]
        c = triangles[None, :, 2, :] - p[:, None, :]
        la, lb, lc = (np.linalg.norm(x, axis=2) for x in (a, b, c))
        det = np.einsum("ijk,ijk->ij", a, np.cross(b, c))
        den = (
            la * lb * lc
            + np.einsum("ijk,ijk->ij", a, b) * lc
            + np.einsum("ijk,ijk->ij", b, c) * la
            + np.einsum("ijk,ijk->ij", c, a) * lb
        )
        out[s : s + chunk] = np.arctan2(det, den).sum(axis=1) / (2 * np.pi)
    return np.abs(out)


def intersect(a, b, shift=(0.0, 0.0, 0.0)):
    request = fcl.CollisionRequest()
    result = fcl.CollisionResult()
    return fcl.collide(a.fcl_object(shift), b.fcl_object((0.0, 0.0, 0.0)), request, result) > 0


def contained(a, b, shift=(0.0, 0.0, 0.0)):
    """Whether a (moved by shift) has a vertex inside b, or b one inside a."""
    shift = np.asarray(shift)
    pa = a.mesh.vertices[:1] + shift
    pb = b.mesh.vertices[:1] - shift
    return inside(pa, b)[0] or inside(pb, a)[0]


def apart(a, b, shift):
    return not intersect(a, b, shift) and not contained(a, b, shift)


def deepest(a, b):
    """The largest distance to b's surface of a point of a inside b."""
    points = a.points[inside(a.points, b)]
    if len(points) == 0:
        return 0.0
    _, distance, _ = trimesh.proximity.closest_point(b.mesh, points)
    return float(distance.max())


def separation(a, b, lo):
    """The shortest verified separating translation found (an upper bound of the depth)."""
    best = np.inf
    for u in DIRECTIONS:
        # Far enough along u: a's box past b's box.
        reach = max(
            float(np.dot(b.bounds[1] - a.bounds[0], np.maximum(u, 0)))
            + float(np.dot(b.bounds[0] - a.bounds[1], np.minimum(u, 0))),
            0.0,
        ) + 1e-6
        if reach >= best:
            continue
        if not apart(a, b, u * reach):
            continue
        low, high = max(lo - 1e-6, 0.0), reach
        for _ in range(18):
            mid = 0.5 * (low + high)
            if apart(a, b, u * mid):
                high = mid
            else:
                low = mid
            if high - low < 2e-5:
                break
        best = min(best, high)
    return best


def boxes_gap(a, b):
    return float(
        np.max(np.maximum(a.bounds[0] - b.bounds[1], b.bounds[0] - a.bounds[1]))
    )


def falls(objects):
    names = sorted(objects)
    gaps = {}
    for name in names:
        o = objects[name]
        gap = max(float(o.bounds[0][2]), 0.0)
        for other_name in names:
            if other_name == name or gap == 0.0:
                continue
            other = objects[other_name]
            xy = np.maximum(o.bounds[0][:2] - other.bounds[1][:2], other.bounds[0][:2] - o.bounds[1][:2])
            # Only what reaches below its lowest point can hold it up: an object standing on
            # it, or sunk into its top, presses it down.
            if np.max(xy) > 0 or other.bounds[0][2] >= o.bounds[0][2]:
                continue
            if float(o.bounds[0][2] - other.bounds[1][2]) >= gap:
                continue
            # Sunk into the other (points inside it, or its surface crossing the other's, as a
            # thin rim or wall that no point is inside): rests.
            if inside(o.points, other).any() or intersect(o, other):
                gap = 0.0
                break
            down = np.tile([0.0, 0.0, -1.0], (len(o.points), 1))
            hits, rays, _ = other.mesh.ray.intersects_location(o.points, down, multiple_hits=True)
            if len(hits):
                d = o.points[rays][:, 2] - hits[:, 2]
                d = d[d >= -1e-9]
                if len(d):
                    gap = min(gap, max(float(d.min()), 0.0))
            up = np.tile([0.0, 0.0, 1.0], (len(other.points), 1))
            hits, rays, _ = o.mesh.ray.intersects_location(other.points, up, multiple_hits=True)
            if len(hits):
                d = hits[:, 2] - other.points[rays][:, 2]
                d = d[d >= -1e-9]
                if len(d):
                    gap = min(gap, max(float(d.min()), 0.0))
        gaps[name] = gap * 1000.0
    return gaps


def scene_reference(glb, instances, tolerance_m):
    objects = load_objects(glb, instances)
    names = sorted(objects)
    pairs = []
    for i, x in enumerate(names):
        for y in names[i + 1 :]:
            a, b = objects[x], objects[y]
            if boxes_gap(a, b) > 0:
                continue
            touching = intersect(a, b)
            inside = not touching and contained(a, b)
            if not touching and not inside:
                continue
            lo = max(deepest(a, b), deepest(b, a))
            hi = separation(a, b, lo)
            pairs.append(
                {
                    "a": x,
                    "b": y,
                    "intersect": bool(touching),
                    "contained": bool(inside),
                    "lo_mm": lo * 1000.0,
                    "hi_mm": hi * 1000.0,
                }
            )
    return {"pairs": pairs, "gaps_mm": falls(objects)}


def main():
    job = json.load(sys.stdin)
    tolerance_m = job.get("tolerance_mm", 2.0) / 1000.0
    out = {}
    for scene in job["scenes"]:
        out[scene["key"]] = scene_reference(scene["glb"], scene["instances"], tolerance_m)
    json.dump(out, sys.stdout, indent=1, sort_keys=True)


if __name__ == "__main__":
    main()
