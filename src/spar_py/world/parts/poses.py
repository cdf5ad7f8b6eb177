"""Stable poses derived from a part's mesh.

Stable poses (Fig. 18): trimesh's ``compute_stable_poses`` (deterministic: no noise, one
sample; world.parts.stable computes the same with arrays) gives the resting orientations of
the convex hull with the probability of each (a hull of more than HULL_FACES_MAX triangles
thinned first, each pose then snapped to the face of the mesh it rests on);
those below ``PROB_FLOOR`` are dropped, and every remaining one must pass
:func:`support_check`, our own quasi-static test (world.parts.support: the part rests on a
face, its centre of mass STABLE_MARGIN_MM inside the support polygon, and a tilt of
STABLE_TILT_DEG about any edge of it does not topple it), since that function can return
poses that are not stable. A pose is kept as R, the least rotation taking the
resting face's outward normal to world -z (so a pose is written as the paper writes it,
``tm`` rows and the frame's height above the table), its ``rfaces`` (faces lying on the
table) and ``ofaces`` (those plus a feature whose mouth or tip is on the table).

A round side of the hull (a pin's, a shaft's, a headed pin's head rim to shaft tip: world.parts.
rolling) is one pose family, any roll about its axis: trimesh's poses resting on it (one per
side facet, each rolling off its narrow facet or kept by a tessellation's chance) are replaced
by one pose standing for the family, with the sum of their probabilities, kept by the same
rule read along the line it touches the table on (:func:`rest_check` judges any pose so).

Units: lengths in the cell unit, constants in mm (converted with spar_py.core.units.from_mm);
angles in radians. Frames: object frame; tool frames T_g are 4x4 in the object frame.
"""
from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np

from spar_py.core.units import from_mm
from spar_py.world.parts.arrays import mesh_arrays
from spar_py.world.parts.mesh import Face, FeatureGeometry, Primitive, clean, cross, minimal_rotation
from spar_py.world.parts.rolling import round_sides, side_of, touching_faces
from spar_py.world.parts.support import DerivedPose, SUPPORT_TOL_MM, feature_face, hull_vertices, support_check

if TYPE_CHECKING:
    import trimesh

__all__ = ["derive_poses", "rest_check"]

#: Poses whose basin of attraction (trimesh's probability) is smaller are dropped.
PROB_FLOOR = 0.01
#: A convex hull of more triangles is thinned before trimesh's pose search (see derive_poses).
HULL_FACES_MAX = 64
#: ... on a grid of the part's size over this.
HULL_GRID = 100
#: A pose trimesh finds is snapped to a face whose normal is within this (deg).
SNAP_DEG = 2.0


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


def rest_check(mesh: "trimesh.Trimesh", R: np.ndarray, faces: list[Face], features: tuple[FeatureGeometry, ...],
               prims: tuple[Primitive, ...], unit: str) -> tuple[str | None, float, list[int]]:
    """Does the part keep the pose R (object to world) on the table? :func:`support_check`'s
    (why not or None, the frame's height, the faces it rests on), judged on a round side of
    its hull by the side's rule where R rests on one (world.parts.rolling: along the line it
    touches the table on, and the roll), so a lying pin is kept as its derived pose is."""
    hull = mesh_arrays(mesh).V[hull_vertices(mesh)]
    sides = round_sides(mesh, hull, faces, features, prims, unit)
    down = np.asarray(R, float).T @ np.array([0.0, 0.0, -1.0])
    k = side_of(sides, hull, down, unit)
    if k is None:
        return support_check(mesh, R, faces, unit)
    height = -float((mesh_arrays(mesh).V @ np.asarray(R, float)[2]).min())
    return sides[k].member_problem(down), height, touching_faces(mesh, faces, R, unit)


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


def derive_poses(mesh: "trimesh.Trimesh", faces: list[Face], features: tuple[FeatureGeometry, ...], unit: str,
                 prefix: str, prob_floor: float = PROB_FLOOR, prims: tuple[Primitive, ...] = ()) -> list[DerivedPose]:
    """The stable poses of the part (module docstring), most probable first, labelled
    ``{prefix}1, {prefix}2, ...``: trimesh's poses the part keeps (:func:`support_check`) and
    one member per round side it keeps (world.parts.rolling), whose probability is the sum of
    trimesh's over the poses resting on that side (each of which is then no pose of its own)."""
    from spar_py.world.parts.stable import stable_poses

    A = mesh_arrays(mesh)
    full = A.V[hull_vertices(mesh)]
    sides = round_sides(mesh, full, faces, features, prims, unit)
    hv = full
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
    rolled = [0.0] * len(sides)  # trimesh's probability of the poses on each round side
    pending: list[tuple[float, np.ndarray]] = []
    for T, p in zip(Ts, probs):
        down = np.asarray(T, float)[:3, :3].T @ np.array([0.0, 0.0, -1.0])  # object vector pointing down
        k = side_of(sides, full, down, unit)
        if k is not None:
            rolled[k] += float(p)
        elif p >= prob_floor:
            pending.append((float(p), down))
    found: list[tuple[float, np.ndarray, float, list[int], list[int]]] = []
    for p, down in pending:
        best = max(normals, key=lambda n: float(n @ down), default=None)
        if best is not None and float(best @ down) > cos_snap:
            down = best
        R = clean(minimal_rotation(down, np.array([0.0, 0.0, -1.0])), 1e-9)
        if any(np.allclose(R[2], f[1][2], atol=1e-6) for f in found):
            continue
        why, height, lying = support_check(mesh, R, faces, unit)
        if why is not None:
            continue
        found.append((p, R, height, lying, _hidden(faces, lying, features, R, height, tol)))
    for side, p in zip(sides, rolled):
        if side.why is not None or p < prob_floor:
            continue
        R, height = side.rest(mesh)
        lying = touching_faces(mesh, faces, R, unit)
        found.append((p, R, height, lying, _hidden(faces, lying, features, R, height, tol)))
    found.sort(key=lambda f: (-round(f[0], 9), tuple(np.round(f[1][2], 9))))
    return [DerivedPose(f"{prefix}{i + 1}", tuple(faces[k].name for k in lying),
                        tuple(faces[k].name for k in hidden), R, float(round(height, 12)), p)
            for i, (p, R, height, lying, hidden) in enumerate(found)]
