"""The compiled root finders (skidmc.solver.finders): the library algorithms they write out,
bit for bit, and driving them from compiled code (the device search's way)."""

import math
import random
import statistics

import numpy as np
import pytest
from numba import njit
from scipy.optimize import brentq

from skidmc.solver import finders
from skidmc.solver.finders import ASK, FINDER_STATE, ROOT
from skidmc.solver.roots import brent_root, go_side_root, prior_bisection_root


def test_normal_functions_equal_statistics_normaldist_bit_for_bit():
    # The prior bisection placed its points with statistics.NormalDist; the compiled finder
    # must place them on the same bits, or the CPU search's heights would change.
    dist = statistics.NormalDist()
    rng = random.Random(7)
    zs = [rng.gauss(0.0, 2.0) for _ in range(20_000)] + [rng.uniform(-38.0, 38.0)
                                                          for _ in range(5_000)]
    ps = ([rng.random() for _ in range(20_000)] + [10.0 ** rng.uniform(-300.0, -1.0)
                                                   for _ in range(5_000)])
    ps += [1.0 - p for p in ps if 0.0 < 1.0 - p < 1.0]
    assert all(finders.normal_cdf(z) == dist.cdf(z) for z in zs)
    assert all(finders.normal_quantile(p) == dist.inv_cdf(p) for p in ps if p > 0.0)


@pytest.mark.parametrize("shape", ["linear", "capped"])
def test_brent_on_a_known_bracket_is_scipy_brentq_on_it(shape):
    # brent_bracket_start: a bracket handed on by a finder that gave up inside it. The points
    # asked and the root are scipy's brentq on that bracket, bit for bit, and nothing outside.
    root, x_tol, horizon = 0.4137, 3e-4, 0.7
    lo, hi = 0.39, 0.45

    def f(x):
        d = x - root
        return (math.inf if d < -0.01 else -1.1 * d) if shape == "capped" else -1.2 * d

    st = np.zeros(1, dtype=FINDER_STATE)
    finders.finder_reset(st)
    code, value = finders.brent_bracket_start(st, lo, f(lo), hi, f(hi), -5.0, 5.0, x_tol,
                                              horizon)
    asked = []
    while code == ASK:
        asked.append(value)
        code, value = finders.finder_step(st, np.empty((2, 1)), f(value))
    assert code == ROOT
    assert all(lo < x < hi for x in asked)

    def bounded(x):
        m = f(x)
        return m if math.isfinite(m) else 2.0 * horizon + 1.0

    g, calls = _recording(bounded)
    assert value == brentq(g, lo, hi, xtol=x_tol, rtol=4 * np.finfo(float).eps)
    assert asked == calls[2:]


def _recording(f):
    calls = []

    def g(x):
        calls.append(x)
        return f(x)

    return g, calls


@pytest.mark.parametrize("shape", ["linear", "cubic", "kinked", "capped"])
def test_brent_phase_takes_scipy_brentq_steps_bit_for_bit(shape):
    # After bracketing, the finder runs scipy's brentq (xtol, rtol = 4 eps) written out: the
    # same points asked in the same order and the same root, to the last bit.
    root, x_tol, horizon = 0.4137, 3e-4, 0.7

    def f(x):
        d = x - root
        if shape == "linear":
            return -1.2 * d
        if shape == "cubic":
            return -d - 3.0 * d ** 3 + 0.2 * d * d
        if shape == "kinked":
            return -1.3 * d + 4.0 * d * d if d >= 0.0 else -0.9 * d - 0.2 * d * d
        return math.inf if d < -0.05 else -1.1 * d   # no event far below the root

    st = np.zeros(1, dtype=FINDER_STATE)
    finders.finder_reset(st)
    code, value = finders.brent_start(st, -0.3, -5.0, 5.0, x_tol, horizon, 0.05)
    asked = []
    while code == ASK and st[0]["mode"] != 4:   # until bracketed (mode 4: Brent)
        asked.append(value)
        code, value = finders.finder_step(st, np.empty((2, 1)), f(value))
    lo, hi = float(st[0]["lo_x"]), float(st[0]["hi_x"])
    assert f(lo) > 0.0 >= f(hi)
    brent_asked = []
    while code == ASK:
        brent_asked.append(value)
        code, value = finders.finder_step(st, np.empty((2, 1)), f(value))
    assert code == ROOT

    def bounded(x):
        m = f(x)
        return m if math.isfinite(m) else 2.0 * horizon + 1.0

    g, calls = _recording(bounded)
    expected = brentq(g, lo, hi, xtol=x_tol, rtol=4 * np.finfo(float).eps)
    assert value == expected
    assert brent_asked == calls[2:]      # scipy evaluates the bracket's ends first
    assert len(brent_asked) >= 1


def test_brent_root_censors_at_the_bounds_it_was_given():
    # A margin positive everywhere: no event up to h_max, censored "above" at x_max exactly.
    assert brent_root(lambda x: 0.3, -2.0, 1.5, 1e-3, 0.7, 1.0) == (1.5, "above")
    assert brent_root(lambda x: -0.3, -2.0, 1.5, 1e-3, 0.7, 1.0) == (-2.0, "below")


def test_finders_never_ask_outside_the_search_bounds():
    # The guided finders give up rather than step outside (x_min, x_max): the search's bounds
    # are the user's h_min and h_max.
    root, x_tol = 1.49, 1e-4
    g, calls = _recording(lambda x: -1.2 * (x - root))
    res = go_side_root(g, 1.45, None, x_tol, -1.0, 1.5, guess_error=0.05)
    assert all(-1.0 < x < 1.5 for x in calls)
    assert res is None or abs(res - root) < x_tol
    g, calls = _recording(lambda x: 0.3 if x < root else -0.3)
    res = prior_bisection_root(g, 1.3, 0.1, x_tol, -1.0, 1.5)
    assert all(-1.0 < x < 1.5 for x in calls)
    assert res is None or abs(res - root) <= x_tol


@njit(cache=True)
def _compiled_search(root, x_guess, sigma, x_tol):
    """A compiled caller drives the prior bisection on a jump margin (as the device search
    drives the finders with its own runs): returns (root, simulations)."""
    st = np.zeros(1, dtype=FINDER_STATE)
    pts = np.empty((2, 8))
    finders.finder_reset(st)
    code, value = finders.prior_bisection_start(st, pts, x_guess, sigma, x_tol, -10.0, 10.0,
                                                40, math.nan, False)
    n = 0
    while code == ASK:
        m = 0.12 - 0.5 * (value - root) if value < root else -0.28 - 1.5 * (value - root) ** 0.45
        n += 1
        code, value = finders.finder_step(st, pts, m)
    return (value if code == ROOT else math.nan), n


def test_a_compiled_caller_finds_the_same_root_as_the_python_driver():
    root, x_guess, sigma, x_tol = 5.118, 5.1, 0.02, 3e-4
    found, n = _compiled_search(root, x_guess, sigma, x_tol)
    g, calls = _recording(lambda x: 0.12 - 0.5 * (x - root) if x < root
                          else -0.28 - 1.5 * (x - root) ** 0.45)
    assert found == prior_bisection_root(g, x_guess, sigma, x_tol, -10.0, 10.0)
    assert n == len(calls)
    assert abs(found - root) <= x_tol   # a jump bracket of 2 x_tol: its midpoint within x_tol


def test_history_slopes_read_a_finished_search():
    # What the next search starts from: the secant across the sign change (on ln H), -inf
    # where the no-go end had no event (a jump: search the next one by signs), and the go side's
    # slope between its two lowest go points; None where the history has none.
    from skidmc.solver.roots import go_side_slope, margin_slope

    h = [1.0, 1.01, 1.02, 1.05]
    history = [(h[0], 0.02), (h[1], -0.01), (h[2], -0.03), (h[3], -0.07)]
    assert margin_slope(history) == (-0.01 - 0.02) / (math.log(h[1]) - math.log(h[0]))
    assert go_side_slope(history) == (-0.03 + 0.01) / (math.log(h[2]) - math.log(h[1]))
    jump = [(1.0, math.inf), (1.001, math.nan), (1.002, -0.4)]
    assert margin_slope(jump) == -math.inf          # the NaN run is skipped
    assert go_side_slope(jump) is None              # one go point only
    assert margin_slope([(1.0, 0.1), (2.0, 0.05)]) is None   # no sign change
    assert go_side_slope([(1.0, -0.1), (2.0, -0.05)]) is None   # rising: not a go side
    assert margin_slope([]) is None and go_side_slope([]) is None


def _go_side_margin(root, slope, kappa):
    """A go side that bends by ``kappa`` (a secant through go points at d_a, d_b above the root
    misses it by kappa d_a d_b) above ``root``, and a no-go side 30 % less steep below it."""
    def margin(x):
        d = x - root
        return slope * d + kappa * abs(slope) * d * d if d >= 0.0 else 0.7 * slope * d
    return margin


def test_go_side_runs_aim_by_a_typical_bend_and_accept_by_the_worst():
    # A temperature-dependent target's coarse search (paper-series1[16338]:alumina-85, the
    # tail's draw): go-side slope -1.08, little bend, the fast tier's guess 6 % above the root.
    root, x_tol = math.log(5.2105), 3e-4
    g, calls = _recording(_go_side_margin(root, -1.08, 0.2))
    found = go_side_root(g, root + 0.06, None, x_tol, -1.0, 5.0, guess_error=0.02)
    # Aimed by the worst bend (GO_BEND) the runs crept down from above: 6 of them (0.08, 0.032,
    # 0.026, 0.0083, 0.0021, 0.0004 above the root); aimed by GO_AIM_BEND, 4.
    assert len(calls) <= 4
    assert abs(found - root) <= 0.5 * x_tol
    # Accepting a root is still decided by GO_BEND: on go sides bent up to the largest kappa
    # measured at the default pairs' levels (6.8) and guesses off either way, each root found
    # lies within x_tol (the finder may give up instead: the search then runs Brent's method).
    for kappa in (0.0, 0.66, 2.0, 6.8):
        for off in (-0.03, 0.02, 0.06, 0.12):
            found = go_side_root(_go_side_margin(root, -1.08, kappa), root + off, None, x_tol,
                                 -1.0, 5.0, guess_error=0.02)
            assert found is None or abs(found - root) <= x_tol, (kappa, off, found)


def test_a_go_run_at_the_root_is_bracketed_from_just_below_it():
    # A temperature-dependent target's coarse search (sobol-series1[56313]:alumina-85, seed 46
    # of benchmarks/study_scenes.py): the fast tier's guess 3.6 % low, a no-go run 1.6 % below
    # the root, then a go run 0.014 % above it. Its prediction gives no progress (the root lies
    # within a push of the go run); halving the way to the no-go run crept up on the root from
    # below, a run per halving (6 runs in all). Two pushes below the go run close a bracket
    # 3 x_tol wide at once: 3 runs.
    root, x_tol = math.log(9.474), 3e-4
    g, calls = _recording(lambda x: -(x - root) if x >= root else -0.97 * (x - root))
    found = go_side_root(g, root - 0.0358, None, x_tol, -1.0, 5.0, guess_error=0.02)
    assert len(calls) <= 3, [x - root for x in calls]
    assert abs(found - root) <= x_tol
