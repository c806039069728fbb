"""Simulation of one impact and the search for the critical drop height.

The critical height H_c is where the time of the thermal event, t_ev(H), equals the
exit time t_exit (rebound or end of sliding), which does not depend on H. The
search works on the continuous margin

    m(H) = ln(t_ev(H) / t_exit),     go  <=>  m <= 0,

where, beyond t_exit, the flux is extended (:mod:`skidmc.model`) so that t_ev stays
finite a little below H_c; m is smooth and close to linear in ln H (the surface
temperature rises roughly as sqrt(q^2 t) ~ sqrt(H t), so t_ev ~ 1/H), which lets a
bracketing Brent iteration converge in a handful of simulations. The extension
never changes a verdict: at the root, t_ev = t_exit and the extended flux has not
acted yet. The report's own method, geometric bisection on go/no-go, is kept as
``method="bisection"``.
"""

from __future__ import annotations

import math
import time
from dataclasses import asdict, dataclass, field

import numpy as np
from scipy.optimize import brentq

from skidmc.errors import SceneError
from skidmc.model import MELT_WIDTH_BIAS_PER_K, build_model, melt_width_floor
from skidmc.thermal import (INFO_EVENT, INFO_FAILED, INFO_REJECTED, INFO_STEPS,
                            INFO_T_EVENT, INFO_T_EXIT_MAX, INFO_T_MAX, INFO_Y_EXIT_MAX,
                            simulate_kernel)

FT = 0.3048  # [m per ft], exact

#: Model fidelity tiers: "full" (the report's model, converged to rtol) and "fast" (the
#: reduced model of :mod:`skidmc.fast`, ~10-20 us per height, a few percent off the full model).
TIERS = ("full", "fast")

#: Default search bounds [m]: 1 mm to 10 km of drop height.
DEFAULT_H_MIN = 1e-3
DEFAULT_H_MAX = 1e4

#: Numerical-error calibration. The refinement study (``python scripts/refinement_study.py``,
#: results/validation/refinement{,_w4,_w1}.md: the level's floor melting width, 4 K and 1 K)
#: measures the discretisation error of the critical height at level L, over all report
#: presets and the second series' extreme mu, as second order from level 0 with a worst
#: case of 7.9e-3 * 4**-L (observed 7.9e-3, 3.7e-3, 1.9e-3, 9.9e-4, 4.8e-4, 2.4e-4 at
#: L = 0 ... 2.5). ERROR_LEVEL0 bounds every observed level from above, with >= 12 % to
#: spare. The tolerance rtol is shared three ways: DISCRETISATION_SHARE to the mesh and time
#: steps (the solver picks the lowest (half-)level whose modelled error is below it),
#: MELT_SHARE to the smoothing of the melting step (its width, :func:`melt_width_for_rtol`)
#: and ROOT_SHARE to the root finder (on ln H). The root finder also gets what the chosen
#: plan leaves unused of the other two shares (:func:`root_tolerance`): levels come in
#: half steps, so the modelled discretisation error is often well below its share.
ERROR_LEVEL0 = 9.0e-3
DISCRETISATION_SHARE = 0.6
MELT_SHARE = 0.2
ROOT_SHARE = 0.2
#: Widest melting step used [K]: the bias per kelvin was measured up to 4 K.
MAX_MELT_WIDTH = 4.0
MAX_STEPS = 200_000

#: Coarse-to-fine search: at level L >= COARSE_GAP, the critical height is first found at level
#: L - COARSE_GAP (each simulation ~10x cheaper), and the search at level L starts there with a
#: bracket a few coarse errors wide, so it needs ~4 fine simulations instead of ~8.
COARSE_GAP = 2.0

#: Richardson extrapolation (second order) of the searches at levels L - 1 and L. The
#: refinement study measures its residual error, over all report presets, the second
#: series' extreme mu and the three melting widths, as 5.6e-4, 3.2e-4, 8.4e-5, 5.2e-5 at
#: L = 1, 1.5, 2, 2.5 (6.7e-4 at L = 1 in a repeat whose searches took other paths: level 0's
#: margin carries ~1e-4 of step-size noise). RICHARDSON_ERROR_LEVEL0 * 4**-L bounds every
#: observed value from L = 1 (RICHARDSON_MIN_LEVEL) up, with 16 % to spare at L = 1.
RICHARDSON_ERROR_LEVEL0 = 3.2e-3

#: Relative error of the fast tier's height used as a first guess [1]: about its median
#: against the full model on the studies' ranges (1.3 %; p90 4.6 %, worst ~10 %,
#: results/benchmarks/fast_tier.md). The go-side search starts this far above the guess;
#: a guess further off costs one or two more simulations, never a wrong root.
FAST_GUESS_ERROR = 0.02

#: d margin / d ln H on the go side [1] when nothing better is known: t_ev ~ H^-s with s
#: measured 1.1-1.35 on the report presets (rebound exits), and its relative uncertainty.
DEFAULT_GO_SLOPE = -1.25
DEFAULT_GO_SLOPE_ERROR = 0.3
#: Relative uncertainty of a go-side slope carried over from a coarser level's search.
#: Measured against the fine level's own secant from the root to 0.2-2 % above it, on the
#: report presets (gold aside: stops sliding) for the Richardson pairs (0, 1) and (0.5, 1.5):
#: 0.05 % to 9.6 % (alumina 50-80 uin, pair (0.5, 1.5)); 0.15 leaves 1.5x to spare. It
#: bounds the error of a root extrapolated from one fine go point (:func:`_go_side_root`).
CARRIED_GO_SLOPE_ERROR = 0.15
#: Go points farther than this from the root [1, in ln H] are not used for the secant slope.
GO_SECANT_SPAN = 0.1
#: Bend of the go-side margin [1]: a secant through go points at distances d_a < d_b (in
#: ln H) from the root misses it by about GO_BEND * d_a * d_b (a quadratic's interpolation
#: error, kappa d_a d_b / (2 |s|)). Measured 0.39 on paper2-quartz (secant through d = 0.034
#: and 0.106 missed by 1.4e-3); 1.0 leaves a factor 2.5 to spare.
GO_BEND = 1.0
RICHARDSON_MIN_LEVEL = 1.0


def melt_width_for_rtol(rtol, level=0.0):
    """Width of the smoothed melting step [K] for tolerance ``rtol`` at ``level``.

    The widest width whose bias, first order in the width and at most
    :data:`skidmc.model.MELT_WIDTH_BIAS_PER_K` per kelvin, stays below MELT_SHARE * rtol;
    at most :data:`MAX_MELT_WIDTH` and at least :func:`melt_width_floor` of ``level``.
    """
    return max(melt_width_floor(level),
               min(MAX_MELT_WIDTH, MELT_SHARE * rtol / MELT_WIDTH_BIAS_PER_K))


def root_tolerance(rtol, level, extrapolate, melt_width):
    """Tolerance of the root finder on ln H [1] for a plan ``(level, extrapolate)``.

    What ``rtol`` leaves after the modelled discretisation error of the plan
    (:func:`modelled_error` or :func:`extrapolated_error`) and the melting width's bias bound,
    and never less than ROOT_SHARE * rtol: the three modelled errors then add up to at most
    ``rtol`` (or to the plan's error plus ROOT_SHARE * rtol when a forced level is coarser
    than ``rtol`` asks for).
    """
    discretisation = extrapolated_error(level) if extrapolate else modelled_error(level)
    melt = (MELT_WIDTH_BIAS_PER_K * melt_width
            if melt_width > melt_width_floor(level) * (1.0 + 1e-9) else 0.0)
    return max(ROOT_SHARE * rtol, rtol - discretisation - melt)


def modelled_error(level):
    """Modelled relative discretisation error of the critical height at ``level`` [1]."""
    return ERROR_LEVEL0 * 4.0 ** (-level)


class SolverError(RuntimeError):
    """The time integration could not proceed (step size underflow or step cap)."""


@dataclass
class Simulation:
    """Outcome of one impact at one drop height."""

    height: float            # [m]
    event: bool              # thermal event before the exit time
    event_time: float        # [s] (inf: none within the horizon)
    exit_time: float         # [s]
    margin: float            # ln(t_ev / t_exit) [1] (inf when no event in the horizon)
    steps: int
    rejected: int
    max_temperature: float   # highest HE cell temperature reached [K]
    exit_max_temperature: float  # highest HE cell temperature at t_exit [K]
    exit_max_reacted: float  # highest fraction reacted at t_exit [1]
    times: np.ndarray | None = None                  # [s]
    interface_temperature: np.ndarray | None = None  # [K]


def simulate(model, height, *, record=False, max_steps=MAX_STEPS, flux_override=None):
    """Simulate the impact from drop height ``height`` [m].

    Parameters
    ----------
    model : skidmc.model.SkidModel
    height : float
        Vertical drop height H [m].
    record : bool
        Keep the interface temperature history (for checks and figures).
    flux_override : tuple, optional
        ``(q0, s, c, omega, t_exit, q_ext)`` to impose another flux shape (tests).

    Returns
    -------
    Simulation
    """
    if flux_override is None:
        q0 = model.flux_amplitude(height)
        flux = (q0, model.slide_s, model.slide_c, model.omega, model.exit_time,
                q0 * model.extension_flux_factor)
    else:
        flux = tuple(float(v) for v in flux_override)
    n_rec = max_steps if record else 0
    rec_t = np.zeros(min(n_rec, 100_000))
    rec_tb = np.zeros_like(rec_t)
    info = simulate_kernel(
        model.width, model.rho_c, model.face_conductance, model.n_target, model.q_share_he,
        model.he_density, model.latent_heat, model.melting_point, model.resolution.melt_width,
        model.prefactor, model.activation_temperature, model.heat_of_reaction,
        flux[0], flux[1], flux[2], flux[3], flux[4], flux[5], model.end_time,
        model.initial_temperature, model.resolution.tol_temperature, model.dt_initial,
        model.runaway_fraction, max_steps, rec_t, rec_tb)
    if info[INFO_FAILED] or (info[INFO_STEPS] + info[INFO_REJECTED] >= max_steps
                             and not info[INFO_EVENT]):
        raise SolverError(
            f"time integration failed at H = {height:.6g} m after {int(info[INFO_STEPS])} "
            f"steps ({int(info[INFO_REJECTED])} rejected)")
    t_ev = info[INFO_T_EVENT]
    t_exit = model.exit_time
    steps = int(info[INFO_STEPS])
    sim = Simulation(
        height=float(height), event=bool(info[INFO_EVENT]) and t_ev <= t_exit,
        event_time=float(t_ev), exit_time=t_exit,
        margin=math.log(t_ev / t_exit) if np.isfinite(t_ev) else math.inf,
        steps=steps, rejected=int(info[INFO_REJECTED]),
        max_temperature=float(info[INFO_T_MAX]),
        exit_max_temperature=float(info[INFO_T_EXIT_MAX]),
        exit_max_reacted=float(info[INFO_Y_EXIT_MAX]),
    )
    if record:
        n = min(steps, rec_t.shape[0])
        sim.times = rec_t[:n].copy()
        sim.interface_temperature = rec_tb[:n].copy()
    return sim


@dataclass
class HeightResult:
    """Critical drop height of one scene.

    Attributes
    ----------
    critical_height : float
        Critical drop height [m]; for censored results the bound that was hit.
    censored : str or None
        None, ``"above"`` (no event up to ``h_max``) or ``"below"`` (event at ``h_min``).
    evaluations : int
        Number of impact simulations used.
    flags : tuple of str
        Model-validity notes, e.g. ``"stops_sliding"`` (heating ended before rebound),
        ``"no_friction"``.
    error_estimate : float
        Estimated relative numerical error of ``critical_height`` [1].
    extrapolated : bool
        The height is the Richardson extrapolation of two levels.
    richardson_correction : float
        Relative size of that extrapolation's correction [1]: an a-posteriori error
        indicator of the finer level alone (0 when not extrapolated).
    rtol, level, method, wall_time, exit_time, exit_kind, terms
        Settings and diagnostics (wall_time [s], exit_time [s]).
    """

    critical_height: float
    censored: str | None
    evaluations: int
    flags: tuple = ()
    error_estimate: float = math.nan
    rtol: float = 1e-3
    level: float = 0.0
    method: str = "brent"
    wall_time: float = 0.0
    exit_time: float = math.nan
    exit_kind: str = ""
    terms: tuple = ()
    extrapolated: bool = False
    richardson_correction: float = 0.0
    history: list = field(default_factory=list, repr=False)

    @property
    def critical_height_ft(self):
        """Critical drop height [ft]."""
        return self.critical_height / FT

    def to_dict(self):
        """JSON-ready dictionary (heights in m and ft)."""
        d = asdict(self)
        d.pop("history")
        d["critical_height_m"] = d.pop("critical_height")
        d["critical_height_ft"] = self.critical_height_ft
        d["flags"] = list(self.flags)
        d["terms"] = list(self.terms)
        return d


def _half_level_above(needed):
    """Smallest half-integer level >= ``needed`` (and >= 0)."""
    return max(0.0, math.ceil(2.0 * needed - 1e-9) / 2.0)


def level_for_rtol(rtol):
    """Lowest half-integer refinement level whose modelled error is below 0.6 rtol [1]."""
    if not rtol > 0.0:
        raise SceneError("rtol", rtol, "must be > 0")
    return _half_level_above(
        math.log(ERROR_LEVEL0 / (DISCRETISATION_SHARE * rtol)) / math.log(4.0))


def extrapolated_error(level):
    """Modelled relative error of the Richardson value from levels ``level - 1`` and ``level`` [1]."""
    return RICHARDSON_ERROR_LEVEL0 * 4.0 ** (-level)


def plan_for_rtol(rtol):
    """Cheapest way to reach ``rtol``: ``(level, extrapolate)``.

    Either one search at :func:`level_for_rtol`, or (when that is cheaper) a search at
    ``level - 1`` and one at ``level`` combined by Richardson extrapolation, whose modelled
    error :func:`extrapolated_error` is below 0.6 rtol. Extrapolation is offered only from
    :data:`RICHARDSON_MIN_LEVEL` up, where the refinement study shows second order.
    """
    plain = level_for_rtol(rtol)
    extrapolated = max(RICHARDSON_MIN_LEVEL, _half_level_above(
        math.log(RICHARDSON_ERROR_LEVEL0 / (DISCRETISATION_SHARE * rtol)) / math.log(4.0)))
    # A search at level L costs ~2.2^L simulations' worth; the pair costs ~1.45x level L.
    if extrapolated < plain:
        return extrapolated, True
    return plain, False


def critical_height(scene, rtol=1e-3, tier="full", h_min=DEFAULT_H_MIN, h_max=DEFAULT_H_MAX,
                    *, method="brent", level=None, extrapolate=None, melting=True,
                    runaway_fraction=None, h_guess=None, model=None, melt_width=None):
    """Critical drop height of a scene [m].

    Parameters
    ----------
    scene : skidmc.scene.Scene
    rtol : float
        Relative tolerance on the critical height [1]: 60 % goes to the mesh and
        steps (see :func:`plan_for_rtol`), 20 % to the smoothing of the melting step
        (:func:`melt_width_for_rtol`), 20 % to the root finder.
    tier : {"full", "fast"}
        Model fidelity: "full" is the report's model converged to ``rtol``; "fast" is the
        reduced model of :func:`skidmc.fast.fast_critical_height` (``rtol`` and the numerical
        options do not apply; its measured error against the full model is in
        ``results/benchmarks/fast_tier.md`` and in the result's ``error_estimate``).
    h_min, h_max : float
        Search bounds [m]. No event at ``h_max`` is censored "above"; an event at
        ``h_min`` is censored "below". Neither is an error.
    method : {"brent", "bisection"}
        Brent's method on the continuous margin (default), or the report's
        geometric bisection on go/no-go.
    level : float, optional
        Force a refinement level instead of deriving it from ``rtol``.
    extrapolate : bool, optional
        Richardson extrapolation from ``level - 1`` and ``level`` (second order). Default:
        chosen with the level by :func:`plan_for_rtol`; False when ``level`` is forced.
    melting : bool
        Model melting of the HE.
    runaway_fraction : float, optional
        Override the runaway rule (:data:`skidmc.model.DEFAULT_RUNAWAY_FRACTION`).
    h_guess : float, optional
        First height tried [m].
    model : SkidModel, optional
        A prebuilt model (overrides scene, level, melting, runaway_fraction, melt_width; no
        extrapolation or coarse start).
    melt_width : float, optional
        Width of the smoothed melting step [K]; default :func:`melt_width_for_rtol`.

    Returns
    -------
    HeightResult
    """
    start = time.perf_counter()
    if tier not in TIERS:
        raise SceneError("tier", tier, f"unknown tier (expected one of {', '.join(TIERS)})")
    if not (0.0 < h_min < h_max):
        raise SceneError("h_min", h_min, f"need 0 < h_min < h_max (h_max = {h_max!r})")
    if tier == "fast":
        from skidmc.fast import fast_critical_height

        res = fast_critical_height(scene, h_min=h_min, h_max=h_max, melting=melting)
        # The same validity flags as the full tier (scene and height), without its meshes.
        model = build_model(scene, melting=melting, meshes=False)
        res.flags = model.flags + model.height_flags(res.critical_height)
        return res
    if not (isinstance(rtol, (int, float)) and 0.0 < rtol < 0.5):
        raise SceneError("rtol", rtol, "must be a number in (0, 0.5)")
    if method not in ("brent", "bisection"):
        raise SceneError("method", method, "expected 'brent' or 'bisection'")
    if melt_width is not None and not (isinstance(melt_width, (int, float))
                                       and melt_width > 0.0):
        raise SceneError("melt_width", melt_width, "must be a number > 0 [K]")
    if level is None:
        level, planned = plan_for_rtol(rtol)
        extrapolate = planned if extrapolate is None else extrapolate
    extrapolate = bool(extrapolate) and model is None and level >= 1.0
    if melt_width is None:
        # The same width at every level of the search (coarse start, Richardson pair).
        melt_width = melt_width_for_rtol(rtol, level)
    common = dict(h_min=h_min, h_max=h_max, method=method, melting=melting,
                  runaway_fraction=runaway_fraction, melt_width=float(melt_width))
    x_tol = root_tolerance(rtol, level, extrapolate, melt_width)
    if not extrapolate:
        res = _search(scene, rtol, level, x_tol, model=model, h_guess=h_guess, **common)
        res.wall_time = time.perf_counter() - start
        return res

    # Richardson: R = H_L + (H_L - H_{L-1}) / 3. Root-finder errors d_L, d_{L-1} enter R as
    # (4 d_L + d_{L-1}) / 3: the cheap coarse search gets the whole root-finder tolerance and
    # the fine one half of it, (4 / 2 + 1) / 3 = 1 tolerance in all.
    coarse = _search(scene, rtol, level - 1.0, x_tol, h_guess=h_guess, **common)
    # The fine root lies above the coarse one by about 3/4 of the coarse level's error (the
    # errors are negative and shrink 4x per level; the fine level keeps 1/4 of it): the
    # go-side search starts that far up, which lands on the go side within the error model.
    fine = _search(scene, rtol, level, 0.5 * x_tol,
                   h_guess=coarse.critical_height if coarse.censored is None else None,
                   overshoot=0.75 * modelled_error(level - 1.0),
                   slope=_margin_slope(coarse.history), go_slope=_go_slope(coarse.history),
                   **common)
    fine.evaluations += coarse.evaluations
    fine.wall_time = time.perf_counter() - start
    if fine.censored is None and coarse.censored is None:
        correction = (fine.critical_height - coarse.critical_height) / 3.0
        fine.critical_height += correction
        fine.richardson_correction = correction / fine.critical_height
        fine.extrapolated = True
        fine.error_estimate = (extrapolated_error(level) + x_tol
                               + _melt_bias(fine.terms, melt_width, level))
    return fine


def _melt_bias(terms, melt_width, level):
    """Bound on the relative bias of the smoothed melting step [1].

    0 without melting, and at the level's floor width, where the bias is part of the
    level's modelled error (:data:`skidmc.model.MELT_WIDTH_LEVEL0`).
    """
    if "melting" not in terms or melt_width <= melt_width_floor(level) * (1.0 + 1e-9):
        return 0.0
    return MELT_WIDTH_BIAS_PER_K * melt_width


def _search(scene, rtol, level, x_tol, *, h_min, h_max, method, melting, runaway_fraction,
            melt_width, model=None, h_guess=None, overshoot=None, slope=None, go_slope=None):
    """One critical-height search at one resolution level (see :func:`critical_height`).

    ``x_tol`` [1] is the root finder's tolerance on ln H. With no guess, the search starts
    from the root found at ``level - COARSE_GAP`` (levels >= COARSE_GAP) or from the fast
    tier's height. From a guess, steps that bracket the predicted root (:func:`_guided_root`)
    usually converge in 3-4 simulations; otherwise bracketing and Brent's method take over,
    reusing every simulation done.
    """
    own_model = model is None
    if own_model:
        kwargs = {} if runaway_fraction is None else {"runaway_fraction": runaway_fraction}
        model = build_model(scene, level=level, melting=melting, melt_width=melt_width,
                            **kwargs)
    base = dict(rtol=rtol, level=level, method=method, exit_time=model.exit_time,
                exit_kind=model.exit_kind, terms=model.terms, flags=model.flags,
                error_estimate=(modelled_error(level) + x_tol
                                + _melt_bias(model.terms, model.resolution.melt_width,
                                             level)))

    if "no_friction" in model.flags:
        return HeightResult(critical_height=h_max, censored="above", evaluations=0, **base)

    coarse_evaluations = 0
    if method == "brent" and h_guess is None and own_model and level >= COARSE_GAP:
        coarse = _search(scene, rtol, level - COARSE_GAP,
                         max(x_tol, 0.2 * modelled_error(level - COARSE_GAP)), h_min=h_min,
                         h_max=h_max, method=method, melting=melting,
                         runaway_fraction=runaway_fraction, melt_width=melt_width)
        coarse_evaluations = coarse.evaluations
        if coarse.censored is None:
            h_guess = coarse.critical_height
            slope = _margin_slope(coarse.history)
            go_slope = _go_slope(coarse.history)
            # The fine root lies within the coarse level's error of the coarse root.
            overshoot = 2.0 * modelled_error(level - COARSE_GAP)
    elif method == "brent" and h_guess is None and own_model:
        fast = _fast_guess(scene, h_min, h_max, melting)
        if fast is not None:
            h_guess, overshoot = fast, FAST_GUESS_ERROR

    cache = {}

    def margin(x):
        if x not in cache:
            cache[x] = simulate(model, math.exp(x)).margin
        return cache[x]

    x_min, x_max = math.log(h_min), math.log(h_max)
    x_root = None
    if method == "bisection":
        x_root, censored = _bisection(margin, x_min, x_max, x_tol)
    elif h_guess is not None and model.exit_kind == "rebound":
        x_root = _go_side_root(margin, math.log(h_guess), go_slope, x_tol, x_min, x_max,
                               guess_error=overshoot or FAST_GUESS_ERROR)
        censored = None
    elif h_guess is not None:
        x_root, censored = _guided_root(margin, math.log(h_guess), slope, x_tol, x_min, x_max), None
    if x_root is None:
        x_root, censored = _brent(margin, x_min, x_max, x_tol, model, h_guess,
                                  overshoot=overshoot or 0.05)
    history = sorted((math.exp(x), m) for x, m in cache.items())
    # Censored results report the bound itself, exactly as given.
    height = {"above": h_max, "below": h_min}.get(censored, math.exp(x_root))
    # Validity at the height found (indentation depth, sliding distance): skidmc.model.
    base["flags"] = model.flags + model.height_flags(height)
    return HeightResult(critical_height=height, censored=censored,
                        evaluations=len(cache) + coarse_evaluations, history=history, **base)


def _fast_guess(scene, h_min, h_max, melting):
    """The fast tier's critical height [m] as a first guess, or None (censored or failed)."""
    from skidmc.fast import fast_critical_height

    try:
        res = fast_critical_height(scene, h_min=h_min, h_max=h_max, melting=melting)
    except Exception:  # noqa: BLE001 - only a guess: the full search does not need it
        return None
    h = res.critical_height
    return h if res.censored is None and math.isfinite(h) else None


def _margin_slope(history):
    """d margin / d ln H [1] across the sign change of a finished search's history, or None."""
    pts = [(math.log(h), m) for h, m in history if math.isfinite(m)]
    for (x0, m0), (x1, m1) in zip(pts, pts[1:]):
        if m0 > 0.0 >= m1 and x1 > x0:
            return (m1 - m0) / (x1 - x0)
    return None


def _margin_inside(margin, x, x_min, x_max):
    """The margin at ``x``, or None when x leaves (x_min, x_max) or the margin is not finite:
    the guided searches then hand over to bracketing and Brent's method."""
    if not (x_min < x < x_max):
        return None
    m = margin(x)
    return m if math.isfinite(m) else None


def _go_slope(history):
    """d margin / d ln H [1] between the two go points (m <= 0) closest to the root, or None."""
    go = [(math.log(h), m) for h, m in history if math.isfinite(m) and m <= 0.0]
    if len(go) < 2:
        return None
    (x0, m0), (x1, m1) = go[0], go[1]
    slope = (m1 - m0) / (x1 - x0)
    return slope if slope < 0.0 else None


def _go_side_root(margin, x_guess, slope, x_tol, x_min, x_max, *, guess_error,
                  max_simulations=8):
    """Root of the margin on ln H by extrapolation from its go side (m <= 0); or None.

    For a rebound exit the margin is analytic on the go side up to the root: the event
    comes before t_exit, under the true flux, and t_ev ~ H^-s with s nearly constant (its
    secant slope changes by < 1 % over 5 % of H on the report presets). On the no-go side
    the event falls after t_exit, under the extension flux, and the margin bends (its slope
    changes by ~30 % within 0.5 % of H_c, with a kink at the root). So the root is taken from
    a secant through go points only, once the closest go point lies within ``4 x_tol`` of
    it (the extrapolation error is then that distance times the slope's relative change over
    it, far below ``x_tol``) or the secant's modelled bend error (:data:`GO_BEND`) is below
    ``x_tol / 2``. With one go point and a slope carried from a coarser level, the root is
    extrapolated along that slope and accepted when its modelled error, the distance times
    :data:`CARRIED_GO_SLOPE_ERROR`, is below ``x_tol / 2``. The secant uses the farthest go point within :data:`GO_SECANT_SPAN`, which
    keeps the margin's ~1e-5 step-size noise out of the slope.

    Each simulation aims just above the predicted root, by the prediction's own uncertainty
    (at least ``1.5 x_tol``), so that it lands on the go side: from a coarse level's root and
    slope this usually takes 2 simulations, from the fast tier's height 3. A no-go point
    only bounds the root from below (and closes a bracket, accepted by linear interpolation
    when it is ``4 x_tol`` wide). Returns None when the steps leave [x_min, x_max], meet a
    non-finite margin, contradict monotonicity or do not converge: the caller then brackets
    and runs Brent's method, reusing every simulation.
    """
    known = slope is not None and slope < 0.0
    slope = slope if known else DEFAULT_GO_SLOPE
    slope_error = CARRIED_GO_SLOPE_ERROR if known else DEFAULT_GO_SLOPE_ERROR
    push = 1.5 * x_tol
    go = []      # (x, m) with m <= 0, closest to the root first
    lo = None    # (x, m) of the highest no-go point (m > 0)
    x = x_guess + guess_error
    for _ in range(max_simulations):
        m = _margin_inside(margin, x, x_min, x_max)
        if m is None:
            return None
        if m > 0.0:
            if lo is None or x > lo[0]:
                lo = (x, m)
        else:
            go.append((x, m))
            go.sort()
        if go and lo is not None and lo[0] >= go[0][0]:
            return None  # not monotone at this scale: leave it to Brent
        if go:
            xa, ma = go[0]
            far = [p for p in go[1:] if p[0] - xa <= GO_SECANT_SPAN]
            if far:
                xb, mb = far[-1]
                secant = (mb - ma) / (xb - xa)
                if not secant < 0.0:
                    return None
                root = xa - ma / secant
                bend = GO_BEND * (xa - root) * (xb - root)
                if (xa - root <= 4.0 * x_tol or bend <= 0.5 * x_tol) and (
                        lo is None or root >= lo[0]):
                    return root
                uncertainty = max(push, bend)
            else:
                root = xa - ma / slope
                # Extrapolating with a slope known to slope_error misses the root by
                # about slope_error (xa - root): one go point suffices when that is small.
                extrapolation_error = slope_error * (xa - root)
                if known and extrapolation_error <= 0.5 * x_tol and (
                        lo is None or root >= lo[0]):
                    return root
                uncertainty = max(push, extrapolation_error)
            if lo is not None:
                if xa - lo[0] <= 4.0 * x_tol:
                    return lo[0] + lo[1] * (xa - lo[0]) / (lo[1] - ma)
                if root <= lo[0]:
                    # The go-side prediction is contradicted by a no-go point: interpolate
                    # in the bracket instead.
                    root = lo[0] + lo[1] * (xa - lo[0]) / (lo[1] - ma)
                    uncertainty = push
            x = root + uncertainty
            if x >= xa - 0.5 * push:
                # The prediction gives no progress: halve the way to the bracket's low end
                # (or to the root predicted from below).
                x = 0.5 * (xa + (lo[0] if lo is not None else root - uncertainty))
        else:
            # Only no-go points: t_ev ~ H^-s predicts the root above; aim past it.
            root = lo[0] - lo[1] / slope
            x = root + max(push, slope_error * (root - lo[0]))
    return None


def _guided_root(margin, x0, slope, x_tol, x_min, x_max, max_simulations=8):
    """Root of the margin on ln H from a close guess ``x0``, always from a tight bracket; or None.

    The margin is smooth but not linear near the root (its slope changes by ~30 % within
    0.5 % of H_c, and it has a kink at the root itself, where the event moves from before to
    after the exit) and carries ~1e-4 of step-size noise, so a root extrapolated from one
    side is not trusted. Steps aim past the predicted root by ``1.5 x_tol`` so that they
    bracket it; once a bracket [a, b] with m(a) > 0 >= m(b) is at most 4 x_tol wide, the
    root is the linear interpolation inside it (error below the bracket width times the
    slope's relative change, < x_tol). The first step uses ``slope`` (d margin / d ln H from
    a coarser search; -1, the t_ev ~ 1/H scaling, when not known). Returns None when the
    steps leave [x_min, x_max], meet a non-finite margin, or do not converge: the caller then
    brackets and runs Brent's method, reusing every simulation.
    """
    slope = slope if slope is not None and slope < 0.0 else -1.0
    push = 1.5 * x_tol
    lo = hi = None  # (x, m) of the closest no-go (m > 0) and go (m <= 0) points
    previous = None
    x = x0
    for _ in range(max_simulations):
        m = _margin_inside(margin, x, x_min, x_max)
        if m is None:
            return None
        if m > 0.0 and (lo is None or x > lo[0]):
            lo = (x, m)
        elif m <= 0.0 and (hi is None or x < hi[0]):
            hi = (x, m)
        if lo is not None and hi is not None:
            if lo[0] >= hi[0]:
                return None  # not monotone at this scale: leave it to Brent
            root = lo[0] + lo[1] * (hi[0] - lo[0]) / (lo[1] - hi[1])
            if hi[0] - lo[0] <= 4.0 * x_tol:
                return root
            # Shrink from the far end: step past the interpolated root, away from the
            # nearer end, so that the new point lands on the far side's sign.
            x = root - push if root - lo[0] > hi[0] - root else root + push
        else:
            # One-sided: secant (or the given slope) prediction, pushed past the root.
            if previous is not None and x != previous[0]:
                secant_slope = (m - previous[1]) / (x - previous[0])
                if secant_slope < 0.0:
                    slope = secant_slope
            x_next = x - m / slope + (push if m > 0.0 else -push)
            previous = (x, m)
            x = x_next
    return None


def _bisection(margin, x_min, x_max, x_tol):
    """The report's search: geometric mean of the lowest go and the highest no-go."""
    if margin(x_max) > 0.0:
        return x_max, "above"
    if margin(x_min) <= 0.0:
        return x_min, "below"
    lo, hi = x_min, x_max
    while hi - lo > x_tol:
        mid = 0.5 * (lo + hi)
        if margin(mid) <= 0.0:
            hi = mid
        else:
            lo = mid
    return 0.5 * (lo + hi), None


def _brent(margin, x_min, x_max, x_tol, model, h_guess, overshoot=0.05):
    """Bracket the root of the margin from a first guess, then Brent's method on ln H.

    ``overshoot`` [1, in ln H] is added to each bracketing step beyond the root that the
    margin predicts (t_ev ~ 1/H): about the error of the guess.
    """
    horizon = math.log(model.end_time / model.exit_time)
    x = math.log(h_guess) if h_guess else 0.0  # 1 m by default
    x = min(max(x, x_min), x_max)
    lo = hi = None  # ln H of the highest no-go and the lowest go
    # Smallest bracketing step, doubled after every step: a margin that hardly depends on H
    # (e.g. a self-heating HE whose event time is set by its bulk, not by friction) still
    # reaches the search bounds within the loop.
    min_step = overshoot
    for _ in range(60):
        m = margin(x)
        if m > 0.0:
            lo = x if lo is None else max(lo, x)
        else:
            hi = x if hi is None else min(hi, x)
        if lo is not None and hi is not None:
            break
        if m > 0.0:
            if x >= x_max:
                return x_max, "above"
            # t_ev ~ 1/H: the root lies about m above; with no event in the horizon, at
            # least `horizon` above. Overshoot a little so one step usually brackets.
            step = 1.2 * m + overshoot if math.isfinite(m) else 2.0 * horizon
            x = min(x + max(step, min_step), x_max)
        else:
            if x <= x_min:
                return x_min, "below"
            x = max(x - max(-1.2 * m + overshoot, min_step), x_min)
        min_step *= 2.0
    else:  # pragma: no cover - the loop always brackets or censors within 60 steps
        raise SolverError("could not bracket the critical height")

    def bounded(xx):
        # Brent needs finite values; "no event within the horizon" means m > horizon.
        m = margin(xx)
        return m if math.isfinite(m) else 2.0 * horizon + 1.0

    x_root = brentq(bounded, lo, hi, xtol=x_tol, rtol=4 * np.finfo(float).eps)
    return x_root, None
