#!/usr/bin/env python3
"""Reads an asset annotation file (and a release's text features) the way MesaTask's retrieval
reads them, and runs its size-similarity step, so that a file mesa wrote can be checked
against the consumer it is written for.

Usage (numpy; compress_pickle for --features):

    mesatask_retrieval.py ANNOTATIONS.json [--features sbert_text_features.pkl]
        [--target-size W D H] [--query-uid UID]... [--top-k-text 20] [--top-k-final 5]
        [--text-weight 0.9] [--size-weight 0.1]

Re-implemented here from the reading logic of InternRobotics/MesaTask (as published; read in
the copy jssfinhoap22/MesaTask), not copied:

- `tools/layout2scene/retrival_object.py`, `get_bbox_dims` and
  `ObjathorRetriever.retrieve_text_size` / `get_bboxes_similarity`: the annotation file is one
  JSON object keyed by uid. An entry's size comes from `bbox` when the entry has that key:
  `bbox` itself when it has an `x` key (returned as it is), else `bbox["size"]`, else
  `bbox["max"][a] - bbox["min"][a]` for a in x, y, z; without `bbox`, from top-level
  `max_point[i] - min_point[i]` for i in 0, 1, 2 (indexed by position). Any exception there
  skips the candidate. The candidate's row is then `[size["x"], size["z"], size["y"]]` (glTF
  Y up: width, depth, height) as float32; that conversion sits outside the per-candidate
  `try`, so a size that `get_bbox_dims` returns but that has no numeric `x`/`y`/`z` (a `size`
  given as a list, a string) drops the whole query, not only that candidate. Size similarity
  is the cosine of the row with the target `[W, D, H]` (norms clamped at 1e-9), combined as
  `text_weight * text + size_weight * size` (config.yaml: 0.9, 0.1) over the `top_k_text`
  (20) best text matches; the best `top_k_final` (5) are kept.
- `tools/layout2scene/json2img.py`, `initialize_pipeline` and `perform_retrieval_processing`:
  the same annotation file is loaded a second time as a dict, and each retrieved uid is kept
  only when its entry is truthy, `entry.get("onTable", True)` is truthy, and
  `entry.get("mark_deletion", False)` and `entry.get("is_composite", False)` are falsy: Python
  truthiness, so `"onTable": "False"` (a non-empty string) keeps an asset, `"onTable": null`
  drops it, and an empty entry `{}` is dropped. This is the only place their code reads
  `onTable`, `mark_deletion` or `is_composite`; `reconstruct_blender.py`, `process_scene.py`,
  `inference.py` and the Drake optimisation (`tools/layoutopt/`) read the uids chosen, not
  the annotations.
- The text features: `compress_pickle.load(path)` of a dict with `"uids"` and
  `"text_features"` (cast to float32); the query is SBERT's encoding of the object's
  description, and the text score its dot product with each row. Neither torch nor
  sentence_transformers is needed here: `--query-uid UID` takes that asset's own row as the
  query's encoding (what SBERT gives for the description the row was made from).

Prints JSON lines:

- per uid of ANNOTATIONS, sorted: {"uid", "size" ([W, D, H] = [x, z, y] as Python floats,
  or null), "problem" (why the candidate is skipped or breaks its query, or null),
  "breaks_query" (true: the conversion to the candidate row raised, outside the per-candidate
  try), "on_table", "mark_deletion", "is_composite" (as their filter reads them), "kept"
  (passes the filter), and with --target-size "size_similarity" (float32 cosine));
- with --features, {"features": rows, "cols", "uids_without_entry": [...]} (a row whose uid
  the annotations lack is skipped by their retrieval);
- per --query-uid (with --features and --target-size), {"query_uid", "candidates" (the top
  text matches whose size reads, in order), "ranked" (uid, combined score: their top_k_final),
  "retrieved" (after the onTable / mark_deletion / is_composite filter), "status"}.

Exits 2 on bad usage or an unreadable file (the message names the file and the fix).
"""
import argparse
import json
import sys

import numpy as np


def fail(message):
    print(f"mesatask_retrieval.py: {message}", file=sys.stderr)
    sys.exit(2)


def size_dict(entry):
    """get_bbox_dims: the extents mapping MesaTask builds from one entry; raises as theirs does."""
    if "bbox" in entry:
        box = entry["bbox"]
        if "x" in box:
            return box
        if "size" in box:
            return box["size"]
        low, high = box["min"], box["max"]
        return {axis: high[axis] - low[axis] for axis in ("x", "y", "z")}
    low, high = entry["min_point"], entry["max_point"]
    return {"x": high[0] - low[0], "y": high[1] - low[1], "z": high[2] - low[2]}


def candidate_row(size):
    """The candidate's row [x, z, y]; raises TypeError where torch.tensor(..., float32) would."""
    row = [size["x"], size["z"], size["y"]]
    for value in row:
        # JSON gives int, float or bool for what torch takes as a number; anything else
        # (str, None, list, dict) makes torch.tensor raise.
        if not isinstance(value, (int, float)):
            raise TypeError(f"{type(value).__name__} {value!r} is not a number")
    return [float(v) for v in row]


def read_entry(entry):
    """One uid as their retrieval sees it: (size or None, problem, breaks_query)."""
    try:
        size = size_dict(entry)
    except Exception as e:  # their `except (KeyError, Exception): continue`
        return None, f"get_bbox_dims raised {type(e).__name__}: {e}", False
    try:
        return candidate_row(size), None, False
    except Exception as e:  # their outer `except Exception: continue` drops the query
        return None, f"the size row raised {type(e).__name__}: {e}", True


def filter_flags(entry):
    """json2img's post-retrieval filter, with Python truthiness as they test it (an entry that
    is not an object counts as dropped: a falsy one is, a truthy one makes their `.get` raise)."""
    if not isinstance(entry, dict):
        return {"on_table": False, "mark_deletion": False, "is_composite": False, "kept": False}
    on_table = bool(entry.get("onTable", True))
    marked = bool(entry.get("mark_deletion", False))
    composite = bool(entry.get("is_composite", False))
    kept = bool(entry) and on_table and not marked and not composite
    return {"on_table": on_table, "mark_deletion": marked, "is_composite": composite, "kept": kept}


def cosine_f32(target, rows):
    """get_bboxes_similarity in float32: each row's cosine with the target."""
    target = np.asarray(target, dtype=np.float32).reshape(1, -1)
    rows = np.asarray(rows, dtype=np.float32).reshape(-1, 3)
    target = target / np.maximum(np.linalg.norm(target, axis=1, keepdims=True), np.float32(1e-9))
    rows = rows / np.maximum(np.linalg.norm(rows, axis=1, keepdims=True), np.float32(1e-9))
    return (rows @ target.T)[:, 0]


def descending(scores, k):
    """torch.topk's indices for distinct scores; ties keep the lower index first."""
    order = np.argsort(-np.asarray(scores), kind="stable")
    return order[: min(k, len(order))]


def retrieve(query_uid, target, database, uids, features, args):
    """retrieve_text_size for one query, then perform_retrieval_processing's filter."""
    out = {"query_uid": query_uid, "candidates": [], "ranked": [], "retrieved": []}
    if query_uid not in uids:
        out["status"] = "the query uid has no row in the features"
        return out
    query = features[uids.index(query_uid)]
    scores = (features @ query).astype(np.float32)
    rows, candidates, text_scores = [], [], []
    for index in descending(scores, args.top_k_text):
        uid = uids[index]
        try:
            size = size_dict(database[uid])
        except Exception:
            continue
        rows.append(size)
        candidates.append(uid)
        text_scores.append(float(scores[index]))
    out["candidates"] = candidates
    if not candidates:
        out["status"] = "no candidate's size reads"
        return out
    try:
        rows = [candidate_row(size) for size in rows]
    except Exception as e:
        out["status"] = f"query dropped: a candidate's size row raised {type(e).__name__}"
        return out
    size_scores = cosine_f32(target, rows)
    text = np.asarray(text_scores, dtype=np.float32)
    combined = args.text_weight * text + args.size_weight * size_scores
    top = descending(combined, args.top_k_final)
    out["ranked"] = [[candidates[i], float(combined[i])] for i in top]
    out["retrieved"] = [
        candidates[i] for i in top if filter_flags(database.get(candidates[i]))["kept"]
    ]
    out["status"] = "ok" if out["retrieved"] else "all candidates filtered out"
    return out


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("annotations")
    parser.add_argument("--features")
    parser.add_argument("--target-size", type=float, nargs=3, metavar=("W", "D", "H"))
    parser.add_argument("--query-uid", action="append", default=[])
    parser.add_argument("--top-k-text", type=int, default=20)
    parser.add_argument("--top-k-final", type=int, default=5)
    parser.add_argument("--text-weight", type=float, default=0.9)
    parser.add_argument("--size-weight", type=float, default=0.1)
    args = parser.parse_args()
    if args.query_uid and not (args.features and args.target_size):
        fail(
            "--query-uid needs --features (the release's sbert_text_features.pkl) and "
            "--target-size W D H"
        )

    try:
        with open(args.annotations, encoding="utf-8") as f:
            database = json.load(f)
    except (OSError, ValueError) as e:
        fail(f"{args.annotations}: {e} (expected the annotation JSON object keyed by uid)")
    if not isinstance(database, dict):
        kind = type(database).__name__
        fail(f"{args.annotations}: $: a {kind} (expected a JSON object keyed by uid)")

    for uid in sorted(database):
        entry = database[uid]
        size, problem, breaks = read_entry(entry)
        line = {"uid": uid, "size": size, "problem": problem, "breaks_query": breaks}
        line.update(filter_flags(entry))
        if args.target_size and size is not None:
            line["size_similarity"] = float(cosine_f32(args.target_size, [size])[0])
        print(json.dumps(line, sort_keys=True))

    if not args.features:
        return
    try:
        import compress_pickle
    except ImportError:
        fail("compress_pickle is missing (pip install -r scripts/requirements-tools.txt)")
    try:
        loaded = compress_pickle.load(args.features)
        uids = list(loaded["uids"])
        features = np.asarray(loaded["text_features"]).astype(np.float32)
    except Exception as e:
        fail(
            f"{args.features}: {type(e).__name__}: {e} "
            "(expected a pickle of {'uids', 'text_features'})"
        )
    if features.ndim != 2 or features.shape[0] != len(uids):
        fail(
            f"{args.features}: text_features: shape {features.shape} for {len(uids)} uids "
            "(expected one row per uid)"
        )
    print(json.dumps({
        "features": len(uids),
        "cols": int(features.shape[1]),
        "uids_without_entry": sorted(u for u in uids if u not in database),
    }, sort_keys=True))
    for query_uid in args.query_uid:
        result = retrieve(query_uid, args.target_size, database, uids, features, args)
        print(json.dumps(result, sort_keys=True))


if __name__ == "__main__":
    main()
