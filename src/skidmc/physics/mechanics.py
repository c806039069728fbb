"""Mechanics of the oblique impact of a plastic hemisphere on a rigid plane.

Pure functions of SI floats (or numpy arrays), one per equation of the report
(Randolph, Hatler & Popolato; LASL skid-test report, section II.A-D). Symbols:

==========  ===========================================================  ==========
symbol      meaning                                                      unit
==========  ===========================================================  ==========
sigma       plastic flow stress of the billet (normal contact pressure)  [Pa]
W           billet mass                                                  [kg]
D           hemisphere diameter                                          [m]
phi         complement of the approach angle (pendulum) or the target    [deg]
            angle (vertical drop)
psi         billet tilt: 0 for the pendulum, = phi for a vertical drop   [deg]
mu          apparent coefficient of sliding friction                     [1]
H           vertical drop height                                         [m]
==========  ===========================================================  ==========

Rebound forces are neglected (plastic impact, report II.B), so every quantity
below holds for ``0 <= t <= t_c``.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

__all__ = [
    "CG_OFFSET_FACTOR",
    "EXIT_KINDS",
    "EXIT_REBOUND",
    "EXIT_STOPS_SLIDING",
    "HEMISPHERE_INERTIA_FACTOR",
    "STANDARD_GRAVITY",
    "angular_frequency",
    "contact_area",
    "contact_pressure",
    "contact_time",
    "exit_from_constants",
    "exit_time",
    "flow_stress_from_contact_diameter",
    "friction_from_spin",
    "frictional_flux",
    "impact_constants",
    "impact_speed",
    "max_contact_diameter",
    "moment_arm_terms",
    "normal_deformation",
    "normal_impact_speed",
    "sliding_deceleration_coefficient",
    "sliding_velocity",
    "spin_after_rebound",
    "stop_time",
]

#: Standard gravity [m/s^2] (the report's g in the drop velocity V0 = sqrt(2 g H)).
STANDARD_GRAVITY = 9.80665

#: Moment of inertia of a solid hemisphere about its centre of gravity, per unit
#: mass and squared diameter: I_cg / W = (83/320) R^2 = 0.0648 D^2 (report II.C).
HEMISPHERE_INERTIA_FACTOR = 83.0 / 1280.0

#: Distance of a hemisphere's centre of gravity from its flat face, per radius (3/8).
CG_OFFSET_FACTOR = 0.375

#: Exit codes of :func:`exit_from_constants` and their names.
EXIT_REBOUND, EXIT_STOPS_SLIDING = 0, 1
EXIT_KINDS = ("rebound", "stops_sliding")


@njit(cache=True)
def contact_pressure(flow_stress, target_hardness):
    """Normal pressure over the contact, p = min(sigma, p_t) [Pa] (docs/model.md, "Targets
    softer than the billet").

    The report's contact (Sec. II.B) is a plastic impact at the billet's flow stress sigma on a
    rigid target. Whichever of billet and target yields at the lower pressure limits it: a
    target whose indentation hardness (or confined crushing strength) p_t lies below sigma is
    indented by the billet, which stays elastic (nearly rigid), and the contact pressure is p_t.
    The cap law a^2 = D X of a sphere in a plastic half-space (pile-up and sink-in neglected)
    and the rigid-body kinematics of Eqs. (2)-(10) are the same with p in place of sigma, so
    every equation of :mod:`skidmc.physics.mechanics` and the flux q = mu p V_r (Eq. 1) take p.

    Parameters
    ----------
    flow_stress : float
        sigma, the billet's plastic flow stress [Pa].
    target_hardness : float
        p_t, the target's yield pressure [Pa]; inf for a rigid target.

    Returns
    -------
    float
        [Pa].
    """
    return min(flow_stress, target_hardness)


def impact_speed(height):
    """Impact speed V0 = sqrt(2 g H) after a vertical drop [m/s].

    Parameters
    ----------
    height : float or array
        Vertical drop height H [m].
    """
    return np.sqrt(2.0 * STANDARD_GRAVITY * np.asarray(height, dtype=float))


def normal_impact_speed(height, angle):
    """Normal component of the impact velocity, V_n0 = sqrt(2 g H) cos(phi) [m/s] (II.B)."""
    return impact_speed(height) * np.cos(np.radians(angle))


def angular_frequency(flow_stress, billet_mass, billet_diameter):
    """Frequency of the constant-stress plastic impact, omega = sqrt(pi sigma D / W) [rad/s].

    From W X'' = -sigma pi D X (report Eq. 2 with F = sigma A, A = pi D X).
    """
    return np.sqrt(np.pi * flow_stress * billet_diameter / billet_mass)


def contact_time(flow_stress, billet_mass, billet_diameter):
    """Contact time t_c = pi / (2 omega) [s], independent of the impact speed (II.B)."""
    return 0.5 * np.pi / angular_frequency(flow_stress, billet_mass, billet_diameter)


def normal_deformation(t, height, angle, flow_stress, billet_mass, billet_diameter):
    """Normal deformation X(t) = (V_n0 / omega) sin(omega t) [m] (II.B)."""
    omega = angular_frequency(flow_stress, billet_mass, billet_diameter)
    return normal_impact_speed(height, angle) / omega * np.sin(omega * np.asarray(t, dtype=float))


def contact_area(t, height, angle, flow_stress, billet_mass, billet_diameter):
    """Contact area A(t) = pi D X(t) [m^2] (II.B, a^2 = D X)."""
    x = normal_deformation(t, height, angle, flow_stress, billet_mass, billet_diameter)
    return np.pi * billet_diameter * x


def max_contact_diameter(height, angle, flow_stress, billet_mass, billet_diameter):
    """Maximum contact diameter d_c [m], report Eq. (5).

    d_c^4 = 32 D W g cos^2(phi) H / (pi sigma), i.e. d_c = K H^(1/4) (Eq. 6).
    """
    cos_phi = np.cos(np.radians(angle))
    dc4 = (
        32.0 * billet_diameter * billet_mass * STANDARD_GRAVITY * cos_phi**2
        * np.asarray(height, dtype=float) / (np.pi * flow_stress)
    )
    return dc4**0.25


def flow_stress_from_contact_diameter(contact_diameter, height, angle, billet_mass,
                                      billet_diameter):
    """Flow stress sigma [Pa] that explains a measured maximum contact diameter, Eq. (5) inverted.

    This is how the report measured sigma (imprint on carbon paper, Fig. 3).
    """
    cos_phi = np.cos(np.radians(angle))
    return (32.0 * billet_diameter * billet_mass * STANDARD_GRAVITY * cos_phi**2 * height
            / (np.pi * np.asarray(contact_diameter, dtype=float) ** 4))


def moment_arm_terms(tilt):
    """Trigonometric moment-arm terms a' = 1 - 0.375 cos(psi), b' = 0.375 sin(psi) [1] (II.C).

    a' R is the arm of the tangential force about the centre of gravity and b' R
    that of the normal force. For the pendulum (psi = 0), b' = 0: the normal force
    passes through the centre of gravity and only friction spins the billet.
    """
    psi = np.radians(tilt)
    return 1.0 - CG_OFFSET_FACTOR * np.cos(psi), CG_OFFSET_FACTOR * np.sin(psi)


def spin_after_rebound(mu, height, angle, tilt, billet_diameter):
    """Angular velocity after rebound theta_dot_c [rad/s], report Eq. (8).

    theta_dot_c = (a' mu + b') D V_n0 W / (2 I_cg) = (a' mu + b') V_n0 / (2 * 0.0648 D),
    the report's "7.72 (a' mu + b') V_n0 / D".
    """
    a_prime, b_prime = moment_arm_terms(tilt)
    vn0 = normal_impact_speed(height, angle)
    return (a_prime * mu + b_prime) * vn0 / (2.0 * HEMISPHERE_INERTIA_FACTOR * billet_diameter)


def friction_from_spin(spin_rate, height, angle, tilt, billet_diameter):
    """Apparent friction coefficient mu [1] from the spin after rebound, report Eq. (9).

    mu = (1/a') (2 * 0.0648 D theta_dot_c / V_n0 - b'): the report's "0.13 D theta_dot_c / V_n0".
    Inverse of :func:`spin_after_rebound`.
    """
    a_prime, b_prime = moment_arm_terms(tilt)
    vn0 = normal_impact_speed(height, angle)
    return (2.0 * HEMISPHERE_INERTIA_FACTOR * billet_diameter * spin_rate / vn0 - b_prime) / a_prime


def sliding_deceleration_coefficient(mu, tilt):
    """Coefficient C of Eq. (10): V_r/V0 = sin(phi) - C cos(phi) (1 - cos(omega t)) [1].

    C = mu + (a' mu + b') D W X''' / (2 I_cg), where X''' = sqrt(X'^2 + X''^2)
    = (D/2) sqrt(a'^2 + b'^2) is the distance from the centre of gravity to the
    contact centre (the report's "X''' = [(X'')^2 + (X''')^2]^(1/2)" is a typo for the length
    of the lever arm (X', X'')). With I_cg = 0.0648 D^2 W the diameter and mass cancel.
    The first term is the translational deceleration by friction, the second the
    contact point's velocity due to the spin friction (and, for psi > 0, the normal
    force) imparts.
    """
    a_prime, b_prime = moment_arm_terms(tilt)
    arm = 0.5 * np.hypot(a_prime, b_prime)  # X''' / D
    return mu + (a_prime * mu + b_prime) * arm / (2.0 * HEMISPHERE_INERTIA_FACTOR)


def sliding_velocity(t, height, mu, angle, tilt, flow_stress, billet_mass, billet_diameter):
    """Sliding velocity of the contact on the target V_r(t) [m/s], report Eq. (10).

    Not clipped: a negative value means the contact has stopped sliding earlier
    (see :func:`stop_time`).
    """
    omega = angular_frequency(flow_stress, billet_mass, billet_diameter)
    phi = np.radians(angle)
    c = sliding_deceleration_coefficient(mu, tilt)
    wt = omega * np.asarray(t, dtype=float)
    return impact_speed(height) * (np.sin(phi) - c * np.cos(phi) * (1.0 - np.cos(wt)))


def stop_time(mu, angle, tilt, flow_stress, billet_mass, billet_diameter):
    """Time at which the contact stops sliding [s]; ``inf`` if it slides until rebound.

    V_r = 0 at cos(omega t_s) = 1 - tan(phi)/C, which lies in the contact phase
    (omega t_s <= pi/2) only when C >= tan(phi). Independent of the drop height.
    """
    omega = angular_frequency(flow_stress, billet_mass, billet_diameter)
    c = sliding_deceleration_coefficient(mu, tilt)
    tan_phi = np.tan(np.radians(angle))
    with np.errstate(divide="ignore", invalid="ignore"):
        cos_wt = 1.0 - tan_phi / c
        ts = np.where(c >= tan_phi, np.arccos(np.clip(cos_wt, -1.0, 1.0)) / omega, np.inf)
    return ts[()] if np.ndim(ts) == 0 else ts


def exit_time(mu, angle, tilt, flow_stress, billet_mass, billet_diameter):
    """End of frictional heating [s] and its cause: ``(t_exit, "rebound" | "stops_sliding")``.

    The report's two non-event exits: "hemisphere rebounds" at t_c and "hemisphere
    stops sliding" at t_s < t_c (:func:`exit_from_constants`). Scalars only.
    """
    _, _, t_exit, exit_code, _, _ = impact_constants(mu, flow_stress, billet_mass,
                                                     billet_diameter, angle, tilt)
    return t_exit, EXIT_KINDS[exit_code]


@njit(cache=True)
def exit_from_constants(omega, coefficient, angle):
    """End of frictional heating from the impact's omega and C (scalars, compiled).

    The report's two non-event exits: "hemisphere rebounds" at t_c = pi / (2 omega) and
    "hemisphere stops sliding" at t_s, where V_r = 0: cos(omega t_s) = 1 - tan(phi) / C
    (Eq. 10), inside the contact only when C >= tan(phi). Both are independent of the drop
    height. The one definition of the exit, used by the full model
    (:func:`skidmc.solver.model.build_model`, through :func:`impact_constants`) and by the fast
    tier's kernels.

    Parameters
    ----------
    omega : float
        :func:`angular_frequency` [rad/s].
    coefficient : float
        :func:`sliding_deceleration_coefficient` C [1].
    angle : float
        phi [deg].

    Returns
    -------
    t_exit : float
        [s].
    exit_code : int
        :data:`EXIT_REBOUND` or :data:`EXIT_STOPS_SLIDING` (names in :data:`EXIT_KINDS`).
    """
    t_c = 0.5 * math.pi / omega
    tan_phi = math.tan(math.radians(angle))
    # C >= tan(phi) > 0 in this branch for a valid scene's 0 < phi < 90 deg.
    if coefficient >= tan_phi:
        cos_wt = min(max(1.0 - tan_phi / coefficient, -1.0), 1.0)
        t_s = math.acos(cos_wt) / omega
        if t_s < t_c:
            return t_s, EXIT_STOPS_SLIDING
    return t_c, EXIT_REBOUND


@njit(cache=True)
def impact_constants(mu, flow_stress, billet_mass, billet_diameter, angle, tilt):
    """Height-independent constants of the impact, report Eqs. 2-10 (scalars, compiled).

    The scalar form of :func:`angular_frequency`, :func:`sliding_deceleration_coefficient` and
    :func:`exit_from_constants`, shared by the full model and the fast tier's kernels.

    Parameters
    ----------
    mu : float
        Apparent friction coefficient [1].
    flow_stress, billet_mass, billet_diameter : float
        sigma [Pa], W [kg], D [m].
    angle, tilt : float
        phi and psi [deg].

    Returns
    -------
    omega : float
        sqrt(pi sigma D / W) [rad/s].
    coefficient : float
        C of Eq. (10) [1].
    t_exit : float
        End of heating, min(t_c, t_s) [s].
    exit_code : int
        :data:`EXIT_REBOUND` or :data:`EXIT_STOPS_SLIDING`.
    s, c : float
        sin(phi) and C cos(phi): V_r / V0 = s - c (1 - cos(omega t)), Eq. (10) [1].
    """
    omega = math.sqrt(math.pi * flow_stress * billet_diameter / billet_mass)
    psi = math.radians(tilt)
    a_prime = 1.0 - CG_OFFSET_FACTOR * math.cos(psi)
    b_prime = CG_OFFSET_FACTOR * math.sin(psi)
    arm = 0.5 * math.hypot(a_prime, b_prime)  # distance from the CG to the contact, per D
    coefficient = mu + (a_prime * mu + b_prime) * arm / (2.0 * HEMISPHERE_INERTIA_FACTOR)
    t_exit, exit_code = exit_from_constants(omega, coefficient, angle)
    phi = math.radians(angle)
    return omega, coefficient, t_exit, exit_code, math.sin(phi), coefficient * math.cos(phi)


def frictional_flux(t, height, mu, angle, tilt, flow_stress, billet_mass, billet_diameter):
    """Frictional heat flux at the interface q(t) = mu sigma V_r(t) [W/m^2], report Eq. (1).

    In SI the report's mechanical-to-thermal factor J is 1. Zero once sliding stops.
    """
    vr = sliding_velocity(t, height, mu, angle, tilt, flow_stress, billet_mass, billet_diameter)
    return mu * flow_stress * np.maximum(vr, 0.0)
