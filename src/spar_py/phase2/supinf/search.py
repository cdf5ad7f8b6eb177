"""Branch and bound: SUP/INF refined to a tolerance, both ends at once (:func:`branch_and_bound`).

A box's lower bound is the best of the natural interval extension, the mean-value form
``f(c) + G (X - c)`` (G the interval gradient) and the affine form; a variable whose
interval derivative has constant sign is fixed at the end that minimises (monotonicity;
only on boxes where every operation is continuous); other boxes are bisected on the
variable with the largest ``width * |derivative|``. Boxes the interval gradient cannot
prove monotone get the affine form of the expression *and its gradient*: on long
transform products the interval gradient suffers the wrapping effect, the affine one
does not, and the intersection of the two proves monotonicity on far more boxes. The
affine gradient is also used as a first-order model of the gradient valid on every
sub-box (:class:`~spar_py.phase2.taylor.GradientModel`): iterated monotonicity reduces a
box to the faces holding its minimum without another evaluation, and the model
integrated from the centre gives a lower bound whose error is third order in the box
size (rigorous: a relative margin covers its floating-point sums); such boxes are
bisected where the model's remainder is largest. Values at points (box centres,
rigorously; corners chosen by the gradient or the affine form and single-coordinate
flips of the best points, in floating point) steer the search; the search stops when
each bound is within ``max(abs_tol, rel_tol * width)`` of a value the function attains
(``width`` the spread of attained values found; the final claim is re-checked with
rigorous values) or when ``max_boxes`` / ``max_time`` run out; :class:`BoundResult` says
which. A chain expression whose search has not finished after :data:`HULL_AFTER` boxes is
also bounded by point sets through its chain (:mod:`spar_py.phase2.hulls`).

Kinks of ``fabs`` do not stop the derivative reasoning: the interval ``sign`` of an
argument that straddles 0 is [-1, 1], so the gradient enclosures hold the Clarke
generalised gradient and Lebourg's mean-value theorem keeps every step sound (see
bounder.Bounder; an expression with a ``sign`` of its own is still treated as
discontinuous).
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, replace
from typing import Protocol

import numpy as np

from spar_py.core.errors import SparValueError
from spar_py.phase2.supinf.affine import AffineProgram
from spar_py.phase2.supinf.intervals import next_down, next_up
from spar_py.phase2.supinf.program import AdaptiveProgram
from spar_py.phase2.symbolic import ChainExpr
from spar_py.phase2.taylor import GradientModel

#: Bounder.bounds' defaults: relative and absolute tolerance, and the budget of boxes.
REL_TOL = 1e-3
ABS_TOL = 1e-9
MAX_BOXES = 5000
#: Boxes evaluated after which a search of a chain expression (symbolic.ChainExpr) also
#: bounds it by point sets through its chain (hulls.py): most expressions are finished
#: before. HULL_TOL: the first round's arc tolerance, as a fraction of the spread found
#: (shared among the arcs); HULL_ROUNDS: the most rounds, each 16 times finer.
HULL_AFTER = 512
HULL_TOL = 0.1
HULL_ROUNDS = 3
#: Boxes taken from the pool per pass of the search.
BATCH = 256

_INF = math.inf
_EPS = float(np.finfo(float).eps)


@dataclass(frozen=True)
class BoundResult:
    """Bounds of an expression over a box: ``lo <= min`` and ``hi >= max`` always (sound).

    ``tolerance_reached`` is True if both bounds are within the requested tolerance of
    values the expression attains (``lo_found``, ``hi_found``: rigorous bounds on the
    expression's value at points of the box, so ``lo <= min <= lo_found`` and
    ``hi_found <= max <= hi``); ``boxes`` counts the boxes evaluated.
    """

    lo: float
    hi: float
    tolerance_reached: bool
    boxes: int
    lo_found: float = _INF
    hi_found: float = -_INF
    #: The search stopped because it had decided the question ``beat`` asked (see
    #: :meth:`Bounder.bounds`): the bound it was asked for is sound but not refined further.
    decided: bool = False

    @property
    def gap(self) -> float:
        """The largest distance of a bound from an attained value (0 when exact)."""
        return max(self.lo_found - self.lo, self.hi - self.hi_found)


def check_options(want: str, rel_tol: float, abs_tol: float, beat: float | None) -> None:
    """SparValueError unless these are options Bounder.bounds can take."""
    if want not in ("both", "lo", "hi"):
        raise SparValueError(f"supinf: want must be 'both', 'lo' or 'hi', got {want!r}")
    if beat is not None and (want == "both" or not math.isfinite(beat)):
        raise SparValueError("supinf: beat needs want 'lo' or 'hi' and a finite number")
    if not (rel_tol >= 0 and abs_tol >= 0) or (rel_tol == 0 and abs_tol == 0):
        raise SparValueError("supinf: tolerances must be >= 0 and not both 0")


class CompiledExpression(Protocol):
    """What the search reads of an expression compiled for bounding (bounder.Bounder is one)."""

    names: list[str]
    chain: ChainExpr | None
    chain_index: dict[int, int]
    gradient: AdaptiveProgram | None

    @property
    def program(self) -> AdaptiveProgram: ...

    @property
    def affine(self) -> AffineProgram: ...

    @property
    def affine_gradient(self) -> AffineProgram | None: ...

    def enclose(self, lo: np.ndarray, hi: np.ndarray) -> np.ndarray: ...

    def values(self, points: np.ndarray) -> np.ndarray: ...


def _mean_value_lower(fc_lo: np.ndarray, G: np.ndarray, bl: np.ndarray, bh: np.ndarray,
                      c: np.ndarray) -> np.ndarray:
    """Rigorous lower end of f(c) + sum_i G_i (X_i - c_i) for boxes (m, nv); G (2, nv, m)."""
    dl = next_down(bl - c).T  # (nv, m)
    dh = next_up(bh - c).T
    p = np.array((G[0] * dl, G[0] * dh, G[1] * dl, G[1] * dh))
    p = np.where(np.isnan(p), 0.0, p)  # 0 * inf: the factor (X_i - c_i) is exactly 0
    t = next_down(p.min(0))  # (nv, m) lower ends of each product
    s = t.sum(0)
    err = (t.shape[0] + 2) * _EPS * np.abs(t).sum(0)  # recursive-summation error bound
    return next_down(next_down(fc_lo + next_down(s - err)))


class Search:
    """Best-first branch and bound for min f (side 0) and min -f (side 1) at once.

    Soundness rests only on the rigorous lower bounds L of the boxes: every box is either
    still in the pool or its L went into ``settled[side]``. The values found at points
    (``U``: interval values at box centres, float values at corners chosen by the
    gradient or the affine form and at single-coordinate flips of the best points) only
    steer the search and decide when to stop; the claimed ``lo_found``/``hi_found`` are
    re-evaluated rigorously at the end.
    """

    def __init__(self, B: CompiledExpression, lo0: np.ndarray, hi0: np.ndarray, sides: list[int],
                 rel_tol: float, abs_tol: float) -> None:
        self.B, self.lo0, self.hi0, self.sides = B, lo0, hi0, sides
        self.rel_tol, self.abs_tol = rel_tol, abs_tol
        self.nv = lo0.size
        self.U = [_INF, _INF]  # best values of g_0 = f and g_1 = -f found at points
        self.R = [_INF, _INF]  # the same, from rigorous values only (box centres)
        self.best = [0.5 * (lo0 + hi0), 0.5 * (lo0 + hi0)]
        self.settled = [_INF, _INF]  # min L over the boxes taken out of the search
        self.done = [s not in sides for s in (0, 1)]
        self.pool = (np.repeat(lo0[None, :], len(sides), 0), np.repeat(hi0[None, :], len(sides), 0),
                     np.array(sides, int), np.full(len(sides), -_INF))
        self.evaluated = 0
        self.steps = 0  # passes made (steps that have begun)
        self.plain: tuple[float, float] | None = None  # the interval value on the whole box
        #: sound lower bounds of min g_0 and min g_1 from outside the boxes (the chain's
        #: point sets, ``use_hull``); None until computed
        self.floor: list[float] | None = None
        #: the best points of the last :meth:`result` (their bytes) and their rigorous values:
        #: a search resumed after a decision (cached_bounds) whose steps found no better point
        #: reads them instead of evaluating the same points again
        self._found: tuple[bytes, np.ndarray] | None = None

    def tol(self) -> float:
        return max(self.abs_tol, self.rel_tol * max(0.0, -self.U[1] - self.U[0]))

    def offer(self, points: np.ndarray, f_hi: np.ndarray, f_lo: np.ndarray, rigorous: bool = False) -> None:
        """Record values at points: ``f_hi`` >= f there (for side 0), ``f_lo`` <= f (side 1);
        ``rigorous``: they are (interval ends), not just floating-point values."""
        for s, g in ((0, f_hi), (1, -f_lo)):
            g = np.where(np.isnan(g), _INF, g)
            j = int(np.argmin(g))
            if g[j] < self.U[s]:
                self.U[s] = float(g[j])
                self.best[s] = points[j].copy()
            if rigorous and g[j] < self.R[s]:
                self.R[s] = float(g[j])

    def decided(self, beat: float) -> bool:
        """Whether the one side searched has settled ``beat`` (Bounder.bounds): its lowest
        box bound is above it, or a rigorous value at a point is at or below it (in the
        side's own terms: g_0 = f against beat, g_1 = -f against -beat)."""
        s = self.sides[0]
        t = beat if s == 0 else -beat
        if self.R[s] <= t:
            return True
        _, _, ps, pL = self.pool
        waiting = pL[ps == s]
        return self._floored(s, min(self.settled[s], float(waiting.min()) if waiting.size else _INF)) > t

    def _floored(self, s: int, lowest: float) -> float:
        """A lower bound of min g_s: ``lowest`` (from the boxes) or the floor, the higher."""
        return lowest if self.floor is None else max(lowest, self.floor[s])

    def use_hull(self, t_end: float | None = None) -> None:
        """Bound the chain expression by point sets through its chain (hulls.py): the bounds
        become the floor, and the variables' values where they are nearly attained are offered
        as points. The arcs' tolerance starts at :data:`HULL_TOL` of the spread found so far
        (shared among the chain's arcs) and is divided by 16 (4 times the segments) while a
        searched side's floor is further than the search's tolerance from the best value,
        at most :data:`HULL_ROUNDS` times: an extreme at the end of every angle's range (the
        usual case) is found exactly by the first, coarse round. No finer round when the
        last could not keep its tolerance (hulls.MAX_POINTS: a finer one cannot either) or
        once ``t_end`` (perf_counter seconds) has passed."""
        from spar_py.phase2.hulls import hull_bounds  # only a refined bound needs it: not in most cold plans

        ce = self.B.chain
        assert ce is not None
        n_arcs = 1 + sum(1 for f in ce.chain.factors if not isinstance(f, np.ndarray))
        for k in range(HULL_ROUNDS):
            spread = max(0.0, -self.U[1] - self.U[0])
            tol = max(self.abs_tol, HULL_TOL * spread) / n_arcs / 16.0 ** k
            if ce.kind == "sqdist":  # x's unit: the spread of |x - q|^2 is about 2 |x - q| times x's
                tol /= max(1.0, 2.0 * math.sqrt(max(0.0, -self.U[1])))
            hb = hull_bounds(ce, self.B.names, self.lo0, self.hi0, tol, self.B.chain_index)
            floor = [hb.lo, -hb.hi]
            self.floor = floor if self.floor is None else [max(a, b) for a, b in zip(floor, self.floor)]
            self.offer_points(np.vstack((hb.lo_at, hb.hi_at)))
            if all(self.U[s] - self.floor[s] <= self.tol() for s in self.sides) or not hb.tol_kept or (
                    t_end is not None and time.perf_counter() >= t_end):
                break

    def offer_points(self, points: np.ndarray) -> None:
        if points.size:
            v = self.B.values(points)
            self.offer(points, v, v)

    def take(self, m: int) -> tuple[np.ndarray, ...]:
        """Remove and return the m most promising boxes of the pool."""
        pl, ph, ps, pL = self.pool
        if ps.size > m:
            key = pL - np.take(self.U, ps)
            idx = np.argpartition(np.where(np.isnan(key), _INF, key), m - 1)[:m]
            rest = np.ones(ps.size, bool)
            rest[idx] = False
            self.pool = (pl[rest], ph[rest], ps[rest], pL[rest])
            return pl[idx], ph[idx], ps[idx], pL[idx]
        self.pool = (np.empty((0, self.nv)), np.empty((0, self.nv)), np.empty(0, int), np.empty(0))
        return pl, ph, ps, pL

    def settle(self, bl: np.ndarray, bh: np.ndarray, side: np.ndarray, L: np.ndarray) -> np.ndarray:
        """Retire boxes that cannot improve a bound by more than tol; True for the boxes to keep."""
        tol = self.tol()
        keep = np.ones(side.size, bool)
        pl, ph, ps, pL = self.pool
        for s in (0, 1):
            on = side == s
            if self.done[s]:
                keep &= ~on
                continue
            waiting = pL[ps == s]
            lowest = self._floored(s, min(self.settled[s], float(L[on].min()) if on.any() else _INF,
                                          float(waiting.min()) if waiting.size else _INF))
            if self.U[s] - lowest <= tol:  # this side is finished
                self.settled[s], self.done[s] = lowest, True
                keep &= ~on
                stay = ps != s
                pl, ph, ps, pL = pl[stay], ph[stay], ps[stay], pL[stay]
                continue
            # boxes close enough to the best point, and points that cannot be split
            out = on & ((L >= self.U[s] - tol) | ~(bh > bl).any(1))
            if out.any():
                self.settled[s] = min(self.settled[s], float(L[out].min()))
            keep &= ~out
        self.pool = (pl, ph, ps, pL)
        return keep

    def settle_pool(self) -> None:
        """:meth:`settle` with no new boxes: retire what the bounds known now finish."""
        self.settle(np.empty((0, self.nv)), np.empty((0, self.nv)), np.empty(0, int), np.empty(0))

    def push(self, bl: np.ndarray, bh: np.ndarray, side: np.ndarray, L: np.ndarray) -> None:
        pl, ph, ps, pL = self.pool
        self.pool = (np.vstack((pl, bl)), np.vstack((ph, bh)), np.concatenate((ps, side)),
                     np.concatenate((pL, L)))

    def step(self) -> None:
        """One pass over a batch of boxes."""
        B, nv = self.B, self.nv
        bl, bh, side, pL = self.take(BATCH)
        self.steps += 1
        m = side.size
        neg = side == 1
        self.evaluated += m
        # 1. interval value and gradient on the boxes and their centres
        c = np.minimum(np.maximum(0.5 * (bl + bh), bl), bh)
        prog = B.gradient if B.gradient is not None else B.program
        outs, disc, kink = prog(np.vstack((bl, c)), np.vstack((bh, c)), with_kinks=True)
        f = outs[0][:, 0, :]
        fb, fc = f[:, :m], f[:, m:]
        if self.plain is None:  # the first batch is the whole box (once per side)
            self.plain = (float(fb[0, 0]), float(fb[1, 0]))
        self.offer(c, fc[1], fc[0], rigorous=True)
        L = np.where(neg, -fb[1], fb[0])
        cand = [np.where(np.eye(nv, dtype=bool), np.where(self.best[s] == self.lo0, self.hi0, self.lo0),
                         self.best[s]) for s in (0, 1) if not self.done[s]]
        G = None
        ok = np.zeros(m, bool)
        # no kink of a fabs in the box: the mean-value and model bounds apply there (they are
        # sound across kinks too, but loose, and bisecting at the kink is exact)
        smooth = ~kink[:m]
        fcv = np.where(neg, -fc[1], fc[0])  # rigorous lower end of g_s at the centres
        if B.gradient is not None:
            G = outs[1][:, :, :m]  # (2, nv, m), for g_s
            G = np.where(neg[None, None, :], -G[::-1], G)
            ok = ~disc[:m] & np.isfinite(G).all((0, 1))
            Lmv = _mean_value_lower(fcv, G, bl, bh, c)
            L = np.where(ok & smooth & ~np.isnan(Lmv), np.maximum(L, Lmv), L)
            gmid = 0.5 * (G[0] + G[1]).T  # (m, nv)
            cand.append(np.where(gmid >= 0, bl, bh)[np.isfinite(gmid).all(1)])
        self.offer_points(np.vstack(cand))
        L = np.maximum(np.where(np.isnan(L), -_INF, L), pL)
        keep = self.settle(bl, bh, side, L)
        if not keep.any():
            return
        bl, bh, side, L, ok = bl[keep], bh[keep], side[keep], L[keep], ok[keep]
        c, fcv, smooth = c[keep], fcv[keep], smooth[keep]
        neg = side == 1
        width = bh - bl
        # 2. monotonicity: fix variables whose derivative has one sign over the box
        nl, nh = bl.copy(), bh.copy()
        reduced = np.zeros(side.size, bool)
        infl = width
        if G is not None:
            Gk = G[:, :, keep]
            okk = ok[:, None] & (width > 0)
            up = (Gk[0].T >= 0) & okk  # g increasing in x_i on the box: its minimum has x_i = lo
            dn = (Gk[1].T <= 0) & okk & ~up
            nh = np.where(up, bl, nh)
            nl = np.where(dn, bh, nl)
            reduced = (up | dn).any(1)
            infl = width * np.maximum(np.abs(Gk[0]), np.abs(Gk[1])).T
            infl = np.where(np.isfinite(infl) & ok[:, None], infl, width)
        self.push(nl[reduced], nh[reduced], side[reduced], L[reduced])
        sp = ~reduced
        if not sp.any():
            return
        # 3. the affine form on the boxes left: a tighter L and its minimising corner
        bl, bh, side, L, infl, neg = bl[sp], bh[sp], side[sp], L[sp], infl[sp], neg[sp]
        # (from the second pass on: most expressions are settled by the first, with the
        # cheaper affine form of f alone)
        AG = B.affine_gradient if G is not None and self.steps > 1 else None
        if AG is not None:
            # ... of f and its gradient: the gradient enclosure, intersected with the interval
            # one (both sound), gives a tighter mean-value form and proves more monotonicity
            k = side.size
            F = AG(bl, bh)
            self.evaluated += k
            enc = AG.enclosure(F.reshape(F.shape[0], -1)).reshape(2, nv + 1, k)
            L = np.maximum(L, np.where(neg, -enc[1, 0], enc[0, 0]))
            GA = np.where(neg[None, None, :], -enc[::-1, 1:], enc[:, 1:])
            Gs = Gk[:, :, sp]
            Gs = np.array((np.maximum(Gs[0], GA[0]), np.minimum(Gs[1], GA[1])))
            oks = ok[sp] & np.isfinite(Gs).all((0, 1))
            Lmv = _mean_value_lower(fcv[sp], Gs, bl, bh, c[sp])
            L = np.where(oks & smooth[sp] & ~np.isnan(Lmv), np.maximum(L, Lmv), L)
            lin = AG.linear(F[:, 0, :])
            lin = np.where(neg[None, :], -lin, lin).T  # (k, nv)
            lin_corners = np.where(lin >= 0, bl, bh)[np.isfinite(lin).all(1)]
            # the affine gradient as a model valid on every sub-box (taylor.py): iterated
            # monotonicity reduces each box to the faces holding its minimum, and the model
            # integrated from the centre gives a third-order lower bound on what is left
            model = GradientModel.from_affine(F, AG.K, bl, bh, neg)
            usable = oks & model.finite
            nl, nh, fixed = model.fix_monotone(bl, bh, usable, (Gs[0].T, Gs[1].T))
            LQ = model.lower(fcv[sp], nl, nh)
            L = np.where(usable & smooth[sp] & ~np.isnan(LQ), np.maximum(L, LQ), L)
            gl, gh = model.gradient(*model.coords(nl, nh))
            corner = np.where(0.5 * (gl + gh) >= 0, nl, nh)
            self.offer_points(np.vstack((lin_corners, corner[usable & np.isfinite(corner).all(1)])))
            keep = self.settle(bl, bh, side, L)
            if not keep.any():
                return
            bl, bh, side, L, Gs, oks = bl[keep], bh[keep], side[keep], L[keep], Gs[:, :, keep], oks[keep]
            nl, nh, fixed = nl[keep], nh[keep], fixed[keep]
            width = bh - bl
            reduced = fixed.any(1)
            self.push(nl[reduced], nh[reduced], side[reduced], L[reduced])
            infl = width * np.maximum(np.abs(Gs[0]), np.abs(Gs[1])).T
            infl = np.where(np.isfinite(infl) & oks[:, None], infl, width)
            # split where the model's remainder (its error) is largest
            gam = (model.rd * model.rho)[keep]
            infl = np.where((usable[keep] & np.isfinite(gam).all(1))[:, None], gam, infl)
            keep = ~reduced
            if not keep.any():
                return
        else:  # ... of f alone
            F = B.affine(bl, bh)[:, 0, :]
            self.evaluated += side.size
            fa = B.affine.enclosure(F)
            L = np.maximum(L, np.where(neg, -fa[1], fa[0]))
            lin = B.affine.linear(F)
            lin = np.where(neg[None, :], -lin, lin).T  # (m, nv)
            self.offer_points(np.where(lin >= 0, bl, bh)[np.isfinite(lin).all(1)])
            keep = self.settle(bl, bh, side, L)
            if not keep.any():
                return
        bl, bh, side, L, infl = bl[keep], bh[keep], side[keep], L[keep], infl[keep]
        # 4. bisect on the most influential variable
        score = np.where(bh > bl, np.nan_to_num(infl, nan=0.0), -1.0)
        j = np.argmax(score, axis=1)
        r = np.arange(j.size)
        mid = 0.5 * (bl[r, j] + bh[r, j])
        left_h, right_l = bh.copy(), bl.copy()
        left_h[r, j] = mid
        right_l[r, j] = mid
        self.push(np.vstack((bl, right_l)), np.vstack((left_h, bh)), np.concatenate((side, side)),
                  np.concatenate((L, L)))

    def result(self) -> BoundResult:
        if self.plain is None:
            f0 = self.B.enclose(self.lo0[None, :], self.hi0[None, :])
            self.plain = (float(f0[0, 0]), float(f0[1, 0]))
        plain = self.plain
        _, _, ps, pL = self.pool
        settled = list(self.settled)  # (not the search's own: a search stopped on beat goes on)
        for s in (0, 1):  # boxes still in the pool (the budget ran out) bound the minimum too
            if not self.done[s] and (ps == s).any():
                settled[s] = min(settled[s], float(pL[ps == s].min()))
            settled[s] = self._floored(s, settled[s])
        lo = settled[0] if 0 in self.sides else plain[0]
        hi = -settled[1] if 1 in self.sides else plain[1]
        lo, hi = max(lo, plain[0]), min(hi, plain[1])  # the plain enclosure is valid too
        # rigorous values at the best points found; the tolerance claim is made with them
        P = np.vstack(self.best)
        if self._found is not None and self._found[0] == P.tobytes():
            fp = self._found[1]
        else:
            fp = self.B.enclose(P, P)
            self._found = (P.tobytes(), fp)
        lo_found = float(fp[1, 0]) if math.isfinite(fp[1, 0]) else _INF
        hi_found = float(fp[0, 1]) if math.isfinite(fp[0, 1]) else -_INF
        tol = max(self.abs_tol, self.rel_tol * max(0.0, hi_found - lo_found))
        reached = ((0 not in self.sides or lo_found - lo <= tol)
                   and (1 not in self.sides or hi - hi_found <= tol))
        return BoundResult(float(lo), float(hi), bool(reached), int(self.evaluated), lo_found, hi_found)


def branch_and_bound(B: CompiledExpression, lo0: np.ndarray, hi0: np.ndarray, rel_tol: float, abs_tol: float,
                      max_boxes: int, max_time: float | None, want: str, beat: float | None = None,
                      search: Search | None = None) -> tuple[BoundResult, Search | None]:
    """The search's result and the search itself (None for a constant or a point).

    ``search``: a search of the same bounder, box and options that stopped on a ``beat``,
    to go on with (its boxes-evaluated budget carries over; ``max_time`` counts anew)."""
    if lo0.size == 0 or np.all(lo0 == hi0):  # a constant or a point: one evaluation is all
        f0 = B.enclose(lo0[None, :], hi0[None, :])
        plain = (float(f0[0, 0]), float(f0[1, 0]))
        exact = math.isfinite(plain[0]) and math.isfinite(plain[1])
        return BoundResult(plain[0], plain[1], exact, 1, plain[1], plain[0]), None
    t_end = None if max_time is None else time.perf_counter() + max_time
    sides = [s for s, w in ((0, "lo"), (1, "hi")) if want in ("both", w)]
    S = search if search is not None else Search(B, lo0, hi0, sides, rel_tol, abs_tol)

    def settled() -> bool:  # (a fresh search has decided nothing before its first step)
        return beat is not None and S.steps > 0 and bool(S.pool[2].size) and S.decided(beat)

    decided = settled()
    while not decided and S.pool[2].size and S.evaluated < max_boxes and (
            t_end is None or time.perf_counter() < t_end):
        if B.chain is not None and S.floor is None and S.evaluated >= HULL_AFTER:
            S.use_hull(t_end)
            S.settle_pool()  # the floor may finish a side
            if not S.pool[2].size:
                break
        S.step()
        decided = settled()
    r = S.result()
    return (replace(r, decided=True) if decided else r), S
