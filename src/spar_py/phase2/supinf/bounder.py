"""Bounder: a scalar expression compiled for bounding, and the plain functions over it.

A :class:`Bounder` holds the expression's programs (the interval program of the value and
its gradient, the affine programs, built on first use) and answers plain interval
evaluation and refined bounds (search.py's branch and bound). Variables are named by
their SX symbol names; a box is ``{name: (lo, hi)}``.
"""
from __future__ import annotations

import functools
import math
from collections.abc import Mapping

import casadi as ca
import numpy as np

from spar_py.core.errors import SparValueError
from spar_py.phase2.supinf.affine import AffineProgram
from spar_py.phase2.supinf.program import AdaptiveProgram
from spar_py.phase2.supinf.schedule import Instruction, cone, instruction_list
from spar_py.phase2.supinf.search import (
    ABS_TOL,
    MAX_BOXES,
    REL_TOL,
    BoundResult,
    branch_and_bound,
    check_options,
)
from spar_py.phase2.symbolic import ChainExpr

#: A box: each variable's name to its (lo, hi).
Box = Mapping[str, tuple[float, float]]


def as_scalar(expr: ca.SX | float | ChainExpr) -> ca.SX:
    """``expr`` as a scalar SX (a chain expression's SX, a number as a constant); SparValueError
    for anything else."""
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


def check_box(names: list[str], box: Box) -> tuple[np.ndarray, np.ndarray]:
    """The lower and upper ends of ``box`` for ``names``, in that order; SparValueError for a
    missing variable or bounds that are not finite numbers with lo <= hi."""
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
    and a search that has not finished once it has evaluated search.HULL_AFTER boxes also
    bounds it by point sets through the chain (:mod:`spar_py.phase2.hulls`), which keeps deep
    products tight. (An SX alone carries no chain: build deep products as chains.)
    ``clarke_fabs``: derivative reasoning (mean value, monotonicity, gradient model) also on
    boxes where a ``fabs`` has its kink, through the Clarke gradient (:meth:`_kinks_only`);
    False: such boxes are bisected only, the search before that change (bench/supinf.py
    compares the two).
    """

    def __init__(self, expr: ca.SX | float | ChainExpr, compiled: bool = False, *,
                 clarke_fabs: bool = True) -> None:
        e = as_scalar(expr)
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
        #: the expression's value and gradient as one CasADi Function, when the gradient can be bounded
        self.value_gradient: ca.Function | None = None
        self._fg_instructions: list[Instruction] | None = None
        if syms:
            fg = ca.Function("fg", [x], [e, ca.densify(ca.jacobian(e, x))], {"cse": True})
            self._fg_instructions = instruction_list(fg)
            try:
                kinks = clarke_fabs and self._kinks_only(fg)
                self.gradient = AdaptiveProgram(fg, compiled, kinks, self._fg_instructions)
                self.value_gradient = fg
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
        return not any(op == ca.OP_SIGN for op, _, _, _ in self.value_instructions)

    @functools.cached_property
    def value_instructions(self) -> list[Instruction]:
        """The instruction list of the expression alone, cut from the value-and-gradient
        Function's (:func:`cone`): the same list ``value_function`` would give, without building it."""
        return cone(self._fg_instructions or [])

    @functools.cached_property
    def value_function(self) -> ca.Function:
        """The expression alone as a CasADi Function of the variable vector (built on first use)."""
        return ca.Function("f", [self._x], [self.expr], {"cse": True})

    @functools.cached_property
    def program(self) -> AdaptiveProgram:
        """The interval program of the expression alone (built on first use)."""
        return AdaptiveProgram(self.value_function, self._compiled)

    @functools.cached_property
    def affine_gradient(self) -> AffineProgram | None:
        """The affine-arithmetic program of the expression and its gradient, one vector
        ``(f, df/dx_1, ...)`` (built on first use; None when the gradient is not bounded).
        On deep transform products its gradient enclosures escape the wrapping effect that
        makes interval gradients too wide to prove monotonicity."""
        if self.gradient is None or self.value_gradient is None:
            return None
        try:  # the value-and-gradient Function's outputs stacked: (f, df/dx_1, ...)
            return AffineProgram(self.value_gradient, stack_outputs=True, instructions=self._fg_instructions)
        except SparValueError:
            return None

    @functools.cached_property
    def affine(self) -> AffineProgram:
        """The affine-arithmetic program of the expression (built on first use): from the
        value-and-gradient Function's instructions for the value when there is one (the
        program ``value_function`` would give, without a second Function)."""
        if self.value_gradient is not None:
            return AffineProgram(self.value_gradient, instructions=self.value_instructions)
        return AffineProgram(self.value_function)

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
        lo, hi = check_box(self.names, box)
        (f,), _ = self.program(lo[None, :], hi[None, :])
        return float(f[0, 0, 0]), float(f[1, 0, 0])

    def values(self, points: np.ndarray) -> np.ndarray:
        """Floating-point values at points (N, n_vars) (CasADi's evaluation; not rounded outward)."""
        P = np.atleast_2d(np.asarray(points, float))
        if not self.names:
            return np.full(P.shape[0], float(self.value_function(np.zeros((0, 1)))))
        if self.value_gradient is not None and P.shape[0] <= 256:  # few points: reuse the compiled f + gradient
            return np.asarray(self.value_gradient(P.T)[0]).reshape(-1)
        return np.asarray(self.value_function(P.T)).reshape(-1)

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
        check_options(want, rel_tol, abs_tol, beat)
        lo, hi = check_box(self.names, box)
        return branch_and_bound(self, lo, hi, rel_tol, abs_tol, max_boxes, max_time, want, beat)[0]


def compile_bounder(expr: ca.SX | float | ChainExpr) -> Bounder:
    """Compile ``expr`` once for repeated bounding (see :class:`Bounder`)."""
    return Bounder(expr)


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

