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

from skidmc.ensemble.storage import (
    FORMAT,
    EnsembleFile,
    StorageError,
    _encode,
    ensemble_variables,
    inspect_file,
)
from skidmc.ensemble.study import parse_study

TEXT = """
[study]
name = "storage-test"
description = "two scenes"
[[scenes]]
name = "quartz"
preset = "paper-quartz"
[[scenes]]
name = "gold"
preset = "paper-gold"
[uncertain.mu]
distribution = "lognorm"
s = 0.2
relative = true
source = "test"
[uncertain."kinetics.rate_at_reference"]
distribution = "lognorm"
s = 1.0
relative = true
reference_temperature = "575 K"
source = "test"
[design]
method = "mc"
n = 10
seed = 42
[solver]
rtol = 1e-2
"""


@pytest.fixture
def study():
    return parse_study(TEXT, file="storage-test.toml")


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
