"""Analysis of ensemble results: functions of arrays and Datasets that compute.

Every analysis reads a result file through :func:`skidmc.ensemble.storage.open_ensemble` (also
exported here and from :mod:`skidmc`), which checks what it opens and hands back plain xarray;
the runners that orchestrate studies are :mod:`skidmc.workflows`. Modules:

- :mod:`~skidmc.analysis.gonogo`: go/no-go statistics (probit with profile-likelihood intervals,
  Dixon-Mood up-down, censored log-normal fits, empirical go curves with simultaneous bands,
  scores);
- :mod:`~skidmc.analysis.experiments`: the report's drops, 50 % heights and friction;
- :mod:`~skidmc.analysis.sensitivity`: Sobol' indices with bootstrap intervals, groups, Morris;
- :mod:`~skidmc.analysis.rare_events` and :mod:`~skidmc.analysis.hazard`: rare-event
  probabilities and the drop-height hazard estimator;
- :mod:`~skidmc.analysis.report`: what ``skidmc report`` says about an ensemble, computed
  (written by :mod:`skidmc.workflows.reporting`).

Figures are drawn by functions that take a matplotlib ``ax``; nothing here imports matplotlib at
import time.
"""

from __future__ import annotations

from skidmc.analysis.experiments import EXPERIMENTS, get_experiment
from skidmc.analysis.gonogo import (
    compare_h50,
    fit_lognormal,
    fit_probit,
    go_curve,
    score_drops,
    updown,
)
from skidmc.analysis.hazard import drop_height_probability
from skidmc.analysis.planning import SequentialPlan, next_drop  # noqa: F401
from skidmc.analysis.posterior import physics_prior, probit_posterior  # noqa: F401
from skidmc.analysis.rare_events import rare_event_probability
from skidmc.analysis.sensitivity import (
    grow_until_stable,
    morris_screening,
    sobol_convergence,
    sobol_indices,
    sobol_stable,
)
from skidmc.ensemble.storage import open_ensemble

__all__ = [
    "EXPERIMENTS",
    "compare_h50",
    "drop_height_probability",
    "fit_lognormal",
    "fit_probit",
    "get_experiment",
    "go_curve",
    "grow_until_stable",
    "morris_screening",
    "open_ensemble",
    "rare_event_probability",
    "score_drops",
    "sobol_convergence",
    "sobol_indices",
    "sobol_stable",
    "updown",
]
