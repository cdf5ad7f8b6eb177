"""Phase 1's reach arcs (Sec. 5.2.4): the pairs behind the CMS's reachable / mate_reachable arcs.

Numbers only; Prolog reaches this module through its run (world.run.WorldRun.arc_pairs,
called by ``spar_py.planning.engine.arc_pairs``). Every answer is an :class:`Arc`: the pairs
and the refusals (a pair whose every joint solution collides, and with which pairs), which
the run logs.
For a grasp label G and a position label P the paper checks

1. the faces the fingers touch (G's gfaces) are not the faces P rests on (rfaces); on a part
   whose faces are derived from its geometry, a grasp on a face it rests on still holds where
   both contacts are above the table (a curved face touches the table along a line only);
2. the arm has a joint solution inside its limits for the tool pose T = T_O T_g
   (reachable) or T = T_O T_a T_g (mate_reachable), T_O the position's world
   transform, T_g the grasp's characteristic transform, T_a the assembly transform.

A position label is either a stable pose of the object (``p2P1``: no X, Y, Z, so
condition 2 is assumed satisfiable, as the paper does) or an absolute position of
the cell (``tr1``: its rotation is classified into the object's stable poses to
find its rfaces, Sec. 5.2.3). Every pair needing IK goes into one batched call.
Lengths are in the cell's unit, which is also the unit the robot was loaded in.
"""
from __future__ import annotations

from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from spar_py.core.errors import SparValueError
from spar_py.core.geometry import same_stable_poses
from spar_py.core.model import Cell, Face, Grasp, ObjectModel, natural_key
from spar_py.core.units import from_mm
from spar_py.world.robot import Gripper, gripper_for
from spar_py.world.reach.workspace import Refusal, Requirement, ik_rows, requirement_clear_ik, requirement_state

if TYPE_CHECKING:
    from spar_py.world.collision import CellCache

__all__ = [
    "ARCS",
    "Arc",
    "arc",
    "hand_above_table",
    "mate_reachable_pairs",
    "reachable_pairs",
    "resting_faces",
    "solutions_for",
]


@dataclass
class Arc:
    """An arc's answer: ``pairs`` the [grasp, position] pairs that hold (natural label order),
    ``refusals`` those refused only because every joint solution collides."""

    pairs: list[list[str]]
    refusals: list[Refusal] = field(default_factory=list)


def _sorted_pairs(pairs: Iterable[tuple[str, str]]) -> list[list[str]]:
    pairs = set(pairs)
    keys = {label: natural_key(label) for pair in pairs for label in pair}  # each label's key once
    return [[g, p] for g, p in sorted(pairs, key=lambda gp: (keys[gp[0]], keys[gp[1]]))]


def _object(cell: Cell, obj: str) -> ObjectModel:
    try:
        return cell.objects[obj]
    except KeyError:
        raise SparValueError(f"unknown object {obj!r} (known: {', '.join(sorted(cell.objects))})") from None


def _grasps(model: ObjectModel, labels: Sequence[str]) -> list[Grasp]:
    out = []
    for g in labels:
        if g not in model.grasps:
            raise SparValueError(f"{g!r} is not a grasp of {model.name}")
        out.append(model.grasps[g])
    return out


def _absolute(cell: Cell, model: ObjectModel, label: str) -> np.ndarray | None:
    """T_O of an absolute position label of ``model``'s object, None for a stable-pose label."""
    if label in model.poses:
        return None
    pos = cell.positions.get(label)
    if pos is None:
        raise SparValueError(f"{label!r} is neither a stable pose of {model.name} nor an absolute position")
    if pos.obj != model.name:
        raise SparValueError(f"position {label} ({pos.name}) holds {pos.obj}, not {model.name}")
    return pos.T


def resting_faces(cell: Cell, obj: str, label: str) -> tuple[Face, ...]:
    """The faces ``obj`` rests on at position ``label`` (stable pose or absolute position, Sec. 5.2.3).

    An absolute position is classified by its rotation (``same_stable_pose``); if
    several stable poses match, the union of their rfaces is returned (the
    conservative choice for condition 1). No match raises SparValueError.
    """
    model = _object(cell, obj)
    T = _absolute(cell, model, label)
    if T is None:
        return model.poses[label].rfaces
    faces: list[Face] = []
    poses = list(model.poses.values())
    same = same_stable_poses(T, np.stack([p.R for p in poses])) if poses else []
    for pose, s in zip(poses, same):
        if s:
            faces += [f for f in pose.rfaces if f not in faces]
    if not faces:
        pos = cell.positions[label]
        raise SparValueError(f"position {label} ({pos.name}) of {obj} is in none of its stable poses")
    return tuple(faces)


#: A grasp on a curved face the part rests on still holds where both its contacts are at least
#: this far above the table (mm): condition 1 below.
CONTACT_CLEAR_MM = 1.0


def _part_on_table(model: ObjectModel, label: str, T_O: np.ndarray | None) -> np.ndarray | None:
    """T_world_part (4x4) at position ``label`` (T_O its world transform, None for a stable pose:
    its R and height, X = Y = 0) for a model whose faces, poses and grasps are derived from its
    geometry (consistent with each other); else None."""
    if getattr(model, "geometry", None) is None:
        return None
    if T_O is not None:
        return np.asarray(T_O, float)
    pose = model.poses[label]
    T = np.eye(4)
    T[:3, :3], T[2, 3] = pose.R, pose.height
    return T


def _holds_on_resting_face(cell: Cell, model: ObjectModel, g: Grasp, T_part: np.ndarray | None,
                           gripper: "Gripper") -> bool:
    """Condition 1 for a part whose faces are derived (``T_part``: :func:`_part_on_table`): the
    paper's faces are planar, so a face the part rests on is on the table wherever the fingers
    would touch it; a derived face may be curved (a round or rounded side lying on the table
    touches it along a line), and a grasp on it holds where both its contacts (the tool centre
    +- width/2 along the closing axis) are CONTACT_CLEAR_MM above the table, or, for a mesh part,
    where the whole hand is above it (:func:`_hand_clear`)."""
    if T_part is None:
        return False
    T = np.asarray(g.T, float)
    P = np.stack([T[:3, 3] + s * g.width / 2 * T[:3, 1] for s in (-1.0, 1.0)])
    if (P @ T_part[2, :3] + T_part[2, 3] >= from_mm(cell.unit, CONTACT_CLEAR_MM)).all():
        return True
    return _hand_clear(cell, model, g, T_part, gripper)


#: A gripper body this far below the table plane still counts as above it (mm): rounding.
TABLE_TOL_MM = 0.05


def hand_above_table(gripper: Gripper, T_tool: np.ndarray, width: float, unit: str,
                     clearance: float = 0.0) -> bool:
    """Whether every corner of the fingers (contact faces ``width`` apart) and the palm of
    ``gripper`` at tool pose ``T_tool`` (4x4, world, cell unit) keeps ``clearance`` (cell unit:
    the collision margin phase 2 keeps the hand off the table by) over the table plane z = 0,
    up to TABLE_TOL_MM."""
    C = np.concatenate([np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
                        for _, lo, hi in gripper.boxes(width)])
    M = np.asarray(T_tool, float)
    return bool((C @ M[2, :3] + M[2, 3]).min() >= float(clearance) - from_mm(unit, TABLE_TOL_MM))


def _hand_clear(cell: Cell, model: ObjectModel, g: Grasp, T_part: np.ndarray, gripper: "Gripper") -> bool:
    """Whether grasp ``g`` of a part with a mesh, at world pose ``T_part``, has the whole hand above
    the table (:func:`hand_above_table`). A face a part rests on whole (a planar one) has every
    pad on it at the table and the finger behind the pad below it, so this refuses those as the
    paper's condition 1 does; a curved one (a round touching the table along a rim or a line) is
    closed on where it is clear of the table. False for every other model (the paper's rule)."""
    if model.geometry is None or model.geometry.mesh_file is None:
        return False
    return hand_above_table(gripper, T_part @ np.asarray(g.T, float), g.width, cell.unit)


#: How a stable-pose label (a put-down position with no X, Y) counts for condition 2:
#: "reachable" (some placement in the free regions reaches it) or "paper" (Sec. 5.2.4:
#: "some suitable choice of X, Y, Z" is assumed). Phase 1's placements(Rule) option.
RULES = ("reachable", "paper")


def _check_rule(rule: str) -> None:
    if rule not in RULES:
        raise SparValueError(f"placement rule {rule!r} is not one of {', '.join(RULES)}")


def _somewhere(cache: CellCache, obj: str, asks: list[tuple[str, list[Grasp], list[Requirement]]],
               rule: str) -> list[tuple[str, str]]:
    """The (grasp label, pose) pairs of ``asks`` (stable pose, grasps, their requirements X: tool
    transform in the object frame, and what is in the hand) whose requirement the arm reaches
    clear of the world at some placement of ``obj`` in that pose (placement.some_placement_reaches,
    every pose of the arc at once); all of them under the paper's rule."""
    if rule == "paper":
        return [(g.label, p) for p, grasps, _ in asks for g in grasps]
    from spar_py.world.reach.placement import some_placement_reaches_each  # on first use

    oks = some_placement_reaches_each(cache, obj, [(p, X) for p, _, X in asks])
    return [(g.label, p) for (p, grasps, _), ok in zip(asks, oks) for g, reached in zip(grasps, ok) if reached]


def _clear_pass(cache: CellCache, obj: str, pending: list[tuple[Grasp, str, np.ndarray]],
                requirement: Callable[[Grasp], Requirement], what: Callable[[Grasp, str], str],
                refused: list[Refusal]) -> list[bool]:
    """Which (grasp, position label, T_O) of ``pending`` the arm reaches clear of the world
    (workspace.requirement_clear, one batched call per grasp); a pair with IK solutions that all
    collide is added to ``refused`` with its pairs."""
    cell = cache.cell
    out = [False] * len(pending)
    if not pending:
        return out
    Q, okb = ik_rows(cell, np.stack([T_O @ g.T if requirement(g).held is None else T_O @ requirement(g).X
                                     for g, _, T_O in pending]))
    by_grasp: dict[str, list[int]] = {}
    for i, (g, _, _) in enumerate(pending):
        by_grasp.setdefault(g.label, []).append(i)
    for ix in by_grasp.values():
        g = pending[ix[0]][0]
        req = requirement(g)
        r = requirement_clear_ik(cache, obj, req, Q[ix], okb[ix], state=requirement_state(cache, obj, req))
        for k, i in enumerate(ix):
            out[i] = bool(r.ok[k])
            if r.ik[k] and not r.ok[k]:
                refused.append(Refusal(what(g, pending[i][1]), tuple(tuple(p) for p in r.pairs[k])))
    return out


def reachable_pairs(cache: CellCache, obj: str, grasp_labels: Sequence[str],
                    pos_labels: Sequence[str], rule: str = "reachable") -> Arc:
    """All [grasp, position] pairs satisfying reachable(Grasp, Position) for ``obj`` (Sec. 5.2.4).

    Condition 1 for every pair; condition 2 (IK with T = T_O T_g inside the joint
    limits, and one solution with the arm, the gripper closed on ``obj`` and ``obj`` itself
    clear of the table and the obstacles: workspace.requirement_clear) only for absolute
    positions, and for stable poses as ``rule`` says (RULES). Sorted by natural label order.
    """
    cell = cache.cell
    _check_rule(rule)
    model = _object(cell, obj)
    grasps = _grasps(model, grasp_labels)
    pending: list[tuple[Grasp, str, np.ndarray]] = []
    asks: list[tuple[str, list[Grasp], list[Requirement]]] = []
    for p in pos_labels:
        T_O = _absolute(cell, model, p)
        rfaces = set(resting_faces(cell, obj, p))
        T_part, gripper = _part_on_table(model, p, T_O), gripper_for(cell)
        free = [g for g in grasps if not rfaces & set(g.gfaces)
                or _holds_on_resting_face(cell, model, g, T_part, gripper)]  # condition 1
        if T_O is None:
            asks.append((p, free, [Requirement(g.T, None, g.width) for g in free]))
            continue
        pending += [(g, p, T_O) for g in free]
    pairs = _somewhere(cache, obj, asks, rule)
    refused: list[Refusal] = []
    ok = _clear_pass(cache, obj, pending, lambda g: Requirement(g.T, None, g.width),
                     lambda g, p: f"pickup({obj}, {g.label}) at {p}", refused)
    pairs += [(g.label, p) for (g, p, _), reached in zip(pending, ok) if reached]
    return Arc(_sorted_pairs(pairs), refused)


def mate_reachable_pairs(cache: CellCache, held_obj: str, fixed_obj: str, grasp_labels: Sequence[str],
                         pos_labels: Sequence[str], Ta: np.ndarray | str,
                         rule: str = "reachable") -> Arc:
    """All [grasp, position] pairs satisfying mate_reachable(Grasp, Position, T_a) (Sec. 5.2.4).

    Grasps are of ``held_obj``, positions of ``fixed_obj``; ``Ta`` (4x4, cell unit,
    or the name of a cell transform) is the held object's frame in the fixed
    object's frame once mated. Condition 2 only, with T = T_O T_a T_g and one solution with
    the arm, the gripper and the held object clear of the table, the obstacles and the fixed
    object (the held and the fixed object may touch); a stable-pose label as ``rule`` says (RULES).
    """
    cell = cache.cell
    _check_rule(rule)
    if isinstance(Ta, str):
        if Ta not in cell.transforms:
            raise SparValueError(f"unknown transform {Ta!r}")
        Ta = cell.transforms[Ta]
    Ta = np.asarray(Ta, float)
    if Ta.shape != (4, 4):
        raise SparValueError(f"T_a must be a 4x4 transform, got shape {Ta.shape}")
    grasps = _grasps(_object(cell, held_obj), grasp_labels)
    fixed = _object(cell, fixed_obj)

    reqs = {g.label: Requirement(Ta @ g.T, (held_obj, np.linalg.inv(g.T)), g.width) for g in grasps}

    def req(g: Grasp) -> Requirement:  # one per grasp, whatever the position
        return reqs[g.label]

    pending: list[tuple[Grasp, str, np.ndarray]] = []
    asks: list[tuple[str, list[Grasp], list[Requirement]]] = []
    for p in pos_labels:
        T_O = _absolute(cell, fixed, p)
        if T_O is None:
            asks.append((p, grasps, [req(g) for g in grasps]))
            continue
        pending += [(g, p, T_O) for g in grasps]
    pairs = _somewhere(cache, fixed_obj, asks, rule)
    refused: list[Refusal] = []
    ok = _clear_pass(cache, fixed_obj, pending, req,
                     lambda g, p: f"assemble({held_obj}, {fixed_obj}) with {g.label} at {p}", refused)
    pairs += [(g.label, p) for (g, p, _), reached in zip(pending, ok) if reached]
    return Arc(_sorted_pairs(pairs), refused)


def _arc_reachable(cache: CellCache, objects: Sequence[str], grasps: Sequence[str],
                   positions: Sequence[str], ta: np.ndarray | str | None, rule: str) -> Arc:
    return reachable_pairs(cache, objects[0], grasps, positions, rule)


def _arc_mate(cache: CellCache, objects: Sequence[str], grasps: Sequence[str],
              positions: Sequence[str], ta: np.ndarray | str | None, rule: str) -> Arc:
    if ta is None or len(objects) != 2:
        raise SparValueError("mate_reachable needs objects [held, fixed] and T_a")
    return mate_reachable_pairs(cache, objects[0], objects[1], grasps, positions, ta, rule)


ARCS: dict[str, Callable[..., Arc]] = {
    "reachable": _arc_reachable,
    "mate_reachable": _arc_mate,
}


def arc(cache: CellCache, kind: str, objects: Sequence[str], grasps: Sequence[str],
        positions: Sequence[str], ta: np.ndarray | str | None = None,
        rule: str = "reachable") -> Arc:
    """The pairs of a geometric arc ``kind`` (reachable | mate_reachable); objects [obj] or
    [held, fixed]; ``rule`` for stable-pose labels (RULES)."""
    if kind not in ARCS:
        raise SparValueError(f"unknown geometric constraint {kind!r} (one of {', '.join(ARCS)})")
    return ARCS[kind](cache, objects, grasps, positions, ta, rule)


def solutions_for(cell: Cell, T: np.ndarray) -> list[list[float]]:
    """Every in-limit joint vector (degrees, for display) reaching world tool pose T (4x4, cell unit)."""
    return [[float(v) for v in np.degrees(q)] for q in cell.robot.ik(T)]
