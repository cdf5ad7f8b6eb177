"""One collision scene per run: the arm's links, the gripper, the held part, the parts, the
obstacles and the table; "is this joint vector clear by the margin", the clearance and the
closest pair.

What is in the scene (:func:`scene_for`, built once per cell and kept by its world.run.CellCache):

- the robot's link shapes (robot file ``collision: links``): capsules, cylinders and boxes,
  each fixed to one of Craig's frames 0..6 (0 is the base: it does not move);
- the gripper (robot file ``gripper:``, :class:`~spar_py.world.robot.Gripper`): the
  palm and two fingers whose contact faces are the grasp's width apart (the open
  finger_separation when no part is in the hand), and the tool body "tool" from the palm back to
  the flange (``gripper: body``; by default, for a robot without ``collision:``, a box the palm's
  size), which counts as the gripper wherever the gripper does;
- the parts (each object's ``shape:`` solids: boxes, z-cylinders; a mesh part: its mesh, as
  its convex hull where that is the mesh within HULL_EXCESS_MM, else as its triangles, bounded
  by the hull either way), placed by :meth:`CollisionScene.at`;
- the obstacles (problem file ``obstacles:``), and the table: the half-space z < 0 over its
  extent (problem file ``table:``; the whole plane when not given).

Which pairs are checked, and with which margin (``margin``: robot file ``collision: margin``,
problem file ``clearance:``, else DEFAULT_MARGIN_MM):

- every moving body (links 1..6, palm, fingers, tool body, held part) against the table, the obstacles
  and every part in the world, by the margin;
- links against links whose frames are two or more apart (self-collision of non-adjacent
  links), the gripper against links 0..5 and the held part against links 0..6, by the margin;
  the robot file's ``collision: allow`` pairs are never checked (bodies that touch by design);
- the gripper and the part in the hand (``grasped``: the part the fingers are closing on, or
  ``held``): not by distance but by the grasp rule, :meth:`SceneState.grasp_ok`: no finger may
  enter the part beyond its contact face, and the palm may not enter it (contact allowed,
  within GRASP_TOL_MM); the part is checked against the links like any other;
- ``allow`` pairs of :meth:`CollisionScene.at`: the step's own contacts, e.g. the held part and
  the part it is inserted into at an assemble, the held part and the table at a put-down.

How: every body has a bounding capsule in its frame (exact for capsules). One vectorised numpy
pass gives each (row, pair) cell's capsule distance, a lower bound of its true distance, and each
body's height over the table. Only the cells within the margin, not both capsules, and not put
beyond it by a second bound (:func:`support_gap`, the separating-axis bound) go to the collision
library. The grasp rule is decided once per grasp and kept in the cell's cache. The closest pair
of a clear row (:meth:`SceneState.clearance`) is sought among the pairs whose bounding spheres
come within the table's distance, in order of their capsule bounds.

The library: python-fcl, imported on first use (the choice: bench/RESULTS.md). Its signed
distance can abort the process on touching shapes, so it is never asked for: a near pair is
tested with ``collide`` (clearance 0) and only a separated pair measured with ``distance``.

Frames and units: world Z up, table top z = 0; all lengths in the cell's unit (the robot is
loaded in it); joint vectors in radians; a body's pose is its frame's world pose times its
fixed local transform.
"""
from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field, replace
from functools import cached_property
from typing import TYPE_CHECKING, Any

import numpy as np

from spar_py.core.errors import SparValueError
from spar_py.core.units import from_mm
from spar_py.world.robot import TOOL_BODY, Gripper, gripper_for

if TYPE_CHECKING:
    from spar_py.core.model import Cell, Solid
    from spar_py.world.robot import Robot

__all__ = ["CollisionScene", "DEFAULT_MARGIN_MM", "Obstacle", "SceneState", "scene_for", "segment_distance",
           "solids_key"]

#: The clearance margin when neither the robot nor the problem file gives one: 2 mm.
DEFAULT_MARGIN_MM = 2.0
#: A part's lowest vertex this near a support's top rests on it (mm; world.reach.supports' tolerance).
REST_TOL_MM = 0.5
#: Contact between the fingers (or palm) and the part in the hand: allowed up to this overlap
#: (rounding, not geometry): 0.05 mm.
GRASP_TOL_MM = 0.05
#: Sides of the polygon circumscribed about a cylinder (its vertices for the table test and
#: the hull a cylinder obstacle or part is given to the library as): the polygon contains
#: the cylinder, so a clearance is never overstated.
CYL_SIDES = 16
#: A mesh part collides as its convex hull where the hull is the mesh within this on average
#: (mm: the volume between them over the hull's area), else as its mesh: 0.05 mm.
HULL_EXCESS_MM = 0.05
#: Frame index of the tool (gripper, held part) and of the world (parts, obstacles).
TOOL, WORLD = 7, -1
#: Bounds of the cell cache's tables: the grasp rule per (part, grasp pose, width); the checked
#: pairs per arrangement of body names (a state's bodies, allowed contacts, attached parts).
GRASP_LIMIT = 4096
PAIRS_LIMIT = 256
#: Bound of the cell cache's table of whole pair structures (_pair_structure's answers, by the
#: head's key and the world's body names: some kB each, up to some 100 kB for a generated
#: cell of hundreds of part bodies).
STRUCTURES_LIMIT = 256
#: Bound of the cell cache's table of placed part bodies per (part, frame, pose): phase 2 places
#: every part on the table at every step, most of them where they were at the step before.
PLACED_LIMIT = 2048
#: The gripper's bodies (robots.py's palm and finger boxes and the tool body behind the palm),
#: checked against the part it closes on by the grasp rule, not by a pair.
_GRIPPER_NAMES = frozenset({"palm", "finger_l", "finger_r", TOOL_BODY})


# --------------------------------------------------------------------------- bodies


@dataclass(frozen=True, eq=False)
class Body:
    """A collision body fixed to ``frame`` (0..6 Craig's link frames, TOOL, WORLD).

    ``kind`` "capsule" (``size`` = (radius, half length) along the local z axis of ``T``),
    "cylinder" (same), "box" (``size`` = half extents along ``T``'s axes), "convex"
    (``points`` its vertices) or "mesh" (a mesh part: ``points`` its convex hull's vertices, which
    every bound uses, a sound one since the mesh is inside its hull; ``mesh`` = (the part's
    world.parts.mesh.Geometry, whose mesh the library is given, and HULL_EXCESS_MM in the cell unit:
    :func:`_mesh_geometry`)); ``T`` the
    shape's pose in the frame (4x4); ``points`` (k, 3) vertices in the frame (a capsule's: its two
    segment ends; a cylinder's: its circumscribed prism's); ``cap`` the bounding capsule (a, b, r)
    in the frame."""

    name: str
    frame: int
    kind: str
    T: np.ndarray
    size: tuple[float, ...]
    points: np.ndarray
    cap: tuple[np.ndarray, np.ndarray, float]
    _fcl: list = field(default_factory=list, repr=False)
    mesh: Any = field(default=None, repr=False)
    #: A body of many vertices (over BOX_FIRST): the 8 corners (k, 3, frame coordinates) of a box
    #: holding them, which the support bound tries first (:meth:`SceneState._support_bounds`).
    corners: np.ndarray | None = field(default=None, repr=False)

    @cached_property
    def extent(self) -> float:
        """The largest distance from the frame origin of a vertex or a box corner (frame
        coordinates): the support bound's rounding allowance scales with it."""
        pts = self.points if self.corners is None else np.concatenate([self.points, self.corners])
        return float(np.sqrt((pts * pts).sum(axis=1)).max())

    @property
    def radius(self) -> float:
        """What the table test subtracts from the lowest vertex (a capsule's radius, else 0)."""
        return self.size[0] if self.kind == "capsule" else 0.0

    def placed(self, T_frame: np.ndarray, frame: int, name: str | None = None) -> "Body":
        """This body moved by ``T_frame`` (4x4) into ``frame`` (a part placed in the world or the tool)."""
        T_frame = np.asarray(T_frame, float)
        R, t = T_frame[:3, :3], T_frame[:3, 3]
        a, b, r = self.cap
        return Body(name or self.name, frame, self.kind, T_frame @ self.T, self.size, self.points @ R.T + t,
                    (R @ a + t, R @ b + t, r), self._fcl, self.mesh,
                    None if self.corners is None else self.corners @ R.T + t)

    def fcl_geometry(self) -> Any:
        """The body's python-fcl geometry (made on first use, shared by the placed copies)."""
        if not self._fcl:
            import fcl  # lazily: most checks never reach the library

            if self.kind == "box":
                g = fcl.Box(*(2 * np.asarray(self.size)))
            elif self.kind == "capsule":
                g = fcl.Capsule(self.size[0], 2 * self.size[1])
            elif self.kind == "cylinder":  # the true cylinder (radius: the prism's inscribed one)
                g = fcl.Cylinder(self.size[0] * math.cos(math.pi / CYL_SIDES), 2 * self.size[1])
            else:  # convex, mesh: of the local vertices (a placed copy's are moved by T)
                Tinv = np.linalg.inv(self.T)
                local = self.points @ Tinv[:3, :3].T + Tinv[:3, 3]
                g = _mesh_geometry(self.mesh, local) if self.kind == "mesh" else _fcl_convex(local)
            self._fcl.append(g)
        return self._fcl[0]


def _bounding_capsule(points: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    """A capsule containing ``points`` (k, 3): the segment over their extent along their
    principal axis, the radius their largest distance from it."""
    c = points.mean(axis=0)
    P = points - c
    if len(points) < 2 or not np.any(P):
        return c.copy(), c.copy(), 0.0
    _, _, Vt = np.linalg.svd(P, full_matrices=False)
    u = Vt[0]
    s = P @ u
    perp = P - s[:, None] * u
    return c + s.min() * u, c + s.max() * u, float(np.sqrt((perp ** 2).sum(axis=1).max()))


def _frame_of_axis(a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, float]:
    """The pose (4x4) with origin mid-way a-b and z along a -> b, and the half length."""
    a, b = np.asarray(a, float), np.asarray(b, float)
    d = b - a
    h = float(np.linalg.norm(d)) / 2
    z = d / (2 * h) if h > 0 else np.array([0.0, 0.0, 1.0])
    x = np.cross(z, [1.0, 0.0, 0.0] if abs(z[0]) < 0.9 else [0.0, 1.0, 0.0])
    x /= np.linalg.norm(x)
    T = np.eye(4)
    T[:3, 0], T[:3, 1], T[:3, 2], T[:3, 3] = x, np.cross(z, x), z, (a + b) / 2
    return T, h


def capsule(name: str, frame: int, a: np.ndarray, b: np.ndarray, radius: float) -> Body:
    """A capsule: the points within ``radius`` of the segment a-b (frame coordinates)."""
    T, h = _frame_of_axis(a, b)
    a, b = np.asarray(a, float), np.asarray(b, float)
    return Body(name, frame, "capsule", T, (float(radius), h), np.stack([a, b]), (a, b, float(radius)))


def cylinder(name: str, frame: int, a: np.ndarray, b: np.ndarray, radius: float) -> Body:
    """A solid cylinder of axis a-b and ``radius``, held as its circumscribed CYL_SIDES-prism."""
    T, h = _frame_of_axis(a, b)
    k = np.arange(CYL_SIDES) * 2 * math.pi / CYL_SIDES
    R = radius / math.cos(math.pi / CYL_SIDES)
    ring = np.stack([R * np.cos(k), R * np.sin(k)], axis=1)
    local = np.concatenate([np.column_stack([ring, np.full(CYL_SIDES, z)]) for z in (-h, h)])
    pts = local @ T[:3, :3].T + T[:3, 3]
    return Body(name, frame, "cylinder", T, (float(R), h), pts,
                (T[:3, 3] - h * T[:3, 2], T[:3, 3] + h * T[:3, 2], float(R)))


def box(name: str, frame: int, lo: np.ndarray, hi: np.ndarray, T: np.ndarray | None = None) -> Body:
    """An axis-aligned box lo..hi in the coordinates of ``T`` (default the frame's own)."""
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    if np.any(hi < lo):
        raise SparValueError(f"box {name}: max below min")
    Tc = np.eye(4) if T is None else np.asarray(T, float).copy()
    c = (lo + hi) / 2
    Tc = Tc @ np.block([[np.eye(3), c[:, None]], [np.zeros((1, 3)), np.ones((1, 1))]])
    half = (hi - lo) / 2
    corners = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)]) * half
    pts = corners @ Tc[:3, :3].T + Tc[:3, 3]
    i = int(np.argmax(half))
    axis = Tc[:3, i]
    r = float(np.sqrt((half ** 2).sum() - half[i] ** 2))
    return Body(name, frame, "box", Tc, tuple(float(v) for v in half), pts,
                (Tc[:3, 3] - half[i] * axis, Tc[:3, 3] + half[i] * axis, r))


def convex(name: str, frame: int, points: np.ndarray) -> Body:
    """The convex hull of ``points`` (k, 3), frame coordinates."""
    pts = np.asarray(points, float).reshape(-1, 3)
    if len(pts) < 4:
        raise SparValueError(f"convex body {name}: needs at least 4 points")
    return Body(name, frame, "convex", np.eye(4), (), pts, _bounding_capsule(pts),
                corners=_box_corners(pts) if len(pts) > BOX_FIRST else None)


def _box_corners(pts: np.ndarray) -> np.ndarray:
    """(8, 3) the corners of a box holding ``pts`` (k, 3): along their principal axes, so a plate
    or a rod gets a thin box, widened by a rounding allowance."""
    c = pts.mean(axis=0)
    _, vecs = np.linalg.eigh(np.cov((pts - c).T))
    local = (pts - c) @ vecs
    pad = 1e-9 * (1.0 + float(np.abs(pts).max()))
    lo, hi = local.min(axis=0) - pad, local.max(axis=0) + pad
    signs = np.array([[i >> 2 & 1, i >> 1 & 1, i & 1] for i in range(8)], dtype=bool)
    return np.where(signs, hi, lo) @ vecs.T + c


def _fcl_convex(points: np.ndarray) -> Any:
    import fcl  # ~0.15 s at import: see Body.fcl_geometry
    from scipy.spatial import ConvexHull  # ~0.7 s at import: only a convex body reaching the library

    hull = ConvexHull(points)
    verts = points[hull.vertices]
    index = {int(v): i for i, v in enumerate(hull.vertices)}
    faces = np.array([[3, index[int(a)], index[int(b)], index[int(c)]] for a, b, c in hull.simplices])
    return fcl.Convex(verts, len(faces), faces.ravel())


def mesh_body(name: str, frame: int, hull: np.ndarray, geometry: Any, unit: str) -> Body:
    """A mesh part's body: bounded by its convex hull ``hull`` (k, 3) (frame coordinates, the
    object frame), colliding as the mesh of ``geometry`` (world.parts.mesh.Geometry, read on first
    use: :func:`_mesh_geometry`); ``unit`` the cell's length unit."""
    body = convex(name, frame, hull)
    return replace(body, kind="mesh", mesh=(geometry, from_mm(unit, HULL_EXCESS_MM)))


def _mesh_geometry(mesh_of: tuple[Any, float], hull: np.ndarray) -> Any:
    """The library's geometry of a mesh body (its ``mesh`` field; ``hull`` its hull's vertices in
    the body's own frame, the object frame): its convex hull where the hull is the mesh within
    HULL_EXCESS_MM (a convex part: the cheaper exact shape), else the mesh's triangles as a
    python-fcl BVHModel (a concave part: a half-shell's hull would cover its recesses). The BVH
    is a surface: :func:`body_distance` adds the containment test for a body wholly inside it."""
    mesh = mesh_of[0].mesh()
    if _hull_is_mesh(mesh, hull, mesh_of[1]):
        return _fcl_convex(hull)
    return bvh(np.asarray(mesh.vertices, float), np.asarray(mesh.faces, int))


def bvh(V: np.ndarray, F: np.ndarray) -> Any:
    """Triangles (vertices V (n, 3), faces F (m, 3) indices into V) as a python-fcl BVHModel: a
    surface, in the frame V is given in (the one home of this build: the collision scene's
    concave bodies, the assembly's sweeps, the grasp derivation's finger test)."""
    import fcl  # ~0.15 s at import: see Body.fcl_geometry

    model = fcl.BVHModel()
    model.beginModel(len(V), len(F))
    model.addSubModel(np.asarray(V, float), np.asarray(F, np.int64))
    model.endModel()
    return model


def _hull_is_mesh(mesh: Any, hull: np.ndarray, excess: float) -> bool:
    """Whether the convex hull of ``hull`` (the mesh's hull vertices) is the closed ``mesh``
    within ``excess`` (cell unit) on average: the volume between them at most that times the hull's area
    (a recess of any depth a finger or a part could enter exceeds it). A mesh that is not closed
    has no volume to compare: its hull stays (the grasp rule still tests its mesh)."""
    from scipy.spatial import ConvexHull  # ~0.7 s at import: see _fcl_convex

    if not mesh.is_watertight:
        return True
    h = ConvexHull(hull)
    return float(h.volume) - abs(float(mesh.volume)) <= excess * float(h.area)


def solid_bodies(name: str, solids: Iterable[Solid]) -> list[Body]:
    """The bodies of an object's ``shape:`` solids (object frame, frame WORLD until placed)."""
    out = []
    for s in solids:
        if s.kind == "box":
            out.append(box(name, WORLD, s.lo, s.hi))
        elif s.kind == "cylinder":
            out.append(cylinder(name, WORLD, [0, 0, s.lo[2]], [0, 0, s.hi[2]], s.radius))
        else:
            out.append(convex(name, WORLD, s.points))
    return out


class Placed(list):
    """A list of bodies (read-only by convention) whose columns a scene state reads
    (:meth:`columns`) are made once, on first use."""

    _columns: tuple | None = None

    def columns(self) -> tuple:
        """(cap_a, cap_b (k, 3) the bounding capsules' ends in the bodies' frames, cap_r (k,) their
        radii, names, frames (k,), is_cap (k,): capsules), made on the first call."""
        if self._columns is None:
            self._columns = _body_columns(self)
        return self._columns


def _body_columns(bodies: list[Body]) -> tuple:
    """The :meth:`Placed.columns` of ``bodies``."""
    return (np.array([b.cap[0] for b in bodies], dtype=float).reshape(-1, 3),
            np.array([b.cap[1] for b in bodies], dtype=float).reshape(-1, 3),
            np.array([b.cap[2] for b in bodies], dtype=float), [b.name for b in bodies],
            np.array([b.frame for b in bodies], dtype=int), np.array([b.kind == "capsule" for b in bodies], dtype=bool))


def _columns(groups: list[Placed]) -> tuple:
    """The columns of :class:`Placed` groups end to end (:meth:`Placed.columns`)."""
    return _joined([g.columns() for g in groups])


def _joined(cols: list[tuple]) -> tuple:
    """Column tuples (:func:`_body_columns`) of body lists, as one of their concatenation."""
    if not cols:
        return _body_columns([])
    return (np.concatenate([c[0] for c in cols]), np.concatenate([c[1] for c in cols]),
            np.concatenate([c[2] for c in cols]), [n for c in cols for n in c[3]],
            np.concatenate([c[4] for c in cols]), np.concatenate([c[5] for c in cols]))


@dataclass(frozen=True)
class Obstacle:
    """A named obstacle of the problem file: its bodies in the world frame (cell unit); a
    ``support`` (a nest, a riser, a fixture plate) is one parts may rest on (its top: world.reach.supports)."""

    name: str
    bodies: tuple[Body, ...]
    support: bool = False


# --------------------------------------------------------------------------- distances


#: Pairs up to which :func:`segment_distance` computes in Python floats: a few pairs (most
#: calls of one check or grasp test) cost tens of numpy calls' overhead each, where the
#: arithmetic itself is some 40 operations per pair.
FEW_SEGMENTS = 12


def segment_distance(p1: np.ndarray, q1: np.ndarray, p2: np.ndarray, q2: np.ndarray) -> np.ndarray:
    """(...,) distance between segments p1-q1 and p2-q2 (arrays (..., 3)), vectorised
    (Ericson, Real-Time Collision Detection, Sec. 5.1.9, every branch as np.where; clamps as
    np.minimum/np.maximum, the same values as np.clip at a fraction of its call overhead on
    the small arrays of one check). Up to :data:`FEW_SEGMENTS` pairs in Python floats
    (:func:`_segment_distance_few`: the same operations in the same order, so the same
    values to the bit)."""
    s1 = np.shape(p1)
    shape = (s1 if np.shape(q1) == s1 == np.shape(p2) == np.shape(q2)
             else np.broadcast_shapes(s1, np.shape(q1), np.shape(p2), np.shape(q2)))[:-1]
    if math.prod(shape) <= FEW_SEGMENTS:
        return _segment_distance_few(p1, q1, p2, q2, shape)
    d1, d2, r = q1 - p1, q2 - p2, p1 - p2
    a = (d1 * d1).sum(-1)
    e = (d2 * d2).sum(-1)
    f = (d2 * r).sum(-1)
    c = (d1 * r).sum(-1)
    b = (d1 * d2).sum(-1)
    eps = 1e-12
    lo, hi = np.maximum, np.minimum
    pa, pe = a > eps, e > eps
    a_, e_ = np.where(pa, a, 1.0), np.where(pe, e, 1.0)
    denom = a * e - b * b
    s = np.where(denom > eps * lo(a * e, eps), hi(lo((b * f - c * e) / np.where(denom > 0, denom, 1.0), 0.0), 1.0),
                 0.0)
    t = (b * s + f) / e_
    tc = hi(lo(t, 0.0), 1.0)
    s = np.where(t != tc, hi(lo((tc * b - c) / a_, 0.0), 1.0), s)
    t = tc
    # degenerate segments: a point on either side
    s = np.where(pa, np.where(pe, s, hi(lo(-c / a_, 0.0), 1.0)), 0.0)
    t = np.where(pe, np.where(pa, t, hi(lo(f / e_, 0.0), 1.0)), 0.0)
    diff = (p1 + d1 * s[..., None]) - (p2 + d2 * t[..., None])
    return np.sqrt((diff * diff).sum(-1))


def _segment_distance_few(p1: np.ndarray, q1: np.ndarray, p2: np.ndarray, q2: np.ndarray,
                          shape: tuple[int, ...]) -> np.ndarray:
    """:func:`segment_distance` of few pairs (broadcast to ``shape`` + (3,)), pair by pair in
    Python floats: each of its np.where branches as a conditional, each sum of three products
    added left to right as numpy adds them, np.maximum/np.minimum as max/min (NaN kept alike)."""
    full = (*shape, 3)
    rows = [np.broadcast_to(x, full).reshape(-1, 3).tolist() if np.shape(x) != full else x.reshape(-1, 3).tolist()
            for x in (np.asarray(p1, float), np.asarray(q1, float), np.asarray(p2, float), np.asarray(q2, float))]
    eps = 1e-12
    out = []
    for (p1x, p1y, p1z), (q1x, q1y, q1z), (p2x, p2y, p2z), (q2x, q2y, q2z) in zip(*rows):
        d1x, d1y, d1z = q1x - p1x, q1y - p1y, q1z - p1z
        d2x, d2y, d2z = q2x - p2x, q2y - p2y, q2z - p2z
        rx, ry, rz = p1x - p2x, p1y - p2y, p1z - p2z
        a = d1x * d1x + d1y * d1y + d1z * d1z
        e = d2x * d2x + d2y * d2y + d2z * d2z
        f = d2x * rx + d2y * ry + d2z * rz
        c = d1x * rx + d1y * ry + d1z * rz
        b = d1x * d2x + d1y * d2y + d1z * d2z
        pa, pe = a > eps, e > eps
        a_, e_ = (a if pa else 1.0), (e if pe else 1.0)
        denom = a * e - b * b
        s = min(max((b * f - c * e) / (denom if denom > 0 else 1.0), 0.0), 1.0) if denom > eps * max(a * e, eps) \
            else 0.0
        t = (b * s + f) / e_
        tc = min(max(t, 0.0), 1.0)
        if t != tc:
            s = min(max((tc * b - c) / a_, 0.0), 1.0)
        t = tc
        s = (s if pe else min(max(-c / a_, 0.0), 1.0)) if pa else 0.0
        t = (t if pa else min(max(f / e_, 0.0), 1.0)) if pe else 0.0
        dx = (p1x + d1x * s) - (p2x + d2x * t)
        dy = (p1y + d1y * s) - (p2y + d2y * t)
        dz = (p1z + d1z * s) - (p2z + d2z * t)
        out.append(math.sqrt(dx * dx + dy * dy + dz * dz))
    return np.array(out, dtype=float).reshape(shape)


def fcl_transform(T: np.ndarray) -> Any:
    import fcl  # ~0.15 s at import: see Body.fcl_geometry

    return fcl.Transform(np.ascontiguousarray(T[:3, :3]), np.ascontiguousarray(T[:3, 3]))


def body_distance(b1: Body, T1: np.ndarray, b2: Body, T2: np.ndarray) -> float:
    """The distance of two placed bodies (world poses T1, T2 of their frames): 0 when they
    touch or overlap (``collide`` first), else python-fcl's unsigned distance."""
    import fcl  # ~0.15 s at import: see Body.fcl_geometry

    g1, g2 = b1.fcl_geometry(), b2.fcl_geometry()
    o1 = fcl.CollisionObject(g1, fcl_transform(T1 @ b1.T))
    o2 = fcl.CollisionObject(g2, fcl_transform(T2 @ b2.T))
    if fcl.collide(o1, o2, fcl.CollisionRequest(), fcl.CollisionResult()):
        return 0.0
    # a mesh's BVH is its surface: a body wholly inside the mesh meets none of its triangles
    if isinstance(g2, fcl.BVHModel) and _inside_mesh(b1, T1, b2, T2):
        return 0.0
    if isinstance(g1, fcl.BVHModel) and _inside_mesh(b2, T2, b1, T1):
        return 0.0
    d = fcl.distance(o1, o2, fcl.DistanceRequest(), fcl.DistanceResult())
    return max(float(d), 0.0)


def _inside_mesh(b: Body, Tb: np.ndarray, m: Body, Tm: np.ndarray) -> bool:
    """Whether body ``b`` (its frame at world pose Tb), known to meet no triangle of mesh body
    ``m`` (frame at Tm), is inside the mesh: then all of it is, so one of its vertices decides
    (the mesh's containment test, asked only when the vertex is inside the mesh's bounding box)."""
    p = Tb[:3, :3] @ b.points[0] + Tb[:3, 3]
    Tw = Tm @ m.T
    local = Tw[:3, :3].T @ (p - Tw[:3, 3])
    mesh = m.mesh[0].mesh()
    lo, hi = mesh.bounds
    if np.any(local < lo) or np.any(local > hi):
        return False
    return bool(mesh.contains(local[None, :])[0])


#: A convex or mesh body with more vertices than this is first bounded by its box's corners
#: (:func:`_box_corners`); only the cells the box leaves within the margin project every vertex.
BOX_FIRST = 64


def support_gap(Pa: np.ndarray, ra: np.ndarray, Ua: np.ndarray, Pb: np.ndarray, rb: np.ndarray,
                Ub: np.ndarray) -> np.ndarray:
    """(c,) a lower bound of the distance (length unit of the inputs) between each of c pairs of
    convex bodies a and b, in one vectorised pass: the largest gap between their supports over
    16 unit directions u (each body's three axes, their nine cross products, the line between
    the vertices' means), less a rounding allowance of 1e-9 * (1 + the largest coordinate).

    ``Pa`` (c, ka, 3) a's vertices (world; a capsule's: the two ends of its segment; repeated
    vertices are fine), ``ra`` (c,) the radius they are swept by (a capsule's, else 0), ``Ua``
    (c, 3, 3) a's axes as columns (any rotation gives a sound bound; a box's face normals make
    it the separating-axis bound); the same for b. For convex sets the distance is at least
    min over b of u.y - max over a of u.x for every unit u (and with a and b swapped), so the
    answer never exceeds the distance: a pair it puts beyond the margin is clear by it.
    A non-positive answer says nothing (the bodies may touch)."""
    U, valid = support_directions(Ua, Ub, Pb.mean(axis=1) - Pa.mean(axis=1))
    pa = Pa @ np.swapaxes(U, 1, 2)                                  # (c, ka, 16)
    pb = Pb @ np.swapaxes(U, 1, 2)
    return _gap_of_extents(pa.min(axis=1), pa.max(axis=1), ra, np.abs(Pa).max(axis=(1, 2)),
                           pb.min(axis=1), pb.max(axis=1), rb, np.abs(Pb).max(axis=(1, 2)), valid)


def support_directions(Ua: np.ndarray, Ub: np.ndarray, line: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The 16 unit directions of :func:`support_gap` for c pairs, (c, 16, 3), and which are valid
    (c, 16) (non-zero before normalising): a's 3 axes, b's 3, their 9 cross products, ``line``
    (c, 3) (from a's vertices' mean to b's)."""
    A, B = np.swapaxes(Ua, 1, 2), np.swapaxes(Ub, 1, 2)            # (c, 3, 3) axes as rows
    c = len(A)
    U = np.empty((c, 16, 3))                                        # A's 3, B's 3, their 9 crosses, the line
    U[:, :3], U[:, 3:6] = A, B
    a0, a1, a2 = A[:, :, None, 0], A[:, :, None, 1], A[:, :, None, 2]   # (c, 3, 1)
    b0, b1, b2 = B[:, None, :, 0], B[:, None, :, 1], B[:, None, :, 2]   # (c, 1, 3)
    X = U[:, 6:15].reshape(c, 3, 3, 3)                              # a view: the crosses written in place
    X[..., 0] = a1 * b2 - a2 * b1
    X[..., 1] = a2 * b0 - a0 * b2
    X[..., 2] = a0 * b1 - a1 * b0
    U[:, 15] = line
    norm = np.sqrt((U * U).sum(-1))
    valid = norm > 1e-12
    return U / np.where(valid, norm, 1.0)[..., None], valid


def _gap_of_extents(alo: np.ndarray, ahi: np.ndarray, ra: np.ndarray, abig: np.ndarray, blo: np.ndarray,
                    bhi: np.ndarray, rb: np.ndarray, bbig: np.ndarray, valid: np.ndarray) -> np.ndarray:
    """:func:`support_gap` from each body's extent along each direction ((c, 16) min and max), the
    radii (c,), a bound of each body's largest coordinate (c,) for the rounding allowance, and
    the directions' validity (c, 16)."""
    gap = np.maximum(blo - ahi, alo - bhi)
    best = np.where(valid, gap, -np.inf).max(axis=1) - ra - rb
    scale = np.maximum(abig, bbig) + np.maximum(ra, rb)
    return best - 1e-9 * (1.0 + scale)


# --------------------------------------------------------------------------- the scene


def _over(P: np.ndarray, r: float, ext: tuple[float, float, float, float]) -> np.ndarray:
    """(n,) whether each row's body (vertices ``P`` (n, k, 3), world, swept by radius ``r``)
    reaches over the table's footprint ``ext`` = (x0, x1, y0, y1) in x and in y."""
    x0, x1, y0, y1 = ext
    return ((P[..., 0].max(axis=1) + r >= x0) & (P[..., 0].min(axis=1) - r <= x1)
            & (P[..., 1].max(axis=1) + r >= y0) & (P[..., 1].min(axis=1) - r <= y1))


def _slab_directions(n_az: int = 32, n_el: int = 9) -> np.ndarray:
    """Unit vectors (k, 3) with z >= 0: ``n_az`` azimuths at ``n_el`` elevations 0..90 deg."""
    az = np.linspace(0.0, 2.0 * np.pi, n_az, endpoint=False)
    el = np.linspace(0.0, 0.5 * np.pi, n_el)[:-1]
    U = np.stack([np.outer(np.cos(el), np.cos(az)).ravel(), np.outer(np.cos(el), np.sin(az)).ravel(),
                  np.repeat(np.sin(el), n_az)], axis=1)
    U[np.abs(U) < 1e-12] = 0.0
    return np.vstack([U, [0.0, 0.0, 1.0]])


_SLAB_U = _slab_directions()


def _slab_gap(P: np.ndarray, r: float, ext: tuple[float, float, float, float]) -> np.ndarray:
    """(n,) a lower bound of each row's body's distance (cell unit) to the table's slab (the
    footprint ``ext`` = (x0, x1, y0, y1) from the top z = 0 down), for bodies beside its edge:
    for convex sets the distance is the largest gap between their supports over unit directions
    u, here the best of :data:`_SLAB_U` (never above the distance, so never too optimistic).
    ``P`` (n, k, 3) are the bodies' world vertices, ``r`` their sweep radius."""
    x0, x1, y0, y1 = ext
    U = _SLAB_U
    support = np.where(U[:, 0] > 0, x1, x0) * U[:, 0] + np.where(U[:, 1] > 0, y1, y0) * U[:, 1]
    return ((P @ U.T).min(axis=1) - support).max(axis=1) - r


class CollisionScene:
    """The run's collision world: link and gripper shapes, part shapes, obstacles, the table,
    the clearance ``margin`` (cell unit). Place the parts with :meth:`at`."""

    def __init__(self, robot: Robot, gripper: Gripper, parts: Mapping[str, list[Body]],
                 obstacles: Iterable[Obstacle], margin: float, table: tuple[float, float, float, float] | None,
                 unit: str, memo: Any = None, meshes: Mapping[str, Any] | None = None) -> None:
        """``meshes``: {model: world.parts.mesh.Geometry} of the mesh parts (``parts`` bodies of kind
        "mesh", or convex hulls where made by hand); the grasp rule tests the gripper against the
        mesh itself."""
        self.robot = robot
        self.meshes = dict(meshes or {})
        self._mesh_fcl: dict[str, Any] = {}  # by model: bounded by the cell's parts
        self.gripper = gripper
        self.parts = dict(parts)
        self.obstacles = tuple(obstacles)
        self.margin = float(margin)
        #: the table's extent (x0, x1, y0, y1) or None: the whole plane
        self.table = table
        self.unit = unit
        self.tol = from_mm(unit, GRASP_TOL_MM)
        self.memo = memo
        self.links = [_link_body(s) for s in robot.links]
        self.allowed = frozenset(frozenset(p) for p in robot.allowed)
        self._grippers: dict = {}  # bounded by the cell's grasp widths
        self._slab: Body | None = None
        self._obstacle_bodies: Placed | None = None  # made on first use by at()
        self._shape_keys: dict[str, tuple] = {}  # by model name: bounded by the cell's parts
        self.stats = {"pairs": 0, "exact": 0}

    def slab(self) -> Body:
        """The table of a table with an extent as a box (world): its footprint, from the top
        z = 0 down as deep as the footprint is wide (for exact distances beside its edge)."""
        if self._slab is None:
            x0, x1, y0, y1 = self.table
            depth = max(x1 - x0, y1 - y0, 1.0)
            self._slab = box("table", WORLD, np.array([x0, y0, -depth]), np.array([x1, y1, 0.0]))
        return self._slab

    def resting_on(self, part: str, T: np.ndarray) -> list[str]:
        """The supports (obstacles marked ``support``) ``part`` at world pose T (4x4) rests on:
        its lowest vertex within REST_TOL_MM of a support's highest and their footprints' boxes
        overlapping. A part lifted straight up off such a support, or set straight down onto
        it, touches it by design (as the table): callers allow that pair."""
        tol = from_mm(self.unit, REST_TOL_MM)
        P = np.concatenate([b.points for b in self.placed(part, T, WORLD)])
        low, lo, hi = P[:, 2].min(), P[:, :2].min(axis=0), P[:, :2].max(axis=0)
        out = []
        for o in self.obstacles:
            if not o.support:
                continue
            Q = np.concatenate([b.points for b in o.bodies])
            over = np.all(Q[:, :2].min(axis=0) <= hi) and np.all(lo <= Q[:, :2].max(axis=0))
            if over and abs(Q[:, 2].max() - low) <= tol:
                out.append(o.name)
        return out

    def gripper_bodies(self, width: float | None) -> list[Body]:
        """The palm and fingers (TOOL frame) with the fingers' contact faces ``width`` apart (default
        open), and the tool body behind the palm when the gripper has one (body "tool"), made once
        per width (a handful of widths per cell)."""
        key = None if width is None else round(float(width), 9)
        if key not in self._grippers:
            self._grippers[key] = ([box(n, TOOL, lo, hi) for n, lo, hi in self.gripper.boxes(width)]
                                   + self._tool_body(0.0))
        return self._grippers[key]

    def shrunk_gripper(self, width: float | None, tol: float) -> list[Body]:
        """The palm, fingers and tool body as :meth:`gripper_bodies`, each shrunk by ``tol`` on every
        side (the grasp rule's: touching counts as clear), made once per width and tolerance."""
        key = ("shrunk", None if width is None else round(float(width), 9), round(float(tol), 12))
        if key not in self._grippers:
            self._grippers[key] = ([box(n, TOOL, lo + tol, hi - tol) for n, lo, hi in self.gripper.boxes(width)]
                                   + self._tool_body(tol))
        return self._grippers[key]

    def enters_mesh(self, part: str, g: Body, T_tool_part: np.ndarray) -> bool:
        """Whether gripper body ``g`` (TOOL frame) meets ``part`` at T_tool_part (4x4): its mesh's
        surface (python-fcl's BVH against the body) or, wholly inside it, the body's centre in the
        mesh; True for a part without a mesh (its bodies are exact)."""
        import fcl  # ~0.15 s at import: see Body.fcl_geometry

        model = part.split("@", 1)[0]
        geo = self.meshes.get(model)
        if geo is None:
            return True
        mesh = geo.mesh()
        bvh = self._mesh_fcl.get(model)
        if bvh is None:
            V, F = np.asarray(mesh.vertices, float), np.asarray(mesh.faces, int)
            bvh = self._mesh_fcl[model] = fcl.BVHModel()
            bvh.beginModel(len(V), len(F))
            bvh.addSubModel(V, F)
            bvh.endModel()
        o1 = fcl.CollisionObject(g.fcl_geometry(), fcl_transform(g.T))
        o2 = fcl.CollisionObject(bvh, fcl_transform(np.asarray(T_tool_part, float)))
        if fcl.collide(o1, o2, fcl.CollisionRequest(), fcl.CollisionResult()):
            return True
        centre = np.linalg.inv(np.asarray(T_tool_part, float)) @ np.append(g.T[:3, 3], 1.0)
        return bool(mesh.contains(centre[None, :3])[0])

    def _tool_body(self, shrink: float) -> list[Body]:
        """The gripper's tool body (world.robot.Gripper.body_shape) as a body in the TOOL frame,
        shrunk by ``shrink`` on every side; [] without one."""
        shape = self.gripper.body_shape()
        if shape is None:
            return []
        name, kind, a, b, r = shape
        if kind == "cylinder":
            u = (b - a) / np.linalg.norm(b - a)
            return [cylinder(name, TOOL, a + shrink * u, b - shrink * u, r - shrink)]
        return [box(name, TOOL, a + shrink, b - shrink)]

    def shapes_of(self, part: str) -> list[Body]:
        """The bodies of ``part`` (an object, or a stock part ``obj@pos``) in its object frame."""
        model = part.split("@", 1)[0]
        if model not in self.parts:
            raise SparValueError(f"no shape known for part {part!r}")
        return self.parts[model]

    def shape_key(self, part: str) -> tuple:
        """The collision geometry of ``part`` (:meth:`shapes_of`: each body's kind, size, pose in
        the object frame and vertices, exactly), not its name: equal for renamed copies of one
        model, so answers that depend on the geometry alone can be shared by them."""
        model = part.split("@", 1)[0]
        key = self._shape_keys.get(model)
        if key is None:
            key = self._shape_keys[model] = tuple(
                (b.kind, np.asarray(b.size, float).tobytes(), np.ascontiguousarray(b.T, float).tobytes(),
                 np.ascontiguousarray(b.points, float).tobytes()) for b in self.shapes_of(part))
        return key

    def placed(self, part: str, T: np.ndarray, frame: int, name: str | None = None) -> Placed:
        """The bodies of ``part`` (:meth:`shapes_of`) moved by T (4x4, the part's pose in
        ``frame``: the world or the tool) and named ``name`` (default the part's), memoised on
        the cell by (part, name, frame, pose): the same Body objects each time (read-only)."""
        T = np.ascontiguousarray(T, dtype=float)
        label = part if name is None else name

        def place() -> Placed:
            return Placed(b.placed(T, frame, label) for b in self.shapes_of(part))

        if self.memo is None:
            return place()
        table = self.memo.table("collision.placed", PLACED_LIMIT)
        return table.get_or_compute((part, label, frame, T.tobytes()), place)

    def at(self, parts: Mapping[str, np.ndarray], held: tuple[str, np.ndarray] | None = None,
           grasped: str | None = None, *, width: float | None = None,
           allow: Iterable[tuple[str, str]] = (), attached: Mapping[str, np.ndarray] | None = None,
           carried: Mapping[str, np.ndarray] | None = None, touch: Iterable[str] = ()) -> SceneState:
        """The world at one point of a plan: ``parts`` = {name: T_world_part 4x4} for every part
        on the table or assembled; ``held`` = (name, T_tool_part) for the part in the hand (it
        moves with the gripper, body name "held:<name>"); ``grasped`` = the part the fingers are
        closing on (its contact with the fingers' contact faces is allowed: the grasp rule).

        Added: ``width`` the fingers' contact faces' distance (cell unit; default the open
        finger separation, or with a part in the hand the rule's own); ``allow`` pairs of body
        names not checked at this point (the step's own contacts: ("held:peg", "block") at an
        assemble, ("held:peg", "table") at a put-down); ``attached`` = {name: T_tool_part}
        parts that are where the tool is (a batch of tool poses with one relative geometry,
        e.g. the part being grasped at every candidate placement), checked as ``parts``;
        ``carried`` = {name: T_tool_part} the parts mated into the held part (a subassembly in
        the hand: one rigid body), bodies "held:<name>" moving with the tool and checked as the
        held part is, except against the gripper (by distance: the fingers may not touch a part
        they do not hold) and against each other (their contacts are the mates'; the caller
        allows none of them: at() does, and gives each carried part the contacts ``allow`` gives
        the held part). ``touch``: bodies checked against the table for contact only, not by the
        margin, up to GRASP_TOL_MM of rounding (a part the product seats on the table or within
        the margin of it: a post's end flush with the bottom of the bar it stands in)."""
        held_name = held[0] if held is not None else None
        if carried and held_name is not None:
            allow = _body_allow(held_name, list(carried), list(allow))
        if self._obstacle_bodies is None:
            self._obstacle_bodies = Placed(b for o in self.obstacles for b in o.bodies)
        groups: list[Placed] = [self._obstacle_bodies]
        table = self.memo.table("collision.placed", PLACED_LIMIT) if self.memo is not None else None
        for name, T in parts.items():  # placed() inlined: the table looked up once, a hit read directly
            if name == held_name or carried and name in carried:
                continue
            T = np.ascontiguousarray(T, dtype=float)
            g = table.get((name, name, WORLD, T.tobytes())) if table is not None else None
            groups.append(g if g is not None else self.placed(name, T, WORLD))
        world: list[Body] = [b for g in groups for b in g]
        tool: list[Body] = []
        for name, T in (attached or {}).items():
            tool += self.placed(name, T, TOOL)
        if held is not None:
            tool += self.placed(held[0], held[1], TOOL, f"held:{held[0]}")
        for name, T in (carried or {}).items():
            tool += self.placed(name, np.ascontiguousarray(T, dtype=float), TOOL, f"held:{name}")
        hand = None
        if held is not None:
            hand = (held[0], "tool", np.asarray(held[1], float))
        elif grasped is not None:
            if attached and grasped in attached:
                hand = (grasped, "tool", np.asarray(attached[grasped], float))
            elif grasped in parts:
                hand = (grasped, "world", np.asarray(parts[grasped], float))
            else:
                raise SparValueError(f"grasped part {grasped!r} is neither in parts nor attached")
        state = SceneState(self, world, tool, hand, width, frozenset(frozenset(p) for p in allow),
                           frozenset(attached or ()), _columns(groups))
        touch = frozenset(touch)
        if touch:
            state.table_touch = np.array([state.bodies[i].name in touch for i in state.table_bodies.tolist()],
                                         dtype=bool)
        return state


def _body_allow(root: str, carried: list[str], allow: list[tuple[str, str]]) -> list[tuple[str, str]]:
    """``allow`` for a held body (``root`` in the hand carrying ``carried``): its parts' contacts
    with each other (their mates') and, for each carried part, the contacts allowed to the root."""
    mine = f"held:{root}"
    out = list(allow)
    for a, b in allow:
        other = b if a == mine else a if b == mine else None
        if other is not None:
            out += [(f"held:{c}", other) for c in carried]
    names = [mine, *(f"held:{c}" for c in carried)]
    out += [(x, y) for i, x in enumerate(names) for y in names[i + 1:]]
    return out


def _link_body(s: Any) -> Body:
    if s.kind == "capsule":
        return capsule(s.name, s.frame, s.a, s.b, s.radius)
    if s.kind == "cylinder":
        return cylinder(s.name, s.frame, s.a, s.b, s.radius)
    if s.kind == "hull":
        return convex(s.name, s.frame, s.points)
    return box(s.name, s.frame, s.a, s.b)


class SceneState:
    """The scene with its parts placed: answers "clear?" and "how clear?" for joint vectors."""

    def __init__(self, scene: CollisionScene, world: list[Body], tool: list[Body],
                 hand: tuple[str, str, np.ndarray] | None, width: float | None, allow: frozenset,
                 attached: frozenset = frozenset(), world_columns: tuple | None = None) -> None:
        """``world_columns``: the :func:`_columns` of ``world`` when the caller has them (at())."""
        self.scene = scene
        self.hand = hand  # (part, "tool" | "world", its pose there) for the grasp rule
        self.width = width
        gripper = scene.gripper_bodies(width)
        links = scene.links
        static = [b for b in links if b.frame == 0]
        moving = [b for b in links if b.frame != 0] + gripper + tool
        self.bodies = moving + static + world
        self.n_moving = len(moving)
        hand_part = hand[0] if hand is not None else None
        wc = _body_columns(world) if world_columns is None else world_columns
        cap_a, cap_b, cap_r, names, frames, is_cap = _joined([_body_columns(moving + static), wc])
        struct = _pair_structure(scene, self.bodies, len(moving), hand_part, allow, attached,
                                 columns=(names, frames, is_cap))
        self.pairs, self.table_bodies, self.exact_pair, rigid = struct
        self._rigid: dict[int, float | None] = dict.fromkeys(rigid)
        self._is_rigid = np.zeros(len(self.pairs), dtype=bool)
        self._is_rigid[list(rigid)] = True
        # the library's distances of the last check(), by (pair, that row's frames): clearance()
        # of a row check() measured reads them instead of asking the library again
        self._measured: dict[tuple[int, bytes], float] = {}
        self._refusal: tuple[tuple[str, str] | None] | None = None  # tool_rigid_refusal's answer
        self._cap_a, self._cap_b, self._cap_r = cap_a, cap_b, cap_r
        # the broad phase of check(): each body's bounding sphere radius (its centre: the
        # middle of its capsule's axis)
        self._sph_r = np.linalg.norm(self._cap_b - self._cap_a, axis=1) / 2 + self._cap_r
        # made on first use by _world_caps: each moving body's frame, the static ends in the world
        self._body_frames = np.zeros(0, dtype=int)
        self._static: tuple[np.ndarray, np.ndarray] | None = None
        self._table_pts: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None  # by _plane_heights
        #: per table-checked body, whether CollisionScene.at was told it may touch the table (None:
        #: none may): :meth:`table_margin`
        self.table_touch: np.ndarray | None = None

    def table_margin(self) -> float | np.ndarray:
        """The least height each table-checked body keeps over the table: the scene's margin, and
        none for the bodies that may touch it (down to GRASP_TOL_MM of rounding)."""
        if self.table_touch is None:
            return self.scene.margin
        return np.where(self.table_touch, -self.scene.tol, self.scene.margin)

    def renamed(self, names: Mapping[str, str]) -> SceneState | None:
        """The state :meth:`CollisionScene.at` makes for this state's world with every part name n
        read as ``names.get(n, n)`` (the parts, ``held``, ``grasped``, ``attached`` and ``allow``
        of its call renamed alike; a held part's bodies are "held:<name>", so both are mapped),
        made without placing anything or deciding the pairs again: the same bodies renamed, the
        same pairs, and the library's distances measured anew where the copy first asks (none
        are shared). None where a renaming could change which pairs are checked: ``names`` not
        one to one, or an old or a new name that is also another body's, the table's, a gripper
        body's or in the robot's allowed pairs, or a held part's two names not mapped alike."""
        olds, news = set(names), set(names.values())
        if len(olds) != len(news):
            return None
        touched = olds | news
        reserved = {"table"} | set(_GRIPPER_NAMES) | {n for p in self.scene.allowed for n in p}
        if touched & reserved:
            return None
        for old, new in names.items():  # "held:a" -> "held:b" exactly where a -> b
            if old.startswith("held:") != new.startswith("held:"):
                return None
            if old.startswith("held:") and names.get(_part_of(old), _part_of(old)) != _part_of(new):
                return None
            if not old.startswith("held:") and f"held:{old}" in names and names[f"held:{old}"] != f"held:{new}":
                return None
        for b in self.bodies:
            if b.name not in names and (b.name in touched or _part_of(b.name) in touched):
                return None
        if self.hand is not None and self.hand[0] not in names and self.hand[0] in touched:
            return None
        new = object.__new__(SceneState)
        new.__dict__.update(self.__dict__)
        new.bodies = [replace(b, name=names[b.name]) if b.name in names else b for b in self.bodies]
        if self.hand is not None:
            new.hand = (names.get(self.hand[0], self.hand[0]), *self.hand[1:])
        new._rigid = dict.fromkeys(self._rigid)
        new._measured = {}
        new._refusal = None
        return new

    # ------------------------------------------------------------------ frames and bounds

    def _frames(self, q: np.ndarray) -> np.ndarray:
        q = np.asarray(q, float)
        if q.ndim != 2 or q.shape[1] != 6:
            raise SparValueError(f"joint vectors must be of shape (n, 6), got {q.shape}")
        return self.scene.robot.frames_batch(q)

    def _world_caps(self, F: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """World ends (n, N, 3) of every body's bounding capsule."""
        n, m = len(F), self.n_moving
        if self._static is None:
            self._body_frames = np.array([b.frame for b in self.bodies[:m]], dtype=int)
            base = self.scene.robot.base
            sa, sb = self._cap_a[m:].copy(), self._cap_b[m:].copy()
            on_base = np.array([b.frame == 0 for b in self.bodies[m:]], dtype=bool)
            sa[on_base] = sa[on_base] @ base[:3, :3].T + base[:3, 3]
            sb[on_base] = sb[on_base] @ base[:3, :3].T + base[:3, 3]
            self._static = (sa, sb)
        A = np.empty((n, len(self.bodies), 3))
        B = np.empty_like(A)
        A[:, m:], B[:, m:] = self._static
        Fm = F[:, self._body_frames]                                 # (n, m, 4, 4) each body's frame
        R, t = Fm[..., :3, :3], Fm[..., :3, 3]
        A[:, :m] = (R @ self._cap_a[:m, :, None])[..., 0] + t
        B[:, :m] = (R @ self._cap_b[:m, :, None])[..., 0] + t
        return A, B

    def moving_spheres(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Bounding spheres of the moving bodies (links 1..6, gripper, tool parts) for joint
        vectors q (n, 6) rad: centres (n, M, 3), world frame, and radii (M,), cell unit. A
        caller's broad phase: a body farther than every sphere plus the margin is never near."""
        F = self._frames(q)
        A, B = self._world_caps(F)
        m = self.n_moving
        return (A[:, :m] + B[:, :m]) / 2, self._sph_r[:m]

    def _frame_pose(self, F: np.ndarray, row: int, b: Body) -> np.ndarray:
        if b.frame == WORLD:
            return np.eye(4)
        if b.frame == 0:
            return self.scene.robot.base
        return F[row, b.frame]

    def _plane_heights(self, F: np.ndarray) -> np.ndarray:
        """(n, m) each table-checked moving body's height above the plane z = 0 (exact, signed):
        the z row of its frame times its vertices, less its radius."""
        if self._table_pts is None:  # every table-checked body's vertices, padded by repeating one
            bodies = [self.bodies[i] for i in self.table_bodies]
            k = max((len(b.points) for b in bodies), default=1)
            pts = np.empty((len(bodies), k, 3))
            for j, b in enumerate(bodies):
                pts[j, :len(b.points)] = b.points
                pts[j, len(b.points):] = b.points[0]
            self._table_pts = (pts, np.array([b.frame for b in bodies], dtype=int),
                               np.array([b.radius for b in bodies]))
        pts, frames, radius = self._table_pts
        Fb = F[:, frames]                                             # (n, m, 4, 4)
        return (pts @ Fb[:, :, 2, :3, None])[..., 0].min(axis=2) + Fb[:, :, 2, 3] - radius

    def _table(self, F: np.ndarray) -> np.ndarray:
        """(n, m) each table-checked moving body's height above the table (exact, signed); for a
        body wholly off a table with an extent but within the margin of its footprint, its
        distance to the slab (a lower bound, :func:`_slab_gap`, made exact where it is within the
        margin), else +inf."""
        ext = self.scene.table
        if ext is None:
            return self._plane_heights(F)
        n = len(F)
        out = np.full((n, len(self.table_bodies)), np.inf)
        for k, i in enumerate(self.table_bodies):
            b = self.bodies[i]
            Fb = F[:, b.frame]
            P = b.points @ np.swapaxes(Fb[:, :3, :3], 1, 2) + Fb[:, None, :3, 3]
            h = P[..., 2].min(axis=1) - b.radius
            out[:, k] = np.where(_over(P, b.radius, ext), h, np.inf)
            # off the footprint but within the margin of it: the distance to the slab's edge
            band = np.isinf(out[:, k]) & _over(P, b.radius + self.scene.margin, ext)
            if band.any():
                rows = np.nonzero(band)[0]
                g = _slab_gap(P[rows], b.radius, ext)
                for j in np.nonzero(g <= self.scene.margin)[0].tolist():  # within it: the exact distance
                    g[j] = body_distance(b, self._frame_pose(F, int(rows[j]), b), self.scene.slab(), np.eye(4))
                out[rows, k] = g
        return out

    def tool_rigid_on_table(self, T_tool: np.ndarray) -> tuple[str, str] | None:
        """The first body rigid with the flange (frames 6 and 7: gripper, tool mount, the part
        attached to the tool) within the margin of an unbounded table at world tool pose T_tool
        (4x4), as (body, "table"), or None; None whenever the table has an extent. Its height does
        not change when the tool pose turns about world z or shifts in x, y, so a refusal here
        refuses every such pose (a placement grid's) before any IK is solved."""
        if self.scene.table is not None or not len(self.table_bodies):
            return None
        T_tool = np.asarray(T_tool, float)
        frames = {TOOL: T_tool, 6: T_tool @ self.scene.robot.tool_inverse()}
        margin = np.broadcast_to(self.table_margin(), (len(self.table_bodies),))
        for k, i in enumerate(self.table_bodies.tolist()):  # as _plane_heights, for the bodies on frames 6 and 7
            b = self.bodies[i]
            Fb = frames.get(b.frame)
            if Fb is not None and (b.points @ Fb[2, :3]).min() + Fb[2, 3] - b.radius <= margin[k]:
                return (b.name, "table")
        return None

    def _tool_frames(self, T_tool: np.ndarray) -> np.ndarray:
        """Frames (1, 8, 4, 4) with only what a tool pose fixes: the robot's base (0), the flange
        (6) and the tool (TOOL) at world tool pose ``T_tool``; the links' frames NaN."""
        F = np.full((1, 8, 4, 4), np.nan)
        F[0, 0] = self.scene.robot.base
        F[0, TOOL] = T_tool
        F[0, 6] = np.asarray(T_tool, float) @ self.scene.robot.tool_inverse()
        return F

    def hand_refusal(self, T_tool: np.ndarray) -> tuple[str, str] | None:
        """The first pair :meth:`check` would find within the margin between a body rigid with the
        flange (frames 6 and 7: the hand, the tool mount, the part in the hand) and a body fixed in
        the world (a part, an obstacle) with the tool at world pose ``T_tool`` (4x4), or None.
        Every joint vector reaching T_tool puts those two bodies there, so :meth:`check` refuses
        each for it: a caller trying many tool poses may skip their IK (the table, the grasp rule
        and the links are :meth:`check`'s alone)."""
        F = self._tool_frames(T_tool)
        with np.errstate(invalid="ignore"):
            A, B = self._world_caps(F)
        m, moving = self.scene.margin, self.n_moving
        hand = np.zeros(len(self.bodies), bool)
        hand[:moving] = np.isin(self._body_frames, (6, TOOL))
        pi, pj = self.pairs[:, 0], self.pairs[:, 1]
        ps = np.flatnonzero((hand[pi] & (pj >= moving)) | (hand[pj] & (pi >= moving)))
        if not len(ps):
            return None
        i, j = self.pairs[ps, 0], self.pairs[ps, 1]
        lb = segment_distance(A[0, i], B[0, i], A[0, j], B[0, j]) - self._cap_r[i] - self._cap_r[j]
        near = ps[lb <= m]
        lbs = lb[lb <= m]
        if not len(near):
            return None
        ask = ~self.exact_pair[near]
        sup = np.full(len(near), -np.inf)
        if ask.any():
            sup[ask] = self._support_bounds(F, np.zeros(int(ask.sum()), int), near[ask])
        for p, lb_p, a, g in zip(near.tolist(), lbs.tolist(), ask.tolist(), sup.tolist()):
            if a and g > m:
                continue
            d = lb_p if not a else self._exact_cell(F, 0, p)
            if d <= m:
                a_, b_ = self.pairs[p]
                return (self.bodies[a_].name, self.bodies[b_].name)
        return None

    def tool_rigid_refusal(self, T_tool: np.ndarray) -> tuple[str, str] | None:
        """What refuses every joint vector of this state whatever the tool pose, as the pair
        :meth:`check` would name, or None: the grasp rule when the part in the hand is given in
        the tool frame, else the first checked pair of two bodies rigid with the flange (frames 6
        and 7) within the margin. Their relative pose does not depend on q, so :meth:`check`
        refuses every row for it; ``T_tool`` (4x4, world) is any tool pose (the distances are the
        same at all of them): the answer is kept with the state."""
        if self._refusal is None:
            self._refusal = (self._tool_rigid_refusal(T_tool),)
        return self._refusal[0]

    def _tool_rigid_refusal(self, T_tool: np.ndarray) -> tuple[str, str] | None:
        if self.hand is not None and self.hand[1] == "tool":
            g_ok, g_name = self.grasp_ok(self.hand[2])
            if not g_ok:
                return (g_name, self.hand[0])
        if not self._rigid:
            return None
        F = self._tool_frames(T_tool)
        with np.errstate(invalid="ignore"):
            A, B = self._world_caps(F)
        m = self.scene.margin
        rigid = list(self._rigid)
        i, j = self.pairs[rigid, 0], self.pairs[rigid, 1]
        lbs = segment_distance(A[0, i], B[0, i], A[0, j], B[0, j]) - self._cap_r[i] - self._cap_r[j]
        for p, lb in zip(rigid, lbs.tolist()):
            if lb > m:
                continue
            d = lb if self.exact_pair[p] else self._exact_cell(F, 0, p)
            if d <= m:
                a, b = self.pairs[p]
                return (self.bodies[a].name, self.bodies[b].name)
        return None

    def _bounds(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        F = self._frames(q)
        A, B = self._world_caps(F)
        pi, pj = self.pairs[:, 0], self.pairs[:, 1]
        lb = segment_distance(A[:, pi], B[:, pi], A[:, pj], B[:, pj]) - self._cap_r[pi] - self._cap_r[pj]
        return F, lb, self._table(F)

    def _near_bounds(self, q: np.ndarray, m: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """As :meth:`_bounds`, but the capsule bound is computed only for the (row, pair) cells
        whose bounding spheres come within ``m``; the others are +inf (their capsule bound, which
        the spheres' contain, is beyond ``m`` too). Same answers as :meth:`_bounds` wherever a bound
        is <= m, at a few flops per cell instead of the segment distance's tens, which pays in
        scenes of many parts (generated cells: hundreds of part bodies, most far from the arm)."""
        F = self._frames(q)
        A, B = self._world_caps(F)
        pi, pj = self.pairs[:, 0], self.pairs[:, 1]
        C = (A + B) / 2                                          # (n, N, 3) sphere centres, world
        lb = np.full((len(q), len(pi)), np.inf)
        # first per pair over all rows at once: each body's spheres lie in their box over the rows
        # (``box_lo``, ``box_hi``), so two boxes apart by more than m (and rounding) along an axis
        # have every row's gap beyond m; only the other pairs' gaps are computed, row by row
        sr = self._sph_r
        box_lo, box_hi = C.min(axis=0) - sr[:, None], C.max(axis=0) + sr[:, None]
        reach = m + 1e-9 * (1.0 + float(np.abs(C).max(initial=0.0)) + float(sr.max(initial=0.0)))
        maybe = np.flatnonzero(np.all((box_lo[pi] <= box_hi[pj] + reach) & (box_lo[pj] <= box_hi[pi] + reach),
                                      axis=1))
        si, sj = pi[maybe], pj[maybe]
        gap = np.sqrt(((C[:, si] - C[:, sj]) ** 2).sum(-1)) - sr[si] - sr[sj]
        r, k = np.nonzero(gap <= m)
        if len(r):
            p = maybe[k]
            i, j = pi[p], pj[p]
            lb[r, p] = segment_distance(A[r, i], B[r, i], A[r, j], B[r, j]) - self._cap_r[i] - self._cap_r[j]
        return F, lb, self._table(F)

    def _exact_cell(self, F: np.ndarray, row: int, p: int) -> float:
        """The library's distance of pair ``p`` at row ``row``; a pair of two bodies rigid with
        the flange (frame 6, the tool) is measured once per state (it does not depend on q)."""
        if p in self._rigid:
            return self._rigid[p] if self._rigid[p] is not None else self._rigid_once(F, row, p)
        i, j = self.pairs[p]
        bi, bj = self.bodies[i], self.bodies[j]
        self.scene.stats["exact"] += 1
        return body_distance(bi, self._frame_pose(F, row, bi), bj, self._frame_pose(F, row, bj))

    def _support_bounds(self, F: np.ndarray, rows: np.ndarray, ps: np.ndarray) -> np.ndarray:
        """(c,) :func:`support_gap` of pair ps[k] at row rows[k] (frames F (n, 8, 4, 4)): a lower
        bound of the distance the library would measure there, all c cells in one pass of the
        directions, then one pass per body over its own vertices (a mesh part's thousands of hull
        vertices are projected only for the cells it is in, not padded into every cell)."""
        i, j = self.pairs[ps, 0], self.pairs[ps, 1]
        ub, inv = np.unique(np.concatenate([i, j]), return_inverse=True)
        used = [self.bodies[u] for u in ub.tolist()]
        axes = np.stack([b.T[:3, :3] for b in used])
        radius = np.array([b.radius for b in used])
        centre = np.stack([b.points.mean(axis=0) for b in used])
        frame = np.array([8 if b.frame == WORLD else b.frame for b in used], dtype=int)
        Fx = np.concatenate([F, np.broadcast_to(np.eye(4), (len(F), 1, 4, 4))], axis=1)  # 8: the world
        ia, ib = inv[:len(i)], inv[len(i):]
        Ga, Gb = Fx[rows, frame[ia]], Fx[rows, frame[ib]]           # (c, 4, 4) the frames' poses
        Ra, Rb = Ga[:, :3, :3], Gb[:, :3, :3]
        Ca = np.einsum("cij,cj->ci", Ra, centre[ia]) + Ga[:, :3, 3]
        Cb = np.einsum("cij,cj->ci", Rb, centre[ib]) + Gb[:, :3, 3]
        U, valid = support_directions(Ra @ axes[ia], Rb @ axes[ib], Cb - Ca)
        cheap = [b.points if b.corners is None else b.corners for b in used]
        extent = np.array([b.extent for b in used])
        gap = self._gap_pass(U, valid, ia, ib, Ga, Gb, Ra, Rb, cheap, radius, extent)
        big = np.array([b.corners is not None for b in used])
        again = np.flatnonzero((big[ia] | big[ib]) & (gap <= self.scene.margin))
        if len(again):
            full = [b.points for b in used]
            gap[again] = self._gap_pass(U[again], valid[again], ia[again], ib[again], Ga[again], Gb[again],
                                        Ra[again], Rb[again], full, radius, extent)
        return gap

    @staticmethod
    def _gap_pass(U: np.ndarray, valid: np.ndarray, ia: np.ndarray, ib: np.ndarray, Ga: np.ndarray, Gb: np.ndarray,
                  Ra: np.ndarray, Rb: np.ndarray, points: list[np.ndarray], radius: np.ndarray,
                  extent: np.ndarray) -> np.ndarray:
        """:func:`support_gap` of c cells along directions U (c, 16, 3), the bodies ia, ib (c,) of
        ``points`` (vertices each, its frame; ``extent`` each body's Body.extent) at frame poses Ga,
        Gb (c, 4, 4): each body's vertices are projected only for the cells it is in."""
        ext = []
        for side, G, R in ((ia, Ga, Ra), (ib, Gb, Rb)):
            lo, hi, big = np.empty((len(side), 16)), np.empty((len(side), 16)), np.empty(len(side))
            for n in np.unique(side).tolist():
                at = np.flatnonzero(side == n)
                pts = points[n]
                local = U[at] @ R[at]                               # (k, 16, 3): u in the body's frame
                off = np.einsum("kdj,kj->kd", U[at], G[at, :3, 3])
                proj = np.einsum("pj,kdj->kpd", pts, local) + off[:, None, :]
                lo[at], hi[at] = proj.min(axis=1), proj.max(axis=1)
                big[at] = np.abs(G[at, :3, 3]).max(axis=1) + extent[n]
            ext.append((lo, hi, big))
        (alo, ahi, abig), (blo, bhi, bbig) = ext
        return _gap_of_extents(alo, ahi, radius[ia], abig, blo, bhi, radius[ib], bbig, valid)

    def _rigid_once(self, F: np.ndarray, row: int, p: int) -> float:
        i, j = self.pairs[p]
        bi, bj = self.bodies[i], self.bodies[j]
        self.scene.stats["exact"] += 1
        d = self._rigid[p] = body_distance(bi, self._frame_pose(F, row, bi), bj, self._frame_pose(F, row, bj))
        return d

    # ------------------------------------------------------------------ the grasp rule

    def _hand_in_tool(self, F: np.ndarray) -> np.ndarray | None:
        """(n, 4, 4) T_tool_part of the part in the hand per row, or None."""
        if self.hand is None:
            return None
        part, where, T = self.hand
        if where == "tool":
            return np.broadcast_to(T, (len(F), 4, 4))
        Ti = F[:, 7]
        R = np.swapaxes(Ti[:, :3, :3], 1, 2)
        inv = np.zeros_like(Ti)
        inv[:, :3, :3] = R
        inv[:, :3, 3] = -np.einsum("nij,nj->ni", R, Ti[:, :3, 3])
        inv[:, 3, 3] = 1.0
        return inv @ T

    def grasp_ok(self, T_tool_part: np.ndarray) -> tuple[bool, str | None]:
        """The grasp rule for the part in the hand at T_tool_part (4x4): no finger enters the
        part beyond its contact face and the palm does not enter it (each shrunk by GRASP_TOL_MM
        so touching counts as clear); (ok, the gripper body that enters it or None). Memoised."""
        part = self.hand[0]
        # rounded to 1e-9 and signed zeros made one (+ 0.0): a part grasped on the table, whose
        # pose in the tool each IK solution's frames give with its own rounding, finds the
        # verdict of the same grasp decided before (a -0.0 would otherwise make another key); the
        # part by its geometry (the verdict names a gripper body, never the part): renamed copies
        # of one model share it
        key = (self.scene.shape_key(part), (np.round(T_tool_part, 9) + 0.0).tobytes(),
               None if self.width is None else round(self.width, 9))
        table = self.scene.memo.table("collision.grasp", GRASP_LIMIT) if self.scene.memo is not None else None
        if table is not None and key in table:
            return table[key]
        tol = self.scene.tol
        verdict: tuple[bool, str | None] = (True, None)
        bodies = [b.placed(T_tool_part, TOOL, part) for b in self.scene.shapes_of(part)]
        gripper = self.scene.shrunk_gripper(self.width, tol)
        near = _near_all(gripper, bodies, 0.0)  # (gripper box, part body): bounding capsules touch
        for gi, g in enumerate(gripper):
            if any(body_distance(g, np.eye(4), b, np.eye(4)) <= 0.0 for bi, b in enumerate(bodies) if near[gi, bi]):
                # a mesh part's body is its convex hull: the gripper in the hull may still be
                # out of the part (fingers on a peg beside its shoulder), so the mesh decides
                if self.scene.enters_mesh(part, g, T_tool_part):
                    verdict = (False, g.name)
                    break
        if table is not None:
            table[key] = verdict
        return verdict

    def _grasp_rows(self, F: np.ndarray) -> list[tuple[bool, str | None]]:
        if self.hand is None:
            return [(True, None)] * len(F)
        if self.hand[1] == "tool":  # the same relative pose on every row: decided once
            return [self.grasp_ok(self.hand[2])] * len(F)
        Th = self._hand_in_tool(F)
        return [self.grasp_ok(Th[r]) for r in range(len(F))]

    # ------------------------------------------------------------------ answers

    def clear(self, q: np.ndarray) -> np.ndarray:
        """q (n, 6) joint vectors, rad -> (n,) bool: arm, gripper and held part clear of the
        table, obstacles, other parts and each other (non-adjacent links) by the margin."""
        return self.check(q)[0]

    def check(self, q: np.ndarray) -> tuple[np.ndarray, list[tuple[str, str] | None]]:
        """As :meth:`clear`, with the first pair found closer than the margin per row (None where clear)."""
        q = np.asarray(q, float).reshape(-1, 6)
        n = len(q)
        ok = np.ones(n, dtype=bool)
        why: list[tuple[str, str] | None] = [None] * n
        if not n:
            return ok, why
        m = self.scene.margin
        F, lb, tab = self._near_bounds(q, m)
        self.scene.stats["pairs"] += lb.size + tab.size
        for r, (g_ok, g_name) in enumerate(self._grasp_rows(F)):
            if not g_ok:
                ok[r], why[r] = False, (g_name, self.hand[0])
        low = tab <= self.table_margin()
        for r, k in zip(*np.nonzero(low)):
            if ok[r]:
                ok[r], why[r] = False, (self.bodies[self.table_bodies[k]].name, "table")
        rows, ps = np.nonzero(lb <= m)
        # the library is asked only where the support bound does not already put the pair beyond
        # the margin (its distance is at least that bound: the same verdict); a pair rigid with the
        # flange is measured once per state, not here
        ask = ~self.exact_pair[ps] & ~self._is_rigid[ps] & ok[rows]
        if ask.any():
            at = np.flatnonzero(ask)
            ask[at] = self._support_bounds(F, rows[at], ps[at]) <= m
        measured: dict[tuple[int, bytes], float] = {}
        keys: dict[int, bytes] = {}
        for r, p, a in zip(rows.tolist(), ps.tolist(), ask.tolist()):
            if not ok[r]:
                continue
            if self.exact_pair[p]:
                d = lb[r, p]
            elif a or self._is_rigid[p]:
                d = self._exact_cell(F, r, p)
                if a:
                    key = keys.get(r)
                    if key is None:
                        key = keys[r] = F[r].tobytes()
                    measured[(p, key)] = d
            else:
                continue
            if d <= m:
                i, j = self.pairs[p]
                ok[r], why[r] = False, (self.bodies[i].name, self.bodies[j].name)
        self._measured = measured
        return ok, why

    def clearance(self, q: np.ndarray) -> tuple[np.ndarray, list[tuple[str, str]]]:
        """(n,) minimum distance (cell length unit; <= 0 when touching/penetrating) and, per
        row, the closest pair of named bodies, e.g. ("forearm", "shelf"). The part in the hand
        and the gripper are not a pair here (their contact is the grasp's: :meth:`grasp_ok`),
        nor a body that may touch the table and the table (``table_touch``: a part seated
        through its mate onto the plane the base rests on; :meth:`check` keeps it from sinking)."""
        q = np.asarray(q, float).reshape(-1, 6)
        F = self._frames(q)
        A, B = self._world_caps(F)
        tab = self._table(F)
        if self.table_touch is not None and tab.shape[1]:
            tab = np.where(self.table_touch[None, :], np.inf, tab)
        out = np.full(len(q), np.inf)
        names: list[tuple[str, str]] = [("", "")] * len(q)
        for r in range(len(q)):
            if tab.shape[1] and np.isfinite(tab[r]).any():
                k = int(np.argmin(tab[r]))
                out[r], names[r] = tab[r, k], (self.bodies[self.table_bodies[k]].name, "table")
            got = self._closest_pair(F, A, B, r, float(out[r]))
            if got is not None:
                out[r], names[r] = got
        return out, names

    def _closest_pair(self, F: np.ndarray, A: np.ndarray, B: np.ndarray, r: int,
                      best: float) -> tuple[float, tuple[str, str]] | None:
        """Row ``r``'s checked pair of least distance if below ``best`` (the table's), as (its
        distance, its names), else None: the pairs visited in order of their capsule bound
        (world capsule ends A, B (n, N, 3)) while that is below the least distance found, the
        library asked for the pairs that are not two capsules (its answers of the last
        :meth:`check` at these frames reused); the first pair visited at the least distance wins.

        Only the pairs whose bounding spheres come within ``best`` (and rounding) can be visited (a
        capsule bound is at least its spheres' gap), so only theirs are computed; where two of those visited
        (or the one the visit stops at) have equal bounds, the order of the whole row's sort
        decides which comes first, and the row is visited as the whole sort has it."""
        pi, pj = self.pairs[:, 0], self.pairs[:, 1]
        if np.isfinite(best):
            C = (A[r] + B[r]) / 2
            d = C[pi] - C[pj]
            reach = best + 1e-9 * (1.0 + float(np.abs(C).max(initial=0.0)) + float(self._sph_r.max(initial=0.0)))
            sub = np.flatnonzero(np.sqrt((d * d).sum(-1)) - self._sph_r[pi] - self._sph_r[pj] < reach)
        else:
            sub = np.arange(len(pi))
        i, j = pi[sub], pj[sub]
        lb = segment_distance(A[r, i], B[r, i], A[r, j], B[r, j]) - self._cap_r[i] - self._cap_r[j]
        done: dict[int, float] = {}  # the library's distances at this row, for a second visit
        tie, found = self._visit(F, r, sub, lb, best, done)
        if tie:  # a tie the order of equal bounds decides: the whole row's order
            i, j = pi, pj
            lb = segment_distance(A[r, i], B[r, i], A[r, j], B[r, j]) - self._cap_r[i] - self._cap_r[j]
            _, found = self._visit(F, r, np.arange(len(pi)), lb, best, done, ties=True)
        return found

    def _visit(self, F: np.ndarray, r: int, sub: np.ndarray, lb: np.ndarray, best: float,
               done: dict[int, float], ties: bool = False) -> tuple[bool, tuple[float, tuple[str, str]] | None]:
        """:meth:`_closest_pair`'s visit of pairs ``sub`` (their capsule bounds ``lb``) at row r:
        (a tie, the pair found below ``best`` or None).

        The least distance it finds is the row's whatever the order of equal bounds; only which
        pair is named can depend on it, where another pair with the winner's bound is at the
        winner's distance too: a tie (never with ``ties``: ``sub`` is then every pair, in the
        whole row's order)."""
        order = np.argsort(lb)
        lbs = lb[order].tolist()
        key = F[r].tobytes()
        found = None
        win = -1
        for n, p in enumerate(sub[order].tolist()):
            if lbs[n] >= best:
                break
            d = self._pair_distance(F, r, p, lbs[n], key, done)
            if d < best:
                i, j = self.pairs[p]
                best, found, win = d, (d, (self.bodies[i].name, self.bodies[j].name)), n
        if not ties and found is not None:
            p_win = int(sub[order[win]])
            for k in np.flatnonzero(lb == lbs[win]).tolist():
                p = int(sub[k])
                if p != p_win and self._pair_distance(F, r, p, float(lb[k]), key, done) == found[0]:
                    return True, found
        return False, found

    def _pair_distance(self, F: np.ndarray, r: int, p: int, lb: float, key: bytes, done: dict[int, float]) -> float:
        """Pair p's distance at row r (frames F, ``key`` their bytes): its capsule bound ``lb``
        for two capsules, else the library's (its answer of the last :meth:`check` at these
        frames, or of this row's visits ``done``, reused)."""
        if self.exact_pair[p]:
            return lb
        d = self._measured.get((p, key), done.get(p))
        if d is None:
            d = done[p] = self._exact_cell(F, r, p)
        return d


def _pair_structure(scene: CollisionScene, bodies: list[Body], n_moving: int, hand_part: str | None,
                    allow: frozenset, attached: frozenset,
                    columns: tuple[list[str], np.ndarray, np.ndarray] | None = None
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, tuple]:
    """Which body pairs a state checks (see the module notes), from the bodies' names, frames and
    kinds alone (``bodies`` moving first, ``n_moving`` of them): (pairs (p, 2), table-checked
    moving bodies, pairs of two capsules (their bound is exact), pairs rigid with the flange).

    Pairs in the order of a loop over the moving bodies i and, within, all bodies j > i (a
    (moving, body) bool matrix read row by row). The columns of the world's bodies (frame WORLD,
    after the moving ones: obstacles and parts, most of a generated cell's bodies) depend only
    on the moving body and the world body's name, and are set a name at a time for all of them;
    the rest (links, gripper, tool parts: the same at most steps) come from
    :func:`_head_structure`, kept in the cell's cache."""
    names, frames, is_cap = _body_columns(bodies)[3:] if columns is None else columns
    world_col = frames == WORLD
    world_col[:n_moving] = False
    head_cols = np.flatnonzero(~world_col)
    skip = scene.allowed | allow
    hkey = (tuple((names[j], int(frames[j]), bodies[j].kind) for j in head_cols.tolist()), head_cols.tobytes(),
            n_moving, hand_part, skip, attached)
    table = scene.memo.table("collision.pairs", PAIRS_LIMIT) if scene.memo is not None else None
    # the whole answer, by what it is made of (the head's key, the world's names in order and
    # every body's kind of bound): the requirement states of phase 1 (one per grasp, in a
    # world of obstacles alone) ask the same few structures again and again
    wcols = np.flatnonzero(world_col)
    fkey = (hkey, len(bodies), tuple(names[j] for j in wcols.tolist()), is_cap.tobytes())
    whole = scene.memo.table("collision.structures", STRUCTURES_LIMIT) if scene.memo is not None else None
    done = whole.get(fkey) if whole is not None else None
    if done is not None:
        return done
    head = table.get(hkey) if table is not None else None
    if head is None:
        head = _head_structure([bodies[j] for j in head_cols.tolist()], n_moving, hand_part, skip, attached)
        if table is not None:
            table[hkey] = head
    block, table_bodies, fixed_in_tool, excluded = head
    M = np.zeros((n_moving, len(bodies)), dtype=bool)
    M[:, head_cols] = block
    if len(wcols) and n_moving:
        index: dict[str, int] = {}
        ids = np.array([index.setdefault(names[j], len(index)) for j in wcols.tolist()], dtype=int)
        ok = np.ones((n_moving, len(index)), dtype=bool)   # (moving body, world name) checked
        ok[fixed_in_tool] = False
        for i, ex in enumerate(excluded):
            for n in ex:
                if n in index:
                    ok[i, index[n]] = False
        if hand_part is not None:  # the gripper against the part it closes on: the grasp rule
            grip = [i for i in range(n_moving) if names[i] in _GRIPPER_NAMES]
            # the world's bodies are named by their part (only the tool's have "held:")
            hand_ids = [index[n] for n in (hand_part, f"held:{hand_part}") if n in index]
            ok[np.ix_(grip, hand_ids)] = False
        M[:, wcols] = ok[:, ids]
    pairs_arr = np.argwhere(M).astype(int).reshape(-1, 2)
    in_hand = (frames == 6) | (frames == TOOL)
    pi, pj = pairs_arr[:, 0], pairs_arr[:, 1]
    exact_pair = is_cap[pi] & is_cap[pj]
    rigid = tuple(np.flatnonzero(in_hand[pi] & in_hand[pj]).tolist())
    out = (pairs_arr, table_bodies, exact_pair, rigid)
    if whole is not None:  # shared by the states that ask it again: read-only
        for a in out[:3]:
            a.setflags(write=False)
        whole[fkey] = out
    return out



def _part_of(name: str) -> str:
    """The part a body belongs to: its name, less the "held:" of the part in the hand."""
    return name[5:] if name.startswith("held:") else name


def _head_structure(head: list[Body], n_moving: int, hand_part: str | None, skip: frozenset,
                    attached: frozenset) -> tuple[np.ndarray, np.ndarray, list[int], list[frozenset]]:
    """The part of :func:`_pair_structure` that does not depend on the world's bodies: for the
    bodies ``head`` (the moving ones first, ``n_moving`` of them, then the others that are not
    the world's: links on the base), the (moving, head body) matrix of checked pairs, the
    table-checked moving bodies, the moving bodies fixed in the tool (attached parts: checked
    against the arm and the gripper only, not the table they rest on nor the world) and, per
    moving body, the names of world bodies it is not checked against (itself, and its
    ``skip`` partners: the robot's allowed pairs and the state's ``allow``)."""
    moving = head[:n_moving]
    block = np.zeros((n_moving, len(head)), dtype=bool)
    # an attached part is a part of the world that happens to be where the tool is: it is
    # checked against the arm and the gripper only (not the table it rests on, nor the rest)
    fixed_in_tool = [i for i, b in enumerate(moving) if b.frame == TOOL and b.name in attached]
    fixed = set(fixed_in_tool)
    for i, bi in enumerate(moving):
        for j, bj in enumerate(head):
            if j <= i and j < n_moving:
                continue
            if frozenset((bi.name, bj.name)) in skip or bi.name == bj.name:
                continue
            if i in fixed and (bj.frame == WORLD or j in fixed):
                continue
            if bj.frame == WORLD or bj.frame == 0 and bi.frame >= 2:
                if bi.name in _GRIPPER_NAMES and _part_of(bj.name) == hand_part and bj.frame == WORLD:
                    continue  # the grasp rule decides
                block[i, j] = True
                continue
            if bj.frame == WORLD or bj.frame == 0:
                continue
            fi, fj = bi.frame, bj.frame
            ti, tj = bi.frame == TOOL, bj.frame == TOOL
            if ti and tj:  # in the hand: gripper and the hand's part by the grasp rule
                ni, nj = _part_of(bi.name), _part_of(bj.name)
                if ni in _GRIPPER_NAMES and nj in _GRIPPER_NAMES or ni == nj:
                    continue
                if hand_part in (ni, nj) and (ni in _GRIPPER_NAMES or nj in _GRIPPER_NAMES):
                    continue
                block[i, j] = True
                continue
            if ti or tj:
                link = bj if ti else bi
                other = bi if ti else bj
                limit = 5 if other.name in _GRIPPER_NAMES else 6
                if link.frame <= limit:
                    block[i, j] = True
                continue
            if abs(fi - fj) >= 2:
                block[i, j] = True
    table_bodies = np.array([i for i, b in enumerate(moving)
                             if frozenset((b.name, "table")) not in skip and i not in fixed], dtype=int)
    excluded = [frozenset({b.name} | {n for p in skip if len(p) == 2 and b.name in p for n in p}) for b in moving]
    return block, table_bodies, fixed_in_tool, excluded


def _near_all(A: list[Body], B: list[Body], within: float) -> np.ndarray:
    """(len(A), len(B)) bool: the bounding capsules of each pair (bodies in one frame) within
    ``within`` of each other, in one vectorised call."""
    if not A or not B:
        return np.zeros((len(A), len(B)), dtype=bool)
    a0, a1 = np.array([a.cap[0] for a in A])[:, None], np.array([a.cap[1] for a in A])[:, None]
    b0, b1 = np.array([b.cap[0] for b in B])[None], np.array([b.cap[1] for b in B])[None]
    ra, rb = np.array([a.cap[2] for a in A])[:, None], np.array([b.cap[2] for b in B])[None]
    shape = (len(A), len(B), 3)
    d = segment_distance(*(np.broadcast_to(x, shape) for x in (a0, a1, b0, b1))) - ra - rb
    return d <= within


# --------------------------------------------------------------------------- the cell's scene


def scene_for(cell: Cell, memo: Any = None) -> CollisionScene:
    """A new collision scene of ``cell``: robot link and gripper shapes, part shapes, obstacles,
    the table; the clearance margin (cell's length unit). ``memo`` (core.memo.Memo) keeps the
    scene's derived answers; a planning run's scene is its cell cache's (world.run.CellCache.scene)."""
    robot = cell.robot
    gripper = gripper_for(cell)
    margin = getattr(cell, "clearance", None)
    if margin is None:
        margin = robot.margin if robot.margin is not None else from_mm(cell.unit, DEFAULT_MARGIN_MM)
    parts = _part_bodies(cell.objects, cell.unit)
    scene = CollisionScene(robot, gripper, parts, getattr(cell, "obstacles", ()), margin,
                           getattr(cell, "table", None), cell.unit, memo, _part_meshes(cell.objects))
    return scene


def _part_meshes(objects: Mapping[str, Any]) -> dict[str, Any]:
    """{name: its world.parts.mesh.Geometry} of the objects given by a mesh file (their shape is its
    convex hull); the mesh (object frame) is read on first use (Geometry.mesh())."""
    out = {}
    for name, m in objects.items():
        geo = getattr(m, "geometry", None)
        if geo is not None and getattr(geo, "mesh_file", None) is not None:
            out[name] = geo
    return out



def solids_key(solids: Iterable[Solid]) -> tuple:
    """What bodies made from an object's ``shape:`` solids depend on: the primitives, exactly (not
    the object's name)."""
    return tuple(s.key() for s in solids)


def _part_bodies(objects: Mapping[str, Any], unit: str) -> dict[str, list[Body]]:
    """Each object's :func:`solid_bodies` (a mesh part's: its :func:`mesh_body`), made once per
    distinct shape: the objects of one shape (generated cells: N copies of one peg and one block)
    get copies renamed, sharing the arrays and the library's geometry (bodies are read-only)."""
    made: dict[tuple, list[Body]] = {}
    out: dict[str, list[Body]] = {}
    meshes = _part_meshes(objects)
    for name, m in objects.items():
        geo = meshes.get(name)
        key = solids_key(m.shape) + (((str(geo.mesh_file), float(geo.scale)),) if geo is not None else ())
        first = made.get(key)
        if first is None:
            if geo is not None and len(m.shape) == 1 and m.shape[0].kind == "hull":
                made[key] = [mesh_body(name, WORLD, m.shape[0].points, geo, unit)]
            else:
                made[key] = solid_bodies(name, m.shape)
            out[name] = made[key]
        else:
            out[name] = [replace(b, name=name) for b in first]
    return out


# --------------------------------------------------------------------------- bounds for motions


def bound_columns(state: SceneState) -> np.ndarray:
    """The columns of :func:`clearance_bounds` as body indices into ``state.bodies``: (P + T, 2),
    one row per checked pair (its two bodies), then one per table-checked body (the body, -1)."""
    tab = np.column_stack([state.table_bodies, np.full(len(state.table_bodies), -1)]).astype(int)
    return np.vstack([state.pairs.reshape(-1, 2), tab.reshape(-1, 2)])


def clearance_bounds(state: SceneState, q: np.ndarray, rate: np.ndarray | None = None,
                     want: np.ndarray | None = None) -> np.ndarray:
    """(n, P + T) sound lower bounds (cell unit) of the distance of each checked pair
    (:func:`bound_columns`) and of each table-checked body's height over the plane z = 0, for
    joint vectors q (n, 6) rad: the bounding capsules' distance, and the lowest vertex (the
    table's footprint ignored, so the bound holds wherever the body goes). The gripper and the
    part in the hand are not a column (the grasp rule decides them: :meth:`SceneState.check`).

    With ``rate`` (P + T,) (cell unit per step) and ``want`` (n,) (steps): per row, the pair
    columns are replaced by the library's exact distance (0 when touching) lazily, in order
    of (bound - margin) / rate, while that is below ``want`` and below the smallest
    (exact - margin) / rate found so far: the row's smallest ratio is then exact (or at least
    ``want``), with as few library queries as that needs."""
    q = np.asarray(q, float).reshape(-1, 6)
    F = state._frames(q)
    A, B = state._world_caps(F)
    pi, pj = state.pairs[:, 0], state.pairs[:, 1]
    lb = segment_distance(A[:, pi], B[:, pi], A[:, pj], B[:, pj]) - state._cap_r[pi] - state._cap_r[pj]
    out = np.hstack([lb, state._plane_heights(F)])
    if rate is None or want is None or not lb.size:
        return out
    m = state.scene.margin
    n_pairs = lb.shape[1]
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = np.where(rate > 0, (out - m) / rate, np.where(out > m, np.inf, -np.inf))
    for r in range(len(q)):
        best = min(float(want[r]), float(ratio[r, n_pairs:].min(initial=np.inf)))
        for p in np.argsort(ratio[r, :n_pairs]):
            if ratio[r, p] >= best:
                break
            if state.exact_pair[p]:
                best = float(ratio[r, p])
                continue
            d = out[r, p] = max(float(out[r, p]), state._exact_cell(F, r, int(p)))
            x = (d - m) / rate[p] if rate[p] > 0 else (np.inf if d > m else -np.inf)
            best = min(best, x)
            if best <= 0:
                break
    return out
