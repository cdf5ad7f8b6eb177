"""A value read from a KB file, with where it came from, and how messages quote values.

:class:`Node` carries a YAML value with its file and key path, so each check of a value
raises a one-line :class:`~spar_py.core.errors.KBError` (``FILE: KEY.PATH: expected ...,
not ...``); :func:`show` and :func:`num` quote a value in such a message, never a whole
structure. The bottom of the kb package: it imports nothing of it.
"""
from __future__ import annotations

import math
import re
from dataclasses import dataclass
from typing import Any, Iterable

import numpy as np

from spar_py.core.errors import KBError

__all__ = ["LABEL_RE", "MAX_MAGNITUDE", "SHOW_CHARS", "Node", "cut", "did_you_mean", "num", "show"]


SHOW_CHARS = 40  # a value quoted in a message is cut to this many characters
LABEL_RE = re.compile(r"[a-z][A-Za-z0-9_]*")  # used with fullmatch: no trailing newline
MAX_MAGNITUDE = 1e9  # any number in a KB file, in the file's units


def show(v: Any) -> str:
    """A value for a message: numbers rounded for reading (``0.16``), strings quoted, cut to
    SHOW_CHARS characters; collections by size only (never a whole structure, never a file)."""
    if v is None:
        return "nothing"
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v) if abs(v) < 10**15 else f"an integer of about {int(v.bit_length() * 0.30103) + 1} digits"
    if isinstance(v, float):
        return f"{v:.6g}"
    if isinstance(v, str):
        return cut(repr(v[: SHOW_CHARS + 2]))
    if isinstance(v, list):
        if len(v) <= 6 and all(isinstance(x, (int, float, str)) for x in v):
            return cut("[" + ", ".join(show(x) for x in v) + "]")
        return f"a list of {len(v)} items"
    if isinstance(v, dict):
        return f"a mapping of {len(v)} keys"
    return cut(type(v).__name__)


def num(x: float) -> str:
    """A number rounded for reading in a message (6 significant digits)."""
    return f"{x:.6g}"


def cut(s: str) -> str:
    """``s`` cut to SHOW_CHARS characters (``...`` marks the cut)."""
    return s if len(s) <= SHOW_CHARS else s[: SHOW_CHARS - 3] + "..."


def did_you_mean(name: str, choices: Iterable[str]) -> str | None:
    """The one of ``choices`` closest to a misspelt ``name`` (None if none is close)."""
    import difflib  # only for an unknown name's message: a cold plan of a good file never needs it

    close = difflib.get_close_matches(name, list(choices), n=1, cutoff=0.6)
    return close[0] if close else None


@dataclass(frozen=True)
class Node:
    """A YAML value with the file and key path it came from, for one-line errors."""

    file: str
    path: str
    value: Any

    def fail(self, expected: str, got: str | None = None) -> KBError:
        """The error for this node: ``FILE: PATH: expected EXPECTED, not GOT``."""
        return KBError(self.file, self.path or "(top level)", expected, got)

    def key(self, name: str, required: bool = True) -> "Node | None":
        """The child ``name`` of a mapping (None if absent and not required)."""
        if not isinstance(self.value, dict):
            raise self.fail("a mapping", show(self.value))
        if name not in self.value:
            if required:
                raise Node(self.file, self._join(name), None).fail("a value (key missing)")
            return None
        return Node(self.file, self._join(name), self.value[name])

    def items(self) -> list[tuple[str, "Node"]]:
        """The (key, child) pairs of a mapping."""
        if not isinstance(self.value, dict):
            raise self.fail("a mapping", show(self.value))
        return [(str(k), Node(self.file, self._join(str(k)), v)) for k, v in self.value.items()]

    def elements(self, min_len: int = 0) -> list["Node"]:
        """The children of a sequence (at least ``min_len`` of them)."""
        if not isinstance(self.value, list) or len(self.value) < min_len:
            raise self.fail((f"a list of at least {min_len} item" + "s" * (min_len > 1)) if min_len else "a list",
                            show(self.value))
        return [Node(self.file, f"{self.path}[{i}]", v) for i, v in enumerate(self.value)]

    def number(self) -> float:
        """A finite real number of magnitude at most MAX_MAGNITUDE."""
        v = self.value
        if isinstance(v, bool) or not isinstance(v, (int, float)):
            raise self.fail("a number", show(v))
        if isinstance(v, float) and not math.isfinite(v):
            raise self.fail("a finite number", show(v))
        if abs(v) > MAX_MAGNITUDE:
            raise self.fail(f"a number of magnitude at most {num(MAX_MAGNITUDE)}", show(v))
        return float(v)

    def positive(self) -> float:
        """A number > 0."""
        v = self.number()
        if v <= 0:
            raise self.fail("a positive number", num(v))
        return v

    def label(self) -> str:
        """A Prolog-atom-like label (lower-case start, letters, digits, underscores), exactly."""
        v = self.value
        if not isinstance(v, str) or not LABEL_RE.fullmatch(v):
            raise self.fail("a label (letters, digits, _; lower-case first)", show(v))
        return v

    def text(self) -> str:
        """A non-empty string."""
        if not isinstance(self.value, str) or not self.value.strip():
            raise self.fail("a non-empty string", show(self.value))
        return self.value

    def choice(self, options: Iterable[str]) -> str:
        """One of the strings ``options``."""
        opts = tuple(options)
        if not isinstance(self.value, str) or self.value not in opts:
            raise self.fail(f"one of {', '.join(opts)}", show(self.value))
        return self.value

    def vector(self, n: int) -> np.ndarray:
        """A list of ``n`` numbers (each as :meth:`number` takes it), as an (n,) float array."""
        v = self.value
        if type(v) is list and len(v) == n:  # every item an int or float number() takes: no Nodes
            xs = [float(x) for x in v if (type(x) is float or type(x) is int) and abs(x) <= MAX_MAGNITUDE]
            if len(xs) == n:
                return np.array(xs)
        items = self.elements()
        if len(items) != n:
            raise self.fail(f"a list of {n} numbers", f"{len(items)} items")
        return np.array([e.number() for e in items])

    def interval(self) -> tuple[float, float]:
        """A ``[lo, hi]`` pair with lo <= hi."""
        lo, hi = self.vector(2)
        if lo > hi:
            raise self.fail("[lo, hi] with lo <= hi", f"[{num(lo)}, {num(hi)}]")
        return float(lo), float(hi)

    def _join(self, name: str) -> str:
        return f"{self.path}.{name}" if self.path else name
