"""Interval programs: a CasADi Function's instruction list evaluated in interval arithmetic.

The expression (and its gradient) is compiled to a CasADi Function and its instruction
list is walked with intervals (:class:`IntervalProgram`, the rules of intervals.py), over a
whole batch of boxes at once (numpy arrays of shape ``(2, n)``: row 0 lower ends, row 1
upper ends), as a levelled, grouped schedule (schedule.py). A result that cannot be
bounded (NaN: 0 * inf, a function outside its domain) is reported as (-inf, inf).

:class:`CompiledIntervalProgram` writes the same rules once as a CasADi SX graph and
evaluates a batch in one call; :class:`AdaptiveProgram` chooses between the two by batch
size (``Bounder(expr, compiled=True)``). Building the compiled graph is costly, so it pays
only for a bounder used many times.
"""
from __future__ import annotations

import math
from collections.abc import Callable

import casadi as ca
import numpy as np

from spar_py.core.errors import SparValueError
from spar_py.phase2.supinf.intervals import (
    BIG_ANGLE,
    BINARY,
    HALF_PI,
    LIBM_REL,
    PI,
    PI_UP,
    TWO_PI,
    UNARY,
    flat,
    iv_pow_const,
    op_name,
    round_out,
)
from spar_py.phase2.supinf.schedule import Instruction, Schedule, instruction_list

_INF = math.inf


def _interval_classify(op: int, args: tuple[int, ...],
                       const_of: dict[int, float]) -> tuple[tuple, tuple[int, ...], float]:
    if op == ca.OP_CONSTPOW:
        if args[1] not in const_of:
            raise SparValueError("supinf: constpow with a non-constant exponent")
        return ("powc", const_of[args[1]]), args[:1], 0.0
    if op == ca.OP_MUL and (args[0] in const_of or args[1] in const_of):
        c, a = (const_of[args[0]], args[1]) if args[0] in const_of else (const_of[args[1]], args[0])
        return ("scale",), (a,), c
    if op == ca.OP_DIV and args[1] in const_of and const_of[args[1]] != 0:
        return ("div_c",), args[:1], const_of[args[1]]
    if op in UNARY:
        return ("unary", op), args, 0.0
    if op in BINARY:
        return ("binary", op), args, 0.0
    raise SparValueError(f"supinf: unsupported operation {op_name(op)} in expression")


class IntervalProgram:
    """A CasADi Function's instruction list, evaluated in interval arithmetic on batches of boxes.

    The Function must take one dense column vector of inputs; outputs may be any
    dense matrices. ``prog(lo, hi)`` with ``lo``, ``hi`` of shape ``(n, n_in)`` returns
    ``(outs, disc)``: ``outs[k]`` of shape ``(2, nnz_k, n)`` enclosing output k over each
    box, ``disc`` (n,) True where some operation may be discontinuous on the box (then
    derivative-based reasoning does not apply there). Evaluated by a :class:`Schedule`:
    one vectorised rule per group of like instructions of one level, over all boxes.

    ``sign_continuous``: ``sign`` never marks a box discontinuous. Only for the gradient
    program of an expression that has no ``sign`` of its own, where every ``sign`` is the
    derivative of a ``fabs`` (see :class:`Bounder`). ``prog(lo, hi, with_kinks=True)``
    returns ``(outs, disc, kink)``, ``kink`` (n,) True where such a ``sign``'s argument
    straddles 0 (a kink of the expression may lie in the box).
    """

    def __init__(self, fn: ca.Function, sign_continuous: bool = False,
                 instructions: list[Instruction] | None = None) -> None:
        S = Schedule(fn, _interval_classify, instructions)
        self._S = S
        self.sign_continuous = sign_continuous
        # per "scale" group: where the constant is negative (None: nowhere) and where it is
        # +-1, so exact (None: nowhere, True: everywhere)
        self._scale_masks: list[tuple] = []
        for g in S.groups:
            if g.key[0] != "scale":  # read by the "scale" rule only
                self._scale_masks.append((None, None))
                continue
            c = g.payload[:, None]
            neg, unit = c < 0, np.abs(c) == 1.0
            self._scale_masks.append((neg if neg.any() else None,
                                      True if unit.all() else (unit if unit.any() else None)))
        self.n_in, self.out_sizes = S.n_in, S.out_sizes
        self.n_work = S.n_regs

    def __call__(self, lo: np.ndarray, hi: np.ndarray, with_kinks: bool = False) -> tuple:
        lo = np.asarray(lo, float)
        hi = np.asarray(hi, float)
        n = lo.shape[0]
        S = self._S
        W = np.empty((2, S.n_regs, n))
        S.load(W, np.array((lo.T, hi.T)), lambda c: c[None, :, None])
        outs = [np.full((2, s, n), np.nan) for s in self.out_sizes]
        disc = np.zeros(n, bool)
        kink = np.zeros(n, bool)
        with np.errstate(all="ignore"):
            for g, masks in zip(S.groups, self._scale_masks):
                kind = g.key[0]
                A = W[:, g.args[0]]  # (2, k, n)
                if kind == "binary":
                    f, dfn = BINARY[g.key[1]]
                    Bv = W[:, g.args[1]]
                    if dfn is not None:
                        disc |= dfn(A.reshape(2, -1), Bv.reshape(2, -1)).reshape(A.shape[1:]).any(0)
                    R = flat(f, A, Bv)
                elif kind == "scale":
                    c = g.payload[:, None]
                    R = A * c
                    neg, unit = masks
                    if neg is not None:
                        R = np.where(neg, R[::-1], R)
                    if unit is None:
                        R = round_out(R)
                    elif unit is not True:
                        R = np.where(unit, R, round_out(R))
                elif kind == "unary":
                    f, dfn = UNARY[g.key[1]]
                    A2 = A.reshape(2, -1)
                    if dfn is not None:
                        d = dfn(A2).reshape(A.shape[1:]).any(0)
                        if self.sign_continuous and g.key[1] == ca.OP_SIGN:
                            kink |= d
                        else:
                            disc |= d
                    R = f(A2).reshape(A.shape)
                elif kind == "div_c":
                    c = g.payload[:, None]
                    R = A / c
                    R = round_out(np.where(c < 0, R[::-1], R))
                else:  # powc
                    c = g.key[1]
                    R = flat(lambda a: iv_pow_const(a, c), A)
                W[:, g.out] = R
        for k, j, r in S.outputs:
            outs[k][:, j, :] = W[:, r]
        for r in outs:
            bad = np.isnan(r).any(0)
            r[0][bad] = -_INF
            r[1][bad] = _INF
        return (outs, disc, kink) if with_kinks else (outs, disc)


# ================================================================== the compiled interval program
#
# The same interval rules as above, written once as a CasADi SX graph over the ends of
# the input intervals and compiled into one Function: evaluating it on a batch of boxes
# is one call into CasADi's virtual machine (no Python per instruction). Outward rounding
# is a relative widening (SX has no nextafter): after an IEEE-exact, correctly rounded
# operation x is moved by |x| 2^-50 + 1e-300 (at least 4 ulps: with the rounding of the
# widening itself the result still lies outside the exact one), after a libm function by
# |x| LIBM_REL + 1e-300. Every value also feeds a finiteness check, ``z * (lo + hi)`` with
# ``z`` an input that is always 0 (so CasADi cannot fold it): the sum is 0 while every end
# is finite and NaN once one is not. The boxes on which some value is infinite or NaN, or
# some operation leaves its domain (division by an interval holding 0, a tan pole,
# atan2's branch cut, log of x <= 0, ...), are evaluated again by :class:`IntervalProgram`,
# whose rules know those cases; the fast path never has to be right about them.

_ULP4 = 2.0 ** -50
_SX_TINY = 1e-300


def _sx_dn(x: ca.SX, rel: float = _ULP4) -> ca.SX:
    return x - (ca.fabs(x) * rel + _SX_TINY)


def _sx_up(x: ca.SX, rel: float = _ULP4) -> ca.SX:
    return x + (ca.fabs(x) * rel + _SX_TINY)


def _sx_hull(vals: list[ca.SX], rel: float = _ULP4) -> tuple[ca.SX, ca.SX]:
    lo, hi = vals[0], vals[0]
    for v in vals[1:]:
        lo, hi = ca.fmin(lo, v), ca.fmax(hi, v)
    return _sx_dn(lo, rel), _sx_up(hi, rel)


def _sx_period_hit(lo: ca.SX, hi: ca.SX, offset: float, period: float) -> ca.SX:
    """1 where some offset + k*period lies in [lo - s, hi + s] (as intervals.py's test for extrema)."""
    s = 1e-9 * (1.0 + ca.fmax(ca.fabs(lo), ca.fabs(hi)))
    k = ca.floor((hi + s - offset) / period)
    return offset + k * period >= lo - s


def _sx_trig(a: tuple[ca.SX, ca.SX], f: Callable[[ca.SX], ca.SX], max_at: float,
             min_at: float) -> tuple[ca.SX, ca.SX]:
    lo, hi = a
    v0, v1 = f(lo), f(hi)
    rlo, rhi = _sx_hull([v0, v1], LIBM_REL)
    full = ca.logic_or(hi - lo >= TWO_PI, ca.fmax(ca.fabs(lo), ca.fabs(hi)) >= BIG_ANGLE)
    rhi = ca.if_else(ca.logic_or(full, _sx_period_hit(lo, hi, max_at, TWO_PI)), 1.0, rhi)
    rlo = ca.if_else(ca.logic_or(full, _sx_period_hit(lo, hi, min_at, TWO_PI)), -1.0, rlo)
    return ca.fmax(rlo, -1.0), ca.fmin(rhi, 1.0)


def _sx_mul(a: tuple[ca.SX, ca.SX], b: tuple[ca.SX, ca.SX]) -> tuple[ca.SX, ca.SX]:
    return _sx_hull([a[0] * b[0], a[0] * b[1], a[1] * b[0], a[1] * b[1]])


def _sx_even(a: tuple[ca.SX, ca.SX], f: Callable[[ca.SX], ca.SX], rel: float) -> tuple[ca.SX, ca.SX]:
    """An even function increasing in |x| (x^2, x^4, cosh): its range from the nearest and farthest |x|."""
    near = ca.fmax(0.0, ca.fmax(a[0], -a[1]))
    lo = _sx_dn(f(near), rel)
    hi = _sx_up(ca.fmax(f(a[0]), f(a[1])), rel)
    return lo, hi


def _sx_monotone(a: tuple[ca.SX, ca.SX], f: Callable[[ca.SX], ca.SX],
                 increasing: bool = True) -> tuple[ca.SX, ca.SX]:
    v0, v1 = f(a[0]), f(a[1])
    if not increasing:
        v0, v1 = v1, v0
    return _sx_dn(v0, LIBM_REL), _sx_up(v1, LIBM_REL)


def _sx_powc(a: tuple[ca.SX, ca.SX], c: float) -> tuple[tuple[ca.SX, ca.SX], ca.SX]:
    """[a] ** c for a constant c, and the out-of-domain condition."""
    no = ca.SX(0)
    if c == 0:
        return (ca.SX(1.0), ca.SX(1.0)), no
    if c == 1:
        return a, no
    if float(c).is_integer():
        n = int(c)
        if n < 0:
            (p0, p1), bad = _sx_powc(a, -n)
            return (_sx_dn(1.0 / p1), _sx_up(1.0 / p0)), ca.logic_or(bad, ca.logic_and(p0 <= 0, p1 >= 0))
        if n % 2:
            return _sx_monotone(a, lambda x: x ** n), no
        lo, hi = _sx_even(a, lambda x: x ** n, LIBM_REL)
        return (ca.fmax(lo, 0.0), hi), no
    if c > 0:
        lo, hi = _sx_monotone((ca.fmax(a[0], 0.0), ca.fmax(a[1], 0.0)), lambda x: x ** c)
        return (ca.fmax(lo, 0.0), hi), a[1] < 0
    lo, hi = _sx_monotone(a, lambda x: x ** c, increasing=False)
    return (ca.fmax(lo, 0.0), hi), a[0] <= 0


def _sx_unary(op: int, a: tuple[ca.SX, ca.SX]) -> tuple[tuple[ca.SX, ca.SX], ca.SX, ca.SX]:
    """(range, out-of-domain condition, discontinuity condition) of a unary operation."""
    lo, hi = a
    no = ca.SX(0)
    if op == ca.OP_NEG:
        return (-hi, -lo), no, no
    if op == ca.OP_TWICE:
        return (2.0 * lo, 2.0 * hi), no, no
    if op == ca.OP_SQ:
        r = _sx_even(a, lambda x: x * x, _ULP4)
        return (ca.fmax(r[0], 0.0), r[1]), no, no
    if op == ca.OP_FABS:
        return (ca.fmax(0.0, ca.fmax(lo, -hi)), ca.fmax(-lo, hi)), no, no
    if op == ca.OP_SQRT:
        r = (ca.fmax(_sx_dn(ca.sqrt(ca.fmax(lo, 0.0))), 0.0), _sx_up(ca.sqrt(ca.fmax(hi, 0.0))))
        return r, hi < 0, lo <= 0
    if op == ca.OP_SIN:
        return _sx_trig(a, ca.sin, HALF_PI, -HALF_PI), no, no
    if op == ca.OP_COS:
        return _sx_trig(a, ca.cos, 0.0, PI), no, no
    if op == ca.OP_EXP:
        r = _sx_monotone(a, ca.exp)
        return (ca.fmax(r[0], 0.0), r[1]), no, no
    if op == ca.OP_LOG:
        return _sx_monotone(a, ca.log), lo <= 0, lo <= 0
    if op == ca.OP_ATAN:
        return _sx_monotone(a, ca.atan), no, no
    if op == ca.OP_SINH:
        return _sx_monotone(a, ca.sinh), no, no
    if op == ca.OP_TANH:
        return _sx_monotone(a, ca.tanh), no, no
    if op == ca.OP_COSH:
        r = _sx_even(a, ca.cosh, LIBM_REL)
        return (ca.fmax(r[0], 1.0), r[1]), no, no
    if op in (ca.OP_ASIN, ca.OP_ACOS):
        f = ca.asin if op == ca.OP_ASIN else ca.acos
        r = _sx_monotone(a, f, op == ca.OP_ASIN)
        return r, ca.logic_or(lo < -1, hi > 1), ca.logic_or(lo <= -1, hi >= 1)
    if op == ca.OP_SIGN:
        return (ca.sign(lo), ca.sign(hi)), no, ca.logic_and(ca.logic_and(lo <= 0, hi >= 0), lo < hi)
    if op == ca.OP_INV:
        zero = ca.logic_and(lo <= 0, hi >= 0)
        return (_sx_dn(1.0 / hi), _sx_up(1.0 / lo)), zero, zero
    if op == ca.OP_TAN:
        pole = ca.logic_or(ca.logic_or(hi - lo >= PI, ca.fmax(ca.fabs(lo), ca.fabs(hi)) >= BIG_ANGLE),
                           _sx_period_hit(lo, hi, HALF_PI, PI))
        return _sx_monotone(a, ca.tan), pole, pole
    raise SparValueError(f"supinf: unsupported operation {op_name(op)} in expression")


def _sx_binary(op: int, a: tuple[ca.SX, ca.SX], b: tuple[ca.SX, ca.SX]) -> tuple[tuple[ca.SX, ca.SX], ca.SX, ca.SX]:
    """(range, out-of-domain condition, discontinuity condition) of a binary operation."""
    no = ca.SX(0)
    if op == ca.OP_ADD:
        return (_sx_dn(a[0] + b[0]), _sx_up(a[1] + b[1])), no, no
    if op == ca.OP_SUB:
        return (_sx_dn(a[0] - b[1]), _sx_up(a[1] - b[0])), no, no
    if op == ca.OP_MUL:
        return _sx_mul(a, b), no, no
    if op == ca.OP_DIV:
        zero = ca.logic_and(b[0] <= 0, b[1] >= 0)
        return _sx_hull([a[0] / b[0], a[0] / b[1], a[1] / b[0], a[1] / b[1]]), zero, zero
    if op == ca.OP_POW:
        la = _sx_monotone(a, ca.log)
        m = _sx_mul(b, la)
        e = _sx_monotone(m, ca.exp)
        return (ca.fmax(e[0], 0.0), e[1]), a[0] <= 0, a[0] <= 0
    if op == ca.OP_ATAN2:
        cut = ca.logic_and(ca.logic_and(b[0] <= 0, a[0] <= 0), a[1] >= 0)
        r = _sx_hull([ca.atan2(y, x) for y in a for x in b], LIBM_REL)
        return (ca.fmax(r[0], -PI_UP), ca.fmin(r[1], PI_UP)), cut, cut
    if op == ca.OP_FMIN:
        return (ca.fmin(a[0], b[0]), ca.fmin(a[1], b[1])), no, no
    if op == ca.OP_FMAX:
        return (ca.fmax(a[0], b[0]), ca.fmax(a[1], b[1])), no, no
    if op == ca.OP_HYPOT:
        sa, sb = _sx_unary(ca.OP_SQ, a)[0], _sx_unary(ca.OP_SQ, b)[0]
        s = (_sx_dn(sa[0] + sb[0]), _sx_up(sa[1] + sb[1]))
        return (ca.fmax(_sx_dn(ca.sqrt(s[0])), 0.0), _sx_up(ca.sqrt(s[1]))), no, no
    raise SparValueError(f"supinf: unsupported operation {op_name(op)} in expression")


class CompiledIntervalProgram:
    """:class:`IntervalProgram`'s rules compiled into one CasADi Function (see the section note).

    Same interface: ``prog(lo, hi)`` with ``lo``, ``hi`` of shape ``(n, n_in)`` returns
    ``(outs, disc)``. The whole batch is one CasADi call; the boxes on which the fast
    path meets an infinite value or leaves an operation's domain are redone by the
    interpreted :class:`IntervalProgram` (built on first need).
    """

    def __init__(self, fn: ca.Function, sign_continuous: bool = False) -> None:
        if fn.n_in() != 1:
            raise SparValueError("IntervalProgram: the Function must have exactly one (vector) input")
        self._fn = fn
        self.sign_continuous = sign_continuous
        self.n_in = int(fn.nnz_in(0))
        self.out_sizes = [int(fn.nnz_out(k)) for k in range(fn.n_out())]
        n = self.n_in
        X = ca.SX.sym("x", 2 * n + 1)
        z = X[2 * n]
        w: dict[int, tuple[ca.SX, ca.SX]] = {}
        consts: dict[int, float] = {}
        outs = [[(ca.SX(np.nan), ca.SX(np.nan))] * s for s in self.out_sizes]
        bad: list[ca.SX] = []  # summed once at the end (a running sum re-walks its chain)
        disc: list[ca.SX] = []
        kink: list[ca.SX] = []
        for op, ins, o_regs, const in instruction_list(fn):
            o = o_regs[0] if o_regs else -1
            if op == ca.OP_CONST:
                consts[o] = const
                w[o] = (ca.SX(const), ca.SX(const))
                continue
            if op == ca.OP_INPUT:
                j = ins[1]
                w[o] = (X[j], X[n + j])
            elif op == ca.OP_OUTPUT:
                outs[o_regs[0]][o_regs[1]] = w[ins[0]]
                continue
            elif op == ca.OP_ASSIGN:
                w[o] = w[ins[0]]
            else:
                d_bad = d_disc = ca.SX(0)
                if op == ca.OP_CONSTPOW:
                    if ins[1] not in consts:
                        raise SparValueError("supinf: constpow with a non-constant exponent")
                    r, d_bad = _sx_powc(w[ins[0]], consts[ins[1]])
                    d_disc = d_bad
                elif op == ca.OP_MUL and (ins[0] in consts or ins[1] in consts):
                    c, a = (consts[ins[0]], ins[1]) if ins[0] in consts else (consts[ins[1]], ins[0])
                    lo, hi = w[a]
                    lo, hi = (c * lo, c * hi) if c >= 0 else (c * hi, c * lo)
                    r = (lo, hi) if abs(c) == 1.0 or c == 0.0 else (_sx_dn(lo), _sx_up(hi))
                elif op == ca.OP_DIV and ins[1] in consts and consts[ins[1]] != 0:
                    c = consts[ins[1]]
                    lo, hi = w[ins[0]]
                    lo, hi = (lo / c, hi / c) if c > 0 else (hi / c, lo / c)
                    r = (_sx_dn(lo), _sx_up(hi))
                elif op in UNARY:
                    r, d_bad, d_disc = _sx_unary(op, w[ins[0]])
                    if sign_continuous and op == ca.OP_SIGN:
                        kink.append(d_disc)
                        d_disc = ca.SX(0)
                elif op in BINARY:
                    r, d_bad, d_disc = _sx_binary(op, w[ins[0]], w[ins[1]])
                else:
                    raise SparValueError(f"supinf: unsupported operation {op_name(op)} in expression")
                w[o] = r
                bad += [d_bad, z * (r[0] + r[1])]
                disc.append(d_disc)
            consts.pop(o, None)
        flat = [e for out in outs for e in (*[lo for lo, _ in out], *[hi for _, hi in out])]
        total = [ca.sum1(ca.vertcat(*t)) if t else ca.SX(0) for t in (disc, bad, kink)]
        self._f = ca.Function("iv", [X], [ca.vertcat(*flat, *total)])
        self._fallback: IntervalProgram | None = None

    @property
    def n_instructions(self) -> int:
        """Instructions of the compiled interval Function (a size measure)."""
        return int(self._f.n_instructions())

    def __call__(self, lo: np.ndarray, hi: np.ndarray, with_kinks: bool = False) -> tuple:
        lo = np.atleast_2d(np.asarray(lo, float))
        hi = np.atleast_2d(np.asarray(hi, float))
        n = lo.shape[0]
        arg = np.vstack((lo.T, hi.T, np.zeros((1, n))))
        with np.errstate(all="ignore"):
            R = np.asarray(self._f(arg)).reshape(-1, n)
        outs, k = [], 0
        for s in self.out_sizes:
            outs.append(np.array((R[k:k + s], R[k + s:k + 2 * s])))
            k += 2 * s
        disc = R[k] != 0
        kink = R[k + 2] != 0
        redo = ~(R[k + 1] == 0) | ~np.isfinite(lo).all(1) | ~np.isfinite(hi).all(1)
        if redo.any():
            if self._fallback is None:
                self._fallback = IntervalProgram(self._fn, self.sign_continuous)
            fo, fd, fk = self._fallback(lo[redo], hi[redo], with_kinks=True)
            for r, f in zip(outs, fo):
                r[:, :, redo] = f
            disc[redo] = fd
            kink[redo] = fk
        for r in outs:  # an output no instruction wrote: unknown
            unknown = np.isnan(r).any(0)
            r[0][unknown] = -_INF
            r[1][unknown] = _INF
        return (outs, disc, kink) if with_kinks else (outs, disc)


#: Batches of at most this many boxes go to the compiled program when there is one: on small
#: batches of deep products its one CasADi call beats the grouped schedule, on large batches
#: numpy's whole-array operations win (bench/supinf.py measures both; bench/RESULTS.md).
COMPILED_MAX_BATCH = 64


class AdaptiveProgram:
    """An interval program that sends small batches to a :class:`CompiledIntervalProgram`
    (built on first use) when ``compiled`` is True, and everything else to the interpreted
    :class:`IntervalProgram`. Same interface and guarantees (both are sound). Which one
    answers depends only on the batch size, never on timing, so a run is reproducible.

    Compiling builds an SX graph in Python, instruction by instruction, which costs far
    more than a pass, so it pays only for an expression bounded many times over; the
    planner leaves it off (bench/supinf.py measures both; bench/RESULTS.md).
    """

    def __init__(self, fn: ca.Function, compiled: bool = False, sign_continuous: bool = False,
                 instructions: list[Instruction] | None = None) -> None:
        self._fn = fn
        self.sign_continuous = sign_continuous
        self.interpreted = IntervalProgram(fn, sign_continuous, instructions)
        self.use_compiled = compiled
        self.compiled: CompiledIntervalProgram | None = None
        self.n_in, self.out_sizes = self.interpreted.n_in, self.interpreted.out_sizes

    def __call__(self, lo: np.ndarray, hi: np.ndarray, with_kinks: bool = False) -> tuple:
        if not self.use_compiled or np.shape(lo)[0] > COMPILED_MAX_BATCH:
            return self.interpreted(lo, hi, with_kinks)
        if self.compiled is None:
            self.compiled = CompiledIntervalProgram(self._fn, self.sign_continuous)
        return self.compiled(lo, hi, with_kinks)
