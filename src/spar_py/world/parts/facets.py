"""Facet grasps: across opposite parallel planar faces, their pads' contact with the faces'
overlap, the half-depth variant, and the labelling and filtering of grasp candidates.

Units: lengths in the cell unit, constants in mm (converted with spar_py.core.units.from_mm);
angles in radians. Frames: object frame; tool frames T_g are 4x4 in the object frame.
"""
from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np

from spar_py.core.units import from_mm
from spar_py.world.parts.clip import area_centroid_many, ccw, clip_many, pack
from spar_py.world.parts.hand import DerivedGrasp, TABLE_STEP_MM, covered_faces, euler_zyz_of, grasp_problem
from spar_py.world.parts.mesh import Face, FeatureGeometry, ON_SURFACE_MM, clean, face_of_point

if TYPE_CHECKING:
    import trimesh
    from spar_py.world.robot import Gripper

__all__ = ["face_at", "facet_grasps", "flatten", "half_depth", "pad_contact"]

#: The least contact of each finger pad with a gripped planar face (mm^2).
MIN_CONTACT_MM2 = 25.0
#: Every facet grasp is also offered backed off along its approach while its pads keep this
#: fraction of their contact area (half_depth) ...
HALF_DEPTH_KEEP = 0.5
#: ... when that is at least this far back (mm).
HALF_DEPTH_MIN_MM = 3.0
#: Opposite faces: normals antiparallel within this (deg).
PARALLEL_DEG = 0.05
#: A backed-off pad keeps its share of contact up to this fraction of it: a face whose far half
#: is exactly the share (a block's face under a pad twice its depth) keeps it in any file unit,
#: where a mesh file's float32 vertices (1e-7 of a coordinate) would decide it by chance.
AREA_REL = 1e-6


def facet_grasps(mesh: "trimesh.Trimesh", faces: list[Face], features: tuple[FeatureGeometry, ...], g: Gripper,
                 unit: str, prefix: str, cands: list[tuple[tuple[str, ...], float, np.ndarray]],
                 out: list[DerivedGrasp], unique: bool = True) -> list[DerivedGrasp]:
    """``out`` followed by the candidates (gfaces, width, T) whose fingers and palm stay out of
    the part (:func:`grasp_problem`), each labelled next and given its ofaces (:func:`covered_faces`);
    with ``unique``, a candidate whose T is one already listed is not repeated."""
    out = list(out)
    order = [f.name for f in faces]
    listed = np.array([d.T for d in out], float).reshape(-1, 4, 4)
    for names, width, T in cands:
        if unique and _listed(T, listed):
            continue
        if grasp_problem(mesh, T, width, g, unit) is not None:
            continue
        cover = {faces[k].name for k in covered_faces(mesh, faces, features, T, width, g, unit)}
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


def half_depth(T: np.ndarray, flat: tuple[np.ndarray, np.ndarray, np.ndarray], areas: np.ndarray,
               e1: np.ndarray, e2: np.ndarray, g: Gripper, unit: str, min_area: float) -> np.ndarray | None:
    """The facet grasp at T backed off along its approach, in whole TABLE_STEP_MM, as far as the
    pads keep at least HALF_DEPTH_KEEP of the contact area they have at T (and ``min_area``): the
    fingers hold the part's outer half only, so they stay off what lies beside its inner half (the
    parts around it where it is mated, the table it lies on). None when that is less than
    HALF_DEPTH_MIN_MM back (the grasp at T itself)."""
    step = from_mm(unit, TABLE_STEP_MM)
    a = T[:3, 2]
    need = max(min_area, HALF_DEPTH_KEEP * pad_contact(flat, areas, e1, e2, T, g))

    def holds(k: int) -> bool:
        Ts = T.copy()
        Ts[:3, 3] = T[:3, 3] - k * step * a
        least = need * (1 - AREA_REL)
        return pad_contact(flat, areas, e1, e2, Ts, g, least) >= least

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


def face_at(faces: list[Face], mesh: "trimesh.Trimesh", p: np.ndarray, unit: str) -> str | None:
    k = face_of_point(faces, mesh, p, 10 * from_mm(unit, ON_SURFACE_MM) + 1e-3 * float(mesh.scale))
    return None if k is None else faces[k].name


def flatten(pieces: list[np.ndarray]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Polygons (each (k, 2)) as their corners stacked, their corner counts and the index of
    each one's first corner: :func:`pad_contact`'s form, built once per face pair."""
    sizes = np.array([len(p) for p in pieces], int)
    starts = np.concatenate([[0], np.cumsum(sizes)[:-1]]).astype(int)
    return (np.concatenate(pieces) if pieces else np.zeros((0, 2))), sizes, starts


def pad_contact(flat: tuple[np.ndarray, np.ndarray, np.ndarray], areas: np.ndarray, e1: np.ndarray,
                e2: np.ndarray, T: np.ndarray, g: Gripper, need: float = math.inf) -> float:
    """Area of the overlap pieces (``flat``: :func:`flatten`'s, plane basis e1, e2) under one
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
        P, cnt = pack([ccw(Q[starts[i]: starts[i] + sizes[i]]) for i in part])
        for a in area_centroid_many(*clip_many(P, cnt, pad))[0]:
            total += float(a)
    return total
