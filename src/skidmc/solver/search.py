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


import math
import numbers
import time

from skidmc.errors import SceneError, SkidmcError
from skidmc.physics.fast import CENSOR_NAMES
from skidmc.physics.thermal import DEFAULT_RUNAWAY_FRACTION
from skidmc.scene.scenes import Scene
from skidmc.solver import adaptive
from skidmc.solver.adaptive import (
    ASK_RUN,
    BACK_LEVEL,
    COARSE_GAP,
    FADING_FAST_SHIFT,
    FADING_FAST_SPREAD,
    FAST_STOPS_SLIDING_SPREAD,
    FINE_SHIFT_SPREAD,
    FINISHED,
    HAND_BACK,
    MELT_SHIFT_FACTOR,
    P_M,
    P_X,
    R_HEIGHT,
    R_N,
    REGIME_FADING,
    REGIME_STEADY,
    REGIME_STOPS_SLIDING,
)
from skidmc.solver.controller import MAX_ADAPTIVE_ROUNDS, first_root_tolerances
from skidmc.solver.model import (
    ModelBuilder,
    build_model,
    constant_properties,
    elastic_target_reason,
    resolution_for_level,
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
from skidmc.solver.plan import root_tolerance
from skidmc.solver.results import HeightResult, flag_unmet_rtol
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
                    melt_spread=None, target=None, max_level=None):
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
    max_level : float, optional
        The finest level the default search may refine its Richardson pair to (the pair's
        finer level; default: as far as it needs, up to
        :data:`skidmc.solver.plan.MAX_ADAPTIVE_LEVEL`). Where the pair would have to move above
        it, the search ends with the last pair's value and its estimate, above ``rtol`` and
        flagged ``"rtol_unmet"``: speed bought with accuracy, stated per height
        (docs/performance.md, "A cap on refinement"). At least the first pair's fine level of
        ``rtol``; only for the default search.

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
    # The scene's inference, made once where the options choose the target (with the default
    # runaway rule, the one whose terms decide it; the target left to each model): that choice
    # and every model the search builds take it (ModelBuilder).
    builders = []

    def terms_of():
        builders.append(ModelBuilder(scene, melting=melting, target=None, rtol=rtol))
        return builders[-1].terms

    opts = resolve_options(scene, rtol, h_min=h_min, h_max=h_max, method=method, level=level,
                           extrapolate=extrapolate, melting=melting,
                           runaway_fraction=runaway_fraction, model=model,
                           melt_width=melt_width, melt_spread=melt_spread, target=target,
                           terms_of=terms_of if runaway_fraction is None else None)
    builder = builders[0] if builders else None
    if max_level is not None:
        if isinstance(max_level, bool) or not isinstance(max_level, numbers.Real):
            raise SceneError("max_level", max_level, "must be a number (a refinement level)")
        if not opts.adaptive:
            raise SceneError("max_level", max_level, "caps the default search's refinement: "
                             "not with a forced level, a given model or extrapolate=False")
        if not max_level >= opts.level:
            raise SceneError("max_level", max_level, f"below the first pair's fine level "
                             f"{opts.level:g} at rtol = {rtol:g}")
    if opts.adaptive:
        # The root finder gets the room the pair is likely not to use; the a posteriori
        # estimate, not the calibrated model, then decides whether it fits (_adaptive_pair).
        return _adaptive_pair(scene, opts, h_guess, start, builder,
                              math.inf if max_level is None else float(max_level))
    x_tol = root_tolerance(rtol, opts.level, opts.extrapolate, opts.melt_width)
    if not opts.extrapolate:
        return _search(scene, opts, opts.level, x_tol, model=model, h_guess=h_guess,
                       start=start, builder=builder)
    # Richardson: R = H_L + (H_L - H_{L-1}) / 3. Root-finder errors d_L, d_{L-1} enter R as
    # (4 d_L + d_{L-1}) / 3: the cheap coarse search gets the whole root-finder tolerance and
    # the fine one half of it, (4 / 2 + 1) / 3 = 1 tolerance in all.
    return _drive(scene, opts, adaptive.PLAN_PAIR, opts.level, x_tol, 0.5 * x_tol, h_guess,
                  start, builder=builder)


critical_height.__doc__ = _critical_height.__doc__.replace(
    "    Returns\n",
    "    A failure of the solver on a valid scene raises :class:`SceneUnsolvable` (a\n"
    "    :class:`SolverError` naming the inputs outside their plausible range). A result whose\n"
    "    ``error_estimate`` stayed above ``rtol`` (the search refined as far as it goes) carries\n"
    "    the flag ``\"rtol_unmet\"`` (:data:`skidmc.solver.results.RTOL_UNMET`); its\n"
    "    ``error_estimate`` is the one reached.\n\n"
    "    Returns\n", 1)
critical_height.__wrapped__ = _critical_height  # inspect.signature: the full signature


_REGIME_CODES = {"steady": REGIME_STEADY, "fading": REGIME_FADING,
                 "stops_sliding": REGIME_STOPS_SLIDING}


def _adaptive_pair(scene, opts, h_guess, start, builder=None, max_level=math.inf):
    """The default search: a Richardson pair whose own estimate is brought within ``rtol``.

    The search is the compiled machine of :mod:`skidmc.solver.adaptive` (the one the device
    search drives too): the first pair ``(level - 1, level)`` with the root tolerances
    :func:`skidmc.solver.controller.first_root_tolerances`, its estimate measured (the a
    posteriori error of the correction, the melting width's bias, and the root errors the
    tolerances allow), then the rounds of :func:`skidmc.solver.controller.next_round` (tighten
    the roots from their own simulations, search the pair again with a narrower melting width,
    or move the pair up a level) until the estimate meets rtol or nothing left can help: then
    the estimate stays above rtol and says so.
    """
    coarse_tol, fine_tol = first_root_tolerances(opts.rtol, opts.level, opts.melt_width,
                                                 opts.melt_spread, opts.exact, opts.signs)
    return _drive(scene, opts, adaptive.PLAN_ADAPTIVE, opts.level, coarse_tol, fine_tol,
                  h_guess, start, builder=builder, max_level=max_level)


def _search(scene, opts, level, x_tol, *, model=None, h_guess=None, start=None, builder=None):
    """One critical-height search at one resolution level, the root to ``x_tol`` [1, in ln H]
    (the fixed plan of a forced level or model without extrapolation; see
    :func:`critical_height`), with the calibrated estimate of its level.

    With no guess, the search starts from the root found at ``level - COARSE_GAP`` (levels >=
    COARSE_GAP) or from the fast tier's height; with a given ``model`` from neither. The
    machine of :mod:`skidmc.solver.adaptive` chooses the root finder, as in every search.
    """
    return _drive(scene, opts, adaptive.PLAN_SINGLE, level, math.nan, x_tol, h_guess,
                  time.perf_counter() if start is None else start, model=model,
                  builder=builder)


def _drive(scene, opts, plan, level, coarse_tol, fine_tol, h_guess, start, model=None,
           builder=None, max_level=math.inf):
    """Run the machine of :mod:`skidmc.solver.adaptive` on one scene with ``plan``
    (``PLAN_*``), answering each run it asks for [HeightResult].

    Each run is :func:`skidmc.solver.simulate.simulate` on the model of its level and melting
    width (or on ``model`` where one was given), the runs of one search sharing a
    :class:`LinearPrefix`; the models come from one :class:`ModelBuilder` of the scene
    (``builder``, one made with the default runaway rule and the target left open, or made
    here). ``level`` is the (first) pair's fine level or the single search's; ``coarse_tol``,
    ``fine_tol`` [1] the root tolerances of the pair's searches (the single search's in
    ``fine_tol``); ``max_level``: the default search's cap on its pair's level (the last pair's
    outcome where it would refine beyond it).
    """
    rtol = opts.rtol
    own_model = model is None
    if own_model and builder is None:
        builder = ModelBuilder(scene, melting=opts.melting, target=opts.target, rtol=rtol,
                               **opts.model_kwargs())
    models = {}

    def build(level, width=None, meshes=True):
        # build_model(scene, level=, melt_width=, meshes=, melting=, melt_spread=, target=,
        # rtol=, runaway_fraction=) of the search's options, from its one inference
        return builder.model(resolution_for_level(level, width, opts.melt_spread),
                             meshes=meshes, target=opts.target)

    def model_of(level, width):
        if not own_model:
            return model
        key = (level, width)
        if key not in models:
            models[key] = build(level, width)
        return models[key]

    measure_bias = False
    if plan == adaptive.PLAN_ADAPTIVE:
        probe = build(level - 1.0, meshes=False)
    else:
        # A fixed plan states the terms and flags of the level it returns.
        probe = model_of(level, opts.melt_width)
    melting_term = "melting" in probe.terms
    if plan == adaptive.PLAN_ADAPTIVE:
        # The melting width's bias is measured where the calibrated bound does not apply:
        # scenes that ignite below the melting point (the bound was measured on scenes igniting
        # above it: the presets, ~47 K above; a level-0 shift overstates the bias there, 3.5x
        # on paper-quartz; below it the runaway starts where the smoothed step releases its
        # latent heat, and the bias is the scene's own, 15x the bound at E/R = 15,000 K with a
        # fast prefactor). The ignition temperature depends on the kinetics and the exit time
        # only: the probe's.
        measure_bias = melting_term and probe.ignition_temperature < scene.he_melting_point
    if own_model:
        regime = _REGIME_CODES[opts.regime if opts.regime is not None else exit_regime(scene)]
        fast = None if h_guess is not None else _fast_guess(scene, opts.h_min, opts.h_max,
                                                            opts.melting, builder)
    else:
        # One model answers every run: how its heating ends, no coarse start, no fast tier.
        regime = (REGIME_STOPS_SLIDING if model.exit_kind == "stops_sliding" else
                  REGIME_STEADY)
        fast = None
    ps, res, pts, st, fpts = adaptive.new_storage()
    code, x = adaptive.pair_start(
        ps, res, pts, st, fpts, rtol, opts.h_min, opts.h_max, level,
        opts.melt_width if own_model else model.resolution.melt_width, coarse_tol, fine_tol,
        opts.melt_spread, opts.exact, opts.signs, regime, melting_term, measure_bias, True,
        max_level, "no_friction" in probe.flags, math.nan if fast is None else fast,
        math.nan if h_guess is None else float(h_guess),
        math.log(probe.end_time / probe.exit_time), opts.method == "bisection", plan,
        own_model)
    prefix, serial = None, -1
    while code == ASK_RUN:
        ask_level, width, until_exit, alone, ask_serial = adaptive.asked(ps)
        run_model = model_of(ask_level, width)
        if not alone and ask_serial != serial:
            prefix, serial = LinearPrefix(run_model), ask_serial   # a new search
        sim = simulate(run_model, math.exp(x), until_exit=until_exit,
                       prefix=None if alone else prefix)
        code, x = adaptive.pair_step(ps, res, pts, st, fpts, sim.margin, sim.event)
    if code == HAND_BACK and int(ps[0]["reason"]) == BACK_LEVEL:
        # The caller's cap on the level (max_level): the last pair's outcome.
        code, x = adaptive.finish_at_level_cap(ps, res)
    if code != FINISHED:   # pragma: no cover - a CPU run raises instead of failing quietly
        raise SolverError(f"the search ended without a root (reason {int(ps[0]['reason'])})")
    (height, censor, estimate, level, extrapolated, correction, melt_bias,
     evaluations) = adaptive.outcome(ps)
    # The fine search's history, flags and model (its own height's flags).
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


def _fast_guess(scene, h_min, h_max, melting, builder=None):
    """The fast tier's critical height [m] as a first guess, or None (censored, refused or
    failed).

    :func:`skidmc.solver.fast.fast_critical_height`'s height without its model and result: the
    scene's terms and flags are the search's ``builder``'s (a :class:`ModelBuilder`; made here
    when not given): the tier's stated error reads the flags self_heating and stops_sliding,
    which neither the level, the rtol nor the runaway rule changes, and the tier refuses a
    stack whose heat reaches below its top layer.
    """
    from skidmc.solver.fast import SCENE_FIELDS, _scene_values, fast_error_bound, fast_height

    if builder is None:
        builder = ModelBuilder(scene, melting=melting)

    if "layered_target" in builder.terms:
        return None
    values = _scene_values(scene)
    if scene.target_table:
        # The fast tier's target has constant properties: for a guess, those of the table at
        # the middle of the interface's rise (docs/targets.md), with the default runaway rule
        # (constant_property_scene's values, without making the scene).
        t_run = (builder.runaway_temperature
                 if builder.runaway_fraction == DEFAULT_RUNAWAY_FRACTION else
                 build_model(scene, meshes=False, melting=melting).runaway_temperature)
        low, high = target_temperature_range(scene.initial_temperature, t_run)
        values = list(values)
        (values[SCENE_FIELDS.index("target_conductivity")],
         values[SCENE_FIELDS.index("target_heat_capacity")]) = constant_properties(
            scene, 0.5 * (low + high))
    try:
        h, censored, _, _ = fast_height(values, fast_error_bound(builder.flags), h_min, h_max,
                                        melting=melting)
    except Exception:  # noqa: BLE001 - only a guess: the full search does not need it
        return None
    return h if censored is None and math.isfinite(h) else None
