#!/usr/bin/env bash
# Renders one 512x512 front view of a 15-object demo scene (dressing_table_0001 of
# `mesa demo --seed 7`, its true layout) with `mesa render` and with Blender (Workbench by
# default, or ENGINE=EEVEE / CYCLES), both on the CPU, and prints the time of each and the
# ratio. mesa is timed by stages/examples/render_timing.rs (the view alone, assets loaded), on one
# thread; Blender by bench/render_blender.py (the render call alone, after a first render that
# compiles its shaders), with one OpenMP and one llvmpipe thread. Blender's picture is written
# beside mesa's for comparison.
#
# Both sides are timed the same way: one warm-up render each, then REPEAT (default 5) turns,
# each running Blender untimed for 0.3 s at least (one render) and then one timed render, then
# the same of mesa's (stages/examples/render_timing.rs --serve: about 36 untimed views, then
# one timed; each view with its scene's shadow map, PNG encoded, on one thread). Taking turns,
# both sides see the same moments of the machine, whose speed moves for seconds at a time; the
# untimed runs put each back in its steady state after the other's turn (bench/timing.py). The
# script prints min and median of each side, the ratio of each, the load average and the CPU.
#
#   bench/compare_blender.sh [OUT_DIR]
#   RENDER_TIMING=/path/to/render_timing bench/compare_blender.sh [OUT_DIR]   (another build's)
#
# Needs: a release build (cargo build --release), Blender as a Python module in a virtualenv
# (python3 -m venv .venv-blender && .venv-blender/bin/pip install "bpy==4.3.0" "numpy<2"; or
# MESA_BLENDER_PYTHON pointing at one; scripts/test.sh makes it). Headless Workbench and Eevee
# draw through EGL with Mesa's software OpenGL (llvmpipe) when there is no GPU.
set -euo pipefail
root="$(cd "$(dirname "$0")/.." && pwd)"
out="${1:-$(mktemp -d)}"
mesa="${MESA:-$root/target/release/mesa}"
python="${MESA_BLENDER_PYTHON:-$root/.venv-blender/bin/python}"
engine="${ENGINE:-WORKBENCH}"
scene_rel="scenes/dressing_table/dressing_table_0001"
mkdir -p "$out"
ws="$out/demo"
"$mesa" demo "$ws" --scenes 5 --seed 7 -q
"$mesa" assets "$ws" -q
"$mesa" render "$ws" --layout truth --scenes dressing_table_0001 --progress off -q
cp "$ws/$scene_rel/render/front.png" "$out/mesa_front.png"

repeat="${REPEAT:-5}"
# RENDER_TIMING: a render_timing binary built elsewhere (an older commit's, copied aside), to
# compare two versions against the same Blender on one machine; by default this tree's.
timing="${RENDER_TIMING:-}"
if [ -z "$timing" ]; then
  (cd "$root" && cargo build --release -q -p mesa-stages --example render_timing)
  timing="$root/target/release/examples/render_timing"
fi
load_before="$(cut -d' ' -f1 /proc/loadavg)"
# The two sides take turns (render_blender.py --alternate), REPEAT times.
RAYON_NUM_THREADS=1 OMP_NUM_THREADS=1 LP_NUM_THREADS=1 "$python" "$root/bench/render_blender.py" \
  "$ws/$scene_rel" "$ws/assets/library" truth/layout.json "$out/blender_front.png" \
  --engine "$engine" --repeat "$repeat" --alternate "'$timing' --serve" 2>/dev/null \
  | grep '^{' > "$out/blender.json"
load_after="$(cut -d' ' -f1 /proc/loadavg)"
python3 - "$out/blender.json" "$engine" "$load_before" "$load_after" <<'PY'
import json, os, statistics, sys
blender = json.load(open(sys.argv[1]))
mesa = blender["alternate_runs_s"]
# Blender's first render compiles its shaders: the warm-up, as mesa's untimed first view.
b = blender["renders_s"][1:]
cpu = next((l.split(":", 1)[1].strip() for l in open("/proc/cpuinfo")
            if l.startswith("model name")), "unknown CPU")
print(f"{cpu}, {os.cpu_count()} CPUs, load average {sys.argv[3]} before, {sys.argv[4]} after; "
      f"{len(mesa)} timed renders a side in turns, each after 0.3 s of untimed ones, one thread")
print(f"mesa:    min {min(mesa) * 1e3:.1f} ms, median {statistics.median(mesa) * 1e3:.1f} ms")
print(f"Blender ({sys.argv[2]}): min {min(b) * 1e3:.0f} ms, median {statistics.median(b) * 1e3:.0f} ms "
      f"(CPU, median {blender['median_render_cpu_s'] * 1e3:.0f} ms)")
print(f"ratio (Blender / mesa): {min(b) / min(mesa):.0f}x on the minima, "
      f"{statistics.median(b) / statistics.median(mesa):.0f}x on the medians")
PY
echo "pictures: $out/mesa_front.png $out/blender_front.png"
