"""Motions between a plan instance's end-points (the paper's Secs. 7.3, 8 leave
gross and fine motion to other planners: this is that planner).

For the chosen plan instance, a joint path from home through every step and back home:

- **approach / retreat** around each pickup, put-down, assemble and squeeze: a straight
  line of the tool (Cartesian interpolation, orientation fixed), of ``approach_length``
  (default 2 in): along the grasp's approach direction (tool z) for pickup, put-down and
  squeeze, along the mating vector V_a for the assemble (the insertion itself); the
  retreat backs off along tool z; a part in the hand leaves and reaches the table
  vertically (the pickup's retreat lifts it straight up, the put-down's approach sets it
  straight down), whatever the grasp's side. IK at every point of the line, each solution the one
  nearest the previous point's (the same branch, no wrist flips: a line whose joint jump
  stays above the resolution after subdivision is refused);
- **transit / transfer** (hand empty / holding a part) between one retreat's end and the
  next approach's start: first the straight joint-space segment, OMPL (RRT-Connect by
  default) only when that is blocked, the solution simplified once (rope shortcut, vertex
  reduction) and checked again at the resolution.

Every waypoint of every segment is clear of the world as it is at that point of the plan
(``collision.SceneState``: parts already moved or assembled, the held part with the
gripper). Consecutive waypoints differ by at most ``resolution`` in every joint, chosen so
that no point of the arm, gripper or held part moves more than the scene's clearance margin
between two waypoints (:func:`resolution`). A segment is not checked waypoint by waypoint
(some 10,000 of them per motion at the paper cell's 0.02 deg): :func:`certify` evaluates
sound lower bounds of every pair's distance at a few waypoints (one batched call per round)
and lets each certify the waypoints within (bound - margin) / rate of it, the rate being how
far the pair can move per joint step (:func:`column_rates`); only where the bound cannot
decide does the scene's own check look at single waypoints, so a segment is accepted exactly
when checking every waypoint would accept it.

Where the held part touches what it rests on (the retreat after a pickup lifts it off its
support, the approach of a put-down sets it down, the assemble's approach inserts it),
the held part is left out of that line's check: it slides along its own contact
direction; arm and gripper are still checked against everything.

Units: lengths in the cell unit, joint angles in radians inside (degrees in the data
for JSON), durations in seconds; world frame, table top z = 0.
"""
from __future__ import annotations

import math
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING, Any, Protocol

import numpy as np

from spar_py.core.errors import SparValueError
from spar_py.core.units import LENGTH_UNITS
from spar_py.world.collision import TOOL, WORLD, bound_columns, clearance_bounds
from spar_py.world.collision import SceneState as Exact
from spar_py.world.motion.options import PLANNERS, MotionFailure, MotionOptions
from spar_py.world.reach import wrist_above_table

if TYPE_CHECKING:
    from spar_py.world.collision import CellCache

__all__ = ["MotionOptions", "Segment", "MotionFailure", "PLANNERS", "resolution", "densify",
           "free_motion", "line_motion", "durations", "DEFAULT_APPROACH_IN"]

#: The default approach / retreat length, inches (converted to the cell's unit).
DEFAULT_APPROACH_IN = 2.0


class SceneState(Protocol):
    """What the motions ask of the world at one point of the plan (world/collision/state.py)."""

    def clear(self, q: np.ndarray) -> np.ndarray: ...

    def clearance(self, q: np.ndarray) -> tuple[np.ndarray, list[tuple[str, str]]]: ...


@dataclass(frozen=True)
class Segment:
    """One motion: ``kind`` transit | transfer | approach | retreat | home; ``waypoints``
    (n, 6) rad, consecutive rows at most the resolution apart in every joint, first and
    last the motion's ends; ``how`` "straight" (the joint-space segment), "cartesian"
    (a tool line) or the OMPL planner's name; ``vertices`` the path's vertices before
    densification; ``length_raw`` / ``length`` its joint-space length (rad, Euclidean)
    before / after simplification; ``time_s`` planning time."""

    kind: str
    waypoints: np.ndarray
    how: str
    vertices: int
    length_raw: float
    length: float
    time_s: float


# ---------------------------------------------------------------------- resolution


def resolution(dh: np.ndarray, tool: np.ndarray, margin: float, extent: float) -> float:
    """The largest joint step (rad) at which no point of the arm, gripper or held part
    moves more than ``margin`` (cell unit) between two checked waypoints.

    A point p moves by at most sum_i |dq_i| r_i(p) when the joints move by dq, r_i(p) its
    distance from joint i's axis; r_i(p) is at most the distance from frame i's origin (on
    axis i) to p, bounded by the link offsets from frame i to the flange (Craig rows
    i+1..6: frame j's origin is sqrt(a_{j-1}^2 + d_j^2) from frame j-1's, a_{j-1} along
    x_{j-1} and d_j along z_j, perpendicular), the tool offset and ``extent`` (the
    gripper's and held part's reach beyond the tool centre, cell unit). So a step of
    ``margin / sum_i R_i`` in every joint keeps every point within the margin."""
    if not margin > 0:
        raise SparValueError(f"clearance margin {margin!r}: expected a positive length")
    off = np.hypot(dh[:, 1], dh[:, 2])
    tail = float(np.linalg.norm(tool[:3, 3])) + float(extent)
    reach = [float(off[i + 1:].sum()) + tail for i in range(6)]
    return margin / sum(reach)


def densify(vertices: np.ndarray, res: float) -> np.ndarray:
    """The polyline through ``vertices`` (m, 6) rad interpolated linearly in joint space so
    that consecutive rows differ by at most ``res`` in every joint; ends kept exactly."""
    v = np.asarray(vertices, float)
    if len(v) < 2:
        return v.copy()
    d = np.diff(v, axis=0)
    k = np.maximum(1, np.ceil(np.abs(d).max(axis=1) / res - 1e-9).astype(int))
    parts = [v[i] + np.outer(np.arange(k[i]) / k[i], d[i]) for i in range(len(d))]
    return np.vstack(parts + [v[-1:]])


def path_length(q: np.ndarray) -> float:
    """Joint-space length (rad) of the polyline q (n, 6)."""
    return float(np.linalg.norm(np.diff(q, axis=0), axis=1).sum()) if len(q) > 1 else 0.0


def blocked(state: SceneState, q: np.ndarray) -> tuple[int, tuple[str, str] | None]:
    """The first row of q (n, 6) that is not clear and its closest pair; (-1, None) if all are."""
    if hasattr(state, "check"):  # collision.SceneState: the first pair closer than the margin, per row
        ok, why = state.check(q)
        ok = np.asarray(ok, bool)
        if ok.all():
            return -1, None
        i = int(np.argmin(ok))
        return i, tuple(why[i]) if why[i] else None
    ok = np.asarray(state.clear(q), bool)
    if ok.all():
        return -1, None
    i = int(np.argmin(ok))
    _, pairs = state.clearance(q[i:i + 1])
    return i, tuple(pairs[0]) if pairs else None


# ---------------------------------------------------------------------- certified segments


def body_reach(dh: np.ndarray, tool: np.ndarray, frame: int, radius: float) -> np.ndarray:
    """(6,) upper bounds (cell unit) of the distance from joint i's axis to any point of a body
    fixed to Craig frame ``frame`` (1..6, 7 the tool) lying within ``radius`` of that frame's
    origin; 0 for the joints that do not move it. Frame i's origin is on axis i, and frame
    m's origin is sqrt(a_{m-1}^2 + d_m^2) from frame m-1's, whatever the joint angles."""
    link = np.hypot(dh[:, 1], dh[:, 2])  # row m-1: frame m's origin from frame m-1's
    f = min(frame, 6)
    tail = float(radius) + (float(np.linalg.norm(tool[:3, 3])) if frame == 7 else 0.0)
    out = np.zeros(6)
    for i in range(1, f + 1):
        out[i - 1] = float(link[i:f].sum()) + tail
    return out


def column_rates(state: Any) -> np.ndarray:
    """(P + T, 6): how fast (cell unit per rad of each joint) each bound column of
    ``collision.clearance_bounds`` can change. For two bodies on frames f1 <= f2 (a part,
    obstacle, the base or the table: frame 0) only joints f1+1..f2 move one relative to the
    other, each moving the f2 body's points by at most their distance from its axis times
    the joint step (:func:`body_reach`); bodies rigid with each other (frame 6 and the tool)
    get 0."""
    robot = state.scene.robot
    cols = bound_columns(state)
    out = np.zeros((len(cols), 6))

    def joint_frame(b: Any) -> int:
        return 0 if b.frame in (WORLD, 0) else min(b.frame, 6)

    for c, (i, j) in enumerate(cols):
        bi = state.bodies[i]
        bj = state.bodies[j] if j >= 0 else None
        fi, fj = joint_frame(bi), 0 if bj is None else joint_frame(bj)
        hi_body = bi if fi >= fj else bj
        lo = min(fi, fj)
        if max(fi, fj) == lo or hi_body is None:
            continue
        a, b, r = hi_body.cap
        rad = max(float(np.linalg.norm(a)), float(np.linalg.norm(b))) + float(r)
        frame = TOOL if hi_body.frame == TOOL else hi_body.frame
        w = body_reach(robot.dh, robot.tool, frame, rad)
        w[:lo] = 0.0
        out[c] = w
    return out


@dataclass
class CertifyMemo:
    """What :func:`certify` learns of one ``collision.SceneState`` and keeps for its next calls on
    that state (one motion's straight segment, OMPL's motion checks, the densified path): the
    bound columns' rates (:func:`column_rates`, (C, 6) cell unit per rad, None until first
    needed) and whether some row was found clear (the grasp rule and the rigid pairs, the same on
    every row, then need no check). Made by the motion that owns the state; never shared
    between states."""

    state: Any
    rates: np.ndarray | None = None
    some_clear: bool = False


def certify(state: Any, w: np.ndarray, memo: CertifyMemo | None = None) -> tuple[int, tuple[str, str] | None]:
    """Is the polyline through waypoints ``w`` (n, 6) rad (consecutive rows at most the
    resolution apart) clear? (-1, None) if so, else a blocked waypoint's index and its pair.

    Every configuration between waypoints k and k' moves each bound column of
    ``collision.clearance_bounds`` by at most |k' - k| times its rate (:func:`column_rates`
    at the largest per-joint step of the polyline), so a waypoint whose bounds exceed the
    margin by d certifies every waypoint (and every configuration of the segments between)
    within d / rate of it. The waypoints are evaluated by bisection of what is not yet
    certified, each round one batched call; a waypoint whose bound does not exceed the margin
    is decided by :meth:`SceneState.check` itself (so the answer is never less strict than
    checking every waypoint). Needs a ``collision.SceneState`` whose hand is empty or holds
    its part (the grasp rule then the same on every row); others: :func:`blocked`. ``memo``
    (of this ``state``) carries what one call learns to the next; None: nothing is kept."""
    if not isinstance(state, Exact) or state.hand is not None and state.hand[1] == "world":
        return blocked(state, w)  # a part being grasped where it lies: the grasp rule varies along w
    w = np.asarray(w, float)
    n = len(w)
    if n == 0:
        return -1, None
    if memo is None:
        memo = CertifyMemo(state)
    elif memo.state is not state:
        raise ValueError("certify: the memo belongs to another scene state")
    if n == 1 or not memo.some_clear:
        # the grasp rule and the rigid pairs are the same on every row: one clear row decides them
        i, pair = blocked(state, w[:1])
        if i >= 0 or n == 1:
            return i, pair
        memo.some_clear = True
    m = float(state.scene.margin)
    if memo.rates is None:
        memo.rates = column_rates(state)
    step = np.abs(np.diff(w, axis=0)).max(axis=0)
    rate = memo.rates @ step  # (C,) cell unit per waypoint index
    rad = np.zeros(n)  # certified radius (waypoint indices) of each evaluated waypoint
    done = np.zeros(n, bool)

    def evaluate(idx: np.ndarray, want: np.ndarray) -> tuple[int, tuple[str, str] | None]:
        lb = clearance_bounds(state, w[idx], rate, want)
        with np.errstate(divide="ignore", invalid="ignore"):
            r = np.where(rate > 0, (lb - m) / rate, np.where(lb > m, np.inf, -1.0)).min(axis=1)
        unsure = r <= 0
        if unsure.any():  # the bound cannot decide: the exact check does
            k, pair = blocked(state, w[idx[unsure]])
            if k >= 0:
                return int(idx[unsure][k]), pair
        rad[idx] = np.maximum(r, 0.0)
        done[idx] = True
        return -1, None

    first = np.unique([0, n // 2, n - 1])
    k, pair = evaluate(first, np.full(len(first), n / 4))
    if k >= 0:
        return k, pair
    while True:
        ev = np.flatnonzero(done)
        left, right = ev[:-1], ev[1:]
        reach_l, reach_r = left + np.floor(rad[left] * 0.999), right - np.floor(rad[right] * 0.999)
        gap = (reach_r - reach_l > 1) & (right - left > 1)
        if not gap.any():
            return -1, None
        lo, hi = np.maximum(reach_l[gap], left[gap]), np.minimum(reach_r[gap], right[gap])
        mid = np.clip(((lo + hi) // 2).astype(int), left[gap] + 1, right[gap] - 1)
        k, pair = evaluate(mid, np.maximum((hi - lo) / 2, 1.0))
        if k >= 0:
            return k, pair


# ---------------------------------------------------------------------- free motions


def free_motion(state: SceneState, a: np.ndarray, b: np.ndarray, limits: np.ndarray, res: float,
                opts: MotionOptions, kind: str, name: str) -> Segment | MotionFailure:
    """A clear joint path from ``a`` to ``b`` (6,) rad within ``limits`` (6, 2) rad: the
    straight segment if it is clear (one batched check), else OMPL's ``opts.planner``
    within ``opts.time_budget_s``, simplified, densified at ``res`` and checked again.
    ``kind`` transit | transfer | home, ``name`` the motion as a failure names it."""
    t0 = time.perf_counter()
    a, b = np.asarray(a, float), np.asarray(b, float)
    for end, q in (("start", a), ("end", b)):
        i, pair = blocked(state, q[None])
        if i >= 0:
            return MotionFailure(name, pair, f"its {end} configuration is not clear")
    memo = CertifyMemo(state)  # this motion's: the straight segment, OMPL's checks, the final path
    line = densify(np.array([a, b]), res)
    i, pair = certify(state, line, memo)
    if i < 0:
        n = path_length(line)
        return Segment(kind, line, "straight", 2, n, n, time.perf_counter() - t0)
    verts, raw = _ompl(state, a, b, limits, res, opts, memo)
    if verts is None:
        return MotionFailure(name, pair, f"{PLANNERS[opts.planner]} found no path within "
                             f"{opts.time_budget_s:g} s (the straight segment is blocked)")
    dense = densify(verts, res)
    j, pair2 = certify(state, dense, memo)
    if j >= 0:  # OMPL's own checks missed a waypoint: never return an unchecked path
        return MotionFailure(name, pair2, "the planner's path is blocked at the checking resolution")
    return Segment(kind, dense, PLANNERS[opts.planner], len(verts), raw, path_length(verts),
                   time.perf_counter() - t0)


def _ompl(state: SceneState, a: np.ndarray, b: np.ndarray, limits: np.ndarray, res: float,
          opts: MotionOptions, memo: CertifyMemo | None = None) -> tuple[np.ndarray | None, float]:
    """OMPL's path (vertices (m, 6) rad, simplified if asked) and its length before
    simplification; (None, 0) when none is found in the budget. States are checked one
    by one, motions by a validator that checks all of a motion's waypoints at ``res`` in
    one batched call (``memo``: the motion's :class:`CertifyMemo` of ``state``)."""
    # OMPL: only a plan with motions loads it (its leak reports change the shutdown: cli.LEAK_REPORTING)
    from ompl import base as ob
    from ompl import geometric as og
    from ompl import util as ou

    ou.setLogLevel(ou.LOG_NONE)
    ou.RNG.setSeed(int(opts.seed) + 1)  # OMPL reads seed 0 as "not set"
    space = ob.RealVectorStateSpace(6)
    bounds = ob.RealVectorBounds(6)
    for j in range(6):
        bounds.setLow(j, float(limits[j, 0]))
        bounds.setHigh(j, float(limits[j, 1]))
    space.setBounds(bounds)
    ss = og.SimpleSetup(space)

    def vec(s: Any) -> np.ndarray:
        return np.array([s[j] for j in range(6)])

    def valid(s: Any) -> bool:
        return bool(state.clear(vec(s)[None])[0])

    class Batched(ob.MotionValidator):
        """A motion's waypoints at the resolution, certified by clearance (:func:`certify`)."""

        def checkMotion(self, s1: Any, s2: Any) -> bool:  # noqa: N802 (OMPL's name)
            return certify(state, densify(np.array([vec(s1), vec(s2)]), res), memo)[0] < 0

    ss.setStateValidityChecker(valid)
    si = ss.getSpaceInformation()
    validator = Batched(si)
    si.setMotionValidator(validator)
    start, goal = space.allocState(), space.allocState()
    for j in range(6):
        start[j], goal[j] = float(a[j]), float(b[j])
    ss.setStartAndGoalStates(start, goal)
    ss.setPlanner(getattr(og, PLANNERS[opts.planner])(si))
    solved = ss.solve(float(opts.time_budget_s))
    if not solved or str(solved) != "Exact solution":
        return None, 0.0
    path = ss.getSolutionPath()
    raw = np.array([vec(path.getState(i)) for i in range(path.getStateCount())])
    if opts.simplify:
        # once, a fixed amount of work (not a time budget, so a seed gives one path): the rope
        # shortcut (pulls the path taut vertex by vertex) then vertex reduction. Against
        # simplifyMax on the paper cell (10 seeds): a third of the time, 13% shorter.
        ps = og.PathSimplifier(si)
        ps.ropeShortcutPath(path)
        ps.reduceVertices(path)
    verts = np.array([vec(path.getState(i)) for i in range(path.getStateCount())])
    verts[0], verts[-1] = a, b
    return verts, path_length(raw)


# ---------------------------------------------------------------------- tool lines


def _nearest(cands: np.ndarray, prev: np.ndarray, limits: np.ndarray) -> np.ndarray | None:
    """Among IK rows ``cands`` (k, 6) rad, each moved by whole turns toward ``prev`` where
    the limits allow, the row nearest ``prev`` (max-joint distance); None if k = 0."""
    if not len(cands):
        return None
    turns = np.round((prev - cands) / (2 * math.pi))
    moved = cands + 2 * math.pi * turns
    inside = np.all((moved >= limits[:, 0] - 1e-9) & (moved <= limits[:, 1] + 1e-9), axis=1)
    c = np.where(inside[:, None], moved, cands)
    return c[int(np.argmin(np.abs(c - prev).max(axis=1)))]


def line_motion(robot: Any, state: SceneState, T_anchor: np.ndarray, q_anchor: np.ndarray,
                direction: np.ndarray, length: float, res: float, margin: float, kind: str,
                name: str, reverse: bool) -> Segment | MotionFailure:
    """A straight tool line from ``T_anchor`` (4x4 world tool pose, where the arm is at
    ``q_anchor``) moving ``length`` (cell unit) along ``direction`` (world, normalised
    here), orientation fixed; returned reversed (ending at the anchor) when ``reverse``
    (an approach). IK at points at most ``margin`` apart, each the solution nearest the
    previous one; an interval whose joint jump exceeds ``res`` is subdivided (up to 6
    times); a jump that does not shrink is a wrist flip or singularity: refused."""
    t0 = time.perf_counter()
    d = np.asarray(direction, float)
    d = d / np.linalg.norm(d)
    n = max(2, int(math.ceil(length / margin)) + 1)
    s = np.linspace(0.0, 1.0, n)
    q = _line_ik(robot, T_anchor, q_anchor, d, length, s)
    if q is None:
        return MotionFailure(name, None, "the tool line leaves the arm's reach or joint limits")
    for _ in range(6):
        jump = np.abs(np.diff(q, axis=0)).max(axis=1)
        if (jump <= res + 1e-12).all():
            break
        k = np.maximum(1, np.ceil(jump / res).astype(int))
        s = _subdivide(s, k)
        q = _line_ik(robot, T_anchor, q_anchor, d, length, s)
        if q is None:
            return MotionFailure(name, None, "the tool line leaves the arm's reach or joint limits")
    else:
        return MotionFailure(name, None, "no continuous IK branch along the tool line (wrist flip or singularity)")
    if reverse:
        q = q[::-1].copy()
    i, pair = certify(state, q)
    if i > 0:  # the first blocked waypoint in the motion's order (a line is a few hundred)
        j, pair_j = blocked(state, q[:i + 1])
        i, pair = (j, pair_j) if j >= 0 else (i, pair)
    if i >= 0:
        return MotionFailure(name, pair, f"the tool line is blocked {length * (s[::-1] if reverse else s)[i]:.3g} "
                             "along it")
    n_len = path_length(q)
    return Segment(kind, q, "cartesian", len(q), n_len, n_len, time.perf_counter() - t0)


def _subdivide(s: np.ndarray, k: np.ndarray) -> np.ndarray:
    """The parameters ``s`` (n,) with interval i cut in ``k[i]`` >= 1 equal parts: the same
    values as ``np.linspace(s[i], s[i + 1], k[i] + 1)[:-1]`` for each, then ``s[-1]`` (linspace's
    own arithmetic, j * step + start, vectorised: one call per interval took a third of a UR16e
    cell's line time)."""
    idx = np.repeat(np.arange(len(k)), k)
    j = (np.arange(len(idx)) - np.repeat(np.cumsum(k) - k, k)).astype(float)
    step = (s[1:] - s[:-1]) / k
    return np.concatenate([j * step[idx] + s[idx], s[-1:]])


def _line_ik(robot: Any, T_anchor: np.ndarray, q_anchor: np.ndarray, d: np.ndarray, length: float,
             s: np.ndarray) -> np.ndarray | None:
    """IK along the line T_anchor + s * length * d (s (n,) from 0), nearest-previous from
    ``q_anchor``; None if some point has no in-limit solution (or the wrist goes under
    the table)."""
    T = np.repeat(np.asarray(T_anchor, float)[None], len(s), axis=0)
    T[:, :3, 3] += np.outer(s * length, d)
    Q, ok = robot.ik_batch(T)
    ok = ok & wrist_above_table(robot, T)[:, None]
    return _walk(Q, ok, np.asarray(q_anchor, float), robot.limits)


def _walk_exact(Q: np.ndarray, ok: np.ndarray, q0: np.ndarray, limits: np.ndarray) -> np.ndarray | None:
    """The nearest-previous walk through IK rows ``Q`` (n, B, 6) rad (``ok`` (n, B) the valid
    ones) from ``q0``, one :func:`_nearest` per point: row 0 is ``q0``, row i the valid row of
    point i nearest row i - 1; None if some point has no valid row."""
    out = np.empty((len(Q), 6))
    prev = out[0] = q0
    for i in range(1, len(Q)):
        q = _nearest(Q[i][ok[i]], prev, limits)
        if q is None:
            return None
        out[i] = prev = q
    return out


def _nearest_rows(Q: np.ndarray, ok: np.ndarray, prev: np.ndarray, limits: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """:func:`_nearest`'s rule at m points at once: for IK rows Q (m, B, 6) (``ok`` (m, B) the
    valid ones) and a previous row per point ``prev`` (m, 6), the index (m,) of the valid row
    nearest it (argmin over all B with the invalid ones at +inf: the first nearest valid row,
    as _nearest over the valid ones finds it) and every row moved by whole turns toward it as
    _nearest moves them (m, B, 6): the same operations element by element, so the same bits."""
    two_pi = 2 * math.pi
    p = prev[:, None, :]
    with np.errstate(invalid="ignore"):
        moved = Q + two_pi * np.round((p - Q) / two_pi)
        inside = np.all((moved >= limits[:, 0] - 1e-9) & (moved <= limits[:, 1] + 1e-9), axis=2)
        c = np.where(inside[..., None], moved, Q)
        dist = np.where(ok, np.abs(c - p).max(axis=2), np.inf)
    return np.argmin(dist, axis=1), c


#: Branch changes along one tool line that :func:`_walk` follows before it walks the rest point by point.
WALK_SWITCHES = 16


def _walk(Q: np.ndarray, ok: np.ndarray, q0: np.ndarray, limits: np.ndarray) -> np.ndarray | None:
    """:func:`_walk_exact`'s result, without its per-point numpy calls (a tool line near a
    singularity has thousands of points, and per-point calls dominated such lines).

    From each point whose row is known, the walk guesses that the next points stay on the same
    branch (the closed forms number their branches consistently), computes their values by
    counting whole turns, and checks the guess against the exact rule at all of them at once
    (:func:`_nearest_rows`: from the previous row as found, the same nearest row, the same
    values bit for bit). It keeps the points up to the first that differs, takes that one's row
    by the exact rule, and goes on from there; after :data:`WALK_SWITCHES` branch changes the
    rest is walked point by point. So the answer is always the exact walk's."""
    n = len(Q)
    if n < 3 or not ok[1:].any(axis=1).all():
        return _walk_exact(Q, ok, q0, limits)
    two_pi = 2 * math.pi
    out = np.empty((n, 6))
    out[0] = q0
    i = 1  # the next point to fill; out[i - 1] is known
    for _ in range(WALK_SWITCHES):
        b, c = _nearest_rows(Q[i:i + 1], ok[i:i + 1], out[i - 1:i], limits)
        out[i] = c[0, b[0]]
        if i == n - 1:
            return out
        raw = Q[i + 1:, b[0]]  # (m, 6) the same branch onwards
        steps = np.round((np.vstack([Q[i, b[0]][None], raw[:-1]]) - raw) / two_pi)
        turns0 = np.round((out[i] - Q[i, b[0]]) / two_pi)
        with np.errstate(invalid="ignore"):
            guess = raw + two_pi * (turns0 + np.cumsum(steps, axis=0))
        prev = np.vstack([out[i][None], guess[:-1]])
        chosen, c = _nearest_rows(Q[i + 1:], ok[i + 1:], prev, limits)
        m = len(raw)
        good = (chosen == b[0]) & np.all(c[np.arange(m), chosen] == guess, axis=1)
        bad = np.flatnonzero(~good)
        if not len(bad):
            out[i + 1:] = guess
            return out
        k = int(bad[0])  # guesses before it are the exact walk's
        out[i + 1:i + 1 + k] = guess[:k]
        i = i + 1 + k
    rest = _walk_exact(Q[i - 1:], ok[i - 1:], out[i - 1], limits)
    if rest is None:
        return None
    out[i - 1:] = rest
    return out


# ---------------------------------------------------------------------- durations


def interval_seconds(q: np.ndarray, velocity: np.ndarray) -> np.ndarray:
    """Seconds of each interval of waypoints q (n, 6) rad at the joint velocity limits
    ``velocity`` (6,) rad/s, each at the pace of its slowest joint (no acceleration phases): (n - 1,)."""
    return (np.abs(np.diff(q, axis=0)) / np.asarray(velocity, float)).max(axis=1)


def durations(q: np.ndarray, velocity: np.ndarray | None) -> float | None:
    """Seconds to run waypoints q (n, 6) rad at the joint velocity limits ``velocity`` (6,)
    rad/s (:func:`interval_seconds` summed); None without limits."""
    if velocity is None or len(q) < 2:
        return None if velocity is None else 0.0
    return float(interval_seconds(q, velocity).sum())


# ---------------------------------------------------------------------- data for JSON


def deg_rows(q: np.ndarray) -> list[list[float]]:
    """Waypoints (n, 6) rad as degrees rounded to 1e-4 deg (JSON)."""
    return np.round(np.degrees(np.asarray(q, float)), 4).tolist()


@dataclass
class StepMotion:
    """The motions of one step: ``path`` the free motion into it (from home or the last
    step's retreat to this step's approach start), ``approach`` and ``retreat`` tool
    lines (None for a step without arm motion), ``joints`` the end-point used (rad)."""

    path: Segment | None = None
    approach: Segment | None = None
    retreat: Segment | None = None
    joints: np.ndarray | None = None

    def segments(self) -> list[Segment]:
        return [s for s in (self.path, self.approach, self.retreat) if s is not None]


@dataclass
class InstanceMotion:
    """Motions of a whole instance: per step (by id), the path home, resolution (rad),
    home (rad), the options used."""

    steps: dict[str, StepMotion]
    home: np.ndarray
    home_path: Segment
    resolution: float
    margin: float
    options: MotionOptions
    velocity: np.ndarray | None = None
    extra: dict[str, Any] = field(default_factory=dict)

    def step_data(self, sid: str) -> dict[str, Any]:
        """``approach``, ``path``, ``retreat`` (degrees) and ``duration_s`` of step ``sid``."""
        m = self.steps.get(sid)
        if m is None:
            return {"approach": None, "path": None, "retreat": None, "duration_s": None}
        out: dict[str, Any] = {k: None if getattr(m, k) is None else deg_rows(getattr(m, k).waypoints)
                               for k in ("approach", "path", "retreat")}
        ds = [durations(s.waypoints, self.velocity) for s in m.segments()]
        out["duration_s"] = None if self.velocity is None else round(sum(x or 0.0 for x in ds), 4)
        return out

    def summary(self) -> dict[str, Any]:
        """The instance's ``motion`` block (docs/json-schema.md)."""
        segs = [s for m in self.steps.values() for s in m.segments()] + [self.home_path]
        free = [s for s in segs if s.kind in ("transit", "transfer", "home")]
        total = None if self.velocity is None else round(sum(durations(s.waypoints, self.velocity) or 0.0
                                                             for s in segs), 4)
        return {"path_resolution_deg": round(math.degrees(self.resolution), 6),
                "clearance_margin": self.margin,
                "home_deg": [round(float(v), 4) for v in np.degrees(self.home)],
                "home_path": deg_rows(self.home_path.waypoints),
                "planner": PLANNERS[self.options.planner], "seed": self.options.seed,
                "time_budget_s": self.options.time_budget_s,
                "approach_length": self.extra.get("approach_length"),
                "duration_s": total,
                "free_motions": len(free),
                "ompl_motions": sum(1 for s in free if s.how not in ("straight",)),
                "length_before_simplification_rad": round(sum(s.length_raw for s in free), 6),
                "length_after_simplification_rad": round(sum(s.length for s in free), 6),
                "planning_s": round(sum(s.time_s for s in segs), 6)}



# ---------------------------------------------------------------------- a whole instance


@dataclass(frozen=True)
class Stop:
    """A step that moves the arm, as the motions see it: ``id``, ``name`` (pickup, putdown,
    assemble, squeeze), ``obj``, ``label`` (the step as text), the tool pose ``T`` (4x4
    world), ``candidates`` (k, 6) rad (phase 2's choice first), the world before and
    after it (``parts`` {key: T_world_part} on the table or assembled, ``held`` (key,
    T_tool_part) or None) and, for an assemble, the insertion direction ``insert``
    (world unit vector, V_a in the world) and the part it goes ``onto``; ``grasped`` the part the
    fingers are on (``obj`` itself, or the carried part a via-grasp holds the body by)."""

    id: str
    name: str
    obj: str
    label: str
    T: np.ndarray
    candidates: np.ndarray
    before: tuple[dict[str, np.ndarray], tuple[str, np.ndarray] | None]
    after: tuple[dict[str, np.ndarray], tuple[str, np.ndarray] | None]
    insert: np.ndarray | None = None
    onto: str | None = None  # the part an assemble inserts into
    grasped: str | None = None

    @property
    def fingers_on(self) -> str:
        """The part the fingers close on: ``grasped``, else ``obj``."""
        return self.grasped or self.obj


#: Bound of the cell cache's table of approach / retreat pairs ("motion.lines").
LINES_LIMIT = 1024


def _world_key(world: tuple[dict[str, np.ndarray], tuple[str, np.ndarray] | None]) -> tuple:
    parts, held = world
    carried = () if held is None or len(held) < 3 else tuple(
        sorted((k, np.asarray(v, float).tobytes()) for k, v in held[2].items()))
    return (tuple(sorted((k, np.asarray(v, float).tobytes()) for k, v in parts.items())),
            None if held is None else (held[0], np.asarray(held[1], float).tobytes(), carried))


def _lines(robot: Any, scene: Any, st: Stop, q: np.ndarray, length: float, res: float,
           margin: float) -> tuple[Segment, Segment] | MotionFailure:
    """Approach and retreat of stop ``st`` with the end-point at ``q``, memoised on the
    scene's memo (the cell cache's "motion.lines"): instances that share a step and its world (and
    runs with another OMPL seed) share its tool lines, which do not depend on the planner."""
    key = (st.name, st.obj, st.grasped, st.onto, np.asarray(st.T, float).tobytes(), np.asarray(q, float).tobytes(),
           None if st.insert is None else np.asarray(st.insert, float).tobytes(), _world_key(st.before),
           _world_key(st.after), float(length), float(res), float(margin), id(robot))
    if getattr(scene, "memo", None) is None:
        return _lines_of(robot, scene, st, q, length, res, margin)
    return scene.memo.table("motion.lines", LINES_LIMIT).get_or_compute(
        key, lambda: _lines_of(robot, scene, st, q, length, res, margin))


def _resting(scene: Any, obj: str, parts: Mapping[str, np.ndarray]) -> list[tuple[str, str]]:
    """The held part's contacts with what it rests on where ``parts`` has it: the table and the
    supports under it (CollisionScene.resting_on)."""
    under = scene.resting_on(obj, parts[obj]) if obj in parts and getattr(scene, "obstacles", ()) else []
    return [(f"held:{obj}", n) for n in ("table", *under)]


def _lines_of(robot: Any, scene: Any, st: Stop, q: np.ndarray, length: float, res: float,
              margin: float) -> tuple[Segment, Segment] | MotionFailure:
    """Approach and retreat of stop ``st`` with the end-point at ``q``. The part in the hand
    may touch what it leaves or reaches along its own line (``allow``): the table as it is
    lifted off (pickup's retreat) or set down (put-down's approach), the hole part as it is
    inserted (the assemble's approach)."""
    z = st.T[:3, 2]
    up = np.array([0.0, 0.0, 1.0])
    (pb, hb), (pa, ha) = st.before, st.after
    r_dir = -z  # the empty hand backs off along its approach
    if st.name == "pickup":
        a_state, a_dir = scene.at(pb, None, grasped=st.fingers_on), z
        r_state, r_dir = _at(scene, pa, ha, allow=_resting(scene, st.obj, pb)), up  # lifted off its support
    elif st.name == "putdown":
        a_state, a_dir = _at(scene, pb, hb, allow=_resting(scene, st.obj, pa)), -up  # set down onto it
        r_state = scene.at(pa, None, grasped=st.fingers_on)
    elif st.name == "assemble":
        a_state, a_dir = _at(scene, pb, hb, allow=[(f"held:{st.obj}", str(st.onto))]), st.insert  # the insertion itself
        r_state = scene.at(pa, None, grasped=st.fingers_on)
    else:  # squeeze: the fingers close on the part where it lies and open again
        a_state = r_state = _at(scene, pb, hb, grasped=st.fingers_on)
        a_dir = z
    app = line_motion(robot, a_state, st.T, q, -np.asarray(a_dir, float), length, res, margin, "approach",
                      f"approach to {st.id} ({st.label})", reverse=True)
    if isinstance(app, MotionFailure):
        return app
    ret = line_motion(robot, r_state, st.T, q, r_dir, length, res, margin, "retreat",
                      f"retreat from {st.id} ({st.label})", reverse=False)
    if isinstance(ret, MotionFailure):
        return ret
    return app, ret


def line_ends(kind: str, X: np.ndarray, up: np.ndarray, length: float,
              insert: np.ndarray | None = None) -> list[np.ndarray]:
    """The far ends of the approach and retreat tool lines (:func:`_lines_of`'s directions)
    of a step whose tool is at ``T_O @ X``, as tool poses relative to the object's frame too:
    ``kind`` pickup, putdown or assemble (onto the object), ``up`` world z in the object's
    frame, ``insert`` (assemble) the insertion direction V_a in it, ``length`` the
    approach length (cell unit). A placement whose line ends the arm cannot reach has no
    motions: phase 2's placements ask for them (phase2.choose_placements)."""
    def moved(v: np.ndarray) -> np.ndarray:  # the tool moved by v (object frame)
        T = np.eye(4)
        T[:3, 3] = v
        return T @ X

    backed = X.copy()  # the tool moved back along its own z (its approach direction)
    backed[:3, 3] -= length * X[:3, 2]
    u = np.asarray(up, float) / np.linalg.norm(up)
    if kind == "pickup":  # approach along tool z; the part lifted straight up off its support
        return [backed, moved(length * u)]
    if kind == "putdown":  # set down from straight above; the empty hand backs off
        return [moved(length * u), backed]
    if kind == "assemble":  # the insertion itself; the empty hand backs off
        v = np.asarray(insert, float)
        return [moved(-length * v / np.linalg.norm(v)), backed]
    raise SparValueError(f"line_ends: no tool lines for {kind!r}")


def plan_stops(robot: Any, scene: Any, stops: Sequence[Stop], home: np.ndarray | None,
               initial: Mapping[str, np.ndarray], res: float, length: float,
               opts: MotionOptions) -> InstanceMotion | MotionFailure:
    """Motions from ``home`` (rad; None: the default, :func:`default_home`) through every
    stop and back. Per stop, its IK candidates in order: the first whose approach and
    retreat exist and whose free motion from the last position is found is used (no
    backtracking into earlier stops). ``initial`` the parts' poses before the first step
    (for the home check); ``length`` the approach length (cell unit)."""
    margin = float(scene.margin)
    start_state = scene.at(dict(initial), None)
    if home is None:
        home = default_home(robot, start_state)
        if home is None and not stops:
            home = robot.limits.mean(axis=1)
    elif blocked(start_state, home[None])[0] >= 0:
        _, pair = blocked(start_state, home[None])
        return MotionFailure("home configuration", pair, "the home configuration is not clear of the initial world")
    out: dict[str, StepMotion] = {}
    prev = home
    for st in stops:
        best: MotionFailure | None = None
        stage = -1
        for q in st.candidates:
            lines = _lines(robot, scene, st, q, length, res, margin)
            if isinstance(lines, MotionFailure):
                if stage < 0:
                    best, stage = lines, 0
                continue
            app, ret = lines
            pb, hb = st.before
            kind = "transfer" if hb is not None else "transit"
            if prev is None:  # home is this first approach's start
                prev = home = app.waypoints[0]
            path = free_motion(_at(scene, pb, hb), prev, app.waypoints[0], robot.limits, res, opts, kind,
                               f"{kind} motion to the approach of {st.id} ({st.label})")
            if isinstance(path, MotionFailure):
                if stage < 1:
                    best, stage = path, 1
                continue
            out[st.id] = StepMotion(path, app, ret, np.asarray(q, float))
            prev = ret.waypoints[-1]
            break
        else:
            fail = best or MotionFailure(f"motion of {st.id} ({st.label})", None, "no joint solution")
            return replace(fail, at=st.id)
    pa, ha = stops[-1].after if stops else (dict(initial), None)
    back = free_motion(_at(scene, pa, ha), prev, home, robot.limits, res, opts,
                       "home", "motion back home") if prev is not None else None
    if isinstance(back, MotionFailure):
        return back
    if back is None:
        back = Segment("home", home[None].copy(), "straight", 1, 0.0, 0.0, 0.0)
    return InstanceMotion(out, np.asarray(home, float), back, res, margin, opts,
                          getattr(robot, "velocity_limits", None), {"approach_length": length})


def default_home(robot: Any, state: SceneState) -> np.ndarray | None:
    """The documented default home: the middle of the joint ranges where that is clear of
    the initial world; else None (then the first approach's start, the first step's IK
    solution lifted clear of the table along its approach, is home)."""
    mid = robot.limits.mean(axis=1)
    return mid if blocked(state, mid[None])[0] < 0 else None


# ---------------------------------------------------------------------- phase 2's call

#: Steps that move the arm to a tool pose (sensing moves nothing).
ARM_STEPS = ("pickup", "putdown", "assemble", "squeeze")
#: Bound of the cell cache's table of instance motions ("motion.runs").
MEMO_LIMIT = 256


def _via(w: Any, obj: str, label: str | None) -> str | None:
    """The carried part a via-grasp ``label`` of ``obj`` holds the body by (the cell's
    product.via), None for the part's own grasps."""
    product = getattr(w.cell, "product", None)
    if product is None or label is None:
        return None
    return product.via.get(obj, {}).get(label)


def _world_parts(w: Any) -> tuple[dict[str, np.ndarray], tuple | None]:
    """A phase-2 world's parts on the table or assembled, and the held body: (key, T_tool_part,
    {carried key: T_tool_part}) of the part the fingers hold and the other parts of its body
    (they move with it: phase2's WorldState.body), or None. The part held is the body's root,
    or for a via-grasp the carried part the fingers are on, at T_tool_part = T_G^-1 T_O^-1 T_V
    (T_G the grasp in the root's frame, T_O, T_V the ideal poses); the root is then carried."""
    parts, held = {}, None
    for k, o in w.unc.objects.items():
        if o.where == "hand":
            T_tool = np.linalg.inv(o.grasp)
            inv_pose = np.linalg.inv(o.pose)
            carried = {c: T_tool @ inv_pose @ np.asarray(w.unc.obj(c).pose, float) for c in w.unc.body(k)[1:]}
            via = _via(w, k, w.grasps.get(k))
            if via is not None and via in carried:
                carried[k] = T_tool
                held = (via, carried.pop(via), carried)
            else:
                held = (k, T_tool, carried)
    body = set() if held is None else {held[0], *held[2]}
    for k, o in w.unc.objects.items():
        if k not in body:
            parts[k] = np.asarray(o.pose, float)
    return parts, held


def _at(scene: Any, parts: Mapping[str, np.ndarray], held: tuple | None, **kw: Any) -> SceneState:
    """``scene.at`` for a world of :func:`_world_parts`: the held part in the hand, the rest of
    its body carried with it (CollisionScene.at's ``carried``). A contact ``allow`` gives a
    carried part (the root, held by a via-grasp) is given to the held part, which at() extends
    to the whole body, as phase 2 checks it."""
    if held is None:
        return scene.at(parts, None, **kw)
    carried = held[2] if len(held) > 2 else None
    if carried:
        kw["carried"] = carried
        names = {f"held:{c}" for c in carried}
        if kw.get("allow"):
            kw["allow"] = [tuple(f"held:{held[0]}" if n in names else n for n in pair) for pair in kw["allow"]]
    return scene.at(parts, (held[0], held[1]), **kw)


def stops_of(cell: Any, steps: Sequence[Mapping[str, Any]], worlds: Sequence[Any],
             records: Sequence[Mapping[str, Any]]) -> list[Stop]:
    """The arm-moving steps of a phase-2 run: ``steps`` as phase2.evaluate takes them,
    ``worlds`` the world before each step and after the last (len(steps) + 1), ``records``
    the run's step records (their geometry: tool pose, joints, IK solutions, degrees)."""
    out = []
    for i, (s, rec) in enumerate(zip(steps, records)):
        geo = rec["geometry"]
        if s["name"] not in ARM_STEPS or geo.get("tool_pose") is None or geo.get("joints_deg") is None:
            continue
        chosen = np.radians(np.asarray(geo["joints_deg"], float))
        sols = np.radians(np.asarray(geo.get("ik_solutions_deg") or [geo["joints_deg"]], float)).reshape(-1, 6)
        order = np.argsort(np.abs(sols - chosen).max(axis=1), kind="stable")
        cands = sols[order]
        if not len(cands) or np.abs(cands[0] - chosen).max() > 1e-6:
            cands = np.vstack([chosen, cands])
        obj = str(s["args"][0])
        insert, onto = None, None
        if s["name"] == "assemble":
            onto = str(s["args"][1])
            hole, va = str(s["args"][1]), cell.vectors[str(s["args"][4])]
            v = worlds[i].unc.obj(hole).pose[:3, :3] @ np.asarray(va, float)
            insert = v / np.linalg.norm(v)
        args = ", ".join(str(a) for a in s["args"][:2])
        label = str(s["args"][1]) if s["name"] in ("pickup", "squeeze") else worlds[i].grasps.get(obj)
        out.append(Stop(str(s["id"]), s["name"], obj, f"{s['name']}({args})", np.asarray(geo["tool_pose"], float),
                        cands, _world_parts(worlds[i]), _world_parts(worlds[i + 1]), insert, onto,
                        _via(worlds[i], obj, label)))
    return out


def extent(cell: Any) -> float:
    """How far the gripper and a held part reach beyond the tool centre (cell unit): half
    the finger opening, or a part's bounding radius plus its grasp offset, the larger."""
    r = cell.finger_separation / 2
    for m in cell.objects.values():
        rad = m.bounding_radius()
        for g in m.grasps.values():
            r = max(r, float(np.linalg.norm(g.T[:3, 3])) + rad)
    return r


def approach_length(cell: Any, opts: MotionOptions) -> float:
    """The approach / retreat length in the cell unit (the option, else 2 in)."""
    if opts.approach_length is not None:
        return float(opts.approach_length)
    return DEFAULT_APPROACH_IN * LENGTH_UNITS["in"] / LENGTH_UNITS[cell.unit]


def run_motions(cache: CellCache, steps: Sequence[Mapping[str, Any]], worlds: Sequence[Any],
                records: list[dict[str, Any]], opts: MotionOptions,
                scene: Any = None) -> tuple[list[dict[str, Any]], InstanceMotion | MotionFailure]:
    """The motions of a phase-2 run that went through (``records`` its step records) and the
    records as they stand with them: each arm step's ``joints_deg`` becomes the IK solution the
    motions use; when no motion exists, the records up to the step whose motion failed, that
    step with a geometric verdict ``motion`` naming the motion and the blocking pair. The
    answer (InstanceMotion or MotionFailure) is kept in the cell's cache by the run's world."""
    cell = cache.cell
    if scene is None:
        scene = cache.scene()
    home = getattr(cell, "home", None)
    key = (worlds[-1].key, opts, None if home is None else np.asarray(home).tobytes(), id(scene))

    def compute() -> InstanceMotion | MotionFailure:
        stops = stops_of(cell, steps, worlds, records)
        res = resolution(cell.robot.dh, cell.robot.tool, float(scene.margin), extent(cell))
        initial, _ = _world_parts(worlds[0])
        return plan_stops(cell.robot, scene, stops, None if home is None else np.asarray(home, float), initial,
                          res, approach_length(cell, opts), opts)

    got = cache.table("motion.runs", MEMO_LIMIT).get_or_compute(key, compute)
    if isinstance(got, MotionFailure):
        at = next((r for r in records if r["id"] == got.at), records[-1])
        at = {**at, "verdicts": list(at["verdicts"]) + [{
            "action": at["id"], "constraint": "motion", "kind": "geometric", "sense": "", "bound": None,
            "threshold": None, "satisfied": False, "tolerance_reached": True, "description": got.text()}]}
        idx = next(i for i, r in enumerate(records) if r["id"] == at["id"])
        return records[:idx] + [at], got
    out = []
    for rec in records:
        m = got.steps.get(rec["id"])
        if m is not None:
            rec = {**rec, "geometry": {**rec["geometry"],
                                       "joints_deg": [round(float(v), 6) for v in np.degrees(m.joints)]}}
        out.append(rec)
    return out, got


def motion_summary(got: InstanceMotion) -> dict[str, Any]:
    """The instance's ``motion`` block as Prolog carries it: :meth:`InstanceMotion.summary`
    without the waypoints (``home_path``; :func:`attach` adds them to the plan)."""
    return {k: v for k, v in got.summary().items() if k != "home_path"}


def attach(got: InstanceMotion, instance: dict[str, Any]) -> None:
    """Put the waypoints of the chosen instance's motions ``got`` into its JSON ``instance`` (in
    place): the waypoints stay in Python while Prolog chooses (they would cost more to carry
    through it than to plan). Every step gains ``approach``, ``path``, ``retreat`` and
    ``duration_s``; the motion block ``home_path``."""
    for st in instance.get("steps", []):
        st.update(got.step_data(st["id"]))
    instance["motion"]["home_path"] = deg_rows(got.home_path.waypoints)
