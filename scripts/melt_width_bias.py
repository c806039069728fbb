"""Bias of the critical height from the smoothed melting step, against its width.

The HE's latent heat is released over a tanh step of width w around T_m
(``skidmc.physics.thermal._he_enthalpy``); sharp Stefan melting is the limit w -> 0. At a fixed,
fine resolution level the critical height is computed for w = 0.125 ... 4 K and compared with
its limit w -> 0, extrapolated linearly from w = 0.25 and 0.125 K (the bias is close to first
order in w). The bias per kelvin bounds ``skidmc.solver.model.MELT_WIDTH_BIAS_PER_K``, which the
solver uses to choose w from its tolerance (``skidmc.solver.plan.melt_width_for_rtol``).

Writes results/validation/melt_width_bias.{csv,md}. Run: ``python scripts/melt_width_bias.py``
(~5 min on one core).
"""

from __future__ import annotations

import argparse
import csv
from pathlib import Path

from skidmc.scene import make_scene
from skidmc.solver import critical_height
from skidmc.solver.model import MELT_WIDTH_BIAS_PER_K

OUT = Path(__file__).resolve().parents[1] / "results" / "validation"
WIDTHS = [0.125, 0.25, 0.5, 1.0, 2.0, 4.0]
CASES = {
    "paper-quartz": {},
    "paper-alumina-smooth": {},
    "paper-alumina-rough": {},
    "paper2-quartz mu=0.056": {"preset": "paper2-quartz", "mu": 0.056},
    "paper2-quartz mu=0.243": {"preset": "paper2-quartz", "mu": 0.243},
}


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--level", type=float, default=2.5)
    args = parser.parse_args()
    OUT.mkdir(parents=True, exist_ok=True)
    rows, worst = [], 0.0
    for case, spec in CASES.items():
        spec = dict(spec)
        scene = make_scene(preset=spec.pop("preset", case), **spec)
        heights, guess = {}, None
        for width in WIDTHS:
            res = critical_height(scene, level=args.level, rtol=1e-6, melt_width=width,
                                  h_guess=guess)
            heights[width] = guess = res.critical_height
        # Sharp limit, linear in w from the two narrowest steps.
        ref = heights[WIDTHS[0]] - (heights[WIDTHS[1]] - heights[WIDTHS[0]]) * WIDTHS[0] / (
            WIDTHS[1] - WIDTHS[0])
        for width in WIDTHS:
            bias = heights[width] / ref - 1.0
            per_k = bias / width
            worst = max(worst, abs(per_k))
            rows.append((case, width, heights[width], bias, per_k))
            print(f"{case:26s} w = {width:5.3f} K  H = {heights[width]:.8g} m  bias {bias:+.2e}"
                  f"  per K {per_k:+.2e}", flush=True)

    with open(OUT / "melt_width_bias.csv", "w", newline="") as fh:
        writer = csv.writer(fh)
        writer.writerow(["case", "melt_width_K", "critical_height_m", "bias_vs_sharp_limit",
                         "bias_per_K"])
        for case, width, h, bias, per_k in rows:
            writer.writerow([case, width, f"{h:.10g}", f"{bias:.3e}", f"{per_k:.3e}"])
    lines = [
        "# Bias of the critical height from the smoothed melting step",
        "",
        f"`python scripts/melt_width_bias.py` - level {args.level:g}, root tolerance 2e-7 on "
        "ln H; relative bias of the critical height against the sharp limit w -> 0 "
        "(extrapolated linearly from w = 0.25 and 0.125 K), and per kelvin (bias / w).",
        "",
        "| case | " + " | ".join(f"w = {w:g} K" for w in WIDTHS) + " |",
        "|---|" + "---|" * len(WIDTHS),
    ]
    for case in CASES:
        cells = [f"{bias:+.1e} ({per_k:+.1e}/K)" for c, w, _, bias, per_k in rows if c == case]
        lines.append(f"| {case} | " + " | ".join(cells) + " |")
    lines += [
        "",
        f"Largest bias per kelvin: {worst:.2e} /K; the solver's bound "
        f"MELT_WIDTH_BIAS_PER_K = {MELT_WIDTH_BIAS_PER_K:.2e} /K "
        + ("covers it." if worst <= MELT_WIDTH_BIAS_PER_K else "DOES NOT cover it."),
        "The bias is close to first order in w (not second, as a symmetric smoothing alone "
        "would give), so the solver keeps w fixed across the levels of a search and bounds "
        "its bias separately (skidmc.solver.plan.melt_width_for_rtol).",
    ]
    (OUT / "melt_width_bias.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
