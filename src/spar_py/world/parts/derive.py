"""Stable poses and parallel-jaw grasps derived from a part's mesh, and the checks of
hand-written ones against it.

Stable poses (Fig. 18): trimesh's ``compute_stable_poses`` (deterministic: no noise, one
sample; world.parts.stable computes the same with arrays) gives the resting orientations of
the convex hull with the probability of each (a hull of more than HULL_FACES_MAX triangles
thinned first, each pose then snapped to the face of the mesh it rests on);
those below ``PROB_FLOOR`` are dropped, and every remaining one must pass
:func:`support_check`, our own quasi-static test (the part rests on a face of its own, not
an edge or a point, and its centre of mass projects inside the support polygon, the convex
hull of the mesh's points on the table, by at least STABLE_MARGIN_MM), since that function
can return poses that are not stable; and it must not topple on a tilt of STABLE_TILT_DEG about
any edge of that polygon (the angle whose tangent is the margin over the centre of mass's
height). A pose is kept as R, the least rotation taking the
resting face's outward normal to world -z (so a pose is written as the paper writes it,
``tm`` rows and the frame's height above the table), its ``rfaces`` (faces lying on the
table) and ``ofaces`` (those plus a feature whose mouth or tip is on the table).

Grasps (Fig. 19) for a parallel-jaw gripper (:class:`Gripper`): the tool frame's z axis is
the approach, y the closing direction, the tool centre the midpoint between the finger tips.
Candidates: pairs of opposite parallel planar faces (the part between them), and round shafts
(the peg feature's, a cylinder primitive's) across their diameter at quantised closing
directions; the width at most the opening; the faces' overlap (projected on their mid-plane)
at least MIN_CONTACT_MM2, the tool centre at the overlap's centroid (on a shaft: its middle);
approaches quantised in the plane normal to the closing direction (``step``, 45 deg by
default), each kept only if the finger pads touch the overlap by MIN_CONTACT_MM2 (a shaft:
MIN_CONTACT_MM along its side) and neither the closed fingers nor the open gripper (fingers
at the opening and palm, swept in along the approach) enter the part. ``ofaces``: the gripped
faces, every planar face whose plane the palm or a closed finger reaches beyond (the part
cannot rest on it while held) and the feature's face if they enter the space its mate needs.
Each facet grasp kept is also offered at half depth (:func:`_half_depth`, listed after the others):
backed off along its approach while its pads keep half their contact, so the fingers hold the
part's outer half and stay off what lies beside the rest (a mated part's neighbours, the table).

Then the antipodal grasps (:func:`antipodal_grasps`): contact pairs sampled on the surface,
planar or curved, within a friction cone; all of them for a part the candidates above leave
with none, and on a mesh part those on curved faces the candidates above do not close on.

Units: lengths in the cell unit, constants in mm (converted with spar_py.core.units.from_mm);
angles in radians. Frames: object frame; tool frames T_g are 4x4 in the object frame.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from spar_py.core.geometry import convex_hull_2d
from spar_py.core.units import from_mm
from spar_py.world.parts.mesh import (ON_SURFACE_MM, Face, FeatureGeometry, Primitive, axis_basis, clean, cross,
                                  derive_faces, face_of_point, minimal_rotation)

if TYPE_CHECKING:
    import trimesh

__all__ = ["Antipodal", "DerivedGrasp", "DerivedPose", "Gripper", "MeshCylinder", "antipodal_grasps", "antipodal_pairs",
           "derive_grasps", "derive_poses", "euler_zyz_of",
           "grasp_problem", "mate_grasp_usable", "mesh_cylinders", "support_check"]

#: Poses whose basin of attraction (trimesh's probability) is smaller are dropped.
PROB_FLOOR = 0.01
#: A convex hull of more triangles is thinned before trimesh's pose search (see derive_poses).
HULL_FACES_MAX = 64
#: ... on a grid of the part's size over this.
HULL_GRID = 100
#: A pose trimesh finds is snapped to a face whose normal is within this (deg).
SNAP_DEG = 2.0
#: The centre of mass must project this far inside the support polygon (mm).
STABLE_MARGIN_MM = 0.5
#: ... and the part must stay after a tilt of this much about any edge of it (deg): a part
#: balanced with its centre of mass high over a narrow face (a peg on a tip off its centre of
#: mass by a millimetre) passes the margin but is knocked over by the least disturbance.
STABLE_TILT_DEG = 5.0
#: Points within this of the table plane support the part (mm).
SUPPORT_TOL_MM = 0.01
#: The least contact of each finger pad with a gripped planar face (mm^2).
MIN_CONTACT_MM2 = 25.0
#: The least contact length of a finger pad along a shaft's side (mm).
MIN_CONTACT_MM = 5.0
#: Fingers touching a face are not inside it: boxes are shrunk by this (mm).
TOUCH_MM = 0.02
#: A facet grasp from above whose fingers or palm come nearer the table than this in a stable pose
#: of the part is offered backed off along its approach until they clear it (mm): more than the
#: collision margin (world.collision.scene's DEFAULT_MARGIN_MM, 2 mm) ...
TABLE_CLEAR_MM = 3.0
#: ... in steps of this (mm) ...
TABLE_STEP_MM = 1.0
#: ... where the approach descends at least this steeply (deg below the horizontal).
TABLE_APPROACH_DEG = 15.0
#: Every facet grasp is also offered backed off along its approach while its pads keep this
#: fraction of their contact area (_half_depth) ...
HALF_DEPTH_KEEP = 0.5
#: ... when that is at least this far back (mm).
HALF_DEPTH_MIN_MM = 3.0
#: A shaft grasp straight down onto a lying part slides along the shaft by this (mm) to keep
#: its fingers off the part beside the shaft (_shaft_from_above).
SHAFT_SLIDE_MM = 1.0
#: Opposite faces: normals antiparallel within this (deg).
PARALLEL_DEG = 0.05


@dataclass(frozen=True)
class Gripper:
    """A parallel-jaw gripper (cell unit): the ``opening`` W_m; each finger ``finger_length``
    long (tip to palm, along tool z), ``finger_width`` across (tool x), ``finger_thickness``
    (tool y, outward); the palm ``palm_depth`` deep behind the fingers and as wide as the open
    fingers. The defaults (:meth:`default`) are in mm, a common industrial jaw."""

    opening: float
    finger_length: float
    finger_width: float
    finger_thickness: float
    palm_depth: float
    #: the palm's size across the fingers (tool x) and along the closing axis (tool y); None: a
    #: finger's width, and the open fingers' span (opening + 2 finger thicknesses)
    palm_width: float | None = None
    palm_thickness: float | None = None

    @classmethod
    def default(cls, unit: str, opening: float) -> "Gripper":
        """Fingers 60 mm long, 20 mm wide, 10 mm thick, a palm 25 mm deep; ``opening`` in ``unit``."""
        return cls(opening, from_mm(unit, 60.0), from_mm(unit, 20.0), from_mm(unit, 10.0), from_mm(unit, 25.0))

    @classmethod
    def of_robot(cls, g: Any) -> "Gripper":
        """The robot file's gripper (world.robot.model.GripperGeometry, cell unit): its opening, its
        fingers' and palm's boxes, so grasps are derived for the fingers the arm really has."""
        return cls(g.finger_separation, g.finger_length, g.finger_width, g.finger_thickness, g.palm_length,
                   g.palm_width, g.palm_thickness)

    def palm_half(self) -> tuple[float, float]:
        """The palm's half sizes along tool x and tool y."""
        x = self.finger_width if self.palm_width is None else self.palm_width
        y = self.opening + 2 * self.finger_thickness if self.palm_thickness is None else self.palm_thickness
        return x / 2, y / 2

    def spec(self) -> list:
        """Plain data for the content hash (the palm's sizes only where they are not the default,
        so caches written before the robot's palm was read stay valid)."""
        base = [round(v, 12) for v in (self.opening, self.finger_length, self.finger_width,
                                       self.finger_thickness, self.palm_depth)]
        px, py = self.palm_half()
        if (round(px, 12), round(py, 12)) != (round(self.finger_width / 2, 12),
                                              round(self.opening / 2 + self.finger_thickness, 12)):
            base += [round(2 * px, 12), round(2 * py, 12)]
        return base


@dataclass(frozen=True)
class DerivedPose:
    """A derived stable pose: R (3x3, object to world, resting face down), the frame's
    ``height`` above the table (cell unit), the faces it rests on and hides, and trimesh's
    probability of it."""

    label: str
    rfaces: tuple[str, ...]
    ofaces: tuple[str, ...]
    R: np.ndarray
    height: float
    probability: float


@dataclass(frozen=True)
class DerivedGrasp:
    """A derived grasp: T (4x4, tool frame in the object frame), ``euler`` (X, Y, Z in the cell
    unit, Z-Y-Z phi, theta, psi in radians: geometry.eulerxyz(*euler) == T), ``width`` W_g,
    the gripped faces and the faces the gripper covers."""

    label: str
    gfaces: tuple[str, ...]
    ofaces: tuple[str, ...]
    T: np.ndarray
    euler: tuple[float, float, float, float, float, float]
    width: float


# =========================================================================== plain arrays


@dataclass(frozen=True)
class _Arrays:
    """A mesh's arrays read once (trimesh re-checks its content hash on every property read):
    vertices V, faces F, triangles (n, 3, 3), normals N, centres C, bounding-box diagonal and
    centre of mass."""

    V: np.ndarray
    F: np.ndarray
    tri: np.ndarray
    N: np.ndarray
    C: np.ndarray
    diag: float
    com: np.ndarray


def _arrays(mesh: "trimesh.Trimesh") -> _Arrays:
    """The arrays of ``mesh``, kept in its metadata (they live and die with the mesh)."""
    a = mesh.metadata.get("_spar_arrays")
    if a is None:
        V = np.asarray(mesh.vertices, float)
        F = np.asarray(mesh.faces)
        a = _Arrays(V, F, V[F], np.asarray(mesh.face_normals, float), np.asarray(mesh.triangles_center, float),
                    float(np.linalg.norm(V.max(0) - V.min(0))), np.asarray(mesh.center_mass, float))
        mesh.metadata["_spar_arrays"] = a
    return a


def hull_vertices(mesh: "trimesh.Trimesh") -> np.ndarray:
    """Indices of the mesh's vertices on its convex hull (sorted; kept in the mesh's metadata).

    qhull with joggled input (``QJ``): a finely tessellated round part has thousands of
    coplanar and cocircular points, which qhull's default facet merging took 0.25 s over
    (5,000 points); joggling is 15-50x faster and moves a point by about 1e-11 of the part's
    size, so it can only keep or drop a point that far from the hull. Qhull's default is
    the fallback if joggling fails."""
    h = mesh.metadata.get("_spar_hull")
    if h is None:
        from scipy.spatial import ConvexHull, QhullError  # ~0.7 s at import: a model with a hull only

        V = _arrays(mesh).V
        try:
            h = np.sort(ConvexHull(V, qhull_options="QJ").vertices)
        except QhullError:
            h = np.sort(ConvexHull(V).vertices)
        mesh.metadata["_spar_hull"] = h
    return h


def _hull_mesh(P: np.ndarray) -> "trimesh.Trimesh":
    """The convex hull of points P as a closed, outward-oriented trimesh (qhull's facets,
    each turned to agree with its outward plane normal)."""
    import trimesh  # ~1.4 s at import (scipy with it): a derivation only
    from scipy.spatial import ConvexHull

    qh = ConvexHull(P)
    F = qh.simplices.copy()
    n = cross(P[F[:, 1]] - P[F[:, 0]], P[F[:, 2]] - P[F[:, 0]])
    flip = np.einsum("ij,ij->i", n, qh.equations[:, :3]) < 0
    F[flip] = F[flip][:, ::-1]
    return trimesh.Trimesh(P, F, process=True)


# =========================================================================== stable poses


def support_check(mesh: "trimesh.Trimesh", R: np.ndarray, faces: list[Face], unit: str,
                  com: np.ndarray | None = None) -> tuple[str | None, float, list[int]]:
    """Is the part at rotation R (object to world) resting quasi-statically on the table?

    Returns (why not or None, height of the object frame above the table, indices of the
    faces lying on the table). Independent of trimesh's pose search: the lowest points of
    the mesh are the support, their 2-D convex hull the support polygon, and the centre of
    mass must project inside it by STABLE_MARGIN_MM; the part must rest on a face.
    """
    tol = from_mm(unit, SUPPORT_TOL_MM)
    A = _arrays(mesh)
    V = A.V @ np.asarray(R, float).T
    zmin = float(V[:, 2].min())
    low = V[:, 2] < zmin + tol
    lying = [k for k, f in enumerate(faces) if (V[A.F[f.tris], 2] < zmin + tol).all(1).any()]
    if not lying:
        return "it rests on an edge or a point, not on a face", -zmin, []
    hull = convex_hull_2d(V[low, :2])
    cw = np.asarray(R, float) @ (A.com if com is None else com)
    c = cw[:2]
    margin = _inside_margin(hull, c)
    need = from_mm(unit, STABLE_MARGIN_MM)
    if margin < need:
        where = "outside" if margin < 0 else "only"
        return (f"its centre of mass is {where} {abs(margin):.4g} {unit} "
                f"{'from' if margin < 0 else 'inside'} the support polygon's edge (at least {need:.4g} {unit} "
                "inside needed)"), -zmin, lying
    tilt = math.degrees(math.atan2(margin, max(float(cw[2]) - zmin, 1e-300)))
    if tilt < STABLE_TILT_DEG:
        return (f"it tips over on a tilt of {tilt:.3g} deg (its centre of mass {float(cw[2]) - zmin:.4g} {unit} "
                f"high, {margin:.4g} {unit} inside the support polygon's edge; at least {STABLE_TILT_DEG:g} deg "
                "needed)"), -zmin, lying
    return None, -zmin, lying


def _inside_margin(hull: np.ndarray, c: np.ndarray) -> float:
    """Signed distance of point c inside the convex polygon ``hull`` (CCW, (k, 2)); negative
    outside; -inf for a degenerate polygon (fewer than 3 corners)."""
    if len(hull) < 3:
        return -math.inf
    a, b = hull, np.roll(hull, -1, axis=0)
    e = b - a
    L = np.linalg.norm(e, axis=1)
    ok = L > 0
    cross = e[ok, 0] * (c[1] - a[ok, 1]) - e[ok, 1] * (c[0] - a[ok, 0])
    return float((cross / L[ok]).min())


def _hidden(faces: list[Face], lying: list[int], features: tuple[FeatureGeometry, ...], R: np.ndarray,
            height: float, tol: float) -> list[int]:
    """The faces a pose hides: those lying on the table and each feature's face if its mouth
    (a hole) or tip (a peg) is on the table."""
    out = list(lying)
    for feature in features:
        mouth = feature.origin if feature.kind == "hole" else feature.end
        if abs(float((R @ mouth)[2]) + height) < tol:
            k = _feature_face(faces, feature)
            if k is not None and k not in out:
                out.append(k)
    return out


def _feature_face(faces: list[Face], feature: FeatureGeometry) -> int | None:
    """The index of ``feature``'s face among ``faces`` (None if its surfaces are not on the mesh)."""
    return next((i for i, f in enumerate(faces) if f.feature and f.name == feature.name), None)


def derive_poses(mesh: "trimesh.Trimesh", faces: list[Face], features: tuple[FeatureGeometry, ...], unit: str,
                 prefix: str, prob_floor: float = PROB_FLOOR) -> list[DerivedPose]:
    """The stable poses of the part (module docstring), most probable first, labelled
    ``{prefix}1, {prefix}2, ...``."""
    from spar_py.world.parts.stable import stable_poses

    A = _arrays(mesh)
    hv = A.V[hull_vertices(mesh)]
    if len(hv) > HULL_FACES_MAX // 2:
        # thin the hull's vertices on a grid of 1/HULL_GRID of the part's size: the topple
        # graph of a finely tessellated round part is otherwise most of the derivation; the
        # poses found are snapped to the real mesh's faces and checked on it below
        _, keep = np.unique(np.floor((hv - hv.min(0)) / (A.diag / HULL_GRID)).astype(np.int64), axis=0,
                            return_index=True)
        hv = hv[np.sort(keep)]
    hull = _hull_mesh(hv)
    Ts, probs = stable_poses(hull, A.com)
    tol = from_mm(unit, SUPPORT_TOL_MM)
    normals = [f.normal for f in faces if f.planar]
    normals += [f.direction for f in features if f.kind == "peg"]  # the tips' caps
    cos_snap = math.cos(math.radians(SNAP_DEG))
    found: list[tuple[float, np.ndarray, float, list[int], list[int]]] = []
    for T, p in zip(Ts, probs):
        if p < prob_floor:
            continue
        down = np.asarray(T, float)[:3, :3].T @ np.array([0.0, 0.0, -1.0])  # object vector pointing down
        best = max(normals, key=lambda n: float(n @ down), default=None)
        if best is not None and float(best @ down) > cos_snap:
            down = best
        R = clean(minimal_rotation(down, np.array([0.0, 0.0, -1.0])), 1e-9)
        if any(np.allclose(R[2], f[1][2], atol=1e-6) for f in found):
            continue
        why, height, lying = support_check(mesh, R, faces, unit)
        if why is not None:
            continue
        found.append((float(p), R, height, lying, _hidden(faces, lying, features, R, height, tol)))
    found.sort(key=lambda f: (-round(f[0], 9), tuple(np.round(f[1][2], 9))))
    return [DerivedPose(f"{prefix}{i + 1}", tuple(faces[k].name for k in lying),
                        tuple(faces[k].name for k in hidden), R, float(round(height, 12)), p)
            for i, (p, R, height, lying, hidden) in enumerate(found)]


# =========================================================================== boxes and triangles


def _tri_box(tri: np.ndarray, lo: np.ndarray, hi: np.ndarray,
             bbox: tuple[np.ndarray, np.ndarray] | None = None) -> np.ndarray:
    """(n,) bool: triangles (n, 3, 3) that meet the axis-aligned box [lo, hi] (separating axes:
    the box's 3 axes, the triangle's normal, the 9 edge cross products); ``bbox`` the
    triangles' (min, max) corners if already known."""
    c = (lo + hi) / 2
    h = (hi - lo) / 2
    tmin, tmax = bbox if bbox is not None else (tri.min(1), tri.max(1))
    keep = ((tmin <= hi) & (tmax >= lo)).all(1)
    if not keep.any():
        return keep
    idx = np.flatnonzero(keep)
    t = tri[idx] - c
    e = np.stack([t[:, 1] - t[:, 0], t[:, 2] - t[:, 1], t[:, 0] - t[:, 2]], axis=1)  # (m, 3, 3)
    n = cross(e[:, 0], e[:, 1])
    ok = np.abs(np.einsum("ij,ij->i", n, t[:, 0])) <= np.abs(n) @ h + 1e-15
    zero = np.zeros(e.shape[:2])
    ex, ey, ez = e[..., 0], e[..., 1], e[..., 2]
    for a in (np.stack([zero, -ez, ey], -1), np.stack([ez, zero, -ex], -1), np.stack([-ey, ex, zero], -1)):
        # a: (m, 3 edges, 3), the cross product of a box axis with each edge
        p = np.einsum("mjd,mvd->mjv", a, t)  # (m, edges, vertices)
        r = np.abs(a) @ h
        ok &= ~((p.min(2) > r + 1e-15) | (p.max(2) < -r - 1e-15)).any(1)
    keep[idx] = ok
    return keep


def _gripper_boxes(g: Gripper, width: float, reach: float, shrink: float) -> list[tuple[str, np.ndarray, np.ndarray]]:
    """(what, lo, hi) boxes in the tool frame: the closed fingers at ``width``, the open fingers
    and the palm swept in along the approach from ``reach`` away, each shrunk by ``shrink``."""
    u, L, t = g.finger_width / 2, g.finger_length, g.finger_thickness
    o, w = g.opening / 2, width / 2
    px, py = g.palm_half()
    boxes = [
        ("a finger", np.array([-u, w, -L]), np.array([u, w + t, 0.0])),
        ("a finger", np.array([-u, -w - t, -L]), np.array([u, -w, 0.0])),
        ("an open finger on the approach", np.array([-u, o, -reach]), np.array([u, o + t, 0.0])),
        ("an open finger on the approach", np.array([-u, -o - t, -reach]), np.array([u, -o, 0.0])),
        ("the palm", np.array([-px, -py, -reach]), np.array([px, py, -L])),
    ]
    return [(what, lo + shrink, hi - shrink) for what, lo, hi in boxes if np.all(hi - lo > 2 * shrink)]


class _BVH:
    """A mesh's python-fcl collision object, kept in its metadata with the arrays it was built
    from; a copy of the mesh (trimesh deep-copies metadata; fcl's objects cannot be) gets none."""

    def __init__(self, of: _Arrays, obj: Any) -> None:
        self.of, self.obj = of, obj

    def __deepcopy__(self, memo: dict) -> None:
        return None


def _bvh(mesh: "trimesh.Trimesh") -> Any:
    """The mesh's triangles as a python-fcl collision object (a BVH, object frame)."""
    A = _arrays(mesh)
    c = mesh.metadata.get("_spar_bvh")
    if c is not None and c.of is A:
        return c.obj
    import fcl  # on a derivation only (a cache miss); world.product.assembly's sweeps import it too
    from spar_py.world.collision import bvh

    obj = fcl.CollisionObject(bvh(A.V, A.F), fcl.Transform())
    mesh.metadata["_spar_bvh"] = _BVH(A, obj)
    return obj


def grasp_problem(mesh: "trimesh.Trimesh", T: np.ndarray, width: float, g: Gripper, unit: str) -> str | None:
    """Why the gripper at tool pose T (object frame) with fingers ``width`` apart cannot hold the
    part, or None: wider than the opening, or a finger or the palm inside the part (a box of
    :func:`_gripper_boxes` meets one of its triangles: python-fcl's box-triangle test over the
    mesh's BVH; the boxes are shrunk by TOUCH_MM, so a finger resting on a face is not in it)."""
    if width > g.opening * (1 + 1e-9):
        return f"{width:.4g} {unit} wide, more than the gripper's opening {g.opening:.4g} {unit}"
    import fcl

    A = _arrays(mesh)
    reach = 2 * A.diag + g.finger_length + g.palm_depth
    part = _bvh(mesh)
    R, o = np.asarray(T, float)[:3, :3], np.asarray(T, float)[:3, 3]
    request = fcl.CollisionRequest()
    for what, lo, hi in _gripper_boxes(g, width, reach, from_mm(unit, TOUCH_MM)):
        box = fcl.CollisionObject(fcl.Box(*(hi - lo)), fcl.Transform(R, R @ ((lo + hi) / 2) + o))
        if fcl.collide(box, part, request, fcl.CollisionResult()):
            return f"{what} enters the part"
    return None


# =========================================================================== polygons


def _clip(poly: list, a: tuple, b: float) -> list:
    """Sutherland-Hodgman: the part of convex polygon ``poly`` (list of (x, y)) with a . p <= b."""
    out = []
    k = len(poly)
    if not k:
        return out
    ax, ay = a
    sv = [ax * x + ay * y - b for x, y in poly]
    for i in range(k):
        (px, py), (qx, qy), sp, sq = poly[i], poly[(i + 1) % k], sv[i], sv[(i + 1) % k]
        if sp <= 0:
            out.append((px, py))
        if (sp < 0 < sq) or (sq < 0 < sp):
            t = sp / (sp - sq)
            out.append((px + (qx - px) * t, py + (qy - py) * t))
    return out


def _clip_convex(poly: "np.ndarray | list", clip: "np.ndarray | list") -> list:
    """The intersection of convex polygon ``poly`` with convex CCW polygon ``clip`` (lists of (x, y))."""
    P = [(float(x), float(y)) for x, y in poly]
    C = [(float(x), float(y)) for x, y in clip]
    for i in range(len(C)):
        (px, py), (qx, qy) = C[i], C[(i + 1) % len(C)]
        n = (qy - py, -(qx - px))  # outward normal of a CCW edge
        P = _clip(P, n, n[0] * px + n[1] * py)
        if not P:
            break
    return P


def _area_centroid(poly: "np.ndarray | list") -> tuple[float, np.ndarray]:
    """|area| and centroid of a simple polygon (list or (k, 2) array of corners)."""
    k = len(poly)
    if k < 3:
        return 0.0, np.zeros(2)
    A = cx = cy = 0.0
    for i in range(k):
        x, y = poly[i]
        xn, yn = poly[(i + 1) % k]
        c = float(x) * float(yn) - float(xn) * float(y)
        A += c
        cx += (float(x) + float(xn)) * c
        cy += (float(y) + float(yn)) * c
    if abs(A) < 1e-300:
        return 0.0, np.zeros(2)
    return abs(A) / 2, np.array([cx, cy]) / (3 * A)


def _pack(polys: "list[np.ndarray]") -> tuple[np.ndarray, np.ndarray]:
    """Polygons of different sizes as one (n, K, 2) array (rows padded with zeros) and their
    corner counts (n,)."""
    cnt = np.array([len(p) for p in polys], int)
    P = np.zeros((len(polys), int(cnt.max()) if len(polys) else 0, 2))
    for i, p in enumerate(polys):
        P[i, : len(p)] = p
    return P, cnt


def _unpack(P: np.ndarray, cnt: np.ndarray, rows: "np.ndarray | range") -> list[np.ndarray]:
    return [P[i, : cnt[i]].copy() for i in rows]


def _next_corner(cnt: np.ndarray, K: int) -> np.ndarray:
    """(n, K): the index of each corner's successor in its polygon (0 past the last corner)."""
    j = np.arange(K)[None, :]
    return np.where(j < cnt[:, None], (j + 1) % np.maximum(cnt, 1)[:, None], 0)


def _clip_many(P: np.ndarray, cnt: np.ndarray, clip: "np.ndarray | list") -> tuple[np.ndarray, np.ndarray]:
    """:func:`_clip_convex` of many convex polygons at once (P (n, K, 2) with ``cnt`` corners
    each) against convex CCW polygon ``clip`` ((m, 2), or (n, m, 2): one per polygon): the same
    arithmetic, corner by corner, so each result is the one :func:`_clip_convex` gives.
    Returns the clipped polygons and counts."""
    C = np.asarray(clip, float)
    C = np.broadcast_to(C, (len(P), *C.shape)) if C.ndim == 2 else C
    rows = np.arange(len(P))[:, None]
    for i in range(C.shape[1]):
        K = P.shape[1]
        if K == 0 or not cnt.any():
            break
        px, py = C[:, i, 0, None], C[:, i, 1, None]
        qx, qy = C[:, (i + 1) % C.shape[1], 0, None], C[:, (i + 1) % C.shape[1], 1, None]
        ax, ay = qy - py, -(qx - px)  # outward normal of a CCW edge
        b = ax * px + ay * py
        valid = np.arange(K)[None, :] < cnt[:, None]
        Q = P[rows, _next_corner(cnt, K)]
        sp = ax * P[..., 0] + ay * P[..., 1] - b
        sq = ax * Q[..., 0] + ay * Q[..., 1] - b
        keep = valid & (sp <= 0)
        cut = valid & (((sp < 0) & (0 < sq)) | ((sq < 0) & (0 < sp)))
        t = sp / np.where(cut, sp - sq, 1.0)
        cand = np.empty((len(P), K, 2, 2))  # corner k's kept point, then its cut point
        cand[:, :, 0] = P
        cand[:, :, 1, 0] = P[..., 0] + (Q[..., 0] - P[..., 0]) * t
        cand[:, :, 1, 1] = P[..., 1] + (Q[..., 1] - P[..., 1]) * t
        cand = cand.reshape(len(P), 2 * K, 2)
        m = np.empty((len(P), K, 2), bool)
        m[:, :, 0], m[:, :, 1] = keep, cut
        m = m.reshape(len(P), 2 * K)
        order = np.argsort(~m, axis=1, kind="stable")
        cnt = m.sum(1)
        P = cand[rows, order][:, : int(cnt.max()) if len(cnt) else 0]
    return P, cnt


def _area_centroid_many(P: np.ndarray, cnt: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """:func:`_area_centroid` of many polygons at once (P (n, K, 2), ``cnt`` corners each),
    summed corner by corner as it does: (areas (n,), centroids (n, 2))."""
    n, K = P.shape[:2]
    A, cx, cy = np.zeros(n), np.zeros(n), np.zeros(n)
    nxt = _next_corner(cnt, K)
    rows = np.arange(n)
    for i in range(K):
        act = i < cnt
        x, y = P[:, i, 0], P[:, i, 1]
        xn, yn = P[rows, nxt[:, i], 0], P[rows, nxt[:, i], 1]
        c = x * yn - xn * y
        A = np.where(act, A + c, A)
        cx = np.where(act, cx + (x + xn) * c, cx)
        cy = np.where(act, cy + (y + yn) * c, cy)
    ok = (cnt >= 3) & ~(np.abs(A) < 1e-300)
    den = np.where(ok, 3 * A, 1.0)
    cen = np.where(ok[:, None], np.stack([cx / den, cy / den], axis=1), 0.0)
    return np.where(ok, np.abs(A) / 2, 0.0), cen


def _ccw(P: np.ndarray) -> np.ndarray:
    """Polygon ``P`` (k, 2) with its corners counter-clockwise (reversed if its signed area is
    negative); the successors by slicing, np.roll's values without its overhead."""
    x, y = P[:, 0], P[:, 1]
    xn, yn = np.concatenate((x[1:], x[:1])), np.concatenate((y[1:], y[:1]))
    return P if (x * yn - xn * y).sum() >= 0 else P[::-1]


def _overlap(mesh: "trimesh.Trimesh", fa: Face, fb: Face, e1: np.ndarray, e2: np.ndarray) -> list[np.ndarray]:
    """The convex pieces (each (k, 2) in the plane basis e1, e2) where the two faces overlap
    when projected on a plane normal to them: each triangle of the face with more (A) clipped
    by each triangle of the other (B) whose box meets its box, in B's order; a triangle of A
    wholly inside one of B is that triangle's piece and no later one's. All pairs at once
    (numpy), the pieces in the order a loop over B would give them."""
    arr = _arrays(mesh)
    E = np.array([e1, e2]).T
    A, B = _ccw_all(arr.tri[fa.tris] @ E), _ccw_all(arr.tri[fb.tris] @ E)   # (n, 3, 2) each
    if len(A) < len(B):
        A, B = B, A  # clip the many against the few
    ii, jj = _box_pairs(A.min(1), A.max(1), B.min(1), B.max(1))
    if not len(ii):
        return []
    inside = _in_triangles(A[ii], B[jj])
    first = np.full(len(A), len(B))  # the first B triangle each A triangle lies in
    np.minimum.at(first, ii[inside], jj[inside])
    take = jj <= first[ii]
    ii, jj, inside = ii[take], jj[take], inside[take]
    cut = np.flatnonzero(~inside)
    P, cnt = _clip_many(A[ii[cut]], np.full(len(cut), 3), B[jj[cut]])
    area, _ = _area_centroid_many(P, cnt)
    ok = (cnt >= 3) & (area > 0)
    # by B triangle, those wholly inside first, then the clipped ones, each by A's order
    whole = np.flatnonzero(inside)
    keys_j = np.r_[jj[whole], jj[cut][ok]]
    keys_k = np.r_[np.zeros(len(whole), int), np.ones(int(ok.sum()), int)]
    keys_i = np.r_[ii[whole], ii[cut][ok]]
    items = [A[i] for i in ii[whole]] + _unpack(P, cnt, np.flatnonzero(ok))
    return [items[k] for k in np.lexsort((keys_i, keys_k, keys_j))]


def _box_pairs(alo: np.ndarray, ahi: np.ndarray, blo: np.ndarray, bhi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The pairs (i, j) of 2-D boxes A[i], B[j] (corners lo, hi) that meet, closed, ordered by
    j then i: both sets binned on a grid of cells the size of a median box, the pairs sharing a
    cell tested (two closed boxes that meet share the cell of their overlap's lowest corner);
    a box over more than BOX_CELLS_MAX cells is tested against every box of the other set."""
    na, nb = len(alo), len(blo)
    if not na or not nb:
        return np.zeros(0, int), np.zeros(0, int)
    ext = np.concatenate([ahi - alo, bhi - blo])
    size = float(np.median(ext.max(1)))
    if not size > 0:
        size = float(ext.max()) or 1.0
    origin = np.minimum(alo.min(0), blo.min(0))
    span = int(np.floor((max(ahi[:, 1].max(), bhi[:, 1].max()) - origin[1]) / size)) + 2
    keys_a, rows_a, wide_a = _box_cells(alo, ahi, origin, size, span)
    keys_b, rows_b, wide_b = _box_cells(blo, bhi, origin, size, span)
    order = np.argsort(keys_a, kind="stable")
    keys_a, rows_a = keys_a[order], rows_a[order]
    start = np.searchsorted(keys_a, keys_b, "left")
    counts = np.searchsorted(keys_a, keys_b, "right") - start
    jj = np.repeat(rows_b, counts)
    ii = rows_a[np.repeat(start - np.cumsum(counts) + counts, counts) + np.arange(int(counts.sum()))]
    cell = np.repeat(keys_b, counts)
    meet = ((alo[ii] <= bhi[jj]) & (ahi[ii] >= blo[jj])).all(1)
    ii, jj, cell = ii[meet], jj[meet], cell[meet]
    # a pair over several shared cells is kept in the one of its overlap's lowest corner only
    c = np.floor((np.maximum(alo[ii], blo[jj]) - origin) / size).astype(np.int64)
    own = c[:, 0] * span + c[:, 1] == cell
    ii, jj = [ii[own]], [jj[own]]
    narrow_a = np.setdiff1d(np.arange(na), wide_a)
    for wi, wj in ((np.repeat(wide_a, nb), np.tile(np.arange(nb), len(wide_a))),
                   (np.tile(narrow_a, len(wide_b)), np.repeat(wide_b, len(narrow_a)))):
        m = ((alo[wi] <= bhi[wj]) & (ahi[wi] >= blo[wj])).all(1)
        ii.append(wi[m])
        jj.append(wj[m])
    i_all, j_all = np.concatenate(ii), np.concatenate(jj)
    order = np.lexsort((i_all, j_all))
    return i_all[order], j_all[order]


#: A box over more cells than this (of the median box's size) is tested against every other.
BOX_CELLS_MAX = 64


def _box_cells(lo: np.ndarray, hi: np.ndarray, origin: np.ndarray, size: float, span: int
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The grid cells (of side ``size`` from ``origin``; key column * span + row) each box
    covers, as (cell keys, box rows), and the boxes over more than BOX_CELLS_MAX cells (left
    out of the former)."""
    c0 = np.floor((lo - origin) / size).astype(np.int64)
    c1 = np.floor((hi - origin) / size).astype(np.int64)
    w = c1 - c0 + 1
    n = w[:, 0] * w[:, 1]
    wide = np.flatnonzero(n > BOX_CELLS_MAX)
    n = np.where(n > BOX_CELLS_MAX, 0, n)
    rows = np.repeat(np.arange(len(lo)), n)
    local = np.arange(int(n.sum())) - np.repeat(np.cumsum(n) - n, n)
    cx = c0[rows, 0] + local % w[rows, 0]
    cy = c0[rows, 1] + local // w[rows, 0]
    return cx * span + cy, rows, wide


def _in_triangles(T: np.ndarray, C: np.ndarray, eps: float = 1e-12) -> np.ndarray:
    """(n,) bool: all three corners of each triangle T[k] (n, 3, 2) in the closed CCW triangle
    C[k] (n, 3, 2): on the inner side of each of its edges, up to ``eps``."""
    ok = np.ones(T.shape[:2], bool)
    for i in range(3):
        a, b = C[:, i, None], C[:, (i + 1) % 3, None]  # (n, 1, 2)
        ok &= ((b[..., 0] - a[..., 0]) * (T[..., 1] - a[..., 1])
               - (b[..., 1] - a[..., 1]) * (T[..., 0] - a[..., 0])) >= -eps
    return ok.all(1)


def _ccw_all(T: np.ndarray) -> np.ndarray:
    """Triangles (n, 3, 2) with their corners counter-clockwise."""
    d = (T[:, 1, 0] - T[:, 0, 0]) * (T[:, 2, 1] - T[:, 0, 1]) - (T[:, 1, 1] - T[:, 0, 1]) * (T[:, 2, 0] - T[:, 0, 0])
    out = T.copy()
    out[d < 0] = T[d < 0][:, ::-1]
    return out


# =========================================================================== grasps


def euler_zyz_of(T: np.ndarray) -> tuple[float, float, float, float, float, float]:
    """(X, Y, Z, phi, theta, psi) with geometry.eulerxyz(...) == T (Paul's Z-Y-Z, radians)."""
    R = T[:3, :3]
    theta = math.acos(max(-1.0, min(1.0, float(R[2, 2]))))
    if abs(math.sin(theta)) > 1e-9:
        phi = math.atan2(R[1, 2], R[0, 2])
        psi = math.atan2(R[2, 1], -R[2, 0])
    elif R[2, 2] > 0:
        phi, psi = 0.0, math.atan2(R[1, 0], R[0, 0])
    else:
        phi, psi = 0.0, math.atan2(R[0, 1], R[1, 1])

    def tidy(a: float) -> float:
        d = round(math.degrees(a), 9)
        d = 180.0 if d == -180.0 else d
        return math.radians(d) + 0.0

    x, y, z = (float(v) + 0.0 for v in T[:3, 3])
    return (x, y, z, tidy(phi), tidy(theta), tidy(psi))


def _canonical(c: np.ndarray) -> np.ndarray:
    """The closing direction with its largest component (the first of equals) positive."""
    i = int(np.argmax(np.round(np.abs(c), 9) - 1e-12 * np.arange(3)))
    return c if c[i] > 0 else -c


def _tool(p: np.ndarray, c: np.ndarray, a: np.ndarray) -> np.ndarray:
    """The tool frame at p with y = c (closing) and z = a (approach)."""
    T = np.eye(4)
    T[:3, 0], T[:3, 1], T[:3, 2], T[:3, 3] = cross(c, a), c, a, p
    return clean(T, 1e-9)


def _approaches(c: np.ndarray, step: float) -> list[np.ndarray]:
    e1, e2 = axis_basis(c)
    n = max(1, int(round(2 * math.pi / step)))
    return [clean(math.cos(2 * math.pi * k / n) * e1 + math.sin(2 * math.pi * k / n) * e2, 1e-12) for k in range(n)]


def _covered(mesh: "trimesh.Trimesh", faces: list[Face], features: tuple[FeatureGeometry, ...], T: np.ndarray,
             width: float, g: Gripper, unit: str) -> set[int]:
    """The faces the gripper at T covers: a planar face if the palm or a closed finger reaches
    beyond its plane (the part could not rest on that face while held); a feature's face if
    they enter the space the mating part needs (a peg: the prism of half-width r about the shaft
    from its root outwards; a hole: that about the hole's axis out of its mouth)."""
    s = from_mm(unit, TOUCH_MM)
    reach = g.finger_length + g.palm_depth
    boxes = [b for b in _gripper_boxes(g, width, reach, s) if "open" not in b[0]]
    corners = np.concatenate([np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1])
                                        for z in (lo[2], hi[2])]) for _, lo, hi in boxes])
    P = corners @ T[:3, :3].T + T[:3, 3]  # gripper corners in the object frame
    out = {k for k, f in enumerate(faces) if f.planar and (P @ f.normal > f.offset + s).any()}
    for feature in features:
        k = _feature_face(faces, feature)
        if k is not None:
            e1, e2 = axis_basis(feature.direction)
            F = np.eye(4)
            F[:3, 0], F[:3, 1], F[:3, 2], F[:3, 3] = e1, e2, feature.direction, feature.origin
            big = 10 * _arrays(mesh).diag + reach
            r = feature.reach
            lo, hi = (np.array([-r, -r, 0.0]), np.array([r, r, big])) if feature.kind == "peg" else (
                np.array([-r, -r, -big]), np.array([r, r, 0.0]))
            M = np.linalg.inv(F) @ T  # tool frame in the feature's frame
            for _, blo, bhi in boxes:
                c = np.array([[x, y, z] for x in (blo[0], bhi[0]) for y in (blo[1], bhi[1]) for z in (blo[2], bhi[2])])
                quads = c[[0, 1, 3, 2, 4, 5, 7, 6]] @ M[:3, :3].T + M[:3, 3]
                tri = quads[np.array([[0, 1, 2], [0, 2, 3], [4, 5, 6], [4, 6, 7], [0, 1, 5], [0, 5, 4],
                                      [2, 3, 7], [2, 7, 6], [1, 2, 6], [1, 6, 5], [0, 3, 7], [0, 7, 4]])]
                inside = ((quads > lo) & (quads < hi)).all(1).any()
                if inside or _tri_box(tri, lo + s, hi - s).any():
                    out.add(k)
                    break
    return out


def _shafts(faces: list[Face], features: tuple[FeatureGeometry, ...], prims: tuple[Primitive, ...],
            mesh: "trimesh.Trimesh | None" = None, unit: str = "mm"
            ) -> list[tuple[np.ndarray, np.ndarray, float, float, str | None]]:
    """Round shafts to grasp across: (root, unit axis, radius, length, face name or None): the
    peg features', the cylinder primitives', then the outer cylinders found on the mesh
    (:func:`mesh_cylinders`: a shoulder, a shaft not declared as a feature), each once."""
    out = [(f.origin, f.direction, f.radius, f.length, f.name) for f in features
           if f.kind == "peg" and f.profile == "round"]
    for p in prims:
        root, d = np.array([0.0, 0.0, p.lo[2]]), np.array([0.0, 0.0, 1.0])
        same = [np.allclose(root, o) and np.allclose(d, a) and abs(p.radius - r) < 1e-9 for o, a, r, _, _ in out]
        if p.kind == "cylinder" and not p.subtract and not any(same):
            out.append((np.array([0.0, 0.0, p.lo[2]]), np.array([0.0, 0.0, 1.0]), p.radius, p.hi[2] - p.lo[2], None))
    if mesh is not None:
        tol = from_mm(unit, ON_SURFACE_MM)
        for c in mesh_cylinders(mesh, faces, unit):
            # one already listed on the same line with the same radius (the feature, a primitive)
            if any(abs(r - c.radius) < tol and abs(abs(float(a @ c.axis)) - 1) < 1e-6
                   and np.linalg.norm(np.cross(c.root - o, a)) < tol for o, a, r, _, _ in out):
                continue
            out.append((c.root, c.axis, c.radius, c.length, c.face))
    return out


#: A face is a cylinder when its triangles' normals are normal to one axis within this (deg) ...
CYL_AXIS_DEG = 0.5
#: ... and its vertices lie at one distance from it within this fraction of the radius (a 32-gon's
#: vertices are on its circle; its triangles' centres 0.5 % inside).
CYL_RADIUS_REL = 0.005
#: Both pads touch the cylinder where it has triangles whose normals are within this of the
#: closing direction, either way (deg): a half-round surface is not closed on across.
CYL_PAD_DEG = 15.0


@dataclass(frozen=True)
class MeshCylinder:
    """An outer cylindrical surface of a mesh (object frame, cell unit): its ``face`` (a derived
    face name), the ``root`` on its axis at one end, the unit ``axis`` towards the other end, the
    ``radius`` and ``length``, and the unit ``normals`` of its triangles (for which closing
    directions both pads find it)."""

    face: str
    root: np.ndarray
    axis: np.ndarray
    radius: float
    length: float
    normals: np.ndarray


def fit_circle(V: np.ndarray, d: np.ndarray, rel: float) -> tuple[np.ndarray, float] | None:
    """The least-squares circle through points ``V`` (k, 3) projected across the unit axis ``d``
    (x^2 + y^2 + a x + b y + c = 0 in axis_basis(d)): the point of the axis nearest the origin
    and the radius, or None when some point is off that circle by more than ``rel`` of it."""
    e1, e2 = axis_basis(d)
    P = np.column_stack([V @ e1, V @ e2])
    M = np.column_stack([P, np.ones(len(P))])
    sol = np.linalg.lstsq(M, -(P ** 2).sum(1), rcond=None)[0]
    c = -sol[:2] / 2
    r = float(np.sqrt(max(c @ c - sol[2], 0.0)))
    if not r > 0 or np.abs(np.linalg.norm(P - c, axis=1) - r).max() > rel * r:
        return None
    return c[0] * e1 + c[1] * e2, r


def mesh_cylinders(mesh: "trimesh.Trimesh", faces: list[Face], unit: str) -> list[MeshCylinder]:
    """The outer cylindrical surfaces of the mesh, one per curved derived face that is one: the
    axis the face's normals are all normal to (the least eigenvector of the area-weighted sum of
    n n^T, within CYL_AXIS_DEG), its vertices at one distance from it (a least-squares circle in
    the plane normal to the axis, within CYL_RADIUS_REL), its normals pointing away from it (a
    shaft, not a bore). Kept in the mesh's metadata."""
    key = (tuple(f.name for f in faces), unit)
    got = mesh.metadata.get("_spar_cylinders")
    if got is not None and got[0] == key:
        return got[1]
    A = _arrays(mesh)
    area = np.asarray(mesh.area_faces, float)
    sin_tol = math.sin(math.radians(CYL_AXIS_DEG))
    out = []
    for f in faces:
        if f.planar or f.feature or len(f.tris) < 6:
            continue
        N, w = A.N[f.tris], area[f.tris]
        vals, vecs = np.linalg.eigh((N * w[:, None]).T @ N)
        d = vecs[:, 0]
        if np.abs(N @ d).max() > sin_tol or vals[1] < 1e-6 * vals[2]:
            continue  # not normal to one axis (a cone, a sphere), or all normals one way (a plane)
        d = clean(d / np.linalg.norm(d), 1e-12)
        d = _canonical(d)
        V = A.V[np.unique(A.F[f.tris])]
        fit = fit_circle(V, d, CYL_RADIUS_REL)
        if fit is None:
            continue
        centre, r = fit
        t = V @ d
        radial = A.C[f.tris] - centre - np.outer(A.C[f.tris] @ d, d)
        if (np.einsum("ij,ij->i", radial, N) <= 0).any():
            continue  # normals towards the axis: a bore
        root = clean(centre + float(t.min()) * d, 1e-9)
        out.append(MeshCylinder(f.name, root, d, float(round(r, 12)), float(t.max() - t.min()), N.copy()))
    mesh.metadata["_spar_cylinders"] = (key, out)
    return out


def _pads_find(normals: np.ndarray | None, c: np.ndarray) -> bool:
    """Both pads closing along +-c find the surface of triangle ``normals`` (None: a whole round)."""
    if normals is None:
        return True
    cos = math.cos(math.radians(CYL_PAD_DEG))
    return bool((normals @ c > cos).any() and (normals @ -c > cos).any())


def derive_grasps(mesh: "trimesh.Trimesh", faces: list[Face], features: tuple[FeatureGeometry, ...],
                  prims: tuple[Primitive, ...], g: Gripper, unit: str, prefix: str,
                  step: float = math.radians(45.0), why: list[str] | None = None,
                  poses: "list[DerivedPose] | None" = None) -> list[DerivedGrasp]:
    """The grasps of the part (module docstring), labelled ``{prefix}1, {prefix}2, ...``: those
    across opposite planar faces and round shafts, then the antipodal grasps found on the
    surface (:func:`antipodal_grasps`): all of them where the first give none; otherwise, on a
    mesh part (no ``prims``), those with a contact on a curved face that no facet or shaft grasp
    closes on and no feature claims (a wheel's tyre beside its axle's grasps; a declared peg is
    the shaft grasps' to close on), while a part of primitives keeps exactly its facet and
    shaft grasps. With none at all, ``why`` (when given) receives one line
    saying which sizes and opening were compared. With the part's stable ``poses``, the
    shallower facet grasps that keep the fingers above the table (:func:`_table_clear`) follow
    the others; the facet grasps at half depth (:func:`_half_depth`) come last."""
    min_area = from_mm(unit, math.sqrt(MIN_CONTACT_MM2)) ** 2
    cos_par = math.cos(math.radians(PARALLEL_DEG))
    cands: list[tuple[tuple[str, ...], float, np.ndarray]] = []  # (gfaces, width, T)
    shallow: list[tuple[tuple[str, ...], float, np.ndarray]] = []  # the same, backed off (_table_clear)
    pending: list[tuple[tuple[str, ...], float, np.ndarray, tuple]] = []  # facet candidates, their pieces
    planar = [k for k, f in enumerate(faces) if f.planar]
    for i in planar:
        for j in planar:
            fa, fb = faces[i], faces[j]
            if j <= i or fa.normal @ fb.normal > -cos_par:
                continue
            width = fa.offset + fb.offset  # n_b = -n_a: the part lies between the planes
            if width <= 0 or width > g.opening * (1 + 1e-9):
                continue
            c = _canonical(fa.normal)
            e1, e2 = axis_basis(c)
            pieces = _overlap(mesh, fa, fb, e1, e2)
            areas, cens = _area_centroid_many(*_pack(pieces))
            area = float(areas.sum())
            if area < min_area:
                continue
            cen2 = sum(float(a) * q for a, q in zip(areas, cens)) / area
            mid = (fa.offset - width / 2) * fa.normal
            p = clean(mid + cen2[0] * e1 + cen2[1] * e2, 1e-9)
            names = tuple(sorted((fa.name, fb.name), key=lambda n: [f.name for f in faces].index(n)))
            flat = _flatten(pieces)
            for a in _approaches(c, step):
                T = _tool(p, c, a)
                if _pad_contact(flat, areas, e1, e2, T, g, min_area) >= min_area:
                    cands.append((names, width, T))
                    for Ts in _table_clear(T, width, g, poses or [], unit):
                        if _pad_contact(flat, areas, e1, e2, Ts, g, min_area) >= min_area:
                            shallow.append((names, width, Ts))
                    pending.append((names, width, T, (flat, areas, e1, e2)))
    min_len = from_mm(unit, MIN_CONTACT_MM)
    cyl_normals = {c.face: c.normals for c in mesh_cylinders(mesh, faces, unit)}
    n_pegs = sum(1 for f in features if f.kind == "peg" and f.profile == "round")  # _shafts lists them first
    at_root: list[tuple[tuple[str, ...], float, np.ndarray]] = []  # a peg's shaft held at its root end
    for k_shaft, (root, d, r, length, fname) in enumerate(_shafts(faces, features, prims, mesh, unit)):
        if not _round(mesh, root, d, r, length, unit):
            continue  # a prismatic shaft (a hexagon): its flats are not a cylinder to close on
        normals = cyl_normals.get(fname) if fname is not None else None  # a mesh cylinder's; else a whole round
        name = fname if fname is not None else _face_at(faces, mesh, root + d * length / 2 + axis_basis(d)[0] * r,
                                                       unit)
        if name is None or 2 * r > g.opening * (1 + 1e-9):
            continue
        p = clean(root + d * length / 2, 1e-9)
        e1, e2 = axis_basis(d)
        n_dirs = max(1, int(round(math.pi / step)))
        for m in range(n_dirs):
            c = _canonical(clean(math.cos(math.pi * m / n_dirs) * e1 + math.sin(math.pi * m / n_dirs) * e2, 1e-12))
            if not _pads_find(normals, c):
                continue
            for a in _approaches(c, step):
                T = _tool(p, c, a)
                # at least MIN_CONTACT_MM up to rounding: a 10 mm shaft closed on at 45 deg has
                # exactly 5 mm under the pad, which rounding puts just below it in some units
                if _line_contact(root + c * r, d, length, T, g) >= min_len * (1 - 1e-9):
                    cands.append(((name,), 2 * r, T))
                if k_shaft >= n_pegs or float(a @ d) < -1e-9:
                    continue
                # a peg's also at its root end: the pad's far edge along the shaft MIN_CONTACT_MM
                # from the root (the hand beyond the root, clear of the hole the rest goes into)
                t_root = min_len - g.finger_width / 2 * abs(float(cross(c, a) @ d))
                if t_root < length / 2 - 1e-9 * (1.0 + length):
                    T = _tool(clean(root + d * t_root, 1e-9), c, a)
                    if _line_contact(root + c * r, d, length, T, g) >= min_len * (1 - 1e-9):
                        at_root.append(((name,), 2 * r, T))
        for T in _shaft_from_above(mesh, root, d, r, length, g, unit, poses or [], min_len):
            if _pads_find(normals, T[:3, 1]):
                shallow.append(((name,), 2 * r, T))
    cands += at_root
    out = _facet_grasps(mesh, faces, features, g, unit, prefix, cands, [], unique=False)
    kept = np.array([d.T for d in out]).reshape(-1, 4, 4)
    half: list[tuple[tuple[str, ...], float, np.ndarray]] = []  # the kept facet grasps at half depth
    for names, width, T, pieces in pending:
        if len(kept) and np.abs(kept - T).max(axis=(1, 2)).min() <= 1e-9:
            Th = _half_depth(T, *pieces, g, unit, min_area)
            if Th is not None:
                half.append((names, width, Th))
    owner = np.full(len(mesh.faces), -1)
    for k, f in enumerate(faces):
        owner[f.tris] = k
    allowed = None  # triangles one contact of an added antipodal grasp must lie on (None: any)
    if out:
        if prims:  # a part of primitives keeps exactly its facet and shaft grasps
            return _facet_grasps(mesh, faces, features, g, unit, prefix, shallow + half, out)
        held = {n for d in out for n in d.gfaces}
        free = [k for k, f in enumerate(faces) if not (f.planar or f.feature) and f.name not in held]
        if not free:
            return _facet_grasps(mesh, faces, features, g, unit, prefix, shallow + half, out)
        allowed = np.isin(owner, free)
    found, least, n_pairs = antipodal_grasps(mesh, g, unit, step, allowed)
    order = [f.name for f in faces]
    for T, width, a in found:
        names = tuple(dict.fromkeys(faces[k].name for k in (owner[a.tp], owner[a.tq]) if k >= 0))
        cover = {faces[k].name for k in _covered(mesh, faces, features, T, width, g, unit)}
        ofaces = names + tuple(sorted(cover - set(names), key=order.index))
        out.append(DerivedGrasp(f"{prefix}{len(out) + 1}", names, ofaces, T, euler_zyz_of(T), float(round(width, 12))))
    out = _facet_grasps(mesh, faces, features, g, unit, prefix, shallow + half, out)
    if not out and why is not None:
        if least is None:
            why.append(f"no two points of its surface face each other within {FRICTION_DEG:g} deg (a sample of "
                       f"{ANTIPODAL_SAMPLES} surface points)")
        elif least > g.opening:
            why.append(f"its narrowest width across opposite surfaces (within {FRICTION_DEG:g} deg) is {least:.4g} "
                       f"{unit}, more than the gripper's opening {g.opening:.4g} {unit}")
        elif not n_pairs:
            why.append(f"its narrowest width across opposite surfaces is {least:.4g} {unit}, within the gripper's "
                       f"opening {g.opening:.4g} {unit}, but no pad finds a {PAD_PATCH_MM:g} mm line of surface there")
        else:
            why.append(f"{n_pairs} contact pairs from {least:.4g} {unit} wide are within the gripper's opening "
                       f"{g.opening:.4g} {unit}, but at each the fingers or palm enter the part")
    return out


def _facet_grasps(mesh: "trimesh.Trimesh", faces: list[Face], features: tuple[FeatureGeometry, ...], g: Gripper,
                  unit: str, prefix: str, cands: list[tuple[tuple[str, ...], float, np.ndarray]],
                  out: list[DerivedGrasp], unique: bool = True) -> list[DerivedGrasp]:
    """``out`` followed by the candidates (gfaces, width, T) whose fingers and palm stay out of
    the part (:func:`grasp_problem`), each labelled next and given its ofaces (:func:`_covered`);
    with ``unique``, a candidate whose T is one already listed is not repeated."""
    out = list(out)
    order = [f.name for f in faces]
    listed = np.array([d.T for d in out], float).reshape(-1, 4, 4)
    for names, width, T in cands:
        if unique and _listed(T, listed):
            continue
        if grasp_problem(mesh, T, width, g, unit) is not None:
            continue
        cover = {faces[k].name for k in _covered(mesh, faces, features, T, width, g, unit)}
        ofaces = tuple(names) + tuple(sorted(cover - set(names), key=order.index))
        out.append(DerivedGrasp(f"{prefix}{len(out) + 1}", names, ofaces, T, euler_zyz_of(T), float(round(width, 12))))
        listed = np.concatenate((listed, np.asarray(T, float)[None]))
    return out


def _listed(T: np.ndarray, listed: np.ndarray) -> bool:
    """Whether one of ``listed`` (k, 4, 4) is ``T`` by ``np.allclose(T, listed[i], atol=1e-9)``
    (the same test, one array operation instead of a call per listed grasp)."""
    if not len(listed):
        return False
    return bool(np.all(np.abs(T - listed) <= 1e-9 + 1e-5 * np.abs(listed), axis=(1, 2)).any())


def _shaft_from_above(mesh: "trimesh.Trimesh", root: np.ndarray, d: np.ndarray, r: float, length: float,
                      g: Gripper, unit: str, poses: "list[DerivedPose]", min_len: float) -> list[np.ndarray]:
    """Tool frames closing across the shaft (root, unit axis d, radius r, length) straight down
    onto it as the part lies in each of its stable ``poses`` whose table the shaft is not normal
    to: the closing direction horizontal there (d x up), the approach -up (the quantised ones
    seldom fall on it), the tool centre on the axis at the shaft's middle or, where the fingers
    meet the part there (a pad wider than a short peg reaches its shoulder), slid along the axis
    by SHAFT_SLIDE_MM steps to the nearest place they do not, while at least ``min_len`` of the
    shaft stays under the pads."""
    out: list[np.ndarray] = []
    slide = from_mm(unit, SHAFT_SLIDE_MM)
    for pose in poses:
        up = np.asarray(pose.R, float)[2]
        c = cross(d, up)
        if np.linalg.norm(c) < math.sin(math.radians(TABLE_APPROACH_DEG)):
            continue  # the shaft stands (nearly) upright: the quantised approaches have it
        c = _canonical(clean(c / np.linalg.norm(c), 1e-12))
        a = clean(-(up - (up @ c) * c) / np.linalg.norm(up - (up @ c) * c), 1e-12)
        n = int(length / 2 // slide) + 1
        for k in sorted(range(-n, n + 1), key=lambda k: (abs(k), k)):
            T = _tool(clean(root + d * (length / 2 + k * slide), 1e-9), c, a)
            if _line_contact(root + c * r, d, length, T, g) < min_len * (1 - 1e-9):
                continue
            if grasp_problem(mesh, T, 2 * r, g, unit) is None:
                if not any(np.allclose(T, U, atol=1e-9) for U in out):
                    out.append(T)
                break
    return out


def _table_clear(T: np.ndarray, width: float, g: Gripper, poses: "list[DerivedPose]", unit: str) -> list[np.ndarray]:
    """Shallower versions of the grasp at T (fingers ``width`` apart) for a part lying in its
    stable ``poses``: where the approach points down (at least TABLE_APPROACH_DEG below the
    horizontal) and the closed fingers or the palm come nearer the table than TABLE_CLEAR_MM (a
    part lower than the fingers' reach, gripped with its contact centre near the table), the
    tool backed off along its approach until they clear it by that, in whole TABLE_STEP_MM
    (at most the finger length: deeper the pads would leave the part). One per distinct
    back-off, shallowest first; the caller keeps those whose pads still touch the part."""
    clear, step = from_mm(unit, TABLE_CLEAR_MM), from_mm(unit, TABLE_STEP_MM)
    boxes = [b for b in _gripper_boxes(g, width, g.finger_length + g.palm_depth, 0.0) if "open" not in b[0]]
    corners = np.concatenate([np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1])
                                        for z in (lo[2], hi[2])]) for _, lo, hi in boxes])
    P = corners @ T[:3, :3].T + T[:3, 3]  # object frame
    a = T[:3, 2]
    down = math.sin(math.radians(TABLE_APPROACH_DEG))
    backs: set[int] = set()
    for pose in poses:
        up = np.asarray(pose.R, float)[2]  # world z of object directions
        fall = -float(up @ a)  # how fast the tool descends along its approach
        low = float((P @ up).min()) + pose.height
        if fall < down or low >= clear:
            continue
        k = math.ceil((clear - low) / fall / step - 1e-9)
        if k * step <= g.finger_length:
            backs.add(k)
    out = []
    for k in sorted(backs):
        Ts = T.copy()
        Ts[:3, 3] = T[:3, 3] - k * step * a
        out.append(clean(Ts, 1e-9))
    return out


def _half_depth(T: np.ndarray, flat: tuple[np.ndarray, np.ndarray, np.ndarray], areas: np.ndarray,
                e1: np.ndarray, e2: np.ndarray, g: Gripper, unit: str, min_area: float) -> np.ndarray | None:
    """The facet grasp at T backed off along its approach, in whole TABLE_STEP_MM, as far as the
    pads keep at least HALF_DEPTH_KEEP of the contact area they have at T (and ``min_area``): the
    fingers hold the part's outer half only, so they stay off what lies beside its inner half (the
    parts around it where it is mated, the table it lies on). None when that is less than
    HALF_DEPTH_MIN_MM back (the grasp at T itself)."""
    step = from_mm(unit, TABLE_STEP_MM)
    a = T[:3, 2]
    need = max(min_area, HALF_DEPTH_KEEP * _pad_contact(flat, areas, e1, e2, T, g))

    def holds(k: int) -> bool:
        Ts = T.copy()
        Ts[:3, 3] = T[:3, 3] - k * step * a
        return _pad_contact(flat, areas, e1, e2, Ts, g, need) >= need

    # bisection: the contact falls as the pads move off the faces (where it does not, the
    # back-off found still holds, since every k kept was checked)
    best, fail = 0, int(g.finger_length / step) + 1
    while fail - best > 1:
        mid = (best + fail) // 2
        best, fail = (mid, fail) if holds(mid) else (best, mid)
    if best * step < from_mm(unit, HALF_DEPTH_MIN_MM) - 1e-9:
        return None
    Ts = T.copy()
    Ts[:3, 3] = T[:3, 3] - best * step * a
    return clean(Ts, 1e-9)


def _round(mesh: "trimesh.Trimesh", root: np.ndarray, d: np.ndarray, r: float, length: float, unit: str) -> bool:
    """True if the mesh's side triangles of the shaft (root, d, r, length) lie on its cylinder:
    their centroids within 1 % of r from the axis (a 64-gon's are within 0.05 %, a hexagon's 6 % off).
    Triangles within ON_SURFACE_MM of either end's plane are the ends' (a shoulder, a cap): a
    mesh's vertices may be float32 (manifold3d's booleans), off by 1e-7 of their value, which in
    inches puts a shoulder's vertices inside or outside the shaft by chance."""
    C = _arrays(mesh).C - root
    t = C @ d
    radial = np.linalg.norm(C - np.outer(t, d), axis=1)
    tol = from_mm(unit, ON_SURFACE_MM)
    side = (t > tol) & (t < length - tol) & (radial > 0.5 * r) & (radial < 1.5 * r)
    return bool(side.any() and (np.abs(radial[side] - r) < 0.01 * r).all())


def _face_at(faces: list[Face], mesh: "trimesh.Trimesh", p: np.ndarray, unit: str) -> str | None:
    k = face_of_point(faces, mesh, p, 10 * from_mm(unit, ON_SURFACE_MM) + 1e-3 * float(mesh.scale))
    return None if k is None else faces[k].name


def _flatten(pieces: list[np.ndarray]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Polygons (each (k, 2)) as their corners stacked, their corner counts and the index of
    each one's first corner: :func:`_pad_contact`'s form, built once per face pair."""
    sizes = np.array([len(p) for p in pieces], int)
    starts = np.concatenate([[0], np.cumsum(sizes)[:-1]]).astype(int)
    return (np.concatenate(pieces) if pieces else np.zeros((0, 2))), sizes, starts


def _pad_contact(flat: tuple[np.ndarray, np.ndarray, np.ndarray], areas: np.ndarray, e1: np.ndarray,
                 e2: np.ndarray, T: np.ndarray, g: Gripper, need: float = math.inf) -> float:
    """Area of the overlap pieces (``flat``: :func:`_flatten`'s, plane basis e1, e2) under one
    finger pad (tool x within +-finger_width/2, tool z from -finger_length to 0); once the
    pieces wholly under it reach ``need`` that lower bound is returned."""
    x, z, o = T[:3, 0], T[:3, 2], T[:3, 3]
    # plane coordinates (s, t) -> pad coordinates (u, w): affine, the plane's offset drops out
    M = np.array([[e1 @ x, e2 @ x], [e1 @ z, e2 @ z]])
    off = -np.array([o @ x, o @ z])
    u, L = g.finger_width / 2, g.finger_length
    pad = np.array([[-u, -L], [u, -L], [u, 0.0], [-u, 0.0]])
    corners, sizes, starts = flat
    if not len(sizes):
        return 0.0
    Q = corners @ M.T + off
    qlo, qhi = np.minimum.reduceat(Q, starts), np.maximum.reduceat(Q, starts)
    lo, hi = pad[0], pad[2]
    inside = (qlo >= lo).all(1) & (qhi <= hi).all(1)
    outside = (qhi < lo).any(1) | (qlo > hi).any(1)
    total = float(areas[inside].sum())
    if total >= need:
        return total  # enough already: the pieces across the pad's edge need no clipping
    part = np.flatnonzero(~inside & ~outside)
    if len(part):
        P, cnt = _pack([_ccw(Q[starts[i]: starts[i] + sizes[i]]) for i in part])
        for a in _area_centroid_many(*_clip_many(P, cnt, pad))[0]:
            total += float(a)
    return total


def _line_contact(start: np.ndarray, d: np.ndarray, length: float, T: np.ndarray, g: Gripper) -> float:
    """Length of the segment start + d t, t in [0, length], inside a finger pad's (u, w) rectangle.

    A segment parallel to a side of the pad is inside it up to a rounding allowance (1e-9 of the
    scale): a shaft closed on with the approach normal to its axis has its contact line on the
    pad's tip edge (w = 0 exactly), where the sign of a dot product's rounding (which differs
    between CPUs' summation orders) would otherwise accept or refuse the grasp."""
    x, z, o = T[:3, 0], T[:3, 2], T[:3, 3]
    u0, w0 = float((start - o) @ x), float((start - o) @ z)
    du, dw = float(d @ x), float(d @ z)
    lo, hi = 0.0, length
    eps = 1e-9 * (1.0 + length + g.finger_length + g.finger_width)
    for p0, dp, a, b in ((u0, du, -g.finger_width / 2, g.finger_width / 2), (w0, dw, -g.finger_length, 0.0)):
        if abs(dp) < 1e-12:
            if not (a - eps <= p0 <= b + eps):
                return 0.0
            continue
        t1, t2 = (a - p0) / dp, (b - p0) / dp
        lo, hi = max(lo, min(t1, t2)), min(hi, max(t1, t2))
    return max(0.0, hi - lo)


# =========================================================================== checks


def check_entries(model: "object", gripper: Gripper, unit: str, which: tuple[str, ...],
                  step: float = math.radians(45.0)) -> list[tuple[str, str, str]]:
    """Hand-written entries of ``model`` (an ObjectModel with a geometry) checked against its
    shape: ``which`` names the lists written by hand ('faces', 'stable_poses', 'grasps').
    Returns (key, expected, got) for each problem, in file order: a face that is not on the
    shape, a stable pose that is not stable (or rests at another height, or on other faces),
    a grasp wider than the opening or whose fingers or palm enter the part."""
    geo = model.geometry  # type: ignore[attr-defined]
    mesh = geo.mesh()
    feats = tuple(f.geometry for f in model.features if f.geometry is not None)  # type: ignore[attr-defined]
    faces = derive_faces(mesh, feats, geo.face_names, unit)
    own = {f.name: k for k, f in enumerate(faces)}
    out: list[tuple[str, str, str]] = []
    tol = max(from_mm(unit, 0.05), 1e-6)
    if "faces" in which:
        for i, f in enumerate(model.faces):  # type: ignore[attr-defined]
            if f not in own:
                out.append((f"faces[{i}]", f"a face of the shape ({', '.join(own)}; face_names: names a face by a "
                            "point on it)", repr(f)))
    if "stable_poses" in which:
        for i, p in enumerate(model.poses.values()):  # type: ignore[attr-defined]
            why, height, lying = support_check(mesh, p.R, faces, unit)
            key = f"stable_poses[{i}]"
            if why is not None:
                out.append((key, "a stable pose of the shape", f"{p.label}: {why}"))
            elif abs(height - p.height) > tol:
                out.append((f"{key}.tm", f"the height the shape rests at in {p.label}, {height:.6g} {unit}",
                            f"{p.height:.6g}"))
            else:
                down = {faces[k].name for k in lying}
                bad = [f for f in p.rfaces if f in own and f not in down]
                if bad:
                    out.append((f"{key}.rfaces", f"faces {p.label} rests on ({', '.join(sorted(down))})",
                                ", ".join(map(str, bad))))
    if "grasps" in which:
        for i, g in enumerate(model.grasps.values()):  # type: ignore[attr-defined]
            why = grasp_problem(mesh, g.T, g.width, gripper, unit)
            if why is not None:
                out.append((f"grasps[{i}]", "a grasp the gripper can make", f"{g.label}: {why}"))
    return out


# =========================================================================== grasps for a mate


#: A gripper body may reach this far past the hole's mouth plane into the hole side (mm):
#: touching the mouth's plane is outside it.
MOUTH_TOL_MM = 0.05


def mate_grasp_usable(T_grasp: np.ndarray, width: float, gripper: Any, T_a: np.ndarray, hole: FeatureGeometry,
                      unit: str) -> bool:
    """Whether a grasp of the peg (tool frame ``T_grasp`` in the peg's frame, fingers ``width``
    apart) can make the mate seated at ``T_a`` (the peg's frame in the hole part's frame, 4x4):
    every corner of the fingers, the palm and the tool body (``gripper``, a
    world.robot.model.GripperGeometry: the finger's size, not only its pad) stays on the outer side of
    the plane of the hole's mouth (``hole``: origin the mouth's centre, direction into the part),
    within MOUTH_TOL_MM, so the hand holds only the length that stays out of the hole when seated.
    Cell unit throughout."""
    corners = np.concatenate([np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1])
                                        for z in (lo[2], hi[2])]) for lo, hi in gripper.hand_boxes(width)])
    M = np.asarray(T_a, float) @ np.asarray(T_grasp, float)  # tool frame in the hole part's frame
    depth = (corners @ M[:3, :3].T + M[:3, 3] - hole.origin) @ hole.direction
    return bool(depth.max() <= from_mm(unit, MOUTH_TOL_MM))


# =========================================================================== antipodal grasps


#: Surface points sampled (area-weighted, seeded) for antipodal contact pairs.
ANTIPODAL_SAMPLES = 3000
#: ... with this seed (the derivation is deterministic).
ANTIPODAL_SEED = 0
#: A pair's normals must be antiparallel within this, each to the closing line (deg): the
#: friction cone of a hard pad (tan 12 deg ~ 0.2).
FRICTION_DEG = 12.0
#: Each pad must find surface along a line this long through its contact (mm), within
#: PAD_DEPTH_MM of the contact's plane (see _pads_on_surface).
PAD_PATCH_MM = 5.0
#: ... (mm): a 35 mm round sags 0.18 mm over the patch's half width.
PAD_DEPTH_MM = 0.5
#: ... along one of this many lines through the contact, evenly turned (a round's axis is then
#: within 90 / PAD_LINES deg of one: a 12 mm round sags 0.08 mm along that line); even.
PAD_LINES = 4
#: Pairs narrower than this are not grasped (mm): a fin or a skin, not a part.
MIN_WIDTH_MM = 1.0
#: Closing directions are clustered on a grid of this many cells per unit of direction
#: component; contact midpoints on a grid of the part's size over ANTIPODAL_GRID.
DIRECTION_CELLS = 4
ANTIPODAL_GRID = 4
#: At most this many clusters are tried for approaches (the best first).
ANTIPODAL_CLUSTERS = 12


@dataclass(frozen=True)
class Antipodal:
    """An antipodal contact pair (object frame, cell unit): contacts ``p`` and ``q``, the unit
    closing direction ``c`` (from p to q), the ``width`` |q - p|, the worse of the two
    normals' angles to the closing line (``angle``, deg) and the contacts' triangles."""

    p: np.ndarray
    q: np.ndarray
    c: np.ndarray
    width: float
    angle: float
    #: the triangles the contacts lie on
    tp: int = -1
    tq: int = -1


def _ray_hit(mesh: "trimesh.Trimesh", S: np.ndarray, D: np.ndarray, farthest_within: float | None = None
             ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """One hit per ray (S, unit D) on the mesh: the first, or with ``farthest_within`` the farthest
    within that distance of S. (hit (k,), points (k, 3) with nan where none, triangle index (k,),
    -1 where none)."""
    k = len(S)
    pts = np.full((k, 3), np.nan)
    tri = np.full(k, -1)
    if k == 0:
        return np.zeros(0, bool), pts, tri
    loc, ri, ti = mesh.ray.intersects_location(S, D, multiple_hits=farthest_within is not None)
    d = np.einsum("ij,ij->i", loc - S[ri], D[ri]) if len(ri) else np.zeros(0)
    if farthest_within is not None:
        keep = d <= farthest_within
        ri, ti, loc, d = ri[keep], ti[keep], loc[keep], -d[keep]
    if len(ri):
        # one per ray (a first-hit query may still report more than one): the least d
        order = np.lexsort((d, ri))
        ri, ti, loc = ri[order], ti[order], loc[order]
        first = np.r_[True, ri[1:] != ri[:-1]]
        pts[ri[first]], tri[ri[first]] = loc[first], ti[first]
    return tri >= 0, pts, tri


def antipodal_pairs(mesh: "trimesh.Trimesh", opening: float, unit: str, samples: int = ANTIPODAL_SAMPLES,
                    seed: int = ANTIPODAL_SEED) -> tuple[list[Antipodal], float | None]:
    """Antipodal contact pairs on the surface: ``samples`` points drawn area-weighted (seeded),
    each with the point where the line into the part along its inward normal first leaves it (a
    ray cast) and, where it is another, the farthest point it leaves it within ``opening`` (the
    other side of a tube across its bore); a pair is kept when both normals lie within
    FRICTION_DEG of the closing line, its width is from MIN_WIDTH_MM to ``opening`` and both
    pads find surface (PAD_PATCH_MM, PAD_DEPTH_MM). Returns the pairs and the least width of
    any pair in the friction cone (None if none), which a refusal names. Cell unit throughout."""
    import trimesh  # a derivation only

    A = _arrays(mesh)
    eps = 1e-6 * A.diag
    P, fi = trimesh.sample.sample_surface(mesh, samples, seed=seed)
    P = np.asarray(P, float)
    n = A.N[fi]
    S = P - eps * n
    hit, Q, ti = _ray_hit(mesh, S, -n)
    far, Qf, tf = _ray_hit(mesh, S, -n, opening * (1 + 1e-9))
    # also the farthest exit within the opening where it is another point: across a bore or a
    # gap the pads close on the outer surface beyond it (a tube's two sides), where the first
    # exit is the inside of the wall, which no pad reaches
    far &= hit & (np.linalg.norm(np.nan_to_num(Qf) - Q, axis=1) > 1e-3 * A.diag)
    fi = np.concatenate([fi[hit], fi[far]])
    P, n = np.concatenate([P[hit], P[far]]), np.concatenate([n[hit], n[far]])
    Q, ti = np.concatenate([Q[hit], Qf[far]]), np.concatenate([ti[hit], tf[far]])
    m = A.N[ti]
    d = Q - P
    w = np.linalg.norm(d, axis=1)
    ok = w > 0
    c = np.zeros_like(d)
    c[ok] = d[ok] / w[ok, None]
    cos_f = math.cos(math.radians(FRICTION_DEG))
    # atan2 of |cross| and dot: accurate near 0 deg, where arccos turns rounding into 1e-6 deg
    ang_p = np.degrees(np.arctan2(np.linalg.norm(cross(-n, c), axis=1), np.einsum("ij,ij->i", -n, c)))
    ang_q = np.degrees(np.arctan2(np.linalg.norm(cross(m, c), axis=1), np.einsum("ij,ij->i", m, c)))
    cone = ok & (np.einsum("ij,ij->i", -n, c) >= cos_f) & (np.einsum("ij,ij->i", m, c) >= cos_f)
    cone &= w >= from_mm(unit, MIN_WIDTH_MM)
    least = float(w[cone].min()) if cone.any() else None
    keep = cone & (w <= opening * (1 + 1e-9))
    idx = np.flatnonzero(keep)
    pads = _pads_on_surface(mesh, P[idx], Q[idx], c[idx], unit)
    out = [Antipodal(P[i], Q[i], c[i], float(w[i]), float(max(ang_p[i], ang_q[i])), int(fi[i]), int(ti[i]))
           for i in idx[pads]]
    return out, least


def _pads_on_surface(mesh: "trimesh.Trimesh", P: np.ndarray, Q: np.ndarray, C: np.ndarray, unit: str) -> np.ndarray:
    """(k,) bool: both pads of each pair find surface. Rays along the closing line from outside,
    at the contact and PAD_PATCH_MM/2 from it each way along PAD_LINES lines in the pad's plane,
    first meet the part within PAD_DEPTH_MM of the contact's depth along at least one line (a
    flat pad touches a round along a line, as the shaft grasps' MIN_CONTACT_MM: a 12 mm round
    sags 0.55 mm over the patch's half width across its axis, 0 along it), and across that line
    the surface falls away from the pad by at most PAD_PATCH_MM/2 (a round, not the edge of a
    flat with nothing beyond it)."""
    k = len(P)
    if k == 0:
        return np.zeros(0, bool)
    half, tol = from_mm(unit, PAD_PATCH_MM) / 2, from_mm(unit, PAD_DEPTH_MM)
    far = 2 * _arrays(mesh).diag
    # a basis normal to each closing direction
    ref = np.where(np.abs(C[:, :1]) < 0.9, np.array([[1.0, 0, 0]]), np.array([[0, 1.0, 0]]))
    e1 = cross(C, ref)
    e1 /= np.linalg.norm(e1, axis=1)[:, None]
    e2 = cross(C, e1)
    angles = [math.pi * j / PAD_LINES for j in range(PAD_LINES)]
    offs = [(0.0, 0.0)] + [(s * math.cos(t), s * math.sin(t)) for t in angles for s in (-1.0, 1.0)]
    ok = np.ones(k, bool)
    for X, sign in ((P, 1.0), (Q, -1.0)):  # the pad at p closes along +c, the pad at q along -c
        D = sign * C
        S = np.concatenate([X + half * (a * e1 + b * e2) - far * D for a, b in offs])
        DD = np.tile(D, (len(offs), 1))
        hit, H, _ = _ray_hit(mesh, S, DD)
        depth = np.einsum("ij,ij->i", np.nan_to_num(H) - np.tile(X, (len(offs), 1)), DD)
        near = (hit & (np.abs(depth) <= tol)).reshape(len(offs), k)
        away = (hit & (depth >= -tol) & (depth <= half)).reshape(len(offs), k)
        good = np.zeros(k, bool)
        for j in range(PAD_LINES):
            a, b = 1 + 2 * j, 2 + 2 * j  # this line's ends
            c, d = 1 + 2 * ((j + PAD_LINES // 2) % PAD_LINES), 2 + 2 * ((j + PAD_LINES // 2) % PAD_LINES)  # across it
            good |= near[0] & near[a] & near[b] & away[c] & away[d]
        ok &= good
    return ok


def antipodal_grasps(mesh: "trimesh.Trimesh", g: Gripper, unit: str, step: float, allowed: np.ndarray | None = None
                     ) -> tuple[list[tuple[np.ndarray, float, Antipodal]], float | None, int]:
    """Tool frames (T, width) of antipodal grasps (:func:`antipodal_pairs`; with ``allowed``, a
    (triangles,) bool, only the pairs with a contact on an allowed triangle), clustered: pairs
    are grouped by closing direction (DIRECTION_CELLS) and midpoint (the part's size over
    ANTIPODAL_GRID), the squarest pair of a group (the least normal angle, then the narrowest)
    stands for it, the ANTIPODAL_CLUSTERS groups of the most pairs are tried, each at the approaches
    normal to its closing direction quantised by ``step``, the contact PAD_PATCH_MM/2 inside
    the fingertips; kept where :func:`grasp_problem` finds neither fingers nor palm in the
    part. Also returns the least width in the friction cone and the pairs found within the
    opening (for a refusal)."""
    pairs, least = antipodal_pairs(mesh, g.opening, unit)
    if allowed is not None:
        pairs = [a for a in pairs if allowed[a.tp] or allowed[a.tq]]
    if not pairs:
        return [], least, 0
    A = _arrays(mesh)
    cell = A.diag / ANTIPODAL_GRID
    mm = from_mm(unit, 1.0)  # ties are broken on lengths in mm: the same grasps in any unit
    groups: dict[tuple, Antipodal] = {}
    count: dict[tuple, int] = {}

    def rank(a: Antipodal) -> tuple:
        return round(a.angle, 6), round(a.width / mm, 9)

    for a in pairs:
        c = _canonical(a.c)
        # cells centred on the origin: a part symmetric about it has midpoints at 0 up to rounding
        key = (*np.round(c * DIRECTION_CELLS).astype(int), *np.round((a.p + a.q) / 2 / cell).astype(int))
        count[key] = count.get(key, 0) + 1
        best = groups.get(key)
        if best is None or rank(a) < rank(best):
            groups[key] = a
    # the groups with the most pairs first (the most surface to close on), then the squarest
    ranked = sorted(groups, key=lambda k: (-count[k], *rank(groups[k]),
                                           *np.round((groups[k].p + groups[k].q) / 2 / mm, 9)))
    chosen = [groups[k] for k in ranked[:ANTIPODAL_CLUSTERS]]
    inset = min(from_mm(unit, PAD_PATCH_MM) / 2, g.finger_length / 2)
    out: list[tuple[np.ndarray, float, Antipodal]] = []
    for a in chosen:
        c = _canonical(clean(a.c, 1e-12))
        mid = (a.p + a.q) / 2
        for ap in _approaches(c, step):
            T = _tool(mid + inset * ap, c, ap)
            if grasp_problem(mesh, T, a.width, g, unit) is None:
                out.append((T, a.width, a))
    return out, least, len(pairs)
