"""Analysis of ensemble results; :func:`open_ensemble` is the one way in.

Every analysis reads a result file through :func:`open_ensemble`, which checks what it opens and
hands back plain xarray. Nothing here imports matplotlib: plotting modules import it themselves.
"""

from __future__ import annotations

import os
from pathlib import Path

try:
    import tomllib
except ModuleNotFoundError:  # Python 3.10: the same parser, packaged as tomli
    import tomli as tomllib

__all__ = ["open_ensemble"]


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
          ``{"method", "n", "seed", "keys", "second_order"}`` (besides the flat attributes the
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
    }
    return ds
