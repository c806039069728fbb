"""The scene's input keys: one definition per key, in one table (:data:`INPUT_KEYS`).

Each :class:`InputKey` states a key's SI unit, its allowed interval, the range in which a bare
number (one written without units, read as SI) is plausible, its description with the report's
symbol, and the report equation or table where it enters. Every other list of keys in skidmc is
derived from the table: :data:`SCENE_KEYS`, :data:`NUMERIC_KEYS`, :data:`SI_UNITS`,
:data:`DESCRIPTIONS`, the :class:`~skidmc.scene.Scene` fields and docstring,
:class:`~skidmc.scene.SceneColumns`' checks, ``skidmc.solver.fast.SCENE_FIELDS``, the storage
attributes, ``skidmc presets`` and ``docs/inputs.md`` (``scripts/make_inputs_doc.py``).

The checks *between* keys (a vertical drop's tilt equals its angle; the initial temperature is
below the melting point) are :func:`between_keys_ok` and :func:`first_broken_between`: written
once, elementwise on arrays, used by both the scalar and the column path.

"The report" is the Los Alamos report "Effect of Target Thermal Conductivity and Roughness on the
Initiation of PBX 9404 by Oblique Impact" (its model also in Randolph, Hatler & Popolato,
Ind. Eng. Chem. Fundam. 15 (1976) 1); equation, table and section numbers are its own.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping

import numpy as np

__all__ = [
    "BETWEEN_KEYS",
    "CONFIGURATIONS",
    "DESCRIPTIONS",
    "DEFAULT_TARGET_HARDNESS",
    "FIELDS",
    "HARDNESS_WORDS",
    "INFINITE_OK",
    "INPUT_KEYS",
    "LAYERS_KEY",
    "TABLE_KEY",
    "NUMERIC_KEYS",
    "PARTNERS",
    "SCENE_KEYS",
    "SI_UNITS",
    "InputKey",
    "Interval",
    "between_keys_ok",
    "bound_reason",
    "first_broken_between",
    "format_number",
    "implausible_reason",
    "in_bounds",
    "input_key",
]

_INF = math.inf

#: Valid values of ``configuration``.
CONFIGURATIONS: tuple[str, ...] = ("pendulum", "vertical")


@dataclasses.dataclass(frozen=True)
class Interval:
    """An interval of allowed values, each end open or closed.

    Attributes
    ----------
    low, high : float
        The ends, in the key's SI unit (``high`` may be ``inf``).
    low_closed, high_closed : bool
        Whether the end itself is allowed.
    """

    low: float
    low_closed: bool
    high: float = _INF
    high_closed: bool = False

    def contains(self, x):
        """Whether `x` (a float, or elementwise an array) lies in the interval; NaN does not."""
        lo = x >= self.low if self.low_closed else x > self.low
        return lo & (x <= self.high if self.high_closed else x < self.high)

    def rule(self, unit: str) -> str:
        """The interval as a rule: ``"must be > 0 Pa"``, ``"must be in [0, 5)"``."""
        unit = f" {unit}" if unit not in ("1", "-") else ""
        if self.high == _INF:
            return f"must be {'>=' if self.low_closed else '>'} {self.low:g}{unit}"
        return (f"must be in {'[' if self.low_closed else '('}{self.low:g}, {self.high:g}"
                f"{']' if self.high_closed else ')'}{unit}")


@dataclasses.dataclass(frozen=True)
class InputKey:
    """The definition of one scene input.

    Attributes
    ----------
    key : str
        Dotted key (``"he.density"``); the :class:`~skidmc.scene.Scene` attribute is
        :attr:`field` (dots -> underscores).
    si_unit : str
        Unit inside skidmc, as pint spells it (SI, angles in degrees; ``"1"`` dimensionless,
        ``"-"`` for the configuration string). Also the ``units`` attribute in storage.
    bounds : Interval or None
        Allowed values [si_unit]; None for ``configuration`` (a choice of :data:`CONFIGURATIONS`).
    plausible : tuple of float or None
        ``(low, high)`` [si_unit]: the range in which a bare number (no units, so read as SI) is
        taken at its word. Outside it, :func:`skidmc.scene.make_scene` and study files refuse
        the number and ask for units. None: no such check (dimensionless keys, whose bare
        number cannot be in the wrong unit, and angles, whose bounds are the whole range).
    description : str
        Long name with the report's symbol (storage ``long_name`` attribute).
    symbol : str
        The report's symbol (``"sigma"``), or ``"-"``.
    equation : str
        Where the report uses or gives the input (equations, tables, sections).
    example_unit : str
        A unit the value is commonly written in, for messages (``"psi"``).
    bound_note : str
        Appended to the bounds rule in messages.
    """

    key: str
    si_unit: str
    bounds: Interval | None
    plausible: tuple[float, float] | None
    description: str
    symbol: str
    equation: str
    example_unit: str = ""
    bound_note: str = ""

    @property
    def field(self) -> str:
        """Attribute name on :class:`~skidmc.scene.Scene` (``he_density``)."""
        return self.key.replace(".", "_")

    @property
    def numeric(self) -> bool:
        """Whether the key holds a float (every key but ``configuration``)."""
        return self.bounds is not None

    @property
    def type_name(self) -> str:
        """Python type of the field: ``"float"`` or ``"str"``."""
        return "float" if self.numeric else "str"


_POSITIVE = Interval(0.0, False)
_NON_NEGATIVE = Interval(0.0, True)

#: The scene vocabulary: one entry per key, in the order of the scene (and of the kernels'
#: arguments, ``configuration`` left out).
INPUT_KEYS: tuple[InputKey, ...] = (
    InputKey(
        "mu", "1", Interval(0.0, True, 5.0, False), None,
        "apparent coefficient of sliding friction mu, Eq. (1)", "mu",
        "Eqs. (1), (7)-(10); Tables V, IX", "",
        " (a friction coefficient of 5 or more is surely a typo)"),
    InputKey(
        "flow_stress", "Pa", _POSITIVE, (1e5, 1e10),
        "plastic flow stress of the billet sigma, Eq. (5)", "sigma",
        "Eqs. (1), (5); omega = (pi sigma D / W)^(1/2) (Sec. II.B); Sec. IV", "psi"),
    InputKey(
        "billet_mass", "kg", _POSITIVE, (1e-3, 1e4),
        "billet mass W", "W", "omega (Sec. II.B), Eqs. (5), (8), (10); Sec. III", "lb"),
    InputKey(
        "billet_diameter", "m", _POSITIVE, (1e-3, 2.0),
        "billet (hemisphere) diameter D", "D",
        "omega (Sec. II.B), Eqs. (5), (8), (10); Sec. III", "in"),
    InputKey(
        "configuration", "-", None, None,
        "drop configuration (pendulum or vertical)", "-", "Sec. II.B-C, Figs. 1-2"),
    InputKey(
        "angle", "deg", Interval(0.0, False, 90.0, False), None,
        "impact angle phi: complement of the approach angle (pendulum) or target angle "
        "(vertical)", "phi", "V_n0 = (2 g H)^(1/2) cos phi (Sec. II.B), Eqs. (5), (10)", "deg"),
    InputKey(
        "tilt", "deg", Interval(0.0, True, 90.0, False), None,
        "billet tilt psi from the target plane (0 for pendulum; phi for vertical)", "psi",
        "a', b' (Sec. II.C), Eq. (10)", "deg"),
    InputKey(
        "initial_temperature", "K", _POSITIVE, (150.0, 1000.0),
        "initial temperature of billet and target T0", "T0",
        "initial condition of Eqs. (11)-(12); Sec. IV (530 degR)", "degF"),
    InputKey(
        "he.density", "kg/m^3", _POSITIVE, (100.0, 3e4),
        "HE density rho_1", "rho_1", "Eq. (11); Table VI", "g/cm^3"),
    InputKey(
        "he.heat_capacity", "J/(kg K)", _POSITIVE, (50.0, 1e4),
        "HE specific heat c_1", "c_1", "Eq. (11); Table VI", "cal/g/K"),
    InputKey(
        "he.conductivity", "W/(m K)", _POSITIVE, (1e-2, 100.0),
        "HE thermal conductivity k_1", "k_1", "Eqs. (11), (15); Table VI", "cal/s/cm/K"),
    InputKey(
        "he.heat_of_fusion", "J/kg", _NON_NEGATIVE, (1e3, 1e7),
        "HE latent heat of melting (0 disables melting)", "-", "Table VII", "cal/g"),
    InputKey(
        "he.melting_point", "K", _POSITIVE, (150.0, 2000.0),
        "HE melting temperature", "-", "Table VII", "degC"),
    InputKey(
        "kinetics.prefactor", "1/s", _POSITIVE, (1e3, 1e40),
        "Arrhenius frequency factor Z", "Z", "rate Z exp(-E/RT) in Eq. (11); Table VII", "1/min"),
    InputKey(
        "kinetics.activation_temperature", "K", _POSITIVE, (1e3, 1e5),
        "Arrhenius activation temperature E/R", "E/R", "rate Z exp(-E/RT) in Eq. (11); Table VII",
        "K"),
    InputKey(
        "kinetics.heat_of_reaction", "J/kg", _NON_NEGATIVE, (1e4, 1e8),
        "heat of reaction per unit mass Q = Delta H / M.W.", "Delta H / M.W.",
        "Eqs. (11), (13); Table VII (per mole, M.W. of HMX 296.16 g/mol)", "cal/g"),
    InputKey(
        "target.density", "kg/m^3", _POSITIVE, (100.0, 3e4),
        "target density rho_2", "rho_2", "Eq. (12); Table VI", "g/cm^3"),
    InputKey(
        "target.heat_capacity", "J/(kg K)", _POSITIVE, (50.0, 1e4),
        "target specific heat c_2", "c_2", "Eq. (12); Table VI", "cal/g/K"),
    InputKey(
        "target.conductivity", "W/(m K)", _POSITIVE, (1e-2, 5e3),
        "target thermal conductivity k_2", "k_2", "Eqs. (12), (15); Tables II, VI",
        "cal/s/cm/K"),
    InputKey(
        "target.hardness", "Pa", Interval(0.0, True, _INF, True), (1e5, 1e12),
        "contact pressure at which the target yields p_t (indentation hardness or confined "
        "crushing strength; \"rigid\" = inf, the report's rigid target; \"elastic\" = 0, a "
        "target the plastic-contact model cannot describe)", "p_t",
        "replaces sigma in omega (Sec. II.B) and Eqs. (1), (5) where p_t < sigma "
        "(docs/model.md, \"Targets softer than the billet\")", "MPa",
        " (\"rigid\" for inf, \"elastic\" for 0)"),
)

#: The scene attribute (not an input key: no unit, not sampled, not stored as a column) that
#: holds a layered target's deeper layers, set with a stack (``target = "gold 3 mil / copper 7
#: mil / aluminium-2024"``) or directly as canonical SI text: the top layer's thickness [m], then
#: density [kg/m^3], heat capacity [J/(kg K)], conductivity [W/(m K)] and thickness [m] of each
#: deeper layer, the last without a thickness (semi-infinite), separated by '|'; empty for a
#: homogeneous target (docs/targets.md). The top layer's properties are the target.* keys.
LAYERS_KEY = "target.layers"

#: The scene attribute (like :data:`LAYERS_KEY`, not an input key) that holds a homogeneous
#: target's temperature table, set with a registry material that has one (``target =
#: "fused-quartz"``) or as canonical SI text ``"T_ref | T k c | T k c | ..."`` (K, W/(m K),
#: J/(kg K)); empty for constant properties. It gives the shape of k(T) and c(T): the model
#: scales it so that its values at T_ref are the scene's target.conductivity and
#: target.heat_capacity (docs/targets.md, "Temperature-dependent properties").
TABLE_KEY = "target.table"

#: Keys that may hold +inf (every other numeric key must be finite).
INFINITE_OK: frozenset[str] = frozenset({"target.hardness"})

#: Words a key of :data:`INFINITE_OK` takes for its ends: ``"rigid"`` -> inf, ``"elastic"`` -> 0.
HARDNESS_WORDS: dict[str, float] = {"rigid": _INF, "elastic": 0.0}

#: Default of ``target.hardness`` when a scene (a preset) does not give it: the report's rigid
#: target.
DEFAULT_TARGET_HARDNESS = _INF

_BY_KEY: dict[str, InputKey] = {k.key: k for k in INPUT_KEYS}

#: The scene vocabulary, in the table's order.
SCENE_KEYS: tuple[str, ...] = tuple(k.key for k in INPUT_KEYS)

#: Keys holding a float; every key but ``configuration``.
NUMERIC_KEYS: tuple[str, ...] = tuple(k.key for k in INPUT_KEYS if k.numeric)

#: Attribute name of each key on :class:`~skidmc.scene.Scene` (dots -> underscores).
FIELDS: dict[str, str] = {k.key: k.field for k in INPUT_KEYS}

#: Unit of each key inside skidmc (SI, angles in degrees), as pint spells it; also the ``units``
#: attribute written to storage.
SI_UNITS: dict[str, str] = {k.key: k.si_unit for k in INPUT_KEYS}

#: Long name of each key with the report's symbol (storage ``long_name`` attribute).
DESCRIPTIONS: dict[str, str] = {k.key: k.description for k in INPUT_KEYS}


def input_key(key: str) -> InputKey:
    """The :class:`InputKey` of a dotted key (``KeyError`` if there is none)."""
    return _BY_KEY[key]


def bound_reason(key: str) -> str:
    """The rule `key`'s bounds state, for messages (``"must be > 0 Pa"``)."""
    ik = _BY_KEY[key]
    return ik.bounds.rule(ik.si_unit) + ik.bound_note


def in_bounds(key: str, x):
    """Whether `x` (a float, or elementwise an array) lies in `key`'s allowed interval; NaN
    does not (its comparisons are False)."""
    return _BY_KEY[key].bounds.contains(x)


# --- plausible bare numbers ----------------------------------------------------------------------


def format_number(x: float) -> str:
    """A short form for messages: ``1e5``, ``2.5e-3``, ``28000``, ``0.13``."""
    if x != 0 and math.isfinite(x) and not 1e-3 <= abs(x) < 1e5:
        mantissa, exponent = f"{x:.6e}".split("e")
        mantissa = mantissa.rstrip("0").rstrip(".")
        return f"{mantissa}e{int(exponent)}"
    return f"{x:.6g}"


def _unit_suffix(unit: str) -> str:
    return "" if unit in ("1", "-") else f" {unit}"


def implausible_reason(key: str, value: float, written: object, difference: bool = False
                       ) -> str | None:
    """Why a bare number (read as SI) is implausible for `key`, or None when it is plausible.

    Parameters
    ----------
    key : str
        A key of :data:`SCENE_KEYS`.
    value : float
        The number read as SI [SI unit of `key`].
    written : object
        The number as the user wrote it (for the example with units).
    difference : bool
        `value` is a spread (a distribution's scale), checked against the width of the
        plausible range instead of the range.

    Returns
    -------
    str or None
        The reason, naming the SI reading, the plausible range and an example with units; None
        if `key` has no plausible range, `value` is 0 (the same in every unit) or inside it.
    """
    ik = _BY_KEY[key]
    if ik.plausible is None or value == 0 or not math.isfinite(value):
        return None
    lo, hi = ik.plausible
    unit = _unit_suffix(ik.si_unit)
    shown = format_number(value)
    if difference:
        width = hi - lo
        if abs(value) <= width:
            return None
        where = f"wider than the plausible range {format_number(lo)}-{format_number(hi)}{unit}"
    else:
        if lo <= value <= hi:
            return None
        where = f"outside the plausible {format_number(lo)}-{format_number(hi)}{unit}"
    number = str(written).strip()
    example = f'"{number} {ik.example_unit}"' if ik.example_unit else f'"{number}{unit}"'
    return (f"is read as {shown}{unit} (SI), {where}; give units, e.g. {example}"
            f" (or \"{number}{unit}\" if SI is meant)")


# --- checks between keys -------------------------------------------------------------------------


def _isclose(a, b, rel_tol: float = 1e-9, abs_tol: float = 1e-9):
    """:func:`math.isclose`, elementwise on arrays (equal infinities are close, NaN is not)."""
    with np.errstate(invalid="ignore"):
        diff = np.abs(np.subtract(a, b))
        tol = np.maximum(rel_tol * np.maximum(np.abs(a), np.abs(b)), abs_tol)
        return np.equal(a, b) | (np.isfinite(diff) & (diff <= tol))


@dataclasses.dataclass(frozen=True)
class _Between:
    """A rule between keys: `key` is the one an error names, `partner` the other one (named
    instead when the user gave only it), `holds` the elementwise test, `reason` the message."""

    key: str
    partner: str | None
    holds: object
    reason: object


#: The checks between keys, in the order they are reported.
_BETWEEN: tuple[_Between, ...] = (
    _Between(
        "tilt", None,
        lambda v: np.logical_or(v["configuration"] != "vertical",
                                _isclose(v["tilt"], v["angle"])),
        lambda v: (f"must equal angle ({v['angle']:g} deg) for a vertical drop, where the "
                   "billet's flat face is horizontal and psi = phi (report Sec. II.C); leave "
                   "tilt out to have it follow angle")),
    _Between(
        "initial_temperature", "he.melting_point",
        lambda v: np.less(v["initial_temperature"], v["he.melting_point"]),
        lambda v: (f"initial_temperature ({v['initial_temperature']:g} K) must be below "
                   f"he.melting_point ({v['he.melting_point']:g} K)")),
)

#: Keys a check between keys reads.
BETWEEN_KEYS: tuple[str, ...] = ("configuration", "angle", "tilt", "initial_temperature",
                                 "he.melting_point")

#: For a check between two keys: the key an error names -> the other key.
PARTNERS: dict[str, str] = {b.key: b.partner for b in _BETWEEN if b.partner}


def between_keys_ok(values: Mapping):
    """Whether every check between keys holds, elementwise.

    Parameters
    ----------
    values : mapping
        :data:`BETWEEN_KEYS` -> SI floats or 1-D arrays of one length (``configuration`` a
        string); values that pass their own bounds.

    Returns
    -------
    bool or ndarray of bool
    """
    ok = True
    for rule in _BETWEEN:
        ok = np.logical_and(ok, rule.holds(values))
    return ok


def first_broken_between(values: Mapping) -> tuple[str, str] | None:
    """The first check between keys that scalar `values` break, as ``(key, reason)``; None if
    all hold (see :func:`between_keys_ok` for `values`)."""
    for rule in _BETWEEN:
        if not rule.holds(values):
            return rule.key, rule.reason(values)
    return None

