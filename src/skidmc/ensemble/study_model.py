"""The data model of a study: what the study loaders return.

Frozen dataclasses: :class:`Study` (:func:`skidmc.ensemble.study.load_study`), its
:class:`StudyScene` s, :class:`Distribution` s, :class:`Correlation` s, :class:`DesignSpec` and
:class:`SolverOptions`; :class:`HazardStudy` (:func:`skidmc.ensemble.hazard_study.
load_hazard_study`) with its :class:`Surface` s and :class:`EstimatorOptions`; and the errors
(:class:`StudyError`). The file formats, and the validation that builds these, are the
pydantic models of :mod:`skidmc.ensemble.study_schema`.
"""

from __future__ import annotations

import dataclasses
import math
import numbers
from collections.abc import Mapping
from functools import cached_property

import numpy as np
import scipy.stats

from skidmc.errors import SkidmcError
from skidmc.scene import NUMERIC_KEYS, Scene

__all__ = [
    "BILLET_KEYS",
    "DESIGN_METHODS",
    "ESTIMATOR_METHODS",
    "EstimatorOptions",
    "HazardStudy",
    "REGIMES",
    "Surface",
    "KINDS",
    "EXTRA_KEYS",
    "RATE_AT_REFERENCE",
    "Correlation",
    "DesignSpec",
    "Distribution",
    "SolverOptions",
    "Study",
    "StudyError",
    "StudyScene",
    "STUDY_RANGES",
    "aleatory_factor_column",
    "check_n",
    "prefactor_from_rate",
]

#: How an uncertain input is drawn: varying from drop to drop, or fixed but unknown.
KINDS: tuple[str, ...] = ("aleatory", "epistemic")

#: Design methods (:mod:`skidmc.ensemble.sampling`).
DESIGN_METHODS: tuple[str, ...] = ("mc", "lhs", "sobol", "saltelli")

#: Pseudo-key sampled instead of ``kinetics.prefactor``: the Arrhenius rate at a reference
#: temperature, k_ref = Z exp(-E/R / T_ref) [1/s]. Fitted (E, Z) pairs of one material fall
#: along ln Z ~ E / (R T_iso) (the kinetic compensation effect; for HMX: Brill, Gongwer &
#: Williams, J. Phys. Chem. 98 (1994) 12242), so the rate near the measured temperatures is
#: far better known than Z; docs/inputs.md, "Kinetics".
RATE_AT_REFERENCE = "kinetics.rate_at_reference"


def prefactor_from_rate(rate, activation_temperature, reference_temperature):
    """Arrhenius prefactor Z = k_ref exp(E/R / T_ref) [1/s] of the rate ``rate`` = k_ref [1/s]
    at ``reference_temperature`` T_ref [K], for ``activation_temperature`` E/R [K] (floats or
    arrays; inf where it overflows)."""
    return rate * np.exp(activation_temperature / reference_temperature)


#: Sampled keys that are not scene keys: key -> (SI unit, long name).
EXTRA_KEYS: dict[str, tuple[str, str]] = {
    RATE_AT_REFERENCE: (
        "1/s",
        "Arrhenius rate constant at the reference temperature, Z exp(-E/R / T_ref)",
    ),
}

#: Tail quantile at which distributions are checked against the physical range, and at which
#: the sampling truncates the design (so that the check covers every sample) [1].
U_TAIL = 1e-9

#: Suffix of the design column of an aleatory factor on an epistemic input (a key uncertain at
#: two levels, :func:`aleatory_factor_column`).
FACTOR_SUFFIX = ":aleatory_factor"


def aleatory_factor_column(key: str) -> str:
    """Name of the design column of the aleatory factor on `key` (``"mu:aleatory_factor"``):
    the drop-to-drop scatter of an input whose level is itself epistemic."""
    return key + FACTOR_SUFFIX


#: Study-level physical ranges stricter than the scene layer's: a friction coefficient that a
# distribution may reach (the scene accepts up to 5 to catch typos, not as physics).
STUDY_RANGES: dict[str, tuple[float, float]] = {"mu": (0.0, 1.0)}

class StudyError(SkidmcError, ValueError):
    """A study file that cannot be run: the message names the file, the key and the value.

    Parameters
    ----------
    file : str
        The study file (or ``"<string>"`` for text parsed directly).
    key : str
        Where in the file, TOML-style (``uncertain."he.conductivity".scale``).
    value : object
        The value as written in the file; ``None`` when the key is missing.
    reason : str
        What is wrong, phrased as the rule it breaks, with a hint where one helps.

    Attributes
    ----------
    file, key, value, reason
        As given; ``str(err)`` is ``"{file}: {key} = {value!r}: {reason}"``.
    """

    def __init__(self, file: str, key: str, value: object, reason: str) -> None:
        self.file = str(file)
        self.key = key
        self.value = value
        self.reason = reason
        shown = f"{key}" if value is None else f"{key} = {value!r}"
        super().__init__(f"{self.file}: {shown}: {reason}")

    def __reduce__(self):
        return (type(self), (self.file, self.key, self.value, self.reason))


# --- the parts of a study -----------------------------------------------------------------------


@dataclasses.dataclass(frozen=True)
class Distribution:
    """The distribution of one uncertain input.

    Attributes
    ----------
    key : str
        Scene key, or :data:`RATE_AT_REFERENCE`.
    name : str
        Name of a :mod:`scipy.stats` continuous distribution (``"truncnorm"``).
    params : tuple of (str, float)
        scipy's parameters (shapes, ``loc``, ``scale``) in the key's SI unit, or of the factor
        when `relative`.
    source : str
        Where the width comes from.
    relative : bool
        The distribution is of a dimensionless factor on the scene's nominal value.
    reference_temperature : float or None
        T_ref for :data:`RATE_AT_REFERENCE` [K].
    kind : {"aleatory", "epistemic"}
        Varies from drop to drop (friction of the spot hit, flow stress lot, angle, temperature)
        or is fixed but unknown (kinetics, material properties).
    """

    key: str
    name: str
    params: tuple[tuple[str, float], ...]
    source: str
    relative: bool = False
    reference_temperature: float | None = None
    kind: str = "aleatory"

    @cached_property
    def frozen(self):
        """The frozen :mod:`scipy.stats` distribution."""
        return getattr(scipy.stats, self.name)(**dict(self.params))

    def ppf(self, u: np.ndarray, nominal: float = 1.0) -> np.ndarray:
        """Values at the quantiles `u`; times `nominal` when relative [SI unit of the key]."""
        x = self.frozen.ppf(u)
        return x * nominal if self.relative else x

    def scaled(self, factor: float):
        """The frozen distribution of ``factor`` x X [SI]: its loc and scale times `factor` (a
        relative distribution on its nominal value, a drop height with its median moved)."""
        params = dict(self.params)
        params["loc"] = params.get("loc", 0.0) * factor
        params["scale"] = params.get("scale", 1.0) * factor
        return getattr(scipy.stats, self.name)(**params)

    def physical(self, nominal: float):
        """The frozen distribution of the input's values [SI]: a relative one scaled by
        `nominal` (the scene's value), an absolute one as it is."""
        return self.scaled(nominal) if self.relative else self.frozen

    def describe(self) -> str:
        """``"lognorm(s=0.2) x nominal"``-style one-liner."""
        args = ", ".join(f"{k}={v:.6g}" for k, v in self.params)
        return f"{self.name}({args})" + (" x nominal" if self.relative else "")


@dataclasses.dataclass(frozen=True)
class Correlation:
    """A Gaussian-copula correlation between two uncertain inputs.

    Attributes
    ----------
    keys : tuple of str
        The two keys.
    rho : float
        Correlation of the copula's normal scores [1].
    spearman : float or None
        The rank correlation it was given as, if so [1]; rho = 2 sin(pi rs / 6).
    source : str
        Where it comes from.
    """

    keys: tuple[str, str]
    rho: float
    spearman: float | None
    source: str


@dataclasses.dataclass(frozen=True)
class DesignSpec:
    """How the samples are drawn (:mod:`skidmc.ensemble.sampling`).

    Attributes
    ----------
    method : {"mc", "lhs", "sobol", "saltelli"}
    n : int
        Number of samples; for ``saltelli`` the base sample count N.
    seed : int
        Seed of :class:`numpy.random.SeedSequence` (>= 0).
    second_order : bool
        ``saltelli`` only: rows for second-order indices too.
    n_epistemic : int
        Epistemic draws of a nested design (0: not nested); each gets `n` aleatory samples.
    n_max : int
        ``saltelli`` only: grow N (doubling, reusing the rows computed) up to this until the
        indices are stable (0: run N only); see :mod:`skidmc.workflows.sobol`.
    stable_threshold, stable_half_width : float
        The stability rule: every index whose interval reaches above the threshold has an
        interval half-width of at most `stable_half_width` [1].
    """

    method: str
    n: int
    seed: int
    second_order: bool = True
    n_epistemic: int = 0
    n_max: int = 0
    stable_threshold: float = 0.1
    stable_half_width: float = 0.05


@dataclasses.dataclass(frozen=True)
class SolverOptions:
    """Arguments of :func:`skidmc.solver.critical_height` for every sample.

    Attributes
    ----------
    rtol : float
        Relative tolerance on the critical height [1].
    tier : str
        Model fidelity tier.
    h_min, h_max : float
        Search bounds [m]; results beyond them are censored.
    backend : str
        Where the full tier runs: "cpu" (default) or "cuda" (the GPU backend,
        :mod:`skidmc.solver.cuda`; a batch at a time, in the process that evaluates it).
    """

    rtol: float = 1e-3
    tier: str = "full"
    h_min: float = 1e-3
    h_max: float = 1e4
    backend: str = "cpu"

    def as_kwargs(self) -> dict:
        """Keyword arguments for :func:`skidmc.solver.critical_height` (and ``backend`` when it
        is not the default "cpu", which :func:`skidmc.evaluate_batch` takes)."""
        kwargs = dataclasses.asdict(self)
        if kwargs["backend"] == "cpu":
            del kwargs["backend"]
        return kwargs


@dataclasses.dataclass(frozen=True)
class StudyScene:
    """One scene of a study with the distributions that apply to it.

    Attributes
    ----------
    name : str
        Scene name (the preset name for a single ``[scene]`` without one).
    scene : Scene
        The nominal scene.
    uncertain : dict
        Key -> :class:`Distribution` (study-wide ones, overridden by the scene's own of the same
        kind).
    experiment : str or None
        The report's experiment this scene is compared with (``skidmc report``).
    factors : dict
        Key -> aleatory :class:`Distribution` (``relative``) of a factor on the key's value: the
        key is uncertain at two levels, its sampled value is (its entry in `uncertain`, or the
        nominal value where it has none) times this factor. Design column
        :func:`aleatory_factor_column` of the key.
    """

    name: str
    scene: Scene
    uncertain: Mapping[str, Distribution]
    experiment: str | None = None
    factors: Mapping[str, Distribution] = dataclasses.field(default_factory=dict)

    def tails(self, key: str) -> np.ndarray:
        """The extreme values of `key` the sampling can reach in this scene [SI unit of the key]:
        its distribution at the quantiles :data:`U_TAIL` and 1 - U_TAIL, times its aleatory
        factor's at the same quantiles where it has one (the four products: a product of two
        monotone quantile functions is extreme at the corners)."""
        q = np.array([U_TAIL, 1.0 - U_TAIL])
        nominal = self.nominal(key)
        level = (self.uncertain[key].ppf(q, nominal) if key in self.uncertain
                 else np.array([nominal]))
        if key not in self.factors:
            return level
        return np.outer(level, self.factors[key].frozen.ppf(q)).ravel()

    def nominal(self, key: str) -> float:
        """The scene's value of `key` [SI]; for :data:`RATE_AT_REFERENCE`, k(T_ref) of the scene."""
        values = self.scene.as_dict()
        if key == RATE_AT_REFERENCE:
            dist = self.uncertain.get(key) or self.factors[key]
            t_ref = dist.reference_temperature
            return values["kinetics.prefactor"] * math.exp(
                -values["kinetics.activation_temperature"] / t_ref
            )
        return values[key]


@dataclasses.dataclass(frozen=True)
class Study:
    """A validated study (build with :func:`load_study` or :func:`parse_study`).

    Attributes
    ----------
    name, description : str
    scenes : tuple of StudyScene
    scene_dimension : bool
        True for ``[[scenes]]`` (storage gets a ``scene`` dimension), False for ``[scene]``.
    keys : tuple of str
        The uncertain keys in design-column order (all scenes together).
    correlations : tuple of Correlation
    design : DesignSpec
    solver : SolverOptions
    text : str
        The study file's full text.
    sha256 : str
        Hex digest of `text` (UTF-8), identifies the study in result files.
    file : str
        Where it was read from (``"<string>"`` if parsed from text).
    """

    name: str
    description: str
    scenes: tuple[StudyScene, ...]
    scene_dimension: bool
    keys: tuple[str, ...]
    correlations: tuple[Correlation, ...]
    design: DesignSpec
    solver: SolverOptions
    text: str
    sha256: str
    file: str

    @property
    def scene_names(self) -> tuple[str, ...]:
        """Names of the scenes, in order."""
        return tuple(s.name for s in self.scenes)

    @property
    def n_rows(self) -> int:
        """Number of samples per scene in the design (``saltelli``: N (2d + 2) or N (d + 2))."""
        d = self.design
        if d.n_epistemic:
            return d.n_epistemic * d.n
        if d.method == "saltelli":
            return d.n * (2 * len(self.keys) + 2 if d.second_order else len(self.keys) + 2)
        return d.n

    def kind(self, key: str) -> str:
        """``"aleatory"`` or ``"epistemic"``: how the design column `key` is drawn (an aleatory
        factor's column, :func:`aleatory_factor_column`, is aleatory)."""
        if key.endswith(FACTOR_SUFFIX):
            return "aleatory"
        for sc in self.scenes:
            if key in sc.uncertain:
                return sc.uncertain[key].kind
        raise KeyError(key)

    @property
    def nested(self) -> bool:
        """Whether the design nests aleatory draws inside epistemic ones."""
        return bool(self.design.n_epistemic)

    def with_n(self, n: int) -> Study:
        """The same study with another sample count, validated as if written in the file.

        Raises
        ------
        StudyError
            `n` is not a valid count for the design (e.g. not a power of 2 for ``sobol``).
        """
        check_n(self.file, self.design.method, n, key="n (--n)")
        return dataclasses.replace(self, design=dataclasses.replace(self.design, n=int(n)))


def check_n(file: str, method: str, n: object, key: str) -> None:
    if n is None:
        raise StudyError(file, key, None, "missing: the number of samples")
    if isinstance(n, bool) or not isinstance(n, numbers.Integral) or n < 1:
        raise StudyError(file, key, n, "expected an integer >= 1")
    if method in ("sobol", "saltelli") and n & (n - 1):
        raise StudyError(file, key, n, f"the {method} design needs a power of 2 (keeps the "
                         f"Sobol sequence balanced): e.g. {1 << (int(n) - 1).bit_length()}")


# --- the hazard kind ([hazard] files, skidmc.ensemble.hazard_study) ---------------------------

#: Keys a ``[hazard.billet.KEY]`` table may sample (aleatory: lot to lot, billet to billet).
BILLET_KEYS: tuple[str, ...] = (
    "flow_stress", "billet_mass", "billet_diameter", "initial_temperature",
    *(k for k in NUMERIC_KEYS if k.startswith("he.")),
)

#: Estimators of :func:`skidmc.analysis.hazard.drop_height_probability`.
ESTIMATOR_METHODS: tuple[str, ...] = ("is", "mc")

#: Regimes of a surface: the report's rigid target, a target that yields under the billet
#: (contact pressure min(sigma, p_t), docs/model.md "Targets softer than the billet"), or one
#: the model does not describe (its weight is an unmodelled share of the accidents).
REGIMES: tuple[str, ...] = ("rigid", "yielding", "outside")

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
    posterior : str or None
        ``[hazard.posterior] calibration``, as written: a calibration study file or a
        posterior.nc (relative to `file`) whose stored draws replace the epistemic loop's
        Latin-hypercube draws (:mod:`skidmc.workflows.hazard_posterior`); None: the priors.
    prior_study : str or None
        ``[hazard.posterior] prior_study``, as written: the same study over the priors, whose
        summary gives the prior's epistemic band beside the posterior's.
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
    posterior: str | None = None
    prior_study: str | None = None

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
