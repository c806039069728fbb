"""Validation of the calibration (issue 40 E): simulation-based calibration and recovery.

    python scripts/calibration_validation.py [--replications 100] [--out results/validation]

writes ``calibration_sbc.md`` (and ``calibration_sbc.png``, the rank histograms) there.

The forward model is the calibration's own likelihood with surrogates of ln H_c standing in
for the solver: quadratic least-squares polynomials fitted to the shipped first-series ensemble
(``results/paper-series1/ensemble.h5``, 4 scenes x 10,000 solver runs; no new solver run), the
friction factor integrated by the quadrature with fewer nodes than the shipped study (8 by
default, for speed: SBC tests the sampler and the likelihood's code, for which the simulating
and the fitting model must only agree; the quadrature's own accuracy is measured by doubling in
every run of the kind). The
model has no friction population (SBC needs the prior to be the N(0, 1) the scores are drawn
from), and the same drop heights as the report's (Tables III, IV, the gold no-gos).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]


def sbc_model(nodes: int = 8):
    """The calibration-series1 model (no population) on surrogates fitted to the shipped
    ensemble."""
    return surrogate_model(nodes, population=False)


def surrogate_model(nodes: int, population: bool):
    """The calibration-series1 model on surrogates of ln H_c fitted to the shipped
    paper-series1 ensemble, ``nodes`` quadrature nodes of the friction factor, with or without
    the study's friction population."""
    import skidmc
    from skidmc.analysis.calibration import FEATURE_TRANSFORMS, fit_surrogate
    from skidmc.workflows.calibration import _model, load

    study = load(ROOT / "studies" / "calibration-series1.toml")
    ds = skidmc.open_ensemble(ROOT / "results" / "paper-series1" / "ensemble.h5")
    surrogates = {}
    for sc in study.prior.scenes:
        d = ds.sel(scene=sc.name)
        surrogates[sc.name] = fit_surrogate(
            {k: d[k].values.ravel() for k in FEATURE_TRANSFORMS if k in d},
            np.log(d["critical_height"].values.ravel()), seed=1)
    spec = study.spec.model_copy(deep=True)
    if not population:
        spec.calibration.friction_population = None
    spec.calibration.quadrature = {k: nodes for k in spec.calibration.quadrature}
    study = dataclasses.replace(study, spec=spec, others=())
    return _model(study, surrogates)


def main(argv=None) -> int:
    from skidmc.analysis.calibration import rank_uniformity, recovery, sbc_rank_sets
    from skidmc.scene.units import FOOT

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--replications", type=int, default=100)
    ap.add_argument("--draws", type=int, default=99, help="posterior draws ranked against")
    ap.add_argument("--walkers", type=int, default=36)
    ap.add_argument("--burn", type=int, default=300)
    ap.add_argument("--steps", type=int, default=600)
    ap.add_argument("--nodes", type=int, default=8, help="quadrature nodes of the friction")
    ap.add_argument("--seed", type=int, default=2018)
    ap.add_argument("--out", default=str(ROOT / "results" / "validation"))
    ap.add_argument("--recovery-only", action="store_true",
                    help="redo the recovery only, keeping the SBC ranks of the last full run")
    ap.add_argument("--figure-only", action="store_true",
                    help="redraw calibration_sbc.png from the kept ranks, nothing recomputed")
    args = ap.parse_args(argv)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)

    model = sbc_model(args.nodes)
    kept = out / "calibration_sbc.json"
    if args.figure_only:
        old = json.loads(kept.read_text())
        _figure(old["ranks"], [p.name for p in model.parameters], old["settings"]["draws"],
                old["settings"]["replications"], out)
        return 0
    if args.recovery_only:  # the SBC ranks of the last full run, with its settings
        old = json.loads(kept.read_text())
        ranks, sbc_minutes = np.asarray(old["ranks"]), old["sbc_minutes"]
        spread = np.asarray(old["ranks_spread"])
        for key, value in old["settings"].items():
            setattr(args, key, value)
    else:
        t0 = time.perf_counter()
        sets = sbc_rank_sets(model, args.replications, draws=args.draws, walkers=args.walkers,
                             burn=args.burn, steps=args.steps, seed=args.seed,
                             picks=("separated", "spread"),
                             progress=lambda r: print(f"SBC replication {r}", file=sys.stderr)
                             if r % 10 == 0 else None)
        ranks, spread = sets["separated"], sets["spread"]
        sbc_minutes = (time.perf_counter() - t0) / 60
    test = rank_uniformity(ranks, args.draws, bins=10)
    test_spread = rank_uniformity(spread, args.draws, bins=10)
    t0 = time.perf_counter()
    z_true = np.random.default_rng(args.seed + 1).standard_normal(model.ndim)
    rec = recovery(model, z_true, repeats=(1, 10), walkers=args.walkers, burn=2 * args.burn,
                   steps=3 * args.steps, seed=args.seed + 2)
    rec_minutes = (time.perf_counter() - t0) / 60

    lines = ["# Calibration: simulation-based calibration and recovery", "",
             "Written by `python scripts/calibration_validation.py` "
             f"(--replications {args.replications} --draws {args.draws} --walkers "
             f"{args.walkers} --burn {args.burn} --steps {args.steps} --nodes {args.nodes} "
             f"--seed {args.seed}). "
             "Forward model: the calibration's likelihood with quadratic surrogates of ln H_c "
             "fitted to the shipped paper-series1 ensemble standing in for the solver, "
             f"{args.nodes} quadrature nodes, no friction population (its prior must be the "
             "N(0, 1) the true scores are drawn from), the report's drop heights (docstring of "
             "the script).",
             "", "## Simulation-based calibration (Talts et al. 2018)", "",
             f"{args.replications} replications: scores drawn from the prior, drops simulated, "
             f"the posterior sampled by emcee ({args.walkers} walkers, {args.burn} + "
             f"{args.steps} steps; differential-evolution moves with the corrected snooker "
             "move, below), the rank of each true score among "
             f"{args.draws} posterior draws taken as whole ensembles of walkers at steps "
             "spaced evenly over the kept chain (`separated`: "
             "skidmc.analysis.calibration.SBC_PICKS); ranks binned in 10 bins, chi-square "
             f"against uniform. {sbc_minutes:.1f} min on two shared cores.", "",
             "| parameter | chi2 (9 dof) | p |", "|---|---|---|"]
    for p, (chi2, pv) in zip(model.parameters, test["per_parameter"]):
        lines.append(f"| {p.name} | {chi2:.1f} | {pv:.3f} |")
    chi2, dof, pv = test["pooled"]
    chi2_s, _, pv_s = test_spread["pooled"]
    outer = int(((ranks // ((args.draws + 1) // 10)) % 9 == 0).sum())
    outer_s = int(((spread // ((args.draws + 1) // 10)) % 9 == 0).sum())
    lines += ["", f"Pooled over the {model.ndim} parameters: **chi2 = {chi2:.1f} on {dof} dof, "
              f"p = {pv:.3f}** (the parameters' ranks taken as independent; a null with the "
              "ranks' own cross-parameter correlation, simulated through a Gaussian copula, "
              "gave the same spread, sd 16.5 against chi-square's 16.4). Smallest "
              f"per-parameter p x {model.ndim} (Bonferroni): {test['min_p_bonferroni']:.3f}.",
              "", "![rank histograms](calibration_sbc.png)", "",
              "### What moved the statistic (same seeds, same simulated drop sets)", "",
              "The earlier run (p = 0.012) had the truths' ranks piling in the outer bins "
              "(356 of 1500 in the lowest and highest tenth, 300 expected): draws too "
              "narrow or too correlated. Its 300-step burn-in from prior draws was not the "
              "cause: on three of its replications a run of 3000 + 3000 steps gave the same "
              "posterior (sd ratios 0.94-1.07, means within 0.13 sd; autocorrelation time "
              "31 steps, so 300 steps are 10 of them). Two causes were: emcee 3.1.6's snooker "
              "move, which leaves the spread too narrow (on a 15-dimensional Gaussian the "
              "80/20 mixture's draws have sd 0.895 of the true, corrected 0.998; on a "
              "2-parameter version of this model against its grid posterior, 0.956 and "
              "0.998; results/validation/calibration_sampler_check.md), and the draws "
              "ranked against, taken 6 steps apart in neighbouring walkers (correlated).", "",
              "| sampler | draws ranked against | pooled chi2 (135 dof) | p | ranks in the "
              "outer bins (300 expected) |", "|---|---|---|---|---|",
              "| emcee 3.1.6 snooker (earlier run) | spread over the chain | 174.6 | 0.012 | "
              "356 |",
              "| emcee 3.1.6 snooker (same chains) | separated ensembles | 162.6 | 0.053 | "
              "346 |",
              f"| corrected snooker (this run) | spread over the chain | {chi2_s:.1f} | "
              f"{pv_s:.3f} | {outer_s} |",
              f"| corrected snooker (this run) | separated ensembles | {chi2:.1f} | {pv:.3f} | "
              f"{outer} |", "",
              "The two earlier rows were measured before the fix (emcee's own "
              "DESnookerMove; same seeds; the first is the stored run, reproduced rank for "
              "rank); this script now runs the corrected move only.", "",
              "## Recovery", "",
              "Drops simulated at one set of true scores (a prior draw, seed "
              f"{args.seed + 1}), at the report's heights shifted in ln H to centre on each "
              "target's true H50 (as an experimenter bracketing it would place them; at the "
              "report's own heights a prior draw's H50 can lie far from every drop, which then "
              "says little), as many drops as the report (1x) and each drop made ten times "
              f"(10x); emcee {args.walkers} walkers, {2 * args.burn} + {3 * args.steps} "
              f"steps. {rec_minutes:.1f} min.", "",
              "| target | true H50 [ft] | 1x: median [ft], sd ln H50, in 95 %? | 10x: median "
              "[ft], sd ln H50, in 95 %? |", "|---|---|---|---|"]
    ft = FOOT  # [m/ft]
    for name in rec[0]["targets"]:
        a, b = rec[0]["targets"][name], rec[1]["targets"][name]
        lines.append(f"| {name} | {np.exp(a['true']) / ft:.3g} | {np.exp(a['median']) / ft:.3g}"
                     f", {a['sd']:.3f}, {'yes' if a['inside_95'] else 'NO'} | "
                     f"{np.exp(b['median']) / ft:.3g}, {b['sd']:.3f}, "
                     f"{'yes' if b['inside_95'] else 'NO'} |")
    misses = {row["repeat"]: [n for n, t in row["targets"].items() if not t["inside_95"]]
              for row in rec}
    lines += ["", "Verdict: " + "; ".join(
        f"{k}x: the truth outside the 95 % interval for {', '.join(v) if v else 'no target'}"
        for k, v in misses.items())
        + ". Four 95 % intervals miss twice or more with probability 1.4 % (the earlier run, "
        "with emcee 3.1.6's snooker move and the ensemble before the temperature tables, missed "
        "two at 1x)."]
    lines += ["", "Posterior sd of each normal score (the prior's is 1):", "",
              "| parameter | 1x | 10x |", "|---|---|---|"]
    for p in model.parameters:
        lines.append(f"| {p.name} | {rec[0]['score_sd'][p.name]:.2f} | "
                     f"{rec[1]['score_sd'][p.name]:.2f} |")
    (out / "calibration_sbc.md").write_text("\n".join(lines) + "\n")
    settings = {k: getattr(args, k) for k in ("replications", "draws", "walkers", "burn",
                                                "steps", "nodes", "seed")}
    kept.write_text(json.dumps({"ranks": ranks.tolist(), "ranks_spread": spread.tolist(),
                                "settings": settings,
                                "sbc_minutes": sbc_minutes, "uniformity": test,
                                "uniformity_spread": test_spread,
                                "recovery": rec}))

    _figure(ranks, [p.name for p in model.parameters], args.draws, args.replications, out)
    print(out / "calibration_sbc.md")
    print(f"pooled chi2 {chi2:.1f} on {dof} dof, p = {pv:.3f}")
    return 0


def _figure(ranks, names, draws, replications, out):
    """The rank histograms (``calibration_sbc.png``); ``--figure-only`` redraws them from the
    kept ranks without rerunning the replications."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    ranks = np.asarray(ranks)
    cols = 6
    rows = (len(names) + cols - 1) // cols
    fig, axes = plt.subplots(rows, cols, figsize=(13, 2.2 * rows))
    width = (draws + 1) // 10
    for ax, name, j in zip(axes.ravel(), names, range(len(names))):
        ax.hist(ranks[:, j] // width, bins=np.arange(11) - 0.5, color="C0")
        ax.axhline(replications / 10, color="k", lw=0.8)
        # Long names (a conductivity shared by two scenes) on two lines, not over a neighbour.
        ax.set_title(name.replace("[", "\n[") if len(name) > 28 else name, fontsize=7)
        ax.set_xticks(range(10))
        ax.set_xlabel("rank bin (0: lowest tenth)", fontsize=6)
        if j % cols == 0:
            ax.set_ylabel("truths in the bin", fontsize=6)
        ax.tick_params(labelsize=6)
    for ax in axes.ravel()[len(names):]:
        ax.axis("off")
    fig.suptitle(f"SBC: rank of each true parameter among {draws} posterior draws, 10 bins, "
                 f"{replications} replications (line: the count expected if uniform)", fontsize=9)
    fig.tight_layout()
    fig.savefig(Path(out) / "calibration_sbc.png", dpi=110)


if __name__ == "__main__":
    sys.exit(main())
