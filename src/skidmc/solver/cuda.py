"""GPU backend of the full tier: one CUDA thread per scene runs :mod:`skidmc.solver.device`.

:func:`critical_heights` is the batch front end of both backends: ``backend="cuda"`` launches
:func:`skidmc.solver.device.critical_height_core` one thread per scene, with the thread's mesh,
integrator state and search in its local memory and no host round trip per simulation;
``backend="cpu"`` runs the same compiled function on the CPU's threads (the reference the GPU
is compared with, and a multi-threaded CPU batch). Scenes the device search hands back
(``STATUS_CPU``: see :mod:`skidmc.solver.device`) are then solved by
:func:`skidmc.solver.critical_height` on the host, so every scene gets the full tier's result.

The CUDA machinery (``numba.cuda``) is imported only when ``backend="cuda"`` is asked for; a
machine without a usable GPU gets a :class:`CudaUnavailableError` naming what is missing. With
``NUMBA_ENABLE_CUDASIM=1`` numba's CUDA simulator runs the kernel on the CPU (the tests do this:
the kernel's indexing, local arrays and launch are then checked without a GPU).

numba-cuda 0.30.4 refers to ``numpy.row_stack``, which NumPy 2.5 removed: every kernel then
fails to compile with ``AttributeError: module 'numpy' has no attribute 'row_stack'``. Before
the first compilation :func:`_numba_cuda` restores the name as ``numpy.vstack`` (its documented
equivalent) when it is missing; nothing else in the package uses it.
"""

from __future__ import annotations

import math
import os
import time

import numpy as np

from skidmc.errors import SceneError
from skidmc.physics.fast import N_TIMES
from skidmc.physics.records import KERNEL_RUN
from skidmc.solver.adaptive import PAIR_STATE, POINTS_SHAPE, RESULT_SIZE, SEARCH_POINTS
from skidmc.solver.device import (
    HISTORY_SHAPE,
    MAX_CELLS,
    PREFIX_SIZE,
    WORK_ROWS,
    critical_height_core,
)
from skidmc.solver.finders import FINDER_STATE

__all__ = [
    "BACKENDS",
    "CudaUnavailableError",
    "THREADS_PER_BLOCK",
    "critical_heights",
    "cpu_only_reason",
    "cuda_status",
    "solve_scenes",
]

#: Backends of :func:`critical_heights` (and of ``[solver] backend`` in a study).
BACKENDS = ("cpu", "cuda")

#: Threads per CUDA block. Each thread holds ~77 KB of local memory (its HE mesh and integrator
#: state, :data:`skidmc.solver.device.MAX_CELLS`, and the exact target's flux history,
#: :data:`skidmc.solver.device.HISTORY_SHAPE`; ptxas for sm_90, docs/gpu.md), so blocks are
#: kept small.
THREADS_PER_BLOCK = 64

#: Scenes per kernel launch: bounds the device memory of one launch and lets a long batch
#: report progress and be interrupted between launches.
LAUNCH_SIZE = 1 << 18


class CudaUnavailableError(RuntimeError):
    """``backend="cuda"`` was asked for where no usable GPU (or CUDA toolchain) is found."""


def _numba_cuda():
    """``numba.cuda``, with the NumPy 2.5 compatibility name restored (module docstring)."""
    global cuda
    if cuda is None:
        if not hasattr(np, "row_stack"):
            np.row_stack = np.vstack
        from numba import cuda as numba_cuda

        cuda = numba_cuda
    return cuda


def cuda_status() -> tuple[bool, str]:
    """(usable, why not): whether ``backend="cuda"`` can run here, and if not, what is missing."""
    try:
        numba_cuda = _numba_cuda()
    except Exception as exc:  # noqa: BLE001 - any import failure means the same to the user
        return False, f"numba's CUDA support cannot be imported ({type(exc).__name__}: {exc})"
    if os.environ.get("NUMBA_ENABLE_CUDASIM") == "1":
        return True, "numba's CUDA simulator (NUMBA_ENABLE_CUDASIM=1): correct but slow"
    try:
        if numba_cuda.is_available():
            return True, ""
        numba_cuda.detect()
    except Exception as exc:  # noqa: BLE001
        return False, f"no usable CUDA GPU: {type(exc).__name__}: {' '.join(str(exc).split())}"
    return False, ("no usable CUDA GPU: numba.cuda.is_available() is False (no NVIDIA driver "
                   "or device found; install the driver and numba-cuda, or use backend='cpu')")


# The kernel's module-level names: ``cuda`` is bound to numba.cuda on first use (the CPU path
# never imports it); the array shapes are compile-time constants of the kernel.
cuda = None
_WORK_SHAPE = (WORK_ROWS, MAX_CELLS)
_HISTORY_SHAPE = HISTORY_SHAPE
_FAST_SHAPE = (3, N_TIMES)
_POINTS_SHAPE = (2,) + POINTS_SHAPE   # the pair's two searches' points
_KERNEL = None


def _thread(rows, rtol, h_min, h_max, melt_spread, melting, runaway_fraction, table, gl_x, gl_w,
            out):
    """One thread: the device search of scene ``rows[i]`` into ``out[i]`` (compiled by
    :func:`_kernel`)."""
    i = cuda.grid(1)
    if i < rows.shape[0]:
        # The thread's whole state: mesh, integrator arrays, search brackets (local memory).
        work = cuda.local.array(_WORK_SHAPE, np.float64)
        history = cuda.local.array(_HISTORY_SHAPE, np.float64)
        fast_work = cuda.local.array(_FAST_SHAPE, np.float64)
        info = cuda.local.array(1, KERNEL_RUN)   # the current run's input and outcome
        prefix = cuda.local.array(PREFIX_SIZE, np.float64)   # the search's linear prefix
        ps = cuda.local.array(1, PAIR_STATE)   # the search machine's state
        res = cuda.local.array((2, RESULT_SIZE), np.float64)
        pts = cuda.local.array(_POINTS_SHAPE, np.float64)
        st = cuda.local.array(1, FINDER_STATE)   # the root finder's state
        fpts = cuda.local.array((2, SEARCH_POINTS), np.float64)
        _core(rows[i], rtol, h_min, h_max, melt_spread, melting, runaway_fraction, table, gl_x,
              gl_w, work, history, fast_work, info, prefix, ps, res, pts, st, fpts, out[i])


#: The types of :func:`_thread`'s arguments, in order: what ``scripts/compile_cuda_ptx.py``
#: compiles ahead of a GPU (tests/test_device.py checks that it names every argument).
THREAD_SIGNATURE = ("void(float64[:, ::1], float64, float64, float64, float64, boolean, float64, "
                    "float64[::1], float64[::1], float64[::1], float64[:, ::1])")


# What a thread calls: the compiled search itself on a GPU (numba compiles the njit function
# for the device). Numba's CUDA simulator runs the kernel as Python and hands it array
# wrappers that a compiled function cannot take, so there :func:`_simulated_core` unwraps them
# and calls the CPU build of the same function.
_core = critical_height_core


def _simulated_core(*args):
    """:func:`critical_height_core` on the NumPy arrays behind the simulator's wrappers."""
    plain = []
    for a in args:
        while hasattr(a, "_item"):          # FakeWithinKernelCUDAArray -> FakeCUDAArray
            a = a._item
        plain.append(getattr(a, "_ary", a))  # FakeCUDAArray -> ndarray
    critical_height_core(*plain)


def _kernel():
    """The CUDA kernel of :func:`_thread` (compiled on first use)."""
    global _KERNEL, _core
    if _KERNEL is None:
        numba_cuda = _numba_cuda()
        if os.environ.get("NUMBA_ENABLE_CUDASIM") == "1":
            _core = _simulated_core
        _KERNEL = numba_cuda.jit(_thread)
    return _KERNEL


def critical_heights(rows, rtol=1e-3, h_min=1e-3, h_max=1e4, *, backend="cuda", melting=True,
                     runaway_fraction=None, progress=None):
    """Device-search results of many scenes: one row of :data:`device.OUT_SIZE` floats each.

    Parameters
    ----------
    rows : ndarray, shape (n, 19)
        Scenes as rows of SI floats in the order of :data:`skidmc.solver.fast.SCENE_FIELDS`
        (already validated: :class:`skidmc.scene.Scene` ranges).
    rtol : float
        Relative tolerance on the critical height [1].
    h_min, h_max : float
        Search bounds [m].
    backend : {"cuda", "cpu"}
        Where :func:`skidmc.solver.device.critical_height_core` runs.
    melting : bool
        Model melting of the HE.
    runaway_fraction : float, optional
        Override of the runaway rule.
    progress : callable, optional
        Called as ``progress(done, total)`` after each launch.

    Returns
    -------
    out : ndarray, shape (n, OUT_SIZE)
        See the ``OUT_*`` layout of :mod:`skidmc.solver.device`. Rows with
        ``out[:, OUT_STATUS] == STATUS_CPU`` still need the CPU search.
    seconds : float
        Wall time of the device part [s] (kernel launches and transfers, or the CPU threads).
    """
    from skidmc.physics.fast import _GL_W01, _GL_X01, MELT_TABLE
    from skidmc.physics.thermal import DEFAULT_RUNAWAY_FRACTION, MELT_SPREAD
    from skidmc.solver.device import OUT_SIZE, critical_heights_cpu

    if backend not in BACKENDS:
        raise SceneError("backend", backend, f"expected one of {', '.join(BACKENDS)}")
    if not (isinstance(rtol, (int, float)) and 0.0 < rtol < 0.5):
        raise SceneError("rtol", rtol, "must be a number in (0, 0.5)")
    if not (0.0 < h_min < h_max):
        raise SceneError("h_min", h_min, f"need 0 < h_min < h_max (h_max = {h_max!r})")
    rows = np.ascontiguousarray(rows, dtype=np.float64)
    if rows.ndim != 2 or rows.shape[1] != 19:
        raise ValueError(f"rows must have shape (n, 19), got {rows.shape}")
    runaway = DEFAULT_RUNAWAY_FRACTION if runaway_fraction is None else float(runaway_fraction)
    # Each scene's plan (first pair, melting width, root tolerances) is made on the device from
    # rtol, as the CPU search makes it; the melting spread is the CPU search's default.
    args = (float(rtol), float(h_min), float(h_max), float(MELT_SPREAD), bool(melting), runaway)
    n = rows.shape[0]
    out = np.zeros((n, OUT_SIZE))
    start = time.perf_counter()
    if backend == "cpu":
        for lo in range(0, n, LAUNCH_SIZE):
            hi = min(n, lo + LAUNCH_SIZE)
            critical_heights_cpu(rows[lo:hi], *args, MELT_TABLE, _GL_X01, _GL_W01, out[lo:hi])
            if progress is not None:
                progress(hi, n)
        return out, time.perf_counter() - start
    usable, why = cuda_status()
    if not usable:
        raise CudaUnavailableError(f"backend='cuda' cannot run here: {why}")
    numba_cuda = _numba_cuda()
    kernel = _kernel()
    tables = [numba_cuda.to_device(np.ascontiguousarray(a)) for a in (MELT_TABLE, _GL_X01, _GL_W01)]
    for lo in range(0, n, LAUNCH_SIZE):
        hi = min(n, lo + LAUNCH_SIZE)
        d_rows = numba_cuda.to_device(rows[lo:hi])
        d_out = numba_cuda.device_array((hi - lo, OUT_SIZE), dtype=np.float64)
        blocks = math.ceil((hi - lo) / THREADS_PER_BLOCK)
        kernel[blocks, THREADS_PER_BLOCK](d_rows, *args, *tables, d_out)
        out[lo:hi] = d_out.copy_to_host()
        if progress is not None:
            progress(hi, n)
    return out, time.perf_counter() - start


#: Options of :func:`skidmc.solver.critical_height` that the device search takes; any other
#: (a forced level, method, model, ...) is refused by name.
_DEVICE_OPTIONS = ("rtol", "tier", "h_min", "h_max", "melting", "runaway_fraction")


def cpu_only_reason(scene, rtol=1e-2, *, melting=True, runaway_fraction=None):
    """Why the device search cannot take ``scene`` (a model term), or None where it can.

    The device's target is homogeneous with constant properties (a row of floats, the exact
    target): a stack whose heat reaches below its top layer (``"layered_target"``) or a target
    whose k and c follow its temperature table by more than the property budget at ``rtol``
    (``"temperature_target"``) is solved by the CPU search, which meshes it
    (:func:`solve_scenes` hands such scenes to its fallback, on this process's threads).
    """
    if not (scene.target_layers or scene.target_table):
        return None
    from skidmc.solver.model import build_model

    extra = {} if runaway_fraction is None else {"runaway_fraction": runaway_fraction}
    terms = build_model(scene, meshes=False, melting=melting, rtol=rtol, **extra).terms
    return next((t for t in ("layered_target", "temperature_target") if t in terms), None)


def solve_scenes(scenes, *, backend="cuda", fallback=None, rtol=1e-3, tier="full",
                 h_min=1e-3, h_max=1e4, melting=True, runaway_fraction=None, threads=None,
                 **options):
    """Full-tier results of many scenes through the device search, one per scene, in order.

    Parameters
    ----------
    scenes : sequence of skidmc.scene.Scene
    backend : {"cuda", "cpu"}
        Where the device search runs (:func:`critical_heights`).
    fallback : callable, optional
        Solver for the scenes the device cannot take (:func:`cpu_only_reason`) or hands back
        (default :func:`skidmc.solver.critical_height`), called as ``fallback(scene, rtol=,
        h_min=, h_max=, melting=, runaway_fraction=)``.
    rtol, tier, h_min, h_max, melting, runaway_fraction
        As :func:`skidmc.solver.critical_height`; ``tier`` must be "full".
    threads : int, optional
        Threads that run the fallback on those scenes (the solver's kernels release the GIL,
        so they run side by side; the results are the same on any number). Default: every
        CPU this process may use where the fallback is :func:`skidmc.solver.critical_height`,
        1 for any other (a caller's solver need not be thread-safe).

    Returns
    -------
    list
        A :class:`~skidmc.solver.HeightResult` per scene (``method`` "device" where the device
        search answered, the fallback's result otherwise), or the exception the fallback
        raised for that scene.
    """
    from concurrent.futures import ThreadPoolExecutor

    from skidmc._system import available_cpus
    from skidmc.physics.fast import CENSOR_NAMES
    from skidmc.physics.mechanics import EXIT_KINDS
    from skidmc.solver import device
    from skidmc.solver.fast import SCENE_FIELDS, _scene_values
    from skidmc.solver.model import build_model
    from skidmc.solver.results import HeightResult
    from skidmc.solver.search import critical_height

    if options:
        key = sorted(options)[0]
        raise SceneError(key, options[key], f"not an option of backend={backend!r} (it takes "
                         f"{', '.join(_DEVICE_OPTIONS)})")
    if tier != "full":
        raise SceneError("tier", tier, f"backend={backend!r} runs the full tier; the fast tier "
                         "runs on the CPU (backend='cpu')")
    if threads is not None and (isinstance(threads, bool) or not isinstance(threads, int)
                                or threads < 1):
        raise SceneError("threads", threads, "must be an integer >= 1 (or None)")
    if fallback is None:
        fallback = critical_height
    if threads is None:
        threads = available_cpus() if fallback is critical_height else 1
    scenes = list(scenes)
    extra = {} if runaway_fraction is None else {"runaway_fraction": runaway_fraction}
    # Scenes a row of floats cannot carry never reach the device.
    take = [i for i, scene in enumerate(scenes)
            if cpu_only_reason(scene, rtol, melting=melting,
                               runaway_fraction=runaway_fraction) is None]
    rows = np.array([_scene_values(scenes[i]) for i in take],
                    dtype=np.float64).reshape(len(take), len(SCENE_FIELDS))
    out = (critical_heights(rows, rtol, h_min, h_max, backend=backend, melting=melting,
                            runaway_fraction=runaway_fraction)[0] if take
           else np.zeros((0, device.OUT_SIZE)))
    results = [None] * len(scenes)
    for i, o in zip(take, out):
        if o[device.OUT_STATUS] != device.STATUS_OK:
            continue
        scene = scenes[i]
        model = build_model(scene, meshes=False, melting=melting, rtol=rtol, **extra)
        height = float(o[device.OUT_HEIGHT])
        censored = CENSOR_NAMES[int(o[device.OUT_CENSOR])]
        results[i] = HeightResult(
            critical_height=height, censored=censored,
            evaluations=int(o[device.OUT_EVALUATIONS]),
            flags=model.flags + model.height_flags(height),
            error_estimate=float(o[device.OUT_ERROR]), rtol=float(rtol),
            level=float(o[device.OUT_LEVEL]), method="device",
            exit_time=float(o[device.OUT_EXIT_TIME]),
            exit_kind=EXIT_KINDS[int(o[device.OUT_EXIT_CODE])], terms=model.terms,
            extrapolated=censored is None,
            richardson_correction=float(o[device.OUT_CORRECTION]),
            melt_bias_estimate=float(o[device.OUT_MELT_BIAS]))

    def solve(i):
        try:
            return fallback(scenes[i], rtol=rtol, h_min=h_min, h_max=h_max, melting=melting,
                            **extra)
        except Exception as exc:  # noqa: BLE001 - the caller records it per sample
            return exc

    rest = [i for i, res in enumerate(results) if res is None]
    if threads > 1 and len(rest) > 1:
        with ThreadPoolExecutor(min(threads, len(rest)), thread_name_prefix="skidmc") as pool:
            answers = list(pool.map(solve, rest))
    else:
        answers = [solve(i) for i in rest]
    for i, res in zip(rest, answers):
        results[i] = res
    return results
