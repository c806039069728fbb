"""Does ending a sign-only run at the looser commit rule ever change its sign?

A search that locates a jumping margin's root by its signs alone runs each simulation with
``until_exit``; such a run is declared a go once its hottest HE cell passes the commit
temperature, where the adiabatic induction time is ``physics.thermal.SIGN_COMMIT_FRACTION`` of
the exit time, provided that it passes it by ``(1 - SIGN_COMMIT_GUARD * fraction) t_exit``
(docs/model.md, "Sign-only runs end at the commit temperature"). This sweep checks that rule
against the plain runaway rule on the runs where it could differ, the heights next to each
root:

* every scene of ``scripts/fast_tier_error.py``'s training and test sets and a fresh broad draw
  (300 scenes, seed 3; activation temperatures 15,000-40,000 K, heats of reaction 500-2,249
  cal/g, initial temperatures 250-350 K), with the exact target and the default search's
  melting spread, at levels 0, 0.5, 1 and 1.5 and melting widths 1 and 4 K;
* the root of each, searched to 2e-6 on ln H (a fixed-model search at rtol 1e-5);
* at H = H_c exp(d), d = +-1e-5, 1e-4, 1e-3, 1e-2 and 3e-2, the sign-only run with the commit
  rule and the same run with it switched off (``sign_commit_fraction`` 0).

Reported: the runs whose signs differ (the rule's claim is that none do); over the no-go runs
whose hottest cell peaked before the exit and cooled (the no-go side of a jump or a fold), the
smallest adiabatic induction time at that peak as a fraction of the exit time, the rule's
safety factor (how far below the commit temperature the hottest no-go peak stayed); and the
attempts the rule saves on the go runs.

Run: ``python scripts/sign_commit.py`` (~2 min on two cores); writes
results/validation/sign_commit.md.
"""

from __future__ import annotations

import argparse
import math
import multiprocessing
import statistics
import sys
from pathlib import Path

from skidmc.physics.thermal import (
    MELT_SPREAD,
    SIGN_COMMIT_FRACTION,
    SIGN_COMMIT_GUARD,
    SIGN_COMMIT_HEATING,
    adiabatic_induction_time,
    simulate_kernel,
)
from skidmc.solver import build_model, critical_height
from skidmc.solver.simulate import kernel_arguments

sys.path.insert(0, str(Path(__file__).resolve().parent))
from fast_tier_error import sweep_items  # noqa: E402

OUT = Path(__file__).resolve().parents[1] / "results" / "validation"
LEVELS = (0.0, 0.5, 1.0, 1.5)
WIDTHS = (1.0, 4.0)   # [K]
ROOT_RTOL = 1e-5      # with a given model: root tolerance 2e-6 on ln H
#: Offsets d of the probed heights H_c exp(d) from each root [1].
OFFSETS = tuple(s * d for d in (1e-5, 1e-4, 1e-3, 1e-2, 3e-2) for s in (-1.0, 1.0))
#: A no-go run "peaked" when its hottest cell at the exit is this much below its peak [K].
PEAKED_DROP = 1.0


#: The commit fraction tried (``--fraction``; the pool's workers inherit it).
COMMIT = {"fraction": SIGN_COMMIT_FRACTION}


def _run(model, height, commit):
    """The kernel's outcome record (:data:`skidmc.physics.records.KERNEL_OUTPUT`) of the
    sign-only run at ``height`` [m], with or without the commit rule."""
    return simulate_kernel(*kernel_arguments(
        model, height, until_exit=True,
        sign_commit_fraction=COMMIT["fraction"] if commit else 0.0))[0]


def _is_go(info, t_exit):
    return bool(info["event"]) and info["t_event"] <= t_exit


def sweep(item):
    """(set, index, rows) for one scene; a row per (level, width, offset)."""
    kind, index, scene = item
    rows = []
    for level in LEVELS:
        for width in WIDTHS:
            model = build_model(scene, level=level, melt_width=width, melt_spread=MELT_SPREAD,
                                target="exact")
            try:
                root = critical_height(scene, rtol=ROOT_RTOL, model=model)
            except Exception:  # noqa: BLE001 - the stall sweep covers failures; skip the scene
                continue
            if root.censored is not None:
                continue
            t_exit = model.exit_time
            rise = model.heat_of_reaction * model.he_density / model.rho_c[model.n_target]
            for offset in OFFSETS:
                height = root.critical_height * math.exp(offset)
                plain, committed = _run(model, height, False), _run(model, height, True)
                go = _is_go(plain, t_exit)
                row = dict(level=level, width=width, offset=offset, go=go,
                           agree=go == _is_go(committed, t_exit), exit_kind=model.exit_kind,
                           plain_attempts=int(plain["steps"] + plain["rejected"]),
                           commit_attempts=int(committed["steps"] + committed["rejected"]),
                           peak_fraction=math.nan)
                if not go and plain["t_exit_max"] < plain["t_max"] - PEAKED_DROP:
                    row["peak_fraction"] = adiabatic_induction_time(
                        plain["t_max"], model.prefactor, model.activation_temperature,
                        rise) / t_exit
                rows.append(row)
    return kind, index, rows


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--processes", type=int, default=2)
    parser.add_argument("--broad", type=int, default=300, help="scenes of the broad draw")
    parser.add_argument("--fraction", type=float, default=SIGN_COMMIT_FRACTION,
                        help="commit fraction to try (default: the kernel's)")
    args = parser.parse_args(argv)
    COMMIT["fraction"] = args.fraction
    items = sweep_items(args.broad)
    with multiprocessing.Pool(args.processes) as pool:
        results = []
        for n, res in enumerate(pool.imap_unordered(sweep, items, chunksize=4), 1):
            results.append(res)
            if n % 50 == 0:
                print(f"{n}/{len(items)} scenes", flush=True)
    rows = [dict(row, set=kind, index=index) for kind, index, rs in results for row in rs]
    report(rows, len(items))


def report(rows, n_scenes):
    fraction = COMMIT["fraction"]
    disagree = [r for r in rows if not r["agree"]]
    peaked = [r for r in rows if not math.isnan(r["peak_fraction"])]
    go = [r for r in rows if r["go"]]
    lines = [
        "# Sign-only runs ended at the commit temperature (scripts/sign_commit.py)",
        "",
        f"Commit rule: adiabatic induction time below {fraction:g} t_exit, "
        f"passed by (1 - {SIGN_COMMIT_GUARD:g} x {fraction:g}) t_exit, heating at least "
        f"{SIGN_COMMIT_HEATING:g} of the adiabatic rate over the step. "
        f"{n_scenes} scenes (scripts/fast_tier_error.py's training and test sets, a broad "
        f"draw of seed 3), exact target, melting spread {MELT_SPREAD:g}, levels "
        f"{', '.join(f'{v:g}' for v in LEVELS)}, widths {', '.join(f'{v:g}' for v in WIDTHS)}"
        " K; each root searched to 2e-6 on ln H, then the sign-only run with and without the "
        "rule at H_c exp(d), d = " + ", ".join(f"{d:+g}" for d in OFFSETS) + ".",
        "",
        f"- Runs compared: {len(rows)} ({len(go)} go, {len(rows) - len(go)} no-go).",
        f"- **Runs whose sign differs: {len(disagree)}.**",
    ]
    for r in disagree[:20]:
        verdict = "go" if r["go"] else "no-go"
        lines.append(f"  - {r['set']} #{r['index']}, level {r['level']:g}, width "
                     f"{r['width']:g} K, d = {r['offset']:+g}: plain {verdict}")
    if peaked:
        fractions = sorted(r["peak_fraction"] for r in peaked)
        lowest = fractions[0]
        lines += [
            f"- No-go runs whose hottest cell peaked before the exit and cooled by more than "
            f"{PEAKED_DROP:g} K: {len(peaked)}. Adiabatic induction time at their peak, as a "
            f"fraction of the exit time: smallest {lowest:.3g}, 1st percentile "
            f"{fractions[len(fractions) // 100]:.3g}, median {statistics.median(fractions):.3g}. "
            f"Safety factor of the rule's fraction (smallest / {fraction:g}): "
            f"**{lowest / fraction:.2g}**.",
        ]
        lines.append("")
        lines.append("| level | peaked no-go runs | smallest peak fraction | at d |")
        lines.append("|---|---|---|---|")
        for level in LEVELS:
            sel = [r for r in peaked if r["level"] == level]
            if sel:
                low = min(sel, key=lambda r: r["peak_fraction"])
                lines.append(f"| {level:g} | {len(sel)} | {low['peak_fraction']:.3g} | "
                             f"{low['offset']:+g} |")
        lines.append("")
    if go:
        saved = [1.0 - r["commit_attempts"] / r["plain_attempts"] for r in go]
        lines.append(f"- Go runs: the rule saves {100 * statistics.mean(saved):.1f} % of their "
                     f"attempts on average (median {100 * statistics.median(saved):.1f} %, "
                     f"range {100 * min(saved):.1f}-{100 * max(saved):.1f} %).")
        lines.append("")
        lines.append("| level | go runs | attempts saved, mean |")
        lines.append("|---|---|---|")
        for level in LEVELS:
            sel = [1.0 - r["commit_attempts"] / r["plain_attempts"] for r in go
                   if r["level"] == level]
            if sel:
                lines.append(f"| {level:g} | {len(sel)} | {100 * statistics.mean(sel):.1f} % |")
    OUT.mkdir(parents=True, exist_ok=True)
    text = "\n".join(lines) + "\n"
    name = ("sign_commit.md" if fraction == SIGN_COMMIT_FRACTION
            else f"sign_commit_fraction_{fraction:g}.md")
    (OUT / name).write_text(text)
    print(text)


if __name__ == "__main__":
    main()
