"""A CasADi Function's instruction list, and the levelled, grouped schedule the programs run.

Interpreting an instruction list one instruction at a time costs a few numpy calls per
instruction whatever the batch size: on a product of 8 transforms and its gradient (2,000
instructions) that overhead is the whole cost. A :class:`Schedule` is built once per
Function: the instructions in single-assignment form, levelled (an instruction's level is
one more than its deepest argument's), and the instructions of one level that apply the
same rule grouped, so that each group is one gather, one vectorised rule over all its
instructions and all boxes at once, and one scatter (far fewer numpy calls). Values
live in a register file whose rows are reused once their last reader has run (liveness),
so memory stays near the Function's own work size. The interval program (program.py) and
the affine one (affine.py) run the same schedule with their own rules, so a pass costs a
few hundred numpy calls instead of a few per instruction (same rules, same results bit
for bit).
"""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import casadi as ca
import numpy as np

from spar_py.core.errors import SparValueError
from spar_py.phase2.supinf.intervals import UNARY

#: One instruction of a CasADi Function: (operation, input registers, output registers, constant).
Instruction = tuple[int, list[int], list[int], float]


def arity(op: int) -> int:
    """How many of an instruction's input registers an operation reads (1 for unary
    operations and OP_ASSIGN, else 2)."""
    return 1 if op in UNARY or op == ca.OP_ASSIGN else 2


def instruction_list(fn: ca.Function) -> list[Instruction]:
    """A Function's instruction list: (operation, input registers, output registers, constant)."""
    op_of, ins_of, outs_of, const_of = (fn.instruction_id, fn.instruction_input, fn.instruction_output,
                                        fn.instruction_constant)
    out = []
    for k in range(fn.n_instructions()):
        op = op_of(k)
        out.append((op, list(ins_of(k)), list(outs_of(k)), float(const_of(k)) if op == ca.OP_CONST else 0.0))
    return out


def cone(instructions: list[Instruction], output: int = 0) -> list[Instruction]:
    """The instructions (in their order) that output ``output`` of a Function depends on, and
    that output's own OP_OUTPUT instructions: the instruction list of the Function of that
    output alone, without building it. (CasADi sorts an SX Function's algorithm depth first
    from its outputs in order, so for output 0 this is, instruction for instruction, the
    list a Function of that output alone would have, up to register numbers, which
    :class:`Schedule` does not read; tests/test_supinf_cone.py checks it.)

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
            deps.append(tuple(writer[i] for i in ins[:arity(op)] if i in writer))
        writer[outs[0]] = k
    keep = [False] * len(instructions)
    todo = wanted
    while todo:
        k = todo.pop()
        if not keep[k]:
            keep[k] = True
            todo.extend(deps[k])
    return [ins for k, ins in enumerate(instructions) if keep[k]]


@dataclass(frozen=True)
class Group:
    """Instructions of one level applying one rule: ``key`` names the rule, ``args`` (arity, k)
    and ``out`` (k,) are registers, ``payload`` (k,) per-instruction constants or noise symbols."""

    key: tuple
    args: np.ndarray
    out: np.ndarray
    payload: np.ndarray


class Schedule:
    """A one-input CasADi Function's instruction list in levelled, grouped form.

    ``classify(op, arg_slots, const_of)`` maps an instruction to ``(key, args, payload)``: the
    rule (instructions with equal keys at one level form a group), the argument slots it
    reads and a per-instruction number (a constant operand, a noise-symbol row, or 0).
    """

    def __init__(self, fn: ca.Function, classify: Callable[[int, tuple[int, ...], dict[int, float]],
                                                           tuple[tuple, tuple[int, ...], float]],
                 instructions: list[Instruction] | None = None) -> None:
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
        for op, ins, outs, const in (instruction_list(fn) if instructions is None else instructions):
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
                key, args, payload = classify(op, tuple(reg[i] for i in ins[:arity(op)]), const_of)
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
        groups: list[Group] = []
        for g, lk in enumerate(order):
            items = buckets[lk]
            for s in readers.get(g, []):
                free.append(where[s])
            outs_g = [s for _, s, _ in items]
            for s in outs_g:
                alloc(s)
            dead = [s for s in outs_g if last[s] < 0]  # computed, never read (CasADi keeps few)
            args = np.array([[where[a] for a in args] for args, _, _ in items], int).T
            groups.append(Group(lk[1], args, np.array([where[s] for s in outs_g], int),
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
