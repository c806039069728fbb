"""The full-tier critical-height search as one compiled function per sample (CPU or GPU thread).

:func:`critical_height_core` runs, for one scene given as a row of SI floats, the default
search of :func:`skidmc.solver.critical_height` on the same model: the exact target (only the
HE meshed, the target through Duhamel's integral), the melting spread over each HE cell, and
the scene's own plan (its regime, :func:`exit_regime_code`, chooses the first pair and its root
tolerances through the same compiled functions of :mod:`skidmc.solver.plan` and
:mod:`skidmc.solver.controller`). Then: the fast tier's height as first guess, a Richardson pair
of levels, its a posteriori error estimate, and the same adaptive rounds (tighten the roots, or
move the pair up a level) while that estimate exceeds ``rtol``: the estimate and each round's
decision are the compiled functions of :mod:`skidmc.solver.controller` that the CPU search calls
too. It calls the same compiled kernels as the CPU search
(:func:`skidmc.physics.thermal.simulate_core`, :func:`skidmc.physics.fast.fast_height_core`,
:func:`skidmc.physics.meshes.fill_meshes`, :func:`skidmc.physics.mechanics.impact_constants`
and the model's scalar functions), on storage the caller owns: NumPy arrays on the CPU, a
thread's local memory on the GPU (:mod:`skidmc.solver.cuda`). Nothing here allocates, raises or
touches Python objects, which is what a CUDA device function needs. One run at one height is
the CPU model's run to the last bit (:func:`device_margin`).

Where it differs from the CPU search, and why
---------------------------------------------
* Root finder: Brent's method (zeroin) on the margin m(ln H) = ln(t_ev / t_exit), capped at the
  horizon ln(t_end / t_exit) where no event happens, from a bracket grown geometrically around
  the guess (the CPU search's priors: the fast tier's measured scatter and shift, the fine
  root's measured place above the coarse one). The CPU search's guided, go-side and
  jump-aware finders (:mod:`skidmc.solver.roots`) keep a history of Python tuples and pick
  among strategies by it, and its runs share a linear prefix and stop at the exit where only
  the sign counts; Brent's bracket keeps every root within its tolerance on smooth margins and
  on jumps alike, and fits in a few registers. Both honour the same root tolerance on the same
  model, so the results agree within the tolerance (``tests/test_device.py`` and
  ``benchmarks/device_agreement.py`` measure it), not bit for bit.
* What is sent back to the CPU search (status :data:`STATUS_CPU`, the reason in
  ``out[OUT_REASON]``, :data:`HANDBACK_REASONS`): scenes whose ignition temperature lies below
  the melting point with melting modelled (the CPU search measures the melting width's bias
  there with an extra simulation and may narrow the width), pairs that ask for a narrower
  width, pairs that would have to move above :data:`DEVICE_MAX_LEVEL` (the thread's fixed-size
  arrays), runs that outgrow the thread's flux history (:data:`DEVICE_HISTORY`), and any search
  that fails (integration failure, no bracket within the evaluation cap): the CPU search then
  gives the result, or the failure with its reason. Scenes the row of floats cannot carry go
  there too, before any device work is trusted: layered targets whose heat reaches below the
  top layer, and targets whose properties follow a temperature table ("temperature_target"; the
  exact target has constant properties). The batch front end
  (:func:`skidmc.solver.cuda.solve_scenes`) does this; no sample is lost.
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
from skidmc.physics.mechanics import (
    EXIT_STOPS_SLIDING,
    STANDARD_GRAVITY,
    contact_pressure,
    impact_constants,
)
from skidmc.physics.meshes import fill_meshes
from skidmc.physics.records import HISTORY_ROWS, KERNEL_RUN, STATE_ROWS
from skidmc.physics.thermal import simulate_core
from skidmc.solver.controller import (
    DONE,
    MAX_ADAPTIVE_ROUNDS,
    NARROW,
    REFINE,
    TIGHTEN_BOTH,
    TIGHTEN_FINE,
    first_root_tolerances,
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
from skidmc.solver.options import FADING_EXIT_SPEED
from skidmc.solver.plan import (
    EXACT_FINE_SHIFT,
    EXACT_FINE_SHIFT_SPREAD,
    EXACT_STEADY_FINE_OVERSHOOT,
    exact_first_pair_level,
    melt_width_for_rtol,
    modelled_error,
)
from skidmc.solver.roots import FAST_GUESS_ERROR
from skidmc.solver.search import FADING_FAST_SHIFT, FADING_FAST_SPREAD, FAST_STOPS_SLIDING_SPREAD
from skidmc.solver.simulate import run_cap

__all__ = [
    "DEVICE_HISTORY",
    "DEVICE_MAX_LEVEL",
    "HANDBACK_REASONS",
    "HISTORY_SHAPE",
    "MAX_CELLS",
    "MAX_SEARCH_EVALUATIONS",
    "OUT_REASON",
    "OUT_SIZE",
    "STATUS_CPU",
    "STATUS_OK",
    "WORK_ROWS",
    "critical_height_core",
    "critical_heights_cpu",
    "device_margin",
    "exit_regime_code",
    "run_cap",
]

#: Finest level a device search refines to: its HE mesh holds 24 * 2**3 = 192 cells (and both
#: media's meshes, built first, 384 in the history's rows: :func:`_build_level`); a pair that
#: would need more goes to the CPU search (:data:`STATUS_CPU`). The first pairs of rtol 1e-2,
#: 3e-3 and 1e-3 are (0, 1), (0, 1) and (0.5, 1.5), and (1.5, 2.5) at 1e-3 where the root is
#: located by signs (:func:`skidmc.solver.plan.exact_first_pair_level`).
DEVICE_MAX_LEVEL = 3.0
#: Cells of the largest mesh a device search runs (the HE's: the exact target has none).
MAX_CELLS = int(round(BASE_RESOLUTION.cells_per_medium * 2.0**DEVICE_MAX_LEVEL))
#: Rows of the work array: the integrator's state (rows ``STATE_*`` of
#: :mod:`skidmc.physics.records`), then the HE mesh's width, rho c, face conductance.
_ROW_WIDTH, _ROW_RHO_C, _ROW_FACE = STATE_ROWS, STATE_ROWS + 1, STATE_ROWS + 2
WORK_ROWS = STATE_ROWS + 3
#: Accepted steps of one run the thread's flux history of the exact target holds; a run that
#: needs more sends its scene to the CPU search (:data:`HANDBACK_HISTORY`). Runs of the exact
#: target near the root on 50 scenes of the shipped studies took at most 113, 220, 486, 752,
#: 1,157 accepted steps at levels 0, 1, 2, 2.5, 3 (99th percentiles 110, 210, 458, 700, 1,068):
#: 1,536 holds level 3 with a third to spare, at 4 x 1,537 x 8 = 49 KB per thread. Its rows
#: (1,537 long) also hold both media's meshes while a level is built (:func:`_build_level`).
DEVICE_HISTORY = 1536
#: Shape of the history array of one thread (rows ``HISTORY_*`` of
#: :mod:`skidmc.physics.records`).
HISTORY_SHAPE = (HISTORY_ROWS, DEVICE_HISTORY + 1)
#: Most simulations one search at one level may use before it gives up (to the CPU search).
MAX_SEARCH_EVALUATIONS = 60

#: Result codes of :func:`critical_height_core` (``out[OUT_STATUS]``).
STATUS_OK, STATUS_CPU = 0, 1
#: Why a scene went to the CPU search (``out[OUT_REASON]``): an elastic target; melting with
#: the ignition temperature below the melting point; a search that failed (integration failure,
#: stall, no bracket within :data:`MAX_SEARCH_EVALUATIONS`, a refined root censored); a run
#: that outgrew :data:`DEVICE_HISTORY`; a narrower melting width; a level above
#: :data:`DEVICE_MAX_LEVEL`.
(HANDBACK_NONE, HANDBACK_ELASTIC, HANDBACK_IGNITION_BELOW_MELTING, HANDBACK_FAILED,
 HANDBACK_HISTORY, HANDBACK_NARROW, HANDBACK_LEVEL) = range(7)
#: Names of the ``HANDBACK_*`` codes, in order.
HANDBACK_REASONS = ("none", "elastic_target", "ignition_below_melting", "search_failed",
                    "history_full", "narrow_width", "level_cap")
#: How the heating ends (:func:`exit_regime_code`; :func:`skidmc.solver.options.exit_regime`).
REGIME_STEADY, REGIME_FADING, REGIME_STOPS_SLIDING = 0, 1, 2

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
OUT_REASON = 10         # HANDBACK_* (STATUS_CPU only)
OUT_SIZE = 11

# Columns of an input row: skidmc.solver.fast.SCENE_FIELDS (NUMERIC_KEYS order), SI units.
(_MU, _SIGMA, _MASS, _DIAMETER, _ANGLE, _TILT, _T0, _HE_RHO, _HE_C, _HE_K, _HE_L, _HE_TM, _Z,
 _TA, _Q, _TG_RHO, _TG_C, _TG_K, _TG_P) = range(19)

# Scalars shared by every level of one scene (the `sc` array).
# _S_MOST: the most step attempts of a run of the current search at its level (run_cap);
# _S_HISTORY_FULL: 1 once a run outgrew the thread's flux history (DEVICE_HISTORY).
(_S_OMEGA, _S_T_EXIT, _S_SLIDE_S, _S_SLIDE_C, _S_EXTENSION, _S_T_END, _S_FLUX,
 _S_LATENT, _S_RUNAWAY, _S_SPREAD, _S_MOST, _S_EFFUSIVITY, _S_HISTORY_FULL) = range(13)
_N_SCALARS = 13


@njit(cache=True)
def _build_level(row, sc, level, work, history):
    """HE mesh of ``level`` in the work rows; returns (cells, tol_T [K]).

    Both media are meshed as :func:`skidmc.solver.model.build_model` meshes them, in the first
    three rows of ``history`` (free between runs, and long enough for 2 :data:`MAX_CELLS`), and
    the HE's cells and faces are copied to the work rows: the exact target's model
    (``target="exact"``) is that HE mesh alone, the target entering through Duhamel's integral.
    """
    n_cells, first_fraction, tol_temperature = level_resolution(level)
    fill_meshes(row[_HE_RHO], row[_HE_C], row[_HE_K], row[_TG_RHO], row[_TG_C], row[_TG_K],
                row[_T0], row[_Z], row[_TA], sc[_S_T_EXIT], sc[_S_T_END], n_cells,
                first_fraction, DEPTH_DIFFUSION_LENGTHS, history[0], history[1], history[2])
    for i in range(n_cells):
        work[_ROW_WIDTH, i] = history[0, n_cells + i]
        work[_ROW_RHO_C, i] = history[1, n_cells + i]
    for i in range(n_cells - 1):
        work[_ROW_FACE, i] = history[2, n_cells + i]
    return n_cells, tol_temperature


@njit(cache=True)
def _margin(x, row, sc, n_cells, tol_temperature, melt_width, work, history, info):
    """Margin ln(t_ev / t_exit) at H = exp(x) [1], capped at the horizon ln(t_end / t_exit)
    (no event); NaN when the integration fails or stalls (:func:`run_cap`) or the run outgrows
    ``history`` (the search then goes to the CPU). Updates ``sc[_S_MOST]``, the most attempts
    of the search's runs.

    The run is the CPU search's model of the same scene and level
    (:func:`skidmc.solver.model.build_model` with ``target="exact"``, the default search's)
    run from t = 0: the same kernel on the same inputs, so the same margin to the last bit
    (``tests/test_device.py``). ``info`` (shape (1,), dtype
    :data:`skidmc.physics.records.KERNEL_RUN`) holds the run's input record, filled here, and
    its outcome; ``work`` the mesh and the integrator's state (:data:`WORK_ROWS`); ``history``
    the exact target's flux history (:data:`HISTORY_SHAPE`). No linear prefix, nothing
    recorded.
    """
    cap = run_cap(tol_temperature, sc[_S_MOST])
    q0 = sc[_S_FLUX] * math.sqrt(math.exp(x))
    run = info[0]
    inp = run.input
    inp.n = n_cells
    inp.n_target = 0
    inp.q_share_he = math.nan
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
    inp.target_effusivity = sc[_S_EFFUSIVITY]
    inp.he_conductivity = row[_HE_K]
    inp.sign_commit_fraction = 0.0
    inp.prefix_mode = 0
    inp.n_table = 0
    res = run.output
    simulate_core(inp, res, work[_ROW_WIDTH], work[_ROW_RHO_C], work[_ROW_FACE], work, history,
                  work[0], work[0], work[0], work[0])
    horizon = math.log(sc[_S_T_END] / sc[_S_T_EXIT])
    attempts = res.steps + res.rejected
    sc[_S_MOST] = max(sc[_S_MOST], attempts)
    if res.history_full:
        sc[_S_HISTORY_FULL] = 1.0
        return math.nan
    if res.failed or (attempts >= cap and not res.event):
        return math.nan
    t_ev = res.t_event
    if not (t_ev < math.inf):
        return horizon
    return min(math.log(t_ev / sc[_S_T_EXIT]), horizon)


@njit(cache=True)
def _brent(lo, f_lo, hi, f_hi, x_tol, row, sc, n_cells, tol_temperature, melt_width, work,
           history, info, budget):
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
        fb = _margin(b, row, sc, n_cells, tol_temperature, melt_width, work, history, info)
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
def _search(row, sc, level, melt_width, x_guess, step, x_tol, x_min, x_max, work, history,
            info, res):
    """One search at ``level``: bracket the root around ``x_guess`` (first step ``step``,
    doubling), then Brent to ``x_tol``. Writes ``res`` = (x_root, censor, lo, f_lo, hi, f_hi,
    evaluations, ok).

    A first step sized from the first margin and the margin's slope was tried: on the report
    presets it saved nothing and cost the stops-sliding scene (gold) 6 more simulations.
    """
    n_cells, tol_temperature = _build_level(row, sc, level, work, history)
    sc[_S_MOST] = 0.0   # the stall cap counts this search's runs (run_cap)
    x0 = min(max(x_guess, x_min), x_max)
    f0 = _margin(x0, row, sc, n_cells, tol_temperature, melt_width, work, history, info)
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
            fx = _margin(x, row, sc, n_cells, tol_temperature, melt_width, work, history, info)
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
            fx = _margin(x, row, sc, n_cells, tol_temperature, melt_width, work, history, info)
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
    lo, f_lo, hi, f_hi, n, ok = _brent(lo, f_lo, hi, f_hi, x_tol, row, sc, n_cells,
                                        tol_temperature, melt_width, work, history, info,
                                        MAX_SEARCH_EVALUATIONS - evaluations)
    res[0] = 0.5 * (lo + hi)
    res[2], res[3], res[4], res[5] = lo, f_lo, hi, f_hi
    res[6] = evaluations + n
    res[7] = 1.0 if ok else 0.0


@njit(cache=True)
def _tighten(row, sc, level, melt_width, x_tol, work, history, info, res):
    """Continue a search's Brent iteration from its final bracket to the tighter ``x_tol``;
    adds its simulations to ``res[6]``."""
    if res[1] != CENSOR_NONE:
        return
    n_cells, tol_temperature = _build_level(row, sc, level, work, history)
    sc[_S_MOST] = 0.0   # a new search at the tighter tolerance, as the CPU search's _tighten
    lo, f_lo, hi, f_hi, n, ok = _brent(res[2], res[3], res[4], res[5], x_tol, row, sc, n_cells,
                                       tol_temperature, melt_width, work, history, info,
                                       MAX_SEARCH_EVALUATIONS)
    res[0] = 0.5 * (lo + hi)
    res[2], res[3], res[4], res[5] = lo, f_lo, hi, f_hi
    res[6] += n
    res[7] = 1.0 if ok else 0.0


@njit(cache=True)
def exit_regime_code(slide_s, slide_c, omega, t_exit, exit_code):
    """How the scene's heating ends [int]: :data:`REGIME_STOPS_SLIDING`,
    :data:`REGIME_FADING` (a rebound whose sliding speed at the exit, report Eq. 10, is below
    :data:`skidmc.solver.options.FADING_EXIT_SPEED` of the initial one) or
    :data:`REGIME_STEADY`: :func:`skidmc.solver.options.exit_regime` from the impact's
    constants (:func:`skidmc.physics.mechanics.impact_constants`)."""
    if exit_code == EXIT_STOPS_SLIDING:
        return REGIME_STOPS_SLIDING
    speed_ratio = (slide_s - slide_c * (1.0 - math.cos(omega * t_exit))) / slide_s
    return REGIME_FADING if speed_ratio < FADING_EXIT_SPEED else REGIME_STEADY


@njit(cache=True)
def _hand_back(out, reason, evaluations):
    """The scene goes to the CPU search, with ``reason`` (``HANDBACK_*``)."""
    out[OUT_STATUS], out[OUT_REASON], out[OUT_EVALUATIONS] = STATUS_CPU, reason, evaluations


@njit(cache=True)
def _search_failed(sc):
    """Why a search that did not finish hands its scene back (``HANDBACK_*``)."""
    return HANDBACK_HISTORY if sc[_S_HISTORY_FULL] == 1.0 else HANDBACK_FAILED


@njit(cache=True)
def _fill_scalars(row, pressure, omega, t_exit, slide_s, slide_c, latent, runaway_fraction,
                  melt_spread, sc):
    """The scene's scalars shared by every level (``sc``, the ``_S_*`` layout), from the
    impact's constants (:func:`skidmc.physics.mechanics.impact_constants`) and the HE's latent
    heat as modelled [J/kg]."""
    extension, _ = flux_extension(omega, t_exit, slide_s, slide_c)
    sc[_S_OMEGA], sc[_S_T_EXIT], sc[_S_SLIDE_S], sc[_S_SLIDE_C] = omega, t_exit, slide_s, slide_c
    sc[_S_EXTENSION], sc[_S_T_END] = extension, HORIZON_EXIT_TIMES * t_exit
    sc[_S_FLUX] = row[_MU] * pressure * math.sqrt(2.0 * STANDARD_GRAVITY)
    sc[_S_LATENT], sc[_S_RUNAWAY], sc[_S_SPREAD] = latent, runaway_fraction, melt_spread
    sc[_S_EFFUSIVITY] = math.sqrt(row[_TG_K] * row[_TG_RHO] * row[_TG_C])
    sc[_S_MOST] = 0.0
    sc[_S_HISTORY_FULL] = 0.0


@njit(cache=True)
def _modelled_latent(row, melting, t_run):
    """The HE's latent heat as the model takes it [J/kg]: its heat of fusion where melting is
    modelled, the scene has friction and the HE melts below the runaway temperature ``t_run``
    [K] (the "melting" term of :func:`skidmc.solver.model.build_model`), else 0."""
    if melting and row[_HE_L] > 0.0 and row[_HE_TM] < t_run and row[_MU] > 0.0:
        return row[_HE_L]
    return 0.0


@njit(cache=True)
def _one_margin(row, x, level, melt_width, melt_spread, melting, runaway_fraction, work,
                history, sc, info):
    """:func:`device_margin`'s compiled part."""
    pressure = contact_pressure(row[_SIGMA], row[_TG_P])
    omega, _, t_exit, _, slide_s, slide_c = impact_constants(
        row[_MU], pressure, row[_MASS], row[_DIAMETER], row[_ANGLE], row[_TILT])
    t_run = model_runaway_temperature(row[_Z], row[_TA], row[_Q] / row[_HE_C], t_exit,
                                      runaway_fraction)
    latent = _modelled_latent(row, melting, t_run)
    _fill_scalars(row, pressure, omega, t_exit, slide_s, slide_c, latent, runaway_fraction,
                  melt_spread, sc)
    n_cells, tol_temperature = _build_level(row, sc, level, work, history)
    return _margin(x, row, sc, n_cells, tol_temperature, melt_width, work, history, info)


def device_margin(row, x, level, melt_width, melt_spread, melting=True, runaway_fraction=None):
    """The margin ln(t_ev / t_exit) [1] one device run computes at H = exp(``x``) [m].

    A diagnostic of what a thread runs: the scene ``row`` (:data:`skidmc.solver.fast.SCENE_FIELDS`
    order, SI) at ``level`` with melting width ``melt_width`` [K] and spread ``melt_spread`` [1],
    the search's first run (its stall cap :func:`run_cap` with no earlier runs); the horizon's
    margin without an event, NaN where the run fails, stalls or outgrows the thread's history.
    Equal to the last bit to :func:`skidmc.solver.simulate.simulate` at ``math.exp(x)`` (the
    height the CPU search simulates for its ``x``) of the CPU search's model
    (``build_model(scene, level=level, target="exact", ...)``) without a linear prefix, capped
    at the same horizon (``tests/test_device.py``).
    """
    from skidmc.physics.thermal import DEFAULT_RUNAWAY_FRACTION

    runaway = DEFAULT_RUNAWAY_FRACTION if runaway_fraction is None else float(runaway_fraction)
    return float(_one_margin(np.ascontiguousarray(row, dtype=np.float64), float(x),
                             float(level), float(melt_width), float(melt_spread), bool(melting),
                             runaway, np.empty((WORK_ROWS, MAX_CELLS)), np.empty(HISTORY_SHAPE),
                             np.empty(_N_SCALARS), np.empty(1, dtype=KERNEL_RUN)))


@njit(cache=True)
def critical_height_core(row, rtol, h_min, h_max, melt_spread, melting, runaway_fraction,
                         table, gl_x, gl_w, work, history, fast_work, info, coarse, fine, out):
    """The default full-tier search of one scene (module docstring); results in ``out``.

    Parameters
    ----------
    row : ndarray, shape (19,)
        The scene's inputs in the order of :data:`skidmc.solver.fast.SCENE_FIELDS` [SI].
    rtol : float
        Relative tolerance on the critical height [1].
    h_min, h_max : float
        Search bounds [m].
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
    history : ndarray, shape HISTORY_SHAPE
        The exact target's flux history of the current run.
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
        _hand_back(out, HANDBACK_ELASTIC, 0)
        return
    pressure = contact_pressure(row[_SIGMA], row[_TG_P])
    omega, _, t_exit, exit_code, slide_s, slide_c = impact_constants(
        mu, pressure, row[_MASS], row[_DIAMETER], row[_ANGLE], row[_TILT])
    out[OUT_EXIT_CODE] = exit_code
    out[OUT_EXIT_TIME] = t_exit
    # The first pair, its melting width and its root tolerances: the CPU default search's plan
    # (skidmc.solver.options.resolve_options with the exact target), from the same compiled
    # functions.
    regime = exit_regime_code(slide_s, slide_c, omega, t_exit, exit_code)
    signs = regime != REGIME_STEADY
    level = exact_first_pair_level(rtol, signs)
    melt_width = melt_width_for_rtol(rtol, level)
    coarse_tol, fine_tol = first_root_tolerances(rtol, level, melt_width, melt_spread, True,
                                                 signs)
    out[OUT_LEVEL] = level
    x_min, x_max = math.log(h_min), math.log(h_max)
    if not mu > 0.0:
        # No frictional heat, no event: censored above without a simulation ("no_friction").
        out[OUT_HEIGHT], out[OUT_CENSOR] = h_max, CENSOR_ABOVE
        out[OUT_ERROR] = modelled_error(level) + fine_tol
        return
    sc = fast_work[2]   # the scalars share the fast tier's last scratch row, used before it
    adiabatic_rise = row[_Q] / row[_HE_C]
    t_run = model_runaway_temperature(row[_Z], row[_TA], adiabatic_rise, t_exit,
                                      runaway_fraction)
    latent = _modelled_latent(row, melting, t_run)
    melting_term = latent > 0.0
    if melting_term and ignition_temperature(row[_Z], row[_TA], adiabatic_rise,
                                             t_exit) < row[_HE_TM]:
        # The CPU search measures the melting width's bias on such scenes (and may narrow it).
        _hand_back(out, HANDBACK_IGNITION_BELOW_MELTING, 0)
        return

    # First guess: the fast tier's height (its scratch rows 0-2 are free until `sc` is set),
    # with the CPU search's prior about it: where sliding stops the fast tier's measured
    # scatter, where the heating fades its measured shift and scatter.
    h_fast, censor_fast, _, _, _ = fast_height_core(
        mu, row[_SIGMA], row[_MASS], row[_DIAMETER], row[_ANGLE], row[_TILT], row[_T0],
        row[_HE_RHO], row[_HE_C], row[_HE_K], latent, row[_HE_TM], row[_Z], row[_TA], row[_Q],
        row[_TG_RHO], row[_TG_C], row[_TG_K], row[_TG_P], h_min, h_max, C_IGNITION, MELT_FACTOR,
        STOPS_SLIDING_FACTOR, table,
        gl_x, gl_w, N_TIMES, fast_work[0], fast_work[1], fast_work[2])
    if censor_fast == CENSOR_NONE and h_fast > 0.0:
        x_guess, guess_error = math.log(h_fast), FAST_GUESS_ERROR
        if regime == REGIME_STOPS_SLIDING:
            guess_error = FAST_STOPS_SLIDING_SPREAD
        elif regime == REGIME_FADING:
            x_guess, guess_error = x_guess + FADING_FAST_SHIFT, FADING_FAST_SPREAD
    else:
        x_guess, guess_error = 0.0, 1.0   # 1 m, and a first step of a factor e

    _fill_scalars(row, pressure, omega, t_exit, slide_s, slide_c, latent, runaway_fraction,
                  melt_spread, sc)

    coarse_level, fine_level = level - 1.0, level
    _search(row, sc, coarse_level, melt_width, x_guess, guess_error, coarse_tol,
            x_min, x_max, work, history, info, coarse)
    evaluations = coarse[6]
    if coarse[7] == 0.0:
        _hand_back(out, _search_failed(sc), evaluations)
        return
    # The fine root lies above the coarse one by a measured fraction of the coarse level's
    # modelled error (skidmc.solver.plan: EXACT_FINE_SHIFT with its spread where the root is
    # located by signs; on steady rebounds 0.30-0.39 of it, EXACT_STEADY_FINE_OVERSHOOT its
    # 90th percentile, so the bracket from there down half as far holds the medians).
    coarse_error = modelled_error(coarse_level)
    if coarse[1] != CENSOR_NONE:
        start, step = x_guess, coarse_error
    elif signs:
        start = coarse[0] + EXACT_FINE_SHIFT * coarse_error
        step = EXACT_FINE_SHIFT_SPREAD * coarse_error + 0.5 * coarse_tol
    else:
        start = coarse[0] + EXACT_STEADY_FINE_OVERSHOOT * coarse_error
        step = 0.5 * EXACT_STEADY_FINE_OVERSHOOT * coarse_error
    _search(row, sc, fine_level, melt_width, start, step, fine_tol,
            x_min, x_max, work, history, info, fine)
    evaluations += fine[6]
    if fine[7] == 0.0:
        _hand_back(out, _search_failed(sc), evaluations)
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

    # The adaptive rounds: the CPU search's rule (skidmc.solver.controller), on the exact
    # target with the width never narrowed here.
    for round_ in range(MAX_ADAPTIVE_ROUNDS + 1):
        height, relative = richardson_value(math.exp(coarse[0]), math.exp(fine[0]))
        pair, estimate = pair_estimate(relative, coarse_level, melt_spread, True, signs,
                                       melt_bias, coarse_tol, fine_tol)
        if round_ == MAX_ADAPTIVE_ROUNDS:
            break
        action, next_coarse_tol, next_fine_tol, value = next_round(
            rtol, estimate, pair, melt_bias, relative, height, coarse_level, coarse_tol,
            fine_tol, melt_width, 0, melt_spread, True, signs)
        if action == DONE:
            break
        if action == TIGHTEN_FINE or action == TIGHTEN_BOTH:
            # Tighten the roots from their brackets.
            before = coarse[6] + fine[6]
            if action == TIGHTEN_BOTH:
                _tighten(row, sc, coarse_level, melt_width, next_coarse_tol, work, history,
                         info, coarse)
            _tighten(row, sc, fine_level, melt_width, next_fine_tol, work, history, info, fine)
            evaluations += coarse[6] + fine[6] - before
            if coarse[7] == 0.0 or fine[7] == 0.0:
                _hand_back(out, _search_failed(sc), evaluations)
                return
        elif action == NARROW:
            # The CPU search narrows the melting width, measuring its bias with an extra
            # simulation.
            _hand_back(out, HANDBACK_NARROW, evaluations)
            return
        elif action == REFINE and fine_level + 1.0 > DEVICE_MAX_LEVEL:
            # Beyond this thread's arrays.
            _hand_back(out, HANDBACK_LEVEL, evaluations)
            return
        elif action == REFINE:
            # The next level's root predicted from this pair (value [m]); the pair moves up.
            for k in range(8):
                coarse[k] = fine[k]
            _search(row, sc, fine_level + 1.0, melt_width, math.log(value),
                    0.5 * abs(relative) + next_fine_tol, next_fine_tol, x_min, x_max, work,
                    history, info, fine)
            evaluations += fine[6]
            coarse_level, fine_level = fine_level, fine_level + 1.0
            if fine[7] == 0.0 or fine[1] != CENSOR_NONE:
                _hand_back(out, _search_failed(sc), evaluations)
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
def critical_heights_cpu(rows, rtol, h_min, h_max, melt_spread, melting, runaway_fraction,
                         table, gl_x, gl_w, out):
    """:func:`critical_height_core` for every row of ``rows`` (shape (n, 19)) on the CPU's
    threads, each with its own NumPy scratch; results in ``out`` (shape (n, OUT_SIZE))."""
    for i in prange(rows.shape[0]):
        work = np.empty((WORK_ROWS, MAX_CELLS))
        history = np.empty(HISTORY_SHAPE)
        fast_work = np.empty((3, N_TIMES))
        info = np.empty(1, dtype=KERNEL_RUN)   # every field written before it is read
        coarse = np.empty(8)
        fine = np.empty(8)
        critical_height_core(rows[i], rtol, h_min, h_max, melt_spread, melting,
                             runaway_fraction, table, gl_x, gl_w, work, history, fast_work,
                             info, coarse, fine, out[i])
