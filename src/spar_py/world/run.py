"""One planning run's view of the world: the cell's kept answers, the run's options and its log.

A :class:`~spar_py.core.model.Cell` is the validated model and is never written to.
Beside it sit two kinds of state:

- :class:`CellCache`: answers that depend only on the cell's content and the question
  (the collision scene, placement grids, requirement states, SUP/INF bounders and
  results, phase-2 step worlds, instance motions), kept in bounded tables across runs of
  the same cell. A kept "no" keeps its reason, so a later run that meets it again logs
  that reason in its own log.
- :class:`WorldRun`: one planning run: the cache, the run's :class:`RunOptions` and its
  :class:`RunLog` (collision refusals with their pairs, motion failures, the instance
  motions and step data Prolog names by token), empty when the run starts. Its
  :meth:`WorldRun.arc_pairs` is phase 1's door to the world; phase 2's door is the
  planning run (planning/run.py), which holds a WorldRun, since the paper's phase 2
  (phase2/) sits above this layer.
"""
from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from spar_py.core.errors import SparValueError
from spar_py.core.memo import LRU
from spar_py.core.model import Cell
from spar_py.world.reach import RULES, arc
from spar_py.world.collision import CellCache
from spar_py.world.motion import FAILURES_KEPT, MotionFailure, MotionOptions
from spar_py.world.reach import Refusal

__all__ = ["RunLog", "RunOptions", "WorldRun"]

#: Refusals a run's log keeps (the "no plan" explanation): at most this many distinct ones.
REFUSALS_LIMIT = 256
#: Tokens a run's log keeps (phase-2 runs whose data stays in Python until the plan is built;
#: the oldest is dropped first, and a plan names one of its run's last few).
TOKENS_LIMIT = 4096


@dataclass(frozen=True)
class RunOptions:
    """What one planning run is asked to do: ``placements`` the rule for a put-down into a
    stable pose (reachable: some placement in the free regions must reach it; paper: assumed,
    Sec. 5.2.4); ``motion`` how motions are planned, None for end-points only."""

    placements: str = "reachable"
    motion: MotionOptions | None = None

    def __post_init__(self) -> None:
        if self.placements not in RULES:
            raise SparValueError(f"placement rule {self.placements!r} is not one of {', '.join(RULES)}")


@dataclass
class RunLog:
    """What one run refused and why, and the data it keeps for the plan: collision refusals
    (by what was refused, their pairs in first-seen order), motion failures (distinct, at
    most FAILURES_KEPT), data Prolog names by token (instance motions, step geometry)."""

    refused: dict[str, list[tuple[str, str]]] = field(default_factory=dict)
    motion_failures: list[MotionFailure] = field(default_factory=list)
    tokens: LRU = field(default_factory=lambda: LRU(TOKENS_LIMIT))
    kept_count: int = 0

    def refuse(self, what: str, pairs: Iterable[Sequence[str]]) -> None:
        """Log that ``what`` had IK solutions, every one colliding with one of ``pairs``."""
        if what not in self.refused and len(self.refused) >= REFUSALS_LIMIT:
            return
        seen = self.refused.setdefault(what, [])
        for p in pairs:
            p = (str(p[0]), str(p[1]))
            if p not in seen:
                seen.append(p)

    def refusals(self) -> list[Refusal]:
        """The logged refusals, in the order first seen."""
        return [Refusal(w, tuple(ps)) for w, ps in self.refused.items()]

    def fail_motion(self, failure: MotionFailure) -> None:
        """Log a motion that does not exist (each distinct one once, at most FAILURES_KEPT)."""
        if len(self.motion_failures) < FAILURES_KEPT and failure not in self.motion_failures:
            self.motion_failures.append(failure)

    def keep(self, data: Any) -> int:
        """Keep ``data`` for the plan and return its token (1, 2, ...; the last TOKENS_LIMIT kept)."""
        self.kept_count += 1
        self.tokens[self.kept_count] = data
        return self.kept_count

    def kept(self, token: int) -> Any:
        """The data kept under ``token`` (SparValueError if this run kept none)."""
        try:
            return self.tokens[int(token)]
        except (KeyError, TypeError, ValueError):
            raise SparValueError(f"token {token!r} names nothing this run keeps") from None


class WorldRun:
    """One planning run's world: the cell's kept answers (``cache``), the run's ``options`` and
    its ``log`` (empty at the start). :meth:`arc_pairs` is phase 1's door."""

    __slots__ = ("cache", "options", "log")

    def __init__(self, cache: CellCache, options: RunOptions | None = None) -> None:
        self.cache = cache
        self.options = options if options is not None else RunOptions()
        self.log = RunLog()

    @property
    def cell(self) -> Cell:
        """The run's cell (read only)."""
        return self.cache.cell

    def arc_pairs(self, kind: str, objects: Sequence[str], grasps: Sequence[str], positions: Sequence[str],
                  ta: np.ndarray | str | None = None, rule: str | None = None) -> list[list[str]]:
        """The [grasp, position] pairs of phase 1's arc ``kind`` (reachable | mate_reachable,
        Sec. 5.2.4; world/reach/arcs.py) under ``rule`` (the run's placement rule by default); the
        pairs refused because every joint solution collides are logged with their pairs."""
        got = arc(self.cache, kind, objects, grasps, positions, ta, rule or self.options.placements)
        for r in got.refusals:
            self.log.refuse(r.what, r.pairs)
        return got.pairs
