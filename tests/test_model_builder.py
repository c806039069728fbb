"""One scene inference per search: ``ModelBuilder`` gives ``build_model``'s models to the bit.

The default search builds its scene's model at every level and melting width it runs and once
more without meshes; since issue 45's tenth pass it infers the scene once
(:class:`skidmc.solver.model.ModelBuilder`) and builds only the meshes per model, and takes the
fast tier's guess from that inference instead of a second model and a rebuilt scene. Both are
checked here against the paths they replace, field by field and bit for bit.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

import skidmc
from skidmc.errors import SceneError
from skidmc.solver.fast import fast_critical_height
from skidmc.solver.model import (
    ModelBuilder,
    build_model,
    constant_property_scene,
    resolution_for_level,
    target_temperature_range,
)
from skidmc.solver.search import _fast_guess

SCENES = {
    "paper-quartz": skidmc.get_preset("paper-quartz"),
    "paper-gold": skidmc.get_preset("paper-gold"),
    "alumina-85 table": skidmc.get_preset("paper-alumina-smooth").replace(target="alumina-85"),
    "fused-quartz table": skidmc.get_preset("paper-quartz").replace(target="fused-quartz"),
    "layered": skidmc.make_scene(preset="paper-gold", target="gold-stack-report"),
    "stops sliding": skidmc.get_preset("paper-gold").replace(mu=0.6),
    "no friction": skidmc.get_preset("paper-quartz").replace(mu=0.0),
}


def _same(a, b):
    """Every field of two SkidModels equal, arrays bit for bit (NaN equal to NaN)."""
    for f in dataclasses.fields(a):
        x, y = getattr(a, f.name), getattr(b, f.name)
        if isinstance(x, np.ndarray):
            assert x.dtype == y.dtype and x.shape == y.shape, f.name
            assert x.tobytes() == y.tobytes(), f.name
        elif isinstance(x, float) and math.isnan(x):
            assert isinstance(y, float) and math.isnan(y), f.name
        else:
            assert x == y, f.name


@pytest.mark.parametrize("name", list(SCENES))
@pytest.mark.parametrize("target", ["mesh", "exact", None])
def test_a_builders_models_are_build_models(name, target):
    scene = SCENES[name]
    kwargs = dict(melting=True, rtol=1e-3)
    try:
        builder = ModelBuilder(scene, target=target, **kwargs)
    except SceneError as exc:
        # The builder refuses what build_model refuses, with its words.
        with pytest.raises(SceneError) as built:
            build_model(scene, target=target, **kwargs)
        assert str(built.value) == str(exc)
        return
    for target_of_model in ("mesh", "exact") if target is None else (target,):
        for level, width, spread, meshes in [(0.5, None, 1.0, True), (1.5, 0.7, 1.0, True),
                                             (2.5, 0.35, 0.0, True), (0.5, None, 1.0, False)]:
            res = resolution_for_level(level, width, spread)
            try:
                expected = build_model(scene, level=level, melt_width=width, melt_spread=spread,
                                       meshes=meshes, target=target_of_model, **kwargs)
            except SceneError as exc:
                with pytest.raises(SceneError) as refused:
                    builder.model(res, meshes=meshes, target=target_of_model)
                assert str(refused.value) == str(exc)
                continue
            _same(builder.model(res, meshes=meshes, target=target_of_model), expected)


def test_a_builder_with_its_target_refuses_another():
    builder = ModelBuilder(SCENES["paper-quartz"], target="mesh")
    with pytest.raises(ValueError, match="models the target 'mesh'"):
        builder.model(resolution_for_level(0.5), target="exact")


@pytest.mark.parametrize("name", list(SCENES))
@pytest.mark.parametrize("runaway", [None, 0.5])
def test_the_searchs_fast_guess_is_the_fast_tiers_height(name, runaway):
    # The guess the search took before: the fast tier on the scene (a tabled target's replaced
    # by its table's properties at the middle of the interface's rise, with the default
    # runaway rule), None where it refuses, fails or censors.
    scene = SCENES[name]
    extra = {} if runaway is None else {"runaway_fraction": runaway}
    builder = ModelBuilder(scene, melting=True, rtol=1e-3, **extra)
    h_min, h_max = 1e-3, 1e4
    before = scene
    if scene.target_table:
        low, high = target_temperature_range(
            scene.initial_temperature,
            build_model(scene, meshes=False, melting=True).runaway_temperature)
        before = constant_property_scene(scene, 0.5 * (low + high))
    try:
        res = fast_critical_height(before, h_min=h_min, h_max=h_max, melting=True)
        expected = (res.critical_height if res.censored is None
                    and math.isfinite(res.critical_height) else None)
    except SceneError:
        expected = None
    got = _fast_guess(scene, h_min, h_max, True, builder)
    assert got == expected
    if name in ("paper-quartz", "alumina-85 table", "fused-quartz table"):
        assert got is not None   # the comparison is not between two Nones
