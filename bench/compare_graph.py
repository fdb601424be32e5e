#!/usr/bin/env python3
"""Times mesa's scene-graph stage against the same rules written in Python, on the same dataset.

The Python side is bench/graph_rules.py: SCENE_GRAPH.md as a user would write it without mesa
(numpy for the pairwise quantities, shapely for the rotated-rectangle intersections), reading the
same layouts and writing the same graph.txt and graph.json. Before timing, every scene's
graph.txt from Python is checked against mesa's, byte for byte (graph.json too: same bytes, or
else the same structure with numbers equal within 1e-9).

Three comparisons, every side timed the same way: a warm-up, then `--repeat` timed runs; the
min and the median over the runs, in ms per scene, and the ratio python / mesa of each. The
sides of a comparison take turns run by run (a Python pass, a mesa pass, ...; in b and c one
process of each in turn), so that both see the same moments of the machine, whose speed moves
for seconds at a time, and each timed run comes after untimed runs of its own side for 0.3 s
(bench/timing.py; in b', whose runs create every file, after one untimed run of each side at
the start only):

  a. in process: the layouts already parsed and the container flags decided, the graph of
     every scene extracted and its text produced, no file I/O. mesa: the example
     stages/examples/graph_timing.rs --serve (extract_graph + to_text; mimalloc, the mesa
     executable's allocator), built here if missing. Python:
     graph_rules.extract_graph + graph_text.
  b. as a dataset stage, whole processes timed from outside: `mesa graph DATASET --force
     --jobs 1` (reads every layout and the annotations, writes graph.json, graph.txt and the
     done markers) vs `python bench/graph_rules.py dataset DATASET --out DIR` (the same reads,
     graph.json and graph.txt written under a separate folder DIR, so mesa's outputs and
     markers are not touched). Process start-up (for Python, importing numpy and shapely) is
     counted on both sides, and printed on its own. Wall time, and the CPU time (user +
     system) of the same runs, which other work on the machine disturbs less. b' is the same
     with the outputs (and mesa's markers) removed before each run, so both sides create
     every file.
  c. the floor under b: the stage's work for each scene in a bare Rust loop, without the
     runner (pipeline/examples/graph_bare.rs, built here if missing): the layout read, the
     graph extracted, graph.json and graph.txt made and compared with the files there (what
     a forced `mesa graph` does before it leaves a file alone), with no lock, done marker,
     SHA-256 or sweep of dead writers' temporary files. Timed as b; printed against Python
     and against mesa (what the runner adds). c' is the same loop writing its files under a
     separate folder with std::fs::write, as the Python side does.

Python runs single-threaded; mesa with --jobs 1 (the example is single-threaded). The load
average and CPU model are printed with the figures.

Without a DATASET, a demo dataset is made in a temporary folder: `mesa demo DIR --scenes N
--seed S`, then the stages up to `graph` (assets, lift, retrieve, place, pack, the simulated
annotator, ingest, check, graph).

    pip install numpy shapely
    python bench/compare_graph.py [DATASET] [--scenes 1000] [--seed 3] [--repeat 5] [--mesa PATH]
"""
import argparse
import json
import math
import os
import platform
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

for var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(var, "1")

sys.dont_write_bytecode = True  # no __pycache__ left in bench/
sys.path.insert(0, str(Path(__file__).resolve().parent))
import graph_rules  # noqa: E402
from timing import WARM_S, Served, alternated, best_median_ms, run_for, timed  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
EXAMPLE = ROOT / "target/release/examples/graph_timing"
BARE = ROOT / "target/release/examples/graph_bare"
STAGES_UP_TO_GRAPH = [["assets"], ["lift"], ["retrieve"], ["place"], ["pack"], ["demo", "annotate"],
                      ["ingest"], ["check"], ["graph"]]


def run(cmd, **kwargs):
    return subprocess.run([str(c) for c in cmd], check=True, **kwargs)


def quiet(mesa, *args):
    """A mesa stage over a dataset, one worker, no progress output."""
    return [mesa, *args, "--jobs", "1", "--progress", "off", "-q"]


def run_quietly(cmd):
    """Runs a command with its output captured; shows it only if the command fails."""
    result = subprocess.run([str(c) for c in cmd], capture_output=True, text=True)
    if result.returncode != 0:
        sys.stderr.write(result.stdout + result.stderr)
        raise subprocess.CalledProcessError(result.returncode, cmd)


def make_demo(mesa, folder, scenes, seed):
    dataset = folder / "ds"
    run_quietly([mesa, "demo", dataset, "--scenes", scenes, "--seed", seed, "-q"])
    for stage in STAGES_UP_TO_GRAPH:
        run_quietly([mesa, *stage, dataset, "--progress", "off", "-q"])
    return dataset


def cpu_model():
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown"


def same_numbers(a, b):
    """Two JSON values equal, numbers within 1e-9 (relative to 1 or their size)."""
    if isinstance(a, float) or isinstance(b, float):
        return math.isclose(a, b, rel_tol=1e-9, abs_tol=1e-9)
    if isinstance(a, dict):
        return a.keys() == b.keys() and all(same_numbers(a[k], b[k]) for k in a)
    if isinstance(a, list):
        return len(a) == len(b) and all(same_numbers(x, y) for x, y in zip(a, b))
    return a == b


def check_outputs(dataset, out):
    """Compares the Python outputs under `out` with mesa's in `dataset`; returns the summary."""
    scenes = graph_rules.dataset_scenes(dataset)
    txt_same, json_same, json_close, differing = 0, 0, 0, []
    for table, scene_id, _ in scenes:
        rel = Path("scenes") / table / scene_id / "graph"
        mesa_txt = (dataset / rel / "graph.txt").read_bytes()
        py_txt = (out / rel / "graph.txt").read_bytes()
        if mesa_txt == py_txt:
            txt_same += 1
        else:
            differing.append(f"{table}/{scene_id}")
        mesa_json = (dataset / rel / "graph.json").read_bytes()
        py_json = (out / rel / "graph.json").read_bytes()
        if mesa_json == py_json:
            json_same += 1
        elif same_numbers(json.loads(mesa_json), json.loads(py_json)):
            json_close += 1
    return len(scenes), txt_same, json_same, json_close, differing


def timed_processes(commands, repeat, warm_s=WARM_S):
    """Commands timed in turns: `repeat` rounds, each a timed run of every command in order, so
    that all of them see the same moments of the machine. Before each timed run, its command
    runs untimed for `warm_s` seconds (at least once), as `timing.alternated` does in process:
    a short run right after a long one of another command would otherwise start with the
    caches and the core as the other one left them. With `warm_s` None, each command runs
    untimed once before the first round only (for commands whose runs create many files: more
    runs a turn would leave the writing of their files to the disk to the timed run).
    `commands` holds (command, prepare) pairs; `prepare`, if not None, runs before each run of
    its command, untimed (removing the outputs of the last one). For each command, the wall
    seconds and the CPU seconds (user + system, of the process and its children) of its timed
    runs."""
    def untimed(cmd, prepare, seconds):
        def once():
            if prepare:
                prepare()
            run_quietly(cmd)
        run_for(once, seconds)

    if warm_s is None:
        for cmd, prepare in commands:
            untimed(cmd, prepare, 0.0)
    timings = [([], []) for _ in commands]
    for _ in range(repeat):
        for (cmd, prepare), (walls, cpus) in zip(commands, timings):
            if warm_s is not None:
                untimed(cmd, prepare, warm_s)
            if prepare:
                prepare()
            before = resource.getrusage(resource.RUSAGE_CHILDREN)
            start = time.perf_counter()
            run_quietly(cmd)
            walls.append(time.perf_counter() - start)
            after = resource.getrusage(resource.RUSAGE_CHILDREN)
            cpus.append(after.ru_utime + after.ru_stime - before.ru_utime - before.ru_stime)
    return timings


def report(label, python_runs, mesa_runs, what, names=("python", "mesa")):
    """Prints min and median per scene (ms) of both sides and the ratios of the first to the
    second (python / mesa unless `names` says otherwise)."""
    py_min, py_med = best_median_ms(python_runs)
    me_min, me_med = best_median_ms(mesa_runs)
    first, second = names
    width = max(len(first), len(second)) + 1
    print(f"{label}: {what}")
    print(f"  {first + ':':{width}} {py_min:9.4f} ms per scene (min of {len(python_runs)}; median {py_med:.4f})")
    print(f"  {second + ':':{width}} {me_min:9.4f} ms per scene (min of {len(mesa_runs)}; median {me_med:.4f})")
    print(f"  ratio {first} / {second}: {py_min / me_min:.1f}x min to min, {py_med / me_med:.1f}x median to median")


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("dataset", nargs="?", help="a dataset whose scenes have layouts (default: a demo dataset)")
    parser.add_argument("--scenes", type=int, default=1000, help="scenes of the demo dataset")
    parser.add_argument("--seed", type=int, default=3, help="seed of the demo dataset")
    parser.add_argument("--repeat", type=int, default=5, help="timed runs on each side")
    parser.add_argument("--mesa", default=str(ROOT / "target/release/mesa"))
    parser.add_argument("--example", default=str(EXAMPLE), help="the built graph_timing example")
    parser.add_argument("--bare", default=str(BARE), help="the built graph_bare example")
    args = parser.parse_args()
    mesa = Path(args.mesa)
    example = Path(args.example)
    bare = Path(args.bare)
    if not example.exists():
        run(["cargo", "build", "--release", "-q", "-p", "mesa-stages", "--example", "graph_timing"], cwd=ROOT)
    if not bare.exists():
        run(["cargo", "build", "--release", "-q", "-p", "mesa-pipeline", "--example", "graph_bare"], cwd=ROOT)

    with tempfile.TemporaryDirectory(prefix="compare_graph_") as tmp:
        tmp = Path(tmp)
        if args.dataset:
            dataset = Path(args.dataset).resolve()
            run_quietly(quiet(mesa, "graph", dataset))  # mesa's graphs, to check against
        else:
            print(f"making a {args.scenes}-scene demo dataset (seed {args.seed}) under {tmp} ...", flush=True)
            dataset = make_demo(mesa, tmp, args.scenes, args.seed)
        scenes = graph_rules.dataset_scenes(dataset)
        n = len(scenes)
        objects = 0

        # Correctness first: Python's outputs against mesa's.
        out = tmp / "python_out"
        graph_rules.graph_dataset(dataset, out)
        total, txt_same, json_same, json_close, differing = check_outputs(dataset, out)
        print(f"dataset: {dataset} ({n} scenes)")
        print(f"check: graph.txt byte-identical in {txt_same}/{total} scenes; graph.json byte-identical "
              f"in {json_same}/{total}, equal within 1e-9 in {json_close} more")
        if differing:
            print(f"  graph.txt differs in: {', '.join(differing[:10])}{' ...' if len(differing) > 10 else ''}")

        # a. In process.
        annotations = graph_rules.read_annotations(dataset)
        parsed = []
        for table, scene_id, rel in scenes:
            scene = graph_rules.read_scene(dataset / "scenes" / table / scene_id / rel)
            parsed.append((scene, graph_rules.container_flags(scene, annotations)))
            objects += len(scene.names)

        def python_pass():
            for scene, flags in parsed:
                graph_rules.graph_text(graph_rules.extract_graph(scene, flags))

        # The two sides alternate pass by pass (bench/timing.py's `alternated`), so both see
        # the same moments of the machine.
        served = Served([example, dataset, "--repeat", args.repeat, "--serve"], "runs_s_per_scene")
        python_runs, mesa_runs = alternated(python_pass, served, args.repeat)
        python_runs = [t / n for t in python_runs]
        timing = served.finish()
        assert timing["scenes"] == n, f"graph_timing found {timing['scenes']} scenes, not {n}"

        # b. As a dataset stage (whole processes).
        stage_out = tmp / "python_stage_out"
        python_cmd = [sys.executable, Path(__file__).resolve().parent / "graph_rules.py", "dataset", dataset,
                      "--out", stage_out]
        mesa_cmd = quiet(mesa, "graph", dataset, "--force")
        # c. The stage's work in a bare Rust loop, without the runner: the floor under b, in
        # the same turns.
        bare_compare_cmd = [bare, dataset, "--compare"]
        (python_wall, python_cpu), (mesa_wall, mesa_cpu), (bare_compare_wall, bare_compare_cpu) = \
            timed_processes([(python_cmd, None), (mesa_cmd, None), (bare_compare_cmd, None)], args.repeat)

        # b'. The same with fresh outputs: before each run, both sides' graph files (and
        # mesa's graph markers) are removed, so each run creates every file (a forced rerun
        # of mesa leaves files that come out the same untouched; Python rewrites them).
        def clear_python():
            shutil.rmtree(stage_out, ignore_errors=True)

        def clear_mesa():
            shutil.rmtree(dataset / ".mesa" / "markers" / "graph", ignore_errors=True)
            for table, scene_id, _ in scenes:
                shutil.rmtree(dataset / "scenes" / table / scene_id / "graph", ignore_errors=True)

        bare_out = tmp / "bare_out"
        # b's runs left files to be written to the disk (Python's side rewrites its 2,000 each
        # run): written now, before b' times the creating of files.
        os.sync()
        (python_fresh_wall, python_fresh_cpu), (mesa_fresh_wall, mesa_fresh_cpu), (bare_write_wall, bare_write_cpu) = \
            timed_processes([(python_cmd, clear_python), (quiet(mesa, "graph", dataset), clear_mesa),
                             ([bare, dataset, "--out", bare_out], None)], args.repeat, warm_s=None)
        # What process start-up alone costs (included in b).
        python_start = min(timed(lambda: run_quietly([sys.executable, "-c", "import numpy, shapely"]), args.repeat))
        mesa_start = min(timed(lambda: run_quietly([mesa, "--version"]), args.repeat))

        load = os.getloadavg()
        print(f"machine: {cpu_model()}, {os.cpu_count()} cores; load average {load[0]:.2f} {load[1]:.2f} {load[2]:.2f}")
        print(f"python {platform.python_version()}, numpy {graph_rules.np.__version__}, "
              f"shapely {graph_rules.shapely.__version__}; {objects / n:.1f} objects per scene")
        report("a. in process", python_runs, mesa_runs,
               "layouts parsed, containers decided; extract the graph and its text, no file I/O")
        if "read_layout_min_s_per_scene" in timing:
            print(f"  mesa's other work of the stage, in process (min of {args.repeat}): reading a layout's "
                  f"text {1e6 * timing['read_layout_min_s_per_scene']:.2f} us, writing graph.json "
                  f"{1e6 * timing['to_json_min_s_per_scene']:.2f} us, the graph alone "
                  f"{1e6 * timing['extract_only_min_s_per_scene']:.2f} us a scene")
        report("b. dataset stage, wall time", [t / n for t in python_wall], [t / n for t in mesa_wall],
               f"whole process over {n} scenes: `mesa graph --force --jobs 1` vs `graph_rules.py dataset "
               f"--out <separate folder>`, reads and writes included")
        report("b. dataset stage, CPU time (user + system)", [t / n for t in python_cpu], [t / n for t in mesa_cpu],
               "the same runs; less sensitive than wall time to other work on the machine")
        report("b'. dataset stage, fresh outputs, wall time", [t / n for t in python_fresh_wall],
               [t / n for t in mesa_fresh_wall],
               "as b, the outputs (and mesa's graph markers) removed before each run")
        report("b'. dataset stage, fresh outputs, CPU time", [t / n for t in python_fresh_cpu],
               [t / n for t in mesa_fresh_cpu], "the same runs")
        report("c. the stage's work in a bare Rust loop, wall time", [t / n for t in python_wall],
               [t / n for t in bare_compare_wall],
               "pipeline/examples/graph_bare.rs --compare: each layout read, its graph extracted, graph.json "
               "and graph.txt made and compared with the files there; no lock, marker, digest or sweep",
               names=("python", "bare loop"))
        report("c. the same, CPU time", [t / n for t in python_cpu], [t / n for t in bare_compare_cpu],
               "the same runs", names=("python", "bare loop"))
        report("c. what mesa's runner adds, wall time", [t / n for t in mesa_wall], [t / n for t in bare_compare_wall],
               "`mesa graph --force` (b) against the bare loop", names=("mesa", "bare loop"))
        report("c'. the bare loop writing its files, wall time", [t / n for t in python_wall],
               [t / n for t in bare_write_wall],
               "graph_bare.rs --out <separate folder>: the files truncated and rewritten with std::fs::write, "
               "as the Python side writes its own", names=("python", "bare loop"))
        print(f"  process start-up, included in b (min of {args.repeat}): python + import numpy, shapely "
              f"{1e3 * python_start:.0f} ms; mesa --version {1e3 * mesa_start:.0f} ms")
    return 0 if not differing else 1


if __name__ == "__main__":
    sys.exit(main())
