"""Bayesian calibration of the skid model's epistemic inputs on the report's drops (issue 40).

The mathematics of the ``calibration`` kind of study (:mod:`skidmc.workflows.calibration`
orchestrates it: study, solver runs, storage, report). Everything here is a function of arrays
or of a callable; nothing opens a file or runs the solver. Modelling choices and their sources:
``docs/calibration.md``.

Model
-----
Parameters are sampled in standard-normal coordinates z (prior N(0, 1) each); a parameter's
physical value is its prior distribution's quantile at Phi(z) (the study's epistemic
distributions, :class:`Parameter`). For a drop i on target t at height H_i:

    P(go | H_i, theta) = sum_j w_j Phi( (ln H_i - g_t(theta, a_j) - delta_t) / s_t )     (1)

with g_t the surrogate of ln H_c [ln m] (:class:`Surrogate`), a_j, w_j the tensor Gauss-Hermite
nodes and weights over the normal scores of the aleatory inputs integrated by quadrature
(friction of the spot hit, flow stress of the billet), s_t the ln H_c spread of the remaining,
small aleatory inputs (temperature, billet mass, angle) folded in linearly, and delta_t the
Kennedy-O'Hagan discrepancy of target t (a multiplicative error exp(delta_t) on H_c, prior
N(0, s_delta^2 + s_sur,t^2), s_sur,t the surrogate's held-out error). An observed outcome is
misread with probability eps: P(observed go) = eps + (1 - 2 eps) P(go). The friction means of
the finishes are tied by a population (hierarchical): ln mu_f ~ N(m, tau^2), each finish's
measurement ln mu_f,meas ~ N(ln mu_f, s_f^2) (:class:`FrictionPopulation`).
"""

from __future__ import annotations

import dataclasses
import functools
import math
from collections.abc import Callable, Mapping, Sequence

import numpy as np
from scipy import special, stats

__all__ = [
    "FEATURE_TRANSFORMS",
    "CalibrationModel",
    "CalibrationTarget",
    "FrictionPopulation",
    "Parameter",
    "Surrogate",
    "diagnostic_lines",
    "diagnostics",
    "fit_surrogate",
    "normal_quadrature",
    "log_score",
    "brier_score",
    "run_emcee",
]

#: How each scene input enters the surrogate's features: "log" (ln of the SI value) or
#: "linear" (the SI value). ln H_c is close to linear in the logarithms of the multiplicative
#: inputs (friction, flow stress, conductivities, rate, heat of reaction) and in E/R.
FEATURE_TRANSFORMS: dict[str, str] = {
    "mu": "log",
    "flow_stress": "log",
    "target.conductivity": "log",
    "he.conductivity": "log",
    "he.heat_capacity": "log",
    "kinetics.activation_temperature": "linear",
    "kinetics.rate_at_reference": "log",
    "kinetics.heat_of_reaction": "log",
    "initial_temperature": "linear",
    "billet_mass": "log",
    "angle": "log",
}


def _transform(key: str, values) -> np.ndarray:
    values = np.asarray(values, dtype=float)
    return np.log(values) if FEATURE_TRANSFORMS[key] == "log" else values


# --- the surrogate ---------------------------------------------------------------------------


def _quadratic_design(z: np.ndarray) -> np.ndarray:
    """[1, z_i, z_i z_j (i <= j)] of standardized features `z` (..., d)."""
    d = z.shape[-1]
    i, j = np.triu_indices(d)
    return np.concatenate([np.ones(z.shape[:-1] + (1,)), z, z[..., i] * z[..., j]], axis=-1)


@dataclasses.dataclass(frozen=True)
class Surrogate:
    """A quadratic least-squares polynomial of ln H_c [ln m] in standardized features (linear
    when the training rows are fewer than twice the quadratic's terms).

    Features are the inputs of :data:`FEATURE_TRANSFORMS` that vary in the training set,
    transformed (ln or linear) and standardized by the training mean and sd. Fitted by
    ordinary least squares (statsmodels ``OLS``).

    Attributes
    ----------
    keys : tuple of str
        Scene keys of the features, in order.
    center, scale : ndarray
        Training mean and sd of each transformed feature.
    coef : ndarray
        Coefficients of :func:`_quadratic_design`'s columns.
    rmse_train, rmse_holdout : float
        Root-mean-square error of ln H_c on the training rows and on the held-out rows [1].
    n_train, n_holdout : int
        Rows used [1].
    degree : int
        2 (quadratic, with every product of two features) or 1.
    """

    keys: tuple[str, ...]
    center: np.ndarray
    scale: np.ndarray
    coef: np.ndarray
    rmse_train: float
    rmse_holdout: float
    n_train: int
    n_holdout: int
    degree: int = 2

    def features(self, inputs: Mapping[str, np.ndarray]) -> np.ndarray:
        """Standardized features (..., d) of `inputs` (key -> SI values, broadcastable)."""
        cols = np.broadcast_arrays(*[_transform(k, inputs[k]) for k in self.keys])
        return (np.stack(cols, axis=-1) - self.center) / self.scale

    def __call__(self, inputs: Mapping[str, np.ndarray]) -> np.ndarray:
        """ln H_c [ln m] at `inputs` (key -> SI values, broadcastable): c + b.z + z'Az."""
        z = self.features(inputs)
        c, b, a = self._form
        out = c + z @ b
        if a is not None:
            out = out + np.einsum("...i,...i->...", z @ a, z)
        return out

    @functools.cached_property
    def _form(self):
        """(c, b, A) of the polynomial as a quadratic form (A symmetric; None if linear)."""
        d = len(self.keys)
        c, b = self.coef[0], self.coef[1:1 + d]
        if self.degree == 1:
            return c, b, None
        a = np.zeros((d, d))
        i, j = np.triu_indices(d)
        q = self.coef[1 + d:]
        a[i, j] += 0.5 * q
        a[j, i] += 0.5 * q
        return c, b, a


def fit_surrogate(inputs: Mapping[str, np.ndarray], ln_height: np.ndarray, *,
                  holdout: float = 0.2, seed: int = 0) -> Surrogate:
    """Fit :class:`Surrogate` to solver results.

    Parameters
    ----------
    inputs : mapping
        Scene key -> SI values (n,) of the training rows (keys outside
        :data:`FEATURE_TRANSFORMS` and constant ones are ignored).
    ln_height : ndarray
        ln H_c [ln m] (n,), finite rows only.
    holdout : float
        Fraction of rows held out (drawn at random with `seed`) to measure the error [1].
    seed : int

    Returns
    -------
    Surrogate
    """
    import statsmodels.api as sm

    y = np.asarray(ln_height, dtype=float)
    keys = tuple(k for k in FEATURE_TRANSFORMS if k in inputs
                 and np.ptp(_transform(k, inputs[k])) > 1e-12 * max(1.0, np.abs(
                     _transform(k, inputs[k])).max()))
    x = np.stack([_transform(k, inputs[k]) for k in keys], axis=-1)
    ok = np.isfinite(y) & np.isfinite(x).all(axis=1)
    x, y = x[ok], y[ok]
    rng = np.random.default_rng(seed)
    test = rng.random(len(y)) < holdout
    center, scale = x[~test].mean(axis=0), x[~test].std(axis=0)
    design = _quadratic_design((x - center) / scale)
    degree = 2
    if (~test).sum() < 2 * design.shape[1]:  # too few rows for every quadratic term: linear
        degree = 1
        design = design[:, :1 + len(keys)]
    fit = sm.OLS(y[~test], design[~test]).fit()
    coef = np.asarray(fit.params)
    resid_train = y[~test] - design[~test] @ coef
    resid_test = y[test] - design[test] @ coef
    return Surrogate(keys, center, scale, coef, float(np.sqrt(np.mean(resid_train**2))),
                     float(np.sqrt(np.mean(resid_test**2))) if test.any() else math.nan,
                     int((~test).sum()), int(test.sum()), degree)


# --- the parameters and the likelihood ---------------------------------------------------------


#: Half-width of the normal-score interval the quadrature covers [1] (the mass beyond it,
#: 2e-9, is dropped and the weights renormalized).
Z_SPAN = 6.0


def normal_quadrature(n: int) -> tuple[np.ndarray, np.ndarray]:
    """Nodes and weights of an n-point rule for E[f(Z)], Z ~ N(0, 1): Gauss-Legendre on
    [-:data:`Z_SPAN`, Z_SPAN] with weights times the normal density, normalized.

    Gauss-Hermite would be exact for polynomials in Z, but the integrand of (1) is a smoothed
    step in Z (the go/no-go kernel is narrow next to the friction's spread), which evenly
    spaced nodes resolve better than Hermite's, sparse in the middle (measured: doubling the
    nodes changes ln L less with this rule; docs/calibration.md).
    """
    x, w = np.polynomial.legendre.leggauss(n)
    z = Z_SPAN * x
    w = w * np.exp(-0.5 * z**2)
    return z, w / w.sum()


#: Normal scores of the table a parameter's value is interpolated in [1].
TABLE_SPAN, TABLE_SIZE = 8.0, 8001


@dataclasses.dataclass(frozen=True)
class Parameter:
    """One calibrated parameter, sampled as a normal score z ~ N(0, 1) a priori.

    Attributes
    ----------
    name : str
        ``"kinetics.activation_temperature"``, ``"mu[quartz]"``, ``"discrepancy[gold]"``...
    prior : scipy.stats frozen distribution or None
        Of the physical value (or of the factor, when `relative`); value = prior.ppf(Phi(z)).
        None: the sampled coordinate is the value itself.
    key : str or None
        Scene key it sets (None: a discrepancy or a hyper-parameter).
    targets : tuple of str
        Targets it applies to (empty: all).
    relative : bool
        The value is a factor on each target's nominal value of `key`.
    source : str
        Where the prior comes from.
    unit : str
        Unit of the physical value (``"1"`` for a factor).
    """

    name: str
    prior: object
    key: str | None = None
    targets: tuple[str, ...] = ()
    relative: bool = False
    source: str = ""
    unit: str = ""

    def value(self, z) -> np.ndarray:
        """Physical value (or factor) at normal score(s) `z`: the prior's quantile at Phi(z),
        interpolated in a table of :data:`TABLE_SIZE` scores over [-8, 8] (scipy's ppf of a
        truncated normal costs ~1 ms a call, the sampler makes 10^5; the table's relative
        error is below 1e-6, tested), clipped to the table's ends beyond it."""
        z = np.asarray(z, dtype=float)
        if self.prior is None:  # a parameter given by its values (predictions)
            return z
        grid, table = self._table
        return np.interp(z, grid, table)

    @functools.cached_property
    def _table(self):
        grid = np.linspace(-TABLE_SPAN, TABLE_SPAN, TABLE_SIZE)
        return grid, self.prior.ppf(special.ndtr(grid))

    def exact_value(self, z) -> np.ndarray:
        """The prior's quantile at Phi(z) without the table (scipy's ppf)."""
        return self.prior.ppf(np.clip(special.ndtr(np.asarray(z, dtype=float)), 1e-15,
                                      1 - 1e-15))

    def applies(self, target: str) -> bool:
        return not self.targets or target in self.targets


@dataclasses.dataclass(frozen=True)
class CalibrationTarget:
    """One target (scene) of the calibration with its drops.

    Attributes
    ----------
    name : str
    nominal : dict
        Scene key -> SI value of every surrogate key (the scene's nominal value; for an
        aleatory key at the median of its distribution).
    surrogate : Surrogate
    ln_heights : ndarray
        ln of the drop heights [ln m].
    went : ndarray of bool
        The drops' outcomes (go = event).
    quadrature : tuple of (key, distribution, relative, n)
        Aleatory inputs integrated by Gauss-Hermite over their normal score: the value at node z
        is ``distribution.ppf(Phi(z))`` (times the nominal, or the epistemic value, when
        relative).
    folded_sd : float
        ln H_c sd of the remaining aleatory inputs, folded into (1) as a normal kernel [1].
    experiment : str
        The report's experiment name (Table II row).
    """

    name: str
    nominal: Mapping[str, float]
    surrogate: Surrogate
    ln_heights: np.ndarray
    went: np.ndarray
    quadrature: tuple = ()
    folded_sd: float = 0.0
    experiment: str = ""

    _cache: dict = dataclasses.field(default_factory=dict, compare=False, hash=False,
                                     repr=False)

    def nodes(self, scale: float = 1.0):
        """(key -> factor-or-value array over the tensor nodes, weights), node counts x `scale`
        (computed once per scale)."""
        if scale not in self._cache:
            self._cache[scale] = self._nodes(scale)
        return self._cache[scale]

    def _nodes(self, scale: float):
        axes, weights, keys = [], [], []
        for key, dist, _relative, n in self.quadrature:
            z, w = normal_quadrature(max(2, int(round(n * scale))))
            u = np.clip(special.ndtr(z), 1e-15, 1 - 1e-15)
            axes.append(dist.ppf(u))
            weights.append(w)
            keys.append(key)
        if not axes:
            return {}, np.ones(1)
        grids = np.meshgrid(*axes, indexing="ij")
        wgrid = np.ones(())
        for w in weights:
            wgrid = np.multiply.outer(wgrid, w)
        return {k: g.ravel() for k, g in zip(keys, grids)}, wgrid.ravel()


@dataclasses.dataclass(frozen=True)
class FrictionPopulation:
    """The finishes' mean friction coefficients as draws from one population (hierarchical).

    ln mu_f ~ N(m, tau^2); m = ln(`median`) + `median_log_sd` z_m; tau = `sd` exp(`sd_log_sd`
    z_tau). The finishes calibrated are parameters ``mu[target]`` whose N(0, 1) prior is their
    measurement (the study's epistemic distribution: measured mean, log-sd of that mean); other
    measured finishes (`extra`: ln of the measured mean, its log-sd) enter through their
    marginal N(ln mu_meas; m, tau^2 + s^2).
    """

    median: float
    median_log_sd: float
    sd: float
    sd_log_sd: float
    extra: tuple[tuple[float, float], ...] = ()
    source: str = ""

    def hyper(self, z_m, z_tau):
        return math.log(self.median) + self.median_log_sd * z_m, self.sd * np.exp(
            self.sd_log_sd * z_tau)


def _norm_logpdf(x, mean, sd):
    return -0.5 * ((x - mean) / sd) ** 2 - np.log(sd) - 0.5 * math.log(2 * math.pi)


@dataclasses.dataclass(frozen=True)
class CalibrationModel:
    """The posterior of :mod:`skidmc.analysis.calibration`'s model (module docstring).

    Attributes
    ----------
    parameters : tuple of Parameter
        In the order of the sampled vector; the discrepancies are ``discrepancy[<target>]``
        (prior N(0, s_delta^2 + s_sur^2) of delta_t), the population's
        ``friction.population_median`` and ``friction.population_sd`` (normal scores).
    targets : tuple of CalibrationTarget
    misclassification : float
        eps [1].
    population : FrictionPopulation or None
    """

    parameters: tuple[Parameter, ...]
    targets: tuple[CalibrationTarget, ...]
    misclassification: float = 0.0
    population: FrictionPopulation | None = None

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(p.name for p in self.parameters)

    @property
    def ndim(self) -> int:
        return len(self.parameters)

    def index(self, name: str) -> int:
        return self.names.index(name)

    def values(self, z: np.ndarray) -> np.ndarray:
        """Physical values (..., ndim) of normal scores `z` (..., ndim)."""
        z = np.asarray(z, dtype=float)
        return np.stack([p.value(z[..., i]) for i, p in enumerate(self.parameters)], axis=-1)

    # -- per target ---------------------------------------------------------------------------

    def ln_critical_height(self, z: np.ndarray, target: CalibrationTarget,
                           node_scale: float = 1.0, values: np.ndarray | None = None):
        """Surrogate ln H_c [ln m] (W, J) at the walkers' `z` (W, ndim) and the quadrature nodes
        (J), discrepancy included, and the nodes' weights (J,); `values`: :meth:`values` of
        `z` if already computed."""
        z = np.atleast_2d(z)
        if values is None:
            values = self.values(z)
        inputs = {k: np.full((1, 1), v) for k, v in target.nominal.items()}
        delta = np.zeros((z.shape[0], 1))
        for i, p in enumerate(self.parameters):
            if not p.applies(target.name):
                continue
            v = values[:, i][:, None]
            if p.key is None:
                if p.name.startswith("discrepancy["):
                    delta = v
                continue
            if p.key not in inputs:
                continue  # the surrogate does not see it (constant in training)
            inputs[p.key] = inputs[p.key] * v if p.relative else v
        nodes, weights = target.nodes(node_scale)
        for key, values in nodes.items():
            relative = next(r for k, _d, r, _n in target.quadrature if k == key)
            if key in inputs:
                inputs[key] = inputs[key] * values[None, :] if relative else np.broadcast_to(
                    values[None, :], (1, values.size))
        return target.surrogate(inputs) + delta, weights

    def go_probability(self, z: np.ndarray, target: CalibrationTarget, ln_heights,
                       node_scale: float = 1.0, observed: bool = False,
                       values: np.ndarray | None = None) -> np.ndarray:
        """P(go | H, theta) (W, n) at ln heights [ln m] (n,), eq. (1); `observed`: with the
        misclassification eps applied."""
        g, w = self.ln_critical_height(z, target, node_scale, values)
        x = np.asarray(ln_heights, dtype=float)[None, None, :] - g[:, :, None]
        sd = target.folded_sd
        inner = special.ndtr(x / sd) if sd > 0 else (x >= 0).astype(float)
        p = np.einsum("wjn,j->wn", inner, w)
        if observed:
            p = self.misclassification + (1 - 2 * self.misclassification) * p
        return np.clip(p, 0.0, 1.0)

    def ln_h50(self, z: np.ndarray, target: CalibrationTarget, p: float = 0.5,
               iterations: int = 50) -> np.ndarray:
        """ln of the height where P(go | H, theta) = p (W,) [ln m], by bisection (to
        2^-50 of the bracket)."""
        g, w = self.ln_critical_height(z, target)
        span = 8 * max(target.folded_sd, 0.05)
        lo, hi = g.min(axis=1) - span, g.max(axis=1) + span
        sd = target.folded_sd
        for _ in range(iterations):
            mid = 0.5 * (lo + hi)
            x = mid[:, None] - g
            inner = special.ndtr(x / sd) if sd > 0 else (x >= 0).astype(float)
            below = inner @ w < p
            lo, hi = np.where(below, mid, lo), np.where(below, hi, mid)
        return 0.5 * (lo + hi)

    # -- densities ----------------------------------------------------------------------------

    def log_likelihood_drops(self, z: np.ndarray, node_scale: float = 1.0,
                             targets: Sequence[str] | None = None,
                             values: np.ndarray | None = None) -> np.ndarray:
        """Sum over drops of ln P(observed outcome | theta) (W,)."""
        z = np.atleast_2d(z)
        total = np.zeros(z.shape[0])
        if values is None:
            values = self.values(z)
        for t in self.targets:
            if targets is not None and t.name not in targets:
                continue
            if t.ln_heights.size == 0:
                continue
            p = self.go_probability(z, t, t.ln_heights, node_scale, observed=True,
                                    values=values)
            p = np.where(t.went[None, :], p, 1.0 - p)
            total += np.log(np.maximum(p, 1e-300)).sum(axis=1)
        return total

    def log_friction_population(self, z: np.ndarray,
                                values: np.ndarray | None = None) -> np.ndarray:
        """ln of the population's density of the finishes' means and of the other measured
        finishes (W,); 0 without a population."""
        z = np.atleast_2d(z)
        if values is None:
            values = self.values(z)
        if self.population is None:
            return np.zeros(z.shape[0])
        pop = self.population
        m, tau = pop.hyper(z[:, self.index("friction.population_median")],
                           z[:, self.index("friction.population_sd")])
        total = np.zeros(z.shape[0])
        for i, p in enumerate(self.parameters):
            if p.key != "mu":
                continue
            target = next(t for t in self.targets if p.applies(t.name))
            ln_mu = math.log(target.nominal["mu"]) + np.log(values[:, i])
            total += _norm_logpdf(ln_mu, m, tau)
        for ln_meas, s in pop.extra:
            total += _norm_logpdf(ln_meas, m, np.sqrt(tau**2 + s**2))
        return total

    def log_prior(self, z: np.ndarray) -> np.ndarray:
        z = np.atleast_2d(z)
        return -0.5 * (z**2).sum(axis=1)

    def log_posterior(self, z: np.ndarray, node_scale: float = 1.0,
                      targets: Sequence[str] | None = None) -> np.ndarray:
        """Unnormalized ln posterior density of the normal scores (W,) (emcee, vectorized)."""
        z = np.atleast_2d(z)
        values = self.values(z)
        out = (self.log_prior(z) + self.log_friction_population(z, values)
               + self.log_likelihood_drops(z, node_scale, targets, values))
        return np.where(np.isfinite(out), out, -np.inf)


# --- sampling and diagnostics -------------------------------------------------------------------


def _snooker_move():
    """emcee's differential-evolution snooker move (Ter Braak and Vrugt 2008) with its
    proposal corrected as in emcee's pull request #531 (merged 2024-12-20, in no release up to
    3.1.6): the unit vector along x - z is (x - z) / |x - z| (3.1.6 divides by |x - z|^(1/2))
    and the Metropolis correction is (ndim - 1) ln(|x' - z| / |x - z|) (3.1.6 halves it).
    3.1.6's move leaves the posterior's spread about 5 % too narrow (a 2-parameter grid check
    of the calibration: docs/calibration.md, "Validation")."""
    import emcee

    class SnookerMove(emcee.moves.DESnookerMove):
        def get_proposal(self, s, c, random):
            ns, ndim = s.shape
            nc = list(map(len, c))
            q = np.empty_like(s)
            metropolis = np.empty(ns, dtype=np.float64)
            for i in range(ns):
                w = np.array([c[j][random.randint(nc[j])] for j in range(3)])
                random.shuffle(w)
                z, z1, z2 = w
                delta = s[i] - z
                norm = np.linalg.norm(delta)
                u = delta / norm
                q[i] = s[i] + u * self.gammas * (np.dot(u, z1) - np.dot(u, z2))
                metropolis[i] = np.log(np.linalg.norm(q[i] - z)) - np.log(norm)
            return q, (ndim - 1.0) * metropolis

    return SnookerMove()


def run_emcee(log_prob: Callable[[np.ndarray], np.ndarray], ndim: int, *, walkers: int,
              burn: int, steps: int, thin: int, seed: int, initial: np.ndarray | None = None,
              progress: Callable[[int, int], None] | None = None):
    """Sample with emcee's affine-invariant ensemble sampler (walkers evaluated as a batch).

    Returns
    -------
    chain : ndarray (walkers, steps // thin, ndim)
        Kept draws after `burn` steps.
    lnp : ndarray (walkers, steps // thin)
    acceptance : float
        Mean acceptance fraction [1].
    """
    import emcee

    rng = np.random.default_rng(seed)
    p0 = rng.standard_normal((walkers, ndim)) if initial is None else np.asarray(initial)
    # Differential-evolution moves (80 %) with snooker updates (20 %), emcee's suggestion for
    # correlated posteriors: on the shipped calibration's 17 parameters their integrated
    # autocorrelation time is 71 steps (median; 81 largest) against 189 (205) for emcee's
    # default stretch move, over 5000 steps of 48 walkers
    # (scripts/calibration_autocorrelation.py; docs/calibration.md).
    moves = [(emcee.moves.DEMove(), 0.8), (_snooker_move(), 0.2)]
    sampler = emcee.EnsembleSampler(walkers, ndim, log_prob, vectorize=True, moves=moves)
    sampler._random = np.random.mtrand.RandomState(seed)  # emcee's own RNG, seeded
    state = p0
    total = burn + steps
    done = 0
    block = max(1, min(500, total))
    while done < total:
        n = min(block, total - done)
        state = sampler.run_mcmc(state, n, progress=False)
        done += n
        if progress is not None:
            progress(done, total)
    chain = sampler.get_chain(discard=burn, thin=thin)  # (steps, walkers, ndim)
    lnp = sampler.get_log_prob(discard=burn, thin=thin)
    return (np.swapaxes(chain, 0, 1), np.swapaxes(lnp, 0, 1),
            float(np.mean(sampler.acceptance_fraction)))


def diagnostics(posterior) -> dict[str, dict[str, float]]:
    """ArviZ R-hat (rank-normalized) and bulk and tail ESS per variable of `posterior` (an
    xarray Dataset with dims chain, draw, or InferenceData)."""
    import arviz as az

    rhat = az.rhat(posterior)
    bulk = az.ess(posterior, method="bulk")
    tail = az.ess(posterior, method="tail")
    return {name: {"r_hat": float(rhat[name]), "ess_bulk": float(bulk[name]),
                   "ess_tail": float(tail[name])} for name in rhat.data_vars}


# --- scores --------------------------------------------------------------------------------------


def log_score(p: np.ndarray, went: np.ndarray) -> float:
    """Mean log score ln P(observed outcome) over drops [nats]; higher is better."""
    p = np.clip(np.asarray(p, dtype=float), 1e-12, 1 - 1e-12)
    return float(np.mean(np.where(went, np.log(p), np.log1p(-p))))


def brier_score(p: np.ndarray, went: np.ndarray) -> float:
    """Mean Brier score (p - y)^2 over drops [1]; lower is better."""
    return float(np.mean((np.asarray(p, dtype=float) - np.asarray(went, dtype=float)) ** 2))


def quadrature_error(model: CalibrationModel, z: np.ndarray) -> dict[str, float]:
    """The quadrature's error measured by doubling the node counts at draws `z` (W, ndim):
    largest |Delta P(go)| over drops and draws, and largest |Delta ln L| over draws."""
    worst_p = 0.0
    for t in model.targets:
        if t.ln_heights.size:
            a = model.go_probability(z, t, t.ln_heights, 1.0)
            b = model.go_probability(z, t, t.ln_heights, 2.0)
            worst_p = max(worst_p, float(np.abs(a - b).max()))
    dl = model.log_likelihood_drops(z, 1.0) - model.log_likelihood_drops(z, 2.0)
    return {"max_abs_dp": worst_p, "max_abs_dloglik": float(np.abs(dl).max())}


def folded_sd(surrogate: Surrogate, nominal: Mapping[str, float],
              spreads: Mapping[str, tuple[float, float]]) -> float:
    """ln H_c sd of small aleatory inputs folded linearly: sqrt(sum (dg/dx_k sd_k)^2), with
    dg/dx_k the surrogate's central difference at `nominal` over each key's (value at Phi(-1),
    value at Phi(+1)) in `spreads` (SI) [1]."""
    total = 0.0
    base = {k: np.asarray(v, dtype=float) for k, v in nominal.items()}
    for key, (lo, hi) in spreads.items():
        if key not in surrogate.keys:
            continue
        a, b = dict(base), dict(base)
        a[key], b[key] = np.asarray(lo), np.asarray(hi)
        total += (0.5 * float(surrogate(b) - surrogate(a))) ** 2
    return math.sqrt(total)


def diagnostic_lines(diag: dict) -> list[str]:
    """The diagnostics per parameter, with the verdict (R-hat <= 1.01, ESS >= 400)."""
    ok = all(d["r_hat"] <= 1.01 and d["ess_bulk"] >= 400 and d["ess_tail"] >= 400
             for d in diag.values())
    width = max(len(k) for k in diag)
    out = [f"diagnostics (ArviZ; R-hat <= 1.01, bulk and tail ESS >= 400): "
           f"{'met' if ok else 'NOT met'}"]
    for k, d in diag.items():
        out.append(f"  {k:<{width}}  R-hat {d['r_hat']:.4f}  ESS bulk {d['ess_bulk']:.0f}  "
                   f"tail {d['ess_tail']:.0f}")
    return out


def normal_prior(sd: float):
    """N(0, sd^2) as a frozen distribution (the discrepancy's prior)."""
    return stats.norm(0.0, sd)


# --- building the model from a study ------------------------------------------------------------


def _same(a, b) -> bool:
    """Two distributions of the same key equal up to their source text."""
    return (a.key, a.name, a.params, a.relative, a.reference_temperature) == (
        b.key, b.name, b.params, b.relative, b.reference_temperature)


def _log_sd(dist) -> float:
    """Half the ln-range between the quantiles at Phi(-1) and Phi(+1) of a positive
    distribution (the log-sd of a log-normal) [1]."""
    lo, hi = dist.frozen.ppf([special.ndtr(-1.0), special.ndtr(1.0)])
    return 0.5 * math.log(hi / lo)


def epistemic_parameters(study) -> list[Parameter]:
    """The calibrated physical parameters of a study: one per epistemic key, shared by the
    scenes whose distributions of it agree (``"he.conductivity"``; a subset of scenes is named,
    ``"target.conductivity[alumina-smooth+alumina-rough]"``), and one friction mean per scene
    (``"mu[quartz]"``: each scene is a finish)."""
    from skidmc.ensemble.study_model import EXTRA_KEYS
    from skidmc.scene import SI_UNITS

    params: list[Parameter] = []
    names = [sc.name for sc in study.scenes]
    for key in study.keys:
        if ":" in key or study.kind(key) != "epistemic":
            continue
        holders = [sc for sc in study.scenes if key in sc.uncertain
                   and sc.uncertain[key].kind == "epistemic"]
        unit = SI_UNITS.get(key) or EXTRA_KEYS.get(key, ("",))[0]
        if key == "mu":
            for sc in holders:
                d = sc.uncertain[key]
                params.append(Parameter(f"mu[{sc.name}]", d.frozen, key, (sc.name,), d.relative,
                                        d.source, "1" if d.relative else unit))
            continue
        groups: list[list] = []
        for sc in holders:
            for g in groups:
                if _same(g[0].uncertain[key], sc.uncertain[key]) and (
                        not sc.uncertain[key].relative
                        or g[0].nominal(key) == sc.nominal(key)):
                    g.append(sc)
                    break
            else:
                groups.append([sc])
        for g in groups:
            d = g[0].uncertain[key]
            scenes = tuple(sc.name for sc in g)
            name = key if list(scenes) == names else f"{key}[{'+'.join(scenes)}]"
            params.append(Parameter(name, d.frozen, key, scenes, d.relative, d.source,
                                    "1" if d.relative else unit))
    return params


def target_from_scene(sc, surrogate: Surrogate, quadrature: Mapping[str, int], *,
                      ln_heights=(), went=(), experiment: str = "") -> CalibrationTarget:
    """A :class:`CalibrationTarget` of a study scene: its nominal values, the aleatory inputs
    integrated by quadrature (`quadrature`: key -> nodes) and the others folded."""
    nominal: dict[str, float] = {}
    quad, spreads = [], {}
    u = special.ndtr(np.array([-1.0, 1.0]))
    for key in surrogate.keys:
        base = sc.nominal(key)
        aleatory = sc.factors.get(key) or (
            sc.uncertain[key] if key in sc.uncertain and sc.uncertain[key].kind == "aleatory"
            else None)
        relative = aleatory is None or aleatory.relative or key in sc.factors
        if aleatory is None:
            nominal[key] = base
        elif key in quadrature:
            nominal[key] = base if relative else 1.0
            quad.append((key, aleatory.frozen, relative, int(quadrature[key])))
        else:
            nominal[key] = base * aleatory.frozen.ppf(0.5) if relative else float(
                aleatory.frozen.ppf(0.5))
            lo, hi = aleatory.frozen.ppf(u)
            spreads[key] = (base * lo, base * hi) if relative else (lo, hi)
    for key, _dist, relative, _n in quad:
        if not relative:
            nominal[key] = 1.0  # replaced by the node's value
    return CalibrationTarget(
        sc.name, nominal, surrogate, np.log(np.asarray(ln_heights, dtype=float))
        if len(ln_heights) else np.zeros(0), np.asarray(went, dtype=bool), tuple(quad),
        folded_sd(surrogate, nominal, spreads), experiment)


def build_model(study, surrogates: Mapping[str, Surrogate], drops: Mapping[str, tuple],
                *, quadrature: Mapping[str, int], discrepancy_sd: float,
                misclassification: float = 0.0,
                population: FrictionPopulation | None = None) -> CalibrationModel:
    """The :class:`CalibrationModel` of a study (its epistemic inputs are the priors).

    Parameters
    ----------
    study : skidmc.ensemble.study_model.Study
    surrogates : mapping
        Scene name -> :class:`Surrogate` of its ln H_c.
    drops : mapping
        Scene name -> (heights [m], went) of its drops.
    quadrature : mapping
        Aleatory key -> Gauss-Hermite nodes (the others are folded linearly).
    discrepancy_sd : float
        s_delta, prior sd of each target's ln H_c discrepancy [1]; the surrogate's held-out
        rmse is added in quadrature.
    misclassification : float
        eps [1].
    population : FrictionPopulation, optional
    """
    params = epistemic_parameters(study)
    targets = []
    for sc in study.scenes:
        h, went = drops.get(sc.name, ((), ()))
        t = target_from_scene(sc, surrogates[sc.name], quadrature, ln_heights=h, went=went,
                              experiment=sc.experiment or "")
        targets.append(t)
        sd = math.hypot(discrepancy_sd, surrogates[sc.name].rmse_holdout)
        params.append(Parameter(f"discrepancy[{sc.name}]", stats.norm(0.0, sd), None,
                                (sc.name,), False,
                                f"s_delta {discrepancy_sd:g} (study) and the surrogate's held-out"
                                f" rmse {surrogates[sc.name].rmse_holdout:.3g} in quadrature",
                                "1"))
    if population is not None:
        params.append(Parameter("friction.population_median",
                                stats.lognorm(population.median_log_sd, scale=population.median),
                                None, (), False, population.source, "1"))
        params.append(Parameter("friction.population_sd",
                                stats.lognorm(population.sd_log_sd, scale=population.sd),
                                None, (), False, population.source, "1"))
    return CalibrationModel(tuple(params), tuple(targets), misclassification, population)


def finish_friction_draws(model: CalibrationModel, z: np.ndarray, measured: float,
                          log_sd: float, rng: np.random.Generator) -> np.ndarray:
    """Draws of a new finish's mean friction given its measurement (`measured`, log-sd
    `log_sd`) and the population at the posterior draws `z` (conjugate normal in ln mu); without
    a population, the measurement alone."""
    if model.population is None:
        return measured * np.exp(log_sd * rng.standard_normal(len(z)))
    m, tau = model.population.hyper(z[:, model.index("friction.population_median")],
                                    z[:, model.index("friction.population_sd")])
    prec = 1 / tau**2 + 1 / log_sd**2
    mean = (m / tau**2 + math.log(measured) / log_sd**2) / prec
    return np.exp(mean + rng.standard_normal(len(z)) / np.sqrt(prec))


# --- validation: simulation-based calibration and recovery -------------------------------------


def simulate_drops(model: CalibrationModel, z_true: np.ndarray,
                   rng: np.random.Generator, repeat: int = 1,
                   center: bool = False) -> CalibrationModel:
    """The model with its targets' outcomes replaced by draws from the model itself at the
    normal scores `z_true` (ndim,): each target's drop heights (each repeated `repeat` times),
    outcome ~ Bernoulli(P(observed go | H, theta_true)) (eq. (1) with the misclassification).
    `center`: the heights are first shifted (in ln H) so that their geometric mean is the true
    H50, as an experimenter bracketing the 50 % point would place them."""
    targets = []
    for t in model.targets:
        ln_h = np.repeat(t.ln_heights, repeat)
        if center and ln_h.size:
            ln_h = ln_h - ln_h.mean() + model.ln_h50(z_true[None, :], t)[0]
        p = model.go_probability(z_true[None, :], t, ln_h, observed=True)[0]
        targets.append(dataclasses.replace(t, ln_heights=ln_h, went=rng.random(ln_h.size) < p,
                                           _cache=t._cache))
    return dataclasses.replace(model, targets=tuple(targets))


#: How :func:`sbc_ranks` picks the posterior draws a truth is ranked among: ``separated``,
#: whole ensembles at ceil(draws / walkers) steps spaced steps / k apart (the walkers of one
#: step are independent draws of a converged ensemble, and steps 200 apart at the shipped
#: settings are 6 autocorrelation times of 31 steps apart: Talts et al.'s thinning to
#: independent draws); ``spread``, the earlier choice, draws evenly spaced over the chain in
#: time order (consecutive picks 6 steps apart in neighbouring walkers, so correlated: that
#: piles ranks at the ends, Talts et al. Sec. 5.1).
SBC_PICKS = ("separated", "spread")


def _sbc_pick(chain: np.ndarray, draws: int, pick: str) -> np.ndarray:
    """`draws` posterior draws (draws, ndim) out of a chain (walkers, steps, ndim)."""
    walkers, steps, ndim = chain.shape
    if pick == "spread":
        flat = np.swapaxes(chain, 0, 1).reshape(-1, ndim)  # steps x walkers, in time order
        return flat[np.linspace(0, len(flat) - 1, draws).astype(int)]
    if pick == "separated":
        k = -(-draws // walkers)  # ensembles needed
        if k > steps:
            raise ValueError(f"draws = {draws}: more than walkers x steps = {walkers * steps}")
        at = (np.arange(1, k + 1) * steps) // k - 1  # steps/k apart, ending at the last
        per = -(-draws // k)  # walkers per ensemble
        return chain[:per][:, at, :].reshape(-1, ndim)[:draws]
    raise ValueError(f"pick = {pick!r}: expected one of {', '.join(SBC_PICKS)}")


def sbc_rank_sets(model: CalibrationModel, replications: int, *, draws: int, walkers: int,
                  burn: int, steps: int, seed: int, picks: Sequence[str] = ("separated",),
                  progress: Callable[[int], None] | None = None) -> dict[str, np.ndarray]:
    """Simulation-based calibration (Talts et al. 2018): for each replication, normal scores
    drawn from the prior, drops simulated by the model (:func:`simulate_drops`), the posterior
    sampled by :func:`run_emcee`, and the rank of each true score among `draws` posterior
    draws taken from the kept chain in each way of `picks` (:data:`SBC_PICKS`), all from the
    same chains.

    The model's prior must be what it samples from: N(0, 1) per score, so a model with a
    friction population (a further factor on the scores) is refused.

    Returns
    -------
    dict
        Pick -> ndarray (replications, ndim) of int, ranks in 0..`draws`; uniform when the
        sampler and likelihood are right and the draws independent.
    """
    if model.population is not None:
        raise ValueError("sbc_ranks: the model's prior must be N(0, 1) per score (no friction "
                         "population): build it with population=None")
    for pick in picks:
        if pick not in SBC_PICKS:
            raise ValueError(f"pick = {pick!r}: expected one of {', '.join(SBC_PICKS)}")
    rng = np.random.default_rng(seed)
    ranks = {pick: np.zeros((replications, model.ndim), dtype=int) for pick in picks}
    for r in range(replications):
        z_true = rng.standard_normal(model.ndim)
        sim = simulate_drops(model, z_true, rng)
        chain, _lnp, _acc = run_emcee(sim.log_posterior, sim.ndim, walkers=walkers, burn=burn,
                                      steps=steps, thin=1, seed=int(rng.integers(2**31)))
        for pick in picks:
            ranks[pick][r] = (_sbc_pick(chain, draws, pick) < z_true[None, :]).sum(axis=0)
        if progress is not None:
            progress(r + 1)
    return ranks


def sbc_ranks(model: CalibrationModel, replications: int, *, draws: int, walkers: int,
              burn: int, steps: int, seed: int, pick: str = "separated",
              progress: Callable[[int], None] | None = None) -> np.ndarray:
    """The ranks of :func:`sbc_rank_sets` for one way of picking the draws (`pick`).

    Returns
    -------
    ndarray (replications, ndim) of int
        Ranks in 0..`draws`; uniform when the sampler and likelihood are right.
    """
    return sbc_rank_sets(model, replications, draws=draws, walkers=walkers, burn=burn,
                         steps=steps, seed=seed, picks=(pick,), progress=progress)[pick]


def rank_uniformity(ranks: np.ndarray, draws: int, bins: int = 10) -> dict:
    """Chi-square test of the SBC ranks' uniformity per parameter and pooled over parameters.

    Ranks 0..`draws` fall into `bins` bins of equal width ((`draws` + 1) / `bins` ranks each;
    `draws` + 1 must be a multiple of `bins`).

    Returns
    -------
    dict
        ``"per_parameter"``: list of (chi2, p) [1]; ``"pooled"``: (chi2, dof, p), the sum of
        the per-parameter statistics against chi-square with ndim (bins - 1) degrees of freedom
        (the parameters' ranks are treated as independent: an approximation, as a
        replication's ranks share its data); ``"min_p_bonferroni"``: smallest per-parameter p
        times ndim, capped at 1.
    """
    if (draws + 1) % bins:
        raise ValueError(f"draws + 1 = {draws + 1} is not a multiple of bins = {bins}")
    width = (draws + 1) // bins
    out = []
    for j in range(ranks.shape[1]):
        counts = np.bincount(ranks[:, j] // width, minlength=bins)
        chi2, p = stats.chisquare(counts)
        out.append((float(chi2), float(p)))
    total = sum(c for c, _ in out)
    dof = ranks.shape[1] * (bins - 1)
    return {"per_parameter": out, "pooled": (total, dof, float(stats.chi2.sf(total, dof))),
            "min_p_bonferroni": min(1.0, min(p for _, p in out) * ranks.shape[1])}


def recovery(model: CalibrationModel, z_true: np.ndarray, *, repeats: Sequence[int],
             walkers: int, burn: int, steps: int, seed: int) -> list[dict]:
    """Posterior of synthetic drop sets made at known scores `z_true`: for each repeat factor
    (1: the report's drop set; 10: each drop ten times), the report's heights per target
    shifted to centre on the true H50 (:func:`simulate_drops`), per target the true ln H50
    [ln m] and its posterior median, sd and whether it lies in the central 95 %, and per
    parameter the posterior sd of its normal score (1 = the prior's)."""
    rng = np.random.default_rng(seed)
    out = []
    for k in repeats:
        sim = simulate_drops(model, z_true, rng, repeat=k, center=True)
        chain, _lnp, _acc = run_emcee(sim.log_posterior, sim.ndim, walkers=walkers, burn=burn,
                                      steps=steps, thin=10, seed=seed + k)
        z = chain.reshape(-1, sim.ndim)
        row = {"repeat": k, "drops": int(sum(t.went.size for t in sim.targets)),
               "score_sd": {p.name: float(z[:, i].std()) for i, p in enumerate(sim.parameters)},
               "targets": {}}
        for t in sim.targets:
            truth = float(sim.ln_h50(z_true[None, :], t)[0])
            h = sim.ln_h50(z[::4], t)
            lo, hi = np.quantile(h, [0.025, 0.975])
            row["targets"][t.name] = {"true": truth, "median": float(np.median(h)),
                                      "sd": float(h.std()), "inside_95": bool(lo <= truth <= hi)}
        out.append(row)
    return out
