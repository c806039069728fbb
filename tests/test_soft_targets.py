"""Targets softer than the billet (``target.hardness``, docs/model.md "Targets softer than the
billet"): the contact pressure is min(sigma, p_t), flagged ``yielding_target``; an elastic target
is refused; a target harder than the billet changes nothing."""

from __future__ import annotations

import math

import numpy as np
import pytest

from skidmc.errors import SceneError
from skidmc.physics import mechanics
from skidmc.scene import get_preset, make_scene
from skidmc.scene.materials import MATERIALS
from skidmc.solver import critical_height
from skidmc.solver.fast import fast_critical_height, fast_critical_heights, scene_columns
from skidmc.solver.model import build_model

# The hazard study's billet on a vertical drop (studies/hazard-handling.toml): 19.1 lb, 10 in,
# 28,000 psi (193 MPa).
FLOOR = dict(preset="paper-quartz", configuration="vertical", angle="20 deg", mu=0.243)


def test_presets_and_hard_materials_keep_the_rigid_target():
    for name in ("paper-quartz", "paper-gold", "paper-alumina-rough"):
        scene = get_preset(name)
        assert scene.target_hardness == math.inf
        assert "yielding_target" not in build_model(scene, meshes=False).flags
    for name, m in MATERIALS.items():
        if m.hardness == "rigid":
            scene = make_scene(target=name, **FLOOR)
            assert "yielding_target" not in build_model(scene, meshes=False).flags, name


def test_words_and_units_for_the_hardness():
    assert make_scene(preset="paper-quartz", **{"target.hardness": "rigid"}).target_hardness \
        == math.inf
    assert make_scene(preset="paper-quartz", **{"target.hardness": "elastic"}).target_hardness \
        == 0.0
    assert make_scene(preset="paper-quartz", **{"target.hardness": "40 MPa"}).target_hardness \
        == pytest.approx(4e7, rel=1e-12)
    with pytest.raises(SceneError, match="target.hardness"):
        make_scene(preset="paper-quartz", **{"target.hardness": "-1 MPa"})
    # concrete: 2 x 0.85 f'c with f'c = 4000 psi (ACI 318 bearing), 6800 psi
    assert make_scene(target="concrete", **FLOOR).target_hardness == pytest.approx(
        6800 * 6894.757293168, rel=1e-9)


def test_contact_pressure_is_the_weaker_of_billet_and_target():
    assert mechanics.contact_pressure(193e6, math.inf) == 193e6
    assert mechanics.contact_pressure(193e6, 47e6) == 47e6
    assert mechanics.contact_pressure(193e6, 1e9) == 193e6


@pytest.mark.parametrize("material", ["concrete", "oak", "pine"])
def test_a_yielding_target_is_the_reports_contact_at_its_hardness(material):
    """The model's claim: with p_t < sigma every equation takes p = p_t. So the scene equals,
    bit for bit, the rigid-target scene whose billet flow stress is p_t (only the flag
    differs); and t_c grows as (sigma / p_t)^(1/2) (omega = (pi p D / W)^(1/2))."""
    soft = make_scene(target=material, **FLOOR)
    p_t = soft.target_hardness
    assert p_t < soft.flow_stress
    same = soft.replace(flow_stress=p_t, **{"target.hardness": "rigid"})
    rigid = soft.replace(**{"target.hardness": "rigid"})
    m_soft, m_same, m_rigid = (build_model(s, level=0.5) for s in (soft, same, rigid))
    assert "yielding_target" in m_soft.flags and "yielding_target" not in m_same.flags
    assert m_soft.omega == m_same.omega and m_soft.exit_time == m_same.exit_time
    assert m_soft.flux_per_root_height == m_same.flux_per_root_height
    np.testing.assert_array_equal(m_soft.width, m_same.width)
    # closed form: the same shape of V_r in omega t, so t_c and t_exit scale alike
    ratio = math.sqrt(soft.flow_stress / p_t)
    assert m_soft.contact_time / m_rigid.contact_time == pytest.approx(ratio, rel=1e-12)
    assert m_soft.exit_time / m_rigid.exit_time == pytest.approx(ratio, rel=1e-12)
    assert m_soft.flux_per_root_height / m_rigid.flux_per_root_height == pytest.approx(
        p_t / soft.flow_stress, rel=1e-12)
    # the fast tier takes the same contact pressure, scalar and batched
    f_soft, f_same = fast_critical_height(soft), fast_critical_height(same)
    assert f_soft.critical_height == f_same.critical_height
    assert "yielding_target" in f_soft.flags
    batch = fast_critical_heights(**scene_columns([soft, same, rigid]))
    assert batch["critical_height"][0] == batch["critical_height"][1] == f_soft.critical_height


def test_full_search_on_a_yielding_floor_equals_the_softer_billet():
    soft = make_scene(target="concrete", **FLOOR)
    same = soft.replace(flow_stress=soft.target_hardness, **{"target.hardness": "rigid"})
    a, b = critical_height(soft, rtol=1e-2), critical_height(same, rtol=1e-2)
    # the same arithmetic: identical heights (a tolerance would hide a difference in p)
    assert a.critical_height == b.critical_height
    assert "yielding_target" in a.flags and "yielding_target" not in b.flags
    rigid = critical_height(soft.replace(**{"target.hardness": "rigid"}), rtol=1e-2)
    # a softer contact heats less: the floor that yields needs a higher drop
    assert a.critical_height > 2.0 * rigid.critical_height


def test_a_target_harder_than_the_billet_changes_nothing():
    scene = make_scene(preset="paper-quartz")
    hard = scene.replace(**{"target.hardness": "1 GPa"})
    a, b = critical_height(hard, rtol=1e-2), critical_height(scene, rtol=1e-2)
    assert a.critical_height == b.critical_height and a.flags == b.flags
    assert a.error_estimate == b.error_estimate and a.evaluations == b.evaluations


def test_an_elastic_target_is_refused_with_the_reason():
    rubber = make_scene(target="rubber", **FLOOR)
    assert rubber.target_hardness == 0.0 and MATERIALS["rubber"].elastic
    for call in (lambda: critical_height(rubber, rtol=1e-2),
                 lambda: critical_height(rubber, tier="fast"),
                 lambda: build_model(rubber),
                 lambda: fast_critical_heights(**scene_columns([rubber]))):
        with pytest.raises(SceneError, match="target.hardness") as info:
            call()
        assert "elastic" in str(info.value) and "plastic-contact" in str(info.value)


def test_the_device_search_takes_the_contact_pressure_and_hands_back_what_it_cannot_do():
    """The GPU search (here its CPU build, skidmc.solver.cuda backend="cpu") reads the
    hardness column: a yielding floor is, bit for bit, the softer billet on a rigid floor;
    an elastic floor and a layered target go to the CPU search (the first refused with the
    reason, the second meshed there)."""
    from skidmc.solver.cuda import solve_scenes

    soft = make_scene(target="concrete", **FLOOR)
    same = soft.replace(flow_stress=soft.target_hardness, **{"target.hardness": "rigid"})
    stack = make_scene(preset="paper-gold", target="gold-stack-report")
    rubber = make_scene(target="rubber", **FLOOR)
    a, b, c, d = solve_scenes([soft, same, stack, rubber], backend="cpu", rtol=1e-2)
    assert a.method == b.method == "device"
    assert a.critical_height == b.critical_height and "yielding_target" in a.flags
    assert c.method != "device" and "layered_target" in c.terms
    assert isinstance(d, SceneError) and "elastic" in str(d)
