"""The presentation layer (skidmc.workflows.reporting): one JSON encoding everywhere, and every
level, band and logarithm a report states is the one its numbers were computed with."""

from __future__ import annotations

import ast
import dataclasses
import json
import math
import re
from pathlib import Path

import numpy as np
import pytest
from scipy import stats
from test_report import SIGMA, _ensemble
from test_workflows import _plain

from skidmc.analysis.report import EPISTEMIC_BAND, analyse_scene
from skidmc.workflows.reporting import band, dumps, json_ready, level, log_name
from skidmc.workflows.reporting.ensemble import write_report

SRC = Path(__file__).resolve().parents[1] / "src" / "skidmc"


def _strict(text: str):
    """json.loads refusing the NaN/Infinity tokens that strict JSON readers reject."""
    def refuse(token):
        raise ValueError(f"non-standard JSON token {token}")

    return json.loads(text, parse_constant=refuse)


# --- the one encoding -----------------------------------------------------------------------------


def test_nan_is_null_and_infinity_a_string_everywhere():
    data = {"nan": math.nan, "np_nan": np.float32("nan"), "inf": math.inf, "-inf": -np.inf,
            "x": np.float64(1.5), "n": np.int64(3), "ok": np.bool_(True),
            "array": np.array([1.0, np.nan]), 7: (1, 2)}
    assert _strict(dumps(data)) == {"nan": None, "np_nan": None, "inf": "inf", "-inf": "-inf",
                                    "x": 1.5, "n": 3, "ok": True, "array": [1.0, None],
                                    "7": [1, 2]}
    assert json_ready([math.nan]) == [None]
    assert dumps({"a": 1}).endswith("}\n")


def test_no_module_encodes_json_but_the_reporting_package():
    # One encoder: every other json.dumps in the package would be a second way to write NaN.
    # (The JSON Schema export writes no computed numbers, only the study formats.)
    allowed = {SRC / "workflows" / "reporting" / "__init__.py",
               SRC / "ensemble" / "study_schema.py"}
    offenders = []
    for path in SRC.rglob("*.py"):
        if path in allowed:
            continue
        for node in ast.walk(ast.parse(path.read_text())):
            if (isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute)
                    and node.func.attr in ("dumps", "dump")
                    and isinstance(node.func.value, ast.Name) and node.func.value.id == "json"):
                offenders.append(f"{path.relative_to(SRC)}:{node.lineno}")
    assert not offenders


def test_labels():
    assert level(0.95) == "95 %" and level(0.9) == "90 %" and level(0.975) == "97.5 %"
    assert band((0.05, 0.95)) == "5-95 %" and band((0.1, 0.9)) == "10-90 %"
    assert log_name(math.e) == "ln" and log_name(10) == "log10"


# --- the ensemble report ------------------------------------------------------------------------


def test_every_interval_of_the_ensemble_report_is_at_the_level_used(tmp_path):
    # At 90 %: the summary states 90 % wherever it states a level, and the intervals it gives
    # are the fit's at 90 % (not at 95 %, the default).
    write_report(_ensemble(), tmp_path, source="synthetic.h5", confidence=0.9,
                 experiments={"quartz": "quartz"})
    text = (tmp_path / "summary.md").read_text()
    # The one 95 % that stays is a measured fact: the coverage of the probit's 95 % intervals
    # on simulated up-down series (results/validation/gonogo_coverage.md).
    stated = re.findall(r"(\d+(?:\.\d+)?) % (?:interval|profile|credible|band|probit)",
                        text.replace("coverage of a 95 % interval", ""))
    assert stated and set(stated) == {"90"}, stated
    assert "95 %" not in text.replace("coverage of a 95 % interval", "")
    summary = _strict((tmp_path / "summary.json").read_text())
    assert summary["confidence"] == 0.9
    fit = analyse_scene(_ensemble(), "quartz", confidence=0.9).fit
    at95 = analyse_scene(_ensemble(), "quartz").fit
    h50 = summary["scenes"][0]["lognormal"]["h50"]
    assert h50 == pytest.approx(list(fit.intervals["h50"]), rel=1e-12)
    assert h50[1] > at95.intervals["h50"][1]  # a 90 % interval is narrower than a 95 % one


def test_the_log_base_stated_is_the_one_fitted(tmp_path):
    # The synthetic heights have a natural-log sd of 0.4: the "sigma_ln" the report states is
    # that (log10 would be 0.17). Tolerance 0.06: four standard errors of a sd estimated from
    # 400 heights (0.4 / sqrt(800) = 0.014).
    write_report(_ensemble(), tmp_path, source="synthetic.h5")
    summary = _strict((tmp_path / "summary.json").read_text())
    assert summary["scenes"][0]["lognormal"]["sigma_ln"][0] == pytest.approx(SIGMA, abs=0.06)
    text = (tmp_path / "summary.md").read_text()
    assert "sigma ln H" in text and "log10" not in text


def test_nested_report_names_the_band_it_computed(tmp_path):
    write_report(_ensemble(n=64, nested=8), tmp_path, source="synthetic.h5")
    text = (tmp_path / "summary.md").read_text()
    assert f"{band(EPISTEMIC_BAND)} of per-draw H50" in text


def test_the_studys_own_assumptions_are_printed_as_written(tmp_path):
    ds = _ensemble(n=64)
    said = ["The shape of k(T) is the steepest reading (not sampled).", "E/R's upper half mirrors."]
    ds.attrs["study"] = {"study": {"name": "synthetic", "assumptions": said}}
    write_report(ds, tmp_path, source="synthetic.h5")
    text = (tmp_path / "summary.md").read_text()
    section = text[text.index("## Assumptions of the study"):]
    assert [ln[2:] for ln in section.splitlines() if ln.startswith("- ")][:2] == said
    ds.attrs["study"] = {"study": {"name": "synthetic"}}
    write_report(ds, tmp_path, source="synthetic.h5")
    assert "Assumptions of the study" not in (tmp_path / "summary.md").read_text()


def test_a_study_refuses_assumptions_that_are_not_sentences(tmp_path):
    from skidmc.ensemble.study import StudyError, load_study

    text = _plain(extra_study='assumptions = "one string, not a list"')
    path = tmp_path / "k.toml"
    path.write_text(text)
    with pytest.raises(StudyError, match=r"study\.assumptions.*one string, not a list"):
        load_study(path)


# --- the hazard summary ---------------------------------------------------------------------------


def test_the_hazard_summary_states_the_results_level_and_band(tmp_path):
    # The summary takes the level and the band from the result (what the estimator used), not
    # from literals: a result recorded at 90 % with a 10-90 % band is written so.
    from test_handling import STUDY, StandIn

    from skidmc.ensemble.hazard_study import parse_hazard_study
    from skidmc.workflows.hazard import run_hazard_study
    from skidmc.workflows.reporting.hazard import write_hazard_report

    study = parse_hazard_study(STUDY.replace("epistemic_draws = 4", "epistemic_draws = 3"))
    result = run_hazard_study(study, tmp_path / "run", solver=StandIn())
    # The interval the result states is at its recorded level: half-width z(level) x CoV x P.
    z = stats.norm.isf((1 - result.confidence) / 2)
    assert result.interval[1] - result.probability == pytest.approx(
        z * result.cov * result.probability, rel=1e-9)
    default = (tmp_path / "run" / "summary.md").read_text()
    assert f"{level(result.confidence)} interval" in default
    _strict((tmp_path / "run" / "summary.json").read_text())

    other = dataclasses.replace(result, confidence=0.9, band_quantiles=(0.1, 0.9))
    write_hazard_report(other, study, tmp_path / "other")
    text = (tmp_path / "other" / "summary.md").read_text()
    assert "90 % interval" in text and "10-90 %" in text and "epistemic 10 %" in text
    assert "95 %" not in text and "5-95" not in text
    assert _strict((tmp_path / "other" / "summary.json").read_text())["confidence"] == 0.9
