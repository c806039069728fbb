"""Sobol' indices, their bootstrap intervals, groups, convergence, output policies and Morris.

Reference function: Ishigami, f = sin x1 + a sin^2 x2 + b x3^4 sin x1, x_i ~ U(-pi, pi), a = 7,
b = 0.1. Its variance components (Ishigami & Homma 1990; Sobol' & Levitan 1999):

    V1 = (1 + b pi^4 / 5)^2 / 2,  V2 = a^2 / 8,  V3 = 0,  V13 = b^2 pi^8 (1/18 - 1/50),
    V = V1 + V2 + V13 (= a^2/8 + b pi^4/5 + b^2 pi^8/18 + 1/2),

so S1 = (V1, V2, 0) / V = (0.3139, 0.4424, 0) and ST = (V1 + V13, V2, V13) / V =
(0.5576, 0.4424, 0.2437).

Seeds: every design and bootstrap seed below was fixed before the test first ran (0, or the
first values of a range) and not changed afterwards; the coverage tests use seed ranges that the
exploratory runs (seeds 1000-3199) did not touch.
"""

from __future__ import annotations

import math
import warnings

import numpy as np
import pytest
import scipy.stats
import xarray as xr
from SALib.analyze import sobol as salib_sobol
from SALib.sample import morris as morris_sample
from SALib.sample import sobol as sobol_sample

from skidmc.analysis import sensitivity as sens
from skidmc.analysis.sensitivity import (
    event_indicator,
    grow_until_stable,
    interval_half_width,
    morris_screening,
    plot_convergence,
    plot_indices,
    prepare_output,
    rows_per_base_row,
    sobol_convergence,
    sobol_indices,
    sobol_stable,
)

A_ISHIGAMI, B_ISHIGAMI = 7.0, 0.1
PROBLEM = {"num_vars": 3, "names": ["x1", "x2", "x3"], "bounds": [[-math.pi, math.pi]] * 3}
GROUPED = {**PROBLEM, "groups": ["g13", "g2", "g13"]}


def ishigami(x: np.ndarray) -> np.ndarray:
    """Ishigami function of rows x (n, 3)."""
    return (np.sin(x[:, 0]) + A_ISHIGAMI * np.sin(x[:, 1]) ** 2
            + B_ISHIGAMI * x[:, 2] ** 4 * np.sin(x[:, 0]))


def ishigami_exact() -> tuple[np.ndarray, np.ndarray]:
    """Analytic (S1, ST) of the Ishigami function (variance components in the module doc)."""
    a, b, pi = A_ISHIGAMI, B_ISHIGAMI, math.pi
    v1 = 0.5 * (1 + b * pi ** 4 / 5) ** 2
    v2 = a ** 2 / 8
    v13 = b ** 2 * pi ** 8 * (1 / 18 - 1 / 50)
    v = v1 + v2 + v13
    return np.array([v1, v2, 0.0]) / v, np.array([v1 + v13, v2, v13]) / v


def test_ishigami_exact_values_are_the_published_ones():
    # the closed forms above against the four-digit values quoted in the literature
    s1, st = ishigami_exact()
    np.testing.assert_allclose(s1, [0.3139, 0.4424, 0.0], atol=5e-5)  # 4-digit rounding
    np.testing.assert_allclose(st, [0.5576, 0.4424, 0.2437], atol=5e-5)


def design(problem, n, second_order=False, seed=0):
    return sobol_sample.sample(dict(problem), n, calc_second_order=second_order, seed=seed)


def iid_design(problem, n, rng, second_order=False):
    """SALib's row layout (A, AB_j, [BA_j,] B per base row) on i.i.d. uniform A and B."""
    d = problem["num_vars"]
    lo, hi = np.array(problem["bounds"]).T
    a = lo + (hi - lo) * rng.random((n, d))
    b = lo + (hi - lo) * rng.random((n, d))
    return _layout_rows(a, b, second_order)


def _layout_rows(a, b, second_order):
    d = a.shape[1]
    rows = [a]
    for j in range(d):
        ab = a.copy()
        ab[:, j] = b[:, j]
        rows.append(ab)
    if second_order:
        for j in range(d):
            ba = b.copy()
            ba[:, j] = a[:, j]
            rows.append(ba)
    rows.append(b)
    return np.stack(rows, axis=1).reshape(-1, d)


def test_iid_design_helper_has_salibs_layout():
    # rebuilding SALib's design from its own A and B rows gives it back exactly
    for second_order in (False, True):
        x = design(PROBLEM, 16, second_order)
        k = rows_per_base_row(PROBLEM, second_order)
        np.testing.assert_array_equal(_layout_rows(x[0::k], x[k - 1::k], second_order), x)


# --------------------------------------------------------------------------- point estimates


@pytest.mark.parametrize("problem", [PROBLEM, GROUPED], ids=["parameters", "groups"])
@pytest.mark.parametrize("second_order", [False, True])
def test_point_estimates_equal_salib(problem, second_order):
    y = ishigami(design(problem, 256, second_order, seed=0))
    res = sobol_indices(problem, y, second_order=second_order, resamples=20)
    ref = salib_sobol.analyze(dict(problem), y, calc_second_order=second_order,
                              num_resamples=10, seed=1)
    # Same ratios of means in double precision, summed in a different order: agreement to
    # ~1e-15; 1e-12 leaves room for platforms without flagging a real difference (>= 1e-6).
    np.testing.assert_allclose(res["S1"].values, ref["S1"], rtol=0, atol=1e-12)
    np.testing.assert_allclose(res["ST"].values, ref["ST"], rtol=0, atol=1e-12)
    if second_order:
        upper = np.triu(np.ones_like(ref["S2"], dtype=bool), 1)
        np.testing.assert_allclose(res["S2"].values[upper], ref["S2"][upper], atol=1e-12)
        np.testing.assert_array_equal(res["S2"].values, res["S2"].values.T)
    names = ["g13", "g2"] if "groups" in problem else PROBLEM["names"]
    assert list(res["parameter"].values) == names
    assert res.attrs["S1_estimator"] == "Saltelli 2010"
    assert res.attrs["ST_estimator"] == "Jansen 1999"
    assert res.attrs["N"] == 256


@pytest.mark.parametrize("interval", ["bca", "percentile"])
def test_ishigami_exact_indices_inside_intervals(interval):
    # N = 1024: fast (< 0.1 s) and in the regime where the coverage tests below show the
    # intervals hold on SALib's design; design and bootstrap seed 0, the first one tried.
    s1, st = ishigami_exact()
    res = sobol_indices(PROBLEM, ishigami(design(PROBLEM, 1024)), interval=interval, seed=0)
    assert np.all((res["S1_low"].values <= s1) & (s1 <= res["S1_high"].values))
    assert np.all((res["ST_low"].values <= st) & (st <= res["ST_high"].values))
    # only S1 of x3 (exactly 0) may be indistinguishable from 0
    assert res["S1_contains_zero"].values.tolist() == [False, False, True]
    assert not res["ST_contains_zero"].values.any()
    # the intervals are narrow enough to mean something: half-width < 0.1 (Ishigami at N=1024
    # has bootstrap standard errors of 0.01-0.04)
    assert float(interval_half_width(res, "ST").max()) < 0.1


def test_seed_zero_is_a_real_seed():
    y = ishigami(design(PROBLEM, 128))
    first = sobol_indices(PROBLEM, y, seed=0)
    again = sobol_indices(PROBLEM, y, seed=0)
    other = sobol_indices(PROBLEM, y, seed=1)
    xr.testing.assert_identical(first, again)
    assert not np.array_equal(first["S1_low"].values, other["S1_low"].values)
    assert first.attrs["seed"] == 0


def test_intervals_agree_with_scipy_bootstrap_on_the_same_replicates():
    """Our BCa/percentile formulas and O(N) jackknife against scipy.stats.bootstrap.

    scipy resamples base-row indices and evaluates our estimator on each resample; its BCa
    acceleration comes from its own brute-force jackknife (N re-evaluations), ours from the
    closed-form leave-one-out means.
    """
    y = ishigami(design(PROBLEM, 64, second_order=True))
    layout = sens._Layout(3, True)
    blocks = y.reshape(64, -1)
    blocks = (blocks - y.mean()) / y.std()
    features = sens._features(blocks, layout)
    estimate = sens._indices_from_means(features.mean(axis=0), layout)

    def statistic(rows, axis=-1):
        return np.moveaxis(sens._indices_from_means(features[rows].mean(axis=-2), layout), -1, 0)

    for method in ("BCa", "percentile"):
        options = {"vectorized": True, "n_resamples": 999, "method": method,
                   "confidence_level": 0.9}
        try:
            ref = scipy.stats.bootstrap((np.arange(64),), statistic,
                                        rng=np.random.default_rng(7), **options)
        except TypeError:  # scipy < 1.15 names the generator random_state
            ref = scipy.stats.bootstrap((np.arange(64),), statistic,
                                        random_state=np.random.default_rng(7), **options)
        low, high = sens._bootstrap_interval(estimate, ref.bootstrap_distribution.T,
                                             sens._jackknife(features, layout), 0.9,
                                             method.lower())
        # same replicates, same formulas: equal up to rounding of the jackknife sums
        np.testing.assert_allclose(low, ref.confidence_interval.low, rtol=0, atol=1e-10)
        np.testing.assert_allclose(high, ref.confidence_interval.high, rtol=0, atol=1e-10)


def test_bootstrap_resamples_whole_blocks():
    # Permuting the base rows (blocks) leaves every number unchanged except the bootstrap draw;
    # permuting rows inside the A column only (breaking the link) changes the estimates.
    y = ishigami(design(PROBLEM, 128))
    blocks = y.reshape(128, 5)
    perm = np.random.default_rng(0).permutation(128)
    res = sobol_indices(PROBLEM, y, interval="percentile")
    shuffled = sobol_indices(PROBLEM, blocks[perm].ravel(), interval="percentile")
    np.testing.assert_allclose(shuffled["S1"], res["S1"], atol=1e-13)  # summation order only
    broken = blocks.copy()
    broken[:, 0] = broken[perm, 0]
    assert not np.allclose(sobol_indices(PROBLEM, broken.ravel())["ST"], res["ST"], atol=1e-3)


# --------------------------------------------------------------------------- groups


def test_groups_ishigami_analytic():
    """Ishigami with groups {x1, x3} and {x2}.

    f = g(x1, x3) + a sin^2 x2 with g = (1 + b x3^4) sin x1: the groups do not interact, so each
    group's first-order index equals its total index, S_{13} = (V1 + V3 + V13) / V =
    1 - V2 / V = 0.5576 and S_2 = V2 / V = 0.4424 (V's components in the module doc).
    """
    s1, _ = ishigami_exact()
    exact = np.array([1.0 - s1[1], s1[1]])
    res = sobol_indices(GROUPED, ishigami(design(GROUPED, 1024)))
    assert list(res["parameter"].values) == ["g13", "g2"]
    for index in ("S1", "ST"):
        assert np.all((res[f"{index}_low"].values <= exact)
                      & (exact <= res[f"{index}_high"].values)), index


def test_groups_of_one_equal_ungrouped_and_keep_first_appearance_order():
    y = ishigami(design(PROBLEM, 128))
    singles = {**PROBLEM, "groups": ["x1", "x2", "x3"]}
    xr.testing.assert_identical(sobol_indices(singles, y), sobol_indices(PROBLEM, y))
    reordered = {**PROBLEM, "groups": ["b", "a", "b"]}
    y2 = ishigami(design(reordered, 64))
    assert list(sobol_indices(reordered, y2)["parameter"].values) == ["b", "a"]


def test_sum_of_independent_terms_group_indices():
    """f = x1 + x2 + 2 x3 + x4 x5 with x_i ~ U(0, 1) (variance 1/12 each).

    Var(x1) = Var(x2) = 1/12, Var(2 x3) = 4/12, Var(x4 x5) = E[x4^2] E[x5^2] - 1/16 =
    1/9 - 1/16 = 7/144. Groups {x1, x2} -> (2/12) / V, {x3} -> (4/12) / V, {x4, x5} -> (7/144)
    / V with V = 6/12 + 7/144 = 79/144, for S1 and ST alike (no interaction between groups).
    """
    problem = {"num_vars": 5, "names": [f"x{i}" for i in range(1, 6)],
               "bounds": [[0.0, 1.0]] * 5, "groups": ["g12", "g12", "g3", "g45", "g45"]}
    x = design(problem, 1024)
    y = x[:, 0] + x[:, 1] + 2 * x[:, 2] + x[:, 3] * x[:, 4]
    exact = np.array([24.0, 48.0, 7.0]) / 79.0
    res = sobol_indices(problem, y)
    for index in ("S1", "ST"):
        assert np.all((res[f"{index}_low"].values <= exact)
                      & (exact <= res[f"{index}_high"].values)), index


# --------------------------------------------------------------------------- convergence


@pytest.mark.parametrize("problem", [PROBLEM, GROUPED], ids=["parameters", "groups"])
@pytest.mark.parametrize("second_order", [False, True])
def test_salib_design_of_n_is_a_prefix_of_2n(problem, second_order):
    k = rows_per_base_row(problem, second_order)
    for seed in (0, 12345):
        small = design(problem, 64, second_order, seed)
        large = design(problem, 128, second_order, seed)
        assert small.shape[0] == 64 * k
        np.testing.assert_array_equal(large[:64 * k], small)


def test_convergence_at_n_equals_the_n_design():
    y_large = ishigami(design(PROBLEM, 256))
    conv = sobol_convergence(PROBLEM, y_large, n_values=[64, 256], resamples=200)
    assert conv["N"].values.tolist() == [64, 256]
    at_64 = sobol_indices(PROBLEM, ishigami(design(PROBLEM, 64)), resamples=200)
    for name in ("S1", "S1_low", "S1_high", "ST", "ST_low", "ST_high"):
        np.testing.assert_array_equal(conv[name].sel(N=64).values, at_64[name].values)
    default = sobol_convergence(PROBLEM, y_large, resamples=50)
    assert default["N"].values.tolist() == [16, 32, 64, 128, 256]


def test_half_width_is_the_larger_side_and_rule_checks_what_may_exceed_threshold():
    res = xr.Dataset(
        {"S1": ("parameter", [0.5, 0.02, 0.08]), "S1_low": ("parameter", [0.46, 0.0, 0.0]),
         "S1_high": ("parameter", [0.56, 0.05, 0.3]),
         "ST": ("parameter", [0.5, 0.02, 0.08]), "ST_low": ("parameter", [0.46, 0.0, 0.05]),
         "ST_high": ("parameter", [0.56, 0.05, 0.11])},
        coords={"parameter": ["a", "b", "c"]})
    np.testing.assert_allclose(interval_half_width(res, "S1").values, [0.06, 0.03, 0.22])
    # S1 of c: estimate below the threshold but its interval reaches 0.3 -> checked, too wide
    # (widths 0.0601 / 0.0599 straddle 0.06 clear of its rounding in 0.56 - 0.5)
    assert not sobol_stable(res, threshold=0.1, half_width=0.0601)
    assert sobol_stable(res, threshold=0.1, half_width=0.0601, indices=("ST",))
    assert not sobol_stable(res, threshold=0.1, half_width=0.0599, indices=("ST",))
    # nothing above a threshold of 0.6: stable whatever the widths
    assert sobol_stable(res, threshold=0.6, half_width=0.0)


def test_grow_until_stable_stops_on_ishigami():
    evaluated = []

    def evaluate(x):
        evaluated.append(len(x))
        return ishigami(x)

    out = grow_until_stable(PROBLEM, evaluate, n_start=64, n_max=8192, half_width=0.05,
                            threshold=0.1, resamples=500)
    n_final = out.result.attrs["N"]
    assert out.result.attrs["stable"] == 1 and n_final < 8192
    assert bool(out.history["stable"][-1]) and not out.history["stable"][:-1].any()
    assert out.history["N"].values.tolist() == [64 * 2 ** i for i in range(len(evaluated))]
    # every row evaluated once: the first call runs the 64-row design, each later one the new half
    assert sum(evaluated) == n_final * 5 == out.outputs.size
    np.testing.assert_array_equal(out.inputs, design(PROBLEM, n_final))
    np.testing.assert_array_equal(out.outputs, ishigami(out.inputs))
    assert sobol_stable(out.result, 0.1, 0.05)


def test_grow_until_stable_keeps_growing_on_a_noisy_function():
    rng = np.random.default_rng(0)

    def noisy(x):
        # noise 10x the signal's standard deviation: indices near 0 (S1) and 1 (ST), wide
        return np.sin(x[:, 0]) + 10.0 * rng.standard_normal(len(x))

    out = grow_until_stable(PROBLEM, noisy, n_start=32, n_max=256, half_width=0.02,
                            resamples=200)
    assert out.history["N"].values.tolist() == [32, 64, 128, 256]
    assert out.result.attrs["stable"] == 0 and not out.history["stable"].any()


# --------------------------------------------------------------------------- output policies


def test_prepare_output_policies_report_shares():
    problem = {"num_vars": 1, "names": ["x"], "bounds": [[0, 1]]}  # blocks of 3 rows
    heights = np.array([1.0, 2.0, 50.0, 0.5, np.nan, 3.0, 1e4, 0.001, 4.0, 2.0, 2.0, 2.0])
    status = ["ok", "ok", "ok", "ok", "failed", "ok", "censored_above", "censored_below", "ok",
              "ok", "ok", "ok"]
    with pytest.raises(ValueError, match="policy = None"):
        prepare_output(heights, status)
    with pytest.raises(ValueError, match="failed rows"):
        prepare_output(heights, status, policy="cap", h_max=20.0)
    with pytest.raises(ValueError, match="censored rows"):
        prepare_output(heights, status, policy="drop", problem=problem)
    out = prepare_output(heights, status, policy="cap+drop", h_max=20.0, problem=problem)
    assert out.kept_base_rows.tolist() == [True, False, True, True]
    assert out.dropped_share == 0.25 and out.failed_share == 1 / 12
    # above: the censored row (1e4) and 50 m capped at 20 m; below: one row
    assert out.censored_above_share == 2 / 12 and out.censored_below_share == 1 / 12
    assert out.censored_share == 3 / 12
    np.testing.assert_allclose(np.exp(out.output),
                               [1.0, 2.0, 20.0, 20.0, 0.001, 4.0, 2.0, 2.0, 2.0])
    # a cap above a censored bound leaves min(H, h_max) unknown there
    with pytest.raises(ValueError, match="h_max = 20000.0"):
        prepare_output(heights, status, policy="cap+drop", h_max=2e4, problem=problem)
    clean = prepare_output(np.array([1.0, 2.0, 4.0]), ["ok"] * 3)
    np.testing.assert_allclose(clean.output, np.log([1.0, 2.0, 4.0]))
    assert clean.censored_share == clean.dropped_share == 0.0


def test_event_indicator():
    heights = np.array([0.5, 1.0, 2.0, 1e4])
    np.testing.assert_array_equal(event_indicator(heights, 1.0), [1.0, 1.0, 0.0, 0.0])
    status = ["ok", "ok", "ok", "censored_above"]
    np.testing.assert_array_equal(event_indicator(heights, 1.5, status), [1.0, 1.0, 0.0, 0.0])
    with pytest.raises(ValueError, match="undecided"):
        event_indicator(np.array([0.5, 3.0]), 5.0, ["ok", "censored_above"])
    with pytest.raises(ValueError, match=r"heights\[1\] = nan"):
        event_indicator(np.array([0.5, np.nan]), 1.0)
    with pytest.raises(ValueError, match="drop_height = -1"):
        event_indicator(heights, -1)


def test_indices_of_an_event_indicator():
    # heights exp(x1): the event at 1 m is {x1 <= 0}, a function of x1 alone, so ST = 1 for x1
    # and exactly 0 for x2, x3 (their AB rows repeat the A row's output)
    x = design(PROBLEM, 512)
    res = sobol_indices(PROBLEM, event_indicator(np.exp(x[:, 0]), 1.0))
    assert res["ST_low"].values[0] <= 1.0 <= res["ST_high"].values[0]
    # x2, x3: every AB row's output equals its A row's, so their indices are exactly 0
    assert np.all(res["ST"].values[1:] == 0.0) and np.all(res["ST_high"].values[1:] == 0.0)
    assert res["ST_contains_zero"].values.tolist() == [False, True, True]


# --------------------------------------------------------------------------- bad input


Y_OK = ishigami(design(PROBLEM, 16))


@pytest.mark.parametrize(("kwargs", "message"), [
    ({"Y": Y_OK[:-1]}, r"Y has 79 values"),
    ({"Y": np.where(np.arange(80) == 3, np.nan, Y_OK)}, r"Y\[3\] = nan"),
    ({"Y": np.ones(80)}, r"Y is constant"),
    ({"Y": Y_OK.reshape(16, 5)}, r"Y has shape \(16, 5\)"),
    ({"confidence": 1.5}, r"confidence = 1.5"),
    ({"confidence": 0.0}, r"confidence = 0.0"),
    ({"confidence": 1}, r"confidence = 1\b"),
    ({"resamples": 1}, r"resamples = 1"),
    ({"seed": -1}, r"seed = -1"),
    ({"seed": None}, r"seed = None"),
    ({"interval": "normal"}, r"interval = 'normal'"),
    ({"problem": {"names": ["x1", "x2", "x3"]}}, r"missing the key 'num_vars'"),
    ({"problem": {"num_vars": 3}}, r"missing the key 'names'"),
    ({"problem": {"num_vars": 2, "names": ["a", "b", "c"]}}, r"problem\['num_vars'\] = 2"),
    ({"problem": {**PROBLEM, "groups": ["a", "b"]}}, r"problem\['groups'\] = \['a', 'b'\]"),
    ({"problem": [1, 2]}, r"problem = \[1, 2\]"),
])
def test_bad_input_names_argument_and_value(kwargs, message):
    args = {"problem": PROBLEM, "Y": Y_OK, **kwargs}
    with pytest.raises(ValueError, match=message):
        sobol_indices(args.pop("problem"), args.pop("Y"), **args)


def test_bad_growth_and_convergence_arguments():
    with pytest.raises(ValueError, match="n_start = 48"):
        grow_until_stable(PROBLEM, ishigami, 48, 128)
    with pytest.raises(ValueError, match="n_max = 32"):
        grow_until_stable(PROBLEM, ishigami, 64, 32)
    with pytest.raises(ValueError, match=r"n_values = \[4, 32\]"):
        sobol_convergence(PROBLEM, Y_OK, n_values=[4, 32])


# --------------------------------------------------------------------------- Morris


def test_morris_linear_function():
    # f = 2 x1 - x3 on [0, 2] x [0, 1] x [0, 1]: every elementary effect of x1 is 2 per unit
    # of the scaled input, i.e. 4 across its range; x2 has none; sigma 0 (no interaction)
    problem = {"num_vars": 3, "names": ["x1", "x2", "x3"],
               "bounds": [[0.0, 2.0], [0.0, 1.0], [0.0, 1.0]]}
    x = morris_sample.sample(dict(problem), 20, num_levels=4, seed=0)
    res = morris_screening(problem, x, 2 * x[:, 0] - x[:, 2])
    # exact arithmetic on grid points: only rounding (1e-15) separates them from the values
    np.testing.assert_allclose(res["mu_star"].values, [4.0, 0.0, 1.0], atol=1e-12)
    np.testing.assert_allclose(res["mu"].values, [4.0, 0.0, -1.0], atol=1e-12)
    np.testing.assert_allclose(res["sigma"].values, 0.0, atol=1e-12)
    assert list(res["parameter"].values) == ["x1", "x2", "x3"]


def test_morris_groups():
    problem = {**PROBLEM, "bounds": [[0.0, 1.0]] * 3, "groups": ["g1", "g1", "g2"]}
    x = morris_sample.sample(dict(problem), 20, num_levels=4, seed=0)
    res = morris_screening(problem, x, 2 * x[:, 0] - x[:, 2])
    assert list(res["parameter"].values) == ["g1", "g2"]
    # a group moves all its members at once: |2 (+-1) + 0 (+-1)| = 2 for g1, 1 for g2
    np.testing.assert_allclose(res["mu_star"].values, [2.0, 1.0], atol=1e-12)
    assert "groups" in problem and "sample_scaled" not in problem  # not modified by SALib
    with pytest.raises(ValueError, match="Y has 59 values"):
        morris_screening(problem, x, (2 * x[:, 0])[:-1])


# --------------------------------------------------------------------------- figures


def test_plots():
    matplotlib = pytest.importorskip("matplotlib")
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    res = sobol_indices(PROBLEM, ishigami(design(PROBLEM, 256)), resamples=100)
    fig, (ax1, ax2) = plt.subplots(1, 2)
    plot_indices(ax1, res)
    hatched = [p.get_hatch() for p in ax1.patches]
    assert len(hatched) == 6  # 3 parameters x (S1, ST)
    flagged = np.r_[res["S1_contains_zero"].values, res["ST_contains_zero"].values]
    assert [h == "//" for h in hatched] == flagged.tolist()
    conv = sobol_convergence(PROBLEM, ishigami(design(PROBLEM, 256)), resamples=50)
    plot_convergence(ax2, conv)
    assert len(ax2.lines) == 3 and len(ax2.collections) == 3
    plt.close(fig)


# --------------------------------------------------------------------------- coverage (slow)


def _coverage(designs, n, reps, seeds, with_salib):
    """Share of reps whose interval holds the exact index, per method and index (S1, ST)."""
    s1, st = ishigami_exact()
    exact = np.r_[s1, st]
    hits = {"bca": np.zeros(6), "percentile": np.zeros(6), "salib normal": np.zeros(6)}
    for seed in seeds[:reps]:
        y = ishigami(designs(seed))
        for method in ("bca", "percentile"):
            res = sobol_indices(PROBLEM, y, interval=method, seed=seed)
            low = np.r_[res["S1_low"].values, res["ST_low"].values]
            high = np.r_[res["S1_high"].values, res["ST_high"].values]
            hits[method] += (low <= exact) & (exact <= high)
        if with_salib:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                ref = salib_sobol.analyze(dict(PROBLEM), y, calc_second_order=False,
                                          num_resamples=1000, seed=seed + 1)
            hits["salib normal"] += np.abs(np.r_[ref["S1"], ref["ST"]] - exact) <= np.r_[
                ref["S1_conf"], ref["ST_conf"]]
    cover = {m: h / reps for m, h in hits.items()}
    print(f"\ncoverage of 95 % intervals, N = {n}, {reps} reps (S1 x1 x2 x3, ST x1 x2 x3):")
    for m, c in cover.items():
        if m == "salib normal" and not with_salib:
            continue
        print(f"  {m:13s} {np.array2string(c, precision=3)}  mean {c.mean():.3f}")
    return cover


@pytest.mark.slow
def test_coverage_near_nominal_on_iid_base_rows():
    """Bootstrap over base rows is exact in its assumption when base rows are i.i.d.

    400 reps: a coverage of 0.95 is measured to +-0.011 (1 s.e.); per index we accept
    [0.91, 0.99] (about 3.5 s.e., 12 checks), pooled over the 6 indices [0.93, 0.97].
    N = 256 keeps 400 reps within about a minute.
    """
    reps, n = 400, 256
    cover = _coverage(lambda s: iid_design(PROBLEM, n, np.random.default_rng(s)), n, reps,
                      range(10_000, 10_400), with_salib=True)
    for method in ("bca", "percentile"):
        assert np.all((cover[method] >= 0.91) & (cover[method] <= 0.99)), method
        assert 0.93 <= cover[method].mean() <= 0.97, method


@pytest.mark.slow
def test_coverage_on_salib_sobol_design_is_conservative_from_1024():
    """On the scrambled Sobol' design the base rows are not i.i.d.; from N = 1024 the estimates
    vary 2-3x less between scrambles than the bootstrap assumes, so the intervals over-cover.

    200 reps; we accept coverage >= 0.95 for every index (measured 1.000 in exploration).
    """
    n = 1024
    cover = _coverage(lambda s: design(PROBLEM, n, seed=s), n, 200, range(20_000, 20_200),
                      with_salib=True)
    for method in ("bca", "percentile"):
        assert np.all(cover[method] >= 0.95), method


@pytest.mark.slow
def test_coverage_on_salib_sobol_design_fails_for_s1_x3_at_512():
    """Known limitation (documented): at N = 512 SALib's Sobol' design gives S1 of x3 (exactly
    0) a scramble-to-scramble spread larger than the bootstrap's, and its intervals under-cover.

    Measured 0.825-0.84 in exploration (seeds 1000-1199, 3000-3199) and 0.895 on the first 200
    seeds of this range; 400 reps measure the coverage to +-0.017 (1 s.e. at 0.87), and we check
    < 0.92, about 3 s.e. below nominal, so the documentation's warning stays true while the other
    indices over-cover.
    """
    n = 512
    cover = _coverage(lambda s: design(PROBLEM, n, seed=s), n, 400, range(30_000, 30_400),
                      with_salib=False)
    for method in ("bca", "percentile"):
        assert cover[method][2] < 0.92, method
        assert np.all(np.delete(cover[method], 2) >= 0.93), method
