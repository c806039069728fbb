"""Probability that a drop ends in a reaction, with the drop height integrated out exactly.

An accident with inputs x (billet, surface, friction, ...) and drop height H_drop reacts when
H_drop >= H_c(x), the critical height of the skid model. H_c does not depend on H_drop, so
conditioning on x gives the event's probability in closed form through the survival function
S_drop of the drop-height distribution:

    P = E_x[ P(H_drop >= H_c(x) | x) ] = E_x[ S_drop(H_c(x)) ]

(conditional Monte Carlo). Each critical-height evaluation contributes a probability rather than a
0/1 outcome, which removes the drop-height part of the variance altogether. Method ``"is"`` adds
importance sampling on x: a unit normal proposal in standard normal space centred on the mode of
S_drop(H_c(x(u))) phi(u), the most likely initiating combination. See ``docs/rare-events.md``.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Callable, Hashable, Sequence
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
from scipy import optimize, stats

from skidmc.analysis.checks import bad as _bad
from skidmc.analysis.checks import check_positive_float as _check_positive_float
from skidmc.analysis.checks import check_positive_int as _check_positive_int
from skidmc.analysis.checks import check_seed as _check_seed
from skidmc.analysis.rare_events import GaussianCopulaTransform, _normal_interval

__all__ = ["DropHeightResult", "Share", "drop_height_probability"]

METHODS = ("is", "mc")

# log S_drop below this counts as "no event" in the mode search: S = exp(-700) is below any
# probability of interest and keeps the objective finite where H_c is infinite.
_LOG_SURVIVAL_FLOOR = -700.0


class Share(NamedTuple):
    """Part of the event probability carried by one category of samples."""

    probability: float
    cov: float


@dataclass(frozen=True)
class DropHeightResult:
    """Estimate of P[H_drop >= H_c(X)] with its uncertainty, cost and per-sample detail.

    Attributes
    ----------
    probability : float
        Point estimate of the event probability.
    cov : float
        Estimated coefficient of variation of `probability` (inf with no positive contribution).
    evaluations : int
        Number of critical heights computed (rows passed to `critical_height`), the mode search
        included.
    interval : tuple of float
        (low, high) at :data:`skidmc.analysis.rare_events.CONFIDENCE` (95 %), normal
        approximation of the sample mean, clipped to [0, 1].
    method : str
        ``"is"`` or ``"mc"``.
    converged : bool
        True when the target CoV was reached within the budget.
    stop_reason : str
        Why the estimator stopped, in words.
    history : tuple of dict
        Running estimate, CoV and cost after each batch.
    design_point : (d,) numpy.ndarray
        Inputs [marginal units] at the mode of S_drop(H_c(x(u))) phi(u): the most likely
        combination that initiates a reaction ("is"), or the sample with the largest such value
        ("mc").
    design_critical_height : float
        H_c at `design_point` [drop-height units].
    samples : (n, d) numpy.ndarray
        Inputs of the samples behind the estimate [marginal units].
    standard_samples : (n, d) numpy.ndarray
        The same samples in standard normal space.
    critical_heights : (n,) numpy.ndarray
        H_c of each sample [drop-height units].
    contributions : (n,) numpy.ndarray
        Each sample's share of `probability` (S_drop(H_c) times its importance weight over n);
        they sum to `probability`.
    posterior_mean : (d,) numpy.ndarray
        E[X | reaction], the contribution-weighted mean of the samples [marginal units].
    posterior_mean_standard : (d,) numpy.ndarray
        E[U | reaction] in standard normal space: how far (in standard deviations) a reaction
        pulls each input from its median; a measure of input importance.
    warnings : tuple of str
        Caveats (mode search trouble); each is also issued as a RuntimeWarning.
    log_weights : (n,) numpy.ndarray
        Natural log of each sample's importance weight phi(u) / q(u) (0 for ``"mc"``). With
        them the same samples give the probability for any other drop-height distribution,
        ``mean(exp(log_weights + other.logsf(critical_heights)))``: the proposal on x does not
        depend on the drop height.
    """

    probability: float
    cov: float
    evaluations: int
    interval: tuple[float, float]
    method: str
    converged: bool
    stop_reason: str
    history: tuple[dict, ...]
    design_point: np.ndarray
    design_critical_height: float
    samples: np.ndarray
    standard_samples: np.ndarray
    critical_heights: np.ndarray
    contributions: np.ndarray
    posterior_mean: np.ndarray
    posterior_mean_standard: np.ndarray
    warnings: tuple[str, ...] = ()
    log_weights: np.ndarray | None = None

    def probability_by(self, labels) -> dict[Hashable, Share]:
        """Split the probability by a label of each sample (e.g. a categorical input).

        Parameters
        ----------
        labels : (n,) array_like
            One label per sample, e.g. ``result.samples[:, k]`` for a categorical input k.

        Returns
        -------
        dict
            label -> :class:`Share` (probability carried by the samples with that label, and its
            CoV); the probabilities sum to :attr:`probability`.
        """
        labels = np.asarray(labels)
        n = self.contributions.size
        if labels.shape != (n,):
            raise _bad("labels", labels, f"expected one label per sample, shape ({n},)")
        terms = self.contributions * n  # each sample's unbiased estimate of the total
        shares = {}
        for label in np.unique(labels):
            part = np.where(labels == label, terms, 0.0)
            probability = float(part.mean())
            error = float(part.std(ddof=1) / math.sqrt(n)) if n > 1 else math.inf
            key = label.item() if hasattr(label, "item") else label
            shares[key] = Share(probability, error / probability if probability > 0 else math.inf)
        return shares


class _CountedCriticalHeight:
    """H_c on standard normal rows, with its checks, its count and log S_drop."""

    def __init__(self, critical_height, transform, drop_height):
        if not callable(critical_height):
            raise _bad("critical_height", critical_height, "expected a callable H_c(X) -> (n,)")
        self.critical_height = critical_height
        self.transform = transform
        self.drop_height = drop_height
        self.evaluations = 0

    def __call__(self, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Physical inputs and critical heights of the rows of u."""
        x = self.transform.to_physical(u)
        heights = np.asarray(self.critical_height(x), dtype=float)
        self.evaluations += u.shape[0]
        if heights.shape != (u.shape[0],):
            raise _bad(
                "critical_height",
                self.critical_height,
                f"returned shape {heights.shape} for X of shape {x.shape}; "
                f"expected ({u.shape[0]},)",
            )
        bad = np.isnan(heights) | (heights < 0)
        if bad.any():
            row = int(np.flatnonzero(bad)[0])
            raise _bad(
                "critical_height",
                self.critical_height,
                f"returned {heights[row]} (expected a height >= 0 or inf) at X[{row}] = "
                f"{x[row].tolist()}",
            )
        return x, heights

    def log_survival(self, heights: np.ndarray) -> np.ndarray:
        """log S_drop(H_c), from scipy's logsf (accurate far into the tail)."""
        with np.errstate(divide="ignore"):
            return np.asarray(self.drop_height.logsf(heights), dtype=float)


def _mode(model: _CountedCriticalHeight, start: np.ndarray, gradient_step: float):
    """Maximiser of log S_drop(H_c(x(u))) - |u|^2 / 2 by BFGS.

    The forward-difference gradient's rows go to H_c in one call, which also gives the value
    (``jac=True``), so each BFGS function request is one batched call. Coordinates of discrete
    (categorical) marginals stay at `start`: the objective is a step function of them, which
    gives BFGS no slope to follow, and any fixed value keeps the importance sampling valid.
    """
    free = np.array([not isinstance(m.dist, stats.rv_discrete) for m in model.transform.marginals])
    steps = gradient_step * np.eye(start.shape[0])[free]
    heights_seen: dict[bytes, float] = {}

    def full(v):
        u = start.copy()
        u[free] = v
        return u

    def negative_log_density(v):
        u = full(v)
        rows = np.vstack([u, u + steps])
        _, heights = model(rows)
        heights_seen[v.tobytes()] = float(heights[0])
        log_s = np.maximum(model.log_survival(heights), _LOG_SURVIVAL_FLOOR)
        values = -(log_s - 0.5 * np.einsum("ij,ij->i", rows, rows))
        return values[0], (values[1:] - values[0]) / gradient_step

    if not free.any():
        _, heights = model(start[np.newaxis])
        return start, float(heights[0]), True, "only discrete inputs: no search"
    # gtol = the step: a forward difference is biased by ~ step/2 times the curvature (about 1
    # here), so a tighter tolerance chases that bias; the proposal only needs the mode to a
    # fraction of a standard deviation.
    result = optimize.minimize(
        negative_log_density,
        start[free],
        jac=True,
        method="BFGS",
        options={"gtol": gradient_step, "maxiter": 200},
    )
    # BFGS's "precision loss" stop near the optimum is harmless when the gradient is small.
    converged = bool(result.success) or bool(
        np.all(np.isfinite(result.jac)) and np.max(np.abs(result.jac)) <= 10 * gradient_step
    )
    best = np.asarray(result.x, dtype=float)
    height = heights_seen.get(best.tobytes())
    if height is None:  # BFGS returns an evaluated point; this is only a safety net
        height = float(model(full(best)[np.newaxis])[1][0])
    return full(best), height, converged, str(result.message)


def drop_height_probability(
    critical_height: Callable[[np.ndarray], np.ndarray],
    marginals: Sequence,
    drop_height,
    correlation=None,
    method: str = "is",
    target_cov: float = 0.1,
    max_evaluations: int = 20_000,
    seed: int = 0,
    *,
    batch_size: int | None = None,
    gradient_step: float = 1e-2,
    pilot_samples: int | None = None,
) -> DropHeightResult:
    """Probability that a drop reacts, P[H_drop >= H_c(X)] = E[S_drop(H_c(X))].

    Parameters
    ----------
    critical_height : callable
        Vectorised ``H_c(X)``: for X an (n, d) array of inputs [marginal units] returns n
        critical heights [drop-height units], >= 0; ``np.inf`` means no reaction at any height.
    marginals : sequence of frozen scipy.stats distributions
        Distribution of each input of H_c (continuous, or discrete for a categorical input).
    drop_height : frozen scipy.stats distribution
        Distribution of the drop height [length, same unit as H_c], e.g. ``scipy.stats.lognorm``.
    correlation : (d, d) array_like, optional
        Gaussian-copula correlation of the inputs; None: independent.
    method : {"is", "mc"}
        ``"mc"``: conditional Monte Carlo on x. ``"is"``: the same with importance sampling on
        x around the mode of S_drop(H_c(x(u))) phi(u).
    target_cov : float
        Stop once the estimated coefficient of variation is at most this (> 0).
    max_evaluations : int
        Budget of critical heights (>= 1), the mode search included.
    seed : int
        Seed (>= 0) of :func:`numpy.random.default_rng`.
    batch_size : int, optional
        Critical heights per batch (default 200 for "is", 2000 for "mc").
    gradient_step : float
        Forward-difference step of the mode search [standard normal units]; raise it (to ~0.1)
        when H_c comes from a solver whose tolerance makes smaller differences noise.
    pilot_samples : int, optional
        Standard normal samples tried as starting points of the mode search when the median
        inputs give no reaction at any height (S_drop(H_c) = 0); default 10 d.

    Returns
    -------
    DropHeightResult

    Raises
    ------
    ValueError
        Bad marginals, drop_height, correlation, method, target_cov, budget, seed or options,
        or critical_height returned the wrong shape, NaN or a negative height.
    """
    transform = GaussianCopulaTransform(marginals, correlation)
    family = getattr(drop_height, "dist", None)
    if not isinstance(family, stats.rv_continuous):
        raise _bad(
            "drop_height",
            drop_height,
            "expected a frozen continuous scipy.stats distribution, e.g. scipy.stats.lognorm(0.5)",
        )
    if method not in METHODS:
        raise _bad("method", method, f"expected one of {', '.join(METHODS)}")
    target_cov = _check_positive_float("target_cov", target_cov)
    max_evaluations = _check_positive_int("max_evaluations", max_evaluations)
    rng = np.random.default_rng(_check_seed(seed))
    default_batch = 200 if method == "is" else 2000
    batch = _check_positive_int(
        "batch_size", default_batch if batch_size is None else batch_size, 2
    )
    gradient_step = _check_positive_float("gradient_step", gradient_step)
    d = transform.dimension
    pilot = _check_positive_int(
        "pilot_samples", 10 * d if pilot_samples is None else pilot_samples, 1
    )
    model = _CountedCriticalHeight(critical_height, transform, drop_height)
    notes = []

    centre = np.zeros(d)
    if method == "is":
        start = np.zeros(d)
        _, origin_height = model(start[np.newaxis])
        if model.log_survival(origin_height)[0] <= _LOG_SURVIVAL_FLOOR:
            # No reaction at any plausible height at the median inputs: start from the best of
            # a few random inputs instead (a flat objective gives BFGS nothing to follow).
            trial = rng.standard_normal((pilot, d))
            _, heights = model(trial)
            score = model.log_survival(heights) - 0.5 * np.einsum("ij,ij->i", trial, trial)
            start = trial[int(np.argmax(score))]
        centre, centre_height, ok, message = _mode(model, start, gradient_step)
        if not ok:
            notes.append(
                f"mode search stopped early ({message}); importance sampling around its last "
                "point (unbiased still, the CoV shows the cost)"
            )
        if not np.all(np.isfinite(centre)):
            notes.append("mode search diverged; falling back to conditional Monte Carlo")
            centre, centre_height = np.zeros(d), float(origin_height[0])
    search_cost = model.evaluations

    all_u, all_x, all_heights, all_terms, all_log_weights = [], [], [], [], []
    history = []
    converged = False
    while model.evaluations < max_evaluations:
        size = min(batch, max_evaluations - model.evaluations)
        u = centre + rng.standard_normal((size, d))
        x, heights = model(u)
        # log phi(u) - log phi(u - centre): the weight of the shifted unit normal proposal.
        log_weight = -u @ centre + 0.5 * centre @ centre
        terms = np.exp(model.log_survival(heights) + log_weight)
        all_u.append(u)
        all_x.append(x)
        all_heights.append(heights)
        all_terms.append(terms)
        all_log_weights.append(log_weight)
        values = np.concatenate(all_terms)
        probability = float(values.mean())
        error = float(values.std(ddof=1) / math.sqrt(values.size)) if values.size > 1 else math.inf
        cov = error / probability if probability > 0 else math.inf
        history.append(
            {
                "batch": len(history),
                "evaluations": model.evaluations,
                "samples": int(values.size),
                "probability": probability,
                "cov": cov,
            }
        )
        if cov <= target_cov:
            converged = True
            break
    if not all_terms:
        raise _bad(
            "max_evaluations",
            max_evaluations,
            f"the mode search used {search_cost} evaluations, none left for sampling",
        )
    u = np.concatenate(all_u)
    x = np.concatenate(all_x)
    heights = np.concatenate(all_heights)
    contributions = values / values.size
    total = float(contributions.sum())
    if total > 0:
        posterior_mean = contributions @ x / total
        posterior_mean_standard = contributions @ u / total
    else:
        posterior_mean = np.full(d, np.nan)
        posterior_mean_standard = np.full(d, np.nan)
    if method == "is":
        design_u, design_height = centre, centre_height
    else:
        score = model.log_survival(heights) - 0.5 * np.einsum("ij,ij->i", u, u)
        best = int(np.argmax(score))
        design_u, design_height = u[best], float(heights[best])
    if converged:
        reason = f"target CoV {target_cov} reached"
    else:
        reason = f"budget of {max_evaluations} evaluations spent"
    for note in notes:
        warnings.warn(note, RuntimeWarning, stacklevel=2)
    return DropHeightResult(
        probability=probability,
        cov=cov,
        evaluations=model.evaluations,
        interval=_normal_interval(probability, error),
        method=method,
        converged=converged,
        stop_reason=reason,
        history=tuple(history),
        design_point=transform.to_physical(design_u)[0],
        design_critical_height=design_height,
        samples=x,
        standard_samples=u,
        critical_heights=heights,
        contributions=contributions,
        posterior_mean=posterior_mean,
        posterior_mean_standard=posterior_mean_standard,
        warnings=tuple(notes),
        log_weights=np.concatenate(all_log_weights),
    )
