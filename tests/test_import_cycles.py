"""No import cycle inside worker/ or frontend/ (issue 53): between worker's subpackages, and
between the modules of frontend/ and of each worker subpackage. Imports are read with the ast
reader of test_import_directions (inside functions and under `if TYPE_CHECKING:` too: a
function-level import hides a cycle, it does not break one)."""

from __future__ import annotations

import ast
from collections.abc import Iterable

from tests.test_import_directions import ROOT, _module, imports_of

Graph = dict[str, set[str]]


def module_sources(package: str) -> dict[str, str]:
    """Each module of `package` (a folder under the repository) by name, with its text."""
    return {_module(p): p.read_text() for p in sorted((ROOT / package).rglob("*.py"))}


def imported_modules(source: str, module: str, known: set[str]) -> set[str]:
    """The modules of `known` that `source` imports. `from pkg import mod` imports the module
    pkg.mod; it imports pkg itself (its __init__) only for a name pkg's __init__ defines."""
    found = set()
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Import | ast.ImportFrom):
            names = imports_of(ast.unparse(node), module)  # the same resolution, one node
        if isinstance(node, ast.Import):
            found |= names
        elif isinstance(node, ast.ImportFrom):
            for base in names:
                subs = {f"{base}.{a.name}" for a in node.names}
                found |= subs & known
                found |= {base} if subs - known else set()
    return found & known


def import_graph(sources: dict[str, str]) -> Graph:
    """importer -> the modules of `sources` it imports (a package means its __init__)."""
    known = set(sources)
    return {m: imported_modules(s, m, known) - {m} for m, s in sources.items()}


def collapse(graph: Graph, group) -> Graph:
    """The graph between groups (`group(module)` names a module's), without self edges."""
    out: Graph = {}
    for a, targets in graph.items():
        ga = group(a)
        out.setdefault(ga, set()).update(group(b) for b in targets if group(b) != ga)
    return out


def restrict(graph: Graph, nodes: Iterable[str]) -> Graph:
    keep = set(nodes)
    return {a: graph[a] & keep for a in keep}


def cycles(graph: Graph) -> list[list[str]]:
    """Per strongly connected component of more than one node (Tarjan's algorithm), a cycle
    through each of its nodes in turn (the first node repeated at its end), each once; sorted,
    so that a failure reads the same twice."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    components: list[set[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in sorted(graph.get(v, ())):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = set()
            while True:
                w = stack.pop()
                on_stack.discard(w)
                comp.add(w)
                if w == v:
                    break
            if len(comp) > 1:
                components.append(comp)

    for v in sorted(graph):
        if v not in index:
            visit(v)
    found = {tuple(_a_cycle(graph, comp, v)) for comp in components for v in comp}
    return sorted(list(c) for c in found)


def _a_cycle(graph: Graph, comp: set[str], start: str) -> list[str]:
    """The shortest cycle through `start` inside its component (breadth first), written from
    its smallest node."""
    came: dict[str, str] = {}
    frontier = [start]
    while frontier:
        nxt = []
        for v in frontier:
            for w in sorted(graph.get(v, set()) & comp):
                if w == start:
                    path = [v]
                    while path[-1] != start:
                        path.append(came[path[-1]])
                    ring = list(reversed(path))
                    i = ring.index(min(ring))
                    return [*ring[i:], *ring[:i], min(ring)]
                if w not in came:
                    came[w] = v
                    nxt.append(w)
        frontier = nxt
    raise AssertionError(f"{sorted(comp)} is no cycle")


def _show(found: list[list[str]]) -> str:
    return "import cycles:\n" + "\n".join("  " + " -> ".join(c) for c in found)


def _subpackage(module: str) -> str:
    """worker.slam.graph.slam -> worker.slam; worker.pipeline -> worker.pipeline."""
    return ".".join(module.split(".")[:2])


def worker_cycles(sources: dict[str, str]) -> list[list[str]]:
    """The cycles between worker's subpackages, then inside each of them."""
    graph = import_graph(sources)
    found = cycles(collapse(graph, _subpackage))
    for sub in sorted({_subpackage(m) for m in graph}):
        found += cycles(restrict(graph, (m for m in graph if _subpackage(m) == sub)))
    return found


def test_cycles_finds_each_cycle_once_and_no_cycle_in_a_chain():
    graph = {"a": {"b"}, "b": {"c"}, "c": {"a", "d"}, "d": set(), "e": {"f"}, "f": {"e"}}
    assert cycles(graph) == [["a", "b", "c", "a"], ["e", "f", "e"]]
    assert cycles({"a": {"b"}, "b": {"c"}, "c": set()}) == []


def test_a_cycle_hidden_in_a_function_or_a_package_import_is_found():
    sources = {
        "worker": "",
        "worker.a": "",
        "worker.a.one": "from worker.a import two\n",
        "worker.a.two": "def f():\n    from worker.b.three import g\n",
        "worker.b": "",
        "worker.b.three": "from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n"
        "    from ..a.one import x\n",
    }
    assert worker_cycles(sources) == [["worker.a", "worker.b", "worker.a"]]
    sources["worker.b.three"] = "import numpy\n"
    sources["worker.a.two"] = "from .one import x\n"
    assert worker_cycles(sources) == [["worker.a.one", "worker.a.two", "worker.a.one"]]


def test_no_import_cycle_inside_worker():
    found = worker_cycles(module_sources("worker"))
    assert not found, _show(found)


def test_no_import_cycle_inside_frontend():
    found = cycles(import_graph(module_sources("frontend")))
    assert not found, _show(found)
