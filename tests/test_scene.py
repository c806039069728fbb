"""Tests of the units edge (skidmc.units) and of scene validation (skidmc.scene).

Conversion factors are written here from their definitions, independently of pint:
1 in = 0.0254 m, 1 lb = 0.45359237 kg, g_n = 9.80665 m/s^2 (so 1 psi = lbf/in^2), 1 cal = 4.184 J
(thermochemical), 1 degR = 5/9 K. These are exact, so the only difference to pint's conversion is
floating-point rounding through a few multiplications: a relative tolerance of 1e-12 is ample.
"""

from __future__ import annotations

import dataclasses
import math
import pickle
import subprocess
import sys

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from skidmc.errors import MissingKeyError, SceneError, UnitError, UnknownKeyError
from skidmc.scene import (
    DESCRIPTIONS,
    NUMERIC_KEYS,
    SCENE_KEYS,
    SI_UNITS,
    Scene,
    make_scene,
)
from skidmc.scene.units import from_si, to_si, ureg

INCH = 0.0254  # m
LB = 0.45359237  # kg
G_N = 9.80665  # m/s^2
PSI = LB * G_N / INCH**2  # Pa, = 6894.757293...
CAL = 4.184  # J (thermochemical)
RANKINE = 5.0 / 9.0  # K per degR
EXACT = 1e-12  # relative; see module docstring


# --- units ---------------------------------------------------------------------------------------


def test_independent_factors_are_the_textbook_values():
    # Guard against a typo in the factors above: values as commonly printed, to their last digit.
    assert PSI == pytest.approx(6894.757, abs=5e-4)
    assert 530 * RANKINE == pytest.approx(294.444, abs=5e-4)


@pytest.mark.parametrize(
    ("text", "unit", "expected"),
    [
        ("28000 psi", "Pa", 28000 * PSI),
        ("1 psi", "Pa", PSI),
        ("19.1 lb", "kg", 19.1 * LB),
        ("10 in", "m", 10 * INCH),
        ("1.8 ft", "m", 1.8 * 12 * INCH),
        ("530 degR", "K", 530 * RANKINE),
        ("20 degC", "K", 293.15),
        ("68 degF", "K", (68 + 459.67) * RANKINE),
        ("0.295 cal/g/K", "J/(kg K)", 0.295 * CAL * 1e3),
        ("0.295 cal/g/degC", "J/(kg K)", 0.295 * CAL * 1e3),  # per degree = per kelvin
        ("9.2e-4 cal/s/cm/K", "W/(m K)", 9.2e-4 * CAL * 1e2),
        ("1 cal/s/cm/K", "W/(m K)", 418.4),
        ("1.91 g/cm^3", "kg/m^3", 1910.0),
        ("50 cal/g", "J/kg", 50 * CAL * 1e3),
        ("6.66e5 cal/mol / (296.16 g/mol)", "J/kg", 6.66e5 / 296.16 * CAL * 1e3),
        ("2.63e4 K", "K", 2.63e4),
        ("5e19 1/s", "1/s", 5e19),
        ("1 BTU/lb/degR", "J/(kg K)", 1055.056 / LB / RANKINE),  # pint's BTU: ISO, 1055.056 J
        ("1 Btu_it/lb/degR", "J/(kg K)", 4186.8),  # the IT Btu is defined by this identity
        ("60 deg", "deg", 60.0),
        (f"{math.pi / 3!r} rad", "deg", 60.0),
        ("0.1", "1", 0.1),
        ("60", "deg", 60.0),  # a bare number is in the key's unit
        ("193.05 MPa", "Pa", 193.05e6),
    ],
)
def test_to_si_converts_unit_strings(text, unit, expected):
    assert to_si("key", text, unit) == pytest.approx(expected, rel=EXACT)


@given(st.floats(min_value=1e-6, max_value=1e9, allow_nan=False))
def test_to_si_is_linear_in_the_magnitude(x):
    # repr() keeps all digits, so the string and the float hold the same number.
    assert to_si("flow_stress", f"{x!r} psi", "Pa") == pytest.approx(x * PSI, rel=EXACT)
    assert to_si("flow_stress", x, "Pa") == x  # numbers are already SI


def test_to_si_accepts_numpy_scalars_and_quantities():
    assert to_si("mu", np.float32(0.25), "1") == 0.25
    assert to_si("billet_mass", np.int64(3), "kg") == 3.0
    quantity = ureg.Quantity(19.1, "lb")
    assert to_si("billet_mass", quantity, "kg") == pytest.approx(19.1 * LB, rel=EXACT)


def test_from_si_inverts_to_si():
    assert from_si(0.3048, "m", "ft") == pytest.approx(1.0, rel=EXACT)
    assert from_si(to_si("t", "530 degR", "K"), "K", "degR") == pytest.approx(530.0, rel=EXACT)


@pytest.mark.parametrize(
    ("value", "unit", "fragment"),
    [
        ("10 in", "Pa", "[length]"),  # a length for a stress: names both dimensions
        ("28000 psi", "m", "[mass] / [length] / [time] ** 2"),
        ("0.1 deg", "1", "angle"),  # pint calls angles dimensionless; we do not
        ("0.5 dimensionless", "deg", "dimensionless"),
        ("10 furlongz", "m", "cannot parse"),
        ("abc", "Pa", "cannot parse"),
        ("20 degC * 2", "K", "offset"),
    ],
)
def test_to_si_refuses_wrong_units(value, unit, fragment):
    with pytest.raises(UnitError) as info:
        to_si("some.key", value, unit)
    assert info.value.key == "some.key"
    assert repr(value) in str(info.value)
    assert fragment in str(info.value)


# --- the vocabulary ------------------------------------------------------------------------------


def test_vocabulary_tables_cover_every_key():
    assert len(SCENE_KEYS) == 20 == len(set(SCENE_KEYS))
    assert set(SI_UNITS) == set(DESCRIPTIONS) == set(SCENE_KEYS)
    assert NUMERIC_KEYS == tuple(k for k in SCENE_KEYS if k != "configuration")
    assert [f.name for f in dataclasses.fields(Scene)] == [
        *(k.replace(".", "_") for k in SCENE_KEYS), "target_layers", "target_table"]
    for key in NUMERIC_KEYS:
        ureg.parse_units(SI_UNITS[key])  # every SI unit string is one pint reads


def test_package_exports_the_scene_layer_lazily():
    import skidmc

    assert set(skidmc.__all__) == {"__version__", *skidmc._LAZY}
    assert skidmc.make_scene is make_scene
    # importing the package (e.g. for a numba kernel in a worker) does not load pint
    code = "import sys, skidmc; assert 'pint' not in sys.modules, 'pint imported'"
    subprocess.run([sys.executable, "-c", code], check=True)


# --- building scenes -----------------------------------------------------------------------------

FULL = {  # a complete scene in SI floats (the first-series quartz values)
    "mu": 0.132,
    "flow_stress": 28000 * PSI,
    "billet_mass": 19.1 * LB,
    "billet_diameter": 10 * INCH,
    "configuration": "pendulum",
    "angle": 60.0,
    "initial_temperature": 530 * RANKINE,
    "he.density": 1910.0,
    "he.heat_capacity": 0.295 * CAL * 1e3,
    "he.conductivity": 9.2e-4 * CAL * 1e2,
    "he.heat_of_fusion": 50 * CAL * 1e3,
    "he.melting_point": 553.0,
    "kinetics.prefactor": 5e19,
    "kinetics.activation_temperature": 2.63e4,
    "kinetics.heat_of_reaction": 6.66e5 / 296.16 * CAL * 1e3,
    "target.density": 2670.0,
    "target.heat_capacity": 0.188 * CAL * 1e3,
    "target.conductivity": 4.05e-3 * CAL * 1e2,
}


def test_make_scene_without_preset_from_si_floats():
    scene = make_scene(FULL)
    assert scene.tilt == 0.0  # pendulum default
    assert scene.as_dict() == {**FULL, "tilt": 0.0, "target.hardness": math.inf}
    assert list(scene.as_dict()) == list(SCENE_KEYS)


def test_nested_mapping_as_from_toml_equals_dotted():
    nested = {k: v for k, v in FULL.items() if "." not in k}
    for key, value in FULL.items():
        if "." in key:
            group, name = key.split(".")
            nested.setdefault(group, {})[name] = value
    assert make_scene(nested) == make_scene(FULL)


def test_overrides_with_units_and_attribute_names():
    scene = make_scene(preset="paper-quartz", flow_stress="34400 psi", he_density="1.85 g/cm^3")
    assert scene.flow_stress == pytest.approx(34400 * PSI, rel=EXACT)
    assert scene.he_density == pytest.approx(1850.0, rel=EXACT)
    # keyword overrides win over the mapping
    assert make_scene({"mu": 0.2}, preset="paper-quartz", mu=0.3).mu == 0.3


def test_scene_is_frozen_and_replace_revalidates():
    scene = make_scene(FULL)
    with pytest.raises(dataclasses.FrozenInstanceError):
        scene.mu = 0.5
    assert scene.replace(mu=0.2).mu == 0.2
    assert scene.replace({"he.density": "1.8 g/cm^3"}).he_density == pytest.approx(1800.0)
    with pytest.raises(SceneError) as info:
        scene.replace(mu=-0.1)
    assert info.value.key == "mu"


def test_describe_lists_every_key_with_units():
    text = make_scene(FULL).describe()
    for key in SCENE_KEYS:
        assert key in text
    assert "W/(m K)" in text and "Pa" in text


def test_scene_pickles():  # scenes travel to worker processes
    scene = make_scene(FULL)
    assert pickle.loads(pickle.dumps(scene)) == scene


# --- tilt follows the configuration (report Sec. II.C) --------------------------------------------


def test_vertical_tilt_follows_angle():
    scene = make_scene(FULL, configuration="vertical", angle="45 deg")
    assert scene.tilt == 45.0
    gold = make_scene(preset="paper-gold")
    assert gold.replace(angle=30.0).tilt == 30.0  # a derived tilt tracks the angle
    assert make_scene(preset="paper-quartz", configuration="vertical").tilt == 60.0


def test_pendulum_tilt_defaults_to_zero_and_keeps_an_explicit_value():
    assert make_scene(preset="paper-gold", configuration="pendulum").tilt == 0.0
    tilted = make_scene(preset="paper-quartz", tilt="5 deg")
    assert tilted.tilt == 5.0
    assert tilted.replace(mu=0.2).tilt == 5.0


def test_vertical_with_a_different_tilt_is_refused():
    with pytest.raises(SceneError) as info:
        make_scene(preset="paper-gold", tilt="30 deg")
    assert info.value.key == "tilt" and "'30 deg'" in str(info.value)
    assert "must equal angle" in str(info.value)


# --- every invalid input names its key and its value ---------------------------------------------

INVALID = [
    # (overrides, key named, exception class, value shown in the message)
    ({"he.densty": "1.9 g/cm^3"}, "he.densty", UnknownKeyError, "'1.9 g/cm^3'"),
    ({"flow_stres": 1e8}, "flow_stres", UnknownKeyError, "100000000.0"),
    ({"flow_stress": "28000 psx"}, "flow_stress", UnitError, "'28000 psx'"),
    ({"flow_stress": "10 in"}, "flow_stress", UnitError, "'10 in'"),
    ({"billet_mass": "10 in"}, "billet_mass", UnitError, "'10 in'"),
    ({"initial_temperature": "530 psi"}, "initial_temperature", UnitError, "'530 psi'"),
    ({"flow_stress": "nan psi"}, "flow_stress", SceneError, "'nan psi'"),
    ({"he.density": math.inf}, "he.density", SceneError, "inf"),
    ({"mu": True}, "mu", SceneError, "True"),
    ({"mu": [0.1, 0.2]}, "mu", SceneError, "[0.1, 0.2]"),
    ({"flow_stress": None}, "flow_stress", SceneError, "None"),
    ({"flow_stress": "-5 psi"}, "flow_stress", SceneError, "'-5 psi'"),
    ({"billet_mass": 0.0}, "billet_mass", SceneError, "0.0"),
    ({"billet_diameter": "-10 in"}, "billet_diameter", SceneError, "'-10 in'"),
    ({"he.density": 0}, "he.density", SceneError, "0"),
    ({"he.heat_capacity": -1.0}, "he.heat_capacity", SceneError, "-1.0"),
    ({"he.conductivity": "0 W/m/K"}, "he.conductivity", SceneError, "'0 W/m/K'"),
    ({"target.density": -2670.0}, "target.density", SceneError, "-2670.0"),
    ({"target.heat_capacity": 0.0}, "target.heat_capacity", SceneError, "0.0"),
    ({"target.conductivity": -1.0}, "target.conductivity", SceneError, "-1.0"),
    ({"kinetics.prefactor": 0.0}, "kinetics.prefactor", SceneError, "0.0"),
    ({"kinetics.activation_temperature": -1.0}, "kinetics.activation_temperature", SceneError,
     "-1.0"),
    ({"initial_temperature": "-300 degC"}, "initial_temperature", SceneError, "'-300 degC'"),
    ({"he.melting_point": 0.0}, "he.melting_point", SceneError, "0.0"),
    ({"he.heat_of_fusion": "-1 cal/g"}, "he.heat_of_fusion", SceneError, "'-1 cal/g'"),
    ({"kinetics.heat_of_reaction": -1.0}, "kinetics.heat_of_reaction", SceneError, "-1.0"),
    ({"mu": -0.01}, "mu", SceneError, "-0.01"),
    ({"mu": 13.2}, "mu", SceneError, "13.2"),
    ({"angle": "0 deg"}, "angle", SceneError, "'0 deg'"),
    ({"angle": 90.0}, "angle", SceneError, "90.0"),
    ({"angle": "2 rad"}, "angle", SceneError, "'2 rad'"),
    ({"tilt": -1.0}, "tilt", SceneError, "-1.0"),
    ({"tilt": "90 deg"}, "tilt", SceneError, "'90 deg'"),
    ({"configuration": "horizontal"}, "configuration", SceneError, "'horizontal'"),
    ({"configuration": 1}, "configuration", SceneError, "1"),
    ({"initial_temperature": "600 K"}, "initial_temperature", SceneError, "'600 K'"),
    ({"he.melting_point": "250 K"}, "he.melting_point", SceneError, "'250 K'"),
]


@pytest.mark.parametrize(("overrides", "key", "cls", "shown"), INVALID)
def test_invalid_input_names_key_and_value(overrides, key, cls, shown):
    with pytest.raises(cls) as info:
        make_scene(overrides, preset="paper-quartz")
    err = info.value
    assert isinstance(err, ValueError)  # SceneError is a ValueError
    assert err.key == key
    assert str(err).startswith(f"{key} = {shown}:")


def test_messages_say_why():
    def message(**overrides):
        with pytest.raises(SceneError) as info:
            make_scene(preset="paper-quartz", **overrides)
        return str(info.value)

    assert message(flow_stress="-5 psi") == "flow_stress = '-5 psi': must be > 0 Pa"
    assert "did you mean 'he.density'" in message(**{"he.densty": 1.0})
    assert "expected [mass] / [length] / [time] ** 2" in message(flow_stress="10 in")
    assert "typo" in message(mu=13.2)
    assert "must be finite" in message(mu=math.nan)
    assert "boolean" in message(mu=True)
    assert "list" in message(mu=[0.1])


def test_missing_keys_without_preset():
    partial = {k: v for k, v in FULL.items() if k not in ("he.density", "target.conductivity")}
    with pytest.raises(MissingKeyError) as info:
        make_scene(partial)
    assert info.value.key == "he.density"
    assert "target.conductivity" in str(info.value)


def test_a_key_given_twice_in_one_mapping_is_refused():
    with pytest.raises(SceneError) as info:
        make_scene({"he.density": 1900.0, "he": {"density": 1800.0}}, preset="paper-quartz")
    assert info.value.key == "he.density"


def test_unknown_preset_lists_presets():
    with pytest.raises(SceneError) as info:
        make_scene(preset="paper-quarz")
    assert info.value.key == "preset" and "paper-quartz" in str(info.value)


def test_direct_construction_validates_si_floats():
    values = {k.replace(".", "_"): v for k, v in {**FULL, "tilt": 0.0}.items()}
    assert Scene(**values) == make_scene(FULL)
    with pytest.raises(SceneError) as info:
        Scene(**{**values, "flow_stress": "28000 psi"})
    assert info.value.key == "flow_stress" and "make_scene" in str(info.value)
    with pytest.raises(SceneError):
        Scene(**{**values, "he_density": -1.0})


@pytest.mark.parametrize(
    "err",
    [
        SceneError("mu", "-1", "must be >= 0"),
        UnknownKeyError("muu", 0.1, ["mu"]),
        UnitError("flow_stress", "10 in", "wrong dimension"),
        MissingKeyError("mu", None, "missing"),
    ],
)
def test_errors_pickle(err):  # errors cross process boundaries in the ensemble runner
    back = pickle.loads(pickle.dumps(err))
    assert type(back) is type(err)
    assert (back.key, back.value, str(back)) == (err.key, err.value, str(err))


# --- SceneColumns: the runner's fast path equals make_scene ---------------------------------------


def _outcome(build):
    """What building a scene gives, comparable bit for bit: the fields (type and exact value) or
    the error (class, key, value, message)."""
    try:
        scene = build()
    except Exception as exc:  # noqa: BLE001 - compared below
        return ("error", type(exc), getattr(exc, "key", None), repr(getattr(exc, "value", None)),
                str(exc))
    return ("scene", tuple(
        (f.name, type(v), v.hex() if isinstance(v, float) else v)
        for f in dataclasses.fields(Scene) for v in [getattr(scene, f.name)]))


def _assert_columns_match_make_scene(base, columns):
    from skidmc.scene import SceneColumns

    columns = {k: np.asarray(v, dtype=float) for k, v in columns.items()}
    built = SceneColumns(base, columns)
    m = len(next(iter(columns.values())))
    assert len(built) == m
    for i in range(m):
        row = {k: v[i].item() for k, v in columns.items()}  # as the runner's general path
        assert [(k, v.hex()) for k, v in built.row(i).items()] == [
            (k, v.hex()) for k, v in row.items()]  # bitwise (NaN too)
        # SceneColumns holds programmatic SI floats: make_scene without the plausibility check
        general = _outcome(lambda: make_scene(row, preset=base, check_plausible=False))  # noqa: B023
        assert _outcome(lambda: built.scene(i)) == general, row  # noqa: B023


_EDGES = [0.0, -0.0, 1e-300, 0.5, 5.0, 45.0, 89.999999, 90.0, 300.0, 553.0, 1e30, -1.0,
          math.nan, math.inf, -math.inf]


@pytest.mark.parametrize("preset", ["paper-quartz", "paper-gold"])  # pendulum, vertical
@pytest.mark.parametrize("keys", [
    ("mu",), ("angle",), ("tilt",), ("angle", "tilt"), ("tilt", "angle", "mu"),
    ("initial_temperature",), ("he.melting_point",), ("he.melting_point", "initial_temperature"),
    ("he.heat_of_fusion", "kinetics.heat_of_reaction", "target.conductivity", "billet_mass"),
])
def test_scene_columns_equal_make_scene_on_edges(preset, keys):
    base = make_scene(preset=preset)
    # Every edge value in every column, plus rows mixing a valid value with an edge elsewhere.
    grid = np.array(np.meshgrid(*[_EDGES] * len(keys))).reshape(len(keys), -1) if len(keys) < 3 \
        else np.array([np.roll(_EDGES, j) for j in range(len(keys))])
    _assert_columns_match_make_scene(base, dict(zip(keys, grid)))


def test_scene_columns_vertical_tilt_close_to_angle():
    gold = make_scene(preset="paper-gold")
    angle = np.array([45.0, 45.0, 45.0, 30.0, 30.0])
    tilt = angle * np.array([1.0, 1 + 1e-12, 1 + 1e-6, 1.0, 0.5])  # equal, close, off, ...
    _assert_columns_match_make_scene(gold, {"angle": angle, "tilt": tilt})
    _assert_columns_match_make_scene(gold, {"tilt": tilt})  # against the base's angle
    # A base whose tilt is within 1e-9 of its angle but not equal: make_scene makes it the angle.
    close = make_scene(preset="paper-gold", tilt=45.0 * (1 + 1e-12))
    assert close.tilt != close.angle
    _assert_columns_match_make_scene(close, {"mu": np.array([0.1, 0.2])})
    _assert_columns_match_make_scene(close, {"angle": angle})


@given(st.lists(st.tuples(*[st.floats(allow_nan=True, allow_infinity=True)] * 4),
                min_size=1, max_size=8),
       st.sampled_from(["paper-quartz", "paper-gold", "paper-alumina-rough"]))
def test_scene_columns_equal_make_scene_on_any_floats(rows, preset):
    keys = ("angle", "mu", "initial_temperature", "he.melting_point")
    _assert_columns_match_make_scene(make_scene(preset=preset), dict(zip(keys, zip(*rows))))


def test_scene_columns_scenes_are_ordinary_scenes():
    from skidmc.scene import SceneColumns

    gold = make_scene(preset="paper-gold")
    built = SceneColumns(gold, {"angle": np.array([30.0]), "mu": np.array([0.2])})
    assert built.derived == ("tilt",) and built.keys == ("angle", "mu")
    assert built.row(0) == {"angle": 30.0, "mu": 0.2}  # the derived tilt is not a given key
    scene = built.scene(0)
    assert scene == gold.replace(angle=30.0, mu=0.2) and scene.tilt == 30.0
    assert hash(scene) == hash(gold.replace(angle=30.0, mu=0.2))
    assert pickle.loads(pickle.dumps(scene)) == scene
    with pytest.raises(dataclasses.FrozenInstanceError):
        scene.mu = 0.3
    assert SceneColumns(make_scene(preset="paper-quartz"), {"mu": np.array([0.2])}).derived == ()


@pytest.mark.parametrize("base, columns", [
    (None, {"mu": np.array([0.1])}),
    ("paper-quartz", {"mu": np.array([0.1])}),
    (make_scene(preset="paper-quartz"), {"mu": np.array([1, 2])}),  # integers: make_scene's
    (make_scene(preset="paper-quartz"), {"mu": np.array([0.1], dtype=np.float32)}),
    (make_scene(preset="paper-quartz"), {"mu": np.array(["0.1"], dtype=object)}),
    (make_scene(preset="paper-quartz"), {"he_density": np.array([1900.0])}),  # attribute name
    (make_scene(preset="paper-quartz"), {"muu": np.array([0.1])}),
    (make_scene(preset="paper-quartz"), {"configuration": np.array(["vertical"])}),
    (make_scene(preset="paper-quartz"), {"mu": np.array([[0.1]])}),
    (make_scene(preset="paper-quartz"), {"mu": np.array(0.1)}),
    (make_scene(preset="paper-quartz"), {"mu": np.array([0.1]), "angle": np.array([1.0, 2.0])}),
    (make_scene(preset="paper-quartz"), [("mu", np.array([0.1]))]),
])
def test_scene_columns_refuses_what_is_make_scenes(base, columns):
    from skidmc.scene import SceneColumns

    assert not SceneColumns.accepts(base, columns)
    with pytest.raises(ValueError, match="make_scene"):
        SceneColumns(base, columns)


def test_scene_columns_without_columns():
    from skidmc.scene import SceneColumns

    assert len(SceneColumns(make_scene(preset="paper-quartz"), {})) == 0
