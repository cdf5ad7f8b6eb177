"""Second-order reasoning from an affine enclosure of the gradient (used by supinf's search).

:class:`~spar_py.phase2.supinf.AffineProgram` run on an expression *and its gradient* over a box
gives, for every component, an affine form in the box's normalised coordinates

    s_j = (x_j - mid_j) / rd_j  in [-1, 1]  (``mid``, ``rd``: the form's centre and radii),

    dg/dx_i (x)  in  G0_i + sum_j A_ij s_j + [-rho_i, rho_i]   for every x in the box,

(``rho_i`` gathers the nonlinear operations' noise symbols and the radius). That is a
first-order model of the gradient valid on the whole box, and so on every sub-box of it.
Two things follow without evaluating the expression again:

1. **Iterated monotonicity.** On a sub-box, the enclosure of dg/dx_i is the model's range
   there. Where it has one sign, the minimum of g lies on the face x_i = lo_i (or hi_i);
   fixing x_i tightens every other component's enclosure, which may fix more. Repeated
   until nothing changes, this collapses a box towards the face or vertex holding the
   minimum in one pass instead of one expression evaluation per fixed variable.
2. **A quadratic lower bound.** With c the centre (where s = 0) and f C^1 on the box,
   g(c + d) - g(c) = int_0^1 grad g(c + t d) . d dt, and the model integrates exactly:

       g(x) >= g(c) + sum_i b_i s_i + 1/2 sum_ij P_ij s_i s_j - sum_i gamma_i |s_i|,
       b_i = rd_i G0_i,  P_ij = rd_i A_ij,  gamma_i = rd_i rho_i,

   whose error is third order in the box size (the mean-value form's is second order).
   Its minimum over a sub-box of s is bounded below separably: around the sub-box centre,
   t^T P t >= sum_i (P_ii - sum_{j != i} |P_ij| tau_j / tau_i) t_i^2 (weighted AM-GM), and
   each coordinate's quadratic is minimised exactly on its interval.

"C^1" may be relaxed to "Lipschitz, with the model enclosing the Clarke gradient" (how
supinf uses it across the kinks of ``fabs``): along a segment a Lipschitz g is the integral
of its derivative, which exists almost everywhere and lies in the Clarke gradient's
projection, so the integral bound holds; and a Clarke gradient component of one sign on a
box makes g monotone in that variable there (Lebourg's mean-value theorem).

Units: ``mid``, ``rd`` and boxes are in the variables' units; ``G0``, ``A``, ``rho`` in units
of g per unit of the variable; ``b``, ``P``, ``gamma`` and the bounds in units of g.
Floating point: every enclosure and bound computed here is widened by a relative margin
(``(n + 4) * 8 * eps`` of the sum of the magnitudes it combines, n the number of
variables), which covers the rounding of the sums and products that computed it.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["GradientModel", "affine_centres"]

_EPS = float(np.finfo(float).eps)


def affine_centres(lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The centres and radii (both (m, n)) an affine program gives boxes (m, n): x_j lies in
    mid_j + rd_j [-1, 1] for every x_j in [lo_j, hi_j] (rd rounded up)."""
    mid = np.minimum(np.maximum(0.5 * (lo + hi), lo), hi)
    rd = np.maximum(np.nextafter(hi - mid, np.inf), np.nextafter(mid - lo, np.inf))
    return mid, rd


@dataclass(frozen=True)
class GradientModel:
    """The affine model of the gradient of g (g = f, or -f for an upper bound) on m boxes.

    For every x in box b: dg/dx_i (x) in G0[b, i] + sum_j A[b, i, j] s_j +- rho[b, i] with
    s_j = (x_j - mid[b, j]) / rd[b, j]. Shapes: mid, rd, G0, rho (m, n); A (m, n, n).
    """

    mid: np.ndarray
    rd: np.ndarray
    G0: np.ndarray
    A: np.ndarray
    rho: np.ndarray

    @classmethod
    def from_affine(cls, F: np.ndarray, n_inputs: int, lo: np.ndarray, hi: np.ndarray,
                    negate: np.ndarray) -> GradientModel:
        """The model from affine forms ``F`` (rows, 1 + n, m) of (f, df/dx_1, ..., df/dx_n) over
        boxes ``lo``, ``hi`` (m, n) (rows: centre, n input symbols, other symbols, radius);
        ``negate`` (m,) True where g = -f."""
        K = n_inputs
        sign = np.where(negate, -1.0, 1.0)
        G = F[:, 1:, :]  # (rows, n, m)
        G0 = (G[0] * sign).T
        A = np.transpose(G[1:K + 1], (2, 1, 0)) * sign[:, None, None]  # (m, i, j)
        other = np.abs(G[K + 1:-1]).sum(0) + G[-1]
        rho = (other * (1.0 + (G.shape[0] + 4) * _EPS) + 1e-300).T
        mid, rd = affine_centres(lo, hi)
        return cls(mid, rd, G0, A, rho)

    @property
    def finite(self) -> np.ndarray:
        """(m,) True where every entry of the model is finite (the others are not used)."""
        return (np.isfinite(self.G0).all(1) & np.isfinite(self.rho).all(1)
                & np.isfinite(self.A).all((1, 2)))

    def coords(self, lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Enclosures (sl, sh) (m, n) of the normalised coordinates of sub-boxes [lo, hi]."""
        sl = (lo - self.mid) / self.rd
        sh = (hi - self.mid) / self.rd
        m = 4 * _EPS * (1.0 + np.abs(sl)), 4 * _EPS * (1.0 + np.abs(sh))
        return sl - m[0], sh + m[1]

    def gradient(self, sl: np.ndarray, sh: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Rigorous enclosures (lo, hi) (m, n) of dg/dx_i over the sub-boxes s in [sl, sh]."""
        sc = 0.5 * (sl + sh)
        sr = 0.5 * (sh - sl) * (1.0 + 4 * _EPS) + 2 * _EPS * np.abs(sc)
        aA = np.abs(self.A)
        lin = self.G0 + np.einsum("bij,bj->bi", self.A, sc)
        spread = np.einsum("bij,bj->bi", aA, sr) + self.rho
        n = sl.shape[1]
        err = (n + 4) * 8 * _EPS * (np.abs(self.G0) + np.einsum("bij,bj->bi", aA, np.abs(sc)) + spread)
        return lin - spread - err, lin + spread + err

    def fix_monotone(self, lo: np.ndarray, hi: np.ndarray, usable: np.ndarray,
                     G: tuple[np.ndarray, np.ndarray] | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Iterated monotonicity on boxes [lo, hi] (sub-boxes of the model's): (nl, nh, fixed),
        the boxes reduced to the faces that hold g's minimum and (m, n) True for the
        variables fixed. ``usable`` (m,): boxes where g is C^1 and the model finite (others
        are returned unchanged). ``G`` (optional, (lo, hi) each (m, n)): another rigorous
        enclosure of the gradient on the boxes, intersected with the model's."""
        nl, nh = lo.copy(), hi.copy()
        free = usable[:, None] & (hi > lo)
        fixed = np.zeros_like(free)
        for _ in range(lo.shape[1]):
            if not free.any():
                break
            gl, gh = self.gradient(*self.coords(nl, nh))
            if G is not None:
                gl, gh = np.maximum(gl, G[0]), np.minimum(gh, G[1])
            up = free & (gl >= 0)  # g increasing in x_i: its minimum has x_i = lo_i
            dn = free & (gh <= 0) & ~up
            if not (up | dn).any():
                break
            nh = np.where(up, nl, nh)
            nl = np.where(dn, nh, nl)
            free &= ~(up | dn)
            fixed |= up | dn
        return nl, nh, fixed

    def lower(self, g_centre: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
        """Rigorous lower bounds (m,) of g over sub-boxes [lo, hi] of the model's boxes, from
        ``g_centre`` (m,), a rigorous lower bound of g at the model's centres; valid only
        where g is C^1 on the model's box (the caller's mask), NaN where not finite."""
        sl, sh = self.coords(lo, hi)
        rd = self.rd
        b = rd * self.G0
        P = rd[:, :, None] * self.A
        P = 0.5 * (P + np.transpose(P, (0, 2, 1)))
        gamma = rd * self.rho
        sc = 0.5 * (sl + sh)
        tau = 0.5 * (sh - sl) * (1.0 + 4 * _EPS) + 2 * _EPS * np.abs(sc)  # > 0: coords() widens
        Psc = np.einsum("bij,bj->bi", P, sc)
        q0 = (b * sc).sum(1) + 0.5 * (sc * Psc).sum(1)  # the quadratic at the sub-box centre
        a = b + Psc  # its gradient there
        aP = np.abs(P)
        diag = np.diagonal(P, axis1=1, axis2=2)
        off = np.einsum("bij,bj->bi", aP, tau) - np.abs(diag) * tau
        d = diag - off / tau  # t^T P t >= sum_i d_i t_i^2 for |t_i| <= tau_i
        ends = np.minimum(-a * tau + 0.5 * d * tau * tau, a * tau + 0.5 * d * tau * tau)
        ts = np.clip(-a / np.where(d > 0, d, np.inf), -tau, tau)
        inner = np.where(d > 0, a * ts + 0.5 * d * ts * ts, np.inf)
        qmin = np.minimum(ends, inner).sum(1)
        smax = np.maximum(np.abs(sl), np.abs(sh))
        rem = (gamma * smax).sum(1)
        n = lo.shape[1]
        mag = (np.abs(g_centre) + (np.abs(b) * smax).sum(1)
               + np.einsum("bij,bi,bj->b", aP, smax, smax) + (np.abs(a) * tau).sum(1) + rem)
        out = g_centre + q0 + qmin - rem - (n + 4) * 8 * _EPS * mag - 1e-300
        return np.where(np.isfinite(out), out, np.nan)
