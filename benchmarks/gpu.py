"""GPU backend against the CPU full tier: critical heights per second and agreement.

    python benchmarks/gpu.py [--sizes 10000 100000] [--cpu-sample 200]

Scenes are the inputs of the shipped ``paper-series1`` ensemble (4 scenes x 50 epistemic x 200
aleatory draws = 40,000 sampled scenes, ``results/paper-series1/ensemble.h5``), resampled with
replacement up to each size. For each rtol (1e-2, 3e-3, 1e-3), side by side in one run:

* CPU full tier: :func:`skidmc.solver.critical_height` on ``--cpu-sample`` scenes in two worker
  processes (the CI machine's two cores), heights per second;
* device search on the CPU: the function a GPU thread runs, on the CPU's threads
  (``backend="cpu"``), same scenes;
* GPU (``backend="cuda"``), where :func:`skidmc.solver.cuda.cuda_status` finds one: each size, and
  the agreement of its heights with the CPU full tier on the common scenes (worst and median
  |H_gpu / H_cpu - 1|, share within rtol, share handed back to the CPU search).

The rows are the ensemble's sampled inputs as constant-property scenes (a row of floats): the
study itself runs its ceramics with k(T), c(T) tables and its gold as a layered stack, which the
device does not take (:func:`skidmc.solver.cuda.cpu_only_reason`; docs/gpu.md). So these
figures are the device search's speed on such scenes, not what a GPU does for the shipped
studies (nothing yet).

Writes ``results/benchmarks/gpu.md`` and ``gpu.json``. Where no GPU is usable the GPU columns say
why; nothing is estimated in their place.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "src"))

from skidmc import evaluate_batch, open_ensemble  # noqa: E402
from skidmc.solver import device  # noqa: E402
from skidmc.solver.cuda import critical_heights, cuda_status  # noqa: E402

RTOLS = (1e-2, 3e-3, 1e-3)


def study_rows():
    """(rows (n, 18) [SI], key columns) of the paper-series1 ensemble's sampled scenes."""
    from skidmc.scene import NUMERIC_KEYS

    ds = open_ensemble(ROOT / "results" / "paper-series1" / "ensemble.h5")
    shape = ds["critical_height"]
    # The ensemble names inputs by scene key (NUMERIC_KEYS, the order of SCENE_FIELDS).
    rows = np.column_stack([np.asarray(ds[key].broadcast_like(shape)).ravel()
                            for key in NUMERIC_KEYS])
    # target.hardness is +inf for the report's rigid targets: drop only scenes with a NaN input.
    return rows[~np.isnan(rows).any(axis=1)]


def cpu_full_tier(rows, rtol):
    """Heights [m] and wall time [s] of the CPU full tier on two worker processes."""
    from skidmc.scene import NUMERIC_KEYS, get_preset

    columns = {key: np.ascontiguousarray(rows[:, j]) for j, key in enumerate(NUMERIC_KEYS)}
    t0 = time.perf_counter()
    res = evaluate_batch(columns, {"rtol": rtol}, base=get_preset("paper-quartz"), workers=2)
    return res.critical_height, time.perf_counter() - t0


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[10_000, 100_000])
    parser.add_argument("--cpu-sample", type=int, default=200)
    parser.add_argument("--seed", type=int, default=17)
    parser.add_argument("--out", default=str(ROOT / "results" / "benchmarks"))
    args = parser.parse_args(argv)
    rng = np.random.default_rng(args.seed)
    pool = study_rows()
    sample = pool[rng.choice(len(pool), args.cpu_sample, replace=False)]
    usable, why = cuda_status()
    report = {"machine": platform.platform(), "cpus": os.cpu_count(), "gpu": usable,
              "gpu_note": why, "cpu_sample": args.cpu_sample, "rows": []}
    if usable:
        critical_heights(sample[:64], 1e-2, backend="cuda")   # compile outside the timing
    critical_heights(sample[:4], 1e-2, backend="cpu")
    cpu_full_tier(sample[:8], 1e-2)   # start the two worker processes outside the timing
    for rtol in RTOLS:
        h_cpu, t_cpu = cpu_full_tier(sample, rtol)
        out, t_dev = critical_heights(sample, rtol, backend="cpu")
        row = {"rtol": rtol, "cpu_full_per_s": len(sample) / t_cpu,
               "device_on_cpu_per_s": len(sample) / t_dev,
               "device_handed_back": float(np.mean(out[:, device.OUT_STATUS] != 0)),
               "device_on_cpu_worst_rel_diff": _worst(out, h_cpu), "gpu": []}
        if usable:
            for n in args.sizes:
                extra = pool[rng.choice(len(pool), max(0, n - len(sample)))]
                rows = np.concatenate([sample, extra])
                gpu, t_gpu = critical_heights(rows, rtol, backend="cuda")
                row["gpu"].append({"n": n, "per_s": n / t_gpu,
                                   "handed_back": float(np.mean(gpu[:, device.OUT_STATUS] != 0)),
                                   "worst_rel_diff": _worst(gpu[:len(sample)], h_cpu),
                                   "median_rel_diff": _median(gpu[:len(sample)], h_cpu)})
        report["rows"].append(row)
        print(json.dumps(row), flush=True)
        # Written after every rtol: a run cut short (a lent GPU's time is short) keeps its rows.
        out_dir = Path(args.out)
        out_dir.mkdir(parents=True, exist_ok=True)
        (out_dir / "gpu.json").write_text(json.dumps(report, indent=2) + "\n")
        (out_dir / "gpu.md").write_text(_markdown(report))
    print(f"wrote {out_dir / 'gpu.md'}")
    return 0


def _rel(out, h_cpu):
    ok = (out[:, device.OUT_STATUS] == 0) & (out[:, device.OUT_CENSOR] == 0) & np.isfinite(h_cpu)
    return np.abs(out[ok, device.OUT_HEIGHT] / h_cpu[ok] - 1.0)


def _worst(out, h_cpu):
    rel = _rel(out, h_cpu)
    return float(rel.max()) if rel.size else float("nan")


def _median(out, h_cpu):
    rel = _rel(out, h_cpu)
    return float(np.median(rel)) if rel.size else float("nan")


def _markdown(report):
    lines = ["# GPU backend: critical heights per second and agreement with the CPU full tier", "",
             "Generated by `python benchmarks/gpu.py` (scenes resampled from the paper-series1 "
             "ensemble's inputs).", "",
             f"Machine: {report['machine']}, {report['cpus']} CPUs. GPU: "
             + ("yes" if report["gpu"] else f"**none usable** ({report['gpu_note']})"), "",
             f"CPU columns on {report['cpu_sample']} scenes: the CPU full tier "
             "(`critical_height`, 2 worker processes) and the device search run on the CPU's "
             "threads (`backend=\"cpu\"`, the function a GPU thread runs). Differences are "
             "|H / H_cpu - 1| on uncensored scenes the device search answered itself.", "",
             "| rtol | CPU full tier [heights/s] | device search on CPU [heights/s] | "
             "handed back to CPU | worst diff vs CPU |",
             "| --- | --- | --- | --- | --- |"]
    for r in report["rows"]:
        lines.append(f"| {r['rtol']:g} | {r['cpu_full_per_s']:.1f} | "
                     f"{r['device_on_cpu_per_s']:.1f} | {100 * r['device_handed_back']:.1f} % | "
                     f"{r['device_on_cpu_worst_rel_diff']:.2e} |")
    lines += ["", "## GPU", ""]
    if not report["gpu"]:
        lines.append(f"Not measured: {report['gpu_note']}.")
    else:
        lines += ["| rtol | scenes | GPU [heights/s] | vs CPU full tier (2 cores) | handed back | "
                  "worst diff | median diff |", "| --- | --- | --- | --- | --- | --- | --- |"]
        for r in report["rows"]:
            for g in r["gpu"]:
                lines.append(f"| {r['rtol']:g} | {g['n']:,} | {g['per_s']:.3g} | "
                             f"{g['per_s'] / r['cpu_full_per_s']:.0f}x | "
                             f"{100 * g['handed_back']:.2f} % | {g['worst_rel_diff']:.2e} | "
                             f"{g['median_rel_diff']:.2e} |")
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    sys.exit(main())
