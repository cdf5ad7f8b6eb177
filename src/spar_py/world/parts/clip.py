"""Polygon clipping and areas in 2-D (Sutherland-Hodgman, one polygon or many at once as packed
arrays) and the overlap of two opposite faces projected on their mid-plane, the area a facet
grasp's finger pads can touch.

Units: lengths in the cell unit, constants in mm (converted with spar_py.core.units.from_mm);
angles in radians. Frames: object frame; tool frames T_g are 4x4 in the object frame.
"""
from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from spar_py.world.parts.arrays import mesh_arrays
from spar_py.world.parts.mesh import Face

if TYPE_CHECKING:
    import trimesh

__all__ = ["area_centroid_many", "ccw", "clip_many", "face_overlap", "pack"]

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


def pack(polys: "list[np.ndarray]") -> tuple[np.ndarray, np.ndarray]:
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


def clip_many(P: np.ndarray, cnt: np.ndarray, clip: "np.ndarray | list") -> tuple[np.ndarray, np.ndarray]:
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


def area_centroid_many(P: np.ndarray, cnt: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
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


def ccw(P: np.ndarray) -> np.ndarray:
    """Polygon ``P`` (k, 2) with its corners counter-clockwise (reversed if its signed area is
    negative); the successors by slicing, np.roll's values without its overhead."""
    x, y = P[:, 0], P[:, 1]
    xn, yn = np.concatenate((x[1:], x[:1])), np.concatenate((y[1:], y[:1]))
    return P if (x * yn - xn * y).sum() >= 0 else P[::-1]


def face_overlap(mesh: "trimesh.Trimesh", fa: Face, fb: Face, e1: np.ndarray, e2: np.ndarray) -> list[np.ndarray]:
    """The convex pieces (each (k, 2) in the plane basis e1, e2) where the two faces overlap
    when projected on a plane normal to them: each triangle of the face with more (A) clipped
    by each triangle of the other (B) whose box meets its box, in B's order; a triangle of A
    wholly inside one of B is that triangle's piece and no later one's. All pairs at once
    (numpy), the pieces in the order a loop over B would give them."""
    arr = mesh_arrays(mesh)
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
    P, cnt = clip_many(A[ii[cut]], np.full(len(cut), 3), B[jj[cut]])
    area, _ = area_centroid_many(P, cnt)
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
