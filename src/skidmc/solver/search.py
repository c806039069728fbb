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
from skidmc.scene.scenes import Scene
from skidmc.solver.controller import (
    DONE,
    MAX_ADAPTIVE_ROUNDS,
    NARROW,
    REFINE,
    TIGHTEN_BOTH,
    TIGHTEN_FINE,
    first_root_tolerances,
    next_round,
    pair_estimate,
    richardson_value,
)
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
    melt_bias_bound,
    modelled_error,
    root_tolerance,
)
from skidmc.solver.results import HeightResult, flag_unmet_rtol
from skidmc.solver.roots import (
    FAST_GUESS_ERROR,
    FOLD_SLOPE,
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

#: The melting width's bias b(w) on the critical height [1] from the root's shift dx when the
#: width is doubled: b(w) = 1.3-1.9 dx on the report presets (concave, first order in w); 2.5
#: bounds it with 30 % to spare (:func:`_melt_width_bias`).
MELT_SHIFT_FACTOR = 2.5

#: Model fidelity tiers: "full" (the report's model, converged to rtol) and "fast" (the
#: reduced model of :mod:`skidmc.solver.fast`, ~10-20 us per height, a few percent off the full
#: model).
TIERS = ("full", "fast")

#: Scatter of the fast tier's ln H about the full model's where sliding stops [1], the prior's
#: spread of a stops-sliding search from the fast tier's height
#: (:func:`skidmc.solver.roots.prior_bisection_root`): sd 0.016 on the training scenes of
#: scripts/fast_tier_error.py after :data:`skidmc.physics.fast.STOPS_SLIDING_FACTOR`,
#: rounded up. A guess further off costs doubling steps, never a wrong root.
FAST_STOPS_SLIDING_SPREAD = 0.02

#: Shift [1, in ln H] of the root's prior above the fast tier's height on rebound scenes whose
#: heating fades before the exit (sliding speed at rebound below :data:`FADING_EXIT_SPEED` of the
#: initial one), and the prior's spread: there the fast tier's height is low. The level-0.5 root
#: (melting width 1 K, spread 1) measured against it on the rebound scenes of
#: ``scripts/fast_tier_error.py``'s sets with an exit speed ratio below 0.5: training set
#: ln(H / H_fast) mean +0.038, sd 0.016 (25 scenes); test set +0.044, sd 0.014 (34 scenes)
#: (+0.032 to +0.052 on the fading scenes of ``skidmc.scene.validation``); at ratios 0.5-0.6
#: +0.016 to +0.025, above 0.6 -0.013 to -0.001. Fitted on the training set (mean rounded,
#: spread rounded up as for :data:`FAST_STOPS_SLIDING_SPREAD`). A guess further off costs
#: doubling steps, never a wrong root.
FADING_FAST_SHIFT = 0.04
FADING_FAST_SPREAD = 0.02

#: Spread of the fine root's prior in a Richardson pair whose margin jumps, as a fraction of the
#: coarse level's modelled error [1] (:func:`_fine_search`; the coarse root's own tolerance is
#: added). The fine root lies 0.375 of that error above the coarse root on average: measured
#: with tight roots, melting width 1 K and spread 1, 0.27-0.44 (sd ~0.04) for the pair
#: (0.5, 1.5) and 0.31-0.48 for (0, 1) on the 20 scenes of seeds 16 and 17 of
#: ``skidmc.scene.validation`` whose margin is likely to jump. 0.06 puts the farthest of them
#: 1.75 spreads out; it was 0.125 (a sixth of 0.75). On a held-out draw (seed 18, 14 such
#: scenes): 0.27-0.39 and 0.31-0.46 (``tests/test_root_tolerance.py``). At rtol 1e-3 it saves
#: one fine simulation on 9 of those 20 scenes. A root farther out costs doubling steps, never
#: a wrong root.
FINE_SHIFT_SPREAD = 0.06

#: Coarse-to-fine search: at level L >= COARSE_GAP, the critical height is first found at level
#: L - COARSE_GAP (each simulation ~10x cheaper), and the search at level L starts there with a
#: bracket a few coarse errors wide, so it needs ~4 fine simulations instead of ~8.
COARSE_GAP = 2.0


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


def _adaptive_pair(scene, opts, h_guess, start):
    """The default search: a Richardson pair whose own estimate is brought within ``rtol``.

    The first pair ``(level - 1, level)`` gets the root tolerances
    :func:`skidmc.solver.controller.first_root_tolerances` (the room its estimate is likely to
    leave). Its estimate is then measured (:func:`_adaptive_value`: the a posteriori error of
    the correction, the melting width's bias, and the root errors the tolerances used allow).
    While it exceeds rtol, :func:`skidmc.solver.controller.next_round` (the rule the device
    search runs too) picks the cheapest fix the measured parts say will do: tighten the roots
    (each re-search starting from its own root and reusing its simulations), search the pair
    again with a narrower melting width (measuring its bias anew), or move the pair up a level
    (its next fine root predicted from the pair), until the estimate meets rtol or nothing
    left can help: then the estimate stays above rtol and says so.
    """
    rtol = opts.rtol
    coarse_tol, fine_tol = first_root_tolerances(rtol, opts.level, opts.melt_width,
                                                 opts.melt_spread, opts.exact, opts.signs)
    coarse = _search(scene, opts, opts.level - 1.0, coarse_tol, h_guess=h_guess)
    fine = _fine_search(scene, opts, opts.level, fine_tol, coarse, coarse_tol)
    evaluations = coarse.evaluations + fine.evaluations
    melt, extra = _melt_width_bias(scene, coarse, opts)
    evaluations += extra
    res, pair = _adaptive_value(coarse, fine, opts, coarse_tol, fine_tol, melt)
    narrowed = 0
    for _ in range(MAX_ADAPTIVE_ROUNDS):
        if not res.extrapolated:
            break
        action, next_coarse_tol, next_fine_tol, value = next_round(
            rtol, res.error_estimate, pair, res.melt_bias_estimate, res.richardson_correction,
            res.critical_height, coarse.level, coarse_tol, fine_tol, opts.melt_width, narrowed,
            opts.melt_spread, opts.exact, opts.signs)
        if action == DONE:
            break
        if action == TIGHTEN_FINE:
            fine, n = _tighten(scene, opts, fine, fine_tol, next_fine_tol)
            evaluations += n
        elif action == TIGHTEN_BOTH:
            coarse, n = _tighten(scene, opts, coarse, coarse_tol, next_coarse_tol)
            fine, m = _tighten(scene, opts, fine, fine_tol, next_fine_tol)
            evaluations += n + m
        elif action == NARROW:
            # Search the pair again at the new width (from the old root), measuring its bias
            # anew.
            opts = opts.with_melt_width(value)
            narrowed += 1
            coarse = _search(scene, opts, coarse.level, next_coarse_tol,
                             h_guess=coarse.critical_height,
                             overshoot=2.0 * res.melt_bias_estimate + next_coarse_tol,
                             slope=margin_slope(coarse.history),
                             go_slope=go_side_slope(coarse.history))
            fine = _fine_search(scene, opts, fine.level, next_fine_tol, coarse, next_coarse_tol)
            melt, extra = _melt_width_bias(scene, coarse, opts)
            evaluations += coarse.evaluations + fine.evaluations + extra
        elif action == REFINE:
            # value: the next level's root predicted from this pair [m].
            finer = _search(scene, opts, fine.level + 1.0, next_fine_tol, h_guess=value,
                            overshoot=0.5 * abs(res.richardson_correction) + next_fine_tol,
                            slope=margin_slope(fine.history),
                            go_slope=go_side_slope(fine.history))
            evaluations += finer.evaluations
            coarse, fine = fine, finer
        else:   # STOP: nothing left that can help
            break
        coarse_tol, fine_tol = next_coarse_tol, next_fine_tol
        res, pair = _adaptive_value(coarse, fine, opts, coarse_tol, fine_tol, melt)
    res = _censor_beyond_bounds(res, opts.h_min, opts.h_max)
    res.evaluations = evaluations
    res.wall_time = time.perf_counter() - start
    return res


def _tighten(scene, opts, search, old_tol, tol):
    """``search`` again at the tighter root tolerance ``tol`` [1], from its own root.

    The root lies within ``old_tol`` of the old one: the new search starts there, with the old
    search's slopes and simulations (no height is simulated twice). Returns the new search and
    the simulations it added.
    """
    if search.censored is not None:
        return search, 0
    new = _search(scene, opts, search.level, tol, h_guess=search.critical_height,
                  overshoot=old_tol, slope=margin_slope(search.history),
                  go_slope=go_side_slope(search.history), known=search.history)
    added = new.evaluations
    new.evaluations += search.evaluations
    return new, added


def _melt_width_bias(scene, coarse, opts):
    """Measured bias of the melting step's width on ln H [1], and the simulations it took.

    Only for scenes whose ignition temperature (:attr:`SkidModel.ignition_temperature`) lies
    below the melting point, where the calibrated bound does not apply.

    One simulation at the coarse level with the width doubled, at the coarse search's go point
    closest to its root: the margin's change over the go side's slope is the root's shift
    dx from w to 2w. The bias is close to first order in w and concave (quartz: b(2 K) = 1.9 x
    (b(4 K) - b(2 K)), b(1 K) = 1.3 x (b(2 K) - b(1 K)); results/validation/melt_width_bias.md),
    so b(w) ~ dx; :data:`MELT_SHIFT_FACTOR` |dx| bounds it. Returns (None, 0) without melting
    or where no smooth go side is known (a margin that jumps or folds at the root: there the
    calibrated bound alone is used).
    """
    if coarse.censored is not None or "melting" not in coarse.terms:
        return None, 0
    if not build_model(scene, level=coarse.level, melting=opts.melting,
                       meshes=False).ignition_temperature < scene.he_melting_point:
        # The calibrated bound was measured on scenes that ignite above the melting point
        # (the presets: T_ign ~600 K, 47 K above it); there it holds, and a level-0 shift
        # overstates the bias (3.5x on paper-quartz). Below it, the runaway starts where the
        # smoothed step releases its latent heat, and the bias is the scene's own (15x the
        # bound at E/R = 15,000 K with a fast prefactor).
        return None, 0
    slope = go_side_slope(coarse.history)
    go = [(h, m) for h, m in coarse.history if math.isfinite(m) and m <= 0.0]
    if slope is None or slope < -FOLD_SLOPE or not go:
        return None, 0
    height, m_go = go[0]
    model = build_model(scene, level=coarse.level, melting=opts.melting,
                        melt_width=2.0 * opts.melt_width, melt_spread=opts.melt_spread,
                        target=opts.target, rtol=coarse.rtol, **opts.model_kwargs())
    m_wide = simulate(model, height).margin
    if not math.isfinite(m_wide):
        return None, 1
    return MELT_SHIFT_FACTOR * abs(m_wide - m_go) / -slope, 1


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


def _adaptive_value(coarse, fine, opts, coarse_tol, fine_tol, melt):
    """The Richardson value of the default search's pair and its a posteriori part [1].

    Its ``error_estimate`` [1] is measured on the pair
    (:func:`skidmc.solver.controller.pair_estimate`): the a posteriori error of its correction,
    plus the melting width's bias (the bound, or ``melt`` measured on the scene when larger)
    and the root errors its searches' tolerances allow.
    """
    res, extrapolated = _pair_value(coarse, fine)
    if not extrapolated:
        return res, 0.0
    # The width's bias: the calibrated bound, or what this scene measured if larger.
    res.melt_bias_estimate = max(melt_bias_bound(fine.terms, opts.melt_width), melt or 0.0)
    pair, res.error_estimate = pair_estimate(res.richardson_correction, coarse.level,
                                             opts.melt_spread, opts.exact, opts.signs,
                                             res.melt_bias_estimate, coarse_tol, fine_tol)
    return res, pair


def _search(scene, opts, level, x_tol, *, model=None, h_guess=None, overshoot=None, slope=None,
            go_slope=None, known=(), guess_sigma=None):
    """One critical-height search at one resolution level (see :func:`critical_height`).

    ``x_tol`` [1] is the root finder's tolerance on ln H. With no guess, the search starts
    from the root found at ``level - COARSE_GAP`` (levels >= COARSE_GAP) or from the fast
    tier's height. From a guess, a rebound exit's root is extrapolated along the go side
    (:func:`~skidmc.solver.roots.go_side_root`, 1-3 simulations); where sliding stops, the
    root's prior is bisected (:func:`~skidmc.solver.roots.prior_bisection_root`; its spread is
    ``guess_sigma`` [1, in ln H] when given). Otherwise bracketing and Brent's method take
    over, reusing every simulation done. ``known``: (H [m], margin) already simulated with
    this search's model (a search repeated at a tighter tolerance): reused, and counted only
    in the earlier search's evaluations.
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

    cache = {math.log(h): m for h, m in known}
    n_known = len(cache)
    points = [(x, m) for x, m in cache.items() if math.isfinite(m)]
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
                               guess_error=overshoot or FAST_GUESS_ERROR, points=points)
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
        known_signs = [(x, m) for x, m in cache.items() if m == math.inf] if signs_only else []
        x_root, censored = prior_bisection_root(margin, center, sigma, x_tol, x_min, x_max,
                                                slope=slope, points=points + known_signs,
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
                        evaluations=len(cache) - n_known + coarse_evaluations, history=history,
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
