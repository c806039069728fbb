"""Designs and the map to inputs: reproducible by sample index, marginals and copula as declared."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest
import scipy.stats

from skidmc.ensemble.sampling import (
    MC_BLOCK,
    StudySampler,
    UniformDesign,
    salib_problem,
    seed_sequence,
    transform,
)
from skidmc.ensemble.study import RATE_AT_REFERENCE, U_TAIL, parse_study

STUDY = """
[study]
name = "t"
[[scenes]]
name = "quartz"
preset = "paper-quartz"
[[scenes]]
name = "gold"
preset = "paper-gold"
[uncertain.mu]
distribution = "lognorm"
s = 0.2
relative = true
source = "test"
[uncertain."target.conductivity"]
distribution = "truncnorm"
a = -2
b = 2
loc = 1.0
scale = 0.1
relative = true
source = "test"
[uncertain."kinetics.activation_temperature"]
distribution = "uniform"
loc = "15000 K"
scale = "19000 K"
source = "test"
[uncertain."kinetics.rate_at_reference"]
distribution = "lognorm"
s = 1.0
relative = true
reference_temperature = "575 K"
source = "test"
[uncertain.flow_stress]
distribution = "beta"
a = 2
b = 3
loc = "25000 psi"
scale = "8000 psi"
source = "test"
[[correlation]]
keys = ["mu", "flow_stress"]
spearman = 0.6
source = "test"
[design]
method = "mc"
n = 64
seed = 7
"""


def _study(method="mc", n=64, text=STUDY):
    text = text.replace('method = "mc"', f'method = "{method}"').replace("n = 64", f"n = {n}")
    if method == "saltelli":  # Sobol indices need independent inputs
        text = text[:text.index("[[correlation]]")] + text[text.index("[design]"):]
    return parse_study(text)


# --- seeds -------------------------------------------------------------------------------------


@pytest.mark.parametrize("bad", [None, -1, 1.5, True, "1"])
def test_seed_must_be_a_non_negative_integer(bad):
    with pytest.raises(ValueError, match="seed"):
        seed_sequence(bad)


def test_seeds_and_streams_differ():
    # SALib's `if seed:` made seed 0 unseeded; here 0 is a seed like any other.
    draws = [np.random.default_rng(seed_sequence(s, *k)).random(4)
             for s, k in [(0, ()), (1, ()), (0, (0, 0)), (0, (0, 1))]]
    for i in range(len(draws)):
        for j in range(i):
            assert not np.array_equal(draws[i], draws[j])
    again = np.random.default_rng(seed_sequence(0)).random(4)
    assert np.array_equal(again, draws[0])


# --- designs --------------------------------------------------------------------------------------


@pytest.mark.parametrize("method,n", [("mc", 2 * MC_BLOCK + 37), ("lhs", 300), ("sobol", 256),
                                      ("saltelli", 32)])
def test_any_slice_equals_the_same_rows_of_the_whole_design(method, n):
    design = UniformDesign(method, n, 5, seed=11)
    whole = design.rows(0, design.n_rows)
    assert whole.shape == (design.n_rows, 5)
    assert np.all((whole >= 0) & (whole < 1))
    fresh = UniformDesign(method, n, 5, seed=11)
    edges = [0, 1, 7, MC_BLOCK - 1, MC_BLOCK + 3, design.n_rows - 5, design.n_rows]
    edges = sorted({min(e, design.n_rows) for e in edges})
    for a, b in itertools.pairwise(edges):
        assert np.array_equal(fresh.rows(a, b), whole[a:b])  # bitwise, any order of slices
    assert not np.array_equal(UniformDesign(method, n, 5, seed=12).rows(0, 4), whole[:4])


def test_mc_samples_do_not_depend_on_n():
    small = UniformDesign("mc", 10, 3, seed=5).rows(0, 10)
    large = UniformDesign("mc", 5000, 3, seed=5).rows(0, 10)
    assert np.array_equal(small, large)


def test_sobol_prefix_property():
    small = UniformDesign("sobol", 64, 3, seed=5).rows(0, 64)
    large = UniformDesign("sobol", 256, 3, seed=5).rows(0, 64)
    assert np.array_equal(small, large)


def test_lhs_is_stratified():
    n = 200
    u = UniformDesign("lhs", n, 4, seed=3).rows(0, n)
    for j in range(4):
        assert np.array_equal(np.sort(np.floor(u[:, j] * n)), np.arange(n))


def test_saltelli_matches_salib_problem_and_row_count():
    study = _study("saltelli", n=16)
    d = len(study.keys)
    assert StudySampler(study).n_rows == study.n_rows == 16 * (2 * d + 2)
    problem = salib_problem(study)
    assert problem["names"] == list(study.keys) and problem["num_vars"] == d


# --- inputs ---------------------------------------------------------------------------------------


def test_batch_composition_does_not_change_a_sample():
    study = _study("mc", n=300)
    u = StudySampler(study).design.rows(0, 300)
    whole = transform(study, u)
    for a, b in [(0, 1), (5, 17), (100, 300)]:
        part = transform(study, u[a:b])
        for scene_whole, scene_part in zip(whole, part):
            for key in scene_whole:
                assert np.array_equal(scene_part[key], scene_whole[key][a:b]), key


def test_marginals_follow_the_declared_distributions():
    study = _study("mc", n=4000)
    draws = StudySampler(study).draw(0, 4000)
    for sc, values in zip(study.scenes, draws):
        for key, dist in sc.uncertain.items():
            nominal = sc.nominal(key)
            x = values[key] / nominal if dist.relative else values[key]
            p = scipy.stats.kstest(x, dist.frozen.cdf).pvalue
            assert p > 1e-4, (sc.name, key, p)


def test_rank_correlation_of_the_copula():
    study = _study("lhs", n=4000)
    quartz = StudySampler(study).draw(0, 4000)[0]
    rs = scipy.stats.spearmanr(quartz["mu"], quartz["flow_stress"]).statistic
    assert rs == pytest.approx(0.6, abs=0.03)
    # Uncorrelated pairs stay uncorrelated.
    other = scipy.stats.spearmanr(quartz["mu"], quartz["target.conductivity"]).statistic
    assert abs(other) < 0.05


def test_prefactor_follows_the_rate_at_reference():
    study = _study("mc", n=500)
    for values in StudySampler(study).draw(0, 500):
        z = values[RATE_AT_REFERENCE] * np.exp(values["kinetics.activation_temperature"] / 575.0)
        assert np.array_equal(values["kinetics.prefactor"], z)
        # The compensation effect: ln Z rises with E/R (rate at T_ref independent of E/R).
        r = np.corrcoef(values["kinetics.activation_temperature"],
                        np.log(values["kinetics.prefactor"]))[0, 1]
        assert r > 0.8


def test_samples_stay_within_the_checked_quantiles():
    study = _study("mc", n=64)
    u = np.array([[0.0] * len(study.keys), [1.0] * len(study.keys)])  # the design's extremes
    for sc, values in zip(study.scenes, transform(study, u)):
        for key, dist in sc.uncertain.items():
            lo, hi = dist.ppf(np.array([U_TAIL, 1 - U_TAIL]), sc.nominal(key))
            assert np.all(np.isfinite(values[key]))
            assert lo <= values[key].min() and values[key].max() <= hi * (1 + 1e-12)
        assert math.isfinite(values["kinetics.prefactor"].max())


def test_transform_checks_the_column_count():
    study = _study()
    with pytest.raises(ValueError, match="columns"):
        transform(study, np.zeros((3, 2)))


# --- nested (epistemic x aleatory) design ---------------------------------------------------------


def test_nested_design_rows_are_outer_times_inner_and_chunk_independent():
    from skidmc.ensemble.sampling import NestedDesign

    design = NestedDesign("lhs", 5, 7, outer_columns=[1, 3], inner_columns=[0, 2], seed=11)
    full = design.rows(0, design.n_rows)
    assert full.shape == (35, 4)
    # Row r = (e, a): the epistemic columns repeat within an outer draw, the aleatory columns
    # repeat across outer draws (common random numbers).
    grid = full.reshape(5, 7, 4)
    assert np.array_equal(grid[:, :, [1, 3]], np.repeat(grid[:, :1, [1, 3]], 7, axis=1))
    assert np.array_equal(grid[:, :, [0, 2]], np.repeat(grid[:1, :, [0, 2]], 5, axis=0))
    # Each level is a Latin hypercube of its own size: one point per stratum in every column.
    for level, n in ((grid[:, 0, [1, 3]], 5), (grid[0, :, [0, 2]].T, 7)):
        for column in level.T:
            assert sorted(np.floor(column * n).astype(int)) == list(range(n))
    # Any chunking gives the same rows.
    parts = [design.rows(a, min(a + 6, 35)) for a in range(0, 35, 6)]
    assert np.array_equal(np.vstack(parts), full)


def test_nested_design_refuses_saltelli():
    from skidmc.ensemble.sampling import NestedDesign

    with pytest.raises(ValueError, match="saltelli"):
        NestedDesign("saltelli", 2, 2, [0], [1], seed=0)
