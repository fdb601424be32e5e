#!/usr/bin/env bash
# Runs mesa's test suite. Installs what the tests need that cargo does not bring (the Khronos
# glTF validator from npm) into scripts/node_modules, once.
set -euo pipefail
cd "$(dirname "$0")/.."
if [ ! -d ../shared/realdata ] && [ -z "${MESA_SHARED:-}" ]; then
  echo "error: the tests read real data from ../shared/realdata beside this repository (or set MESA_SHARED)" >&2
  exit 2
fi
if [ -f scripts/package.json ] && [ ! -d scripts/node_modules ]; then
  (cd scripts && npm ci --no-audit --no-fund --loglevel=error)
fi
cargo test --workspace "$@"
