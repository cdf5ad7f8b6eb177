"""The one place that says whether the arm reaches a tool pose: "the arm has an in-limit
joint solution for T, with its wrist above the table top, clear of the world".

Phase 1's reach arcs (arcs.py), the put-down placement search (placement.py) and
phase 2's steps (phase2/arm.py, :func:`arm_at`) all ask here, so the rule is written once. The paper's
condition 2 of a reachable constraint (Sec. 5.2.4) looks at joint limits only; a tool
pose whose wrist (the flange origin) would be under the table top (z = 0), e.g. a
grasp from below, is refused too, so the CMS stays conservative (Sec. 7.1). With the
cell (:func:`reach_clear`; unless the problem file opts out with ``collision: false``,
``Cell.collisions``), an IK solution counts only if the arm, the gripper and the
part in the hand are clear of the table, the obstacles and the parts given, by the
margin (world.collision.scene); a pose whose every solution collides is refused with the
colliding pairs, which the caller's run logs (world.run.RunLog) so a "no plan" can say
which pair stood in the way. Every function here is a pure answer about the cell; the
tables it keeps are its world.run.CellCache's.

Frames and units: ``T`` is ``T_world_tool`` (4x4, or a batch (n, 4, 4)), lengths in the
robot's unit (the cell's); joint vectors in radians, in the robot file's DH zero
convention; world Z up, table top z = 0.
"""
from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from spar_py.core.model import Cell
    from spar_py.world.collision import SceneState
    from spar_py.world.robot import Robot
    from spar_py.world.collision import CellCache

__all__ = ["ArmAt", "Reached", "Refusal", "Requirement", "arm_at", "assembled_touch", "clear_of_world", "ik_rows",
           "pair_text", "reach_clear", "reachable_ignoring_collisions", "requirement_clear", "requirement_clear_each",
           "requirement_clear_ik", "requirement_state", "shape_key", "solutions", "tool_on_table", "tool_refusal",
           "wrist_above_table", "wrist_height"]
#: Bound of the cell cache's table of requirement answers by geometry (:func:`requirement_clear`).
REQUIREMENT_LIMIT = 2048
#: Scene states kept per cell by requirement (:func:`requirement_state`), and by the requirement's
#: geometry (the state a renamed copy's is made from).
STATE_LIMIT = 512


def wrist_height(robot: Robot, T: np.ndarray) -> np.ndarray:
    """(n,): the height above the table top of the flange (wrist) origin for world tool
    poses T (n, 4, 4)."""
    return (np.asarray(T, float) @ robot.tool_inverse())[:, 2, 3]


def wrist_above_table(robot: Robot, T: np.ndarray) -> np.ndarray:
    """(n,) bool: for world tool poses T (n, 4, 4), the flange (wrist) origin lies above z = 0."""
    return wrist_height(robot, T) > 0.0


def reachable_ignoring_collisions(robot: Robot, T: np.ndarray) -> np.ndarray:
    """(n,) bool: the arm reaches each world tool pose of T (n, 4, 4) within its joint
    limits, wrist above the table; one batched IK call (no collision check: :func:`reach_clear`)."""
    T = np.asarray(T, float)
    if not len(T):
        return np.zeros(0, dtype=bool)
    return robot.reachable_mask(T) & wrist_above_table(robot, T)


def solutions(robot: Robot, T: np.ndarray) -> np.ndarray:
    """(k, 6): every in-limit joint vector (rad) reaching world tool pose T (4x4), none
    (k = 0) when the wrist would be under the table."""
    T = np.asarray(T, float)
    if not wrist_above_table(robot, T[None])[0]:
        return np.zeros((0, 6))
    sols = np.asarray(robot.ik(T), float)
    return sols.reshape(-1, 6)


@dataclass(frozen=True)
class Requirement:
    """A tool pose relative to an object lying somewhere: the tool at ``T_O @ X`` (X 4x4, object
    frame). ``held`` None: the object itself is in the hand (a pickup or put-down with a grasp
    whose fingers are ``width`` apart, cell unit); else (name, T_tool_part) of the part in the
    hand being mated onto the object (their contact is allowed)."""

    X: np.ndarray
    held: tuple[str, np.ndarray] | None = None
    width: float | None = None


@dataclass
class Reached:
    """The answer of :func:`reach_clear` for n tool poses: ``ok`` (n,) some in-limit solution
    clear of the world; ``ik`` (n,) some in-limit solution at all (wrist above the table);
    ``pairs`` per pose the colliding pairs of its solutions (empty where ok or no IK)."""

    ok: np.ndarray
    ik: np.ndarray
    pairs: list[list[tuple[str, str]]] = field(default_factory=list)


def reach_clear(cache: CellCache, T: np.ndarray, *, parts: Mapping[str, np.ndarray] | None = None,
                held: tuple[str, np.ndarray] | None = None, grasped: str | None = None,
                attached: Mapping[str, np.ndarray] | None = None, width: float | None = None,
                allow: Iterable[tuple[str, str]] = ()) -> Reached:
    """Which world tool poses T (n, 4, 4) the arm reaches with a solution clear of the world:
    the scene (world.collision.scene.scene_for) with ``parts`` at their world poses, ``held`` in the
    hand, ``grasped`` closing on, ``attached`` parts where the tool is (T_tool_part, the same
    for every row), ``width`` the fingers' opening, ``allow`` the step's own contacts
    (CollisionScene.at). One batched IK call and one batched clearance check."""
    cell = cache.cell
    T = np.asarray(T, float).reshape(-1, 4, 4)
    if not len(T):
        return Reached(np.zeros(0, bool), np.zeros(0, bool), [])
    return clear_of_world(cache, *ik_rows(cell, T), parts=parts, held=held, grasped=grasped, attached=attached,
                          width=width, allow=allow)


def ik_rows(cell: Cell, T: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Every IK branch of tool poses T (n, 4, 4): (Q (n, B, 6) rad, ok (n, B): in limits, wrist
    above the table); one batched call (Robot.ik_batch)."""
    Q, okb = cell.robot.ik_batch(T)
    return Q, okb & wrist_above_table(cell.robot, T)[:, None]


def clear_of_world(cache: CellCache, Q: np.ndarray, okb: np.ndarray, *, parts: Mapping[str, np.ndarray] | None = None,
                   held: tuple[str, np.ndarray] | None = None, grasped: str | None = None,
                   attached: Mapping[str, np.ndarray] | None = None, width: float | None = None,
                   allow: Iterable[tuple[str, str]] = (), state: SceneState | None = None,
                   touch: Iterable[str] = ()) -> Reached:
    """:func:`reach_clear` from the IK branches already solved (:func:`ik_rows`); ``state`` the
    scene state of those arguments when the caller has it already (CollisionScene.at); ``touch``
    the bodies that may touch the table (CollisionScene.at)."""
    cell = cache.cell
    n = len(Q)
    ik = okb.any(axis=1)
    if not cell.collisions:  # the problem file opted out (collision: false): IK alone
        return Reached(ik.copy(), ik, [[] for _ in range(n)])
    rows, cols = np.nonzero(okb)
    if state is None:
        state = cache.scene().at(parts or {}, held, grasped, width=width, allow=allow, attached=attached,
                                 touch=touch)
    clear, why = state.check(Q[rows, cols])
    ok = np.zeros(n, dtype=bool)
    ok[rows[clear]] = True
    pairs: list[list[tuple[str, str]]] = [[] for _ in range(n)]
    for r, c, w in zip(rows.tolist(), clear.tolist(), why):
        if not c and not ok[r] and w is not None and w not in pairs[r]:
            pairs[r].append(w)
    return Reached(ok, ik, pairs)


def requirement_clear(cache: CellCache, obj: str, TO: np.ndarray, req: Requirement | np.ndarray,
                      state: SceneState | None = None,
                      ik: tuple[np.ndarray, np.ndarray] | None = None) -> Reached:
    """:func:`reach_clear` for the tool at ``TO[i] @ X`` for object poses TO (n, 4, 4) of ``obj``
    and one requirement (a :class:`Requirement`, or a bare X: the object in the hand with the
    fingers open); ``state`` its :func:`requirement_state` and ``ik`` the :func:`ik_rows` of
    those tool poses when the caller has them (a batch solved for several requirements)."""
    cell = cache.cell
    req = req if isinstance(req, Requirement) else Requirement(np.asarray(req, float))
    TO = np.asarray(TO, float).reshape(-1, 4, 4)
    T = TO @ np.asarray(req.X, float)
    if not len(T):
        return Reached(np.zeros(0, bool), np.zeros(0, bool), [])
    if not cell.collisions:
        return requirement_clear_ik(cache, obj, req, *(ik if ik is not None else ik_rows(cell, T)))
    # the answer depends on the geometry only (no other part is in this world): renamed copies
    # of one model (generated cells: N identical blocks) asked the same poses share it
    held = req.held[0] if req.held is not None else None
    hand = None if held is None else (shape_key(cache, held), np.round(req.held[1], 12).tobytes())
    width = None if req.width is None else round(float(req.width), 12)
    key = (shape_key(cache, obj), hand, np.round(req.X, 12).tobytes(), width, np.round(TO, 12).tobytes())
    table = cache.table("workspace.requirement", REQUIREMENT_LIMIT)
    names = {obj: "\0obj"} | ({f"held:{held}": "\0held"} if held is not None else {})
    back = {v: k for k, v in names.items()}
    if key in table:
        ok, ik, pairs = table[key]
        return Reached(ok.copy(), ik.copy(), [[tuple(back.get(n, n) for n in p) for p in row] for row in pairs])
    r = requirement_clear_ik(cache, obj, req, *(ik if ik is not None else ik_rows(cell, T)), state=state)
    table[key] = (r.ok.copy(), r.ik.copy(), [[tuple(names.get(n, n) for n in p) for p in row] for row in r.pairs])
    return r


def requirement_clear_each(cache: CellCache, obj: str, TO: np.ndarray, req: Requirement,
                           state: SceneState | None, ik: tuple[np.ndarray, np.ndarray]) -> np.ndarray:
    """(k,) bool: :func:`requirement_clear` of each object pose TO[i] (k, 4, 4) alone, ``ik`` the
    :func:`ik_rows` of TO @ req.X: the same answers and memo entries as k calls with one pose
    each (rows are independent), the poses the memo lacks checked in one batch."""
    cell = cache.cell
    TO = np.asarray(TO, float).reshape(-1, 4, 4)
    Q, okb = ik
    if not cell.collisions:
        return requirement_clear_ik(cache, obj, req, Q, okb).ok.copy()
    held = req.held[0] if req.held is not None else None
    hand = None if held is None else (shape_key(cache, held), np.round(req.held[1], 12).tobytes())
    width = None if req.width is None else round(float(req.width), 12)
    base = (shape_key(cache, obj), hand, np.round(req.X, 12).tobytes(), width)
    keys = [(*base, np.round(TO[i:i + 1], 12).tobytes()) for i in range(len(TO))]
    table = cache.table("workspace.requirement", REQUIREMENT_LIMIT)
    out = np.zeros(len(TO), dtype=bool)
    miss = []
    for i, key in enumerate(keys):
        if key in table:
            out[i] = bool(table[key][0][0])
        else:
            miss.append(i)
    if miss:
        names = {obj: "\0obj"} | ({f"held:{held}": "\0held"} if held is not None else {})
        r = requirement_clear_ik(cache, obj, req, Q[miss], okb[miss], state=state)
        for k, i in enumerate(miss):
            out[i] = bool(r.ok[k])
            table[keys[i]] = (r.ok[k:k + 1].copy(), r.ik[k:k + 1].copy(),
                              [[tuple(names.get(n, n) for n in p) for p in r.pairs[k]]])
    return out


def shape_key(cache: CellCache, obj: str) -> tuple:
    """The collision geometry of ``obj`` (world.collision.scene.CollisionScene.shape_key): equal for
    renamed copies of one model."""
    return cache.scene().shape_key(obj)


def requirement_clear_ik(cache: CellCache, obj: str, req: Requirement, Q: np.ndarray, okb: np.ndarray,
                         state: SceneState | None = None) -> Reached:
    """:func:`requirement_clear` from the IK branches already solved (:func:`ik_rows`)."""
    return clear_of_world(cache, Q, okb, **_requirement_world(obj, req, cache.cell), state=state)


def requirement_state(cache: CellCache, obj: str, req: Requirement) -> SceneState | None:
    """The scene state (CollisionScene.at) of a requirement on ``obj`` (:func:`requirement_clear`'s
    world), or None when the cell has no collision check. Kept in the cell's cache (at most STATE_LIMIT):
    it depends on the requirement only, not on where the object is, so one state serves
    :func:`tool_refusal` and every batch of poses of that requirement, in every stable pose
    (phase 1 asks each grasp's requirement once per pose)."""
    cell = cache.cell
    if not cell.collisions:
        return None
    held = None if req.held is None else (req.held[0], np.round(req.held[1], 12).tobytes())
    width = None if req.width is None else round(float(req.width), 12)
    key = (obj, np.round(req.X, 12).tobytes(), held, width)
    table = cache.table("workspace.requirement_state", STATE_LIMIT)
    state = table.get(key)
    if state is None:
        state = table[key] = _renamed_or_new(cache, obj, req)
    return state


def _renamed_or_new(cache: CellCache, obj: str, req: Requirement) -> SceneState:
    """A new scene state of a requirement on ``obj``: the state of the same requirement on a
    renamed copy of ``obj`` (the same geometry exactly: shape, X, the part in the hand and its
    pose, the width) renamed (SceneState.renamed: the state at() would make, without placing or
    pairing again), else at()'s. Generated cells ask one requirement of each of N copies."""
    scene = cache.scene()
    held = None if req.held is None else req.held[0]
    hand = None if held is None else (scene.shape_key(held), np.ascontiguousarray(req.held[1], float).tobytes())
    width = None if req.width is None else float(req.width)
    key = (scene.shape_key(obj), hand, np.ascontiguousarray(req.X, float).tobytes(), width)
    table = cache.table("workspace.requirement_proto", STATE_LIMIT)
    proto = table.get(key)
    if proto is not None:
        state, p_obj, p_held = proto
        names = {p_obj: obj} | ({} if held is None else {p_held: held, f"held:{p_held}": f"held:{held}"})
        copy = state.renamed({a: b for a, b in names.items() if a != b})
        if copy is not None:
            return copy
    state = scene.at({}, **_requirement_world(obj, req, cache.cell))
    if proto is None:
        table[key] = (state, obj, held)
    return state


def _requirement_world(obj: str, req: Requirement, cell: Cell | None = None) -> dict:
    """The world of a requirement on ``obj`` (CollisionScene.at's arguments): ``obj`` where the
    tool is (T_tool_obj = X^-1), closing on it or, with a part in the hand, in contact with it
    (and, given the ``cell``, with the table where the product seats it so: :func:`assembled_touch`)."""
    inv = np.linalg.inv(np.asarray(req.X, float))
    if req.held is None:
        return {"grasped": obj, "attached": {obj: inv}, "width": req.width}
    return {"held": req.held, "attached": {obj: inv}, "width": req.width,
            "allow": [(f"held:{req.held[0]}", obj)],
            "touch": assembled_touch(cell, [req.held[0]]) if cell is not None else []}


def assembled_touch(cell: Cell, held: Sequence[str]) -> list[str]:
    """The bodies of the ``held`` parts (names) that may touch the table at an assemble
    (CollisionScene.at's ``touch``): in a product's cell, all of them, since the mated pose is
    the product's assembled geometry, which may seat a part flush with the underside of the
    part it goes into (a post through a bar lying on the table), where no margin can be kept;
    none in a cell without a product (its goals' T_a are the user's: a part pressed onto the
    table as it is inserted is refused by the margin)."""
    return [f"held:{n}" for n in held] if getattr(cell, "product", None) is not None else []


def tool_on_table(cache: CellCache, obj: str, T: np.ndarray, req: Requirement) -> tuple[str, str] | None:
    """The body rigid with the tool that meets an unbounded table when the tool is at world pose
    T (4x4) for ``req`` on ``obj`` (the world of :func:`requirement_clear_ik`), or None
    (SceneState.tool_rigid_on_table): a refusal for every pose turned about z or shifted in x, y."""
    cell = cache.cell
    if not cell.collisions or cell.table is not None:
        return None
    state = cache.scene().at({}, **_requirement_world(obj, req, cache.cell))
    return state.tool_rigid_on_table(np.asarray(T, float))


def tool_refusal(cache: CellCache, obj: str, T: np.ndarray, req: Requirement, *, table: bool = True,
                 state: SceneState | None = None) -> tuple[str, str] | None:
    """A pair that refuses ``req`` on ``obj`` at every tool pose of a batch, before any IK, or None:
    the grasp rule or two bodies rigid with the flange closer than the margin
    (SceneState.tool_rigid_refusal: true at every tool pose), and with ``table`` the body
    rigid with the tool that meets an unbounded table at world tool pose T (4x4)
    (:func:`tool_on_table`: true at every pose turned about z or shifted in x, y from T).
    One scene state for both (``state``: the :func:`requirement_state` when the caller has it);
    None without collision checks."""
    cell = cache.cell
    if not cell.collisions:
        return None
    if state is None:
        state = requirement_state(cache, obj, req)
    T = np.asarray(T, float)
    if table and cell.table is None:
        hit = state.tool_rigid_on_table(T)
        if hit is not None:
            return hit
    return state.tool_rigid_refusal(T)


def pair_text(p: Sequence[str]) -> str:
    """A colliding pair as the user reads it (the two fingers are "fingers")."""
    return "-".join("fingers" if n in ("finger_l", "finger_r") else n for n in p)


@dataclass(frozen=True)
class Refusal:
    """``what`` (e.g. "pickup(block, p2G3) at tr1") has joint solutions, every one colliding:
    ``pairs`` the colliding pairs of bodies, in the order found."""

    what: str
    pairs: tuple[tuple[str, str], ...]

    def text(self) -> str:
        """One line: ``no collision-free IK for pickup(block, p2G3): forearm-shelf, fingers-table``."""
        return f"no collision-free IK for {self.what}: {', '.join(dict.fromkeys(pair_text(p) for p in self.pairs))}"


@dataclass
class ArmAt:
    """The answer of :func:`arm_at`: ``q`` the chosen joint vector (rad) or None, ``solutions``
    every in-limit IK solution (k, 6) rad, ``clearance`` (cell unit) and ``closest_pair`` of the
    chosen one (None without a collision check), ``collisions`` the pairs that refused every
    solution (empty unless there were solutions and all collide)."""

    q: np.ndarray | None
    solutions: np.ndarray
    clearance: float | None = None
    closest_pair: tuple[str, str] | None = None
    collisions: list[tuple[str, str]] = field(default_factory=list)


def arm_at(cache: CellCache, T: np.ndarray, ref: np.ndarray | None, *, parts: Mapping[str, np.ndarray],
           held: tuple[str, np.ndarray] | None = None, grasped: str | None = None, width: float | None = None,
           allow: Iterable[tuple[str, str]] = (), carried: Mapping[str, np.ndarray] | None = None,
           touch: Iterable[str] = (), hand_first: bool = False) -> ArmAt:
    """The arm at world tool pose T (4x4) in a world of ``parts`` (key -> T_world_part), ``held``
    in the hand with the parts mated into it ``carried`` (key -> T_tool_part: a subassembly held
    as one body, CollisionScene.at), ``grasped`` being closed on with the fingers ``width`` apart, ``allow`` the
    step's own contacts, ``touch`` the bodies that may touch the table (CollisionScene.at): the
    solution nearest ``ref`` (rad; zeros if None) among those clear of the world (all of them when
    the cell opts out of collision checks), with the reason when there is none (:class:`ArmAt`).
    Phase 2 asks this for every step that moves the arm. ``hand_first``: refuse T before its IK
    when the hand meets a part or obstacle there (SceneState.hand_refusal; then that one pair is
    the reason), for a caller trying many tool poses in a crowded world."""
    cell = cache.cell
    sols = solutions(cell.robot, T)
    ref = np.zeros(6) if ref is None else ref
    if not len(sols):
        return ArmAt(None, sols)
    if not cell.collisions:
        return ArmAt(sols[int(np.argmin(np.abs(sols - ref).sum(axis=1)))], sols)
    state = cache.scene().at(parts, held, grasped, width=width, allow=allow, carried=carried, touch=touch)
    if hand_first:
        hit = state.hand_refusal(T)
        if hit is not None:
            return ArmAt(None, sols, collisions=[hit])
    clear, why = state.check(sols)
    good = sols[clear]
    if not len(good):
        return ArmAt(None, sols, collisions=list(dict.fromkeys(w for w in why if w is not None)))
    q = good[int(np.argmin(np.abs(good - ref).sum(axis=1)))]
    d, names = state.clearance(q[None])
    return ArmAt(q, sols, float(d[0]), tuple(names[0]))
