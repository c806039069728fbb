"""Are the numbers a shipped report quotes stable at the study's size?

A nested study's report quotes, per scene, the pooled H50 (censored log-normal fit), the median
of the per-epistemic-draw H50 and its 5-95 % band across epistemic draws. This script recomputes
them from the two halves of the epistemic draws (draws 0, 2, 4, ... and 1, 3, 5, ...: each half
a spread-out subset of the Latin hypercube) and from bootstrap resamples of the draws, and writes
how far they move: a quoted number is stable when the halves agree to within a few percent and
the bootstrap spread is small against the differences the report discusses.

Usage::

    python scripts/report_stability.py results/paper-series1/ensemble.h5 [...]

writes ``stability.md`` beside each ensemble.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from skidmc.analysis import open_ensemble
from skidmc.analysis.report import EPISTEMIC_BAND, FT, analyse_scene, scene_names

RESAMPLES = 400


def _band(h50: np.ndarray) -> tuple[float, float, float]:
    lo, hi = np.nanquantile(h50, EPISTEMIC_BAND)
    return float(np.nanmedian(h50)), float(lo), float(hi)


def _pooled_h50(ds, scene: str) -> float:
    sub = ds.sel(scene=scene) if "scene" in ds.dims else ds
    h = sub["critical_height"].values.reshape(-1) / FT
    st = np.asarray(sub["status"].values).astype(str).reshape(-1)
    ok = (st != "") & (st != "failed")
    return float(np.median(np.where(st[ok] == "censored_above", np.inf, h[ok])))


def main(paths: list[str]) -> None:
    rng = np.random.default_rng(0)
    for path in map(Path, paths):
        ds = open_ensemble(path)
        if "epistemic" not in ds.dims:
            raise SystemExit(f"{path}: not a nested design")
        n_e = ds.sizes["epistemic"]
        lines = [f"# Stability of the quoted numbers: {path.parent.name}", "",
                 f"`python scripts/report_stability.py {path}`: {n_e} epistemic draws x "
                 f"{ds.sizes['sample']} aleatory samples. Halves: even and odd epistemic draws. "
                 f"Bootstrap: {RESAMPLES} resamples of the draws (their 5-95 % range). Heights "
                 "in ft.", "",
                 "| scene | quantity | all draws | even half | odd half | halves differ | "
                 "bootstrap 5-95 % |", "|---|---|---|---|---|---|---|"]
        for scene in scene_names(ds):
            h50 = analyse_scene(ds, scene).epistemic["h50"].values
            halves = [h50[0::2], h50[1::2]]
            boots = np.array([_band(h50[rng.integers(0, n_e, n_e)]) for _ in range(RESAMPLES)])
            full = _band(h50)
            parts = [_band(h) for h in halves]
            names = ("median of per-draw H50", "5 % of per-draw H50", "95 % of per-draw H50")
            for i, name in enumerate(names):
                a, b = parts[0][i], parts[1][i]
                lo, hi = np.quantile(boots[:, i], [0.05, 0.95])
                lines.append(f"| {scene} | {name} | {full[i]:.3g} | {a:.3g} | {b:.3g} | "
                             f"{abs(a / b - 1):.1%} | {lo:.3g} - {hi:.3g} |")
            pooled = _pooled_h50(ds, scene)
            even = _pooled_h50(ds.isel(epistemic=slice(0, None, 2)), scene)
            odd = _pooled_h50(ds.isel(epistemic=slice(1, None, 2)), scene)
            lines.append(f"| {scene} | pooled median H_c | {pooled:.3g} | {even:.3g} | "
                         f"{odd:.3g} | {abs(even / odd - 1):.1%} | - |")
        out = path.parent / "stability.md"
        out.write_text("\n".join(lines) + "\n")
        print(out)


if __name__ == "__main__":
    main(sys.argv[1:])
