#!/usr/bin/env bash
# Compares mesa's convex parts with V-HACD and CoACD on ../shared/realdata/glb: builds what the
# bench needs, makes .venv-bench if it is missing, runs bench/compare_decomposition.py (extra
# arguments are passed on) and leaves results.json under target/bench-decomposition.
set -euo pipefail
cd "$(dirname "$0")/.."
if [ ! -x .venv-bench/bin/python ]; then
  python3 -m venv .venv-bench
  .venv-bench/bin/pip install trimesh numpy scipy rtree vhacdx coacd
fi
cargo build --release -p mesa-pipeline --bin mesa
cargo build --release -p mesa-stages --example table_mesh
exec .venv-bench/bin/python bench/compare_decomposition.py "$@"
