"""Searches by signs, side by side: no-go simulations stopped at the exit against full runs.

Where the margin jumps at the root (sliding stops before rebound, or a rebound's heating fades
before the exit), the critical height is located by the margin's signs alone, and a simulation
without an event by the exit stops there (``simulate(..., until_exit=True)``) instead of
running on under the extension flux. This benchmark times the default search with that (A)
and with every simulation run in full (B: the search's ``simulate`` patched to ignore
``until_exit``), alternated in one process on one core, over the report presets and the
off-preset scenes of ``benchmarks/solver.py``. The steady rebounds run the same code in A and
B: their ratio is the control, and shows the noise of the comparison. Where sliding stops, every
height must come out the same in A and B (checked: the same signs lead to the same points).
Where the heating fades, B's full runs may show a bracket across which the margin is smooth,
and interpolate in it where A halves: such heights may differ within their estimates, and the
differences are listed.

Writes results/benchmarks/signs_only.md. Run: ``python benchmarks/signs_only.py`` (~4 min).
"""

from __future__ import annotations

import os

# One core, set before numpy/numba load: the targets are per core.
for _var in ("NUMBA_NUM_THREADS", "OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_var] = "1"

import argparse  # noqa: E402
import platform  # noqa: E402
import statistics  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))

from solver import PRESETS, off_preset_scenes  # noqa: E402

from skidmc.scene import get_preset  # noqa: E402
from skidmc.solver import critical_height, simulate  # noqa: E402
from skidmc.solver.options import exit_regime  # noqa: E402

OUT = ROOT / "results" / "benchmarks"
RTOLS = (1e-2, 3e-3, 1e-3)
# The module, not the function the package re-exports under the same name.
search_module = sys.modules["skidmc.solver.search"]


def _full_runs(model, height, **kwargs):
    """``simulate`` with every run to the horizon (B)."""
    kwargs.pop("until_exit", None)
    return simulate(model, height, **kwargs)


def _timed(scene, rtol, simulate_fn):
    search_module.simulate = simulate_fn
    start = time.perf_counter()
    res = critical_height(scene, rtol=rtol)
    return time.perf_counter() - start, res


def measure(scenes, rtol, repeats):
    """(label, exit regime, median time A [s], median time B [s], differing heights) per scene;
    differing heights: (H_A [m], H_B [m], estimate A [1], estimate B [1]) or None."""
    rows = []
    for label, scene in scenes:
        regime = exit_regime(scene)
        differing = None
        _timed(scene, rtol, simulate)   # warm-up
        times_a, times_b = [], []
        for _ in range(repeats):
            t_a, res_a = _timed(scene, rtol, simulate)
            t_b, res_b = _timed(scene, rtol, _full_runs)
            if res_a.critical_height != res_b.critical_height and regime == "fading":
                differing = (res_a.critical_height, res_b.critical_height,
                             res_a.error_estimate, res_b.error_estimate)
            elif res_a.critical_height != res_b.critical_height:
                raise AssertionError(f"{label}, rtol {rtol:g}: {res_a.critical_height!r} with "
                                     f"sign-only runs against {res_b.critical_height!r}")
            times_a.append(t_a)
            times_b.append(t_b)
        rows.append((label, regime, statistics.median(times_a), statistics.median(times_b),
                     differing))
    search_module.simulate = simulate
    return rows


def report(results, repeats, load):
    lines = [
        "# Searches by signs: no-go runs stopped at the exit against full runs "
        "(benchmarks/signs_only.py)",
        "",
        f"Machine: {os.cpu_count()} CPUs ({platform.machine()}), Python "
        f"{platform.python_version()}, one thread. Load average before the run: {load}. "
        f"Median of {repeats} alternated calls per scene and variant, in one process. *speed-up*: "
        "time with full runs / time with sign-only runs, per scene; median [min-max] over the "
        "scenes. The steady rebounds run the same code in both: the control. Where sliding "
        "stops, every height was the same in both variants; where the heating fades, the "
        "heights that differ are listed below the table.",
        "",
        "| rtol | scenes | n | speed-up | median time, sign-only | median time, full runs |",
        "|---|---|---|---|---|---|",
    ]
    for rtol, rows in results.items():
        for name, keep in (("stops sliding", lambda r: r[1] == "stops_sliding"),
                           ("heating fades", lambda r: r[1] == "fading"),
                           ("control (steady rebounds)", lambda r: r[1] == "steady"),
                           ("all", lambda r: True)):
            sel = [r for r in rows if keep(r)]
            ratios = [r[3] / r[2] for r in sel]
            lines.append(
                f"| {rtol:g} | {name} | {len(sel)} | {statistics.median(ratios):.2f} "
                f"[{min(ratios):.2f}-{max(ratios):.2f}] "
                f"| {1e3 * statistics.median(r[2] for r in sel):.2f} ms "
                f"| {1e3 * statistics.median(r[3] for r in sel):.2f} ms |")
    differing = [(rtol, r) for rtol, rows in results.items() for r in rows if r[4] is not None]
    lines += ["", f"Heights that differ between the variants (heating fades): {len(differing)}."]
    if differing:
        lines += ["", "| scene | rtol | H sign-only | H full runs | difference | estimate "
                  "sign-only | estimate full runs |", "|---|---|---|---|---|---|---|"]
        for rtol, (label, _, _, _, (h_a, h_b, e_a, e_b)) in differing:
            lines.append(f"| {label} | {rtol:g} | {h_a:.6g} m | {h_b:.6g} m | "
                         f"{h_a / h_b - 1.0:+.1e} | {e_a:.1e} | {e_b:.1e} |")
    return "\n".join(lines) + "\n"


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--repeats", type=int, default=5, help="alternated calls per variant")
    args = p.parse_args(argv)
    load = ", ".join(f"{v:.2f}" for v in os.getloadavg())
    scenes = [(name, get_preset(name)) for name in PRESETS] + off_preset_scenes()
    results = {}
    for rtol in RTOLS:
        results[rtol] = measure(scenes, rtol, args.repeats)
        print(f"rtol {rtol:g} done", flush=True)
    text = report(results, args.repeats, load)
    OUT.mkdir(parents=True, exist_ok=True)
    (OUT / "signs_only.md").write_text(text)
    print(text)


if __name__ == "__main__":
    main()
