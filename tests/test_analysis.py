"""open_ensemble: the one way the analysis layer reads a result file."""

from __future__ import annotations

import subprocess
import sys

import h5py
import numpy as np
import pytest
from conftest import fake_height, interrupting_height, subprocess_env

from skidmc.analysis import open_ensemble
from skidmc.ensemble.run import RunInterrupted, run_study
from skidmc.ensemble.storage import StorageError


@pytest.fixture
def unfinished(tmp_path, study_file):
    """The tiny study interrupted after 8 of its 12 samples, plus a half-written chunk: data of
    sample 10 written without its done flag (as a kill between the two would leave it)."""
    path = tmp_path / "part.h5"
    with pytest.raises(RunInterrupted):
        run_study(study_file, path, workers=1, chunk_size=2, progress=False,
                  solver=interrupting_height)
    with h5py.File(path, "r+") as f:
        assert f["done"][:].tolist() == [1] * 8 + [0] * 4
        f["critical_height"][:, 10] = 123.0
        f["mu"][:, 10] = 0.5
        f["status"][:, 10] = np.frombuffer(b"ok".ljust(16, b"\0"), "S1")
    return path


def test_unfinished_samples_are_masked(unfinished):
    ds = open_ensemble(unfinished)
    done = ds.done.values
    assert done.dtype == bool and done.sum() == 8 and ds.attrs["unfinished"] == 4
    assert np.isnan(ds.critical_height.values[:, ~done]).all()  # 123.0 of sample 10: masked
    assert np.isfinite(ds.critical_height.values[0, :8]).sum() > 0
    assert np.isnan(ds.mu.values[:, ~done]).all() and np.isfinite(ds.mu.values[:, done]).all()
    assert (ds.status.values[:, ~done] == "").all() and "ok" in ds.status.values[:, done]
    assert np.isnan(ds.evaluations.values[:, ~done]).all()
    ok = ds.status.values == "ok"
    assert (ds.evaluations.values[ok] == 3).all()  # the stand-in's count, as float now


def test_study_metadata_is_decoded(tmp_path, study_file):
    path = run_study(study_file, tmp_path / "full.h5", workers=1, progress=False,
                     solver=fake_height)
    ds = open_ensemble(path)
    assert ds.attrs["unfinished"] == 0 and ds.evaluations.dtype.kind == "i"  # nothing masked
    study = ds.attrs["study"]
    assert study["study"]["name"] == "tiny" and study["design"]["seed"] == 2024
    assert study["uncertain"]["mu"]["source"] == "test"
    assert ds.attrs["solver"] == {"rtol": 1e-2, "tier": "full", "h_min": 1e-3, "h_max": 1e4}
    design = dict(ds.attrs["design"])
    keys = design.pop("keys")
    assert design == {"method": "mc", "n": 12, "seed": 2024, "second_order": True,
                      "n_epistemic": 0, "kinds": ["aleatory"] * 4}
    assert sorted(keys) == sorted(["mu", "target.conductivity", "kinetics.activation_temperature",
                                   "kinetics.prefactor"])
    assert list(ds.scene.values) == ["quartz", "alumina"]


def test_the_file_is_not_held_open(unfinished):
    ds = open_ensemble(unfinished)
    with h5py.File(unfinished, "r+") as f:  # fails if this process still had it open read-only
        f.attrs["touched"] = 1
    assert ds.critical_height.values.shape == (2, 12)  # in memory


def test_clear_errors_for_foreign_and_damaged_files(tmp_path, unfinished):
    text = tmp_path / "notes.h5"
    text.write_text("not hdf5")
    with pytest.raises(StorageError, match="not an HDF5 file"):
        open_ensemble(text)
    foreign = tmp_path / "foreign.h5"
    with h5py.File(foreign, "w") as f:
        f["x"] = np.arange(3)
    with pytest.raises(StorageError, match="not a skidmc ensemble"):
        open_ensemble(foreign)
    with pytest.raises(StorageError, match="does not exist"):
        open_ensemble(tmp_path / "missing.h5")
    with h5py.File(unfinished, "r") as f:
        offset = f["mu"].id.get_chunk_info(0).byte_offset
    with open(unfinished, "r+b") as fh:
        fh.seek(offset + 3)
        fh.write(b"\x7f")
    with pytest.raises(StorageError, match="damaged: variable 'mu'") as info:
        open_ensemble(unfinished)
    assert info.value.damaged


def test_no_matplotlib():
    code = ("import sys; import skidmc.analysis; from skidmc.analysis import open_ensemble; "
            "assert 'matplotlib' not in sys.modules, 'matplotlib imported'; "
            "print(skidmc.analysis.__all__)")
    out = subprocess.run([sys.executable, "-c", code], env=subprocess_env(), capture_output=True,
                         text=True, check=True)
    assert "'open_ensemble'" in out.stdout


NESTED = """
[study]
name = "nested"
[scene]
preset = "paper-quartz"
[uncertain.mu]
distribution = "lognorm"
s = 0.1
relative = true
kind = "aleatory"
source = "test"
[uncertain."kinetics.activation_temperature"]
distribution = "uniform"
loc = "24000 K"
scale = "4000 K"
kind = "epistemic"
source = "test"
[design]
method = "lhs"
n = 6
n_epistemic = 4
seed = 7
[solver]
rtol = 1e-2
"""


def test_a_nested_design_opens_as_epistemic_by_sample(tmp_path):
    study = tmp_path / "nested.toml"
    study.write_text(NESTED)
    path = run_study(study, tmp_path / "n.h5", workers=1, progress=False, solver=fake_height)
    ds = open_ensemble(path)
    assert ds.critical_height.dims == ("epistemic", "sample")
    assert ds.critical_height.shape == (4, 6)
    assert ds.attrs["design"]["kinds"] == ["aleatory", "epistemic"]
    # The epistemic input is constant within an epistemic draw and differs between draws; the
    # aleatory one repeats across draws (common random numbers).
    t_act = ds["kinetics.activation_temperature"].values
    mu = ds["mu"].values
    assert np.all(t_act == t_act[:, :1]) and len(np.unique(t_act[:, 0])) == 4
    assert np.all(mu == mu[:1, :])
