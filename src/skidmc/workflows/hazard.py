"""The handling hazard: probability per accident that a dropped billet reacts, on the skid model.

The kind ``hazard`` of :mod:`skidmc.workflows.registry` (a study file with a ``[hazard]``
table): ``skidmc run`` keeps every solver call in ``results/<name>/evaluations.h5``
(:class:`skidmc.ensemble.storage.EvaluationLog`: checksummed; ``--resume`` replays the kept
calls and continues, with the numbers of an uninterrupted run; a complete log of the same study
is up to date) and writes the summary beside it; ``skidmc report`` rebuilds the summary from the
log without a solver run. ``--n`` is refused (the estimator stops at its target CoV or run
budget, ``[hazard.estimator]``), and so is ``--confidence`` other than the estimator's 95 %.

:func:`run_hazard_study` runs a hazard study (:mod:`skidmc.ensemble.hazard_study`). An accident
reacts when its drop height reaches the critical height of its scene, H_drop >= H_c(x); H_c
comes from the solver through :func:`skidmc.ensemble.batch.evaluate_batch`, one batched call
per request of the estimator. The drop height integrates out exactly
(:func:`skidmc.analysis.hazard.drop_height_probability`), and so does the surface: it is a
categorical input with a handful of values, so the probability is the weighted sum over
surfaces of P(reaction | surface), each estimated on its own (stratification). Each surface
then gets its own importance-sampling proposal, centred on its own most likely initiating
combination; one proposal for all surfaces holds the category fixed at one surface and samples
the others where their reactions are not (``docs/rare-events.md``, validity).

Three layers of estimate:

* **pooled**: aleatory and epistemic inputs sampled together, P = E_theta E_x[S_drop(H_c)]:
  the probability per accident with the epistemic uncertainty averaged in, its 95 % interval
  (normal approximation of the strata's sum), the per-surface split (each surface's share sums
  to the total exactly), the design point, and the importance of each input (E[U | reaction],
  the posterior mean of each input's normal score: how many standard deviations a reaction
  pulls it from its median).
* **epistemic band**: the epistemic inputs drawn (Latin hypercube) and held fixed, P(theta_j)
  estimated for each; the 5-95 % quantiles of P(theta_j) are the band.
* **fragility curve**: P against the median drop height. The estimator's proposal on x does not
  involve the drop height, so the same H_c samples give P for any drop-height distribution,
  mean(w_i S'(H_c,i)) with the samples' importance weights w_i: the curve costs no solver run.

Solver outcomes: ``censored_above`` (no reaction up to h_max) is H_c = inf; ``censored_below``
is H_c = 0 (reacts at any height: conservative by at most P(H_drop < h_min)); ``failed`` is
counted, its reasons kept, taken as no reaction (H_c = inf) in the estimate, and bounded: the
result also states how much P would rise if every failed sample had reacted. Samples are clipped
to their distributions' 1e-9 and 1 - 1e-9 quantiles (:data:`~skidmc.ensemble.study_model.
U_TAIL`, where the study file's supports were checked), as a study's design is.
"""

from __future__ import annotations

import dataclasses
import json
import math
import time
import warnings
from collections.abc import Callable, Mapping
from pathlib import Path

import numpy as np
from scipy import stats
from scipy.stats import qmc

from skidmc.analysis.hazard import DropHeightResult, drop_height_probability
from skidmc.analysis.rare_events import CONFIDENCE, GaussianCopulaTransform
from skidmc.ensemble.hazard_study import HazardStudy, Surface, load_hazard_study
from skidmc.ensemble.study_model import (
    RATE_AT_REFERENCE,
    U_TAIL,
    Distribution,
    StudyScene,
    prefactor_from_rate,
)
from skidmc.workflows.replay import RecordedSolver

__all__ = [
    "BAND",
    "FRAGILITY_FACTORS",
    "FAST_TIER_P90_ERROR",
    "HazardResult",
    "SurfaceEstimate",
    "categorical_critical_height",
    "default_out",
    "detect",
    "load",
    "report",
    "run",
    "run_hazard_study",
]

DESCRIPTION = "the probability per handling accident that a dropped billet reacts"
RUN_OPTIONS = frozenset({"out", "resume", "force", "workers", "scheduler"})
REPORT_OPTIONS = frozenset({"out"})
REFUSED = {
    "n": "the estimator stops at [hazard.estimator] target_cov or max_runs (set those "
         "instead)",
    "chunk_size": "its solver calls are the estimator's batches",
    "confidence": f"its intervals are the estimator's {CONFIDENCE * 100:g} % ones, fixed when "
                  "it ran",
}

#: Largest impact angle sent to the solver [deg]: the scene's angle lies in (0, 90) deg, and a
#: wide half-normal (20 deg scale: 6.8e-6 beyond 90 deg) is clipped to grazing there.
ANGLE_MAX = 89.0
#: P at another angle scale is rerun (pooled, at the epistemic draws' target CoV) when the
#: reweighted estimate's CoV exceeds this, or its alternative puts more than
#: RERUN_UNCOVERED x P beyond the angles the study sampled.
RERUN_COV = 0.2
RERUN_UNCOVERED = 0.1
#: Quantiles of the epistemic band of P [1].
BAND = (0.05, 0.95)

#: Factors on the study's median drop height at which the fragility curve is given [1].
FRAGILITY_FACTORS = tuple(float(f) for f in np.geomspace(0.25, 4.0, 9))

#: The fast tier's 90th-percentile relative error on H_c against the full model
#: (results/benchmarks/fast_tier.md, 341 scenes): what a study run on the fast tier carries.
FAST_TIER_P90_ERROR = 0.045

_Z = float(stats.norm.isf((1 - CONFIDENCE) / 2))
_MAX_REASONS = 10


@dataclasses.dataclass(frozen=True)
class SurfaceEstimate:
    """The pooled estimate on one surface.

    Attributes
    ----------
    material : str
    weight : float
        Share of accidents on this surface [1].
    conditional : float
        P(reaction | this surface) [1].
    share : float
        weight x conditional: this surface's part of the probability per accident [1].
    cov : float
        Coefficient of variation of `conditional` (and of `share`) [1].
    interval : tuple of float
        95 % interval of `share` [1].
    runs : int
        Solver runs of the estimate (mode search included).
    converged : bool
        Whether the target CoV was reached within the budget.
    design_point : dict
        Input -> value [SI] at the mode of S_drop(H_c(x)) phi(u) on this surface.
    design_critical_height : float
        H_c at the design point [m].
    design_log_density : float
        ln(weight S_drop(H_c) phi(u)) at the design point, up to a constant shared by all
        surfaces: the largest is the most likely initiating combination overall.
    importance : dict
        Input -> E[U | reaction] on this surface [standard deviations].
    failed : int
        Samples the solver failed on (taken as no reaction).
    failed_bound : float
        How much `share` would rise if every failed sample had reacted [1].
    regime : str
        ``rigid``, ``yielding`` or ``outside`` (:data:`skidmc.ensemble.hazard_study.REGIMES`);
        an ``outside`` surface is not run: its conditional and share are NaN and its weight is
        the result's `unmodelled_weight`.
    regime_note : str
        The regime in words, with the hardness and its source.
    """

    material: str
    weight: float
    conditional: float
    share: float
    cov: float
    interval: tuple[float, float]
    runs: int
    converged: bool
    design_point: dict[str, float]
    design_critical_height: float
    design_log_density: float
    importance: dict[str, float]
    failed: int
    failed_bound: float
    regime: str = "rigid"
    regime_note: str = ""


@dataclasses.dataclass(frozen=True)
class HazardResult:
    """What :func:`run_hazard_study` found (also written to ``summary.json``).

    Attributes
    ----------
    name : str
        The study's name.
    probability : float
        Probability per accident of an accident on a surface the model describes *and* a
        reaction, epistemic inputs averaged in (pooled) [1]: the headline. Surfaces outside
        the model are not in it (see `unmodelled_weight`, `bounds`).
    cov : float
        Its coefficient of variation [1].
    interval : tuple of float
        Its 95 % interval (normal approximation of the sum over surfaces) [1].
    surfaces : tuple of SurfaceEstimate
        The pooled estimate per surface, in file order; the modelled surfaces' shares sum to
        `probability` (a surface outside the model has NaN conditional and share).
    epistemic_probabilities : numpy.ndarray
        P at each epistemic draw (empty without an epistemic loop) [1].
    epistemic_covs : numpy.ndarray
        CoV of each draw's P [1].
    epistemic_draws : dict
        Epistemic input -> its value at each draw [SI].
    band : tuple of float
        5 % and 95 % quantiles of `epistemic_probabilities` (NaN without draws) [1].
    design_point : dict
        Input -> value [SI] of the most likely initiating combination (with ``"surface"``, the
        material, and ``"critical_height"``, the height it reacts from [m]).
    importance : dict
        Input -> E[U | reaction] [standard deviations], share-weighted over the surfaces.
    fragility : dict
        ``median`` [m], ``probability``, ``cov``, ``band_low``, ``band_high`` [1], lists over
        :data:`FRAGILITY_FACTORS` times the study's median drop height.
    runs : dict
        Solver runs: ``pooled``, ``epistemic``, ``total``.
    failed : int
        Solver failures in all estimates (taken as no reaction).
    failure_reasons : tuple of str
        Up to 10 distinct failure reasons.
    elasticity : float
        -d ln P / d ln H_c: a relative error e in every H_c moves P by about elasticity x e [1].
    notes : tuple of str
        Caveats in words (tier, budget, failures).
    wall_time : float
        Seconds the run took [s].
    unmodelled_weight : float
        Share of accidents on surfaces outside the model [1].
    bounds : tuple of float
        What the model supports about the probability per accident over all surfaces:
        [probability, probability + unmodelled_weight] (an unmodelled accident may or may not
        react) [1].
    conditional_modelled : float
        P(reaction | a surface the model describes) = probability / (1 - unmodelled_weight) [1].
    alternative : dict
        P under ``[hazard.alternatives] configuration`` (pooled, no epistemic loop):
        ``configuration``, ``probability``, ``cov``, ``interval``, ``runs``, ``surfaces``
        (material -> P(reaction | surface)); empty when the study names none.
    angle_scales : list of dict
        P at other angle distributions from the same samples reweighted by the ratio of the
        angle densities: ``distribution``, ``probability``, ``cov``, ``band_low``,
        ``band_high``, ``uncovered`` (the alternative's probability of angles beyond the
        study's sampled range, an upper bound on what the reweighting cannot see) [1], and
        ``rerun`` (``probability``, ``cov``, ``interval``, ``runs``: a direct estimate with
        fresh samples) where the reweighting does not cover the alternative
        (:data:`RERUN_COV`, :data:`RERUN_UNCOVERED`).
    confidence : float
        Coverage of `interval` and of every sampling interval of the result [1].
    band_quantiles : tuple of float
        The quantiles of `band` and of every epistemic band of the result [1].
    design_medians : dict
        Input -> median of its distribution on the design point's surface [SI] (beside the
        design point in the summary).
    rerun_rule : dict
        When P at another angle scale was rerun: ``cov`` (:data:`RERUN_COV`), ``uncovered``
        (:data:`RERUN_UNCOVERED`), ``angle_max_deg`` (:data:`ANGLE_MAX`).
    posterior : dict
        Empty over the priors. With ``[hazard.posterior]`` (the epistemic draws taken from a
        calibration's posterior, :mod:`skidmc.workflows.hazard_posterior`): ``probability``
        (the mean of `epistemic_probabilities` over the posterior draws), ``se``, ``cov``,
        ``interval`` [1]; ``band`` (= `band`); ``prior`` (the pooled P over the priors, its
        interval, and the prior study's band where its summary is found); ``spread`` (input
        -> 5/50/95 % of the hazard's prior, the calibration's prior draws, the posterior and
        the draws taken [SI]); ``correlation`` (Spearman, of all stored draws and of those
        taken); ``unused`` (the posterior's other parameters -> why); the file, its sha256,
        the draws' indices.
    files : tuple of str
        Files written.
    """

    name: str
    probability: float
    cov: float
    interval: tuple[float, float]
    surfaces: tuple[SurfaceEstimate, ...]
    epistemic_probabilities: np.ndarray
    epistemic_covs: np.ndarray
    epistemic_draws: dict[str, np.ndarray]
    band: tuple[float, float]
    design_point: dict[str, object]
    importance: dict[str, float]
    fragility: dict[str, list[float]]
    runs: dict[str, int]
    failed: int
    failure_reasons: tuple[str, ...]
    elasticity: float
    notes: tuple[str, ...]
    wall_time: float
    unmodelled_weight: float = 0.0
    bounds: tuple[float, float] = (math.nan, math.nan)
    conditional_modelled: float = math.nan
    alternative: dict = dataclasses.field(default_factory=dict)
    angle_scales: list = dataclasses.field(default_factory=list)
    confidence: float = CONFIDENCE
    band_quantiles: tuple[float, float] = BAND
    design_medians: dict = dataclasses.field(default_factory=dict)
    rerun_rule: dict = dataclasses.field(default_factory=dict)
    files: tuple[str, ...] = ()
    posterior: dict = dataclasses.field(default_factory=dict)

    def to_dict(self) -> dict:
        """Plain JSON-ready data (arrays as lists)."""
        out = dataclasses.asdict(self)
        out["surfaces"] = [dataclasses.asdict(s) for s in self.surfaces]
        out["epistemic_probabilities"] = self.epistemic_probabilities.tolist()
        out["epistemic_covs"] = self.epistemic_covs.tolist()
        out["epistemic_draws"] = {k: np.asarray(v).tolist()
                                  for k, v in self.epistemic_draws.items()}
        if not self.posterior:  # a study over the priors: its summary.json as before
            out.pop("posterior")
        from skidmc.workflows.reporting import json_ready

        return json_ready(out)


# --------------------------------------------------------------------------------------------
# the limit state on one surface
# --------------------------------------------------------------------------------------------


class _Tally:
    """Solver runs, failures and their reasons, over every estimate of a run."""

    def __init__(self) -> None:
        self.runs = 0
        self.failed = 0
        self.censored_above = 0
        self.reasons: list[str] = []

    def add_reasons(self, reasons) -> None:
        for reason in reasons:
            if reason not in self.reasons and len(self.reasons) < _MAX_REASONS:
                self.reasons.append(str(reason))


class _CriticalHeight:
    """H_c(X) [m] on one surface: X's columns are `keys` [SI], `fixed` fills in the rest.

    Calls the solver (evaluate_batch's signature) once per call, maps its statuses to heights,
    counts runs and failures in `tally`, and remembers the failed rows (for the bound).
    """

    def __init__(self, study: HazardStudy, surface: Surface, keys: tuple[str, ...],
                 marginals: list, fixed: Mapping[str, float], solver: Callable, workers,
                 tally: _Tally) -> None:
        self.study = study
        self.surface = surface
        self.keys = keys
        self.fixed = dict(fixed)
        self.solver = solver
        self.workers = workers
        self.tally = tally
        self.low = np.array([m.ppf(U_TAIL) for m in marginals])
        self.high = np.array([m.isf(U_TAIL) for m in marginals])
        if "angle" in keys:  # a wide angle distribution's tail beyond grazing: clipped to it
            j = list(keys).index("angle")
            self.high[j] = min(self.high[j], ANGLE_MAX)
        self.failed_rows: set[bytes] = set()
        self.runs = 0
        self.failed = 0

    def columns(self, x: np.ndarray) -> dict[str, np.ndarray]:
        """Scene columns [SI] of the rows of x (the rate at T_ref turned into a prefactor)."""
        n = x.shape[0]
        values = {k: np.full(n, v, dtype=float) for k, v in self.fixed.items()}
        values.update({k: np.ascontiguousarray(x[:, j], dtype=float)
                       for j, k in enumerate(self.keys)})
        rate = values.pop(RATE_AT_REFERENCE, None)
        if rate is not None:
            t_ref = self.study.epistemic[RATE_AT_REFERENCE].reference_temperature
            t_act = values.get("kinetics.activation_temperature",
                               np.full(n, self.surface.scene.kinetics_activation_temperature))
            values["kinetics.prefactor"] = prefactor_from_rate(rate, t_act, t_ref)
        return values

    def __call__(self, x: np.ndarray) -> np.ndarray:
        x = np.clip(x, self.low, self.high)
        res = self.solver(self.columns(x), self.study.solver, base=self.surface.scene,
                          workers=self.workers)
        status = np.asarray(res.status).astype(str)
        heights = np.asarray(res.critical_height, dtype=float)
        if status.shape != (x.shape[0],) or heights.shape != (x.shape[0],):
            raise ValueError(f"solver = {self.solver!r}: returned {status.shape[0]} statuses "
                             f"and {heights.shape[0]} heights for {x.shape[0]} scenes")
        out = np.where(status == "ok", heights, np.inf)
        out[status == "censored_below"] = 0.0
        failed = ~np.isin(status, ("ok", "censored_above", "censored_below"))
        bad_height = (status == "ok") & ~(np.isfinite(heights) & (heights >= 0))
        failed |= bad_height
        out[failed] = np.inf
        n_failed = int(failed.sum())
        self.runs += x.shape[0]
        self.failed += n_failed
        self.tally.runs += x.shape[0]
        self.tally.failed += n_failed
        self.tally.censored_above += int((status == "censored_above").sum())
        if n_failed:
            reasons = np.asarray(getattr(res, "failure_reason", [""] * x.shape[0]), dtype=object)
            self.tally.add_reasons(r or "non-finite or negative height"
                                   for r in reasons[failed])
            self.failed_rows.update(row.tobytes() for row in x[failed])
        return out


def _nominal(study: HazardStudy, surface: Surface, key: str) -> float:
    sc = StudyScene(name=surface.material, scene=surface.scene,
                    uncertain={**study.billet, **study.epistemic})
    return sc.nominal(key)


def _marginals(study: HazardStudy, surface: Surface, keys: tuple[str, ...]) -> list:
    out = []
    for key in keys:
        if key == "mu":
            d = surface.friction
        elif key == "angle":
            d = study.angle
        else:
            d = study.billet.get(key) or study.epistemic[key]
        out.append(d.physical(_nominal(study, surface, key) if d.relative else 1.0))
    return out


@dataclasses.dataclass
class _Estimate:
    """One call of the structured estimator on one surface, with its limit state."""

    surface: Surface
    keys: tuple[str, ...]
    marginals: list
    result: DropHeightResult
    limit_state: _CriticalHeight
    notes: tuple[str, ...]


def _estimate(study, surface, keys, fixed, target_cov, seed, solver, workers, tally):
    marginals = _marginals(study, surface, keys)
    limit_state = _CriticalHeight(study, surface, keys, marginals, fixed, solver, workers, tally)
    # The forward-difference step of the mode search: the solver's tolerance makes ln H_c noisy
    # by ~rtol, which a step of 0.01 would turn into O(1) gradient noise; 10 rtol keeps it
    # at ~0.1 of the gradient (docs/rare-events.md).
    step = float(min(0.3, max(0.01, 10.0 * study.solver.rtol)))
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", RuntimeWarning)
        result = drop_height_probability(
            limit_state, marginals, study.drop_height.frozen, method=study.estimator.method,
            target_cov=target_cov, max_evaluations=study.estimator.max_runs, seed=seed,
            gradient_step=step)
    notes = tuple(f"{surface.material}: {w.message}" for w in caught)
    return _Estimate(surface, keys, marginals, result, limit_state, notes)


def _failed_bound(est: _Estimate) -> float:
    """P(reaction | surface) added if every failed sample of the estimate had reacted."""
    if not est.limit_state.failed_rows:
        return 0.0
    x = np.clip(est.result.samples, est.limit_state.low, est.limit_state.high)
    failed = np.array([row.tobytes() in est.limit_state.failed_rows for row in x])
    return float(np.exp(est.result.log_weights[failed]).sum() / x.shape[0])


def _design_log_density(est: _Estimate) -> float:
    u = GaussianCopulaTransform(est.marginals).to_standard(est.result.design_point)[0]
    drop = est.limit_state.study.drop_height.frozen
    with np.errstate(divide="ignore"):
        log_s = float(drop.logsf(est.result.design_critical_height))
    return math.log(est.surface.weight) + log_s - 0.5 * float(u @ u)


def _reweighted(results: list[tuple[float, DropHeightResult]], drop) -> tuple[float, float]:
    """sum_s w_s P_s and its standard error, for another drop-height distribution."""
    total, variance = 0.0, 0.0
    for weight, r in results:
        with np.errstate(divide="ignore"):
            terms = np.exp(r.log_weights + drop.logsf(r.critical_heights))
        total += weight * float(terms.mean())
        variance += weight**2 * float(terms.var(ddof=1)) / terms.size
    return total, math.sqrt(variance)


def _elasticity(results: list[tuple[float, DropHeightResult]], drop) -> float:
    """-d ln P / d ln H_c, the contribution-weighted H f(H) / S(H) of the drop height."""
    total, weighted = 0.0, 0.0
    for weight, r in results:
        h = r.critical_heights
        ok = np.isfinite(h) & (h > 0) & (r.contributions > 0)
        hazard = np.zeros_like(h)
        with np.errstate(divide="ignore", over="ignore"):
            hazard[ok] = np.exp(np.log(h[ok]) + drop.logpdf(h[ok]) - drop.logsf(h[ok]))
        weighted += weight * float(r.contributions @ hazard)
        total += weight * float(r.contributions.sum())
    return weighted / total if total > 0 else math.nan


def categorical_critical_height(study: HazardStudy, *, workers: int | None = 1,
                                solver: Callable | None = None):
    """H_c on all surfaces at once, the surface a categorical input (for the generic methods).

    The inputs are: the surface's index (a discrete marginal with the surfaces' weights), the
    friction's standard normal score (each surface maps it through its own friction
    distribution), then the other aleatory inputs. The epistemic inputs stay at the scene's
    values. This is the form the generic rare-event methods and a single-proposal structured
    estimate need; :func:`run_hazard_study` stratifies by surface instead. A surface outside
    the model keeps its category (its weight) but is never run: its rows get H_c = inf, so the
    event is the headline's "a modelled surface and a reaction".

    Parameters
    ----------
    study : HazardStudy
    workers : int or None
        As in :func:`run_hazard_study`.
    solver : callable, optional
        As in :func:`run_hazard_study`.

    Returns
    -------
    critical_height : callable
        X (n, d) -> H_c (n,) [m]; ``critical_height.runs`` and ``.failed`` count solver runs
        and failures.
    marginals : list
        Frozen scipy distributions of the d inputs.
    names : tuple of str
        ``("surface", "mu_score", *study.aleatory_keys[1:])``.
    """
    if solver is None:
        from skidmc.ensemble.batch import evaluate_batch as solver
    keys = study.aleatory_keys
    tally = _Tally()
    heights = []
    for surface in study.surfaces:
        marginals = _marginals(study, surface, keys)
        heights.append(_CriticalHeight(study, surface, keys, marginals, {}, solver, workers,
                                       tally))
    weights = np.array([s.weight for s in study.surfaces])
    category = stats.rv_discrete(values=(np.arange(weights.size), weights))()
    others = _marginals(study, study.surfaces[0], keys[1:])

    def critical_height(x: np.ndarray) -> np.ndarray:
        out = np.empty(x.shape[0])
        index = np.rint(x[:, 0]).astype(int)
        score = x[:, 1]
        for k, (surface, h) in enumerate(zip(study.surfaces, heights)):
            rows = index == k
            if not rows.any():
                continue
            if not surface.modelled:  # outside the model: not run, not a reaction of it
                out[rows] = np.inf
                continue
            z = score[rows]
            friction = _marginals(study, surface, ("mu",))[0]
            mu = np.where(z > 0, friction.isf(stats.norm.sf(z)), friction.ppf(stats.norm.cdf(z)))
            out[rows] = h(np.column_stack([mu, x[rows, 2:]]))
        critical_height.runs = tally.runs
        critical_height.failed = tally.failed
        return out

    critical_height.runs = 0
    critical_height.failed = 0
    return critical_height, [category, stats.norm(), *others], ("surface", "mu_score", *keys[1:])


# --------------------------------------------------------------------------------------------
# the run
# --------------------------------------------------------------------------------------------


def run_hazard_study(study: HazardStudy | str | Path, out_dir: str | Path | None, *,
                     workers: int | None = None, solver: Callable | None = None,
                     progress: Callable[[str], None] | None = None, scheduler=None,
                     log=None, replay_only: bool = False) -> HazardResult:
    """Probability per accident that a handling drop reacts, with its intervals and drivers.

    Parameters
    ----------
    study : HazardStudy, str or Path
        A validated study or the path of a hazard study file
        (:func:`skidmc.ensemble.hazard_study.load_hazard_study`).
    out_dir : str, Path or None
        Folder for ``summary.md``, ``summary.json``, ``fragility.csv``, ``fragility.png`` and
        ``importance.png`` (created); None writes nothing.
    workers : int or None
        Local worker processes of :func:`skidmc.ensemble.batch.evaluate_batch` (None: all
        CPUs, 1: in this process).
    solver : callable, optional
        Stand-in for :func:`~skidmc.ensemble.batch.evaluate_batch`, with its signature
        ``solver(columns, solver_options, base=scene, workers=workers)`` and a result with
        ``critical_height`` [m], ``status`` (``ok``, ``censored_above``, ``censored_below``,
        ``failed``) and ``failure_reason`` arrays; for tests and cheaper models.
    progress : callable, optional
        Called with a line of text after each estimate.
    scheduler : str, optional
        As :func:`~skidmc.ensemble.batch.evaluate_batch`'s (``local``, ``dask`` or an
        address); passed to the solver only when given.
    log : skidmc.ensemble.storage.EvaluationLog, optional
        Keeps every solver call (and replays those it holds already): a resumed run gives the
        numbers of an uninterrupted one. Completed (gathered into one file) at the end.
    replay_only : bool
        With `log`: every call must come from the log (a report); a call it lacks raises
        StorageError.

    Returns
    -------
    HazardResult

    Raises
    ------
    StudyError
        `study` is a path to an invalid study file.
    """
    started = time.perf_counter()
    if not isinstance(study, HazardStudy):
        study = load_hazard_study(study)
    if solver is None:
        from skidmc.ensemble.batch import evaluate_batch as solver
    if scheduler is not None:
        solver = _with_scheduler(solver, scheduler)
    recorder = None
    if log is not None:
        solver = recorder = RecordedSolver(solver, log, replay_only)
    say = progress or (lambda _line: None)
    options = study.estimator
    tally = _Tally()
    seeds = np.random.SeedSequence(options.seed)
    pooled_seeds, outer_seeds, design_seed = seeds.spawn(3)
    notes: list[str] = []
    post = None
    if study.posterior is not None:  # refused here, before any solver run, if unreadable
        from skidmc.workflows.hazard_posterior import read_posterior

        post = read_posterior(study)

    # pooled: aleatory and epistemic inputs together, one estimate per surface
    # (a surface outside the model is not run: its weight is reported, not taken as no reaction)
    keys = (*study.aleatory_keys, *study.epistemic_keys)
    pooled: list[_Estimate] = []
    for surface, child in zip(study.surfaces, pooled_seeds.spawn(len(study.surfaces))):
        if not surface.modelled:
            say(f"pooled {surface.material}: outside the model, not run (weight "
                f"{surface.weight:g} reported as unmodelled)")
            continue
        est = _estimate(study, surface, keys, {}, options.target_cov,
                        int(child.generate_state(1)[0]), solver, workers, tally)
        pooled.append(est)
        notes += est.notes
        say(f"pooled {surface.material}: P(reaction | surface) = {est.result.probability:.3g} "
            f"(CoV {est.result.cov:.2f}, {est.result.evaluations} runs)")
    pooled_runs = tally.runs

    surfaces = tuple(_surface_estimate(est) for est in pooled)
    listed = {s.material: s for s in surfaces}
    listed.update({s.material: _outside_estimate(s) for s in study.surfaces if not s.modelled})
    all_surfaces = tuple(listed[s.material] for s in study.surfaces)
    probability = math.fsum(s.share for s in surfaces)
    error = math.sqrt(math.fsum((s.share * s.cov) ** 2 for s in surfaces
                                if math.isfinite(s.cov)))
    if any(not math.isfinite(s.cov) and s.share > 0 for s in surfaces):
        error = math.inf
    cov = error / probability if probability > 0 else math.inf
    interval = (max(0.0, probability - _Z * error), min(1.0, probability + _Z * error))

    # epistemic loop: the epistemic inputs drawn and held, one estimate per surface per draw
    draws: dict[str, np.ndarray] = {}
    outer: list[list[tuple[float, DropHeightResult]]] = []
    outer_p, outer_cov = [], []
    if study.epistemic and options.epistemic_draws:
        draws = (dict(post.draws) if post is not None else
                 _epistemic_draws(study, options.epistemic_draws, design_seed))
        for j, child in enumerate(outer_seeds.spawn(options.epistemic_draws)):
            fixed = {k: float(v[j]) for k, v in draws.items()}
            parts, variance = [], 0.0
            for surface, grandchild in zip(study.surfaces, child.spawn(len(study.surfaces))):
                if not surface.modelled:
                    continue
                est = _estimate(study, surface, study.aleatory_keys, fixed,
                                options.epistemic_target_cov,
                                int(grandchild.generate_state(1)[0]), solver, workers, tally)
                notes += [f"draw {j}: {n}" for n in est.notes]
                parts.append((surface.weight, est.result))
                variance += (surface.weight * est.result.probability * est.result.cov) ** 2 \
                    if est.result.probability > 0 else 0.0
            p_j = math.fsum(w * r.probability for w, r in parts)
            outer.append(parts)
            outer_p.append(p_j)
            outer_cov.append(math.sqrt(variance) / p_j if p_j > 0 else math.inf)
            say(f"epistemic draw {j + 1}/{options.epistemic_draws}: P = {p_j:.3g}")
    epistemic_runs = tally.runs - pooled_runs
    outer_p_arr = np.array(outer_p)
    band = ((float(np.quantile(outer_p_arr, BAND[0])), float(np.quantile(outer_p_arr, BAND[1])))
            if outer_p else (math.nan, math.nan))

    # design point, importance, fragility, tolerance
    best = max(surfaces, key=lambda s: s.design_log_density)
    design: dict[str, object] = {"surface": best.material, **best.design_point,
                                 "critical_height": best.design_critical_height}
    importance = {k: math.fsum(s.share * s.importance[k] for s in surfaces) / probability
                  if probability > 0 else math.nan for k in keys}
    fragility = _fragility(study, pooled, outer)
    strata = [(e.surface.weight, e.result) for e in pooled]
    elasticity = _elasticity(strata, study.drop_height.frozen)
    angle_scales = _angle_scales(study, pooled, outer)
    rerun_seeds = seeds.spawn(1)[0].spawn(max(1, len(angle_scales)))
    for entry, d, child in zip(angle_scales[1:], study.angle_alternatives, rerun_seeds):
        if entry["cov"] > RERUN_COV or entry["uncovered"] > RERUN_UNCOVERED * entry[
                "probability"]:
            entry["rerun"] = _rerun_angle(study, d, keys, child, solver, workers, tally, say)
            notes += entry["rerun"].pop("notes")

    # the alternative geometry: the pooled estimate again, each surface's scene reconfigured
    alternative: dict = {}
    if study.alternative_configuration is not None:
        alternative = _alternative(study, keys, seeds.spawn(1)[0], solver, workers, tally,
                                   say)
        notes += alternative.pop("notes")
    alternative_runs = tally.runs - pooled_runs - epistemic_runs

    if study.solver.tier == "fast":
        notes.append(f"fast tier: its measured error on H_c (p90 {FAST_TIER_P90_ERROR:.1%}, "
                     "results/benchmarks/fast_tier.md) moves P by about "
                     f"{elasticity * FAST_TIER_P90_ERROR:.0%} (elasticity {elasticity:.1f})")
    for s in surfaces:
        if not s.converged:
            notes.append(f"{s.material}: run budget spent before the target CoV "
                         f"({s.cov:.2f} > {options.target_cov})")
    if tally.failed:
        notes.append(f"{tally.failed} solver runs failed (taken as no reaction); had every "
                     "failed sample of the pooled estimate reacted, P would rise by "
                     f"{sum(s.failed_bound for s in surfaces):.3g}")
    result = HazardResult(
        name=study.name, probability=probability, cov=cov, interval=interval,
        surfaces=surfaces, epistemic_probabilities=outer_p_arr,
        epistemic_covs=np.array(outer_cov), epistemic_draws=draws, band=band,
        design_point=design, importance=importance, fragility=fragility,
        runs={"pooled": pooled_runs, "epistemic": epistemic_runs,
              "alternatives": alternative_runs, "total": tally.runs},
        failed=tally.failed, failure_reasons=tuple(tally.reasons), elasticity=elasticity,
        notes=tuple(dict.fromkeys(notes)), wall_time=time.perf_counter() - started,
        unmodelled_weight=study.unmodelled_weight,
        bounds=(probability, min(1.0, probability + study.unmodelled_weight)),
        conditional_modelled=probability / (1.0 - study.unmodelled_weight),
        alternative=alternative, angle_scales=angle_scales, confidence=CONFIDENCE,
        band_quantiles=BAND, design_medians=_medians(study, design["surface"]),
        rerun_rule={"cov": RERUN_COV, "uncovered": RERUN_UNCOVERED, "angle_max_deg": ANGLE_MAX},
    )
    result = dataclasses.replace(result, surfaces=all_surfaces)
    if post is not None:
        from skidmc.workflows.hazard_posterior import posterior_summary

        result = dataclasses.replace(result, posterior=posterior_summary(
            study, post, result, _marginals(study, study.surfaces[0], post.keys)))
        say(f"posterior ({post.calibration}): P = {result.posterior['probability']:.3g}, "
            f"{BAND[0]:.0%}-{BAND[1]:.0%} band [{band[0]:.3g}, {band[1]:.3g}]")
    if recorder is not None and not replay_only:
        log.complete(recorder.calls)
    if out_dir is not None:
        from skidmc.workflows.reporting.hazard import write_hazard_report

        files = write_hazard_report(result, study, Path(out_dir))
        result = dataclasses.replace(result, files=tuple(str(f) for f in files))
    return result


def _with_scheduler(solver: Callable, scheduler) -> Callable:
    def solve(columns, options, **kwargs):
        return solver(columns, options, scheduler=scheduler, **kwargs)
    return solve


# --------------------------------------------------------------------------------------------
# the kind of study (skidmc.workflows.registry)
# --------------------------------------------------------------------------------------------


def detect(doc: dict) -> bool:
    """A ``[hazard]`` table (:func:`skidmc.ensemble.hazard_study.is_hazard_study`)."""
    return "hazard" in doc


def load(path) -> HazardStudy:
    """The validated hazard study; with ``[hazard.posterior]``, its posterior read (refused
    here if missing or lacking an input) and its file's hash made part of the study's."""
    return _posterior_identity(load_hazard_study(path))


def _posterior_identity(study: HazardStudy) -> HazardStudy:
    if study.posterior is None:
        return study
    from skidmc.workflows.hazard_posterior import read_posterior, with_posterior_sha

    return with_posterior_sha(study, read_posterior(study))


def default_out(study: HazardStudy) -> Path:
    """``results/<name>/evaluations.h5`` (the summary beside it)."""
    return Path("results") / study.name / "evaluations.h5"


def _paths(study: HazardStudy, out) -> tuple[Path, Path]:
    """(evaluation log, folder of the summary) for ``--out`` (a folder, or the log's .h5)."""
    if out is None:
        path = default_out(study)
    else:
        out = Path(out)
        path = out if out.suffix == ".h5" else out / "evaluations.h5"
    return path, path.parent


def _log(study: HazardStudy, path: Path):
    from skidmc.ensemble.storage import EvaluationLog

    return EvaluationLog(path, {"study_name": study.name, "study_sha256": study.sha256,
                                "study_text": study.text, "study_file": str(study.file)})


def _summary_sha(folder: Path) -> str:
    try:
        return json.loads((folder / "summary.json").read_text())["study"]["sha256"]
    except (OSError, ValueError, KeyError, TypeError):
        return ""


def run(study: HazardStudy, options):
    """``skidmc run`` of a hazard study: through the evaluation log (resume, up to date,
    checksums), then the summary."""
    from skidmc.ensemble.run import RunInterrupted
    from skidmc.ensemble.storage import StorageError
    from skidmc.workflows.registry import Outcome

    path, folder = _paths(study, options.out)
    log = _log(study, path)
    info = log.info()
    say = (lambda line: None) if options.quiet else (lambda line: options.log(line))
    if options.force:
        log.discard()
        info = log.info()
    if info["exists"] and info["study_sha256"] != study.sha256:
        raise StorageError(path, "holds the solver calls of another study (or another version "
                           "of this one); skidmc run --force recomputes it")
    if info["exists"] and not info["complete"] and not options.resume:
        raise StorageError(path, f"holds an unfinished run ({info['calls']} solver calls kept): "
                           "skidmc run --resume continues it, --force starts over")
    summary_ok = _summary_sha(folder) == study.sha256 and (folder / "summary.md").is_file()
    if summary_ok and not options.force and (info["complete"] or not info["exists"]):
        return Outcome(0, folder / "summary.md", () if options.quiet else (
            f"{folder / 'summary.md'}: up to date (a complete run of this study); nothing "
            "computed (--force recomputes it)",))
    from skidmc.ensemble.executors import DaskExecutor, check_scheduler

    scheduler = check_scheduler(options.scheduler)
    executor = None
    if scheduler not in (None, "local", "threads"):  # one dask client for every solver call
        executor = DaskExecutor(None if scheduler == "dask" else scheduler, options.workers)
        scheduler = executor.client
    log.start(keep=info["exists"])
    try:
        result = run_hazard_study(study, folder, workers=options.workers, solver=options.solver,
                                  scheduler=scheduler, progress=say, log=log)
    except KeyboardInterrupt:
        kept = log.info()["calls"]
        raise RunInterrupted(f"{kept} solver calls kept in {log.folder}; skidmc run "
                             f"{options.study_path or study.file} --resume continues with the "
                             "same numbers") from None
    finally:
        if executor is not None:
            executor.shutdown()
    low, high = result.interval
    lines = () if options.quiet else (
        f"skidmc run: P(reaction per accident) = {result.probability:.3g} [{low:.3g}, "
        f"{high:.3g}] ({CONFIDENCE * 100:g} %), {result.runs['total']} solver runs; "
        f"{folder / 'summary.md'}",)
    if result.posterior and not options.quiet:
        p = result.posterior
        lines += (f"skidmc run: under the posterior of {p['calibration']}: P = "
                  f"{p['probability']:.3g} [{p['interval'][0]:.3g}, {p['interval'][1]:.3g}] "
                  f"({CONFIDENCE * 100:g} %, {p['draws']} posterior draws); the line above is "
                  "over the priors",)
    return Outcome(0, folder / "summary.md", lines)


def report(target, options):
    """``skidmc report`` of a hazard study (or its evaluations.h5): the summary rebuilt from the
    kept solver calls (no solver run), else the one the run wrote."""
    from skidmc.workflows.registry import Outcome

    if isinstance(target, Path):
        from skidmc.ensemble.storage import EvaluationLog
        from skidmc.workflows.registry import study_of_result

        file = EvaluationLog(target, {}).info().get("study_file") or str(target)
        study = _posterior_identity(load_hazard_study_text(study_of_result(target), file))
        path = target
    else:
        study = target
        path = default_out(study)
    folder = Path(options.out) if options.out else path.parent
    log = _log(study, path)
    info = log.info()
    if info["complete"] and info["study_sha256"] == study.sha256:
        run_hazard_study(study, folder, log=log, replay_only=True,
                         solver=_no_solver)
    summary = folder / "summary.md"
    if not summary.is_file() or _summary_sha(folder) != study.sha256:
        return Outcome(2, None, (f"skidmc report: error: {options.source}: no result yet at "
                                 f"{path}; run it first: skidmc run {options.source}",))
    return Outcome(0, summary, (), (summary.read_text().rstrip("\n"),))


def load_hazard_study_text(text: str, file: str) -> HazardStudy:
    from skidmc.ensemble.hazard_study import parse_hazard_study

    return parse_hazard_study(text, file=file)


def _no_solver(*args, **kwargs):  # pragma: no cover - replay_only never calls it
    raise RuntimeError("a report does not run the solver")


def _surface_estimate(est: _Estimate) -> SurfaceEstimate:
    r = est.result
    w = est.surface.weight
    return SurfaceEstimate(
        material=est.surface.material, weight=w, conditional=r.probability,
        regime=est.surface.regime, regime_note=est.surface.regime_note,
        share=w * r.probability, cov=r.cov, interval=(w * r.interval[0], w * r.interval[1]),
        runs=r.evaluations, converged=r.converged,
        design_point={k: float(v) for k, v in zip(est.keys, r.design_point)},
        design_critical_height=float(r.design_critical_height),
        design_log_density=_design_log_density(est),
        importance={k: float(v) for k, v in zip(est.keys, r.posterior_mean_standard)},
        failed=est.limit_state.failed, failed_bound=w * _failed_bound(est),
    )


def _outside_estimate(surface: Surface) -> SurfaceEstimate:
    """A surface outside the model: listed with its weight, no estimate (NaN), not run."""
    return SurfaceEstimate(
        material=surface.material, weight=surface.weight, conditional=math.nan,
        share=math.nan, cov=math.nan, interval=(math.nan, math.nan), runs=0, converged=True,
        design_point={}, design_critical_height=math.nan, design_log_density=-math.inf,
        importance={}, failed=0, failed_bound=0.0, regime="outside",
        regime_note=surface.regime_note)


def _alternative(study: HazardStudy, keys, seed: np.random.SeedSequence, solver, workers,
                 tally: _Tally, say) -> dict:
    """The pooled estimate under the alternative configuration (the tilt follows it)."""
    configuration = study.alternative_configuration
    before = tally.runs
    parts, notes = [], []
    for surface, child in zip(study.surfaces, seed.spawn(len(study.surfaces))):
        if not surface.modelled:
            continue
        other = dataclasses.replace(surface, scene=surface.scene.replace(
            configuration=configuration))
        est = _estimate(study, other, keys, {}, study.estimator.target_cov,
                        int(child.generate_state(1)[0]), solver, workers, tally)
        notes += [f"{configuration}: {n}" for n in est.notes]
        parts.append((surface, est.result))
        say(f"{configuration} {surface.material}: P(reaction | surface) = "
            f"{est.result.probability:.3g} (CoV {est.result.cov:.2f})")
    p = math.fsum(s.weight * r.probability for s, r in parts)
    error = math.sqrt(math.fsum((s.weight * r.probability * r.cov) ** 2 for s, r in parts
                                if r.probability > 0))
    return {"configuration": configuration, "probability": p,
            "cov": error / p if p > 0 else math.inf,
            "interval": (max(0.0, p - _Z * error), min(1.0, p + _Z * error)),
            "runs": tally.runs - before,
            "surfaces": {s.material: r.probability for s, r in parts}, "notes": notes}


def _rerun_angle(study: HazardStudy, angle: Distribution, keys, seed, solver, workers,
                 tally: _Tally, say) -> dict:
    """The pooled estimate again with another angle distribution (fresh samples), each
    surface at the epistemic draws' target CoV (a cheaper check than the headline's)."""
    other = dataclasses.replace(study, angle=angle)
    parts, notes, before = [], [], tally.runs
    for surface, child in zip(study.surfaces, seed.spawn(len(study.surfaces))):
        if not surface.modelled:
            continue
        est = _estimate(other, surface, keys, {}, study.estimator.epistemic_target_cov,
                        int(child.generate_state(1)[0]), solver, workers, tally)
        notes += [f"angle {angle.describe()}: {n}" for n in est.notes]
        parts.append((surface, est.result))
    p = math.fsum(s.weight * r.probability for s, r in parts)
    error = math.sqrt(math.fsum((s.weight * r.probability * r.cov) ** 2 for s, r in parts
                                if r.probability > 0))
    say(f"angle {angle.describe()} rerun: P = {p:.3g}")
    return {"probability": p, "cov": error / p if p > 0 else math.inf,
            "interval": (max(0.0, p - _Z * error), min(1.0, p + _Z * error)),
            "runs": tally.runs - before, "notes": notes}


def _angle_log_ratio(study: HazardStudy, keys, samples: np.ndarray, other) -> np.ndarray:
    """ln(f_other(phi) / f_study(phi)) of each sample's angle (the density ratio that turns the
    study's samples into samples of another angle distribution)."""
    phi = samples[:, list(keys).index("angle")]
    with np.errstate(divide="ignore", invalid="ignore"):
        out = other.logpdf(phi) - study.angle.frozen.logpdf(phi)
    return np.where(np.isfinite(out), out, -np.inf)


def _angle_reweighted(study, parts, other) -> tuple[float, float]:
    """sum_s w_s P_s and its standard error under another angle distribution."""
    total, variance = 0.0, 0.0
    for weight, keys, r in parts:
        n = r.critical_heights.size
        terms = n * r.contributions * np.exp(_angle_log_ratio(study, keys, r.samples, other))
        total += weight * float(terms.mean())
        variance += weight**2 * float(terms.var(ddof=1)) / n
    return total, math.sqrt(variance)


def _angle_scales(study: HazardStudy, pooled: list[_Estimate], outer) -> list[dict]:
    """P at each ``angle_scales`` alternative (and at the study's own), from the same samples.

    Each sample's contribution is multiplied by f_alt(phi) / f(phi): unbiased where the
    sampling density covers the alternative's, and the CoV (from the reweighted terms' spread)
    says how well it does. Samples were clipped to the study's 1e-9..1-1e-9 angle quantiles
    before the solver; the alternative's probability beyond them (``uncovered``) is what the
    reweighting cannot see (an upper bound on the part of P it misses, per accident).
    """
    if not study.angle_alternatives:
        return []
    high = float(study.angle.frozen.isf(U_TAIL))
    low = float(study.angle.frozen.ppf(U_TAIL))
    strata = [(e.surface.weight, e.keys, e.result) for e in pooled]
    out = []
    for d in (study.angle, *study.angle_alternatives):
        other = d.frozen
        p, se = _angle_reweighted(study, strata, other)
        draws = [_angle_reweighted(study, [(w, study.aleatory_keys, r) for w, r in parts],
                                   other)[0] for parts in outer]
        uncovered = float(other.sf(high) + other.cdf(low))
        out.append({"distribution": d.describe(), "scale_deg": dict(d.params).get("scale"),
                    "probability": p, "cov": se / p if p > 0 else math.inf,
                    "band_low": float(np.quantile(draws, BAND[0])) if draws else math.nan,
                    "band_high": float(np.quantile(draws, BAND[1])) if draws else math.nan,
                    "uncovered": uncovered * (1.0 - study.unmodelled_weight),
                    "study": d is study.angle})
    return out


def _epistemic_draws(study: HazardStudy, n: int, seed: np.random.SeedSequence):
    """Latin-hypercube draws of the epistemic inputs [SI], each from its own distribution."""
    keys = study.epistemic_keys
    points = qmc.LatinHypercube(d=len(keys), seed=np.random.default_rng(seed)).random(n)
    points = np.clip(points, U_TAIL, 1 - U_TAIL)
    marginals = _marginals(study, study.surfaces[0], keys)  # epistemic: surface-independent
    return {k: m.ppf(points[:, j]) for j, (k, m) in enumerate(zip(keys, marginals))}


def _fragility(study: HazardStudy, pooled: list[_Estimate], outer) -> dict[str, list[float]]:
    median = float(study.drop_height.frozen.median())
    strata = [(e.surface.weight, e.result) for e in pooled]
    out: dict[str, list[float]] = {"median": [], "probability": [], "cov": [], "band_low": [],
                                   "band_high": []}
    for factor in FRAGILITY_FACTORS:
        drop = study.drop_height.scaled(factor)
        p, se = _reweighted(strata, drop)
        out["median"].append(median * factor)
        out["probability"].append(p)
        out["cov"].append(se / p if p > 0 else math.inf)
        draws = [_reweighted(parts, drop)[0] for parts in outer]
        out["band_low"].append(float(np.quantile(draws, BAND[0])) if draws else math.nan)
        out["band_high"].append(float(np.quantile(draws, BAND[1])) if draws else math.nan)
    return out


def _medians(study: HazardStudy, material: str) -> dict[str, float]:
    surface = next(s for s in study.surfaces if s.material == material)
    keys = (*study.aleatory_keys, *study.epistemic_keys)
    return {k: float(m.median()) for k, m in zip(keys, _marginals(study, surface, keys))}
