"""Closed form for a layered target: constant flux between the HE and a layer on a substrate.

The reference the layered meshed target (:func:`skidmc.physics.meshes.layered_target_cells`) is
checked against (docs/targets.md). Three media, all inert and semi-infinite but the middle one:
the HE (effusivity e0) above the interface, a target layer of thickness d (e1, diffusivity
alpha1) on a semi-infinite substrate (e2). A constant flux q enters at the interface from
t = 0 and splits between HE and target by Fourier's law (report Eqs. 14-16).

In Laplace space the target's surface admittance is e1 sqrt(s) (1 - g E) / (1 + g E), with
E = exp(-2 d sqrt(s / alpha1)) and g = (e1 - e2) / (e1 + e2) the substrate's reflection
coefficient (Carslaw & Jaeger, *Conduction of Heat in Solids*, 2nd ed., Sec. 12.8, the
composite slab), so the interface temperature is

    T(s) = q / (s^(3/2) (e0 + e1)) (1 + g E) / (1 - b g E),   b = (e1 - e0) / (e0 + e1).

Expanding in powers of E and inverting term by term, with
L^-1[exp(-2 m d sqrt(s / alpha1)) / s^(3/2)] = 2 sqrt(t) ierfc(m d / sqrt(alpha1 t)):

    T(t) - T0 = 2 q sqrt(t) / (e0 + e1) sum_m c_m ierfc(m d / sqrt(alpha1 t)),
    c_0 = 1, c_m = g (1 + b) (b g)^(m - 1).

Checks: e2 = e1 (g = 0) gives two semi-infinite media, 2 q sqrt(t) / (sqrt(pi) (e0 + e1));
d -> 0 gives the substrate alone, e1 -> the sum's limit (1 + g) / (1 - b g) = (e0 + e1) /
(e0 + e2); e0 = 0 gives the classical layer on a substrate heated at its face.
"""

from __future__ import annotations

import math

from scipy.special import erfc

__all__ = ["ierfc", "layer_interface_rise"]


def ierfc(x):
    """First integral of erfc, ierfc(x) = exp(-x^2) / sqrt(pi) - x erfc(x) [1]."""
    return math.exp(-x * x) / math.sqrt(math.pi) - x * erfc(x)


def layer_interface_rise(q, t, e_he, e_layer, alpha_layer, thickness, e_substrate,
                         rtol=1e-14):
    """Interface temperature rise T - T0 [K] under a constant flux ``q`` [W/m^2] at time ``t``
    [s] (module docstring).

    Parameters
    ----------
    q : float
        Flux into the interface [W/m^2].
    t : float
        Time since the flux started [s].
    e_he, e_layer, e_substrate : float
        Effusivities sqrt(k rho c) of the HE, the layer and the substrate [W s^0.5/(m^2 K)].
    alpha_layer : float
        The layer's diffusivity [m^2/s].
    thickness : float
        The layer's thickness [m].
    rtol : float
        The series stops when a term is below ``rtol`` of the sum [1].

    Returns
    -------
    float
        [K].
    """
    g = (e_layer - e_substrate) / (e_layer + e_substrate)
    b = (e_layer - e_he) / (e_he + e_layer)
    x = thickness / math.sqrt(alpha_layer * t)
    total = ierfc(0.0)
    c = g * (1.0 + b)
    for m in range(1, 100_000):
        term = c * ierfc(m * x)
        total += term
        if abs(term) <= rtol * abs(total) and (m * x > 1.0 or abs(c) <= rtol * abs(total)):
            break
        c *= b * g
    return 2.0 * q * math.sqrt(t) / (e_he + e_layer) * total
