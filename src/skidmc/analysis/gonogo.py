"""Go/no-go statistics: from drops and critical heights to go-probability curves and scores.

Everything here works on the logarithm of the drop height, because the report's up-down analysis
(and the skid-test literature after it) assumes that the probability of an event is log-normal in
the height: P(go | h) = Phi((ln h - mu) / sigma). Heights may be in any unit (ft, m); medians and
quantiles come back in the unit they went in, and ``sigma`` is the standard deviation of ln h,
which no unit changes.

Methods (see ``docs/go-no-go.md`` for assumptions, validity and literature):

- :func:`fit_probit`: maximum-likelihood probit fit to go/no-go drops, with profile-likelihood
  (likelihood-ratio) intervals for any quantile, and an honest report when the go and no-go heights
  do not overlap and the maximum-likelihood estimate does not exist.
- :func:`updown`: the Dixon-Mood (1948) analysis of an up-down (Bruceton) sequence, with its
  validity conditions checked and reported.
- :func:`fit_lognormal`: log-normal fit to critical heights, some censored ("no event up to the
  search ceiling", "event already at the floor"), with profile-likelihood intervals for H01, H10,
  H50, H90 and sigma, and a probability-plot-correlation goodness-of-fit test.
- :func:`go_curve`: the empirical P(go | H) of an ensemble of critical heights with a simultaneous
  confidence band (Dvoretzky-Kiefer-Wolfowitz with Massart's constant).
- :func:`score_drops`, :func:`compare_h50`: how well a predicted curve or H50 matches experiment.
- :func:`plot_go_curve`, :func:`plot_qq`: figures (matplotlib is imported only inside them).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
import xarray as xr
from scipy import optimize, special, stats

from skidmc.analysis.checks import bad as _bad
from skidmc.analysis.checks import check_confidence as _as_confidence
from skidmc.analysis.checks import check_probability as _as_probability

__all__ = [
    "DropScores",
    "H50Comparison",
    "LognormalFit",
    "ProbitFit",
    "QQData",
    "UpDownResult",
    "compare_h50",
    "fit_lognormal",
    "fit_probit",
    "go_curve",
    "plot_go_curve",
    "plot_qq",
    "score_drops",
    "updown",
]

#: Interval methods of :func:`fit_probit`.
INTERVALS = ("calibrated", "profile", "fieller", "wald")

#: Labels accepted in the ``censored`` argument of :func:`fit_lognormal` and :func:`go_curve`.
CENSOR_LABELS = ("", "above", "below")

# The profile maximisations run in standardised log-height units (ln h centred on the data and
# divided by its spread), where 1/sigma within [1e-7, 1e12] covers every spread that can matter:
# below it the likelihood is flat to machine precision, and 1e12 resolves gaps between go and
# no-go heights down to the 1e-9 relative spacing under which heights are merged (_snap).
_LOG_SLOPE_BOUNDS = (math.log(1e-7), math.log(1e12))

# Heights closer than this (relative) are one height: a level reached twice by adding and
# subtracting a logarithmic step differs in the last bits, and must still count as a tie.
_SAME_HEIGHT_RTOL = 1e-9


# --------------------------------------------------------------------------------------------
# input checks


def _as_heights(name: str, values: object) -> np.ndarray:
    """`values` as a 1-D float array of finite heights > 0, or a ValueError naming `name`."""
    try:
        heights = np.asarray(values, dtype=float)
    except (TypeError, ValueError):
        raise _bad(name, values, "must be an array of numbers (heights > 0)") from None
    if heights.ndim != 1 or heights.size == 0:
        raise _bad(name, values, "must be a non-empty 1-D array of heights")
    bad = ~np.isfinite(heights) | (heights <= 0)
    if bad.any():
        index = int(np.flatnonzero(bad)[0])
        raise _bad(f"{name}[{index}]", float(heights[index]), "must be a finite height > 0")
    return heights


def _as_outcomes(name: str, values: object, size: int, size_name: str) -> np.ndarray:
    """`values` as a boolean array (True = go) of length `size`, or a ValueError naming `name`."""
    raw = np.asarray(values)
    if raw.ndim != 1:
        raise _bad(name, values, "must be a 1-D array of outcomes (True = go)")
    if raw.size != size:
        raise _bad(name, values, f"has {raw.size} outcomes but {size_name} has {size} heights")
    if raw.dtype == bool:
        return raw.copy()
    if raw.dtype.kind not in "iuf":
        raise _bad(name, values, "must hold booleans or 0/1 (True/1 = go)")
    numeric = raw.astype(float)
    bad = ~np.isin(numeric, (0.0, 1.0))  # NaN is not in the set, so it is caught here too
    if bad.any():
        index = int(np.flatnonzero(bad)[0])
        raise _bad(f"{name}[{index}]", raw[index].item(), "must be True/False or 1/0")
    return numeric == 1.0


def _snap(heights: np.ndarray) -> np.ndarray:
    """Heights with values closer than _SAME_HEIGHT_RTOL (relative) replaced by one value."""
    order = np.argsort(heights)
    snapped = heights.copy()
    anchor = heights[order[0]]
    for i in order[1:]:
        if heights[i] - anchor <= _SAME_HEIGHT_RTOL * anchor:
            snapped[i] = anchor
        else:
            anchor = heights[i]
    return snapped


def _both_outcomes(name: str, went: np.ndarray) -> None:
    if went.all() or not went.any():
        only = "go" if went.all() else "no-go"
        raise _bad(
            name, went.tolist(), f"every drop is a {only}: a single outcome class cannot be fitted"
        )


def _as_censoring(censored: object, size: int) -> np.ndarray:
    """`censored` as an array of labels in CENSOR_LABELS (None: all exact)."""
    if censored is None:
        return np.full(size, "", dtype=object)
    labels = np.asarray(censored, dtype=object)
    if labels.ndim != 1 or labels.size != size:
        raise _bad("censored", censored, f"must be a 1-D array of {size} labels like the heights")
    for index, label in enumerate(labels):
        if not isinstance(label, str) or label not in CENSOR_LABELS:
            raise _bad(
                f"censored[{index}]", label, 'must be "" (exact), "above" or "below"'
            )
    return labels


# --------------------------------------------------------------------------------------------
# the likelihood engine: a normal model for x = ln h with exact and censored observations
#
# A go/no-go drop is a censored observation of the critical height: a go from h says H_c <= h
# (left-censored at h), a no-go says H_c > h (right-censored). So one engine serves the probit fit
# (all observations censored) and the censored log-normal fit. It works in the parametrisation
# u = a + b x (b = 1/sigma, a = -mu/sigma), where the log-likelihood is concave (Pratt 1981,
# "Concavity of the log likelihood", JASA 76:103), so a local maximum is the global one and every
# profile below is a one-dimensional concave maximisation. scipy fits censored normals
# (stats.norm.fit on CensoredData) but gives no likelihood intervals, and statsmodels (not a
# dependency) gives only Wald intervals; the profile intervals need the likelihood itself.


def _log_mills(u: np.ndarray) -> np.ndarray:
    """phi(u) / Phi(u), computed in logs so that it stays finite far in the lower tail."""
    return np.exp(-0.5 * u * u - 0.5 * math.log(2.0 * math.pi) - special.log_ndtr(u))


class _NormalLikelihood:
    """Log-likelihood of standardised log heights: exact, "<= bound" and "> bound" observations.

    Parameters
    ----------
    log_exact, log_below, log_above : ndarray
        ln h of exact observations, of observations known to be <= their value (a go; an event
        already at the floor) and of observations known to be > their value (a no-go).
    """

    def __init__(self, log_exact, log_below, log_above) -> None:
        everything = np.concatenate([log_exact, log_below, log_above])
        self.center = float(np.mean(everything))
        spread = float(np.std(everything))
        self.scale = spread if spread > 0 else 1.0
        self.exact = (np.asarray(log_exact, float) - self.center) / self.scale
        self.below = (np.asarray(log_below, float) - self.center) / self.scale
        self.above = (np.asarray(log_above, float) - self.center) / self.scale
        self.n_exact = self.exact.size

    # -- log-likelihood in (a, b), standardised units ---------------------------------------
    def loglik(self, a: float, b: float) -> float:
        if self.n_exact and b <= 0:
            return -math.inf
        total = 0.0
        if self.n_exact:
            u = a + b * self.exact
            total += float(np.sum(-0.5 * u * u)) + self.n_exact * (
                math.log(b) - 0.5 * math.log(2.0 * math.pi)
            )
        if self.below.size:
            total += float(np.sum(special.log_ndtr(a + b * self.below)))
        if self.above.size:
            total += float(np.sum(special.log_ndtr(-(a + b * self.above))))
        return total

    def _derivatives(self, a: float, b: float):
        """Gradient and Hessian of the log-likelihood in (a, b)."""
        grad = np.zeros(2)
        hess = np.zeros((2, 2))
        for x, sign in ((self.below, 1.0), (self.above, -1.0)):
            if not x.size:
                continue
            v = sign * (a + b * x)  # the term is log Phi(v)
            lam = _log_mills(v)
            curvature = -lam * (v + lam)  # d2/dv2 log Phi(v)
            grad += sign * np.array([lam.sum(), (lam * x).sum()])
            hess += np.array(
                [[curvature.sum(), (curvature * x).sum()],
                 [(curvature * x).sum(), (curvature * x * x).sum()]]
            )
        if self.n_exact:
            u = a + b * self.exact
            x = self.exact
            grad += np.array([-u.sum(), -(u * x).sum() + self.n_exact / b])
            hess += -np.array([[self.n_exact, x.sum()], [x.sum(), (x * x).sum()]])
            hess[1, 1] -= self.n_exact / b**2
        return grad, hess

    def maximise(self, start=(0.0, 1.0)):
        """Maximum-likelihood (a, b) by a trust-region Newton method on the concave function."""

        def objective(theta):
            value = self.loglik(theta[0], theta[1])
            return math.inf if not math.isfinite(value) else -value

        def gradient(theta):
            return -self._derivatives(theta[0], theta[1])[0]

        def hessian(theta):
            return -self._derivatives(theta[0], theta[1])[1]

        result = optimize.minimize(
            objective, np.asarray(start, float), jac=gradient, hess=hessian,
            method="trust-exact", options={"gtol": 1e-9, "maxiter": 500},
        )
        return float(result.x[0]), float(result.x[1]), -float(result.fun)

    # -- conversions ---------------------------------------------------------------------------
    def to_log_height(self, standardised: float) -> float:
        return self.center + self.scale * standardised

    def to_standardised(self, log_height):
        return (np.asarray(log_height, float) - self.center) / self.scale

    def jacobian_term(self) -> float:
        """Add to a standardised log-likelihood to get the log-likelihood of ln h."""
        return -self.n_exact * math.log(self.scale)

    # -- profiles ------------------------------------------------------------------------------
    def profile_quantile(self, q: float, z: float) -> float:
        """max over b > 0 of the log-likelihood with the p-quantile fixed at q (standardised).

        With mu = q - z sigma the linear predictor is u = b (x - q) + z: one concave parameter.
        """
        def negative(log_b):
            return -self.loglik(z - math.exp(log_b) * q, math.exp(log_b))

        result = optimize.minimize_scalar(
            negative, bounds=_LOG_SLOPE_BOUNDS, method="bounded", options={"xatol": 1e-7}
        )
        best = -float(result.fun)
        if not self.n_exact:
            # Censored data only: as b -> 0 every drop's probability tends to Phi(z), a value
            # the supremum always includes. Far from the data the bounded search can stop
            # short of it (the slope floor, or a flat objective), and the profile would then
            # fall spuriously and close an interval that is open (issue 41's 26-drop sequence).
            flat = self.below.size * float(special.log_ndtr(z)) + self.above.size * float(
                special.log_ndtr(-z)
            )
            best = max(best, flat)
        return best

    def profile_sigma(self, sigma: float, a_start: float) -> float:
        """max over a of the log-likelihood with sigma (standardised) fixed: concave in a."""
        b = 1.0 / sigma

        def negative(a):
            return -self.loglik(a, b)

        result = optimize.minimize_scalar(negative, bracket=(a_start - 1.0, a_start + 1.0))
        return -float(result.fun)


def _binomial_loglik(successes: int, trials: int, p: float) -> float:
    """Log-likelihood of a constant probability p for `successes` of `trials` (0 log 0 = 0)."""
    return float(special.xlogy(successes, p) + special.xlog1py(trials - successes, -p))


def _search_bound(
    excess, start: float, step: float, direction: float, open_limit: bool,
    open_after: float = 1e4,
):
    """Outermost-first crossing of excess(q) = 0 going from `start` in `direction`.

    ``excess`` is 2 (l_max - l_profile) - chi2 critical value: negative inside the confidence set.
    Steps double until the excess turns positive, then brentq finds the crossing. Where the
    likelihood never falls far enough (`open_limit`, known from the profile's limit), the bound is
    infinite. Returns (bound, reason or "").
    """
    inner = start
    for _ in range(80):
        outer = inner + direction * step
        value = excess(outer)
        if value > 0:
            root = optimize.brentq(excess, min(inner, outer), max(inner, outer), xtol=1e-10)
            return float(root), ""
        inner, step = outer, step * 2.0
        if open_limit and abs(outer - start) > open_after:
            return direction * math.inf, (
                "the likelihood never falls by the chi-square critical value in this direction "
                "(the data cannot exclude arbitrarily extreme values)"
            )
    return math.nan, "no crossing found within 2^80 steps of the estimate"


# --------------------------------------------------------------------------------------------
# results shared by the probit and log-normal fits


@dataclass(frozen=True)
class _LogNormalResponse:
    """P(go | h) = Phi((ln h - mu) / sigma) with likelihood intervals; base of the two fits."""

    mu: float
    sigma: float
    confidence: float
    _model: _NormalLikelihood = field(repr=False, compare=False)
    _loglik_max: float = field(repr=False, compare=False)  # standardised units
    _a: float = field(repr=False, compare=False)
    _b: float = field(repr=False, compare=False)

    @property
    def h50(self) -> float:
        """Median height (probability 0.5), in the unit of the input heights."""
        return math.exp(self.mu) if math.isfinite(self.mu) else math.nan

    def probability(self, height) -> np.ndarray | float:
        """Predicted P(go | h) (the fitted log-normal CDF of the critical height).

        Parameters
        ----------
        height : float or array_like
            Drop heights in the unit of the fit's input heights; must be > 0.

        Returns
        -------
        float or ndarray
            Probability of an event at each height; NaN where the fit does not exist.
        """
        h = np.asarray(height, dtype=float)
        if np.any(~(h > 0)):
            raise _bad("height", height, "must be > 0 (heights in the unit of the fit's input)")
        if not (math.isfinite(self.mu) and math.isfinite(self.sigma)):
            result = np.full(h.shape, math.nan)
        else:
            result = special.ndtr((np.log(h) - self.mu) / self.sigma)
        return float(result) if result.ndim == 0 else result

    def _critical(self) -> float:
        return float(stats.chi2.ppf(self.confidence, df=1))

    def _profile_quantile_interval(
        self, z: float, q_hat: float, open_limits=(False, False), crit: float | None = None
    ):
        """Profile-likelihood interval (standardised) for q = mu + z sigma around q_hat."""
        model, l_max = self._model, self._loglik_max
        crit = self._critical() if crit is None else crit

        def excess(q):
            return 2.0 * (l_max - model.profile_quantile(q, z)) - crit

        step = 0.25 * (1.0 / self._b if self._b > 0 and math.isfinite(self._b) else 1.0)
        low, why_low = _search_bound(excess, q_hat, step, -1.0, open_limits[0])
        high, why_high = _search_bound(excess, q_hat, step, +1.0, open_limits[1])
        return low, high, "; ".join(r for r in (why_low, why_high) if r)

    def _sigma_interval_std(
        self, sigma_hat: float, a_start: float, open_high: bool, search_low: bool = True
    ):
        """Profile-likelihood interval of sigma (standardised), searched on ln sigma."""
        model, crit, l_max = self._model, self._critical(), self._loglik_max

        def excess(log_sigma):
            return 2.0 * (l_max - model.profile_sigma(math.exp(log_sigma), a_start)) - crit

        start = math.log(sigma_hat)
        low = -math.inf
        if search_low:
            low, _ = _search_bound(excess, start, 0.1, -1.0, open_limit=False)
        # beyond sigma = e^40 (standardised) the likelihood is flat to machine precision
        high, why = _search_bound(excess, start, 0.1, +1.0, open_limit=open_high, open_after=40.0)
        return _exp_or_inf(low), _exp_or_inf(high), why


def _exp_or_inf(log_value: float) -> float:
    """exp(log_value), inf beyond the double range (an open side, never an OverflowError)."""
    if math.isnan(log_value):
        return math.nan
    return math.exp(log_value) if log_value < 709.0 else math.inf


def _quantile_result(model: _NormalLikelihood, q_std: float, low_std: float, high_std: float):
    """Standardised log-quantile and bounds -> heights (a bound of -inf becomes 0)."""

    def height(v):
        if v == -math.inf:
            return 0.0
        if v == math.inf:
            return math.inf
        if not math.isfinite(v):
            return math.nan
        return _exp_or_inf(model.to_log_height(v))

    return height(q_std), height(low_std), height(high_std)


# --------------------------------------------------------------------------------------------
# probit maximum likelihood


def _updown_step(log_h: np.ndarray, went: np.ndarray) -> float | None:
    """The logarithmic step when every drop followed the up-down rule with one step, else None."""
    if log_h.size < 2:
        return None
    moves = np.diff(log_h) * np.where(went[:-1], -1.0, 1.0)
    step = float(np.mean(moves))
    if step <= 0 or np.any(np.abs(moves - step) > 0.05 * step):
        return None
    return step


def _lr_statistic(log_h: np.ndarray, went: np.ndarray, q_log: float, z: float) -> float:
    """2 (sup l - l_profile(q)) of probit data at the p-quantile q (ln h), z = Phi^-1(p).

    The supremum is over b > 0: the maximum-likelihood value where it exists, the separated
    data's supremum (each side's drops predicted perfectly, shared heights at their own
    fraction), the best constant probability where the best slope is not positive.
    """
    model = _NormalLikelihood(np.empty(0), log_h[went], log_h[~went])
    n, n_go = went.size, int(went.sum())
    constant = _binomial_loglik(n_go, n, n_go / n)
    if 0 < n_go < n and log_h[~went].max() <= log_h[went].min():
        x0 = log_h[~went].max()
        if x0 == log_h[went].min():
            k, m = int((went & (log_h == x0)).sum()), int((~went & (log_h == x0)).sum())
            sup = _binomial_loglik(k, k + m, k / (k + m))
        else:
            sup = 0.0
    elif 0 < n_go < n and np.unique(log_h).size > 1:
        a, b, l_max = model.maximise()
        sup = max(l_max if b > 0 else -math.inf, constant)
    else:
        sup = constant
    profile = model.profile_quantile(float(model.to_standardised(q_log)), z)
    return max(2.0 * (sup - profile), 0.0)


@dataclass(frozen=True)
class ProbitFit(_LogNormalResponse):
    """Maximum-likelihood probit fit of go/no-go drops on ln h.

    Attributes
    ----------
    exists : bool
        False when the maximum-likelihood estimate does not exist (no overlap of go and no-go
        heights, all drops at one height, or a response that decreases with height).
    reason : str
        Why it does not exist ("" when it does).
    mu : float
        Mean of ln h_c [ln of the input unit]; NaN when ``exists`` is False.
    sigma : float
        Standard deviation of ln h_c [-]; NaN when ``exists`` is False.
    h50 : float
        Median height, in the unit of the input heights (property).
    h50_range : tuple of float
        Heights between which the median must lie when the fit does not exist because go and
        no-go heights do not overlap: (highest no-go, lowest go). (NaN, NaN) otherwise.
    confidence : float
        Confidence level of the intervals.
    interval : str
        "fieller" (the default), "profile" (likelihood ratio), "calibrated" (likelihood ratio
        with a bootstrap critical value) or "wald" (normal approximation, for contrast); see
        :func:`fit_probit`.
    n_bootstrap, seed : int
        Simulations and seed of the "calibrated" critical value.
    loglik : float
        Maximised binomial log-likelihood (its supremum when ``exists`` is False).
    n, n_go : int
        Number of drops and of gos.
    """

    exists: bool = True
    reason: str = ""
    h50_range: tuple[float, float] = (math.nan, math.nan)
    interval: str = "fieller"
    loglik: float = math.nan
    n: int = 0
    n_go: int = 0
    _covariance: np.ndarray | None = field(default=None, repr=False, compare=False)
    _cov_ab: np.ndarray | None = field(default=None, repr=False, compare=False)
    _kind: str = field(default="overlap", repr=False, compare=False)
    _tie_fraction: float = field(default=math.nan, repr=False, compare=False)
    _drops: tuple | None = field(default=None, repr=False, compare=False)
    n_bootstrap: int = 0
    seed: int | None = 0

    def quantile(self, p: float) -> tuple[float, float, float]:
        """Height with P(go) = p, and its confidence interval.

        Parameters
        ----------
        p : float
            Probability of an event, in (0, 1).

        Returns
        -------
        tuple of float
            (estimate, low, high) in the unit of the input heights. With ``interval="fieller"``
            the set of q where (a + b q - z_p)^2 <= chi2_1(confidence) Var(a + b q); with
            "profile" the set where 2 (l_max - l_profile(q)) <= chi2_1(confidence); with
            "calibrated" the same with a bootstrap critical value. A bound of 0 or inf means
            the data cannot bound that side (an open-ended interval, honestly reported).
            When the fit does not exist because the outcomes do not overlap, the estimate is
            NaN and (low, high) still hold the likelihood-ratio bounds, measured from the
            likelihood's supremum; when it does not exist for another reason everything is NaN.
        """
        p = _as_probability("p", p)
        z = float(special.ndtri(p))
        model = self._model
        if self._kind in ("reversed", "decreasing", "one height"):
            return (math.nan, math.nan, math.nan)
        if self.interval == "wald":
            if not self.exists:
                return (math.nan, math.nan, math.nan)
            return self._wald_quantile(z)
        if self.interval == "fieller" and self.exists:
            return self._fieller_quantile(z)
        # open-ended sides: the profile tends to the best constant probability as q -> +-inf
        limit_high = _binomial_loglik(self.n_go, self.n, min(self.n_go / self.n, p))
        limit_low = _binomial_loglik(self.n_go, self.n, max(self.n_go / self.n, p))
        crit = self._critical()
        if self.interval == "calibrated" and self.exists:
            crit = self.calibrated_critical(p)
        open_limits = (
            2.0 * (self._loglik_max - limit_low) <= crit,
            2.0 * (self._loglik_max - limit_high) <= crit,
        )
        if self.exists:
            q_hat = -self._a / self._b + z / self._b
            low, high, _ = self._profile_quantile_interval(z, q_hat, open_limits, crit)
            return _quantile_result(model, q_hat, low, high)
        # No overlap: the likelihood's supremum is reached (sigma -> 0) for any q strictly
        # between the highest no-go and the lowest go, so the search starts in that gap. When
        # they share one height x0, the supremum is approached from the side of x0 on which the
        # shared drops' go fraction f can be matched: q -> x0 from above if z_p > z_f.
        gap_low, gap_high = (float(model.to_standardised(math.log(h))) for h in self.h50_range)
        if gap_high > gap_low:
            start = 0.5 * (gap_low + gap_high)
        else:
            side = np.sign(z - float(special.ndtri(self._tie_fraction)))
            start = gap_low + 1e-6 * side
        low, high, _ = self._profile_quantile_interval(z, start, open_limits)
        _, low_h, high_h = _quantile_result(model, 0.0, low, high)
        return (math.nan, low_h, high_h)

    def calibrated_critical(self, p: float) -> float:
        """Critical value of the likelihood-ratio statistic for the p-quantile, by bootstrap.

        A parametric bootstrap (Efron & Tibshirani 1993, ch. 16; the calibration of a
        likelihood-ratio statistic is in Hall 1992, ch. 3): ``n_bootstrap`` data sets are drawn
        from the fitted curve with the experiment's own design, the statistic
        2 (l_max - l_profile(q)) is computed at the fitted quantile q (the truth of the
        simulated world), and its ``confidence`` quantile replaces chi2_1(confidence). The
        design: when the drops follow the up-down rule on a regular logarithmic grid, new
        up-down sequences of the same length from the same first height and step; otherwise
        the observed heights with new outcomes. Data sets without a maximum-likelihood estimate
        (no overlap) enter with the statistic from the likelihood's supremum, as the data
        would.

        Parameters
        ----------
        p : float
            Probability of the quantile, in (0, 1).

        Returns
        -------
        float
            The calibrated critical value; chi2_1(confidence) where no fit exists.
        """
        p = _as_probability("p", p)
        if not self.exists or self._drops is None or self.n_bootstrap < 1:
            return self._critical()
        key = (p, self.n_bootstrap, self.seed)
        cache = self.__dict__.setdefault("_calibration_cache", {})
        if key in cache:
            return cache[key]
        z = float(special.ndtri(p))
        heights, went = self._drops
        log_h = np.log(heights)
        mu, sigma = self.mu, self.sigma
        q_true = mu + z * sigma
        rng = np.random.default_rng(self.seed)
        step = _updown_step(log_h, went)
        statistics = np.empty(self.n_bootstrap)
        for i in range(self.n_bootstrap):
            if step is not None:
                # integer levels, so that a level reached twice is the same number (a tie)
                level, sim_h = 0, np.empty(heights.size)
                sim_went = np.empty(heights.size, bool)
                critical = rng.normal(mu, sigma, heights.size)
                for j in range(heights.size):
                    sim_h[j] = log_h[0] + level * step
                    sim_went[j] = critical[j] <= sim_h[j]
                    level += -1 if sim_went[j] else 1
            else:
                sim_h = log_h
                sim_went = rng.random(heights.size) < special.ndtr((log_h - mu) / sigma)
            statistics[i] = _lr_statistic(sim_h, sim_went, q_true, z)
        value = float(np.quantile(statistics, self.confidence))
        cache[key] = value
        return value

    def _fieller_quantile(self, z: float) -> tuple[float, float, float]:
        """Fieller's (1954) interval for q = (z - a) / b, a ratio of normal estimates.

        The set of q where (a + b q - z)^2 <= k Var(a + b q), k the chi-square critical value
        and the variance from the observed information of (a, b): a quadratic inequality
        A q^2 + B q + C <= 0. With A > 0 it is the interval between the roots; with A <= 0 (the
        slope b is not significantly above 0 at this level) it is unbounded and the interval is
        reported as (0, inf).
        """
        model, k = self._model, self._critical()
        a, b = self._a, self._b
        (v_aa, v_ab), (_, v_bb) = self._cov_ab
        shifted = a - z
        quad_a = b * b - k * v_bb
        quad_b = 2.0 * (shifted * b - k * v_ab)
        quad_c = shifted * shifted - k * v_aa
        q_hat = -shifted / b
        if quad_a <= 0:
            return _quantile_result(model, q_hat, -math.inf, math.inf)
        root = math.sqrt(max(quad_b * quad_b - 4.0 * quad_a * quad_c, 0.0))
        low, high = (-quad_b - root) / (2 * quad_a), (-quad_b + root) / (2 * quad_a)
        return _quantile_result(model, q_hat, low, high)

    def _wald_quantile(self, z: float) -> tuple[float, float, float]:
        model = self._model
        mu_s, sigma_s = -self._a / self._b, 1.0 / self._b
        gradient = np.array([1.0, z])
        variance = float(gradient @ self._covariance @ gradient)
        half = float(special.ndtri(0.5 + self.confidence / 2.0)) * math.sqrt(max(variance, 0.0))
        q = mu_s + z * sigma_s
        return _quantile_result(model, q, q - half, q + half)

    def sigma_interval(self) -> tuple[float, float]:
        """Profile-likelihood interval for sigma [-] (standard deviation of ln h_c).

        Returns
        -------
        tuple of float
            (low, high). When the outcomes do not overlap the lower bound is 0 (sigma -> 0 is
            the supremum) and the upper bound is where the likelihood ratio reaches its critical
            value; inf where it never does. NaN for a decreasing or one-height data set.
        """
        model = self._model
        if self._kind in ("reversed", "decreasing", "one height"):
            return (math.nan, math.nan)
        limit = _binomial_loglik(self.n_go, self.n, self.n_go / self.n)
        open_high = 2.0 * (self._loglik_max - limit) <= self._critical()
        if self.exists:
            low, high, _ = self._sigma_interval_std(1.0 / self._b, self._a, open_high)
            return (low * model.scale, high * model.scale)
        # separated: the profile over sigma is maximised as sigma -> 0; the bound above is where
        # the profile has fallen by the critical value (searched upward from a tiny sigma).
        gap = model.to_standardised(np.log(self.h50_range))
        a_start = -float(np.mean(gap)) * 1e3
        _, high, _ = self._sigma_interval_std(1e-3, a_start, open_high, search_low=False)
        return (0.0, high * model.scale if math.isfinite(high) else math.inf)


def fit_probit(
    heights, went, confidence: float = 0.95, *, interval: str = "fieller",
    n_bootstrap: int = 199, seed: int | None = 0,
) -> ProbitFit:
    """Fit P(go | h) = Phi((ln h - mu) / sigma) to go/no-go drops by maximum likelihood.

    Parameters
    ----------
    heights : array_like of float
        Drop heights, > 0, in any unit (ft, m); quantiles come back in the same unit.
    went : array_like of bool
        Outcome of each drop: True (or 1) for an event (go), False (or 0) for none.
    confidence : float, optional
        Confidence level of the intervals given by :meth:`ProbitFit.quantile`.
    interval : {"fieller", "profile", "calibrated", "wald"}, optional
        How :meth:`ProbitFit.quantile` bounds a quantile (see ``docs/go-no-go.md`` for the
        coverage measured at 10-40 drops of up-down sequences, ``scripts/gonogo_coverage.py``):
        "fieller" (the default: Fieller's interval, 0.945-0.952 at 20-30 drops, open at most
        10-drop sequences), "profile" (likelihood-ratio set with the chi-square critical value;
        0.92 at 20-30 drops), "calibrated" (the likelihood-ratio set with a parametric-bootstrap
        critical value, ``n_bootstrap`` simulated experiments; about 1 s per quantile; no
        better than Fieller here) and "wald" (normal approximation on ln h, 0.83: kept only to
        show how much it undercovers). Where go and no-go heights do not overlap every method
        gives the likelihood-ratio set from the supremum.
    n_bootstrap : int, optional
        Simulated experiments of the "calibrated" interval.
    seed : int or None, optional
        Seed of those simulations (0 by default so that results repeat).

    Returns
    -------
    ProbitFit
        ``exists`` is False (and ``reason`` says why) when the maximum-likelihood estimate does
        not exist: when every go lies at or above every no-go (sigma -> 0; ``h50_range`` then
        gives the bracket), when every go lies at or below every no-go (the response decreases
        with height), or when all drops share one height.

    Raises
    ------
    ValueError
        For a non-positive or non-finite height, mismatched lengths, outcomes other than
        booleans/0/1 (NaN included), a single outcome class, or a bad confidence.
    """
    heights = _as_heights("heights", heights)
    went = _as_outcomes("went", went, heights.size, "heights")
    _both_outcomes("went", went)
    confidence = _as_confidence(confidence)
    heights = _snap(heights)
    if interval not in INTERVALS:
        raise _bad("interval", interval, f"must be one of {', '.join(map(repr, INTERVALS))}")

    log_h = np.log(heights)
    model = _NormalLikelihood(np.empty(0), log_h[went], log_h[~went])
    n, n_go = heights.size, int(went.sum())
    highest_nogo, lowest_go = float(heights[~went].max()), float(heights[went].min())
    highest_go, lowest_nogo = float(heights[went].max()), float(heights[~went].min())
    if int(n_bootstrap) < 1:
        raise _bad("n_bootstrap", n_bootstrap, "must be an integer >= 1")
    common = {"confidence": confidence, "interval": interval, "n": n, "n_go": n_go,
              "_model": model, "_drops": (heights, went), "n_bootstrap": int(n_bootstrap),
              "seed": seed}

    if np.unique(heights).size < 2:
        return ProbitFit(
            mu=math.nan, sigma=math.nan, _loglik_max=math.nan, _a=math.nan, _b=math.nan,
            exists=False, reason="all drops were made from one height: no slope can be fitted",
            _kind="one height", **common,
        )
    if highest_nogo <= lowest_go:
        # Separated (or quasi-separated at one shared height): the supremum of the likelihood is
        # approached as sigma -> 0 with the median in [highest no-go, lowest go]; it is 0 when
        # strictly separated, and the shared height's own binomial likelihood when they touch.
        tied = heights == highest_nogo if highest_nogo == lowest_go else np.zeros(n, bool)
        k, m = int((tied & went).sum()), int((tied & ~went).sum())
        sup = _binomial_loglik(k, k + m, k / (k + m)) if k + m else 0.0
        return ProbitFit(
            mu=math.nan, sigma=math.nan, _loglik_max=sup, _a=math.nan, _b=math.inf,
            exists=False,
            reason=(
                f"no overlap: the highest no-go ({highest_nogo:g}) is not above the lowest go "
                f"({lowest_go:g}), so the likelihood keeps rising as sigma -> 0; the median lies "
                "between them"
            ),
            h50_range=(highest_nogo, lowest_go), loglik=sup, _kind="separated",
            _tie_fraction=k / (k + m) if k + m else math.nan, **common,
        )
    if highest_go <= lowest_nogo:
        return ProbitFit(
            mu=math.nan, sigma=math.nan, _loglik_max=math.nan, _a=math.nan, _b=math.nan,
            exists=False,
            reason=(
                f"reversed: every go ({highest_go:g} at most) lies at or below every no-go "
                f"({lowest_nogo:g} at least); the data contradict a go probability rising "
                "with height"
            ),
            _kind="reversed", **common,
        )

    # Overlapping outcomes: the unconstrained maximum exists (Silvapulle 1981); with b <= 0 the
    # fitted response falls with height, which the model excludes.
    a, b, l_max = model.maximise()
    if b <= 0:
        return ProbitFit(
            mu=math.nan, sigma=math.nan, _loglik_max=l_max, _a=a, _b=b, exists=False,
            reason="the best-fitting response decreases with height; the model cannot fit it",
            loglik=l_max, _kind="decreasing", **common,
        )
    _, hessian = model._derivatives(a, b)
    cov_ab = np.linalg.inv(-hessian)
    # delta method from (a, b) to (mu, sigma) = (-a/b, 1/b), standardised units
    jac = np.array([[-1.0 / b, a / b**2], [0.0, -1.0 / b**2]])
    covariance = jac @ cov_ab @ jac.T
    return ProbitFit(
        mu=model.to_log_height(-a / b), sigma=model.scale / b, _loglik_max=l_max, _a=a, _b=b,
        loglik=l_max, _covariance=covariance, _cov_ab=cov_ab, **common,
    )


# --------------------------------------------------------------------------------------------
# Dixon-Mood up-down analysis


#: Conventions of :func:`updown` for the spread when M < 0.3, where Dixon & Mood's formula
#: does not apply.
SMALL_M_CONVENTIONS = ("nan", "iso12107")

#: Spread as a multiple of the step when M < 0.3 under ISO 12107:2012 (and GB/T 24176-2009,
#: which follows it), s = 0.53 d.
_ISO_SMALL_M_FACTOR = 0.53


@dataclass(frozen=True)
class UpDownResult:
    """Dixon-Mood analysis of an up-down sequence.

    Attributes
    ----------
    h50 : float
        Estimated median, in the unit of the input heights (stimuli) (NaN when the levels are
        not on a regular grid of the chosen scale).
    sigma : float
        Estimated standard deviation of the critical stimulus: of ln h [-] on the "log" scale,
        in the input unit on the "linear" scale. Where M < 0.3 it is NaN, or 0.53 d with
        ``small_m="iso12107"`` (see :func:`updown`).
    valid : bool
        True only when every condition of the method holds (see ``reasons``).
    reasons : list of str
        Each condition that fails, in words; empty when ``valid``.
    mu : float
        Mean of the critical stimulus on the chosen scale: ln of ``h50`` ("log"), ``h50``
        ("linear").
    step : float
        Step d between levels on the chosen scale (logarithmic [-] or in the input unit).
    outcome_used : str
        "go" or "no-go": the less frequent outcome, on which the estimate is based.
    n_used, a_sum, b_sum : int
        Dixon-Mood's N, A = sum i n_i and B = sum i^2 n_i for the outcome used, with i = 0 at
        the lowest level at which that outcome occurred (numbering from a lower level changes A
        and B but neither the mean nor M).
    m_statistic : float
        M = (N B - A^2) / N^2.
    scale : str
        "log" or "linear".
    sigma_rule : str
        How ``sigma`` was obtained: "Dixon-Mood 1.62 d (M + 0.029)", "ISO 12107 0.53 d (M < 0.3)"
        or "none (M < 0.3)".
    """

    h50: float
    sigma: float
    valid: bool
    reasons: list[str]
    mu: float = math.nan
    step: float = math.nan
    outcome_used: str = ""
    n_used: int = 0
    a_sum: int = 0
    b_sum: int = 0
    m_statistic: float = math.nan
    scale: str = "log"
    sigma_rule: str = ""


def _counts_to_drops(counts) -> tuple[np.ndarray, np.ndarray]:
    """{level: (gos, no-gos)} -> (levels, outcomes) with one entry per drop (order unknown)."""
    if not isinstance(counts, dict) or not counts:
        raise _bad("counts", counts, "must be a non-empty dict {level: (gos, no-gos)}")
    levels, outcomes = [], []
    for level, pair in counts.items():
        try:
            gos, nogos = (int(v) for v in pair)
            value = float(level)
        except (TypeError, ValueError):
            raise _bad(
                f"counts[{level!r}]", pair, "must be a pair of counts (gos, no-gos)"
            ) from None
        if gos < 0 or nogos < 0 or any(float(v) != int(v) for v in pair):
            raise _bad(f"counts[{level!r}]", pair, "counts must be integers >= 0")
        levels += [value] * (gos + nogos)
        outcomes += [True] * gos + [False] * nogos
    if not levels:
        raise _bad("counts", counts, "holds no drops")
    return np.array(levels), np.array(outcomes)


def updown(
    heights=None, went=None, *, counts=None, scale: str = "log", small_m: str = "nan",
    step_tolerance: float = 0.05, min_count: int = 10,
) -> UpDownResult:
    """Dixon & Mood (1948) estimates of the median and spread from an up-down sequence.

    Levels are read on the chosen scale (ln h for "log", the stimulus itself for "linear");
    with d the step, i the level index counted from the lowest level at which the less frequent
    outcome occurred, y0 that level, n_i the count there, N = sum n_i, A = sum i n_i,
    B = sum i^2 n_i:

        mean = y0 + d (A/N + 1/2)  (estimate based on no-gos)
        mean = y0 + d (A/N - 1/2)  (estimate based on gos)
        s = 1.62 d (M + 0.029),    M = (N B - A^2) / N^2, for M >= 0.3.

    Parameters
    ----------
    heights : array_like of float, optional
        Drop heights (stimuli) in test order, > 0, any unit.
    went : array_like of bool, optional
        Outcome of each drop (True = go).
    counts : dict, optional
        Instead of ``heights`` and ``went``: ``{level: (gos, no-gos)}``, the form in which
        published staircase data often come (the order of the trials unprinted). Dixon-Mood
        uses only these counts; the up-down rule then cannot be checked (a reason says so).
    scale : {"log", "linear"}, optional
        The scale on which the levels are equally spaced and the critical stimulus is normal:
        "log" (the default, as for drop heights of explosives) or "linear" (e.g. stress
        amplitudes of fatigue staircases).
    small_m : {"nan", "iso12107"}, optional
        Convention when M < 0.3, where Dixon & Mood's spread formula does not hold: "nan" (the
        default) leaves sigma NaN; "iso12107" gives s = 0.53 d, the fallback of ISO 12107:2012
        (and GB/T 24176). Either way a reason records it and the result is not ``valid``.
    step_tolerance : float, optional
        Largest allowed distance of a level from the regular grid, as a fraction of the step.
        The default 5 % accepts heights printed to three significant figures (rounding moves
        ln h by up to 0.5 % of the height, a few per cent of a typical step of 0.1-0.4).
    min_count : int, optional
        Smallest N (count of the less frequent outcome) for which the large-sample formulas are
        taken as usable; below it the result is flagged invalid (see Notes).

    Returns
    -------
    UpDownResult
        Estimates with ``valid`` and the list of failed conditions. When the levels are not on
        a regular grid of the chosen scale, the method cannot be applied: h50 and sigma are NaN.
        When the order breaks the up-down rule (one step down after a go, up after a no-go),
        the estimates are still computed from the counts but flagged invalid, drop by drop.

    Raises
    ------
    ValueError
        For bad heights, outcomes or counts, both or neither of (heights, went) and counts,
        mismatched lengths, a single outcome class, or an unknown scale or convention.

    Notes
    -----
    Conditions checked: levels on a regular grid; the up-down rule between consecutive drops
    (sequences only); M >= 0.3, without which Dixon & Mood's spread formula does not apply;
    a step within 0.5-2 s (Dixon & Mood's recommended range, outside which their approximations
    degrade); N >= ``min_count``. Dixon & Mood derived the formulas as large-sample
    approximations; the threshold of 10 is this package's conservative reading of that, not a
    number from the paper (Brownlee, Hodges & Rosenblatt 1953 and Dixon 1965 treat small samples).
    On a tie of the two outcomes' counts the gos are used.
    """
    if scale not in ("log", "linear"):
        raise _bad("scale", scale, 'must be "log" or "linear"')
    if small_m not in SMALL_M_CONVENTIONS:
        choices = ", ".join(map(repr, SMALL_M_CONVENTIONS))
        raise _bad("small_m", small_m, f"must be one of {choices}")
    from_counts = counts is not None
    if from_counts:
        if heights is not None or went is not None:
            raise _bad("counts", counts, "give either counts or (heights, went), not both")
        heights, went = _counts_to_drops(counts)
    elif heights is None or went is None:
        raise _bad("heights", heights, "give heights and went (in test order), or counts")
    heights = _as_heights("heights", heights)
    went = _as_outcomes("went", went, heights.size, "heights")
    _both_outcomes("went", went)
    if not 0.0 < float(step_tolerance) < 0.5:
        raise _bad("step_tolerance", step_tolerance, "must be in (0, 0.5)")
    if int(min_count) < 1:
        raise _bad("min_count", min_count, "must be >= 1")

    snapped = _snap(heights)
    y = np.log(snapped) if scale == "log" else snapped
    levels = np.unique(y)
    reasons: list[str] = []
    if from_counts:
        reasons.append("counts per level were given: the up-down rule was not checked")

    def back(value: float) -> float:
        return math.exp(value) if scale == "log" else value

    if levels.size < 2:
        return UpDownResult(math.nan, math.nan, False, ["all drops at one height: no step"],
                            scale=scale)

    # Regular grid: index every level by the smallest gap, then refine the step by least squares.
    first_step = float(np.min(np.diff(levels)))
    index = np.rint((levels - levels[0]) / first_step)
    step = float(np.sum(index * (levels - levels[0])) / np.sum(index * index))
    off_grid = np.abs(levels - levels[0] - index * step) > step_tolerance * step
    if off_grid.any():
        bad_heights = ", ".join(f"{back(v):g}" for v in levels[off_grid])
        return UpDownResult(
            math.nan, math.nan, False,
            [(f"heights {bad_heights} are off the regular "
              f"{'logarithmic' if scale == 'log' else 'linear'} grid of step "
              f"{step:.4g} (tolerance {step_tolerance:.0%} of a step): Dixon-Mood does not "
              "apply")],
            step=step, scale=scale,
        )
    level_of = {float(v): int(i) for v, i in zip(levels, index)}
    k = np.array([level_of[float(v)] for v in y])

    if not from_counts:
        for drop in range(heights.size - 1):
            expected = k[drop] - 1 if went[drop] else k[drop] + 1
            if k[drop + 1] != expected:
                outcome = "go" if went[drop] else "no-go"
                reasons.append(
                    f"drop {drop + 2} (in the order given) breaks the up-down rule: after a "
                    f"{outcome} at "
                    f"{heights[drop]:g} it was made at {heights[drop + 1]:g}, not one step "
                    f"{'down' if went[drop] else 'up'}"
                )

    n_go = int(went.sum())
    use_go = n_go <= heights.size - n_go  # the less frequent outcome; the gos on a tie
    chosen = went if use_go else ~went
    i = k[chosen] - k[chosen].min()
    y0 = float(levels[0] + k[chosen].min() * step)
    n_used, a_sum, b_sum = int(i.size), int(i.sum()), int((i * i).sum())
    sign = -0.5 if use_go else 0.5
    mu = y0 + step * (a_sum / n_used + sign)
    m_stat = (n_used * b_sum - a_sum**2) / n_used**2
    sigma = math.nan
    if m_stat >= 0.3:
        sigma = 1.62 * step * (m_stat + 0.029)
        rule = "Dixon-Mood 1.62 d (M + 0.029)"
        if not 0.5 <= step / sigma <= 2.0:
            reasons.append(
                f"step d = {step:.3g} is {step / sigma:.2f} s; Dixon-Mood want 0.5-2 s"
            )
    elif small_m == "iso12107":
        sigma = _ISO_SMALL_M_FACTOR * step
        rule = "ISO 12107 0.53 d (M < 0.3)"
        reasons.append(
            f"M = (NB - A^2)/N^2 = {m_stat:.3g} < 0.3: Dixon-Mood's spread formula does not "
            f"apply; sigma = 0.53 d = {sigma:.3g} by the fallback of ISO 12107 (a convention, "
            "not an estimate: the step is probably too large for the spread)"
        )
    else:
        rule = "none (M < 0.3)"
        reasons.append(
            f"M = (NB - A^2)/N^2 = {m_stat:.3g} < 0.3: Dixon-Mood's spread formula does not "
            "apply (sigma is NaN; small_m='iso12107' gives ISO 12107's 0.53 d); the step is "
            "probably too large for the spread"
        )
    if n_used < min_count:
        reasons.append(
            f"only N = {n_used} {'gos' if use_go else 'no-gos'} (the less frequent outcome); the "
            f"large-sample formulas are used here only from N >= {min_count}"
        )
    return UpDownResult(
        h50=back(mu), sigma=sigma, valid=not reasons, reasons=reasons, mu=mu, step=step,
        outcome_used="go" if use_go else "no-go", n_used=n_used, a_sum=a_sum, b_sum=b_sum,
        m_statistic=m_stat, scale=scale, sigma_rule=rule,
    )


# --------------------------------------------------------------------------------------------
# censored log-normal fit with goodness of fit


@dataclass(frozen=True)
class QQData:
    """Points of a log-normal Q-Q plot, uncensored samples only.

    Attributes
    ----------
    observed : ndarray
        Sorted uncensored heights [input unit].
    theoretical : ndarray
        Fitted log-normal quantiles at their plotting positions [input unit].
    positions : ndarray
        Plotting positions (probabilities) that account for the censored samples [-].
    """

    observed: np.ndarray
    theoretical: np.ndarray
    positions: np.ndarray


@dataclass(frozen=True)
class LognormalFit(_LogNormalResponse):
    """Censored log-normal fit of critical heights.

    Attributes
    ----------
    mu, sigma : float
        Mean [ln of input unit] and standard deviation [-] of ln h_c.
    h50 : float
        Median critical height [input unit] (property).
    intervals : dict of str to tuple
        ``"h01"``, ``"h10"``, ``"h50"``, ``"h90"``: (estimate, low, high) [input unit];
        ``"sigma"``: (estimate, low, high) [-]; all profile-likelihood intervals.
    loglik : float
        Maximised log-likelihood of ln h.
    n, n_exact, n_above, n_below : int
        Counts of samples: all, uncensored, right-censored ("above"), left-censored ("below").
    ppcc : float
        Probability-plot correlation coefficient of the uncensored samples (NaN if not computed).
    p_value : float
        p-value of the PPCC against its null distribution (NaN if not computed).
    verdict : str
        "log-normal rejected at 5 %", "consistent with log-normal at 5 %", or why no test.
    gof_method : str
        How the null distribution was obtained.
    qq : QQData or None
        Data for a Q-Q plot (None when there are too few uncensored samples).
    """

    intervals: dict = field(default_factory=dict)
    loglik: float = math.nan
    n: int = 0
    n_exact: int = 0
    n_above: int = 0
    n_below: int = 0
    ppcc: float = math.nan
    p_value: float = math.nan
    verdict: str = ""
    gof_method: str = ""
    qq: QQData | None = None

    def quantile(self, p: float) -> tuple[float, float, float]:
        """Height below which a fraction p of critical heights lie, with its interval.

        Parameters
        ----------
        p : float
            Probability in (0, 1).

        Returns
        -------
        tuple of float
            (estimate, low, high) [input unit], profile-likelihood interval at ``confidence``.
        """
        z = float(special.ndtri(_as_probability("p", p)))
        q_hat = -self._a / self._b + z / self._b
        low, high, _ = self._profile_quantile_interval(z, q_hat)
        return _quantile_result(self._model, q_hat, low, high)


def _plotting_positions(values, labels):
    """Censoring-aware plotting positions of the uncensored values, or (None, reason).

    Kaplan-Meier (scipy.stats.ecdf) turns the censored samples into an adjusted rank r for each
    uncensored value (r = its rank when nothing is censored); the position is the median of the
    r-th uniform order statistic, Beta(r, n + 1 - r), as in scipy's Filliben statistic. Kaplan-
    Meier handles one censoring direction; both directions are handled only when the censoring
    does not interleave with the exact values (all "below" bounds under every exact value, or all
    "above" bounds over every exact value), which is the case of an ensemble searched between a
    fixed floor and ceiling.
    """
    exact = values[labels == ""]
    below, above = values[labels == "below"], values[labels == "above"]
    n = values.size
    if exact.size < 3:
        return None, "fewer than three uncensored samples"
    exact_sorted = np.sort(exact)
    if (not below.size or below.max() <= exact.min()) and (
        not above.size or above.min() >= exact.max()
    ):
        # Censoring only outside the exact values (a fixed floor and ceiling): the ranks are
        # known exactly and Kaplan-Meier would return them; skip it (the bootstrap's hot path).
        ranks = below.size + np.arange(1.0, exact.size + 1.0)
        return (exact_sorted, stats.beta(ranks, n + 1.0 - ranks).median()), ""
    if below.size and above.size:
        if below.max() <= exact.min():
            below_as_exact, flip = True, False
        elif above.min() >= exact.max():
            below_as_exact, flip = False, True
        else:
            return None, ("left- and right-censored samples interleave with the uncensored "
                          "ones (needs the Turnbull estimator, not implemented)")
    else:
        below_as_exact, flip = False, bool(below.size)
    if flip:
        # reflect: "below" (<= bound) becomes right-censored in -x; "above" over every exact
        # value is then below all of them and ranks as exact (its position does not matter).
        uncensored = np.concatenate([-exact, -above])
        data = stats.CensoredData(uncensored=uncensored, right=-below)
        survival_rank = n * stats.ecdf(data).cdf.evaluate(-exact_sorted)
        ranks = n + 1.0 - survival_rank
    else:
        uncensored = np.concatenate([exact, below]) if below_as_exact else exact
        data = stats.CensoredData(uncensored=uncensored, right=above)
        ranks = n * stats.ecdf(data).cdf.evaluate(exact_sorted)
    ranks = np.clip(ranks, 1e-9, n + 1.0 - 1e-9)
    return (exact_sorted, stats.beta(ranks, n + 1.0 - ranks).median()), ""


def _ppcc(values, labels):
    points, why = _plotting_positions(values, labels)
    if points is None:
        return math.nan, None, why
    observed, positions = points
    return float(np.corrcoef(observed, special.ndtri(positions))[0, 1]), points, ""


def fit_lognormal(
    heights,
    censored=None,
    confidence: float = 0.95,
    *,
    n_bootstrap: int = 999,
    seed: int | np.random.Generator | None = 0,
) -> LognormalFit:
    """Fit a log-normal distribution to critical heights, some of them censored.

    Parameters
    ----------
    heights : array_like of float
        Critical heights, or their censoring bounds, > 0, any unit.
    censored : array_like of str, optional
        Per sample: ``""`` exact; ``"above"``: no event up to this height (the critical height is
        above it, right-censored); ``"below"``: an event already at this height (the critical
        height is at or below it, left-censored). None: all exact.
    confidence : float, optional
        Confidence level of the profile-likelihood intervals.
    n_bootstrap : int, optional
        Simulated samples for the goodness-of-fit p-value (>= 99).
    seed : int, numpy Generator or None, optional
        Seed of the goodness-of-fit simulation (0 by default so that results repeat).

    Returns
    -------
    LognormalFit
        Maximum-likelihood mu and sigma of ln h, H50, profile-likelihood intervals for H01, H10,
        H50, H90 and sigma, and a goodness-of-fit verdict. Without censoring the test is
        Filliben's probability-plot correlation test (scipy.stats.goodness_of_fit, Monte Carlo
        null); with censoring the same statistic on Kaplan-Meier adjusted ranks, with its null
        distribution simulated from the fit under the same censoring (a parametric bootstrap;
        censoring is taken as type I at each censored sample's own bound and, for the exact
        samples, at the tightest floor and ceiling seen).

    Raises
    ------
    ValueError
        For bad heights or labels, fewer than two distinct uncensored heights, a bad confidence
        or a bad ``n_bootstrap``.
    """
    heights = _as_heights("heights", heights)
    labels = _as_censoring(censored, heights.size)
    confidence = _as_confidence(confidence)
    if int(n_bootstrap) < 99:
        raise _bad("n_bootstrap", n_bootstrap, "must be >= 99 for a usable p-value")
    log_h = np.log(heights)
    exact = log_h[labels == ""]
    if np.unique(exact).size < 2:
        raise _bad(
            "heights", heights.tolist(),
            "need at least two distinct uncensored heights for a log-normal fit "
            "(for go/no-go drops use fit_probit)",
        )
    model = _NormalLikelihood(exact, log_h[labels == "below"], log_h[labels == "above"])
    a, b, l_max = model.maximise()
    fit = LognormalFit(
        mu=model.to_log_height(-a / b), sigma=model.scale / b, confidence=confidence,
        _model=model, _loglik_max=l_max, _a=a, _b=b,
        loglik=l_max + model.jacobian_term(), n=heights.size, n_exact=int(exact.size),
        n_above=int((labels == "above").sum()), n_below=int((labels == "below").sum()),
    )
    intervals = {name: fit.quantile(p) for name, p in
                 (("h01", 0.01), ("h10", 0.10), ("h50", 0.50), ("h90", 0.90))}
    low, high, _ = fit._sigma_interval_std(1.0 / b, a, open_high=False)
    intervals["sigma"] = (fit.sigma, low * model.scale, high * model.scale)

    ppcc, points, why = _ppcc(log_h, labels)
    p_value, method, qq = math.nan, "", None
    if points is not None:
        observed, positions = points
        qq = QQData(
            observed=np.exp(observed),
            theoretical=np.exp(fit.mu + fit.sigma * special.ndtri(positions)),
            positions=positions,
        )
        rng = np.random.default_rng(seed)
        if fit.n_exact == fit.n:
            result = stats.goodness_of_fit(
                # random_state (not rng, which needs scipy >= 1.15) keeps scipy 1.11+ working
                stats.norm, log_h, statistic="filliben", n_mc_samples=int(n_bootstrap),
                random_state=rng,
            )
            p_value = float(result.pvalue)
            method = "Filliben PPCC, Monte Carlo null (scipy.stats.goodness_of_fit)"
        else:
            p_value, used = _censored_ppcc_pvalue(fit, log_h, labels, ppcc, int(n_bootstrap), rng)
            method = (f"PPCC on Kaplan-Meier adjusted ranks, parametric-bootstrap null "
                      f"({used} of {int(n_bootstrap)} simulated samples usable)")
    if math.isfinite(p_value):
        verdict = ("log-normal rejected at 5 %" if p_value < 0.05
                   else "consistent with log-normal at 5 %")
    else:
        verdict = f"no goodness-of-fit test: {why}"
    return LognormalFit(
        mu=fit.mu, sigma=fit.sigma, confidence=confidence, _model=model, _loglik_max=l_max,
        _a=a, _b=b, intervals=intervals, loglik=fit.loglik, n=fit.n, n_exact=fit.n_exact,
        n_above=fit.n_above, n_below=fit.n_below, ppcc=ppcc, p_value=p_value, verdict=verdict,
        gof_method=method, qq=qq,
    )


def _censored_ppcc_pvalue(fit, log_h, labels, observed_ppcc, n_bootstrap, rng):
    """Parametric-bootstrap p-value of the censored PPCC (small values mean poor fit)."""
    floor = log_h[labels == "below"].max() if (labels == "below").any() else -math.inf
    ceiling = log_h[labels == "above"].min() if (labels == "above").any() else math.inf
    lower = np.where(labels == "below", log_h, floor)  # each sample's own censoring window
    upper = np.where(labels == "above", log_h, ceiling)
    simulated = []
    for _ in range(n_bootstrap):
        draw = rng.normal(fit.mu, fit.sigma, size=log_h.size)
        sim_labels = np.full(log_h.size, "", dtype=object)
        sim_labels[draw <= lower] = "below"
        sim_labels[draw > upper] = "above"
        sim_values = np.where(sim_labels == "below", lower,
                              np.where(sim_labels == "above", upper, draw))
        value, _, _ = _ppcc(sim_values, sim_labels)
        if math.isfinite(value):
            simulated.append(value)
    simulated = np.asarray(simulated)
    if simulated.size < 99:
        return math.nan, int(simulated.size)
    return float((1 + np.sum(simulated <= observed_ppcc)) / (simulated.size + 1)), simulated.size


# --------------------------------------------------------------------------------------------
# empirical go curve with a simultaneous band


def go_curve(
    heights, censored=None, *, confidence: float = 0.95, grid=None, units: str = ""
) -> xr.Dataset:
    """Empirical P(go | H) of a set of critical heights, with a simultaneous confidence band.

    A drop from H goes when H >= H_c, so P(go | H) is the fraction of samples with H_c <= H
    (the empirical CDF of the critical heights).

    Parameters
    ----------
    heights : array_like of float
        Critical heights, or their censoring bounds, > 0.
    censored : array_like of str, optional
        ``""``, ``"above"`` (no event up to this height) or ``"below"`` (an event already at this
        height), as in :func:`fit_lognormal`. None: all exact.
    confidence : float, optional
        Simultaneous coverage of the band.
    grid : array_like of float, optional
        Heights at which to evaluate (> 0). Default: every distinct sample height, where the
        curve steps (it is right-continuous, constant between them).
    units : str, optional
        Unit of the heights, recorded in the attributes (e.g. "ft").

    Returns
    -------
    xarray.Dataset
        Over dimension ``height``: ``p_go`` (the empirical fraction; NaN where censored samples
        leave it unknown), ``p_go_low`` and ``p_go_high`` (the band), ``identified`` (bool).
        An "above" sample is a no-go at every height up to its bound and unknown above it; a
        "below" sample is a go at every height from its bound and unknown under it. Where
        samples are unknown the band is built on the lowest and highest fractions they allow:
        [F_lower - eps, F_upper + eps], eps = sqrt(ln(2 / alpha) / (2 n)) (Dvoretzky-Kiefer-
        Wolfowitz inequality with Massart's constant), which still covers the true curve with
        probability >= ``confidence`` at every height at once, whatever caused the censoring.

    Raises
    ------
    ValueError
        For bad heights, labels, confidence or grid.
    """
    heights = _as_heights("heights", heights)
    labels = _as_censoring(censored, heights.size)
    confidence = _as_confidence(confidence)
    grid = np.unique(heights) if grid is None else np.sort(_as_heights("grid", grid))
    n = heights.size
    exact = np.sort(heights[labels == ""])
    below = np.sort(heights[labels == "below"])
    above = np.sort(heights[labels == "above"])
    known_go = np.searchsorted(exact, grid, side="right") + np.searchsorted(below, grid, "right")
    unknown = (below.size - np.searchsorted(below, grid, side="right")) + np.searchsorted(
        above, grid, side="left"
    )
    lower_fraction = known_go / n
    upper_fraction = (known_go + unknown) / n
    epsilon = math.sqrt(math.log(2.0 / (1.0 - confidence)) / (2.0 * n))
    identified = unknown == 0
    unit_attrs = {"units": units} if units else {}
    return xr.Dataset(
        {
            "p_go": ("height", np.where(identified, lower_fraction, np.nan),
                     {"long_name": "empirical P(go | H)", "units": "1"}),
            "p_go_low": ("height", np.clip(lower_fraction - epsilon, 0.0, 1.0),
                         {"long_name": "lower edge of the simultaneous band", "units": "1"}),
            "p_go_high": ("height", np.clip(upper_fraction + epsilon, 0.0, 1.0),
                          {"long_name": "upper edge of the simultaneous band", "units": "1"}),
            "identified": ("height", identified,
                           {"long_name": "no censored sample leaves P(go | H) unknown here"}),
        },
        coords={"height": ("height", grid, {"long_name": "drop height", **unit_attrs})},
        attrs={
            "confidence": confidence,
            "band": "Dvoretzky-Kiefer-Wolfowitz, Massart (1990) constant; simultaneous",
            "dkw_epsilon": epsilon,
            "n": n,
            "n_above": int(above.size),
            "n_below": int(below.size),
            "height_units": units or "as the input heights",
        },
    )


# --------------------------------------------------------------------------------------------
# scores


@dataclass(frozen=True)
class DropScores:
    """How well a predicted P(go | h) explains experimental drops.

    Attributes
    ----------
    p_go : ndarray
        Predicted probability of a go at each drop [-].
    p_outcome : ndarray
        Predicted probability of what did happen (p_go for a go, 1 - p_go for a no-go) [-].
    log_likelihood : float
        Sum of ln p_outcome (-inf if an outcome was predicted impossible) [-].
    log_score : float
        Mean of -ln p_outcome per drop: lower is better, 0 is perfect, ln 2 = 0.693 is a coin.
    brier : float
        Mean of (p_go - outcome)^2: lower is better, 0.25 is a coin.
    brier_base_rate : float
        Brier score of always predicting the observed go fraction, a no-skill reference.
    n : int
        Number of drops.
    """

    p_go: np.ndarray
    p_outcome: np.ndarray
    log_likelihood: float
    log_score: float
    brier: float
    brier_base_rate: float
    n: int


def score_drops(prob_go: Callable, heights, went) -> DropScores:
    """Score a predicted go curve against experimental drops.

    Parameters
    ----------
    prob_go : callable
        P(go | h) for an array of heights (a fit's ``probability``, an interpolated curve...),
        returning values in [0, 1], in the same height unit as `heights`.
    heights : array_like of float
        Drop heights, > 0.
    went : array_like of bool
        Outcome of each drop (True = go).

    Returns
    -------
    DropScores
        Per-drop probabilities and totals (log-likelihood, log score, Brier score).

    Raises
    ------
    ValueError
        For bad heights or outcomes, or when `prob_go` is not callable or returns values outside
        [0, 1], NaN, or the wrong shape.
    """
    if not callable(prob_go):
        raise _bad("prob_go", prob_go, "must be a callable returning P(go | h)")
    heights = _as_heights("heights", heights)
    went = _as_outcomes("went", went, heights.size, "heights")
    p_go = np.asarray(prob_go(heights), dtype=float)
    if p_go.shape != heights.shape:
        raise _bad("prob_go", prob_go, f"returned shape {p_go.shape} for {heights.size} heights")
    bad = ~((p_go >= 0) & (p_go <= 1))
    if bad.any():
        index = int(np.flatnonzero(bad)[0])
        raise _bad("prob_go", prob_go,
                   f"returned {float(p_go[index])!r} at height {heights[index]:g}; "
                   "must be in [0, 1]")
    p_outcome = np.where(went, p_go, 1.0 - p_go)
    with np.errstate(divide="ignore"):
        log_p = np.log(p_outcome)
    outcome = went.astype(float)
    return DropScores(
        p_go=p_go, p_outcome=p_outcome, log_likelihood=float(log_p.sum()),
        log_score=float(-log_p.mean()), brier=float(np.mean((p_go - outcome) ** 2)),
        brier_base_rate=float(np.mean((outcome.mean() - outcome) ** 2)), n=heights.size,
    )


@dataclass(frozen=True)
class H50Comparison:
    """Predicted against experimental median height, each with its interval.

    Attributes
    ----------
    predicted, experimental : tuple of float
        (estimate, low, high) [input unit]; NaN where a side gives no estimate (e.g. "> 150 ft"
        is (nan, 150, inf)).
    ratio : float
        predicted / experimental estimate [-] (NaN if either is missing).
    intervals_overlap : bool
        Whether the two intervals share any height.
    predicted_inside : bool
        Whether the predicted estimate lies in the experimental interval.
    """

    predicted: tuple[float, float, float]
    experimental: tuple[float, float, float]
    ratio: float
    intervals_overlap: bool
    predicted_inside: bool


def _as_triple(name: str, value) -> tuple[float, float, float]:
    if hasattr(value, "quantile"):
        return tuple(float(v) for v in value.quantile(0.5))  # type: ignore[return-value]
    if isinstance(value, (int, float)):
        return (float(value), math.nan, math.nan)
    try:
        triple = tuple(float(v) for v in value)
    except (TypeError, ValueError):
        raise _bad(name, value, "must be a fit, a number or (estimate, low, high)") from None
    if len(triple) != 3:
        raise _bad(name, value, "must be (estimate, low, high)")
    return triple  # type: ignore[return-value]


def compare_h50(predicted, experimental) -> H50Comparison:
    """Compare a predicted and an experimental H50, each with its interval.

    Parameters
    ----------
    predicted, experimental : fit, float or sequence of 3 floats
        A fit (its ``quantile(0.5)`` is used), a bare estimate (no interval), or
        (estimate, low, high) in the same unit; use NaN for an unknown entry, e.g.
        ``(nan, 150.0, inf)`` for "more than 150 ft".

    Returns
    -------
    H50Comparison
        Both triples, their ratio, and whether the intervals overlap.
    """
    pred = _as_triple("predicted", predicted)
    expt = _as_triple("experimental", experimental)

    def span(t):
        low = t[1] if math.isfinite(t[1]) or t[1] == math.inf else t[0]
        high = t[2] if not math.isnan(t[2]) else t[0]
        return low, high

    p_low, p_high = span(pred)
    e_low, e_high = span(expt)
    overlap = bool(p_low <= e_high and e_low <= p_high)
    inside = bool(e_low <= pred[0] <= e_high)
    return H50Comparison(pred, expt, pred[0] / expt[0], overlap, inside)


# --------------------------------------------------------------------------------------------
# figures


def _drops_of(drops):
    if hasattr(drops, "heights") and hasattr(drops, "went"):
        return np.asarray(drops.heights, float), np.asarray(drops.went, bool)
    heights, went = drops
    return np.asarray(heights, float), np.asarray(went, bool)


def plot_go_curve(ax, curve: xr.Dataset, drops=None, *, label: str = "ensemble"):
    """Draw a go curve (from :func:`go_curve`) with its band, and optionally drops.

    Parameters
    ----------
    ax : matplotlib.axes.Axes
        Axes to draw on (log height axis).
    curve : xarray.Dataset
        Output of :func:`go_curve`.
    drops : object with ``heights`` and ``went``, or (heights, went), optional
        Experimental drops, drawn at P = 1 (go, filled) and P = 0 (no-go, open).
    label : str, optional
        Legend label of the curve.

    Returns
    -------
    matplotlib.axes.Axes
        The same axes.
    """
    height = curve["height"].values
    ax.step(height, curve["p_go"].values, where="post", label=label)
    ax.fill_between(height, curve["p_go_low"].values, curve["p_go_high"].values, step="post",
                    alpha=0.3, label=f"{curve.attrs.get('confidence', 0.95):.0%} band")
    if drops is not None:
        drop_h, went = _drops_of(drops)
        ax.plot(drop_h[went], np.ones(went.sum()), "o", color="k", label="go")
        ax.plot(drop_h[~went], np.zeros((~went).sum()), "o", mfc="none", color="k",
                label="no-go")
    ax.set_xscale("log")
    ax.set_ylim(-0.05, 1.05)
    units = curve["height"].attrs.get("units", "")
    ax.set_xlabel(f"drop height [{units}]" if units else "drop height")
    ax.set_ylabel("P(go | H)")
    ax.legend(loc="best")
    return ax


def plot_qq(ax, fit: LognormalFit):
    """Log-normal Q-Q plot of a :func:`fit_lognormal` result (uncensored samples).

    Parameters
    ----------
    ax : matplotlib.axes.Axes
        Axes to draw on (log-log).
    fit : LognormalFit
        A fit with ``qq`` data.

    Returns
    -------
    matplotlib.axes.Axes
        The same axes.
    """
    if fit.qq is None:
        raise _bad("fit", fit.verdict, "has no Q-Q data (too few uncensored samples)")
    theoretical, observed = fit.qq.theoretical, fit.qq.observed
    ax.plot(theoretical, observed, "o", label="uncensored samples")
    span = [min(theoretical.min(), observed.min()), max(theoretical.max(), observed.max())]
    ax.plot(span, span, "-", color="grey", label="1:1")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("fitted log-normal quantile")
    ax.set_ylabel("observed height")
    ax.set_title(f"PPCC {fit.ppcc:.3f}, p = {fit.p_value:.2g}: {fit.verdict}")
    ax.legend(loc="best")
    return ax

