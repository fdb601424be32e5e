#!/usr/bin/env python3
"""Seeds of the lift_inputs fuzz target from a `mesa demo` scene's input/ folder (stdlib only).

    python3 fuzz/lift_seeds.py SCENE/input fuzz/corpus/lift_inputs

Each seed is the target's 5-byte header (reader, width u16, height u16) and a file: the demo's
own camera.json, instances.json, depth.png, masks.png and image.png, and what the demo does
not write but lift reads: depth.npy (float32, float64 big-endian, Fortran order; cropped to
keep inputs small), camera.json with a FOV or a calibration, COCO RLE masks (compressed and
list counts) in instances.json, and a per-instance masks/<id>.png.
"""

import json
import os
import struct
import sys
import zlib

RLE, NPY, DEPTH_PNG, CAMERA, INSTANCES, MASKS_PNG, MASK_FILE, PHOTO = range(8)


def header(reader: int, width: int = 0, height: int = 0) -> bytes:
    return bytes([reader]) + struct.pack("<HH", width, height)


def read_gray_png(path: str):
    """(width, height, rows of ints) of a non-interlaced 8- or 16-bit grayscale PNG."""
    data = open(path, "rb").read()
    pos, idat = 8, b""
    while pos < len(data):
        (length,) = struct.unpack(">I", data[pos : pos + 4])
        kind = data[pos + 4 : pos + 8]
        body = data[pos + 8 : pos + 8 + length]
        if kind == b"IHDR":
            width, height, depth, color = struct.unpack(">IIBB", body[:10])
            assert color == 0 and body[12] == 0, "grayscale, non-interlaced"
        elif kind == b"IDAT":
            idat += body
        pos += 12 + length
    raw = zlib.decompress(idat)
    bpp = depth // 8
    stride = width * bpp
    rows, prev = [], bytearray(stride)
    for y in range(height):
        f = raw[y * (stride + 1)]
        line = bytearray(raw[y * (stride + 1) + 1 : (y + 1) * (stride + 1)])
        for i in range(stride):
            a = line[i - bpp] if i >= bpp else 0
            b = prev[i]
            c = prev[i - bpp] if i >= bpp else 0
            if f == 1:
                line[i] = (line[i] + a) & 0xFF
            elif f == 2:
                line[i] = (line[i] + b) & 0xFF
            elif f == 3:
                line[i] = (line[i] + (a + b) // 2) & 0xFF
            elif f == 4:
                p = a + b - c
                pa, pb, pc = abs(p - a), abs(p - b), abs(p - c)
                line[i] = (line[i] + (a if pa <= pb and pa <= pc else b if pb <= pc else c)) & 0xFF
        prev = line
        if bpp == 1:
            rows.append(list(line))
        else:
            rows.append([line[2 * i] << 8 | line[2 * i + 1] for i in range(width)])
    return width, height, rows


def gray_png(rows) -> bytes:
    """An 8-bit grayscale PNG of rows of 0..255."""
    height, width = len(rows), len(rows[0])

    def chunk(kind: bytes, body: bytes) -> bytes:
        return struct.pack(">I", len(body)) + kind + body + struct.pack(">I", zlib.crc32(kind + body))

    raw = b"".join(b"\x00" + bytes(r) for r in rows)
    return (
        b"\x89PNG\r\n\x1a\n"
        + chunk(b"IHDR", struct.pack(">IIBBBBB", width, height, 8, 0, 0, 0, 0))
        + chunk(b"IDAT", zlib.compress(raw))
        + chunk(b"IEND", b"")
    )


def npy(values, shape, descr: str, fortran: bool) -> bytes:
    text = f"{{'descr': '{descr}', 'fortran_order': {fortran}, 'shape': {tuple(shape)}, }}"
    text += " " * ((64 - (10 + len(text) + 1) % 64) % 64) + "\n"
    fmt = {"<f4": "<f", ">f8": ">d", "<f8": "<d"}[descr]
    return b"\x93NUMPY\x01\x00" + struct.pack("<H", len(text)) + text.encode() + b"".join(
        struct.pack(fmt, v) for v in values
    )


def rle_counts(width: int, height: int, inside) -> list:
    """COCO run lengths (column-major, starting with 0s) of a mask."""
    counts, current, run = [], False, 0
    for x in range(width):
        for y in range(height):
            v = inside(y, x)
            if v != current:
                counts.append(run)
                run, current = 0, v
            run += 1
    counts.append(run)
    return counts


def compress(counts: list) -> str:
    """pycocotools' rleToString."""
    out = []
    for i, c in enumerate(counts):
        x = c - counts[i - 2] if i > 2 else c
        more = True
        while more:
            ch = x & 0x1F
            x >>= 5
            more = x != -1 if ch & 0x10 else x != 0
            if more:
                ch |= 0x20
            out.append(chr(ch + 48))
    return "".join(out)


def main() -> None:
    src, out = sys.argv[1], sys.argv[2]
    os.makedirs(out, exist_ok=True)

    def seed(name: str, data: bytes) -> None:
        with open(os.path.join(out, name), "wb") as f:
            f.write(data)

    def read(name: str) -> bytes:
        return open(os.path.join(src, name), "rb").read()

    camera = json.loads(read("camera.json"))
    width, height = camera["width"], camera["height"]
    seed("camera", header(CAMERA) + read("camera.json"))
    seed("camera_fov", header(CAMERA) + json.dumps({"width": width, "height": height, "fov_x_deg": 60}).encode())
    calibrated = dict(camera, depth_calibration={"kind": "disparity", "scale": 0.5, "shift": 0.1})
    seed("camera_calibrated", header(CAMERA) + json.dumps(calibrated).encode())
    seed("depth_png", header(DEPTH_PNG) + read("depth.png"))
    seed("depth_png_calibrated", header(DEPTH_PNG | 0x80) + read("depth.png"))
    seed("masks_png", header(MASKS_PNG, width, height) + read("masks.png"))
    seed("photo", header(PHOTO, width, height) + read("image.png"))

    _, _, depth_mm = read_gray_png(os.path.join(src, "depth.png"))
    _, _, labels = read_gray_png(os.path.join(src, "masks.png"))
    # A crop around the centre keeps the npy seeds small (48 x 64).
    y0, x0, ch, cw = height // 2 - 24, width // 2 - 32, 48, 64
    crop = [[depth_mm[y][x] / 1000.0 for x in range(x0, x0 + cw)] for y in range(y0, y0 + ch)]
    c_order = [v for row in crop for v in row]
    f_order = [crop[y][x] for x in range(cw) for y in range(ch)]
    seed("depth_npy_f4", header(NPY) + npy(c_order, (ch, cw), "<f4", False))
    seed("depth_npy_f8_big", header(NPY) + npy(c_order, (ch, cw, 1), ">f8", False))
    seed("depth_npy_fortran", header(NPY | 0x80) + npy(f_order, (ch, cw), "<f8", True))

    instances = json.loads(read("instances.json"))
    seed("instances", header(INSTANCES, width, height) + read("instances.json"))
    with_rle = json.loads(json.dumps(instances))
    for k, entry in enumerate(with_rle["instances"]):
        counts = rle_counts(width, height, lambda y, x, i=entry["id"]: labels[y][x] == i)
        entry["rle"] = {"size": [height, width], "counts": compress(counts) if k % 2 == 0 else counts}
        if k == 0:
            seed("rle_compressed", header(RLE) + json.dumps(entry["rle"]).encode())
        if k == 1:
            seed("rle_list", header(RLE) + json.dumps(entry["rle"]).encode())
    seed("instances_rle", header(INSTANCES, width, height) + json.dumps(with_rle).encode())

    first = instances["instances"][0]["id"]
    mask = [[255 if labels[y][x] == first else 0 for x in range(width)] for y in range(height)]
    seed("mask_file", header(MASK_FILE, width, height) + gray_png(mask))


if __name__ == "__main__":
    main()
