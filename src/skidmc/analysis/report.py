"""What a user runs a study for: go-probability curves, log-normal fits, the experiments' verdict.

Reads an ensemble (the Dataset of :func:`skidmc.analysis.open_ensemble`) and answers, per scene:

* P(go | H): the empirical distribution of the critical heights with a simultaneous band
  (:func:`~skidmc.analysis.gonogo.go_curve`); a sample censored "above" is a no-go at every height
  up to its bound;
* the censored log-normal fit of the critical heights: H50, the log standard deviation, H01, H10,
  H90 with profile-likelihood intervals, and its goodness-of-fit verdict
  (:func:`~skidmc.analysis.gonogo.fit_lognormal`);
* with aleatory and epistemic inputs (a nested design, dims ``epistemic`` x ``sample``): one
  P(go | H) curve per epistemic draw, their median and 5-95 % band, the H50 of each draw;
* against the report's drops (:mod:`~skidmc.analysis.experiments`): the probit fit of the drops
  (Fieller's interval, or the bracket the data support when the maximum does not exist), the
  Bayesian H50 of the drops under a vague and under the model's prior
  (:func:`~skidmc.analysis.posterior.posterior_h50_table`), the Dixon-Mood estimate, and scores
  of the prediction (log-likelihood, Brier and log scores) next to the base rate and a coin flip;
* for a ``saltelli`` design, first-order and total Sobol' indices of ln H_c with bootstrap
  intervals (:func:`~skidmc.analysis.sensitivity.sobol_indices`).

The analysis computes; :mod:`skidmc.workflows.reporting` writes what it found (the figures,
``summary.md``, ``summary.json`` and the curves, :func:`skidmc.workflows.reporting.ensemble.
write_report`). Heights in feet (the report's unit) and metres.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np
import xarray as xr

from skidmc.analysis import experiments as experiments_module
from skidmc.analysis.gonogo import (
    fit_lognormal,
    fit_probit,
    go_curve,
    score_drops,
    updown,
)
from skidmc.scene.units import FOOT as FT  # [m per ft]

__all__ = [
    "EPISTEMIC_BAND",
    "FT",
    "SceneAnalysis",
    "analyse_ensemble",
    "analyse_scene",
    "ensemble_sobol",
    "scene_names",
    "scene_outcomes",
]

#: Censoring marks of the fits, by the ensemble's ``status``.
_CENSORING = {"ok": "", "censored_above": "above", "censored_below": "below"}

#: Quantiles of the epistemic band [1].
EPISTEMIC_BAND = (0.05, 0.95)


def scene_names(ds: xr.Dataset) -> list[str]:
    return [str(s) for s in ds["scene"].values] if "scene" in ds.dims else [ds.attrs.get(
        "study_name", "scene")]


def _select(ds: xr.Dataset, scene: str) -> xr.Dataset:
    return ds.sel(scene=scene) if "scene" in ds.dims else ds


def scene_outcomes(ds: xr.Dataset, scene: str) -> dict:
    """Critical heights of one scene as the fits take them.

    Parameters
    ----------
    ds : xarray.Dataset
        An ensemble (:func:`skidmc.analysis.open_ensemble`).
    scene : str
        A scene name (ignored for a study without scenes).

    Returns
    -------
    dict
        ``heights_m`` [m] (finished, not failed samples, flattened over the sample dims, bounds
        for censored samples; of a ``saltelli`` design only the base rows), ``censored`` ("",
        "above", "below"), and the counts ``n``, ``n_failed``, ``n_unfinished``, ``n_above``,
        ``n_below``; ``flags``: flag -> written samples of the scene carrying it (all rows of
        the design; the solver's validity flags, ``rtol_unmet``, ``implausible_input``).
    """
    from skidmc.ensemble.storage import flag_counts

    sub = _select(ds, scene)
    height = np.asarray(sub["critical_height"].values, dtype=float).reshape(-1)
    status = np.asarray(sub["status"].values).astype(str).reshape(-1)
    if ds.attrs.get("design_method") == "saltelli":
        # Only the base rows (matrix A of Saltelli's design: a scrambled Sobol' sample of the
        # inputs) enter curves and fits; the other rows of a block share all but one input with
        # them, and would make the intervals look far tighter than the information they hold.
        step = _saltelli_block(ds)
        height, status = height[::step], status[::step]
    unfinished = status == ""
    failed = status == "failed"
    keep = ~unfinished & ~failed
    censored = np.array([_CENSORING[s] for s in status[keep]], dtype=object)
    return {
        "heights_m": height[keep],
        "censored": censored,
        "n": int(keep.sum()),
        "n_failed": int(failed.sum()),
        "n_unfinished": int(unfinished.sum()),
        "n_above": int((censored == "above").sum()),
        "n_below": int((censored == "below").sum()),
        "flags": flag_counts(sub["flags"].values) if "flags" in sub else {},
    }


@dataclass
class SceneAnalysis:
    """Everything the report says about one scene. Heights in feet unless named ``_m``.

    Attributes
    ----------
    scene : str
    counts : dict
        From :func:`scene_outcomes`.
    curve : xarray.Dataset
        Empirical P(go | H) on ``grid_ft`` with its simultaneous band (pooled over epistemic
        draws when there are any: labelled so in its attributes).
    fit : LognormalFit or None
        Censored log-normal fit (None with fewer than 3 exact heights).
    epistemic : xarray.Dataset or None
        With a nested design: ``p_go`` per epistemic draw on the grid, its median and
        :data:`EPISTEMIC_BAND`, and ``h50`` per draw [ft].
    experiment : Experiment or None
    experimental_fit, updown, scores
        Probit fit and Dixon-Mood estimate of the experiment's drops, and the prediction's scores
        against them (None where there are no drops).
    sobol : xarray.Dataset or None
        Sobol' indices of ln H_c (``saltelli`` designs).
    sobol_convergence : xarray.Dataset or None
        The same against N (200 bootstrap resamples per N).
    sobol_event : xarray.Dataset or None
        Sobol' indices of the event (go) at a drop from the fitted median critical height.
    """

    scene: str
    counts: dict
    curve: xr.Dataset
    fit: object | None
    epistemic: xr.Dataset | None = None
    experiment: object | None = None
    experimental_fit: object | None = None
    updown: object | None = None
    scores: object | None = None
    sobol: xr.Dataset | None = None
    sobol_convergence: xr.Dataset | None = None
    sobol_event: xr.Dataset | None = None
    notes: list = field(default_factory=list)

    def predicted_h50(self) -> tuple[float, float, float]:
        """(estimate, low, high) of the predicted H50 [ft].

        With epistemic draws: the median of the per-draw H50 and its :data:`EPISTEMIC_BAND`
        across draws (what is not known about the fixed inputs); otherwise the log-normal fit's
        H50 and its profile-likelihood interval (sampling error only)."""
        if self.epistemic is not None:
            h50 = self.epistemic["h50"].values
            low, high = (float(np.nanquantile(h50, q)) for q in EPISTEMIC_BAND)
            return (float(np.nanmedian(h50)), low, high)
        if self.fit is None:
            return (math.nan, math.nan, math.nan)
        return tuple(float(v) for v in self.fit.intervals["h50"])

    def experimental_h50(self) -> tuple[float, float, float]:
        """(estimate, low, high) of the experimental H50 [ft]: the probit fit of the drops (its
        bracket when the maximum does not exist), or the report's value alone."""
        exp = self.experiment
        if exp is None:
            return (math.nan, math.nan, math.nan)
        if exp.h50_qualifier == "lower_bound":
            return (math.nan, exp.h50, math.inf)
        fit = self.experimental_fit
        if fit is None:
            return (exp.h50, math.nan, math.nan)
        estimate, low, high = (float(v) for v in fit.quantile(0.5))
        # Without a maximum (go and no-go heights do not overlap) the likelihood-ratio bounds
        # still hold; the report's own value stands in for the estimate.
        return (estimate if fit.exists else exp.h50, low, high)


def _grid_ft(heights_ft: np.ndarray, extra=()) -> np.ndarray:
    """Heights [ft] at which curves are evaluated: 241 log-spaced points over the samples' span
    (a step function between sample heights reads the same on them at figure resolution) and
    the experiments' drop heights, so that the curves are known where the drops were made."""
    finite = heights_ft[np.isfinite(heights_ft) & (heights_ft > 0)]
    extra = np.asarray(extra, dtype=float)
    values = np.concatenate([finite, extra])
    lo, hi = values.min() / 1.5, values.max() * 1.5
    return np.unique(np.concatenate([np.geomspace(lo, hi, 241), extra]))


def _epistemic_family(sub: xr.Dataset, grid_ft: np.ndarray) -> xr.Dataset:
    """One P(go | H) per epistemic draw (ECDF over its aleatory samples), median and band."""
    n_draws = sub.sizes["epistemic"]
    curves = np.full((n_draws, grid_ft.size), np.nan)
    h50 = np.full(n_draws, np.nan)
    for e in range(n_draws):
        draw = sub.isel(epistemic=e)
        status = np.asarray(draw["status"].values).astype(str)
        height_ft = np.asarray(draw["critical_height"].values, dtype=float) / FT
        ok = (status != "") & (status != "failed")
        if not ok.any():
            continue
        h, st = height_ft[ok], status[ok]
        # A drop from H goes when H >= H_c: censored "below" goes everywhere on the grid above
        # its bound; censored "above" is a no-go up to its bound (beyond: not identified, NaN).
        went = (h[None, :] <= grid_ft[:, None]) & (st[None, :] != "censored_above")
        p = went.mean(axis=1)
        top = h[st == "censored_above"].min() if (st == "censored_above").any() else math.inf
        p[grid_ft > top] = np.nan
        curves[e] = p
        # H50 of the draw: the median critical height (NaN if censoring hides it).
        order = np.sort(np.where(st == "censored_above", np.inf, h))
        h50[e] = np.median(order) if np.isfinite(np.median(order)) else np.nan
    low, high = EPISTEMIC_BAND
    with np.errstate(all="ignore"):
        median = np.nanmedian(curves, axis=0)
        band = np.nanquantile(curves, [low, high], axis=0)
    return xr.Dataset(
        {
            "p_go": (("epistemic", "height_ft"), curves,
                     {"long_name": "P(go | H) of one epistemic draw", "units": "1"}),
            "p_go_median": ("height_ft", median, {"units": "1"}),
            "p_go_low": ("height_ft", band[0], {"units": "1",
                                                "long_name": f"{low:.0%} across draws"}),
            "p_go_high": ("height_ft", band[1], {"units": "1",
                                                 "long_name": f"{high:.0%} across draws"}),
            "h50": ("epistemic", h50, {"units": "ft",
                                       "long_name": "median critical height of the draw"}),
        },
        coords={"height_ft": grid_ft, "epistemic": np.arange(n_draws)},
    )


def analyse_scene(ds: xr.Dataset, scene: str, *, experiment: str | None = None,
                  confidence: float = 0.95, sobol: bool | None = None) -> SceneAnalysis:
    """Go curve, log-normal fit, epistemic family, experiment and Sobol' indices of one scene.

    Parameters
    ----------
    ds : xarray.Dataset
        An ensemble (:func:`skidmc.analysis.open_ensemble`).
    scene : str
        A scene of `ds`.
    experiment : str, optional
        A key of :data:`skidmc.analysis.experiments.EXPERIMENTS` to compare with.
    confidence : float
        Coverage of every interval and band [1].
    sobol : bool, optional
        Compute Sobol' indices; default: when the design is ``saltelli``.

    Returns
    -------
    SceneAnalysis
    """
    counts = scene_outcomes(ds, scene)
    heights_ft = counts["heights_m"] / FT
    censored = counts["censored"]
    exp = experiments_module.get_experiment(experiment) if experiment else None
    extra = [] if exp is None or exp.drops is None else exp.drops.heights
    if exp is not None and math.isfinite(exp.h50):
        extra = list(extra) + [exp.h50]
    grid = _grid_ft(heights_ft, extra)
    nested = "epistemic" in ds.dims
    curve = go_curve(heights_ft, censored, confidence=confidence, grid=grid, units="ft")
    curve.attrs["pooled"] = int(nested)
    if nested:
        curve.attrs["note"] = ("pooled over epistemic draws: mixes what is unknown (epistemic) "
                               "with what varies from drop to drop (aleatory)")
    n_exact = int((censored == "").sum())
    fit = (fit_lognormal(heights_ft, censored, confidence=confidence) if n_exact >= 3
           else None)
    analysis = SceneAnalysis(scene=scene, counts=counts, curve=curve, fit=fit, experiment=exp)
    if nested:
        analysis.epistemic = _epistemic_family(_select(ds, scene), grid)
    if exp is not None and exp.drops is not None and len(exp.drops):
        drops = exp.drops
        if drops.went.any() and not drops.went.all():
            analysis.experimental_fit = fit_probit(drops.heights, drops.went,
                                                   confidence=confidence)
            analysis.updown = updown(drops.heights, drops.went)
        if fit is not None:
            analysis.scores = score_drops(fit.probability, drops.heights, drops.went)
    design = ds.attrs.get("design_method", "")
    if (sobol if sobol is not None else design == "saltelli") and design == "saltelli":
        analysis.sobol = ensemble_sobol(ds, scene, confidence=confidence)
        analysis.sobol_convergence = ensemble_sobol(ds, scene, confidence=confidence,
                                                    resamples=200, convergence=True)
        # What decides a go at the median critical height, where the event varies most.
        if fit is not None:
            analysis.sobol_event = ensemble_sobol(ds, scene, confidence=confidence,
                                                  drop_height=fit.h50 * FT)
    return analysis


def _saltelli_block(ds: xr.Dataset) -> int:
    """Rows per base row of a saltelli design: d + 2, or 2 d + 2 with second order."""
    d = len(_design_keys(ds))
    return 2 * d + 2 if bool(ds.attrs.get("saltelli_second_order", 0)) else d + 2


def _design_keys(ds: xr.Dataset) -> list[str]:
    """The design columns, as :func:`skidmc.ensemble.storage.open_ensemble` decoded them (or
    the flat attribute of a Dataset built otherwise)."""
    if "design" in ds.attrs:
        return list(ds.attrs["design"]["keys"])
    return [str(k) for k in np.atleast_1d(ds.attrs.get("design_keys", []))]


def ensemble_sobol(ds: xr.Dataset, scene: str, *, confidence: float = 0.95,
                   resamples: int = 1000, seed: int = 0, policy: str = "cap+drop",
                   convergence: bool = False, drop_height: float | None = None) -> xr.Dataset:
    """Sobol' indices of ln H_c of one scene of a ``saltelli`` ensemble.

    The design columns are the study's uncertain keys (uniform on [0, 1), mapped to each scene's
    distributions: the indices are invariant under those monotone maps). A key that this scene
    does not vary (a column of the design that another scene samples: its stored input is one
    value on every row) has no effect on it, so its indices are 0 by construction; it is left out
    of the result and named in the ``not_varied`` attribute (comma-separated).

    Parameters
    ----------
    ds : xarray.Dataset
        A complete ``saltelli`` ensemble.
    scene : str
    confidence, resamples, seed
        Of the bootstrap intervals (:func:`~skidmc.analysis.sensitivity.sobol_indices`).
    policy : str
        Censored and failed samples (:func:`~skidmc.analysis.sensitivity.prepare_output`): by
        default ln min(H, h_max) for censored samples and the whole linked block of a failed
        sample dropped; the shares affected are in the result's attributes.
    drop_height : float, optional
        Analyse the event at this drop height [m] (1 where H_c <= drop_height:
        :func:`~skidmc.analysis.sensitivity.event_indicator`) instead of ln H_c: what decides
        whether a drop from that height goes.
    convergence : bool
        Return the indices against N instead (the first n base rows, n = 16, 32, ..., N:
        :func:`~skidmc.analysis.sensitivity.sobol_convergence`).

    Returns
    -------
    xarray.Dataset
        As :func:`~skidmc.analysis.sensitivity.sobol_indices`, with ``censored_share``,
        ``failed_share`` and ``dropped_share`` attributes.
    """
    from skidmc.analysis.sensitivity import prepare_output, sobol_indices

    if ds.attrs.get("design_method") != "saltelli":
        raise ValueError(f"design_method = {ds.attrs.get('design_method')!r}: Sobol' indices "
                         "need a 'saltelli' design")
    sub = _select(ds, scene)
    status = np.asarray(sub["status"].values).astype(str).reshape(-1)
    if (status == "").any():
        raise ValueError(f"scene {scene!r}: {(status == '').sum()} unfinished samples; Sobol' "
                         "indices need the whole design (finish the run with --resume)")
    keys = _design_keys(ds)
    second = bool(ds.attrs.get("saltelli_second_order", 0))
    problem = {"num_vars": len(keys), "names": keys, "bounds": [[0.0, 1.0]] * len(keys)}
    prepared = prepare_output(sub["critical_height"].values.reshape(-1), status, policy=policy,
                              h_max=float(ds.attrs["solver_h_max"]), problem=problem,
                              second_order=second)
    output_name = "ln critical_height [ln m]"
    if drop_height is not None:
        from skidmc.analysis.sensitivity import event_indicator

        # prepare_output's output is ln min(H, h_max) of the kept rows: the event needs H itself.
        prepared = dataclasses.replace(
            prepared, output=event_indicator(np.exp(prepared.output), drop_height))
        output_name = f"event at a drop from {drop_height:.4g} m (1 where H_c <= H)"
    held = [k for k in keys if k in sub.data_vars
            and np.unique(np.asarray(sub[k].values).reshape(-1)).size == 1]
    if convergence:
        from skidmc.analysis.sensitivity import sobol_convergence

        conv = sobol_convergence(problem, prepared.output, second_order=second,
                                 confidence=confidence, resamples=resamples, seed=seed)
        return _without(conv, held)
    res = sobol_indices(problem, prepared.output, second_order=second, confidence=confidence,
                        resamples=resamples, seed=seed)
    res.attrs.update(output=output_name, policy=str(policy),
                     censored_share=prepared.censored_share,
                     failed_share=prepared.failed_share, dropped_share=prepared.dropped_share)
    return _without(res, held)


def _without(res: xr.Dataset, held: list[str]) -> xr.Dataset:
    """Indices without the inputs in `held` (not varied in this scene), named in
    ``not_varied``."""
    if held:
        res = res.drop_sel(parameter=held)
        if "parameter_2" in res.dims:
            res = res.drop_sel(parameter_2=held)
    res.attrs["not_varied"] = ", ".join(held)
    return res


def analyse_ensemble(ds: xr.Dataset, *, experiments: Mapping[str, str] | None = None,
                     confidence: float = 0.95) -> list[SceneAnalysis]:
    """:func:`analyse_scene` for every scene of an ensemble.

    Parameters
    ----------
    ds : xarray.Dataset
    experiments : mapping of str to str, optional
        Scene name -> experiment name; default: the study's ``experiment`` keys (from
        ``attrs["study"]``, as :func:`~skidmc.analysis.open_ensemble` decodes it), if any.
    confidence : float

    Returns
    -------
    list of SceneAnalysis
    """
    if experiments is None:
        experiments = _study_experiments(ds)
    return [analyse_scene(ds, s, experiment=experiments.get(s), confidence=confidence)
            for s in scene_names(ds)]


def _study_experiments(ds: xr.Dataset) -> dict[str, str]:
    """Scene -> experiment from the study that :func:`~skidmc.analysis.open_ensemble` decoded
    (``attrs["study"]``); none for a Dataset without it."""
    doc = ds.attrs.get("study") or {}
    return {sc["name"]: sc["experiment"] for sc in doc.get("scenes", [])
            if "experiment" in sc and "name" in sc}
