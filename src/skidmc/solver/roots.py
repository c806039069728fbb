"""Root finders as Python functions of a margin m(x), x = ln H.

The searches of :func:`skidmc.critical_height` (every plan) and of the device drive the
compiled finders through the machine of :mod:`skidmc.solver.adaptive`; these drivers serve a
caller with a margin function of its own (``scripts/go_side_bend.py``, the tests).

``margin(x)`` runs (or recalls) one simulation and returns ln(t_ev / t_exit): go <=> m <= 0.
The finders differ in what they know beforehand: a guess and a slope (:func:`go_side_root`,
:func:`guided_root`), a guess and its scatter (:func:`prior_bisection_root`), nothing
(:func:`brent_root`, :func:`bisection_root`). Each but the report's bisection is a thin driver
of the compiled finder of the same name in :mod:`skidmc.solver.finders`, which the device
search drives too: the finder asks for an x, the driver calls ``margin(x)`` and hands the value
back, until the finder has its root. The algorithms and their measured constants are
documented there.
"""

from __future__ import annotations

import math

import numpy as np

from skidmc.solver import finders
from skidmc.solver.finders import (
    ASK,
    CARRIED_GO_SLOPE_ERROR,
    CENSORED_ABOVE,
    CENSORED_BELOW,
    DEFAULT_GO_SLOPE,
    DEFAULT_GO_SLOPE_ERROR,
    FAST_GUESS_ERROR,
    FINDER_STATE,
    FOLD_SLOPE,
    GIVE_UP,
    GO_BEND,
    GO_MIN_SEPARATION,
    GO_SECANT_SPAN,
    JUMP_SLOPE,
    PRIOR_TAIL,
    PRIOR_TAIL_Z,
    ROOT,
)
from skidmc.solver.simulate import SolverError

__all__ = [
    "CARRIED_GO_SLOPE_ERROR",
    "DEFAULT_GO_SLOPE",
    "DEFAULT_GO_SLOPE_ERROR",
    "FAST_GUESS_ERROR",
    "FOLD_SLOPE",
    "GO_BEND",
    "GO_MIN_SEPARATION",
    "GO_SECANT_SPAN",
    "JUMP_SLOPE",
    "PRIOR_TAIL",
    "PRIOR_TAIL_Z",
    "bisection_root",
    "brent_root",
    "go_side_root",
    "go_side_slope",
    "guided_root",
    "margin_slope",
    "prior_bisection_root",
]

# The finders' constants live with the compiled finders (:mod:`skidmc.solver.finders`), which
# both searches run; they are re-exported here, where the searches' docs name them.


def _history_slopes(history):
    """:func:`skidmc.solver.finders.history_slopes` of a history [(H [m], margin), ...] sorted
    by (H, margin), as the searches keep it."""
    if not history:
        return math.nan, math.nan
    heights, margins = np.array(history, dtype=np.float64).T.copy()
    return finders.history_slopes(heights, margins, len(history))


def margin_slope(history):
    """d margin / d ln H [1] across the sign change of a finished search's history, or None.

    -inf where the no-go end has no event (margin inf: a run stopped at the exit, searched by
    its signs, or none within the horizon): the margin is taken to jump there (steeper than
    :data:`JUMP_SLOPE`), so the next search locates the root by its signs too
    (:func:`skidmc.solver.finders.history_slopes`, which the device search calls too).
    """
    slope = _history_slopes(history)[0]
    return None if math.isnan(slope) else slope


def go_side_slope(history):
    """d margin / d ln H [1] between the two go points (m <= 0) closest to the root, or None
    (:func:`skidmc.solver.finders.history_slopes`)."""
    slope = _history_slopes(history)[1]
    return None if math.isnan(slope) else slope


def _nan_for_none(value):
    return math.nan if value is None else float(value)


def _state(points, room):
    """A fresh finder state with ``points`` known, and room for ``room`` more go points."""
    st = np.zeros(1, dtype=FINDER_STATE)
    pts = np.empty((2, len(points) + room + 1))
    finders.finder_reset(st)
    for x, m in points:
        finders.finder_point(st, pts, float(x), float(m))
    return st, pts


def _drive(margin, st, pts, code, value):
    """Run the finder: answer each of its questions with ``margin(x)``. Returns its final
    (code, value)."""
    while code == ASK:
        code, value = finders.finder_step(st, pts, float(margin(value)))
    return code, value


def _root_or_none(code, value):
    if code == ROOT:
        return value
    if code == GIVE_UP:
        return None
    if code == finders.BAD_PROBABILITY:
        # what statistics.NormalDist.inv_cdf raised (StatisticsError, a ValueError)
        raise ValueError(f"p must be in the range 0.0 < p < 1.0 (p = {value!r})")
    raise SolverError(f"root finder ended with code {code}")  # pragma: no cover


def go_side_root(margin, x_guess, slope, x_tol, x_min, x_max, *, guess_error,
                 max_simulations=finders.GO_SIDE_MAX_SIMULATIONS, points=()):
    """Root of the margin on ln H by extrapolation from its go side (m <= 0); or None.

    :func:`skidmc.solver.finders.go_side_start`, driven by ``margin``. ``slope``: the go side's
    d margin / d ln H [1] carried from a coarser search, or None. ``points``: (x, m) already
    known (the same search at a looser tolerance), used with the new ones. Returns None when
    the finder gives up: the caller then brackets and runs Brent's method, reusing every
    simulation.
    """
    st, pts = _state(points, max_simulations)
    code, value = finders.go_side_start(st, pts, float(x_guess), _nan_for_none(slope),
                                        float(x_tol), float(x_min), float(x_max),
                                        float(guess_error), int(max_simulations))
    return _root_or_none(*_drive(margin, st, pts, code, value))


def guided_root(margin, x0, slope, x_tol, x_min, x_max,
                max_simulations=finders.GUIDED_MAX_SIMULATIONS, *, spread=None, points=()):
    """Root of the margin on ln H from a close guess ``x0``, always from a tight bracket; or None.

    :func:`skidmc.solver.finders.guided_start`, driven by ``margin``. ``slope`` [1] from a
    coarser search or None; ``spread`` [1, in ln H]: the guess's uncertainty, which limits
    one-sided steps (None: no limit); ``points``: (x, m) already known.
    """
    st, pts = _state(points, 0)
    code, value = finders.guided_start(st, float(x0), _nan_for_none(slope), float(x_tol),
                                       float(x_min), float(x_max), int(max_simulations),
                                       _nan_for_none(spread))
    return _root_or_none(*_drive(margin, st, pts, code, value))


def prior_bisection_root(margin, x_guess, sigma, x_tol, x_min, x_max,
                         max_simulations=finders.GUIDED_MAX_SIMULATIONS, *, slope=None,
                         points=(), signs_only=False):
    """Root of a margin that may jump at its root, from a guess with a known spread; or None.

    :func:`skidmc.solver.finders.prior_bisection_start`, driven by ``margin``: the root's prior
    ln H ~ N(``x_guess``, ``sigma``^2) is halved by each simulation. ``slope`` [1] goes to the
    guided finder if a bracket turns out smooth; ``points``: (x, m) already known; with
    ``signs_only`` a no-go margin may be inf (a run stopped at the exit).
    """
    st, pts = _state(points, 0)
    code, value = finders.prior_bisection_start(st, pts, float(x_guess), float(sigma),
                                                float(x_tol), float(x_min), float(x_max),
                                                int(max_simulations), _nan_for_none(slope),
                                                bool(signs_only))
    return _root_or_none(*_drive(margin, st, pts, code, value))


def bisection_root(margin, x_min, x_max, x_tol):
    """The report's search: geometric mean of the lowest go and the highest no-go
    (:func:`skidmc.solver.finders.bisection_start`, driven by ``margin``). Returns
    (x_root, censored), censored "above", "below" or None."""
    st, pts = _state((), 0)
    code, value = finders.bisection_start(st, float(x_min), float(x_max), float(x_tol))
    code, value = _drive(margin, st, pts, code, value)
    if code == CENSORED_ABOVE:
        return x_max, "above"
    if code == CENSORED_BELOW:
        return x_min, "below"
    return value, None


def brent_root(margin, x_min, x_max, x_tol, horizon, h_guess, overshoot=0.05):
    """Bracket the root of the margin from a first guess, then Brent's method on ln H.

    :func:`skidmc.solver.finders.brent_start`, driven by ``margin``. ``h_guess`` [m]: the first
    height (None: 1 m). ``overshoot`` [1, in ln H] is added to each bracketing step beyond the
    root that the margin predicts (t_ev ~ 1/H): about the error of the guess. ``horizon`` [1]
    is ln(t_end / t_exit) of the model: "no event within the horizon" means m > horizon.
    Returns (x_root, censored), censored "above", "below" or None.
    """
    x0 = math.log(h_guess) if h_guess else 0.0  # 1 m by default
    st, pts = _state((), 0)
    code, value = finders.brent_start(st, x0, float(x_min), float(x_max), float(x_tol),
                                      float(horizon), float(overshoot))
    code, value = _drive(margin, st, pts, code, value)
    if code == ROOT:
        return value, None
    if code == CENSORED_ABOVE:
        return x_max, "above"
    if code == CENSORED_BELOW:
        return x_min, "below"
    if code == finders.NO_CONVERGENCE:
        # what scipy.optimize.brentq raised
        raise RuntimeError(f"Failed to converge after {finders.BRENT_ITERATIONS} iterations, "
                           f"value is {value}")
    if code == finders.SIGN_ERROR:
        raise ValueError("f(a) and f(b) must have different signs")
    raise SolverError("could not bracket the critical height")
