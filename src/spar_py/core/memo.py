"""Bounded memo tables (no module-level caches).

A planning run asks the same geometric questions many times: phase 1 in every round
of its deepening search, phase 2 each time it re-runs an instance after a remedy, and
planning a cell again asks them all again. The answers that depend only on the cell and
the question are kept in the tables of the cell's cache (world.run.CellCache, kept beside
the immutable cell by the Planner or the engine): they live as long as it does, and each
table holds at most ``limit`` entries (the least recently used is dropped first). A
run's own state (what it refused, its tokens) is in its log, never here.
"""
from __future__ import annotations

from collections import OrderedDict
from collections.abc import Callable, Hashable
from typing import Generic, TypeVar

V = TypeVar("V")

__all__ = ["LRU", "Memo"]


class LRU(Generic[V]):
    """A mapping of at most ``limit`` entries that drops the least recently used."""

    __slots__ = ("limit", "_d")

    def __init__(self, limit: int) -> None:
        if limit < 1:
            raise ValueError("an LRU table needs a limit of at least 1")
        self.limit = limit
        self._d: OrderedDict[Hashable, V] = OrderedDict()

    def __len__(self) -> int:
        return len(self._d)

    def __contains__(self, key: Hashable) -> bool:
        return key in self._d

    def __getitem__(self, key: Hashable) -> V:
        v = self._d[key]
        self._d.move_to_end(key)
        return v

    def get(self, key: Hashable, default: V | None = None) -> V | None:
        """The value of ``key`` (marked as just used), or ``default``."""
        if key in self._d:
            return self[key]
        return default

    def __setitem__(self, key: Hashable, value: V) -> None:
        self._d[key] = value
        self._d.move_to_end(key)
        while len(self._d) > self.limit:
            self._d.popitem(last=False)

    def pop(self, key: Hashable, default: V | None = None) -> V | None:
        """Remove ``key`` and return its value, or ``default`` if it is not there."""
        return self._d.pop(key, default)

    def get_or_compute(self, key: Hashable, compute: Callable[[], V]) -> V:
        """The value of ``key``, computed with ``compute()`` and kept on a miss."""
        if key in self._d:
            return self[key]
        v = compute()
        self[key] = v
        return v

    def clear(self) -> None:
        """Drop every entry."""
        self._d.clear()


class Memo:
    """The memo tables of one cell, by name; each created on first use with its limit."""

    __slots__ = ("_tables",)

    def __init__(self) -> None:
        self._tables: dict[str, LRU] = {}

    def table(self, name: str, limit: int) -> LRU:
        """The table ``name`` (at most ``limit`` entries)."""
        t = self._tables.get(name)
        if t is None:
            t = self._tables[name] = LRU(limit)
        return t

    def existing(self, name: str) -> LRU | None:
        """The table ``name`` if it has been made, else None (none is made)."""
        return self._tables.get(name)

    def sizes(self) -> dict[str, int]:
        """Entries per table (for tests and benchmarks)."""
        return {k: len(v) for k, v in self._tables.items()}

    def clear(self) -> None:
        """Drop every table."""
        self._tables.clear()
