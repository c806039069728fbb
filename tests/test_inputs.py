"""The one definition of each input (skidmc.scene.keys): what is derived from it, the checks
between keys shared by the scalar and column paths, and the plausibility of bare numbers."""

from __future__ import annotations

import dataclasses
import inspect
import math

import numpy as np
import pytest

from skidmc.errors import SceneError
from skidmc.scene import (
    DESCRIPTIONS,
    INPUT_KEYS,
    NUMERIC_KEYS,
    PRESETS,
    SCENE_KEYS,
    SI_UNITS,
    Scene,
    SceneColumns,
    get_preset,
    make_scene,
)
from skidmc.scene.keys import (
    BETWEEN_KEYS,
    between_keys_ok,
    first_broken_between,
    implausible_reason,
    input_key,
)

PSI = 6894.757293168361  # [Pa], lbf/in^2
PLAUSIBLE = [k for k in INPUT_KEYS if k.plausible is not None]


# --- derived from the table ----------------------------------------------------------------------


def test_every_list_of_keys_is_the_table():
    assert SCENE_KEYS == tuple(k.key for k in INPUT_KEYS)
    assert NUMERIC_KEYS == tuple(k.key for k in INPUT_KEYS if k.key != "configuration")
    assert SI_UNITS == {k.key: k.si_unit for k in INPUT_KEYS}
    assert DESCRIPTIONS == {k.key: k.description for k in INPUT_KEYS}
    fields = dataclasses.fields(Scene)
    assert [(f.name, f.type) for f in fields[:-2]] == [
        (k.key.replace(".", "_"), "str" if k.key == "configuration" else "float")
        for k in INPUT_KEYS]
    # and, not input keys, a layered target's layers and a target's temperature table
    # (docs/targets.md)
    assert [(f.name, f.type, f.default) for f in fields[-2:]] == [
        ("target_layers", "str", ""), ("target_table", "str", "")]


def test_scene_docstring_lists_every_field_with_its_unit():
    doc = Scene.__doc__
    assert "<attributes" not in doc
    for k in INPUT_KEYS:
        unit = f"[{k.si_unit}]" if k.key != "configuration" else "'vertical'"
        entry = doc.split(f"    {k.field} : ")[1].split("\n    ")[1]  # the description line
        assert unit in entry, (k.key, entry)


def test_every_key_documents_its_source():
    for k in INPUT_KEYS:
        assert k.description and k.symbol and k.equation, k.key
        assert k.plausible is None or k.example_unit, k.key  # the refusal shows an example


def test_fast_tier_fields_are_the_kernels_arguments():
    """SCENE_FIELDS comes from the table; the kernels take the same quantities in that order."""
    from skidmc.physics.fast import fast_height_kernel, fast_heights_kernel
    from skidmc.solver.fast import SCENE_FIELDS

    for kernel in (fast_height_kernel, fast_heights_kernel):
        params = list(inspect.signature(getattr(kernel, "py_func", kernel)).parameters)
        kernel_names = params[:len(SCENE_FIELDS)]
        assert [f.removeprefix("kinetics_") for f in SCENE_FIELDS] == kernel_names
    assert len(SCENE_FIELDS) == len(NUMERIC_KEYS)


# --- the checks between keys, once for scalars and arrays -----------------------------------------

_EDGE = [0.0, 1e-300, 30.0, 45.0, 45.0 * (1 + 1e-12), 45.0 * (1 + 1e-6), 89.9, 553.0, 600.0,
         math.nan, math.inf, -math.inf]


@pytest.mark.parametrize("configuration", ["pendulum", "vertical"])
def test_between_keys_vectorised_equals_scalar_and_math_isclose(configuration):
    grid = np.array(np.meshgrid(_EDGE, _EDGE)).reshape(2, -1)
    values = {"configuration": configuration, "angle": grid[0], "tilt": grid[1],
              "initial_temperature": grid[1], "he.melting_point": grid[0]}
    ok = between_keys_ok(values)
    for i in range(grid.shape[1]):
        row = {k: v if isinstance(v, str) else float(v[i]) for k, v in values.items()}
        broken = first_broken_between(row)
        assert bool(ok[i]) == (broken is None), row
        # the reference: the rules as written out with the standard library
        tilt_ok = configuration != "vertical" or math.isclose(
            row["tilt"], row["angle"], rel_tol=1e-9, abs_tol=1e-9)
        assert bool(ok[i]) == (tilt_ok and row["initial_temperature"] < row["he.melting_point"])
        if broken is not None:
            assert broken[0] == ("tilt" if not tilt_ok else "initial_temperature")
    assert set(BETWEEN_KEYS) == set(values)


def test_scene_and_scene_columns_use_the_same_between_check():
    gold = get_preset("paper-gold")  # vertical, angle 45
    with pytest.raises(SceneError, match="must equal angle") as info:
        Scene(**{**dataclasses.asdict(gold), "tilt": 30.0})
    assert info.value.key == "tilt"
    columns = SceneColumns(gold, {"tilt": np.array([45.0, 30.0]),
                                  "initial_temperature": np.array([300.0, 300.0])})
    assert columns.scene(0).tilt == 45.0
    with pytest.raises(SceneError) as info:
        columns.scene(1)
    assert info.value.key == "tilt"


# --- plausible bare numbers ----------------------------------------------------------------------


def test_plausible_ranges_are_inside_the_bounds():
    for k in PLAUSIBLE:
        lo, hi = k.plausible
        assert 0 < lo < hi < math.inf
        assert k.bounds.contains(lo) and k.bounds.contains(hi), k.key


@pytest.mark.parametrize("name", list(PRESETS))
def test_every_preset_value_is_a_plausible_bare_number(name):
    """A preset written in SI without units is accepted: the ranges are wide enough."""
    scene = get_preset(name)
    values = scene.as_dict()
    for k in PLAUSIBLE:
        assert implausible_reason(k.key, values[k.key], values[k.key]) is None, k.key
    assert make_scene({k: v for k, v in values.items()}) == scene


@pytest.mark.parametrize("k", PLAUSIBLE, ids=[k.key for k in PLAUSIBLE])
def test_implausible_reason_at_the_edges(k):
    lo, hi = k.plausible
    assert implausible_reason(k.key, lo, lo) is None
    assert implausible_reason(k.key, hi, hi) is None
    assert implausible_reason(k.key, 0.0, 0) is None  # zero is zero in every unit
    for x in (lo / 2, hi * 2):
        reason = implausible_reason(k.key, x, x)
        assert reason is not None and "plausible" in reason and k.example_unit in reason
    assert implausible_reason(k.key, hi - lo, 1, difference=True) is None
    assert "wider than" in implausible_reason(k.key, 2 * (hi - lo), 1, difference=True)


@pytest.mark.parametrize("given, shown", [(28000, "28000"), ("28000", "'28000'"),
                                          (28000.0, "28000.0"), ("28e3", "'28e3'")])
def test_a_bare_flow_stress_in_psi_is_refused(given, shown):
    with pytest.raises(SceneError) as info:
        make_scene(preset="paper-quartz", flow_stress=given)
    err = info.value
    assert err.key == "flow_stress" and err.value == given
    assert str(err).startswith(f"flow_stress = {shown}: is read as 28000 Pa (SI)")
    assert "outside the plausible 1e5-1e10 Pa" in str(err)
    assert f'"{str(given).strip()} psi"' in str(err)


@pytest.mark.parametrize("key, given, reading", [
    ("initial_temperature", 20, "20 K"),            # meant degC
    ("billet_diameter", "10", "10 m"),              # meant inches
    ("he.density", 1.91, "1.91 kg/m^3"),            # meant g/cm^3
    ("target.conductivity", 4.05e-3, "0.00405 W/(m K)"),  # meant cal/s/cm/K
    ("kinetics.heat_of_reaction", 2249, "2249 J/kg"),     # meant cal/g
    ("he.heat_of_fusion", 50, "50 J/kg"),                 # meant cal/g
])
def test_bare_numbers_in_the_reports_units_are_refused(key, given, reading):
    with pytest.raises(SceneError) as info:
        make_scene({key: given}, preset="paper-quartz")
    assert info.value.key == key and info.value.value == given
    assert f"is read as {reading} (SI)" in str(info.value)
    assert input_key(key).example_unit in str(info.value)


def test_unit_strings_are_never_refused_for_plausibility():
    assert make_scene(preset="paper-quartz", flow_stress="28000 Pa").flow_stress == 28000.0
    assert make_scene(preset="paper-quartz", flow_stress="1 Pa").flow_stress == 1.0
    assert make_scene(preset="paper-quartz", flow_stress="28000 psi").flow_stress == \
        pytest.approx(28000 * PSI, rel=1e-12)


def test_bounds_come_before_plausibility_and_zero_is_plausible():
    with pytest.raises(SceneError) as info:
        make_scene(preset="paper-quartz", flow_stress=-5)
    assert str(info.value) == "flow_stress = -5: must be > 0 Pa"
    assert make_scene(preset="paper-quartz", **{"he.heat_of_fusion": 0}).he_heat_of_fusion == 0


def test_programmatic_si_floats_are_not_checked():
    scene = make_scene(preset="paper-quartz", flow_stress=28000.0, check_plausible=False)
    assert scene.flow_stress == 28000.0
    assert scene.replace(billet_mass=1e6, check_plausible=False).billet_mass == 1e6
    with pytest.raises(SceneError, match="plausible"):
        scene.replace(billet_mass=1e6)
    direct = Scene(**{**dataclasses.asdict(scene), "billet_mass": 1e6})
    assert direct.billet_mass == 1e6
    columns = SceneColumns(scene, {"flow_stress": np.array([28000.0, 1.0])})
    assert [columns.scene(i).flow_stress for i in range(2)] == [28000.0, 1.0]


def test_the_cli_refuses_a_bare_implausible_set(capsys):
    from skidmc.cli import main

    assert main(["height", "--preset", "paper-quartz", "--set", "flow_stress=28000"]) == 2
    err = capsys.readouterr().err
    assert "flow_stress = '28000'" in err and "28000 psi" in err
