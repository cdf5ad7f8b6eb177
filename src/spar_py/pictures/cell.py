"""The work-cell picture at one step: the table, each part drawn from its object's shape at
its world pose (a part from a mesh, or with holes, by its mesh's facets: world.parts.mesh), the
obstacles, the arm's collision shapes (each link's capsules, cylinders and boxes, placed in
its frame), the gripper's palm and fingers at the grasp's width, and the arm's skeleton (a
polyline through its frames) over them.

The shapes drawn are the collision scene's own bodies (world.collision.scene: ``scene_for(cell)``'s
link bodies and gripper boxes, ``cell.obstacles``' bodies), so the picture shows what the
collision check sees: a cylinder as its circumscribed prism, a mesh obstacle as its hull.

Three panels per picture: a 3-D view, a top view and a side view, with equal axis scaling
and the same extents for every step of a plan. What is drawn is a :class:`Scene`
(:mod:`spar_py.pictures.scene`); the arm's points come from ``Scene.frames``, the
robot's own ``Robot.frames(q)``.

Frames and units: world Z up, table top at z = 0, 4x4 transforms with column vectors
(``T_world_obj``), lengths in the cell's unit (``cell.unit``, which is also the unit the
robot was loaded in). matplotlib is imported (Agg backend) inside the drawing functions only.
"""
from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from itertools import product
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from spar_py.core.errors import SparValueError
from spar_py.core.geometry import convex_hull_2d
from spar_py.core.units import from_mm
from spar_py.pictures.plandoc import instance
from spar_py.pictures.scene import AT_REST, MIN_SIZE_MM, Scene, part_model, scenes
from spar_py.world.collision import TOOL, scene_for
from spar_py.world.parts import part_mesh

if TYPE_CHECKING:
    from matplotlib.axes import Axes

    from spar_py.planning.planner import Plan
    from spar_py.world.collision import Body
    from spar_py.world.robot import Robot
    from spar_py.core.model import Cell, MatingFeature, ObjectModel, Solid

__all__ = ["Shape", "Tolerance", "arm_polyline", "assemble_tolerance", "body_faces", "cell_figure", "cell_png",
           "closeup_figure", "closeup_png", "draw_figure", "extent",
           "gripper_segments", "hole_mouth", "hole_mouths", "obstacle_shapes", "object_points", "robot_shapes",
           "solid_faces", "solid_points"]

OBJECT_COLOURS = ("#4c72b0", "#dd8452", "#55a868", "#c44e52", "#8172b3", "#937860", "#da8bc3")
TABLE_COLOUR = "#c8b48a"
ARM_COLOUR = "#3a3a3a"
GRIPPER_COLOUR = "#b22222"
LINK_COLOUR = "#9aa7b8"
OBSTACLE_COLOUR = "#7f7f7f"
#: Sides of the polygons a capsule is drawn with (round its axis), and rings per end cap.
CAPSULE_SIDES, CAPSULE_RINGS = 16, 4
HOLE_COLOUR = "#1a1a1a"
VIEW_3D = (22.0, -58.0)  # elevation, azimuth (deg) of the 3-D panel
ZOOM_3D = 1.1  # the 3-D panel's box in its axes (matplotlib's set_box_aspect zoom)
TOP_EYE = (0.0, 0.0, 1.0)  # the top view looks down from +z
SIDE_EYE = (0.0, -1.0, 0.0)  # the side view looks from -y

#: The PNG's text chunks: none that names the matplotlib version, so the same picture is the same
#: bytes whichever matplotlib drew it.
PNG_METADATA: dict[str, Any] = {"Software": None}

Projection = Callable[[np.ndarray], tuple[np.ndarray, ...]]  # (k, 3) world points -> plot arguments


# =========================================================================== geometry


def solid_points(solid: Solid, T: np.ndarray, segments: int = 24) -> np.ndarray:
    """World points (k, 3) outlining a Solid placed by ``T`` (4x4, T_world_obj, cell unit).

    A box gives its 8 corners (x slowest, z fastest: lo/hi per axis); a cylinder its two
    rim circles, ``segments`` points each (bottom rim first); a mesh part's hull its vertices.
    """
    if solid.kind == "hull":
        local = np.asarray(solid.points, float)
    elif solid.kind == "cylinder":
        a = np.linspace(0.0, 2 * math.pi, segments, endpoint=False)
        rim = np.stack([solid.radius * np.cos(a), solid.radius * np.sin(a)], axis=1)
        local = np.vstack([np.column_stack([rim, np.full(segments, z)]) for z in (solid.lo[2], solid.hi[2])])
    else:
        local = np.array(list(product(*zip(solid.lo, solid.hi))), float)
    return local @ np.asarray(T, float)[:3, :3].T + np.asarray(T, float)[:3, 3]


def _faces_of_points(p: np.ndarray) -> list[np.ndarray]:
    """Faces of a solid from its :func:`solid_points` outline (8 box corners or two rims)."""
    if len(p) == 8:
        quads = [(0, 1, 3, 2), (4, 5, 7, 6), (0, 1, 5, 4), (2, 3, 7, 6), (0, 2, 6, 4), (1, 3, 7, 5)]
        return [p[list(q)] for q in quads]
    n = len(p) // 2
    bottom, top = p[:n], p[n:]
    return [bottom, top, *[np.array([bottom[i], bottom[(i + 1) % n], top[(i + 1) % n], top[i]]) for i in range(n)]]


def solid_faces(solid: Solid, T: np.ndarray, segments: int = 24) -> list[np.ndarray]:
    """The faces (each (m, 3) world points, in order round the face) of a Solid placed by ``T``."""
    return _faces_of_points(solid_points(solid, T, segments))


def object_points(model: ObjectModel, T: np.ndarray) -> np.ndarray:
    """All outline points (k, 3) of an object's shape at world pose ``T``; its origin if it has no shape."""
    if not model.shape:
        return np.asarray(T, float)[:3, 3][None]
    return np.vstack([solid_points(s, T) for s in model.shape])


def arm_polyline(robot: Robot, frames: np.ndarray) -> np.ndarray:
    """World points (k, 3) of the arm's skeleton through ``frames`` = ``robot.frames(q)`` (8, 4, 4):
    frame 0, then per link the corner after its a_{i-1} (along x_{i-1}) and frame i's origin
    (after d_i), up to frame 6 (the flange). Repeated points (zero-length links) are dropped.
    """
    F = np.asarray(frames, float)
    pts = [F[0, :3, 3]]
    for i, a in enumerate(np.asarray(robot.dh, float)[:, 1]):
        # rotx(alpha_{i-1}) leaves x_{i-1} alone: the corner is a_{i-1} along it
        pts += [F[i, :3, 3] + a * F[i, :3, 0], F[i + 1, :3, 3]]
    out = [pts[0]]
    for p in pts[1:]:
        if np.linalg.norm(p - out[-1]) > 1e-9:
            out.append(p)
    return np.array(out)


def gripper_segments(tool: np.ndarray, width: float, length: float) -> list[np.ndarray]:
    """Line segments (each (2, 3) world points) of a parallel gripper at tool pose ``tool``.

    The tool centre point is midway between the finger tips (Sec. 3.2.2); fingers lie
    at tool y = +-width/2 and run ``length`` back along -z to the palm, which is joined
    by the palm bar. Lengths in the cell unit.
    """
    T = np.asarray(tool, float)
    w = width / 2

    def world(p: Sequence[float]) -> np.ndarray:
        return T[:3, :3] @ np.asarray(p, float) + T[:3, 3]

    return [np.array([world((0, s * w, -length)), world((0, s * w, 0))]) for s in (-1, 1)] + [
        np.array([world((0, -w, -length)), world((0, w, -length))])
    ]


def hole_mouth(cell: Cell, obj: str, feature: MatingFeature | None = None
               ) -> tuple[np.ndarray, np.ndarray, float] | None:
    """The mouth of ``obj``'s hole ``feature`` (default: its only hole) in its object frame:
    (centre (3,), outward axis (3,), radius), or None.

    A hole declared by geometry gives its mouth (the axis origin) and axis. The paper's form
    gives the hole's bottom centre F_h and radius (Sec. 3.2.2) but not its axis; a goal
    ``assembled(P, obj, [_, HoleFaces], Ta, Va)`` naming the hole's faces does: the mating
    motion Va (obj's frame) runs down the hole, so the mouth is where the ray F_h - t Va
    leaves obj's boxes. None for an object with no such hole or no such goal.
    """
    model = cell.objects.get(obj)
    if model is None:
        return None
    if feature is None:
        holes = [f for f in model.features if f.kind == "hole"]
        if len(holes) != 1:
            return None
        feature = holes[0]
    if feature.kind != "hole":
        return None
    if feature.geometry is not None:
        g = feature.geometry
        return np.asarray(g.origin, float), -np.asarray(g.direction, float), float(feature.radius)
    axis = None
    for g in cell.goals:  # term data (core.model.Term): ("assembled", peg, hole, faces, ta, va)
        if (isinstance(g, tuple) and g[0] == "assembled" and len(g) == 6 and g[2] == obj and g[5] in cell.vectors
                and model.feature_on(_hole_faces(g[3])) is feature):
            va = np.asarray(cell.vectors[g[5]], float)
            if np.linalg.norm(va) > 0:
                axis = -va / np.linalg.norm(va)
                break
    if axis is None:
        return None
    origin = np.asarray(feature.vector, float)
    exits = [0.0]
    for sd in model.shape:
        with np.errstate(divide="ignore", invalid="ignore"):
            t1, t2 = (np.asarray(sd.lo) - origin) / axis, (np.asarray(sd.hi) - origin) / axis
        lo = np.where(axis != 0, np.minimum(t1, t2), -np.inf)
        hi = np.where(axis != 0, np.maximum(t1, t2), np.inf)
        inside_other = np.all((axis != 0) | ((sd.lo <= origin) & (origin <= sd.hi)))
        if inside_other and lo.max() <= 1e-9 <= hi.min():
            exits.append(float(hi.min()))
    return origin + max(exits) * axis, axis, float(feature.radius)


def _hole_faces(faces: Any) -> list:
    """The hole's face list of a goal's ``[PegFaces, HoleFaces]`` (empty if malformed)."""
    return list(faces[1]) if isinstance(faces, list) and len(faces) == 2 and isinstance(faces[1], list) else []


def hole_mouths(cell: Cell, obj: str) -> list[tuple[np.ndarray, np.ndarray, float]]:
    """The mouth (:func:`hole_mouth`) of each of ``obj``'s holes that has one."""
    model = cell.objects.get(obj)
    found = [hole_mouth(cell, obj, f) for f in (model.features if model is not None else ()) if f.kind == "hole"]
    return [m for m in found if m is not None]


def _disc(centre: np.ndarray, normal: np.ndarray, radius: float, segments: int = 24) -> np.ndarray:
    """Points (segments, 3) of a circle of ``radius`` about ``centre`` in the plane normal to ``normal``."""
    n = normal / np.linalg.norm(normal)
    u = np.cross(n, [1.0, 0.0, 0.0] if abs(n[0]) < 0.9 else [0.0, 1.0, 0.0])
    u /= np.linalg.norm(u)
    v = np.cross(n, u)
    a = np.linspace(0.0, 2 * math.pi, segments, endpoint=False)
    return centre + radius * (np.outer(np.cos(a), u) + np.outer(np.sin(a), v))

# =========================================================================== collision shapes


@dataclass(frozen=True)
class Shape:
    """One collision body as drawn: ``gid`` names it (``link:forearm``, ``gripper:palm``,
    ``obstacle:shelf``; the matplotlib artists carry it), ``faces`` its polygons (each (m, 3)
    world points, cell unit), ``points`` its outline points (k, 3) (the 2-D views draw their
    projected hull: the bodies are convex), ``colour`` and ``alpha``."""

    gid: str
    faces: list[np.ndarray]
    points: np.ndarray
    colour: str
    alpha: float = 1.0


def _capsule_mesh(a: np.ndarray, b: np.ndarray, r: float) -> tuple[list[np.ndarray], np.ndarray]:
    """Faces and points of a capsule (segment a-b grown by r, world): rings of CAPSULE_SIDES
    points along the axis, CAPSULE_RINGS per hemispherical end, joined by quads."""
    d = b - a
    L = float(np.linalg.norm(d))
    z = d / L if L > 0 else np.array([0.0, 0.0, 1.0])
    x = np.cross(z, [1.0, 0.0, 0.0] if abs(z[0]) < 0.9 else [0.0, 1.0, 0.0])
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    k = np.linspace(0.0, 2 * math.pi, CAPSULE_SIDES, endpoint=False)
    circle = np.cos(k)[:, None] * x + np.sin(k)[:, None] * y
    lat = np.linspace(0.0, math.pi / 2, CAPSULE_RINGS + 1)  # 0 at the equator, pi/2 at the pole
    rings = [a - r * math.sin(t) * z + r * math.cos(t) * circle for t in lat[::-1]]
    rings += [b + r * math.sin(t) * z + r * math.cos(t) * circle for t in lat]
    faces = [np.array([p[i], p[(i + 1) % CAPSULE_SIDES], q[(i + 1) % CAPSULE_SIDES], q[i]])
             for p, q in zip(rings, rings[1:]) for i in range(CAPSULE_SIDES)]
    return faces, np.vstack(rings)


def body_faces(body: Body, T_frame: np.ndarray) -> tuple[list[np.ndarray], np.ndarray]:
    """A collision body (world.collision.Body) placed by its frame's world pose ``T_frame``
    (4x4): its faces (each (m, 3) world points) and outline points (k, 3). A box gives its 6
    faces, a cylinder its prism's, a capsule a tube with round ends, a convex body its hull's
    triangles."""
    T = np.asarray(T_frame, float)
    P = np.asarray(body.points, float) @ T[:3, :3].T + T[:3, 3]
    if body.kind == "capsule":
        return _capsule_mesh(P[0], P[-1], float(body.size[0]))
    if body.kind in ("box", "cylinder"):
        return _faces_of_points(P), P
    from scipy.spatial import ConvexHull  # a convex body only

    try:
        hull = ConvexHull(P)
    except Exception:  # flat or degenerate: its points as one polygon
        return [P], P
    return [P[list(f)] for f in hull.simplices], P


def robot_shapes(cell: Cell, s: Scene) -> list[Shape]:
    """The arm's collision bodies at scene ``s``: each link shape of the robot file in its
    frame (the pedestal's frame 0 even without a configuration), and with a configuration the
    palm and fingers, their contact faces at the held grasp's width (open: finger_separation)."""

    scene = scene_for(cell)
    base = np.asarray(cell.robot.base, float)
    alpha = 0.9 * _arm_alpha(s)
    out = []
    for b in scene.links:
        if s.frames is None and b.frame != 0:
            continue
        T = base if b.frame == 0 else s.frames[b.frame]
        faces, pts = body_faces(b, T)
        out.append(Shape(f"link:{b.name}", faces, pts, LINK_COLOUR, alpha))
    if s.frames is not None:
        for b in scene.gripper_bodies(_grip_width(cell, s)):
            faces, pts = body_faces(b, s.frames[TOOL])
            out.append(Shape(f"gripper:{b.name}", faces, pts, GRIPPER_COLOUR, alpha))
    return out


def obstacle_shapes(cell: Cell) -> list[Shape]:
    """The problem file's obstacles (``cell.obstacles``), one Shape per body, in the world."""
    out = []
    for o in getattr(cell, "obstacles", ()):
        for b in o.bodies:
            faces, pts = body_faces(b, np.eye(4))
            out.append(Shape(f"obstacle:{o.name}", faces, pts, OBSTACLE_COLOUR, 0.55))
    return out


def _grip_width(cell: Cell, s: Scene) -> float:
    """The fingers' opening at scene ``s``: the held grasp's width, else finger_separation (cell unit)."""
    if s.held is not None and s.grasp is not None:
        return float(cell.objects[part_model(s.held)].grasps[s.grasp].width)
    return float(cell.finger_separation)



# =========================================================================== extents


@dataclass(frozen=True)
class Extent:
    """Shared extents of a picture series: the table rectangle and the axis box (cell unit)."""

    table: tuple[float, float, float, float]  # x0, x1, y0, y1 at z = 0
    lo: np.ndarray
    hi: np.ndarray


def finger_length(cell: Cell) -> float:
    return 0.5 * cell.finger_separation


def _arm_points(cell: Cell, s: Scene) -> np.ndarray | None:
    """The arm's skeleton (k, 3) at scene ``s``, on to the gripper's palm; None without a configuration."""
    if s.frames is None:
        return None
    tool = s.frames[-1]
    palm = tool[:3, :3] @ [0.0, 0.0, -finger_length(cell)] + tool[:3, 3]
    return np.vstack([arm_polyline(cell.robot, s.frames), palm])


def part_points(cell: Cell, all_scenes: Sequence[Scene]) -> list[np.ndarray]:
    return [object_points(cell.objects[part_model(k)], T) for s in all_scenes for k, T in s.poses.items()
            if part_model(k) in cell.objects]


#: The work box of the pictures: the parts' and obstacles' box grown on every side by this
#: fraction of its largest side, and at least by WORK_PAD_SIZES times the largest part's size.
WORK_PAD, WORK_PAD_SIZES = 0.1, 1.0
#: Above the parts the box reaches this many gripper lengths (finger and palm): the arm over the work.
REACH_OVER = 2.5


def table_extent(cell: Cell, lo: np.ndarray, hi: np.ndarray) -> tuple[float, float, float, float]:
    """The table top drawn (x0, x1, y0, y1 at z = 0, cell unit): the cell's ``table:`` extent,
    else the whole view (without ``table:`` the table is the whole plane), cut to the view box
    ``lo``..``hi`` (a polygon is drawn whole or not at all in the 3-D panel)."""
    t = cell.table if cell.table is not None else (lo[0], hi[0], lo[1], hi[1])
    x0, x1 = max(float(t[0]), float(lo[0])), min(float(t[1]), float(hi[0]))
    y0, y1 = max(float(t[2]), float(lo[1])), min(float(t[3]), float(hi[1]))
    return (x0, max(x0, x1), y0, max(y0, y1))


def extent(cell: Cell, all_scenes: Sequence[Scene]) -> Extent:
    """The view shared by all pictures of a plan, zoomed to the work: the parts of every scene
    and the obstacles, padded (WORK_PAD, WORK_PAD_SIZES), from the table top up to REACH_OVER
    gripper lengths over the highest part; the arm is drawn where it enters that box. The table
    is its ``table:`` extent cut to the box (cell unit)."""
    pts = part_points(cell, all_scenes) + [sh.points for sh in obstacle_shapes(cell)]
    allp = np.vstack(pts) if pts else np.asarray(cell.robot.base, float)[None, :3, 3]
    lo, hi = allp.min(axis=0), allp.max(axis=0)
    size = max((m.bounding_radius() for m in cell.objects.values()), default=from_mm(cell.unit, MIN_SIZE_MM))
    pad = max(WORK_PAD * float(max(hi - lo)), WORK_PAD_SIZES * size, from_mm(cell.unit, 1e-3))
    lo = np.array([lo[0] - pad, lo[1] - pad, min(0.0, float(lo[2])) - 0.02 * pad])
    hi = np.array([hi[0] + pad, hi[1] + pad, float(hi[2]) + REACH_OVER * 2 * finger_length(cell)])
    return Extent(table_extent(cell, lo, hi), lo, hi)


# =========================================================================== painting


def _colour(cell: Cell, obj: str) -> str:
    names = list(cell.objects)
    return OBJECT_COLOURS[names.index(obj) % len(OBJECT_COLOURS)] if obj in names else "#777777"


def _paint_list(cell: Cell, s: Scene, eye: Sequence[float]) -> list[tuple[str, np.ndarray, str]]:
    """What to paint for the parts, far to near along ``eye`` (unit vector towards the viewer):
    (kind 'solid' | 'hole', world points, colour). Hole mouths facing away are left out."""
    eye = np.asarray(eye, float)
    items: list[tuple[float, str, np.ndarray, str]] = []
    size = max((m.bounding_radius() for m in cell.objects.values()), default=from_mm(cell.unit, MIN_SIZE_MM))
    for key, T in s.poses.items():
        o = part_model(key)
        if o not in cell.objects:
            continue
        facets = _mesh_facets(cell.objects[o], T, eye, _colour(cell, o))
        if facets is not None:
            items += facets
            continue
        for sd in cell.objects[o].shape:
            p = solid_points(sd, T, 24)
            items.append((float(p.mean(axis=0) @ eye), "solid", p, _colour(cell, o)))
        for c, n, r in hole_mouths(cell, o):
            nw = T[:3, :3] @ n
            if float(nw @ eye) > 1e-6:
                cw = T[:3, :3] @ c + T[:3, 3] + 1e-3 * size * nw
                items.append((float(cw @ eye), "hole", _disc(cw, nw, r), HOLE_COLOUR))
    items.sort(key=lambda t: _depth_key(t[0], size))
    return [(k, p, col) for _, k, p, col in items]


#: Depths (along the eye) closer than this fraction of the largest part's size are a tie.
DEPTH_TIE = 1e-6


def _depth_key(depth: float, size: float) -> float:
    """The painter's sort key of a depth: rounded to DEPTH_TIE x ``size``, so that items at the
    same depth (a peg centred in its hole) keep the order they were listed in (a stable sort)
    whatever the last bits of their arithmetic, and every machine paints them alike."""
    q = DEPTH_TIE * max(size, 1e-12)
    return round(depth / q) * q


#: Where the light comes from when a mesh's facets are shaded (world frame, towards the light).
LIGHT = np.array([0.3, -0.5, 0.81])


def _mesh_facets(model: ObjectModel, T: np.ndarray, eye: np.ndarray, colour: str
                 ) -> list[tuple[float, str, np.ndarray, str]] | None:
    """The facets of a part drawn from its real shape (world.parts.mesh.part_mesh) facing the
    viewer ``eye``, shaded: for a part from a mesh or with subtracted primitives (holes,
    pockets), whose primitives alone do not show it; None for the others."""
    geo = model.geometry
    if geo is None or not (geo.mesh_file or any(p.subtract for p in geo.primitives)):
        return None
    from matplotlib.colors import to_hex, to_rgb  # drawing only (the viewer needs none)

    mesh = part_mesh(model)
    R = np.asarray(T, float)[:3, :3]
    W = np.asarray(mesh.vertices, float) @ R.T + np.asarray(T, float)[:3, 3]
    N = np.asarray(mesh.face_normals, float) @ R.T
    tris = W[np.asarray(mesh.faces)]
    base = np.array(to_rgb(colour))
    light = LIGHT / np.linalg.norm(LIGHT)
    out = []
    for k in np.flatnonzero(N @ eye > 1e-9):
        shade = 0.55 + 0.45 * max(0.0, float(N[k] @ light))
        out.append((float(tris[k].mean(axis=0) @ eye), "facet", tris[k], to_hex(np.clip(base * shade, 0, 1))))
    return out


def _view_eye(elev_deg: float, azim_deg: float) -> np.ndarray:
    """Unit vector from the scene towards a 3-D axes' viewer at (elev, azim) degrees."""
    e, a = math.radians(elev_deg), math.radians(azim_deg)
    return np.array([math.cos(e) * math.cos(a), math.cos(e) * math.sin(a), math.sin(e)])


def _arm_alpha(s: Scene) -> float:
    return 0.35 if s.arm_note == AT_REST else 1.0


def _draw_arm(ax: Any, cell: Cell, s: Scene, proj: Projection, zorder: float = 3, shapes: bool = False,
              **clip: Any) -> None:
    """The pedestal (unless its link shape is drawn), the arm skeleton over the link shapes,
    and the gripper as lines where its boxes are not drawn (``shapes``: they are); ``clip``:
    the 3-D panel's ``axlim_clip=True`` (hide what leaves the view box)."""
    base = np.asarray(cell.robot.base, float)[:3, 3]
    if not shapes or not any(b.frame == 0 for b in cell.robot.links):
        ax.plot(*proj(np.array([[base[0], base[1], 0.0], base])), color="#888888", lw=7, solid_capstyle="butt",
                zorder=zorder, **clip)
    pts = _arm_points(cell, s)
    if pts is None or s.tool is None:
        return
    ax.plot(*proj(pts), color=ARM_COLOUR, lw=1.6 if shapes else 3.5, alpha=_arm_alpha(s), marker="o",
            ms=3 if shapes else 4, solid_capstyle="round", zorder=zorder, gid="skeleton", **clip)
    if shapes:
        return
    for seg in gripper_segments(s.tool, _grip_width(cell, s), finger_length(cell)):
        ax.plot(*proj(seg), color=GRIPPER_COLOUR, lw=2.4, alpha=_arm_alpha(s), zorder=zorder + 0.1, **clip)


def _items(cell: Cell, s: Scene, eye: Sequence[float]) -> list[tuple[str, list[np.ndarray], np.ndarray, str, float,
                                                                   str]]:
    """Everything painted in a view, far to near along ``eye``: the parts (:func:`_paint_list`),
    the obstacles and the arm's collision shapes, each (kind, faces, outline points, colour,
    alpha, gid); kinds 'solid' | 'hole' | 'facet' (parts) and 'shape'."""
    e = np.asarray(eye, float)
    items: list[tuple[float, tuple[str, list[np.ndarray], np.ndarray, str, float, str]]] = []
    for kind, p, colour in _paint_list(cell, s, eye):
        faces = [p] if kind in ("hole", "facet") else _faces_of_points(p)
        items.append((float(p.mean(axis=0) @ e),
                      (kind, faces, p, colour, 0.92 if kind == "solid" else 1.0, f"part:{kind}")))
    for sh in obstacle_shapes(cell) + robot_shapes(cell, s):
        items.append((float(sh.points.mean(axis=0) @ e), ("shape", sh.faces, sh.points, sh.colour, sh.alpha, sh.gid)))
    size = max((m.bounding_radius() for m in cell.objects.values()), default=from_mm(cell.unit, MIN_SIZE_MM))
    items.sort(key=lambda t: _depth_key(t[0], size))
    return [it for _, it in items]


def draw_3d(ax: Any, cell: Cell, s: Scene, fr: Extent) -> None:
    """The 3-D panel; painted in a fixed order (table, parts, obstacles and the arm's shapes far
    to near, the skeleton on top)."""
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection  # drawing only (the viewer needs none)

    ax.computed_zorder = False
    x0, x1, y0, y1 = fr.table
    ax.add_collection3d(Poly3DCollection([np.array([[x0, y0, 0], [x1, y0, 0], [x1, y1, 0], [x0, y1, 0]])],
                                         facecolor=TABLE_COLOUR, alpha=0.35, edgecolor="#8a7a5a", zorder=1,
                                         axlim_clip=True),
                        autolim=False)
    for k, (kind, faces, _, colour, alpha, gid) in enumerate(_items(cell, s, _view_eye(*VIEW_3D))):
        edge = colour if kind == "facet" else "#555555" if kind == "shape" else "#222222"
        ax.add_collection3d(Poly3DCollection(faces, facecolor=colour, alpha=alpha, edgecolor=edge,
                                             linewidths=0.1 if kind == "shape" else 0.3, zorder=2 + k * 1e-3,
                                             gid=gid, axlim_clip=True),
                            autolim=False)
    _draw_arm(ax, cell, s, lambda p: (p[:, 0], p[:, 1], p[:, 2]), zorder=3, shapes=True, axlim_clip=True)
    ax.set_xlim(fr.lo[0], fr.hi[0])
    ax.set_ylim(fr.lo[1], fr.hi[1])
    ax.set_zlim(fr.lo[2], fr.hi[2])
    ax.set_box_aspect(tuple(fr.hi - fr.lo), zoom=ZOOM_3D)  # equal scaling on the three axes
    ax.view_init(elev=VIEW_3D[0], azim=VIEW_3D[1])
    from matplotlib.ticker import MaxNLocator

    for axis, n in ((ax.xaxis, 4), (ax.yaxis, 5), (ax.zaxis, 5)):
        axis.set_major_locator(MaxNLocator(n, steps=[1, 2, 5, 10]))
    u = cell.unit
    ax.set_xlabel(f"x ({u})")
    ax.set_ylabel(f"y ({u})")
    ax.set_zlabel(f"z ({u})")


def _tick_step(lo: float, hi: float) -> float:
    """The largest round step (1, 2 or 5 times a power of ten) that puts at least two ticks in
    ``lo``..``hi``: a narrow panel gets few, readable tick labels."""
    power = 10.0 ** math.floor(math.log10(max(hi - lo, 1e-12)))
    for step in (5 * power, 2 * power, power, power / 2, power / 5):
        if math.floor(hi / step) - math.ceil(lo / step) + 1 >= 2:
            return step
    return power / 10


def _draw_2d(ax: Axes, cell: Cell, s: Scene, fr: Extent, axes: tuple[int, int], eye: Sequence[float]) -> None:
    """An orthographic view onto world axes ``axes`` (0 x, 1 y, 2 z) seen from ``eye``, far to near."""
    from matplotlib.patches import Polygon, Rectangle  # drawing only (the viewer needs none)

    i, j = axes
    x0, x1, y0, y1 = fr.table
    if axes == (0, 1):
        ax.add_patch(Rectangle((x0, y0), x1 - x0, y1 - y0, fc=TABLE_COLOUR, alpha=0.35, ec="#8a7a5a"))
    else:
        lo, hi = (x0, x1) if i == 0 else (y0, y1)
        ax.plot([lo, hi], [0, 0], color="#8a7a5a", lw=4, solid_capstyle="butt")
    for kind, _, p, colour, alpha, gid in _items(cell, s, eye):
        ax.add_patch(Polygon(convex_hull_2d(p[:, [i, j]]), closed=True, fc=colour, ec="#222222",
                             lw=0.6 if kind in ("solid", "shape") else 0.0, alpha=alpha, gid=gid))
    _draw_arm(ax, cell, s, lambda p: (p[:, i], p[:, j]), shapes=True)
    ax.set_xlim(fr.lo[i], fr.hi[i])
    ax.set_ylim(fr.lo[j], fr.hi[j])
    ax.set_aspect("equal", adjustable="box", anchor="W")
    from matplotlib.ticker import MaxNLocator, MultipleLocator

    ax.xaxis.set_major_locator(MultipleLocator(_tick_step(float(fr.lo[i]), float(fr.hi[i]))))
    ax.tick_params(axis="x", labelsize=8)
    ax.yaxis.set_major_locator(MaxNLocator(6, steps=[1, 2, 5, 10]))
    names = "xyz"
    ax.set_xlabel(f"{names[i]} ({cell.unit})")
    ax.set_ylabel(f"{names[j]} ({cell.unit})")
    ax.grid(True, lw=0.3, alpha=0.5)


def _legend(cell: Cell, s: Scene) -> list[Any]:
    """Legend entries: each object present (the held one with its grasp), hole mouths if any
    is seen, the obstacles, the link shapes, the table, the arm's frames and the gripper."""
    # matplotlib: drawing only (the viewer needs none)
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch

    held = part_model(s.held) if s.held else None
    drawn = {part_model(k) for k in s.poses}
    handles: list[Any] = [Patch(fc=_colour(cell, o), ec="#222222",
                                label=o + ((f" (held, {s.grasp})" if s.grasp else " (held)") if o == held else ""))
                          for o in cell.objects if o in drawn]
    eyes = (_view_eye(*VIEW_3D), TOP_EYE, SIDE_EYE)
    if any(kind == "hole" for e in eyes for kind, *_ in _paint_list(cell, s, e)):
        handles.append(Patch(fc=HOLE_COLOUR, label="hole mouth"))
    if getattr(cell, "obstacles", ()):
        handles.append(Patch(fc=OBSTACLE_COLOUR, alpha=0.55, ec="#222222",
                             label="obstacles: " + ", ".join(o.name for o in cell.obstacles)))
    if cell.robot.links:
        handles.append(Patch(fc=LINK_COLOUR, alpha=0.9 * _arm_alpha(s), ec="#222222", label="link shapes"))
    return handles + [
        Patch(fc=TABLE_COLOUR, alpha=0.35, ec="#8a7a5a", label="table (z = 0)"),
        Line2D([], [], color=ARM_COLOUR, lw=1.6, marker="o", ms=3, alpha=_arm_alpha(s),
               label=f"{cell.robot.name} DH frames" + (f" ({s.arm_note})" if s.arm_note else "")),
        Patch(fc=GRIPPER_COLOUR, ec="#222222", label="gripper (palm, fingers)"),
    ]


def draw_figure(cell: Cell, s: Scene, fr: Extent) -> Any:
    """The matplotlib Figure (1200 x 720 px at 100 dpi) of scene ``s`` within extents ``fr``,
    not saved; the caller closes it (``matplotlib.pyplot.close``). Each drawn collision body's
    artists carry its ``gid`` (:class:`Shape`): one per panel."""
    import matplotlib  # only to draw; Agg is chosen before pyplot loads

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig = plt.figure(figsize=(12, 7.2), dpi=100)
    try:
        draw_3d(fig.add_axes((0.0, 0.09, 0.6, 0.82), projection="3d"), cell, s, fr)
        top = fig.add_axes((0.6, 0.56, 0.38, 0.32))
        _draw_2d(top, cell, s, fr, (0, 1), TOP_EYE)
        top.set_title("top view (looking down)", fontsize=9)
        side = fig.add_axes((0.6, 0.13, 0.38, 0.32))
        _draw_2d(side, cell, s, fr, (0, 2), SIDE_EYE)
        side.set_title("side view (from -y)", fontsize=9)
        fig.text(0.5, 0.975, s.title, ha="center", va="top", fontsize=13, weight="bold", family="monospace")
        if s.detail:
            fig.text(0.5, 0.935, s.detail, ha="center", va="top", fontsize=9, family="monospace")
        handles = _legend(cell, s)
        fig.legend(handles=handles, loc="lower center", ncol=min(len(handles), 6), fontsize=9, frameon=False)
    except BaseException:
        plt.close(fig)
        raise
    return fig


def cell_figure(cell: Cell, s: Scene, fr: Extent, path: str | Path) -> Path:
    """Draw scene ``s`` within extents ``fr`` into the PNG ``path`` (1200 x 720 px) and return the path."""
    return _save_png(draw_figure(cell, s, fr), path)


def _save_png(fig: Any, path: str | Path) -> Path:
    """Write the matplotlib figure ``fig`` to the PNG ``path`` (100 dpi, no varying metadata), close it."""
    import matplotlib.pyplot as plt  # loaded already by whoever drew ``fig`` (with Agg)

    try:
        fig.savefig(path, dpi=100, facecolor="white", metadata=PNG_METADATA)
    finally:
        plt.close(fig)
    return Path(path)


def cell_png(cell: Cell, plan: Plan, step_index: int, path: str | Path) -> Path:
    """Draw the work cell at step ``step_index`` (0 = initial state, k = after step k) into ``path``.

    Extents are those of the whole plan, as :func:`spar_py.pictures.write_pictures` uses.
    Raises SparValueError for a step index outside 0..n.
    """
    all_scenes = scenes(cell, plan)
    if not 0 <= step_index < len(all_scenes):
        raise SparValueError(f"step_index {step_index} outside 0..{len(all_scenes) - 1}")
    return cell_figure(cell, all_scenes[step_index], extent(cell, all_scenes), path)


# =========================================================================== close-up of an assemble

#: The close-up's half-width: this many times the largest of the hole's radius, the tolerance
#: and the bound reached, round the hole's mouth.
CLOSEUP_RADII = 3.0
TOLERANCE_COLOUR = "#2ca02c"
BOUND_COLOUR = "#d62728"


@dataclass(frozen=True)
class Tolerance:
    """The insertion check of an assemble step at the hole's mouth (cell unit): the hole
    object, the mouth's world centre (3,) and outward axis (3,), the hole's radius, the
    tolerance R_h - R_p (the square root of the check's threshold), the bound reached (the
    square root of the check's bound: how far the peg's centre may be off the hole's) and
    whether the check is satisfied. pictures/viewer.py draws the same circles."""

    hole: str
    centre: np.ndarray
    axis: np.ndarray
    hole_radius: float
    tolerance: float
    bound: float
    satisfied: bool


def assemble_tolerance(cell: Cell, plan: Plan, s: Scene) -> Tolerance | None:
    """The :class:`Tolerance` of the step scene ``s`` shows (``s.index`` >= 1), if it is an
    assemble step whose insertion check (the ``centres`` constraint, with a threshold) is in
    the plan and whose hole has a mouth (:func:`hole_mouth`); None otherwise."""
    inst = instance(plan)
    steps = list(inst.get("steps") or [])
    if not 1 <= s.index <= len(steps):
        return None
    step = steps[s.index - 1]
    args = step.get("args") or []
    if step.get("name") != "assemble" or len(args) < 2:
        return None
    checks = list(inst.get("constraints") or []) + list(inst.get("verifications") or [])
    check = next((c for c in checks if c.get("action") == step.get("id") and c.get("constraint") == "centres"
                  and c.get("threshold") is not None and c.get("bound") is not None), None)
    hole = str(args[1])
    model = cell.objects.get(hole)
    feature = model.feature_on(_hole_faces(args[2]) if len(args) > 2 else []) if model is not None else None
    mouth = hole_mouth(cell, hole, feature) if feature is not None else None
    T = s.poses.get(hole)
    if check is None or mouth is None or T is None:
        return None
    c, n, radius = mouth
    T = np.asarray(T, float)
    return Tolerance(hole, T[:3, :3] @ c + T[:3, 3], T[:3, :3] @ n, float(radius),
                     math.sqrt(max(float(check["threshold"]), 0.0)), math.sqrt(max(float(check["bound"]), 0.0)),
                     bool(check.get("satisfied")))


def _mouth_basis(axis: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(u, v, n): the hole's outward axis n and two unit vectors across it (u nearest world x)."""
    n = np.asarray(axis, float) / np.linalg.norm(axis)
    a = np.array([1.0, 0.0, 0.0]) if abs(n[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    u = a - (a @ n) * n
    u /= np.linalg.norm(u)
    return u, np.cross(n, u), n


def _draw_closeup(ax: Axes, cell: Cell, s: Scene, tol: Tolerance, across: np.ndarray, up: np.ndarray,
                  eye: np.ndarray, alpha: float) -> None:
    """The parts of ``s`` (no arm: it would hide the mouth) projected onto (``across``, ``up``)
    about the mouth's centre, far to near along ``eye``."""
    from matplotlib.patches import Polygon  # drawing only

    for kind, p, colour in _paint_list(cell, s, eye):
        q = np.column_stack([(p - tol.centre) @ across, (p - tol.centre) @ up])
        ax.add_patch(Polygon(convex_hull_2d(q) if kind == "solid" else q, closed=True, fc=colour,
                             ec="#222222", lw=0.6 if kind == "solid" else 0.0, alpha=alpha if kind == "solid" else 1.0,
                             gid=f"part:{kind}"))


def closeup_figure(cell: Cell, s: Scene, tol: Tolerance) -> Any:
    """The matplotlib Figure (1000 x 560 px at 100 dpi) of the close-up of an assemble step:
    looking down the hole (the peg over the hole's mouth, the tolerance R_h - R_p circle and
    the bound reached drawn about the mouth's centre) and across it (the same radii at the
    mouth). The caller closes it."""
    import matplotlib  # only to draw; Agg is chosen before pyplot loads

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.lines import Line2D
    from matplotlib.patches import Circle

    u, v, n = _mouth_basis(tol.axis)
    half = CLOSEUP_RADII * max(tol.hole_radius, tol.tolerance, tol.bound, from_mm(cell.unit, 1e-3))
    fig = plt.figure(figsize=(10, 5.6), dpi=100)
    try:
        down = fig.add_axes((0.06, 0.16, 0.42, 0.66))
        _draw_closeup(down, cell, s, tol, u, v, n, 0.5)
        for r, colour, style in ((tol.tolerance, TOLERANCE_COLOUR, "--"), (tol.bound, BOUND_COLOUR, "-")):
            down.add_patch(Circle((0.0, 0.0), r, fill=False, ec=colour, ls=style, lw=1.8, zorder=5))
        down.plot([0.0], [0.0], marker="+", color="#ffffff", ms=10, zorder=6)
        down.set_title(f"looking down {tol.hole}'s hole (the parts see-through)", fontsize=9)
        side = fig.add_axes((0.55, 0.16, 0.42, 0.66))
        _draw_closeup(side, cell, s, tol, u, n, -v, 0.5)
        for r, colour, style, y in ((tol.tolerance, TOLERANCE_COLOUR, "--", 0.0), (tol.bound, BOUND_COLOUR, "-", 0.0)):
            side.plot([-r, r], [y, y], color=colour, ls=style, lw=2.2, marker="|", ms=12, zorder=5)
        side.set_title("across the hole (the parts see-through)", fontsize=9)
        for ax in (down, side):
            ax.set_xlim(-half, half)
            ax.set_ylim(-half, half)
            ax.set_aspect("equal", adjustable="box")
            ax.grid(True, lw=0.3, alpha=0.5)
            ax.tick_params(labelsize=8)
        down.set_xlabel(f"across the hole ({cell.unit})")
        down.set_ylabel(f"across the hole ({cell.unit})")
        side.set_xlabel(f"across the hole ({cell.unit})")
        side.set_ylabel(f"along the hole's axis, from its mouth ({cell.unit})")
        fig.text(0.5, 0.975, f"{s.title}: close-up", ha="center", va="top", fontsize=12, weight="bold",
                 family="monospace")
        verdict = "satisfied" if tol.satisfied else "NOT satisfied: the insertion may fail"
        fig.text(0.5, 0.92, f"the peg's centre within {tol.bound:.4g} {cell.unit} of the hole's (bound reached) "
                 f"< tolerance R_h - R_p = {tol.tolerance:.4g} {cell.unit}: {verdict}",
                 ha="center", va="top", fontsize=9, family="monospace")
        drawn = {part_model(k) for k in s.poses}
        handles: list[Any] = [Line2D([], [], color=_colour(cell, o), lw=8, label=o) for o in cell.objects if o in drawn]
        handles += [Line2D([], [], color=HOLE_COLOUR, lw=8, label="hole mouth"),
                    Line2D([], [], color=TOLERANCE_COLOUR, ls="--", lw=1.8,
                           label=f"tolerance R_h - R_p ({tol.tolerance:.4g} {cell.unit})"),
                    Line2D([], [], color=BOUND_COLOUR, lw=1.8, label=f"bound reached ({tol.bound:.4g} {cell.unit})")]
        fig.legend(handles=handles, loc="lower center", ncol=len(handles), fontsize=8, frameon=False)
    except BaseException:
        plt.close(fig)
        raise
    return fig


def closeup_png(cell: Cell, plan: Plan, s: Scene, path: str | Path) -> Path | None:
    """Draw the close-up of the assemble step scene ``s`` shows into the PNG ``path`` and return
    the path; None (nothing written) when ``s`` is no assemble step with an insertion check."""
    tol = assemble_tolerance(cell, plan, s)
    if tol is None:
        return None
    return _save_png(closeup_figure(cell, s, tol), path)
