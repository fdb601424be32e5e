#!/usr/bin/env bash
# Times `mesa export` on N demo scenes (default 100) with J threads (default 2): the coarse
# layouts of `mesa demo` → assets → lift → retrieve → place, exported as MJCF, URDF and USD.
# Prints the wall time, the time per scene, the size on disk of sim/ and the largest scene.
#
#   bench/export_scenes.sh [N] [J]        (needs a release build: cargo build --release)
set -euo pipefail
n="${1:-100}"
jobs="${2:-2}"
mesa="${MESA:-$(dirname "$0")/../target/release/mesa}"
work="$(mktemp -d)"
trap 'rm -rf "$work"' EXIT
"$mesa" demo "$work/d" --scenes "$n" --seed 11 -q >/dev/null 2>&1
for stage in assets lift retrieve place; do
  "$mesa" "$stage" "$work/d" --jobs "$jobs" --progress off -q >/dev/null 2>&1
done
objects=$(cat "$work"/d/scenes/*/*/coarse/layout.json | grep -c '"instance"')
echo "exporting $n scenes ($objects objects) with $jobs threads:"
/usr/bin/time -f "%e s wall, %U s user, %S s system, %M kB peak" "$mesa" export "$work/d" \
  --layout coarse --jobs "$jobs" --progress off 2>&1 | grep -E "^export|wall"
du -sh "$work"/d/scenes/*/*/sim | sort -h | tail -1 | sed 's/^/largest scene: /'
du -cb "$work"/d/scenes/*/*/sim | tail -1 | awk -v n="$n" \
  '{printf "sim/ on disk: %.1f MB in all, %.2f MB per scene\n", $1/1e6, $1/1e6/n}'
for f in mjcf urdf usd textures; do
  du -cb "$work"/d/scenes/*/*/sim/$f | tail -1 | awk -v f="$f" '{printf "  %s: %.1f MB\n", f, $1/1e6}'
done
echo "rerun (nothing changed):"
/usr/bin/time -f "%e s wall" "$mesa" export "$work/d" --layout coarse --jobs "$jobs" \
  --progress off 2>&1 | grep -E "^export:|wall"
