"""The adaptive controller (skidmc.solver.controller): one rule for the CPU and device searches.

That the move of the rule changed no result is shown by ``benchmarks/heights_fingerprint.py``
(every height, estimate and evaluation count bit for bit, before and after); these tests check
the rule's own promises on its inputs.
"""

from __future__ import annotations

import numpy as np
import pytest

from skidmc.solver import controller as ctl
from skidmc.solver.model import MELT_WIDTH_BIAS_PER_K, melt_width_floor
from skidmc.solver.plan import (
    MAX_ADAPTIVE_LEVEL,
    MAX_ROOT_TOLERANCE,
    MELT_SHARE,
    ROOT_SHARE,
    TIGHTEN_FRACTION,
    a_posteriori_error,
    jump_root_tolerances,
    pair_root_tolerance,
)


def _round(rtol, correction, coarse_level, coarse_tol, fine_tol, melt_bias, width=1.0,
           narrowed=0, exact=True, signs=False, spread=1.0, height=10.0):
    pair, estimate = ctl.pair_estimate(correction, coarse_level, spread, exact, signs, melt_bias,
                                       coarse_tol, fine_tol)
    return pair, estimate, ctl.next_round(rtol, estimate, pair, melt_bias, correction, height,
                                          coarse_level, coarse_tol, fine_tol, width, narrowed,
                                          spread, exact, signs)


def test_richardson_value_is_second_order_extrapolation():
    # H_L = R (1 - e 4^-L): with H_0 = 0.9 and H_1 = 0.975 (e = 0.1), R = 1 exactly.
    height, correction = ctl.richardson_value(0.9, 0.975)
    assert height == pytest.approx(1.0, rel=1e-15)
    assert correction == pytest.approx(0.025, rel=1e-14)


def test_the_estimate_adds_its_parts_in_the_searchs_order():
    pair, estimate = ctl.pair_estimate(-2e-3, 0.5, 1.0, True, False, 1e-4, 4e-4, 2e-4)
    assert pair == a_posteriori_error(-2e-3, 0.5, 1.0, True, False)
    assert estimate == pair + 1e-4 + (4.0 * 2e-4 + 4e-4) / 3.0


def test_an_estimate_within_rtol_is_done_and_changes_nothing():
    _, estimate, (action, c_tol, f_tol, value) = _round(1e-3, 1e-4, 0.5, 2e-4, 1e-4, 1e-4)
    assert estimate <= 1e-3
    assert (action, c_tol, f_tol, value) == (ctl.DONE, 2e-4, 1e-4, 0.0)


@pytest.mark.parametrize("seed", range(3))
def test_tightened_roots_bring_the_estimate_within_rtol(seed):
    # Wherever the roots are tightened, the new tolerances' root error is TIGHTEN_FRACTION of
    # the room the pair and the width leave: the estimate with the same pair then meets rtol.
    rng = np.random.default_rng(seed)
    seen = set()
    for _ in range(400):
        rtol = 10.0 ** rng.uniform(-4.0, -2.0)
        coarse_tol = rtol * rng.uniform(0.1, 3.0)
        fine_tol = coarse_tol * rng.uniform(0.2, 1.0)
        pair, estimate, (action, c_tol, f_tol, _) = _round(
            rtol, rtol * rng.uniform(0.0, 0.7), rng.choice([0.0, 0.5, 1.0]), coarse_tol,
            fine_tol, rtol * rng.uniform(0.0, 0.1))
        melt = estimate - pair - ctl.root_error(coarse_tol, fine_tol)
        room = rtol - pair - melt
        if action in (ctl.TIGHTEN_FINE, ctl.TIGHTEN_BOTH) and room >= ROOT_SHARE * rtol:
            # (A smaller room is tightened within a bound on the roots' move:
            # test_bounded_tightening_holds_however_the_roots_move.)
            seen.add(action)
            assert estimate > rtol
            # Equality up to rounding: 1e-12 relative is many ulps of sums of three terms.
            assert ctl.root_error(c_tol, f_tol) == pytest.approx(TIGHTEN_FRACTION * room,
                                                                 rel=1e-12)
            assert pair + melt + ctl.root_error(c_tol, f_tol) < rtol
            if action == ctl.TIGHTEN_FINE:
                assert c_tol == coarse_tol and f_tol < fine_tol
            else:
                assert f_tol == 0.5 * c_tol and c_tol < coarse_tol
    assert seen == {ctl.TIGHTEN_FINE, ctl.TIGHTEN_BOTH}


def _moved_estimates(rtol, correction, coarse_level, coarse_tol, fine_tol, melt_bias, c_tol,
                     f_tol, height, exact, signs, spread):
    """Estimates of a pair whose roots were searched again at (c_tol, f_tol), at the extremes
    of where the new roots can lie: each within its old tolerance plus its new one of the old
    root (both within their tolerances of the level's root), in ln H."""
    # R = H_L + (H_L - H_{L-1}) / 3 and c = (H_L - H_{L-1}) / (3 R): exactly these heights [m].
    h_fine = height * (1.0 - correction)
    h_coarse = height * (1.0 - 4.0 * correction)
    moves = [0.0] if c_tol == coarse_tol else [-1.0, 1.0]
    out = []
    for sc in moves:
        for sf in (-1.0, 1.0):
            hc = h_coarse * np.exp(sc * (coarse_tol + c_tol))
            hf = h_fine * np.exp(sf * (fine_tol + f_tol))
            _, c = ctl.richardson_value(hc, hf)
            out.append(ctl.pair_estimate(c, coarse_level, spread, exact, signs, melt_bias,
                                         c_tol, f_tol)[1])
    return out


@pytest.mark.parametrize("exact,signs,spread", [(True, False, 1.0), (True, True, 1.0),
                                                (False, False, 0.0), (False, False, 1.0)])
def test_bounded_tightening_holds_however_the_roots_move(exact, signs, spread):
    # Where the pair and the width leave less than ROOT_SHARE rtol, the roots are tightened
    # only to tolerances whose estimate stays within rtol wherever the new roots lie (each
    # within its old tolerance plus its new one of the old root): checked at those extremes,
    # over random pairs and tolerances of the searches' ranges. Else the pair moves up a level.
    rng = np.random.default_rng(7)
    seen = {}
    for _ in range(3000):
        rtol = 10.0 ** rng.uniform(-4.0, -2.0)
        coarse_level = float(rng.choice([0.0, 0.5, 1.0, 1.5]))
        coarse_tol = rtol * rng.uniform(0.05, 0.5)
        fine_tol = coarse_tol * rng.uniform(0.3, 1.0)
        melt = rtol * rng.uniform(0.0, 0.3)
        # A posteriori parts of 0.4-1.0 rtol: the pairs whose room is below ROOT_SHARE rtol.
        slope = a_posteriori_error(1.0, coarse_level, spread, exact, signs)
        correction = rng.choice([-1.0, 1.0]) * rtol * rng.uniform(0.4, 1.0) / slope
        height = 10.0 ** rng.uniform(-1.0, 2.0)
        pair, estimate = ctl.pair_estimate(correction, coarse_level, spread, exact, signs, melt,
                                           coarse_tol, fine_tol)
        if estimate <= rtol or rtol - pair - melt >= ROOT_SHARE * rtol:
            continue
        action, c_tol, f_tol, _ = ctl.next_round(
            rtol, estimate, pair, melt, correction, height, coarse_level, coarse_tol,
            fine_tol, 1.0, 0, spread, exact, signs)
        seen[action] = seen.get(action, 0) + 1
        if action not in (ctl.TIGHTEN_FINE, ctl.TIGHTEN_BOTH):
            continue
        assert f_tol >= ctl.BOUNDED_MIN_ROOT * rtol and f_tol < fine_tol
        if action == ctl.TIGHTEN_FINE:
            assert c_tol == coarse_tol
        else:
            assert c_tol == ctl.BOUNDED_COARSE_RATIO * f_tol and c_tol < coarse_tol
        worst = max(_moved_estimates(rtol, correction, coarse_level, coarse_tol, fine_tol, melt,
                                     c_tol, f_tol, height, exact, signs, spread))
        # The bound aims at BOUNDED_AIM rtol; what it neglects (R's change in c, ln H against
        # relative height) is ~c t, far below the 1 % spare.
        assert worst <= rtol
    # Every branch was reached: the fine root alone, a refinement where no bounded tolerance of
    # at least BOUNDED_MIN_ROOT rtol reaches, and both roots where the a posteriori part grows
    # by less than the coarse root's own error weighs (k < 1: a coarse root searched again then
    # frees more than its move costs; with signs, k = 2, it never does).
    assert seen.get(ctl.TIGHTEN_FINE, 0) > 20 and seen.get(ctl.REFINE, 0) > 20
    if not signs:
        assert seen.get(ctl.TIGHTEN_BOTH, 0) > 5


def test_bounded_tightening_prefers_the_fine_root_and_gives_up_below_its_floor():
    # Exact target, steady margin, pair (0.5, 1.5) at rtol 1e-3: a posteriori 0.75 |c|.
    # sobol-series1 scenes measured with |c| = 8.9e-4, bias 2e-4, tolerances (2e-4, 1e-4): the
    # room, 1.3e-4, is below ROOT_SHARE rtol; the bound leaves the fine root 1.8e-5.
    rtol, c_tol, f_tol, melt = 1e-3, 2e-4, 1e-4, 2e-4
    k = a_posteriori_error(1.0, 0.5, 1.0, True, False)
    for correction in (8e-4, 8.9e-4):
        pair = a_posteriori_error(correction, 0.5, 1.0, True, False)
        tight = ctl.bounded_tightening(rtol, pair, melt, correction, 0.5, c_tol, f_tol, 1.0,
                                       True, False)
        kg = k * (1.0 + 8.0 * correction)
        expected = ((ctl.BOUNDED_AIM * rtol - pair - melt - kg * f_tol / 3.0 - c_tol / 3.0)
                    * 3.0 / (4.0 + kg))
        assert tight == pytest.approx(expected, rel=1e-14)
        assert ctl.BOUNDED_MIN_ROOT * rtol <= tight < f_tol
    # A correction whose a posteriori part alone nearly fills rtol leaves nothing: refine.
    pair = a_posteriori_error(1.25e-3, 0.5, 1.0, True, False)
    assert ctl.bounded_tightening(rtol, pair, melt, 1.25e-3, 0.5, c_tol, f_tol, 1.0, True,
                                  False) == 0.0
    _, _, (action, *_rest) = _round(rtol, 1.25e-3, 0.5, c_tol, f_tol, melt)
    assert action == ctl.REFINE


def test_a_width_bias_above_twice_its_share_narrows_the_width():
    # rtol 1e-3 and a measured width bias of 6e-4 (> 2 x 0.2 rtol) leave the roots < 0.2 rtol:
    # the width is scaled to bring its bias to MELT_SHARE rtol (first order in w), and the
    # first root tolerances at the new width follow.
    rtol, width, bias = 1e-3, 3.0, 6e-4
    _, _, (action, c_tol, f_tol, value) = _round(rtol, 4e-4, 0.5, 3e-4, 1.5e-4, bias,
                                                 width=width)
    assert action == ctl.NARROW
    assert value == pytest.approx(max(melt_width_floor(0.5), width * MELT_SHARE * rtol / bias))
    assert c_tol == pair_root_tolerance(rtol, 1.5, value, 1.0, True, False)
    assert f_tol == 0.5 * c_tol
    # Never twice more, and never below the coarse level's floor: then the pair refines.
    floor = melt_width_floor(0.5)
    for narrowed, w in ((2, width), (0, floor)):
        _, _, (action, *_rest) = _round(rtol, 4e-4, 0.5, 3e-4, 1.5e-4, bias, width=w,
                                        narrowed=narrowed)
        assert action == ctl.REFINE


def test_a_refined_pair_starts_from_the_predicted_root():
    # The pair's correction leaves no room for the roots: move up a level, the next fine root
    # guessed a quarter of the correction below the Richardson value (the fine level's error is
    # about the correction, the next level's a quarter of it).
    rtol, correction, height = 1e-3, -1.2e-3, 25.0
    _, _, (action, c_tol, f_tol, value) = _round(rtol, correction, 0.5, 2e-4, 1e-4, 1e-4,
                                                 height=height)
    assert action == ctl.REFINE
    assert value == height * (1.0 - 0.25 * correction)
    assert c_tol == 1e-4    # the old fine search becomes the coarse one
    assert 0.5 * ROOT_SHARE * rtol <= f_tol <= MAX_ROOT_TOLERANCE


def test_nothing_left_to_do_stops_with_the_estimate_above_rtol():
    # At the finest level, with the width at its floor: STOP, tolerances unchanged.
    coarse_level = MAX_ADAPTIVE_LEVEL - 1.0
    width = melt_width_floor(coarse_level)
    _, estimate, (action, c_tol, f_tol, value) = _round(
        1e-3, -1.2e-3, coarse_level, 2e-4, 1e-4, MELT_WIDTH_BIAS_PER_K * width, width=width)
    assert estimate > 1e-3
    assert (action, c_tol, f_tol, value) == (ctl.STOP, 2e-4, 1e-4, 0.0)


def test_first_root_tolerances_follow_the_margins_kind():
    assert ctl.first_root_tolerances(1e-3, 1.5, 1.0, 1.0, True, True) == jump_root_tolerances(
        1e-3, 1.5, 1.0, 1.0, True)
    coarse = pair_root_tolerance(1e-3, 1.5, 1.0, 1.0, True)
    assert ctl.first_root_tolerances(1e-3, 1.5, 1.0, 1.0, True, False) == (coarse,
                                                                          0.5 * coarse)
