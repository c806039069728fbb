"""Analysis of ensemble results; :func:`open_ensemble` is the one way in.

Every analysis reads a result file through :func:`open_ensemble`, which checks what it opens and
hands back plain xarray. Modules:

- :mod:`~skidmc.analysis.gonogo`: go/no-go statistics (probit with profile-likelihood intervals,
  Dixon-Mood up-down, censored log-normal fits, empirical go curves with simultaneous bands,
  scores);
- :mod:`~skidmc.analysis.experiments`: the report's drops, 50 % heights and friction;
- :mod:`~skidmc.analysis.sensitivity`: Sobol' indices with bootstrap intervals, groups, Morris;
- :mod:`~skidmc.analysis.rare_events` and :mod:`~skidmc.analysis.hazard`: rare-event
  probabilities and the drop-height hazard estimator;
- :mod:`~skidmc.analysis.report`: what ``skidmc report`` writes.

Figures are drawn by functions that take a matplotlib ``ax``; nothing here imports matplotlib at
import time.
"""

from __future__ import annotations

import os
from pathlib import Path

from skidmc.analysis.experiments import EXPERIMENTS, get_experiment
from skidmc.analysis.gonogo import (
    compare_h50,
    fit_lognormal,
    fit_probit,
    go_curve,
    score_drops,
    updown,
)
from skidmc.analysis.hazard import drop_height_probability
from skidmc.analysis.planning import SequentialPlan, next_drop  # noqa: F401
from skidmc.analysis.posterior import physics_prior, probit_posterior  # noqa: F401
from skidmc.analysis.rare_events import rare_event_probability
from skidmc.analysis.sensitivity import (
    grow_until_stable,
    morris_screening,
    sobol_convergence,
    sobol_indices,
    sobol_stable,
)

try:
    import tomllib
except ModuleNotFoundError:  # Python 3.10: the same parser, packaged as tomli
    import tomli as tomllib

__all__ = [
    "EXPERIMENTS",
    "compare_h50",
    "drop_height_probability",
    "fit_lognormal",
    "fit_probit",
    "get_experiment",
    "go_curve",
    "grow_until_stable",
    "morris_screening",
    "open_ensemble",
    "rare_event_probability",
    "score_drops",
    "sobol_convergence",
    "sobol_indices",
    "sobol_stable",
    "updown",
]


def open_ensemble(path: str | os.PathLike):
    """An ensemble file as an xarray Dataset in memory, unfinished samples masked.

    The file is verified first (every variable read once: HDF5's checksums), then loaded into
    memory and closed: the Dataset does not hold the file open, so a run may continue it
    (``skidmc run --resume``) while the Dataset is in use; an analysis of a large file pays its
    memory (about the file's size) for that.

    Parameters
    ----------
    path : path
        A result file of ``skidmc run``.

    Returns
    -------
    xarray.Dataset
        The file's variables and attributes, with:

        - every per-sample variable (inputs and outputs) masked where ``done`` is 0 (samples
          not computed yet, or a chunk interrupted before its done flags): NaN for numbers
          (``evaluations`` becomes float then; a complete run keeps its integers), ``""`` for
          text; ``done`` itself as bool;
        - ``attrs["unfinished"]``: the number of such samples (0 for a complete run);
        - ``attrs["study"]``: the study file's text parsed back (a dict, as TOML reads it),
          ``attrs["solver"]``: ``{"rtol", "tier", "h_min", "h_max"}``, ``attrs["design"]``:
          ``{"method", "n", "seed", "keys", "second_order", "n_epistemic", "kinds"}`` (besides the
          flat attributes the
          file stores: ``solver_rtol``, ``seed``, ...). These three are dicts, which netCDF
          cannot store: drop them before ``Dataset.to_netcdf``.

    Raises
    ------
    skidmc.ensemble.storage.StorageError
        Not an HDF5 file, not a skidmc ensemble file, or damaged (``damaged=True``: truncated,
        or data failing their checksums).
    """
    import numpy as np
    import xarray as xr

    from skidmc.ensemble.storage import StorageError, inspect_file

    path = Path(path)
    if not path.is_file():
        raise StorageError(path, "does not exist (or is not a file)")
    info = inspect_file(path, verify=True)
    if not info["skidmc"]:
        raise StorageError(path, "is an HDF5 file but not a skidmc ensemble file (no "
                           "skidmc_format attribute or no done flags)")
    try:
        with xr.open_dataset(path, engine="h5netcdf") as ds:
            ds = ds.load()
    except (OSError, ValueError, KeyError) as exc:
        raise StorageError(path, f"is damaged: xarray cannot read it ({exc})",
                           damaged=True) from None

    done = ds["done"].values.astype(bool)
    masked = {}
    for name, var in ds.data_vars.items():
        if name == "done" or "sample" not in var.dims or done.all():
            continue
        keep = xr.DataArray(done, dims=("sample",))
        if var.dtype.kind in "OUS":
            masked[name] = var.where(keep, "")
        else:
            masked[name] = var.astype(float).where(keep)  # NaN where not done
        masked[name].attrs = var.attrs
    ds = ds.assign(masked)
    ds["done"] = ds["done"].astype(bool)

    attrs = ds.attrs
    text = str(attrs.get("study_text", ""))
    try:
        study = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise StorageError(path, f"is damaged: its study text is not valid TOML ({exc})",
                           damaged=True) from None

    def scalar(key):
        value = attrs.get(key)
        return value.item() if isinstance(value, np.generic) else value

    keys = attrs.get("design_keys", [])
    attrs["unfinished"] = int(np.count_nonzero(~done))
    attrs["study"] = study
    attrs["solver"] = {k: scalar(f"solver_{k}") for k in ("rtol", "tier", "h_min", "h_max")}
    attrs["design"] = {
        "method": scalar("design_method"), "n": scalar("design_n"), "seed": scalar("seed"),
        "keys": [str(k) for k in np.atleast_1d(keys)] if len(np.atleast_1d(keys)) else [],
        "second_order": bool(scalar("saltelli_second_order")),
        "n_epistemic": int(scalar("design_n_epistemic") or 0),
        "kinds": [str(k) for k in np.atleast_1d(attrs.get("design_kinds", []))],
    }
    n_epistemic = attrs["design"]["n_epistemic"]
    if n_epistemic:
        ds = _unnest(ds, n_epistemic)
    return ds


def _unnest(ds, n_epistemic: int):
    """Split the flat ``sample`` dim of a nested design into ``epistemic`` x ``sample``."""
    import numpy as np
    import xarray as xr

    n_aleatory = ds.sizes["sample"] // n_epistemic
    out = {}
    for name, var in ds.data_vars.items():
        if "sample" not in var.dims:
            out[name] = var
            continue
        axis = var.dims.index("sample")
        shape = var.shape[:axis] + (n_epistemic, n_aleatory) + var.shape[axis + 1:]
        dims = var.dims[:axis] + ("epistemic", "sample") + var.dims[axis + 1:]
        out[name] = xr.DataArray(var.values.reshape(shape), dims=dims, attrs=var.attrs)
    coords = {k: v for k, v in ds.coords.items() if "sample" not in v.dims}
    coords.update(epistemic=np.arange(n_epistemic), sample=np.arange(n_aleatory))
    return xr.Dataset(out, coords=coords, attrs=ds.attrs)
