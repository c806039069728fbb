"""The root finders meet their tolerance on ln H, on scenes they were not tuned on.

The error estimate of every result counts the root finder's error as its tolerance x_tol
(docs/model.md, "Accuracy control"). The go-side finder's bend constant
(:data:`skidmc.solver.roots.GO_BEND`) was measured by ``scripts/go_side_bend.py`` on the report
presets and the off-preset scenes of seed 16; here the searches of the default pairs run on a
fresh draw of the off-preset box (seed 17) and their roots are compared with roots found 1000x
tighter on the same level. Level 0 is left out: its margin jumps by ~1e-3 between heights
0.1 % apart, so a "tight" level-0 root is not better defined than that (its error is part of
level 0's discretisation error, which the Richardson estimate covers).
"""

from __future__ import annotations

import math

import pytest

from skidmc.physics.thermal import MELT_SPREAD
from skidmc.scene import get_preset
from skidmc.scene.validation import off_preset_scenes
from skidmc.solver.options import exit_regime, margin_likely_jumps
from skidmc.solver.plan import modelled_error
from skidmc.solver.search import (
    FADING_FAST_SHIFT,
    FADING_FAST_SPREAD,
    FINE_SHIFT_SPREAD,
    SearchOptions,
    _fast_guess,
    _search,
)

SCENES = [("paper-quartz", get_preset("paper-quartz"))] + off_preset_scenes(8, seed=17)
def _options(width):
    """A plain search at rtol 1e-3 with melting width ``width`` [K] and the default spread."""
    return SearchOptions(rtol=1e-3, melt_width=width, melt_spread=MELT_SPREAD)


@pytest.mark.parametrize(("level", "width", "x_tol"), [
    (1.0, 4.0, 2.5e-3),  # rtol 1e-2: the fine search of the pair (0, 1)
    (1.0, 3.0, 3e-4),    # rtol 3e-3: the fine search of the pair (0, 1)
    (0.5, 1.0, 2e-4),    # rtol 1e-3: the pair (0.5, 1.5)
    (1.5, 1.0, 1e-4),
])
def test_roots_are_within_their_tolerance(level, width, x_tol):
    misses = {}
    for label, scene in SCENES:
        found = _search(scene, _options(width), level, x_tol)
        tight = _search(scene, _options(width), level, 1e-3 * x_tol)
        if found.censored or tight.censored:
            assert found.censored == tight.censored, label
            continue
        miss = abs(math.log(found.critical_height / tight.critical_height)) / x_tol
        if miss > 1.0:
            misses[label] = round(miss, 2)
    assert not misses, misses


# Rebound scenes whose heating fades before the exit: their coarse search starts from the
# prior FADING_FAST_SHIFT above the fast tier's height (fitted on scripts/fast_tier_error.py's
# training set). The off-preset box's fading scenes (seeds 16 and 17) are outside that set.
FADING = [(label, scene) for seed, n in ((16, 16), (17, 24))
          for label, scene in off_preset_scenes(n, seed=seed)
          if exit_regime(scene) == "fading"]


def test_the_box_has_fading_rebound_scenes():
    # Four of seed 16 (exit speed 0.14-0.47 of the initial one) and two of seed 17.
    assert len(FADING) >= 4


@pytest.mark.parametrize(("label", "scene"), FADING, ids=[label for label, _ in FADING])
def test_fading_rebound_prior_and_root(label, scene):
    x_tol = 2e-4   # tighter than rtol 1e-3's coarse search of a jumping pair (3.8e-4)
    found = _search(scene, _options(1.0), 0.5, x_tol)
    tight = _search(scene, _options(1.0), 0.5, 1e-3 * x_tol)
    assert found.censored is None and tight.censored is None
    assert abs(math.log(found.critical_height / tight.critical_height)) <= x_tol
    # The prior is honest here: the root lies within 2.5 spreads of its centre (measured
    # +0.032 to +0.052 in ln H above the fast tier, centre +0.04, spread 0.02).
    fast = _fast_guess(scene, 1e-3, 1e4, True)
    offset = math.log(tight.critical_height / fast) - FADING_FAST_SHIFT
    assert abs(offset) <= 2.5 * FADING_FAST_SPREAD, offset


JUMPING_HELD_OUT = [(label, scene) for label, scene in off_preset_scenes(8, seed=18)
                    if margin_likely_jumps(scene)]


@pytest.mark.parametrize(("label", "scene"), JUMPING_HELD_OUT,
                         ids=[label for label, _ in JUMPING_HELD_OUT])
def test_fine_root_prior_of_a_jumping_pair(label, scene):
    # The fine search of a pair whose margin jumps starts from a prior 0.375 (half of 0.75) of
    # the coarse level's modelled error above the coarse root, with FINE_SHIFT_SPREAD of it as
    # its spread (fitted on seeds 16 and 17); seed 18 was not used to choose it.
    coarse = _search(scene, _options(1.0), 0.5, 2e-7)
    fine = _search(scene, _options(1.0), 1.5, 1e-7)
    shift = math.log(fine.critical_height / coarse.critical_height) / modelled_error(0.5)
    assert abs(shift - 0.5 * 0.75) <= 2.5 * FINE_SHIFT_SPREAD, shift
