"""The compiled methods of the planner's dataclasses, kept between ``spar`` runs (cold start).

``@dataclass`` writes each class's ``__init__``, ``__repr__``, ``__eq__``, ``__hash__``,
``__setattr__`` ... as Python source and compiles it with ``exec`` when the class is
defined. A cold ``spar plan`` defines some 54 dataclasses (model, kb, planner,
uncertainty, the world layer), about 290 generated functions, and compiling their source
is the largest single cost of importing the planner (bench/coldstart.py, bench/RESULTS.md).

This module compiles each such source text once and keeps the code objects in a
``marshal`` file in the planner's cache directory (qlf.py's, ``SPAR_QLF_CACHE``; ``off``
turns this off too), keyed by the source text itself, next to the planner's Prolog image.
While it is installed, dataclasses' ``exec`` of a text it has seen runs the kept code
object instead of compiling the text again. Nothing else changes: the code object is
what ``exec`` would have compiled from the same text (same file name ``<string>``, no
inherited ``__future__`` flags, the interpreter's optimisation level, all part of the
file's key with the bytecode magic number), so the classes and their methods are the
same (tests/test_dcimage.py compares them).

Only the ``spar`` console script installs it (entry.main, ``python -m spar_py``),
before its first import of the planner, and saves what was new when the process ends;
the Python API never does (a library must not change the stdlib for its host). A file
that cannot be read, is corrupt or is of another interpreter is ignored (and rewritten);
one that cannot be written is left as it is. At most :data:`MAX_ENTRIES` texts are kept.
"""
from __future__ import annotations

import builtins
import dataclasses
import marshal
import os
import sys
from importlib.util import MAGIC_NUMBER
from pathlib import Path
from types import CodeType
from typing import Any

from spar_py.planning import qlf

#: Layout version of the file; part of its name.
FORMAT = 2
#: Most source texts kept (a plan uses about 300; other commands add their own).
MAX_ENTRIES = 4096
#: Files larger than this are not read (a plan's file is about 0.3 MB).
MAX_BYTES = 16 * 1024 * 1024
_FILENAME = "<string>"  # what exec() of a str names the code's file


class CodeImage:
    """Code objects of dataclass method sources: loaded from ``path``, extended by compiling
    what is missing, written back (atomically) by :meth:`save` if anything was added."""

    def __init__(self, path: Path | None) -> None:
        self.path = path
        #: source text -> its code object, marshalled: unmarshalled only when a class asks
        #: (the file also holds other commands' and other checkouts' methods)
        self.codes: dict[str, bytes] = _read(path) if path is not None else {}
        self.used: set[str] = set()
        self.added = 0

    def code(self, source: str) -> CodeType:
        """The code object of ``source`` as ``exec(source)`` in the dataclasses module compiles it."""
        data = self.codes.get(source)
        code = _code(data) if data is not None else None
        if code is None:
            code = compile(source, _FILENAME, "exec", dont_inherit=True)
            self.codes[source] = marshal.dumps(code)
            self.added += 1
        self.used.add(source)
        return code

    def exec(self, source: Any, globals: dict | None = None, locals: dict | None = None) -> None:
        """``exec`` for the dataclasses module: a str source runs from its kept code object."""
        if isinstance(source, str):
            source = self.code(source)
        builtins.exec(source, globals, locals)

    def save(self) -> bool:
        """Write the image if this process added texts (those used now first, then the rest up
        to :data:`MAX_ENTRIES`); True if written. Never raises for a file-system problem."""
        if self.path is None or not self.added:
            return False
        keep: dict[str, bytes] = {}
        for s in [*self.used, *self.codes]:
            if len(keep) >= MAX_ENTRIES:
                break
            keep.setdefault(s, self.codes[s])
        tmp = self.path.with_name(f".{self.path.name}.{os.getpid()}.tmp")
        try:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            with open(tmp, "wb") as f:
                marshal.dump(keep, f)
            os.replace(tmp, self.path)
        except OSError:
            try:
                tmp.unlink()
            except OSError:
                pass
            return False
        self.added = 0
        _drop_other_formats(self.path.parent)
        return True


def _drop_other_formats(base: Path) -> None:
    """Remove images of this module's other layouts (``dataclass-methods-<F>-*.marshal``,
    F != FORMAT) from ``base``: no process reads them again. Images of the same layout for
    other interpreters stay (their processes still use them)."""
    for p in base.glob("dataclass-methods-*-*.marshal"):
        fmt = p.name[len("dataclass-methods-"):].split("-", 1)[0]
        if fmt != str(FORMAT):
            try:
                p.unlink()
            except OSError:
                pass


def _code(data: bytes) -> CodeType | None:
    """A kept code object (None if ``data`` is not one: then it is compiled again)."""
    try:
        code = marshal.loads(data)
    except (EOFError, ValueError, TypeError):
        return None
    return code if isinstance(code, CodeType) else None


def _read(path: Path) -> dict[str, bytes]:
    """The image at ``path``; empty if it is missing, unreadable, too large or not an image."""
    try:
        if path.stat().st_size > MAX_BYTES:
            return {}
        with open(path, "rb") as f:
            data = marshal.load(f)
    except (OSError, EOFError, ValueError, TypeError):
        return {}
    if not isinstance(data, dict) or not all(
            isinstance(k, str) and isinstance(v, bytes) for k, v in data.items()):
        return {}
    return data


def image_path(base: Path | None = None) -> Path | None:
    """This interpreter's image file in the cache directory (qlf.cache_dir()), or None when
    the cache is off. Its name holds the bytecode magic number and the optimisation level."""
    base = qlf.cache_dir() if base is None else base
    if base is None:
        return None
    tag = f"{sys.implementation.cache_tag}-{MAGIC_NUMBER.hex()}-O{sys.flags.optimize}"
    return base / f"dataclass-methods-{FORMAT}-{tag}.marshal"


def install(path: Path | None = None) -> CodeImage | None:
    """Make dataclasses compile through a :class:`CodeImage` of ``path`` (default
    :func:`image_path`) from now on; the image, or None if the cache is off or an image is
    installed already. For the ``spar`` process only (module doc)."""
    if "exec" in vars(dataclasses):
        return None
    path = image_path() if path is None else path
    if path is None:
        return None
    image = CodeImage(path)
    dataclasses.exec = image.exec  # type: ignore[attr-defined]
    return image


def uninstall(image: CodeImage) -> None:
    """Undo :func:`install` of ``image`` (dataclasses compiles with the builtin exec again)."""
    if vars(dataclasses).get("exec") == image.exec:
        del dataclasses.exec  # type: ignore[attr-defined]
