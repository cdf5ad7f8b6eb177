"""The dataclass-method image (dcimage.py): the same classes as without it, kept between runs.

The reference for "the same" is the interpreter itself: every class below is defined once
with the builtin ``exec`` and once through an image (empty, then loaded back from its file),
and every generated method's code object must be equal (code objects compare their
bytecode, constants, names, flags and line table).
"""
from __future__ import annotations

import dataclasses
import inspect
import json
import marshal
import os
import subprocess
import sys
from pathlib import Path
from typing import Any, Callable

import pytest

from spar_py.startup import dcimage
from spar_py.planning import qlf

from paths import ROOT

METHODS = ("__init__", "__repr__", "__eq__", "__hash__", "__setattr__", "__delattr__", "__lt__", "__le__",
           "__gt__", "__ge__", "__getstate__", "__setstate__")


def _make_classes() -> list[type]:
    """Dataclasses of every kind the planner uses (frozen, defaults, factories, order, slots,
    keyword-only, init=False fields, a ClassVar, a forward-referenced annotation)."""
    from typing import ClassVar

    @dataclasses.dataclass(frozen=True)
    class Frozen:
        a: int
        b: str = "x"
        c: tuple = dataclasses.field(default=(), compare=False, repr=False)

    @dataclasses.dataclass
    class Mutable:
        xs: list = dataclasses.field(default_factory=list)
        n: float = 0.0
        kind: ClassVar[str] = "m"

        def __post_init__(self) -> None:
            self.n = float(self.n)

    @dataclasses.dataclass(order=True, slots=True)
    class Ordered:
        k: int
        v: "Frozen | None" = None

    @dataclasses.dataclass(kw_only=True, eq=False)
    class KwOnly:
        a: int
        b: int = dataclasses.field(default=2, init=False)

    return [Frozen, Mutable, Ordered, KwOnly]


def _codes(classes: list[type]) -> dict[str, Any]:
    out = {}
    for cls in classes:
        for name in METHODS:
            fn = vars(cls).get(name)
            if inspect.isfunction(fn):
                out[f"{cls.__name__}.{name}"] = fn.__code__
    return out


def _with_image(image: dcimage.CodeImage, make: Callable[[], list[type]]) -> list[type]:
    dataclasses.exec = image.exec  # type: ignore[attr-defined]
    try:
        return make()
    finally:
        dcimage.uninstall(image)


def test_classes_through_the_image_have_the_interpreters_code(tmp_path: Path) -> None:
    reference = _codes(_make_classes())
    path = tmp_path / "img.marshal"
    first = dcimage.CodeImage(path)
    compiled = _codes(_with_image(first, _make_classes))
    assert first.added == len(first.codes) > 0 and first.save()
    loaded = dcimage.CodeImage(path)
    assert set(loaded.codes) == set(first.codes)
    again = _codes(_with_image(loaded, _make_classes))
    assert loaded.added == 0, "a text the image holds was compiled again"
    assert len(reference) >= 15
    assert compiled == reference and again == reference
    # and they behave as dataclasses do
    Frozen, Mutable, Ordered, KwOnly = _with_image(loaded, _make_classes)
    f = Frozen(1)
    assert f == Frozen(1, "x", (9,)) and repr(f).endswith(".Frozen(a=1, b='x')") and hash(f) == hash(Frozen(1))
    with pytest.raises(dataclasses.FrozenInstanceError):
        f.a = 2  # type: ignore[misc]
    assert Mutable().xs == [] and Mutable().xs is not Mutable().xs and Mutable(n=3).n == 3.0
    assert sorted([Ordered(2), Ordered(1)])[0].k == 1
    assert KwOnly(a=1).b == 2 and KwOnly(a=1) != KwOnly(a=1)


def test_a_text_is_compiled_without_this_modules_future_flags() -> None:
    # this module has `from __future__ import annotations` (annotations left unevaluated);
    # the dataclasses module has not, and its exec evaluates them when the def runs
    src = "def f(x: undefined_name):\n return x\n"
    exec(compile(src, "<string>", "exec"), {}, {})  # inherits the future flag: no NameError
    with pytest.raises(NameError):
        dcimage.CodeImage(None).exec(src, {}, {})


def test_a_damaged_or_foreign_file_is_ignored_and_rewritten(tmp_path: Path) -> None:
    path = tmp_path / "img.marshal"
    for junk in (b"not marshal at all", marshal.dumps([1, 2, 3]), marshal.dumps({"def f(): pass": 3}), b"",
                 marshal.dumps({"def f(): pass": compile("pass", "<string>", "exec")})):  # format 1
        path.write_bytes(junk)
        image = dcimage.CodeImage(path)
        assert image.codes == {}
        _with_image(image, _make_classes)
        assert image.save()
        assert dcimage.CodeImage(path).codes.keys() == image.codes.keys()


def test_the_image_is_bounded(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(dcimage, "MAX_ENTRIES", 5)
    path = tmp_path / "img.marshal"
    old = dcimage.CodeImage(path)
    for i in range(8):
        old.code(f"x{i} = {i}\n")
    old.save()
    assert len(dcimage.CodeImage(path).codes) == 5
    image = dcimage.CodeImage(path)
    used = [image.code(f"y{i} = {i}\n") for i in range(3)]
    assert used and image.save()
    kept = dcimage.CodeImage(path).codes
    assert len(kept) == 5 and {f"y{i} = {i}\n" for i in range(3)} <= set(kept), "what a run used is kept first"


def test_an_unwritable_cache_is_left_alone(tmp_path: Path) -> None:
    where = tmp_path / "a_file"
    where.write_text("")
    image = dcimage.CodeImage(where / "img.marshal")  # its directory is a file
    image.code("z = 1\n")
    assert image.save() is False and image.codes


def test_cache_off_means_no_image(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv(qlf.ENV, "off")
    assert dcimage.image_path() is None and dcimage.install() is None
    assert "exec" not in vars(dataclasses)


def _spar(args: list[str], cache: Path) -> subprocess.CompletedProcess:
    env = {**os.environ, qlf.ENV: str(cache)}
    return subprocess.run([sys.executable, "-m", "spar_py", *args], env=env, cwd=ROOT, capture_output=True,
                          text=True, timeout=300)


def test_spar_fills_the_image_once_and_then_compiles_nothing(tmp_path: Path) -> None:
    cache = tmp_path / "cache"
    args = ["kb", "check", "kb/objects/peg.yaml"]
    first = _spar(args, cache)
    assert first.returncode == 0, first.stderr
    path = dcimage.image_path(cache)
    assert path is not None and path.exists()
    before = (path.stat().st_mtime_ns, path.read_bytes())
    second = _spar(args, cache)
    assert second.returncode == 0 and second.stdout == first.stdout
    assert (path.stat().st_mtime_ns, path.read_bytes()) == before, "the second run compiled a method again"
    n = len(dcimage.CodeImage(path).codes)
    assert n >= 20  # kb.py's and model.py's dataclasses at least


def test_the_python_api_leaves_dataclasses_alone() -> None:
    code = ("import dataclasses, json; from spar_py import Planner, load_problem; import spar_py.app.cli; "
            "print(json.dumps('exec' in vars(dataclasses)))")
    r = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    assert json.loads(r.stdout) is False


def test_an_entry_that_is_not_code_is_compiled_again(tmp_path: Path) -> None:
    path = tmp_path / "img.marshal"
    src = "x = 1\n"
    path.write_bytes(marshal.dumps({src: b"\x00junk", "y = 2\n": marshal.dumps(7)}))
    image = dcimage.CodeImage(path)
    assert len(image.codes) == 2
    ns: dict[str, Any] = {}
    image.exec(src, {}, ns)
    assert ns["x"] == 1 and image.added == 1 and image.save()
    assert marshal.loads(dcimage.CodeImage(path).codes[src]) == compile(src, "<string>", "exec", dont_inherit=True)


def test_saving_removes_images_of_other_layouts_only(tmp_path: Path) -> None:
    """An image of an older layout of this module (format 1 before) is never read again and is
    removed when this one is written; another interpreter's image of this layout stays."""
    path = dcimage.image_path(tmp_path)
    assert path is not None and f"-{dcimage.FORMAT}-" in path.name
    old = tmp_path / path.name.replace(f"-{dcimage.FORMAT}-", "-1-", 1)
    other = tmp_path / f"dataclass-methods-{dcimage.FORMAT}-cpython-399-00000000-O0.marshal"
    unrelated = tmp_path / "notes.marshal"
    for p in (old, other, unrelated):
        p.write_bytes(marshal.dumps({}))
    image = dcimage.CodeImage(path)
    _with_image(image, _make_classes)
    assert image.save()
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted([path.name, other.name, unrelated.name])
