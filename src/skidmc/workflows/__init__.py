"""Runners of every kind of study, looked up by name (:mod:`skidmc.workflows.registry`).

Each kind is one module: :mod:`~skidmc.workflows.ensemble` (a plain ensemble over a design),
:mod:`~skidmc.workflows.sobol` (a saltelli design grown until its Sobol' indices are stable),
:mod:`~skidmc.workflows.hazard` (the probability per handling accident). They orchestrate the
layers below (:mod:`skidmc.ensemble`: study formats, designs, executors, storage;
:mod:`skidmc.analysis`: the computations) and write through :mod:`skidmc.ensemble.storage`;
``skidmc run`` and ``skidmc report`` find them here and nowhere else.
"""

from skidmc.workflows.registry import (
    KINDS,
    Outcome,
    ReportOptions,
    RunOptions,
    check_options,
    get_kind,
    kind_of_file,
    kind_of_result,
    load,
)

__all__ = ["KINDS", "Outcome", "ReportOptions", "RunOptions", "check_options", "get_kind",
           "kind_of_file", "kind_of_result", "load"]
