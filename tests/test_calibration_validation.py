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
    # steps, 8 nodes): ranks among 99 draws spread over the chain. The pooled chi-square
    # (17 parameters x 9 dof) falls below p = 1e-3 once in a thousand runs of a correct
    # sampler and likelihood (seed fixed: deterministic). What it catches: a posterior too
    # narrow or too wide for the data (a likelihood counted twice, a chain not mixed) piles the
    # truths' ranks at the ends or the middle. (It cannot catch a likelihood that ignores the
    # data: the posterior is then the prior, and the ranks are uniform.)
    from skidmc.analysis.calibration import rank_uniformity, sbc_ranks

    ranks = sbc_ranks(model, 100, draws=99, walkers=36, burn=300, steps=600, seed=7)
    test = rank_uniformity(ranks, 99, bins=10)
    assert test["pooled"][2] > 1e-3, test


def test_recovery_narrows_with_ten_times_the_drops(model):
    # One known parameter set (a prior draw), drops at the report's heights and ten times as
    # many. Each target's ln H50 posterior must narrow (sd at 10x below 0.8 of 1x where the
    # drops bracket it: quartz and the alumina finishes; the gold no-gos lie far below its H50
    # and say little either way) and hold the truth within its 95 % interval at both sizes for
    # at least three of the four targets (four 95 % intervals miss twice or more with
    # probability 1.4 %; the seed is fixed, so the test is deterministic).
    from skidmc.analysis.calibration import recovery

    z_true = np.random.default_rng(11).standard_normal(model.ndim)
    rows = recovery(model, z_true, repeats=(1, 10), walkers=40, burn=600, steps=1500, seed=5)
    one, ten = rows[0]["targets"], rows[1]["targets"]
    for name in ("quartz", "alumina-smooth", "alumina-rough"):
        assert ten[name]["sd"] < 0.8 * one[name]["sd"], (name, one[name], ten[name])
    for row in rows:
        assert sum(t["inside_95"] for t in row["targets"].values()) >= 3, row["targets"]
