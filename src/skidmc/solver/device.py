"""The full-tier critical-height search as one compiled function per sample (CPU or GPU thread).

:func:`critical_height_core` runs, for one scene given as a row of SI floats, the default
search of :func:`skidmc.solver.critical_height`: the fast tier's height as first guess, a
Richardson pair of levels (the first pair, melting width and root tolerances of
:mod:`skidmc.solver.plan`), its a posteriori error estimate, and the same adaptive rounds
(tighten the roots, or move the pair up a level) while that estimate exceeds ``rtol``: the
estimate and each round's decision are the compiled functions of
:mod:`skidmc.solver.controller` that the CPU search calls too. It
calls the same compiled kernels as the CPU search (:func:`skidmc.physics.thermal.simulate_core`,
:func:`skidmc.physics.fast.fast_height_core`, :func:`skidmc.physics.meshes.fill_meshes`,
:func:`skidmc.physics.mechanics.impact_constants` and the model's scalar functions), on
storage the caller owns: a NumPy array on the CPU, a thread's local memory on the GPU
(:mod:`skidmc.solver.cuda`). Nothing here allocates, raises or touches Python objects, which
is what a CUDA device function needs.

Where it differs from the CPU search, and why
---------------------------------------------
* Root finder: Brent's method (zeroin) on the margin m(ln H) = ln(t_ev / t_exit), capped at the
  horizon ln(t_end / t_exit) where no event happens, from a bracket grown geometrically around
  the guess. The CPU search's guided, go-side and jump-aware finders
  (:mod:`skidmc.solver.roots`) keep a history of Python tuples and pick among strategies by it;
  Brent's bracket keeps every root within its tolerance on smooth margins and on jumps alike,
  and fits in a few registers. Both honour the same root tolerance, so the results agree
  within the tolerance (``tests/test_device.py`` measures it), not bit for bit.
* What is sent back to the CPU search (status :data:`STATUS_CPU`): scenes whose ignition
  temperature lies below the melting point with melting modelled (the CPU search measures the
  melting width's bias there with an extra simulation and may narrow the width), scenes whose
  pair would have to move above :data:`DEVICE_MAX_LEVEL` (the thread's fixed-size arrays), and
  any search that fails (integration failure, no bracket within the evaluation cap): the CPU
  search then gives the result, or the failure with its reason. Scenes the row of floats
  cannot carry go there too, before any device work is trusted: layered targets whose heat
  reaches below the top layer, and targets whose properties follow a temperature table
  ("temperature_target"; the thread's target has constant properties). The batch front end
  (:func:`skidmc.solver.cuda.cuda_critical_heights`) does this; no sample is lost.
* Stalled runs: the CPU search's cap, the same compiled function
  (:func:`skidmc.solver.simulate.run_cap`: 10x the most step attempts of the search's earlier
  runs, at least 4,000 and 2,000 x 2^level, 12,500 x 2^level in any case), so a run that stalls
  hands its scene to the CPU search after a few thousand attempts instead of 200,000.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from skidmc.physics.fast import (
    C_IGNITION,
    CENSOR_ABOVE,
    CENSOR_BELOW,
    CENSOR_NONE,
    MELT_FACTOR,
    N_TIMES,
    STOPS_SLIDING_FACTOR,
    fast_height_core,
)
from skidmc.physics.mechanics import STANDARD_GRAVITY, contact_pressure, impact_constants
from skidmc.physics.meshes import fill_meshes
from skidmc.physics.records import KERNEL_RUN, STATE_ROWS
from skidmc.physics.thermal import simulate_core
from skidmc.solver.controller import (
    DONE,
    MAX_ADAPTIVE_ROUNDS,
    NARROW,
    REFINE,
    TIGHTEN_BOTH,
    TIGHTEN_FINE,
    next_round,
    pair_estimate,
    richardson_value,
)
from skidmc.solver.model import (
    BASE_RESOLUTION,
    DEPTH_DIFFUSION_LENGTHS,
    HORIZON_EXIT_TIMES,
    MELT_WIDTH_BIAS_PER_K,
    flux_extension,
    ignition_temperature,
    level_resolution,
    melt_width_floor,
    model_runaway_temperature,
)
from skidmc.solver.plan import modelled_error
from skidmc.solver.roots import FAST_GUESS_ERROR
from skidmc.solver.simulate import run_cap

__all__ = [
    "DEVICE_MAX_LEVEL",
    "MAX_CELLS",
    "MAX_SEARCH_EVALUATIONS",
    "OUT_SIZE",
    "STATUS_CPU",
    "STATUS_OK",
    "WORK_ROWS",
    "critical_height_core",
    "critical_heights_cpu",
    "run_cap",
]

#: Finest level a device search refines to (its arrays hold 2 * 24 * 2**3 = 384 cells); a pair
#: that would need more goes to the CPU search (:data:`STATUS_CPU`). The first pairs of rtol
#: 1e-2, 3e-3 and 1e-3 are (0, 1), (0, 1) and (0.5, 1.5).
DEVICE_MAX_LEVEL = 3.0
#: Cells of the largest mesh a device search builds (both media).
MAX_CELLS = 2 * int(round(BASE_RESOLUTION.cells_per_medium * 2.0**DEVICE_MAX_LEVEL))
#: Rows of the work array: the integrator's state (rows ``STATE_*`` of
#: :mod:`skidmc.physics.records`), then width, rho c, face conductance.
_ROW_WIDTH, _ROW_RHO_C, _ROW_FACE = STATE_ROWS, STATE_ROWS + 1, STATE_ROWS + 2
WORK_ROWS = STATE_ROWS + 3
#: Most simulations one search at one level may use before it gives up (to the CPU search).
MAX_SEARCH_EVALUATIONS = 60

#: Result codes of :func:`critical_height_core` (``out[OUT_STATUS]``).
STATUS_OK, STATUS_CPU = 0, 1

# Layout of the output row.
OUT_HEIGHT = 0          # critical height [m] (the bound when censored)
OUT_CENSOR = 1          # CENSOR_NONE / ABOVE / BELOW
OUT_ERROR = 2           # a posteriori error estimate [1]
OUT_EVALUATIONS = 3     # simulations used
OUT_STATUS = 4          # STATUS_OK / STATUS_CPU
OUT_LEVEL = 5           # fine level of the final pair
OUT_CORRECTION = 6      # Richardson correction c / R [1]
OUT_EXIT_CODE = 7       # EXIT_REBOUND / EXIT_STOPS_SLIDING
OUT_MELT_BIAS = 8       # melting width's bias bound in the estimate [1]
OUT_EXIT_TIME = 9       # t_exit [s]
OUT_SIZE = 10

# Columns of an input row: skidmc.solver.fast.SCENE_FIELDS (NUMERIC_KEYS order), SI units.
(_MU, _SIGMA, _MASS, _DIAMETER, _ANGLE, _TILT, _T0, _HE_RHO, _HE_C, _HE_K, _HE_L, _HE_TM, _Z,
 _TA, _Q, _TG_RHO, _TG_C, _TG_K, _TG_P) = range(19)

# Scalars shared by every level of one scene (the `sc` array).
# _S_MOST: the most step attempts of a run of the current search at its level (run_cap).
(_S_OMEGA, _S_T_EXIT, _S_SLIDE_S, _S_SLIDE_C, _S_EXTENSION, _S_T_END, _S_FLUX,
 _S_LATENT, _S_RUNAWAY, _S_SPREAD, _S_MOST) = range(11)
_N_SCALARS = 11



@njit(cache=True)
def _build_level(row, sc, level, work):
    """Mesh of ``level`` into the work rows; returns (cells, flux share into the HE, tol_T)."""
    n_cells, first_fraction, tol_temperature = level_resolution(level)
    share = fill_meshes(row[_HE_RHO], row[_HE_C], row[_HE_K], row[_TG_RHO], row[_TG_C],
                        row[_TG_K], row[_T0], row[_Z], row[_TA], sc[_S_T_EXIT], sc[_S_T_END],
                        n_cells, first_fraction, DEPTH_DIFFUSION_LENGTHS, work[_ROW_WIDTH],
                        work[_ROW_RHO_C], work[_ROW_FACE])
    return n_cells, share, tol_temperature


@njit(cache=True)
def _margin(x, row, sc, n_cells, share, tol_temperature, melt_width, work, info):
    """Margin ln(t_ev / t_exit) at H = exp(x) [1], capped at the horizon ln(t_end / t_exit)
    (no event); NaN when the integration fails or stalls (:func:`run_cap`; the search then
    goes to the CPU). Updates ``sc[_S_MOST]``, the most attempts of the search's runs.

    ``info`` (shape (1,), dtype :data:`skidmc.physics.records.KERNEL_RUN`) holds the run's
    input record, filled here, and its outcome; ``work`` the mesh and the integrator's state
    (:data:`WORK_ROWS`). The target is meshed with constant properties (tables go to the CPU
    search), no linear prefix, nothing recorded.
    """
    cap = run_cap(tol_temperature, sc[_S_MOST])
    q0 = sc[_S_FLUX] * math.sqrt(math.exp(x))
    run = info[0]
    inp = run.input
    inp.n = 2 * n_cells
    inp.n_target = n_cells
    inp.q_share_he = share
    inp.he_density = row[_HE_RHO]
    inp.latent_heat = sc[_S_LATENT]
    inp.melting_point = row[_HE_TM]
    inp.melt_width = melt_width
    inp.melt_spread = sc[_S_SPREAD]
    inp.prefactor = row[_Z]
    inp.activation_temperature = row[_TA]
    inp.heat_of_reaction = row[_Q]
    inp.q0 = q0
    inp.slide_s = sc[_S_SLIDE_S]
    inp.slide_c = sc[_S_SLIDE_C]
    inp.omega = sc[_S_OMEGA]
    inp.t_exit = sc[_S_T_EXIT]
    inp.q_ext = q0 * sc[_S_EXTENSION]
    inp.t_end = sc[_S_T_END]
    inp.t_stop = sc[_S_T_END]
    inp.initial_temperature = row[_T0]
    inp.tol_temperature = tol_temperature
    inp.dt_initial = 1e-6 * sc[_S_T_EXIT]
    inp.runaway_fraction = sc[_S_RUNAWAY]
    inp.max_steps = cap
    inp.n_record = 0
    inp.target_effusivity = 0.0
    inp.he_conductivity = 0.0
    inp.sign_commit_fraction = 0.0
    inp.prefix_mode = 0
    inp.n_table = 0
    res = run.output
    simulate_core(inp, res, work[_ROW_WIDTH], work[_ROW_RHO_C], work[_ROW_FACE], work, work,
                  work[0], work[0], work[0], work[0])
    horizon = math.log(sc[_S_T_END] / sc[_S_T_EXIT])
    attempts = res.steps + res.rejected
    sc[_S_MOST] = max(sc[_S_MOST], attempts)
    if res.failed or (attempts >= cap and not res.event):
        return math.nan
    t_ev = res.t_event
    if not (t_ev < math.inf):
        return horizon
    return min(math.log(t_ev / sc[_S_T_EXIT]), horizon)


@njit(cache=True)
def _brent(lo, f_lo, hi, f_hi, x_tol, row, sc, n_cells, share, tol_temperature, melt_width,
           work, info, budget):
    """Brent's zeroin on a bracket f(lo) > 0 >= f(hi) until it is ``x_tol`` wide.

    Returns (lo, f_lo, hi, f_hi, evaluations, ok): the final bracket (no-go end ``lo``, go end
    ``hi``), at most 2 ``x_tol`` wide, so its midpoint is within ``x_tol`` of the root.
    """
    a, fa, b, fb = lo, f_lo, hi, f_hi
    c, fc = a, fa
    d = b - a
    e = d
    evaluations = 0
    while True:
        if abs(fc) < abs(fb):
            a, fa = b, fb
            b, fb = c, fc
            c, fc = a, fa
        # Converged when the bracket |c - b| is at most 2 x_tol: its midpoint is then within
        # x_tol of every root inside it.
        tol1 = 2.0 * 2.2e-16 * abs(b) + x_tol
        m = 0.5 * (c - b)
        if abs(m) <= tol1 or fb == 0.0:
            break
        if evaluations >= budget:
            return lo, f_lo, hi, f_hi, evaluations, False
        if abs(e) >= tol1 and abs(fa) > abs(fb):
            s = fb / fa
            if a == c:
                p = 2.0 * m * s
                q = 1.0 - s
            else:
                q = fa / fc
                r = fb / fc
                p = s * (2.0 * m * q * (q - r) - (b - a) * (r - 1.0))
                q = (q - 1.0) * (r - 1.0) * (s - 1.0)
            if p > 0.0:
                q = -q
            else:
                p = -p
            if 2.0 * p < min(3.0 * m * q - abs(tol1 * q), abs(e * q)):
                e = d
                d = p / q
            else:
                d = m
                e = m
        else:
            d = m
            e = m
        a, fa = b, fb
        if abs(d) > tol1:
            b += d
        else:
            b += tol1 if m > 0.0 else -tol1
        fb = _margin(b, row, sc, n_cells, share, tol_temperature, melt_width, work, info)
        evaluations += 1
        if fb != fb:
            return lo, f_lo, hi, f_hi, evaluations, False
        if (fb > 0.0) == (fc > 0.0):
            c, fc = a, fa
            d = b - a
            e = d
    # The bracket is b and c: order it as (no-go, go).
    if fb > 0.0:
        return b, fb, c, fc, evaluations, True
    return c, fc, b, fb, evaluations, True


@njit(cache=True)
def _search(row, sc, level, melt_width, x_guess, step, x_tol, x_min, x_max, work, info, res):
    """One search at ``level``: bracket the root around ``x_guess`` (first step ``step``,
    doubling), then Brent to ``x_tol``. Writes ``res`` = (x_root, censor, lo, f_lo, hi, f_hi,
    evaluations, ok).

    A first step sized from the first margin and the margin's slope was tried: on the report
    presets it saved nothing and cost the stops-sliding scene (gold) 6 more simulations.
    """
    n_cells, share, tol_temperature = _build_level(row, sc, level, work)
    sc[_S_MOST] = 0.0   # the stall cap counts this search's runs (run_cap)
    x0 = min(max(x_guess, x_min), x_max)
    f0 = _margin(x0, row, sc, n_cells, share, tol_temperature, melt_width, work, info)
    evaluations = 1
    res[1] = CENSOR_NONE
    res[7] = 0.0
    if f0 != f0:
        res[6] = evaluations
        return
    step = max(step, 2.0 * x_tol)
    lo = hi = x0
    f_lo = f_hi = f0
    while True:
        if evaluations >= MAX_SEARCH_EVALUATIONS:
            res[6] = evaluations
            return
        if f_hi <= 0.0 and f_lo <= 0.0:   # go everywhere so far: look lower
            if lo <= x_min:
                res[0], res[1], res[6], res[7] = x_min, CENSOR_BELOW, evaluations, 1.0
                return
            x = max(lo - step, x_min)
            fx = _margin(x, row, sc, n_cells, share, tol_temperature, melt_width, work, info)
            evaluations += 1
            if fx != fx:
                res[6] = evaluations
                return
            if fx > 0.0:
                f_hi = f_lo
                hi = lo
                lo, f_lo = x, fx
                break
            lo, f_lo = x, fx
            hi, f_hi = x, fx
        else:                              # no-go so far: look higher
            if hi >= x_max:
                res[0], res[1], res[6], res[7] = x_max, CENSOR_ABOVE, evaluations, 1.0
                return
            x = min(hi + step, x_max)
            fx = _margin(x, row, sc, n_cells, share, tol_temperature, melt_width, work, info)
            evaluations += 1
            if fx != fx:
                res[6] = evaluations
                return
            if fx <= 0.0:
                lo, f_lo = hi, f_hi
                hi, f_hi = x, fx
                break
            lo, f_lo = x, fx
            hi, f_hi = x, fx
        step *= 2.0
    lo, f_lo, hi, f_hi, n, ok = _brent(lo, f_lo, hi, f_hi, x_tol, row, sc, n_cells, share,
                                        tol_temperature, melt_width, work, info,
                                        MAX_SEARCH_EVALUATIONS - evaluations)
    res[0] = 0.5 * (lo + hi)
    res[2], res[3], res[4], res[5] = lo, f_lo, hi, f_hi
    res[6] = evaluations + n
    res[7] = 1.0 if ok else 0.0


@njit(cache=True)
def _tighten(row, sc, level, melt_width, x_tol, work, info, res):
    """Continue a search's Brent iteration from its final bracket to the tighter ``x_tol``;
    adds its simulations to ``res[6]``."""
    if res[1] != CENSOR_NONE:
        return
    n_cells, share, tol_temperature = _build_level(row, sc, level, work)
    sc[_S_MOST] = 0.0   # a new search at the tighter tolerance, as the CPU search's _tighten
    lo, f_lo, hi, f_hi, n, ok = _brent(res[2], res[3], res[4], res[5], x_tol, row, sc, n_cells,
                                       share, tol_temperature, melt_width, work, info,
                                       MAX_SEARCH_EVALUATIONS)
    res[0] = 0.5 * (lo + hi)
    res[2], res[3], res[4], res[5] = lo, f_lo, hi, f_hi
    res[6] += n
    res[7] = 1.0 if ok else 0.0


@njit(cache=True)
def critical_height_core(row, rtol, h_min, h_max, level, melt_width, melt_spread, x_tol,
                         melting, runaway_fraction, table, gl_x, gl_w, work, fast_work, info,
                         coarse, fine, out):
    """The default full-tier search of one scene (module docstring); results in ``out``.

    Parameters
    ----------
    row : ndarray, shape (19,)
        The scene's inputs in the order of :data:`skidmc.solver.fast.SCENE_FIELDS` [SI].
    rtol : float
        Relative tolerance on the critical height [1].
    h_min, h_max : float
        Search bounds [m].
    level, melt_width, x_tol : float
        The first pair's fine level, melting width [K] and root tolerance on ln H [1]
        (:func:`skidmc.solver.plan.first_pair_level`, ``melt_width_for_rtol``,
        ``pair_root_tolerance``).
    melt_spread : float
        Melting spread over each HE cell [1] (:data:`skidmc.physics.thermal.MELT_SPREAD`, the
        CPU search's default).
    melting : bool
        Model melting of the HE.
    runaway_fraction : float
        Runaway rule (:data:`skidmc.physics.thermal.DEFAULT_RUNAWAY_FRACTION`).
    table, gl_x, gl_w : ndarray
        The fast tier's melt table and Gauss-Legendre nodes and weights (first guess).
    work : ndarray, shape (WORK_ROWS, >= MAX_CELLS)
    fast_work : ndarray, shape (3, >= N_TIMES)
    info : ndarray, shape (1,), dtype :data:`skidmc.physics.records.KERNEL_RUN`
        The record of the search's current run (:func:`_margin`).
    coarse, fine : ndarray, shape (8,)
        Scratch for the two searches of the pair.
    out : ndarray, shape (OUT_SIZE,)
        Written (see the ``OUT_*`` layout).
    """
    for k in range(OUT_SIZE):
        out[k] = 0.0
    mu = row[_MU]
    if not row[_TG_P] > 0.0:
        # An elastic target: the CPU path refuses it with the reason (model.elastic_target_reason).
        out[OUT_STATUS] = STATUS_CPU
        return
    pressure = contact_pressure(row[_SIGMA], row[_TG_P])
    omega, _, t_exit, exit_code, slide_s, slide_c = impact_constants(
        mu, pressure, row[_MASS], row[_DIAMETER], row[_ANGLE], row[_TILT])
    out[OUT_EXIT_CODE] = exit_code
    out[OUT_EXIT_TIME] = t_exit
    out[OUT_LEVEL] = level
    x_min, x_max = math.log(h_min), math.log(h_max)
    if not mu > 0.0:
        # No frictional heat, no event: censored above without a simulation ("no_friction").
        out[OUT_HEIGHT], out[OUT_CENSOR] = h_max, CENSOR_ABOVE
        out[OUT_ERROR] = modelled_error(level) + 0.5 * x_tol
        return
    sc = fast_work[2]   # the scalars share the fast tier's last scratch row, used before it
    extension, _ = flux_extension(omega, t_exit, slide_s, slide_c)
    adiabatic_rise = row[_Q] / row[_HE_C]
    t_run = model_runaway_temperature(row[_Z], row[_TA], adiabatic_rise, t_exit,
                                      runaway_fraction)
    latent = row[_HE_L] if melting else 0.0
    melting_term = latent > 0.0 and row[_HE_TM] < t_run
    if not melting_term:
        latent = 0.0
    if melting_term and ignition_temperature(row[_Z], row[_TA], adiabatic_rise,
                                             t_exit) < row[_HE_TM]:
        # The CPU search measures the melting width's bias on such scenes (and may narrow it).
        out[OUT_STATUS] = STATUS_CPU
        return

    # First guess: the fast tier's height (its scratch rows 0-2 are free until `sc` is set).
    h_fast, censor_fast, _, _, _ = fast_height_core(
        mu, row[_SIGMA], row[_MASS], row[_DIAMETER], row[_ANGLE], row[_TILT], row[_T0],
        row[_HE_RHO], row[_HE_C], row[_HE_K], latent, row[_HE_TM], row[_Z], row[_TA], row[_Q],
        row[_TG_RHO], row[_TG_C], row[_TG_K], row[_TG_P], h_min, h_max, C_IGNITION, MELT_FACTOR,
        STOPS_SLIDING_FACTOR, table,
        gl_x, gl_w, N_TIMES, fast_work[0], fast_work[1], fast_work[2])
    if censor_fast == CENSOR_NONE and h_fast > 0.0:
        x_guess, guess_error = math.log(h_fast), FAST_GUESS_ERROR
    else:
        x_guess, guess_error = 0.0, 1.0   # 1 m, and a first step of a factor e

    sc[_S_OMEGA], sc[_S_T_EXIT], sc[_S_SLIDE_S], sc[_S_SLIDE_C] = omega, t_exit, slide_s, slide_c
    sc[_S_EXTENSION], sc[_S_T_END] = extension, HORIZON_EXIT_TIMES * t_exit
    sc[_S_FLUX] = mu * pressure * math.sqrt(2.0 * STANDARD_GRAVITY)
    sc[_S_LATENT], sc[_S_RUNAWAY], sc[_S_SPREAD] = latent, runaway_fraction, melt_spread

    coarse_level, fine_level = level - 1.0, level
    coarse_tol, fine_tol = x_tol, 0.5 * x_tol
    _search(row, sc, coarse_level, melt_width, x_guess, guess_error, coarse_tol,
            x_min, x_max, work, info, coarse)
    evaluations = coarse[6]
    if coarse[7] == 0.0:
        out[OUT_STATUS], out[OUT_EVALUATIONS] = STATUS_CPU, evaluations
        return
    # The fine root lies ~3/4 of the coarse level's error above the coarse one.
    spread = modelled_error(coarse_level)
    start = coarse[0] + 0.75 * spread if coarse[1] == CENSOR_NONE else x_guess
    _search(row, sc, fine_level, melt_width, start, spread, fine_tol,
            x_min, x_max, work, info, fine)
    evaluations += fine[6]
    if fine[7] == 0.0:
        out[OUT_STATUS], out[OUT_EVALUATIONS] = STATUS_CPU, evaluations
        return
    melt_bias = MELT_WIDTH_BIAS_PER_K * melt_width if melting_term else 0.0
    if coarse[1] != CENSOR_NONE or fine[1] != CENSOR_NONE:
        # As the CPU search: the fine search's result (its bound when censored, else its
        # own root, not extrapolated) with the calibrated estimate of its level.
        out[OUT_CENSOR] = fine[1]
        out[OUT_HEIGHT] = (h_max if fine[1] == CENSOR_ABOVE else
                           h_min if fine[1] == CENSOR_BELOW else math.exp(fine[0]))
        width_bias = (melt_bias if melt_width > melt_width_floor(fine_level) * (1.0 + 1e-9)
                      else 0.0)
        out[OUT_ERROR] = modelled_error(fine_level) + fine_tol + width_bias
        out[OUT_EVALUATIONS] = evaluations
        return

    # The adaptive rounds: the CPU search's rule (skidmc.solver.controller), on the meshed
    # target (exact and signs False) with the width never narrowed here.
    for round_ in range(MAX_ADAPTIVE_ROUNDS + 1):
        height, relative = richardson_value(math.exp(coarse[0]), math.exp(fine[0]))
        pair, estimate = pair_estimate(relative, coarse_level, melt_spread, False, False,
                                       melt_bias, coarse_tol, fine_tol)
        if round_ == MAX_ADAPTIVE_ROUNDS:
            break
        action, next_coarse_tol, next_fine_tol, value = next_round(
            rtol, estimate, pair, melt_bias, relative, height, coarse_level, coarse_tol,
            fine_tol, melt_width, 0, melt_spread, False, False)
        if action == DONE:
            break
        if action == TIGHTEN_FINE or action == TIGHTEN_BOTH:
            # Tighten the roots from their brackets.
            before = coarse[6] + fine[6]
            if action == TIGHTEN_BOTH:
                _tighten(row, sc, coarse_level, melt_width, next_coarse_tol, work, info, coarse)
            _tighten(row, sc, fine_level, melt_width, next_fine_tol, work, info, fine)
            evaluations += coarse[6] + fine[6] - before
            if coarse[7] == 0.0 or fine[7] == 0.0:
                out[OUT_STATUS], out[OUT_EVALUATIONS] = STATUS_CPU, evaluations
                return
        elif action == NARROW or (action == REFINE and fine_level + 1.0 > DEVICE_MAX_LEVEL):
            # The CPU search narrows the melting width (measuring its bias with an extra
            # simulation), or refines beyond this thread's arrays.
            out[OUT_STATUS], out[OUT_EVALUATIONS] = STATUS_CPU, evaluations
            return
        elif action == REFINE:
            # The next level's root predicted from this pair (value [m]); the pair moves up.
            for k in range(8):
                coarse[k] = fine[k]
            _search(row, sc, fine_level + 1.0, melt_width, math.log(value),
                    0.5 * abs(relative) + next_fine_tol, next_fine_tol, x_min, x_max, work,
                    info, fine)
            evaluations += fine[6]
            coarse_level, fine_level = fine_level, fine_level + 1.0
            if fine[7] == 0.0 or fine[1] != CENSOR_NONE:
                out[OUT_STATUS], out[OUT_EVALUATIONS] = STATUS_CPU, evaluations
                return
        else:   # STOP
            break
        coarse_tol, fine_tol = next_coarse_tol, next_fine_tol
    out[OUT_HEIGHT] = height
    out[OUT_CENSOR] = CENSOR_NONE
    # As the CPU search (search._censor_beyond_bounds): an extrapolation beyond a bound is
    # censored there.
    if height >= h_max:
        out[OUT_HEIGHT], out[OUT_CENSOR] = h_max, CENSOR_ABOVE
    elif height <= h_min:
        out[OUT_HEIGHT], out[OUT_CENSOR] = h_min, CENSOR_BELOW
    out[OUT_ERROR] = estimate
    out[OUT_EVALUATIONS] = evaluations
    out[OUT_LEVEL] = fine_level
    out[OUT_CORRECTION] = relative
    out[OUT_MELT_BIAS] = melt_bias


@njit(cache=True, parallel=True)
def critical_heights_cpu(rows, rtol, h_min, h_max, level, melt_width, melt_spread, x_tol,
                         melting, runaway_fraction, table, gl_x, gl_w, out):
    """:func:`critical_height_core` for every row of ``rows`` (shape (n, 19)) on the CPU's
    threads, each with its own NumPy scratch; results in ``out`` (shape (n, OUT_SIZE))."""
    for i in prange(rows.shape[0]):
        work = np.empty((WORK_ROWS, MAX_CELLS))
        fast_work = np.empty((3, N_TIMES))
        info = np.empty(1, dtype=KERNEL_RUN)   # every field written before it is read
        coarse = np.empty(8)
        fine = np.empty(8)
        critical_height_core(rows[i], rtol, h_min, h_max, level, melt_width, melt_spread, x_tol,
                             melting, runaway_fraction, table, gl_x, gl_w, work, fast_work,
                             info, coarse, fine, out[i])
