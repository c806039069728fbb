"""Validation of layered targets (issue 42; docs/targets.md).

1. The layered meshed target against the series solution for a constant flux into a layer on
   a substrate (inert HE; skidmc.physics.layered), levels 0-2, with the homogeneous target's
   error for comparison.
2. A stack of identical layers against the homogeneous target.
3. Thickness sweep: gold of thickness d on Dural (the report's gold scene), from far thinner
   than the heated depth (-> Dural) to far thicker (-> gold; the scene then uses the
   homogeneous top and says so).
4. The margin of "top layer only": high-contrast stacks with the top just thinner and just
   thicker than the cutoff (the target mesh's depth, 4 sqrt(alpha t_exit)) and at 2-3
   diffusion lengths, against the homogeneous top.
5. The report's gold target (3 mil gold / 7 mil copper / Dural): refinement at fixed levels,
   the default search at rtol 1e-3, against homogeneous gold, copper, Dural and the report's
   gold values.

Run:  PYTHONPATH=src python scripts/layers_validation.py   (a few minutes on one core)
Writes results/validation/layers.md and results/validation/layers.png.
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import time
from pathlib import Path

import numpy as np

from skidmc.physics.layered import layer_interface_rise
from skidmc.scene import make_scene
from skidmc.scene.materials import parse_layers
from skidmc.scene.units import FOOT
from skidmc.solver import critical_height, simulate
from skidmc.solver.model import build_model

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "results" / "validation"
FT = FOOT  # [m per ft]


def _eff(k, rho, c):
    return math.sqrt(k * rho * c)


def series_check(stack, level, preset="paper-gold", q=5e7):
    """(max relative error over 0.05-1 t_exit, times/t_exit, kernel rise, series rise,
    two-media rise of the top alone) of the interface temperature under a constant flux."""
    s = make_scene(preset=preset, target=stack)
    m = dataclasses.replace(build_model(s, level=level, target="mesh"), prefactor=0.0,
                            latent_heat=0.0)
    e0 = _eff(s.he_conductivity, s.he_density, s.he_heat_capacity)
    e1 = _eff(s.target_conductivity, s.target_density, s.target_heat_capacity)
    a1 = s.target_conductivity / (s.target_density * s.target_heat_capacity)
    if s.target_layers:
        top, deeper = parse_layers(s.target_layers)
        rho2, c2, k2, _ = deeper[0]
        e2 = _eff(k2, rho2, c2)
    else:
        top, e2 = 1.0, e1
    sim = simulate(m, 1.0, record=True,
                   flux_override=(q, 1.0, 0.0, m.omega, 10 * m.exit_time, q))
    t, tb = sim.times, sim.interface_temperature
    late = (t > 0.05 * m.exit_time) & (t <= m.exit_time)
    exact = np.array([layer_interface_rise(q, ti, e0, e1, a1, top, e2) for ti in t[late]])
    rise = tb[late] - m.initial_temperature
    ref = 2 * q * np.sqrt(t[late]) / (math.sqrt(math.pi) * (e0 + e1))
    return (float(np.max(np.abs(rise - exact) / exact)), t[late] / m.exit_time, rise / ref,
            exact / ref, top / math.sqrt(a1 * m.exit_time))


def height(scene, **kw):
    t = time.perf_counter()
    r = critical_height(scene, **kw)
    return r, time.perf_counter() - t


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=OUT)
    args = parser.parse_args(argv)
    lines = ["# Layered targets: validation", "",
             "`PYTHONPATH=src python scripts/layers_validation.py` (issue 42, docs/targets.md). "
             "Report scene paper-gold (vertical drop, 45 deg, mu 0.117, first-series billet) "
             "unless said otherwise; layer properties from the registry (Incropera Table A.1).",
             ""]

    # 1. series solution -------------------------------------------------------------------
    stacks = ["gold 3 mil / aluminium-2024", "fused-quartz 20 um / copper",
              "copper 100 um / fused-quartz", "gold 3 mil / gold", "gold"]
    lines += ["## 1. Constant flux into a layer on a substrate: kernel against the series", "",
              "Inert HE, constant flux 5e7 W/m^2 from t = 0; the interface temperature rise of "
              "the layered meshed target against the series solution "
              "(skidmc.physics.layered.layer_interface_rise: HE | layer | substrate, image "
              "series of Carslaw & Jaeger's composite slab); worst relative error over "
              "0.05-1 t_exit. x = d / sqrt(alpha_1 t_exit). `gold` is the homogeneous "
              "meshed target against the two-media closed form (the same check as "
              "tests/test_thermal.py), for comparison.", "",
              "| stack | x | rise at t_exit / top alone | level 0 | level 1 | level 2 | "
              "ratio 1->2 |", "|---|---|---|---|---|---|---|"]
    curves = {}
    for stack in stacks:
        errs = []
        for level in (0, 1, 2):
            e, tt, kern, ser, x = series_check(stack, level)
            errs.append(e)
            if level == 2:
                curves[stack] = (tt, kern, ser)
        lines.append(f"| {stack} | {x:.3g} | {ser[-1]:.4f} | {errs[0]:.2e} | {errs[1]:.2e} | "
                     f"{errs[2]:.2e} | {errs[1] / errs[2]:.2f} |")
    lines.append("")

    # 2. identical layers -------------------------------------------------------------------
    lines += ["## 2. Identical layers against the homogeneous target", "",
              "Default search at rtol 1e-3, both on the meshed target (a stack is meshed; "
              "`target='mesh'` for the homogeneous one), and at fixed level 1.5 "
              "(extrapolate=False, root tolerance from rtol 1e-5).", "",
              "| target | H_c default [ft] | estimate | H_c level 1.5 [ft] |", "|---|---|---|---|"]
    ident = {}
    for stack in ("gold", "gold 3 mil / gold", "gold 30 um / gold 100 um / gold"):
        s = make_scene(preset="paper-gold", target=stack)
        r, _ = height(s, rtol=1e-3, target="mesh")
        f, _ = height(s, rtol=1e-5, level=1.5, extrapolate=False, target="mesh")
        ident[stack] = (r.critical_height, f.critical_height)
        lines.append(f"| {stack} | {r.critical_height / FT:.2f} | {r.error_estimate:.1e} | "
                     f"{f.critical_height / FT:.2f} |")
    base = ident["gold"]
    for stack, (h, f) in ident.items():
        if stack != "gold":
            lines.append(f"| {stack}: relative difference | {h / base[0] - 1:+.1e} | | "
                         f"{f / base[1] - 1:+.1e} |")
    lines.append("")

    # 3. thickness sweep --------------------------------------------------------------------
    lines += ["## 3. Gold of thickness d on Dural: thin -> substrate, thick -> top", "",
              "Default search, rtol 1e-3. Homogeneous gold and Dural (aluminium-2024) on the "
              "exact target, as the default search has them.", "",
              "| d [um] | x = d / sqrt(alpha t_exit) | H_c [ft] | estimate | terms |",
              "|---|---|---|---|---|"]
    h_gold = critical_height(make_scene(preset="paper-gold", target="gold"), rtol=1e-3)
    h_dural = critical_height(make_scene(preset="paper-gold", target="aluminium-2024"),
                              rtol=1e-3)
    sweep = []
    for d_um in (0.01, 0.1, 1.0, 3.0, 10.0, 30.0, 76.2, 200.0, 500.0, 1000.0, 1500.0, 3000.0):
        s = make_scene(preset="paper-gold", target=f"gold {d_um} um / aluminium-2024")
        r, _ = height(s, rtol=1e-3)
        m = build_model(s, meshes=False)
        alpha = s.target_conductivity / (s.target_density * s.target_heat_capacity)
        x = d_um * 1e-6 / math.sqrt(alpha * m.exit_time)
        sweep.append((d_um, r.critical_height))
        lines.append(f"| {d_um:g} | {x:.3g} | {r.critical_height / FT:.2f} | "
                     f"{r.error_estimate:.1e} | {r.terms[-1]} |")
    lines += ["", f"Homogeneous gold: {h_gold.critical_height / FT:.2f} ft (estimate "
              f"{h_gold.error_estimate:.1e}); Dural: {h_dural.critical_height / FT:.2f} ft "
              f"({h_dural.error_estimate:.1e}).", ""]

    # 4. margin of "top layer only" ---------------------------------------------------------
    lines += ["## 4. The margin of \"top layer only\"", "",
              "A top layer at least 4 sqrt(alpha_1 t_exit) thick (the homogeneous target "
              "mesh's depth, 2 sqrt(alpha t_end)) is taken as the homogeneous top (term "
              "`top_layer_only`). High-contrast stacks at fixed level 1.5 on the meshed "
              "target (extrapolate=False, root tolerance from rtol 1e-5), against the "
              "homogeneous top at the same level; x = d / sqrt(alpha_1 t_exit).", "",
              "| scene | stack (top / substrate) | x | H_c / H_c(top) - 1 | terms |",
              "|---|---|---|---|---|"]
    for preset, top, sub in (("paper-quartz", "fused-quartz", "copper"),
                             ("paper-gold", "copper", "fused-quartz"),
                             ("paper-gold", "gold", "aluminium-2024")):
        s0 = make_scene(preset=preset, target=top)
        m0 = build_model(s0, meshes=False)
        alpha = s0.target_conductivity / (s0.target_density * s0.target_heat_capacity)
        ref, _ = height(s0, rtol=1e-5, level=1.5, extrapolate=False, target="mesh")
        for x in (1.0, 2.0, 3.0, 3.9, 4.1):
            d = x * math.sqrt(alpha * m0.exit_time)
            s = make_scene(preset=preset, target=f"{top} {d * 1e6:.6g} um / {sub}")
            r, _ = height(s, rtol=1e-5, level=1.5, extrapolate=False, target="mesh")
            lines.append(f"| {preset} | {top} / {sub} | {x:g} | "
                         f"{r.critical_height / ref.critical_height - 1:+.2e} | "
                         f"{r.terms[-1]} |")
    lines.append("")

    # 5. the report's gold target -----------------------------------------------------------
    stack = make_scene(preset="paper-gold", target="gold-stack-report")
    lines += ["## 5. The report's gold target: 3 mil gold / 7 mil copper / Dural", "",
              "Refinement at fixed levels on the meshed target (extrapolate=False, root "
              "tolerance from rtol 1e-5), with the Richardson value of each pair "
              "R = H_L + (H_L - H_{L-1}) / 3:", "",
              "| level | H_c [ft] | Richardson (L-1, L) [ft] | simulations |",
              "|---|---|---|---|"]
    prev = None
    levels = {}
    for level in (0.0, 1.0, 2.0, 3.0):
        r, dt = height(stack, rtol=1e-5, level=level, extrapolate=False, target="mesh")
        h = r.critical_height
        levels[level] = h
        rich = "" if prev is None else f"{(h + (h - prev) / 3) / FT:.2f}"
        lines.append(f"| {level:g} | {h / FT:.2f} | {rich} | {r.evaluations} |")
        prev = h
    lines += ["", "Default search, rtol 1e-3 (homogeneous targets on the exact target, the "
              "stack on the meshed one):", "",
              "| target | H_c [ft] | H_c [m] | estimate | terms |", "|---|---|---|---|---|"]
    table = {}
    for name in ("gold-stack-report", "gold", "copper", "aluminium-2024", "gold-report"):
        r, dt = height(make_scene(preset="paper-gold", target=name), rtol=1e-3)
        table[name] = r
        lines.append(f"| {name} | {r.critical_height / FT:.1f} | {r.critical_height:.1f} | "
                     f"{r.error_estimate:.1e} | {', '.join(r.terms[3:]) or '-'} |")
    lines += ["", "The report calculated 515 ft for its gold target with the Table VI values "
              "(the registry's gold-report, homogeneous) and found no event at 25-150 ft "
              "(Table VIII).", ""]

    # figure --------------------------------------------------------------------------------
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (a, b) = plt.subplots(1, 2, figsize=(10, 4))
    for (stack_name, (tt, kern, ser)), color in zip(curves.items(), plt.cm.tab10.colors):
        if stack_name == "gold":
            continue
        a.plot(tt, ser, "-", color=color, label=f"{stack_name} (series)")
        a.plot(tt[::4], kern[::4], "o", ms=3, color=color, label="kernel, level 2")
    a.set_xlabel("time / t_exit")
    a.set_ylabel("interface rise / rise with the top layer alone")
    a.set_title("Constant flux: layered mesh vs series", fontsize=10)
    a.legend(fontsize=6.5)
    d = np.array([p[0] for p in sweep])
    hh = np.array([p[1] for p in sweep]) / FT
    b.semilogx(d, hh, "o-", label="gold d / Dural (stack)")
    b.axhline(h_gold.critical_height / FT, color="goldenrod", ls="--", label="homogeneous gold")
    b.axhline(h_dural.critical_height / FT, color="gray", ls=":", label="homogeneous Dural")
    b.axvline(76.2, color="k", lw=0.6)
    b.text(80, hh.min() + 0.25 * (hh.max() - hh.min()), " 3 mil", fontsize=8)
    b.set_xlabel("gold thickness d [um]")
    b.set_ylabel("critical height [ft]")
    b.set_title("paper-gold scene, rtol 1e-3", fontsize=10)
    b.legend(fontsize=7)
    fig.tight_layout()
    args.out.mkdir(parents=True, exist_ok=True)
    fig.savefig(args.out / "layers.png", dpi=110)
    lines += ["![validation](layers.png)", "",
              "Left: the interface rise of three stacks under a constant flux, over the rise "
              "with the top layer alone, kernel (level 2) against the series. Right: the "
              "critical height of gold on Dural against the gold's thickness, between the "
              "homogeneous Dural and gold values.", ""]
    (args.out / "layers.md").write_text("\n".join(lines), encoding="utf-8")
    print(f"wrote {args.out / 'layers.md'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
