#!/usr/bin/env bash
# Renders one 512x512 front view of a 15-object demo scene (dressing_table_0001 of
# `mesa demo --seed 7`, its true layout) with `mesa render` and with Blender (Workbench by
# default, or ENGINE=EEVEE / CYCLES), both on the CPU, and prints the time of each and the
# ratio. mesa is timed by its criterion bench (the view alone, assets loaded), run here on one
# thread; Blender by bench/render_blender.py (the render call alone, after a first render that
# compiles its shaders), with one OpenMP and one llvmpipe thread. Blender's picture is written
# beside mesa's for comparison.
#
#   bench/compare_blender.sh [OUT_DIR]
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

echo "mesa (criterion, one thread):"
(cd "$root" && RAYON_NUM_THREADS=1 cargo bench -q -p mesa-stages --bench render -- \
  'render/front_512_15_objects$' 2>/dev/null | grep -E "time:" | head -1)

echo "Blender ($engine):"
OMP_NUM_THREADS=1 LP_NUM_THREADS=1 "$python" "$root/bench/render_blender.py" "$ws/$scene_rel" \
  "$ws/assets/library" truth/layout.json "$out/blender_front.png" --engine "$engine" \
  --repeat 5 2>/dev/null | grep '^{' | tee "$out/blender.json"
echo "pictures: $out/mesa_front.png $out/blender_front.png"
