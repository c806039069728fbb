"""In-process evaluation of a batch of scenes: one status and height per sample.

The solver is a parameter: every function that solves takes ``solver``, a callable with the
signature of :func:`skidmc.solver.critical_height` (None: that function). A caller injects another
one (a stand-in in tests, an instrumented solver in a benchmark); for worker processes it travels
with the chunk, so it must pickle (a module-level function does).
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Callable, Mapping

import numpy as np

from skidmc.scene import NUMERIC_KEYS, Scene, SceneColumns, make_scene
from skidmc.scene.scenes import implausible_inputs

__all__ = [
    "BatchResult",
    "as_rows",
    "empty_result",
    "evaluate_here",
    "record_given",
    "resolve_solver",
    "solver_kwargs",
]


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


def as_rows(scenes) -> list:
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
    """(height [m], status, evaluations, flags, failure reason) of one scene; never raises.

    The flags are the solver's, with :data:`~skidmc.solver.results.RTOL_UNMET` where the
    result's error estimate stayed above the requested rtol (whatever the solver: a stand-in or
    the GPU backend too) and :data:`~skidmc.solver.results.IMPLAUSIBLE_INPUT` where an input
    lies outside its plausible range (also on a failed sample: the likely cause)."""
    from skidmc.solver.results import IMPLAUSIBLE_INPUT, flag_unmet_rtol

    odd = (IMPLAUSIBLE_INPUT,) if implausible_inputs(scene) else ()
    try:
        res = critical_height(scene, **kwargs)
    except Exception as exc:  # noqa: BLE001 - recorded, see the module docstring
        return math.nan, "failed", 0, ",".join(odd), f"{type(exc).__name__}: {exc}"
    if kwargs.get("tier", "full") == "full" and kwargs.get("level") is None \
            and kwargs.get("model") is None:
        res = flag_unmet_rtol(res, kwargs.get("rtol", 1e-3))
    h, evaluations = float(res.critical_height), int(res.evaluations)
    flags = ",".join((*res.flags, *odd))
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


def resolve_solver(solver: Callable | None) -> Callable:
    """`solver`, or :func:`skidmc.solver.critical_height` when it is None (imported only then)."""
    if solver is not None:
        if not callable(solver):
            raise TypeError(f"solver must be a callable like skidmc.solver.critical_height, got "
                            f"{solver!r}")
        return solver
    from skidmc.solver import critical_height

    return critical_height


def solver_kwargs(solver_options) -> dict:
    """SolverOptions or mapping -> plain keyword arguments (picklable without
    skidmc.ensemble.study)."""
    if hasattr(solver_options, "as_kwargs"):  # a SolverOptions
        return dict(solver_options.as_kwargs())
    return dict(solver_options or {})


def empty_result(m: int) -> BatchResult:
    return BatchResult(
        critical_height=np.full(m, np.nan), status=np.full(m, "failed", dtype=object),
        evaluations=np.zeros(m, dtype=np.int32), flags=np.full(m, "", dtype=object),
        failure_reason=np.full(m, "", dtype=object), wall_time=np.zeros(m),
        inputs={k: np.full(m, np.nan) for k in NUMERIC_KEYS},
    )


def record_given(out: BatchResult, i: int, row, base_values: dict) -> None:
    """Inputs of sample i as given (a row whose scene was never built)."""
    if isinstance(row, Scene):
        given = row.as_dict()
    else:
        given = {**base_values, **(row if isinstance(row, Mapping) else {})}
    for k in NUMERIC_KEYS:
        if isinstance(given.get(k), (int, float)):
            out.inputs[k][i] = given[k]


def evaluate_here(scenes, kwargs: dict, base: Scene | None,
                  solver: Callable | None = None) -> BatchResult:
    """evaluate_batch in this process: columns through :func:`_evaluate_columns`, rows or
    scenes through :func:`_evaluate_rows`; `solver` as in the module docstring."""
    if isinstance(scenes, Mapping):
        return _evaluate_columns(scenes, kwargs, base, solver)
    return _evaluate_rows(as_rows(scenes), kwargs, base, solver)


def _evaluate_rows(rows: list, kwargs: dict, base: Scene | None,
                   solver: Callable | None = None) -> BatchResult:
    """evaluate_batch in this process."""
    critical_height = resolve_solver(solver)
    m = len(rows)
    out = empty_result(m)
    base_values = base.as_dict() if base is not None else {}
    pending = []
    for i, row in enumerate(rows):
        try:
            # rows are programmatic SI floats (samples): no plausibility check on bare numbers
            scene = row if isinstance(row, Scene) else make_scene(row, preset=base,
                                                                  check_plausible=False)
        except Exception as exc:  # noqa: BLE001 - an invalid sample fails alone, not the run
            record_given(out, i, row, base_values)
            out.failure_reason[i] = f"invalid inputs: {type(exc).__name__}: {exc}"
            continue
        values = scene.as_dict()
        for k in NUMERIC_KEYS:
            out.inputs[k][i] = values[k]
        pending.append((i, scene))
    _solve_pending(out, pending, critical_height, kwargs)
    return out


def _evaluate_columns(columns: Mapping, kwargs: dict, base: Scene | None,
                      solver: Callable | None = None) -> BatchResult:
    """evaluate_batch of columns ``{key: array}`` in this process (a study chunk's scene).

    Columns of SI floats on a base scene (a study's samples) have their scenes built by
    :class:`~skidmc.scene.SceneColumns`, which validates whole columns once instead of every key
    of every row; anything else goes row by row through :func:`_evaluate_rows`. The result is
    the same either way, bit for bit: the same scenes, the same errors, the same recorded inputs.
    """
    columns = {k: np.asarray(v) for k, v in columns.items()}
    if not SceneColumns.accepts(base, columns):
        return _evaluate_rows(as_rows(columns), kwargs, base, solver)
    critical_height = resolve_solver(solver)
    scenes = SceneColumns(base, columns)
    m = len(scenes)
    out = empty_result(m)
    # The inputs as given (the columns over the base), which record_given keeps for a row whose
    # scene cannot be built; a built scene differs from them only in its derived keys.
    base_values = base.as_dict()
    for k in NUMERIC_KEYS:
        out.inputs[k][:] = columns.get(k, base_values[k])
    derived = [(out.inputs[k], k.replace(".", "_")) for k in scenes.derived]  # attribute names
    pending = []
    for i in range(m):
        try:
            scene = scenes.scene(i)
        except Exception as exc:  # noqa: BLE001 - an invalid sample fails alone, not the run
            out.failure_reason[i] = f"invalid inputs: {type(exc).__name__}: {exc}"
            continue
        for values, field in derived:
            values[i] = getattr(scene, field)
        pending.append((i, scene))
    _solve_pending(out, pending, critical_height, kwargs)
    return out


def _solve_pending(out: BatchResult, pending: list, critical_height, kwargs: dict) -> None:
    """Solve the valid samples ``pending`` = [(index, scene)] into `out`.

    With ``backend="cuda"`` in `kwargs` the whole list goes to the GPU backend at once
    (:func:`skidmc.solver.cuda.solve_scenes`; each sample's wall time is its share of the
    batch's); otherwise one :func:`_solve_into` per sample.
    """
    kwargs = dict(kwargs)
    backend = kwargs.pop("backend", "cpu")
    if backend == "cpu":
        for i, scene in pending:
            _solve_into(out, i, critical_height, scene, kwargs)
        return
    from skidmc.solver.cuda import solve_scenes

    t0 = time.perf_counter()
    results = solve_scenes([scene for _, scene in pending], backend=backend,
                           fallback=critical_height, **kwargs)
    share = (time.perf_counter() - t0) / max(1, len(pending))
    for (i, scene), res in zip(pending, results):
        (out.critical_height[i], out.status[i], out.evaluations[i], out.flags[i],
         out.failure_reason[i]) = _solve(lambda _scene, _res=res, **_kw: _raise_or(_res),
                                         scene, kwargs)
        out.wall_time[i] = share


def _raise_or(result):
    """`result`, or raise it when it is the exception a sample's solve ended with."""
    if isinstance(result, BaseException):
        raise result
    return result
