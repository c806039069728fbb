"""Scenes: the named, validated inputs of one skid-test simulation.

A scene is the 19 flat keys of ``docs/architecture.md`` held as SI floats (angles in degrees)
plus the configuration string, in a frozen :class:`Scene`. Build one with :func:`make_scene`,
which starts from a preset or from nothing, applies overrides given as SI floats or unit strings
(``"28000 psi"``), converts them (:func:`skidmc.scene.units.to_si`) and validates them. Every rejected
input raises :class:`skidmc.errors.SceneError` naming the key and the value as given.

The billet tilt psi follows the configuration unless it is given explicitly (report Sec. II.C and
physics notes sec. 1): for a vertical drop onto an inclined target psi = phi, the target angle;
for the pendulum drop psi = 0, the harness keeps the flat face horizontal.
"""

from __future__ import annotations

import dataclasses
import math
import numbers
from collections.abc import Mapping

import numpy as np

from skidmc.errors import MissingKeyError, SceneError, UnknownKeyError
from skidmc.scene.keys import (
    _BOUNDS,
    _PARTNER,
    CONFIGURATIONS,
    DESCRIPTIONS,
    NUMERIC_KEYS,
    SCENE_KEYS,
    SI_UNITS,
    bound_reason,
    in_bounds,
)
from skidmc.scene.presets import PRESETS
from skidmc.scene.units import to_si

__all__ = [
    "CONFIGURATIONS",
    "DESCRIPTIONS",
    "NUMERIC_KEYS",
    "SCENE_KEYS",
    "SI_UNITS",
    "Scene",
    "SceneColumns",
    "get_preset",
    "list_presets",
    "make_scene",
]

# Attribute name of each key (dots -> underscores) and back; attribute names are also accepted as
# keys in overrides, so that ``scene.replace(he_density=1900.0)`` works.
_FIELD_OF_KEY: dict[str, str] = {k: k.replace(".", "_") for k in SCENE_KEYS}
_KEY_OF_NAME: dict[str, str] = {
    **{field: key for key, field in _FIELD_OF_KEY.items()},
    **{key: key for key in SCENE_KEYS},
}

@dataclasses.dataclass(frozen=True)
class Scene:
    """The validated inputs of one skid-test simulation, in SI units (angles in degrees).

    Construct with :func:`make_scene` (unit strings, presets, defaults for ``tilt``); direct
    construction takes SI floats and validates them the same way.

    Attributes
    ----------
    mu : float
        Apparent coefficient of sliding friction, Eq. (1) [1].
    flow_stress : float
        Plastic flow stress of the billet sigma [Pa].
    billet_mass : float
        Billet mass W [kg].
    billet_diameter : float
        Hemisphere diameter D [m].
    configuration : str
        ``"pendulum"`` or ``"vertical"``.
    angle : float
        phi: complement of the approach angle (pendulum) or target angle (vertical) [deg].
    tilt : float
        psi: billet tilt; 0 for the pendulum, equal to `angle` for the vertical drop [deg].
    initial_temperature : float
        T0 [K].
    he_density, he_heat_capacity, he_conductivity : float
        HE density [kg/m^3], specific heat [J/(kg K)], thermal conductivity [W/(m K)].
    he_heat_of_fusion : float
        HE latent heat of melting, 0 disables melting [J/kg].
    he_melting_point : float
        HE melting temperature [K].
    kinetics_prefactor : float
        Arrhenius frequency factor Z [1/s].
    kinetics_activation_temperature : float
        Activation temperature E/R [K].
    kinetics_heat_of_reaction : float
        Heat of reaction per unit mass Q [J/kg].
    target_density, target_heat_capacity, target_conductivity : float
        Target density [kg/m^3], specific heat [J/(kg K)], thermal conductivity [W/(m K)].

    Raises
    ------
    SceneError
        On any invalid value (see :func:`make_scene`).
    """

    mu: float
    flow_stress: float
    billet_mass: float
    billet_diameter: float
    configuration: str
    angle: float
    tilt: float
    initial_temperature: float
    he_density: float
    he_heat_capacity: float
    he_conductivity: float
    he_heat_of_fusion: float
    he_melting_point: float
    kinetics_prefactor: float
    kinetics_activation_temperature: float
    kinetics_heat_of_reaction: float
    target_density: float
    target_heat_capacity: float
    target_conductivity: float

    def __post_init__(self) -> None:
        for key in NUMERIC_KEYS:
            field = _FIELD_OF_KEY[key]
            value = getattr(self, field)
            if isinstance(value, bool) or not isinstance(value, numbers.Real):
                raise SceneError(
                    key, value,
                    f"Scene() takes a real number in [{SI_UNITS[key]}]; use make_scene() for "
                    "unit strings",
                )
            x = float(value)
            if not math.isfinite(x):
                raise SceneError(key, value, "must be finite")
            if not in_bounds(key, x):
                raise SceneError(key, value, bound_reason(key))
            object.__setattr__(self, field, x)
        if self.configuration not in CONFIGURATIONS:
            raise SceneError(
                "configuration", self.configuration,
                "must be one of " + ", ".join(repr(c) for c in CONFIGURATIONS),
            )
        if self.configuration == "vertical" and not math.isclose(
            self.tilt, self.angle, rel_tol=1e-9, abs_tol=1e-9
        ):
            raise SceneError(
                "tilt", self.tilt,
                f"must equal angle ({self.angle:g} deg) for a vertical drop, where the billet's "
                "flat face is horizontal and psi = phi (report Sec. II.C); leave tilt out to have "
                "it follow angle",
            )
        if self.initial_temperature >= self.he_melting_point:
            raise SceneError(
                "initial_temperature", self.initial_temperature,
                f"initial_temperature ({self.initial_temperature:g} K) must be below "
                f"he.melting_point ({self.he_melting_point:g} K)",
            )

    def as_dict(self) -> dict[str, float | str]:
        """Flat dotted keys -> SI values, in the order of :data:`SCENE_KEYS`."""
        return {key: getattr(self, _FIELD_OF_KEY[key]) for key in SCENE_KEYS}

    def replace(self, mapping: Mapping | None = None, /, **overrides) -> Scene:
        """A new scene with some values changed, re-validated.

        Parameters
        ----------
        mapping : mapping, optional
            Overrides with dotted keys (or nested dicts), values as in :func:`make_scene`.
        **overrides
            More overrides; dotted keys via ``**{"he.density": 1900.0}`` or attribute names
            (``he_density=1900.0``).

        Returns
        -------
        Scene
            ``make_scene(mapping, preset=self, **overrides)``: an unchanged default ``tilt`` keeps
            following the configuration (it tracks a new ``angle`` in a vertical drop).
        """
        return make_scene(mapping, preset=self, **overrides)

    def describe(self) -> str:
        """An aligned plain-text table: key, value, unit, description."""
        rows = []
        for key, value in self.as_dict().items():
            unit = SI_UNITS[key]
            shown = value if isinstance(value, str) else f"{value:.6g}"
            rows.append((key, shown, "" if unit in ("1", "-") else unit, DESCRIPTIONS[key]))
        widths = [max(len(r[i]) for r in rows) for i in range(3)]
        return "\n".join(
            f"{k:<{widths[0]}}  {v:>{widths[1]}}  {u:<{widths[2]}}  {d}" for k, v, u, d in rows
        )


def _flatten(mapping: Mapping, prefix: str = "", out: dict | None = None) -> dict:
    """Nested dicts (as read from TOML) -> flat dotted keys; attribute names -> dotted keys."""
    out = {} if out is None else out
    for name, value in mapping.items():
        if not isinstance(name, str):
            raise UnknownKeyError(str(name), value, SCENE_KEYS)
        dotted = prefix + name
        if isinstance(value, Mapping):
            _flatten(value, dotted + ".", out)
            continue
        key = _KEY_OF_NAME.get(dotted, dotted)
        if key in out:
            raise SceneError(key, value, f"given twice (also as {out[key]!r})")
        out[key] = value
    return out


def _base_values(preset: str | Scene | None) -> dict:
    if preset is None:
        return {}
    if isinstance(preset, Scene):
        return preset.as_dict()
    if isinstance(preset, str):
        return get_preset(preset).as_dict()
    raise SceneError("preset", preset, "expected a preset name or a Scene")


def _convert(key: str, value: object) -> float | str:
    if key == "configuration":
        if not isinstance(value, str):
            raise SceneError(key, value, "must be one of " + ", ".join(map(repr, CONFIGURATIONS)))
        return value.strip().lower()
    return to_si(key, value, SI_UNITS[key])


def make_scene(
    mapping: Mapping | None = None, *, preset: str | Scene | None = None, **overrides
) -> Scene:
    """Build a validated :class:`Scene` from a preset and overrides with units.

    Parameters
    ----------
    mapping : mapping, optional
        Overrides with dotted keys (``{"he.density": "1.91 g/cm^3"}``) or nested dicts as read
        from TOML (``{"he": {"density": ...}}``). Attribute names (``he_density``) are accepted too.
        Values are SI floats or strings with units (:func:`skidmc.scene.units.to_si`).
    preset : str or Scene, optional
        Name of a preset (:mod:`skidmc.scene.presets`) or a scene to start from. Without one, every key
        of :data:`SCENE_KEYS` must be given (``tilt`` may be left to its default).
    **overrides
        More overrides, applied after `mapping` (a key in both takes this value).

    Returns
    -------
    Scene
        The validated scene, SI floats (angles in degrees).

    Raises
    ------
    UnknownKeyError
        A key not in :data:`SCENE_KEYS`, with close matches suggested.
    MissingKeyError
        No preset, and some key has no value.
    UnitError
        Units that cannot be parsed or have the wrong dimension.
    SceneError
        Otherwise invalid: not a single number (booleans and lists are refused); not finite;
        out of range (``flow_stress``, ``billet_mass``, ``billet_diameter``, densities, heat
        capacities, conductivities, ``kinetics.prefactor``, ``kinetics.activation_temperature``,
        ``initial_temperature``, ``he.melting_point`` > 0; ``he.heat_of_fusion``,
        ``kinetics.heat_of_reaction`` >= 0; 0 <= ``mu`` < 5; 0 < ``angle`` < 90 deg;
        0 <= ``tilt`` < 90 deg); ``configuration`` not ``"pendulum"``/``"vertical"``; a vertical
        drop whose ``tilt`` differs from ``angle``; ``initial_temperature`` not below
        ``he.melting_point``.

    Notes
    -----
    ``tilt`` not given in the overrides follows the configuration: it equals ``angle`` for a
    vertical drop (report Sec. II.C: psi = phi), and for a pendulum drop it is the starting
    scene's tilt if that was a pendulum scene too, else 0 (the harness keeps the billet level).
    """
    base = _base_values(preset)
    if mapping is not None and not isinstance(mapping, Mapping):
        raise SceneError("mapping", mapping, "expected a mapping of scene keys to values")
    given = _flatten(mapping or {})
    given.update(_flatten(overrides))  # keyword overrides win over the mapping
    values = dict(base)
    for key, raw in given.items():
        if key not in SI_UNITS:
            raise UnknownKeyError(key, raw, SCENE_KEYS)
        values[key] = _convert(key, raw)

    if "tilt" not in given and "configuration" in values:
        if values["configuration"] == "vertical" and "angle" in values:
            values["tilt"] = values["angle"]
        elif values["configuration"] == "pendulum" and base.get("configuration") != "pendulum":
            values["tilt"] = 0.0

    missing = [key for key in SCENE_KEYS if key not in values]
    if missing:
        raise MissingKeyError(
            missing[0], None,
            "missing; no value for " + ", ".join(missing) + "; give them or start from a preset",
        )
    try:
        return Scene(**{_FIELD_OF_KEY[key]: values[key] for key in SCENE_KEYS})
    except SceneError as err:
        # Name the value as the user wrote it (not its SI conversion), and for a check between two
        # keys name the one the user gave.
        key = err.key
        if key not in given and _PARTNER.get(key) in given:
            key = _PARTNER[key]
        if key in given:
            raise SceneError(key, given[key], err.reason) from None
        raise


class SceneColumns:
    """The scenes of a batch of samples that each set the same numeric keys of one base scene.

    ``SceneColumns(base, columns).scene(i)`` is ``make_scene(row, preset=base)`` for the row
    ``row = {key: float(columns[key][i]) for key in columns}`` (:meth:`row`): the same scene, bit
    for bit, and for an invalid row the same error. It exists for the ensemble runner, which
    builds a scene per sample from sampled SI floats: :func:`make_scene` does per row what is
    the same for every row of a batch (flattening and looking up keys, unit conversion, checking
    the 18 keys, most of them the base's), ~60 us a scene, a few percent of a study's time at
    the solver's speed. Here the checks run once per batch on whole columns, and only for what
    can change: the range of each key given and the checks between keys that involve one; the
    rest of the scene is the validated base. A row that passes is the base with the row's values
    (and, in a vertical drop, ``tilt`` following ``angle`` as :func:`make_scene` has it); a row
    that fails goes through :func:`make_scene`, which raises the error naming key and value.

    Parameters
    ----------
    base : Scene
        The scene the rows override.
    columns : mapping of str to ndarray
        Dotted numeric keys (:data:`NUMERIC_KEYS`) -> 1-D float64 arrays of one length, in SI
        units. Other batches (unit strings, attribute names, integers, ``configuration``) are
        :func:`make_scene`'s alone: check with :meth:`accepts`.

    Attributes
    ----------
    base : Scene
    keys : tuple of str
        The keys of `columns`, in their order.
    derived : tuple of str
        Keys not given whose value a row's scene takes from the row: ``("tilt",)`` in a vertical
        drop without a ``tilt`` column (tilt = angle), else empty. Every other key is the row's
        value (given) or the base's.

    Raises
    ------
    ValueError
        `columns` not accepted by :meth:`accepts`.
    """

    def __init__(self, base: Scene, columns: Mapping[str, np.ndarray]) -> None:
        if not self.accepts(base, columns):
            raise ValueError("SceneColumns takes a Scene and columns {numeric scene key: 1-D "
                             "float64 array} of one length; use make_scene for other inputs")
        self.base = base
        self.keys = tuple(columns)
        self._m = len(next(iter(columns.values()))) if columns else 0
        follows = base.configuration == "vertical" and "tilt" not in columns
        self.derived = ("tilt",) if follows else ()

        # A scene's fields: the base's, then the row's values; tolist() gives the Python floats
        # that make_scene's float() would. A vertical drop's tilt is the row's angle (or the
        # base's: make_scene sets it to angle, which a valid base matches only to 1e-9), so it
        # goes last in each row, after the given keys, where row() does not see it.
        self._base_fields = {f.name: getattr(base, f.name) for f in dataclasses.fields(Scene)}
        values = [columns[k].tolist() for k in self.keys]
        self._fields = tuple(_FIELD_OF_KEY[k] for k in self.keys)
        if follows:
            if "angle" in columns:
                values.append(values[self.keys.index("angle")])
                self._fields += ("tilt",)
            else:
                self._base_fields["tilt"] = base.angle
        self._rows = list(zip(*values)) if values else [()] * self._m

        # Scene.__post_init__'s checks for what a row changes, all rows at once (comparisons
        # with NaN are False, and +-inf fails every range: both go to make_scene, which says
        # "must be finite").
        ok = np.ones(self._m, dtype=bool)
        for key in self.keys:
            ok &= in_bounds(key, columns[key])
        if "initial_temperature" in columns or "he.melting_point" in columns:
            t0 = columns.get("initial_temperature", base.initial_temperature)
            ok &= t0 < columns.get("he.melting_point", base.he_melting_point)
        if base.configuration == "vertical" and "tilt" in columns:
            angles = columns["angle"].tolist() if "angle" in columns else [base.angle] * self._m
            ok &= np.array([math.isclose(t, a, rel_tol=1e-9, abs_tol=1e-9)  # as __post_init__
                            for t, a in zip(values[self.keys.index("tilt")], angles)], dtype=bool)
        self._ok = ok.tolist()

    @staticmethod
    def accepts(base: object, columns: Mapping) -> bool:
        """Whether ``SceneColumns(base, columns)`` applies: `base` a Scene, `columns` dotted
        numeric keys -> 1-D float64 arrays of one length."""
        return (isinstance(base, Scene) and isinstance(columns, Mapping)
                and all(isinstance(k, str) and k in _BOUNDS for k in columns)
                and all(isinstance(v, np.ndarray) and v.ndim == 1 and v.dtype == np.float64
                        for v in columns.values())
                and len({len(v) for v in columns.values()}) <= 1)

    def __len__(self) -> int:
        return self._m

    def row(self, i: int) -> dict[str, float]:
        """Row `i` as :func:`make_scene` overrides: key -> SI float."""
        return dict(zip(self.keys, self._rows[i]))  # zip stops before a derived tilt

    def scene(self, i: int) -> Scene:
        """The scene of row `i`: ``make_scene(self.row(i), preset=self.base)``.

        Raises
        ------
        SceneError
            Row `i` is invalid; the error :func:`make_scene` raises for it.
        """
        if not self._ok[i]:
            return make_scene(self.row(i), preset=self.base)
        # Every value was checked above (or is the validated base's), so the scene is filled in
        # directly rather than through the frozen dataclass's __init__ and __post_init__, which
        # would check all 18 keys again.
        fields = self._base_fields.copy()
        fields.update(zip(self._fields, self._rows[i]))
        scene = object.__new__(Scene)
        scene.__dict__.update(fields)
        return scene


def list_presets() -> list[str]:
    """Names of the presets, in the order of :data:`PRESETS`."""
    return list(PRESETS)


def get_preset(name: str) -> Scene:
    """The validated scene of a preset.

    Parameters
    ----------
    name : str
        A key of :data:`PRESETS`.

    Returns
    -------
    Scene
        The preset's values converted to SI.

    Raises
    ------
    SceneError
        Unknown name (the message lists the presets).
    """
    if not isinstance(name, str) or name not in PRESETS:
        raise SceneError("preset", name, "unknown preset; presets: " + ", ".join(PRESETS))
    return make_scene(PRESETS[name]["values"])
