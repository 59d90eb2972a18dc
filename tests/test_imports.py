"""The import graph of the three parts, the ground floor below them and the cross-check above
them, read from their source (``ast``): no circle of imports, dem imports nothing of fem, none
of hmodel, fem and dem imports the cross-check (``crosscheck``, which imports all three), and
the ground floor (``common``) imports none of them. And no module sets the process umask.

Every ``import`` and ``from ... import`` counts, at module level and inside functions alike (an
import inside a function only hides a circle: it closes at the first call). An import names a
module of ``common``, ``hmodel``, ``fem``, ``dem`` or ``crosscheck`` (others are left out): ``from pkg import name`` is an
edge to ``pkg.name`` where that is a module of its own, else to ``pkg`` (its ``__init__``). The
implicit import of a module's parent packages is not an edge (every module would be in a circle
with its package's ``__init__``)."""
from __future__ import annotations

import ast
import os

ROOT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..")
PACKAGES = ("common", "point", "hmodel", "fem", "dem", "crosscheck")
# the three parts, below the cross-check
PARTS = ("hmodel", "fem", "dem")
# the ground floor, below the three parts
GROUND = "common"
# the material point of any law, between the ground floor and the parts (the H-model is one law
# of it: point finds it by name, ``importlib``, and imports no part)
POINT = "point"


def _modules() -> dict[str, str]:
    """Dotted module name -> file of every module of the packages (a package is its __init__)."""
    out = {}
    for pkg in PACKAGES:
        for dirpath, dirnames, filenames in os.walk(os.path.join(ROOT, pkg)):
            dirnames[:] = sorted(d for d in dirnames if d != "__pycache__")
            rel = os.path.relpath(dirpath, ROOT).split(os.sep)
            for f in sorted(filenames):
                if not f.endswith(".py"):
                    continue
                name = rel if f == "__init__.py" else rel + [f[:-3]]
                out[".".join(name)] = os.path.join(dirpath, f)
    return out


def _is_package(name: str, modules: dict) -> bool:
    return os.path.basename(modules[name]) == "__init__.py"


def import_graph() -> dict[str, dict[str, int]]:
    """Module -> {imported module of the packages: line of the first such import}."""
    modules = _modules()
    graph = {}
    for name, path in modules.items():
        with open(path, encoding="utf-8") as f:
            tree = ast.parse(f.read(), filename=path)
        here = name if _is_package(name, modules) else name.rpartition(".")[0]
        edges = {}

        def add(target, line):
            if target in modules and target != name:
                edges.setdefault(target, line)

        for node in ast.walk(tree):
            if isinstance(node, ast.Import):
                for alias in node.names:
                    add(alias.name, node.lineno)
            elif isinstance(node, ast.ImportFrom):
                if node.level:
                    base = here.split(".")[:len(here.split(".")) - (node.level - 1)]
                    base = ".".join(base + ([node.module] if node.module else []))
                else:
                    base = node.module
                for alias in node.names:
                    sub = f"{base}.{alias.name}"
                    add(sub if sub in modules else base, node.lineno)
        graph[name] = edges
    return graph


def cycles(graph: dict[str, dict[str, int]]) -> list[list[str]]:
    """The strongly connected components of more than one module (Tarjan), members sorted: each
    is a set of modules every one of which imports every other, directly or not."""
    index, low, on, stack, out = {}, {}, set(), [], []

    def visit(v):
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in sorted(graph[v]):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return sorted(out)


def describe(graph, comp) -> str:
    """A shortest circle from the component's first member back to it, each module with the line
    of its import of the next, and the component's other members (all of them take part)."""
    start, inside = comp[0], set(comp)
    prev, queue, path = {start: None}, [start], comp
    while queue and path is comp:
        v = queue.pop(0)
        for w in sorted(graph[v]):
            if w == start:
                path = [v]
                while prev[path[-1]] is not None:
                    path.append(prev[path[-1]])
                path = path[::-1]
                break
            if w in inside and w not in prev:
                prev[w] = v
                queue.append(w)
    line = " -> ".join(f"{a} ({graph[a][b]})" for a, b in zip(path, path[1:] + path[:1]))
    rest = sorted(inside - set(path))
    return f"{line} -> {start}" + (f"; also in this circle: {', '.join(rest)}" if rest else "")


def test_no_circle_of_imports():
    graph = import_graph()
    found = cycles(graph)
    assert not found, "circles of imports (module (line of its import of the next) -> ...):\n" + \
        "\n".join(describe(graph, c) for c in found)


def test_dem_imports_nothing_of_fem():
    graph = import_graph()
    bad = sorted(f"{m} ({line}) imports {t}" for m, edges in graph.items() for t, line in edges.items()
                 if m.split(".")[0] == "dem" and t.split(".")[0] == "fem")
    assert not bad, "\n".join(bad)


def test_no_part_imports_the_crosscheck():
    """The cross-check stands above the three parts: hmodel, fem and dem import nothing of it."""
    graph = import_graph()
    bad = sorted(f"{m} ({line}) imports {t}" for m, edges in graph.items() for t, line in edges.items()
                 if m.split(".")[0] in PARTS and t.split(".")[0] == "crosscheck")
    assert not bad, "\n".join(bad)


def test_the_ground_floor_imports_no_part():
    """common is below everything: it imports none of hmodel, fem, dem and crosscheck."""
    graph = import_graph()
    bad = sorted(f"{m} ({line}) imports {t}" for m, edges in graph.items() for t, line in edges.items()
                 if m.split(".")[0] == GROUND and t.split(".")[0] != GROUND)
    assert not bad, "\n".join(bad)


def test_the_material_point_imports_no_part():
    """point (the contract, the analysis of any law) imports none of hmodel, fem, dem and
    crosscheck: a law is found by its name (``point.contract.material_named``), the H-model
    registers itself when hmodel is imported."""
    graph = import_graph()
    bad = sorted(f"{m} ({line}) imports {t}" for m, edges in graph.items() for t, line in edges.items()
                 if m.split(".")[0] == POINT and t.split(".")[0] not in (POINT, GROUND))
    assert not bad, "\n".join(bad)


def test_no_module_sets_the_umask():
    """The umask is the process's, shared by every thread: setting it even for a moment (to read
    it) races with any other thread creating a file. No module of the packages, the benchmarks
    or the examples calls ``os.umask`` (``common.io`` reads it from /proc, and creates files
    with mode 0666 so that the kernel takes it off); only the tests set it, to test modes."""
    bad = []
    for top in PACKAGES + ("bench", os.path.join("docs", "examples"), os.path.join("docs", "reference")):
        for dirpath, dirnames, filenames in os.walk(os.path.join(ROOT, top)):
            dirnames[:] = [d for d in dirnames if d != "__pycache__"]
            for f in filenames:
                if f.endswith(".py"):
                    path = os.path.join(dirpath, f)
                    with open(path, encoding="utf-8") as fh:
                        tree = ast.parse(fh.read(), filename=path)
                    for node in ast.walk(tree):
                        if isinstance(node, ast.Call) and "umask" in (
                                getattr(node.func, "attr", None), getattr(node.func, "id", None)):
                            bad.append(f"{os.path.relpath(path, ROOT)}:{node.lineno}")
    assert not bad, "calls of umask: " + ", ".join(bad)


def test_the_graph_is_read():
    """The reading itself: relative, absolute and in-function imports, packages and modules."""
    graph = import_graph()
    assert "point.mixed" in graph["point.driver"]                   # from .mixed import ...
    assert "point.mixed" in graph["point.controllability"]
    assert "point.driver" in graph["hmodel.driver"]                 # from point import driver
    assert "hmodel.material" in graph["hmodel"]                     # a package's __init__
    assert "point.driver" in graph["fem.reference"]                # from point.driver import
    assert "fem.indicators" in graph["fem.__main__"]               # from . import indicators as ind
    assert "point.driver" in graph["point.experiment"]
    assert "fem.biaxial" in graph["crosscheck.parts"]              # from fem.biaxial import, in a function
    assert "crosscheck.burst.report" in graph["crosscheck.report"]  # from .burst.report import
    assert "common.io" in graph["common.options"]                  # from .io import, in a function
    assert "common.io" in graph["dem.io"]                          # from common.io import
    assert "common.threads" in graph["fem.indicators.local"]


def test_a_circle_is_found():
    """The search itself, on a made-up graph: a circle through three modules beside a branch
    that leads out of it, and its shortest description."""
    g = {"a": {"b": 3}, "b": {"c": 5}, "c": {"a": 9, "d": 1}, "d": {}, "e": {"d": 2}}
    assert cycles(g) == [["a", "b", "c"]]
    assert describe(g, ["a", "b", "c"]) == "a (3) -> b (5) -> c (9) -> a"
    g["a"]["c"] = 4                                         # a shorter circle a -> c -> a
    assert describe(g, ["a", "b", "c"]) == "a (4) -> c (9) -> a; also in this circle: b"
    assert cycles({"a": {"b": 1}, "b": {}}) == []
