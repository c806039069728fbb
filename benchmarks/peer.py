"""The "peer": the skid-test model written the way a capable engineer would *without* skidmc.

This module is the baseline of the speed benchmark (issue 3). It solves the same model as
skidmc (report sections II.B-II.E), but the standard way: a
method-of-lines discretisation handed to ``scipy.integrate.solve_ivp(method="BDF")`` with a
sparse Jacobian (by default the exact one, assembled into a fixed CSC pattern; or, with
``jacobian="sparsity"``, only its pattern via ``jac_sparsity`` so that scipy builds it by grouped
finite differences; either way factorised by sparse LU), on a stretched mesh per medium, and the
report's geometric bisection for the critical height. It uses numpy only (no numba, no skidmc
import), with a vectorised right-hand side.

Model (all SI)
--------------
Mechanics (report II.B-D, Eq. 10):
    omega = sqrt(pi sigma D / W), t_c = pi / (2 omega), V0 = sqrt(2 g H),
    a' = 1 - 0.375 cos psi, b' = 0.375 sin psi, X''' = (D/2) sqrt(a'^2 + b'^2),
    C = mu + (a' mu + b') X''' D W / (2 I_cg),  I_cg = (83/320) R^2 W = 0.0648 D^2 W,
    V_r(t) = V0 [sin phi - C cos phi (1 - cos omega t)],
    q(t) = mu sigma V_r(t) for 0 <= t <= t_exit, t_exit = min(t_c, t_s) where V_r(t_s) = 0.
    (I_cg/W D^2 = 83/1280 = 0.06484375 exactly; the report rounds it to 0.0648.)

Heat (report II.E, Eqs. 11-16): 1-D conduction in the HE (x > 0) and the target (x < 0),
cell-centred finite volumes, one geometric mesh per medium with its finest cell at the interface,
insulated far ends. The interface temperature is eliminated as (Eq. 16)

    T_b = (q + g1 T1 + g2 T2) / (g1 + g2),   g = 2 k / (first cell width),

and the flux g1 (T_b - T1) enters the first HE cell, g2 (T_b - T2) the first target cell.

HE chemistry: first order Arrhenius, dy/dt = Z exp(-Ta/T) (1 - y), heat release rho Q dy/dt.

Melting: *enthalpy formulation* with a linear mushy interval. The HE state is the
temperature-equivalent enthalpy u = h / c [K] above T0, with

    u(T) = (T - T0) + (L / c) * clip((T - Tm + w/2) / w, 0, 1),

which is inverted exactly and cheaply (piecewise linear). ``melt_width`` w [K] is a
discretisation parameter (w -> 0 is the sharp-interface enthalpy method; w = 0 is allowed).
Same heat capacity in both phases. L = 0 disables melting.

Thermal event: the report's criterion, y > 0.99 in any cell, as a terminal ``solve_ivp``
event on max(y) - 0.99. In the last instants of a runaway the local induction time falls below
the time resolution a stiff integrator can step (scipy's BDF refuses steps under
10 ulp(t) ~ 1e-19 s at t ~ 1e-4 s; with y alone it fails with "Required step size is less than
spacing between numbers" at 2300-7000 K, sooner the tighter rtol). So a second terminal event fires
when any HE cell passes ``runaway_temperature`` (default 1500 K): there the adiabatic induction
time c T^2 / (Q Ta Z exp(-Ta/T)) is ~1e-14 s for the report's HMX kinetics, 10 orders of
magnitude shorter than the contact time and 6 shorter than conduction across a 0.1 um layer
(~1e-8 s), so the run would certainly reach y > 0.99 too (the benchmark checks that 1200, 1500
and 2000 K give the same critical height). If the integrator nevertheless fails (status -1) with
a cell above half-way to that temperature, the run is counted as an event and flagged
(``event_kind="integrator_failure"``). Set ``runaway_temperature=None`` to use the y-criterion
alone (then a failed integration raises ``RuntimeError``).

A run is a "go" when an event happens at t <= t_exit (the heating and the simulation both end at
the exit, as in the report).

Public API
----------
``simulate(inputs, height, rtol=1e-5, atol=None, n_cells=80, ...) -> dict``
``critical_height(inputs, rel_tol=1e-3, solver_rtol=1e-5, n_cells=80, h_lo=0.01, h_hi=1000.0,
                  ...) -> dict``
``QUARTZ``, ``ALUMINA_SMOOTH``: the report's first-series inputs (dicts of SI floats).
"""

from __future__ import annotations

import math
import time
from types import SimpleNamespace

import numpy as np
import scipy.sparse as sp
from scipy.integrate import solve_ivp

__all__ = [
    "ALUMINA_SMOOTH",
    "QUARTZ",
    "Mesh",
    "build_system",
    "critical_height",
    "exit_time",
    "make_mesh",
    "simulate",
]

G = 9.80665  # standard gravity [m/s^2]
INERTIA = 83.0 / 1280.0  # I_cg / (W D^2) of a solid hemisphere (report: 0.0648)
CAL = 4.184  # J

# ----------------------------------------------------------------------------------------------
# The report's first-series inputs (Tables II, VI, VII, VIII), SI floats.
# ----------------------------------------------------------------------------------------------
_HE = {
    "initial_temperature": 530.0 / 1.8,  # 530 R
    "he.density": 1910.0,
    "he.heat_capacity": 0.295 * CAL * 1000.0,
    "he.conductivity": 9.2e-4 * CAL * 100.0,
    "he.heat_of_fusion": 50.0 * CAL * 1000.0,
    "he.melting_point": 553.0,
    "kinetics.prefactor": 5.0e19,
    "kinetics.activation_temperature": 2.63e4,
    "kinetics.heat_of_reaction": 6.66e5 * CAL / 296.16e-3,
}
_BILLET = {
    "flow_stress": 28000.0 * 6894.757293168361,
    "billet_mass": 19.1 * 0.45359237,
    "billet_diameter": 10.0 * 0.0254,
    "angle": 60.0,
    "tilt": 0.0,
}
QUARTZ = {
    "mu": 0.132, **_BILLET, **_HE,
    "target.density": 2670.0,
    "target.heat_capacity": 0.188 * CAL * 1000.0,
    "target.conductivity": 4.05e-3 * CAL * 100.0,
}
ALUMINA_SMOOTH = {
    "mu": 0.0576, **_BILLET, **_HE,
    "target.density": 3400.0,
    "target.heat_capacity": 0.18 * CAL * 1000.0,
    "target.conductivity": 2.1e-2 * CAL * 100.0,
}


# ----------------------------------------------------------------------------------------------
# Mechanics
# ----------------------------------------------------------------------------------------------
def _mechanics(inputs):
    mu = inputs["mu"]
    sigma = inputs["flow_stress"]
    W = inputs["billet_mass"]
    D = inputs["billet_diameter"]
    phi = math.radians(inputs["angle"])
    psi = math.radians(inputs["tilt"])
    omega = math.sqrt(math.pi * sigma * D / W)
    t_c = 0.5 * math.pi / omega
    a1 = 1.0 - 0.375 * math.cos(psi)
    b1 = 0.375 * math.sin(psi)
    arm = 0.5 * math.hypot(a1, b1)  # X''' / D
    C = mu + (a1 * mu + b1) * arm / (2.0 * INERTIA)
    tan_phi = math.tan(phi)
    if C >= tan_phi:
        t_s = math.acos(max(-1.0, min(1.0, 1.0 - tan_phi / C))) / omega
    else:
        t_s = math.inf
    if t_s < t_c:
        t_exit, cause = t_s, "stops_sliding"
    else:
        t_exit, cause = t_c, "rebound"
    return {"omega": omega, "t_c": t_c, "C": C, "sin_phi": math.sin(phi),
            "cos_phi": math.cos(phi), "t_exit": t_exit, "exit_cause": cause}


def exit_time(inputs):
    """End of frictional heating ``(t_exit [s], "rebound" | "stops_sliding")``."""
    m = _mechanics(inputs)
    return m["t_exit"], m["exit_cause"]


# ----------------------------------------------------------------------------------------------
# Mesh
# ----------------------------------------------------------------------------------------------
class Mesh:
    """Geometric cell-centred mesh of one semi-infinite medium: ``widths[0]`` at the interface."""

    def __init__(self, widths):
        self.widths = np.asarray(widths, dtype=float)
        self.n = self.widths.size
        faces = np.concatenate(([0.0], np.cumsum(self.widths)))
        self.centres = 0.5 * (faces[1:] + faces[:-1])
        self.depth = faces[-1]


def make_mesh(length, n_cells, first_cell, depth):
    """Geometric mesh of ``n_cells`` cells over ``depth * length`` [m], first cell ``first_cell *
    length``; the stretch ratio r solves first * (r^n - 1) / (r - 1) = depth."""
    dx0 = first_cell * length
    total = depth * length
    if dx0 * n_cells >= total:  # uniform would already reach the depth
        return Mesh(np.full(n_cells, total / n_cells))
    # solve dx0 (r^n - 1)/(r - 1) = total for r > 1 (monotone): bisection on log r
    lo, hi = 1.0 + 1e-12, 2.0
    while dx0 * (hi**n_cells - 1.0) / (hi - 1.0) < total:
        hi *= 2.0
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        if dx0 * (mid**n_cells - 1.0) / (mid - 1.0) < total:
            lo = mid
        else:
            hi = mid
    r = 0.5 * (lo + hi)
    return Mesh(dx0 * r ** np.arange(n_cells))


# ----------------------------------------------------------------------------------------------
# One simulation at a height
# ----------------------------------------------------------------------------------------------
def build_system(inputs, height, n_cells=80, *, first_cell=None, depth=8.0, melt_width=0.0,
                 constant_flux=None, reaction=True):
    """The method-of-lines system of :func:`simulate` (arguments as there).

    Returns a ``types.SimpleNamespace`` with ``rhs(t, s)``, ``jac(t, s)`` (sparse CSC),
    ``sparsity``, ``flux(t)``, ``temperature_he(u)``, the state slices ``s_u``, ``s_th``, ``s_y``,
    the meshes ``m1`` (HE), ``m2`` (target) and the constants used by :func:`simulate`.
    """
    mech = _mechanics(inputs)
    T0 = inputs["initial_temperature"]
    rho1, c1, k1 = inputs["he.density"], inputs["he.heat_capacity"], inputs["he.conductivity"]
    rho2, c2, k2 = (inputs["target.density"], inputs["target.heat_capacity"],
                    inputs["target.conductivity"])
    L = inputs["he.heat_of_fusion"]
    Tm = inputs["he.melting_point"]
    Z = inputs["kinetics.prefactor"] if reaction else 0.0
    Ta = inputs["kinetics.activation_temperature"]
    Q = inputs["kinetics.heat_of_reaction"]
    a1, a2 = k1 / (rho1 * c1), k2 / (rho2 * c2)

    t_c = mech["t_c"]
    if first_cell is None:
        first_cell = 0.2 / n_cells
    m1 = make_mesh(math.sqrt(a1 * t_c), n_cells, first_cell, depth)
    m2 = make_mesh(math.sqrt(a2 * t_c), n_cells, first_cell, depth)
    n1, n2 = m1.n, m2.n

    # conductances [W/m^2/K] between neighbouring cell centres and to the interface
    G1 = k1 / np.diff(m1.centres)
    G2 = k2 / np.diff(m2.centres)
    g1 = 2.0 * k1 / m1.widths[0]
    g2 = 2.0 * k2 / m2.widths[0]
    inv_cap1 = 1.0 / (rho1 * c1 * m1.widths)  # -> K/s per W/m^2
    inv_cap2 = 1.0 / (rho2 * c2 * m2.widths)
    qc = Q / c1  # adiabatic temperature rise per unit progress [K]

    # enthalpy <-> temperature (temperature-equivalent u = h/c, relative to T0)
    lc = L / c1
    w = float(melt_width)
    u1 = Tm - 0.5 * w - T0  # start of melting
    u2 = u1 + w + lc  # end of melting
    mush_slope = w / (w + lc) if (w + lc) > 0.0 else 1.0

    def temperature_he(u):
        # piecewise linear exact inverse of u(T)
        return T0 + np.where(u < u1, u, np.where(u > u2, u - lc, u1 + (u - u1) * mush_slope))

    # flux
    V0 = math.sqrt(2.0 * G * height)
    mu_sigma = inputs["mu"] * inputs["flow_stress"]
    omega, C, sphi, cphi = mech["omega"], mech["C"], mech["sin_phi"], mech["cos_phi"]

    if constant_flux is not None:
        q0 = float(constant_flux)

        def flux(t):
            return q0
    else:
        def flux(t):
            vr = V0 * (sphi - C * cphi * (1.0 - math.cos(omega * t)))
            return mu_sigma * vr if vr > 0.0 else 0.0

    # state: [u (HE, n1) | theta (target, n2) | y (HE, n1)], u and theta in K above T0
    s_u = slice(0, n1)
    s_th = slice(n1, n1 + n2)
    s_y = slice(n1 + n2, 2 * n1 + n2)
    n_state = 2 * n1 + n2
    out = np.empty(n_state)
    flux_he = np.empty(n1 + 1)  # flux into HE cell i through its interface-side face
    flux_tg = np.empty(n2 + 1)
    flux_he[-1] = 0.0
    flux_tg[-1] = 0.0
    gsum = g1 + g2

    def rhs(t, s):
        u = s[s_u]
        th = s[s_th]
        y = s[s_y]
        T1 = temperature_he(u)
        th1 = T1 - T0
        tb = (flux(t) + g1 * th1[0] + g2 * th[0]) / gsum
        flux_he[0] = g1 * (tb - th1[0])
        flux_he[1:-1] = G1 * (th1[:-1] - th1[1:])
        flux_tg[0] = g2 * (tb - th[0])
        flux_tg[1:-1] = G2 * (th[:-1] - th[1:])
        rate = Z * np.exp(-Ta / np.maximum(T1, 1.0)) * (1.0 - y)
        out[s_u] = (flux_he[:-1] - flux_he[1:]) * inv_cap1 + qc * rate
        out[s_th] = (flux_tg[:-1] - flux_tg[1:]) * inv_cap2
        out[s_y] = rate
        return out.copy()

    # Jacobian structure: tridiagonal in u and in theta, u_0 <-> theta_0 through T_b,
    # u_i <-> y_i (reaction), y_i <-> y_i. The linear conduction operator A acts on the node
    # temperatures [theta_HE (n1) | theta_target (n2)]; T_b is eliminated, which leaves a
    # conductance g1 g2 / (g1 + g2) between the two interface cells.
    i1 = np.arange(n1)
    i2 = np.arange(n2)
    a_r, a_c, a_v = [], [], []

    def link(i, j, g, inv_cap_i, inv_cap_j):
        # conductance g between nodes i and j (arrays)
        a_r.extend((i, i, j, j))
        a_c.extend((i, j, j, i))
        a_v.extend((-g * inv_cap_i, g * inv_cap_i, -g * inv_cap_j, g * inv_cap_j))

    link(i1[:-1], i1[1:], G1, inv_cap1[:-1], inv_cap1[1:])
    link(n1 + i2[:-1], n1 + i2[1:], G2, inv_cap2[:-1], inv_cap2[1:])
    geff = g1 * g2 / (g1 + g2)
    link(np.array([0]), np.array([n1]), np.array([geff]), inv_cap1[:1], inv_cap2[:1])
    a_r = np.concatenate(a_r)
    a_c = np.concatenate(a_c)
    a_v = np.concatenate(a_v)
    iy = n1 + n2 + i1
    rr = np.concatenate((a_r, i1, i1, iy, iy))
    cc = np.concatenate((a_c, i1, iy, i1, iy))
    # CSC structure (duplicates merged) and the position of every entry in it
    keys = cc.astype(np.int64) * n_state + rr
    ukeys, pos = np.unique(keys, return_inverse=True)
    jac_indices = (ukeys % n_state).astype(np.int32)
    jac_indptr = np.searchsorted(ukeys // n_state, np.arange(n_state + 1)).astype(np.int32)
    nnz = ukeys.size
    sparsity = sp.csc_matrix((np.ones(nnz), jac_indices, jac_indptr), shape=(n_state, n_state))
    n_a = a_v.size
    scale = np.ones(n1 + n2)

    def jac(t, s):
        u = s[s_u]
        y = s[s_y]
        T1 = np.maximum(temperature_he(u), 1.0)
        slope = np.where((u < u1) | (u > u2), 1.0, mush_slope)  # dT/du
        K = Z * np.exp(-Ta / T1)
        dK = K * Ta / (T1 * T1) * (1.0 - y) * slope  # d rate / d u
        scale[:n1] = slope
        vals = np.concatenate((a_v * scale[a_c[:n_a]], qc * dK, -qc * K, dK, -K))
        data = np.bincount(pos, weights=vals, minlength=nnz)
        return sp.csc_matrix((data, jac_indices, jac_indptr), shape=(n_state, n_state))

    return SimpleNamespace(
        mech=mech, T0=T0, t_c=t_c, m1=m1, m2=m2, n1=n1, n2=n2, n_state=n_state, s_u=s_u,
        s_th=s_th, s_y=s_y, g1=g1, g2=g2, gsum=gsum, lc=lc, w=w, Tm=Tm, rho1=rho1, c1=c1,
        rho2=rho2, c2=c2, rhs=rhs, jac=jac, sparsity=sparsity, flux=flux,
        temperature_he=temperature_he)


def simulate(inputs, height, rtol=1e-5, atol=None, n_cells=80, *, first_cell=None, depth=8.0,
             melt_width=0.0, runaway_temperature=1500.0, y_event=0.99, constant_flux=None,
             t_end=None, t_eval=None, reaction=True, max_step=np.inf,
             jacobian="analytic"):
    """Simulate one drop from ``height`` [m] and report whether a thermal event happens.

    Parameters
    ----------
    inputs : dict
        SI floats with the skidmc flat keys (see module docstring / ``QUARTZ``).
    height : float
        Vertical drop height H [m].
    rtol : float
        ``solve_ivp`` relative tolerance.
    atol : float or None
        Absolute tolerance on the temperature-like states [K]; default ``rtol * 1 K``
        (1e-3 K at rtol 1e-3). The reaction progress y gets ``atol * 1e-3`` (y is dimensionless
        and tiny until runaway; its heat release is measured by the temperature states).
    n_cells : int
        Cells per medium (HE and target each).
    first_cell : float or None
        Width of the interface cell in units of sqrt(alpha t_c) of its medium (default
        ``0.2 / n_cells``: 0.005 at 40 cells, so that the stretch ratio is the same function of
        n and doubling n halves every cell: a consistent refinement family).
    depth : float
        Depth of each medium in units of its sqrt(alpha t_c) (default 8).
    melt_width : float
        Width w [K] of the linear mushy interval of the enthalpy formulation (0 = sharp).
    runaway_temperature : float or None
        Extra terminal event: an HE cell above this temperature [K] counts as a thermal event
        (see module docstring). None: the report's y > 0.99 alone.
    y_event : float
        Reaction progress defining the thermal event (report: 0.99).
    constant_flux : float or None
        If given, replace the frictional flux by this constant flux q0 [W/m^2] from t = 0 to
        ``t_end`` (verification against the closed form).
    t_end : float or None
        End time [s]; default t_exit (end of frictional heating).
    t_eval : array or None
        Passed to ``solve_ivp``; the interface temperature at these times is returned.
    reaction : bool
        False switches the chemistry off (inert).
    max_step : float
        Passed to ``solve_ivp``.
    jacobian : {"analytic", "sparsity"}
        "analytic" (default): the exact sparse Jacobian, passed as ``jac`` (CSC, same pattern);
        2-3x faster. "sparsity": ``jac_sparsity`` only, scipy differences the right-hand side in
        column groups (the textbook use of solve_ivp; its per-column bookkeeping dominates).

    Returns
    -------
    dict with ``event`` (bool), ``t_event`` (s or None), ``t_exit`` (s), ``exit_cause``,
    ``event_kind`` ("y", "temperature", "integrator_failure" or None), ``max_temperature`` (K),
    ``max_y``, ``nfev``, ``njev``, ``nlu``, ``status``, ``message``, ``wall_s``, and with
    ``t_eval``: ``t``, ``interface_temperature`` [K] and ``stored_heat`` [J/m^2] arrays.
    """
    t_wall = time.perf_counter()
    sy = build_system(inputs, height, n_cells, first_cell=first_cell, depth=depth,
                      melt_width=melt_width, constant_flux=constant_flux, reaction=reaction)
    mech, T0, t_c, n_state = sy.mech, sy.T0, sy.t_c, sy.n_state
    s_u, s_th, s_y, n1 = sy.s_u, sy.s_th, sy.s_y, sy.n1
    lc, w, Tm = sy.lc, sy.w, sy.Tm
    temperature_he, flux = sy.temperature_he, sy.flux
    if t_end is None:
        t_end = mech["t_exit"]
    if atol is None:
        atol = rtol * 1.0
    atol_vec = np.full(n_state, float(atol))
    atol_vec[s_y] = atol * 1e-3

    def ev_y(t, s):
        return s[s_y].max() - y_event

    ev_y.terminal = True
    ev_y.direction = 1.0
    events = [ev_y]
    if runaway_temperature is not None and reaction:
        # T > T_run  <=>  u > u(T_run) (u is monotone in T)
        Tr = float(runaway_temperature)
        u_run = (Tr - T0) + lc * min(1.0, max(0.0, (Tr - Tm + 0.5 * w) / w)) if w > 0 else (
            (Tr - T0) + (lc if Tr >= Tm else 0.0))

        def ev_T(t, s):
            return s[s_u].max() - u_run

        ev_T.terminal = True
        ev_T.direction = 1.0
        events.append(ev_T)

    if jacobian == "analytic":
        jac_option = {"jac": sy.jac}
    elif jacobian == "sparsity":
        jac_option = {"jac_sparsity": sy.sparsity}
    else:
        raise ValueError(f"jacobian must be 'analytic' or 'sparsity', not {jacobian!r}")
    s0 = np.zeros(n_state)
    with np.errstate(over="ignore"):
        sol = solve_ivp(sy.rhs, (0.0, t_end), s0, method="BDF", rtol=rtol, atol=atol_vec,
                        events=events, t_eval=t_eval, max_step=max_step, **jac_option)

    event_kind = None
    t_event = None
    if sol.status == 1:
        for kind, te in zip(("y", "temperature"), sol.t_events, strict=False):
            if te.size:
                event_kind, t_event = kind, float(te[0])
                break
    s_last = sol.y[:, -1] if sol.y.size else s0
    if sol.y_events is not None and t_event is not None:
        k = 0 if event_kind == "y" else 1
        s_last = sol.y_events[k][0]
    T_last = temperature_he(s_last[s_u])
    max_T = float(T_last.max())
    if sol.status == -1 and runaway_temperature is not None and max_T > 0.5 * (
            runaway_temperature + T0):
        # the stiff integrator gave up inside a runaway (see module docstring)
        event_kind, t_event = "integrator_failure", float(sol.t[-1])
    result = {
        "event": event_kind is not None,
        "t_event": t_event,
        "event_kind": event_kind,
        "t_exit": float(t_end),
        "t_c": t_c,
        "exit_cause": mech["exit_cause"] if constant_flux is None else "constant_flux",
        "max_temperature": max_T,
        "max_y": float(s_last[s_y].max()),
        "nfev": int(sol.nfev),
        "njev": int(sol.njev),
        "nlu": int(sol.nlu),
        "status": int(sol.status),
        "message": sol.message,
        "wall_s": time.perf_counter() - t_wall,
    }
    if sol.status == -1 and event_kind is None:
        raise RuntimeError(f"solve_ivp failed at H = {height} m, t = {sol.t[-1]:.6g} s, "
                           f"max T = {max_T:.1f} K, max y = {s_last[s_y].max():.3g}: "
                           f"{sol.message}")
    if t_eval is not None:
        th1 = temperature_he(sol.y[s_u]) - T0
        tb = (np.array([flux(t) for t in sol.t]) + sy.g1 * th1[0] + sy.g2 * sol.y[n1]) / sy.gsum
        result["t"] = sol.t
        result["interface_temperature"] = T0 + tb
        # heat stored per unit area [J/m^2] (sensible + latent + reaction-released in the HE
        # enthalpy u), to check conservation against the heat put in
        result["stored_heat"] = (sy.rho1 * sy.c1 * (sy.m1.widths @ sol.y[s_u])
                                 + sy.rho2 * sy.c2 * (sy.m2.widths @ sol.y[s_th]))
    return result


# ----------------------------------------------------------------------------------------------
# Critical height: the report's geometric bisection
# ----------------------------------------------------------------------------------------------
def critical_height(inputs, rel_tol=1e-3, solver_rtol=1e-5, n_cells=80, h_lo=0.01, h_hi=1000.0,
                    solver_atol=None, verbose=False, **sim_kwargs):
    """Critical drop height [m] by the report's search (II.E): after checking the bracket
    [h_lo, h_hi] (no-go at h_lo, go at h_hi), the next height is the geometric mean of the lowest
    go and the highest no-go, until go/no-go - 1 < ``rel_tol``.

    Returns a dict: ``height_m`` (geometric mean of the final bracket; for a censored search the
    bound), ``lo``, ``hi`` (final no-go and go heights), ``censored`` (None, "below": event at
    h_lo, "above": no event at h_hi), ``evaluations``, ``wall_s``, ``nfev`` (total right-hand-side
    calls), ``exit_cause``, ``event_kinds`` (count per kind).
    """
    t0 = time.perf_counter()
    evals = 0
    nfev = 0
    kinds = {}

    def go(h):
        nonlocal evals, nfev
        r = simulate(inputs, h, rtol=solver_rtol, atol=solver_atol, n_cells=n_cells, **sim_kwargs)
        evals += 1
        nfev += r["nfev"]
        if r["event"]:
            kinds[r["event_kind"]] = kinds.get(r["event_kind"], 0) + 1
        if verbose:
            print(f"  H = {h:.6g} m: {'go' if r['event'] else 'no-go'} "
                  f"({r['event_kind']}, {r['wall_s']:.2f} s, nfev {r['nfev']})", flush=True)
        return r["event"]

    lo, hi = float(h_lo), float(h_hi)
    censored = None
    if go(lo):
        censored, height = "below", lo
    elif not go(hi):
        censored, height = "above", hi
    else:
        while hi / lo - 1.0 >= rel_tol:
            h = math.sqrt(lo * hi)
            if go(h):
                hi = h
            else:
                lo = h
        height = math.sqrt(lo * hi)
    return {
        "height_m": height,
        "lo": lo,
        "hi": hi,
        "censored": censored,
        "evaluations": evals,
        "nfev": nfev,
        "wall_s": time.perf_counter() - t0,
        "exit_cause": _mechanics(inputs)["exit_cause"],
        "event_kinds": kinds,
    }


if __name__ == "__main__":  # pragma: no cover
    import argparse

    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--preset", choices=("quartz", "alumina"), default="quartz")
    p.add_argument("--rtol", type=float, default=1e-5)
    p.add_argument("--n-cells", type=int, default=80)
    p.add_argument("--rel-tol", type=float, default=1e-3)
    p.add_argument("--melt-width", type=float, default=0.0)
    p.add_argument("--jacobian", choices=("analytic", "sparsity"), default="analytic")
    p.add_argument("-v", "--verbose", action="store_true")
    a = p.parse_args()
    inp = QUARTZ if a.preset == "quartz" else ALUMINA_SMOOTH
    res = critical_height(inp, rel_tol=a.rel_tol, solver_rtol=a.rtol, n_cells=a.n_cells,
                          melt_width=a.melt_width, jacobian=a.jacobian, verbose=a.verbose)
    print(res, f"({res['height_m'] / 0.3048:.4g} ft)")
