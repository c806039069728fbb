"""Scenes: the named, validated inputs of one skid-test simulation.

A scene is the 19 flat keys of ``docs/architecture.md`` held as SI floats (angles in degrees)
plus the configuration string, in a frozen :class:`Scene`. Build one with :func:`make_scene`,
which starts from a preset or from nothing, applies overrides given as SI floats or unit strings
(``"28000 psi"``), converts them (:func:`skidmc.scene.units.to_si`) and validates them. Every
rejected input raises :class:`skidmc.errors.SceneError` naming the key and the value as given.

The billet tilt psi follows the configuration unless it is given explicitly (report Sec. II.C,
"psi = phi for vertical drops when the flat surface of the hemisphere is horizontal at impact"):
for a vertical drop onto an inclined target psi = phi, the target angle; for the pendulum drop
psi = 0, the harness keeps the flat face horizontal.

A named target material (``target="steel"``, :mod:`skidmc.scene.materials`) sets the three
``target.*`` keys; a bare number for a dimensional key is read as SI and refused by
:func:`make_scene` when that reading is implausible (:attr:`skidmc.scene.keys.InputKey.plausible`).
"""

from __future__ import annotations

import dataclasses
import math
import numbers
from collections.abc import Mapping

import numpy as np

from skidmc.errors import MissingKeyError, SceneError, UnknownKeyError
from skidmc.scene.keys import (
    BETWEEN_KEYS,
    CONFIGURATIONS,
    DEFAULT_TARGET_HARDNESS,
    DESCRIPTIONS,
    FIELDS,
    INFINITE_OK,
    INPUT_KEYS,
    LAYERS_KEY,
    NUMERIC_KEYS,
    PARTNERS,
    SCENE_KEYS,
    SI_UNITS,
    TABLE_KEY,
    between_keys_ok,
    bound_reason,
    first_broken_between,
    format_number,
    implausible_reason,
    in_bounds,
)
from skidmc.scene.materials import (
    MATERIAL_KEY,
    format_layers,
    format_table,
    parse_layers,
    parse_table,
    target_values,
)
from skidmc.scene.presets import PRESETS
from skidmc.scene.units import read_si

__all__ = [
    "CONFIGURATIONS",
    "DESCRIPTIONS",
    "NUMERIC_KEYS",
    "SCENE_KEYS",
    "SI_UNITS",
    "Scene",
    "SceneColumns",
    "get_preset",
    "implausible_inputs",
    "list_presets",
    "make_scene",
]

# Attribute name of each key (dots -> underscores) and back; attribute names are also accepted as
# keys in overrides, so that ``scene.replace(he_density=1900.0)`` works.
_FIELD_OF_KEY: dict[str, str] = FIELDS
_LAYERS_FIELD = LAYERS_KEY.replace(".", "_")
_TABLE_FIELD = TABLE_KEY.replace(".", "_")
_KEY_OF_NAME: dict[str, str] = {
    **{field: key for key, field in _FIELD_OF_KEY.items()},
    **{key: key for key in SCENE_KEYS},
    _LAYERS_FIELD: LAYERS_KEY, LAYERS_KEY: LAYERS_KEY,
    _TABLE_FIELD: TABLE_KEY, TABLE_KEY: TABLE_KEY,
}
_NUMERIC = frozenset(NUMERIC_KEYS)
_ATTRIBUTES_MARK = "<attributes from skidmc.scene.keys.INPUT_KEYS>"


def _fields_from_input_keys(cls: type) -> type:
    """Give `cls` one field per :data:`~skidmc.scene.keys.INPUT_KEYS` entry (in its order, typed
    float or str) and the docstring's Attributes section, before :func:`dataclasses.dataclass`
    makes it a dataclass: the table is the one definition of the fields."""
    cls.__annotations__ = {k.field: k.type_name for k in INPUT_KEYS}
    # The last key, the target's hardness, defaults to the report's rigid target, so that a
    # scene written without it (Scene(...) by hand) means what it did.
    assert INPUT_KEYS[-1].key == "target.hardness"
    cls.target_hardness = DEFAULT_TARGET_HARDNESS
    # Not an input key: a layered target's deeper layers (skidmc.scene.keys.LAYERS_KEY).
    cls.__annotations__[_LAYERS_FIELD] = "str"
    cls.target_layers = ""  # a homogeneous target
    # Not an input key either: a target's temperature table (skidmc.scene.keys.TABLE_KEY).
    cls.__annotations__[_TABLE_FIELD] = "str"
    cls.target_table = ""  # constant properties
    lines = []
    for k in INPUT_KEYS:
        unit = f" [{k.si_unit}]" if k.numeric else ""
        text = k.description[0].upper() + k.description[1:]
        if k.key == "configuration":
            text += ": " + " or ".join(f"``{c!r}``" for c in CONFIGURATIONS)
        lines += [f"    {k.field} : {k.type_name}", f"        {text}{unit}."]
    lines += [f"    {_LAYERS_FIELD} : str",
              "        A layered target's layers beneath the top (canonical SI text, "
              "skidmc.scene.keys.LAYERS_KEY); empty for a homogeneous target.",
              f"    {_TABLE_FIELD} : str",
              "        A target's temperature table (canonical SI text, "
              "skidmc.scene.keys.TABLE_KEY); empty for constant properties."]
    if cls.__doc__:  # None under python -OO
        cls.__doc__ = cls.__doc__.replace("    " + _ATTRIBUTES_MARK, "\n".join(lines))
    return cls


@dataclasses.dataclass(frozen=True)
@_fields_from_input_keys
class Scene:
    """The validated inputs of one skid-test simulation, in SI units (angles in degrees).

    Construct with :func:`make_scene` (unit strings, presets, materials, defaults for
    ``tilt``); direct construction takes SI floats and validates them the same way (bounds and
    the checks between keys; bare numbers are not checked for plausibility here). The fields,
    one per key of :data:`skidmc.scene.keys.INPUT_KEYS` in its order, are generated from that
    table, as is this list.

    Attributes
    ----------
    <attributes from skidmc.scene.keys.INPUT_KEYS>

    Raises
    ------
    SceneError
        On any invalid value (see :func:`make_scene`).
    """

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
            if not (math.isfinite(x) or (key in INFINITE_OK and x == math.inf)):
                raise SceneError(key, value, "must be finite")
            if not in_bounds(key, x):
                raise SceneError(key, value, bound_reason(key))
            object.__setattr__(self, field, x)
        if not isinstance(self.target_layers, str):
            raise SceneError(LAYERS_KEY, self.target_layers, "expected a string (empty for "
                             "a homogeneous target)")
        if self.target_layers:
            parse_layers(self.target_layers)
        if not isinstance(self.target_table, str):
            raise SceneError(TABLE_KEY, self.target_table, "expected a string (empty for "
                             "constant properties)")
        if self.target_table:
            parse_table(self.target_table)
        if self.configuration not in CONFIGURATIONS:
            raise SceneError(
                "configuration", self.configuration,
                "must be one of " + ", ".join(repr(c) for c in CONFIGURATIONS),
            )
        broken = first_broken_between({k: getattr(self, _FIELD_OF_KEY[k]) for k in BETWEEN_KEYS})
        if broken is not None:
            key, reason = broken
            raise SceneError(key, getattr(self, _FIELD_OF_KEY[key]), reason)

    def as_dict(self) -> dict[str, float | str]:
        """Flat dotted keys -> SI values, in the order of :data:`SCENE_KEYS`."""
        return {key: getattr(self, _FIELD_OF_KEY[key]) for key in SCENE_KEYS}

    def replace(self, mapping: Mapping | None = None, /, *, check_plausible: bool = True,
                **overrides) -> Scene:
        """A new scene with some values changed, re-validated.

        Parameters
        ----------
        mapping : mapping, optional
            Overrides with dotted keys (or nested dicts), values as in :func:`make_scene`.
        check_plausible : bool
            As in :func:`make_scene`.
        **overrides
            More overrides; dotted keys via ``**{"he.density": 1900.0}`` or attribute names
            (``he_density=1900.0``); ``target="steel"`` for a material.

        Returns
        -------
        Scene
            ``make_scene(mapping, preset=self, **overrides)``: an unchanged default ``tilt`` keeps
            following the configuration (it tracks a new ``angle`` in a vertical drop).
        """
        return make_scene(mapping, preset=self, check_plausible=check_plausible, **overrides)

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
        return {**preset.as_dict(), LAYERS_KEY: preset.target_layers,
                TABLE_KEY: preset.target_table}
    if isinstance(preset, str):
        return get_preset(preset).as_dict()
    raise SceneError("preset", preset, "expected a preset name or a Scene")


def _convert(key: str, value: object) -> tuple[float | str, bool]:
    """A user value in SI, and whether it was a bare number (see :func:`read_si`)."""
    if key == "configuration":
        if not isinstance(value, str):
            raise SceneError(key, value, "must be one of " + ", ".join(map(repr, CONFIGURATIONS)))
        return value.strip().lower(), False
    if key == LAYERS_KEY:
        if not isinstance(value, str):
            raise SceneError(key, value, "expected a string (set it with a stack: target = "
                             "\"gold 3 mil / copper 7 mil / aluminium-2024\")")
        return (format_layers(*parse_layers(value)) if value.strip() else ""), False
    if key == TABLE_KEY:
        if not isinstance(value, str):
            raise SceneError(key, value, "expected a string (set it with a material that has "
                             "a table: target = \"fused-quartz\")")
        return (format_table(*parse_table(value)) if value.strip() else ""), False
    return read_si(key, value, SI_UNITS[key])


def make_scene(
    mapping: Mapping | None = None, *, preset: str | Scene | None = None,
    check_plausible: bool = True, **overrides
) -> Scene:
    """Build a validated :class:`Scene` from a preset and overrides with units.

    Parameters
    ----------
    mapping : mapping, optional
        Overrides with dotted keys (``{"he.density": "1.91 g/cm^3"}``) or nested dicts as read
        from TOML (``{"he": {"density": ...}}``). Attribute names (``he_density``) are accepted too.
        Values are SI floats or strings with units (:func:`skidmc.scene.units.to_si`). The key
        ``target`` names a material (:mod:`skidmc.scene.materials`): ``{"target": "steel"}``
        sets ``target.density``, ``target.heat_capacity`` and ``target.conductivity``; a
        ``target.*`` key given as well wins over the material's value.
    preset : str or Scene, optional
        Name of a preset (:mod:`skidmc.scene.presets`) or a scene to start from. Without one,
        every key of :data:`SCENE_KEYS` must be given (``tilt`` may be left to its default).
    check_plausible : bool
        Refuse a bare number (no units, read as SI) whose SI reading lies outside its key's
        plausible range (:attr:`skidmc.scene.keys.InputKey.plausible`): ``flow_stress=28000``
        is 28 kPa, surely meant in psi. Unit strings are never refused for plausibility, only
        for bounds. ``False`` for programmatic SI floats (samplers, searches).
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
        ``he.melting_point``; an unknown material (key ``target``, close names suggested); with
        `check_plausible`, a bare number read as an implausible SI value (checked after the
        bounds, so an invalid number gets the bounds' message).

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
    if MATERIAL_KEY in given:  # before the keys given: an explicit target.* key wins
        for key, text in target_values(given.pop(MATERIAL_KEY)).items():
            values[key] = _convert(key, text)[0]
    bare = []
    for key, raw in given.items():
        if key not in SI_UNITS and key not in (LAYERS_KEY, TABLE_KEY):
            raise UnknownKeyError(key, raw, [*SCENE_KEYS, MATERIAL_KEY])
        values[key], is_bare = _convert(key, raw)
        if is_bare:
            bare.append(key)

    if "tilt" not in given and "configuration" in values:
        if values["configuration"] == "vertical" and "angle" in values:
            values["tilt"] = values["angle"]
        elif values["configuration"] == "pendulum" and base.get("configuration") != "pendulum":
            values["tilt"] = 0.0

    # A scene that does not name the target's hardness (the report's presets) has the report's
    # rigid target.
    values.setdefault("target.hardness", DEFAULT_TARGET_HARDNESS)
    values.setdefault(LAYERS_KEY, "")
    values.setdefault(TABLE_KEY, "")
    missing = [key for key in SCENE_KEYS if key not in values]
    if missing:
        raise MissingKeyError(
            missing[0], None,
            "missing; no value for " + ", ".join(missing) + "; give them or start from a preset",
        )
    try:
        scene = Scene(**{_FIELD_OF_KEY[key]: values[key] for key in SCENE_KEYS},
                      target_layers=values[LAYERS_KEY], target_table=values[TABLE_KEY])
    except SceneError as err:
        # Name the value as the user wrote it (not its SI conversion), and for a check between two
        # keys name the one the user gave.
        key = err.key
        if key not in given and PARTNERS.get(key) in given:
            key = PARTNERS[key]
        if key in given:
            raise SceneError(key, given[key], err.reason) from None
        raise
    if check_plausible:
        for key in bare:
            reason = implausible_reason(key, values[key], given[key])
            if reason is not None:
                raise SceneError(key, given[key], reason)
    return scene


class SceneColumns:
    """The scenes of a batch of samples that each set the same numeric keys of one base scene.

    ``SceneColumns(base, columns).scene(i)`` is ``make_scene(row, preset=base,
    check_plausible=False)`` (programmatic SI floats are not checked for plausibility) for the row
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
        # "must be finite"). The checks between keys are the scalar path's own function, on
        # the base's values with the columns (and a derived tilt) laid over them.
        ok = np.ones(self._m, dtype=bool)
        for key in self.keys:
            ok &= in_bounds(key, columns[key])
        if any(k in BETWEEN_KEYS for k in (*self.keys, *self.derived)):
            between = {k: columns[k] if k in columns else getattr(base, _FIELD_OF_KEY[k])
                       for k in BETWEEN_KEYS}
            if follows:
                between["tilt"] = between["angle"]
            ok &= between_keys_ok(between)
        self._ok = ok.tolist()

    @staticmethod
    def accepts(base: object, columns: Mapping) -> bool:
        """Whether ``SceneColumns(base, columns)`` applies: `base` a Scene, `columns` dotted
        numeric keys -> 1-D float64 arrays of one length."""
        return (isinstance(base, Scene) and isinstance(columns, Mapping)
                and all(isinstance(k, str) and k in _NUMERIC for k in columns)
                and all(isinstance(v, np.ndarray) and v.ndim == 1 and v.dtype == np.float64
                        for v in columns.values())
                and len({len(v) for v in columns.values()}) <= 1)

    def __len__(self) -> int:
        return self._m

    def row(self, i: int) -> dict[str, float]:
        """Row `i` as :func:`make_scene` overrides: key -> SI float."""
        return dict(zip(self.keys, self._rows[i]))  # zip stops before a derived tilt

    def scene(self, i: int) -> Scene:
        """The scene of row `i`: ``make_scene(self.row(i), preset=self.base,
        check_plausible=False)``.

        Raises
        ------
        SceneError
            Row `i` is invalid; the error :func:`make_scene` raises for it.
        """
        if not self._ok[i]:
            return make_scene(self.row(i), preset=self.base, check_plausible=False)
        # Every value was checked above (or is the validated base's), so the scene is filled in
        # directly rather than through the frozen dataclass's __init__ and __post_init__, which
        # would check all 18 keys again.
        fields = self._base_fields.copy()
        fields.update(zip(self._fields, self._rows[i]))
        scene = object.__new__(Scene)
        scene.__dict__.update(fields)
        return scene


def implausible_inputs(scene: Scene) -> tuple[str, ...]:
    """The scene's values outside their key's plausible range (:attr:`InputKey.plausible`),
    one line each: ``"flow_stress = 6.9e18 Pa is outside the plausible 1e5-1e10 Pa"``.

    A bare number outside that range is refused by :func:`make_scene` (it is likely in another
    unit); a value written with units is taken at its word but flagged with this: the model was
    never meant for it, and its critical height may mean nothing. Only the allowed interval
    (:attr:`InputKey.bounds`: a negative density, an angle of 90 deg) is physically impossible
    and refused.
    """
    out = []
    for ik in INPUT_KEYS:
        if ik.plausible is None:
            continue
        value = getattr(scene, ik.field)
        lo, hi = ik.plausible
        if isinstance(value, (int, float)) and value != 0 and math.isfinite(value) \
                and not lo <= value <= hi:
            unit = "" if ik.si_unit in ("1", "-") else f" {ik.si_unit}"
            out.append(f"{ik.key} = {format_number(value)}{unit} is outside the plausible "
                       f"{format_number(lo)}-{format_number(hi)}{unit}")
    return tuple(out)


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
