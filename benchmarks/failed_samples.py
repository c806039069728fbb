"""How long a sample the solver cannot finish takes to fail: with and without the stall cap.

Issue 44: scenes that pass validation but cannot be integrated (an implausible heat of fusion, a
prefactor that overflows) end as failed samples with their reason (``SceneUnsolvable``). One of
them, a melting step with ``he.heat_of_fusion = 1e10 J/kg``, used to run one simulation to the
global cap of 200,000 step attempts (``solver.simulate.MAX_STEPS``), each ~50x a normal attempt's
cost through failing Newton iterations. ``solver.simulate.stall_cap`` now stops a run at
``STALL_FACTOR`` x the most attempts of the earlier runs of its search at its level (at least
``STALL_FLOOR`` and ``STALL_FLOOR_LEVEL0 x 2^level``), and at ``STALL_ATTEMPTS_LEVEL0 x
2^level`` attempts in any case. This
script times each failing scene side by side in one process, alternating the shipped caps
("after") with the old one (``stall_cap`` patched to ``MAX_STEPS``, "before"), and writes the
median seconds per failed sample. The solvable scenes' results
cannot change unless one of their runs reaches the cap; the presets are solved both ways and
compared bit for bit.

Run: ``python benchmarks/failed_samples.py [--calls 1]`` (~1 min per call on an idle
machine); writes ``results/benchmarks/failed_samples.md``. The machine may be shared: the
ratio, taken side by side, is what to read.
"""

from __future__ import annotations

import os

# One core, set before numpy/numba load: the timings are per core.
for _var in ("NUMBA_NUM_THREADS", "OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_var] = "1"

import argparse  # noqa: E402
import importlib  # noqa: E402
import platform  # noqa: E402
import statistics  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

from skidmc.scene import PRESETS, get_preset, make_scene  # noqa: E402
from skidmc.solver import critical_height  # noqa: E402

OUT = Path(__file__).resolve().parents[1] / "results" / "benchmarks"

#: The failing scenes: paper-quartz with one input far outside its plausible range.
CASES = {
    "he.heat_of_fusion = 1e10 J/kg": {"he.heat_of_fusion": "1e10 J/kg"},
    "he.heat_of_fusion = 1e30 J/kg": {"he.heat_of_fusion": "1e30 J/kg"},
    "kinetics.prefactor = 1e300 1/s": {"kinetics.prefactor": "1e300 1/s"},
}


def _failure(scene) -> tuple[float, str]:
    """Seconds until critical_height gives up, and its reason (first 90 characters)."""
    t0 = time.perf_counter()
    try:
        res = critical_height(scene)
    except Exception as exc:  # noqa: BLE001 - the failure is what is timed
        return time.perf_counter() - t0, f"{type(exc).__name__}: {exc}"[:200]
    return time.perf_counter() - t0, f"solved: {res.critical_height:.6g} m"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--calls", type=int, default=1, help="timed calls per case and cap")
    args = parser.parse_args()
    sim = importlib.import_module("skidmc.solver.simulate")  # the module, not the function
    shipped = sim.stall_cap

    def old_cap(model, prefix=None):
        return sim.MAX_STEPS

    critical_height(get_preset("paper-quartz"))  # kernels loaded before any timing
    rows = []
    for label, overrides in CASES.items():
        scene = make_scene(overrides, preset="paper-quartz")
        times = {"before": [], "after": []}
        reasons = {}
        for _ in range(args.calls):
            for which, cap in (("after", shipped), ("before", old_cap)):
                sim.stall_cap = cap
                try:
                    seconds, reasons[which] = _failure(scene)
                finally:
                    sim.stall_cap = shipped
                times[which].append(seconds)
        before, after = (statistics.median(times[k]) for k in ("before", "after"))
        rows.append((label, before, after, reasons["after"]))
        print(f"{label}: before {before:.3g} s, after {after:.3g} s; {reasons['after'][:120]}",
              flush=True)
    same = []
    for name in PRESETS:
        a = critical_height(get_preset(name))
        sim.stall_cap = old_cap
        try:
            b = critical_height(get_preset(name))
        finally:
            sim.stall_cap = shipped
        same.append((name, a.critical_height == b.critical_height
                     and a.evaluations == b.evaluations))
    lines = ["# Seconds per failed sample: the stall cap", "",
             f"`python benchmarks/failed_samples.py --calls {args.calls}` on "
             f"{platform.node()} ({os.cpu_count()} CPUs, possibly shared: read the ratio), "
             f"{time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}. Median of "
             f"{args.calls} calls per case, the caps alternated call by call in one process. "
             "Before: every run capped at 200,000 step attempts; after: `stall_cap`, "
             f"{sim.STALL_FACTOR} x the most attempts of the earlier runs of the search at "
             f"its level (at least {sim.STALL_FLOOR:,} and {sim.STALL_FLOOR_LEVEL0:,} x "
             f"2^level) and {sim.STALL_ATTEMPTS_LEVEL0:,} x "
             "2^level (at most 200,000).", "",
             "| paper-quartz with | before [s] | after [s] | ratio | reason (after) |",
             "|---|---|---|---|---|"]
    lines += [f"| {label} | {b:.3g} | {a:.3g} | {b / a:.3g} | {why} |"
              for label, b, a, why in rows]
    lines += ["", "Presets solved both ways, same height and evaluations: "
              + ", ".join(f"{name} {'yes' if ok else 'NO'}" for name, ok in same) + "."]
    OUT.mkdir(parents=True, exist_ok=True)
    (OUT / "failed_samples.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
