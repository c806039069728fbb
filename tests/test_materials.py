"""The materials registry (skidmc.scene.materials): every entry is sourced and builds a scene;
``target=NAME`` in make_scene, the CLI and study files; an explicit target.* key wins."""

from __future__ import annotations

import json

import pytest

from skidmc.errors import SceneError
from skidmc.scene import MATERIALS, SI_UNITS, get_material, get_preset, list_materials, make_scene
from skidmc.scene.keys import HARDNESS_WORDS
from skidmc.scene.materials import TARGET_KEYS
from skidmc.scene.units import read_si

NAMES = list(MATERIALS)

# Incropera et al., Fundamentals of Heat and Mass Transfer, Tables A.1-A.3: the diffusivity
# column alpha [1e-6 m^2/s] printed next to rho, c and k. Recomputing it from the three
# transcribed values catches a typo in any of them.
INCROPERA_ALPHA = {
    "gold": 127, "copper": 117, "aluminium-2024": 73.0, "steel": 17.7, "stainless-304": 3.95,
    "alumina-99.5": 11.9, "fused-quartz": 0.834, "soda-lime-glass": 0.75, "concrete": 0.69,
    "granite": 1.37, "oak": 0.177, "pine": 0.171, "rubber": 0.0589,
}
# The report's Table VI diffusivity column [cm^2/s].
TABLE_VI_ALPHA = {"gold-report": 1.16, "alumina-85-report": 3.45e-2, "quartz-report": 8.11e-3}


def test_the_registry_has_the_materials_asked_for():
    assert list_materials() == NAMES
    for name in ("gold", "copper", "aluminium-2024", "steel", "stainless-304", "alumina-99.5",
                 "alumina-85-report", "fused-quartz", "quartz-report", "soda-lime-glass",
                 "concrete", "granite", "oak", "rubber"):
        assert name in MATERIALS


@pytest.mark.parametrize("name", NAMES)
def test_every_entry_is_sourced_has_units_and_builds_a_scene(name):
    m = get_material(name)
    assert m.name == name and m.description and m.source and m.spread
    assert list(m.values) == list(TARGET_KEYS)
    si = {}
    for key, text in m.values.items():
        if key == "target.hardness" and text in HARDNESS_WORDS:  # "rigid" / "elastic"
            si[key] = HARDNESS_WORDS[text]
            assert m.hardness_source, f"{name}: the hardness needs a source or reason"
            continue
        si[key], bare = read_si(key, text, SI_UNITS[key])
        assert not bare, f"{name}: {key} = {text!r} needs units"
    scene = make_scene(preset="paper-quartz", target=name)
    assert {key: getattr(scene, key.replace(".", "_")) for key in TARGET_KEYS} == si
    base = get_preset("paper-quartz")  # everything else is the preset's
    # (a material with a temperature table sets it too: docs/targets.md)
    assert scene.replace(**{k: getattr(base, k.replace(".", "_")) for k in TARGET_KEYS},
                         **{"target.table": ""}) == base


@pytest.mark.parametrize("name, alpha", INCROPERA_ALPHA.items())
def test_handbook_entries_reproduce_the_tables_diffusivity(name, alpha):
    s = make_scene(preset="paper-quartz", target=name)
    assert s.target_conductivity / (s.target_density * s.target_heat_capacity) * 1e6 == \
        pytest.approx(alpha, rel=0.01)


@pytest.mark.parametrize("name, alpha", TABLE_VI_ALPHA.items())
def test_report_entries_reproduce_table_vi_diffusivity(name, alpha):
    s = make_scene(preset="paper-quartz", target=name)
    assert s.target_conductivity / (s.target_density * s.target_heat_capacity) * 1e4 == \
        pytest.approx(alpha, rel=0.015)


@pytest.mark.parametrize("preset, name", [("paper-quartz", "quartz-report"),
                                          ("paper-alumina-rough", "alumina-85-report"),
                                          ("paper-gold", "gold-report")])
def test_presets_targets_are_the_report_entries(preset, name):
    assert make_scene(preset=preset, target=name) == get_preset(preset)


def test_unknown_material_names_key_value_and_close_matches():
    with pytest.raises(SceneError) as info:
        make_scene(preset="paper-quartz", target="stainles-304")
    err = info.value
    assert err.key == "target" and err.value == "stainles-304"
    assert str(err).startswith("target = 'stainles-304': unknown material; did you mean "
                               "'stainless-304'")
    for name in NAMES:
        assert name in str(err)
    with pytest.raises(SceneError) as info:
        make_scene(preset="paper-quartz", target=5)
    assert info.value.key == "target" and "material name" in str(info.value)


def test_an_explicit_target_key_wins_over_the_material():
    steel = get_material("steel")
    for scene in (
        make_scene(preset="paper-quartz", target="steel", **{"target.conductivity": "50 W/(m K)"}),
        make_scene({"target.conductivity": "50 W/(m K)", "target": "steel"}, preset="paper-quartz"),
        make_scene({"target.conductivity": 50.0}, preset="paper-quartz", target="steel"),
        make_scene({"target": {"conductivity": 50.0}}, preset="paper-quartz", target="steel"),
    ):
        assert scene.target_conductivity == 50.0
        assert scene.target_density == read_si("target.density", steel.density, "kg/m^3")[0]


def test_replace_with_a_material_keeps_the_rest():
    quartz = get_preset("paper-quartz")
    copper = quartz.replace(target="copper", mu=0.2)
    assert copper.mu == 0.2 and copper.flow_stress == quartz.flow_stress
    assert copper.target_conductivity == 401.0


def test_cli_height_set_target(monkeypatch, capsys):
    import sys
    import types

    from skidmc.cli import main

    calls = []

    def critical_height(scene, rtol=1e-3, tier="full", h_min=1e-3, h_max=1e4):
        calls.append(scene)
        return types.SimpleNamespace(critical_height=1.0, censored=None, evaluations=3, flags=(),
                                     wall_time=0.1, to_dict=dict)

    module = types.ModuleType("skidmc.solver")
    module.critical_height = critical_height
    monkeypatch.setitem(sys.modules, "skidmc.solver", module)
    assert main(["height", "--preset", "paper-quartz", "--set", "target=steel",
                 "--set", "target.conductivity=45 W/(m K)", "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert calls[0] == make_scene(preset="paper-quartz", target="steel",
                                  **{"target.conductivity": 45.0})
    assert report["scene"]["target.density"]["value"] == 7854.0
    assert report["overrides"]["target"] == "steel"
    assert main(["height", "--preset", "paper-quartz", "--set", "target=steal"]) == 2
    assert "did you mean 'steel'" in capsys.readouterr().err


def test_cli_materials(capsys):
    from skidmc.cli import main

    assert main(["materials"]) == 0
    out = capsys.readouterr().out
    for name in NAMES:
        assert name in out
    assert main(["materials", "fused-quartz", "--json"]) == 0
    data = json.loads(capsys.readouterr().out)
    assert list(data) == ["fused-quartz"]
    entry = data["fused-quartz"]
    assert entry["values"] == MATERIALS["fused-quartz"].values
    assert entry["si"]["target.conductivity"] == 1.38 and "Incropera" in entry["source"]
    assert main(["materials", "steal"]) == 2
    assert "did you mean 'steel'" in capsys.readouterr().err


def test_study_file_target():
    from skidmc.ensemble.study import parse_study

    study = parse_study("""
[study]
name = "t"
[[scenes]]
name = "steel"
preset = "paper-quartz"
target = "steel"
[[scenes]]
name = "steel-k45"
preset = "paper-quartz"
target = "steel"
"target.conductivity" = "45 W/(m K)"
[uncertain.mu]
distribution = "lognorm"
s = 0.1
relative = true
source = "test"
[design]
method = "mc"
n = 8
seed = 1
""")
    steel, steel45 = (sc.scene for sc in study.scenes)
    assert steel == make_scene(preset="paper-quartz", target="steel")
    assert steel45 == steel.replace(**{"target.conductivity": 45.0})
