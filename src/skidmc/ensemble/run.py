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

The target file. A run never overwrites what it did not make (:func:`_plan`): a missing file is
created; a complete file of this very study (same study text hash, same n) is up to date, verified
(checksums) and reported, and nothing is computed; ``resume`` continues this study's unfinished
file; ``force`` recomputes this study's file (any version, any n, or a damaged file) into
``<name>.new`` beside it, renamed over it only when complete, so an interrupted forced run loses
nothing (the next forced run continues the ``.new`` file); everything else (a foreign file,
another study's, an unfinished file without ``resume``) is refused with a message saying what to
do. A run that stops before writing any sample (an error, Ctrl-C) removes the file it created.
Ctrl-C raises :class:`RunInterrupted`, whose ``hint`` says what was kept.

The solver is injectable: ``solver=`` (default :func:`skidmc.solver.critical_height`) travels
with every chunk to the worker that evaluates it (:mod:`skidmc.ensemble.evaluate`).

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
import signal
import sys
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from skidmc.ensemble.evaluate import BatchResult, resolve_solver, solver_kwargs
from skidmc.ensemble.executors import (
    LOCAL_SCHEDULERS,
    POOLS,
    Chunk,
    ChunkOut,
    DaskExecutor,
    InlineExecutor,
    ProcessExecutor,
    ThreadExecutor,
    check_scheduler,
    default_workers,
)
from skidmc.ensemble.schedule import Schedule, run_chunks
from skidmc.errors import SkidmcError
from skidmc.scene import SI_UNITS

if TYPE_CHECKING:
    from skidmc.ensemble.storage import EnsembleFile
    from skidmc.ensemble.study import Study

__all__ = [
    "DRAW_BLOCK",
    "OutputLock",
    "RunInterrupted",
    "RunReport",
    "RunSize",
    "check_size",
    "execute_study",
    "lock_output",
    "measured_rate",
    "run_size",
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
    action : str
        What the run did with its file: ``"new"``, ``"resume"``, ``"replace"`` (``force``) or
        ``"up_to_date"`` (a complete file of this very study was there: nothing computed).
    completed : str
        For ``"up_to_date"``: when the file was completed (its ``completed`` attribute).
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
    action: str = "new"
    completed: str = ""

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


def _target_exists(study, out) -> bool:
    """Whether the result file of a run seems to exist, judged before the study is loaded
    (its name read from the TOML file when the path depends on it); True when unsure."""
    if out is not None and Path(out).suffix in (".h5", ".nc", ".hdf5"):
        return Path(out).exists()
    if hasattr(study, "name"):  # a Study
        return _resolve_out(study, out).exists()
    try:
        import tomllib

        with open(study, "rb") as f:
            name = tomllib.load(f)["study"]["name"]
    except Exception:  # noqa: BLE001 - unsure: the study's own loading reports any error
        return True
    target = Path("results") / str(name) / "ensemble.h5" if out is None else \
        Path(out) / "ensemble.h5"
    return target.exists()


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


def _plan(study: Study, path: Path, resume: bool, force: bool) -> str:
    """What to do with the target, without touching it: ``"new"``, ``"resume"``,
    ``"up_to_date"`` (a complete run of this very study: same text hash, same n) or
    ``"replace"`` (``force``: compute into a new file that replaces this one when complete).

    Raises
    ------
    StorageError
        The target is refused: a foreign file, another study's run, this study's unfinished run
        without `resume` or `force`, a damaged file without `force`.
    """
    from skidmc.ensemble.storage import StorageError, inspect_file

    if not path.exists():
        return "new"
    if path.is_dir():
        raise StorageError(path, "is a folder; give a file name ending in .h5 or a folder "
                           "that does not hold one of that name")
    try:
        info = inspect_file(path)
    except StorageError as exc:
        if force and exc.damaged:
            return "replace"
        if not exc.damaged:  # a foreign file: say what a run does with it
            raise StorageError(path, f"{exc.reason}; refusing to overwrite it (choose another "
                               "--out)") from None
        raise
    if not info["skidmc"]:
        raise StorageError(path, "exists and is not a skidmc ensemble file; refusing to "
                           "overwrite it, even with --force (choose another --out)")
    name = info["study_name"]
    same = info["study_sha256"] == study.sha256 and info["n_rows"] == study.n_rows
    if not same:
        if name != study.name:
            raise StorageError(path, f"holds a run of another study ({name!r}, this is "
                               f"{study.name!r}); refusing to overwrite it, even with --force: "
                               "choose another --out")
        if force:
            return "replace"
        what = ("another version of this study (its text changed)"
                if info["study_sha256"] != study.sha256 else
                f"{info['n_rows']} samples per scene, this run asks for {study.n_rows} "
                "(a different --n?)")
        raise StorageError(path, f"holds a run of study {name!r} with {what}; recompute it "
                           "with --force (the old file stays until the new one is complete) "
                           "or choose another --out")
    if force:
        return "replace"
    if info["complete"]:
        return "up_to_date"
    if resume:
        return "resume"
    raise StorageError(path, f"holds an unfinished run of study {name!r} "
                       f"({info['done']} of {info['n_rows']} samples written); continue it with "
                       "--resume, recompute it with --force, or choose another --out")


def _open_result_file(study: Study, path: Path, action: str, work: Path) -> EnsembleFile:
    """The file to write: a new one, this study's unfinished one (`resume`), or, for
    ``"replace"``, the new file `work` beside the old one (continued if an interrupted --force
    run of the same study left it)."""
    from skidmc.ensemble.sampling import MC_BLOCK
    from skidmc.ensemble.storage import EnsembleFile, StorageError

    if action == "resume":
        return EnsembleFile.resume(path, study)
    if action == "replace" and work.exists():
        try:
            return EnsembleFile.resume(work, study)
        except StorageError:  # ours by name, not this study's or damaged: start it again
            work.unlink()
    attrs = {"mc_block": np.int64(MC_BLOCK)} if study.design.method == "mc" else {}
    return EnsembleFile.create(work if action == "replace" else path, study, attrs=attrs)


def _executor(scheduler, use_dask: bool, workers: int | None):
    """(executor, owned): owned executors are shut down after the run; a warm pool that
    :func:`evaluate_batch` left running is used as it is and left running."""
    if scheduler in LOCAL_SCHEDULERS and not use_dask:
        slots = workers or default_workers()
        if slots == 1:
            return InlineExecutor(), True
        if scheduler == "threads":
            return ThreadExecutor(slots), True
        if slots in POOLS:
            return POOLS[slots], False
        return ProcessExecutor(slots), True
    return DaskExecutor(None if scheduler in LOCAL_SCHEDULERS else scheduler, workers), True


class RunInterrupted(KeyboardInterrupt):
    """A run stopped by Ctrl-C (SIGINT); `hint` says what was kept and how to go on.

    Parameters
    ----------
    hint : str
        One sentence, e.g. ``"12 of 256 samples are saved in x.h5; continue with --resume"``.
    """

    def __init__(self, hint: str) -> None:
        self.hint = hint
        super().__init__(hint)


#: Scene evaluations per second of one worker at the default rtol, as measured by
#: ``benchmarks/throughput.py`` (results/benchmarks/throughput.md: 350-380/s in process at
#: rtol 1e-2 on the 2-CPU development machine): the rate assumed where none is measured (a
#: small run, the GPU backend, a run that cannot fit the disk); only for the estimated time
#: printed before a run and asked about (:func:`run_size`), never for a result.
EVALUATIONS_PER_SECOND_PER_WORKER = 300.0

#: A run whose time at :data:`EVALUATIONS_PER_SECOND_PER_WORKER` is this long or more [s] has
#: its rate measured on its own first heights (:func:`measured_rate`) before it starts: the
#: rate differs by two decades between studies (rtol 1e-2 against 1e-4, scenes whose margin
#: jumps, layered targets), so neither a fixed rate nor one a different study recorded says
#: how long this one takes. Below, the run is over in seconds and the measurement (one
#: warm-up height, the kernels loaded in this process) would be a large part of it.
MEASURE_FROM_SECONDS = 2.0

#: The measurement: at most this many timed heights, after one untimed warm-up (which loads
#: the compiled kernels), and no more timed heights once this many seconds are spent.
MEASURE_HEIGHTS = 4
MEASURE_SECONDS = 3.0

#: A run above this many bytes on disk or this many seconds (estimated) needs a confirmation
#: (``skidmc run --yes``, or an answer at a terminal).
LARGE_RUN_BYTES = 2 * 1024**3
LARGE_RUN_SECONDS = 6 * 3600.0

#: Disk space a run leaves free, beyond its file [bytes] (HDF5 metadata, the compacted copy).
DISK_MARGIN_BYTES = 64 * 1024**2


class RunTooLarge(SkidmcError, ValueError):
    """A run refused for its size (it cannot fit the free disk, or a large run was not
    confirmed); ``str(err)`` gives its samples, bytes and estimated time."""


class BackendUnavailable(SkidmcError, ValueError):
    """The study's ``solver.backend`` cannot run on this machine (no usable CUDA GPU)."""


class AllSamplesFailed(SkidmcError):
    """Every sample a run evaluated failed; ``str(err)`` counts the reasons."""


def failure_counts(reasons) -> str:
    """``"8 x RuntimeError: boom; 2 x SolverError: ..."``: the distinct reasons, most frequent
    first (at most 3, the rest counted)."""
    from collections import Counter

    counts = Counter(str(r) for r in reasons).most_common()
    shown = "; ".join(f"{n} x {reason[:256]}" for reason, n in counts[:3])
    if len(counts) > 3:
        shown += f"; and {len(counts) - 3} other reasons"
    return shown


@dataclasses.dataclass(frozen=True)
class RunSize:
    """How large a run is, before it starts.

    Attributes
    ----------
    n_rows, n_scenes : int
        Samples per scene, scenes.
    bytes : int
        Size of the result file [bytes] (allocated in full when it is created).
    seconds : float
        Estimated wall time [s]: the evaluations at `rate` per worker.
    free_bytes : int
        Free space of the disk that holds the result file [bytes].
    workers : int
    rate : float
        Evaluations per second of one worker [1/s] the estimate uses.
    basis : str
        Where `rate` comes from: ``"measured: 4 heights of this study in 0.12 s"`` or
        ``"assumed ..."`` (:data:`EVALUATIONS_PER_SECOND_PER_WORKER`); printed with the estimate.
    what : str
        What the size is of, when not simply the run (a growing Sobol' study: up to n_max).
    """

    n_rows: int
    n_scenes: int
    bytes: int
    seconds: float
    free_bytes: int
    workers: int
    rate: float = EVALUATIONS_PER_SECOND_PER_WORKER
    basis: str = ""
    what: str = ""

    @property
    def evaluations(self) -> int:
        return self.n_rows * self.n_scenes

    @property
    def large(self) -> bool:
        return self.bytes > LARGE_RUN_BYTES or self.seconds > LARGE_RUN_SECONDS

    def describe(self) -> str:
        basis = f" ({self.rate:.3g} heights/s per worker, {self.basis})" if self.basis else ""
        return (f"{self.what}{self.n_rows:,} samples x {self.n_scenes} scenes = "
                f"{self.evaluations:,} evaluations, a result file of {_bytes(self.bytes)}, about "
                f"{_duration(self.seconds)} on {self.workers} workers{basis}")


def _bytes(n: float) -> str:
    for unit in ("B", "KB", "MB", "GB", "TB", "PB"):
        if abs(n) < 1000 or unit == "PB":
            return f"{n:.3g} {unit}"
        n /= 1000
    return f"{n:.3g} PB"  # pragma: no cover


def _duration(seconds: float) -> str:
    for unit, length in (("years", 365.25 * 86400), ("days", 86400), ("h", 3600), ("min", 60)):
        if seconds >= length:
            return f"{seconds / length:.3g} {unit}"
    return f"{seconds:.2g} s"


def run_size(study: Study, path: Path, workers: int | None = None, *,
             solver: Callable | None = None, measure: bool = True,
             evaluations: int | None = None) -> RunSize:
    """The size of a run of `study` into `path` (see :class:`RunSize`), from the file's
    layout (:func:`skidmc.ensemble.storage.estimated_bytes`) and a rate per worker: measured
    on the study's own first heights (:func:`measured_rate`, with `solver`) where the run
    is long enough for it to matter (:data:`MEASURE_FROM_SECONDS`) and fits the disk,
    else :data:`EVALUATIONS_PER_SECOND_PER_WORKER`. `evaluations`: those still to compute,
    when not all of the study's (a run that continues one)."""
    import shutil

    from skidmc.ensemble.storage import estimated_bytes

    slots = workers or default_workers()
    if study.solver.backend != "cpu":
        slots = 1
    where = Path(path).absolute().parent
    while not where.exists() and where != where.parent:
        where = where.parent
    try:
        free = shutil.disk_usage(where).free
    except OSError:
        free = -1
    size_bytes = estimated_bytes(study)
    todo = study.n_rows * len(study.scenes) if evaluations is None else evaluations
    rate = EVALUATIONS_PER_SECOND_PER_WORKER
    basis = (f"assumed: the rate of benchmarks/throughput.py at rtol 1e-2, "
             f"{EVALUATIONS_PER_SECOND_PER_WORKER:g}/s; not measured")
    fits = free < 0 or size_bytes + DISK_MARGIN_BYTES <= free
    if measure and fits and study.solver.backend == "cpu" \
            and todo / (rate * slots) >= MEASURE_FROM_SECONDS:
        measured = measured_rate(study, solver)
        if measured is not None:
            rate, count, seconds = measured
            basis = (f"measured: {count} heights of this study in {seconds:.2g} s in this "
                     "process")
    return RunSize(study.n_rows, len(study.scenes), size_bytes, todo / (rate * slots), free,
                   slots, rate, basis)


def measured_rate(study: Study, solver: Callable | None = None,
                  heights: int = MEASURE_HEIGHTS,
                  budget: float = MEASURE_SECONDS) -> tuple[float, int, float] | None:
    """Heights per second [1/s] of one worker on this study, timed in this process: first one
    untimed warm-up height per scene (its first sample: the compiled kernels a scene needs
    load, or compile, on its first height; a layered target needs others than a homogeneous
    one), then its next samples, scene after scene as a run evaluates them; at most `heights`
    timed, and no more once `budget` seconds [s] are spent. Returns (rate, heights timed,
    seconds) or None when nothing could be timed (a study of one row per scene). The heights
    are computed again by the run (a few seconds at most)."""
    from skidmc.ensemble.evaluate import evaluate_here
    from skidmc.ensemble.sampling import StudySampler

    n_scenes = len(study.scenes)
    rows = min(study.n_rows, 1 + -(-heights // n_scenes))
    if rows < 2:
        return None
    drawn = StudySampler(study).draw(0, rows)
    options = solver_kwargs(study.solver)
    options.pop("backend", None)

    def solve(j: int, i: int) -> float:
        columns = {key: v[i:i + 1] for key, v in drawn[j].items() if key in SI_UNITS}
        t0 = time.perf_counter()
        evaluate_here(columns, options, study.scenes[j].scene, solver)
        return time.perf_counter() - t0

    for j in range(n_scenes):
        solve(j, 0)  # the warm-ups
    timed, spent = 0, 0.0
    for i, j in [(i, j) for i in range(1, rows) for j in range(n_scenes)][:heights]:
        spent += solve(j, i)
        timed += 1
        if spent >= budget:
            break
    if timed == 0 or spent <= 0.0:
        return None
    return timed / spent, timed, spent


def check_size(size: RunSize, path: Path, confirm: Callable[[RunSize], bool] | None) -> None:
    """Refuse a run that cannot fit the free disk; then ask `confirm` (it is told the size,
    and answers whether to go on; :attr:`RunSize.large` says whether to ask a person).

    Raises
    ------
    RunTooLarge
        The file would not fit the free disk, or `confirm` said no to a large run.
    """
    if size.free_bytes >= 0 and size.bytes + DISK_MARGIN_BYTES > size.free_bytes:
        raise RunTooLarge(f"{path}: the run cannot fit the free disk: {size.describe()}, but "
                          f"only {_bytes(size.free_bytes)} free; lower --n (or n in the "
                          "study) or choose another --out")
    if confirm is not None and not confirm(size):
        raise RunTooLarge(f"{path}: the run was not confirmed: {size.describe()}; run it "
                          "with --yes, or lower --n (or n in the study)")


def _interrupted_hint(path: Path, file_path: Path, action: str, done: int, n_rows: int,
                      removed: bool) -> str:
    if removed:
        return "nothing was written (the new file was removed)"
    if action == "replace":
        return (f"{path} is unchanged; the new run's {done} of {n_rows} samples are in "
                f"{file_path}: run again with --force to continue it")
    return f"{done} of {n_rows} samples are saved in {path}; continue with --resume"


def execute_study(study: Study | str | os.PathLike, out=None, *, n: int | None = None,
                  workers: int | None = None, scheduler=None, use_dask: bool = False,
                  resume: bool = False, force: bool = False, progress: bool | None = None,
                  chunk_size: int | None = None, command: str | None = None,
                  timeline: bool = False, solver: Callable | None = None,
                  confirm: Callable[[RunSize], bool] | None = None) -> RunReport:
    """Run a study to its result file; like :func:`run_study` but returns a :class:`RunReport`.

    See :func:`run_study` for the parameters; in addition `chunk_size` sets the samples per chunk
    (default: sized by time, see the module docstring), `command` is the command line recorded
    in the file's history, and `timeline` records per-chunk timings in the report. Before a
    file is created, the run's size (:func:`run_size`) is checked: a run that cannot fit the free
    disk is refused (:class:`RunTooLarge`); then `confirm`, given the :class:`RunSize`, decides
    (the CLI prints the size and asks about a large run, :data:`LARGE_RUN_BYTES`,
    :data:`LARGE_RUN_SECONDS`); without `confirm` it runs.

    Raises
    ------
    RunInterrupted
        A KeyboardInterrupt (Ctrl-C), with what was kept in its ``hint``.
    """
    from skidmc import __version__
    from skidmc.ensemble.storage import timestamp

    if workers is not None and (isinstance(workers, bool) or not isinstance(workers, int)
                                or workers < 1):
        raise ValueError(f"workers must be an integer >= 1 (or None: all CPUs), got {workers!r}")
    if resume and force:
        raise ValueError("resume and force exclude each other: resume continues the file, "
                         "force recomputes it")
    scheduler = check_scheduler(scheduler)
    if solver is not None:
        resolve_solver(solver)  # a TypeError now rather than one per sample
    # Local worker processes start first, so that their start-up overlaps the loading of the
    # study and the opening of the file, unless the target file exists already (it may be up to
    # date: then no worker is wanted at all).
    executor, owned, t0 = None, False, None
    lock = None
    if scheduler in LOCAL_SCHEDULERS and not use_dask and (workers or default_workers()) > 1 \
            and not _target_exists(study, out):
        executor, owned = _executor(scheduler, use_dask, workers)
        t0 = time.perf_counter()
    file = None
    try:
        from skidmc.ensemble.study import Study, load_study

        if not isinstance(study, Study):
            study = load_study(study)
        if n is not None:
            study = study.with_n(n)
        if study.solver.backend == "cuda" and solver is None:
            from skidmc.solver.cuda import cuda_status

            usable, why = cuda_status()
            if not usable:  # before any file is made
                raise BackendUnavailable(
                    f"{study.file}: solver.backend = 'cuda' cannot run here: {why.split(':')[0]}"
                    "; use backend = 'cpu' (the same kernel on the CPUs) or a machine with a "
                    "CUDA GPU")
        if study.solver.backend != "cpu" and scheduler in LOCAL_SCHEDULERS and not use_dask:
            # The GPU backend solves each chunk in one launch: one local process drives the GPU
            # (worker processes would only queue on it).
            workers = 1
            if executor is not None and owned:
                executor.shutdown()
            executor, owned = None, False
        path = _resolve_out(study, out)
        lock = lock_output(path)
        command = command or f"run_study({study.file!r}, n={study.design.n})"
        report = RunReport(path=path, n_rows=study.n_rows, n_scenes=len(study.scenes),
                           timeline=[] if timeline else None)
        action = _plan(study, path, resume, force)
        report.action = action
        if action == "up_to_date":
            from skidmc.ensemble.storage import inspect_file

            info = inspect_file(path, verify=True)  # a damaged file is not up to date
            report.completed = str(info.get("completed", ""))
            return report
        # An owned dask cluster is reached before any file is made, so that an unreachable
        # scheduler leaves nothing behind.
        if executor is None and not (scheduler in LOCAL_SCHEDULERS and not use_dask):
            executor, owned = _executor(scheduler, use_dask, workers)
        work = path.with_name(path.name + ".new")  # --force: the new file until complete
        created = action == "new" or (action == "replace" and not work.exists())
        if created:
            check_size(run_size(study, path, workers, solver=solver), path, confirm)
        file = _open_result_file(study, path, action, work)
        todo = ~file.done()
        try:
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
                    with _DeferredInterrupt() as interrupt:
                        _evaluate_chunks(study, file, executor, schedule, report, progress, t0,
                                         solver, interrupt.check)
                    outcome = "finished"
                finally:
                    file.add_history(f"{timestamp()} skidmc {__version__}: {outcome}: "
                                     f"{report.summary()}")
            if not file.complete and file.done().all():
                file.mark_complete()
        except BaseException as exc:
            try:
                done = int(file.done().sum())
            except Exception:  # noqa: BLE001 - only for the message
                done = -1
            file.close()
            removed = created and done == 0
            if removed:  # nothing computed: leave no half-made file behind
                file.path.unlink(missing_ok=True)
            if isinstance(exc, KeyboardInterrupt) and not isinstance(exc, RunInterrupted):
                raise RunInterrupted(_interrupted_hint(path, file.path, action, done,
                                                       study.n_rows, removed)) from None
            raise
        complete = file.complete
        file.close()
        if complete:
            from skidmc.ensemble.storage import compact_file

            compact_file(file.path)  # never written again: the compact layout
        if action == "replace":
            os.replace(file.path, path)  # the old file is replaced only by a complete one
    except KeyboardInterrupt as exc:
        if isinstance(exc, RunInterrupted):
            raise
        raise RunInterrupted("nothing was written") from None
    finally:
        if file is not None:
            file.close()
        if executor is not None and owned:
            executor.shutdown()
        if lock is not None:
            lock.release()
    return report


class OutputLock:
    """This process's hold on one result file (see :func:`lock_output`); :meth:`release` ends
    it (also a kill does: the kernel drops an ``flock`` with its process)."""

    def __init__(self, key, fd: int, lock_path: Path) -> None:
        self._key, self._fd, self.lock_path = key, fd, lock_path

    def release(self) -> None:
        """Let go of the file (once; a nested hold of the same file by this process lets go
        when the outermost one does)."""
        if self._fd is None:
            return
        held = _HELD.get(self._key)
        if held is not None:
            held[1] -= 1
            if held[1] > 0:  # an outer hold of this process still runs
                self._fd = None
                return
            del _HELD[self._key]
            try:
                self.lock_path.unlink()  # still ours: we hold its lock
            except OSError:
                pass
            os.close(held[0])
        self._fd = None

    def __enter__(self) -> OutputLock:  # noqa: PYI034 - not subclassed
        return self

    def __exit__(self, *exc) -> None:
        self.release()


#: The result files this process holds: (device, inode of the lock file, thread) -> [fd, holds].
_HELD: dict = {}


def lock_output(path: Path) -> OutputLock | None:
    """Hold the result file `path` for this run: an exclusive ``flock`` on ``.<name>.lock``
    beside it, made for the run and removed when it ends (a run killed with -9 leaves it, an
    empty file that the next run takes over). A second run on the same file (whatever path
    names it: the lock is on the file's inode) is refused at once with a clear message instead
    of an HDF5 lock error or a missing ``.new.tmp``; runs on other files of the same folder go
    on side by side. The file's work files (``.new``, ``.compact``) share its hold. Nested
    holds of one file by one thread (a growing Sobol' study's steps) are counted, not refused;
    another thread of the same process is refused like another process.
    None where no lock can be made (the file's creation then says why).
    """
    import errno

    from skidmc.ensemble.storage import StorageError

    try:
        import fcntl
    except ImportError:  # pragma: no cover - not a POSIX system: no lock
        return None

    folder = path.absolute().parent
    lock_path = folder / f".{path.name}.lock"
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError:
        return None
    for _ in range(10):  # retried only when another run removed the file between open and lock
        try:
            fd = os.open(lock_path, os.O_RDWR | os.O_CREAT, 0o644)
        except OSError:
            return None
        st = os.fstat(fd)
        key = (st.st_dev, st.st_ino, threading.get_ident())
        if key in _HELD:  # this thread holds it already (a nested run)
            os.close(fd)
            _HELD[key][1] += 1
            return OutputLock(key, _HELD[key][0], lock_path)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError as exc:
            os.close(fd)
            if exc.errno in (errno.EWOULDBLOCK, errno.EAGAIN, errno.EACCES):
                raise StorageError(path, "another skidmc run holds this output (a run in "
                                   f"progress writes it: {lock_path.name} is locked); wait for "
                                   "it to end or choose another --out") from None
            return None
        try:
            same = os.stat(lock_path).st_ino == st.st_ino
        except OSError:
            same = False
        if same:
            _HELD[key] = [fd, 1]
            return OutputLock(key, fd, lock_path)
        os.close(fd)  # the holder removed it as we opened it: take the new one
    return None


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


class _DeferredInterrupt:
    """SIGINT handling of the chunk loop: the first Ctrl-C stops the run at the next safe point
    (:meth:`check`, after a chunk is written), not wherever Python happens to be: a
    KeyboardInterrupt raised inside a weakref callback or a ``__del__`` (the executor's
    machinery has both) is printed as "Exception ignored" and lost, and the run went on. A second
    Ctrl-C raises at once. Installed only from the main thread over Python's default handler
    (a custom handler, e.g. a notebook's, is left alone)."""

    def __init__(self) -> None:
        self.requested = False
        self._old = None

    def __enter__(self) -> _DeferredInterrupt:  # noqa: PYI034 - not subclassed
        if threading.current_thread() is threading.main_thread() \
                and signal.getsignal(signal.SIGINT) is signal.default_int_handler:
            self._old = signal.signal(signal.SIGINT, self._handle)
        return self

    def _handle(self, signum, frame) -> None:
        if self.requested:
            raise KeyboardInterrupt
        self.requested = True

    def check(self) -> None:
        """Raise KeyboardInterrupt if Ctrl-C was pressed."""
        if self.requested:
            raise KeyboardInterrupt

    def __exit__(self, *exc) -> None:
        if self._old is not None:
            signal.signal(signal.SIGINT, self._old)


def _evaluate_chunks(study: Study, file: EnsembleFile, executor, schedule: Schedule,
                     report: RunReport, progress: bool | None, t0: float | None = None,
                     solver: Callable | None = None, check_interrupt=None) -> None:
    """Send the study's chunks to `executor` (:func:`run_chunks`) and write each one as soon
    as it is back; `t0` is when the workers were launched (default: now); `solver` as in
    :func:`run_study`; `check_interrupt()` is called after each chunk is written (it raises
    KeyboardInterrupt to stop)."""
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
        chunk = Chunk(start, stop, base_scenes, overrides, options, isolated, solver)
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
        if check_interrupt is not None:
            check_interrupt()

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
              chunk_size: int | None = None, force: bool = False,
              solver: Callable | None = None) -> Path:
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
        None or ``"local"``: local processes; ``"threads"``: `workers` threads of this process
        (no start-up, no isolation: :class:`~skidmc.ensemble.executors.ThreadExecutor`);
        ``"dask"``: a dask LocalCluster of `workers` processes; an address
        (``"tcp://host:8786"``) or a Client: that dask cluster (its workers must be able to
        import skidmc).
    resume : bool
        Continue an unfinished file of the same study (a missing file starts a new run).
    force : bool
        Recompute: the run writes a new file beside the target (``<name>.new``) and renames it
        over the target only when complete, so an interrupted forced run loses nothing (the next
        forced run continues the ``.new`` file). Replaces this study's file (any version of it,
        any n) or a damaged file; never a file of another study or a foreign file.
    progress : bool, optional
        Progress bar on stderr; None: only when stderr is a terminal.
    use_dask : bool
        Use a dask LocalCluster of `workers` processes (as ``scheduler="dask"``).
    chunk_size : int, optional
        Samples per chunk (does not change any result).
    solver : callable, optional
        Instead of :func:`skidmc.solver.critical_height` (see
        :func:`skidmc.ensemble.batch.evaluate_batch`); with worker processes it must pickle
        (a module-level function).

    Returns
    -------
    Path
        The result file.

    Raises
    ------
    StudyError
        The study is invalid.
    StorageError
        The target exists and is not this study's run to resume or replace (a foreign file,
        another study's, an unfinished or damaged file without `resume`/`force`), or the file
        cannot be created there: nothing is overwritten. A complete file of this very study (same
        text, same n) is not an error: it is up to date and nothing is computed.
    SchedulerError
        `scheduler` is malformed or no dask scheduler answers at it.
    RunInterrupted
        Ctrl-C; what was kept is in its ``hint``.
    """
    return execute_study(study_path_or_obj, out, n=n, workers=workers, scheduler=scheduler,
                         use_dask=use_dask, resume=resume, force=force, progress=progress,
                         chunk_size=chunk_size, solver=solver).path
