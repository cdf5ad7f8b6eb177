"""Hand access: which grasps can seat a product's part at all, and which parts in place must wait.

A part P may be insertable along its axis whatever is in place (world.product.assembly's sweeps give that
precedence), and yet the hand or arm holding it may meet a part already in place: a stool's leg
held across its side meets the leg seated beside it. Phase 2 finds this only by running plan
instances into it, and the instances of one partial plan share phase 1's grasps and order. Said
before planning, phase 1 avoids both (computed once per cell, when it is loaded):

1. ``blocked``: P's grasps no plan can seat it with: refused by world.product.grasp_report's filters 1 to
   3 (not usable for its mates, the hand inside the parts that must be in place, or inside P), or
   with no arm solution clear of the table and of the parts that must be in place (P's
   transitive predecessors) when P is seated. Its assemble does not offer them
   (kb.prolog_facts' mate_grasps). A part none of whose grasps passes keeps them all (the grasp
   report says what it needs).
2. ``precedence(P, Q)``: of P's grasps that seat it, those with the hand over the table and the
   arm clear (nothing else on the table) where the cell lays P, and every one of them has no arm
   solution clear of Q in place too. Phase 1 then orders P's assemble before Q's
   (establish.pl's post_precedence/3), as for the sweeps' precedence.

Each check is made with the fewest obstacles any plan has at that step, and more obstacles never
free a blocked pose, so a plan that picks each part where the cell lays it satisfies both (a plan
putting a part down to grasp it anew is not covered by 2.). Both assume the product is built
where the cell lays its base, in that pose: a product one of whose insertions does not come from
above there (within LOOSE_MAX_DEG of down: it must be turned on the way) gets neither.

Lengths in the cell unit; the product frame for the parts' assembled poses, the world's (table top
z = 0) for the cell's.
"""
from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING

import numpy as np

from spar_py.core.model import LOOSE_MAX_DEG, Grasp, Precedence, Product
from spar_py.world.collision import CellCache
from spar_py.world.product.grasp_report import ArmClear

if TYPE_CHECKING:
    from spar_py.core.model import Cell

__all__ = ["Access", "arm_clear_of", "hand_access", "with_hand_access"]

#: How many colliding pairs a precedence's reason names.
PAIRS_SAID = 2

def arm_clear_of(cache: CellCache) -> ArmClear:
    """The cell's arm check for world.product.grasp_report and :func:`hand_access`: the arm, the hand
    closing on the part at ``T_part`` and the part are clear of the table, the obstacles and
    ``parts`` (world.reach.workspace.reach_clear)."""
    from spar_py.world.reach import reach_clear

    def arm_clear(part: str, T_part: np.ndarray, g: Grasp, parts: Mapping[str, np.ndarray]
                  ) -> tuple[bool, list[tuple[str, str]]]:
        got = reach_clear(cache, (T_part @ np.asarray(g.T, float))[None], parts={**parts, part: T_part},
                          grasped=part, width=g.width)
        return bool(got.ok[0]), list(got.pairs[0])

    return arm_clear


@dataclass(frozen=True)
class Access:
    """What hand access says of a product cell: ``blocked`` per part, the grasps no plan can seat it
    with (refused by world.product.grasp_report's filters 1 to 3, or with no arm solution clear of the parts
    that must be in place); ``precedence`` the orderings of the module docstring."""

    blocked: Mapping[str, frozenset[str]] = field(default_factory=dict)
    precedence: tuple[Precedence, ...] = ()


def hand_access(cell: Cell, cache: CellCache, held: Mapping[str, frozenset[str]] | None = None) -> Access:
    """:class:`Access` for the product cell ``cell`` (whose kept answers are ``cache``; ``held``: the
    grasp report's held_grasps for the robot's gripper when the caller has them, the layout's). Empty
    without a product, meshes, or one cell position of the base; a part with several initial
    positions (a stock) is picked where any of them lies."""
    from spar_py.world.product.grasp_report import above_table, held_grasps, seat_order
    from spar_py.world.robot import gripper_for

    product = cell.product
    if product is None or not product.goals:
        return Access()
    gripper = gripper_for(cell)
    if held is None:
        held = held_grasps(product, gripper, cell.unit)
    at: dict[str, list[np.ndarray]] = {}  # an object's every initial position (a stock of parts)
    for p in cell.positions.values():
        at.setdefault(p.obj, []).append(np.asarray(p.T, float))
    if held is None or len(at.get(product.base, ())) != 1:
        return Access()
    order, before = seat_order(product)
    W = at[product.base][0] @ np.linalg.inv(np.asarray(product.parts[product.base].pose, float))
    if not _built_in_place(product, W):
        return Access()
    placed = {q: W @ np.asarray(pp.pose, float) for q, pp in product.parts.items()}
    arm_clear = arm_clear_of(cache)
    margin = cache.scene().margin
    known = {(pr.first, pr.then) for pr in product.precedence}
    blocked: dict[str, frozenset[str]] = {}
    out: list[Precedence] = []
    for part in order:
        model = product.parts[part].model
        via = product.via.get(part, {})
        need = {q: placed[q] for q in before[part]}
        candidates = [model.grasps[label] for label in sorted(held.get(part, ())) if label in model.grasps]
        seat = [g for g in candidates if arm_clear(part, placed[part], g, need)[0]]
        ok = {g.label for g in seat}
        if ok:  # none at all: the product built elsewhere may serve it; the grasp report says so
            blocked[part] = frozenset(label for label in model.grasps if label not in via and label not in ok)
        if part not in at:
            continue
        seated = [g for g in seat if any(above_table([g], gripper, T, cell.unit, margin) and
                                         arm_clear(part, T, g, {})[0] for T in at[part])]
        if not seated:
            continue  # no grasp at all: the grasp report names what it needs, no order helps
        for q in sorted(product.parts):
            if q == part or q in before[part] or (part, q) in known:
                continue
            got = [arm_clear(part, placed[part], g, {**need, q: placed[q]}) for g in seated]
            if any(ok for ok, _ in got):
                continue
            pairs = list(dict.fromkeys(p for _, ps in got for p in ps if q in p))[:PAIRS_SAID]
            said = ", ".join(f"{a}-{b}" for a, b in pairs)
            n = len(seated)
            out.append(Precedence(part, q, f"{q} in place blocks the arm at {'the' if n == 1 else f'all {n}'} "
                                           f"grasp{'s' if n != 1 else ''} picking and seating {part}"
                                           + (f": {said}" if said else "")))
    return Access(blocked, tuple(out))


def _built_in_place(product: Product, W: np.ndarray) -> bool:
    """Whether every insertion of ``product`` comes from above (within LOOSE_MAX_DEG of world down)
    with the product at world pose ``W`` (T_world_product): the base then need not move, and the
    checks here at its pose are the plan's. A product some insertion of which needs the partial
    product turned gets no hand access (the parts would be seated in poses not known here)."""
    from spar_py.world.product.single_arm import insertions

    R = np.asarray(W, float)[:3, :3]
    limit = math.cos(math.radians(LOOSE_MAX_DEG)) - 1e-9
    return all(-(R @ np.asarray(i.direction, float))[2] >= limit for i in insertions(product))


def with_hand_access(cell: Cell, held: Mapping[str, frozenset[str]] | None = None) -> Cell:
    """``cell`` with its :func:`hand_access` (``held`` as there, asked of a cache of its own):
    a new cell whose product (a copy: a loaded product may be shared) gains the precedences
    and which has the blocked grasps (``Cell.blocked_grasps``)."""
    acc = hand_access(cell, CellCache(cell), held)
    product = cell.product
    if acc.precedence and product is not None:
        product = replace(product, precedence=tuple(product.precedence) + acc.precedence)
    return replace(cell, blocked_grasps=dict(acc.blocked), product=product)
