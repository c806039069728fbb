"""The report of an ensemble (kinds ``ensemble`` and ``sobol``): what ``skidmc report`` writes.

:func:`write_report` analyses an ensemble (:func:`skidmc.analysis.report.analyse_ensemble`) and
writes into a folder: one figure per scene of P(go | H) with its band, the log-normal fit and
the report's drops; the predicted against the experimental 50 % heights; the log-normal Q-Q;
reliability diagrams at the drops; Sobol' indices; ``summary.md`` (every interval labelled with
the level it was computed at), ``summary.json`` (the one encoding,
:func:`skidmc.workflows.reporting.dumps`) and the curves (``curves.h5``, ``sobol.h5``).
Heights in feet (the report's unit) and metres.
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping
from pathlib import Path

import numpy as np
import xarray as xr

from skidmc.analysis import experiments as experiments_module
from skidmc.analysis.gonogo import plot_qq
from skidmc.analysis.report import (
    EPISTEMIC_BAND,
    SceneAnalysis,
    analyse_ensemble,
)
from skidmc.analysis.skill import MIN_DROPS_RELIABILITY, plot_reliability, reliability, skill_scores
from skidmc.workflows.reporting import band, level, pyplot, save, write_json

__all__ = ["write_report"]


def _fmt(x: float, digits: int = 3) -> str:
    if x is None or (isinstance(x, float) and math.isnan(x)):
        return "-"
    if math.isinf(x):
        return "inf" if x > 0 else "-inf"
    return f"{x:.{digits}g}"


def _triple(t) -> str:
    est, low, high = t
    return f"{_fmt(est)} [{_fmt(low)}, {_fmt(high)}]"


def _summary_dict(a: SceneAnalysis) -> dict:
    out = {"scene": a.scene, "counts": {k: v for k, v in a.counts.items()
                                        if k not in ("heights_m", "censored")}}
    if a.fit is not None:
        out["lognormal"] = {
            "units": "ft",
            "h50": list(a.fit.intervals["h50"]), "h01": list(a.fit.intervals["h01"]),
            "h10": list(a.fit.intervals["h10"]), "h90": list(a.fit.intervals["h90"]),
            "sigma_ln": list(a.fit.intervals["sigma"]),
            "ppcc": a.fit.ppcc, "p_value": a.fit.p_value, "verdict": a.fit.verdict,
        }
    if a.epistemic is not None:
        h50 = a.epistemic["h50"].values
        out["epistemic"] = {
            "draws": int(h50.size),
            "h50_ft_median": float(np.nanmedian(h50)),
            "h50_ft_band": [float(np.nanquantile(h50, q)) for q in EPISTEMIC_BAND],
        }
    if a.experiment is not None:
        exp = {"name": a.experiment.name, "description": a.experiment.description,
               "report_h50_ft": a.experiment.h50, "qualifier": a.experiment.h50_qualifier,
               "experimental_h50_ft": list(a.experimental_h50()),
               "predicted_h50_ft": list(a.predicted_h50()), "source": a.experiment.source}
        if a.experimental_fit is not None:
            fit = a.experimental_fit
            exp["probit"] = {"exists": bool(fit.exists), "reason": fit.reason,
                             "h50_ft": fit.h50 if fit.exists else None,
                             "sigma_ln": fit.sigma if fit.exists else None}
        if a.updown is not None:
            exp["updown"] = {"h50_ft": a.updown.h50, "sigma_ln": a.updown.sigma,
                             "valid": bool(a.updown.valid), "reasons": list(a.updown.reasons)}
        if a.scores is not None:
            s = a.scores
            exp["scores"] = {"n": s.n, "log_likelihood": s.log_likelihood,
                             "log_score": s.log_score, "brier": s.brier,
                             "brier_base_rate": s.brier_base_rate,
                             "p_outcome": [float(p) for p in s.p_outcome]}
        out["experiment"] = exp
    if a.sobol is not None:
        out["sobol"] = {
            name: {k: float(a.sobol[k].sel(parameter=name))
                   for k in ("S1", "S1_low", "S1_high", "ST", "ST_low", "ST_high")}
            for name in map(str, a.sobol["parameter"].values)}
        out["sobol_attrs"] = {k: (v if isinstance(v, (int, float, str)) else str(v))
                              for k, v in a.sobol.attrs.items()}
    return out


def _sobol_rows(res: xr.Dataset) -> list[str]:
    rows = []
    for rank, i in enumerate(np.argsort(-res["ST"].values), 1):
        r = res.isel(parameter=i)
        flag = " (interval contains 0)" if bool(r["ST_contains_zero"]) else ""
        rows.append(f"| {rank} | {str(r['parameter'].values)} | "
                    f"{_triple((float(r.S1), float(r.S1_low), float(r.S1_high)))} | "
                    f"{_triple((float(r.ST), float(r.ST_low), float(r.ST_high)))}{flag} |")
    return rows


def _inside_band(a: SceneAnalysis) -> str:
    """Whether the report's experimental 50 % height lies in the predicted H50 band (a finding,
    stated in words; for a lower bound: whether the band reaches above it)."""
    exp = a.experiment
    _, low, high = a.predicted_h50()
    if exp is None or not (math.isfinite(low) and math.isfinite(high)) or not math.isfinite(
            exp.h50):
        return "-"
    if exp.h50_qualifier == "lower_bound":
        return (f"consistent (band reaches above {exp.h50:g})" if high > exp.h50
                else f"no (whole band below {exp.h50:g})")
    if low <= exp.h50 <= high:
        return "yes"
    return "no (below the band)" if exp.h50 < low else "no (above the band)"


def _skill(a: SceneAnalysis):
    """Scores of the fitted P(go | H) at the target's drops, with references (or None)."""
    if a.scores is None or a.experiment is None or a.experiment.drops is None:
        return None
    return skill_scores(a.scores.p_go, a.experiment.drops.went)


def _credible(row: xr.Dataset) -> str:
    return f"{_fmt(float(row.h50))} [{_fmt(float(row.h50_low))}, {_fmt(float(row.h50_high))}]"


def _posterior_lines(analyses: list[SceneAnalysis], confidence: float) -> list[str]:
    """Bayesian H50 of each target with drops (:func:`.posterior.posterior_h50_table`): from
    the drops alone (a vague prior) and from the model's prior predictive updated by the
    drops; it exists where the probit maximum does not (issue 40 A)."""
    from skidmc.analysis import posterior

    names = [a.experiment.name for a in analyses
             if a.experiment is not None and a.experiment.name in posterior._DROP_TARGETS]
    if not names:
        return []
    tables = {prior: posterior.posterior_h50_table(prior, credibility=confidence).sel(target=names)
              for prior in ("vague", "physics")}
    level = f"{confidence * 100:g} %"
    lines = ["", f"## Bayesian H50 from the drops (median and {level} equal-tailed credible "
             "interval)", "",
             "Probit on ln H with normal priors on ln H50 and ln sigma, integrated on a grid "
             "(docs/planning.md). Vague prior: wide, centred on the geometric mean of the drop "
             "heights (it depends on the data). Physics prior: the model's own epistemic spread of "
             "H50 for this target (`src/skidmc/data/priors/`, from the shipped paper-series1 "
             "ensemble), without a model-discrepancy term.", "",
             "| scene | drops (go) | experimental H50 [ft] | vague prior: H50 [ft] | "
             "physics prior: prior H50 [ft] | physics prior: H50 [ft] |",
             "|---|---|---|---|---|---|"]
    by_name = {a.experiment.name: a for a in analyses if a.experiment is not None}
    for name in names:
        v, p = (tables[k].sel(target=name) for k in ("vague", "physics"))
        exp = by_name[name].experiment
        lines.append(f"| {by_name[name].scene} | {int(v.n)} ({int(v.n_go)}) | "
                     f"{'> ' if exp.h50_qualifier == 'lower_bound' else ''}{_fmt(exp.h50)} | "
                     f"{_credible(v)} | {_fmt(float(p.prior_h50))} | {_credible(p)} |")
    lines += ["", "Priors, per target:", ""]
    for name in names:
        for k in ("vague", "physics"):
            prior = str(tables[k].sel(target=name).prior.values)
            lines.append(f"- {by_name[name].scene}, {k}: {prior}")
    return lines


def _skill_lines(analyses: list[SceneAnalysis]) -> list[str]:
    """The skill table: per target with drops, each score next to the base rate and a coin."""
    rows = [(a, _skill(a)) for a in analyses]
    rows = [(a, k) for a, k in rows if k is not None]
    if not rows:
        return []
    lines = ["", "## Skill of the predicted go curve at the drops", "",
             "Lower is better. Base rate: always predicting the observed go fraction (it knows "
             "the outcomes: an optimistic reference); coin: always 1/2. \"no skill\" where the "
             "prediction is not better than both. +/- is the standard error over drops.", "",
             "| scene | drops (goes) | log score [nats/drop] | base rate | coin | verdict | "
             "Brier | base rate | coin | verdict |",
             "|---|---|---|---|---|---|---|---|---|---|"]
    for a, k in rows:
        lines.append(
            f"| {a.scene} | {k.n} ({k.n_go}) | {_fmt(k.log_score)} +/- {_fmt(k.log_score_se, 2)} "
            f"| {_fmt(k.log_score_base_rate)} | {_fmt(k.log_score_coin)} | {k.verdict('log')} | "
            f"{_fmt(k.brier)} +/- {_fmt(k.brier_se, 2)} | {_fmt(k.brier_base_rate)} | "
            f"{_fmt(k.brier_coin)} | {k.verdict('brier')} |")
    lines += ["", "Scores use the ensemble's fitted log-normal P(go | H) at each drop height. "
              f"Targets with {MIN_DROPS_RELIABILITY} or more drops get a reliability diagram "
              "(`reliability_<scene>.png`)."]
    return lines


def _assumption_lines(ds: xr.Dataset) -> list[str]:
    """The presets' stated assumptions (inputs the report does not give, values inferred by
    fitting), disclosed in every summary of a study that uses them."""
    from skidmc.scene.presets import PRESETS

    doc = ds.attrs.get("study") or {}
    presets = []
    for sc in doc.get("scenes", []) + ([doc["scene"]] if isinstance(doc.get("scene"), dict)
                                       else []):
        name = sc.get("preset")
        if name in PRESETS and name not in presets:
            presets.append(name)
    lines = []
    for name in presets:
        notes = PRESETS[name].get("notes", "")
        if "ASSUMPTION" not in notes:
            continue
        lines.append(f"- Preset `{name}`: {notes[notes.index('ASSUMPTION'):]}")
    out = []
    if lines:
        sampled = (doc.get("uncertain") or {}).get("billet_mass", {})
        if sampled.get("kind") == "epistemic":
            lines.append(f"- This study samples the billet mass as an epistemic input: "
                         f"{sampled.get('source', '')}.")
        out += ["## Assumptions of the presets (not in the report)", ""] + lines + [""]
    own = (doc.get("study") or {}).get("assumptions") or []
    if own:
        out += ["## Assumptions of the study", "",
                "Judgements no input's source states (the study file's `assumptions`); each "
                "input's own source is stored with the results.", ""]
        out += [f"- {a.strip()}" for a in own] + [""]
    return out


def _stability_lines(ds: xr.Dataset, growth: Mapping | None) -> list[str]:
    """What the growth's stopping rule said at the ensemble's N (``convergence.json`` of
    :func:`skidmc.workflows.sobol.run_until_stable`), or nothing when the record is absent or
    of another N."""
    try:
        last = growth["steps"][-1]
        if int(last["n"]) != int(ds.attrs.get("design_n", -1)):
            return []
        threshold, half = float(growth["threshold"]), float(growth["half_width"])
        met = [s for s, ok in last["stable"].items() if ok]
        unmet = [s for s, ok in last["stable"].items() if not ok]
        widest = last["max_half_width"]
    except (TypeError, KeyError, IndexError, ValueError):
        return []
    rule = (f"Stopping rule of the growth (`convergence.json`): every index whose interval "
            f"reaches above {threshold:g} has a half-width of at most {half:g}. At N = "
            f"{last['n']} (n_max {growth.get('n_max')}): ")
    if not unmet:
        return [rule + "met for every scene.", ""]
    said = "; ".join(f"{s} (widest half-width {widest[s]:.3f})" for s in unmet)
    return [rule + (f"met for {', '.join(met)}; " if met else "") + f"**not met** for {said}: "
            "n_max was reached, and these scenes' intervals are wider than the rule asks.", ""]


def _markdown(ds: xr.Dataset, analyses: list[SceneAnalysis], source: str,
              confidence: float = 0.95, growth: Mapping | None = None) -> str:
    lines = [f"# {ds.attrs.get('study_name', 'ensemble')}: go-probability report", "",
             f"Generated by `skidmc report {source}` from `{source}` "
             f"(design {ds.attrs.get('design_method')}, n = {ds.attrs.get('design_n')}, "
             f"seed {ds.attrs.get('seed')}, solver rtol {ds.attrs.get('solver_rtol')}, tier "
             f"{ds.attrs.get('solver_tier')}). Heights in ft (1 ft = 0.3048 m). Intervals: "
             f"{confidence * 100:g} % (profile likelihood for the model's log-normal fits, "
             "Fieller for the drops' probit fits); the go curves' bands are simultaneous (DKW).",
             ""]
    lines += _assumption_lines(ds)
    if "epistemic" in ds.dims:
        lines += ["The design nests aleatory (drop to drop) inside epistemic (fixed but unknown) "
                  "inputs: the pooled fit below mixes both; the epistemic band is the spread of "
                  "the per-draw curves.", ""]
    lines += ["## Predicted critical heights (censored log-normal fit)", "",
              "| scene | n | censored above/below | failed | H50 [ft] | sigma ln H | H01 | H10 | "
              "H90 | log-normal? |", "|---|---|---|---|---|---|---|---|---|---|"]
    for a in analyses:
        c = a.counts
        if a.fit is None:
            lines.append(f"| {a.scene} | {c['n']} | {c['n_above']}/{c['n_below']} | "
                         f"{c['n_failed']} | - | - | - | - | - | too few exact heights |")
            continue
        iv = a.fit.intervals
        lines.append(
            f"| {a.scene} | {c['n']} | {c['n_above']}/{c['n_below']} | {c['n_failed']} | "
            f"{_triple(iv['h50'])} | {_triple(iv['sigma'])} | {_triple(iv['h01'])} | "
            f"{_triple(iv['h10'])} | {_triple(iv['h90'])} | {a.fit.verdict} "
            f"(PPCC p = {_fmt(a.fit.p_value, 2)}) |")
    flagged = [a for a in analyses if a.counts.get("flags")]
    if flagged:  # issue 44: never silently unmet rtol or implausible inputs
        lines += ["", "Flagged samples (written samples carrying each flag; `rtol_unmet`: the "
                  "requested rtol was not reached, `implausible_input`: an input outside its "
                  "plausible range): " + "; ".join(
                      f"{a.scene}: " + ", ".join(f"{k} {v}" for k, v in a.counts["flags"].items())
                      for a in flagged)]
    nested = [a for a in analyses if a.epistemic is not None]
    if nested:
        lines += ["", "## Epistemic spread", "",
                  f"| scene | draws | median of per-draw H50 [ft] | {band(EPISTEMIC_BAND)} of "
                  "per-draw H50 [ft] |",
                  "|---|---|---|---|"]
        for a in nested:
            h50 = a.epistemic["h50"].values
            lo, hi = (np.nanquantile(h50, q) for q in EPISTEMIC_BAND)
            lines.append(f"| {a.scene} | {h50.size} | {_fmt(np.nanmedian(h50))} | "
                         f"{_fmt(lo)} - {_fmt(hi)} |")
    with_exp = [a for a in analyses if a.experiment is not None]
    if with_exp:
        lines += ["", "## Against the experiments", "",
                  "| scene | experiment | predicted H50 [ft] | experimental H50 [ft] | report | "
                  "report's calculation [ft] | experiment in the predicted band? | "
                  "drops | log-likelihood | Brier | log score |",
                  "|---|---|---|---|---|---|---|---|---|---|---|"]
        for a in with_exp:
            s = a.scores
            exp = a.experiment
            report = (f"> {_fmt(exp.h50)}" if exp.h50_qualifier == "lower_bound"
                      else f"{'~' if exp.h50_qualifier == 'approximate' else ''}{_fmt(exp.h50)}")
            lines.append(
                f"| {a.scene} | {exp.name} | {_triple(a.predicted_h50())} | "
                f"{_triple(a.experimental_h50())} | {report} | "
                f"{_fmt(experiments_module.report_calculated_height(exp.name))} | "
                f"{_inside_band(a)} | "
                f"{0 if exp.drops is None else len(exp.drops)} | "
                f"{_fmt(s.log_likelihood) if s else '-'} | {_fmt(s.brier) if s else '-'} | "
                f"{_fmt(s.log_score) if s else '-'} |")
        predicted = ("the median of the per-epistemic-draw H50 with its "
                     f"{band(EPISTEMIC_BAND)} band across epistemic draws (what is not known "
                     "about kinetics and properties), not the pooled fit's far narrower sampling "
                     "interval." if "epistemic" in ds.dims
                     else f"the log-normal fit with its {level(confidence)} profile-likelihood "
                     "interval (sampling error of the ensemble only).")
        lines += ["", "Predicted H50: " + predicted,
                  "", "Experimental intervals: probit maximum likelihood on ln H of the drops "
                  f"with Fieller's {level(confidence)} interval (measured coverage of a 95 % "
                  "interval on simulated up-down series: 0.952 at 20 drops, 0.945 at 30, 0.932 at "
                  "40; results/validation/gonogo_coverage.md); where the go and no-go heights do "
                  "not overlap the maximum does not exist: the likelihood-ratio bounds are given "
                  "around the report's value, and the Bayesian H50 below. Scores use the fitted "
                  "log-normal P(go | H) of the ensemble."]
        for a in with_exp:
            if a.updown is not None:
                lines.append(f"- {a.scene}: Dixon-Mood H50 {_fmt(a.updown.h50)} ft, "
                             f"{'valid' if a.updown.valid else 'not valid: '}"
                             f"{'; '.join(a.updown.reasons)}")
            if a.experimental_fit is not None and not a.experimental_fit.exists:
                lines.append(f"- {a.scene}: probit MLE does not exist: "
                             f"{a.experimental_fit.reason}")
        lines += _posterior_lines(with_exp, confidence)
        lines += _skill_lines(with_exp)
    with_sobol = [a for a in analyses if a.sobol is not None]
    if with_sobol:
        lines += ["", "## Sobol' indices of ln H_c", ""]
        lines += _stability_lines(ds, growth)
        for a in with_sobol:
            res = a.sobol
            lines += [f"### {a.scene}", "",
                      f"N = {res.attrs.get('N')}, interval {res.attrs.get('interval')}, censored "
                      f"share {_fmt(res.attrs.get('censored_share'), 2)}, dropped share "
                      f"{_fmt(res.attrs.get('dropped_share'), 2)}", "",
                      "| rank | input | S1 | ST |", "|---|---|---|---|"]
            lines += _sobol_rows(res)
            if res.attrs.get("not_varied"):
                lines += ["", f"Not varied in this scene (held at its value; indices 0 by "
                          f"construction, left out): {res.attrs['not_varied']}."]
            if a.sobol_event is not None:
                lines += ["", f"What decides a go at H = {a.fit.h50:.3g} ft (the median critical "
                          "height): indices of the event indicator.", "",
                          "| rank | input | S1 | ST |", "|---|---|---|---|"]
                lines += _sobol_rows(a.sobol_event)
            lines.append("")
    lines += ["", "Figures: `go_<scene>.png` (P(go | H) with its band, the log-normal fit and the "
              "drops), `h50.png` (predicted against experimental 50 % heights), `qq.png` "
              "(log-normal Q-Q)" + (", `reliability_<scene>.png` (calibration at the drops)"
                                    if any(_skill(a) is not None
                                           and _skill(a).n >= MIN_DROPS_RELIABILITY
                                           for a in analyses) else "")
              + (", `h50_vs_mu.png` (second series: H50 against friction, the report's "
                 "Fig. 6 with bands)"
                 if sum(a.experiment is not None and a.fit is not None
                        and a.experiment.name.startswith("series2_") for a in analyses) >= 2
                 else "")
              + (", `sobol_<scene>.png`" if with_sobol else "") + ". Numbers: "
              "`summary.json`; curves: `curves.h5`."]
    return "\n".join(lines) + "\n"


#: Words for the report's experimental 50 % heights, by qualifier (legends).
_QUALIFIER_WORDS = {
    "updown": "report's experimental 50 % height (up-and-down method, Table II)",
    "approximate": "report's estimated 50 % height (~, too few drops for up-and-down; Table II)",
    "": "report's experimental 50 % height (Table IX)",
}


def _log_ticks(axis) -> None:
    """Plain-number tick labels on a log axis (1, 2, 5 per decade when the span is under two
    decades, else one per decade), no minor labels: no overlapping '2x10^-1'-style labels."""
    from matplotlib.ticker import FuncFormatter, LogLocator, NullFormatter

    lo, hi = axis.get_view_interval()
    few = hi / max(lo, 1e-300) < 100.0
    axis.set_major_locator(LogLocator(base=10.0, subs=(1.0, 2.0, 5.0) if few else (1.0,)))
    axis.set_major_formatter(FuncFormatter(lambda v, _: f"{v:g}"))
    axis.set_minor_formatter(NullFormatter())


def _draw_drops(ax, drops) -> None:
    """The drops at each height: go (filled, at P = 1) and no-go (open, at P = 0) markers with
    their counts written beside them, and the observed go fraction k/n at that height."""
    heights = np.asarray(drops.heights, dtype=float)
    went = np.asarray(drops.went, dtype=bool)
    first = {"go": True, "no": True, "frac": True}
    for j, h in enumerate(np.unique(heights)):
        at = heights == h
        # Neighbouring heights' labels on four rows: the report's alumina 20-35 drops sit at
        # five heights within a factor of two, closer on a log axis than a label is wide.
        stagger = 10 * (j % 4)
        k, n = int(went[at].sum()), int(at.sum())
        if k:
            ax.plot([h], [1.0], "o", color="k", ms=6, zorder=5,
                    label="go drops (count beside)" if first["go"] else None)
            ax.annotate(f"{k} go", (h, 1.0), textcoords="offset points", xytext=(5, -11 - stagger),
                        fontsize=8)
            first["go"] = False
        if n - k:
            ax.plot([h], [0.0], "o", mfc="white", color="k", ms=6, zorder=5,
                    label="no-go drops (count beside)" if first["no"] else None)
            ax.annotate(f"{n - k} no-go", (h, 0.0), textcoords="offset points",
                        xytext=(5, 4 + stagger), fontsize=8)
            first["no"] = False
        if 0 < k < n:  # at 0 or 1 it would hide the markers above
            ax.plot([h], [k / n], "D", color="C2", ms=5, zorder=5,
                    label="observed go fraction at that height" if first["frac"] else None)
            first["frac"] = False


def _report_lines(ax, a: SceneAnalysis) -> None:
    """The report's experimental 50 % height (an arrow for an open bound) and its own
    calculated height (Tables VIII, IX) as vertical lines."""
    exp = a.experiment
    if exp is None:
        return
    if math.isfinite(exp.h50):
        if exp.h50_qualifier == "lower_bound":
            ax.axvline(exp.h50, color="k", ls=":", lw=1,
                       label=f"report: no event up to {exp.h50:g} ft (Table II: > {exp.h50:g})")
            ax.annotate("", xy=(exp.h50 * 2.5, 0.5), xytext=(exp.h50, 0.5),
                        arrowprops={"arrowstyle": "->", "color": "k"})
        else:
            ax.axvline(exp.h50, color="k", ls=":", lw=1,
                       label=_QUALIFIER_WORDS.get(exp.h50_qualifier, "report's 50 % height"))
    calc = experiments_module.report_calculated_height(exp.name)
    if math.isfinite(calc):
        table = "Table IX" if exp.name.startswith("series2_") else "Table VIII"
        ax.axvline(calc, color="0.35", ls="-.", lw=1,
                   label=f"report's calculated critical height ({table})")


def _go_figure(plt, out: Path, a: SceneAnalysis) -> Path:
    fig, ax = plt.subplots(figsize=(9.2, 4.4))
    nested = a.epistemic is not None
    if nested:
        fam = a.epistemic
        h = fam["height_ft"].values
        for e in range(fam.sizes["epistemic"]):
            ax.plot(h, fam["p_go"].isel(epistemic=e).values, color="0.75", lw=0.5,
                    label="one draw of the fixed-but-unknown inputs" if e == 0 else None)
        ax.fill_between(h, fam["p_go_low"].values, fam["p_go_high"].values, color="C1",
                        alpha=0.25, label=f"{band(EPISTEMIC_BAND)} across those draws")
        ax.plot(h, fam["p_go_median"].values, color="C1", lw=2, label="median across draws")
    c = a.curve
    conf = c.attrs.get("confidence", 0.95)
    hc = c["height"].values
    ax.step(hc, c["p_go"].values, where="post", color="C0",
            label="all draws pooled" if nested else "ensemble (empirical)")
    ax.fill_between(hc, c["p_go_low"].values, c["p_go_high"].values, step="post", color="C0",
                    alpha=0.25, label=f"{level(conf)} band of the {'pooled' if nested else ''} "
                    "curve (finite ensemble)".replace("  ", " "))
    if a.fit is not None:
        ax.plot(hc, a.fit.probability(hc), "--", color="C3",
                label="log-normal fit to the " + ("pooled heights" if nested else "heights"))
    if a.experiment is not None and a.experiment.drops is not None:
        _draw_drops(ax, a.experiment.drops)
    _report_lines(ax, a)
    ax.set_xscale("log")
    ax.set_xlabel("drop height H [ft]")
    ax.set_ylabel("probability of a reaction, P(go | H) [-]")
    ax.set_ylim(-0.05, 1.05)
    _log_ticks(ax.xaxis)
    ax.set_title(f"{a.scene}: predicted probability of a reaction against drop height",
                 fontsize=10)
    ax.legend(fontsize=7, loc="center left", bbox_to_anchor=(1.01, 0.5), frameon=False)
    fig.tight_layout()
    path = out / f"go_{a.scene}.png"
    save(fig, path)
    return path


def _open_arrow(ax, x, y, direction, color) -> None:
    """An arrow from (x, y) along a log axis: 'right'/'left' (x open) or 'up'/'down'."""
    factor = {"right": (3.0, 1.0), "left": (1 / 3.0, 1.0), "up": (1.0, 3.0),
              "down": (1.0, 1 / 3.0)}[direction]
    ax.annotate("", xy=(x * factor[0], y * factor[1]), xytext=(x, y),
                arrowprops={"arrowstyle": "->", "color": color, "lw": 1.5})


def _h50_figure(plt, out: Path, comparable: list[SceneAnalysis], confidence: float) -> Path:
    fig, ax = plt.subplots(figsize=(7.6, 5.2))
    xs, ys = [], []
    calc_label = True
    for i, a in enumerate(comparable):
        color = f"C{i % 10}"
        p, e = a.predicted_h50(), a.experimental_h50()
        x = e[0] if math.isfinite(e[0]) else e[1]
        yerr = [[max(p[0] - p[1], 0)], [max(p[2] - p[0], 0)]]
        lower_bound = a.experiment.h50_qualifier == "lower_bound"
        ax.errorbar([x], [p[0]], yerr=yerr, fmt=">" if lower_bound else "o", color=color,
                    capsize=3, label=a.scene)
        low_open = not (math.isfinite(e[1]) and e[1] > 0)
        high_open = not math.isfinite(e[2])
        if not low_open and not high_open:
            ax.errorbar([x], [p[0]], xerr=[[max(x - e[1], 0)], [max(e[2] - x, 0)]],
                        fmt="none", color=color, capsize=3)
        elif not high_open:  # [0, high]: a bar to the finite end, an arrow to the open one
            ax.plot([x, e[2]], [p[0], p[0]], color=color)
            _open_arrow(ax, x, p[0], "left", color)
        elif not low_open:  # [low, inf): lower bound
            if e[1] < x:
                ax.plot([e[1], x], [p[0], p[0]], color=color)
            _open_arrow(ax, x, p[0], "right", color)
        calc = experiments_module.report_calculated_height(a.experiment.name)
        if math.isfinite(calc):
            ax.plot([x], [calc], "x", color=color, ms=8, mew=2,
                    label="report's calculated height (Tables VIII, IX)" if calc_label else None)
            calc_label = False
            ys.append(calc)
        xs.append(x)
        ys += [p[1], p[2]]
    finite = [v for v in xs + ys if math.isfinite(v) and v > 0]
    lo, hi = min(finite) / 3.0, max(finite) * 3.0
    ax.plot([lo, hi], [lo, hi], "k--", lw=0.8, label="predicted = experimental")
    ax.set_xlim(lo, hi)
    ax.set_ylim(lo, hi)
    ax.set_xscale("log")
    ax.set_yscale("log")
    _log_ticks(ax.xaxis)
    _log_ticks(ax.yaxis)
    ax.set_xlabel(f"experimental 50 % height [ft]\n(bars: {level(confidence)} probit interval "
                  "where the drops are listed; arrows: open bounds)", fontsize=9)
    nested = any(a.epistemic is not None for a in comparable)
    ax.set_ylabel("predicted H50 [ft] " + (f"(median, bars {band(EPISTEMIC_BAND)} across "
                                            "epistemic draws)" if nested else
                                            f"(bars: {level(confidence)} interval)"), fontsize=9)
    ax.set_title("Predicted against experimental 50 % heights", fontsize=10)
    ax.legend(fontsize=7, loc="center left", bbox_to_anchor=(1.01, 0.5), frameon=False)
    fig.tight_layout()
    path = out / "h50.png"
    save(fig, path)
    return path


def _mu_figure(plt, out: Path, series: list[SceneAnalysis], confidence: float) -> Path:
    """The second series as the report's Fig. 6, made probabilistic: predicted H50 against the
    finish's friction coefficient with its band, the experiments and the report's calculation."""
    series = sorted(series, key=lambda a: experiments_module.experiment_friction(
        a.experiment.name))
    mu = np.array([experiments_module.experiment_friction(a.experiment.name) for a in series])
    pred = np.array([a.predicted_h50() for a in series])
    exp = np.array([a.experiment.h50 for a in series])
    calc = np.array([experiments_module.report_calculated_height(a.experiment.name)
                     for a in series])
    nested = any(a.epistemic is not None for a in series)
    fig, ax = plt.subplots(figsize=(7.8, 4.6))
    ax.fill_between(mu, pred[:, 1], pred[:, 2], color="C1", alpha=0.25,
                    label="predicted H50, " + (f"{band(EPISTEMIC_BAND)} across epistemic draws"
                                               if nested else f"{level(confidence)} interval"))
    ax.plot(mu, pred[:, 0], "o-", color="C1", label="predicted H50 (median)")
    ax.plot(mu, exp, "s", color="k", label="experimental 50 % height (Table IX)")
    ax.plot(mu, calc, "x--", color="0.35", label="report's calculated critical height (Table IX)")
    ax.set_yscale("log")
    _log_ticks(ax.yaxis)
    ax.set_xlabel("apparent friction coefficient of the finish, mu [-] (Tables I, IX)")
    ax.set_ylabel("50 % drop height [ft]")
    ax.set_title("Second series: drop height against friction (the report's Fig. 6, with "
                 "bands)", fontsize=10)
    ax.legend(fontsize=7, loc="upper right")
    fig.tight_layout()
    path = out / "h50_vs_mu.png"
    save(fig, path)
    return path


def _qq_figure(plt, out: Path, with_qq: list[SceneAnalysis]) -> Path:
    cols = min(3, len(with_qq))
    rows = math.ceil(len(with_qq) / cols)
    fig, axes = plt.subplots(rows, cols, figsize=(3.9 * cols, 3.6 * rows), squeeze=False)
    for ax, a in zip(axes.flat, with_qq):
        plot_qq(ax, a.fit)
        for artist in ax.get_lines() + ax.collections:
            label = str(artist.get_label())
            if "uncensored" in label:
                artist.set_label("model samples (uncensored)")
            elif label == "1:1":
                artist.set_label("on the fitted log-normal")
        ax.set_xlabel("fitted log-normal quantile [ft]", fontsize=8)
        ax.set_ylabel("model samples: critical height [ft]", fontsize=8)
        _log_ticks(ax.xaxis)
        _log_ticks(ax.yaxis)
        ax.tick_params(labelsize=7)
        if ax.get_legend():
            ax.legend(fontsize=7, loc="upper left")
        ax.set_title(f"{a.scene}: {a.fit.verdict}", fontsize=8)
    for ax in list(axes.flat)[len(with_qq):]:
        ax.set_visible(False)
    fig.suptitle("Log-normal Q-Q of the model's critical heights", fontsize=9)
    fig.tight_layout()
    path = out / "qq.png"
    save(fig, path)
    return path


def _figures(out: Path, analyses: list[SceneAnalysis], confidence: float) -> list[Path]:
    plt = pyplot("the report's figures")
    if plt is None:  # pragma: no cover - matplotlib is in the figures extra
        raise ImportError("skidmc report draws figures with matplotlib: "
                          "pip install 'skidmc[figures]'")
    written = [_go_figure(plt, out, a) for a in analyses]

    for a in analyses:
        k = _skill(a)
        if k is None or k.n < MIN_DROPS_RELIABILITY:
            continue
        fig, ax = plt.subplots(figsize=(4.8, 4.4))
        plot_reliability(ax, reliability(a.scores.p_go, a.experiment.drops.went),
                         title=f"{a.scene}: reliability of the predicted P(go) at its {k.n} "
                         "drops")
        fig.tight_layout()
        path = out / f"reliability_{a.scene}.png"
        save(fig, path)
        written.append(path)

    comparable = [a for a in analyses if a.experiment is not None and a.fit is not None]
    if comparable:
        written.append(_h50_figure(plt, out, comparable, confidence))
    series2 = [a for a in comparable if a.experiment.name.startswith("series2_")]
    if len(series2) >= 2:
        written.append(_mu_figure(plt, out, series2, confidence))

    with_qq = [a for a in analyses if a.fit is not None and a.fit.qq is not None]
    if with_qq:
        written.append(_qq_figure(plt, out, with_qq))

    for a in analyses:
        if a.sobol is None:
            continue
        from skidmc.analysis.sensitivity import plot_indices

        fig, ax = plt.subplots(figsize=(8.0, 0.42 * a.sobol.sizes["parameter"] + 1.6))
        plot_indices(ax, a.sobol)
        ax.set_title(f"{a.scene}: Sobol' indices of ln H_c\n{ax.get_title()}", fontsize=9)
        fig.tight_layout()
        path = out / f"sobol_{a.scene}.png"
        save(fig, path)
        written.append(path)
        if a.sobol_convergence is not None and a.sobol_convergence.sizes["N"] > 1:
            from skidmc.analysis.sensitivity import plot_convergence

            fig, axes = plt.subplots(1, 2, figsize=(12.0, 4.4), sharey=True)
            for ax, index in zip(axes, ("S1", "ST")):
                plot_convergence(ax, a.sobol_convergence, index=index, legend=False)
                ax.set_title(f"{a.scene}: {index} against N", fontsize=9)
            handles, labels = axes[1].get_legend_handles_labels()
            fig.legend(handles, labels, fontsize=7, loc="center left",
                       bbox_to_anchor=(0.79, 0.5), frameon=False)
            fig.tight_layout(rect=(0, 0, 0.79, 1))
            path = out / f"sobol_convergence_{a.scene}.png"
            save(fig, path)
            written.append(path)
    return written


def _curves_dataset(analyses: list[SceneAnalysis]) -> xr.Dataset:
    parts = {}
    for a in analyses:
        c = a.curve.rename({"height": f"height_ft_{a.scene}"})
        for name in ("p_go", "p_go_low", "p_go_high"):
            parts[f"{name}_{a.scene}"] = c[name]
        if a.epistemic is not None:
            e = a.epistemic.rename({"height_ft": f"height_ft_{a.scene}",
                                    "epistemic": "epistemic"})
            for name in ("p_go", "p_go_median", "p_go_low", "p_go_high", "h50"):
                parts[f"epistemic_{name}_{a.scene}"] = e[name]
    ds = xr.Dataset(parts)
    for a in analyses:
        ds[f"height_ft_{a.scene}"].attrs.update(units="ft", long_name="drop height H")
    ds.attrs["description"] = "P(go | H) per scene: empirical curve with a simultaneous band"
    return ds


def _sobol_dataset(analyses: list[SceneAnalysis]) -> xr.Dataset:
    """Every scene's indices (of ln H_c, and of the event at its median height) in one file."""
    parts = []
    for a in analyses:
        for output, res in (("log_height", a.sobol), ("event_at_h50", a.sobol_event)):
            if res is None:
                continue
            keep = [v for v in res.data_vars if res[v].dims == ("parameter",)]
            parts.append(res[keep].astype(float).expand_dims(scene=[a.scene], output=[output]))
    ds = xr.merge(parts, join="outer", compat="no_conflicts", combine_attrs="drop")
    first = analyses[0].sobol.attrs
    ds.attrs = {k: v for k, v in first.items() if isinstance(v, (int, float, str))}
    ds.attrs["description"] = ("Sobol' indices per scene: of ln H_c (log_height) and of the go "
                               "event at a drop from the fitted median height (event_at_h50)")
    return ds


def write_report(ds: xr.Dataset, out_dir: str | Path, *, source: str = "",
                 experiments: Mapping[str, str] | None = None,
                 confidence: float = 0.95) -> dict:
    """Analyse an ensemble and write its report.

    Parameters
    ----------
    ds : xarray.Dataset
        An ensemble (:func:`skidmc.analysis.open_ensemble`).
    out_dir : str or Path
        Folder to write into (created).
    source : str
        How the ensemble was named on the command line (for the report's header).
    experiments : mapping of str to str, optional
        Scene -> experiment; default: the study's ``experiment`` keys.
    confidence : float

    Returns
    -------
    dict
        ``analyses`` (list of :class:`SceneAnalysis`) and ``files`` (paths written).
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    analyses = analyse_ensemble(ds, experiments=experiments, confidence=confidence)
    files = _figures(out, analyses, confidence)
    summary = {"study": ds.attrs.get("study_name", ""), "confidence": confidence,
               "nested": "epistemic" in ds.dims,
               "scenes": [_summary_dict(a) for a in analyses]}
    write_json(out / "summary.json", summary)
    growth = None
    if (out / "convergence.json").is_file():   # a grown saltelli study's stopping rule
        try:
            growth = json.loads((out / "convergence.json").read_text())
        except ValueError:
            growth = None
    (out / "summary.md").write_text(_markdown(ds, analyses, source, confidence, growth))
    curves_path = out / "curves.h5"
    _curves_dataset(analyses).to_netcdf(curves_path, engine="h5netcdf")
    files += [out / "summary.json", out / "summary.md", curves_path]
    with_sobol = [a for a in analyses if a.sobol is not None]
    if with_sobol:
        sobol_path = out / "sobol.h5"
        _sobol_dataset(with_sobol).to_netcdf(sobol_path, engine="h5netcdf")
        files.append(sobol_path)
    return {"analyses": analyses, "files": files}
