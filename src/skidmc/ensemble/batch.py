"""The batch API: :func:`evaluate_batch`, for any caller that hands over a batch of scenes.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import TYPE_CHECKING

import numpy as np

from skidmc.ensemble.evaluate import (
    BatchResult,
    as_rows,
    empty_result,
    evaluate_here,
    resolve_solver,
    solver_kwargs,
)
from skidmc.ensemble.executors import (
    LOCAL_SCHEDULERS,
    Chunk,
    DaskExecutor,
    ThreadExecutor,
    check_scheduler,
    default_workers,
    shared_pool,
)
from skidmc.ensemble.schedule import Schedule, run_chunks
from skidmc.scene import NUMERIC_KEYS, Scene

if TYPE_CHECKING:
    from skidmc.ensemble.study import SolverOptions

__all__ = [
    "evaluate_batch",
]


def evaluate_batch(scenes, solver_options: SolverOptions | Mapping | None = None, *,
                   base: Scene | str | None = None, workers: int | None = 1,
                   chunk_size: int | None = None, scheduler=None,
                   solver: Callable | None = None) -> BatchResult:
    """Critical heights of any batch of scenes, one status per sample, never raising for one.

    Parameters
    ----------
    scenes : sequence of Scene or mapping, or mapping of columns
        The batch: :class:`~skidmc.scene.Scene` objects; or mappings of scene keys to values
        (SI floats or unit strings), applied as overrides to `base`
        (``make_scene(row, preset=base, check_plausible=False)``: rows are programmatic, so
        bare numbers are SI and not checked for plausibility); or one mapping
        ``{key: 1-D array}`` of columns.
    solver_options : SolverOptions or mapping, optional
        Keyword arguments of :func:`skidmc.solver.critical_height` (default: its defaults),
        and ``backend``: "cpu" (default) or "cuda", the GPU backend of the full tier
        (:mod:`skidmc.solver.cuda`), which solves the batch in this process whatever
        `workers` says.
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
        ``"threads"``: `workers` threads of this process instead of worker processes (no
        worker to start; the same results; but a crash in one sample ends the process:
        :class:`~skidmc.ensemble.executors.ThreadExecutor`; 300 heights at rtol 1e-3 on 2
        threads ran at 84 % of twice the in-process rate, a warm pool at 94 %:
        results/benchmarks/batch_overhead.md). ``"dask"`` or a dask Client/address instead of
        local processes (as in :func:`run_study`).
    solver : callable, optional
        Used instead of :func:`skidmc.solver.critical_height` (default), called as
        ``solver(scene, **solver_options)`` and returning an object with ``critical_height``,
        ``censored``, ``evaluations`` and ``flags`` as :class:`~skidmc.solver.HeightResult`
        has. With worker processes it is pickled: a module-level function.

    Returns
    -------
    BatchResult
        In the batch's order, the same for any `workers`, `chunk_size` or `scheduler`. Invalid
        inputs and solver exceptions give status ``failed`` with the reason; nothing is dropped;
        a sample that kills its worker process is retried alone and, if it kills it again,
        recorded as failed (``worker process died ...``).
    """
    kwargs = solver_kwargs(solver_options)
    if isinstance(base, str):
        from skidmc.scene import get_preset

        base = get_preset(base)
    if solver is not None:
        resolve_solver(solver)  # a TypeError now rather than one per sample
    if workers is not None and workers < 1:
        raise ValueError(f"workers must be >= 1 (or None: all CPUs), got {workers!r}")
    scheduler = check_scheduler(scheduler)
    if scheduler in LOCAL_SCHEDULERS and ((workers or default_workers()) == 1
                                          or kwargs.get("backend", "cpu") != "cpu"):
        # The GPU backend takes the whole batch in this process (one kernel launch per
        # LAUNCH_SIZE scenes); worker processes would only share the one GPU.
        return evaluate_here(scenes, kwargs, base, solver)
    return _evaluate_rows_parallel(as_rows(scenes), kwargs, base, workers, chunk_size, scheduler,
                                   solver)


def _evaluate_rows_parallel(rows: list, kwargs: dict, base: Scene | None, workers,
                            chunk_size, scheduler, solver: Callable | None) -> BatchResult:
    """evaluate_batch through the chunk machinery of a study run (warm local pool or dask)."""
    m = len(rows)
    out = empty_result(m)
    if m == 0:
        return out
    if scheduler in (None, "local"):
        executor, owned = shared_pool(workers or default_workers()), False
    elif scheduler == "threads":
        executor, owned = ThreadExecutor(workers or default_workers()), True
    else:
        executor, owned = DaskExecutor(None if scheduler == "dask" else scheduler, workers), True

    def make_chunk(start: int, stop: int, isolated: bool):
        return Chunk(start, stop, (base,), [rows[start:stop]], kwargs, isolated, solver), None

    def consume(chunk: Chunk, _context, results: list[BatchResult], _out) -> None:
        (res,) = results
        sl = slice(chunk.start, chunk.stop)
        for name in ("critical_height", "status", "evaluations", "flags", "failure_reason",
                     "wall_time"):
            getattr(out, name)[sl] = getattr(res, name)
        for k in NUMERIC_KEYS:
            out.inputs[k][sl] = res.inputs[k]

    todo = np.ones(m, dtype=bool)
    try:
        run_chunks(executor, Schedule(todo, 1, executor.workers, chunk_size,
                                        balance=executor.workers > 1),
                    make_chunk, consume)
    finally:
        if owned:
            executor.shutdown()
    return out
