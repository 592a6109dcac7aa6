"""The tree's imports run one way and never in a circle (issue 78; docs/interfaces.md,
"Layout and the direction of dependencies").

Read from the source, not from what happens to be imported: every ``import x``,
``import x.y as z``, ``from x import y`` and relative ``from . import y`` /
``from ..x import y``, at module level or inside a function (the lazy imports the
packages use to keep start-up light count as much as the others). An import names the
deepest module of the tree it reaches (``from service import sweeps`` is
``service.sweeps``; ``from solver.case import Case`` is ``solver.case``).

* Layers, lowest first: ``solver`` (the numerics) <- ``service`` (the REST service, the
  result store, sweeps, the export, what the CLI and the workers share) <- ``worker``
  (Celery) <- ``hockle`` (the command line and the Python API) <- ``benchmarks`` <-
  ``research`` (the laboratory, which may also use the tests' case builders). A module
  may import its own layer and the layers below it, never one above; nothing but
  ``research`` imports ``tests``.
* No circle between any two modules of those folders.
* ``benchmarks`` is a package that edits no ``sys.path``.
"""
from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

#: the layers, lowest first: a module may import only its own and lower layers
LAYERS = ("solver", "service", "worker", "hockle", "benchmarks", "research")
#: folders that no layer below ``research`` may import
OUTSIDE = ("tests",)
#: Alembic's revision scripts, loaded by Alembic from their folder, not imported
SKIPPED_PARTS = ("versions",)


def module_name(path: Path, root: Path = ROOT) -> str:
    parts = list(path.relative_to(root).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def tree_modules(root: Path = ROOT, folders=LAYERS) -> dict[str, Path]:
    """Module name -> file, for every .py file under the given top-level folders."""
    found = {}
    for folder in folders:
        for path in sorted((root / folder).rglob("*.py")):
            if any(part in SKIPPED_PARTS for part in path.relative_to(root).parts):
                continue
            found[module_name(path, root)] = path
    return found


def imports_of(name: str, source: str, is_package: bool) -> list[tuple[str, int]]:
    """(imported name as written, made absolute, line) of every import in ``source``, the
    text of module ``name``: for ``from x import y`` it is ``x.y``, of which the caller
    takes the deepest module (``x.y`` where y is a module, else ``x``)."""
    package = name if is_package else name.rpartition(".")[0]
    out = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Import):
            out += [(alias.name, node.lineno) for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                anchor = package.split(".") if package else []
                anchor = anchor[:len(anchor) - (node.level - 1)]
                base = ".".join(anchor + ([base] if base else []))
            out += [(base if alias.name == "*" else f"{base}.{alias.name}", node.lineno)
                    for alias in node.names]
    return out


def _resolve(target: str, known: set[str]) -> str | None:
    """The deepest module of ``known`` that ``target`` names, or None."""
    while target and target not in known:
        target = target.rpartition(".")[0]
    return target or None


def import_graph(modules: dict[str, Path]) -> dict[str, dict[str, int]]:
    """Module -> {module of the tree it imports: first line}."""
    known = set(modules)
    graph = {}
    for name, path in modules.items():
        edges: dict[str, int] = {}
        for target, line in imports_of(name, path.read_text(), path.name == "__init__.py"):
            found = _resolve(target, known)
            if found and found != name:
                edges.setdefault(found, line)
        graph[name] = edges
    return graph


def back_edges(graph: dict[str, dict[str, int]], layers=LAYERS, outside=OUTSIDE,
               lab: str = "research") -> list[str]:
    """``module:line -> module`` for every import of a higher layer, or of ``outside`` from
    below the ``lab``."""
    rank = {layer: i for i, layer in enumerate(layers)}
    bad = []
    for name, edges in sorted(graph.items()):
        mine = name.split(".")[0]
        for target, line in sorted(edges.items()):
            top = target.split(".")[0]
            if (top in outside and mine != lab) or (
                    mine in rank and rank.get(top, -1) > rank[mine]):
                bad.append(f"{name}:{line} -> {target}")
    return bad


def circles(graph: dict[str, dict[str, int]]) -> list[list[str]]:
    """The import circles: every strongly connected set of two or more modules (and a
    module importing itself), each as a path ``a -> b -> ... -> a`` through it."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found: list[list[str]] = []
    counter = [0]

    def connect(v: str) -> None:          # Tarjan, iteratively deep enough for this tree
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on_stack.add(v)
        for w in sorted(graph.get(v, ())):
            if w not in graph:
                continue
            if w not in index:
                connect(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            group = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                group.append(w)
                if w == v:
                    break
            if len(group) > 1 or v in graph.get(v, ()):
                found.append(_cycle_through(sorted(group), graph))

    for v in sorted(graph):
        if v not in index:
            connect(v)
    return found


def _cycle_through(group: list[str], graph) -> list[str]:
    """One circle through the first module of a strongly connected ``group``."""
    members, start = set(group), group[0]
    paths = {start: [start]}
    frontier = [start]
    while frontier:                       # breadth first, inside the group
        nxt = []
        for v in frontier:
            for w in sorted(graph[v]):
                if w == start:
                    return paths[v] + [start]
                if w in members and w not in paths:
                    paths[w] = paths[v] + [w]
                    nxt.append(w)
        frontier = nxt
    return group                          # pragma: no cover - a group always closes


@pytest.fixture(scope="module")
def graph():
    modules = tree_modules()
    assert {"solver.simulation", "service.app", "worker.tasks", "hockle.cli"} <= set(modules)
    return import_graph(modules)


def test_layers_import_only_downwards(graph):
    bad = back_edges(graph)
    assert not bad, "imports of a higher layer:\n" + "\n".join(bad)


def test_no_import_circles_anywhere(graph):
    found = circles(graph)
    assert not found, "import circles:\n" + "\n".join(" -> ".join(c) for c in found)


def test_benchmarks_are_a_package_without_path_edits():
    folder = ROOT / "benchmarks"
    assert (folder / "__init__.py").is_file()
    edits = [f"{path.name}:{node.lineno}" for path in sorted(folder.glob("*.py"))
             for node in ast.walk(ast.parse(path.read_text()))
             if isinstance(node, ast.Attribute) and node.attr == "path"
             and isinstance(node.value, ast.Name) and node.value.id == "sys"]
    assert not edits, edits


def test_lazy_and_relative_imports_are_read(graph):
    # a function-level import (service.validation reads a job's result lazily) and a
    # relative one (the routers take the app's services from service/deps.py)
    assert "solver.results" in graph["service.validation"]
    assert "service.deps" in graph["service.routers.jobs"]
    # the checkpoint pickles the run without knowing the step logic
    assert not {"solver.simulation", "solver.run"} & set(graph["solver.checkpoint"])


def test_the_checks_find_a_back_edge_and_a_circle(tmp_path):
    """Both checks on a tree made for the purpose: every form of import is read."""
    files = {
        "solver/__init__.py": "",
        "solver/core.py": "def f():\n    from ..hockle import cli\n",        # lazy, relative
        "service/__init__.py": "",
        "service/a.py": "import service.b as b\n",
        "service/b.py": "from service import c\n",
        "service/c.py": "from . import a\nfrom solver.core import f\n",
        "hockle/__init__.py": "",
        "hockle/cli.py": "from solver import core\nimport tests.helpers\n",
        "research/__init__.py": "",
        "research/study.py": "from tests import helpers\nfrom hockle import cli\n",
        "tests/__init__.py": "",
        "tests/helpers.py": "",
    }
    for rel, text in files.items():
        (tmp_path / rel).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / rel).write_text(text)
    g = import_graph(tree_modules(tmp_path, ("solver", "service", "hockle", "research", "tests")))
    assert back_edges(g, ("solver", "service", "hockle", "research")) == [
        "hockle.cli:2 -> tests.helpers", "solver.core:2 -> hockle.cli"]
    assert sorted(map(tuple, circles(g))) == [
        ("hockle.cli", "solver.core", "hockle.cli"),
        ("service.a", "service.b", "service.c", "service.a")]
    assert circles({"a": {"b": 1}, "b": {}}) == []
