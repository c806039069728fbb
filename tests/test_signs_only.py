"""Searches by signs stop no-go simulations at the exit (simulate's ``until_exit``) and must
change nothing but the cost: the same signs, the same go margins, the same heights."""

import math
import sys

import pytest

from skidmc.scene import get_preset
from skidmc.solver import build_model, critical_height, simulate

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
        short = simulate(model, factor * h_c, until_exit=True)
        assert full.event and short.event
        # The same steps up to the event, so the same margin to the last bit.
        assert short.margin == full.margin
        assert short.steps == full.steps
    for factor in (0.97, 0.99):          # no-go side: no event by the exit
        full = simulate(model, factor * h_c)
        short = simulate(model, factor * h_c, until_exit=True)
        assert full.margin > 0.0 and not full.event
        assert short.margin == math.inf and not short.event
        # The full run goes on to its event under the extension flux, ~1.1 t_exit.
        assert short.steps < full.steps


def test_signs_only_search_finds_the_full_runs_height(gold, monkeypatch):
    scene, _, _ = gold
    fast = critical_height(scene, rtol=3e-3)
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
