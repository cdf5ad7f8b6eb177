"""Which mate an assemble step of phase 2 checks: the features its faces name, a product
part's seat or held hole slid onto a fixed peg, the part its body carries when the goal's mate
is with that one, and the retention the mate is made with.
"""
from __future__ import annotations

from dataclasses import replace
from typing import Any

import numpy as np

from spar_py.core.errors import SparValueError
from spar_py.core.model import Cell, MatingFeature
from spar_py.phase2.state import World

def carried_mate(world: World, peg: str, hole: str, faces: Any, Ta: np.ndarray) -> tuple[str, np.ndarray, Any]:
    """The part, T_a and ``[PegFaces, HoleFaces]`` a product part's insertion into ``hole`` is
    checked against: its goal's first mate with a part ``hole``'s body carries (a goal into the
    ancestor that still has a location, world.product.products.goal_parents) when the goal makes none
    with ``hole`` itself, that part with T_a relative to it (T_M^-1 T_H T_a at their present
    ideal poses) and the mate's features' faces; else ``hole``, ``Ta`` and ``faces`` unchanged."""
    cell = world.cell
    goal = None if cell.product is None else cell.product.goal_of(peg)
    if goal is None:
        return hole, Ta, faces
    mates = [m for m in cell.product.mates if m.name in goal.mates and peg in (m.peg, m.hole)]
    if any(hole in (m.peg, m.hole) for m in mates):
        return hole, Ta, faces
    body = set(world.unc.body(world.unc.root(hole)))
    for m in mates:
        other = m.hole if m.peg == peg else m.peg
        if other != hole and other in body:
            own, theirs = (m.peg_feature, m.hole_feature) if m.peg == peg else (m.hole_feature, m.peg_feature)
            T_rel = np.linalg.inv(world.unc.obj(other).pose) @ world.unc.obj(hole).pose
            return other, T_rel @ Ta, [list(cell.objects[peg].feature_named(own).faces),
                                       list(cell.objects[other].feature_named(theirs).faces)]
    return hole, Ta, faces


def mate_retention(cell: Cell, peg: str, hole: str, fh: MatingFeature | None) -> tuple[str, str]:
    """(retention, the mate as messages name it) of the insertion of ``peg`` into ``hole``: a product
    part's goal is ``fixed`` if a mate it makes is fixed, else loose (seats are held by gravity);
    outside a product loose. Named ``loose in block.bore_b`` by the mate into ``hole`` (else
    the hole feature, else the part)."""
    where = hole if fh is None or not fh.name else f"{hole}.{fh.name}"
    if cell.product is None or cell.product.goal_of(peg) is None:
        return "loose", f"loose in {where}"
    goal = cell.product.goal_of(peg)
    mates = [m for m in cell.product.mates if m.name in goal.mates]
    retention = "fixed" if any(m.retention == "fixed" for m in mates) else "loose"
    into = next((m for m in mates if (m.peg, m.hole) == (peg, hole)), None)
    if into is not None:
        return retention, f"{retention} in {into.hole}.{into.hole_feature}"
    onto = next((m for m in mates if (m.peg, m.hole) == (hole, peg)), None)
    if onto is not None:
        return retention, f"{retention} on {onto.peg}.{onto.peg_feature}"
    return retention, f"{retention} on {hole}"


def product_mate(cell: Cell, held: str, fixed: str, faces: Any, Ta: np.ndarray
                  ) -> tuple[MatingFeature | None, MatingFeature | None] | None:
    """A product part's assemble that is not a held peg into a fixed hole: a seat (no features
    on its faces: (None, None), no insertion inequality, as a put-down has none), or a held
    hole slid onto a fixed peg: the pair as the inequality takes it, the held part's point
    the fixed peg's tip where it sits when seated (T_a^-1 F_p, so a perfect insertion has
    |C_h - C_p| = 0) and the margin R_hole - R_peg. None for any other assemble."""
    if cell.product is None or cell.product.goal_of(held) is None or not (
            isinstance(faces, list) and len(faces) == 2):
        return None
    fa, fb = cell.objects[held].feature_on(faces[0]), cell.objects[fixed].feature_on(faces[1])
    if fa is None and fb is None:
        return None, None
    if fa is None or fb is None or not (fa.kind == "hole" and fb.kind == "peg"):
        return None
    tip = np.asarray(fb.vector, float)
    inv = np.linalg.inv(np.asarray(Ta, float))
    seated = inv[:3, :3] @ tip + inv[:3, 3]
    return (replace(fa, kind="peg", radius=fb.radius, vector=seated, geometry=None),
            replace(fb, kind="hole", radius=fa.radius, vector=tip, geometry=None))


def mate_features(cell: Cell, peg: str, hole: str, faces: Any) -> tuple[MatingFeature, MatingFeature]:
    """The peg and hole features an assemble step's ``[PegFaces, HoleFaces]`` name (the goal's own)."""
    ok = isinstance(faces, list) and len(faces) == 2 and all(isinstance(f, list) for f in faces)
    fp = cell.objects[peg].feature_on(faces[0]) if ok else None
    fh = cell.objects[hole].feature_on(faces[1]) if ok else None
    if fp is None or fh is None:
        raise SparValueError(f"assemble({peg}, {hole}): its faces {faces!r} name no peg feature of {peg} "
                             f"and hole feature of {hole}")
    return fp, fh
