"""A product's parts laid out on the table for a robot (``spar gen layout``, a problem's
``layout: auto``).

The base part stands at the build spot in its own stable pose (not one that needs its subtree
mated) in which the build makes the most insertions from above (within DOWN_DEG of down, in an
order the precedence allows, before the first that needs a turn); among those the one that
keeps the product frame's down (-z) down (the product built as assembled); every other part
lies in its most probable stable pose of its own (it starts alone: none that needs its subtree
mated; a derived model lists its poses most probable first, so the first one the planner
knows) among those where a grasp its mate can use (the grasp report's filters 1 to 3,
world.product.grasp_report.held_grasps; else world.parts.mate_grasp_usable: the hand outside
the hole's mouth plane when seated) keeps the hand the robot's collision margin (phase 2's)
above the table and comes from above both there and on the assembled product
(FROM_ABOVE_DEG), else among those where one keeps the hand above the table (a parallel gripper cannot turn a part
over between its two poses, so a part lying where only grasps from below would seat it is
never assembled), else its most probable, yaw 0.
The build spot is on the robot base's x axis, at the distance
(PEDESTAL_MM + the product's footprint radius up to the arm's length, in STEP_MM) where the
fewest of the parts' grasps at their assembled poses are out of IK reach (ties: the nearer).
The other parts, largest footprint first, take the free grid point (STEP_MM) nearest the
build spot, turned about the vertical by one of YAWS yaws (yaw 0 first among equally near
spots), where their footprint keeps GAP_MM (room for the open fingers) from every placed
footprint and from the assembled product's, PEDESTAL_MM from the robot's base axis, and some
grasp the part is laid out for (a product's: world.product.grasp_report.held_grasps, the grasp
report's own filters; of those, the ones the arm reaches with its links and hand the margin
over the table seating the part where the product is built, when it has such) keeps the hand
the collision margin over the table there and is within IK reach (workspace.
reachable_ignoring_collisions): the report's "at the pose the cell lays it in"; its chosen
pose first, then the others where such a grasp keeps the hand over the table; where none is
at any free spot, the nearest free spot at yaw 0 within the arm's
length (the planner then says which grasps fail, rather than the layout refusing the cell).
Footprints: the convex hull of the part's mesh vertices turned by the pose, on the table;
two are apart when a separating axis (an edge normal of either) shows the gap (conservative).

Lengths in the cell unit (constants in mm, converted), world frame, table top z = 0.
"""
from __future__ import annotations

from dataclasses import dataclass, replace
import math
from typing import Mapping, Sequence

import numpy as np

from spar_py.core.errors import SparValueError
from spar_py.core.geometry import convex_hull_2d, rotz
from spar_py.core.model import LOOSE_MAX_DEG, ObjectModel, Product, StablePose
from spar_py.core.units import from_mm
from spar_py.world.reach import reachable_ignoring_collisions

__all__ = ["GAP_MM", "PEDESTAL_MM", "STEP_MM", "Layout", "PartPlacement", "apart", "layout_parts", "layout_product",
           "mate_usable_grasps",
           "part_footprint"]

#: Kept between two footprints (mm): the open fingers go down beside a part.
GAP_MM = 50.0
#: No footprint nearer the robot's base axis than this (mm): nearer, the upper arm comes down on the table
#: (a UR5e standing on it; its own cells put parts 457 to 686 mm out).
PEDESTAL_MM = 350.0
#: Spacing of the candidate spots (mm).
STEP_MM = 25.0


@dataclass(frozen=True)
class PartPlacement:
    """A part's initial position: its stable pose's label and T (4x4, world, cell unit)."""

    part: str
    pose: str
    T: np.ndarray


@dataclass(frozen=True)
class Layout:
    """Every part placed (the base first) and the build spot (world xy, cell unit)."""

    placements: tuple[PartPlacement, ...]
    build_spot: tuple[float, float]
    #: A product's grasps each part was laid out for (world.product.grasp_report.held_grasps), or None.
    held: Mapping[str, frozenset[str]] | None = None


def part_footprint(model: ObjectModel, R: np.ndarray) -> np.ndarray:
    """(k, 2) the convex footprint of the part's mesh turned by R (object to world) about the
    object origin, counter-clockwise (cell unit)."""
    from spar_py.world.parts import part_mesh  # trimesh: a layout only

    mesh = part_mesh(model)
    if mesh is None:
        raise SparValueError(f"expected a part with a mesh or shape to lay out: {model.name} has none")
    V = np.asarray(mesh.convex_hull.vertices, float)
    return convex_hull_2d((V @ np.asarray(R, float).T)[:, :2])


def _axes(P: np.ndarray) -> np.ndarray:
    """(k, 2) the unit edge normals of a convex polygon."""
    e = np.roll(P, -1, axis=0) - P
    n = np.column_stack([e[:, 1], -e[:, 0]])
    L = np.linalg.norm(n, axis=1)
    return n[L > 0] / L[L > 0, None]


def apart(P: np.ndarray, t: np.ndarray, Q: np.ndarray, gap: float) -> np.ndarray:
    """(n,) bool: convex polygon P moved by each row of t (n, 2) lies at least ``gap`` from
    convex polygon Q along some edge normal of either (a separating axis: conservative)."""
    t = np.atleast_2d(t)
    A = np.concatenate([_axes(P), _axes(Q)])
    pp, qq = P @ A.T, Q @ A.T                   # (k, m) projections
    pmin, pmax, qmin, qmax = pp.min(0), pp.max(0), qq.min(0), qq.max(0)
    s = t @ A.T                                  # (n, m) shifts along each axis
    return ((s + pmin >= qmax + gap) | (s + pmax <= qmin - gap)).any(axis=1)


#: Yaws (evenly spaced about world z) a lying part is tried in, yaw 0 first.
YAWS = 8
#: Candidate spots whose footprint and reach are tested in one batch (nearest first).
SPOT_BATCH = 64


def _seat_clear(robot, unit: str, margin: float, grasps: Sequence, T_seat: np.ndarray) -> list:
    """Those of ``grasps`` the arm reaches with its links and hand the collision ``margin`` (cell
    unit) over the table holding the part at its seated world pose ``T_seat`` (world.collision.scene's
    scene with no parts: the table check phase 2 makes there; the parts are the planner's)."""
    from spar_py.world.collision import CollisionScene
    from spar_py.world.reach import wrist_above_table

    if not grasps or robot.gripper is None or not getattr(robot, "links", ()):
        return list(grasps)
    T = np.stack([np.asarray(T_seat, float) @ np.asarray(g.T, float) for g in grasps])
    Q, okb = robot.ik_batch(T)
    okb = okb & wrist_above_table(robot, T)[:, None]
    scene = CollisionScene(robot, robot.gripper, {}, (), margin, None, unit)
    ok = np.zeros(len(grasps), bool)
    for w in sorted({g.width for g in grasps}):
        rows = np.asarray([i for i, g in enumerate(grasps) if g.width == w])
        r, c = np.nonzero(okb[rows])
        if len(r):
            clear, _ = scene.at({}, width=w).check(Q[rows][r, c])
            ok[rows[r[clear]]] = True
    return [g for g, k in zip(grasps, ok) if k]


def _spot(robot, model: ObjectModel, pose: StablePose, grasps: Sequence, grid: np.ndarray, o: np.ndarray,
          taken: Sequence[np.ndarray], gap: float, ped: float, arm: float, unit: str, margin: float,
          F0: np.ndarray | None = None):
    """Where a part lies in ``pose``: the free ``grid`` point nearest the build spot (the grid's
    order) and the yaw (YAWS, yaw 0 first) where one of ``grasps`` keeps the hand ``margin`` over
    the table and is reached (IK, wrist above the table), as (rank, yaw index, T, footprint placed) or
    None; and the nearest free spot at yaw 0 as (rank, T, footprint placed) or None. Free: the
    footprint ``gap`` from every ``taken`` one, ``ped`` from the base axis ``o``, within ``arm``."""
    from spar_py.world.product.grasp_report import above_table

    found = nearest = None
    # the hand's height over the table does not change with the yaw or the spot: one test per pose
    up = (above_table(list(grasps), robot.gripper, _placed(np.asarray(pose.R, float), pose.height, np.zeros(2)),
                      unit, margin) if robot.gripper is not None else list(grasps))
    G = np.stack([np.asarray(g.T, float) for g in up]) if up else np.zeros((0, 4, 4))
    for k in range(YAWS):
        R = rotz(2 * math.pi * k / YAWS)[:3, :3] @ np.asarray(pose.R, float)
        F = F0 if (not k and F0 is not None) else part_footprint(model, R)
        fc = (F.min(0) + F.max(0)) / 2
        t = grid - fc                              # the footprint's centre on the grid point
        # the footprint's every vertex PEDESTAL_MM from the base axis (a convex polygon: its nearest point
        # to the axis may be on an edge; the centre's distance less the footprint's radius bounds it)
        rad = float(np.linalg.norm(F - fc, axis=1).max())
        d = np.linalg.norm(grid - o, axis=1)
        cand = np.flatnonzero((d - rad >= ped) & (d + rad <= arm))
        if found is not None:
            cand = cand[cand < found[0]]
        # nearest first, in batches: the footprint tests (the costly part) stop with the first spot found
        for c in range(0, len(cand), SPOT_BATCH):
            ii = cand[c:c + SPOT_BATCH]
            ok = np.ones(len(ii), bool)
            for Q in taken:
                ok &= apart(F, t[ii], Q, gap)
            ii = ii[ok]
            if not len(ii):
                continue
            if not k and nearest is None:
                nearest = (int(ii[0]), _placed(R, pose.height, t[ii[0]]), F + t[ii[0]])
            if not len(G):
                break
            Ts = np.stack([_placed(R, pose.height, t[i]) for i in ii])
            got = reachable_ignoring_collisions(robot, (Ts[:, None] @ G[None]).reshape(-1, 4, 4))
            hit = np.flatnonzero(got.reshape(len(ii), len(G)).any(axis=1))
            if len(hit):
                i = int(ii[hit[0]])
                found = (i, k, Ts[hit[0]], F + t[i])
                break
    return found, nearest


def _grasps_reach(robot, model: ObjectModel, T: np.ndarray) -> int:
    """How many of the part's grasps at world pose T the arm reaches (IK, wrist above the table)."""
    G = np.stack([g.T for g in model.grasps.values()]) if model.grasps else np.zeros((0, 4, 4))
    return int(reachable_ignoring_collisions(robot, T @ G).sum()) if len(G) else 0


#: An insertion points down in a pose when its direction is within this angle of world down (deg):
#: a loose mate stays, the arm inserts from above.
DOWN_DEG = LOOSE_MAX_DEG


def _down_count(R: np.ndarray, insertions: Sequence[tuple[str, np.ndarray, frozenset[str]]]) -> int:
    """How many insertions the build can make from above with the product turned by R (product
    frame to world): made greedily in an order the precedence allows (each ``(part, direction in
    the product frame, the parts it needs first)``), stopping where none ready points down."""
    down = [p for p, d, _ in insertions if -float((R @ d)[2]) >= math.cos(math.radians(DOWN_DEG)) - 1e-9]
    placed: set[str] = set()
    grew = True
    while grew:
        grew = False
        for p, _, needs in insertions:
            if p in down and p not in placed and needs <= placed:
                placed.add(p)
                grew = True
    return len(placed)


def _base_pose(model: ObjectModel, R_prod: np.ndarray | None = None,
               insertions: Sequence[tuple[str, np.ndarray, frozenset[str]]] = ()) -> StablePose:
    """The base's stable pose in which the build makes the most insertions from above
    (:func:`_down_count`; ``R_prod`` the base's orientation in the product frame); among those
    the one that keeps the product frame's -z down (R's third row +z), else the most probable."""
    poses = list(model.poses.values())
    upright = [np.allclose(np.asarray(p.R)[2], [0.0, 0.0, 1.0], atol=1e-6) for p in poses]
    Rb = np.eye(3) if R_prod is None else np.asarray(R_prod, float)[:3, :3]
    counts = [_down_count(np.asarray(p.R, float) @ Rb.T, insertions) if insertions else 0 for p in poses]
    best = max(counts) if counts else 0
    pick = [i for i, c in enumerate(counts) if c == best]
    return poses[next((i for i in pick if upright[i]), pick[0])]


#: A grasp is from above where its approach descends at least this steeply (deg below the
#: horizontal): the wrist stays off the table and off the product.
FROM_ABOVE_DEG = 15.0


def _lying_pose(model: ObjectModel, usable: frozenset[str] | None, gripper, unit: str,
                R_asm: np.ndarray | None = None, margin: float = 0.0) -> StablePose:
    """The stable pose a part other than the base lies in (module docstring): the most probable
    one where some grasp of ``usable`` (None: no preference) keeps ``gripper``'s hand above the
    table and is from above (FROM_ABOVE_DEG) both there and on the assembled product (``R_asm``,
    the part's world orientation when assembled: a grasp made sideways on the table puts the
    wrist on it, one made sideways on the product puts the hand into it); else the most probable
    where one keeps the hand above the table; else the most probable. Above the table: by
    ``margin`` (cell unit, the collision margin phase 2 keeps the hand off it by;
    world.product.grasp_report.above_table, the report's own test)."""
    from spar_py.world.product.grasp_report import above_table

    poses = list(model.poses.values())
    if not (usable and gripper is not None):
        return poses[0]
    down = -math.sin(math.radians(FROM_ABOVE_DEG))
    grasps = [g for label, g in model.grasps.items() if label in usable]
    above = []
    for pose in poses:
        T = _placed(np.asarray(pose.R, float), pose.height, np.zeros(2))
        ok = [np.asarray(g.T, float) for g in above_table(grasps, gripper, T, unit, margin)]
        if R_asm is not None and any((T @ G)[2, 2] <= down and (R_asm @ G[:3, 2])[2] <= down for G in ok):
            return pose
        if ok:
            above.append(pose)
    return above[0] if above else poses[0]


def mate_usable_grasps(product: Product, gripper, unit: str) -> dict[str, frozenset[str]]:
    """Each mated peg part's grasps usable for its mate (world.parts.mate_grasp_usable
    at the product poses; the features' geometry in their parts' frames, cell unit); parts
    without a mate of known geometry are absent."""
    from spar_py.world.parts import mate_grasp_usable  # numpy only

    out: dict[str, frozenset[str]] = {}
    if gripper is None:
        return out
    for m in product.mates:
        peg, hole = product.parts[m.peg], product.parts[m.hole]
        hf = hole.model.feature_named(m.hole_feature).geometry
        if hf is None or hf.kind != "hole":
            continue
        T_a = np.linalg.inv(np.asarray(hole.pose, float)) @ np.asarray(peg.pose, float)
        got = {g.label for g in peg.model.grasps.values()
               if mate_grasp_usable(g.T, g.width, gripper, T_a, hf, unit)}
        out[m.peg] = out.get(m.peg, frozenset()) | frozenset(got)
    return out


def _placed(R: np.ndarray, height: float, xy: np.ndarray) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = R
    T[:2, 3] = xy
    T[2, 3] = height
    return T


def layout_parts(parts: Mapping[str, ObjectModel], poses: Mapping[str, np.ndarray], base: str, robot,
                 unit: str, name: str = "the product",
                 insertions: Sequence[tuple[str, np.ndarray, frozenset[str]]] = (),
                 usable: Mapping[str, frozenset[str]] | None = None, margin: float | None = None) -> Layout:
    """Lay out ``parts`` (name: model; ``poses``: each part's pose in the product frame, 4x4)
    on the table for ``robot`` (module docstring; ``usable``: each part's grasps its mate can
    use, :func:`mate_usable_grasps`; ``margin``: the hand's clearance over the table at pickup,
    cell unit, None: the robot's collision margin, else the default). SparValueError (one line)
    when the assembled product is out of reach at every build spot or a part finds no free spot."""
    from spar_py.world.collision import DEFAULT_MARGIN_MM
    from spar_py.world.product.grasp_report import above_table

    if margin is None:
        margin = robot.margin if getattr(robot, "margin", None) is not None else from_mm(unit, DEFAULT_MARGIN_MM)
    step, gap, ped = (from_mm(unit, v) for v in (STEP_MM, GAP_MM, PEDESTAL_MM))
    arm = float(np.abs(robot.dh[:, 1]).sum() + np.abs(robot.dh[:, 2]).sum() + np.linalg.norm(robot.tool[:3, 3]))
    B = np.asarray(robot.base, float)
    o, ex = B[:2, 3], B[:2, 0] / max(np.linalg.norm(B[:2, 0]), 1e-12)
    bp = _base_pose(parts[base], poses[base], insertions)
    Rb = np.asarray(bp.R, float)
    Pb = np.linalg.inv(poses[base])
    # the assembled product at the base's pose, its footprint about the base's origin
    world_of = {p: Rb @ (Pb @ poses[p])[:3, :3] for p in parts}
    shift = {p: Rb @ (Pb @ poses[p])[:3, 3] for p in parts}
    prod = convex_hull_2d(np.concatenate([part_footprint(parts[p], world_of[p]) + shift[p][:2] for p in parts]))
    c0 = (prod.min(0) + prod.max(0)) / 2
    radius = float(np.linalg.norm(prod - c0, axis=1).max())
    best: tuple[int, float, np.ndarray] | None = None
    for d in np.arange(ped + radius, arm, step):
        xy = o + d * ex - c0
        Tb = _placed(Rb, bp.height, xy)
        counts = [_grasps_reach(robot, parts[p], Tb @ Pb @ poses[p]) for p in parts]
        if min(counts) == 0:
            continue
        missing = sum(len(parts[p].grasps) - c for p, c in zip(parts, counts))
        if best is None or missing < best[0]:
            best = (missing, float(d), xy)
    if best is None:
        raise SparValueError(f"expected {name} within {robot.name}'s reach when assembled in front of it: no build "
                             f"spot from {ped + radius:.0f} to {arm:.0f} {unit} reaches a grasp of every part")
    xy_b = best[2]
    out = [PartPlacement(base, bp.label, _placed(Rb, bp.height, xy_b))]
    taken = [prod + xy_b]
    others = [p for p in parts if p != base]
    # each part laid out for the grasps (its mate's, else all) that also seat it where the product is
    # built with the arm clear of the table, when it has such
    Tb = _placed(Rb, bp.height, xy_b)
    keep: dict[str, frozenset[str]] = {}
    full: dict[str, list] = {}
    for p in others:
        want = (usable or {}).get(p)
        gs = full[p] = [g for label, g in parts[p].grasps.items() if not want or label in want]
        seated = _seat_clear(robot, unit, margin, gs, Tb @ Pb @ poses[p])
        keep[p] = frozenset(g.label for g in (seated or gs)) if (want or seated) else frozenset()
    lying = {p: _lying_pose(parts[p], keep[p] or None, robot.gripper, unit, world_of[p], margin)
             for p in others}
    feet = {p: part_footprint(parts[p], lying[p].R) for p in others}
    others.sort(key=lambda p: -float(np.ptp(feet[p][:, 0]) * np.ptp(feet[p][:, 1])))
    n = int(np.ceil(arm / step))
    g = np.arange(-n, n + 1) * step
    grid = np.stack(np.meshgrid(g, g), axis=-1).reshape(-1, 2) + o
    spot = xy_b + c0
    grid = grid[np.argsort(np.linalg.norm(grid - spot, axis=1), kind="stable")]
    for p in others:
        want = keep[p]
        grasps = [g for label, g in parts[p].grasps.items() if not want or label in want]
        # the pose chosen first, then every other pose where one of those grasps keeps the hand over the table
        rest = [q for q in parts[p].poses.values() if q.label != lying[p].label and robot.gripper is not None
                and above_table(full[p], robot.gripper, _placed(np.asarray(q.R, float), q.height, np.zeros(2)),
                                unit, margin)]
        nearest: tuple[int, np.ndarray, np.ndarray] | None = None      # the nearest free spot, chosen pose, yaw 0
        found: tuple[int, int, np.ndarray, np.ndarray] | None = None
        tries = [grasps]
        if len(grasps) < len(full[p]):  # none of the grasps that seat it clear reached: any it may be held by
            tries.append(full[p])
        for gs in tries:
            for pose in [lying[p], *rest]:
                found, near = _spot(robot, parts[p], pose, gs, grid, o, taken, gap, ped, arm, unit, margin,
                                    feet[p] if pose is lying[p] else None)
                if pose is lying[p]:
                    nearest = near
                if found is not None:
                    break
            if found is not None:
                break
        pose = pose if found is not None else lying[p]
        if found is not None:
            out.append(PartPlacement(p, pose.label, found[2]))
            taken.append(found[3])
        elif nearest is not None:  # no grasp of p reaches at any free spot: lay it at the nearest, the planner says why
            out.append(PartPlacement(p, pose.label, nearest[1]))
            taken.append(nearest[2])
        else:
            F = feet[p]
            raise SparValueError(f"expected room for every part of {name} within {robot.name}'s reach: none for "
                                 f"{p} (footprint {np.ptp(F[:, 0]):.0f} x {np.ptp(F[:, 1]):.0f} {unit}, "
                                 f"{gap:.0f} {unit} apart from the others)")
    return Layout(tuple(out), (float(spot[0]), float(spot[1])))


def layout_product(product: Product, robot, unit: str) -> Layout:
    """:func:`layout_parts` for the parts of a loaded product (cell unit ``unit``), the base
    turned so that the most insertions are made from above (its goals' directions, their
    parents and the precedence first), each other part laid out for the grasps the grasp report
    keeps through its filters 1 to 3 (world.product.grasp_report.held_grasps: usable for its mates, clear
    of the parts in place when seated, outside the part), so the layout and the report agree."""
    needs: dict[str, set[str]] = {g.part: {g.parent} - {product.base} for g in product.goals}
    for pr in product.precedence:
        if pr.then in needs and pr.first != product.base:
            needs[pr.then].add(pr.first)
    insertions = [(g.part, np.asarray(product.parts[g.parent].pose, float)[:3, :3] @ np.asarray(g.V_a, float),
                   frozenset(needs[g.part])) for g in product.goals]
    from spar_py.world.product.grasp_report import held_grasps  # trimesh: a laid-out product only

    # every part starts alone on the table: not in a pose that needs its subtree mated
    models = {p: replace(pp.model, poses={k: v for k, v in pp.model.poses.items()
                                          if k not in product.sub_poses.get(p, {})})
              for p, pp in product.parts.items()}
    held = held_grasps(product, robot.gripper, unit) if robot.gripper is not None else None
    out = layout_parts(models, {p: np.asarray(pp.pose, float) for p, pp in product.parts.items()},
                       product.base, robot, unit, f"product {product.name}", insertions,
                       held if held is not None else mate_usable_grasps(product, robot.gripper, unit))
    return replace(out, held=held)
