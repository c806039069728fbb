"""The go-probability report on synthetic ensembles whose answers are known."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
import xarray as xr
from scipy import stats

from skidmc.analysis.report import FT, analyse_scene, ensemble_sobol, scene_outcomes
from skidmc.workflows.reporting.ensemble import write_report

H50_FT, SIGMA = 2.0, 0.4


def _ensemble(n=400, seed=1, h_max_ft=6.0, nested=None):
    """An ensemble of log-normal critical heights (median 2 ft, sigma 0.4) in the layout of
    skidmc.analysis.open_ensemble: one scene "quartz", statuses, one failed and one unfinished
    sample, heights above h_max censored "above" at it."""
    rng = np.random.default_rng(seed)
    shape = (n,) if nested is None else (nested, n)
    h_ft = H50_FT * np.exp(SIGMA * rng.standard_normal(shape))
    status = np.where(h_ft > h_max_ft, "censored_above", "ok").astype(object)
    h_ft = np.minimum(h_ft, h_max_ft)
    flat_status = status.reshape(-1)
    flat_h = h_ft.reshape(-1)
    flat_status[0], flat_h[0] = "failed", np.nan
    flat_status[1], flat_h[1] = "", np.nan  # unfinished (masked by open_ensemble)
    dims = ("scene", "sample") if nested is None else ("scene", "epistemic", "sample")
    return xr.Dataset(
        {"critical_height": (dims, (h_ft * FT)[None]), "status": (dims, status[None])},
        coords={"scene": ["quartz"]},
        attrs={"study_name": "synthetic", "design_method": "mc", "design_n": n, "seed": seed,
               "solver_rtol": 1e-2, "solver_tier": "full", "solver_h_max": h_max_ft * FT})


def test_outcomes_count_every_status():
    ds = _ensemble()
    out = scene_outcomes(ds, "quartz")
    n_above = int((ds.status.values == "censored_above").sum())
    assert (out["n_failed"], out["n_unfinished"], out["n_above"]) == (1, 1, n_above)
    assert out["n"] == 400 - 2 and out["heights_m"].size == out["n"]
    assert n_above > 0  # the test exercises censoring


def test_fit_recovers_the_lognormal():
    a = analyse_scene(_ensemble(), "quartz")
    n = a.counts["n"]
    est, low, high = a.predicted_h50()
    # Estimates within 3 standard errors of the truth (SE of ln H50 = sigma/sqrt(n), of sigma
    # ~ sigma/sqrt(2n)); the intervals' coverage itself is measured in tests/test_gonogo.py.
    assert abs(math.log(est / H50_FT)) < 3 * SIGMA / math.sqrt(n)
    s_est, s_low, s_high = a.fit.intervals["sigma"]
    assert abs(s_est - SIGMA) < 3 * SIGMA / math.sqrt(2 * n)
    # The 95 % interval of ln H50 is about 2 x 1.96 standard errors wide.
    width = math.log(high / low)
    assert width == pytest.approx(2 * 1.96 * s_est / math.sqrt(n), rel=0.15)
    assert "consistent" in a.fit.verdict


def test_go_curve_follows_the_lognormal_cdf_and_stops_at_the_censoring_bound():
    a = analyse_scene(_ensemble(n=2000), "quartz")
    curve = a.curve
    h = curve["height"].values
    inside = curve["identified"].values.astype(bool)
    truth = stats.norm.cdf(np.log(h / H50_FT) / SIGMA)
    # The simultaneous band covers the true CDF (95 %: a fixed seed, not cherry-picked).
    assert np.all(curve["p_go_low"].values[inside] <= truth[inside] + 1e-12)
    assert np.all(truth[inside] <= curve["p_go_high"].values[inside] + 1e-12)
    assert not inside[h > 6.0].any()  # above the censoring bound nothing is identified


def test_nested_design_gives_one_curve_per_epistemic_draw():
    ds = _ensemble(n=300, nested=8)
    a = analyse_scene(ds, "quartz")
    fam = a.epistemic
    assert fam.sizes["epistemic"] == 8
    # Each draw's H50 is the median of its own samples (exact heights here are all below 6 ft
    # except the censored ones, which sort last).
    h = ds.critical_height.values[0] / FT
    st = ds.status.values[0].astype(str)
    for e in (2, 5):
        ok = (st[e] != "") & (st[e] != "failed")
        expect = np.median(np.where(st[e][ok] == "censored_above", np.inf, h[e][ok]))
        assert fam["h50"].values[e] == pytest.approx(expect)
    assert np.all(fam["p_go_low"].values <= fam["p_go_high"].values + 1e-12)
    assert a.curve.attrs["pooled"] == 1 and "mixes" in a.curve.attrs["note"]


def test_experiment_is_scored_and_bracketed():
    a = analyse_scene(_ensemble(), "quartz", experiment="quartz")
    # Table III: ten drops; the probit maximum does not exist (no overlap), so the experimental
    # H50 is the report's 1.8 ft with likelihood-ratio bounds around it.
    assert a.scores.n == 10
    est, low, high = a.experimental_h50()
    assert est == 1.8 and low < 1.8 < high
    assert not a.experimental_fit.exists
    assert a.updown.h50 == pytest.approx(math.sqrt(1.5 * 2.12), rel=1e-12)


def test_sobol_on_a_saltelli_ensemble_ranks_the_inputs():
    from SALib.sample import sobol as saltelli

    keys = ["mu", "flow_stress", "angle"]
    problem = {"num_vars": 3, "names": keys, "bounds": [[0.0, 1.0]] * 3}
    x = saltelli.sample(problem, 256, calc_second_order=False, scramble=True, seed=3)
    # ln H = 2 x0 + 0.5 x1 (angle does not matter): ST(mu) = 16/17, ST(flow) = 1/17, ST(angle) = 0.
    height = np.exp(2.0 * x[:, 0] + 0.5 * x[:, 1])
    status = np.full(height.shape, "ok", dtype=object)
    ds = xr.Dataset({"critical_height": (("scene", "sample"), height[None]),
                     "status": (("scene", "sample"), status[None])},
                    coords={"scene": ["s"]},
                    attrs={"design_method": "saltelli", "design_keys": keys,
                           "saltelli_second_order": 0, "solver_h_max": 1e4})
    # Curves and fits of a saltelli design use its base rows only: N of the N (d + 2) rows.
    assert scene_outcomes(ds, "s")["n"] == 256
    res = ensemble_sobol(ds, "s", resamples=200)
    st = dict(zip(keys, res["ST"].values))
    assert st["mu"] > st["flow_stress"] > st["angle"]
    assert res["ST_low"].sel(parameter="mu") < 16 / 17 < res["ST_high"].sel(parameter="mu")
    assert bool(res["ST_contains_zero"].sel(parameter="angle"))
    assert res.attrs["censored_share"] == 0.0
    # The event at a drop from the median height: decided by mu and the conductivity alike
    # (their ln H terms are monotone, so each moves the event), never by the angle.
    event = ensemble_sobol(ds, "s", resamples=200, drop_height=float(np.median(height)))
    assert "event" in event.attrs["output"]
    assert event["ST"].sel(parameter="mu") > event["ST"].sel(parameter="flow_stress") > 0.0
    assert bool(event["ST_contains_zero"].sel(parameter="angle"))


def test_sobol_leaves_out_a_design_column_the_scene_does_not_vary():
    from SALib.sample import sobol as saltelli

    keys = ["mu", "flow_stress", "target.conductivity"]
    problem = {"num_vars": 3, "names": keys, "bounds": [[0.0, 1.0]] * 3}
    x = saltelli.sample(problem, 64, calc_second_order=False, scramble=True, seed=4)
    # Scene "a" samples all three columns; scene "b" (a layered target, say) holds its
    # conductivity: its stored input is one value on every row, whatever the design column says.
    ln_a = 2.0 * x[:, 0] + 0.5 * x[:, 1] + 0.3 * x[:, 2]
    ln_b = 2.0 * x[:, 0] + 0.5 * x[:, 1]
    k = np.stack([10.0 + x[:, 2], np.full(len(x), 317.0)])
    ds = xr.Dataset({"critical_height": (("scene", "sample"), np.exp(np.stack([ln_a, ln_b]))),
                     "status": (("scene", "sample"), np.full((2, len(x)), "ok", dtype=object)),
                     "target.conductivity": (("scene", "sample"), k)},
                    coords={"scene": ["a", "b"]},
                    attrs={"design_method": "saltelli", "design_keys": keys,
                           "saltelli_second_order": 0, "solver_h_max": 1e4})
    a = ensemble_sobol(ds, "a", resamples=50)
    assert list(a["parameter"].values) == keys and a.attrs["not_varied"] == ""
    b = ensemble_sobol(ds, "b", resamples=50)
    assert list(b["parameter"].values) == keys[:2]
    assert b.attrs["not_varied"] == "target.conductivity"
    # the inputs kept have the indices they have with the column in: leaving it out is exact
    full = ensemble_sobol(ds.drop_vars("target.conductivity"), "b", resamples=50)
    assert full["ST"].sel(parameter="target.conductivity") == 0.0
    np.testing.assert_array_equal(b["ST"].values, full["ST"].sel(parameter=keys[:2]).values)
    conv = ensemble_sobol(ds, "b", resamples=50, convergence=True)
    assert list(conv["parameter"].values) == keys[:2]


def test_sobol_refuses_other_designs():
    with pytest.raises(ValueError, match="design_method = 'mc'"):
        ensemble_sobol(_ensemble(), "quartz")


def test_write_report_writes_every_file(tmp_path):
    out = write_report(_ensemble(), tmp_path, source="synthetic.h5",
                       experiments={"quartz": "quartz"})
    names = {p.name for p in out["files"]}
    assert {"go_quartz.png", "h50.png", "qq.png", "summary.json", "summary.md",
            "curves.h5"} <= names
    summary = json.loads((tmp_path / "summary.json").read_text())
    scene = summary["scenes"][0]
    assert scene["experiment"]["report_h50_ft"] == 1.8
    assert scene["counts"]["n_failed"] == 1
    assert "| quartz | quartz |" in (tmp_path / "summary.md").read_text()
    curves = xr.open_dataset(tmp_path / "curves.h5", engine="h5netcdf")
    assert "p_go_quartz" in curves and curves["height_ft_quartz"].attrs["units"] == "ft"


def test_summary_states_skill_against_base_rate_and_coin(tmp_path):
    # The synthetic ensemble (H50 2 ft, sigma 0.4) scored on the report's ten quartz drops:
    # the summary's skill row must carry the scores of skidmc.analysis.skill and the references.
    from skidmc.analysis.skill import skill_scores

    out = write_report(_ensemble(), tmp_path, source="synthetic.h5",
                       experiments={"quartz": "quartz"})
    a = analyse_scene(_ensemble(), "quartz", experiment="quartz")
    k = skill_scores(a.scores.p_go, a.experiment.drops.went)
    text = (tmp_path / "summary.md").read_text()
    skill = text[text.index("## Skill of the predicted go curve"):]
    row = next(line for line in skill.splitlines() if line.startswith("| quartz | 10 (4) |"))
    assert f"{k.log_score:.3g}" in row and f"{k.log_score_base_rate:.3g}" in row
    assert "0.693" in row and "0.25" in row
    assert k.verdict("log") in row and k.verdict("brier") in row
    # Ten drops: a reliability diagram.
    assert "reliability_quartz.png" in {p.name for p in out["files"]}


def test_figures_count_drops_per_height_and_name_the_report_lines():
    # The report's ten quartz drops sit at two heights: one marker per height and outcome, each
    # with its count (Table III: 5 no-go at 1.5 ft; 4 go and 1 no-go at 2.12 ft), the observed
    # go fraction 4/5 at 2.12 ft, and the report's 1.8 ft (up-and-down) and 1.25 ft (Table VIII).
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from skidmc.workflows.reporting.ensemble import _draw_drops, _report_lines

    a = analyse_scene(_ensemble(), "quartz", experiment="quartz")
    fig, ax = plt.subplots()
    _draw_drops(ax, a.experiment.drops)
    _report_lines(ax, a)
    assert sorted(t.get_text() for t in ax.texts) == ["1 no-go", "4 go", "5 no-go"]
    fractions = [line for line in ax.get_lines() if line.get_marker() == "D"]
    assert len(fractions) == 1 and fractions[0].get_ydata()[0] == pytest.approx(0.8)
    labels = [line.get_label() for line in ax.get_lines()]
    assert any("up-and-down" in lab for lab in labels)
    assert any("Table VIII" in lab for lab in labels)
    assert not any("(updown)" in lab or "lower_bound" in lab for lab in labels)
    plt.close(fig)


def test_sobol_figure_ranks_inputs_and_names_them_with_units():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from skidmc.analysis.sensitivity import input_label, plot_indices

    assert input_label("target.conductivity") == "target conductivity k [W/(m K)]"
    assert input_label("mu") == "friction coefficient mu [-]"
    assert input_label("kinetics.rate_at_reference") == "reaction rate at T_ref [1/s]"
    res = xr.Dataset(
        {k: ("parameter", v) for k, v in {
            "S1": [0.1, 0.6, 0.2], "S1_low": [0.0, 0.5, 0.1], "S1_high": [0.2, 0.7, 0.3],
            "ST": [0.1, 0.7, 0.2], "ST_low": [0.0, 0.6, 0.1], "ST_high": [0.2, 0.8, 0.3],
            "S1_contains_zero": [True, False, False], "ST_contains_zero": [True, False, False],
        }.items()},
        coords={"parameter": ["angle", "mu", "flow_stress"]},
        attrs={"interval": "bca", "confidence": 0.95, "N": 512})
    fig, ax = plt.subplots()
    plot_indices(ax, res)
    names = [t.get_text() for t in ax.get_yticklabels()]
    # inverted y axis: rank 1 (largest ST) drawn on top, i.e. first tick label
    assert names == ["friction coefficient mu [-]", "billet flow stress sigma [Pa]",
                     "impact angle phi [deg]"]
    assert "bootstrap BCa 95 % intervals" in ax.get_title()
    plt.close(fig)


def test_convergence_plot_gives_every_input_its_own_colour():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.colors import to_rgb

    from skidmc.analysis.sensitivity import plot_convergence

    names = [f"x{i}" for i in range(13)]
    shape = (3, len(names))
    vals = np.zeros(shape)
    conv = xr.Dataset({k: (("N", "parameter"), vals) for k in ("ST", "ST_low", "ST_high")},
                      coords={"N": [128, 256, 512], "parameter": names})
    fig, ax = plt.subplots()
    plot_convergence(ax, conv, index="ST", legend=False)
    colours = {to_rgb(line.get_color()) for line in ax.get_lines()}
    assert len(colours) == len(names)
    plt.close(fig)


def test_summary_says_whether_the_experiment_lies_in_the_band(tmp_path):
    # Synthetic H50 = 2 ft with a narrow sampling interval (400 samples): the report's 1.8 ft
    # lies below it; the row also carries the report's own calculation (Table VIII: 1.25 ft).
    from skidmc.workflows.reporting.ensemble import _inside_band

    a = analyse_scene(_ensemble(), "quartz", experiment="quartz")
    _, low, high = a.predicted_h50()
    assert 1.8 < low < 2.0 < high  # the premise: 400 samples pin H50 within a few percent
    assert _inside_band(a) == "no (below the band)"
    write_report(_ensemble(), tmp_path, source="synthetic.h5", experiments={"quartz": "quartz"})
    row = next(line for line in (tmp_path / "summary.md").read_text().splitlines()
               if line.startswith("| quartz | quartz |"))
    assert "| 1.25 | no (below the band) |" in row
