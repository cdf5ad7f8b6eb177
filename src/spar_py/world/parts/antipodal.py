"""Antipodal grasps: contact pairs sampled on the surface, planar or curved, within a friction
cone, clustered by closing direction and tried at quantised approaches.

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
from spar_py.world.parts.hand import approaches, canonical, grasp_problem, tool_frame
from spar_py.world.parts.mesh import clean, cross

if TYPE_CHECKING:
    import trimesh
    from spar_py.world.robot import Gripper

__all__ = ["Antipodal", "antipodal_grasps", "antipodal_pairs"]

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

    A = mesh_arrays(mesh)
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
    far = 2 * mesh_arrays(mesh).diag
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
    pairs, least = antipodal_pairs(mesh, g.finger_separation, unit)
    if allowed is not None:
        pairs = [a for a in pairs if allowed[a.tp] or allowed[a.tq]]
    if not pairs:
        return [], least, 0
    A = mesh_arrays(mesh)
    cell = A.diag / ANTIPODAL_GRID
    mm = from_mm(unit, 1.0)  # ties are broken on lengths in mm: the same grasps in any unit
    groups: dict[tuple, Antipodal] = {}
    count: dict[tuple, int] = {}

    def rank(a: Antipodal) -> tuple:
        return round(a.angle, 6), round(a.width / mm, 9)

    for a in pairs:
        c = canonical(a.c)
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
        c = canonical(clean(a.c, 1e-12))
        mid = (a.p + a.q) / 2
        for ap in approaches(c, step):
            T = tool_frame(mid + inset * ap, c, ap)
            if grasp_problem(mesh, T, a.width, g, unit) is None:
                out.append((T, a.width, a))
    return out, least, len(pairs)
