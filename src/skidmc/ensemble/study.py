"""Study files: one user's question, declared once in TOML and validated on load.

A study names the scene(s), the uncertain inputs with their distributions, the design and the
solver settings; :func:`load_study` turns it into a :class:`Study` and rejects anything it cannot
run with a :class:`StudyError` naming the file, the key and the value. The format::

    [study]
    name = "paper-quartz-mu"            # results go to results/<name>/ensemble.h5
    description = "..."
    # kind = "ensemble"                 # or "sobol" (grows N to n_max); without it: "sobol"
    #                                   # for a saltelli design with n_max, else "ensemble"
    #                                   # (skidmc.workflows.registry)

    [scene]                             # one scene: a preset plus overrides (units allowed) ...
    preset = "paper-quartz"
    flow_stress = "30000 psi"

    # [[scenes]]                        # ... or several named scenes (storage dimension `scene`)
    # name = "gold"
    # preset = "paper-gold"
    # experiment = "gold"               # compared with the report's drops in `skidmc report`
    # [scenes.uncertain."target.conductivity"]   # a distribution for this scene only
    # ...

    [uncertain.mu]                      # any numeric scene key
    distribution = "lognorm"            # a scipy.stats continuous distribution, by its name
    s = 0.2                             # scipy's parameter names (shapes, loc, scale)
    relative = true                     # the distribution is of a factor on each scene's value
    source = "report Sec. IV: least reproducible input"   # mandatory
    kind = "aleatory"                   # varies drop to drop (default) or "epistemic": fixed
                                        # but unknown (kinetics, properties); both -> nested

    [uncertain."kinetics.activation_temperature"]
    distribution = "uniform"
    loc = "15000 K"                     # values with units where the key has units
    scale = "19000 K"
    source = "..."

    [uncertain."kinetics.rate_at_reference"]    # samples Z through the rate at T_ref:
    distribution = "lognorm"                    # Z = k_ref exp(E/R / T_ref)
    s = 1.0
    scale = "1 1/s"
    reference_temperature = "580 K"
    source = "..."

    [[correlation]]                     # Gaussian copula between two uncertain inputs
    keys = ["kinetics.activation_temperature", "kinetics.prefactor"]
    spearman = 0.9                      # rank correlation (or `gaussian`: the copula's own rho)
    source = "..."

    [design]
    method = "lhs"                      # mc | lhs | sobol | saltelli
    n = 256                             # samples (saltelli: base samples N, N (2d + 2) rows)
    seed = 20240601
    # n_epistemic = 32                  # with aleatory AND epistemic inputs: outer draws, each
    #                                   # with n aleatory samples (32 x 256 rows)
    # n_max = 4096                      # saltelli: double N until every index above
    #                                   # stable_threshold (0.1) has a half-width
    #                                   # <= stable_half_width (0.05), reusing the rows

    [solver]                            # skidmc.solver.critical_height arguments
    rtol = 1e-2
    tier = "full"
    h_min = "1 mm"
    h_max = "10 km"

How study-wide and per-scene entries of one key combine. A scene's own entry
(``[scenes.uncertain.KEY]``) replaces the study-wide ``[uncertain.KEY]`` when both have the same
kind. When one is epistemic and the other aleatory, the key is uncertain at two levels: the
epistemic entry gives its level (absolute, or ``relative`` to the scene's value) and the aleatory
entry, which must say ``relative = true``, a factor on that level drawn for every sample, so the
value sampled is the epistemic value times the aleatory factor. Friction, for example: a fixed
but poorly known mean per finish, times drop-to-drop scatter::

    [[scenes]]
    name = "quartz"
    preset = "paper-quartz"
    [scenes.uncertain.mu]               # this finish's mean friction: fixed but unknown
    distribution = "uniform"
    loc = 0.11
    scale = 0.05
    kind = "epistemic"
    source = "..."

    [uncertain.mu]                      # every finish: scatter from drop to drop, a factor
    distribution = "lognorm"
    s = 0.1
    relative = true
    kind = "aleatory"
    source = "..."

The factor has a design column of its own (``"mu:aleatory_factor"``, aleatory), so such a study
nests (``design.n_epistemic``). A scene without an epistemic entry for the key then takes the
factor on its nominal value (the same values as the plain relative distribution). Refused, with
both TOML keys named: an aleatory entry that is not relative where it would be the factor (in
this scene or, for the same key, in another). The physical range is checked on the products of
both entries' tail quantiles.

Physical bounds are checked at load: every distribution's 1e-9 and 1 - 1e-9 quantiles, for every
scene it applies to, must be valid scene values (the scene layer's ranges, and a friction
coefficient in (0, 1)); the sampling then never leaves those quantiles
(:data:`U_TAIL`), so no sample can fall outside the range that was checked.

A bare number (no units) for a dimensional key is read in the key's SI unit, and refused where
that reading is implausible (:attr:`skidmc.scene.keys.InputKey.plausible`): a scene value or a
distribution's level parameter (``loc``; ``loguniform``'s ``a``, ``b``; ``lognorm``'s median
``scale``) outside the key's plausible range, a spread (``scale``) wider than that range. The
error names the TOML key and the number as written (``uncertain.flow_stress.loc = 28000: is
read as 28000 Pa (SI), ...``); write units to use such a value. A scene table may name its
target material, ``target = "steel"`` (:mod:`skidmc.scene.materials`).
"""

from __future__ import annotations

import dataclasses
import difflib
import hashlib
import math
import numbers
import re
from collections.abc import Mapping
from pathlib import Path

import numpy as np
import scipy.stats

from skidmc.ensemble.study_model import (
    DESIGN_METHODS,
    EXTRA_KEYS,
    KINDS,
    RATE_AT_REFERENCE,
    STUDY_RANGES,
    U_TAIL,
    Correlation,
    DesignSpec,
    Distribution,
    SolverOptions,
    Study,
    StudyError,
    StudyScene,
    aleatory_factor_column,
    check_n,
    prefactor_from_rate,
)
from skidmc.errors import SceneError
from skidmc.scene import SCENE_KEYS, SI_UNITS, make_scene
from skidmc.scene.keys import implausible_reason
from skidmc.scene.units import read_si, to_si

try:
    import tomllib
except ModuleNotFoundError:  # Python 3.10: the same parser, packaged as tomli
    import tomli as tomllib

__all__ = [
    "DESIGN_METHODS",
    "EXTRA_KEYS",
    "RATE_AT_REFERENCE",
    "U_TAIL",
    "Correlation",
    "DesignSpec",
    "Distribution",
    "SolverOptions",
    "Study",
    "StudyError",
    "StudyScene",
    "load_study",
    "parse_study",
    "parse_toml",
    "read_study_text",
]

_TOP_LEVEL = ("study", "scene", "scenes", "uncertain", "correlation", "design", "solver")
_STUDY_KEYS = ("name", "description", "kind")
_SCENE_RESERVED = ("name", "preset", "uncertain", "experiment")
_DIST_META = ("distribution", "source", "relative", "reference_temperature", "kind")
_DESIGN_KEYS = ("method", "n", "seed", "second_order", "n_epistemic", "n_max",
                "stable_threshold", "stable_half_width")
_SOLVER_KEYS = ("rtol", "tier", "h_min", "h_max", "backend")
#: Where the full tier runs (``[solver] backend``): skidmc.solver.cuda.BACKENDS.
_BACKENDS = ("cpu", "cuda")
_CORRELATION_KEYS = ("keys", "spearman", "gaussian", "source")
_NAME_PATTERN = re.compile(r"^[A-Za-z0-9][A-Za-z0-9._-]*$")
# "<number> <unit>": to convert a spread (a temperature difference) separately from a level.
_NUMBER_THEN_UNIT = re.compile(r"^\s*[+-]?(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?\s*(?P<unit>.*?)\s*$")
_NO_VALUE = object()




# --- loading --------------------------------------------------------------------------------------


def load_study(path: str | Path) -> Study:
    """Read and validate a study file.

    Parameters
    ----------
    path : str or Path
        A TOML study file.

    Returns
    -------
    Study

    Raises
    ------
    StudyError
        The file cannot be read, is not valid TOML, or breaks a rule of the format.
    """
    path = Path(path)
    return parse_study(read_study_text(path), file=str(path))


def read_study_text(path: Path) -> str:
    """The text of a study file (UTF-8), or a StudyError naming the file."""
    try:
        return path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise StudyError(str(path), "(file)", None, f"cannot read: {exc}") from None


def parse_study(text: str, file: str = "<string>") -> Study:
    """Validate the text of a study file (see the module docstring for the format).

    Parameters
    ----------
    text : str
        TOML text.
    file : str
        Name used in error messages and recorded in results.

    Returns
    -------
    Study

    Raises
    ------
    StudyError
        On the first rule the study breaks.
    """
    return _Parser(file, parse_toml(text, file)).study(text)


def parse_toml(text: str, file: str) -> dict:
    """The TOML document of a study file's text, or a StudyError naming the file."""
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise StudyError(file, "(syntax)", None, f"not valid TOML: {exc}") from None


def _toml_key(*parts: str | int) -> str:
    """Dotted TOML path for messages; parts holding a dot are quoted (``uncertain."he.k"``)."""
    out = []
    for part in parts:
        if isinstance(part, int):
            out[-1] += f"[{part}]"
        elif re.fullmatch(r"[A-Za-z0-9_-]+", part):
            out.append(part)
        else:
            out.append(f'"{part}"')
    return ".".join(out)


def _suggest(word: str, options) -> str:
    close = difflib.get_close_matches(word, list(options), n=3, cutoff=0.6)
    if close:
        return "did you mean " + " or ".join(repr(c) for c in close) + "?"
    return "expected one of " + ", ".join(repr(o) for o in options)


class _Parser:
    """Walks the TOML document; each method raises StudyError at the first problem."""

    def __init__(self, file: str, doc: dict) -> None:
        self.file = file
        self.doc = doc

    def error(self, key: str, value: object, reason: str) -> StudyError:
        return StudyError(self.file, key, value, reason)

    def unknown_keys(self, table: Mapping, allowed, *where: str | int) -> None:
        for name, value in table.items():
            if name not in allowed:
                raise self.error(_toml_key(*where, name), value, "unknown key; " +
                                 _suggest(name, allowed))

    def table(self, value: object, *where: str | int) -> dict:
        if not isinstance(value, dict):
            raise self.error(_toml_key(*where), value, "expected a table")
        return value

    def string(self, table: Mapping, name: str, *where: str | int, required=True,
               default: str = "") -> str:
        if name not in table:
            if required:
                raise self.error(_toml_key(*where, name), None, "missing")
            return default
        value = table[name]
        if not isinstance(value, str):
            raise self.error(_toml_key(*where, name), value, "expected a string")
        return value

    # -- the whole document

    def study(self, text: str) -> Study:
        doc = self.doc
        self.unknown_keys(doc, _TOP_LEVEL)
        if "study" not in doc:
            raise self.error("study", None, "missing table [study] (with at least `name`)")
        head = self.table(doc["study"], "study")
        self.unknown_keys(head, _STUDY_KEYS, "study")
        name = self.string(head, "name", "study")
        if not _NAME_PATTERN.match(name):
            raise self.error("study.name", name, "must be letters, digits, '.', '_' or '-' "
                             "(it names the results folder)")
        description = self.string(head, "description", "study", required=False)
        self.string(head, "kind", "study", required=False)  # its name: skidmc.workflows

        common = self.uncertain(doc.get("uncertain", {}), "uncertain")
        scenes, scene_dimension = self.scenes(common)
        keys: list[str] = []
        for sc in scenes:
            keys += [k for k in sc.uncertain if k not in keys]
        for sc in scenes:  # aleatory factors of keys uncertain at two levels: columns of their own
            keys += [aleatory_factor_column(k) for k in sc.factors
                     if aleatory_factor_column(k) not in keys]
        if not keys:
            raise self.error("uncertain", None, "no uncertain inputs: give at least one "
                             "[uncertain.KEY] table (use `skidmc height` for a single scene)")
        design = self.design(doc.get("design"))
        correlations = self.correlations(doc.get("correlation", []), scenes)
        if correlations and design.method == "saltelli":
            raise self.error("correlation", [list(c.keys) for c in correlations],
                             "the saltelli design needs independent inputs (Sobol indices are "
                             "defined for them); sample kinetics.rate_at_reference instead of "
                             "correlating the kinetics pair, or use mc/lhs/sobol")
        self.check_kinds(scenes, keys, design, correlations)
        solver = self.solver(doc.get("solver", {}))
        return Study(
            name=name, description=description, scenes=scenes,
            scene_dimension=scene_dimension, keys=tuple(keys), correlations=correlations,
            design=design, solver=solver, text=text,
            sha256=hashlib.sha256(text.encode("utf-8")).hexdigest(), file=self.file,
        )

    def check_kinds(self, scenes, keys, design: DesignSpec, correlations) -> None:
        """Aleatory and epistemic inputs: one kind per key; both present <=> a nested design."""
        kinds: dict[str, str] = {}
        for sc in scenes:
            for key, dist in sc.uncertain.items():
                if kinds.setdefault(key, dist.kind) != dist.kind:
                    raise self.error(_toml_key("uncertain", key, "kind"), dist.kind,
                                     f"{key} is {kinds[key]} in another scene: one kind per "
                                     "input across the study")
            for key in sc.factors:
                kinds[aleatory_factor_column(key)] = "aleatory"
        both = len(set(kinds.values())) == 2
        if both and not design.n_epistemic:
            epistemic = [k for k in keys if kinds[k] == "epistemic"]
            raise self.error("design.n_epistemic", None,
                             f"missing: {', '.join(epistemic)} are epistemic and the other "
                             "inputs aleatory, so the design nests; give the number of epistemic "
                             "draws (each gets design.n aleatory samples)")
        if design.n_epistemic and not both:
            raise self.error("design.n_epistemic", design.n_epistemic,
                             "only for a study with both aleatory and epistemic inputs (mark "
                             "each [uncertain.KEY] with kind = 'aleatory' or 'epistemic')")
        for c in correlations:
            if kinds[c.keys[0]] != kinds[c.keys[1]]:
                raise self.error("correlation", list(c.keys), "correlates an aleatory with an "
                                 "epistemic input: a nested design draws them at different levels")

    # -- scenes

    def scenes(self, common: dict[str, Distribution]) -> tuple[tuple[StudyScene, ...], bool]:
        doc = self.doc
        if "scene" in doc and "scenes" in doc:
            raise self.error("scenes", None, "give either one [scene] or several [[scenes]], "
                             "not both")
        if "scene" in doc:
            table = self.table(doc["scene"], "scene")
            return (self.one_scene(table, common, ("scene",), name_required=False),), False
        if "scenes" in doc:
            entries = doc["scenes"]
            if not isinstance(entries, list) or not entries:
                raise self.error("scenes", entries, "expected one or more [[scenes]] tables")
            out: list[StudyScene] = []
            for i, entry in enumerate(entries):
                table = self.table(entry, "scenes", i)
                sc = self.one_scene(table, common, ("scenes", i), name_required=True)
                if sc.name in [o.name for o in out]:
                    raise self.error(_toml_key("scenes", i, "name"), sc.name,
                                     "duplicate scene name")
                out.append(sc)
            return self.two_level(tuple(out), common,
                                  [("scenes", i) for i in range(len(out))]), True
        raise self.error("scene", None, "missing: give a [scene] table (a preset plus "
                         "overrides) or several [[scenes]]")

    def one_scene(self, table: dict, common: dict[str, Distribution],
                  where: tuple, name_required: bool) -> StudyScene:
        name = self.string(table, "name", *where, required=name_required)
        preset = table.get("preset")
        if preset is not None and not isinstance(preset, str):
            raise self.error(_toml_key(*where, "preset"), preset, "expected a preset name")
        if name and not _NAME_PATTERN.match(name):
            raise self.error(_toml_key(*where, "name"), name,
                             "must be letters, digits, '.', '_' or '-'")
        overrides = {k: v for k, v in table.items() if k not in _SCENE_RESERVED}
        try:
            scene = make_scene(overrides, preset=preset)
        except SceneError as exc:  # exc.key is "preset" for an unknown preset
            raise self.error(_toml_key(*where, exc.key), exc.value, exc.reason) from None
        own = self.uncertain(table.get("uncertain", {}), *where, "uncertain")
        uncertain, factors = self.combine(common, own, where)
        if RATE_AT_REFERENCE in uncertain and "kinetics.prefactor" in uncertain:
            raise self.error(_toml_key(*where, "uncertain"), None,
                             "kinetics.prefactor and kinetics.rate_at_reference are both "
                             "uncertain in this scene (one study-wide, one its own): keep one")
        experiment = table.get("experiment")
        if experiment is not None and not isinstance(experiment, str):
            raise self.error(_toml_key(*where, "experiment"), experiment,
                             "expected the name of an experiment (skidmc.analysis.experiments)")
        sc = StudyScene(name=name or preset or "scene", scene=scene, uncertain=uncertain,
                        experiment=experiment, factors=factors)
        self.check_scene(sc, own, where)
        return sc

    def check_scene(self, sc: StudyScene, own: Mapping, where: tuple) -> None:
        """The physical range of every uncertain input of a scene (its rate first: a bad T_ref
        also spoils the rate's support)."""
        self.check_rate_reference(sc)
        for key in dict.fromkeys([*sc.uncertain, *sc.factors]):
            dist = sc.uncertain.get(key) or sc.factors[key]
            origin = (*where, "uncertain", key) if key in own else ("uncertain", key)
            self.check_support(sc, dist, origin)

    def combine(self, common: Mapping[str, Distribution], own: Mapping[str, Distribution],
                where: tuple) -> tuple[dict[str, Distribution], dict[str, Distribution]]:
        """A scene's distributions from the study-wide ones (`common`) and its own (`own`).

        A scene's entry replaces the study-wide entry of the same key and kind. A key with an
        entry of each kind is uncertain at two levels: the epistemic entry gives its level
        (absolute, or relative to the nominal value) and the aleatory entry, which must be
        ``relative = true``, a factor on that level drawn for every sample (friction: a fixed
        but poorly known mean per finish, times drop-to-drop scatter).

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
            by_kind = {own[key].kind: (own[key], (*where, "uncertain", key)),
                       common[key].kind: (common[key], ("uncertain", key))}
            aleatory, at = by_kind["aleatory"]
            epistemic, at_epistemic = by_kind["epistemic"]
            if not aleatory.relative:
                raise self.error(
                    _toml_key(*at, "relative"), False,
                    f"{key} is uncertain at two levels ({_toml_key(*at_epistemic)} epistemic, "
                    f"{_toml_key(*at)} aleatory): the aleatory entry is a factor on the "
                    "epistemic value and must say relative = true (the value sampled is the "
                    "epistemic value times the factor); or give both entries the same kind, "
                    "and the scene's own replaces the study-wide one")
            uncertain[key], factors[key] = epistemic, aleatory
        return uncertain, factors

    def two_level(self, scenes: tuple[StudyScene, ...], common: Mapping[str, Distribution],
                  where: tuple) -> tuple[StudyScene, ...]:
        """Make a key uncertain at two levels in one scene so in every scene: where its only
        entry is the study-wide aleatory one, that entry is the factor (on the nominal value:
        the same values) in the factor's design column, so that the key's own column is
        epistemic throughout."""
        keys = {k for sc in scenes for k in sc.factors}
        out = []
        for i, sc in enumerate(scenes):
            moved = {k: sc.uncertain[k] for k in keys
                     if k in sc.uncertain and k not in sc.factors
                     and sc.uncertain[k].kind == "aleatory"}
            for key, dist in moved.items():
                at = ("uncertain", key) if common.get(key) is dist else (*where[i], "uncertain",
                                                                         key)
                if not dist.relative:
                    raise self.error(
                        _toml_key(*at, "relative"), False,
                        f"{key} is uncertain at two levels in another scene (an epistemic level "
                        f"times an aleatory factor); in scene {sc.name!r} its aleatory entry is "
                        "then that factor and must say relative = true")
            if moved:
                sc = dataclasses.replace(
                    sc, uncertain={k: d for k, d in sc.uncertain.items() if k not in moved},
                    factors={**sc.factors, **moved})
            out.append(sc)
        return tuple(out)

    # -- distributions

    def uncertain(self, table: object, *where: str | int) -> dict[str, Distribution]:
        table = self.table(table, *where)
        specs: dict[str, tuple[dict, tuple]] = {}

        def walk(node: dict, prefix: tuple[str, ...]) -> None:
            for name, value in node.items():
                path = (*prefix, name)
                if not isinstance(value, dict):
                    raise self.error(_toml_key(*where, *path), value,
                                     "expected a table with a `distribution`")
                if any(not isinstance(v, dict) for v in value.values()) or not value:
                    specs[".".join(path)] = (value, (*where, ".".join(path)))
                else:
                    walk(value, path)

        walk(table, ())
        out = {}
        for key, (spec, at) in specs.items():
            if key == "configuration":
                raise self.error(_toml_key(*at), spec, "configuration is a choice, not a "
                                 "number: run one scene per configuration ([[scenes]])")
            if key not in SI_UNITS and key not in EXTRA_KEYS:
                raise self.error(_toml_key(*at), spec, "not a scene key; " +
                                 _suggest(key, [*SCENE_KEYS, *EXTRA_KEYS]))
            out[key] = self.distribution(key, spec, at)
        if RATE_AT_REFERENCE in out and "kinetics.prefactor" in out:
            raise self.error(_toml_key(*where, RATE_AT_REFERENCE), None,
                             "kinetics.prefactor is sampled through the rate at the reference "
                             "temperature; give one of the two, not both")
        return out

    def distribution(self, key: str, spec: dict, at: tuple) -> Distribution:
        where = _toml_key(*at)
        name = spec.get("distribution")
        if name is None:
            raise self.error(where + ".distribution", None,
                             "missing (a scipy.stats name: norm, lognorm, truncnorm, uniform, "
                             "loguniform, triang, beta, ...)")
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
        relative = spec.get("relative", False)
        if not isinstance(relative, bool):
            raise self.error(where + ".relative", relative, "expected true or false")
        kind = spec.get("kind", "aleatory")
        if kind not in KINDS:
            raise self.error(where + ".kind", kind, "expected 'aleatory' (varies from drop to "
                             "drop) or 'epistemic' (fixed but unknown)")
        shapes = [s.strip() for s in (dist.shapes or "").split(",") if s.strip()]
        allowed = (*shapes, "loc", "scale")
        given = {k: v for k, v in spec.items() if k not in _DIST_META}
        for pname, value in given.items():
            if pname not in allowed:
                raise self.error(f"{where}.{pname}", value,
                                 f"not a parameter of scipy.stats.{name} (its parameters: "
                                 f"{', '.join(allowed)})")
        for s in shapes:
            if s not in given:
                raise self.error(f"{where}.{s}", None,
                                 f"missing: scipy.stats.{name} needs {', '.join(shapes)}")

        t_ref = None
        if key == RATE_AT_REFERENCE:
            raw = spec.get("reference_temperature")
            if raw is None:
                raise self.error(where + ".reference_temperature", None,
                                 "missing: the temperature the rate refers to (e.g. '580 K')")
            t_ref = self.quantity(key, raw, "K", where + ".reference_temperature")
            if not (math.isfinite(t_ref) and t_ref > 0):
                raise self.error(where + ".reference_temperature", raw, "must be > 0 K")
        elif "reference_temperature" in spec:
            raise self.error(where + ".reference_temperature", spec["reference_temperature"],
                             f"only for {RATE_AT_REFERENCE}")

        unit = EXTRA_KEYS[key][0] if key in EXTRA_KEYS else SI_UNITS[key]
        params: dict[str, float] = {}
        # loc first: the role of lognorm's scale depends on it.
        for pname in sorted(given, key=lambda p: p != "loc"):
            raw = given[pname]
            role = _parameter_role(name, pname, params.get("loc", 0.0))
            at_param = f"{where}.{pname}"
            if relative or role == "number":
                if isinstance(raw, bool) or not isinstance(raw, numbers.Real):
                    why = ("a relative distribution is of a dimensionless factor"
                           if relative else f"`{pname}` of {name} is dimensionless")
                    raise self.error(at_param, raw, f"expected a plain number ({why})")
                params[pname] = float(raw)
            elif role == "difference":
                params[pname] = self.difference(key, raw, unit, at_param)
            else:
                params[pname] = self.quantity(key, raw, unit, at_param)
            if not math.isfinite(params[pname]):
                raise self.error(at_param, raw, "must be finite")
            if not relative and role != "number" and key in SI_UNITS:
                self.check_plausible(key, raw, params[pname], at_param,
                                     difference=role == "difference")
        params = {p: params[p] for p in allowed if p in params}  # scipy's order
        d = Distribution(key=key, name=name, params=tuple(params.items()), source=source,
                         relative=relative, reference_temperature=t_ref, kind=kind)
        lo, hi = d.frozen.support()
        if np.isnan(lo) or np.isnan(hi) or not np.isfinite(d.frozen.ppf(0.5)):
            raise self.error(where, spec, f"invalid parameters for scipy.stats.{name} "
                             f"({d.describe()}): " + _PARAMETER_RULES.get(
                                 name, "check scipy's documentation of the parameters"))
        return d

    def quantity(self, key: str, raw: object, unit: str, at: str) -> float:
        try:
            return to_si(key, raw, unit)
        except SceneError as exc:
            raise self.error(at, raw, exc.reason) from None

    def check_plausible(self, key: str, raw: object, value: float, at: str,
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
            raise self.error(at, raw, reason)

    def difference(self, key: str, raw: object, unit: str, at: str) -> float:
        """A spread: converted as a difference (5 degC of spread is 5 K, not 278.15 K)."""
        value = self.quantity(key, raw, unit, at)
        match = _NUMBER_THEN_UNIT.match(raw) if isinstance(raw, str) else None
        if match and match["unit"]:
            try:
                value -= to_si(key, "0 " + match["unit"], unit)
            except SceneError:
                pass  # an expression, not "<number> <unit>": only offset units need this
        return value

    def check_support(self, sc: StudyScene, d: Distribution, at: tuple) -> None:
        """Reject a distribution whose tail quantiles leave the physical range (any scene); for
        a key uncertain at two levels, the products of both levels' tail quantiles."""
        where = _toml_key(*at)
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
                raise self.error(
                    where, dict(d.params),
                    f"{d.describe()}{level} reaches {x:.6g} [{unit}] at its {q} quantile in "
                    "scene "
                    f"{sc.name!r}, outside the physical range ({reason}); use a distribution "
                    "whose support stays inside it (truncnorm with suitable a/b, lognorm, "
                    "beta, uniform, loguniform)")

    def check_rate_reference(self, sc: StudyScene) -> None:
        """Z = k_ref exp(E/R / T_ref) must stay a valid prefactor at the corners of the design."""
        d = sc.uncertain.get(RATE_AT_REFERENCE) or sc.factors.get(RATE_AT_REFERENCE)
        if d is None:
            return
        rates = sc.tails(RATE_AT_REFERENCE)
        temps = sc.tails("kinetics.activation_temperature")
        for rate in rates:
            for t_act in temps:
                with np.errstate(over="ignore", invalid="ignore"):
                    z = float(prefactor_from_rate(rate, t_act, d.reference_temperature))
                if not (math.isfinite(z) and z > 0):
                    raise self.error(
                        _toml_key("uncertain", RATE_AT_REFERENCE), dict(d.params),
                        f"in scene {sc.name!r} the prefactor k_ref exp(E/R / T_ref) reaches "
                        f"{z:g} 1/s (k_ref = {rate:g} 1/s, E/R = {t_act:g} K, T_ref = "
                        f"{d.reference_temperature:g} K); raise reference_temperature")

    # -- correlation, design, solver

    def correlations(self, entries: object, scenes) -> tuple[Correlation, ...]:
        if isinstance(entries, dict):
            entries = [entries]
        if not isinstance(entries, list):
            raise self.error("correlation", entries, "expected [[correlation]] tables")
        out: list[Correlation] = []
        for i, entry in enumerate(entries):
            table = self.table(entry, "correlation", i)
            self.unknown_keys(table, _CORRELATION_KEYS, "correlation", i)
            at = _toml_key("correlation", i)
            keys = table.get("keys")
            if (not isinstance(keys, list) or len(keys) != 2
                    or not all(isinstance(k, str) for k in keys)):
                raise self.error(at + ".keys", keys, "expected two uncertain keys")
            if keys[0] == keys[1]:
                raise self.error(at + ".keys", keys, "a key cannot be correlated with itself")
            for k in keys:
                lacking = [sc.name for sc in scenes if k not in sc.uncertain]
                if lacking:
                    raise self.error(at + ".keys", keys, f"{k!r} is not uncertain in scene(s) "
                                     f"{', '.join(lacking)}: only uncertain inputs correlate")
            if any(set(c.keys) == set(keys) for c in out):
                raise self.error(at + ".keys", keys, "this pair is correlated twice")
            source = table.get("source")
            if not isinstance(source, str) or not source.strip():
                raise self.error(at + ".source", source, "every correlation needs a `source`")
            given = [m for m in ("spearman", "gaussian") if m in table]
            if len(given) != 1:
                raise self.error(at, None, "give exactly one of `spearman` (rank correlation) "
                                 "or `gaussian` (the copula's normal-score correlation)")
            value = table[given[0]]
            if isinstance(value, bool) or not isinstance(value, numbers.Real) \
                    or not -1.0 < value < 1.0:
                raise self.error(f"{at}.{given[0]}", value, "must be a number in (-1, 1)")
            rho = 2.0 * math.sin(math.pi * value / 6.0) if given[0] == "spearman" else value
            out.append(Correlation(keys=(keys[0], keys[1]), rho=float(rho),
                                   spearman=float(value) if given[0] == "spearman" else None,
                                   source=source))
        if out:
            names = sorted({k for c in out for k in c.keys})
            r = np.eye(len(names))
            for c in out:
                a, b = names.index(c.keys[0]), names.index(c.keys[1])
                r[a, b] = r[b, a] = c.rho
            if np.linalg.eigvalsh(r).min() <= 1e-10:
                raise self.error("correlation", [[*c.keys, c.rho] for c in out],
                                 "the correlations are inconsistent: their matrix is not "
                                 "positive definite")
        return tuple(out)

    def design(self, table: object) -> DesignSpec:
        if table is None:
            raise self.error("design", None, "missing table [design] (method, n, seed)")
        table = self.table(table, "design")
        self.unknown_keys(table, _DESIGN_KEYS, "design")
        method = self.string(table, "method", "design")
        if method not in DESIGN_METHODS:
            raise self.error("design.method", method, _suggest(method, DESIGN_METHODS))
        n = table.get("n")
        check_n(self.file, method, n, key="design.n")
        seed = table.get("seed")
        if seed is None:
            raise self.error("design.seed", None, "missing: a study must be reproducible "
                             "(any integer >= 0)")
        if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
            raise self.error("design.seed", seed, "expected an integer >= 0")
        second = table.get("second_order", True)
        if not isinstance(second, bool):
            raise self.error("design.second_order", second, "expected true or false")
        if "second_order" in table and method != "saltelli":
            raise self.error("design.second_order", second, "only for method = 'saltelli'")
        n_epistemic = table.get("n_epistemic", 0)
        if "n_epistemic" in table:
            if isinstance(n_epistemic, bool) or not isinstance(n_epistemic, int) or n_epistemic < 2:
                raise self.error("design.n_epistemic", n_epistemic, "expected an integer >= 2 "
                                 "(epistemic draws, each with n aleatory samples)")
            if method == "saltelli":
                raise self.error("design.n_epistemic", n_epistemic, "a nested design takes mc, "
                                 "lhs or sobol, not saltelli")
        growth = {}
        if "n_max" in table:
            n_max = table["n_max"]
            if method != "saltelli":
                raise self.error("design.n_max", n_max, "only for method = 'saltelli' (grows N "
                                 "until the Sobol' indices are stable)")
            check_n(self.file, method, n_max, key="design.n_max")
            if n_max < n:
                raise self.error("design.n_max", n_max, f"must be >= design.n ({n})")
            growth["n_max"] = int(n_max)
        for name in ("stable_threshold", "stable_half_width"):
            if name in table:
                value = table[name]
                if "n_max" not in table:
                    raise self.error("design." + name, value, "only with design.n_max")
                if (isinstance(value, bool) or not isinstance(value, numbers.Real)
                        or not 0 < value < 1):
                    raise self.error("design." + name, value, "expected a number in (0, 1)")
                growth[name] = float(value)
        return DesignSpec(method=method, n=n, seed=seed, second_order=second,
                          n_epistemic=n_epistemic, **growth)

    def solver(self, table: object) -> SolverOptions:
        table = self.table(table, "solver")
        self.unknown_keys(table, _SOLVER_KEYS, "solver")
        defaults = SolverOptions()
        rtol = table.get("rtol", defaults.rtol)
        if isinstance(rtol, bool) or not isinstance(rtol, numbers.Real) or not 0 < rtol < 1:
            raise self.error("solver.rtol", rtol, "expected a number in (0, 1)")
        tier = table.get("tier", defaults.tier)
        tiers = _solver_tiers()
        if not isinstance(tier, str) or (tiers and tier not in tiers):
            raise self.error("solver.tier", tier, _suggest(str(tier), tiers or ["full"]))
        bounds = {}
        for name in ("h_min", "h_max"):
            raw = table.get(name, getattr(defaults, name))
            bounds[name] = self.quantity("solver." + name, raw, "m", "solver." + name)
            if not (math.isfinite(bounds[name]) and bounds[name] > 0):
                raise self.error("solver." + name, raw, "must be a finite height > 0")
        if not bounds["h_min"] < bounds["h_max"]:
            raise self.error("solver.h_min", table.get("h_min", defaults.h_min),
                             f"must be below h_max ({bounds['h_max']:g} m)")
        backend = table.get("backend", defaults.backend)
        if not isinstance(backend, str) or backend not in _BACKENDS:
            raise self.error("solver.backend", backend, _suggest(str(backend), list(_BACKENDS)))
        if backend != "cpu" and tier != "full":
            raise self.error("solver.backend", backend,
                             f"runs the full tier only; tier = {tier!r} runs on the CPU")
        return SolverOptions(rtol=float(rtol), tier=tier, backend=backend, **bounds)


def _solver_tiers() -> tuple[str, ...]:
    """Tiers the solver offers, if it lists them (``skidmc.solver.TIERS``); else ("full",)."""
    from skidmc import solver

    return tuple(getattr(solver, "TIERS", ("full",)))


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
