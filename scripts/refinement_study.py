"""Refinement study: numerical error of the critical height versus resolution level.

For every report preset (and the second series' extreme mu values) the critical
height is computed at levels 0, 0.5, ..., 4 (each level doubles the cells per medium,
halves the first cell and halves the time step, see skidmc.solver.model) with a root-finder
tolerance far below the discretisation error. The converged value is estimated by
Richardson extrapolation of the two finest levels (second order: ratio 4 per level),
and the error of each level is measured against it. The observed order is reported,
and the calibration constant ``skidmc.solver.ERROR_LEVEL0`` is checked against the
worst case. The same runs give the residual error of the solver's Richardson value
(levels L - 1 and L, ``skidmc.solver.RICHARDSON_ERROR_LEVEL0``).

Writes results/validation/refinement.{csv,md,png}. Run: ``python scripts/refinement_study.py``.

The melting step's width w is, by default, the solver's floor at each level
(``skidmc.solver.model.melt_width_floor``: 2 K * 2**-L, the rule the error model was calibrated
with). ``--melt-width W`` holds it at W kelvin at every level instead, as the solver does
when rtol sets a wider step (``melt_width_for_rtol``); the files then get a ``_wW`` suffix.
``--melt-spread S`` runs every level with the per-cell melting spread S
(``critical_height(..., melt_spread=S)``; the default search's is 1); the files get an ``_sS``
suffix. With ``--melt-width W --melt-spread 1`` (W = 0.35, 1, 2, 3, 4 K) they calibrate the
default search's a posteriori ratios (``skidmc.solver.plan.RICHARDSON_RESIDUAL_RATIO_SPREAD``).
"""

from __future__ import annotations

import argparse
import csv
import math
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from skidmc.scene import make_scene  # noqa: E402
from skidmc.scene.units import FOOT  # noqa: E402
from skidmc.solver import critical_height  # noqa: E402
from skidmc.solver.model import melt_width_floor, resolution_for_level  # noqa: E402
from skidmc.solver.plan import (  # noqa: E402
    ERROR_LEVEL0,
    RICHARDSON_ERROR_LEVEL0,
    RICHARDSON_MIN_LEVEL,
    RICHARDSON_RESIDUAL_RATIO,
    RICHARDSON_RESIDUAL_RATIO_LEVEL0,
    RICHARDSON_RESIDUAL_RATIO_SPREAD,
    SPREAD_FINE_LEVEL,
    a_posteriori_error,
    level_for_rtol,
    plan_for_rtol,
)

OUT = Path(__file__).resolve().parents[1] / "results" / "validation"
LEVELS = [0.0, 0.5, 1.0, 1.5, 2.0, 2.5, 3.0, 3.5, 4.0]
CASES = {
    "paper-quartz": {},
    "paper-alumina-smooth": {},
    "paper-alumina-rough": {},
    "paper-gold": {},
    "paper2-quartz mu=0.056": {"preset": "paper2-quartz", "mu": 0.056},
    "paper2-quartz mu=0.243": {"preset": "paper2-quartz", "mu": 0.243},
}


def richardson_pairs(heights, levels):
    """(L, R, c) for each pair (L - 1, L) with L >= 1: the Richardson value
    R = H_L + (H_L - H_{L-1}) / 3 [m] and its relative correction c = (H_L - H_{L-1}) / (3 R)."""
    for i, lv in enumerate(levels):
        if lv < 1.0:
            continue
        j = levels.index(lv - 1.0)
        r = heights[i] + (heights[i] - heights[j]) / 3.0
        yield lv, r, (heights[i] - heights[j]) / (3.0 * r)


def pair_rows(table, levels, measure, fmt):
    """Markdown rows (one per case) of ``measure(R, H_conv, c)`` for each Richardson pair of
    :func:`richardson_pairs`, each cell formatted with ``fmt``, and the worst value per fine
    level."""
    rows, worst = [], {}
    for case, (h, conv, _) in table.items():
        cells = []
        for lv, r, c in richardson_pairs(h, levels):
            value = measure(r, conv, c)
            worst[lv] = max(worst.get(lv, 0.0), value)
            cells.append(fmt.format(value))
        rows.append(f"| {case} | " + " | ".join(cells) + " |")
    return rows, worst


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--melt-width", type=float, default=None,
                        help="melting-step width [K] at every level (default: the level floor)")
    parser.add_argument("--melt-spread", type=float, default=0.0,
                        help="per-cell melting spread [1] at every level (default 0: the fixed "
                             "step; the default search uses thermal.MELT_SPREAD)")
    parser.add_argument("--max-level", type=float, default=LEVELS[-1])
    args = parser.parse_args()
    levels = [lv for lv in LEVELS if lv <= args.max_level]
    suffix = "" if args.melt_width is None else f"_w{args.melt_width:g}"
    option = f" --melt-width {args.melt_width:g}" if suffix else ""
    if args.melt_spread:
        suffix += f"_s{args.melt_spread:g}"
        option += f" --melt-spread {args.melt_spread:g}"
    width_text = ("the solver's floor 2 K * 2^-L" if args.melt_width is None
                  else f"{args.melt_width:g} K at every level")
    OUT.mkdir(parents=True, exist_ok=True)
    table = {}
    for case, spec in CASES.items():
        spec = dict(spec)
        scene = make_scene(preset=spec.pop("preset", case), **spec)
        heights, costs = [], []
        for level in levels:
            width = melt_width_floor(level) if args.melt_width is None else args.melt_width
            res = critical_height(scene, level=level, rtol=1e-7, melt_width=width,
                                  melt_spread=args.melt_spread)
            heights.append(res.critical_height)
            costs.append(res.wall_time / max(res.evaluations, 1))
            print(f"{case:28s} level {level:3.1f} H = {res.critical_height:.8g} m "
                  f"({res.evaluations} sims, {1e3 * costs[-1]:.1f} ms/sim)", flush=True)
        h = np.array(heights)
        # Richardson on the two finest levels, one level apart (ratio 4 for second order).
        converged = h[-1] + (h[-1] - h[-3]) / 3.0
        table[case] = (h, converged, np.array(costs))

    with open(OUT / f"refinement{suffix}.csv", "w", newline="") as fh:
        writer = csv.writer(fh)
        writer.writerow(["case", "level", "cells_per_medium", "tol_temperature_K",
                         "critical_height_m", "rel_error", "ms_per_simulation"])
        for case, (h, conv, costs) in table.items():
            for level, hh, cc in zip(levels, h, costs):
                res = resolution_for_level(level)
                writer.writerow([case, level, res.cells_per_medium, res.tol_temperature,
                                 f"{hh:.10g}", f"{hh / conv - 1:.3e}", f"{1e3 * cc:.3f}"])

    lines = [
        "# Refinement study: error of the critical height vs resolution level",
        "",
        f"`python scripts/refinement_study.py{option}`"
        f" (melting-step width: {width_text}). Converged value: Richardson extrapolation of "
        f"levels {levels[-3]:g} and {levels[-1]:g} (second order). Relative error of each level "
        "against it.",
        "",
        "| case | converged H [m] | converged H [ft] | "
        + " | ".join(f"L{lv:g}" for lv in levels) + " | observed order (L1->L3) |",
        "|---|---|---|" + "---|" * len(levels) + "---|",
    ]
    worst = np.zeros(len(levels))
    for case, (h, conv, _) in table.items():
        err = np.abs(h / conv - 1)
        worst = np.maximum(worst, err)
        i1, i3 = levels.index(1.0), levels.index(3.0)
        order = math.log(max(err[i1], 1e-16) / max(err[i3], 1e-16)) / math.log(4.0)
        lines.append(f"| {case} | {conv:.6g} | {conv / FOOT:.5g} | "
                     + " | ".join(f"{e:.1e}" for e in err) + f" | {order:.2f} |")
    model_err = [ERROR_LEVEL0 * 4.0 ** (-lv) for lv in levels]
    lines += [
        "| worst case | | | " + " | ".join(f"{e:.1e}" for e in worst) + " | |",
        "| solver's error model ERROR_LEVEL0 * 4^-L | | | "
        + " | ".join(f"{e:.1e}" for e in model_err) + " | 2 |",
        "",
        "## Richardson extrapolation of levels L - 1 and L",
        "",
        "R = H_L + (H_L - H_{L-1}) / 3; relative error of R against the converged value.",
        "",
        "| case | " + " | ".join(f"L{lv:g}" for lv in levels if lv >= 1.0) + " |",
        "|---|" + "---|" * sum(lv >= 1.0 for lv in levels),
    ]
    rows, r_worst = pair_rows(table, levels, lambda r, conv, c: abs(r / conv - 1), "{:.1e}")
    lines += rows
    lines += [
        "| worst case | " + " | ".join(f"{r_worst[lv]:.1e}" for lv in sorted(r_worst)) + " |",
        "| error model RICHARDSON_ERROR_LEVEL0 * 4^-L | "
        + " | ".join(f"{RICHARDSON_ERROR_LEVEL0 * 4.0 ** -lv:.1e}"
                     if lv >= RICHARDSON_MIN_LEVEL else "(not used)" for lv in sorted(r_worst))
        + " |",
        "",
        f"(The values at L >= {levels[-2]:g} use the L{levels[-1]:g} data that define the "
        "converged value, so they are not independent.)",
        "",
        "## The a posteriori ratio: residual of R over the pair's own correction",
        "",
        "|R / H_conv - 1| / |c| with c = (H_L - H_{L-1}) / (3 R), the multiple of its own "
        "correction that the default search's estimate assumes (`a_posteriori_error`: "
        f"{RICHARDSON_RESIDUAL_RATIO:g}, or {RICHARDSON_RESIDUAL_RATIO_LEVEL0:g} for the pair "
        f"(0, 1); {RICHARDSON_RESIDUAL_RATIO_SPREAD:g} with the melting spread from the pair "
        f"({SPREAD_FINE_LEVEL:g}, {SPREAD_FINE_LEVEL + 1:g}) up).",
        "",
        "| case | " + " | ".join(f"({lv - 1:g}, {lv:g})" for lv in levels if lv >= 1.0) + " |",
        "|---|" + "---|" * sum(lv >= 1.0 for lv in levels),
    ]
    rows, ratio_worst = pair_rows(
        table, levels, lambda r, conv, c: abs(r / conv - 1) / abs(c) if c != 0.0 else math.inf,
        "{:.2f}")
    lines += rows
    lines += [
        "| worst case | " + " | ".join(f"{ratio_worst[lv]:.2f}" for lv in sorted(ratio_worst))
        + " |",
        "| assumed by the default search | "
        + " | ".join(f"{a_posteriori_error(1.0, lv - 1.0, args.melt_spread):g}"
                     for lv in sorted(ratio_worst)) + " |",
        "",
        "The solver chooses the cheapest plan whose error model is below 0.6 rtol "
        "(DISCRETISATION_SHARE): "
        + ", ".join(f"rtol {r:g} -> level {plan_for_rtol(r)[0]:g}"
                    + (" extrapolated" if plan_for_rtol(r)[1] else "")
                    for r in (1e-2, 3e-3, 1e-3, 1e-4))
        + " (plain levels alone: "
        + ", ".join(f"{level_for_rtol(r):g}" for r in (1e-2, 3e-3, 1e-3, 1e-4)) + ").",
    ]
    (OUT / f"refinement{suffix}.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))

    fig, ax = plt.subplots(figsize=(6.5, 4.5))
    for case, (h, conv, _) in table.items():
        cells = [resolution_for_level(lv).cells_per_medium for lv in levels]
        err = np.abs(h / conv - 1)
        ax.loglog(cells[:-1], err[:-1], "o-", label=case)
    cells = np.array([resolution_for_level(lv).cells_per_medium for lv in levels])
    ax.loglog(cells, model_err, "k--", label="error model (2nd order)")
    ax.set_xlabel("cells per medium (time step halves with each doubling)")
    ax.set_ylabel("relative error of the critical height [1]")
    ax.set_title("Refinement of the critical height")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(OUT / f"refinement{suffix}.png", dpi=150)


if __name__ == "__main__":
    main()
