"""The ensemble file: plain-xarray readable, self-describing, chunk by chunk, never clobbered."""

from __future__ import annotations

import hashlib
import os
import subprocess
import sys

import h5py
import numpy as np
import pytest
import xarray as xr
from conftest import STORAGE_TEXT as TEXT

from skidmc.ensemble.storage import (
    CHUNK_BYTES,
    FORMAT,
    PAGE_BYTES,
    EnsembleFile,
    StorageError,
    _encode,
    ensemble_variables,
    inspect_file,
    summarize_file,
    verify_file,
)
from skidmc.ensemble.study import parse_study


@pytest.fixture
def study(storage_study):
    return storage_study


def _columns(study, start, stop, status="ok"):
    m, s = stop - start, len(study.scenes)
    cols = {}
    for spec in ensemble_variables(study):
        if spec.dtype == "str":
            cols[spec.name] = np.full((s, m), status if spec.name == "status" else "é" * 3,
                                      dtype=object)
        else:
            cols[spec.name] = np.arange(start, stop, dtype=float)[None, :] + np.arange(s)[:, None]
    return cols


def test_written_file_reads_in_xarray_with_units_everywhere(tmp_path, study):
    path = tmp_path / "ens.h5"
    with EnsembleFile.create(path, study, history="created by test") as f:
        assert f.done().sum() == 0
        f.write_chunk(0, 4, _columns(study, 0, 4))
        f.write_chunk(7, 10, _columns(study, 7, 10, status="failed"))
        assert np.array_equal(np.flatnonzero(f.done()), [0, 1, 2, 3, 7, 8, 9])
    ds = xr.open_dataset(path)
    assert dict(ds.sizes) == {"scene": 2, "sample": 10}
    assert list(ds.scene.values) == ["quartz", "gold"]
    assert list(ds.configuration.values) == ["pendulum", "vertical"]
    for name, var in ds.variables.items():
        assert "units" in var.attrs and "long_name" in var.attrs, name
    assert ds.critical_height.attrs["units"] == "m"
    assert ds["flow_stress"].attrs["units"] == "Pa"
    assert ds["kinetics.rate_at_reference"].attrs["reference_temperature"].tolist() == [575, 575]
    assert ds.critical_height.dims == ("scene", "sample")
    assert ds.critical_height.values[1, 2] == 3.0
    assert np.isnan(ds.critical_height.values[:, 4:7]).all()  # not written: NaN, not zero
    assert ds.status.values[0, 0] == "ok" and ds.status.values[0, 8] == "failed"
    assert ds.status.values[0, 5] == ""  # not evaluated yet
    assert ds.failure_reason.values[0, 0] == "ééé"
    assert ds.attrs["complete"] == 0


def test_plain_xarray_needs_no_skidmc(tmp_path, study):
    path = tmp_path / "ens.h5"
    with EnsembleFile.create(path, study) as f:
        f.write_chunk(0, 10, _columns(study, 0, 10))
        f.mark_complete()
    code = ("import sys; sys.modules['skidmc'] = None\n"  # importing skidmc would now fail
            "import xarray as xr\n"
            f"ds = xr.open_dataset({str(path)!r})\n"
            "print(ds.critical_height.sum().item(), ds.status.values[0, 0])\n")
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env,
                         check=True)
    assert out.stdout.split() == [str(float(2 * 45 + 10)), "ok"]


def test_provenance_attributes(tmp_path, study):
    path = tmp_path / "ens.h5"
    with EnsembleFile.create(path, study, history="line one") as f:
        f.add_history("line two")
    attrs = xr.open_dataset(path).attrs
    assert attrs["skidmc_format"] == FORMAT
    assert attrs["skidmc_version"]
    assert attrs["study_text"] == TEXT
    assert attrs["study_sha256"] == hashlib.sha256(TEXT.encode()).hexdigest()
    assert attrs["seed"] == 42 and attrs["design_method"] == "mc" and attrs["design_n"] == 10
    assert attrs["solver_rtol"] == 1e-2 and attrs["solver_tier"] == "full"
    assert attrs["solver_h_min"] == 1e-3 and attrs["solver_h_max"] == 1e4
    assert attrs["created"].startswith("20")
    assert attrs["history"].splitlines() == ["line one", "line two"]


def test_create_never_overwrites(tmp_path, study):
    path = tmp_path / "ens.h5"
    path.write_text("precious")
    with pytest.raises(StorageError, match="exists"):
        EnsembleFile.create(path, study)
    assert path.read_text() == "precious"


def test_stale_temporary_file_from_a_killed_create_is_replaced(tmp_path, study):
    path = tmp_path / "ens.h5"
    (tmp_path / "ens.h5.tmp").write_bytes(b"half a skeleton")
    EnsembleFile.create(path, study).close()
    assert inspect_file(path)["skidmc"] and not (tmp_path / "ens.h5.tmp").exists()


def test_foreign_files_are_detected(tmp_path, study):
    text = tmp_path / "notes.h5"
    text.write_text("not hdf5")
    with pytest.raises(StorageError, match="not an HDF5 file"):
        inspect_file(text)
    foreign = tmp_path / "foreign.h5"
    with h5py.File(foreign, "w") as f:
        f["x"] = np.arange(3)
    assert inspect_file(foreign)["skidmc"] is False
    before = foreign.read_bytes()
    with pytest.raises(StorageError, match="not a skidmc ensemble"):
        EnsembleFile.resume(foreign, study)
    assert foreign.read_bytes() == before


def test_resume_refuses_another_study_or_n(tmp_path, study):
    path = tmp_path / "ens.h5"
    with EnsembleFile.create(path, study) as f:
        f.write_chunk(0, 3, _columns(study, 0, 3))
    info = inspect_file(path)
    assert (info["complete"], info["done"], info["n_rows"]) == (False, 3, 10)
    other = parse_study(TEXT.replace("seed = 42", "seed = 43"), file="other.toml")
    with pytest.raises(StorageError, match="another study"):
        EnsembleFile.resume(path, other)
    with pytest.raises(StorageError, match="--n"):
        EnsembleFile.resume(path, study.with_n(12))
    with EnsembleFile.resume(path, study, history="resumed") as f:
        assert f.done().sum() == 3
    assert xr.open_dataset(path).attrs["history"].endswith("resumed")


def test_single_scene_study_has_no_scene_dimension(tmp_path):
    text = TEXT.split("[[scenes]]")[0] + '[scene]\npreset = "paper-quartz"\n' + \
        TEXT[TEXT.index("[uncertain.mu]"):]
    study = parse_study(text)
    path = tmp_path / "one.h5"
    cols = {k: v[0] for k, v in _columns(study, 0, 10).items()}
    with EnsembleFile.create(path, study) as f:
        f.write_chunk(0, 10, cols)
    ds = xr.open_dataset(path)
    assert "scene" not in ds.dims and ds.critical_height.dims == ("sample",)
    assert ds.configuration.values == "pendulum"


def test_text_is_cut_at_a_character_boundary():
    chars = _encode(["é" * 10, "ok"], 5)
    assert chars.shape == (2, 5)
    decoded = [b"".join(row).decode("utf-8") for row in chars]
    assert decoded == ["éé", "ok"]


# --- checksums and crash safety -------------------------------------------------------------------


def _chunk_extents(path) -> list[tuple[int, int, str]]:
    """(first byte, end byte, variable) of every HDF5 chunk of every chunked variable."""
    out = []
    with h5py.File(path, "r") as f:
        def visit(name, obj):
            if isinstance(obj, h5py.Dataset) and obj.chunks:
                for i in range(obj.id.get_num_chunks()):
                    info = obj.id.get_chunk_info(i)
                    out.append((info.byte_offset, info.byte_offset + info.size, name))
        f.visititems(visit)
    return out


def test_every_per_sample_variable_is_checksummed_in_page_sized_aligned_chunks(tmp_path, study):
    path = tmp_path / "ens.h5"
    EnsembleFile.create(path, study.with_n(1000)).close()
    with h5py.File(path, "r") as f:
        for spec in ensemble_variables(study):
            ds = f[spec.name]
            assert ds.fletcher32 and ds.chunks, spec.name
            assert ds.id.get_create_plist().get_alloc_time() == h5py.h5d.ALLOC_TIME_EARLY
            assert ds.id.get_num_chunks() == np.prod(
                [-(-n // c) for n, c in zip(ds.shape, ds.chunks)])  # all allocated at creation
        assert f["done"].fletcher32 and f["sample"].fletcher32
    extents = _chunk_extents(path)
    for first, end, name in extents:
        assert end - first <= PAGE_BYTES and first % PAGE_BYTES == 0, name  # one page each
    # The largest chunks fill their page but for the remainder of CHUNK_BYTES / element size.
    assert max(end - first for first, end, _ in extents) > CHUNK_BYTES - 256


def test_writing_a_chunk_changes_only_chunk_data(tmp_path, study):
    # The crash-safety rule of the module docstring: after creation, writes touch raw data only
    # (chunks rewritten in place, the chunk index never changes).
    path = tmp_path / "ens.h5"
    EnsembleFile.create(path, study).close()
    before = np.frombuffer(path.read_bytes(), np.uint8)
    with EnsembleFile.resume(path, study) as f:
        f.write_chunk(3, 6, _columns(study, 3, 6))
        f.write_chunk(6, 7, _columns(study, 6, 7, status="failed"))
    after = np.frombuffer(path.read_bytes(), np.uint8)
    assert before.size == after.size
    changed = np.flatnonzero(before != after)
    assert changed.size > 0
    extents = _chunk_extents(path)
    outside = [int(i) for i in changed if not any(a <= i < b for a, b, _ in extents)]
    assert outside == []


def _flip_byte_in(path, variable: str, chunk: int = 0, at: int = 5) -> None:
    with h5py.File(path, "r") as f:
        offset = f[variable].id.get_chunk_info(chunk).byte_offset
    with open(path, "r+b") as fh:
        fh.seek(offset + at)
        byte = fh.read(1)
        fh.seek(offset + at)
        fh.write(bytes([byte[0] ^ 0x10]))


def test_bytes_overwritten_in_the_data_are_detected(tmp_path, study):
    path = tmp_path / "ens.h5"
    with EnsembleFile.create(path, study) as f:
        f.write_chunk(0, 10, _columns(study, 0, 10))
        f.mark_complete()
    verify_file(path)  # intact
    _flip_byte_in(path, "critical_height", chunk=1)
    assert inspect_file(path)["complete"]  # attributes and done flags alone look fine ...
    with pytest.raises(StorageError, match="damaged: variable 'critical_height'.*samples 0-9"
                       ".*--force") as info:
        inspect_file(path, verify=True)  # ... the checksums do not
    assert info.value.damaged
    with pytest.raises(StorageError, match="damaged"):
        EnsembleFile.resume(path, study)


def test_a_truncated_file_is_damaged_not_busy(tmp_path, study):
    path = tmp_path / "ens.h5"
    with EnsembleFile.create(path, study) as f:
        f.write_chunk(0, 10, _columns(study, 0, 10))
    data = path.read_bytes()
    path.write_bytes(data[: len(data) // 2])
    with pytest.raises(StorageError, match="is damaged: the file is truncated") as info:
        inspect_file(path)
    assert info.value.damaged and "another process" not in str(info.value)
    assert "--force" in str(info.value)
    path.write_bytes(b"")
    with pytest.raises(StorageError, match="empty file") as info:
        inspect_file(path)
    assert info.value.damaged


def test_create_says_why_it_cannot(tmp_path, study):
    blocker = tmp_path / "notes.txt"
    blocker.write_text("a file")
    with pytest.raises(StorageError, match=f"cannot create the result file: {blocker} is a "
                       "file, not a folder"):
        EnsembleFile.create(blocker / "sub" / "ens.h5", study)
    assert blocker.read_text() == "a file"


@pytest.mark.skipif(hasattr(os, "geteuid") and os.geteuid() == 0,
                    reason="root may write anywhere")
def test_create_in_a_folder_without_permission(tmp_path, study):
    locked = tmp_path / "locked"
    locked.mkdir(mode=0o500)
    try:
        with pytest.raises(StorageError, match=f"permission denied for {locked}"):
            EnsembleFile.create(locked / "ens.h5", study)
        assert list(locked.iterdir()) == []
    finally:
        locked.chmod(0o700)


def test_summary_per_scene(tmp_path, study):
    path = tmp_path / "ens.h5"
    cols = _columns(study, 0, 10)
    cols["critical_height"] = np.array([np.arange(1.0, 11.0), np.full(10, 1e4)])
    cols["status"] = np.array([["ok"] * 8 + ["failed", "censored_below"],
                               ["censored_above"] * 10], dtype=object)
    cols["critical_height"][0, 8:] = np.nan, 1e-3  # failed; censored below at h_min
    with EnsembleFile.create(path, study) as f:
        f.write_chunk(0, 10, cols)
    quartz, gold = summarize_file(path)
    assert (quartz.scene, quartz.written, quartz.ok, quartz.failed) == ("quartz", 10, 8, 1)
    assert (quartz.censored_below, quartz.censored_above) == (1, 0)
    # Empirical quantiles over the 9 that did not fail (1e-3, 1, ..., 8): sample values.
    assert (quartz.p05, quartz.median, quartz.p95) == (1e-3, 4.0, 8.0)
    assert quartz.range_bound == ("<", "") and quartz.median_bound == ""
    assert gold.censored_above == 10 and gold.median == 1e4 and gold.median_bound == ">"


def test_create_reports_permission_denied_by_the_system(tmp_path, study, monkeypatch):
    # As root the chmod test above cannot fail; the system's answer is simulated here.
    import errno
    import pathlib

    def denied(self, *args, **kwargs):
        raise PermissionError(errno.EACCES, "Permission denied", str(self))

    monkeypatch.setattr(pathlib.Path, "mkdir", denied)
    target = tmp_path / "no" / "ens.h5"
    with pytest.raises(StorageError, match=f"{target}: cannot create the result file: "
                       f"permission denied for {target.parent}"):
        EnsembleFile.create(target, study)
