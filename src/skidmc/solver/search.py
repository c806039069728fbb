"""Simulation of one impact and the search for the critical drop height.

The critical height H_c is where the time of the thermal event, t_ev(H), equals the
exit time t_exit (rebound or end of sliding), which does not depend on H. The
search works on the continuous margin

    m(H) = ln(t_ev(H) / t_exit),     go  <=>  m <= 0,

where, beyond t_exit, the flux is extended (:mod:`skidmc.solver.model`) so that t_ev stays
finite a little below H_c; m is smooth and close to linear in ln H (the surface
temperature rises roughly as sqrt(q^2 t) ~ sqrt(H t), so t_ev ~ 1/H), which lets a
bracketing Brent iteration converge in a handful of simulations. The extension
never changes a verdict: at the root, t_ev = t_exit and the extended flux has not
acted yet. The report's own method, geometric bisection on go/no-go, is kept as
``method="bisection"``.
"""


import dataclasses
import math
import numbers
import time

from skidmc.errors import SceneError, SkidmcError
from skidmc.physics.fast import CENSOR_NAMES
from skidmc.scene.scenes import Scene
from skidmc.solver import adaptive
from skidmc.solver.adaptive import (
    ASK_RUN,
    COARSE_GAP,
    FADING_FAST_SHIFT,
    FADING_FAST_SPREAD,
    FAST_STOPS_SLIDING_SPREAD,
    FINE_SHIFT_SPREAD,
    FINISHED,
    MELT_SHIFT_FACTOR,
    P_M,
    P_X,
    R_HEIGHT,
    R_N,
    REGIME_FADING,
    REGIME_STEADY,
    REGIME_STOPS_SLIDING,
)
from skidmc.solver.controller import MAX_ADAPTIVE_ROUNDS, first_root_tolerances, richardson_value
from skidmc.solver.model import (
    build_model,
    constant_property_scene,
    elastic_target_reason,
    target_temperature_range,
)
from skidmc.solver.options import (
    DEFAULT_H_MAX,
    DEFAULT_H_MIN,
    FADING_EXIT_SPEED,
    TARGETS,
    SearchOptions,
    exit_regime,
    resolve_options,
)
from skidmc.solver.plan import (
    EXACT_FINE_SHIFT,
    EXACT_FINE_SHIFT_SPREAD,
    EXACT_STEADY_FINE_OVERSHOOT,
    extrapolated_error,
    melt_bias,
    modelled_error,
    root_tolerance,
)
from skidmc.solver.results import HeightResult, flag_unmet_rtol
from skidmc.solver.roots import (
    FAST_GUESS_ERROR,
    JUMP_SLOPE,
    bisection_root,
    brent_root,
    go_side_root,
    go_side_slope,
    margin_slope,
    prior_bisection_root,
)
from skidmc.solver.simulate import LinearPrefix, SolverError, simulate

__all__ = ["COARSE_GAP", "DEFAULT_H_MAX", "DEFAULT_H_MIN", "FADING_EXIT_SPEED",
           "FADING_FAST_SHIFT", "FADING_FAST_SPREAD", "FAST_STOPS_SLIDING_SPREAD",
           "FINE_SHIFT_SPREAD",
           "MAX_ADAPTIVE_ROUNDS",
           "MELT_SHIFT_FACTOR", "TARGETS", "TIERS", "SceneUnsolvable", "SearchOptions",
           "critical_height"]

#: Model fidelity tiers: "full" (the report's model, converged to rtol) and "fast" (the
#: reduced model of :mod:`skidmc.solver.fast`, ~10-20 us per height, a few percent off the full
#: model).
TIERS = ("full", "fast")

class SceneUnsolvable(SolverError, SkidmcError):
    """The solver could not finish a scene that passed validation (a time integration that
    cannot proceed, an overflow): ``str(err)`` gives the reason and the scene's inputs outside
    their plausible range (:func:`skidmc.scene.scenes.implausible_inputs`), the likely cause.
    A :class:`SolverError`, so that a run records it as a failed sample with this reason."""

    def __init__(self, scene, exc: BaseException) -> None:
        from skidmc.scene.scenes import implausible_inputs

        odd = implausible_inputs(scene) if isinstance(scene, Scene) else ()
        why = f"{type(exc).__name__}: {exc}"
        # the likely cause first: a run's reasons are kept to 256 characters
        hint = " (likely cause: " + "; ".join(odd) + ")" if odd else ""
        super().__init__(f"the solver could not finish this scene{hint}: {why}")
        self.cause, self.implausible = why, odd


def critical_height(scene, rtol=1e-3, tier="full", h_min=DEFAULT_H_MIN, h_max=DEFAULT_H_MAX,
                    **kwargs):
    try:
        res = _critical_height(scene, rtol, tier, h_min, h_max, **kwargs)
    except (SolverError, ArithmeticError, ValueError) as exc:
        if isinstance(exc, (SkidmcError, TypeError)):  # argument errors name their argument
            raise
        raise SceneUnsolvable(scene, exc) from exc
    if tier == "full" and kwargs.get("level") is None and kwargs.get("model") is None:
        # rtol chose the plan: never silently unmet (the fast tier and a forced level or
        # model do not aim at rtol)
        res = flag_unmet_rtol(res, rtol)
    return res


def _critical_height(scene, rtol=1e-3, tier="full", h_min=DEFAULT_H_MIN, h_max=DEFAULT_H_MAX,
                    *, method="brent", level=None, extrapolate=None, melting=True,
                    runaway_fraction=None, h_guess=None, model=None, melt_width=None,
                    melt_spread=None, target=None):
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
        reduced model of :func:`skidmc.solver.fast.fast_critical_height` (``rtol`` and the numerical
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
        Override the runaway rule (:data:`skidmc.physics.thermal.DEFAULT_RUNAWAY_FRACTION`).
    h_guess : float, optional
        First height tried [m].
    model : SkidModel, optional
        A prebuilt model (overrides scene, level, melting, runaway_fraction, melt_width; no
        extrapolation or coarse start).
    melt_width : float, optional
        Width of the smoothed melting step [K]; default :func:`melt_width_for_rtol`.
    melt_spread : float, optional
        Spread of each HE cell's melting step over the cell's own temperature range, as a
        multiple of it [1], in [0, 1.5]. Default: :data:`skidmc.physics.thermal.MELT_SPREAD`
        (1) in the default search, whose a posteriori estimate was calibrated with it
        (3-4x fewer time steps at rtol 1e-3; docs/model.md, "Melting spread over a cell"); 0
        (the fixed step the calibrated level model was fitted on) when ``level``, ``model``
        or ``extrapolate=False`` fixes the plan (given with a fixed plan, the reported
        calibrated estimate may understate its error by up to 8 %).
    target : {"exact", "mesh"}, optional
        How the target is modelled (:func:`skidmc.solver.model.build_model`). Default: "exact"
        (the exact semi-infinite solid, only the HE meshed) in the default search, whose a
        posteriori estimate was calibrated with it (``scripts/a_posteriori_calibration.py``;
        2-5x smaller level errors at ~0.75x the time per simulation; docs/model.md, "The
        target as an exact semi-infinite solid"); "mesh" (the target on its own mesh, what the
        calibrated level model was fitted on) when ``level``, ``model`` or
        ``extrapolate=False`` fixes the plan. Ignored with ``model``.

    Returns
    -------
    HeightResult
    """
    start = time.perf_counter()
    if model is None and not isinstance(scene, Scene):
        raise TypeError(f"scene: expected a skidmc.scene.Scene (skidmc.scene.make_scene or "
                        f"get_preset), got {type(scene).__name__} {scene!r:.60}")
    if tier not in TIERS:
        raise SceneError("tier", tier, f"unknown tier (expected one of {', '.join(TIERS)})")
    for name, bound in (("h_min", h_min), ("h_max", h_max)):
        if isinstance(bound, bool) or not isinstance(bound, numbers.Real) \
                or not 0.0 < bound < math.inf:
            raise SceneError(name, bound, "must be a finite number > 0 [m]")
    if not h_min < h_max:
        # name the bound that was moved: the other one is (likely) the default
        name, value = (("h_max", h_max) if h_min == DEFAULT_H_MIN else ("h_min", h_min))
        raise SceneError(name, value, f"need h_min < h_max [m] (h_min = {h_min!r}, "
                         f"h_max = {h_max!r})")
    refused = elastic_target_reason(scene)
    if refused is not None:
        raise SceneError("target.hardness", scene.target_hardness, refused)
    if tier == "fast":
        from skidmc.solver.fast import fast_critical_height

        return fast_critical_height(scene, h_min=h_min, h_max=h_max, melting=melting)
    opts = resolve_options(scene, rtol, h_min=h_min, h_max=h_max, method=method, level=level,
                           extrapolate=extrapolate, melting=melting,
                           runaway_fraction=runaway_fraction, model=model,
                           melt_width=melt_width, melt_spread=melt_spread, target=target)
    if opts.adaptive:
        # The root finder gets the room the pair is likely not to use; the a posteriori
        # estimate, not the calibrated model, then decides whether it fits (_adaptive_pair).
        return _adaptive_pair(scene, opts, h_guess, start)
    x_tol = root_tolerance(rtol, opts.level, opts.extrapolate, opts.melt_width)
    if not opts.extrapolate:
        res = _search(scene, opts, opts.level, x_tol, model=model, h_guess=h_guess)
        res.wall_time = time.perf_counter() - start
        return res

    # Richardson: R = H_L + (H_L - H_{L-1}) / 3. Root-finder errors d_L, d_{L-1} enter R as
    # (4 d_L + d_{L-1}) / 3: the cheap coarse search gets the whole root-finder tolerance and
    # the fine one half of it, (4 / 2 + 1) / 3 = 1 tolerance in all.
    coarse = _search(scene, opts, opts.level - 1.0, x_tol, h_guess=h_guess)
    fine = _fine_search(scene, opts, opts.level, 0.5 * x_tol, coarse, x_tol)
    res = _censor_beyond_bounds(_richardson(coarse, fine, opts, x_tol), h_min, h_max)
    res.evaluations = coarse.evaluations + fine.evaluations
    res.wall_time = time.perf_counter() - start
    return res


critical_height.__doc__ = _critical_height.__doc__.replace(
    "    Returns\n",
    "    A failure of the solver on a valid scene raises :class:`SceneUnsolvable` (a\n"
    "    :class:`SolverError` naming the inputs outside their plausible range). A result whose\n"
    "    ``error_estimate`` stayed above ``rtol`` (the search refined as far as it goes) carries\n"
    "    the flag ``\"rtol_unmet\"`` (:data:`skidmc.solver.results.RTOL_UNMET`); its\n"
    "    ``error_estimate`` is the one reached.\n\n"
    "    Returns\n", 1)
critical_height.__wrapped__ = _critical_height  # inspect.signature: the full signature


def _fine_search(scene, opts, level, x_tol, coarse, coarse_tol):
    """The fine search of a Richardson pair, started from its coarse search's root and slopes.

    The fine root lies above the coarse one by about 3/4 of the coarse level's error (the
    errors are negative and shrink 4x per level; the fine level keeps 1/4 of it): the go-side
    search starts that far up, which lands on the go side within the error model. Where the
    margin jumps (sliding stops), the coarse root's own tolerance ``coarse_tol`` [1] widens
    the prior of the fine root (:func:`skidmc.solver.roots.prior_bisection_root`). With the
    exact target on a scene located by ``opts.signs``, the prior is the one measured for it
    (:data:`skidmc.solver.plan.EXACT_FINE_SHIFT`, ``EXACT_FINE_SHIFT_SPREAD``).
    """
    coarse_error = modelled_error(level - 1.0)
    overshoot, spread = 0.75, FINE_SHIFT_SPREAD
    if opts.exact:
        overshoot = 2.0 * EXACT_FINE_SHIFT if opts.signs else EXACT_STEADY_FINE_OVERSHOOT
        spread = EXACT_FINE_SHIFT_SPREAD
    return _search(scene, opts, level, x_tol,
                   h_guess=coarse.critical_height if coarse.censored is None else None,
                   overshoot=overshoot * coarse_error,
                   guess_sigma=spread * coarse_error + 0.5 * coarse_tol,
                   slope=margin_slope(coarse.history), go_slope=go_side_slope(coarse.history))


_REGIME_CODES = {"steady": REGIME_STEADY, "fading": REGIME_FADING,
                 "stops_sliding": REGIME_STOPS_SLIDING}


def _adaptive_pair(scene, opts, h_guess, start):
    """The default search: a Richardson pair whose own estimate is brought within ``rtol``.

    The search is the compiled machine of :mod:`skidmc.solver.adaptive` (the one the device
    search drives too): the first pair ``(level - 1, level)`` with the root tolerances
    :func:`skidmc.solver.controller.first_root_tolerances`, its estimate measured (the a
    posteriori error of the correction, the melting width's bias, and the root errors the
    tolerances allow), then the rounds of :func:`skidmc.solver.controller.next_round` (tighten
    the roots from their own simulations, search the pair again with a narrower melting width,
    or move the pair up a level) until the estimate meets rtol or nothing left can help: then
    the estimate stays above rtol and says so. This function only answers the machine's
    questions: each run it asks for is :func:`skidmc.solver.simulate.simulate` on the model of
    its level and melting width, the runs of one search sharing a :class:`LinearPrefix`.
    """
    rtol = opts.rtol
    coarse_tol, fine_tol = first_root_tolerances(rtol, opts.level, opts.melt_width,
                                                 opts.melt_spread, opts.exact, opts.signs)
    kwargs = dict(melting=opts.melting, melt_spread=opts.melt_spread, target=opts.target,
                  rtol=rtol, **opts.model_kwargs())
    probe = build_model(scene, level=opts.level - 1.0, meshes=False, **kwargs)
    melting_term = "melting" in probe.terms
    # The melting width's bias is measured where the calibrated bound does not apply: scenes
    # that ignite below the melting point (the bound was measured on scenes igniting above it:
    # the presets, ~47 K above; a level-0 shift overstates the bias there, 3.5x on
    # paper-quartz; below it the runaway starts where the smoothed step releases its latent
    # heat, and the bias is the scene's own, 15x the bound at E/R = 15,000 K with a fast
    # prefactor).
    measure_bias = melting_term and build_model(
        scene, level=opts.level - 1.0, melting=opts.melting,
        meshes=False).ignition_temperature < scene.he_melting_point
    fast = None if h_guess is not None else _fast_guess(scene, opts.h_min, opts.h_max,
                                                        opts.melting)
    ps, res, pts, st, fpts = adaptive.new_storage()
    code, x = adaptive.pair_start(
        ps, res, pts, st, fpts, rtol, opts.h_min, opts.h_max, opts.level, opts.melt_width,
        coarse_tol, fine_tol, opts.melt_spread, opts.exact, opts.signs,
        _REGIME_CODES[exit_regime(scene)], melting_term, measure_bias, True, math.inf,
        "no_friction" in probe.flags, math.nan if fast is None else fast,
        math.nan if h_guess is None else float(h_guess),
        math.log(probe.end_time / probe.exit_time), opts.method == "bisection")
    models, prefix, serial = {}, None, -1

    def model_of(level, width):
        key = (level, width)
        if key not in models:
            models[key] = build_model(scene, level=level, melt_width=width, **kwargs)
        return models[key]

    while code == ASK_RUN:
        level, width, until_exit, alone, ask_serial = adaptive.asked(ps)
        model = model_of(level, width)
        if not alone and ask_serial != serial:
            prefix, serial = LinearPrefix(model), ask_serial   # a new search
        sim = simulate(model, math.exp(x), until_exit=until_exit,
                       prefix=None if alone else prefix)
        code, x = adaptive.pair_step(ps, res, pts, st, fpts, sim.margin, sim.event)
    if code != FINISHED:   # pragma: no cover - a CPU run raises instead of failing quietly
        raise SolverError(f"the search ended without a root (reason {int(ps[0]['reason'])})")
    (height, censor, estimate, level, extrapolated, correction, melt_bias,
     evaluations) = adaptive.outcome(ps)
    # The fine search's history, flags and model (its own height's flags, as _search gives).
    model = model_of(level, float(ps[0]["melt_width"]))
    n = int(res[1, R_N])
    history = sorted((math.exp(float(x)), float(m))
                     for x, m in zip(pts[1, P_X, :n], pts[1, P_M, :n]))
    flags = model.flags
    if "no_friction" not in model.flags:
        flags = flags + model.height_flags(float(res[1, R_HEIGHT]))
    return HeightResult(
        critical_height=float(height), censored=CENSOR_NAMES[int(censor)],
        evaluations=int(evaluations), flags=flags, error_estimate=float(estimate), rtol=rtol,
        level=float(level), method=opts.method, exit_time=model.exit_time,
        exit_kind=model.exit_kind, terms=model.terms, extrapolated=bool(extrapolated),
        richardson_correction=float(correction), melt_bias_estimate=float(melt_bias),
        history=history, wall_time=time.perf_counter() - start)


def _censor_beyond_bounds(res, h_min, h_max):
    """``res`` censored at the search bound its extrapolated height crossed [a new result].

    Both roots of a Richardson pair lie inside [h_min, h_max], but their extrapolation may not:
    a fine root just below h_max with a coarse one below it extrapolates above (the extremes
    matrix's box: 1002 m with h_max = 1000 m). The converged model then has no event at the
    bound, which is what "above" says (and "below" for h_min); the error estimate is kept.
    """
    if res.censored is not None or h_min < res.critical_height < h_max:
        return res
    censored = "above" if res.critical_height >= h_max else "below"
    return dataclasses.replace(res, censored=censored, extrapolated=False,
                               critical_height=h_max if censored == "above" else h_min)


def _pair_value(coarse, fine):
    """The Richardson value of a pair of searches (a new result; ``fine`` if either is
    censored) and whether it was extrapolated."""
    res = dataclasses.replace(fine, history=list(fine.history))
    if fine.censored is not None or coarse.censored is not None:
        return res, False
    res.critical_height, res.richardson_correction = richardson_value(coarse.critical_height,
                                                                      fine.critical_height)
    res.extrapolated = True
    return res, True


def _richardson(coarse, fine, opts, x_tol):
    """The Richardson value of a pair of a fixed plan, with the calibrated model's estimate
    (``x_tol``: the plan's root tolerance [1])."""
    res, extrapolated = _pair_value(coarse, fine)
    if extrapolated:
        res.error_estimate = (extrapolated_error(fine.level) + x_tol
                              + melt_bias(fine.terms, opts.melt_width, fine.level))
    return res


def _search(scene, opts, level, x_tol, *, model=None, h_guess=None, overshoot=None, slope=None,
            go_slope=None, guess_sigma=None):
    """One critical-height search at one resolution level (see :func:`critical_height`).

    ``x_tol`` [1] is the root finder's tolerance on ln H. With no guess, the search starts
    from the root found at ``level - COARSE_GAP`` (levels >= COARSE_GAP) or from the fast
    tier's height. From a guess, a rebound exit's root is extrapolated along the go side
    (:func:`~skidmc.solver.roots.go_side_root`, 1-3 simulations); where sliding stops, the
    root's prior is bisected (:func:`~skidmc.solver.roots.prior_bisection_root`; its spread is
    ``guess_sigma`` [1, in ln H] when given). Otherwise bracketing and Brent's method take
    over, reusing every simulation done. The default search does not come here: its searches
    are the compiled machine's (:func:`_adaptive_pair`); this is the search of the fixed plans
    (a forced level or model, no extrapolation, the report's bisection).
    """
    rtol, method, h_min, h_max = opts.rtol, opts.method, opts.h_min, opts.h_max
    own_model = model is None
    if own_model:
        model = build_model(scene, level=level, melting=opts.melting,
                            melt_width=opts.melt_width, melt_spread=opts.melt_spread,
                            target=opts.target, rtol=rtol, **opts.model_kwargs())
    base = dict(rtol=rtol, level=level, method=method, exit_time=model.exit_time,
                exit_kind=model.exit_kind, terms=model.terms, flags=model.flags,
                error_estimate=(modelled_error(level) + x_tol
                                + melt_bias(model.terms, model.resolution.melt_width,
                                             level)))

    if "no_friction" in model.flags:
        return HeightResult(critical_height=h_max, censored="above", evaluations=0, **base)

    coarse_evaluations = 0
    from_fast_tier = False
    if method == "brent" and h_guess is None and own_model and level >= COARSE_GAP:
        coarse = _search(scene, opts, level - COARSE_GAP,
                         max(x_tol, 0.2 * modelled_error(level - COARSE_GAP)))
        coarse_evaluations = coarse.evaluations
        if coarse.censored is None:
            h_guess = coarse.critical_height
            slope = margin_slope(coarse.history)
            go_slope = go_side_slope(coarse.history)
            # The fine root lies within the coarse level's error of the coarse root.
            overshoot = 2.0 * modelled_error(level - COARSE_GAP)
    elif method == "brent" and h_guess is None and own_model:
        fast = _fast_guess(scene, h_min, h_max, opts.melting)
        if fast is not None:
            h_guess, overshoot, from_fast_tier = fast, FAST_GUESS_ERROR, True

    cache = {}
    # A margin that jumped at the root of the search the guess came from (a coarser level, or
    # this one at a looser tolerance) is searched by its signs (prior_bisection_root): its
    # go side says nothing about where the jump lies.
    jumped = slope is not None and slope < -JUMP_SLOPE
    # From the fast tier's height, a rebound whose heating fades before the exit is searched
    # from the prior of its root (FADING_FAST_SHIFT above that height): the go-side search
    # would start below the root there, and its first step up overshoots by the margin's jump.
    fading = from_fast_tier and exit_regime(scene) == "fading"
    # Where the root is located by the margin's signs alone (prior_bisection_root below: sliding
    # stops before rebound, or a rebound's margin jumped or its heating fades), a simulation
    # without an event by the exit stops there (until_exit; margin inf) instead of going on
    # under the extension flux to ~1.1 t_exit, which took 35-40 % of a no-go run's steps and
    # half its time. The verdict is the same: only events before the exit count.
    signs_only = method == "brent" and h_guess is not None and (
        model.exit_kind != "rebound" or jumped or fading)
    sign_only_points = set()
    # The search's runs share their linear start (the first run records it).
    prefix = LinearPrefix(model)

    def margin(x):
        if x not in cache:
            sim = simulate(model, math.exp(x), until_exit=signs_only, prefix=prefix)
            cache[x] = sim.margin
            if signs_only and not sim.event:
                sign_only_points.add(x)
        return cache[x]

    x_min, x_max = math.log(h_min), math.log(h_max)
    x_root = None
    if method == "bisection":
        x_root, censored = bisection_root(margin, x_min, x_max, x_tol)
    elif h_guess is not None and model.exit_kind == "rebound" and not (jumped or fading):
        x_root = go_side_root(margin, math.log(h_guess), go_slope, x_tol, x_min, x_max,
                               guess_error=overshoot or FAST_GUESS_ERROR)
        censored = None
    elif h_guess is not None:
        # Sliding stops before rebound, or the guess's search saw the margin jump at its root
        # (``slope`` steeper than JUMP_SLOPE: some rebound scenes, whose event either comes
        # before the exit or not at all): the margin jumps at the root, so only the signs of its
        # values locate it. The prior of the root: the fast tier's height and its measured
        # scatter there (FADING_FAST_SHIFT above it where the heating fades), or (a coarser
        # level's root, a re-search) half the guess's uncertainty up, with guess_sigma or a
        # third of that as its spread (a Richardson pair's fine search: 0.375 of the coarse
        # level's modelled error up, FINE_SHIFT_SPREAD of it wide).
        if fading:
            center, sigma = math.log(h_guess) + FADING_FAST_SHIFT, FADING_FAST_SPREAD
        elif from_fast_tier:
            center, sigma = math.log(h_guess), FAST_STOPS_SLIDING_SPREAD
        else:
            spread = 0.5 * (overshoot or FAST_GUESS_ERROR)
            center, sigma = math.log(h_guess) + spread, guess_sigma or spread / 3.0
        x_root, censored = prior_bisection_root(margin, center, sigma, x_tol, x_min, x_max,
                                                slope=slope,
                                                signs_only=signs_only), None
    if x_root is None:
        # Brent's bracketing steps by the margin's value: the sign-only runs are done again in
        # full when it needs them.
        signs_only = False
        for x in sign_only_points:
            del cache[x]
        x_root, censored = brent_root(margin, x_min, x_max, x_tol,
                                       math.log(model.end_time / model.exit_time), h_guess,
                                  overshoot=overshoot or 0.05)
    history = sorted((math.exp(x), m) for x, m in cache.items())
    # Censored results report the bound itself, exactly as given.
    height = {"above": h_max, "below": h_min}.get(censored, math.exp(x_root))
    # Validity at the height found (indentation depth, sliding distance): skidmc.solver.model.
    base["flags"] = model.flags + model.height_flags(height)
    return HeightResult(critical_height=height, censored=censored,
                        evaluations=len(cache) + coarse_evaluations, history=history,
                        **base)


def _fast_guess(scene, h_min, h_max, melting):
    """The fast tier's critical height [m] as a first guess, or None (censored or failed)."""
    from skidmc.solver.fast import fast_critical_height

    if scene.target_table:
        # The fast tier's target has constant properties: for a guess, those of the table at
        # the middle of the interface's rise (docs/targets.md).
        model = build_model(scene, meshes=False, melting=melting)
        low, high = target_temperature_range(scene.initial_temperature,
                                             model.runaway_temperature)
        scene = constant_property_scene(scene, 0.5 * (low + high))
    try:
        res = fast_critical_height(scene, h_min=h_min, h_max=h_max, melting=melting)
    except Exception:  # noqa: BLE001 - only a guess: the full search does not need it
        return None
    h = res.critical_height
    return h if res.censored is None and math.isfinite(h) else None
