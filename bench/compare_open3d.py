#!/usr/bin/env python3
"""Times `mesa lift` against the same work done with Open3D, on the same input.

The input is the synthetic benchmark scene (1024x1024 depth, 15 boxes on a table, a label mask),
written by `cargo run --release -p mesa-stages --example synthetic_scene`. The Open3D pipeline
is what a user would otherwise write: read the PNGs, `PointCloud.create_from_depth_image`, a
RANSAC table plane (`segment_plane` on the table mask's points; on the background's when no
mask is the table, as mesa fits it then), and per instance `select_by_index`,
`remove_statistical_outlier(20, 2.0)` and `get_axis_aligned_bounding_box`. Open3D runs
single-threaded (OMP_NUM_THREADS=1); mesa runs with --jobs 1 over copies of the scene, so its
process start-up is amortised but counted.

With `--m2t2 FRAME` (a folder of the M2T2 real-world sample data, e.g.
../shared/realdata/rgbd/m2t2_real/00: depth.npy in metres, rgb.png, seg.png, meta.json), the
input is that real 1280x720 frame instead: its label image with the robot's and unlisted labels
set to background, the table labelled as the support when its label is in the image, as
`stages/tests/lift_real.rs` reads it. Frame 00 has no table pixels labelled (the table is in
the background, label 0): 12 objects, and both sides fit the table plane on the background.
Before 2026-11-30 14:15 the Open3D side fitted no plane for such a frame, and the script said
"11 objects + table".

    pip install open3d numpy pillow
    python bench/compare_open3d.py [--copies 20] [--repeat 5] [--m2t2 FRAME]
    (both sides: best and median of the runs, taken in turns)
"""
import argparse, json, os, shutil, subprocess, sys, tempfile
from pathlib import Path

os.environ.setdefault("OMP_NUM_THREADS", "1")
import numpy as np  # noqa: E402
import open3d as o3d  # noqa: E402
from PIL import Image  # noqa: E402

sys.dont_write_bytecode = True  # no __pycache__ left in bench/
sys.path.insert(0, str(Path(__file__).resolve().parent))
from timing import best_median_ms, in_turns  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent


def cargo(*args):
    subprocess.run(["cargo", *args], cwd=ROOT, check=True, stdout=subprocess.DEVNULL)


# mesa's lift fits the table plane on every step-th pixel of the table mask (or background),
# the step the smallest that leaves at most this many (`PLANE_PIXELS` in stages/src/lift/mod.rs).
MESA_PLANE_PIXELS = 200_000


def open3d_lift(input_dir: Path, plane_sample: bool = False):
    """The Open3D pipeline; with `plane_sample`, the plane is fitted on the pixels mesa's lift
    fits it on (every step-th, at most MESA_PLANE_PIXELS) instead of all of them."""
    camera = json.loads((input_dir / "camera.json").read_text())
    instances = json.loads((input_dir / "instances.json").read_text())["instances"]
    if (input_dir / "depth.npy").exists():
        depth = o3d.geometry.Image(np.load(input_dir / "depth.npy").astype(np.float32))
        scale = 1.0
    else:
        depth = o3d.io.read_image(str(input_dir / "depth.png"))
        scale = 1000.0
    labels = np.asarray(Image.open(input_dir / "masks.png"))
    _photo = o3d.io.read_image(str(input_dir / "image.png"))
    intrinsic = o3d.camera.PinholeCameraIntrinsic(
        camera["width"], camera["height"], camera["fx"], camera["fy"], camera["cx"], camera["cy"])
    cloud = o3d.geometry.PointCloud.create_from_depth_image(depth, intrinsic, depth_scale=scale, depth_trunc=100.0)
    valid = np.asarray(depth).reshape(-1) > 0
    index_of_pixel = np.cumsum(valid) - 1
    flat = labels.reshape(-1)
    def fit_plane(pixels):
        if plane_sample:
            pixels = pixels[::max(1, -(-len(pixels) // MESA_PLANE_PIXELS))]
        pixels = pixels[valid[pixels]]
        cloud.select_by_index(index_of_pixel[pixels].tolist()).segment_plane(
            distance_threshold=0.005, ransac_n=3, num_iterations=400)

    boxes = {}
    for inst in instances:
        if inst.get("support"):
            fit_plane(np.nonzero(flat == inst["id"])[0])
            continue
        pixels = np.nonzero((flat == inst["id"]) & valid)[0]
        part = cloud.select_by_index(index_of_pixel[pixels].tolist())
        kept, _ = part.remove_statistical_outlier(nb_neighbors=20, std_ratio=2.0)
        boxes[inst["id"]] = kept.get_axis_aligned_bounding_box()
    if not any(inst.get("support") for inst in instances):
        # No table mask (a real frame whose labels leave the table in the background): the
        # table plane is fitted on the background, as mesa's lift does.
        fit_plane(np.nonzero(~np.isin(flat, [inst["id"] for inst in instances]))[0])
    return boxes


def m2t2_input(frame: Path, out: Path):
    """A mesa scene input from an M2T2 real frame (as stages/tests/lift_real.rs builds it)."""
    out.mkdir(parents=True)
    meta = json.loads((frame / "meta.json").read_text())
    labels = np.asarray(Image.open(frame / "seg.png").convert("L"))
    present = set(np.unique(labels).tolist())
    instances = []
    for name, label in meta["label_map"].items():
        if label == 0 or label not in present or name == "robot":
            continue
        instances.append({"id": label, "label": "table" if name == "table" else "object",
                          "support": name == "table"})
    listed = [i["id"] for i in instances]
    relabelled = np.where(np.isin(labels, listed), labels, 0).astype(np.uint8)
    Image.fromarray(relabelled).save(out / "masks.png")
    shutil.copy(frame / "depth.npy", out / "depth.npy")
    shutil.copy(frame / "rgb.png", out / "image.png")
    k = meta["intrinsics"]
    height, width = labels.shape
    (out / "camera.json").write_text(json.dumps(
        {"width": width, "height": height, "fx": k[0][0], "fy": k[1][1], "cx": k[0][2], "cy": k[1][2]}))
    (out / "instances.json").write_text(json.dumps({"instances": instances}))
    objects = sum(1 for i in instances if not i["support"])
    return width, height, objects, any(i["support"] for i in instances)


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--copies", type=int, default=20, help="scenes in the mesa dataset")
    parser.add_argument("--repeat", type=int, default=5, help="Open3D repetitions")
    parser.add_argument("--mesa", default=str(ROOT / "target/release/mesa"))
    parser.add_argument("--m2t2", help="an M2T2 real frame folder to use as the input")
    args = parser.parse_args()
    cargo("build", "--release", "-p", "mesa-pipeline")
    with tempfile.TemporaryDirectory() as tmp:
        dataset = Path(tmp) / "dataset"
        first = dataset / "scenes/office_table/office_table_0000/input"
        if args.m2t2:
            width, height, objects, table = m2t2_input(Path(args.m2t2), first)
            table = "a table mask" if table else "no table label (the table is background)"
            what = f"real M2T2 frame {args.m2t2}: {width}x{height} depth.npy, {objects} objects, {table}"
        else:
            cargo("run", "--release", "-q", "-p", "mesa-stages", "--example", "synthetic_scene", "--", str(first))
            what = "1024x1024 depth, 15 instances + table"
        for k in range(1, args.copies):
            shutil.copytree(first, dataset / f"scenes/office_table/office_table_{k:04d}/input")

        # Both sides the same way: a warm-up, then `--repeat` timed runs in turns (one of each side
        # a round, so all see the same moments of the machine); best and median.
        # The second Open3D side fits the plane on the pixels mesa fits it on (a second figure).
        cmd = [args.mesa, "lift", str(dataset), "--jobs", "1", "--force", "--progress", "off", "-q"]
        open3d_runs, sampled_runs, mesa_runs = in_turns(
            [lambda: open3d_lift(first), lambda: open3d_lift(first, plane_sample=True),
             lambda: subprocess.run(cmd, check=True)], args.repeat)
        open3d_ms, open3d_median = best_median_ms(open3d_runs)
        sampled_ms, sampled_median = best_median_ms(sampled_runs)
        mesa_ms, mesa_median = (t / args.copies for t in best_median_ms(mesa_runs))

    load = os.getloadavg()
    print(f"input: {what}; Open3D {o3d.__version__}, single-threaded; load average "
          f"{load[0]:.2f} {load[1]:.2f} {load[2]:.2f}")
    print(f"open3d: {open3d_ms:8.1f} ms per scene (best of {args.repeat}; median {open3d_median:.1f})")
    print(
        f"mesa:   {mesa_ms:8.1f} ms per scene (best of {args.repeat} runs of mesa lift --jobs 1 over "
        f"{args.copies} scenes, writes included; median {mesa_median:.1f})"
    )
    print(f"ratio:  {open3d_ms / mesa_ms:8.2f}x best to best, {open3d_median / mesa_median:.2f}x median to median")
    print(f"open3d, its plane fitted on mesa's sample of the pixels: {sampled_ms:.1f} ms (median "
          f"{sampled_median:.1f}); ratio {sampled_ms / mesa_ms:.2f}x best to best, "
          f"{sampled_median / mesa_median:.2f}x median to median")


if __name__ == "__main__":
    sys.exit(main())
