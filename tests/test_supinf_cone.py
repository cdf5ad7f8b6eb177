"""supinf.cone: the value's instructions cut from the value-and-gradient Function's.

Bounder builds one CasADi Function (value and gradient) and takes the instruction list
of the value alone from it (:func:`spar_py.phase2.supinf.cone`) for the affine program of the
value and for the kinks check, instead of building a second Function. The results are
only the same bit for bit if the cut list is, instruction for instruction, the list the
second Function would have had; these tests check that on expressions like the
planner's, and that the affine program built from it answers identically.
"""
from __future__ import annotations

import casadi as ca
import numpy as np
import pytest

from spar_py.core import geometry
from spar_py.phase2.supinf import AffineProgram, Bounder, arity, cone, instruction_list

_INSTR = list[tuple[int, list[int], list[int], float]]


def _ssa(instructions: _INSTR) -> list[tuple]:
    """The list with registers replaced by the index of the instruction that wrote them
    (the form supinf's Schedule reads: register numbers, reused by CasADi, do not matter)."""
    reg: dict[int, int] = {}
    out: list[tuple] = []
    for op, ins, outs, c in instructions:
        if op == ca.OP_OUTPUT:
            out.append(("out", reg[ins[0]], outs[0], outs[1]))
            continue
        if op == ca.OP_INPUT:
            out.append(("in", ins[0], ins[1]))
        elif op == ca.OP_CONST:
            out.append(("const", c))
        else:
            out.append((op, tuple(reg[i] for i in ins[:arity(op)])))
        reg[outs[0]] = len(out) - 1
    return out


def _expressions() -> list[ca.SX]:
    th, dx, dy, dz, a, b = (ca.SX.sym(n) for n in ("th", "dx", "dy", "dz", "a", "b"))
    T = geometry.compose(geometry.trans(30 + dx, dy, dz), geometry.rotz(th))
    T = geometry.compose(T, geometry.trans(1.5, -2.0, 0.5), geometry.rotz(0.3 * th + a))
    d = geometry.apply(T, [1.0, 2.0, 3.0])
    sumsqr = sum(ca.power(ca.fabs(d[r] + 0.25) + 0.125, 2) for r in range(3))  # as uncertainty._sup_sumsqr
    return [T[0, 3], d[1], ca.sumsqr(d - ca.DM([30.0, 1.0, 2.0])), ca.cse(sumsqr),
            ca.atan2(d[1], d[0] + 40.0) + ca.sqrt(1.0 + a * a), ca.exp(0.1 * b) * ca.cos(th) - 3.0 * dx / (2.0 + a),
            ca.sign(a) * b + ca.fabs(th)]


@pytest.mark.parametrize("k", range(len(_expressions())))
def test_value_instructions_are_those_of_a_value_function(k: int) -> None:
    """Fails if cone keeps an instruction the value does not read, drops one it does, or
    orders them otherwise than CasADi orders a Function of the value alone."""
    B = Bounder(_expressions()[k])
    assert B.value_gradient is not None
    assert _ssa(B.value_instructions) == _ssa(instruction_list(B.value_function))


@pytest.mark.parametrize("k", range(len(_expressions())))
def test_affine_program_from_the_cut_list_answers_bit_for_bit(k: int) -> None:
    """Bounder.affine (from the cut list) against AffineProgram of the value's own Function,
    on random boxes: fails on any difference in any entry of the affine forms."""
    B = Bounder(_expressions()[k])
    rng = np.random.default_rng(k)
    n = len(B.names)
    c = rng.uniform(-1.0, 1.0, (40, n))
    r = rng.uniform(0.0, 0.3, (40, n))
    ours = B.affine(c - r, c + r)
    theirs = AffineProgram(B.value_function)(c - r, c + r)
    assert ours.shape == theirs.shape
    np.testing.assert_array_equal(ours, theirs)  # NaN == NaN here, bits otherwise


def test_cone_selects_one_output_and_what_it_reads() -> None:
    """A Function whose outputs read different operations: each output's cone holds its own
    operations only (fails if cone keeps everything or resolves a reused register wrong)."""
    x = ca.SX.sym("x", 2)
    fn = ca.Function("two", [x], [ca.sin(x[0]) * x[1], ca.exp(x[1]) + 2.0], {"cse": True})
    ins = instruction_list(fn)
    ops0 = {op for op, _, _, _ in cone(ins, 0)}
    ops1 = {op for op, _, _, _ in cone(ins, 1)}
    assert ca.OP_SIN in ops0 and ca.OP_MUL in ops0 and ca.OP_EXP not in ops0
    assert ca.OP_EXP in ops1 and ca.OP_SIN not in ops1 and ca.OP_MUL not in ops1
    f0 = ca.Function("f0", [x], [ca.sin(x[0]) * x[1]], {"cse": True})
    assert _ssa(cone(ins, 0)) == _ssa(instruction_list(f0))


def test_kinks_check_reads_the_value_instructions() -> None:
    """fabs alone: the gradient's sign is a kink marker (continuous); a sign of the
    expression's own makes it discontinuous (fails if the check reads the wrong list)."""
    a, b = ca.SX.sym("a"), ca.SX.sym("b")
    assert Bounder(ca.fabs(a - 0.5) * b).gradient.sign_continuous
    assert not Bounder(ca.sign(a) * b + ca.fabs(b)).gradient.sign_continuous
