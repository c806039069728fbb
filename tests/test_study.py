"""Study files: every shipped study validates, every malformed one is rejected as its header says.

Each file in ``tests/malformed_studies/`` starts with comment lines naming what is wrong and the
error expected::

    # a plain normal whose tail reaches negative conductivity
    # error: StudyError
    # key: uncertain."target.conductivity"
    # match: truncnorm

``key`` is the error's ``key`` attribute exactly, ``match`` a regular expression searched in the
message, which must also name the file.
"""

from __future__ import annotations

import math
import pickle
import re
from pathlib import Path

import numpy as np
import pytest
import scipy.stats

try:
    import tomllib
except ModuleNotFoundError:  # Python 3.10
    import tomli as tomllib

from skidmc import errors
from skidmc.ensemble.hazard_study import is_hazard_study
from skidmc.ensemble.study import (
    RATE_AT_REFERENCE,
    StudyError,
    load_study,
    parse_study,
)
from skidmc.scene import make_scene
from skidmc.workflows import registry

ROOT = Path(__file__).resolve().parents[1]
# Ensemble studies; hazard studies ([hazard] table) have their own format and tests
# (tests/test_hazard_study.py).
# The ensemble-format studies (a hazard or calibration study has its own loader and tests).
SHIPPED = sorted(p for p in (ROOT / "studies").glob("*.toml")
                 if not is_hazard_study(p) and "[calibration]" not in p.read_text())
MALFORMED = sorted((ROOT / "tests" / "malformed_studies").glob("*.toml"))
PSI = 6894.757293168361  # [Pa], lbf/in^2

MINIMAL = """
[study]
name = "t"
[scene]
preset = "paper-quartz"
[uncertain.mu]
distribution = "lognorm"
s = 0.1
relative = true
source = "test"
[design]
method = "mc"
n = 8
seed = 1
"""


def _expectation(path: Path) -> dict:
    fields = {}
    for line in path.read_text().splitlines():
        m = re.match(r"#\s*(error|key|match):\s*(.*)$", line)
        if m:
            fields[m[1]] = m[2].strip()
    assert {"error", "key", "match"} <= set(fields), f"{path.name}: header incomplete"
    return fields


# --- shipped studies ---------------------------------------------------------------------------


def test_the_shipped_studies_exist():
    assert {p.stem for p in SHIPPED} >= {"paper-series1", "paper-series2"}


@pytest.mark.parametrize("path", SHIPPED, ids=[p.stem for p in SHIPPED])
def test_shipped_study_validates(path):
    study = load_study(path)
    assert study.name == path.stem  # results/<name>/ matches the file name
    assert study.keys and study.design.n >= 1
    for sc in study.scenes:
        for dist in sc.uncertain.values():
            assert dist.source.strip()
    for corr in study.correlations:
        assert corr.source.strip()


def test_paper_series1_scenes_and_kinetics_pair():
    study = load_study(ROOT / "studies" / "paper-series1.toml")
    assert study.scene_names == ("gold", "alumina-smooth", "alumina-rough", "quartz")
    assert study.scene_dimension
    # The kinetics pair is not sampled independently: Z goes through the rate at T_ref.
    assert "kinetics.activation_temperature" in study.keys
    assert RATE_AT_REFERENCE in study.keys and "kinetics.prefactor" not in study.keys
    # The gold scene is the report's target as built: the preset on the registry's stack.
    assert study.scenes[0].scene == make_scene(preset="paper-gold", target="gold-stack-report")
    assert study.scenes[0].scene.target_layers


def test_paper_series2_finishes():
    study = load_study(ROOT / "studies" / "paper-series2.toml")
    mus = [sc.scene.mu for sc in study.scenes]
    assert mus == [0.056, 0.092, 0.114, 0.151, 0.243]
    assert all(sc.scene.flow_stress == pytest.approx(34400 * PSI) for sc in study.scenes)


# --- malformed studies ---------------------------------------------------------------------------


def test_malformed_corpus_is_large_enough():
    assert len(MALFORMED) >= 30
    assert sum(is_hazard_study(p) for p in MALFORMED) >= 16  # hazard mistakes too


@pytest.mark.parametrize("path", MALFORMED, ids=[p.stem for p in MALFORMED])
def test_malformed_study_is_rejected(path):
    expected = _expectation(path)
    error = getattr(errors, expected["error"], None) or {"StudyError": StudyError}[
        expected["error"]]
    with pytest.raises(error) as info:
        registry.load(path)  # the kind looked up as `skidmc run` does (hazard files too)
    err = info.value
    assert isinstance(err, ValueError)
    assert err.key == expected["key"], str(err)
    assert re.search(expected["match"], str(err)), str(err)
    assert str(path) in str(err) and err.file == str(path)
    # The offending value is the one the user wrote (not its SI conversion), shown in the message.
    # (Tables and lists, e.g. a [[correlation]] array, are named by a digest, not verbatim.)
    written = _value_at(path, err.key) if err.key != "(syntax)" else _ABSENT
    if isinstance(written, (str, int, float)) and err.value is not None:
        assert err.value == written, (err.value, written)
        assert f"{err.key} = {err.value!r}" in str(err) or f"= {err.value}" in str(err), str(err)


_ABSENT = object()


def _value_at(path: Path, key: str):
    """The value at a TOML key path as written in the file (``_ABSENT`` if there is none)."""
    node = tomllib.loads(path.read_text())
    for part in re.findall(r'"[^"]*"|[^."\[\]]+|\[\d+\]', key):
        if part.startswith("["):
            index = int(part[1:-1])
            if not isinstance(node, list) or index >= len(node):
                return _ABSENT
            node = node[index]
            continue
        name = part.strip('"')
        if not isinstance(node, dict) or name not in node:
            return _ABSENT
        node = node[name]
    return node


def test_value_at_reads_the_written_value(tmp_path):
    f = tmp_path / "s.toml"
    f.write_text('[[scenes]]\nname = "a"\n[scenes.uncertain."target.conductivity"]\na = 3\n')
    assert _value_at(f, 'scenes[0].uncertain."target.conductivity".a') == 3
    assert _value_at(f, "scenes[1].name") is _ABSENT


def test_unreadable_file_names_it(tmp_path):
    with pytest.raises(StudyError, match="cannot read"):
        load_study(tmp_path / "nope.toml")


def test_study_error_pickles_and_is_a_value_error():
    err = StudyError("f.toml", "design.n", 0, "expected an integer >= 1")
    again = pickle.loads(pickle.dumps(err))
    assert (again.file, again.key, again.value, str(again)) == (
        err.file, err.key, err.value, str(err))
    assert str(err) == "f.toml: design.n = 0: expected an integer >= 1"


# --- what a valid study means ---------------------------------------------------------------------


def test_units_convert_levels_and_spreads():
    text = MINIMAL + """
[uncertain.flow_stress]
distribution = "norm"
loc = "28000 psi"
scale = "1000 psi"
source = "test"
[uncertain.initial_temperature]
distribution = "norm"
loc = "21 degC"
scale = "2 degC"
source = "test"
"""
    study = parse_study(text)
    (sc,) = study.scenes
    fs = dict(sc.uncertain["flow_stress"].params)
    assert fs == pytest.approx({"loc": 28000 * PSI, "scale": 1000 * PSI})
    t0 = dict(sc.uncertain["initial_temperature"].params)
    # A level in degC is absolute, a spread in degC is a difference.
    assert t0 == pytest.approx({"loc": 294.15, "scale": 2.0})


def test_lognorm_scale_is_a_level_and_loguniform_bounds_are_levels():
    text = MINIMAL + """
[uncertain."target.conductivity"]
distribution = "loguniform"
a = "0.021 cal/s/cm/K"
b = "30 W/(m K)"
source = "test"
[uncertain."kinetics.heat_of_reaction"]
distribution = "lognorm"
s = 0.3
scale = "1000 cal/g"
source = "test"
"""
    sc = parse_study(text).scenes[0]
    k = dict(sc.uncertain["target.conductivity"].params)
    assert k == pytest.approx({"a": 0.021 * 418.4, "b": 30.0})
    q = dict(sc.uncertain["kinetics.heat_of_reaction"].params)
    assert q == pytest.approx({"s": 0.3, "scale": 4.184e6})


def test_relative_distribution_follows_each_scene():
    text = """
[study]
name = "t"
[[scenes]]
name = "quartz"
preset = "paper-quartz"
[[scenes]]
name = "alumina"
preset = "paper-alumina-smooth"
[uncertain.mu]
distribution = "lognorm"
s = 0.2
relative = true
source = "test"
[design]
method = "mc"
n = 4
seed = 0
"""
    study = parse_study(text)
    for sc in study.scenes:
        assert sc.uncertain["mu"].ppf(np.float64(0.5), sc.nominal("mu")) == pytest.approx(
            sc.scene.mu)


def test_scene_overrides_and_nested_uncertain_tables():
    text = """
[study]
name = "t"
[scene]
preset = "paper-quartz"
flow_stress = "30000 psi"
he.density = "1.9 g/cm^3"
[uncertain.he.conductivity]
distribution = "truncnorm"
a = -3
b = 3
loc = 1.0
scale = 0.1
relative = true
source = "test"
[design]
method = "lhs"
n = 8
seed = 3
"""
    study = parse_study(text)
    (sc,) = study.scenes
    assert not study.scene_dimension and sc.name == "paper-quartz"
    assert sc.scene.flow_stress == pytest.approx(30000 * PSI)
    assert sc.scene.he_density == pytest.approx(1900.0)
    assert study.keys == ("he.conductivity",)


def test_rate_at_reference_nominal_is_the_scene_rate():
    text = MINIMAL + """
[uncertain."kinetics.rate_at_reference"]
distribution = "lognorm"
s = 1.0
relative = true
reference_temperature = "575 K"
source = "test"
"""
    sc = parse_study(text).scenes[0]
    z, ta = sc.scene.kinetics_prefactor, sc.scene.kinetics_activation_temperature
    assert sc.nominal(RATE_AT_REFERENCE) == pytest.approx(z * math.exp(-ta / 575.0))
    assert sc.uncertain[RATE_AT_REFERENCE].reference_temperature == 575.0


def test_spearman_converts_to_the_copula_correlation():
    text = MINIMAL + """
[uncertain."kinetics.activation_temperature"]
distribution = "uniform"
loc = "20000 K"
scale = "10000 K"
source = "test"
[[correlation]]
keys = ["mu", "kinetics.activation_temperature"]
spearman = 0.5
source = "test"
"""
    (corr,) = parse_study(text).correlations
    assert corr.rho == pytest.approx(2 * math.sin(math.pi * 0.5 / 6))
    assert corr.spearman == 0.5


def test_any_scipy_continuous_distribution_with_its_parameter_names():
    text = MINIMAL + """
[uncertain.flow_stress]
distribution = "weibull_min"
c = 8.0
scale = "30000 psi"
loc = 0
source = "test"
"""
    sc = parse_study(text).scenes[0]
    d = sc.uncertain["flow_stress"]
    assert isinstance(d.frozen.dist, type(scipy.stats.weibull_min))


def test_with_n_validates_like_the_file():
    study = parse_study(MINIMAL)
    assert study.with_n(100).design.n == 100
    sobol = parse_study(MINIMAL.replace('method = "mc"', 'method = "sobol"'))
    with pytest.raises(StudyError, match="power of 2"):
        sobol.with_n(100)
    assert sobol.with_n(64).n_rows == 64


def test_saltelli_rows():
    text = MINIMAL.replace('method = "mc"', 'method = "saltelli"') + """
[uncertain.flow_stress]
distribution = "lognorm"
s = 0.05
relative = true
source = "test"
"""
    study = parse_study(text)
    assert study.n_rows == 8 * (2 * 2 + 2)
    first = parse_study(text.replace("seed = 1", "seed = 1\nsecond_order = false"))
    assert first.n_rows == 8 * (2 + 2)


def test_sha256_identifies_the_text():
    a, b = parse_study(MINIMAL), parse_study(MINIMAL + "\n# a comment\n")
    assert a.sha256 != b.sha256 and len(a.sha256) == 64
