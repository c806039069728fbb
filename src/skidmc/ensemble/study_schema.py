"""The study file formats declared as pydantic v2 models, exported as JSON Schema for editors.

These models state the *structure* of each kind's TOML file (tables, keys, types, allowed
words), discriminated by kind, with one distribution schema shared by every kind
(:class:`DistributionSpec`). Editors with a TOML language server (taplo, Even Better TOML) check
a study file against ``docs/schemas/<kind>.json`` (``#:schema ../docs/schemas/ensemble.json`` as
the file's first line). Loading still goes through :func:`skidmc.ensemble.study.load_study` and
:func:`skidmc.ensemble.hazard_study.load_hazard_study`, whose checks go further (units, physical
ranges at the tail quantiles, plausibility, correlations) and whose messages name the TOML key,
the value as written and a suggestion; a test keeps the two in step (every shipped study
validates against its model, and the exported files are current).

pydantic rather than attrs + cattrs: it exports JSON Schema itself, and it is already a
dependency of the tools around the package.
"""

from __future__ import annotations

import json
from typing import Annotated, Literal

from pydantic import BaseModel, ConfigDict, Field, StrictBool

__all__ = ["SCHEMAS", "DistributionSpec", "EnsembleFile", "HazardFile", "SobolFile",
           "json_schema"]

# A number or a quantity with units ("28000 psi", "580 K").
Quantity = Annotated[float | str, Field(description="a number (SI) or a quantity with units")]


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid")


class DistributionSpec(BaseModel):
    """One uncertain input: a scipy.stats continuous distribution by name, its parameters by
    scipy's names (shapes, loc, scale; any extra key here), a source (every kind)."""

    model_config = ConfigDict(extra="allow", json_schema_extra={
        "additionalProperties": {"type": ["number", "string"]}})
    distribution: str = Field(description="name of a scipy.stats continuous distribution")
    source: str = Field(min_length=1, description="where its width comes from")
    relative: StrictBool = Field(False, description="a factor on each scene's value")
    kind: Literal["aleatory", "epistemic"] = Field(
        "aleatory", description="varies drop to drop, or fixed but unknown")
    reference_temperature: Quantity | None = Field(
        None, description="kinetics.rate_at_reference only: T_ref")


class StudyHead(_Strict):
    name: str = Field(pattern=r"^[A-Za-z0-9][A-Za-z0-9._-]*$")
    description: str = ""


class SceneTable(BaseModel):
    """A preset plus overrides (any scene key, units allowed)."""

    model_config = ConfigDict(extra="allow")
    name: str | None = None
    preset: str | None = None
    experiment: str | None = None
    uncertain: dict[str, DistributionSpec] = {}


class CorrelationSpec(_Strict):
    keys: list[str] = Field(min_length=2, max_length=2)
    spearman: float | None = Field(None, gt=-1, lt=1)
    gaussian: float | None = Field(None, gt=-1, lt=1)
    source: str = Field(min_length=1)


class SolverSpec(_Strict):
    rtol: float = Field(1e-3, gt=0, lt=1)
    tier: str = "full"
    h_min: Quantity = "1 mm"
    h_max: Quantity = "10 km"
    backend: Literal["cpu", "cuda"] = "cpu"


class DesignSpec(_Strict):
    method: Literal["mc", "lhs", "sobol", "saltelli"]
    n: int = Field(ge=1)
    seed: int = Field(ge=0)
    second_order: bool = True
    n_epistemic: int = Field(0, ge=2)


class SobolDesignSpec(_Strict):
    method: Literal["saltelli"]
    n: int = Field(ge=1)
    seed: int = Field(ge=0)
    second_order: bool = True
    n_max: int = Field(ge=1)
    stable_threshold: float = Field(0.1, gt=0, lt=1)
    stable_half_width: float = Field(0.05, gt=0, lt=1)


class _StudyFile(_Strict):
    scene: SceneTable | None = None
    scenes: list[SceneTable] | None = None
    uncertain: dict[str, DistributionSpec] = {}
    correlation: list[CorrelationSpec] = []
    solver: SolverSpec = SolverSpec()


class EnsembleHead(StudyHead):
    kind: Literal["ensemble"] = "ensemble"


class SobolHead(StudyHead):
    kind: Literal["sobol"] = "sobol"


class EnsembleFile(_StudyFile):
    """Kind ``ensemble``: a design of samples over one or several scenes."""

    study: EnsembleHead
    design: DesignSpec


class SobolFile(_StudyFile):
    """Kind ``sobol``: a saltelli design grown until its Sobol' indices are stable."""

    study: SobolHead
    design: SobolDesignSpec


class SurfaceSpec(_Strict):
    material: str
    weight: float = Field(gt=0, le=1)
    source: str = Field(min_length=1)
    friction: DistributionSpec
    #: Why this surface lies outside the model (required for an elastic material, e.g. rubber):
    #: its weight is reported as an unmodelled share, not counted as "no reaction".
    outside_model: str | None = Field(None, min_length=1)


class AlternativesSpec(_Strict):
    """What the summary shows besides the headline: another geometry, other angle scales."""

    configuration: Literal["pendulum", "vertical"] | None = None
    angle_scales: list[str] = []


class EstimatorSpec(_Strict):
    method: Literal["is", "mc"] = "is"
    target_cov: float = Field(0.1, gt=0)
    max_runs: int = Field(20000, ge=1)
    seed: int = Field(ge=0)
    epistemic_draws: int = Field(0, ge=0)
    epistemic_target_cov: float = Field(0.2, gt=0)


class HazardTable(_Strict):
    name: str = Field(pattern=r"^[A-Za-z0-9][A-Za-z0-9._-]*$")
    description: str = ""
    scene: SceneTable
    drop_height: DistributionSpec
    angle: DistributionSpec
    surface: list[SurfaceSpec] = Field(min_length=1)
    billet: dict[str, DistributionSpec] = {}
    epistemic: dict[str, DistributionSpec] = {}
    estimator: EstimatorSpec
    solver: SolverSpec = SolverSpec()
    assumptions: list[str] = []
    alternatives: AlternativesSpec | None = None


class HazardFile(_Strict):
    """Kind ``hazard``: the probability per handling accident (everything under [hazard])."""

    hazard: HazardTable


#: Kind -> model of its file.
SCHEMAS: dict[str, type[BaseModel]] = {"ensemble": EnsembleFile, "sobol": SobolFile,
                                       "hazard": HazardFile}


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


SCHEMAS["calibration"] = CalibrationFile
__all__.append("CalibrationFile")
