"""Which unreported input explains the report's second-series calculations (Table IX)?

The report gives neither the sensitive-pole billets' mass nor their approach angle.
With the first series' 19.1 lb and 30 deg approach, skidmc lands 13-18% above every
Table IX calculated height. This script asks, for each candidate input alone
(billet mass, approach angle, flow stress), which value makes skidmc reproduce the
five calculated heights best (least squares on ln H), and how well: an input that
explains the offset leaves a flat residual across the five mu values.

Writes results/validation/second_series.{md,csv}. Run: ``python scripts/second_series.py``
(about a minute).
"""

from __future__ import annotations

import csv
import math
from pathlib import Path

import numpy as np
from scipy.optimize import minimize_scalar

from skidmc.scene import make_scene
from skidmc.scene.presets import PAPER_TABLE_IX
from skidmc.scene.units import from_si
from skidmc.solver import critical_height

OUT = Path(__file__).resolve().parents[1] / "results" / "validation"
RTOL = 2e-3  # 0.2 %: far below the 15 % offset being explained

CANDIDATES = {
    # key: (bounds in SI, display unit, SI unit)
    "billet_mass": ((5.0, 20.0), "lb", "kg"),
    "angle": ((45.0, 80.0), "deg", "deg"),
    "flow_stress": ((2.0e8, 3.2e8), "psi", "Pa"),
}


#: The first series' billet and angle: the starting point every fit changes one input of.
FIRST_SERIES_GUESS = {"billet_mass": "19.1 lb", "angle": "60 deg"}


def heights(overrides):
    overrides = {**FIRST_SERIES_GUESS, **overrides}
    out = []
    for row in PAPER_TABLE_IX:
        scene = make_scene(preset="paper2-quartz", mu=row.mu, **overrides)
        out.append(critical_height(scene, rtol=RTOL).critical_height_ft)
    return np.array(out)


def main():
    OUT.mkdir(parents=True, exist_ok=True)
    report = np.array([row.calculated_ft for row in PAPER_TABLE_IX])
    mus = [row.mu for row in PAPER_TABLE_IX]
    base = heights({})
    rows = [("first-series inputs (19.1 lb, phi 60 deg, 34400 psi)", "", base)]
    for key, (bounds, unit, si_unit) in CANDIDATES.items():
        def misfit(value, key=key):
            return float(np.sum(np.log(heights({key: value}) / report) ** 2))
        best = minimize_scalar(misfit, bounds=bounds, method="bounded",
                               options={"xatol": 1e-3 * (bounds[1] - bounds[0])})
        value = best.x
        shown = from_si(value, si_unit, unit)
        label = f"{key} = {shown:.4g} {unit}"
        if key == "angle":
            label += f" (approach {90.0 - value:.1f} deg)"
        rows.append((f"fit {key} alone", label, heights({key: value})))
        print(rows[-1][0], label, rows[-1][2] / report)

    with open(OUT / "second_series.csv", "w", newline="") as fh:
        writer = csv.writer(fh)
        writer.writerow(["case", "value"] + [f"H_ft(mu={m})" for m in mus]
                        + ["rms_log_ratio", "ratio_spread"])
        writer.writerow(["report Table IX calculated", ""] + list(report) + ["", ""])
        for case, label, h in rows:
            r = h / report
            writer.writerow([case, label] + [f"{v:.4f}" for v in h]
                            + [f"{math.sqrt(np.mean(np.log(r) ** 2)):.4f}",
                               f"{r.max() - r.min():.4f}"])
    lines = [
        "# Second series (Table IX): which unreported input explains the report's heights?",
        "",
        f"skidmc critical heights [ft] at rtol = {RTOL:g}; `python scripts/second_series.py`.",
        "",
        "| case | value | " + " | ".join(f"mu = {m}" for m in mus)
        + " | rms ln(H/H_report) | spread of H/H_report |",
        "|---|---|" + "---|" * len(mus) + "---|---|",
        "| report, calculated | | " + " | ".join(f"{v:.2f}" for v in report) + " | | |",
    ]
    for case, label, h in rows:
        r = h / report
        cells = " | ".join(f"{v:.3f} ({x:.2f})" for v, x in zip(h, r))
        lines.append(f"| {case} | {label} | " + cells
                     + f" | {math.sqrt(np.mean(np.log(r) ** 2)):.3f} | {r.max() - r.min():.3f} |")
    lines += ["", "Values in parentheses: ratio to the report's calculated height."]
    (OUT / "second_series.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
