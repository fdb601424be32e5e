#!/usr/bin/env bash
# `mesa assets` over a library of N demo-sized assets (default 1,000), as one task and as T
# shards (default 4) started at once (`--shard k/T`, as the tasks of a Slurm array; the last to
# finish merges the index), each task with one worker thread. Prints the wall time of both,
# the CPU time of every task, and checks the two indexes are the same bytes.
#
#   bench/index_assets_sharded.sh [N] [T]        (needs a release build: cargo build --release)
#
# On a machine with fewer cores than T, the tasks share them: the wall time of the sharded run
# is then bounded by cores, not by T (the CPU time per task shows the split of the work).
# The copies are named by digests, as library uids are: named in cycle order (00000..., the
# 44 demo assets over and over) with T dividing 44, task k would get only the demo assets
# j = k mod T, and the costly ones all in one task.
set -euo pipefail
n="${1:-1000}"
shards="${2:-4}"
mesa="${MESA:-$(dirname "$0")/../target/release/mesa}"
work="$(mktemp -d)"
trap 'rm -rf "$work"' EXIT
"$mesa" demo "$work/demo" --scenes 1 >/dev/null 2>&1
mkdir -p "$work/one/assets/library" "$work/one/scenes"
python3 - "$work" "$n" <<'PY'
import hashlib, json, os, shutil, sys
work, n = sys.argv[1], int(sys.argv[2])
src = os.path.join(work, "demo/assets")
glbs = sorted(f[:-4] for f in os.listdir(os.path.join(src, "library")) if f.endswith(".glb"))
annotations = json.load(open(os.path.join(src, "annotations.json")))
out = {}
for i in range(n):
    uid = glbs[i % len(glbs)]
    # Library uids are digests (Objaverse's are 32 hex digits): name each copy so, so that the
    # sorted order (and with it the k mod T split) does not follow the 44-asset cycle.
    new = hashlib.md5(f"mesa bench asset {i}".encode()).hexdigest()
    shutil.copy(os.path.join(src, "library", uid + ".glb"),
                os.path.join(work, "one/assets/library", new + ".glb"))
    out[new] = annotations[uid]
json.dump(out, open(os.path.join(work, "one/assets/annotations.json"), "w"))
PY
cp -r "$work/one" "$work/sharded"
echo "cores: $(nproc); library: $n assets"
echo "one task, 1 thread:"
/usr/bin/time -f "  %e s wall, %U s user + %S s system CPU" "$mesa" assets "$work/one" --jobs 1 \
  --progress off 2>&1 | grep -E "^assets:|wall"
echo "$shards tasks at once (--shard k/$shards), 1 thread each:"
start=$(date +%s.%N)
for k in $(seq 0 $((shards - 1))); do
  /usr/bin/time -f "  task $k: %e s wall, %U s user + %S s system CPU" -o "$work/time-$k" \
    "$mesa" assets "$work/sharded" --shard "$k/$shards" --jobs 1 --progress off \
    >"$work/log-$k" 2>&1 &
done
wait
end=$(date +%s.%N)
cat "$work"/time-*
grep -h -E "^assets \(shard" "$work"/log-* | sed 's/^/  /'
echo "  all $shards tasks: $(echo "$end - $start" | bc) s wall"
if diff -r "$work/one/assets/index" "$work/sharded/assets/index" >/dev/null; then
  echo "the index of $shards tasks is the index of one task, byte for byte"
else
  echo "error: the index of $shards tasks differs from one task's" >&2
  exit 1
fi
