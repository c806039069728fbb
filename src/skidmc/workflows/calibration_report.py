"""The report of a calibration (``skidmc report`` of the ``calibration`` kind).

Reads ``posterior.nc`` alone (ArviZ InferenceData written by
:func:`skidmc.workflows.calibration.run`; no solver, no sampling) and writes beside it:
``prior_posterior.png`` (every parameter), ``go_curves.png`` (posterior-predictive P(go | H) per
target with the drops and their counts), ``h50.png`` (posterior H50 per target against Table II,
and the second series' predictions against Table IX), ``correlations.png`` (pairwise posterior
rank correlations) and ``summary.md`` (every assumption, the diagnostics, the tables).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

__all__ = ["write_calibration_report"]

DPI = 110


def _load(path: Path):
    import warnings

    import arviz as az
    import xarray as xr

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        idata = az.from_netcdf(str(path), engine="h5netcdf")
        curves = xr.open_dataset(path, group="go_curves", engine="h5netcdf").load()
    return idata, curves, json.loads(idata.attrs["summary"])


def _q(values, qs=(0.05, 0.5, 0.95)):
    return [float(v) for v in np.quantile(np.asarray(values).ravel(), qs)]


def _fmt(v: float) -> str:
    if v == 0 or not np.isfinite(v):
        return f"{v:g}"
    a = abs(v)
    if 1e-3 <= a < 1e5:
        return f"{v:.3g}"
    return f"{v:.3e}"


def _plot_prior_posterior(idata, params, out: Path):
    """One panel per parameter (`params`: the summary's parameter records), its title the name
    with its unit: [1] for a factor on the scene's nominal value (the key's own unit otherwise)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names = [p["name"] for p in params]
    units = {p["name"]: ("factor [1]" if p.get("relative") else
                         f"[{p['unit']}]" if p.get("unit") not in (None, "", "1") else "[1]")
             for p in params}
    n = len(names)
    cols = 4
    rows = (n + cols - 1) // cols
    fig, axes = plt.subplots(rows, cols, figsize=(12, 2.3 * rows))
    for ax, name in zip(axes.ravel(), names):
        post = idata.posterior[name].values.ravel()
        prior = idata.prior[name].values.ravel()
        if units[name] == "[J/kg]":  # heats of reaction: MJ/kg, not an axis offset of 1e6
            post, prior, units[name] = post / 1e6, prior / 1e6, "[MJ/kg]"
        lo, hi = np.quantile(np.concatenate([prior, post]), [0.005, 0.995])
        bins = np.linspace(lo, hi, 40)
        ax.hist(prior, bins=bins, density=True, color="0.75", label="prior")
        ax.hist(post, bins=bins, density=True, histtype="step", color="C0", lw=1.6,
                label="posterior")
        sep = "\n" if len(name) + len(units[name]) > 40 else " "  # long names: unit below
        ax.set_title(f"{name}{sep}{units[name]}", fontsize=8)
        ax.tick_params(labelsize=7)
        ax.set_yticks([])
    for ax in axes.ravel()[n:]:
        ax.axis("off")
    axes.ravel()[0].legend(fontsize=7)
    fig.suptitle("Prior (grey) and posterior (blue) of every calibrated parameter "
                 "(factors are on the scene's nominal value)", fontsize=10)
    fig.tight_layout()
    fig.savefig(out, dpi=DPI)
    plt.close(fig)


def _drop_counts(heights, went):
    """(height, goes, drops) per distinct height."""
    out = []
    for h in np.unique(heights):
        at = heights == h
        out.append((float(h), int(went[at].sum()), int(at.sum())))
    return out


def _plot_go_curves(idata, curves, summary, out: Path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.ticker import FormatStrFormatter, NullFormatter

    targets = list(curves.target.values)
    cols = 2 if len(targets) > 1 else 1
    rows = (len(targets) + cols - 1) // cols
    fig, axes = plt.subplots(rows, cols, figsize=(5.2 * cols, 3.4 * rows), squeeze=False)
    h = curves.height.values
    for ax, t in zip(axes.ravel(), targets):
        pr = curves.prior.sel(target=t)
        po = curves.posterior.sel(target=t)
        ax.fill_between(h, pr.sel(quantity="q05"), pr.sel(quantity="q95"), color="0.85",
                        label="prior 5-95 %")
        ax.fill_between(h, po.sel(quantity="q05"), po.sel(quantity="q95"), color="C0",
                        alpha=0.35, label="posterior 5-95 %")
        ax.plot(h, po.sel(quantity="mean"), color="C0", label="posterior predictive")
        heights = idata.observed_data[f"height[{t}]"].values
        went = idata.observed_data[f"went[{t}]"].values.astype(bool)
        for i, (x, k, n) in enumerate(_drop_counts(heights, went)):
            ax.plot(x, k / n, "ko", ms=4)
            # labels alternate above and below, so that neighbouring heights do not collide
            up = 6 if k / n < 0.5 else -12
            ax.annotate(f"{k}/{n}", (x, k / n), textcoords="offset points", ha="center",
                        xytext=(0, up + (10 if i % 2 and up > 0 else 0)
                                - (10 if i % 2 and up < 0 else 0)), fontsize=7)
        ax.set_xscale("log")
        ax.xaxis.set_major_formatter(FormatStrFormatter("%g"))
        ax.xaxis.set_minor_formatter(NullFormatter())
        ax.set_ylim(-0.05, 1.05)
        lo = max(h[0], 0.3 * min(heights.min(), _q(idata.posterior_predictive[f"h50[{t}]"])[0]))
        hi = min(h[-1], 3 * max(heights.max(), _q(idata.posterior_predictive[f"h50[{t}]"])[2]))
        ax.set_xlim(lo, hi)
        ax.set_xlabel("drop height [ft]")
        ax.set_title(f"{t}: P(go | H) and the drops (goes/drops at each height)", fontsize=9)
        ax.set_ylabel("P(go | H)")
        ax.grid(alpha=0.3)
    for ax in axes.ravel()[len(targets):]:
        ax.axis("off")
    axes[0][0].legend(fontsize=7, loc="center left")
    fig.tight_layout()
    fig.savefig(out, dpi=DPI)
    plt.close(fig)


def _experimental(name):
    from skidmc.analysis.experiments import get_experiment

    e = get_experiment(name)
    return e.h50, e.h50_qualifier


def _plot_h50(idata, summary, out: Path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    preds = summary["predictions"]
    fig, axes = plt.subplots(1, 2 if preds else 1, figsize=(10 if preds else 5.5, 3.6),
                             squeeze=False)
    ax = axes[0][0]
    targets = list(summary["experiments"])
    for i, t in enumerate(targets):
        q = _q(idata.posterior_predictive[f"h50[{t}]"])
        p = summary["prior_h50_ft"][t]
        ax.errorbar(i - 0.12, p[1], yerr=[[p[1] - p[0]], [p[2] - p[1]]], fmt="s", color="0.6",
                    capsize=3, label="prior 90 %" if i == 0 else None)
        ax.errorbar(i + 0.12, q[1], yerr=[[q[1] - q[0]], [q[2] - q[1]]], fmt="o", color="C0",
                    capsize=3, label="posterior 90 %" if i == 0 else None)
        h, qual = _experimental(summary["experiments"][t])
        bound = qual == "lower_bound"
        label = "experiment, lower bound (Table II)" if bound else "experiment (Table II)"
        ax.plot(i, h, "^" if bound else "D", color="C3", ms=7,
                label=label if label not in ax.get_legend_handles_labels()[1] else None)
    ax.set_xticks(range(len(targets)), targets, fontsize=8)
    ax.set_yscale("log")
    ax.set_ylabel("H50 [ft]")
    ax.set_title("First series: calibrated on these drops", fontsize=9)
    ax.legend(fontsize=7)
    ax.grid(alpha=0.3)
    if preds:
        ax = axes[0][1]
        for i, r in enumerate(preds):
            q = r["h50_ft"]
            ax.errorbar(i, q[1], yerr=[[q[1] - q[0]], [q[2] - q[1]]], fmt="o", color="C0",
                        capsize=3, label="predicted 90 %" if i == 0 else None)
            ax.plot(i, r["experimental_h50_ft"], "D", color="C3", ms=7,
                    label="experiment (Table IX)" if i == 0 else None)
        ax.set_xticks(range(len(preds)), [f"{r['scene']}\nmu {r['mu_measured']:g}"
                                          for r in preds], fontsize=7)
        ax.set_yscale("log")
        ax.set_ylabel("H50 [ft]")
        ax.set_title("Second series: predicted from the first's posterior", fontsize=9)
        ax.legend(fontsize=7)
        ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(out, dpi=DPI)
    plt.close(fig)


def _correlations(idata, names):
    from scipy import stats

    x = np.stack([idata.posterior[n].values.ravel() for n in names], axis=1)
    rho = stats.spearmanr(x).statistic
    return np.atleast_2d(rho)


def _plot_correlations(rho, names, out: Path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(8.5, 7.5))
    im = ax.imshow(rho, vmin=-1, vmax=1, cmap="RdBu_r")
    # Long names (a conductivity shared by two scenes) on two lines, so none is cut off.
    labels = [n.replace("[", "\n[") if len(n) > 28 else n for n in names]
    ax.set_xticks(range(len(names)), labels, rotation=90, fontsize=7)
    ax.set_yticks(range(len(names)), labels, fontsize=7)
    for i in range(len(names)):
        for j in range(len(names)):
            if i != j and abs(rho[i, j]) >= 0.3:
                ax.text(j, i, f"{rho[i, j]:.1f}", ha="center", va="center", fontsize=6)
    fig.colorbar(im, ax=ax, label="posterior Spearman rank correlation")
    fig.suptitle("What the drops cannot separate: pairwise posterior rank correlations "
                 "(|rho| >= 0.3 printed)", fontsize=9)
    fig.tight_layout()
    fig.savefig(out, dpi=DPI)
    plt.close(fig)


def write_calibration_report(path: Path, out: Path) -> list[str]:
    """Write the report of the calibration result `path` into folder `out`; returns the lines
    printed (H50 per target against the experiments)."""
    from skidmc.analysis.calibration import diagnostic_lines

    out.mkdir(parents=True, exist_ok=True)
    idata, curves, summary = _load(path)
    params = summary["parameters"]
    names = [p["name"] for p in params]
    _plot_prior_posterior(idata, params, out / "prior_posterior.png")
    _plot_go_curves(idata, curves, summary, out / "go_curves.png")
    _plot_h50(idata, summary, out / "h50.png")
    rho = _correlations(idata, names)
    _plot_correlations(rho, names, out / "correlations.png")

    attrs = idata.attrs
    md = [f"# Calibration {attrs['study_name']}", "",
          f"skidmc {attrs['skidmc_version']}, completed {attrs['completed']}, sampler seed "
          f"{attrs['sampler_seed']}, surrogate seed {attrs['surrogate_seed']}; posterior: "
          f"`{path.name}` (ArviZ InferenceData; the study texts in its attributes). Method and "
          "sources: docs/calibration.md.", ""]
    md += ["## Assumptions", ""] + [f"- {a}" for a in _assumptions(summary, attrs)] + [""]
    md += ["## Sampler diagnostics", "", "```"] + diagnostic_lines(summary["diagnostics"]) + [
        "```", "", f"Mean acceptance fraction {summary['acceptance']:.2f}.", ""]
    md += ["## Prior and posterior of every input (median [5 %, 95 %])", "",
           "| parameter | unit | prior | posterior | posterior sd / prior sd |",
           "|---|---|---|---|---|"]
    for p in params:
        pr, po = _q(idata.prior[p["name"]]), _q(idata.posterior[p["name"]])
        ratio = float(np.std(idata.posterior[p["name"]].values)
                      / np.std(idata.prior[p["name"]].values))
        md.append(f"| {p['name']} | {p['unit'] or '-'} | {_fmt(pr[1])} [{_fmt(pr[0])}, "
                  f"{_fmt(pr[2])}] | {_fmt(po[1])} [{_fmt(po[0])}, {_fmt(po[2])}] | "
                  f"{ratio:.2f} |")
    md += ["", "Factors (unit 1) multiply the scene's nominal value (docs/inputs.md); "
           "`mu[...]` is the factor on the finish's measured mean friction.", "",
           "![prior and posterior](prior_posterior.png)", ""]
    md += ["## Posterior H50 per target against the experiments (Table II)", "",
           "| target | prior H50 [ft] (90 %) | posterior H50 [ft] (90 %) | experiment [ft] | "
           "inside the posterior 90 %? |", "|---|---|---|---|---|"]
    printed = []
    for t, exp in summary["experiments"].items():
        q = _q(idata.posterior_predictive[f"h50[{t}]"])
        p = summary["prior_h50_ft"][t]
        h, qual = _experimental(exp)
        shown = f"> {h:g}" if qual == "lower_bound" else (f"~ {h:g}" if qual == "approximate"
                                                          else f"{h:g}")
        inside = (q[2] > h) if qual == "lower_bound" else (q[0] <= h <= q[2])
        md.append(f"| {t} | {_fmt(p[1])} [{_fmt(p[0])}, {_fmt(p[2])}] | {_fmt(q[1])} "
                  f"[{_fmt(q[0])}, {_fmt(q[2])}] | {shown} ({qual}) | "
                  f"{'yes' if inside else 'NO'} |")
        printed.append(f"{t}: posterior H50 {_fmt(q[1])} ft (90 % {_fmt(q[0])} to "
                       f"{_fmt(q[2])}); experiment {shown} ft")
    md += ["", "![H50](h50.png)", "", "![go curves](go_curves.png)", "",
           "Posterior predictive P(go | H): the mean over posterior draws of eq. (1) (aleatory "
           "friction, flow stress, temperature, mass and angle integrated; the target's "
           "discrepancy included; misclassification not applied); the bands are the 5-95 % "
           "range of P(go | H, theta) over the draws. Points: the report's drops at each "
           "height, goes/drops.", ""]
    cv = summary["cross_validation"]
    if cv:
        md += ["## Cross-validation: one target left out", "",
               "Calibrated on the other targets' drops, the left-out target's drops predicted "
               "(its discrepancy from its prior). Mean log score per drop [nats] (higher is "
               "better; a coin flip scores ln 0.5 = -0.693) and Brier score (lower is better; "
               "a coin flip 0.25). Base rate: the training drops' fraction of goes.", "",
               "| left out | drops (goes) | log: posterior | prior | base rate | coin | "
               "Brier: posterior | prior | base rate | coin | verdict (log score) |",
               "|---|---|---|---|---|---|---|---|---|---|---|"]
        for r in cv:
            verdict = _cv_verdict(r)
            md.append(f"| {r['target']} | {r['drops']} ({r['goes']}) | "
                      f"{r['log_posterior']:.3f} | {r['log_prior']:.3f} | "
                      f"{r['log_base_rate']:.3f} | {r['log_coin']:.3f} | "
                      f"{r['brier_posterior']:.3f} | {r['brier_prior']:.3f} | "
                      f"{r['brier_base_rate']:.3f} | {r['brier_coin']:.3f} | {verdict} |")
        md.append("")
    preds = summary["predictions"]
    if preds:
        md += ["## The second series predicted from the first's posterior (Table IX)", "",
               "The second series used other billets (sensitive-pole billets, flow stress "
               "34,400 psi against the first's 28,000 psi; paper-series2.toml and "
               "docs/inputs.md) on quartz of five finishes. Shared inputs (kinetics, PBX 9404 "
               "properties, quartz conductivity) from the first series' posterior; each "
               "finish's mean friction from its Table I measurement and the posterior friction "
               "population; a new discrepancy from its prior (an unseen target); the second "
               "series' own flow stress and billet.", "",
               "| finish | mu measured | predicted H50 [ft] (90 %) | experiment [ft] | "
               "inside? |", "|---|---|---|---|---|"]
        for r in preds:
            q = r["h50_ft"]
            md.append(f"| {r['scene']} | {r['mu_measured']:g} | {_fmt(q[1])} [{_fmt(q[0])}, "
                      f"{_fmt(q[2])}] | {r['experimental_h50_ft']:g} | "
                      f"{'yes' if r['inside_90'] else 'NO'} |")
        n_in = sum(r["inside_90"] for r in preds)
        outside = [r["scene"] for r in preds if not r["inside_90"]]
        md += ["", f"{n_in} of {len(preds)} experimental H50 inside the 90 % band."
               + (f" Outside: {', '.join(outside)}: there the model, as calibrated on the "
                  "first series, has no skill; what it may lack there: the report itself names "
                  "machining of the billet by the roughest finish, and the model's friction is "
                  "one coefficient per finish, not the asperities' plowing." if outside else ""),
               ""]
    md += ["## Pairwise posterior correlations", "",
           "Pairs with |Spearman rho| >= 0.3 (what the drops cannot separate: a change of one "
           "is traded against the other):", ""]
    pairs = [(names[i], names[j], rho[i, j]) for i in range(len(names))
             for j in range(i + 1, len(names)) if abs(rho[i, j]) >= 0.3]
    md += [f"- {a} and {b}: {r:+.2f}" for a, b, r in sorted(pairs, key=lambda x: -abs(x[2]))]
    md += (["- none"] if not pairs else []) + ["", "![correlations](correlations.png)", ""]
    md += _hazard_section(path, attrs)
    md += ["## Numerical checks", "",
           "| target | surrogate keys | rmse ln H_c training | held out | at posterior draws "
           "(solver) | largest there | folded aleatory sd |", "|---|---|---|---|---|---|---|"]
    for t, s in summary["surrogates"].items():
        if t not in summary["experiments"]:
            continue
        c = summary["surrogate_check"].get(t, {})
        md.append(f"| {t} | {len(s['keys'])} | {s['rmse_train']:.4f} | "
                  f"{s['rmse_holdout']:.4f} | {c.get('rmse', float('nan')):.4f} "
                  f"({c.get('draws', 0)} draws) | {c.get('max_abs', float('nan')):.4f} | "
                  f"{summary['folded_sd'][t]:.4f} |")
    qe = summary["quadrature_error"]
    cost = summary["cost"]
    md += ["", f"Quadrature, nodes doubled at 200 posterior draws: largest |Delta P(go)| "
           f"{qe['max_abs_dp']:.2e}, largest |Delta ln L| {qe['max_abs_dloglik']:.2e}.", "",
           f"Cost: {cost['solver_runs']} solver runs ({cost['solver_minutes']:.2f} min), "
           f"sampling {cost['sampling_minutes']:.2f} min ({cost['log_posterior_evaluations']} "
           f"posterior evaluations), {cost['minutes']:.2f} min in all (a shared 2-core machine: "
           "noisy).", ""]
    (out / "summary.md").write_text("\n".join(md) + "\n")
    return printed


def _cv_verdict(r: dict) -> str:
    """The cross-validation row's verdict on the log score: against the prior, then skill as in
    the go-curve reports (:mod:`skidmc.analysis.skill`): better than both the base rate and a
    coin flip, else "no skill" naming what it does not beat; not measurable where every drop
    had the same outcome."""
    gain = r["log_posterior"] - r["log_prior"]
    verdict = ("better than the prior" if gain > 0.005 else
               "worse than the prior" if gain < -0.005 else "as the prior")
    lost = [w for w, key in (("the base rate", "log_base_rate"), ("a coin flip", "log_coin"))
            if not r["log_posterior"] > r[key]]
    if r["goes"] in (0, r["drops"]):
        return verdict + "; skill not measurable (every drop had the same outcome)"
    if not lost:
        return verdict + "; skill (beats the base rate and a coin flip)"
    return verdict + "; **no skill**: not better than " + " or ".join(lost)


def _hazard_studies(attrs) -> list[Path]:
    """Hazard study files beside the calibration study whose ``[hazard.posterior]`` names it."""
    import tomllib

    file = Path(attrs.get("study_file", ""))
    if not file.is_file():
        return []
    found = []
    for candidate in sorted(file.parent.glob("*.toml")):
        try:
            doc = tomllib.loads(candidate.read_text(encoding="utf-8"))
            named = doc["hazard"]["posterior"]["calibration"]
        except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError, KeyError, TypeError):
            continue
        if (candidate.parent / named).resolve() == file.resolve():
            found.append(candidate)
    return found


def _hazard_section(path: Path, attrs) -> list[str]:
    """What the posterior does to the handling hazard: the summary of each hazard study that
    takes its draws from this posterior (``[hazard.posterior]``), or the command that makes it."""
    import hashlib

    import tomllib

    md = ["## What the posterior does to the handling hazard", ""]
    studies = _hazard_studies(attrs)
    if not studies:
        return md + ["No hazard study beside this calibration's study names it in "
                     "`[hazard.posterior]` (docs/rare-events.md, \"The handling study under a "
                     "calibration's posterior\").", ""]
    sha = hashlib.sha256(path.read_bytes()).hexdigest()
    for study in studies:
        name = tomllib.loads(study.read_text(encoding="utf-8"))["hazard"]["name"]
        summary = Path("results") / name / "summary.json"
        command = f"`skidmc run {study} --force`"
        try:
            data = json.loads(summary.read_text(encoding="utf-8"))
            post = data["posterior"]
        except (OSError, ValueError, KeyError):
            md += [f"- `{study.name}`: not run yet; {command} computes it (about 20 minutes "
                   f"on two cores) and writes `{summary}`, which this report then reads.", ""]
            continue
        if post.get("sha256") != sha:
            md += [f"- `{study.name}`: `{summary}` was computed from another posterior than "
                   f"this one; {command} recomputes it.", ""]
            continue
        prior, pooled = post["prior"]["study"], post["prior"]["pooled"]
        lo, hi = post["interval"]
        prior_band = (f"[{prior['band'][0]:.3g}, {prior['band'][1]:.3g}]"
                      if prior.get("status") == "found" else prior.get("status", "?"))
        md += [f"From `{summary}` (`{study.name}`: the hazard with its epistemic inputs, "
               f"{', '.join(post['keys'])}, held at {post['draws']} equally spaced draws of "
               "this posterior; the model discrepancy, a factor on the report's targets' H_c, "
               "is not carried to the hazard's floors):", "",
               "| P per accident | mean | 95 % interval | epistemic 5-95 % |",
               "|---|---|---|---|",
               f"| over the priors (pooled) | {pooled['probability']:.3g} | "
               f"[{pooled['interval'][0]:.3g}, {pooled['interval'][1]:.3g}] | {prior_band} |",
               f"| under this posterior (mean over its draws) | {post['probability']:.3g} | "
               f"[{lo:.3g}, {hi:.3g}] | [{post['band'][0]:.3g}, {post['band'][1]:.3g}] |", ""]
    return md


def _assumptions(summary, attrs) -> list[str]:
    import tomllib

    doc = tomllib.loads(attrs["study_text"])["calibration"]
    out = [
        "Priors: the epistemic inputs of the prior study as written there (their sources in "
        "docs/inputs.md), sampled as normal scores; a parameter is shared by the scenes whose "
        "distributions of its key agree.",
        "Data: the report's drops (Tables III, IV without drop 7, the gold no-gos at 25-150 ft "
        "without the missed drop), the friction measurement of each finish (the prior study's "
        "epistemic friction: measured mean and log-sd of that mean, Tables I and V) and the "
        "series' flow stress (the scenes' nominal, Sec. IV) with its billet-to-billet spread.",
        "Likelihood: P(go | H, theta) with the aleatory friction factor integrated by "
        "quadrature ("
        + ", ".join(f"{n} nodes over the normal score of {k}" for k, n in
                    doc["quadrature"].items())
        + ") and the other aleatory "
        "inputs folded in linearly as a normal kernel (docs/calibration.md).",
        f"Model discrepancy (Kennedy-O'Hagan): ln H_c + delta_t per target, delta_t ~ N(0, "
        f"{doc['discrepancy_sd']}^2 + surrogate rmse^2): {doc['discrepancy_source']}.",
        f"Misclassification probability {doc.get('misclassification', 0)}: "
        f"{doc.get('misclassification_source', '')}.",
        "Surrogate: a quadratic least-squares polynomial of ln H_c in standardized "
        "(log-)inputs per scene, trained on solver runs over the prior's normal scores on "
        "[-3, 3]; its held-out error enters the discrepancy's variance.",
        "Sampler: emcee's ensemble sampler with differential-evolution and snooker moves, "
        "the snooker move corrected as in emcee PR #531 (3.1.6's leaves posteriors ~10 % too "
        "narrow: docs/calibration.md); walkers as chains for ArviZ's R-hat.",
    ]
    # The prior study's own judgements (its [study] assumptions) are this calibration's too.
    prior_doc = tomllib.loads(attrs.get("prior_study_text", "") or "")
    out += [f"From the prior study: {a.strip()}"
            for a in (prior_doc.get("study") or {}).get("assumptions", [])]
    own = tomllib.loads(attrs["study_text"]).get("study", {}).get("assumptions", [])
    out += [a.strip() for a in own]
    pop = doc.get("friction_population")
    if pop:
        out.append(f"Friction population: ln mu_f ~ N(m, tau^2), m ~ N(ln {pop['median']}, "
                   f"{pop['median_log_sd']}^2), ln tau ~ N(ln {pop['sd']}, "
                   f"{pop['sd_log_sd']}^2); other finishes from {pop.get('other_finishes_from')}"
                   f" (not {', '.join(pop.get('exclude', [])) or '-'}): {pop['source']}.")
    return out
