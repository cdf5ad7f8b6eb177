"""Concrete put-down placements: where on the table an object in a stable pose can go.

The paper leaves a put-down position as a stable pose and assumes "some suitable
choice of X, Y, Z" reaches it (Sec. 5.2.4). Plan instances need real coordinates,
and the arm must reach the object there for the put-down and for every later action
on it (a pickup, a mate). This module searches a grid of placements (x, y, yaw) over
the free table regions, batching every inverse-kinematics query.

Units: lengths in the cell unit, angles in radians; world frame, table top z = 0.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .geometry import rotz
from .model import Cell
from .reach import above_table

#: Grid spacing of candidate placements (cell units) and number of yaw steps.
GRID_STEP = 2.0
YAW_STEPS = 12
#: Extra distance kept between objects' bounding circles (cell units).
CLEARANCE = 1.0


@dataclass(frozen=True)
class Placement:
    """A placement: object frame at (x, y, height of the pose), turned ``yaw`` about world z."""

    obj: str
    pose: str
    x: float
    y: float
    z: float
    yaw: float
    T: np.ndarray

    def as_dict(self) -> dict:
        """JSON-ready form (yaw in degrees)."""
        return {"object": self.obj, "pose": self.pose, "x": round(self.x, 6), "y": round(self.y, 6),
                "z": round(self.z, 6), "yaw_deg": round(float(np.degrees(self.yaw)), 6)}


def default_regions(cell: Cell) -> list[dict]:
    """The free table regions: the problem's ``placement_regions`` or, without any, the
    rectangle spanned by the initial positions grown by 12 units each way."""
    if cell.placement_regions:
        return cell.placement_regions
    xy = np.array([p.T[:2, 3] for p in cell.positions.values()])
    lo, hi = xy.min(axis=0) - 12.0, xy.max(axis=0) + 12.0
    return [{"x": (float(lo[0]), float(hi[0])), "y": (float(lo[1]), float(hi[1]))}]


def candidates(cell: Cell, obj: str, pose: str, occupied: list[tuple[np.ndarray, float]],
               step: float = GRID_STEP, yaw_steps: int = YAW_STEPS) -> list[Placement]:
    """Grid placements of ``obj`` in stable pose ``pose`` inside the free regions, clear of
    ``occupied`` (list of (xy centre, radius) of other objects on the table)."""
    model = cell.objects[obj]
    sp = model.poses[pose]
    r = model.bounding_radius()
    out: list[Placement] = []
    for reg in default_regions(cell):
        xs = np.arange(reg["x"][0], reg["x"][1] + 1e-9, step)
        ys = np.arange(reg["y"][0], reg["y"][1] + 1e-9, step)
        for x in xs:
            for y in ys:
                if any(np.hypot(x - c[0], y - c[1]) < r + rc + CLEARANCE for c, rc in occupied):
                    continue
                for k in range(yaw_steps):
                    yaw = 2 * np.pi * k / yaw_steps
                    T = np.eye(4)
                    T[:3, :3] = rotz(yaw)[:3, :3] @ sp.R
                    T[:3, 3] = (x, y, sp.height)
                    out.append(Placement(obj, pose, float(x), float(y), sp.height, yaw, T))
    return out


def feasible(cell: Cell, placements: list[Placement], requirements: list[np.ndarray]) -> np.ndarray:
    """(n,) bool: placements at which every requirement is reachable.

    A requirement is a 4x4 X: the tool must reach T_O @ X (X = T_g for a pickup or
    put-down with grasp g; X = T_a @ T_g' for mating another object onto this one).
    One batched IK call for all placements x requirements.
    """
    if not placements:
        return np.zeros(0, dtype=bool)
    if not requirements:
        return np.ones(len(placements), dtype=bool)
    TO = np.stack([p.T for p in placements])                   # (n,4,4)
    X = np.stack(requirements)                                  # (m,4,4)
    T = np.einsum("nij,mjk->nmik", TO, X).reshape(-1, 4, 4)     # (n*m,4,4)
    ok = cell.robot.reachable_mask(T) & above_table(cell, T)
    return ok.reshape(len(placements), len(requirements)).all(axis=1)


def choose(cell: Cell, obj: str, pose: str, requirements: list[np.ndarray],
           occupied: list[tuple[np.ndarray, float]], near: np.ndarray | None = None) -> Placement | None:
    """The feasible placement nearest ``near`` (xy; default the regions' centre), or None."""
    cands = candidates(cell, obj, pose, occupied)
    ok = feasible(cell, cands, requirements)
    good = [c for c, f in zip(cands, ok) if f]
    if not good:
        return None
    if near is None:
        regs = default_regions(cell)
        near = np.mean([[(r["x"][0] + r["x"][1]) / 2, (r["y"][0] + r["y"][1]) / 2] for r in regs], axis=0)
    return min(good, key=lambda p: (round(float(np.hypot(p.x - near[0], p.y - near[1])), 9), p.yaw))


#: The coarser grid phase 1 uses to decide whether a stable pose is reachable at all.
PHASE1_STEP = 6.0
PHASE1_YAWS = 6


def reachable_somewhere(cell: Cell, obj: str, pose: str, requirements: list[np.ndarray]) -> np.ndarray:
    """(m,) bool: for each tool transform X (object frame), some placement of ``obj`` in
    ``pose`` on the phase-1 grid of the free regions where the arm reaches T_O @ X.

    A necessary condition for a put-down or mate at a stable-pose position: it ignores
    the other objects (phase 1 does not know where they will be); phase 2 chooses a real
    placement clear of them that serves every later action at once.
    """
    if not requirements:
        return np.zeros(0, dtype=bool)
    X = np.stack(requirements)
    out = np.zeros(len(X), dtype=bool)
    todo = []
    for i, x in enumerate(X):
        key = (cell.memo_key(), obj, pose, np.round(x, 12).tobytes())
        if key in _SOMEWHERE:
            out[i] = _SOMEWHERE[key]
        else:
            todo.append((i, key))
    if todo:
        ok = _any_placement(cell, _grid(cell, obj, pose), X[[i for i, _ in todo]])
        if len(_SOMEWHERE) > 100_000:
            _SOMEWHERE.clear()
        for (i, key), v in zip(todo, ok):
            _SOMEWHERE[key] = out[i] = bool(v)
    return out


def _any_placement(cell: Cell, cands: np.ndarray, X: np.ndarray, chunk: int = 48) -> np.ndarray:
    """(m,) bool: for each X, some object pose of ``cands`` (n,4,4) with T_O @ X reachable.
    Placements are tried a chunk at a time and a requirement is dropped once met, so the
    usual case (met in the first chunk) costs a fraction of the whole grid."""
    ok = np.zeros(len(X), dtype=bool)
    for start in range(0, len(cands), chunk):
        open_ = np.flatnonzero(~ok)
        if not len(open_):
            break
        C = cands[start:start + chunk]
        T = np.einsum("nij,mjk->nmik", C, X[open_]).reshape(-1, 4, 4)
        hit = (cell.robot.reachable_mask(T) & above_table(cell, T)).reshape(len(C), len(open_)).any(axis=0)
        ok[open_[hit]] = True
    return ok


#: Memo of reachable_somewhere per (cell, object, pose, requirement): phase 1 asks the
#: same arcs again in every round of its deepening search.
_SOMEWHERE: dict[tuple, bool] = {}
_GRIDS: dict[tuple, np.ndarray] = {}


def _grid(cell: Cell, obj: str, pose: str) -> np.ndarray:
    """(n,4,4) object poses of the phase-1 grid (memoised per cell, object and pose)."""
    key = (cell.memo_key(), obj, pose)
    if key not in _GRIDS:
        if len(_GRIDS) > 1024:
            _GRIDS.clear()
        cands = candidates(cell, obj, pose, [], PHASE1_STEP, PHASE1_YAWS)
        _GRIDS[key] = np.stack([p.T for p in cands]) if cands else np.zeros((0, 4, 4))
    return _GRIDS[key]
