"""The quasi-static rule a part resting on the table is kept by, and the pose data derived
with it (world.parts.poses derives the poses; world.parts.rolling reads the rule along the
line a round side rests on).

:func:`support_check`: the part rests on a face of its own, not an edge or a point, and its
centre of mass projects inside the support polygon (the convex hull of the mesh's points on
the table) by at least STABLE_MARGIN_MM, and it does not topple on a tilt of STABLE_TILT_DEG
about any edge of that polygon (the angle whose tangent is the margin over the centre of
mass's height).

Units: lengths in the cell unit, constants in mm (converted with spar_py.core.units.from_mm);
angles in radians. Frames: the object frame; a pose's R turns it into the world's.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from spar_py.core.geometry import convex_hull_2d
from spar_py.core.units import from_mm
from spar_py.world.parts.arrays import mesh_arrays
from spar_py.world.parts.mesh import Face, FeatureGeometry

if TYPE_CHECKING:
    import trimesh

__all__ = ["DerivedPose", "STABLE_MARGIN_MM", "STABLE_TILT_DEG", "SUPPORT_TOL_MM", "feature_face", "hull_vertices",
           "support_check"]

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


def feature_face(faces: list[Face], feature: FeatureGeometry) -> int | None:
    """The index of ``feature``'s face among ``faces`` (None if its surfaces are not on the mesh)."""
    return next((i for i, f in enumerate(faces) if f.feature and f.name == feature.name), None)
