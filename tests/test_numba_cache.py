"""Numba's cache in a source checkout is keyed by the package's source (skidmc._numba_cache).

Numba re-validates a cached function only against its own file, so a change to a callee's or a
constant's module (``physics.mechanics``, compiled into ``physics.fast``) would otherwise leave
stale compiled code in use. These tests copy the package into a checkout-shaped directory, so
that nothing here touches the repository's own caches.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import time

import pytest
from conftest import ROOT

from skidmc import _numba_cache
from skidmc._numba_cache import clean_other_caches, configure, source_cache_dir


def _checkout(tmp_path):
    """A copy of the package laid out as a source checkout holds it (root/src/skidmc next to
    root/pyproject.toml)."""
    package = tmp_path / "src" / "skidmc"
    shutil.copytree(ROOT / "src" / "skidmc", package,
                    ignore=shutil.ignore_patterns("__pycache__", "*.nbi", "*.nbc"))
    (tmp_path / "pyproject.toml").write_text("[project]\nname = 'skidmc'\n")
    return package


def test_cache_dir_follows_every_source_file(tmp_path):
    package = _checkout(tmp_path)
    first = source_cache_dir(package)
    assert first.parent == tmp_path / ".numba-cache"
    assert source_cache_dir(package) == first  # the same source, the same cache
    mechanics = package / "physics" / "mechanics.py"
    mechanics.write_text(mechanics.read_text() + "\n# an edit\n")
    assert source_cache_dir(package) != first


def test_no_cache_dir_outside_a_checkout(tmp_path):
    package = tmp_path / "site-packages" / "skidmc"
    shutil.copytree(ROOT / "src" / "skidmc", package,
                    ignore=shutil.ignore_patterns("__pycache__", "*.nbi", "*.nbc"))
    assert source_cache_dir(package) is None


def test_configure_keeps_a_cache_dir_already_set(monkeypatch, tmp_path):
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path / "mine"))
    assert configure() is None
    assert os.environ["NUMBA_CACHE_DIR"] == str(tmp_path / "mine")


def test_configure_sets_the_source_cache(monkeypatch):
    monkeypatch.delenv("NUMBA_CACHE_DIR", raising=False)
    monkeypatch.setattr(_numba_cache, "clean_other_caches", lambda here: [])
    here = configure()
    assert here == source_cache_dir()
    assert os.environ["NUMBA_CACHE_DIR"] == str(here)


def test_clean_keeps_the_current_the_newest_and_the_young(tmp_path):
    root = tmp_path / ".numba-cache"
    now = time.time()
    # Newest first: young, a (kept: the 2 most recent others), b, c (removed), while "current"
    # stays whatever its age; with keep=0 "young" stays by its age alone.
    ages = {"current": 10 * 86_400, "a": 5 * 86_400, "b": 6 * 86_400, "c": 7 * 86_400,
            "young": 60.0}
    for name, age in ages.items():
        (root / name).mkdir(parents=True)
        os.utime(root / name, (now - age, now - age))
    removed = clean_other_caches(root / "current", keep=2, keep_younger_than=86_400.0)
    assert sorted(p.name for p in removed) == ["b", "c"]
    assert sorted(p.name for p in root.iterdir()) == ["a", "current", "young"]
    removed = clean_other_caches(root / "current", keep=0, keep_younger_than=86_400.0)
    assert [p.name for p in removed] == ["a"]


_FAST_HEIGHT = ("import skidmc, os; from skidmc.scene import get_preset; "
                "from skidmc.solver import critical_height; "
                "print(os.environ['NUMBA_CACHE_DIR']); "
                "print(repr(critical_height(get_preset('paper-quartz'), tier='fast')"
                ".critical_height))")


def test_an_edit_to_a_compiled_in_module_recompiles(tmp_path):
    """physics.fast compiles physics.mechanics' gravity into its kernels: after an edit of
    mechanics.py alone, the cached fast tier must not answer with the old value."""
    package = _checkout(tmp_path)
    env = {k: v for k, v in os.environ.items() if k != "NUMBA_CACHE_DIR"}
    env["PYTHONPATH"] = str(tmp_path / "src")

    def fast_height():
        out = subprocess.run([sys.executable, "-c", _FAST_HEIGHT], env=env, cwd=tmp_path,
                             capture_output=True, text=True, timeout=600)
        assert out.returncode == 0, out.stderr
        cache_dir, height = out.stdout.split()
        return cache_dir, float(height)

    cache_before, before = fast_height()
    assert cache_before.startswith(str(tmp_path / ".numba-cache"))
    mechanics = package / "physics" / "mechanics.py"
    text = mechanics.read_text()
    assert "STANDARD_GRAVITY = 9.80665" in text
    # Twice the gravity: H enters the flux as sqrt(2 g H), so the fast tier's height halves.
    mechanics.write_text(text.replace("STANDARD_GRAVITY = 9.80665", "STANDARD_GRAVITY = 19.6133"))
    cache_after, after = fast_height()
    assert cache_after != cache_before
    # Halved to the fast tier's own root tolerance (far tighter than the 1e-3 allowed here);
    # a stale gravity would leave the height unchanged.
    assert after == pytest.approx(before / 2.0, rel=1e-3)
