"""The kinds of study, looked up by name: how a file names its kind, and what each kind does.

A kind is one module of :mod:`skidmc.workflows` plus one line of :data:`KINDS`. The module
provides (see :mod:`skidmc.workflows.ensemble`, the plain kind, for the reference):

``DESCRIPTION``
    One line for ``skidmc run --help`` and error messages.
``RUN_OPTIONS``
    The ``skidmc run`` options it honours (names of :class:`RunOptions` fields); any other
    option given is refused by :func:`check_options`, with the kind's reason from ``REFUSED``
    (option -> why, optional).
``REPORT_OPTIONS``
    Likewise for ``skidmc report`` (:class:`ReportOptions`).
``detect(doc) -> bool``
    Whether a study file without an explicit kind is of this kind (its TOML document); tried in
    the order of :data:`KINDS`, so the plain kind, last, takes what no other claims.
``load(path) -> study``
    The validated study (:class:`~skidmc.ensemble.study_model.StudyError` otherwise).
``default_out(study) -> Path``
    Its result file when ``--out`` is not given (``results/<name>/...``).
``run(study, options) -> Outcome``
    Runs it to its result file through :mod:`skidmc.ensemble.storage`.
``report(study_or_path, options) -> Outcome``
    Writes/prints its report.

How a file names its kind: ``[study] kind = "..."``; files without it keep working as they
always did, the kind inferred once, here (:func:`kind_of_document`): a ``[hazard]`` table is
a hazard study, a saltelli design with ``n_max`` a growing Sobol' study, anything else a plain
ensemble. A result file names its kind through the study text it stores.

The registry sits above the ensemble engine and the analysis and below the command line: it
maps names to runners, which orchestrate both layers below; the command line knows no kind.
"""

from __future__ import annotations

import dataclasses
import difflib
import importlib
import sys
from collections.abc import Callable
from pathlib import Path
from types import ModuleType

from skidmc.errors import SkidmcError

__all__ = [
    "KINDS",
    "OptionError",
    "Outcome",
    "ReportOptions",
    "RunOptions",
    "check_options",
    "get_kind",
    "kind_of_document",
    "kind_of_file",
    "kind_of_result",
    "load",
    "study_of_result",
]

#: Kind name -> the module that implements it, in the order their ``detect`` is tried.
KINDS: dict[str, str] = {
    "hazard": "skidmc.workflows.hazard",
    "calibration": "skidmc.workflows.calibration",
    "sobol": "skidmc.workflows.sobol",
    "ensemble": "skidmc.workflows.ensemble",
}


class OptionError(SkidmcError, ValueError):
    """A command-line option that the kind of study given does not take.

    ``str(err)`` names the option, its value, the kind and why.
    """

    def __init__(self, option: str, value: object, kind: str, reason: str) -> None:
        self.option, self.value, self.kind, self.reason = option, value, kind, reason
        shown = f"{option} {value}" if value not in ("", None) else option
        super().__init__(f"{shown}: not for a {kind} study: {reason}")


def _stderr(line: str) -> None:
    print(line, file=sys.stderr)


@dataclasses.dataclass(frozen=True)
class RunOptions:
    """What ``skidmc run`` asks of every kind (None/False: not given).

    Attributes
    ----------
    out : str or None
        Result file or folder (``--out``).
    n : int or None
        Samples per scene instead of the study's (``--n``).
    resume, force : bool
        Continue an interrupted run; recompute a complete one.
    workers : int or None
        Local worker processes (None: the CPUs available).
    scheduler : str or None
        ``local``, ``dask`` or a dask scheduler's address.
    quiet : bool
        No progress or summary lines.
    chunk_size : int or None
        Samples per runner chunk (hidden option, for tests).
    command : str or None
        The command line, recorded in result files.
    solver : callable or None
        Stand-in for the solver (tests).
    study_path : str or None
        The study file as given.
    log : callable
        Receives each progress or summary line (stderr by default).
    confirm : callable or None
        Told a new run's size (:class:`skidmc.ensemble.run.RunSize`) before its file is made;
        returns whether to go on (``skidmc run``: prints it, asks about a large run).
    yes : bool
        ``--yes``: a large run goes on without asking (the kinds that ask: ensemble, sobol).
    """

    out: str | None = None
    n: int | None = None
    resume: bool = False
    force: bool = False
    workers: int | None = None
    scheduler: str | None = None
    quiet: bool = False
    chunk_size: int | None = None
    command: str | None = None
    solver: Callable | None = None
    study_path: str | None = None
    log: Callable[[str], None] = _stderr
    confirm: Callable | None = None
    yes: bool = False

    #: The options a user gives (the rest are plumbing), with their command-line spelling.
    USER_OPTIONS = {"out": "--out", "n": "--n", "resume": "--resume", "force": "--force",
                    "workers": "--workers", "scheduler": "--scheduler",
                    "chunk_size": "--chunk-size", "yes": "--yes"}


@dataclasses.dataclass(frozen=True)
class ReportOptions:
    """What ``skidmc report`` asks of every kind.

    Attributes
    ----------
    out : str or None
        Folder of the report (default: beside the result).
    confidence : float or None
        Coverage of every interval and band; None: the kind's default (0.95).
    source : str
        The target as given (recorded in the report).
    """

    out: str | None = None
    confidence: float | None = None
    source: str = ""

    USER_OPTIONS = {"out": "--out", "confidence": "--confidence"}


@dataclasses.dataclass(frozen=True)
class Outcome:
    """The end of a run or report: exit status, lines for stderr (`lines`), for stdout
    (`printed`), then the path printed last on stdout."""

    status: int
    path: Path | None = None
    lines: tuple[str, ...] = ()
    printed: tuple[str, ...] = ()


def get_kind(name: str) -> ModuleType:
    """The module of the kind `name` (KeyError for an unknown one)."""
    return importlib.import_module(KINDS[name])


def _suggest(word: str) -> str:
    close = difflib.get_close_matches(word, list(KINDS), n=2, cutoff=0.5)
    if close:
        return "did you mean " + " or ".join(repr(c) for c in close) + "?"
    return "expected one of " + ", ".join(repr(k) for k in KINDS)


def kind_of_document(doc: dict, file: str) -> str:
    """The kind of a study file's TOML document: ``[study] kind``, else inferred.

    Raises
    ------
    StudyError
        ``[study] kind`` names no registered kind.
    """
    from skidmc.ensemble.study_model import StudyError

    head = doc.get("study")
    if isinstance(head, dict) and "kind" in head:
        name = head["kind"]
        if not isinstance(name, str) or name not in KINDS:
            raise StudyError(file, "study.kind", name, _suggest(str(name)))
        return name
    for name in KINDS:
        if get_kind(name).detect(doc):
            return name
    return "ensemble"  # pragma: no cover - the plain kind detects everything


def kind_of_file(path: str | Path) -> str:
    """The kind of a study file (read once; a StudyError names the file if it cannot be)."""
    from skidmc.ensemble.study import parse_toml, read_study_text

    path = Path(path)
    return kind_of_document(parse_toml(read_study_text(path), str(path)), str(path))


def study_of_result(path: str | Path) -> str:
    """The study text a result file stores (its ``study_text`` attribute; ``""`` if none or
    the file cannot be read: reading it properly then says why)."""
    import h5py

    try:
        with h5py.File(path, "r") as f:
            text = f.attrs.get("study_text", "")
    except OSError:
        return ""
    return text.decode("utf-8") if isinstance(text, bytes) else str(text)


def kind_of_result(path: str | Path) -> str:
    """The kind of study whose result `path` is, from the study text it stores (the plain
    kind when it stores none: its reader then reports what is wrong)."""
    from skidmc.ensemble.study import parse_toml
    from skidmc.ensemble.study_model import StudyError

    text = study_of_result(path)
    if not text:
        return "ensemble"
    try:
        return kind_of_document(parse_toml(text, str(path)), str(path))
    except StudyError:
        return "ensemble"


HDF5_SIGNATURE = b"\x89HDF\r\n\x1a\n"


def load(path: str | Path) -> tuple[str, object]:
    """The kind of a study file and the study, validated by its kind.

    A result file (HDF5) given where a study is wanted is refused saying so (a StudyError),
    rather than failing to decode it as text."""
    from skidmc.ensemble.study_model import StudyError

    try:
        with open(path, "rb") as f:
            head = f.read(8)
    except OSError:
        head = b""  # reading it as a study says why
    if head == HDF5_SIGNATURE:
        raise StudyError(str(path), "study", Path(path).name,
                         "is a result file (HDF5), not a study file (TOML): run the study that "
                         f"made it, or analyse it with: skidmc report {path}")
    name = kind_of_file(path)
    return name, get_kind(name).load(path)


def check_options(kind: str, options, given: dict | None = None) -> None:
    """Refuse every option given that the kind does not take (:class:`OptionError`).

    Parameters
    ----------
    kind : str
    options : RunOptions or ReportOptions
    given : dict, optional
        Option -> value as the user gave it; default: the fields of `options` that differ from
        their defaults.
    """
    module = get_kind(kind)
    report = isinstance(options, ReportOptions)
    allowed = module.REPORT_OPTIONS if report else module.RUN_OPTIONS
    defaults = type(options)()
    for field, flag in options.USER_OPTIONS.items():
        value = getattr(options, field)
        if value == getattr(defaults, field) or field in allowed:
            continue
        reason = getattr(module, "REFUSED", {}).get(field, "it has no meaning there")
        shown = "" if isinstance(value, bool) else value
        raise OptionError(flag, shown, kind, reason)
