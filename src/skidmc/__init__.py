"""skidmc: the oblique-impact ("skid test") initiation model of HE billets.

Critical drop heights of hemispherical billets sliding on a target (Los Alamos report "Effect of
Target Thermal Conductivity and Roughness on the Initiation of PBX 9404 by Oblique Impact"),
ensembles over uncertain inputs, sensitivity and hazard. See ``docs/architecture.md``.

The scene layer is re-exported here lazily, so that importing a kernel module
(``skidmc.mechanics``) does not pay for pint::

    >>> import skidmc
    >>> scene = skidmc.make_scene(preset="paper-quartz", mu="0.1")
"""

from __future__ import annotations

from importlib import import_module
from importlib.metadata import PackageNotFoundError, version

try:
    __version__ = version("skidmc")
except PackageNotFoundError:  # running from a source tree that is not installed
    __version__ = "0+unknown"

# name -> module that defines it; resolved on first attribute access (PEP 562)
_LAZY = {
    "Scene": "skidmc.scene",
    "make_scene": "skidmc.scene",
    "SCENE_KEYS": "skidmc.scene",
    "SI_UNITS": "skidmc.scene",
    "get_preset": "skidmc.scene",
    "list_presets": "skidmc.scene",
    "SkidmcError": "skidmc.errors",
    "SceneError": "skidmc.errors",
    "UnknownKeyError": "skidmc.errors",
    "UnitError": "skidmc.errors",
}

__all__ = [  # noqa: RUF022 (grouped as in _LAZY)
    "__version__",
    "Scene",
    "make_scene",
    "SCENE_KEYS",
    "SI_UNITS",
    "get_preset",
    "list_presets",
    "SkidmcError",
    "SceneError",
    "UnknownKeyError",
    "UnitError",
]


def __getattr__(name: str):
    if name in _LAZY:
        value = getattr(import_module(_LAZY[name]), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module 'skidmc' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_LAZY))
