"""The vectorised distance bounds: the distance of segments (a capsule pair's, exact), the
separating-axis lower bound of convex bodies (:func:`support_gap`), the table's slab beside its
edge, and bounding capsules within a distance. A pair a bound puts beyond the margin is clear by
it; only the others go to the library (bodies.py's :func:`~spar_py.world.collision.bodies.body_distance`).
"""
from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from spar_py.world.collision.bodies import Body

__all__ = ["FEW_SEGMENTS", "gap_of_extents", "near_all", "over_table", "segment_distance", "slab_gap",
           "support_directions", "support_gap"]


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
    return gap_of_extents(pa.min(axis=1), pa.max(axis=1), ra, np.abs(Pa).max(axis=(1, 2)),
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


def gap_of_extents(alo: np.ndarray, ahi: np.ndarray, ra: np.ndarray, abig: np.ndarray, blo: np.ndarray,
                   bhi: np.ndarray, rb: np.ndarray, bbig: np.ndarray, valid: np.ndarray) -> np.ndarray:
    """:func:`support_gap` from each body's extent along each direction ((c, 16) min and max), the
    radii (c,), a bound of each body's largest coordinate (c,) for the rounding allowance, and
    the directions' validity (c, 16)."""
    gap = np.maximum(blo - ahi, alo - bhi)
    best = np.where(valid, gap, -np.inf).max(axis=1) - ra - rb
    scale = np.maximum(abig, bbig) + np.maximum(ra, rb)
    return best - 1e-9 * (1.0 + scale)


def over_table(P: np.ndarray, r: float, ext: tuple[float, float, float, float]) -> np.ndarray:
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


def slab_gap(P: np.ndarray, r: float, ext: tuple[float, float, float, float]) -> np.ndarray:
    """(n,) a lower bound of each row's body's distance (cell unit) to the table's slab (the
    footprint ``ext`` = (x0, x1, y0, y1) from the top z = 0 down), for bodies beside its edge:
    for convex sets the distance is the largest gap between their supports over unit directions
    u, here the best of :data:`_SLAB_U` (never above the distance, so never too optimistic).
    ``P`` (n, k, 3) are the bodies' world vertices, ``r`` their sweep radius."""
    x0, x1, y0, y1 = ext
    U = _SLAB_U
    support = np.where(U[:, 0] > 0, x1, x0) * U[:, 0] + np.where(U[:, 1] > 0, y1, y0) * U[:, 1]
    return ((P @ U.T).min(axis=1) - support).max(axis=1) - r


def near_all(A: list[Body], B: list[Body], within: float) -> np.ndarray:
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
