"""A solver that keeps its calls: resume and replay for the kinds of study whose work is a
sequence of adaptive solver calls (the hazard estimator; a calibration's sampler).

:class:`RecordedSolver` wraps a solver of :func:`skidmc.ensemble.batch.evaluate_batch`'s
signature. Call k is answered from an :class:`skidmc.ensemble.storage.EvaluationLog` when the log
holds a call k with the same digest (inputs, base scene, options), else computed and kept.
Given its seeds an estimator asks the same calls in the same order, so a run resumed after
Ctrl-C or kill -9 reaches the numbers of an uninterrupted one, and a report replays a complete
log without a solver run.
"""

from __future__ import annotations

import hashlib
from collections.abc import Callable, Mapping

import numpy as np

__all__ = ["RecordedSolver", "call_digest"]


def call_digest(columns: Mapping[str, np.ndarray], options, base) -> str:
    """sha256 of a solver call: its columns (names and float64 bytes), base scene, options."""
    h = hashlib.sha256()
    for key in sorted(columns):
        h.update(key.encode() + b"\0")
        h.update(np.ascontiguousarray(columns[key], dtype=np.float64).tobytes())
    h.update(repr(sorted(base.as_dict().items())).encode())
    h.update(repr(options).encode())
    return h.hexdigest()


class RecordedSolver:
    """The solver, answering from an :class:`~skidmc.ensemble.storage.EvaluationLog` the
    calls it holds (same digest, same place in the sequence) and keeping every new one."""

    def __init__(self, solver: Callable, log, replay_only: bool) -> None:
        from skidmc.ensemble.storage import LoggedCall

        self._make = LoggedCall
        self.solver, self.log, self.replay_only = solver, log, replay_only
        self.kept = log.load() if log.info()["exists"] else []
        self.calls: list = []
        self.computed = 0

    def __call__(self, columns, options, **kwargs):
        import types

        from skidmc.ensemble.storage import StorageError

        i = len(self.calls)
        digest = call_digest(columns, options, kwargs["base"])
        if i < len(self.kept) and self.kept[i].digest == digest:
            call = self.kept[i]
        else:
            if self.replay_only:
                from skidmc.ensemble.storage import blas_kernels, library_versions

                info = self.log.info()
                logged, here = info.get("libraries", ""), library_versions()
                logged_blas, here_blas = info.get("blas", ""), blas_kernels()
                why = (f"; the log was computed with {logged}, this machine has {here}, and a "
                       "call's inputs are compared to the last bit" if logged and logged != here
                       else f"; the log's BLAS kernels are {logged_blas or 'not recorded'}, "
                       f"this machine's {here_blas}, and a call's inputs are compared to the "
                       "last bit: another CPU's kernels move them" if logged_blas != here_blas
                       else "")
                raise StorageError(self.log.path, f"holds {len(self.kept)} solver calls that "
                                   f"do not cover this study's estimate (call {i} differs or "
                                   f"is missing{why}): finish it with skidmc run --resume, or "
                                   "recompute it with skidmc run --force")
            if i < len(self.kept):  # another computation from here on: forget the rest
                self.kept = self.kept[:i]
                self.log.drop_from(i)
            res = self.solver(columns, options, **kwargs)
            n = len(next(iter(columns.values())))
            call = self._make(
                digest, np.asarray(res.critical_height, dtype=float),
                np.asarray(res.status).astype(str).astype(object),
                np.asarray(getattr(res, "failure_reason", [""] * n), dtype=object))
            self.log.append(i, call)
            self.computed += n
        self.calls.append(call)
        return types.SimpleNamespace(critical_height=call.critical_height, status=call.status,
                                     failure_reason=call.failure_reason)
