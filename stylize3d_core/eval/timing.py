"""Timing helpers for the benchmarks: repeated runs after warm-up calls, their median and minimum, peak memory.

The benchmark scripts in ``tests/benchmarks/`` time a callable several times and
report the median (robust to a burst of load on a shared machine) and the
minimum (the least disturbed run). Everything here is in seconds; a script
that prints milliseconds scales the result itself.

The clock is a parameter (default :func:`time.perf_counter`), so the helpers
can be tested with a fake clock.
"""

from __future__ import annotations

import statistics
import sys
import time
from typing import Callable, List, Tuple

from ..errors import InputError

Clock = Callable[[], float]


def time_runs(fn: Callable[[], object], repeats: int, *, warmup: int = 0,
              clock: Clock = time.perf_counter) -> List[float]:
    """Seconds of each of ``repeats`` timed calls of ``fn``, after ``warmup`` untimed calls.

    Args:
        fn: the work to time, called with no arguments (its result is ignored).
        repeats: timed calls, >= 1.
        warmup: untimed calls made first (imports, allocator, thread pool), >= 0.
        clock: returns the current time in seconds; read once before and once
            after every timed call.
    """
    if isinstance(repeats, bool) or int(repeats) != repeats or repeats < 1:
        raise InputError("repeats", f"must be an integer >= 1, got {repeats!r}")
    if isinstance(warmup, bool) or int(warmup) != warmup or warmup < 0:
        raise InputError("warmup", f"must be an integer >= 0, got {warmup!r}")
    for _ in range(int(warmup)):
        fn()
    times = []
    for _ in range(int(repeats)):
        t0 = clock()
        fn()
        times.append(clock() - t0)
    return times


def median_time(fn: Callable[[], object], repeats: int, *, warmup: int = 0,
                clock: Clock = time.perf_counter) -> float:
    """Median seconds of ``repeats`` calls of ``fn`` after ``warmup`` untimed calls (see :func:`time_runs`)."""
    return statistics.median(time_runs(fn, repeats, warmup=warmup, clock=clock))


def median_and_min(fn: Callable[[], object], repeats: int, *, warmup: int = 0,
                   clock: Clock = time.perf_counter) -> Tuple[float, float]:
    """(median, minimum) seconds of ``repeats`` calls of ``fn`` after ``warmup`` untimed calls."""
    times = time_runs(fn, repeats, warmup=warmup, clock=clock)
    return statistics.median(times), min(times)


def peak_rss_gib() -> float:
    """Peak resident memory of this process so far, in GiB (``getrusage`` ``ru_maxrss``).

    Run each measurement in a fresh process for a peak that belongs to it alone.
    Unix only (the ``resource`` module).
    """
    import resource

    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    per_gib = 2**30 if sys.platform == "darwin" else 2**20  # macOS reports bytes, Linux KiB
    return peak / per_gib
