"""Where a critical height's cost and error come from: space against time, and melting.

Issue 16 asks for rtol = 1e-3 at ~2 ms per height (the fixed melting step cost ~10 ms). This
benchmark measures the facts any lever has to start from, on the report presets and two off-preset
scenes, with the melting step at 1 K (the width rtol = 1e-3 sets, ``melt_width_for_rtol``):

1. **Error split.** The critical height at levels 0, 1 and 2, against level 3, with the level's
   mesh and time tolerance ("total"), the level's mesh with level 3's time tolerance ("space"),
   and level 3's mesh with the level's time tolerance ("time"). Which part dominates decides
   whether cheaper time steps can buy anything.
2. **Steps through melting.** One simulation at the critical height, level 1.5: accepted and
   rejected steps, Newton iterations and wall time, with melting at 1, 2 and 4 K, without
   melting, and inert (no reaction, no melting). The melting front crosses the HE cells one by
   one; each crossing puts a kink into the temperature histories of its neighbours, which the
   step controller resolves.
3. **First cell.** The error at levels 0-2 with the first HE cell 0.25, 0.5 (the shipped
   ``BASE_RESOLUTION``) and 1.0 reaction zones wide at level 0.
4. **Melting spread over each cell** (``melt_spread``, the default search's since issue 16's
   fifth pass): part 2's simulation with each HE cell's step widened to its own temperature
   range, and the default search at rtol = 1e-3 with the fixed step (0) and with the spread
   over the report presets and the 16 off-preset scenes of ``benchmarks/solver.py``: time,
   simulations, error against a tight solve with the fixed step (rtol 3e-5) and the share of
   estimates that bound it.

Writes results/benchmarks/cost_breakdown.{csv,md}. Run: ``python benchmarks/cost_breakdown.py``
(~5 min on one core). Times are medians of repeats on a shared machine: read them as ratios.
"""

from __future__ import annotations

import csv
import dataclasses
import math
import platform
import statistics
import sys
import time
from pathlib import Path

from skidmc.physics.thermal import MELT_SPREAD
from skidmc.scene import get_preset, make_scene
from skidmc.scene.validation import off_preset_scenes
from skidmc.solver import build_model, critical_height, simulate
from skidmc.solver.model import BASE_RESOLUTION, Resolution, level_resolution

OUT = Path(__file__).resolve().parents[1] / "results" / "benchmarks"
MELT_WIDTH = 1.0          # [K]: the width rtol = 1e-3 uses
REFERENCE_LEVEL = 3.0
ROOT_RTOL = 1e-5          # root tolerance 2e-6 on ln H: far below every error measured here
LEVELS = (0.0, 1.0, 2.0)
REPEATS = 7


def scenes():
    """(label, scene): four report presets, a pendulum steel scene and E/R = 15,000 K."""
    rate_575 = 5e19 * math.exp(-26300.0 / 575.0 + 15000.0 / 575.0)
    return [
        ("paper-quartz", get_preset("paper-quartz")),
        ("paper-alumina-smooth", get_preset("paper-alumina-smooth")),
        ("paper-gold", get_preset("paper-gold")),
        ("paper2-quartz", get_preset("paper2-quartz")),
        ("steel mu=0.1 pendulum", make_scene({"target": "steel"}, preset="paper-quartz",
                                             mu=0.1)),
        ("Ta15000-series1", make_scene(preset="paper-quartz", **{
            "kinetics.activation_temperature": 15000.0, "kinetics.prefactor": rate_575})),
    ]


def resolution(level, *, mesh_level=None, time_level=None, first_fraction=None,
               melt_width=MELT_WIDTH, melt_spread=0.0):
    """A Resolution whose mesh comes from ``mesh_level`` and time tolerance from
    ``time_level`` (each defaulting to ``level``); ``first_fraction`` replaces the level-0 first
    cell fraction (halved per level as the shipped levels do); melting step ``melt_width`` [K],
    spread ``melt_spread`` [1]."""
    cells, fraction, _ = level_resolution(level if mesh_level is None else mesh_level)
    _, _, tol = level_resolution(level if time_level is None else time_level)
    if first_fraction is not None:
        fraction = first_fraction * 2.0 ** -(level if mesh_level is None else mesh_level)
    return Resolution(int(cells), float(fraction), float(tol), float(melt_width),
                      float(melt_spread))


def height(scene, res, melting=True):
    """Critical height [m] with a fixed resolution and a tight root."""
    model = build_model(scene, res, melting=melting)
    return critical_height(scene, rtol=ROOT_RTOL, model=model).critical_height


def simulation_cost(scene, h, level, melt_width, melting=True, inert=False, melt_spread=0.0):
    """(median wall time [s], steps, rejected) of one simulation at ``h`` [m]."""
    model = build_model(scene, resolution(level, melt_width=melt_width, melt_spread=melt_spread),
                        melting=melting and not inert)
    if inert:
        model = dataclasses.replace(model, prefactor=0.0)
    sim = simulate(model, h)
    times = []
    for _ in range(REPEATS):
        t0 = time.perf_counter()
        sim = simulate(model, h)
        times.append(time.perf_counter() - t0)
    return statistics.median(times), sim.steps, sim.rejected


def main():
    rows, split, steps, first = [], [], [], []
    for label, scene in scenes():
        ref_res = resolution(REFERENCE_LEVEL)
        ref = height(scene, ref_res)
        print(f"{label}: reference H = {ref:.6g} m", flush=True)
        for level in LEVELS:
            total = height(scene, resolution(level)) / ref - 1.0
            space = height(scene, resolution(level, time_level=REFERENCE_LEVEL)) / ref - 1.0
            tim = height(scene, resolution(level, mesh_level=REFERENCE_LEVEL)) / ref - 1.0
            split.append((label, level, total, space, tim))
            rows.append(("split", label, level, "", f"{total:.3e}", f"{space:.3e}",
                         f"{tim:.3e}", "", "", ""))
        for variant, width, melting, inert, spread in (
                ("melting w = 1 K", 1.0, True, False, 0.0),
                ("melting w = 2 K", 2.0, True, False, 0.0),
                ("melting w = 4 K", 4.0, True, False, 0.0),
                (f"melting w = 1 K, spread {MELT_SPREAD:g}", 1.0, True, False, MELT_SPREAD),
                (f"melting w = 4 K, spread {MELT_SPREAD:g}", 4.0, True, False, MELT_SPREAD),
                ("no melting", 1.0, False, False, 0.0),
                ("inert", 1.0, False, True, 0.0)):
            wall, n_steps, n_rej = simulation_cost(scene, ref, 1.5, width, melting, inert,
                                                   spread)
            steps.append((label, variant, wall, n_steps, n_rej))
            rows.append(("steps", label, 1.5, variant, "", "", "", f"{wall:.4e}", n_steps, n_rej))
        for fraction in (0.25, BASE_RESOLUTION.first_cell_fraction, 1.0):
            errs = [height(scene, resolution(level, first_fraction=fraction)) / ref - 1.0
                    for level in LEVELS]
            first.append((label, fraction, errs))
            for level, err in zip(LEVELS, errs):
                rows.append(("first_cell", label, level, f"{fraction:g}", f"{err:.3e}", "", "",
                             "", "", ""))

    spread_rows = spread_search()
    for row in spread_rows:
        rows.append(("spread_search", row[0], "", f"spread {row[1]:g}", f"{row[4]:.3e}", "", "",
                     f"{row[2]:.4e}", row[3], ""))

    OUT.mkdir(parents=True, exist_ok=True)
    with open(OUT / "cost_breakdown.csv", "w", newline="") as fh:
        writer = csv.writer(fh)
        writer.writerow(["part", "scene", "level", "variant", "error_total", "error_space",
                         "error_time", "wall_s", "steps", "rejected"])
        writer.writerows(rows)

    lines = [
        "# Where the cost and the error of a critical height come from "
        "(benchmarks/cost_breakdown.py)", "",
        f"Machine: {platform.machine()}, Python {sys.version.split()[0]}, one thread. Melting "
        f"step {MELT_WIDTH:g} K (rtol = 1e-3's width) unless stated; errors are relative to "
        f"level {REFERENCE_LEVEL:g} with the same width; root tolerance 2e-6 on ln H.", "",
        "## 1. Error split: space against time", "",
        "space = the level's mesh with level 3's time tolerance; time = level 3's mesh with "
        "the level's tolerance.", "",
        "| scene | level | total | space | time | time share |", "|---|---|---|---|---|---|",
    ]
    for label, level, total, space, tim in split:
        share = abs(tim) / (abs(space) + abs(tim)) if (space or tim) else 0.0
        lines.append(f"| {label} | {level:g} | {total:+.2e} | {space:+.2e} | {tim:+.2e} | "
                     f"{share:.0%} |")
    lines += ["", "## 2. One simulation at the critical height, level 1.5", "",
              "| scene | variant | time | steps | rejected | time / inert |",
              "|---|---|---|---|---|---|"]
    inert = {label: wall for label, variant, wall, _, _ in steps if variant == "inert"}
    for label, variant, wall, n_steps, n_rej in steps:
        lines.append(f"| {label} | {variant} | {wall * 1e3:.2f} ms | {n_steps} | {n_rej} | "
                     f"{wall / inert[label]:.1f} |")
    lines += ["", "## 3. First HE cell (fraction of the reaction zone at level 0)", "",
              "| scene | first cell | " + " | ".join(f"level {lv:g}" for lv in LEVELS) + " |",
              "|---|---|" + "---|" * len(LEVELS)]
    for label, fraction, errs in first:
        lines.append(f"| {label} | {fraction:g} | "
                     + " | ".join(f"{e:+.2e}" for e in errs) + " |")
    lines += spread_lines(spread_rows)
    (OUT / "cost_breakdown.md").write_text("\n".join(lines) + "\n")
    print(f"wrote {OUT / 'cost_breakdown.md'}")


SEARCH_RTOL = 1e-3
SEARCH_REFERENCE_RTOL = 3e-5
SEARCH_REPEATS = 3
PRESETS = ("paper-quartz", "paper-alumina-smooth", "paper-alumina-rough", "paper-gold",
           "paper2-quartz")


def spread_search():
    """Rows (scene, spread, median time [s], simulations, error, estimate) of the default search
    at SEARCH_RTOL without and with the melting spread, errors against the fixed step at
    SEARCH_REFERENCE_RTOL."""
    out = []
    for label, scene in ([(name, get_preset(name)) for name in PRESETS] + off_preset_scenes()):
        ref = critical_height(scene, rtol=SEARCH_REFERENCE_RTOL, melt_spread=0.0,
                              target="mesh")
        for spread in (0.0, MELT_SPREAD):
            res = critical_height(scene, rtol=SEARCH_RTOL, melt_spread=spread)
            times = []
            for _ in range(SEARCH_REPEATS):
                t0 = time.perf_counter()
                res = critical_height(scene, rtol=SEARCH_RTOL, melt_spread=spread)
                times.append(time.perf_counter() - t0)
            if res.censored or ref.censored:
                continue
            error = abs(res.critical_height / ref.critical_height - 1.0)
            out.append((label, spread, statistics.median(times), res.evaluations, error,
                        res.error_estimate))
        print(f"{label}: spread searches done", flush=True)
    return out


def spread_lines(rows):
    """Markdown of part 4."""
    lines = ["", f"## 4. Default search at rtol = {SEARCH_RTOL:g}, without and with the melting "
             f"spread ({MELT_SPREAD:g})", "",
             f"Error against the fixed step at rtol = {SEARCH_REFERENCE_RTOL:g}; time the "
             f"median of {SEARCH_REPEATS} repeats.", "",
             "| scene | spread | time | simulations | error | estimate | error / estimate |",
             "|---|---|---|---|---|---|---|"]
    for label, spread, wall, sims, error, estimate in rows:
        lines.append(f"| {label} | {spread:g} | {wall * 1e3:.1f} ms | {sims} | {error:.1e} | "
                     f"{estimate:.1e} | {error / estimate:.2f} |")
    lines += ["", "| spread | median time, presets | median time, all | worst error | "
              "worst error / estimate | estimate bounds error |", "|---|---|---|---|---|---|"]
    for spread in (0.0, MELT_SPREAD):
        sel = [r for r in rows if r[1] == spread]
        presets = [r[2] for r in sel if r[0] in PRESETS]
        ratios = [r[4] / r[5] for r in sel]
        lines.append(
            f"| {spread:g} | {statistics.median(presets) * 1e3:.1f} ms | "
            f"{statistics.median(r[2] for r in sel) * 1e3:.1f} ms | {max(r[4] for r in sel):.1e} | "
            f"{max(ratios):.2f} | {sum(q <= 1.0 for q in ratios)}/{len(ratios)} |")
    return lines


if __name__ == "__main__":
    main()
