#!/usr/bin/env bash
# The records benchmark of issue 9: `mesa records` over 10,000 synthetic scenes × 5 template
# tasks, timed with peak memory (and over 1,000 scenes, to show the memory stays flat).
#   bench/records_10k.sh [WORK_DIR]   (default: a temporary folder, removed afterwards)
set -euo pipefail
cd "$(dirname "$0")/.."
work="${1:-$(mktemp -d)}"
[ -n "${1:-}" ] || trap 'rm -rf "$work"' EXIT
cargo build --release -p mesa-pipeline --bin mesa --example synthetic_records_dataset
target="${CARGO_TARGET_DIR:-target}/release"
for scenes in 1000 10000; do
  dataset="$work/records-$scenes"
  if [ ! -d "$dataset/scenes" ]; then
    "$target/examples/synthetic_records_dataset" "$dataset" "$scenes" 1
  fi
  echo "== mesa records over $scenes scenes ($(nproc) cores)"
  /usr/bin/time -f "wall %e s, peak memory %M kB" \
    "$target/mesa" records "$dataset" --force --progress off
  du -sh "$dataset/records"
done
