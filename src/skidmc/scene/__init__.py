"""Scenes: the named inputs of one simulation, their units, checks, materials and presets.

``make_scene(preset="paper-quartz", mu=0.2, target="steel")`` builds a validated
:class:`Scene` (SI floats) from a preset, a named target material and overrides given as SI
floats or unit strings (``"28000 psi"``). Every input key is defined once, in
:mod:`skidmc.scene.keys` (:data:`INPUT_KEYS`); the materials are :mod:`skidmc.scene.materials`.
"""

from skidmc.scene.keys import (
    CONFIGURATIONS,
    DESCRIPTIONS,
    INPUT_KEYS,
    NUMERIC_KEYS,
    SCENE_KEYS,
    SI_UNITS,
    InputKey,
)
from skidmc.scene.materials import MATERIALS, Material, get_material, list_materials
from skidmc.scene.presets import PRESETS
from skidmc.scene.scenes import Scene, SceneColumns, get_preset, list_presets, make_scene

__all__ = [
    "CONFIGURATIONS",
    "DESCRIPTIONS",
    "INPUT_KEYS",
    "MATERIALS",
    "NUMERIC_KEYS",
    "PRESETS",
    "SCENE_KEYS",
    "SI_UNITS",
    "InputKey",
    "Material",
    "Scene",
    "SceneColumns",
    "get_material",
    "get_preset",
    "list_materials",
    "list_presets",
    "make_scene",
]
