"""The device search (GPU backend, on the CPU's threads) against the CPU full tier, on study scenes.

    python benchmarks/device_agreement.py [--n 70] [--seed 45]
    git archive <commit> src | tar -x -C /tmp/base-<commit>
    python benchmarks/device_agreement.py --base /tmp/base-<commit>/src   # and side by side

The function a CUDA thread runs (:func:`skidmc.solver.device.critical_height_core`) is run on
the CPU (``backend="cpu"``, one numba thread, so that its time per height compares with one
process of the CPU search), on scenes drawn from the shipped studies' ensembles
(``benchmarks/study_scenes.py``; the temperature-dependent targets among them go to the CPU
search by design and are counted as handed back). For each rtol (1e-2, 3e-3, 1e-3):

* agreement: |H_device / H_cpu - 1| / rtol on the uncensored scenes the device answered itself
  (both are converged to rtol by their own estimates, so up to 2 is allowed; what is left is the
  difference of the two searches);
* honesty: |H_device / H_ref - 1| against the device's own error estimate, where H_ref is the
  CPU search at rtol 1e-5 (its own estimate listed: an error below it is not resolved);
* time: the device's time per height (the whole batch on one thread, the smaller of
  ``--repeat`` calls) and the CPU search's (each scene the smaller of ``--repeat`` calls, in
  process), side by side.

With ``--base``, the same measurement runs in a subprocess on that source tree, the trees taking
turns for the timings (``--rounds``), and the table shows both. Writes
``results/benchmarks/device_agreement.md``. No GPU is needed or used.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
if "PYTHONPATH" not in os.environ:
    sys.path.insert(0, str(ROOT / "src"))
sys.path.insert(0, str(ROOT / "benchmarks"))

import numpy as np  # noqa: E402
import study_scenes  # noqa: E402

RTOLS = (1e-2, 3e-3, 1e-3)
#: The reference's tolerance: the CPU search converged far below every rtol measured.
REFERENCE_RTOL = 1e-5


def _scenes(n, seed):
    return study_scenes.draw(n, seed)


def measure(n, seed, repeat, timing_only=False):
    """This tree's device and CPU results on the drawn scenes [dict of lists per rtol]."""
    import numba

    from skidmc.solver import critical_height
    from skidmc.solver.cuda import critical_heights, solve_scenes
    from skidmc.solver.fast import SCENE_FIELDS, _scene_values

    numba.set_num_threads(1)
    drawn = _scenes(n, seed)
    scenes = [s for _, _, s in drawn]
    rows = np.array([_scene_values(s) for s in scenes], dtype=float).reshape(
        len(scenes), len(SCENE_FIELDS))
    critical_heights(rows[:2], 1e-2, backend="cpu")   # load the kernels outside the timing
    critical_height(scenes[0], rtol=1e-2)
    out = {"labels": [label for label, _, _ in drawn], "rtols": {}}
    for rtol in RTOLS:
        best = np.inf
        for _ in range(repeat):
            _, seconds = critical_heights(rows, rtol, backend="cpu")
            best = min(best, seconds)
        entry = {"device_seconds": best}
        if not timing_only:
            dev = solve_scenes(scenes, backend="cpu", rtol=rtol)
            cpu, cpu_s = [], []
            for s in scenes:
                t = np.inf
                for _ in range(repeat):
                    t0 = time.perf_counter()
                    r = critical_height(s, rtol=rtol)
                    t = min(t, time.perf_counter() - t0)
                cpu.append(r)
                cpu_s.append(t)
            entry.update(
                device_method=[getattr(d, "method", "error") for d in dev],
                device_height=[float(getattr(d, "critical_height", np.nan)) for d in dev],
                device_censored=[getattr(d, "censored", "error") for d in dev],
                device_estimate=[float(getattr(d, "error_estimate", np.nan)) for d in dev],
                device_evaluations=[int(getattr(d, "evaluations", 0)) for d in dev],
                cpu_height=[r.critical_height for r in cpu],
                cpu_censored=[r.censored for r in cpu],
                cpu_seconds=cpu_s)
        out["rtols"][str(rtol)] = entry
    if not timing_only:
        refs = [critical_height(s, rtol=REFERENCE_RTOL) for s in scenes]
        out["reference_height"] = [r.critical_height for r in refs]
        out["reference_estimate"] = [r.error_estimate for r in refs]
        out["reference_censored"] = [r.censored for r in refs]
    return out


def _in_tree(src, args, timing_only):
    env = dict(os.environ, PYTHONPATH=str(src))
    cmd = [sys.executable, str(Path(__file__).resolve()), "--json", "--n", str(args.n),
           "--seed", str(args.seed), "--repeat", str(args.repeat)]
    if timing_only:
        cmd.append("--timing-only")
    proc = subprocess.run(cmd, env=env, capture_output=True, text=True, check=True)
    return json.loads(proc.stdout.strip().splitlines()[-1])


def _summary(res, rtol):
    e = res["rtols"][str(rtol)]
    dev_h = np.array(e["device_height"])
    cpu_h = np.array(e["cpu_height"])
    ref_h = np.array(res["reference_height"])
    ref_est = np.array(res["reference_estimate"])
    answered = np.array([m == "device" for m in e["device_method"]])
    both = answered & np.array([c is None for c in e["device_censored"]]) & np.array(
        [c is None for c in e["cpu_censored"]]) & np.array(
        [c is None for c in res["reference_censored"]])
    agree = np.abs(dev_h[both] / cpu_h[both] - 1.0) / rtol
    err = np.abs(dev_h[both] / ref_h[both] - 1.0)
    est = np.array(e["device_estimate"])[both]
    n = len(dev_h)
    return {
        "scenes": n, "answered": int(answered.sum()), "compared": int(both.sum()),
        "agree_median": float(np.median(agree)) if agree.size else np.nan,
        "agree_p90": float(np.percentile(agree, 90)) if agree.size else np.nan,
        "agree_max": float(agree.max()) if agree.size else np.nan,
        "err_over_est_max": float((err / est).max()) if err.size else np.nan,
        "err_over_est_median": float(np.median(err / est)) if err.size else np.nan,
        "beyond_estimate": int((err > est + ref_est[both]).sum()),
        "reference_estimate_max": float(ref_est[both].max()) if err.size else np.nan,
        "device_ms": 1e3 * e["device_seconds"] / n,
        "cpu_ms_mean": 1e3 * float(np.mean(e["cpu_seconds"])),
        "cpu_ms_answered_mean": 1e3 * float(np.mean(np.array(e["cpu_seconds"])[answered])),
        "device_evaluations_mean": float(np.mean(np.array(e["device_evaluations"])[answered])),
    }


def _markdown(trees, args, load_before, load_after):
    lines = [
        "# The device search against the CPU full tier on study scenes",
        "",
        f"Generated by `python benchmarks/device_agreement.py --n {args.n} --seed {args.seed}"
        + (f" --base {args.base}" if args.base else "") + "`. "
        f"{len(trees[0][1]['labels'])} scenes drawn from the shipped studies' ensembles "
        "(`benchmarks/study_scenes.py`, temperature-dependent targets included: the device "
        "hands those to the CPU search by design). The device search is the function a CUDA "
        "thread runs, here on the CPU with one numba thread; no GPU is used.",
        "",
        f"Machine: {os.cpu_count()} CPUs ({platform.machine()}), Python "
        f"{platform.python_version()}; load average {load_before} before, {load_after} after "
        "(shared machine: read the times as ratios within a row).",
        "",
        "- agreement: |H_device / H_cpu - 1| / rtol on the uncensored scenes the device answered "
        "(each search is converged to rtol by its own estimate, so up to 2 is within "
        "tolerance);",
        f"- error / estimate: |H_device / H_ref - 1| over the device's own estimate, H_ref the CPU "
        f"search at rtol {REFERENCE_RTOL:g} (largest reference estimate listed; 'beyond' counts "
        "errors above the device's estimate plus the reference's);",
        "- time per height: the device's whole batch on one thread over the scene count "
        "(smaller of the repeats and rounds); the CPU search per scene in process, mean over "
        "all scenes and over those the device answered, one pass per tree (not alternated: "
        "both trees run the same CPU search, so the difference between its two rows is the "
        "machine's noise).",
        "",
        "| rtol | tree | answered / scenes | agreement median, p90, max [rtol] | error / estimate "
        "median, max | beyond | ref. estimate max | device evaluations (mean) | device "
        "[ms/height] | CPU search [ms/height] (all; answered) |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for rtol in RTOLS:
        for name, res in trees:
            s = _summary(res, rtol)
            lines.append(
                f"| {rtol:g} | {name} | {s['answered']} / {s['scenes']} | "
                f"{s['agree_median']:.2f}, {s['agree_p90']:.2f}, {s['agree_max']:.2f} | "
                f"{s['err_over_est_median']:.2f}, {s['err_over_est_max']:.2f} | "
                f"{s['beyond_estimate']} | {s['reference_estimate_max']:.1e} | "
                f"{s['device_evaluations_mean']:.1f} | {s['device_ms']:.2f} | "
                f"{s['cpu_ms_mean']:.2f}; {s['cpu_ms_answered_mean']:.2f} |")
    return "\n".join(lines) + "\n"


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n", type=int, default=70, help="samples per study ensemble")
    parser.add_argument("--seed", type=int, default=45)
    parser.add_argument("--repeat", type=int, default=2)
    parser.add_argument("--rounds", type=int, default=2,
                        help="with --base: timing rounds, the trees taking turns")
    parser.add_argument("--base", help="src folder of the tree to compare with")
    parser.add_argument("--json", action="store_true", help=argparse.SUPPRESS)
    parser.add_argument("--timing-only", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.json:
        print(json.dumps(measure(args.n, args.seed, args.repeat, args.timing_only)))
        return 0
    load_before = ", ".join(f"{v:.2f}" for v in os.getloadavg())
    this_src = ROOT / "src"
    trees = []
    if args.base:
        trees.append(("base", _in_tree(args.base, args, False)))
    trees.append(("this", _in_tree(this_src, args, False)))
    if args.base:
        for _ in range(args.rounds - 1):
            for name, res in trees:
                again = _in_tree(args.base if name == "base" else this_src, args, True)
                for rtol in RTOLS:
                    e = res["rtols"][str(rtol)]
                    e["device_seconds"] = min(e["device_seconds"],
                                              again["rtols"][str(rtol)]["device_seconds"])
    load_after = ", ".join(f"{v:.2f}" for v in os.getloadavg())
    text = _markdown(trees, args, load_before, load_after)
    out = ROOT / "results" / "benchmarks" / "device_agreement.md"
    out.write_text(text)
    print(text)
    print(f"wrote {out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
