"""Presets against the report's tables, and the transcribed tables against themselves.

Expected SI values are computed here from the report's printed numbers and exact unit definitions
(1 in = 0.0254 m, 1 lb = 0.45359237 kg, g_n = 9.80665 m/s^2, 1 cal = 4.184 J, 1 degR = 5/9 K),
independently of pint; the relative tolerance 1e-12 only absorbs floating-point rounding.
"""

from __future__ import annotations

import itertools

import pytest

from skidmc.errors import SceneError
from skidmc.scene import SCENE_KEYS, Scene, get_preset, list_presets
from skidmc.scene.presets import (
    PAPER_TABLE_III,
    PAPER_TABLE_IV,
    PAPER_TABLE_IX,
    PAPER_TABLE_VIII,
    PRESETS,
)

INCH = 0.0254
LB = 0.45359237
PSI = LB * 9.80665 / INCH**2
CAL = 4.184
EXACT = 1e-12

# Table VI: density [g/cm^3], heat capacity [cal/g-C], conductivity [cal/s-cm-C], and the
# report's own diffusivity column [cm^2/s].
TABLE_VI = {
    "HMX": (1.91, 0.295, 9.2e-4, 1.65e-3),
    "quartz": (2.67, 0.188, 4.05e-3, 8.11e-3),
    "alumina": (3.40, 0.18, 2.1e-2, 3.45e-2),
    "gold": (19.3, 0.0316, 7.03e-1, 1.16),
}

# preset -> (mu [Table V / IX], sigma [psi], configuration, phi [deg], psi [deg], target row)
EXPECTED = {
    "paper-quartz": (0.132, 28000, "pendulum", 60.0, 0.0, "quartz"),
    "paper-alumina-smooth": (0.0576, 28000, "pendulum", 60.0, 0.0, "alumina"),
    "paper-alumina-rough": (0.0808, 28000, "pendulum", 60.0, 0.0, "alumina"),
    "paper-gold": (0.117, 28000, "vertical", 45.0, 45.0, "gold"),
    "paper2-quartz": (0.114, 34400, "pendulum", 60.0, 0.0, "quartz"),
}


def test_list_presets():
    assert list_presets() == list(PRESETS) == list(EXPECTED)


@pytest.mark.parametrize("name", list(PRESETS))
def test_preset_is_complete_and_documented(name):
    entry = PRESETS[name]
    assert set(entry) == {"source", "notes", "values"}
    assert entry["source"] and entry["notes"]
    assert set(entry["values"]) == set(SCENE_KEYS)
    assert all(isinstance(v, str) for v in entry["values"].values())  # human-readable units


@pytest.mark.parametrize("name", list(PRESETS))
def test_preset_matches_report_tables(name):
    mu, sigma_psi, configuration, phi, psi, target = EXPECTED[name]
    scene = get_preset(name)
    assert isinstance(scene, Scene)
    assert scene.mu == mu
    assert scene.flow_stress == pytest.approx(sigma_psi * PSI, rel=EXACT)
    assert scene.billet_diameter == pytest.approx(10 * INCH, rel=EXACT)
    # Second series: 25.3 lb is the documented inferred assumption (not in the report).
    mass_lb = 25.3 if name == "paper2-quartz" else 19.1
    assert scene.billet_mass == pytest.approx(mass_lb * LB, rel=EXACT)
    assert (scene.configuration, scene.angle, scene.tilt) == (configuration, phi, psi)
    # HE: Tables VI and VII, T0 = 530 degR (Sec. IV)
    rho, c, k, _ = TABLE_VI["HMX"]
    assert scene.he_density == pytest.approx(rho * 1e3, rel=EXACT)
    assert scene.he_heat_capacity == pytest.approx(c * CAL * 1e3, rel=EXACT)
    assert scene.he_conductivity == pytest.approx(k * CAL * 1e2, rel=EXACT)
    assert scene.he_heat_of_fusion == pytest.approx(50 * CAL * 1e3, rel=EXACT)
    assert scene.he_melting_point == 553.0
    assert scene.kinetics_prefactor == 5.0e19
    assert scene.kinetics_activation_temperature == 2.63e4
    assert scene.kinetics_heat_of_reaction == pytest.approx(6.66e5 / 296.16 * CAL * 1e3, rel=EXACT)
    assert scene.initial_temperature == pytest.approx(530 * 5 / 9, rel=EXACT)
    rho, c, k, _ = TABLE_VI[target]
    assert scene.target_density == pytest.approx(rho * 1e3, rel=EXACT)
    assert scene.target_heat_capacity == pytest.approx(c * CAL * 1e3, rel=EXACT)
    assert scene.target_conductivity == pytest.approx(k * CAL * 1e2, rel=EXACT)


def test_heat_of_reaction_and_adiabatic_rise_as_in_physics_notes():
    scene = get_preset("paper-quartz")
    assert scene.kinetics_heat_of_reaction / (CAL * 1e3) == pytest.approx(2249, abs=0.5)  # cal/g
    adiabatic_rise = scene.kinetics_heat_of_reaction / scene.he_heat_capacity
    assert adiabatic_rise == pytest.approx(7600, rel=0.01)  # K


def test_conductivities_are_per_degree_celsius():
    """Table VI's diffusivity column k / (rho c) holds only if k and c share the degree.

    The printed inputs have three significant figures, so the recomputed diffusivities agree with
    the printed ones to ~1%; reading k per degR would be off by a factor of 1.8.
    """
    presets = {"HMX": "paper-quartz", "quartz": "paper-quartz", "alumina": "paper-alumina-smooth",
               "gold": "paper-gold"}
    for material, name in presets.items():
        scene = get_preset(name)
        if material == "HMX":
            k, rho, c = scene.he_conductivity, scene.he_density, scene.he_heat_capacity
        else:
            k, rho, c = scene.target_conductivity, scene.target_density, scene.target_heat_capacity
        alpha_cm2_s = k / (rho * c) * 1e4
        assert alpha_cm2_s == pytest.approx(TABLE_VI[material][3], rel=0.015)


def test_second_series_assumption_is_marked():
    notes = PRESETS["paper2-quartz"]["notes"]
    assert "ASSUMPTION" in notes and "25.3 lb" in notes and "second_series.md" in notes


def test_unknown_preset_lists_the_names():
    with pytest.raises(SceneError) as info:
        get_preset("quartz")
    assert info.value.key == "preset" and info.value.value == "quartz"
    for name in PRESETS:
        assert name in str(info.value)


# --- published heights -----------------------------------------------------------------------


def test_table_viii_rows_match_presets():
    assert [row.calculated_ft for row in PAPER_TABLE_VIII] == [515.0, 22.8, 14.2, 1.25]
    assert [row.experimental_ft for row in PAPER_TABLE_VIII] == [150.0, 19.0, 11.0, 1.8]
    for row in PAPER_TABLE_VIII:
        assert get_preset(row.preset).mu == row.mu
        assert row.experimental_qualifier in {"=", "~", ">"}


def test_table_ix_rows():
    assert [row.mu for row in PAPER_TABLE_IX] == [0.056, 0.092, 0.114, 0.151, 0.243]
    assert [row.calculated_ft for row in PAPER_TABLE_IX] == [3.76, 1.48, 1.0, 0.61, 0.28]
    assert [row.experimental_ft for row in PAPER_TABLE_IX] == [4.8, 1.8, 2.4, 0.5, 0.7]
    for row in PAPER_TABLE_IX:
        assert get_preset(row.preset).replace(mu=row.mu).mu == row.mu
    # the calculated heights fall monotonically with mu (Fig. 6)
    calculated = [row.calculated_ft for row in PAPER_TABLE_IX]
    assert calculated == sorted(calculated, reverse=True)


# --- up-down sequences (Tables III, IV) -----------------------------------------------------------


@pytest.mark.parametrize("table", [PAPER_TABLE_III, PAPER_TABLE_IV], ids=["III", "IV"])
def test_up_down_sequence_follows_the_up_down_rule(table):
    """Dixon & Mood: after an event the next drop is one level lower, after none one level higher.

    This checks the transcription of the OCR'd tables (column positions) against the method.
    """
    levels = sorted({d.height_ft for d in table})
    assert [d.drop for d in table] == list(range(1, len(table) + 1))
    for this, following in itertools.pairwise(table):
        step = -1 if this.event else 1
        assert levels.index(following.height_ft) == levels.index(this.height_ft) + step


def test_table_iii_quartz():
    assert len(PAPER_TABLE_III) == 10 and all(d.valid for d in PAPER_TABLE_III)
    events = [d.drop for d in PAPER_TABLE_III if d.event]
    assert events == [2, 4, 6, 8]
    assert {d.height_ft for d in PAPER_TABLE_III} == {1.5, 2.12}


def test_table_iv_alumina():
    assert len(PAPER_TABLE_IV) == 12
    assert [d.drop for d in PAPER_TABLE_IV if not d.valid] == [7]
    assert [d.drop for d in PAPER_TABLE_IV if d.event] == [1, 3, 7, 10]
    assert {d.finish for d in PAPER_TABLE_IV[:3]} == {"50-80 uin"}
    assert {d.finish for d in PAPER_TABLE_IV[3:]} == {"20-35 uin"}
    assert {d.height_ft for d in PAPER_TABLE_IV} == {9.25, 11.0, 13.1, 15.6, 18.5}
