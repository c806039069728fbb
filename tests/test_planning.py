"""Planning drops: the next drop's criterion, the sequential plan, up-down, Langlie and Neyer."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from scipy import special

from skidmc.analysis import fit_probit
from skidmc.analysis.planning import (
    Langlie,
    Neyer,
    SequentialPlan,
    UpDown,
    _d_optimal,
    _expected_variance,
    _probit_mle,
    _Tracker,
    classical_designs,
    next_drop,
    simulate_sequence,
)
from skidmc.analysis.posterior import (
    NormalPrior,
    _build_grid,
    physics_prior,
    posterior_from_prior,
)
from skidmc.cli import main

PRIOR = NormalPrior((math.log(10.0), 0.4), (math.log(0.38), 0.5), "ft")


def test_up_down_steps_one_level():
    d = UpDown(10.0, 0.2)
    assert d.next_height() == pytest.approx(10.0)
    d.add(10.0, True)
    assert d.next_height() == pytest.approx(10.0 * math.exp(-0.2))
    d.add(d.next_height(), False)
    assert d.next_height() == pytest.approx(10.0)


def test_langlie_by_hand():
    # limits 1 and 100: first at their log-midpoint, 10; after a go no earlier balance exists,
    # so halfway (in ln h) to the lower limit, sqrt(10); after a no-go there, tests 1-2 balance
    # (one go, one no-go): halfway between test 1 and test 2, 10^0.75; after a go there, only
    # test 3 alone is unbalanced and tests 2-3 balance: halfway between them, 10^0.625.
    d = Langlie(1.0, 100.0)
    expected = [10.0, 10**0.5, 10**0.75, 10**0.625]
    outcomes = [True, False, True]
    for i, h in enumerate(expected):
        assert d.next_height() == pytest.approx(h, rel=1e-12)
        if i < len(outcomes):
            d.add(h, outcomes[i])


def test_neyer_part_one_and_two_by_hand():
    # mu range 1-100 (ln 0 to 4.605), sigma guess 0.5: first at 10; after a no-go the next is
    # the largest of (ln 100 + ln 10)/2, ln 10 + 2 (0.5) and 2 ln 10 - ln 10: 10^1.5; after a go
    # there the gap between lowest go and highest no-go (ln 10^0.5 = 1.15) exceeds sigma_g, so
    # the next is its midpoint, 10^1.25.
    d = Neyer(1.0, 100.0, 0.5)
    assert d.next_height() == pytest.approx(10.0)
    d.add(10.0, False)
    assert d.next_height() == pytest.approx(10**1.5)
    d.add(10**1.5, True)
    assert d.next_height() == pytest.approx(10**1.25)


def test_d_optimal_reaches_the_optimal_design_points():
    # The locally D-optimal two-point probit design sits at m +- 1.1381 s (equal weights); by the
    # Kiefer-Wolfowitz equivalence theorem the variance function is largest at those points, so
    # after many drops there, the next D-optimal drop is one of them (the grid of k has step
    # 0.01, hence the tolerance).
    x = np.array([-1.1381] * 50 + [1.1381] * 50)
    k = _d_optimal(x, None, 0.0, 1.0)
    assert abs(abs(k) - 1.1381) < 0.011


def test_own_mle_matches_fit_probit():
    # Neyer's part 3 uses a small Newton fit at every drop; it must give fit_probit's MLE
    # (both converge to the unique maximum of a concave function: 1e-6).
    rng = np.random.default_rng(3)
    x = rng.normal(2.0, 0.5, 40)
    y = rng.random(40) < special.ndtr((x - 2.0) / 0.4)
    fit = fit_probit(np.exp(x), y)
    mu, sigma = _probit_mle(x, y)
    assert mu == pytest.approx(fit.mu, abs=1e-6) and sigma == pytest.approx(fit.sigma, rel=1e-6)


def test_expected_variance_is_exact():
    # The criterion's closed form against the two possible posteriors computed separately on a
    # fine grid: E[Var] = P(go) Var(. | go) + P(no-go) Var(. | no-go). Both use grids, of
    # different boxes and sizes: 1 % relative.
    h, y = np.array([11.0, 9.25, 11.0]), np.array([True, False, True])
    grid = _build_grid(PRIOR, np.log(h), y, shape=(81, 121))
    x = math.log(14.0)
    var_now, expected, p1 = _expected_variance(grid, np.array([x]), 0.0)
    parts = []
    for went in (True, False):
        post = posterior_from_prior(np.append(h, 14.0), np.append(y, went), PRIOR,
                                    grid=(161, 401), draws=1)
        parts.append(post._grid.moments(0.0)[1])
    brute = p1[0] * parts[0] + (1 - p1[0]) * parts[1]
    assert expected[0] == pytest.approx(brute, rel=0.01)
    assert var_now > expected[0]


def test_next_drop_without_data_is_at_the_prior_median():
    # With no drops and a prior symmetric in ln H50 the criterion is symmetric about the prior
    # median; a single drop teaches most where P(go) = 1/2. Tolerance: the refined candidate
    # step (about 0.06 prior sd).
    plan = next_drop([], [], PRIOR)
    assert abs(math.log(plan.height) - PRIOR.location[0]) < 0.05
    assert plan.p_go == pytest.approx(0.5, abs=0.03)
    assert plan.sd_expected < plan.sd_now and plan.expected_gain > 0


def test_next_drop_respects_limits_and_candidates():
    plan = next_drop([11.0, 9.25, 11.0], [1, 0, 1], PRIOR, limits=(1.0, 9.0))
    assert 1.0 <= plan.height <= 9.0
    plan = next_drop([11.0, 9.25, 11.0], [1, 0, 1], PRIOR, candidates=[5.0, 10.0, 20.0])
    assert plan.height in (5.0, 10.0, 20.0)
    with pytest.raises(ValueError, match="p"):
        next_drop([], [], PRIOR, p=1.5)
    with pytest.raises(ValueError, match="heights"):
        next_drop([-1.0], [1], PRIOR)


def test_tracker_matches_the_fine_posterior():
    # The sequential procedures' small grid (24 x 40) against probit_posterior's (161 x 401)
    # after a simulated 60-drop sequence: the 90 % interval of ln H50 to 0.005 (0.5 % of a
    # height; the stopping rule compares it with +-10 %).
    rng = np.random.default_rng(11)
    x = np.log(10.0) + 0.4 * rng.normal(size=60)
    y = rng.random(60) < special.ndtr((x - math.log(10.0)) / 0.38)
    t = _Tracker(PRIOR)
    for xi, yi in zip(x, y):
        t.add(xi, yi)
    post = posterior_from_prior(np.exp(x), y, PRIOR, credibility=0.9, draws=1)
    np.testing.assert_allclose(t.h50(0.9), np.log(post.quantile(0.5)), atol=0.005)


def test_sequential_plan_stops_by_its_rule():
    truth = (math.log(12.0), 0.3)
    plan = SequentialPlan(PRIOR, budget=200)
    r = simulate_sequence(plan, PRIOR, truth, np.random.default_rng(2), budget=200,
                          also=(0.25,))
    assert r.stopped and r.n < 200
    assert r.high <= 1.1 * r.h50 + 1e-9 and r.low >= 0.9 * r.h50 - 1e-9
    n25 = r.first_met[0.25][0]
    assert n25 <= r.n
    budgeted = simulate_sequence(SequentialPlan(PRIOR, budget=5), PRIOR, truth,
                                 np.random.default_rng(2), budget=5)
    assert budgeted.n == 5 and not budgeted.stopped


@pytest.mark.parametrize("name", ["up-down", "Langlie", "Neyer"])
def test_classical_designs_run(name):
    design = classical_designs(PRIOR)[name]
    r = simulate_sequence(design, PRIOR, (math.log(8.0), 0.4), np.random.default_rng(4),
                          budget=40)
    assert r.n == len(r.heights) and np.all(r.heights > 0)
    assert r.low < r.h50 < r.high


@pytest.mark.slow
def test_bayesian_coverage_with_truths_from_the_prior():
    # Truths drawn from the prior the posterior uses: the 90 % interval covers with probability
    # exactly 0.9 whatever the (adaptive) design; checked after 8 planned drops over 300 truths
    # (binomial sd 0.017; 3 sd allowed).
    rng = np.random.default_rng(21)
    m, sigma = PRIOR.sample(300, rng)
    covered = 0
    for mj, sj in zip(m, sigma):
        r = simulate_sequence(SequentialPlan(PRIOR, budget=8), PRIOR, (mj, sj), rng, budget=8)
        covered += r.low <= math.exp(mj) <= r.high
    assert abs(covered / 300 - 0.9) < 3 * math.sqrt(0.09 / 300)


def test_cli_plan_experiment(capsys):
    assert main(["plan", "--experiment", "alumina_50_80", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    expected = next_drop([11.0, 9.25, 11.0], [True, False, True], physics_prior("alumina_50_80"))
    assert out["height"] == pytest.approx(expected.height, rel=1e-9)
    assert out["n"] == 3 and out["n_go"] == 2
    assert main(["plan", "--experiment", "alumina_50_80"]) == 0
    text = capsys.readouterr().out
    assert "next drop:" in text and "current H50:" in text and "expected gain" in text
    assert main(["plan", "--experiment", "alumina_50_80", "--discrepancy", "0.6"]) == 0
    assert "discrepancy sd 0.6" in capsys.readouterr().out
    assert main(["plan", "--experiment", "alumina_50_80", "--discrepancy", "-1"]) == 2
    assert "discrepancy_sd" in capsys.readouterr().err


def test_cli_plan_csv(tmp_path, capsys):
    path = tmp_path / "drops.csv"
    path.write_text("# my drops\nheight_m,go\n3.35,1\n2.82,0\n3.35,1\n", encoding="utf-8")
    assert main(["plan", str(path), "--units", "ft", "--target", "alumina_50_80",
                 "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["n"] == 3 and out["units"] == "ft" and out["height"] > 0
    bad = tmp_path / "bad.csv"
    bad.write_text("height_ft,go\n3,maybe\n", encoding="utf-8")
    assert main(["plan", str(bad)]) == 2
    assert "maybe" in capsys.readouterr().err
    assert main(["plan"]) == 2
