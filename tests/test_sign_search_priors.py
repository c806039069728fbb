"""``scripts/sign_search_priors.py``: its emulated finder replays a search's runs exactly.

The script's finding (results/validation/sign_search_priors.md: how many runs other priors
would have cost) rests on one property: the compiled prior finder, answered by a measured
root's signs alone, places the runs the search placed. Checked here on a stops-sliding study
scene (held out from the script's training draws: seed 104) whose coarse and fine searches
locate their roots by signs.
"""

from __future__ import annotations

import math
import sys

import pytest
from conftest import ROOT
from test_refine_prior import _scene

sys.path.insert(0, str(ROOT / "scripts"))
from sign_search_priors import emulated_runs, measure  # noqa: E402

from skidmc.solver.adaptive import FAST_STOPS_SLIDING_SPREAD, REGIME_STOPS_SLIDING  # noqa: E402


@pytest.mark.parametrize("rtol", [1e-3, 1e-2])
def test_the_emulated_finder_takes_the_searchs_own_runs(rtol):
    rows = measure(_scene("sobol-series1[41012]"), rtol)
    stages = sorted(r["stage"] for r in rows)
    assert stages == ["coarse", "fine"], stages
    for r in rows:
        if r["stage"] == "coarse":
            assert r["from_fast"] == 1 and r["regime"] == REGIME_STOPS_SLIDING
            centre, sigma = 0.0, FAST_STOPS_SLIDING_SPREAD
        else:
            centre, sigma = 0.5 * r["overshoot"], r["sigma"]
        # The measured root (by signs to 1e-7) lies where the search's own bracket put it:
        # replaying the finder against it must ask the same number of runs.
        assert emulated_runs(r["d"], centre, sigma, r["x_tol"]) == r["runs"], r


def test_a_root_far_out_in_the_prior_costs_runs_that_creep():
    # The finder's run count grows with the root's distance from the prior's centre in
    # spreads: the reason a too-narrow prior costs runs (the script's question).
    x_tol, sigma = 3e-4, 1e-3
    near = emulated_runs(0.2 * sigma, 0.0, sigma, x_tol)
    far = emulated_runs(3.0 * sigma, 0.0, sigma, x_tol)
    assert near <= 3 < far
    with pytest.raises(RuntimeError, match="missed the root"):
        emulated_runs(math.nan, 0.0, sigma, x_tol)
