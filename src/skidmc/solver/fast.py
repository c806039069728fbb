"""The fast tier at the scene level: critical heights of scenes by the reduced model.

The model and its compiled kernels are :mod:`skidmc.physics.fast` (its docstring derives the
model and states how its two constants were fitted and its error measured). This module feeds
scenes to those kernels and reports results as the full tier does: the same
:class:`~skidmc.solver.results.HeightResult`, with the terms and validity flags inferred by
:func:`skidmc.solver.model.build_model` (without its meshes), so that both tiers describe a scene
alike.
"""

from __future__ import annotations

import math
import operator

import numpy as np
from numba import njit

from skidmc.errors import SceneError
from skidmc.physics.fast import (
    _GL_W01,
    _GL_X01,
    C_IGNITION,
    CENSOR_NAMES,
    ERROR_ESTIMATE,
    MELT_FACTOR,
    MELT_TABLE,
    N_TIMES,
    STOPS_SLIDING_FACTOR,
    censor_near_bounds,
    duhamel_theta,
    fast_height_kernel,
    fast_heights_kernel,
    stated_error,
)
from skidmc.physics.mechanics import (
    EXIT_REBOUND,
    EXIT_STOPS_SLIDING,
    STANDARD_GRAVITY,
    contact_pressure,
    impact_constants,
)
from skidmc.scene.keys import (
    DEFAULT_TARGET_HARDNESS,
    FIELDS,
    INFINITE_OK,
    NUMERIC_KEYS,
    bound_reason,
    in_bounds,
)
from skidmc.solver.model import SELF_HEATING_TIME, build_model, rest_runaway_time
from skidmc.solver.results import HeightResult

__all__ = [
    "REFUSED_FLAGS",
    "SCENE_FIELDS",
    "fast_critical_height",
    "fast_critical_heights",
    "fast_error_bound",
    "fast_height",
    "scene_columns",
    "theta_history",
]

#: Scene attributes in the kernels' argument order: the numeric keys in the order of
#: :data:`skidmc.scene.keys.INPUT_KEYS` (a test checks it against the kernels' signatures).
SCENE_FIELDS: tuple[str, ...] = tuple(FIELDS[key] for key in NUMERIC_KEYS)

#: The scene's values in the kernels' argument order (a Scene stores validated floats).
_scene_values = operator.attrgetter(*SCENE_FIELDS)

#: Scene key (skidmc.scene.keys) of each field, for the errors of :func:`_check_columns`.
_KEY_OF_FIELD = {key.replace(".", "_"): key for key in NUMERIC_KEYS}

#: Validity flags of the regions where the fast tier is known to fail beyond its rebound-exit
#: bound: ``strict=True`` refuses them (docs/model.md, "Fast tier").
REFUSED_FLAGS = ("stops_sliding", "self_heating")

_EXIT_NAMES = {EXIT_REBOUND: "rebound", EXIT_STOPS_SLIDING: "stops_sliding"}


def theta_history(scene, n_times=N_TIMES):
    """Inert interface temperature rise per root height of a scene (for checks and figures).

    Parameters
    ----------
    scene : skidmc.scene.Scene
    n_times : int
        Number of uniform times in (0, t_exit].

    Returns
    -------
    times : ndarray
        [s].
    theta : ndarray
        Theta(t) [K/m^0.5]: T_s - T0 = sqrt(H) Theta(t) for an inert HE.
    """
    pressure = contact_pressure(scene.flow_stress, scene.target_hardness)
    omega, _, t_exit, _, s, c = impact_constants(scene.mu, pressure, scene.billet_mass,
                                              scene.billet_diameter, scene.angle, scene.tilt)
    e1 = math.sqrt(scene.he_conductivity * scene.he_density * scene.he_heat_capacity)
    e2 = math.sqrt(scene.target_conductivity * scene.target_density
                   * scene.target_heat_capacity)
    times = t_exit * np.arange(1, n_times + 1) / n_times
    theta = np.empty(n_times)
    flux_per_root_height = scene.mu * pressure * math.sqrt(2.0 * STANDARD_GRAVITY)
    duhamel_theta(flux_per_root_height, s, c, omega, t_exit, e1 + e2, times, _GL_X01, _GL_W01,
                  theta)
    return times, theta


def fast_error_bound(flags):
    """Stated relative error of a fast-tier height [1] for a scene with validity ``flags``.

    :data:`~skidmc.physics.fast.ERROR_SELF_HEATING` for a self-heating HE,
    :data:`~skidmc.physics.fast.ERROR_STOPS_SLIDING` where sliding stops before rebound, else
    :data:`~skidmc.physics.fast.ERROR_ESTIMATE` (each measured, with its coverage, by
    ``scripts/fast_tier_error.py``).
    """
    return stated_error("self_heating" in flags,
                        EXIT_STOPS_SLIDING if "stops_sliding" in flags else EXIT_REBOUND)


def fast_critical_height(scene, h_min=1e-3, h_max=1e4, *, melting=True, c_ign=C_IGNITION,
                         melt_factor=MELT_FACTOR, stops_factor=STOPS_SLIDING_FACTOR,
                         strict=False):
    """Critical drop height of a scene by the fast (reduced) tier [m].

    Parameters
    ----------
    scene : skidmc.scene.Scene
    h_min, h_max : float
        Search bounds [m]; no event at ``h_max`` is censored "above", an event at ``h_min``
        "below".
    melting : bool
        Account for melting of the HE (as the full model's switch).
    c_ign, melt_factor, stops_factor : float
        The fitted constants (defaults :data:`C_IGNITION`, :data:`MELT_FACTOR`,
        :data:`STOPS_SLIDING_FACTOR`), exposed for the fit in ``scripts/fast_tier_error.py``.

    strict : bool
        Refuse (raise :class:`SceneError`) scenes in the regions where the tier is known to
        fail beyond its rebound-exit bound (:data:`REFUSED_FLAGS`); by default they are
        answered with their own, larger stated error and their validity flags.

    Returns
    -------
    skidmc.solver.HeightResult
        ``evaluations=0`` (no PDE run), ``method="fast"``, ``error_estimate`` =
        :func:`fast_error_bound` of the scene's flags (measured, see
        results/benchmarks/fast_tier.md). A height within that error of ``h_max`` or ``h_min``
        is censored there (:func:`skidmc.physics.fast.censor_near_bounds`).
    """
    if not (0.0 < h_min < h_max):
        raise SceneError("h_min", h_min, f"need 0 < h_min < h_max (h_max = {h_max!r})")
    # Terms and validity flags (scene and height) as the full tier infers them, without meshes.
    # A tabled target's properties are held constant where that fits the tier's own stated
    # error (its error budget), else refused: the tier's target has constant properties.
    model = build_model(scene, melting=melting, meshes=False, rtol=ERROR_ESTIMATE)
    if "layered_target" in model.terms:
        raise SceneError("tier", "fast", "the fast tier's target is homogeneous, and this "
                         "stack's heat reaches below its top layer (use the full tier)")
    if "temperature_target" in model.terms:
        raise SceneError("tier", "fast", "the fast tier's target has constant properties, and "
                         "this target's k and c change over the interface's rise by more "
                         f"than the tier's error ({ERROR_ESTIMATE:g}; use the full tier, "
                         "or a material without a table, e.g. target.table = \"\")")
    error = fast_error_bound(model.flags)
    refused = [f for f in REFUSED_FLAGS if f in model.flags]
    if strict and refused:
        raise SceneError("tier", "fast", f"the fast tier is refused where the scene is "
                         f"{', '.join(refused)} (use the full tier)")
    height, censored, t_exit, ecode = fast_height(_scene_values(scene), error, h_min, h_max,
                                                  melting=melting, c_ign=c_ign,
                                                  melt_factor=melt_factor,
                                                  stops_factor=stops_factor)
    return HeightResult(critical_height=height, censored=censored, evaluations=0,
                        flags=model.flags + model.height_flags(height),
                        error_estimate=error, rtol=error, level=0.0,
                        method="fast", exit_time=float(t_exit),
                        exit_kind=_EXIT_NAMES[int(ecode)], terms=model.terms)


def fast_height(values, error, h_min, h_max, *, melting=True, c_ign=C_IGNITION,
                melt_factor=MELT_FACTOR, stops_factor=STOPS_SLIDING_FACTOR):
    """The fast tier's height of a scene given as its values, censored within ``error``.

    :func:`fast_critical_height` without its checks and result: what the full search's first
    guess needs (``skidmc.solver.search``, which has the scene's flags already).

    Parameters
    ----------
    values : sequence of float
        The scene's values in the order of :data:`SCENE_FIELDS` [SI].
    error : float
        The tier's stated error for the scene [1] (:func:`fast_error_bound` of its flags).
    h_min, h_max : float
        Search bounds [m].
    melting, c_ign, melt_factor, stops_factor
        As :func:`fast_critical_height`.

    Returns
    -------
    height : float
        [m]; ``h_max`` or ``h_min`` where censored there.
    censored : str or None
        "above", "below" or None.
    t_exit : float
        [s].
    exit_code : int
        :data:`skidmc.physics.mechanics.EXIT_KINDS` index.
    """
    args = list(values)
    if not melting:
        args[10] = 0.0
    h, cens, t_exit, ecode, _ = fast_height_kernel(
        *args, float(h_min), float(h_max), float(c_ign), float(melt_factor),
        float(stops_factor), MELT_TABLE, _GL_X01, _GL_W01, N_TIMES)
    # Within its stated error of a bound, censored there (the batch tier's and the device
    # search's rule, one compiled function).
    height, cens = censor_near_bounds(float(h), int(cens), error, float(h_min), float(h_max))
    censored = CENSOR_NAMES[int(cens)]
    height = {"above": h_max, "below": h_min}.get(censored, float(height))
    return height, censored, float(t_exit), int(ecode)


def fast_critical_heights(h_min=1e-3, h_max=1e4, *, melting=True, c_ign=C_IGNITION,
                          melt_factor=MELT_FACTOR, stops_factor=STOPS_SLIDING_FACTOR,
                          **columns):
    """Critical heights of many scenes in one compiled call [m].

    Parameters
    ----------
    h_min, h_max : float
        Search bounds [m].
    melting : bool
        Account for melting.
    c_ign, melt_factor, stops_factor : float
        Fitted constants.
    **columns : array_like
        One 1-D array (or scalar, broadcast) per name of :data:`SCENE_FIELDS` (Scene attribute
        names, SI units, angles in degrees). All are required.

    Raises
    ------
    SceneError
        A value a :class:`~skidmc.scene.Scene` would refuse (the full tier's ranges), naming
        the key, the value and its row; or ``h_min``, ``h_max`` out of order.

    Returns
    -------
    dict
        ``critical_height`` [m] (the bound for censored rows), ``censored`` (int codes
        :data:`CENSOR_NONE`/``ABOVE``/``BELOW``), ``exit_time`` [s], ``exit_code``,
        ``error_estimate`` [1] (:func:`fast_error_bound`; heights within it of a bound are
        censored there, as :func:`fast_critical_height` does).
    """
    # A batch that does not give the target's hardness has the report's rigid target.
    columns.setdefault("target_hardness", DEFAULT_TARGET_HARDNESS)
    missing = [f for f in SCENE_FIELDS if f not in columns]
    if missing:
        raise TypeError(f"missing columns: {missing}")
    if not (0.0 < h_min < h_max):
        raise SceneError("h_min", h_min, f"need 0 < h_min < h_max (h_max = {h_max!r})")
    arrays = np.broadcast_arrays(*[np.asarray(columns[f], dtype=float) for f in SCENE_FIELDS])
    arrays = [np.array(np.atleast_1d(a), dtype=float) for a in arrays]  # own, writable copies
    _check_columns(arrays)
    hardness = arrays[SCENE_FIELDS.index("target_hardness")]
    if (hardness == 0.0).any():
        row = int(np.argmax(hardness == 0.0))
        raise SceneError("target.hardness", 0.0, "an elastic target (rubber) cannot be "
                         "described by the report's plastic-contact model (docs/model.md, "
                         f"targets softer than the billet) (row {row})")
    if not melting:
        arrays[10] = np.zeros_like(arrays[10])
    n = arrays[0].shape[0]
    out_h = np.empty(n)
    out_c = np.empty(n, dtype=np.int64)
    out_t = np.empty(n)
    out_e = np.empty(n, dtype=np.int64)
    fast_heights_kernel(*arrays, float(h_min), float(h_max), float(c_ign), float(melt_factor),
                        float(stops_factor), MELT_TABLE, _GL_X01, _GL_W01, N_TIMES, out_h, out_c,
                        out_t, out_e)
    col = dict(zip(SCENE_FIELDS, arrays))
    error = np.empty(n)
    _censor_rows(col["kinetics_prefactor"], col["kinetics_activation_temperature"],
                 col["kinetics_heat_of_reaction"], col["he_heat_capacity"],
                 col["initial_temperature"], float(h_min), float(h_max), out_h, out_c, out_e,
                 error)
    return {"critical_height": out_h, "censored": out_c, "exit_time": out_t,
            "exit_code": out_e, "error_estimate": error}


@njit(cache=True)
def _censor_rows(prefactor, activation_temperature, heat_of_reaction, he_heat_capacity,
                 initial_temperature, h_min, h_max, height, censor, exit_code, error):
    """Each row's stated error [1] into ``error``, and its height censored near the bounds in
    place (``height`` [m], ``censor``): the scalar tier's rule
    (:func:`skidmc.physics.fast.stated_error`, :func:`skidmc.physics.fast.censor_near_bounds`)
    row by row, with the full tier's self-heating rule
    (:func:`skidmc.solver.model.rest_runaway_time`)."""
    for i in range(height.shape[0]):
        rest = rest_runaway_time(prefactor[i], activation_temperature[i],
                                 heat_of_reaction[i] / he_heat_capacity[i],
                                 initial_temperature[i])
        error[i] = stated_error(rest < SELF_HEATING_TIME, exit_code[i])
        height[i], censor[i] = censor_near_bounds(height[i], censor[i], error[i], h_min, h_max)


def _check_columns(arrays):
    """Raise :class:`SceneError` for the first value a :class:`Scene` would refuse.

    The same ranges as the full tier's scenes (:func:`skidmc.scene.keys.in_bounds`, every value
    finite, T0 below the melting point), checked on whole columns; the error names the scene key,
    the first offending value and its row.
    """
    for field, values in zip(SCENE_FIELDS, arrays):
        key = _KEY_OF_FIELD[field]
        finite = np.isfinite(values) | ((values == np.inf) if key in INFINITE_OK else False)
        bad = ~(finite & in_bounds(key, values))
        if bad.any():
            row = int(np.argmax(bad))
            raise SceneError(key, float(values[row]), f"{bound_reason(key)} (row {row})")
    t0 = arrays[SCENE_FIELDS.index("initial_temperature")]
    t_m = arrays[SCENE_FIELDS.index("he_melting_point")]
    bad = ~(t0 < t_m)
    if bad.any():
        row = int(np.argmax(bad))
        raise SceneError("initial_temperature", float(t0[row]),
                         f"must be below he.melting_point ({float(t_m[row]):g} K) (row {row})")


def scene_columns(scenes):
    """Columns of :data:`SCENE_FIELDS` from a sequence of scenes.

    For :func:`fast_critical_heights`.
    """
    return {f: np.array([float(getattr(s, f)) for s in scenes]) for f in SCENE_FIELDS}
