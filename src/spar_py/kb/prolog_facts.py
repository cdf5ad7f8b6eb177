"""A loaded cell as the Prolog facts of module kb, as term data for the bridge.

The shapes follow the paper's Figs. 18-19 (pose/5, grasp/6) with the cell's objects,
positions, named transforms and vectors, derived turns, initial facts and goals; the
engine sends them to Prolog as they are (engine.Engine.load_cell).
"""
from __future__ import annotations

import math
from typing import Any

import numpy as np

from spar_py.core.errors import SparError
from spar_py.core.geometry import same_stable_pose
from spar_py.core.model import Cell, Position
from spar_py.world.robot import gripper_for

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
    with and the hole part's stable poses in which the mated peg clears the table;
    mate_grasps(Ta, Peg, Grasps) for a goal whose features have geometry (:func:`_mate_grasps`);
    for a product cell, precedence(P, Q, Reason) (P before Q, world.product.products.precedence) and
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
    out += _mate_grasps(cell)
    if cell.product is not None:
        out += [("precedence", pr.first, pr.then, pr.reason) for pr in cell.product.precedence]
        other = {lk.name: lk.ends for lk in (*cell.product.mates, *cell.product.seats)}
        out += [("mates", g.part, [("-", n, next(q for q in other[n] if q != g.part)) for n in g.mates])
                for g in cell.product.goals]
    return out


def _feature_geometry(model: Any, faces: Any) -> Any:
    """The geometry (world.parts.mesh.FeatureGeometry) of ``model``'s feature named among ``faces``
    (a goal's mating faces), or None (none named, or one declared without geometry)."""
    if not isinstance(faces, (list, tuple)):
        return None
    feature = model.feature_on(tuple(faces))
    return None if feature is None else feature.geometry


def _mate_grasps(cell: Cell) -> list[tuple]:
    """``mate_grasps(Ta, Peg, Grasps)`` per assembled goal whose peg and hole features both have
    geometry (axis, length): the peg's grasps the goal's assemble may use, which the planner reads
    instead of the rule by ofaces (kb/templates/spar_actions.pl mating_grasps/4). A grasp on the
    peg's shaft (its gripped faces hold the feature's) is usable where it holds only the length
    staying out of the hole when seated at T_a (world.parts.mate_grasp_usable); any other
    grasp as by the ofaces rule (it hides none of the goal's peg faces)."""
    from spar_py.world.parts import mate_grasp_usable  # numpy only; trimesh is not imported

    gripper = gripper_for(cell)
    out: list[tuple] = []
    for g in cell.goals:
        if not (isinstance(g, tuple) and g[0] == "assembled" and len(g) == 6):
            continue
        _, peg, hole, faces, ta, _ = g
        if not (isinstance(faces, list) and len(faces) == 2 and peg in cell.objects and hole in cell.objects
                and ta in cell.transforms):
            continue
        pf, hf = _feature_geometry(cell.objects[peg], faces[0]), _feature_geometry(cell.objects[hole], faces[1])
        shown = set(faces[0]) if isinstance(faces[0], list) else set()
        blocked = cell.blocked_grasps.get(peg, frozenset())
        shaft = pf is not None and hf is not None and hf.kind == "hole"
        if not (shaft or blocked):
            continue  # the planner's rule by ofaces stands as it is
        usable = [gr.label for gr in cell.objects[peg].grasps.values() if gr.label not in blocked
                  and (mate_grasp_usable(gr.T, gr.width, gripper, cell.transforms[ta], hf, cell.unit)
                       if shaft and pf.name in gr.gfaces else not shown & set(gr.ofaces))]
        fact = ("mate_grasps", ta, peg, usable)
        if fact not in out:
            out.append(fact)
    return out
