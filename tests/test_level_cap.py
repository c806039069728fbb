"""A cap on the default search's refinement (``critical_height(..., max_level=...)``).

Where the first Richardson pair's a posteriori estimate stays above rtol, the default search
moves the pair up a level; a run there costs ~5 of the level below, and those scenes are the slow
tail of a study (docs/performance.md). ``max_level`` lets a user buy speed with accuracy, stated
per height: the search ends with the last pair's value and its estimate, flagged
``rtol_unmet``. Checked on a stops-sliding study scene that refines at rtol 1e-3
(``tests/test_refine_prior.py``'s held-out draw).
"""

from __future__ import annotations

import math

import pytest
from test_refine_prior import _scene

import skidmc
from skidmc.errors import SceneError
from skidmc.solver.results import RTOL_UNMET

RTOL = 1e-3


@pytest.fixture(scope="module")
def refined():
    scene = _scene("sobol-series1[41012]")
    return scene, skidmc.critical_height(scene, rtol=RTOL)


def test_a_capped_search_stops_at_its_last_pair_and_says_so(refined):
    scene, full = refined
    assert full.level == 2.5 and full.error_estimate <= RTOL   # the scene refines
    capped = skidmc.critical_height(scene, rtol=RTOL, max_level=1.5)
    assert capped.level == 1.5 and capped.extrapolated
    assert capped.error_estimate > RTOL and RTOL_UNMET in capped.flags
    assert capped.evaluations < full.evaluations
    # Honest: the capped height lies within its own estimate of the refined one (whose own
    # error is within rtol: the two estimates together bound the difference).
    gap = abs(math.log(capped.critical_height / full.critical_height))
    assert gap <= capped.error_estimate + full.error_estimate


def test_a_cap_at_or_above_the_level_reached_changes_nothing(refined):
    scene, full = refined
    for cap in (2.5, 3.0):
        same = skidmc.critical_height(scene, rtol=RTOL, max_level=cap)
        assert (same.critical_height, same.error_estimate, same.evaluations, same.level) == (
            full.critical_height, full.error_estimate, full.evaluations, full.level)


@pytest.mark.parametrize("kwargs, words", [
    (dict(max_level=1.0), "below the first pair's fine level 1.5"),
    (dict(max_level="2"), "must be a number"),
    (dict(max_level=True), "must be a number"),
    (dict(max_level=2.0, level=1.0), "caps the default search's refinement"),
    (dict(max_level=2.0, extrapolate=False), "caps the default search's refinement"),
])
def test_a_cap_the_search_cannot_take_is_refused_by_name(kwargs, words):
    with pytest.raises(SceneError, match="max_level") as refused:
        skidmc.critical_height(skidmc.get_preset("paper-quartz"), rtol=RTOL, **kwargs)
    assert words in str(refused.value)
