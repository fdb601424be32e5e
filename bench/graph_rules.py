#!/usr/bin/env python3
"""The scene-graph rules of SCENE_GRAPH.md in Python, as a user would write them without mesa:
numpy for the pairwise quantities, shapely for the rotated-rectangle intersections.

It reads the layouts mesa reads (a dataset layout, an LLM layout, or a published MesaTask
record) and writes what the `mesa graph` stage writes for a scene: `graph/graph.txt` (the same
bytes) and `graph/graph.json` (`mesa.graph/1`, keys sorted, numbers as mesa prints them).

    pip install numpy shapely
    python bench/graph_rules.py layout FILE                # prints the triplets, like `mesa graph --layout FILE`
    python bench/graph_rules.py dataset DATASET --out DIR  # DIR/scenes/<table_type>/<scene_id>/graph/graph.{txt,json}

Containers: the `isContainer` (or objathor `receptacle`) annotation of the object's
`retrieved_uid` in DATASET/assets/annotations.json, else the keyword rule (the category, that is
the instance name without its `_<n>` suffix, is or ends with bowl, basket, box, ...).

One case SCENE_GRAPH.md leaves open is settled as mesa settles it (stages/src/graph.rs,
`containment`): when two containers of equal footprint each qualify as the other's container
(two identical cups stacked), only the upper one (higher centre; on equal centres the later in
layout order) is in the lower one.
"""
import argparse
import json
import math
import sys
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import shapely

# Thresholds of SCENE_GRAPH.md.
LEFT_BELOW, RIGHT_ABOVE = 0.20, 0.80  # is at: x bands of fx
FRONT_BELOW, BACK_ABOVE = 0.15, 0.85  # is at: y bands of fy
IN_MIN_FOOTPRINT_SHARE = 0.9
IN_MIN_Z_SHARE = 0.5
ABOVE_Z_TOLERANCE = 1.0
ABOVE_MIN_FOOTPRINT_SHARE = 0.5
RAISED_Z_MIN = 0.5
NEIGHBOUR_MAX_DISTANCE_SHARE = 0.4
NEIGHBOURS_PER_SUBJECT = 5

FACINGS = ["front", "front_right", "right", "back_right", "back", "back_left", "left", "front_left"]
DEFAULT_CONTAINER_KEYWORDS = ("bowl", "basket", "box", "bin", "bucket", "cup", "mug", "pot", "pan",
                              "jar", "vase", "holder", "container", "caddy", "crate", "organizer")
# The layouts a scene's later stages read, most refined first (the settled one wins).
LAYOUT_CANDIDATES = ("qa/layout.json", "refined/layout.json")
ANNOTATIONS = "assets/annotations.json"


# ---------------------------------------------------------------------------------------------
# Reading layouts.

@dataclass
class Scene:
    """A layout as the graph sees it: the zone [x_min, x_max, y_min, y_max] (cm) and the objects
    in the file's order."""
    zone: tuple
    names: list
    position: np.ndarray  # (n, 3) centres, cm
    size: np.ndarray  # (n, 3) width, depth, height before rotation, cm
    yaw: np.ndarray  # (n,) degrees, counter-clockwise
    retrieved_uids: list = field(default_factory=list)


def normalize_deg(angle):
    """An angle in degrees mapped to (-180, 180]."""
    a = angle % 360.0
    return a - 360.0 if a > 180.0 else a


def yaw_of_quaternion(q):
    """The twist about +z of a quaternion [x, y, z, w], in degrees."""
    _, _, z, w = q
    if z == 0.0 and w == 0.0:
        return 0.0
    return normalize_deg(2.0 * math.degrees(math.atan2(z, w)))


def dataset_yaw(obj):
    """A dataset object's yaw: its `z_rotation` when it agrees with `rotation`, else the yaw of
    the quaternion."""
    from_quat = yaw_of_quaternion(obj["rotation"])
    z_rotation = obj.get("z_rotation")
    if z_rotation is not None and abs(normalize_deg(z_rotation - from_quat)) < 1e-6:
        return z_rotation
    return from_quat


def layout_form(doc):
    """'record', 'dataset' or 'llm', recognised by shape as mesa does."""
    if "scene_layout_json" in doc:
        return "record"
    if doc.get("schema") == "mesa.layout/1":
        return "dataset"
    objects = doc.get("objects")
    first = objects[0] if isinstance(objects, list) and objects else None
    if isinstance(first, dict) and ("rotation" in first or "retrieved_uid" in first):
        return "dataset"
    if isinstance(first, dict) and "z_rotation" in first:
        return "llm"
    return "llm" if "sink_zone" in doc else "dataset"


def scene_of(doc):
    """The Scene of a parsed layout document of any form."""
    form = layout_form(doc)
    if form == "record":
        doc = doc["scene_layout_json"]
        if isinstance(doc, str):
            doc = json.loads(doc)
        form = "llm"
    objects = doc["objects"]
    if form == "dataset":
        yaws = [dataset_yaw(o) for o in objects]
        uids = [o.get("retrieved_uid", "") for o in objects]
    else:
        yaws = [o["z_rotation"] for o in objects]
        uids = [""] * len(objects)
    return Scene(
        zone=tuple(float(v) for v in doc["item_placement_zone"]),
        names=[o["instance"] for o in objects],
        position=np.array([o["position"] for o in objects], dtype=float).reshape(-1, 3),
        size=np.array([o["size"] for o in objects], dtype=float).reshape(-1, 3),
        yaw=np.array(yaws, dtype=float),
        retrieved_uids=uids,
    )


def read_scene(path):
    with open(path, encoding="utf-8") as f:
        return scene_of(json.load(f))


# ---------------------------------------------------------------------------------------------
# Containers.

def category_of(instance):
    """`desk_lamp_0` -> `desk_lamp`."""
    stem, sep, index = instance.rpartition("_")
    return stem if sep and index.isdigit() and index.isascii() else instance


def is_keyword_container(instance, keywords=DEFAULT_CONTAINER_KEYWORDS):
    category = category_of(instance).lower()
    return any(k and category.endswith(k) for k in keywords)


def annotation_flag(value):
    """A boolean as annotation files write it (true, 1, "True"); None when absent."""
    if value is None or isinstance(value, bool):
        return value
    if isinstance(value, (int, float)) and value in (0, 1):
        return bool(value)
    if isinstance(value, str) and value.lower() in ("true", "false"):
        return value.lower() == "true"
    raise ValueError(f"not a boolean: {value!r}")


def container_flags(scene, annotations=None, keywords=DEFAULT_CONTAINER_KEYWORDS):
    """One flag per object: the annotation of its retrieved asset, else the keyword rule."""
    flags = []
    for name, uid in zip(scene.names, scene.retrieved_uids or [""] * len(scene.names)):
        entry = annotations.get(uid) if (annotations is not None and uid) else None
        flag = None
        if entry is not None:
            flag = annotation_flag(entry.get("isContainer"))
            if flag is None:
                flag = annotation_flag(entry.get("receptacle"))
        flags.append(flag if flag is not None else is_keyword_container(name, keywords))
    return flags


# ---------------------------------------------------------------------------------------------
# The rules.

@dataclass
class Graph:
    nodes: list  # (instance, is_at, face_to, container)
    edges: list  # (subject, relation, object, {name: number})


def sin_cos_deg(angle):
    """sin and cos of an angle in degrees, exact at quarter turns (axis-aligned footprints stay
    exactly axis-aligned)."""
    a = angle % 360.0
    exact = {0.0: (0.0, 1.0), 90.0: (1.0, 0.0), 180.0: (0.0, -1.0), 270.0: (-1.0, 0.0)}
    if a in exact:
        return exact[a]
    r = math.radians(a)
    return math.sin(r), math.cos(r)


def footprint_corners(size, yaw):
    """(n, 4, 2): each object's w x d rectangle turned by its yaw, corners counter-clockwise,
    as offsets from its centre."""
    sc = np.array([sin_cos_deg(a) for a in yaw]).reshape(-1, 2)
    s, c = sc[:, 0:1], sc[:, 1:2]
    hw, hd = size[:, 0:1] / 2.0, size[:, 1:2] / 2.0
    u = np.hstack([-hw, hw, hw, -hw])
    v = np.hstack([-hd, -hd, hd, hd])
    return np.stack([c * u - s * v, s * u + c * v], axis=-1)


def is_at(fx, fy):
    x = "left" if fx < LEFT_BELOW else "right" if fx > RIGHT_ABOVE else "middle"
    y = "front" if fy < FRONT_BELOW else "back" if fy > BACK_ABOVE else "middle"
    return "center" if (x, y) == ("middle", "middle") else f"{y}_{x}"


def face_to(yaw):
    a = ((yaw + 180.0) % 360.0) - 180.0
    return FACINGS[int(math.floor((a + 22.5) / 45.0)) % 8]


def horizontal(dx, dy):
    if abs(dx) > abs(dy):
        return "right of" if dx > 0 else "left of"
    return "behind" if dy > 0 else "in front of"


def extract_graph(scene, containers):
    """The scene graph of a Scene with one container flag per object (SCENE_GRAPH.md)."""
    n = len(scene.names)
    names = scene.names
    x_min, x_max, y_min, y_max = scene.zone
    width, depth = x_max - x_min, y_max - y_min
    x, y, z = scene.position[:, 0], scene.position[:, 1], scene.position[:, 2]
    h = scene.size[:, 2]
    z_min, z_max = z - h / 2.0, z + h / 2.0
    area = scene.size[:, 0] * scene.size[:, 1]
    is_container = np.array(containers, dtype=bool)

    # Nodes.
    fx = (x - x_min) / width if width != 0 else np.full(n, 0.5)
    fy = (y - y_min) / depth if depth != 0 else np.full(n, 0.5)
    nodes = [(names[i], is_at(fx[i], fy[i]), face_to(float(scene.yaw[i])), bool(containers[i]))
             for i in range(n)]

    # Pairwise quantities, [subject, object]: offsets, distances, vertical tests.
    dx = x[:, None] - x[None, :]
    dy = y[:, None] - y[None, :]
    dz = z[:, None] - z[None, :]
    d2_squared = dx * dx + dy * dy
    d3 = np.sqrt(d2_squared + dz * dz)
    other = ~np.eye(n, dtype=bool)
    z_overlap = np.maximum(0.0, np.minimum(z_max[:, None], z_max[None, :])
                           - np.maximum(z_min[:, None], z_min[None, :]))
    z_share = z_overlap / np.minimum(h[:, None], h[None, :])
    may_be_in = (other & is_container[None, :] & (area[None, :] >= area[:, None])
                 & (z[:, None] > z_min[None, :]) & (z_share >= IN_MIN_Z_SHARE))
    may_be_above = other & (z_min[:, None] > z_max[None, :] - ABOVE_Z_TOLERANCE) & (z[:, None] > z[None, :])

    # Footprint shares share[s, o] = area(fp(s) ∩ fp(o)) / area(s), with shapely, for the pairs
    # the vertical tests leave whose bounding boxes overlap. Each pair is intersected in the
    # subject's frame (centred on it) so that a translated scene gives the same decisions.
    corners = footprint_corners(scene.size, scene.yaw)
    half = np.abs(corners).max(axis=1)
    boxes_overlap = ((np.abs(dx) < half[:, None, 0] + half[None, :, 0])
                     & (np.abs(dy) < half[:, None, 1] + half[None, :, 1]))
    s_idx, o_idx = np.nonzero((may_be_in | may_be_above) & boxes_overlap)
    share = np.zeros((n, n))
    if len(s_idx):
        offset = np.stack([-dx[s_idx, o_idx], -dy[s_idx, o_idx]], axis=-1)[:, None, :]
        subject = shapely.polygons(corners[s_idx])
        obj = shapely.polygons(corners[o_idx] + offset)
        share[s_idx, o_idx] = shapely.area(shapely.intersection(subject, obj)) / area[s_idx]
    qualifies_in = may_be_in & (share >= IN_MIN_FOOTPRINT_SHARE)

    edges = []
    # `in`: the qualifying container with the smallest footprint (ties: earlier).
    contained = np.zeros(n, dtype=bool)
    for s in range(n):
        best = None
        for c in np.flatnonzero(qualifies_in[s]):
            # Two containers that could each be in the other: only the upper one is in.
            if (z[s], s) < (z[c], c) and qualifies_in[c, s]:
                continue
            if best is None or area[c] < area[best]:
                best = c
        if best is not None:
            contained[s] = True
            edges.append((names[s], "in", names[best], {
                "footprint_share": share[s, best], "z_share": z_share[s, best],
                "subject_area_cm2": area[s], "container_area_cm2": area[best]}))
    free = np.flatnonzero(~contained)
    is_free = ~contained

    # `above`: of the qualifying free objects, the one with the highest top (ties: earlier).
    qualifies_above = may_be_above & (share >= ABOVE_MIN_FOOTPRINT_SHARE) & is_free[None, :]
    for s in free:
        candidates = np.flatnonzero(qualifies_above[s])
        if len(candidates):
            o = candidates[np.argmax(z_max[candidates])]
            edges.append((names[s], "above", names[o], {
                "footprint_share": share[s, o], "z_gap_cm": z_min[s] - z_max[o]}))

    # Horizontal: each subject's 5 nearest within 0.4·max(W, D), duals removed.
    max_distance = NEIGHBOUR_MAX_DISTANCE_SHARE * max(width, depth)
    raised = z_min > RAISED_Z_MIN
    visit = [s for s in free if not raised[s]] + [s for s in free if raised[s]]
    emitted = set()
    blocks = {}
    for s in visit:
        others = free[free != s]
        ranked = others[np.argsort(d2_squared[s, others], kind="stable")]
        kept = ranked[d3[s, ranked] <= max_distance][:NEIGHBOURS_PER_SUBJECT]
        for rank, o in enumerate(kept, start=1):
            pair = (min(s, o), max(s, o))
            if (raised[s] and not raised[o]) or pair in emitted:
                continue
            emitted.add(pair)
            blocks.setdefault(s, []).append((names[s], horizontal(dx[s, o], dy[s, o]), names[o], {
                "dx_cm": dx[s, o], "dy_cm": dy[s, o], "distance_2d_cm": math.sqrt(d2_squared[s, o]),
                "distance_3d_cm": d3[s, o], "max_distance_cm": max_distance, "rank": float(rank)}))
    for s in sorted(blocks):
        edges.extend(blocks[s])
    return Graph(nodes, edges)


# ---------------------------------------------------------------------------------------------
# Output.

def graph_text(graph):
    """graph.txt: one triplet per line."""
    lines = []
    for name, cell, facing, _ in graph.nodes:
        lines.append(f"({name}, is at, {cell})\n")
        lines.append(f"({name}, face to, {facing})\n")
    lines.extend(f"({s}, {rel}, {o})\n" for s, rel, o, _ in graph.edges)
    return "".join(lines)


def graph_artifact(graph, scene_id, layout_rel):
    """graph.json's content (mesa.graph/1)."""
    return {
        "schema": "mesa.graph/1",
        "scene_id": scene_id,
        "layout": layout_rel,
        "nodes": [{"instance": i, "is_at": a, "face_to": f, "container": c} for i, a, f, c in graph.nodes],
        "edges": [{"subject": s, "relation": r, "object": o, "numbers": {k: float(v) for k, v in nums.items()}}
                  for s, r, o, nums in graph.edges],
    }


def number_text(v):
    """A float as serde_json prints it: shortest round-trip digits, plain notation for decimal
    exponents -5..15, else `1.5e-7` / `1e+16`."""
    text = repr(v)
    if "e" not in text:
        return text  # Python's repr also prints decimal exponents -4..15 plainly, the same digits
    sign = "-" if v < 0 else ""
    mantissa, _, exponent = repr(abs(v)).partition("e")
    whole, _, fraction = mantissa.partition(".")
    digits = (whole + fraction).lstrip("0")
    exp = len(whole) + int(exponent or 0) - (len(whole + fraction) - len(digits)) - 1
    digits = digits.rstrip("0")
    if -5 <= exp <= 15:
        if len(digits) - 1 <= exp:
            return f"{sign}{digits}{'0' * (exp + 1 - len(digits))}.0"
        if exp >= 0:
            return f"{sign}{digits[:exp + 1]}.{digits[exp + 1:]}"
        return f"{sign}0.{'0' * (-exp - 1)}{digits}"
    head = digits[0] + ("." + digits[1:] if len(digits) > 1 else "")
    return f"{sign}{head}e{'+' if exp >= 0 else '-'}{abs(exp)}"


_json_string = json.JSONEncoder(ensure_ascii=False).encode  # serde_json leaves non-ASCII as is


def pretty_json(value, indent=""):
    """JSON with sorted keys and two-space indents, as serde_json's pretty printer writes it."""
    if isinstance(value, dict):
        if not value:
            return "{}"
        inner = indent + "  "
        items = [f"{inner}{_json_string(k)}: {pretty_json(value[k], inner)}" for k in sorted(value)]
        return "{\n" + ",\n".join(items) + "\n" + indent + "}"
    if isinstance(value, list):
        if not value:
            return "[]"
        inner = indent + "  "
        return "[\n" + ",\n".join(inner + pretty_json(v, inner) for v in value) + "\n" + indent + "]"
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        return number_text(value)
    if isinstance(value, str):
        return _json_string(value)
    return json.dumps(value)


def graph_json(graph, scene_id, layout_rel):
    return pretty_json(graph_artifact(graph, scene_id, layout_rel)) + "\n"


# ---------------------------------------------------------------------------------------------
# A dataset.

def read_annotations(dataset):
    path = Path(dataset) / ANNOTATIONS
    if not path.exists():
        return None
    with open(path, encoding="utf-8") as f:
        return json.load(f)


def dataset_scenes(dataset):
    """(table_type, scene_id, layout path relative to the scene) of every scene with a layout,
    sorted by table type then scene id."""
    scenes = []
    root = Path(dataset) / "scenes"
    for table in sorted(p for p in root.iterdir() if p.is_dir() and not p.name.startswith(".")):
        for scene in sorted(p for p in table.iterdir() if p.is_dir() and not p.name.startswith(".")):
            rel = next((r for r in LAYOUT_CANDIDATES if (scene / r).is_file()), None)
            if rel is not None:
                scenes.append((table.name, scene.name, rel))
    return scenes


def graph_dataset(dataset, out):
    """Reads every scene's layout (and the annotations, once) from `dataset` and writes
    `out/scenes/<table_type>/<scene_id>/graph/graph.txt` and `graph.json`; returns the count."""
    dataset, out = Path(dataset), Path(out)
    annotations = read_annotations(dataset)
    scenes = dataset_scenes(dataset)
    for table, scene_id, rel in scenes:
        scene = read_scene(dataset / "scenes" / table / scene_id / rel)
        graph = extract_graph(scene, container_flags(scene, annotations))
        folder = out / "scenes" / table / scene_id / "graph"
        folder.mkdir(parents=True, exist_ok=True)
        (folder / "graph.txt").write_text(graph_text(graph), encoding="utf-8")
        (folder / "graph.json").write_text(graph_json(graph, scene_id, rel), encoding="utf-8")
    return len(scenes)


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = parser.add_subparsers(dest="command", required=True)
    one = sub.add_parser("layout", help="print the triplets of one layout file (keyword containers)")
    one.add_argument("file")
    many = sub.add_parser("dataset", help="write graph.txt and graph.json for every scene")
    many.add_argument("dataset")
    many.add_argument("--out", required=True, help="output root (the dataset itself is allowed)")
    args = parser.parse_args()
    if args.command == "layout":
        scene = read_scene(args.file)
        sys.stdout.write(graph_text(extract_graph(scene, container_flags(scene))))
    else:
        count = graph_dataset(args.dataset, args.out)
        print(f"{count} scenes", file=sys.stderr)


if __name__ == "__main__":
    main()
