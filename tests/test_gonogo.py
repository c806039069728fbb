"""Go/no-go statistics: fits against independent code, the report's data, and measured coverage."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import optimize, stats

from skidmc.analysis.experiments import load_drops
from skidmc.analysis.gonogo import (
    compare_h50,
    fit_lognormal,
    fit_probit,
    go_curve,
    plot_go_curve,
    plot_qq,
    score_drops,
    updown,
)

CHI2_95 = stats.chi2.ppf(0.95, df=1)

# An overlapping go/no-go data set (heights in ft, printed to 3 figures as in the report).
HEIGHTS = np.array([3.1, 4.2, 5.0, 5.9, 6.3, 7.4, 8.1, 9.0, 10.2, 11.5, 12.8, 14.0, 15.9, 18.3])
WENT = np.array([0, 0, 0, 1, 0, 0, 1, 0, 1, 1, 0, 1, 1, 1], dtype=bool)


def simulate_updown(rng, n, mu, sigma, step, start):
    """An up-down sequence in ln h: one step down after a go, up after a no-go."""
    x, heights, went = start, [], []
    for _ in range(n):
        go = rng.normal(mu, sigma) <= x
        heights.append(math.exp(x))
        went.append(go)
        x = x - step if go else x + step
    return np.array(heights), np.array(went)


# ---------------------------------------------------------------------------------------------
# probit maximum likelihood


def test_probit_matches_statsmodels_glm():
    sm = pytest.importorskip("statsmodels.api")
    design = sm.add_constant(np.log(HEIGHTS))
    glm = sm.GLM(WENT.astype(float), design,
                 family=sm.families.Binomial(link=sm.families.links.Probit())).fit(tol=1e-12)
    b0, b1 = glm.params
    fit = fit_probit(HEIGHTS, WENT)
    assert fit.exists
    # Both optimisers stop at gradients ~1e-9 of a log-likelihood with curvature O(1-10): the
    # estimates agree to ~1e-8; 1e-6 leaves room for the different parametrisations.
    assert fit.mu == pytest.approx(-b0 / b1, rel=1e-6)
    assert fit.sigma == pytest.approx(1.0 / b1, rel=1e-6)
    assert fit.loglik == pytest.approx(glm.llf, rel=1e-8)
    # The Wald option is the GLM's own normal approximation carried to ln H50 by the delta method.
    cov = glm.cov_params()
    grad = np.array([-1.0 / b1, b0 / b1**2])  # d(-b0/b1)/d(b0, b1)
    half = stats.norm.ppf(0.975) * math.sqrt(grad @ cov @ grad)
    _, low, high = fit_probit(HEIGHTS, WENT, interval="wald").quantile(0.5)
    # observed (ours) and expected (GLM IRLS) information coincide for the probit link only at
    # the optimum up to O(1e-3) here; the bounds agree to 1 %.
    assert math.log(low) == pytest.approx(-b0 / b1 - half, rel=1e-2)
    assert math.log(high) == pytest.approx(-b0 / b1 + half, rel=1e-2)


def _independent_profile(heights, went, q_log, z):
    """max over sigma of the binomial log-likelihood with the quantile fixed (scipy.stats)."""
    x = np.log(heights)

    def negative(log_sigma):
        sigma = math.exp(log_sigma)
        mu = q_log - z * sigma
        return -np.sum(np.where(went, stats.norm.logcdf(x, mu, sigma),
                                stats.norm.logsf(x, mu, sigma)))

    return -optimize.minimize_scalar(negative, bounds=(-12, 8), method="bounded",
                                     options={"xatol": 1e-10}).fun


@pytest.mark.parametrize("p", [0.5, 0.1, 0.9])
def test_profile_bounds_sit_where_the_likelihood_ratio_reaches_chi2(p):
    fit = fit_probit(HEIGHTS, WENT, interval="profile")
    estimate, low, high = fit.quantile(p)
    assert low < estimate < high
    z = stats.norm.ppf(p)
    for bound in (low, high):
        ratio = 2 * (fit.loglik - _independent_profile(HEIGHTS, WENT, math.log(bound), z))
        # root found to 1e-10 in q; the independent optimiser is converged to ~1e-9: the
        # likelihood ratio at the bound matches the critical value to 1e-5
        assert ratio == pytest.approx(CHI2_95, abs=1e-5)


def test_probability_is_half_at_h50_and_rises():
    fit = fit_probit(HEIGHTS, WENT)
    assert fit.probability(fit.h50) == pytest.approx(0.5, abs=1e-12)
    curve = fit.probability(np.array([2.0, 5.0, 10.0, 20.0]))
    assert np.all(np.diff(curve) > 0)


def test_open_ended_interval_is_reported_not_clipped():
    # four drops, outcomes alternating: the slope is not significant, so the likelihood never
    # falls by the critical value however far the median moves
    for interval in ("profile", "fieller"):
        fit = fit_probit([1.0, 2.0, 3.0, 4.0], [0, 1, 0, 1], interval=interval)
        assert fit.exists
        estimate, low, high = fit.quantile(0.5)
        assert 1.0 < estimate < 4.0
        assert (low, high) == (0.0, math.inf)
    assert fit.sigma_interval()[1] == math.inf


def test_no_overlap_reports_bounds_instead_of_an_estimate():
    heights = [1.0, 1.2, 1.4, 1.7, 2.0, 2.4]
    fit = fit_probit(heights, [0, 0, 0, 1, 1, 1])
    assert not fit.exists
    assert "no overlap" in fit.reason
    assert math.isnan(fit.h50) and math.isnan(fit.sigma)
    assert fit.h50_range == (1.4, 1.7)
    estimate, low, high = fit.quantile(0.5)
    assert math.isnan(estimate)
    # the likelihood-ratio set contains the whole gap and reaches past it
    assert low < 1.4 and high > 1.7
    assert 1.0 <= low and high <= 2.4
    sigma_low, sigma_high = fit.sigma_interval()
    assert sigma_low == 0.0 and 0.0 < sigma_high < math.inf
    # at the upper sigma bound the likelihood ratio from the supremum (0) is the critical value
    x, went = np.log(heights), np.array([0, 0, 0, 1, 1, 1], bool)

    def profile(sigma):
        return -optimize.minimize_scalar(
            lambda mu: -np.sum(np.where(went, stats.norm.logcdf(x, mu, sigma),
                                        stats.norm.logsf(x, mu, sigma))),
            bounds=(x.min(), x.max()), method="bounded", options={"xatol": 1e-12}).fun

    # bounded search to 1e-12 in mu; the ratio is matched to 1e-5 (root tolerance of sigma)
    assert -2 * profile(sigma_high) == pytest.approx(CHI2_95, abs=1e-5)


def test_reversed_separation_and_one_height_do_not_fit():
    reversed_fit = fit_probit([1.0, 1.2, 1.4, 1.7], [1, 1, 0, 0])
    assert not reversed_fit.exists and "reversed" in reversed_fit.reason
    assert all(math.isnan(v) for v in reversed_fit.quantile(0.5))
    one = fit_probit([2.0, 2.0, 2.0], [1, 0, 1])
    assert not one.exists and "one height" in one.reason


def test_quartz_table_iii_probit_touches_at_one_height():
    drops = load_drops("quartz")
    fit = fit_probit(drops.heights, drops.went)
    # no-gos at 1.5 and 2.12 ft, gos only at 2.12 ft: the outcomes touch but do not overlap
    assert not fit.exists and fit.h50_range == (2.12, 2.12)
    _, low, high = fit.quantile(0.5)
    assert low < 1.8 < high  # the report's 1.8 ft is inside the likelihood-ratio set


# ---------------------------------------------------------------------------------------------
# Dixon-Mood


def _worked_sequence(last_went: bool):
    """A 17-drop up-down sequence on log10 levels 1.0-1.3 (step 0.1), worked by hand below."""
    levels = [1.2, 1.1, 1.2, 1.1, 1.0, 1.1, 1.2, 1.3, 1.2, 1.1, 1.2, 1.1, 1.2, 1.3, 1.2, 1.3, 1.2]
    went = [1, 0, 1, 1, 0, 0, 0, 1, 1, 0, 1, 0, 0, 1, 0, 1, int(last_went)]
    return 10.0 ** np.array(levels), went


@pytest.mark.parametrize("last_went", [False, True])
def test_dixon_mood_hand_worked_example(last_went):
    # Worked by hand. Last drop a no-go: 8 gos, 9 no-gos, so the gos are used: levels 1.1, 1.2,
    # 1.3 -> i = 0, 1, 2 with n_i = 1, 4, 3: N = 8, A = 10, B = 16, mean = 1.1 + 0.1 (10/8 - 1/2)
    # = 1.175. Last drop a go: 9 gos, 8 no-gos, so the no-gos: levels 1.0, 1.1, 1.2 with
    # n_i = 1, 4, 3: the same N, A, B and mean = 1.0 + 0.1 (10/8 + 1/2) = 1.175. Both:
    # M = (8*16 - 100)/64 = 0.4375, s = 1.62 * 0.1 * (0.4375 + 0.029) = 0.075573 (log10).
    heights, went = _worked_sequence(last_went)
    result = updown(heights, went)
    assert result.outcome_used == ("no-go" if last_went else "go")
    assert (result.n_used, result.a_sum, result.b_sum) == (8, 10, 16)
    assert result.m_statistic == pytest.approx(0.4375, abs=1e-12)
    # exact arithmetic on a grid that is exact to rounding: 1e-9 relative is round-off only
    assert result.h50 == pytest.approx(10**1.175, rel=1e-9)
    assert result.sigma == pytest.approx(0.075573 * math.log(10), rel=1e-5)  # 5 printed figures
    # every condition holds except the sample size (N = 8 < 10)
    assert len(result.reasons) == 1 and "N = 8" in result.reasons[0]
    assert not result.valid
    assert updown(heights, went, min_count=8).valid


def test_dixon_mood_on_report_table_iii_quartz():
    drops = load_drops("quartz")
    result = updown(drops.heights, drops.went)
    # 4 gos (less frequent), all at 2.12 ft: N = 4, A = B = 0, so mean = ln 2.12 - d/2, the
    # geometric mean of 1.5 and 2.12 ft = 1.783 ft. The report prints 1.8 ft (Table II), two
    # significant figures: 1.783 rounds to it, |1.783 - 1.8| = 0.017 < 0.05 half a last digit.
    assert result.h50 == pytest.approx(math.sqrt(1.5 * 2.12), rel=1e-12)
    assert abs(result.h50 - 1.8) < 0.05
    # ...but the method's own conditions fail: M = 0 (no spread estimate) and N = 4
    assert not result.valid and math.isnan(result.sigma)
    assert any("M = " in r for r in result.reasons)
    assert any("N = 4" in r for r in result.reasons)


# A published staircase worked to the end: Ekaputra, Dewa, Haryadi & Kim, "Fatigue strength
# analysis of S34MnV steel by accelerated staircase test", Open Engineering 10 (2020) 394-400,
# doi:10.1515/eng-2020-0048. Stress amplitude [MPa] -> (fractures = "go", survivals = "no-go");
# step d = 20 MPa on the linear stress scale; 12 specimens; the order of the trials is not
# printed. Printed answer: fractures are the less frequent outcome (N = 5), A = 8 and B = 14
# with i = 0 at 260 MPa, mean 282 MPa, M = 0.24 < 0.3, so the paper takes the spread from the
# fallback of ISO 12107 / GB/T 24176, s = 0.53 d = 10.6 MPa (the formula would give 8.7 MPa).
STAIRCASE_S34MNV = {300.0: (3, 0), 280.0: (2, 4), 260.0: (0, 3)}


def test_dixon_mood_on_a_published_staircase_from_counts():
    result = updown(counts=STAIRCASE_S34MNV, scale="linear", small_m="iso12107")
    assert result.outcome_used == "go" and result.n_used == 5
    # i = 0 here at 280 MPa (the lowest level with a fracture): A = 3, B = 3; with the paper's
    # i = 0 at 260 MPa, A = 8 = 3 + 5 and B = 14 = 3 + 2*3 + 5; mean and M do not change.
    assert (result.a_sum, result.b_sum) == (3, 3)
    assert result.a_sum + result.n_used == 8
    assert result.b_sum + 2 * result.a_sum + result.n_used == 14
    # exact arithmetic: 280 + 20 (3/5 - 1/2) = 282; M = (5*3 - 9)/25 = 0.24; 1e-12 is round-off
    assert result.h50 == pytest.approx(282.0, rel=1e-12)
    assert result.step == pytest.approx(20.0, rel=1e-12)
    assert result.m_statistic == pytest.approx(0.24, abs=1e-12)
    # the paper prints 10.6 MPa = 0.53 * 20 exactly
    assert result.sigma == pytest.approx(10.6, rel=1e-12)
    assert result.sigma_rule.startswith("ISO 12107")
    assert not result.valid and any("= 0.24 < 0.3" in r for r in result.reasons)
    # the default convention leaves sigma undefined and says how to get the published fallback
    default = updown(counts=STAIRCASE_S34MNV, scale="linear")
    assert math.isnan(default.sigma) and any("iso12107" in r for r in default.reasons)
    # Dixon-Mood's formula outside its range would give 1.62 d (M + 0.029) = 8.7 MPa (printed)
    assert 1.62 * 20.0 * (0.24 + 0.029) == pytest.approx(8.7, abs=0.05)


def test_dixon_mood_counts_and_sequence_agree_and_scale_matters():
    heights, went = _worked_sequence(False)
    sequence = updown(heights, went)
    counts: dict = {}
    for h, w in zip(np.round(heights, 9), went):
        gos, nogos = counts.get(h, (0, 0))
        counts[h] = (gos + w, nogos + (1 - w))
    from_counts = updown(counts=counts)
    assert from_counts.h50 == pytest.approx(sequence.h50, rel=1e-9)
    assert from_counts.sigma == pytest.approx(sequence.sigma, rel=1e-9)
    assert any("not checked" in r for r in from_counts.reasons)
    # the same heights on the linear scale are off a regular grid (10^1.0, 10^1.1, ...)
    assert math.isnan(updown(heights, went, scale="linear").h50)
    with pytest.raises(ValueError, match="scale = 'ln'"):
        updown(heights, went, scale="ln")
    with pytest.raises(ValueError, match="not both"):
        updown(heights, went, counts=counts)
    with pytest.raises(ValueError, match=r"counts\[1.0\] = \(1, -2\)"):
        updown(counts={1.0: (1, -2), 2.0: (1, 1)})


def test_dixon_mood_flags_a_broken_sequence_and_refuses_an_irregular_grid():
    drops = load_drops("alumina_20_35")  # drop 7 removed: 13.1 N followed by 13.1
    result = updown(drops.heights, drops.went)
    assert not result.valid and any("breaks the up-down rule" in r for r in result.reasons)
    irregular = updown([1.0, 1.5, 1.0, 1.4, 2.0], [0, 1, 0, 0, 1])
    assert not irregular.valid and math.isnan(irregular.h50)
    assert "off the regular logarithmic grid" in irregular.reasons[0]


# ---------------------------------------------------------------------------------------------
# censored log-normal


def _censored_sample(rng, n, mu, sigma, floor, ceiling):
    x = rng.normal(mu, sigma, n)
    labels = np.where(x > ceiling, "above", np.where(x <= floor, "below", ""))
    values = np.where(labels == "above", ceiling, np.where(labels == "below", floor, x))
    return np.exp(values), labels


def test_censored_lognormal_recovers_parameters():
    rng = np.random.default_rng(314)
    mu, sigma, n = math.log(20.0), 0.35, 400
    heights, labels = _censored_sample(rng, n, mu, sigma, mu - 1.2 * sigma, mu + 0.9 * sigma)
    assert 0.15 < np.mean(labels == "above") < 0.25 and np.mean(labels == "below") > 0.08
    fit = fit_lognormal(heights, labels, n_bootstrap=199)
    # standard errors of the uncensored MLE are sigma/sqrt(n) and sigma/sqrt(2n); ~30 %
    # censoring inflates them by < 1.5x. Four such errors: a false failure has odds < 1e-4.
    assert abs(fit.mu - mu) < 4 * 1.5 * sigma / math.sqrt(n)
    assert abs(fit.sigma - sigma) < 4 * 1.5 * sigma / math.sqrt(2 * n)
    # the same maximum as scipy's censored fit (Nelder-Mead, stopping at ~1e-4 relative)
    data = stats.CensoredData(uncensored=np.log(heights[labels == ""]),
                              left=np.log(heights[labels == "below"]),
                              right=np.log(heights[labels == "above"]))
    loc, scale = stats.norm.fit(data)
    assert fit.mu == pytest.approx(loc, rel=1e-3)
    assert fit.sigma == pytest.approx(scale, rel=1e-3)
    for name in ("h01", "h10", "h50", "h90", "sigma"):
        estimate, low, high = fit.intervals[name]
        assert low < estimate < high


def test_lognormal_gof_statistic_is_fillibens_without_censoring():
    rng = np.random.default_rng(2)
    heights = np.exp(rng.normal(1.0, 0.3, 40))
    fit = fit_lognormal(heights, n_bootstrap=199)
    reference = stats.goodness_of_fit(stats.norm, np.log(heights), statistic="filliben",
                                      n_mc_samples=199,
                                      random_state=np.random.default_rng(0))
    # the same statistic from the same formula in scipy: agreement to round-off
    assert fit.ppcc == pytest.approx(reference.statistic, rel=1e-12)
    assert fit.qq is not None and fit.qq.observed.size == 40


def test_lognormal_gof_rejects_a_clearly_non_lognormal_sample():
    rng = np.random.default_rng(7)
    # two well-separated modes in ln h: a log-normal fit is plainly wrong
    heights = np.exp(np.concatenate([rng.normal(0.0, 0.1, 60), rng.normal(1.5, 0.1, 60)]))
    labels = np.where(heights > np.exp(1.6), "above", "")
    heights = np.where(labels == "above", np.exp(1.6), heights)
    fit = fit_lognormal(heights, labels, n_bootstrap=199)
    assert fit.p_value < 0.05 and fit.verdict == "log-normal rejected at 5 %"


# ---------------------------------------------------------------------------------------------
# go curve


def test_go_curve_is_the_ecdf_and_unknown_above_the_censoring_bound():
    heights = np.array([2.0, 3.0, 5.0, 7.0, 7.0, 1.0])
    labels = np.array(["", "", "", "above", "above", "below"])
    curve = go_curve(heights, labels, units="ft", grid=[1.5, 2.0, 6.0, 7.0, 8.0])
    # at 1.5 ft the "below 1" sample went, the others not: 1/6; at 2 ft 2/6; at 6 ft 4/6;
    # at 7 ft the two "above 7" samples are still no-gos: 4/6; above 7 ft they are unknown
    np.testing.assert_allclose(curve.p_go.values[:4], [1 / 6, 2 / 6, 4 / 6, 4 / 6])
    assert math.isnan(curve.p_go.values[4]) and not curve.identified.values[4]
    eps = curve.attrs["dkw_epsilon"]
    assert eps == pytest.approx(math.sqrt(math.log(2 / 0.05) / 12))
    assert curve.p_go_high.values[4] == 1.0  # 4/6 + 2 unknown + eps, clipped
    assert curve["height"].attrs["units"] == "ft"
    known = curve.identified.values
    assert np.all(curve.p_go_low.values[known] <= curve.p_go.values[known])
    assert np.all(curve.p_go.values[known] <= curve.p_go_high.values[known])


def _band_covers(curve, true_cdf):
    """Whether the step band holds the true CDF everywhere (at each step and just before it)."""
    h = curve["height"].values
    low, high = curve.p_go_low.values, curve.p_go_high.values
    at_steps = np.all((low <= true_cdf(h)) & (true_cdf(h) <= high))
    # between steps the band is constant and the CDF rises: its largest value in [h_i, h_i+1)
    # is reached just before h_i+1, the smallest at h_i (checked above); below the first step
    # the band is [0, eps]
    before = np.all(true_cdf(h[1:]) <= high[:-1])
    first = true_cdf(h[0]) <= curve.attrs["dkw_epsilon"]
    return bool(at_steps and before and first)


# ---------------------------------------------------------------------------------------------
# scores and comparison


def test_score_drops_limits():
    heights, went = np.array([1.0, 2.0, 3.0, 4.0]), np.array([0, 0, 1, 1], bool)
    perfect = score_drops(lambda h: (h > 2.5).astype(float), heights, went)
    assert perfect.log_score == 0.0 and perfect.brier == 0.0 and perfect.log_likelihood == 0.0
    coin = score_drops(lambda h: np.full(h.shape, 0.5), heights, went)
    assert coin.log_score == pytest.approx(math.log(2)) and coin.brier == pytest.approx(0.25)
    assert coin.brier_base_rate == pytest.approx(0.25)
    wrong = score_drops(lambda h: (h < 2.5).astype(float), heights, went)
    assert wrong.log_likelihood == -math.inf and wrong.brier == 1.0
    fit = fit_probit(HEIGHTS, WENT)
    scored = score_drops(fit.probability, HEIGHTS, WENT)
    assert scored.log_likelihood == pytest.approx(fit.loglik, rel=1e-12)


def test_compare_h50_gold_lower_bound_and_quartz():
    gold = compare_h50(515.0, (math.nan, 150.0, math.inf))
    assert gold.intervals_overlap and gold.predicted_inside and math.isnan(gold.ratio)
    quartz = compare_h50((1.25, 1.1, 1.4), fit_probit(HEIGHTS, WENT))
    assert quartz.ratio == pytest.approx(1.25 / fit_probit(HEIGHTS, WENT).h50)
    assert not quartz.predicted_inside


# ---------------------------------------------------------------------------------------------
# figures


def test_figures_draw_the_data():
    matplotlib = pytest.importorskip("matplotlib")
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    heights = np.exp(np.random.default_rng(3).normal(1.0, 0.3, 30))
    fig, (ax1, ax2) = plt.subplots(1, 2)
    plot_go_curve(ax1, go_curve(heights, units="ft"), drops=load_drops("quartz"))
    step_line = ax1.get_lines()[0]
    np.testing.assert_allclose(step_line.get_xdata(), np.sort(heights))
    assert ax1.get_xscale() == "log" and ax1.get_xlabel() == "drop height [ft]"
    fit = fit_lognormal(heights, n_bootstrap=99)
    plot_qq(ax2, fit)
    np.testing.assert_allclose(ax2.get_lines()[0].get_ydata(), np.sort(heights))
    plt.close(fig)


# ---------------------------------------------------------------------------------------------
# bad input


BAD_CALLS = [
    (lambda: fit_probit([1.0, -2.0], [0, 1]), r"heights\[1\] = -2\.0"),
    (lambda: fit_probit([1.0, 0.0], [0, 1]), r"heights\[1\] = 0\.0"),
    (lambda: fit_probit([1.0, math.nan], [0, 1]), r"heights\[1\] = nan"),
    (lambda: fit_probit([1.0, math.inf], [0, 1]), r"heights\[1\] = inf"),
    (lambda: fit_probit([], []), r"heights = \[\]"),
    (lambda: fit_probit(["a", "b"], [0, 1]), r"heights = \['a', 'b'\]"),
    (lambda: fit_probit([1.0, 2.0, 3.0], [0, 1]), r"went = \[0, 1\]: has 2 outcomes but"),
    (lambda: fit_probit([1.0, 2.0], [1, 1]), r"went = \[True, True\]: every drop is a go"),
    (lambda: fit_probit([1.0, 2.0], [0, 0]), r"every drop is a no-go"),
    (lambda: fit_probit([1.0, 2.0], [0, math.nan]), r"went\[1\] = nan"),
    (lambda: fit_probit([1.0, 2.0], [0, 2]), r"went\[1\] = 2"),
    (lambda: fit_probit([1.0, 2.0], ["n", "e"]), r"went = \['n', 'e'\]"),
    (lambda: fit_probit([1.0, 2.0], [0, 1], confidence=1.5), r"confidence = 1\.5"),
    (lambda: fit_probit([1.0, 2.0], [0, 1], interval="bootstrap"), r"interval = 'bootstrap'"),
    (lambda: fit_probit(HEIGHTS, WENT).quantile(1.0), r"p = 1\.0"),
    (lambda: fit_probit(HEIGHTS, WENT).probability(-1.0), r"height = -1\.0"),
    (lambda: updown([1.0, -1.0], [1, 0]), r"heights\[1\] = -1\.0"),
    (lambda: updown([1.0, 2.0], [1, 1]), r"every drop is a go"),
    (lambda: updown([1.0, 2.0], [1]), r"went = \[1\]"),
    (lambda: updown([1.0, 2.0], [1, 0], step_tolerance=0.7), r"step_tolerance = 0\.7"),
    (lambda: fit_lognormal([1.0, 2.0, 3.0], ["", "up", ""]), r"censored\[1\] = 'up'"),
    (lambda: fit_lognormal([1.0, 2.0, 3.0], ["", ""]), r"censored = \['', ''\]"),
    (lambda: fit_lognormal([1.0, 2.0, 3.0], ["above", "above", ""]), r"two distinct"),
    (lambda: fit_lognormal([1.0, 0.0, 3.0]), r"heights\[1\] = 0\.0"),
    (lambda: fit_lognormal([1.0, 2.0, 3.0], n_bootstrap=10), r"n_bootstrap = 10"),
    (lambda: go_curve([1.0, 2.0], grid=[1.0, -3.0]), r"grid\[1\] = -3\.0"),
    (lambda: go_curve([1.0, 2.0], confidence=0.0), r"confidence = 0\.0"),
    (lambda: go_curve([1.0, math.nan]), r"heights\[1\] = nan"),
    (lambda: score_drops(0.5, [1.0], [1]), r"prob_go = 0\.5"),
    (lambda: score_drops(lambda h: h, [1.0, 2.0], [1, 0]), r"returned 2\.0 at height 2"),
    (lambda: score_drops(lambda h: np.full(h.shape, np.nan), [1.0], [1]), r"returned nan"),
    (lambda: score_drops(lambda h: 0.5, [1.0, 2.0], [1, 0]), r"returned shape \(\)"),
    (lambda: compare_h50("big", 1.0), r"predicted = 'big'"),
]


@pytest.mark.parametrize("call, message", BAD_CALLS)
def test_bad_input_raises_a_value_error_naming_argument_and_value(call, message):
    with pytest.raises(ValueError, match=message):
        call()


# ---------------------------------------------------------------------------------------------
# measured coverage (slow)


@pytest.mark.slow
def test_profile_interval_coverage_on_simulated_updown_sequences():
    """Coverage of the 95 % H50 interval over up-down sequences of N = 10-30 drops.

    Seed, truth and design drawn here were not used while writing the code (development used
    other seeds). Measured (seed 20240611, 2000 sequences): profile 0.959 where the MLE exists
    (1381 sequences), Wald 0.913 on the same sequences; where the outcomes do not overlap (the
    other 619) the likelihood-ratio set from the supremum covers only 0.837 (documented).
    """
    rng = np.random.default_rng(20240611)
    mu, sigma = math.log(10.0), 0.2
    covered, wald_covered, n_exists, separated_covered, n_separated = 0, 0, 0, 0, 0
    for _ in range(2000):
        n = int(rng.integers(10, 31))
        step = sigma * rng.uniform(0.5, 2.0)  # Dixon-Mood's recommended 0.5-2 sigma
        heights, went = simulate_updown(rng, n, mu, sigma, step, mu + sigma * rng.normal())
        heights = np.round(heights, 3)  # heights as recorded, to three decimals
        if went.all() or not went.any():
            continue
        fit = fit_probit(heights, went, interval="profile")
        _, low, high = fit.quantile(0.5)
        hit = low <= 10.0 <= high
        if fit.exists:
            n_exists += 1
            covered += hit
            _, w_low, w_high = fit_probit(heights, went, interval="wald").quantile(0.5)
            wald_covered += w_low <= 10.0 <= w_high
        else:
            n_separated += 1
            separated_covered += hit
    coverage, wald = covered / n_exists, wald_covered / n_exists
    print(f"profile {coverage:.3f} (n={n_exists}), wald {wald:.3f}, "
          f"separated {separated_covered / n_separated:.3f} (n={n_separated})")
    tolerance = 3 * math.sqrt(0.95 * 0.05 / n_exists)  # three binomial standard errors
    assert abs(coverage - 0.95) < tolerance
    assert wald < coverage - tolerance  # Wald undercovers at these sizes
    # documented in docs/go-no-go.md: "about 0.8" where the outcomes do not overlap
    assert 0.72 < separated_covered / n_separated < 0.88


@pytest.mark.slow
def test_lognormal_interval_coverage_with_censoring():
    """95 % profile intervals of H50, H10 and sigma from 30 samples, ~25 % censored.

    Measured (seed 99, 600 samples): H50 0.948, H10 0.950, sigma 0.953.
    """
    rng = np.random.default_rng(99)
    mu, sigma, reps = math.log(20.0), 0.3, 600
    hits = {"h50": 0, "h10": 0, "sigma": 0}
    truth = {"h50": 20.0, "h10": math.exp(mu + stats.norm.ppf(0.1) * sigma), "sigma": sigma}
    for _ in range(reps):
        heights, labels = _censored_sample(rng, 30, mu, sigma, mu - 1.5 * sigma, mu + sigma)
        if np.unique(heights[labels == ""]).size < 2:
            continue
        fit = fit_lognormal(heights, labels, n_bootstrap=99)
        for name in hits:
            _, low, high = fit.intervals[name]
            hits[name] += low <= truth[name] <= high
    tolerance = 3 * math.sqrt(0.95 * 0.05 / reps)
    print({k: v / reps for k, v in hits.items()})
    for name, count in hits.items():
        assert abs(count / reps - 0.95) < tolerance, name


@pytest.mark.slow
def test_lognormal_gof_false_rejection_rate_with_censoring():
    """Measured (seed 4242, 300 samples of 40, ~30 % censored): 0.037 rejected at 5 %."""
    rng = np.random.default_rng(4242)
    rejected, reps = 0, 300
    for k in range(reps):
        heights, labels = _censored_sample(rng, 40, 0.0, 1.0, -1.3, 0.8)
        rejected += fit_lognormal(heights, labels, n_bootstrap=199, seed=k).p_value < 0.05
    rate = rejected / reps
    print(f"false rejection rate {rate:.3f}")
    assert abs(rate - 0.05) < 3 * math.sqrt(0.05 * 0.95 / reps)


@pytest.mark.slow
@pytest.mark.parametrize("censor", [False, True])
def test_go_curve_band_covers_the_true_cdf_simultaneously(censor):
    """Measured (2000 samples of 50): 0.961 without censoring, 0.968 with a ceiling."""
    rng = np.random.default_rng(777 + censor)
    reps, n = 2000, 50
    true_cdf = stats.lognorm(s=0.4, scale=5.0).cdf
    covered = 0
    for _ in range(reps):
        heights = np.exp(rng.normal(math.log(5.0), 0.4, n))
        labels = None
        if censor:  # a search ceiling at the 80th percentile
            ceiling = 5.0 * math.exp(0.4 * 0.8416)
            labels = np.where(heights > ceiling, "above", "")
            heights = np.minimum(heights, ceiling)
        covered += _band_covers(go_curve(heights, labels), true_cdf)
    coverage = covered / reps
    print(f"simultaneous coverage {coverage:.3f}")
    # DKW with Massart's constant is conservative: coverage >= nominal up to sampling error
    assert coverage > 0.95 - 3 * math.sqrt(0.95 * 0.05 / reps)


# ---------------------------------------------------------------------------------------------
# bound searches never raise (issue 41)

# An ordinary 26-drop up-down sequence (median 2 ft, sigma 0.1 in log10, step 0.5 sigma) on which
# quantile(0.5) raised OverflowError: the profile's limit as H50 -> inf lies 0.0034 below the
# chi-square level, and the search passed the slope floor and found a spurious crossing.
OPEN_HEIGHTS = [2.825075, 2.517851, 2.825075, 2.517851, 2.244037, 2.0, 1.782502, 1.588656,
                1.415892, 1.588656, 1.782502, 2.0, 1.782502, 2.0, 1.782502, 1.588656, 1.782502,
                1.588656, 1.782502, 2.0, 2.244037, 2.517851, 2.244037, 2.517851, 2.825075,
                2.517851]
OPEN_WENT = [1, 0, 1, 1, 1, 1, 1, 1, 0, 0, 0, 1, 0, 1, 1, 0, 1, 0, 0, 0, 0, 1, 0, 0, 1, 1]


def test_open_bound_is_inf_not_an_overflow():
    fit = fit_probit(OPEN_HEIGHTS, OPEN_WENT)
    went = np.array(OPEN_WENT, bool)
    # the constant-probability limits of the profile, computed here from the binomial likelihood
    for p_limit in (0.5, went.mean()):
        limit = stats.binom.logpmf(went.sum(), went.size, p_limit)
        # log-likelihood of the data in a sequence (no binomial coefficient) at constant p
        limit -= math.log(math.comb(went.size, int(went.sum())))
        assert 2.0 * (fit.loglik - limit) < CHI2_95  # so both sides are open for H50
    estimate, low, high = fit_probit(OPEN_HEIGHTS, OPEN_WENT, interval="profile").quantile(0.5)
    assert 1.5 < estimate < 2.5
    assert (low, high) == (0.0, math.inf)


def _no_bound_search_raises(n_sequences, seed):
    rng = np.random.default_rng(seed)
    sigma = 0.1 * math.log(10.0)
    n_fits = n_open = 0
    for _ in range(n_sequences):
        n = int(rng.integers(6, 41))
        step = sigma * rng.choice([0.25, 0.5, 1.0, 2.0])
        heights, went = simulate_updown(rng, n, math.log(2.0), sigma, step,
                                        math.log(2.0) + sigma * rng.normal())
        heights = np.round(heights, int(rng.integers(3, 7)))
        if went.all() or not went.any():
            continue
        n_fits += 1
        for interval in ("profile", "fieller"):
            fit = fit_probit(heights, went, interval=interval)
            for p in (0.01, 0.5, 0.9):
                estimate, low, high = fit.quantile(p)  # must not raise
                assert not (low > high), (p, low, high)
                n_open += high == math.inf
        s_low, s_high = fit.sigma_interval()
        assert not (s_low > s_high)
    assert n_open > 0  # the sample does reach open bounds, the case that used to raise
    return n_fits


def test_no_bound_search_raises_on_simulated_sequences():
    assert _no_bound_search_raises(150, seed=41) > 100


@pytest.mark.slow
def test_no_bound_search_raises_on_thousands_of_simulated_sequences():
    assert _no_bound_search_raises(3000, seed=4141) > 2000
