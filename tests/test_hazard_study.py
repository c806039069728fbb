"""Hazard study files: the shipped one loads, malformed ones fail naming the key and the value."""

from __future__ import annotations

from pathlib import Path

import pytest

from skidmc.ensemble.hazard_study import (
    is_hazard_study,
    load_hazard_study,
    parse_hazard_study,
)
from skidmc.ensemble.study_model import StudyError

ROOT = Path(__file__).resolve().parents[1]
SHIPPED = ROOT / "studies" / "hazard-handling.toml"

MINIMAL = """
[hazard]
name = "mini"

[hazard.scene]
preset = "paper-quartz"
configuration = "vertical"

[hazard.drop_height]
distribution = "lognorm"
s = 0.5
scale = "1 m"
source = "judgement"

[hazard.angle]
distribution = "halfnorm"
scale = "10 deg"
source = "judgement"

[[hazard.surface]]
material = "concrete"
weight = 0.7
source = "judgement"
[hazard.surface.friction]
distribution = "lognorm"
s = 0.2
scale = 0.24
source = "report Table I"

[[hazard.surface]]
material = "oak"
weight = 0.3
source = "judgement"
[hazard.surface.friction]
distribution = "loguniform"
a = 0.056
b = 0.243
source = "report Table I range"

[hazard.billet.flow_stress]
distribution = "lognorm"
s = 0.15
scale = "28000 psi"
source = "report Sec. IV"

[hazard.epistemic."kinetics.activation_temperature"]
distribution = "uniform"
loc = "15000 K"
scale = "19000 K"
source = "literature"

[hazard.estimator]
seed = 1
"""


def test_shipped_study_loads_with_its_parts():
    study = load_hazard_study(SHIPPED)
    assert study.name == "hazard-handling"
    assert study.materials == ("concrete", "steel", "oak", "rubber", "soda-lime-glass")
    assert sum(s.weight for s in study.surfaces) == pytest.approx(1.0)
    assert study.aleatory_keys[:2] == ("mu", "angle")
    assert "kinetics.rate_at_reference" in study.epistemic_keys
    # The first-series billet: 19.1 lb, 10 in, 28,000 psi (report Sec. III, IV).
    assert study.scene.billet_mass == pytest.approx(19.1 * 0.45359237)
    assert study.scene.billet_diameter == pytest.approx(0.254)
    assert study.drop_height.frozen.median() == pytest.approx(1.0)
    for s in study.surfaces:  # the material's registry values reach the surface's scene
        assert s.scene.configuration == "vertical"
    assert is_hazard_study(SHIPPED)
    assert not is_hazard_study(ROOT / "studies" / "paper-series1.toml")


def test_minimal_study_defaults():
    study = parse_hazard_study(MINIMAL)
    assert study.estimator.method == "is" and study.estimator.target_cov == 0.1
    assert study.solver.tier == "full"
    assert study.surfaces[1].scene.target_conductivity == pytest.approx(0.16)  # oak
    assert study.billet["flow_stress"].kind == "aleatory"
    assert study.epistemic["kinetics.activation_temperature"].kind == "epistemic"


def _broken(old: str, new: str) -> str:
    assert old in MINIMAL, old
    return MINIMAL.replace(old, new, 1)


# (replace this, with this) -> (key path in the message, a fragment of the reason)
MALFORMED = [
    pytest.param('scale = "1 m"', 'scale = "1 kg"', "hazard.drop_height.scale", "",
                 id="drop height in kg"),
    pytest.param('scale = "1 m"', "scale = 1.0", "hazard.drop_height.scale", "needs its unit",
                 id="drop height without unit"),
    pytest.param('scale = "10 deg"\nsource = "judgement"', 'scale = "10 deg"',
                 "hazard.angle.source", "needs a `source`", id="angle without source"),
    pytest.param('s = 0.2\nscale = 0.24\nsource = "report Table I"', "s = 0.2\nscale = 0.24",
                 "hazard.surface[0].friction.source", "source", id="friction without source"),
    pytest.param('material = "concrete"', 'material = "concret"', "hazard.surface[0].material",
                 "did you mean 'concrete'", id="unknown material with suggestion"),
    pytest.param("weight = 0.3", "weight = 0.2", "hazard.surface", "sum to 0.9",
                 id="weights not summing to 1"),
    pytest.param("weight = 0.3", "weight = 0", "hazard.surface[1].weight", "(0, 1]",
                 id="zero weight"),
    pytest.param('material = "oak"', 'material = "concrete"', "hazard.surface[1].material",
                 "twice", id="duplicate material"),
    pytest.param("s = 0.2\nscale = 0.24", "s = 0.8\nscale = 0.24",
                 "hazard.surface[0].friction", "must lie in (0, 1)",
                 id="friction reaching above 1"),
    pytest.param("[hazard.estimator]", "[hazard.estimatr]", "hazard.estimatr",
                 "did you mean 'estimator'", id="unknown table with suggestion"),
    pytest.param("seed = 1", "sed = 1", "hazard.estimator.sed", "did you mean 'seed'",
                 id="unknown estimator key"),
    pytest.param("seed = 1", "method = 'is'", "hazard.estimator.seed", "reproducible",
                 id="missing seed"),
    pytest.param("seed = 1", "seed = 1\nmethod = 'subset'", "hazard.estimator.method",
                 "expected one of", id="unknown method"),
    pytest.param("seed = 1", "seed = 1\ntarget_cov = 0", "hazard.estimator.target_cov",
                 "(0, 1)", id="target cov zero"),
    pytest.param('scale = "28000 psi"', "scale = 28000", "hazard.billet.flow_stress.scale",
                 "28000 Pa", id="bare implausible flow stress"),
    pytest.param("[hazard.billet.flow_stress]", "[hazard.billet.mu]", "hazard.billet.mu",
                 "[[hazard.surface]] friction", id="friction in the billet table"),
    pytest.param("[hazard.billet.flow_stress]", '[hazard.billet."kinetics.prefactor"]',
                 'hazard.billet."kinetics.prefactor"', "not a billet input",
                 id="kinetics as billet input"),
    pytest.param("[hazard.billet.flow_stress]", "[hazard.billet.flow_stres]",
                 "hazard.billet.flow_stres", "did you mean 'flow_stress'",
                 id="misspelt billet key"),
    pytest.param('configuration = "vertical"', 'configuration = "vertical"\nmu = 0.2',
                 "hazard.scene.mu", "set by", id="friction in the scene"),
    pytest.param('preset = "paper-quartz"', 'preset = "paper-quartzz"', "hazard.scene.preset",
                 "", id="unknown preset"),
    pytest.param('source = "literature"', 'source = "literature"\nkind = "aleatory"',
                 'hazard.epistemic."kinetics.activation_temperature".kind', "table says",
                 id="kind in a hazard table"),
    pytest.param('[hazard.angle]\ndistribution = "halfnorm"\nscale = "10 deg"',
                 '[hazard.angle]\ndistribution = "norm"\nloc = "30 deg"\nscale = "10 deg"',
                 "hazard.angle", "outside the physical range", id="angle leaving (0, 90)"),
    pytest.param('name = "mini"', 'name = "mini/one"', "hazard.name", "letters",
                 id="bad name"),
    pytest.param("[hazard]\n", "[study]\nname = 'x'\n[hazard]\n", "study",
                 "everything goes under [hazard]", id="other top-level table"),
]


@pytest.mark.parametrize(("old", "new", "key", "reason"), MALFORMED)
def test_malformed_study_names_key_and_value(old, new, key, reason):
    with pytest.raises(StudyError) as info:
        parse_hazard_study(_broken(old, new), file="case.toml")
    err = info.value
    assert err.key == key
    assert reason in err.reason
    assert str(err).startswith(f"case.toml: {key}")


def test_same_input_aleatory_and_epistemic_is_refused():
    text = MINIMAL + """
[hazard.epistemic.flow_stress]
distribution = "lognorm"
s = 0.1
scale = "28000 psi"
source = "x"
"""
    with pytest.raises(StudyError, match=r"hazard\.epistemic\.flow_stress.*aleatory"):
        parse_hazard_study(text)


def test_missing_hazard_table_and_bad_toml():
    with pytest.raises(StudyError, match="missing table \\[hazard\\]"):
        parse_hazard_study("[study]\nname = 'x'\n")
    with pytest.raises(StudyError, match="not valid TOML"):
        parse_hazard_study("[hazard\n")
    with pytest.raises(StudyError, match="cannot read"):
        load_hazard_study(ROOT / "studies" / "no-such-file.toml")
