"""The device search stops a stalled run by the CPU search's rule (simulate.stall_cap)."""

from __future__ import annotations

import numpy as np
import pytest

from skidmc.scene import NUMERIC_KEYS, get_preset
from skidmc.solver.model import build_model
from skidmc.solver.simulate import MAX_STEPS, LinearPrefix, stall_cap


@pytest.mark.parametrize("level", [0.0, 0.5, 1.0, 1.5, 2.0, 2.5, 3.0, 4.0, 5.0])
@pytest.mark.parametrize("most", [0, 1, 144, 399, 400, 460, 1_000, 7_071, 50_000])
def test_device_cap_is_the_cpu_search_s(level, most):
    # the same rule on the same constants: equal, attempt for attempt, for a search's first run
    # (most = 0) and after earlier runs of any size, at the levels a search uses
    from skidmc.solver.device import run_cap

    model = build_model(get_preset("paper-quartz"), level=level, meshes=False)
    prefix = LinearPrefix.__new__(LinearPrefix)  # only what stall_cap reads
    prefix.model, prefix.most_attempts = model, most
    assert run_cap(model.resolution.tol_temperature, float(most)) == stall_cap(model, prefix)


def test_a_stalled_scene_goes_to_the_cpu_search():
    # he.heat_of_fusion = 1e10 J/kg stalls a run (tests/test_edges.py): the device search
    # hands the scene back (STATUS_CPU) to the CPU search, which fails it with its reason; its
    # runs now stop at run_cap (above) rather than MAX_STEPS attempts (the time this saves is
    # measured in docs/performance.md, not here)
    from skidmc.solver import device
    from skidmc.solver.cuda import critical_heights

    scene = get_preset("paper-quartz").replace({"he.heat_of_fusion": 1e10},
                                               check_plausible=False)
    row = np.array([[scene.as_dict()[k] for k in NUMERIC_KEYS]])
    out, _ = critical_heights(row, 1e-3, backend="cpu")
    assert out[0, device.OUT_STATUS] == device.STATUS_CPU
    assert device.run_cap(0.5, 0.0) < MAX_STEPS  # level 0's cap is below the global one
