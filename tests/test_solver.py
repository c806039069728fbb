"""The critical-height solver: the report's Table VIII, convergence, trends, censoring."""

import math

import pytest

from skidmc.errors import SceneError
from skidmc.scene import get_preset, make_scene
from skidmc.scene.presets import PAPER_TABLE_VIII
from skidmc.solver import critical_height
from skidmc.solver.model import MELT_WIDTH_BIAS_PER_K, melt_width_floor
from skidmc.solver.plan import (
    DISCRETISATION_SHARE,
    ERROR_LEVEL0,
    MAX_MELT_WIDTH,
    MELT_SHARE,
    ROOT_SHARE,
    extrapolated_error,
    level_for_rtol,
    melt_width_for_rtol,
    modelled_error,
    plan_for_rtol,
    root_tolerance,
)
from skidmc.solver.roots import CARRIED_GO_SLOPE_ERROR

FT = 0.3048

# rtol 1e-2 keeps the default run fast; its error (< 0.8 %) is small against what is tested.
FAST = 1e-2


@pytest.mark.parametrize("row", PAPER_TABLE_VIII, ids=lambda r: r.preset)
def test_first_series_within_20_percent_of_table_viii(row):
    # The report omits its mesh, time step and search tolerance, and its explicit
    # scheme with Eq. (16)'s zero-capacity boundary node differs from ours; two inputs
    # (the target properties of "85 % alumina", the rounding of I_cg/W = 0.0648) are
    # also only approximately known. Our converged values sit within 3 % of Table VIII
    # for quartz, smooth alumina and within 7 % for gold, but 16 % below for rough
    # alumina (whose report value departs from the mu^-2 scaling its own smooth-alumina
    # value implies). 20 % is the bound the issue sets for this comparison.
    res = critical_height(get_preset(row.preset), rtol=FAST)
    assert res.censored is None
    assert res.critical_height_ft == pytest.approx(row.calculated_ft, rel=0.20)


def test_gold_above_the_tower():
    # Table II: no event on gold at 25-150 ft; the model must agree (> 150 ft).
    res = critical_height(get_preset("paper-gold"), rtol=FAST)
    assert res.critical_height_ft > 150.0
    assert "stops_sliding" in res.flags


@pytest.mark.parametrize("name", ["paper-quartz", "paper-gold"])
def test_halving_mesh_and_step_changes_less_than_claimed_error(name):
    # Level L+1 doubles the cells, halves the first cell and the time step.
    scene = get_preset(name)
    coarse = critical_height(scene, level=1.0, rtol=1e-5)
    fine = critical_height(scene, level=2.0, rtol=1e-5)
    change = abs(fine.critical_height / coarse.critical_height - 1)
    claimed = ERROR_LEVEL0 * 4.0 ** -1.0
    assert change < claimed
    # ... and the change is a real refinement effect, not noise: second order means the
    # next halving changes the result ~4x less.
    finer = critical_height(scene, level=3.0, rtol=1e-5)
    change2 = abs(finer.critical_height / fine.critical_height - 1)
    assert 2.0 < change / change2 < 8.0


def test_runaway_rule_does_not_move_the_height():
    # The runaway rule stops the run once the adiabatic induction time is below a small
    # fraction of the contact time. Moving that fraction by 4 decades, or switching the
    # rule off (the report's criterion alone, y > 0.99), must move H by far less than
    # the error budget (1e-3): measured 4e-5 between 1e-3 and 0 at level 1.
    scene = get_preset("paper-quartz")
    heights = [critical_height(scene, level=1.0, rtol=1e-6, runaway_fraction=f).critical_height
               for f in (1e-4, 1e-6, 0.0)]
    assert max(heights) / min(heights) - 1 < 1e-4


def test_bisection_reference_agrees_with_brent():
    scene = get_preset("paper-alumina-smooth")
    brent = critical_height(scene, rtol=FAST)
    bisect = critical_height(scene, rtol=FAST, method="bisection")
    assert bisect.critical_height == pytest.approx(brent.critical_height, rel=FAST)
    assert brent.evaluations < bisect.evaluations


def test_height_falls_as_mu_rises():
    heights = [critical_height(make_scene(preset="paper-quartz", mu=mu), rtol=FAST).critical_height
               for mu in (0.06, 0.1, 0.15, 0.25)]
    assert all(a > b for a, b in zip(heights, heights[1:]))


def test_height_rises_with_target_effusivity():
    base = get_preset("paper-quartz")
    heights = [critical_height(base.replace({"target.conductivity": k}), rtol=FAST).critical_height
               for k in (1.0, 2.0, 5.0, 20.0)]
    assert all(a < b for a, b in zip(heights, heights[1:]))


def test_melting_raises_the_height():
    scene = get_preset("paper-quartz")
    with_melt = critical_height(scene, rtol=FAST)
    without = critical_height(scene, rtol=FAST, melting=False)
    assert "melting" in with_melt.terms and "melting" not in without.terms
    # 50 cal/g absorbed at 553 K: ~13 % higher critical height.
    assert with_melt.critical_height > 1.05 * without.critical_height


def test_censoring_is_a_result_not_an_error():
    scene = get_preset("paper-quartz")
    above = critical_height(scene, rtol=FAST, h_max=0.1)
    assert above.censored == "above" and above.critical_height == 0.1
    below = critical_height(scene, rtol=FAST, h_min=2.0)
    assert below.censored == "below" and below.critical_height == 2.0
    frictionless = critical_height(make_scene(preset="paper-quartz", mu=0.0))
    assert frictionless.censored == "above" and frictionless.evaluations == 0
    assert "no_friction" in frictionless.flags


def test_pendulum_has_no_normal_force_moment():
    quartz = critical_height(get_preset("paper-quartz"), rtol=FAST)
    gold = critical_height(get_preset("paper-gold"), rtol=FAST)
    assert "normal_force_spin" not in quartz.terms
    assert "normal_force_spin" in gold.terms


def test_level_for_rtol_meets_error_model():
    for rtol in (1e-1, 1e-2, 1e-3, 1e-4):
        level = level_for_rtol(rtol)
        assert ERROR_LEVEL0 * 4.0 ** -level <= DISCRETISATION_SHARE * rtol
        assert level == 0 or ERROR_LEVEL0 * 4.0 ** -(level - 0.5) > DISCRETISATION_SHARE * rtol


def test_rtol_shares_add_up_and_melt_width_bias_fits_its_share():
    assert DISCRETISATION_SHARE + MELT_SHARE + ROOT_SHARE == pytest.approx(1.0)
    for rtol in (3e-2, 1e-2, 3e-3, 1e-3, 3e-4, 1e-4):
        level, _ = plan_for_rtol(rtol)
        width = melt_width_for_rtol(rtol, level)
        assert melt_width_floor(level) <= width <= MAX_MELT_WIDTH
        # Above the floor the bias must fit its share; at the floor it is in the level's error.
        if width > melt_width_floor(level):
            assert MELT_WIDTH_BIAS_PER_K * width <= MELT_SHARE * rtol * (1 + 1e-12)


def test_plan_for_rtol_meets_its_error_model_and_is_never_finer_than_plain():
    for rtol in (1e-1, 1e-2, 3e-3, 1e-3, 1e-4):
        level, extrapolate = plan_for_rtol(rtol)
        model = extrapolated_error(level) if extrapolate else modelled_error(level)
        assert model <= DISCRETISATION_SHARE * rtol
        assert level <= level_for_rtol(rtol)
    assert plan_for_rtol(1e-3) == (1.5, True)    # the default: levels 0.5 and 1.5
    assert plan_for_rtol(1e-2) == (0.5, False)


def test_root_tolerance_takes_what_the_plan_leaves_of_rtol():
    for rtol in (3e-2, 1e-2, 5e-3, 3e-3, 1e-3, 3e-4, 1e-4):
        level, extrapolate = plan_for_rtol(rtol)
        width = melt_width_for_rtol(rtol, level)
        x_tol = root_tolerance(rtol, level, extrapolate, width)
        discretisation = extrapolated_error(level) if extrapolate else modelled_error(level)
        melt = MELT_WIDTH_BIAS_PER_K * width if width > melt_width_floor(level) else 0.0
        assert x_tol >= ROOT_SHARE * rtol
        # The three modelled errors add up to rtol, never more.
        assert discretisation + melt + x_tol <= rtol * (1 + 1e-12)
    # A forced level coarser than rtol asks for still leaves the root finder its share.
    assert root_tolerance(1e-4, 0.0, False, 2.0) == pytest.approx(ROOT_SHARE * 1e-4)


@pytest.mark.parametrize("name", ["paper-quartz", "paper-alumina-rough"])
def test_richardson_value_within_its_error_estimate_of_a_finer_level(name):
    # The default (rtol 1e-3) extrapolates levels 0.5 and 1.5. Against a plain level-3
    # search (modelled error 1.9e-4, measured <= 1.7e-4 in the refinement study), it must
    # agree within the sum of both error estimates; and the extrapolation must be a real
    # correction (the finer level alone is off by ~1e-3).
    scene = get_preset(name)
    res = critical_height(scene, rtol=1e-3)
    assert res.extrapolated and res.level == 1.5
    reference = critical_height(scene, level=3.0, rtol=1e-5)
    assert not reference.extrapolated
    bound = res.error_estimate + reference.error_estimate
    assert abs(res.critical_height / reference.critical_height - 1) < bound
    assert 3e-4 < abs(res.richardson_correction) < 3e-3


def test_fast_tier_is_offered_and_close_to_the_full_model():
    # tier="fast" dispatches to skidmc.fast (no PDE run). Its measured error against the full
    # model on the report presets is <= 3 % (results/benchmarks/fast_tier.md); allow 6 %
    # (that plus the full model's 1 % at rtol 1e-2, doubled for other machines' rounding).
    scene = get_preset("paper-quartz")
    fast = critical_height(scene, tier="fast")
    full = critical_height(scene, rtol=1e-2)
    assert fast.method == "fast" and fast.evaluations == 0
    assert fast.critical_height == pytest.approx(full.critical_height, rel=0.06)


def test_fast_tier_carries_the_full_tiers_validity_flags():
    # phi = 1 deg: sliding stops at 0.21 t_c ("stops_early") and the height found indents the
    # billet past 0.1 D ("crushed"); the fast tier must say so as the full tier does.
    scene = make_scene(preset="paper-quartz", angle=1.0)
    fast = critical_height(scene, tier="fast", h_min=0.01, h_max=1000.0)
    full = critical_height(scene, rtol=1e-2, h_min=0.01, h_max=1000.0)
    assert {"stops_sliding", "stops_early"} <= set(fast.flags)
    assert set(fast.flags) == set(full.flags)


@pytest.mark.parametrize("kwargs, key", [
    ({"tier": "fastest"}, "tier"),
    ({"rtol": -1.0}, "rtol"),
    ({"h_min": 10.0, "h_max": 1.0}, "h_min"),
    ({"method": "newton"}, "method"),
])
def test_bad_solver_options_name_the_key(kwargs, key):
    with pytest.raises(SceneError) as err:
        critical_height(get_preset("paper-quartz"), **kwargs)
    assert err.value.key == key


def test_result_json_fields():
    d = critical_height(get_preset("paper-quartz"), rtol=FAST).to_dict()
    for key in ("critical_height_m", "critical_height_ft", "censored", "evaluations"):
        assert key in d
    assert d["critical_height_ft"] == pytest.approx(d["critical_height_m"] / FT)
    assert math.isfinite(d["error_estimate"])


def _kinked_margin(root, go_slope=-1.3, bend=0.2, nogo_slope=-0.9):
    """A margin shaped like the measured one: smooth, slightly bent go side (m <= 0 above the
    root), a different slope and a kink on the no-go side; counts its evaluations."""
    calls = []

    def margin(x):
        calls.append(x)
        d = x - root
        return go_slope * d + bend * d * d if d >= 0.0 else nogo_slope * d - 2.0 * d * d

    return margin, calls


@pytest.mark.parametrize("guess_offset", [-0.08, -0.02, 0.0, 0.01, 0.05])
@pytest.mark.parametrize("slope", [None, -1.25])
def test_go_side_root_lands_within_tolerance_from_either_side(guess_offset, slope):
    from skidmc.solver.roots import go_side_root as _go_side_root

    root, x_tol = 0.3, 1.2e-4
    margin, calls = _kinked_margin(root)
    x = _go_side_root(margin, root + guess_offset, slope, x_tol, -10.0, 10.0,
                      guess_error=0.02)
    assert x is not None
    assert abs(x - root) < x_tol
    assert len(calls) <= 6


def test_go_side_root_from_a_close_guess_takes_two_simulations():
    from skidmc.solver.roots import go_side_root as _go_side_root

    # A coarse level's root 0.4 % low with its go-side slope: what a Richardson pair's fine
    # search sees. The first point lands 0.2 % above the root, the second within 4 x_tol.
    root, x_tol = -1.0, 1.2e-4
    margin, calls = _kinked_margin(root)
    x = _go_side_root(margin, root - 0.004, -1.32, x_tol, -10.0, 10.0, guess_error=0.006)
    assert abs(x - root) < x_tol
    assert len(calls) == 2


@pytest.mark.parametrize("slope_error", [-CARRIED_GO_SLOPE_ERROR, 0.0, CARRIED_GO_SLOPE_ERROR])
def test_go_side_root_accepts_one_go_point_along_a_carried_slope(slope_error):
    from skidmc.solver.roots import go_side_root as _go_side_root

    # A coarse level's slope off by up to its bound, the first point 0.1 % above the root:
    # the extrapolation error (<= 0.15 * 1e-3) is below x_tol / 2, so one simulation does.
    root, x_tol = -1.0, 4e-4
    margin, calls = _kinked_margin(root)
    x = _go_side_root(margin, root - 0.002, -1.3 * (1 + slope_error), x_tol, -10.0, 10.0,
                      guess_error=0.003)
    assert len(calls) == 1
    assert abs(x - root) < 0.5 * x_tol
    # With no slope carried over (the default slope, 30 % uncertain), one point is not enough.
    margin, calls = _kinked_margin(root)
    x = _go_side_root(margin, root - 0.002, None, x_tol, -10.0, 10.0, guess_error=0.003)
    assert len(calls) >= 2 and abs(x - root) < x_tol


def test_go_side_root_gives_up_on_a_margin_that_is_not_monotone():
    from skidmc.solver.roots import go_side_root as _go_side_root

    # Positive everywhere but the search's own first point: no root near the guess.
    assert _go_side_root(lambda x: 1.0 + 0.0 * x, 0.0, None, 1e-4, -10.0, 10.0,
                         guess_error=0.02) is None


@pytest.mark.parametrize("name", ["paper-quartz", "paper-alumina-rough"])
def test_go_side_search_agrees_with_bisection_on_the_same_mesh(name):
    # Same model (level 0.5), two root finders: they must agree within their tolerances
    # (x_tol = 0.2 rtol on ln H each; bisection ends inside a bracket of x_tol). From the fast
    # tier's guess (0.1-0.3 % off on these presets) the go-side search needs 3-5 simulations:
    # whether its third lands within 4 x_tol of the root turns on the level's step noise (a
    # few 1e-4 in the margin; alumina-rough took 4 before its runs shared their linear start,
    # 5 after: docs/model.md, "Runs of one search share their linear start"). Bisection 10+.
    from skidmc.solver.model import build_model

    scene = get_preset(name)
    model = build_model(scene, level=0.5)
    rtol = 1e-3
    guess = critical_height(scene, tier="fast").critical_height
    go = critical_height(scene, rtol=rtol, model=model, h_guess=guess)
    bisect = critical_height(scene, rtol=rtol, model=model, method="bisection")
    assert abs(math.log(go.critical_height / bisect.critical_height)) < 0.4 * rtol
    assert go.evaluations <= 5 < bisect.evaluations


def _jump_margin(root, nogo=0.12, go_at_root=-0.28):
    """A margin shaped like a stops-sliding scene's (paper-gold, level 0): nearly flat and
    positive below the root, a jump of ~0.4 at it, and a go side that falls off as
    (x - root)^0.45; counts its evaluations."""
    calls = []

    def margin(x):
        calls.append(x)
        d = x - root
        return nogo - 0.5 * d if d < 0.0 else go_at_root - 1.5 * d ** 0.45

    return margin, calls


@pytest.mark.parametrize("offset_sigmas, most", [(-0.7, 9), (0.0, 8), (0.3, 8), (1.5, 10),
                                                 (-2.0, 12)])
def test_prior_bisection_finds_a_jump_in_about_log2_of_its_prior_over_the_bracket(
        offset_sigmas, most):
    from skidmc.solver.roots import prior_bisection_root

    # Halving the prior's mass reaches a bracket of 2 x_tol from a root within ~1 sigma of the
    # guess in about log2(4.13 sigma / (2 x_tol)) = 7 simulations (+1 for rounding, +1 for the
    # halving's unevenness at 0.7 sigma); a root 1.5-2 sigma off costs 2-4 more (the tail).
    sigma, x_tol, root = 0.02, 3e-4, 5.118
    margin, calls = _jump_margin(root)
    x = prior_bisection_root(margin, root - offset_sigmas * sigma, sigma, x_tol, -10.0, 10.0)
    assert abs(x - root) <= x_tol
    assert len(calls) <= most


def test_prior_bisection_steps_out_of_a_prior_that_is_far_off():
    from skidmc.solver.roots import prior_bisection_root

    # The root 10 sigma above the guess: 4 points halve the prior (z = 0 ... 1.53), 3 double
    # the distance (z = 3.1, 6.1, 12.3), then ln H is bisected from 6.1 sigma = 0.12 down to
    # 2 x_tol (8 halvings): 15, and 2 to spare for where the halvings fall.
    sigma, x_tol, root = 0.02, 3e-4, 0.2
    margin, calls = _jump_margin(root)
    x = prior_bisection_root(margin, root - 10 * sigma, sigma, x_tol, -10.0, 10.0)
    assert abs(x - root) <= x_tol
    assert len(calls) <= 17


def test_prior_bisection_hands_a_smooth_bracket_to_interpolation():
    from skidmc.solver.roots import prior_bisection_root

    # A margin that does not jump (the kinked rebound shape): once bracketed, the linear
    # interpolation of guided_root finishes in fewer simulations than bisection would.
    sigma, x_tol, root = 0.02, 1.2e-4, 0.3
    margin, calls = _kinked_margin(root)
    x = prior_bisection_root(margin, root + 0.01, sigma, x_tol, -10.0, 10.0)
    assert abs(x - root) <= x_tol
    assert len(calls) <= 6


def test_prior_bisection_continues_a_known_bracket_in_ln_h():
    from skidmc.solver.roots import prior_bisection_root

    # A re-search at a 4x tighter tolerance from its own bracket (2 x 1.2e-3 wide): two
    # halvings, no simulation outside the bracket.
    root, x_tol = 1.0, 3e-4
    margin, calls = _jump_margin(root)
    lo, hi = root - 0.0007, root + 0.0017
    points = [(lo, margin(lo)), (hi, margin(hi))]
    calls.clear()
    x = prior_bisection_root(margin, root + 0.0005, 0.0004, x_tol, -10.0, 10.0, points=points)
    assert abs(x - root) <= x_tol
    assert len(calls) == 2 and all(lo < c < hi for c in calls)
