"""The search, compiled once, as a state machine that its caller drives with simulations.

The default search of :func:`skidmc.critical_height` is a Richardson pair of levels brought
within ``rtol`` by rounds. Which searches it runs, in what order, from which guesses, with which
root finder, when it measures the melting width's bias and what each round does: all of it is
here, one compiled text, in the form the root finders of :mod:`skidmc.solver.finders` have
("reverse communication"). The fixed plans (a forced level or model, ``extrapolate=False``) run
here too (:data:`PLAN_PAIR`, :data:`PLAN_SINGLE`): the same searches, without the rounds, with
the calibrated estimate. The machine never runs a simulation. It asks its caller for one
(:data:`ASK`: ln H, the level, the melting width, whether the run may stop at the exit, and
whether it belongs to the current search's linear prefix), the caller runs it however it
models the scene and hands back the margin ln(t_ev / t_exit) and whether the event came by the
exit, until the machine is done (:data:`FINISHED`) or, on the device, hands the scene back
(:data:`HAND_BACK`, the reason in ``reason``).

Two callers drive it: the CPU search (:func:`skidmc.solver.search._drive`, with
:func:`skidmc.solver.simulate.simulate` on any model: tabled, layered, meshed targets) and the
device search (:func:`skidmc.solver.device.critical_height_core`, with the compiled run of a
constant-property exact target on a CPU or GPU thread's storage). The decisions inside are the
compiled functions of :mod:`skidmc.solver.controller` (each round), :mod:`skidmc.solver.plan`
and :mod:`skidmc.solver.finders` (each root).

The state is one record (:data:`PAIR_STATE`) and arrays the caller owns (:func:`new_storage`):
the two searches' results (``res``, rows coarse and fine, the ``R_*`` layout) and points
(``pts``: ln H as the CPU search's cache keys it, the margin, and whether the run stopped at the
exit), and the root finder's state and go points. Nothing allocates, raises or touches Python
objects, so a GPU thread runs it in its local memory.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from skidmc.physics.fast import CENSOR_ABOVE, CENSOR_BELOW, CENSOR_NONE
from skidmc.solver.controller import (
    DONE,
    MAX_ADAPTIVE_ROUNDS,
    NARROW,
    REFINE,
    TIGHTEN_BOTH,
    TIGHTEN_FINE,
    next_round,
    pair_estimate,
    richardson_value,
)
from skidmc.solver.finders import (
    ASK,
    BAD_PROBABILITY,
    CENSORED_ABOVE,
    CENSORED_BELOW,
    FAST_GUESS_ERROR,
    FINDER_STATE,
    FOLD_SLOPE,
    GIVE_UP,
    GO_SIDE_MAX_SIMULATIONS,
    GUIDED_MAX_SIMULATIONS,
    JUMP_SLOPE,
    ROOT,
    bisection_start,
    brent_bracket_start,
    brent_start,
    finder_point,
    finder_reset,
    finder_step,
    go_side_start,
    history_slopes,
    prior_bisection_start,
)
from skidmc.solver.model import MELT_WIDTH_BIAS_PER_K, melt_width_floor
from skidmc.solver.plan import (
    EXACT_FINE_SHIFT,
    EXACT_FINE_SHIFT_SPREAD,
    EXACT_STEADY_FINE_OVERSHOOT,
    extrapolated_error,
    modelled_error,
)

__all__ = [
    "COARSE_GAP",
    "FADING_FAST_SHIFT",
    "FADING_FAST_SPREAD",
    "FAST_STOPS_SLIDING_SPREAD",
    "FINE_SHIFT_SPREAD",
    "FINISHED",
    "HAND_BACK",
    "MELT_SHIFT_FACTOR",
    "PAIR_STATE",
    "PLAN_ADAPTIVE",
    "PLAN_PAIR",
    "PLAN_SINGLE",
    "POINTS_SHAPE",
    "REFINE_SPREAD",
    "REGIME_FADING",
    "REGIME_STEADY",
    "REGIME_STOPS_SLIDING",
    "RESULT_SIZE",
    "SEARCH_POINTS",
    "asked",
    "new_storage",
    "outcome",
    "pair_start",
    "pair_step",
]

#: The melting width's bias b(w) on the critical height [1] from the root's shift dx when the
#: width is doubled: b(w) = 1.3-1.9 dx on the report presets (concave, first order in w); 2.5
#: bounds it with 30 % to spare (the bias run, see :func:`_bias_run`).
MELT_SHIFT_FACTOR = 2.5

#: Scatter of the fast tier's ln H about the full model's where sliding stops [1], the prior's
#: spread of a stops-sliding search from the fast tier's height
#: (:func:`skidmc.solver.finders.prior_bisection_start`): sd 0.016 on the training scenes of
#: scripts/fast_tier_error.py after :data:`skidmc.physics.fast.STOPS_SLIDING_FACTOR`,
#: rounded up. A guess further off costs doubling steps, never a wrong root.
FAST_STOPS_SLIDING_SPREAD = 0.02

#: Spread of a refined pair's new fine root about the root the pair predicts for its level
#: (``value`` of :func:`skidmc.solver.controller.next_round`, REFINE), in units of
#: |c| + x_tol (c the pair's relative correction, x_tol the new search's root tolerance): the
#: prior of that search where the margin jumps (:func:`skidmc.solver.finders.
#: prior_bisection_start`), centred on the prediction. ``python scripts/refine_prior.py``
#: (135 refined searches of 452 stops-sliding scenes drawn from the shipped studies, seeds
#: 101-103, rtol 1e-3 and 3e-3): (ln H - ln value) / (|c| + x_tol) has mean -0.05, sd 0.18,
#: median -0.01, range -0.57..+0.35 (at 1e-3: mean -0.01, sd 0.14); rounded up to 0.2. The
#: prior it replaces (centred half the search's overshoot above the prediction, spread a sixth
#: of it: +0.35 and 0.12 in these units, set by analogy with the first pair's fine search,
#: whose root lies above its coarse one) put the roots at -3.3 of its spreads on average. A
#: root farther out costs doubling steps, never a wrong root.
REFINE_SPREAD = 0.2

#: Shift [1, in ln H] of the root's prior above the fast tier's height on rebound scenes whose
#: heating fades before the exit (sliding speed at rebound below
#: :data:`skidmc.solver.options.FADING_EXIT_SPEED` of the initial one), and the prior's spread:
#: there the fast tier's height is low. The level-0.5 root (melting width 1 K, spread 1)
#: measured against it on the rebound scenes of ``scripts/fast_tier_error.py``'s sets with an
#: exit speed ratio below 0.5: training set ln(H / H_fast) mean +0.038, sd 0.016 (25 scenes);
#: test set +0.044, sd 0.014 (34 scenes) (+0.032 to +0.052 on the fading scenes of
#: ``skidmc.scene.validation``); at ratios 0.5-0.6 +0.016 to +0.025, above 0.6 -0.013 to -0.001.
#: Fitted on the training set (mean rounded, spread rounded up as for
#: :data:`FAST_STOPS_SLIDING_SPREAD`). A guess further off costs doubling steps, never a wrong
#: root.
FADING_FAST_SHIFT = 0.04
FADING_FAST_SPREAD = 0.02

#: Spread of the fine root's prior in a Richardson pair whose margin jumps, as a fraction of the
#: coarse level's modelled error [1] (the meshed target's fine search; the coarse root's own
#: tolerance is added). The fine root lies 0.375 of that error above the coarse root on
#: average: measured with tight roots, melting width 1 K and spread 1, 0.27-0.44 (sd ~0.04) for
#: the pair (0.5, 1.5) and 0.31-0.48 for (0, 1) on the 20 scenes of seeds 16 and 17 of
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

#: How the heating ends (:func:`skidmc.solver.options.exit_regime`).
REGIME_STEADY, REGIME_FADING, REGIME_STOPS_SLIDING = 0, 1, 2

#: Points one search may hold (its simulations, and those of the search it tightens); a search
#: that needs more ends the machine with :data:`HAND_BACK`. The finders stop after 8 + 41 (go
#: side, then guided), 40 + 41 (prior bisection, then guided) or 60 + 100 (bracketing, then
#: Brent) simulations; study scenes use 2-10 per search.
SEARCH_POINTS = 128
#: Shape of one search's points: rows ln H, margin, 1 where the run stopped at the exit without
#: an event (to be run again in full where Brent's method needs it).
POINTS_SHAPE = (3, SEARCH_POINTS)
P_X, P_M, P_SIGN_ONLY = 0, 1, 2
#: Length of one search's result row: ln H of the root, censoring (``CENSOR_*``), height [m],
#: points held, simulations, 1 when it finished.
RESULT_SIZE = 8
R_X, R_CENSOR, R_HEIGHT, R_N, R_EVALUATIONS, R_OK = 0, 1, 2, 3, 6, 7

# What pair_start / pair_step return; inside, a search's end is returned as a code too
# (_SEARCH_DONE, _GAP_DONE) and taken up by _settle's loop: the stages never call each other
# in a cycle (numba compiles recursion poorly, CUDA not at all).
ASK_RUN, FINISHED, HAND_BACK = 0, 1, 2
_SEARCH_DONE, _GAP_DONE = 10, 11
# Why the machine handed its scene back (``reason``): a run or finder failed (or more points than
# SEARCH_POINTS), a narrower melting width was asked for (allow_narrow 0), a level above
# max_level. The device search maps these to its HANDBACK_* codes.
BACK_FAILED, BACK_NARROW, BACK_LEVEL = 1, 2, 3

#: Plans the machine runs (``plan`` of :func:`pair_start`): the default search (a pair and its
#: rounds, the a posteriori estimate); a fixed pair (``level - 1``, ``level``: one Richardson
#: value, no round, the calibrated estimate); one search at ``level`` (no extrapolation).
PLAN_ADAPTIVE, PLAN_PAIR, PLAN_SINGLE = 0, 1, 2

# Stages of the pair.
(_S_COARSE, _S_FINE, _S_BIAS, _S_TIGHTEN_C, _S_TIGHTEN_F, _S_NARROW_C, _S_NARROW_F,
 _S_NARROW_BIAS, _S_REFINE, _S_SINGLE) = range(10)
# Phases of one level's search: the coarse start two levels down, the search itself; and of one
# search: its guided finder, then bracketing and Brent's method.
_PH_GAP, _PH_MAIN = 0, 1
_ONE_FINDER, _ONE_BRENT = 0, 1

#: The machine's record. Inputs (set by :func:`pair_start`), the pair's plan and rounds, the
#: running search, the run asked for, and the outcome.
PAIR_STATE = np.dtype([
    # inputs
    ("rtol", np.float64), ("h_min", np.float64), ("h_max", np.float64), ("x_min", np.float64),
    ("x_max", np.float64), ("h_fast", np.float64), ("horizon", np.float64),
    ("melt_spread", np.float64), ("exact", np.int64), ("signs", np.int64),
    ("regime", np.int64), ("melting_term", np.int64), ("measure_bias", np.int64),
    ("allow_narrow", np.int64), ("max_level", np.float64), ("no_friction", np.int64),
    ("bisection", np.int64), ("plan", np.int64), ("own_model", np.int64),
    # the pair
    ("stage", np.int64), ("melt_width", np.float64), ("coarse_level", np.float64),
    ("fine_level", np.float64), ("coarse_tol", np.float64), ("fine_tol", np.float64),
    ("next_coarse_tol", np.float64), ("next_fine_tol", np.float64), ("value", np.float64),
    ("rounds", np.int64), ("narrowed", np.int64), ("evaluations", np.int64),
    ("before", np.int64), ("melt", np.float64), ("bias_x", np.float64), ("bias_m", np.float64),
    ("bias_slope", np.float64), ("extrapolated", np.int64), ("height", np.float64),
    ("relative", np.float64), ("estimate", np.float64), ("pair", np.float64),
    ("melt_bias", np.float64),
    # the running search: which row, its phase, its inputs
    ("cur", np.int64), ("phase", np.int64), ("one", np.int64), ("level", np.float64),
    ("level_tol", np.float64), ("l_guess", np.float64), ("l_overshoot", np.float64),
    ("l_slope", np.float64), ("l_go_slope", np.float64), ("l_sigma", np.float64),
    ("x_tol", np.float64), ("guess", np.float64), ("overshoot", np.float64),
    ("n_known", np.int64), ("n", np.int64), ("signs_only", np.int64), ("from_fast", np.int64),
    ("gap_evaluations", np.int64), ("serial", np.int64),
    # the run asked for
    ("ask_x", np.float64), ("ask_level", np.float64), ("ask_width", np.float64),
    ("ask_until_exit", np.int64), ("ask_alone", np.int64),
    # the outcome
    ("reason", np.int64), ("out_height", np.float64), ("out_censor", np.int64),
    ("out_error", np.float64), ("out_level", np.float64), ("out_extrapolated", np.int64),
])


def new_storage():
    """The arrays one machine runs on, for a CPU caller: (ps, res, pts, st, fpts)."""
    return (np.zeros(1, dtype=PAIR_STATE), np.zeros((2, RESULT_SIZE)),
            np.zeros((2,) + POINTS_SHAPE), np.zeros(1, dtype=FINDER_STATE),
            np.zeros((2, SEARCH_POINTS)))


@njit(cache=True)
def _or_default(value, default):
    """Python's ``value or default`` for an optional float (NaN: None)."""
    return default if value != value or value == 0.0 else value


@njit(cache=True)
def _find(pts, n, x):
    """Index of the point at exactly ``x`` among the first ``n`` of ``pts``, or -1."""
    for i in range(n):
        if pts[P_X, i] == x:
            return i
    return -1


@njit(cache=True)
def _slopes(pts, n, sorted_pts):
    """The slopes a finished search's points say (:func:`~skidmc.solver.finders.history_slopes`,
    NaN for none), on its history as the CPU search keeps it: (exp(x), m), sorted as Python
    sorts (H, m) tuples. ``sorted_pts`` (2 x >= n): scratch for that history."""
    for i in range(n):
        h, m = math.exp(pts[P_X, i]), pts[P_M, i]
        j = i - 1
        while j >= 0 and (sorted_pts[0, j] > h or (sorted_pts[0, j] == h and
                                                    sorted_pts[1, j] > m)):
            sorted_pts[0, j + 1] = sorted_pts[0, j]
            sorted_pts[1, j + 1] = sorted_pts[1, j]
            j -= 1
        sorted_pts[0, j + 1] = h
        sorted_pts[1, j + 1] = m
    return history_slopes(sorted_pts[0], sorted_pts[1], n)


# ------------------------------------------------------------------ one search at one level


@njit(cache=True)
def _search_begin(s, res, pts, st, fpts, cur, level, x_tol, guess, overshoot, slope, go_slope,
                  sigma, n_known):
    """Start a level's search into row ``cur``, its first ``n_known`` points known: without a
    guess (NaN), from the root two levels down where ``level`` >= :data:`COARSE_GAP` and the
    caller models the scene by level (``own_model``), else from the fast tier's height (NaN:
    none). Returns the machine's next (code, x)."""
    s.cur = cur
    s.level, s.level_tol = level, x_tol
    s.l_guess, s.l_overshoot, s.l_slope, s.l_go_slope, s.l_sigma = (guess, overshoot, slope,
                                                                    go_slope, sigma)
    s.gap_evaluations = 0
    row = res[cur]
    row[R_OK] = 0.0
    if s.no_friction == 1:
        # No frictional heat, no event: censored above without a simulation.
        row[R_X], row[R_CENSOR], row[R_HEIGHT] = s.x_max, CENSOR_ABOVE, s.h_max
        row[R_N], row[R_EVALUATIONS], row[R_OK] = 0.0, 0.0, 1.0
        return _SEARCH_DONE, math.nan
    if guess != guess and level >= COARSE_GAP and s.bisection == 0 and s.own_model == 1:
        s.phase = _PH_GAP
        gap = level - COARSE_GAP
        return _one_begin(s, res, pts, st, fpts, gap, max(x_tol, 0.2 * modelled_error(gap)),
                          math.nan, math.nan, math.nan, math.nan, math.nan, 0, True)
    s.phase = _PH_MAIN
    return _one_begin(s, res, pts, st, fpts, level, x_tol, guess, overshoot, slope, go_slope,
                      sigma, n_known, True)


@njit(cache=True)
def _one_begin(s, res, pts, st, fpts, level, x_tol, guess, overshoot, slope, go_slope, sigma,
               n_known, use_fast):
    """One search at ``level`` itself, its root finder chosen by the guess and how the margin
    behaves (the fast tier's height as guess where none is given and ``use_fast``); a new
    search serial (the caller's linear prefix and stall cap start anew)."""
    p = pts[s.cur]
    s.serial += 1
    s.ask_level = level
    s.from_fast = 0
    s.n_known, s.n = n_known, n_known
    s.x_tol, s.guess, s.overshoot = x_tol, guess, overshoot
    if s.bisection == 1:
        # The report's method: bisection between the bounds, no guess (a search repeated at a
        # tighter tolerance finds its earlier midpoints among its points).
        s.signs_only = 0
        s.one = _ONE_BRENT   # its end is the search's end
        finder_reset(st)
        code, value = bisection_start(st, s.x_min, s.x_max, x_tol)
        return _one_pump(s, res, pts, st, fpts, code, value)
    if guess != guess and use_fast and s.h_fast == s.h_fast:
        guess, overshoot, s.from_fast = s.h_fast, FAST_GUESS_ERROR, 1
    for i in range(n_known):
        p[P_SIGN_ONLY, i] = 0.0   # stopped at the exit in an earlier search: kept as known
    has_guess = guess == guess
    jumped = slope < -JUMP_SLOPE
    fading = s.from_fast == 1 and s.regime == REGIME_FADING
    signs_only = has_guess and (s.regime == REGIME_STOPS_SLIDING or jumped or fading)
    s.signs_only = 1 if signs_only else 0
    s.n_known, s.n = n_known, n_known
    s.x_tol, s.guess, s.overshoot = x_tol, guess, overshoot
    s.one = _ONE_FINDER
    finder_reset(st)
    code, value = GIVE_UP, math.nan
    if has_guess and s.regime != REGIME_STOPS_SLIDING and not (jumped or fading):
        for i in range(n_known):
            if math.isfinite(p[P_M, i]):
                finder_point(st, fpts, p[P_X, i], p[P_M, i])
        code, value = go_side_start(st, fpts, math.log(guess), go_slope, x_tol, s.x_min,
                                    s.x_max, _or_default(overshoot, FAST_GUESS_ERROR),
                                    GO_SIDE_MAX_SIMULATIONS)
    elif has_guess:
        if fading:
            center, spread = math.log(guess) + FADING_FAST_SHIFT, FADING_FAST_SPREAD
        elif s.from_fast == 1:
            center, spread = math.log(guess), FAST_STOPS_SLIDING_SPREAD
        elif s.stage == _S_REFINE and n_known == 0:
            # The root the refined pair predicts for this level: the prior's centre.
            center, spread = math.log(guess), sigma
        else:
            half = 0.5 * _or_default(overshoot, FAST_GUESS_ERROR)
            center, spread = math.log(guess) + half, _or_default(sigma, half / 3.0)
        for i in range(n_known):
            m = p[P_M, i]
            if math.isfinite(m) or (signs_only and m == math.inf):
                finder_point(st, fpts, p[P_X, i], m)
        code, value = prior_bisection_start(st, fpts, center, spread, x_tol, s.x_min, s.x_max,
                                            GUIDED_MAX_SIMULATIONS, slope, signs_only)
    return _one_pump(s, res, pts, st, fpts, code, value)


@njit(cache=True)
def _one_pump(s, res, pts, st, fpts, code, value):
    """Answer the finder from the search's own points until it wants a new run (ask the
    caller) or ends (the search's result)."""
    p = pts[s.cur]
    while True:
        while code == ASK:
            i = _find(p, s.n, value)
            if i < 0:
                if s.n >= p.shape[1]:
                    return _fail(s)
                s.ask_x, s.ask_width = value, s.melt_width
                s.ask_until_exit = s.signs_only
                s.ask_alone = 0
                return ASK_RUN, value
            code, value = finder_step(st, fpts, p[P_M, i])
        if s.one == _ONE_FINDER and code != ROOT:
            if code == BAD_PROBABILITY:
                return _fail(s)
            # Brent's bracketing steps by the margin's value: the runs stopped at the exit are
            # dropped, to be run again in full where it needs them.
            kept = 0
            for i in range(s.n):
                if p[P_SIGN_ONLY, i] == 0.0:
                    p[P_X, kept], p[P_M, kept], p[P_SIGN_ONLY, kept] = p[P_X, i], p[P_M, i], 0.0
                    kept += 1
            s.n = kept
            s.one, s.signs_only = _ONE_BRENT, 0
            finder_reset(st)
            # Where the kept runs already bracket the root, every no-go run below every go
            # run, Brent's method starts on that bracket (the finder gave up inside it, at
            # its simulation limit or on a fold); otherwise it brackets from the guess.
            for i in range(kept):
                finder_point(st, fpts, p[P_X, i], p[P_M, i])
            f = st[0]
            if f.has_lo == 1 and f.has_hi == 1 and f.lo_x < f.hi_x:
                code, value = brent_bracket_start(st, f.lo_x, f.lo_m, f.hi_x, f.hi_m, s.x_min,
                                                  s.x_max, s.x_tol, s.horizon)
                continue
            guess = s.guess
            x0 = math.log(guess) if guess == guess and guess != 0.0 else 0.0   # 1 m by default
            code, value = brent_start(st, x0, s.x_min, s.x_max, s.x_tol, s.horizon,
                                      _or_default(s.overshoot, 0.05))
            continue
        break
    row = res[s.cur]
    row[R_N] = s.n
    row[R_EVALUATIONS] = s.n - s.n_known
    if code == ROOT:
        row[R_X], row[R_CENSOR], row[R_HEIGHT] = value, CENSOR_NONE, math.exp(value)
    elif code == CENSORED_ABOVE:
        row[R_X], row[R_CENSOR], row[R_HEIGHT] = s.x_max, CENSOR_ABOVE, s.h_max
    elif code == CENSORED_BELOW:
        row[R_X], row[R_CENSOR], row[R_HEIGHT] = s.x_min, CENSOR_BELOW, s.h_min
    else:
        return _fail(s)   # no bracket, no convergence: the CPU search raises
    row[R_OK] = 1.0
    if s.phase == _PH_MAIN:
        row[R_EVALUATIONS] += s.gap_evaluations
        return _SEARCH_DONE, math.nan
    return _GAP_DONE, math.nan


@njit(cache=True)
def _after_gap(s, res, pts, st, fpts):
    """The coarse start is done: the level's own search, from its root where it found one."""
    row = res[s.cur]
    s.phase = _PH_MAIN
    s.gap_evaluations = int(row[R_EVALUATIONS])
    guess, overshoot = s.l_guess, s.l_overshoot
    slope, go_slope = s.l_slope, s.l_go_slope
    if row[R_CENSOR] == CENSOR_NONE:
        guess = row[R_HEIGHT]
        slope, go_slope = _slopes(pts[s.cur], int(row[R_N]), fpts)
        overshoot = 2.0 * modelled_error(s.level - COARSE_GAP)
    return _one_begin(s, res, pts, st, fpts, s.level, s.level_tol, guess, overshoot, slope,
                      go_slope, s.l_sigma, 0, False)


@njit(cache=True)
def _settle(s, res, pts, st, fpts, code, value):
    """Carry the machine on through searches that end without asking for a run (a coarse start
    done, a search done, a censored search not tightened) until it asks or ends."""
    while True:
        if code == _GAP_DONE:
            code, value = _after_gap(s, res, pts, st, fpts)
        elif code == _SEARCH_DONE:
            code, value = _search_done(s, res, pts, st, fpts)
        else:
            return code, value


@njit(cache=True)
def _one_tell(s, res, pts, st, fpts, m, event):
    """The run asked for by the running search: its margin [1] and whether its event came by the
    exit. A NaN margin (a run that failed) ends the machine."""
    if m != m:
        return _fail(s)
    p = pts[s.cur]
    n = s.n
    p[P_X, n], p[P_M, n] = s.ask_x, m
    p[P_SIGN_ONLY, n] = 1.0 if s.signs_only == 1 and not event else 0.0
    s.n = n + 1
    code, value = finder_step(st, fpts, m)
    return _one_pump(s, res, pts, st, fpts, code, value)


@njit(cache=True)
def _fail(s):
    s.reason = BACK_FAILED
    return HAND_BACK, math.nan


# ------------------------------------------------------------------------------- the pair


@njit(cache=True)
def pair_start(ps, res, pts, st, fpts, rtol, h_min, h_max, level, melt_width, coarse_tol,
               fine_tol, melt_spread, exact, signs, regime, melting_term, measure_bias,
               allow_narrow, max_level, no_friction, h_fast, h_guess, horizon, bisection,
               plan=PLAN_ADAPTIVE, own_model=True):
    """Start the search of one scene; returns (code, x) (:func:`pair_step`).

    Parameters
    ----------
    ps, res, pts, st, fpts : ndarray
        The machine's storage (:func:`new_storage`; on a GPU thread, its local arrays).
    rtol : float
        Relative tolerance on the critical height [1].
    h_min, h_max : float
        Search bounds [m].
    level, melt_width, coarse_tol, fine_tol : float
        The first pair's fine level, its melting width [K] and root tolerances [1]
        (:func:`skidmc.solver.options.resolve_options`,
        :func:`skidmc.solver.controller.first_root_tolerances`); for a fixed pair the plan's
        root tolerance and half of it (:func:`skidmc.solver.plan.root_tolerance`), for one
        search its level and tolerance in ``level`` and ``fine_tol``.
    melt_spread : float
        Melting spread over each HE cell [1].
    exact, signs : bool
        The target is the exact semi-infinite solid; the root is located by signs.
    regime : int
        ``REGIME_*`` of the scene.
    melting_term : bool
        The model has the "melting" term.
    measure_bias : bool
        Measure the melting width's bias with one run at twice the width (melting modelled and
        the ignition temperature below the melting point).
    allow_narrow : bool
        Narrow the melting width when a round asks for it (else hand the scene back).
    max_level : float
        Finest level the caller can run (above it: hand back).
    no_friction : bool
        The scene has no friction: censored above without a simulation.
    h_fast : float
        The fast tier's height [m] as a first guess (NaN: none).
    h_guess : float
        The caller's first guess [m] (NaN: none).
    horizon : float
        ln(t_end / t_exit) of the model [1].
    bisection : bool
        Each search is the report's bisection on go / no-go between the bounds
        (``method="bisection"``) instead of the guided finders and Brent's method.
    plan : int
        :data:`PLAN_ADAPTIVE` (the default search), :data:`PLAN_PAIR` or :data:`PLAN_SINGLE`
        (the fixed plans of a forced level, a given model or ``extrapolate=False``: the
        calibrated estimate, no round).
    own_model : bool
        The caller models the scene level by level (else one model it was given answers every
        run: no coarse start two levels down; pass ``h_fast`` NaN).
    """
    s = ps[0]
    s.rtol, s.h_min, s.h_max = rtol, h_min, h_max
    s.x_min, s.x_max = math.log(h_min), math.log(h_max)
    s.h_fast, s.horizon, s.melt_spread = h_fast, horizon, melt_spread
    s.exact, s.signs, s.regime = 1 if exact else 0, 1 if signs else 0, regime
    s.melting_term, s.measure_bias = 1 if melting_term else 0, 1 if measure_bias else 0
    s.allow_narrow, s.max_level = 1 if allow_narrow else 0, max_level
    s.no_friction = 1 if no_friction else 0
    s.bisection = 1 if bisection else 0
    s.plan, s.own_model = plan, 1 if own_model else 0
    s.melt_width, s.coarse_tol, s.fine_tol = melt_width, coarse_tol, fine_tol
    s.coarse_level, s.fine_level = level - 1.0, level
    s.rounds = s.narrowed = s.evaluations = s.serial = 0
    s.reason = 0
    s.melt = math.nan
    s.extrapolated = 0
    if plan == PLAN_SINGLE:
        s.stage = _S_SINGLE
        code, value = _search_begin(s, res, pts, st, fpts, 1, level, fine_tol, h_guess,
                                    math.nan, math.nan, math.nan, math.nan, 0)
    else:
        s.stage = _S_COARSE
        code, value = _search_begin(s, res, pts, st, fpts, 0, level - 1.0, coarse_tol, h_guess,
                                    math.nan, math.nan, math.nan, math.nan, 0)
    return _settle(s, res, pts, st, fpts, code, value)


@njit(cache=True)
def pair_step(ps, res, pts, st, fpts, m, event):
    """The run asked for: its margin ln(t_ev / t_exit) [1] (inf: no event; NaN: the run failed)
    and whether its event came by the exit. Returns the machine's next (code, x):
    (:data:`ASK_RUN`, ln H) with the run's level, width, ``until_exit`` and ``alone`` (no
    linear prefix) in ``ps[0]``'s ``ask_*`` fields and its search in ``serial``;
    (:data:`FINISHED`, NaN) with the outcome in ``out_*`` (``out_extrapolated``: the height is
    the pair's Richardson value), the pair's ``extrapolated``, ``relative`` (its correction) and
    ``melt_bias``, ``evaluations``, and ``res`` / ``pts`` (row 1: the fine search); or
    (:data:`HAND_BACK`, NaN) with ``reason``."""
    s = ps[0]
    if s.stage == _S_BIAS or s.stage == _S_NARROW_BIAS:
        s.evaluations += 1
        s.melt = (MELT_SHIFT_FACTOR * abs(m - s.bias_m) / -s.bias_slope if math.isfinite(m)
                  else math.nan)
        if s.stage == _S_BIAS:
            _value(s, res)
            code, value = _round(s, res, pts, st, fpts)
        else:
            code, value = _round_end(s, res, pts, st, fpts)
    else:
        code, value = _one_tell(s, res, pts, st, fpts, m, event)
    return _settle(s, res, pts, st, fpts, code, value)


@njit(cache=True)
def _fine_begin(s, res, pts, st, fpts, x_tol, coarse_tol):
    """The pair's fine search: from the coarse root, the fine
    root's measured place above it (with the exact target: EXACT_FINE_SHIFT and its spread
    where the root is located by signs, EXACT_STEADY_FINE_OVERSHOOT on steady rebounds), the
    coarse search's slopes."""
    coarse = res[0]
    coarse_error = modelled_error(s.fine_level - 1.0)
    factor, spread = 0.75, FINE_SHIFT_SPREAD
    if s.exact == 1:
        factor = 2.0 * EXACT_FINE_SHIFT if s.signs == 1 else EXACT_STEADY_FINE_OVERSHOOT
        spread = EXACT_FINE_SHIFT_SPREAD
    slope, go_slope = _slopes(pts[0], int(coarse[R_N]), fpts)
    guess = coarse[R_HEIGHT] if coarse[R_CENSOR] == CENSOR_NONE else math.nan
    return _search_begin(s, res, pts, st, fpts, 1, s.fine_level, x_tol, guess,
                         factor * coarse_error, slope, go_slope,
                         spread * coarse_error + 0.5 * coarse_tol, 0)


@njit(cache=True)
def _bias_begin(s, res, pts, st, fpts):
    """The melting width's measured bias (the CPU search's ``_melt_width_bias``): one run at
    the coarse level with the width doubled, at the coarse search's lowest go point; the root's
    shift is the margin's change over the go side's slope, and :data:`MELT_SHIFT_FACTOR` times
    it bounds the bias. None (NaN) without melting, where the ignition temperature is not below
    the melting point (there the calibrated bound holds), or where no smooth go side is known."""
    coarse = res[0]
    s.melt = math.nan
    if coarse[R_CENSOR] != CENSOR_NONE or s.measure_bias == 0:
        return _bias_done(s, res, pts, st, fpts)
    n = int(coarse[R_N])
    go_slope = _slopes(pts[0], n, fpts)[1]
    p = pts[0]
    best = -1
    for i in range(n):   # the lowest go point (the first of the sorted history's go points)
        if math.isfinite(p[P_M, i]) and p[P_M, i] <= 0.0:
            if best < 0 or math.exp(p[P_X, i]) < math.exp(p[P_X, best]) or (
                    math.exp(p[P_X, i]) == math.exp(p[P_X, best]) and p[P_M, i] < p[P_M, best]):
                best = i
    if go_slope != go_slope or go_slope < -FOLD_SLOPE or best < 0:
        return _bias_done(s, res, pts, st, fpts)
    s.bias_x, s.bias_m, s.bias_slope = p[P_X, best], p[P_M, best], go_slope
    s.stage = _S_BIAS if s.stage == _S_FINE else _S_NARROW_BIAS
    s.ask_x, s.ask_level, s.ask_width = p[P_X, best], s.coarse_level, 2.0 * s.melt_width
    s.ask_until_exit, s.ask_alone = 0, 1
    return ASK_RUN, s.ask_x


@njit(cache=True)
def _bias_done(s, res, pts, st, fpts):
    """After the bias (measured or not): the pair's value and the rounds."""
    if s.stage == _S_FINE:
        _value(s, res)
        return _round(s, res, pts, st, fpts)
    return _round_end(s, res, pts, st, fpts)


@njit(cache=True)
def _value(s, res):
    """The pair's Richardson value and its a posteriori estimate (the CPU search's
    ``_adaptive_value``), or not extrapolated where either search is censored."""
    coarse, fine = res[0], res[1]
    if coarse[R_CENSOR] != CENSOR_NONE or fine[R_CENSOR] != CENSOR_NONE:
        s.extrapolated = 0
        return
    s.extrapolated = 1
    s.height, s.relative = richardson_value(coarse[R_HEIGHT], fine[R_HEIGHT])
    bound = MELT_WIDTH_BIAS_PER_K * s.melt_width if s.melting_term == 1 else 0.0
    measured = 0.0 if (s.melt != s.melt or s.melt == 0.0) else s.melt
    s.melt_bias = measured if measured > bound else bound
    s.pair, s.estimate = pair_estimate(s.relative, s.coarse_level, s.melt_spread,
                                       s.exact == 1, s.signs == 1, s.melt_bias, s.coarse_tol,
                                       s.fine_tol)


@njit(cache=True)
def _round(s, res, pts, st, fpts):
    """One adaptive round: the controller's decision (:func:`~skidmc.solver.controller.next_round`)
    and the searches it asks for, or the outcome."""
    if s.extrapolated == 0 or s.rounds >= MAX_ADAPTIVE_ROUNDS:
        return _finish(s, res)
    s.rounds += 1
    action, s.next_coarse_tol, s.next_fine_tol, s.value = next_round(
        s.rtol, s.estimate, s.pair, s.melt_bias, s.relative, s.height, s.coarse_level,
        s.coarse_tol, s.fine_tol, s.melt_width, s.narrowed, s.melt_spread, s.exact == 1,
        s.signs == 1)
    if action == DONE:
        return _finish(s, res)
    if action == TIGHTEN_FINE:
        s.stage = _S_TIGHTEN_F
        return _tighten_begin(s, res, pts, st, fpts, 1, s.fine_tol, s.next_fine_tol)
    if action == TIGHTEN_BOTH:
        s.stage = _S_TIGHTEN_C
        return _tighten_begin(s, res, pts, st, fpts, 0, s.coarse_tol, s.next_coarse_tol)
    if action == NARROW:
        if s.allow_narrow == 0:
            s.reason = BACK_NARROW
            return HAND_BACK, math.nan
        # Search the pair again at the new width (from the old root), measuring its bias anew.
        slope, go_slope = _slopes(pts[0], int(res[0, R_N]), fpts)
        overshoot = 2.0 * s.melt_bias + s.next_coarse_tol
        s.melt_width = s.value
        s.narrowed += 1
        s.stage = _S_NARROW_C
        return _search_begin(s, res, pts, st, fpts, 0, s.coarse_level, s.next_coarse_tol,
                             res[0, R_HEIGHT], overshoot, slope, go_slope, math.nan, 0)
    if action == REFINE:
        if s.fine_level + 1.0 > s.max_level:
            s.reason = BACK_LEVEL
            return HAND_BACK, math.nan
        # The pair moves up a level; the new fine search starts from the root predicted from
        # the pair (value [m]) with the old fine search's slopes.
        for k in range(RESULT_SIZE):
            res[0, k] = res[1, k]
        for r in range(POINTS_SHAPE[0]):
            for k in range(int(res[1, R_N])):
                pts[0, r, k] = pts[1, r, k]
        slope, go_slope = _slopes(pts[0], int(res[0, R_N]), fpts)
        s.coarse_level, s.fine_level = s.fine_level, s.fine_level + 1.0
        s.stage = _S_REFINE
        return _search_begin(s, res, pts, st, fpts, 1, s.fine_level, s.next_fine_tol, s.value,
                             0.5 * abs(s.relative) + s.next_fine_tol, slope, go_slope,
                             REFINE_SPREAD * (abs(s.relative) + s.next_fine_tol), 0)
    return _finish(s, res)   # STOP: nothing left that can help


@njit(cache=True)
def _tighten_begin(s, res, pts, st, fpts, cur, old_tol, x_tol):
    """A search again at the tighter ``x_tol`` from its own root, slopes and simulations (the
    CPU search's ``_tighten``); a censored search stays as it is."""
    row = res[cur]
    if row[R_CENSOR] != CENSOR_NONE:
        s.cur = cur
        row[R_EVALUATIONS] = 0.0   # nothing added
        return _SEARCH_DONE, math.nan
    n = int(row[R_N])
    p = pts[cur]
    slope, go_slope = _slopes(p, n, fpts)
    for i in range(n):   # the CPU search's history holds heights: ln of them
        p[P_X, i] = math.log(math.exp(p[P_X, i]))
    level = s.fine_level if cur == 1 else s.coarse_level
    return _search_begin(s, res, pts, st, fpts, cur, level, x_tol, row[R_HEIGHT], old_tol,
                         slope, go_slope, math.nan, n)


@njit(cache=True)
def _search_done(s, res, pts, st, fpts):
    """A level's search finished (its new simulations in ``res[cur, R_EVALUATIONS]``): the
    pair's next step."""
    s.evaluations += int(res[s.cur, R_EVALUATIONS])
    stage = s.stage
    if stage == _S_COARSE:
        s.stage = _S_FINE
        return _fine_begin(s, res, pts, st, fpts, s.fine_tol, s.coarse_tol)
    if stage == _S_SINGLE:
        return _finish(s, res)
    if stage == _S_FINE and s.plan == PLAN_PAIR:
        _value(s, res)   # its Richardson value; _finish states the calibrated estimate
        return _finish(s, res)
    if stage == _S_FINE or stage == _S_NARROW_F:
        return _bias_begin(s, res, pts, st, fpts)
    if stage == _S_TIGHTEN_C:
        s.stage = _S_TIGHTEN_F
        return _tighten_begin(s, res, pts, st, fpts, 1, s.fine_tol, s.next_fine_tol)
    if stage == _S_NARROW_C:
        s.stage = _S_NARROW_F
        return _fine_begin(s, res, pts, st, fpts, s.next_fine_tol, s.next_coarse_tol)
    return _round_end(s, res, pts, st, fpts)   # _S_TIGHTEN_F, _S_REFINE


@njit(cache=True)
def _round_end(s, res, pts, st, fpts):
    s.coarse_tol, s.fine_tol = s.next_coarse_tol, s.next_fine_tol
    _value(s, res)
    return _round(s, res, pts, st, fpts)


@njit(cache=True)
def _finish(s, res):
    """The outcome: the pair's Richardson value (its a posteriori estimate; a fixed pair's
    calibrated one, :func:`skidmc.solver.plan.extrapolated_error` plus the coarse root's
    tolerance and the width's bias), or the fine search's own result (its bound when censored)
    with the calibrated estimate of its level; a pair's extrapolation beyond a bound is
    censored there, its estimate kept."""
    fine = res[1]
    s.out_level = s.fine_level
    # The melting width's bias bound, 0 at the level's floor width, where the level's modelled
    # error holds it (skidmc.solver.plan.melt_bias).
    width_bias = 0.0
    if s.melting_term == 1 and s.melt_width > melt_width_floor(s.fine_level) * (1.0 + 1e-9):
        width_bias = MELT_WIDTH_BIAS_PER_K * s.melt_width
    if s.extrapolated == 1:
        s.out_height, s.out_censor, s.out_error = s.height, CENSOR_NONE, s.estimate
        if s.plan == PLAN_PAIR:
            s.out_error = extrapolated_error(s.fine_level) + s.coarse_tol + width_bias
    else:
        s.out_height, s.out_censor = fine[R_HEIGHT], int(fine[R_CENSOR])
        s.out_error = modelled_error(s.fine_level) + s.fine_tol + width_bias
    s.out_extrapolated = s.extrapolated
    if s.plan == PLAN_SINGLE:
        return FINISHED, math.nan
    if s.out_censor == CENSOR_NONE and not (s.h_min < s.out_height < s.h_max):
        above = s.out_height >= s.h_max
        s.out_censor = CENSOR_ABOVE if above else CENSOR_BELOW
        s.out_height = s.h_max if above else s.h_min
        s.out_extrapolated = 0   # the pair's correction and width bias are kept
    return FINISHED, math.nan


@njit(cache=True)
def finish_at_level_cap(ps, res):
    """The outcome of a default search stopped by its caller's cap on the level
    (``max_level`` of :func:`pair_start`, where the machine handed its scene back with
    :data:`BACK_LEVEL`): the last pair's value and a posteriori estimate, as the round that
    would have refined found them (above rtol: the caller flags it). Returns (FINISHED, NaN)."""
    return _finish(ps[0], res)


@njit(cache=True)
def asked(ps):
    """The run the machine asked for, for a Python caller: (level, melting width [K],
    until_exit, alone (no linear prefix), the search's serial)."""
    s = ps[0]
    return s.ask_level, s.ask_width, s.ask_until_exit == 1, s.ask_alone == 1, s.serial


@njit(cache=True)
def outcome(ps):
    """The finished machine's outcome, for a Python caller: (height [m], censoring, error
    estimate [1], fine level, extrapolated, the pair's correction [1] and width bias [1] (0 where
    the pair was not extrapolated), simulations)."""
    s = ps[0]
    pair = s.extrapolated == 1
    return (s.out_height, s.out_censor, s.out_error, s.out_level, s.out_extrapolated == 1,
            s.relative if pair else 0.0,
            s.melt_bias if pair and s.plan == PLAN_ADAPTIVE else 0.0, s.evaluations)
