"""The import graph of spar_py has no cycle: module-level and function-level imports alike.

The graph is read from the sources with ``ast`` (nothing is imported): an edge A -> B for every
``import``/``from ... import`` of a spar_py module anywhere in A's file, except under
``if TYPE_CHECKING:`` (never executed: annotations only). ``from P import name`` counts as an
import of ``P.name`` when that is a module, else of ``P``.
"""
from __future__ import annotations

import ast
from pathlib import Path

SRC = Path(__file__).resolve().parent.parent / "src"
PACKAGE = "spar_py"


def modules(src: Path = SRC, package: str = PACKAGE) -> dict[str, Path]:
    """Dotted module name -> file, for every .py of ``package`` under the directory ``src``."""
    out = {}
    for p in sorted((src / package).rglob("*.py")):
        parts = list(p.relative_to(src).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts = parts[:-1]
        out[".".join(parts)] = p
    return out


def _type_checking_nodes(tree: ast.AST) -> set[int]:
    skip: set[int] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.If) and "TYPE_CHECKING" in ast.unparse(node.test):
            skip.update(id(n) for stmt in node.body for n in ast.walk(stmt))
    return skip


def _edges(name: str, path: Path, modules: dict[str, Path]) -> set[str]:
    tree = ast.parse(path.read_text(), str(path))
    skip = _type_checking_nodes(tree)
    is_pkg = path.name == "__init__.py"
    here = name.split(".") if is_pkg else name.split(".")[:-1]
    out: set[str] = set()
    for node in ast.walk(tree):
        if id(node) in skip:
            continue
        if isinstance(node, ast.Import):
            targets = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                base = ".".join(here[:len(here) - node.level + 1] + ([base] if base else []))
            targets = [f"{base}.{a.name}" if f"{base}.{a.name}" in modules else base for a in node.names]
        else:
            continue
        out.update(t for t in targets if t in modules and t != name)
    return out


def _graph() -> dict[str, set[str]]:
    mods = modules()
    return {m: _edges(m, p, mods) for m, p in mods.items()}


def import_cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of more than one module (Tarjan), each sorted."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on: set[str] = set()
    out: list[list[str]] = []

    def visit(v: str) -> None:
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
    return out


def test_the_graph_is_read() -> None:
    g = _graph()
    assert "spar_py.planning.planner" in g and "spar_py.planning.engine" in g["spar_py.planning.planner"]
    assert "spar_py.core.errors" in g["spar_py.app.cli"]


def test_a_cycle_is_found() -> None:
    assert import_cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]
    assert import_cycles({"a": {"b"}, "b": set()}) == []


def test_spar_py_has_no_import_cycle() -> None:
    cycles = import_cycles(_graph())
    assert cycles == [], "import cycles: " + "; ".join(" <-> ".join(c) for c in cycles)


def test_the_start_up_code_is_imported_by_nothing_of_the_planner() -> None:
    """startup/ (the console script's first code and the methods image) is fenced: only itself and
    ``python -m spar_py`` import it."""
    g = _graph()
    users = sorted(m for m, es in g.items() if any(e.startswith(f"{PACKAGE}.startup") for e in es)
                   and not m.startswith(f"{PACKAGE}.startup") and m != f"{PACKAGE}.__main__")
    assert users == []


#: The layers of spar_py, top first: a module imports only from its own layer or those below.
#: The kb's loaders build world objects (robots, shapes, the collision scene), so kb sits above
#: world; phase2 and pictures are side by side and import neither each other.
LAYERS = (("startup", "__main__"), ("app",), ("planning",), ("phase2",), ("pictures",), ("kb",), ("world",),
          ("core",))
SIDE_BY_SIDE = {"phase2", "pictures"}


def _layer(module: str) -> int | None:
    part = module.split(".")[1] if "." in module else ""
    return next((i for i, names in enumerate(LAYERS) if part in names), None)


def test_imports_run_one_way_down_the_layers() -> None:
    up = []
    for m, es in sorted(_graph().items()):
        for e in sorted(es):
            a, b = _layer(m), _layer(e)
            if a is None or b is None or a == b:
                continue
            parts = {m.split(".")[1], e.split(".")[1]}
            if b < a or parts <= SIDE_BY_SIDE:
                up.append(f"{m} -> {e}")
    assert up == [], "imports against the layers: " + "; ".join(up)
