"""The first series' calibration: solver runs and minutes (issue 40 D: at most 15 minutes on the
project's 2-core machine).

Runs ``studies/calibration-series1.toml`` as ``skidmc run`` does (its kind's ``run``), into a
temporary folder (the shipped result is left alone), with 2 worker processes, and reads the
cost the run records: solver runs (surrogate training of the first series' 4 scenes and of the
second series' 5 predicted scenes, and the check at posterior draws) with their minutes, the
sampling's minutes and posterior evaluations, and the whole run's minutes (cross-validation,
predictions and writing included). Also the time of one posterior evaluation of the 48
walkers, and what the same evaluation would cost with the full-tier solver in the loop (heights
per evaluation x the measured seconds per solver run).

Minutes are wall time on this machine: 2 cores shared with other work, so noisy; count the
solver runs first.

Writes ``results/benchmarks/calibration.md``.

Usage::

    python benchmarks/calibration.py                      # a fresh run (~15 min)
    python benchmarks/calibration.py --result results/calibration-series1/posterior.nc
        # the costs a finished run recorded (the shipped one: skidmc run, 2 workers)
"""

from __future__ import annotations

import json
import os
import platform
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]


def main(argv=None) -> int:
    import argparse

    import xarray as xr

    from skidmc.workflows.calibration import _drops, load, run
    from skidmc.workflows.registry import RunOptions

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--result", help="tabulate the costs this finished run recorded instead")
    args = ap.parse_args(argv)
    study = load(ROOT / "studies" / "calibration-series1.toml")
    if args.result:
        attrs = xr.open_dataset(args.result, engine="h5netcdf").attrs
        summary = json.loads(attrs["summary"])
        wall = summary["cost"]["minutes"]
        how = (f"the costs recorded by the run that wrote `{args.result}` (command "
               f"`{attrs.get('command') or 'skidmc run'}`, completed {attrs['completed']})")
    else:
        with tempfile.TemporaryDirectory() as tmp:
            out = Path(tmp) / "posterior.nc"
            t0 = time.perf_counter()
            outcome = run(study, RunOptions(out=str(out), workers=2, force=True,
                                            log=lambda line: print(line, file=sys.stderr)))
            wall = (time.perf_counter() - t0) / 60
            if outcome.status:
                print("\n".join(outcome.lines), file=sys.stderr)
                return outcome.status
            summary = json.loads(xr.open_dataset(out, engine="h5netcdf").attrs["summary"])
        how = "a fresh run into a temporary folder, 2 workers"
    cost = summary["cost"]
    c = study.spec.calibration
    n_drops = sum(len(h) for h, _ in _drops(study.prior).values())
    per_run = cost["solver_minutes"] * 60 / max(cost["solver_runs"], 1)
    heights_per_eval = c.sampler.walkers * len(study.prior.scenes) * c.quadrature["mu"]
    lines = [
        "# Calibration of the first series: cost", "",
        f"`python benchmarks/calibration.py{' --result ' + args.result if args.result else ''}`"
        f": `studies/calibration-series1.toml`, {how}. Machine: {platform.machine()}, "
        f"{os.cpu_count()} CPUs (shared with other work: minutes are noisy). Target: at most "
        "15 minutes.", "",
        "| quantity | value |", "|---|---|",
        f"| whole run (training, sampling, checks, cross-validation, prediction, writing) | "
        f"{wall:.1f} min |",
        f"| solver runs (full tier, rtol {study.prior.solver.rtol:g}) | {cost['solver_runs']} |",
        f"| of which surrogate training | {c.surrogate.runs} per scene x "
        f"{len(study.prior.scenes) + (len(study.predict.scenes) if study.predict else 0)} "
        "scenes |",
        f"| of which checks at posterior draws | {c.surrogate.check_draws} per first-series "
        "scene |",
        f"| solver minutes (2 workers) | {cost['solver_minutes']:.1f} |",
        f"| wall seconds per solver run (2 workers) | {per_run:.4f} |",
        f"| sampling minutes ({c.sampler.walkers} walkers x {c.sampler.burn + c.sampler.steps} "
        f"steps) | {cost['sampling_minutes']:.1f} |",
        f"| posterior evaluations in the main chain | {cost['log_posterior_evaluations']} |",
        f"| cross-validation: runs of {c.sampler.burn // 2} + {c.sampler.cv_steps} steps | "
        f"{len(summary['cross_validation'])} |",
        f"| drops in the likelihood | {n_drops} |", "",
        "With the solver in the loop, one step of the sampler would need walkers x targets x "
        f"quadrature nodes = {heights_per_eval} critical heights, about "
        f"{heights_per_eval * per_run / 60:.1f} min at the measured rate; the main chain's "
        f"{c.sampler.burn + c.sampler.steps} steps alone about "
        f"{heights_per_eval * per_run * (c.sampler.burn + c.sampler.steps) / 86400:.0f} days. "
        "Hence the surrogate (docs/calibration.md, \"Cost\").", "",
        "Surrogate error (rmse of ln H_c): held out / at posterior draws against the solver:", ""]
    for name, s in summary["surrogates"].items():
        chk = summary["surrogate_check"].get(name)
        at = f"{chk['rmse']:.4f} ({chk['draws']} draws)" if chk else "-"
        lines.append(f"- {name}: {s['rmse_holdout']:.4f} / {at}")
    diag = summary["diagnostics"]
    lines += ["", f"Diagnostics of that run: largest R-hat "
              f"{max(d['r_hat'] for d in diag.values()):.4f}, smallest bulk ESS "
              f"{min(d['ess_bulk'] for d in diag.values()):.0f}, smallest tail ESS "
              f"{min(d['ess_tail'] for d in diag.values()):.0f}."]
    dest = ROOT / "results" / "benchmarks" / "calibration.md"
    dest.parent.mkdir(parents=True, exist_ok=True)
    dest.write_text("\n".join(lines) + "\n")
    print(dest)
    print(f"{wall:.1f} min, {cost['solver_runs']} solver runs")
    return 0 if np.isfinite(wall) else 1


if __name__ == "__main__":
    sys.exit(main())
