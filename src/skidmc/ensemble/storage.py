"""Ensemble results as one self-describing netCDF-4/HDF5 file per study, written chunk by chunk.

The file is written with h5netcdf and follows xarray's conventions, so ``xarray.open_dataset(path)``
reads it without skidmc. Layout (``scene`` only for studies with ``[[scenes]]``)::

    dimensions  sample (, scene)
    coordinates sample [1], scene (names)
    inputs      every numeric scene key, e.g. "he.density" (scene, sample) [kg/m^3]; every other
                sampled quantity (kinetics.rate_at_reference); configuration (scene)
    outputs     critical_height [m], status, evaluations [1], flags, failure_reason
    bookkeeping done (sample): 1 once the sample's results are written
    attributes  skidmc version, study name/text/sha256/file, seed, design, solver settings,
                created/completed timestamps, history (one line per run)

Crash safety. A kill -9 must not lose a finished chunk nor corrupt the file, so: the file skeleton
is built under a temporary name and renamed into place; every variable is contiguous and
allocated at creation (HDF5 early allocation), so writing a chunk changes raw data only, never
the file's metadata; strings are fixed-width (char arrays that xarray decodes to ``str``), not
variable-length strings whose heap would be metadata; and the ``done`` flags of a chunk are
written and flushed only after its data were flushed. A chunk interrupted half-way has no done
flags and is simply computed again on ``--resume``.
"""

from __future__ import annotations

import dataclasses
import datetime
import os
from collections.abc import Mapping
from pathlib import Path

import h5netcdf
import h5py
import numpy as np

from skidmc.ensemble.study import EXTRA_KEYS, RATE_AT_REFERENCE, Study
from skidmc.errors import SkidmcError
from skidmc.scene import DESCRIPTIONS, NUMERIC_KEYS, SI_UNITS

__all__ = [
    "FORMAT",
    "EnsembleFile",
    "StorageError",
    "VariableSpec",
    "default_path",
    "ensemble_variables",
    "inspect_file",
    "timestamp",
]

#: Value of the ``skidmc_format`` attribute that marks an ensemble file (and its version).
FORMAT = "skidmc-ensemble 1"

#: Values of ``status``.
STATUSES = ("ok", "censored_above", "censored_below", "failed")


class StorageError(SkidmcError):
    """A result file that cannot be written or continued: foreign, unfinished, another study's.

    Parameters
    ----------
    path : str
        The file.
    reason : str
        What is wrong and what to do about it.
    """

    def __init__(self, path: str | os.PathLike, reason: str) -> None:
        self.path = str(path)
        self.reason = reason
        super().__init__(f"{self.path}: {reason}")

    def __reduce__(self):
        return (type(self), (self.path, self.reason))


@dataclasses.dataclass(frozen=True)
class VariableSpec:
    """One per-sample variable of the ensemble file.

    Attributes
    ----------
    name : str
    dtype : str
        ``"f8"``, ``"i4"`` or ``"str"`` (fixed width, UTF-8).
    units : str
        ``units`` attribute (``"1"`` for numbers without units, ``"-"`` for text).
    long_name : str
    width : int
        Bytes per string (``"str"`` only); longer text is cut at a character boundary.
    attrs : dict
        More attributes.
    """

    name: str
    dtype: str
    units: str
    long_name: str
    width: int = 0
    attrs: Mapping = dataclasses.field(default_factory=dict)


#: The outputs, in file order.
OUTPUTS: tuple[VariableSpec, ...] = (
    VariableSpec("critical_height", "f8", "m", "critical drop height H_c", attrs={
        "comment": "for censored samples the search bound that was hit (see status); NaN for "
                   "failed samples"}),
    VariableSpec("status", "str", "-", "sample status", width=16, attrs={
        "flag_meanings": " ".join(STATUSES),
        "comment": "ok; censored_above: no event up to solver h_max; censored_below: event at "
                   "solver h_min; failed: see failure_reason; empty: not evaluated yet"}),
    VariableSpec("evaluations", "i4", "1", "number of impact simulations used"),
    VariableSpec("flags", "str", "-", "solver flags (comma separated)", width=64),
    VariableSpec("failure_reason", "str", "-", "why the sample failed (exception type and "
                 "message)", width=256),
)


def ensemble_variables(study: Study) -> tuple[VariableSpec, ...]:
    """Per-sample variables of a study's file: every numeric scene key, extras, outputs."""
    out = [VariableSpec(k, "f8", SI_UNITS[k], DESCRIPTIONS[k]) for k in NUMERIC_KEYS]
    for key, (unit, long_name) in EXTRA_KEYS.items():
        if any(key in sc.uncertain for sc in study.scenes):
            attrs = {}
            if key == RATE_AT_REFERENCE:
                attrs = {"reference_temperature": np.array(
                    [sc.uncertain[key].reference_temperature if key in sc.uncertain else np.nan
                     for sc in study.scenes]), "reference_temperature_units": "K"}
            out.append(VariableSpec(key, "f8", unit, long_name, attrs=attrs))
    return (*out, *OUTPUTS)


def default_path(study: Study) -> Path:
    """``results/<study name>/ensemble.h5`` (relative to the working directory)."""
    return Path("results") / study.name / "ensemble.h5"


def timestamp() -> str:
    """Now, UTC, ISO 8601 to the second (for attributes and history lines)."""
    return datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds")


def _version() -> str:
    from skidmc import __version__

    return __version__


def _encode(values, width: int) -> np.ndarray:
    """Text -> fixed-width UTF-8 bytes viewed as chars, shape (..., width)."""
    values = np.asarray(values, dtype=object)
    flat = []
    for text in values.ravel():
        raw = str(text).encode("utf-8")
        if len(raw) > width:  # cut at a character boundary, never inside a UTF-8 sequence
            raw = raw[:width].decode("utf-8", errors="ignore").encode("utf-8")
        flat.append(raw)
    return np.array(flat, dtype=f"S{width}").reshape(values.shape + (1,)).view("S1")


def _early() -> h5py.h5p.PropDCID:
    """Dataset creation properties allocating all storage at creation (crash safety)."""
    dcpl = h5py.h5p.create(h5py.h5p.DATASET_CREATE)
    dcpl.set_alloc_time(h5py.h5d.ALLOC_TIME_EARLY)
    return dcpl


def _open(path: Path, mode: str) -> h5py.File:
    # Plain h5py once the file exists: the netCDF structure is fixed at creation, and from then
    # on only raw data and attributes change (h5py is also quicker per write than h5netcdf).
    try:
        return h5py.File(path, mode)
    except BlockingIOError:
        raise StorageError(path, "is open in another process (a run still going?); wait for it "
                           "or stop it first") from None
    except OSError as exc:
        if "lock" in str(exc):
            raise StorageError(path, "is open in another process (a run still going?): "
                               f"{exc}") from None
        raise StorageError(path, f"cannot open as HDF5: {exc}") from None


def inspect_file(path: str | os.PathLike) -> dict:
    """What an existing file is, without changing it.

    Returns
    -------
    dict
        ``skidmc`` (bool: an ensemble file), ``complete`` (bool), ``done``/``n_rows`` (samples
        written / in the design), ``study_name``, ``study_sha256``, ``history``.

    Raises
    ------
    StorageError
        Not an HDF5 file, or it cannot be opened.
    """
    path = Path(path)
    if not h5py.is_hdf5(path):
        raise StorageError(path, "exists but is not an HDF5 file: not a skidmc result; "
                           "refusing to overwrite it (choose another --out)")
    with _open(path, "r") as f:
        attrs = dict(f.attrs)
        if attrs.get("skidmc_format") != FORMAT or "done" not in f:
            return {"skidmc": False, "format": attrs.get("skidmc_format")}
        done = f["done"][:]
    return {
        "skidmc": True,
        "complete": bool(attrs.get("complete", 0)),
        "done": int(np.count_nonzero(done)),
        "n_rows": int(done.shape[0]),
        "study_name": attrs.get("study_name"),
        "study_sha256": attrs.get("study_sha256"),
        "history": attrs.get("history", ""),
    }


class EnsembleFile:
    """An ensemble file open for writing (use :meth:`create` or :meth:`resume`).

    Attributes
    ----------
    path : Path
    n_rows : int
        Samples per scene.
    variables : tuple of VariableSpec
    """

    def __init__(self, path: Path, f: h5py.File, study: Study) -> None:
        self.path = path
        self._f = f
        self.study = study
        self.variables = ensemble_variables(study)
        self.n_rows = int(f["done"].shape[0])
        self._multi = study.scene_dimension

    # -- opening

    @classmethod
    def create(cls, path: str | os.PathLike, study: Study, *, attrs: Mapping | None = None,
               history: str = "") -> EnsembleFile:
        """Create the file of a study's run (all variables allocated, nothing evaluated yet).

        Parameters
        ----------
        path : path
            Target file; must not exist (see :meth:`resume` and :func:`inspect_file`).
        study : Study
        attrs : mapping, optional
            More global attributes (design details).
        history : str
            First line of the ``history`` attribute.

        Returns
        -------
        EnsembleFile
            Open for writing.
        """
        path = Path(path)
        if path.exists():
            raise StorageError(path, "exists; refusing to overwrite it")
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_name(path.name + ".tmp")  # ours by name: a stale one is a killed create
        with h5netcdf.File(tmp, "w") as f:
            _write_skeleton(f, study, {**_global_attrs(study, history), **dict(attrs or {})})
        os.replace(tmp, path)
        return cls(path, _open(path, "r+"), study)

    @classmethod
    def resume(cls, path: str | os.PathLike, study: Study, *, history: str = "") -> EnsembleFile:
        """Open an existing file of the same study to finish it.

        Raises
        ------
        StorageError
            Not a skidmc ensemble file, another study (hash), or another sample count.
        """
        path = Path(path)
        info = inspect_file(path)
        if not info["skidmc"]:
            raise StorageError(path, "is an HDF5 file but not a skidmc ensemble; refusing to "
                               "touch it (choose another --out)")
        if info["study_sha256"] != study.sha256:
            raise StorageError(
                path, f"was written by another study or another version of it (study "
                f"{info['study_name']!r}, sha256 {info['study_sha256'][:12]}..., this study "
                f"{study.sha256[:12]}...); resuming would mix two studies: choose another --out")
        if info["n_rows"] != study.n_rows:
            raise StorageError(
                path, f"holds {info['n_rows']} samples per scene, this run asks for "
                f"{study.n_rows} (a different --n?); resume with the same n or use another --out")
        f = _open(path, "r+")
        out = cls(path, f, study)
        if history:
            out.add_history(history)
        return out

    # -- writing

    @property
    def complete(self) -> bool:
        """Whether the file is marked complete."""
        return bool(self._f.attrs.get("complete", 0))

    def done(self) -> np.ndarray:
        """Boolean mask (n_rows,): samples whose results are written."""
        return self._f["done"][:].astype(bool)

    def write_chunk(self, start: int, stop: int, columns: Mapping[str, np.ndarray]) -> None:
        """Write samples ``start:stop`` of every variable, then mark them done.

        Parameters
        ----------
        start, stop : int
            Sample range.
        columns : mapping
            Variable name -> values of shape (n_scenes, stop - start) (or (stop - start,) for a
            single-scene study); every variable of :attr:`variables` must be given.
        """
        f = self._f
        sl = (slice(None), slice(start, stop)) if self._multi else (slice(start, stop),)
        for spec in self.variables:
            values = np.asarray(columns[spec.name])
            if spec.dtype == "str":
                f[spec.name][(*sl, slice(None))] = _encode(values, spec.width)
            else:
                f[spec.name][sl] = values.astype(spec.dtype, copy=False)
        f.flush()  # data on disk before the flags that vouch for them
        f["done"][start:stop] = 1
        f.flush()

    def add_history(self, line: str) -> None:
        """Append a line to the ``history`` attribute (and flush)."""
        old = self._f.attrs.get("history", "")
        self._f.attrs["history"] = f"{old}\n{line}" if old else line
        self._f.flush()

    def mark_complete(self) -> None:
        """Record that every sample is written (``complete = 1``, ``completed`` timestamp)."""
        self._f.attrs["complete"] = np.int8(1)
        self._f.attrs["completed"] = timestamp()
        self._f.flush()

    def close(self) -> None:
        """Flush and close."""
        if self._f is not None:
            self._f.close()
            self._f = None

    def __enter__(self) -> EnsembleFile:  # noqa: PYI034 - not subclassed
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def _write_skeleton(f: h5netcdf.File, study: Study, attrs: Mapping) -> None:
    """Dimensions, coordinates, attributes and every variable, allocated, nothing evaluated."""
    n = study.n_rows
    f.dimensions = {"sample": n, **({"scene": len(study.scenes)} if study.scene_dimension
                                    else {})}
    lead = ("scene", "sample") if study.scene_dimension else ("sample",)
    f.attrs.update(attrs)
    sample = f.create_variable("sample", ("sample",), dtype="i8", dcpl=_early())
    sample.attrs.update({"units": "1", "long_name": "sample index in the design"})
    step = 1 << 16  # in slices: memory flat in n
    for i in range(0, n, step):
        sample[i:min(n, i + step)] = np.arange(i, min(n, i + step))
    if study.scene_dimension:
        scene = f.create_variable("scene", ("scene",), dtype=h5py.string_dtype())
        scene[:] = np.array(study.scene_names, dtype=object)
        scene.attrs.update({"units": "-", "long_name": "scene name"})
    config = f.create_variable("configuration", lead[:-1], dtype=h5py.string_dtype())
    configs = [sc.scene.configuration for sc in study.scenes]
    config[...] = np.array(configs, dtype=object) if study.scene_dimension else configs[0]
    config.attrs.update({"units": SI_UNITS["configuration"],
                         "long_name": DESCRIPTIONS["configuration"]})
    for spec in ensemble_variables(study):
        if spec.dtype == "str":  # fixed-width chars, decoded to str by xarray (_Encoding)
            char_dim = f"strlen{spec.width}"
            if char_dim not in f.dimensions:
                f.dimensions[char_dim] = spec.width
            v = f.create_variable(spec.name, (*lead, char_dim), dtype="S1", dcpl=_early())
            v.attrs["_Encoding"] = "utf-8"
        elif spec.dtype == "f8":  # NaN until written
            v = f.create_variable(spec.name, lead, dtype="f8", fillvalue=np.nan, dcpl=_early())
        else:
            v = f.create_variable(spec.name, lead, dtype=spec.dtype, dcpl=_early())
        v.attrs.update({"units": spec.units, "long_name": spec.long_name, **dict(spec.attrs)})
    done = f.create_variable("done", ("sample",), dtype="u1", dcpl=_early())
    done.attrs.update({"units": "1",
                       "long_name": "1 once the sample's results are written (resume bookkeeping)"})


def _global_attrs(study: Study, history: str) -> dict:
    """Provenance: version, the study itself, design and solver settings, timestamps."""
    d, s = study.design, study.solver
    return {
        "title": f"skidmc ensemble: {study.name}",
        "skidmc_format": FORMAT,
        "skidmc_version": _version(),
        "study_name": study.name,
        "study_description": study.description,
        "study_file": str(Path(study.file).resolve()) if study.file != "<string>" else "<string>",
        "study_sha256": study.sha256,
        "study_text": study.text,
        "design_method": d.method,
        "design_n": np.int64(d.n),
        "design_keys": list(study.keys),
        "seed": np.int64(d.seed),
        "saltelli_second_order": np.int8(d.second_order),
        "solver_rtol": s.rtol,
        "solver_tier": s.tier,
        "solver_h_min": s.h_min,
        "solver_h_max": s.h_max,
        "created": timestamp(),
        "completed": "",
        "complete": np.int8(0),
        "history": history,
    }
