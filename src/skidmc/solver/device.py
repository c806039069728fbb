"""The full-tier critical-height search as one compiled function per sample (CPU or GPU thread).

:func:`critical_height_core` runs, for one scene given as a row of SI floats, the default
search of :func:`skidmc.solver.critical_height` on the same model: the exact target (only the
HE meshed, the target through Duhamel's integral), the melting spread over each HE cell, and
the scene's own plan (its regime, :func:`exit_regime_code`, chooses the first pair and its root
tolerances through the same compiled functions of :mod:`skidmc.solver.plan` and
:mod:`skidmc.solver.controller`). The search itself is not written here: it is the compiled
machine of :mod:`skidmc.solver.adaptive`, the CPU search's own, which this function drives with
its runs (:func:`_margin`: the same compiled kernel as the CPU search's,
:func:`skidmc.physics.thermal.simulate_core`, on storage the caller owns: NumPy arrays on the
CPU, a thread's local memory on the GPU, :mod:`skidmc.solver.cuda`), building a level's mesh
when the machine moves to it and starting the linear prefix and the stall cap anew with each of
its searches. The fast tier's height (:func:`skidmc.physics.fast.fast_height_core`) is the first
guess. Nothing here allocates, raises or touches Python objects, which is what a CUDA device
function needs.

One search, two drivers
-----------------------
Every decision of the search (which search, where to simulate next, when a root is found, the
pair's estimate and each round) is compiled code that both searches run; each only answers the
runs it asks for, the CPU search through :func:`skidmc.solver.simulate.simulate`, this one
through :func:`_margin` on the same kernel and inputs. One run at one height is the CPU model's
run to the last bit (:func:`device_margin`), so on the scenes it takes the device search finds
the CPU search's heights, error estimates and simulation counts to the last bit
(``tests/test_device.py``; ``benchmarks/heights_fingerprint.py``: 185 study and preset scenes at
rtol 1e-2, 3e-3 and 1e-3). Across machines the last bits may differ: the kernels' fused
multiply-adds are the compiling machine's choice (docs/model.md).

What is sent back to the CPU search
-----------------------------------
Status :data:`STATUS_CPU`, the reason in ``out[OUT_REASON]`` (:data:`HANDBACK_REASONS`): scenes
whose ignition temperature lies below the melting point with melting modelled (the CPU search
measures the melting width's bias there with an extra simulation and may narrow the width),
pairs that ask for a narrower width, pairs that would have to move above
:data:`DEVICE_MAX_LEVEL` (the thread's fixed-size arrays), runs that outgrow the thread's flux
history (:data:`DEVICE_HISTORY`), searches that need more than :data:`SEARCH_POINTS`
simulations, and any search that fails (integration failure, stall, a finder that ends without
a root): the CPU search then gives the result, or the failure with its
reason. Scenes the row of floats cannot carry go there too, before any device work is trusted:
layered targets whose heat reaches below the top layer, and targets whose properties follow a
temperature table ("temperature_target"; the exact target has constant properties). The batch
front end (:func:`skidmc.solver.cuda.solve_scenes`) does this; no sample is lost. Stalled runs
stop at the CPU search's cap, the same compiled function (:func:`skidmc.solver.simulate.run_cap`),
so a run that stalls hands its scene back after a few thousand attempts instead of 200,000.

The fast tier's first guess is censored near the search bounds by the CPU tier's own
compiled rule (:func:`skidmc.physics.fast.censor_near_bounds` with
:func:`skidmc.physics.fast.stated_error`, the self-heating flag from
:func:`skidmc.solver.model.rest_runaway_time`), so that a scene whose fast height lies within
its stated error of h_min or h_max starts where the CPU search starts.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from skidmc.physics.fast import (
    C_IGNITION,
    CENSOR_ABOVE,
    CENSOR_NONE,
    MELT_FACTOR,
    N_TIMES,
    STOPS_SLIDING_FACTOR,
    censor_near_bounds,
    fast_height_core,
    stated_error,
)
from skidmc.physics.mechanics import (
    EXIT_STOPS_SLIDING,
    STANDARD_GRAVITY,
    contact_pressure,
    impact_constants,
)
from skidmc.physics.meshes import fill_meshes
from skidmc.physics.records import HISTORY_ROWS, KERNEL_RUN, STATE_ROWS
from skidmc.physics.thermal import (
    _PX_VALID,
    PREFIX_WRITE,
    SIGN_COMMIT_FRACTION,
    prefix_size,
    simulate_core,
)
from skidmc.solver.adaptive import (
    ASK_RUN,
    BACK_LEVEL,
    BACK_NARROW,
    HAND_BACK,
    PAIR_STATE,
    PLAN_ADAPTIVE,
    POINTS_SHAPE,
    REGIME_FADING,
    REGIME_STEADY,
    REGIME_STOPS_SLIDING,
    RESULT_SIZE,
    SEARCH_POINTS,
    pair_start,
    pair_step,
)
from skidmc.solver.controller import first_root_tolerances
from skidmc.solver.finders import FINDER_STATE
from skidmc.solver.model import (
    BASE_RESOLUTION,
    DEPTH_DIFFUSION_LENGTHS,
    HORIZON_EXIT_TIMES,
    SELF_HEATING_TIME,
    flux_extension,
    ignition_temperature,
    level_resolution,
    model_runaway_temperature,
    rest_runaway_time,
)
from skidmc.solver.options import FADING_EXIT_SPEED
from skidmc.solver.plan import (
    exact_first_pair_level,
    melt_width_for_rtol,
    modelled_error,
)
from skidmc.solver.simulate import prefix_mode, run_cap

__all__ = [
    "DEVICE_HISTORY",
    "DEVICE_MAX_LEVEL",
    "HANDBACK_REASONS",
    "HISTORY_SHAPE",
    "MAX_CELLS",
    "POINTS_SHAPE",
    "PREFIX_SIZE",
    "RESULT_SIZE",
    "SEARCH_POINTS",
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
#: Length of a thread's linear prefix (:class:`skidmc.solver.simulate.LinearPrefix`) at the
#: finest mesh, :data:`MAX_CELLS` HE cells: 8.6 KB.
PREFIX_SIZE = int(prefix_size.py_func(MAX_CELLS))

#: Result codes of :func:`critical_height_core` (``out[OUT_STATUS]``).
STATUS_OK, STATUS_CPU = 0, 1
#: Why a scene went to the CPU search (``out[OUT_REASON]``): an elastic target; melting with
#: the ignition temperature below the melting point; a search that failed (integration failure,
#: stall, a finder that ends without a root, more points than :data:`SEARCH_POINTS`); a run
#: that outgrew :data:`DEVICE_HISTORY`; a narrower melting width; a level above
#: :data:`DEVICE_MAX_LEVEL`.
(HANDBACK_NONE, HANDBACK_ELASTIC, HANDBACK_IGNITION_BELOW_MELTING, HANDBACK_FAILED,
 HANDBACK_HISTORY, HANDBACK_NARROW, HANDBACK_LEVEL) = range(7)
#: Names of the ``HANDBACK_*`` codes, in order.
HANDBACK_REASONS = ("none", "elastic_target", "ignition_below_melting", "search_failed",
                    "history_full", "narrow_width", "level_cap")

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
# _S_PREFIX_H: the height [m] whose run recorded the search's linear prefix (0: none yet).
(_S_OMEGA, _S_T_EXIT, _S_SLIDE_S, _S_SLIDE_C, _S_EXTENSION, _S_T_END, _S_FLUX,
 _S_LATENT, _S_RUNAWAY, _S_SPREAD, _S_MOST, _S_EFFUSIVITY, _S_HISTORY_FULL,
 _S_PREFIX_H) = range(14)
_N_SCALARS = 14


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
def _margin(x, row, sc, n_cells, tol_temperature, melt_width, until_exit, work, history, info,
            prefix):
    """Margin ln(t_ev / t_exit) at H = exp(x) [1] and whether the event came by the exit
    (inf: no event within the horizon, or by the exit ``until_exit``); NaN when the
    integration fails or stalls (:func:`run_cap`) or the run outgrows ``history`` (the search
    then goes to the CPU). Updates ``sc[_S_MOST]``, the most attempts of the search's runs.

    The run is the CPU search's model of the same scene and level
    (:func:`skidmc.solver.model.build_model` with ``target="exact"``, the default search's)
    run from t = 0: the same kernel on the same inputs, so the same margin to the last bit as
    :func:`skidmc.solver.simulate.simulate` (``tests/test_device.py``), with ``until_exit`` as
    there (a run that stops at the exit, its go runs at the commit temperature). ``info``
    (shape (1,), dtype :data:`skidmc.physics.records.KERNEL_RUN`) holds the run's input record,
    filled here, and its outcome; ``work`` the mesh and the integrator's state
    (:data:`WORK_ROWS`); ``history`` the exact target's flux history (:data:`HISTORY_SHAPE`).
    ``prefix`` (length :data:`PREFIX_SIZE`; empty: none) is the search's linear prefix, used as
    the CPU search's :class:`skidmc.solver.simulate.LinearPrefix`: the search's first run
    records it, later runs within its scale resume from it (``sc[_S_PREFIX_H]``: the height that
    recorded it, 0 before). Nothing recorded.
    """
    cap = run_cap(tol_temperature, sc[_S_MOST])
    height = math.exp(x)
    q0 = sc[_S_FLUX] * math.sqrt(height)
    mode = prefix_mode(height, sc[_S_PREFIX_H]) if prefix.shape[0] > 0 else 0
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
    inp.t_stop = min(sc[_S_T_EXIT], sc[_S_T_END]) if until_exit else sc[_S_T_END]
    inp.initial_temperature = row[_T0]
    inp.tol_temperature = tol_temperature
    inp.dt_initial = 1e-6 * sc[_S_T_EXIT]
    inp.runaway_fraction = sc[_S_RUNAWAY]
    inp.max_steps = cap
    inp.n_record = 0
    inp.target_effusivity = sc[_S_EFFUSIVITY]
    inp.he_conductivity = row[_HE_K]
    inp.sign_commit_fraction = SIGN_COMMIT_FRACTION if until_exit else 0.0
    inp.prefix_mode = mode
    inp.n_table = 0
    res = run.output
    simulate_core(inp, res, work[_ROW_WIDTH], work[_ROW_RHO_C], work[_ROW_FACE], work, history,
                  work[0], work[0], prefix, work[0])
    if mode == PREFIX_WRITE and prefix[_PX_VALID] == 1.0:
        sc[_S_PREFIX_H] = height
    attempts = res.steps + res.rejected
    sc[_S_MOST] = max(sc[_S_MOST], attempts)
    if res.history_full:
        sc[_S_HISTORY_FULL] = 1.0
        return math.nan, False
    if res.failed or (attempts >= cap and not res.event):
        return math.nan, False
    t_ev = res.t_event
    if not (t_ev < math.inf):
        return math.inf, False
    return math.log(t_ev / sc[_S_T_EXIT]), res.event and t_ev <= sc[_S_T_EXIT]


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
    sc[_S_PREFIX_H] = 0.0


@njit(cache=True)
def _modelled_latent(row, melting, t_run):
    """The HE's latent heat as the model takes it [J/kg]: its heat of fusion where melting is
    modelled, the scene has friction and the HE melts below the runaway temperature ``t_run``
    [K] (the "melting" term of :func:`skidmc.solver.model.build_model`), else 0."""
    if melting and row[_HE_L] > 0.0 and row[_HE_TM] < t_run and row[_MU] > 0.0:
        return row[_HE_L]
    return 0.0


@njit(cache=True)
def _one_margin(row, x, level, melt_width, melt_spread, melting, runaway_fraction, until_exit,
                work, history, sc, info, prefix):
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
    return _margin(x, row, sc, n_cells, tol_temperature, melt_width, until_exit, work, history,
                   info, prefix)[0]


def device_margin(row, x, level, melt_width, melt_spread, melting=True, runaway_fraction=None,
                  until_exit=False):
    """The margin ln(t_ev / t_exit) [1] one device run computes at H = exp(``x``) [m].

    A diagnostic of what a thread runs: the scene ``row`` (:data:`skidmc.solver.fast.SCENE_FIELDS`
    order, SI) at ``level`` with melting width ``melt_width`` [K] and spread ``melt_spread`` [1],
    the search's first run (its stall cap :func:`run_cap` with no earlier runs); inf without an
    event, NaN where the run fails, stalls or outgrows the thread's history. Equal to the last
    bit to :func:`skidmc.solver.simulate.simulate` at ``math.exp(x)`` (the height the CPU search
    simulates for its ``x``) of the CPU search's model
    (``build_model(scene, level=level, target="exact", ...)``) without a linear prefix, with
    the same ``until_exit`` (``tests/test_device.py``).
    """
    from skidmc.physics.thermal import DEFAULT_RUNAWAY_FRACTION

    runaway = DEFAULT_RUNAWAY_FRACTION if runaway_fraction is None else float(runaway_fraction)
    return float(_one_margin(np.ascontiguousarray(row, dtype=np.float64), float(x),
                             float(level), float(melt_width), float(melt_spread), bool(melting),
                             runaway, bool(until_exit), np.empty((WORK_ROWS, MAX_CELLS)),
                             np.empty(HISTORY_SHAPE),
                             np.empty(_N_SCALARS), np.empty(1, dtype=KERNEL_RUN),
                             np.empty(0)))


@njit(cache=True)
def critical_height_core(row, rtol, h_min, h_max, melt_spread, melting, runaway_fraction,
                         table, gl_x, gl_w, work, history, fast_work, info, prefix, ps, res,
                         pts, st, fpts, out):
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
    prefix : ndarray, shape (PREFIX_SIZE,)
        The current search's linear prefix (:func:`_margin`).
    ps, res, pts, st, fpts : ndarray
        The search machine's storage (:func:`skidmc.solver.adaptive.new_storage`'s shapes and
        dtypes).
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
    # as the CPU search's _fast_guess takes it (the HE's heat of fusion unless melting is off),
    # none where it is censored, also within its stated error of a bound.
    fusion = row[_HE_L] if melting else 0.0
    h_fast, censor_fast, _, exit_fast, _ = fast_height_core(
        mu, row[_SIGMA], row[_MASS], row[_DIAMETER], row[_ANGLE], row[_TILT], row[_T0],
        row[_HE_RHO], row[_HE_C], row[_HE_K], fusion, row[_HE_TM],
        row[_Z], row[_TA], row[_Q], row[_TG_RHO], row[_TG_C], row[_TG_K], row[_TG_P], h_min,
        h_max, C_IGNITION, MELT_FACTOR, STOPS_SLIDING_FACTOR, table,
        gl_x, gl_w, N_TIMES, fast_work[0], fast_work[1], fast_work[2])
    self_heating = rest_runaway_time(row[_Z], row[_TA], adiabatic_rise,
                                     row[_T0]) < SELF_HEATING_TIME
    h_fast, censor_fast = censor_near_bounds(h_fast, censor_fast,
                                             stated_error(self_heating, exit_fast), h_min, h_max)
    if not (censor_fast == CENSOR_NONE and 0.0 < h_fast < math.inf):
        h_fast = math.nan

    _fill_scalars(row, pressure, omega, t_exit, slide_s, slide_c, latent, runaway_fraction,
                  melt_spread, sc)

    # The search itself: the machine of skidmc.solver.adaptive, the CPU search's own, answered
    # with this thread's runs (the mesh built when the level changes, the linear prefix and the
    # stall cap started anew with each search).
    horizon = math.log(sc[_S_T_END] / sc[_S_T_EXIT])
    code, value = pair_start(ps, res, pts, st, fpts, rtol, h_min, h_max, level, melt_width,
                             coarse_tol, fine_tol, melt_spread, True, signs, regime,
                             melting_term, False, False, DEVICE_MAX_LEVEL, False, h_fast,
                             math.nan, horizon, False, PLAN_ADAPTIVE, True)
    built, serial = -1.0, -1
    n_cells, tol_temperature = 0, 0.0
    while code == ASK_RUN:
        s = ps[0]
        if s.ask_level != built:
            n_cells, tol_temperature = _build_level(row, sc, s.ask_level, work, history)
            built = s.ask_level
        if s.serial != serial:
            sc[_S_MOST] = 0.0      # the stall cap counts this search's runs (run_cap)
            sc[_S_PREFIX_H] = 0.0  # and its first run records its linear prefix
            serial = s.serial
        m, event = _margin(value, row, sc, n_cells, tol_temperature, s.ask_width,
                           s.ask_until_exit == 1, work, history, info, prefix)
        code, value = pair_step(ps, res, pts, st, fpts, m, event)
    s = ps[0]
    if code == HAND_BACK:
        reason = _search_failed(sc)
        if s.reason == BACK_NARROW:
            reason = HANDBACK_NARROW   # the CPU search narrows the width, measuring its bias
        elif s.reason == BACK_LEVEL:
            reason = HANDBACK_LEVEL    # beyond this thread's arrays
        _hand_back(out, reason, s.evaluations)
        return
    out[OUT_HEIGHT] = s.out_height
    out[OUT_CENSOR] = s.out_censor
    out[OUT_ERROR] = s.out_error
    out[OUT_EVALUATIONS] = s.evaluations
    out[OUT_LEVEL] = s.out_level
    if s.extrapolated == 1:
        out[OUT_CORRECTION] = s.relative
        out[OUT_MELT_BIAS] = s.melt_bias


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
        prefix = np.empty(PREFIX_SIZE)         # written by each search's first run
        ps = np.empty(1, dtype=PAIR_STATE)     # every field written before it is read
        res = np.empty((2, RESULT_SIZE))
        pts = np.empty((2,) + POINTS_SHAPE)
        st = np.empty(1, dtype=FINDER_STATE)   # finder_reset before every use
        fpts = np.empty((2, SEARCH_POINTS))
        critical_height_core(rows[i], rtol, h_min, h_max, melt_spread, melting,
                             runaway_fraction, table, gl_x, gl_w, work, history, fast_work,
                             info, prefix, ps, res, pts, st, fpts,
                             out[i])
