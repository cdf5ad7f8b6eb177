"""The collision bodies: a :class:`Body` fixed to one frame (Craig's link frames 0..6, the tool, the
world) with its bounding capsule; the builders (capsule, cylinder, box, convex hull, mesh part, a
robot link's shape, an object's ``shape:`` solids); the placed groups whose columns a scene state
reads; the obstacles; and the library's side (python-fcl, imported on first use): a body's
geometry, a pose as its transform, and the distance of two placed bodies.

Frames and units: world Z up, table top z = 0; all lengths in the cell's unit; a body's pose is its
frame's world pose times its fixed local transform.
"""
from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass, field, replace
from functools import cached_property
from typing import TYPE_CHECKING, Any

import numpy as np

from spar_py.core.errors import SparValueError
from spar_py.core.units import from_mm

if TYPE_CHECKING:
    from spar_py.core.model import Solid

__all__ = ["BOX_FIRST", "Body", "CYL_SIDES", "HULL_EXCESS_MM", "Obstacle", "Placed", "TOOL", "WORLD", "body_columns",
           "body_distance", "box", "bvh", "capsule", "convex", "cylinder", "fcl_transform", "group_columns",
           "joined_columns", "link_body", "mesh_body", "solid_bodies"]

#: Sides of the polygon circumscribed about a cylinder (its vertices for the table test and
#: the hull a cylinder obstacle or part is given to the library as): the polygon contains
#: the cylinder, so a clearance is never overstated.
CYL_SIDES = 16
#: A mesh part collides as its convex hull where the hull is the mesh within this on average
#: (mm: the volume between them over the hull's area), else as its mesh: 0.05 mm.
HULL_EXCESS_MM = 0.05
#: Frame index of the tool (gripper, held part) and of the world (parts, obstacles).
TOOL, WORLD = 7, -1

#: A convex or mesh body with more vertices than this is first bounded by its box's corners
#: (:func:`_box_corners`); only the cells the box leaves within the margin project every vertex.
BOX_FIRST = 64


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
    import fcl  # lazily: see Body.fcl_geometry
    from scipy.spatial import ConvexHull  # lazily: only a convex body reaching the library needs it

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
    import fcl  # lazily: see Body.fcl_geometry

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
    from scipy.spatial import ConvexHull  # lazily: see _fcl_convex

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
            self._columns = body_columns(self)
        return self._columns


def body_columns(bodies: list[Body]) -> tuple:
    """The :meth:`Placed.columns` of ``bodies``."""
    return (np.array([b.cap[0] for b in bodies], dtype=float).reshape(-1, 3),
            np.array([b.cap[1] for b in bodies], dtype=float).reshape(-1, 3),
            np.array([b.cap[2] for b in bodies], dtype=float), [b.name for b in bodies],
            np.array([b.frame for b in bodies], dtype=int), np.array([b.kind == "capsule" for b in bodies], dtype=bool))


def group_columns(groups: list[Placed]) -> tuple:
    """The columns of :class:`Placed` groups end to end (:meth:`Placed.columns`)."""
    return joined_columns([g.columns() for g in groups])


def joined_columns(cols: list[tuple]) -> tuple:
    """Column tuples (:func:`body_columns`) of body lists, as one of their concatenation."""
    if not cols:
        return body_columns([])
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


def link_body(s: Any) -> Body:
    """A robot file's link shape (world.robot: capsule, cylinder, hull or box) as a body of its frame."""
    if s.kind == "capsule":
        return capsule(s.name, s.frame, s.a, s.b, s.radius)
    if s.kind == "cylinder":
        return cylinder(s.name, s.frame, s.a, s.b, s.radius)
    if s.kind == "hull":
        return convex(s.name, s.frame, s.points)
    return box(s.name, s.frame, s.a, s.b)


def fcl_transform(T: np.ndarray) -> Any:
    import fcl  # lazily: see Body.fcl_geometry

    return fcl.Transform(np.ascontiguousarray(T[:3, :3]), np.ascontiguousarray(T[:3, 3]))


def body_distance(b1: Body, T1: np.ndarray, b2: Body, T2: np.ndarray) -> float:
    """The distance of two placed bodies (world poses T1, T2 of their frames): 0 when they
    touch or overlap (``collide`` first), else python-fcl's unsigned distance."""
    import fcl  # lazily: see Body.fcl_geometry

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
