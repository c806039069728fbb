"""The package's layers: each imports only the layers below it, and no modules import in a cycle.

Walks every module's source (imports inside functions and ``TYPE_CHECKING`` blocks included, since a
function-level import of a higher layer is still an upward dependency) rather than importing it.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "src" / "skidmc"

#: Layer of each top-level part of the package, lowest first (docs/architecture.md).
LAYERS = {
    "skidmc": 0,             # the front door: lazy re-exports by name, imports nothing of skidmc
    "skidmc.errors": 0,
    "skidmc._numba_cache": 0,   # stdlib only; run by the front door before any kernel compiles
    "skidmc.physics": 1,
    "skidmc.scene": 2,
    "skidmc.solver": 3,
    "skidmc.ensemble": 4,
    "skidmc.analysis": 5,
    "skidmc.workflows": 6,      # the kinds of study: runners over ensemble and analysis
    "skidmc.cli": 7,
    "skidmc.__main__": 7,
}


def _module_name(path: Path) -> str:
    parts = path.relative_to(PACKAGE.parent).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _layer(module: str) -> int:
    parts = module.split(".")
    for n in range(len(parts), 0, -1):
        prefix = ".".join(parts[:n])
        if prefix in LAYERS:
            return LAYERS[prefix]
    raise KeyError(module)


def _imports(path: Path, module: str) -> set[str]:
    """skidmc modules that `path` imports (absolute names; relative imports resolved)."""
    tree = ast.parse(path.read_text(), filename=str(path))
    package = module if path.name == "__init__.py" else module.rpartition(".")[0]
    found = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            found.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                anchor = package.split(".")[: len(package.split(".")) - node.level + 1]
                base = ".".join(anchor + ([base] if base else []))
            # "from skidmc.solver import model" imports the submodule skidmc.solver.model
            for alias in node.names:
                candidate = f"{base}.{alias.name}"
                found.add(candidate if _is_module(candidate) else base)
    return {name for name in found if name == "skidmc" or name.startswith("skidmc.")}


def _is_module(name: str) -> bool:
    rel = Path(*name.split("."))
    return ((PACKAGE.parent / rel).with_suffix(".py").is_file()
            or (PACKAGE.parent / rel / "__init__.py").is_file())


MODULES = {_module_name(p): p for p in sorted(PACKAGE.rglob("*.py"))}
GRAPH = {name: _imports(path, name) - {name} for name, path in MODULES.items()}


def test_every_module_has_a_layer():
    assert {name: _layer(name) for name in MODULES}  # raises KeyError on an unplaced module


@pytest.mark.parametrize("module", sorted(MODULES))
def test_no_upward_import(module):
    upward = sorted(t for t in GRAPH[module] if _layer(t) > _layer(module))
    assert not upward, f"{module} (layer {_layer(module)}) imports higher layers: {upward}"


def test_the_front_door_imports_nothing_of_skidmc_eagerly():
    # `import skidmc` stays fast: its names are resolved lazily (PEP 562), so the package root
    # itself imports no skidmc module but the numba-cache set-up, which must come before any
    # kernel compiles and itself imports nothing of skidmc.
    assert GRAPH["skidmc"] == {"skidmc._numba_cache"}
    assert GRAPH["skidmc._numba_cache"] == set()


def _cycle(graph: dict[str, set[str]]) -> list[str] | None:
    state: dict[str, int] = {}  # 1 on the stack, 2 done
    stack: list[str] = []

    def visit(node: str) -> list[str] | None:
        state[node] = 1
        stack.append(node)
        for nxt in sorted(graph.get(node, ())):
            if state.get(nxt) == 1:
                return stack[stack.index(nxt):] + [nxt]
            if nxt not in state and (found := visit(nxt)):
                return found
        stack.pop()
        state[node] = 2
        return None

    for start in sorted(graph):
        if start not in state and (found := visit(start)):
            return found
    return None


def test_no_import_cycle():
    # A package __init__ that re-exports its modules is not part of a cycle through them: the
    # modules import each other directly (skidmc.scene.scenes -> skidmc.scene.keys), so the
    # edges into a package are those of code that imports the package's re-exports.
    assert _cycle(GRAPH) is None, " -> ".join(_cycle(GRAPH))


def test_the_cycle_finder_finds_a_cycle():
    # The check above can fail: a planted cycle is found, an acyclic graph is not flagged.
    assert _cycle({"a": {"b"}, "b": {"c"}, "c": {"a"}}) == ["a", "b", "c", "a"]
    assert _cycle({"a": {"b"}, "b": {"c"}, "c": set()}) is None


def test_the_walk_sees_function_level_imports():
    # solver.search imports the fast tier inside critical_height: the walk must see it.
    assert "skidmc.solver.fast" in GRAPH["skidmc.solver.search"]
