"""The Python around the kernel: per-height time spent outside the compiled simulation.

A critical height is ~4-6 simulations (the compiled kernel,
``skidmc.physics.thermal.simulate_kernel``) and the Python that drives them: the search's
options, the scene's models at each level, the fast tier's guess, each run's arguments and
outcome, the result. At the shipped studies' rtol (1e-2) that Python was a fifth of a height
(docs/performance.md). This benchmark measures it on study scenes (``benchmarks/study_scenes.py``,
the tail's draw): each pass solves every scene once at one rtol, its wall time and the kernel's
own time (a timer around each kernel call) summed; per rtol the best of ``--passes`` passes.
With ``--base SRC`` another source tree (``git archive <commit> src | tar -x -C /tmp/base``) is
measured the same way in its own process, the two trees taking turns ``--rounds`` times, and
each tree's heights are checked equal to the other's bit for bit.

Usage::

    python benchmarks/outside_kernel.py                              # this tree
    python benchmarks/outside_kernel.py --base /tmp/base/src         # side by side

Writes ``results/benchmarks/outside_kernel.md`` (``--out``).
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import platform
import statistics
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
if "PYTHONPATH" not in os.environ:
    sys.path.insert(0, str(ROOT / "src"))
sys.path.insert(0, str(ROOT / "benchmarks"))

import study_scenes  # noqa: E402

RTOLS = (1e-2, 1e-3)


def measure(n, seed, passes):
    """{rtol: (seconds per height, kernel seconds per height, digest of the heights)}."""
    import skidmc
    import skidmc.solver.simulate  # noqa: F401 - the module (skidmc.solver.simulate is a function)

    simulate_module = sys.modules["skidmc.solver.simulate"]
    kernel = simulate_module.simulate_kernel
    spent = [0.0]

    def timed(*args):
        t = time.perf_counter()
        try:
            return kernel(*args)
        finally:
            spent[0] += time.perf_counter() - t

    scenes = [scene for _, _, scene in study_scenes.draw(n, seed)]
    out = {}
    for rtol in RTOLS:
        digest = hashlib.sha256()
        for scene in scenes:   # warm: kernels loaded, tables parsed
            res = skidmc.critical_height(scene, rtol=rtol)
            digest.update(repr((res.critical_height, res.error_estimate,
                                res.evaluations)).encode())
        best = None
        simulate_module.simulate_kernel = timed
        try:
            for _ in range(passes):
                spent[0] = 0.0
                t = time.perf_counter()
                for scene in scenes:
                    skidmc.critical_height(scene, rtol=rtol)
                wall = time.perf_counter() - t
                if best is None or wall < best[0]:
                    best = (wall, spent[0])
        finally:
            simulate_module.simulate_kernel = kernel
        out[repr(rtol)] = (best[0] / len(scenes), best[1] / len(scenes), digest.hexdigest())
    return {"scenes": len(scenes), "package": skidmc.__file__, "rows": out}


def _child(args, src):
    env = dict(os.environ, PYTHONPATH=str(src))
    env.pop("NUMBA_CACHE_DIR", None)   # each tree its own cache (skidmc._numba_cache)
    out = subprocess.run([sys.executable, __file__, "--child", "--n", str(args.n), "--seed",
                          str(args.seed), "--passes", str(args.passes)], env=env,
                         capture_output=True, text=True, check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=70, help="samples per study (default 70)")
    ap.add_argument("--seed", type=int, default=45)
    ap.add_argument("--passes", type=int, default=5)
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--base", help="the src folder of another tree, measured side by side")
    ap.add_argument("--out", default=str(ROOT / "results" / "benchmarks" / "outside_kernel.md"))
    ap.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.child:
        print(json.dumps(measure(args.n, args.seed, args.passes)))
        return
    load_before = os.getloadavg()
    here = ROOT / "src"
    trees = [("this", here)] + ([("base", Path(args.base))] if args.base else [])
    runs = {name: [] for name, _ in trees}
    for r in range(args.rounds):
        for name, src in trees:
            runs[name].append(_child(args, src))
            print(f"round {r + 1} {name}: " + ", ".join(
                f"rtol {k}: {v[0] * 1e3:.3f} ms" for k, v in runs[name][-1]["rows"].items()),
                flush=True)
    lines = [
        "# The Python around the kernel: per-height time outside the compiled simulation",
        "",
        f"Generated by `python benchmarks/outside_kernel.py --n {args.n} --seed {args.seed} "
        f"--passes {args.passes} --rounds {args.rounds}"
        + (" --base BASE`" if args.base else "`") + f": {runs['this'][0]['scenes']} study "
        "scenes (`benchmarks/study_scenes.py`), each pass every scene once in one warm process "
        "per tree; per round the best of the passes; the trees take turns. Outside = the "
        "height's time less the kernel's (a timer around each `simulate_kernel` call).",
        "",
        f"Machine: {os.cpu_count()} CPUs ({platform.machine()}), Python "
        f"{platform.python_version()}; load average {', '.join(f'{x:.2f}' for x in load_before)}"
        f" before, {', '.join(f'{x:.2f}' for x in os.getloadavg())} after.",
        "",
        "| rtol | tree | per height [ms] (median of rounds) | kernel [ms] | outside [us] | "
        "outside share |",
        "|---|---|---|---|---|---|",
    ]
    for rtol in RTOLS:
        key = repr(rtol)
        for name, src in trees:
            per = statistics.median(x["rows"][key][0] for x in runs[name])
            ker = statistics.median(x["rows"][key][1] for x in runs[name])
            label = "this tree" if name == "this" else f"base (`{src}`)"
            lines.append(f"| {rtol:g} | {label} | {per * 1e3:.3f} | {ker * 1e3:.3f} | "
                         f"{(per - ker) * 1e6:.0f} | {(per - ker) / per:.1%} |")
    if args.base:
        lines += ["", "Ratio this / base, per round (the same machine load): " + "; ".join(
            f"rtol {rtol:g}: " + ", ".join(
                f"{a['rows'][repr(rtol)][0] / b['rows'][repr(rtol)][0]:.3f}"
                for a, b in zip(runs["this"], runs["base"])) for rtol in RTOLS) + "."]
        same = all(a["rows"][k][2] == b["rows"][k][2] for a, b in zip(runs["this"], runs["base"])
                   for k in a["rows"])
        lines += ["", f"Heights, estimates and simulation counts identical between the trees: "
                  f"{same}."]
    Path(args.out).write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
