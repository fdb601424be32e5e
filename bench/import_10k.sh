#!/usr/bin/env bash
# The import benchmark of issue 18: `mesa import mesatask` of a synthetic release of 10,700
# scenes (bench/synthetic_release.py: 15,507 annotations, 8,225 GLBs, the features pickle) on
# 2 threads, timed with peak memory; then the same import again (nothing to write).
#   bench/import_10k.sh [WORK_DIR] [SCENES]   (default: a temporary folder, removed afterwards)
# Needs a Python with numpy ($MESA_PYTHON, default python3).
set -euo pipefail
cd "$(dirname "$0")/.."
work="${1:-$(mktemp -d)}"
[ -n "${1:-}" ] || trap 'rm -rf "$work"' EXIT
scenes="${2:-10700}"
cargo build --release -p mesa-pipeline --bin mesa
mesa="${CARGO_TARGET_DIR:-target}/release/mesa"
[ -d "$work/release/Layout_info" ] || "${MESA_PYTHON:-python3}" bench/synthetic_release.py "$work/release" "$scenes"
rm -rf "$work/dataset"
echo "== mesa import mesatask: $scenes scenes, first import, 2 threads ($(nproc) cores)"
/usr/bin/time -f "wall %e s, user %U s, sys %S s, peak memory %M kB" \
  "$mesa" import mesatask "$work/release" "$work/dataset" -j 2 --progress off
echo "== the same import again (idempotent: nothing written)"
/usr/bin/time -f "wall %e s, user %U s, sys %S s, peak memory %M kB" \
  "$mesa" import mesatask "$work/release" "$work/dataset" -j 2 --progress off
