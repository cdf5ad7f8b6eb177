"""Structure facts of src/spar_py, read from the sources (the AST), not from importing them.

- no import circle among the package's modules, ``if TYPE_CHECKING:`` imports and imports
  inside functions counted;
- the world layer's rooms (subpackages of world/) are entered through their doors: code
  outside a room imports ``spar_py.world.<room>`` and names its ``__all__`` lists, never a
  module behind it;
- no private name (``_x``) taken across modules, by import or by attribute of an imported
  module;
- no file over 1,000 lines; one gripper class; ``Cell`` and ``Product`` frozen dataclasses.

Each check is also run on a small synthetic package, so a check that cannot fail is caught.
"""
from __future__ import annotations

import ast
from dataclasses import dataclass, field
from pathlib import Path

import pytest

from test_imports import import_cycles, modules

SRC = Path(__file__).resolve().parent.parent / "src"
MAX_LINES = 1000


@dataclass
class Sources:
    """A package's modules read once: each module's file, its parsed tree and, for a package,
    the names its ``__all__`` lists."""

    root: str
    files: dict[str, Path]
    trees: dict[str, ast.Module] = field(init=False)
    exports: dict[str, set[str]] = field(init=False)

    def __post_init__(self) -> None:
        self.trees = {m: ast.parse(p.read_text(), str(p)) for m, p in self.files.items()}
        self.exports = {m: _all_of(self.trees[m]) for m, p in self.files.items() if p.name == "__init__.py"}


def read(src: Path, root: str) -> Sources:
    return Sources(root, modules(src, root))


def _all_of(tree: ast.Module) -> set[str]:
    for node in tree.body:
        if isinstance(node, ast.Assign) and any(isinstance(t, ast.Name) and t.id == "__all__" for t in node.targets):
            return {e.value for e in node.value.elts}  # type: ignore[attr-defined]
    return set()


def _target(mod: str, path: Path, node: ast.ImportFrom) -> str:
    if not node.level:
        return node.module or ""
    base = mod.split(".") if path.name == "__init__.py" else mod.split(".")[:-1]
    base = base[: len(base) - (node.level - 1)]
    return ".".join(base + ([node.module] if node.module else []))


def imports(src: Sources) -> list[tuple[str, str, str, int]]:
    """(importer, imported module, name or "", line) for every import of a module of the package
    (at any depth of the file: functions and TYPE_CHECKING blocks included)."""
    root, mods, out = src.root, src.files, []
    for mod, tree in src.trees.items():
        for node in ast.walk(tree):
            if isinstance(node, ast.ImportFrom):
                target = _target(mod, mods[mod], node)
                if target != root and not target.startswith(root + "."):
                    continue
                for a in node.names:
                    sub = f"{target}.{a.name}"
                    if sub in mods and a.name not in src.exports.get(target, set()):  # `from pkg import module`
                        out.append((mod, sub, "", node.lineno))
                    else:
                        out.append((mod, target, a.name, node.lineno))
            elif isinstance(node, ast.Import):
                for a in node.names:
                    if a.name == root or a.name.startswith(root + "."):
                        out.append((mod, a.name, "", node.lineno))
    return out


def cycles(src: Sources) -> list[list[str]]:
    """The import circles (test_imports' strongly connected components), counting every import
    of :func:`imports`: a package's import of its own modules (the door imports what it
    exports) and a module's import of its own package too."""
    graph: dict[str, set[str]] = {m: set() for m in src.files}
    for a, b, _, _ in imports(src):
        if b in src.files and a != b:
            graph[a].add(b)
    return import_cycles(graph)


def rooms(src: Sources) -> set[str]:
    """The rooms of the package's ``world``: its subpackages (dotted names)."""
    world = f"{src.root}.world"
    return {m for m in src.exports if m.startswith(world + ".") and m.count(".") == world.count(".") + 1}


def room_of(mod: str, rms: set[str]) -> str | None:
    return next((r for r in rms if mod == r or mod.startswith(r + ".")), None)


def door_breaches(src: Sources) -> list[str]:
    """Imports that enter a room of the package's world other than through its door, or take a
    name its door does not list."""
    rms = rooms(src)
    out = []
    for a, b, name, line in imports(src):
        r = room_of(b, rms)
        if r is None or room_of(a, rms) == r:
            continue
        if b != r:
            out.append(f"{a}:{line} imports {b}{'.' + name if name else ''} behind the door {r}")
        elif name and name not in src.exports[r]:
            out.append(f"{a}:{line} takes {name} from {r}, whose __all__ does not list it")
    return out


def private_crossings(src: Sources) -> list[str]:
    """Private names (one leading underscore) one module takes from another: ``from m import _x``
    or ``m._x`` where ``m`` names an imported module of the package."""
    mods, out = src.files, []
    for a, b, name, line in imports(src):
        if name.startswith("_") and not name.startswith("__") and a != b:
            out.append(f"{a}:{line} imports {b}.{name}")
    for mod, tree in src.trees.items():
        aliases: dict[str, str] = {}
        for node in ast.walk(tree):
            if isinstance(node, ast.ImportFrom):
                target = _target(mod, mods[mod], node)
                for al in node.names:
                    if f"{target}.{al.name}" in mods:
                        aliases[al.asname or al.name] = f"{target}.{al.name}"
            elif isinstance(node, ast.Import):
                for al in node.names:
                    if al.name in mods and al.asname:
                        aliases[al.asname] = al.name
        for node in ast.walk(tree):
            if (isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name) and node.value.id in aliases
                    and node.attr.startswith("_") and not node.attr.startswith("__")
                    and aliases[node.value.id] != mod):
                out.append(f"{mod}:{node.lineno} takes {aliases[node.value.id]}.{node.attr}")
    return out


def long_files(src: Sources) -> list[str]:
    return [f"{m}: {n} lines" for m, p in src.files.items() if (n := len(p.read_text().splitlines())) > MAX_LINES]


def classes_named(src: Sources, word: str) -> list[str]:
    """Classes whose name contains ``word`` (case-insensitive)."""
    return [f"{m}.{n.name}" for m, tree in src.trees.items() for n in ast.walk(tree)
            if isinstance(n, ast.ClassDef) and word in n.name.lower()]


def is_frozen_dataclass(tree: ast.Module, cls: str) -> bool:
    for node in ast.walk(tree):
        if isinstance(node, ast.ClassDef) and node.name == cls:
            for d in node.decorator_list:
                if isinstance(d, ast.Call) and getattr(d.func, "id", getattr(d.func, "attr", "")) == "dataclass":
                    return any(k.arg == "frozen" and getattr(k.value, "value", False) is True for k in d.keywords)
    return False


# ---------------------------------------------------------------------------------- the package

PKG = read(SRC, "spar_py")


def test_no_import_circle() -> None:
    assert cycles(PKG) == []


def test_rooms_are_entered_through_their_doors() -> None:
    rms = rooms(PKG)
    assert {"spar_py.world.robot", "spar_py.world.parts", "spar_py.world.collision", "spar_py.world.reach",
            "spar_py.world.motion", "spar_py.world.product"} <= rms
    for r in rms:  # every door says what its room answers and lists what it exports
        assert ast.get_docstring(PKG.trees[r]), f"{r}: the door has no docstring"
        assert PKG.exports[r], f"{r}: the door has no __all__"
    assert door_breaches(PKG) == []


def test_no_private_name_crosses_modules() -> None:
    assert private_crossings(PKG) == []


def test_no_file_over_1000_lines() -> None:
    assert long_files(PKG) == []


def test_one_gripper_class() -> None:
    assert len(classes_named(PKG, "gripper")) == 1, classes_named(PKG, "gripper")


def test_cell_and_product_are_frozen() -> None:
    assert is_frozen_dataclass(PKG.trees["spar_py.core.model"], "Cell")
    assert is_frozen_dataclass(PKG.trees["spar_py.core.model"], "Product")


# ------------------------------------------------------------------ the checks can fail: a fake package


@pytest.fixture()
def fake(tmp_path: Path) -> Path:
    def w(rel: str, text: str) -> None:
        p = tmp_path / "pkg" / rel
        p.parent.mkdir(parents=True, exist_ok=True)
        p.write_text(text)

    w("__init__.py", "")
    w("world/__init__.py", "")
    w("world/room/__init__.py", '"""A room."""\nfrom pkg.world.room.inner import f\n__all__ = ["f"]\n')
    w("world/room/inner.py", "def f(): pass\ndef _g(): pass\ndef h(): pass\n")
    w("a.py", "from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    from pkg.b import x\n")
    w("b.py", "from pkg.a import y\n")
    w("c.py", "from pkg.world.room.inner import f\nfrom pkg.world.room import h\n"
              "from pkg.world.room import inner\ninner._g()\nfrom pkg.world.room.inner import _g\n")
    w("big.py", "x = 1\n" * (MAX_LINES + 1))
    w("model.py", "from dataclasses import dataclass\n@dataclass\nclass Cell:\n    x: int\n"
                  "class Gripper: pass\nclass GripperGeometry: pass\n")
    return tmp_path


def test_the_checks_find_what_they_look_for(fake: Path) -> None:
    mods = read(fake, "pkg")
    assert cycles(mods) == [["pkg.a", "pkg.b"]]  # the TYPE_CHECKING import counts
    breaches = door_breaches(mods)
    assert any("behind the door" in b for b in breaches) and any("does not list it" in b for b in breaches)
    crossings = private_crossings(mods)
    assert any("inner._g" in c for c in crossings) and sum("_g" in c for c in crossings) == 2
    assert long_files(mods) == [f"pkg.big: {MAX_LINES + 1} lines"]
    assert len(classes_named(mods, "gripper")) == 2
    assert not is_frozen_dataclass(mods.trees["pkg.model"], "Cell")
