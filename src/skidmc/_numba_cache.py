"""Numba's on-disk cache, keyed by the package's source when it runs from a source checkout.

Numba re-validates a cached function only against its own file. The constants it read from other
modules and the callees it compiled into itself stay as they were when it was cached:
``physics.fast`` compiles ``physics.mechanics.impact_constants`` and ``STANDARD_GRAVITY`` into
its own code, ``solver.device`` compiles ``physics.thermal.simulate_core``. In a git checkout
installed with ``pip install -e`` (the README's way), a ``git pull`` or an edit that changes only
the callee's file would leave the caller's stale compiled code in use, silently. So there the
cache goes to ``<checkout>/.numba-cache/<hash of the package's source>``: any change to any
source file starts a fresh cache (one compile per source version).

An installed release is left to numba's default (``__pycache__`` next to each file): an upgrade
rewrites every file, which invalidates every cached function. A ``NUMBA_CACHE_DIR`` set by the
user (or by a parent process, which is how worker processes share their parent's cache) is
never overridden.
"""

from __future__ import annotations

import hashlib
import os
import shutil
import sys
import time
from pathlib import Path

__all__ = ["CACHE_ROOT_NAME", "clean_other_caches", "configure", "source_cache_dir"]

#: Directory under the checkout's root that holds one cache per source version.
CACHE_ROOT_NAME = ".numba-cache"
#: Caches of other source versions kept by :func:`clean_other_caches` by default (the most
#: recently used), so that processes still running an older version keep theirs.
KEEP_OTHER = 3
#: ... and none younger than this [s] is removed, whatever its rank.
KEEP_YOUNGER_THAN = 86_400.0

_PACKAGE = Path(__file__).resolve().parent


def source_cache_dir(package=_PACKAGE):
    """``<checkout>/.numba-cache/<16 hex digits>`` for a package in a source checkout
    (``<checkout>/src/<package>`` next to ``<checkout>/pyproject.toml``), else None [Path]."""
    package = Path(package)
    root = package.parent.parent
    if package.parent.name != "src" or not (root / "pyproject.toml").is_file():
        return None
    digest = hashlib.sha256()
    for path in sorted(package.rglob("*.py")):
        digest.update(path.relative_to(package).as_posix().encode())
        digest.update(path.read_bytes())
    return root / CACHE_ROOT_NAME / digest.hexdigest()[:16]


def configure():
    """Point numba's cache at :func:`source_cache_dir` unless ``NUMBA_CACHE_DIR`` is set.

    Called by ``import skidmc`` before any of its kernels is compiled. Sets the environment
    variable (worker processes inherit it) and, when numba is already imported, numba's config.
    Returns the directory used, or None where numba's default stands.
    """
    if os.environ.get("NUMBA_CACHE_DIR"):
        return None
    here = source_cache_dir()
    if here is None:
        return None
    if not here.is_dir():
        # A source version not seen before: a good moment to drop the caches of old ones.
        clean_other_caches(here)
    os.environ["NUMBA_CACHE_DIR"] = str(here)
    config = sys.modules.get("numba.core.config")
    if config is not None:
        config.CACHE_DIR = str(here)
    return here


def clean_other_caches(here, keep=KEEP_OTHER, keep_younger_than=KEEP_YOUNGER_THAN):
    """Remove the caches of other source versions next to ``here`` (the current one, a Path).

    Keeps ``here``, the ``keep`` most recently modified others and any modified within
    ``keep_younger_than`` [s]. Returns the directories removed (list of Path).
    """
    here = Path(here)
    if not here.parent.is_dir():
        return []
    others = sorted((p for p in here.parent.iterdir() if p.is_dir() and p != here),
                    key=lambda p: p.stat().st_mtime, reverse=True)
    now = time.time()
    removed = []
    for path in others[keep:]:
        if now - path.stat().st_mtime >= keep_younger_than:
            shutil.rmtree(path, ignore_errors=True)
            removed.append(path)
    return removed
