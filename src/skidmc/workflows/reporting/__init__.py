"""Presentation: what every kind of study writes, apart from what it computes.

The analysis (:mod:`skidmc.analysis`) and the runners compute and return dataclasses and
xarray objects; this package turns them into the files a reader opens: ``summary.md``,
``summary.json`` and figures. One module per kind (:mod:`.ensemble` for plain and growing
studies, :mod:`.hazard`), on the primitives here:

- **JSON**: one encoder for every file skidmc writes and every ``--json`` it prints
  (:func:`dumps`, :func:`json_ready`): numpy scalars and arrays as Python numbers and lists,
  keys as strings, **NaN as ``null``** (JSON has no NaN; ``null`` is what every JSON reader
  takes as "no value"), infinities as the strings ``"inf"`` and ``"-inf"`` (a number that
  is known to be unbounded, e.g. a CoV with P = 0, not a missing one). ``allow_nan=False``
  guarantees no bare ``NaN``/``Infinity`` token, which strict readers reject, slips through.
- **Labels** that say what was computed: :func:`level` writes the confidence level that an
  interval was computed at, :func:`band` the quantiles of a band, :func:`log_name` the base of
  a logarithm; a line that states a level takes it from the analysis' result, never a literal
  (tests/test_reporting.py writes reports at other levels and bands and reads them back).
- **Figures**: :func:`pyplot` (matplotlib with the Agg backend, or None with a warning when the
  figures extra is not installed) and :func:`save`.

Why a package of the workflows layer: a report is an output of a run, like its result file,
and the layer that runs the kinds is the one that knows them all; below it the analysis keeps
to computing (docs/architecture.md).
"""

from __future__ import annotations

import json
import math
import warnings
from pathlib import Path

import numpy as np

__all__ = ["DPI", "band", "dumps", "json_ready", "level", "log_name", "pyplot", "save",
           "write_json"]

#: Resolution of every figure [dots per inch].
DPI = 110


def json_ready(obj):
    """`obj` as plain JSON data: the one encoding of skidmc's JSON (module docstring)."""
    if isinstance(obj, dict):
        return {str(k): json_ready(v) for k, v in obj.items()}
    if isinstance(obj, np.ndarray):
        return json_ready(obj.tolist())
    if isinstance(obj, (list, tuple, set, frozenset)):
        return [json_ready(v) for v in obj]
    if isinstance(obj, (np.floating, float)):
        x = float(obj)
        return None if math.isnan(x) else (str(x) if math.isinf(x) else x)
    if isinstance(obj, np.integer):
        return int(obj)
    if isinstance(obj, np.bool_):
        return bool(obj)
    return obj


def dumps(obj, indent: int | None = 1) -> str:
    """JSON text of `obj` (:func:`json_ready`; no NaN or Infinity token; any other object as
    its ``str``), ending in a newline."""
    return json.dumps(json_ready(obj), indent=indent, allow_nan=False, default=str) + "\n"


def write_json(path: str | Path, obj) -> Path:
    """Write :func:`dumps` of `obj` to `path` (UTF-8)."""
    path = Path(path)
    path.write_text(dumps(obj), encoding="utf-8")
    return path


def level(confidence: float) -> str:
    """``"95 %"`` for a confidence of 0.95: how a level is written in every report."""
    return f"{confidence * 100:g} %"


def band(quantiles: tuple[float, float]) -> str:
    """``"5-95 %"`` for the quantiles (0.05, 0.95) of a band."""
    low, high = quantiles
    return f"{low * 100:g}-{high * 100:g} %"


def log_name(base: float) -> str:
    """``"ln"`` for base e, ``"log10"`` for 10, else ``"log_b"``: the name of a logarithm."""
    if base == math.e:
        return "ln"
    return "log10" if base == 10 else f"log_{base:g}"


def pyplot(what: str = "figures"):
    """matplotlib.pyplot on the Agg backend, or None (with a RuntimeWarning naming `what`)
    where matplotlib, in the figures extra, is not installed."""
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:  # pragma: no cover - matplotlib is in the figures extra
        warnings.warn(f"matplotlib is not installed: {what} skipped", RuntimeWarning,
                      stacklevel=3)
        return None
    return plt


def save(fig, path: Path, dpi: int = DPI) -> Path:
    """Save a figure at `dpi` and close it."""
    import matplotlib.pyplot as plt

    fig.savefig(path, dpi=dpi)
    plt.close(fig)
    return path
