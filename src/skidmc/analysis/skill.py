"""Skill of a predicted go curve against experimental drops, said plainly.

A prediction P(go | H) scored on a handful of drops means little on its own: a log score of
0.8 nats per drop reads as a number, not as "worse than tossing a coin". This module puts each
score next to the two forecasts that need no model:

* the **base rate**: always predict the observed fraction of goes f (log score
  -[f ln f + (1 - f) ln(1 - f)], Brier f (1 - f)); it knows the outcome fraction, so it is an
  in-sample, optimistic reference;
* a **coin flip**: always predict 1/2 (log score ln 2 = 0.693 nats, Brier 0.25).

A prediction has skill on a score only when it is lower (better) than *both* references; the
summary writes "no skill" otherwise. Skill scores 1 - S / S_ref (Brier and log skill scores,
Wilks, *Statistical Methods in the Atmospheric Sciences*, 3rd ed., 2011, Sec. 8.4) are given
against the better reference. With ten drops the scores' own sampling error is large: each is a
mean over drops, and its standard error (sd of the per-drop scores / sqrt(n)) is reported.

Where a target has at least :data:`MIN_DROPS_RELIABILITY` drops, :func:`reliability` bins the
predictions and gives the observed go fraction per bin with a Wilson interval
(:meth:`scipy.stats.binomtest` ``proportion_ci``), and :func:`plot_reliability` draws the
reliability (calibration) diagram.

Kept here rather than taken from a forecast-verification package: the scores are two lines each;
the references, the verdict and the small-sample standard errors are what this module adds.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import stats

__all__ = [
    "COIN_BRIER",
    "COIN_LOG_SCORE",
    "MIN_DROPS_RELIABILITY",
    "Skill",
    "plot_reliability",
    "reliability",
    "skill_scores",
]

#: Log score of always predicting 1/2 [nats per drop].
COIN_LOG_SCORE = math.log(2.0)
#: Brier score of always predicting 1/2 [1].
COIN_BRIER = 0.25
#: Fewest drops for which a reliability diagram is drawn (issue 39: "ten or more drops").
MIN_DROPS_RELIABILITY = 10


def _check(p_go, went) -> tuple[np.ndarray, np.ndarray]:
    p = np.asarray(p_go, dtype=float).ravel()
    w = np.asarray(went).ravel()
    if p.size == 0:
        raise ValueError("p_go = []: at least one drop is needed to score a prediction")
    if p.shape != w.shape:
        raise ValueError(f"p_go has {p.size} values but went has {w.size}: one per drop")
    if not np.all((p >= 0.0) & (p <= 1.0)):
        bad = p[~((p >= 0.0) & (p <= 1.0))][0]
        raise ValueError(f"p_go = {bad!r}: a probability must lie in [0, 1]")
    if w.dtype != bool:
        if not np.all(np.isin(w, (0, 1))):
            raise ValueError(f"went = {w.tolist()!r}: outcomes must be True/False or 1/0")
        w = w.astype(bool)
    return p, w


def _entropy(f: float) -> float:
    """-[f ln f + (1 - f) ln(1 - f)] [nats], 0 at f = 0 or 1."""
    return float(0.0 - sum(x * math.log(x) for x in (f, 1.0 - f) if x > 0.0))


@dataclass(frozen=True)
class Skill:
    """Scores of a prediction on n drops and of the base-rate and coin-flip references.

    Attributes
    ----------
    n, n_go : int
        Drops and goes among them.
    log_score, log_score_se : float
        Mean of -ln p(outcome) per drop [nats] and its standard error; lower is better.
    brier, brier_se : float
        Mean of (p_go - outcome)^2 [1] and its standard error; lower is better.
    base_rate : float
        Observed go fraction n_go / n [1].
    log_score_base_rate, brier_base_rate : float
        The base-rate forecast's scores.
    log_score_coin, brier_coin : float
        The coin flip's: ln 2 and 0.25.
    """

    n: int
    n_go: int
    log_score: float
    log_score_se: float
    brier: float
    brier_se: float
    base_rate: float
    log_score_base_rate: float
    brier_base_rate: float
    log_score_coin: float = COIN_LOG_SCORE
    brier_coin: float = COIN_BRIER

    @property
    def log_reference(self) -> float:
        """The better (lower) of the two references' log scores [nats]."""
        return min(self.log_score_base_rate, self.log_score_coin)

    @property
    def brier_reference(self) -> float:
        """The better (lower) of the two references' Brier scores [1]."""
        return min(self.brier_base_rate, self.brier_coin)

    @property
    def log_skill(self) -> bool:
        """True when the log score beats both references."""
        return self.log_score < self.log_reference

    @property
    def brier_skill(self) -> bool:
        """True when the Brier score beats both references."""
        return self.brier < self.brier_reference

    @property
    def log_skill_score(self) -> float:
        """1 - log score / better reference's (1 perfect, <= 0 no skill; nan if the reference
        is perfect, i.e. every drop had the same outcome)."""
        ref = self.log_reference
        return 1.0 - self.log_score / ref if ref > 0 else math.nan

    @property
    def brier_skill_score(self) -> float:
        """1 - Brier / better reference's Brier (nan when that reference is perfect)."""
        ref = self.brier_reference
        return 1.0 - self.brier / ref if ref > 0 else math.nan

    def verdict(self, score: str) -> str:
        """Words for one score (``"log"`` or ``"brier"``): ``"skill"`` or why there is none."""
        if score not in ("log", "brier"):
            raise ValueError(f"score = {score!r}: choose 'log' or 'brier'")
        value = self.log_score if score == "log" else self.brier
        base = self.log_score_base_rate if score == "log" else self.brier_base_rate
        coin = self.log_score_coin if score == "log" else self.brier_coin
        if value < min(base, coin):
            return "skill"
        if self.n_go in (0, self.n):
            # Every drop had the same outcome: the base rate is perfect, nothing can beat it.
            head = "better than a coin flip; " if value < coin else "not better than a coin flip; "
            return head + "skill not measurable (every drop had the same outcome)"
        worse = [name for name, ref in (("a coin flip", coin), ("the base rate", base))
                 if value >= ref]
        return "no skill (not better than " + " or ".join(worse) + ")"


def skill_scores(p_go, went) -> Skill:
    """Log and Brier scores of predicted go probabilities against drops, with references.

    Parameters
    ----------
    p_go : array_like of float
        Predicted P(go) at each drop [1], in [0, 1].
    went : array_like of bool
        What each drop did (True = go).

    Returns
    -------
    Skill

    Raises
    ------
    ValueError
        Naming the argument and value, for empty input, mismatched lengths, probabilities
        outside [0, 1] or outcomes that are not booleans.
    """
    p, w = _check(p_go, went)
    outcome = w.astype(float)
    p_outcome = np.where(w, p, 1.0 - p)
    with np.errstate(divide="ignore"):
        per_log = -np.log(p_outcome)
    per_brier = (p - outcome) ** 2
    n = p.size

    def se(x):
        if n < 2 or not np.all(np.isfinite(x)):
            return math.nan
        return float(np.std(x, ddof=1) / math.sqrt(n))

    f = float(outcome.mean())
    return Skill(n=n, n_go=int(w.sum()), log_score=float(per_log.mean()), log_score_se=se(per_log),
                 brier=float(per_brier.mean()), brier_se=se(per_brier), base_rate=f,
                 log_score_base_rate=_entropy(f), brier_base_rate=f * (1.0 - f))


def reliability(p_go, went, *, bins: int = 5, confidence: float = 0.9) -> list[dict]:
    """Observed go fraction against predicted probability, per bin.

    Drops whose predictions take at most `bins` distinct values (drops repeated at a few
    heights) are grouped by value; otherwise by `bins` equal-width bins on [0, 1].

    Parameters
    ----------
    p_go, went
        As :func:`skill_scores`.
    bins : int
        Number of bins (>= 1).
    confidence : float
        Coverage of the Wilson interval of each bin's observed fraction, in (0, 1).

    Returns
    -------
    list of dict
        One per non-empty bin, by increasing prediction: ``predicted`` (mean P(go) in the bin),
        ``observed`` (go fraction), ``n``, ``n_go``, ``low``, ``high`` (Wilson interval).
    """
    p, w = _check(p_go, went)
    if int(bins) != bins or bins < 1:
        raise ValueError(f"bins = {bins!r}: must be a positive integer")
    if not 0.0 < confidence < 1.0:
        raise ValueError(f"confidence = {confidence!r}: must lie in (0, 1)")
    values = np.unique(p)
    if values.size <= bins:
        labels = np.searchsorted(values, p)
    else:
        labels = np.minimum((p * bins).astype(int), bins - 1)
    rows = []
    for label in np.unique(labels):
        sel = labels == label
        k, m = int(w[sel].sum()), int(sel.sum())
        ci = stats.binomtest(k, m).proportion_ci(confidence_level=confidence, method="wilson")
        rows.append({"predicted": float(p[sel].mean()), "observed": k / m, "n": m, "n_go": k,
                     "low": float(ci.low), "high": float(ci.high)})
    return rows


def plot_reliability(ax, rows: list[dict], *, confidence: float = 0.9, title: str = ""):
    """Draw a reliability diagram on `ax` from :func:`reliability`'s rows.

    Each bin: its observed go fraction against its mean prediction with the Wilson interval,
    labelled with its number of drops; the diagonal is perfect calibration.
    """
    ax.plot([0, 1], [0, 1], "k--", lw=0.8, label="perfectly calibrated")
    x = [r["predicted"] for r in rows]
    y = [r["observed"] for r in rows]
    err = [[r["observed"] - r["low"] for r in rows], [r["high"] - r["observed"] for r in rows]]
    ax.errorbar(x, y, yerr=err, fmt="o", color="C0", capsize=3,
                label=f"observed go fraction ({confidence:.0%} Wilson interval)")
    for r in rows:
        right = r["predicted"] > 0.6  # label on the side with room
        ax.annotate(f"{r['n_go']} goes in {r['n']} drops", (r["predicted"], r["observed"]),
                    textcoords="offset points", xytext=(-8 if right else 8, 6),
                    ha="right" if right else "left", fontsize=7)
    ax.set_xlim(-0.02, 1.02)
    ax.set_ylim(-0.02, 1.02)
    ax.set_xlabel("predicted P(go) at the drop height [-]")
    ax.set_ylabel("observed fraction of goes [-]")
    if title:
        ax.set_title(title, fontsize=9)
    ax.legend(fontsize=7, loc="upper left")
    return ax
