"""What sharing the linear start saves in time: the default search with and without it.

``solver.simulate.LinearPrefix`` (docs/model.md, "Runs of one search share their linear start")
lets the runs of a search after its first skip their linear start. Its saving in kernel work is
deterministic (``scripts/linear_prefix.py``: 0.853x per scene at rtol 1e-3 on 864 scenes);
its saving in time is smaller, since the skipped steps are the cheap ones (cold cells, no
exponentials, a short flux history). This script times it side by side in one process, which
keeps the machine's drifts out of the ratio: per scene, the default search as shipped and with
every run from t = 0 (``LinearPrefix.mode`` patched to 0), alternated call by call, and the
ratio of the two medians.

Scenes: the report presets and ``benchmarks/solver.py``'s 18 off-preset scenes.

Run: ``python benchmarks/linear_prefix.py [--calls 31]`` (~1 min); writes
``results/benchmarks/linear_prefix.md``.
"""

from __future__ import annotations

import os

# One core, set before numpy/numba load: the timings are per core.
for _var in ("NUMBA_NUM_THREADS", "OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_var] = "1"

import argparse  # noqa: E402
import platform  # noqa: E402
import statistics  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

from solver import PRESETS, off_preset_scenes  # noqa: E402

from skidmc.scene import get_preset  # noqa: E402
from skidmc.solver import critical_height  # noqa: E402
from skidmc.solver.simulate import LinearPrefix  # noqa: E402

OUT = Path(__file__).resolve().parents[1] / "results" / "benchmarks"
RTOLS = (1e-3, 3e-3)


def _no_prefix(self, height):
    """LinearPrefix.mode with every run from t = 0."""
    return 0


def time_pair(scene, rtol, calls):
    """(median time shared [s], median time plain [s], simulations shared, plain) of the
    default search, alternating the two variants call by call (the order flipped each call)."""
    shipped = LinearPrefix.mode
    times = {True: [], False: []}
    sims = {}
    try:
        for call in range(calls):
            for shared in ((True, False) if call % 2 == 0 else (False, True)):
                LinearPrefix.mode = shipped if shared else _no_prefix
                start = time.perf_counter()
                res = critical_height(scene, rtol=rtol)
                times[shared].append(time.perf_counter() - start)
                sims[shared] = res.evaluations
    finally:
        LinearPrefix.mode = shipped
    return (statistics.median(times[True]), statistics.median(times[False]), sims[True],
            sims[False])


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--calls", type=int, default=31, help="timed calls per variant")
    args = parser.parse_args(argv)
    scenes = [(name, get_preset(name), "presets") for name in PRESETS]
    scenes += [(name, scene, "off-preset") for name, scene in off_preset_scenes()]
    for rtol in RTOLS:   # compile (or load) every kernel both variants use
        for name in ("paper-quartz", "paper-gold"):
            critical_height(get_preset(name), rtol=rtol)
    rows = []
    for rtol in RTOLS:
        for name, scene, kind in scenes:
            shared, plain, sims_shared, sims_plain = time_pair(scene, rtol, args.calls)
            rows.append((rtol, kind, name, shared, plain, sims_shared, sims_plain))
            print(f"rtol {rtol:g} {name}: {shared * 1e3:.3f} ms shared, {plain * 1e3:.3f} ms "
                  f"plain, ratio {plain / shared:.3f}", flush=True)
    lines = ["# Sharing the linear start, timed side by side (benchmarks/linear_prefix.py)", "",
             f"Machine: {os.cpu_count()} CPUs ({platform.machine()}), Python "
             f"{platform.python_version()}, one thread. Per scene, {args.calls} calls of the "
             "default search as shipped (*shared*) and as many with every run from t = 0 "
             "(*plain*), alternated call by call in one process; *ratio*: plain median over "
             "shared median (> 1: sharing is faster). Per set: the median over its scenes.", "",
             "| rtol | scenes | n | median time shared | median time plain | median ratio "
             "| ratio range |", "|---|---|---|---|---|---|---|"]
    for rtol in RTOLS:
        for kind in ("presets", "off-preset", "all"):
            sel = [r for r in rows if r[0] == rtol and kind in ("all", r[1])]
            ratios = [r[4] / r[3] for r in sel]
            shared = statistics.median(r[3] for r in sel)
            plain = statistics.median(r[4] for r in sel)
            lines.append(
                f"| {rtol:g} | {kind} | {len(sel)} | {shared * 1e3:.2f} ms | {plain * 1e3:.2f} ms "
                f"| {statistics.median(ratios):.3f} | {min(ratios):.2f}-{max(ratios):.2f} |")
    lines += ["", "## Per scene", "", "| rtol | scene | shared | plain | ratio | simulations "
              "shared | plain |", "|---|---|---|---|---|---|---|"]
    lines += [f"| {r[0]:g} | {r[2]} | {r[3] * 1e3:.3f} ms | {r[4] * 1e3:.3f} ms "
              f"| {r[4] / r[3]:.3f} | {r[5]} | {r[6]} |" for r in rows]
    lines += ["", "Command: `python benchmarks/linear_prefix.py`."]
    OUT.mkdir(parents=True, exist_ok=True)
    (OUT / "linear_prefix.md").write_text("\n".join(lines) + "\n")


if __name__ == "__main__":
    main()
