"""Finite-volume meshes of the two media (report II.E), as compiled kernels in SI units.

Both media get a cell-centred mesh stretched geometrically away from the sliding interface:
the first HE cell is a fraction of the estimated reaction zone at ignition, the target's first
cell is scaled by sqrt(alpha_target / alpha_HE) so that both resolve the same time scale, and
each mesh is a fixed number of diffusion lengths deep. The functions fill caller-owned arrays
and allocate nothing, so that the CPU model builder (:func:`skidmc.solver.model.build_model`)
and a GPU thread (:mod:`skidmc.solver.device`) build the same mesh from the same code.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

__all__ = ["fill_meshes", "geometric_ratio", "layered_target_cells", "reaction_zone"]


@njit(cache=True)
def geometric_ratio(first_width, depth, n_cells):
    """Growth ratio r of a geometric mesh of ``n_cells`` cells, ``depth`` [m] deep [1].

    r solves first_width (r^n - 1) / (r - 1) = depth (bisection to 1e-14); 1.0 (a uniform mesh)
    when even ``n_cells`` cells of ``first_width`` [m] reach deeper than ``depth``.
    """
    if first_width * n_cells >= depth:
        return 1.0
    target = depth / first_width
    power = float(n_cells)
    lo, hi = 1.0 + 1e-12, 2.0
    while (hi**power - 1.0) / (hi - 1.0) < target:
        hi *= 2.0
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        if (mid**power - 1.0) / (mid - 1.0) < target:
            lo = mid
        else:
            hi = mid
        if hi - lo < 1e-14 * mid:
            break
    return 0.5 * (lo + hi)


@njit(cache=True)
def reaction_zone(model_time, he_diffusivity, initial_temperature, prefactor,
                  activation_temperature):
    """Rough thickness of the reacting layer at ignition [m], used only to size the mesh.

    The surface ignites near the temperature T_i at which the reaction time
    1/(Z exp(-T_a/T_i)) is ~1e-3 of the contact time; the layer in which the rate is
    within a factor e of the surface rate is ~ sqrt(alpha t) T_i^2 / (T_a (T_i - T0))
    (the thermal layer times the temperature fraction within T_i^2/T_a of the top).
    """
    thermal_layer = math.sqrt(he_diffusivity * model_time)
    if prefactor <= 0.0:
        return thermal_layer
    log_arg = math.log(max(prefactor * model_time * 1e-3, math.e))
    t_ign = activation_temperature / log_arg
    rise = max(t_ign - initial_temperature, 1.0)
    zone = thermal_layer * t_ign**2 / (activation_temperature * rise)
    return min(zone, thermal_layer)


@njit(cache=True)
def fill_meshes(he_density, he_heat_capacity, he_conductivity, target_density,
                target_heat_capacity, target_conductivity, initial_temperature, prefactor,
                activation_temperature, t_exit, t_end, n_cells, first_cell_fraction,
                depth_diffusion_lengths, width, rho_c, face):
    """Both media's meshes as :func:`skidmc.physics.thermal.simulate_core` takes them.

    Parameters
    ----------
    he_density, he_heat_capacity, he_conductivity : float
        rho1 [kg/m^3], c1 [J/(kg K)], k1 [W/(m K)].
    target_density, target_heat_capacity, target_conductivity : float
        rho2, c2, k2 (same units).
    initial_temperature, prefactor, activation_temperature : float
        T0 [K], Z [1/s], T_a [K] (they size the first HE cell).
    t_exit, t_end : float
        End of heating and of the integration [s].
    n_cells : int
        Cells per medium.
    first_cell_fraction : float
        First HE cell as a fraction of :func:`reaction_zone` [1].
    depth_diffusion_lengths : float
        Mesh depth in diffusion lengths sqrt(alpha t_end) [1].
    width, rho_c : ndarray, at least 2 n_cells long
        Written: cell widths [m] and volumetric heat capacities [J/(m^3 K)], target (far end
        first) then HE (interface first).
    face : ndarray, at least 2 n_cells - 1 long
        Written: conductance between cells i and i+1 [W/(m^2 K)]: half-cell resistances
        w / (2 k) in series (at the interface, Eq. 16's elimination of T_b).

    Returns
    -------
    float
        Share of the interface flux that enters the HE, g_he / (g_target + g_he) [1].
    """
    he_rho_c = he_density * he_heat_capacity
    tg_rho_c = target_density * target_heat_capacity
    alpha_he = he_conductivity / he_rho_c
    alpha_tg = target_conductivity / tg_rho_c
    zone = reaction_zone(t_exit, alpha_he, initial_temperature, prefactor,
                         activation_temperature)
    h0_he = first_cell_fraction * zone
    h0_tg = h0_he * math.sqrt(alpha_tg / alpha_he)
    r_he = geometric_ratio(h0_he, depth_diffusion_lengths * math.sqrt(alpha_he * t_end), n_cells)
    r_tg = geometric_ratio(h0_tg, depth_diffusion_lengths * math.sqrt(alpha_tg * t_end), n_cells)
    for i in range(n_cells):
        # Target cells from the far end to the interface, then HE cells away from it.
        width[n_cells - 1 - i] = h0_tg * r_tg ** float(i)
        rho_c[n_cells - 1 - i] = tg_rho_c
        width[n_cells + i] = h0_he * r_he ** float(i)
        rho_c[n_cells + i] = he_rho_c
    prev = width[0] / (2.0 * target_conductivity)
    for i in range(2 * n_cells - 1):
        k_next = target_conductivity if i + 1 < n_cells else he_conductivity
        half = width[i + 1] / (2.0 * k_next)
        face[i] = 1.0 / (prev + half)
        prev = half
    g_tg = 1.0 / (width[n_cells - 1] / (2.0 * target_conductivity))
    g_he = 1.0 / (width[n_cells] / (2.0 * he_conductivity))
    return g_he / (g_tg + g_he)


def layered_target_cells(rho_c, conductivity, thickness, first_width, t_end, n_cells,
                         depth_diffusion_lengths):
    """Cells of a layered target with a cell face on every interface (docs/targets.md).

    The mesh is the homogeneous target's geometric mesh laid out in the *diffusion depth*
    zeta = sum of (depth within layer j) / sqrt(alpha_j t_end) instead of in metres: each layer
    gets cells in proportion to how far heat diffuses into it, the mesh ends
    ``depth_diffusion_lengths`` diffusion depths down (the homogeneous rule, layer by layer),
    and for a stack of one material it is the homogeneous mesh. Each interface above that depth
    takes the nearest face of the geometric mesh (no two interfaces the same face), so every
    cell lies in one layer.

    Parameters
    ----------
    rho_c, conductivity : sequence of float
        Volumetric heat capacity [J/(m^3 K)] and conductivity [W/(m K)] of each layer, from the
        surface down.
    thickness : sequence of float
        Each layer's thickness [m]; the last is ignored (semi-infinite).
    first_width : float
        Width of the first cell [m] (in the top layer; as the homogeneous target's).
    t_end : float
        End of the integration [s].
    n_cells : int
        Number of cells.
    depth_diffusion_lengths : float
        Mesh depth in diffusion depths [1].

    Returns
    -------
    width, cell_rho_c, cell_conductivity : ndarray
        Per cell, from the surface down [m], [J/(m^3 K)], [W/(m K)].

    Raises
    ------
    ValueError
        More interfaces inside the mesh than it has inner faces.
    """
    rho_c = np.asarray(rho_c, dtype=float)
    k = np.asarray(conductivity, dtype=float)
    lengths = np.sqrt(k / rho_c * t_end)          # diffusion length of each layer [m]
    n_layers = len(rho_c)
    zeta_total = float(depth_diffusion_lengths)
    # diffusion depths of the interfaces
    bounds = np.cumsum([thickness[j] / lengths[j] for j in range(n_layers - 1)])
    h0 = first_width / lengths[0]
    r = geometric_ratio(h0, zeta_total, n_cells)
    if r == 1.0:  # uniform cells reach deeper than asked (as fill_meshes has it)
        faces = h0 * np.arange(n_cells + 1, dtype=float)
    else:
        faces = h0 * (r ** np.arange(n_cells + 1, dtype=float) - 1.0) / (r - 1.0)
        faces[-1] = zeta_total
    inner = bounds[bounds < faces[-1]]
    last = 0
    for z in inner:
        candidates = np.arange(last + 1, n_cells)
        if candidates.size == 0:
            raise ValueError(f"{inner.size} layer interfaces inside the heated depth need more "
                             f"than {n_cells} cells")
        j = int(candidates[np.argmin(np.abs(faces[candidates] - z))])
        faces[j] = z
        last = j
    # each cell's layer: the one holding its midpoint in zeta
    mid = 0.5 * (faces[:-1] + faces[1:])
    layer = np.searchsorted(bounds, mid, side="right")
    width = np.diff(faces) * lengths[layer]
    return width, rho_c[layer], k[layer]
