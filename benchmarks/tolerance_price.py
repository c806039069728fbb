"""The default tolerance's price: this tree at rtol 1e-3 against an older tree at 3e-3.

Issue 16 asked for the default ``rtol = 1e-3`` "at the 3e-3 price": when it was filed, rtol 1e-3
cost ~5x rtol 3e-3 (7.6 against 1.4 ms median per height on the report presets), and its
absolute target, 2 ms at 1e-3, was ~1.4x that 3e-3 price on that day's machine. Absolute times
on a shared machine move with its load from one day to the next (the same tree's median has
read 4.2 and 5.7 ms in two runs), so this script measures the price as a ratio in one run:

* this tree and each older tree (a path holding ``src/skidmc``, e.g. the tree the issue was
  filed against: ``git archive e9bb787 src | tar -x -C /tmp/rev_issue16``) time the same
  scenes (the report presets and ``benchmarks/solver.py``'s 18 off-preset scenes) at rtol
  1e-3 and 3e-3, in alternated rounds of fresh one-core processes;
* per scene, the ratio of the older tree's time at 3e-3 to this tree's at 1e-3 (> 1: this
  tree's 1e-3 costs less than the older tree's 3e-3), its median over a scene set, and the
  range of that median over the rounds; the same at equal rtol;
* each result's error against the converged reference heights of
  ``results/benchmarks/solver.csv`` (``benchmarks/solver.py``'s reference runs, rtol 3e-5), so
  that the price is read together with what it buys;
* when one older tree is labelled ``e9bb787`` (the tree the issue was filed on), the issue's
  absolute 2 ms read on this run's machine: 2 ms times that tree's median at 3e-3 on the
  presets in this run over the 1.4 ms it measured on the day the issue was filed.

Usage::

    python benchmarks/tolerance_price.py /tmp/rev_issue16=e9bb787 [--rounds 5] [--repeats 3]

Each older tree is ``PATH`` or ``PATH=LABEL`` (the label names it in the table, e.g. its commit).

Writes ``results/benchmarks/tolerance_price.md``; ~1 minute with one older tree (its first
round compiles its kernels, not timed).
"""

from __future__ import annotations

import os

# One core, set before numpy/numba load: the targets are per core.
for _var in ("NUMBA_NUM_THREADS", "OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_var] = "1"

import argparse  # noqa: E402
import csv  # noqa: E402
import json  # noqa: E402
import statistics  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
from pathlib import Path  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "results" / "benchmarks"
#: The default tolerance and the one whose price it was asked to meet (issue 16).
DEFAULT_RTOL = 1e-3
PRICE_RTOL = 3e-3
#: Issue 16's absolute target [s]: the median per critical height at DEFAULT_RTOL.
ISSUE_TARGET = 2e-3
#: The tree the issue was filed on, and what it measured on the issue's machine that day [s]:
#: its median per height at PRICE_RTOL on the report presets. A run that includes this tree
#: reads the target on its own machine: ISSUE_TARGET x (the tree's median there today / this).
ISSUE_TREE = "e9bb787"
ISSUE_TREE_PRESETS_PRICE = 1.4e-3


def _worker(spec):
    """Time every scene of ``spec`` at each rtol with the skidmc on ``sys.path``.

    Imports only what every skidmc since the layout issue has (``make_scene``, ``get_preset``,
    ``critical_height``), so that an older tree can run it. Returns one row per (rtol, scene).
    """
    from timing import median_time

    from skidmc.scene import get_preset, make_scene
    from skidmc.solver import critical_height

    scenes = [(label, kind, get_preset(preset) if not overrides
               else make_scene(preset=preset, **overrides))
              for label, kind, preset, overrides in spec["scenes"]]
    # Compile (or load) every kernel both search paths use before anything is timed.
    for rtol in spec["rtols"]:
        for name in ("paper-quartz", "paper-gold"):
            critical_height(get_preset(name), rtol=rtol)
    rows = []
    for rtol in spec["rtols"]:
        for label, kind, scene in scenes:
            seconds, res = median_time(lambda s=scene, r=rtol: critical_height(s, rtol=r),
                                       spec["repeats"])
            rows.append(dict(rtol=rtol, scene=label, kind=kind,
                             time_s=seconds, evaluations=res.evaluations,
                             height_m=res.critical_height,
                             exit_kind=getattr(res, "exit_kind", "")))
    return rows


def _scene_specs():
    """(label, kind, preset, overrides) of the presets and the off-preset scenes."""
    sys.path.insert(0, str(ROOT / "benchmarks"))
    from solver import PRESETS, off_preset_overrides

    return ([(name, "preset", name, {}) for name in PRESETS]
            + [(label, "off-preset", "paper-quartz", overrides)
               for label, overrides in off_preset_overrides()])


def _reference_heights():
    """Scene -> converged reference height [m] from ``results/benchmarks/solver.csv``."""
    path = OUT / "solver.csv"
    if not path.exists():
        return {}
    with path.open() as f:
        return {r["preset"]: float(r["height_m"]) for r in csv.DictReader(f)
                if r["method"] == "skidmc reference"}


def _run_round(src, spec):
    env = dict(os.environ, PYTHONPATH=str(src))
    text = subprocess.run([sys.executable, __file__, "--worker"], input=json.dumps(spec),
                          env=env, capture_output=True, text=True, check=True).stdout
    return json.loads(text.split("JSON", 1)[1])


def _med_range(values):
    return f"{statistics.median(values):.2f} [{min(values):.2f}-{max(values):.2f}]"


def measure(trees, rounds, repeats):
    specs = _scene_specs()
    spec = dict(rtols=[DEFAULT_RTOL, PRICE_RTOL], repeats=repeats, scenes=specs)
    labels = ["this tree"] + [label for _, label in trees]
    srcs = [ROOT / "src"] + [Path(path) / "src" for path, _ in trees]
    # An untimed first pass per tree: a fresh tree compiles its kernels into its cache here.
    for label, src in zip(labels, srcs):
        _run_round(src, dict(spec, repeats=1, scenes=specs[:1]))
        print(f"warm-up: {label} done", flush=True)
    runs = {label: [] for label in labels}
    for rnd in range(rounds):
        order = list(zip(labels, srcs))
        if rnd % 2:
            order.reverse()
        for label, src in order:
            runs[label].append(_run_round(src, spec))
            print(f"round {rnd + 1}: {label} done", flush=True)
    return labels, runs, _reference_heights()


def report(labels, runs, reference, rounds, repeats):
    def pick(rows, rtol, kind):
        return {r["scene"]: r for r in rows if r["rtol"] == rtol
                and (kind is None or r["kind"] == kind)}

    lines = ["# The default tolerance's price, side by side (benchmarks/tolerance_price.py)", "",
             f"Machine: {os.cpu_count()} CPUs, shared; {rounds} alternated rounds, each a fresh "
             f"one-core process per tree, median of {repeats} calls per scene, kernels compiled "
             "beforehand. *time*: median over the set's scenes and the rounds. *error*: "
             "|H / H_ref - 1| against the reference heights of results/benchmarks/solver.csv "
             "(rtol 3e-5), median and worst over the set. *simulations*: median (range).", "",
             "| scenes | tree | rtol | median time | median error | worst error "
             "| simulations |", "|---|---|---|---|---|---|---|"]
    sets = (("presets", "preset"), ("off-preset", "off-preset"), ("all", None))
    for set_label, kind in sets:
        for label in labels:
            for rtol in (DEFAULT_RTOL, PRICE_RTOL):
                per_round = [pick(rows, rtol, kind) for rows in runs[label]]
                t_med = statistics.median(r["time_s"] for rows in per_round
                                          for r in rows.values())
                errs = [abs(r["height_m"] / reference[s] - 1.0)
                        for s, r in per_round[0].items() if s in reference]
                ev = sorted(r["evaluations"] for r in per_round[0].values())
                err_txt = (f"{statistics.median(errs):.1e} | {max(errs):.1e}" if errs
                           else "- | -")
                lines.append(f"| {set_label} | {label} | {rtol:g} | {1e3 * t_med:.2f} ms | "
                             f"{err_txt} | {statistics.median(ev):g} ({ev[0]}-{ev[-1]}) |")
    lines += ["", f"## Ratios per scene (> 1: this tree at rtol {DEFAULT_RTOL:g} is faster)",
              "", "Per round, the median over the set's scenes of (older tree's time / this "
              f"tree's time at rtol {DEFAULT_RTOL:g}); then the median [min-max] over rounds.",
              "", "| scenes | older tree | its rtol | ratio |", "|---|---|---|---|"]
    new_rounds = runs[labels[0]]
    for set_label, kind in sets:
        for label in labels[1:]:
            for rtol in (PRICE_RTOL, DEFAULT_RTOL):
                meds = []
                for old_rows, new_rows in zip(runs[label], new_rounds):
                    old = pick(old_rows, rtol, kind)
                    new = pick(new_rows, DEFAULT_RTOL, kind)
                    meds.append(statistics.median(old[s]["time_s"] / new[s]["time_s"]
                                                  for s in new))
                lines.append(f"| {set_label} | {label} | {rtol:g} | {_med_range(meds)} |")
    if ISSUE_TREE in labels:
        lines += _scaled_target(runs, new_rounds, pick, sets)
    OUT.mkdir(parents=True, exist_ok=True)
    (OUT / "tolerance_price.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


def _scaled_target(runs, new_rounds, pick, sets):
    """Issue 16's absolute target read on this run's machine, from the filing tree's own time.

    Per round: the machine factor is the filing tree's median at PRICE_RTOL on the presets
    over ISSUE_TREE_PRESETS_PRICE, the scaled target ISSUE_TARGET times it, and this tree's
    median at DEFAULT_RTOL over each scene set is divided by it (<= 1: the target is met).
    """
    factors, ratios = [], {set_label: [] for set_label, _ in sets}
    for old_rows, new_rows in zip(runs[ISSUE_TREE], new_rounds):
        factor = statistics.median(r["time_s"] for r in pick(old_rows, PRICE_RTOL,
                                                              "preset").values())
        factor /= ISSUE_TREE_PRESETS_PRICE
        factors.append(factor)
        for set_label, kind in sets:
            mine = statistics.median(r["time_s"] for r in pick(new_rows, DEFAULT_RTOL,
                                                               kind).values())
            ratios[set_label].append(mine / (ISSUE_TARGET * factor))
    lines = ["", f"## Issue 16's {1e3 * ISSUE_TARGET:g} ms, read on this run's machine", "",
             f"{ISSUE_TREE} measured {1e3 * ISSUE_TREE_PRESETS_PRICE:g} ms at rtol "
             f"{PRICE_RTOL:g} on the presets (median) on the day the issue was filed. The machine "
             "factor is its median there in this run over that; the scaled target is "
             f"{1e3 * ISSUE_TARGET:g} ms times the factor. *time / target*: this tree's median "
             f"at rtol {DEFAULT_RTOL:g} over the set divided by the scaled target (<= 1: met); "
             "median [min-max] over rounds.", "",
             f"Machine factor: {_med_range(factors)}; scaled target "
             f"{1e3 * ISSUE_TARGET * statistics.median(factors):.2f} ms.", "",
             "| scenes | time / target |", "|---|---|"]
    lines += [f"| {set_label} | {_med_range(ratios[set_label])} |" for set_label, _ in sets]
    return lines


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("trees", nargs="*", metavar="TREE",
                   help="older source trees: PATH or PATH=LABEL (PATH holds src/skidmc)")
    p.add_argument("--rounds", type=int, default=3, help="alternated rounds")
    p.add_argument("--repeats", type=int, default=3, help="timed calls per scene and rtol")
    p.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)
    a = p.parse_args(argv)
    if a.worker:
        print("JSON" + json.dumps(_worker(json.loads(sys.stdin.read()))))
        return
    if not a.trees:
        p.error("give at least one older tree to compare with (a path holding src/skidmc)")
    trees = []
    for tree in a.trees:
        path, _, label = tree.partition("=")
        if not (Path(path) / "src" / "skidmc").is_dir():
            p.error(f"tree {path!r} holds no src/skidmc")
        trees.append((path, label or path))
    report(*measure(trees, a.rounds, a.repeats), a.rounds, a.repeats)


if __name__ == "__main__":
    main()
