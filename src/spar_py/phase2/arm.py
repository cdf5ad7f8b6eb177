"""The arm at one of phase 2's steps: the joint vector that reaches a tool pose clear of the
world as the step leaves it (the parts where they are, the held body in the hand), with the
display data and the refusal a step reports (world.reach's arm_at does the asking).
"""
from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from spar_py.phase2 import uncertainty as ur
from spar_py.core.model import Cell
from spar_py.world.reach import arm_at, assembled_touch, pair_text
from spar_py.phase2.state import Refusals, World

def arm_for(world: World, T: np.ndarray, what: str = "", held: tuple[str, np.ndarray] | None = None,
         grasped: str | None = None, width: float | None = None,
         allow: Sequence[tuple[str, str]] = (), via: str | None = None, touch: bool = False,
         hand_first: bool = False) -> tuple[np.ndarray | None, dict[str, Any], Refusals]:
    """The joint vector reaching tool pose T nearest the previous one among those clear of the
    world at this step (workspace.arm_at: every part where it is now, ``held`` in the hand,
    ``grasped`` being closed on, ``allow`` the step's own contacts), display data (every IK
    solution, the chosen one's clearance (cell unit) and closest pair; without a clear solution
    ``collisions`` the pairs) and the refusal of ``what`` with those pairs (empty if none).
    ``via``: the held body is held by this carried part (a via-grasp): the fingers' contact is
    allowed with it alone, and the root is checked as a carried part. ``touch``: an assemble, whose
    held body may touch the table where the product seats it so (workspace.assembled_touch).
    ``hand_first``: workspace.arm_at's (a squeeze tries the part's grasps in turn)."""
    cell = world.cell
    body = set(_held_body(world.unc))
    carried = None
    if held is not None:
        carried = _carried(world.unc, held[0], held[1])
        body |= {held[0], *carried}
        if via is not None and via in carried:
            root = held[0]
            carried[root] = np.asarray(held[1], float)
            held = (via, carried.pop(via))
            allow = [tuple(f"held:{via}" if n == f"held:{root}" else n for n in pair) for pair in allow]
    parts = {k: o.pose for k, o in world.unc.objects.items() if k not in body}
    near_table = assembled_touch(cell, [held[0], *(carried or {})] if held is not None and touch else [])
    got = arm_at(world.cache, T, world.joints, parts=parts, held=held, grasped=grasped, width=width, allow=allow,
                 carried=carried, touch=near_table, hand_first=hand_first)
    geo: dict[str, Any] = {}
    if got.clearance is not None:
        geo["clearance"] = round(got.clearance, 6)
        geo["closest_pair"] = list(got.closest_pair or ())
    refused: Refusals = ()
    if got.collisions:
        geo["collisions"] = [list(p) for p in got.collisions]
        refused = ((what, tuple(got.collisions)),)
    q = got.q
    geo = {"tool_pose": np.round(T, 9).tolist(),
           "joints_deg": None if q is None else [round(float(v), 6) for v in np.degrees(q)],
           "ik_solutions_deg": [[round(float(v), 6) for v in np.degrees(r)] for r in got.solutions],
           "ik_solver": cell.robot.solver_name, **geo}
    return q, geo, refused


def via_part(cell: Cell, obj: str, label: str) -> str | None:
    """The part a via-grasp ``label`` of ``obj`` holds (world.product.products.via_grasps), None for the
    part's own grasps."""
    if cell.product is None:
        return None
    return cell.product.via.get(obj, {}).get(label)


def _held_body(unc: ur.WorldState) -> list[str]:
    """The parts of the body in the hand (its root first), none if the hand is empty."""
    return [] if unc.holding is None else unc.body(unc.holding)


def _carried(unc: ur.WorldState, root: str, T_tool_root: np.ndarray) -> dict[str, np.ndarray]:
    """The parts ``root`` carries, each at its pose in the tool frame (T_tool_root times its pose
    relative to the root, from the parts' ideal poses), for the collision check of the held body."""
    R = unc.obj(root).pose
    inv_R = np.linalg.inv(R)
    return {c: np.asarray(T_tool_root, float) @ inv_R @ unc.obj(c).pose for c in unc.body(root)[1:]}


def no_arm(what: str, geo: dict[str, Any]) -> str:
    """Why no joint vector was chosen for ``what``: none at all, or none clear of the world."""
    if "collisions" not in geo:
        return f"no joint solution for {what}"
    return f"no collision-free IK for {what}: {', '.join(dict.fromkeys(pair_text(p) for p in geo['collisions']))}"
