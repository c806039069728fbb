"""The handling hazard under a calibration's posterior (issue 40, G): the epistemic draws are
stored posterior draws (their values and their correlation), a missing posterior or input is
refused naming the key and the value, and the run on the stand-in solver of test_handling
matches its closed form at every posterior draw."""

from __future__ import annotations

import hashlib
import json
import math
from pathlib import Path

import numpy as np
import pytest
from scipy import stats
from test_handling import S_TOTAL, STUDY, WEIGHTS, StandIn, exact

from skidmc.ensemble.hazard_study import load_hazard_study, parse_hazard_study
from skidmc.ensemble.study_model import StudyError
from skidmc.workflows.hazard import load, run_hazard_study
from skidmc.workflows.hazard_posterior import read_posterior, thinned_indices

ROOT = Path(__file__).resolve().parents[1]
Q = "kinetics.heat_of_reaction"
T = "kinetics.activation_temperature"
CHAINS, LENGTH = 8, 250
RHO = 0.8  # the synthetic posterior's correlation of ln Q and T

T_EPISTEMIC = """
[hazard.epistemic."kinetics.activation_temperature"]
distribution = "uniform"
loc = "15000 K"
scale = "22000 K"
source = "test"
"""


def _write_posterior(path: Path, *, with_t: bool = True, seed: int = 3) -> dict:
    """A calibration's posterior.nc as skidmc writes it (physical values; Q a factor on the
    nominal, relative), with ln Q and T correlated RHO; returns the arrays written."""
    import arviz as az
    import xarray as xr

    rng = np.random.default_rng(seed)
    z = rng.multivariate_normal([0, 0], [[1, RHO], [RHO, 1]], size=(CHAINS, LENGTH))
    values = {Q: np.exp(0.3 * z[..., 0]).astype(np.float32),
              "discrepancy[gold]": rng.normal(0, 0.5, (CHAINS, LENGTH)).astype(np.float32)}
    if with_t:
        values[T] = (26000 + 3000 * z[..., 1]).astype(np.float32)
    ds = xr.Dataset({k: (("chain", "draw"), v) for k, v in values.items()},
                    coords={"chain": np.arange(CHAINS), "draw": np.arange(LENGTH)})
    prior = xr.Dataset({k: (("chain", "draw"), v[:1]) for k, v in values.items()})
    nominal = parse_hazard_study(STUDY).scene.kinetics_heat_of_reaction
    params = [{"name": Q, "key": Q, "relative": True, "unit": "1", "nominal": nominal},
              {"name": "discrepancy[gold]", "key": None, "relative": False, "unit": "1",
               "nominal": None}]
    if with_t:
        params.append({"name": T, "key": T, "relative": False, "unit": "K",
                       "nominal": 26300.0})
    idata = az.InferenceData(posterior=ds, prior=prior)
    idata.attrs.update({"study_name": "synthetic-calibration", "completed": "today",
                        "summary": json.dumps({"parameters": params})})
    idata.to_netcdf(str(path), engine="h5netcdf")
    return {**values, "nominal": nominal}


def _study(tmp_path: Path, posterior: str, *, with_t: bool = False, draws: int = 4) -> Path:
    """test_handling's study with [hazard.posterior] (and T epistemic if `with_t`)."""
    text = STUDY.replace("epistemic_draws = 4", f"epistemic_draws = {draws}")
    if with_t:
        text = text.replace("[hazard.estimator]", T_EPISTEMIC + "\n[hazard.estimator]")
    text += f'\n[hazard.posterior]\ncalibration = "{posterior}"\n'
    path = tmp_path / "hazard-posterior.toml"
    path.write_text(text)
    return path


def test_the_draws_taken_are_the_stored_ones(tmp_path):
    stored = _write_posterior(tmp_path / "posterior.nc")
    study = load_hazard_study(_study(tmp_path, "posterior.nc", with_t=True, draws=10))
    post = read_posterior(study)
    index = thinned_indices(CHAINS * LENGTH, 10)
    assert post.stored == CHAINS * LENGTH and list(post.indices) == list(index)
    # Equally spaced over the flattened (chain, draw) order, centred: 2000 / 10 = 200 apart.
    assert list(index) == list(range(100, 2000, 200))
    # The values are the stored ones (float32 as written), a factor times the nominal for the
    # relative Q: equal to the last bit after the same multiplication.
    flat_q = stored[Q].reshape(-1).astype(float) * stored["nominal"]
    flat_t = stored[T].reshape(-1).astype(float)
    np.testing.assert_array_equal(post.draws[Q], flat_q[index])
    np.testing.assert_array_equal(post.draws[T], flat_t[index])
    np.testing.assert_array_equal(post.posterior[Q], flat_q)
    assert set(post.unused) == {"discrepancy[gold]"}
    assert "report's targets" in post.unused["discrepancy[gold]"]


def test_correlation_kept(tmp_path):
    _write_posterior(tmp_path / "posterior.nc")
    study = load_hazard_study(_study(tmp_path, "posterior.nc", with_t=True, draws=400))
    post = read_posterior(study)
    # Rows kept whole: each draw's (Q, T) pair is one stored row.
    rows = set(zip(post.posterior[Q].tolist(), post.posterior[T].tolist()))
    assert all((q, t) in rows for q, t in zip(post.draws[Q], post.draws[T]))
    # Pearson of (ln Q, T) of the draws against the stored ones: the sampling sd of a correlation
    # near 0.8 from 400 draws is (1 - 0.8^2) / sqrt(400) = 0.018; 0.07 is 4 sd. A shuffled
    # pairing would give ~0.
    full = np.corrcoef(np.log(post.posterior[Q]), post.posterior[T])[0, 1]
    taken = np.corrcoef(np.log(post.draws[Q]), post.draws[T])[0, 1]
    assert full == pytest.approx(RHO, abs=0.05)  # 2000 draws of correlated chains
    assert taken == pytest.approx(full, abs=0.07)


def test_missing_posterior_refused_naming_key_and_value(tmp_path):
    study = load_hazard_study(_study(tmp_path, "nowhere.nc"))
    with pytest.raises(StudyError, match=r"hazard\.posterior\.calibration = 'nowhere\.nc'.*"
                                         r"no posterior at"):
        read_posterior(study)
    study = load_hazard_study(_study(tmp_path, "no-such-calibration.toml"))
    with pytest.raises(StudyError, match=r"calibration = 'no-such-calibration\.toml'.*no such "
                                         r"calibration study file"):
        load(study.file)  # the registry's load refuses it before any solver run
    with pytest.raises(StudyError, match="no posterior at"):
        run_hazard_study(load_hazard_study(_study(tmp_path, "nowhere.nc")), None,
                         solver=StandIn())


def test_posterior_without_an_input_refused(tmp_path):
    _write_posterior(tmp_path / "posterior.nc", with_t=False)
    study = load_hazard_study(_study(tmp_path, "posterior.nc", with_t=True))
    with pytest.raises(StudyError, match=r"calibration = 'posterior\.nc'.*holds no draws of "
                                         r"kinetics\.activation_temperature"):
        read_posterior(study)


def test_posterior_table_refused_without_epistemic_inputs():
    text = STUDY.split('[hazard.epistemic."kinetics.heat_of_reaction"]')[0] + \
        '[hazard.estimator]\nseed = 7\n[hazard.posterior]\ncalibration = "x.toml"\n'
    with pytest.raises(StudyError, match=r"hazard\.posterior\.calibration = 'x\.toml'.*no "
                                         r"\[hazard\.epistemic\] input"):
        parse_hazard_study(text)


@pytest.fixture(scope="module")
def posterior_run(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("hazard-posterior")
    stored = _write_posterior(tmp / "posterior.nc")
    study = load(_study(tmp, "posterior.nc", with_t=True, draws=6))  # the stand-in ignores T
    result = run_hazard_study(study, tmp / "out", solver=StandIn())
    # The same study over the priors: the file without its [hazard.posterior] table.
    text = Path(study.file).read_text().split("[hazard.posterior]")[0]
    prior = run_hazard_study(parse_hazard_study(text), None, solver=StandIn())
    return result, prior, stored, tmp


def test_posterior_run_against_closed_form_at_each_draw(posterior_run):
    result, prior, stored, _ = posterior_run
    q_taken = (stored[Q].reshape(-1).astype(float) * stored["nominal"])[
        thinned_indices(CHAINS * LENGTH, 6)]
    np.testing.assert_array_equal(result.epistemic_draws[Q], q_taken)
    # At a fixed Q the stand-in's P has a closed form (test_handling): each draw within 3 of its
    # own standard errors (6 draws: a false alarm has odds ~1.6 %).
    log_sd = math.sqrt(S_TOTAL**2 - 0.3**2)
    for p, cov, q in zip(result.epistemic_probabilities, result.epistemic_covs, q_taken):
        want = sum(WEIGHTS[s] * exact(s, log_sd, -math.log(q / stored["nominal"]))
                   for s in WEIGHTS)
        assert abs(p - want) <= 3 * cov * p
    post = result.posterior
    assert post["probability"] == pytest.approx(result.epistemic_probabilities.mean(), rel=1e-12)
    se = result.epistemic_probabilities.std(ddof=1) / math.sqrt(6)
    t = stats.t.isf(0.025, 5)
    assert post["interval"][0] == pytest.approx(max(0.0, post["probability"] - t * se))
    # The pooled estimate over the priors is the prior study's, to the bit (same seed, same
    # samples: the posterior only changes the epistemic loop).
    assert result.probability == prior.probability and result.interval == prior.interval


def test_posterior_summary_says_prior_against_posterior(posterior_run):
    result, prior, _, tmp = posterior_run
    md = (tmp / "out" / "summary.md").read_text()
    assert "## Prior against posterior" in md
    assert f"{result.posterior['probability']:.3g}" in md
    assert "discrepancy[gold]" in md and "not to the hazard's floors" in md
    assert "Rank (Spearman) correlation" in md  # two inputs: the table of their correlation
    rho = result.posterior["correlation"]["posterior"][0][1]
    assert rho == pytest.approx(RHO, abs=0.05)  # ranks of (Q, T): as Pearson of (ln Q, T)
    data = json.loads((tmp / "out" / "summary.json").read_text())
    assert data["posterior"]["calibration"] == "synthetic-calibration"
    assert data["posterior"]["prior"]["study"]["status"].startswith("no prior_study")
    # A study over the priors writes no posterior key (its summary.json as before).
    assert "posterior" not in prior.to_dict()


def test_shipped_posterior_study_reads_the_stored_posterior(monkeypatch):
    # The posterior is whatever results/calibration-series1/posterior.nc holds (it is rerun when
    # the priors change): checked against that file, not against numbers.
    monkeypatch.chdir(ROOT)
    path = ROOT / "results" / "calibration-series1" / "posterior.nc"
    if not path.is_file():
        pytest.skip("no calibration posterior in this checkout")
    import arviz as az

    study = load_hazard_study(ROOT / "studies" / "hazard-handling-posterior.toml")
    prior = load_hazard_study(ROOT / "studies" / "hazard-handling.toml")
    # The two files differ only in the name and [hazard.posterior]: same inputs, same seed.
    assert study.estimator == prior.estimator and study.epistemic == prior.epistemic
    assert study.surfaces == prior.surfaces and study.billet == prior.billet
    post = read_posterior(study)
    idata = az.from_netcdf(str(path), engine="h5netcdf")
    summary = {p["name"]: p for p in json.loads(idata.attrs["summary"])["parameters"]}
    for key in study.epistemic_keys:
        flat = np.asarray(idata.posterior[key].values, dtype=float).reshape(-1)
        if summary[key]["relative"]:
            flat = flat * summary[key]["nominal"]
        # 550 K in both studies: no conversion of the rate's reference temperature.
        np.testing.assert_allclose(post.draws[key], flat[post.indices], rtol=1e-12)
    assert post.draws[Q].size == study.estimator.epistemic_draws


def test_calibration_report_states_the_hazard_under_its_posterior(tmp_path, monkeypatch):
    from skidmc.workflows.calibration_report import _hazard_section

    monkeypatch.chdir(tmp_path)
    (tmp_path / "studies").mkdir()
    (tmp_path / "studies" / "cal.toml").write_text('[study]\nname = "cal"\n')
    (tmp_path / "studies" / "hz.toml").write_text(
        '[hazard]\nname = "hz"\n[hazard.posterior]\ncalibration = "cal.toml"\n')
    posterior = tmp_path / "posterior.nc"
    posterior.write_bytes(b"a posterior")
    attrs = {"study_file": "studies/cal.toml"}
    text = "\n".join(_hazard_section(posterior, attrs))
    assert "not run yet" in text and "skidmc run studies/hz.toml --force" in text
    summary = tmp_path / "results" / "hz" / "summary.json"
    summary.parent.mkdir(parents=True)
    post = {"sha256": hashlib.sha256(b"a posterior").hexdigest(), "keys": [Q], "draws": 20,
            "probability": 1.23e-5, "interval": [1e-5, 1.5e-5], "band": [2e-6, 4e-5],
            "prior": {"pooled": {"probability": 2.0e-5, "interval": [1.8e-5, 2.2e-5]},
                      "study": {"status": "found", "band": [1.4e-6, 5.84e-5]}}}
    summary.write_text(json.dumps({"posterior": post}))
    text = "\n".join(_hazard_section(posterior, attrs))
    assert "| under this posterior (mean over its draws) | 1.23e-05 | [1e-05, 1.5e-05] |" in text
    assert "[1.4e-06, 5.84e-05]" in text and "not carried to the hazard's floors" in text
    posterior.write_bytes(b"the posterior rerun")  # the hazard's summary is of the old one
    assert "computed from another posterior" in "\n".join(_hazard_section(posterior, attrs))
