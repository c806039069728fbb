"""Extract the model's prior predictive of H50 per target from a shipped ensemble into a small CSV.

Usage::

    PYTHONPATH=src python scripts/physics_prior.py [results/paper-series1/ensemble.h5]

writes ``src/skidmc/data/priors/paper_series1_h50.csv``: one row per (scene, epistemic draw) with
the draw's median critical height (ln H50 [ln ft]: the median of ln H_c over the draw's aleatory
samples) and its aleatory spread (sigma_ln: the sd of ln H_c over those samples). The planning
(``skidmc.analysis.planning``) and ``skidmc.analysis.physics_prior`` read it; a calibration
posterior can later be written in the same form. Censored or failed samples: the median uses the
censored bound (a censored sample lies beyond it, so the median is still right while fewer than
half are censored); the sd uses the finite uncensored values only and the count is recorded.
"""

from __future__ import annotations

import argparse
import hashlib
import sys
from pathlib import Path

import numpy as np

import skidmc
from skidmc.scene.units import FOOT


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("ensemble", nargs="?", default="results/paper-series1/ensemble.h5")
    parser.add_argument("--out", default="src/skidmc/data/priors/paper_series1_h50.csv")
    args = parser.parse_args(argv)
    path = Path(args.ensemble)
    ds = skidmc.open_ensemble(path)
    if "epistemic" not in ds.dims:
        print(f"{path}: not a nested (epistemic x aleatory) design", file=sys.stderr)
        return 2
    scenes = ds.attrs["study"]["scenes"]
    experiment = {s["name"]: s.get("experiment", "") for s in scenes}
    digest = hashlib.sha256(path.read_bytes()).hexdigest()
    rows = []
    for scene in ds.scene.values:
        h = ds.critical_height.sel(scene=scene).values / FOOT  # (epistemic, sample) [ft]
        status = ds.status.sel(scene=scene).values
        for e in range(h.shape[0]):
            ok = (status[e] == "ok") & np.isfinite(h[e])
            finite = np.isfinite(h[e])
            ln_h50 = float(np.median(np.log(h[e][finite])))
            sigma = float(np.std(np.log(h[e][ok]), ddof=1))
            rows.append((str(scene), experiment[str(scene)], e, ln_h50, sigma,
                         int(ok.sum()), int(finite.sum() - ok.sum())))
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    a = ds.attrs
    with out.open("w", encoding="utf-8") as f:
        f.write("# The model's prior predictive of the 50 % drop height per target (issue 43), "
                "from\n")
        f.write(f"# ensemble {path.as_posix()} (study {a['study_name']}, study sha256 "
                f"{a['study_sha256']},\n")
        f.write(f"# file sha256 {digest}, skidmc {a['skidmc_version']}, completed "
                f"{a['completed']}, solver tier {a['solver']['tier']} rtol "
                f"{a['solver']['rtol']}),\n")
        f.write("# written by scripts/physics_prior.py. One row per scene and epistemic draw:\n")
        f.write("# ln_h50_ft = median of ln(H_c / ft) over the draw's aleatory samples; "
                "sigma_ln = sd "
                "of ln H_c over them\n")
        f.write("# (uncensored samples, n_ok); n_censored = samples at a search bound.\n")
        f.write("scene,experiment,draw,ln_h50_ft,sigma_ln,n_ok,n_censored\n")
        for r in rows:
            f.write(f"{r[0]},{r[1]},{r[2]},{r[3]:.6f},{r[4]:.6f},{r[5]},{r[6]}\n")
    print(f"wrote {out} ({len(rows)} rows)")
    for scene in ds.scene.values:
        mine = [r for r in rows if r[0] == scene]
        ln = np.array([r[3] for r in mine])
        sg = np.array([r[4] for r in mine])
        print(f"{scene:15s} H50 median {np.exp(np.median(ln)):8.3g} ft, "
              f"sd ln H50 {ln.std(ddof=1):.3f},"
              f" sigma {np.median(sg):.3f} ({sg.min():.3f}-{sg.max():.3f})")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
