"""The fast tier (skidmc.physics.fast kernels, skidmc.solver.fast).

Duhamel integral, agreement with the full model, trends, censoring and robustness at the extremes
of the input ranges."""

import math

import numpy as np
import pytest
from scipy.integrate import quad

from skidmc.physics import fast, mechanics
from skidmc.physics.fast import (
    CENSOR_ABOVE,
    CENSOR_BELOW,
    CENSOR_NONE,
    duhamel_theta,
)
from skidmc.physics.mechanics import impact_constants
from skidmc.scene import get_preset
from skidmc.solver import critical_height
from skidmc.solver.fast import (
    fast_critical_height,
    fast_critical_heights,
    scene_columns,
    theta_history,
)

G = 9.80665
PRESETS = ["paper-gold", "paper-alumina-smooth", "paper-alumina-rough", "paper-quartz",
           "paper2-quartz"]


def effusivities(scene):
    e1 = math.sqrt(scene.he_conductivity * scene.he_density * scene.he_heat_capacity)
    e2 = math.sqrt(scene.target_conductivity * scene.target_density
                   * scene.target_heat_capacity)
    return e1, e2


@pytest.mark.parametrize("name", ["paper-quartz", "paper-gold"])
def test_theta_constant_flux_closed_form(name):
    """Constant flux q: T_s - T0 = 2 q sqrt(t) / (sqrt(pi) (e1 + e2))."""
    scene = get_preset(name)
    e1, e2 = effusivities(scene)
    omega, _, t_exit, _, s, _ = impact_constants(scene.mu, scene.flow_stress, scene.billet_mass,
                                              scene.billet_diameter, scene.angle, scene.tilt)
    q_root = scene.mu * scene.flow_stress * math.sqrt(2.0 * G)
    times = t_exit * np.linspace(0.01, 1.0, 40)
    out = np.empty_like(times)
    duhamel_theta(q_root, s, 0.0, omega, t_exit, e1 + e2, times, fast._GL_X01, fast._GL_W01,
                  out)
    exact = 2.0 * q_root * s * np.sqrt(times) / (math.sqrt(math.pi) * (e1 + e2))
    np.testing.assert_allclose(out, exact, rtol=1e-12)


@pytest.mark.parametrize("name", ["paper-quartz", "paper-gold"])
def test_theta_eq10_flux_against_quadrature(name):
    """The scene's own flux shape (Eq. 10) against adaptive quadrature of the singular kernel."""
    scene = get_preset(name)
    e1, e2 = effusivities(scene)
    omega, _, t_exit, _, s, c = impact_constants(scene.mu, scene.flow_stress, scene.billet_mass,
                                              scene.billet_diameter, scene.angle, scene.tilt)
    q_root = scene.mu * scene.flow_stress * math.sqrt(2.0 * G)
    times, theta = theta_history(scene)
    for t, th in zip(times[::7], theta[::7]):
        # int_0^t q(tau) (t - tau)^(-1/2) dtau with QUADPACK's algebraic-singularity weight
        val, _ = quad(lambda tau: q_root * max(s - c * (1.0 - math.cos(omega * tau)), 0.0),
                      0.0, t, weight="alg", wvar=(0.0, -0.5), epsabs=0.0, epsrel=1e-12)
        assert th == pytest.approx(val / (math.sqrt(math.pi) * (e1 + e2)), rel=1e-8)


def test_theta_scales_with_root_height():
    # The separation T_s - T0 = sqrt(H) Theta(t) that the tier rests on: Theta is a property of
    # the scene alone. Compare with the full model's own mechanics (flux per root height).
    from skidmc.solver.model import build_model

    scene = get_preset("paper-alumina-rough")
    model = build_model(scene)
    omega, _, t_exit, _, s, c = impact_constants(scene.mu, scene.flow_stress, scene.billet_mass,
                                              scene.billet_diameter, scene.angle, scene.tilt)
    assert omega == pytest.approx(model.omega, rel=1e-12)
    assert t_exit == pytest.approx(model.exit_time, rel=1e-12)
    assert (s, c) == pytest.approx((model.slide_s, model.slide_c), rel=1e-12)
    gold = get_preset("paper-gold")
    gm = build_model(gold)
    _, _, t_exit_g, code, _, _ = impact_constants(gold.mu, gold.flow_stress, gold.billet_mass,
                                               gold.billet_diameter, gold.angle, gold.tilt)
    assert code == mechanics.EXIT_STOPS_SLIDING and gm.exit_kind == "stops_sliding"
    assert t_exit_g == pytest.approx(gm.exit_time, rel=1e-12)


def test_melt_depression_table():
    assert fast.melt_depression(1.0) == 0.0
    g = fast.MELT_TABLE
    assert np.all(np.isfinite(g)) and g[-1] == 0.0
    assert np.all(np.diff(g) <= 0.0)  # more melting the further T_s is above T_m


def test_stored_melt_table_is_the_computed_one():
    # MELT_TABLE is read from skidmc/data/melt_table.txt (scripts/make_melt_table.py), not
    # computed at import. It is melt_table()'s values written exactly (float.hex), so on the
    # scipy it was written with the two agree bit for bit; the tolerance admits only the
    # last-bit differences another scipy release's erfc (cephes, ~1e-16 relative) could make
    # through the Newton solve and the 48-point sum.
    assert fast.MELT_TABLE.shape == (fast.MELT_TABLE_POINTS,)
    np.testing.assert_allclose(fast.MELT_TABLE, fast.melt_table(), rtol=1e-13, atol=0.0)


# Tolerance against the full model: the measured test-set error of the tier
# (results/benchmarks/fast_tier.md: p90 ~5 %, the presets themselves within 3 %) plus the full
# model's own rtol (1 %).
PRESET_TOLERANCE = 0.06


@pytest.mark.parametrize("name", PRESETS)
def test_presets_close_to_full_model(name):
    scene = get_preset(name)
    full = critical_height(scene, rtol=1e-2)
    res = fast_critical_height(scene)
    assert res.censored is None and full.censored is None
    assert res.critical_height == pytest.approx(full.critical_height, rel=PRESET_TOLERANCE)
    assert res.method == "fast" and res.evaluations == 0
    assert res.exit_kind == full.exit_kind
    assert res.exit_time == pytest.approx(full.exit_time, rel=1e-12)
    assert set(res.flags) <= set(full.flags)  # the tier infers stops_sliding, no_friction
    assert set(res.terms) == set(full.terms)
    assert 0.0 < res.error_estimate < 0.2


@pytest.mark.parametrize("name", ["paper-quartz", "paper-alumina-smooth"])
def test_melting_increment_follows_full_model(name):
    # Melting raises the critical height by ~8-13 % in the full model; the tier's approximate
    # latent-heat depression must reproduce that rise within a few percent.
    scene = get_preset(name)
    full_ratio = (critical_height(scene, rtol=1e-2).critical_height
                  / critical_height(scene, rtol=1e-2, melting=False).critical_height)
    fast_ratio = (fast_critical_height(scene).critical_height
                  / fast_critical_height(scene, melting=False).critical_height)
    assert full_ratio > 1.05 and fast_ratio > 1.03
    assert fast_ratio == pytest.approx(full_ratio, rel=0.04)


def test_height_falls_with_friction():
    base = get_preset("paper-quartz")
    heights = [fast_critical_height(base.replace(mu=mu)).critical_height
               for mu in (0.02, 0.05, 0.1, 0.2, 0.4)]
    assert all(np.diff(heights) < 0.0)


def test_height_rises_with_target_effusivity():
    base = get_preset("paper-alumina-smooth")
    heights = [fast_critical_height(base.replace(**{"target.conductivity": k})).critical_height
               for k in (1.0, 3.0, 10.0, 30.0, 100.0, 400.0)]
    assert all(np.diff(heights) > 0.0)


def test_censoring():
    quartz = get_preset("paper-quartz")
    res = fast_critical_height(quartz.replace(mu=0.0))
    assert res.censored == "above" and res.critical_height == 1e4
    assert "no_friction" in res.flags and res.terms == ()
    h = fast_critical_height(quartz).critical_height
    above = fast_critical_height(quartz, h_max=0.5 * h)
    assert above.censored == "above" and above.critical_height == 0.5 * h
    below = fast_critical_height(quartz, h_min=2.0 * h)
    assert below.censored == "below" and below.critical_height == 2.0 * h
    # An HE that runs away at its initial temperature within the contact: "below", as in the
    # full model.
    hot = quartz.replace(**{"kinetics.prefactor": 1e30, "kinetics.activation_temperature": 15000.0})
    assert fast_critical_height(hot).censored == "below"
    assert critical_height(hot, rtol=1e-2).censored == "below"
    with pytest.raises(ValueError):
        fast_critical_height(quartz, h_min=10.0, h_max=1.0)


def test_batched_equals_single():
    scenes = [get_preset(n) for n in PRESETS] + [get_preset("paper-quartz").replace(mu=0.0)]
    res = fast_critical_heights(**scene_columns(scenes))
    for i, s in enumerate(scenes):
        one = fast_critical_height(s)
        assert res["critical_height"][i] == one.critical_height
        assert res["exit_time"][i] == one.exit_time
    assert list(res["censored"]) == [CENSOR_NONE] * 5 + [CENSOR_ABOVE]
    with pytest.raises(TypeError):
        fast_critical_heights(mu=[0.1])


def _extreme_columns(n, seed):
    """Random scenes over the extreme ranges the tier must survive."""
    rng = np.random.default_rng(seed)
    loguni = lambda a, b: np.exp(rng.uniform(math.log(a), math.log(b), n))  # noqa: E731
    t_act = rng.uniform(15000.0, 40000.0, n)
    # prefactor over 10 decades around a compensation line through the report's rate at 575 K
    z = 5e19 * np.exp(-26300.0 / 575.0 + t_act / 575.0) * 10.0 ** rng.uniform(-5.0, 5.0, n)
    angle = rng.uniform(1.0, 89.0, n)
    k2 = loguni(1.3, 400.0)  # fused quartz ... copper
    return {
        "mu": loguni(1e-3, 0.8), "flow_stress": loguni(1e6, 500e6),
        "billet_mass": loguni(0.1, 100.0), "billet_diameter": loguni(0.02, 0.5),
        "angle": angle, "tilt": np.where(rng.random(n) < 0.5, angle, 0.0),
        "initial_temperature": rng.uniform(200.0, 450.0, n),
        "he_density": np.full(n, 1910.0), "he_heat_capacity": rng.uniform(900.0, 1500.0, n),
        "he_conductivity": rng.uniform(0.2, 0.6, n),
        "he_heat_of_fusion": np.where(rng.random(n) < 0.8, 209200.0, 0.0),
        "he_melting_point": np.full(n, 553.0),
        "kinetics_prefactor": z, "kinetics_activation_temperature": t_act,
        "kinetics_heat_of_reaction": np.where(rng.random(n) < 0.05, 0.0,
                                              rng.uniform(5e5, 1e7, n)),
        "target_density": rng.uniform(2200.0, 8960.0, n),
        "target_heat_capacity": rng.uniform(385.0, 750.0, n),
        "target_conductivity": k2,
    }


def test_extremes_finite_or_censored():
    cols = _extreme_columns(4000, seed=7)
    res = fast_critical_heights(**cols)
    h, c = res["critical_height"], res["censored"]
    assert np.all(np.isfinite(h)) and np.all(np.isfinite(res["exit_time"]))
    assert np.all((h >= 1e-3) & (h <= 1e4))
    assert set(np.unique(c)) <= {CENSOR_NONE, CENSOR_ABOVE, CENSOR_BELOW}
    assert np.all(h[c == CENSOR_ABOVE] == 1e4) and np.all(h[c == CENSOR_BELOW] == 1e-3)
    assert (c == CENSOR_NONE).sum() > 1000  # most of the range gives a real root


@pytest.mark.parametrize("target", [("fused quartz", 1.3, 2200.0, 740.0),
                                    ("copper", 400.0, 8960.0, 385.0)])
@pytest.mark.parametrize("mu", [1e-3, 0.8])
@pytest.mark.parametrize("angle", [1.0, 89.0])
@pytest.mark.parametrize("t_act", [15000.0, 40000.0])
def test_extreme_corners(target, mu, angle, t_act):
    _, k, rho, cp = target
    base = get_preset("paper-quartz")
    for sigma, mass, t0, zfac in [(1e6, 0.1, 200.0, 1e-5), (500e6, 100.0, 450.0, 1e5)]:
        z = 5e19 * math.exp(-26300.0 / 575.0 + t_act / 575.0) * zfac
        scene = base.replace(**{
            "mu": mu, "angle": angle, "flow_stress": sigma, "billet_mass": mass,
            "initial_temperature": t0, "kinetics.prefactor": z,
            "kinetics.activation_temperature": t_act, "target.conductivity": k,
            "target.density": rho, "target.heat_capacity": cp})
        res = fast_critical_height(scene)
        assert math.isfinite(res.critical_height)
        assert 1e-3 <= res.critical_height <= 1e4
        assert res.censored in (None, "above", "below")
        assert (res.censored is None) or res.critical_height in (1e-3, 1e4)


# --- the fast tier's validity flags: the mesh-less model ----------------------------------------

def _flag_scenes():
    """Presets and variants that between them set every validity flag."""
    quartz = get_preset("paper-quartz")
    variants = [
        {"mu": 0.0},                                       # no_friction
        {"mu": 0.9},                                       # stops_sliding
        {"mu": 4.0, "angle": 20.0},                        # stops_early
        {"configuration": "vertical", "angle": 30.0},      # normal_force_spin
        {"initial_temperature": 440.0},                    # self_heating
        {"kinetics.prefactor": 1e10},                      # hot_ignition
        {"flow_stress": 1e6},                              # crushed
        {"angle": 89.0, "mu": 0.01},                       # long_slide
        {"he.heat_of_fusion": 0.0},
        {"kinetics.heat_of_reaction": 0.0},
    ]
    return [get_preset(n) for n in PRESETS] + [quartz.replace(**v) for v in variants]


@pytest.mark.parametrize("melting", [True, False])
def test_meshless_model_equals_meshed_one(melting):
    # critical_height(tier="fast") takes its flags from build_model(meshes=False), which skips
    # the mesh arithmetic: every other field, and the per-height flags, must be the meshed
    # model's, bit for bit.
    import dataclasses

    from skidmc.solver.model import build_model

    mesh_fields = {"width", "rho_c", "face_conductance", "n_target", "q_share_he",
                   "target_table"}
    seen = set()
    for scene in _flag_scenes():
        meshed = build_model(scene, melting=melting)
        bare = build_model(scene, melting=melting, meshes=False)
        for f in dataclasses.fields(bare):
            if f.name not in mesh_fields:
                a, b = getattr(meshed, f.name), getattr(bare, f.name)
                assert a == b or (a != a and b != b), f.name  # NaN == NaN here
        assert bare.n_target == 0 and math.isnan(bare.q_share_he)
        for arr in (bare.width, bare.rho_c, bare.face_conductance):
            assert arr.shape == (0,) and arr.dtype == np.float64
        for h in (1e-3, 0.1, 1.0, 10.0, 100.0, 1e4):
            assert bare.height_flags(h) == meshed.height_flags(h)
            seen.update(bare.height_flags(h))
        seen.update(bare.flags)
    assert seen == {"no_friction", "stops_sliding", "stops_early", "self_heating",
                    "hot_ignition", "crushed", "long_slide"}


def test_exit_from_constants_equals_contact_and_stop_time():
    # The compiled scalar exit (mechanics.exit_from_constants, used by build_model and the fast
    # kernels) equals the array functions' contact_time / stop_time over the whole input range.
    # Not bit for bit: the kernel calls libm's tan and acos, numpy's array functions its own
    # SIMD versions, which differ by an ulp on some inputs; acos near 1 magnifies an ulp of its
    # argument (d acos / dx ~ 1/sqrt(2 (1 - x))), hence 1e-12 relative rather than 1e-15.
    from skidmc.physics import mechanics

    rng = np.random.default_rng(3)
    n = 2000
    mu = np.where(rng.random(n) < 0.1, 0.0, rng.uniform(0.0, 4.9, n))
    angle = rng.uniform(0.01, 89.99, n)
    tilt = np.where(rng.random(n) < 0.5, angle, 0.0)
    sigma, mass, diam = (np.exp(rng.uniform(math.log(a), math.log(b), n))
                         for a, b in ((1e6, 5e8), (0.1, 100.0), (0.02, 0.5)))
    kinds = set()
    for args in zip(mu, angle, tilt, sigma, mass, diam):
        args = [float(a) for a in args]
        t_c = float(mechanics.contact_time(*args[3:]))
        t_s = float(mechanics.stop_time(*args))
        expected = (t_s, "stops_sliding") if t_s < t_c else (t_c, "rebound")
        t_exit, kind = mechanics.exit_time(*args)
        assert kind == expected[1]
        assert t_exit == pytest.approx(expected[0], rel=1e-12, abs=0.0)
        kinds.add(expected[1])
    assert kinds == {"rebound", "stops_sliding"}


def test_batched_inputs_are_validated_like_scenes():
    # The batched entry takes raw columns: a value a Scene would refuse (here a negative target
    # conductivity, which used to come back censored "above") raises, naming key, value and row.
    from skidmc.errors import SceneError
    from skidmc.solver.fast import fast_critical_heights, scene_columns

    cols = scene_columns([get_preset("paper-quartz")] * 3)
    cols["target_conductivity"] = np.array([1.7, -1.0, 2.0])
    with pytest.raises(SceneError) as err:
        fast_critical_heights(**cols)
    assert err.value.key == "target.conductivity" and "row 1" in str(err.value)
    cols = scene_columns([get_preset("paper-quartz")])
    cols["initial_temperature"] = np.array([600.0])  # above the melting point
    with pytest.raises(SceneError):
        fast_critical_heights(**cols)


def test_fast_height_within_its_error_of_h_max_is_censored_above():
    # phi = 1 deg: the fast tier found 9,647 m, 3.5 % below h_max = 10 km, before its
    # stops-sliding factor (1.039), where the full tier finds no event up to h_max; within its
    # stated error it cannot tell (and with the factor it finds no event either).
    from skidmc.scene import make_scene
    from skidmc.solver import critical_height

    scene = make_scene(preset="paper-quartz", angle=1.0)
    res = critical_height(scene, tier="fast", h_max=1e4)
    assert res.censored == "above" and res.critical_height == 1e4
    assert critical_height(scene, rtol=1e-2, h_max=1e4).censored == "above"
    batch = fast_critical_heights(h_max=1e4, **scene_columns([scene]))
    assert batch["censored"][0] == CENSOR_ABOVE and batch["critical_height"][0] == 1e4


def test_fast_stated_error_by_region_and_strict_refusal():
    from skidmc.errors import SceneError
    from skidmc.physics.fast import ERROR_ESTIMATE, ERROR_SELF_HEATING, ERROR_STOPS_SLIDING
    from skidmc.scene import get_preset, make_scene
    from skidmc.solver.fast import fast_critical_height

    scenes = {"rebound": get_preset("paper-quartz"), "stops": get_preset("paper-gold"),
              "self": make_scene(preset="paper-quartz",
                                 **{"kinetics.activation_temperature": 15000.0})}
    expected = {"rebound": ERROR_ESTIMATE, "stops": ERROR_STOPS_SLIDING,
                "self": ERROR_SELF_HEATING}
    batch = fast_critical_heights(**scene_columns(list(scenes.values())))
    for (name, scene), batch_error in zip(scenes.items(), batch["error_estimate"]):
        assert fast_critical_height(scene).error_estimate == expected[name] == batch_error
    assert fast_critical_height(scenes["rebound"], strict=True).censored is None
    for name in ("stops", "self"):
        with pytest.raises(SceneError):
            fast_critical_height(scenes[name], strict=True)


def test_stops_sliding_factor_scales_only_where_sliding_stops():
    from skidmc.physics.fast import STOPS_SLIDING_FACTOR
    from skidmc.scene import get_preset
    from skidmc.solver.fast import fast_critical_height

    # The fitted factor multiplies the reduced model's height where sliding stops (paper-gold)
    # and nowhere else (paper-quartz rebounds); the root is found to 1e-6 in ln H either way.
    for name, factor in (("paper-gold", STOPS_SLIDING_FACTOR), ("paper-quartz", 1.0)):
        scene = get_preset(name)
        raw = fast_critical_height(scene, stops_factor=1.0).critical_height
        assert fast_critical_height(scene).critical_height == pytest.approx(factor * raw,
                                                                            rel=1e-5)
    # A bound between the unscaled and the scaled height censors the scaled one.
    gold = get_preset("paper-gold")
    raw = fast_critical_height(gold, stops_factor=1.0).critical_height
    batch = fast_critical_heights(h_max=1.01 * raw, **scene_columns([gold]))
    assert batch["censored"][0] == CENSOR_ABOVE and batch["critical_height"][0] == 1.01 * raw
