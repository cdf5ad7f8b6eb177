"""Parts of a derived product that overlap as placed: a pin wider than its bore, a cover whose
bores are farther apart than the shafts they go over. Such parts cannot be assembled, and the
derivation would find them stuck; this names them instead, with what meets where.

Frames and units: the meshes in the product frame, one length unit (the derivation's); the
volumes in that unit cubed. Two parts overlap when their meshes' intersection (manifold3d,
through trimesh) has a mean thickness (2 V / A, V its volume and A its area) above
OVERLAP_REL of ``contact_tol``: touching faces leave a sliver of float noise (3e-5 mm thick
across Fabrica's beam's tenons, 3e-6 mm across its duct's halves), a pin 0.1 mm wider than
its bore a ring 0.05 mm thick.

Where they meet: the intersection's faces lie on one part's surface inside the other; each
side's faces (those nearer its surface than the other's) are mapped to that part's triangles,
and those are fitted as a round wall about an axis (the least eigenvector of the area-weighted
sum of n n^T, the walls' vertices on one circle about it): a peg when their normals point away
from the axis, a hole when towards it; anything else is a surface, placed at its centroid.
"""
from __future__ import annotations

import itertools
import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    import trimesh

__all__ = ["OVERLAP_REL", "Overlap", "Wall", "overlaps"]

#: Parts overlap when their intersection's mean thickness exceeds this fraction of contact_tol.
OVERLAP_REL = 0.01
#: A triangle is a wall about an axis when |n . d| is below this (sin 3 deg).
SIN_WALL = math.sin(math.radians(3.0))
#: A wall's vertices lie on its fitted circle within this fraction of the radius.
CIRCLE_REL = 0.01


@dataclass(frozen=True)
class Wall:
    """Where one part's surface lies inside another (product frame, the meshes' unit):
    ``kind`` 'peg' (a round wall whose normals point away from its axis), 'hole' (towards
    it) or 'surface' (neither); for a peg or hole ``point`` is on the axis, midway along the
    overlap, ``axis`` unit (its largest component positive) and ``radius`` the wall's; for a
    surface ``point`` is the overlap's centroid there, ``axis`` None and ``radius`` 0."""

    kind: str
    point: tuple[float, float, float]
    axis: tuple[float, float, float] | None = None
    radius: float = 0.0


@dataclass(frozen=True)
class Overlap:
    """Parts ``a`` and ``b`` overlap by ``volume`` (the meshes' unit cubed); ``wall_a`` is
    a's surface inside b, ``wall_b`` b's inside a."""

    a: str
    b: str
    volume: float
    wall_a: Wall
    wall_b: Wall


def overlaps(meshes: dict[str, "trimesh.Trimesh"], contact_tol: float) -> list[Overlap]:
    """The pairs of ``meshes`` (product frame) that overlap (module docstring), the largest
    volume first. A pair whose boxes are apart is not intersected; one whose meshes are not
    closed volumes cannot be, and is taken as not overlapping."""
    import trimesh

    out = []
    for a, b in itertools.combinations(meshes, 2):
        ma, mb = meshes[a], meshes[b]
        if np.any(ma.bounds[0] >= mb.bounds[1]) or np.any(mb.bounds[0] >= ma.bounds[1]):
            continue
        if not (ma.is_volume and mb.is_volume):
            continue
        inter = trimesh.boolean.intersection([ma, mb], engine="manifold")
        if len(inter.faces) == 0 or inter.area <= 0:
            continue
        with np.errstate(divide="ignore", invalid="ignore"):
            volume = float(abs(inter.volume))
        if not 2 * volume / float(inter.area) > OVERLAP_REL * contact_tol:
            continue
        wall_a, wall_b = _walls(ma, mb, inter)
        out.append(Overlap(a, b, volume, wall_a, wall_b))
    return sorted(out, key=lambda o: -o.volume)


def _walls(ma: "trimesh.Trimesh", mb: "trimesh.Trimesh", inter: "trimesh.Trimesh") -> tuple[Wall, Wall]:
    """Each part's surface inside the other: the intersection's faces split by which part's
    surface each lies on (the nearer), each side fitted on its part's own triangles there."""
    import trimesh

    C = np.asarray(inter.triangles_center, float)
    _, da, ta = trimesh.proximity.closest_point(ma, C)
    _, db, tb = trimesh.proximity.closest_point(mb, C)
    on_a = np.asarray(da) <= np.asarray(db)
    areas = np.asarray(inter.area_faces, float)
    T = np.asarray(inter.triangles, float)
    return (_wall(ma, np.asarray(ta)[on_a], T[on_a], areas[on_a]),
            _wall(mb, np.asarray(tb)[~on_a], T[~on_a], areas[~on_a]))


def _wall(mesh: "trimesh.Trimesh", tris: np.ndarray, T: np.ndarray, w: np.ndarray) -> Wall:
    """The part's triangles ``tris`` (under the intersection's faces there: ``T`` (k, 3, 3),
    areas ``w``) as a round wall (peg or hole) when they fit one, else a surface at the faces'
    centroid."""
    from spar_py.world.parts import fit_circle

    if len(T) == 0:
        return Wall("surface", (math.nan,) * 3)
    centroid = tuple(float(x) for x in (T.mean(1) * w[:, None]).sum(0) / max(float(w.sum()), 1e-300))
    tris, inv = np.unique(tris, return_inverse=True)
    N = np.asarray(mesh.face_normals[tris], float)
    area = np.bincount(inv.ravel(), weights=w, minlength=len(tris))  # the overlap's area on each triangle
    _, vecs = np.linalg.eigh((N * area[:, None]).T @ N)
    d = vecs[:, 0]
    wall = np.abs(N @ d) < SIN_WALL
    if wall.sum() < 3 or area[wall].sum() < 0.5 * area.sum():
        return Wall("surface", centroid)
    fit = fit_circle(np.asarray(mesh.vertices, float)[np.unique(mesh.faces[tris[wall]])], d, CIRCLE_REL)
    if fit is None:
        return Wall("surface", centroid)
    o, r = fit
    Cw = np.asarray(mesh.triangles_center[tris[wall]], float) - o
    out = np.einsum("ij,ij->i", Cw - np.outer(Cw @ d, d), N[wall])
    if not ((out > 0).all() or (out < 0).all()):
        return Wall("surface", centroid)
    d = d if d[np.argmax(np.abs(d))] > 0 else -d
    t = (T.reshape(-1, 3) - o) @ d
    mid = o + d * float((t.min() + t.max()) / 2)
    return Wall("peg" if out[0] > 0 else "hole", tuple(float(x) for x in mid), tuple(float(x) for x in d), float(r))
