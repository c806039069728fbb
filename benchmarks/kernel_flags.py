"""The thermal kernel's compile options, side by side: speed and what they change in the results.

``skidmc.physics.thermal`` compiles its kernels with ``_JIT`` (``error_model="numpy"``,
``fastmath={"contract"}``). This benchmark compiles the same source three more times, with only
that line changed, as standalone modules (the file imports nothing of skidmc):

* ``python``: numba's defaults (``error_model="python"``, no fast-math), what the kernels used
  before; every division then carries a test for a zero divisor;
* ``numpy``: ``error_model="numpy"`` alone;
* ``shipped``: the module's own ``_JIT``;
* ``fastmath``: numba's full ``fastmath=True`` (for scale only: it lets LLVM assume no nan or
  inf, which the integrator's finiteness checks rely on, so it is not an option).

Then, for the report presets and the first off-preset scenes of ``benchmarks/solver.py``, at
levels 0.5 and 1.5 (rtol 1e-3's pair, melting width 1 K, the default spread), at 0.995 and
1.005 of each scene's critical height: the best of 15 alternated calls of each variant's
``simulate_kernel`` on the same arguments, the time ratio to ``python`` (> 1: faster), and
the largest relative change of the event time and the step count against ``python``. Then the
search itself: the default ``critical_height`` at rtol 1e-3 over the presets and the 18
off-preset scenes with ``skidmc.solver.simulate``'s kernel swapped between ``python`` and
``shipped`` (alternated, best of 3, three rounds): the ratio per height, and the largest
relative change of the height.

Writes results/benchmarks/kernel_flags.md. Run: ``python benchmarks/kernel_flags.py`` (~30 s).
"""

from __future__ import annotations

import os

# One core, set before numpy/numba load: the targets are per core.
for _var in ("NUMBA_NUM_THREADS", "OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_var] = "1"

import argparse  # noqa: E402
import importlib.util  # noqa: E402
import math  # noqa: E402
import platform  # noqa: E402
import re  # noqa: E402
import statistics  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))

from solver import PRESETS, off_preset_scenes  # noqa: E402
from timing import best_time  # noqa: E402

import skidmc.physics.thermal as thermal  # noqa: E402
from skidmc.scene import get_preset  # noqa: E402
from skidmc.solver import build_model, critical_height  # noqa: E402
from skidmc.solver.simulate import kernel_arguments  # noqa: E402

OUT = ROOT / "results" / "benchmarks"
#: The variants' ``_JIT`` lines (``cache=False``: each is compiled afresh in this process).
VARIANTS = {
    "python": 'dict(cache=False)',
    "numpy": 'dict(cache=False, error_model="numpy")',
    "shipped": None,   # the module's own line, with cache=False
    "fastmath": 'dict(cache=False, error_model="numpy", fastmath=True)',
}
_JIT_LINE = re.compile(r"^_JIT = (dict\(.*\))$", re.MULTILINE)


def compile_variants(directory):
    """{name: module} of the thermal source compiled with each variant's options."""
    source = Path(thermal.__file__).read_text()
    shipped = _JIT_LINE.search(source)
    if shipped is None:
        raise RuntimeError("skidmc/physics/thermal.py has no `_JIT = dict(...)` line")
    modules = {}
    for name, line in VARIANTS.items():
        options = line or shipped.group(1).replace("cache=True", "cache=False")
        path = Path(directory) / f"thermal_{name}.py"
        path.write_text(_JIT_LINE.sub(lambda _m, o=options: f"_JIT = {o}", source, count=1))
        spec = importlib.util.spec_from_file_location(f"thermal_{name}", path)
        module = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(module)
        modules[name] = module
    return modules


def kernel_rows(modules, scenes, calls):
    rows = []
    for label, scene in scenes:
        height = critical_height(scene, rtol=1e-2).critical_height
        for level in (0.5, 1.5):
            model = build_model(scene, level=level, melt_width=1.0,
                                melt_spread=thermal.MELT_SPREAD)
            for factor in (0.995, 1.005):
                args = kernel_arguments(model, factor * height)
                info = {name: m.simulate_kernel(*args)[0] for name, m in modules.items()}
                best = {name: math.inf for name in modules}
                for _ in range(calls):
                    for name, m in modules.items():
                        t0 = time.perf_counter()
                        m.simulate_kernel(*args)
                        best[name] = min(best[name], time.perf_counter() - t0)
                base = info["python"]
                rows.append(dict(
                    scene=label, level=level, factor=factor, best=best,
                    event_change={n: _rel(i["t_event"], base["t_event"])
                                  for n, i in info.items()},
                    steps_change={n: int(i["steps"] - base["steps"])
                                  for n, i in info.items()}))
    return rows


def _rel(a, b):
    if a == b:
        return 0.0
    if not (math.isfinite(a) and math.isfinite(b)):
        return math.inf
    return abs(a / b - 1.0)


def search_rows(modules, scenes, rounds, calls):
    """Per scene: [time ratio python/shipped per round], max |height change|, simulations."""
    simulate_module = sys.modules["skidmc.solver.simulate"]
    original = simulate_module.simulate_kernel

    def timed(scene, name):
        simulate_module.simulate_kernel = modules[name].simulate_kernel
        return best_time(lambda: critical_height(scene, rtol=1e-3), calls)

    out = {label: dict(ratios=[], change=0.0, simulations=None) for label, _ in scenes}
    try:
        for _label, scene in scenes[:2]:   # warm-up: the searches' own compiled code
            timed(scene, "python")
            timed(scene, "shipped")
        for rnd in range(rounds):
            for label, scene in scenes:
                order = ("python", "shipped") if rnd % 2 == 0 else ("shipped", "python")
                got = {name: timed(scene, name) for name in order}
                out[label]["ratios"].append(got["python"][0] / got["shipped"][0])
                out[label]["change"] = max(out[label]["change"],
                                           _rel(got["shipped"][1].critical_height,
                                                got["python"][1].critical_height))
                out[label]["simulations"] = (got["python"][1].evaluations,
                                             got["shipped"][1].evaluations)
    finally:
        simulate_module.simulate_kernel = original
    return out


def report(kernel, search, n_kernel_scenes, calls, rounds):
    load = os.getloadavg()
    lines = ["# The thermal kernel's compile options, side by side (benchmarks/kernel_flags.py)",
             "",
             f"Machine: {os.cpu_count()} CPUs ({platform.machine()}), Python "
             f"{platform.python_version()}, one thread. Load average before the run: "
             f"{load[0]:.2f}, {load[1]:.2f}, {load[2]:.2f}. Variants: "
             + "; ".join(f"*{n}* `{v or 'the module _JIT'}`" for n, v in VARIANTS.items())
             + ".", "",
             f"## One simulation ({n_kernel_scenes} scenes x levels 0.5, 1.5 x 0.995, 1.005 "
             f"H_c; best of {calls} alternated calls)", "",
             "*ratio*: python's time / the variant's (> 1: faster), median [min-max] over the "
             "runs. *event change*: largest |t_ev / t_ev(python) - 1|; *steps*: largest change "
             "of the accepted steps.", "",
             "| variant | ratio | event change | steps |", "|---|---|---|---|"]
    for name in VARIANTS:
        ratios = [r["best"]["python"] / r["best"][name] for r in kernel]
        change = max(r["event_change"][name] for r in kernel)
        steps = max(abs(r["steps_change"][name]) for r in kernel)
        lines.append(f"| {name} | {statistics.median(ratios):.3f} [{min(ratios):.3f}-"
                     f"{max(ratios):.3f}] | {change:.1e} | {steps} |")
    per_scene = {label: statistics.median(v["ratios"]) for label, v in search.items()}
    pre = [v for label, v in per_scene.items() if label in PRESETS]
    off = [v for label, v in per_scene.items() if label not in PRESETS]
    changes = [v["change"] for v in search.values()]
    same_sims = sum(v["simulations"][0] == v["simulations"][1] for v in search.values())
    lines += ["", f"## The default search at rtol 1e-3 ({len(search)} scenes; best of 3 calls, "
              f"{rounds} alternated rounds)", "",
              "*ratio*: python's time / shipped's per height, median over rounds, then median "
              "[min-max] over the set.", "",
              "| scenes | n | ratio python/shipped |", "|---|---|---|",
              *(f"| {name} | {len(v)} | {statistics.median(v):.3f} [{min(v):.3f}-"
                f"{max(v):.3f}] |" for name, v in (("presets", pre), ("off-preset", off),
                                                    ("all", list(per_scene.values()))) if v),
              "",
              f"Largest relative change of a critical height, shipped against python: "
              f"{max(changes):.1e}; the same number of simulations on {same_sims} of "
              f"{len(search)} scenes."]
    OUT.mkdir(parents=True, exist_ok=True)
    (OUT / "kernel_flags.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--quick", action="store_true", help="two scenes, fewer calls and rounds")
    a = p.parse_args(argv)
    scenes = [(name, get_preset(name)) for name in PRESETS] + off_preset_scenes()
    kernel_scenes = scenes[:2] if a.quick else scenes[:5] + scenes[5:11]
    calls, rounds = (3, 1) if a.quick else (15, 3)
    with tempfile.TemporaryDirectory() as directory:
        modules = compile_variants(directory)
        kernel = kernel_rows(modules, kernel_scenes, calls)
        search = search_rows(modules, scenes[:2] if a.quick else scenes, rounds, 3)
    report(kernel, search, len(kernel_scenes), calls, rounds)


if __name__ == "__main__":
    main()
