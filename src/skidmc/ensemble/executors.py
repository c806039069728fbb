"""Where chunks of samples are evaluated: in process, local worker processes, threads of this
process, or dask.

Local workers ignore SIGINT: a Ctrl-C at the terminal reaches the whole process group, and only
the parent acts on it (it stops handing out chunks, keeps what is written and says so in one line);
a worker finishes the chunk it holds and exits with the pool, without a traceback of its own.
"""

from __future__ import annotations

import atexit
import concurrent.futures as cf
import concurrent.futures.process  # noqa: F401  (cf.process: BrokenProcessPool; not loaded by cf)
import dataclasses
import math
import multiprocessing
import os
import re
import signal
import sys
import threading
import time
from collections.abc import Callable, Mapping

import numpy as np

from skidmc._system import available_cpus
from skidmc.ensemble.evaluate import BatchResult, empty_result, evaluate_here, record_given
from skidmc.errors import SkidmcError
from skidmc.scene import NUMERIC_KEYS, Scene

__all__ = [
    "CONNECT_TIMEOUT",
    "POOLS",
    "SCHEDULER_CHOICES",
    "Chunk",
    "ChunkOut",
    "DaskExecutor",
    "InlineExecutor",
    "LOCAL_SCHEDULERS",
    "ProcessExecutor",
    "SchedulerError",
    "ThreadExecutor",
    "check_scheduler",
    "default_workers",
    "evaluate_chunk",
    "failed_results",
    "shared_pool",
    "shutdown_workers",
    "worker_died",
]

#: Seconds to wait for a dask scheduler at an address before giving up.
CONNECT_TIMEOUT = 5.0

#: What ``--scheduler`` accepts, in words (for help and messages).
SCHEDULER_CHOICES = ("'local' (worker processes on this machine, the default), 'threads' "
                     "(threads of this process: no start-up, no isolation), 'dask' (a local "
                     "dask cluster of --workers processes) or the address of a running dask "
                     "scheduler, tcp://host:port")

#: Schedulers that run on this machine without dask.
LOCAL_SCHEDULERS = (None, "local", "threads")

_HOST = r"(\[[0-9a-fA-F:.]+\]|[A-Za-z0-9_.-]+)"
_ADDRESS = re.compile(rf"^((tcp|tls|ucx|inproc)://{_HOST}(:\d{{1,5}})?|{_HOST}:\d{{1,5}})/?$")


class SchedulerError(SkidmcError):
    """A ``--scheduler`` value that is malformed, or a dask scheduler that cannot be reached.

    Parameters
    ----------
    value : str
        The value given.
    reason : str
        What is wrong.
    """

    def __init__(self, value: object, reason: str) -> None:
        self.value = value
        self.reason = reason
        super().__init__(f"--scheduler {value!r}: {reason}")

    def __reduce__(self):
        return (type(self), (self.value, self.reason))


def check_scheduler(scheduler):
    """Validate a scheduler argument: None, ``"local"``, ``"dask"``, an address or a Client.

    Returns
    -------
    The value unchanged (an address without ``/`` at the end).

    Raises
    ------
    SchedulerError
        A string that is none of these.
    """
    if scheduler is None or not isinstance(scheduler, str):
        return scheduler
    text = scheduler.strip()
    if text in ("local", "threads", "dask"):
        return text
    if _ADDRESS.match(text):
        return text.rstrip("/")
    raise SchedulerError(scheduler, f"expected {SCHEDULER_CHOICES}")



@dataclasses.dataclass
class Chunk:
    """What a worker needs for samples ``start:stop``: base scenes and each scene's overrides.

    `overrides[j]` holds scene j's inputs: columns ``{key: array}`` (a study) or a list of rows
    (Scene objects or mappings; :func:`evaluate_batch`). `options` are plain keyword arguments,
    so that a worker never imports :mod:`skidmc.ensemble.study` (scipy.stats) to unpickle a chunk.
    """

    start: int
    stop: int
    scenes: tuple[Scene | None, ...]
    overrides: list
    options: dict
    isolated: bool = False  # a retry of one sample after a worker died
    solver: Callable | None = None  # None: skidmc.solver.critical_height


@dataclasses.dataclass
class ChunkOut:
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


def evaluate_chunk(chunk: Chunk) -> ChunkOut:
    """Worker entry point (module level: picklable for processes and dask)."""
    began = time.time()
    results = [evaluate_here(ov, chunk.options, sc, chunk.solver)
               for sc, ov in zip(chunk.scenes, chunk.overrides)]
    return ChunkOut(results, os.getpid(), _peak_rss_mib(), began, time.time())


def _worker_probe(_=None) -> tuple[int, float, float]:
    """(pid, peak RSS, current RSS [MiB]) of the worker that runs it (benchmarks/throughput.py);
    the current RSS is nan where /proc is missing."""
    try:
        with open("/proc/self/statm") as f:
            rss = int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE") / 2**20
    except (OSError, ValueError, AttributeError):
        rss = math.nan
    return os.getpid(), _peak_rss_mib(), rss


def failed_results(chunk: Chunk, reason: str) -> list[BatchResult]:
    """Results marking every sample of a chunk failed (the worker died), inputs as given."""
    out = []
    m = chunk.stop - chunk.start
    for sc, ov in zip(chunk.scenes, chunk.overrides):
        res = empty_result(m)
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
                record_given(res, i, row, base_values)
        out.append(res)
    return out


#: How often a local worker checks that the process that started it is alive [s].
PARENT_POLL_SECONDS = 0.5


def _alive(pid: int) -> bool:
    """Whether process `pid` exists and is not a zombie (killed, not yet reaped)."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # pragma: no cover - someone else's process of that id
        return True
    try:
        with open(f"/proc/{pid}/stat", "rb") as f:
            state = f.read().rsplit(b")", 1)[1].split()[0]
        return state not in (b"Z", b"X")
    except (OSError, IndexError):  # no /proc (not Linux): os.kill said it exists
        return True


def _watch_parent(parent: int) -> None:
    """End this worker (``os._exit``) once `parent` is gone: a run killed with SIGKILL gets no
    chance to stop its workers, and a worker's own parent is the forkserver, not the run, so
    ``prctl(PR_SET_PDEATHSIG)`` would not see the run die."""
    while _alive(parent):
        time.sleep(PARENT_POLL_SECONDS)
    os._exit(1)


def _warm_worker(warm_up: dict | None, parent: int | None = None) -> None:
    """Initializer of a local worker: import the solver, load its compiled kernels once.

    A small solve (paper-quartz at the given options) makes numba load the kernels from its
    cache (or compile them) now rather than in the first sample; its result is discarded, and
    nothing it does can fail the worker. The worker ignores SIGINT (module docstring). With
    `parent` (the process id of the run), a daemon thread ends the worker when that process is
    gone (:func:`_watch_parent`).
    """
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    if parent is not None:
        threading.Thread(target=_watch_parent, args=(parent,), daemon=True,
                         name="skidmc-parent-watch").start()
    try:
        from skidmc.solver import critical_height

        if warm_up is not None:
            from skidmc.scene import get_preset

            critical_height(get_preset("paper-quartz"), **warm_up)
    except Exception:  # noqa: BLE001, S110 - a warm-up only; the samples report any error
        pass


def _ping(_=None) -> int:
    return os.getpid()


class InlineExecutor:
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


class ThreadExecutor:
    """Threads of this process (``scheduler="threads"``): no worker to start or warm up.

    The solver's kernels release the GIL (``nogil``), so threads run simulations side by side:
    62 heights on 2 threads took 0.52x the time of one (temperature-dependent targets at rtol
    1e-2; ``benchmarks/batch_overhead.py`` measures 300 study scenes at 1e-3,
    docs/performance.md), and the first batch pays no process start and no kernel load. What
    they give up is isolation: a sample that crashes the interpreter (a fault in compiled code)
    ends the whole run instead of one worker, and the threads share this process's memory.
    Results are bit for bit those of any other scheduler.
    """

    def __init__(self, workers: int) -> None:
        self.workers = workers
        self._pool = cf.ThreadPoolExecutor(workers, thread_name_prefix="skidmc")

    def submit(self, fn, arg):
        return self._pool.submit(fn, arg)

    def wait_first(self, futures):
        return cf.wait(futures, return_when=cf.FIRST_COMPLETED).done

    def restart(self) -> None:
        pass  # a thread does not die with its task

    def shutdown(self):
        self._pool.shutdown(wait=False, cancel_futures=True)


#: Warm-up options of a worker (the cheapest full-tier solve that loads every kernel).
_WARM_UP = {"rtol": 0.1, "tier": "full"}


def _mp_context():
    """forkserver where available (workers forked from one warm server process), else spawn."""
    if "forkserver" in multiprocessing.get_all_start_methods():
        ctx = multiprocessing.get_context("forkserver")
        # Modules the server imports once, before forking any worker (no effect once running).
        # Not skidmc.runner itself: `python -m skidmc.runner` re-runs it as the workers' main
        # module, which runpy warns about when it is imported already; its imports are these.
        # The last loads the solver's kernels in the server (its docstring), so that each
        # worker is forked with them loaded.
        ctx.set_forkserver_preload(["__main__", "skidmc.scene", "skidmc.solver",
                                    "skidmc.ensemble._forkserver_warm"])
        return ctx
    return multiprocessing.get_context("spawn")


class ProcessExecutor:
    """Local worker processes (forkserver or spawn: safe with threads in the parent)."""

    def __init__(self, workers: int) -> None:
        self.workers = workers
        self._pool = self._new()

    def _new(self):
        pool = cf.ProcessPoolExecutor(self.workers, mp_context=_mp_context(),
                                      initializer=_warm_worker,
                                      initargs=(_WARM_UP, os.getpid()))
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
POOLS: dict[int, ProcessExecutor] = {}


def shared_pool(workers: int) -> ProcessExecutor:
    pool = POOLS.get(workers)
    if pool is None:
        pool = POOLS[workers] = ProcessExecutor(workers)
    return pool


def shutdown_workers() -> None:
    """End the warm local worker processes that :func:`evaluate_batch` keeps between calls."""
    while POOLS:
        _, pool = POOLS.popitem()
        pool.shutdown()


atexit.register(shutdown_workers)


class DaskExecutor:
    """Chunks sent to a dask.distributed cluster (an address, a Client, or a LocalCluster).

    Raises
    ------
    SchedulerError
        dask.distributed is not installed, or no scheduler answers at the address within
        :data:`CONNECT_TIMEOUT` seconds.
    """

    def __init__(self, scheduler, workers: int | None) -> None:
        scheduler = check_scheduler(scheduler)
        try:
            from distributed import Client, LocalCluster
        except ImportError:
            raise SchedulerError(scheduler, "needs dask.distributed, which is not installed "
                                 "(pip install distributed)") from None

        self._own = []
        if scheduler is None or scheduler == "dask":
            cluster = LocalCluster(n_workers=workers or default_workers(), threads_per_worker=1,
                                   processes=True, dashboard_address=None)
            self._own.append(cluster)
            scheduler = cluster
        if isinstance(scheduler, Client):
            self.client = scheduler
        else:
            try:
                self.client = Client(scheduler, timeout=CONNECT_TIMEOUT)
            except (OSError, TimeoutError) as exc:
                for obj in self._own:
                    obj.close()
                raise SchedulerError(scheduler, f"no dask scheduler answered within "
                                     f"{CONNECT_TIMEOUT:g} s ({type(exc).__name__}: {exc}); is "
                                     "it running, and is the address right?") from None
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


def default_workers() -> int:
    """The CPUs this process may run on (its affinity mask where the OS has one) [1]: the
    default worker count, and what ``skidmc run`` compares ``--workers`` with."""
    return available_cpus()


def worker_died(exc: BaseException) -> bool:
    if isinstance(exc, cf.process.BrokenProcessPool):
        return True
    try:
        from distributed import KilledWorker
    except ImportError:  # pragma: no cover - distributed is a dependency
        return False
    return isinstance(exc, KilledWorker)
