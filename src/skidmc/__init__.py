"""skidmc: the oblique-impact ("skid test") initiation model of HE billets.

Critical drop heights of hemispherical billets sliding on a target (Los Alamos report "Effect of
Target Thermal Conductivity and Roughness on the Initiation of PBX 9404 by Oblique Impact"),
ensembles over uncertain inputs, their analysis (go-probability curves, sensitivity, hazard).
See ``docs/architecture.md`` for the layers.

The front door: the names a user needs, resolved on first use (PEP 562), so that ``import
skidmc`` stays fast and importing a kernel module does not pay for pint, scipy.stats or h5py::

    >>> import skidmc
    >>> scene = skidmc.make_scene(preset="paper-quartz", mu="0.1")
    >>> skidmc.critical_height(scene, rtol=1e-2).critical_height  # doctest: +SKIP
"""

from __future__ import annotations

from importlib import import_module
from importlib.metadata import PackageNotFoundError, version

from skidmc._numba_cache import configure as _configure_numba_cache

# Before any kernel is compiled: in a source checkout, numba's cache keyed by the source
# (skidmc/_numba_cache.py says why).
_configure_numba_cache()

try:
    __version__ = version("skidmc")
except PackageNotFoundError:  # running from a source tree that is not installed
    __version__ = "0+unknown"

# name -> module that defines it; resolved on first attribute access (PEP 562)
_LAZY = {
    # scenes
    "Scene": "skidmc.scene",
    "make_scene": "skidmc.scene",
    "get_preset": "skidmc.scene",
    "list_presets": "skidmc.scene",
    "SCENE_KEYS": "skidmc.scene",
    "SI_UNITS": "skidmc.scene",
    # solver
    "critical_height": "skidmc.solver",
    "HeightResult": "skidmc.solver",
    # ensembles
    "load_study": "skidmc.ensemble.study",
    "run_study": "skidmc.ensemble.run",
    "evaluate_batch": "skidmc.ensemble.batch",
    # analysis
    "open_ensemble": "skidmc.ensemble.storage",
    # errors
    "SkidmcError": "skidmc.errors",
    "SceneError": "skidmc.errors",
    "UnknownKeyError": "skidmc.errors",
    "UnitError": "skidmc.errors",
}

__all__ = ["__version__", *_LAZY]  # noqa: PLE0604 (names resolved by __getattr__)


def __getattr__(name: str):
    if name in _LAZY:
        value = getattr(import_module(_LAZY[name]), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module 'skidmc' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_LAZY))
