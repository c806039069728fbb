"""Stability at the extremes: every input at the edges of its range, one at a time and in corners.

The matrix spans the issue's ranges: targets from fused quartz to copper (diffusivity ~1.2 cm^2/s),
mu 1e-3..0.8, phi 1..89 deg, H 1 cm..1 km (the search bounds), E/R 15,000..40,000 K, the prefactor
over 10 decades (5e14..5e24 1/s), flow stress 1..500 MPa, billet mass 0.1..100 kg, T0 200..450 K.
Each case must return a finite height or a censoring that physics confirms - never NaN, an exception
or a hang - and must carry a validity flag exactly where it leaves the model's validity
(docs/model.md, "Validity flags").

Trends are checked only where a comparison principle guarantees them: the reactive heat equation
with an increasing Arrhenius source (and the monotone enthalpy of melting) is order-preserving, so
a pointwise larger flux history q(t) on a window at least as long, a larger rate k(T) at every
temperature, or a hotter start can only make the event earlier, i.e. the critical height lower.
The flow stress is deliberately absent: a larger sigma raises the flux but shortens the contact,
so no ordering is guaranteed.

Each solve runs under a wall-clock watchdog (:data:`TIME_BOUND`, ~100x what it needs) that fails the
test instead of hanging; nothing asserts on speed. The default run takes well under a minute; the
``slow`` tests (``python -m pytest -m slow tests/test_extremes.py``) run the property tests with
~10x more examples.
"""

from __future__ import annotations

import contextlib
import math
import signal
import threading

import pytest
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st

from skidmc.physics import mechanics
from skidmc.scene import make_scene
from skidmc.solver import critical_height, simulate
from skidmc.solver.model import build_model
from skidmc.solver.results import RTOL_SLACK, RTOL_UNMET

RTOL = 1e-2
H_MIN = 0.01     # [m] 1 cm
H_MAX = 1000.0   # [m] 1 km
#: Wall-clock bound of one critical-height search [s]. Observed: < 1 s for every case (numba
#: compilation included); the bound only turns a hang into a failure.
TIME_BOUND = 60.0
#: Hang proxy independent of the clock: a bracketing Brent search on [1 cm, 1 km] with rtol 1e-2
#: needs ~4-20 simulations; the bisection fallback ~30.
MAX_EVALUATIONS = 80

# Targets (SI). Fused quartz (handbook low end) to copper, alpha = 401 / (8960 * 385) = 1.16 cm^2/s.
FUSED_QUARTZ = {"target.conductivity": 1.3, "target.density": 2200.0,
                "target.heat_capacity": 740.0}
ALUMINA = {"target.conductivity": 30.0, "target.density": 3900.0, "target.heat_capacity": 880.0}
GOLD = {"target.conductivity": 317.0, "target.density": 19300.0, "target.heat_capacity": 129.0}
COPPER = {"target.conductivity": 401.0, "target.density": 8960.0, "target.heat_capacity": 385.0}

#: Every validity flag skidmc.model can set (scene flags, then per-height flags).
SCENE_FLAGS = {"stops_sliding", "stops_early", "self_heating", "hot_ignition", "no_friction"}
HEIGHT_FLAGS = {"crushed", "long_slide"}


class Hang(AssertionError):
    """A solve exceeded TIME_BOUND."""


@contextlib.contextmanager
def watchdog(seconds):
    """Raise :class:`Hang` in the main thread after ``seconds`` (no-op where SIGALRM is missing)."""
    if (not hasattr(signal, "setitimer")
            or threading.current_thread() is not threading.main_thread()):
        yield
        return

    def _raise(signum, frame):
        raise Hang(f"critical-height search exceeded {seconds:g} s (hang?)")

    previous = signal.signal(signal.SIGALRM, _raise)
    signal.setitimer(signal.ITIMER_REAL, seconds)
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0.0)
        signal.signal(signal.SIGALRM, previous)


def solve(scene):
    """critical_height on [1 cm, 1 km] at rtol 1e-2, bounded in time; checks the invariants."""
    with watchdog(TIME_BOUND):
        res = critical_height(scene, rtol=RTOL, h_min=H_MIN, h_max=H_MAX)
    h = res.critical_height
    assert isinstance(h, float) and math.isfinite(h), f"non-finite height {h!r}"
    assert res.censored in (None, "above", "below")
    if res.censored is None:
        assert H_MIN < h < H_MAX
    else:
        assert h == {"above": H_MAX, "below": H_MIN}[res.censored]
    assert math.isfinite(res.error_estimate) and 0.0 < res.error_estimate < 0.1
    assert res.evaluations <= MAX_EVALUATIONS
    _check_unmet(res)
    assert set(res.flags) - {RTOL_UNMET} <= SCENE_FLAGS | HEIGHT_FLAGS, res.flags
    return res


def _check_unmet(res):
    """rtol_unmet (issue 44) is set exactly where an uncensored result's estimate stayed above
    rtol. The slow matrix finds such results at rtol 1e-2: self-heating scenes (E/R 15,000-
    21,700 K, T0 = 404 K) whose measured melting-width bias alone is 1.5-1.9e-2, estimates
    2.2-2.5e-2 after two narrowings and a refinement (the flag was missing from this check)."""
    unmet = res.censored is None and res.error_estimate > RTOL * (1.0 + RTOL_SLACK)
    assert (RTOL_UNMET in res.flags) == unmet, (res.flags, res.error_estimate)


def all_flags(scene, res):
    """The result's flags, checked to hold the height-dependent ones at the reported height.

    ``SkidModel.height_flags`` checks the indentation and sliding distance at the height the
    result reports (for "above": h_max, the height the claim "no event up to h_max" reaches);
    the solver must have merged them into the result.
    """
    model = build_model(scene, level=res.level)
    flags = set(res.flags)
    assert set(model.height_flags(res.critical_height)) <= flags
    _check_unmet(res)
    flags.discard(RTOL_UNMET)
    assert flags <= SCENE_FLAGS | HEIGHT_FLAGS
    return flags


# --- the matrix -------------------------------------------------------------------------------
# (id, preset, overrides, allowed outcomes, expected flags). Outcomes: "finite", "above", "below".
# Flags are compared exactly: a flag must appear where the model's validity is left and nowhere
# else.
_T_REF = 1000.0  # [K] reference temperature of the compensated kinetics below


def _rate_at_ref(activation_temperature, t_ref=_T_REF):
    """Prefactor with the report's rate k(t_ref) (5e19 exp(-26300 / t_ref)) at this E/R [1/s]."""
    return 5.0e19 * math.exp(-26300.0 / t_ref + activation_temperature / t_ref)


ONE_AT_A_TIME = [
    # preset reference points
    ("quartz", "paper-quartz", {}, {"finite"}, set()),
    ("gold", "paper-gold", {}, {"finite"}, {"stops_sliding"}),
    # targets, quartz to copper (diffusivity 8e-3 to 1.16 cm^2/s)
    ("fused-quartz", "paper-quartz", FUSED_QUARTZ, {"finite"}, set()),
    ("alumina", "paper-quartz", ALUMINA, {"finite"}, set()),
    ("gold-target", "paper-quartz", GOLD, {"finite"}, set()),
    ("copper", "paper-quartz", COPPER, {"finite"}, set()),
    # friction
    ("mu=1e-3", "paper-quartz", {"mu": 1e-3}, {"above"}, set()),
    ("mu=0.8", "paper-quartz", {"mu": 0.8}, {"finite"}, {"stops_sliding"}),
    ("gold-mu=1e-3", "paper-gold", {"mu": 1e-3}, {"above"}, set()),
    ("gold-mu=0.8", "paper-gold", {"mu": 0.8}, {"finite"}, {"stops_sliding"}),
    ("alumina-mu=1e-3", "paper-alumina-smooth", {"mu": 1e-3}, {"above"}, set()),
    ("alumina-mu=0.8", "paper-alumina-smooth", {"mu": 0.8}, {"finite"}, {"stops_sliding"}),
    # angle: phi = 1 deg is a nearly normal impact (sliding stops at 0.2 t_c, and a 1 km drop
    # crushes the billet); phi = 89 deg a grazing one
    ("phi=1", "paper-quartz", {"angle": 1.0}, {"above"},
     {"stops_sliding", "stops_early", "crushed"}),
    ("phi=89", "paper-quartz", {"angle": 89.0}, {"finite"}, set()),
    ("gold-phi=1", "paper-gold", {"angle": 1.0}, {"above"},
     {"stops_sliding", "stops_early", "crushed"}),
    ("gold-phi=89", "paper-gold", {"angle": 89.0}, {"finite"}, set()),
    # kinetics. E/R = 15,000 K with the report's prefactor: k(T0) = 4e-3 1/s, the billet runs away
    # by itself in 0.2 s; its "height" (~1.2 cm) is not a friction result.
    ("Ta=15000", "paper-quartz", {"kinetics.activation_temperature": 15000.0},
     {"finite", "below"}, {"self_heating"}),
    ("Ta=40000", "paper-quartz", {"kinetics.activation_temperature": 40000.0}, {"finite"}, set()),
    ("Ta=15000-compensated", "paper-quartz",
     {"kinetics.activation_temperature": 15000.0, "kinetics.prefactor": _rate_at_ref(15000.0)},
     {"finite"}, set()),
    ("Ta=40000-compensated", "paper-quartz",
     {"kinetics.activation_temperature": 40000.0, "kinetics.prefactor": _rate_at_ref(40000.0)},
     {"finite"}, set()),
    ("Z=5e14", "paper-quartz", {"kinetics.prefactor": 5e14}, {"finite"}, set()),
    ("Z=5e24", "paper-quartz", {"kinetics.prefactor": 5e24}, {"finite"}, set()),
    # billet: with sigma = 1 MPa, H_c ~ 770 m, where the billet is flattened (X_max = 0.8 D)
    # and slides over more than its contact diameter
    ("sigma=1MPa", "paper-quartz", {"flow_stress": 1e6}, {"finite"}, {"crushed", "long_slide"}),
    ("sigma=500MPa", "paper-quartz", {"flow_stress": 5e8}, {"finite"}, set()),
    ("W=0.1kg", "paper-quartz", {"billet_mass": 0.1}, {"finite"}, set()),
    ("W=100kg", "paper-quartz", {"billet_mass": 100.0}, {"finite"}, set()),
    # initial temperature. At 450 K the report's kinetics run away adiabatically in ~8 min.
    ("T0=200", "paper-quartz", {"initial_temperature": 200.0}, {"finite"}, set()),
    ("T0=450", "paper-quartz", {"initial_temperature": 450.0}, {"finite"}, {"self_heating"}),
    ("gold-T0=200", "paper-gold", {"initial_temperature": 200.0}, {"finite", "above"},
     {"stops_sliding"}),
]

CORNERS = [
    # coldest: copper, nearly no friction, cold start, slow kinetics that need > 1000 K
    ("coldest", "paper-quartz",
     {**COPPER, "mu": 1e-3, "initial_temperature": 200.0,
      "kinetics.activation_temperature": 40000.0, "kinetics.prefactor": 5e14},
     {"above"}, {"hot_ignition"}),
    # hottest with fast kinetics: the HE runs away at rest within ~1e-13 s
    ("hottest-unstable", "paper-quartz",
     {"mu": 0.8, "angle": 89.0, "flow_stress": 5e8, "billet_mass": 100.0,
      "initial_temperature": 450.0, "kinetics.activation_temperature": 15000.0,
      "kinetics.prefactor": 5e24},
     {"below"}, {"self_heating"}),
    # a valid scene that goes at 1 cm: grazing impact, high friction, warm billet
    ("goes-at-1cm", "paper-quartz", {"mu": 0.8, "angle": 89.0, "initial_temperature": 400.0},
     {"below"}, set()),
    # shortest contact (t_c = 27 us) on copper with little friction
    ("short-contact-copper", "paper-quartz",
     {**COPPER, "mu": 1e-3, "billet_mass": 0.1, "flow_stress": 5e8}, {"above"}, set()),
    # longest contact (t_c = 17 ms): the critical height crushes the billet
    ("long-contact", "paper-quartz", {"billet_mass": 100.0, "flow_stress": 1e6},
     {"finite"}, {"crushed", "long_slide"}),
    ("long-contact-copper", "paper-quartz", {**COPPER, "billet_mass": 100.0, "flow_stress": 1e6},
     {"above"}, {"crushed", "long_slide"}),
    # sliding stops at 0.08 t_c; mu = 0.8 still heats enough below 1 km, where the billet is crushed
    ("stops-at-once", "paper-quartz", {"mu": 0.8, "angle": 1.0}, {"finite"},
     {"stops_sliding", "stops_early", "crushed"}),
    ("stops-at-once-gold", "paper-gold", {"mu": 0.8, "angle": 1.0}, {"finite", "above"},
     {"stops_sliding", "stops_early", "crushed"}),
    # slow kinetics, short hard contact: ignition needs > 1400 K
    ("hot-ignition", "paper-quartz",
     {"kinetics.activation_temperature": 40000.0, "kinetics.prefactor": 5e14,
      "billet_mass": 0.1, "flow_stress": 5e8}, {"finite"}, {"hot_ignition"}),
    # gold tower, grazing, warm
    ("gold-grazing-warm", "paper-gold", {"angle": 89.0, "mu": 0.8, "initial_temperature": 400.0},
     {"finite"}, set()),
    # no friction: no simulation, above
    ("no-friction", "paper-quartz", {"mu": 0.0}, {"above"}, {"no_friction"}),
]


def _outcome(res):
    return "finite" if res.censored is None else res.censored


@pytest.mark.parametrize("case_id, preset, overrides, outcomes, flags",
                         ONE_AT_A_TIME + CORNERS, ids=[c[0] for c in ONE_AT_A_TIME + CORNERS])
def test_matrix_case(case_id, preset, overrides, outcomes, flags):
    scene = make_scene(preset=preset, **overrides)
    res = solve(scene)
    assert _outcome(res) in outcomes, (case_id, res.critical_height, res.censored)
    assert all_flags(scene, res) == flags, (case_id, res.flags)


def test_censoring_agrees_with_a_direct_simulation():
    # "above" means no event at h_max, "below" an event at h_min: checked on the model itself.

    for preset, overrides, bound in [
        ("paper-quartz", {**COPPER, "mu": 1e-3}, H_MAX),
        ("paper-quartz", {"mu": 0.8, "angle": 89.0, "initial_temperature": 400.0}, H_MIN),
    ]:
        scene = make_scene(preset=preset, **overrides)
        res = solve(scene)
        sim = simulate(build_model(scene, level=res.level), bound)
        assert sim.event == (res.censored == "below")
        assert res.censored == ("above" if bound == H_MAX else "below")


def test_self_heating_billet_goes_at_once():
    # With E/R = 15,000 K and Z = 5e24 1/s the HE at 450 K runs away in ~1e-13 s: it goes at any
    # height, and says why.
    scene = make_scene(preset="paper-quartz", **{"initial_temperature": 450.0,
                                                  "kinetics.activation_temperature": 15000.0,
                                                  "kinetics.prefactor": 5e24})
    res = solve(scene)
    assert res.censored == "below"
    assert "self_heating" in res.flags
    assert build_model(scene).rest_time < res.exit_time


def test_self_heating_just_after_the_exit_is_censored_above():
    # Found by the slow property test: at 405 K with E/R = 15,000 K and Z = 2.5e16 1/s the bulk
    # runs away ~2 % after the exit whatever the height (nearly normal impact, mu = 0.007: little
    # frictional heat), so the margin is ~0.02 and flat in H. The bracketing steps (1.2 m + a few
    # percent) used to stall short of h_max; they now double, and the search reaches the bound.
    scene = make_scene(preset="paper-quartz", **{
        "mu": 0.006737946999085467, "angle": 1.0, "flow_stress": 24154952.7535753,
        "billet_mass": 3.955076722920577, "initial_temperature": 405.0,
        "kinetics.activation_temperature": 15000.0, "kinetics.prefactor": 2.4809424597909428e16,
        "target.conductivity": 2.718281828459045})
    res = solve(scene)
    assert res.censored == "above"
    assert "self_heating" in res.flags
    sim = simulate(build_model(scene, level=res.level), H_MAX)
    assert not sim.event and 0.0 < sim.margin < 0.05   # the premise: flat, just no-go


def test_flags_fit_storage_width():
    # storage keeps the comma-separated flags in a fixed width (ensemble.storage.OUTPUTS); every
    # combination that can occur together must fit (self_heating and hot_ignition exclude each
    # other in practice: one needs a runaway at T0 within an hour, the other a runaway within
    # t_exit only above 1000 K; no_friction simulates nothing). Of the target's regime flags at
    # most two occur together: yielding targets are untabled homogeneous floors, tabled targets
    # (temperature_target / constant_target) are rigid ceramics and never layered, layered stacks
    # are rigid metals. rtol_unmet and implausible_input can join any of them.
    from skidmc.ensemble.storage import OUTPUTS

    width = next(v.width for v in OUTPUTS if v.name == "flags")
    model = ["stops_sliding", "stops_early", "hot_ignition", "crushed", "long_slide"]
    ensemble = ["rtol_unmet", "implausible_input"]
    for regime in (["yielding_target"], ["temperature_target"], ["layered_target"],
                   ["top_layer_only"], ["constant_target"]):
        for first in ("hot_ignition", "self_heating"):
            flags = [first if f == "hot_ignition" else f for f in model] + regime + ensemble
            assert len(",".join(flags)) <= width, flags


# --- monotone trends --------------------------------------------------------------------------

def _interval(res):
    """[lo, hi] holding the true critical height, given the result's numerical error."""
    if res.censored == "above":
        return H_MAX * (1.0 - res.error_estimate), math.inf
    if res.censored == "below":
        return 0.0, H_MIN * (1.0 + res.error_estimate)
    e = res.error_estimate
    return res.critical_height * (1.0 - e), res.critical_height * (1.0 + e)


def assert_not_higher(low, high, what):
    """H(low) <= H(high) within the numerical error: ``low``'s interval may not lie above."""
    lo_low, _ = _interval(low)
    _, hi_high = _interval(high)
    assert lo_low <= hi_high, (
        f"{what}: H = {low.critical_height:.6g} ({low.censored}) should not exceed "
        f"{high.critical_height:.6g} ({high.censored})")


_PRESETS = ["paper-quartz", "paper-alumina-smooth", "paper-gold", "paper2-quartz"]


@st.composite
def base_scenes(draw, pendulum=False):
    """A scene drawn from the issue's box (all inputs at once; the kinetic box includes scenes
    that self-heat at rest)."""
    preset = "paper-quartz" if pendulum else draw(st.sampled_from(_PRESETS))
    log = st.floats
    overrides = {
        "mu": math.exp(draw(log(math.log(1e-3), math.log(0.8)))),
        "angle": draw(log(1.0, 89.0)),
        "flow_stress": math.exp(draw(log(math.log(1e6), math.log(5e8)))),
        "billet_mass": math.exp(draw(log(math.log(0.1), math.log(100.0)))),
        "initial_temperature": draw(log(200.0, 450.0)),
        "kinetics.activation_temperature": draw(log(15000.0, 40000.0)),
        "kinetics.prefactor": math.exp(draw(log(math.log(5e14), math.log(5e24)))),
        "target.conductivity": math.exp(draw(log(math.log(1.3), math.log(401.0)))),
    }
    return preset, overrides


def _property_settings(examples):
    return settings(max_examples=examples, deadline=None, derandomize=True,
                    suppress_health_check=[HealthCheck.too_slow], database=None)


def _check_ordering(preset, overrides, key, low_value, high_value, falls):
    """Solve at two values of ``key``; H must fall (``falls``) or rise from low to high value."""
    lo = solve(make_scene(preset=preset, **{**overrides, key: low_value}))
    hi = solve(make_scene(preset=preset, **{**overrides, key: high_value}))
    what = f"{preset} {overrides} {key}: {low_value:.6g} -> {high_value:.6g}"
    if falls:
        assert_not_higher(hi, lo, what)
    else:
        assert_not_higher(lo, hi, what)


def _trend_initial_temperature(data):
    # A hotter start is a pointwise larger initial state: the event can only come earlier.
    preset, ov = data.draw(base_scenes())
    a, b = sorted(data.draw(st.floats(200.0, 450.0)) for _ in range(2))
    assume(b - a > 1.0)
    _check_ordering(preset, ov, "initial_temperature", a, b, falls=True)


def _trend_prefactor(data):
    # A larger Z is a larger rate at every temperature.
    preset, ov = data.draw(base_scenes())
    a, b = sorted(math.exp(data.draw(st.floats(math.log(5e14), math.log(5e24)))) for _ in range(2))
    assume(b > 1.01 * a)
    _check_ordering(preset, ov, "kinetics.prefactor", a, b, falls=True)


def _trend_activation_temperature(data):
    # At fixed Z, a larger E/R is a smaller rate at every temperature: H rises.
    preset, ov = data.draw(base_scenes())
    a, b = sorted(data.draw(st.floats(15000.0, 40000.0)) for _ in range(2))
    assume(b - a > 10.0)
    _check_ordering(preset, ov, "kinetics.activation_temperature", a, b, falls=False)


def _trend_mass(data):
    # A heavier billet has a smaller omega: the flux q0 (s - c (1 - cos omega t)) is pointwise
    # larger and the heating lasts longer (t_c and the stop time scale as 1/omega).
    preset, ov = data.draw(base_scenes())
    a, b = sorted(math.exp(data.draw(st.floats(math.log(0.1), math.log(100.0)))) for _ in range(2))
    assume(b > 1.01 * a)
    _check_ordering(preset, ov, "billet_mass", a, b, falls=True)


def _trend_angle(data):
    # Pendulum (psi = 0, C independent of phi): q ~ sin(phi) - C cos(phi) (1 - cos omega t) rises
    # with phi at every t and sliding stops later, so H falls with phi.
    preset, ov = data.draw(base_scenes(pendulum=True))
    a, b = sorted(data.draw(st.floats(1.0, 89.0)) for _ in range(2))
    assume(b - a > 0.1)
    _check_ordering(preset, ov, "angle", a, b, falls=True)


def _trend_mu(data):
    # q = mu sigma V0 (s - C(mu) cos(phi) (1 - cos omega t)) with C = mu kappa + beta rises with mu
    # at every t <= t_c only while (2 C(mu) - beta) cos(phi) <= sin(phi) (which also means it
    # slides until rebound). Beyond, a larger mu brakes the sliding sooner and no order is
    # guaranteed, so the draw is restricted to that regime.
    preset, ov = data.draw(base_scenes())
    scene = make_scene(preset=preset, **ov)
    beta = float(mechanics.sliding_deceleration_coefficient(0.0, scene.tilt))
    kappa = float(mechanics.sliding_deceleration_coefficient(1.0, scene.tilt)) - beta
    phi = math.radians(scene.angle)
    mu_max = min(0.8, (math.tan(phi) - beta) / (2.0 * kappa))
    assume(mu_max > 1.01e-3)
    a, b = sorted(math.exp(data.draw(st.floats(math.log(1e-3), math.log(mu_max))))
                  for _ in range(2))
    assume(b > 1.01 * a)
    _check_ordering(preset, ov, "mu", a, b, falls=True)


def _trend_target_conductivity(data):
    # A more conductive target (same rho c: larger effusivity) drains more heat from the HE.
    preset, ov = data.draw(base_scenes())
    a, b = sorted(math.exp(data.draw(st.floats(math.log(1.3), math.log(401.0)))) for _ in range(2))
    assume(b > 1.01 * a)
    _check_ordering(preset, ov, "target.conductivity", a, b, falls=False)


TRENDS = {
    "initial_temperature": _trend_initial_temperature,
    "prefactor": _trend_prefactor,
    "activation_temperature": _trend_activation_temperature,
    "billet_mass": _trend_mass,
    "angle": _trend_angle,
    "mu": _trend_mu,
    "target_conductivity": _trend_target_conductivity,
}


@pytest.mark.parametrize("trend", list(TRENDS))
@_property_settings(12)
@given(data=st.data())
def test_trend_property(trend, data):
    TRENDS[trend](data)


@pytest.mark.slow
@pytest.mark.parametrize("trend", list(TRENDS))
@_property_settings(150)
@given(data=st.data())
def test_trend_property_many(trend, data):
    TRENDS[trend](data)


@pytest.mark.parametrize("key, values, falls", [
    ("mu", [1e-3, 3e-3, 1e-2, 3e-2, 0.1, 0.2, 0.3], True),  # paper-quartz: monotone up to 0.35
    ("angle", [1.0, 2.0, 5.0, 10.0, 20.0, 45.0, 60.0, 75.0, 89.0], True),
    ("initial_temperature", [200.0, 250.0, 300.0, 350.0, 400.0, 450.0], True),
    ("kinetics.prefactor", [5e14, 5e16, 5e18, 5e20, 5e22, 5e24], True),
    ("kinetics.activation_temperature", [15000.0, 20000.0, 26300.0, 33000.0, 40000.0], False),
    ("billet_mass", [0.1, 0.5, 2.0, 8.66, 30.0, 100.0], True),
    ("target.conductivity", [1.3, 5.0, 20.0, 80.0, 200.0, 401.0], False),
])
def test_sweep_from_quartz_is_monotone(key, values, falls):
    results = [solve(make_scene(preset="paper-quartz", **{key: v})) for v in values]
    for (va, ra), (vb, rb) in zip(zip(values, results), zip(values[1:], results[1:])):
        what = f"paper-quartz {key}: {va:g} -> {vb:g}"
        if falls:
            assert_not_higher(rb, ra, what)
        else:
            assert_not_higher(ra, rb, what)


def test_compensated_kinetics_rise_with_activation_temperature():
    # At a fixed rate at T_ref = 1000 K, a larger E/R is a smaller rate at every T < T_ref; the
    # event is declared below the runaway temperature, which stays below T_ref here, so H rises.
    values = [15000.0, 20000.0, 26300.0, 33000.0, 40000.0]
    results = []
    for ta in values:
        scene = make_scene(preset="paper-quartz", **{"kinetics.activation_temperature": ta,
                                                      "kinetics.prefactor": _rate_at_ref(ta)})
        assert build_model(scene).runaway_temperature < _T_REF  # the premise
        results.append(solve(scene))
    for ra, rb in zip(results, results[1:]):
        assert_not_higher(ra, rb, "compensated E/R")


# --- never NaN, never an exception, never a hang, over the whole box --------------------------

@st.composite
def box_scenes(draw):
    preset, overrides = draw(base_scenes())
    # a real target, or the drawn conductivity on the preset's rho c
    overrides.update(draw(st.sampled_from([{}, FUSED_QUARTZ, ALUMINA, GOLD, COPPER])))
    return preset, overrides


def _box_case(case):
    preset, overrides = case
    scene = make_scene(preset=preset, **overrides)
    res = solve(scene)
    all_flags(scene, res)


@_property_settings(40)
@given(case=box_scenes())
def test_whole_box_returns_a_height_or_a_censoring(case):
    _box_case(case)


@pytest.mark.slow
@_property_settings(600)
@given(case=box_scenes())
def test_whole_box_many(case):
    _box_case(case)


def test_an_extrapolation_beyond_h_max_is_censored_above():
    # Found by test_trend_property_many[prefactor]: both roots of the Richardson pair lie just
    # below h_max = 1 km and their extrapolation above it (1002 m was returned uncensored).
    scene = make_scene(preset="paper-alumina-smooth", **{
        "mu": 0.04515491028971929, "angle": 14.875, "flow_stress": 2884897.7057018704,
        "billet_mass": 0.30025444914408245, "initial_temperature": 305.625,
        "kinetics.activation_temperature": 15000.0, "kinetics.prefactor": math.exp(47.03125),
        "target.conductivity": 1.3042458747676378})
    assert solve(scene).censored == "above"   # solve() checks H_MIN < H < H_MAX if uncensored
    from skidmc.solver.cuda import solve_scenes

    device = solve_scenes([scene], backend="cpu", rtol=RTOL, h_min=H_MIN, h_max=H_MAX)[0]
    assert device.censored == "above" or H_MIN < device.critical_height < H_MAX


# --- a run whose first HE cell's melting width folds its enthalpy: frozen, not stalled --------

# Three scenes of scripts/fast_tier_error.py's sets (broad draws, seeds 2 and 1) at the levels
# and heights where a run with the exact target and the melting spread stalled before the kernel
# froze the first HE cell's width (thermal.FREEZE_WIDTH_AFTER): 24,000-135,000 steps, half of
# them rejected by Newton failures, and a SolverError in a tight fixed-model search.
FOLDING = {
    "fading": ({"mu": 0.17465999323767326, "flow_stress": 430751803.4717943,
                "billet_mass": 3.289741757472737, "angle": 67.17789296902461,
                "tilt": 67.17789296902461, "initial_temperature": 299.4996164849088,
                "kinetics.prefactor": 4.269904805346351e+29,
                "kinetics.activation_temperature": 34242.37707697529,
                "kinetics.heat_of_reaction": 7849135.935151171,
                "target.density": 7969.821394174166, "target.heat_capacity": 585.2571746439196,
                "target.conductivity": 38.42377242446599}, 0.5, 2.03652),
    "stops_sliding": ({"mu": 0.05337876364053461, "flow_stress": 388839194.96550834,
                       "billet_mass": 6.228194420916689, "angle": 38.26365779454411,
                       "tilt": 38.26365779454411, "initial_temperature": 261.37815169597985,
                       "kinetics.prefactor": 98576321309531.12,
                       "kinetics.activation_temperature": 17413.356077077005,
                       "kinetics.heat_of_reaction": 7625217.912556841,
                       "target.density": 7049.135669935857,
                       "target.heat_capacity": 382.48064571753827,
                       "target.conductivity": 274.5127376196037}, 0.5, 256.0),
    "stops_sliding_level1": ({"mu": 0.4547584148539359, "flow_stress": 40427120.09806611,
                              "billet_mass": 15.997277584387321, "angle": 40.36501355219284,
                              "initial_temperature": 270.43604623102703,
                              "kinetics.prefactor": 256731360754647.3,
                              "kinetics.activation_temperature": 16677.871268450366,
                              "kinetics.heat_of_reaction": 9030038.103546679,
                              "target.density": 5283.035621015802,
                              "target.heat_capacity": 509.22087360617377,
                              "target.conductivity": 20.037728935212044}, 1.0, 6.83489),
}


@pytest.mark.parametrize("label", sorted(FOLDING))
def test_a_folding_first_cell_width_is_frozen_not_stalled(label):
    from skidmc.physics.thermal import simulate_kernel
    from skidmc.solver.plan import modelled_error
    from skidmc.solver.simulate import kernel_arguments

    overrides, level, height = FOLDING[label]
    scene = make_scene(preset="paper-quartz", **overrides)
    model = build_model(scene, level=level, melt_width=1.0, melt_spread=1.0, target="exact")
    with watchdog(TIME_BOUND):
        info = simulate_kernel(*kernel_arguments(model, height))[0]
    assert info["frozen_width"]
    # Now 269, 363 and 340 attempts (the presets take 100-300 at these levels).
    assert info["steps"] + info["rejected"] < 1000
    with watchdog(TIME_BOUND):
        found = critical_height(scene, rtol=1e-5, model=model)
        reference = critical_height(scene, rtol=1e-5, model=build_model(
            scene, level=2.5, melt_width=1.0, melt_spread=1.0, target="mesh"))
    assert found.censored is None and reference.censored is None
    # The root is still its level's: within that level's calibrated error (4.5e-3 at level 0.5,
    # 2.3e-3 at 1) of a finer level on the other target model (measured 9e-5, 1.2e-3, 2.8e-4).
    assert (abs(math.log(found.critical_height / reference.critical_height))
            <= modelled_error(level))


def test_an_ordinary_run_never_freezes_the_width():
    from skidmc.physics.thermal import simulate_kernel
    from skidmc.solver.simulate import kernel_arguments

    scene = make_scene(preset="paper-quartz")
    model = build_model(scene, level=0.5, melt_width=1.0, melt_spread=1.0, target="exact")
    for height in (0.5, 1.0, 2.0):
        assert not simulate_kernel(*kernel_arguments(model, height))[0]["frozen_width"]
