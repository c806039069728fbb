"""The ensemble runner: statuses, determinism across workers/chunks/dask, kill -9 and resume.

Tests marked "real solver" run skidmc.solver on a tiny study (2 scenes x 12 samples, rtol 1e-2);
the others inject an analytic stand-in (tests/conftest.py: ``solver=fake_height``) to check the
runner's bookkeeping quickly.
"""

from __future__ import annotations

import concurrent.futures as cf
import math
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import h5py
import numpy as np
import pytest
import xarray as xr
from conftest import TINY, crashing_height, fake_height, nan_height, subprocess_env

from skidmc.cli import main
from skidmc.ensemble import evaluate as evaluate_module
from skidmc.ensemble import executors, schedule
from skidmc.ensemble.batch import evaluate_batch
from skidmc.ensemble.run import execute_study, run_study
from skidmc.ensemble.storage import StorageError, inspect_file, open_ensemble
from skidmc.ensemble.study import SolverOptions
from skidmc.scene import get_preset


def _solver_available() -> bool:
    try:
        import skidmc.solver  # noqa: F401
    except ImportError:
        return False
    return True


real_solver = pytest.mark.skipif(not _solver_available(), reason="skidmc.solver not importable")


def _data(path) -> xr.Dataset:
    """The data of a result file without its attributes (timestamps and history differ)."""
    # Without attributes (provenance, times); Dataset.drop_attrs needs xarray >= 2024.10.
    ds = open_ensemble(path)
    ds.attrs = {}
    for var in ds.variables.values():
        var.attrs = {}
    return ds


def _assert_same_data(a, b):
    da, db = _data(a), _data(b)
    assert set(da.variables) == set(db.variables)
    for name in da.variables:
        x, y = da[name].values, db[name].values
        if x.dtype.kind == "f":
            assert np.array_equal(x, y, equal_nan=True), name  # bitwise, NaN where NaN
        else:
            assert np.array_equal(x, y), name


# --- evaluate_batch ------------------------------------------------------------------------------


def test_evaluate_batch_statuses_and_failures():
    base = get_preset("paper-quartz")
    rows = [{"mu": 0.132}, {"mu": 0.2}, {"mu": -1.0}, {"mu": 0.01}, {"mu": 0.14}]
    res = evaluate_batch(rows, SolverOptions(h_max=50.0), base=base, solver=fake_height)
    assert list(res.status) == ["ok", "failed", "failed", "censored_above", "ok"]
    assert res.critical_height[0] == pytest.approx(0.37, rel=1e-2)
    assert np.isnan(res.critical_height[[1, 2]]).all()  # failed: NaN, never imputed
    assert res.critical_height[3] == 50.0  # censored: the bound
    assert "FloatingPointError: stand-in failure" in res.failure_reason[1]
    assert res.failure_reason[2].startswith("invalid inputs: SceneError")
    assert res.inputs["mu"][2] == -1.0  # the value that was asked for is kept
    assert res.flags[0] == "stand_in" and res.evaluations[0] == 3
    assert len(res) == 5


def test_evaluate_batch_accepts_scenes_and_columns():
    base = get_preset("paper-quartz")
    by_scene = evaluate_batch([base, base.replace(mu=0.1)], solver=fake_height)
    by_columns = evaluate_batch({"mu": np.array([0.132, 0.1])}, base="paper-quartz",
                                solver=fake_height)
    assert np.array_equal(by_scene.critical_height, by_columns.critical_height)
    assert list(by_scene.inputs["flow_stress"]) == [base.flow_stress] * 2


@pytest.mark.parametrize("preset", ["paper-quartz", "paper-gold"])  # pendulum, vertical drop
def test_study_columns_fast_path_equals_row_by_row(preset):
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
    fast = evaluate_module._evaluate_columns(columns, {}, base, fake_height)
    general = evaluate_module._evaluate_rows(evaluate_module.as_rows(columns), {}, base,
                                             fake_height)
    _assert_same_batch(fast, general)
    for k in fast.inputs:  # np.array_equal takes -0.0 for 0.0: bytes do not
        assert fast.inputs[k].tobytes() == general.inputs[k].tobytes(), k
    assert list(fast.status).count("failed") >= 5 and "ok" in set(fast.status)
    assert fast.failure_reason[2] == "invalid inputs: SceneError: mu = -1.0: must be in [0, 5) " \
        "(a friction coefficient of 5 or more is surely a typo)"
    # evaluate_batch in process takes the same path; a chunk of a study too.
    batch = evaluate_batch(columns, base=base, solver=fake_height)
    _assert_same_batch(batch, general)
    chunk = executors.Chunk(0, 8, (base, base), [columns, evaluate_module.as_rows(columns)], {},
                            solver=fake_height)
    for res in executors.evaluate_chunk(chunk).results:
        _assert_same_batch(res, general)


def test_columns_outside_the_fast_path_go_row_by_row():
    quartz = get_preset("paper-quartz")
    ints = evaluate_batch({"he.density": np.array([1900, 0])}, base=quartz,  # make_scene's
                          solver=fake_height)
    assert list(ints.status) == ["ok", "failed"] and ints.inputs["he.density"][0] == 1900.0
    assert ints.failure_reason[1] == "invalid inputs: SceneError: he.density = 0: must be > 0 " \
        "kg/m^3"  # the integer as given
    names = evaluate_batch({"he_density": np.array([1800.0, -1.0])}, base=quartz,
                           solver=fake_height)
    assert list(names.status) == ["ok", "failed"] and names.inputs["he.density"][0] == 1800.0
    unknown = evaluate_batch({"muu": np.array([0.1])}, base=quartz, solver=fake_height)
    assert unknown.failure_reason[0].startswith("invalid inputs: UnknownKeyError: muu = 0.1")
    with pytest.raises(ValueError, match="different lengths"):
        evaluate_batch({"mu": np.array([0.1]), "angle": np.array([1.0, 2.0])}, base=quartz,
                       solver=fake_height)


def test_non_finite_height_is_a_failure():
    res = evaluate_batch([get_preset("paper-quartz")], solver=nan_height)
    assert res.status[0] == "failed" and "non-finite" in res.failure_reason[0]


def test_the_solver_is_injected_not_imported(monkeypatch):
    # With a solver given, skidmc.solver is never consulted: a broken one cannot be reached.
    import skidmc.solver

    def broken(*args, **kwargs):
        raise AssertionError("the default solver was called")

    monkeypatch.setattr(skidmc.solver, "critical_height", broken)
    res = evaluate_batch([get_preset("paper-quartz")], solver=fake_height)
    assert list(res.status) == ["ok"]
    with pytest.raises(TypeError, match="callable"):
        evaluate_batch([get_preset("paper-quartz")], solver="critical_height")


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


def test_failing_samples_never_stop_the_run(tmp_path, study_file, ):
    path = run_study(study_file, tmp_path / "out", workers=1, progress=False, solver=fake_height)
    assert path == tmp_path / "out" / "ensemble.h5"
    ds = open_ensemble(path)
    status = ds.status.values
    assert ds.attrs["complete"] == 1
    assert set(status.ravel()) <= {"ok", "failed"} and "failed" in status  # mu > 0.15 fails
    failed = status == "failed"
    assert np.isnan(ds.critical_height.values[failed]).all()
    assert np.isfinite(ds.critical_height.values[~failed]).all()
    assert all("stand-in failure" in r for r in ds.failure_reason.values[failed])
    assert (ds.mu.values[failed] > 0.15).all() and (ds.mu.values[~failed] <= 0.15).all()


def test_single_scene_study(tmp_path, ):
    path = tmp_path / "one.toml"
    path.write_text(TINY.split("[[scenes]]")[0] + '[scene]\npreset = "paper-quartz"\n'
                    + TINY[TINY.index("[uncertain.mu]"):])
    ds = open_ensemble(run_study(path, tmp_path / "one.h5", workers=1, progress=False,
                                   solver=fake_height))
    assert ds.critical_height.dims == ("sample",) and ds.sizes["sample"] == 12
    assert "" not in ds.status.values and ds.attrs["complete"] == 1


def test_n_override_and_mc_prefix(tmp_path, study_file, ):
    full = run_study(study_file, tmp_path / "full.h5", workers=1, progress=False,
                     solver=fake_height)
    short = run_study(study_file, tmp_path / "short.h5", n=5, workers=1, progress=False,
                      solver=fake_height)
    a, b = _data(full), _data(short)
    assert b.sizes["sample"] == 5
    assert np.array_equal(a.mu.values[:, :5], b.mu.values)


def test_a_sample_that_kills_its_worker_is_isolated(tmp_path, study_file,
                                                    monkeypatch):
    real = executors.evaluate_chunk

    def crashing(chunk):
        if chunk.start <= 3 < chunk.stop:
            raise cf.process.BrokenProcessPool("worker died")
        return real(chunk)

    monkeypatch.setattr(schedule, "evaluate_chunk", crashing)
    path = run_study(study_file, tmp_path / "o.h5", workers=1, chunk_size=4, progress=False,
                     solver=fake_height)
    ds = open_ensemble(path)
    assert list(ds.status.values[:, 3]) == ["failed", "failed"]
    assert "worker process died" in ds.failure_reason.values[0, 3]
    others = np.delete(ds.status.values, 3, axis=1)
    assert "" not in others and ds.attrs["complete"] == 1


def test_existing_files_are_never_overwritten(tmp_path, study_file):
    out = tmp_path / "o.h5"
    run_study(study_file, out, workers=1, progress=False, solver=fake_height)
    before = out.read_bytes()
    # A complete file of this very study is up to date: nothing computed, nothing written.
    report = execute_study(study_file, out, workers=1, progress=False, solver=fake_height)
    assert report.action == "up_to_date" and report.evaluated == 0 and report.completed
    report = execute_study(study_file, out, workers=1, resume=True, progress=False,
                           solver=fake_height)
    assert report.evaluated == 0  # already complete: nothing to do
    assert out.read_bytes() == before
    foreign = tmp_path / "foreign.h5"
    foreign.write_text("mine")
    for kwargs in ({}, {"resume": True}, {"force": True}):
        with pytest.raises(StorageError, match="not an HDF5"):
            run_study(study_file, foreign, workers=1, progress=False, solver=fake_height,
                      **kwargs)
    assert foreign.read_text() == "mine"


def test_a_file_of_another_study_or_n_is_refused(tmp_path, study_file):
    out = tmp_path / "o.h5"
    run_study(study_file, out, workers=1, progress=False, solver=fake_height)
    before = out.read_bytes()
    other = tmp_path / "other.toml"
    other.write_text(TINY.replace('name = "tiny"', 'name = "other"'))
    for kwargs in ({}, {"force": True}, {"resume": True}):  # another study: even with force
        with pytest.raises(StorageError, match="another study .*'tiny'.*even with --force"):
            run_study(other, out, workers=1, progress=False, solver=fake_height, **kwargs)
    edited = tmp_path / "edited.toml"  # the same study, edited: its text hash differs
    edited.write_text(TINY.replace("seed = 2024", "seed = 2025"))
    with pytest.raises(StorageError, match="another version of this study.*--force"):
        run_study(edited, out, workers=1, progress=False, solver=fake_height)
    with pytest.raises(StorageError, match="a different --n"):
        run_study(study_file, out, n=5, workers=1, progress=False, solver=fake_height)
    assert out.read_bytes() == before
    # --force recomputes this study's file into the new version.
    run_study(edited, out, workers=1, progress=False, solver=fake_height, force=True)
    with xr.open_dataset(out) as ds:
        assert ds.attrs["seed"] == 2025 and ds.attrs["complete"] == 1
    assert not (tmp_path / "o.h5.new").exists()


def test_force_replaces_the_file_only_when_complete(tmp_path, study_file):
    from conftest import interrupting_height

    from skidmc.ensemble.run import RunInterrupted

    out = tmp_path / "o.h5"
    run_study(study_file, out, workers=1, progress=False, solver=fake_height)
    before = out.read_bytes()
    with pytest.raises(RunInterrupted) as info:  # Ctrl-C half-way through a --force run
        run_study(study_file, out, workers=1, chunk_size=2, progress=False, force=True,
                  solver=interrupting_height)
    new = tmp_path / "o.h5.new"
    assert out.read_bytes() == before  # the old file is untouched
    partial = inspect_file(new)
    assert 0 < partial["done"] < 12 and not partial["complete"]
    assert f"{out} is unchanged" in info.value.hint and str(new) in info.value.hint
    # The next --force continues the new file, then renames it over the old one.
    report = execute_study(study_file, out, workers=1, chunk_size=2, progress=False, force=True,
                           solver=fake_height)
    assert report.action == "replace" and report.evaluated == 2 * (12 - partial["done"])
    assert not new.exists() and inspect_file(out)["complete"]
    _assert_same_data(out, run_study(study_file, tmp_path / "fresh.h5", workers=1,
                                     progress=False, solver=fake_height))
    history = xr.open_dataset(out).attrs["history"]
    assert f"started with {partial['done']} of 12" in history


def test_an_interrupted_new_run_keeps_its_chunks_or_leaves_nothing(tmp_path, study_file):
    from conftest import interrupting_height

    from skidmc.ensemble.run import RunInterrupted

    out = tmp_path / "o.h5"
    with pytest.raises(RunInterrupted) as info:
        run_study(study_file, out, workers=1, chunk_size=2, progress=False,
                  solver=interrupting_height)
    done = inspect_file(out)["done"]
    assert info.value.hint == f"{done} of 12 samples are saved in {out}; continue with --resume"
    first = tmp_path / "first.h5"  # interrupted before any chunk was written: no file
    with pytest.raises(RunInterrupted, match="nothing was written"):
        run_study(study_file, first, workers=1, chunk_size=12, progress=False,
                  solver=interrupting_height)
    assert not first.exists() and not Path(f"{first}.tmp").exists()


def test_no_progress_bar_when_stderr_is_not_a_terminal(tmp_path, study_file, capfd):
    run_study(study_file, tmp_path / "o.h5", workers=1, solver=fake_height)  # progress: auto
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
    status = open_ensemble(path).status.values
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


@real_solver
def test_threads_equal_a_local_run(tmp_path, study_file, reference):
    # scheduler="threads": the same chunks on threads of this process (the kernels release the
    # GIL); every number as the in-process reference, and no worker process started.
    pools = dict(executors.POOLS)
    report = execute_study(study_file, tmp_path / "threads.h5", workers=2, chunk_size=3,
                           scheduler="threads", progress=False, timeline=True)
    _assert_same_data(report.path, reference)
    assert report.workers == 2 and report.chunks == 4   # 12 rows, 3 per chunk
    assert set(report.worker_peak_rss_mib) == {os.getpid()}
    assert executors.POOLS == pools


@real_solver
def test_evaluate_batch_on_threads_identical_ordered():
    options = {"rtol": 1e-2}
    pools = dict(executors.POOLS)
    one = evaluate_batch(_ROWS, options, base="paper-quartz")
    threads = evaluate_batch(_ROWS, options, base="paper-quartz", workers=2, chunk_size=2,
                             scheduler="threads")
    _assert_same_batch(one, threads)
    assert list(threads.status) == ["ok", "ok", "failed", "ok", "ok", "ok", "ok"]
    assert executors.POOLS == pools   # no worker process was started
    assert executors.check_scheduler(" threads ") == "threads"
    with pytest.raises(executors.SchedulerError, match="'threads'"):
        evaluate_batch(_ROWS, options, base="paper-quartz", workers=2, scheduler="thread")


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
    env = subprocess_env()
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
    assert main(["run", str(study_file), "--out", str(out), "--workers", "1", "--quiet"]) == 2
    assert inspect_file(out)["done"] == info["done"]

    run_study(study_file, out, workers=1, resume=True, chunk_size=5, progress=False)
    _assert_same_data(out, reference)
    history = xr.open_dataset(out).attrs["history"].splitlines()
    assert any("started with 0 of 12" in line for line in history)
    assert any(f"started with {info['done']} of 12" in line for line in history)


@real_solver
def test_ctrl_c_during_a_multi_worker_run_is_one_line_and_exit_130(tmp_path, study_file):
    # Ctrl-C at a terminal sends SIGINT to the whole process group: the run, the forkserver
    # and every worker. Only the parent acts on it.
    out = tmp_path / "interrupted.h5"
    cmd = [sys.executable, "-m", "skidmc", "run", str(study_file), "--out", str(out),
           "--workers", "2", "--chunk-size", "1", "--n", "400"]
    # As at a terminal, the run starts with SIGINT at its default: a pytest started in the
    # background of a shell without job control ignores SIGINT, and its children would inherit
    # that (the run then ignores Ctrl-C by design, leaving a custom disposition alone, and
    # finished with exit 0: seen twice when .ci/run was started with '&').
    proc = subprocess.Popen(cmd, env=subprocess_env(), start_new_session=True,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    deadline = time.monotonic() + 300
    try:
        while _done_count(out) < 2:
            assert proc.poll() is None, proc.communicate()
            assert time.monotonic() < deadline, "no chunk written in 300 s"
            time.sleep(0.01)
        os.killpg(proc.pid, signal.SIGINT)
        stdout, stderr = proc.communicate(timeout=120)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.communicate()
    info = inspect_file(out)
    assert proc.returncode == 130, stderr
    assert "Traceback" not in stderr and "KeyboardInterrupt" not in stderr, stderr
    line = (f"skidmc run: interrupted; {info['done']} of 400 samples are saved in {out}; "
            "continue with --resume")
    assert stderr.splitlines() == [line]
    assert stdout == "" and 2 <= info["done"] < 400 and not info["complete"]


# A solver that kills its worker process is injected like any other (conftest.crashing_height,
# module level: it pickles by reference into the workers); the test process only hands out chunks.


def test_a_crashing_worker_process_costs_only_its_sample(tmp_path, study_file):
    out = tmp_path / "crash.h5"
    try:
        run_study(study_file, out, workers=2, chunk_size=4, progress=False,
                  solver=crashing_height)
    finally:
        executors.shutdown_workers()
    ds = open_ensemble(out)
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


def test_evaluate_batch_survives_a_crashing_worker():
    rows = [{"mu": m} for m in (0.10, 0.12, 0.145, 0.13, 0.16, 0.11)]
    try:
        res = evaluate_batch(rows, {"rtol": 1e-2}, base="paper-quartz", workers=2, chunk_size=2,
                             solver=crashing_height)
    finally:
        executors.shutdown_workers()
    assert list(res.inputs["mu"]) == [0.10, 0.12, 0.145, 0.13, 0.16, 0.11]  # order kept
    assert list(res.status) == ["ok", "ok", "failed", "ok", "failed", "ok"]
    assert all("worker process died" in res.failure_reason[i] for i in (2, 4))
