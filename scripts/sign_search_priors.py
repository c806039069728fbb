"""Where the roots of sign-located searches lie, against the priors that place their runs.

Where sliding stops before rebound (and on a rebound whose margin jumps at its root) the margin
says nothing of where the root lies, only its sign does: the search places each run at the
median of a normal prior on ln H inside its bracket (``finders.prior_bisection_start``). A root
several spreads from the prior's centre is reached by runs that creep: the prior's median moves
by ever smaller steps into its tail (z = 0, 0.67, 1.15, 1.53, ...) before the doubling steps
start. Two priors decide the first pair of such a scene:

* the **coarse** search from the fast tier's height: centre ln H_fast, spread
  ``adaptive.FAST_STOPS_SLIDING_SPREAD`` (measured on ``scripts/fast_tier_error.py``'s training
  scenes);
* the **fine** search from the coarse root: centre ln H_coarse + half the overshoot the machine
  gives it, spread ``sigma`` (with the exact target ``plan.EXACT_FINE_SHIFT`` and
  ``plan.EXACT_FINE_SHIFT_SPREAD`` of the coarse level's modelled error, measured on scenes of
  ``skidmc.scene.validation``; the meshed target's 0.375 and ``adaptive.FINE_SHIFT_SPREAD``).

For every search of a draw of study scenes (``benchmarks/study_scenes.py``) that locates its
root by signs, this script records the prior the search used and the level's own root found by
signs to 1e-7 in ln H from the bracket the search left, and writes the roots' places in the
priors' units: ``d = ln H_root - ln guess`` (the fast tier's height or the coarse root), in
ln H and, for the fine search, over the coarse level's modelled error. Usage::

    python scripts/sign_search_priors.py --seeds 101 102 103 --n 300        # training draws
    python scripts/sign_search_priors.py --seeds 104 --n 300 \
        --out results/validation/sign_search_priors_104.md                  # held out

Writes a markdown table (``--out``, default ``results/validation/sign_search_priors.md``).
"""

from __future__ import annotations

import argparse
import json
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
from skidmc.solver.adaptive import FAST_STOPS_SLIDING_SPREAD, REGIME_STOPS_SLIDING  # noqa: E402
from skidmc.solver.plan import EXACT_FINE_SHIFT_SPREAD, modelled_error  # noqa: E402
from skidmc.solver.roots import prior_bisection_root  # noqa: E402

_STAGES = {0: "coarse", 1: "fine"}   # adaptive's stage codes (_S_COARSE, _S_FINE, checked below)
_FIELDS = ("serial", "stage", "ask_level", "signs_only", "from_fast", "guess", "overshoot",
           "l_sigma", "x_tol", "exact", "fine_level", "regime")


class Recorder:
    """Wraps the search driver's calls: each run with the state of the search that asked it."""

    def __init__(self):
        self.runs = []
        self._asked, self._sim = adaptive.asked, search.simulate
        self._state = None

    def __enter__(self):
        def asked(ps):
            self._state = {f: ps[0][f].item() for f in _FIELDS}
            return self._asked(ps)

        def simulate(model, height, **kw):
            sim = self._sim(model, height, **kw)
            self.runs.append((self._state, model, math.log(height), sim.margin,
                              kw.get("until_exit", False)))
            return sim

        adaptive.asked, search.simulate = asked, simulate
        return self

    def __exit__(self, *exc):
        adaptive.asked, search.simulate = self._asked, self._sim


def sign_root(model, lo, hi, until_exit, tol=1e-7):
    """The margin's root by signs on ln H between a no-go ``lo`` and a go ``hi`` [ln m]."""
    from skidmc.solver.simulate import simulate

    while hi - lo > tol:
        mid = 0.5 * (lo + hi)
        if simulate(model, math.exp(mid), until_exit=until_exit).margin <= 0.0:
            hi = mid
        else:
            lo = mid
    return 0.5 * (lo + hi)


def measure(scene, rtol):
    """One row per sign-located coarse or fine search of the scene's first pair."""
    rec = Recorder()
    with rec:
        critical_height(scene, rtol=rtol)
    searches = {}
    for state, model, x, m, until_exit in rec.runs:
        searches.setdefault(state["serial"], []).append((state, model, x, m, until_exit))
    rows = []
    for runs in searches.values():
        state, model = runs[0][0], runs[0][1]
        if state["stage"] not in _STAGES or not state["signs_only"]:
            continue
        xs = [(x, m) for _s, mo, x, m, _u in runs if mo is model]
        go = [x for x, m in xs if m <= 0.0]
        nogo = [x for x, m in xs if m > 0.0]
        if not go or not nogo or max(nogo) >= min(go):
            continue
        root = sign_root(model, max(nogo), min(go), runs[0][4])
        x_guess = math.log(state["guess"])
        stage = _STAGES[state["stage"]]
        err = modelled_error(state["fine_level"] - 1.0)
        rows.append(dict(stage=stage, from_fast=state["from_fast"], exact=state["exact"],
                         regime=state["regime"],
                         level=state["ask_level"], d=root - x_guess, d_err=(root - x_guess) / err,
                         overshoot=state["overshoot"], sigma=state["l_sigma"],
                         x_tol=state["x_tol"], runs=len(xs), err=err))
    return rows


def emulated_runs(d, centre, sigma, x_tol):
    """Runs the prior's finder takes to a root at ``d`` [ln H, from the guess] from the prior
    N(``centre``, ``sigma``^2), with root tolerance ``x_tol``: the compiled finder
    (``finders.prior_bisection_start``) answered by the root's signs alone, as the search's
    runs answer it (no-go: a run stopped at the exit, margin inf). Raises where the finder's
    root is not within ``x_tol`` of ``d`` (it cannot be: the finder ends on a bracket at most
    2 ``x_tol`` wide around the root)."""
    count = 0

    def margin(x):
        nonlocal count
        count += 1
        return -0.2 if x >= d else math.inf

    root = prior_bisection_root(margin, centre, sigma, x_tol, -10.0, 10.0, signs_only=True)
    if root is None or abs(root - d) > x_tol * (1.0 + 1e-9):
        raise RuntimeError(f"the prior's finder missed the root {d!r} (got {root!r})")
    return count


#: The priors tried by emulation: the fine search's (centre, spread) in units of the coarse
#: level's modelled error (spread plus half the coarse root tolerance, as the search adds it),
#: and the coarse search's spread [ln H] about the fast tier's height.
FINE_TRIALS = [(c, s) for c in (0.10, 0.13) for s in (0.04, 0.06, 0.08, 0.10, 0.12, 0.15)]
COARSE_TRIALS = (0.012, 0.015, 0.02, 0.025)


def emulation_lines(rows, rtols):
    """Markdown: the mean runs (and the most) each trial prior would have taken on ``rows``."""
    lines = ["", "## Runs under other priors (emulated)", "",
             "Each search's runs replayed by the compiled finder answered by the measured root's "
             "signs (`emulated_runs`; with the prior the search used it gives the recorded runs "
             "exactly, checked in the first column). Mean runs per search (the most).", "",
             "| search | rtol | recorded | emulated, the prior used | "
             + " | ".join(f"c {c:g}, s {s:g}" for c, s in FINE_TRIALS) + " |",
             "|---|---|---|---|" + "---|" * len(FINE_TRIALS)]
    for rtol in rtols:
        sel = [r for r in rows if r["stage"] == "fine" and r["exact"] == 1 and r["rtol"] == rtol]
        if not sel:
            continue
        used = [emulated_runs(r["d"], 0.5 * r["overshoot"], r["sigma"], r["x_tol"]) for r in sel]
        cells = []
        for c, s in FINE_TRIALS:
            # the search's spread: EXACT_FINE_SHIFT_SPREAD err + half the coarse tolerance
            n = [emulated_runs(r["d"], c * r["err"],
                               r["sigma"] + (s - EXACT_FINE_SHIFT_SPREAD) * r["err"], r["x_tol"])
                 for r in sel]
            cells.append(f"{statistics.fmean(n):.2f} ({max(n)})")
        lines.append(f"| fine, exact target | {rtol:g} | "
                     f"{statistics.fmean(r['runs'] for r in sel):.2f} | "
                     f"{statistics.fmean(used):.2f} ({max(used)}) | " + " | ".join(cells) + " |")
    lines += ["", "| search | rtol | recorded | "
              + "emulated, the prior used | "
              + " | ".join(f"spread {s:g}" for s in COARSE_TRIALS) + " |",
              "|---|---|---|---|" + "---|" * len(COARSE_TRIALS)]
    for rtol in rtols:
        sel = [r for r in rows if r["stage"] == "coarse" and r["exact"] == 1 and r["from_fast"]
               and r["regime"] == REGIME_STOPS_SLIDING and r["rtol"] == rtol]
        if not sel:
            continue
        used = [emulated_runs(r["d"], 0.0, FAST_STOPS_SLIDING_SPREAD, r["x_tol"]) for r in sel]
        cells = [f"{statistics.fmean(used):.2f} ({max(used)})"]
        for s in COARSE_TRIALS:
            n = [emulated_runs(r["d"], 0.0, s, r["x_tol"]) for r in sel]
            cells.append(f"{statistics.fmean(n):.2f} ({max(n)})")
        lines.append(f"| coarse from the fast tier, exact target | {rtol:g} | "
                     f"{statistics.fmean(r['runs'] for r in sel):.2f} | " + " | ".join(cells)
                     + " |")
    return lines


def _summary(values):
    if not values:
        return "-"
    sd = statistics.stdev(values) if len(values) > 1 else math.nan
    q = statistics.quantiles(values, n=10) if len(values) > 2 else [math.nan] * 9
    return (f"{len(values)} | {statistics.fmean(values):+.4f} | {sd:.4f} | {min(values):+.4f} | "
            f"{q[0]:+.4f} | {statistics.median(values):+.4f} | {q[-1]:+.4f} | {max(values):+.4f}")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, nargs="+", default=[101, 102, 103])
    ap.add_argument("--n", type=int, default=300, help="samples per study and seed")
    ap.add_argument("--rtols", type=float, nargs="+", default=[1e-3, 3e-3, 1e-2])
    ap.add_argument("--out", default=str(ROOT / "results" / "validation" /
                                         "sign_search_priors.md"))
    ap.add_argument("--json", default=None, help="also every search's row, as JSON")
    args = ap.parse_args(argv)
    assert (adaptive._S_COARSE, adaptive._S_FINE) == (0, 1)
    rows = []
    t0 = time.perf_counter()
    n_scenes = 0
    for seed in args.seeds:
        scenes = study_scenes.draw(n_per_study=args.n, seed=seed)
        n_scenes += len(scenes)
        for label, _group, scene in scenes:
            for rtol in args.rtols:
                try:
                    found = measure(scene, rtol)
                except Exception as exc:  # noqa: BLE001 - a failed search is reported, not fatal
                    print(f"{label} rtol {rtol:g}: {type(exc).__name__}: {exc}", flush=True)
                    continue
                for row in found:
                    row.update(label=label, seed=seed, rtol=rtol)
                    rows.append(row)
                    print(f"{label} rtol {rtol:g} {row['stage']}: d = {row['d']:+.5f} "
                          f"({row['d_err']:+.3f} err), {row['runs']} runs", flush=True)
    lines = [
        "# Where sign-located searches find their roots, against their priors",
        "",
        f"Generated by `python scripts/sign_search_priors.py --seeds "
        f"{' '.join(map(str, args.seeds))} --n {args.n} --rtols "
        f"{' '.join(f'{r:g}' for r in args.rtols)}` in {time.perf_counter() - t0:.0f} s: "
        f"{n_scenes} scenes drawn from the shipped studies (`benchmarks/study_scenes.py`); every "
        "coarse or fine search of a first pair that located its root by signs. d = ln H_root - "
        "ln guess, H_root the search level's own root by signs to 1e-7 in ln H, the guess the "
        "fast tier's height (coarse search) or the coarse root (fine search); err = the coarse "
        "level's modelled error (`plan.modelled_error`).",
        "",
        "| search | target | rtol | searches | mean | sd | min | p10 | median | p90 | max | "
        "runs (mean) | prior used: centre, spread |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for stage, unit in (("coarse", "d"), ("fine", "d_err")):
        for exact in (1, 0):
            for rtol in args.rtols:
                sel = [r for r in rows if r["stage"] == stage and r["exact"] == exact
                       and r["rtol"] == rtol and (stage == "fine" or (
                           r["from_fast"] and r["regime"] == REGIME_STOPS_SLIDING))]
                if not sel:
                    continue
                if stage == "coarse":
                    prior = "0, adaptive.FAST_STOPS_SLIDING_SPREAD (ln H)"
                else:
                    c = statistics.fmean(0.5 * r["overshoot"] / r["err"] for r in sel)
                    s = statistics.fmean(r["sigma"] / r["err"] for r in sel)
                    prior = f"{c:+.3f}, {s:.3f} (err; spread with half the coarse tolerance)"
                lines.append(
                    f"| {stage} ({'ln H' if unit == 'd' else 'err'}) | "
                    f"{'exact' if exact else 'meshed'} | {rtol:g} | "
                    f"{_summary([r[unit] for r in sel])} | "
                    f"{statistics.fmean(r['runs'] for r in sel):.2f} | {prior} |")
    lines += emulation_lines(rows, args.rtols)
    Path(args.out).write_text("\n".join(lines) + "\n")
    if args.json:
        Path(args.json).write_text(json.dumps(rows))
    print("\n".join(lines))


if __name__ == "__main__":
    main()
