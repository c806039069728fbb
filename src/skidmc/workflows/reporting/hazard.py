"""The summary of a hazard study (kind ``hazard``): what ``skidmc run`` and ``skidmc report``
write beside its evaluation log.

:func:`write_hazard_report` writes ``summary.json`` (the one encoding,
:func:`skidmc.workflows.reporting.dumps`), ``summary.md``, ``fragility.csv`` and two figures
(``fragility.png``, ``importance.png``) from a
:class:`~skidmc.workflows.hazard.HazardResult`. Every interval and band is labelled with the
confidence level and quantiles the result records it was computed at (``confidence``,
``band_quantiles``).
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
from scipy import stats

from skidmc.ensemble.hazard_study import HazardStudy
from skidmc.ensemble.study_model import EXTRA_KEYS
from skidmc.scene import SI_UNITS
from skidmc.scene.units import from_si
from skidmc.workflows.reporting import band, level, pyplot, save, write_json

__all__ = ["write_hazard_report"]

# Display units of the summary (SI inside).
_DISPLAY_UNITS = {"flow_stress": "psi", "billet_mass": "lb", "billet_diameter": "in",
                  "drop_height": "m", "kinetics.heat_of_reaction": "cal/g"}


def _unit(key: str) -> str:
    if key in SI_UNITS:
        return SI_UNITS[key]
    if key in EXTRA_KEYS:
        return EXTRA_KEYS[key][0]
    return "m"


def _shown(key: str, value: float) -> str:
    """A value with its unit, in the summary's display unit."""
    unit = _unit(key)
    if key in _DISPLAY_UNITS:
        return f"{from_si(value, unit, _DISPLAY_UNITS[key]):.4g} {_DISPLAY_UNITS[key]}"
    return f"{value:.4g}" + ("" if unit in ("1", "-") else f" {unit}")


def write_hazard_report(result, study: HazardStudy, out: Path) -> list[Path]:
    """Write the summary of a hazard study's result into `out` (created).

    Parameters
    ----------
    result : skidmc.workflows.hazard.HazardResult
    study : HazardStudy
    out : Path

    Returns
    -------
    list of Path
        ``summary.json``, ``summary.md``, ``fragility.csv`` and the figures.
    """
    out.mkdir(parents=True, exist_ok=True)
    files = [out / "summary.json", out / "summary.md", out / "fragility.csv"]
    data = result.to_dict()
    data["study"] = {"file": study.file, "sha256": study.sha256}
    data.pop("files", None)
    data.pop("wall_time", None)  # machine-dependent: the summary stays reproducible
    write_json(files[0], data)
    files[1].write_text(_markdown(result, study), encoding="utf-8")
    f = result.fragility
    lines = ["median_drop_height_m,probability,cov,band_low,band_high"]
    lines += [f"{m:.6g},{p:.6g},{c:.4g},{lo:.6g},{hi:.6g}" for m, p, c, lo, hi in
              zip(f["median"], f["probability"], f["cov"], f["band_low"], f["band_high"])]
    files[2].write_text("\n".join(lines) + "\n", encoding="utf-8")
    files += _figures(result, study, out)
    return files


def _markdown(r, study: HazardStudy) -> str:
    lo, hi = r.interval
    ci, qs = level(r.confidence), band(r.band_quantiles)
    q_low, q_high = (f"{q * 100:g} %" for q in r.band_quantiles)
    lines = [
        f"# Hazard study `{r.name}`",
        "",
        f"Study file `{Path(study.file).name}` (sha256 {study.sha256[:12]}). "
        f"{study.description}",
        "",
        "## Probability of a reaction per accident",
        "",
        f"- **P = {r.probability:.3g}** per accident, {ci} interval [{lo:.3g}, {hi:.3g}], "
        f"CoV {r.cov:.3f} (epistemic inputs averaged in: the pooled estimate)"
        + (": accidents on the surfaces the model describes that end in a reaction."
           if r.unmodelled_weight > 0 else "."),
    ]
    outside = [s for s in r.surfaces if s.regime == "outside"]
    if outside:
        names = ", ".join(f"{s.material} ({s.weight:.0%} of accidents)" for s in outside)
        lines += [
            f"- **Outside the model: {names}.** These accidents are not in P and not counted "
            "as \"no reaction\": the model says nothing about them. The probability per "
            f"accident over all surfaces lies in **[{r.bounds[0]:.3g}, {r.bounds[1]:.3g}]** "
            f"(P, and P plus the unmodelled share {r.unmodelled_weight:.3g}, as if every "
            "unmodelled accident reacted). Were they to react as often as the modelled ones, "
            f"it would be P / (1 - {r.unmodelled_weight:.3g}) = {r.conditional_modelled:.3g} "
            "(P(reaction | a modelled surface)); that is a judgement, not a result.",
        ]
    post = getattr(r, "posterior", None) or {}
    if r.epistemic_probabilities.size and post:
        e = r.epistemic_probabilities
        lines.append(
            f"- Epistemic band **under the posterior** of `{post['calibration']}` (the "
            f"epistemic inputs held at each of {e.size} draws of it): {qs} [{r.band[0]:.3g}, "
            f"{r.band[1]:.3g}], median {np.median(e):.3g}; their mean, **P = "
            f"{post['probability']:.3g}** per accident, {ci} interval "
            f"[{post['interval'][0]:.3g}, {post['interval'][1]:.3g}] (over the draws), is "
            "the posterior's P (the pooled P above is over the priors: see \"Prior against "
            f"posterior\"); draws' own CoV at most {np.max(r.epistemic_covs):.2f}.")
    elif r.epistemic_probabilities.size:
        e = r.epistemic_probabilities
        lines.append(
            f"- Epistemic band (kinetics held at each of {e.size} Latin-hypercube draws): "
            f"{qs} [{r.band[0]:.3g}, {r.band[1]:.3g}], median {np.median(e):.3g}, mean "
            f"{e.mean():.3g} (the pooled P estimates this mean); draws' own CoV at most "
            f"{np.max(r.epistemic_covs):.2f}.")
    lines += [
        f"- Solver runs: {r.runs['total']} ({r.runs['pooled']} pooled, {r.runs['epistemic']} "
        f"epistemic loop, {r.runs.get('alternatives', 0)} geometry and angle alternatives), "
        f"tier `{study.solver.tier}`, rtol {study.solver.rtol:g}; "
        f"failures: {r.failed}.",
        f"- Solver tolerance: -d ln P / d ln H_c = {r.elasticity:.1f}, so an error of rtol = "
        f"{study.solver.rtol:g} on every H_c would move P by about "
        f"{r.elasticity * study.solver.rtol:.0%}.",
        "",
        *(_posterior_section(r, study) if post else []),
        "## Per surface (pooled)",
        "",
        "| surface | regime | weight | P(reaction given surface) | share of P per accident | "
        f"{ci} interval of share | CoV | runs | failed |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for s in r.surfaces:
        if s.regime == "outside":
            lines.append(f"| {s.material} | outside the model | {s.weight:g} | not modelled | "
                         f"not in P (unmodelled share {s.weight:g}) | - | - | 0 | - |")
            continue
        lines.append(f"| {s.material} | {s.regime} | {s.weight:g} | {s.conditional:.3g} | "
                     f"{s.share:.3g} | [{s.interval[0]:.3g}, {s.interval[1]:.3g}] | "
                     f"{s.cov:.3f} | {s.runs} | {s.failed} |")
    lines += ["", f"The shares of the modelled surfaces sum to P = {r.probability:.3g}.", "",
              "Regime of each surface (the contact pressure the model uses: the billet's flow "
              "stress sigma on a rigid target, min(sigma, p_t) on one that yields at p_t; "
              "docs/model.md, \"Targets softer than the billet\"):", ""]
    lines += [f"- **{s.material}**: {s.regime_note}" for s in r.surfaces]
    if r.alternative:
        a = r.alternative
        alo, ahi = a["interval"]
        lines += ["", f"## Geometry: {study.scene.configuration} drop against "
                  f"{a['configuration']}", "",
                  f"The headline uses the {study.scene.configuration} geometry (report Sec. "
                  "II.C: the billet falls onto a surface inclined at the impact angle, tilt = "
                  f"angle). Under the {a['configuration']} geometry (the billet level, tilt = "
                  "0: a billet carried level that meets the floor obliquely) the same "
                  f"population gives **P = {a['probability']:.3g}** [{alo:.3g}, {ahi:.3g}] "
                  f"(CoV {a['cov']:.3f}, pooled, {a['runs']} solver runs, no epistemic loop).",
                  "", f"| surface | P(reaction given surface), {study.scene.configuration} | "
                  f"P(reaction given surface), {a['configuration']} |", "|---|---|---|"]
        for s in r.surfaces:
            if s.material in a["surfaces"]:
                lines.append(f"| {s.material} | {s.conditional:.3g} | "
                             f"{a['surfaces'][s.material]:.3g} |")
        lines += ["", f"| | {study.scene.configuration} | {a['configuration']} |",
                  "|---|---|---|",
                  f"| P per accident (modelled surfaces) | {r.probability:.3g} | "
                  f"{a['probability']:.3g} |"]
    if r.angle_scales:
        rule = r.rerun_rule
        lines += ["", "## The angle distribution's scale", "",
                  "P at other plausible scales of the angle distribution, from the same solver "
                  "samples reweighted by the ratio of the angle densities f_alt(phi) / f(phi) "
                  "(no extra solver run; unbiased where the samples cover the alternative, the "
                  "CoV says how well; the epistemic band likewise from the draws' samples, "
                  "so it is no better covered than the reweighted P on its row). "
                  "\"Beyond sampled range\": the alternative's probability of angles beyond "
                  "the study's 1e-9 quantiles, which no sample reached (an upper bound on what "
                  "the reweighting misses).", "",
                  f"Where the reweighted CoV exceeds {rule['cov']:g} or the range the samples "
                  f"missed holds more than {rule['uncovered']:g} P, the samples do not cover the "
                  "alternative: P is then rerun with fresh samples of it (pooled, at the "
                  "epistemic draws' target CoV, no epistemic loop; angles beyond "
                  f"{rule['angle_max_deg']:g} deg clipped to it) and the rerun is the value to "
                  "use.", "",
                  "| angle distribution | P per accident, reweighted | CoV | epistemic "
                  f"{q_low} | epistemic {q_high} | beyond sampled range | P, rerun [{ci} "
                  "interval] |",
                  "|---|---|---|---|---|---|---|"]
        for a in r.angle_scales:
            label = f"half-normal, scale {a['scale_deg']:g} deg" if a["distribution"].startswith(
                "halfnorm") and a["scale_deg"] is not None else a["distribution"]
            label += " (the study's)" if a["study"] else ""
            rerun = a.get("rerun")
            again = (f"**{rerun['probability']:.3g}** [{rerun['interval'][0]:.3g}, "
                     f"{rerun['interval'][1]:.3g}] ({rerun['runs']} runs)" if rerun else
                     "not needed")
            lines.append(f"| {label} | {a['probability']:.3g} | {a['cov']:.2f} | "
                         f"{a['band_low']:.3g} | {a['band_high']:.3g} | {a['uncovered']:.2g} | "
                         f"{again} |")
    lines += ["",
              "## Design point: the most likely initiating combination", "",
              f"Surface **{r.design_point['surface']}**; it reacts from a drop of "
              f"{r.design_point['critical_height']:.3g} m or more "
              f"({from_si(r.design_point['critical_height'], 'm', 'ft'):.3g} ft).", "",
              "| input | design point | median of its distribution | E[U given reaction] |",
              "|---|---|---|---|"]
    best = next(e for e in r.surfaces if e.material == r.design_point["surface"])
    medians = r.design_medians
    for key, value in best.design_point.items():
        lines.append(f"| `{key}` | {_shown(key, value)} | {_shown(key, medians[key])} | "
                     f"{r.importance[key]:+.2f} |")
    lines += ["", "E[U given reaction]: the mean normal score of each input over the reactions "
              "(share-weighted over the surfaces), in standard deviations from its median: the "
              "inputs that a reaction pulls furthest drive the hazard.", "",
              "Design point per surface:", "",
              "| surface | H_c at its design point | ln density (relative) |", "|---|---|---|"]
    top = max(s.design_log_density for s in r.surfaces)
    for s in r.surfaces:
        if s.regime == "outside":
            lines.append(f"| {s.material} | outside the model (not run) | - |")
            continue
        lines.append(f"| {s.material} | {s.design_critical_height:.3g} m | "
                     f"{s.design_log_density - top:+.1f} |")
    f = r.fragility
    lines += ["", "## Fragility: P against the median drop height", "",
              "The same H_c samples reweighted (no extra solver run); the band from the "
              f"epistemic draws' samples: it covers the kinetics inputs only "
              f"({', '.join(study.epistemic_keys) or 'none'}; "
              f"{study.estimator.epistemic_draws} draws"
              + (f" of the posterior of `{post['calibration']}`" if post else "")
              + "), every other input averaged within "
              "each draw.", "",
              f"| median drop height | P per accident | CoV | epistemic {q_low} | epistemic "
              f"{q_high} |",
              "|---|---|---|---|---|"]
    for m, p, c, a, b in zip(f["median"], f["probability"], f["cov"], f["band_low"],
                             f["band_high"]):
        lines.append(f"| {m:.3g} m | {p:.3g} | {c:.2f} | {a:.3g} | {b:.3g} |")
    lines += ["", "## Assumptions", "",
              "The study's judgements, as its file states them:", ""]
    lines += [f"- {a}" for a in study.assumptions] or [
        "- (the study file lists none: `assumptions = [...]` in [hazard])"]
    lines += ["", "Every sampled input and its source, as the study file gives it:", "",
              "| input | distribution (parameters in SI: Pa, K, J/kg, 1/s; angle in deg; "
              "`x nominal`: a factor on the scene's value) | source |", "|---|---|---|",
              f"| drop height [m] | {study.drop_height.describe()} | "
              f"{study.drop_height.source} |",
              f"| impact angle [deg] | {study.angle.describe()} | {study.angle.source} |"]
    for surf in study.surfaces:
        lines.append(f"| friction on {surf.material} | {surf.friction.describe()} | "
                     f"{surf.friction.source} |")
    for part, group in (("billet", study.billet), ("epistemic", study.epistemic)):
        for key, d in group.items():
            lines.append(f"| `{key}` ({part}) | {d.describe()} | {d.source} |")
    lines += ["", "| surface | weight | source of the weight |", "|---|---|---|"]
    lines += [f"| {surf.material} | {surf.weight:g} | {surf.source} |"
              for surf in study.surfaces]
    lines += ["", f"Configuration of the headline: {study.scene.configuration}; epistemic "
              f"draws: {study.estimator.epistemic_draws}; solver tolerance rtol "
              f"{study.solver.rtol:g} (moves P by about {r.elasticity * study.solver.rtol:.0%}, "
              "above).", "", "## Run notes", ""]
    lines += [f"- {n}" for n in r.notes] or ["- none (no failures, every estimate reached "
                                              "its target CoV)"]
    if r.failure_reasons:
        lines += ["", "Failure reasons:", ""] + [f"- {x}" for x in r.failure_reasons]
    lines += ["", "Figures: `fragility.png`, `importance.png`. Data: `summary.json`, "
              "`fragility.csv`.", ""]
    return "\n".join(lines)


def _posterior_section(r, study: HazardStudy) -> list[str]:
    """Prior against posterior: P and its band under both, the inputs' spread, what the
    posterior's other parameters are and why the hazard does not use them."""
    post = r.posterior
    ci, qs = level(r.confidence), band(r.band_quantiles)
    prior, pooled = post["prior"]["study"], post["prior"]["pooled"]
    lo, hi = post["interval"]
    found = prior.get("status") == "found"
    if found:
        prior_band = (f"[{prior['band'][0]:.3g}, {prior['band'][1]:.3g}] "
                      f"({len(prior['epistemic_probabilities'])} Latin-hypercube draws of the "
                      f"priors, from `{Path(prior['file']).name}`'s summary)")
        check = (f"; that study's pooled P: {prior['probability']:.3g} "
                 f"[{prior['interval'][0]:.3g}, {prior['interval'][1]:.3g}]")
    else:
        prior_band = f"not available: {prior['status']}"
        check = ""
    lines = [
        "## Prior against posterior",
        "",
        f"The epistemic inputs ({', '.join(f'`{k}`' for k in post['keys'])}) are taken from "
        f"the posterior of the calibration `{post['calibration']}` (`{post['file']}`, "
        f"sha256 {post['sha256'][:12]}, completed {post['completed'] or '?'}): "
        f"{post['draws']} of its {post['stored']} stored draws, equally spaced over the "
        "flattened (chain, draw) order, each a whole row of the posterior (their joint "
        "distribution, correlation included, kept). Every other input is as in the study "
        "over the priors. P under the posterior is the mean of P over these draws, its "
        f"{ci} interval a Student-t one over the {post['draws']} draws (it holds the spread "
        "between draws and each draw's own sampling error); P over the priors is the pooled "
        "estimate of this run (same seed as the study over the priors" + check + ").",
        "",
        f"| | P per accident | {ci} interval | epistemic {qs} |",
        "|---|---|---|---|",
        f"| prior | {pooled['probability']:.3g} | [{pooled['interval'][0]:.3g}, "
        f"{pooled['interval'][1]:.3g}] (pooled) | {prior_band} |",
        *([f"| prior, mean of its {prior['draws_mean']['n']} draws (as the posterior's) | "
           f"{prior['draws_mean']['probability']:.3g} | "
           f"[{prior['draws_mean']['interval'][0]:.3g}, "
           f"{prior['draws_mean']['interval'][1]:.3g}] (over its draws) | as above |"]
          if found else []),
        f"| posterior (`{post['calibration']}`) | {post['probability']:.3g} | "
        f"[{lo:.3g}, {hi:.3g}] (over {post['draws']} draws) | [{post['band'][0]:.3g}, "
        f"{post['band'][1]:.3g}] ({post['draws']} posterior draws) |",
        "",
        "Spread of each input (" + "-".join(f"{q * 100:g}" for q in post["spread_quantiles"])
        + " % quantiles): the hazard study's prior, the calibration's prior (its stored prior "
        "draws), the calibration's posterior (every stored draw) and the draws taken here.",
        "",
        "| input | hazard prior | calibration prior | posterior | draws taken |",
        "|---|---|---|---|---|",
    ]
    for key, sp in post["spread"].items():
        cells = [" / ".join(_shown(key, v) for v in sp[part]) if sp[part] else "not stored"
                 for part in ("hazard_prior", "calibration_prior", "posterior", "draws")]
        lines.append(f"| `{key}` | " + " | ".join(cells) + " |")
    corr = post["correlation"]
    keys = corr["keys"]
    if len(keys) > 1:
        lines += ["", "Rank (Spearman) correlation of the inputs: posterior (every stored draw) "
                  "/ the draws taken.", "", "| | " + " | ".join(f"`{k}`" for k in keys) + " |",
                  "|---|" + "---|" * len(keys)]
        for i, k in enumerate(keys):
            lines.append(f"| `{k}` | " + " | ".join(
                f"{corr['posterior'][i][j]:+.2f} / {corr['draws'][i][j]:+.2f}"
                for j in range(len(keys))) + " |")
    lines += ["", "The posterior's other parameters, not used by this study:", ""]
    reasons: dict[str, list[str]] = {}
    for name, why in post["unused"].items():
        reasons.setdefault(why, []).append(f"`{name}`")
    lines += [f"- {', '.join(names)}: {why}" for why, names in reasons.items()] or ["- none"]
    lines += ["", "Below, the per-surface table, the geometry and angle alternatives, the design "
              "point and the importance are the pooled estimate over the priors; the epistemic "
              "bands (fragility, angle scales) are over the posterior draws.", ""]
    return lines


def _figures(r, study: HazardStudy, out: Path) -> list[Path]:
    plt = pyplot("hazard figures")
    if plt is None:  # pragma: no cover - matplotlib is in the figures extra
        return []
    import matplotlib
    paths = []
    f = r.fragility
    fig, ax = plt.subplots(figsize=(6, 4))
    m = np.array(f["median"])
    p = np.array(f["probability"])
    c = np.array(f["cov"])
    if np.isfinite(f["band_low"]).all():
        ax.fill_between(m, f["band_low"], f["band_high"], color="C0", alpha=0.2,
                        label=f"{band(r.band_quantiles)} over {study.estimator.epistemic_draws} "
                              + ("posterior draws of the kinetics" if getattr(r, "posterior", None)
                                 else "kinetics draws (kinetics only)"))
    z = float(stats.norm.isf((1 - r.confidence) / 2))
    ax.errorbar(m, p, yerr=z * c * p, fmt="o-", color="C0", capsize=3,
                label=("all inputs sampled" + (", the kinetics from their priors"
                                               if getattr(r, "posterior", None) else "")
                       + f", {level(r.confidence)} sampling interval"))
    ax.axvline(float(study.drop_height.frozen.median()), color="grey", ls=":",
               label="study median")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xticks(m[::2], [f"{v:.3g}" for v in m[::2]])
    ax.xaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())
    ax.set_xlabel("median drop height [m]")
    ax.set_ylabel("P(reaction) per accident")
    outside = [x.material for x in r.surfaces if x.regime == "outside"]
    ax.set_title(f"{r.name}: fragility" + (f"\n(modelled surfaces; {', '.join(outside)} "
                                           "outside the model, not in P)" if outside else ""),
                 fontsize=10)
    ax.legend(fontsize=8)
    fig.tight_layout()
    paths.append(out / "fragility.png")
    save(fig, paths[-1])

    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(9, 4), gridspec_kw={"width_ratios": [3, 2]})
    keys = list(r.importance)
    values = [r.importance[k] for k in keys]
    ax1.barh(range(len(keys)), values, color=["C3" if v > 0 else "C0" for v in values])
    ax1.set_yticks(range(len(keys)), [k.replace("kinetics.", "kinetics: ").replace("_", " ")
                                      for k in keys], fontsize=8)
    ax1.axvline(0, color="black", lw=0.5)
    ax1.set_xlabel("mean shift of the input over reactions\n"
                   "E[U | reaction] [standard deviations from its median]", fontsize=8)
    ax1.invert_yaxis()
    from matplotlib.patches import Patch

    ax1.legend(handles=[Patch(color="C3", label="reactions need a higher value"),
                        Patch(color="C0", label="reactions need a lower value")],
               fontsize=7, loc="best")
    names = [s.material for s in r.surfaces]
    x = np.arange(len(names))
    ax2.bar(x - 0.2, [s.weight for s in r.surfaces], 0.4, color="C7",
            label="share of accidents")
    shares = [s.share / r.probability if r.probability > 0 and s.regime != "outside"
              and s.share > 0 else np.nan for s in r.surfaces]
    ax2.bar(x + 0.2, shares, 0.4, color="C1", label="share of P")
    ax2.set_yscale("log")
    floor = min([v for v in shares if np.isfinite(v)] + [0.01])
    bottom = max(floor / 3, 1e-16)
    ax2.set_ylim(bottom, 50.0)  # room above 1 for the legend
    for k, s in enumerate(r.surfaces):
        if s.regime == "outside":
            ax2.text(k + 0.2, math.sqrt(bottom), "outside the model:\nnot in P", rotation=90,
                     fontsize=7, ha="center", va="center", color="C1")
    ax2.set_xticks(x, [f"{n}\n({s.regime})" for n, s in zip(names, r.surfaces)], rotation=30,
                   fontsize=7)
    ax2.set_xlim(-0.6, len(names) - 0.4)
    ax2.set_ylabel("fraction (log scale)", fontsize=8)
    ax2.legend(fontsize=7, loc="upper right", ncol=2)
    fig.suptitle(f"{r.name}: what drives a reaction (left: inputs, pooled; right: surfaces)",
                 fontsize=10)
    fig.tight_layout()
    paths.append(out / "importance.png")
    save(fig, paths[-1])
    return paths
