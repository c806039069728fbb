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
        if action in (ctl.TIGHTEN_FINE, ctl.TIGHTEN_BOTH):
            seen.add(action)
            assert estimate > rtol
            melt = estimate - pair - ctl.root_error(coarse_tol, fine_tol)
            room = rtol - pair - melt
            # Equality up to rounding: 1e-12 relative is many ulps of sums of three terms.
            assert ctl.root_error(c_tol, f_tol) == pytest.approx(TIGHTEN_FRACTION * room,
                                                                 rel=1e-12)
            assert pair + melt + ctl.root_error(c_tol, f_tol) < rtol
            if action == ctl.TIGHTEN_FINE:
                assert c_tol == coarse_tol and f_tol < fine_tol
            else:
                assert f_tol == 0.5 * c_tol and c_tol < coarse_tol
    assert seen == {ctl.TIGHTEN_FINE, ctl.TIGHTEN_BOTH}


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
