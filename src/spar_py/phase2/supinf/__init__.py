"""SUP and INF (Sec. 5.3): sound bounds of a scalar CasADi SX expression over a box.

What this package answers: bounds of a symbolic expression over a box of its variables
that are sound, SUP never below the true maximum and INF never above the true minimum,
whatever floating point does, and tight: refined until each is within a tolerance of a
value the expression attains, or until a budget runs out (:class:`BoundResult` says
which). The paper's SUP/INF (after Bledsoe, Shostak and Brooks' ACRONYM) combines bounds
of subexpressions by interval arithmetic; this keeps its guarantee and removes most of
its looseness on nonlinear expressions.

Ask :func:`cached_bounds` (the planner's door: bounders and results kept in a cell's
memo), a :class:`Bounder` (one expression compiled, bounded on many boxes) or the plain
:func:`bounds`, :func:`inf`, :func:`sup` and :func:`interval`. Variables are named by
their SX symbol names; a box is ``{name: (lo, hi)}``. Units are whatever the
expression's are (the planner: cell length unit, radians).

The modules, each depending only on those above it:

- ``intervals``: interval arithmetic on batches of intervals, rounded outward.
- ``schedule``: a CasADi Function's instruction list, levelled and grouped so that a pass
  is a few hundred vectorised numpy operations.
- ``program``: the interval program, also compiled into one CasADi Function.
- ``affine``: affine arithmetic over the same instruction list.
- ``search``: branch and bound over boxes, both ends at once.
- ``bounder``: :class:`Bounder`, an expression compiled for bounding.
- ``keys``: expressions keyed by structure, and :func:`cached_bounds`.
"""
from __future__ import annotations

from spar_py.phase2.supinf.affine import AffineProgram
from spar_py.phase2.supinf.bounder import Bounder, Box, bounds, compile_bounder, inf, interval, sup
from spar_py.phase2.supinf.intervals import (
    iv_add,
    iv_atan2,
    iv_cos,
    iv_cosh,
    iv_div,
    iv_exp,
    iv_fabs,
    iv_log,
    iv_mul,
    iv_neg,
    iv_pow,
    iv_pow_const,
    iv_scale,
    iv_sign,
    iv_sin,
    iv_sq,
    iv_sqrt,
    iv_sub,
    iv_tan,
)
from spar_py.phase2.supinf.keys import (
    BOUNDER_LIMIT,
    CANONICAL_LIMIT,
    RESULT_LIMIT,
    SEARCH_LIMIT,
    cached_bounds,
    canonical,
    expression_key,
)
from spar_py.phase2.supinf.program import AdaptiveProgram, CompiledIntervalProgram, IntervalProgram
from spar_py.phase2.supinf.schedule import Instruction, arity, cone, instruction_list
from spar_py.phase2.supinf.search import ABS_TOL, MAX_BOXES, REL_TOL, BoundResult

__all__ = [
    # bounding
    "BoundResult",
    "Bounder",
    "Box",
    "bounds",
    "cached_bounds",
    "compile_bounder",
    "inf",
    "interval",
    "sup",
    # options and table bounds
    "ABS_TOL",
    "BOUNDER_LIMIT",
    "CANONICAL_LIMIT",
    "MAX_BOXES",
    "REL_TOL",
    "RESULT_LIMIT",
    "SEARCH_LIMIT",
    # memo keys
    "canonical",
    "expression_key",
    # programs and their instruction lists
    "AdaptiveProgram",
    "AffineProgram",
    "CompiledIntervalProgram",
    "Instruction",
    "IntervalProgram",
    "arity",
    "cone",
    "instruction_list",
    # interval arithmetic
    "iv_add",
    "iv_atan2",
    "iv_cos",
    "iv_cosh",
    "iv_div",
    "iv_exp",
    "iv_fabs",
    "iv_log",
    "iv_mul",
    "iv_neg",
    "iv_pow",
    "iv_pow_const",
    "iv_scale",
    "iv_sign",
    "iv_sin",
    "iv_sq",
    "iv_sqrt",
    "iv_sub",
    "iv_tan",
]
