"""Accuracy plan and calibrated error model of the critical-height search.

The tolerance ``rtol`` on the critical height is shared three ways: the mesh and time steps
(a refinement level, or a Richardson pair of levels), the smoothing of HMX's melting step (its
width) and the root finder on ln H. The discretisation error model is calibrated by the
refinement study (``python scripts/refinement_study.py``, ``results/validation/refinement.md``).
"""

from __future__ import annotations

import math

from numba import njit

from skidmc.errors import SceneError
from skidmc.solver.model import MELT_WIDTH_BIAS_PER_K, melt_width_floor

__all__ = [
    "DISCRETISATION_SHARE",
    "ERROR_LEVEL0",
    "EXACT_FINE_SHIFT",
    "EXACT_FINE_SHIFT_SPREAD",
    "EXACT_LIKELY_CORRECTION",
    "EXACT_LIKELY_CORRECTION_SIGNS",
    "EXACT_RESIDUAL_RATIO",
    "EXACT_SIGN_FLOOR",
    "EXACT_SIGN_RESIDUAL_RATIO",
    "EXACT_STEADY_FINE_OVERSHOOT",
    "exact_first_pair_level",
    "JUMP_COARSE_SHARE",
    "LIKELY_CORRECTION_FRACTION",
    "MAX_ADAPTIVE_LEVEL",
    "MAX_ROOT_TOLERANCE",
    "MAX_MELT_WIDTH",
    "MELT_SHARE",
    "RICHARDSON_ERROR_LEVEL0",
    "RICHARDSON_MIN_LEVEL",
    "RICHARDSON_RESIDUAL_RATIO",
    "RICHARDSON_RESIDUAL_RATIO_LEVEL0",
    "RICHARDSON_RESIDUAL_RATIO_SPREAD",
    "ROOT_SHARE",
    "SPREAD_FINE_LEVEL",
    "TIGHTEN_FRACTION",
    "a_posteriori_error",
    "extrapolated_error",
    "first_pair_level",
    "jump_root_tolerances",
    "level_for_rtol",
    "melt_bias",
    "melt_bias_bound",
    "melt_width_for_rtol",
    "modelled_error",
    "pair_root_tolerance",
    "plan_for_rtol",
    "predicted_correction",
    "predicted_pair_error",
    "root_tolerance",
]

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

#: Richardson extrapolation (second order) of the searches at levels L - 1 and L. The
#: refinement study measures its residual error, over all report presets, the second
#: series' extreme mu and the three melting widths, as 5.6e-4, 3.2e-4, 8.4e-5, 5.2e-5 at
#: L = 1, 1.5, 2, 2.5 (6.7e-4 at L = 1 in a repeat whose searches took other paths: level 0's
#: margin carries ~1e-4 of step-size noise). RICHARDSON_ERROR_LEVEL0 * 4**-L bounds every
#: observed value from L = 1 (RICHARDSON_MIN_LEVEL) up, with 16 % to spare at L = 1.
RICHARDSON_ERROR_LEVEL0 = 3.2e-3

RICHARDSON_MIN_LEVEL = 1.0

#: A posteriori error of a Richardson value R = H_L + c H_L, c = (H_L - H_{L-1}) / (3 H_L),
#: measured per scene: the residual |R / H_ref - 1| is at most this multiple of the pair's own
#: correction |c|. Measured against tight solves (levels 3 and 4) on the report presets and 22
#: off-preset scenes (quartz, alumina, steel and an in-between target; mu 0.04-0.3; pendulum and
#: vertical; E/R 15,000-34,000 K, one of them self-heating), tight root tolerance, melting
#: widths 1-2 K: at most 0.37 |c| for the pairs (0.5, 1.5) and (1, 2), typically 0.01-0.3.
#: 0.5 leaves 35 % to spare. ``benchmarks/solver.py`` reports, per rtol, the share of results
#: whose whole estimate bounds their error; ``tests/test_error_estimate.py`` checks it.
RICHARDSON_RESIDUAL_RATIO = 0.5
#: The same for a pair whose coarse level is 0: level 0 is not always in the asymptotic range
#: (on two of the 27 scenes its error is not 2-4x that of level 1: the residual of the (0, 1)
#: value was 1.2 |c| and 1.5 |c|; otherwise <= 0.31 |c|). 0.75 bounds 25 of 27 scenes alone; the
#: width's bias bound and the root tolerance, added to it in the reported estimate, cover the
#: other two (tests/test_error_estimate.py checks the total).
RICHARDSON_RESIDUAL_RATIO_LEVEL0 = 0.75
#: With the melting spread over each HE cell (:data:`skidmc.physics.thermal.MELT_SPREAD`, the
#: default search's), the levels' errors fall faster than 4x per level from about level 1.5
#: on, while the spread fades out of the cells (observed order 2.0-3.0 from L = 1 to 3, the
#: higher the narrower the width), and a
#: second-order extrapolation overshoots: by |4 - 2^p| / (2^p - 1) of its correction for a
#: pure order p per level (0.57 at p = 3), by at most the whole correction for any p >= 1.32
#: with errors of one sign. The refinement study at the fixed widths the search uses
#: (``scripts/refinement_study.py --melt-width W --melt-spread 1``, W = 0.35, 1, 2, 3, 4 K;
#: results/validation/refinement_wW_s1.md, "a posteriori ratio") measures the residual at most
#: 0.40 |c| for the pairs (0.5, 1.5) and (1, 2) and 0.56 |c| for (0, 1) (within the ratios
#: above), but up to 0.62 |c| for (1.5, 2.5) and 0.74 |c| for the finer pairs at W = 0.35 K,
#: rising as W narrows. So a spread pair whose coarse level is at least SPREAD_FINE_LEVEL is
#: estimated at RICHARDSON_RESIDUAL_RATIO_SPREAD = 1, the bound that does not depend on the
#: order.
SPREAD_FINE_LEVEL = 1.5
RICHARDSON_RESIDUAL_RATIO_SPREAD = 1.0
#: The exact target (``build_model(..., target="exact")``: the target as the exact semi-infinite
#: solid, only the HE meshed; the default search's since issue 16's last pass). Its levels' errors
#: are 2x (steady rebounds) to 4-5x (sign-located scenes: sliding stops, or the heating fades
#: before rebound) smaller than the meshed target's (results/benchmarks/exact_target.md), and on
#: the sign-located scenes they converge faster than second order and change sign, so a pair's
#: correction can be small by cancellation. Calibrated by ``python
#: scripts/a_posteriori_calibration.py --target exact`` (results/validation/a_posteriori_exact.md:
#: 41 scenes apart from the error-honesty test's, x melting widths 1, 3 and 4 K, spread 1, tight
#: roots, against the Richardson value of levels 3 and 4 at the same width):
#:
#: * steady rebounds: the residual |R / H - 1| is at most 0.48, 0.53, 0.58 |c| for the pairs
#:   (0, 1), (0.5, 1.5), (1, 2) and 0.88 |c| for (1.5, 2.5): EXACT_RESIDUAL_RATIO (0.75, 23 % to
#:   spare) below coarse level :data:`SPREAD_FINE_LEVEL`, and from there
#:   :data:`RICHARDSON_RESIDUAL_RATIO_SPREAD` (1, the bound for any order >= 1.32 with errors of
#:   one sign);
#: * sign-located scenes: up to 1.38 and 1.99 |c| for (0, 1) and (0.5, 1.5), and 23 |c| or more for
#:   the finer pairs, whose corrections (median 4.8e-5 and 1.8e-5) cancel. The estimate is
#:   max(EXACT_SIGN_RESIDUAL_RATIO |c|, EXACT_SIGN_FLOOR 3^-(L - 1)) for the fine level L: 2 |c|
#:   bounds the residual of any order >= 1 with errors of one sign (|4 - 2^p| / (2^p - 1) <= 2),
#:   and the floor, measured, where the correction cancels (worst residuals 6.6e-4, 2.7e-4,
#:   1.2e-4, 6.9e-5 at L = 1 ... 2.5: it bounds them all with the 2 |c| term, with 1 % to spare at
#:   (0.5, 1.5), the pair rtol 1e-3 uses; per level it falls 3x, slower than the measured 4-5x
#:   at the coarse pairs, because its finer pairs are not measured independently of the
#:   reference).
EXACT_RESIDUAL_RATIO = 0.75
EXACT_SIGN_RESIDUAL_RATIO = 2.0
EXACT_SIGN_FLOOR = 4.0e-4
#: Likely |c| of the exact target's pair (0, 1) [1], falling 4x per level: the first root
#: tolerances' prediction (:func:`predicted_correction`). Measured medians: steady 8.9e-4, 5.9e-4,
#: 2.5e-4, 1.4e-4 for the pairs (0, 1) ... (1.5, 2.5); sign-located 3.5e-4, 1.4e-4. The steady
#: value is set above its median, where the default rtol 1e-3 costs least: in kernel-cost units
#: (simulations weighted by their level's cost) the steady benchmark scenes' median search took
#: 5.0 with 1.6e-3 and 6.9 with 1.0e-3, whose looser first roots then had to be tightened; but
#: 4.8 against 3.0 at rtol 3e-3 and 28 against 18 at 3e-4 (pair (2, 3) against (1.5, 2.5)):
#: :func:`pair_root_tolerance`'s step from the room to ROOT_SHARE rtol makes the best value
#: depend on rtol. 3.5e-4 for the sign-located scenes: 5e-4 cost the same, 7e-4 more.
EXACT_LIKELY_CORRECTION = 1.6e-3
EXACT_LIKELY_CORRECTION_SIGNS = 3.5e-4
#: Where the exact target's fine root lies above its coarse root on a sign-located scene, and the
#: spread of that, as fractions of the coarse level's modelled error :func:`modelled_error`:
#: measured 0.119 (sd 0.036), 0.099 (0.024), 0.066 (0.032) for the pairs (0, 1), (0.5, 1.5),
#: (1, 2) (the meshed target's: 0.375, :data:`skidmc.solver.search.FINE_SHIFT_SPREAD`). A root
#: farther out costs doubling steps, never a wrong root.
EXACT_FINE_SHIFT = 0.1
EXACT_FINE_SHIFT_SPREAD = 0.04
#: Where the exact target's fine search of a steady rebound first simulates, above the coarse root,
#: as a fraction of :func:`modelled_error` of the coarse level: the go-side search wants its first
#: point just above the root. The fine root lies 0.30, 0.39, 0.34 of it up (median; 90th
#: percentile 0.40, 0.45, 0.39) for the pairs (0, 1), (0.5, 1.5), (1, 2); the meshed target's
#: first point is 0.75 up.
EXACT_STEADY_FINE_OVERSHOOT = 0.45

#: Fraction of the calibrated worst-case correction (:func:`predicted_correction`) expected of
#: a pair when its root tolerance is first chosen (:func:`pair_root_tolerance`). On the 23
#: scenes of benchmarks/solver.py the pair (0, 1) measured |c| = 0.6-2.3e-3 (median ~0.5 of
#: the worst case 2.25e-3): 0.75 lets about one scene in six need its roots tightened
#: afterwards (one or two more fine simulations) instead of every scene paying for a tight
#: root finder.
LIKELY_CORRECTION_FRACTION = 0.75
#: Fraction of the room a pair's estimate leaves that its tightened roots aim at [1]. A
#: tightened root moves within its old tolerance, and the pair's correction with it: aiming at
#: the whole room left the estimate converging on rtol from above over every adaptive round
#: (the extremes matrix's long-contact scene at rtol 3e-3, fixed step: 8 rounds, ending
#: 1.3e-11 above rtol).
TIGHTEN_FRACTION = 0.9
#: Coarse root tolerance of a pair whose margin jumps, as a multiple of the root room the pair
#: is likely to leave [1] (:func:`jump_root_tolerances`; the fine root gets (3 - it) / 4 of
#: the room, so that the root errors' share (4 d_f + d_c) / 3 is the room). Halvings at equal
#: cost would be fewest at d_c = 4 d_f (1.5); but a coarse halving costs about a third of a
#: fine one, and the fine root's prior (:data:`skidmc.solver.search.FINE_SHIFT_SPREAD`) is
#: widened by half the coarse tolerance. Measured in cell-steps summed over the 20 scenes of
#: seeds 16 and 17 of ``skidmc.scene.validation`` whose margin is likely to jump: 1.0 cost
#: 14 % less than 1.5 at rtol 1e-3 and 3e-3 (0.75 as much as 1.0 at 1e-3, 4 % more at 3e-3;
#: 0.5 and 1.25 more; equal at 1e-2, where MAX_ROOT_TOLERANCE caps both), and on a held-out
#: draw (seed 18, 14 such scenes) 13 % and 12 % less.
JUMP_COARSE_SHARE = 1.0
#: Widest root tolerance on ln H [1]: the root finders' acceptance rules assume brackets of at
#: most ~2 % (4 x_tol: linear interpolation across the no-go side's bend, whose slope changes
#: by ~30 % within 0.5 % of H_c, and :data:`skidmc.solver.roots.FOLD_SLOPE` and ``JUMP_SLOPE``,
#: which separate a steep or jumping margin from a smooth one in brackets up to ~3 %).
MAX_ROOT_TOLERANCE = 5e-3
#: Finest level the default search refines to when its a posteriori estimate exceeds rtol.
MAX_ADAPTIVE_LEVEL = 4.0


@njit(cache=True)
def melt_width_for_rtol(rtol, level=0.0):
    """Width of the smoothed melting step [K] for tolerance ``rtol`` at ``level``.

    The widest width whose bias, first order in the width and at most
    :data:`skidmc.solver.model.MELT_WIDTH_BIAS_PER_K` per kelvin, stays below MELT_SHARE * rtol;
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


@njit(cache=True)
def modelled_error(level):
    """Modelled relative discretisation error of the critical height at ``level`` [1]."""
    return ERROR_LEVEL0 * 4.0 ** (-level)


def _half_level_above(needed):
    """Smallest half-integer level >= ``needed`` (and >= 0)."""
    return max(0.0, math.ceil(2.0 * needed - 1e-9) / 2.0)


def level_for_rtol(rtol):
    """Lowest half-integer refinement level whose modelled error is below 0.6 rtol [1]."""
    if not rtol > 0.0:
        raise SceneError("rtol", rtol, "must be > 0")
    return _half_level_above(
        math.log(ERROR_LEVEL0 / (DISCRETISATION_SHARE * rtol)) / math.log(4.0))


@njit(cache=True)
def extrapolated_error(level):
    """Modelled relative error of the Richardson value of levels ``level - 1`` and ``level`` [1]."""
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

@njit(cache=True)
def exact_first_pair_level(rtol, signs):
    """:func:`first_pair_level` of the exact target [1] (``signs``: the root is located by
    signs), compiled: the default CPU search and the device search
    (:mod:`skidmc.solver.device`) plan their first pair with this one text."""
    level = RICHARDSON_MIN_LEVEL
    while level < MAX_ADAPTIVE_LEVEL:
        # The exact rule does not depend on the melting spread (1: the default's).
        predicted = predicted_pair_error(level, melt_width_for_rtol(rtol, level), 1.0,
                                         True, signs)
        if predicted <= (1.0 - ROOT_SHARE) * rtol:
            break
        level += 0.5
    return level


def first_pair_level(rtol, exact=False, signs=False):
    """Fine level of the first Richardson pair ``(L - 1, L)`` the default search tries [1].

    The calibrated model's plan (:func:`plan_for_rtol`), at least :data:`RICHARDSON_MIN_LEVEL`:
    every default result is a Richardson value, so that its error is estimated from its own
    pair (:func:`a_posteriori_error`). A plain-level plan ``L`` becomes the pair whose fine
    level is ``L`` rounded up to a whole level.

    The exact target (``exact``; ``signs``: the root is located by signs): the lowest
    half-integer level from RICHARDSON_MIN_LEVEL whose :func:`predicted_pair_error` (the
    predicted estimate and the melting width's bias) leaves the root finder at least ROOT_SHARE
    rtol; at most :data:`MAX_ADAPTIVE_LEVEL`. rtol 1e-2, 3e-3 -> 1; 1e-3 -> 1.5; 3e-4 -> 3
    (steady) or 2.5 (signs).
    """
    if exact:
        return exact_first_pair_level(rtol, signs)
    level, extrapolate = plan_for_rtol(rtol)
    if not extrapolate:
        level = math.ceil(level - 1e-9)
    return max(RICHARDSON_MIN_LEVEL, float(level))


@njit(cache=True)
def a_posteriori_error(correction, coarse_level, melt_spread, exact=False, signs=False):
    """Estimated discretisation error of a Richardson value [1], from its own pair.

    Parameters
    ----------
    correction : float
        (H_L - H_{L-1}) / (3 R) of the pair, R the extrapolated height [1].
    coarse_level : float
        L - 1.
    melt_spread : float
        The pair's melting spread over each HE cell [1] (0: the fixed step).
    exact : bool
        The pair's target is the exact semi-infinite solid (``target="exact"``).
    signs : bool
        The scene's root is located by signs (sliding stops, or the heating fades before
        rebound); only with ``exact``.

    Returns
    -------
    float
        Meshed target: :data:`RICHARDSON_RESIDUAL_RATIO` |correction|;
        :data:`RICHARDSON_RESIDUAL_RATIO_LEVEL0` |correction| when ``coarse_level`` is 0;
        :data:`RICHARDSON_RESIDUAL_RATIO_SPREAD` |correction| when a spread pair's coarse level
        is at least :data:`SPREAD_FINE_LEVEL`. Exact target: :data:`EXACT_RESIDUAL_RATIO`
        |correction| (RICHARDSON_RESIDUAL_RATIO_SPREAD from SPREAD_FINE_LEVEL); where ``signs``,
        the larger of :data:`EXACT_SIGN_RESIDUAL_RATIO` |correction| and
        :data:`EXACT_SIGN_FLOOR` 3^-(L - 1).
    """
    if exact:
        if signs:
            return max(EXACT_SIGN_RESIDUAL_RATIO * abs(correction),
                       EXACT_SIGN_FLOOR * 3.0 ** (-coarse_level))
        if coarse_level >= SPREAD_FINE_LEVEL:
            return RICHARDSON_RESIDUAL_RATIO_SPREAD * abs(correction)
        return EXACT_RESIDUAL_RATIO * abs(correction)
    if melt_spread > 0.0 and coarse_level >= SPREAD_FINE_LEVEL:
        return RICHARDSON_RESIDUAL_RATIO_SPREAD * abs(correction)
    if coarse_level < 0.5:
        return RICHARDSON_RESIDUAL_RATIO_LEVEL0 * abs(correction)
    return RICHARDSON_RESIDUAL_RATIO * abs(correction)


def melt_bias_bound(terms, melt_width):
    """Bound on the relative bias of a smoothed melting step of width ``melt_width`` [1].

    :data:`skidmc.solver.model.MELT_WIDTH_BIAS_PER_K` * w when the scene melts, else 0. Unlike
    :func:`melt_bias`, it is not dropped at the level's floor width: a Richardson pair keeps
    one width at both levels, so its difference does not see the width's bias.
    """
    return MELT_WIDTH_BIAS_PER_K * melt_width if "melting" in terms else 0.0


def melt_bias(terms, melt_width, level):
    """Bound on the relative bias of the smoothed melting step [1].

    0 without melting, and at the level's floor width, where the bias is part of the
    level's modelled error (:data:`skidmc.solver.model.MELT_WIDTH_LEVEL0`).
    """
    if "melting" not in terms or melt_width <= melt_width_floor(level) * (1.0 + 1e-9):
        return 0.0
    return MELT_WIDTH_BIAS_PER_K * melt_width


@njit(cache=True)
def predicted_correction(level, exact=False, signs=False):
    """Likely size of the Richardson correction |c| of the pair ``(level - 1, level)`` [1].

    With the levels' errors e_L ~ :data:`ERROR_LEVEL0` 4^-L (a worst case over the refinement
    study), c = (H_L - H_{L-1}) / (3 R) ~ (e_{L-1} - e_L) / 3 = 0.25 ERROR_LEVEL0 4^-(L-1)
    (2.25e-3 for the pair (0, 1)); :data:`LIKELY_CORRECTION_FRACTION` of that. The exact target
    (``exact``): :data:`EXACT_LIKELY_CORRECTION` 4^-(L-1), or
    :data:`EXACT_LIKELY_CORRECTION_SIGNS` 4^-(L-1) where the root is located by ``signs``.
    """
    if exact:
        return ((EXACT_LIKELY_CORRECTION_SIGNS if signs else EXACT_LIKELY_CORRECTION)
                * 4.0 ** (-(level - 1.0)))
    return LIKELY_CORRECTION_FRACTION * 0.25 * ERROR_LEVEL0 * 4.0 ** (-(level - 1.0))


@njit(cache=True)
def predicted_pair_error(level, melt_width, melt_spread, exact=False, signs=False):
    """Likely estimate of the pair ``(level - 1, level)`` before it is searched [1]: its
    :func:`a_posteriori_error` of :func:`predicted_correction` plus the melting width's bias
    bound. ``exact``, ``signs``: as for :func:`a_posteriori_error`."""
    return (a_posteriori_error(predicted_correction(level, exact, signs), level - 1.0,
                               melt_spread, exact, signs)
            + MELT_WIDTH_BIAS_PER_K * melt_width)


@njit(cache=True)
def pair_root_tolerance(rtol, level, melt_width, melt_spread, exact=False, signs=False):
    """First tolerance of the root finder on ln H [1] for a default search's pair at ``level``.

    What ``rtol`` leaves after the pair's a posteriori estimate predicted from the calibrated
    model (:func:`a_posteriori_error` of :func:`predicted_correction`) and the melting width's
    bias bound: the room the pair is likely not to use (at most :data:`MAX_ROOT_TOLERANCE`,
    unless ROOT_SHARE rtol is more).
    Where that is under twice :data:`ROOT_SHARE` rtol, ROOT_SHARE rtol: measured side by side
    (``benchmarks/solver.py --compare``), a first tolerance 1.9x looser at rtol 3e-3 and 1e-3
    cost 7-9 % more time, because the roots then had to be tightened on more scenes than it
    saved simulations on the others. This is only a first choice: the reported estimate adds
    the root errors the tolerances actually used allow to the pair's measured error, and the
    search tightens the roots (or refines the pair) while that exceeds rtol. With w from
    :func:`melt_width_for_rtol`: rtol 1e-2 -> 5e-3 (pair (0, 1), w = 4 K), 3e-3 -> 6e-4 and
    1e-3 -> 2e-4 (the first pass of issue 16 fixed 0.2 rtol everywhere). ``exact``, ``signs``:
    as for :func:`a_posteriori_error`.
    """
    room = rtol - predicted_pair_error(level, melt_width, melt_spread, exact, signs)
    if room < 2.0 * ROOT_SHARE * rtol:
        return ROOT_SHARE * rtol
    return max(ROOT_SHARE * rtol, min(MAX_ROOT_TOLERANCE, room))


@njit(cache=True)
def jump_root_tolerances(rtol, level, melt_width, melt_spread, exact=False):
    """First root tolerances on ln H [1] ``(coarse, fine)`` of a pair whose margin jumps.

    Where sliding stops before rebound, each halving of a root's bracket costs one simulation
    (:func:`skidmc.solver.roots.prior_bisection_root`), and tightening a root later continues
    the same bisection from its bracket at no extra cost. So the first tolerances take all the
    room the pair is likely to leave (as :func:`pair_root_tolerance`, but never held back to
    ROOT_SHARE rtol). The root errors enter the Richardson value as (4 d_fine + d_coarse) / 3,
    and the split is :data:`JUMP_COARSE_SHARE` of the room to the coarse root, the rest to the
    fine one. Each at most :data:`MAX_ROOT_TOLERANCE`. rtol 1e-3 (pair (0.5, 1.5), w = 1 K) ->
    (3.8e-4, 1.9e-4) instead of (2e-4, 1e-4). ``exact``: the exact target's pair, estimated as
    located by signs (:func:`a_posteriori_error`).
    """
    room = max(ROOT_SHARE * rtol,
               rtol - predicted_pair_error(level, melt_width, melt_spread, exact, exact))
    coarse = min(MAX_ROOT_TOLERANCE, JUMP_COARSE_SHARE * room)
    fine = min(MAX_ROOT_TOLERANCE, (3.0 * room - coarse) / 4.0)
    return coarse, fine
