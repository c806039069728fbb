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
    # assumptions = ["..."]             # judgements no input's source states, printed by
    #                                   # `skidmc report` under "Assumptions of the study"

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

The format is declared once, as the pydantic models of :mod:`skidmc.ensemble.study_schema`
(:class:`~skidmc.ensemble.study_schema.StudyFile`), which validate a file and build its
:class:`Study`; this module reads the file and names it in every error.
"""

from __future__ import annotations

from pathlib import Path

from skidmc.ensemble.study_model import (
    DESIGN_METHODS,
    EXTRA_KEYS,
    RATE_AT_REFERENCE,
    U_TAIL,
    Correlation,
    DesignSpec,
    Distribution,
    SolverOptions,
    Study,
    StudyError,
    StudyScene,
)
from skidmc.ensemble.study_schema import SCHEMAS, StudyFile, load_model

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


def load_study(path: str | Path, kind: str | None = None) -> Study:
    """Read and validate a study file.

    Parameters
    ----------
    path : str or Path
        A TOML study file.
    kind : {"ensemble", "sobol"}, optional
        Validate it as this kind's file (:data:`skidmc.ensemble.study_schema.SCHEMAS`); by
        default as either.

    Returns
    -------
    Study

    Raises
    ------
    StudyError
        The file cannot be read, is not valid TOML, or breaks a rule of the format.
    """
    path = Path(path)
    return parse_study(read_study_text(path), file=str(path), kind=kind)


def read_study_text(path: Path) -> str:
    """The text of a study file (UTF-8), or a StudyError naming the file."""
    try:
        return path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise StudyError(str(path), "(file)", None, f"cannot read: {exc}") from None


def parse_study(text: str, file: str = "<string>", kind: str | None = None) -> Study:
    """Validate the text of a study file (see the module docstring for the format).

    Parameters
    ----------
    text : str
        TOML text.
    file : str
        Name used in error messages and recorded in results.
    kind : {"ensemble", "sobol"}, optional
        Validate it as this kind's file; by default as either.

    Returns
    -------
    Study

    Raises
    ------
    StudyError
        On the first rule the study breaks.
    """
    model = StudyFile if kind is None else SCHEMAS[kind]
    return load_model(model, parse_toml(text, file), file).build(text, file)


def parse_toml(text: str, file: str) -> dict:
    """The TOML document of a study file's text, or a StudyError naming the file."""
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise StudyError(file, "(syntax)", None, f"not valid TOML: {exc}") from None
