"""Global sensitivity analysis on arrays: Sobol' indices with bootstrap intervals, Morris screening.

Everything here is a pure function of a SALib ``problem`` dict and output arrays; reading
ensembles and studies is done elsewhere. The method notes (estimators, assumptions, validity,
literature) are in ``docs/sensitivity.md``.

* :func:`sobol_indices`: first-order (Saltelli 2010) and total (Jansen 1999) indices, optionally
  second-order (Saltelli 2002), on SALib's :func:`SALib.sample.sobol.sample` design; point
  estimates equal :func:`SALib.analyze.sobol.analyze`; intervals are percentile or BCa bootstrap
  intervals that resample base rows with all their linked rows.
* :func:`sobol_convergence`, :func:`sobol_stable`, :func:`grow_until_stable`: indices against the
  number of base rows N, a stopping rule, and a loop that doubles N reusing the rows already run
  (the SALib design with a fixed seed is a prefix of the larger one).
* :func:`prepare_output`, :func:`event_indicator`: the policy for censored and failed samples,
  and the 0/1 output "a drop from this height goes".
* :func:`morris_screening`: elementary-effects screening through SALib.
* :func:`plot_indices`, :func:`plot_convergence`: figures (matplotlib imported on use).
"""

from __future__ import annotations

import copy
import numbers
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np
import xarray as xr
from scipy.special import ndtr, ndtri

from skidmc.analysis.checks import bad as _bad
from skidmc.analysis.checks import check_confidence as _check_confidence
from skidmc.analysis.checks import check_seed as _check_seed

__all__ = [
    "GrowthResult",
    "PreparedOutput",
    "event_indicator",
    "grow_until_stable",
    "interval_half_width",
    "morris_screening",
    "input_label",
    "plot_convergence",
    "plot_indices",
    "prepare_output",
    "rows_per_base_row",
    "sobol_convergence",
    "sobol_indices",
    "sobol_stable",
]

#: Estimators, as recorded in the result's attributes.
ESTIMATORS = {"S1": "Saltelli 2010", "ST": "Jansen 1999", "S2": "Saltelli 2002"}

INTERVAL_METHODS = ("bca", "percentile")
POLICIES = ("cap", "drop", "cap+drop")

# Bootstrap resamples are drawn in batches so that the (batch x N) count matrix stays below
# about this many entries (32 MiB of float64) whatever N and the number of resamples.
_BATCH_ENTRIES = 4_000_000


# --------------------------------------------------------------------------- validation


def _check_problem(problem) -> tuple[list[str], list[str], bool]:
    """(parameter names, index names, grouped) of a SALib problem dict, or ValueError."""
    if not isinstance(problem, dict):
        # ValueError, not TypeError: every bad argument of this module raises ValueError
        raise ValueError(f"problem = {problem!r}: expected a SALib problem dict")  # noqa: TRY004
    for key in ("names", "num_vars"):
        if key not in problem:
            raise ValueError(f"problem = {problem!r}: missing the key {key!r} "
                             "(a SALib problem needs 'names' and 'num_vars')")
    names = list(problem["names"])
    num_vars = problem["num_vars"]
    if (isinstance(num_vars, bool) or not isinstance(num_vars, numbers.Integral)
            or num_vars < 1 or num_vars != len(names)):
        raise ValueError(f"problem['num_vars'] = {num_vars!r}: expected a positive integer equal "
                         f"to the number of names ({len(names)})")
    if len(set(names)) != len(names):
        raise ValueError(f"problem['names'] = {names!r}: names must be unique")
    groups = problem.get("groups")
    if not groups:
        return names, names, False
    groups = list(groups)
    if len(groups) != len(names):
        raise ValueError(f"problem['groups'] = {groups!r}: expected one group per name "
                         f"({len(names)} names)")
    # SALib's order of groups: first appearance (pandas.unique in SALib.util).
    return names, list(dict.fromkeys(groups)), True


def rows_per_base_row(problem: dict, second_order: bool = False) -> int:
    """Rows of SALib's Sobol' design per base row: G + 2, or 2 G + 2 with second order.

    G is the number of parameters, or of groups when the problem has a ``groups`` key.

    Parameters
    ----------
    problem : dict
        SALib problem (``names``, ``num_vars``, optional ``groups``).
    second_order : bool
        Whether the design was drawn with ``calc_second_order=True``.

    Returns
    -------
    int
    """
    _, index_names, _ = _check_problem(problem)
    n_index = len(index_names)
    return 2 * n_index + 2 if second_order else n_index + 2


def _check_resamples(resamples) -> int:
    if isinstance(resamples, bool) or not isinstance(resamples, numbers.Integral) or resamples < 2:
        raise ValueError(f"resamples = {resamples!r}: expected an integer >= 2")
    return int(resamples)


def _check_outputs(Y, k: int, second_order: bool, name: str = "Y") -> np.ndarray:
    """Y as a float (N, k) block matrix, one row per base row, or ValueError."""
    y = np.asarray(Y, dtype=float)
    if y.ndim != 1:
        raise ValueError(f"{name} has shape {y.shape}: expected a 1-D array of outputs")
    if y.size % k or y.size < 2 * k:
        raise ValueError(f"{name} has {y.size} values: expected N * {k} with N >= 2 (the design "
                         f"has {k} rows per base row with second_order={second_order})")
    bad = np.flatnonzero(~np.isfinite(y))
    if bad.size:
        raise ValueError(f"{name}[{bad[0]}] = {float(y[bad[0]])!r} ({bad.size} non-finite "
                         "values): choose a policy with prepare_output first")
    if np.ptp(y) == 0.0:
        raise ValueError(f"{name} is constant ({float(y[0])!r}): the output variance is 0 and "
                         "the indices are undefined")
    return y.reshape(-1, k)


# --------------------------------------------------------------------------- estimators
#
# Every estimator used here is a smooth function of means over base rows of a few per-row
# products ("features"). Computing the features once makes the point estimate, every bootstrap
# replicate (a weighted mean: counts @ features) and every leave-one-out jackknife value (sum
# minus one row) cheap and exactly consistent with each other.
#
# Why not the libraries' bootstraps: SALib.analyze.sobol only gives a symmetric normal
# half-width, keeps no replicates for S2, and treats seed=0 as "no seed" (`if seed:`);
# scipy.stats.sobol_indices(...).bootstrap is BCa only, takes no seed (not reproducible), has no
# second order and centres the output differently from SALib (so its point estimates differ
# from SALib's); scipy.stats.bootstrap computes BCa's jackknife by re-evaluating the statistic on
# N leave-one-out samples (O(N^2) work), whereas here it is O(N). The interval formulas follow
# scipy.stats.bootstrap and a test checks they agree with it on the same replicates.


@dataclass(frozen=True)
class _Layout:
    """Column layout of the feature matrix for G indices."""

    n_index: int
    second_order: bool
    pairs: tuple[np.ndarray, np.ndarray] = field(init=False)

    def __post_init__(self):
        object.__setattr__(self, "pairs", np.triu_indices(self.n_index, 1))


def _features(blocks: np.ndarray, layout: _Layout) -> np.ndarray:
    """Per-base-row features (N, K) of the standardised output blocks (N, k).

    Block columns are SALib's order: A, AB_1..AB_G, [BA_1..BA_G,] B.
    """
    g = layout.n_index
    a, b = blocks[:, 0], blocks[:, -1]
    ab = blocks[:, 1:1 + g]
    cols = [blocks.mean(axis=1)[:, None], a[:, None], b[:, None], (a * a)[:, None],
            (b * b)[:, None], (a * b)[:, None], ab, b[:, None] * ab, (a[:, None] - ab) ** 2]
    if layout.second_order:
        ba = blocks[:, 1 + g:1 + 2 * g]
        j, k = layout.pairs
        cols += [ba, ba[:, j] * ab[:, k]]
    return np.concatenate(cols, axis=1)


def _indices_from_means(m: np.ndarray, layout: _Layout) -> np.ndarray:
    """Indices (..., 2 G [+ pairs]) = S1, ST [, S2 of pairs j < k] from feature means (..., K).

    The output is centred by the mean of all rows (as SALib does), recomputed from the means so
    that a resample is centred by its own mean.
    """
    g = layout.n_index
    centre, ma, mb, maa, mbb, mab = (m[..., i] for i in range(6))
    m_ab = m[..., 6:6 + g]
    m_b_ab = m[..., 6 + g:6 + 2 * g]
    m_sq = m[..., 6 + 2 * g:6 + 3 * g]
    # variance of the pooled A and B outputs (ddof 0), as in Saltelli 2010 and SALib
    var = 0.5 * (maa + mbb) - (0.5 * (ma + mb)) ** 2
    with np.errstate(divide="ignore", invalid="ignore"):
        s1 = (m_b_ab - mab[..., None] - centre[..., None] * (m_ab - ma[..., None])) / var[..., None]
        st = 0.5 * m_sq / var[..., None]
        out = [s1, st]
        if layout.second_order:
            j, k = layout.pairs
            m_ba = m[..., 6 + 3 * g:6 + 4 * g]
            m_ba_ab = m[..., 6 + 4 * g:]
            cross = m_ba[..., j] + m_ab[..., k] - ma[..., None] - mb[..., None]
            v_jk = (m_ba_ab - mab[..., None] - centre[..., None] * cross) / var[..., None]
            out.append(v_jk - s1[..., j] - s1[..., k])
    return np.concatenate(out, axis=-1)


def _bootstrap_replicates(features: np.ndarray, layout: _Layout, resamples: int,
                          rng: np.random.Generator) -> np.ndarray:
    """Indices on `resamples` bootstrap resamples of the base rows, shape (resamples, n_stat).

    A resample draws N base rows with replacement; each carries its whole block (A, B, AB_i,
    BA_i), which is what makes the replicate a draw of the same estimator.
    """
    n = features.shape[0]
    batch = max(1, min(resamples, _BATCH_ENTRIES // n))
    out = []
    for start in range(0, resamples, batch):
        size = min(batch, resamples - start)
        rows = rng.integers(0, n, size=(size, n))
        counts = np.bincount((rows + n * np.arange(size)[:, None]).ravel(),
                             minlength=size * n).reshape(size, n)
        out.append(_indices_from_means(counts @ features / n, layout))
    return np.concatenate(out, axis=0)


def _jackknife(features: np.ndarray, layout: _Layout) -> np.ndarray:
    """Leave-one-base-row-out indices, shape (N, n_stat), in O(N)."""
    n = features.shape[0]
    loo_means = (features.sum(axis=0) - features) / (n - 1)
    return _indices_from_means(loo_means, layout)


def _column_quantiles(replicates: np.ndarray, probs: np.ndarray) -> np.ndarray:
    """Quantile probs[i] of column i (linear interpolation, as numpy's default), NaNs ignored."""
    ordered = np.sort(replicates, axis=0)  # NaNs sort last
    count = np.sum(np.isfinite(replicates), axis=0)
    pos = probs * (count - 1)
    lo = np.floor(pos).astype(int)
    hi = np.minimum(lo + 1, count - 1)
    cols = np.arange(replicates.shape[1])
    frac = pos - lo
    low_value, high_value = ordered[lo, cols], ordered[hi, cols]
    # the interpolation form of numpy's "linear" method (exact when both values are equal)
    return low_value + frac * (high_value - low_value)


def _bootstrap_interval(estimate: np.ndarray, replicates: np.ndarray, jackknife: np.ndarray,
                        confidence: float, method: str) -> tuple[np.ndarray, np.ndarray]:
    """Two-sided percentile or BCa interval of each column (Efron & Tibshirani 1993, 14.3).

    estimate (m,), replicates (R, m), jackknife (N, m). Formulas as scipy.stats.bootstrap.
    """
    alpha = (1.0 - confidence) / 2.0
    m = estimate.shape[0]
    if method == "percentile":
        probs_low, probs_high = np.full(m, alpha), np.full(m, 1.0 - alpha)
    else:
        valid = np.isfinite(replicates)
        n_valid = valid.sum(axis=0)
        # share of replicates below the estimate, ties counted half (scipy's convention)
        below = (np.sum(replicates < estimate, axis=0)
                 + np.sum(replicates <= estimate, axis=0)) / (2.0 * n_valid)
        # An estimate outside every replicate would give z0 = -+inf and no interval; it is
        # clipped to half a replicate from the edge, i.e. the extreme replicate is used.
        below = np.clip(below, 0.5 / n_valid, 1.0 - 0.5 / n_valid)
        z0 = ndtri(below)
        u = jackknife.mean(axis=0) - jackknife
        sum_sq = np.sum(u * u, axis=0)
        with np.errstate(divide="ignore", invalid="ignore"):
            accel = np.where(sum_sq > 0.0, np.sum(u ** 3, axis=0) / (6.0 * sum_sq ** 1.5), 0.0)
        z_alpha = ndtri(alpha)
        shift_low, shift_high = z0 + z_alpha, z0 - z_alpha
        probs_low = ndtr(z0 + shift_low / (1.0 - accel * shift_low))
        probs_high = ndtr(z0 + shift_high / (1.0 - accel * shift_high))
    return _column_quantiles(replicates, probs_low), _column_quantiles(replicates, probs_high)


# --------------------------------------------------------------------------- Sobol' indices


def sobol_indices(problem: dict, Y, second_order: bool = False, confidence: float = 0.95,
                  resamples: int = 1000, seed: int = 0, interval: str = "bca") -> xr.Dataset:
    """Sobol' first-order, total (and second-order) indices with bootstrap intervals.

    Parameters
    ----------
    problem : dict
        SALib problem: ``names``, ``num_vars``, optional ``groups`` (then the indices are per
        group, in the order groups first appear). ``bounds`` are not used.
    Y : array_like, shape (N * k,)
        Outputs on the :func:`SALib.sample.sobol.sample` design of `problem` with the same
        `second_order`, in its row order; k = G + 2 (2 G + 2 with second order), G the number of
        parameters or groups. Any units; the indices are dimensionless [1].
    second_order : bool
        Whether the design has the BA rows (``calc_second_order=True``); adds S2.
    confidence : float
        Two-sided confidence level of the intervals, in (0, 1).
    resamples : int
        Bootstrap resamples (>= 2; 1000 or more for 95 % BCa intervals).
    seed : int
        Seed of the bootstrap (``numpy.random.default_rng(seed)``); 0 is a real seed.
    interval : {"bca", "percentile"}
        Bootstrap interval: bias-corrected and accelerated (acceleration from the jackknife over
        base rows) or plain percentile.

    Returns
    -------
    xarray.Dataset
        Over ``parameter`` (names, or group names): ``S1``, ``S1_low``, ``S1_high``, ``ST``,
        ``ST_low``, ``ST_high``, ``S1_contains_zero``, ``ST_contains_zero`` (the interval
        contains 0); with second order also ``S2``, ``S2_low``, ``S2_high``,
        ``S2_contains_zero`` over (``parameter``, ``parameter_2``), symmetric, NaN (False) on the
        diagonal. Attributes: ``S1_estimator``, ``ST_estimator`` (``S2_estimator``), ``N``,
        ``confidence``, ``interval``, ``resamples``, ``seed``, ``second_order`` (0/1),
        ``invalid_resamples`` (replicates with zero output variance, left out).

    Raises
    ------
    ValueError
        Bad `problem`, `Y` (wrong length for the design, NaN, constant), `confidence`,
        `resamples`, `seed` or `interval`; the message names the argument and shows the value.

    Notes
    -----
    Base rows are resampled with replacement, each with all its linked rows, so an interval
    reflects the estimator's sampling distribution under i.i.d. base rows; on a scrambled
    Sobol' design the true error is usually smaller (intervals 2-12x too wide from N = 1024)
    but not always (coverage 0.81-0.86 for small indices at N = 256, 0.86 for one G-function
    index at N = 1024; docs/sensitivity.md gives the table per N).
    """
    _, index_names, _ = _check_problem(problem)
    second_order = bool(second_order)
    confidence = _check_confidence(confidence)
    resamples = _check_resamples(resamples)
    seed = _check_seed(seed)
    if interval not in INTERVAL_METHODS:
        raise ValueError(f"interval = {interval!r}: expected one of {INTERVAL_METHODS}")
    layout = _Layout(len(index_names), second_order)
    k = 2 * layout.n_index + 2 if second_order else layout.n_index + 2
    blocks = _check_outputs(Y, k, second_order)
    # Standardise once (as SALib does); every estimator here is invariant to it, and it keeps
    # the sums of squares free of cancellation.
    flat = blocks.ravel()
    blocks = (blocks - flat.mean()) / flat.std()

    features = _features(blocks, layout)
    n = features.shape[0]
    estimate = _indices_from_means(features.mean(axis=0), layout)
    if not np.all(np.isfinite(estimate)):
        raise ValueError("Y: the outputs of the A and B rows are constant, so the variance in "
                         "the indices' denominator is 0")
    replicates = _bootstrap_replicates(features, layout, resamples, np.random.default_rng(seed))
    invalid = ~np.all(np.isfinite(replicates), axis=1)
    replicates[invalid] = np.nan
    low, high = _bootstrap_interval(estimate, replicates, _jackknife(features, layout),
                                    confidence, interval)
    return _to_dataset(estimate, low, high, index_names, layout, attrs={
        "S1_estimator": ESTIMATORS["S1"], "ST_estimator": ESTIMATORS["ST"],
        **({"S2_estimator": ESTIMATORS["S2"]} if second_order else {}),
        "N": n, "confidence": confidence, "interval": interval, "resamples": resamples,
        "seed": seed, "second_order": int(second_order), "invalid_resamples": int(invalid.sum()),
    })


def _to_dataset(estimate, low, high, index_names, layout: _Layout, attrs) -> xr.Dataset:
    g = layout.n_index
    data = {}
    for i, name in enumerate(("S1", "ST")):
        part = slice(i * g, (i + 1) * g)
        data[name] = ("parameter", estimate[part])
        data[f"{name}_low"] = ("parameter", low[part])
        data[f"{name}_high"] = ("parameter", high[part])
        data[f"{name}_contains_zero"] = ("parameter", (low[part] <= 0.0) & (high[part] >= 0.0))
    coords = {"parameter": list(index_names)}
    if layout.second_order:
        j, k = layout.pairs
        for suffix, values in (("", estimate), ("_low", low), ("_high", high)):
            square = np.full((g, g), np.nan)
            square[j, k] = square[k, j] = values[2 * g:]
            data[f"S2{suffix}"] = (("parameter", "parameter_2"), square)
        data["S2_contains_zero"] = (("parameter", "parameter_2"),
                                    (data["S2_low"][1] <= 0.0) & (data["S2_high"][1] >= 0.0))
        coords["parameter_2"] = list(index_names)
    return xr.Dataset(data, coords=coords, attrs=attrs)


# --------------------------------------------------------------------------- convergence


def interval_half_width(res: xr.Dataset, index: str = "ST") -> xr.DataArray:
    """Half-width of an asymmetric interval: the larger distance from estimate to either end.

    With this definition the interval lies inside estimate +- half-width, so "half-width <= h"
    means the index is known to within h at the interval's confidence.

    Parameters
    ----------
    res : xarray.Dataset
        A result of :func:`sobol_indices` (or :func:`sobol_convergence`).
    index : {"S1", "ST", "S2"}

    Returns
    -------
    xarray.DataArray
        Half-widths [1], same dims as ``res[index]``.
    """
    if index not in res:
        raise ValueError(f"index = {index!r}: not in the result ({sorted(res.data_vars)})")
    return np.maximum(res[index] - res[f"{index}_low"], res[f"{index}_high"] - res[index])


def sobol_stable(res: xr.Dataset, threshold: float = 0.1, half_width: float = 0.05,
                 indices: Sequence[str] = ("S1", "ST")) -> bool:
    """Stopping rule: every index that may exceed `threshold` is known to within `half_width`.

    An index "may exceed the threshold" when its interval's upper end is above it (an estimate
    below the threshold with a wide interval still counts); its half-width is
    :func:`interval_half_width` (the larger side of the interval).

    Parameters
    ----------
    res : xarray.Dataset
        A result of :func:`sobol_indices`.
    threshold : float
        Indices whose whole interval lies at or below this [1] are not checked.
    half_width : float
        Largest accepted half-width [1].
    indices : sequence of {"S1", "ST", "S2"}
        Which indices the rule looks at.

    Returns
    -------
    bool
    """
    for name, value in (("threshold", threshold), ("half_width", half_width)):
        if not isinstance(value, numbers.Real) or not value >= 0:
            raise _bad(name, value, "expected a number >= 0")
    for index in indices:
        width = interval_half_width(res, index)
        relevant = res[f"{index}_high"] > threshold
        if bool(np.any((width > half_width) & relevant)):
            return False
    return True


def sobol_convergence(problem: dict, Y, n_values: Sequence[int] | None = None,
                      second_order: bool = False, confidence: float = 0.95,
                      resamples: int = 1000, seed: int = 0, interval: str = "bca") -> xr.Dataset:
    """Indices and intervals against the number of base rows, from the first n base rows.

    Parameters
    ----------
    problem, Y, second_order, confidence, resamples, seed, interval
        As :func:`sobol_indices`; `Y` is the output of the largest design.
    n_values : sequence of int, optional
        Base-row counts to analyse, each in [2, N]. Default: the powers of 2 from 16 (or N if
        smaller) up to N, and N itself. Powers of 2 keep the Sobol' prefix balanced.

    Returns
    -------
    xarray.Dataset
        The variables of :func:`sobol_indices` with an ``N`` dimension first (coordinate: the
        base-row counts); attribute ``N`` is the design's total.
    """
    k = rows_per_base_row(problem, second_order)
    blocks = _check_outputs(Y, k, bool(second_order))
    n_total = blocks.shape[0]
    if n_values is None:
        n_values = [2 ** e for e in range(4, int(np.log2(n_total)) + 1)] or [n_total]
        if n_values[-1] != n_total:
            n_values.append(n_total)
    n_values = [int(v) for v in n_values]
    if not n_values or any(not 2 <= v <= n_total for v in n_values):
        raise ValueError(f"n_values = {n_values!r}: expected base-row counts in [2, {n_total}]")
    results = [sobol_indices(problem, blocks[:v].ravel(), second_order, confidence, resamples,
                             seed, interval) for v in n_values]
    conv = xr.concat(results, dim="N", combine_attrs="drop_conflicts")
    conv = conv.assign_coords(N=n_values)
    conv.attrs["N"] = n_total
    return conv


class GrowthResult(NamedTuple):
    """Outcome of :func:`grow_until_stable`.

    Attributes
    ----------
    result : xarray.Dataset
        Indices at the last N (attribute ``stable``: 1 when the rule was met, else 0).
    history : xarray.Dataset
        Indices at every N tried (dimension ``N``), with ``stable`` (bool) over ``N``.
    inputs : numpy.ndarray
        Design rows evaluated, shape (N k, num_vars), in the problem's bounds.
    outputs : numpy.ndarray
        Their outputs, shape (N k,).
    """

    result: xr.Dataset
    history: xr.Dataset
    inputs: np.ndarray
    outputs: np.ndarray


def _is_power_of_two(n) -> bool:
    return (not isinstance(n, bool) and isinstance(n, numbers.Integral) and n >= 2
            and not n & (n - 1))


def grow_until_stable(problem: dict, evaluate: Callable[[np.ndarray], np.ndarray],
                      n_start: int, n_max: int, *, second_order: bool = False,
                      threshold: float = 0.1, half_width: float = 0.05,
                      confidence: float = 0.95, resamples: int = 1000, seed: int = 0,
                      interval: str = "bca", design_seed: int | None = None) -> GrowthResult:
    """Double the number of base rows until :func:`sobol_stable` holds or N reaches `n_max`.

    Each step draws SALib's scrambled Sobol' design for 2N base rows with the same seed; its
    first N k rows are the rows already run (checked), so only the new rows are evaluated.

    Parameters
    ----------
    problem : dict
        SALib problem with ``bounds`` (and optional ``groups``).
    evaluate : callable
        ``evaluate(X) -> Y``: outputs (finite floats, shape (len(X),)) of design rows X.
    n_start, n_max : int
        First and largest base-row counts, powers of 2 with n_start <= n_max.
    second_order : bool
        Draw and analyse the second-order design.
    threshold, half_width
        The stopping rule (:func:`sobol_stable`).
    confidence, resamples, seed, interval
        As :func:`sobol_indices`.
    design_seed : int, optional
        Seed of the design's scrambling (default: `seed`).

    Returns
    -------
    GrowthResult
        ``(result, history, inputs, outputs)``.
    """
    from SALib.sample import sobol as sobol_sample

    for name, value in (("n_start", n_start), ("n_max", n_max)):
        if not _is_power_of_two(value):
            raise _bad(name, value, "expected a power of 2 >= 2")
    if n_max < n_start:
        raise _bad("n_max", n_max, f"expected >= n_start ({n_start})")
    if "bounds" not in problem:
        raise ValueError(f"problem = {problem!r}: missing the key 'bounds' needed to draw the "
                         "design")
    design_seed = _check_seed(seed if design_seed is None else design_seed)
    rows_per_base_row(problem, second_order)  # validates the problem before any evaluation
    inputs = np.empty((0, problem["num_vars"]))
    outputs = np.empty(0)
    history, stable_at = [], []
    n = n_start
    while True:
        # a fresh copy of the problem each call: SALib may add keys to it
        design = sobol_sample.sample(copy.deepcopy(problem), n, calc_second_order=second_order,
                                     scramble=True, seed=design_seed)
        done = inputs.shape[0]
        if not np.array_equal(design[:done], inputs):
            raise RuntimeError("SALib's design for the larger N does not start with the rows "
                               "already evaluated; cannot reuse them")
        new_inputs = design[done:]
        new_outputs = np.asarray(evaluate(new_inputs), dtype=float).reshape(-1)
        if new_outputs.shape != (new_inputs.shape[0],):
            raise ValueError(f"evaluate returned {new_outputs.size} values for "
                             f"{new_inputs.shape[0]} rows")
        inputs, outputs = design, np.concatenate([outputs, new_outputs])
        res = sobol_indices(problem, outputs, second_order, confidence, resamples, seed,
                            interval)
        stable = sobol_stable(res, threshold, half_width)
        history.append(res)
        stable_at.append(stable)
        if stable or n >= n_max:
            break
        n *= 2
    hist = xr.concat(history, dim="N", combine_attrs="drop_conflicts")
    hist = hist.assign_coords(N=[r.attrs["N"] for r in history])
    hist["stable"] = ("N", np.array(stable_at))
    hist.attrs.update(threshold=float(threshold), half_width=float(half_width))
    res = res.assign_attrs(stable=int(stable), threshold=float(threshold),
                           half_width=float(half_width))
    return GrowthResult(res, hist, inputs, outputs)


# --------------------------------------------------------------------------- outputs


@dataclass(frozen=True)
class PreparedOutput:
    """An output ready for :func:`sobol_indices`, with what the policy did to it.

    Attributes
    ----------
    output : numpy.ndarray
        ln of the critical height in metres [ln m], rows of dropped blocks removed.
    kept_base_rows : numpy.ndarray of bool or None
        Which base rows (blocks of the design) are kept; None when no problem was given (then
        nothing was dropped).
    policy : str or None
    h_max : float or None
        The cap [m] (``cap`` policies).
    censored_share : float
        Share of rows [1] whose value is a bound, not a critical height: censored above or
        below, or above `h_max` and capped (over all rows, before dropping).
    censored_above_share, censored_below_share : float
        The same split by side [1] (rows capped at `h_max` count as above).
    failed_share : float
        Share of rows [1] that failed.
    dropped_share : float
        Share of base rows [1] dropped (each with all its linked rows).
    """

    output: np.ndarray
    kept_base_rows: np.ndarray | None
    policy: str | None
    h_max: float | None
    censored_share: float
    censored_above_share: float
    censored_below_share: float
    failed_share: float
    dropped_share: float


def prepare_output(heights, status, *, policy: str | None = None, h_max: float | None = None,
                   problem: dict | None = None, second_order: bool = False) -> PreparedOutput:
    """Turn critical heights and their statuses into an analysable output, never silently.

    The analysed output is ln H [ln m]. Policies:

    * ``None``: every row must be ``ok``; any censored or failed row (or NaN) is an error.
    * ``"cap"``: (a) analyse ln min(H, h_max); a row censored above (its bound must be >=
      h_max) is then exactly ln h_max; a row censored below keeps its bound (the solver's h_min,
      an upper bound of H). Failed rows are an error. The censored share is reported: the
      indices then describe the capped output.
    * ``"drop"``: (b) drop every base row (its whole block A, B, AB_i, BA_i) that holds a failed
      row; censored rows are an error. The dropped share is reported.
    * ``"cap+drop"``: both.

    Parameters
    ----------
    heights : array_like
        Critical heights [m] in design order: the bound for censored rows, NaN for failed.
    status : array_like of str
        ``ok``, ``censored_above``, ``censored_below`` or ``failed`` per row.
    policy : {None, "cap", "drop", "cap+drop"}
    h_max : float, optional
        Cap [m] (> 0) for the ``cap`` policies.
    problem : dict, optional
        SALib problem, needed to find the blocks for the ``drop`` policies.
    second_order : bool
        Design with second order (blocks of 2 G + 2 rows).

    Returns
    -------
    PreparedOutput
    """
    h = np.asarray(heights, dtype=float).reshape(-1)
    st = np.asarray(status).astype(str).reshape(-1)
    if st.shape != h.shape:
        raise ValueError(f"status has {st.size} values: expected one per height ({h.size})")
    known = ("ok", "censored_above", "censored_below", "failed")
    unknown = sorted(set(np.unique(st)) - set(known))
    if unknown:
        raise ValueError(f"status = {unknown[0]!r}: expected one of {known}")
    if policy not in (None, *POLICIES):
        raise ValueError(f"policy = {policy!r}: expected None or one of {POLICIES}")
    failed = st == "failed"
    above, below = st == "censored_above", st == "censored_below"
    bad_height = ~failed & ~(np.isfinite(h) & (h > 0))
    if np.any(bad_height):
        i = np.flatnonzero(bad_height)[0]
        raise ValueError(f"heights[{i}] = {float(h[i])!r} with status {str(st[i])!r}: expected "
                         "a finite height > 0 (NaN is only for failed rows)")
    capping = policy in ("cap", "cap+drop")
    dropping = policy in ("drop", "cap+drop")
    if np.any(failed) and not dropping:
        raise ValueError(f"heights: {int(failed.sum())} failed rows (NaN) with policy = "
                         f"{policy!r}: choose 'drop' or 'cap+drop' to drop their blocks")
    if np.any(above | below) and not capping:
        raise ValueError(f"heights: {int((above | below).sum())} censored rows with policy = "
                         f"{policy!r}: choose 'cap' or 'cap+drop' and an h_max")
    if capping:
        if (h_max is None or isinstance(h_max, bool) or not isinstance(h_max, numbers.Real)
                or not 0 < h_max < np.inf):
            raise ValueError(f"h_max = {h_max!r}: expected a finite height > 0 [m] for "
                             f"policy {policy!r}")
        h_max = float(h_max)
        # ln min(H, h_max) of a row censored above is exactly ln h_max only if its bound is at
        # least h_max (then H > bound >= h_max); a lower bound would leave it unknown.
        short = above & (h < h_max)
        if np.any(short):
            i = np.flatnonzero(short)[0]
            raise ValueError(f"h_max = {h_max!r}: above the bound {float(h[i])!r} [m] of the "
                             f"censored row {i}, so min(H, h_max) is unknown there; use h_max <= "
                             f"{float(h[short].min())!r}")
        capped = ~failed & (h > h_max)
        above = above | capped
        h = np.where(failed, h, np.minimum(h, h_max))
    else:
        h_max = None

    n_rows = h.size
    if dropping:
        if problem is None:
            raise ValueError(f"problem = None: policy {policy!r} needs the problem to find the "
                             "blocks of base rows")
        k = rows_per_base_row(problem, second_order)
        if n_rows % k:
            raise ValueError(f"heights has {n_rows} values: expected N * {k} for the design")
        kept = ~failed.reshape(-1, k).any(axis=1)
        output = np.log(h.reshape(-1, k)[kept].reshape(-1))
    else:
        kept = None
        if problem is not None:
            k = rows_per_base_row(problem, second_order)
            if n_rows % k:
                raise ValueError(f"heights has {n_rows} values: expected N * {k} for the design")
            kept = np.ones(n_rows // k, dtype=bool)
        output = np.log(h)
    return PreparedOutput(
        output=output, kept_base_rows=kept, policy=policy, h_max=h_max,
        censored_share=float(np.mean(above | below)),
        censored_above_share=float(np.mean(above)), censored_below_share=float(np.mean(below)),
        failed_share=float(np.mean(failed)),
        dropped_share=0.0 if kept is None else float(1.0 - kept.mean()))


def event_indicator(heights, drop_height: float, status=None) -> np.ndarray:
    """1.0 where a drop from `drop_height` initiates (H_c <= drop_height), else 0.0.

    Sobol' indices of this output are indices of the event's probability at that height.

    Parameters
    ----------
    heights : array_like
        Critical heights H_c [m]; for censored rows the bound that was hit.
    drop_height : float
        Drop height [m], > 0.
    status : array_like of str, optional
        Row statuses. With them, a censored row whose bound leaves the event undecided
        (``censored_above`` with bound < drop height, ``censored_below`` with bound > drop
        height) is an error; failed rows must be removed first (:func:`prepare_output`).

    Returns
    -------
    numpy.ndarray of float
        0.0 or 1.0 per row.
    """
    h = np.asarray(heights, dtype=float).reshape(-1)
    if (isinstance(drop_height, bool) or not isinstance(drop_height, numbers.Real)
            or not 0 < drop_height < np.inf):
        raise ValueError(f"drop_height = {drop_height!r}: expected a finite height > 0 [m]")
    bad = np.flatnonzero(~np.isfinite(h))
    if bad.size:
        raise ValueError(f"heights[{bad[0]}] = {float(h[bad[0]])!r}: failed rows must be dropped "
                         "first (prepare_output with policy 'drop')")
    if status is not None:
        st = np.asarray(status).astype(str).reshape(-1)
        if st.shape != h.shape:
            raise ValueError(f"status has {st.size} values: expected one per height ({h.size})")
        undecided = (((st == "censored_above") & (h < drop_height))
                     | ((st == "censored_below") & (h > drop_height)) | (st == "failed"))
        if np.any(undecided):
            i = np.flatnonzero(undecided)[0]
            raise ValueError(f"heights[{i}] = {float(h[i])!r} ({st[i]}): the event at "
                             f"drop_height = {drop_height!r} is undecided for this row")
    return (h <= drop_height).astype(float)


# --------------------------------------------------------------------------- Morris


def morris_screening(problem: dict, X, Y, *, num_levels: int = 4, confidence: float = 0.95,
                     resamples: int = 1000, seed: int = 0, scaled: bool = False) -> xr.Dataset:
    """Morris elementary-effects screening (:func:`SALib.analyze.morris.analyze`).

    Parameters
    ----------
    problem : dict
        SALib problem (optional ``groups``: effects per group).
    X : array_like, shape (r (G + 1), num_vars)
        The :func:`SALib.sample.morris.sample` design, in the problem's bounds.
    Y : array_like, shape (r (G + 1),)
        Outputs of its rows.
    num_levels : int
        Grid levels, as used for the design.
    confidence : float
        Level of the bootstrap interval of ``mu_star``, in (0, 1).
    resamples : int
        Bootstrap resamples (>= 2).
    seed : int
        Seed of SALib's bootstrap (0 is a real seed there).
    scaled : bool
        Scale the effects by std(X) / std(Y) (Sin and Gernaey 2009).

    Returns
    -------
    xarray.Dataset
        Over ``parameter`` (or group names): ``mu``, ``mu_star``, ``mu_star_conf`` (half-width
        of the normal bootstrap interval of mu_star), ``sigma`` (NaN for groups of several
        parameters, as SALib). Elementary effects are in output units per unit of the scaled
        [0, 1] input range.
    """
    from SALib.analyze import morris

    names, index_names, _ = _check_problem(problem)
    confidence = _check_confidence(confidence)
    resamples = _check_resamples(resamples)
    seed = _check_seed(seed)
    x = np.asarray(X, dtype=float)
    y = np.asarray(Y, dtype=float).reshape(-1)
    if x.ndim != 2 or x.shape[1] != len(names):
        raise ValueError(f"X has shape {x.shape}: expected (rows, {len(names)})")
    if y.size != x.shape[0] or y.size % (len(index_names) + 1):
        raise ValueError(f"Y has {y.size} values: expected one per row of X ({x.shape[0]}), "
                         f"a multiple of {len(index_names) + 1}")
    if not np.all(np.isfinite(y)):
        i = np.flatnonzero(~np.isfinite(y))[0]
        raise ValueError(f"Y[{i}] = {float(y[i])!r}: outputs must be finite")
    # SALib's morris.analyze adds a 'groups' key to the problem it is given: pass a copy.
    si = morris.analyze(copy.deepcopy(problem), x, y, num_resamples=resamples,
                        conf_level=confidence, num_levels=num_levels, seed=seed, scaled=scaled)
    data = {key: ("parameter", np.asarray(si[key], dtype=float))
            for key in ("mu", "mu_star", "mu_star_conf", "sigma")}
    return xr.Dataset(data, coords={"parameter": index_names}, attrs={
        "method": "Morris 1991, mu* of Campolongo et al. 2007", "num_levels": int(num_levels),
        "confidence": confidence, "resamples": resamples, "seed": seed,
        "trajectories": y.size // (len(index_names) + 1), "scaled": int(bool(scaled))})


# --------------------------------------------------------------------------- figures


#: Short readable names of sampled keys for figures; the unit is added from the key's table
#: (:data:`skidmc.scene.keys.INPUT_KEYS`). Keys missing here fall back to the key itself.
_SHORT_NAMES = {
    "mu": "friction coefficient mu",
    "flow_stress": "billet flow stress sigma",
    "billet_mass": "billet mass W",
    "billet_diameter": "billet diameter D",
    "angle": "impact angle phi",
    "tilt": "billet tilt psi",
    "initial_temperature": "initial temperature T0",
    "he.density": "HE density",
    "he.heat_capacity": "HE heat capacity",
    "he.conductivity": "HE conductivity",
    "he.heat_of_fusion": "HE heat of fusion",
    "he.melting_point": "HE melting point",
    "kinetics.prefactor": "Arrhenius prefactor Z",
    "kinetics.activation_temperature": "activation temperature E/R",
    "kinetics.heat_of_reaction": "heat of reaction Q",
    "kinetics.rate_at_reference": "reaction rate at T_ref",
    "target.density": "target density",
    "target.heat_capacity": "target heat capacity",
    "target.conductivity": "target conductivity k",
}

#: Words for the bootstrap interval types of :func:`sobol_indices`.
_INTERVAL_WORDS = {"bca": "bootstrap BCa", "percentile": "bootstrap percentile"}


def input_label(key: str) -> str:
    """A figure label for a sampled input: short name and SI unit (``"target conductivity k
    [W/(m K)]"``); the key itself for an unknown key."""
    from skidmc.scene.keys import INPUT_KEYS

    units = {k.key: k.si_unit for k in INPUT_KEYS}
    units.setdefault("kinetics.rate_at_reference", "1/s")
    unit = units.get(key)
    name = _SHORT_NAMES.get(key, key)
    if unit is None:
        return name
    return f"{name} [{'-' if unit == '1' else unit}]"


def plot_indices(ax, res: xr.Dataset, indices: Sequence[str] = ("S1", "ST")):
    """Horizontal bars of the indices, ranked by total index (largest on top), with their
    asymmetric intervals; hatched where the interval contains 0.

    Inputs are named in words with their units (:func:`input_label`); the title states the
    interval (bootstrap BCa or percentile, its confidence) and N.

    Parameters
    ----------
    ax : matplotlib.axes.Axes
    res : xarray.Dataset
        A result of :func:`sobol_indices`.
    indices : sequence of {"S1", "ST"}

    Returns
    -------
    matplotlib.axes.Axes
    """
    rank_by = "ST" if "ST" in indices else indices[0]
    order = np.argsort(-np.nan_to_num(res[rank_by].values, nan=-np.inf))
    res = res.isel(parameter=order)
    names = [input_label(str(v)) for v in res["parameter"].values]
    y = np.arange(len(names))
    height = 0.8 / len(indices)
    words = {"S1": "first order S1", "ST": "total ST"}
    for i, index in enumerate(indices):
        est = res[index].values
        err = np.vstack([est - res[f"{index}_low"].values, res[f"{index}_high"].values - est])
        flagged = res[f"{index}_contains_zero"].values
        bars = ax.barh(y + (i - (len(indices) - 1) / 2) * height, est, height,
                       label=words.get(index, index), xerr=np.clip(err, 0.0, None), capsize=2,
                       color=f"C{i}")
        for bar, flag in zip(bars, flagged):
            if flag:
                bar.set_hatch("//")
                bar.set_alpha(0.5)
    ax.axvline(0.0, color="black", linewidth=0.8)
    ax.set_yticks(y)
    ax.set_yticklabels(names, fontsize=8)
    ax.invert_yaxis()  # rank 1 on top
    ax.set_xlabel("Sobol' index of ln H_c [-] (share of its variance)")
    interval = _INTERVAL_WORDS.get(str(res.attrs.get("interval", "")),
                                   str(res.attrs.get("interval", "")))
    ax.set_title(f"ranked by {words.get(rank_by, rank_by)}; N = {res.attrs.get('N', '?')}; "
                 f"bars: {interval} {100 * res.attrs.get('confidence', 0):g} % intervals\n"
                 "(hatched: interval contains 0)", fontsize="small")
    ax.legend(fontsize=8, loc="lower right")
    return ax


def plot_convergence(ax, conv: xr.Dataset, index: str = "ST", *, legend: bool = True):
    """One index against N with its interval band, one line per parameter.

    Every input gets its own colour and marker (up to 20 distinct colours: ``tab10`` and ten
    named ones; markers cycling), named in words with its unit (:func:`input_label`).

    Parameters
    ----------
    ax : matplotlib.axes.Axes
    conv : xarray.Dataset
        A result of :func:`sobol_convergence` (or the history of :func:`grow_until_stable`).
    index : {"S1", "ST"}
    legend : bool
        Draw the legend on `ax` (a figure with several panels may draw one for all).

    Returns
    -------
    matplotlib.axes.Axes
    """
    import matplotlib
    import matplotlib.ticker

    n = conv["N"].values
    # tab10, then ten more colours far from every tab10 one (its light tab20 partners would
    # read as the same input).
    palette = list(matplotlib.colormaps["tab10"].colors) + [
        "black", "darkgoldenrod", "teal", "navy", "lime", "maroon", "indigo", "salmon",
        "olive", "slategray"]
    markers = "os^vD<>pPX*h"
    for j, name in enumerate(conv["parameter"].values):
        sel = conv.sel(parameter=name)
        color = palette[j % len(palette)]
        ax.plot(n, sel[index].values, marker=markers[j % len(markers)], color=color,
                label=input_label(str(name)))
        ax.fill_between(n, sel[f"{index}_low"].values, sel[f"{index}_high"].values,
                        color=color, alpha=0.15)
    ax.set_xscale("log", base=2)
    ax.xaxis.set_major_formatter(matplotlib.ticker.FuncFormatter(lambda v, _: f"{v:g}"))
    ax.set_xlabel("base rows N")
    interval = _INTERVAL_WORDS.get(str(conv.attrs.get("interval", "")), "interval")
    ax.set_ylabel(f"{index} [-] (bands: {interval})")
    if legend:
        ax.legend(fontsize=7)
    return ax
