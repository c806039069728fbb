"""Integrated autocorrelation time of the calibration's sampler, per move set.

    python scripts/calibration_autocorrelation.py [--steps 5000] [--walkers 48]

writes ``results/validation/calibration_autocorrelation.md``.

The model is the shipped calibration's (``studies/calibration-series1.toml``: the report's drops,
17 parameters with the friction population) with the forward model replaced by quadratic
surrogates of ln H_c fitted to the shipped first-series ensemble (as
``scripts/calibration_validation.py`` does; no solver run), and 16 quadrature nodes of the
friction factor instead of the study's 64 (for speed: the sampler's mixing, not the
quadrature's accuracy, is measured). Three move sets, each from the same prior draws and seed:

* the shipped one (:func:`skidmc.analysis.calibration.run_emcee`): differential evolution 80 %
  and the corrected snooker move 20 %;
* the same with emcee 3.1.6's own snooker move (what the figures of docs/calibration.md were
  first measured with);
* emcee's default stretch move.

The integrated autocorrelation time is emcee's estimate (``emcee.autocorr.integrated_time``,
Sokal's window c = 5) on the chain after the burn-in, per parameter; the median and the largest
over the parameters are reported.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]


def calibration_model(nodes):
    """The calibration-series1 model (with its friction population) on surrogates."""
    sys.path.insert(0, str(ROOT / "scripts"))
    from calibration_validation import surrogate_model

    return surrogate_model(nodes, population=True)


def move_sets():
    import emcee

    from skidmc.analysis.calibration import _snooker_move

    return {
        "differential evolution 80 % + corrected snooker 20 % (shipped)":
            lambda: [(emcee.moves.DEMove(), 0.8), (_snooker_move(), 0.2)],
        "differential evolution 80 % + emcee 3.1.6 snooker 20 %":
            lambda: [(emcee.moves.DEMove(), 0.8), (emcee.moves.DESnookerMove(), 0.2)],
        "stretch (emcee's default)": lambda: None,
    }


def measure(model, moves, walkers, burn, steps, seed):
    import emcee

    rng = np.random.default_rng(seed)
    p0 = rng.standard_normal((walkers, model.ndim))
    sampler = emcee.EnsembleSampler(walkers, model.ndim, model.log_posterior, vectorize=True,
                                    moves=moves)
    sampler._random = np.random.mtrand.RandomState(seed)
    t0 = time.perf_counter()
    sampler.run_mcmc(p0, burn + steps, progress=False)
    seconds = time.perf_counter() - t0
    tau = emcee.autocorr.integrated_time(sampler.get_chain(discard=burn), quiet=True)
    return tau, float(np.mean(sampler.acceptance_fraction)), seconds


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--walkers", type=int, default=48)
    ap.add_argument("--burn", type=int, default=1000)
    ap.add_argument("--steps", type=int, default=5000)
    ap.add_argument("--nodes", type=int, default=16)
    ap.add_argument("--seed", type=int, default=40)
    ap.add_argument("--out", default=str(ROOT / "results" / "validation"))
    args = ap.parse_args(argv)
    model = calibration_model(args.nodes)
    names = [p.name for p in model.parameters]
    rows = []
    for label, make in move_sets().items():
        tau, acceptance, seconds = measure(model, make(), args.walkers, args.burn, args.steps,
                                           args.seed)
        worst = names[int(np.argmax(tau))]
        rows.append((label, float(np.median(tau)), float(np.max(tau)), worst, acceptance,
                     seconds))
        print(f"{label}: median {np.median(tau):.0f}, max {np.max(tau):.0f} ({worst}); "
              f"acceptance {acceptance:.2f}; {seconds:.0f} s", file=sys.stderr)
    lines = ["# Calibration sampler: integrated autocorrelation time per move set", "",
             f"Written by `python scripts/calibration_autocorrelation.py` (--walkers "
             f"{args.walkers} --burn {args.burn} --steps {args.steps} --nodes {args.nodes} "
             f"--seed {args.seed}). The shipped calibration's model ({model.ndim} parameters, "
             "the report's drops, the friction population) with surrogates of ln H_c fitted to "
             "the shipped paper-series1 ensemble standing in for the solver, and "
             f"{args.nodes} quadrature nodes of the friction factor. Each move set starts from "
             "the same prior draws with the same seed. Autocorrelation time: "
             "`emcee.autocorr.integrated_time` on the chain after the burn-in, per parameter "
             "[steps]; fewer steps mean more independent draws per step.", "",
             "| moves | median over parameters [steps] | largest [steps] | its parameter | "
             "acceptance | time [s] |", "|---|---|---|---|---|---|"]
    for label, med, top, worst, acc, sec in rows:
        lines.append(f"| {label} | {med:.0f} | {top:.0f} | {worst} | {acc:.2f} | {sec:.0f} |")
    shipped, _old, stretch = rows
    lines += ["", f"The shipped moves mix {stretch[1] / shipped[1]:.1f}x faster than the stretch "
              "move (median over parameters), "
              f"{stretch[2] / shipped[2]:.1f}x for the slowest parameter. "
              f"The {args.steps} steps hold {args.steps / shipped[2]:.0f} or more "
              "autocorrelation times of the shipped moves (emcee asks for 50 before trusting "
              f"the estimate), {args.steps / stretch[2]:.0f} of the stretch move's (its times "
              "are the less certain).", "",
              "The shipped run (`studies/calibration-series1.toml`: 1500 burn-in steps, 12,000 "
              f"kept, thinned by 40) burns in {1500 / shipped[2]:.0f} of the shipped moves' "
              f"largest autocorrelation times and keeps {12000 / shipped[2]:.0f}; its R-hat and "
              "ESS, printed in its summary, are the check on the run itself.", ""]
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "calibration_autocorrelation.md").write_text("\n".join(lines))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
