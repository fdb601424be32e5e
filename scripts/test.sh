#!/usr/bin/env bash
# Runs mesa's test suite. First installs, once, what the tests need that cargo does not bring:
#   - a Python virtualenv with trimesh (PLY files are checked with it; with python-fcl, rtree
#     and scipy it is the exact-mesh reference of `mesa check`; mujoco drops the checked
#     scenes), datasets (the training records are loaded with it, as LLaMA-Factory and TRL
#     do) and shapely (with numpy, the Python scene-graph rules that `mesa graph` is compared
#     with): .venv-tools/
#   - Blender 4.3 as a Python module (bpy, numpy<2) in its own virtualenv: .venv-blender/
#   - from npm, the Khronos glTF validator (every GLB we write is validated) and gltf-transform
#     (KHR_mesh_quantization and Draco test files): scripts/node_modules/
# Extra arguments go to `cargo test`.
set -euo pipefail
cd "$(dirname "$0")/.."
root="$(pwd)"
if [ ! -d ../shared/realdata ] && [ -z "${MESA_SHARED:-}" ]; then
  echo "error: the tests read real data from ../shared/realdata beside this repository (or set MESA_SHARED)" >&2
  exit 2
fi

venv="$root/.venv-tools"
if [ ! -x "$venv/bin/python" ] || ! "$venv/bin/python" -c "import trimesh, numpy, datasets, fcl, rtree, scipy, mujoco, compress_pickle, pybullet, pxr, PIL, shapely" 2>/dev/null; then
  echo "test.sh: installing trimesh and datasets into $venv" >&2
  python3 -m venv "$venv"
  "$venv/bin/pip" install --quiet --disable-pip-version-check --no-cache-dir -r scripts/requirements-tools.txt
fi
export MESA_PYTHON="$venv/bin/python"

# Blender 4.3 as a Python module, in its own virtualenv with numpy<2 (as MesaTask pins it).
blender_venv="$root/.venv-blender"
if [ ! -x "$blender_venv/bin/python" ] || ! "$blender_venv/bin/python" -c "import bpy" 2>/dev/null; then
  echo "test.sh: installing bpy 4.3 into $blender_venv (about 380 MB)" >&2
  python3 -m venv "$blender_venv"
  "$blender_venv/bin/pip" install --quiet --disable-pip-version-check --no-cache-dir "bpy==4.3.0" "numpy<2"
fi
export MESA_BLENDER_PYTHON="$blender_venv/bin/python"

if [ -f scripts/package.json ]; then
  if [ ! -d scripts/node_modules ] || [ scripts/package-lock.json -nt scripts/node_modules ]; then
    echo "test.sh: installing the npm packages of scripts/package.json" >&2
    (cd scripts && npm ci --no-audit --no-fund --loglevel=error)
  fi
fi

cargo test --workspace "$@"
