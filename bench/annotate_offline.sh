#!/usr/bin/env bash
# The offline backend of `mesa annotate assets` against the demo's own annotations:
# retrieval on the demo with the annotations removed and replaced by the offline placeholder,
# and a control with the asset names withheld (size only). Prints the category match rates.
# Usage: bench/annotate_offline.sh [MESA_BINARY] (default: target/debug/mesa)
set -euo pipefail
mesa=${1:-target/debug/mesa}
here=$(cd "$(dirname "$0")" && pwd)
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
"$mesa" demo "$work/demo" >/dev/null
"$mesa" assets "$work/demo" --progress off >/dev/null 2>&1 || true
"$mesa" lift "$work/demo" --progress off >/dev/null 2>&1 || true
mv "$work/demo/assets/annotations.json" "$work/original.json"
cp -r "$work/demo" "$work/control"
time "$mesa" annotate assets "$work/demo" --progress off
"$mesa" assets "$work/demo" --progress off >/dev/null 2>&1 || true
"$mesa" retrieve "$work/demo" --progress off >/dev/null
python3 "$here/annotate_retrieval_match.py" "$work/demo" "$work/original.json" | head -1
# The control: the same placeholder with every name withheld.
"$mesa" annotate assets "$work/control" --progress off >/dev/null
python3 - "$work/control/assets/annotations.json" <<'PY'
import json, re, sys
path = sys.argv[1]
entries = json.load(open(path))
for entry in entries.values():
    size = re.search(r"about ([0-9 x]+) cm", entry["description"]).group(1)
    entry["description"] = f"object, about {size} cm (placeholder, names withheld)"
    entry["category"] = "object"
json.dump(entries, open(path, "w"), indent=1, sort_keys=True)
PY
"$mesa" assets "$work/control" --progress off >/dev/null 2>&1 || true
"$mesa" retrieve "$work/control" --progress off >/dev/null
python3 "$here/annotate_retrieval_match.py" "$work/control" "$work/original.json" | head -1
