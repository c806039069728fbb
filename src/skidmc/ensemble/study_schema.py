"""The study file formats, declared once as pydantic v2 models that load them.

Each kind of study file is one model (:data:`SCHEMAS`, kind -> model): its tables, keys, types,
defaults and allowed words are the models' fields, with one distribution schema shared by every
kind (:class:`DistributionSpec`). The same models

- load a file: ``model.model_validate(doc)`` validates the TOML document and builds the study's
  data model (:mod:`skidmc.ensemble.study_model`): :func:`load_model` turns the first error
  into a :class:`~skidmc.ensemble.study_model.StudyError` naming the file, the TOML key path,
  the value as written and the rule with a suggestion (:func:`skidmc.ensemble.study.load_study`,
  :func:`skidmc.ensemble.hazard_study.load_hazard_study`);
- export the JSON Schema of each kind (:func:`json_schema`, ``docs/schemas/<kind>.json``), so that
  an editor with a TOML language server (taplo, Even Better TOML) checks a study file as it is
  typed (``#:schema ../docs/schemas/ensemble.json`` as the file's first line).

How the models keep skidmc's messages. Every table derives from :class:`_Table`, whose
before-validator refuses, in this order, a value that is not a table, an unknown key (with the
closest names, ``did you mean 'design'?``) and a missing required key (the model's
``MISSING`` says why it is needed). Each field's type carries a validator with the rule in words
(:func:`_integer`, :func:`_word`, ...); a rule that needs several fields is an after-validator of
the table that holds them. They raise :class:`_Problem`, which carries the rule and, where
it is not the field's own, the key path below it and the value as written; :func:`load_model`
reads the path from pydantic's error location.

What pydantic cannot express, kept as validators (and why):

- a distribution's parameters are scipy's names for the distribution the file names
  (``s`` for lognorm, ``a``/``b`` for truncnorm): the allowed keys depend on a value, not on
  a static field set (:meth:`DistributionSpec._parameters`);
- units: a parameter's role (a level, a spread, a pure number, :func:`_parameter_role`)
  depends on the distribution and on ``loc``; its unit on the key the table is filed under;
  a bare number is refused where its SI reading is implausible (:func:`_convert`);
- the physical range at the tail quantiles, per scene, for keys uncertain at two levels on
  the products of both levels (:func:`_check_support`), the kinetics prefactor reached through
  the rate at a reference temperature (:func:`_check_rate_reference`), a positive definite
  correlation matrix, one kind per key across scenes: each is a computation on several tables
  (the root model's after-validator);
- the scene itself (a preset plus overrides with units, validated by
  :func:`skidmc.scene.make_scene`) and a surface's material (the registry
  :mod:`skidmc.scene.materials`): their rules live in the scene layer, called here.

pydantic rather than attrs + cattrs: it validates and exports JSON Schema from the same
declaration, and it is already a dependency of the tools around the package.

A new kind's file format is one model class, registered with :func:`register`; it may reuse
:class:`DistributionSpec`, :class:`SceneTable`, :class:`SolverSpec` and the field types here.
"""

from __future__ import annotations

import dataclasses
import difflib
import hashlib
import json
import math
import numbers
import re
from collections.abc import Callable, Mapping
from typing import Annotated, ClassVar, Literal

import numpy as np
import scipy.stats
from pydantic import (
    BaseModel,
    BeforeValidator,
    ConfigDict,
    Field,
    PrivateAttr,
    ValidationError,
    model_validator,
)

from skidmc.ensemble import study_model
from skidmc.ensemble.study_model import (
    BILLET_KEYS,
    DESIGN_METHODS,
    ESTIMATOR_METHODS,
    EXTRA_KEYS,
    KINDS,
    RATE_AT_REFERENCE,
    STUDY_RANGES,
    U_TAIL,
    Correlation,
    Distribution,
    EstimatorOptions,
    HazardStudy,
    SolverOptions,
    Study,
    StudyError,
    StudyScene,
    Surface,
    aleatory_factor_column,
    check_n,
    prefactor_from_rate,
)
from skidmc.errors import SceneError
from skidmc.scene import NUMERIC_KEYS, SCENE_KEYS, SI_UNITS, Scene, make_scene
from skidmc.scene.keys import implausible_reason
from skidmc.scene.materials import TARGET_KEYS, get_material
from skidmc.scene.units import from_si, read_si, to_si

__all__ = [
    "SCHEMAS",
    "DistributionSpec",
    "EnsembleFile",
    "HazardFile",
    "SceneTable",
    "SobolFile",
    "SolverSpec",
    "StudyFile",
    "json_schema",
    "load_model",
    "register",
    "suggest",
    "toml_key",
]


# --- messages -------------------------------------------------------------------------------------


class _Problem(ValueError):
    """A broken rule, raised inside a validator: `reason` in words; `where`, the key path below
    the location pydantic reports (empty: the location itself); `value`, the value as written
    (default: the input pydantic reports there)."""

    _INPUT: ClassVar[object] = object()

    def __init__(self, reason: str, *where: str | int, value: object = _INPUT) -> None:
        super().__init__(reason)
        self.reason, self.where, self.value = reason, where, value


def toml_key(*parts: str | int) -> str:
    """Dotted TOML path for messages; parts holding a dot are quoted (``uncertain."he.k"``)."""
    out: list[str] = []
    for part in parts:
        if isinstance(part, int):
            out[-1] += f"[{part}]"
        elif re.fullmatch(r"[A-Za-z0-9_-]+", part):
            out.append(part)
        else:
            out.append(f'"{part}"')
    return ".".join(out)


def suggest(word: str, options) -> str:
    """``did you mean 'x'?`` for close matches of `word`, else the list of `options`."""
    close = difflib.get_close_matches(word, list(options), n=3, cutoff=0.6)
    if close:
        return "did you mean " + " or ".join(repr(c) for c in close) + "?"
    return "expected one of " + ", ".join(repr(o) for o in options)


def load_model(model: type[BaseModel], doc: object, file: str) -> BaseModel:
    """Validate a TOML document with `model`; its first error as a StudyError.

    Parameters
    ----------
    model : type
        A model of :data:`SCHEMAS`.
    doc : dict
        The TOML document.
    file : str
        The file named in messages.

    Returns
    -------
    BaseModel
        The validated model (``.build(text, file)`` builds the study's data model).

    Raises
    ------
    StudyError
        Naming the file, the TOML key path, the value as written and the rule broken.
    """
    try:
        return model.model_validate(doc)
    except ValidationError as exc:
        raise _study_error(exc, file) from None


def _study_error(exc: ValidationError, file: str) -> StudyError:
    error = exc.errors(include_url=False)[0]
    loc = tuple(error["loc"])
    value = error.get("input")
    problem = (error.get("ctx") or {}).get("error")
    if isinstance(problem, _Problem):
        loc += problem.where
        reason = problem.reason
        if problem.value is not _Problem._INPUT:
            value = problem.value
    elif error["type"] == "missing":  # pragma: no cover - MISSING names every required key
        value, reason = None, "missing"
    else:  # pragma: no cover - every field's validator phrases its own rule first
        reason = error["msg"]
    return StudyError(file, toml_key(*loc), value, reason)


# --- field rules ----------------------------------------------------------------------------------


def _rule(check: Callable[[object], bool], reason: str) -> BeforeValidator:
    """A validator refusing a value for which `check` is false, with `reason`."""

    def validate(value):
        if not check(value):
            raise _Problem(reason)
        return value

    return BeforeValidator(validate)


def _is_real(value: object) -> bool:
    return not isinstance(value, bool) and isinstance(value, numbers.Real)


def _integer(minimum: int, reason: str | None = None) -> BeforeValidator:
    return _rule(lambda v: isinstance(v, int) and not isinstance(v, bool) and v >= minimum,
                 reason or f"expected an integer >= {minimum}")


def _open_unit(reason: str = "expected a number in (0, 1)") -> BeforeValidator:
    return _rule(lambda v: _is_real(v) and 0 < v < 1, reason)


def _boolean() -> BeforeValidator:
    return _rule(lambda v: isinstance(v, bool), "expected true or false")


def _text(reason: str) -> BeforeValidator:
    """A string that is not blank."""
    return _rule(lambda v: isinstance(v, str) and bool(v.strip()), reason)


def _string(reason: str = "expected a string") -> BeforeValidator:
    return _rule(lambda v: isinstance(v, str), reason)


def _word(options: tuple[str, ...] | Callable[[], tuple[str, ...]],
          reason: str | None = None) -> BeforeValidator:
    """One of `options` (or of what it returns), else `reason` or the closest words."""

    def validate(value):
        words = options() if callable(options) else options
        if not isinstance(value, str) or value not in words:
            raise _Problem(reason or suggest(str(value), words))
        return value

    return BeforeValidator(validate)


_NAME_PATTERN = re.compile(r"^[A-Za-z0-9][A-Za-z0-9._-]*$")


def _name(reason: str, empty: bool = False) -> BeforeValidator:
    """A name of results or scenes (letters, digits, '.', '_', '-'); "" only if `empty`."""

    def validate(value):
        if not isinstance(value, str):
            raise _Problem("expected a string")
        if not (empty and not value) and not _NAME_PATTERN.match(value):
            raise _Problem(reason)
        return value

    return BeforeValidator(validate)


def _quantity_rule(value: object) -> object:
    if not (_is_real(value) or isinstance(value, str)):
        raise _Problem("expected a number (SI) or a quantity with units, e.g. '580 K'")
    return value


def _sentences(value: object) -> object:
    if not isinstance(value, list) or not all(isinstance(v, str) and v.strip() for v in value):
        raise _Problem("expected a list of sentences, one judgement of the study each (printed "
                       "under Assumptions)")
    return value


#: A number (SI) or a quantity with units ("28000 psi", "580 K").
Quantity = Annotated[float | str, BeforeValidator(_quantity_rule),
                     Field(description="a number (SI) or a quantity with units")]
_STUDY_NAME = _name("must be letters, digits, '.', '_' or '-' (it names the results folder)")
_DIST_SOURCE_RULE = ("every distribution needs a `source`: where its width comes from (report, "
                     "handbook, literature)")
_DIST_SOURCE = _text(_DIST_SOURCE_RULE)


class _Table(BaseModel):
    """A TOML table: a table, no unknown key (the closest names suggested), every required key
    given (``MISSING``: key -> why it is needed)."""

    model_config = ConfigDict(extra="forbid")
    NOT_A_TABLE: ClassVar[str] = "expected a table"
    MISSING: ClassVar[dict[str, str]] = {}

    @model_validator(mode="before")
    @classmethod
    def _table(cls, value: object) -> object:
        if not isinstance(value, dict):
            raise _Problem(cls.NOT_A_TABLE)
        cls._first(value)
        if cls.model_config.get("extra") == "forbid":
            allowed = list(cls.model_fields)
            for name, item in value.items():
                if name not in allowed:
                    raise _Problem("unknown key; " + suggest(name, allowed), name, value=item)
        for name, reason in cls.MISSING.items():
            if name not in value:
                raise _Problem(reason, name, value=None)
        cls._then(value)
        return value

    @classmethod
    def _first(cls, table: dict) -> None:
        """Rules checked before the keys (none here)."""

    @classmethod
    def _then(cls, table: dict) -> None:
        """Rules between keys checked before their values (none here)."""


# --- distributions --------------------------------------------------------------------------------


_CONTINUOUS = tuple(n for n in dir(scipy.stats)
                    if isinstance(getattr(scipy.stats, n), scipy.stats.rv_continuous))
# "<number> <unit>": to convert a spread (a temperature difference) separately from a level.
_NUMBER_THEN_UNIT = re.compile(r"^\s*[+-]?(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?\s*(?P<unit>.*?)\s*$")

# Hints for invalid parameters of the common distributions (scipy's conventions).
_PARAMETER_RULES = {
    "norm": "scale > 0",
    "lognorm": "s > 0 and scale > 0 (scale is the median when loc = 0)",
    "truncnorm": "scale > 0 and a < b; a and b are in standard deviations from loc: "
                 "a = (lower - loc) / scale",
    "uniform": "scale > 0: the interval is [loc, loc + scale]",
    "loguniform": "0 < a < b: the interval is [a, b]",
    "triang": "0 <= c <= 1 and scale > 0: the interval is [loc, loc + scale], mode at "
              "loc + c scale",
    "beta": "a > 0, b > 0 and scale > 0: the interval is [loc, loc + scale]",
}


def _distribution_name(value: object) -> object:
    dist = getattr(scipy.stats, value, None) if isinstance(value, str) else None
    if not isinstance(dist, scipy.stats.rv_continuous):
        raise _Problem("not a scipy.stats continuous distribution; " +
                       suggest(str(value), _CONTINUOUS))
    return value


class DistributionSpec(_Table):
    """One uncertain input: a scipy.stats continuous distribution by name, its parameters by
    scipy's names (shapes, loc, scale; any extra key here), a source (every kind).

    The parameters are checked against the distribution named (its shapes, ``loc``,
    ``scale``); their units against the key the table is filed under, when the study is built
    (:meth:`build`)."""

    model_config = ConfigDict(extra="allow", json_schema_extra={
        "additionalProperties": {"type": ["number", "string"]}})
    NOT_A_TABLE = "expected a table with a `distribution`"
    MISSING = {"distribution": "missing (a scipy.stats name: norm, lognorm, truncnorm, uniform, "
               "loguniform, triang, beta, ...)", "source": _DIST_SOURCE_RULE}
    distribution: Annotated[str, BeforeValidator(_distribution_name)] = Field(
        description="name of a scipy.stats continuous distribution")
    source: Annotated[str, _DIST_SOURCE] = Field(min_length=1,
                                                 description="where its width comes from")
    relative: Annotated[bool, _boolean()] = Field(False, description="a factor on each "
                                                  "scene's value")
    kind: Annotated[Literal["aleatory", "epistemic"], _word(
        KINDS, "expected 'aleatory' (varies from drop to drop) or 'epistemic' (fixed but "
        "unknown)")] = Field("aleatory", description="varies drop to drop, or fixed but unknown")
    reference_temperature: Quantity | None = Field(
        None, description="kinetics.rate_at_reference only: T_ref")

    @model_validator(mode="after")
    def _parameters(self) -> DistributionSpec:
        dist = getattr(scipy.stats, self.distribution)
        shapes = [s.strip() for s in (dist.shapes or "").split(",") if s.strip()]
        allowed = (*shapes, "loc", "scale")
        given = self.parameters
        for pname, value in given.items():
            if pname not in allowed:
                raise _Problem(f"not a parameter of scipy.stats.{self.distribution} (its "
                               f"parameters: {', '.join(allowed)})", pname, value=value)
        for s in shapes:
            if s not in given:
                raise _Problem(f"missing: scipy.stats.{self.distribution} needs "
                               f"{', '.join(shapes)}", s, value=None)
        return self

    @property
    def parameters(self) -> dict[str, object]:
        """scipy's parameters as written."""
        return dict(self.model_extra or {})

    def build(self, key: str, at: tuple) -> Distribution:
        """The :class:`Distribution` of `key` (parameters in its SI unit), filed at `at`.

        Raises
        ------
        _Problem
            With the full key path: units, plausibility, scipy's parameter rules.
        """
        name, relative = self.distribution, self.relative
        t_ref = None
        if key == RATE_AT_REFERENCE:
            raw = self.reference_temperature
            if raw is None:
                raise _Problem("missing: the temperature the rate refers to (e.g. '580 K')",
                               *at, "reference_temperature", value=None)
            t_ref = _quantity(key, raw, "K", (*at, "reference_temperature"))
            if not (math.isfinite(t_ref) and t_ref > 0):
                raise _Problem("must be > 0 K", *at, "reference_temperature", value=raw)
        elif "reference_temperature" in self.model_fields_set:
            raise _Problem(f"only for {RATE_AT_REFERENCE}", *at, "reference_temperature",
                           value=self.reference_temperature)
        unit = EXTRA_KEYS[key][0] if key in EXTRA_KEYS else SI_UNITS[key]
        params = _convert(key, name, self.parameters, unit, at, relative=relative)
        d = Distribution(key=key, name=name, params=tuple(params.items()), source=self.source,
                         relative=relative, reference_temperature=t_ref, kind=self.kind)
        _check_parameters(d, at, self.model_dump(exclude_unset=True))
        return d


def _check_parameters(d: Distribution, at: tuple, written: dict) -> None:
    lo, hi = d.frozen.support()
    if np.isnan(lo) or np.isnan(hi) or not np.isfinite(d.frozen.ppf(0.5)):
        raise _Problem(f"invalid parameters for scipy.stats.{d.name} ({d.describe()}): " +
                       _PARAMETER_RULES.get(d.name, "check scipy's documentation of the "
                                            "parameters"), *at, value=written)


def _parameter_role(dist: str, param: str, loc: float) -> str:
    """How a parameter converts: "level" (absolute value), "difference" (a spread) or "number".

    loc is a level; scale is a spread, except lognorm's scale with loc = 0 (the median, a
    level); loguniform's a and b are the bounds (levels) and its scale a pure factor; every
    other shape parameter is dimensionless (truncnorm's a and b are in units of scale).
    """
    if param == "loc":
        return "level"
    if dist in ("loguniform", "reciprocal"):
        return "level" if param in ("a", "b") else "number"
    if param == "scale":
        return "level" if dist == "lognorm" and loc == 0.0 else "difference"
    return "number"


def _convert(key: str, name: str, given: Mapping[str, object], unit: str, at: tuple,
             relative: bool = False, plausible: bool = True,
             unit_needed: str | None = None) -> dict[str, float]:
    """scipy's parameters in SI, in scipy's order: levels and spreads in `unit`, pure numbers
    as they are (every parameter of a `relative` distribution is a pure number); a bare number
    for a dimensional key refused where implausible (`plausible`), or where `unit_needed` says
    a unit must be written."""
    dist = getattr(scipy.stats, name)
    shapes = [s.strip() for s in (dist.shapes or "").split(",") if s.strip()]
    params: dict[str, float] = {}
    for pname in sorted(given, key=lambda p: p != "loc"):  # loc first: lognorm's scale
        raw = given[pname]
        role = _parameter_role(name, pname, params.get("loc", 0.0))
        here = (*at, pname)
        if relative or role == "number":
            if not _is_real(raw):
                why = ("a relative distribution is of a dimensionless factor" if relative
                       else f"`{pname}` of {name} is dimensionless")
                raise _Problem(f"expected a plain number ({why})", *here, value=raw)
            params[pname] = float(raw)
        else:
            if unit_needed is not None and not isinstance(raw, str):
                raise _Problem(unit_needed, *here, value=raw)
            if role == "difference":
                params[pname] = _difference(key, raw, unit, here)
            else:
                params[pname] = _quantity(key, raw, unit, here)
        if not math.isfinite(params[pname]):
            raise _Problem("must be finite", *here, value=raw)
        if plausible and not relative and role != "number" and key in SI_UNITS:
            _check_plausible(key, raw, params[pname], here, difference=role == "difference")
    return {p: params[p] for p in (*shapes, "loc", "scale") if p in params}


def _quantity(key: str, raw: object, unit: str, at: tuple) -> float:
    try:
        return to_si(key, raw, unit)
    except SceneError as exc:
        raise _Problem(exc.reason, *at, value=raw) from None


def _difference(key: str, raw: object, unit: str, at: tuple) -> float:
    """A spread: converted as a difference (5 degC of spread is 5 K, not 278.15 K)."""
    value = _quantity(key, raw, unit, at)
    match = _NUMBER_THEN_UNIT.match(raw) if isinstance(raw, str) else None
    if match and match["unit"]:
        try:
            value -= to_si(key, "0 " + match["unit"], unit)
        except SceneError:
            pass  # an expression, not "<number> <unit>": only offset units need this
    return value


def _check_plausible(key: str, raw: object, value: float, at: tuple,
                     difference: bool = False) -> None:
    """Refuse a bare number (no units: read as SI) that is implausible for `key`: a level
    outside the key's plausible range, a difference wider than that range
    (:func:`skidmc.scene.keys.implausible_reason`)."""
    if isinstance(raw, bool) or not isinstance(raw, (numbers.Real, str)):
        return
    if not read_si(key, raw, SI_UNITS[key])[1]:
        return  # written with units: only the bounds apply
    reason = implausible_reason(key, value, raw, difference=difference)
    if reason is not None:
        raise _Problem(reason, *at, value=raw)


def _flatten(table: object, *where: str) -> dict[str, object]:
    """A table of distributions keyed by input, the dotted keys read either quoted
    (``[uncertain."he.density"]``) or nested (``[uncertain.he.density]``)."""
    if not isinstance(table, dict):
        raise _Problem("expected a table")
    specs: dict[str, object] = {}

    def walk(node: dict, prefix: tuple[str, ...]) -> None:
        for name, value in node.items():
            path = (*prefix, name)
            if not isinstance(value, dict):
                raise _Problem("expected a table with a `distribution`", *path, value=value)
            if any(not isinstance(v, dict) for v in value.values()) or not value:
                specs[".".join(path)] = value
            else:
                walk(value, path)

    walk(table, ())
    return specs


def _input_key(key: str, spec: object) -> None:
    """Refuse a key no distribution can sample."""
    if key == "configuration":
        raise _Problem("configuration is a choice, not a number: run one scene per "
                       "configuration ([[scenes]])", key, value=spec)
    if key not in SI_UNITS and key not in EXTRA_KEYS:
        raise _Problem("not a scene key; " + suggest(key, [*SCENE_KEYS, *EXTRA_KEYS]), key,
                       value=spec)


def _uncertain_table(table: object) -> dict[str, object]:
    specs = _flatten(table)
    for key, spec in specs.items():
        _input_key(key, spec)
    return specs


#: ``[uncertain.KEY]`` tables: input key -> distribution.
Uncertain = Annotated[dict[str, DistributionSpec], BeforeValidator(_uncertain_table)]


def _build_all(specs: Mapping[str, DistributionSpec], at: tuple) -> dict[str, Distribution]:
    out = {key: spec.build(key, (*at, key)) for key, spec in specs.items()}
    if RATE_AT_REFERENCE in out and "kinetics.prefactor" in out:
        raise _Problem("kinetics.prefactor is sampled through the rate at the reference "
                       "temperature; give one of the two, not both", *at, RATE_AT_REFERENCE,
                       value=None)
    return out


# --- physical range at the tails ------------------------------------------------------------------


def _check_support(sc: StudyScene, d: Distribution, at: tuple) -> None:
    """Refuse a distribution whose tail quantiles leave the physical range (in scene `sc`); for
    a key uncertain at two levels, the products of both levels' tail quantiles."""
    both = d.key in sc.factors and d.key in sc.uncertain
    quantiles = ([f"{q:g}" for q in (U_TAIL, 1.0 - U_TAIL)] if not both else
                 [f"{q:g} and the factor's {p:g}" for q in (U_TAIL, 1.0 - U_TAIL)
                  for p in (U_TAIL, 1.0 - U_TAIL)])
    for x, q in zip(sc.tails(d.key), quantiles):
        x = float(x)
        reason = None
        if not math.isfinite(x):
            reason = "is not finite there"
        elif d.key in STUDY_RANGES:
            lo, hi = STUDY_RANGES[d.key]
            if not lo < x < hi:
                reason = f"a sampled {d.key} must lie in ({lo:g}, {hi:g})"
        if reason is None and d.key in SI_UNITS:
            try:
                sc.scene.replace({d.key: x}, check_plausible=False)  # SI, not written
            except SceneError as exc:
                reason = exc.reason
        elif reason is None and x <= 0.0:
            reason = "must be > 0"
        if reason is not None:
            unit = EXTRA_KEYS[d.key][0] if d.key in EXTRA_KEYS else SI_UNITS[d.key]
            level = ("" if not both else
                     f" times the aleatory factor {sc.factors[d.key].describe()}")
            raise _Problem(
                f"{d.describe()}{level} reaches {x:.6g} [{unit}] at its {q} quantile in scene "
                f"{sc.name!r}, outside the physical range ({reason}); use a distribution whose "
                "support stays inside it (truncnorm with suitable a/b, lognorm, beta, uniform, "
                "loguniform)", *at, value=dict(d.params))


def _check_rate_reference(sc: StudyScene, at: tuple) -> None:
    """Z = k_ref exp(E/R / T_ref) must stay a valid prefactor at the corners of the design."""
    d = sc.uncertain.get(RATE_AT_REFERENCE) or sc.factors.get(RATE_AT_REFERENCE)
    if d is None:
        return
    for rate in sc.tails(RATE_AT_REFERENCE):
        for t_act in sc.tails("kinetics.activation_temperature"):
            with np.errstate(over="ignore", invalid="ignore"):
                z = float(prefactor_from_rate(rate, t_act, d.reference_temperature))
            if not (math.isfinite(z) and z > 0):
                raise _Problem(
                    f"in scene {sc.name!r} the prefactor k_ref exp(E/R / T_ref) reaches {z:g} "
                    f"1/s (k_ref = {rate:g} 1/s, E/R = {t_act:g} K, T_ref = "
                    f"{d.reference_temperature:g} K); raise reference_temperature",
                    *at, value=dict(d.params))


# --- the common tables ----------------------------------------------------------------------------


def _solver_tiers() -> tuple[str, ...]:
    """Tiers the solver offers (``skidmc.solver.TIERS``; ("full",) if it lists none)."""
    from skidmc import solver

    return tuple(getattr(solver, "TIERS", ("full",)))


class SolverSpec(_Table):
    """``[solver]``: :func:`skidmc.solver.critical_height` arguments for every sample."""

    rtol: Annotated[float, _open_unit(), Field(gt=0, lt=1)] = Field(
        1e-3, description="relative tolerance on the critical height [1]")
    tier: Annotated[str, _word(_solver_tiers)] = "full"
    h_min: Quantity = Field(1e-3, description="lower search bound (a height; SI: m)")
    h_max: Quantity = Field(1e4, description="upper search bound (a height; SI: m)")
    backend: Annotated[Literal["cpu", "cuda"], _word(("cpu", "cuda"))] = Field(
        "cpu", description="where the full tier runs (skidmc.solver.cuda)")
    _options: SolverOptions = PrivateAttr()

    @model_validator(mode="after")
    def _bounds(self) -> SolverSpec:
        bounds = {}
        for name in ("h_min", "h_max"):
            raw = getattr(self, name)
            bounds[name] = _quantity("solver." + name, raw, "m", (name,))
            if not (math.isfinite(bounds[name]) and bounds[name] > 0):
                raise _Problem("must be a finite height > 0", name, value=raw)
        if not bounds["h_min"] < bounds["h_max"]:
            raise _Problem(f"must be below h_max ({bounds['h_max']:g} m)", "h_min",
                           value=self.h_min)
        if self.backend != "cpu" and self.tier != "full":
            raise _Problem(f"runs the full tier only; tier = {self.tier!r} runs on the CPU",
                           "backend", value=self.backend)
        self._options = SolverOptions(rtol=float(self.rtol), tier=self.tier,
                                      backend=self.backend, **bounds)
        return self

    @property
    def options(self) -> SolverOptions:
        """The validated :class:`SolverOptions` (heights in m)."""
        return self._options


class SceneTable(BaseModel):
    """``[scene]``: a preset plus overrides (any scene key, units allowed), the scene's own
    distributions, the experiment it is compared with."""

    model_config = ConfigDict(extra="allow")
    MISSING: ClassVar[dict[str, str]] = {}
    name: Annotated[str, _name("must be letters, digits, '.', '_' or '-'", empty=True)
                    ] | None = None
    preset: Annotated[str, _string("expected a preset name")] | None = None
    experiment: Annotated[str, _string(
        "expected the name of an experiment (skidmc.analysis.experiments)")] | None = None
    uncertain: Uncertain = {}
    _scene: Scene = PrivateAttr()

    @model_validator(mode="before")
    @classmethod
    def _table(cls, value: object) -> object:
        if not isinstance(value, dict):
            raise _Problem("expected a table")
        for name, reason in cls.MISSING.items():
            if name not in value:
                raise _Problem(reason, name, value=None)
        return value

    @model_validator(mode="after")
    def _make(self) -> SceneTable:
        try:
            self._scene = make_scene(self.model_extra or {}, preset=self.preset)
        except SceneError as exc:  # exc.key is "preset" for an unknown preset
            raise _Problem(exc.reason, exc.key, value=exc.value) from None
        return self

    @property
    def scene(self) -> Scene:
        """The nominal scene."""
        return self._scene


class NamedSceneTable(SceneTable):
    """One of several ``[[scenes]]``: named (the storage dimension ``scene``)."""

    MISSING = {"name": "missing"}
    name: Annotated[str, _name("must be letters, digits, '.', '_' or '-'")]


def _correlation_keys(value: object) -> object:
    if not (isinstance(value, list) and len(value) == 2 and all(isinstance(k, str)
                                                                for k in value)):
        raise _Problem("expected two uncertain keys")
    if value[0] == value[1]:
        raise _Problem("a key cannot be correlated with itself")
    return value


#: A correlation coefficient [1].
_Rho = Annotated[float, _rule(lambda v: _is_real(v) and -1 < v < 1,
                              "must be a number in (-1, 1)"), Field(gt=-1, lt=1)]


class CorrelationSpec(_Table):
    """``[[correlation]]``: a Gaussian copula between two uncertain inputs."""

    MISSING = {"source": "every correlation needs a `source`"}
    keys: Annotated[list[str], BeforeValidator(_correlation_keys)] = Field(
        min_length=2, max_length=2)
    spearman: _Rho | None = None
    gaussian: _Rho | None = None
    source: Annotated[str, _text("every correlation needs a `source`")] = Field(min_length=1)

    @model_validator(mode="after")
    def _one_measure(self) -> CorrelationSpec:
        if (self.spearman is None) == (self.gaussian is None):
            raise _Problem("give exactly one of `spearman` (rank correlation) or `gaussian` "
                           "(the copula's normal-score correlation)", value=None)
        return self

    def correlation(self) -> Correlation:
        rs = self.spearman
        rho = 2.0 * math.sin(math.pi * rs / 6.0) if rs is not None else self.gaussian
        return Correlation(keys=(self.keys[0], self.keys[1]), rho=float(rho),
                           spearman=None if rs is None else float(rs), source=self.source)


def _correlation_tables(value: object) -> object:
    if isinstance(value, dict):
        return [value]
    if not isinstance(value, list):
        raise _Problem("expected [[correlation]] tables")
    return value


class DesignTable(_Table):
    """``[design]``: how the samples are drawn (:mod:`skidmc.ensemble.sampling`)."""

    MISSING = {"method": "missing", "n": "missing: the number of samples",
               "seed": "missing: a study must be reproducible (any integer >= 0)"}
    method: Annotated[Literal["mc", "lhs", "sobol", "saltelli"], _word(DESIGN_METHODS)]
    n: Annotated[int, _integer(1), Field(ge=1)] = Field(
        description="samples (saltelli: base samples N)")
    seed: Annotated[int, _integer(0), Field(ge=0)]
    second_order: Annotated[bool, _boolean()] = Field(True, description="saltelli only")
    n_epistemic: Annotated[int, _integer(2, "expected an integer >= 2 (epistemic draws, each "
                                            "with n aleatory samples)"), Field(ge=2)] = 0
    n_max: Annotated[int, _integer(1), Field(ge=1)] | None = Field(
        None, description="saltelli only: grow N up to n_max until the indices are stable")
    stable_threshold: Annotated[float, _open_unit(), Field(gt=0, lt=1)] = 0.1
    stable_half_width: Annotated[float, _open_unit(), Field(gt=0, lt=1)] = 0.05
    #: Whether the design grows N (kind sobol: True; ensemble: False; either: None).
    GROWS: ClassVar[bool | None] = None
    _spec: study_model.DesignSpec = PrivateAttr()

    @model_validator(mode="after")
    def _combination(self) -> DesignTable:
        given, saltelli = self.model_fields_set, self.method == "saltelli"
        _n(self.method, self.n, "n")
        if "second_order" in given and not saltelli:
            raise _Problem("only for method = 'saltelli'", "second_order",
                           value=self.second_order)
        if "n_epistemic" in given and saltelli:
            raise _Problem("a nested design takes mc, lhs or sobol, not saltelli",
                           "n_epistemic", value=self.n_epistemic)
        if self.n_max is not None:
            if not saltelli:
                raise _Problem("only for method = 'saltelli' (grows N until the Sobol' indices "
                               "are stable)", "n_max", value=self.n_max)
            _n(self.method, self.n_max, "n_max")
            if self.n_max < self.n:
                raise _Problem(f"must be >= design.n ({self.n})", "n_max", value=self.n_max)
            if self.GROWS is False:
                raise _Problem("grows N until the Sobol' indices are stable: only for kind = "
                               "'sobol' (drop the kind line, or n_max)", "n_max",
                               value=self.n_max)
        for name in ("stable_threshold", "stable_half_width"):
            if name in given and self.n_max is None:
                raise _Problem("only with design.n_max", name, value=getattr(self, name))
        growth = {} if self.n_max is None else {
            "n_max": self.n_max, **{k: float(getattr(self, k)) for k in given
                                    if k.startswith("stable_")}}
        self._spec = study_model.DesignSpec(method=self.method, n=self.n, seed=self.seed,
                                second_order=self.second_order, n_epistemic=self.n_epistemic,
                                **growth)
        return self


def _n(method: str, n: int, name: str) -> None:
    try:
        check_n("", method, n, key=name)
    except StudyError as exc:
        raise _Problem(exc.reason, name, value=exc.value) from None


# --- ensemble and sobol files ---------------------------------------------------------------------


class StudyHead(_Table):
    """``[study]``."""

    MISSING = {"name": "missing"}
    name: Annotated[str, _STUDY_NAME] = Field(pattern=_NAME_PATTERN.pattern)
    description: Annotated[str, _string()] = ""
    kind: Annotated[str, _string()] | None = Field(
        None, description="the kind of study (skidmc.workflows.registry); inferred if absent")
    assumptions: Annotated[list[str], BeforeValidator(_sentences)] = Field(
        [], description="the study's judgements that no input's source states, one sentence "
        "each; the report prints them under Assumptions")


class StudyFile(_Table):
    """A study file of the ensemble engine (kinds ``ensemble`` and ``sobol``).

    Builds the :class:`~skidmc.ensemble.study_model.Study` (:meth:`build`); the rules between
    tables are :meth:`_meaning` (the module docstring says why they are validators)."""

    MISSING = {"study": "missing table [study] (with at least `name`)"}
    study: StudyHead
    uncertain: Uncertain = {}
    scene: SceneTable | None = None
    scenes: Annotated[list[NamedSceneTable], _rule(
        lambda v: isinstance(v, list) and bool(v), "expected one or more [[scenes]] tables")
    ] | None = None
    design: DesignTable
    correlation: Annotated[list[CorrelationSpec], BeforeValidator(_correlation_tables)] = []
    solver: SolverSpec = SolverSpec()
    _parts: dict = PrivateAttr()

    @classmethod
    def _then(cls, table: dict) -> None:
        if "scene" in table and "scenes" in table:
            raise _Problem("give either one [scene] or several [[scenes]], not both", "scenes",
                           value=None)
        if "scene" not in table and "scenes" not in table:
            raise _Problem("missing: give a [scene] table (a preset plus overrides) or several "
                           "[[scenes]]", "scene", value=None)
        if "design" not in table:
            raise _Problem("missing table [design] (method, n, seed)", "design", value=None)

    @model_validator(mode="after")
    def _meaning(self) -> StudyFile:
        common = _build_all(self.uncertain, ("uncertain",))
        if self.scene is not None:
            tables = [(self.scene, ("scene",))]
        else:
            tables = [(t, ("scenes", i)) for i, t in enumerate(self.scenes)]
        scenes: list[StudyScene] = []
        for table, at in tables:
            if table.name in [s.name for s in scenes]:
                raise _Problem("duplicate scene name", *at, "name", value=table.name)
            scenes.append(_study_scene(table, common, at))
        if self.scenes is not None:
            scenes = _two_level(scenes, common, [at for _, at in tables])
        keys: list[str] = []
        for sc in scenes:
            keys += [k for k in sc.uncertain if k not in keys]
        for sc in scenes:  # aleatory factors of keys uncertain at two levels: own columns
            keys += [aleatory_factor_column(k) for k in sc.factors
                     if aleatory_factor_column(k) not in keys]
        if not keys:
            raise _Problem("no uncertain inputs: give at least one [uncertain.KEY] table (use "
                           "`skidmc height` for a single scene)", "uncertain", value=None)
        design = self.design._spec
        correlations = _correlations(self.correlation, scenes)
        if correlations and design.method == "saltelli":
            raise _Problem("the saltelli design needs independent inputs (Sobol indices are "
                           "defined for them); sample kinetics.rate_at_reference instead of "
                           "correlating the kinetics pair, or use mc/lhs/sobol", "correlation",
                           value=[list(c.keys) for c in correlations])
        _check_kinds(scenes, keys, design, correlations)
        self._parts = dict(name=self.study.name, description=self.study.description,
                           scenes=tuple(scenes), scene_dimension=self.scenes is not None,
                           keys=tuple(keys), correlations=correlations, design=design,
                           solver=self.solver.options)
        return self

    def build(self, text: str, file: str) -> Study:
        """The validated :class:`Study` of this file, whose text is `text`."""
        return Study(**self._parts, text=text, file=file,
                     sha256=hashlib.sha256(text.encode("utf-8")).hexdigest())


def _study_scene(table: SceneTable, common: dict[str, Distribution], at: tuple) -> StudyScene:
    own = _build_all(table.uncertain, (*at, "uncertain"))
    uncertain, factors = _combine(common, own, at)
    if RATE_AT_REFERENCE in uncertain and "kinetics.prefactor" in uncertain:
        raise _Problem("kinetics.prefactor and kinetics.rate_at_reference are both uncertain "
                       "in this scene (one study-wide, one its own): keep one", *at,
                       "uncertain", value=None)
    sc = StudyScene(name=table.name or table.preset or "scene", scene=table.scene,
                    uncertain=uncertain, experiment=table.experiment, factors=factors)
    # The physical range of every uncertain input (the rate first: a bad T_ref also spoils
    # the rate's support).
    _check_rate_reference(sc, ("uncertain", RATE_AT_REFERENCE))
    for key in dict.fromkeys([*sc.uncertain, *sc.factors]):
        dist = sc.uncertain.get(key) or sc.factors[key]
        _check_support(sc, dist, (*at, "uncertain", key) if key in own else ("uncertain", key))
    return sc


def _combine(common: Mapping[str, Distribution], own: Mapping[str, Distribution],
             at: tuple) -> tuple[dict[str, Distribution], dict[str, Distribution]]:
    """A scene's distributions from the study-wide ones (`common`) and its own (`own`).

    A scene's entry replaces the study-wide entry of the same key and kind. A key with an
    entry of each kind is uncertain at two levels: the epistemic entry gives its level and the
    aleatory entry, which must be ``relative = true``, a factor on that level drawn for every
    sample.

    Returns
    -------
    uncertain, factors : dict
        Key -> distribution of the value (or its level), key -> aleatory factor.
    """
    uncertain = {**common, **own}
    factors: dict[str, Distribution] = {}
    for key in own.keys() & common.keys():
        if own[key].kind == common[key].kind:
            continue
        by_kind = {own[key].kind: (own[key], (*at, "uncertain", key)),
                   common[key].kind: (common[key], ("uncertain", key))}
        aleatory, where = by_kind["aleatory"]
        epistemic, where_epistemic = by_kind["epistemic"]
        if not aleatory.relative:
            raise _Problem(
                f"{key} is uncertain at two levels ({toml_key(*where_epistemic)} epistemic, "
                f"{toml_key(*where)} aleatory): the aleatory entry is a factor on the epistemic "
                "value and must say relative = true (the value sampled is the epistemic value "
                "times the factor); or give both entries the same kind, and the scene's own "
                "replaces the study-wide one", *where, "relative", value=False)
        uncertain[key], factors[key] = epistemic, aleatory
    return uncertain, factors


def _two_level(scenes: list[StudyScene], common: Mapping[str, Distribution],
               where: list[tuple]) -> list[StudyScene]:
    """Make a key uncertain at two levels in one scene so in every scene: where its only entry
    is the study-wide aleatory one, that entry is the factor (on the nominal value: the same
    values) in the factor's design column, so that the key's own column is epistemic."""
    keys = {k for sc in scenes for k in sc.factors}
    out = []
    for i, sc in enumerate(scenes):
        moved = {k: sc.uncertain[k] for k in keys
                 if k in sc.uncertain and k not in sc.factors
                 and sc.uncertain[k].kind == "aleatory"}
        for key, dist in moved.items():
            at = ("uncertain", key) if common.get(key) is dist else (*where[i], "uncertain", key)
            if not dist.relative:
                raise _Problem(
                    f"{key} is uncertain at two levels in another scene (an epistemic level "
                    f"times an aleatory factor); in scene {sc.name!r} its aleatory entry is "
                    "then that factor and must say relative = true", *at, "relative",
                    value=False)
        if moved:
            sc = dataclasses.replace(
                sc, uncertain={k: d for k, d in sc.uncertain.items() if k not in moved},
                factors={**sc.factors, **moved})
        out.append(sc)
    return out


def _correlations(tables: list[CorrelationSpec], scenes) -> tuple[Correlation, ...]:
    out: list[Correlation] = []
    for i, table in enumerate(tables):
        at = ("correlation", i, "keys")
        for k in table.keys:
            lacking = [sc.name for sc in scenes if k not in sc.uncertain]
            if lacking:
                raise _Problem(f"{k!r} is not uncertain in scene(s) {', '.join(lacking)}: only "
                               "uncertain inputs correlate", *at, value=table.keys)
        if any(set(c.keys) == set(table.keys) for c in out):
            raise _Problem("this pair is correlated twice", *at, value=table.keys)
        out.append(table.correlation())
    if out:
        names = sorted({k for c in out for k in c.keys})
        r = np.eye(len(names))
        for c in out:
            a, b = names.index(c.keys[0]), names.index(c.keys[1])
            r[a, b] = r[b, a] = c.rho
        if np.linalg.eigvalsh(r).min() <= 1e-10:
            raise _Problem("the correlations are inconsistent: their matrix is not positive "
                           "definite", "correlation", value=[[*c.keys, c.rho] for c in out])
    return tuple(out)


def _check_kinds(scenes, keys, design: study_model.DesignSpec, correlations) -> None:
    """Aleatory and epistemic inputs: one kind per key; both present <=> a nested design."""
    kinds: dict[str, str] = {}
    for sc in scenes:
        for key, dist in sc.uncertain.items():
            if kinds.setdefault(key, dist.kind) != dist.kind:
                raise _Problem(f"{key} is {kinds[key]} in another scene: one kind per input "
                               "across the study", "uncertain", key, "kind", value=dist.kind)
        for key in sc.factors:
            kinds[aleatory_factor_column(key)] = "aleatory"
    both = len(set(kinds.values())) == 2
    if both and not design.n_epistemic:
        epistemic = [k for k in keys if kinds[k] == "epistemic"]
        raise _Problem(f"missing: {', '.join(epistemic)} are epistemic and the other inputs "
                       "aleatory, so the design nests; give the number of epistemic draws "
                       "(each gets design.n aleatory samples)", "design", "n_epistemic",
                       value=None)
    if design.n_epistemic and not both:
        raise _Problem("only for a study with both aleatory and epistemic inputs (mark each "
                       "[uncertain.KEY] with kind = 'aleatory' or 'epistemic')", "design",
                       "n_epistemic", value=design.n_epistemic)
    for c in correlations:
        if kinds[c.keys[0]] != kinds[c.keys[1]]:
            raise _Problem("correlates an aleatory with an epistemic input: a nested design "
                           "draws them at different levels", "correlation",
                           value=list(c.keys))


class EnsembleHead(StudyHead):
    kind: Literal["ensemble"] | None = None


class SobolHead(StudyHead):
    kind: Literal["sobol"] | None = None


class SobolDesignTable(DesignTable):
    """``[design]`` of a growing Sobol' study: saltelli, with ``n_max``."""

    MISSING = {**DesignTable.MISSING, "n_max": "missing: kind = 'sobol' grows a saltelli "
               "design's N up to n_max (e.g. n_max = 4096)"}
    method: Annotated[Literal["saltelli"], _word(("saltelli",))]
    n_max: Annotated[int, _integer(1), Field(ge=1)]
    GROWS = True


class EnsembleDesignTable(DesignTable):
    """``[design]`` of a plain ensemble: N as given (``n_max`` is the sobol kind's)."""

    GROWS = False


class EnsembleFile(StudyFile):
    """Kind ``ensemble``: a design of samples over one or several scenes."""

    study: EnsembleHead
    design: EnsembleDesignTable


class SobolFile(StudyFile):
    """Kind ``sobol``: a saltelli design grown until its Sobol' indices are stable."""

    study: SobolHead
    design: SobolDesignTable


# --- hazard files ---------------------------------------------------------------------------------


#: Keys the hazard tables own: the friction is the surface's, the angle has its own table, the
#: tilt follows the configuration, the target's properties come from the material.
_OWNED_KEYS = {"mu": "[[hazard.surface]] friction", "angle": "[hazard.angle]",
               "tilt": "the configuration (vertical: tilt = angle; pendulum: 0)",
               **{k: "the surface's material" for k in TARGET_KEYS}}
# The mixture's weights are typed by hand: 1e-6 accepts any rounding of a decimal sum and
# refuses 1/3 written as 0.333 three times (0.999, off by 1e-3).
_WEIGHT_TOLERANCE = 1e-6
_NOT_BILLET = (f"not a billet input (one of {', '.join(BILLET_KEYS)}); kinetics and other "
               "unknowns go in [hazard.epistemic]")


class HazardSceneTable(BaseModel):
    """``[hazard.scene]``: the billet and everything not sampled, a preset plus overrides."""

    model_config = ConfigDict(extra="allow")
    preset: Annotated[str, _string("expected a preset name")] | None = None
    _scene: Scene = PrivateAttr()

    @model_validator(mode="before")
    @classmethod
    def _owned(cls, value: object) -> object:
        if not isinstance(value, dict):
            raise _Problem("expected a table")
        for key, item in value.items():
            if key in _OWNED_KEYS or key == "target":
                owner = _OWNED_KEYS.get(key, "the surfaces' materials")
                raise _Problem(f"set by {owner} in a hazard study", key, value=item)
        return value

    @model_validator(mode="after")
    def _make(self) -> HazardSceneTable:
        try:
            self._scene = make_scene(self.model_extra or {}, preset=self.preset)
        except SceneError as exc:
            raise _Problem(exc.reason, exc.key, value=exc.value) from None
        return self


def _keyed(part: str) -> BeforeValidator:
    """``[hazard.billet.KEY]`` / ``[hazard.epistemic.KEY]`` tables: inputs the hazard tables do
    not own; the billet's among :data:`BILLET_KEYS`."""

    def validate(table: object) -> object:
        specs = _flatten(table)
        for key in specs:
            if key in _OWNED_KEYS:
                raise _Problem(f"{key} is set by {_OWNED_KEYS[key]} in a hazard study", key,
                               value=None)
            if part == "billet" and key not in BILLET_KEYS and key in NUMERIC_KEYS:
                raise _Problem(_NOT_BILLET, key, value=None)
        for key, spec in specs.items():
            _input_key(key, spec)
        return specs

    return BeforeValidator(validate)


def _material(value: object) -> object:
    try:
        get_material(value)
    except SceneError as exc:
        raise _Problem(exc.reason) from None
    return value


_WEIGHT = "expected a share of accidents in (0, 1]"
_SURFACE_SOURCE = ("every surface needs a `source` for its weight (statistics, or 'judgement: "
                   "why')")


class SurfaceSpec(_Table):
    """``[[hazard.surface]]``: a material of the registry, the share of accidents on it, its
    friction."""

    MISSING = {"material": "missing: a material name (skidmc materials lists them)",
               "weight": _WEIGHT, "source": _SURFACE_SOURCE,
               "friction": "missing: the apparent friction coefficient's distribution on this "
                           "surface"}
    material: Annotated[str, BeforeValidator(_material)] = Field(
        description="a name of skidmc.scene.materials")
    weight: Annotated[float, _rule(lambda v: _is_real(v) and 0 < v <= 1, _WEIGHT)] = Field(
        gt=0, le=1)
    source: Annotated[str, _text(_SURFACE_SOURCE)] = Field(min_length=1)
    friction: DistributionSpec
    #: Why this surface lies outside the model (required for an elastic material, e.g. rubber):
    #: its weight is reported as an unmodelled share, not counted as "no reaction".
    outside_model: Annotated[str, _text("expected why this surface lies outside the model, in "
                                        "words"), Field(min_length=1)] | None = None

    @model_validator(mode="after")
    def _elastic(self) -> SurfaceSpec:
        entry = get_material(self.material)
        if entry.elastic and self.outside_model is None:
            raise _Problem("an elastic material: the report's plastic-contact model cannot "
                           f"describe it ({entry.hardness_source}); keep it with "
                           "`outside_model = \"why\"` (its weight is then reported as an "
                           "unmodelled share, not as no reaction) or remove it", "material",
                           value=self.material)
        return self


def _angle_scales(value: object) -> object:
    if not isinstance(value, list):
        raise _Problem("expected a list of angles with units, e.g. ['5 deg', '15 deg']")
    return value


class AlternativesSpec(_Table):
    """What the summary shows besides the headline: another geometry, other angle scales."""

    configuration: Annotated[Literal["pendulum", "vertical"], _word(
        ("pendulum", "vertical"), "expected 'pendulum' or 'vertical'")] | None = None
    angle_scales: Annotated[list[Quantity], BeforeValidator(_angle_scales)] = []


class EstimatorSpec(_Table):
    """``[hazard.estimator]`` (:func:`skidmc.analysis.hazard.drop_height_probability`)."""

    MISSING = {"seed": "missing: a study must be reproducible (any integer >= 0)"}
    method: Annotated[Literal["is", "mc"], _word(ESTIMATOR_METHODS)] = "is"
    target_cov: Annotated[float, _open_unit("expected a coefficient of variation in (0, 1)"),
                          Field(gt=0, lt=1)] = 0.1
    max_runs: Annotated[int, _integer(10), Field(ge=10)] = 20_000
    seed: Annotated[int, _integer(0), Field(ge=0)]
    epistemic_draws: Annotated[int, _integer(0), Field(ge=0)] = 20
    epistemic_target_cov: Annotated[float, _open_unit(
        "expected a coefficient of variation in (0, 1)"), Field(gt=0, lt=1)] = 0.2

    def options(self) -> EstimatorOptions:
        return EstimatorOptions(**{k: getattr(self, k) for k in (
            "method", "target_cov", "max_runs", "seed", "epistemic_draws",
            "epistemic_target_cov")})


_POSTERIOR_FILE = ("expected a calibration study file (its posterior is results/<name>/"
                   "posterior.nc) or an ArviZ posterior file (.nc), relative to this file")


class PosteriorSpec(_Table):
    """``[hazard.posterior]``: the epistemic draws taken from a calibration's posterior.

    The epistemic loop's draws of the ``[hazard.epistemic]`` inputs are then equally spaced
    thinned draws of the stored posterior (joint, so their correlation is kept) instead of
    Latin-hypercube draws of the priors; the pooled estimate stays over the priors."""

    MISSING = {"calibration": "missing: " + _POSTERIOR_FILE}
    calibration: Annotated[str, _string(_POSTERIOR_FILE)] = Field(min_length=1)
    #: The same study over the priors: its summary.json gives the prior's epistemic band.
    prior_study: Annotated[str, _string("expected the hazard study file over the priors "
                                        "(relative to this file)")] | None = None


class HazardTable(_Table):
    """``[hazard]``: the population of handling accidents."""

    MISSING = {
        "name": "missing",
        "scene": "missing table [hazard.scene] (a preset for the HE and kinetics, plus "
                 "overrides)",
        "drop_height": "missing table [hazard.drop_height] (a distribution of a length with "
                       "its source)",
        "angle": "missing table [hazard.angle] (a distribution with its source)",
        "surface": "missing: give one or more [[hazard.surface]] tables (material, weight, "
                   "source, friction)",
        "estimator": "missing table [hazard.estimator] (at least the seed)",
    }
    name: Annotated[str, _STUDY_NAME] = Field(pattern=_NAME_PATTERN.pattern)
    description: Annotated[str, _string()] = ""
    scene: HazardSceneTable
    drop_height: DistributionSpec
    angle: DistributionSpec
    billet: Annotated[dict[str, DistributionSpec], _keyed("billet")] = {}
    epistemic: Annotated[dict[str, DistributionSpec], _keyed("epistemic")] = {}
    surface: Annotated[list[SurfaceSpec], _rule(
        lambda v: isinstance(v, list) and bool(v), "expected [[hazard.surface]] tables")
    ] = Field(min_length=1)
    estimator: EstimatorSpec
    solver: SolverSpec = SolverSpec()
    assumptions: Annotated[list[str], BeforeValidator(_sentences)] = []
    alternatives: AlternativesSpec = AlternativesSpec()
    posterior: PosteriorSpec | None = None


class HazardFile(_Table):
    """Kind ``hazard``: the probability per handling accident (everything under [hazard]).

    Builds the :class:`~skidmc.ensemble.study_model.HazardStudy` (:meth:`build`)."""

    hazard: HazardTable
    _parts: dict = PrivateAttr()

    @classmethod
    def _first(cls, table: dict) -> None:
        if "hazard" not in table:
            raise _Problem("missing table [hazard]: a hazard study keeps everything under it "
                           "(see skidmc.ensemble.hazard_study)", "hazard", value=None)
        others = [k for k in table if k != "hazard"]
        if others:
            raise _Problem("unknown top-level key in a hazard study: everything goes under "
                           "[hazard]", others[0], value=table[others[0]])

    @model_validator(mode="after")
    def _meaning(self) -> HazardFile:
        h = self.hazard
        scene = h.scene._scene
        drop = _drop_height(h.drop_height)
        angle = _hazard_distribution("angle", h.angle, ("hazard", "angle"))
        billet, epistemic = ({key: dataclasses.replace(
            _hazard_distribution(key, spec, ("hazard", part, key)), kind=kind)
            for key, spec in getattr(h, part).items()}
            for part, kind in (("billet", "aleatory"), ("epistemic", "epistemic")))
        for part, group in (("billet", billet), ("epistemic", epistemic)):
            if RATE_AT_REFERENCE in group and "kinetics.prefactor" in group:
                raise _Problem("kinetics.prefactor is sampled through the rate at the "
                               "reference temperature; give one of the two, not both",
                               "hazard", part, RATE_AT_REFERENCE, value=None)
            if part == "billet" and (set(group) - set(BILLET_KEYS)):
                raise _Problem(_NOT_BILLET, "hazard", part,
                               sorted(set(group) - set(BILLET_KEYS))[0], value=None)
        both = sorted(set(billet) & set(epistemic))
        if both:
            raise _Problem(f"{both[0]} is also in [hazard.billet]: an input is either aleatory "
                           "(billet) or epistemic, not both", "hazard", "epistemic", both[0],
                           value=None)
        surfaces = _surfaces(h.surface, scene, angle, billet, epistemic)
        if not any(s.modelled for s in surfaces):
            raise _Problem("every surface is outside the model: there is nothing to estimate",
                           "hazard", "surface", value=[s.material for s in surfaces])
        alternatives = h.alternatives
        if alternatives.configuration == scene.configuration:
            raise _Problem(f"the study's scene is {scene.configuration} already: name the "
                           "other geometry", "hazard", "alternatives", "configuration",
                           value=alternatives.configuration)
        angles = []
        for i, scale in enumerate(alternatives.angle_scales):
            spec = DistributionSpec.model_validate({
                **h.angle.model_dump(exclude_unset=True), **h.angle.parameters,
                "scale": scale})
            angles.append(_hazard_distribution(
                "angle", spec, ("hazard", "alternatives", "angle_scales", i)))
        self._parts = dict(
            name=h.name, description=h.description, scene=scene, drop_height=drop,
            angle=angle, surfaces=surfaces, billet=billet, epistemic=epistemic,
            estimator=h.estimator.options(), solver=h.solver.options,
            assumptions=tuple(v.strip() for v in h.assumptions),
            alternative_configuration=alternatives.configuration,
            angle_alternatives=tuple(angles))
        if h.posterior is not None:
            if not epistemic:
                raise _Problem("there is no [hazard.epistemic] input to take from a posterior",
                               "hazard", "posterior", "calibration",
                               value=h.posterior.calibration)
            if not h.estimator.epistemic_draws:
                raise _Problem("a posterior's draws need epistemic_draws >= 1", "hazard",
                               "estimator", "epistemic_draws",
                               value=h.estimator.epistemic_draws)
            self._parts.update(posterior=h.posterior.calibration,
                               prior_study=h.posterior.prior_study)
        return self

    def build(self, text: str, file: str) -> HazardStudy:
        """The validated :class:`HazardStudy` of this file, whose text is `text`."""
        return HazardStudy(**self._parts, text=text, file=file,
                           sha256=hashlib.sha256(text.encode("utf-8")).hexdigest())


def _hazard_distribution(key: str, spec: DistributionSpec, at: tuple) -> Distribution:
    if "kind" in spec.model_fields_set:
        raise _Problem("not used in a hazard study: the table says the kind ([hazard.billet] "
                       "aleatory, [hazard.epistemic] epistemic)", *at, "kind", value=spec.kind)
    return spec.build(key, at)


def _drop_height(spec: DistributionSpec) -> Distribution:
    """The drop height: a distribution of a length (units required), not a scene key."""
    at = ("hazard", "drop_height")
    for name in ("relative", "kind", "reference_temperature"):
        if name in spec.model_fields_set:
            raise _Problem("not used for the drop height (a distribution of a length)", *at,
                           name, value=getattr(spec, name))
    params = _convert("drop_height", spec.distribution, spec.parameters, "m", at,
                      plausible=False,
                      unit_needed="a height needs its unit, e.g. '1 m' or '3 ft'")
    d = Distribution(key="drop_height", name=spec.distribution, params=tuple(params.items()),
                     source=spec.source)
    written = spec.model_dump(exclude_unset=True)
    _check_parameters(d, at, written)
    lo = d.frozen.support()[0]
    if lo < 0:
        raise _Problem(f"{d.describe()} reaches below 0 m (its support starts at {lo:g} m): a "
                       "drop height is >= 0; use lognorm, loguniform, or truncate", *at,
                       value=written)
    return d


def _surfaces(tables: list[SurfaceSpec], scene: Scene, angle: Distribution, billet: dict,
              epistemic: dict) -> tuple[Surface, ...]:
    out: list[Surface] = []
    for i, table in enumerate(tables):
        at = ("hazard", "surface", i)
        if table.material in [s.material for s in out]:
            raise _Problem("this material is listed twice: give it one surface with the summed "
                           "weight", *at, "material", value=table.material)
        friction = _hazard_distribution("mu", table.friction, (*at, "friction"))
        surface_scene = scene.replace(target=table.material)
        sc = StudyScene(name=table.material, scene=surface_scene,
                        uncertain={"mu": friction, "angle": angle, **billet, **epistemic})
        _check_rate_reference(sc, ("hazard", "epistemic", RATE_AT_REFERENCE))
        _check_support(sc, friction, (*at, "friction"))
        _check_support(sc, angle, ("hazard", "angle"))
        for part, group in (("billet", billet), ("epistemic", epistemic)):
            for key, d in group.items():
                _check_support(sc, d, ("hazard", part, key))
        regime, note = _regime(table, surface_scene, billet)
        out.append(Surface(material=table.material, weight=float(table.weight),
                           source=table.source, friction=friction, scene=surface_scene,
                           regime=regime, regime_note=note))
    total = math.fsum(s.weight for s in out)
    if abs(total - 1.0) > _WEIGHT_TOLERANCE:
        raise _Problem(f"the weights sum to {total:.6g}, not 1: they are the shares of "
                       "accidents on each surface", "hazard", "surface",
                       value={s.material: s.weight for s in out})
    return tuple(out)


def _regime(table: SurfaceSpec, scene: Scene, billet: Mapping[str, Distribution]
            ) -> tuple[str, str]:
    """(regime, note) of a surface: outside, yielding or rigid, from its hardness against the
    billet's flow stress (its distribution's 1e-9..1-1e-9 range where it is sampled)."""
    entry = get_material(table.material)
    if table.outside_model is not None:
        return "outside", f"outside the model: {table.outside_model.strip()}"
    hardness = float(scene.target_hardness)
    if "flow_stress" in billet:
        frozen = billet["flow_stress"].physical(scene.flow_stress)
        low, high = float(frozen.ppf(1e-9)), float(frozen.isf(1e-9))
    else:
        low = high = float(scene.flow_stress)
    if not math.isfinite(hardness) or hardness >= high:
        return "rigid", ("rigid: hardness above every sampled flow stress of the billet "
                         f"({entry.hardness_source})")
    pressure = f"{hardness / 1e6:.3g} MPa ({from_si(hardness, 'Pa', 'psi'):.4g} psi)"
    part = ("for every sampled billet" if hardness <= low else
            f"for billets whose flow stress exceeds it (sampled range "
            f"{low / 1e6:.3g}-{high / 1e6:.3g} MPa)")
    return "yielding", (f"yielding: contact pressure p_t = {pressure} {part}, below the "
                        f"billet's flow stress (source: {entry.hardness_source})")


# --- the registry of file formats -----------------------------------------------------------------


#: Kind -> the model of its file (:func:`register` adds one).
SCHEMAS: dict[str, type[BaseModel]] = {}


def register(kind: str) -> Callable[[type[BaseModel]], type[BaseModel]]:
    """Class decorator: `kind`'s files are validated and loaded by the model decorated."""

    def add(model: type[BaseModel]) -> type[BaseModel]:
        SCHEMAS[kind] = model
        return model

    return add


#: Names of these models before they loaded the files (kept for code written against them).
_Strict = _Table
_StudyFile = StudyFile
DesignSpec = DesignTable
SobolDesignSpec = SobolDesignTable

register("ensemble")(EnsembleFile)
register("sobol")(SobolFile)
register("hazard")(HazardFile)


def json_schema(kind: str) -> str:
    """The JSON Schema of a kind's study file, as written to ``docs/schemas/<kind>.json``."""
    schema = SCHEMAS[kind].model_json_schema()
    schema["title"] = f"skidmc {kind} study file"
    schema["$schema"] = "https://json-schema.org/draft/2020-12/schema"
    return json.dumps(schema, indent=1, sort_keys=True) + "\n"


# --- kind "calibration" (issue 40; appended by the calibration work) -------------------------


class CalibrationHead(StudyHead):
    kind: Literal["calibration"]


class FrictionPopulationSpec(_Strict):
    """The population the finishes' mean friction coefficients are drawn from."""

    median: float = Field(gt=0, lt=1, description="prior median of the population's median mu")
    median_log_sd: float = Field(gt=0, description="prior log-sd of that median")
    sd: float = Field(gt=0, description="prior median of the population's log-sd tau")
    sd_log_sd: float = Field(gt=0, description="prior log-sd of tau")
    other_finishes_from: str | None = Field(
        None, description="a study file whose scenes' epistemic mu are other finishes measured")
    exclude: list[str] = Field([], description="scenes of that study not counted (why: source)")
    source: str = Field(min_length=1)


class SurrogateSpec(_Strict):
    runs: int = Field(ge=20, description="solver runs per scene to train the surrogate")
    seed: int = Field(ge=0)
    check_draws: int = Field(0, ge=0, description="posterior draws checked against the solver")


class SamplerSpec(_Strict):
    walkers: int = Field(ge=4)
    burn: int = Field(ge=0)
    steps: int = Field(ge=1)
    thin: int = Field(1, ge=1)
    seed: int = Field(ge=0)
    cv_steps: int = Field(0, ge=0, description="steps of each leave-one-target-out run (0: none)")


class CalibrationTable(_Strict):
    prior: str = Field(description="the study file whose epistemic inputs are the priors")
    predict: str | None = Field(None, description="a study file whose scenes are predicted")
    quadrature: dict[str, int] = Field(description="aleatory key -> quadrature nodes")
    discrepancy_sd: float = Field(gt=0, description="prior sd of each target's ln H_c error")
    discrepancy_source: str = Field(min_length=1)
    misclassification: float = Field(0.0, ge=0, lt=0.5)
    misclassification_source: str = ""
    friction_population: FrictionPopulationSpec | None = None
    surrogate: SurrogateSpec
    sampler: SamplerSpec


class CalibrationFile(_Strict):
    """Kind ``calibration``: the epistemic inputs of a study calibrated on the report's drops."""

    study: CalibrationHead
    calibration: CalibrationTable


register("calibration")(CalibrationFile)
__all__.append("CalibrationFile")
