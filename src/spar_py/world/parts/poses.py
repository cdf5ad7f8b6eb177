"""Stable poses derived from a part's mesh, and the quasi-static support check.

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

Units: lengths in the cell unit, constants in mm (converted with spar_py.core.units.from_mm);
angles in radians. Frames: object frame; tool frames T_g are 4x4 in the object frame.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from spar_py.core.geometry import convex_hull_2d
from spar_py.core.units import from_mm
from spar_py.world.parts.arrays import mesh_arrays
from spar_py.world.parts.mesh import Face, FeatureGeometry, clean, cross, minimal_rotation

if TYPE_CHECKING:
    import trimesh

__all__ = ["DerivedPose", "derive_poses", "feature_face", "hull_vertices", "support_check"]

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


def hull_vertices(mesh: "trimesh.Trimesh") -> np.ndarray:
    """Indices of the mesh's vertices on its convex hull (sorted; kept in the mesh's metadata).

    qhull with joggled input (``QJ``): a finely tessellated round part has thousands of
    coplanar and cocircular points, over which qhull's default facet merging is slow; joggling is
    much faster and moves a point by about 1e-11 of the part's
    size, so it can only keep or drop a point that far from the hull. Qhull's default is
    the fallback if joggling fails."""
    h = mesh.metadata.get("_spar_hull")
    if h is None:
        from scipy.spatial import ConvexHull, QhullError  # scipy: a model with a hull only

        V = mesh_arrays(mesh).V
        try:
            h = np.sort(ConvexHull(V, qhull_options="QJ").vertices)
        except QhullError:
            h = np.sort(ConvexHull(V).vertices)
        mesh.metadata["_spar_hull"] = h
    return h


def _hull_mesh(P: np.ndarray) -> "trimesh.Trimesh":
    """The convex hull of points P as a closed, outward-oriented trimesh (qhull's facets,
    each turned to agree with its outward plane normal)."""
    import trimesh  # scipy with it: a derivation only
    from scipy.spatial import ConvexHull

    qh = ConvexHull(P)
    F = qh.simplices.copy()
    n = cross(P[F[:, 1]] - P[F[:, 0]], P[F[:, 2]] - P[F[:, 0]])
    flip = np.einsum("ij,ij->i", n, qh.equations[:, :3]) < 0
    F[flip] = F[flip][:, ::-1]
    return trimesh.Trimesh(P, F, process=True)


def support_check(mesh: "trimesh.Trimesh", R: np.ndarray, faces: list[Face], unit: str,
                  com: np.ndarray | None = None) -> tuple[str | None, float, list[int]]:
    """Is the part at rotation R (object to world) resting quasi-statically on the table?

    Returns (why not or None, height of the object frame above the table, indices of the
    faces lying on the table). Independent of trimesh's pose search: the lowest points of
    the mesh are the support, their 2-D convex hull the support polygon, and the centre of
    mass must project inside it by STABLE_MARGIN_MM; the part must rest on a face.
    """
    tol = from_mm(unit, SUPPORT_TOL_MM)
    A = mesh_arrays(mesh)
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
            k = feature_face(faces, feature)
            if k is not None and k not in out:
                out.append(k)
    return out


def feature_face(faces: list[Face], feature: FeatureGeometry) -> int | None:
    """The index of ``feature``'s face among ``faces`` (None if its surfaces are not on the mesh)."""
    return next((i for i, f in enumerate(faces) if f.feature and f.name == feature.name), None)


def derive_poses(mesh: "trimesh.Trimesh", faces: list[Face], features: tuple[FeatureGeometry, ...], unit: str,
                 prefix: str, prob_floor: float = PROB_FLOOR) -> list[DerivedPose]:
    """The stable poses of the part (module docstring), most probable first, labelled
    ``{prefix}1, {prefix}2, ...``."""
    from spar_py.world.parts.stable import stable_poses

    A = mesh_arrays(mesh)
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
