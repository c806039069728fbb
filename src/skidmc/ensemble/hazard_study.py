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

    [hazard.posterior]                  # optional: the epistemic loop's draws taken from a
    calibration = "calibration-series1.toml"  # calibration's stored posterior (or a .nc),
    prior_study = "hazard-handling.toml"      # beside the same study over the priors
                                        # (skidmc.workflows.hazard_posterior)

Distributions follow the rules of :mod:`skidmc.ensemble.study`: scipy's parameter names, values
with units where the key has units (a bare number is read in SI and refused where implausible),
``relative = true`` for a factor on the scene's value, a ``source`` on every one, and the
1e-9 and 1 - 1e-9 quantiles must be valid scene values for every surface. Each surface's
regime (:data:`REGIMES`) follows from its material: ``outside`` where the file says
``outside_model`` (an elastic material must), ``yielding`` where its hardness
(``target.hardness``) lies below the billet's sampled flow stress, else ``rigid``. Every error is a
:class:`~skidmc.ensemble.study_model.StudyError` naming the file, the key path and the value as
written. The format is declared once, as the pydantic model
:class:`~skidmc.ensemble.study_schema.HazardFile`, which validates a file and builds its
:class:`HazardStudy` (the data model, :mod:`skidmc.ensemble.study_model`).
"""

from __future__ import annotations

from pathlib import Path

from skidmc.ensemble.study import parse_toml, read_study_text
from skidmc.ensemble.study_model import (
    BILLET_KEYS,
    ESTIMATOR_METHODS,
    REGIMES,
    EstimatorOptions,
    HazardStudy,
    Surface,
)
from skidmc.ensemble.study_schema import HazardFile, load_model

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
    return load_model(HazardFile, parse_toml(text, file), file).build(text, file)
