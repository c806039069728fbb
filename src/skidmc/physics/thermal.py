"""Reactive heat conduction in two media joined at a sliding interface (report II.E).

Compiled kernels in SI units. The HE (medium 1) and the target (medium 2) each get
their own cell-centred finite-volume mesh, geometrically stretched away from the
interface where the frictional flux q(t) enters (report Eqs. 11-16):

* the interface temperature T_b is eliminated exactly as in Eq. (16): with face
  conductances g = 2 k / (first cell width) on each side, q splits between the two
  first cells in proportion g_1 : g_2 and the two cells exchange heat through the
  series conductance g_1 g_2 / (g_1 + g_2);
* the HE obeys Eq. (11) with first-order Arrhenius decomposition,
  dy/dt = Z exp(-T_a / T) (1 - y), heat release rho Q dy/dt (Eq. 13), and melts at
  T_m with latent heat L through an enthalpy formulation (the cell's volumetric
  enthalpy h is the unknown; T(h) is piecewise linear with a plateau at T_m);
* the target obeys Eq. (12); far ends are insulated (they lie many diffusion
  lengths away). Or, with ``n_target = 0`` and a target effusivity e > 0, the target is the
  exact semi-infinite solid of Eq. (12): its surface temperature is Duhamel's integral
  T_b - T0 = 1/(e sqrt(pi)) int_0^t q_t(tau) / sqrt(t - tau) dtau of the flux q_t it takes,
  integrated exactly for q_t piecewise linear on the accepted steps (product integration),
  and eliminating T_b with the first HE cell's half-cell conductance leaves a Robin
  condition on that cell (:func:`_duhamel_history`);

Time stepping is the variable-step, L-stable BDF2 method with Newton iterations on
the (tridiagonal) system and a local-error step controller. The fraction reacted is
updated implicitly in closed form inside each Newton iteration, which keeps the
source bounded however stiff the reaction gets.

Thermal runaway is detected robustly instead of being integrated to the end: once
the hottest HE cell passes the *runaway temperature* T_run, at which the adiabatic
(Frank-Kamenetskii) induction time is a fixed small fraction of the contact time,
nothing can quench it within the contact, and the event time is taken as the
crossing time plus that induction time. The report's own criterion (fraction reacted
above 0.99 in any cell) is checked too and ends the run if it comes first.

Runs of one model at nearby heights can share their start (``prefix``, :data:`PREFIX_MAX_SCALE`):
while the HE is cold and far below its melting step the discrete equations are linear in
T - T0 and the flux scales with sqrt(H), so one run's recorded start, scaled, serves the others.

The kernel takes its scalar inputs as one record and writes its outcome into another
(:mod:`skidmc.physics.records`: ``KERNEL_INPUT``, ``KERNEL_OUTPUT``); its body,
:func:`simulate_core`, is a sequence of steps inlined into it (docs/architecture.md, "The
thermal kernel").
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from skidmc.physics.records import (
    HISTORY_QL,
    HISTORY_QR,
    HISTORY_ROWS,
    HISTORY_T,
    HISTORY_WORK,
    KERNEL_INPUT,
    KERNEL_OUTPUT,
    STATE_CP,
    STATE_DP,
    STATE_H,
    STATE_H_NEW,
    STATE_H_PREV,
    STATE_HIST_H,
    STATE_HIST_Y,
    STATE_ROWS,
    STATE_TEMP,
    STATE_TEMP_NEW,
    STATE_TEMP_PREV,
    STATE_TEMP_PREV2,
    STATE_Y,
    STATE_Y_NEW,
    STATE_Y_PREV,
)

__all__ = [
    "COLD_SOURCE_FRACTION",
    "DEFAULT_RUNAWAY_FRACTION",
    "FREEZE_WIDTH_AFTER",
    "KERNEL_INPUT",
    "KERNEL_OUTPUT",
    "MELT_SPREAD",
    "NEWTON_TOLERANCE_FRACTION",
    "RETRY_SAFETY",
    "SIGN_COMMIT_FRACTION",
    "SIGN_COMMIT_GUARD",
    "SIGN_COMMIT_HEATING",
    "STEP_SAFETY",
    "HISTORY_CAPACITY",
    "PREFIX_MAX_SCALE",
    "PREFIX_STEPS",
    "PREFIX_WRITE",
    "PREFIX_RESUME",
    "prefix_melt_z",
    "prefix_size",
    "adiabatic_induction_time",
    "runaway_temperature",
    "simulate_core",
    "simulate_kernel",
]

# Ratio LTE / (corrector - quadratic predictor) of BDF2 at constant step:
# BDF2 error -(2/9) h^3 y''', predictor error +h^3 y''' -> 2/11.
_BDF2_ERROR_CONSTANT = 2.0 / 11.0

#: Default runaway rule: the event is declared when the hottest cell's adiabatic
#: induction time falls below this fraction of the exit time (:func:`runaway_temperature`).
#: tests/test_solver.py shows that moving it by decades moves the critical height
#: by far less than rtol.
DEFAULT_RUNAWAY_FRACTION = 1e-5

#: Newton's iterations stop when the largest temperature update falls below this fraction
#: of the step's error tolerance. Newton converges quadratically here, so the error left
#: is far below the update: 0.1 (was 0.01) moved the event time of the report presets by
#: < 2e-5 relative at level 0 (1e-4 for gold next to its fold, against a level-0
#: discretisation error of ~1e-2), < 5e-6 at level 1.5 and < 1e-7 at level 2.5, and saves
#: 10-18 % of the Newton iterations (3.1 -> 2.6 per step at level 1.5).
#: From the second iteration on, the iterate kept is the one the converged iteration was
#: assembled at, not the one after its (small) update: the step's final state is computed in
#: that same pass instead of a pass of its own, ~12 % of a simulation's time (13 scenes at
#: levels 0.5 and 1.5, best of 5, 42 against 48 ms). Its error is below this fraction of the
#: step tolerance per step and of one sign (the update is upward while the HE heats): the
#: margin moved by +1-3e-4 at level 0.5 (worst 4.9e-4), +3-8e-5 at level 1.5 and +1e-5 at level
#: 2.5 (later events), on 13 scenes at 0.98 and 1.02 H_c: falling with the level like the
#: level's own error (~4e-3, 1e-3, 2.5e-4), which Richardson's extrapolation and the a
#: posteriori estimate take in with it. 0.03 halved the mean shift but gave back half the gain.
NEWTON_TOLERANCE_FRACTION = 0.1

#: Newton failures in one run after which the first HE cell's spread melting width is frozen
#: for the rest of the run (exact target only; see ``frozen_width`` in :func:`simulate_core`).
#: Over 8,800 runs (the presets, the off-preset scenes of ``benchmarks/solver.py`` and half of
#: ``scripts/fast_tier_error.py``'s training set, levels 0-1.5, both targets, with and without
#: the spread, at 0.97-1.03 H_c) a run had at most 18; the two runs that stalled had 933 and 940
#: after 3,000 attempts.
FREEZE_WIDTH_AFTER = 40

#: The commit rule of a run that needs only its sign (``sign_commit_fraction`` of
#: :func:`simulate_kernel`; docs/model.md, "Sign-only go runs end at the commit temperature"):
#: it is a go once its hottest HE cell passes the temperature where the adiabatic induction
#: time is SIGN_COMMIT_FRACTION of the exit time, heating at least SIGN_COMMIT_HEATING of the
#: adiabatic rate over that step, by (1 - SIGN_COMMIT_GUARD SIGN_COMMIT_FRACTION) t_exit.
#: The plain runaway rule (DEFAULT_RUNAWAY_FRACTION) would take 8-13 % more attempts on a go
#: run to get there. No-go runs next to a jump's root peak at the fold and cool, their
#: induction time at the peak at least 8.6e-4 of t_exit (median 4.6e-3) over the 864 scenes of
#: ``scripts/sign_commit.py`` (levels 0-1.5): 3e-4 lies 2.9x below the lowest. On its 68,320
#: runs next to the roots, no sign differs from the plain rule's; nor with the fraction alone
#: (heating 0), nor with the heating guard alone at 1e-3 (604 of the scenes); at 3e-2 both
#: guards together flip the stops-sliding scenes of ``benchmarks/solver.py``.
SIGN_COMMIT_FRACTION = 3e-4
SIGN_COMMIT_GUARD = 10.0
SIGN_COMMIT_HEATING = 0.5

#: Reaction sources are skipped in cells too cold to release this fraction of the step
#: tolerance [1] over the whole run (see ``t_cold`` in the kernel).
COLD_SOURCE_FRACTION = 1e-3

#: Step-size controller: the next step is STEP_SAFETY * (tol / err)^(1/3) times the last
#: (growth capped at 2, within BDF2's variable-step zero-stability bound 1 + sqrt(2)); after
#: a rejection the retry uses RETRY_SAFETY instead. Measured at level 1.5 on the report
#: presets: 0.8 / 0.7 (was 0.9 / 0.9) cut the rejected steps from ~32 % to ~7-14 % of the
#: attempts and the Newton iterations per simulation by 15-21 %.
STEP_SAFETY = 0.8
RETRY_SAFETY = 0.7


#: Spread of each HE cell's melting step, as a multiple of the cell's temperature range, that
#: the default search uses (:func:`_he_cell_enthalpy`; ``melt_spread=0`` keeps one fixed width
#: w, as forced plans do). At level 1.5 at the critical height of the report presets
#: (benchmarks/cost_breakdown.py): 0.5 leaves ~320 steps + ~30 rejected, 1.0 ~195 + 5 (an
#: inert run ~150), against 600-780 + 110-150 with a fixed 1 K step; 2.0 failed to converge on
#: paper-gold. Its error and how the search's estimate covers it: docs/model.md, "Melting
#: spread over a cell".
MELT_SPREAD = 1.0
# When a melting step counts as settled. An HE cell's melt fraction is
# phi(z) = (1 + tanh z) / 2 with z = (T - T_m) / W (W the step's width, :func:`_he_enthalpy`,
# :func:`_he_cell_enthalpy`); the latent heat a cell at z < 0 already holds, or at z > 0 still
# lacks, is rho L e^(-2 |z|) / (1 + e^(-2 |z|)), i.e. L e^(-2 |z|) / c [K] of temperature. Two
# different questions are asked of that one quantity, so two thresholds answer them:
#
# * Whether the kernel may *compute* the cell as settled (the step's limit, fully melted or
#   solid, instead of the exponential): a fixed |z| beyond which the heat left out is far
#   below any level's step tolerance, :data:`_SETTLED_Z` = 12 for the spread step
#   (e^(-24) L / c ~ 1e-8 K for HMX, four decades below level 4's tolerance of 1.2e-4 K;
#   with W spread over the cells' temperature ranges, 10-20 K near the front, a cutoff at 20
#   evaluated the exponential over +-400 K) and 20 for the fixed step of :func:`_he_enthalpy`
#   (1 - tanh 20 = 8e-18: the limit to double precision). It is part of the arithmetic of
#   every run.
# * Whether a *recorded state* still counts as linear in T - T0 for the linear prefix
#   (:func:`_linear_at_scale`): the heat its step holds must stay below
#   :data:`COLD_SOURCE_FRACTION` of the run's step tolerance, the criterion ``t_cold`` applies
#   to the reaction, so the threshold follows the tolerance: :func:`prefix_melt_z`,
#   z < 0.5 ln(COLD_SOURCE_FRACTION tol c / L) (-6.4 at level 0 to -10.5 at level 4 for
#   HMX). It decides how far a prefix reaches, never how a step is computed.
#
# One threshold for both would change results: -_SETTLED_Z for the prefix ends every prefix
# earlier (later runs resume fewer steps, and a resumed run's margin differs from its own run's
# by the step sequence's error, LinearPrefix), and the tolerance-derived value as the
# computing cutoff changes the enthalpy of every cell with |z| between it and 12.
_SETTLED_Z = 12.0

#: Accepted steps whose target flux :func:`simulate_kernel` first makes room for with the exact
#: target (the history of Duhamel's integral); a run that needs more is run again with room for
#: ``max_steps`` (paper-quartz at 0.99-1.01 H_c: ~200 steps at level 1.5, ~700 at level 3).
HISTORY_CAPACITY = 4096


#: The linear prefix (``prefix`` of :func:`simulate_core`; docs/model.md, "Runs of one search
#: share their linear start"). Until the hottest HE cell nears the cold-source cutoff (t_cold)
#: and every HE cell lies far below the melting step, the discrete equations are linear in
#: T - T0, and the flux of a model is q0(H) times a shape that does not depend on the height:
#: a run at another height is the recorded one with T - T0 and the target's flux history
#: scaled by the ratio of the flux amplitudes, a = q0 / q0_ref, on the recorded run's steps. A
#: prefix is taken over for 1 / PREFIX_MAX_SCALE <= a <= PREFIX_MAX_SCALE (heights within a
#: factor 1.1025 of the recorded one); each of its states stays in the linear regime at a up to
#: PREFIX_MAX_SCALE. The recorded steps met the tolerance at a = 1; at a their local errors are
#: a times theirs: at most 5 % above the tolerance.
PREFIX_MAX_SCALE = 1.05
#: Most accepted steps a prefix holds (the linear start takes ~25-50 at levels 0.5-1.5).
PREFIX_STEPS = 160
#: ``prefix_mode`` of the kernel's input record (:func:`simulate_kernel`): record the run's
#: linear start into ``prefix``, or resume from the one it holds (0: neither).
PREFIX_WRITE = 1
PREFIX_RESUME = 2
_NO_PREFIX = np.zeros(0)   # simulate_kernel's default: no prefix
# Header of a prefix array: validity, the recording run's q0, its state's scalars and the
# settings a resumed run must share with it.
_PX_VALID, _PX_Q0, _PX_T, _PX_DT, _PX_DT_PREV, _PX_DT_PREV2, _PX_N_HIST, _PX_STEPS = range(8)
_PX_Q_T_LAST, _PX_T_MAX, _PX_N, _PX_TOL, _PX_T_EXIT, _PX_T0, _PX_Q_EXT = range(8, 15)
_PX_HEADER = 16


#: Compilation options of this module's kernels. ``error_model="numpy"``: a division by zero
#: gives inf or nan (which the integrator's finiteness checks reject) instead of a Python
#: exception, so no division carries a zero test. ``fastmath={"contract"}``: LLVM may fuse a
#: multiply and an add into one fused multiply-add (one rounding instead of two; no other
#: fast-math assumption, so the inf and nan checks stay exact). Together 1.15x faster per
#: simulation, measured side by side (docs/model.md, "Compiled kernels").
_JIT = dict(cache=True, error_model="numpy", fastmath={"contract"})


@njit(**_JIT)
def prefix_size(n):
    """Length of a prefix array for a mesh of ``n`` cells (:func:`simulate_core`)."""
    return _PX_HEADER + 3 * n + 3 * PREFIX_STEPS + 1


@njit(**_JIT, inline="always")
def prefix_melt_z(tol_temperature, rho_c, latent_v):
    """The largest z = (T - T_m) / W [1] of an HE cell in a linear prefix's state: the latent
    heat its melting step holds, L e^(2 z) / c [K], is :data:`COLD_SOURCE_FRACTION` of the step
    tolerance ``tol_temperature`` [K] there (``rho_c`` [J/(m^3 K)], ``latent_v`` = rho L
    [J/m^3] > 0; the comment block above :data:`_SETTLED_Z` says why this is not that
    threshold)."""
    return 0.5 * math.log(COLD_SOURCE_FRACTION * tol_temperature * rho_c / latent_v)


@njit(**_JIT, inline="always")
def _contact_flux(t, q0, s, c, w):
    """Frictional flux during the contact [W/m^2]: q0 max(s - c (1 - cos w t), 0) (Eq. 10)."""
    v = s - c * (1.0 - math.cos(w * t))
    return q0 * v if v > 0.0 else 0.0


@njit(**_JIT, inline="always")
def _flux(t, q0, s, c, w, t_exit, q_ext):
    """Frictional flux q(t) [W/m^2]: :func:`_contact_flux` on [0, t_exit), then q_ext."""
    if t < t_exit:
        return _contact_flux(t, q0, s, c, w)
    return q_ext


@njit(**_JIT, inline="always")
def _he_enthalpy(temperature, rho_c, latent_v, melting_point, melt_width):
    """Volumetric enthalpy h [J/m^3] of an HE cell and its derivative dh/dT [J/(m^3 K)].

    h = rho c T + rho L phi(T), with melt fraction phi = (1 + tanh((T - T_m)/w)) / 2:
    the latent heat is released smoothly over a few widths ``melt_width`` = w [K]
    around T_m. The width is a discretisation parameter that shrinks with the
    resolution level (sharp Stefan melting is the limit w -> 0); a smooth enthalpy
    keeps the BDF2 error control from resolving every cell's melting kink.
    """
    if latent_v <= 0.0:
        return rho_c * temperature, rho_c
    inv_width = 1.0 / melt_width
    z = (temperature - melting_point) * inv_width
    if z > 20.0:   # 1 - tanh(20) = 8e-18: melted, to double precision
        return rho_c * temperature + latent_v, rho_c
    if z < -20.0:
        return rho_c * temperature, rho_c
    # (1 + tanh z) / 2 = e / (1 + e) and (1 - tanh^2 z) / 2 = 2 e / (1 + e)^2 with e = exp(2 z):
    # the same function as tanh, at a third of libm tanh's cost (it is evaluated for every
    # HE cell near T_m in every Newton iteration).
    e = math.exp(2.0 * z)
    inv = 1.0 / (1.0 + e)
    return (rho_c * temperature + latent_v * e * inv,
            rho_c + 2.0 * latent_v * e * inv * inv * inv_width)


@njit(**_JIT, inline="always")
def _first_cell_range(temp, width):
    """The first HE cell's temperature difference across it [K] and its width over the span
    of that difference [1], with the exact target (n_target = 0): no cell lies below it, so the
    range comes from the one-sided difference to the next cell (centres 0.5 (w_0 + w_1) apart).
    """
    return temp[1] - temp[0], width[0] / (0.5 * width[0] + 0.5 * width[1])


@njit(**_JIT, inline="always")
def _spread_width(diff, ratio, melt_width, melt_spread):
    """The spread s |diff| ratio [K] of a cell's melting step and the step's width
    W = sqrt(w^2 + spread^2) [K] (:func:`_he_cell_enthalpy`)."""
    spread = melt_spread * abs(diff) * ratio
    return spread, math.sqrt(melt_width * melt_width + spread * spread)


@njit(**_JIT, inline="always")
def _he_cell_enthalpy(i, n, n_target, temp, width, rho_c, latent_v, melting_point, melt_width,
                      melt_spread, frozen_width=0.0):
    """Enthalpy [J/m^3] of HE cell ``i`` with its melting spread over the cell's own range.

    A melting front crosses a cell in the time the temperature profile takes to sweep the
    cell's temperature range dT_i (the cell width times the local gradient). With a step of
    fixed width w << dT_i the cell instead sits on a plateau at T_m until its whole latent heat
    is in, and then jumps on: every crossing kinks the histories of the cell and its
    neighbours, and the step controller resolves each kink (6-10x an inert run's steps at
    w = 1 K). With ``melt_spread`` = s > 0 the step's width is W_i = sqrt(w^2 + (s dT_i)^2), dT_i
    from the centred difference of the two neighbours (across the interface for the first HE
    cell: T is continuous there); the melt fraction then follows the front across the cell,
    as the linear profile inside it would. W_i -> w as the mesh is refined (dT_i ~ cell
    width), so the spreading is a discretisation error and converges with the levels, but not
    as cleanly second order as the fixed step (docs/model.md, "Melting spread over a cell").
    s = 0 is the fixed step of :func:`_he_enthalpy`, to the last bit. ``frozen_width`` > 0 [K]
    replaces the first cell's (``i`` = 0, the exact target's) spread width by that fixed one (the
    kernel's fallback where that cell's enthalpy folds; :func:`simulate_core`).

    Returns
    -------
    h, dh_dself, dh_dlow, dh_dup : float
        Enthalpy [J/m^3] and its derivatives [J/(m^3 K)] with respect to the temperatures of
        cell ``i`` and of its neighbours ``i - 1`` and ``i + 1`` (for Newton's Jacobian).
    """
    rc = rho_c[i]
    t_i = temp[i]
    if latent_v <= 0.0:
        return rc * t_i, rc, 0.0, 0.0
    if melt_spread <= 0.0 or i == n - 1:   # (the deepest cell has no neighbour beyond it)
        h, dh = _he_enthalpy(t_i, rc, latent_v, melting_point, melt_width)
        return h, dh, 0.0, 0.0
    if i == 0:
        if frozen_width > 0.0:
            h, dh = _he_enthalpy(t_i, rc, latent_v, melting_point, frozen_width)
            return h, dh, 0.0, 0.0
        diff, ratio = _first_cell_range(temp, width)
    else:
        diff = temp[i + 1] - temp[i - 1]
        ratio = width[i] / (0.5 * width[i - 1] + width[i] + 0.5 * width[i + 1])
    deviation = t_i - melting_point
    # Settled cells (melted or solid) skip the square root and exponential. W <= w + spread
    # and spread <= s |diff| (a cell is narrower than its neighbours' centres
    # are apart), so |deviation| > _SETTLED_Z (w + spread) puts |z| above it.
    if abs(deviation) > _SETTLED_Z * (melt_width + melt_spread * abs(diff)):
        return rc * t_i + (latent_v if deviation > 0.0 else 0.0), rc, 0.0, 0.0
    spread, step_width = _spread_width(diff, ratio, melt_width, melt_spread)
    z = deviation / step_width
    if abs(z) > _SETTLED_Z:
        return rc * t_i + (latent_v if z > 0.0 else 0.0), rc, 0.0, 0.0
    h, dh = _he_enthalpy(t_i, rc, latent_v, melting_point, step_width)
    # dh/dT_up = rho L phi'(z) dz/dW dW/dspread dspread/dT_up with rho L phi'(z) = (dh - rho c) W
    # and dz/dW = -z / W; dh/dT_low = -dh/dT_up.
    d_up = (-(dh - rc) * z * (melt_spread * spread / step_width) * ratio
            * (1.0 if diff >= 0.0 else -1.0))
    if i == 0:
        return h, dh - d_up, 0.0, d_up
    return h, dh, -d_up, d_up


@njit(**_JIT, inline="always")
def _local_error(i, temp_new, temp, temp_prev, temp_prev2, dt, inv_dt1, inv_dt0, c2):
    """BDF2's local error estimate [K] in cell ``i``: the corrector ``temp_new`` minus the
    quadratic extrapolation through the last three accepted temperatures (Newton divided
    differences; ``inv_dt1``, ``inv_dt0`` the inverse last two steps [1/s], ``c2`` the
    extrapolation's second-difference weight [s]), times the error constant."""
    d1 = (temp[i] - temp_prev[i]) * inv_dt1
    d0 = (temp_prev[i] - temp_prev2[i]) * inv_dt0
    pred = temp[i] + dt * d1 + c2 * (d1 - d0)
    return abs(temp_new[i] - pred) * _BDF2_ERROR_CONSTANT


@njit(**_JIT, inline="always")
def _duhamel_history(t_new, hist_t, hist_ql, hist_qr, work, n_intervals):
    """int_0^{t_n} q_t(tau) / sqrt(t_new - tau) dtau [W s^0.5 / m^2] over the accepted steps.

    ``hist_t[j]`` (j = 0 .. n_intervals) are the accepted times [s], q_t is linear on each
    interval [t_j, t_j+1] from ``hist_ql[j]`` to ``hist_qr[j]`` [W/m^2]; ``work`` is scratch of
    at least n_intervals + 1. With u = sqrt(t_new - t_j+1) and v = sqrt(t_new - t_j) the
    interval's integral is exact: d (2 q_r + (2/3) (q_l - q_r) d (v + 2u) / dt_j) with
    d = v - u = dt_j / (u + v) (no cancellation however old the interval). One square root per
    interval, in a loop LLVM vectorises: ~1.5 ns per interval on this project's machine.
    """
    for j in range(n_intervals + 1):
        work[j] = math.sqrt(t_new - hist_t[j])
    total = 0.0
    for j in range(n_intervals):
        v = work[j]
        u = work[j + 1]
        width = hist_t[j + 1] - hist_t[j]
        inv_sum = 1.0 / (u + v)
        d = width * inv_sum
        total += d * (2.0 * hist_qr[j] + (2.0 / 3.0) * (hist_ql[j] - hist_qr[j])
                      * (v + 2.0 * u) * inv_sum)
    return total


@njit(**_JIT)
def _linear_at_scale(temp, width, n, n_target, initial_temperature, scale, reactive, t_cold,
                     latent_v, melting_point, melt_width, melt_spread, melt_z):
    """Whether the state ``temp`` [K], with T - T0 scaled by ``scale``, leaves every HE cell in
    the kernel's linear regime [bool]: below the cold-source cutoff ``t_cold`` (no reaction
    source) and with its melting step's z = (T - T_m) / W (W spread over the scaled neighbour
    difference, as :func:`_he_cell_enthalpy` takes it) below ``melt_z``."""
    for i in range(n_target, n):
        scaled = initial_temperature + scale * (temp[i] - initial_temperature)
        if reactive and scaled >= t_cold:
            return False
        if latent_v > 0.0:
            step_width = melt_width
            if melt_spread > 0.0 and i < n - 1:
                if i == 0:
                    diff, ratio = _first_cell_range(temp, width)
                else:
                    diff = temp[i + 1] - temp[i - 1]
                    ratio = width[i] / (0.5 * width[i - 1] + width[i] + 0.5 * width[i + 1])
                _, step_width = _spread_width(scale * diff, ratio, melt_width, melt_spread)
            if (scaled - melting_point) / step_width > melt_z:
                return False
    return True


@njit(**_JIT)
def _record_prefix(prefix, n, temp, temp_prev, temp_prev2, hist_t, hist_ql, hist_qr,
                   exact_target, q0, t, dt, dt_prev, dt_prev2, n_hist, steps, q_t_last,
                   t_max, tol_temperature, t_exit, initial_temperature, q_ext):
    """Write an accepted state and what a resumed run must match into ``prefix``.

    Called on every accepted step from the first (:func:`simulate_core`), and the exact
    target's flux history only grows: only the newest step's entries of it are copied.
    """
    base = _PX_HEADER
    for i in range(n):
        prefix[base + i] = temp[i]
        prefix[base + n + i] = temp_prev[i]
        prefix[base + 2 * n + i] = temp_prev2[i]
    if exact_target:
        base = _PX_HEADER + 3 * n
        if steps == 1:
            prefix[base] = hist_t[0]
        prefix[base + steps] = hist_t[steps]
        prefix[base + PREFIX_STEPS + steps] = hist_ql[steps - 1]
        prefix[base + 2 * PREFIX_STEPS + steps] = hist_qr[steps - 1]
    prefix[_PX_Q0] = q0
    prefix[_PX_T] = t
    prefix[_PX_DT] = dt
    prefix[_PX_DT_PREV] = dt_prev
    prefix[_PX_DT_PREV2] = dt_prev2
    prefix[_PX_N_HIST] = n_hist
    prefix[_PX_STEPS] = steps
    prefix[_PX_Q_T_LAST] = q_t_last
    prefix[_PX_T_MAX] = t_max
    prefix[_PX_N] = n
    prefix[_PX_TOL] = tol_temperature
    prefix[_PX_T_EXIT] = t_exit
    prefix[_PX_T0] = initial_temperature
    prefix[_PX_Q_EXT] = q_ext
    prefix[_PX_VALID] = 1.0


@njit(**_JIT, inline="always")
def target_properties(temperature, table, m):
    """A temperature-dependent target's properties at ``temperature`` [K].

    ``table`` holds ``m`` >= 2 nodes as four rows: temperatures T_j [K] (increasing),
    conductivities k_j [W/(m K)], volumetric heat capacities C_j = rho c_j [J/(m^3 K)] and
    enthalpies H_j = int_{T_0}^{T_j} C dT [J/m^3]. k and C are linear in T between nodes and
    constant beyond the ends, so H, their exact integral, is piecewise quadratic (linear beyond
    the ends): the target's energy is conserved by construction.

    Returns
    -------
    k, dk_dT, C, H : float
        [W/(m K)], [W/(m K^2)], [J/(m^3 K)], [J/m^3].
    """
    if temperature <= table[0]:
        c = table[2 * m]
        return table[m], 0.0, c, table[3 * m] + c * (temperature - table[0])
    if temperature >= table[m - 1]:
        c = table[3 * m - 1]
        return table[2 * m - 1], 0.0, c, table[4 * m - 1] + c * (temperature - table[m - 1])
    j = 0
    while temperature > table[j + 1]:
        j += 1
    dt = temperature - table[j]
    inv_span = 1.0 / (table[j + 1] - table[j])
    slope_k = (table[m + j + 1] - table[m + j]) * inv_span
    slope_c = (table[2 * m + j + 1] - table[2 * m + j]) * inv_span
    c0 = table[2 * m + j]
    return (table[m + j] + slope_k * dt, slope_k, c0 + slope_c * dt,
            table[3 * m + j] + dt * (c0 + 0.5 * slope_c * dt))


@njit(**_JIT)
def runaway_temperature(prefactor, activation_temperature, adiabatic_rise, time_scale,
                        fraction):
    """Temperature [K] at which the adiabatic induction time equals ``fraction * time_scale``.

    The Frank-Kamenetskii adiabatic induction time of first-order kinetics is
    tau(T) = T^2 / (T_a * dT_ad * Z exp(-T_a / T)), with dT_ad = Q / c the adiabatic
    temperature rise. Solved by bisection on ln tau, which decreases monotonically
    in T for T < T_a / 2.
    """
    target = math.log(fraction * time_scale)
    lo = 1.0
    hi = 0.5 * activation_temperature
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        ln_tau = (2.0 * math.log(mid) - math.log(activation_temperature * adiabatic_rise)
                  - math.log(prefactor) + activation_temperature / mid)
        if ln_tau > target:
            lo = mid
        else:
            hi = mid
        if hi - lo < 1e-9 * hi:
            break
    return 0.5 * (lo + hi)


@njit(**_JIT)
def adiabatic_induction_time(temperature, prefactor, activation_temperature, adiabatic_rise):
    """Frank-Kamenetskii adiabatic induction time [s] at ``temperature`` [K]."""
    return temperature**2 / (activation_temperature * adiabatic_rise * prefactor
                             * math.exp(-activation_temperature / temperature))


@njit(**_JIT, nogil=True)
def simulate_kernel(width, rho_c, face_conductance, inputs, record_t=_NO_PREFIX,
                    record_tb=_NO_PREFIX, prefix=_NO_PREFIX, target_table=_NO_PREFIX):
    """Integrate one impact from t = 0 to an event or ``t_stop``.

    Parameters
    ----------
    width : ndarray, shape (n,)
        Cell widths [m], ordered from the deep target (index 0) to the interface
        (``n_target - 1`` | ``n_target``) to the deep HE (``n - 1``).
    rho_c : ndarray, shape (n,)
        Volumetric heat capacity of each cell [J/(m^3 K)].
    face_conductance : ndarray, shape (n - 1,)
        Conductance of the face between cells i and i+1 [W/(m^2 K)]; at the
        interface, the series conductance g_1 g_2 / (g_1 + g_2) of Eq. (16).
    inputs : ndarray, shape (1,), dtype :data:`~skidmc.physics.records.KERNEL_INPUT`
        The run's scalar inputs (:func:`skidmc.physics.records.kernel_input`;
        :func:`skidmc.solver.simulate.kernel_arguments` builds them for a model):

        ``n``, ``n_target`` : int
            Cells (``width.shape[0]``) and target cells; HE cells are ``n_target .. n-1``.
            ``n_target`` 0 with ``target_effusivity`` > 0: the target is the exact
            semi-infinite solid (Duhamel's integral; the arrays then hold the HE's cells and
            faces alone).
        ``q_share_he`` : float
            Fraction of the interface flux entering the first HE cell, g_1/(g_1+g_2) [1]
            (unused with the exact target).
        ``he_density`` : float
            HE density [kg/m^3].
        ``latent_heat`` : float
            Heat of fusion L [J/kg]; 0 disables melting.
        ``melting_point``, ``melt_width`` : float
            T_m [K] and the width w [K] over which the latent heat is released.
        ``melt_spread`` : float
            0: the fixed width w. s > 0: each HE cell's step widened to sqrt(w^2 + (s dT_i)^2)
            with its temperature range dT_i (:func:`_he_cell_enthalpy`, :data:`MELT_SPREAD`)
            [1].
        ``prefactor``, ``activation_temperature``, ``heat_of_reaction`` : float
            Z [1/s], T_a = E/R [K], Q [J/kg]; Z = 0 makes the HE inert.
        ``q0``, ``slide_s``, ``slide_c``, ``omega``, ``t_exit``, ``q_ext`` : float
            Flux q(t) = q0 (s - c (1 - cos omega t)) [W/m^2] before ``t_exit`` [s]
            (Eqs. 1 and 10, q0 = mu sigma V0), ``q_ext`` [W/m^2] after it.
        ``t_end`` : float
            End of the model's horizon [s]: of the integration, unless ``t_stop`` is earlier.
        ``t_stop`` : float
            Where the integration stops without an event [s], t_exit <= t_stop <= t_end: a
            run that needs only the margin's sign (go or no-go) stops at t_exit. The run up to
            it is the same as the full run's, step for step (``t_end`` still sets the
            cold-source cutoff).
        ``initial_temperature`` : float
            T0 [K].
        ``tol_temperature`` : float
            Local error tolerance of the step controller [K].
        ``dt_initial`` : float
            First time step [s] (also after the flux jumps at ``t_exit``).
        ``runaway_fraction`` : float
            Runaway is declared when the hottest cell's adiabatic induction time falls below
            ``runaway_fraction * t_exit``; 0 disables the rule and only the report's
            y > 0.99 criterion ends the run.
        ``max_steps`` : int
            Cap on accepted plus rejected steps.
        ``n_record`` : int
            How many steps to record in ``record_t``, ``record_tb`` (at most their length;
            0: none).
        ``target_effusivity`` : float
            sqrt(k rho c) of the target [W s^0.5 / (m^2 K)] for the exact target
            (``n_target`` 0); 0 with a meshed target.
        ``he_conductivity`` : float
            k of the HE [W/(m K)]: the first HE cell's half-cell conductance to the
            interface, with the exact target.
        ``sign_commit_fraction`` : float
            0: the runaway rule alone declares an event. > ``runaway_fraction``: a run that
            needs only its sign (``t_stop`` at the exit) is a go once its hottest cell's
            adiabatic induction time falls below this fraction of ``t_exit`` while it heats at
            :data:`SIGN_COMMIT_HEATING` of the adiabatic rate, by (1 -
            :data:`SIGN_COMMIT_GUARD` x this fraction) ``t_exit``; its event time is then the
            crossing plus that induction time, an early estimate (:data:`SIGN_COMMIT_FRACTION`).
        ``prefix_mode`` : int
            What the run does with ``prefix``: 0 nothing, :data:`PREFIX_WRITE` record its
            linear start there (or mark it invalid), :data:`PREFIX_RESUME` start from the one
            recorded, scaled to its own flux, where that applies (same mesh, tolerance, exit
            time, T0 and flux shape, flux amplitude within PREFIX_MAX_SCALE, nothing
            recorded), else from t = 0.
        ``n_table`` : int
            Nodes of ``target_table`` (0: constant target properties).
    record_t, record_tb : ndarray
        The time [s] and interface temperature [K] after each accepted step are written there
        (the first ``n_record`` steps).
    prefix : ndarray, shape (prefix_size(n),)
        A linear prefix (:data:`PREFIX_MAX_SCALE`; ``prefix_mode``).
    target_table : ndarray, shape (4 n_table,)
        A meshed target's temperature-dependent properties (:func:`target_properties`):
        temperatures [K], conductivities [W/(m K)], volumetric heat capacities [J/(m^3 K)] and
        volumetric enthalpies [J/m^3] at ``n_table`` nodes, piecewise linear in T between them
        (the enthalpy their exact integral). With ``n_table`` >= 2 every target cell takes
        k(T) and rho c(T) at its own current temperature, inside Newton's iteration (fully
        implicit, with their derivatives in the Jacobian), and the faces between target cells
        and at the interface the half-cell resistances w / (2 k(T)) in series; the target's
        ``rho_c`` and face conductances are then unused, and the linear prefix is off (the
        equations are no longer linear in T - T0). 0: constant properties, the arrays as
        given, to the last bit.

    Returns
    -------
    outputs : ndarray, shape (1,), dtype :data:`~skidmc.physics.records.KERNEL_OUTPUT`
        The run's outcome (the fields of :data:`~skidmc.physics.records.KERNEL_OUTPUT`).
    """
    inp = inputs[0]
    n = inp.n
    exact_target = inp.n_target == 0 and inp.target_effusivity > 0.0
    max_steps = inp.max_steps
    capacity = min(max_steps, HISTORY_CAPACITY) if exact_target else 0
    outputs = np.zeros(1, dtype=KERNEL_OUTPUT)
    while True:
        simulate_core(inp, outputs[0], width, rho_c, face_conductance,
                      np.empty((STATE_ROWS, n)), np.empty((HISTORY_ROWS, capacity + 1)),
                      record_t, record_tb, prefix, target_table)
        if not outputs[0].history_full or capacity >= max_steps:
            return outputs
        capacity = max_steps   # rare (far finer than level 3): run again, with room for every step


# The steps of simulate_core. Each is inlined into it at numba's IR level (inline="always"),
# so the compiled code, and its floating-point arithmetic (fused multiply-adds included), is
# that of one function: the results are those of the one-function kernel, to the last bit.


@njit(**_JIT, inline="always")
def _thresholds(prefactor, activation_temperature, adiabatic_rise, reactive, t_exit, t_end,
                tol_temperature, runaway_fraction, sign_commit_fraction):
    """The temperatures [K] at which a run's rules act, from its kinetics and tolerances.

    Returns
    -------
    t_run, t_commit, commit_by, t_relax, t_cold : float
        Runaway temperature [K] (inf: no rule), the sign-only commit temperature [K] and the
        time it must be passed by [s], the temperature past which step error control is
        dropped [K], and the cold-source cutoff [K] (the comments below say why each).
    """
    if runaway_fraction > 0.0 and reactive and adiabatic_rise > 0.0:
        t_run = runaway_temperature(prefactor, activation_temperature, adiabatic_rise,
                                    t_exit, runaway_fraction)
    else:
        t_run = math.inf
    # A run that needs only its sign is declared a go as soon as its hottest cell passes
    # t_commit, where the adiabatic induction time is sign_commit_fraction of the exit time,
    # heating fast (_event), by commit_by, when that induction time still fits
    # SIGN_COMMIT_GUARD times before the exit: near a smooth margin's root, where the event
    # comes at ~t_exit, the plain rule decides. Past t_commit a go run's event is sure (no
    # no-go run's fold peak came within 2.9x of it, SIGN_COMMIT_FRACTION), so the steps
    # through the rest of the runaway, ~8-13 % of its attempts, are skipped.
    t_commit = math.inf
    commit_by = -math.inf
    if t_run < math.inf and sign_commit_fraction > runaway_fraction:
        t_commit = runaway_temperature(prefactor, activation_temperature, adiabatic_rise,
                                       t_exit, sign_commit_fraction)
        commit_by = t_exit * (1.0 - SIGN_COMMIT_GUARD * sign_commit_fraction)
    # Past t_relax (adiabatic induction time below 1e-9 t_exit) the run is a runaway
    # whatever happens next: the step error control is dropped there, and steps are
    # limited only by Newton's convergence, so that the report's own criterion
    # (y > 0.99) is reached in a few dozen steps instead of stalling. The event time
    # moves by at most ~1e-9 t_exit.
    t_relax = math.inf
    if reactive and adiabatic_rise > 0.0:
        t_relax = runaway_temperature(prefactor, activation_temperature, adiabatic_rise,
                                      t_exit, 1e-9)
    # Below t_cold, the heat a cell's reaction could release over the whole run,
    # dT_ad Z exp(-Ta/T) t_end, is under COLD_SOURCE_FRACTION of the step tolerance [K]: its
    # source (and exponential) is skipped. Measured on the report presets at level 1.5: the
    # event time moves by ~1e-10 relative, the simulation runs ~9 % faster.
    t_cold = 0.0
    if reactive and adiabatic_rise > 0.0:
        t_cold = activation_temperature / math.log(max(
            prefactor * t_end * adiabatic_rise / (COLD_SOURCE_FRACTION * tol_temperature), 2.0))
    return t_run, t_commit, commit_by, t_relax, t_cold


@njit(**_JIT, inline="always")
def _initial_state(n, n_target, initial_temperature, rho_c, latent_v, melting_point,
                   melt_width, tdep, target_table, n_table, temp, temp_prev, temp_prev2, h,
                   h_prev):
    """Every cell at T0 [K], with its enthalpy [J/m^3] (HE: the fixed-width step's)."""
    for i in range(n):
        temp[i] = initial_temperature
        temp_prev[i] = initial_temperature
        temp_prev2[i] = initial_temperature
        if i >= n_target:
            h[i], _ = _he_enthalpy(initial_temperature, rho_c[i], latent_v,
                                   melting_point, melt_width)
        elif tdep:
            _, _, _, h[i] = target_properties(initial_temperature, target_table, n_table)
        else:
            h[i] = rho_c[i] * initial_temperature
        h_prev[i] = h[i]


@njit(**_JIT, inline="always")
def _prefix_scale(prefix, n, n_record, tdep, t_stop, tol_temperature, t_exit,
                  initial_temperature, q0, q_ext, exact_target, capacity):
    """The flux ratio a = q0 / q0_ref [1] a run resumes ``prefix`` at (:data:`PREFIX_RESUME`),
    or 0.0 where the prefix does not apply (see ``prefix_mode`` of :func:`simulate_kernel`)."""
    if (n_record == 0 and prefix.shape[0] >= prefix_size(n)
            and not tdep
            and prefix[_PX_VALID] == 1.0 and prefix[_PX_N] == n and prefix[_PX_T] < t_stop
            and prefix[_PX_TOL] == tol_temperature and prefix[_PX_T_EXIT] == t_exit
            and prefix[_PX_T0] == initial_temperature
            and abs(q_ext * prefix[_PX_Q0] - prefix[_PX_Q_EXT] * q0)
            <= 1e-12 * abs(q0 * prefix[_PX_Q0])
            and (not exact_target or prefix[_PX_STEPS] <= capacity)):
        scale = q0 / prefix[_PX_Q0]
        if 1.0 / PREFIX_MAX_SCALE <= scale <= PREFIX_MAX_SCALE:
            return scale
    return 0.0


@njit(**_JIT, inline="always")
def _resume_prefix(prefix, scale, n, n_target, initial_temperature, width, rho_c, latent_v,
                   melting_point, melt_width, melt_spread, exact_target, temp, temp_prev,
                   temp_prev2, h, h_prev, hist_t, hist_ql, hist_qr):
    """Start from the recorded prefix, T - T0 and the target's flux history scaled by ``scale``.

    Returns
    -------
    t, dt, dt_prev, dt_prev2 : float
        The prefix's time and last step sizes [s].
    n_hist, steps : int
        Its multistep history's length and accepted steps.
    t_max_prev : float
        Its hottest HE cell, scaled [K].
    q_t_last : float
        The exact target's last flux, scaled [W/m^2] (0 with a meshed target).
    """
    base = _PX_HEADER
    for i in range(n):
        temp[i] = initial_temperature + scale * (prefix[base + i] - initial_temperature)
        temp_prev[i] = initial_temperature + scale * (
            prefix[base + n + i] - initial_temperature)
        temp_prev2[i] = initial_temperature + scale * (
            prefix[base + 2 * n + i] - initial_temperature)
    for i in range(n):
        if i >= n_target:
            h[i], _, _, _ = _he_cell_enthalpy(i, n, n_target, temp, width, rho_c,
                                              latent_v, melting_point, melt_width,
                                              melt_spread)
            h_prev[i], _, _, _ = _he_cell_enthalpy(i, n, n_target, temp_prev, width,
                                                   rho_c, latent_v, melting_point,
                                                   melt_width, melt_spread)
        else:
            h[i] = rho_c[i] * temp[i]
            h_prev[i] = rho_c[i] * temp_prev[i]
    t = prefix[_PX_T]
    dt = prefix[_PX_DT]
    dt_prev = prefix[_PX_DT_PREV]
    dt_prev2 = prefix[_PX_DT_PREV2]
    n_hist = int(prefix[_PX_N_HIST])
    steps = int(prefix[_PX_STEPS])
    t_max_prev = initial_temperature + scale * (prefix[_PX_T_MAX] - initial_temperature)
    q_t_last = 0.0
    if exact_target:
        q_t_last = scale * prefix[_PX_Q_T_LAST]
        base = _PX_HEADER + 3 * n
        for j in range(steps + 1):
            hist_t[j] = prefix[base + j]
        for j in range(steps):
            hist_ql[j] = scale * prefix[base + PREFIX_STEPS + 1 + j]
            hist_qr[j] = scale * prefix[base + 2 * PREFIX_STEPS + 1 + j]
    return t, dt, dt_prev, dt_prev2, n_hist, steps, t_max_prev, q_t_last


@njit(**_JIT, inline="always")
def _bdf2_coefficients(dt, dt_prev, n_hist):
    """Variable-step BDF2's h_new = a1 h - a2 h_prev + beta dt f(T_new): (a1, a2 [1],
    bdt = beta dt [s], om [1]: the step ratio dt / dt_prev of Newton's linear start, 0 after a
    (re)start of the history, where the step is backward Euler's)."""
    if n_hist == 0:
        a1, a2, beta = 1.0, 0.0, 1.0        # backward Euler start
    else:
        om = dt / dt_prev
        a1 = (1.0 + om) ** 2 / (1.0 + 2.0 * om)
        a2 = om * om / (1.0 + 2.0 * om)
        beta = (1.0 + om) / (1.0 + 2.0 * om)
    bdt = beta * dt
    om = dt / dt_prev if n_hist > 0 else 0.0
    return a1, a2, bdt, om


@njit(**_JIT, inline="always")
def _exact_target_drive(t_new, dt, n_hist, steps, q, q_t_last, g_h, duhamel, bdt,
                        initial_temperature, hist_t, hist_ql, hist_qr, hist_work):
    """The exact target's Robin condition on the first HE cell for the step to ``t_new`` [s]:
    q_h = g_eff (drive - T_he). Returns g_eff [W/(m^2 K)], drive [K] and robin = bdt g_eff
    [J/(m^2 K)]."""
    # Duhamel's integral at t_new: the accepted steps, then this step with q_t linear
    # from the last accepted value (weight 2/3 sqrt(dt)) to the new one (4/3 sqrt(dt));
    # after a (re)start of the history, constant at the new value (2 sqrt(dt)), as the
    # backward-Euler step takes it.
    past = _duhamel_history(t_new, hist_t, hist_ql, hist_qr, hist_work, steps)
    root_dt = math.sqrt(dt)
    if n_hist == 0:
        weight_new = 2.0 * root_dt
    else:
        past += (2.0 / 3.0) * root_dt * q_t_last
        weight_new = (4.0 / 3.0) * root_dt
    g_eff = g_h / (1.0 + duhamel * weight_new * g_h)
    drive = initial_temperature + duhamel * (past + weight_new * q)
    robin = bdt * g_eff
    return g_eff, drive, robin


@njit(**_JIT, inline="always")
def _assemble_and_sweep(final, estimate, err, t_max, y_max, n, n_target, width, rho_c,
                        face_conductance, melting, kinetics, frozen_width, tdep, target_table,
                        n_table, exact_target, g_h, step, temps, rows):
    """One Newton pass: assemble each row of J delta = -R and eliminate it at once.

    R = w (h(T) - hist) - bdt [fluxes + w S(T)] and J tridiagonal, at the iterate
    ``temp_new`` [K]; the Thomas forward sweep's coefficients go to ``cp`` and ``dp`` (the
    update follows by :func:`_back_substitution`). ``melting`` = (rho L [J/m^3], T_m [K], w [K],
    s [1]) and ``kinetics`` = (reactive, t_cold [K], Z [1/s], T_a [K], rho Q [J/m^3]). A
    ``final`` pass also computes the step's final state at the iterate: ``y_new``, and returns
    the hottest HE cell [K], the largest fraction reacted [1] and (with ``estimate``) the
    largest local error [K] (:func:`_local_error`); otherwise it returns ``err``, ``t_max``,
    ``y_max`` as given.

    ``step`` = (bdt [s], q [W/m^2], bdt q into the target and into the HE [J/m^2], the exact
    target's robin [J/(m^2 K)] and drive [K], dt [s], 1 / dt_prev, 1 / dt_prev2 [1/s] and the
    error estimate's weight c2 [s]); ``temps`` = (T_new, T, T_prev, T_prev2) [K]; ``rows`` =
    (h_new, hist_h, y_new, hist_y, cp, dp). (Grouped in tuples: numba inlines a call of at most
    30 arguments.)
    """
    latent_v, melting_point, melt_width, melt_spread = melting
    reactive, t_cold, prefactor, activation_temperature, q_v = kinetics
    bdt, q, q_target, q_he, robin, drive, dt, inv_dt1, inv_dt0, c2 = step
    temp_new, temp, temp_prev, temp_prev2 = temps
    h_new, hist_h, y_new, hist_y, cp, dp = rows
    if final:
        err = 0.0
        t_max = -math.inf
        y_max = 0.0
    # The row's assembly overlaps the division chain of the sweep (one division per row).
    flow_in = 0.0   # bdt * heat into cell i from cell i-1
    g_low = 0.0     # bdt * conductance of the face below cell i
    cp_prev = 0.0
    dp_prev = 0.0
    if tdep:
        # The temperature-dependent target: each cell's properties at its current
        # temperature, carried from the row that needed them first (the face below).
        tk_next, tdk_next, tc_next, th_next = target_properties(
            temp_new[0], target_table, n_table)
        jac_low_self = 0.0    # d(flow in from below)/dT_i beyond the conductance
        jac_low_other = 0.0   # d(flow in from below)/dT_{i-1} beyond it
        d_share = 0.0         # bdt q d(share into the HE)/dT of the last target cell
    for i in range(n):
        dh_dlow = 0.0
        dh_dup = 0.0
        if i >= n_target:
            h_new[i], dh_dself, dh_dlow, dh_dup = _he_cell_enthalpy(
                i, n, n_target, temp_new, width, rho_c, latent_v, melting_point,
                melt_width, melt_spread, frozen_width)
        elif tdep:
            tk, tdk = tk_next, tdk_next
            h_new[i] = th_next
            dh_dself = tc_next
        else:
            h_new[i] = rho_c[i] * temp_new[i]
            dh_dself = rho_c[i]
        r = width[i] * (h_new[i] - hist_h[i]) + flow_in
        d = width[i] * dh_dself + g_low
        lower = width[i] * dh_dlow - g_low
        up_extra = 0.0
        if tdep and 0 < i <= n_target:
            # The face below depends on both its cells' k(T): d(flow_in)/dT.
            d += jac_low_self
            lower += jac_low_other
        if tdep and i < n_target:
            # Face i | i+1: half-cell resistances a = w_i / (2 k_i) and b in series,
            # G = 1 / (a + b), dG/dT_i = G^2 a k_i' / k_i (and likewise for b).
            a_half = width[i] / (2.0 * tk)
            if i < n_target - 1:
                tk_next, tdk_next, tc_next, th_next = target_properties(
                    temp_new[i + 1], target_table, n_table)
                b_half = width[i + 1] / (2.0 * tk_next)
            else:
                b_half = 1.0 / g_h   # the first HE cell's half cell
            g_face = 1.0 / (a_half + b_half)
            dg_self = g_face * g_face * a_half * tdk / tk
            dg_other = (g_face * g_face * b_half * tdk_next / tk_next
                        if i < n_target - 1 else 0.0)
            g_up = bdt * g_face
            diff = temp_new[i + 1] - temp_new[i]
            flow_out = g_up * diff
            r -= flow_out
            d += g_up - bdt * dg_self * diff
            up_extra = -bdt * dg_other * diff
            jac_low_self = bdt * dg_other * diff
            jac_low_other = bdt * dg_self * diff
            if i == n_target - 1:
                # The flux splits as the half cells' conductances: share a / (a + b)
                # into the HE; d(share)/dT_i = -b G^2 a k_i' / k_i.
                share = a_half * g_face
                q_target = bdt * (1.0 - share) * q
                q_he = bdt * share * q
                d_share = -bdt * q * b_half * g_face * g_face * a_half * tdk / tk
                d += d_share
        elif i < n - 1:
            g_up = bdt * face_conductance[i]
            flow_out = g_up * (temp_new[i + 1] - temp_new[i])  # into i from i+1
            r -= flow_out
            d += g_up
        else:
            g_up = 0.0
            flow_out = 0.0
        if i == n_target - 1:
            r -= q_target
        elif i == n_target:
            if exact_target:
                r -= robin * (drive - temp_new[i])
                d += robin
            else:
                r -= q_he
                if tdep:
                    lower -= d_share
        if reactive and i >= n_target and temp_new[i] >= t_cold:
            j = i - n_target
            inv_t = 1.0 / temp_new[i]
            k = prefactor * math.exp(-activation_temperature * inv_t)
            inv_denom = 1.0 / (1.0 + bdt * k)
            source = q_v * k * (1.0 - hist_y[j]) * inv_denom
            dsource = source * activation_temperature * inv_t * inv_t * inv_denom
            r -= bdt * width[i] * source
            d -= bdt * width[i] * dsource
            if final:
                y_new[j] = (hist_y[j] + bdt * k) * inv_denom
        elif final and i >= n_target:
            y_new[i - n_target] = hist_y[i - n_target]
        if final:
            if i >= n_target:
                if temp_new[i] > t_max:
                    t_max = temp_new[i]
                if y_new[i - n_target] > y_max:
                    y_max = y_new[i - n_target]
            if estimate:
                e = _local_error(i, temp_new, temp, temp_prev, temp_prev2, dt, inv_dt1,
                                 inv_dt0, c2)
                if e > err:
                    err = e
        # Forward sweep (the melting cells' enthalpies make the off-diagonals unequal).
        upper = width[i] * dh_dup - g_up + up_extra
        inv = 1.0 / (d - lower * cp_prev)
        cp_prev = upper * inv
        dp_prev = (-r - lower * dp_prev) * inv
        cp[i] = cp_prev
        dp[i] = dp_prev
        flow_in = flow_out
        g_low = g_up
    return err, t_max, y_max


@njit(**_JIT, inline="always")
def _back_substitution(n, temp_new, cp, dp):
    """The Newton update delta [K] into ``dp`` (kept there, applied by the caller once it is
    known not to be the last): returns its largest magnitude [K] and whether every updated
    temperature stays finite and positive."""
    change = 0.0
    finite = True
    delta_next = 0.0
    for i in range(n - 1, -1, -1):
        d_i = dp[i] - cp[i] * delta_next
        delta_next = d_i
        dp[i] = d_i
        a = abs(d_i)
        if not math.isfinite(a) or temp_new[i] + d_i <= 0.0:
            finite = False
        if a > change:
            change = a
    return change, finite


@njit(**_JIT, inline="always")
def _retry_step(dt, converged, err, tol_temperature):
    """The step [s] a rejected attempt is retried with: by the error estimate (safety
    :data:`RETRY_SAFETY`, at least a fifth) when Newton converged, else a quarter."""
    if converged:
        dt *= max(0.2, RETRY_SAFETY * (tol_temperature / err) ** (1.0 / 3.0))
    else:
        dt *= 0.25
    return dt


@njit(**_JIT, inline="always")
def _next_step(dt, n_hist, err, tol_temperature):
    """The step [s] after an accepted one, from the error estimate (:data:`STEP_SAFETY`;
    growth capped at 2 for smoothness, and 2 while the history is too short to estimate)."""
    if n_hist >= 3 and err > 0.0:
        fac = min(2.0, max(0.2, STEP_SAFETY * (tol_temperature / err) ** (1.0 / 3.0)))
    else:
        fac = 2.0
    return dt * fac


@njit(**_JIT, inline="always")
def _frozen_first_cell(temp, width, h, rho_c, latent_v, melting_point, melt_width,
                       melt_spread):
    """Freeze the first HE cell's spread melting width at the accepted temperatures ``temp``
    (the width :func:`_he_cell_enthalpy` gives it there), with its enthalpy ``h[0]``
    recomputed at that width: returns the width [K] (:data:`FREEZE_WIDTH_AFTER`)."""
    diff, ratio = _first_cell_range(temp, width)
    _, frozen_width = _spread_width(diff, ratio, melt_width, melt_spread)
    h[0], _ = _he_enthalpy(temp[0], rho_c[0], latent_v, melting_point, frozen_width)
    return frozen_width


@njit(**_JIT, inline="always")
def _interface_temperature(q, temp, n_target, width, g_t, g_h, g_eff, drive, exact_target,
                           tdep, target_table, n_table):
    """The interface temperature T_b [K] of an accepted state (Eq. 16; with the exact target,
    from its Robin condition)."""
    if exact_target:
        return temp[0] + g_eff * (drive - temp[0]) / g_h
    g_rec = g_t
    if tdep:
        tk, _, _, _ = target_properties(temp[n_target - 1], target_table, n_table)
        g_rec = 2.0 * tk / width[n_target - 1]
    return ((q + g_rec * temp[n_target - 1] + g_h * temp[n_target])
            / (g_rec + g_h))


@njit(**_JIT, inline="always")
def _event(t, t_old, dt, t_max, t_max_prev, y_max, y_max_prev, t_run, t_commit, commit_by,
           prefactor, activation_temperature, adiabatic_rise):
    """The thermal-event rule on an accepted step from ``t_old`` to ``t`` [s].

    An event is the report's criterion (fraction reacted above 0.99 in a cell), the runaway
    rule (the hottest cell past t_run), or, for a sign-only run, the commit rule: past
    t_commit, early enough (``commit_by``), and heating at least :data:`SIGN_COMMIT_HEATING`
    of the adiabatic rate dT_ad Z exp(-T_a / T) over its last step.

    Returns
    -------
    event : bool
    t_event : float
        The crossing time interpolated within the step, plus the adiabatic induction time at
        the threshold for the temperature rules [s] (inf without an event).
    """
    committed = (t_max >= t_commit and t <= commit_by
                 and t_max - t_max_prev >= SIGN_COMMIT_HEATING * dt * adiabatic_rise
                 * prefactor * math.exp(-activation_temperature / t_max_prev))
    if y_max > 0.99 or t_max >= t_run or committed:
        frac = 1.0
        if y_max > 0.99:
            if y_max > y_max_prev:
                frac = (0.99 - y_max_prev) / (y_max - y_max_prev)
            t_event = t_old + min(max(frac, 0.0), 1.0) * dt
        else:
            threshold = t_run if t_max >= t_run else t_commit
            if t_max > t_max_prev:
                frac = (threshold - t_max_prev) / (t_max - t_max_prev)
            t_event = t_old + min(max(frac, 0.0), 1.0) * dt + adiabatic_induction_time(
                threshold, prefactor, activation_temperature, adiabatic_rise)
        return True, t_event
    return False, math.inf


@njit(**_JIT, nogil=True)
def simulate_core(inp, out, width, rho_c, face_conductance, state, history, record_t,
                  record_tb, prefix, target_table):
    """:func:`simulate_kernel` on caller-owned storage, allocating nothing.

    The one integrator of both backends: the CPU wrapper :func:`simulate_kernel` allocates the
    work arrays with NumPy; a GPU thread (:mod:`skidmc.solver.device`) passes arrays and
    records of its own local memory, where NumPy cannot allocate. Only the first ``n`` cells
    of each array are used, so fixed-size arrays larger than the mesh serve any level up to
    their size.

    Parameters
    ----------
    inp : record of :data:`~skidmc.physics.records.KERNEL_INPUT`
        The run's scalar inputs (an element of a structured array; see
        :func:`simulate_kernel`).
    out : record of :data:`~skidmc.physics.records.KERNEL_OUTPUT`
        Written with the outcome.
    width, rho_c, face_conductance : ndarray
        The mesh (:func:`simulate_kernel`).
    state : ndarray, shape (>= STATE_ROWS, >= n)
        Work array, overwritten: the integrator's per-cell state, rows ``STATE_*`` of
        :mod:`skidmc.physics.records`.
    history : ndarray, shape (>= HISTORY_ROWS, capacity + 1)
        The exact target's accepted times [s], its flux [W/m^2] at the start and end of each
        accepted step, and scratch (rows ``HISTORY_*``): a run that needs more than
        ``capacity`` steps stops with ``history_full``. Unused (any 2-D array) with a meshed
        target.
    record_t, record_tb : ndarray
        The first ``inp.n_record`` steps' times [s] and interface temperatures [K].
    prefix, target_table : ndarray
        The linear prefix and a temperature-dependent target's table (:func:`simulate_kernel`;
        ``prefix_mode`` 0 and ``n_table`` 0 with any array leave them alone).

    The run, step by step: :func:`_thresholds` and :func:`_initial_state` (or
    :func:`_resume_prefix`); per attempt the BDF2 coefficients, the exact target's drive,
    Newton's passes (:func:`_assemble_and_sweep`, :func:`_back_substitution`); a rejected
    attempt's retry (:func:`_retry_step`, the frozen width); an accepted step's history and
    records, the event rule (:func:`_event`), the next step (:func:`_next_step`) and the
    linear prefix (:func:`_linear_at_scale`, :func:`_record_prefix`).
    """
    # The inputs, as locals (the compiled loop keeps them in registers).
    n = inp.n
    n_target = inp.n_target
    q_share_he = inp.q_share_he
    he_density = inp.he_density
    latent_heat = inp.latent_heat
    melting_point = inp.melting_point
    melt_width = inp.melt_width
    melt_spread = inp.melt_spread
    prefactor = inp.prefactor
    activation_temperature = inp.activation_temperature
    heat_of_reaction = inp.heat_of_reaction
    q0 = inp.q0
    slide_s = inp.slide_s
    slide_c = inp.slide_c
    omega = inp.omega
    t_exit = inp.t_exit
    q_ext = inp.q_ext
    t_end = inp.t_end
    t_stop = inp.t_stop
    initial_temperature = inp.initial_temperature
    tol_temperature = inp.tol_temperature
    dt_initial = inp.dt_initial
    runaway_fraction = inp.runaway_fraction
    max_steps = inp.max_steps
    n_record = inp.n_record
    target_effusivity = inp.target_effusivity
    he_conductivity = inp.he_conductivity
    sign_commit_fraction = inp.sign_commit_fraction
    prefix_mode = inp.prefix_mode
    n_table = inp.n_table

    temp = state[STATE_TEMP]
    temp_prev = state[STATE_TEMP_PREV]
    temp_prev2 = state[STATE_TEMP_PREV2]
    temp_new = state[STATE_TEMP_NEW]
    h = state[STATE_H]
    h_prev = state[STATE_H_PREV]
    h_new = state[STATE_H_NEW]
    y = state[STATE_Y]
    y_prev = state[STATE_Y_PREV]
    y_new = state[STATE_Y_NEW]
    hist_h = state[STATE_HIST_H]
    hist_y = state[STATE_HIST_Y]
    cp = state[STATE_CP]
    dp = state[STATE_DP]
    hist_t = history[HISTORY_T]
    hist_ql = history[HISTORY_QL]
    hist_qr = history[HISTORY_QR]
    hist_work = history[HISTORY_WORK]

    n_he = n - n_target
    # A temperature-dependent meshed target (n_table nodes; target_properties).
    tdep = n_table >= 2 and n_target > 0
    for j in range(n_he):
        y[j] = 0.0
        y_prev[j] = 0.0
        y_new[j] = 0.0

    latent_v = he_density * latent_heat
    q_v = he_density * heat_of_reaction
    rho_c_he = rho_c[n_target]
    adiabatic_rise = heat_of_reaction / (rho_c_he / he_density)
    reactive = prefactor > 0.0 and heat_of_reaction >= 0.0
    t_run, t_commit, commit_by, t_relax, t_cold = _thresholds(
        prefactor, activation_temperature, adiabatic_rise, reactive, t_exit, t_end,
        tol_temperature, runaway_fraction, sign_commit_fraction)
    melting = (latent_v, melting_point, melt_width, melt_spread)
    kinetics = (reactive, t_cold, prefactor, activation_temperature, q_v)

    _initial_state(n, n_target, initial_temperature, rho_c, latent_v, melting_point,
                   melt_width, tdep, target_table, n_table, temp, temp_prev, temp_prev2, h,
                   h_prev)

    # The outcome, kept in locals and written to `out` once at the end.
    event = False
    t_event = math.inf
    run_t_max = initial_temperature
    run_y_max = 0.0
    t_exit_max = math.nan
    y_exit_max = math.nan
    failed = False
    history_full = False
    width_frozen = False
    newton_failures = 0
    newton_iterations = 0
    resumed_steps = 0

    exact_target = n_target == 0 and target_effusivity > 0.0
    if exact_target:
        # T_b - T0 = duhamel (A + B q_t) with the new step's weight B on its own q_t; the first
        # HE cell takes q_h = g_h (T_b - T_he) through its half cell, and q_t = q - q_h, so
        # q_h = g_eff (T0 + duhamel A + duhamel B q - T_he), g_eff = g_h / (1 + duhamel B g_h).
        g_t = 0.0
        g_h = 2.0 * he_conductivity / width[0]
        duhamel = 1.0 / (target_effusivity * math.sqrt(math.pi))
        hist_t[0] = 0.0
    else:
        # Side conductances at the interface, for the recorded T_b of Eq. (16): G = g_t g_h /
        # (g_t + g_h) and s = g_h / (g_t + g_h) give g_t = G / s, g_h = G / (1 - s).
        g_t = face_conductance[n_target - 1] / q_share_he
        g_h = face_conductance[n_target - 1] / (1.0 - q_share_he)
        duhamel = 0.0
    capacity = history.shape[1] - 1
    q_t_last = 0.0      # the exact target's flux at the last accepted step [W/m^2]
    g_eff = 0.0
    robin = 0.0
    drive = 0.0

    # The flux at t_exit from the left (the contact's last step ends there), and whether the
    # extension flux jumps from it.
    q_exit_left = _contact_flux(t_exit, q0, slide_s, slide_c, omega)
    exit_jump = abs(q_ext - q_exit_left) > 1e-6 * abs(q0)

    t = 0.0
    dt = dt_initial
    dt_prev = dt_initial
    dt_prev2 = dt_initial
    n_hist = 0          # accepted steps since the last (re)start of the multistep history
    steps = 0
    rejected = 0
    t_max_prev = initial_temperature
    y_max_prev = 0.0
    newton_tol = NEWTON_TOLERANCE_FRACTION * tol_temperature
    # With the exact target the first HE cell's spread width comes from the one-sided
    # difference T_1 - T_0, so its enthalpy depends on its own temperature twice (through T_0
    # and through the width) and can fold (decrease with T_0) near T_m: the implicit step then
    # has no solution near the last one at any step size, and the run stalls (three scenes of
    # scripts/fast_tier_error.py's sets, scripts/stall_sweep.py: up to 200,000 steps, half of
    # the attempts Newton failures). After
    # FREEZE_WIDTH_AFTER Newton failures the cell's width is frozen at its value at the last
    # accepted step, where the stored enthalpy is exactly consistent with it, and the multistep
    # history restarts; its enthalpy then increases with T_0. A run that never gets there is
    # unchanged to the last bit.
    frozen_width = 0.0

    # The linear prefix: record it (the run itself is unchanged), or start from it.
    recording = (prefix_mode == PREFIX_WRITE and prefix.shape[0] >= prefix_size(n)
                 and not tdep)
    melt_z = -math.inf
    if recording:
        prefix[_PX_VALID] = 0.0
        if latent_v > 0.0:
            melt_z = prefix_melt_z(tol_temperature, rho_c_he, latent_v)
    if prefix_mode == PREFIX_RESUME:
        scale = _prefix_scale(prefix, n, n_record, tdep, t_stop, tol_temperature, t_exit,
                              initial_temperature, q0, q_ext, exact_target, capacity)
        if scale != 0.0:
            t, dt, dt_prev, dt_prev2, n_hist, steps, t_max_prev, q_t_last = _resume_prefix(
                prefix, scale, n, n_target, initial_temperature, width, rho_c, latent_v,
                melting_point, melt_width, melt_spread, exact_target, temp, temp_prev,
                temp_prev2, h, h_prev, hist_t, hist_ql, hist_qr)
            run_t_max = t_max_prev
            resumed_steps = steps

    while t < t_stop and steps + rejected < max_steps:
        # Land exactly on t_exit (flux kink or jump) and on t_stop, stretching the step
        # by up to 1 % rather than leaving a sliver of a step before them.
        if t < t_exit and t + 1.01 * dt > t_exit:
            dt = t_exit - t
        if t + 1.01 * dt > t_stop:
            dt = t_stop - t
        t_new = t + dt

        # History terms, and Newton's start: the linear extrapolation of the temperatures.
        a1, a2, bdt, om = _bdf2_coefficients(dt, dt_prev, n_hist)
        for i in range(n):
            hist_h[i] = a1 * h[i] - a2 * h_prev[i]
            temp_new[i] = temp[i] + om * (temp[i] - temp_prev[i])
        for j in range(n_he):
            hist_y[j] = a1 * y[j] - a2 * y_prev[j]

        if t < t_exit <= t_new:
            # A step that ends on t_exit integrates the contact's flux up to it: BDF2 takes
            # the flux at the step's end, so it takes the left limit there, not q_ext. (With
            # q_ext the extension's jump fell into the contact's last step: its error estimate
            # rejected such steps, and the retries crept up to t_exit in shrinking steps.)
            q = q_exit_left
        else:
            q = _flux(t_new, q0, slide_s, slide_c, omega, t_exit, q_ext)
        q_target = bdt * (1.0 - q_share_he) * q
        q_he = bdt * q_share_he * q
        if exact_target:
            g_eff, drive, robin = _exact_target_drive(
                t_new, dt, n_hist, steps, q, q_t_last, g_h, duhamel, bdt, initial_temperature,
                hist_t, hist_ql, hist_qr, hist_work)
        # Local error: BDF2 corrector minus the quadratic extrapolation through the last three
        # accepted temperatures (Newton divided differences).
        estimate = n_hist >= 2
        inv_dt1 = 1.0 / dt_prev
        inv_dt0 = 1.0 / dt_prev2
        c2 = dt * (dt + dt_prev) / (dt_prev + dt_prev2)
        converged = False
        err = 0.0
        t_max = -math.inf
        y_max = 0.0
        for _it in range(12):
            newton_iterations += 1
            # From the second iteration on, Newton usually converges: the step's final state
            # (fraction reacted, maxima, error estimate) is computed in the same pass, at the
            # iterate the residual is assembled at, and kept if this iteration's update is
            # within Newton's tolerance.
            final = _it >= 1
            err, t_max, y_max = _assemble_and_sweep(
                final, estimate, err, t_max, y_max, n, n_target, width, rho_c,
                face_conductance, melting, kinetics, frozen_width, tdep, target_table,
                n_table, exact_target, g_h,
                (bdt, q, q_target, q_he, robin, drive, dt, inv_dt1, inv_dt0, c2),
                (temp_new, temp, temp_prev, temp_prev2),
                (h_new, hist_h, y_new, hist_y, cp, dp))
            change, finite = _back_substitution(n, temp_new, cp, dp)
            if not finite:
                break
            if change < newton_tol and final:
                converged = True
                break
            # A step whose first update is already within tolerance takes the second, final
            # pass too, so that one pass computes every step's final state: 1.8 % more
            # iterations (2.14 against 2.10 per attempt, 13 scenes at levels 0.5 and 1.5 at
            # 0.98 and 1.02 H_c), no measurable time, the same margins to 2e-16.
            for i in range(n):
                temp_new[i] += dp[i]

        if converged:
            if not math.isfinite(t_max):
                converged = False
            if t_max_prev >= t_relax:
                err = 0.0

        if not converged or err > tol_temperature:
            rejected += 1
            if not converged:
                newton_failures += 1
                if (exact_target and melt_spread > 0.0 and latent_v > 0.0 and n > 1
                        and frozen_width == 0.0
                        and newton_failures >= FREEZE_WIDTH_AFTER):
                    frozen_width = _frozen_first_cell(temp, width, h, rho_c, latent_v,
                                                      melting_point, melt_width, melt_spread)
                    n_hist = 0
                    width_frozen = True
            dt = _retry_step(dt, converged, err, tol_temperature)
            if dt < 1e-14 * t_end:
                if t_max_prev >= t_relax:
                    # Past t_relax the runaway cannot be stopped: the event follows
                    # within the adiabatic induction time, whatever the integrator does.
                    event = True
                    t_event = t + adiabatic_induction_time(
                        t_max_prev, prefactor, activation_temperature, adiabatic_rise)
                else:
                    failed = True
                break
            continue

        # Accept the step: rotate the state buffers (no copies).
        if exact_target:
            if steps >= capacity:
                history_full = True
                break
            q_t_new = q - g_eff * (drive - temp_new[0])
            hist_ql[steps] = q_t_new if n_hist == 0 else q_t_last
            hist_qr[steps] = q_t_new
            hist_t[steps + 1] = t_new
            q_t_last = q_t_new
        steps += 1
        temp_prev2, temp_prev, temp, temp_new = temp_prev, temp, temp_new, temp_prev2
        h_prev, h, h_new = h, h_new, h_prev
        y_prev, y, y_new = y, y_new, y_prev
        dt_prev2 = dt_prev
        dt_prev = dt
        n_hist += 1
        t_old = t
        t = t_new
        if steps <= n_record:
            record_t[steps - 1] = t
            record_tb[steps - 1] = _interface_temperature(
                q, temp, n_target, width, g_t, g_h, g_eff, drive, exact_target, tdep,
                target_table, n_table)
        if t_max > run_t_max:
            run_t_max = t_max
        if y_max > run_y_max:
            run_y_max = y_max
        if t_old < t_exit <= t:
            t_exit_max = t_max
            y_exit_max = y_max

        event, t_event = _event(t, t_old, dt, t_max, t_max_prev, y_max, y_max_prev, t_run,
                                t_commit, commit_by, prefactor, activation_temperature,
                                adiabatic_rise)
        if event:
            break
        t_max_prev = t_max
        y_max_prev = y_max

        dt = _next_step(dt, n_hist, err, tol_temperature)
        # A jump of the flux at t_exit restarts the multistep history with a small step.
        if t == t_exit and exit_jump:
            n_hist = 0
            dt = dt_initial
        if recording:
            # Still linear at every height the prefix may serve: record this state (every
            # earlier one was too); else the prefix ends at the last one recorded.
            recording = steps <= PREFIX_STEPS and _linear_at_scale(
                temp, width, n, n_target, initial_temperature, PREFIX_MAX_SCALE, reactive,
                t_cold, latent_v, melting_point, melt_width, melt_spread, melt_z)
            if recording:
                _record_prefix(prefix, n, temp, temp_prev, temp_prev2, hist_t, hist_ql,
                               hist_qr, exact_target, q0, t, dt, dt_prev, dt_prev2, n_hist,
                               steps, q_t_last, t_max_prev, tol_temperature, t_exit,
                               initial_temperature, q_ext)

    out.event = event
    out.t_event = t_event
    out.steps = steps
    out.rejected = rejected
    out.t_max = run_t_max
    out.y_max = run_y_max
    out.t_final = t
    out.failed = failed
    out.t_exit_max = t_exit_max
    out.y_exit_max = y_exit_max
    out.newton_failures = newton_failures
    out.newton_iterations = newton_iterations
    out.history_full = history_full
    out.frozen_width = width_frozen
    out.resumed_steps = resumed_steps
