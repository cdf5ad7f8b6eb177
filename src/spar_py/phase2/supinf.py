"""SUP and INF: sound, tight bounds of a scalar CasADi SX expression over a box (Sec. 5.3).

The paper's SUP/INF (after Bledsoe, Shostak and Brooks' ACRONYM) bounds an expression
by combining bounds of its subexpressions with interval arithmetic; it is conservative
(SUP >= max, INF <= min) but can be loose on nonlinear expressions. This module keeps
the guarantee and removes most of the looseness:

1. **Interval arithmetic over the SX graph.** The expression (and its gradient) is
   compiled to a CasADi Function and its instruction list is walked with intervals
   (:class:`IntervalProgram`), over a whole batch of boxes at once (numpy arrays of
   shape ``(2, n)``: row 0 lower ends, row 1 upper ends). Every operation rounds
   outward (``np.nextafter`` after IEEE-exact ops; a relative widening of a few dozen
   ulps after libm functions, whose results numpy's SIMD code computes to within a few
   ulps), so floating point never makes a bound unsound. sin, cos and tan are exact
   over intervals (extrema inside the interval, tan poles give infinite bounds); atan2
   takes the corners of a box that avoids its branch cut and (-pi, pi] otherwise.
   A result that cannot be bounded (NaN: 0 * inf, a function outside its domain) is
   reported as (-inf, inf).
2. **Affine arithmetic** over the same instruction list (:class:`AffineProgram`): every
   quantity is a centre plus a linear form in one noise symbol per input variable and
   per nonlinear unary operation, plus a rigorous remainder. It keeps the correlations
   that plain intervals lose, e.g. in ``(30 + d) cos(th) - 30 cos(th)`` or in the inverse
   of a chain of transforms with long lever arms.
3. **Refinement** (branch and bound), both ends at once: a box's lower bound is the best
   of the natural interval extension, the mean-value form ``f(c) + G (X - c)`` (G the
   interval gradient) and the affine form; a variable whose interval derivative has
   constant sign is fixed at the end that minimises (monotonicity; only on boxes where
   every operation is continuous); other boxes are bisected on the variable with the
   largest ``width * |derivative|``. Boxes the interval gradient cannot prove monotone
   get the affine form of the expression *and its gradient*: on long transform products
   the interval gradient suffers the wrapping effect, the affine one does not, and the
   intersection of the two proves monotonicity on far more boxes. The affine gradient is
   also used as a first-order model of the gradient valid on every sub-box
   (:class:`~spar_py.phase2.taylor.GradientModel`): iterated monotonicity reduces a box to the
   faces holding its minimum without another evaluation, and the model integrated from
   the centre gives a lower bound whose error is third order in the box size (rigorous:
   a relative margin covers its floating-point sums). Values at points (box
   centres, rigorously; corners chosen by the gradient or the affine form and
   single-coordinate flips of the best points, in floating point) steer the search; the search stops when each bound is
   within ``max(abs_tol, rel_tol * width)`` of a value the function attains (``width``
   the spread of attained values found; the final claim is re-checked with rigorous
   values) or when ``max_boxes`` / ``max_time`` run out; :class:`BoundResult` says which.
   Kinks of ``fabs`` do not stop this derivative reasoning: the interval ``sign`` of an
   argument that straddles 0 is [-1, 1], so the gradient enclosures hold the Clarke
   generalised gradient and Lebourg's mean-value theorem keeps every step sound
   (:meth:`Bounder._kinks_only`; an expression with a ``sign`` of its own is still treated
   as discontinuous).

4. **Evaluation.** Both programs run as a levelled, grouped schedule (:class:`_Schedule`):
   the instructions of one level that apply the same rule are one vectorised numpy
   operation over all of them and all boxes, so a pass costs a few hundred numpy calls
   instead of a few per instruction (same rules, same results bit for bit).

5. **Compiling and caching.** :class:`CompiledIntervalProgram` writes the interval rules
   once as a CasADi SX graph and evaluates a batch in one call (``Bounder(expr,
   compiled=True)`` uses it for small batches; building it costs ~250 us per
   instruction, so it pays only for a bounder used many times). :func:`cached_bounds`
   keeps bounders and results in a cell cache's memo tables (bounded LRUs), keyed by the
   expression's structure up to variable names.

Variables are named by their SX symbol names; a box is ``{name: (lo, hi)}``. Units are
whatever the expression's are (the planner: cell length unit, radians).
"""
from __future__ import annotations

import functools
import math
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, replace

import casadi as ca
import numpy as np

from spar_py.core.errors import SparValueError
from spar_py.core.memo import Memo
from spar_py.phase2.symbolic import ChainExpr
from spar_py.phase2.taylor import GradientModel, affine_centres

__all__ = [
    "BoundResult",
    "AdaptiveProgram",
    "Bounder",
    "CompiledIntervalProgram",
    "IntervalProgram",
    "bounds",
    "cached_bounds",
    "compile_bounder",
    "expression_key",
    "inf",
    "interval",
    "sup",
]

Box = Mapping[str, tuple[float, float]]

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
BATCH = 256

_INF = math.inf
_DIR = np.array([[-np.inf], [np.inf]])
_LIBM_REL = 4e-15  # relative widening after libm/SIMD functions (>= 18 ulps)
_LIBM_ABS = 1e-300
_PI = math.pi
_TWO_PI = 2.0 * math.pi
_HALF_PI = 0.5 * math.pi
_PI_UP = float(np.nextafter(math.pi, np.inf))
_BIG_ANGLE = 1e8  # beyond this |x| sin/cos/tan ranges are taken as the full range
_EPS = float(np.finfo(float).eps)


# ================================================================== interval operations
#
# An interval batch is an array of shape (2, n): row 0 the lower ends, row 1 the upper
# ends. Each operation returns a fresh array. NaN anywhere means "unknown".


def _rnd(r: np.ndarray) -> np.ndarray:
    """Round outward by one ulp (after an IEEE-exact, correctly rounded operation); ``r`` has
    its lower ends in ``r[0]`` and upper ends in ``r[1]``, of any shape."""
    return np.nextafter(r, _DIR if r.ndim == 2 else _DIR.reshape((2,) + (1,) * (r.ndim - 1)))


def _widen(r: np.ndarray) -> np.ndarray:
    """Widen outward by a relative margin covering libm / SIMD error (a few ulps)."""
    m = np.abs(r) * _LIBM_REL + _LIBM_ABS
    return np.array((r[0] - m[0], r[1] + m[1]))


def iv_add(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """[a] + [b], rounded outward."""
    return _rnd(a + b)


def iv_sub(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """[a] - [b] = [a0 - b1, a1 - b0], rounded outward."""
    return _rnd(a - b[::-1])


def iv_neg(a: np.ndarray) -> np.ndarray:
    """-[a] = [-a1, -a0] (exact)."""
    return -a[::-1]


def iv_mul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """[a] * [b]: min and max of the four end products, rounded outward."""
    p = (a[:, None, :] * b[None, :, :]).reshape(4, -1)
    return _rnd(np.array((p.min(0), p.max(0))))


def iv_scale(a: np.ndarray, c: float) -> np.ndarray:
    """c * [a] for a constant c, rounded outward."""
    r = a * c if c >= 0 else (a * c)[::-1]
    return r if abs(c) == 1.0 else _rnd(r)


def iv_div(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """[a] / [b]; (-inf, inf) where [b] contains 0; rounded outward."""
    q = (a[:, None, :] / b[None, :, :]).reshape(4, -1)
    r = _rnd(np.array((q.min(0), q.max(0))))
    zero = (b[0] <= 0) & (b[1] >= 0)
    if zero.any():
        r[0, zero] = -_INF
        r[1, zero] = _INF
    return r


def iv_sq(a: np.ndarray) -> np.ndarray:
    """[a]^2 (0 is the minimum where [a] straddles 0), rounded outward."""
    s = a * a
    lo = np.where(a[0] > 0, s[0], np.where(a[1] < 0, s[1], 0.0))
    r = _rnd(np.array((lo, np.maximum(s[0], s[1]))))
    r[0] = np.maximum(r[0], 0.0)
    return r


def iv_sqrt(a: np.ndarray) -> np.ndarray:
    """sqrt([a]) over the part of [a] in its domain; NaN where [a] < 0 entirely."""
    r = _rnd(np.sqrt(np.maximum(a, 0.0)))
    r[0] = np.maximum(r[0], 0.0)
    r[:, a[1] < 0] = np.nan
    return r


def iv_fabs(a: np.ndarray) -> np.ndarray:
    """|[a]| (exact)."""
    b = np.abs(a)
    lo = np.where(a[0] > 0, a[0], np.where(a[1] < 0, -a[1], 0.0))
    return np.array((lo, np.maximum(b[0], b[1])))


def _monotone(f: Callable[[np.ndarray], np.ndarray], a: np.ndarray, increasing: bool = True) -> np.ndarray:
    v = f(a)
    return _widen(v if increasing else v[::-1])


def iv_exp(a: np.ndarray) -> np.ndarray:
    """exp([a]) (increasing), widened for libm error."""
    r = _monotone(np.exp, a)
    r[0] = np.maximum(r[0], 0.0)
    return r


def iv_log(a: np.ndarray) -> np.ndarray:
    """log([a]) over the positive part; NaN where [a] <= 0 entirely."""
    r = _monotone(np.log, np.maximum(a, 0.0))
    r[:, a[1] <= 0] = np.nan
    return r


def _period_hits(lo: np.ndarray, hi: np.ndarray, offset: float, period: float) -> np.ndarray:
    """True where some point offset + k*period lies in [lo - s, hi + s] (s a generous slack).

    The slack absorbs the rounding of the quotient and of the float constants; near an
    extremum the function is flat, so counting one just outside costs ~s^2.
    """
    s = 1e-9 * (1.0 + np.maximum(np.abs(lo), np.abs(hi)))
    k = np.floor((hi + s - offset) / period)
    return offset + k * period >= lo - s


def _trig_range(a: np.ndarray, f: Callable[[np.ndarray], np.ndarray], max_at: float, min_at: float) -> np.ndarray:
    v = f(a)
    r = _widen(np.array((np.minimum(v[0], v[1]), np.maximum(v[0], v[1]))))
    lo, hi = a[0], a[1]
    full = ~((hi - lo) < _TWO_PI) | ~(np.maximum(np.abs(lo), np.abs(hi)) < _BIG_ANGLE)
    r[1] = np.where(full | _period_hits(lo, hi, max_at, _TWO_PI), 1.0, r[1])
    r[0] = np.where(full | _period_hits(lo, hi, min_at, _TWO_PI), -1.0, r[0])
    r = np.clip(r, -1.0, 1.0)
    r[:, np.isnan(a).any(0)] = np.nan
    return r


def _small(a: np.ndarray, limit: float) -> bool:
    """True if every end of the batch is finite with |x| < limit (the fast paths' condition)."""
    return bool(np.all(np.abs(a) < limit))


def iv_cos(a: np.ndarray) -> np.ndarray:
    """cos([a]), exact up to rounding: 1 / -1 where 2k*pi / pi + 2k*pi lie inside."""
    if _small(a, 3.0):  # within (-pi, pi): the only extremum inside can be the maximum at 0
        v = np.cos(a)
        hi = np.where((a[0] <= 0) & (a[1] >= 0), 1.0, np.maximum(v[0], v[1]))
        r = _widen(np.array((np.minimum(v[0], v[1]), hi)))
        return np.minimum(r, 1.0)
    return _trig_range(a, np.cos, 0.0, _PI)


def iv_sin(a: np.ndarray) -> np.ndarray:
    """sin([a]), exact up to rounding: 1 / -1 where pi/2 + 2k*pi / -pi/2 + 2k*pi lie inside."""
    if _small(a, 1.5):  # within (-pi/2, pi/2): increasing
        return np.clip(_widen(np.sin(a)), -1.0, 1.0)
    return _trig_range(a, np.sin, _HALF_PI, -_HALF_PI)


def _tan_poles(a: np.ndarray) -> np.ndarray:
    lo, hi = a[0], a[1]
    return (~((hi - lo) < _PI) | ~(np.maximum(np.abs(lo), np.abs(hi)) < _BIG_ANGLE)
            | _period_hits(lo, hi, _HALF_PI, _PI))


def iv_tan(a: np.ndarray) -> np.ndarray:
    """tan([a]): increasing between poles; (-inf, inf) where a pole pi/2 + k*pi is inside."""
    r = _monotone(np.tan, a)
    pole = _tan_poles(a)
    r[0, pole] = -_INF
    r[1, pole] = _INF
    return r


def _atan2_cut(y: np.ndarray, x: np.ndarray) -> np.ndarray:
    """True where the box touches atan2's branch cut (x <= 0, y = 0), origin included."""
    return (x[0] <= 0) & (y[0] <= 0) & (y[1] >= 0)


def iv_atan2(y: np.ndarray, x: np.ndarray) -> np.ndarray:
    """atan2([y], [x]): corner extremes off the branch cut, [-pi, pi] on it (widened)."""
    c = np.arctan2(y[:, None, :], x[None, :, :]).reshape(4, -1)
    r = _widen(np.array((c.min(0), c.max(0))))
    cut = _atan2_cut(y, x)
    r[0, cut] = -_PI_UP
    r[1, cut] = _PI_UP
    return np.clip(r, -_PI_UP, _PI_UP)


def iv_pow_const(a: np.ndarray, c: float) -> np.ndarray:
    """[a] ** c for a constant exponent c (integers on all of R, others on a >= 0)."""
    if c == 0:
        return np.ones_like(a)
    if c == 1:
        return a.copy()
    if float(c).is_integer():
        n = int(c)
        if n < 0:
            return iv_div(np.ones_like(a), iv_pow_const(a, -n))
        v = np.power(a, n)
        if n % 2:  # odd: increasing
            return _widen(v)
        lo = np.where(a[0] > 0, v[0], np.where(a[1] < 0, v[1], 0.0))
        r = _widen(np.array((lo, np.maximum(v[0], v[1]))))
        r[0] = np.maximum(r[0], 0.0)
        return r
    v = np.power(np.maximum(a, 0.0), c)
    r = _widen(v if c > 0 else v[::-1])
    r[0] = np.maximum(r[0], 0.0)
    r[:, a[1] < 0] = np.nan
    return r


def iv_pow(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """[a] ** [b] = exp([b] * log([a])) for a > 0; NaN where [a] reaches <= 0."""
    r = iv_exp(iv_mul(b, iv_log(a)))
    r[:, a[0] <= 0] = np.nan
    return r


def iv_sign(a: np.ndarray) -> np.ndarray:
    """sign([a]) (exact)."""
    return np.sign(a)


def iv_cosh(a: np.ndarray) -> np.ndarray:
    """cosh([a]) (even; 1 where [a] straddles 0), widened."""
    v = np.cosh(a)
    lo = np.where(a[0] > 0, v[0], np.where(a[1] < 0, v[1], 1.0))
    r = _widen(np.array((lo, np.maximum(v[0], v[1]))))
    r[0] = np.maximum(r[0], 1.0)
    return r


def _clip_domain(f: Callable[[np.ndarray], np.ndarray], increasing: bool) -> Callable[[np.ndarray], np.ndarray]:
    def op(a: np.ndarray) -> np.ndarray:
        r = _monotone(f, np.clip(a, -1.0, 1.0), increasing)
        r[:, (a[1] < -1) | (a[0] > 1)] = np.nan
        return r
    return op


# ================================================================== the interval program

# unary: op -> (function, discontinuous-where or None)
_UNARY: dict[int, tuple[Callable[[np.ndarray], np.ndarray], Callable[[np.ndarray], np.ndarray] | None]] = {
    ca.OP_NEG: (iv_neg, None),
    ca.OP_TWICE: (lambda a: _rnd(2.0 * a), None),  # exact unless it overflows
    ca.OP_SQ: (iv_sq, None),
    ca.OP_SQRT: (iv_sqrt, lambda a: a[0] <= 0),
    ca.OP_FABS: (iv_fabs, None),
    ca.OP_SIN: (iv_sin, None),
    ca.OP_COS: (iv_cos, None),
    ca.OP_TAN: (iv_tan, _tan_poles),
    ca.OP_EXP: (iv_exp, None),
    ca.OP_LOG: (iv_log, lambda a: a[0] <= 0),
    ca.OP_ATAN: (lambda a: _monotone(np.arctan, a), None),
    ca.OP_ASIN: (_clip_domain(np.arcsin, True), lambda a: (a[0] <= -1) | (a[1] >= 1)),
    ca.OP_ACOS: (_clip_domain(np.arccos, False), lambda a: (a[0] <= -1) | (a[1] >= 1)),
    ca.OP_SINH: (lambda a: _monotone(np.sinh, a), None),
    ca.OP_COSH: (iv_cosh, None),
    ca.OP_TANH: (lambda a: _monotone(np.tanh, a), None),
    ca.OP_SIGN: (iv_sign, lambda a: (a[0] <= 0) & (a[1] >= 0) & (a[0] < a[1])),
    ca.OP_INV: (lambda a: iv_div(np.ones_like(a), a), lambda a: (a[0] <= 0) & (a[1] >= 0)),
}

_BINARY: dict[int, tuple[Callable[[np.ndarray, np.ndarray], np.ndarray],
                         Callable[[np.ndarray, np.ndarray], np.ndarray] | None]] = {
    ca.OP_ADD: (iv_add, None),
    ca.OP_SUB: (iv_sub, None),
    ca.OP_MUL: (iv_mul, None),
    ca.OP_DIV: (iv_div, lambda a, b: (b[0] <= 0) & (b[1] >= 0)),
    ca.OP_POW: (iv_pow, lambda a, b: a[0] <= 0),
    ca.OP_ATAN2: (iv_atan2, _atan2_cut),
    ca.OP_FMIN: (lambda a, b: np.minimum(a, b), None),
    ca.OP_FMAX: (lambda a, b: np.maximum(a, b), None),
    ca.OP_HYPOT: (lambda a, b: iv_sqrt(iv_add(iv_sq(a), iv_sq(b))), None),
}

_OP_NAMES: dict[int, str] = {}


def _op_name(op: int) -> str:
    if not _OP_NAMES:
        _OP_NAMES.update({getattr(ca, n): n for n in dir(ca) if n.startswith("OP_")})
    return _OP_NAMES.get(op, str(op))


def _instructions(fn: ca.Function) -> list[tuple[int, list[int], list[int], float]]:
    """A Function's instruction list: (operation, input registers, output registers, constant)."""
    op_of, ins_of, outs_of, const_of = (fn.instruction_id, fn.instruction_input, fn.instruction_output,
                                        fn.instruction_constant)
    out = []
    for k in range(fn.n_instructions()):
        op = op_of(k)
        out.append((op, list(ins_of(k)), list(outs_of(k)), float(const_of(k)) if op == ca.OP_CONST else 0.0))
    return out


def _cone(instructions: list[tuple[int, list[int], list[int], float]],
          output: int = 0) -> list[tuple[int, list[int], list[int], float]]:
    """The instructions (in their order) that output ``output`` of a Function depends on, and
    that output's own OP_OUTPUT instructions: the instruction list of the Function of that
    output alone, without building it. (CasADi sorts an SX Function's algorithm depth first
    from its outputs in order, so for output 0 this is, instruction for instruction, the
    list a Function of that output alone would have, up to register numbers, which
    :class:`_Schedule` does not read; tests/test_supinf_cone.py checks it.)

    Registers are reused in the list, so each read is resolved to the latest write before
    it; an instruction is kept iff the output reads it, directly or through kept ones."""
    writer: dict[int, int] = {}  # register -> index of the instruction that last wrote it
    deps: list[tuple[int, ...]] = []
    wanted: list[int] = []
    for k, (op, ins, outs, _) in enumerate(instructions):
        if op == ca.OP_OUTPUT:
            deps.append((writer[ins[0]],))
            if outs[0] == output:
                wanted.append(k)
            continue
        if op in (ca.OP_CONST, ca.OP_INPUT):
            deps.append(())
        else:
            arity = 1 if op in _UNARY or op == ca.OP_ASSIGN else 2
            deps.append(tuple(writer[i] for i in ins[:arity] if i in writer))
        writer[outs[0]] = k
    keep = [False] * len(instructions)
    todo = wanted
    while todo:
        k = todo.pop()
        if not keep[k]:
            keep[k] = True
            todo.extend(deps[k])
    return [ins for k, ins in enumerate(instructions) if keep[k]]


# ================================================================== the grouped schedule
#
# Interpreting an instruction list one instruction at a time costs a few numpy calls per
# instruction whatever the batch size: on a product of 8 transforms and its gradient (2,000
# instructions) that overhead is the whole cost. The schedule below is built once per
# Function: the instructions in single-assignment form, levelled (an instruction's level is
# one more than its deepest argument's), and the instructions of one level that apply the
# same rule grouped, so that each group is one gather, one vectorised rule over all its
# instructions and all boxes at once, and one scatter (about 10x fewer numpy calls). Values
# live in a register file whose rows are reused once their last reader has run (liveness),
# so memory stays near the Function's own work size.


@dataclass(frozen=True)
class _Group:
    """Instructions of one level applying one rule: ``key`` names the rule, ``args`` (arity, k)
    and ``out`` (k,) are registers, ``payload`` (k,) per-instruction constants or noise symbols."""

    key: tuple
    args: np.ndarray
    out: np.ndarray
    payload: np.ndarray


class _Schedule:
    """A one-input CasADi Function's instruction list in levelled, grouped form.

    ``classify(op, arg_slots, const_of)`` maps an instruction to ``(key, args, payload)``: the
    rule (instructions with equal keys at one level form a group), the argument slots it
    reads and a per-instruction number (a constant operand, a noise-symbol row, or 0).
    """

    def __init__(self, fn: ca.Function, classify: Callable[[int, tuple[int, ...], dict[int, float]],
                                                           tuple[tuple, tuple[int, ...], float]],
                 instructions: list[tuple[int, list[int], list[int], float]] | None = None) -> None:
        if fn.n_in() != 1:
            raise SparValueError("supinf: the Function must have exactly one (vector) input")
        self.n_in = int(fn.nnz_in(0))
        self.out_sizes = [int(fn.nnz_out(k)) for k in range(fn.n_out())]
        reg: dict[int, int] = {}  # CasADi work register -> slot
        const_of: dict[int, float] = {}  # slot -> the constant it holds
        inputs: list[tuple[int, int]] = []  # (slot, input nonzero)
        ops: list[tuple[tuple, tuple[int, ...], int, float]] = []  # (key, arg slots, out slot, payload)
        outputs: list[tuple[int, int, int]] = []  # (output, nonzero, slot)
        n = 0
        for op, ins, outs, const in (_instructions(fn) if instructions is None else instructions):
            if op == ca.OP_OUTPUT:
                outputs.append((outs[0], outs[1], reg[ins[0]]))
                continue
            if op == ca.OP_ASSIGN:
                reg[outs[0]] = reg[ins[0]]
                continue
            s, n = n, n + 1
            if op == ca.OP_CONST:
                const_of[s] = const
            elif op == ca.OP_INPUT:
                inputs.append((s, ins[1]))
            else:
                arity = 1 if op in _UNARY else 2
                key, args, payload = classify(op, tuple(reg[i] for i in ins[:arity]), const_of)
                ops.append((key, args, s, payload))
            reg[outs[0]] = s
        # plain lists below: the loops touch every instruction a few times, and numpy's
        # per-element indexing would cost more than the work (the result is the same arrays)
        level = [0] * n
        for _, args, s, _ in ops:
            level[s] = 1 + max([level[a] for a in args])
        buckets: dict[tuple, list[tuple[tuple[int, ...], int, float]]] = {}
        for key, args, s, payload in ops:
            buckets.setdefault((level[s], key), []).append((args, s, payload))
        order = sorted(buckets, key=lambda lk: lk[0])  # stable: keys of one level in first-met order
        # liveness: the last group reading each slot (outputs are read at the very end)
        last = [-1] * n
        for g, lk in enumerate(order):
            for args, _, _ in buckets[lk]:
                for a in args:
                    last[a] = g
        end = len(order)
        for _, _, s in outputs:
            last[s] = end
        # registers: inputs and constants first, then each group's outputs in rows freed by
        # slots whose last reader has already run (an instruction reads before it writes)
        where = [-1] * n
        free: list[int] = []
        size = 0

        def alloc(s: int) -> None:
            nonlocal size
            if free:
                where[s] = free.pop()
            else:
                where[s], size = size, size + 1

        inputs = [(s, j) for s, j in inputs if last[s] >= 0]  # read by some instruction or output
        for s in [s for s, _ in inputs] + sorted(c for c in const_of if last[c] >= 0):
            alloc(s)
        readers: dict[int, list[int]] = {}
        for s in range(n):
            if 0 <= last[s] < end:
                readers.setdefault(last[s], []).append(s)
        groups: list[_Group] = []
        for g, lk in enumerate(order):
            items = buckets[lk]
            for s in readers.get(g, []):
                free.append(where[s])
            outs_g = [s for _, s, _ in items]
            for s in outs_g:
                alloc(s)
            dead = [s for s in outs_g if last[s] < 0]  # computed, never read (CasADi keeps few)
            args = np.array([[where[a] for a in args] for args, _, _ in items], int).T
            groups.append(_Group(lk[1], args, np.array([where[s] for s in outs_g], int),
                                 np.array([p for _, _, p in items])))
            free.extend(where[s] for s in dead)
        self.n_regs = max(size, 1)
        self.groups = groups
        self.input_regs = np.array([where[s] for s, _ in inputs], int)
        self.input_nz = np.array([j for _, j in inputs], int)
        cs = sorted(c for c in const_of if last[c] >= 0)
        self.const_regs = np.array([where[s] for s in cs], int)
        self.const_vals = np.array([const_of[s] for s in cs], float)
        self.outputs = [(k, j, where[s]) for k, j, s in outputs]
        self.n_instructions = len(ops)

    def load(self, W: np.ndarray, X: np.ndarray, const: Callable[[np.ndarray], np.ndarray]) -> None:
        """Fill the input registers of ``W`` from ``X`` (rows along axis 1) and the constants."""
        if self.input_regs.size:
            W[:, self.input_regs] = X[:, self.input_nz]
        if self.const_regs.size:
            W[:, self.const_regs] = const(self.const_vals)


def _flat(f: Callable[..., np.ndarray], *args: np.ndarray) -> np.ndarray:
    """Apply a rule on (2, n) batches to (2, k, n) arrays (flattened, then reshaped back)."""
    shape = args[0].shape
    return f(*[a.reshape(a.shape[0], -1) for a in args]).reshape(shape)


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
    if op in _UNARY:
        return ("unary", op), args, 0.0
    if op in _BINARY:
        return ("binary", op), args, 0.0
    raise SparValueError(f"supinf: unsupported operation {_op_name(op)} in expression")


class IntervalProgram:
    """A CasADi Function's instruction list, evaluated in interval arithmetic on batches of boxes.

    The Function must take one dense column vector of inputs; outputs may be any
    dense matrices. ``prog(lo, hi)`` with ``lo``, ``hi`` of shape ``(n, n_in)`` returns
    ``(outs, disc)``: ``outs[k]`` of shape ``(2, nnz_k, n)`` enclosing output k over each
    box, ``disc`` (n,) True where some operation may be discontinuous on the box (then
    derivative-based reasoning does not apply there). Evaluated by a :class:`_Schedule`:
    one vectorised rule per group of like instructions of one level, over all boxes.

    ``sign_continuous``: ``sign`` never marks a box discontinuous. Only for the gradient
    program of an expression that has no ``sign`` of its own, where every ``sign`` is the
    derivative of a ``fabs`` (see :class:`Bounder`). ``prog(lo, hi, with_kinks=True)``
    returns ``(outs, disc, kink)``, ``kink`` (n,) True where such a ``sign``'s argument
    straddles 0 (a kink of the expression may lie in the box).
    """

    def __init__(self, fn: ca.Function, sign_continuous: bool = False,
                 instructions: list[tuple[int, list[int], list[int], float]] | None = None) -> None:
        S = _Schedule(fn, _interval_classify, instructions)
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
                    f, dfn = _BINARY[g.key[1]]
                    Bv = W[:, g.args[1]]
                    if dfn is not None:
                        disc |= dfn(A.reshape(2, -1), Bv.reshape(2, -1)).reshape(A.shape[1:]).any(0)
                    R = _flat(f, A, Bv)
                elif kind == "scale":
                    c = g.payload[:, None]
                    R = A * c
                    neg, unit = masks
                    if neg is not None:
                        R = np.where(neg, R[::-1], R)
                    if unit is None:
                        R = _rnd(R)
                    elif unit is not True:
                        R = np.where(unit, R, _rnd(R))
                elif kind == "unary":
                    f, dfn = _UNARY[g.key[1]]
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
                    R = _rnd(np.where(c < 0, R[::-1], R))
                else:  # powc
                    c = g.key[1]
                    R = _flat(lambda a: iv_pow_const(a, c), A)
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
# |x| _LIBM_REL + 1e-300. Every value also feeds a finiteness check, ``z * (lo + hi)`` with
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
    """1 where some offset + k*period lies in [lo - s, hi + s] (as :func:`_period_hits`)."""
    s = 1e-9 * (1.0 + ca.fmax(ca.fabs(lo), ca.fabs(hi)))
    k = ca.floor((hi + s - offset) / period)
    return offset + k * period >= lo - s


def _sx_trig(a: tuple[ca.SX, ca.SX], f: Callable[[ca.SX], ca.SX], max_at: float,
             min_at: float) -> tuple[ca.SX, ca.SX]:
    lo, hi = a
    v0, v1 = f(lo), f(hi)
    rlo, rhi = _sx_hull([v0, v1], _LIBM_REL)
    full = ca.logic_or(hi - lo >= _TWO_PI, ca.fmax(ca.fabs(lo), ca.fabs(hi)) >= _BIG_ANGLE)
    rhi = ca.if_else(ca.logic_or(full, _sx_period_hit(lo, hi, max_at, _TWO_PI)), 1.0, rhi)
    rlo = ca.if_else(ca.logic_or(full, _sx_period_hit(lo, hi, min_at, _TWO_PI)), -1.0, rlo)
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
    return _sx_dn(v0, _LIBM_REL), _sx_up(v1, _LIBM_REL)


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
        lo, hi = _sx_even(a, lambda x: x ** n, _LIBM_REL)
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
        return _sx_trig(a, ca.sin, _HALF_PI, -_HALF_PI), no, no
    if op == ca.OP_COS:
        return _sx_trig(a, ca.cos, 0.0, _PI), no, no
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
        r = _sx_even(a, ca.cosh, _LIBM_REL)
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
        pole = ca.logic_or(ca.logic_or(hi - lo >= _PI, ca.fmax(ca.fabs(lo), ca.fabs(hi)) >= _BIG_ANGLE),
                           _sx_period_hit(lo, hi, _HALF_PI, _PI))
        return _sx_monotone(a, ca.tan), pole, pole
    raise SparValueError(f"supinf: unsupported operation {_op_name(op)} in expression")


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
        r = _sx_hull([ca.atan2(y, x) for y in a for x in b], _LIBM_REL)
        return (ca.fmax(r[0], -_PI_UP), ca.fmin(r[1], _PI_UP)), cut, cut
    if op == ca.OP_FMIN:
        return (ca.fmin(a[0], b[0]), ca.fmin(a[1], b[1])), no, no
    if op == ca.OP_FMAX:
        return (ca.fmax(a[0], b[0]), ca.fmax(a[1], b[1])), no, no
    if op == ca.OP_HYPOT:
        sa, sb = _sx_unary(ca.OP_SQ, a)[0], _sx_unary(ca.OP_SQ, b)[0]
        s = (_sx_dn(sa[0] + sb[0]), _sx_up(sa[1] + sb[1]))
        return (ca.fmax(_sx_dn(ca.sqrt(s[0])), 0.0), _sx_up(ca.sqrt(s[1]))), no, no
    raise SparValueError(f"supinf: unsupported operation {_op_name(op)} in expression")


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
        for op, ins, o_regs, const in _instructions(fn):
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
                elif op in _UNARY:
                    r, d_bad, d_disc = _sx_unary(op, w[ins[0]])
                    if sign_continuous and op == ca.OP_SIGN:
                        kink.append(d_disc)
                        d_disc = ca.SX(0)
                elif op in _BINARY:
                    r, d_bad, d_disc = _sx_binary(op, w[ins[0]], w[ins[1]])
                else:
                    raise SparValueError(f"supinf: unsupported operation {_op_name(op)} in expression")
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


#: Batches of at most this many boxes go to the compiled program when there is one (on
#: deep products it is 4-10x faster there; on large batches numpy's whole-array
#: operations win: bench/supinf.py).
COMPILED_MAX_BATCH = 64


class AdaptiveProgram:
    """An interval program that sends small batches to a :class:`CompiledIntervalProgram`
    (built on first use) when ``compiled`` is True, and everything else to the interpreted
    :class:`IntervalProgram`. Same interface and guarantees (both are sound). Which one
    answers depends only on the batch size, never on timing, so a run is reproducible.

    Compiling costs about 250 us per instruction of the Function (building the SX graph
    in Python: 0.5 s for a product of 8 transforms), so it pays only for an expression
    bounded many times over; the planner leaves it off (bench/supinf.py measures both).
    """

    def __init__(self, fn: ca.Function, compiled: bool = False, sign_continuous: bool = False,
                 instructions: list[tuple[int, list[int], list[int], float]] | None = None) -> None:
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


# ================================================================== affine arithmetic
#
# An affine batch is an array of shape (K + J + 2, n) for K input variables and J
# nonlinear unary operations: row 0 the centre, rows 1..K the coefficients of the noise
# symbols e_1..e_K in [-1, 1] (input variable j is mid_j + rad_j e_j), rows K+1..K+J
# one noise symbol per nonlinear unary operation (sin, cos, ...: its linearisation
# error, shared by every use of that subexpression so that it cancels where it
# should), and the last row a radius covering everything else (product remainders,
# rounding). Linear operations keep the correlations between subexpressions that plain
# intervals lose, which is what makes chains of homogeneous transforms (and their
# inverses) bound tightly. Rounding: every computed entry errs by at most u |entry|
# (u = 2^-53), added to the radius, which is itself rounded up by a relative factor
# covering the float operations that computed it.

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
                 instructions: list[tuple[int, list[int], list[int], float]] | None = None) -> None:
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
            if op in _UNARY:
                return ("fb1", op), args, sym()
            if op in _BINARY:
                return ("fb2", op), args, sym()
            raise SparValueError(f"supinf: unsupported operation {_op_name(op)} in expression")

        S = _Schedule(fn, classify, instructions)
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
        return _rnd(np.array((A[0] - r, A[0] + r)))

    def _from_interval(self, R: np.ndarray, sym: np.ndarray) -> np.ndarray:
        """The affine forms mid + rad e_sym of interval batches R (2, k, n), one noise symbol
        row per instruction (``sym`` (k,)); the radius row is infinite where R is unbounded."""
        Z = np.zeros((self.rows, *R.shape[1:]))
        fin = np.isfinite(R).all(0)
        Z[0] = np.where(fin, 0.5 * (R[0] + R[1]), 0.0)
        rad = _up(np.maximum(R[1] - Z[0], Z[0] - R[0]))
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
            rng = _rnd(np.array((a0 - r, a0 + r)))
            m2 = _flat(lambda x: iv_fabs(iv_pow_const(x, n - 2)), rng)[1] * (n * (n - 1))
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
        Z[sym, k] = (0.5 * m2 * r * r + _LIBM_REL * (np.abs(f0) + ad * r)) * self._up + _TINY
        Z = self._fin(Z, ad * A[-1])
        bad = ~np.isfinite(Z[-1]) | ~np.isfinite(f0) | ~np.isfinite(Z[sym, k])
        if bad.any():  # outside the rule's domain: interval arithmetic on the range
            Z = np.where(bad[None], self._from_interval(_flat(iv, rng), sym), Z)
        return Z

    def _taylor(self, A: np.ndarray, op: int, sym: np.ndarray) -> np.ndarray:
        a0 = A[0]
        r = (self._rad(A) + A[-1]) * self._up
        rng = _rnd(np.array((a0 - r, a0 + r)))
        f, d, m2 = (np.reshape(v, a0.shape) for v in _TAYLOR[op](a0.ravel(), rng.reshape(2, -1)))
        return self._taylor_step(A, f, d, m2, r, rng, _UNARY[op][0], sym)

    def _fallback1(self, A: np.ndarray, f: Callable[[np.ndarray], np.ndarray], sym: np.ndarray) -> np.ndarray:
        return self._from_interval(_flat(f, self.range(A)), sym)

    def _fallback2(self, A: np.ndarray, B: np.ndarray,
                   f: Callable[[np.ndarray, np.ndarray], np.ndarray], sym: np.ndarray) -> np.ndarray:
        return self._from_interval(_flat(f, self.range(A), self.range(B)), sym)

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
                    R = self._fallback1(A, _UNARY[g.key[1]][0], g.payload.astype(int))
                else:  # fb2
                    R = self._fallback2(A, W[g.args[1]].transpose(1, 0, 2), _BINARY[g.key[1]][0],
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


# ================================================================== results and compiling


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


def _as_scalar(expr: ca.SX | float | ChainExpr) -> ca.SX:
    if isinstance(expr, ChainExpr):
        return expr.expr
    if isinstance(expr, (int, float, np.floating, np.integer)):
        return ca.SX(float(expr))
    if isinstance(expr, ca.DM):
        expr = ca.SX(expr)
    if not isinstance(expr, ca.SX):
        raise SparValueError(f"supinf: expected a CasADi SX expression, got {type(expr).__name__}")
    if expr.shape != (1, 1):
        raise SparValueError(f"supinf: expected a scalar expression, got shape {expr.shape}")
    return expr


def _check_box(names: list[str], box: Box) -> tuple[np.ndarray, np.ndarray]:
    lo = np.empty(len(names))
    hi = np.empty(len(names))
    for i, n in enumerate(names):
        if n not in box:
            raise SparValueError(f"supinf: the box gives no bounds for variable {n!r}")
        try:
            a, b = (float(v) for v in box[n])
        except (TypeError, ValueError):
            raise SparValueError(f"supinf: bounds of {n!r} must be a pair of numbers, got {box[n]!r}") from None
        if not (math.isfinite(a) and math.isfinite(b)) or a > b:
            raise SparValueError(f"supinf: bounds of {n!r} must be finite with lo <= hi, got [{a}, {b}]")
        lo[i], hi[i] = a, b
    return lo, hi


class Bounder:
    """A scalar expression compiled for bounding; reuse it to bound the same expression on many boxes.

    ``names`` are the expression's free variables (in the order of the compiled input).
    ``compiled``: evaluate small batches of boxes with the interval rules compiled into a
    CasADi Function (:class:`AdaptiveProgram`; worth it only for a bounder used many times).
    ``expr`` may be a :class:`~spar_py.phase2.symbolic.ChainExpr`: its SX is bounded as any other,
    and a search that has not finished once it has evaluated :data:`HULL_AFTER` boxes also
    bounds it by point sets through the chain (:mod:`spar_py.phase2.hulls`), which keeps deep
    products tight. (An SX alone carries no chain: build deep products as chains.)
    ``clarke_fabs``: derivative reasoning (mean value, monotonicity, gradient model) also on
    boxes where a ``fabs`` has its kink, through the Clarke gradient (:meth:`_kinks_only`);
    False: such boxes are bisected only, the search before that change (bench/supinf.py
    compares the two).
    """

    def __init__(self, expr: ca.SX | float | ChainExpr, compiled: bool = False, *,
                 clarke_fabs: bool = True) -> None:
        e = _as_scalar(expr)
        self.chain: ChainExpr | None = expr if isinstance(expr, ChainExpr) else None
        self._compiled = compiled
        syms = ca.symvar(e)
        self.names: list[str] = [s.name() for s in syms]
        if len(set(self.names)) != len(self.names):
            raise SparValueError("supinf: two different symbols share a name in the expression")
        #: the chain's variables (element_hash) -> their positions in ``names``
        self.chain_index: dict[int, int] = {v.element_hash(): i for i, v in enumerate(syms)}
        self.expr = e
        x = ca.vertcat(*syms) if syms else ca.SX(0, 1)
        self._x = x
        self.gradient: AdaptiveProgram | None = None
        self._fg: ca.Function | None = None  # value and gradient, when the gradient can be bounded
        self._fg_instructions: list[tuple[int, list[int], list[int], float]] | None = None
        if syms:
            fg = ca.Function("fg", [x], [e, ca.densify(ca.jacobian(e, x))], {"cse": True})
            self._fg_instructions = _instructions(fg)
            try:
                kinks = clarke_fabs and self._kinks_only(fg)
                self.gradient = AdaptiveProgram(fg, compiled, kinks, self._fg_instructions)
                self._fg = fg
            except SparValueError:
                self.gradient = None  # derivative uses operations we cannot bound: bisection only
        if self.gradient is None:
            _ = self.program  # compile now, so unsupported operations fail here

    def _kinks_only(self, fg: ca.Function) -> bool:
        """True if every ``sign`` in the value-and-gradient Function ``fg`` is the derivative
        of a ``fabs`` (the expression itself has none): then the expression is continuous
        where its other operations are, and Lipschitz where its gradient enclosure is
        finite.

        Why derivative reasoning stays sound across the kinks of ``fabs``: the interval
        (or affine) value of ``sign`` over an argument that straddles 0 is [-1, 1], which
        holds the Clarke generalised gradient of |.| there, and interval evaluation of the
        chain rule then encloses the Clarke gradient of the whole expression (Clarke's
        sum, product and chain rules are inclusions). Lebourg's mean-value theorem, f(x) -
        f(c) = <z, x - c> with z in the Clarke gradient at a point of the segment, gives
        the mean-value form and monotonicity; along a segment a Lipschitz f is the integral
        of its derivative, which lies in the Clarke gradient's projection, which gives the
        gradient model's bound (taylor.py). Where the argument's enclosure has one sign,
        say [0, b], |a| = a on the whole box and the true factor 1 lies in [0, 1]."""
        if not any(op == ca.OP_SIGN for op, _, _, _ in self._fg_instructions or ()):
            return False
        return not any(op == ca.OP_SIGN for op, _, _, _ in self._value_instructions)

    @functools.cached_property
    def _value_instructions(self) -> list[tuple[int, list[int], list[int], float]]:
        """The instruction list of the expression alone, cut from the value-and-gradient
        Function's (:func:`_cone`): the same list ``_point`` would give, without building it."""
        return _cone(self._fg_instructions or [])

    @functools.cached_property
    def _point(self) -> ca.Function:
        """The expression alone as a CasADi Function of the variable vector (built on first use)."""
        return ca.Function("f", [self._x], [self.expr], {"cse": True})

    @functools.cached_property
    def program(self) -> AdaptiveProgram:
        """The interval program of the expression alone (built on first use)."""
        return AdaptiveProgram(self._point, self._compiled)

    @functools.cached_property
    def affine_gradient(self) -> AffineProgram | None:
        """The affine-arithmetic program of the expression and its gradient, one vector
        ``(f, df/dx_1, ...)`` (built on first use; None when the gradient is not bounded).
        On deep transform products its gradient enclosures escape the wrapping effect that
        makes interval gradients too wide to prove monotonicity."""
        if self.gradient is None or self._fg is None:
            return None
        try:  # the value-and-gradient Function's outputs stacked: (f, df/dx_1, ...)
            return AffineProgram(self._fg, stack_outputs=True, instructions=self._fg_instructions)
        except SparValueError:
            return None

    @functools.cached_property
    def affine(self) -> AffineProgram:
        """The affine-arithmetic program of the expression (built on first use): from the
        value-and-gradient Function's instructions for the value when there is one (the
        program ``_point`` would give, without a second Function)."""
        if self._fg is not None:
            return AffineProgram(self._fg, instructions=self._value_instructions)
        return AffineProgram(self._point)

    def enclose(self, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
        """Rigorous interval values (2, n) of the expression on boxes (n, n_vars)."""
        if self.gradient is not None:
            outs, _ = self.gradient(lo, hi)
        else:
            outs, _ = self.program(lo, hi)
        return outs[0][:, 0, :]

    # -------------------------------------------------------------- plain interval evaluation

    def interval(self, box: Box) -> tuple[float, float]:
        """Natural interval extension over ``box``: sound, one pass, no refinement."""
        lo, hi = _check_box(self.names, box)
        (f,), _ = self.program(lo[None, :], hi[None, :])
        return float(f[0, 0, 0]), float(f[1, 0, 0])

    def values(self, points: np.ndarray) -> np.ndarray:
        """Floating-point values at points (N, n_vars) (CasADi's evaluation; not rounded outward)."""
        P = np.atleast_2d(np.asarray(points, float))
        if not self.names:
            return np.full(P.shape[0], float(self._point(np.zeros((0, 1)))))
        if self._fg is not None and P.shape[0] <= 256:  # few points: reuse the compiled f + gradient
            return np.asarray(self._fg(P.T)[0]).reshape(-1)
        return np.asarray(self._point(P.T)).reshape(-1)

    # -------------------------------------------------------------- branch and bound

    def bounds(self, box: Box, *, rel_tol: float = REL_TOL, abs_tol: float = ABS_TOL,
               max_boxes: int = MAX_BOXES, max_time: float | None = None,
               want: str = "both", beat: float | None = None) -> BoundResult:
        """Sound bounds (INF, SUP) of the expression over ``box``, refined to the tolerance.

        ``want`` is 'both', 'lo' (only INF is refined; ``hi`` is the plain interval end)
        or 'hi'. Tolerance: each bound within ``max(abs_tol, rel_tol * w)`` of an attained
        value, ``w`` the spread of attained values found; the budget is ``max_boxes``
        boxes evaluated and ``max_time`` seconds (None: no time limit).

        ``beat`` (with ``want`` 'lo' or 'hi') asks only whether INF > beat (SUP < beat):
        the search also stops as soon as that is decided, either way: its bound beats
        ``beat``, or a point where the expression is, rigorously, at most (at least)
        ``beat`` shows that no sound bound can (``decided`` is then True). The answer to
        the question is the one the full refinement would give, which continues from
        the same state: its bound only improves, and the point stays.
        """
        _check_options(want, rel_tol, abs_tol, beat)
        lo, hi = _check_box(self.names, box)
        return _branch_and_bound(self, lo, hi, rel_tol, abs_tol, max_boxes, max_time, want, beat)[0]


def _check_options(want: str, rel_tol: float, abs_tol: float, beat: float | None) -> None:
    """SparValueError unless these are options Bounder.bounds can take."""
    if want not in ("both", "lo", "hi"):
        raise SparValueError(f"supinf: want must be 'both', 'lo' or 'hi', got {want!r}")
    if beat is not None and (want == "both" or not math.isfinite(beat)):
        raise SparValueError("supinf: beat needs want 'lo' or 'hi' and a finite number")
    if not (rel_tol >= 0 and abs_tol >= 0) or (rel_tol == 0 and abs_tol == 0):
        raise SparValueError("supinf: tolerances must be >= 0 and not both 0")


def compile_bounder(expr: ca.SX | float | ChainExpr) -> Bounder:
    """Compile ``expr`` once for repeated bounding (see :class:`Bounder`)."""
    return Bounder(expr)


#: Bounds of the memo tables :func:`cached_bounds` keeps in a cell's cache (world.run.CellCache.memo): compiled
#: bounders (CasADi Functions and instruction lists: about 0.2 MB for a pickup constraint,
#: 1-2 MB for a product of 8 transforms, so at most some 100 MB) and bound results (a few
#: hundred bytes each).
BOUNDER_LIMIT = 64
RESULT_LIMIT = 8192


def _canonical(expr: ca.SX | float | ChainExpr) -> tuple[ca.SX | ChainExpr, list[str]]:
    """``expr`` with its free symbols renamed ``v0, v1, ...`` in CasADi's order of appearance,
    and their original names in that order (a chain expression stays one, renamed)."""
    e = _as_scalar(expr)
    syms = ca.symvar(e)
    canon = [ca.SX.sym(f"v{i}") for i in range(len(syms))]
    names = [v.name() for v in syms]
    if len(set(names)) != len(names):
        raise SparValueError("supinf: two different symbols share a name in the expression")
    if isinstance(expr, ChainExpr):
        return expr.substitute(dict(zip(names, canon))), names
    if syms:
        e = ca.substitute(e, ca.vertcat(*syms), ca.vertcat(*canon))
    return e, names


def _key(canon: ca.SX | ChainExpr) -> bytes:
    if isinstance(canon, ChainExpr):
        return canon.expr.serialize().encode() + b"|chain|" + canon.structure_key()
    return canon.serialize().encode()


def expression_key(expr: ca.SX | float | ChainExpr) -> bytes:
    """A key equal for expressions equal up to the names of their variables (the same
    operations and constants, the variables met in the same order): CasADi's exact
    serialisation of the graph with its symbols renamed by order of appearance (and, for
    a chain expression, its chain's structure)."""
    return _key(_canonical(expr)[0])


def cached_bounds(expr: ca.SX | float | ChainExpr, box: Box, memo: Memo | None = None,
                  **options: object) -> BoundResult:
    """``Bounder.bounds(box, **options)`` of ``expr``, with the compiled bounder and the result
    remembered in ``memo``'s tables ``supinf.bounders`` (at most :data:`BOUNDER_LIMIT`
    entries) and ``supinf.results`` (at most :data:`RESULT_LIMIT`), least recently used
    dropped first. Both are keyed by :func:`expression_key`, so a constraint built again
    in another registry, with other variable names, finds them; the result's key adds
    the box (by position) and the options: bounding is deterministic, so an equal
    question gets the equal answer. Without ``memo``, computed afresh.

    A search that stopped on ``beat`` is kept (``supinf.searches``, at most
    :data:`SEARCH_LIMIT`) and resumed by the next question on the same expression, box
    and other options: the full refinement asked later goes on from where the decision
    stopped (the same steps, so the same result as one made from the start), and a
    search that ran to its end answers the full refinement too."""
    if memo is None:
        return Bounder(expr).bounds(box, **options)  # type: ignore[arg-type]
    canon, names, k = _canonical_key(expr, memo)
    lo, hi = _check_box(names, box)
    beat = options.pop("beat", None)
    full_key = (k, lo.tobytes(), hi.tobytes(), tuple(sorted(options.items())))
    rkey = full_key if beat is None else full_key + (("beat", beat),)
    results = memo.table("supinf.results", RESULT_LIMIT)
    r = results.get(rkey)
    if r is None and beat is not None:
        r = results.get(full_key)  # the full refinement answers every beat
    if r is None:
        o = _search_options(options)
        _check_options(o["want"], o["rel_tol"], o["abs_tol"], beat)  # type: ignore[arg-type]
        B = memo.table("supinf.bounders", BOUNDER_LIMIT).get_or_compute(k, lambda: Bounder(canon))
        # (made by the first search with a beat: bounding without one never needs it)
        searches = memo.table("supinf.searches", SEARCH_LIMIT) if beat is not None else memo.existing("supinf.searches")
        S0 = searches.pop(full_key, None) if searches is not None else None
        if S0 is not None:
            S0.B = B  # (kept without it: the table of bounders alone bounds what they hold)
        r, S = _branch_and_bound(B, lo, hi, beat=beat, search=S0, **o)  # type: ignore[arg-type]
        if r.decided and searches is not None and S is not None:
            S.B = None  # type: ignore[assignment]  # the same bounder again on resuming: it is deterministic
            searches[full_key] = S
        else:  # the search ran to its end: the full answer
            results[full_key] = r
        results[rkey] = r
    return r


def _canonical_key(expr: ca.SX | float | ChainExpr, memo: Memo) -> tuple[ca.SX | ChainExpr, list[str], bytes]:
    """:func:`_canonical` of ``expr`` and its :func:`_key`, kept in ``memo``'s table
    ``supinf.canonical`` (at most :data:`CANONICAL_LIMIT`) by the expression object itself:
    one object asked again (a constraint decided, then refined; the core two pickup
    constraints share) is renamed and serialised once. The entry holds the object, so its
    id cannot be another's while it is there."""
    table = memo.table("supinf.canonical", CANONICAL_LIMIT)
    hit = table.get(id(expr))
    if hit is not None and hit[0] is expr:
        return hit[1], hit[2], hit[3]
    canon, names = _canonical(expr)
    k = _key(canon)
    table[id(expr)] = (expr, canon, names, k)
    return canon, names, k


#: Bound of the table of canonical forms by expression object (:func:`_canonical_key`): each
#: holds a renamed copy of its expression (kB for a pickup constraint, about 1 MB for a
#: product of 8 transforms).
CANONICAL_LIMIT = 128

#: Bound of the table of searches stopped on ``beat`` (:func:`cached_bounds`): each holds
#: its pool of boxes (a few kB), not its bounder.
SEARCH_LIMIT = 512


def _search_options(options: Mapping[str, object]) -> dict[str, object]:
    """Bounder.bounds' options (without beat) with their defaults; SparValueError for an
    option it does not take (their values: :func:`_check_options`)."""
    o = {"rel_tol": REL_TOL, "abs_tol": ABS_TOL, "max_boxes": MAX_BOXES, "max_time": None, "want": "both", **options}
    unknown = sorted(set(o) - {"rel_tol", "abs_tol", "max_boxes", "max_time", "want"})
    if unknown:
        raise SparValueError(f"supinf: unknown bounding options {unknown}")
    return o


# ================================================================== the search


def _down(x: np.ndarray) -> np.ndarray:
    return np.nextafter(x, -np.inf)


def _up(x: np.ndarray) -> np.ndarray:
    return np.nextafter(x, np.inf)


def _mean_value_lower(fc_lo: np.ndarray, G: np.ndarray, bl: np.ndarray, bh: np.ndarray,
                      c: np.ndarray) -> np.ndarray:
    """Rigorous lower end of f(c) + sum_i G_i (X_i - c_i) for boxes (m, nv); G (2, nv, m)."""
    dl = _down(bl - c).T  # (nv, m)
    dh = _up(bh - c).T
    p = np.array((G[0] * dl, G[0] * dh, G[1] * dl, G[1] * dh))
    p = np.where(np.isnan(p), 0.0, p)  # 0 * inf: the factor (X_i - c_i) is exactly 0
    t = _down(p.min(0))  # (nv, m) lower ends of each product
    s = t.sum(0)
    err = (t.shape[0] + 2) * _EPS * np.abs(t).sum(0)  # recursive-summation error bound
    return _down(_down(fc_lo + _down(s - err)))


class _Search:
    """Best-first branch and bound for min f (side 0) and min -f (side 1) at once.

    Soundness rests only on the rigorous lower bounds L of the boxes: every box is either
    still in the pool or its L went into ``settled[side]``. The values found at points
    (``U``: interval values at box centres, float values at corners chosen by the
    gradient or the affine form and at single-coordinate flips of the best points) only
    steer the search and decide when to stop; the claimed ``lo_found``/``hi_found`` are
    re-evaluated rigorously at the end.
    """

    def __init__(self, B: Bounder, lo0: np.ndarray, hi0: np.ndarray, sides: list[int],
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


def _branch_and_bound(B: Bounder, lo0: np.ndarray, hi0: np.ndarray, rel_tol: float, abs_tol: float,
                      max_boxes: int, max_time: float | None, want: str, beat: float | None = None,
                      search: _Search | None = None) -> tuple[BoundResult, _Search | None]:
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
    S = search if search is not None else _Search(B, lo0, hi0, sides, rel_tol, abs_tol)

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


# ================================================================== plain functions


def interval(expr: ca.SX | float, box: Box) -> tuple[float, float]:
    """Plain interval evaluation (no refinement) of ``expr`` over ``box``: sound but loose."""
    return Bounder(expr).interval(box)


def bounds(expr: ca.SX | float, box: Box, **options: object) -> tuple[float, float]:
    """(INF, SUP) of ``expr`` over ``box``: ``lo <= min`` and ``hi >= max`` (options: Bounder.bounds)."""
    r = Bounder(expr).bounds(box, **options)  # type: ignore[arg-type]
    return r.lo, r.hi


def inf(expr: ca.SX | float, box: Box, **options: object) -> float:
    """INF: a lower bound (<= the minimum) of ``expr`` over ``box``, refined to the tolerance."""
    return Bounder(expr).bounds(box, want="lo", **options).lo  # type: ignore[arg-type]


def sup(expr: ca.SX | float, box: Box, **options: object) -> float:
    """SUP: an upper bound (>= the maximum) of ``expr`` over ``box``, refined to the tolerance."""
    return Bounder(expr).bounds(box, want="hi", **options).hi  # type: ignore[arg-type]
