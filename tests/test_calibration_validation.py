"""Validation of the calibration's inference (issue 40 E), slow: simulation-based calibration
over 100 replications and recovery from synthetic drop sets of the report's size and ten times
that. The forward model is the calibration's own likelihood with surrogates fitted to the
shipped paper-series1 ensemble standing in for the solver (scripts/calibration_validation.py,
which writes the full version to results/validation/calibration_sbc.md)."""

from __future__ import annotations

import sys

import numpy as np
import pytest
from conftest import ROOT

sys.path.insert(0, str(ROOT / "scripts"))

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def model():
    from calibration_validation import sbc_model

    if not (ROOT / "results" / "paper-series1" / "ensemble.h5").is_file():
        pytest.skip("needs the shipped paper-series1 ensemble (skidmc run studies/"
                    "paper-series1.toml)")
    return sbc_model(nodes=8)


def test_sbc_ranks_are_uniform(model):
    # 100 replications (the minimum), the script's settings (36 walkers, 300 + 600
    # steps, 8 nodes): ranks among 99 draws, whole ensembles at 3 steps 200 apart (the
    # default pick, analysis.calibration.SBC_PICKS). The pooled chi-square
    # (17 parameters x 9 dof) falls below p = 1e-3 once in a thousand runs of a correct
    # sampler and likelihood (seed fixed: deterministic). What it catches: a posterior too
    # narrow or too wide for the data (a likelihood counted twice, a chain not mixed) piles the
    # truths' ranks at the ends or the middle. (It cannot catch a likelihood that ignores the
    # data: the posterior is then the prior, and the ranks are uniform.)
    from skidmc.analysis.calibration import rank_uniformity, sbc_ranks

    # seed 2018: the script's run, pooled p = 0.282 on the tabled paper-series1 ensemble
    # (results/validation/calibration_sbc.md; 0.087 on the ensemble before, 0.012 before the
    # snooker move was corrected and the draws separated)
    ranks = sbc_ranks(model, 100, draws=99, walkers=36, burn=300, steps=600, seed=2018)
    test = rank_uniformity(ranks, 99, bins=10)
    assert test["pooled"][2] > 1e-3, test


def test_recovery_narrows_with_ten_times_the_drops(model):
    # One known parameter set (a prior draw), the report's drop heights centred on each
    # target's true H50, as many drops as the report and ten times as many. Each target's ln H50
    # posterior must narrow, and on average over the targets to below 0.7 of its 1x sd
    # (measured sd ratios 10x/1x: 0.20, 0.58, 0.55, 0.83 for gold, alumina-smooth,
    # alumina-rough, quartz here; 0.16, 0.21, 0.37, 0.70 in the script's run: less than the
    # 1/sqrt(10) = 0.32 of independent data, as the discrepancy and the friction's drop-to-drop
    # spread do not shrink with more drops), and hold the truth within its 95 % interval at 10x
    # for at least three of the four targets (four 95 % intervals miss twice or more with
    # probability 1.4 %; seeds fixed, so deterministic). At 1x the script's run missed one of
    # four (results/validation/calibration_sbc.md): reported there, not asserted here.
    from skidmc.analysis.calibration import recovery

    z_true = np.random.default_rng(11).standard_normal(model.ndim)
    rows = recovery(model, z_true, repeats=(1, 10), walkers=36, burn=600, steps=1800, seed=5)
    one, ten = rows[0]["targets"], rows[1]["targets"]
    ratios = [ten[name]["sd"] / one[name]["sd"] for name in one]
    assert max(ratios) < 1 and np.mean(ratios) < 0.7, ratios
    assert sum(t["inside_95"] for t in ten.values()) >= 3, ten
