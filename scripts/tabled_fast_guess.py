"""The fast tier's first guess on temperature-dependent targets: at which temperature to hold them.

The fast tier's target has constant properties. For a tabled target (k(T), c(T)) the default
search's first guess is the fast tier's height with the table's k and c held at one temperature
T* = T0 + f (T_high - T0) of the interface's rise (:func:`skidmc.solver.model.
target_temperature_range`: T0 to the runaway temperature). Until 2026-11-28 f was 0.5 (the
middle of the rise), with no measurement behind it; a guess far off costs the search doubling
steps (never a wrong root). This script measures ln(H_fast(f) / H) against the default search's
height H at rtol 1e-2 over a grid of f, on the temperature-dependent-target scenes of one draw
of the shipped studies' ensembles (``benchmarks/study_scenes.py``, the training set: seed 45) and
checks the fitted f on another draw (the test set: seed 46), reporting both.

Usage::

    python scripts/tabled_fast_guess.py            # ~2 min; writes results/validation/
                                                   # tabled_fast_guess.md
"""

from __future__ import annotations

import argparse
import math
import statistics
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))

import study_scenes  # noqa: E402

FRACTIONS = np.round(np.arange(0.0, 1.0001, 0.05), 2)

#: Parameter-free alternatives to one temperature: the constant k and c from means of the table
#: over the rise T0..T_high (401 points): arithmetic (Kirchhoff's mean of k, as in steady
#: conduction), harmonic k (layers in series), geometric, and a harmonic mean of the effusivity
#: sqrt(k c) with c's arithmetic mean.
MEANS = ("arithmetic k and c", "harmonic k, arithmetic c", "geometric k and c",
         "harmonic effusivity")


def _mean_properties(kind, k, c):
    if kind == "arithmetic k and c":
        return k.mean(), c.mean()
    if kind == "harmonic k, arithmetic c":
        return 1.0 / np.mean(1.0 / k), c.mean()
    if kind == "geometric k and c":
        return np.exp(np.mean(np.log(k))), np.exp(np.mean(np.log(c)))
    e = 1.0 / np.mean(1.0 / np.sqrt(k * c))
    return e * e / c.mean(), c.mean()


def tabled_scenes(seed, n):
    return [(label, scene) for label, group, scene in study_scenes.draw(n, seed)
            if ":" in group]


def offsets(scenes):
    """{f or mean: [ln(H_fast / H)]} and the labels used (scenes the fast tier or search censor
    are left out)."""
    from skidmc.solver import critical_height
    from skidmc.solver.fast import fast_critical_height
    from skidmc.solver.model import (
        build_model,
        constant_property_scene,
        target_property_table,
        target_temperature_range,
    )

    out = {**{float(f): [] for f in FRACTIONS}, **{kind: [] for kind in MEANS}}
    used = []
    for label, scene in scenes:
        ref = critical_height(scene, rtol=1e-2)
        if ref.censored is not None:
            continue
        model = build_model(scene, meshes=False)
        low, high = target_temperature_range(scene.initial_temperature,
                                             model.runaway_temperature)
        row = {}
        for f in FRACTIONS:
            fast = fast_critical_height(constant_property_scene(scene, low + f * (high - low)),
                                        h_min=1e-3, h_max=1e4)
            if fast.censored is not None:
                break
            row[float(f)] = math.log(fast.critical_height / ref.critical_height)
        t, k, c = target_property_table(scene)
        temps = np.linspace(low, high, 401)
        for kind in MEANS:
            k_mean, c_mean = _mean_properties(kind, np.interp(temps, t, k),
                                              np.interp(temps, t, c))
            fast = fast_critical_height(scene.replace(
                {"target.conductivity": float(k_mean), "target.heat_capacity": float(c_mean),
                 "target.table": ""}, check_plausible=False), h_min=1e-3, h_max=1e4)
            if fast.censored is not None:
                break
            row[kind] = math.log(fast.critical_height / ref.critical_height)
        else:
            used.append(label)
            for f, v in row.items():
                out[f].append(v)
    return out, used


def _stats(values):
    a = np.abs(values)
    return (statistics.median(values), float(np.median(a)), float(np.quantile(a, 0.9)),
            float(a.max()))


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n", type=int, default=60, help="samples per study in each draw")
    parser.add_argument("--out", default=str(ROOT / "results" / "validation" /
                                             "tabled_fast_guess.md"))
    args = parser.parse_args(argv)
    train, used_train = offsets(tabled_scenes(45, args.n))
    test, used_test = offsets(tabled_scenes(46, args.n))
    fractions = [float(f) for f in FRACTIONS]
    best = min(fractions, key=lambda f: float(np.median(np.abs(train[f]))))
    lines = [
        "# The fast tier's first guess on temperature-dependent targets",
        "",
        f"Generated by `python scripts/tabled_fast_guess.py --n {args.n}`. ln(H_fast(f) / H): "
        "the fast tier's height with the table's k and c held at T0 + f (T_high - T0) "
        "(T_high: the runaway temperature) against the default search's height at rtol 1e-2. "
        f"Training set: the {len(used_train)} temperature-dependent-target scenes of the "
        f"study draw of seed 45; test set: the {len(used_test)} of seed 46 "
        "(`benchmarks/study_scenes.py`; scenes either tier censors are left out).",
        "",
        "| f | training: median ln ratio | median abs | p90 abs | max abs | test: median ln "
        "ratio | median abs | p90 abs | max abs |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for f in fractions:
        a, b = _stats(train[f]), _stats(test[f])
        mark = " (fit)" if f == best else (" (before)" if f == 0.5 else "")
        lines.append(f"| {f:.2f}{mark} | " + " | ".join(f"{x:+.3f}" if i == 0 else f"{x:.3f}"
                                                         for i, x in enumerate(a)) + " | "
                     + " | ".join(f"{x:+.3f}" if i == 0 else f"{x:.3f}"
                                  for i, x in enumerate(b)) + " |")
    lines += ["", f"Fit (smallest median |ln ratio| on the training set): f = {best:.2f}.", "",
              "By material (training and test sets together): the f with the smallest median "
              "|ln ratio|, and the figures at the fit's f.", "",
              "| material | scenes | its best f | median abs there | at the fit: median ln ratio "
              "| median abs | p90 abs | max abs |", "|---|---|---|---|---|---|---|---|"]
    for material in sorted({label.rsplit(":", 1)[1] for label in used_train + used_test}):
        rows = {f: [v for label, v in zip(used_train + used_test, train[f] + test[f])
                    if label.endswith(":" + material)] for f in fractions}
        own = min(rows, key=lambda f: float(np.median(np.abs(rows[f]))))
        a = _stats(rows[best])
        lines.append(f"| {material} | {len(rows[best])} | {own:.2f} | "
                     f"{float(np.median(np.abs(rows[own]))):.3f} | {a[0]:+.3f} | {a[1]:.3f} | "
                     f"{a[2]:.3f} | {a[3]:.3f} |")
    lines += ["", "Means of the table over the rise instead of one temperature (no constant "
              "fitted; training and test sets together), against the median 0.013 of "
              "constant targets (`skidmc.solver.finders.FAST_GUESS_ERROR` rounds it up to "
              "0.02):", "",
              "| properties | material | median ln ratio | median abs | p90 abs | max abs |",
              "|---|---|---|---|---|---|"]
    labels = used_train + used_test
    for kind in (0.5, *MEANS):
        values = train[kind] + test[kind]
        name = "middle of the rise (f = 0.50)" if kind == 0.5 else kind
        for material in ("all", *sorted({label.rsplit(":", 1)[1] for label in labels})):
            picked = [v for label, v in zip(labels, values)
                      if material == "all" or label.endswith(":" + material)]
            a = _stats(picked)
            lines.append(f"| {name} | {material} | {a[0]:+.3f} | {a[1]:.3f} | {a[2]:.3f} | "
                         f"{a[3]:.3f} |")
    lines.append("")
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text("\n".join(lines))
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
