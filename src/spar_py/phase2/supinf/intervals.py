"""Interval arithmetic on batches of intervals, rounded outward (the rules of SUP/INF).

An interval batch is an array of shape ``(2, n)``: row 0 the lower ends, row 1 the upper
ends. Each operation returns a fresh array; NaN anywhere means "unknown". Every
operation rounds outward (``np.nextafter`` after IEEE-exact ops; a relative widening of
:data:`LIBM_REL` after libm functions, whose results numpy's SIMD code computes to within
a few ulps), so floating point never makes a bound unsound. sin, cos and tan are exact
over intervals (extrema inside the interval, tan poles give infinite bounds); atan2
takes the corners of a box that avoids its branch cut and (-pi, pi] otherwise.

:data:`UNARY` and :data:`BINARY` map CasADi operations to their rules and to where an
operation may be discontinuous on a box; the programs (program.py, affine.py) read them.
"""
from __future__ import annotations

import math
from collections.abc import Callable

import casadi as ca
import numpy as np

_INF = math.inf
_DIR = np.array([[-np.inf], [np.inf]])
LIBM_REL = 4e-15  # relative widening after libm/SIMD functions (>= 18 ulps)
_LIBM_ABS = 1e-300
PI = math.pi
TWO_PI = 2.0 * math.pi
HALF_PI = 0.5 * math.pi
PI_UP = float(np.nextafter(math.pi, np.inf))
BIG_ANGLE = 1e8  # beyond this |x| sin/cos/tan ranges are taken as the full range


def round_out(r: np.ndarray) -> np.ndarray:
    """Round outward by one ulp (after an IEEE-exact, correctly rounded operation); ``r`` has
    its lower ends in ``r[0]`` and upper ends in ``r[1]``, of any shape."""
    return np.nextafter(r, _DIR if r.ndim == 2 else _DIR.reshape((2,) + (1,) * (r.ndim - 1)))


def _widen(r: np.ndarray) -> np.ndarray:
    """Widen outward by a relative margin covering libm / SIMD error (a few ulps)."""
    m = np.abs(r) * LIBM_REL + _LIBM_ABS
    return np.array((r[0] - m[0], r[1] + m[1]))


def iv_add(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """[a] + [b], rounded outward."""
    return round_out(a + b)


def iv_sub(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """[a] - [b] = [a0 - b1, a1 - b0], rounded outward."""
    return round_out(a - b[::-1])


def iv_neg(a: np.ndarray) -> np.ndarray:
    """-[a] = [-a1, -a0] (exact)."""
    return -a[::-1]


def iv_mul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """[a] * [b]: min and max of the four end products, rounded outward."""
    p = (a[:, None, :] * b[None, :, :]).reshape(4, -1)
    return round_out(np.array((p.min(0), p.max(0))))


def iv_scale(a: np.ndarray, c: float) -> np.ndarray:
    """c * [a] for a constant c, rounded outward."""
    r = a * c if c >= 0 else (a * c)[::-1]
    return r if abs(c) == 1.0 else round_out(r)


def iv_div(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """[a] / [b]; (-inf, inf) where [b] contains 0; rounded outward."""
    q = (a[:, None, :] / b[None, :, :]).reshape(4, -1)
    r = round_out(np.array((q.min(0), q.max(0))))
    zero = (b[0] <= 0) & (b[1] >= 0)
    if zero.any():
        r[0, zero] = -_INF
        r[1, zero] = _INF
    return r


def iv_sq(a: np.ndarray) -> np.ndarray:
    """[a]^2 (0 is the minimum where [a] straddles 0), rounded outward."""
    s = a * a
    lo = np.where(a[0] > 0, s[0], np.where(a[1] < 0, s[1], 0.0))
    r = round_out(np.array((lo, np.maximum(s[0], s[1]))))
    r[0] = np.maximum(r[0], 0.0)
    return r


def iv_sqrt(a: np.ndarray) -> np.ndarray:
    """sqrt([a]) over the part of [a] in its domain; NaN where [a] < 0 entirely."""
    r = round_out(np.sqrt(np.maximum(a, 0.0)))
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
    full = ~((hi - lo) < TWO_PI) | ~(np.maximum(np.abs(lo), np.abs(hi)) < BIG_ANGLE)
    r[1] = np.where(full | _period_hits(lo, hi, max_at, TWO_PI), 1.0, r[1])
    r[0] = np.where(full | _period_hits(lo, hi, min_at, TWO_PI), -1.0, r[0])
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
    return _trig_range(a, np.cos, 0.0, PI)


def iv_sin(a: np.ndarray) -> np.ndarray:
    """sin([a]), exact up to rounding: 1 / -1 where pi/2 + 2k*pi / -pi/2 + 2k*pi lie inside."""
    if _small(a, 1.5):  # within (-pi/2, pi/2): increasing
        return np.clip(_widen(np.sin(a)), -1.0, 1.0)
    return _trig_range(a, np.sin, HALF_PI, -HALF_PI)


def _tan_poles(a: np.ndarray) -> np.ndarray:
    lo, hi = a[0], a[1]
    return (~((hi - lo) < PI) | ~(np.maximum(np.abs(lo), np.abs(hi)) < BIG_ANGLE)
            | _period_hits(lo, hi, HALF_PI, PI))


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
    r[0, cut] = -PI_UP
    r[1, cut] = PI_UP
    return np.clip(r, -PI_UP, PI_UP)


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


# ================================================================== the rules by CasADi operation

# unary: op -> (function, discontinuous-where or None)
UNARY: dict[int, tuple[Callable[[np.ndarray], np.ndarray], Callable[[np.ndarray], np.ndarray] | None]] = {
    ca.OP_NEG: (iv_neg, None),
    ca.OP_TWICE: (lambda a: round_out(2.0 * a), None),  # exact unless it overflows
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

BINARY: dict[int, tuple[Callable[[np.ndarray, np.ndarray], np.ndarray],
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

_OP_NAMES: dict[int, str] = {}  # filled on first use; as many entries as casadi has OP_ names


def op_name(op: int) -> str:
    """CasADi's name of an operation code (for messages)."""
    if not _OP_NAMES:
        _OP_NAMES.update({getattr(ca, n): n for n in dir(ca) if n.startswith("OP_")})
    return _OP_NAMES.get(op, str(op))


def flat(f: Callable[..., np.ndarray], *args: np.ndarray) -> np.ndarray:
    """Apply a rule on (2, n) batches to (2, k, n) arrays (flattened, then reshaped back)."""
    shape = args[0].shape
    return f(*[a.reshape(a.shape[0], -1) for a in args]).reshape(shape)


def next_down(x: np.ndarray) -> np.ndarray:
    """The next float below each entry."""
    return np.nextafter(x, -np.inf)


def next_up(x: np.ndarray) -> np.ndarray:
    """The next float above each entry."""
    return np.nextafter(x, np.inf)
