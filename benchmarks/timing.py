"""Wall-clock timing of a call, shared by the benchmark scripts.

Imports nothing of skidmc, so that a benchmark's worker running an older source tree can use it.
"""

from __future__ import annotations

import statistics
import time

__all__ = ["best_time", "median_time"]


def _times(fn, calls):
    """([wall time [s] of each call], the last call's result) of ``calls`` calls of ``fn()``."""
    times, out = [], None
    for _ in range(calls):
        start = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - start)
    return times, out


def median_time(fn, calls):
    """(median wall time [s], last result) of ``calls`` calls of ``fn()``."""
    times, out = _times(fn, calls)
    return statistics.median(times), out


def best_time(fn, calls):
    """(shortest wall time [s], last result) of ``calls`` calls of ``fn()``."""
    times, out = _times(fn, calls)
    return min(times), out
