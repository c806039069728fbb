"""Imported by the forkserver of the local worker processes, once, before it forks any worker.

Importing this module loads the solver's compiled kernels into the forkserver: numba's own
start (its typing and lowering registries, which import scipy.linalg, ~0.3-0.5 s) and each
kernel's load from numba's on-disk cache (~0.1-0.2 s), by the warm-up solve of
:func:`skidmc.ensemble.executors._warm_worker`. Every worker forked afterwards starts with
them loaded, instead of loading them itself (``docs/performance.md``: a pool of 2 workers
took ~0.6 s of CPU per worker to warm up).

The import never fails: the forkserver ignores only ImportError from its preloads, so anything
else is swallowed here, and a worker then loads the kernels in its own warm-up as before. The
forkserver is single-threaded and the warm-up solve runs no parallel kernel, so no threading
layer is started before the forks.
"""

from __future__ import annotations

__all__: list[str] = []


def _warm() -> None:
    try:
        from skidmc.ensemble.executors import _WARM_UP
        from skidmc.scene import get_preset
        from skidmc.solver import critical_height

        critical_height(get_preset("paper-quartz"), **_WARM_UP)
    except Exception:  # noqa: BLE001, S110 - a warm-up only (module docstring)
        pass


_warm()
