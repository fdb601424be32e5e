"""`mesa annotate assets` offline backend, measured: retrieval on a demo dataset against the truth: for every demo instance, is the chosen
asset's true category (from the original annotations) the instance's true category, and is it
the true uid? Usage: measure_retrieval.py DATASET ORIGINAL_ANNOTATIONS"""
import json, sys, glob, os
ds, orig = sys.argv[1], json.load(open(sys.argv[2]))
n = cat_ok = uid_ok = 0
misses = []
for rpath in sorted(glob.glob(f"{ds}/scenes/*/*/coarse/retrieval.json")):
    scene = os.path.dirname(os.path.dirname(rpath))
    truth = {t["id"]: t for t in json.load(open(f"{scene}/truth/instances.json"))["instances"]}
    for inst in json.load(open(rpath))["instances"]:
        t = truth.get(inst.get("mask_id", inst.get("id")))
        if t is None or t.get("support"):
            continue
        chosen = inst.get("chosen")
        n += 1
        got = orig.get(chosen, {}).get("category")
        if got == t["category"]:
            cat_ok += 1
        else:
            misses.append((os.path.basename(scene), t["label"], t["category"], got))
        uid_ok += chosen == t["uid"]
print(f"{ds}: {n} instances: category match {cat_ok}/{n} = {cat_ok/n:.3f}; same uid as truth {uid_ok}/{n} = {uid_ok/n:.3f}")
for m in misses[:40]:
    print("  miss", *m, flush=True)
