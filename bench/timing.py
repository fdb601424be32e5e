"""Timing shared by the comparison scripts of bench/: both sides of a comparison are timed by
the same function, so they are timed the same way."""
import json
import statistics
import subprocess
import time


def timed(function, repeat):
    """A warm-up call (the page cache, the allocator), then `repeat` timed calls: the seconds of
    each."""
    function()
    runs = []
    for _ in range(repeat):
        start = time.perf_counter()
        function()
        runs.append(time.perf_counter() - start)
    return runs


def in_turns(functions, repeat):
    """A warm-up call of each function, then `repeat` rounds, each a timed call of every
    function in order, so that all of them see the same moments of the machine: the seconds
    of each function's calls, a list per function. For functions whose calls each take a
    tenth of a second or more (a short one timed in a block of its own is what `Served` and
    `alternated` are for)."""
    for function in functions:
        function()
    runs = [[] for _ in functions]
    for _ in range(repeat):
        for function, times in zip(functions, runs):
            start = time.perf_counter()
            function()
            times.append(time.perf_counter() - start)
    return runs


def best_median_ms(runs):
    """The best and the median of some runs in seconds, in ms."""
    return 1000 * min(runs), 1000 * statistics.median(runs)


class Served:
    """A mesa timing example run with `--serve` (stages/examples/graph_timing.rs,
    render_timing.rs, pack_timing.rs): it sets up and warms up once, then times as many runs as it is asked for
    at a time, so that a comparison can alternate its two sides run by run. Both sides then
    see the same moments of the machine: the hosts these comparisons run on change speed for
    seconds at a time, and a side timed in one block of a few milliseconds can fall entirely
    into a slow moment that the other side, timed over seconds, only grazes."""

    def __init__(self, command, key):
        self._key = key
        self._process = subprocess.Popen([str(c) for c in command], stdin=subprocess.PIPE,
                                         stdout=subprocess.PIPE, text=True)

    def take(self, count=1, warm_s=0.0):
        """Times `count` runs after untimed ones for `warm_s` seconds (at least one): the
        seconds of each timed run, as the example reports them."""
        self._process.stdin.write(f"{count} {warm_s}\n")
        self._process.stdin.flush()
        line = self._process.stdout.readline()
        if not line:
            raise RuntimeError(f"the timing example stopped (exit {self._process.wait()})")
        return json.loads(line)[self._key]

    def finish(self):
        """Ends the input; the example's last line (its report), parsed."""
        out, _ = self._process.communicate()
        if self._process.returncode != 0:
            raise RuntimeError(f"the timing example failed (exit {self._process.returncode})")
        return json.loads(out.strip().splitlines()[-1])


# How long each side of an alternated comparison runs untimed before its timed run.
WARM_S = 0.3


def run_for(function, seconds):
    """Calls `function` untimed until `seconds` have passed, at least once."""
    start = time.perf_counter()
    function()
    while time.perf_counter() - start < seconds:
        function()


def alternated(python_function, served, repeat, warm_s=WARM_S):
    """`repeat` turns, each a run of `python_function` and a run of `served` (a Served
    example), each timed run after untimed runs of its own side for `warm_s` seconds (at
    least one): the seconds of each side's timed runs. The untimed runs put each side back in
    its steady state after the other's turn: its data in the caches, and the core at the speed
    a long run sees (on these hosts a core takes a few tenths of a second of work to reach it:
    in a burst of mesa's renders after a pause of a second, the first took a quarter longer
    than the twentieth)."""
    python_runs, served_runs = [], []
    for _ in range(repeat):
        run_for(python_function, warm_s)
        start = time.perf_counter()
        python_function()
        python_runs.append(time.perf_counter() - start)
        served_runs.extend(served.take(1, warm_s))
    return python_runs, served_runs
