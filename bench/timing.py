"""Timing shared by the comparison scripts of bench/: both sides of a comparison are timed by
the same function, so they are timed the same way."""
import statistics
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


def best_median_ms(runs):
    """The best and the median of some runs in seconds, in ms."""
    return 1000 * min(runs), 1000 * statistics.median(runs)
