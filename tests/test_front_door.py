"""`import skidmc`: the names a user needs, lazily; every module declares its public names."""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

import pytest

import skidmc

PACKAGE = Path(__file__).resolve().parents[1] / "src" / "skidmc"

FRONT_DOOR = ("critical_height", "make_scene", "get_preset", "load_study", "run_study",
              "evaluate_batch", "open_ensemble")


@pytest.mark.parametrize("name", FRONT_DOOR)
def test_front_door_names(name):
    assert name in skidmc.__all__
    assert callable(getattr(skidmc, name))


def test_every_exported_name_resolves():
    missing = [n for n in skidmc.__all__ if not hasattr(skidmc, n)]
    assert not missing


def test_unknown_attribute_is_an_attribute_error():
    with pytest.raises(AttributeError, match="no attribute 'critical_hieght'"):
        skidmc.critical_hieght  # noqa: B018


def test_import_is_lazy():
    # A fresh interpreter: `import skidmc` loads none of the heavy dependencies; they come with
    # the first use of a name that needs them.
    code = ("import sys, skidmc; heavy = ('numba', 'scipy', 'pint', 'h5py', 'xarray'); "
            "print(sorted({m.split('.')[0] for m in sys.modules if m.startswith(heavy)}))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True).stdout.strip()
    assert out == "[]"


@pytest.mark.parametrize("path", sorted(PACKAGE.rglob("*.py")), ids=lambda p: str(
    p.relative_to(PACKAGE)))
def test_every_module_declares_all(path):
    if path.name == "__main__.py":
        return  # a script, not an importable API
    tree = ast.parse(path.read_text())
    names = [t.id for node in tree.body if isinstance(node, (ast.Assign, ast.AnnAssign))
             for t in (node.targets if isinstance(node, ast.Assign) else [node.target])
             if isinstance(t, ast.Name)]
    assert "__all__" in names, f"{path.relative_to(PACKAGE)} has no __all__"
