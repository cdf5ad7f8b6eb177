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
from .workspace import reaches, wrist_height

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


def _grid_arrays(cell: Cell, obj: str, pose: str, occupied: list[tuple[np.ndarray, float]],
                 step: float, yaw_steps: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The grid placements of :func:`candidates` as arrays, in the same order (regions, x,
    y, yaw): ``(xy (n, 2), yaw (n,), T (n, 4, 4))``. Each yaw's rotation is computed once,
    by the same expression (``rotz(yaw)[:3, :3] @ R``) a placement at a time would use."""
    sp = cell.objects[obj].poses[pose]
    r = cell.objects[obj].bounding_radius() if occupied else 0.0
    yaws = [2 * np.pi * k / yaw_steps for k in range(yaw_steps)]
    rots = np.stack([rotz(yaw)[:3, :3] @ sp.R for yaw in yaws])  # (yaw_steps, 3, 3)
    xy_parts = []
    for reg in default_regions(cell):
        xs = np.arange(reg["x"][0], reg["x"][1] + 1e-9, step)
        ys = np.arange(reg["y"][0], reg["y"][1] + 1e-9, step)
        X, Y = np.meshgrid(xs, ys, indexing="ij")
        X, Y = X.ravel(), Y.ravel()
        free = np.ones(len(X), dtype=bool)
        for c, rc in occupied:
            free &= ~(np.hypot(X - c[0], Y - c[1]) < r + rc + CLEARANCE)
        xy_parts.append(np.stack([X[free], Y[free]], axis=1))
    xy = np.concatenate(xy_parts) if xy_parts else np.zeros((0, 2))
    n = len(xy) * yaw_steps
    T = np.zeros((len(xy), yaw_steps, 4, 4))
    T[:, :, :3, :3] = rots
    T[:, :, 0, 3] = xy[:, 0, None]
    T[:, :, 1, 3] = xy[:, 1, None]
    T[:, :, 2, 3] = sp.height
    T[:, :, 3, 3] = 1.0
    return np.repeat(xy, yaw_steps, axis=0), np.tile(np.array(yaws), len(xy)), T.reshape(n, 4, 4)


def candidates(cell: Cell, obj: str, pose: str, occupied: list[tuple[np.ndarray, float]],
               step: float = GRID_STEP, yaw_steps: int = YAW_STEPS) -> list[Placement]:
    """Grid placements of ``obj`` in stable pose ``pose`` inside the free regions, clear of
    ``occupied`` (list of (xy centre, radius) of other objects on the table)."""
    height = cell.objects[obj].poses[pose].height
    xy, yaw, T = _grid_arrays(cell, obj, pose, occupied, step, yaw_steps)
    return [Placement(obj, pose, x, y, height, w, t) for (x, y), w, t in zip(xy.tolist(), yaw.tolist(), T)]


def _reach_all(cell: Cell, TO: np.ndarray, X: np.ndarray) -> np.ndarray:
    """(n, m) bool: the arm reaches T_O @ X (wrist above the table) for object poses TO
    (n, 4, 4) and tool transforms X (m, 4, 4); one batched IK call."""
    T = np.einsum("nij,mjk->nmik", TO, X).reshape(-1, 4, 4)     # (n*m,4,4)
    return reaches(cell.robot, T).reshape(len(TO), len(X))


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
    return _reach_all(cell, np.stack([p.T for p in placements]), np.stack(requirements)).all(axis=1)


#: Placements :func:`choose` checks at a time, nearest first.
CHOOSE_CHUNK = 96


def choose(cell: Cell, obj: str, pose: str, requirements: list[np.ndarray],
           occupied: list[tuple[np.ndarray, float]], near: np.ndarray | None = None) -> Placement | None:
    """The feasible placement nearest ``near`` (xy; default the regions' centre), or None.

    Nearest: least distance rounded to 1e-9, then least yaw, then first in grid order.
    The candidates are checked in that order a chunk at a time, so the search stops
    at the first chunk holding a feasible one instead of solving IK for the whole grid.
    """
    xy, yaw, T = _grid_arrays(cell, obj, pose, occupied, GRID_STEP, YAW_STEPS)
    if not len(T):
        return None
    if near is None:
        regs = default_regions(cell)
        near = np.mean([[(r["x"][0] + r["x"][1]) / 2, (r["y"][0] + r["y"][1]) / 2] for r in regs], axis=0)
    dist = np.hypot(xy[:, 0] - near[0], xy[:, 1] - near[1]).tolist()
    yaws = yaw.tolist()
    order = sorted(range(len(T)), key=lambda i: (round(dist[i], 9), yaws[i]))  # stable: grid order breaks ties
    X = np.stack(requirements) if requirements else None
    for start in range(0, len(order), CHOOSE_CHUNK):
        idx = order[start:start + CHOOSE_CHUNK]
        ok = np.ones(len(idx), dtype=bool) if X is None else _reach_all(cell, T[idx], X).all(axis=1)
        hits = np.flatnonzero(ok)
        if len(hits):
            i = idx[hits[0]]
            height = cell.objects[obj].poses[pose].height
            return Placement(obj, pose, float(xy[i, 0]), float(xy[i, 1]), height, yaws[i], T[i])
    return None


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
    memo = cell.memo.table("placement.somewhere", SOMEWHERE_LIMIT)
    gkey = _grid_key(cell, obj, pose)
    todo: dict[tuple, list[int]] = {}  # equal requirements are solved once
    for i, x in enumerate(np.round(X, 12)):
        key = (gkey, x.tobytes())
        if key in memo:
            out[i] = memo[key]
        else:
            todo.setdefault(key, []).append(i)
    if todo:
        ok = _any_placement(cell, _grid(cell, obj, pose), X[[ix[0] for ix in todo.values()]])
        for (key, ix), v in zip(todo.items(), ok):
            memo[key] = out[ix] = bool(v)
    return out


def _any_placement(cell: Cell, cands: np.ndarray, X: np.ndarray, chunk: int = 48) -> np.ndarray:
    """(m,) bool: for each X, some object pose of ``cands`` (n,4,4) with T_O @ X reachable.
    Placements are tried a chunk at a time and a requirement is dropped once met, so the
    usual case (met in the first chunk) costs a fraction of the whole grid.

    The grid's placements differ only by a turn about world z and a shift in x, y, so
    the height of the wrist for a given X is the same at all of them: an X whose wrist
    is below the table top at the first placement (by more than rounding) is below it at
    every one and fails without solving IK over the whole grid."""
    ok = np.zeros(len(X), dtype=bool)
    if not len(cands):
        return ok
    if np.all(cands[:, 2, :] == cands[0, 2, :]):  # one z row: turns about z, shifts in x, y
        T0 = np.einsum("ij,mjk->mik", cands[0], X)
        below = wrist_height(cell.robot, T0) < -1e-9
    else:
        below = np.zeros(len(X), dtype=bool)
    for start in range(0, len(cands), chunk):
        open_ = np.flatnonzero(~ok & ~below)
        if not len(open_):
            break
        C = cands[start:start + chunk]
        T = np.einsum("nij,mjk->nmik", C, X[open_]).reshape(-1, 4, 4)
        hit = reaches(cell.robot, T).reshape(len(C), len(open_)).any(axis=0)
        ok[open_[hit]] = True
    return ok


#: Bounds of the cell's memo tables (cell.memo): reachable_somewhere's answers per
#: (grid, requirement), and the phase-1 grids per stable-pose geometry. Phase 1 asks the
#: same arcs again in every round of its deepening search, and objects that are copies of
#: one model (the same stable pose, so the same grid) ask the same questions.
SOMEWHERE_LIMIT = 100_000
GRID_LIMIT = 1024


def _grid_key(cell: Cell, obj: str, pose: str) -> tuple:
    """What the phase-1 grid of ``obj`` in ``pose`` depends on within a cell: the stable
    pose's rotation and height, not the object's name."""
    sp = cell.objects[obj].poses[pose]
    return (np.asarray(sp.R, float).tobytes(), float(sp.height))


def _grid(cell: Cell, obj: str, pose: str) -> np.ndarray:
    """(n,4,4) object poses of the phase-1 grid (memoised in the cell per stable-pose geometry)."""
    return cell.memo.table("placement.grids", GRID_LIMIT).get_or_compute(
        _grid_key(cell, obj, pose), lambda: _grid_arrays(cell, obj, pose, [], PHASE1_STEP, PHASE1_YAWS)[2])
