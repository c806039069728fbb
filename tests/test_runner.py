"""The ensemble runner: statuses, determinism across workers/chunks/dask, kill -9 and resume.

Tests marked "real solver" run skidmc.solver on a tiny study (2 scenes x 12 samples, rtol 1e-2);
the others replace the solver by an analytic stand-in to check the runner's bookkeeping quickly.
"""

from __future__ import annotations

import argparse
import concurrent.futures as cf
import math
import os
import signal
import subprocess
import sys
import time
import types
from pathlib import Path

import h5py
import numpy as np
import pytest
import xarray as xr

from skidmc.cli import _cmd_run as main_run
from skidmc.ensemble import evaluate as evaluate_module
from skidmc.ensemble import executors, schedule
from skidmc.ensemble.batch import evaluate_batch
from skidmc.ensemble.run import execute_study, run_study
from skidmc.ensemble.storage import StorageError, inspect_file
from skidmc.ensemble.study import SolverOptions
from skidmc.scene import get_preset

ROOT = Path(__file__).resolve().parents[1]

TINY = """
[study]
name = "tiny"
[[scenes]]
name = "quartz"
preset = "paper-quartz"
[[scenes]]
name = "alumina"
preset = "paper-alumina-smooth"
[uncertain.mu]
distribution = "lognorm"
s = 0.1
relative = true
source = "test"
[uncertain."target.conductivity"]
distribution = "truncnorm"
a = -3
b = 3
loc = 1.0
scale = 0.1
relative = true
source = "test"
[uncertain."kinetics.activation_temperature"]
distribution = "uniform"
loc = "24000 K"
scale = "4000 K"
source = "test"
[uncertain."kinetics.prefactor"]
distribution = "lognorm"
s = 0.5
relative = true
source = "test"
[[correlation]]
keys = ["kinetics.activation_temperature", "kinetics.prefactor"]
spearman = 0.8
source = "test"
[design]
method = "mc"
n = 12
seed = 2024
[solver]
rtol = 1e-2
"""


def _solver_available() -> bool:
    try:
        import skidmc.solver  # noqa: F401
    except ImportError:
        return False
    return True


real_solver = pytest.mark.skipif(not _solver_available(), reason="skidmc.solver not importable")


def _data(path) -> xr.Dataset:
    """The data of a result file without its attributes (timestamps and history differ)."""
    with xr.open_dataset(path) as ds:
        return ds.load().drop_attrs()


def _assert_same_data(a, b):
    da, db = _data(a), _data(b)
    assert set(da.variables) == set(db.variables)
    for name in da.variables:
        x, y = da[name].values, db[name].values
        if x.dtype.kind == "f":
            assert np.array_equal(x, y, equal_nan=True), name  # bitwise, NaN where NaN
        else:
            assert np.array_equal(x, y), name


@pytest.fixture
def study_file(tmp_path):
    path = tmp_path / "tiny.toml"
    path.write_text(TINY)
    return path


# --- a stand-in for the solver -------------------------------------------------------------------


def _fake_height(scene, rtol=1e-3, tier="full", h_min=1e-3, h_max=1e4):
    """H = 0.37 m (0.132 / mu)^2 (k2 / 1.69)^0.5: the trends of the model, none of its cost."""
    if scene.mu > 0.15:
        raise FloatingPointError(f"stand-in failure at mu = {scene.mu:.4f}")
    h = 0.37 * (0.132 / scene.mu) ** 2 * math.sqrt(scene.target_conductivity / 1.69)
    censored = "above" if h > h_max else "below" if h < h_min else None
    h = min(max(h, h_min), h_max)
    return types.SimpleNamespace(critical_height=h, censored=censored, evaluations=3,
                                 flags=("stand_in",), wall_time=1e-6)


@pytest.fixture
def fake_solver(monkeypatch):
    import skidmc.solver

    monkeypatch.setattr(skidmc.solver, "critical_height", _fake_height)


# --- evaluate_batch ------------------------------------------------------------------------------


def test_evaluate_batch_statuses_and_failures(fake_solver):
    base = get_preset("paper-quartz")
    rows = [{"mu": 0.132}, {"mu": 0.2}, {"mu": -1.0}, {"mu": 0.01}, {"mu": 0.14}]
    res = evaluate_batch(rows, SolverOptions(h_max=50.0), base=base)
    assert list(res.status) == ["ok", "failed", "failed", "censored_above", "ok"]
    assert res.critical_height[0] == pytest.approx(0.37, rel=1e-2)
    assert np.isnan(res.critical_height[[1, 2]]).all()  # failed: NaN, never imputed
    assert res.critical_height[3] == 50.0  # censored: the bound
    assert "FloatingPointError: stand-in failure" in res.failure_reason[1]
    assert res.failure_reason[2].startswith("invalid inputs: SceneError")
    assert res.inputs["mu"][2] == -1.0  # the value that was asked for is kept
    assert res.flags[0] == "stand_in" and res.evaluations[0] == 3
    assert len(res) == 5


def test_evaluate_batch_accepts_scenes_and_columns(fake_solver):
    base = get_preset("paper-quartz")
    by_scene = evaluate_batch([base, base.replace(mu=0.1)])
    by_columns = evaluate_batch({"mu": np.array([0.132, 0.1])}, base="paper-quartz")
    assert np.array_equal(by_scene.critical_height, by_columns.critical_height)
    assert list(by_scene.inputs["flow_stress"]) == [base.flow_stress] * 2


@pytest.mark.parametrize("preset", ["paper-quartz", "paper-gold"])  # pendulum, vertical drop
def test_study_columns_fast_path_equals_row_by_row(fake_solver, preset):
    # A study chunk's columns (SI floats on a base scene) go through SceneColumns; the result must
    # be the general path's, bit for bit: statuses, reasons, heights and recorded inputs (for a
    # sample whose scene could not be built, its given values; a vertical drop's derived tilt).
    base = get_preset(preset)
    columns = {
        "mu": np.array([0.132, 0.12, -1.0, 0.2, np.nan, 0.1, 0.11, 0.13]),
        "angle": np.array([45.0, 30.0, 40.0, 50.0, 45.0, 90.0, 20.0, 44.0]),
        "initial_temperature": np.array([294.0, 600.0, 290.0, 300.0, 295.0, 296.0, 297.0, 298.0]),
        "target.conductivity": np.array([1.5, 1.6, 1.7, np.inf, 1.2, 1.3, -0.0, 1.4]),
    }
    fast = evaluate_module._evaluate_columns(columns, {}, base)
    general = evaluate_module._evaluate_rows(evaluate_module.as_rows(columns), {}, base)
    _assert_same_batch(fast, general)
    for k in fast.inputs:  # np.array_equal takes -0.0 for 0.0: bytes do not
        assert fast.inputs[k].tobytes() == general.inputs[k].tobytes(), k
    assert list(fast.status).count("failed") >= 5 and "ok" in set(fast.status)
    assert fast.failure_reason[2] == "invalid inputs: SceneError: mu = -1.0: must be in [0, 5) " \
        "(a friction coefficient of 5 or more is surely a typo)"
    # evaluate_batch in process takes the same path; a chunk of a study too.
    batch = evaluate_batch(columns, base=base)
    _assert_same_batch(batch, general)
    chunk = executors.Chunk(0, 8, (base, base), [columns, evaluate_module.as_rows(columns)], {})
    for res in executors.evaluate_chunk(chunk).results:
        _assert_same_batch(res, general)


def test_columns_outside_the_fast_path_go_row_by_row(fake_solver):
    quartz = get_preset("paper-quartz")
    ints = evaluate_batch({"he.density": np.array([1900, 0])}, base=quartz)  # make_scene's
    assert list(ints.status) == ["ok", "failed"] and ints.inputs["he.density"][0] == 1900.0
    assert ints.failure_reason[1] == "invalid inputs: SceneError: he.density = 0: must be > 0 " \
        "kg/m^3"  # the integer as given
    names = evaluate_batch({"he_density": np.array([1800.0, -1.0])}, base=quartz)
    assert list(names.status) == ["ok", "failed"] and names.inputs["he.density"][0] == 1800.0
    unknown = evaluate_batch({"muu": np.array([0.1])}, base=quartz)
    assert unknown.failure_reason[0].startswith("invalid inputs: UnknownKeyError: muu = 0.1")
    with pytest.raises(ValueError, match="different lengths"):
        evaluate_batch({"mu": np.array([0.1]), "angle": np.array([1.0, 2.0])}, base=quartz)


def test_non_finite_height_is_a_failure(monkeypatch):
    import skidmc.solver

    monkeypatch.setattr(skidmc.solver, "critical_height", lambda scene, **kw: types.SimpleNamespace(
        critical_height=float("nan"), censored=None, evaluations=1, flags=(), wall_time=0.0))
    res = evaluate_batch([get_preset("paper-quartz")])
    assert res.status[0] == "failed" and "non-finite" in res.failure_reason[0]


@real_solver
def test_evaluate_batch_real_solver_and_censoring():
    quartz = get_preset("paper-quartz")
    res = evaluate_batch([quartz, quartz, quartz], None)
    assert set(res.status) == {"ok"} and np.all(res.wall_time > 0)
    h = res.critical_height[0]
    low = evaluate_batch([quartz], {"rtol": 1e-2, "h_max": 0.5 * h})
    high = evaluate_batch([quartz], {"rtol": 1e-2, "h_min": 2 * h, "h_max": 10 * h})
    assert low.status[0] == "censored_above" and low.critical_height[0] == 0.5 * h
    assert high.status[0] == "censored_below" and high.critical_height[0] == 2 * h


# --- run_study bookkeeping (stand-in solver, in-process) -----------------------------------------


def test_failing_samples_never_stop_the_run(tmp_path, study_file, fake_solver):
    path = run_study(study_file, tmp_path / "out", workers=1, progress=False)
    assert path == tmp_path / "out" / "ensemble.h5"
    ds = xr.open_dataset(path)
    status = ds.status.values
    assert ds.attrs["complete"] == 1
    assert set(status.ravel()) <= {"ok", "failed"} and "failed" in status  # mu > 0.15 fails
    failed = status == "failed"
    assert np.isnan(ds.critical_height.values[failed]).all()
    assert np.isfinite(ds.critical_height.values[~failed]).all()
    assert all("stand-in failure" in r for r in ds.failure_reason.values[failed])
    assert (ds.mu.values[failed] > 0.15).all() and (ds.mu.values[~failed] <= 0.15).all()


def test_single_scene_study(tmp_path, fake_solver):
    path = tmp_path / "one.toml"
    path.write_text(TINY.split("[[scenes]]")[0] + '[scene]\npreset = "paper-quartz"\n'
                    + TINY[TINY.index("[uncertain.mu]"):])
    ds = xr.open_dataset(run_study(path, tmp_path / "one.h5", workers=1, progress=False))
    assert ds.critical_height.dims == ("sample",) and ds.sizes["sample"] == 12
    assert "" not in ds.status.values and ds.attrs["complete"] == 1


def test_n_override_and_mc_prefix(tmp_path, study_file, fake_solver):
    full = run_study(study_file, tmp_path / "full.h5", workers=1, progress=False)
    short = run_study(study_file, tmp_path / "short.h5", n=5, workers=1, progress=False)
    a, b = _data(full), _data(short)
    assert b.sizes["sample"] == 5
    assert np.array_equal(a.mu.values[:, :5], b.mu.values)


def test_a_sample_that_kills_its_worker_is_isolated(tmp_path, study_file, fake_solver,
                                                    monkeypatch):
    real = executors.evaluate_chunk

    def crashing(chunk):
        if chunk.start <= 3 < chunk.stop:
            raise cf.process.BrokenProcessPool("worker died")
        return real(chunk)

    monkeypatch.setattr(schedule, "evaluate_chunk", crashing)
    path = run_study(study_file, tmp_path / "o.h5", workers=1, chunk_size=4, progress=False)
    ds = xr.open_dataset(path)
    assert list(ds.status.values[:, 3]) == ["failed", "failed"]
    assert "worker process died" in ds.failure_reason.values[0, 3]
    others = np.delete(ds.status.values, 3, axis=1)
    assert "" not in others and ds.attrs["complete"] == 1


def test_existing_files_are_never_overwritten(tmp_path, study_file, fake_solver):
    out = tmp_path / "o.h5"
    run_study(study_file, out, workers=1, progress=False)
    before = out.read_bytes()
    with pytest.raises(StorageError, match="complete run"):
        run_study(study_file, out, workers=1, progress=False)
    report = execute_study(study_file, out, workers=1, resume=True, progress=False)
    assert report.evaluated == 0  # already complete: nothing to do
    assert out.read_bytes() == before
    foreign = tmp_path / "foreign.h5"
    foreign.write_text("mine")
    with pytest.raises(StorageError, match="not an HDF5"):
        run_study(study_file, foreign, workers=1, progress=False)
    with pytest.raises(StorageError, match="not an HDF5"):
        run_study(study_file, foreign, workers=1, progress=False, resume=True)
    assert foreign.read_text() == "mine"


def _args(study, out, **kw):
    return argparse.Namespace(study=str(study), out=str(out), n=kw.get("n"), workers=1,
                              scheduler=None, resume=kw.get("resume", False),
                              quiet=kw.get("quiet", True))


def test_main_run_exit_codes(tmp_path, study_file, fake_solver, capsys):
    bad = tmp_path / "bad.toml"
    bad.write_text(TINY.replace("seed = 2024", "seed = -1"))
    assert main_run(_args(bad, tmp_path / "x")) == 2
    assert "design.seed" in capsys.readouterr().err
    assert main_run(_args(study_file, tmp_path / "x", quiet=False)) == 0
    captured = capsys.readouterr()
    assert captured.out.strip() == str(tmp_path / "x" / "ensemble.h5")
    assert "evaluations" in captured.err and "failed" in captured.err
    assert main_run(_args(study_file, tmp_path / "x")) == 2
    assert "refusing to overwrite" in capsys.readouterr().err


def test_no_progress_bar_when_stderr_is_not_a_terminal(tmp_path, study_file, fake_solver,
                                                       capfd):
    run_study(study_file, tmp_path / "o.h5", workers=1)  # progress=None: automatic
    err = capfd.readouterr().err
    assert "sample/s" not in err and "%|" not in err


# --- determinism, dask, interruption (real solver) ----------------------------------------------


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    """The tiny study run uninterrupted, in this process, in one chunk."""
    if not _solver_available():
        pytest.skip("skidmc.solver not importable")
    d = tmp_path_factory.mktemp("reference")
    (d / "tiny.toml").write_text(TINY)
    path = run_study(d / "tiny.toml", d / "ref.h5", workers=1, chunk_size=12, progress=False)
    status = xr.open_dataset(path).status.values
    assert set(status.ravel()) == {"ok"}, status
    return path


@real_solver
def test_identical_for_any_worker_count_and_chunk_size(tmp_path, study_file, reference):
    one = run_study(study_file, tmp_path / "one.h5", workers=1, chunk_size=5, progress=False)
    _assert_same_data(one, reference)
    two = run_study(study_file, tmp_path / "two.h5", workers=2, chunk_size=3, progress=False)
    _assert_same_data(two, reference)
    # Automatic (time-sized, guided) chunks, with the per-chunk record of the report.
    report = execute_study(study_file, tmp_path / "auto.h5", workers=2, progress=False,
                           timeline=True)
    _assert_same_data(report.path, reference)
    assert report.evaluated == 24 and report.chunks == len(report.timeline) >= 2
    assert sorted(i for c in report.timeline for i in range(c["start"], c["stop"])) \
        == list(range(12))
    assert 1 <= len(report.worker_peak_rss_mib) <= 2
    assert all(v > 0 for v in report.worker_peak_rss_mib.values())
    assert 0 < report.solver_time and 0 <= report.outside_solver < 1


@real_solver
def test_dask_cluster_equals_local_run(tmp_path, study_file, reference):
    distributed = pytest.importorskip("distributed")
    with distributed.LocalCluster(n_workers=1, threads_per_worker=2, processes=False,
                                  dashboard_address=None) as cluster, \
            distributed.Client(cluster) as client:
        path = run_study(study_file, tmp_path / "dask.h5", scheduler=client, chunk_size=4,
                         progress=False)
    _assert_same_data(path, reference)


def _done_count(path: Path) -> int:
    """Samples written so far, read while the writer holds the file (no HDF5 file lock)."""
    try:
        with h5py.File(path, "r", locking=False) as f:
            return int(f["done"][:].sum())
    except (OSError, KeyError):  # not created yet, or caught mid-rename
        return 0


@real_solver
def test_kill_9_then_resume_equals_an_uninterrupted_run(tmp_path, study_file, reference):
    out = tmp_path / "killed.h5"
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(ROOT / "src"),
                                                      env.get("PYTHONPATH")]))
    cmd = [sys.executable, "-m", "skidmc", "run", str(study_file), "--out", str(out),
           "--workers", "1", "--chunk-size", "1", "--quiet"]
    proc = subprocess.Popen(cmd, env=env, start_new_session=True, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE)
    deadline = time.monotonic() + 300
    try:
        while _done_count(out) < 1:
            assert proc.poll() is None, proc.communicate()
            assert time.monotonic() < deadline, "no chunk written in 300 s"
            time.sleep(0.005)
    finally:
        os.killpg(proc.pid, signal.SIGKILL)  # the run and anything it started
        proc.communicate()
    info = inspect_file(out)
    assert info["skidmc"] and not info["complete"]
    assert 1 <= info["done"] < info["n_rows"], "killed too late to interrupt anything"

    # Without --resume the unfinished file is refused, and left as it is.
    assert main_run(_args(study_file, out)) == 2
    assert inspect_file(out)["done"] == info["done"]

    run_study(study_file, out, workers=1, resume=True, chunk_size=5, progress=False)
    _assert_same_data(out, reference)
    history = xr.open_dataset(out).attrs["history"].splitlines()
    assert any("started with 0 of 12" in line for line in history)
    assert any(f"started with {info['done']} of 12" in line for line in history)


_CRASHING_SOLVER = '''
# Loaded at start-up of every Python process of the test (worker processes included): replaces
# the solver by the stand-in of tests/test_runner.py, which kills its process for mu > 0.14.
import math, os, types
import skidmc.solver

def critical_height(scene, rtol=1e-3, tier="full", h_min=1e-3, h_max=1e4):
    if scene.mu > 0.14:
        os._exit(3)  # a crash in compiled code: no exception, the process is gone
    h = 0.37 * (0.132 / scene.mu) ** 2 * math.sqrt(scene.target_conductivity / 1.69)
    return types.SimpleNamespace(critical_height=h, censored=None, evaluations=3, flags=(),
                                 wall_time=1e-6)

skidmc.solver.critical_height = critical_height
'''


def test_a_crashing_worker_process_costs_only_its_sample(tmp_path, study_file):
    (tmp_path / "sitecustomize.py").write_text(_CRASHING_SOLVER)
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(tmp_path), str(ROOT / "src"),
                                                      env.get("PYTHONPATH")]))
    out = tmp_path / "crash.h5"
    proc = subprocess.run([sys.executable, "-m", "skidmc", "run", str(study_file), "--out",
                           str(out), "--workers", "2", "--chunk-size", "4", "--quiet"],
                          env=env, capture_output=True, text=True, timeout=300, check=False)
    assert proc.returncode == 0, proc.stderr
    ds = xr.open_dataset(out)
    crashed = ds.mu.values > 0.14
    assert crashed.any() and (~crashed).any()
    # Every sample of a scene where it crashed is failed, as the crash took the whole sample
    # (all scenes) down; every other sample is evaluated.
    failed = (ds.status.values == "failed").any(axis=0)
    assert np.array_equal(failed, crashed.any(axis=0))
    assert all("worker process died" in r
               for r in ds.failure_reason.values[:, failed].ravel())
    assert set(ds.status.values[:, ~failed].ravel()) == {"ok"}
    assert ds.attrs["complete"] == 1


# --- evaluate_batch on worker processes (real solver) --------------------------------------------


def test_schedule_hands_out_every_sample_once_in_order():
    todo = np.ones(50, dtype=bool)
    todo[[3, 4, 20]] = False  # done already (a resumed run)
    fixed = schedule.Schedule(todo, 4, 2, chunk_size=7)
    chunks = []
    while fixed:
        chunks.append(fixed.next())
    assert [i for a, b in chunks for i in range(a, b)] == list(np.flatnonzero(todo))
    assert max(b - a for a, b in chunks) == 7 and fixed.remaining == 0
    timed = schedule.Schedule(np.ones(2000, dtype=bool), 4, 2)
    sizes = []
    while timed:
        a, b = timed.next()
        sizes.append(b - a)
        timed.observe(b - a, 0.004 * (b - a))  # 4 ms a sample
    assert sum(sizes) == 2000 and sizes[0] == 2  # FIRST_CHUNK_EVALUATIONS / 4 scenes
    assert sizes[1] == 125  # TARGET_CHUNK_SECONDS of work at 4 ms a sample
    shortest = math.ceil(schedule.MIN_CHUNK_SECONDS / 0.004)  # guided: short chunks at the end
    assert min(sizes[1:-1]) == shortest and sizes[-1] <= shortest
    assert sizes[-10:] == sorted(sizes[-10:], reverse=True)


_ROWS = [{"mu": 0.132}, {"mu": 0.12}, {"mu": -1.0}, {"mu": 0.15}, {"mu": 0.11}, {"mu": 0.14},
         {"mu": 0.125}]


def _assert_same_batch(a, b):
    assert list(a.status) == list(b.status)
    assert np.array_equal(a.critical_height, b.critical_height, equal_nan=True)  # bitwise
    assert np.array_equal(a.evaluations, b.evaluations)
    assert list(a.flags) == list(b.flags) and list(a.failure_reason) == list(b.failure_reason)
    for k in a.inputs:
        assert np.array_equal(a.inputs[k], b.inputs[k], equal_nan=True), k


@real_solver
def test_evaluate_batch_on_workers_identical_ordered_isolated():
    options = {"rtol": 1e-2}
    try:
        one = evaluate_batch(_ROWS, options, base="paper-quartz")
        two = evaluate_batch(_ROWS, options, base="paper-quartz", workers=2, chunk_size=2)
        _assert_same_batch(one, two)
        assert list(two.status) == ["ok", "ok", "failed", "ok", "ok", "ok", "ok"]
        assert two.failure_reason[2].startswith("invalid inputs: SceneError")
        assert two.inputs["mu"][2] == -1.0
        # Order: heights fall as mu rises, row by row as given.
        ok = two.status == "ok"
        mu, h = two.inputs["mu"][ok], two.critical_height[ok]
        assert np.array_equal(np.argsort(mu), np.argsort(-h))
        assert np.all(two.wall_time[ok] > 0)
        # The pool stays warm for the next call: Scene objects, automatic chunks, censoring.
        pool = executors.POOLS[2]
        quartz = get_preset("paper-quartz")
        scenes = [quartz.replace(mu=r["mu"]) for r in _ROWS if r["mu"] > 0][::-1]
        capped = {"rtol": 1e-2, "h_max": float(np.nanmedian(one.critical_height))}
        inline = evaluate_batch(scenes, capped)
        pooled = evaluate_batch(scenes, capped, workers=2)
        assert executors.POOLS[2] is pool
        _assert_same_batch(inline, pooled)
        assert "censored_above" in set(pooled.status) and "ok" in set(pooled.status)
    finally:
        executors.shutdown_workers()
    assert not executors.POOLS


_BATCH_SCRIPT = """
import json, sys
from skidmc.ensemble.batch import evaluate_batch
if __name__ == "__main__":
    rows = [{"mu": m} for m in (0.10, 0.12, 0.145, 0.13, 0.16, 0.11)]
    res = evaluate_batch(rows, {"rtol": 1e-2}, base="paper-quartz", workers=2, chunk_size=2)
    print(json.dumps({"status": list(res.status), "reason": list(res.failure_reason),
                      "mu": list(res.inputs["mu"])}))
"""


def test_evaluate_batch_survives_a_crashing_worker(tmp_path):
    (tmp_path / "sitecustomize.py").write_text(_CRASHING_SOLVER)
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(tmp_path), str(ROOT / "src"),
                                                      env.get("PYTHONPATH")]))
    proc = subprocess.run([sys.executable, "-c", _BATCH_SCRIPT], env=env, capture_output=True,
                          text=True, timeout=300, check=False)
    assert proc.returncode == 0, proc.stderr
    out = __import__("json").loads(proc.stdout.strip().splitlines()[-1])
    assert out["mu"] == [0.10, 0.12, 0.145, 0.13, 0.16, 0.11]  # order kept
    assert out["status"] == ["ok", "ok", "failed", "ok", "failed", "ok"]
    assert all("worker process died" in out["reason"][i] for i in (2, 4))
