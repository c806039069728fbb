"""Space against time in the default search's discretisation (melting spread over each cell).

``benchmarks/cost_breakdown.py`` part 1 splits a level's error into its mesh's and its time
steps' parts with the fixed melting step (``melt_spread=0``), on six scenes. The default search
spreads each HE cell's step over the cell's own temperature range
(:data:`skidmc.physics.thermal.MELT_SPREAD`), which removes most of the steps the fixed step
spent on melting kinks, and so moves the balance between the two. This benchmark measures the
split as the default search sees it, on the report presets and the off-preset scenes of
``benchmarks/solver.py``, with the melting width rtol = 1e-3 sets (1 K), at the levels of its
first Richardson pair (0.5 and 1.5):

* **total**: the critical height at level L (its mesh and its step tolerance) against the
  reference, level 3's mesh and tolerance;
* **space**: level L's mesh with level 3's tolerance; **time**: level 3's mesh with level L's
  tolerance (as in cost_breakdown.py part 1);
* the scene's **regime** (``skidmc.solver.options.exit_regime``): "steady" rebounds, whose root
  the search finds along the margin's go side, against "stops_sliding" and "fading" ones, whose
  margin jumps at the root and is located by its signs;
* **one level looser in time at L = 1.5**: level 1.5's mesh with level 0.5's tolerance, the
  time error that tolerance leaves (against level 1.5's mesh with level 3's tolerance) and the
  Newton iterations of one simulation at the level's critical height (times 0.995 and 1.005,
  both run to the horizon), against level 1.5's own tolerance. A Richardson pair (0.5, 1.5)
  whose fine level took level 0.5's tolerance would cancel no time error: that error would
  stay in the extrapolated height, outside the pair's a posteriori estimate.

Counts, not timings (deterministic: iterations and steps). Writes
results/benchmarks/space_time_split.md. Run: ``python benchmarks/space_time_split.py``
(~15 s on one core).
"""

from __future__ import annotations

import os

for _var in ("NUMBA_NUM_THREADS", "OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_var] = "1"

import statistics  # noqa: E402
import sys  # noqa: E402
from pathlib import Path  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))

from cost_breakdown import MELT_WIDTH, height  # noqa: E402
from cost_breakdown import resolution as split_resolution  # noqa: E402
from solver import PRESETS, off_preset_scenes  # noqa: E402

from skidmc.physics.thermal import MELT_SPREAD  # noqa: E402
from skidmc.scene import get_preset  # noqa: E402
from skidmc.solver import build_model, simulate  # noqa: E402
from skidmc.solver.options import exit_regime  # noqa: E402

OUT = ROOT / "results" / "benchmarks"
REFERENCE_LEVEL = 3.0
LEVELS = (0.5, 1.5)
FINE = 1.5
LOOSE_TIME_LEVEL = 0.5  # one level looser than FINE


def resolution(mesh_level, time_level):
    """Resolution with ``mesh_level``'s mesh and ``time_level``'s step tolerance, the melting
    width 1 K and the default search's spread (cost_breakdown.py's, with the spread)."""
    return split_resolution(mesh_level, time_level=time_level, melt_width=MELT_WIDTH,
                            melt_spread=MELT_SPREAD)


def newton_iterations(scene, mesh_level, time_level, h):
    """Newton iterations of one full simulation at ``h`` [m] (the kernel's own count)."""
    model = build_model(scene, resolution(mesh_level, time_level))
    return simulate(model, h).newton_iterations


def measure(label, scene):
    """One scene's rows: per level (total, space, time), and the looser-time variant."""
    heights = {}

    def h(mesh_level, time_level):   # each resolution searched once (tight root)
        key = (mesh_level, time_level)
        if key not in heights:
            heights[key] = height(scene, resolution(mesh_level, time_level))
        return heights[key]

    ref = h(REFERENCE_LEVEL, REFERENCE_LEVEL)
    out = {"scene": label, "regime": exit_regime(scene), "levels": {}}
    for level in LEVELS:
        out["levels"][level] = (h(level, level) / ref - 1.0,
                                h(level, REFERENCE_LEVEL) / ref - 1.0,
                                h(REFERENCE_LEVEL, level) / ref - 1.0)
    fine_space = h(FINE, REFERENCE_LEVEL)
    fine = h(FINE, FINE)
    loose = h(FINE, LOOSE_TIME_LEVEL)
    out["loose_time_error"] = loose / fine_space - 1.0
    out["fine_time_error"] = fine / fine_space - 1.0
    its = [newton_iterations(scene, FINE, tl, fine * k)
           for tl in (FINE, LOOSE_TIME_LEVEL) for k in (0.995, 1.005)]
    out["iteration_ratio"] = (its[0] + its[1]) / (its[2] + its[3])
    return out


def main():
    scenes = [(name, get_preset(name)) for name in PRESETS] + off_preset_scenes()
    rows = []
    for label, scene in scenes:
        rows.append(measure(label, scene))
        print(f"{label}: done", flush=True)

    lines = [
        "# Space against time with the melting spread (benchmarks/space_time_split.py)", "",
        f"Melting width {MELT_WIDTH:g} K (rtol = 1e-3's), spread {MELT_SPREAD:g} (the default "
        f"search's). Errors are relative to level {REFERENCE_LEVEL:g} (mesh and tolerance); "
        "space = the level's mesh with level 3's tolerance, time = level 3's mesh with the "
        "level's tolerance; root tolerance 2e-6 on ln H. Regime: how the scene's heating ends "
        "(steady rebounds are searched along the margin's go side; stops_sliding and fading "
        "ones by the margin's signs).", "",
        "| scene | regime | level | total | space | time | time share |",
        "|---|---|---|---|---|---|---|",
    ]

    def share(space, tim):
        return abs(tim) / (abs(space) + abs(tim)) if (space or tim) else 0.0

    for r in rows:
        for level, (total, space, tim) in r["levels"].items():
            lines.append(f"| {r['scene']} | {r['regime']} | {level:g} | {total:+.2e} | "
                         f"{space:+.2e} | {tim:+.2e} | {share(space, tim):.0%} |")
    lines += ["", f"## Level {FINE:g} one level looser in time (level "
              f"{LOOSE_TIME_LEVEL:g}'s tolerance)", "",
              f"time error = against level {FINE:g}'s mesh with level 3's tolerance; "
              "iterations = Newton iterations of level 1.5's own tolerance over the looser "
              "one's, for one simulation at 0.995 and 1.005 of the critical height (to the "
              "horizon).", "",
              "| scene | regime | time error, own | time error, looser | iterations own / looser |",
              "|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r['scene']} | {r['regime']} | {r['fine_time_error']:+.2e} | "
                     f"{r['loose_time_error']:+.2e} | {r['iteration_ratio']:.2f} |")
    lines += ["", "## By regime", "",
              "| regime | scenes | time share at 1.5, median (range) | time error at 1.5 "
              "(range) | looser: time error (range) | iterations own / looser, median |",
              "|---|---|---|---|---|---|"]
    for regime in ("steady", "stops_sliding", "fading"):
        sel = [r for r in rows if r["regime"] == regime]
        if not sel:
            continue
        shares = [share(*r["levels"][FINE][1:]) for r in sel]
        own = [abs(r["fine_time_error"]) for r in sel]
        loose = [abs(r["loose_time_error"]) for r in sel]
        lines.append(
            f"| {regime} | {len(sel)} | {statistics.median(shares):.0%} "
            f"({min(shares):.0%}-{max(shares):.0%}) | {min(own):.1e}-{max(own):.1e} | "
            f"{min(loose):.1e}-{max(loose):.1e} | "
            f"{statistics.median(r['iteration_ratio'] for r in sel):.2f} |")
    OUT.mkdir(parents=True, exist_ok=True)
    (OUT / "space_time_split.md").write_text("\n".join(lines) + "\n")
    print(f"wrote {OUT / 'space_time_split.md'}")


if __name__ == "__main__":
    main()
