"""Round shafts to close on: the cylinders of a mesh (fitted circles), a peg feature's or a
cylinder primitive's shaft, whether a shaft is round, the contact length of a pad along it, and
shaft grasps from above backed off the table.

Units: lengths in the cell unit, constants in mm (converted with spar_py.core.units.from_mm);
angles in radians. Frames: object frame; tool frames T_g are 4x4 in the object frame.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from spar_py.core.units import from_mm
from spar_py.world.parts.arrays import mesh_arrays
from spar_py.world.parts.hand import TABLE_APPROACH_DEG, canonical, grasp_problem, tool_frame
from spar_py.world.parts.mesh import Face, FeatureGeometry, ON_SURFACE_MM, Primitive, axis_basis, clean, cross

if TYPE_CHECKING:
    import trimesh
    from spar_py.world.parts.support import DerivedPose
    from spar_py.world.robot import Gripper

__all__ = [
    "MeshCylinder", "fit_circle", "is_round", "line_contact", "mesh_cylinders", "pads_find", "shaft_from_above",
    "shafts_of"
]

#: The least contact length of a finger pad along a shaft's side (mm).
MIN_CONTACT_MM = 5.0
#: A shaft grasp straight down onto a lying part slides along the shaft by this (mm) to keep
#: its fingers off the part beside the shaft (shaft_from_above).
SHAFT_SLIDE_MM = 1.0


def shafts_of(faces: list[Face], features: tuple[FeatureGeometry, ...], prims: tuple[Primitive, ...],
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
    A = mesh_arrays(mesh)
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
        d = canonical(d)
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


def pads_find(normals: np.ndarray | None, c: np.ndarray) -> bool:
    """Both pads closing along +-c find the surface of triangle ``normals`` (None: a whole round)."""
    if normals is None:
        return True
    cos = math.cos(math.radians(CYL_PAD_DEG))
    return bool((normals @ c > cos).any() and (normals @ -c > cos).any())


def shaft_from_above(mesh: "trimesh.Trimesh", root: np.ndarray, d: np.ndarray, r: float, length: float,
                     g: Gripper, unit: str, poses: "list[DerivedPose]", min_len: float) -> list[np.ndarray]:
    """Tool frames closing across the shaft (root, unit axis d, radius r, length) straight down
    onto it as the part lies in each of its stable ``poses`` whose table the shaft is not normal
    to: the closing direction horizontal there (d x up), the approach -up (the quantised ones
    seldom fall on it), the tool centre on the axis at the shaft's middle or, where the fingers
    meet the part there (a pad wider than a short peg reaches its shoulder), slid along the axis
    by SHAFT_SLIDE_MM steps to the nearest place they do not, while at least ``min_len`` of the
    shaft (up to ON_SURFACE_MM: a mesh's float32 vertices) stays under the pads."""
    out: list[np.ndarray] = []
    slide = from_mm(unit, SHAFT_SLIDE_MM)
    least = min_len - from_mm(unit, ON_SURFACE_MM)
    for pose in poses:
        up = np.asarray(pose.R, float)[2]
        c = cross(d, up)
        if np.linalg.norm(c) < math.sin(math.radians(TABLE_APPROACH_DEG)):
            continue  # the shaft stands (nearly) upright: the quantised approaches have it
        c = canonical(clean(c / np.linalg.norm(c), 1e-12))
        a = clean(-(up - (up @ c) * c) / np.linalg.norm(up - (up @ c) * c), 1e-12)
        n = int(length / 2 // slide) + 1
        for k in sorted(range(-n, n + 1), key=lambda k: (abs(k), k)):
            T = tool_frame(clean(root + d * (length / 2 + k * slide), 1e-9), c, a)
            if line_contact(root + c * r, d, length, T, g) < least:
                continue
            if grasp_problem(mesh, T, 2 * r, g, unit) is None:
                if not any(np.allclose(T, U, atol=1e-9) for U in out):
                    out.append(T)
                break
    return out


def is_round(mesh: "trimesh.Trimesh", root: np.ndarray, d: np.ndarray, r: float, length: float, unit: str) -> bool:
    """True if the mesh's side triangles of the shaft (root, d, r, length) lie on its cylinder:
    their centroids within 1 % of r from the axis (a 64-gon's are within 0.05 %, a hexagon's 6 % off).
    Triangles within ON_SURFACE_MM of either end's plane are the ends' (a shoulder, a cap): a
    mesh's vertices may be float32 (manifold3d's booleans), off by 1e-7 of their value, which in
    inches puts a shoulder's vertices inside or outside the shaft by chance."""
    C = mesh_arrays(mesh).C - root
    t = C @ d
    radial = np.linalg.norm(C - np.outer(t, d), axis=1)
    tol = from_mm(unit, ON_SURFACE_MM)
    side = (t > tol) & (t < length - tol) & (radial > 0.5 * r) & (radial < 1.5 * r)
    return bool(side.any() and (np.abs(radial[side] - r) < 0.01 * r).all())


def line_contact(start: np.ndarray, d: np.ndarray, length: float, T: np.ndarray, g: Gripper) -> float:
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
