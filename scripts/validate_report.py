"""Validation against the report: Table VIII (first series) and Table IX (second series).

Computes skidmc's critical height for every row at rtol = 1e-3 and writes, beside the
report's calculated and experimental heights, results/validation/report_tables.{csv,md,png}.
Run: ``python scripts/validate_report.py`` (about a minute on 2 cores).
"""

from __future__ import annotations

import csv
import statistics
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

from skidmc.scene import make_scene  # noqa: E402
from skidmc.scene.presets import PAPER_TABLE_IX, PAPER_TABLE_VIII  # noqa: E402
from skidmc.solver import critical_height  # noqa: E402

OUT = Path(__file__).resolve().parents[1] / "results" / "validation"
RTOL = 1e-3


def main():
    OUT.mkdir(parents=True, exist_ok=True)
    rows = []
    for table, entries in (("VIII", PAPER_TABLE_VIII), ("IX", PAPER_TABLE_IX)):
        for row in entries:
            scene = make_scene(preset=row.preset, mu=row.mu)
            critical_height(scene, rtol=1e-1)  # compile outside the timing
            res = critical_height(scene, rtol=RTOL)
            rows.append(dict(
                table=table, preset=row.preset, label=row.label, mu=row.mu,
                report_ft=row.calculated_ft, skidmc_ft=res.critical_height_ft,
                diff=res.critical_height_ft / row.calculated_ft - 1.0,
                experimental=(row.experimental_qualifier.replace("=", "")
                              + f"{row.experimental_ft:g}"),
                experimental_ft=row.experimental_ft, censored=res.censored or "",
                error=res.error_estimate, evaluations=res.evaluations,
                wall_ms=1e3 * res.wall_time, exit=res.exit_kind))
            print(rows[-1], flush=True)

    with open(OUT / "report_tables.csv", "w", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)

    median_ms = statistics.median(r["wall_ms"] for r in rows)
    lines = [
        "# skidmc against the report's calculated critical heights",
        "",
        f"`python scripts/validate_report.py`; rtol = {RTOL:g} (estimated numerical error of each "
        "value in the `error` column). Heights in ft.",
        "",
        "| table | scene | mu | report calculated | skidmc | difference | experimental 50 % | "
        "exit | error | simulations | time [ms] |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        lines.append(
            f"| {r['table']} | {r['label']} | {r['mu']} | {r['report_ft']:g} | "
            f"{r['skidmc_ft']:.3f} | "
            f"{100 * r['diff']:+.1f} % | {r['experimental']} | {r['exit']} | {r['error']:.1e} | "
            f"{r['evaluations']} | {r['wall_ms']:.0f} |")
    lines += [
        "",
        f"Median wall time per critical height at rtol = {RTOL:g}: {median_ms:.0f} ms "
        "(one core of this machine, numba compiled beforehand).",
        "",
        "Second-series billets: mass 25.3 lb is an inferred assumption (the report does not give "
        "it); see second_series.md.",
    ]
    (OUT / "report_tables.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))

    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(11, 4.5))
    first = [r for r in rows if r["table"] == "VIII"]
    x = range(len(first))
    ax1.semilogy(x, [r["report_ft"] for r in first], "s", label="report, calculated")
    ax1.semilogy(x, [r["skidmc_ft"] for r in first], "o", mfc="none", ms=10, label="skidmc")
    ax1.semilogy(x, [r["experimental_ft"] for r in first], "^",
                 label="experimental 50 % (gold: > 150)")
    ax1.set_xticks(list(x), [r["preset"].replace("paper-", "") for r in first])
    ax1.set_ylabel("critical drop height [ft]")
    ax1.set_title("First series (Table VIII)")
    ax1.grid(True, which="both", alpha=0.3)
    ax1.legend(fontsize=8)
    second = [r for r in rows if r["table"] == "IX"]
    mus = [r["mu"] for r in second]
    ax2.loglog(mus, [r["report_ft"] for r in second], "s", label="report, calculated")
    ax2.loglog(mus, [r["skidmc_ft"] for r in second], "o", mfc="none", ms=10, label="skidmc")
    ax2.loglog(mus, [r["experimental_ft"] for r in second], "^", label="experimental")
    ax2.set_xlabel("apparent coefficient of friction mu [1]")
    ax2.set_ylabel("critical drop height [ft]")
    ax2.set_title("Second series on quartz (Table IX)")
    ax2.grid(True, which="both", alpha=0.3)
    ax2.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(OUT / "report_tables.png", dpi=150)


if __name__ == "__main__":
    main()
