"""A loaded cell as the Prolog facts of module kb, as term data for the bridge.

The shapes follow the paper's Figs. 18-19 (pose/5, grasp/6) with the cell's objects,
positions, named transforms and vectors, derived turns, initial facts and goals; the
engine sends them to Prolog as they are (engine.Engine.load_cell).
"""
from __future__ import annotations

import math

import numpy as np

from spar_py.core.errors import SparError
from spar_py.core.geometry import same_stable_pose
from spar_py.core.model import Cell, Position

__all__ = ["facts", "position_class"]


def _tm(T: np.ndarray) -> tuple:
    """A 4x4 transform as the paper's ``tm(Rows)`` term: the rotation's columns as rows, then the displacement."""
    rows = [[_num(v) for v in T[:3, i]] for i in range(3)] + [[_num(v) for v in T[:3, 3]]]
    return ("tm", rows)


def _num(v: float) -> float:
    """A number for a fact: rounded to 12 decimals, without a negative zero."""
    r = round(float(v), 12)
    return 0.0 if r == 0 else r


def position_class(cell: Cell, pos: Position) -> str:
    """The stable pose an absolute position rests in (Sec. 5.2.3)."""
    for label, pose in cell.objects[pos.obj].poses.items():
        if same_stable_pose(pos.T[:3, :3], pose.R):
            return label
    raise SparError(f"{cell.file}: objects.{pos.obj}.initial.tm: an orientation of a stable pose")


def facts(cell: Cell) -> list[tuple]:
    """The Prolog facts of a cell (module kb), as term data for the bridge.

    Shapes follow Figs. 18-19: pose/5, grasp/6, plus object/1, face/2, position/4,
    position_class/2, initial/1, goal/1, transform/2, vector/2, problem/1, and turn/3 for
    a derived T_a: turn(Ta, Turn, HolePoses), in order, each turn the planner may assemble
    with and the hole part's stable poses in which the mated peg clears the table; for a
    product cell, precedence(P, Q, Reason) (P before Q, world.products.precedence) and
    mates(Part, Names) (the mates Part's insertion makes).
    """
    out: list[tuple] = [("problem", cell.name)]
    for o in cell.objects.values():
        out.append(("object", o.name))
        out += [("face", o.name, f) for f in o.faces]
        for p in o.poses.values():
            T = np.eye(4)
            T[:3, :3] = p.R
            T[2, 3] = p.height
            out.append(("pose", o.name, p.label, ("rfaces", list(p.rfaces)), ("ofaces", list(p.ofaces)), _tm(T)))
        for g in o.grasps.values():
            x, y, z, a, b, c = g.euler
            e = ("eulerxyz", _num(x), _num(y), _num(z),
                 _num(math.degrees(a)), _num(math.degrees(b)), _num(math.degrees(c)))
            out.append(("grasp", o.name, g.label, ("gfaces", list(g.gfaces)), ("ofaces", list(g.ofaces)), e,
                        ("width", g.width)))
    for p in cell.positions.values():
        out.append(("position", p.name, p.obj, p.label, _tm(p.T)))
        out.append(("position_class", p.label, position_class(cell, p)))
    out += [("transform", k, _tm(T)) for k, T in cell.transforms.items()]
    out += [("vector", k, [_num(v) for v in vec]) for k, vec in cell.vectors.items()]
    out += [("turn", ta, t, list(poses)) for ta, alts in cell.turns.items() for t, poses in alts]
    out += [("initial", f) for f in cell.initial]
    out += [("goal", g) for g in cell.goals]
    if cell.product is not None:
        out += [("precedence", pr.first, pr.then, pr.reason) for pr in cell.product.precedence]
        out += [("mates", g.part, list(g.mates)) for g in cell.product.goals]
    return out
