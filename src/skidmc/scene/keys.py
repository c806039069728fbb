"""The scene's input keys: one definition per key (SI unit, bounds, description).

Every other list of keys in skidmc (the :class:`~skidmc.scene.Scene` fields, validation,
:class:`~skidmc.scene.SceneColumns`, storage attributes, ``skidmc presets``, the docs' tables)
is derived from this module.
"""

from __future__ import annotations

import math

__all__ = [
    "CONFIGURATIONS",
    "DESCRIPTIONS",
    "NUMERIC_KEYS",
    "SCENE_KEYS",
    "SI_UNITS",
    "bound_reason",
    "in_bounds",
]

#: The scene vocabulary, in the order of docs/architecture.md.
SCENE_KEYS: tuple[str, ...] = (
    "mu",
    "flow_stress",
    "billet_mass",
    "billet_diameter",
    "configuration",
    "angle",
    "tilt",
    "initial_temperature",
    "he.density",
    "he.heat_capacity",
    "he.conductivity",
    "he.heat_of_fusion",
    "he.melting_point",
    "kinetics.prefactor",
    "kinetics.activation_temperature",
    "kinetics.heat_of_reaction",
    "target.density",
    "target.heat_capacity",
    "target.conductivity",
)

#: Keys holding a float; every key but ``configuration``.
NUMERIC_KEYS: tuple[str, ...] = tuple(k for k in SCENE_KEYS if k != "configuration")

#: Unit of each key inside skidmc (SI, angles in degrees), as pint spells it; also the ``units``
#: attribute written to storage.
SI_UNITS: dict[str, str] = {
    "mu": "1",
    "flow_stress": "Pa",
    "billet_mass": "kg",
    "billet_diameter": "m",
    "configuration": "-",
    "angle": "deg",
    "tilt": "deg",
    "initial_temperature": "K",
    "he.density": "kg/m^3",
    "he.heat_capacity": "J/(kg K)",
    "he.conductivity": "W/(m K)",
    "he.heat_of_fusion": "J/kg",
    "he.melting_point": "K",
    "kinetics.prefactor": "1/s",
    "kinetics.activation_temperature": "K",
    "kinetics.heat_of_reaction": "J/kg",
    "target.density": "kg/m^3",
    "target.heat_capacity": "J/(kg K)",
    "target.conductivity": "W/(m K)",
}

#: Long name of each key with the report's symbol (storage ``long_name`` attribute).
DESCRIPTIONS: dict[str, str] = {
    "mu": "apparent coefficient of sliding friction mu, Eq. (1)",
    "flow_stress": "plastic flow stress of the billet sigma, Eq. (5)",
    "billet_mass": "billet mass W",
    "billet_diameter": "billet (hemisphere) diameter D",
    "configuration": "drop configuration (pendulum or vertical)",
    "angle": "impact angle phi: complement of the approach angle (pendulum) or target angle "
    "(vertical)",
    "tilt": "billet tilt psi from the target plane (0 for pendulum; phi for vertical)",
    "initial_temperature": "initial temperature of billet and target T0",
    "he.density": "HE density rho_1",
    "he.heat_capacity": "HE specific heat c_1",
    "he.conductivity": "HE thermal conductivity k_1",
    "he.heat_of_fusion": "HE latent heat of melting (0 disables melting)",
    "he.melting_point": "HE melting temperature",
    "kinetics.prefactor": "Arrhenius frequency factor Z",
    "kinetics.activation_temperature": "Arrhenius activation temperature E/R",
    "kinetics.heat_of_reaction": "heat of reaction per unit mass Q = Delta H / M.W.",
    "target.density": "target density rho_2",
    "target.heat_capacity": "target specific heat c_2",
    "target.conductivity": "target thermal conductivity k_2",
}

#: Valid values of ``configuration``.
CONFIGURATIONS: tuple[str, ...] = ("pendulum", "vertical")

_INF = math.inf
# Allowed interval per numeric key: (low, low included, high, high included), in SI_UNITS.
_BOUNDS: dict[str, tuple[float, bool, float, bool]] = {
    "mu": (0.0, True, 5.0, False),
    "flow_stress": (0.0, False, _INF, False),
    "billet_mass": (0.0, False, _INF, False),
    "billet_diameter": (0.0, False, _INF, False),
    "angle": (0.0, False, 90.0, False),
    "tilt": (0.0, True, 90.0, False),
    "initial_temperature": (0.0, False, _INF, False),
    "he.density": (0.0, False, _INF, False),
    "he.heat_capacity": (0.0, False, _INF, False),
    "he.conductivity": (0.0, False, _INF, False),
    "he.heat_of_fusion": (0.0, True, _INF, False),
    "he.melting_point": (0.0, False, _INF, False),
    "kinetics.prefactor": (0.0, False, _INF, False),
    "kinetics.activation_temperature": (0.0, False, _INF, False),
    "kinetics.heat_of_reaction": (0.0, True, _INF, False),
    "target.density": (0.0, False, _INF, False),
    "target.heat_capacity": (0.0, False, _INF, False),
    "target.conductivity": (0.0, False, _INF, False),
}
# Checks between two keys are raised on the first; make_scene names the second if only it was given.
_PARTNER: dict[str, str] = {"initial_temperature": "he.melting_point"}
_BOUND_NOTES: dict[str, str] = {
    "mu": " (a friction coefficient of 5 or more is surely a typo)",
}


def bound_reason(key: str) -> str:
    lo, lo_in, hi, hi_in = _BOUNDS[key]
    unit = SI_UNITS[key]
    unit = f" {unit}" if unit not in ("1", "-") else ""
    if hi == _INF:
        rule = f"must be {'>=' if lo_in else '>'} {lo:g}{unit}"
    else:
        rule = f"must be in {'[' if lo_in else '('}{lo:g}, {hi:g}{']' if hi_in else ')'}{unit}"
    return rule + _BOUND_NOTES.get(key, "")


def in_bounds(key: str, x):
    """Whether `x` (a float, or elementwise an array) lies in `key`'s allowed interval; NaN
    does not (its comparisons are False)."""
    lo, lo_in, hi, hi_in = _BOUNDS[key]
    return (x >= lo if lo_in else x > lo) & (x <= hi if hi_in else x < hi)
