"""Coverage of the Sobol' bootstrap intervals on SALib's scrambled Sobol' design, per N.

For the Ishigami function (a = 7, b = 0.1) and Sobol's G-function (8 inputs, a = 0, 1, 4.5, 9,
99, 99, 99, 99; Saltelli et al. 2010) with their analytic S1 and ST, each repetition draws the
design with a new scrambling seed (``SALib.sample.sobol.sample(..., scramble=True, seed=s)``),
computes ``sobol_indices`` (BCa, 1000 resamples) and checks whether each 95 % interval holds the
exact index. Besides the coverage the table gives, per index, the ratio of the mean bootstrap
half-width to 1.96 times the observed spread of the estimates between scrambles (1: the
bootstrap's spread is the real one; < 1: intervals too narrow; > 1: too wide).

Usage::

    PYTHONPATH=$PWD/src python scripts/sobol_coverage.py [--sizes 256,1024,4096 --reps 200]

writes results/validation/sobol_coverage.md and .csv.
"""

from __future__ import annotations

import argparse
import csv
import math
import subprocess
import time
import warnings
from pathlib import Path

import numpy as np
from SALib.sample import sobol as sobol_sample

from skidmc.analysis.sensitivity import sobol_indices

G_A = np.array([0.0, 1.0, 4.5, 9.0, 99.0, 99.0, 99.0, 99.0])


def ishigami(x, a=7.0, b=0.1):
    return np.sin(x[:, 0]) + a * np.sin(x[:, 1]) ** 2 + b * x[:, 2] ** 4 * np.sin(x[:, 0])


def ishigami_exact(a=7.0, b=0.1):
    pi = math.pi
    v1 = 0.5 * (1 + b * pi**4 / 5) ** 2
    v2 = a**2 / 8
    v13 = b**2 * pi**8 * (1 / 18 - 1 / 50)
    v = v1 + v2 + v13
    return np.array([v1, v2, 0.0]) / v, np.array([v1 + v13, v2, v13]) / v


def g_function(x):
    return np.prod((np.abs(4 * x - 2) + G_A) / (1 + G_A), axis=1)


def g_exact():
    vi = 1.0 / (3.0 * (1.0 + G_A) ** 2)
    v = np.prod(1 + vi) - 1
    return vi / v, vi * np.array([np.prod(np.delete(1 + vi, i)) for i in range(vi.size)]) / v


PROBLEMS = {
    "Ishigami": ({"num_vars": 3, "names": ["x1", "x2", "x3"], "bounds": [[-math.pi, math.pi]] * 3},
                 ishigami, ishigami_exact),
    "G-function": ({"num_vars": 8, "names": [f"x{i + 1}" for i in range(8)],
                    "bounds": [[0.0, 1.0]] * 8}, g_function, g_exact),
}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", default="256,1024,4096")
    parser.add_argument("--reps", type=int, default=200)
    parser.add_argument("--first-seed", type=int, default=41_000)
    parser.add_argument("--out", default="results/validation")
    args = parser.parse_args()
    start = time.time()
    rows = []
    for name, (problem, model, exact_fn) in PROBLEMS.items():
        s1, st = exact_fn()
        exact = np.r_[s1, st]
        labels = [f"S1 {n}" for n in problem["names"]] + [f"ST {n}" for n in problem["names"]]
        for n in [int(v) for v in args.sizes.split(",")]:
            hits = np.zeros(exact.size)
            estimates, half = [], []
            for rep in range(args.reps):
                seed = args.first_seed + rep
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore")
                    x = sobol_sample.sample(problem, n, calc_second_order=False, scramble=True,
                                            seed=seed)
                res = sobol_indices(problem, model(x), seed=seed)
                est = np.r_[res["S1"].values, res["ST"].values]
                low = np.r_[res["S1_low"].values, res["ST_low"].values]
                high = np.r_[res["S1_high"].values, res["ST_high"].values]
                hits += (low <= exact) & (exact <= high)
                estimates.append(est)
                half.append(0.5 * (high - low))
            spread = 1.96 * np.std(estimates, axis=0, ddof=1)
            ratio = np.mean(half, axis=0) / np.where(spread > 0, spread, np.nan)
            for j, label in enumerate(labels):
                rows.append({"function": name, "N": n, "index": label, "exact": exact[j],
                             "reps": args.reps, "coverage": hits[j] / args.reps,
                             "width_ratio": ratio[j]})
            print(name, n, np.round(hits / args.reps, 3), flush=True)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    with open(out / "sobol_coverage.csv", "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True,
                            text=True).stdout.strip()
    sizes = sorted({r["N"] for r in rows})
    lines = [
        "# Coverage of the 95 % Sobol' intervals on the scrambled Sobol' design",
        "",
        f"`scripts/sobol_coverage.py --sizes {args.sizes} --reps {args.reps}` at commit "
        f"{commit}, {time.time() - start:.0f} s. BCa bootstrap over base rows (1000 resamples),",
        f"{args.reps} scrambles per N (a coverage of 0.95 is measured to +-"
        f"{math.sqrt(0.95 * 0.05 / args.reps):.3f}, one standard error). Each cell: coverage /",
        "ratio of the mean bootstrap half-width to 1.96 x the observed spread between scrambles.",
        "",
        "| function | index | exact | " + " | ".join(f"N = {n}" for n in sizes) + " |",
        "|---|---|---|" + "---|" * len(sizes),
    ]
    for name in PROBLEMS:
        for label in dict.fromkeys(r["index"] for r in rows if r["function"] == name):
            cells = []
            for n in sizes:
                r = next(r for r in rows
                         if r["function"] == name and r["N"] == n and r["index"] == label)
                cells.append(f"{r['coverage']:.3f} / {r['width_ratio']:.2f}")
                exact_value = r["exact"]
            lines.append(f"| {name} | {label} | {exact_value:.4f} | " + " | ".join(cells) + " |")
    (out / "sobol_coverage.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
