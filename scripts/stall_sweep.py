"""Does any tight fixed-model search stall? A sweep over the fast tier's scene sets.

Every scene of ``scripts/fast_tier_error.py``'s training and test sets and a fresh broad draw
(300 scenes, seed 3) is searched with a fixed model (exact target, the default search's melting
spread, levels 0, 0.5, 1 and 1.5, melting widths 1 and 4 K) at a tight root tolerance (2e-6 on
ln H): the runs a default search makes at rtol 1e-3 to 1e-2, at many more heights near each
root. Reported: the searches that raised an error or took longer than :data:`SLOW` seconds.
Before ``physics.thermal.FREEZE_WIDTH_AFTER`` (docs/model.md, "The target as an exact
semi-infinite solid") 4 of the 6,912 raised SolverError after 135,000 steps and 2 took 1-3 s.

Run: ``python scripts/stall_sweep.py`` (~20 s on two cores); writes
results/validation/stall_sweep.md.
"""

from __future__ import annotations

import argparse
import multiprocessing
import sys
import time
from pathlib import Path

from skidmc.physics.thermal import MELT_SPREAD
from skidmc.solver import build_model, critical_height

sys.path.insert(0, str(Path(__file__).resolve().parent))
from fast_tier_error import sweep_items  # noqa: E402

OUT = Path(__file__).resolve().parents[1] / "results" / "validation"
LEVELS = (0.0, 0.5, 1.0, 1.5)
WIDTHS = (1.0, 4.0)   # [K]
ROOT_RTOL = 1e-5      # with a given model: root tolerance 2e-6 on ln H
SLOW = 0.5            # [s] per search; the median search takes a few ms


def sweep(item):
    """(set, index, [(level, width, seconds, error or None)]) for one scene."""
    kind, index, scene = item
    out = []
    for level in LEVELS:
        for width in WIDTHS:
            started = time.perf_counter()
            error = None
            try:
                model = build_model(scene, level=level, melt_width=width,
                                    melt_spread=MELT_SPREAD, target="exact")
                critical_height(scene, rtol=ROOT_RTOL, model=model)
            except Exception as exc:  # noqa: BLE001 - every failure is what this sweep reports
                error = f"{type(exc).__name__}: {exc}"
            out.append((level, width, time.perf_counter() - started, error))
    return kind, index, out


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--processes", type=int, default=2)
    args = parser.parse_args(argv)
    items = sweep_items()
    started = time.time()
    with multiprocessing.Pool(args.processes) as pool:
        rows = pool.map(sweep, items, chunksize=8)
    seconds = time.time() - started
    searches = [(kind, i, *run) for kind, i, runs in rows for run in runs]
    bad = [s for s in searches if s[5] is not None or s[4] > SLOW]
    times = sorted(s[4] for s in searches)
    lines = ["# Tight fixed-model searches over the fast tier's scene sets "
             "(scripts/stall_sweep.py)", "",
             f"{len(items)} scenes x levels {', '.join(f'{lv:g}' for lv in LEVELS)} x widths "
             f"{', '.join(f'{w:g}' for w in WIDTHS)} K = {len(searches)} searches (exact target, "
             f"spread {MELT_SPREAD:g}, root tolerance 2e-6), {seconds:.0f} s on "
             f"{args.processes} processes. Per search: median {times[len(times) // 2] * 1e3:.1f} "
             f"ms, slowest {times[-1]:.2f} s.", "",
             f"Searches that failed or took over {SLOW:g} s: {len(bad)}.", ""]
    if bad:
        lines += ["| set | scene | level | width [K] | time [s] | error |",
                  "|---|---|---|---|---|---|"]
        lines += [f"| {k} | {i} | {lv:g} | {w:g} | {t:.2f} | {e or ''} |"
                  for k, i, lv, w, t, e in bad]
        lines.append("")
    OUT.mkdir(parents=True, exist_ok=True)
    (OUT / "stall_sweep.md").write_text("\n".join(lines))
    print("\n".join(lines))


if __name__ == "__main__":
    main()
