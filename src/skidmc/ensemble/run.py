"""The ensemble runner: a study's samples, evaluated in chunks, written as they finish.

Two levels:

* :func:`evaluate_batch` evaluates any batch of scenes (or input rows on a base scene) that a
  caller hands it and returns one status per sample; nothing about designs or files. Adaptive
  methods (subset simulation, importance sampling) call it with the batch they chose. With
  ``workers > 1`` the batch goes in chunks to local worker processes that stay warm between
  calls (:func:`shutdown_workers` ends them), through the same chunk machinery as a study.
* :func:`run_study` (``skidmc run``) draws a study's design chunk by chunk
  (:class:`skidmc.ensemble.sampling.StudySampler`), sends the chunks to local worker processes
  (:class:`concurrent.futures.ProcessPoolExecutor`, spawn start method) or to a
  :mod:`dask.distributed` cluster, and writes each finished chunk to the result file
  (:class:`skidmc.ensemble.storage.EnsembleFile`) at once, so memory does not grow with n and an
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

import dataclasses
import math
import os
import sys
import time
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from skidmc.ensemble.evaluate import BatchResult, solver_kwargs
from skidmc.ensemble.executors import (
    POOLS,
    Chunk,
    ChunkOut,
    DaskExecutor,
    InlineExecutor,
    ProcessExecutor,
    default_workers,
)
from skidmc.ensemble.schedule import Schedule, run_chunks
from skidmc.scene import SI_UNITS

if TYPE_CHECKING:
    from skidmc.ensemble.storage import EnsembleFile
    from skidmc.ensemble.study import Study

__all__ = [
    "DRAW_BLOCK",
    "RunReport",
    "execute_study",
    "run_study",
]



#: Samples the parent draws from the design at once (then hands out slices as chunks).
DRAW_BLOCK = 1024


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
    from skidmc.ensemble.storage import default_path

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
    from skidmc.ensemble.storage import EnsembleFile, StorageError, inspect_file

    if not path.exists():
        from skidmc.ensemble.sampling import MC_BLOCK

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
        slots = workers or default_workers()
        if slots == 1:
            return InlineExecutor(), True
        if slots in POOLS:
            return POOLS[slots], False
        return ProcessExecutor(slots), True
    return DaskExecutor(None if scheduler == "local" else scheduler, workers), True


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
    if scheduler in (None, "local") and not use_dask and (workers or default_workers()) > 1:
        executor, owned = _executor(scheduler, use_dask, workers)
        t0 = time.perf_counter()
    try:
        from skidmc.ensemble.storage import timestamp
        from skidmc.ensemble.study import Study, load_study

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
                schedule = Schedule(todo, len(study.scenes), executor.workers, chunk_size,
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


def _evaluate_chunks(study: Study, file: EnsembleFile, executor, schedule: Schedule,
                     report: RunReport, progress: bool | None, t0: float | None = None) -> None:
    """Send the study's chunks to `executor` (:func:`run_chunks`) and write each one as soon
    as it is back; `t0` is when the workers were launched (default: now)."""
    from tqdm.auto import tqdm

    from skidmc.ensemble.sampling import StudySampler

    draws = _Draws(StudySampler(study), study.n_rows)
    base_scenes = tuple(sc.scene for sc in study.scenes)
    options = solver_kwargs(study.solver)
    n_scenes = len(base_scenes)
    names = [spec.name for spec in file.variables]
    t0 = time.perf_counter() if t0 is None else t0
    t_wall = time.time() - (time.perf_counter() - t0)  # t0 on the clock the workers share

    def make_chunk(start: int, stop: int, isolated: bool):
        drawn = draws(start, stop)
        overrides = [{k: v for k, v in d.items() if k in SI_UNITS} for d in drawn]
        chunk = Chunk(start, stop, base_scenes, overrides, options, isolated)
        return chunk, (drawn, time.perf_counter() - t0)

    def consume(chunk: Chunk, context, results: list[BatchResult], out: ChunkOut) -> None:
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
        run_chunks(executor, schedule, make_chunk, consume)
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
        A study file or a loaded :class:`~skidmc.ensemble.study.Study`.
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
