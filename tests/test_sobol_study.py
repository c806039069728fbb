"""A saltelli study that doubles N until its Sobol' indices are stable, reusing every row."""

from __future__ import annotations

import json
import shutil

import numpy as np
import pytest
from conftest import fake_height

from skidmc.analysis import open_ensemble
from skidmc.ensemble.run import run_study
from skidmc.ensemble.study import StudyError, parse_study
from skidmc.workflows.sobol import run_until_stable

# ln H = 2 ln(0.132 / mu) + 0.5 ln(k / 1.69) + const in the stand-in solver: mu dominates,
# the conductivity matters a little, the activation temperature not at all.
GROWING = """
[study]
name = "grow"
[scene]
preset = "paper-quartz"
[uncertain.mu]
distribution = "uniform"
loc = 0.08
scale = 0.06
source = "test"
[uncertain."target.conductivity"]
distribution = "uniform"
loc = "1.0 W/(m K)"
scale = "1.0 W/(m K)"
source = "test"
[uncertain."kinetics.activation_temperature"]
distribution = "uniform"
loc = "24000 K"
scale = "4000 K"
source = "test"
[design]
method = "saltelli"
n = 8
n_max = 8192
second_order = false
seed = 3
stable_half_width = 0.1
"""


def test_growth_reuses_every_row_and_stops_when_stable(tmp_path):
    study = tmp_path / "grow.toml"
    study.write_text(GROWING)
    lines = []
    steps = run_until_stable(study, tmp_path / "g.h5", workers=1, progress=False,
                             solver=fake_height, resamples=200, log=lines.append)
    ns = [s["n"] for s in steps]
    assert ns == [8 * 2**k for k in range(len(ns))] and len(ns) >= 2
    # Each step computes only the rows the smaller design did not have: N (d + 2) rows in all.
    rows = [s["rows"] for s in steps]
    assert [s["new_rows"] for s in steps] == [rows[0]] + [b - a for a, b in zip(rows, rows[1:])]
    assert rows[-1] == ns[-1] * (3 + 2)
    assert steps[-1]["stable"] == {"grow": True} and not all(
        s["stable"]["grow"] for s in steps[:-1])
    assert len(lines) == len(steps)
    # The grown file equals a direct run at the final N, sample for sample.
    direct = run_study(parse_study(GROWING.replace("n = 8\n", f"n = {ns[-1]}\n")),
                       tmp_path / "direct.h5", workers=1, progress=False, solver=fake_height)
    a, b = open_ensemble(tmp_path / "g.h5"), open_ensemble(direct)
    for name in ("mu", "target.conductivity", "critical_height"):
        assert np.array_equal(a[name].values, b[name].values), name
    record = json.loads((tmp_path / "convergence.json").read_text())
    assert record["stable"] and [s["n"] for s in record["steps"]] == ns
    # Run again: the complete file is the starting point, nothing is computed.
    again = run_until_stable(study, tmp_path / "g.h5", workers=1, progress=False,
                             solver=fake_height, resamples=200, log=lines.append)
    assert [(s["n"], s["new_rows"]) for s in again] == [(ns[-1], 0)]


def test_force_discards_an_interrupted_growth_of_an_earlier_run(tmp_path):
    # An earlier growth interrupted mid-step leaves <out>.grow.h5 (here: a complete file of
    # another N). `--force` recomputes everything: the leftover must neither stop the run
    # (it once failed with "holds a run ... with other samples per scene") nor be resumed.
    study = tmp_path / "grow.toml"
    study.write_text(GROWING)
    out = tmp_path / "g.h5"
    first = run_until_stable(study, out, workers=1, progress=False, solver=fake_height,
                             resamples=200, log=lambda line: None)
    shutil.copy(out, tmp_path / "g.grow.h5")
    again = run_until_stable(study, out, workers=1, progress=False, solver=fake_height,
                             resamples=200, force=True, log=lambda line: None)
    assert [s["n"] for s in again] == [s["n"] for s in first]
    assert again[0]["new_rows"] == again[0]["rows"]   # recomputed from the study's N
    assert not (tmp_path / "g.grow.h5").exists()


def test_n_max_only_for_saltelli():
    with pytest.raises(StudyError, match="only for method = 'saltelli'") as info:
        parse_study(GROWING.replace('method = "saltelli"', 'method = "lhs"')
                    .replace("second_order = false\n", ""))
    assert info.value.key == "design.n_max"


def test_n_max_below_n_is_refused():
    with pytest.raises(StudyError, match="must be >= design.n") as info:
        parse_study(GROWING.replace("n_max = 8192", "n_max = 4"))
    assert info.value.key == "design.n_max"


def test_a_large_growth_is_sized_up_to_n_max_and_needs_confirming(tmp_path, capsys):
    # n_max = 2^20: 5.2 million rows of 5 per base sample, about 4.8 GB for the last step's
    # grown file beside the result it grows from: large (over 2 GB), so asked about first
    from skidmc.cli import main
    from skidmc.ensemble.run import RunTooLarge

    big = GROWING.replace("n_max = 8192", "n_max = 1048576")
    seen = []

    def decline(size) -> bool:
        seen.append(size)
        return False

    with pytest.raises(RunTooLarge, match="not confirmed: growing N from 8 up to 1048576"):
        run_until_stable(parse_study(big), tmp_path / "g.h5", workers=1, solver=fake_height,
                         confirm=decline, log=lambda line: None)
    (size,) = seen
    assert size.large and size.n_rows == 5 * 1048576 and size.bytes > 2e9
    assert size.basis  # the estimated time says where its rate comes from
    assert list(tmp_path.iterdir()) == []  # refused before anything was made
    # the command line: refused without a terminal, naming --yes and the size
    (tmp_path / "g.toml").write_text(big)
    status = main(["run", str(tmp_path / "g.toml"), "--out", str(tmp_path / "g.h5"),
                   "--workers", "1"], solver=fake_height)
    err = capsys.readouterr().err
    assert status == 2 and "--yes" in err and "GB" in err and "up to 1048576" in err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["g.toml"]


def test_the_report_says_whether_the_growths_stopping_rule_held(tmp_path):
    # A growth cut off by n_max (N = 8 to 16, a half-width rule no N that small meets) and one
    # that stops stable: the report states the rule's verdict at the ensemble's N, with the
    # widest half-width where it failed (read from convergence.json beside the result).
    from skidmc.workflows.reporting.ensemble import write_report

    for name, text, verdict in (
            ("cut", GROWING.replace("n_max = 8192", "n_max = 16").replace(
                "stable_half_width = 0.1", "stable_half_width = 0.001"), "**not met** for grow"),
            ("stable", GROWING, "met for every scene")):
        folder = tmp_path / name
        folder.mkdir()
        study = folder / "grow.toml"
        study.write_text(text)
        steps = run_until_stable(study, folder / "ensemble.h5", workers=1, progress=False,
                                 solver=fake_height, resamples=200, log=lambda line: None)
        write_report(open_ensemble(folder / "ensemble.h5"), folder)
        summary = (folder / "summary.md").read_text()
        assert f"At N = {steps[-1]['n']}" in summary and verdict in summary
        if name == "cut":
            assert steps[-1]["n"] == 16
            assert f"widest half-width {steps[-1]['max_half_width']['grow']:.3f}" in summary
    # A record of another N (the file regrown since) is not reported.
    (tmp_path / "stable" / "convergence.json").write_text(json.dumps(
        {"threshold": 0.1, "half_width": 0.1, "n_max": 8, "steps": [
            {"n": 8, "rows": 40, "new_rows": 40, "stable": {"grow": False},
             "max_half_width": {"grow": 0.5}}], "stable": False}))
    write_report(open_ensemble(tmp_path / "stable" / "ensemble.h5"), tmp_path / "stable")
    assert "Stopping rule" not in (tmp_path / "stable" / "summary.md").read_text()
