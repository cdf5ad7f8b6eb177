"""Physical sanity of a loaded cell: is the cell one that could exist?

Checked once at load (:func:`check_cell`, the last step of kb.problem.load_problem), before any
grid or IK is built, each failure a one-line :class:`~spar_py.core.errors.KBError` naming the
file, the key and both parties:

- reach: every initial position, placement region, named transform's displacement and
  object-frame length (shape, grasp, feature, pose height) lies within a box about the
  robot's base of half-width REACH_FACTOR x (sum of the DH link lengths |a| + |d| and
  the tool offset), so no placement grid is ever unbounded;
- resting: each initial part's rotation is one of its stable poses (kb checks this), its
  lowest point is on the table top (z = 0), a support's top or another part's top within
  REST_TOL_MM and its centre of mass over its support polygon (world.reach.supports);
- overlap: no two initial parts overlap by more than OVERLAP_TOL_MM;
- gripper: every grasp's width W_g is at most the finger separation W_m;
- vectors: every approach / mating vector under ``vectors:`` is non-zero.

Overlap test: a separating-axis test between convex polytopes, per pair of shape
primitives (model.Solid) placed at the positions' transforms. Boxes are exact (their 3
face normals each and the 9 edge cross products); a z-cylinder is the prism on the
regular CYL_SIDES-gon *inscribed* in its rims, a subset of the cylinder, so an overlap
is never reported that the true solids do not have (no false errors); an overlap
shallower than r (1 - cos(pi / CYL_SIDES)) (1.9 % of the radius) of a cylinder's side
can go unreported. The depth printed is the least overlap of the projections over the
tested axes (for two boxes: the penetration depth along a separating-axis direction).

Units: lengths in the cell unit (``Cell.unit``); the tolerances are mm (units.py) and
converted. Frames: world Z up, table top z = 0; shapes in the object frame.
"""
from __future__ import annotations

from pathlib import Path
from typing import Any, Iterator

import numpy as np
import yaml

from spar_py.core.errors import KBError
from spar_py.core.model import Cell, Position, Solid
from spar_py.core.units import from_mm
from spar_py.kb.reader import SAFE_LOADER
from spar_py.kb.terms import atoms
from spar_py.world.reach import REST_TOL_MM, lowest, part_surface, rest_of, solid_points, surfaces_of

__all__ = ["REST_TOL_MM", "check_cell", "overlap_depth", "reach_box", "solid_points"]

#: Half-width of the box of admissible coordinates, in multiples of the arm's length
#: (sum of |a| + |d| + tool offset: 66.5 in for the PUMA 762, whose real reach from the
#: shoulder is about 49 in). 2, not 1.5: kb/problems/unreachable.yaml puts its parts
#: 100 in out on purpose, a cell that loads and has no plan; 1.5 x 66.5 in is 99.8 in.
REACH_FACTOR = 2.0
#: Parts may overlap this much (mm): touching parts, rounding.
OVERLAP_TOL_MM = 0.01
#: Sides of the polygon inscribed in a cylinder's rims for the overlap test.
CYL_SIDES = 16
#: A vector shorter than this is zero (vectors are directions: no unit).
ZERO_VECTOR = 1e-9


def check_cell(cell: Cell) -> None:
    """Raise KBError for the first physically impossible thing in ``cell`` (see the
    module docstring); return None for a sane cell."""
    for err in _problems(cell):
        raise err


def _problems(cell: Cell) -> Iterator[KBError]:
    """Every check in order, cheapest and most basic first; each yields its errors."""
    yield from _reach(cell)
    yield from _gripper(cell)
    yield from _vectors(cell)
    yield from _on_table(cell)
    yield from _overlaps(cell)


# --------------------------------------------------------------------------- helpers


def _fmt(v: float, unit: str = "") -> str:
    """A number rounded for reading (4 significant digits), with its unit."""
    s = f"{v:.4g}"
    return f"{s} {unit}" if unit else s


def _sources(cell: Cell) -> dict[str, Any]:
    """The problem file's own text as data, read again on the error path only (to name
    the robot and model files):
    ``{"robot": path, "models": {obj: path}}``; paths as the problem names them,
    resolved against its folder. Empty where the file cannot be read again."""
    try:
        data = yaml.load(Path(cell.file).read_text(encoding="utf-8"), Loader=SAFE_LOADER)
        base = Path(cell.file).parent
        return {"robot": str(base / data["robot"]),
                "models": {o: str(base / n["model"]) for o, n in data["objects"].items()}}
    except Exception:  # the file was read once by kb; a race is reported against the problem
        return {}


def _position_key(cell: Cell, pos: Position) -> str:
    """The key of a position in the problem file: ``objects.OBJ.initial`` (``[i]`` in a stock)."""
    same = [p for p in cell.positions.values() if p.obj == pos.obj]
    return f"objects.{pos.obj}.initial" + (f"[{same.index(pos)}]" if len(same) > 1 else "")


def reach_box(cell: Cell) -> tuple[np.ndarray, float]:
    """(centre (3,), half-width) of the box of admissible world coordinates (cell unit):
    the robot base's origin, REACH_FACTOR x (sum over the DH rows of |a| + |d| plus the
    tool offset's length)."""
    r = cell.robot
    arm = float(np.abs(r.dh[:, 1]).sum() + np.abs(r.dh[:, 2]).sum() + np.linalg.norm(r.tool[:3, 3]))
    return r.base[:3, 3].copy(), REACH_FACTOR * arm


def _axes(s: Solid, sides: int = CYL_SIDES) -> tuple[np.ndarray, np.ndarray]:
    """(face normals (f, 3), edge directions (e, 3)) of a primitive's polytope, object frame."""
    if s.kind == "hull":
        return _hull_axes(np.asarray(s.points, float))
    if s.kind == "cylinder":
        a = 2 * np.pi * (np.arange(sides) + 0.5) / sides
        normals = np.concatenate([np.stack([np.cos(a), np.sin(a), np.zeros(sides)], axis=1), np.eye(3)[2:]])
        b = 2 * np.pi * np.arange(sides) / sides + np.pi / 2 + np.pi / sides
        edges = np.concatenate([np.stack([np.cos(b), np.sin(b), np.zeros(sides)], axis=1), np.eye(3)[2:]])
        return normals, edges
    return np.eye(3), np.eye(3)


def _hull_axes(P: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(unique face normals, unique edge directions) of the convex hull of points P (k, 3)."""
    from scipy.spatial import ConvexHull  # only a part with a hull (a mesh) needs it

    h = ConvexHull(P)
    normals = np.unique(np.round(h.equations[:, :3], 9), axis=0)
    tri = P[h.simplices]
    e = np.concatenate([tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 1], tri[:, 0] - tri[:, 2]])
    e = e[np.linalg.norm(e, axis=1) > 1e-12]
    e /= np.linalg.norm(e, axis=1)[:, None]
    e *= np.where((e @ [1.0, 1e-3, 1e-6]) < 0, -1.0, 1.0)[:, None]  # one sign per direction
    return normals, np.unique(np.round(e, 9), axis=0)


def overlap_depth(s1: Solid, T1: np.ndarray, s2: Solid, T2: np.ndarray) -> float:
    """How deep two primitives at world poses T1, T2 (4x4) overlap (cell unit): the
    least overlap of their projections over the separating-axis candidates (face
    normals of each, cross products of their edges); <= 0 when an axis separates them."""
    return _depth(_placed(s1, T1), _placed(s2, T2))


def _placed(s: Solid, T: np.ndarray, local: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None
            ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A primitive at world pose T (4x4): its polytope's vertices (k, 3), face normals (f, 3)
    and edge directions (e, 3) in the world frame (cell unit); ``local``: the same three in
    the object frame (:func:`_local`), when the caller has them already."""
    pts, normals, edges = _local(s) if local is None else local
    return pts @ T[:3, :3].T + T[:3, 3], normals @ T[:3, :3].T, edges @ T[:3, :3].T


def _local(s: Solid) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A primitive's polytope in the object frame: vertices, face normals, edge directions."""
    return (solid_points(s), *_axes(s))


#: Edge-pair axes projected per block in :func:`_depth` (two mesh hulls of thousands of edges
#: each give millions of cross products: projected a block at a time, memory stays bounded).
AXES_BLOCK = 1 << 14
#: Horizontal axes every 5 deg and the vertical, tried with the face normals when only whether
#: two primitives overlap is asked: any axis that separates them proves they are apart, and
#: parts side by side on the table are most often apart along a level one.
LEVEL_AXES = np.concatenate([np.stack([np.cos(a), np.sin(a), np.zeros_like(a)], axis=1)
                             for a in [np.radians(np.arange(0.0, 180.0, 5.0))]] + [np.eye(3)[2:]])


def _overlap(P1: np.ndarray, P2: np.ndarray, A: np.ndarray) -> float:
    """The least overlap of the projections of points P1 and P2 on the axes A (unit rows)."""
    p1, p2 = P1 @ A.T, P2 @ A.T                              # (k, axes)
    return float(np.minimum(p1.max(axis=0) - p2.min(axis=0), p2.max(axis=0) - p1.min(axis=0)).min())


def _cross_axes(e1: np.ndarray, e2: np.ndarray) -> np.ndarray:
    """Every edge of e1 crossed with every edge of e2 (np.cross's terms), (len(e1) len(e2), 3)."""
    u, v = e1[:, None, :], e2[None, :, :]
    return np.stack([u[..., 1] * v[..., 2] - u[..., 2] * v[..., 1], u[..., 2] * v[..., 0] - u[..., 0] * v[..., 2],
                     u[..., 0] * v[..., 1] - u[..., 1] * v[..., 0]], axis=-1).reshape(-1, 3)


def _unit_axes(A: np.ndarray) -> np.ndarray:
    """The rows of A normalised, those shorter than 1e-9 (parallel edges) dropped."""
    norm = np.linalg.norm(A, axis=1)
    return A[norm > 1e-9] / norm[norm > 1e-9, None]


def _depth(a: tuple[np.ndarray, np.ndarray, np.ndarray], b: tuple[np.ndarray, np.ndarray, np.ndarray],
           apart_is_enough: bool = False) -> float:
    """:func:`overlap_depth` of two primitives already :func:`_placed` (cell unit): the least
    overlap over every axis. With ``apart_is_enough`` (the sanity check asks no more than
    whether they overlap) LEVEL_AXES are tried first, then the face normals, then the edge
    pairs a block of AXES_BLOCK at a time, and the first overlap <= 0 is the answer: two mesh hulls of
    thousands of edges each are not crossed all at once."""
    (P1, n1, e1), (P2, n2, e2) = a, b
    if not apart_is_enough:
        return _overlap(P1, P2, _unit_axes(np.concatenate([n1, n2, _cross_axes(e1, e2)])))
    depth = _overlap(P1, P2, LEVEL_AXES)
    if depth > 0:
        depth = min(depth, _overlap(P1, P2, _unit_axes(np.concatenate([n1, n2]))))
    rows = max(1, AXES_BLOCK // max(1, len(e2)))
    for k in range(0, len(e1), rows):
        if depth <= 0:
            break
        A = _unit_axes(_cross_axes(e1[k:k + rows], e2))
        if len(A):
            depth = min(depth, _overlap(P1, P2, A))
    return depth


# --------------------------------------------------------------------------- checks


def _reach(cell: Cell) -> Iterator[KBError]:
    """Coordinates within the reach box (a fast guard before any grid is built)."""
    c, h = reach_box(cell)
    u, robot = cell.unit, cell.robot.name
    where = f"within {_fmt(h, u)} of {robot}'s base at ({', '.join(_fmt(v) for v in c)}) {u}"
    for pos in cell.positions.values():
        d = pos.T[:3, 3]
        for i in np.flatnonzero(np.abs(d - c) > h):
            yield KBError(cell.file, _position_key(cell, pos),
                          f"expected {pos.obj} at {pos.name} {where}, not {'xyz'[i]} = {_fmt(d[i], u)}")
    for k, reg in enumerate(cell.placement_regions):
        for i, ax in enumerate("xy"):
            for v in reg[ax]:
                if abs(v - c[i]) > h:
                    yield KBError(cell.file, f"placement_regions[{k}].{ax}",
                                  f"expected a free table region {where}, not {ax} = {_fmt(v, u)}")
    for name, T in cell.transforms.items():
        if np.abs(T[:3, 3]).max() > h:
            yield KBError(cell.file, f"transforms.{name}",
                          f"expected a displacement shorter than {robot}'s reach bound {_fmt(h, u)}, "
                          f"not {_fmt(float(np.abs(T[:3, 3]).max()), u)}")
    for obj, m in cell.objects.items():
        sizes = [(f"shape[{i}]", float(np.abs(np.concatenate([s.lo, s.hi])).max())) for i, s in enumerate(m.shape)]
        sizes += [(f"grasps[{i}].eulerxyz", float(np.abs(g.euler[:3]).max())) for i, g in enumerate(m.grasps.values())]
        sizes += [(f"stable_poses[{i}].tm", abs(p.height)) for i, p in enumerate(m.poses.values())]
        many = len(m.features) > 1
        sizes += [(f"features[{i}]" if many else "feature", max(float(np.abs(f.vector).max()), f.radius))
                  for i, f in enumerate(m.features)]
        for key, size in sizes:
            if size > h:
                models = _sources(cell).get("models", {})  # read again only to name the file
                yield KBError(models.get(obj, cell.file), key if obj in models else f"objects.{obj}.model",
                              f"expected a length of {obj} within {robot}'s reach bound {_fmt(h, u)}, "
                              f"not {_fmt(size, u)}")
                break


def _gripper(cell: Cell) -> Iterator[KBError]:
    """Every grasp fits the open gripper: W_g <= W_m."""
    wm, u = cell.finger_separation, cell.unit
    for obj, m in cell.objects.items():
        for i, g in enumerate(m.grasps.values()):
            if g.width > wm * (1 + 1e-9):
                src = _sources(cell)  # read again only to name the files
                file = src.get("models", {}).get(obj, cell.file)
                key = f"grasps[{i}].width" if obj in src.get("models", {}) else f"objects.{obj}.model"
                yield KBError(file, key,
                              f"expected a grasp that fits {cell.robot.name}'s gripper (finger separation "
                              f"W_m = {_fmt(wm, u)}, {src.get('robot', cell.file)}: gripper.finger_separation), "
                              f"not {obj}'s {g.label} {_fmt(g.width, u)} wide")


def _vectors(cell: Cell) -> Iterator[KBError]:
    """Approach and mating vectors (``vectors:``, the V_a of assembled goals) are non-zero."""
    users: dict[str, list[str]] = {}
    for k, g in enumerate(cell.goals):
        used = set(atoms(g))
        for name in cell.vectors:
            if name in used:
                users.setdefault(name, []).append(f"goals[{k}] {g[0] if isinstance(g, tuple) else g}")
    for name, v in cell.vectors.items():
        if float(np.linalg.norm(v)) <= ZERO_VECTOR:
            who = ", ".join(users.get(name, [])) or "no goal"
            yield KBError(cell.file, f"vectors.{name}",
                          f"expected a non-zero approach vector (used by {who}), "
                          f"not [{', '.join(_fmt(float(x)) for x in v)}]")


def _on_table(cell: Cell) -> Iterator[KBError]:
    """Each initial part rests on the table top, a support's top or another part's top
    (world.reach.supports.rest): its lowest point on the surface within REST_TOL_MM and its centre
    of mass over its support polygon; a part without a shape: its frame at its stable pose's
    height over the surface. A part on an unbounded table at z = 0 in a stable pose rests there
    (kb checks the pose), so its centre of mass is not computed."""
    tol = from_mm(cell.unit, REST_TOL_MM)
    base = surfaces_of(cell)
    tops = {p.label: part_surface(p.obj, cell.objects[p.obj], p.T, tol)
            for p in cell.positions.values() if cell.objects[p.obj].shape}
    for pos in cell.positions.values():
        m = cell.objects[pos.obj]
        if cell.table is None and m.shape and abs(lowest(m, pos.T)) <= tol:
            continue
        on = rest_of(cell, pos.obj, pos.T, base + [s for k, s in tops.items() if k != pos.label])
        if on is None:
            continue  # kb refuses an orientation that is no stable pose
        if not on.ok:
            yield KBError(cell.file, _position_key(cell, pos),
                          f"expected {pos.obj} at {pos.name} resting on the table, a support or another part "
                          f"(its lowest point on the surface, its centre of mass over it); it {on.why}")


def _overlaps(cell: Cell) -> Iterator[KBError]:
    """No two initial parts overlap (separating axes over their primitives' polytopes).

    Pairs whose bounding spheres are apart are skipped; all pairs' centre distances are
    computed at once only to pick the pairs that get the exact per-pair test (with slack
    for rounding, so every pair the exact test keeps is picked), and each part's
    primitives are placed once."""
    tol, u = from_mm(cell.unit, OVERLAP_TOL_MM), cell.unit
    pos = list(cell.positions.values())
    if len(pos) < 2:
        return
    shapes = [cell.objects[p.obj].shape for p in pos]
    by_shape: dict[tuple, float] = {}  # bounding radii by the shapes' Solid.keys: parts share models
    radii = []
    for p in pos:
        key = tuple(s.key() for s in cell.objects[p.obj].shape)
        if key not in by_shape:
            by_shape[key] = cell.objects[p.obj].bounding_radius()
        radii.append(by_shape[key])
    centres = np.array([p.T[:3, 3] for p in pos])
    r = np.array(radii)
    gap = np.sqrt(((centres[:, None, :] - centres[None, :, :]) ** 2).sum(axis=2))
    near = gap <= (r[:, None] + r[None, :] + tol) * (1 + 1e-9) + 1e-9 * (1 + gap)
    placed: dict[tuple[int, int], tuple[np.ndarray, np.ndarray, np.ndarray]] = {}
    local: dict[tuple, tuple[np.ndarray, np.ndarray, np.ndarray]] = {}  # by Solid.key: parts share models

    def at(k: int, m: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Part k's primitive m, placed (once; in the order the pairs first need them)."""
        if (k, m) not in placed:
            s = shapes[k][m]
            key = s.key()
            if key not in local:
                local[key] = _local(s)
            placed[k, m] = _placed(s, pos[k].T, local[key])
        return placed[k, m]

    for i, j in zip(*(ix.tolist() for ix in np.nonzero(np.triu(near, 1)))):  # row-major: (i, j) order
        a, b = pos[i], pos[j]
        if np.linalg.norm(a.T[:3, 3] - b.T[:3, 3]) > radii[i] + radii[j] + tol:
            continue  # bounding spheres apart
        depth = max((_depth(at(i, m), at(j, n), True) for m in range(len(shapes[i])) for n in range(len(shapes[j]))),
                    default=0.0)
        if depth > tol:
            yield KBError(cell.file, _position_key(cell, a),
                          f"expected a part clear of {b.obj} at {b.name}, "
                          f"not overlapping it by {_fmt(depth, u)}")
