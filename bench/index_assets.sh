#!/usr/bin/env bash
# Times `mesa assets` on a library of N demo-sized assets (default 1,000) with J threads
# (default 2): the 44 procedural assets of `mesa demo`, copied under N distinct uids (every
# copy is indexed on its own: records are per uid), their annotations likewise.
#
#   bench/index_assets.sh [N] [J]        (needs a release build: cargo build --release)
set -euo pipefail
n="${1:-1000}"
jobs="${2:-2}"
mesa="${MESA:-$(dirname "$0")/../target/release/mesa}"
work="$(mktemp -d)"
trap 'rm -rf "$work"' EXIT
"$mesa" demo "$work/demo" --scenes 1 >/dev/null 2>&1
mkdir -p "$work/lib/assets/library" "$work/lib/scenes"
python3 - "$work" "$n" <<'PY'
import json, os, shutil, sys
work, n = sys.argv[1], int(sys.argv[2])
src = os.path.join(work, "demo/assets")
glbs = sorted(f[:-4] for f in os.listdir(os.path.join(src, "library")) if f.endswith(".glb"))
annotations = json.load(open(os.path.join(src, "annotations.json")))
out = {}
for i in range(n):
    uid = glbs[i % len(glbs)]
    new = f"{i:05d}{uid[5:]}"
    shutil.copy(os.path.join(src, "library", uid + ".glb"),
                os.path.join(work, "lib/assets/library", new + ".glb"))
    out[new] = annotations[uid]
json.dump(out, open(os.path.join(work, "lib/assets/annotations.json"), "w"))
PY
echo "indexing $n assets with $jobs threads:"
/usr/bin/time -f "%e s wall, %U s user, %M kB peak" "$mesa" assets "$work/lib" --jobs "$jobs" \
  --progress off 2>&1 | grep -E "^assets:|wall"
du -sh "$work/lib/assets/index" | sed 's/^/index size: /'
echo "rerun (nothing changed):"
"$mesa" assets "$work/lib" --jobs "$jobs" --progress off 2>&1 | grep -E "^assets:"
