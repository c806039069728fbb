"""The ensemble runner: a study's samples, evaluated in chunks, written as they finish.

Two levels:

* :func:`evaluate_batch` evaluates any batch of scenes (or input rows on a base scene) that a
  caller hands it and returns one status per sample; nothing about designs or files. Adaptive
  methods (subset simulation, importance sampling) call it with the batch they chose.
* :func:`run_study` (``skidmc run``) draws a study's design chunk by chunk
  (:class:`skidmc.sampling.StudySampler`), sends the chunks to local worker processes
  (:class:`concurrent.futures.ProcessPoolExecutor`, spawn start method) or to a
  :mod:`dask.distributed` cluster, and writes each finished chunk to the result file
  (:class:`skidmc.storage.EnsembleFile`) at once, so memory does not grow with n and an
  interrupted run keeps every finished chunk (``--resume`` computes only the rest).

Sample i gets the same inputs and, the solver being deterministic, the same result whatever the
worker count, chunk size, scheduler or interruptions: inputs come from the design by index, and
chunks only decide who computes what.

Every sample ends with a status: ``ok``, ``censored_above`` / ``censored_below`` (the critical
height lies beyond the search bounds; the bound is stored), or ``failed`` with the exception
that stopped it (height NaN). A failing sample never stops the run, nor is it dropped or imputed.
A sample that kills its worker process (a crash in compiled code) is retried alone and, if it
kills a worker again, recorded as failed.
"""

from __future__ import annotations

import argparse
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
from skidmc.scene import NUMERIC_KEYS, SI_UNITS, Scene, make_scene

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
]

#: Longest chunk, in scene evaluations (samples x scenes): small enough for a steady progress
#: bar and little lost work on interruption, large enough that scheduling costs nothing.
MAX_CHUNK_EVALUATIONS = 64


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


def evaluate_batch(scenes, solver_options: SolverOptions | Mapping | None = None, *,
                   base: Scene | str | None = None) -> BatchResult:
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

    Returns
    -------
    BatchResult
        In the batch's order. Invalid inputs and solver exceptions give status ``failed`` with
        the reason; nothing is dropped.
    """
    from skidmc.solver import critical_height

    if hasattr(solver_options, "as_kwargs"):  # a SolverOptions
        kwargs = solver_options.as_kwargs()
    else:
        kwargs = dict(solver_options or {})
    if isinstance(base, str):
        from skidmc.presets import get_preset

        base = get_preset(base)
    rows = _rows(scenes)
    m = len(rows)
    out = BatchResult(
        critical_height=np.full(m, np.nan), status=np.empty(m, dtype=object),
        evaluations=np.zeros(m, dtype=np.int32), flags=np.full(m, "", dtype=object),
        failure_reason=np.full(m, "", dtype=object), wall_time=np.zeros(m),
        inputs={k: np.full(m, np.nan) for k in NUMERIC_KEYS},
    )
    base_values = base.as_dict() if base is not None else {}
    for i, row in enumerate(rows):
        try:
            scene = row if isinstance(row, Scene) else make_scene(row, preset=base)
        except Exception as exc:  # noqa: BLE001 - an invalid sample fails alone, not the run
            given = {**base_values, **(row if isinstance(row, Mapping) else {})}
            for k in NUMERIC_KEYS:
                if isinstance(given.get(k), (int, float)):
                    out.inputs[k][i] = given[k]
            out.status[i] = "failed"
            out.failure_reason[i] = f"invalid inputs: {type(exc).__name__}: {exc}"
            continue
        values = scene.as_dict()
        for k in NUMERIC_KEYS:
            out.inputs[k][i] = values[k]
        t0 = time.perf_counter()
        (out.critical_height[i], out.status[i], out.evaluations[i], out.flags[i],
         out.failure_reason[i]) = _solve(critical_height, scene, kwargs)
        out.wall_time[i] = time.perf_counter() - t0
    return out


# --- chunks -----------------------------------------------------------------------------------


@dataclasses.dataclass
class _Chunk:
    """What a worker needs for samples ``start:stop``: base scenes and each scene's overrides."""

    start: int
    stop: int
    scenes: tuple[Scene, ...]
    overrides: list[dict[str, np.ndarray]]
    options: SolverOptions
    isolated: bool = False  # a retry of one sample after a worker died


def _evaluate_chunk(chunk: _Chunk) -> list[BatchResult]:
    """Worker entry point (module level: picklable for processes and dask)."""
    return [evaluate_batch(ov, chunk.options, base=sc)
            for sc, ov in zip(chunk.scenes, chunk.overrides)]


def _failed_results(chunk: _Chunk, reason: str) -> list[BatchResult]:
    """Results marking every sample of a chunk failed (the worker died), inputs as given."""
    out = []
    for sc, ov in zip(chunk.scenes, chunk.overrides):
        m = chunk.stop - chunk.start
        inputs = {k: np.full(m, v) for k, v in sc.as_dict().items() if k in NUMERIC_KEYS}
        inputs.update({k: np.asarray(v, dtype=float) for k, v in ov.items()})
        out.append(BatchResult(
            critical_height=np.full(m, np.nan), status=np.full(m, "failed", dtype=object),
            evaluations=np.zeros(m, dtype=np.int32), flags=np.full(m, "", dtype=object),
            failure_reason=np.full(m, reason, dtype=object), wall_time=np.zeros(m),
            inputs=inputs))
    return out


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


class _Processes:
    """Local worker processes (spawn: safe with threads, the same on every platform)."""

    def __init__(self, workers: int) -> None:
        self.workers = workers
        self._pool = self._new()

    def _new(self):
        return cf.ProcessPoolExecutor(self.workers,
                                      mp_context=multiprocessing.get_context("spawn"))

    def submit(self, fn, arg):
        return self._pool.submit(fn, arg)

    def wait_first(self, futures):
        return cf.wait(futures, return_when=cf.FIRST_COMPLETED).done

    def restart(self) -> None:
        self._pool.shutdown(wait=False, cancel_futures=True)
        self._pool = self._new()

    def shutdown(self):
        self._pool.shutdown(wait=False, cancel_futures=True)


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
        Wall time of the evaluation loop [s].
    solver_time : float
        Sum of the per-sample solver wall times [s].
    workers : int
        Parallel slots used.
    """

    path: Path
    n_rows: int
    n_scenes: int
    evaluated: int = 0
    status_counts: dict = dataclasses.field(default_factory=dict)
    wall_time: float = 0.0
    solver_time: float = 0.0
    workers: int = 1

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
        return (f"{self.evaluated} evaluations in {self.wall_time:.1f} s "
                f"({self.rate:.1f}/s on {self.workers} workers, "
                f"{100 * self.outside_solver:.1f}% outside the solver); {counts or 'nothing to do'}")


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
    if scheduler in (None, "local") and not use_dask:
        slots = workers or _default_workers()
        return _Inline() if slots == 1 else _Processes(slots)
    return _Dask(None if scheduler == "local" else scheduler, workers)


def execute_study(study: Study | str | os.PathLike, out=None, *, n: int | None = None,
                  workers: int | None = None, scheduler=None, use_dask: bool = False,
                  resume: bool = False, progress: bool | None = None,
                  chunk_size: int | None = None, command: str | None = None) -> RunReport:
    """Run a study to its result file; like :func:`run_study` but returns a :class:`RunReport`.

    See :func:`run_study` for the parameters; in addition `chunk_size` sets the samples per chunk
    (default: from the worker count, at most :data:`MAX_CHUNK_EVALUATIONS` evaluations) and
    `command` is the command line recorded in the file's history.
    """
    from skidmc import __version__
    from skidmc.storage import timestamp
    from skidmc.study import Study, load_study

    if not isinstance(study, Study):
        study = load_study(study)
    if n is not None:
        study = study.with_n(n)
    path = _resolve_out(study, out)
    command = command or f"run_study({study.file!r}, n={study.design.n})"
    report = RunReport(path=path, n_rows=study.n_rows, n_scenes=len(study.scenes))
    with _open_result_file(study, path, resume) as file:
        done = file.done()
        todo = int(np.count_nonzero(~done))
        if todo:
            file.add_history(f"{timestamp()} skidmc {__version__}: {command}: started with "
                             f"{study.n_rows - todo} of {study.n_rows} samples written")
            executor = _executor(scheduler, use_dask, workers)
            report.workers = executor.workers
            if chunk_size is None:
                chunk_size = max(1, min(MAX_CHUNK_EVALUATIONS // len(study.scenes),
                                        math.ceil(todo / (8 * executor.workers))))
            ranges = deque((s, min(s + chunk_size, study.n_rows))
                           for s in range(0, study.n_rows, chunk_size)
                           if not done[s:s + chunk_size].all())
            del done
            outcome = "interrupted"
            try:
                _evaluate_chunks(study, file, executor, ranges, report, progress)
                outcome = "finished"
            finally:
                executor.shutdown()
                file.add_history(f"{timestamp()} skidmc {__version__}: {outcome}: "
                                 f"{report.summary()}")
        if not file.complete and file.done().all():
            file.mark_complete()
    return report


def _evaluate_chunks(study: Study, file: EnsembleFile, executor, ranges: deque,
                     report: RunReport, progress: bool | None) -> None:
    """Send the chunks `ranges` to `executor` and write each one as soon as it is back.

    At most two chunks per worker are in flight, so memory does not grow with n. When a worker
    process dies (BrokenProcessPool, dask's KilledWorker) the chunks it took down are retried one
    sample at a time, each alone in flight, so that a sample that kills its worker again is
    known to be the culprit and is recorded as failed while every other sample is evaluated.
    """
    from tqdm.auto import tqdm

    from skidmc.sampling import StudySampler

    sampler = StudySampler(study)
    base_scenes = tuple(sc.scene for sc in study.scenes)
    n_scenes = len(base_scenes)
    names = [spec.name for spec in file.variables]

    def submit(start: int, stop: int, isolated: bool = False) -> None:
        draws = sampler.draw(start, stop)
        overrides = [{k: v for k, v in d.items() if k in SI_UNITS} for d in draws]
        chunk = _Chunk(start, stop, base_scenes, overrides, study.solver, isolated)
        in_flight[executor.submit(_evaluate_chunk, chunk)] = (draws, chunk)

    todo = sum(b - a for a, b in ranges)
    bar = tqdm(total=study.n_rows * n_scenes, initial=(study.n_rows - todo) * n_scenes,
               unit="sample", desc=study.name, file=sys.stderr, dynamic_ncols=True,
               smoothing=0.05, disable=True if progress is False else
               (None if progress is None else False))  # None: only on a terminal
    in_flight: dict = {}
    retry: deque = deque()  # single samples to rerun alone after a worker died
    t0 = time.perf_counter()
    try:
        while ranges or retry or in_flight:
            if retry and not in_flight:
                submit(*retry.popleft(), isolated=True)
            while ranges and not retry and len(in_flight) < 2 * executor.workers:
                submit(*ranges.popleft())
            for fut in executor.wait_first(list(in_flight)):
                if fut not in in_flight:  # requeued after a worker died
                    continue
                draws, chunk = in_flight.pop(fut)
                try:
                    results = fut.result()
                except Exception as exc:
                    if not _worker_died(exc):
                        raise
                    if not chunk.isolated:
                        retry.extend((i, i + 1) for i in range(chunk.start, chunk.stop))
                        for other, (_, lost) in list(in_flight.items()):
                            if not (other.done() and other.exception() is None):
                                in_flight.pop(other)  # taken down with the pool: rerun alone
                                retry.extend((i, i + 1) for i in range(lost.start, lost.stop))
                        executor.restart()
                        continue
                    executor.restart()
                    results = _failed_results(chunk, "worker process died while evaluating "
                                              f"this sample ({exc!r})")
                file.write_chunk(chunk.start, chunk.stop,
                                 _columns(names, study.scene_dimension, draws, results))
                report.evaluated += (chunk.stop - chunk.start) * n_scenes
                for res in results:
                    report.solver_time += float(res.wall_time.sum())
                    for s in res.status:
                        report.status_counts[s] = report.status_counts.get(s, 0) + 1
                bar.update((chunk.stop - chunk.start) * n_scenes)
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
