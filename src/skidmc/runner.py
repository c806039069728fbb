"""The ensemble runner: a study's samples, evaluated in chunks, written as they finish.

Two levels:

* :func:`evaluate_batch` evaluates any batch of scenes (or input rows on a base scene) that a
  caller hands it and returns one status per sample; nothing about designs or files. Adaptive
  methods (subset simulation, importance sampling) call it with the batch they chose. With
  ``workers > 1`` the batch goes in chunks to local worker processes that stay warm between
  calls (:func:`shutdown_workers` ends them), through the same chunk machinery as a study.
* :func:`run_study` (``skidmc run``) draws a study's design chunk by chunk
  (:class:`skidmc.sampling.StudySampler`), sends the chunks to local worker processes
  (:class:`concurrent.futures.ProcessPoolExecutor`, spawn start method) or to a
  :mod:`dask.distributed` cluster, and writes each finished chunk to the result file
  (:class:`skidmc.storage.EnsembleFile`) at once, so memory does not grow with n and an
  interrupted run keeps every finished chunk (``--resume`` computes only the rest).

Sample i gets the same inputs and, the solver being deterministic, the same result whatever the
worker count, chunk size, scheduler or interruptions: inputs come from the design by index, and
chunks only decide who computes what.

Worker processes. Local workers are started with the ``forkserver`` method where the platform
has it (else ``spawn``): one server process imports numpy, numba, scipy and skidmc once and every
worker is forked from it, so a worker (also one that replaces a crashed worker) starts in
milliseconds instead of re-importing everything; each worker then loads the compiled kernels
from numba's cache once (a small warm-up solve), before its first chunk. :func:`execute_study`
launches its workers before it loads the study and opens the result file, so that their start
overlaps the parent's own preparation.

Chunks. Unless a chunk size is given, chunks are sized by time (guided self-scheduling): about
:data:`TARGET_CHUNK_SECONDS` of solver work each, measured as results come back, shrinking toward
the end of a run so that the workers finish together; the parent draws the design in blocks of
:data:`DRAW_BLOCK` samples rather than once per chunk.

Every sample ends with a status: ``ok``, ``censored_above`` / ``censored_below`` (the critical
height lies beyond the search bounds; the bound is stored), or ``failed`` with the exception
that stopped it (height NaN). A failing sample never stops the run, nor is it dropped or imputed.
A sample that kills its worker process (a crash in compiled code) is retried alone and, if it
kills a worker again, recorded as failed.
"""

from __future__ import annotations

import argparse
import atexit
import concurrent.futures as cf
import dataclasses
import math
import multiprocessing
import os
import sys
import time
from collections import deque
from collections.abc import Mapping
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from skidmc.errors import SkidmcError
from skidmc.scene import NUMERIC_KEYS, SI_UNITS, Scene, SceneColumns, make_scene

if TYPE_CHECKING:
    from skidmc.storage import EnsembleFile
    from skidmc.study import SolverOptions, Study

# skidmc.study and skidmc.storage (scipy.stats, h5py) are imported where the parent process needs
# them, not at module level: a worker process only evaluates, and starts ~0.4 s sooner.

__all__ = [
    "BatchResult",
    "RunReport",
    "add_run_arguments",
    "evaluate_batch",
    "execute_study",
    "main_run",
    "run_study",
    "shutdown_workers",
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

#: Samples the parent draws from the design at once (then hands out slices as chunks).
DRAW_BLOCK = 1024


@dataclasses.dataclass
class BatchResult:
    """Results of a batch of scene evaluations (arrays of the batch's length).

    Attributes
    ----------
    critical_height : ndarray of float
        Critical drop height [m]; the bound hit when censored; NaN when failed.
    status : ndarray of str
        ``ok``, ``censored_above``, ``censored_below`` or ``failed``.
    evaluations : ndarray of int32
        Impact simulations used [1] (0 when failed).
    flags : ndarray of str
        Solver flags, comma separated.
    failure_reason : ndarray of str
        ``"ExceptionType: message"`` for failed samples, else empty.
    wall_time : ndarray of float
        Time spent in the solver call per sample [s].
    inputs : dict
        Numeric scene key -> the values the sample was evaluated with [SI]; for a sample whose
        scene could not be built, the values it was given.
    """

    critical_height: np.ndarray
    status: np.ndarray
    evaluations: np.ndarray
    flags: np.ndarray
    failure_reason: np.ndarray
    wall_time: np.ndarray
    inputs: dict[str, np.ndarray]

    def __len__(self) -> int:
        return len(self.status)


def _rows(scenes) -> list:
    """Batch forms -> list of Scene or mapping (columns {key: array} become rows)."""
    if isinstance(scenes, Mapping):
        columns = {k: np.asarray(v) for k, v in scenes.items()}
        lengths = {len(v) for v in columns.values()}
        if len(lengths) > 1:
            raise ValueError(f"columns of different lengths: {sorted(lengths)}")
        m = lengths.pop() if lengths else 0
        return [{k: v[i].item() if v.dtype.kind != "O" else v[i] for k, v in columns.items()}
                for i in range(m)]
    if isinstance(scenes, Scene):
        return [scenes]
    return list(scenes)


_STATUS_OF_CENSORING = {None: "ok", "above": "censored_above", "below": "censored_below"}


def _solve(critical_height, scene: Scene, kwargs: dict) -> tuple[float, str, int, str, str]:
    """(height [m], status, evaluations, flags, failure reason) of one scene; never raises."""
    try:
        res = critical_height(scene, **kwargs)
    except Exception as exc:  # noqa: BLE001 - recorded, see the module docstring
        return math.nan, "failed", 0, "", f"{type(exc).__name__}: {exc}"
    h, flags, evaluations = float(res.critical_height), ",".join(res.flags), int(res.evaluations)
    status = _STATUS_OF_CENSORING.get(res.censored)
    if status is None:
        return math.nan, "failed", evaluations, flags, f"unknown censoring {res.censored!r}"
    if not math.isfinite(h):
        return math.nan, "failed", evaluations, flags, f"solver returned a non-finite height ({h})"
    return h, status, evaluations, flags, ""


def _solve_into(out: BatchResult, i: int, critical_height, scene: Scene, kwargs: dict) -> None:
    """Solve sample i's scene and record its outcome and solver wall time [s] in `out`."""
    t0 = time.perf_counter()
    (out.critical_height[i], out.status[i], out.evaluations[i], out.flags[i],
     out.failure_reason[i]) = _solve(critical_height, scene, kwargs)
    out.wall_time[i] = time.perf_counter() - t0


def _solver_kwargs(solver_options) -> dict:
    """SolverOptions or mapping -> plain keyword arguments (picklable without skidmc.study)."""
    if hasattr(solver_options, "as_kwargs"):  # a SolverOptions
        return dict(solver_options.as_kwargs())
    return dict(solver_options or {})


def _empty_result(m: int) -> BatchResult:
    return BatchResult(
        critical_height=np.full(m, np.nan), status=np.full(m, "failed", dtype=object),
        evaluations=np.zeros(m, dtype=np.int32), flags=np.full(m, "", dtype=object),
        failure_reason=np.full(m, "", dtype=object), wall_time=np.zeros(m),
        inputs={k: np.full(m, np.nan) for k in NUMERIC_KEYS},
    )


def _record_given(out: BatchResult, i: int, row, base_values: dict) -> None:
    """Inputs of sample i as given (a row whose scene was never built)."""
    if isinstance(row, Scene):
        given = row.as_dict()
    else:
        given = {**base_values, **(row if isinstance(row, Mapping) else {})}
    for k in NUMERIC_KEYS:
        if isinstance(given.get(k), (int, float)):
            out.inputs[k][i] = given[k]


def evaluate_batch(scenes, solver_options: SolverOptions | Mapping | None = None, *,
                   base: Scene | str | None = None, workers: int | None = 1,
                   chunk_size: int | None = None, scheduler=None) -> BatchResult:
    """Critical heights of any batch of scenes, one status per sample, never raising for one.

    Parameters
    ----------
    scenes : sequence of Scene or mapping, or mapping of columns
        The batch: :class:`~skidmc.scene.Scene` objects; or mappings of scene keys to values
        (SI floats or unit strings), applied as overrides to `base`
        (``make_scene(row, preset=base)``); or one mapping ``{key: 1-D array}`` of columns.
    solver_options : SolverOptions or mapping, optional
        Keyword arguments of :func:`skidmc.solver.critical_height` (default: its defaults).
    base : Scene or str, optional
        Scene or preset name the mapping rows override; without it rows must be complete.
    workers : int or None
        1 (default): evaluate in this process. More: local worker processes, started on the
        first such call and kept warm for later calls with the same count (end them with
        :func:`shutdown_workers`; they also end with this process). None: all CPUs available.
    chunk_size : int, optional
        Samples per chunk sent to a worker (default: sized by time, see the module docstring).
        Does not change any result.
    scheduler : str or distributed.Client, optional
        ``"dask"`` or a dask Client/address instead of local processes (as in
        :func:`run_study`).

    Returns
    -------
    BatchResult
        In the batch's order, the same for any `workers`, `chunk_size` or `scheduler`. Invalid
        inputs and solver exceptions give status ``failed`` with the reason; nothing is dropped;
        a sample that kills its worker process is retried alone and, if it kills it again,
        recorded as failed (``worker process died ...``).
    """
    kwargs = _solver_kwargs(solver_options)
    if isinstance(base, str):
        from skidmc.presets import get_preset

        base = get_preset(base)
    if scheduler in (None, "local") and (workers or _default_workers()) == 1:
        return _evaluate_here(scenes, kwargs, base)
    return _evaluate_rows_parallel(_rows(scenes), kwargs, base, workers, chunk_size, scheduler)


def _evaluate_here(scenes, kwargs: dict, base: Scene | None) -> BatchResult:
    """evaluate_batch in this process: columns through :func:`_evaluate_columns`, rows or
    scenes through :func:`_evaluate_rows`."""
    if isinstance(scenes, Mapping):
        return _evaluate_columns(scenes, kwargs, base)
    return _evaluate_rows(_rows(scenes), kwargs, base)


def _evaluate_rows(rows: list, kwargs: dict, base: Scene | None) -> BatchResult:
    """evaluate_batch in this process."""
    from skidmc.solver import critical_height

    m = len(rows)
    out = _empty_result(m)
    base_values = base.as_dict() if base is not None else {}
    for i, row in enumerate(rows):
        try:
            scene = row if isinstance(row, Scene) else make_scene(row, preset=base)
        except Exception as exc:  # noqa: BLE001 - an invalid sample fails alone, not the run
            _record_given(out, i, row, base_values)
            out.failure_reason[i] = f"invalid inputs: {type(exc).__name__}: {exc}"
            continue
        values = scene.as_dict()
        for k in NUMERIC_KEYS:
            out.inputs[k][i] = values[k]
        _solve_into(out, i, critical_height, scene, kwargs)
    return out


def _evaluate_columns(columns: Mapping, kwargs: dict, base: Scene | None) -> BatchResult:
    """evaluate_batch of columns ``{key: array}`` in this process (a study chunk's scene).

    Columns of SI floats on a base scene (a study's samples) have their scenes built by
    :class:`~skidmc.scene.SceneColumns`, which validates whole columns once instead of every key
    of every row; anything else goes row by row through :func:`_evaluate_rows`. The result is
    the same either way, bit for bit: the same scenes, the same errors, the same recorded inputs.
    """
    columns = {k: np.asarray(v) for k, v in columns.items()}
    if not SceneColumns.accepts(base, columns):
        return _evaluate_rows(_rows(columns), kwargs, base)
    from skidmc.solver import critical_height

    scenes = SceneColumns(base, columns)
    m = len(scenes)
    out = _empty_result(m)
    # The inputs as given (the columns over the base), which _record_given keeps for a row whose
    # scene cannot be built; a built scene differs from them only in its derived keys.
    base_values = base.as_dict()
    for k in NUMERIC_KEYS:
        out.inputs[k][:] = columns.get(k, base_values[k])
    derived = [(out.inputs[k], k.replace(".", "_")) for k in scenes.derived]  # attribute names
    for i in range(m):
        try:
            scene = scenes.scene(i)
        except Exception as exc:  # noqa: BLE001 - an invalid sample fails alone, not the run
            out.failure_reason[i] = f"invalid inputs: {type(exc).__name__}: {exc}"
            continue
        for values, field in derived:
            values[i] = getattr(scene, field)
        _solve_into(out, i, critical_height, scene, kwargs)
    return out


def _evaluate_rows_parallel(rows: list, kwargs: dict, base: Scene | None, workers,
                            chunk_size, scheduler) -> BatchResult:
    """evaluate_batch through the chunk machinery of a study run (warm local pool or dask)."""
    m = len(rows)
    out = _empty_result(m)
    if m == 0:
        return out
    if scheduler in (None, "local"):
        executor, owned = _shared_pool(workers or _default_workers()), False
    else:
        executor, owned = _Dask(None if scheduler == "dask" else scheduler, workers), True

    def make_chunk(start: int, stop: int, isolated: bool):
        return _Chunk(start, stop, (base,), [rows[start:stop]], kwargs, isolated), None

    def consume(chunk: _Chunk, _context, results: list[BatchResult], _out) -> None:
        (res,) = results
        sl = slice(chunk.start, chunk.stop)
        for name in ("critical_height", "status", "evaluations", "flags", "failure_reason",
                     "wall_time"):
            getattr(out, name)[sl] = getattr(res, name)
        for k in NUMERIC_KEYS:
            out.inputs[k][sl] = res.inputs[k]

    todo = np.ones(m, dtype=bool)
    try:
        _run_chunks(executor, _Schedule(todo, 1, executor.workers, chunk_size,
                                        balance=executor.workers > 1),
                    make_chunk, consume)
    finally:
        if owned:
            executor.shutdown()
    return out


# --- chunks -----------------------------------------------------------------------------------


@dataclasses.dataclass
class _Chunk:
    """What a worker needs for samples ``start:stop``: base scenes and each scene's overrides.

    `overrides[j]` holds scene j's inputs: columns ``{key: array}`` (a study) or a list of rows
    (Scene objects or mappings; :func:`evaluate_batch`). `options` are plain keyword arguments,
    so that a worker never imports :mod:`skidmc.study` (scipy.stats) to unpickle a chunk.
    """

    start: int
    stop: int
    scenes: tuple[Scene | None, ...]
    overrides: list
    options: dict
    isolated: bool = False  # a retry of one sample after a worker died


@dataclasses.dataclass
class _ChunkOut:
    """A chunk's results and where/when it was computed (for the run report)."""

    results: list[BatchResult]
    pid: int | None = None
    peak_rss_mib: float = math.nan  # the worker's peak resident memory so far
    began: float = math.nan  # time.time() in the worker
    ended: float = math.nan


def _peak_rss_mib() -> float:
    """Peak resident memory of this process [MiB] (nan where the platform cannot tell)."""
    try:
        import resource
    except ImportError:  # not on Unix
        return math.nan
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return peak / 2**20 if sys.platform == "darwin" else peak / 1024  # bytes on macOS, else KiB


def _evaluate_chunk(chunk: _Chunk) -> _ChunkOut:
    """Worker entry point (module level: picklable for processes and dask)."""
    began = time.time()
    results = [_evaluate_here(ov, chunk.options, sc)
               for sc, ov in zip(chunk.scenes, chunk.overrides)]
    return _ChunkOut(results, os.getpid(), _peak_rss_mib(), began, time.time())


def _worker_probe(_=None) -> tuple[int, float, float]:
    """(pid, peak RSS, current RSS [MiB]) of the worker that runs it (benchmarks/throughput.py);
    the current RSS is nan where /proc is missing."""
    try:
        with open("/proc/self/statm") as f:
            rss = int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE") / 2**20
    except (OSError, ValueError, AttributeError):
        rss = math.nan
    return os.getpid(), _peak_rss_mib(), rss


def _failed_results(chunk: _Chunk, reason: str) -> list[BatchResult]:
    """Results marking every sample of a chunk failed (the worker died), inputs as given."""
    out = []
    m = chunk.stop - chunk.start
    for sc, ov in zip(chunk.scenes, chunk.overrides):
        res = _empty_result(m)
        res.failure_reason[:] = reason
        if isinstance(ov, Mapping):  # a study's columns on a base scene
            for k, v in sc.as_dict().items():
                if k in NUMERIC_KEYS:
                    res.inputs[k][:] = v
            for k, v in ov.items():
                res.inputs[k] = np.asarray(v, dtype=float)
        else:  # evaluate_batch rows
            base_values = sc.as_dict() if sc is not None else {}
            for i, row in enumerate(ov):
                _record_given(res, i, row, base_values)
        out.append(res)
    return out


def _warm_worker(warm_up: dict | None) -> None:
    """Initializer of a local worker: import the solver, load its compiled kernels once.

    A small solve (paper-quartz at the given options) makes numba load the kernels from its
    cache (or compile them) now rather than in the first sample; its result is discarded, and
    nothing it does can fail the worker.
    """
    try:
        from skidmc.solver import critical_height

        if warm_up is not None:
            from skidmc.presets import get_preset

            critical_height(get_preset("paper-quartz"), **warm_up)
    except Exception:  # noqa: BLE001, S110 - a warm-up only; the samples report any error
        pass


def _ping(_=None) -> int:
    return os.getpid()


class _Inline:
    """Executor that runs each task when submitted (workers = 1: no process to start)."""

    workers = 1

    def submit(self, fn, arg):
        fut = cf.Future()
        try:
            fut.set_result(fn(arg))
        except Exception as exc:  # noqa: BLE001 - surfaced by fut.result(), as from a pool
            fut.set_exception(exc)
        return fut

    def wait_first(self, futures):
        return futures  # all done already

    def restart(self) -> None:
        pass

    def shutdown(self):
        pass


#: Warm-up options of a worker (the cheapest full-tier solve that loads every kernel).
_WARM_UP = {"rtol": 0.1, "tier": "full"}


def _mp_context():
    """forkserver where available (workers forked from one warm server process), else spawn."""
    if "forkserver" in multiprocessing.get_all_start_methods():
        ctx = multiprocessing.get_context("forkserver")
        # Modules the server imports once, before forking any worker (no effect once running).
        # Not skidmc.runner itself: `python -m skidmc.runner` re-runs it as the workers' main
        # module, which runpy warns about when it is imported already; its imports are these.
        ctx.set_forkserver_preload(["__main__", "skidmc.presets", "skidmc.solver"])
        return ctx
    return multiprocessing.get_context("spawn")


class _Processes:
    """Local worker processes (forkserver or spawn: safe with threads in the parent)."""

    def __init__(self, workers: int) -> None:
        self.workers = workers
        self._pool = self._new()

    def _new(self):
        pool = cf.ProcessPoolExecutor(self.workers, mp_context=_mp_context(),
                                      initializer=_warm_worker, initargs=(_WARM_UP,))
        # Start every worker now (the pool would start them one per submitted task), so that
        # they import and warm up while the caller prepares its first chunks.
        for _ in range(self.workers):
            pool.submit(_ping)
        return pool

    def submit(self, fn, arg):
        try:
            return self._pool.submit(fn, arg)
        except cf.process.BrokenProcessPool as exc:
            # A worker died since the last results came back: the task fails as the ones in
            # flight do, and the caller's retry logic takes it from there.
            fut = cf.Future()
            fut.set_exception(exc)
            return fut

    def wait_first(self, futures):
        return cf.wait(futures, return_when=cf.FIRST_COMPLETED).done

    def restart(self) -> None:
        self._pool.shutdown(wait=False, cancel_futures=True)
        self._pool = self._new()

    def shutdown(self):
        self._pool.shutdown(wait=False, cancel_futures=True)


#: Warm local pools of evaluate_batch (and of runs that find one), by worker count.
_POOLS: dict[int, _Processes] = {}


def _shared_pool(workers: int) -> _Processes:
    pool = _POOLS.get(workers)
    if pool is None:
        pool = _POOLS[workers] = _Processes(workers)
    return pool


def shutdown_workers() -> None:
    """End the warm local worker processes that :func:`evaluate_batch` keeps between calls."""
    while _POOLS:
        _, pool = _POOLS.popitem()
        pool.shutdown()


atexit.register(shutdown_workers)


class _Schedule:
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


def _run_chunks(executor, schedule: _Schedule, make_chunk, consume) -> None:
    """Send the schedule's chunks to `executor`; `consume` each one's results as it is back.

    ``make_chunk(start, stop, isolated) -> (_Chunk, context)`` builds a chunk;
    ``consume(chunk, context, results, out)`` takes its list of BatchResult (one per scene) and
    the :class:`_ChunkOut` (timing, worker). At most two chunks per worker are in flight, so
    memory does not grow with n. When a worker process dies (BrokenProcessPool, dask's
    KilledWorker) the chunks it took down are retried one sample at a time, each alone in
    flight, so that a sample that kills its worker again is known to be the culprit and is
    recorded as failed while every other sample is evaluated.
    """
    in_flight: dict = {}
    retry: deque = deque()  # single samples to rerun alone after a worker died

    def submit(start: int, stop: int, isolated: bool = False) -> None:
        chunk, context = make_chunk(start, stop, isolated)
        in_flight[executor.submit(_evaluate_chunk, chunk)] = (chunk, context)

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
                if not _worker_died(exc):
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
                out = _ChunkOut(_failed_results(chunk, "worker process died while evaluating "
                                                f"this sample ({exc!r})"))
            if not isinstance(out, _ChunkOut):  # a bare list of results
                out = _ChunkOut(list(out))
            if not chunk.isolated:
                seconds = out.ended - out.began
                if not math.isfinite(seconds):
                    seconds = sum(float(r.wall_time.sum()) for r in out.results)
                schedule.observe(chunk.stop - chunk.start, seconds)
            consume(chunk, context, out.results, out)


class _Dask:
    """Chunks sent to a dask.distributed cluster (an address, a Client, or a LocalCluster)."""

    def __init__(self, scheduler, workers: int | None) -> None:
        from distributed import Client, LocalCluster

        self._own = []
        if scheduler is None or scheduler == "dask":
            cluster = LocalCluster(n_workers=workers or _default_workers(), threads_per_worker=1,
                                   processes=True, dashboard_address=None)
            self._own.append(cluster)
            scheduler = cluster
        if isinstance(scheduler, Client):
            self.client = scheduler
        else:
            self.client = Client(scheduler)
            self._own.insert(0, self.client)
        self.workers = max(1, sum(self.client.nthreads().values()))

    def submit(self, fn, arg):
        return self.client.submit(fn, arg, pure=False)

    def wait_first(self, futures):
        from distributed import wait

        return wait(futures, return_when="FIRST_COMPLETED").done

    def restart(self) -> None:
        pass  # the scheduler replaces dead workers itself

    def shutdown(self):
        for obj in self._own:
            obj.close()


def _default_workers() -> int:
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        return os.cpu_count() or 1


def _worker_died(exc: BaseException) -> bool:
    if isinstance(exc, cf.process.BrokenProcessPool):
        return True
    try:
        from distributed import KilledWorker
    except ImportError:  # pragma: no cover - distributed is a dependency
        return False
    return isinstance(exc, KilledWorker)


# --- the study run ------------------------------------------------------------------------------


@dataclasses.dataclass
class RunReport:
    """What one run did.

    Attributes
    ----------
    path : Path
        The result file.
    n_rows, n_scenes : int
        Samples per scene, scenes.
    evaluated : int
        Scene evaluations done by this run (samples x scenes).
    status_counts : dict
        Status -> count, over this run's evaluations.
    wall_time : float
        Wall time the workers were there for [s]: from the launch of the local worker processes
        (which overlaps the loading of the study and the opening of the file) or, in process
        and on dask, from the first chunk, to the last result written.
    solver_time : float
        Sum of the per-sample solver wall times [s].
    workers : int
        Parallel slots used.
    chunks : int
        Chunks evaluated.
    worker_peak_rss_mib : dict
        Worker process id -> its peak resident memory [MiB] (local processes and dask workers;
        in process: this process).
    timeline : list of dict or None
        With ``execute_study(..., timeline=True)``: per chunk, its samples, worker, solver time
        and the times [s from the start of `wall_time`] it was sent, began and ended in the
        worker, and was written.
    """

    path: Path
    n_rows: int
    n_scenes: int
    evaluated: int = 0
    status_counts: dict = dataclasses.field(default_factory=dict)
    wall_time: float = 0.0
    solver_time: float = 0.0
    workers: int = 1
    chunks: int = 0
    worker_peak_rss_mib: dict = dataclasses.field(default_factory=dict)
    timeline: list | None = None

    @property
    def rate(self) -> float:
        """Scene evaluations per second [1/s]."""
        return self.evaluated / self.wall_time if self.wall_time > 0 else math.nan

    @property
    def outside_solver(self) -> float:
        """Share of the workers' wall time not spent in the solver [1]."""
        capacity = self.wall_time * self.workers
        return 1.0 - self.solver_time / capacity if capacity > 0 else math.nan

    def summary(self) -> str:
        """One line for the terminal and the file's history."""
        counts = ", ".join(f"{k} {v}" for k, v in sorted(self.status_counts.items()))
        peak = max(self.worker_peak_rss_mib.values(), default=math.nan)
        memory = f", peak {peak:.0f} MiB per worker" if math.isfinite(peak) else ""
        return (f"{self.evaluated} evaluations in {self.wall_time:.1f} s "
                f"({self.rate:.1f}/s on {self.workers} workers, "
                f"{100 * self.outside_solver:.1f}% outside the solver{memory}); "
                f"{counts or 'nothing to do'}")


def _resolve_out(study: Study, out) -> Path:
    from skidmc.storage import default_path

    if out is None:
        return default_path(study)
    out = Path(out)
    return out if out.suffix in (".h5", ".nc", ".hdf5") else out / "ensemble.h5"


def _columns(names, scene_dimension: bool, draws: list[dict],
             results: list[BatchResult]) -> dict:
    """Arrays (scenes x samples, or samples) of the file's variables `names` for one chunk."""

    def column(name: str, draw: dict, res: BatchResult) -> np.ndarray:
        if name in res.inputs:  # the inputs the sample was evaluated with
            return res.inputs[name]
        if name in draw:  # sampled, not a scene key (kinetics.rate_at_reference)
            return draw[name]
        if hasattr(res, name):  # an output
            return getattr(res, name)
        return np.full(len(res), np.nan)  # sampled in another scene only

    cols = {name: [column(name, d, r) for d, r in zip(draws, results)] for name in names}
    return {k: np.stack(v) if scene_dimension else v[0] for k, v in cols.items()}


def _open_result_file(study: Study, path: Path, resume: bool) -> EnsembleFile:
    """The file to write: a new one, or this study's unfinished one when resuming."""
    from skidmc.storage import EnsembleFile, StorageError, inspect_file

    if not path.exists():
        from skidmc.sampling import MC_BLOCK

        attrs = {"mc_block": np.int64(MC_BLOCK)} if study.design.method == "mc" else {}
        return EnsembleFile.create(path, study, attrs=attrs)
    if resume:
        return EnsembleFile.resume(path, study)
    info = inspect_file(path)  # raises for a file that is not HDF5
    if not info["skidmc"]:
        raise StorageError(path, "exists and is not a skidmc ensemble file; refusing to "
                           "overwrite it (choose another --out)")
    if info["complete"]:
        raise StorageError(path, f"already holds a complete run of study "
                           f"{info['study_name']!r}; refusing to overwrite it: delete it or "
                           "choose another --out")
    raise StorageError(path, f"holds an unfinished run of study {info['study_name']!r} "
                       f"({info['done']} of {info['n_rows']} samples written); continue it with "
                       "--resume or choose another --out")


def _executor(scheduler, use_dask: bool, workers: int | None):
    """(executor, owned): owned executors are shut down after the run; a warm pool that
    :func:`evaluate_batch` left running is used as it is and left running."""
    if scheduler in (None, "local") and not use_dask:
        slots = workers or _default_workers()
        if slots == 1:
            return _Inline(), True
        if slots in _POOLS:
            return _POOLS[slots], False
        return _Processes(slots), True
    return _Dask(None if scheduler == "local" else scheduler, workers), True


def execute_study(study: Study | str | os.PathLike, out=None, *, n: int | None = None,
                  workers: int | None = None, scheduler=None, use_dask: bool = False,
                  resume: bool = False, progress: bool | None = None,
                  chunk_size: int | None = None, command: str | None = None,
                  timeline: bool = False) -> RunReport:
    """Run a study to its result file; like :func:`run_study` but returns a :class:`RunReport`.

    See :func:`run_study` for the parameters; in addition `chunk_size` sets the samples per chunk
    (default: sized by time, see the module docstring), `command` is the command line recorded
    in the file's history, and `timeline` records per-chunk timings in the report.
    """
    from skidmc import __version__

    # Local worker processes start first, so that their start-up overlaps the loading of the
    # study and the opening of the file (they are shut down below if there is nothing to do).
    executor, t0 = None, None
    if scheduler in (None, "local") and not use_dask and (workers or _default_workers()) > 1:
        executor, owned = _executor(scheduler, use_dask, workers)
        t0 = time.perf_counter()
    try:
        from skidmc.storage import timestamp
        from skidmc.study import Study, load_study

        if not isinstance(study, Study):
            study = load_study(study)
        if n is not None:
            study = study.with_n(n)
        path = _resolve_out(study, out)
        command = command or f"run_study({study.file!r}, n={study.design.n})"
        report = RunReport(path=path, n_rows=study.n_rows, n_scenes=len(study.scenes),
                           timeline=[] if timeline else None)
        with _open_result_file(study, path, resume) as file:
            todo = ~file.done()
            if todo.any():
                file.add_history(f"{timestamp()} skidmc {__version__}: {command}: started with "
                                 f"{study.n_rows - int(todo.sum())} of {study.n_rows} samples "
                                 "written")
                if executor is None:
                    executor, owned = _executor(scheduler, use_dask, workers)
                report.workers = executor.workers
                schedule = _Schedule(todo, len(study.scenes), executor.workers, chunk_size,
                                     balance=executor.workers > 1)
                del todo
                outcome = "interrupted"
                try:
                    _evaluate_chunks(study, file, executor, schedule, report, progress, t0)
                    outcome = "finished"
                finally:
                    file.add_history(f"{timestamp()} skidmc {__version__}: {outcome}: "
                                     f"{report.summary()}")
            if not file.complete and file.done().all():
                file.mark_complete()
    finally:
        if executor is not None and owned:
            executor.shutdown()
    return report


class _Draws:
    """The study's design drawn in blocks of :data:`DRAW_BLOCK` samples, handed out in slices."""

    def __init__(self, sampler, n_rows: int) -> None:
        self._sampler, self._n_rows = sampler, n_rows
        self._start, self._stop, self._block = 0, 0, []

    def __call__(self, start: int, stop: int) -> list[dict]:
        if not (self._start <= start and stop <= self._stop):
            end = max(stop, min(start + DRAW_BLOCK, self._n_rows))
            self._start, self._stop = start, end
            self._block = self._sampler.draw(start, end)
        a, b = start - self._start, stop - self._start
        return [{k: v[a:b] for k, v in d.items()} for d in self._block]


def _evaluate_chunks(study: Study, file: EnsembleFile, executor, schedule: _Schedule,
                     report: RunReport, progress: bool | None, t0: float | None = None) -> None:
    """Send the study's chunks to `executor` (:func:`_run_chunks`) and write each one as soon
    as it is back; `t0` is when the workers were launched (default: now)."""
    from tqdm.auto import tqdm

    from skidmc.sampling import StudySampler

    draws = _Draws(StudySampler(study), study.n_rows)
    base_scenes = tuple(sc.scene for sc in study.scenes)
    options = _solver_kwargs(study.solver)
    n_scenes = len(base_scenes)
    names = [spec.name for spec in file.variables]
    t0 = time.perf_counter() if t0 is None else t0
    t_wall = time.time() - (time.perf_counter() - t0)  # t0 on the clock the workers share

    def make_chunk(start: int, stop: int, isolated: bool):
        drawn = draws(start, stop)
        overrides = [{k: v for k, v in d.items() if k in SI_UNITS} for d in drawn]
        chunk = _Chunk(start, stop, base_scenes, overrides, options, isolated)
        return chunk, (drawn, time.perf_counter() - t0)

    def consume(chunk: _Chunk, context, results: list[BatchResult], out: _ChunkOut) -> None:
        drawn, sent = context
        file.write_chunk(chunk.start, chunk.stop,
                         _columns(names, study.scene_dimension, drawn, results))
        m = (chunk.stop - chunk.start) * n_scenes
        report.evaluated += m
        report.chunks += 1
        solver = sum(float(res.wall_time.sum()) for res in results)
        report.solver_time += solver
        for res in results:
            for s in res.status:
                report.status_counts[s] = report.status_counts.get(s, 0) + 1
        if out.pid is not None and math.isfinite(out.peak_rss_mib):
            report.worker_peak_rss_mib[out.pid] = max(
                out.peak_rss_mib, report.worker_peak_rss_mib.get(out.pid, 0.0))
        if report.timeline is not None:
            report.timeline.append({
                "start": chunk.start, "stop": chunk.stop, "evaluations": m, "pid": out.pid,
                "solver_s": solver, "sent_s": sent, "began_s": out.began - t_wall,
                "ended_s": out.ended - t_wall, "written_s": time.perf_counter() - t0})
        bar.update(m)

    bar = tqdm(total=study.n_rows * n_scenes, initial=(study.n_rows - schedule.remaining)
               * n_scenes, unit="sample", desc=study.name, file=sys.stderr, dynamic_ncols=True,
               smoothing=0.05, disable=True if progress is False else
               (None if progress is None else False))  # None: only on a terminal
    try:
        _run_chunks(executor, schedule, make_chunk, consume)
    finally:
        report.wall_time = time.perf_counter() - t0
        bar.close()


def run_study(study_path_or_obj: Study | str | os.PathLike, out=None, n: int | None = None,
              workers: int | None = None, scheduler=None, resume: bool = False,
              progress: bool | None = None, *, use_dask: bool = False,
              chunk_size: int | None = None) -> Path:
    """Run a study and write its ensemble file.

    Parameters
    ----------
    study_path_or_obj : Study or path
        A study file or a loaded :class:`~skidmc.study.Study`.
    out : path, optional
        Result file (``.h5``/``.nc``) or folder for ``ensemble.h5``; default
        ``results/<study name>/ensemble.h5``.
    n : int, optional
        Samples per scene instead of the study's (saltelli: base samples).
    workers : int, optional
        Parallel workers (default: the CPUs available). 1 evaluates in this process.
    scheduler : str or distributed.Client, optional
        None or ``"local"``: local processes; ``"dask"``: a dask LocalCluster of `workers`
        processes; an address (``"tcp://host:8786"``) or a Client: that dask cluster (its workers
        must be able to import skidmc).
    resume : bool
        Continue an unfinished file of the same study (a missing file starts a new run).
    progress : bool, optional
        Progress bar on stderr; None: only when stderr is a terminal.
    use_dask : bool
        Use a dask LocalCluster of `workers` processes (as ``scheduler="dask"``).
    chunk_size : int, optional
        Samples per chunk (does not change any result).

    Returns
    -------
    Path
        The result file.

    Raises
    ------
    StudyError
        The study is invalid.
    StorageError
        The target exists and is not this study's unfinished run to resume (a complete file, a
        foreign file, another study's or an unfinished run without `resume`): nothing is
        overwritten.
    """
    return execute_study(study_path_or_obj, out, n=n, workers=workers, scheduler=scheduler,
                         use_dask=use_dask, resume=resume, progress=progress,
                         chunk_size=chunk_size).path


# --- command line --------------------------------------------------------------------------------


def add_run_arguments(parser: argparse.ArgumentParser) -> None:
    """The options of ``skidmc run`` (for parsers that host the subcommand)."""
    parser.add_argument("study", help="study file (TOML)")
    parser.add_argument("--out", help="result file (.h5) or folder (default: "
                        "results/<study name>/ensemble.h5)")
    parser.add_argument("--n", type=int, help="samples per scene (default: the study's)")
    parser.add_argument("--workers", type=int, help="parallel workers (default: all CPUs)")
    parser.add_argument("--scheduler", help="'local' (processes, default), 'dask' (a local dask "
                        "cluster of --workers) or a dask scheduler address")
    parser.add_argument("--resume", action="store_true", help="finish an interrupted run")
    parser.add_argument("--quiet", action="store_true", help="no progress bar or summary")


def main_run(args: argparse.Namespace) -> int:
    """``skidmc run``: run a study from parsed arguments.

    Parameters
    ----------
    args : argparse.Namespace
        With ``study``, ``out``, ``n``, ``workers``, ``scheduler``, ``resume``, ``quiet``
        (and optionally ``chunk_size``).

    Returns
    -------
    int
        Exit status: 0 done, 2 invalid study or result file, 130 interrupted.
    """
    parts = ["skidmc run", str(args.study)]
    for name in ("out", "n", "workers", "scheduler"):
        if getattr(args, name, None) is not None:
            parts.append(f"--{name} {getattr(args, name)}")
    parts += ["--resume"] * bool(args.resume)
    try:
        report = execute_study(
            args.study, args.out, n=args.n, workers=args.workers, scheduler=args.scheduler,
            resume=args.resume, progress=False if args.quiet else None,
            chunk_size=getattr(args, "chunk_size", None), command=" ".join(parts))
    except SkidmcError as exc:  # StudyError, StorageError: a message, not a traceback
        print(f"skidmc run: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("skidmc run: interrupted; finished chunks are saved, continue with --resume",
              file=sys.stderr)
        return 130
    if not args.quiet:
        print(f"{report.path}: {report.summary()}", file=sys.stderr)
        failed = report.status_counts.get("failed", 0)
        if failed:
            print(f"skidmc run: {failed} samples failed; see failure_reason in the file",
                  file=sys.stderr)
    print(report.path)
    return 0


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="python -m skidmc.runner",
                                     description="Run a study (same as `skidmc run`).")
    add_run_arguments(parser)
    parser.add_argument("--chunk-size", type=int, help=argparse.SUPPRESS)
    return parser


if __name__ == "__main__":
    # Run from the importable module rather than from __main__, so that worker processes and
    # dask workers find the chunk function by its name, skidmc.runner._evaluate_chunk.
    from skidmc import runner  # noqa: PLW0406 - see above

    sys.exit(runner.main_run(runner._parser().parse_args()))
