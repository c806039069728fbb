"""The report's experimental data: drops, 50 % heights and measured friction, as tidy arrays.

The data files live in ``skidmc/data/experiments/`` (found with :mod:`importlib.resources`, so
they work from an installed package). Each is a CSV file with a ``# source: ...`` comment block
naming the report, table and page, then a header with units in the column names (``height_ft``).
The report is the Los Alamos report "Effect of Target Thermal Conductivity and Roughness on the
Initiation of PBX 9404 by Oblique Impact" (same model: Randolph, Hatler & Popolato, Ind. Eng.
Chem. Fundam. 15 (1976) 1); its OCR text has no page markers, so the files cite tables only.

Heights are stored in feet as printed; every loader can return metres instead (``units="m"``).
"""

from __future__ import annotations

import csv
import math
from dataclasses import dataclass
from importlib import resources

import numpy as np
import xarray as xr

from skidmc.scene.units import FOOT

__all__ = [
    "DROP_SERIES",
    "EXPERIMENTS",
    "TABLES",
    "DropSeries",
    "Experiment",
    "get_experiment",
    "experiment_friction",
    "experimental_h50",
    "load_drops",
    "measured_friction",
    "read_table",
    "report_calculated_height",
    "second_series",
]

#: Data files shipped, by table.
TABLES = (
    "table1_quartz_finish_friction.csv",
    "table2_experimental_h50.csv",
    "table3_quartz_drops.csv",
    "table4_alumina_drops.csv",
    "table5_friction_first_series.csv",
    "table8_h50_calculated.csv",
    "table9_second_series.csv",
    "gold_drops.csv",
)

#: Drop series known to :func:`load_drops`: name -> (file, finish filter or None).
DROP_SERIES = {
    "quartz": ("table3_quartz_drops.csv", None),
    "alumina": ("table4_alumina_drops.csv", None),
    "alumina_50_80": ("table4_alumina_drops.csv", "50-80"),
    "alumina_20_35": ("table4_alumina_drops.csv", "20-35"),
    "gold": ("gold_drops.csv", None),
}

_UNIT_FACTORS = {"ft": 1.0, "m": FOOT}  # from feet [m per ft]


def _height_factor(units: str) -> float:
    if units not in _UNIT_FACTORS:
        raise ValueError(f"units = {units!r}: must be 'ft' or 'm'")
    return _UNIT_FACTORS[units]


def read_table(name: str) -> tuple[list[str], dict[str, list[str]]]:
    """Read one shipped data file.

    Parameters
    ----------
    name : str
        File name, one of :data:`TABLES`.

    Returns
    -------
    comments : list of str
        The comment block (lines after ``#``), including the ``source:`` lines.
    columns : dict of str to list of str
        Column name -> the column's cells as text, in file order.

    Raises
    ------
    ValueError
        For an unknown name.
    """
    if name not in TABLES:
        raise ValueError(f"name = {name!r}: not a shipped table; choose from {', '.join(TABLES)}")
    path = resources.files("skidmc").joinpath("data", "experiments", name)
    text = path.read_text(encoding="utf-8")
    lines = text.splitlines()
    comments = [line[1:].strip() for line in lines if line.startswith("#")]
    rows = list(csv.reader(line for line in lines if line.strip() and not line.startswith("#")))
    header, body = rows[0], rows[1:]
    columns = {column: [row[i] for row in body] for i, column in enumerate(header)}
    return comments, columns


def _floats(cells: list[str]) -> np.ndarray:
    """Cells as floats; an empty cell is NaN (a value the report does not give)."""
    return np.array([float(cell) if cell.strip() else math.nan for cell in cells])


def _source(comments: list[str]) -> str:
    return " ".join(c[len("source:"):].strip() for c in comments if c.startswith("source:"))


@dataclass(frozen=True)
class DropSeries:
    """One series of experimental drops, in test order.

    Attributes
    ----------
    series : str
        Name given to :func:`load_drops`.
    drop : ndarray of float
        Drop number in the report (NaN where the report gives no order).
    heights : ndarray of float
        Drop heights [``units``].
    went : ndarray of bool
        True for an event (E), False for none (N).
    valid : ndarray of bool
        False for drops the report declares invalid (kept only with ``include_invalid``).
    finish : ndarray of str
        Target surface roughness range [micro-inch], e.g. "20-35".
    note : ndarray of str
        Remarks from the report.
    units : str
        "ft" or "m".
    source : str
        Where the data come from (report, table).
    """

    series: str
    drop: np.ndarray
    heights: np.ndarray
    went: np.ndarray
    valid: np.ndarray
    finish: np.ndarray
    note: np.ndarray
    units: str
    source: str

    def __len__(self) -> int:
        return int(self.heights.size)


def load_drops(series: str, *, include_invalid: bool = False, units: str = "ft") -> DropSeries:
    """Experimental drops of one series, in test order.

    Parameters
    ----------
    series : str
        "quartz" (Table III), "alumina" (Table IV, both finishes), "alumina_50_80" (drops 1-3),
        "alumina_20_35" (drops 4-12), or "gold" (text of Sections IV and V).
    include_invalid : bool, optional
        Keep the drops the report declares invalid (Table IV drop 7; the 150 ft drop that
        missed the gold target). Dropped by default.
    units : {"ft", "m"}, optional
        Unit of the returned heights.

    Returns
    -------
    DropSeries
        Heights, outcomes and provenance.

    Raises
    ------
    ValueError
        For an unknown series or unit.
    """
    if series not in DROP_SERIES:
        raise ValueError(f"series = {series!r}: choose from {', '.join(DROP_SERIES)}")
    factor = _height_factor(units)
    name, finish_filter = DROP_SERIES[series]
    comments, columns = read_table(name)
    keep = np.ones(len(columns["height_ft"]), dtype=bool)
    valid = np.array([cell == "1" for cell in columns["valid"]])
    finish = np.array(columns["finish_uin"], dtype=object)
    if finish_filter is not None:
        keep &= finish == finish_filter
    if not include_invalid:
        keep &= valid
    return DropSeries(
        series=series,
        drop=_floats(columns["drop"])[keep],
        heights=_floats(columns["height_ft"])[keep] * factor,
        went=np.array([cell == "E" for cell in columns["outcome"]])[keep],
        valid=valid[keep],
        finish=finish[keep],
        note=np.array(columns["note"], dtype=object)[keep],
        units=units,
        source=_source(comments),
    )


def experimental_h50(units: str = "ft") -> xr.Dataset:
    """The first series' 50 % drop heights per target: Table II, with Table VIII's calculation.

    Parameters
    ----------
    units : {"ft", "m"}, optional
        Unit of the heights.

    Returns
    -------
    xarray.Dataset
        Over dimension ``target`` ("gold", "alumina_20_35", "alumina_50_80", "quartz"):
        ``h50_experimental`` [units] (for gold the lower bound 150 ft), ``qualifier``
        ("lower_bound", "approximate", "updown"), ``thermal_conductivity``
        [cal/(s cm degC)] and ``h50_calculated_report`` [units], the report's own model.
    """
    factor = _height_factor(units)
    comments, table2 = read_table("table2_experimental_h50.csv")
    comments8, table8 = read_table("table8_h50_calculated.csv")

    def keys(columns):
        return [t if not f else f"{t}_{f.replace('-', '_')}"
                for t, f in zip(columns["target"], columns["finish_uin"])]

    targets = keys(table2)
    calculated = dict(zip(keys(table8), _floats(table8["calculated_h50_ft"]) * factor))
    return xr.Dataset(
        {
            "h50_experimental": ("target", _floats(table2["h50_ft"]) * factor,
                                 {"units": units, "long_name": "experimental 50% drop height"}),
            "qualifier": ("target", np.array(table2["h50_qualifier"], dtype=object),
                          {"long_name": "lower_bound: > value; approximate: ~ value; updown"}),
            "thermal_conductivity": (
                "target", _floats(table2["thermal_conductivity_cal_per_s_cm_degC"]),
                {"units": "cal/(s cm degC)", "long_name": "target thermal conductivity"}),
            "h50_calculated_report": (
                "target", np.array([calculated[t] for t in targets]),
                {"units": units, "long_name": "calculated 50% drop height (report, Table VIII)"}),
        },
        coords={"target": targets},
        attrs={"source": _source(comments) + " " + _source(comments8)},
    )


def measured_friction() -> xr.Dataset:
    """Apparent friction coefficients measured per target finish (Tables V and I).

    Returns
    -------
    xarray.Dataset
        Over dimension ``surface``: ``friction`` [-], ``series`` (1: first series, Table V;
        2: second series, quartz finishes, Table I), ``target``, ``finish`` (roughness as text,
        empty where not printed), ``roughness_low_uin`` and ``roughness_high_uin`` [micro-inch]
        (NaN where not given; Table I's "> 1000" has no upper value), ``description``.
    """
    comments5, table5 = read_table("table5_friction_first_series.csv")
    comments1, table1 = read_table("table1_quartz_finish_friction.csv")
    n5, n1 = len(table5["target"]), len(table1["friction"])
    low5 = [float(f.split("-")[0]) if f else math.nan for f in table5["finish_uin"]]
    high5 = [float(f.split("-")[1]) if f else math.nan for f in table5["finish_uin"]]
    low1, high1 = _floats(table1["roughness_low_uin"]), _floats(table1["roughness_high_uin"])
    finish1 = [f"{lo:g}-{hi:g}" if math.isfinite(hi) else f"> {lo:g}"
               for lo, hi in zip(low1, high1)]
    surfaces = [f"{t}_{f.replace('-', '_')}" if f else t
                for t, f in zip(table5["target"], table5["finish_uin"])]
    surfaces += [f"quartz_series2_{i + 1}" for i in range(n1)]
    return xr.Dataset(
        {
            "friction": ("surface", np.concatenate([_floats(table5["friction"]),
                                                    _floats(table1["friction"])]),
                         {"units": "1", "long_name": "apparent coefficient of friction"}),
            "series": ("surface", np.array([1] * n5 + [2] * n1)),
            "target": ("surface", np.array(table5["target"] + ["quartz"] * n1, dtype=object)),
            "finish": ("surface", np.array(table5["finish_uin"] + finish1, dtype=object),
                       {"units": "micro-inch"}),
            "roughness_low_uin": ("surface", np.concatenate([low5, low1]),
                                  {"units": "micro-inch"}),
            "roughness_high_uin": ("surface", np.concatenate([high5, high1]),
                                   {"units": "micro-inch"}),
            "description": ("surface", np.array(table5["note"] + table1["surface_treatment"],
                                                dtype=object)),
        },
        coords={"surface": surfaces},
        attrs={"source": _source(comments5) + " " + _source(comments1)},
    )


def second_series(units: str = "ft") -> xr.Dataset:
    """Second series (quartz finishes): Table IX joined with Table I by friction coefficient.

    Parameters
    ----------
    units : {"ft", "m"}, optional
        Unit of the heights.

    Returns
    -------
    xarray.Dataset
        Over dimension ``surface`` (Table IX order): ``friction`` [-],
        ``h50_experimental`` and ``h_calculated_report`` [units], ``surface_treatment`` and
        ``roughness_low_uin``/``roughness_high_uin`` [micro-inch] from Table I.
    """
    factor = _height_factor(units)
    comments9, table9 = read_table("table9_second_series.csv")
    comments1, table1 = read_table("table1_quartz_finish_friction.csv")
    friction = _floats(table9["friction"])
    by_friction = {float(f): i for i, f in enumerate(_floats(table1["friction"]))}
    rows = [by_friction[float(f)] for f in friction]
    return xr.Dataset(
        {
            "friction": ("surface", friction, {"units": "1"}),
            "h50_experimental": ("surface", _floats(table9["experimental_h50_ft"]) * factor,
                                 {"units": units}),
            "h_calculated_report": ("surface", _floats(table9["calculated_h_ft"]) * factor,
                                    {"units": units}),
            "surface_treatment": ("surface", np.array(table1["surface_treatment"],
                                                      dtype=object)[rows]),
            "roughness_low_uin": ("surface", _floats(table1["roughness_low_uin"])[rows],
                                  {"units": "micro-inch"}),
            "roughness_high_uin": ("surface", _floats(table1["roughness_high_uin"])[rows],
                                   {"units": "micro-inch"}),
        },
        coords={"surface": np.arange(1, friction.size + 1)},
        attrs={"source": _source(comments9) + " " + _source(comments1)},
    )


@dataclass(frozen=True)
class Experiment:
    """What the report measured for one target and finish: its drops and its 50 % height.

    Attributes
    ----------
    name : str
        A key of :data:`EXPERIMENTS`.
    description : str
    drops : DropSeries or None
        The individual drops, where the report lists them (first series only).
    h50 : float
        The report's experimental 50 % height [``units``] (NaN where none is given).
    h50_qualifier : str
        "updown" (Dixon-Mood on the drops), "approximate" (too few drops), "lower_bound" (no event
        up to this height) or "" (second series: as printed in Table IX).
    units : str
        "ft" or "m".
    source : str
    """

    name: str
    description: str
    drops: DropSeries | None
    h50: float
    h50_qualifier: str
    units: str
    source: str


#: Experiments a study scene can be compared with (``experiment = NAME`` in a study's scene):
#: the first series' targets (Tables II-IV and the gold drops) and the second series' five
#: quartz finishes (Table IX, by friction coefficient, in the printed order).
EXPERIMENTS = {
    "quartz": "first series, fused quartz (Table III drops, Table II 50 % height)",
    "alumina_20_35": "first series, 85 % alumina, 20-35 uin (Table IV drops 4-12, Table II)",
    "alumina_50_80": "first series, 85 % alumina, 50-80 uin (Table IV drops 1-3, Table II)",
    "gold": "first series, gold on a 45 deg target (no event at 25-150 ft, Sec. IV)",
    **{f"series2_{i}": f"second series, quartz finish {i} (Table IX row {i})"
       for i in range(1, 6)},
}


def get_experiment(name: str, units: str = "ft") -> Experiment:
    """The drops and 50 % height the report gives for one target and finish.

    Parameters
    ----------
    name : str
        A key of :data:`EXPERIMENTS`.
    units : {"ft", "m"}, optional
        Unit of the heights.

    Returns
    -------
    Experiment

    Raises
    ------
    ValueError
        An unknown name (the message lists the known ones) or unit.
    """
    if name not in EXPERIMENTS:
        raise ValueError(f"experiment = {name!r}: choose from {', '.join(EXPERIMENTS)}")
    if name.startswith("series2_"):
        table = second_series(units)
        row = table.isel(surface=int(name.split("_")[1]) - 1)
        description = (f"{EXPERIMENTS[name]}: mu = {float(row.friction):g}, "
                       f"{row.surface_treatment.item()}")
        return Experiment(name, description, None, float(row.h50_experimental), "",
                          units, table.attrs["source"])
    table = experimental_h50(units)
    h50 = table.sel(target=name)
    drops = load_drops(name, units=units)
    return Experiment(name, EXPERIMENTS[name], drops, float(h50.h50_experimental),
                      str(h50.qualifier.item()), units,
                      f"drops: {drops.source}; 50 % heights: {table.attrs['source']}")


def report_calculated_height(name: str, units: str = "ft") -> float:
    """The report's own calculated height for an experiment's target and finish [``units``].

    Table VIII (first series: "calculated 50 % drop height") or Table IX (second series:
    "calculated critical drop height"); NaN for a name without one.

    Parameters
    ----------
    name : str
        A key of :data:`EXPERIMENTS`.
    units : {"ft", "m"}, optional
    """
    if name not in EXPERIMENTS:
        raise ValueError(f"experiment = {name!r}: choose from {', '.join(EXPERIMENTS)}")
    if name.startswith("series2_"):
        row = second_series(units).isel(surface=int(name.split("_")[1]) - 1)
        return float(row.h_calculated_report)
    table = experimental_h50(units)
    if name not in table["target"].values:
        return math.nan
    return float(table["h50_calculated_report"].sel(target=name))


def experiment_friction(name: str) -> float:
    """The friction coefficient the report tabulates for an experiment's finish [-] (Table V for
    the first series, Tables I and IX for the second)."""
    if name not in EXPERIMENTS:
        raise ValueError(f"experiment = {name!r}: choose from {', '.join(EXPERIMENTS)}")
    if name.startswith("series2_"):  # Table IX's row (Table I lists the finishes otherwise)
        return float(second_series()["friction"][int(name.split("_")[1]) - 1])
    return float(measured_friction()["friction"].sel(surface=name))
