"""Can the product's parts be held for their mates? A grasp-feasibility report, part by part, for
a NO PLAN that names the first mate no grasp serves and what it needs.

For each non-base part, in an order the assembly tree and the precedence allow, its grasps are
counted through four filters, each keeping a subset of the one before:

1. ``usable``: the grasp can make every mate in which the part is the peg
   (world.parts.mate_grasp_usable: fingers, palm and tool on the outer side of the hole's
   mouth when seated); a part entering as the hole keeps every grasp here (filter 2 sees the peg);
2. ``clear``: at the seated pose the closed fingers, the palm and the tool body are clear of the
   parts that must be in place before it (its parent and everything the tree and the precedence
   put before it, transitively: the fewest any order has, so a grasp refused here is refused by
   every order);
3. ``pickup``: free at pickup in some stable pose of the part alone on the table (its model's:
   the only poses the planner puts it down in or a cell may lay it in; a round side's family
   counted once): the fingers and palm the collision margin above the table (the margin
   phase 2 keeps them off it by) and outside the part itself;
4. ``reached``: in such a pose, at the part's spot in the cell turned to one of YAWS yaws, the arm
   reaches the grasp (IK within limits, wrist above the table; no arm collision check).
``at_cell`` then counts those the arm reaches, hand above the table, at the pose the cell lays
the part in, ``at_clear`` those of them with an arm solution clear of the world there (the
caller's collision scene, when it gives one), and ``held`` those of them the arm also reaches,
clear of the world, seating the part on the product built where the cell lays the base (the
parts in place there, the others where the cell lays them). The first part whose count
reaches zero is the blocker (one refused by filters 1 to 3 before one refused only later); the
filter where it does says what it needs. Filters 1 to 3 are
necessary conditions of the planner's own checks whatever the layout and order, so a zero there
is a real refusal; the later counts judge the cell as laid out (a zero names what the layout or
a regrasp on the table must give). A part that passes them all may still be refused later
(motions, uncertainty, another order).

Lengths in the cell unit; the product's frame for seated poses, the world's (table top z = 0)
for pickups.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, fields
from typing import Any, Callable, Mapping

import numpy as np

from spar_py.core.geometry import rotz
from spar_py.core.model import Grasp, Product
from spar_py.core.units import from_mm
from spar_py.world.reach import reachable_ignoring_collisions

__all__ = ["ArmClear", "CLEAR_TOL_MM", "YAWS", "GraspReport", "MateGrasps", "above_table", "grasp_report",
           "held_grasps", "seat_order"]

#: The hand's boxes are shrunk by this (mm) before the checks against the parts in place: the
#: held part touches them when seated, and a finger flush with its face may graze theirs.
CLEAR_TOL_MM = 0.05
#: A pose is named by the object axis within this of its down vector (deg): '+z down'.
POSE_SAME_DEG = 5.0
#: How many poses offering a grasp the JSON names (the most probable first).
POSES_SAID = 6
#: How many colliding pairs a line names.
PAIRS_SAID = 3
#: ``arm_clear(part, T_part, grasp, parts)``: whether the arm reaches ``grasp`` of ``part`` at world
#: pose ``T_part`` with a solution clear of the world (``parts``: the other parts' world poses),
#: and the colliding pairs where not.
ArmClear = Callable[[str, np.ndarray, Grasp, Mapping[str, np.ndarray]], tuple[bool, list[tuple[str, str]]]]
#: ``put_down(part, grasps)``: the labels of ``grasps`` of ``part`` the arm reaches clear of the
#: world after a put-down on the cell's table, in one of the part's stable poses that leaves the
#: grasp free (phase 1's reachable arc for a put-down position: world.reach.arcs.reachable_pairs).
PutDown = Callable[[str, list[Grasp]], set[str]]
#: How many faces a line names.
FACES_SAID = 6
#: Yaws (evenly spaced about world z) tried for each stable pose in the reach count.
YAWS = 8


@dataclass(frozen=True)
class MateGrasps:
    """One part's insertion: ``part`` into ``parent`` making ``mate`` (its first peg mate, else its
    first mate or seat); the counts of the module docstring (-1 for ``reached`` and ``at_cell``
    when the report has no robot or no cell position); ``faces`` the faces its grasps hold
    (when none is usable: those the mate covers); ``hits`` the parts in place its usable grasps
    meet when seated (when none is clear); ``poses`` the stable poses tried, ``pose_ok`` those
    offering a reached grasp and ``cell_pose`` the cell's, each named by the part's axis that
    points down (:func:`_pose_text`); ``at_clear`` those of ``at_cell`` with an arm solution clear
    of the world, ``arm_pairs`` the pairs the others collide in (with how many grasps each);
    ``held`` those of ``at_clear`` also reached clear seating the part, ``seat_pairs`` likewise."""

    part: str
    parent: str
    mate: str
    grasps: int
    usable: int
    clear: int
    pickup: int
    reached: int
    at_cell: int
    faces: tuple[str, ...] = ()
    hits: tuple[str, ...] = ()
    poses: int = 0
    pose_ok: tuple[str, ...] = ()
    cell_pose: str = ""
    at_clear: int = -1
    arm_pairs: tuple[str, ...] = ()
    held: int = -1
    seat_pairs: tuple[str, ...] = ()
    #: When ``held`` is 0: of the ``pickup`` grasps (free in some stable pose), those reached clear
    #: seating the part where the cell builds the product (what a regrasp on the table could use),
    #: and the pairs the others collide in (out of reach: "no IK"); -1 when not asked.
    seat_any: int = -1
    seat_any_pairs: tuple[str, ...] = ()
    #: Of the ``seat_any`` grasps, those the arm reaches clear after a put-down on the cell's table
    #: (what a regrasp can use: :data:`PutDown`); -1 when not asked.
    placed_any: int = -1

    def to_json(self) -> dict[str, Any]:
        """As plain data (one row of the plan's JSON ``reason.grasps.parts``)."""
        return {"part": self.part, "parent": self.parent, "mate": self.mate, "grasps": self.grasps,
                "usable": self.usable, "clear": self.clear, "pickup": self.pickup, "reached": self.reached,
                "at_cell": self.at_cell, "faces": list(self.faces), "hits": list(self.hits),
                "poses": self.poses, "pose_ok": list(self.pose_ok[:POSES_SAID]), "cell_pose": self.cell_pose,
                "at_clear": self.at_clear, "arm_pairs": list(self.arm_pairs), "held": self.held,
                "seat_pairs": list(self.seat_pairs), "seat_any": self.seat_any,
                "seat_any_pairs": list(self.seat_any_pairs), "placed_any": self.placed_any}

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> MateGrasps:
        """From a row :meth:`to_json` wrote (lists read back as tuples; a count left out keeps its
        default)."""
        return cls(**{f.name: tuple(d[f.name]) if isinstance(d[f.name], list) else d[f.name]
                      for f in fields(cls) if f.name in d})


@dataclass
class GraspReport:
    """The report: ``ok`` when every part keeps a grasp through every filter; otherwise
    ``blocked`` the first part that keeps none, ``needs`` what it needs and ``why`` one line
    naming the mate and that. ``parts`` every part's counts, in order (those after the blocker
    too: a later part may need something else)."""

    ok: bool
    parts: list[MateGrasps] = field(default_factory=list)
    blocked: MateGrasps | None = None
    needs: str = ""
    why: str = ""

    def to_json(self) -> dict[str, Any]:
        """As plain data (the plan's JSON ``reason.grasps``)."""
        out: dict[str, Any] = {"ok": self.ok, "parts": [m.to_json() for m in self.parts]}
        if not self.ok and self.blocked is not None:
            out.update(part=self.blocked.part, mate=self.blocked.mate, needs=self.needs, why=self.why)
        return out

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> GraspReport:
        """From what :meth:`to_json` wrote: the blocked part is its row among ``parts``."""
        rows = [MateGrasps.from_json(r) for r in d.get("parts") or ()]
        blocked = None if d["ok"] else next((r for r in rows if r.part == d.get("part")), None)
        return cls(bool(d["ok"]), rows, blocked, d.get("needs", ""), d.get("why", ""))


def seat_order(product: Product) -> tuple[list[str], dict[str, set[str]]]:
    """The non-base parts in an order the tree (parent first) and the precedence allow (the goals'
    order among the ready), and each part's transitive predecessors (the base included)."""
    parts = [g.part for g in product.goals]
    before: dict[str, set[str]] = {g.part: {g.parent} for g in product.goals}
    for pr in product.precedence:
        if pr.then in before:
            before[pr.then].add(pr.first)
    closed: dict[str, set[str]] = {}

    def close(p: str, seen: frozenset[str] = frozenset()) -> set[str]:
        if p not in closed:
            out: set[str] = set()
            for q in before.get(p, set()):
                if q not in seen:
                    out |= {q} | close(q, seen | {p})
            closed[p] = out
        return closed[p]

    order: list[str] = []
    placed = {product.base}
    left = list(parts)
    while left:
        ready = [p for p in left if before[p] <= placed] or left[:1]  # a cycle: take the goals' order
        order.append(ready[0])
        placed.add(ready[0])
        left.remove(ready[0])
    return order, {p: close(p) | {product.base} for p in parts}


def _boxes(gripper: Any, width: float, shrink: float) -> list[tuple[np.ndarray, np.ndarray]]:
    """(lo, hi) boxes of the closed hand in the tool frame (Gripper.hand_boxes), each
    shrunk by ``shrink``."""
    return [(lo + shrink, hi - shrink) for lo, hi in gripper.hand_boxes(width) if np.all(hi - lo > 2 * shrink)]


def _hits(manager: Any, gripper: Any, T_tool: np.ndarray, width: float, shrink: float) -> set[str]:
    """The names of the meshes in ``manager`` (a trimesh CollisionManager) the closed hand at tool
    pose ``T_tool`` (the manager's frame) meets."""
    import trimesh

    out: set[str] = set()
    for lo, hi in _boxes(gripper, width, shrink):
        T = np.asarray(T_tool, float).copy()
        T[:3, 3] = T[:3, :3] @ ((lo + hi) / 2) + T[:3, 3]
        hit, names = manager.in_collision_single(trimesh.creation.box(hi - lo), transform=T, return_names=True)
        if hit:
            out |= set(names)
    return out


def _yawed(T: np.ndarray, yaw: float, xy: np.ndarray) -> np.ndarray:
    """Pose T (world, on the table) turned by ``yaw`` (rad) about world z and moved to ``xy``."""
    out = rotz(yaw) @ np.asarray(T, float)
    out[:2, 3] = xy
    return out


def grasp_report(product: Product, gripper: Any, unit: str, robot: Any = None,
                 positions: Mapping[str, np.ndarray] | None = None, arm_clear: ArmClear | None = None,
                 margin: float = 0.0, put_down: PutDown | None = None) -> GraspReport | None:
    """The report of the module docstring for ``product`` held by ``gripper`` (a
    world.robot.Gripper, cell unit ``unit``); ``robot`` and ``positions`` (each part's
    world pose in the cell) for the reach counts, else those are -1; ``arm_clear`` for the
    arm's collisions at the cell's pickups (:data:`ArmClear`), else ``at_clear`` is -1;
    ``margin`` (cell unit) the clearance the hand keeps over the table at pickups (the
    collision scene's); ``put_down`` for the grasps a regrasp on the table can use
    (``placed_any``), else that is -1. None when a part has no mesh or shape, or the product
    has no goal."""
    from spar_py.world.parts import part_mesh

    meshes = {p: part_mesh(pp.model) for p, pp in product.parts.items()}
    if any(m is None for m in meshes.values()) or not product.goals:
        return None
    order, before = seat_order(product)
    at = dict(positions or {})
    rows = [_row(product, part, meshes, before[part], gripper, unit, robot if part in at else None, at,
                 arm_clear, margin, put_down) for part in order]
    # a part no layout or order can serve (filters 1 to 3) first, then the first the cell's layout fails
    for row in sorted(rows, key=lambda r: not _refused_anywhere(r)):
        needs = _needs(row)
        if needs:
            return GraspReport(False, rows, row, needs, f"no grasp of {row.part} serves {row.mate}: {_said(row)}; "
                               f"it needs {needs}")
    return GraspReport(True, rows)


def held_grasps(product: Product, gripper: Any, unit: str) -> dict[str, frozenset[str]] | None:
    """Each non-base part's grasps through filters 1 to 3 but the table (usable for its mates,
    clear of the parts in place when seated, outside the part itself): those a layout may lay
    it out for (the table check is the pose's: :func:`above_table`). None when a part has no
    mesh or shape, or the product has no goal."""
    from spar_py.world.parts import part_mesh

    meshes = {p: part_mesh(pp.model) for p, pp in product.parts.items()}
    if any(m is None for m in meshes.values()) or not product.goals:
        return None
    order, before = seat_order(product)
    return {part: frozenset(g.label for g in _filtered(product, part, meshes, before[part], gripper, unit)[4])
            for part in order}


def _filtered(product: Product, part: str, meshes: Mapping[str, Any], placed: set[str], gripper: Any, unit: str
              ) -> tuple[list[Grasp], list[Grasp], list[Grasp], set[str], list[Grasp]]:
    """Filters 1 to 3 but the table, for ``part`` seated with ``placed`` in place: (its own grasps,
    those usable for its peg mates, those also clear of ``placed`` when seated, the parts the
    usable ones meet, those clear ones also outside the part itself)."""
    import trimesh

    from spar_py.world.parts import grasp_problem, mate_grasp_usable

    g = next(x for x in product.goals if x.part == part)
    pp = product.parts[part]
    pegs = [m for m in product.mates if m.name in g.mates and m.peg == part]
    via = product.via.get(part, {})
    own = [gr for label, gr in pp.model.grasps.items() if label not in via]
    usable = [gr for gr in own if all(_usable(mate_grasp_usable, gr, gripper, product, m, unit) for m in pegs)]
    manager = trimesh.collision.CollisionManager()
    for q in sorted(placed):
        manager.add_object(q, meshes[q], transform=np.asarray(product.parts[q].pose, float))
    P = np.asarray(pp.pose, float)
    hits: set[str] = set()
    clear: list[Grasp] = []
    for gr in usable:
        h = _hits(manager, gripper, P @ np.asarray(gr.T, float), gr.width, from_mm(unit, CLEAR_TOL_MM))
        hits |= h
        if not h:
            clear.append(gr)
    free = [gr for gr in clear if grasp_problem(meshes[part], np.asarray(gr.T, float), gr.width, gripper,
                                                unit) is None]
    return own, usable, clear, hits, free


def _refused_anywhere(r: MateGrasps) -> bool:
    """Whether a part keeps no grasp through filters 1 to 3 (whatever the layout and order)."""
    return r.usable == 0 or r.clear == 0 or r.pickup == 0


def _row(product: Product, part: str, meshes: Mapping[str, Any], placed: set[str], gripper: Any, unit: str,
         robot: Any, at: Mapping[str, np.ndarray], arm_clear: ArmClear | None, margin: float = 0.0,
         put_down: PutDown | None = None) -> MateGrasps:
    """One part's counts (module docstring): ``placed`` the parts in place when it is seated,
    ``at`` the parts' poses in the cell (world) and ``robot`` the arm, for the reach counts (None,
    or the part not in ``at``: -1), ``arm_clear`` for ``at_clear`` and ``held``, ``margin`` the
    hand's clearance over the table at pickup (cell unit), ``put_down`` for ``placed_any``."""

    g = next(x for x in product.goals if x.part == part)
    pp = product.parts[part]
    T_cell = at.get(part)
    mates = [m for m in product.mates if m.name in g.mates]
    pegs = [m for m in mates if m.peg == part]
    name = (pegs or mates)[0].name if (pegs or mates) else (g.mates[0] if g.mates else f"{part} on {g.parent}")
    own, usable, clear, hits, free = _filtered(product, part, meshes, placed, gripper, unit)
    P = np.asarray(pp.pose, float)
    Ts = _poses(pp.model, product.sub_poses.get(part, {}))
    pick: set[str] = set()
    reach: set[str] = set()
    pose_ok: list[str] = []
    for Tp in Ts:
        up = above_table(free, gripper, Tp, unit, margin)
        pick |= {gr.label for gr in up}
        if robot is None or T_cell is None or not up:
            continue
        xy = np.asarray(T_cell, float)[:2, 3]
        W = np.stack([_yawed(Tp, 2 * math.pi * i / YAWS, xy) @ np.asarray(gr.T, float)
                      for gr in up for i in range(YAWS)])
        got = reachable_ignoring_collisions(robot, W).reshape(len(up), YAWS).any(axis=1)
        if got.any():
            reach |= {gr.label for gr, ok in zip(up, got) if ok}
            pose_ok.append(_pose_text(Tp))
    reached, at_cell, at_clear, held, cell_pose, seat_any, placed_any = -1, -1, -1, -1, "", -1, -1
    seat_any_pairs: list[str] = []
    arm_pairs: list[str] = []
    seat_pairs: list[str] = []
    if robot is not None and T_cell is not None:
        Tc = np.asarray(T_cell, float)
        up = above_table(free, gripper, Tc, unit, margin)
        reached, cell_pose = len(reach), _pose_text(Tc)
        ok = reachable_ignoring_collisions(robot, np.stack([Tc @ np.asarray(gr.T, float) for gr in up])) if up \
            else np.zeros(0, bool)
        at_cell = int(ok.sum())
        if arm_clear is not None:
            others = {q: T for q, T in at.items() if q != part}
            got = [(gr, *arm_clear(part, Tc, gr, others)) for gr, k in zip(up, ok) if k]
            picked = [gr for gr, c, _ in got if c]
            at_clear = len(picked)
            arm_pairs = _pair_counts([pairs for _, _, pairs in got])
            if product.base in at:
                W = np.asarray(at[product.base], float) @ np.linalg.inv(np.asarray(product.parts[product.base].pose,
                                                                                   float))
                built = {**others, **{q: W @ np.asarray(product.parts[q].pose, float) for q in placed}}
                seat = [(gr, *arm_clear(part, W @ P, gr, built)) for gr in picked]
                held = sum(1 for _, c, _ in seat if c)
                seat_pairs = _pair_counts([pairs for _, _, pairs in seat])
                if held == 0:  # could a regrasp on the table serve? the grasps free in any pose, seated
                    known = {gr.label: (c, pairs) for gr, c, pairs in seat}
                    tried = [gr for gr in free if gr.label in pick]
                    anyw = [known.get(gr.label) or arm_clear(part, W @ P, gr, built) for gr in tried]
                    seat_any = sum(1 for c, _ in anyw if c)
                    seat_any_pairs = _pair_counts([pairs or [("no", "IK")] for c, pairs in anyw if not c])
                    if put_down is not None and seat_any > 0:
                        placed_any = len(put_down(part, [gr for gr, (c, _) in zip(tried, anyw) if c]))
    faces = tuple(sorted({str(f) for gr in own for f in gr.gfaces})) if not usable else ()
    return MateGrasps(part, g.parent, name, len(own), len(usable), len(clear), len(pick), reached, at_cell, faces,
                      tuple(sorted(hits)) if not clear else (), len(Ts), tuple(pose_ok), cell_pose, at_clear,
                      tuple(arm_pairs[:PAIRS_SAID]), held, tuple(seat_pairs[:PAIRS_SAID]), seat_any,
                      tuple(seat_any_pairs[:PAIRS_SAID]), placed_any)


def above_table(grasps: list[Grasp], gripper: Any, T_part: np.ndarray, unit: str, margin: float = 0.0
                ) -> list[Grasp]:
    """The grasps whose fingers and palm keep ``margin`` (cell unit) over the table with the part
    at world pose ``T_part`` (world.reach.arcs.hand_above_table)."""
    from spar_py.world.reach import hand_above_table

    return [gr for gr in grasps
            if hand_above_table(gripper, T_part @ np.asarray(gr.T, float), gr.width, unit, margin)]


def _poses(model: Any, sub: Mapping[str, Any]) -> list[np.ndarray]:
    """The stable poses of the part alone on the table (4x4, object to world): its model's own,
    derived or declared, less those that need its subtree mated (``sub``'s labels)."""
    out: list[np.ndarray] = []
    for sp in model.poses.values():
        if sp.label in sub:
            continue
        T = np.eye(4)
        T[:3, :3] = np.asarray(sp.R, float)
        T[2, 3] = float(sp.height)
        out.append(T)
    return out


def _usable(test: Any, gr: Grasp, gripper: Any, product: Product, m: Any, unit: str) -> bool:
    """Whether grasp ``gr`` of peg ``m.peg`` can make mate ``m`` (``test``:
    world.parts.mate_grasp_usable); True when the hole feature has no geometry to judge by."""
    peg, hole = product.parts[m.peg], product.parts[m.hole]
    hf = hole.model.feature_named(m.hole_feature).geometry
    if hf is None or hf.kind != "hole":
        return True
    T_a = np.linalg.inv(np.asarray(hole.pose, float)) @ np.asarray(peg.pose, float)
    return bool(test(np.asarray(gr.T, float), gr.width, gripper, T_a, _mouth(hf, peg.model, m.peg_feature, T_a), unit))


def _mouth(hf: Any, peg_model: Any, peg_feature: str, T_a: np.ndarray) -> Any:
    """The hole feature as the peg enters it: a through hole entered from its far end (the peg's
    direction, turned into the hole's frame by ``T_a``, against the hole's) has its mouth there
    and its direction reversed; otherwise ``hf`` itself."""
    from dataclasses import replace

    pf = peg_model.feature_named(peg_feature).geometry
    if not hf.through or pf is None:
        return hf
    d = np.asarray(T_a, float)[:3, :3] @ np.asarray(pf.direction, float)
    if float(d @ np.asarray(hf.direction, float)) >= 0.0:
        return hf
    return replace(hf, origin=hf.end, direction=-np.asarray(hf.direction, float))


def _said(r: MateGrasps) -> str:
    """The counts, as far as they go: '12 grasps, 4 usable for the mate, 0 clear of ...'."""
    out = [f"{r.grasps} grasps", f"{r.usable} usable for the mate (hand outside the hole when seated)"]
    if r.usable:
        out.append(f"{r.clear} of those clear of the parts in place when seated")
    if r.clear:
        out.append(f"{r.pickup} of those free at pickup in some of its {r.poses} stable poses")
    if r.pickup and r.reached >= 0:
        out.append(f"{r.reached} of those reached by the arm at its spot")
    if r.reached > 0 and r.at_cell >= 0:
        out.append(f"{r.at_cell} at the pose the cell lays it in")
    if r.at_cell > 0 and r.at_clear >= 0:
        out.append(f"{r.at_clear} of those with the arm clear of the world there")
    if r.at_clear > 0 and r.held >= 0:
        out.append(f"{r.held} of those also reached clear seating it")
    return ", ".join(out)


def _needs(r: MateGrasps) -> str:
    """What the part needs, from the first filter that leaves none ('' when some grasp passes all)."""
    if r.usable == 0:
        faces = ", ".join(r.faces[:FACES_SAID]) + (", ..." if len(r.faces) > FACES_SAID else "")
        return (f"grasps on other faces ({r.grasps} grasps, on {faces}: each puts the hand past the mouth of the "
                f"hole when seated)" if r.grasps
                else f"a grasp: the gripper finds none on {r.part}")
    if r.clear == 0:
        return (f"grasps clear of {', '.join(r.hits) or 'the parts in place'} ({r.usable} usable grasps, each "
                f"meets them when {r.part} is seated), or a fixture holding {r.part}")
    if r.pickup == 0:
        return (f"a regrasp or a fixture holding {r.part} (no stable pose of {r.part} offers a grasp usable for "
                f"{r.mate})")
    if r.reached == 0:
        return (f"{r.part} within the arm's reach (no grasp usable for {r.mate} is reached at its spot in any "
                f"stable pose)")
    if r.at_cell == 0:
        other = [p for p in r.pose_ok if p != r.cell_pose]
        where = (f"turned about the vertical or moved (resting {r.cell_pose}, as the cell lays it, the arm reaches "
                 f"none there)" if r.cell_pose in r.pose_ok else
                 f"resting {' or '.join(other[:3])} (resting {r.cell_pose}, as the cell lays it, offers none)")
        return f"{r.part} laid where a grasp usable for {r.mate} is reached: {where}, or a regrasp on the table"
    if r.at_clear == 0:
        return (f"{r.part} laid where the arm reaches a grasp usable for {r.mate} clear of the world (resting "
                f"{r.cell_pose}, as the cell lays it, every arm solution collides: {', '.join(r.arm_pairs)}), "
                f"or a regrasp on the table")
    if r.held == 0:
        how = (f"collide seating it where the cell builds the product: {', '.join(r.seat_pairs)}" if r.seat_pairs
               else "are out of the arm's reach seating it where the cell builds the product")
        if r.seat_any == 0:  # no pose on the table offers a grasp that seats it: a regrasp cannot help
            said = ", ".join(p.replace("no-IK", "out of reach") for p in r.seat_any_pairs)
            return (f"the product built elsewhere, or grasps of {r.part} that seat it clear (none of the "
                    f"{r.pickup} grasps usable for {r.mate} free at pickup in some stable pose is reached clear "
                    f"seating it where the cell builds the product: {said}; so no regrasp on the table helps)")
        if r.placed_any == 0:  # those that seat it are reached after no put-down on the table
            return (f"the product built elsewhere ({r.seat_any} grasps of {r.part} free at pickup in some stable pose "
                    f"seat it clear, but the arm reaches none of them clear of the world after a put-down on the "
                    f"table in a stable pose that leaves it free, so no regrasp on the table helps; the "
                    f"{r.at_clear} grasps usable for {r.mate} the arm reaches where the cell lays {r.part} {how})")
        regrasp = (f"a regrasp of {r.part} on the table ({r.placed_any} of its grasps seat it clear and are reached "
                   f"after a put-down in some stable pose)" if r.placed_any > 0 else
                   f"a regrasp of {r.part} on the table ({r.seat_any} of its grasps free at pickup in some stable "
                   f"pose seat it clear)" if r.seat_any > 0 else f"a regrasp of {r.part} on the table")
        return (f"{regrasp}, or the product built elsewhere (the {r.at_clear} grasps usable "
                f"for {r.mate} the arm reaches where the cell lays {r.part} {how})")
    return ""


def _pair_counts(pairs: list[list[tuple[str, str]]]) -> list[str]:
    """'a-b (n)' for each colliding pair, n the grasps it refused, most often first."""
    counts: dict[str, int] = {}
    for ps in pairs:
        for a, b in ps:
            counts[f"{a}-{b}"] = counts.get(f"{a}-{b}", 0) + 1
    return [f"{k} ({n})" for k, n in sorted(counts.items(), key=lambda kv: (-kv[1], kv[0]))]


def _pose_text(T: np.ndarray) -> str:
    """A pose on the table named by the part's own axis that points down in it: '+z down', else
    the object-frame down vector."""
    d = -np.asarray(T, float)[2, :3]  # world down in the object frame: R^T (0, 0, -1)
    for k, axis in enumerate("xyz"):
        for s in (1.0, -1.0):
            if float(d[k]) * s > math.cos(math.radians(POSE_SAME_DEG)):
                return f"{'+' if s > 0 else '-'}{axis} down"
    return "(" + ", ".join(f"{round(float(x), 2) + 0.0:.2g}" for x in d) + ") down"
