"""The default search's corrections of its first Richardson pair (issue 16, second pass).

The root finder first gets the room the pair is likely not to use
(:func:`skidmc.solver.plan.pair_root_tolerance`); a root that then does not fit is tightened from
its own simulations; a melting width whose measured bias exceeds its share is narrowed
(docs/model.md, "Accuracy control").
"""

from __future__ import annotations

import math

import pytest
from test_extremes import _rate_at_ref

from skidmc.errors import SceneError
from skidmc.physics.thermal import MELT_SPREAD
from skidmc.scene import get_preset, make_scene
from skidmc.solver import critical_height
from skidmc.solver.model import MELT_WIDTH_BIAS_PER_K
from skidmc.solver.plan import (
    JUMP_COARSE_SHARE,
    MAX_ROOT_TOLERANCE,
    ROOT_SHARE,
    a_posteriori_error,
    first_pair_level,
    jump_root_tolerances,
    melt_width_for_rtol,
    pair_root_tolerance,
    predicted_correction,
)


@pytest.mark.parametrize("rtol", [3e-2, 1e-2, 5e-3, 3e-3, 1e-3, 1e-4])
def test_pair_root_tolerance_is_the_room_left_or_the_root_share(rtol):
    level = first_pair_level(rtol)
    x_tol = pair_root_tolerance(rtol, level, melt_width_for_rtol(rtol, level), MELT_SPREAD)
    assert x_tol >= ROOT_SHARE * rtol * (1 - 1e-12)
    assert x_tol <= max(MAX_ROOT_TOLERANCE, ROOT_SHARE * rtol)
    assert x_tol < rtol


@pytest.mark.parametrize(("spread", "exact"), [(0.0, False), (MELT_SPREAD, False),
                                               (MELT_SPREAD, True)])
@pytest.mark.parametrize("rtol", [3e-2, 1e-2, 3e-3, 1e-3, 1e-4])
def test_jump_root_tolerances_spend_the_room_split_as_measured(rtol, spread, exact):
    level = first_pair_level(rtol, exact, exact)
    width = melt_width_for_rtol(rtol, level)
    coarse, fine = jump_root_tolerances(rtol, level, width, spread, exact)
    predicted = (a_posteriori_error(predicted_correction(level, exact, exact), level - 1.0,
                                    spread, exact, exact)
                 + MELT_WIDTH_BIAS_PER_K * width)
    room = max(ROOT_SHARE * rtol, rtol - predicted)
    # The Richardson value's root error (4 fine + coarse) / 3 fills the room the pair is likely
    # to leave (at least ROOT_SHARE rtol) unless the widest bracket caps both; the coarse root
    # takes JUMP_COARSE_SHARE of the room (2:1, the split measured cheapest in cell-steps).
    assert max(coarse, fine) <= MAX_ROOT_TOLERANCE
    assert (4.0 * fine + coarse) / 3.0 <= room * (1 + 1e-12)
    if coarse < MAX_ROOT_TOLERANCE:
        assert coarse == pytest.approx(JUMP_COARSE_SHARE * room)
        assert coarse == pytest.approx(2.0 * fine)
        assert (4.0 * fine + coarse) / 3.0 == pytest.approx(room)


@pytest.mark.parametrize("signs", [False, True])
@pytest.mark.parametrize("rtol", [3e-2, 1e-2, 3e-3, 1e-3, 3e-4, 1e-4])
def test_the_exact_targets_first_pair_leaves_the_root_finder_its_share(rtol, signs):
    # The lowest level whose predicted estimate and melting bias leave ROOT_SHARE rtol to the
    # roots; the level below it would not (from RICHARDSON_MIN_LEVEL up).
    def predicted(level):
        return (a_posteriori_error(predicted_correction(level, True, signs), level - 1.0,
                                   MELT_SPREAD, True, signs)
                + MELT_WIDTH_BIAS_PER_K * melt_width_for_rtol(rtol, level))

    level = first_pair_level(rtol, True, signs)
    assert level >= 1.0 and (2.0 * level) % 1.0 == 0.0
    assert predicted(level) <= (1.0 - ROOT_SHARE) * rtol or level == 4.0
    if level > 1.0:
        assert predicted(level - 0.5) > (1.0 - ROOT_SHARE) * rtol
    assert {1e-2: 1.0, 3e-3: 1.0, 1e-3: 1.5}.get(rtol, level) == level


@pytest.mark.parametrize("correction", [0.0, 5e-5, 2e-4, 1e-3])
@pytest.mark.parametrize("coarse_level", [0.0, 0.5, 1.0, 1.5, 2.5])
def test_the_exact_targets_estimate(correction, coarse_level):
    # Steady rebounds: a multiple of the pair's own correction (0.75, or 1 from level 1.5 up).
    # Located by signs: twice the correction (the residual of any order >= 1 with errors of one
    # sign), never below the measured floor 4e-4 3^-(L - 1) where the correction cancels.
    steady = a_posteriori_error(-correction, coarse_level, MELT_SPREAD, True, False)
    assert steady == pytest.approx((0.75 if coarse_level < 1.5 else 1.0) * correction)
    signs = a_posteriori_error(-correction, coarse_level, MELT_SPREAD, True, True)
    assert signs == pytest.approx(max(2.0 * correction, 4e-4 * 3.0 ** -coarse_level))
    # The meshed target's estimate is unchanged by the new arguments' defaults.
    assert a_posteriori_error(correction, coarse_level, MELT_SPREAD) == a_posteriori_error(
        correction, coarse_level, MELT_SPREAD, False, True)


@pytest.mark.parametrize("rtol", [1e-2, 3e-3, 1e-3])
def test_stops_sliding_takes_at_most_twice_the_simulations_of_rebound(rtol):
    # Issue 16: paper-gold (sliding stops, the margin jumps at the root) against the two
    # rebound presets of the report's first series. Simulation counts are deterministic.
    gold = critical_height(get_preset("paper-gold"), rtol=rtol)
    rebound = [critical_height(get_preset(name), rtol=rtol).evaluations
               for name in ("paper-quartz", "paper-alumina-smooth")]
    assert gold.exit_kind == "stops_sliding"
    assert gold.error_estimate <= rtol
    assert gold.evaluations <= 2 * max(rebound)


def test_the_studies_rtol_gets_a_looser_root():
    # rtol 1e-2 (the shipped studies): the pair (0, 1) is likely to use ~2.5e-3 of it.
    assert pair_root_tolerance(1e-2, 1.0, 4.0, MELT_SPREAD) == pytest.approx(MAX_ROOT_TOLERANCE)


def test_a_tightened_root_reuses_its_simulations(monkeypatch):
    # A paper-series2 sample (rounded) whose first pair at rtol 1e-3 leaves too much room to its
    # fine root: the search machine tightens it (stage _S_TIGHTEN_F), from its own root and
    # simulations. Every run the CPU search makes is recorded: no height is simulated twice
    # with the same model in full (a run stopped at the exit may be redone in full for Brent).
    from skidmc.solver import adaptive, search

    scene = get_preset("paper2-quartz").replace(
        mu=0.0622, flow_stress=2.328e8, billet_mass=11.18, initial_temperature=295.26,
        he_heat_capacity=988.07, he_conductivity=0.3539, target_conductivity=1.4456,
        kinetics_prefactor=3.6992e10, kinetics_activation_temperature=16036.4,
        kinetics_heat_of_reaction=7.4065e6, target_density=2220.0, target_heat_capacity=745.0)
    runs, stages = [], []
    simulate, asked = search.simulate, adaptive.asked

    def recording_simulate(model, height, **kw):
        runs.append((id(model), height, kw.get("until_exit", False)))
        return simulate(model, height, **kw)

    def recording_asked(ps):
        stages.append(int(ps[0]["stage"]))
        return asked(ps)

    monkeypatch.setattr(search, "simulate", recording_simulate)
    monkeypatch.setattr(adaptive, "asked", recording_asked)
    res = critical_height(scene, rtol=1e-3)
    assert adaptive._S_TIGHTEN_F in stages      # a root was tightened
    full = [(m, h) for m, h, until_exit in runs if not until_exit]
    assert len(full) == len(set(full))          # never the same run twice
    assert res.evaluations <= len(runs)
    assert len(res.history) == len({h for h, _ in res.history})
    assert res.error_estimate <= 1e-3


def test_a_finder_that_gives_up_inside_a_bracket_hands_it_to_brent(monkeypatch):
    # The runs answer from a margin of our own (the machine reads a run's margin and event
    # only): roots r_L = r + 1e-3 (34 / cells)^2 [ln H] at each level; at the coarse level a go
    # side twice as steep as the finder's default slope (-2.5 against -1.25) and no event at all
    # (margin inf) more than 0.01 below the root. From its first go run 0.1 above the root the
    # go-side finder extrapolates along the default slope to 0.04 below it, gets no event there
    # and gives up, holding the bracket those two runs make. Brent's method must start on that
    # bracket: before (issue 45), it bracketed again from the guess, outside it. No run of a
    # model may fall outside the tightest bracket its earlier full runs hold.
    from types import SimpleNamespace

    from skidmc.solver import search

    runs, root = [], []

    def margin(cells, x):
        d = x - (root[0] + 1e-3 * (34 / cells) ** 2)
        if cells > 34:
            return -1.2 * d if d >= 0.0 else -0.8 * d
        if d < -0.01:
            return math.inf
        return -2.5 * d if d >= 0.0 else -1.5 * d

    def fake_simulate(model, height, **kw):
        x = math.log(height)
        if not root:
            root.append(x - 0.1)   # the first coarse run lands 0.1 above the coarse root
        m = margin(len(model.width), x)
        runs.append((len(model.width), height, m))
        return SimpleNamespace(margin=m, event=math.isfinite(m))

    monkeypatch.setattr(search, "simulate", fake_simulate)
    res = critical_height(get_preset("paper-quartz"), rtol=1e-3)
    outside = []
    for i, (cells, height, _) in enumerate(runs):
        before = [(h, m) for c, h, m in runs[:i] if c == cells]
        lo = max((h for h, m in before if m > 0.0), default=0.0)
        hi = min((h for h, m in before if m <= 0.0), default=math.inf)
        if lo < hi and not lo < height < hi:
            outside.append((i, height, lo, hi))
    assert not outside, outside
    coarse = [(h, m) for c, h, m in runs if c == 34]
    # The finder's two runs, the second without an event, then Brent's inside their bracket.
    assert coarse[0][1] < 0.0 and coarse[1][1] == math.inf
    assert coarse[1][0] < min(h for h, _ in coarse[2:]) <= max(h for h, _ in coarse[2:]) \
        < coarse[0][0]
    # And the search ends on the fine level's root, within its error estimate.
    fine_root = math.exp(root[0] + 1e-3 * (34 / 68) ** 2)
    assert abs(math.log(res.critical_height / fine_root)) <= res.error_estimate


def test_a_melting_bias_above_its_share_narrows_the_width():
    # E/R = 15,000 K with the rate at 575 K kept (as paper-series1 samples it): ignition starts
    # below the melting point and the 3 K width of rtol 3e-3 biases the height by ~6e-3. The
    # first pass of issue 16 returned it 6.4e-3 off (estimate 1.1e-2); narrowing the width
    # brings the height within rtol of a tight solve (measured 2.7e-3, estimate still above
    # rtol: the bias measured at the coarse level stays conservative).
    scene = make_scene(preset="paper-quartz", **{
        "kinetics.activation_temperature": 15000.0,
        "kinetics.prefactor": _rate_at_ref(15000.0, 575.0)})
    res = critical_height(scene, rtol=3e-3)
    ref = critical_height(scene, rtol=3e-4)
    assert abs(res.critical_height / ref.critical_height - 1.0) <= 3e-3 + ref.error_estimate
    assert abs(res.critical_height / ref.critical_height - 1.0) <= res.error_estimate


def test_the_default_search_models_the_target_as_the_exact_solid():
    # The default (adaptive) search uses target="exact"; a fixed plan keeps the meshed target
    # its calibrated level model was fitted on. Both are deterministic, so equality is exact.
    scene = get_preset("paper-gold")
    default = critical_height(scene, rtol=3e-3)
    assert default.critical_height == critical_height(scene, rtol=3e-3,
                                                      target="exact").critical_height
    meshed = critical_height(scene, rtol=3e-3, target="mesh")
    assert meshed.critical_height != default.critical_height
    # The two agree within their estimates (both bound their distance to the converged model).
    assert abs(meshed.critical_height / default.critical_height - 1.0) <= (
        meshed.error_estimate + default.error_estimate)
    fixed = critical_height(scene, level=1.0)
    assert fixed.critical_height == critical_height(scene, level=1.0,
                                                    target="mesh").critical_height


@pytest.mark.parametrize("bad", ["meshed", "Exact", 1])
def test_target_is_validated(bad):
    with pytest.raises(SceneError, match="target"):
        critical_height(get_preset("paper-quartz"), target=bad)


def test_the_fixed_plans_run_on_the_machine_with_the_levels_they_name(monkeypatch):
    # A forced level, extrapolate=False and a given model are plans of the same machine
    # (adaptive.PLAN_PAIR, PLAN_SINGLE): the runs it asks for are at the levels the plan names
    # (the root two levels down first where no guess is given), every run of a given model is
    # that model's (no coarse start, no fast tier), and the simulations counted are those made.
    from skidmc.solver import adaptive, search
    from skidmc.solver.model import build_model

    scene = get_preset("paper-quartz")
    runs, levels = [], []
    simulate, asked = search.simulate, adaptive.asked

    def recording_simulate(model, height, **kw):
        runs.append(model)
        return simulate(model, height, **kw)

    def recording_asked(ps):
        out = asked(ps)
        levels.append(out[0])
        return out

    monkeypatch.setattr(search, "simulate", recording_simulate)
    monkeypatch.setattr(adaptive, "asked", recording_asked)
    cases = [({"level": 1.0}, {1.0}, False), ({"level": 2.0}, {0.0, 2.0}, False),
             ({"level": 1.5, "extrapolate": True}, {0.5, 1.5}, True),
             ({"level": 3.0, "extrapolate": True}, {0.0, 2.0, 3.0}, True)]
    for kwargs, named, extrapolated in cases:
        runs.clear()
        levels.clear()
        res = critical_height(scene, rtol=1e-2, **kwargs)
        assert set(levels) == named, kwargs
        assert res.evaluations == len(runs) and res.level == kwargs["level"]
        assert res.extrapolated is extrapolated and res.melt_bias_estimate == 0.0
    given = build_model(scene, level=2.0)
    runs.clear()
    res = critical_height(scene, rtol=1e-2, model=given)
    assert runs and all(m is given for m in runs)
    assert res.evaluations == len(runs) and res.extrapolated is False
