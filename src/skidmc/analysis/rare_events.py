"""Probability of a rare event ``g(X) <= 0``: plain Monte Carlo, subset simulation, FORM + IS.

Every method works in the standard normal space U of the inputs: a row u of independent standard
normals becomes the physical inputs x through the Gaussian copula of
:class:`GaussianCopulaTransform` (correlated normal scores z = L u with L the Cholesky factor of
the copula correlation, then each marginal's quantile at Phi(z)). The limit state g is called
on whole batches of rows, because in
skidmc it is an expensive batched solver: the number of rows passed to g is the cost that every
result reports (:attr:`RareEventResult.evaluations`).

Methods (see ``docs/rare-events.md`` for the assumptions and the literature):

* ``"mc"``: plain Monte Carlo in batches; exact binomial (Clopper-Pearson) interval.
* ``"subset"``: subset simulation (Au & Beck 2001) with the component-wise (modified) Metropolis
  sampler, p0 = 0.1; independent runs are averaged until the target CoV or the budget is reached.
* ``"form-is"``: design point(s) by SLSQP on a batched finite-difference gradient (further ones
  searched from probes and from failures found while sampling), then importance sampling with
  standard normals shifted to the design point(s); its result is checked (weights, failures far
  from every design point, curvature) and says in ``warnings`` when it may be wrong.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
from scipy import optimize, stats
from scipy.special import logsumexp, ndtr, ndtri

from skidmc.analysis.checks import bad as _bad
from skidmc.analysis.checks import check_positive_float as _check_positive_float
from skidmc.analysis.checks import check_positive_int as _check_positive_int
from skidmc.analysis.checks import check_seed as _check_seed
from skidmc.ensemble.sampling import correlate_normal_scores

__all__ = [
    "CONFIDENCE",
    "GaussianCopulaTransform",
    "RareEventResult",
    "rare_event_probability",
]

#: Confidence level of every interval returned by this module.
CONFIDENCE = 0.95

METHODS = ("subset", "form-is", "mc")

# Two-sided normal quantile of CONFIDENCE (1.96).
_Z_INTERVAL = float(ndtri(0.5 + CONFIDENCE / 2))

# Minimum number of failure samples before an importance-sampling CoV estimate is trusted as a
# stopping criterion: with fewer, the sample variance of the weights is itself too noisy.
_MIN_FAILURES_TO_STOP = 10

# A failure sample lies on an unknown branch of the failure domain when its projection on every
# design point's direction falls this far [U units] short of that point's beta: two standard
# deviations of the unit-variance IS proposal, so a sample of a known, flat branch never does.
_STRAY_MARGIN = 2.0

# Angle [deg] beyond which two failure directions in U space count as different branches of the
# failure domain (the four-branch system's design points are 90 deg apart; a single curved
# branch spreads its failures over about +-35 deg at one unit beyond its design point).
_BRANCH_ANGLE_DEG = 45.0

# Curvature check of form-is. Near a design point at distance beta with a principal curvature
# kappa of the limit state (positive where the failure domain wraps back toward the origin), the
# weights phi(u)/q(u) of a unit-normal proposal centred there grow like exp(beta kappa t^2 / 2)
# along the tangent coordinate t ~ N(0, 1): their tail is Pareto with index k = beta kappa. The
# variance of the weights is infinite from k = 1/2 and the variance of the sample variance (from
# which the CoV is stated) from k = 1/4; above that the stated CoV is not to be trusted.
_CURVATURE_K_LIMIT = 0.25
# Step [U units] of the central differences of the curvature: the scale of the proposal's spread
# (unit variance), where the curvature decides the weights.
_CURVATURE_STEP = 0.5

# Generalised-Pareto shape of the largest IS weights above which their variance is infinite
# (Vehtari, Simpson, Gelman, Yao & Gabry 2024, "Pareto smoothed importance sampling", JMLR 25:72:
# k > 0.5 infinite variance, k > 0.7 not even the smoothed estimate is reliable).
_PARETO_K_LIMIT = 0.5

# Kish's effective sample size of the failures' weights, as a fraction of the failure count,
# below which a handful of samples carries the estimate.
_ESS_FRACTION_LIMIT = 0.1


def _check_marginals(marginals: Sequence) -> tuple:
    """The marginals as a tuple of frozen scipy.stats distributions (continuous or discrete)."""
    if isinstance(marginals, (str, bytes)) or not isinstance(marginals, Sequence):
        raise _bad("marginals", marginals, "expected a list of frozen scipy.stats distributions")
    if len(marginals) == 0:
        raise _bad("marginals", marginals, "expected at least one distribution")
    for i, marginal in enumerate(marginals):
        family = getattr(marginal, "dist", None)
        if not isinstance(family, (stats.rv_continuous, stats.rv_discrete)) or not callable(
            getattr(marginal, "ppf", None)
        ):
            raise _bad(
                f"marginals[{i}]",
                marginal,
                "expected a frozen scipy.stats distribution such as scipy.stats.norm(0, 1)",
            )
    return tuple(marginals)


def _check_correlation(correlation, dimension: int) -> np.ndarray:
    """The copula correlation as a (d, d) array; the identity when `correlation` is None."""
    if correlation is None:
        return np.eye(dimension)
    try:
        matrix = np.array(correlation, dtype=float)
    except (TypeError, ValueError):
        raise _bad("correlation", correlation, "expected a (d, d) matrix of numbers") from None
    if matrix.shape != (dimension, dimension):
        raise _bad(
            "correlation",
            correlation,
            f"expected shape ({dimension}, {dimension}) for "
            f"{dimension} marginals, got {matrix.shape}",
        )
    if not np.all(np.isfinite(matrix)):
        raise _bad("correlation", correlation, "entries must be finite")
    # 1e-12: round-off of a matrix typed or computed in double precision, far below any
    # correlation an analyst would state.
    if not np.allclose(np.diag(matrix), 1.0, rtol=0.0, atol=1e-12):
        raise _bad("correlation", correlation, "diagonal entries must be 1")
    if not np.allclose(matrix, matrix.T, rtol=0.0, atol=1e-12):
        raise _bad("correlation", correlation, "must be symmetric")
    try:
        np.linalg.cholesky(matrix)
    except np.linalg.LinAlgError:
        smallest = float(np.linalg.eigvalsh(matrix)[0])
        raise _bad(
            "correlation",
            correlation,
            f"must be positive definite (smallest eigenvalue {smallest:.3g})",
        ) from None
    return matrix


def _quantile(marginal, normal_scores: np.ndarray) -> np.ndarray:
    """Marginal quantile at Phi(z), accurate in both tails.

    Above the median the quantile is taken from the upper tail (``isf`` at Phi(-z)): Phi(z)
    rounds to 1 for z > 8.3, and loses relative precision in 1 - Phi(z) well before that, which
    would flatten the physical inputs exactly where rare events live.
    """
    out = np.empty_like(normal_scores)
    upper = normal_scores > 0
    out[upper] = marginal.isf(ndtr(-normal_scores[upper]))
    out[~upper] = marginal.ppf(ndtr(normal_scores[~upper]))
    return out


class GaussianCopulaTransform:
    """Isoprobabilistic map between independent standard normals and physical inputs.

    u (independent standard normals) -> z = L u (normals with the copula correlation, L its lower
    Cholesky factor) -> Phi(z) (uniforms) -> x_j = F_j^-1(Phi(z_j)) (each marginal). This is the
    Nataf transform with the correlation given directly in normal space.

    Parameters
    ----------
    marginals : sequence of frozen scipy.stats distributions
        One per input, in physical units; continuous or discrete (a discrete marginal gives
        categories; it has no inverse map, so :meth:`to_standard` refuses it).
    correlation : (d, d) array_like, optional
        Correlation matrix of the underlying standard normals (Gaussian copula): symmetric, unit
        diagonal, positive definite. None means independent inputs.

    Raises
    ------
    ValueError
        A marginal is not a frozen scipy distribution, or `correlation` is not a valid
        correlation matrix of matching size.
    """

    def __init__(self, marginals: Sequence, correlation=None) -> None:
        self.marginals = _check_marginals(marginals)
        self.dimension = len(self.marginals)
        self.correlation = _check_correlation(correlation, self.dimension)
        self.cholesky = np.linalg.cholesky(self.correlation)

    def _rows(self, values, name: str) -> np.ndarray:
        array = np.asarray(values, dtype=float)
        if array.ndim == 1 and array.shape[0] == self.dimension:
            array = array[np.newaxis, :]
        if array.ndim != 2 or array.shape[1] != self.dimension:
            raise _bad(name, values, f"expected shape (n, {self.dimension})")
        return array

    def to_physical(self, u) -> np.ndarray:
        """Physical inputs of standard normal rows.

        Parameters
        ----------
        u : (n, d) or (d,) array_like
            Independent standard normal coordinates.

        Returns
        -------
        (n, d) numpy.ndarray
            Inputs in the marginals' physical units.
        """
        u = self._rows(u, "u")
        z = correlate_normal_scores(u, self.cholesky)
        x = np.empty_like(z)
        for j, marginal in enumerate(self.marginals):
            x[:, j] = _quantile(marginal, z[:, j])
        return x

    def to_standard(self, x) -> np.ndarray:
        """Standard normal coordinates of physical rows (continuous marginals only).

        Parameters
        ----------
        x : (n, d) or (d,) array_like
            Inputs in the marginals' physical units.

        Returns
        -------
        (n, d) numpy.ndarray
            u with ``to_physical(u) == x``.
        """
        x = self._rows(x, "x")
        z = np.empty_like(x)
        for j, marginal in enumerate(self.marginals):
            if isinstance(marginal.dist, stats.rv_discrete):
                raise _bad(f"marginals[{j}]", marginal, "a discrete marginal has no inverse map")
            # Same tail care as _quantile: the upper half from the survival function.
            cdf = marginal.cdf(x[:, j])
            upper = cdf > 0.5
            z[upper, j] = -ndtri(marginal.sf(x[upper, j]))
            z[~upper, j] = ndtri(cdf[~upper])
        return np.linalg.solve(self.cholesky, z.T).T


class _CountedLimitState:
    """g on standard normal rows: maps to physical inputs, checks the output, counts rows."""

    def __init__(self, g: Callable, transform: GaussianCopulaTransform) -> None:
        if not callable(g):
            raise _bad("g", g, "expected a callable g(X) -> (n,) array")
        self.g = g
        self.transform = transform
        self.evaluations = 0

    def __call__(self, u: np.ndarray) -> np.ndarray:
        if u.shape[0] == 0:
            return np.empty(0)
        x = self.transform.to_physical(u)
        values = np.asarray(self.g(x), dtype=float)
        self.evaluations += u.shape[0]
        if values.shape != (u.shape[0],):
            raise _bad(
                "g",
                self.g,
                f"returned shape {values.shape} for X of shape {x.shape}; expected ({u.shape[0]},)",
            )
        nan = np.isnan(values)
        if nan.any():
            row = int(np.flatnonzero(nan)[0])
            raise _bad("g", self.g, f"returned NaN at X[{row}] = {x[row].tolist()}")
        return values


@dataclass(frozen=True)
class RareEventResult:
    """Estimate of P[g(X) <= 0] with its uncertainty and its cost.

    Attributes
    ----------
    probability : float
        Point estimate of the failure probability (NaN when the method stopped before it could
        form one, e.g. subset simulation out of budget before reaching g <= 0).
    cov : float
        Estimated coefficient of variation of `probability` (inf when no failure was seen).
    evaluations : int
        Number of rows passed to g, the design-point search included.
    interval : tuple of float
        (low, high) confidence interval at :data:`CONFIDENCE` (95 %). With no failure observed
        the low end is 0 and only the high end (an upper bound) is informative.
    method : str
        ``"mc"``, ``"subset"`` or ``"form-is"``.
    converged : bool
        True when the target CoV was reached within the budget.
    stop_reason : str
        Why the method stopped, in words.
    history : tuple of dict
        Per batch (mc, form-is) or per level of each run (subset): running estimates and costs.
    design_point : (d,) numpy.ndarray or None
        Physical inputs [marginal units] of the most likely failure point: the FORM design point
        (form-is; the one of smallest beta when several were found) or the failure sample of
        highest standard normal density (mc, subset). None when no failure was seen.
    beta : float or None
        FORM reliability index ||u*|| of `design_point` (form-is only).
    design_points : (k, d) numpy.ndarray or None
        All design points found (form-is), physical units, in order of increasing beta.
    warnings : tuple of str
        Caveats in words, each also issued as a RuntimeWarning: other failure branches,
        optimiser trouble, and for form-is every failed check of its result (failures far
        from every design point, importance weights with a small effective sample size or an
        infinite-variance tail, a strongly curved limit state at a design point), followed by
        the advice to use subset simulation where one fails. A report of the result should
        print them.
    """

    probability: float
    cov: float
    evaluations: int
    interval: tuple[float, float]
    method: str
    converged: bool
    stop_reason: str
    history: tuple[dict, ...]
    design_point: np.ndarray | None = None
    beta: float | None = None
    design_points: np.ndarray | None = None
    warnings: tuple[str, ...] = ()


def _lognormal_interval(
    probability: float, cov: float, quantile: float = _Z_INTERVAL
) -> tuple[float, float]:
    """Interval of a positive estimator taken as log-normal with the given mean and CoV.

    `quantile` is the two-sided quantile of log(estimate) (1.96 for 95 %, or a Student-t one
    when the CoV comes from a few replications).
    """
    if not (probability > 0 and math.isfinite(cov)):
        return (0.0, 1.0)
    sigma = math.sqrt(math.log1p(cov * cov))
    # The log-normal with mean p and CoV c has median p / sqrt(1 + c^2).
    median = probability / math.sqrt(1.0 + cov * cov)
    return (median * math.exp(-quantile * sigma), min(1.0, median * math.exp(quantile * sigma)))


def _normal_interval(probability: float, standard_error: float) -> tuple[float, float]:
    return (
        max(0.0, probability - _Z_INTERVAL * standard_error),
        min(1.0, probability + _Z_INTERVAL * standard_error),
    )


def _most_likely(u: np.ndarray, mask: np.ndarray, best: np.ndarray | None) -> np.ndarray | None:
    """The row of u[mask] (or `best`) nearest the origin of U space, i.e. of highest density."""
    if mask.any():
        candidates = u[mask]
        row = candidates[np.argmin(np.einsum("ij,ij->i", candidates, candidates))]
        if best is None or row @ row < best @ best:
            return row.copy()
    return best


# --------------------------------------------------------------------------------------------
# plain Monte Carlo
# --------------------------------------------------------------------------------------------


def _monte_carlo(limit_state, rng, target_cov, max_evaluations, batch_size):
    d = limit_state.transform.dimension
    failures = 0
    samples = 0
    best = None
    history = []
    converged = False
    while samples < max_evaluations:
        size = min(batch_size, max_evaluations - samples)
        u = rng.standard_normal((size, d))
        failed = limit_state(u) <= 0
        failures += int(failed.sum())
        samples += size
        best = _most_likely(u, failed, best)
        probability = failures / samples
        cov = math.sqrt((1 - probability) / (samples * probability)) if failures else math.inf
        history.append(
            {
                "batch": len(history),
                "evaluations": samples,
                "failures": failures,
                "probability": probability,
                "cov": cov,
            }
        )
        if cov <= target_cov:
            converged = True
            break
    # scipy's exact binomial (Clopper-Pearson) interval: valid at any count, zero included.
    ci = stats.binomtest(failures, samples).proportion_ci(CONFIDENCE, method="exact")
    interval = (float(ci.low), float(ci.high))
    if converged:
        reason = f"target CoV {target_cov} reached"
    elif failures == 0:
        reason = (
            f"budget of {max_evaluations} evaluations spent with no failure observed: "
            f"only an upper bound, P < {interval[1]:.3g} at {CONFIDENCE:.0%} confidence"
        )
    else:
        reason = f"budget of {max_evaluations} evaluations spent ({failures} failures)"
    return {
        "probability": probability,
        "cov": cov,
        "interval": interval,
        "converged": converged,
        "stop_reason": reason,
        "history": history,
        "best": best,
    }


# --------------------------------------------------------------------------------------------
# subset simulation
# --------------------------------------------------------------------------------------------


def _chain_correlation_factor(indicator: np.ndarray) -> float:
    """Au & Beck's (2001, Eq. 29) gamma of a level from its chains.

    Parameters
    ----------
    indicator : (chain_length, chains) bool array
        Whether each state of each Markov chain lies below the next threshold.

    Returns
    -------
    float
        gamma = 2 sum_k (1 - k/Ns) rho(k), with rho(k) the lag-k autocorrelation of the indicator
        estimated by pooling all chains. Clipped at 0: the chains of the modified Metropolis
        sampler are positively correlated, a negative estimate is sampling noise and would
        understate the CoV.
    """
    chain_length, chains = indicator.shape
    total = chain_length * chains
    values = indicator.astype(float)
    p = values.mean()
    variance = p * (1.0 - p)
    if variance == 0.0:
        return 0.0
    gamma = 0.0
    for lag in range(1, chain_length):
        pairs = values[:-lag] * values[lag:]
        autocovariance = pairs.sum() / (total - lag * chains) - p * p
        gamma += 2.0 * (1.0 - lag / chain_length) * autocovariance / variance
    return max(gamma, 0.0)


def _subset_run(limit_state, rng, run, samples_per_level, p0, budget, proposal_scale, max_levels):
    """One subset-simulation run; returns its estimate, its CoV and its per-level history.

    Level 0 is plain Monte Carlo. Each later level grows p0 N chains of length 1/p0 from the
    p0 N samples of lowest g (the seeds); every Metropolis step moves all chains at once, so a
    step is one batched call of g on (at most) p0 N rows.
    """
    d = limit_state.transform.dimension
    seeds_per_level = round(p0 * samples_per_level)
    chain_length = samples_per_level // seeds_per_level
    level_cost = seeds_per_level * (chain_length - 1)
    start = limit_state.evaluations

    u = rng.standard_normal((samples_per_level, d))
    values = limit_state(u)
    # Layout of the current level's samples as (chain_length, chains); level 0 is independent.
    chain_shape = None
    levels = []
    log_probability = 0.0
    squared_cov = 0.0
    threshold = math.inf
    best = None
    for level in range(max_levels):
        failed = values <= 0
        best = _most_likely(u, failed, best)
        n_failed = int(failed.sum())
        if n_failed >= seeds_per_level:
            conditional = n_failed / samples_per_level
            gamma = (
                0.0
                if chain_shape is None
                else _chain_correlation_factor(failed.reshape(chain_shape))
            )
            level_cov2 = (1 - conditional) / (conditional * samples_per_level) * (1 + gamma)
            squared_cov += level_cov2
            log_probability += math.log(conditional)
            levels.append(
                {
                    "run": run,
                    "level": level,
                    "threshold": 0.0,
                    "conditional_probability": conditional,
                    "gamma": gamma,
                    "cov": math.sqrt(level_cov2),
                    "evaluations": limit_state.evaluations - start,
                }
            )
            return {
                "complete": True,
                "probability": math.exp(log_probability),
                "cov": math.sqrt(squared_cov),
                "levels": levels,
                "best": best,
                "evaluations": limit_state.evaluations - start,
                "reason": "reached g <= 0",
            }
        # Ties are broken at random (an independent uniform key per sample): a rejected
        # Metropolis move repeats its chain's state, so equal g values are common, and which
        # copies become seeds must not depend on where they sit in the chains.
        order = np.lexsort((rng.random(values.size), values))
        # Au & Beck: the threshold halfway between the p0 N-th and the next smallest g (the
        # tied value itself when they are equal).
        new_threshold = 0.5 * (values[order[seeds_per_level - 1]] + values[order[seeds_per_level]])
        if not new_threshold < threshold:
            return {
                "complete": False,
                "probability": math.nan,
                "cov": math.inf,
                "levels": levels,
                "best": best,
                "evaluations": limit_state.evaluations - start,
                "upper_bound": math.exp(log_probability),
                "reason": f"no progress at level {level}: the threshold stayed at "
                f"{new_threshold:.6g} (g flat or infinite on the samples)",
            }
        threshold = new_threshold
        # The level's conditional probability is p0 by construction (Au & Beck 2001, Sec. 5): the
        # p0 N seeds are the samples of lowest g. Counting mean(values <= threshold) instead
        # adds every tied copy at the threshold and biased P high (+9 % at P = 2.9e-7 on the
        # 10-d linear state, see docs/rare-events.md).
        below = np.zeros(values.size, dtype=bool)
        below[order[:seeds_per_level]] = True
        conditional = seeds_per_level / samples_per_level
        gamma = (
            0.0 if chain_shape is None else _chain_correlation_factor(below.reshape(chain_shape))
        )
        level_cov2 = (1 - conditional) / (conditional * samples_per_level) * (1 + gamma)
        squared_cov += level_cov2
        log_probability += math.log(conditional)
        levels.append(
            {
                "run": run,
                "level": level,
                "threshold": float(threshold),
                "conditional_probability": float(conditional),
                "gamma": gamma,
                "cov": math.sqrt(level_cov2),
                "evaluations": limit_state.evaluations - start,
            }
        )
        if limit_state.evaluations + level_cost > budget:
            return {
                "complete": False,
                "probability": math.nan,
                "cov": math.inf,
                "levels": levels,
                "best": best,
                "evaluations": limit_state.evaluations - start,
                "upper_bound": math.exp(log_probability),
                "reason": f"budget too small for level {level + 1}: "
                f"P(g <= {threshold:.6g}) = {math.exp(log_probability):.3g} "
                "is only an upper bound",
            }
        # Modified Metropolis (Au & Beck 2001, Sec. 4): component-wise proposals accepted against
        # the standard normal density, then the whole candidate against the level's domain.
        current = u[order[:seeds_per_level]]
        current_values = values[order[:seeds_per_level]]
        chain_u = np.empty((chain_length, seeds_per_level, d))
        chain_values = np.empty((chain_length, seeds_per_level))
        chain_u[0], chain_values[0] = current, current_values
        moves = 0
        for step in range(1, chain_length):
            candidate = current + proposal_scale * rng.standard_normal(current.shape)
            log_ratio = 0.5 * (current * current - candidate * candidate)
            keep_component = np.log(rng.random(current.shape)) < log_ratio
            candidate = np.where(keep_component, candidate, current)
            changed = keep_component.any(axis=1)
            candidate_values = current_values.copy()
            candidate_values[changed] = limit_state(candidate[changed])  # one batched call
            accepted = changed & (candidate_values <= threshold)
            current = np.where(accepted[:, None], candidate, current)
            current_values = np.where(accepted, candidate_values, current_values)
            moves += int(accepted.sum())
            chain_u[step], chain_values[step] = current, current_values
        levels[-1]["acceptance"] = moves / level_cost
        u = chain_u.reshape(-1, d)
        values = chain_values.reshape(-1)
        chain_shape = (chain_length, seeds_per_level)
    return {
        "complete": False,
        "probability": math.nan,
        "cov": math.inf,
        "levels": levels,
        "best": best,
        "evaluations": limit_state.evaluations - start,
        "upper_bound": math.exp(log_probability),
        "reason": f"{max_levels} levels without reaching g <= 0",
    }


def _averaged_runs_cov(runs: list[dict]) -> tuple[float, float]:
    """CoV of the average of independent subset-simulation runs, and its interval quantile.

    Each run's relative variance is Au & Beck's sum over levels, which neglects the correlation
    between the levels' estimates (the seeds of a level come from the chains of the one before)
    and so runs low: measured on the 10-d linear limit state, 0.24 stated against 0.27 observed
    at 3 levels, 0.33 against 0.47 at 6; on the four-branch system 0.095 against 0.111 for the
    average of ~8 runs. With two or more runs their spread is an unbiased but noisy estimate of
    the same relative variance: the larger of the two is used, and the interval takes the
    Student-t quantile with R - 1 degrees of freedom for the noise of the spread (measured
    coverage of the nominal 95 %: 0.96 on the four-branch system, 0.99 on the linear state).
    """
    estimates = np.array([r["probability"] for r in runs])
    formula = float(np.mean([r["cov"] ** 2 for r in runs]))
    if len(runs) == 1:
        return math.sqrt(formula), _Z_INTERVAL
    spread = float(estimates.var(ddof=1) / estimates.mean() ** 2)
    quantile = float(stats.t.ppf(0.5 + CONFIDENCE / 2, len(runs) - 1))
    return math.sqrt(max(formula, spread) / len(runs)), quantile


def _subset_simulation(
    limit_state,
    rng,
    target_cov,
    max_evaluations,
    samples_per_level,
    proposal_scale,
    max_levels,
    p0=0.1,
):
    runs = []
    history = []
    notes = []
    best = None
    largest_run_cost = 0
    while True:
        remaining = max_evaluations - limit_state.evaluations
        # Start another run only when a full one fits (the largest so far, plus one level's
        # margin): a run abandoned half-way is wasted and, worse, dropping it would favour
        # runs that needed few levels, i.e. bias the average upward.
        margin = round(samples_per_level * (1 - p0))
        if runs and remaining < largest_run_cost + margin:
            reason = (
                f"budget of {max_evaluations} evaluations: no room for another run "
                f"({len(runs)} runs)"
            )
            break
        if not runs and remaining < samples_per_level:
            raise _bad(
                "max_evaluations",
                max_evaluations,
                f"subset simulation needs at least samples_per_level = "
                f"{samples_per_level} evaluations",
            )
        run = _subset_run(
            limit_state,
            rng,
            len(runs),
            samples_per_level,
            p0,
            max_evaluations,
            proposal_scale,
            max_levels,
        )
        history.extend(run["levels"])
        if run["best"] is not None and (best is None or run["best"] @ run["best"] < best @ best):
            best = run["best"]
        if not run["complete"]:
            if runs:
                notes.append(
                    f"run {len(runs)} stopped unfinished ({run['reason']}); "
                    "it is left out of the average"
                )
                reason = f"budget of {max_evaluations} evaluations spent ({len(runs)} runs)"
            else:
                reason = run["reason"]
                return {
                    "probability": math.nan,
                    "cov": math.inf,
                    "interval": (0.0, run["upper_bound"]),
                    "converged": False,
                    "stop_reason": reason,
                    "history": history,
                    "best": best,
                    "notes": notes,
                }
            break
        runs.append(run)
        run["levels"][-1]["run_probability"] = run["probability"]
        run["levels"][-1]["run_cov"] = run["cov"]
        largest_run_cost = max(largest_run_cost, run["evaluations"])
        cov, _ = _averaged_runs_cov(runs)
        if cov <= target_cov:
            reason = f"target CoV {target_cov} reached ({len(runs)} runs)"
            break
    probability = float(np.mean([r["probability"] for r in runs]))
    cov, quantile = _averaged_runs_cov(runs)
    if len(runs) == 1:
        notes.append(
            "one subset-simulation run: its CoV is Au & Beck's formula, which neglects the "
            "correlation between levels and ran low by 1.4-5.7x in measurements "
            "(docs/rare-events.md); give a budget for several runs to have their spread checked"
        )
    return {
        "probability": probability,
        "cov": cov,
        "interval": _lognormal_interval(probability, cov, quantile),
        "converged": cov <= target_cov,
        "stop_reason": reason,
        "history": history,
        "best": best,
        "notes": notes,
    }


# --------------------------------------------------------------------------------------------
# FORM + importance sampling
# --------------------------------------------------------------------------------------------


def _design_point(limit_state, start, gradient_step, scale, bounds=None):
    """Nearest point of g = 0 to the origin of U space, by SLSQP.

    The constraint's gradient is a forward difference whose d + 1 rows go to g in one call;
    value and gradient at a point are cached together, so SLSQP's separate requests for the
    constraint and its Jacobian cost one call.
    """
    d = start.shape[0]
    cache: dict[bytes, tuple[float, np.ndarray]] = {}

    def value_and_gradient(u):
        key = u.tobytes()
        if key not in cache:
            rows = np.vstack([u, u + gradient_step * np.eye(d)])
            values = limit_state(rows) / scale
            cache[key] = (values[0], (values[1:] - values[0]) / gradient_step)
        return cache[key]

    with warnings.catch_warnings():
        # SLSQP's own warnings about bounds/values are reported through result.success.
        warnings.simplefilter("ignore", RuntimeWarning)
        result = optimize.minimize(
            lambda u: 0.5 * u @ u,
            start,
            jac=lambda u: u,
            method="SLSQP",
            constraints=[
                {
                    "type": "eq",
                    "fun": lambda u: value_and_gradient(u)[0],
                    "jac": lambda u: value_and_gradient(u)[1],
                }
            ],
            # ftol 1e-6 of 0.5 beta^2 (5-20 for rare events) pins beta far below the
            # finite-difference error; tighter, SLSQP spends its iterations chasing that error.
            options={"maxiter": 100, "ftol": 1e-6},
            bounds=bounds,
        )
    u_star = np.asarray(result.x, dtype=float)
    value = value_and_gradient(u_star)[0] if np.all(np.isfinite(u_star)) else math.nan
    # 1e-3 of g's scale at the origin: far below what moves the IS proposal noticeably.
    ok = bool(np.all(np.isfinite(u_star)) and abs(value) <= 1e-3)
    return u_star, ok, result.message


def _branch_point(limit_state, start, gradient_step, scale):
    """A design point of a further branch, or None.

    The IS proposal only has to sit near a branch, not on its exact design point: a search that
    stops short (SLSQP at a kink of a series or parallel system, where the constraint is not
    differentiable) still yields a usable centre when it ends within 5 % of g's scale of g = 0.
    """
    surface = _surface_start(limit_state, start)
    # Kept within a box around the start (half-width half its distance from the origin, at
    # least one unit): without it SLSQP often jumps to the nearest point of a branch already
    # known, which is where the constraint is met at least cost.
    half = max(1.0, 0.5 * float(np.linalg.norm(surface)))
    bounds = optimize.Bounds(surface - half, surface + half)
    u_new, ok_new, _ = _design_point(limit_state, surface, gradient_step, scale, bounds)
    if ok_new:
        return u_new
    if np.all(np.isfinite(u_new)):
        value = float(limit_state(u_new[np.newaxis])[0]) / scale
        if abs(value) <= 0.05:
            return u_new
    return None


def _surface_start(limit_state, point: np.ndarray, points_on_ray: int = 20) -> np.ndarray:
    """Where the ray from the origin to a failure point first reaches g <= 0 (one call of g).

    A design point search started far out on a branch can jump to another branch (SLSQP's
    equality constraint is met anywhere on g = 0); started on the surface near the failure's own
    branch it stays there. Linear interpolation between the last safe and the first failed of
    `points_on_ray` equally spaced points; the failure point itself when the ray fails at once.
    """
    fractions = np.arange(1, points_on_ray + 1) / points_on_ray
    values = limit_state(fractions[:, None] * point[None, :])
    failed = np.flatnonzero(values <= 0)
    if not failed.size or failed[0] == 0:
        return point
    i = failed[0]
    g_safe, g_fail = values[i - 1], values[i]
    share = g_safe / (g_safe - g_fail) if math.isfinite(g_safe - g_fail) else 0.5
    return (fractions[i - 1] + share * (fractions[i] - fractions[i - 1])) * point


def _angle_cosines(directions: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Cosine of the angle between each row of `directions` and each row of `points`."""
    a = directions / np.linalg.norm(directions, axis=1, keepdims=True)
    b = points / np.maximum(np.linalg.norm(points, axis=1, keepdims=True), 1e-300)
    return a @ b.T


def _principal_curvatures(limit_state, u_star: np.ndarray, step: float) -> np.ndarray:
    """Principal curvatures [1/U units] of the limit state g = 0 at a design point.

    Central differences of step `step` give the gradient and Hessian of g at u* in one batched
    call of 1 + 2d + 2d(d-1) rows. With alpha = -grad g / |grad g| (into the failure domain) and P
    the projection on the tangent plane, the curvatures are the eigenvalues of
    -P H P / |grad g| on that plane: positive where the surface bends back toward the origin
    (the failure domain wraps around the design point), the case in which the weights of a
    proposal centred at u* have a heavy tail (see _CURVATURE_K_LIMIT).
    """
    d = u_star.size
    eye = np.eye(d)
    pairs = [(i, j) for i in range(d) for j in range(i + 1, d)]
    rows = [u_star]
    rows += [u_star + step * eye[i] for i in range(d)]
    rows += [u_star - step * eye[i] for i in range(d)]
    for i, j in pairs:
        for si, sj in ((1, 1), (1, -1), (-1, 1), (-1, -1)):
            rows.append(u_star + step * (si * eye[i] + sj * eye[j]))
    values = limit_state(np.array(rows))
    centre, plus, minus = values[0], values[1 : d + 1], values[d + 1 : 2 * d + 1]
    gradient = (plus - minus) / (2 * step)
    hessian = np.diag((plus - 2 * centre + minus) / step**2)
    mixed = values[2 * d + 1 :].reshape(-1, 4)
    for (i, j), (pp, pm, mp, mm) in zip(pairs, mixed):
        hessian[i, j] = hessian[j, i] = (pp - pm - mp + mm) / (4 * step**2)
    norm = float(np.linalg.norm(gradient))
    if not (np.all(np.isfinite(hessian)) and norm > 0 and math.isfinite(norm)):
        return np.full(max(d - 1, 0), math.nan)
    alpha = -gradient / norm
    # orthonormal basis of the tangent plane: the last d - 1 columns of a QR of [alpha, I]
    basis = np.linalg.qr(np.column_stack([alpha, eye]))[0][:, 1:d]
    return np.linalg.eigvalsh(-basis.T @ hessian @ basis / norm)


def _pareto_k(weights: np.ndarray) -> float:
    """Shape k of a generalised Pareto fitted to the largest importance weights.

    The tail size M = min(n / 5, 3 sqrt(n)) and the threshold (the (M+1)-th largest weight) follow
    Vehtari et al. (2024); the fit is scipy's maximum likelihood with the location fixed at the
    threshold (their Zhang & Stephens estimator differs only in small-sample details, which the
    limits used here do not resolve). NaN with fewer than 20 positive weights.
    """
    positive = np.sort(weights[weights > 0])
    n = positive.size
    if n < 20:
        return math.nan
    m = int(min(n / 5, 3 * math.sqrt(n)))
    threshold = positive[-m - 1]
    tail = positive[-m:] - threshold
    if not np.any(tail > 0):
        return math.nan
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        shape, _, _ = stats.genpareto.fit(tail / tail.max(), floc=0.0)
    return float(shape)


def _form_importance_sampling(
    limit_state,
    rng,
    target_cov,
    max_evaluations,
    batch_size,
    gradient_step,
    probe_directions,
    max_design_points,
):
    d = limit_state.transform.dimension
    notes = []
    origin_value = float(limit_state(np.zeros((1, d)))[0])
    scale = abs(origin_value) if math.isfinite(origin_value) and origin_value != 0 else 1.0
    start = np.zeros(d)
    if origin_value > 0:
        # SLSQP cannot leave the origin of 0.5 |u|^2 when g's gradient there is tiny; a start one
        # unit down g's slope is harmless and avoids the degenerate first step.
        start = np.full(d, 1e-3)
    u_star, ok, message = _design_point(limit_state, start, gradient_step, scale)
    if not ok:
        notes.append(
            f"design point search did not converge ({message}); importance sampling "
            "around its last point (the estimate stays unbiased, the CoV shows the cost)"
        )
    design_points = [u_star]
    beta = float(np.linalg.norm(u_star))
    # Probe for other branches of the failure domain: random directions one unit beyond beta,
    # one batched call; failures far from every known design point start another search.
    cos_branch = math.cos(math.radians(_BRANCH_ANGLE_DEG))
    # Each extra search may fail or slide back to a known branch: cap them so a ragged failure
    # domain cannot spend the budget on searches.
    searches_left = 2 * max_design_points
    if probe_directions > 0 and max_design_points > 1:
        directions = rng.standard_normal((probe_directions, d))
        directions /= np.linalg.norm(directions, axis=1, keepdims=True)
        probe_values = limit_state((beta + 1.0) * directions)
        order = np.argsort(probe_values)
        candidates = [directions[i] for i in order if probe_values[i] <= 0]
        while candidates and len(design_points) < max_design_points and searches_left > 0:
            searches_left -= 1
            known = np.array(design_points)
            candidates = [
                c for c in candidates if _angle_cosines(c[np.newaxis], known).max() < cos_branch
            ]
            if not candidates:
                break
            candidate = candidates.pop(0)
            u_new = _branch_point(limit_state, (beta + 1.0) * candidate, gradient_step, scale)
            if u_new is None:
                continue
            if _angle_cosines(u_new[np.newaxis], known).max() < cos_branch:
                design_points.append(u_new)
            else:
                # It slid back to a known branch: drop the probes near where it started.
                candidates = [c for c in candidates if c @ candidate < cos_branch]
    search_cost = limit_state.evaluations
    # Starts (directions) from which a search slid back to a known branch: failures near them
    # start no further search.
    tried: list[np.ndarray] = []
    restarts = 0
    while True:
        design_points.sort(key=lambda p: p @ p)
        centres = np.array(design_points)
        betas = np.linalg.norm(centres, axis=1)
        # beta is negative when the origin itself fails (then the event is not rare).
        betas = betas if origin_value > 0 else -betas
        # Mixture weights ~ Phi(-beta_k): each branch's FORM share of the probability.
        log_mixture = stats.norm.logsf(betas)
        log_mixture -= logsumexp(log_mixture)
        directions = centres / np.maximum(np.abs(betas), 1e-300)[:, None]
        terms = []
        stray_share = 0.0
        astray_share = 0.0
        history = []
        converged = False
        failures = 0
        new_point = None
        # The curvature check's rows are kept out of the sampling budget when they fit in a
        # fifth of it; otherwise the check is skipped (and the result says so).
        curvature_rows = len(centres) * (1 + 2 * d * d)
        reserve = curvature_rows if curvature_rows <= 0.2 * max_evaluations else 0
        sampling_budget = max_evaluations - reserve
        while limit_state.evaluations < sampling_budget:
            size = min(batch_size, sampling_budget - limit_state.evaluations)
            component = rng.choice(len(centres), size=size, p=np.exp(log_mixture))
            u = centres[component] + rng.standard_normal((size, d))
            failed = limit_state(u) <= 0
            # log phi(u) - log q(u), q the mixture of unit normals around the design points.
            log_q = logsumexp(
                log_mixture[np.newaxis, :]
                - 0.5
                * (
                    np.einsum("ij,ij->i", u, u)[:, None]
                    - 2 * u @ centres.T
                    + np.einsum("ij,ij->i", centres, centres)[None, :]
                ),
                axis=1,
            )
            batch_terms = np.where(
                failed, np.exp(-0.5 * np.einsum("ij,ij->i", u, u) - log_q), 0.0
            )
            terms.append(batch_terms)
            failures += int(failed.sum())
            if failed.any():
                # A failure belongs to a known branch when its projection on that design
                # point's direction reaches near its beta (for a flat or convex branch it
                # reaches beta itself); projections short of every beta by _STRAY_MARGIN lie
                # elsewhere.
                far = np.all(
                    u[failed] @ directions.T < np.abs(betas) - _STRAY_MARGIN, axis=1
                )
                stray_share += float(batch_terms[failed][far].sum())
                # Failures more than _BRANCH_ANGLE_DEG away from every design point: another
                # branch, or the far flank of a curved one.
                astray = _angle_cosines(u[failed], centres).max(axis=1) < cos_branch
                astray_share += float(batch_terms[failed][astray].sum())
                # Such failures (away from every start that already slid back, too) start a
                # search for another design point.
                if len(design_points) < max_design_points and searches_left > 0:
                    seen = np.vstack([centres] + ([np.array(tried)] if tried else []))
                    lost = u[failed][_angle_cosines(u[failed], seen).max(axis=1) < cos_branch]
                    if lost.size:
                        searches_left -= 1
                        candidate = lost[np.argmin(np.einsum("ij,ij->i", lost, lost))]
                        u_new = _branch_point(limit_state, candidate, gradient_step, scale)
                        if (
                            u_new is not None
                            and _angle_cosines(u_new[None], centres).max() < cos_branch
                        ):
                            # restart only when a batch still fits after the larger reserve
                            more = (len(centres) + 1) * (1 + 2 * d * d)
                            room = max_evaluations - (more if reserve else 0)
                            if room - limit_state.evaluations >= batch_size:
                                new_point = u_new
                                break
                            searches_left = 0
                            notes.append(
                                "a further design point was found from the failures (beta "
                                f"{np.linalg.norm(u_new):.3f}) with no budget left to sample "
                                "around it; raise max_evaluations"
                            )
                        else:
                            tried.append(candidate)
            values = np.concatenate(terms)
            probability = float(values.mean())
            standard_error = (
                float(values.std(ddof=1) / math.sqrt(values.size))
                if values.size > 1
                else math.inf
            )
            cov = standard_error / probability if probability > 0 else math.inf
            history.append(
                {
                    "batch": len(history),
                    "evaluations": limit_state.evaluations,
                    "samples": int(values.size),
                    "failures": failures,
                    "probability": probability,
                    "cov": cov,
                    "design_points": len(centres),
                }
            )
            if failures >= _MIN_FAILURES_TO_STOP and cov <= target_cov:
                converged = True
                break
        if new_point is None:
            break
        # Another branch, found from the failures: restart the sampling with it in the mixture
        # (the samples drawn so far came from a proposal that missed it and are dropped).
        design_points.append(new_point)
        restarts += 1
    if not terms or not history:
        raise _bad(
            "max_evaluations",
            max_evaluations,
            f"the design point search used {search_cost} evaluations, none left for "
            "importance sampling",
        )
    values = np.concatenate(terms)
    if len(design_points) > 1:
        found = (
            f", {restarts} of them from failures found while sampling" if restarts else ""
        )
        notes.append(
            f"{len(design_points)} design points found (betas "
            + ", ".join(f"{abs(b):.3f}" for b in betas)
            + f"{found}): importance sampling from their mixture"
        )

    # -- checks of the result: each failed check is a warning in words ----------------------
    doubts = []
    if max_design_points == 1:
        doubts.append(
            "max_design_points = 1: no other branch of the failure domain was searched for, and "
            "a branch the samples around the one design point never reach is missed without "
            "any sign in the result"
        )
    total = float(values.sum())
    if total > 0 and stray_share / total > 0.01:
        doubts.append(
            f"{stray_share / total:.1%} of the estimate comes from failures whose projection "
            f"falls {_STRAY_MARGIN} short of every design point's beta: the failure domain "
            "has branches the search missed, the estimate and its CoV may be too low"
        )
    if total > 0 and astray_share / total > 0.01:
        doubts.append(
            f"{astray_share / total:.1%} of the estimate comes from failures more than "
            f"{_BRANCH_ANGLE_DEG:g} deg away from every design point"
            + (
                " and the search for further design points was spent"
                if len(design_points) < max_design_points
                else f" and max_design_points = {max_design_points} was reached"
            )
            + ": part of the failure domain may lie where the proposal rarely samples, the "
            "estimate and its CoV may be too low"
        )
    weights = values[values > 0]
    if weights.size >= _MIN_FAILURES_TO_STOP:
        ess = float(weights.sum() ** 2 / np.sum(weights**2))
        if ess < _ESS_FRACTION_LIMIT * weights.size:
            doubts.append(
                f"the importance weights of the {weights.size} failures have an effective "
                f"sample size of {ess:.1f} (Kish): a few samples carry the estimate, whose CoV "
                "is then itself unreliable"
            )
        k_hat = _pareto_k(values)
        if k_hat > _PARETO_K_LIMIT:
            doubts.append(
                f"the largest importance weights have a Pareto tail shape k = {k_hat:.2f} "
                f"(> {_PARETO_K_LIMIT}: infinite variance, Vehtari et al. 2024): the stated CoV "
                "and interval are not to be trusted"
            )
    curvatures = []
    if origin_value > 0 and not reserve:
        notes.append(
            f"the curvature at the design points was not checked: its {curvature_rows} "
            f"evaluations exceed a fifth of max_evaluations = {max_evaluations}"
        )
    elif origin_value > 0:
        for point, b in zip(centres, betas):
            kappa = _principal_curvatures(limit_state, point, _CURVATURE_STEP)
            curvatures.append(kappa)
            k_index = float(np.nanmax(kappa)) * abs(b) if np.any(np.isfinite(kappa)) else 0.0
            if k_index > _CURVATURE_K_LIMIT:
                doubts.append(
                    f"the limit state is strongly curved at the design point of beta {abs(b):.3f}"
                    f" (largest principal curvature {np.nanmax(kappa):.3g}, beta kappa = "
                    f"{k_index:.2f} > {_CURVATURE_K_LIMIT}): the failure domain wraps around the "
                    "design point, the importance weights have a heavy tail and the stated CoV "
                    "runs low"
                )
    if doubts:
        doubts.append(
            'subset simulation (method="subset") assumes nothing about the shape of the failure '
            "domain and would be safer here"
        )
    notes.extend(doubts)
    probability = float(values.mean())
    standard_error = float(values.std(ddof=1) / math.sqrt(values.size))
    cov = standard_error / probability if probability > 0 else math.inf
    interval = _normal_interval(probability, standard_error)
    if converged:
        reason = f"target CoV {target_cov} reached"
    else:
        reason = f"budget of {max_evaluations} evaluations spent"
    return {
        "probability": probability,
        "cov": cov,
        "interval": interval,
        "converged": converged,
        "stop_reason": reason,
        "history": history,
        "best": centres[0],
        "beta": float(betas[0]),
        "centres": centres,
        "curvatures": curvatures,
        "notes": notes,
    }


# --------------------------------------------------------------------------------------------
# public entry point
# --------------------------------------------------------------------------------------------


def rare_event_probability(
    g: Callable[[np.ndarray], np.ndarray],
    marginals: Sequence,
    method: str = "subset",
    correlation=None,
    target_cov: float = 0.1,
    max_evaluations: int = 100_000,
    seed: int = 0,
    *,
    batch_size: int | None = None,
    samples_per_level: int = 1000,
    proposal_scale: float = 1.0,
    max_levels: int = 50,
    gradient_step: float = 1e-2,
    probe_directions: int | None = None,
    max_design_points: int = 4,
) -> RareEventResult:
    """Probability P[g(X) <= 0] of a rare event, with its CoV, interval and cost.

    Parameters
    ----------
    g : callable
        Vectorised limit state: ``g(X)`` with X an (n, d) array of physical inputs returns n
        finite (or +-inf) values; failure where ``g <= 0``. Called on whole batches.
    marginals : sequence of frozen scipy.stats distributions
        Distribution of each input [physical units].
    method : {"subset", "form-is", "mc"}
        Estimator (see the module docstring).
    correlation : (d, d) array_like, optional
        Gaussian-copula correlation (of the underlying standard normals); None: independent.
    target_cov : float
        Stop once the estimated coefficient of variation is at most this (> 0).
    max_evaluations : int
        Budget of rows passed to g (>= 1); the method stops when the next step would exceed it.
    seed : int
        Seed (>= 0) of :func:`numpy.random.default_rng`; equal seeds give equal results.
    batch_size : int, optional
        Rows per batch of "mc" (default 10 000) and of the importance sampling of "form-is"
        (default 500).
    samples_per_level : int
        N of subset simulation, a multiple of 10 (p0 = 0.1); each run costs about
        N (1 + 0.9 m) evaluations for m intermediate levels.
    proposal_scale : float
        Standard deviation of subset simulation's component-wise Gaussian proposal [U units].
    max_levels : int
        Subset simulation gives up after this many levels without reaching g <= 0.
    gradient_step : float
        Forward-difference step of the FORM gradient [U units]; raise it (to ~0.1) when g is a
        solver whose tolerance makes smaller differences noise.
    probe_directions : int, optional
        Random directions probed one unit beyond the first design point to detect other
        failure branches (form-is); default max(64, 8 d); 0 disables.
    max_design_points : int
        Most design points form-is looks for (the IS proposal is their mixture).

    Returns
    -------
    RareEventResult

    Raises
    ------
    ValueError
        Bad marginals, correlation, method, target_cov, budget, seed or options, or g returned
        the wrong shape or NaN.
    """
    transform = GaussianCopulaTransform(marginals, correlation)
    if method not in METHODS:
        raise _bad("method", method, f"expected one of {', '.join(METHODS)}")
    target_cov = _check_positive_float("target_cov", target_cov)
    max_evaluations = _check_positive_int("max_evaluations", max_evaluations)
    rng = np.random.default_rng(_check_seed(seed))
    limit_state = _CountedLimitState(g, transform)
    d = transform.dimension
    extra = {}
    if method == "mc":
        batch = _check_positive_int("batch_size", 10_000 if batch_size is None else batch_size)
        out = _monte_carlo(limit_state, rng, target_cov, max_evaluations, batch)
    elif method == "subset":
        samples_per_level = _check_positive_int("samples_per_level", samples_per_level, 10)
        if samples_per_level % 10:
            raise _bad(
                "samples_per_level", samples_per_level, "must be a multiple of 10 (p0 = 0.1)"
            )
        out = _subset_simulation(
            limit_state,
            rng,
            target_cov,
            max_evaluations,
            samples_per_level,
            _check_positive_float("proposal_scale", proposal_scale),
            _check_positive_int("max_levels", max_levels),
        )
    else:
        batch = _check_positive_int("batch_size", 500 if batch_size is None else batch_size, 2)
        probes = max(64, 8 * d) if probe_directions is None else probe_directions
        out = _form_importance_sampling(
            limit_state,
            rng,
            target_cov,
            max_evaluations,
            batch,
            _check_positive_float("gradient_step", gradient_step),
            _check_positive_int("probe_directions", probes, 0),
            _check_positive_int("max_design_points", max_design_points),
        )
        extra = {"beta": out["beta"], "design_points": transform.to_physical(out["centres"])}
    notes = tuple(out.get("notes", ()))
    for note in notes:
        warnings.warn(note, RuntimeWarning, stacklevel=2)
    best = out["best"]
    return RareEventResult(
        probability=float(out["probability"]),
        cov=float(out["cov"]),
        evaluations=limit_state.evaluations,
        interval=(float(out["interval"][0]), float(out["interval"][1])),
        method=method,
        converged=bool(out["converged"]),
        stop_reason=out["stop_reason"],
        history=tuple(out["history"]),
        design_point=None if best is None else transform.to_physical(best)[0],
        warnings=notes,
        **extra,
    )
