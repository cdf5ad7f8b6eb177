"""Concrete put-down placements: where on the table an object in a stable pose can go.

The paper leaves a put-down position as a stable pose and assumes "some suitable
choice of X, Y, Z" reaches it (Sec. 5.2.4). Plan instances need real coordinates,
and the arm must reach the object there for the put-down and for every later action
on it (a pickup, a mate). This module searches a grid of placements (x, y, yaw) over
the free table regions, batching every inverse-kinematics query. A placement's whole
footprint (its shape projected on the table, a convex polygon) lies in one free region
and keeps the clearance from every other part's footprint.

Units: lengths in the cell unit, angles in radians; world frame, table top z = 0. The
constants below are in mm (units.INTERNAL_UNIT) and converted to the cell's unit
where used (units.from_mm), so a cell plans alike in in, mm or m.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Sequence

import numpy as np

from .geometry import convex_hull_2d, rotz
from .model import Cell, ObjectModel
from .units import from_mm, mm_per
from .workspace import Requirement, reaches, requirement_clear, wrist_height

#: Grid spacing of candidate placements: 50.8 mm (2 in); number of yaw steps.
GRID_STEP_MM = 50.8
YAW_STEPS = 12
#: Gap kept between two parts' footprints on the table: 25.4 mm (1 in).
CLEARANCE_MM = 25.4
#: Without ``placement_regions``: the initial positions' rectangle grown by 304.8 mm
#: (12 in) each way is the free table.
REGION_MARGIN_MM = 304.8
#: Length rounding: a footprint this far outside a region is inside it (float
#: rounding, not geometry), and distances to ``near`` equal to this are ties: 1e-6 mm.
ROUND_MM = 1e-6
#: Sides of the polygon circumscribed about a cylinder's rim in a footprint (the
#: polygon contains the rim, so a footprint never understates the shape).
ARC_SIDES = 16

#: An entry of ``occupied``: (xy centre, bounding radius) of a part on the table, or
#: (xy centre, bounding radius, footprint) with its footprint polygon ((k, 2) world xy,
#: counter-clockwise; :func:`occupant`). Without a footprint the part counts as the disc
#: of its bounding radius (a superset of its footprint: conservative).
Occupant = tuple


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
    """The free table regions (cell unit): the problem's ``placement_regions`` or, without
    any, the rectangle spanned by the initial positions grown by REGION_MARGIN_MM each way."""
    if cell.placement_regions:
        return cell.placement_regions
    xy = np.array([p.T[:2, 3] for p in cell.positions.values()])
    margin = from_mm(cell.unit, REGION_MARGIN_MM)
    lo, hi = xy.min(axis=0) - margin, xy.max(axis=0) + margin
    return [{"x": (float(lo[0]), float(hi[0])), "y": (float(lo[1]), float(hi[1]))}]


def _disc(c: np.ndarray, r: float) -> np.ndarray:
    """(ARC_SIDES, 2) the regular polygon circumscribed about the disc (c, r), CCW."""
    a = 2 * np.pi * np.arange(ARC_SIDES) / ARC_SIDES
    R = r / math.cos(math.pi / ARC_SIDES)
    return np.asarray(c, float)[:2] + R * np.stack([np.cos(a), np.sin(a)], axis=1)


def footprint(model: ObjectModel, R: np.ndarray) -> np.ndarray:
    """(k, 2) the footprint of ``model`` turned by rotation R (3x3, object to world):
    the convex hull of its shape projected on the table, in world xy about the object
    origin (cell unit), counter-clockwise. Boxes by their 8 corners; a z-cylinder by the
    ARC_SIDES-gons circumscribed about its two rims (a superset of the cylinder's
    shadow); a mesh part's hull by its vertices. A model without a shape has the point footprint [[0, 0]]."""
    pts = [np.zeros((1, 3))]
    for s in model.shape:
        if s.kind == "hull":
            pts.append(np.asarray(s.points, float))
        elif s.kind == "cylinder":
            rim = _disc(np.zeros(2), s.radius)
            pts += [np.column_stack([rim, np.full(len(rim), z)]) for z in (s.lo[2], s.hi[2])]
        else:
            pts.append(np.array([[x, y, z] for x in (s.lo[0], s.hi[0]) for y in (s.lo[1], s.hi[1])
                                 for z in (s.lo[2], s.hi[2])], float))
    P = np.concatenate(pts[1:] if len(pts) > 1 else pts)
    return convex_hull_2d((P @ np.asarray(R, float).T)[:, :2])


def occupant(cell: Cell, obj: str, T: np.ndarray) -> Occupant:
    """The ``occupied`` entry of a part of ``obj`` at world pose T (4x4): its xy centre,
    bounding radius and footprint polygon in world xy (cell unit)."""
    model = cell.objects[obj]
    return (np.asarray(T, float)[:2, 3].copy(), model.bounding_radius(),
            footprint(model, T[:3, :3]) + T[:2, 3])


def _occupant_polygon(entry: Sequence) -> np.ndarray:
    """The footprint polygon (k, 2) of an ``occupied`` entry (the bounding disc's
    circumscribed polygon for a (centre, radius) entry)."""
    if len(entry) >= 3 and entry[2] is not None:
        return np.asarray(entry[2], float)
    return _disc(np.asarray(entry[0], float), float(entry[1]))


def _minkowski(P: np.ndarray, Q: np.ndarray) -> np.ndarray:
    """(k, 2) the Minkowski sum of convex CCW polygons P and Q (edges merged by angle)."""
    def start(V: np.ndarray) -> np.ndarray:
        i = int(np.lexsort((V[:, 0], V[:, 1]))[0])  # lowest, then leftmost vertex first
        return np.roll(V, -i, axis=0)

    P, Q = start(P), start(Q)
    E = np.concatenate([np.roll(P, -1, axis=0) - P, np.roll(Q, -1, axis=0) - Q])
    ang = np.mod(np.arctan2(E[:, 1], E[:, 0]), 2 * np.pi)
    steps = E[np.argsort(ang, kind="stable")]
    return P[0] + Q[0] + np.concatenate([np.zeros((1, 2)), np.cumsum(steps, axis=0)[:-1]])


def _clear_of(M: np.ndarray, t: np.ndarray, gap: float) -> np.ndarray:
    """(n,) bool: points t (n, 2) lie outside the convex CCW polygon M, at least ``gap``
    from it."""
    A = M
    B = np.roll(M, -1, axis=0)
    E = B - A                                                   # (m, 2)
    D = t[:, None, :] - A[None, :, :]                           # (n, m, 2)
    cross = E[None, :, 0] * D[..., 1] - E[None, :, 1] * D[..., 0]
    inside = np.all(cross >= 0, axis=1)
    L2 = np.einsum("ij,ij->i", E, E)
    u = np.clip(np.einsum("nmj,mj->nm", D, E) / np.where(L2 > 0, L2, 1.0), 0.0, 1.0)
    d = np.hypot(D[..., 0] - u * E[None, :, 0], D[..., 1] - u * E[None, :, 1]).min(axis=1)
    return ~inside & (d >= gap)


def _grid_arrays(cell: Cell, obj: str, pose: str, occupied: list[Occupant],
                 step: float, yaw_steps: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The grid placements of :func:`candidates` as arrays, in the same order (regions, x,
    y, yaw): ``(xy (n, 2), yaw (n,), T (n, 4, 4))``, lengths in the cell unit.

    Kept: the placements whose footprint (:func:`footprint`, turned by the yaw) lies in
    the region of the grid point, and is at least the clearance (CLEARANCE_MM) from the
    footprint of every ``occupied`` entry (exactly, for the polygons: the placement's
    origin outside the Minkowski sum of the other footprint and the mirrored own one, by
    the clearance). Each yaw's rotation is computed once, by the same expression
    (``rotz(yaw)[:3, :3] @ R``) a placement at a time would use."""
    model = cell.objects[obj]
    sp = model.poses[pose]
    tol = from_mm(cell.unit, ROUND_MM)
    gap = from_mm(cell.unit, CLEARANCE_MM) - tol
    yaws = np.array([2 * np.pi * k / yaw_steps for k in range(yaw_steps)])
    rots = np.stack([rotz(yaw)[:3, :3] @ sp.R for yaw in yaws])  # (yaw_steps, 3, 3)
    feet = [footprint(model, R) for R in rots]
    lo = np.array([f.min(axis=0) for f in feet])                # (yaw_steps, 2)
    hi = np.array([f.max(axis=0) for f in feet])
    others = [_occupant_polygon(e) for e in occupied]
    mirrored = [[_minkowski(W, -f) for W in others] for f in feet]
    xy_parts, yaw_parts = [], []
    for reg in default_regions(cell):
        (x0, x1), (y0, y1) = reg["x"], reg["y"]
        xs = x0 + step * np.arange(math.floor((x1 - x0) / step + 1e-9) + 1)
        ys = y0 + step * np.arange(math.floor((y1 - y0) / step + 1e-9) + 1)
        X, Y = np.meshgrid(xs, ys, indexing="ij")
        P = np.stack([X.ravel(), Y.ravel()], axis=1)             # (n, 2)
        ok = ((P[:, None, 0] + lo[None, :, 0] >= x0 - tol) & (P[:, None, 0] + hi[None, :, 0] <= x1 + tol)
              & (P[:, None, 1] + lo[None, :, 1] >= y0 - tol) & (P[:, None, 1] + hi[None, :, 1] <= y1 + tol))
        for k in range(yaw_steps):
            for M in mirrored[k]:
                idx = np.flatnonzero(ok[:, k])
                ok[idx, k] = _clear_of(M, P[idx], gap)
        i, k = np.nonzero(ok)                                    # row-major: grid order, then yaw
        xy_parts.append(P[i])
        yaw_parts.append(k)
    xy = np.concatenate(xy_parts) if xy_parts else np.zeros((0, 2))
    k = np.concatenate(yaw_parts) if yaw_parts else np.zeros(0, dtype=int)
    T = np.zeros((len(xy), 4, 4))
    T[:, :3, :3] = rots[k]
    T[:, 0, 3] = xy[:, 0]
    T[:, 1, 3] = xy[:, 1]
    T[:, 2, 3] = sp.height
    T[:, 3, 3] = 1.0
    return xy, yaws[k], T


def candidates(cell: Cell, obj: str, pose: str, occupied: list[Occupant],
               step: float | None = None, yaw_steps: int = YAW_STEPS) -> list[Placement]:
    """Grid placements of ``obj`` in stable pose ``pose`` whose footprint lies in a free
    region, clear of ``occupied`` (:data:`Occupant` entries: the other parts on the
    table) by the clearance. ``step``: grid spacing in the cell unit (default GRID_STEP_MM)."""
    height = cell.objects[obj].poses[pose].height
    step = from_mm(cell.unit, GRID_STEP_MM) if step is None else step
    xy, yaw, T = _grid_arrays(cell, obj, pose, occupied, step, yaw_steps)
    return [Placement(obj, pose, x, y, height, w, t) for (x, y), w, t in zip(xy.tolist(), yaw.tolist(), T)]


def _req_X(r: Requirement | np.ndarray) -> np.ndarray:
    return np.asarray(r.X if isinstance(r, Requirement) else r, float)


def _reach_all(cell: Cell, TO: np.ndarray, X: Sequence[Requirement | np.ndarray], obj: str | None = None) -> np.ndarray:
    """(n, m) bool: the arm reaches T_O @ X (wrist above the table) for object poses TO
    (n, 4, 4) and requirements X (m: 4x4 tool transforms, or workspace.Requirement); with the
    object ``obj`` named, by a solution clear of the table, the obstacles and the object itself
    (workspace.requirement_clear, one batched call per requirement), else by IK alone."""
    if obj is None:
        Xs = np.stack([_req_X(x) for x in X])
        T = np.einsum("nij,mjk->nmik", TO, Xs).reshape(-1, 4, 4)     # (n*m,4,4)
        return reaches(cell.robot, T).reshape(len(TO), len(Xs))
    out = np.zeros((len(TO), len(X)), dtype=bool)
    for k, x in enumerate(X):
        out[:, k] = requirement_clear(cell, obj, TO, x).ok
    return out


def feasible(cell: Cell, placements: list[Placement], requirements: list[np.ndarray | Requirement]) -> np.ndarray:
    """(n,) bool: placements at which every requirement is reachable, clear of the world.

    A requirement is a 4x4 X: the tool must reach T_O @ X (X = T_g for a pickup or
    put-down with grasp g; X = T_a @ T_g' for mating another object onto this one), or a
    workspace.Requirement saying what is in the hand. One batched IK and clearance call per
    requirement for all placements.
    """
    if not placements:
        return np.zeros(0, dtype=bool)
    if not requirements:
        return np.ones(len(placements), dtype=bool)
    objs = {p.obj for p in placements}
    obj = objs.pop() if len(objs) == 1 else None
    return _reach_all(cell, np.stack([p.T for p in placements]), requirements, obj).all(axis=1)


#: Placements :func:`choose` checks at a time, nearest first.
CHOOSE_CHUNK = 96


def choose(cell: Cell, obj: str, pose: str, requirements: list[np.ndarray],
           occupied: list[Occupant], near: np.ndarray | None = None) -> Placement | None:
    """The feasible placement nearest ``near`` (xy, cell unit; default the regions'
    centre), or None. Candidates as :func:`candidates`: the footprint in a free region,
    clear of the ``occupied`` parts' footprints by the clearance.

    Nearest: least distance rounded to ROUND_MM, then least yaw, then first in grid order.
    The candidates are checked in that order a chunk at a time, so the search stops
    at the first chunk holding a feasible one instead of solving IK for the whole grid.
    """
    xy, yaw, T = _grid_arrays(cell, obj, pose, occupied, from_mm(cell.unit, GRID_STEP_MM), YAW_STEPS)
    if not len(T):
        return None
    if near is None:
        regs = default_regions(cell)
        near = np.mean([[(r["x"][0] + r["x"][1]) / 2, (r["y"][0] + r["y"][1]) / 2] for r in regs], axis=0)
    # distances in mm, so ties are broken alike whatever the cell's unit
    dist = (np.hypot(xy[:, 0] - near[0], xy[:, 1] - near[1]) * mm_per(cell.unit)).tolist()
    yaws = yaw.tolist()
    digits = -round(math.log10(ROUND_MM))
    order = sorted(range(len(T)), key=lambda i: (round(dist[i], digits), yaws[i]))  # stable: grid order breaks ties
    for start in range(0, len(order), CHOOSE_CHUNK):
        idx = order[start:start + CHOOSE_CHUNK]
        ok = np.ones(len(idx), dtype=bool)
        for x in requirements or ():  # each requirement by IK and clearance, on the survivors only
            live = np.flatnonzero(ok)
            if not len(live):
                break
            ok[live] = _reach_all(cell, T[[idx[i] for i in live]], [x], obj)[:, 0]
        hits = np.flatnonzero(ok)
        if len(hits):
            i = idx[hits[0]]
            height = cell.objects[obj].poses[pose].height
            return Placement(obj, pose, float(xy[i, 0]), float(xy[i, 1]), height, yaws[i], T[i])
    return None


#: The coarser grid phase 1 uses to decide whether a stable pose is reachable at all:
#: 152.4 mm (6 in) apart, 6 yaws.
PHASE1_STEP_MM = 152.4
PHASE1_YAWS = 6


def reachable_somewhere(cell: Cell, obj: str, pose: str,
                        requirements: Sequence[np.ndarray | Requirement]) -> np.ndarray:
    """(m,) bool: for each requirement (a tool transform X in the object frame, or a
    workspace.Requirement), some placement of ``obj`` in ``pose`` on the phase-1 grid of the
    free regions where the arm reaches T_O @ X by a solution clear of the table, the obstacles
    and the object (and the part in the hand).

    A necessary condition for a put-down or mate at a stable-pose position: it ignores
    the other objects (phase 1 does not know where they will be); phase 2 chooses a real
    placement clear of them that serves every later action at once.
    """
    if not len(requirements):
        return np.zeros(0, dtype=bool)
    reqs = [r if isinstance(r, Requirement) else Requirement(np.asarray(r, float)) for r in requirements]
    out = np.zeros(len(reqs), dtype=bool)
    memo = cell.memo.table("placement.somewhere", SOMEWHERE_LIMIT)
    gkey = _grid_key(cell, obj, pose)
    todo: dict[tuple, list[int]] = {}  # equal requirements are solved once
    for i, r in enumerate(reqs):
        held = None if r.held is None else (r.held[0], np.round(r.held[1], 12).tobytes())
        key = (gkey, obj, np.round(r.X, 12).tobytes(), held, None if r.width is None else round(r.width, 12))
        if key in memo:
            out[i] = memo[key]
        else:
            todo.setdefault(key, []).append(i)
    if todo:
        cands = _grid(cell, obj, pose)
        for key, ix in todo.items():
            memo[key] = out[ix] = _some_placement(cell, obj, cands, reqs[ix[0]])
    return out


def _some_placement(cell: Cell, obj: str, cands: np.ndarray, req: Requirement, chunk: int = 48) -> bool:
    """Some object pose of ``cands`` (n,4,4) at which the arm reaches T_O @ req.X clear of the
    world, a chunk at a time (the usual case is met in the first chunk). The grid's placements
    differ only by a turn about world z and a shift in x, y, so a wrist below the table at the
    first one (by more than rounding) is below it at every one: no IK is solved then."""
    if not len(cands):
        return False
    if np.all(cands[:, 2, :] == cands[0, 2, :]):
        if wrist_height(cell.robot, (cands[0] @ req.X)[None])[0] < -from_mm(cell.unit, ROUND_MM):
            return False
    for start in range(0, len(cands), chunk):
        if requirement_clear(cell, obj, cands[start:start + chunk], req).ok.any():
            return True
    return False


def _any_placement(cell: Cell, cands: np.ndarray, X: np.ndarray, chunk: int = 48) -> np.ndarray:
    """(m,) bool: for each X, some object pose of ``cands`` (n,4,4) with T_O @ X reachable.
    Placements are tried a chunk at a time and a requirement is dropped once met, so the
    usual case (met in the first chunk) costs a fraction of the whole grid.

    The grid's placements differ only by a turn about world z and a shift in x, y, so
    the height of the wrist for a given X is the same at all of them: an X whose wrist
    is below the table top at the first placement (by more than rounding) is below it at
    every one and fails without solving IK over the whole grid (below by more than
    ROUND_MM: a prune only, as :func:`workspace.reaches` refuses every wrist below z = 0)."""
    ok = np.zeros(len(X), dtype=bool)
    if not len(cands):
        return ok
    if np.all(cands[:, 2, :] == cands[0, 2, :]):  # one z row: turns about z, shifts in x, y
        T0 = np.einsum("ij,mjk->mik", cands[0], X)
        below = wrist_height(cell.robot, T0) < -from_mm(cell.unit, ROUND_MM)
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
    pose's rotation and height and the object's footprint in it, not the object's name."""
    model = cell.objects[obj]
    sp = model.poses[pose]
    return (np.asarray(sp.R, float).tobytes(), float(sp.height), footprint(model, sp.R).tobytes())


def _grid(cell: Cell, obj: str, pose: str) -> np.ndarray:
    """(n,4,4) object poses of the phase-1 grid (memoised in the cell per stable-pose geometry)."""
    step = from_mm(cell.unit, PHASE1_STEP_MM)
    return cell.memo.table("placement.grids", GRID_LIMIT).get_or_compute(
        _grid_key(cell, obj, pose), lambda: _grid_arrays(cell, obj, pose, [], step, PHASE1_YAWS)[2])
