"""A cell's kept answers: the bounded memo tables the rooms keep per cell, and its scene.

Answers here depend only on the cell's content and the question asked, so they are kept
across planning runs of the same cell; a run's own state (options, log) is world.run's.
"""
from __future__ import annotations

from typing import TYPE_CHECKING

from spar_py.core.memo import LRU, Memo
from spar_py.world.collision.scene import CollisionScene, scene_for

if TYPE_CHECKING:
    from spar_py.core.model import Cell


class CellCache:
    """The bounded answers kept for one cell across its runs (content-keyed memo tables:
    core/memo.py) and its collision scene. Holds no run's state."""

    __slots__ = ("cell", "memo", "_scene")

    def __init__(self, cell: Cell) -> None:
        self.cell = cell
        self.memo = Memo()
        self._scene: CollisionScene | None = None

    def table(self, name: str, limit: int) -> LRU:
        """The kept table ``name`` (at most ``limit`` entries)."""
        return self.memo.table(name, limit)

    def scene(self) -> CollisionScene:
        """The cell's collision scene (world.collision.scene.scene_for), built once and kept."""
        if self._scene is None:
            self._scene = scene_for(self.cell, self.memo)
        return self._scene
