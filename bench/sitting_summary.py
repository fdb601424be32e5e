#!/usr/bin/env python3
"""The table of one sitting of bench/sitting.sh: for each target of issue #23, each run's ratio
(peer time / mesa time) on the minima and, in brackets, on the medians, the target, and whether
every run meets it (on the minima). A run whose output lacks the line the table needs shows
"missing" and counts as not met: a failed script is never read as a pass.

    python3 bench/sitting_summary.py OUT_DIR
"""
import re
import sys
from pathlib import Path

def read(path: Path) -> str:
    try:
        return path.read_text(errors="replace")
    except OSError:
        return ""


def find(text: str, pattern: str):
    """The groups of the first match of `pattern` in `text`, as floats; None without one."""
    match = re.search(pattern, text, re.MULTILINE)
    return tuple(float(g) for g in match.groups()) if match else None


def section(text: str, start: str, end: str) -> str:
    """The text from the first `start` to the next `end` after it (to the end without one)."""
    at = text.find(start)
    if at < 0:
        return ""
    stop = text.find(end, at + len(start))
    return text[at:] if stop < 0 else text[at:stop]


def runs(out: Path, stem: str):
    return sorted(out.glob(f"{stem}_*.txt"), key=lambda p: int(p.stem.rsplit("_", 1)[1]))


RATIO = {
    "open3d": r"^ratio:\s+([\d.]+)x best to best, ([\d.]+)x median to median",
    "open3d_sampled": r"^open3d, its plane fitted on mesa's sample.*ratio ([\d.]+)x best to best, "
                      r"([\d.]+)x median to median",
    "blender": r"^ratio \(Blender / mesa\): ([\d.]+)x on the minima, ([\d.]+)x on the medians",
    "graph": r"ratio python / mesa: ([\d.]+)x min to min, ([\d.]+)x median to median",
}


def targets(out: Path):
    """(what, [(ratio on the minima, ratio on the medians or None) or None per run], goal)."""
    rows = []
    for stem, what in (("open3d_syn", "lift, 1024² synthetic, as a stage"),
                       ("open3d_m2t2", "lift, real M2T2 frame, as a stage")):
        rows.append((what, [find(read(p), RATIO["open3d"]) for p in runs(out, stem)], 10.0))
        rows.append((f"{what} (Open3D's plane on mesa's sample of the pixels)",
                     [find(read(p), RATIO["open3d_sampled"]) for p in runs(out, stem)], 10.0))
    rows.append(("render, 512² view, one thread",
                 [find(read(p), RATIO["blender"]) for p in runs(out, "blender")], 100.0))
    rows.append(("pack, 15 objects",
                 [find(read(p), RATIO["blender"]) for p in runs(out, "pack")], 100.0))
    graphs = [read(p) for p in runs(out, "graph")]
    rows.append(("graph, in process",
                 [find(section(t, "a. in process", "\nb"), RATIO["graph"]) for t in graphs], 100.0))
    rows.append(("graph as a dataset stage (wall)",
                 [find(section(t, "b. dataset stage, wall", "\nb"), RATIO["graph"]) for t in graphs],
                 20.0))
    fcl = read(out / "fcl.txt")
    query = find(fcl, r"^the query alone .*: mesa ([\d.]+)x faster")
    scene = find(fcl, r"mesa's whole check ([\d.]+)x faster than FCL")
    rows.append(("check, the query against FCL's", [query and (query[0], None)], 1.0))
    rows.append(("check, a scene from cached parts", [scene and (scene[0], None)], 50.0))
    return rows


def mesa_run(out: Path):
    text = read(out / "run100.txt")
    runs_s = [float(s) for s in re.findall(r"^run \d+: ([\d.]+) s wall", text, re.MULTILINE)]
    reruns_s = [float(s) for s in re.findall(r"^rerun \d+: ([\d.]+) s wall", text, re.MULTILINE)]
    return runs_s, reruns_s


def cell(ratio):
    if ratio is None:
        return "missing"
    low, median = ratio
    return f"{low:.1f}×" + ("" if median is None else f" ({median:.1f}×)")


def main():
    out = Path(sys.argv[1]) if len(sys.argv) > 1 else sys.exit(__doc__)
    log = read(out / "sitting.log").splitlines()
    if log:
        print(f"sitting: {log[0]} … {log[-1]}")
        print("(each line of sitting.log: time, load averages over 1, 5 and 15 minutes, step)\n")
    print("| target | runs: ratio on the minima (medians) | goal | met in every run |")
    print("|---|---|---|---|")
    unmet = 0
    for what, ratios, goal in targets(out):
        met = bool(ratios) and all(r is not None and r[0] >= goal for r in ratios)
        unmet += not met
        shown = ", ".join(cell(r) for r in ratios) or "missing"
        print(f"| {what} | {shown} | ≥ {goal:g}× | {'yes' if met else 'no'} |")
    runs_s, reruns_s = mesa_run(out)
    per_scene = [s / 100 for s in runs_s]
    met = bool(runs_s) and all(s <= 0.15 for s in per_scene) and bool(reruns_s) and all(
        s < 1.0 for s in reruns_s)
    unmet += not met
    shown = (", ".join(f"{s:.3f}" for s in per_scene) + " s a scene; reruns "
             + ", ".join(f"{s:.2f}" for s in reruns_s) + " s") if runs_s else "missing"
    print(f"| `mesa run`, 100 demo scenes | {shown} | ≤ 0.15 s a scene, rerun < 1 s | "
          f"{'yes' if met else 'no'} |")
    print(f"\n{unmet} target(s) not met in every run.")
    # Not a target: the floor under the graph stage's figure (compare_graph.py's section c).
    bare = [find(section(read(p), "c. the stage's work in a bare Rust loop, wall", "\nc"),
                 r"ratio python / bare loop: ([\d.]+)x min to min, ([\d.]+)x median to median")
            for p in runs(out, "graph")]
    runner = [find(section(read(p), "c. what mesa's runner adds", "\nc"),
                   r"ratio mesa / bare loop: ([\d.]+)x min to min, ([\d.]+)x median to median")
              for p in runs(out, "graph")]
    if any(bare):
        print("graph, the stage's work in a bare loop without the runner (the floor under the "
              "stage's figure; no target): python / bare loop " + ", ".join(cell(r) for r in bare)
              + "; mesa graph / bare loop " + ", ".join(cell(r) for r in runner))


if __name__ == "__main__":
    main()
