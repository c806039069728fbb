"""The kinds of study: one registry, the kind inferred in one place, options that mean the same
for every kind or are refused, and hazard results kept through storage (resume, up to date)."""

from __future__ import annotations

import ast
import json
import types
from pathlib import Path

import numpy as np
import pytest
from test_handling import STUDY as HAZARD
from test_handling import StandIn

from skidmc.cli import main
from skidmc.ensemble.study_model import StudyError
from skidmc.workflows import registry
from skidmc.workflows.registry import OptionError, ReportOptions, RunOptions

ROOT = Path(__file__).resolve().parents[1]


# --- one registry, no kind in the command line ------------------------------------------------


def test_cli_has_no_kind_specific_branch():
    tree = ast.parse((ROOT / "src" / "skidmc" / "cli.py").read_text())
    kind_modules = {f"skidmc.workflows.{k}" for k in registry.KINDS}
    kind_modules |= {"skidmc.ensemble.hazard_study", "skidmc.ensemble.study",
                     "skidmc.ensemble.storage"}
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom):
            assert node.module not in kind_modules, node.module
        if isinstance(node, ast.Compare):  # no `kind == "hazard"` and the like
            names = {c.value for c in [node.left, *node.comparators]
                     if isinstance(c, ast.Constant)}
            assert not names & set(registry.KINDS), ast.unparse(node)
        if isinstance(node, ast.Attribute):
            assert node.attr not in ("n_max", "is_hazard_study"), ast.unparse(node)


@pytest.mark.parametrize("name, kind", [("paper-series1", "ensemble"),
                                        ("paper-series2", "ensemble"),
                                        ("sobol-series1", "sobol"),
                                        ("hazard-handling", "hazard")])
def test_shipped_studies_kinds_are_inferred_and_load(name, kind):
    path = ROOT / "studies" / f"{name}.toml"
    assert registry.kind_of_file(path) == kind
    got, study = registry.load(path)
    assert got == kind and study.name == name
    module = registry.get_kind(kind)
    assert module.default_out(study).parts[:2] == ("results", name)


def _plain(extra_study="", extra_design=""):
    return f"""
[study]
name = "k"
{extra_study}
[scene]
preset = "paper-quartz"
[uncertain.mu]
distribution = "uniform"
loc = 0.08
scale = 0.06
source = "test"
[design]
method = "saltelli"
n = 8
seed = 1
{extra_design}
"""


def test_explicit_kind_wins_and_is_checked(tmp_path):
    path = tmp_path / "k.toml"
    path.write_text(_plain('kind = "sobol"', "n_max = 64"))
    assert registry.kind_of_file(path) == "sobol"
    path.write_text(_plain('kind = "sobol"'))
    with pytest.raises(StudyError, match="missing: kind = 'sobol' grows") as info:
        registry.load(path)
    assert info.value.key == "design.n_max"
    path.write_text(_plain('kind = "ensemble"', "n_max = 64"))
    with pytest.raises(StudyError, match="only for kind = 'sobol'"):
        registry.load(path)
    path.write_text(_plain('kind = "sobl"'))
    with pytest.raises(StudyError, match="did you mean 'sobol'") as info:
        registry.load(path)
    assert info.value.key == "study.kind" and info.value.value == "sobl"


# --- options: the same meaning for every kind, or refused -----------------------------------------


@pytest.mark.parametrize("option, value, flag", [("n", 5, "--n 5"),
                                                 ("chunk_size", 2, "--chunk-size 2")])
def test_hazard_refuses_options_it_cannot_honour(option, value, flag):
    with pytest.raises(OptionError, match=f"^{flag}: not for a hazard study: "):
        registry.check_options("hazard", RunOptions(**{option: value}))
    for kind in ("ensemble", "sobol"):
        registry.check_options(kind, RunOptions(**{option: value}))  # honoured there
    for field in ("out", "resume", "force", "workers", "scheduler"):
        value = {"out": "x", "workers": 2, "scheduler": "dask"}.get(field, True)
        for kind in registry.KINDS:
            registry.check_options(kind, RunOptions(**{field: value}))


def test_cli_refuses_n_for_a_hazard_study_before_running(tmp_path, capsys):
    study = tmp_path / "h.toml"
    study.write_text(HAZARD)
    solver = StandIn()
    assert main(["run", str(study), "--n", "5", "--out", str(tmp_path / "o")],
                solver=solver) == 2
    err = capsys.readouterr().err
    assert err.startswith("skidmc run: error: --n 5: not for a hazard study: the estimator "
                          "stops at [hazard.estimator] target_cov or max_runs")
    assert solver.calls == 0 and not (tmp_path / "o").exists()


def test_report_refuses_confidence_for_a_hazard_study():
    with pytest.raises(OptionError, match="--confidence 0.9: not for a hazard study: its "
                       "intervals are the estimator's 95 % ones"):
        registry.check_options("hazard", ReportOptions(confidence=0.9))
    registry.check_options("ensemble", ReportOptions(confidence=0.9))


def test_hazard_scheduler_garbage_is_refused(tmp_path, capsys):
    study = tmp_path / "h.toml"
    study.write_text(HAZARD)
    assert main(["run", str(study), "--scheduler", "garbage", "--out", str(tmp_path / "o")],
                solver=StandIn()) == 2
    assert "--scheduler 'garbage': expected 'local'" in capsys.readouterr().err


# --- hazard results through storage -------------------------------------------------------------


class Interrupting(StandIn):
    """The stand-in, with Ctrl-C at its call number `at`."""

    def __init__(self, at):
        super().__init__()
        self.at = at

    def __call__(self, columns, solver_options, **kwargs):
        if self.calls == self.at:
            raise KeyboardInterrupt
        return super().__call__(columns, solver_options, **kwargs)


def _summary(folder: Path) -> dict:
    return json.loads((folder / "summary.json").read_text())


def test_hazard_run_resumes_with_the_numbers_of_an_uninterrupted_run(tmp_path, capsys):
    study = tmp_path / "h.toml"
    study.write_text(HAZARD)
    whole = StandIn()
    assert main(["run", str(study), "--out", str(tmp_path / "a"), "--quiet"], solver=whole) == 0
    assert (tmp_path / "a" / "evaluations.h5").is_file()
    assert not (tmp_path / "a" / "evaluations.h5.calls").exists()

    cut = Interrupting(at=whole.calls // 2)
    assert main(["run", str(study), "--out", str(tmp_path / "b")], solver=cut) == 130
    err = capsys.readouterr().err
    assert "interrupted" in err and "--resume" in err
    kept = sorted((tmp_path / "b" / "evaluations.h5.calls").glob("*.h5"))
    assert len(kept) == whole.calls // 2
    # What a kill -9 in the middle of a write leaves: a temporary file, ignored.
    (tmp_path / "b" / "evaluations.h5.calls" / "999999.tmp").write_bytes(b"torn")
    # Without --resume an unfinished run is refused, naming both ways on.
    assert main(["run", str(study), "--out", str(tmp_path / "b")], solver=StandIn()) == 2
    assert "--resume continues it, --force starts over" in capsys.readouterr().err
    rest = StandIn()
    assert main(["run", str(study), "--out", str(tmp_path / "b"), "--resume", "--quiet"],
                solver=rest) == 0
    assert rest.calls == whole.calls - whole.calls // 2   # only the calls not kept
    assert _summary(tmp_path / "a") == _summary(tmp_path / "b")   # the same numbers, exactly


def test_hazard_up_to_date_force_and_report_replay(tmp_path, capsys):
    study = tmp_path / "h.toml"
    study.write_text(HAZARD)
    out = tmp_path / "r"
    first = StandIn()
    assert main(["run", str(study), "--out", str(out), "--quiet"], solver=first) == 0
    before = _summary(out)
    again = StandIn()
    assert main(["run", str(study), "--out", str(out)], solver=again) == 0
    assert again.calls == 0 and "up to date" in capsys.readouterr().err
    # The report rebuilds the summary from the kept calls, no solver run.
    (out / "summary.json").unlink()
    assert main(["report", str(out / "evaluations.h5")]) == 0
    assert _summary(out) == before and "per accident" in capsys.readouterr().out
    forced = StandIn()
    assert main(["run", str(study), "--out", str(out), "--force", "--quiet"],
                solver=forced) == 0
    assert forced.calls == first.calls and _summary(out) == before


def test_damaged_evaluation_log_is_refused_naming_it(tmp_path, capsys):
    study = tmp_path / "h.toml"
    study.write_text(HAZARD)
    out = tmp_path / "d"
    assert main(["run", str(study), "--out", str(out), "--quiet"], solver=StandIn()) == 0
    log = out / "evaluations.h5"
    data = bytearray(log.read_bytes())
    data[len(data) // 2: len(data) // 2 + 64] = bytes(64)  # bytes overwritten mid-file
    log.write_bytes(bytes(data))
    (out / "summary.json").unlink()
    assert main(["report", str(log)]) == 2
    assert "damaged" in capsys.readouterr().err


def _mu_solver(columns, options, **kwargs):
    """A stand-in solver of evaluate_batch's signature: H = 1 / mu."""
    mu = columns["mu"]
    return types.SimpleNamespace(critical_height=1.0 / mu, status=["ok"] * mu.size,
                                 failure_reason=[""] * mu.size)


def _new_log(tmp_path):
    """An empty evaluation log and the base scene of its calls."""
    from skidmc.ensemble.storage import EvaluationLog
    from skidmc.scene import get_preset

    log = EvaluationLog(tmp_path / "e.h5", {"study_sha256": "x"})
    log.start(keep=False)
    return log, get_preset("paper-quartz")


def test_recorder_replays_and_forgets_a_diverging_tail(tmp_path):
    from skidmc.workflows.replay import RecordedSolver

    log, base = _new_log(tmp_path)
    solver = _mu_solver
    rec = RecordedSolver(solver, log, False)
    for k in range(3):
        rec({"mu": np.array([0.1, 0.2]) + k}, "opts", base=base)
    assert rec.computed == 6
    again = RecordedSolver(solver, log, False)
    again({"mu": np.array([0.1, 0.2])}, "opts", base=base)       # kept: replayed
    again({"mu": np.array([0.5])}, "opts", base=base)            # another question
    assert again.computed == 1 and len(list(log.folder.glob("*.h5"))) == 2


def test_a_log_names_its_blas_kernels_and_a_replay_elsewhere_says_so(tmp_path):
    # A replay compares each call's inputs to the last bit, and the estimator's numbers go
    # through BLAS: a log records the kernels it was computed with, and a replay that fails
    # where they differ names both (the shipped hazard logs: SkylakeX, against an AMD EPYC's
    # Haswell).
    import h5py

    from skidmc.ensemble.storage import StorageError, blas_kernels
    from skidmc.workflows.replay import RecordedSolver

    here = blas_kernels()
    assert here.startswith(("openblas ", "mkl ", "blis ", "flexiblas "))
    log, base = _new_log(tmp_path)
    solver = _mu_solver
    rec = RecordedSolver(solver, log, False)
    rec({"mu": np.array([0.1, 0.2])}, "opts", base=base)
    log.complete(rec.calls)
    assert log.info()["blas"] == here
    with h5py.File(log.path, "r+") as f:
        f.attrs["blas"] = "openblas Elsewhere"
    replay = RecordedSolver(solver, log, True)
    with pytest.raises(StorageError, match="BLAS kernels are openblas Elsewhere, this "
                       f"machine's {here}"):
        replay({"mu": np.array([0.1, 0.2 + 1e-16])}, "opts", base=base)
    # Where the kernels are the same, the refusal does not blame them.
    with h5py.File(log.path, "r+") as f:
        f.attrs["blas"] = here
    with pytest.raises(StorageError) as same:
        RecordedSolver(solver, log, True)({"mu": np.array([0.3])}, "opts", base=base)
    assert "BLAS" not in str(same.value)


# --- the growing Sobol' kind: resume with the numbers of an uninterrupted run ---------------------

_CALLS = {"n": 0, "stop_at": -1}


def _interrupting_fake(scene, rtol=1e-3, tier="full", h_min=1e-3, h_max=1e4):
    """conftest.fake_height, with Ctrl-C at call number _CALLS["stop_at"] (in-process runs)."""
    from conftest import fake_height

    _CALLS["n"] += 1
    if _CALLS["n"] == _CALLS["stop_at"]:
        raise KeyboardInterrupt
    return fake_height(scene, rtol, tier, h_min, h_max)


@pytest.mark.parametrize("where", ["first step", "growth step"])
def test_sobol_run_resumes_with_the_numbers_of_an_uninterrupted_run(tmp_path, capsys, where):
    from test_sobol_study import GROWING

    from skidmc.ensemble.storage import open_ensemble

    study = tmp_path / "grow.toml"
    study.write_text(GROWING.replace("n_max = 8192", "n_max = 16"))  # two steps: N = 8, 16
    _CALLS.update(n=0, stop_at=-1)
    base = ["run", str(study), "--workers", "1", "--chunk-size", "4", "--quiet"]
    assert main([*base, "--out", str(tmp_path / "a.h5")], solver=_interrupting_fake) == 0
    first_rows = 8 * (3 + 2)   # N (d + 2) rows of the first step
    _CALLS.update(n=0, stop_at=first_rows // 2 if where == "first step" else first_rows + 7)
    assert main([*base, "--out", str(tmp_path / "b.h5")], solver=_interrupting_fake) == 130
    assert "interrupted" in capsys.readouterr().err
    if where == "first step":  # an unfinished file is continued only with --resume
        assert main([*base, "--out", str(tmp_path / "b.h5")], solver=_interrupting_fake) == 2
        assert "--resume" in capsys.readouterr().err
    _CALLS.update(stop_at=-1)
    assert main([*base, "--out", str(tmp_path / "b.h5"), "--resume"],
                solver=_interrupting_fake) == 0
    a, b = open_ensemble(tmp_path / "a.h5"), open_ensemble(tmp_path / "b.h5")
    assert a.sizes == b.sizes and a.sizes["sample"] == 16 * (3 + 2)
    for name in ("mu", "critical_height", "status"):
        assert np.array_equal(a[name].values, b[name].values), name
