"""A synthetic MesaTask-10K release for the import benchmark (bench/import_10k.sh).

usage: synthetic_release.py OUT [SCENES] [ASSETS] [GLBS]

OUT/Layout_info/<table_type>/<scene_id>/{layout.json, front.png}: SCENES scenes (default 10,700)
of 8 to 20 objects in the released form (cm, xyzw, scale_factor), 2 % naming an asset without a
GLB and 1 % of objects without scale_factor (which MesaTask's reader skips); front.png a small PNG.
OUT/Asset_annotation.json: ASSETS annotations (default 15,507), `detailed_caption` text, the
four bbox forms in turn. OUT/Assets_library/<uid>.glb: the first GLBS uids (default 8,225, as
the release ships), each a hard link to one small GLB (the import links, never reads them).
OUT/sbert_text_features.pkl: ASSETS × 768 float16, pickle protocol 4 as numpy writes it.
Seeded: the same arguments give the same tree.
"""
import json
import os
import pickle
import random
import struct
import sys
import zlib

import numpy as np

TABLES = ["office_table", "dining_table", "kitchen_counter", "coffee_table", "bathroom_vanity"]
CATEGORIES = ["mug", "book", "plate", "bowl", "lamp", "laptop", "vase", "plant", "pen", "phone"]


def png(width, height):
    raw = b"".join(b"\x00" + bytes([(x * 7 + y * 3) % 256 for x in range(width)] * 3) for y in range(height))
    def chunk(kind, data):
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))
    return (b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", width, height, 8, 2, 0, 0, 0))
            + chunk(b"IDAT", zlib.compress(raw)) + chunk(b"IEND", b""))


def glb():
    """A one-triangle GLB."""
    positions = struct.pack("<9f", 0, 0, 0, 0.1, 0, 0, 0, 0.1, 0)
    doc = {"asset": {"version": "2.0"}, "scene": 0, "scenes": [{"nodes": [0]}], "nodes": [{"mesh": 0}],
           "meshes": [{"primitives": [{"attributes": {"POSITION": 0}}]}],
           "accessors": [{"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3",
                          "min": [0, 0, 0], "max": [0.1, 0.1, 0]}],
           "bufferViews": [{"buffer": 0, "byteLength": len(positions)}],
           "buffers": [{"byteLength": len(positions)}]}
    text = json.dumps(doc).encode()
    text += b" " * ((4 - len(text) % 4) % 4)
    body = struct.pack("<I4s", len(text), b"JSON") + text + struct.pack("<I4s", len(positions), b"BIN\x00") + positions
    return struct.pack("<4sII", b"glTF", 2, 12 + len(body)) + body


def main():
    out = sys.argv[1]
    scenes = int(sys.argv[2]) if len(sys.argv) > 2 else 10700
    assets = int(sys.argv[3]) if len(sys.argv) > 3 else 15507
    glbs = int(sys.argv[4]) if len(sys.argv) > 4 else 8225
    rng = random.Random(18)
    uids = [f"{rng.getrandbits(128):032x}" for _ in range(assets)]
    os.makedirs(f"{out}/Assets_library", exist_ok=True)
    first = f"{out}/Assets_library/{uids[0]}.glb"
    with open(first, "wb") as f:
        f.write(glb())
    for uid in uids[1:glbs]:
        path = f"{out}/Assets_library/{uid}.glb"
        if not os.path.exists(path):
            os.link(first, path)
    picture = png(64, 48)
    for k in range(scenes):
        table = TABLES[k % len(TABLES)]
        d = f"{out}/Layout_info/{table}/{table}_{k:05d}"
        os.makedirs(d, exist_ok=True)
        objects = []
        for i in range(rng.randint(8, 20)):
            cat = rng.choice(CATEGORIES)
            uid = uids[rng.randrange(glbs)] if rng.random() > 0.02 else uids[glbs + rng.randrange(assets - glbs)]
            size = [round(rng.uniform(5, 30), 1) for _ in range(3)]
            yaw = rng.uniform(-180, 180)
            import math
            obj = {"instance": f"{cat}_{i}", "retrieved_uid": uid,
                   "position": [round(rng.uniform(0, 150), 1), round(rng.uniform(0, 80), 1), round(size[2] / 2, 1)],
                   "rotation": [0.0, 0.0, math.sin(math.radians(yaw) / 2), math.cos(math.radians(yaw) / 2)],
                   "size": size, "scale_factor": [s / 10 for s in size]}
            if rng.random() < 0.01:
                del obj["scale_factor"]
            objects.append(obj)
        with open(f"{d}/layout.json", "w") as f:
            json.dump({"item_placement_zone": [0, 160, 0, 90], "objects": objects}, f, indent=2)
        with open(f"{d}/front.png", "wb") as f:
            f.write(picture)
    forms = [
        lambda: {"bbox": {"x": 0.1, "y": 0.2, "z": 0.1}},
        lambda: {"bbox": {"size": {"x": 0.1, "y": 0.2, "z": 0.1}}},
        lambda: {"bbox": {"min": {"x": -0.05, "y": 0, "z": -0.05}, "max": {"x": 0.05, "y": 0.2, "z": 0.05}}},
        lambda: {"min_point": [-0.05, 0, -0.05], "max_point": [0.05, 0.2, 0.05]},
    ]
    annotations = {}
    for k, uid in enumerate(uids):
        entry = forms[k % 4]()
        entry.update({"category": CATEGORIES[k % len(CATEGORIES)],
                      "detailed_caption": f"a {CATEGORIES[k % len(CATEGORIES)]} number {k}",
                      "onTable": True})
        annotations[uid] = entry
    with open(f"{out}/Asset_annotation.json", "w") as f:
        json.dump(annotations, f, indent=2)
    features = np.random.default_rng(18).standard_normal((assets, 768)).astype(np.float16)
    with open(f"{out}/sbert_text_features.pkl", "wb") as f:
        pickle.dump({"uids": uids, "text_features": features}, f, protocol=4)


if __name__ == "__main__":
    main()
