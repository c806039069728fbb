"""Closed forms of the impact mechanics (report Eqs. 1-10)."""

import math

import numpy as np
import pytest

from skidmc.physics import mechanics as mech
from skidmc.scene import get_preset

# First-series billet in SI (independent of the units layer: factors written out).
PSI = 6894.757293168361  # [Pa]
LB = 0.45359237          # [kg]
INCH = 0.0254            # [m]
SIGMA, W, D = 28000 * PSI, 19.1 * LB, 10 * INCH


def test_contact_time_closed_form():
    # t_c = (pi/2) sqrt(W / (pi sigma D)) (II.B): 0.3725 ms for the first series.
    expected = 0.5 * math.pi * math.sqrt(W / (math.pi * SIGMA * D))
    assert mech.contact_time(SIGMA, W, D) == pytest.approx(expected, rel=1e-14)
    assert 3.6e-4 < expected < 3.8e-4


def test_contact_time_is_where_normal_velocity_vanishes():
    tc = mech.contact_time(SIGMA, W, D)
    omega = mech.angular_frequency(SIGMA, W, D)
    # X(t) is maximal at t_c: its derivative V_n0 cos(omega t) is zero there.
    assert math.cos(omega * tc) == pytest.approx(0.0, abs=1e-15)


@pytest.mark.parametrize("angle", [10.0, 45.0, 60.0])
def test_contact_diameter_quarter_power_law(angle):
    # Eq. (6): d_c = K H^(1/4); doubling H 4 times multiplies d_c by 2.
    h = np.array([0.1, 0.2, 0.4, 0.8, 1.6])
    dc = mech.max_contact_diameter(h, angle, SIGMA, W, D)
    slope = np.polyfit(np.log(h), np.log(dc), 1)[0]
    assert slope == pytest.approx(0.25, abs=1e-12)
    assert dc[-1] / dc[0] == pytest.approx(2.0, rel=1e-12)


def test_contact_diameter_matches_max_area():
    # A_c = pi d_c^2 / 4 = pi D X_max, X_max = V_n0 / omega (II.B).
    h, angle = 0.5, 60.0
    dc = mech.max_contact_diameter(h, angle, SIGMA, W, D)
    tc = mech.contact_time(SIGMA, W, D)
    area = mech.contact_area(tc, h, angle, SIGMA, W, D)
    assert math.pi * dc**2 / 4 == pytest.approx(area, rel=1e-12)


def test_flow_stress_round_trip_eq5():
    dc = mech.max_contact_diameter(0.6, 8.0, SIGMA, W, D)
    assert mech.flow_stress_from_contact_diameter(dc, 0.6, 8.0, W, D) == pytest.approx(SIGMA,
                                                                                      rel=1e-12)


@pytest.mark.parametrize("tilt", [0.0, 20.0, 45.0])
@pytest.mark.parametrize("mu", [0.05, 0.132, 0.3])
def test_spin_round_trip_eq8_eq9(mu, tilt):
    spin = mech.spin_after_rebound(mu, 0.5, 60.0, tilt, D)
    assert mech.friction_from_spin(spin, 0.5, 60.0, tilt, D) == pytest.approx(mu, rel=1e-12)


def test_spin_matches_report_constant():
    # The report's "theta_c = 7.72 (a' mu + b') V_n0 / D" (3 significant figures).
    vn0 = mech.normal_impact_speed(1.0, 60.0)
    spin = mech.spin_after_rebound(0.1, 1.0, 60.0, 0.0, D)
    a_prime, _ = mech.moment_arm_terms(0.0)
    # 7.72 is 1/(2 * 0.0648) rounded (+-0.065 %), and 0.0648 is the exact 83/1280 = 0.064844
    # rounded (-0.07 %): the two roundings allow 0.14 %; 2e-3 would still catch a wrong arm.
    assert spin == pytest.approx(7.72 * a_prime * 0.1 * vn0 / D, rel=2e-3)


def test_sliding_velocity_eq10_pendulum():
    # psi = 0: a' = 0.625, b' = 0, X''' = 0.3125 D; C = mu (1 + 0.625 * 0.3125 / 0.1296).
    mu = 0.132
    c = mech.sliding_deceleration_coefficient(mu, 0.0)
    assert c == pytest.approx(mu * (1 + 0.625 * 0.3125 / (2 * 83 / 1280)), rel=1e-12)
    tc = mech.contact_time(SIGMA, W, D)
    v0 = mech.impact_speed(0.4)
    vr = mech.sliding_velocity(tc, 0.4, mu, 60.0, 0.0, SIGMA, W, D)
    assert vr == pytest.approx(v0 * (math.sin(math.radians(60)) - c * 0.5), rel=1e-12)


def test_stop_time_and_exits():
    # Pendulum quartz slides until rebound; the gold vertical drop stops sliding.
    quartz = get_preset("paper-quartz")
    t, kind = mech.exit_time(quartz.mu, quartz.angle, quartz.tilt, quartz.flow_stress,
                             quartz.billet_mass, quartz.billet_diameter)
    assert kind == "rebound"
    assert t == pytest.approx(mech.contact_time(SIGMA, W, D), rel=1e-6)
    gold = get_preset("paper-gold")
    t, kind = mech.exit_time(gold.mu, gold.angle, gold.tilt, gold.flow_stress,
                             gold.billet_mass, gold.billet_diameter)
    assert kind == "stops_sliding"
    vr = mech.sliding_velocity(t, 1.0, gold.mu, gold.angle, gold.tilt, gold.flow_stress,
                               gold.billet_mass, gold.billet_diameter)
    assert vr == pytest.approx(0.0, abs=1e-12)


def test_flux_is_mu_sigma_v_and_zero_after_stop():
    q = mech.frictional_flux(0.0, 1.0, 0.1, 60.0, 0.0, SIGMA, W, D)
    assert q == pytest.approx(0.1 * SIGMA * mech.impact_speed(1.0) * math.sin(math.radians(60)))
    # Large mu at a shallow angle: sliding stops early, flux clipped to zero afterwards.
    assert mech.frictional_flux(3e-4, 1.0, 0.8, 20.0, 0.0, SIGMA, W, D) == 0.0
