"""Structured drop-height estimator against a synthetic critical height with a closed form.

Synthetic model: three correlated inputs (a log-normal friction-like input, a normal one, a
log-normal mass-like one) with ln H_c = c0 - ln X0 + 0.05 X1 - 0.5 ln X2, which is linear in the
underlying normals z: ln H_c = m + a . z, a = (-0.3, 0.1, -0.1). With ln H_drop ~ N(0, 0.5^2)
independent of x, ln H_drop - ln H_c is normal and

    P[H_drop >= H_c] = Phi(-m / sqrt(0.5^2 + a' R a)),

so c0 is set for a chosen P. This closed form never goes through S_drop or the estimator's
sampling, so it checks them.
"""

from __future__ import annotations

import math
import warnings

import numpy as np
import pytest
from scipy import optimize, stats

from skidmc.analysis.hazard import drop_height_probability
from skidmc.analysis.rare_events import rare_event_probability

CORRELATION = np.array([[1.0, 0.5, 0.0], [0.5, 1.0, -0.3], [0.0, -0.3, 1.0]])
MARGINALS = [stats.lognorm(0.3, scale=0.4), stats.norm(20.0, 2.0), stats.lognorm(0.2, scale=10.0)]
# d ln H_c / d z_j: coefficient of each input times its log-scale standard deviation.
LOG_HEIGHT_SLOPES = np.array([-1.0 * 0.3, 0.05 * 2.0, -0.5 * 0.2])
DROP_LOG_SD = 0.5
DROP_HEIGHT = stats.lognorm(DROP_LOG_SD, scale=1.0)  # median drop 1 m


def total_log_sd() -> float:
    return math.sqrt(DROP_LOG_SD**2 + LOG_HEIGHT_SLOPES @ CORRELATION @ LOG_HEIGHT_SLOPES)


def synthetic_critical_height(probability: float):
    """H_c(X) [m] whose event probability with DROP_HEIGHT is `probability` exactly."""
    median_log_height = stats.norm.isf(probability) * total_log_sd()
    offset = median_log_height - (-math.log(0.4) + 0.05 * 20.0 - 0.5 * math.log(10.0))

    def critical_height(x):
        return np.exp(offset - np.log(x[:, 0]) + 0.05 * x[:, 1] - 0.5 * np.log(x[:, 2]))

    return critical_height


def extended_limit_state(critical_height):
    """The same event with H_drop as a 4th input: g = H_c(x) - H_drop, failure g <= 0."""
    return lambda x: critical_height(x[:, :3]) - x[:, 3]


EXTENDED_CORRELATION = np.eye(4)
EXTENDED_CORRELATION[:3, :3] = CORRELATION


def within(result, exact: float) -> bool:
    return result.interval[0] <= exact <= result.interval[1]


@pytest.mark.parametrize("method", ["is", "mc"])
def test_1e6_within_interval_of_closed_form(method):
    result = drop_height_probability(
        synthetic_critical_height(1e-6), MARGINALS, DROP_HEIGHT, CORRELATION, method=method
    )
    assert result.converged and result.cov <= 0.1
    assert within(result, 1e-6)
    assert result.evaluations <= 20_000
    assert result.contributions.sum() == pytest.approx(result.probability, rel=1e-12)


def test_1e3_agrees_with_plain_monte_carlo_on_the_indicator():
    critical_height = synthetic_critical_height(1e-3)
    structured = drop_height_probability(
        critical_height, MARGINALS, DROP_HEIGHT, CORRELATION, method="mc"
    )
    plain = rare_event_probability(
        extended_limit_state(critical_height),
        [*MARGINALS, DROP_HEIGHT],
        "mc",
        correlation=EXTENDED_CORRELATION,
        max_evaluations=200_000,
    )
    assert within(structured, 1e-3) and within(plain, 1e-3)
    # Two independent estimates with their own standard errors: 3 combined standard errors
    # (a 0.3 % false alarm for normal errors).
    combined = math.hypot(structured.cov * structured.probability, plain.cov * plain.probability)
    assert abs(structured.probability - plain.probability) <= 3 * combined
    # The conditional estimator needs far fewer evaluations for the same CoV.
    assert structured.evaluations * 10 < plain.evaluations


def test_posterior_mean_matches_closed_form():
    # Conditional on the event, u is pulled along -w (w = L' a the slopes in u space):
    # E[u | event] = -(w / s) phi(b) / Phi(-b) with s the total log sd and b = isf(P).
    probability = 1e-4
    result = drop_height_probability(
        synthetic_critical_height(probability),
        MARGINALS,
        DROP_HEIGHT,
        CORRELATION,
        target_cov=0.05,
    )
    slopes_u = np.linalg.cholesky(CORRELATION).T @ LOG_HEIGHT_SLOPES
    b = stats.norm.isf(probability)
    exact = -(slopes_u / total_log_sd()) * stats.norm.pdf(b) / probability
    # Standard error of the contribution-weighted (ratio) mean, from the samples themselves.
    weights = result.contributions / result.contributions.sum()
    residual = result.standard_samples - result.posterior_mean_standard
    standard_error = np.sqrt((weights[:, None] ** 2 * residual**2).sum(axis=0))
    # 4 standard errors: a false alarm below 1e-4 per component.
    assert np.all(np.abs(result.posterior_mean_standard - exact) <= 4 * standard_error)
    # The physical posterior mean is the same weighting of the physical samples.
    np.testing.assert_allclose(result.posterior_mean, weights @ result.samples, rtol=1e-12)


def test_design_point_is_the_mode_along_the_slope():
    # ln H_c is linear in u, so the mode of S_drop(H_c(x(u))) phi(u) lies on the line u = -t w/|w|;
    # a 1-d maximisation along it is an independent reference for the d-dimensional search.
    critical_height = synthetic_critical_height(1e-6)
    result = drop_height_probability(critical_height, MARGINALS, DROP_HEIGHT, CORRELATION)
    slopes_u = np.linalg.cholesky(CORRELATION).T @ LOG_HEIGHT_SLOPES
    direction = -slopes_u / np.linalg.norm(slopes_u)
    from skidmc.analysis.rare_events import GaussianCopulaTransform

    transform = GaussianCopulaTransform(MARGINALS, CORRELATION)

    def negative_log_density(t):
        x = transform.to_physical(t * direction)
        return -(DROP_HEIGHT.logsf(critical_height(x))[0] - 0.5 * t * t)

    t_star = optimize.minimize_scalar(negative_log_density, bounds=(0.0, 10.0), method="bounded").x
    mode_u = transform.to_standard(result.design_point)[0]
    # 0.05 [U units]: forward differences with step 1e-2 bias the gradient by ~ step/2 times the
    # curvature (<= 1), and BFGS stops at a gradient of 1e-2 (its gtol is the step).
    np.testing.assert_allclose(mode_u, t_star * direction, atol=0.05)
    assert result.design_critical_height == pytest.approx(
        critical_height(result.design_point[np.newaxis])[0], rel=1e-12
    )


def test_split_by_categorical_input_with_infinite_heights():
    # A categorical "surface" input: on surface 0 nothing reacts at any height (H_c = inf), on
    # surface 1 (probability 0.2) ln H_c = m + 0.3 z. Then P = 0.2 Phi(-m / sqrt(0.5^2 + 0.3^2)).
    surface_probability = 0.2
    conditional = 1e-5
    median_log = stats.norm.isf(conditional) * math.hypot(DROP_LOG_SD, 0.3)
    marginals = [stats.bernoulli(surface_probability), stats.lognorm(0.3)]

    def critical_height(x):
        height = np.exp(median_log) * x[:, 1]
        return np.where(x[:, 0] == 1, height, np.inf)

    result = drop_height_probability(critical_height, marginals, DROP_HEIGHT, target_cov=0.05)
    exact = surface_probability * conditional
    assert within(result, exact)
    shares = result.probability_by(result.samples[:, 0])
    assert shares[0.0].probability == 0.0
    assert shares[1.0].probability == pytest.approx(result.probability, rel=1e-12)
    # The share's CoV is a stated accuracy: its 95 % interval covers the exact share.
    share = shares[1.0]
    assert abs(share.probability - exact) <= 1.96 * share.cov * share.probability


def test_split_shares_sum_to_total_and_cover_their_exact_values():
    # Two finite surfaces: H_c halved on surface 1 (probability 0.3). Each share is exact in
    # closed form: P(surface k) Phi(-(m_k) / sqrt(0.5^2 + 0.3^2)).
    marginals = [stats.bernoulli(0.3), stats.lognorm(0.3)]
    log_sd = math.hypot(DROP_LOG_SD, 0.3)
    median_log = stats.norm.isf(1e-5) * log_sd

    def critical_height(x):
        return np.exp(median_log) * x[:, 1] * np.where(x[:, 0] == 1, 0.5, 1.0)

    result = drop_height_probability(critical_height, marginals, DROP_HEIGHT, target_cov=0.05)
    exact = {
        0.0: 0.7 * stats.norm.sf(median_log / log_sd),
        1.0: 0.3 * stats.norm.sf((median_log + math.log(0.5)) / log_sd),
    }
    assert within(result, sum(exact.values()))
    shares = result.probability_by(result.samples[:, 0])
    assert sum(s.probability for s in shares.values()) == pytest.approx(result.probability)
    for label, share in shares.items():
        assert abs(share.probability - exact[label]) <= 1.96 * share.cov * share.probability


def test_budget_respected_and_reported():
    result = drop_height_probability(
        synthetic_critical_height(1e-6),
        MARGINALS,
        DROP_HEIGHT,
        CORRELATION,
        method="mc",
        max_evaluations=500,
    )
    assert result.evaluations == 500
    assert not result.converged and "budget" in result.stop_reason


def _heights(x):
    return np.exp(x[:, 0])


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"critical_height": lambda x: -np.ones(x.shape[0])}, r"critical_height = .*-1\.0"),
        ({"critical_height": lambda x: np.full(x.shape[0], np.nan)}, r"critical_height = .*nan"),
        ({"critical_height": lambda x: x}, r"critical_height = .*shape"),
        ({"drop_height": stats.lognorm}, r"drop_height = .*frozen"),
        ({"drop_height": stats.poisson(3)}, r"drop_height = .*continuous"),
        ({"marginals": [1.0]}, r"marginals\[0\] = 1.0"),
        ({"method": "subset"}, r"method = 'subset'"),
        ({"target_cov": 0}, r"target_cov = 0"),
        ({"max_evaluations": 0}, r"max_evaluations = 0"),
        ({"max_evaluations": 3}, r"max_evaluations = 3: the mode search"),
        ({"correlation": [[1.0]]}, r"(?s)correlation = .*shape \(2, 2\)"),
        ({"seed": 1.5}, r"seed = 1.5"),
    ],
)
def test_bad_input_raises_value_error_naming_argument(kwargs, match):
    arguments = {
        "critical_height": _heights,
        "marginals": [stats.norm(), stats.norm()],
        "drop_height": DROP_HEIGHT,
        "max_evaluations": 100,
    }
    arguments.update(kwargs)
    with pytest.raises(ValueError, match=match):
        drop_height_probability(**arguments)


@pytest.mark.slow
def test_evaluations_for_1e6_against_subset_and_form_is():
    """Cost of P ~ 1e-6 at CoV 0.1: structured estimator against the generic methods.

    The generic methods see H_drop as a 4th input (g = H_c - H_drop); every row they pass to
    g is one critical-height evaluation, as for the structured estimator.
    """
    critical_height = synthetic_critical_height(1e-6)
    costs = {}
    for method in ("is", "mc"):
        result = drop_height_probability(
            critical_height, MARGINALS, DROP_HEIGHT, CORRELATION, method=method
        )
        assert result.converged and within(result, 1e-6)
        costs[f"structured-{method}"] = result.evaluations
    # Budgets: subset simulation needs about 0.75-3.5 million evaluations for a stated CoV of 0.1
    # here, whatever samples_per_level (N = 1000-10000, seeds 0-3): its runs scatter by a log-sd
    # of about 1 (a CoV per run of 1.1-2.4, 2.6-5.7x what Au & Beck's formula states), and the
    # stated CoV takes the runs' noisy spread (docs/rare-events.md). The budget of 1e6 this test
    # had passed at one seed by luck (seeds 1-3 fail it with the code before issue 41 too);
    # 6e6 leaves room at any seed measured. The seed is the default one: 2.48e6 were used.
    budgets = {"form-is": 1_000_000, "subset": 6_000_000}
    for method in ("form-is", "subset"):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            result = rare_event_probability(
                extended_limit_state(critical_height),
                [*MARGINALS, DROP_HEIGHT],
                method,
                correlation=EXTENDED_CORRELATION,
                max_evaluations=budgets[method],
            )
        assert result.converged and within(result, 1e-6)
        costs[method] = result.evaluations
    print("evaluations for P = 1e-6 at CoV 0.1:", costs)
    assert costs["structured-is"] < costs["form-is"] < costs["subset"]


@pytest.mark.slow
@pytest.mark.parametrize(("method", "probability"), [("is", 1e-6), ("mc", 1e-3)])
def test_interval_coverage_over_seeds(method, probability):
    critical_height = synthetic_critical_height(probability)
    runs = 300
    hits = sum(
        within(
            drop_height_probability(
                critical_height, MARGINALS, DROP_HEIGHT, CORRELATION, method=method, seed=seed
            ),
            probability,
        )
        for seed in range(1000, 1000 + runs)  # seeds never used in the default tests
    )
    coverage = hits / runs
    spread = 3.0 * math.sqrt(0.95 * 0.05 / runs)  # 3 binomial standard deviations
    print(f"structured {method} at {probability}: coverage {coverage:.3f} over {runs} seeds")
    assert 0.95 - spread <= coverage <= 0.95 + spread


def test_log_weights_reweight_the_same_samples_to_another_drop_height():
    # The proposal on x does not involve the drop height, so the samples of one run give P for
    # another drop-height median: ln H_drop ~ N(ln f, 0.5^2) shifts the closed form to
    # Phi(-(m - ln f) / s). f = 2 raises P from 1e-6 to about 8e-6; the reweighted estimate
    # carries its own sample CoV, and its 95 % interval (+- 1.96 SE) must cover the exact value.
    critical_height = synthetic_critical_height(1e-6)
    result = drop_height_probability(critical_height, MARGINALS, DROP_HEIGHT, CORRELATION)
    assert result.log_weights.shape == result.critical_heights.shape
    same = np.exp(result.log_weights + DROP_HEIGHT.logsf(result.critical_heights))
    assert same.mean() == pytest.approx(result.probability, rel=1e-12)
    factor = 2.0
    other = stats.lognorm(DROP_LOG_SD, scale=factor)
    terms = np.exp(result.log_weights + other.logsf(result.critical_heights))
    estimate, error = terms.mean(), terms.std(ddof=1) / math.sqrt(terms.size)
    median_log = stats.norm.isf(1e-6) * total_log_sd()
    exact = stats.norm.sf((median_log - math.log(factor)) / total_log_sd())
    assert abs(estimate - exact) <= 1.96 * error
    mc = drop_height_probability(critical_height, MARGINALS, DROP_HEIGHT, CORRELATION,
                                 method="mc", max_evaluations=2000)
    np.testing.assert_array_equal(mc.log_weights, 0.0)
