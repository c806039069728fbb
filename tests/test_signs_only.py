"""Searches by signs stop no-go simulations at the exit (simulate's ``until_exit``) and must
change nothing but the cost: the same signs, the same go margins, the same heights.

They apply where the root is located by the margin's signs: sliding stops before rebound
(paper-gold), or a rebound whose heating fades before the exit (an off-preset scene)."""

import math
import sys

import pytest

from skidmc.physics.thermal import SIGN_COMMIT_FRACTION, simulate_kernel
from skidmc.scene import get_preset
from skidmc.scene.validation import off_preset_scenes
from skidmc.solver import build_model, critical_height, simulate
from skidmc.solver.options import exit_regime
from skidmc.solver.roots import margin_slope
from skidmc.solver.simulate import kernel_arguments

# The module, not the function the package re-exports under the same name.
search_module = sys.modules["skidmc.solver.search"]


@pytest.fixture(scope="module")
def gold():
    """paper-gold: sliding stops before rebound, so its margin jumps at the root."""
    scene = get_preset("paper-gold")
    root = critical_height(scene, rtol=1e-2)
    model = build_model(scene, level=0.5, melt_width=4.0, melt_spread=1.0)
    return scene, root.critical_height, model


def test_stopping_at_the_exit_keeps_the_run_up_to_it(gold):
    _, h_c, model = gold
    for factor in (1.01, 1.03):          # go side: the event comes before the exit
        full = simulate(model, factor * h_c)
        # The commit rule off (next test).
        info = simulate_kernel(*kernel_arguments(model, factor * h_c, until_exit=True,
                                                 sign_commit_fraction=0.0))[0]
        assert full.event and info["event"]
        # The same steps up to the event, so the same event time to the last bit.
        assert info["t_event"] == full.event_time
        assert info["steps"] == full.steps
        assert info["newton_iterations"] == full.newton_iterations
    for factor in (0.97, 0.99):          # no-go side: no event by the exit
        full = simulate(model, factor * h_c)
        short = simulate(model, factor * h_c, until_exit=True)
        assert full.margin > 0.0 and not full.event
        assert short.margin == math.inf and not short.event
        # The full run goes on to its event under the extension flux, ~1.1 t_exit.
        assert short.steps < full.steps
        # Its cost in the kernel's own count: at least one Newton iteration per step attempt.
        assert short.steps + short.rejected <= short.newton_iterations < full.newton_iterations


def test_a_sign_only_go_run_ends_at_the_commit_temperature(gold):
    # A sign-only go run is declared once its hottest cell passes the commit temperature
    # (adiabatic induction time SIGN_COMMIT_FRACTION t_exit) while heating fast, instead of at
    # the runaway temperature (DEFAULT_RUNAWAY_FRACTION): the same sign, in fewer steps.
    _, h_c, model = gold
    for factor in (1.001, 1.01, 1.03):
        full = simulate(model, factor * h_c)
        short = simulate(model, factor * h_c, until_exit=True)
        assert full.event and short.event
        # Measured 10-25 % fewer Newton iterations on these runs (results/validation/
        # sign_commit.md: 8-13 % of the attempts on average over 34,000 go runs).
        assert short.newton_iterations < 0.95 * full.newton_iterations
        # Its margin is the commit crossing plus the adiabatic induction time there: the
        # conduction losses between the two temperatures make the true event later, by
        # 3.2e-4 in the margin at 1.01 H_c here; 2e-3 is a sixth of the commit's own
        # fraction-to-event window and far below the jump's 0.3.
        assert short.margin <= full.margin
        assert short.margin == pytest.approx(full.margin, abs=2e-3)


@pytest.mark.parametrize("fraction", [SIGN_COMMIT_FRACTION, 3e-2])
def test_the_commit_rule_needs_its_fraction_below_the_fold(fraction):
    # No-go runs just below a jump's root peak at the fold and cool, their adiabatic induction
    # time there at least 8.6e-4 of the exit time, median 4.6e-3
    # (results/validation/sign_commit.md). A commit fraction far above that (3e-2) declares
    # them a go, heating guard and all, on this scene (and on every stops-sliding scene of
    # benchmarks/solver.py): the check can fail. SIGN_COMMIT_FRACTION stays below every peak
    # the sweep saw.
    scene = dict(off_preset_scenes())["alumina-vertical-1"]
    model = build_model(scene, level=0.5, melt_width=4.0, melt_spread=1.0, target="exact")
    h_c = critical_height(scene, rtol=1e-5, model=model).critical_height
    flipped = 0
    for factor in (0.9999, 0.999, 0.995, 0.99):
        info = simulate_kernel(*kernel_arguments(model, factor * h_c, until_exit=True,
                                                 sign_commit_fraction=fraction))[0]
        flipped += bool(info["event"]) and info["t_event"] <= model.exit_time
    if fraction == SIGN_COMMIT_FRACTION:
        assert flipped == 0
    else:
        assert flipped > 0


def _fading_scene():
    """alumina-vertical-1 of the off-preset box: a rebound whose sliding speed at the exit is
    below FADING_EXIT_SPEED of the initial one; its margin jumps at the root at levels 0.5 and
    1.5 (slopes of -600 to -900 across the brackets of full runs)."""
    scene = dict(off_preset_scenes())["alumina-vertical-1"]
    assert exit_regime(scene) == "fading"
    return scene


@pytest.mark.parametrize("which", ["stops_sliding", "fading"])
def test_signs_only_search_finds_the_full_runs_height(gold, monkeypatch, which):
    scene = gold[0] if which == "stops_sliding" else _fading_scene()
    stopped_at_exit = []

    def recording_simulate(model, height, **kwargs):
        if kwargs.get("until_exit"):
            stopped_at_exit.append(model.exit_kind)
        return simulate(model, height, **kwargs)

    monkeypatch.setattr(search_module, "simulate", recording_simulate)
    fast = critical_height(scene, rtol=3e-3)
    # The search located the root by signs, stopping runs at the exit (a rebound's too).
    expected_kind = "rebound" if which == "fading" else "stops_sliding"
    assert stopped_at_exit and set(stopped_at_exit) == {expected_kind}
    full_runs = []

    def full_simulate(model, height, **kwargs):
        kwargs.pop("until_exit", None)
        full_runs.append(height)
        return simulate(model, height, **kwargs)

    monkeypatch.setattr(search_module, "simulate", full_simulate)
    slow = critical_height(scene, rtol=3e-3)
    assert full_runs, "the search did not go through the patched simulate"
    # The same signs lead the bisection to the same brackets: the same height, bit for bit.
    assert fast.critical_height == slow.critical_height
    assert fast.evaluations == slow.evaluations
    assert fast.error_estimate == slow.error_estimate


def test_a_no_event_point_next_to_a_go_point_reads_as_a_jump():
    # A sign-only search's history: its closest no-go point has no event (margin inf). The
    # next level's search must treat the margin as jumping (steeper than JUMP_SLOPE) and
    # locate its root by signs as well, not extrapolate along a go side it cannot trust.
    assert margin_slope([(1.00, math.inf), (1.01, -0.02), (1.03, -0.05)]) == -math.inf
    # Full runs: the secant across the sign change, the no-event point further out ignored.
    slope = margin_slope([(0.98, math.inf), (1.00, 0.01), (1.01, -0.02)])
    assert slope == pytest.approx(-0.03 / math.log(1.01))
    assert margin_slope([(1.00, math.inf), (1.01, math.inf)]) is None
