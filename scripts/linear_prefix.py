"""What sharing the linear start costs and saves: the default search with and without it.

The runs of one search at one level share their linear start (``solver.simulate.LinearPrefix``;
docs/model.md, "Runs of one search share their linear start"): a run after the first starts from
the first one's recorded state, scaled to its own flux, and takes that run's steps up to there.
Its result is then not the run from t = 0 but another step sequence's. This script measures what
that does to the default search's answers and what it saves, on

* every scene of ``scripts/fast_tier_error.py``'s training and test sets and a broad draw (300
  scenes, seed 3; activation temperatures 15,000-40,000 K): 864 scenes;
* at rtol 1e-3 and 3e-3, each searched twice in the same process: as shipped, and with every
  run from t = 0 (``LinearPrefix.mode`` patched to 0).

Reported per rtol: how far the heights moved, against the smaller of the two error estimates
(the claim: well inside them); the kernel's work (Newton iterations x cells, deterministic,
unlike the time) with over without, per scene; simulations; and the estimates.

Run: ``python scripts/linear_prefix.py`` (~8 min on two cores); writes
results/validation/linear_prefix.md.
"""

from __future__ import annotations

import argparse
import multiprocessing
import statistics
import sys
from pathlib import Path

import skidmc.solver.search as search
from skidmc.solver.simulate import LinearPrefix

sys.path.insert(0, str(Path(__file__).resolve().parent))
from fast_tier_error import sweep_items  # noqa: E402

OUT = Path(__file__).resolve().parents[1] / "results" / "validation"
RTOLS = (1e-3, 3e-3)

_WORK = [0]
_SIMULATE = search.simulate


def _counted_simulate(model, height, **kwargs):
    """search.simulate, adding each run's Newton iterations x cells to _WORK."""
    sim = _SIMULATE(model, height, **kwargs)
    _WORK[0] += sim.newton_iterations * model.width.shape[0]
    return sim


def _search(scene, rtol, shared):
    """(height [m], censoring, estimate [1], simulations, work) of the default search."""
    original = LinearPrefix.mode
    if not shared:
        LinearPrefix.mode = lambda self, height: 0
    _WORK[0] = 0
    try:
        res = search.critical_height(scene, rtol=rtol)
    finally:
        LinearPrefix.mode = original
    return res.critical_height, res.censored, res.error_estimate, res.evaluations, _WORK[0]


def _scene(item):
    index, scene = item
    search.simulate = _counted_simulate
    return index, {rtol: (_search(scene, rtol, True), _search(scene, rtol, False))
                   for rtol in RTOLS}


def _quantile(values, q):
    values = sorted(values)
    return values[min(len(values) - 1, int(q * len(values)))]


def report(rows, n):
    lines = ["# Runs of one search sharing their linear start (scripts/linear_prefix.py)", "",
             f"{n} scenes (the fast tier's training and test sets and a broad draw of 300, "
             "seed 3), each searched at each rtol as shipped (*shared*) and with every run "
             "from t = 0 (*plain*), in the same process. *moved*: |H_shared / H_plain - 1|; "
             "*/ estimate*: that over the smaller of the two error estimates. *work*: the "
             "kernel's Newton iterations x cells, shared over plain, per scene.", "",
             "| rtol | scenes | censoring differs | moved: median | p95 | max | "
             "/ estimate: median | p95 | max | > 1 | work: median | p10-p90 | total "
             "| simulations plain | shared | more | fewer | estimate > rtol (plain, shared) |",
             "|" + "---|" * 19]
    for rtol in RTOLS:
        pairs = [r[rtol] for r in rows]
        both = [(s, p) for s, p in pairs if s[1] is None and p[1] is None]
        moved = [abs(s[0] / p[0] - 1.0) for s, p in both]
        ratio = [m / min(s[2], p[2]) for m, (s, p) in zip(moved, both)]
        work = [s[4] / p[4] for s, p in pairs if p[4] > 0]
        total = sum(s[4] for s, _ in pairs) / sum(p[4] for _, p in pairs)
        sims_s = sum(s[3] for s, _ in pairs)
        sims_p = sum(p[3] for _, p in pairs)
        lines.append(
            f"| {rtol:g} | {len(pairs)} | {sum(s[1] != p[1] for s, p in pairs)} "
            f"| {statistics.median(moved):.1e} | {_quantile(moved, 0.95):.1e} "
            f"| {max(moved):.1e} | {statistics.median(ratio):.3f} "
            f"| {_quantile(ratio, 0.95):.3f} | {max(ratio):.3f} | {sum(r > 1 for r in ratio)} "
            f"| {statistics.median(work):.3f} | {_quantile(work, 0.1):.2f}-"
            f"{_quantile(work, 0.9):.2f} | {total:.3f} | {sims_p} | {sims_s} "
            f"| {sum(s[3] > p[3] for s, p in pairs)} | {sum(s[3] < p[3] for s, p in pairs)} "
            f"| {sum(p[2] > rtol * (1 + 1e-9) for _, p in both)}, "
            f"{sum(s[2] > rtol * (1 + 1e-9) for s, _ in both)} |")
    lines += ["", "Command: `python scripts/linear_prefix.py`."]
    return "\n".join(lines) + "\n"


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--processes", type=int, default=2)
    args = parser.parse_args(argv)
    items = list(enumerate(scene for _, _, scene in sweep_items()))
    rows = [None] * len(items)
    with multiprocessing.Pool(args.processes) as pool:
        for done, (index, row) in enumerate(pool.imap_unordered(_scene, items, chunksize=8), 1):
            rows[index] = row
            if done % 100 == 0:
                print(f"  {done}/{len(items)} scenes", file=sys.stderr)
    OUT.mkdir(parents=True, exist_ok=True)
    text = report(rows, len(items))
    (OUT / "linear_prefix.md").write_text(text)
    print(text)


if __name__ == "__main__":
    main()
