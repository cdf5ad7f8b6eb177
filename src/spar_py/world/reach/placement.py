"""Concrete put-down placements: where on the table, or on a support's top, an object in a
stable pose can go.

The paper leaves a put-down position as a stable pose and assumes "some suitable
choice of X, Y, Z" reaches it (Sec. 5.2.4). Plan instances need real coordinates,
and the arm must reach the object there for the put-down and for every later action
on it (a pickup, a mate). This module searches a grid of placements (x, y, yaw) over
the free table regions, batching every inverse-kinematics query. A placement's whole
footprint (its shape projected on the table, a convex polygon) lies in one free region
and keeps the clearance from every other part's footprint. The regions are the free table
regions (clear of the supports' footprints by the clearance) and the top of each obstacle
marked ``support: true`` (world.reach.supports): a placement there lies wholly on the top, at its
height, so the part rests on it stably (its contact face within the top).

Units: lengths in the cell unit, angles in radians; world frame, table top z = 0. The
constants below are in mm (units.INTERNAL_UNIT) and converted to the cell's unit
where used (units.from_mm), so a cell plans alike in in, mm or m.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Sequence

import numpy as np

from spar_py.core.geometry import convex_hull_2d, rotz
from spar_py.core.model import Cell, ObjectModel
from spar_py.core.units import from_mm, mm_per
from spar_py.world.reach.workspace import (Requirement, ik_rows, reachable_ignoring_collisions, requirement_clear,
                                     requirement_clear_each, requirement_state, shape_key, tool_refusal, wrist_height)

if TYPE_CHECKING:
    from spar_py.world.collision import SceneState
    from spar_py.world.collision import CellCache

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
    """A placement: object frame at (x, y, z: the pose's height over the surface it rests on),
    turned ``yaw`` about world z; ``on`` that surface ("table", or a support's name)."""

    obj: str
    pose: str
    x: float
    y: float
    z: float
    yaw: float
    T: np.ndarray
    on: str = "table"

    def as_dict(self) -> dict:
        """JSON-ready form (yaw in degrees; ``on`` only for a support's top)."""
        out = {"object": self.obj, "pose": self.pose, "x": round(self.x, 6), "y": round(self.y, 6),
               "z": round(self.z, 6), "yaw_deg": round(float(np.degrees(self.yaw)), 6)}
        return out if self.on == "table" else {**out, "on": self.on}


def default_regions(cell: Cell) -> list[dict]:
    """The free table regions (cell unit): the problem's ``placement_regions`` or, without
    any, the rectangle spanned by the initial positions grown by REGION_MARGIN_MM each way;
    either cut to the table top's extent where the problem gives one (``table:``), so no
    put-down hangs over its edge (a region wholly off the table is dropped)."""
    if cell.placement_regions:
        regions = cell.placement_regions
    else:
        xy = np.array([p.T[:2, 3] for p in cell.positions.values()])
        margin = from_mm(cell.unit, REGION_MARGIN_MM)
        lo, hi = xy.min(axis=0) - margin, xy.max(axis=0) + margin
        regions = [{"x": (float(lo[0]), float(hi[0])), "y": (float(lo[1]), float(hi[1]))}]
    return regions if cell.table is None else _on_table(regions, cell.table)


@dataclass(frozen=True)
class Level:
    """A region of the grid: its rectangle (cell unit), the surface's height ``z`` and name ``on``,
    the polygon a footprint must lie in (None: the rectangle is all) and the polygons it must
    keep the clearance from besides the parts' (the supports standing on the table). ``parts``:
    None, the clearance is kept from every ``occupied`` part; else from these footprints instead
    (a part's top: every occupant but the part it is the top of)."""

    x: tuple[float, float]
    y: tuple[float, float]
    z: float
    on: str
    polygon: np.ndarray | None
    keep_off: tuple[np.ndarray, ...]
    parts: tuple[np.ndarray, ...] | None = None


def part_level(name: str, top: np.ndarray, z: float, others: Sequence[Occupant]) -> Level:
    """The grid region of a part's flat top: its polygon ``top`` ((k, 2) world xy, CCW) at height
    ``z`` (world.reach.supports.part_surface), named ``name``; a placement there keeps the clearance
    from the footprints of ``others`` (the occupants but the part under it)."""
    lo, hi = top.min(axis=0), top.max(axis=0)
    return Level((float(lo[0]), float(hi[0])), (float(lo[1]), float(hi[1])), float(z), name,
                 np.asarray(top, float), (), tuple(_occupant_polygon(e) for e in others))


def levels(cell: Cell) -> list[Level]:
    """The grid's regions: the free table regions (:func:`default_regions`), clear of every
    support's footprint, then each support's top (world.reach.supports) in the file's order."""
    from spar_py.world.reach.supports import obstacle_footprint, support_surfaces  # the supports' geometry

    tops = support_surfaces(cell)
    feet = tuple(obstacle_footprint(o) for o in cell.obstacles if getattr(o, "support", False))
    out = [Level(r["x"], r["y"], 0.0, "table", None, feet) for r in default_regions(cell)]
    for s in tops:
        lo, hi = s.polygon.min(axis=0), s.polygon.max(axis=0)
        out.append(Level((float(lo[0]), float(hi[0])), (float(lo[1]), float(hi[1])), s.z, s.name, s.polygon, ()))
    return out


#: Bound of the cell cache's table of the supports' levels (by the supports' geometry).
LEVELS_LIMIT = 16


def _levels(cache: CellCache) -> list[Level]:
    """:func:`levels` of the cache's cell: the table's alone as :func:`default_regions` gives them
    (a cell without supports), else kept in the cell's cache by the regions, the table and the
    supports' bodies (caches may share their memo)."""
    cell = cache.cell
    sups = [o for o in cell.obstacles if getattr(o, "support", False)]
    if not sups:
        return [Level(r["x"], r["y"], 0.0, "table", None, ()) for r in default_regions(cell)]
    key = (tuple((tuple(r["x"]), tuple(r["y"])) for r in cell.placement_regions), cell.table,
           tuple((o.name, tuple(np.ascontiguousarray(b.points, float).tobytes() for b in o.bodies)) for o in sups))
    return cache.table("placement.levels", LEVELS_LIMIT).get_or_compute(key, lambda: levels(cell))


def _within(poly: np.ndarray, pts: np.ndarray, tol: float) -> np.ndarray:
    """(...) bool: each point of pts (..., 2) inside the convex CCW polygon ``poly`` (k, 2), or
    within ``tol`` of it."""
    E = np.roll(poly, -1, axis=0) - poly                      # (k, 2)
    D = pts[..., None, :] - poly                               # (..., k, 2)
    cross = (E[:, 0] * D[..., 1] - E[:, 1] * D[..., 0]) / np.linalg.norm(E, axis=1)
    return cross.min(axis=-1) >= -tol


def _on_table(regions: list[dict], table: tuple[float, float, float, float]) -> list[dict]:
    """``regions`` cut to the table top (xlo, xhi, ylo, yhi); the empty ones dropped."""
    out = []
    for r in regions:
        x = (max(r["x"][0], table[0]), min(r["x"][1], table[1]))
        y = (max(r["y"][0], table[2]), min(r["y"][1], table[3]))
        if x[0] < x[1] and y[0] < y[1]:
            out.append({**r, "x": (float(x[0]), float(x[1])), "y": (float(y[0]), float(y[1]))})
    return out


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


#: Bound of the cell cache's table of footprints per (object, rotation): phase 2 asks for
#: the footprints of the parts on the table at every put-down it places.
FOOTPRINT_LIMIT = 4096


def _shape_key(model: ObjectModel) -> tuple:
    """What a footprint depends on in ``model``: its shape's primitives (world.collision.solids_key;
    not the object's name: copies of one model share their footprints)."""
    from spar_py.world.collision import solids_key  # on first use: the collision layer loads lazily

    return solids_key(model.shape)


#: Bound of the cell cache's table of shape keys per object name.
SHAPE_KEY_LIMIT = 1024


def _model_key(cache: CellCache, obj: str) -> tuple:
    """:func:`_shape_key` of ``obj``'s model, kept in the cell's cache by the object's name (and
    made again should the name stand for another model)."""
    cell = cache.cell
    model = cell.objects[obj]
    table = cache.table("placement.shape_key", SHAPE_KEY_LIMIT)
    hit = table.get(obj)
    if hit is None or hit[0] is not model:
        hit = table[obj] = (model, _shape_key(model))
    return hit[1]


def _footprint(cache: CellCache, obj: str, R: np.ndarray) -> np.ndarray:
    """:func:`footprint` of ``obj`` turned by R (3x3), kept in the cell's cache by the shape and
    the rotation; read-only."""
    cell = cache.cell
    model = cell.objects[obj]
    R = np.ascontiguousarray(R, dtype=float)

    def compute() -> np.ndarray:
        f = footprint(model, R)
        f.setflags(write=False)
        return f

    key = (_model_key(cache, obj), R.tobytes())
    return cache.table("placement.footprints", FOOTPRINT_LIMIT).get_or_compute(key, compute)


def occupant(cache: CellCache, obj: str, T: np.ndarray) -> Occupant:
    """The ``occupied`` entry of a part of ``obj`` at world pose T (4x4): its xy centre,
    bounding radius and footprint polygon in world xy (cell unit); memoised in the cell
    by the object's shape and the pose (the arrays are read-only)."""
    cell = cache.cell
    model = cell.objects[obj]
    T = np.ascontiguousarray(T, dtype=float)

    def compute() -> Occupant:
        c, poly = T[:2, 3].copy(), _footprint(cache, obj, T[:3, :3]) + T[:2, 3]
        c.setflags(write=False)
        poly.setflags(write=False)
        return (c, model.bounding_radius(), poly)

    key = (_model_key(cache, obj), T.tobytes())
    return cache.table("placement.occupants", FOOTPRINT_LIMIT).get_or_compute(key, compute)


def _occupant_polygon(entry: Sequence) -> np.ndarray:
    """The footprint polygon (k, 2) of an ``occupied`` entry (the bounding disc's
    circumscribed polygon for a (centre, radius) entry)."""
    if len(entry) >= 3 and entry[2] is not None:
        return np.asarray(entry[2], float)
    return _disc(np.asarray(entry[0], float), float(entry[1]))


def _minkowski_batch(P: np.ndarray, Q: np.ndarray) -> np.ndarray:
    """(b, a + c, 2) the Minkowski sums of b pairs of convex CCW polygons P (b, a, 2) and
    Q (b, c, 2), each sum as :func:`_minkowski` forms it: both polygons started at their
    lowest, then leftmost, vertex, their edges merged by angle (P's first on a tie)."""
    def start(V: np.ndarray) -> np.ndarray:
        first = np.lexsort((V[..., 0], V[..., 1]), axis=-1)[:, :1]  # lowest, then leftmost
        idx = (first + np.arange(V.shape[1])[None, :]) % V.shape[1]
        return np.take_along_axis(V, idx[..., None], axis=1)

    P, Q = start(P), start(Q)
    E = np.concatenate([np.roll(P, -1, axis=1) - P, np.roll(Q, -1, axis=1) - Q], axis=1)
    ang = np.mod(np.arctan2(E[..., 1], E[..., 0]), 2 * np.pi)
    steps = np.take_along_axis(E, np.argsort(ang, axis=1, kind="stable")[..., None], axis=1)
    walk = np.concatenate([np.zeros((len(E), 1, 2)), np.cumsum(steps, axis=1)[:, :-1]], axis=1)
    return (P[:, :1] + Q[:, :1]) + walk


def _clear_of_each(M: np.ndarray, t: np.ndarray, gap: float) -> np.ndarray:
    """(n,) bool: point t[i] (t (n, 2)) lies outside the convex CCW polygon M[i] (M (n, m, 2)),
    at least ``gap`` from it: not left of (or on) every edge, and at least ``gap`` from the
    nearest edge segment."""
    E = np.roll(M, -1, axis=1) - M                              # (n, m, 2)
    D = t[:, None, :] - M                                       # (n, m, 2)
    E0, E1, D0, D1 = E[..., 0], E[..., 1], D[..., 0], D[..., 1]
    inside = np.all(E0 * D1 - E1 * D0 >= 0, axis=1)
    L2 = E0 * E0 + E1 * E1
    u = np.clip((D0 * E0 + D1 * E1) / np.where(L2 > 0, L2, 1.0), 0.0, 1.0)
    d = np.hypot(D0 - u * E0, D1 - u * E1).min(axis=1)
    return ~inside & (d >= gap)


def _near_pairs(lo: np.ndarray, hi: np.ndarray, xs: np.ndarray, ys: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The grid points within boxes: for boxes ``lo``, ``hi`` (b, 2) and the grid xs x ys
    (points numbered x-major, as meshgrid "ij" ravelled), ``(box, point)`` index arrays of
    every point inside a box (bounds included), box by box, points in grid order."""
    ix0 = np.searchsorted(xs, lo[:, 0], side="left")
    ix1 = np.searchsorted(xs, hi[:, 0], side="right")
    iy0 = np.searchsorted(ys, lo[:, 1], side="left")
    iy1 = np.searchsorted(ys, hi[:, 1], side="right")
    nx, ny = np.maximum(ix1 - ix0, 0), np.maximum(iy1 - iy0, 0)
    count = nx * ny
    box = np.repeat(np.arange(len(lo)), count)
    if not len(box):
        return box, box
    # the r-th point of a box: r // ny steps in x, r % ny in y from its corner
    r = np.arange(len(box)) - np.repeat(np.cumsum(count) - count, count)
    ny_b = ny[box]
    point = (ix0[box] + r // ny_b) * len(ys) + iy0[box] + r % ny_b
    return box, point


def _blocks(P: np.ndarray, xs: np.ndarray, ys: np.ndarray, feet: list[np.ndarray],
            others: list[np.ndarray], gap: float, margin: float) -> list[np.ndarray]:
    """For each polygon of ``others``, the grid placements it blocks: the flat indices
    ``i * K + k`` (sorted, int32) of grid point P[i] (the grid xs x ys, x-major) with
    footprint feet[k] (K of them) closer than ``gap`` to it.

    All grid points x yaws x polygons at once: a point whose distance along x or y to the
    bounding box of the Minkowski sum of polygon j and the mirrored footprint k exceeds
    ``gap + margin`` is clear of it without more ado (the box holds the sum, and
    ``margin`` covers the sum's rounding); the rest are tested exactly
    (:func:`_clear_of_each`) against the sums, which are formed only for the (k, j) pairs
    that have such points."""
    K, J = len(feet), len(others)
    flo = np.array([f.min(axis=0) for f in feet])               # (K, 2)
    fhi = np.array([f.max(axis=0) for f in feet])
    wlo = np.array([W.min(axis=0) for W in others])             # (J, 2)
    whi = np.array([W.max(axis=0) for W in others])
    reach = gap + margin
    lo = (wlo[None, :, :] - fhi[:, None, :] - reach).reshape(-1, 2)  # pair p = k * J + j
    hi = (whi[None, :, :] - flo[:, None, :] + reach).reshape(-1, 2)
    pair, point = _near_pairs(lo, hi, xs, ys)
    if not len(pair):
        return [np.zeros(0, dtype=np.int32) for _ in others]
    used, slot = np.unique(pair, return_inverse=True)           # the sums needed, and each test's
    fail = np.zeros(len(pair), dtype=bool)
    uk, uj = used // J, used % J
    # one batch per (polygon size, footprint size): the sums of a batch share a vertex count
    sizes = np.array([[len(others[j]), len(feet[k])] for j, k in zip(uj, uk)])
    _, size_of = np.unique(sizes, axis=0, return_inverse=True)
    size_of = size_of.ravel()
    where = np.empty(len(used), dtype=np.int64)
    for g in range(int(size_of.max()) + 1):
        grp = np.flatnonzero(size_of == g)                      # indices into used
        M = _minkowski_batch(np.stack([others[j] for j in uj[grp]]), -np.stack([feet[k] for k in uk[grp]]))
        where[grp] = np.arange(len(grp))
        tests = np.flatnonzero(size_of[slot] == g)
        fail[tests] = ~_clear_of_each(M[where[slot[tests]]], P[point[tests]], gap)
    j_of, flat = pair[fail] % J, (point[fail] * K + pair[fail] // J).astype(np.int32)
    order = np.lexsort((flat, j_of))
    j_of, flat = j_of[order], flat[order]
    cut = np.searchsorted(j_of, np.arange(J + 1))
    return [flat[cut[j]:cut[j + 1]] for j in range(J)]


#: Bound of the cell cache's table of :func:`_blocks` answers per (grid, footprints,
#: occupant polygon): phase 2 places parts among mostly the same occupants at every
#: put-down of an instance and in every instance.
BLOCKS_LIMIT = 4096


def _blocked(cache: CellCache, P: np.ndarray, xs: np.ndarray, ys: np.ndarray, feet: list[np.ndarray],
             others: list[np.ndarray], gap: float, margin: float) -> np.ndarray:
    """The flat indices ``i * K + k`` of the grid placements some polygon of ``others``
    blocks (:func:`_blocks`), each polygon's answer kept in the cell's cache by what it
    depends on: the grid, the footprints, the clearance and the polygon."""
    memo = cache.table("placement.blocks", BLOCKS_LIMIT)
    gkey = (xs.tobytes(), ys.tobytes(), tuple(f.tobytes() for f in feet), gap, margin)
    keys = [(gkey, W.tobytes()) for W in others]
    todo = {k: W for k, W in zip(keys, others) if k not in memo}  # equal polygons are one
    if todo:
        for k, b in zip(todo, _blocks(P, xs, ys, feet, list(todo.values()), gap, margin)):
            memo[k] = b
    parts = [memo[k] for k in keys]
    return np.concatenate(parts) if parts else np.zeros(0, dtype=np.int32)


def _grid_arrays(cache: CellCache, obj: str, pose: str, occupied: list[Occupant],
                 step: float, yaw_steps: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The grid placements of :func:`candidates` as arrays, in the same order (regions, x,
    y, yaw): ``(xy (n, 2), yaw (n,), T (n, 4, 4))``, lengths in the cell unit
    (:func:`_grid_points`, their poses made for all)."""
    xy, k, yaws, rots, height, zs, _ = _grid_points(cache, obj, pose, occupied, step, yaw_steps)
    return xy, yaws[k], _grid_poses(xy, rots[k], height + zs)


def _grid_points(cache: CellCache, obj: str, pose: str, occupied: list[Occupant], step: float, yaw_steps: int,
                 tops: Sequence[Level] = ()
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, float, np.ndarray, np.ndarray]:
    """The grid placements of :func:`candidates`, in its order (regions, x, y, yaw), without
    their poses: ``(xy (n, 2), k (n,) each one's yaw step, yaws (yaw_steps,) rad, rots
    (yaw_steps, 3, 3) each yaw's object rotation, the pose's height, zs (n,) each one's surface
    height, on (n,) each one's surface name)``, lengths in the cell unit; the regions are
    :func:`levels`' (a support's top: the footprint within its top polygon), then ``tops`` (parts'
    tops, :func:`part_level`: likewise within the top, clear of the other parts).

    Kept: the placements whose footprint (:func:`footprint`, turned by the yaw) lies in
    the region of the grid point, and is at least the clearance (CLEARANCE_MM) from the
    footprint of every ``occupied`` entry (exactly, for the polygons: the placement's
    origin outside the Minkowski sum of the other footprint and the mirrored own one, by
    the clearance; every grid point, yaw and occupant at once, :func:`_blocked`).
    Each yaw's rotation is computed once, by the same expression (``rotz(yaw)[:3, :3] @
    R``) a placement at a time would use."""
    cell = cache.cell
    model = cell.objects[obj]
    sp = model.poses[pose]
    tol = from_mm(cell.unit, ROUND_MM)
    gap = from_mm(cell.unit, CLEARANCE_MM) - tol
    yaws = np.array([2 * np.pi * k / yaw_steps for k in range(yaw_steps)])
    rots = np.stack([rotz(yaw)[:3, :3] @ sp.R for yaw in yaws])  # (yaw_steps, 3, 3)
    feet = [_footprint(cache, obj, R) for R in rots]
    lo = np.array([f.min(axis=0) for f in feet])                # (yaw_steps, 2)
    hi = np.array([f.max(axis=0) for f in feet])
    parts = [_occupant_polygon(e) for e in occupied]
    xy_parts, yaw_parts, z_parts, on_parts = [], [], [], []
    for reg in [*_levels(cache), *tops]:
        (x0, x1), (y0, y1) = reg.x, reg.y
        others = (parts if reg.parts is None else list(reg.parts)) + list(reg.keep_off)
        if reg.polygon is None:
            xs = x0 + step * np.arange(math.floor((x1 - x0) / step + 1e-9) + 1)
            ys = y0 + step * np.arange(math.floor((y1 - y0) / step + 1e-9) + 1)
        else:  # a support's top, often little more than a part: the grid about its centre
            xs, ys = (_centred(lo, hi, step) for lo, hi in ((x0, x1), (y0, y1)))
        X, Y = np.meshgrid(xs, ys, indexing="ij")
        P = np.stack([X.ravel(), Y.ravel()], axis=1)             # (n, 2)
        ok = ((P[:, None, 0] + lo[None, :, 0] >= x0 - tol) & (P[:, None, 0] + hi[None, :, 0] <= x1 + tol)
              & (P[:, None, 1] + lo[None, :, 1] >= y0 - tol) & (P[:, None, 1] + hi[None, :, 1] <= y1 + tol))
        if others:
            ok.flat[_blocked(cache, P, xs, ys, feet, others, gap, tol + step * 1e-9)] = False
        if reg.polygon is not None:  # every footprint vertex on the support's top
            for kk, f in enumerate(feet):
                live = np.flatnonzero(ok[:, kk])
                ok[live, kk] = _within(reg.polygon, P[live, None, :] + f[None], tol).all(axis=1)
        i, k = np.nonzero(ok)                                    # row-major: grid order, then yaw
        xy_parts.append(P[i])
        yaw_parts.append(k)
        z_parts.append(np.full(len(i), reg.z))
        on_parts.append(np.full(len(i), reg.on, dtype=object))
    xy = np.concatenate(xy_parts) if xy_parts else np.zeros((0, 2))
    k = np.concatenate(yaw_parts) if yaw_parts else np.zeros(0, dtype=int)
    zs = np.concatenate(z_parts) if z_parts else np.zeros(0)
    on = np.concatenate(on_parts) if on_parts else np.zeros(0, dtype=object)
    return xy, k, yaws, rots, float(sp.height), zs, on


def _centred(lo: float, hi: float, step: float) -> np.ndarray:
    """Grid coordinates in [lo, hi] ``step`` apart, symmetric about its middle (which is one)."""
    m = math.floor((hi - lo) / 2 / step + 1e-9)
    return (lo + hi) / 2 + step * np.arange(-m, m + 1)


def _grid_poses(xy: np.ndarray, R: np.ndarray, height: float | np.ndarray) -> np.ndarray:
    """(n, 4, 4) the object poses of grid placements at ``xy`` (n, 2) turned by R (n, 3, 3), at
    ``height`` (cell unit: the stable pose's over its surface, one or (n,))."""
    T = np.zeros((len(xy), 4, 4))
    T[:, :3, :3] = R
    T[:, 0, 3] = xy[:, 0]
    T[:, 1, 3] = xy[:, 1]
    T[:, 2, 3] = height
    T[:, 3, 3] = 1.0
    return T


def candidates(cache: CellCache, obj: str, pose: str, occupied: list[Occupant],
               step: float | None = None, yaw_steps: int = YAW_STEPS) -> list[Placement]:
    """Grid placements of ``obj`` in stable pose ``pose`` whose footprint lies in a free
    region, clear of ``occupied`` (:data:`Occupant` entries: the other parts on the
    table) by the clearance. ``step``: grid spacing in the cell unit (default GRID_STEP_MM)."""
    cell = cache.cell
    step = from_mm(cell.unit, GRID_STEP_MM) if step is None else step
    xy, k, yaws, rots, height, zs, on = _grid_points(cache, obj, pose, occupied, step, yaw_steps)
    T = _grid_poses(xy, rots[k], height + zs)
    # copies, not views of T: a kept placement must not keep the whole grid's poses alive
    return [Placement(obj, pose, x, y, float(t[2, 3]), w, t.copy(), str(o))
            for (x, y), w, t, o in zip(xy.tolist(), yaws[k].tolist(), T, on.tolist())]


def _req_X(r: Requirement | np.ndarray) -> np.ndarray:
    return np.asarray(r.X if isinstance(r, Requirement) else r, float)


def _reach_all(cache: CellCache, TO: np.ndarray, X: Sequence[Requirement | np.ndarray],
               obj: str | None = None) -> np.ndarray:
    """(n, m) bool: the arm reaches T_O @ X (wrist above the table) for object poses TO
    (n, 4, 4) and requirements X (m: 4x4 tool transforms, or workspace.Requirement); with the
    object ``obj`` named, by a solution clear of the table, the obstacles and the object itself
    (workspace.requirement_clear, one batched call per requirement), else by IK alone."""
    cell = cache.cell
    if obj is None:
        Xs = np.stack([_req_X(x) for x in X])
        T = np.einsum("nij,mjk->nmik", TO, Xs).reshape(-1, 4, 4)     # (n*m,4,4)
        return reachable_ignoring_collisions(cell.robot, T).reshape(len(TO), len(Xs))
    out = np.zeros((len(TO), len(X)), dtype=bool)
    for k, x in enumerate(X):
        out[:, k] = requirement_clear(cache, obj, TO, x).ok
    return out


def feasible(cache: CellCache, placements: list[Placement], requirements: list[np.ndarray | Requirement]) -> np.ndarray:
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
    return _reach_all(cache, np.stack([p.T for p in placements]), requirements, obj).all(axis=1)


#: Placements :func:`choose` checks at a time, nearest first.
CHOOSE_CHUNK = 96


def round_like_python(x: np.ndarray, digits: int) -> np.ndarray:
    """(n,) ``round(v, digits)`` of each v of ``x`` (float64, digits >= 0), exactly as Python's
    correctly rounded ``round`` gives it, for a whole array at once.

    ``rint(v * 10**digits) / 10**digits`` (what ``np.round`` does) is the same double as
    Python's answer whenever it picks the same integer k (both then give the double nearest
    k / 10**digits: the division is correctly rounded); it can pick another only where the
    product's rounding moved it across a half (or onto one). Those few values, the product
    within 1e-3 of a half, and any too large for the product to hold a fraction, are
    rounded by Python's ``round`` itself."""
    x = np.asarray(x, dtype=float)
    f = 10.0 ** digits
    y = x * f
    out = np.rint(y) / f
    doubt = ~(np.abs(y) < 2.0 ** 52) | (np.abs(np.abs(y - np.floor(y)) - 0.5) < 1e-3)
    for i in np.flatnonzero(doubt):
        out[i] = round(float(x[i]), digits)
    return out


def nearest_order(dist: np.ndarray, yaw: np.ndarray, digits: int) -> np.ndarray:
    """(n,) int indices of the candidates ordered as ``sorted(range(n), key=lambda i:
    (round(dist[i], digits), yaw[i]))`` orders them: least rounded distance, then least
    yaw, then first in grid order (a stable sort), computed on the arrays."""
    dist, yaw = np.asarray(dist, dtype=float), np.asarray(yaw, dtype=float)
    return np.lexsort((np.arange(len(dist)), yaw, round_like_python(dist, digits)))


def choose(cache: CellCache, obj: str, pose: str, requirements: list[np.ndarray],
           occupied: list[Occupant], near: np.ndarray | None = None,
           reach: Sequence[np.ndarray] = (), tops: Sequence[Level] = ()) -> Placement | None:
    """The feasible placement nearest ``near`` (xy, cell unit; default the regions'
    centre), or None. Candidates as :func:`candidates`: the footprint in a free region,
    clear of the ``occupied`` parts' footprints by the clearance, or on one of ``tops`` (parts'
    tops, :func:`part_level`) clear of the other parts. Feasible: every
    requirement reached clear of the world, and every tool pose of ``reach`` (relative to
    the object, as requirements are) reached by IK alone (the far ends of the motions' tool
    lines: the motion planner checks the lines' clearance itself).

    Nearest: least distance rounded to ROUND_MM, then least yaw, then first in grid order.
    The candidates are checked in that order, the nearest alone and then a chunk at a time,
    so the search stops at the first chunk holding a feasible one instead of solving IK for
    the whole grid.
    """
    cell = cache.cell
    xy, kyaw, yaw_of, rots, height, zs, on = _grid_points(cache, obj, pose, occupied,
                                                          from_mm(cell.unit, GRID_STEP_MM), YAW_STEPS, tops)
    n = len(xy)
    if not n:
        return None
    if near is None:
        regs = default_regions(cell)
        near = np.mean([[(r["x"][0] + r["x"][1]) / 2, (r["y"][0] + r["y"][1]) / 2] for r in regs], axis=0)
    # distances in mm, so ties are broken alike whatever the cell's unit
    dist = np.hypot(xy[:, 0] - near[0], xy[:, 1] - near[1]) * mm_per(cell.unit)
    yaw = yaw_of[kyaw]
    digits = -round(math.log10(ROUND_MM))
    # the first two chunks' worth of the order (what the search usually reads), the whole of it
    # only if the search goes on
    order = _nearest_head(round_like_python(dist, digits), yaw, 1 + CHOOSE_CHUNK).tolist()
    starts = [0, *range(1, n, CHOOSE_CHUNK)]  # the nearest alone first: it usually serves
    for start, end in zip(starts, [*starts[1:], n]):
        if end > len(order):
            order = nearest_order(dist, yaw, digits).tolist()
        idx = order[start:end]
        ok = np.ones(len(idx), dtype=bool)
        for x in requirements or ():  # each requirement by IK and clearance, on the survivors only
            live = np.flatnonzero(ok)
            if not len(live):
                break
            at = np.array([idx[i] for i in live], dtype=int)
            ok[live] = _reach_all(cache, _grid_poses(xy[at], rots[kyaw[at]], height + zs[at]), [x], obj)[:, 0]
        live = np.flatnonzero(ok)
        if len(reach) and len(live):
            at = np.array([idx[i] for i in live], dtype=int)
            ok[live] = _reach_all(cache, _grid_poses(xy[at], rots[kyaw[at]], height + zs[at]), list(reach)).all(axis=1)
        hits = np.flatnonzero(ok)
        if len(hits):
            i = idx[hits[0]]
            # the pose made for this placement alone: no view keeps a grid's poses alive wherever
            # the placement is kept (phase 2's memo tables)
            T = _grid_poses(xy[i:i + 1], rots[kyaw[i:i + 1]], height + zs[i:i + 1])[0]
            return Placement(obj, pose, float(xy[i, 0]), float(xy[i, 1]), float(T[2, 3]), float(yaw[i]), T,
                             str(on[i]))
    return None


def _nearest_head(key: np.ndarray, yaw: np.ndarray, m: int) -> np.ndarray:
    """The first min(m, n) or more entries of :func:`nearest_order`'s order, from the rounded
    distances ``key`` (n,): every candidate whose key is at most the m-th least, ordered by
    (key, yaw, index); the others' keys are larger, so they all come after these."""
    n = len(key)
    if n <= m:
        return np.lexsort((np.arange(n), yaw, key))
    v = np.partition(key, m - 1)[m - 1]
    cand = np.flatnonzero(key <= v)
    return cand[np.lexsort((cand, yaw[cand], key[cand]))]


#: The coarser grid phase 1 uses to decide whether a stable pose is reachable at all:
#: 152.4 mm (6 in) apart, 6 yaws.
PHASE1_STEP_MM = 152.4
PHASE1_YAWS = 6


def some_placement_reaches(cache: CellCache, obj: str, pose: str,
                        requirements: Sequence[np.ndarray | Requirement]) -> np.ndarray:
    """(m,) bool: for each requirement (a tool transform X in the object frame, or a
    workspace.Requirement), some placement of ``obj`` in ``pose`` on the phase-1 grid of the
    free regions where the arm reaches T_O @ X by a solution clear of the table, the obstacles
    and the object (and the part in the hand).

    A necessary condition for a put-down or mate at a stable-pose position: it ignores
    the other objects (phase 1 does not know where they will be); phase 2 chooses a real
    placement clear of them that serves every later action at once.
    """
    return some_placement_reaches_each(cache, obj, [(pose, requirements)])[0]


def some_placement_reaches_each(cache: CellCache, obj: str,
                             asks: Sequence[tuple[str, Sequence[np.ndarray | Requirement]]]) -> list[np.ndarray]:
    """:func:`some_placement_reaches` for each (stable pose, requirements) of ``asks`` (one arc's
    positions), solved together: a requirement asked in several poses is checked at all their
    first placements in one batch (one scene state, one IK call, one clearance check)."""
    cell = cache.cell
    memo = cache.table("placement.somewhere", SOMEWHERE_LIMIT)
    # the answer depends on the geometry only (the world holds no other part): renamed copies
    # of one model (generated cells: N identical blocks and pegs) share it
    shape = shape_key if cell.collisions else _name_key
    okey = shape(cache, obj)
    outs: list[np.ndarray] = []
    todo: dict[tuple, list[tuple[int, int]]] = {}  # equal (pose, requirement) asks are solved once
    items: dict[tuple, tuple[str, Requirement]] = {}
    for a, (pose, requirements) in enumerate(asks):
        reqs = [r if isinstance(r, Requirement) else Requirement(np.asarray(r, float)) for r in requirements]
        out = np.zeros(len(reqs), dtype=bool)
        gkey = _grid_key(cache, obj, pose) if reqs else None
        for i, r in enumerate(reqs):
            held = None if r.held is None else (shape(cache, r.held[0]), np.round(r.held[1], 12).tobytes())
            key = (gkey, okey, np.round(r.X, 12).tobytes(), held, None if r.width is None else round(r.width, 12))
            if key in memo:
                out[i] = memo[key]
            else:
                todo.setdefault(key, []).append((a, i))
                items.setdefault(key, (pose, r))
        outs.append(out)
    if todo:
        grids: dict[str, np.ndarray] = {}  # one grid per stable pose (its key made once, not per item)
        for pose, _ in items.values():
            if pose not in grids:
                grids[pose] = _grid(cache, obj, pose)
        got = _some_placement(cache, obj, [(grids[pose], r) for pose, r in items.values()])
        for (key, where), ok in zip(todo.items(), got):
            memo[key] = ok
            for a, i in where:
                outs[a][i] = ok
    return outs


def _name_key(cache: CellCache, obj: str) -> str:
    """The memo key of ``obj`` in a cell without collision checks: its name (IK alone does not
    look at the object, so any key serves; the name keeps such cells' tables as they were)."""
    return obj


def _some_placement(cache: CellCache, obj: str, items: list[tuple[np.ndarray, Requirement]],
                    chunk: int = 48) -> list[bool]:
    """For each (object poses ``cands`` (n,4,4), requirement) of ``items``, some pose of ``cands``
    at which the arm reaches T_O @ req.X clear of the world: the first :data:`FIRST_PLACEMENTS`
    placements alone (one IK batch for every item; one clearance check per requirement for
    those placements of all its items), then ``chunk`` at a time (the usual case is met at the
    first placement or the second, so the whole first chunk's IK and clearance are seldom
    needed). Which placements are tried together changes the work, never the answer (some
    placement of the grid, or none).

    Refused before any IK (workspace.tool_refusal): the grasp rule, or two bodies rigid with
    the flange (gripper, held part, the object where the tool is) closer than the margin, which
    refuse every placement alike; and, the grid's placements differing only by a turn about
    world z and a shift in x, y, a wrist below the table at the first one (by more than
    rounding) or a body rigid with the tool on an unbounded table, which are so at every one."""
    cell = cache.cell
    out = [False] * len(items)
    live: list[tuple[int, SceneState | None]] = []  # (item, its requirement's scene state)
    T0 = [cands[0] @ np.asarray(req.X, float) if len(cands) else None for cands, req in items]
    # the items share a few grids (one per stable pose): each grid's z-row test made once, and
    # every item's wrist height at its first placement in one batch
    z_rows: dict[int, bool] = {}
    for cands, _ in items:
        if len(cands) and id(cands) not in z_rows:
            z_rows[id(cands)] = bool(np.all(cands[:, 2, :] == cands[0, 2, :]))
    placed = [k for k, (cands, _) in enumerate(items) if len(cands)]
    wrist = dict(zip(placed, wrist_height(cell.robot, np.stack([T0[k] for k in placed])).tolist())) if placed else {}
    below = -from_mm(cell.unit, ROUND_MM)
    for k, (cands, req) in enumerate(items):
        if not len(cands):
            continue
        z_row = z_rows[id(cands)]
        if z_row and wrist[k] < below:
            continue
        state = requirement_state(cache, obj, req)
        if tool_refusal(cache, obj, T0[k], req, table=z_row, state=state) is None:
            live.append((k, state))
    if not live:
        return out
    # the first FIRST_PLACEMENTS placements of every live item: (its row in live, object pose, tool pose)
    heads: list[tuple[int, np.ndarray, np.ndarray]] = []
    for row, (k, _) in enumerate(live):
        cands, req = items[k]
        heads.append((row, cands[0], T0[k]))
        if FIRST_PLACEMENTS > 1 and len(cands) > 1:
            more = cands[1:FIRST_PLACEMENTS]
            heads += [(row, TO, T) for TO, T in zip(more, more @ np.asarray(req.X, float))]
    Q, okb = ik_rows(cell, np.stack([T for _, _, T in heads]))
    groups: dict[int, list[int]] = {}  # heads by requirement state (None: no collision check)
    for h, (row, _, _) in enumerate(heads):
        state = live[row][1]
        groups.setdefault(id(state) if state is not None else -1 - row, []).append(h)
    first = np.zeros(len(live), dtype=bool)
    for hs in groups.values():
        k, state = live[heads[hs[0]][0]]
        ok = requirement_clear_each(cache, obj, np.stack([heads[h][1] for h in hs]), items[k][1], state,
                                    (Q[hs], okb[hs]))
        first[[heads[h][0] for h, o in zip(hs, ok.tolist()) if o]] = True
    for row, (k, state) in enumerate(live):
        cands, req = items[k]
        start0 = min(FIRST_PLACEMENTS, len(cands))
        out[k] = bool(first[row]) or any(
            requirement_clear(cache, obj, cands[start:start + chunk], req, state=state).ok.any()
            for start in [start0, *range(start0 + chunk, len(cands), chunk)] if start < len(cands))
    return out


#: Placements of each item of :func:`_some_placement` tried in its first batch (one IK call for
#: every item, one clearance check per requirement): an item refused at the first is mostly
#: met at the second (7 of 7 in the paper's cell), and one more row in a batched check costs
#: far less than the chunk's own call it saves.
FIRST_PLACEMENTS = 2


#: Bounds of the cell cache's tables: some_placement_reaches's answers per
#: (grid, requirement), and the phase-1 grids per stable-pose geometry. Phase 1 asks the
#: same arcs again in every round of its deepening search, and objects that are copies of
#: one model (the same stable pose, so the same grid) ask the same questions.
SOMEWHERE_LIMIT = 100_000
GRID_LIMIT = 1024


def _grid_key(cache: CellCache, obj: str, pose: str) -> tuple:
    """What the phase-1 grid of ``obj`` in ``pose`` depends on within a cell: the stable
    pose's rotation and height and the object's footprint in it, not the object's name."""
    cell = cache.cell
    model = cell.objects[obj]
    sp = model.poses[pose]
    return (np.asarray(sp.R, float).tobytes(), float(sp.height), _footprint(cache, obj, sp.R).tobytes())


def _grid(cache: CellCache, obj: str, pose: str) -> np.ndarray:
    """(n,4,4) object poses of the phase-1 grid (kept in the cell's cache per stable-pose geometry)."""
    cell = cache.cell
    step = from_mm(cell.unit, PHASE1_STEP_MM)
    return cache.table("placement.grids", GRID_LIMIT).get_or_compute(
        _grid_key(cache, obj, pose), lambda: _grid_arrays(cache, obj, pose, [], step, PHASE1_YAWS)[2])
