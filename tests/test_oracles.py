"""skidmc against peer implementations (OpenTURNS, statsmodels) on published benchmark problems.

Optional: OpenTURNS is in the ``oracle`` extra (``pip install skidmc[oracle]``); without it these
tests are skipped. Every reference is recomputed here independently of both codes:

* 10-d linear limit state g = beta sqrt(10) - sum(u): pf = Phi(-beta) exactly;
* the curved state g = x1 x2 - 146.14, x1 ~ N(78064, 11710), x2 ~ N(0.0104, 0.00156) (a product
  of normals; its design point in U space, where the hyperbola (1 + a u1)(1 + a u2) = c with
  a = 0.15 is nearest the origin, is u1 = u2 = (sqrt(c) - 1)/a);
* Sobol's G-function (8 inputs, a = 0, 1, 4.5, 9, 99, 99, 99, 99; Saltelli et al. 2010,
  "Variance based sensitivity analysis of model output", Comput. Phys. Commun. 181:259): the
  estimators are compared on one and the same design, so they must agree to round-off up to
  the variance normalisation;
* a probit fit: Fieller's interval recomputed from statsmodels' Probit covariance.

All are marked slow (about a minute together).
"""

from __future__ import annotations

import math
import warnings

import numpy as np
import pytest
from scipy import stats

from skidmc.analysis.gonogo import fit_probit
from skidmc.analysis.rare_events import rare_event_probability
from skidmc.analysis.sensitivity import sobol_indices

ot = pytest.importorskip("openturns")

pytestmark = pytest.mark.slow


def _ot_linear_event(beta: float, d: int = 10):
    inputs = [f"x{i}" for i in range(d)]
    formula = f"{beta * math.sqrt(d)} - (" + " + ".join(inputs) + ")"
    g = ot.SymbolicFunction(inputs, [formula])
    vector = ot.CompositeRandomVector(g, ot.RandomVector(ot.JointDistribution([ot.Normal()] * d)))
    return ot.ThresholdEvent(vector, ot.LessOrEqual(), 0.0)


def test_subset_simulation_bias_against_openturns_on_the_linear_state():
    # pf = 1e-5 (beta = 4.2649), N = 1000 per level, p0 = 0.1, single runs, 100 seeds each.
    beta, runs = 4.264891, 100
    exact = stats.norm.sf(beta)
    ours, theirs = [], []
    for seed in range(runs):
        result = rare_event_probability(
            lambda x: beta * math.sqrt(10) - x.sum(axis=1), [stats.norm()] * 10, "subset",
            target_cov=100.0, seed=70_000 + seed,
        )
        ours.append(result.probability / exact)
        ot.RandomGenerator.SetSeed(70_000 + seed)
        algo = ot.SubsetSampling(_ot_linear_event(beta))
        algo.setMaximumOuterSampling(1000)
        algo.setConditionalProbability(0.1)
        algo.run()
        theirs.append(algo.getResult().getProbabilityEstimate() / exact)
    ours, theirs = np.array(ours), np.array(theirs)
    se_ours = ours.std(ddof=1) / math.sqrt(runs)
    print(f"skidmc {ours.mean() - 1:+.3f} +- {se_ours:.3f}, OpenTURNS "
          f"{theirs.mean() - 1:+.3f} +- {theirs.std(ddof=1) / math.sqrt(runs):.3f}")
    # unbiased to within three standard errors of the mean (about +-10 % here)
    assert abs(ours.mean() - 1.0) < 3.0 * se_ours
    # and as precise as the peer: the spreads of single runs agree within 30 %
    assert ours.std() == pytest.approx(theirs.std(), rel=0.3)


def test_form_design_point_against_openturns_on_the_curved_state():
    marginals = [stats.norm(78064.0, 11710.0), stats.norm(0.0104, 0.00156)]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        ours = rare_event_probability(lambda x: x[:, 0] * x[:, 1] - 146.14, marginals,
                                      "form-is", seed=1)
    g = ot.SymbolicFunction(["x1", "x2"], ["x1 * x2 - 146.14"])
    distribution = ot.JointDistribution([ot.Normal(78064.0, 11710.0), ot.Normal(0.0104, 0.00156)])
    vector = ot.CompositeRandomVector(g, ot.RandomVector(distribution))
    event = ot.ThresholdEvent(vector, ot.LessOrEqual(), 0.0)
    solver = ot.AbdoRackwitz()
    solver.setMaximumIterationNumber(1000)
    form = ot.FORM(solver, event, distribution.getMean())
    form.run()
    theirs = form.getResult().getHasoferReliabilityIndex()
    a, c = 0.15, 146.14 / (78064.0 * 0.0104)
    closed = math.sqrt(2.0) * (1.0 - math.sqrt(c)) / a
    # both solvers stop within ~1e-4 of the closed form (finite differences, Cobyla's tolerance)
    assert theirs == pytest.approx(closed, abs=2e-3)
    assert ours.beta == pytest.approx(closed, abs=2e-3)
    assert any("strongly curved" in w for w in ours.warnings)


G_A = np.array([0.0, 1.0, 4.5, 9.0, 99.0, 99.0, 99.0, 99.0])


def test_sobol_estimators_equal_openturns_on_the_same_g_function_design():
    from SALib.sample import sobol as sobol_sample

    d, n = 8, 1024
    problem = {"num_vars": d, "names": [f"x{i}" for i in range(d)], "bounds": [[0.0, 1.0]] * d}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        x = sobol_sample.sample(problem, n, calc_second_order=False, scramble=True, seed=11)
    y = np.prod((np.abs(4 * x - 2) + G_A) / (1 + G_A), axis=1)
    ours = sobol_indices(problem, y, resamples=2, seed=0)
    # SALib's blocks per base row are (A, A with column i from B, ..., B); OpenTURNS' design is
    # A, B, then the d pick-freeze blocks
    blocks, outputs = x.reshape(n, d + 2, d), y.reshape(n, d + 2)
    design = np.vstack([blocks[:, 0], blocks[:, -1]] + [blocks[:, 1 + i] for i in range(d)])
    values = np.concatenate([outputs[:, 0], outputs[:, -1]]
                            + [outputs[:, 1 + i] for i in range(d)])
    sample_x, sample_y = ot.Sample(design), ot.Sample(values[:, None])
    total = np.array(ot.JansenSensitivityAlgorithm(sample_x, sample_y, n).getTotalOrderIndices())
    first = np.array(
        ot.MauntzKucherenkoSensitivityAlgorithm(sample_x, sample_y, n).getFirstOrderIndices()
    )
    # Same numerators (Jansen 1999 for ST; Saltelli 2010 = Mauntz-Kucherenko for S1); only the
    # variance in the denominator differs (SALib and skidmc: of A and B together), so the ratio
    # is one constant for every index: checked on the four influential inputs to 1e-9.
    for ours_index, theirs_index in ((ours["ST"].values, total), (ours["S1"].values, first)):
        ratio = ours_index[:4] / theirs_index[:4]
        assert np.ptp(ratio) < 1e-9 * ratio.mean()
        assert ratio.mean() == pytest.approx(1.0, abs=0.01)


def test_fieller_interval_against_statsmodels_probit():
    sm = pytest.importorskip("statsmodels.api")
    heights = np.array([3.1, 4.2, 5.0, 5.9, 6.3, 7.4, 8.1, 9.0, 10.2, 11.5, 12.8, 14.0, 15.9, 18.3])
    went = np.array([0, 0, 0, 1, 0, 0, 1, 0, 1, 1, 0, 1, 1, 1], dtype=bool)
    model = sm.Probit(went.astype(float), sm.add_constant(np.log(heights))).fit(
        disp=0, method="newton", tol=1e-12)
    (c, s), cov = model.params, model.cov_params()
    k = stats.chi2.ppf(0.95, 1)
    # (c + s q)^2 <= k (v_cc + 2 q v_cs + q^2 v_ss) for the median (z = 0)
    quad = [s * s - k * cov[1, 1], 2 * (c * s - k * cov[0, 1]), c * c - k * cov[0, 0]]
    roots = np.sort(np.roots(quad))
    _, low, high = fit_probit(heights, went, interval="fieller").quantile(0.5)
    # statsmodels' Newton and ours stop at gradients ~1e-9: the bounds agree to ~1e-7
    assert math.log(low) == pytest.approx(roots[0], rel=1e-5)
    assert math.log(high) == pytest.approx(roots[1], rel=1e-5)
