"""Bayesian probit fit of go/no-go drops: a posterior H50 and its interval, even without an MLE.

The model is the one of :mod:`skidmc.analysis.gonogo` (``docs/go-no-go.md``): a drop from height
h goes with probability P(go | h) = Phi((x - m) / sigma), x = ln h (or log10 h), with a normal
prior on the location m (the log of H50) and a normal prior on ln sigma. Where the go and no-go
heights do not overlap (every target of the report) the likelihood keeps rising as sigma -> 0 and
the maximum-likelihood estimate does not exist (:func:`~skidmc.analysis.gonogo.fit_probit`); the
posterior still does, because the prior on ln sigma is proper.

Computation: the posterior has two parameters, so it is computed on a grid, deterministically,
rather than sampled by MCMC (emcee is installed and would work, but adds Monte Carlo error, a
burn-in and convergence checks to a problem that a quadrature solves to any precision in
milliseconds). The grid's box adapts to the posterior: it starts from the prior's +-10 sd, is
shrunk to where the log posterior lies within 25 of its maximum (so the mass left out is below
about e^-25 per cell) and extended where that region touches an edge. Each cell holds the
posterior density at its centre times its area (midpoint rule); within a cell the mass is taken
as uniform in the location, so a quantile q_p = m + z_p sigma has a piecewise-linear
distribution function row by row, which is inverted exactly (``brentq``). The error of this
quadrature is measured against an independent adaptive integration (``scipy.integrate.quad``) in
``tests/test_posterior.py``: below 1e-3 relative on H50 and on the interval's ends. Draws are
exact samples of that piecewise-constant density (a cell drawn by its mass, a uniform point
within it); summaries (``h50``, ``quantile``) come from the grid itself, free of Monte Carlo
error.

Priors enter through a small interface (:class:`NormalPrior`, ``logpdf(m, log_sigma)``,
``location``, ``log_sigma``) so that a calibration posterior (issue 40 B) can replace the normal
priors later. :func:`physics_prior` reads the model's own prior predictive per target from a
shipped CSV (``skidmc/data/priors/``, written by ``scripts/physics_prior.py``).
"""

from __future__ import annotations

import csv
import math
from dataclasses import dataclass, field
from importlib import resources

import numpy as np
import xarray as xr
from scipy import optimize, special

from skidmc.analysis.checks import bad as _bad
from skidmc.scene.units import FOOT

__all__ = [
    "NormalPrior",
    "ProbitPosterior",
    "physics_prior",
    "posterior_from_prior",
    "posterior_h50_table",
    "probit_posterior",
    "vague_prior",
]

_SCALES = {"ln": 1.0, "log10": 1.0 / math.log(10.0)}  # x = factor * ln h
_SHIPPED_PRIOR = "paper_series1_h50.csv"
_DROP_TARGETS = ("quartz", "alumina_20_35", "alumina_50_80", "gold")

#: The physics prior's sd of ln sigma [-]: the model's own aleatory spread varies by ~1 % between
#: epistemic draws, but it is set by the friction scatter of the study (20 % per drop, a
#: judgement in studies/paper-series1.toml); 0.5 lets sigma be a factor 2 off at 1.4 sd.
PHYSICS_LOG_SIGMA_SD = 0.5

#: The vague prior: location sd ln 10 (a decade at one sd), ln sigma ~ N(ln 0.3, 1) (sigma within
#: 0.04-2.1 at 95 %; 0.3 is a round value between the model's aleatory spread, 0.37, and the
#: spreads that put the report's mixed quartz drops at 1.5 and 2.12 ft within a sigma or two).
VAGUE_LOCATION_SD = math.log(10.0)
VAGUE_LOG_SIGMA = (math.log(0.3), 1.0)


def _normal_pair(name, value) -> tuple[float, float]:
    try:
        mean, sd = (float(v) for v in value)
    except (TypeError, ValueError):
        raise _bad(name, value, "must be a pair (mean, sd) of numbers") from None
    if not (math.isfinite(mean) and math.isfinite(sd) and sd > 0):
        raise _bad(name, value, "must be (finite mean, sd > 0)")
    return mean, sd


# --------------------------------------------------------------------------------------------
# priors


@dataclass(frozen=True)
class NormalPrior:
    """Independent normal priors on the location m = log H50 and on ln sigma.

    The interface the grid posterior needs from any prior: ``logpdf(m, log_sigma)`` (up to a
    constant) and ``location``/``log_sigma`` (mean, sd) pairs that say where the prior's mass is
    (used for the starting box and for starting values of classical procedures). A calibration
    posterior can replace it by any object with the same three members.

    Attributes
    ----------
    location : (float, float)
        Mean and sd of m [log of the height unit, in ``scale``].
    log_sigma : (float, float)
        Mean and sd of ln sigma, sigma in ``scale`` [-].
    unit : str
        Height unit the location refers to ("ft", "m", or any label).
    scale : {"ln", "log10"}
    source : str
        Where the numbers come from, in words.
    """

    location: tuple[float, float]
    log_sigma: tuple[float, float]
    unit: str = ""
    scale: str = "ln"
    source: str = ""

    def __post_init__(self):
        object.__setattr__(self, "location", _normal_pair("prior_location", self.location))
        object.__setattr__(self, "log_sigma", _normal_pair("prior_log_sigma", self.log_sigma))
        if self.scale not in _SCALES:
            raise _bad("scale", self.scale, 'must be "ln" or "log10"')

    def logpdf(self, m, log_sigma):
        """Log prior density (up to a constant) at location m and ln sigma (arrays broadcast)."""
        (m0, s0), (l0, t0) = self.location, self.log_sigma
        m, log_sigma = np.asarray(m), np.asarray(log_sigma)
        return -0.5 * ((m - m0) / s0) ** 2 - 0.5 * ((log_sigma - l0) / t0) ** 2

    def sample(self, n: int, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
        """n draws of (m, sigma) from the prior."""
        (m0, s0), (l0, t0) = self.location, self.log_sigma
        return rng.normal(m0, s0, n), np.exp(rng.normal(l0, t0, n))

    @property
    def h50(self) -> float:
        """Prior median of H50 [``unit``]."""
        return float(np.exp(self.location[0] / _SCALES[self.scale]))

    def describe(self) -> str:
        (m0, s0), (l0, t0) = self.location, self.log_sigma
        log = "ln" if self.scale == "ln" else "log10"
        return (f"{log} H50 ~ N({m0:.3g}, {s0:.3g}) (median {self.h50:.3g} {self.unit}), "
                f"ln sigma ~ N({l0:.3g}, {t0:.3g}) (median sigma {math.exp(l0):.3g})"
                + (f"; {self.source}" if self.source else ""))


def _read_prior_csv(name: str = _SHIPPED_PRIOR):
    text = resources.files("skidmc").joinpath("data", "priors", name).read_text(encoding="utf-8")
    lines = text.splitlines()
    comments = [line[1:].strip() for line in lines if line.startswith("#")]
    rows = list(csv.DictReader(line for line in lines if line.strip() and not line.startswith("#")))
    return comments, rows


def physics_prior(experiment: str, *, units: str = "ft", discrepancy_sd: float = 0.0,
                  log_sigma_sd: float = PHYSICS_LOG_SIGMA_SD) -> NormalPrior:
    """The model's prior predictive of H50 and sigma for one of the report's targets.

    Read from the shipped CSV (``skidmc/data/priors/paper_series1_h50.csv``, written by
    ``scripts/physics_prior.py`` from the ``paper-series1`` ensemble): per epistemic draw the
    median critical height (ln H50) and the spread of ln H_c over the aleatory inputs. The prior
    on ln H50 is the normal with the draws' mean and sd; the prior on ln sigma is centred on the
    draws' median spread, with sd ``log_sigma_sd`` (see :data:`PHYSICS_LOG_SIGMA_SD`).

    Parameters
    ----------
    experiment : str
        "quartz", "alumina_20_35", "alumina_50_80" or "gold" (names of
        :data:`skidmc.analysis.experiments.EXPERIMENTS`).
    units : {"ft", "m"}, optional
    discrepancy_sd : float, optional
        A model-discrepancy sd [-] added in quadrature to the sd of ln H50 (0: the model taken
        as it is; the calibration issue is to estimate it).
    log_sigma_sd : float, optional
        Prior sd of ln sigma [-].

    Returns
    -------
    NormalPrior
        In the ln scale, location in ln(``units``).
    """
    if units not in ("ft", "m"):
        raise _bad("units", units, 'must be "ft" or "m"')
    if not (discrepancy_sd >= 0 and math.isfinite(discrepancy_sd)):
        raise _bad("discrepancy_sd", discrepancy_sd, "must be a finite number >= 0")
    comments, rows = _read_prior_csv()
    mine = [r for r in rows if r["experiment"] == experiment]
    if not mine:
        known = sorted({r["experiment"] for r in rows})
        raise _bad("experiment", experiment, f"no physics prior; choose from {', '.join(known)}")
    ln_h50 = np.array([float(r["ln_h50_ft"]) for r in mine])
    sigma = np.array([float(r["sigma_ln"]) for r in mine])
    shift = 0.0 if units == "ft" else math.log(FOOT)
    sd = math.hypot(float(np.std(ln_h50, ddof=1)), discrepancy_sd)
    source = (f"model prior predictive, {mine[0]['scene']} scene of paper-series1 "
              f"({len(mine)} epistemic draws)"
              + (f", discrepancy sd {discrepancy_sd:g}" if discrepancy_sd else ""))
    return NormalPrior((float(np.mean(ln_h50)) + shift, sd),
                       (math.log(float(np.median(sigma))), log_sigma_sd), units, "ln", source)


def vague_prior(center_height: float, *, units: str = "ft") -> NormalPrior:
    """A weak prior: ln H50 ~ N(ln center_height, ln 10), ln sigma ~ N(ln 0.3, 1).

    Parameters
    ----------
    center_height : float
        A guess of H50 [``units``] (e.g. the geometric mean of the drop heights, or the height an
        analyst would start an up-down sequence at).
    units : str, optional
        Label of the height unit.
    """
    if not (center_height > 0 and math.isfinite(center_height)):
        raise _bad("center_height", center_height, "must be a finite height > 0")
    return NormalPrior((math.log(center_height), VAGUE_LOCATION_SD), VAGUE_LOG_SIGMA, units, "ln",
                       f"vague: a decade at 1 sd around {center_height:.3g} {units}")


# --------------------------------------------------------------------------------------------
# the grid


class _Grid:
    """Posterior of (m, ln sigma) on a regular grid of cells; see the module docstring."""

    def __init__(self, m_edges: np.ndarray, s_edges: np.ndarray, logw: np.ndarray):
        self.m_edges, self.s_edges = m_edges, s_edges
        self.m = 0.5 * (m_edges[1:] + m_edges[:-1])
        self.log_sigma = 0.5 * (s_edges[1:] + s_edges[:-1])
        self.sigma = np.exp(self.log_sigma)
        self.dm = m_edges[1] - m_edges[0]
        self.logw = logw  # shape (n_sigma, n_m)
        top = float(np.max(logw))
        w = np.exp(logw - top)
        total = float(w.sum())
        self.w = w / total
        self.log_evidence = top + math.log(total)  # of the unnormalised cell masses
        self._cdf_rows = None

    # ---- distribution of q = m + z sigma -------------------------------------------------
    def _rows(self):
        if self._cdf_rows is None:
            self._cdf_rows = np.concatenate(
                [np.zeros((self.w.shape[0], 1)), np.cumsum(self.w, axis=1)], axis=1)
        return self._cdf_rows

    def cdf(self, t: float, z: float) -> float:
        """P(m + z sigma <= t) with mass uniform in m within each cell."""
        rows = self._rows()
        u = (t - z * self.sigma - self.m_edges[0]) / self.dm  # position in cells, per row
        n = self.m.size
        k = np.clip(np.floor(u).astype(int), 0, n - 1)
        frac = np.clip(u - k, 0.0, 1.0)
        j = np.arange(rows.shape[0])
        below = np.where(u <= 0, 0.0, np.where(u >= n, rows[:, -1],
                                               rows[j, k] + frac * (rows[j, k + 1] - rows[j, k])))
        return float(below.sum())

    def quantile_of(self, z: float, alpha: float) -> float:
        """The alpha quantile of q = m + z sigma [log scale]."""
        lo = self.m_edges[0] + min(z * self.sigma[0], z * self.sigma[-1]) - 1e-9
        hi = self.m_edges[-1] + max(z * self.sigma[0], z * self.sigma[-1]) + 1e-9
        return optimize.brentq(lambda t: self.cdf(t, z) - alpha, lo, hi, xtol=1e-12, rtol=1e-13)

    def moments(self, z: float = 0.0) -> tuple[float, float]:
        """Mean and variance of q = m + z sigma (within-cell spread in m included)."""
        q = self.m[None, :] + z * self.sigma[:, None]
        mean = float(np.sum(self.w * q))
        var = float(np.sum(self.w * (q - mean) ** 2)) + self.dm**2 / 12.0
        return mean, var

    def sample(self, n: int, rng: np.random.Generator):
        cells = rng.choice(self.w.size, size=n, p=self.w.ravel())
        j, i = np.unravel_index(cells, self.w.shape)
        ds = self.s_edges[1] - self.s_edges[0]
        m = self.m_edges[i] + self.dm * rng.random(n)
        log_sigma = self.s_edges[j] + ds * rng.random(n)
        return m, np.exp(log_sigma)

    def prob_go(self, x) -> np.ndarray:
        """Posterior predictive P(go) at log heights x."""
        x = np.atleast_1d(np.asarray(x, float))
        p = special.ndtr((x[:, None, None] - self.m[None, None, :]) / self.sigma[None, :, None])
        return np.sum(p * self.w[None], axis=(1, 2))


def _log_posterior(prior, x, went, m, log_sigma):
    """Log prior + log likelihood on the grid m (n_m) x log_sigma (n_s): shape (n_s, n_m).

    Drops at the same height with the same outcome are counted once with their multiplicity,
    and the rest are summed in blocks of about two million terms.
    """
    mm, ll = np.meshgrid(m, log_sigma)
    out = np.asarray(prior.logpdf(mm, ll), float).copy()
    if not len(x):
        return out
    signed, counts = np.unique(np.column_stack([np.asarray(x, float),
                                                np.where(went, 1.0, -1.0)]),
                               axis=0, return_counts=True)
    inv = np.exp(-log_sigma)[None, :, None]
    block = max(1, 2_000_000 // mm.size)
    for start in range(0, len(counts), block):
        xs, sg = signed[start:start + block, 0], signed[start:start + block, 1]
        u = sg[:, None, None] * (xs[:, None, None] - m[None, None, :]) * inv
        out += np.tensordot(counts[start:start + block].astype(float), special.log_ndtr(u),
                            axes=1)
    return out


def _build_grid(prior, x, went, shape=(161, 401), *, threshold=25.0, max_iter=40,
                coarse=None) -> _Grid:
    """A grid posterior whose box holds the region where log post > max - threshold.

    ``shape`` is (cells in ln sigma, cells in m) of the final grid; ``coarse`` that of the grids
    that find the box (default: a third of ``shape``, at least 41 x 61).
    """
    n_s, n_m = shape
    (m0, s0), (l0, t0) = prior.location, prior.log_sigma
    box = [m0 - 10 * s0, m0 + 10 * s0, l0 - 10 * t0, l0 + 10 * t0]
    if len(x):
        box[0], box[1] = min(box[0], float(np.min(x)) - 1.0), max(box[1], float(np.max(x)) + 1.0)
    if coarse is None:
        coarse = (max(41, n_s // 3), max(61, n_m // 3))
    for _ in range(max_iter):
        m_edges = np.linspace(box[0], box[1], coarse[1] + 1)
        s_edges = np.linspace(box[2], box[3], coarse[0] + 1)
        m = 0.5 * (m_edges[1:] + m_edges[:-1])
        s = 0.5 * (s_edges[1:] + s_edges[:-1])
        lp = _log_posterior(prior, x, went, m, s)
        keep = lp > lp.max() - threshold
        rows, cols = np.flatnonzero(keep.any(axis=1)), np.flatnonzero(keep.any(axis=0))
        dm, ds = m_edges[1] - m_edges[0], s_edges[1] - s_edges[0]
        new = [m_edges[cols[0]] - dm, m_edges[cols[-1] + 1] + dm,
               s_edges[rows[0]] - ds, s_edges[rows[-1] + 1] + ds]
        grown = False
        # the region touches an edge: extend the box that way by its width
        if cols[0] == 0:
            new[0], grown = box[0] - (box[1] - box[0]), True
        if cols[-1] == m.size - 1:
            new[1], grown = box[1] + (box[1] - box[0]), True
        if rows[0] == 0:
            new[2], grown = box[2] - (box[3] - box[2]), True
        if rows[-1] == s.size - 1:
            new[3], grown = box[3] + (box[3] - box[2]), True
        shrink = ((new[1] - new[0]) < 0.6 * (box[1] - box[0])
                  or (new[3] - new[2]) < 0.6 * (box[3] - box[2]))
        box = new
        if not grown and not shrink:
            break
    m_edges = np.linspace(box[0], box[1], n_m + 1)
    s_edges = np.linspace(box[2], box[3], n_s + 1)
    m = 0.5 * (m_edges[1:] + m_edges[:-1])
    s = 0.5 * (s_edges[1:] + s_edges[:-1])
    return _Grid(m_edges, s_edges, _log_posterior(prior, x, went, m, s))


# --------------------------------------------------------------------------------------------
# the result


@dataclass(frozen=True)
class ProbitPosterior:
    """Posterior of the probit model on log height (from :func:`probit_posterior`).

    Attributes
    ----------
    location : ndarray
        Posterior draws of the location m [log of the input unit, in ``scale``].
    sigma : ndarray
        Posterior draws of sigma [-] (sd of log h_c in ``scale``).
    scale : {"ln", "log10"}
    credibility : float
        Level of the equal-tailed intervals of :meth:`quantile`.
    prior : NormalPrior
    n, n_go : int
        Number of drops and of gos.
    """

    location: np.ndarray
    sigma: np.ndarray
    scale: str
    credibility: float
    prior: NormalPrior
    n: int
    n_go: int
    _grid: _Grid = field(repr=False, compare=False)

    def _to_height(self, v: float) -> float:
        return float(np.exp(v / _SCALES[self.scale]))

    def quantile(self, p: float = 0.5,
                 credibility: float | None = None) -> tuple[float, float, float]:
        """Height at which P(go) = p: posterior median and equal-tailed credible interval.

        Parameters
        ----------
        p : float
            Probability of a go, in (0, 1).
        credibility : float, optional
            Level of the interval (default: the fit's ``credibility``).

        Returns
        -------
        (median, low, high) : tuple of float
            In the unit of the input heights; from the grid (no Monte Carlo error).
        """
        if not 0.0 < float(p) < 1.0:
            raise _bad("p", p, "must be a probability in (0, 1)")
        level = self.credibility if credibility is None else float(credibility)
        if not 0.0 < level < 1.0:
            raise _bad("credibility", credibility, "must be in (0, 1)")
        z = float(special.ndtri(p))
        tail = 0.5 * (1.0 - level)
        return tuple(self._to_height(self._grid.quantile_of(z, a))
                     for a in (0.5, tail, 1.0 - tail))

    @property
    def h50(self) -> float:
        """Posterior median of H50 [input unit]."""
        return self.quantile(0.5)[0]

    @property
    def h50_interval(self) -> tuple[float, float]:
        """Equal-tailed credible interval of H50 at ``credibility`` [input unit]."""
        return self.quantile(0.5)[1:]

    def sigma_quantile(self, alpha) -> float:
        """The alpha quantile of sigma's posterior [-] (from the grid)."""
        g = self._grid
        cdf = np.concatenate([[0.0], np.cumsum(g.w.sum(axis=1))])
        return float(np.exp(np.interp(alpha, cdf, g.s_edges)))

    def prob_go(self, heights) -> np.ndarray:
        """Posterior predictive P(go | h) at heights [input unit]."""
        x = np.log(np.asarray(heights, float)) * _SCALES[self.scale]
        return self._grid.prob_go(x)


def probit_posterior(heights, went, *, prior_location, prior_log_sigma, scale: str = "ln",
                     credibility: float = 0.95, draws: int = 4000, seed=None,
                     grid: tuple[int, int] = (161, 401)) -> ProbitPosterior:
    """Bayesian probit fit of go/no-go drops on log height, exact on a 2-D grid.

    P(go | h) = Phi((x - m) / sigma), x = ln h (``scale="ln"``) or log10 h; m ~ N(prior_location),
    ln sigma ~ N(prior_log_sigma). Works for any data, separated or one-sided (all gos or all
    no-gos) included: the posterior is proper whenever the priors are.

    Parameters
    ----------
    heights : array_like of float
        Drop heights > 0, any unit; results come back in it.
    went : array_like of bool
        True (or 1) for a go, False (0) for a no-go.
    prior_location : (float, float)
        Mean and sd of m = log H50, in ``scale`` of the input unit (e.g. (ln 10, 1) for H50 near
        10 ft with heights in ft).
    prior_log_sigma : (float, float)
        Mean and sd of ln sigma, sigma in ``scale``.
    scale : {"ln", "log10"}, optional
    credibility : float, optional
        Level of the equal-tailed intervals.
    draws : int, optional
        Number of posterior draws returned (exact samples of the grid density).
    seed : int or numpy Generator, optional
    grid : (int, int), optional
        Cells in ln sigma and in m of the final grid. The cost grows with the number of
        distinct (height, outcome) pairs times the cells: about 0.1 s for the report's drop
        series, about 10 ms per distinct drop beyond that.

    Returns
    -------
    ProbitPosterior

    Raises
    ------
    ValueError
        Bad heights or outcomes, priors, scale, credibility or draws (the message names them).
    """
    from skidmc.analysis.gonogo import _as_heights, _as_outcomes

    heights = _as_heights("heights", heights)
    went = _as_outcomes("went", went, heights.size, "heights")
    if scale not in _SCALES:
        raise _bad("scale", scale, 'must be "ln" or "log10"')
    if not 0.0 < float(credibility) < 1.0:
        raise _bad("credibility", credibility, "must be in (0, 1), e.g. 0.95")
    if int(draws) < 1:
        raise _bad("draws", draws, "must be >= 1")
    prior = NormalPrior(prior_location, prior_log_sigma, scale=scale)
    x = np.log(heights) * _SCALES[scale]
    g = _build_grid(prior, x, went, shape=grid)
    location, sigma = g.sample(int(draws), np.random.default_rng(seed))
    return ProbitPosterior(location, sigma, scale, float(credibility), prior, int(heights.size),
                           int(went.sum()), g)


def posterior_from_prior(heights, went, prior, *, credibility=0.95, draws=4000, seed=None,
                         grid=(161, 401)) -> ProbitPosterior:
    """:func:`probit_posterior` with a prior object (``NormalPrior`` or a replacement)."""
    from skidmc.analysis.gonogo import _as_heights, _as_outcomes

    heights = _as_heights("heights", heights)
    went = _as_outcomes("went", went, heights.size, "heights")
    x = np.log(heights) * _SCALES[prior.scale]
    g = _build_grid(prior, x, went, shape=grid)
    location, sigma = g.sample(int(draws), np.random.default_rng(seed))
    return ProbitPosterior(location, sigma, prior.scale, float(credibility), prior,
                           int(heights.size), int(went.sum()), g)


# --------------------------------------------------------------------------------------------
# every target of the report with drops


def posterior_h50_table(prior: str = "physics", *, credibility: float = 0.9,
                        units: str = "ft") -> xr.Dataset:
    """Posterior H50 with its credible interval for every target of the report with drops.

    Parameters
    ----------
    prior : {"physics", "vague"}, optional
        "physics": :func:`physics_prior` of each target (the model's prior predictive);
        "vague": :func:`vague_prior` centred on the geometric mean of the target's drop heights.
    credibility : float, optional
        Level of the equal-tailed interval.
    units : {"ft", "m"}, optional

    Returns
    -------
    xarray.Dataset
        Over ``target`` ("quartz", "alumina_20_35", "alumina_50_80", "gold"): ``h50``,
        ``h50_low``, ``h50_high`` [units], ``sigma`` (posterior median) [-], ``n``, ``n_go``,
        ``prior_h50`` [units] and ``prior`` (the priors in words). Attribute ``credibility``.
    """
    from skidmc.analysis.experiments import get_experiment

    if prior not in ("physics", "vague"):
        raise _bad("prior", prior, 'must be "physics" or "vague"')
    out = {k: [] for k in ("h50", "h50_low", "h50_high", "sigma", "n", "n_go", "prior_h50",
                           "prior")}
    for target in _DROP_TARGETS:
        drops = get_experiment(target, units=units).drops
        if prior == "physics":
            pr = physics_prior(target, units=units)
        else:
            pr = vague_prior(float(np.exp(np.mean(np.log(drops.heights)))), units=units)
        post = posterior_from_prior(drops.heights, drops.went, pr, credibility=credibility,
                                    draws=1, seed=0)
        h50, low, high = post.quantile(0.5)
        for key, value in (("h50", h50), ("h50_low", low), ("h50_high", high),
                           ("sigma", post.sigma_quantile(0.5)), ("n", post.n),
                           ("n_go", post.n_go), ("prior_h50", pr.h50), ("prior", pr.describe())):
            out[key].append(value)
    attrs = {"units": units}
    return xr.Dataset(
        {
            "h50": ("target", out["h50"], {**attrs, "long_name": "posterior median H50"}),
            "h50_low": ("target", out["h50_low"], attrs),
            "h50_high": ("target", out["h50_high"], attrs),
            "sigma": ("target", out["sigma"], {"long_name": "posterior median sigma of ln h"}),
            "n": ("target", out["n"]),
            "n_go": ("target", out["n_go"]),
            "prior_h50": ("target", out["prior_h50"], {**attrs, "long_name": "prior median H50"}),
            "prior": ("target", np.array(out["prior"], dtype=object)),
        },
        coords={"target": list(_DROP_TARGETS)},
        attrs={"credibility": credibility, "prior_kind": prior,
               "method": "probit on ln h, grid posterior (skidmc.analysis.probit_posterior)"},
    )
