"""Model inference: what one scene needs, turned into the kernels' SI arrays.

A :class:`SkidModel` is built once per scene (it does not depend on the drop
height: the contact time and the exit time are height-independent, report II.B-D)
and is then simulated at as many heights as the critical-height search needs.

Inference follows the scene, so a scene that needs nothing more gets nothing more:

* the normal-force moment (b' of Eq. 10) only when the billet is tilted (psi > 0,
  vertical drops); for the pendulum (psi = 0) only friction spins the billet;
* melting only when the HE has a heat of fusion, melting is switched on, and the
  melting point lies below the runaway temperature (otherwise no cell can melt
  before the event is declared, so the enthalpy plateau can never be reached);
* each medium's mesh depth from its own diffusion length over the simulated time,
  its first cell from the estimated thickness of the reaction zone at ignition;
* a frictionless scene (mu = 0) generates no heat and needs no simulation at all.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field

import numpy as np
from numba import njit

from skidmc.errors import SceneError
from skidmc.physics import mechanics
from skidmc.physics.meshes import (
    fill_meshes,
    geometric_ratio,
    layered_target_cells,
    reaction_zone,
)
from skidmc.physics.thermal import DEFAULT_RUNAWAY_FRACTION, runaway_temperature
from skidmc.scene.materials import parse_layers, parse_table

__all__ = [
    "BASE_RESOLUTION",
    "CRUSH_DEPTH_FRACTION",
    "DEPTH_DIFFUSION_LENGTHS",
    "EARLY_STOP_FRACTION",
    "HORIZON_EXIT_TIMES",
    "HOT_IGNITION_TEMPERATURE",
    "LONG_SLIDE_DIAMETERS",
    "MELT_WIDTH_BIAS_PER_K",
    "MELT_WIDTH_LEVEL0",
    "PROPERTY_BUDGET_FRACTION",
    "Resolution",
    "SELF_HEATING_TIME",
    "ModelBuilder",
    "SkidModel",
    "build_model",
    "elastic_target_reason",
    "estimated_reaction_zone",
    "flux_extension",
    "ignition_temperature",
    "model_runaway_temperature",
    "geometric_widths",
    "level_resolution",
    "melt_width_floor",
    "resolution_for_level",
    "rest_runaway_time",
    "target_layers",
    "target_property_change",
    "target_property_table",
    "target_temperature_range",
    "constant_properties",
    "constant_property_scene",
]

#: Integration horizon, in exit times. Beyond the exit the flux is extended (see
#: :attr:`SkidModel.extension_flux_factor`) only to give the critical-height search
#: a continuous margin; the go/no-go verdict only looks at events before t_exit.
HORIZON_EXIT_TIMES = 4.0

#: Depth of each medium's mesh in diffusion lengths sqrt(alpha t_end). With t_end =
#: 4 t_exit this is 4 sqrt(alpha t_exit): the insulated far end (an image source at twice its
#: depth) changes the surface temperature under a constant flux by 2 ierfc(4) / ierfc(0)
#: ~ 7e-9 of its rise at t_exit, which decides go/no-go, and by 2 ierfc(2) / ierfc(0) ~ 3e-3
#: at t_end, late in the flux extension that only shapes the search margin. A shallower mesh
#: puts its cells where the heat is: at level 1.5 the
#: critical height's error is 0.8-0.9e-3 with depth 2 against 1.1e-3 with depth 4 (same cells,
#: same cost), and the levels converge cleanly at second order from level 0 (measured on the
#: report presets, results/validation/refinement.md).
DEPTH_DIFFUSION_LENGTHS = 2.0


# --- Validity flags (docs/model.md, "Validity flags"). Each marks a scene, or a result, where
# the report's model is stretched beyond what it can support; the number is still computed.
# Names are short: storage keeps the comma-separated flags in 64 characters.

#: "stops_early": sliding stops before this fraction of the contact time t_c. The contact area
#: (pi D X, X ~ sin(omega t)) is then under sin(pi/8) = 38 % of its maximum and still growing
#: fast, and the result hangs on Eq. (10)'s stop criterion (the contact sticks for good once V_r
#: reaches 0; re-sliding under the still-rising normal load is not modelled).
EARLY_STOP_FRACTION = 0.25

#: "self_heating": the unheated HE at T0 runs away (adiabatic induction time, or reaction time
#: 1/k for a weakly exothermic HE) within this time [s]: a billet with these kinetics could not be
#: held at T0, and a height, if one is found, is not a friction result.
SELF_HEATING_TIME = 3600.0

#: A target with a temperature table (``target.table``) keeps constant properties (those of its
#: scene, the table's values at its reference temperature) where the bound on their effect on
#: the critical height, |ln k(T) / k| + |ln c(T) / c| at worst over T0 to the interface's highest
#: temperature (:func:`target_property_change`), is within this fraction of the search's rtol;
#: otherwise it takes k(T), c(T) in every target cell ("temperature_target"). The bound: the
#: interface's rise under a flux q is ~ q sqrt(t) / (e_HE + e_t) (report Eq. 16's split), and
#: q ~ sqrt(H), so at a fixed ignition temperature H ~ (e_HE + e_t)^2 and |d ln H| <= 2 |d ln e_t|
#: = |d ln k| + |d ln c|. It overstates the measured effect 1.5-3.5 fold (constant
#: properties at the interface's mean temperature moved ln H_c by 0.31-0.37 where the bound
#: gives 0.54-1.08: results/validation/temperature_dependence.md). A tenth of rtol leaves the
#: rest of the budget to the discretisation, melting width and root (skidmc.solver.plan).
PROPERTY_BUDGET_FRACTION = 0.1

#: "hot_ignition": the kinetics need the HE above this temperature [K] to run away within the
#: heating time (the temperature at which the adiabatic induction time equals t_exit, a lower
#: bound on the surface temperature at ignition). Beyond it the HE would be a vaporising melt
#: and the targets near or past melting (copper 1358 K) while the model keeps room-temperature
#: properties, and the kinetics are extrapolated far from any measurement.
HOT_IGNITION_TEMPERATURE = 1000.0

#: "crushed" (per height): the indentation depth X_max = V_n0 / omega exceeds this fraction of
#: the diameter D: the cap law a^2 = D X is off by more than 10 % and the hemisphere's rigid-body
#: kinematics (Eq. 10) no longer describe a billet flattened by a fifth of its height.
CRUSH_DEPTH_FRACTION = 0.1

#: "long_slide" (per height): the contact slides over more than this many maximum contact
#: diameters d_c (Eq. 5) while heating. The model keeps the target under the contact fixed; in
#: fact fresh, cold target keeps arriving, which draws more heat from the HE, so the height is
#: then conservative (too low).
LONG_SLIDE_DIAMETERS = 1.0

#: What each validity flag means for the reported height, in one line (for ``skidmc height``
#: and reports; the full table with the criteria is in docs/model.md, "Validity flags").
FLAG_MEANINGS: dict[str, str] = {
    "no_friction": "mu = 0: no frictional heat, so no event; censored above without a "
                   "simulation",
    "stops_sliding": "the billet stops sliding before it rebounds: frictional heating ends "
                     "early (Eq. 10)",
    "stops_early": f"sliding stops within {EARLY_STOP_FRACTION:g} of the contact time: the "
                   "height hangs on Eq. (10)'s stop rule and is very sensitive to the angle "
                   "and mu",
    "self_heating": f"the unheated HE at T0 runs away within {SELF_HEATING_TIME:g} s: a "
                    "billet with these kinetics cannot be held at T0; not a friction result",
    "hot_ignition": f"ignition needs the HE above {HOT_IGNITION_TEMPERATURE:g} K: a vaporising "
                    "melt, room-temperature properties and kinetics far from data",
    "crushed": f"at this height the indentation exceeds {CRUSH_DEPTH_FRACTION:g} D: the "
               "billet is flattened and the contact model (cap law, rigid hemisphere) fails",
    "long_slide": f"the contact slides over more than {LONG_SLIDE_DIAMETERS:g} contact "
                  "diameter(s) while heating: fresh cold target is ignored, so the real height "
                  "is higher (the model is conservative)",
    "layered_target": "the heat reaches below the target's top layer: the layers are meshed "
                      "(docs/targets.md)",
    "top_layer_only": "a layered target whose top layer is thicker than the heat reaches: "
                      "the homogeneous top layer is used (docs/targets.md)",
    "temperature_target": "the target's k and c change with temperature by more than the "
                          "error budget over the interface's rise: they follow the "
                          "material's table in every target cell (docs/targets.md)",
    "constant_target": "the target has a temperature table, but its rise changes k and c "
                       "by less than the error budget: constant properties at the table's "
                       "reference temperature (docs/targets.md)",
    "yielding_target": "the target yields below the billet's flow stress: the contact "
                       "pressure is the target's hardness (longer, gentler contact, less "
                       "frictional heat; docs/model.md, targets softer than the billet)",
}


def elastic_target_reason(scene):
    """Why the solver refuses a scene's target, or None: an elastic target
    (``target.hardness`` = 0, ``"elastic"``, the registry's rubber).

    The report's impact is plastic at a constant contact pressure (Sec. II.B) and its heat is
    friction at that pressure (Eq. 1). An elastomer does not flow: its contact pressure grows
    with its compression (Hertz, then the mat's thickness bottoming out on the floor beneath),
    the billet rebounds elastically, and the heat comes partly from the rubber's hysteresis.
    None of Eqs. (2)-(10) describes that, so no height is given rather than a number the model
    cannot support.
    """
    if scene.target_hardness > 0.0:
        return None
    return ("an elastic target (rubber) cannot be described by the report's plastic-contact "
            "model (constant contact pressure, Sec. II.B; heat mu p V_r, Eq. 1): its pressure "
            "grows with compression until a mat bottoms out on the floor beneath, and the "
            "billet rebounds elastically; give the floor beneath (e.g. target = \"concrete\") "
            "or a yield pressure (target.hardness) to bound it")


@dataclass(frozen=True)
class Resolution:
    """Numerical resolution of one simulation.

    Attributes
    ----------
    cells_per_medium : int
        Number of finite-volume cells in each medium [1].
    first_cell_fraction : float
        Width of the first HE cell, as a fraction of the estimated reaction-zone
        thickness at ignition [1].
    tol_temperature : float
        Local error tolerance of the BDF2 step controller [K].
    melt_width : float
        Width w [K] of the smoothed melting step (see skidmc.physics.thermal._he_enthalpy).
    melt_spread : float
        0 (default): the step has the width w in every HE cell. s > 0 widens each cell's step
        to sqrt(w^2 + (s dT)^2), dT its temperature range (experimental; see
        skidmc.physics.thermal._he_cell_enthalpy and docs/model.md) [1].
    """

    cells_per_medium: int
    first_cell_fraction: float
    tol_temperature: float
    melt_width: float
    melt_spread: float = 0.0


#: Melting-step width at level 0 [K]; the width at level L is at least
#: MELT_WIDTH_LEVEL0 * 2**-L (:func:`melt_width_floor`), the rule with which the levels' error
#: model (skidmc.solver.ERROR_LEVEL0, RICHARDSON_ERROR_LEVEL0) was first calibrated
#: (results/validation/refinement.md). A much narrower step is not resolved by the level's
#: cells and steps (level 1 with w = 0.013 K is off by 8e-3); at the floor the width's bias is
#: part of the level's modelled error. Above it, w is not a refinement parameter: its bias
#: on the critical height is first order in w (below), and the number of time steps grows
#: steeply as w shrinks (each HE cell's melting kink must be resolved: 3,356 steps at level 3
#: with w = 0.25 K, 729 with w = 2 K). The solver therefore picks w from its tolerance
#: (skidmc.solver.plan.melt_width_for_rtol) and keeps it the same at every level of one search.
MELT_WIDTH_LEVEL0 = 2.0

#: Bound on the critical height's relative bias per kelvin of melting width [1/K]: measured
#: at level 2.5 against the sharp limit (``python scripts/melt_width_bias.py``,
#: results/validation/melt_width_bias.md): close to first order in w, largest per kelvin for
#: narrow steps (~1.8e-4/K at w <= 0.5 K on paper-quartz, ~1.3e-4/K at 2 K, ~0.9e-4/K at 4 K).
MELT_WIDTH_BIAS_PER_K = 2.0e-4

#: Base resolution (level 0). Each level doubles the cells, halves the first cell and
#: divides the step tolerance by 8 (BDF2: step ~ tol^(1/3), so the time step halves),
#: so that both spatial and temporal errors fall ~4x per level (second order).
BASE_RESOLUTION = Resolution(cells_per_medium=24, first_cell_fraction=0.5, tol_temperature=0.5,
                             melt_width=MELT_WIDTH_LEVEL0)


@njit(cache=True)
def melt_width_floor(level):
    """Narrowest melting-step width used at refinement level ``level`` [K]."""
    return MELT_WIDTH_LEVEL0 * 2.0 ** (-level)


@functools.lru_cache(maxsize=256, typed=True)
def resolution_for_level(level, melt_width=None, melt_spread=0.0):
    """Resolution of refinement level ``level`` (float allowed) [see :data:`BASE_RESOLUTION`].

    ``melt_width`` [K] is carried unchanged; default :func:`melt_width_floor` of ``level``.
    ``melt_spread`` [1]: see :class:`Resolution`.
    Cached (by value and type, so a result never depends on an earlier call): a
    :class:`Resolution` is immutable, and every model (the fast tier's mesh-less one
    included, built per result) asks for one of a few levels.
    """
    if melt_width is None:
        melt_width = melt_width_floor(level)
    cells, first_cell_fraction, tol_temperature = level_resolution(float(level))
    return Resolution(cells_per_medium=int(cells), first_cell_fraction=float(first_cell_fraction),
                      tol_temperature=float(tol_temperature), melt_width=float(melt_width),
                      melt_spread=float(melt_spread))


@njit(cache=True)
def level_resolution(level):
    """(cells per medium, first cell fraction, step tolerance [K]) of refinement ``level``:
    :data:`BASE_RESOLUTION` with twice the cells, half the first cell and an eighth of the
    step tolerance per level (compiled, for a GPU thread too)."""
    scale = 2.0 ** level
    cells = max(8, int(round(_BASE_CELLS * scale)))
    return cells, _BASE_FIRST_FRACTION / scale, _BASE_TOL_TEMPERATURE / scale**3


_BASE_CELLS = float(BASE_RESOLUTION.cells_per_medium)
_BASE_FIRST_FRACTION = BASE_RESOLUTION.first_cell_fraction
_BASE_TOL_TEMPERATURE = BASE_RESOLUTION.tol_temperature


def geometric_widths(first_width, depth, n_cells):
    """Cell widths [m] of a geometric mesh of ``n_cells`` cells, ``depth`` deep.

    The first cell is ``first_width`` wide; the growth ratio is
    :func:`skidmc.physics.meshes.geometric_ratio` (a uniform mesh when even a uniform mesh of
    ``first_width`` cells is deeper than ``depth``).
    """
    r = geometric_ratio(first_width, depth, n_cells)
    return first_width * r ** np.arange(n_cells, dtype=float)


def estimated_reaction_zone(model_time, he_diffusivity, initial_temperature, prefactor,
                            activation_temperature):
    """Rough thickness of the reacting layer at ignition [m], used only to size the mesh
    (:func:`skidmc.physics.meshes.reaction_zone`)."""
    return float(reaction_zone(model_time, he_diffusivity, initial_temperature, prefactor,
                               activation_temperature))


@dataclass
class SkidModel:
    """Everything the kernels need for one scene, independent of the drop height.

    Built by :func:`build_model`. Heights enter only through the flux amplitude
    q0 = mu sigma sqrt(2 g H) (Eqs. 1, 10).
    """

    # Mechanics (Eqs. 1-10)
    omega: float                  # [rad/s]
    contact_time: float           # t_c [s]
    exit_time: float              # t_exit [s]
    exit_kind: str                # "rebound" | "stops_sliding"
    slide_s: float                # sin(phi) [1]
    slide_c: float                # C cos(phi) [1]
    flux_per_root_height: float   # mu sigma sqrt(2 g) [W/m^2 / m^0.5]
    extension_flux_factor: float  # q_ext / q0 after t_exit [1]
    end_time: float               # t_end [s]
    # Thermal
    width: np.ndarray             # [m]
    rho_c: np.ndarray             # [J/(m^3 K)]
    face_conductance: np.ndarray  # [W/(m^2 K)]
    n_target: int
    q_share_he: float             # [1]
    he_density: float             # [kg/m^3]
    latent_heat: float            # [J/kg] (0 when melting is not modelled)
    melting_point: float          # [K]
    prefactor: float              # [1/s]
    activation_temperature: float  # [K]
    heat_of_reaction: float       # [J/kg]
    initial_temperature: float    # [K]
    runaway_temperature: float    # [K]
    # Numerics
    resolution: Resolution
    runaway_fraction: float
    dt_initial: float             # [s]
    terms: tuple = field(default_factory=tuple)
    flags: tuple = field(default_factory=tuple)
    # Validity diagnostics (see the flags at the top of this module)
    ignition_temperature: float = math.nan  # T at which tau_ad = t_exit [K] (inf: never)
    rest_time: float = math.inf       # runaway time of the unheated HE at T0 [s]
    billet_diameter: float = math.nan  # D [m]
    indent_per_root_height: float = 0.0  # X_max / sqrt(H) = sqrt(2 g) cos(phi) / omega [m^0.5]
    slide_per_root_height: float = 0.0   # sliding distance / sqrt(H) while heating [m^0.5]
    # The exact target (``build_model(..., target="exact")``; n_target = 0): its effusivity
    # sqrt(k rho c) [W s^0.5 / (m^2 K)] and the HE's conductivity k [W/(m K)]; 0 when meshed.
    target_effusivity: float = 0.0
    he_conductivity: float = 0.0
    # A temperature-dependent target ("temperature_target"): the kernel's table
    # (skidmc.physics.thermal.target_properties: T [K], k [W/(m K)], rho c [J/(m^3 K)],
    # H [J/m^3] at each node); empty with constant properties.
    target_table: np.ndarray = field(default_factory=lambda: np.zeros(0))

    def flux_amplitude(self, height):
        """q0 = mu sigma V0 [W/m^2] for drop height ``height`` [m] (Eqs. 1, 10)."""
        return self.flux_per_root_height * math.sqrt(height)

    def height_flags(self, height):
        """Validity flags that depend on the drop height ``height`` [m] (tuple of str).

        ``"crushed"``: indentation depth X_max > :data:`CRUSH_DEPTH_FRACTION` D.
        ``"long_slide"``: sliding distance while heating > :data:`LONG_SLIDE_DIAMETERS` d_c.
        Both grow with H, so for a result censored "above" they are checked at ``h_max``.
        """
        if "no_friction" in self.flags or not height > 0.0:
            return ()
        root = math.sqrt(height)
        indent = self.indent_per_root_height * root
        flags = []
        if indent > CRUSH_DEPTH_FRACTION * self.billet_diameter:
            flags.append("crushed")
        contact_diameter = 2.0 * math.sqrt(self.billet_diameter * indent)  # Eq. (5)
        if self.slide_per_root_height * root > LONG_SLIDE_DIAMETERS * contact_diameter:
            flags.append("long_slide")
        return tuple(flags)


def build_model(scene, resolution=None, *, level=0.0, melting=True,
                runaway_fraction=DEFAULT_RUNAWAY_FRACTION, horizon=HORIZON_EXIT_TIMES,
                meshes=True, melt_width=None, melt_spread=0.0, target="mesh", rtol=1e-3):
    """Infer the model a scene needs and build its meshes.

    Parameters
    ----------
    scene : skidmc.scene.Scene
        The scene (SI attributes).
    resolution : Resolution, optional
        Numerical resolution; default ``resolution_for_level(level)``.
    level : float
        Refinement level used when ``resolution`` is not given.
    melt_width : float, optional
        Width of the smoothed melting step [K], used when ``resolution`` is not given;
        default :func:`melt_width_floor` of ``level``.
    melt_spread : float
        Spread of each HE cell's melting step [1] (:class:`Resolution`), used when
        ``resolution`` is not given.
    melting : bool
        Model melting of the HE (enthalpy plateau at T_m) when the scene has a
        heat of fusion.
    runaway_fraction : float
        Runaway rule, see :mod:`skidmc.physics.thermal` (0 disables it).
    horizon : float
        Integration horizon in exit times.
    meshes : bool
        Build the meshes. Without them (empty arrays) the model still carries the mechanics,
        terms and validity flags, e.g. for the fast tier's results.
    target : {"mesh", "exact"}
        "mesh": the target on its own finite-volume mesh (what the search uses). "exact": the
        target as the exact semi-infinite solid of Eq. (12), through Duhamel's integral at the
        interface (:mod:`skidmc.physics.thermal`); only the HE is meshed. The target's mesh
        carries most of a level's spatial error (docs/model.md, "The target as an exact
        semi-infinite solid"); the search's error model is not yet calibrated for it.
    rtol : float
        The search's relative tolerance on the critical height [1]: a target with a
        temperature table takes k(T), c(T) where holding them constant could move the height by
        more than :data:`PROPERTY_BUDGET_FRACTION` of it.

    Returns
    -------
    SkidModel
    """
    if target not in ("mesh", "exact"):
        raise SceneError("target", target, 'must be "mesh" or "exact"')
    if resolution is None:
        resolution = resolution_for_level(level, melt_width, melt_spread)
    return ModelBuilder(scene, melting=melting, runaway_fraction=runaway_fraction,
                        horizon=horizon, target=target, rtol=rtol).model(resolution,
                                                                         meshes=meshes)


class ModelBuilder:
    """The models of one scene at any resolution: what :func:`build_model` infers from the
    scene (the impact's mechanics, the terms and validity flags, the target's layers or
    temperature table) done once, the meshes per resolution.

    A search builds its scene's model at every level and melting width it runs (~5 per
    height); each is ``ModelBuilder(scene, ...).model(resolution)``, the same arithmetic as
    :func:`build_model`, so a search that keeps one builder gets the same models to the last
    bit for a fifth of the Python (docs/performance.md, issue 45's tenth pass).

    Parameters
    ----------
    scene, melting, runaway_fraction, horizon, rtol
        As :func:`build_model`.
    target : {"mesh", "exact"} or None
        As :func:`build_model`; None: given to each :meth:`model` instead (refused there, as
        :func:`build_model` refuses it, where the exact target cannot carry the scene's).

    Attributes
    ----------
    terms, flags : tuple of str
        The model's terms and scene validity flags (those of every model it builds).
    exit_time : float
        [s].
    exit_kind : str
    runaway_temperature : float
        [K].
    """

    def __init__(self, scene, *, melting=True, runaway_fraction=DEFAULT_RUNAWAY_FRACTION,
                 horizon=HORIZON_EXIT_TIMES, target="mesh", rtol=1e-3):
        if target not in ("mesh", "exact", None):
            raise SceneError("target", target, 'must be "mesh" or "exact"')
        self.scene, self.target, self.runaway_fraction = scene, target, runaway_fraction
        reason = elastic_target_reason(scene)
        if reason is not None:
            raise SceneError("target.hardness", scene.target_hardness, reason)
        # The contact pressure: the billet's flow stress on a rigid target, the target's hardness
        # where it yields first (docs/model.md, "Targets softer than the billet").
        sigma = mechanics.contact_pressure(scene.flow_stress, scene.target_hardness)
        mass = scene.billet_mass
        diameter = scene.billet_diameter
        mu = scene.mu
        # The impact's constants from the one compiled definition the fast tier uses too.
        omega, coefficient, t_exit, exit_code, slide_s, slide_c = mechanics.impact_constants(
            mu, sigma, mass, diameter, scene.angle, scene.tilt)
        t_c = 0.5 * math.pi / omega
        exit_kind = mechanics.EXIT_KINDS[exit_code]
        phi = math.radians(scene.angle)

        terms = ["frictional_heating", "friction_spin"]
        flags = []
        if scene.tilt > 0.0:
            terms.append("normal_force_spin")
        if sigma < scene.flow_stress:
            flags.append("yielding_target")
        if exit_kind == "stops_sliding":
            flags.append("stops_sliding")
            if t_exit < EARLY_STOP_FRACTION * t_c:
                flags.append("stops_early")

        extension, mean_shape = flux_extension(omega, t_exit, slide_s, slide_c)

        t_end = horizon * t_exit
        heat_of_reaction = scene.kinetics_heat_of_reaction
        prefactor = scene.kinetics_prefactor
        t_a = scene.kinetics_activation_temperature
        adiabatic_rise = heat_of_reaction / scene.he_heat_capacity
        t_run = float(model_runaway_temperature(prefactor, t_a, adiabatic_rise, t_exit,
                                                runaway_fraction))

        t_ign, rest_time = _ignition_diagnostics(prefactor, t_a, adiabatic_rise,
                                                 scene.initial_temperature, t_exit)
        if rest_time < SELF_HEATING_TIME:
            flags.append("self_heating")
        if t_ign > HOT_IGNITION_TEMPERATURE:
            flags.append("hot_ignition")
        if mu == 0.0:
            terms = []
            flags.append("no_friction")

        latent = scene.he_heat_of_fusion if melting else 0.0
        if latent > 0.0 and scene.he_melting_point < t_run:
            if mu > 0.0:  # without friction nothing heats, so nothing melts
                terms.append("melting")
        else:
            latent = 0.0

        layers = target_layers(scene)
        if layers is not None:
            # Layers only where heat reaches below the top layer within the simulated time: a
            # top deeper than the homogeneous target's mesh (DEPTH_DIFFUSION_LENGTHS
            # sqrt(alpha t_end)) leaves the meshed model unchanged, and the exact target's far
            # field changes the height by less than measured in docs/targets.md.
            top_alpha = layers[1][0] / layers[0][0]
            if layers[2][0] >= DEPTH_DIFFUSION_LENGTHS * math.sqrt(top_alpha * t_end):
                terms.append("top_layer_only")
                flags.append("top_layer_only")
                layers = None
            else:
                terms.append("layered_target")
                flags.append("layered_target")
                if target == "exact":
                    _refuse_exact("layered_target")

        table = None
        t_high = math.nan
        if getattr(scene, "target_table", ""):
            if getattr(scene, "target_layers", ""):
                raise SceneError("target.table", scene.target_table, "a temperature table "
                                 "applies to a homogeneous target; a stack's layers keep "
                                 "constant properties")
            t_low, t_high = target_temperature_range(scene.initial_temperature, t_run)
            change = target_property_change(scene, t_low, t_high)
            if change > PROPERTY_BUDGET_FRACTION * rtol:
                terms.append("temperature_target")
                flags.append("temperature_target")
                table = target_property_table(scene)
                if target == "exact":
                    _refuse_exact("temperature_target")
            else:
                terms.append("constant_target")
                flags.append("constant_target")

        self.terms, self.flags = tuple(terms), tuple(flags)
        self.exit_time, self.exit_kind, self.runaway_temperature = t_exit, exit_kind, t_run
        self._layers, self._table, self._t_high, self._t_end = layers, table, t_high, t_end
        # SkidModel's fields that do not depend on the resolution.
        self._fields = dict(
            omega=omega, contact_time=t_c, exit_time=t_exit, exit_kind=exit_kind,
            slide_s=slide_s, slide_c=slide_c,
            flux_per_root_height=mu * sigma * math.sqrt(2.0 * mechanics.STANDARD_GRAVITY),
            extension_flux_factor=extension, end_time=t_end, he_density=scene.he_density,
            latent_heat=latent, melting_point=scene.he_melting_point, prefactor=prefactor,
            activation_temperature=t_a, heat_of_reaction=heat_of_reaction,
            initial_temperature=scene.initial_temperature, runaway_temperature=t_run,
            runaway_fraction=runaway_fraction, dt_initial=1e-6 * t_exit, terms=self.terms,
            flags=self.flags, ignition_temperature=t_ign, rest_time=rest_time,
            billet_diameter=diameter,
            indent_per_root_height=(math.sqrt(2.0 * mechanics.STANDARD_GRAVITY) * math.cos(phi)
                                    / omega),
            slide_per_root_height=(math.sqrt(2.0 * mechanics.STANDARD_GRAVITY) * mean_shape
                                   * t_exit))

    def model(self, resolution, *, meshes=True, target=None):
        """The scene's model at ``resolution`` [SkidModel] (:func:`build_model`): with its
        meshes, or without them (``meshes=False``); ``target`` the builder's unless it was
        built with None."""
        if target is None:
            target = self.target
        elif self.target is not None and target != self.target:
            raise ValueError(f"this builder models the target {self.target!r}, not {target!r}")
        if target not in ("mesh", "exact"):
            raise SceneError("target", target, 'must be "mesh" or "exact"')
        if target == "exact" and self.target is None:
            for term in ("layered_target", "temperature_target"):
                if term in self.terms:
                    _refuse_exact(term)
        scene, layers, table = self.scene, self._layers, self._table
        kernel_table = np.zeros(0)
        if meshes:
            f = self._fields
            n_cells = resolution.cells_per_medium
            width, rho_c, face, q_share_he = _meshes(scene, resolution, f["exit_time"],
                                                     self._t_end, f["prefactor"],
                                                     f["activation_temperature"])
            if layers is not None:
                q_share_he = _layer_meshes(scene, layers, self._t_end, n_cells, width, rho_c,
                                           face)
            if table is not None:
                q_share_he, kernel_table = _table_meshes(scene, table, self._t_high,
                                                         self._t_end, n_cells, width, rho_c,
                                                         face)
        else:
            # No cells: the fields as the mesh arithmetic would leave them, without running it
            # (the fast tier builds a mesh-less model for every result).
            n_cells = 0
            width, rho_c, face, q_share_he = np.empty(0), np.empty(0), np.empty(0), math.nan
        target_effusivity = he_conductivity = 0.0
        if target == "exact":
            # The HE's cells and faces alone (the same HE mesh as the meshed target's); the
            # target enters through Duhamel's integral.
            width, rho_c, face = (width[n_cells:].copy(), rho_c[n_cells:].copy(),
                                  face[n_cells:].copy())
            n_cells, q_share_he = 0, math.nan
            target_effusivity = math.sqrt(scene.target_conductivity * scene.target_density
                                          * scene.target_heat_capacity)
            he_conductivity = scene.he_conductivity
        return SkidModel(
            width=width, rho_c=rho_c, face_conductance=face, n_target=n_cells,
            q_share_he=q_share_he, resolution=resolution, target_effusivity=target_effusivity,
            he_conductivity=he_conductivity, target_table=kernel_table, **self._fields)


def _refuse_exact(term):
    """Raise the exact target's refusal of a scene with ``term`` (SceneError on "target")."""
    if term == "layered_target":
        raise SceneError("target", "exact", "the heat reaches below the target's top "
                         "layer: a layered target needs the meshed target "
                         "(target='mesh'; the default search chooses it)")
    raise SceneError("target", "exact", "a temperature-dependent target needs the "
                     "meshed target (target='mesh'; the default search chooses "
                     "it)")


def _meshes(scene, resolution, t_exit, t_end, prefactor, activation_temperature):
    """Both media's meshes as the kernels take them (:func:`skidmc.physics.meshes.fill_meshes`).

    Returns
    -------
    width : ndarray
        Cell widths [m], target (far end first) then HE (interface first).
    rho_c : ndarray
        Volumetric heat capacity per cell [J/(m^3 K)].
    face : ndarray
        Conductance between cells i and i+1 [W/(m^2 K)].
    q_share_he : float
        Share of the interface flux that enters the HE [1].
    """
    n_cells = resolution.cells_per_medium
    width, rho_c, face = np.empty(2 * n_cells), np.empty(2 * n_cells), np.empty(2 * n_cells - 1)
    share = fill_meshes(scene.he_density, scene.he_heat_capacity, scene.he_conductivity,
                        scene.target_density, scene.target_heat_capacity,
                        scene.target_conductivity, scene.initial_temperature, prefactor,
                        activation_temperature, t_exit, t_end, n_cells,
                        resolution.first_cell_fraction, DEPTH_DIFFUSION_LENGTHS,
                        width, rho_c, face)
    return width, rho_c, face, float(share)


def target_layers(scene):
    """The scene's target as layers, or None for a homogeneous one.

    Returns
    -------
    (rho_c, conductivity, thickness) : tuple of tuple of float, or None
        Per layer from the surface down: volumetric heat capacity [J/(m^3 K)], conductivity
        [W/(m K)], thickness [m] (inf for the last); the first layer is the scene's target.*
        keys, the deeper ones ``target.layers``.
    """
    text = getattr(scene, "target_layers", "")
    if not text:
        return None
    top, deeper = parse_layers(text)
    rho_c = (scene.target_density * scene.target_heat_capacity,
             *(rho * c for rho, c, _, _ in deeper))
    k = (scene.target_conductivity, *(row[2] for row in deeper))
    thickness = (top, *(row[3] for row in deeper))
    return rho_c, k, thickness


def _layer_meshes(scene, layers, t_end, n_cells, width, rho_c, face):
    """Replace the target's cells of the homogeneous meshes (``width``, ``rho_c``, ``face``,
    target far end first) by a layered target's
    (:func:`skidmc.physics.meshes.layered_target_cells`), with the same first cell; returns
    the share of the interface flux into the HE [1]."""
    cells_w, cells_rc, cells_k = layered_target_cells(
        layers[0], layers[1], layers[2], width[n_cells - 1], t_end, n_cells,
        DEPTH_DIFFUSION_LENGTHS)
    width[:n_cells] = cells_w[::-1]
    rho_c[:n_cells] = cells_rc[::-1]
    k = np.concatenate([cells_k[::-1], np.full(n_cells, scene.he_conductivity)])
    half = width / (2.0 * k)
    face[:n_cells] = 1.0 / (half[:n_cells] + half[1:n_cells + 1])
    g_tg, g_he = 1.0 / half[n_cells - 1], 1.0 / half[n_cells]
    return float(g_he / (g_tg + g_he))


def target_property_table(scene):
    """A scene's temperature table as the model uses it, or None (no ``target.table``).

    The table gives the shape: k(T) = k k_tab(T) / k_tab(T_ref) and c(T) = c c_tab(T) /
    c_tab(T_ref), with k, c the scene's target.conductivity and target.heat_capacity, so that a
    registry material's table is used as printed and a scene (or a study's draw) that sets k or
    c at T_ref scales the whole curve. The density stays constant (thermal expansion moves it by
    ~1-2 % to 800 K).

    Returns
    -------
    (temperature, conductivity, heat_capacity) : tuple of ndarray, or None
        [K], [W/(m K)], [J/(kg K)] at the table's nodes.
    """
    text = getattr(scene, "target_table", "")
    if not text:
        return None
    return _scaled_table(text, scene.target_conductivity, scene.target_heat_capacity)


@functools.lru_cache(maxsize=256)
def _scaled_table(text, conductivity, heat_capacity):
    """:func:`target_property_table` of a table's text and the scene's k, c [read-only arrays].

    Kept: one search builds its scene's model ~5 times per height and parsed the table text
    each time (~10 % of a height on the temperature-dependent targets; docs/performance.md).
    The arrays are the same computation's, read-only so that no caller can change the cache.
    """
    reference, rows = parse_table(text)
    t, k, c = (np.array(col, dtype=float) for col in zip(*rows))
    k_ref, c_ref = np.interp(reference, t, k), np.interp(reference, t, c)
    out = (t, k * (conductivity / k_ref), c * (heat_capacity / c_ref))
    for array in out:
        array.setflags(write=False)
    return out


def target_temperature_range(initial_temperature, runaway_temperature):
    """(T0, the interface's highest temperature before an event) [K], the range over which a
    tabled target's properties move: an HE cell that passes the runaway temperature ends the run
    with an event, and the HE's surface cell is its hottest and lies at the interface, so the
    runaway temperature bounds the interface up to the event (the interface peaked at 717-759 K
    at the critical height of the report's ceramic scenes; results/validation/
    temperature_dependence.md). Without a runaway rule (inert HE, rule off): 2000 K."""
    high = runaway_temperature if math.isfinite(runaway_temperature) else 2000.0
    return initial_temperature, max(high, initial_temperature)


def target_property_change(scene, t_low, t_high):
    """Bound on |ln H(k(T), c(T)) - ln H(k, c)| [1] over ``t_low``..``t_high`` [K]:
    max |ln k(T) / k| + max |ln c(T) / c| (:data:`PROPERTY_BUDGET_FRACTION`), with k, c the
    scene's constant values; 0 without a table. Both are piecewise linear in T, so the maxima lie
    at the nodes inside the range or at its ends."""
    table = target_property_table(scene)
    if table is None:
        return 0.0
    t, k, c = table
    inside = t[(t > t_low) & (t < t_high)]
    points = np.concatenate([[t_low, t_high], inside])
    k_at, c_at = np.interp(points, t, k), np.interp(points, t, c)
    return float(np.max(np.abs(np.log(k_at / scene.target_conductivity)))
                 + np.max(np.abs(np.log(c_at / scene.target_heat_capacity))))


def constant_property_scene(scene, temperature):
    """The scene with constant target properties: k and c of its table at ``temperature`` [K]
    and no table (itself without one). The fast tier's guess for a temperature-dependent target,
    and the comparison in scripts/temperature_dependent_targets.py."""
    if not getattr(scene, "target_table", ""):
        return scene
    k, c = constant_properties(scene, temperature)
    return scene.replace({"target.conductivity": k, "target.heat_capacity": c,
                          "target.table": ""}, check_plausible=False)


def constant_properties(scene, temperature):
    """The conductivity [W/(m K)] and specific heat capacity [J/(kg K)] of the scene's
    temperature table at ``temperature`` [K]: what :func:`constant_property_scene` gives the
    scene (the search's fast-tier guess takes them without making the scene)."""
    t, k, c = target_property_table(scene)
    return float(np.interp(temperature, t, k)), float(np.interp(temperature, t, c))


def _table_meshes(scene, table, t_high, t_end, n_cells, width, rho_c, face):
    """Replace the target's cells of the homogeneous meshes by a temperature-dependent
    target's, and build the kernel's table (:func:`skidmc.physics.thermal.target_properties`).

    The mesh is the homogeneous one's geometric mesh, its first cell sized by the smallest
    diffusivity k / (rho c) over T0..``t_high`` [K] (the interface's, where the gradient is
    steepest: as fill_meshes scales it, sqrt(alpha_target / alpha_HE) times the first HE cell)
    and its depth by the largest (DEPTH_DIFFUSION_LENGTHS diffusion lengths over ``t_end`` [s]);
    for a table constant in T it is the homogeneous mesh. The arrays' target cells and faces
    are filled at T0 (the kernel evaluates them per step). Returns (share of the interface flux
    into the HE at T0 [1], the kernel's table).
    """
    t, k, c = table
    rho_cv = scene.target_density * c
    points = np.concatenate([[scene.initial_temperature, t_high],
                             t[(t > scene.initial_temperature) & (t < t_high)]])
    alpha = np.interp(points, t, k) / np.interp(points, t, rho_cv)
    alpha_he = scene.he_conductivity / (scene.he_density * scene.he_heat_capacity)
    h0_he = width[n_cells]
    h0 = h0_he * math.sqrt(float(alpha.min()) / alpha_he)
    r = geometric_ratio(h0, DEPTH_DIFFUSION_LENGTHS * math.sqrt(float(alpha.max()) * t_end),
                        n_cells)
    for i in range(n_cells):
        width[n_cells - 1 - i] = h0 * r ** float(i)
    k0 = float(np.interp(scene.initial_temperature, t, k))
    rho_c[:n_cells] = float(np.interp(scene.initial_temperature, t, rho_cv))
    kk = np.concatenate([np.full(n_cells, k0), np.full(n_cells, scene.he_conductivity)])
    half = width / (2.0 * kk)
    face[:n_cells] = 1.0 / (half[:n_cells] + half[1:n_cells + 1])
    g_tg, g_he = 1.0 / half[n_cells - 1], 1.0 / half[n_cells]
    # Enthalpy at the nodes: the exact integral of the piecewise-linear rho c(T).
    enthalpy = np.concatenate([[0.0], np.cumsum(0.5 * (rho_cv[1:] + rho_cv[:-1]) * np.diff(t))])
    kernel_table = np.ascontiguousarray(np.concatenate([t, k, rho_cv, enthalpy]))
    return float(g_he / (g_tg + g_he)), kernel_table


def _ignition_diagnostics(prefactor, activation_temperature, adiabatic_rise,
                          initial_temperature, t_exit):
    """(ignition temperature [K], runaway time at rest [s]) for the validity flags.

    The ignition temperature is where the adiabatic induction time
    tau_ad(T) = T^2 / (T_a dT_ad k(T)) equals t_exit (for an inert HE, dT_ad = 0, where
    the reaction time 1/k does): no cell can run away within the heating time below it.
    The runaway time at rest is min(1/k, tau_ad) at T0.
    """
    if not prefactor > 0.0:
        return math.inf, math.inf
    rest_time = float(rest_runaway_time(prefactor, activation_temperature, adiabatic_rise,
                                        initial_temperature))
    t_ign = float(ignition_temperature(prefactor, activation_temperature, adiabatic_rise, t_exit))
    return t_ign, rest_time


# --- the scalar parts of the model as compiled functions: build_model and a GPU thread
# (skidmc.solver.device) share them.

@njit(cache=True)
def rest_runaway_time(prefactor, activation_temperature, adiabatic_rise, initial_temperature):
    """Runaway time of the unheated HE at rest [s]: min(1/k, tau_ad) at T0.

    k = Z exp(-T_a / T0) and tau_ad = T0^2 / (T_a dT_ad k) (Frank-Kamenetskii's adiabatic
    induction time; for an inert HE, dT_ad = 0, the reaction time 1/k alone), capped at
    exp(700) s; inf where Z = 0. Below :data:`SELF_HEATING_TIME` the scene has the validity flag
    "self_heating" (:func:`build_model`), and the fast tier states its larger error
    (:func:`skidmc.physics.fast.stated_error`): one rule for the flag, the batch fast tier and
    the device search's first guess.

    Parameters
    ----------
    prefactor : float
        Z [1/s].
    activation_temperature : float
        T_a [K].
    adiabatic_rise : float
        dT_ad = Q / c1 [K].
    initial_temperature : float
        T0 [K].
    """
    if not prefactor > 0.0:
        return math.inf
    ln_k0 = math.log(prefactor) - activation_temperature / initial_temperature
    ln_ratio = 0.0
    if adiabatic_rise > 0.0:
        ln_ratio = math.log(initial_temperature**2 / (activation_temperature * adiabatic_rise))
    return math.exp(min(-ln_k0 + min(0.0, ln_ratio), 700.0))


@njit(cache=True)
def flux_extension(omega, t_exit, slide_s, slide_c):
    """Flux after the exit over q0, and the contact's mean flux shape over q0 [1].

    Beyond t_exit the flux is extended only to give the critical-height search a continuous
    margin: the exit flux (continuous) is kept unless it has dropped below the contact's mean
    (Eq. 10's shape s - c (1 - cos omega t) averaged over (0, t_exit)).
    """
    wt = omega * t_exit
    mean_shape = slide_s - slide_c * (1.0 - math.sin(wt) / wt)
    exit_shape = max(slide_s - slide_c * (1.0 - math.cos(wt)), 0.0)
    return max(exit_shape, mean_shape), mean_shape


@njit(cache=True)
def model_runaway_temperature(prefactor, activation_temperature, adiabatic_rise, t_exit,
                              runaway_fraction):
    """The runaway rule's temperature [K] (:func:`skidmc.physics.thermal.runaway_temperature`),
    inf for an inert HE or with the rule switched off (``runaway_fraction`` 0)."""
    if runaway_fraction > 0.0 and prefactor > 0.0 and adiabatic_rise > 0.0:
        return runaway_temperature(prefactor, activation_temperature, adiabatic_rise, t_exit,
                                   runaway_fraction)
    return math.inf


@njit(cache=True)
def ignition_temperature(prefactor, activation_temperature, adiabatic_rise, t_exit):
    """Temperature [K] at which the adiabatic induction time equals t_exit (for an inert HE,
    dT_ad = 0, where the reaction time 1/k does); inf when none (``prefactor`` <= 0)."""
    if not prefactor > 0.0:
        return math.inf
    if adiabatic_rise > 0.0:
        return runaway_temperature(prefactor, activation_temperature, adiabatic_rise, t_exit,
                                   1.0)
    if prefactor * t_exit > 1.0:
        return activation_temperature / math.log(prefactor * t_exit)
    return math.inf
