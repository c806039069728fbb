"""Shared test material: paths, the tiny studies, and stand-in solvers.

The stand-ins are injected (``evaluate_batch(..., solver=fake_height)``, ``run_study(...,
solver=...)``), never patched into :mod:`skidmc.solver`. They are module-level functions, so that
they pickle by reference into worker processes (which import this module from ``tests/``, on the
``sys.path`` that pytest set up and the workers inherit).
"""

from __future__ import annotations

import math
import multiprocessing
import os
import types
from pathlib import Path

import pytest

from skidmc._numba_cache import clean_other_caches, source_cache_dir

#: The repository root (``src/`` holds the package).
ROOT = Path(__file__).resolve().parents[1]


def _numba_cache_for_this_source():
    """Point numba's on-disk cache at a directory keyed by a hash of the package's source.

    Numba invalidates a cached function only when its own file changes: the constants it read
    from other modules (e.g. ``plan.RICHARDSON_RESIDUAL_RATIO`` in ``solver.device``) and the
    callees it compiled in stay as they were. A cache left by other source could then make a
    test pass or fail. Keyed by the source, every edit gets a fresh cache (one compile per
    source version, shared by the workers and CLI subprocesses the tests start, which inherit
    the variable). ``import skidmc`` does the same in a source checkout
    (:mod:`skidmc._numba_cache`); here it is forced, over any ``NUMBA_CACHE_DIR`` already set
    and whatever way the package was installed, and every other version's cache is removed.
    Set before anything imports numba (``import skidmc`` does not).
    """
    here = source_cache_dir(ROOT / "src" / "skidmc")
    clean_other_caches(here, keep=0, keep_younger_than=0.0)
    os.environ["NUMBA_CACHE_DIR"] = str(here)


_numba_cache_for_this_source()

#: Two scenes x 12 samples, four uncertain keys, a correlation: the runner's test study.
TINY = """
[study]
name = "tiny"
[[scenes]]
name = "quartz"
preset = "paper-quartz"
[[scenes]]
name = "alumina"
preset = "paper-alumina-smooth"
[uncertain.mu]
distribution = "lognorm"
s = 0.1
relative = true
source = "test"
[uncertain."target.conductivity"]
distribution = "truncnorm"
a = -3
b = 3
loc = 1.0
scale = 0.1
relative = true
source = "test"
[uncertain."kinetics.activation_temperature"]
distribution = "uniform"
loc = "24000 K"
scale = "4000 K"
source = "test"
[uncertain."kinetics.prefactor"]
distribution = "lognorm"
s = 0.5
relative = true
source = "test"
[[correlation]]
keys = ["kinetics.activation_temperature", "kinetics.prefactor"]
spearman = 0.8
source = "test"
[design]
method = "mc"
n = 12
seed = 2024
[solver]
rtol = 1e-2
"""

#: Two scenes x 10 samples with an extra sampled key: the storage tests' study.
STORAGE_TEXT = """
[study]
name = "storage-test"
description = "two scenes"
[[scenes]]
name = "quartz"
preset = "paper-quartz"
[[scenes]]
name = "gold"
preset = "paper-gold"
[uncertain.mu]
distribution = "lognorm"
s = 0.2
relative = true
source = "test"
[uncertain."kinetics.rate_at_reference"]
distribution = "lognorm"
s = 1.0
relative = true
reference_temperature = "575 K"
source = "test"
[design]
method = "mc"
n = 10
seed = 42
[solver]
rtol = 1e-2
"""


def subprocess_env(*first: str | os.PathLike) -> dict:
    """The environment for a subprocess that must import this worktree's skidmc (`first`
    folders ahead of it on PYTHONPATH)."""
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [*map(str, first), str(ROOT / "src"),
                                                      env.get("PYTHONPATH")]))
    return env


# --- stand-ins for skidmc.solver.critical_height -------------------------------------------------


def _result(h: float, h_min: float, h_max: float, flags=("stand_in",)):
    censored = "above" if h > h_max else "below" if h < h_min else None
    return types.SimpleNamespace(critical_height=min(max(h, h_min), h_max), censored=censored,
                                 evaluations=3, flags=flags, wall_time=1e-6)


def fake_height(scene, rtol=1e-3, tier="full", h_min=1e-3, h_max=1e4):
    """H = 0.37 m (0.132 / mu)^2 (k2 / 1.69)^0.5: the model's trends, none of its cost; raises
    FloatingPointError for mu > 0.15 (a failing sample)."""
    if scene.mu > 0.15:
        raise FloatingPointError(f"stand-in failure at mu = {scene.mu:.4f}")
    h = 0.37 * (0.132 / scene.mu) ** 2 * math.sqrt(scene.target_conductivity / 1.69)
    return _result(h, h_min, h_max)


def nan_height(scene, **kwargs):
    """A solver that returns a non-finite height without raising."""
    return types.SimpleNamespace(critical_height=float("nan"), censored=None, evaluations=1,
                                 flags=(), wall_time=0.0)


def crashing_height(scene, rtol=1e-3, tier="full", h_min=1e-3, h_max=1e4):
    """:func:`fake_height` without failures, except that it kills its process for mu > 0.14 (a
    crash in compiled code: no exception, the process is gone). Only in worker processes: in
    the test process it raises instead of killing pytest."""
    if scene.mu > 0.14:
        if multiprocessing.parent_process() is None:
            raise RuntimeError("crashing_height would kill the test process: use workers >= 2")
        os._exit(3)
    h = 0.37 * (0.132 / scene.mu) ** 2 * math.sqrt(scene.target_conductivity / 1.69)
    return _result(h, h_min, h_max, flags=())


def interrupting_height(scene, rtol=1e-3, tier="full", h_min=1e-3, h_max=1e4):
    """:func:`fake_height`, but Ctrl-C (KeyboardInterrupt) for mu > 0.16 (in the tiny study:
    sample 9 of quartz): an interrupted in-process run."""
    if scene.mu > 0.16:
        raise KeyboardInterrupt
    return fake_height(scene, rtol, tier, h_min, h_max)


# --- fixtures ------------------------------------------------------------------------------------


@pytest.fixture
def study_file(tmp_path):
    """The tiny study written to a file."""
    path = tmp_path / "tiny.toml"
    path.write_text(TINY)
    return path


@pytest.fixture
def storage_study():
    """The storage tests' study, parsed."""
    from skidmc.ensemble.study import parse_study

    return parse_study(STORAGE_TEXT, file="storage-test.toml")


@pytest.fixture
def cli_runs(monkeypatch):
    """``skidmc run`` through :func:`skidmc.cli.main` with :func:`fake_height` injected: the
    CLI's call of :func:`skidmc.ensemble.run.execute_study` is recorded (its arguments, parsed
    from the command line) and passed on with ``solver=fake_height`` unless one is given."""
    from skidmc.ensemble import run as run_module

    real = run_module.execute_study
    calls: list[dict] = []

    def execute_study(study, out=None, **kwargs):
        calls.append({"study": study, "out": out, **kwargs})
        if kwargs.get("solver") is None:
            kwargs["solver"] = fake_height
        return real(study, out, **kwargs)

    monkeypatch.setattr(run_module, "execute_study", execute_study)
    return calls
