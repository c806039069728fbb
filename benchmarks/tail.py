"""The slow tail of real study scenes: per-height time at three tolerances, and where it goes.

Scenes: drawn from the shipped studies' ensembles (``benchmarks/study_scenes.py``:
paper-series1, paper-series2, sobol-series1, each sample rebuilt from its inputs; about half of
the alumina and quartz samples also with the temperature-dependent target ``alumina-85`` /
``fused-quartz`` the studies move to). For each scene and each rtol (1e-2, 3e-3, 1e-3):

1. Time: :func:`skidmc.critical_height` in this process, the smaller of ``--repeat`` calls
   (kernels loaded first), so that another tenant's burst on the shared machine weighs less.
2. Where the time goes, in a separate instrumented call (its own timings include the
   instrumentation and are used only as shares): each simulation's wall time and step
   attempts, attributed to the phase of the default search that ran it: ``first pair`` (the
   coarse and fine searches of the first Richardson pair, with their coarse starts),
   ``melt bias`` (the simulation that measures the melting width's bias), ``tighten`` (a
   root re-searched at a tighter tolerance), ``narrow`` (the pair searched again with a
   narrower melting width), ``refine`` (a search one level finer); ``fast guess`` (the fast
   tier's first guess) and ``other`` (model builds, root finding, Python) make up the rest.

Writes ``results/benchmarks/tail.md`` and ``tail.csv`` (one row per scene and rtol) and
``tail.png`` (per-height time, sorted, at each rtol). Usage::

    python benchmarks/tail.py                 # ~270 scenes, 3 rtol, 2 repeats: a few minutes
    python benchmarks/tail.py --n 20 --repeat 1
    git archive <commit> src | tar -x -C /tmp/base-<commit>
    python benchmarks/tail.py --base /tmp/base-<commit>/src --pairs 4   # and side by side

Side by side, each tree runs in one warm process and the scenes are timed interleaved (scene i
in the base tree, then in this one, round after round), so that another tenant's burst on the
shared machine falls on both; the in-process table is measured first and alone, and carries
such bursts (compare within it only).
"""

from __future__ import annotations

import argparse
import csv
import math
import os
import platform
import subprocess
import sys
import time
from collections import defaultdict
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
if "PYTHONPATH" not in os.environ:
    sys.path.insert(0, str(ROOT / "src"))
sys.path.insert(0, str(ROOT / "benchmarks"))

import numpy as np  # noqa: E402
import study_scenes  # noqa: E402

RTOLS = (1e-2, 3e-3, 1e-3)
PHASES = ("first pair", "melt bias", "tighten", "narrow", "refine", "fast guess", "other")


class Instrument:
    """Attributes each simulation of the default search to a phase of the search: the stage of
    the search machine (``skidmc.solver.adaptive``) that asked for it, read when the CPU search
    asks the machine what to run (``adaptive.asked``); and records the first pair's estimate."""

    def __init__(self):
        from skidmc.solver import adaptive, search

        self.search, self.adaptive = search, adaptive
        self.saved = []
        self.phase = "other"
        self.seconds = defaultdict(float)
        self.attempts = defaultdict(int)
        self.runs = defaultdict(int)
        self.estimates = []   # the first pair's error estimate, one per search
        a = adaptive
        self.stage_phase = {a._S_COARSE: "first pair", a._S_FINE: "first pair",
                            a._S_BIAS: "melt bias", a._S_NARROW_BIAS: "melt bias",
                            a._S_TIGHTEN_C: "tighten", a._S_TIGHTEN_F: "tighten",
                            a._S_NARROW_C: "narrow", a._S_NARROW_F: "narrow",
                            a._S_REFINE: "refine"}
        self.first_pair = {a._S_COARSE, a._S_FINE, a._S_BIAS}

    def _wrap(self, module, name, make):
        original = getattr(module, name)
        self.saved.append((module, name, original))
        setattr(module, name, make(original))

    def __enter__(self):
        inst = self

        def simulate(original):
            def wrapped(model, height, **kw):
                t0 = time.perf_counter()
                try:
                    sim = original(model, height, **kw)
                finally:
                    inst.seconds[inst.phase] += time.perf_counter() - t0
                    inst.runs[inst.phase] += 1
                inst.attempts[inst.phase] += sim.steps + sim.rejected
                return sim
            return wrapped

        def asked(original):
            def wrapped(ps):
                stage = int(ps[0]["stage"])
                if stage not in inst.first_pair and len(inst.estimates) == 0:
                    inst.estimates.append(float(ps[0]["estimate"]))   # the first pair's
                inst.phase = inst.stage_phase[stage]
                return original(ps)
            return wrapped

        def outcome(original):
            def wrapped(ps):
                if len(inst.estimates) == 0:   # no round asked for a run
                    s = ps[0]
                    inst.estimates.append(float(s["estimate"] if s["extrapolated"]
                                                else s["out_error"]))
                inst.phase = "other"
                return original(ps)
            return wrapped

        def fast_guess(original):
            def wrapped(*args, **kw):
                t0 = time.perf_counter()
                try:
                    return original(*args, **kw)
                finally:
                    inst.seconds["fast guess"] += time.perf_counter() - t0
            return wrapped

        self._wrap(self.search, "simulate", simulate)
        self._wrap(self.adaptive, "asked", asked)
        self._wrap(self.adaptive, "outcome", outcome)
        self._wrap(self.search, "_fast_guess", fast_guess)
        return self

    def __exit__(self, *exc):
        for module, name, original in reversed(self.saved):
            setattr(module, name, original)


def regime(scene):
    """How the scene's heating ends (the search's own classification)."""
    from skidmc.solver.options import exit_regime

    return exit_regime(scene)


def _serve(args):
    """Child of :func:`side_by_side`: time the scene whose index each stdin line names (the
    smaller of ``--repeat`` calls) and answer with the seconds, one line each."""
    import skidmc

    scenes = study_scenes.draw(args.n, args.seed)
    skidmc.critical_height(scenes[0][2], rtol=args.serve)   # kernels loaded first
    print("ready", flush=True)
    for line in sys.stdin:
        scene = scenes[int(line)][2]
        best = math.inf
        for _ in range(args.repeat):
            t0 = time.perf_counter()
            try:
                skidmc.critical_height(scene, rtol=args.serve)
            except Exception:  # noqa: BLE001, S110 - timed as it is
                pass
            best = min(best, time.perf_counter() - t0)
        print(repr(best), flush=True)
    return 0


def _server(args, rtol, src):
    """A :func:`_serve` child on the source tree ``src``, its kernels loaded."""
    # Each tree its own numba cache (skidmc._numba_cache keys it by the tree's source): the
    # NUMBA_CACHE_DIR this process set would make the trees overwrite each other's kernels.
    env = {k: v for k, v in os.environ.items() if k != "NUMBA_CACHE_DIR"}
    env["PYTHONPATH"] = str(src)
    proc = subprocess.Popen([sys.executable, __file__, "--serve", repr(rtol), "--n",
                             str(args.n), "--seed", str(args.seed), "--repeat",
                             str(args.repeat)], env=env, stdin=subprocess.PIPE,
                            stdout=subprocess.PIPE, text=True)
    if proc.stdout.readline().strip() != "ready":
        raise RuntimeError(f"the timing child on {src} did not start")
    return proc


def side_by_side(args, rtol, n):
    """Per-scene times [s] of the tree ``args.base`` and of this one, interleaved scene by
    scene: one warm process per tree, each scene timed ``args.pairs`` times in each, the two
    trees taking turns (base first in even rounds, this one in odd ones), so that a burst of
    another tenant's load falls on both; the smaller time per scene and tree. ``n``: how many
    scenes the children draw (the same draw as this process's)."""
    import skidmc

    here = Path(skidmc.__file__).resolve().parents[1]
    servers = {"base": _server(args, rtol, args.base), "this": _server(args, rtol, here)}
    best = {name: [math.inf] * n for name in servers}
    try:
        for k in range(args.pairs):
            order = ("base", "this") if k % 2 == 0 else ("this", "base")
            for i in range(n):
                for name in order:
                    proc = servers[name]
                    proc.stdin.write(f"{i}\n")
                    proc.stdin.flush()
                    best[name][i] = min(best[name][i], float(proc.stdout.readline()))
    finally:
        for proc in servers.values():
            proc.stdin.close()
            proc.wait()
    return best


def measure(scenes, repeat, args=None):
    import skidmc

    rows = []
    base = {}
    for rtol in RTOLS:
        if args is not None and args.base:
            base[rtol] = side_by_side(args, rtol, len(scenes))
        skidmc.critical_height(scenes[0][2], rtol=rtol)   # load what this rtol uses
        for label, group, scene in scenes:
            best, res, error = math.inf, None, ""
            for _ in range(repeat):
                t0 = time.perf_counter()
                try:
                    res = skidmc.critical_height(scene, rtol=rtol)
                except Exception as exc:  # noqa: BLE001 - a failed sample is a row too
                    error = f"{type(exc).__name__}"
                best = min(best, time.perf_counter() - t0)
            with Instrument() as inst:
                t0 = time.perf_counter()
                try:
                    skidmc.critical_height(scene, rtol=rtol)
                except Exception:  # noqa: BLE001, S110 - recorded above
                    pass
                total = time.perf_counter() - t0
            seconds = dict(inst.seconds)
            seconds["other"] = max(0.0, total - sum(seconds.values()))
            row = {"label": label, "group": group, "rtol": rtol, "seconds": best,
                   "regime": regime(scene), "table_target": bool(scene.target_table),
                   "error": error}
            if res is not None and not error:
                row.update(height=res.critical_height, evaluations=res.evaluations,
                           level=res.level, flags=";".join(res.flags),
                           censored=res.censored or "", estimate=res.error_estimate)
            row["first estimate"] = inst.estimates[0] if inst.estimates else math.nan
            for phase in PHASES:
                row[f"share {phase}"] = seconds.get(phase, 0.0) / total if total > 0 else 0.0
                row[f"runs {phase}"] = inst.runs.get(phase, 0)
                row[f"attempts {phase}"] = inst.attempts.get(phase, 0)
            rows.append(row)
        print(f"rtol {rtol:g}: {len(scenes)} scenes", flush=True)
    return rows, base


def _stats(ms):
    ms = np.asarray(ms)
    return (float(ms.mean()), float(np.median(ms)), float(np.percentile(ms, 90)),
            float(ms.max()))


def markdown(args, scenes, rows, base, load_before, load_after):
    groups = sorted({g for _, g, _ in scenes})
    lines = [
        "# The slow tail of study scenes: per-height time and where it goes",
        "",
        f"Generated by `python benchmarks/tail.py --n {args.n} --repeat {args.repeat}`: "
        f"{len(scenes)} scenes drawn from the shipped studies' ensembles "
        "(`benchmarks/study_scenes.py`, seed "
        f"{args.seed}; groups: {', '.join(groups)}; a group `study:material` holds samples "
        "rebuilt with the temperature-dependent target). Each time is the smaller of "
        f"{args.repeat} calls of `skidmc.critical_height(scene, rtol=...)` in one process, "
        "kernels loaded.",
        "",
        f"Machine: {os.cpu_count()} CPUs ({platform.machine()}), Python "
        f"{platform.python_version()}; load average {load_before} before, {load_after} after. "
        "The machine is shared: absolute times carry the other tenants' load (a few tens of %), "
        "ratios within one rtol much less.",
        "",
        "## Per-height time [ms]",
        "",
        "| rtol | scenes | mean | median | p90 | max | mean / median | max / median | "
        "evaluations (mean, max) |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for rtol in RTOLS:
        sel = [r for r in rows if r["rtol"] == rtol]
        mean, med, p90, mx = _stats([1e3 * r["seconds"] for r in sel])
        ev = [r.get("evaluations", 0) for r in sel]
        lines.append(f"| {rtol:g} | {len(sel)} | {mean:.2f} | {med:.2f} | {p90:.2f} | "
                     f"{mx:.2f} | {mean / med:.2f} | {mx / med:.1f} | "
                     f"{np.mean(ev):.1f}, {max(ev)} |")
    if base:
        lines += ["", f"Side by side with the tree at `{args.base}`: one warm process per "
                  f"tree, scene by scene, the trees taking turns ({args.pairs} rounds per "
                  "rtol, the same scenes and repeats; per scene the smaller time of its "
                  "rounds), so that another tenant's burst falls on both. Ratio: this tree's "
                  "time over the base's per scene (median, and over the summed time):", "",
                  "| rtol | tree | mean | median | p90 | max | mean / median | max / median "
                  "| ratio to base (per-scene median; total) |",
                  "|---|---|---|---|---|---|---|---|---|"]
        for rtol in RTOLS:
            for name in ("base", "this"):
                ms = [1e3 * t for t in base[rtol][name]]
                mean, med, p90, mx = _stats(ms)
                ratio = ""
                if name == "this":
                    per = np.array(base[rtol]["this"]) / np.array(base[rtol]["base"])
                    ratio = (f"{np.median(per):.2f}; "
                             f"{sum(base[rtol]['this']) / sum(base[rtol]['base']):.2f}")
                lines.append(f"| {rtol:g} | {name} | {mean:.2f} | {med:.2f} | {p90:.2f} | "
                             f"{mx:.2f} | {mean / med:.2f} | {mx / med:.1f} | {ratio} |")
    lines += ["", "## By group and regime at rtol 1e-3 [ms]", "",
              "| group | regime | scenes | mean | median | p90 | max | share of the total time |",
              "|---|---|---|---|---|---|---|---|"]
    sel = [r for r in rows if r["rtol"] == 1e-3]
    total = sum(r["seconds"] for r in sel)
    keys = sorted({(r["group"], r["regime"]) for r in sel})
    for group, reg in keys:
        part = [r for r in sel if r["group"] == group and r["regime"] == reg]
        mean, med, p90, mx = _stats([1e3 * r["seconds"] for r in part])
        share = sum(r["seconds"] for r in part) / total
        lines.append(f"| {group} | {reg} | {len(part)} | {mean:.2f} | {med:.2f} | {p90:.2f} | "
                     f"{mx:.2f} | {100 * share:.0f} % |")
    lines += ["", "## Where the time goes: phases of the search", "",
              "Share of the instrumented time per phase (summed over the scenes), for all "
              "scenes and for the slowest tenth at each rtol; runs and step attempts per scene "
              "(mean).", "",
              "| rtol | scenes | " + " | ".join(PHASES) + " | runs | attempts |",
              "|---|---|" + "---|" * len(PHASES) + "---|---|"]
    for rtol in RTOLS:
        sel = sorted((r for r in rows if r["rtol"] == rtol), key=lambda r: r["seconds"])
        for name, part in (("all", sel), ("slowest 10 %", sel[-max(1, len(sel) // 10):])):
            weights = [r["seconds"] for r in part]
            shares = [sum(w * r[f"share {p}"] for w, r in zip(weights, part)) / sum(weights)
                      for p in PHASES]
            runs = np.mean([sum(r[f"runs {p}"] for p in PHASES) for r in part])
            att = np.mean([sum(r[f"attempts {p}"] for p in PHASES) for r in part])
            lines.append(f"| {rtol:g} | {name} | "
                         + " | ".join(f"{100 * s:.0f} %" for s in shares)
                         + f" | {runs:.1f} | {att:.0f} |")
    lines += ["", "## What a refinement costs, and what skipping it would give up", "",
              "A scene refines when its first pair's a posteriori estimate exceeds rtol and no "
              "tightening of its roots can bring it within, however far the re-searched roots "
              "move (`controller.bounded_tightening`; the pair moves one level up). Time without "
              "the refine phase: each scene's time x (1 - its refine share); the first pair's "
              "estimate is what such a scene would report instead (flag rtol_unmet).", "",
              "| rtol | scenes refined | their share of the time | mean, median, p90, max "
              "without refining [ms] | first-pair estimate of the refined / rtol (median, "
              "max) |", "|---|---|---|---|---|"]
    for rtol in RTOLS:
        sel_r = [r for r in rows if r["rtol"] == rtol]
        refined = [r for r in sel_r if r["runs refine"] > 0]
        share = (sum(r["seconds"] for r in refined) / sum(r["seconds"] for r in sel_r))
        cut = [1e3 * r["seconds"] * (1 - r["share refine"]) for r in sel_r]
        mean, med, p90, mx = _stats(cut)
        est = [r["first estimate"] / rtol for r in refined if math.isfinite(r["first estimate"])]
        est_text = (f"{np.median(est):.2f}, {max(est):.2f}" if est else "-")
        lines.append(f"| {rtol:g} | {len(refined)} of {len(sel_r)} | {100 * share:.0f} % | "
                     f"{mean:.2f}, {med:.2f}, {p90:.2f}, {mx:.2f} | {est_text} |")
    lines += ["", "## The slowest 12 scenes at rtol 1e-3", "",
              "| scene | group | regime | ms | evaluations | final level | flags | "
              "phases (share of time > 5 %) | attempts |", "|---|---|---|---|---|---|---|---|---|"]
    for r in sorted(sel, key=lambda r: -r["seconds"])[:12]:
        phases = ", ".join(f"{p} {100 * r[f'share {p}']:.0f} %" for p in PHASES
                           if r[f"share {p}"] > 0.05)
        att = sum(r[f"attempts {p}"] for p in PHASES)
        lines.append(f"| {r['label']} | {r['group']} | {r['regime']} | "
                     f"{1e3 * r['seconds']:.1f} | {r.get('evaluations', '')} | "
                     f"{r.get('level', '')} | {r.get('flags', '') or r['error']} | {phases} | "
                     f"{att} |")
    return "\n".join(lines) + "\n"


def figure(rows, path, base=None, base_name=None):
    """Per-height times sorted, per rtol: the side-by-side times where a base tree was timed
    (base dashed, this tree solid), else the in-process ones."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.ticker import FuncFormatter

    fig, ax = plt.subplots(figsize=(6.8, 3.9))
    colors = dict(zip(RTOLS, ("tab:blue", "tab:orange", "tab:green"), strict=True))
    for rtol in RTOLS:
        if base:
            for name, style in (("base", "--"), ("this", "-")):
                ms = np.sort(1e3 * np.array(base[rtol][name]))
                label = f"rtol {rtol:g}, " + (f"base ({base_name})" if name == "base"
                                              else "this tree")
                ax.plot(np.arange(1, len(ms) + 1) / len(ms), ms, style, color=colors[rtol],
                        label=label)
        else:
            ms = np.sort([1e3 * r["seconds"] for r in rows if r["rtol"] == rtol])
            ax.plot(np.arange(1, len(ms) + 1) / len(ms), ms, color=colors[rtol],
                    label=f"rtol {rtol:g}")
    ax.set_yscale("log")
    ax.yaxis.set_major_formatter(FuncFormatter(lambda v, _: f"{v:g}"))
    ax.yaxis.set_minor_formatter(FuncFormatter(
        lambda v, _: f"{v:g}" if f"{v:g}"[0] in "25" else ""))
    ax.set_xlabel("fraction of scenes (sorted by time)")
    ax.set_ylabel("time per critical height [ms]")
    ax.set_title("Study scenes: per-height time"
                 + (", side by side (warm processes, scenes interleaved)" if base
                    else ", one process"), fontsize=10)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7.5, ncol=1 if not base else 2, loc="upper left")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n", type=int, default=70, help="samples per study (default 70)")
    parser.add_argument("--seed", type=int, default=45)
    parser.add_argument("--repeat", type=int, default=2)
    parser.add_argument("--out", default=str(ROOT / "results" / "benchmarks"))
    parser.add_argument("--base", help="the src folder of another tree, timed side by side")
    parser.add_argument("--pairs", type=int, default=3,
                        help="side-by-side rounds per rtol (each scene timed once per tree per "
                             "round)")
    parser.add_argument("--serve", type=float, help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.serve:
        return _serve(args)
    load_before = ", ".join(f"{v:.2f}" for v in os.getloadavg())
    scenes = study_scenes.draw(args.n, args.seed)
    rows, base = measure(scenes, args.repeat, args)
    load_after = ", ".join(f"{v:.2f}" for v in os.getloadavg())
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "tail.md").write_text(markdown(args, scenes, rows, base, load_before,
                                          load_after))
    with open(out / "tail.csv", "w", newline="") as f:
        fields = list(dict.fromkeys(k for r in rows for k in r))
        writer = csv.DictWriter(f, fieldnames=fields)
        writer.writeheader()
        writer.writerows(rows)
    figure(rows, out / "tail.png", base, Path(args.base).parent.name if args.base else None)
    print((out / "tail.md").read_text())
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
