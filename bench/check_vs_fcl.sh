#!/usr/bin/env bash
# `mesa check` against trimesh's CollisionManager (python-fcl) on the same convex parts: the
# `mesa demo` scene with the number of objects closest to 15 (its true layout), shapes from
# `mesa assets`. mesa is timed by the criterion bench (`stages/benches/check.rs`: the query on
# parts placed beforehand; every part placed by the layout, then the query; the whole check),
# FCL by bench/check_vs_fcl.py: the query alone on BVHs built and scaled beforehand (the
# counterpart of mesa's query on placed parts), and one scene from the cached parts (scale,
# build, query), the counterpart of mesa placing and querying: a scale factor differs per
# scene. Both sides report medians. The script prints each figure, the ratios, the machine
# and the load average.
#
#   bench/check_vs_fcl.sh [DIR]     (DIR: where the demo dataset goes; default a temp folder)
#
# Needs a Python with trimesh, numpy, scipy, networkx (trimesh's fix_normals) and python-fcl:
#   python3 -m venv /work/venv-check
#   /work/venv-check/bin/pip install trimesh numpy scipy networkx python-fcl
# (CHECK_BENCH_PYTHON chooses another interpreter.)
set -euo pipefail
root="$(cd "$(dirname "$0")/.." && pwd)"
python="${CHECK_BENCH_PYTHON:-/work/venv-check/bin/python}"
target="${CARGO_TARGET_DIR:-$root/target}"
work="${1:-}"
if [ -z "$work" ]; then
  work="$(mktemp -d)"
  trap 'rm -rf "$work"' EXIT
fi
(cd "$root" && cargo build --release -q)
mesa="$target/release/mesa"
"$mesa" demo "$work/demo" --scenes 6 -q
"$mesa" assets "$work/demo" --progress off -q >/dev/null
layout="$(python3 - "$work/demo" <<'PY'
import glob, json, sys
best = min(glob.glob(sys.argv[1] + "/scenes/*/*/truth/layout.json"),
           key=lambda p: (abs(len(json.load(open(p))["objects"]) - 15), p))
print(best)
PY
)"
echo "scene: $layout"
(cd "$root" && MESA_CHECK_BENCH_DATASET="$work/demo" MESA_CHECK_BENCH_LAYOUT="$layout" \
  cargo bench -q -p mesa-stages --bench check 2>&1 | grep -E "check bench|^check/|time:")
fcl="$("$python" "$root/bench/check_vs_fcl.py" "$work/demo" "$layout")"
echo "fcl: $fcl"
python3 - "$target/criterion" "$fcl" <<'PY'
import json, os, sys
crit, fcl = sys.argv[1], json.loads(sys.argv[2])
def median_s(name):
    return json.load(open(f"{crit}/check/{name}/new/estimates.json"))["median"]["point_estimate"] / 1e9
ours_c, ours_q, ours_f = median_s("collisions"), median_s("collisions_placed"), median_s("full")
cpu = next((l.split(":", 1)[1].strip() for l in open("/proc/cpuinfo")
            if l.startswith("model name")), "?")
print(f"machine: {cpu}, {os.cpu_count()} cores, load average {open('/proc/loadavg').read().split()[0]}")
print(f"mesa, colliding pairs with depth, parts placed beforehand: {ours_q * 1e3:.4f} ms a scene")
print(f"mesa, placing every part and finding the colliding pairs:  {ours_c * 1e3:.4f} ms a scene")
print(f"mesa, the whole check.json (placing included):             {ours_f * 1e3:.4f} ms a scene")
print(f"FCL in_collision_internal (setting the transforms included): {fcl['fcl_collisions_s'] * 1e3:.4f} ms "
      f"({fcl['objects']} objects, {fcl['triangles']} triangles; BVHs built and scaled beforehand)")
print(f"FCL min_distance_internal:               {fcl['fcl_min_distance_s'] * 1e3:.4f} ms")
print(f"FCL, one scene from the cached parts:    {fcl['fcl_scene_from_cache_s'] * 1e3:.3f} ms "
      f"(scale, build the BVHs, in_collision_internal)")
print(f"the query alone (mesa's parts placed, FCL's trees built beforehand): mesa "
      f"{fcl['fcl_collisions_s'] / ours_q:.1f}x faster")
print(f"FCL's query alone against mesa placing and querying: mesa {fcl['fcl_collisions_s'] / ours_c:.2f}x "
      f"(below 1: FCL faster)")
print(f"a scene from cached shapes: mesa's collisions {fcl['fcl_scene_from_cache_s'] / ours_c:.0f}x, "
      f"mesa's whole check {fcl['fcl_scene_from_cache_s'] / ours_f:.0f}x faster than FCL")
PY
