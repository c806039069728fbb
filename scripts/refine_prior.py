"""Where a refined pair's new fine root lies, against the root the search predicts for it.

When the default search's first Richardson pair (L-1, L) leaves an estimate above rtol that no
tightening can bring within it, the pair moves up a level (``controller.next_round``, REFINE)
and a new fine search at L+1 starts from the root the pair predicts for that level,
``value = R (1 - c / 4)`` [m] (R the pair's Richardson value, c its relative correction). Where
the margin jumps at the root (sliding stops before rebound), that search places its runs by a
prior on ln H (``finders.prior_bisection_start``), and each run at L+1 = 2.5 costs ~5x one at
1.5: the prior decides most of what the slowest study scenes cost (``results/benchmarks/
tail.md``).

For every stops-sliding scene of a draw from the shipped studies (``benchmarks/
study_scenes.py``) that refines at the given rtols, this script records the prior the search
used (its centre and spread, on ln H) and the new fine level's own root found by signs to
1e-7 in ln H from the bracket the search left, and writes

    d = ln H_{L+1} - ln value, in units of s = |c| + x_tol

(c the pair's relative correction, x_tol the new search's root tolerance; s is what the
search knows of the move before it runs). Usage::

    python scripts/refine_prior.py --seeds 101 102 103 --n 300      # training draws
    python scripts/refine_prior.py --seeds 45 --n 70 --out results/validation/refine_prior_45.md

Writes a markdown table (``--out``, default ``results/validation/refine_prior.md``).
"""

from __future__ import annotations

import argparse
import math
import os
import statistics
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
if "PYTHONPATH" not in os.environ:   # another source tree's, to compare (PYTHONPATH=...)
    sys.path.insert(0, str(ROOT / "src"))
sys.path.insert(0, str(ROOT / "benchmarks"))

import study_scenes  # noqa: E402

from skidmc import critical_height  # noqa: E402
from skidmc.solver import adaptive, search  # noqa: E402
from skidmc.solver.options import exit_regime  # noqa: E402

_S_REFINE = 8   # adaptive's stage code of a refined pair's new fine search (checked below)


class Recorder:
    """Wraps the search driver's calls: the refine's prior and the runs at its level."""

    def __init__(self):
        self.refine = None
        self.runs = []
        self._step, self._sim = adaptive.pair_step, search.simulate

    def __enter__(self):
        def pair_step(ps, *args):
            out = self._step(ps, *args)
            self._look(ps)
            return out

        def simulate(model, height, **kw):
            sim = self._sim(model, height, **kw)
            self.runs.append((model, height, sim.margin, kw.get("until_exit", False)))
            return sim

        adaptive.pair_step, search.simulate = pair_step, simulate
        return self

    def _look(self, ps):
        p = ps[0]
        if self.refine is None and int(p["stage"]) == _S_REFINE:
            self.refine = dict(value=float(p["l_guess"]), overshoot=float(p["l_overshoot"]),
                               relative=float(p["relative"]), x_tol=float(p["level_tol"]),
                               sigma=float(p["l_sigma"]),
                               level=float(p["level"]), signs=int(p["signs_only"]),
                               n_before=len(self.runs))

    def __exit__(self, *exc):
        adaptive.pair_step, search.simulate = self._step, self._sim


def sign_root(model, lo, hi, tol=1e-7):
    """The margin's root by signs on ln H between a no-go ``lo`` and a go ``hi`` [ln m]."""
    from skidmc.solver.simulate import simulate

    while hi - lo > tol:
        mid = 0.5 * (lo + hi)
        m = simulate(model, math.exp(mid), until_exit=True).margin
        if m <= 0.0:
            hi = mid
        else:
            lo = mid
    return 0.5 * (lo + hi)


def measure(scene, rtol, reference_rtol=None):
    rec = Recorder()
    with rec:
        res = critical_height(scene, rtol=rtol)
    r = rec.refine
    if r is None or not r["signs"]:
        return None
    runs = rec.runs[r["n_before"]:]
    model = runs[0][0]
    xs = [(math.log(h), m) for mo, h, m, _ in runs if mo is model]
    go = [x for x, m in xs if m <= 0.0]
    nogo = [x for x, m in xs if m > 0.0]
    if not go or not nogo:
        return None
    root = sign_root(model, max(nogo), min(go))
    half = 0.5 * r["overshoot"]
    scale = abs(r["relative"]) + r["x_tol"]
    x_value = math.log(r["value"])
    # The prior's centre and spread on ln H: on the prediction with the given spread
    # (adaptive.REFINE_SPREAD), or, before it, half the overshoot above it and a sixth of that.
    given = math.isfinite(r["sigma"])
    centre = 0.0 if given else half
    spread = r["sigma"] if given else half / 3.0
    row = {}
    if reference_rtol:
        # Honesty: the refined search's error against a tight default search, over its
        # own error estimate.
        ref = critical_height(scene, rtol=reference_rtol)
        row = dict(error=abs(math.log(res.critical_height / ref.critical_height)),
                   estimate=res.error_estimate, reference_estimate=ref.error_estimate)
    return row | dict(d=(root - x_value) / scale, root_minus_value=root - x_value, scale=scale,
                centre=centre / scale, spread=spread / scale,
                z=(root - x_value - centre) / spread, x_tol=r["x_tol"],
                relative=r["relative"], runs_at_level=len(xs), evaluations=res.evaluations,
                level=r["level"])


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, nargs="+", default=[101, 102, 103])
    ap.add_argument("--n", type=int, default=300, help="samples per study and seed")
    ap.add_argument("--rtols", type=float, nargs="+", default=[1e-3, 3e-3])
    ap.add_argument("--reference-rtol", type=float, default=None,
                    help="also each refined height's error against the default search at this "
                         "rtol (e.g. 1e-4), over its error estimate")
    ap.add_argument("--out", default=str(ROOT / "results" / "validation" / "refine_prior.md"))
    args = ap.parse_args(argv)
    assert adaptive._S_REFINE == _S_REFINE
    rows = []
    t0 = time.perf_counter()
    n_scenes = 0
    for seed in args.seeds:
        scenes = [x for x in study_scenes.draw(n_per_study=args.n, seed=seed)
                  if exit_regime(x[2]) == "stops_sliding"]
        n_scenes += len(scenes)
        for label, _group, scene in scenes:
            for rtol in args.rtols:
                try:
                    row = measure(scene, rtol, args.reference_rtol)
                except Exception as exc:  # noqa: BLE001 - a failed search is reported, not fatal
                    print(f"{label} rtol {rtol:g}: {type(exc).__name__}: {exc}", flush=True)
                    continue
                if row is not None:
                    row.update(label=label, seed=seed, rtol=rtol)
                    rows.append(row)
                    print(f"{label} rtol {rtol:g}: d = {row['d']:+.3f} s (s = {row['scale']:.2e}),"
                          f" prior centre {row['centre']:+.3f} s, spread {row['spread']:.3f} s,"
                          f" {row['runs_at_level']} runs at level {row['level']:g}", flush=True)
    d = [r["d"] for r in rows]
    lines = [
        "# Where a refined pair's new fine root lies (stops-sliding scenes)",
        "",
        f"Generated by `python scripts/refine_prior.py --seeds {' '.join(map(str, args.seeds))} "
        f"--n {args.n} --rtols {' '.join(f'{r:g}' for r in args.rtols)}` in "
        f"{time.perf_counter() - t0:.0f} s: {n_scenes} stops-sliding scenes drawn from the "
        "shipped studies (`benchmarks/study_scenes.py`), those whose search refines at each "
        "rtol. d = ln H_{L+1} - ln value, in units of s = |c| + x_tol (value [m]: the root the "
        "pair predicts for the new level; c: its relative correction; x_tol: the new search's "
        "root tolerance); H_{L+1}: the new level's root by signs to 1e-7 in ln H.",
        "",
    ]
    if d:
        lines += [
            f"Refined searches: {len(d)}. d / s: mean {statistics.fmean(d):+.3f}, sd "
            f"{statistics.stdev(d) if len(d) > 1 else math.nan:.3f}, min {min(d):+.3f}, "
            f"median {statistics.median(d):+.3f}, max {max(d):+.3f}. The prior the search used: "
            f"centre {statistics.fmean(r['centre'] for r in rows):+.3f} s, spread "
            f"{statistics.fmean(r['spread'] for r in rows):.3f} s (mean), the roots at "
            f"{statistics.fmean(r['z'] for r in rows):+.2f} of its spreads (mean; "
            f"|z| max {max(abs(r['z']) for r in rows):.2f}); runs at the new level "
            f"mean {statistics.fmean(r['runs_at_level'] for r in rows):.2f}.",
            "",
        ]
        if args.reference_rtol:
            ratio = [r["error"] / r["estimate"] for r in rows]
            lines += [
                f"Honesty: each refined height against the default search at rtol "
                f"{args.reference_rtol:g} (its own estimates at most "
                f"{max(r['reference_estimate'] for r in rows):.2g}): |ln(H / H_ref)| / "
                f"estimate median {statistics.median(ratio):.2f}, max {max(ratio):.2f}; "
                f"{sum(x > 1.0 for x in ratio)} of {len(ratio)} above 1.",
                "",
            ]
        lines += [
            "| scene | seed | rtol | level | s | d / s | prior centre / s | prior spread / s "
            "| runs at the level | evaluations |",
            "|---|---|---|---|---|---|---|---|---|---|",
        ]
        for r in sorted(rows, key=lambda r: (r["seed"], r["label"], r["rtol"])):
            lines.append(
                f"| {r['label']} | {r['seed']} | {r['rtol']:g} | {r['level']:g} | "
                f"{r['scale']:.2e} | {r['d']:+.3f} | {r['centre']:+.3f} | {r['spread']:.3f} | "
                f"{r['runs_at_level']} | {r['evaluations']} |")
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text("\n".join(lines) + "\n")
    print("\n".join(lines[:8]))


if __name__ == "__main__":
    main()
