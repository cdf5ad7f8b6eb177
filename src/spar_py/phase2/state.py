"""Phase 2's world before a step (:class:`World`) and the lookups every part of an instance's
run shares: a step's key, a grasp by label, where a part lies, the stock objects, a world key's
model. The run itself is instance.py's; one step steps.py's, the put-downs' placements
placements.py's.
"""
from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from spar_py.phase2 import uncertainty as ur
from spar_py.core.errors import SparValueError
from spar_py.core.geometry import same_stable_pose
from spar_py.core.model import Bounds, Cell, Grasp
from spar_py.world import reach
from spar_py.world.collision import CellCache

Step = dict[str, Any]


@dataclass(frozen=True)
class World:
    """The world before a step: uncertainty state, what the hand holds and with which grasp,
    the put-down placements chosen for this instance, the arm's last joint vector."""

    cache: CellCache
    unc: ur.WorldState
    placements: dict[str, reach.Placement | None]
    grasps: dict[str, str] = field(default_factory=dict)  # object -> grasp label while held
    joints: np.ndarray | None = None
    sources: dict[str, dict[str, str]] = field(default_factory=dict)  # step id -> {object: position label}
    active: dict[str, str] = field(default_factory=dict)  # stock object -> initial position name of its active part
    scans: Mapping[str, Bounds] = field(default_factory=dict)  # sensing action -> the bounds it leaves (cell units)
    key: tuple = ()  # what determines this world: the placements' key and the steps so far
    checked: tuple = ()  # (Constraint, satisfied) of every UR precondition checked so far
    complete: bool = True  # False: the last step's verdicts stop at its first unsatisfied one (step's early)
    #: What the step that made this world refused because every joint solution collides:
    #: (what, colliding pairs) each.
    refused: tuple[tuple[str, tuple[tuple[str, str], ...]], ...] = ()

    @property
    def cell(self) -> Cell:
        """The cell this world is of."""
        return self.cache.cell


Refusals = tuple[tuple[str, tuple[tuple[str, str], ...]], ...]


#: Bounds of the cell cache's tables (world.run.CellCache): placements per manipulation sequence;
#: step results per world key. Phase 2 re-runs an instance from the start after each
#: remedy it tries, and instances share prefixes; a world is fully determined by its key,
#: so a step's result can be reused (its uncertainty variables stay in the registry they
#: were made in).
MEMO_LIMIT = 4096


def hashable(d: Any) -> Any:
    """Term data (lists, dicts) as a hashable value."""
    if isinstance(d, list):
        return tuple(hashable(x) for x in d)
    if isinstance(d, dict):
        return tuple(sorted((str(k), hashable(v)) for k, v in d.items()))
    return d


def step_key(s: Step) -> tuple:
    return (s["id"], s["name"], hashable(list(s["args"])))


def grasp_of(cell: Cell, obj: str, label: str) -> Grasp:
    try:
        return cell.objects[obj].grasps[label]
    except KeyError:
        raise SparValueError(f"{label!r} is not a grasp of {obj!r}") from None


def stock_of(cell: Cell) -> dict[str, list]:
    """Objects with several initial positions -> those positions (in the file's order)."""
    by_obj: dict[str, list] = {}
    for p in cell.positions.values():
        by_obj.setdefault(p.obj, []).append(p)
    return {o: ps for o, ps in by_obj.items() if len(ps) > 1}


def lies_at(cell: Cell, obj: str, label: str, T: np.ndarray) -> bool:
    """A part of ``obj`` with pose ``T`` lies at position ``label``: at that initial
    position (an absolute label), or in that stable pose (a pose label)."""
    if label in cell.positions:
        return bool(np.allclose(T, cell.positions[label].T, atol=1e-9))
    if label in cell.objects[obj].poses:
        return same_stable_pose(T[:3, :3], cell.objects[obj].poses[label].R)
    return False


def model_of(key: str) -> str:
    """The object (model) name of a world key (``obj`` or ``obj@position``)."""
    return key.split("@", 1)[0]
