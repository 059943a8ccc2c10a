"""The package's imports point down its floors: no module imports another that imports it back.

The import graph is read from the sources with :mod:`ast` (nothing is imported): one node per
module of ``src/cosserat_chain``, one edge per ``import``/``from ... import`` naming another
of them. ``if TYPE_CHECKING:`` blocks are left out, since they never run. The graph of the
imports a module runs when it is loaded must be acyclic, and so must the graph with the
deferred imports inside functions too: a deferred import only hides a circle from Python's
loader, not from a reader. No module imports the package's top level, which is the lazy public
API above every floor.
"""

from __future__ import annotations

import ast
import functools
from pathlib import Path

import pytest

import cosserat_chain

PACKAGE = Path(cosserat_chain.__file__).parent
TOP = "cosserat_chain"


def package_modules(root: Path = PACKAGE) -> dict[str, Path]:
    """Dotted module name -> source file, for every module under ``root`` (a package's name for its ``__init__``)."""
    out = {}
    for path in sorted(root.rglob("*.py")):
        parts = list(path.relative_to(root.parent).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts.pop()
        out[".".join(parts)] = path
    return out


def _type_checking_only(node: ast.AST) -> bool:
    return isinstance(node, ast.If) and isinstance(node.test, ast.Name | ast.Attribute) and ast.unparse(node.test).endswith("TYPE_CHECKING")


def _import_nodes(tree: ast.Module, deferred: bool) -> list[ast.Import | ast.ImportFrom]:
    """The import statements of a module: those run at load (bodies of functions and classes'
    methods left out) or, with ``deferred``, all of them; never those under ``if TYPE_CHECKING``."""
    found = []

    def visit(node: ast.AST) -> None:
        for child in ast.iter_child_nodes(node):
            if _type_checking_only(child):
                continue
            if isinstance(child, ast.Import | ast.ImportFrom):
                found.append(child)
            elif deferred or not isinstance(child, ast.FunctionDef | ast.AsyncFunctionDef | ast.Lambda):
                visit(child)

    visit(tree)
    return found


def imported_modules(name: str, source: str, is_package: bool, modules: set[str], deferred: bool) -> set[str]:
    """The package's modules that module ``name`` imports (a package when the name is not a module)."""
    return set(_imports_at_load_and_deferred(name, source, is_package, frozenset(modules))[deferred])


@functools.cache
def _imports_at_load_and_deferred(name: str, source: str, is_package: bool, modules: frozenset[str]) -> tuple[frozenset[str], ...]:
    """:func:`imported_modules` both ways from one parse, kept for the session by the source text: the package's graph is
    read four times (at load and with the deferred imports, here and in test_linalg.py), and parsing is most of it."""
    tree = ast.parse(source)
    return tuple(frozenset(_imported_by(tree, name, is_package, modules, deferred)) for deferred in (False, True))


def _imported_by(tree: ast.Module, name: str, is_package: bool, modules: frozenset[str], deferred: bool) -> set[str]:
    out = set()
    for node in _import_nodes(tree, deferred):
        if isinstance(node, ast.Import):
            targets = [alias.name for alias in node.names]
        else:
            if node.level:
                base = name.split(".") if is_package else name.split(".")[:-1]
                base = base[: len(base) - (node.level - 1)]
                target = ".".join([*base, node.module] if node.module else base)
            else:
                target = node.module or ""
            targets = [f"{target}.{alias.name}" if f"{target}.{alias.name}" in modules else target for alias in node.names]
        out.update(t for t in targets if t in modules and t != name)
    return out


def import_graph(deferred: bool, root: Path = PACKAGE) -> dict[str, set[str]]:
    modules = package_modules(root)
    return {
        name: imported_modules(name, path.read_text(encoding="utf-8"), path.name == "__init__.py", set(modules), deferred)
        for name, path in modules.items()
    }


def find_cycle(graph: dict[str, set[str]]) -> list[str] | None:
    """One circle of the graph as ``[a, b, ..., a]``, or None if it is acyclic (depth-first search)."""
    state: dict[str, int] = {}  # 1 on the current path, 2 finished
    path: list[str] = []

    def visit(node: str) -> list[str] | None:
        state[node] = 1
        path.append(node)
        for nxt in sorted(graph.get(node, ())):
            if state.get(nxt) == 1:
                return [*path[path.index(nxt) :], nxt]
            if nxt not in state and (cycle := visit(nxt)):
                return cycle
        path.pop()
        state[node] = 2
        return None

    for start in sorted(graph):
        if start not in state and (cycle := visit(start)):
            return cycle
    return None


# --------------------------------------------------------------------------- the checker itself
def test_the_cycle_finder_finds_a_circle_and_passes_a_tree():
    assert find_cycle({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == ["a", "b", "c", "a"]
    assert find_cycle({"a": {"b", "c"}, "b": {"c"}, "c": set()}) is None


def test_relative_and_deferred_imports_are_resolved_to_the_modules_they_name():
    modules = {"p", "p.a", "p.b", "p.sub", "p.sub.c", "p.sub.d"}
    source = (
        "from typing import TYPE_CHECKING\n"
        "from .. import a\n"
        "from ..b import thing\n"
        "from . import d as dee\n"
        "import numpy\n"
        "if TYPE_CHECKING:\n"
        "    from .d import Never\n"
        "def late():\n"
        "    from .. import sub\n"
    )
    assert imported_modules("p.sub.c", source, False, modules, deferred=False) == {"p.a", "p.b", "p.sub.d"}
    assert imported_modules("p.sub.c", source, False, modules, deferred=True) == {"p.a", "p.b", "p.sub.d", "p.sub"}
    assert imported_modules("p.sub", "from . import c\nfrom .. import b\n", True, modules, deferred=False) == {"p.sub.c", "p.b"}


def test_a_package_with_a_circle_hidden_in_a_function_is_caught(tmp_path):
    package = tmp_path / "pkg"
    package.mkdir()
    (package / "__init__.py").write_text("")
    (package / "low.py").write_text("def f():\n    from .high import g\n    return g\n")
    (package / "high.py").write_text("from .low import f\n")
    assert find_cycle(import_graph(deferred=False, root=package)) is None
    assert find_cycle(import_graph(deferred=True, root=package)) == ["pkg.high", "pkg.low", "pkg.high"]


# --------------------------------------------------------------------------- the package
@pytest.mark.parametrize("deferred", [False, True], ids=["at-load", "with-deferred"])
def test_the_package_imports_form_no_circle(deferred):
    graph = import_graph(deferred)
    assert len(graph) > 50 and any(graph.values())  # the graph was read, not empty
    cycle = find_cycle(graph)
    assert cycle is None, "import circle: " + " -> ".join(cycle)


def test_no_module_imports_the_package_top_level():
    upward = sorted(name for name, imports in import_graph(deferred=True).items() if TOP in imports)
    assert not upward, f"these modules import the package's top level (the lazy API above every floor): {upward}"
