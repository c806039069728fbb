"""``scripts/search_cost.py``: its comparison table from two hand-made records."""

import json
import math
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "scripts"))

import search_cost  # noqa: E402


def _record(rows, reference=True):
    return {"package": "p", "seed": 7, "n_per_study": 1,
            "reference_rtol": 1e-4 if reference else None,
            "rows": [{"label": label, "tabled": tabled,
                      "runs": {"0.001": (h, est, sims, passes)},
                      "reference": ref if reference else None}
                     for label, tabled, h, est, sims, passes, ref in rows]}


def test_the_table_counts_the_work_and_measures_the_error_against_the_reference(tmp_path):
    before = _record([("a", True, 1.001, 1e-3, 6, 3000, 1.0),
                      ("b", False, 2.0 * math.exp(4e-4), 1e-3, 4, 1000, 2.0)])
    after = _record([("a", True, 1.0005, 1e-3, 4, 2000, None),
                     ("b", False, 2.0 * math.exp(2e-3), 1e-3, 4, 1000, None)],
                    reference=False)
    a, b = tmp_path / "a.json", tmp_path / "b.json"
    a.write_text(json.dumps(before))
    b.write_text(json.dumps(after))
    s = search_cost.summary(after, [1.0, 2.0])["0.001"]
    assert (s["sims_tabled"], s["sims_constant"], s["cell_passes"]) == (4, 4, 3000)
    assert math.isclose(s["error_max"], 2e-3) and s["over_estimate"] == 1
    assert math.isclose(s["ratio_median"], 0.5 * (math.log(1.0005) / 1e-3 + 2.0))
    table = search_cost.compare(a, b, labels=("old", "new"))
    assert "old -> new" in table
    assert "0.00M -> 0.00M (-25.0 %)" in table   # 4,000 -> 3,000 cell-passes
    assert "| 0 -> 1 |" in table                                # one error above its estimate
