"""The critical drop height of a scene.

- :mod:`~skidmc.solver.model`: what a scene needs (terms, exits, meshes, validity flags).
- :mod:`~skidmc.solver.plan`: the accuracy plan and its calibrated error model.
- :mod:`~skidmc.solver.simulate`: one impact at one drop height.
- :mod:`~skidmc.solver.roots`: root finders, pure functions of a margin.
- :mod:`~skidmc.solver.search`: :func:`critical_height`, the search itself.
- :mod:`~skidmc.solver.fast`: the fast tier at the scene level.
- :mod:`~skidmc.solver.results`: :class:`HeightResult`.
"""

from skidmc.solver.model import FLAG_MEANINGS, SkidModel, build_model
from skidmc.solver.results import FT, HeightResult
from skidmc.solver.search import DEFAULT_H_MAX, DEFAULT_H_MIN, TIERS, critical_height
from skidmc.solver.simulate import Simulation, SolverError, simulate

__all__ = [
    "DEFAULT_H_MAX",
    "DEFAULT_H_MIN",
    "FLAG_MEANINGS",
    "FT",
    "TIERS",
    "HeightResult",
    "Simulation",
    "SkidModel",
    "SolverError",
    "build_model",
    "critical_height",
    "simulate",
]
