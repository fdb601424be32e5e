#!/usr/bin/env bash
# One sitting of issue #23's speed comparisons: every script of bench/ that compares mesa with
# the tool a user would otherwise run, ROUNDS times in a row (default 3: each round runs every
# script once, so the rounds interleave with whatever else the machine does; within a script,
# the two sides take turns run by run: bench/timing.py), then `mesa run`
# over 100 demo scenes and a rerun ROUNDS times, then bench/check_vs_fcl.sh once. Each
# script's output is kept in OUT_DIR; bench/sitting_summary.py reads them and prints one table:
# each target, each run's ratio (minima, and medians), the load averages, and whether the
# target is met in every run.
#
#   bench/sitting.sh OUT_DIR [GRAPH_DATASET]
#
# GRAPH_DATASET: a dataset whose stages up to `graph` have run (bench/compare_graph.py makes a
# 1,000-scene one when it is left out, which takes a few minutes a round; give it once made).
# Environment: ROUNDS (3), PYTHON (a Python with open3d numpy pillow shapely trimesh scipy
# networkx python-fcl; /work/benchvenv/bin/python), BLENDER_PYTHON (.venv-blender/bin/python),
# M2T2_FRAME (../shared/realdata/rgbd/m2t2_real/00). docs/performance.md says how to make the
# virtualenvs.
set -euo pipefail
root="$(cd "$(dirname "$0")/.." && pwd)"
out="${1:?usage: bench/sitting.sh OUT_DIR [GRAPH_DATASET]}"
dataset="${2:-}"
rounds="${ROUNDS:-3}"
py="${PYTHON:-/work/benchvenv/bin/python}"
blender_py="${BLENDER_PYTHON:-$root/.venv-blender/bin/python}"
frame="${M2T2_FRAME:-$root/../shared/realdata/rgbd/m2t2_real/00}"
mkdir -p "$out"
out="$(cd "$out" && pwd)"
cd "$root"
cargo build --release -q -p mesa-pipeline --bins --examples
cargo build --release -q -p mesa-stages --examples
mesa="$root/target/release/mesa"

stamp() { echo "$(date -u +%FT%TZ) $(cut -d' ' -f1-3 /proc/loadavg) $*" | tee -a "$out/sitting.log"; }

# The machine, with the commit: the ratios move with the CPU (docs/performance.md gives sittings
# on an AMD EPYC and an Intel Xeon).
machine="$(grep -m1 '^model name' /proc/cpuinfo | cut -d: -f2- | sed 's/^ *//'), $(nproc) CPUs, Linux $(uname -r)"
stamp "start: $(git rev-parse --short HEAD)$(git diff --quiet || echo ' (uncommitted changes)') on $machine"
for i in $(seq 1 "$rounds"); do
  stamp "round $i: lift, synthetic"
  "$py" bench/compare_open3d.py > "$out/open3d_syn_$i.txt" 2>&1
  stamp "round $i: lift, real frame"
  "$py" bench/compare_open3d.py --m2t2 "$frame" > "$out/open3d_m2t2_$i.txt" 2>&1
  stamp "round $i: render"
  REPEAT=10 MESA_BLENDER_PYTHON="$blender_py" bench/compare_blender.sh "$out/blender_$i" \
    > "$out/blender_$i.txt" 2>&1
  stamp "round $i: pack"
  "$blender_py" bench/compare_blender_pack.py --repeat 7 > "$out/pack_$i.txt" 2>&1
  stamp "round $i: graph"
  # shellcheck disable=SC2086
  "$py" bench/compare_graph.py $dataset --repeat 5 > "$out/graph_$i.txt" 2>&1
done

stamp "mesa run, 100 demo scenes"
work="$(mktemp -d)"
trap 'rm -rf "$work"' EXIT
"$mesa" demo "$work/demo" --scenes 100 --seed 3 -q
: > "$out/run100.txt"
for i in $(seq 1 "$rounds"); do
  rm -rf "$work/run" && cp -r "$work/demo" "$work/run"
  echo "load average $(cut -d' ' -f1-3 /proc/loadavg)" >> "$out/run100.txt"
  /usr/bin/time -f "run $i: %e s wall, %U s user, %S s system" \
    "$mesa" run "$work/run" --progress off -q > /dev/null 2>> "$out/run100.txt"
  /usr/bin/time -f "rerun $i: %e s wall" \
    "$mesa" run "$work/run" --progress off -q > /dev/null 2>> "$out/run100.txt"
done

stamp "check against FCL"
CHECK_BENCH_PYTHON="$py" bench/check_vs_fcl.sh > "$out/fcl.txt" 2>&1
stamp "done"
python3 bench/sitting_summary.py "$out" | tee "$out/summary.md"
