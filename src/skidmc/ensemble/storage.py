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
is built under a temporary name and renamed into place; every variable is allocated at creation
(HDF5 early allocation), so writing a chunk changes raw data only, never the file's metadata;
strings are fixed-width (char arrays that xarray decodes to ``str``), not variable-length strings
whose heap would be metadata; and the ``done`` flags of a chunk are written and flushed only after
its data were flushed. A chunk interrupted half-way has no done flags and is simply computed again
on ``--resume``.

Checksums. Every variable is chunked (HDF5 chunks, not the runner's) with HDF5's Fletcher-32
filter, so damage anywhere in the data (a truncated copy, bytes overwritten in the middle of the
file) is detected when the file is read back: :func:`verify_file` reads every variable once, and
resuming or reporting a complete file up to date does so first. Fletcher-32 keeps the two rules
above: it does not change a chunk's stored size (data + 4 bytes), so HDF5 rewrites a chunk in
place at the address allocated at creation and the chunk index never changes after creation
(tests/test_storage.py checks that writing changes no byte outside the chunks' data). What it adds
is that a chunk is one checksummed unit: a write torn half-way would make the whole HDF5 chunk
unreadable, samples of earlier runner chunks that share it included, where contiguous storage
only ever lost not-yet-done samples. Linux copies a write into the page cache a page at a time and
stops a killed process's write only between pages, so no HDF5 chunk is larger than one 4096-byte
page (:data:`CHUNK_BYTES` of data + the checksum) and every chunk starts on a page boundary (HDF5
alignment at creation): a chunk is then written whole or not at all by a killed process. (A power
cut or a kernel crash can still tear a page; the checksum then reports the file as damaged instead
of letting bad numbers through, and ``skidmc run --force`` recomputes it.)
"""

from __future__ import annotations

import dataclasses
import datetime
import enum
import errno
import math
import os
from collections.abc import Mapping
from pathlib import Path

import h5netcdf
import h5py
import numpy as np

try:
    import tomllib
except ModuleNotFoundError:  # Python 3.10: the same parser, packaged as tomli
    import tomli as tomllib

from skidmc.ensemble.study import EXTRA_KEYS, RATE_AT_REFERENCE, Study
from skidmc.errors import SkidmcError
from skidmc.scene import DESCRIPTIONS, NUMERIC_KEYS, SI_UNITS

__all__ = [
    "CHUNK_BYTES",
    "EVALUATIONS_FORMAT",
    "FORMAT",
    "FORMATS",
    "PAGE_BYTES",
    "EnsembleAttrs",
    "EnsembleFile",
    "EvaluationLog",
    "LoggedCall",
    "SceneSummary",
    "compact_file",
    "Status",
    "StorageError",
    "VariableSpec",
    "default_path",
    "ensemble_variables",
    "flag_counts",
    "inspect_file",
    "open_ensemble",
    "summarize_file",
    "timestamp",
    "verify_file",
]

#: Value of the ``skidmc_format`` attribute that marks an ensemble file (and its version).
#: Version 2: a complete file is compacted (:func:`compact_file`); version 1 files (never
#: compacted) are still read and resumed.
FORMAT = "skidmc-ensemble 2"

#: Every ensemble format this module reads.
FORMATS = ("skidmc-ensemble 1", FORMAT)

#: Samples per HDF5 chunk of a compacted file (compressed chunks, read whole).
COMPACT_CHUNK = 1 << 15

#: Values of ``status``.
STATUSES = ("ok", "censored_above", "censored_below", "failed")

#: Page size [bytes] that no HDF5 chunk crosses (see the module docstring, "Checksums").
PAGE_BYTES = 4096

#: Largest HDF5 chunk of a per-sample variable [bytes of data]: with its 4-byte Fletcher-32
#: checksum it fills at most one page.
CHUNK_BYTES = PAGE_BYTES - 4

#: Samples read at once by :func:`verify_file` (bounds its memory: a 256-byte text variable of
#: 5 scenes is read 80 MiB at a time).
VERIFY_SAMPLES = 1 << 16


class StorageError(SkidmcError):
    """A result file that cannot be written or continued: foreign, unfinished, another study's,
    damaged, or a place where no file can be created.

    Parameters
    ----------
    path : str
        The file.
    reason : str
        What is wrong and what to do about it.
    damaged : bool
        The file is (or may be) a skidmc result that cannot be read back: truncated, or its data
        fail their checksums (``skidmc run --force`` replaces it).
    """

    def __init__(self, path: str | os.PathLike, reason: str, damaged: bool = False) -> None:
        self.path = str(path)
        self.reason = reason
        self.damaged = damaged
        super().__init__(f"{self.path}: {reason}")

    def __reduce__(self):
        return (type(self), (self.path, self.reason, self.damaged))


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
    # 128: the model's validity flags that can occur together take up to ~60 characters, the
    # target's regime flag (temperature_target, the longest) 19 more, rtol_unmet and
    # implausible_input 29 more: 108 (tests/test_extremes.py checks each combination; files
    # written with 64 keep their width: EnsembleFile.write_chunk writes to the file's own width)
    VariableSpec("flags", "str", "-", "solver flags (comma separated)", width=128),
    VariableSpec("failure_reason", "str", "-", "why the sample failed (exception type and "
                 "message)", width=256),
)


def ensemble_variables(study: Study) -> tuple[VariableSpec, ...]:
    """Per-sample variables of a study's file: every numeric scene key, extras, outputs."""
    out = [VariableSpec(k, "f8", SI_UNITS[k], DESCRIPTIONS[k]) for k in NUMERIC_KEYS]
    for key, (unit, long_name) in EXTRA_KEYS.items():
        dists = [sc.uncertain.get(key) or sc.factors.get(key) for sc in study.scenes]
        if any(dists):
            attrs = {}
            if key == RATE_AT_REFERENCE:
                attrs = {"reference_temperature": np.array(
                    [d.reference_temperature if d else np.nan for d in dists]),
                    "reference_temperature_units": "K"}
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


def _chunk_shape(lead: tuple, n: int, sample_bytes: int, width: int = 0) -> tuple:
    """HDF5 chunk of a per-sample variable: one scene, as many samples as fit in
    :data:`CHUNK_BYTES` (at most n), the whole string."""
    k = max(1, min(n, CHUNK_BYTES // sample_bytes))
    return (*(1,) * (len(lead) - 1), k, *((width,) if width else ()))


_DAMAGED_HINT = ("if it is a skidmc result, recompute it with `skidmc run --force` (or restore "
                 "a copy); the file is left as it is")


def _open(path: Path, mode: str) -> h5py.File:
    # Plain h5py once the file exists: the netCDF structure is fixed at creation, and from then
    # on only raw data and attributes change (h5py is also quicker per write than h5netcdf).
    try:
        return h5py.File(path, mode)
    except OSError as exc:
        text = str(exc)
        if isinstance(exc, BlockingIOError) or exc.errno in (errno.EAGAIN, errno.EWOULDBLOCK) \
                or "unable to lock file" in text.lower():
            raise StorageError(path, "is open in another process (a run still going?); wait "
                               "for it or stop it first") from None
        if isinstance(exc, PermissionError) or exc.errno == errno.EACCES:
            access = "writing" if mode != "r" else "reading"
            raise StorageError(path, f"cannot be opened for {access}: permission denied") \
                from None
        if "truncated file" in text:
            raise StorageError(path, f"is damaged: the file is truncated ({text}); "
                               f"{_DAMAGED_HINT}", damaged=True) from None
        raise StorageError(path, f"is damaged or not a valid HDF5 file ({text}); {_DAMAGED_HINT}",
                           damaged=True) from None


def _read_all(name: str, ds: h5py.Dataset, path: Path, axis: int | None) -> None:
    """Read a dataset once (HDF5 checks every chunk's Fletcher-32 checksum as it reads it), in
    slabs of :data:`VERIFY_SAMPLES` along its sample axis `axis` (None: at once)."""
    n = 1 if axis is None else ds.shape[axis]
    step = VERIFY_SAMPLES
    if axis is not None and ds.chunks:
        step = max(ds.chunks[axis], step // ds.chunks[axis] * ds.chunks[axis])
    for start in range(0, n, step):
        stop = min(n, start + step)
        sl = [slice(None)] * len(ds.shape or ())
        if axis is not None:
            sl[axis] = slice(start, stop)
        try:
            ds[tuple(sl)]
        except (OSError, ValueError, RuntimeError) as exc:
            where = f" (samples {start}-{stop - 1})" if axis is not None else ""
            raise StorageError(path, f"is damaged: variable {name!r} cannot be read back{where}:"
                               f" a checksum mismatch or corrupt data ({exc}); {_DAMAGED_HINT}",
                               damaged=True) from None


def verify_file(path: str | os.PathLike) -> None:
    """Read every variable of a file once, so that HDF5 checks each chunk's checksum.

    Parameters
    ----------
    path : path
        An ensemble file (files written before checksums were added are read all the same: their
        data have no checksum, but their structure is still checked).

    Raises
    ------
    StorageError
        With ``damaged=True``: the file cannot be opened (truncated, corrupt metadata) or a
        variable cannot be read back (a checksum mismatch).
    """
    path = Path(path)
    with _open(path, "r") as f:
        datasets: list[tuple[str, h5py.Dataset]] = []
        try:
            f.visititems(lambda name, obj: datasets.append((name, obj))
                         if isinstance(obj, h5py.Dataset) else None)
        except (OSError, KeyError, RuntimeError, ValueError) as exc:
            raise StorageError(path, f"is damaged: its structure cannot be read ({exc}); "
                               f"{_DAMAGED_HINT}", damaged=True) from None
        n_rows = f["done"].shape[0] if isinstance(f.get("done"), h5py.Dataset) else None
        for name, ds in datasets:
            shape = ds.shape or ()
            # The sample axis: the last but the text width for text, else the last.
            axis = len(shape) - (2 if ds.dtype == "S1" else 1)
            _read_all(name, ds, path, axis if axis >= 0 and shape[axis] == n_rows else None)


def inspect_file(path: str | os.PathLike, *, verify: bool = False) -> dict:
    """What an existing file is, without changing it.

    Parameters
    ----------
    path : path
    verify : bool
        Also read every variable once (:func:`verify_file`: checksums) when it is an ensemble
        file.

    Returns
    -------
    dict
        ``skidmc`` (bool: an ensemble file), ``complete`` (bool), ``done``/``n_rows`` (samples
        written / in the design), ``study_name``, ``study_sha256``, ``history``, ``completed``
        (timestamp or "").

    Raises
    ------
    StorageError
        Not an HDF5 file, it cannot be opened, or (``damaged=True``) it is damaged.
    """
    path = Path(path)
    try:
        hdf5 = h5py.is_hdf5(path)
    except OSError as exc:
        raise StorageError(path, f"cannot be read: {exc.strerror or exc}") from None
    if not hdf5:
        if path.stat().st_size == 0:
            raise StorageError(path, "is an empty file (a truncated result?); delete it, "
                               "replace it with `skidmc run --force` or choose another --out",
                               damaged=True)
        raise StorageError(path, "exists but is not an HDF5 file: not a skidmc result")
    with _open(path, "r") as f:
        try:
            attrs = dict(f.attrs)
            if attrs.get("skidmc_format") not in FORMATS or "done" not in f:
                return {"skidmc": False, "format": attrs.get("skidmc_format")}
            done = f["done"][:]
        except (OSError, KeyError, RuntimeError, ValueError) as exc:
            raise StorageError(path, f"is damaged: its attributes or done flags cannot be read "
                               f"({exc}); {_DAMAGED_HINT}", damaged=True) from None
    if verify:
        verify_file(path)
    return {
        "skidmc": True,
        "complete": bool(attrs.get("complete", 0)),
        "done": int(np.count_nonzero(done)),
        "n_rows": int(done.shape[0]),
        "study_name": attrs.get("study_name"),
        "study_sha256": attrs.get("study_sha256"),
        "history": attrs.get("history", ""),
        "completed": attrs.get("completed", ""),
        "compact": bool(attrs.get("compact", 0)),
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
        tmp = path.with_name(path.name + ".tmp")  # ours by name: a stale one is a killed create
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
            # Chunks of at least the smallest chunk's size start on a page boundary (module
            # docstring, "Checksums"): every HDF5 chunk then lies within one page.
            smallest = min(_chunk_bytes(study))
            with h5netcdf.File(tmp, "w", alignment_threshold=smallest,
                               alignment_interval=PAGE_BYTES) as f:
                _write_skeleton(f, study, {**_global_attrs(study, history),
                                           **dict(attrs or {})})
            os.replace(tmp, path)
        except BaseException as exc:  # also Ctrl-C: an interrupted create leaves no .tmp
            try:
                tmp.unlink(missing_ok=True)
            except OSError:  # nowhere to have made it (a path through a file)
                pass
            if not isinstance(exc, OSError):
                raise
            raise StorageError(path, f"cannot create the result file: {_os_reason(path, exc)}") \
                from None
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
        info = inspect_file(path, verify=True)
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
        if info["compact"]:
            raise StorageError(path, "is a complete, compacted result: nothing to resume "
                               "(skidmc run --force recomputes it)")
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
            if spec.dtype == "str":  # the file's own width (an older file's may be narrower)
                f[spec.name][(*sl, slice(None))] = _encode(values, f[spec.name].shape[-1])
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


def _os_reason(path: Path, exc: OSError) -> str:
    """Why a file cannot be created at `path`, in words naming the path that is in the way."""
    where = Path(exc.filename) if exc.filename else path
    if isinstance(exc, (FileExistsError, NotADirectoryError)) or exc.errno in (
            errno.EEXIST, errno.ENOTDIR):
        for parent in path.parents:  # the nearest existing ancestor that is not a folder
            if parent.exists() and not parent.is_dir():
                return f"{parent} is a file, not a folder"
    if isinstance(exc, PermissionError) or exc.errno in (errno.EACCES, errno.EPERM):
        return f"permission denied for {where}"
    if exc.errno == errno.EROFS:
        return f"{where} is on a read-only file system"
    if exc.errno == errno.ENOSPC:
        return f"no space left on the device of {where}"
    if isinstance(exc, FileNotFoundError):
        return f"{where} cannot be created (no such file or directory)"
    return f"{exc.strerror or exc} ({where})"


def _sample_bytes(spec: VariableSpec) -> int:
    return spec.width if spec.dtype == "str" else np.dtype(spec.dtype).itemsize


def estimated_bytes(study: Study) -> int:
    """Size [bytes] of a study's result file as created (every variable allocated at once):
    the per-sample bytes of every variable times the samples, without the small metadata."""
    n, lead = study.n_rows, len(study.scenes) if study.scene_dimension else 1
    per_sample = sum(_sample_bytes(spec) for spec in ensemble_variables(study))
    # sample, done, the per-scene variables; x 1.06: page alignment, checksums and metadata
    # (measured: paper-series1 at n = 4096 creates 441 MB against 418 MB of data)
    return int(1.06 * n * (8 + 1 + lead * per_sample))


def _chunk_bytes(study: Study) -> list[int]:
    """Stored size [bytes] of each chunked variable's HDF5 chunk (data + checksum)."""
    n = study.n_rows
    sizes = [min(n, CHUNK_BYTES // b) * b + 4 for b in (8, 1)]  # sample, done
    for spec in ensemble_variables(study):
        b = _sample_bytes(spec)
        sizes.append(max(1, min(n, CHUNK_BYTES // b)) * b + 4)
    return sizes


def _write_skeleton(f: h5netcdf.File, study: Study, attrs: Mapping) -> None:
    """Dimensions, coordinates, attributes and every variable, allocated, nothing evaluated."""
    n = study.n_rows
    f.dimensions = {"sample": n, **({"scene": len(study.scenes)} if study.scene_dimension
                                    else {})}
    lead = ("scene", "sample") if study.scene_dimension else ("sample",)
    f.attrs.update(attrs)
    lead_shape = (len(study.scenes), n) if study.scene_dimension else (n,)

    def chunked(spec_bytes: int, width: int = 0) -> dict:
        """Chunking, checksums and early allocation (a fresh property list each time)."""
        return {"chunks": _chunk_shape(lead_shape, n, spec_bytes, width), "fletcher32": True,
                "dcpl": _early()}

    sample = f.create_variable("sample", ("sample",), dtype="i8",
                               **{**chunked(8), "chunks": _chunk_shape((n,), n, 8)})
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
            v = f.create_variable(spec.name, (*lead, char_dim), dtype="S1",
                                  **chunked(spec.width, spec.width))
            v.attrs["_Encoding"] = "utf-8"
        elif spec.dtype == "f8":  # NaN until written
            v = f.create_variable(spec.name, lead, dtype="f8", fillvalue=np.nan,
                                  **chunked(8))
        else:
            v = f.create_variable(spec.name, lead, dtype=spec.dtype,
                                  **chunked(_sample_bytes(spec)))
        v.attrs.update({"units": spec.units, "long_name": spec.long_name, **dict(spec.attrs)})
    done = f.create_variable("done", ("sample",), dtype="u1",
                             **{**chunked(1), "chunks": _chunk_shape((n,), n, 1)})
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
        # Nested designs: row r is epistemic draw r // design_n, aleatory draw r % design_n.
        "design_n_epistemic": np.int64(d.n_epistemic),
        "design_kinds": [study.kind(k) for k in study.keys],
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


@dataclasses.dataclass(frozen=True)
class EnsembleAttrs:
    """The global attributes of an ensemble file, decoded (written by :func:`_global_attrs`).

    The one place that reads them back: numpy scalars become Python numbers, lists stored as
    arrays become tuples of str. :func:`open_ensemble` hands them on as
    ``attrs["design"]`` and ``attrs["solver"]`` (dicts, see there).

    Attributes
    ----------
    skidmc_format, skidmc_version : str
    study_name, study_sha256, study_file, study_text : str
    design_method : str
    design_n, design_n_epistemic, seed : int
    design_keys, design_kinds : tuple of str
        The design columns and how each is drawn (aleatory, epistemic).
    saltelli_second_order : bool
    solver_rtol, solver_h_min, solver_h_max : float
        [1], [m], [m].
    solver_tier : str
    complete : bool
    created, completed, history : str
    """

    skidmc_format: str
    skidmc_version: str
    study_name: str
    study_sha256: str
    study_file: str
    study_text: str
    design_method: str
    design_n: int
    design_n_epistemic: int
    seed: int
    design_keys: tuple[str, ...]
    design_kinds: tuple[str, ...]
    saltelli_second_order: bool
    solver_rtol: float
    solver_tier: str
    solver_h_min: float
    solver_h_max: float
    complete: bool
    created: str
    completed: str
    history: str

    @classmethod
    def read(cls, attrs: Mapping) -> EnsembleAttrs:
        """Decode a file's global attributes (missing ones: empty or zero)."""
        def scalar(key, default=None):
            value = attrs.get(key, default)
            if isinstance(value, np.ndarray) and value.size == 1:
                value = value.reshape(())[()]
            return value.item() if isinstance(value, np.generic) else value

        def words(key):
            value = attrs.get(key, [])
            return tuple(str(k) for k in np.atleast_1d(value)) if np.size(value) else ()

        return cls(
            skidmc_format=str(scalar("skidmc_format", "")),
            skidmc_version=str(scalar("skidmc_version", "")),
            study_name=str(scalar("study_name", "")),
            study_sha256=str(scalar("study_sha256", "")),
            study_file=str(scalar("study_file", "")),
            study_text=str(scalar("study_text", "")),
            design_method=str(scalar("design_method", "")),
            design_n=int(scalar("design_n", 0) or 0),
            design_n_epistemic=int(scalar("design_n_epistemic", 0) or 0),
            seed=int(scalar("seed", 0) or 0),
            design_keys=words("design_keys"), design_kinds=words("design_kinds"),
            saltelli_second_order=bool(scalar("saltelli_second_order", 0)),
            solver_rtol=float(scalar("solver_rtol", math.nan)),
            solver_tier=str(scalar("solver_tier", "")),
            solver_h_min=float(scalar("solver_h_min", math.nan)),
            solver_h_max=float(scalar("solver_h_max", math.nan)),
            complete=bool(scalar("complete", 0)),
            created=str(scalar("created", "")), completed=str(scalar("completed", "")),
            history=str(scalar("history", "")))

    @property
    def design(self) -> dict:
        """``{"method", "n", "seed", "keys", "second_order", "n_epistemic", "kinds"}``."""
        return {"method": self.design_method, "n": self.design_n, "seed": self.seed,
                "keys": list(self.design_keys), "second_order": self.saltelli_second_order,
                "n_epistemic": self.design_n_epistemic, "kinds": list(self.design_kinds)}

    @property
    def solver(self) -> dict:
        """``{"rtol", "tier", "h_min", "h_max"}`` ([1], -, [m], [m])."""
        return {"rtol": self.solver_rtol, "tier": self.solver_tier, "h_min": self.solver_h_min,
                "h_max": self.solver_h_max}


@dataclasses.dataclass(frozen=True)
class SceneSummary:
    """The critical heights of one scene of an ensemble file, in a few numbers.

    Quantiles are empirical (``numpy.quantile(..., method="inverted_cdf")``: always a sample's
    value) over the written samples that did not fail, censored ones at the bound they hit, so
    that a quantile falling among censored samples is that bound, marked by `median_bound` /
    `range_bound` (``">"`` above h_max, ``"<"`` below h_min, else ``""``).

    Attributes
    ----------
    scene : str
        Scene name (the study name for a single-scene study).
    samples, written : int
        Samples in the design, samples written so far.
    ok, censored_above, censored_below, failed : int
        Written samples by status.
    median, p05, p95 : float
        Median and 5 % / 95 % quantiles of the critical height [m] (NaN when no sample counts).
    median_bound : str
    range_bound : tuple of str
        Qualifiers of p05 and p95.
    flags : dict
        Flag -> written samples carrying it (the solver's validity flags, ``rtol_unmet``,
        ``implausible_input``; :func:`flag_counts`), most frequent first.
    """

    scene: str
    samples: int
    written: int
    ok: int
    censored_above: int
    censored_below: int
    failed: int
    median: float
    p05: float
    p95: float
    median_bound: str = ""
    range_bound: tuple[str, str] = ("", "")
    flags: dict = dataclasses.field(default_factory=dict)


def flag_counts(flags) -> dict[str, int]:
    """Flag -> how many of the samples carry it, most frequent first, from an array of
    comma-separated flag strings (the ``flags`` variable of an ensemble, any shape)."""
    from collections import Counter

    counts = Counter(flag for text in np.asarray(flags, dtype=object).ravel().tolist()
                     for flag in str(text).split(",") if flag)
    return dict(counts.most_common())


def _flag_words(raw: np.ndarray, attrs) -> np.ndarray:
    """Flags as comma-separated text from either layout: fixed-width chars (appendable) or
    indices into ``flag_meanings`` (compact; "none" is index 0)."""
    if raw.dtype == "S1":
        return _decode_chars(raw)
    meanings = str(attrs.get("flag_meanings", "")).split(" ")
    table = np.array(["" if i == 0 else m for i, m in enumerate(meanings)], dtype=object)
    return table[raw.astype(np.intp)]


def _decode_chars(chars: np.ndarray) -> np.ndarray:
    """Fixed-width char array (..., width) -> array of str."""
    width = chars.shape[-1]
    joined = np.ascontiguousarray(chars).view(f"S{width}")[..., 0]
    return np.char.decode(joined, "utf-8")


def _status_words(raw: np.ndarray) -> np.ndarray:
    """Status as words from either layout: fixed-width chars (appendable) or codes (compact)."""
    if raw.dtype == "S1":
        return _decode_chars(raw)
    return np.array([s.word for s in Status], dtype=object)[raw.astype(np.intp)]


def _table_attrs(values: np.ndarray, none: str) -> tuple[np.ndarray, dict]:
    """Text values -> (uint16 index, CF flag_values / flag_meanings of the distinct values);
    ``""`` is value 0, meaning `none`."""
    meanings = ["", *sorted(set(values.ravel().tolist()) - {""})]
    rank = {m: i for i, m in enumerate(meanings)}
    index = np.array([rank[v] for v in values.ravel().tolist()],
                     dtype=np.uint16).reshape(values.shape)
    return index, {"flag_values": np.arange(len(meanings), dtype=np.uint16),
                   "flag_meanings": " ".join(m.replace(" ", "_") or none for m in meanings)}


def compact_file(path: str | os.PathLike) -> None:
    """Rewrite a complete ensemble file compactly, in place (atomically: built aside, renamed).

    While a run writes, the file keeps the appendable layout of the module docstring (fixed-size
    page chunks rewritten in place, fixed-width text). Once complete it is never written again,
    so it is rewritten: ``status`` as :class:`Status` codes and ``flags`` as indices of their
    distinct combinations (both CF ``flag_values`` / ``flag_meanings``), ``failure_reason`` as
    an index (-1: none) into a ``failure_reasons`` table, every input that does not vary within
    a scene once per scene (attribute ``constant_along = "sample"``), and every variable in
    chunks of :data:`COMPACT_CHUNK` samples, compressed (HDF5's shuffle + gzip, which h5py,
    h5netcdf and netCDF read without plugins) and checksummed (Fletcher-32).
    :func:`open_ensemble` gives back the same Dataset as for the appendable layout.
    """
    path = Path(path)
    verify_file(path)
    tmp = path.with_name(path.name + ".compact")
    with _open(path, "r") as src:
        attrs = dict(src.attrs)
        if attrs.get("compact"):
            return
        multi = "scene" in src
        n = int(src["done"].shape[0])
        n_scenes = int(src["scene"].shape[0]) if multi else 0
        variables = {name: (obj[...], dict(obj.attrs)) for name, obj in src.items()
                     if isinstance(obj, h5py.Dataset) and not name.startswith("strlen")}
    lead = ("scene", "sample") if multi else ("sample",)
    inputs = {*NUMERIC_KEYS, *EXTRA_KEYS}

    def opts(shape) -> dict:
        if not shape or shape[-1] == 0:
            return {}
        chunks = (*(1,) * (len(shape) - 1), min(shape[-1], COMPACT_CHUNK))
        return {"chunks": chunks, "compression": "gzip", "shuffle": True, "fletcher32": True}

    clean = {k: v for k, v in attrs.items() if k not in ("_NCProperties",)}
    clean.update({"skidmc_format": FORMAT, "compact": np.int8(1)})
    with h5netcdf.File(tmp, "w") as f:
        f.dimensions = {"sample": n, **({"scene": n_scenes} if multi else {})}
        f.attrs.update(clean)
        for name, (data, vattrs) in variables.items():
            vattrs = {k: v for k, v in vattrs.items()
                      if k not in ("DIMENSION_LIST", "REFERENCE_LIST", "CLASS", "NAME",
                                   "_Netcdf4Dimid", "_Netcdf4Coordinates", "_Encoding",
                                   "_FillValue")}
            if name in ("sample", "done"):
                dims = ("sample",)
            elif name == "scene":
                dims = ("scene",)
            elif name == "configuration":
                dims = lead[:-1]
            else:
                dims = lead
            if data.dtype == "S1":  # fixed-width text of the appendable layout
                text = _decode_chars(data).astype(object)
                if name == "status":
                    data = Status.codes(text).reshape(text.shape)
                    vattrs.update(Status.flag_attrs())
                elif name == "failure_reason":
                    reasons = sorted(set(text.ravel().tolist()) - {""})
                    rank = {r: i for i, r in enumerate(reasons)}
                    data = np.array([rank.get(r, -1) for r in text.ravel().tolist()],
                                    dtype=np.int32).reshape(text.shape)
                    f.dimensions["reason"] = len(reasons)
                    table = f.create_variable("failure_reasons", ("reason",),
                                              dtype=h5py.string_dtype())
                    if reasons:
                        table[:] = np.array(reasons, dtype=object)
                    table.attrs.update({"units": "-", "long_name": "distinct failure reasons"})
                    vattrs["comment"] = "index into failure_reasons; -1: none"
                else:  # flags
                    data, flag = _table_attrs(text, "none")
                    vattrs.update(flag)
            elif name in inputs and data.ndim == len(lead) and n and np.array_equal(
                    data, np.broadcast_to(data[..., :1], data.shape), equal_nan=True):
                data = data[..., 0]
                dims = dims[:-1]
                vattrs["constant_along"] = "sample"
            if data.dtype.kind in "OU":
                v = f.create_variable(name, dims, dtype=h5py.string_dtype())
                v[...] = np.asarray(data, dtype=object)
            else:
                kw = opts(data.shape) if dims and dims[-1] == "sample" else {}
                fill = {"fillvalue": np.nan} if data.dtype.kind == "f" else {}
                v = f.create_variable(name, dims, dtype=data.dtype, data=data, **kw, **fill)
            v.attrs.update(vattrs)
    os.replace(tmp, path)


def _decode_compact(ds):
    """The Dataset of a compacted file as that of the appendable layout (words, text, inputs
    per sample)."""
    import xarray as xr

    out = {}
    words = np.array([s.word for s in Status], dtype=object)
    if "status" in ds and ds["status"].dtype.kind in "iu":
        out["status"] = ds["status"].copy(data=words[ds["status"].values.astype(np.intp)])
        for k in ("flag_values", "flag_meanings"):
            out["status"].attrs.pop(k, None)
        out["status"].attrs["flag_meanings"] = " ".join(STATUSES)
    if "flags" in ds and ds["flags"].dtype.kind in "iu":
        meanings = str(ds["flags"].attrs.get("flag_meanings", "")).split(" ")
        table = np.array(["" if i == 0 else m for i, m in enumerate(meanings)], dtype=object)
        out["flags"] = ds["flags"].copy(data=table[ds["flags"].values.astype(np.intp)])
        for k in ("flag_values", "flag_meanings"):
            out["flags"].attrs.pop(k, None)
    if "failure_reason" in ds and ds["failure_reason"].dtype.kind in "iu":
        reasons = np.array([*(str(r) for r in np.atleast_1d(ds["failure_reasons"].values)),
                            ""], dtype=object)
        out["failure_reason"] = ds["failure_reason"].copy(
            data=reasons[ds["failure_reason"].values.astype(np.intp)])
        out["failure_reason"].attrs.pop("comment", None)
    shape = ds["critical_height"]
    for name, var in ds.data_vars.items():
        if var.attrs.get("constant_along") == "sample":
            full = xr.DataArray(np.broadcast_to(var.values[..., None], shape.shape).copy(),
                                dims=shape.dims, attrs={k: v for k, v in var.attrs.items()
                                                        if k != "constant_along"})
            out[name] = full
    ds = ds.drop_vars([v for v in ("failure_reasons",) if v in ds])
    return ds.assign(out)


def summarize_file(path: str | os.PathLike) -> list[SceneSummary]:
    """Per-scene summary of an ensemble file's critical heights (see :class:`SceneSummary`).

    Raises
    ------
    StorageError
        The file cannot be read (``damaged=True`` when it is damaged).
    """
    path = Path(path)
    with _open(path, "r") as f:
        try:
            attrs = dict(f.attrs)
            done = f["done"][:].astype(bool)
            heights = np.atleast_2d(f["critical_height"][...])
            status = _status_words(f["status"][...])
            flags = (_flag_words(f["flags"][...], f["flags"].attrs) if "flags" in f
                     else np.full(status.shape, "", dtype=object))
            names = ([s.decode() if isinstance(s, bytes) else str(s) for s in f["scene"][...]]
                     if "scene" in f else [str(attrs.get("study_name", ""))])
        except (OSError, KeyError, RuntimeError, ValueError) as exc:
            raise StorageError(path, f"is damaged: its results cannot be read ({exc}); "
                               f"{_DAMAGED_HINT}", damaged=True) from None
    status = np.atleast_2d(status)
    flags = np.atleast_2d(flags)
    meta = EnsembleAttrs.read(attrs)
    h_min, h_max = meta.solver_h_min, meta.solver_h_max
    out = []
    for name, h, st, fl in zip(names, heights, status, flags):
        h, st, fl = h[done], st[done], fl[done]
        counts = {k: int(np.count_nonzero(st == k)) for k in STATUSES}
        usable = h[(st != "failed") & np.isfinite(h)]
        if usable.size:
            p05, median, p95 = np.quantile(usable, [0.05, 0.5, 0.95], method="inverted_cdf")
        else:
            p05 = median = p95 = math.nan

        def bound(q: float, counts=counts) -> str:
            if counts["censored_above"] and q >= h_max:
                return ">"
            if counts["censored_below"] and q <= h_min:
                return "<"
            return ""

        out.append(SceneSummary(
            scene=name, samples=int(done.size), written=int(done.sum()), ok=counts["ok"],
            censored_above=counts["censored_above"], censored_below=counts["censored_below"],
            failed=counts["failed"], median=float(median), p05=float(p05), p95=float(p95),
            median_bound=bound(median), range_bound=(bound(p05), bound(p95)),
            flags=flag_counts(fl)))
    return out


# --- reading -------------------------------------------------------------------------------------


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

    if ds.attrs.get("compact"):
        ds = _decode_compact(ds)
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

    meta = EnsembleAttrs.read(attrs)
    attrs["unfinished"] = int(np.count_nonzero(~done))
    attrs["study"] = study
    attrs["solver"] = meta.solver
    attrs["design"] = meta.design
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


# --- the solver calls of an adaptive study --------------------------------------------------------


#: Value of the ``skidmc_format`` attribute of an evaluation log (:class:`EvaluationLog`).
EVALUATIONS_FORMAT = "skidmc-evaluations 1"


class Status(enum.IntEnum):
    """A solver outcome as a small integer (CF ``flag_values`` / ``flag_meanings``)."""

    NOT_RUN = 0
    OK = 1
    CENSORED_ABOVE = 2
    CENSORED_BELOW = 3
    FAILED = 4

    @property
    def word(self) -> str:
        """The status word of ensemble files and :class:`~skidmc.ensemble.evaluate.BatchResult`
        (``""`` for NOT_RUN)."""
        return "" if self is Status.NOT_RUN else self.name.lower()

    @classmethod
    def codes(cls, words) -> np.ndarray:
        """Status words -> codes (uint8); anything unknown counts as FAILED."""
        table = {s.word: int(s) for s in cls}
        return np.array([table.get(str(w), int(cls.FAILED)) for w in np.ravel(words)],
                        dtype=np.uint8)

    @classmethod
    def flag_attrs(cls) -> dict:
        """CF attributes of a status variable."""
        return {"flag_values": np.array([int(s) for s in cls], dtype=np.uint8),
                "flag_meanings": " ".join(s.name.lower() for s in cls)}


@dataclasses.dataclass(frozen=True)
class LoggedCall:
    """One solver call kept by an :class:`EvaluationLog`.

    Attributes
    ----------
    digest : str
        sha256 of what was asked (inputs, base scene, solver options).
    critical_height : numpy.ndarray
        [m], one per scene of the call.
    status : numpy.ndarray
        Status words (``ok``, ``censored_above``, ``censored_below``, ``failed``).
    failure_reason : numpy.ndarray
        Text, ``""`` where none.
    """

    digest: str
    critical_height: np.ndarray
    status: np.ndarray
    failure_reason: np.ndarray


def library_versions() -> str:
    """``"numpy X, scipy Y"``: the libraries whose last bits a replayed log's inputs depend on
    (the estimator's draws and transforms; an EvaluationLog compares inputs by digest)."""
    import scipy

    return f"numpy {np.__version__}, scipy {scipy.__version__}"


def blas_kernels() -> str:
    """``"openblas Haswell"``: the BLAS libraries numpy and scipy run on and the kernels each
    chose for this CPU (threadpoolctl). A replayed log's inputs depend on them to the last bit
    as on the library versions: the hazard study's shipped log, computed with OpenBLAS's
    SkylakeX kernels, replays with them and not with the Haswell kernels OpenBLAS takes on an
    AMD EPYC (docs/rare-events.md). "" where no BLAS library is found."""
    import scipy.linalg  # noqa: F401 - scipy's BLAS, loaded as the estimators load it
    from threadpoolctl import threadpool_info

    return ", ".join(sorted({f"{d.get('internal_api', '?')} {d.get('architecture') or '?'}"
                             for d in threadpool_info() if d.get("user_api") == "blas"}))


class EvaluationLog:
    """The solver calls of an adaptive study, kept so that a run resumes and a report replays.

    An adaptive estimator (the hazard study's importance sampling) decides its next solver call
    from the previous ones, so its work is a sequence of calls rather than a design of samples.
    Given its seeds the sequence is deterministic: replaying the kept answers of calls 0..k-1
    brings the estimator to call k with the same state, and the numbers of a resumed run are
    those of an uninterrupted one. Each call is checked by the digest of what it asked (inputs,
    base scene, solver options): a call that asks something else (other code, another study)
    ends the replay there and is computed.

    Layout. While running, one small HDF5 file per call in ``<path>.calls/`` (written under a
    temporary name, then renamed: a kill -9 leaves whole calls or none). When the run completes
    the calls are gathered into one file at `path` (``complete = 1``; every variable
    compressed with shuffle + gzip and checksummed with Fletcher-32), and the folder removed.
    Inputs are not stored: the replay recomputes them from the study's seeds and checks them
    against the digest. Variables (dimension ``row``, all calls one after another): ``call``
    (the call of each row), ``critical_height`` [m], ``status`` (:class:`Status` codes, CF
    flags), ``failure_reason`` (index into the ``reasons`` table, -1 for none); per call
    ``digest``.

    Parameters
    ----------
    path : path
        The gathered file (``evaluations.h5``).
    attrs : mapping
        Global attributes (``study_sha256``, ``study_text``, ...); a log whose ``study_sha256``
        differs is not resumed.
    """

    def __init__(self, path: str | os.PathLike, attrs: Mapping) -> None:
        self.path = Path(path)
        self.folder = self.path.with_name(self.path.name + ".calls")
        self.attrs = dict(attrs)

    # -- reading

    def info(self) -> dict:
        """``{"exists", "complete", "study_sha256", "calls"}`` of what is on disk (and
        ``study_file`` once gathered)."""
        if self.path.is_file():
            with _open(self.path, "r") as f:
                return {"exists": True, "complete": bool(f.attrs.get("complete", 0)),
                        "study_sha256": str(f.attrs.get("study_sha256", "")),
                        "study_file": str(f.attrs.get("study_file", "")),
                        "libraries": str(f.attrs.get("libraries", "")),
                        "blas": str(f.attrs.get("blas", "")),
                        "calls": int(f["digest"].shape[0]) if "digest" in f else 0}
        calls = sorted(self.folder.glob("*.h5")) if self.folder.is_dir() else []
        return {"exists": bool(calls), "complete": False,
                "study_sha256": self._folder_sha(), "calls": len(calls)}

    def _folder_sha(self) -> str:
        marker = self.folder / "study_sha256"
        return marker.read_text().strip() if marker.is_file() else ""

    def load(self) -> list[LoggedCall]:
        """Every kept call, in order (verified: a damaged file raises StorageError)."""
        if self.path.is_file():
            verify_file(self.path)
            with _open(self.path, "r") as f:
                call = f["call"][:]
                heights, codes = f["critical_height"][:], f["status"][:]
                index = f["failure_reason"][:]
                reasons = np.array([r.decode("utf-8") for r in f["reasons"][:]] + [""],
                                   dtype=object)
                digests = [d.decode("ascii") for d in f["digest"][:]]
            words = np.array([Status(int(c)).word for c in codes], dtype=object)
            text = reasons[index]  # -1 -> the "" appended
            return [LoggedCall(d, heights[call == i], words[call == i], text[call == i])
                    for i, d in enumerate(digests)]
        out = []
        for i in range(len(list(self.folder.glob("*.h5"))) if self.folder.is_dir() else 0):
            part = self.folder / f"{i:06d}.h5"
            if not part.is_file():
                break
            try:
                verify_file(part)
                with _open(part, "r") as f:
                    out.append(LoggedCall(
                        str(f.attrs["digest"]), f["critical_height"][:],
                        np.array([Status(int(c)).word for c in f["status"][:]], dtype=object),
                        np.array([r.decode("utf-8") for r in f["failure_reason"][:]],
                                 dtype=object)))
            except (StorageError, KeyError, OSError):
                break  # a damaged call and those after it are computed again
        return out

    # -- writing

    def start(self, *, keep: bool) -> None:
        """Begin a run: keep the calls on disk (resume) or discard them (a new run)."""
        if not keep:
            self.discard()
        if self.path.is_file():  # a complete log being resumed: unpack it into calls
            calls = self.load()
            self.path.unlink()
            self.folder.mkdir(parents=True, exist_ok=True)
            (self.folder / "study_sha256").write_text(str(self.attrs.get("study_sha256", "")))
            for i, c in enumerate(calls):
                self._write_call(i, c)
        self.folder.mkdir(parents=True, exist_ok=True)
        (self.folder / "study_sha256").write_text(str(self.attrs.get("study_sha256", "")))

    def discard(self) -> None:
        """Remove the log (file and folder)."""
        self.path.unlink(missing_ok=True)
        if self.folder.is_dir():
            for p in self.folder.iterdir():
                p.unlink()
            self.folder.rmdir()

    def drop_from(self, index: int) -> None:
        """Forget calls `index`, `index` + 1, ... (they asked something else)."""
        for p in sorted(self.folder.glob("*.h5")):
            if int(p.stem) >= index:
                p.unlink()

    def append(self, index: int, call: LoggedCall) -> None:
        """Keep call number `index` (crash-safe: written aside, then renamed)."""
        self._write_call(index, call)

    def _write_call(self, index: int, call: LoggedCall) -> None:
        final = self.folder / f"{index:06d}.h5"
        tmp = final.with_suffix(".tmp")
        with h5py.File(tmp, "w") as f:
            f.attrs["digest"] = call.digest
            kw = {"fletcher32": True} if len(call.critical_height) else {}
            f.create_dataset("critical_height", data=np.asarray(call.critical_height, float), **kw)
            f.create_dataset("status", data=Status.codes(call.status), **kw)
            f.create_dataset("failure_reason", data=np.array(
                [str(r).encode("utf-8") for r in call.failure_reason], dtype=object),
                dtype=h5py.string_dtype("utf-8"))
        os.replace(tmp, final)

    def complete(self, calls: list[LoggedCall]) -> None:
        """Gather `calls` into the one file at `path` (atomically) and remove the folder."""
        reasons = sorted({str(r) for c in calls for r in c.failure_reason if r})
        rank = {r: i for i, r in enumerate(reasons)}
        call = np.concatenate([np.full(len(c.critical_height), i, dtype=np.int32)
                               for i, c in enumerate(calls)] or [np.zeros(0, np.int32)])
        heights = np.concatenate([np.asarray(c.critical_height, float) for c in calls]
                                 or [np.zeros(0)])
        codes = np.concatenate([Status.codes(c.status) for c in calls]
                               or [np.zeros(0, np.uint8)])
        index = np.concatenate([np.array([rank[str(r)] if r else -1 for r in c.failure_reason],
                                         dtype=np.int32) for c in calls]
                               or [np.zeros(0, np.int32)])
        tmp = self.path.with_name(self.path.name + ".tmp")
        self.path.parent.mkdir(parents=True, exist_ok=True)
        kw = {"shuffle": True, "compression": "gzip", "fletcher32": True} if len(call) else {}
        with h5py.File(tmp, "w") as f:
            f.attrs.update({"skidmc_format": EVALUATIONS_FORMAT,
                            "skidmc_version": _version(), "complete": np.int8(1),
                            "completed": timestamp(), "libraries": library_versions(),
                            "blas": blas_kernels(), **self.attrs})
            f.create_dataset("call", data=call, **kw)
            f.create_dataset("critical_height", data=heights, **kw).attrs["units"] = "m"
            f.create_dataset("status", data=codes, **kw).attrs.update(Status.flag_attrs())
            f.create_dataset("failure_reason", data=index, **kw).attrs["comment"] = (
                "index into reasons; -1: none")
            f.create_dataset("reasons", data=np.array([r.encode("utf-8") for r in reasons],
                                                      dtype=object),
                             dtype=h5py.string_dtype("utf-8"))
            f.create_dataset("digest", data=np.array([c.digest.encode("ascii") for c in calls],
                                                     dtype="S64"))
        os.replace(tmp, self.path)
        if self.folder.is_dir():
            for p in self.folder.iterdir():
                p.unlink()
            self.folder.rmdir()
