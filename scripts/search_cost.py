"""What the default search costs on study scenes, and how far its heights lie from tight ones.

For each scene of a draw from the shipped studies (``benchmarks/study_scenes.py``) and each
rtol, records the critical height, its error estimate, the simulations the search ran and its
Newton cell-passes (each run's Newton iterations times its cells: the kernel's work, free of the
shared machine's timing noise), and, at ``--reference-rtol``, a tight height to measure the
error against. Run it once per source tree (``PYTHONPATH`` selects the tree, as for
``benchmarks/heights_fingerprint.py``), then compare::

    git archive <commit> src | tar -x -C /tmp/base-<commit>
    PYTHONPATH=/tmp/base-<commit>/src python scripts/search_cost.py --seed 45 --out /tmp/a.json
    PYTHONPATH=$PWD/src python scripts/search_cost.py --seed 45 --no-reference --out /tmp/b.json
    python scripts/search_cost.py --compare /tmp/a.json /tmp/b.json --labels <commit> HEAD \
        --md results/validation/x.md

The reference heights are taken from the first file (or from the second where the first has
none). Used for the go-side finder's aim (docs/performance.md, issue 45, ninth pass).
"""

from __future__ import annotations

import argparse
import json
import math
import statistics
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))

RTOLS = (1e-2, 3e-3, 1e-3)


def record(seed, n_per_study, rtols, reference_rtol):
    """Per scene: label, tabled (a temperature-dependent target) and, per rtol, (height [m],
    estimate [1], simulations, Newton cell-passes); the reference height [m] or None."""
    import study_scenes

    import skidmc
    from skidmc import critical_height
    from skidmc.solver import search

    counts = [0, 0]
    simulate = search.simulate

    def counting(model, height, **kw):
        sim = simulate(model, height, **kw)
        counts[0] += 1
        counts[1] += sim.newton_iterations * len(model.width)
        return sim

    search.simulate = counting
    try:
        rows = []
        for label, group, scene in study_scenes.draw(n_per_study, seed):
            row = {"label": label, "tabled": ":" in group, "runs": {}}
            for rtol in rtols:
                counts[:] = [0, 0]
                res = critical_height(scene, rtol=rtol)
                row["runs"][repr(rtol)] = (res.critical_height, res.error_estimate, counts[0],
                                           counts[1])
            row["reference"] = (critical_height(scene, rtol=reference_rtol).critical_height
                                if reference_rtol else None)
            rows.append(row)
    finally:
        search.simulate = simulate
    return {"package": skidmc.__file__, "seed": seed, "n_per_study": n_per_study,
            "reference_rtol": reference_rtol, "rows": rows}


def summary(data, reference):
    """Per rtol: simulations (tabled, constant targets), cell-passes, |error| and error /
    estimate against ``reference`` (heights [m], one per scene)."""
    out = {}
    for rtol in data["rows"][0]["runs"]:
        runs = [(row, row["runs"][rtol]) for row in data["rows"]]
        err = [abs(math.log(r[0] / ref)) for (_, r), ref in zip(runs, reference)]
        ratio = [e / r[1] for e, (_, r) in zip(err, runs)]
        out[rtol] = {
            "sims_tabled": sum(r[2] for row, r in runs if row["tabled"]),
            "sims_constant": sum(r[2] for row, r in runs if not row["tabled"]),
            "cell_passes": sum(r[3] for _, r in runs),
            "error_median": statistics.median(err), "error_max": max(err),
            "ratio_median": statistics.median(ratio), "ratio_max": max(ratio),
            "over_estimate": sum(1 for x in ratio if x > 1.0),
        }
    return out


def compare(path_a, path_b, labels=None):
    a, b = (json.loads(Path(p).read_text()) for p in (path_a, path_b))
    name_a, name_b = labels or (a["package"], b["package"])
    if [r["label"] for r in a["rows"]] != [r["label"] for r in b["rows"]]:
        raise SystemExit("the two files hold different scenes")
    source = a if a["rows"][0]["reference"] is not None else b
    reference = [r["reference"] for r in source["rows"]]
    if any(x is None for x in reference):
        raise SystemExit("neither file holds reference heights (run one without "
                         "--no-reference)")
    sa, sb = summary(a, reference), summary(b, reference)
    lines = [
        f"# Search cost and error: {name_a} -> {name_b}",
        "",
        f"`python scripts/search_cost.py --compare`: {len(reference)} scenes drawn from the "
        f"shipped studies (`benchmarks/study_scenes.py`, seed {a['seed']}, {a['n_per_study']} "
        f"per study); reference: each scene's height at rtol {source['reference_rtol']:g}. "
        "Cell-passes: Newton iterations x cells, summed over the search's runs.",
        "",
        "| rtol | simulations, tabled targets | constant targets | Newton cell-passes "
        "| error / estimate (median, max) | \\|error\\| (median, max) | errors above their "
        "estimate |",
        "|---|---|---|---|---|---|---|",
    ]
    for rtol in sa:
        x, y = sa[rtol], sb[rtol]
        change = y["cell_passes"] / x["cell_passes"] - 1.0
        lines.append(
            f"| {float(rtol):g} | {x['sims_tabled']} -> {y['sims_tabled']} | "
            f"{x['sims_constant']} -> {y['sims_constant']} | "
            f"{x['cell_passes'] / 1e6:.2f}M -> {y['cell_passes'] / 1e6:.2f}M "
            f"({100 * change:+.1f} %) | {x['ratio_median']:.3f}, {x['ratio_max']:.3f} -> "
            f"{y['ratio_median']:.3f}, {y['ratio_max']:.3f} | {x['error_median']:.2e}, "
            f"{x['error_max']:.2e} -> {y['error_median']:.2e}, {y['error_max']:.2e} | "
            f"{x['over_estimate']} -> {y['over_estimate']} |")
    return "\n".join(lines) + "\n"


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seed", type=int, default=45)
    parser.add_argument("--n", type=int, default=30, help="samples per study (default 30)")
    parser.add_argument("--rtols", type=float, nargs="+", default=list(RTOLS))
    parser.add_argument("--reference-rtol", type=float, default=1e-4)
    parser.add_argument("--no-reference", action="store_true",
                        help="skip the tight reference heights (take them from the other file)")
    parser.add_argument("--out", help="write the record here (JSON)")
    parser.add_argument("--compare", nargs=2, metavar=("BEFORE", "AFTER"))
    parser.add_argument("--md", help="with --compare: write the table here too")
    parser.add_argument("--labels", nargs=2, metavar=("BEFORE", "AFTER"),
                        help="with --compare: name the two trees (default: their packages)")
    args = parser.parse_args(argv)
    if args.compare:
        text = compare(*args.compare, labels=args.labels)
        print(text)
        if args.md:
            Path(args.md).write_text(text)
        return
    if not args.out:
        parser.error("--out or --compare is required")
    data = record(args.seed, args.n, args.rtols,
                  None if args.no_reference else args.reference_rtol)
    Path(args.out).write_text(json.dumps(data))
    print(f"{len(data['rows'])} scenes x {len(args.rtols)} rtol from {data['package']} "
          f"-> {args.out}")


if __name__ == "__main__":
    main()
