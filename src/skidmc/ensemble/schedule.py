"""Chunk scheduling: time-sized guided chunks, crash retry, in-order consumption.
"""

from __future__ import annotations

import math
from collections import deque

import numpy as np

from skidmc.ensemble.executors import ChunkOut, evaluate_chunk, failed_results, worker_died

__all__ = [
    "FIRST_CHUNK_EVALUATIONS",
    "MAX_CHUNK_EVALUATIONS",
    "MIN_CHUNK_SECONDS",
    "TARGET_CHUNK_SECONDS",
    "Schedule",
    "run_chunks",
]



#: Longest chunk, in scene evaluations (samples x scenes): bounds a chunk's memory and the work
#: lost on interruption whatever the solver's speed.
MAX_CHUNK_EVALUATIONS = 16384

#: Solver work per chunk aimed at [s] when the chunk size is automatic: long enough that the
#: per-chunk costs (pickling, drawing, writing: ~10-20 ms) are a few percent of one core, short
#: enough for a steady progress bar and little lost work on interruption.
TARGET_CHUNK_SECONDS = 0.5

#: Shortest automatic chunk [s of solver work] (the tail of a run), and the evaluations in each
#: worker's first chunks, sized before any timing is known.
MIN_CHUNK_SECONDS = 0.05
FIRST_CHUNK_EVALUATIONS = 8


class Schedule:
    """Which samples go in the next chunk: the samples still to do, in order, in chunks.

    With a fixed `chunk_size`, chunks of that many samples. Otherwise sized by time: the first
    chunks hold :data:`FIRST_CHUNK_EVALUATIONS` evaluations; then each holds about
    :data:`TARGET_CHUNK_SECONDS` of work at the measured seconds per sample, and, with
    `balance` (several workers), at most a 1/(3 x workers) share of what is left (guided
    self-scheduling), but no less than :data:`MIN_CHUNK_SECONDS`, so the last chunks are short
    and the workers finish together.
    """

    def __init__(self, todo: np.ndarray, per_sample: int, workers: int,
                 chunk_size: int | None = None, balance: bool = True) -> None:
        idx = np.flatnonzero(todo)
        breaks = np.flatnonzero(np.diff(idx) > 1) + 1
        self._segments = deque((int(seg[0]), int(seg[-1]) + 1)
                               for seg in np.split(idx, breaks) if len(seg))
        self.remaining = len(idx)
        self._per_sample = max(1, per_sample)
        self._workers = max(1, workers)
        self._fixed = chunk_size
        self._balance = balance
        self._samples = 0  # measured so far
        self._seconds = 0.0

    def __bool__(self) -> bool:
        return bool(self._segments)

    def observe(self, samples: int, seconds: float) -> None:
        """Record that a chunk of `samples` took `seconds` of worker time."""
        if samples > 0 and math.isfinite(seconds) and seconds >= 0:
            self._samples += samples
            self._seconds += seconds

    def _size(self) -> int:
        if self._fixed:
            return int(self._fixed)
        cap = max(1, MAX_CHUNK_EVALUATIONS // self._per_sample)
        if self._samples == 0 or self._seconds <= 0:
            return min(cap, max(1, -(-FIRST_CHUNK_EVALUATIONS // self._per_sample)))
        per = self._seconds / self._samples
        size = math.ceil(TARGET_CHUNK_SECONDS / per)
        if self._balance:
            size = min(size, math.ceil(self.remaining / (3 * self._workers)))
            size = max(size, math.ceil(MIN_CHUNK_SECONDS / per))
        return max(1, min(size, cap))

    def next(self) -> tuple[int, int] | None:
        """(start, stop) of the next chunk; None when every sample has been handed out."""
        if not self._segments:
            return None
        start, end = self._segments[0]
        stop = min(end, start + self._size())
        if stop == end:
            self._segments.popleft()
        else:
            self._segments[0] = (stop, end)
        self.remaining -= stop - start
        return start, stop


def run_chunks(executor, schedule: Schedule, make_chunk, consume) -> None:
    """Send the schedule's chunks to `executor`; `consume` each one's results as it is back.

    ``make_chunk(start, stop, isolated) -> (Chunk, context)`` builds a chunk;
    ``consume(chunk, context, results, out)`` takes its list of BatchResult (one per scene) and
    the :class:`ChunkOut` (timing, worker). At most two chunks per worker are in flight, so
    memory does not grow with n. When a worker process dies (BrokenProcessPool, dask's
    KilledWorker) the chunks it took down are retried one sample at a time, each alone in
    flight, so that a sample that kills its worker again is known to be the culprit and is
    recorded as failed while every other sample is evaluated.
    """
    in_flight: dict = {}
    retry: deque = deque()  # single samples to rerun alone after a worker died

    def submit(start: int, stop: int, isolated: bool = False) -> None:
        chunk, context = make_chunk(start, stop, isolated)
        in_flight[executor.submit(evaluate_chunk, chunk)] = (chunk, context)

    while schedule or retry or in_flight:
        if retry and not in_flight:
            submit(*retry.popleft(), isolated=True)
        while schedule and not retry and len(in_flight) < 2 * executor.workers:
            submit(*schedule.next())
        for fut in executor.wait_first(list(in_flight)):
            if fut not in in_flight:  # requeued after a worker died
                continue
            chunk, context = in_flight.pop(fut)
            try:
                out = fut.result()
            except Exception as exc:
                if not worker_died(exc):
                    raise
                if not chunk.isolated:
                    retry.extend((i, i + 1) for i in range(chunk.start, chunk.stop))
                    for other, (lost, _) in list(in_flight.items()):
                        if not (other.done() and other.exception() is None):
                            in_flight.pop(other)  # taken down with the pool: rerun alone
                            retry.extend((i, i + 1) for i in range(lost.start, lost.stop))
                    executor.restart()
                    continue
                executor.restart()
                out = ChunkOut(failed_results(chunk, "worker process died while evaluating "
                                                f"this sample ({exc!r})"))
            if not isinstance(out, ChunkOut):  # a bare list of results
                out = ChunkOut(list(out))
            if not chunk.isolated:
                seconds = out.ended - out.began
                if not math.isfinite(seconds):
                    seconds = sum(float(r.wall_time.sum()) for r in out.results)
                schedule.observe(chunk.stop - chunk.start, seconds)
            consume(chunk, context, out.results, out)
