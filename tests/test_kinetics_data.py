"""The published one-step HMX pairs file and its compensation fit (issue 39, kinetics).

``src/skidmc/data/properties/hmx_one_step_kinetics.csv`` feeds docs/inputs.md ("HMX kinetics")
and scripts/kinetics_compensation.py; these tests check that it parses, that every row names its
source and where its numbers were seen, that its units are the ones its header states, and that
the script's fit is the closed-form least-squares line.
"""

from __future__ import annotations

import importlib.util
import math
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]


def _script():
    spec = importlib.util.spec_from_file_location(
        "kinetics_compensation", ROOT / "scripts" / "kinetics_compensation.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.fixture(scope="module")
def kc():
    return _script()


@pytest.fixture(scope="module")
def rows(kc):
    return kc.load_pairs()


def test_every_row_parses_and_names_its_source(rows):
    assert len(rows) >= 4
    labels = [r["label"] for r in rows]
    assert len(set(labels)) == len(labels), labels
    for r in rows:
        assert len(r["source"].strip()) > 20, r["label"]  # a citation, not a placeholder
        assert r["retrieved"].strip(), r["label"]
        assert r["order"] in ("", "0", "1"), r["label"]
        copy = r["copy_of"].strip()
        assert copy == "" or copy in labels, (r["label"], copy)
        if r["T_low_K"] and r["T_high_K"]:
            assert 300.0 < float(r["T_low_K"]) < float(r["T_high_K"]) < 1500.0, r["label"]


def test_units_are_kcal_per_mol_and_log10_per_second(rows):
    # E in kcal/mol gives E/R of a nitramine's decomposition, 10,000-40,000 K (kJ/mol read as
    # kcal/mol would give 4.2 times as much); log10 Z of such first-order rates is 8-25 in 1/s
    # (ln Z read as log10 Z would give 2.3 times as much).
    for r in rows:
        assert 10000.0 <= r["E_R"] <= 40000.0, (r["label"], r["E_R"])
        assert 8.0 <= float(r["log10_Z"]) <= 25.0, (r["label"], r["log10_Z"])


def test_the_report_row_is_table_vii(rows):
    rep = next(r for r in rows if r["label"] == "report-gmx2")
    # Table VII: E/R = 2.63e4 K and Z = 5.0e19 1/s, to the digits the file writes (52.26
    # kcal/mol: 2e-4 relative; log10 Z to 3 decimals).
    assert rep["E_R"] == pytest.approx(2.63e4, rel=2e-4)
    assert float(rep["log10_Z"]) == pytest.approx(math.log10(5.0e19), abs=1e-3)


def test_fit_is_the_closed_form_least_squares_line(kc, rows):
    d = kc.distinct(rows)
    x = np.array([r["E_R"] for r in d])
    y = np.array([r["ln_Z"] for r in d])
    fit = kc.compensation_fit(x, y)
    xm, ym = x.mean(), y.mean()
    b = np.sum((x - xm) * (y - ym)) / np.sum((x - xm) ** 2)
    a = ym - b * xm
    ssr = np.sum((y - a - b * x) ** 2)
    # Same arithmetic in double precision by two routes (QR in statsmodels, sums here); x near
    # 2.5e4 costs a few digits in the sums: 1e-8 relative is far above that and far below any
    # difference that would matter.
    assert fit["b"] == pytest.approx(b, rel=1e-8)
    assert fit["a"] == pytest.approx(a, rel=1e-8, abs=1e-8)
    assert fit["t_iso"] == pytest.approx(1.0 / b, rel=1e-8)
    assert fit["resid_sd"] == pytest.approx(math.sqrt(ssr / (len(x) - 2)), rel=1e-8)
    assert fit["b_ci"][0] < fit["b"] < fit["b_ci"][1]


def test_fit_recovers_a_known_line_and_its_isokinetic_temperature(kc):
    # Pairs exactly on ln Z = a + E/R / 500 K share one rate at 500 K: T_iso = 500 K, no
    # residual; the robust fit of exact data is the same line (to solver tolerance, 1e-6).
    x = np.array([15000.0, 20000.0, 26000.0, 33000.0])
    y = -4.0 + x / 500.0
    fit = kc.compensation_fit(x, y)
    assert fit["t_iso"] == pytest.approx(500.0, rel=1e-10)
    assert fit["resid_sd"] == pytest.approx(0.0, abs=1e-9)
    assert fit["robust_t_iso"] == pytest.approx(500.0, rel=1e-6)
    assert np.ptp(kc.ln_rate(y, x, 500.0)) == pytest.approx(0.0, abs=1e-9)


def test_fit_refuses_pairs_that_fix_no_slope(kc):
    with pytest.raises(ValueError, match="e_r"):
        kc.compensation_fit([26300.0, 26300.0], [45.3, 45.4])


def test_script_writes_its_report_and_figure(kc, tmp_path):
    assert kc.main(["--out", str(tmp_path)]) == 0
    text = (tmp_path / "kinetics_compensation.md").read_text(encoding="utf-8")
    assert "T_iso" in text and "Leave-one-out" in text
    assert (tmp_path / "kinetics_compensation.png").stat().st_size > 10_000
