"""Sound bounds of a function of a transform chain's point by convex point sets (used by supinf).

A :class:`~spar_py.phase2.symbolic.ChainExpr` is ``g(x)``, ``x = F_1 F_2 ... F_n p``: constant
transforms and error transforms ``trans(d) rotz(theta)`` (or their inverses), each error
variable bounded. The set of points ``x`` the variables reach is built from the right:

    S_n = {p},   S_{k-1} = {F_k(v) y : v in its box, y in S_k},

and carried as a finite point set V with a ball radius e: S_k lies in conv(V) + B(e). Each
factor maps the representation soundly:

* a constant affine map y -> A y + t maps every point (e grows by ||A||_2 and by a bound
  on the rounding of the products);
* a translation over a box adds its corners (conv(V) + box = conv(V + corners));
* a rotation about z by theta in [a, b] replaces each point by a polygon around its arc:
  the arc's end points and, for k segments of angle delta, the k points where neighbouring
  tangents meet (at radius r / cos(delta / 2)); the arc lies in their hull, and the hull
  of the union over theta of R(theta) conv(V) is the hull of the points' arcs. k is chosen
  so that the polygon leaves the arc by at most ``tol`` (r (1 / cos(delta / 2) - 1)).

After each step V is pruned to its convex hull's vertices (scipy's Qhull). Qhull decides
in floating point which points are interior; its roundoff is of the order of 1e-15 of the
coordinates, and e grows by :data:`PRUNE_MARGIN` of them at every pruning, which
covers a point it may misjudge (a set too flat for a 3-d hull is pruned in its plane,
and e grows by twice its distance from it too). Every other rounding (sin, cos, hypot,
products) is bounded by a few dozen ulps of the magnitudes involved and added to e.

The end: for ``c . x + offset`` the bounds are ``min / max_V c . v -+ |c| e``; for
``|x - q|^2`` the maximum is at a vertex, and the minimum distance is bounded below by
the plane through q's nearest point of conv(V) (Gilbert's algorithm; any unit normal n
gives ``dist >= n . q - max_V n . v``). The set is not convex, and its hull may come far
nearer q than the set does, so the minimum is also bounded by splitting the chain after
its first error factors (``_split_lower``: the distance between the hull of the right
part's points and the hull of q carried back through the left part, on pieces of the left
part's angles), and the best bound is kept. Each point also carries the variables' values it
came from (its *witness*: an arc end point's angle is attained exactly, a tangent point's
is the middle of its segment), so supinf can evaluate the function where the bounds are
nearly attained.

Units: the chain's (lengths in the cell unit, angles in radians); ``tol`` in the unit of x.
"""
from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np

from spar_py.core.geometry import inv
from spar_py.phase2.symbolic import ChainExpr, ErrorFactor

__all__ = ["HullBound", "hull_bounds"]

_U = 2.0 ** -53
#: Relative margin (of the largest coordinate) added to the ball radius at each pruning to
#: a convex hull: orders of magnitude above Qhull's roundoff (about 1e-15 of the
#: coordinates). A set too flat for a 3-d hull is pruned to the hull of its projection on
#: its plane (or line), and the radius grows by twice its distance from it as well.
PRUNE_MARGIN = 1e-11
#: The largest arc segment (rad): the tangent construction needs delta < pi.
MAX_SEGMENT = 0.5 * math.pi
#: The most points one rotation makes (segments are widened beyond: sound, but looser than
#: the tolerance asked).
MAX_POINTS = 200_000


@dataclass(frozen=True)
class HullBound:
    """Sound bounds ``lo <= g <= hi`` over the box; ``lo_at`` / ``hi_at`` (the variables'
    values, in the caller's order) are where g is near them; ``vertices`` the largest point
    set carried; ``radius`` the final ball radius e (unit of x); ``tol_kept``: every arc was
    followed within the tolerance asked (False: :data:`MAX_POINTS` made some segments wider)."""

    lo: float
    hi: float
    lo_at: np.ndarray
    hi_at: np.ndarray
    vertices: int
    radius: float
    tol_kept: bool = True


class _Points:
    """conv(V) + B(e) with a witness row per point (W: the variables' values)."""

    def __init__(self, p: np.ndarray, w0: np.ndarray) -> None:
        self.V = p[None, :].astype(float)
        self.W = w0[None, :].copy()
        self.e = 0.0
        self.most = 1
        self.tol_kept = True

    def scale(self) -> float:
        return float(np.abs(self.V).max()) if self.V.size else 0.0

    def affine(self, M: np.ndarray) -> None:
        A, t = M[:3, :3], M[:3, 3]
        # ||A||_2 from the SVD (backward stable: within a few ulps), rounded up generously
        sigma = float(np.linalg.norm(A, 2)) * (1.0 + 1e-12) + 1e-300
        err = 8.0 * _U * float((np.abs(self.V) @ np.abs(A).T + np.abs(t)).max()) * math.sqrt(3.0)
        self.V = self.V @ A.T + t
        self.e = self.e * sigma + err

    def shift(self, ends: Sequence[tuple[float, float, int | None]], sign: float) -> None:
        """V + sign * corners of the box ``ends`` ((lo, hi, variable index or None) per axis)."""
        axes = [sorted({lo, hi}) for lo, hi, _ in ends]
        corners = np.array(np.meshgrid(*axes, indexing="ij")).reshape(3, -1).T
        n, k = len(self.V), len(corners)
        V = (self.V[:, None, :] + sign * corners[None, :, :]).reshape(n * k, 3)
        W = np.repeat(self.W[:, None, :], k, 1)
        for a, (_, _, j) in enumerate(ends):
            if j is not None:
                W[:, :, j] = corners[None, :, a]
        err = 4.0 * _U * (self.scale() + float(np.abs(corners).max())) * math.sqrt(3.0)
        self.V, self.W = V, W.reshape(n * k, -1)
        self.e += err

    def rotate(self, a: float, b: float, j: int | None, sign: float, tol: float) -> None:
        """Every point's arc under rotz(alpha), alpha in [a, b] (a <= b); witness theta = sign * alpha."""
        x, y, z = self.V[:, 0], self.V[:, 1], self.V[:, 2]
        r = np.hypot(x, y)
        phi = np.arctan2(y, x)
        rmax = float(r.max())
        if b > a and rmax > 0.0:
            delta_max = min(MAX_SEGMENT, math.sqrt(8.0 * max(tol, 1e-300) / rmax))
            want = max(1, math.ceil((b - a) / delta_max))
            # at most MAX_POINTS points: fewer, wider segments beyond (still sound, looser than tol)
            k = max(min(want, MAX_POINTS // len(r) - 2), math.ceil((b - a) / MAX_SEGMENT))
            self.tol_kept &= k >= want
            delta = (b - a) / k
            apex = (1.0 / math.cos(0.5 * delta)) * (1.0 + 16.0 * _U)
            # the polygon's excess over the arc must stay within tol: r (1/cos - 1) <= r delta^2 / 8
            offs = np.concatenate(([a, b], a + (np.arange(k) + 0.5) * delta))
            scales = np.concatenate(([1.0, 1.0], np.full(k, apex)))
        else:
            offs, scales = np.array([a]), np.array([1.0])
        ang = phi[:, None] + offs[None, :]
        rr = r[:, None] * scales[None, :]
        m = offs.size
        V = np.stack((rr * np.cos(ang), rr * np.sin(ang), np.repeat(z[:, None], m, 1)), axis=-1).reshape(-1, 3)
        W = np.repeat(self.W[:, None, :], m, 1)
        if j is not None:
            W[:, :, j] = sign * offs[None, :]
        self.e += 64.0 * _U * rmax * float(scales.max()) * (3.0 + float(np.abs(ang).max()))
        self.V, self.W = V, W.reshape(len(V), -1)

    def prune(self) -> None:
        """V to the vertices of its convex hull (duplicates dropped first)."""
        self.most = max(self.most, len(self.V))
        if len(self.V) <= 4:
            return
        V, idx = np.unique(self.V, axis=0, return_index=True)
        keep = idx
        if len(V) > 4:
            from scipy.spatial import ConvexHull, QhullError  # only a pruned vertex set

            try:
                keep = idx[ConvexHull(V).vertices]
            except (QhullError, ValueError):  # flat (or on a line): the hull of its projection
                sub, extra = _flat_vertices(V)
                keep = idx[sub]
                self.e += extra
            self.e += PRUNE_MARGIN * self.scale()
        self.V, self.W = self.V[keep], self.W[keep]


def _flat_vertices(V: np.ndarray) -> tuple[np.ndarray, float]:
    """For points V (n, 3) too flat for a 3-d hull: the indices of the vertices of the hull
    of their projection on their best plane (or line), and how far that can leave out: every
    point is within ``h`` of the plane (its largest residual), so within 2 h (plus rounding)
    of the hull of the kept points themselves."""
    from scipy.spatial import ConvexHull, QhullError  # see prune

    c = V.mean(axis=0)
    D = V - c
    _, _, Vt = np.linalg.svd(D, full_matrices=False)
    for dim in (2, 1):
        P = D @ Vt[:dim].T
        R = D - P @ Vt[:dim]
        h = float(np.sqrt((R * R).sum(1)).max()) if len(R) else 0.0
        extra = 2.0 * h + 16.0 * _U * float(np.abs(V).max()) * math.sqrt(3.0)
        if dim == 1:
            return np.unique([int(np.argmin(P[:, 0])), int(np.argmax(P[:, 0]))]), extra
        try:
            return ConvexHull(P).vertices, extra
        except (QhullError, ValueError):
            continue
    raise AssertionError("unreachable")  # pragma: no cover


def _ends(v: object, index: dict[int, int], lo: np.ndarray, hi: np.ndarray) -> tuple[float, float, int | None]:
    if isinstance(v, float):
        return v, v, None
    j = index.get(v.element_hash())  # type: ignore[attr-defined]
    if j is None:  # a variable the expression does not depend on (CasADi folded it away): any value
        return 0.0, 0.0, None
    return float(lo[j]), float(hi[j]), j


def _propagate(S: _Points, factors: Sequence[object], index: dict[int, int], lo: np.ndarray, hi: np.ndarray,
               tol: float, stages: list[tuple[np.ndarray, float]] | None = None) -> _Points:
    """S through ``factors`` (applied right to left, as a product maps a point); ``stages``
    gets (V, e) before each factor, last factor first (so stages[-1 - k] is the set of
    ``factors[k:]``'s points once the loop is done)."""
    for f in reversed(factors):
        if stages is not None:
            stages.append((S.V, S.e))
        if not isinstance(f, ErrorFactor):
            S.affine(f)  # type: ignore[arg-type]
            continue
        d = [_ends(e, index, lo, hi) for e in (f.dx, f.dy, f.dz)]
        ta, tb, tj = _ends(f.theta, index, lo, hi)
        if f.inverse:  # rotz(-theta) (y - d)
            S.shift(d, -1.0)
            S.prune()
            S.rotate(-tb, -ta, tj, -1.0, tol)
        else:  # trans(d) rotz(theta) y
            S.rotate(ta, tb, tj, 1.0, tol)
            S.prune()
            S.shift(d, 1.0)
        S.prune()
    return S


def hull_bounds(ce: ChainExpr, names: Sequence[str], lo: np.ndarray, hi: np.ndarray, tol: float,
                index: dict[int, int] | None = None) -> HullBound:
    """Sound bounds of ``ce`` over the box ``lo <= v <= hi`` (the variables ``names``, in that
    order); every arc polygon leaves its arc by at most ``tol`` (unit of x). ``index`` maps
    the chain's symbols (``element_hash``) to positions in ``names`` (default: by name)."""
    if index is None:
        pos = {n: i for i, n in enumerate(names)}
        index = {s.element_hash(): pos[s.name()] for s in ce.chain.symbols() if s.name() in pos}
    stages: list[tuple[np.ndarray, float]] = []
    S = _propagate(_Points(np.array(ce.point), 0.5 * (lo + hi)), ce.chain.factors, index, lo, hi, tol, stages)
    out = _finish(ce, S)
    if ce.kind == "sqdist" and out.lo < out.hi:
        stages.append((S.V, S.e))
        stages.reverse()  # stages[k]: the points of factors[k:] applied to the point
        lower = max(_split_lower(ce, stages, k, index, lo, hi, tol) for k in _splits(ce.chain.factors))
        if lower > 0.0:
            lo_k = float(np.nextafter(lower * lower * (1.0 - 4.0 * _U), 0.0))
            out = replace(out, lo=max(out.lo, lo_k))
    return out


#: The distance splits of a squared distance (``_split_lower``): after the first SPLITS error
#: factors, each of whose angles is cut into SPLIT_PIECES pieces.
SPLITS = 2
SPLIT_PIECES = 4


def _splits(factors: Sequence[object]) -> list[int]:
    """The k (prefix lengths) just after each of the first SPLITS error factors."""
    ks = [k + 1 for k, f in enumerate(factors) if isinstance(f, ErrorFactor)]
    return ks[:SPLITS] or [0]


def _split_lower(ce: ChainExpr, stages: list[tuple[np.ndarray, float]], k: int, index: dict[int, int],
                 lo: np.ndarray, hi: np.ndarray, tol: float) -> float:
    """A lower bound on min |x - q| from the split T = A B (A the first k factors): for
    A an isometry up to sigma = the product of its constants' smallest singular values,
    |A B p - q| >= sigma |B p - A^-1 q|, so the distance between the hull of B's points
    (stages[k]) and the hull of A^-1 q, taken on pieces of A's angles (the least over the
    pieces), bounds it. The hull of A^-1 q is far less bent than the whole set's, whose
    hull can come much nearer q than the set does."""
    if k == 0:
        return -math.inf
    A = ce.chain.factors[:k]
    VB, eB = stages[k]
    sigma = 1.0
    inverse: list[object] = []  # F_1^-1, ..., F_k^-1: the order they meet q in
    for f in A:
        if isinstance(f, ErrorFactor):
            inverse.append(f.inverted())
            continue
        M = np.asarray(f, float)
        s_min, g = _inverse_error(M[:3, :3])
        sigma *= s_min
        inverse.append((M, g))
    angle_vars = (_ends(f.theta, index, lo, hi)[2] for f in A if isinstance(f, ErrorFactor))
    thetas = sorted({j for j in angle_vars if j is not None})
    worst = math.inf
    for cell in np.ndindex(*(SPLIT_PIECES,) * len(thetas)):
        l2, h2 = lo.copy(), hi.copy()
        for j, c in zip(thetas, cell):
            w = (hi[j] - lo[j]) / SPLIT_PIECES
            l2[j] = lo[j] + c * w
            h2[j] = hi[j] if c == SPLIT_PIECES - 1 else lo[j] + (c + 1) * w
        Q = _Points(np.array(ce.vector), 0.5 * (l2 + h2))
        for f in inverse:  # A^-1 q = F_k^-1 (... F_1^-1 (q))
            if isinstance(f, ErrorFactor):
                _propagate(Q, [f], index, l2, h2, tol)
            else:
                M, g = f
                t = M[:3, 3]
                reach = float(np.sqrt(((Q.V - t) ** 2).sum(1)).max()) * (1.0 + 4.0 * _U) + Q.e
                Q.affine(np.asarray(inv(M), float))  # [R^T, -R^T t]
                # the exact inverse maps y to within g |y - t| of R^T (y - t); -R^T t is rounded
                Q.e += g * reach + 8.0 * _U * float(np.abs(t).sum()) * math.sqrt(3.0)
        d = _distance_lower(VB, Q.V) - eB - Q.e
        worst = min(worst, d)
        if worst <= 0.0:
            return 0.0
    return sigma * worst


def _inverse_error(A: np.ndarray) -> tuple[float, float]:
    """(a lower bound on A's smallest singular value, a bound on ||A^-1 - A^T||_2): A is
    nearly orthonormal, E = I - A^T A, A^-1 = (I - E)^-1 A^T, so the gap is at most
    ||A|| ||E|| / (1 - ||E||)."""
    sv = np.linalg.svd(A, compute_uv=False)
    s_min = float(sv[-1]) * (1.0 - 1e-12)
    nA = float(sv[0]) * (1.0 + 1e-12)
    E = float(np.linalg.norm(np.eye(3) - A.T @ A, 2)) + 16.0 * _U * nA * nA
    if not (E < 0.5 and s_min > 0.0):
        return 0.0, math.inf  # not nearly orthonormal: the split gives nothing
    return s_min, nA * E / (1.0 - E)


def _finish(ce: ChainExpr, S: _Points) -> HullBound:
    V, W, e = S.V, S.W, S.e
    if ce.kind == "linear":
        c = np.array(ce.vector)
        vals = V @ c + ce.offset
        err = float(np.linalg.norm(c)) * (1.0 + 1e-12) * e + 8.0 * _U * float((np.abs(V) @ np.abs(c)).max()
                                                                          + abs(ce.offset))
        i, k = int(np.argmin(vals)), int(np.argmax(vals))
        lo = float(np.nextafter(vals[i] - err, -np.inf))
        hi = float(np.nextafter(vals[k] + err, np.inf))
        return HullBound(lo, hi, W[i].copy(), W[k].copy(), S.most, e, S.tol_kept)
    q = np.array(ce.vector)
    D = V - q
    dist = np.sqrt((D * D).sum(1))
    rounding = 8.0 * _U * (float(np.abs(V).max()) + float(np.abs(q).max())) * math.sqrt(3.0)
    k = int(np.argmax(dist))
    hi = float(np.nextafter((dist[k] * (1.0 + 4.0 * _U) + e + rounding) ** 2 * (1.0 + 4.0 * _U), np.inf))
    i = int(np.argmin(dist))
    lower = _distance_lower(V, q) - e - rounding
    lo = 0.0 if lower <= 0.0 else float(np.nextafter(lower * lower * (1.0 - 4.0 * _U), 0.0))
    return HullBound(lo, hi, W[i].copy(), W[k].copy(), S.most, e, S.tol_kept)


def _distance_lower(P: np.ndarray, Q: np.ndarray, iterations: int = 64) -> float:
    """A lower bound on the distance between conv(P) and conv(Q) (<= 0 when they may meet;
    Q may be one point): the best separating direction found by Gilbert's algorithm on
    conv(Q) - conv(P), each checked against every vertex of both, with rounding margins."""
    Q = np.atleast_2d(Q)
    x = Q[0] - P[int(np.argmin(((P - Q[0]) ** 2).sum(1)))]
    best = -math.inf
    margin = 8.0 * _U * (float(np.abs(P).max()) + float(np.abs(Q).max())) * 3.0
    for _ in range(iterations):
        nx = float(np.linalg.norm(x))
        if nx == 0.0:
            return 0.0
        iq, ip = int(np.argmin(Q @ x)), int(np.argmax(P @ x))
        v = Q[iq] - P[ip]  # the support point of Q - P furthest against x
        best = max(best, float(x @ v) / nx - margin)
        dv = v - x
        den = float(dv @ dv)
        if den == 0.0:
            break
        t = min(1.0, max(0.0, -float(x @ dv) / den))
        if t == 0.0:
            break
        x = x + t * dv
    return best
