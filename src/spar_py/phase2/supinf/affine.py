"""Affine arithmetic over a CasADi Function's instruction list (:class:`AffineProgram`).

Every quantity is a centre plus a linear form in one noise symbol per input variable and
per nonlinear unary operation, plus a rigorous remainder. Linear operations keep the
correlations between subexpressions that plain intervals lose, e.g. in ``(30 + d) cos(th)
- 30 cos(th)`` or in the inverse of a chain of transforms with long lever arms: what makes
chains of homogeneous transforms (and their inverses) bound tightly.

An affine batch is an array of shape (K + J + 2, n) for K input variables and J
nonlinear unary operations: row 0 the centre, rows 1..K the coefficients of the noise
symbols e_1..e_K in [-1, 1] (input variable j is mid_j + rad_j e_j), rows K+1..K+J
one noise symbol per nonlinear unary operation (sin, cos, ...: its linearisation
error, shared by every use of that subexpression so that it cancels where it
should), and the last row a radius covering everything else (product remainders,
rounding). Rounding: every computed entry errs by at most u |entry|
(u = 2^-53), added to the radius, which is itself rounded up by a relative factor
covering the float operations that computed it.
"""
from __future__ import annotations

import math
from collections.abc import Callable

import casadi as ca
import numpy as np

from spar_py.core.errors import SparValueError
from spar_py.phase2.supinf.intervals import (
    BINARY,
    LIBM_REL,
    UNARY,
    flat,
    iv_cos,
    iv_div,
    iv_exp,
    iv_fabs,
    iv_mul,
    iv_pow_const,
    iv_sin,
    iv_sq,
    iv_sqrt,
    next_up,
    op_name,
    round_out,
)
from spar_py.phase2.supinf.schedule import Instruction, Schedule
from spar_py.phase2.taylor import affine_centres

_INF = math.inf
_U = 2.0 ** -53
_TINY = 1e-300
_ATAN_D2 = 0.65  # max |atan''| = 3 sqrt(3) / 8 = 0.6495...
_TANH_D2 = 0.77  # max |tanh''| = 4 / (3 sqrt(3)) = 0.7698...


class AffineProgram:
    """A CasADi Function's instruction list evaluated in affine arithmetic on batches of boxes.

    Same input convention as :class:`IntervalProgram`; ``prog(lo, hi)`` returns the affine
    forms of output 0, shape ``(K + J + 2, nnz_0, n)`` (``stack_outputs``: of all outputs,
    their nonzeros one after another; ``instructions``: ``fn``'s instruction list, if the
    caller has it already). Operations without an affine rule
    (atan2, fabs, tan, ...) fall back to interval arithmetic on the ranges of their inputs
    (the result gets its own noise symbol).
    """

    def __init__(self, fn: ca.Function, stack_outputs: bool = False,
                 instructions: list[Instruction] | None = None) -> None:
        nsym = int(fn.nnz_in(0))  # rows 1..K: the inputs; each nonlinear operation gets the next row

        def sym() -> int:
            nonlocal nsym
            nsym += 1
            return nsym

        def classify(op: int, args: tuple[int, ...], consts: dict[int, float]) -> tuple[tuple, tuple[int, ...], float]:
            if op == ca.OP_MUL and (args[0] in consts or args[1] in consts):
                c, a = (consts[args[0]], args[1]) if args[0] in consts else (consts[args[1]], args[0])
                return ("scale", False), (a,), c
            if op == ca.OP_DIV and args[1] in consts and consts[args[1]] != 0:
                return ("scale", True), args[:1], 1.0 / consts[args[1]]
            if op in (ca.OP_ADD, ca.OP_SUB, ca.OP_MUL):
                return (op,), args, 0.0
            if op == ca.OP_DIV:
                return (op,), args, sym()
            if op == ca.OP_NEG:
                return ("neg",), args, 0.0
            if op == ca.OP_TWICE:
                return ("scale", False), args, 2.0
            if op == ca.OP_SQ:
                return ("sq",), args, 0.0
            if op == ca.OP_CONSTPOW:
                if args[1] not in consts:
                    raise SparValueError("supinf: constpow with a non-constant exponent")
                return ("powc", consts[args[1]]), args[:1], sym()
            if op in _TAYLOR:
                return ("taylor", op), args, sym()
            if op in UNARY:
                return ("fb1", op), args, sym()
            if op in BINARY:
                return ("fb2", op), args, sym()
            raise SparValueError(f"supinf: unsupported operation {op_name(op)} in expression")

        S = Schedule(fn, classify, instructions)
        self._S = S
        self.K = S.n_in
        sizes = S.out_sizes if stack_outputs else S.out_sizes[:1]
        self._offset = np.concatenate(([0], np.cumsum(sizes))).astype(int)
        self.out_size = int(self._offset[-1])
        self.n_work = S.n_regs
        self.rows = nsym + 2
        self._up = 1.0 + (nsym + 16) * 2.0 ** -52

    # -------------------------------------------------------------- helpers

    def _fin(self, Z: np.ndarray, e: np.ndarray, extra_ops: int = 1) -> np.ndarray:
        """Set the radius row: propagated error e plus the rounding of the computed entries."""
        s = np.abs(Z[:-1]).sum(0)
        s *= extra_ops * _U
        s += e
        s *= self._up
        s += _TINY
        Z[-1] = s
        return Z

    def _rad(self, A: np.ndarray) -> np.ndarray:
        """Sum of |coefficients| (rounded up)."""
        r = np.abs(A[1:-1]).sum(0)
        r *= self._up
        return r

    def range(self, A: np.ndarray) -> np.ndarray:
        """The interval (2, n) an affine batch encloses (rounded outward)."""
        r = (self._rad(A) + A[-1]) * self._up
        return round_out(np.array((A[0] - r, A[0] + r)))

    def _from_interval(self, R: np.ndarray, sym: np.ndarray) -> np.ndarray:
        """The affine forms mid + rad e_sym of interval batches R (2, k, n), one noise symbol
        row per instruction (``sym`` (k,)); the radius row is infinite where R is unbounded."""
        Z = np.zeros((self.rows, *R.shape[1:]))
        fin = np.isfinite(R).all(0)
        Z[0] = np.where(fin, 0.5 * (R[0] + R[1]), 0.0)
        rad = next_up(np.maximum(R[1] - Z[0], Z[0] - R[0]))
        Z[sym, np.arange(sym.size)] = np.where(fin, rad, 0.0)
        Z[-1] = np.where(fin, _TINY, _INF)
        return Z

    # -------------------------------------------------------------- operations

    def _add(self, A: np.ndarray, B: np.ndarray) -> np.ndarray:
        return self._fin(A + B, A[-1] + B[-1])

    def _sub(self, A: np.ndarray, B: np.ndarray) -> np.ndarray:
        return self._fin(A - B, A[-1] + B[-1])

    def _neg(self, A: np.ndarray) -> np.ndarray:
        Z = -A
        Z[-1] = A[-1]
        return Z

    def _scale(self, A: np.ndarray, c: np.ndarray, inexact_c: bool = False) -> np.ndarray:
        # c (k, 1): one constant per instruction; inexact_c: c = 1/d was rounded, so c * A
        # errs by another u |c * A| per entry
        return self._fin(A * c, np.abs(c) * A[-1], 2 if inexact_c else 1)

    def _mul(self, A: np.ndarray, B: np.ndarray) -> np.ndarray:
        a0, b0 = A[0], B[0]
        ca_, cb = A[1:-1], B[1:-1]
        Ra, Rb = self._rad(A), self._rad(B)
        ea, eb = A[-1], B[-1]
        prod = ca_ * cb
        q = prod.sum(0)
        qa = np.abs(prod, out=prod).sum(0)
        Z = np.empty_like(A)
        Z[0] = a0 * b0 + 0.5 * q  # the e_i^2 terms have mean 1/2
        lin = Z[1:-1]
        np.multiply(a0, cb, out=lin)
        np.multiply(b0, ca_, out=prod)
        lin += prod
        aa0, ab0 = np.abs(a0), np.abs(b0)
        e = ((Ra * Rb - 0.5 * qa) + ea * (ab0 + Rb + eb) + eb * (aa0 + Ra)
             + (2 * _U) * (aa0 * Rb + ab0 * Ra) + self.rows * _U * qa)
        return self._fin(Z, e)

    def _sq(self, A: np.ndarray) -> np.ndarray:
        return self._mul(A, A)

    def _div(self, A: np.ndarray, B: np.ndarray, sym: np.ndarray) -> np.ndarray:
        return self._mul(A, self._taylor(B, ca.OP_INV, sym))  # 1/B gets its own noise symbol

    def _powc(self, A: np.ndarray, c: float, sym: np.ndarray) -> np.ndarray:
        if c == 0:
            Z = np.zeros_like(A)
            Z[0] = 1.0
            return Z
        if c == 1:
            return A
        if float(c).is_integer() and c > 1:
            n = int(c)
            a0 = A[0]
            r = (self._rad(A) + A[-1]) * self._up
            rng = round_out(np.array((a0 - r, a0 + r)))
            m2 = flat(lambda x: iv_fabs(iv_pow_const(x, n - 2)), rng)[1] * (n * (n - 1))
            return self._taylor_step(A, np.power(a0, n), n * np.power(a0, n - 1), m2, r, rng,
                                     lambda x: iv_pow_const(x, c), sym)
        return self._fallback1(A, lambda x: iv_pow_const(x, c), sym)

    def _taylor_step(self, A: np.ndarray, f0: np.ndarray, d: np.ndarray, m2: np.ndarray,
                     r: np.ndarray, rng: np.ndarray, iv: Callable[[np.ndarray], np.ndarray],
                     sym: np.ndarray) -> np.ndarray:
        """f(a) = f0 + d (a - a0) + R, |R| <= m2 r^2 / 2 (m2 >= sup |f''| over a0 +- r).

        The remainder R (with the libm error of f0 and d) becomes the coefficient of the
        operation's own noise symbol ``sym``.
        """
        Z = np.empty_like(A)
        Z[0] = f0
        Z[1:-1] = d * A[1:-1]
        ad = np.abs(d)
        k = np.arange(sym.size)
        Z[sym, k] = (0.5 * m2 * r * r + LIBM_REL * (np.abs(f0) + ad * r)) * self._up + _TINY
        Z = self._fin(Z, ad * A[-1])
        bad = ~np.isfinite(Z[-1]) | ~np.isfinite(f0) | ~np.isfinite(Z[sym, k])
        if bad.any():  # outside the rule's domain: interval arithmetic on the range
            Z = np.where(bad[None], self._from_interval(flat(iv, rng), sym), Z)
        return Z

    def _taylor(self, A: np.ndarray, op: int, sym: np.ndarray) -> np.ndarray:
        a0 = A[0]
        r = (self._rad(A) + A[-1]) * self._up
        rng = round_out(np.array((a0 - r, a0 + r)))
        f, d, m2 = (np.reshape(v, a0.shape) for v in _TAYLOR[op](a0.ravel(), rng.reshape(2, -1)))
        return self._taylor_step(A, f, d, m2, r, rng, UNARY[op][0], sym)

    def _fallback1(self, A: np.ndarray, f: Callable[[np.ndarray], np.ndarray], sym: np.ndarray) -> np.ndarray:
        return self._from_interval(flat(f, self.range(A)), sym)

    def _fallback2(self, A: np.ndarray, B: np.ndarray,
                   f: Callable[[np.ndarray, np.ndarray], np.ndarray], sym: np.ndarray) -> np.ndarray:
        return self._from_interval(flat(f, self.range(A), self.range(B)), sym)

    # -------------------------------------------------------------- evaluation

    #: Boxes per pass: at most this many values (rows x registers x boxes) held at once.
    CHUNK_VALUES = 1 << 22

    def __call__(self, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
        lo = np.asarray(lo, float)
        hi = np.asarray(hi, float)
        n = lo.shape[0]
        step = max(1, self.CHUNK_VALUES // (self.rows * self._S.n_regs))
        if n <= step:
            return self._run(lo, hi)
        return np.concatenate([self._run(lo[i:i + step], hi[i:i + step]) for i in range(0, n, step)], axis=2)

    def _run(self, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
        S = self._S
        n = lo.shape[0]
        mid, rd = (v.T for v in affine_centres(lo, hi))  # (K, n): input j is mid_j + rd_j e_j
        # The work array is register-major, (n_regs, rows, n): a register's forms are one
        # contiguous block, so gathering and scattering registers are block copies; the rules
        # see (rows, k, n) views and allocate their results in the same memory order
        # (np.empty_like, elementwise ops keep it). Every register but the inputs and
        # constants is written (all rows) before it is read, so only those are zeroed.
        W = np.empty((S.n_regs, self.rows, n))
        if S.input_regs.size:  # input j is mid_j + rd_j e_j
            W[S.input_regs] = 0.0
            W[S.input_regs, 0] = mid[S.input_nz]
            W[S.input_regs, 1 + S.input_nz] = rd[S.input_nz]
        if S.const_regs.size:
            W[S.const_regs] = 0.0
            W[S.const_regs, 0] = S.const_vals[:, None]
        out = np.full((self.rows, self.out_size, n), np.nan)
        with np.errstate(all="ignore"):
            for g in S.groups:
                kind = g.key[0]
                A = W[g.args[0]].transpose(1, 0, 2)
                if kind in (ca.OP_ADD, ca.OP_SUB, ca.OP_MUL, ca.OP_DIV):
                    Bv = W[g.args[1]].transpose(1, 0, 2)
                    if kind == ca.OP_ADD:
                        R = self._add(A, Bv)
                    elif kind == ca.OP_SUB:
                        R = self._sub(A, Bv)
                    elif kind == ca.OP_MUL:
                        R = self._mul(A, Bv)
                    else:
                        R = self._div(A, Bv, g.payload.astype(int))
                elif kind == "scale":
                    R = self._scale(A, g.payload[:, None], g.key[1])
                elif kind == "neg":
                    R = self._neg(A)
                elif kind == "sq":
                    R = self._sq(A)
                elif kind == "powc":
                    R = self._powc(A, g.key[1], g.payload.astype(int))
                elif kind == "taylor":
                    R = self._taylor(A, g.key[1], g.payload.astype(int))
                elif kind == "fb1":
                    R = self._fallback1(A, UNARY[g.key[1]][0], g.payload.astype(int))
                else:  # fb2
                    R = self._fallback2(A, W[g.args[1]].transpose(1, 0, 2), BINARY[g.key[1]][0],
                                        g.payload.astype(int))
                W[g.out] = R.transpose(1, 0, 2)
        for k, j, r in S.outputs:
            if k < self._offset.size - 1:
                out[:, self._offset[k] + j, :] = W[r]
        return out

    def linear(self, F: np.ndarray) -> np.ndarray:
        """The coefficients (K, n) of the input variables' noise symbols in affine forms F."""
        return F[1:self.K + 1]

    def enclosure(self, F: np.ndarray) -> np.ndarray:
        """The interval (2, n) of affine forms F (rows, n); NaN becomes (-inf, inf)."""
        with np.errstate(all="ignore"):
            r = self.range(F)
        bad = np.isnan(r).any(0)
        r[0, bad] = -_INF
        r[1, bad] = _INF
        return r


def _t_sin(a0: np.ndarray, rng: np.ndarray) -> tuple:
    return np.sin(a0), np.cos(a0), np.abs(iv_sin(rng)).max(0)


def _t_cos(a0: np.ndarray, rng: np.ndarray) -> tuple:
    return np.cos(a0), -np.sin(a0), np.abs(iv_cos(rng)).max(0)


def _t_exp(a0: np.ndarray, rng: np.ndarray) -> tuple:
    e = np.exp(a0)
    return e, e, iv_exp(rng)[1]


def _positive(rng: np.ndarray, m2: np.ndarray) -> np.ndarray:
    return np.where(rng[0] > 0, m2, _INF)


def _t_log(a0: np.ndarray, rng: np.ndarray) -> tuple:
    m2 = iv_div(np.ones_like(rng), iv_sq(rng))[1]
    return np.log(a0), 1.0 / a0, _positive(rng, m2)


def _t_sqrt(a0: np.ndarray, rng: np.ndarray) -> tuple:
    m2 = iv_div(np.full_like(rng, 0.25), iv_mul(rng, iv_sqrt(rng)))[1]
    s = np.sqrt(a0)
    return s, 0.5 / s, _positive(rng, m2)


def _t_inv(a0: np.ndarray, rng: np.ndarray) -> tuple:
    m2 = iv_div(np.full_like(rng, 2.0), iv_pow_const(iv_fabs(rng), 3))[1]
    zero = (rng[0] <= 0) & (rng[1] >= 0)
    return 1.0 / a0, -1.0 / (a0 * a0), np.where(zero, _INF, m2)


def _t_atan(a0: np.ndarray, rng: np.ndarray) -> tuple:
    return np.arctan(a0), 1.0 / (1.0 + a0 * a0), np.full_like(a0, _ATAN_D2)


def _t_tanh(a0: np.ndarray, rng: np.ndarray) -> tuple:
    t = np.tanh(a0)
    return t, 1.0 - t * t, np.full_like(a0, _TANH_D2)


# op -> (a0, range) -> (f(a0), f'(a0), sup |f''| over the range)
_TAYLOR: dict[int, Callable[[np.ndarray, np.ndarray], tuple]] = {
    ca.OP_SIN: _t_sin,
    ca.OP_COS: _t_cos,
    ca.OP_EXP: _t_exp,
    ca.OP_LOG: _t_log,
    ca.OP_SQRT: _t_sqrt,
    ca.OP_INV: _t_inv,
    ca.OP_ATAN: _t_atan,
    ca.OP_TANH: _t_tanh,
}
