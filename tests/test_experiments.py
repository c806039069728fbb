"""The report's data files: every file loads, cites its source, and matches the printed tables."""

from __future__ import annotations

import math

import numpy as np
import pytest

from skidmc.analysis.experiments import (
    DROP_SERIES,
    TABLES,
    experimental_h50,
    load_drops,
    measured_friction,
    read_table,
    second_series,
)


@pytest.mark.parametrize("name", TABLES)
def test_every_file_loads_and_names_its_source(name):
    comments, columns = read_table(name)
    sources = [c for c in comments if c.startswith("source:")]
    assert sources and any("Table" in c or "Section" in c for c in sources)
    assert any("Oblique Impact" in c for c in sources)
    lengths = {len(cells) for cells in columns.values()}
    assert len(lengths) == 1 and lengths.pop() > 0  # rectangular, not empty
    for column in (c for c in columns if c.endswith("_ft")):  # heights: unit in the name
        assert all(float(v) > 0 for v in columns[column] if v)


@pytest.mark.parametrize("series", DROP_SERIES)
def test_every_drop_series_loads(series):
    drops = load_drops(series)
    assert len(drops) == drops.went.size == drops.valid.size > 0
    assert drops.valid.all() and drops.units == "ft" and "Oblique Impact" in drops.source


def test_table_iii_quartz_drops():
    drops = load_drops("quartz")
    np.testing.assert_array_equal(drops.drop, np.arange(1, 11))
    # 1.5 ft no-go at drops 1, 3, 5, 7, 9; 2.12 ft go at 2, 4, 6, 8 and no-go at 10
    np.testing.assert_array_equal(drops.heights, [1.5, 2.12] * 5)
    np.testing.assert_array_equal(drops.went, [0, 1, 0, 1, 0, 1, 0, 1, 0, 0])


def test_table_iv_alumina_drops_and_the_invalid_drop_7():
    everything = load_drops("alumina", include_invalid=True)
    np.testing.assert_array_equal(everything.drop, np.arange(1, 13))
    np.testing.assert_array_equal(
        everything.heights, [11.0, 9.25, 11.0, 9.25, 11.0, 13.1, 15.6, 13.1, 15.6, 18.5, 15.6, 18.5]
    )
    np.testing.assert_array_equal(everything.went, [1, 0, 1, 0, 0, 0, 1, 0, 0, 1, 0, 0])
    assert list(everything.valid).index(False) == 6 and (~everything.valid).sum() == 1
    assert "invalid" in everything.note[6]
    assert 7 not in load_drops("alumina").drop  # dropped by default
    np.testing.assert_array_equal(load_drops("alumina_50_80").drop, [1, 2, 3])
    np.testing.assert_array_equal(load_drops("alumina_20_35").drop, [4, 5, 6, 8, 9, 10, 11, 12])


def test_gold_drops_no_event_up_to_the_tower_height():
    drops = load_drops("gold")
    np.testing.assert_array_equal(drops.heights, [25, 50, 100, 150])
    assert not drops.went.any() and np.isnan(drops.drop).all()  # order not given
    missed = load_drops("gold", include_invalid=True)
    assert len(missed) == 5 and "missed" in missed.note[~missed.valid][0]


def test_table_ii_and_viii_heights():
    h50 = experimental_h50()
    assert list(h50.target.values) == ["gold", "alumina_20_35", "alumina_50_80", "quartz"]
    np.testing.assert_array_equal(h50.h50_experimental, [150, 19, 11, 1.8])
    assert list(h50.qualifier.values) == ["lower_bound", "approximate", "approximate", "updown"]
    np.testing.assert_array_equal(h50.h50_calculated_report, [515, 22.8, 14.2, 1.25])
    np.testing.assert_array_equal(h50.thermal_conductivity, [0.703, 0.021, 0.021, 0.00405])
    in_metres = experimental_h50(units="m")
    # 0.3048 m per ft exactly; float products agree to round-off
    np.testing.assert_allclose(in_metres.h50_experimental, h50.h50_experimental * 0.3048,
                               rtol=1e-15)
    assert in_metres.h50_experimental.attrs["units"] == "m"


def test_friction_tables_i_and_v():
    friction = measured_friction()
    first = friction.where(friction.series == 1, drop=True)
    np.testing.assert_array_equal(first.friction, [0.117, 0.0576, 0.0808, 0.132])
    second = friction.where(friction.series == 2, drop=True)
    np.testing.assert_array_equal(second.friction, [0.092, 0.056, 0.114, 0.151, 0.243])
    assert list(second.finish.values) == ["1-2", "6-7", "60-80", "180-220", "> 1000"]
    assert math.isnan(float(second.roughness_high_uin[-1]))


def test_table_ix_second_series():
    series = second_series()
    np.testing.assert_array_equal(series.friction, [0.056, 0.092, 0.114, 0.151, 0.243])
    np.testing.assert_array_equal(series.h50_experimental, [4.8, 1.8, 2.4, 0.5, 0.7])
    np.testing.assert_array_equal(series.h_calculated_report, [3.76, 1.48, 1.0, 0.61, 0.28])
    # joined to Table I by friction: 0.056 is the No. 900 powder, 6-7 micro-inch
    assert "No. 900" in series.surface_treatment.values[0]
    assert float(series.roughness_low_uin[0]) == 6.0


@pytest.mark.parametrize(
    "call, message",
    [
        (lambda: load_drops("steel"), r"series = 'steel'"),
        (lambda: load_drops("quartz", units="cm"), r"units = 'cm'"),
        (lambda: experimental_h50(units="in"), r"units = 'in'"),
        (lambda: read_table("table7.csv"), r"name = 'table7\.csv'"),
    ],
)
def test_bad_arguments(call, message):
    with pytest.raises(ValueError, match=message):
        call()


# --- experiments a study scene refers to ---------------------------------------------------------


def test_every_experiment_loads_with_its_source():
    from skidmc.analysis.experiments import EXPERIMENTS, get_experiment

    for name in EXPERIMENTS:
        exp = get_experiment(name)
        assert exp.name == name and "Table" in exp.source
        assert exp.h50 > 0.0


def test_first_series_experiments_join_drops_and_table_ii():
    from skidmc.analysis.experiments import get_experiment

    quartz = get_experiment("quartz")
    # Table III: ten drops, four events; Table II: 1.8 ft by the up-down method.
    assert len(quartz.drops) == 10 and quartz.drops.went.sum() == 4
    assert (quartz.h50, quartz.h50_qualifier) == (1.8, "updown")
    gold = get_experiment("gold", units="m")
    assert gold.h50_qualifier == "lower_bound" and not gold.drops.went.any()
    assert gold.h50 == pytest.approx(150 * 0.3048, rel=1e-15)


def test_second_series_experiments_follow_table_ix_order():
    from skidmc.analysis.experiments import get_experiment

    rows = [get_experiment(f"series2_{i}") for i in range(1, 6)]
    assert [r.h50 for r in rows] == [4.8, 1.8, 2.4, 0.5, 0.7]  # Table IX as printed
    assert all(r.drops is None for r in rows)
    assert "mu = 0.243" in rows[-1].description


def test_unknown_experiment_lists_the_known_ones():
    from skidmc.analysis.experiments import get_experiment

    with pytest.raises(ValueError, match="experiment = 'quarts'.*quartz"):
        get_experiment("quarts")


def test_report_calculated_height_and_friction_follow_tables_viii_and_ix():
    from skidmc.analysis.experiments import experiment_friction, report_calculated_height

    # Table VIII (first series) and Table IX (second series, in its printed order).
    assert report_calculated_height("quartz") == 1.25
    assert report_calculated_height("gold") == 515.0
    assert report_calculated_height("alumina_50_80", units="m") == pytest.approx(14.2 * 0.3048)
    assert [report_calculated_height(f"series2_{i}") for i in range(1, 6)] == [
        3.76, 1.48, 1.0, 0.61, 0.28]
    assert [experiment_friction(f"series2_{i}") for i in range(1, 6)] == [
        0.056, 0.092, 0.114, 0.151, 0.243]
    assert experiment_friction("alumina_20_35") == 0.0576
    with pytest.raises(ValueError, match="experiment = 'nope'"):
        report_calculated_height("nope")
