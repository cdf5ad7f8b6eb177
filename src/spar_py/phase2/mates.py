"""Which mate an assemble step of phase 2 checks: the features its faces name, a product
part's seat or held hole slid onto a fixed peg, the part its body carries when the goal's mate
is with that one, and the retention the mate is made with.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from spar_py.core.errors import SparValueError
from spar_py.core.model import Cell, Mate, MatingFeature, Seat
from spar_py.phase2 import uncertainty as ur
from spar_py.phase2.state import World, model_of
from spar_py.world.product import link_directions

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


def mate_retention(cell: Cell, peg: str, hole: str, fh: MatingFeature | None,
                   made: "list[MadeLink]") -> tuple[str, str]:
    """(retention, the mate as messages name it) of the insertion of ``peg`` into ``hole``: a product
    part's insertion is ``fixed`` if a mate it makes (``made``, :func:`made_links`; where none is
    known, one its goal can make) is fixed, else loose (seats are held by gravity); outside a
    product loose. Named ``loose in block.bore_b`` by the mate into ``hole`` (else the hole
    feature, else the part)."""
    where = hole if fh is None or not fh.name else f"{hole}.{fh.name}"
    if cell.product is None or cell.product.goal_of(peg) is None:
        return "loose", f"loose in {where}"
    goal = cell.product.goal_of(peg)
    mates = [m for m in cell.product.mates if m.name in goal.mates]
    retention = made_retention(made) if made else (
        "fixed" if any(m.retention == "fixed" for m in mates) else "loose")
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


@dataclass(frozen=True)
class MadeLink:
    """A mate or seat an assemble makes: ``link`` (core.model's Mate or Seat), ``moving`` its part
    in the moving body (the held part or a part it carries), ``fixed`` its part in the body the
    insertion goes into."""

    link: Mate | Seat
    moving: str
    fixed: str


def made_links(world: World, peg: str, hole: str) -> list[MadeLink]:
    """The mates and seats ``assemble(peg, hole)`` makes in ``world`` (before it): each with one
    part in the moving body (``peg``'s: the held part and the parts mated into it) and the other
    in the body ``hole`` belongs to. That insertion is the one that brings the two parts
    together, whatever order the plan took (a pin set into a base before a cover makes its base
    mate; the cover coming down over it later makes the cover's; a pin through a cover already
    in place makes both). Mates in the product file's order, then seats; none outside a product."""
    product = world.cell.product
    if product is None:
        return []
    unc = world.unc
    moving = set(unc.body(unc.root(peg)))
    target = set(unc.body(unc.root(hole)))
    out = []
    for lk in (*product.mates, *product.seats):
        a, b = lk.ends
        if a in moving and b in target:
            out.append(MadeLink(lk, a, b))
        elif b in moving and a in target:
            out.append(MadeLink(lk, b, a))
    return out


def wrong_way(world: World, made: list[MadeLink], goal_hole: str, va: np.ndarray | None) -> list[str]:
    """The mates of ``made`` the insertion's direction cannot make: ``va`` (unit, ``goal_hole``'s
    frame: the way the moving body moves) is not a way the mate lets its moving part go
    (world.product.link_directions: the peg toward its tip, the hole part against it or, through,
    either way), each as ``MATE (it needs ...)``; none without a direction."""
    if va is None:
        return []
    product = world.cell.product
    out = []
    d_world = world.unc.obj(goal_hole).pose[:3, :3] @ np.asarray(va, float)
    for m in made:
        if not isinstance(m.link, Mate):
            continue
        # the mate's directions in the product frame, into the world through the fixed part's pose
        R = world.unc.obj(m.fixed).pose[:3, :3] @ product.parts[m.fixed].pose[:3, :3].T
        allowed = [R @ d for d in link_directions(product, m.link, m.moving)]
        if not any(float(d @ d_world) > 1 - 1e-6 for d in allowed):
            need = " or ".join(f"({', '.join(f'{v:.3g}' for v in d)})" for d in allowed)
            out.append(f"{m.link.name} (the insertion goes along ({', '.join(f'{v:.3g}' for v in d_world)}); "
                       f"{m.moving} must move along {need} to make it)")
    return out


def mate_constraints(world: World, peg: str, goal_hole: str, goal_Ta: np.ndarray, made: list[MadeLink],
                     va: np.ndarray | None, action: str) -> list[ur.Constraint]:
    """One insertion check per peg-hole mate of ``made`` (Sec. 3.2.2's inequality, each where that
    peg meets that mouth), the mates in order, each constraint tagged with its mate: the moving
    side's point (a peg's tip, or the fixed peg's tip where the held hole takes it) carried by the
    held part ``peg`` through its grasp error, the fixed side's axis through its own body's
    propagated errors (uncertainty.WorldState.possible_rel). So a part's turn about the insertion
    axis moves a pattern's far pegs by the turn times their distance, and each mate has its own
    margin. A mate's part carried by the held part (a subassembly going in) is at its nominal
    place in the held part, its mates' clearances taken off the margin (each at most
    sqrt(2) c across: the bounds are a box per axis): sound, not tight. A peg that seats off
    its hole's axis (within the clearance) has that offset taken off the margin too.
    ``goal_Ta`` the held part's pose relative to ``goal_hole`` when seated; ``va`` the insertion
    direction in ``goal_hole``'s frame. Names: the first mate's ``centres`` (and ``cornerN``),
    the k-th's ``centres_k``."""
    unc = world.unc
    cell = world.cell
    T_final = unc.obj(goal_hole).pose @ np.asarray(goal_Ta, float)  # the held part seated (world)
    P_pose = unc.obj(peg).pose
    va_world = None if va is None else unc.obj(goal_hole).pose[:3, :3] @ np.asarray(va, float)
    out: list[ur.Constraint] = []
    k = 0
    for m in made:
        if not isinstance(m.link, Mate):
            continue
        k += 1
        mate = m.link
        X, Y = m.moving, m.fixed
        T_PX = np.linalg.inv(P_pose) @ unc.obj(X).pose  # X in the held part's frame (identity for X = peg)
        Ta = np.linalg.inv(unc.obj(Y).pose) @ T_final  # the held part seated, in Y's frame
        slack = _carried_slack(unc, X, peg)
        axis = None if va_world is None else unc.obj(Y).pose[:3, :3].T @ va_world
        if X == mate.peg:
            fp = cell.objects[model_of(X)].feature_named(mate.peg_feature)
            fh = cell.objects[model_of(Y)].feature_named(mate.hole_feature)
            tip = _apply(T_PX, fp.vector)
            off = _off_axis(fh, _apply(Ta, tip))  # the seated tip, in Y's frame, off Y's hole axis
            fp = replace(fp, vector=tip, radius=float(fp.radius) + slack + off,
                         corners=None if fp.corners is None else np.array([_apply(T_PX, c) for c in fp.corners]))
        else:  # the held part's hole slides onto Y's fixed peg: the fixed tip is the point checked
            fa = cell.objects[model_of(X)].feature_named(mate.hole_feature)
            fb = cell.objects[model_of(Y)].feature_named(mate.peg_feature)
            tip = np.asarray(fb.vector, float)
            seated = _apply(np.linalg.inv(Ta), tip)  # where Y's tip sits in the held part's frame, seated
            off = _off_axis(fa, _apply(np.linalg.inv(T_PX), seated))
            fp = replace(fa, kind="peg", radius=float(fb.radius) + slack + off, vector=seated, geometry=None,
                         profile="round", corners=None)
            fh = replace(fb, kind="hole", radius=fa.radius, vector=tip, geometry=None, profile="round",
                         corners=None)
        cs = ur.assemble_constraints(unc, peg, Y, Ta, fp, fh, action=action, memo=world.cache.memo, axis=axis)
        for c in cs:
            name = c.name if k == 1 else f"{c.name}_{k}"
            out.append(replace(c, name=name, mate=mate.name))
    return out


def _off_axis(hole: MatingFeature, point: np.ndarray) -> float:
    """How far ``point`` (the hole part's frame) lies from ``hole``'s axis (0 without its geometry):
    a peg seated off its hole's centre (within the clearance: kb.products accepts it) has that
    much less room, taken off the margin R_h - R_p."""
    g = hole.geometry
    if g is None:
        return 0.0
    u = np.asarray(g.direction, float) / np.linalg.norm(g.direction)
    v = np.asarray(point, float) - np.asarray(g.origin, float)
    r = float(np.linalg.norm(v - (v @ u) * u))
    return r if r > 1e-9 else 0.0


def _apply(T: np.ndarray, p: Any) -> np.ndarray:
    """Point ``p`` (3,) moved by the 4x4 ``T``."""
    p = np.asarray(p, float)
    return T[:3, :3] @ p + T[:3, 3]


def _carried_slack(unc: ur.WorldState, part: str, root: str) -> float:
    """How far (cell unit) ``part``'s mates' clearances may move it across, relative to ``root``
    which carries it: the sum over the attachments from ``part`` up to ``root`` of sqrt(2) times
    the clearance (each mate's two offsets are bounded by it); 0 for ``root`` itself."""
    total = 0.0
    while part != root and part in unc.attached:
        a = unc.attached[part]
        total += math.sqrt(2.0) * float(a.clearance) if a.offsets else 0.0
        part = a.parent
    return total


def made_retention(made: list[MadeLink]) -> str:
    """``fixed`` if a mate of ``made`` is fixed (press fit, snap, screw), else ``loose``."""
    return "fixed" if any(isinstance(m.link, Mate) and m.link.retention == "fixed" for m in made) else "loose"
