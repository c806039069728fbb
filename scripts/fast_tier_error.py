"""Error and cost of the fast tier (skidmc.solver.fast) against the full model.

Usage::

    python scripts/fast_tier_error.py          # test-set error + timing -> results/benchmarks/
    python scripts/fast_tier_error.py --fit    # refit the three constants on the training set

Scene sets (all scenes are valid skidmc scenes; full model = skidmc.solver.critical_height with
rtol = 1e-2, melting on, i.e. the default model):

* studies: samples of the shipped studies' designs (studies/paper-series1.toml: 4 scenes,
  studies/paper-series2.toml: 5 scenes), turned into scenes the way the runner does
  (StudySampler.draw -> scene.replace). Training uses design rows [0, N_TRAIN_ROWS); the test
  uses rows [TEST_START, TEST_START + n) - disjoint.
* broad: scenes drawn around the paper-quartz preset far beyond the studies (friction
  0.02-0.5, flow stress 30-500 MPa, mass 1-50 kg, angle 20-80 deg, pendulum or vertical drop,
  T0 250-350 K, T_a 15000-40000 K, rate at 575 K over +/- 1.5 decades (1 sigma), Q 500-2249
  cal/g, target k 1-400 W/(m K), rho 2200-9000 kg/m^3, c 380-900 J/(kg K)). Training uses seed
  1, the test seed 2.

The constants were fitted with ``--fit`` on the training set only; the reported error is on the
test set. Timing: microseconds per height of the compiled batched kernel (one core, after
compilation; call time over the batch size, median of repeated calls), and the median over scenes
of the per-scene Python entry point.
"""

from __future__ import annotations

import argparse
import csv
import math
import sys
import time
from pathlib import Path

import numpy as np

from skidmc.ensemble.sampling import StudySampler
from skidmc.ensemble.study import RATE_AT_REFERENCE, load_study
from skidmc.physics.fast import ERROR_ESTIMATE, ERROR_SELF_HEATING, ERROR_STOPS_SLIDING
from skidmc.physics.mechanics import EXIT_STOPS_SLIDING
from skidmc.scene import get_preset
from skidmc.scene.units import FOOT
from skidmc.solver import critical_height, fast

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "results" / "benchmarks"
STUDIES = ("studies/paper-series1.toml", "studies/paper-series2.toml")
PRESETS = ("paper-gold", "paper-alumina-smooth", "paper-alumina-rough", "paper-quartz",
           "paper2-quartz")
N_TRAIN_ROWS = 12
TEST_START = 128
RTOL = 1e-2


def study_scenes(path, start, stop):
    """(label, scene) of design rows start:stop of every scene of a study."""
    study = load_study(ROOT / path)
    draws = StudySampler(study).draw(start, stop)
    out = []
    for sc, d in zip(study.scenes, draws):
        for i in range(stop - start):
            ov = {k: float(v[i]) for k, v in d.items() if k != RATE_AT_REFERENCE}
            out.append((f"{study.name}/{sc.name}", sc.scene.replace(ov)))
    return out


def broad_scenes(n, seed):
    """(label, scene) of n scenes far beyond the studies (see module docstring)."""
    rng = np.random.default_rng(seed)
    base = get_preset("paper-quartz")
    out = []
    for _ in range(n):
        t_act = rng.uniform(15000.0, 40000.0)
        k_ref = 5e19 * math.exp(-26300.0 / 575.0) * math.exp(rng.normal(0.0, 1.5 * math.log(10)))
        vertical = rng.random() < 0.3
        angle = rng.uniform(20.0, 80.0)
        ov = {
            "mu": math.exp(rng.uniform(math.log(0.02), math.log(0.5))),
            "flow_stress": math.exp(rng.uniform(math.log(30e6), math.log(500e6))),
            "billet_mass": math.exp(rng.uniform(math.log(1.0), math.log(50.0))),
            "angle": angle, "tilt": angle if vertical else 0.0,
            "initial_temperature": rng.uniform(250.0, 350.0),
            "kinetics.activation_temperature": t_act,
            "kinetics.prefactor": k_ref * math.exp(t_act / 575.0),
            "kinetics.heat_of_reaction": rng.uniform(500.0, 2249.0) * 4184.0,
            "target.conductivity": math.exp(rng.uniform(math.log(1.0), math.log(400.0))),
            "target.density": rng.uniform(2200.0, 9000.0),
            "target.heat_capacity": rng.uniform(380.0, 900.0),
        }
        out.append(("broad", base.replace(ov)))
    return out


def scene_set(kind):
    if kind == "train":
        rows = (0, N_TRAIN_ROWS)
        seed, n_broad = 1, 120
    else:
        rows = (TEST_START, TEST_START + 24)
        seed, n_broad = 2, 120
    scenes = []
    for path in STUDIES:
        scenes += study_scenes(path, *rows)
    scenes += broad_scenes(n_broad, seed)
    return scenes


def sweep_items(n_broad=300, seed=3):
    """(set, index, scene) of the sweeps' scenes (``scripts/stall_sweep.py``,
    ``scripts/sign_commit.py``): the training and test sets and a broad draw of ``n_broad``."""
    items = [(kind, i, scene) for kind in ("train", "test")
             for i, (_, scene) in enumerate(scene_set(kind))]
    items += [(f"broad seed {seed}", i, scene)
              for i, (_, scene) in enumerate(broad_scenes(n_broad, seed))]
    return items


def full_heights(scenes):
    """Full-model heights [m], censoring and wall time per scene [s]."""
    h, cens, wall = [], [], []
    for i, (_, s) in enumerate(scenes):
        t = time.perf_counter()
        r = critical_height(s, rtol=RTOL)
        wall.append(time.perf_counter() - t)
        h.append(r.critical_height)
        cens.append(r.censored)
        if (i + 1) % 50 == 0:
            print(f"  full model: {i + 1}/{len(scenes)}", file=sys.stderr)
    return np.array(h), np.array(cens, dtype=object), np.array(wall)


def fast_heights(scenes, with_error=False, **kw):
    cols = fast.scene_columns([s for _, s in scenes])
    res = fast.fast_critical_heights(**cols, **kw)
    names = {fast.CENSOR_NONE: None, fast.CENSOR_ABOVE: "above", fast.CENSOR_BELOW: "below"}
    out = (res["critical_height"], np.array([names[int(c)] for c in res["censored"]],
                                            dtype=object))
    return out + (res["error_estimate"],) if with_error else out


def region(error):
    """Region name of a stated error (skidmc.solver.fast.fast_error_bound)."""
    return {ERROR_ESTIMATE: "rebound", ERROR_STOPS_SLIDING: "stops sliding",
            ERROR_SELF_HEATING: "self-heating"}[float(error)]


def coverage_lines(scenes, label):
    """Markdown rows: per region, scenes, median/p95/max |error| and the share within the
    stated error (both models uncensored), and the censoring disagreements."""
    h_full, c_full, _ = full_heights(scenes)
    h_fast, c_fast, err = fast_heights(scenes, with_error=True)
    both = np.array([a is None and b is None for a, b in zip(c_full, c_fast)])
    rel = np.abs(np.where(both, h_fast / h_full - 1.0, np.nan))
    regions = np.array([region(e) for e in err])
    rows = []
    for name in ("rebound", "stops sliding", "self-heating"):
        m = (regions == name) & both
        if not m.any():
            continue
        a = rel[m]
        stated = float(err[m][0])
        rows.append(f"| {label} | {name} | {stated:.0%} | {m.sum()} | {np.median(a):.3f} | "
                    f"{np.quantile(a, 0.95):.3f} | {a.max():.3f} | "
                    f"{np.mean(a <= stated):.1%} |")
    n_dis = sum(a != b for a, b in zip(c_full, c_fast))
    return rows, n_dis


def fit(scenes):
    """Fit C_IGNITION and MELT_FACTOR (least squares on ln H over all training scenes, with the
    stops-sliding factor at 1, as they were fitted first), then STOPS_SLIDING_FACTOR given the
    shipped C_IGNITION and MELT_FACTOR: exp of the mean ln(H_full / H_fast) over the training
    scenes where sliding stops."""
    from scipy.optimize import least_squares

    h_full, c_full, _ = full_heights(scenes)
    ok = np.array([c is None for c in c_full])
    print(f"training scenes: {len(scenes)}, uncensored in the full model: {ok.sum()}")

    def resid(p):
        h, c = fast_heights(scenes, c_ign=math.exp(p[0]), melt_factor=p[1], stops_factor=1.0)
        r = np.log(h[ok] / h_full[ok])
        return np.where(np.isfinite(r), r, 1.0)

    sol = least_squares(resid, x0=[math.log(fast.C_IGNITION), fast.MELT_FACTOR])
    r = resid(sol.x)
    print(f"C_IGNITION = {math.exp(sol.x[0]):.4g}, MELT_FACTOR = {sol.x[1]:.4g} (shipped: "
          f"{fast.C_IGNITION}, {fast.MELT_FACTOR})")
    a = np.abs(np.expm1(r))
    print(f"training |rel err|: median {np.median(a):.4f}, p90 {np.quantile(a, 0.9):.4f}, "
          f"max {a.max():.4f}")
    cols = fast.scene_columns([s for _, s in scenes])
    stops = fast.fast_critical_heights(**cols)["exit_code"] == EXIT_STOPS_SLIDING
    h, _ = fast_heights(scenes, stops_factor=1.0)
    ln_ratio = np.log(h_full / h)[ok & stops]
    print(f"stops sliding, shipped C_IGNITION and MELT_FACTOR: {ln_ratio.size} scenes, "
          f"ln(H_full / H_fast) mean "
          f"{ln_ratio.mean():.4f}, sd {ln_ratio.std(ddof=1):.4f} -> STOPS_SLIDING_FACTOR = "
          f"{math.exp(ln_ratio.mean()):.4g}")


def timing(scenes, repeats=200):
    """Median us per height: batched kernel, the per-scene Python entry point, and the
    public ``critical_height(tier="fast")`` (which adds the full tier's validity flags)."""
    cols = fast.scene_columns([s for _, s in scenes])
    fast.fast_critical_heights(**cols)  # compiled already; warm caches
    per = []
    for _ in range(repeats // 10):
        t = time.perf_counter()
        fast.fast_critical_heights(**cols)
        per.append((time.perf_counter() - t) / len(scenes))
    batch_us = 1e6 * float(np.median(per))
    one, public = [], []
    for _ in range(3):
        for _, s in scenes:
            t = time.perf_counter()
            fast.fast_critical_height(s)
            one.append(time.perf_counter() - t)
            t = time.perf_counter()
            critical_height(s, tier="fast")
            public.append(time.perf_counter() - t)
    return batch_us, 1e6 * float(np.median(one)), 1e6 * float(np.median(public))


def stats(rel):
    a = np.abs(rel)
    return np.median(a), np.quantile(a, 0.9), a.max(), np.mean(rel)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--fit", action="store_true", help="refit the constants on the training set")
    args = ap.parse_args(argv)
    fast.fast_critical_height(get_preset("paper-quartz"))  # compile
    if args.fit:
        fit(scene_set("train"))
        return 0

    t_start = time.perf_counter()
    scenes = [(f"preset/{p}", get_preset(p)) for p in PRESETS] + scene_set("test")
    h_full, c_full, wall_full = full_heights(scenes)
    h_fast, c_fast = fast_heights(scenes)
    batch_us, one_us, public_us = timing(scenes)
    labels = np.array([lab for lab, _ in scenes])
    group = np.array([lab.split("/")[0] for lab in labels])
    both = np.array([a is None and b is None for a, b in zip(c_full, c_fast)])
    rel = np.where(both, h_fast / h_full - 1.0, np.nan)
    agree_cens = np.array([a == b for a, b in zip(c_full, c_fast)])

    OUT.mkdir(parents=True, exist_ok=True)
    with open(OUT / "fast_tier.csv", "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["label", "mu", "target_conductivity_W_mK", "activation_temperature_K",
                    "h_full_m", "censored_full", "h_fast_m", "censored_fast", "rel_error",
                    "full_wall_s"])
        for i, (lab, s) in enumerate(scenes):
            w.writerow([lab, f"{s.mu:.5g}", f"{s.target_conductivity:.5g}",
                        f"{s.kinetics_activation_temperature:.6g}", f"{h_full[i]:.6g}",
                        c_full[i] or "", f"{h_fast[i]:.6g}", c_fast[i] or "",
                        "" if np.isnan(rel[i]) else f"{rel[i]:.5f}", f"{wall_full[i]:.4f}"])

    lines = ["# Fast tier vs full model", "",
             "Generated by `python scripts/fast_tier_error.py` (skidmc.solver.fast; full model "
             f"`critical_height(scene, rtol={RTOL})`, melting on). Constants "
             f"C_IGNITION = {fast.C_IGNITION}, MELT_FACTOR = {fast.MELT_FACTOR}, "
             f"STOPS_SLIDING_FACTOR = {fast.STOPS_SLIDING_FACTOR}, fitted on a "
             "separate training set (`--fit`: design rows 0-11 of both studies, broad seed 1); "
             f"the test set here is design rows {TEST_START}-{TEST_START + 23} of every study "
             "scene, broad seed 2 and the five report presets.", "",
             "Relative error = H_fast / H_full - 1 over scenes neither model censors.", "",
             "| set | scenes | both uncensored | median abs | p90 abs | max abs | mean (bias) |",
             "|---|---|---|---|---|---|---|"]
    for name, mask in [("all", np.ones(len(scenes), bool))] + [
            (g, group == g) for g in ("preset", "paper-series1", "paper-series2", "broad")]:
        r = rel[mask & both]
        if r.size == 0:
            continue
        md, p90, mx, mean = stats(r)
        lines.append(f"| {name} | {mask.sum()} | {r.size} | {md:.3f} | {p90:.3f} | {mx:.3f} "
                     f"| {mean:+.3f} |")
    lines += ["", "Report presets (ft):", "", "| preset | full | fast | rel |", "|---|---|---|---|"]
    for i, lab in enumerate(labels):
        if lab.startswith("preset/"):
            lines.append(f"| {lab[7:]} | {h_full[i] / FOOT:.4g} | {h_fast[i] / FOOT:.4g} "
                         f"| {rel[i]:+.3f} |")
    lines += ["", "## Stated error by region and its coverage", "",
              "`error_estimate` of a fast result is the bound of its region "
              "(`skidmc.solver.fast.fast_error_bound`), chosen on the training set; *covered*: "
              "share of scenes (both models uncensored) whose |H_fast / H_full - 1| is within "
              "it. `fast_critical_height(..., strict=True)` refuses the stops-sliding and "
              "self-heating regions. A fast height within its stated error of h_max (h_min) is "
              "censored \"above\" (\"below\").", "",
              "| set | region | stated | scenes | median abs | p95 abs | max abs | covered |",
              "|---|---|---|---|---|---|---|---|"]
    train_rows, _ = coverage_lines(scene_set("train"), "training")
    test_rows, _ = coverage_lines(scenes, "test")
    lines += train_rows + test_rows
    n_dis = int((~agree_cens).sum())
    lines += ["", f"Censoring disagreements (one model censored, the other not, or different "
              f"bounds): {n_dis} of {len(scenes)}."]
    for i in np.flatnonzero(~agree_cens):
        lines.append(f"- {labels[i]}: full {c_full[i] or 'none'} ({h_full[i]:.4g} m), "
                     f"fast {c_fast[i] or 'none'} ({h_fast[i]:.4g} m)")
    lines += ["", "## Cost", "",
              f"- fast tier, batched kernel (`fast_critical_heights`, one core, compiled): "
              f"**{batch_us:.1f} us per height** (call time / {len(scenes)} scenes, median "
              f"over repeated calls)",
              f"- fast tier, per-scene Python entry (`fast_critical_height`, includes building "
              f"the HeightResult): median {one_us:.1f} us over the scenes",
              f"- fast tier, public call (`critical_height(scene, tier=\"fast\")`, adds the full "
              f"tier's validity flags): median {public_us:.1f} us over the scenes",
              f"- full model, rtol={RTOL}: median {1e3 * np.median(wall_full):.1f} ms, "
              f"max {1e3 * wall_full.max():.0f} ms per height",
              f"- script wall time: {time.perf_counter() - t_start:.0f} s", ""]
    (OUT / "fast_tier.md").write_text("\n".join(lines))
    print("\n".join(lines))

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(5.5, 5.0))
    colors = {"preset": "k", "paper-series1": "tab:blue", "paper-series2": "tab:orange",
              "broad": "tab:green"}
    for g, col in colors.items():
        m = (group == g) & both
        ax.loglog(h_full[m], h_fast[m], "o", ms=3 if g != "preset" else 6, color=col,
                  label=g, alpha=0.7)
    lo = np.nanmin(h_full[both]) / 2
    hi = np.nanmax(h_full[both]) * 2
    ax.loglog([lo, hi], [lo, hi], "k-", lw=0.8, label="1:1")
    ax.loglog([lo, hi], [lo * 1.1, hi * 1.1], "k:", lw=0.6, label="+/-10 %")
    ax.loglog([lo, hi], [lo / 1.1, hi / 1.1], "k:", lw=0.6)
    ax.set_xlabel("full model critical height [m]")
    ax.set_ylabel("fast tier critical height [m]")
    ax.set_title("skidmc fast tier vs full model (test set)")
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(OUT / "fast_tier.png", dpi=120)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
