"""Scenes drawn from the shipped studies' ensembles, for the solver's benchmarks and checks.

Used by ``benchmarks/tail.py`` (per-height time on study scenes) and
``benchmarks/heights_fingerprint.py`` (every height bit for bit, before and after a change).
Only the public API is used (:func:`skidmc.open_ensemble`, :func:`skidmc.make_scene`,
``Scene.replace``), so that the same file runs against an older source tree.

A draw: ``n`` samples chosen at random (``numpy.random.default_rng(seed)``) among the finished
samples of each ensemble (paper-series1, paper-series2, sobol-series1; every scene and epistemic
draw of them), each rebuilt as a scene from its numeric inputs on its configuration. A fraction
of the alumina and quartz samples is drawn a second time with the report's constant target
replaced by the temperature-dependent one (``target="alumina-85"`` or ``"fused-quartz"``, whose
k(T) and c(T) tables the shipped studies move to), the inputs other than the target's kept.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
STUDIES = ("paper-series1", "paper-series2", "sobol-series1")

#: The temperature-dependent target that replaces a scene's constant ceramic (by scene name).
TABLE_TARGETS = {"alumina": "alumina-85", "quartz": "fused-quartz"}


def _numeric_keys():
    from skidmc.scene import NUMERIC_KEYS

    return NUMERIC_KEYS


def study_samples(study, n, rng):
    """``n`` samples of ``study``'s ensemble: list of (label, scene name, {key: SI float},
    configuration)."""
    import skidmc

    ds = skidmc.open_ensemble(ROOT / "results" / study / "ensemble.h5")
    keys = _numeric_keys()
    shape = ds["critical_height"]
    done = np.asarray(ds["done"].broadcast_like(shape)).ravel().astype(bool)
    cols = {k: np.asarray(ds[k].broadcast_like(shape), dtype=float).ravel() for k in keys}
    config = np.asarray(ds["configuration"].broadcast_like(shape)).ravel()
    scene_names = (np.asarray(ds["scene"].broadcast_like(shape)).ravel()
                   if "scene" in ds.coords else np.full(shape.size, study))
    ok = done & np.all([~np.isnan(cols[k]) for k in keys], axis=0)
    picks = rng.choice(np.flatnonzero(ok), size=n, replace=False)
    return [(f"{study}[{i}]", str(scene_names[i]), {k: float(cols[k][i]) for k in keys},
             str(config[i])) for i in sorted(picks)]


def build_scene(values, configuration, target=None):
    """The scene of a sample's inputs [SI] on its configuration (and `target`, a material name
    replacing the sample's target properties)."""
    import skidmc

    values = {k: v for k, v in values.items() if not (k == "target.hardness" and math.isinf(v))}
    scene = skidmc.make_scene(values, preset="paper-quartz", check_plausible=False,
                              configuration=configuration)
    if target is not None:
        scene = scene.replace(target=target, check_plausible=False)
    return scene


def draw(n_per_study=60, seed=45, table_fraction=0.5):
    """Study scenes: list of (label, group, scene); ``group`` names the study and, for a
    temperature-dependent target, the material."""
    rng = np.random.default_rng(seed)
    out = []
    for study in STUDIES:
        for label, name, values, configuration in study_samples(study, n_per_study, rng):
            out.append((label, study, build_scene(values, configuration)))
            material = next((m for key, m in TABLE_TARGETS.items() if key in name), None)
            if material is not None and rng.random() < table_fraction:
                out.append((f"{label}:{material}", f"{study}:{material}",
                            build_scene(values, configuration, material)))
    return out


def presets():
    """The report's presets and their temperature-dependent-target variants: (label, group,
    scene)."""
    import skidmc
    from skidmc.scene import list_presets

    out = []
    for name in list_presets():
        scene = skidmc.get_preset(name)
        out.append((name, "preset", scene))
        material = next((m for key, m in TABLE_TARGETS.items() if key in name), None)
        if material is not None:
            out.append((f"{name}:{material}", f"preset:{material}", scene.replace(target=material)))
    return out
