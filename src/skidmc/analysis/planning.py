"""Planning go/no-go drops: the next drop to make, a sequential procedure, and classical designs.

The state of knowledge about a target is a posterior of the probit model on ln h
(:mod:`skidmc.analysis.posterior`): P(go | h) = Phi((ln h - m) / sigma), with a prior that is the
model's prior predictive (:func:`~skidmc.analysis.posterior.physics_prior`; later a calibration
posterior) or a vague one (:func:`~skidmc.analysis.posterior.vague_prior`).

**The next drop** (:func:`next_drop`): the height that minimises the expected posterior variance
of ln q_p (q_p the height at which P(go) = p; p = 0.5 gives H50) after the drop's outcome, one
drop ahead. The quantity of interest is a scalar, so the criterion is its variance (Bayesian
c-optimality) rather than the entropy or determinant of the whole (m, sigma) posterior, which
would also spend drops on sigma for its own sake; variance rather than the entropy of ln q_p
because the stopping rule is an interval width on ln H50, which for a near-normal posterior is
proportional to the sd, and because the variance is an exact sum over the grid while a marginal
entropy needs a density estimate. With a binary outcome y at height h, and w the posterior cell
masses, the expectation is exact:
E[Var(theta | y)] = sum w theta^2 - (sum w P theta)^2 / P1 - (sum w (1-P) theta)^2 / (1 - P1),
P = Phi((ln h - m)/sigma), P1 = sum w P; the expected gain is Var(theta) - E[Var(theta | y)].

**The sequential procedure** (:class:`SequentialPlan`): that choice drop after drop, stopping when
the H50's equal-tailed 90 % interval lies within +-10 % of its median, or at a budget of drops.

**Classical procedures**, for comparison, on ln h (each proposes the next height from the
drops so far; none uses the physics):

- :class:`UpDown`: Dixon & Mood (1948), "A method for obtaining and analyzing sensitivity data",
  JASA 43:109: one step up after a no-go, down after a go.
- :class:`Langlie`: Langlie (1962), "A reliability test method for 'one-shot' items",
  Aeronutronic publication U-1792: between limits L and U, the first test at (L+U)/2; then,
  working back from the last test n, the first p at which tests p..n hold as many gos as no-gos
  gives x = (x_p + x_n)/2; if there is none, x = (x_n + U)/2 after a no-go, (x_n + L)/2 after a
  go.
- :class:`Neyer`: Neyer (1994), "A D-optimality-based sensitivity test", Technometrics 36:61-70:
  part 1 brackets the response from guesses (mu_min, mu_max, sigma_g); part 2 closes the gap
  between the lowest go and the highest no-go, shrinking sigma_g by 0.8 when the gap is below it;
  part 3, once the outcomes overlap, puts the next test where it most increases the determinant of
  the Fisher information at the maximum-likelihood estimate (mu clipped to the tested range,
  sigma to its width). The part 1 and 2 rules are those of R gonogo (Roediger, AFIT-R/gonogo,
  functions nphaseI/ykpm), which implements the paper; they were not checked against the paper's
  printed examples (not at hand).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import special

from skidmc.analysis.checks import bad as _bad
from skidmc.analysis.posterior import NormalPrior, _build_grid, _Grid

__all__ = [
    "DropPlan",
    "Langlie",
    "Neyer",
    "SequentialPlan",
    "UpDown",
    "classical_designs",
    "next_drop",
    "simulate_sequence",
]

_Z90 = float(special.ndtri(0.95))


# --------------------------------------------------------------------------------------------
# an incremental grid posterior for drop-by-drop use


class _Tracker:
    """Posterior of (m, ln sigma) after each drop: a small grid, rebuilt when it no longer fits.

    Each drop adds its log-likelihood to the grid (O(cells)); the grid is rebuilt from all drops
    (:func:`~skidmc.analysis.posterior._build_grid`, on the region within ``threshold`` + 4 of
    the maximum) when the posterior's region (log density within ``threshold`` of the maximum)
    touches the box or fills less than 40 % of it in m or in ln sigma.
    """

    def __init__(self, prior, shape=(24, 40), threshold=16.0):
        self.prior, self.shape, self.threshold = prior, shape, threshold
        self.x: list[float] = []
        self.y: list[bool] = []
        self._rebuild()

    def _rebuild(self):
        # built on a box 4 log units wider than the region checked in add(): room to move
        self.grid = _build_grid(self.prior, np.array(self.x), np.array(self.y, bool),
                                shape=self.shape, threshold=self.threshold + 4.0,
                                coarse=self.shape)
        self.rebuilds = getattr(self, "rebuilds", -1) + 1
        self._logw = self.grid.logw

    def add(self, x: float, went: bool):
        self.x.append(float(x))
        self.y.append(bool(went))
        g = self.grid
        u = (x - g.m[None, :]) / g.sigma[:, None]
        logw = self._logw + special.log_ndtr(u if went else -u)
        keep = logw > logw.max() - self.threshold
        rows, cols = np.flatnonzero(keep.any(axis=1)), np.flatnonzero(keep.any(axis=0))
        n_s, n_m = logw.shape
        touches = rows[0] == 0 or rows[-1] == n_s - 1 or cols[0] == 0 or cols[-1] == n_m - 1
        small = (cols[-1] - cols[0] + 1) < 0.4 * n_m or (rows[-1] - rows[0] + 1) < 0.4 * n_s
        if touches or small:
            self._rebuild()
        else:
            self._logw = logw
            self.grid = _Grid(g.m_edges, g.s_edges, logw)

    def h50(self, credibility=0.9):
        """(median, low, high) of ln H50."""
        tail = 0.5 * (1.0 - credibility)
        g = self.grid
        cdf = np.concatenate([[0.0], np.cumsum(g.w.sum(axis=0))])
        return tuple(float(np.interp(a, cdf, g.m_edges)) for a in (0.5, tail, 1.0 - tail))

    def quantile(self, p=0.5, credibility=0.9):
        if p == 0.5:
            return self.h50(credibility)
        z = float(special.ndtri(p))
        tail = 0.5 * (1.0 - credibility)
        return tuple(self.grid.quantile_of(z, a) for a in (0.5, tail, 1.0 - tail))


def _expected_variance(grid: _Grid, x_candidates: np.ndarray, z: float):
    """Current variance of theta = m + z sigma and its expectation after a drop at each x."""
    w = grid.w.ravel()
    theta = (grid.m[None, :] + z * grid.sigma[:, None]).ravel()
    wt = w * theta
    u = (x_candidates[:, None, None] - grid.m[None, None, :]) / grid.sigma[None, :, None]
    prob = special.ndtr(u.reshape(x_candidates.size, -1))
    p1 = prob @ w
    a1 = prob @ wt
    total, total2 = float(wt.sum()), float(wt @ theta)
    a0, p0 = total - a1, 1.0 - p1
    tiny = 1e-300
    expected = total2 - a1 * a1 / np.maximum(p1, tiny) - a0 * a0 / np.maximum(p0, tiny)
    return total2 - total * total, np.maximum(expected, 0.0), p1


def _candidates(grid: _Grid, z: float, n: int = 41, limits=None) -> np.ndarray:
    """Log heights to consider: theta's posterior mean +- 2.5 sd, widened by 2 sigma."""
    mean, var = grid.moments(z)
    s = float(np.exp(np.sum(grid.w.sum(axis=1) * grid.log_sigma)))
    lo, hi = mean - 2.5 * math.sqrt(var) - 2.0 * s, mean + 2.5 * math.sqrt(var) + 2.0 * s
    if limits is not None:
        lo, hi = max(lo, limits[0]), min(hi, limits[1])
        if lo >= hi:
            lo, hi = limits
    return np.linspace(lo, hi, n)


def _choose(grid: _Grid, z: float, candidates=None, limits=None):
    """The candidate of least expected variance; without a list, refined once around it."""
    x = _candidates(grid, z, limits=limits) if candidates is None else np.asarray(candidates)
    var_now, expected, p1 = _expected_variance(grid, x, z)
    best = int(np.argmin(expected))
    if candidates is None and x.size > 1:  # a finer look between the neighbours
        step = x[1] - x[0]
        fine = np.linspace(x[best] - step, x[best] + step, 9)
        if limits is not None:
            fine = np.clip(fine, *limits)
        _, expected_f, p1_f = _expected_variance(grid, fine, z)
        i = int(np.argmin(expected_f))
        if expected_f[i] < expected[best]:
            return float(fine[i]), var_now, float(expected_f[i]), float(p1_f[i])
    return float(x[best]), var_now, float(expected[best]), float(p1[best])


# --------------------------------------------------------------------------------------------
# the next drop


@dataclass(frozen=True)
class DropPlan:
    """The next drop to make and what it is expected to teach.

    Attributes
    ----------
    height : float
        Recommended drop height [units].
    p_go : float
        Posterior predictive probability of a go there [-].
    sd_now, sd_expected : float
        Posterior sd of ln q_p now and expected after the drop [-] (sqrt of the variances of the
        criterion); their difference is the expected gain.
    p : float
        The quantile planned for (0.5: H50).
    estimate : (float, float, float)
        Current posterior median of q_p and its equal-tailed interval [units].
    credibility : float
    n, n_go : int
        Drops so far.
    units : str
    prior : str
        The prior in words.
    """

    height: float
    p_go: float
    sd_now: float
    sd_expected: float
    p: float
    estimate: tuple[float, float, float]
    credibility: float
    n: int
    n_go: int
    units: str
    prior: str

    @property
    def expected_gain(self) -> float:
        """Expected reduction of the posterior variance of ln q_p [-]."""
        return self.sd_now**2 - self.sd_expected**2


def next_drop(heights, went, prior, *, p: float = 0.5, credibility: float = 0.9,
              candidates=None, limits=None, units: str = "") -> DropPlan:
    """The drop height that minimises the expected posterior variance of ln q_p.

    Parameters
    ----------
    heights, went : array_like
        Drops so far (may be empty) [any unit; the prior's location must be in the same unit].
    prior : NormalPrior
        Prior of (ln H50, ln sigma) in the ln scale (:func:`physics_prior`, :func:`vague_prior`,
        or a calibration posterior's summary).
    p : float, optional
        Quantile to learn about (0.5: H50).
    credibility : float, optional
        Level of the reported interval.
    candidates : array_like, optional
        Heights allowed (e.g. the tower's settings) [units]; default: 61 heights spanning the
        central 95 % of the posterior of q_p widened by two sigma.
    limits : (float, float), optional
        Lowest and highest height the tower allows [units].
    units : str, optional
        Label for printing.

    Returns
    -------
    DropPlan
    """
    from skidmc.analysis.gonogo import _as_outcomes

    if getattr(prior, "scale", "ln") != "ln":
        raise _bad("prior.scale", prior.scale, 'planning works in the "ln" scale')
    if not 0.0 < float(p) < 1.0:
        raise _bad("p", p, "must be a probability in (0, 1)")
    h = np.asarray(heights, float).ravel()
    if h.size and (not np.all(np.isfinite(h)) or np.any(h <= 0)):
        raise _bad("heights", heights, "must be finite heights > 0")
    y = _as_outcomes("went", went, h.size, "heights") if h.size else np.zeros(0, bool)
    x = np.log(h)
    z = float(special.ndtri(p))
    grid = _build_grid(prior, x, y, shape=(81, 121))
    cand = None if candidates is None else np.log(np.asarray(candidates, float))
    lim = None if limits is None else (math.log(limits[0]), math.log(limits[1]))
    best, var_now, expected, p1 = _choose(grid, z, cand, lim)
    tail = 0.5 * (1.0 - credibility)
    estimate = tuple(float(np.exp(grid.quantile_of(z, a))) for a in (0.5, tail, 1.0 - tail))
    describe = prior.describe() if hasattr(prior, "describe") else str(prior)
    height = float(np.exp(best))
    if candidates is not None:  # the allowed height itself, not its exp(log(.)) round trip
        allowed = np.asarray(candidates, float).ravel()
        height = float(allowed[int(np.argmin(np.abs(cand - best)))])
    return DropPlan(height, p1, math.sqrt(var_now), math.sqrt(expected), float(p),
                    estimate, float(credibility), int(h.size), int(y.sum()), units, describe)


# --------------------------------------------------------------------------------------------
# stopping rule and the procedures


def _rule_met(ln_estimate, halfwidth: float) -> bool:
    med, low, high = ln_estimate
    return high - med <= math.log1p(halfwidth) and med - low <= -math.log1p(-halfwidth)


class SequentialPlan:
    """The planned procedure, drop by drop: ``next_height()``, ``add(height, went)``, ``done``.

    Parameters
    ----------
    prior : NormalPrior
        ln scale, location in ln of the height unit.
    p : float, optional
        Quantile planned for (0.5: H50).
    halfwidth : float, optional
        Stop when the ``credibility`` interval of q_p lies within +-halfwidth of its median
        (0.10: +-10 %).
    credibility : float, optional
    budget : int, optional
        Stop after this many drops whatever the interval.
    limits : (float, float), optional
        Lowest and highest height allowed [unit].
    """

    def __init__(self, prior, *, p=0.5, halfwidth=0.10, credibility=0.90, budget=60,
                 limits=None):
        if not 0.0 < halfwidth < 1.0:
            raise _bad("halfwidth", halfwidth, "must be in (0, 1), e.g. 0.10 for +-10 %")
        if int(budget) < 1:
            raise _bad("budget", budget, "must be >= 1")
        self.prior, self.p, self.halfwidth = prior, float(p), float(halfwidth)
        self.credibility, self.budget = float(credibility), int(budget)
        self.z = float(special.ndtri(self.p))
        self.limits = None if limits is None else (math.log(limits[0]), math.log(limits[1]))
        self.tracker = _Tracker(prior)

    def next_height(self) -> float:
        """The next height [unit]."""
        return float(np.exp(_choose(self.tracker.grid, self.z, limits=self.limits)[0]))

    def add(self, height: float, went: bool) -> None:
        """Record a drop's outcome."""
        if not (height > 0 and math.isfinite(height)):
            raise _bad("height", height, "must be a finite height > 0")
        self.tracker.add(math.log(height), bool(went))

    def estimate(self) -> tuple[float, float, float]:
        """Posterior median of q_p and its ``credibility`` interval [unit]."""
        return tuple(float(np.exp(v)) for v in self.tracker.quantile(self.p, self.credibility))

    @property
    def n(self) -> int:
        return len(self.tracker.x)

    @property
    def done(self) -> bool:
        """True once the interval rule is met or the budget is spent."""
        return self.n >= self.budget or _rule_met(
            self.tracker.quantile(self.p, self.credibility), self.halfwidth)


class UpDown:
    """Up-down (Bruceton) levels on ln h: Dixon & Mood (1948).

    Parameters
    ----------
    start : float
        First height [unit].
    step : float
        Step in ln h [-] (Dixon & Mood: about one sigma).
    """

    def __init__(self, start: float, step: float):
        self.x = math.log(start)
        self.step = float(step)

    def next_height(self) -> float:
        return math.exp(self.x)

    def add(self, height: float, went: bool) -> None:
        self.x = math.log(height) + (-self.step if went else self.step)


class Langlie:
    """Langlie (1962) one-shot levels on ln h between limits (lower, upper) [unit]."""

    def __init__(self, lower: float, upper: float):
        if not 0 < lower < upper:
            raise _bad("(lower, upper)", (lower, upper), "must be 0 < lower < upper")
        self.lo, self.hi = math.log(lower), math.log(upper)
        self.x: list[float] = []
        self.y: list[bool] = []

    def next_height(self) -> float:
        if not self.x:
            return math.exp(0.5 * (self.lo + self.hi))
        n = len(self.x)
        balance = 0
        for p in range(n - 1, -1, -1):  # tests p..n-1 (0-based) going back from the last
            balance += 1 if self.y[p] else -1
            if balance == 0:
                return math.exp(0.5 * (self.x[p] + self.x[-1]))
        limit = self.lo if self.y[-1] else self.hi
        return math.exp(0.5 * (self.x[-1] + limit))

    def add(self, height: float, went: bool) -> None:
        self.x.append(math.log(height))
        self.y.append(bool(went))


def _d_optimal(x, y, m, s):
    """Neyer's next level: maximise det of the probit Fisher information at (m, s) over m + k s."""
    del y  # the information of a binary probit design does not depend on the outcomes

    def weights(u):  # phi^2 / (Phi (1 - Phi)), in logs so that it stays finite in the tails
        log_phi = -0.5 * u * u - 0.5 * math.log(2.0 * math.pi)
        return np.exp(2.0 * log_phi - special.log_ndtr(u) - special.log_ndtr(-u))

    u = (np.asarray(x) - m) / s
    w = weights(u)
    info = np.array([[w.sum(), (w * u).sum()], [(w * u).sum(), (w * u * u).sum()]])
    k = np.linspace(-4.0, 4.0, 801)
    wk = weights(k)
    det = ((info[0, 0] + wk) * (info[1, 1] + wk * k * k) - (info[0, 1] + wk * k) ** 2)
    return m + float(k[int(np.argmax(det))]) * s


def _probit_mle(x, y, start=None, *, iterations=50):
    """Maximum-likelihood (mu, sigma) of overlapping probit data by Newton's method on (a, b).

    The log-likelihood in u = a + b x is concave (Pratt 1981), so Newton's method with step
    halving converges from any start; returns None when the maximum has b <= 0 (a response that
    falls with height). Used by :class:`Neyer` at every drop, where
    :func:`~skidmc.analysis.gonogo.fit_probit`'s checks and interval machinery are not needed
    (the two agree to 1e-6 in a test).
    """
    x, y = np.asarray(x, float), np.asarray(y, bool)
    sign = np.where(y, 1.0, -1.0)
    if start is None:
        theta = np.array([-np.mean(x) / max(np.std(x), 1e-3), 1.0 / max(np.std(x), 1e-3)])
    else:
        theta = np.array([-start[0] / start[1], 1.0 / start[1]])

    def loglik(t):
        return float(np.sum(special.log_ndtr(sign * (t[0] + t[1] * x))))

    current = loglik(theta)
    for _ in range(iterations):
        v = sign * (theta[0] + theta[1] * x)
        lam = np.exp(-0.5 * v * v - 0.5 * math.log(2 * math.pi) - special.log_ndtr(v))
        curv = -lam * (v + lam)
        grad = np.array([np.sum(sign * lam), np.sum(sign * lam * x)])
        hess = np.array([[curv.sum(), (curv * x).sum()], [(curv * x).sum(), (curv * x * x).sum()]])
        try:
            step = -np.linalg.solve(hess, grad)
        except np.linalg.LinAlgError:
            return None
        t = 1.0
        while t > 1e-10:
            trial = theta + t * step
            value = loglik(trial)
            if value >= current - 1e-12:
                break
            t *= 0.5
        theta, gain, current = trial, value - current, value
        if abs(gain) < 1e-12 and np.max(np.abs(t * step)) < 1e-10:
            break
    if not theta[1] > 0:
        return None
    return (-theta[0] / theta[1], 1.0 / theta[1])


class Neyer:
    """Neyer (1994) D-optimality-based levels on ln h.

    Parameters
    ----------
    mu_min, mu_max : float
        Guessed range of H50 [unit].
    sigma_guess : float
        Guess of sigma of ln h [-].
    """

    def __init__(self, mu_min: float, mu_max: float, sigma_guess: float):
        if not 0 < mu_min < mu_max:
            raise _bad("(mu_min, mu_max)", (mu_min, mu_max), "must be 0 < mu_min < mu_max")
        if not sigma_guess > 0:
            raise _bad("sigma_guess", sigma_guess, "must be > 0")
        self.lo, self.hi = math.log(mu_min), math.log(mu_max)
        self.sg = float(sigma_guess)
        self._start = None
        self.x: list[float] = []
        self.y: list[bool] = []

    def next_height(self) -> float:
        return math.exp(self._next())

    def _next(self) -> float:
        x, y = np.array(self.x), np.array(self.y, bool)
        if not x.size:
            return 0.5 * (self.lo + self.hi)
        xlo, xhi = float(x.min()), float(x.max())
        if not y.any():  # all no-go: go up
            return max(0.5 * (self.hi + xhi), xhi + 2.0 * self.sg, 2.0 * xhi - xlo)
        if y.all():  # all go: go down
            return min(0.5 * (self.lo + xlo), xlo - 2.0 * self.sg, 2.0 * xlo - xhi)
        lowest_go, highest_nogo = float(x[y].min()), float(x[~y].max())
        gap = lowest_go - highest_nogo
        if gap > self.sg:
            return 0.5 * (lowest_go + highest_nogo)
        if gap >= 0:
            m = min(max(0.5 * (lowest_go + highest_nogo), xlo), xhi)
            s = min(self.sg, xhi - xlo) if xhi > xlo else self.sg  # one height tested: sigma_g
            self.sg *= 0.8
            return _d_optimal(x, y, m, s)
        # overlap: part 3, the D-optimal level at the maximum-likelihood estimate
        mle = _probit_mle(x, y, self._start)
        if mle is None:  # a response decreasing with height: step away from the last outcome
            m = 0.5 * (lowest_go + highest_nogo)
            return m + 1.31525757633905 * self.sg * (1.0 if not y[-1] else -1.0)
        self._start = mle
        m = min(max(mle[0], xlo), xhi)
        s = min(mle[1], xhi - xlo)
        return _d_optimal(x, y, m, s)

    def add(self, height: float, went: bool) -> None:
        self.x.append(math.log(height))
        self.y.append(bool(went))


# --------------------------------------------------------------------------------------------
# one simulated sequence


@dataclass(frozen=True)
class SequenceResult:
    """Outcome of :func:`simulate_sequence`: drops, whether the rule was met, final estimate."""

    n: int
    stopped: bool
    h50: float
    low: float
    high: float
    heights: np.ndarray
    went: np.ndarray
    first_met: dict


def simulate_sequence(design, prior, truth, rng, *, halfwidth=0.10, credibility=0.90,
                      budget=120, also=()) -> SequenceResult:
    """Run one go/no-go sequence against a known truth (m, sigma) of the probit model.

    Parameters
    ----------
    design : SequentialPlan, UpDown, Langlie or Neyer
        Proposes heights (``next_height()``) and learns outcomes (``add``). A
        :class:`SequentialPlan` is also the estimator; for the others the estimate is the grid
        posterior under ``prior``, so every procedure is judged with the same estimator.
    prior : NormalPrior
    truth : (float, float)
        True location m [ln unit] and sigma [-].
    rng : numpy Generator
    halfwidth, credibility, budget
        The stopping rule (see :class:`SequentialPlan`).
    also : sequence of float, optional
        Looser half-widths whose first meeting is recorded (``first_met``: half-width -> (drops,
        median, low, high), or None if never met) without stopping there.

    Returns
    -------
    SequenceResult
        Drops made, whether the rule was met within the budget, the final posterior median of
        H50 and its interval [unit], the sequence, and ``first_met``.
    """
    m, sigma = truth
    planned = isinstance(design, SequentialPlan)
    tracker = design.tracker if planned else _Tracker(prior)
    heights, went = [], []
    stopped = False
    first_met = {float(a): None for a in also}
    while len(heights) < budget:
        h = design.next_height()
        if not (h > 0 and math.isfinite(h)):
            break
        go = bool(rng.random() < special.ndtr((math.log(h) - m) / sigma))
        design.add(h, go)
        if not planned:
            tracker.add(math.log(h), go)
        heights.append(h)
        went.append(go)
        estimate = tracker.h50(credibility)
        for a in first_met:
            if first_met[a] is None and _rule_met(estimate, a):
                first_met[a] = (len(heights), *(float(np.exp(v)) for v in estimate))
        if _rule_met(estimate, halfwidth):
            stopped = True
            break
    med, low, high = (float(np.exp(v)) for v in tracker.h50(credibility))
    return SequenceResult(len(heights), stopped, med, low, high, np.array(heights),
                          np.array(went, bool), first_met)


def classical_designs(prior: NormalPrior):
    """Up-down, Langlie and Neyer set up from the same prior guesses as the plan.

    Up-down starts at the prior median of H50 with a step of the prior median sigma (Dixon &
    Mood's advice: a step near sigma); Langlie's limits are the prior median times exp(+-3 sd);
    Neyer's mu range is the prior median times exp(+-2 sd), its sigma guess the prior median
    sigma.
    """
    (m0, s0), (l0, _) = prior.location, prior.log_sigma
    sg = math.exp(l0)
    return {
        "up-down": UpDown(math.exp(m0), sg),
        "Langlie": Langlie(math.exp(m0 - 3 * s0), math.exp(m0 + 3 * s0)),
        "Neyer": Neyer(math.exp(m0 - 2 * s0), math.exp(m0 + 2 * s0), sg),
    }
