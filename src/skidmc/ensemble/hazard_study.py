"""Hazard study files: an accident population, declared once in TOML and validated on load.

A hazard study asks how likely one handling accident is to end in a reaction. It describes the
population of accidents rather than one experiment: how high the billet falls, at what angle it
strikes, which surface it strikes (a mixture of materials from the registry, each with its own
friction), the billet population, and what is not known about the kinetics. It is run by
:func:`skidmc.workflows.hazard.run_hazard_study`. The format (all under one ``[hazard]``
table, so that a file is recognised by it; :func:`is_hazard_study`)::

    [hazard]
    name = "hazard-handling"            # results go to results/<name>/
    description = "..."
    assumptions = ["...", "..."]        # every judgement in words: the summary prints them

    [hazard.scene]                      # the billet and everything not sampled: a preset ...
    preset = "paper-quartz"             # ... (its HE and kinetics) plus overrides with units
    configuration = "vertical"
    billet_mass = "19.1 lb"

    [hazard.drop_height]                # the drop height [length]: any scipy.stats continuous
    distribution = "lognorm"            # distribution, parameters as in study files
    s = 0.5
    scale = "1 m"                       # lognorm's median (loc = 0)
    source = "judgement: ..."           # mandatory, on every distribution

    [hazard.angle]                      # impact angle phi [angle], in (0, 90) deg
    distribution = "halfnorm"
    scale = "10 deg"
    source = "..."

    [[hazard.surface]]                  # the surface struck: one table per material
    material = "concrete"               # a name of skidmc.scene.materials (skidmc materials)
    weight = 0.55                       # share of accidents on it; weights sum to 1
    source = "..."                      # where the weight comes from
    [hazard.surface.friction]           # its apparent friction coefficient mu, in (0, 1)
    distribution = "lognorm"
    s = 0.2
    scale = 0.24
    source = "..."

    [[hazard.surface]]                  # a surface the model does not describe (required for
    material = "rubber"                 # an elastic material): listed with its weight, never
    weight = 0.13                       # run; its weight is reported as an unmodelled share
    source = "..."                      # beside P (bound [P, P + w]), not as "no reaction"
    outside_model = "elastic: ..."
    [hazard.surface.friction]
    ...

    [hazard.billet.flow_stress]         # billet population (aleatory, drop to drop): flow
    distribution = "lognorm"            # stress, mass, diameter, initial temperature, he.*
    s = 0.15
    scale = "28000 psi"
    source = "..."

    [hazard.epistemic."kinetics.activation_temperature"]   # fixed but unknown: any scene key
    distribution = "uniform"                               # (not mu, angle, tilt, target.*) or
    loc = "15000 K"                                        # kinetics.rate_at_reference
    scale = "19000 K"
    source = "..."

    [hazard.alternatives]               # optional, shown beside the headline:
    configuration = "pendulum"          # P under the other geometry (pooled estimate)
    angle_scales = ["5 deg", "15 deg"]  # P with the angle's scale replaced: the same samples
                                        # reweighted, rerun where they do not cover it

    [hazard.estimator]
    method = "is"                       # "is" (importance sampling) or "mc" (conditional MC)
    target_cov = 0.1                    # stop each estimate at this coefficient of variation
    max_runs = 20000                    # ... or after this many solver runs, per estimate
    seed = 20240601
    epistemic_draws = 20                # outer draws of the epistemic inputs (the band of P)
    epistemic_target_cov = 0.2          # target CoV of each draw's estimate

    [hazard.solver]                     # skidmc.solver.critical_height arguments
    rtol = 1e-2
    tier = "full"

Distributions follow the rules of :mod:`skidmc.ensemble.study`: scipy's parameter names, values
with units where the key has units (a bare number is read in SI and refused where implausible),
``relative = true`` for a factor on the scene's value, a ``source`` on every one, and the
1e-9 and 1 - 1e-9 quantiles must be valid scene values for every surface. Each surface's
regime (:data:`REGIMES`) follows from its material: ``outside`` where the file says
``outside_model`` (an elastic material must), ``yielding`` where its hardness
(``target.hardness``) lies below the billet's sampled flow stress, else ``rigid``. Every error is a
:class:`~skidmc.ensemble.study_model.StudyError` naming the file, the key path and the value as
written.
"""

from __future__ import annotations

import dataclasses
import hashlib
import math
import numbers
from collections.abc import Mapping
from pathlib import Path

import numpy as np
import scipy.stats

from skidmc.ensemble.study import (
    _NAME_PATTERN,
    _PARAMETER_RULES,
    _parameter_role,
    _Parser,
    _suggest,
    _toml_key,
    parse_toml,
    read_study_text,
)
from skidmc.ensemble.study_model import (
    RATE_AT_REFERENCE,
    Distribution,
    SolverOptions,
    StudyError,
    StudyScene,
)
from skidmc.errors import SceneError
from skidmc.scene import NUMERIC_KEYS, Scene, make_scene
from skidmc.scene.materials import TARGET_KEYS, get_material
from skidmc.scene.units import to_si

try:
    import tomllib
except ModuleNotFoundError:  # Python 3.10: the same parser, packaged as tomli
    import tomli as tomllib

__all__ = [
    "BILLET_KEYS",
    "ESTIMATOR_METHODS",
    "EstimatorOptions",
    "HazardStudy",
    "REGIMES",
    "Surface",
    "is_hazard_study",
    "load_hazard_study",
    "parse_hazard_study",
]

#: Keys a ``[hazard.billet.KEY]`` table may sample (aleatory: lot to lot, billet to billet).
BILLET_KEYS: tuple[str, ...] = (
    "flow_stress", "billet_mass", "billet_diameter", "initial_temperature",
    *(k for k in NUMERIC_KEYS if k.startswith("he.")),
)

#: Estimators of :func:`skidmc.analysis.hazard.drop_height_probability`.
ESTIMATOR_METHODS: tuple[str, ...] = ("is", "mc")

#: Keys the hazard tables own: the friction is the surface's, the angle has its own table, the
#: tilt follows the configuration, the target's properties come from the material.
_OWNED_KEYS = {"mu": "[[hazard.surface]] friction", "angle": "[hazard.angle]",
               "tilt": "the configuration (vertical: tilt = angle; pendulum: 0)",
               **{k: "the surface's material" for k in TARGET_KEYS}}

_HAZARD_KEYS = ("name", "description", "scene", "drop_height", "angle", "surface", "billet",
                "epistemic", "estimator", "solver", "assumptions", "alternatives")
_SURFACE_KEYS = ("material", "weight", "source", "friction", "outside_model")
_ALTERNATIVE_KEYS = ("configuration", "angle_scales")

#: Regimes of a surface: the report's rigid target, a target that yields under the billet
#: (contact pressure min(sigma, p_t), docs/model.md "Targets softer than the billet"), or one
#: the model does not describe (its weight is an unmodelled share of the accidents).
REGIMES: tuple[str, ...] = ("rigid", "yielding", "outside")
_ESTIMATOR_KEYS = ("method", "target_cov", "max_runs", "seed", "epistemic_draws",
                   "epistemic_target_cov")
_DROP_META = ("distribution", "source")
# The mixture's weights are typed by hand: 1e-6 accepts any rounding of a decimal sum and
# refuses 1/3 written as 0.333 three times (0.999, off by 1e-3).
_WEIGHT_TOLERANCE = 1e-6


@dataclasses.dataclass(frozen=True)
class Surface:
    """One surface an accident may strike.

    Attributes
    ----------
    material : str
        Registry name (:mod:`skidmc.scene.materials`).
    weight : float
        Share of accidents on this surface [1].
    source : str
        Where the weight comes from.
    friction : Distribution
        Apparent friction coefficient mu on this surface [1].
    scene : Scene
        The study's scene with this material as the target.
    regime : {"rigid", "yielding", "outside"}
        How the model treats the surface (:data:`REGIMES`): rigid (hardness above the billet's
        flow stress), yielding (below it: contact pressure p_t) or outside the model (not run;
        its weight is reported as an unmodelled share).
    regime_note : str
        The regime in words, with the hardness and its source (or why it is outside).
    """

    material: str
    weight: float
    source: str
    friction: Distribution
    scene: Scene
    regime: str = "rigid"
    regime_note: str = ""

    @property
    def modelled(self) -> bool:
        """Whether the model describes this surface (rigid or yielding)."""
        return self.regime != "outside"


@dataclasses.dataclass(frozen=True)
class EstimatorOptions:
    """How the probability is estimated (:func:`skidmc.analysis.hazard.drop_height_probability`).

    Attributes
    ----------
    method : {"is", "mc"}
        Structured estimator with importance sampling, or conditional Monte Carlo.
    target_cov : float
        Target coefficient of variation of each pooled per-surface estimate [1].
    max_runs : int
        Budget of solver runs of one estimate (one surface, one epistemic draw or pooled).
    seed : int
        Root seed (>= 0) of every estimate's random stream.
    epistemic_draws : int
        Outer draws of the epistemic inputs (Latin hypercube); 0 for no epistemic loop.
    epistemic_target_cov : float
        Target coefficient of variation of each draw's per-surface estimates [1].
    """

    method: str = "is"
    target_cov: float = 0.1
    max_runs: int = 20_000
    seed: int = 0
    epistemic_draws: int = 20
    epistemic_target_cov: float = 0.2


@dataclasses.dataclass(frozen=True)
class HazardStudy:
    """A validated hazard study (build with :func:`load_hazard_study`).

    Attributes
    ----------
    name, description : str
    scene : Scene
        The billet, HE, kinetics and configuration (the target is each surface's).
    drop_height : Distribution
        Drop height [m] (key ``"drop_height"``).
    angle : Distribution
        Impact angle phi [deg].
    surfaces : tuple of Surface
    billet : dict
        Key -> :class:`Distribution`, aleatory inputs of the billet population.
    epistemic : dict
        Key -> :class:`Distribution`, fixed but unknown inputs.
    estimator : EstimatorOptions
    solver : SolverOptions
    text, sha256, file : str
        The file's text, its SHA-256 and where it was read from.
    assumptions : tuple of str
        The study's judgements in words (``assumptions = [...]``), printed in the summary.
    alternative_configuration : str or None
        A second geometry (``[hazard.alternatives] configuration``) under which P is also
        estimated (pooled, no epistemic loop).
    angle_alternatives : tuple of Distribution
        The angle distribution at other scales (``[hazard.alternatives] angle_scales``): P at
        each from the same samples, reweighted.
    """

    name: str
    description: str
    scene: Scene
    drop_height: Distribution
    angle: Distribution
    surfaces: tuple[Surface, ...]
    billet: Mapping[str, Distribution]
    epistemic: Mapping[str, Distribution]
    estimator: EstimatorOptions
    solver: SolverOptions
    text: str
    sha256: str
    file: str
    assumptions: tuple[str, ...] = ()
    alternative_configuration: str | None = None
    angle_alternatives: tuple[Distribution, ...] = ()

    @property
    def modelled_surfaces(self) -> tuple[Surface, ...]:
        """The surfaces the model describes (rigid or yielding), in file order."""
        return tuple(s for s in self.surfaces if s.modelled)

    @property
    def unmodelled_weight(self) -> float:
        """Share of accidents on surfaces outside the model [1]."""
        return math.fsum(s.weight for s in self.surfaces if not s.modelled)

    @property
    def aleatory_keys(self) -> tuple[str, ...]:
        """Sampled scene inputs that vary from accident to accident: mu, angle, the billet's."""
        return ("mu", "angle", *self.billet)

    @property
    def epistemic_keys(self) -> tuple[str, ...]:
        """The epistemic inputs, in file order."""
        return tuple(self.epistemic)

    @property
    def materials(self) -> tuple[str, ...]:
        """The surfaces' material names, in file order."""
        return tuple(s.material for s in self.surfaces)


def is_hazard_study(path_or_text: str | Path) -> bool:
    """Whether a TOML file (a path) or text has a top-level ``[hazard]`` table.

    Parameters
    ----------
    path_or_text : str or Path
        A path to an existing file, or TOML text.

    Returns
    -------
    bool
        False also for unreadable files or invalid TOML (the study loaders report those).
    """
    text = str(path_or_text)
    try:
        if isinstance(path_or_text, Path) or (len(text) < 4096 and Path(text).is_file()):
            text = Path(path_or_text).read_text(encoding="utf-8")
        return isinstance(tomllib.loads(text).get("hazard"), dict)
    except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError):
        return False


def load_hazard_study(path: str | Path) -> HazardStudy:
    """Read and validate a hazard study file.

    Parameters
    ----------
    path : str or Path
        A TOML file with a ``[hazard]`` table.

    Returns
    -------
    HazardStudy

    Raises
    ------
    StudyError
        The file cannot be read, is not valid TOML, or breaks a rule of the format.
    """
    path = Path(path)
    return parse_hazard_study(read_study_text(path), file=str(path))


def parse_hazard_study(text: str, file: str = "<string>") -> HazardStudy:
    """Validate the text of a hazard study (the format is in the module docstring).

    Parameters
    ----------
    text : str
        TOML text.
    file : str
        Name used in error messages.

    Returns
    -------
    HazardStudy

    Raises
    ------
    StudyError
        On the first rule the study breaks: the message names the key path and the value.
    """
    return _HazardParser(file, parse_toml(text, file)).hazard(text)


class _HazardParser(_Parser):
    """The study parser's checks (units, plausibility, supports), walking a ``[hazard]``."""

    def hazard(self, text: str) -> HazardStudy:
        if "hazard" not in self.doc:
            raise self.error("hazard", None, "missing table [hazard]: a hazard study keeps "
                             "everything under it (see skidmc.ensemble.hazard_study)")
        others = [k for k in self.doc if k != "hazard"]
        if others:
            raise self.error(others[0], self.doc[others[0]], "unknown top-level key in a "
                             "hazard study: everything goes under [hazard]")
        head = self.table(self.doc["hazard"], "hazard")
        self.unknown_keys(head, _HAZARD_KEYS, "hazard")
        name = self.string(head, "name", "hazard")
        if not _NAME_PATTERN.match(name):
            raise self.error("hazard.name", name, "must be letters, digits, '.', '_' or '-' "
                             "(it names the results folder)")
        description = self.string(head, "description", "hazard", required=False)
        scene = self.base_scene(head.get("scene"))
        drop = self.drop_height(head.get("drop_height"))
        angle = self.required_distribution(head, "angle", "angle")
        billet = self.keyed(head.get("billet", {}), "billet")
        epistemic = self.keyed(head.get("epistemic", {}), "epistemic")
        both = sorted(set(billet) & set(epistemic))
        if both:
            raise self.error(_toml_key("hazard", "epistemic", both[0]), None,
                             f"{both[0]} is also in [hazard.billet]: an input is either "
                             "aleatory (billet) or epistemic, not both")
        surfaces = self.surfaces(head.get("surface"), scene, angle, billet, epistemic)
        if not any(s.modelled for s in surfaces):
            raise self.error("hazard.surface", [s.material for s in surfaces], "every surface "
                             "is outside the model: there is nothing to estimate")
        estimator = self.estimator(head.get("estimator"))
        solver = self.solver_options(head.get("solver", {}))
        assumptions = self.assumptions(head.get("assumptions", []))
        configuration, angles = self.alternatives(head.get("alternatives", {}), scene,
                                                  head["angle"])
        return HazardStudy(
            name=name, description=description, scene=scene, drop_height=drop, angle=angle,
            surfaces=surfaces, billet=billet, epistemic=epistemic, estimator=estimator,
            solver=solver, text=text, sha256=hashlib.sha256(text.encode("utf-8")).hexdigest(),
            file=self.file, assumptions=assumptions, alternative_configuration=configuration,
            angle_alternatives=angles,
        )

    def assumptions(self, value: object) -> tuple[str, ...]:
        if not isinstance(value, list) or not all(isinstance(v, str) and v.strip()
                                                  for v in value):
            raise self.error("hazard.assumptions", value, "expected a list of sentences, one "
                             "judgement of the study each (printed under Assumptions)")
        return tuple(v.strip() for v in value)

    def alternatives(self, table: object, scene: Scene, angle_spec: dict):
        at = ("hazard", "alternatives")
        table = self.table(table, *at)
        self.unknown_keys(table, _ALTERNATIVE_KEYS, *at)
        configuration = table.get("configuration")
        if configuration is not None and configuration not in ("pendulum", "vertical"):
            raise self.error("hazard.alternatives.configuration", configuration,
                             "expected 'pendulum' or 'vertical'")
        if configuration == scene.configuration:
            raise self.error("hazard.alternatives.configuration", configuration,
                             f"the study's scene is {configuration} already: name the other "
                             "geometry")
        scales = table.get("angle_scales", [])
        if not isinstance(scales, list):
            raise self.error("hazard.alternatives.angle_scales", scales,
                             "expected a list of angles with units, e.g. ['5 deg', '15 deg']")
        angles = []
        for i, scale in enumerate(scales):
            spec = {**angle_spec, "scale": scale}
            angles.append(self.checked_distribution("angle", spec,
                                                    (*at, "angle_scales", i)))
        return configuration, tuple(angles)

    # -- scene and distributions

    def base_scene(self, table: object) -> Scene:
        if table is None:
            raise self.error("hazard.scene", None, "missing table [hazard.scene] (a preset "
                             "for the HE and kinetics, plus overrides)")
        table = self.table(table, "hazard", "scene")
        for key in table:
            if key in _OWNED_KEYS or key == "target":
                owner = _OWNED_KEYS.get(key, "the surfaces' materials")
                raise self.error(_toml_key("hazard", "scene", key), table[key],
                                 f"set by {owner} in a hazard study")
        preset = table.get("preset")
        if preset is not None and not isinstance(preset, str):
            raise self.error("hazard.scene.preset", preset, "expected a preset name")
        overrides = {k: v for k, v in table.items() if k != "preset"}
        try:
            return make_scene(overrides, preset=preset)
        except SceneError as exc:
            raise self.error(_toml_key("hazard", "scene", exc.key), exc.value,
                             exc.reason) from None

    def required_distribution(self, head: Mapping, name: str, key: str) -> Distribution:
        if name not in head:
            raise self.error(_toml_key("hazard", name), None, f"missing table [hazard.{name}] "
                             "(a distribution with its source)")
        spec = self.table(head[name], "hazard", name)
        return self.checked_distribution(key, spec, ("hazard", name))

    def checked_distribution(self, key: str, spec: dict, at: tuple) -> Distribution:
        if "kind" in spec:
            raise self.error(_toml_key(*at, "kind"), spec["kind"], "not used in a hazard "
                             "study: the table says the kind ([hazard.billet] aleatory, "
                             "[hazard.epistemic] epistemic)")
        return self.distribution(key, spec, at)

    def keyed(self, table: object, part: str) -> dict[str, Distribution]:
        where = ("hazard", part)
        table = self.table(table, *where)
        for key in _dotted_keys(table):
            if key in _OWNED_KEYS:
                raise self.error(_toml_key(*where, key), None,
                                 f"{key} is set by {_OWNED_KEYS[key]} in a hazard study")
            if part == "billet" and key not in BILLET_KEYS and key in NUMERIC_KEYS:
                raise self.error(_toml_key(*where, key), None,
                                 f"not a billet input (one of {', '.join(BILLET_KEYS)}); "
                                 "kinetics and other unknowns go in [hazard.epistemic]")
        out = self.uncertain(table, *where)
        for key in out:
            if "kind" in _lookup(table, key):
                raise self.error(_toml_key(*where, key, "kind"), _lookup(table, key)["kind"],
                                 "not used in a hazard study: the table says the kind")
            if part == "billet" and key not in BILLET_KEYS:
                raise self.error(_toml_key(*where, key), None,
                                 f"not a billet input (one of {', '.join(BILLET_KEYS)}); "
                                 "kinetics and other unknowns go in [hazard.epistemic]")
        return {k: dataclasses.replace(d, kind="aleatory" if part == "billet" else "epistemic")
                for k, d in out.items()}

    def drop_height(self, table: object) -> Distribution:
        """The drop height: a distribution of a length, not a scene key."""
        at = ("hazard", "drop_height")
        where = _toml_key(*at)
        if table is None:
            raise self.error(where, None, "missing table [hazard.drop_height] (a distribution "
                             "of a length with its source)")
        spec = self.table(table, *at)
        name = spec.get("distribution")
        dist = getattr(scipy.stats, name, None) if isinstance(name, str) else None
        if not isinstance(dist, scipy.stats.rv_continuous):
            continuous = [n for n in dir(scipy.stats)
                          if isinstance(getattr(scipy.stats, n), scipy.stats.rv_continuous)]
            raise self.error(where + ".distribution", name, "not a scipy.stats continuous "
                             "distribution; " + _suggest(str(name), continuous))
        source = spec.get("source")
        if not isinstance(source, str) or not source.strip():
            raise self.error(where + ".source", source, "every distribution needs a `source`: "
                             "where its width comes from (report, handbook, literature)")
        shapes = [s.strip() for s in (dist.shapes or "").split(",") if s.strip()]
        allowed = (*shapes, "loc", "scale")
        given = {k: v for k, v in spec.items() if k not in _DROP_META}
        for pname, value in given.items():
            if pname not in allowed:
                raise self.error(f"{where}.{pname}", value,
                                 f"not a parameter of scipy.stats.{name} (its parameters: "
                                 f"{', '.join(allowed)})")
        for s in shapes:
            if s not in given:
                raise self.error(f"{where}.{s}", None,
                                 f"missing: scipy.stats.{name} needs {', '.join(shapes)}")
        params: dict[str, float] = {}
        for pname in sorted(given, key=lambda p: p != "loc"):
            raw = given[pname]
            role = _parameter_role(name, pname, params.get("loc", 0.0))
            at_param = f"{where}.{pname}"
            if role == "number":
                if isinstance(raw, bool) or not isinstance(raw, numbers.Real):
                    raise self.error(at_param, raw, f"expected a plain number (`{pname}` of "
                                     f"{name} is dimensionless)")
                params[pname] = float(raw)
            else:
                if not isinstance(raw, str):
                    raise self.error(at_param, raw, "a height needs its unit, e.g. '1 m' or "
                                     "'3 ft'")
                try:
                    params[pname] = to_si("drop_height", raw, "m")
                except SceneError as exc:
                    raise self.error(at_param, raw, exc.reason) from None
            if not math.isfinite(params[pname]):
                raise self.error(at_param, raw, "must be finite")
        params = {p: params[p] for p in allowed if p in params}
        d = Distribution(key="drop_height", name=name, params=tuple(params.items()),
                         source=source)
        lo, hi = d.frozen.support()
        if np.isnan(lo) or np.isnan(hi) or not np.isfinite(d.frozen.ppf(0.5)):
            raise self.error(where, spec, f"invalid parameters for scipy.stats.{name} "
                             f"({d.describe()}): " + _PARAMETER_RULES.get(
                                 name, "check scipy's documentation of the parameters"))
        if lo < 0:
            raise self.error(where, spec, f"{d.describe()} reaches below 0 m (its support "
                             f"starts at {lo:g} m): a drop height is >= 0; use lognorm, "
                             "loguniform, or truncate")
        return d

    # -- surfaces

    def surfaces(self, entries: object, scene: Scene, angle: Distribution, billet: dict,
                 epistemic: dict) -> tuple[Surface, ...]:
        if entries is None:
            raise self.error("hazard.surface", None, "missing: give one or more "
                             "[[hazard.surface]] tables (material, weight, source, friction)")
        if not isinstance(entries, list) or not entries:
            raise self.error("hazard.surface", entries, "expected [[hazard.surface]] tables")
        out: list[Surface] = []
        for i, entry in enumerate(entries):
            at = ("hazard", "surface", i)
            table = self.table(entry, *at)
            self.unknown_keys(table, _SURFACE_KEYS, *at)
            material = table.get("material")
            if material is None:
                raise self.error(_toml_key(*at, "material"), None, "missing: a material name "
                                 "(skidmc materials lists them)")
            try:
                get_material(material)
            except SceneError as exc:
                raise self.error(_toml_key(*at, "material"), material, exc.reason) from None
            if material in [s.material for s in out]:
                raise self.error(_toml_key(*at, "material"), material, "this material is "
                                 "listed twice: give it one surface with the summed weight")
            weight = table.get("weight")
            if (isinstance(weight, bool) or not isinstance(weight, numbers.Real)
                    or not 0.0 < weight <= 1.0):
                raise self.error(_toml_key(*at, "weight"), weight,
                                 "expected a share of accidents in (0, 1]")
            source = table.get("source")
            if not isinstance(source, str) or not source.strip():
                raise self.error(_toml_key(*at, "source"), source, "every surface needs a "
                                 "`source` for its weight (statistics, or 'judgement: why')")
            if "friction" not in table:
                raise self.error(_toml_key(*at, "friction"), None, "missing: the apparent "
                                 "friction coefficient's distribution on this surface")
            friction = self.checked_distribution(
                "mu", self.table(table["friction"], *at, "friction"), (*at, "friction"))
            surface_scene = scene.replace(target=material)
            sc = StudyScene(name=material, scene=surface_scene,
                            uncertain={"mu": friction, "angle": angle, **billet, **epistemic})
            try:
                self.check_rate_reference(sc)
            except StudyError as exc:
                raise self.error(_toml_key("hazard", "epistemic", RATE_AT_REFERENCE),
                                 exc.value, exc.reason) from None
            self.check_support(sc, friction, (*at, "friction"))
            self.check_support(sc, angle, ("hazard", "angle"))
            for part, group in (("billet", billet), ("epistemic", epistemic)):
                for key, d in group.items():
                    self.check_support(sc, d, ("hazard", part, key))
            regime, note = self.regime(table, at, material, surface_scene, billet)
            out.append(Surface(material=material, weight=float(weight), source=source,
                               friction=friction, scene=surface_scene, regime=regime,
                               regime_note=note))
        total = math.fsum(s.weight for s in out)
        if abs(total - 1.0) > _WEIGHT_TOLERANCE:
            raise self.error("hazard.surface", {s.material: s.weight for s in out},
                             f"the weights sum to {total:.6g}, not 1: they are the shares of "
                             "accidents on each surface")
        return tuple(out)

    def regime(self, table: Mapping, at: tuple, material: str, scene: Scene,
               billet: Mapping[str, Distribution]) -> tuple[str, str]:
        """(regime, note) of a surface: outside, yielding or rigid, from its hardness against
        the billet's flow stress (its distribution's 1e-9..1-1e-9 range where it is sampled)."""
        entry = get_material(material)
        outside = table.get("outside_model")
        if outside is not None and (not isinstance(outside, str) or not outside.strip()):
            raise self.error(_toml_key(*at, "outside_model"), outside, "expected why this "
                             "surface lies outside the model, in words")
        if entry.elastic and outside is None:
            raise self.error(_toml_key(*at, "material"), material, "an elastic material: the "
                             "report's plastic-contact model cannot describe it ("
                             f"{entry.hardness_source}); keep it with `outside_model = \"why\"` "
                             "(its weight is then reported as an unmodelled share, not as no "
                             "reaction) or remove it")
        if outside is not None:
            return "outside", f"outside the model: {outside.strip()}"
        hardness = float(scene.target_hardness)
        if "flow_stress" in billet:
            d = billet["flow_stress"]
            frozen = _scaled_frozen(d, scene.flow_stress)
            low, high = float(frozen.ppf(1e-9)), float(frozen.isf(1e-9))
        else:
            low = high = float(scene.flow_stress)
        if not math.isfinite(hardness) or hardness >= high:
            return "rigid", ("rigid: hardness above every sampled flow stress of the billet "
                             f"({entry.hardness_source})")
        pressure = f"{hardness / 1e6:.3g} MPa ({hardness / 6894.757:.4g} psi)"
        part = ("for every sampled billet" if hardness <= low else
                f"for billets whose flow stress exceeds it (sampled range "
                f"{low / 1e6:.3g}-{high / 1e6:.3g} MPa)")
        return "yielding", (f"yielding: contact pressure p_t = {pressure} {part}, below the "
                            f"billet's flow stress (source: {entry.hardness_source})")

    # -- settings

    def estimator(self, table: object) -> EstimatorOptions:
        at = ("hazard", "estimator")
        if table is None:
            raise self.error("hazard.estimator", None, "missing table [hazard.estimator] "
                             "(at least the seed)")
        table = self.table(table, *at)
        self.unknown_keys(table, _ESTIMATOR_KEYS, *at)
        defaults = EstimatorOptions()
        method = table.get("method", defaults.method)
        if method not in ESTIMATOR_METHODS:
            raise self.error("hazard.estimator.method", method,
                             _suggest(str(method), ESTIMATOR_METHODS))
        values = {"method": method}
        for name in ("target_cov", "epistemic_target_cov"):
            value = table.get(name, getattr(defaults, name))
            if (isinstance(value, bool) or not isinstance(value, numbers.Real)
                    or not 0.0 < value < 1.0):
                raise self.error(f"hazard.estimator.{name}", value,
                                 "expected a coefficient of variation in (0, 1)")
            values[name] = float(value)
        for name, minimum in (("max_runs", 10), ("epistemic_draws", 0)):
            value = table.get(name, getattr(defaults, name))
            if isinstance(value, bool) or not isinstance(value, int) or value < minimum:
                raise self.error(f"hazard.estimator.{name}", value,
                                 f"expected an integer >= {minimum}")
            values[name] = value
        if "seed" not in table:
            raise self.error("hazard.estimator.seed", None, "missing: a study must be "
                             "reproducible (any integer >= 0)")
        seed = table["seed"]
        if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
            raise self.error("hazard.estimator.seed", seed, "expected an integer >= 0")
        values["seed"] = seed
        return EstimatorOptions(**values)

    def solver_options(self, table: object) -> SolverOptions:
        try:
            return self.solver(self.table(table, "hazard", "solver"))
        except StudyError as exc:  # the study parser names solver.*; here it is hazard.solver.*
            raise self.error("hazard." + exc.key, exc.value, exc.reason) from None


def _scaled_frozen(d: Distribution, nominal: float):
    """d's frozen distribution [SI], a relative one scaled by `nominal`."""
    if not d.relative:
        return d.frozen
    params = dict(d.params)
    params["loc"] = params.get("loc", 0.0) * nominal
    params["scale"] = params.get("scale", 1.0) * nominal
    return getattr(scipy.stats, d.name)(**params)


def _dotted_keys(table: Mapping, prefix: tuple[str, ...] = ()) -> list[str]:
    """The dotted keys of a table of distributions, as the study parser's walk reads them."""
    keys = []
    for name, value in table.items():
        path = (*prefix, name)
        if not isinstance(value, dict) or not value or any(
                not isinstance(v, dict) for v in value.values()):
            keys.append(".".join(path))
        else:
            keys += _dotted_keys(value, path)
    return keys


def _lookup(table: Mapping, key: str) -> Mapping:
    """The spec of a dotted key in a TOML table read either nested or quoted."""
    if key in table:
        return table[key]
    node: object = table
    for part in key.split("."):
        node = node.get(part, {}) if isinstance(node, Mapping) else {}
    return node if isinstance(node, Mapping) else {}
