"""The linear prefix: runs of one model at nearby heights share their linear start.

``skidmc.solver.simulate.LinearPrefix``; docs/model.md, "Runs of one search share their linear
start".
"""

import math

import numpy as np
import pytest

from skidmc.physics.thermal import (
    _PX_STEPS,
    _PX_T,
    _PX_T_MAX,
    _PX_VALID,
    PREFIX_MAX_SCALE,
    PREFIX_RESUME,
    simulate_kernel,
)
from skidmc.scene import get_preset
from skidmc.solver import critical_height
from skidmc.solver.model import build_model
from skidmc.solver.simulate import LinearPrefix, kernel_arguments, simulate


@pytest.fixture(scope="module", params=["paper-quartz", "paper-gold"])
def recorded(request):
    """A model of the default search's coarse level, the height its prefix was recorded at
    (near the root) and the prefix."""
    scene = get_preset(request.param)
    model = build_model(scene, level=0.5, melt_width=1.0, melt_spread=1.0, target="exact")
    height = 1.01 * critical_height(scene, rtol=1e-2).critical_height
    prefix = LinearPrefix(model)
    simulate(model, height, prefix=prefix)
    return model, height, prefix


def test_recording_leaves_the_run_unchanged(recorded):
    model, height, _ = recorded
    prefix = LinearPrefix(model)
    with_prefix = simulate(model, height, prefix=prefix)
    plain = simulate(model, height)
    assert prefix.array[_PX_VALID] == 1.0 and prefix.recorded_height == height
    assert with_prefix.margin == plain.margin
    assert with_prefix.steps == plain.steps
    assert with_prefix.newton_iterations == plain.newton_iterations
    assert with_prefix.resumed_steps == 0


def test_prefix_ends_in_the_linear_start_before_the_exit(recorded):
    model, _, prefix = recorded
    steps = int(prefix.array[_PX_STEPS])
    # ~25-60 steps; the hottest cell below the cold-source cutoff (~450-470 K here) and far
    # below the melting point (553 K), which is what lets it scale.
    assert 10 <= steps
    assert prefix.array[_PX_T] < 0.3 * model.exit_time
    assert prefix.array[_PX_T_MAX] < model.melting_point - 50.0


@pytest.mark.parametrize("scale", [1.0 / PREFIX_MAX_SCALE, 1.03, PREFIX_MAX_SCALE])
def test_prefix_is_the_run_at_another_height_with_its_steps(recorded, scale):
    # At flux scale a, the run from t = 0 with the step tolerance a x tol takes the same step
    # decisions as the recorded run (its errors are a times those): its state at the prefix's
    # end must be the recorded one scaled, T - T0 -> a (T - T0), to rounding. This is the
    # linearity the prefix rests on, checked through the hottest cell and the step count.
    model, height, prefix = recorded
    other = height * scale**2
    args = kernel_arguments(model, other)
    args[3]["tol_temperature"] = model.resolution.tol_temperature * scale
    args[3]["t_stop"] = prefix.array[_PX_T]                    # the prefix's end
    info = simulate_kernel(*args)[0]
    t0 = model.initial_temperature
    expected = t0 + scale * (prefix.array[_PX_T_MAX] - t0)
    assert info["steps"] == prefix.array[_PX_STEPS]
    # Relative to the rise T - T0 (~150 K): rounding of ~50 steps' sums, 1e-12 each.
    assert abs(info["t_max"] - expected) <= 1e-9 * (expected - t0)


def test_resumed_run_at_the_recorded_height_is_the_run(recorded):
    model, height, prefix = recorded
    resumed = simulate(model, height, prefix=prefix)
    plain = simulate(model, height)
    assert resumed.resumed_steps == prefix.array[_PX_STEPS] > 0
    assert resumed.newton_iterations < plain.newton_iterations
    # T0 + 1 x (T - T0) rounds differently from T by an ulp; nothing else differs.
    assert resumed.margin == pytest.approx(plain.margin, abs=1e-9)


def test_heights_outside_the_scale_and_other_models_start_at_zero(recorded):
    model, height, prefix = recorded
    far = height * (1.01 * PREFIX_MAX_SCALE) ** 2
    assert prefix.mode(far) == 0
    run = simulate(model, far, prefix=prefix)
    assert run.resumed_steps == 0 and run.margin == simulate(model, far).margin
    # Another model, even an identical one: simulate leaves the prefix alone.
    twin = build_model(get_preset("paper-quartz"), level=0.5, melt_width=1.0, melt_spread=1.0,
                       target="exact")
    assert simulate(twin, height, prefix=prefix).resumed_steps == 0
    # Another level (another mesh): the kernel itself refuses the prefix, runs from t = 0.
    finer = build_model(get_preset("paper-quartz"), level=1.5, melt_width=1.0, melt_spread=1.0,
                        target="exact")
    args = kernel_arguments(finer, height, prefix=prefix.array, prefix_mode=PREFIX_RESUME)
    plain = simulate_kernel(*kernel_arguments(finer, height))[0]
    resumed = simulate_kernel(*args)[0]
    assert resumed["resumed_steps"] == 0
    for field in plain.dtype.names:   # every field, nan (none reached) equal to nan
        assert np.array_equal(resumed[field], plain[field], equal_nan=True), field


def test_resumed_runs_stay_within_the_levels_step_noise(recorded):
    # A resumed run is the recorded run's steps up to the prefix's end, not its own: its margin
    # differs from the run from t = 0 by the step sequence's error. At level 0.5 the margin
    # itself jumps by up to ~1.5e-3 between heights 0.05 % apart where a step is added or
    # rejected (quartz-pendulum-8 of benchmarks/solver.py: +1.1e-3 and -0.9e-3 within 3 % of
    # its root), against a discretisation error of ~4e-3: 2e-3 bounds what was seen here.
    model, height, prefix = recorded
    for factor in (0.97, 0.99, 0.999, 1.001, 1.02):
        resumed = simulate(model, factor * height, prefix=prefix)
        plain = simulate(model, factor * height)
        assert resumed.resumed_steps > 0
        if math.isfinite(plain.margin):
            assert abs(resumed.margin - plain.margin) <= 2e-3
        else:
            assert resumed.margin == plain.margin


def test_search_with_and_without_prefixes_agree_within_their_estimates(monkeypatch):
    with_prefix = {name: critical_height(get_preset(name), rtol=1e-3)
                   for name in ("paper-quartz", "paper-gold")}
    monkeypatch.setattr(LinearPrefix, "mode", lambda self, height: 0)
    for name, res in with_prefix.items():
        plain = critical_height(get_preset(name), rtol=1e-3)
        assert abs(res.critical_height / plain.critical_height - 1.0) <= min(
            res.error_estimate, plain.error_estimate)
