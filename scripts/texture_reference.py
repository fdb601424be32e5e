#!/usr/bin/env python3
"""An independent colour reference for `mesa export`'s textured visual meshes.

Usage: texture_reference.py DATASET [--flip-v]
    DATASET holds assets/index/assets.json and assets/sim/<uid>/ (`mesa export --assets`).
Output: JSON on standard output,
    {uid: {"samples": n, "agree": n, "textured": n, "textured_agree": n, "unmatched": n},
     "all": {the same, summed}}

trimesh reads both sides: each asset's source GLB (its textures with Pillow; trimesh turns
glTF's v, which points down the image, into its own, which points up) and each exported
`mjcf/meshes/<uid>.visual_<k>.obj` with the MTL and PNG it names. The samples are every
vertex and every triangle's centroid (the export keeps every triangle, so centroids match;
there the texture coordinate is interpolated, away from the texture's corners, where a wrong
flip often lands on the same colour). An exported sample gets the colour trimesh gives it
(`trimesh.visual.color.uv_to_color`: the texel under its texture coordinate; else the MTL's
`Kd`); the GLB's samples at the same place (the GLB's points taken to the export's body frame:
glTF's y up turned to z up, the index's front yaw, minus the centre of the index's bounding
box) get theirs (the texel, or the base colour factor sRGB-encoded, as the export writes
`Kd`). A sample agrees when one GLB sample at its place (within 10 µm; seams put several
there) differs by at most 24 of 255 in every channel (a neighbouring texel at a rounded
coordinate, a JPEG decoded by another library).

--flip-v is the control: the exported `vt` read as v -> 1 - v, what a writer that forgot the
opposite v axes of glTF and OBJ would give; the textured agreement must then fall.
"""

import json
import math
import os
import shutil
import sys
import tempfile

import numpy as np
import trimesh
from scipy.spatial import cKDTree

TOLERANCE = 24
PLACE_M = 1e-5


def srgb(linear):
    c = np.clip(np.asarray(linear, dtype=float), 0.0, 1.0)
    return np.where(c <= 0.0031308, 12.92 * c, 1.055 * np.power(c, 1 / 2.4) - 0.055)


def body_from_gltf(points, geometry):
    """The export's body frame of an asset at its own size (`mesa export --assets`)."""
    p = np.column_stack([points[:, 0], -points[:, 2], points[:, 1]])
    yaw = math.radians(geometry["front_yaw_deg"])
    if yaw != 0.0:
        c, s = math.cos(yaw), math.sin(yaw)
        p = np.column_stack([c * p[:, 0] - s * p[:, 1], s * p[:, 0] + c * p[:, 1], p[:, 2]])
    centre = 0.5 * (np.asarray(geometry["bounds_min_m"]) + np.asarray(geometry["bounds_max_m"]))
    return p - centre


def samples(points, faces, uv, image, colour):
    """Points, RGB colours and whether textured, at every vertex and at every triangle's
    centroid (where a texture coordinate is interpolated, not one of the vertices' own)."""
    centroids = points[faces].mean(axis=1)
    at = np.vstack([points, centroids])
    if image is not None and uv is not None and len(uv) == len(points):
        uvs = np.vstack([uv, uv[faces].mean(axis=1)])
        c = trimesh.visual.color.uv_to_color(uvs, image)[:, :3].astype(float)
        return at, c, np.ones(len(at), dtype=bool), len(points)
    return at, np.tile(np.asarray(colour, dtype=float)[:3], (len(at), 1)), np.zeros(len(at), dtype=bool), len(points)


def glb_colours(path, geometry):
    """Samples (body frame) of the GLB's placed primitives, as trimesh colours them."""
    scene = trimesh.load(path, force="scene", process=False)
    out = []
    for node in scene.graph.nodes_geometry:
        transform, name = scene.graph[node]
        mesh = scene.geometry[name]
        if not isinstance(mesh, trimesh.Trimesh) or len(mesh.vertices) == 0:
            continue
        v = body_from_gltf(trimesh.transform_points(mesh.vertices, transform), geometry)
        material = getattr(mesh.visual, "material", None)
        uv = getattr(mesh.visual, "uv", None)
        image = getattr(material, "baseColorTexture", None) if material is not None else None
        factor = getattr(material, "baseColorFactor", None) if material is not None else None
        if material is None:
            # No glTF material (glTF's default is white): the export draws it grey, 0.8 sRGB.
            rgb = np.array([204.0, 204.0, 204.0])
        else:
            if factor is None:
                factor = np.array([255, 255, 255, 255])
            rgb = 255.0 * srgb(np.asarray(factor, dtype=float)[:3] / 255.0)
        out.append(samples(v, mesh.faces, uv, image, rgb))
    return [np.vstack([o[0] for o in out]), np.vstack([o[1] for o in out])]


def flipped_copy(folder, uid, tmp):
    """A copy of the asset's meshes folder with every `vt` line's v replaced by 1 - v."""
    meshes = os.path.join(folder, "mjcf", "meshes")
    out = os.path.join(tmp, uid, "mjcf", "meshes")
    os.makedirs(out)
    if os.path.isdir(os.path.join(folder, "textures")):
        shutil.copytree(os.path.join(folder, "textures"), os.path.join(tmp, uid, "textures"))
    for name in os.listdir(meshes):
        text = open(os.path.join(meshes, name)).read()
        if name.endswith(".obj"):
            lines = []
            for line in text.splitlines():
                if line.startswith("vt "):
                    u, v = line.split()[1:3]
                    line = f"vt {u} {1.0 - float(v):.6f}"
                lines.append(line)
            text = "\n".join(lines) + "\n"
        open(os.path.join(out, name), "w").write(text)
    return os.path.join(tmp, uid)


def export_colours(folder, uid, materials):
    """Samples of the exported OBJ files, as trimesh colours them (MTL `Kd`, `map_Kd`)."""
    out = []
    for k in range(materials):
        path = os.path.join(folder, "mjcf", "meshes", f"{uid}.visual_{k:03d}.obj")
        mesh = trimesh.load(path, force="mesh", process=False, maintain_order=True)
        material = mesh.visual.material
        out.append(
            samples(
                np.asarray(mesh.vertices, dtype=float),
                mesh.faces,
                getattr(mesh.visual, "uv", None),
                getattr(material, "image", None),
                np.asarray(material.main_color, dtype=float),
            )
        )
    return out


def compare(dataset, uid, record, flip, tmp):
    folder = os.path.join(dataset, "assets", "sim", uid)
    manifest = json.load(open(os.path.join(folder, "export.json")))
    materials = manifest["objects"][0]["visual_materials"]
    if flip:
        folder = flipped_copy(folder, uid, tmp)
    ref_points, ref_colours = glb_colours(os.path.join(dataset, record["file"]), record["geometry"])
    tree = cKDTree(ref_points)
    out = {k: 0 for k in ["samples", "agree", "textured", "textured_agree", "unmatched"]}
    for points, colours, textured, _ in export_colours(folder, uid, materials):
        for p, c, t in zip(points, colours, textured):
            out["samples"] += 1
            out["textured"] += bool(t)
            near = tree.query_ball_point(p, PLACE_M)
            if not near:
                out["unmatched"] += 1
                continue
            ok = bool(np.min(np.max(np.abs(ref_colours[near] - c), axis=1)) <= TOLERANCE)
            out["agree"] += ok
            out["textured_agree"] += ok and bool(t)
    return out


def main():
    dataset = sys.argv[1]
    flip = "--flip-v" in sys.argv[2:]
    index = json.load(open(os.path.join(dataset, "assets", "index", "assets.json")))["assets"]
    root = os.path.join(dataset, "assets", "sim")
    result = {}
    with tempfile.TemporaryDirectory() as tmp:
        for uid in sorted(os.listdir(root)):
            result[uid] = compare(dataset, uid, index[uid], flip, tmp)
    total = {k: sum(r[k] for r in result.values()) for k in next(iter(result.values()))}
    result["all"] = total
    print(json.dumps(result))


if __name__ == "__main__":
    main()
