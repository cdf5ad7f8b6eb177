"""Phase 2's world along a plan instance: geometry (placements, tool poses, joint angles)
and uncertainty (uncertainty.py), evaluated a whole instance at a time.

prolog/uncertainty.pl makes every decision (which remedy, where to insert it, giving up,
verification and recovery) and, through the bridge, calls :func:`evaluate` once per run
of an instance: Python runs the whole step list and returns plain data (dicts, lists,
numbers, strings; no Python objects): each step's verdicts, its geometry, the world at
its end-point (every part's pose, the held part) and where the run stopped (ok, failed
at a step, infeasible at a step). A step is plain data from Prolog: ``{"id":
"action_2", "name": "pickup", "args": ["peg", "p1G11"]}``, the arguments as term data
(foreign.pl's term_data/2: atoms are strings, lists lists, compounds
``{"functor", "args"}``); names: pickup, putdown, assemble, dense_range_scan, squeeze.

Step results are kept in the cell's cache (world.run.CellCache), keyed by everything
that determines the world before the step, so a re-run after a remedy reuses the
prefix it shares with earlier runs, and instances (and later runs of the cell) reuse
each other's prefixes. A kept step keeps its refusals (:attr:`World.refused`), so every
run that meets it again hears why its arm did not reach.

The bounds a sensing action leaves (Fig. 11) come from the problem file's ``sensors``
entry where it has one, else from the sensing rule's bounds that Prolog passes with
the call (kb/templates/spar_sensing.pl's sensing_rule/5, in its own units, converted here by
:func:`sensing_bounds`).

An object may have several initial positions (a stock of identical parts, kb-format.md).
The world then holds one state per part: the part the plan is working with under the
object's name, each other under ``"<object>@<its initial position name>"``. Which part an
action takes comes from the plan: the *sources* of an instance (uncertainty.pl's
instance_sources/2) give, per action id, the label of the position each
``part_location(Obj, Pos)`` precondition was established at (``{"action_2": {"peg": "tr5"}}``).

Units: lengths in the cell unit, angles in radians inside, degrees in the dicts
returned for display; world frame, table top z = 0.
"""
from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING, Any

import casadi as ca
import numpy as np

from spar_py.phase2 import uncertainty as ur
from spar_py.core.errors import SparValueError
from spar_py.core.geometry import same_stable_pose
from spar_py.core.model import LOOSE_MAX_DEG, Bounds, Cell, Grasp, MatingFeature
from spar_py.core.units import ANGLE_UNITS, LENGTH_UNITS, from_mm
from spar_py.world import reach
from spar_py.world.reach import reachable_pairs
from spar_py.world.motion import MotionFailure, MotionOptions
from spar_py.world.collision import CellCache
from spar_py.world.reach import REST_TOL_MM, part_surface, rest_of, rest_of_body, surfaces_of
from spar_py.world.reach import arm_at, assembled_touch, pair_text
from spar_py.phase2.supinf import cached_bounds
from spar_py.phase2.symbolic import Registry, is_symbolic, snap

if TYPE_CHECKING:
    from spar_py.world.motion import InstanceMotion

Step = dict[str, Any]


@dataclass(frozen=True)
class World:
    """The world before a step: uncertainty state, what the hand holds and with which grasp,
    the put-down placements chosen for this instance, the arm's last joint vector."""

    cache: CellCache
    unc: ur.WorldState
    placements: dict[str, reach.Placement | None]
    grasps: dict[str, str] = field(default_factory=dict)  # object -> grasp label while held
    joints: np.ndarray | None = None
    sources: dict[str, dict[str, str]] = field(default_factory=dict)  # step id -> {object: position label}
    active: dict[str, str] = field(default_factory=dict)  # stock object -> initial position name of its active part
    scans: Mapping[str, Bounds] = field(default_factory=dict)  # sensing action -> the bounds it leaves (cell units)
    key: tuple = ()  # what determines this world: the placements' key and the steps so far
    checked: tuple = ()  # (Constraint, satisfied) of every UR precondition checked so far
    complete: bool = True  # False: the last step's verdicts stop at its first unsatisfied one (step's early)
    #: What the step that made this world refused because every joint solution collides:
    #: (what, colliding pairs) each.
    refused: tuple[tuple[str, tuple[tuple[str, str], ...]], ...] = ()

    @property
    def cell(self) -> Cell:
        """The cell this world is of."""
        return self.cache.cell


Refusals = tuple[tuple[str, tuple[tuple[str, str], ...]], ...]


@dataclass
class Evaluation:
    """One run of a plan instance (:func:`evaluate`): ``status`` ok | failed | infeasible, ``at``
    the step id where it stopped (None if ok), ``steps`` the step records, ``refusals`` what
    its steps refused with the colliding pairs (in order), ``motion`` the instance's motions
    (world/motion/paths.py InstanceMotion), or the MotionFailure that made it infeasible, or None."""

    status: str
    at: str | None
    steps: list[dict[str, Any]]
    refusals: list[tuple[str, tuple[tuple[str, str], ...]]] = field(default_factory=list)
    motion: InstanceMotion | MotionFailure | None = None
    #: An infeasible run's :func:`nogood`, or None.
    nogood: dict[str, Any] | None = None


# ---------------------------------------------------------------------- set-up


def new_world(cache: CellCache, steps: list[Step], sources: Sources | None = None,
              sensing: Mapping[str, Bounds] | None = None, motion: MotionOptions | None = None) -> World:
    """The initial world for an instance whose steps (in order) are ``steps``; chooses
    every put-down placement now, knowing the later actions on the object (Sec. 5.2.4).
    ``sources`` says where each action takes its objects from (module doc), step id ->
    {obj: label}; needed only where an object has several initial positions.
    ``sensing``: the bounds each sensing action's rule leaves (cell units,
    :func:`sensing_bounds`); the cell's own ``sensors`` entries take precedence; ``motion``
    the run's motion options (their approach length shapes the placements)."""
    cell = cache.cell
    src = _inherit_sources(steps, {str(k): dict(v) for k, v in (sources or {}).items()})
    key, placements = _placements(cache, steps, src, motion)
    active = _first_parts(cell, steps, src)
    scans = {**(sensing or {}), **{n: sn.leaves for n, sn in cell.sensors.items()}}
    unc = ur.initial_world(cell, Registry(), active=active)
    scan_key = tuple(sorted(scans.items()))
    # the key holds what the world depends on before any step; step() adds each step's own
    # inputs (its placement, its sources), so instances that agree on a prefix share it
    return World(cache, unc, placements, sources=src, active=active, scans=scans,
                 key=(tuple(sorted(active.items())), scan_key))


def sensing_bounds(cell: Cell, rules: Mapping[str, Mapping[str, Any]] | None) -> dict[str, Bounds]:
    """The bounds each sensing rule leaves, in the cell's units: ``rules`` maps a sensing
    action's name to ``{"dx": [lo, hi], "dy": ..., "dz": ..., "dtheta": [lo, hi],
    "units": {"length": "in", "angle": "deg"}}`` (uncertainty.pl's sensing data, from
    kb/templates/spar_sensing.pl's sensing_rule/5, in the units the templates state)."""
    out: dict[str, Bounds] = {}
    for name, r in (rules or {}).items():
        units = r.get("units", {})
        try:
            length = LENGTH_UNITS[str(units["length"])] / LENGTH_UNITS[cell.unit]
            angle = ANGLE_UNITS[str(units["angle"])]
        except KeyError:
            raise SparValueError(f"sensing rule {name}: units must name a length ({', '.join(LENGTH_UNITS)}) "
                                 f"and an angle ({', '.join(ANGLE_UNITS)}), got {units!r}") from None

        def iv(k: str, scale: float) -> tuple[float, float]:
            lo, hi = (float(v) for v in r[k])
            if not lo <= hi:
                raise SparValueError(f"sensing rule {name}: {k} bounds [{lo}, {hi}] are not an interval")
            return lo * scale, hi * scale

        out[str(name)] = Bounds(iv("dx", length), iv("dy", length), iv("dz", length), iv("dtheta", angle))
    return out


Sources = dict[str, dict[str, str]]


def _inherit_sources(steps: list[Step], src: dict[str, dict[str, str]]) -> dict[str, dict[str, str]]:
    """Sensing and squeezes inserted by phase 2 act on the part the next action on their
    object takes: they get that action's source."""
    out = dict(src)
    for i, s in enumerate(steps):
        if s["name"] in ("dense_range_scan", "squeeze") and s["id"] not in out:
            obj = s["args"][0]
            nxt = next((src[t["id"]][obj] for t in steps[i + 1:] if obj in src.get(t["id"], {})), None)
            if nxt is not None:
                out[s["id"]] = {obj: nxt}
    return out


def _stock(cell: Cell) -> dict[str, list]:
    """Objects with several initial positions -> those positions (in the file's order)."""
    by_obj: dict[str, list] = {}
    for p in cell.positions.values():
        by_obj.setdefault(p.obj, []).append(p)
    return {o: ps for o, ps in by_obj.items() if len(ps) > 1}


def _first_parts(cell: Cell, steps: list[Step], src: dict[str, dict[str, str]]) -> dict[str, str]:
    """For each stock object, the initial position name of the part the plan takes first
    (the first position listed if the plan never says)."""
    out = {}
    for obj, ps in _stock(cell).items():
        names = {p.label: p.name for p in ps}
        first = next((names[src[s["id"]][obj]] for s in steps
                      if obj in src.get(s["id"], {}) and src[s["id"]][obj] in names), None)
        out[obj] = first if first is not None else ps[0].name
    return out


#: Bounds of the cell cache's tables (world.run.CellCache): placements per manipulation sequence;
#: step results per world key. Phase 2 re-runs an instance from the start after each
#: remedy it tries, and instances share prefixes; a world is fully determined by its key,
#: so a step's result can be reused (its uncertainty variables stay in the registry they
#: were made in).
MEMO_LIMIT = 4096
#: Entries of the cell cache's table of a squeezed part's reach arc at its position (:func:`_squeeze`).
SQUEEZE_ARCS = 64


def _frozen(d: Any) -> Any:
    """Term data (lists, dicts) as a hashable value."""
    if isinstance(d, list):
        return tuple(_frozen(x) for x in d)
    if isinstance(d, dict):
        return tuple(sorted((str(k), _frozen(v)) for k, v in d.items()))
    return d


def _step_key(s: Step) -> tuple:
    return (s["id"], s["name"], _frozen(list(s["args"])))


def _placements(cache: CellCache, steps: list[Step], src: dict[str, dict[str, str]],
                motion: MotionOptions | None) -> tuple[tuple, dict[str, reach.Placement | None]]:
    """choose_placements memoised per cell, manipulation sequence (sensing moves nothing),
    the parts those manipulations take and the motions' approach length (None without them)."""
    manip = [s for s in steps if s["name"] in ("pickup", "putdown", "assemble")]
    length = _approach_length(cache.cell, motion)
    key = (tuple(_step_key(s) for s in manip), tuple(sorted((k, tuple(sorted(v.items()))) for k, v in src.items())),
           length)
    memo = cache.table("phase2.placements", MEMO_LIMIT)
    return key, memo.get_or_compute(key, lambda: choose_placements(cache, manip, src, length))


def _approach_length(cell: Cell, motion: MotionOptions | None) -> float | None:
    """The motions' approach length (cell unit; world/motion.approach_length), None without motions."""
    if motion is None:
        return None
    from spar_py.world.motion import approach_length  # motion.py is some 2 ms of a cold start

    return approach_length(cell, motion)


def _grasp(cell: Cell, obj: str, label: str) -> Grasp:
    try:
        return cell.objects[obj].grasps[label]
    except KeyError:
        raise SparValueError(f"{label!r} is not a grasp of {obj!r}") from None


def choose_placements(cache: CellCache, steps: list[Step], sources: dict[str, dict[str, str]] | None = None,
                      length: float | None = None) -> dict[str, reach.Placement | None]:
    """For each putdown into a stable pose, the placement nearest the object's previous spot
    at which the arm reaches the put-down grasp and every later grasp and mate on the object
    until it is picked up again, clear of every part on the table; None where no placement
    in the free regions works. ``sources`` (see :func:`new_world`) says which part of a
    stock a pickup takes; ``length`` the motions' approach length (cell unit), None without
    motions (with motions, each put-down's tool lines must be reachable too)."""
    cell = cache.cell
    src = sources or {}
    # parts on the table: initial position name or putdown id -> (object, pose)
    on_table: dict[str, tuple[str, np.ndarray]] = {p.name: (p.obj, p.T) for p in cell.positions.values()}
    last: dict[str, np.ndarray] = {}  # object -> where the part in the hand was picked from
    held: dict[str, str] = {}
    out: dict[str, reach.Placement | None] = {}
    for i, s in enumerate(steps):
        name, args = s["name"], s["args"]
        if name == "pickup":
            held[args[0]] = args[1]
            k = _taken(cell, on_table, args[0], src.get(s["id"], {}).get(args[0]))
            if k is not None:
                last[args[0]] = on_table.pop(k)[1]
        elif name == "putdown":
            obj, pos = args[0], args[1]
            prev = last.pop(obj, None)
            if pos in cell.positions:
                T = cell.positions[pos].T
                out[s["id"]] = reach.Placement(obj, cell.positions[pos].label, *T[:3, 3], 0.0, T)
            else:
                uses = [("putdown", _grasp(cell, obj, held[obj]).T, None),
                        *_later_requirements(cell, steps[i + 1:], obj, held)]
                occupied = [reach.occupant(cache, o, T) for o, T in on_table.values()]
                near = prev[:2, 3] if prev is not None else None
                tops = _part_tops(cell, on_table, occupied, obj, steps, i)
                out[s["id"]] = reach.choose(cache, obj, pos, [X for _, X, _ in uses], occupied, near,
                                         reach=[] if length is None else _line_ends(cell, obj, pos, uses, length),
                                         tops=tops)
            held.pop(obj, None)
            if out[s["id"]] is not None:
                on_table[s["id"]] = (obj, out[s["id"]].T)
        elif name == "assemble":
            held.pop(args[0], None)
    return out


def _part_tops(cell: Cell, on_table: dict[str, tuple[str, np.ndarray]], occupied: list[reach.Occupant],
               obj: str, steps: list[Step], i: int) -> list[reach.Level]:
    """The tops of the parts on the table a put-down of ``obj`` at step ``i`` may go onto
    (placement.part_level): parts with a shape, not of ``obj``, not of a stock (a part's top is
    named by its object), that no step after ``i`` picks up and no step of the plan mates
    anything into (so the top stays where it is, bare of carried parts, while ``obj`` rests there
    until it is moved again). ``occupied``: the occupants of ``on_table``, in its order."""
    stock = _stock(cell)
    later = {s["args"][0] for s in steps[i + 1:] if s["name"] == "pickup"}
    mated = {s["args"][1] for s in steps if s["name"] == "assemble"}
    tol = from_mm(cell.unit, REST_TOL_MM)
    out = []
    for k, (o, T) in enumerate(on_table.values()):
        model = cell.objects[o]
        if o == obj or o in stock or o in later or o in mated or not model.shape:
            continue
        top = part_surface(o, model, T, tol)
        if len(top.polygon) >= 3:
            out.append(reach.part_level(o, top.polygon, top.z, occupied[:k] + occupied[k + 1:]))
    return out


def _lies_at(cell: Cell, obj: str, label: str, T: np.ndarray) -> bool:
    """A part of ``obj`` with pose ``T`` lies at position ``label``: at that initial
    position (an absolute label), or in that stable pose (a pose label)."""
    if label in cell.positions:
        return bool(np.allclose(T, cell.positions[label].T, atol=1e-9))
    if label in cell.objects[obj].poses:
        return same_stable_pose(T[:3, :3], cell.objects[obj].poses[label].R)
    return False


def _taken(cell: Cell, on_table: dict[str, tuple[str, np.ndarray]], obj: str, label: str | None) -> str | None:
    """The key in ``on_table`` of the part of ``obj`` a pickup from ``label`` takes: the
    part lying there, the one put down last first; else the one put down last, else the
    first part of ``obj``."""
    keys = [k for k, (o, _) in on_table.items() if o == obj]
    if label is not None:
        fit = [k for k in keys if _lies_at(cell, obj, label, on_table[k][1])]
        keys = fit or keys
    initial = {p.name for p in cell.positions.values()}
    placed = [k for k in keys if k not in initial]
    if placed:
        return placed[-1]
    return keys[0] if keys else None


def _later_requirements(cell: Cell, rest: list[Step], obj: str,
                        held: dict[str, str]) -> list[tuple[str, np.ndarray, np.ndarray | None]]:
    """What later steps need of ``obj`` while it stays put: (step name, the tool transform
    relative to ``obj``'s frame, for an assemble onto it the insertion direction V_a in it)."""
    reqs: list[tuple[str, np.ndarray, np.ndarray | None]] = []
    grasps = dict(held)
    for s in rest:
        name, args = s["name"], s["args"]
        if name == "pickup":
            grasps[args[0]] = args[1]
            if args[0] == obj:
                reqs.append(("pickup", _grasp(cell, obj, args[1]).T, None))
                break
        elif name == "assemble" and args[1] == obj and args[0] in grasps:
            reqs.append(("assemble", cell.transforms[args[3]] @ _grasp(cell, args[0], grasps[args[0]]).T,
                         np.asarray(cell.vectors[args[4]], float)))
    return reqs


def _line_ends(cell: Cell, obj: str, pose: str, uses: list[tuple[str, np.ndarray, np.ndarray | None]],
               length: float) -> list[np.ndarray]:
    """The far ends of the approach and retreat lines of each use of ``obj`` put down in stable
    pose ``pose`` (world/motion/paths.py's line_ends), relative to its frame: world z in that frame
    is the same at every placement of the pose (they differ by a turn about world z)."""
    from spar_py.world.motion import line_ends  # motion.py is some 2 ms of a cold start

    up = cell.objects[obj].poses[pose].R.T @ np.array([0.0, 0.0, 1.0])
    return [T for kind, X, v in uses for T in line_ends(kind, X, up, length, v)]


# ---------------------------------------------------------------------- one step


def step(world: World, s: Step, early: bool = False) -> tuple[list[dict[str, Any]], World, dict[str, Any]]:
    """The verdicts of step ``s``'s preconditions in ``world``, the world after it, and its
    geometry for display (tool pose, joint angles in degrees, placement).

    ``early``: the caller stops at this step if one of its uncertainty-reduction
    preconditions fails (:func:`evaluate` unless the step is given up), so its verdicts
    may end at the first unsatisfied one (in order): the run's outcome is the same and
    the rest are never bounded. A memoised step so cut short is computed again, whole,
    when a later run needs every verdict (the step given up)."""
    handler = STEPS.get(s["name"])
    if handler is None:
        raise SparValueError(f"phase 2 cannot execute {s['name']!r}")
    place = world.placements.get(s["id"]) if s["name"] == "putdown" else None
    key = world.key + ((_step_key(s), _frozen(world.sources.get(s["id"], {})),
                        None if place is None else (place.pose, place.T.tobytes())),)

    def run() -> tuple[list[dict[str, Any]], World, dict[str, Any], bool]:
        before = replace(_activate(world, s), refused=())
        checks, after, geo = handler(before, s, early)
        if s["id"] in world.sources:
            geo["source"] = dict(world.sources[s["id"]])
        geo["moves"] = moves(before, s)
        return checks, replace(after, key=key), geo, not (early and not after.complete)

    table = world.cache.table("phase2.steps", MEMO_LIMIT)
    hit = table.get(key)
    if hit is None or not (early or hit[3]):
        hit = table[key] = run()
    checks, after, geo, _ = hit
    # a world from the memo may come from another instance: keep this instance's plan data
    return checks, replace(after, placements=world.placements, sources=world.sources, complete=True), geo


def moves(world: World, s: Step) -> list[str]:
    """The parts step ``s`` moves in ``world`` (the world before it): the body of its object (the
    object, then every part mated into it, directly or transitively); none for a sensing step."""
    if s["name"] not in ("pickup", "putdown", "assemble", "squeeze"):
        return []
    obj = str(s["args"][0])
    return world.unc.body(obj) if obj in world.unc.objects else [obj]


def poses(world: World, seen: dict[int, tuple[ur.ObjectState, list[list[float]]]] | None = None
          ) -> dict[str, list[list[float]]]:
    """Every part's ideal 4x4 world pose (cell unit) in ``world``, keyed by object name or
    ``"<object>@<initial position name>"`` for the other parts of a stock. A held part's
    pose is where it was grasped, an assembled one's where it was inserted.

    ``seen`` (one run's, by the state's id; the state is kept with its rows so the id
    stays its own) reuses the rows of a part whose state a step left as it was: a step
    moves one part, so a run of n steps over m parts rounds n poses, not n * m."""
    if seen is None:
        return {k: np.round(o.pose, 9).tolist() for k, o in sorted(world.unc.objects.items())}
    out = {}
    for k, o in sorted(world.unc.objects.items()):
        hit = seen.get(id(o))
        if hit is None or hit[0] is not o:
            hit = seen[id(o)] = (o, np.round(o.pose, 9).tolist())
        out[k] = hit[1]
    return out


#: Entries of the cell cache's table of parts' position bounds (:func:`position_bounds`), one
#: per error structure and variables' bounds.
BOUNDS_LIMIT = 4096


def _displacement(o: ur.ObjectState) -> list[Any]:
    """Part ``o``'s error as four expressions in its error variables: the displacement of its
    origin from the ideal one along world x, y, z (cell unit) and its turn about world z (rad).

    On the table (Eq. 2, ``trans(d) Tr_O rotz(theta) R_O``) the origin moves by ``d`` and turns
    by ``theta``. Held or assembled (Eq. 4, ``T_O T_G E T_G^-1`` with ``E = trans(t_E) rotz(theta)``)
    the origin, at ``p = -R_G^T t_G`` in the tool frame, goes to ``E p``: it moves by
    ``R_M ((rotz(theta) - I) p + t_E)`` with ``R_M = R_O R_G`` (the constant parts cancel
    exactly), and it turns by ``theta`` about the tool z axis, whose world-z component
    ``R_M[2, 2]`` times ``theta`` is the rotation vector's z component (as a put-down maps
    it, Sec. 3.2.3)."""
    e = o.error
    if o.where == ur.TABLE:
        return [e.dx, e.dy, e.dz, e.theta]
    G = snap(np.asarray(o.grasp, float))
    R_M = snap(o.pose[:3, :3] @ G[:3, :3])
    p = [float(v) for v in -G[:3, :3].T @ G[:3, 3]]
    c, s = ca.cos(e.theta) - 1.0, ca.sin(e.theta)
    local = [c * p[0] - s * p[1] + e.dx, s * p[0] + c * p[1] + e.dy, e.dz]  # (rotz(theta) - I) p + t_E
    world = [sum((float(R_M[i, j]) * local[j] for j in range(3) if R_M[i, j] != 0.0), ca.SX(0.0))
             for i in range(3)]
    return [*world, float(R_M[2, 2]) * e.theta]


def _degrees(lo: float, hi: float) -> list[float]:
    """[lo, hi] rad in degrees, each nonzero end moved two floats outwards (the product's
    rounding), so the interval in degrees holds the one in radians."""
    out = []
    for x, way in ((lo, -math.inf), (hi, math.inf)):
        d = math.degrees(x)
        if d != 0.0:
            d = math.nextafter(math.nextafter(d, way), way)
        out.append(d)
    return out


def _part_bounds(cache: CellCache, reg: Registry, o: ur.ObjectState) -> tuple[tuple[float, float], ...]:
    """SUP/INF of :func:`_displacement` over the error variables' registry box: four
    (lo, hi), sound (lo <= min, hi >= max). Kept in the cell cache by the error's structure
    (ErrorTm.shape), the numbers the expressions use and the variables' bounds: parts alike
    in how their error came about are bounded once."""
    vs = o.error.vars
    key = None
    if o.error.shape and len({v.element_hash() for v in vs}) == len(vs):
        R = snap(o.pose[:3, :3])
        G = None if o.grasp is None else snap(np.asarray(o.grasp, float)).tobytes()
        key = (o.where, R.tobytes(), G, o.error.shape, tuple(reg.bounds(v.name()) for v in vs))
        hit = cache.table("phase2.position_bounds", BOUNDS_LIMIT).get(key)
        if hit is not None:
            return hit

    def bound(e: Any) -> tuple[float, float]:
        if not is_symbolic(e):
            return float(e), float(e)
        if isinstance(e, ca.SX) and e.is_symbolic():  # one variable (a fresh error): its own bounds, exactly
            return reg.bounds(e.name())
        r = cached_bounds(e, reg.box(e), cache.memo, want="both")
        return float(r.lo), float(r.hi)

    got = tuple(bound(e) for e in _displacement(o))
    if key is not None:
        cache.table("phase2.position_bounds", BOUNDS_LIMIT)[key] = got
    return got


def position_bounds(cache: CellCache, world: World,
                    seen: dict[int, tuple[ur.ObjectState, dict[str, list[float]]]] | None = None
                    ) -> dict[str, dict[str, list[float]]]:
    """Every part's position uncertainty in ``world`` as phase 2 propagated it (the parts keyed
    as :func:`poses`): ``{"dx", "dy", "dz": [lo, hi]}`` the displacement of its origin from its
    ideal pose along the world axes (cell unit) and ``"dtheta_deg": [lo, hi]`` its rotation
    about world z (degrees; :func:`_displacement`: a part held by a side grasp turns about a
    level axis, not about z), each SUP/INF's sound bound (not rounded: a sensor's bounds
    are given exactly). After a sensing step a part has the sensor's bounds, held the
    grasp's, after a put-down or a squeeze what the hand left. ``seen`` as :func:`poses` (a
    step changes one part's state)."""
    reg = world.unc.registry
    out = {}
    for k, o in sorted(world.unc.objects.items()):
        hit = None if seen is None else seen.get(id(o))
        if hit is None or hit[0] is not o:
            x, y, z, t = _part_bounds(cache, reg, o)
            hit = (o, {"dx": list(x), "dy": list(y), "dz": list(z), "dtheta_deg": _degrees(*t)})
            if seen is not None:
                seen[id(o)] = hit
        out[k] = hit[1]
    return out


def _all_satisfied(checks: list[dict[str, Any]], kind: str) -> bool:
    return all(c["satisfied"] for c in checks if c["kind"] == kind)


def evaluate(cache: CellCache, steps: Sequence[Step], sources: Sources | None = None,
             given_up: Sequence[str] = (), sensing: Mapping[str, Mapping[str, Any]] | None = None,
             motion: MotionOptions | None = None) -> Evaluation:
    """Run the plan instance ``steps`` (in order) of the cell of ``cache`` from its initial
    world: one call per run (planning/run.py's PlanRun.evaluate, for Prolog).

    ``sources`` as :func:`new_world`; ``given_up`` the ids of steps whose unmet
    uncertainty-reduction preconditions the run goes past (they count as errors);
    ``sensing`` the sensing rules' bounds in their own units (:func:`sensing_bounds`);
    ``motion`` the run's motion options (None: end-points only). The run stops at the first
    step whose uncertainty-reduction preconditions are not all satisfied and that is not in
    ``given_up`` (failed) or at the first whose geometric precondition fails (infeasible: no
    placement, no joint solution, no motion); each step record, up to and including that
    one, is ``{"id", "verdicts": [verdict dicts], "geometry": {"tool_pose", "joints_deg",
    "ik_solutions_deg", "placement", "source", ...}, "poses": poses(world after it), "held":
    the object in the hand after it or None}``, and in a run that went through (status ok)
    ``"position_bounds"``: :func:`position_bounds` of the world after it. Lengths in the cell
    unit, angles in degrees, world frame."""
    cell = cache.cell
    world = new_world(cache, list(steps), sources, sensing_bounds(cell, sensing), motion)
    skip = set(given_up)
    out: list[dict[str, Any]] = []
    refused: list[tuple[str, tuple[tuple[str, str], ...]]] = []
    worlds = [world]
    seen: dict[int, tuple[ur.ObjectState, list[list[float]]]] = {}
    for i, s in enumerate(steps):
        checks, world, geo = step(world, s, early=s["id"] not in skip)
        worlds.append(world)
        refused += world.refused
        out.append({"id": s["id"], "verdicts": checks, "geometry": geo,
                    "poses": poses(world, seen), "held": world.unc.holding})
        if not _all_satisfied(checks, "geometric"):
            return Evaluation("infeasible", s["id"], out, refused, nogood=nogood(worlds[-2], world, steps, i, checks))
        if not _all_satisfied(checks, "uncertainty") and s["id"] not in skip:
            return Evaluation("failed", s["id"], out, refused)
    out = _refined(cache, out, worlds)
    # a run that went through is one Prolog may report: its parts' propagated bounds, per step
    bseen: dict[int, tuple[ur.ObjectState, dict[str, list[float]]]] = {}
    out = [{**rec, "position_bounds": position_bounds(cache, w, bseen)} for rec, w in zip(out, worlds[1:])]
    if motion is not None:  # the end-points are fixed: the motions between them (world/motion/paths.py)
        from spar_py.world.motion import run_motions  # motion.py is some 2 ms of a cold start

        records, got = run_motions(cache, steps, worlds, out, motion)
        if isinstance(got, MotionFailure):
            return Evaluation("infeasible", records[-1]["id"], records, refused, got)
        return Evaluation("ok", None, records, refused, got)
    return Evaluation("ok", None, out, refused)


def nogood(before: World, after: World, steps: Sequence[Step], at: int, checks: list[dict[str, Any]]
           ) -> dict[str, Any] | None:
    """What makes step ``steps[at]`` (``s``) of the instance ``steps`` infeasible, as a condition on any plan
    instance of the same partial plan, for phase 2's instance search (prolog/uncertainty.pl): the
    step ``step`` with the grasp its pickup ``grasp_step`` bound, executed after every step of
    ``done`` and before every step of ``not_done``, fails the same way. None unless that is sure.

    It is sure when the step is a pickup or an assemble refused only for want of an arm solution
    (no IK, or every solution collides: no state check), the instance has no put-down (every part
    is where the cell lays it or in its place on its body) and no stock object, and every part
    the refusals name outside the moving body, and the part an assemble goes into, lies as
    ``done``/``not_done`` fix it: the steps that mated it and each part between it and its
    body's root, with the root not yet picked. Its world pose is then the same, the tool pose is
    (the grasp and the mate are in the steps' terms), and a part the refusals do not name is
    no obstacle of any solution; more parts elsewhere never free one."""
    s = steps[at]
    name = s["name"]
    if name not in ("pickup", "assemble") or any(t["name"] == "putdown" for t in steps) or _stock(before.cell):
        return None
    bad = [c for c in checks if c["kind"] == "geometric" and not c["satisfied"]]
    if not bad or any(c.get("constraint") != "reachable" for c in bad):
        return None
    unc = before.unc
    obj = str(s["args"][0])
    done_before = steps[:at]
    picks = [t for t in done_before if t["name"] == "pickup" and str(t["args"][0]) == obj]
    grasp_step = s["id"] if name == "pickup" else (picks[-1]["id"] if picks else None)
    if grasp_step is None or unc.root(obj) != obj:
        return None
    moving = set(unc.body(obj))
    named = {n.removeprefix("held:") for _, pairs in after.refused for pair in pairs for n in pair}
    fixed = {n for n in named if n in unc.objects} - {obj}
    if fixed & moving:
        return None  # a part carried with it: its presence is the body's, not said here
    if name == "assemble":
        fixed.add(str(s["args"][1]))
    done: set[str] = set()
    not_done: set[str] = set()
    for part in sorted(fixed):
        chain = [part]
        while chain[-1] in unc.attached:
            chain.append(unc.attached[chain[-1]].parent)
        root = chain[-1]
        if unc.obj(root).where == ur.HAND or any(t["name"] == "pickup" and str(t["args"][0]) == root
                                                 for t in done_before):
            return None  # its body has moved: its pose is the plan's
        for c in chain[:-1]:
            mated = [t["id"] for t in done_before if t["name"] == "assemble" and str(t["args"][0]) == c]
            if not mated:
                return None
            done.add(mated[-1])
        not_done |= {t["id"] for t in steps if t["name"] == "pickup" and str(t["args"][0]) == root}
    return {"step": s["id"], "grasp_step": grasp_step, "done": sorted(done), "not_done": sorted(not_done)}


def _refined(cache: CellCache, out: list[dict[str, Any]], worlds: list[World]) -> list[dict[str, Any]]:
    """The step records of a run that went through, with each uncertainty-reduction
    verdict's bound refined to SUP/INF's tolerance.

    The steps decide their constraints with ``decide`` (uncertainty.evaluate): SUP/INF
    stops once the verdict is settled. A run that went through is one Prolog may report,
    so its bounds are refined here, as they would have been without ``decide`` (the
    verdicts do not change). Step i's constraints are the last entries of the world after
    it, ``worlds[i + 1].checked`` (phase2._checked), in the order of its verdicts, and are
    bounded in that world's registry (variables' bounds never change)."""
    records = []
    for i, rec in enumerate(out):
        k = sum(1 for v in rec["verdicts"] if v["kind"] == "uncertainty")
        if not k:
            records.append(rec)
            continue
        after = worlds[i + 1]
        pairs = iter(after.checked[len(after.checked) - k:])
        verdicts = []
        for v in rec["verdicts"]:
            if v["kind"] == "uncertainty":
                c, satisfied = next(pairs)
                unit = cache.cell.unit if c.power == 1 else f"{cache.cell.unit}^{c.power}"
                v = {**ur.evaluate(c, after.unc.registry, memo=cache.memo).as_dict(), "kind": "uncertainty",
                     "unit": unit}
                if v["satisfied"] != satisfied:  # cannot happen (Bounder.bounds' beat): say so if it does
                    raise AssertionError(f"phase 2: {c.action} {c.name}: the refined verdict differs")
            verdicts.append(v)
        records.append({**rec, "verdicts": verdicts})
    return records


def _activate(world: World, s: Step) -> World:
    """``world`` with the parts step ``s`` takes (its sources) made the active parts of
    their stock objects; the part they replace keeps its state under ``obj@origin``."""
    for obj, label in world.sources.get(s["id"], {}).items():
        if obj not in world.active:
            continue
        key = _part_at(world, obj, label)
        if key is None or key == obj:
            continue
        objs = dict(world.unc.objects)
        retired = f"{obj}@{world.active[obj]}"
        objs[retired] = replace(objs.pop(obj), name=retired)
        objs[obj] = replace(objs.pop(key), name=obj)
        names = {obj: retired, key: obj}  # the mates follow their parts
        attached = {names.get(c, c): replace(a, parent=names.get(a.parent, a.parent))
                    for c, a in world.unc.attached.items()}
        world = replace(world, unc=replace(world.unc, objects=objs, attached=attached),
                        active={**world.active, obj: key.split("@", 1)[1]})
    return world


def _part_at(world: World, obj: str, label: str) -> str | None:
    """The world key of the part of stock object ``obj`` lying at position ``label`` (an
    initial position's label, or a stable pose): the active part if it is there."""
    parts = world.unc.objects
    keys = [obj] + [k for k in parts if k.startswith(f"{obj}@")]
    return next((k for k in keys if parts[k].where == ur.TABLE and _lies_at(world.cell, obj, label, parts[k].pose)),
                None)


def _arm(world: World, T: np.ndarray, what: str = "", held: tuple[str, np.ndarray] | None = None,
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


def _via(cell: Cell, obj: str, label: str) -> str | None:
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




def retention_refusal(unc: ur.WorldState, what: str) -> str | None:
    """Why the state ``unc`` (after step ``what``) loses a part, or None: the first loose mate
    whose insertion direction (the child's way into its parent, the parent's frame, turned by the
    parent's ideal pose into the world) is more than LOOSE_MAX_DEG from world down: ``pickup(block)
    would turn pin_b (loose in block.bore_b) 90 deg from down``."""
    for child, a in unc.attached.items():
        if a.retention != "loose" or a.direction is None:
            continue
        d = unc.obj(a.parent).pose[:3, :3] @ a.direction
        n = float(np.linalg.norm(d))
        if not n > 0:
            continue
        angle = math.degrees(math.acos(max(-1.0, min(1.0, -float(d[2]) / n))))
        if angle > LOOSE_MAX_DEG + 1e-6:
            return f"{what} would turn {child} ({a.mate}) {angle:.0f} deg from down"
    return None


def _stacked_on(world: World, obj: str) -> str | None:
    """A part resting on ``obj``'s body (on its top, not mated into it), or None: picking ``obj`` up
    would leave it unsupported. A part rests on it when its lowest point is at the top's height
    (world.reach.supports' tolerance) over the top's polygon (world.reach.supports.rest_of)."""
    cell, unc = world.cell, world.unc
    body = unc.body(obj)
    tol = from_mm(cell.unit, REST_TOL_MM)
    tops = [part_surface(k, cell.objects[_model(k)], unc.obj(k).pose, tol) for k in body
            if cell.objects[_model(k)].shape]
    if not tops:
        return None
    for k, o in unc.objects.items():
        if k in body or o.where != ur.TABLE or k in unc.attached:
            continue
        r = rest_of(cell, _model(k), o.pose, [*surfaces_of(cell), *tops])
        if r is not None and r.surface is not None and r.surface.name in body:
            return k
    return None


def _model(key: str) -> str:
    """The object (model) name of a world key (``obj`` or ``obj@position``)."""
    return key.split("@", 1)[0]


def _no_arm(what: str, geo: dict[str, Any]) -> str:
    """Why no joint vector was chosen for ``what``: none at all, or none clear of the world."""
    if "collisions" not in geo:
        return f"no joint solution for {what}"
    return f"no collision-free IK for {what}: {', '.join(dict.fromkeys(pair_text(p) for p in geo['collisions']))}"


#: The geometric verdicts of a body's own state (not of the arm's reach): a put-down body at rest,
#: loose mates kept, no part left unsupported; a no plan names them (planning/run.py).
STATE_CHECKS = ("stable", "retention", "supported")


def _reach_verdict(action: str, ok: bool, what: str, constraint: str = "reachable") -> dict[str, Any]:
    return {"action": action, "constraint": constraint, "kind": "geometric", "sense": "",
            "bound": None, "threshold": None, "satisfied": ok, "tolerance_reached": True,
            "description": what}


def _verdicts(world: World, cs: list[ur.Constraint], early: bool = False) -> list[dict[str, Any]]:
    """The verdicts of ``cs`` in order; with ``early`` up to the first unsatisfied one."""
    if early:
        return _verdicts_until_unsatisfied(world, cs)
    out = []
    for v in ur.evaluate_all(cs, world.unc.registry, memo=world.cache.memo, decide=True):
        d = v.as_dict()
        d["kind"] = "uncertainty"
        out.append(d)
    return out


def _verdicts_until_unsatisfied(world: World, cs: list[ur.Constraint]) -> list[dict[str, Any]]:
    """The verdicts of ``cs`` in order, up to and including the first unsatisfied one."""
    out = []
    for c in cs:
        d = ur.evaluate(c, world.unc.registry, memo=world.cache.memo, decide=True).as_dict()
        d["kind"] = "uncertainty"
        out.append(d)
        if not d["satisfied"]:
            break
    return out


def _checked(world: World, cs: list[ur.Constraint], checks: list[dict[str, Any]]) -> tuple:
    """``world.checked`` extended by this step's constraints and their verdicts."""
    ur_checks = [c for c in checks if c["kind"] == "uncertainty"]
    return world.checked + tuple((c, v["satisfied"]) for c, v in zip(cs, ur_checks))


def _pickup(world: World, s: Step, early: bool = False) -> tuple[list[dict], World, dict]:
    obj, label = s["args"][0], s["args"][1]
    g = _grasp(world.cell, obj, label)
    o = world.unc.obj(obj)
    manip = world.unc.manipulator_error()
    what = f"pickup({obj}, {label})"
    via = _via(world.cell, obj, label)
    carried = via is None or via in world.unc.body(obj)[1:]
    cs = ur.pickup_constraints(world.unc, obj, g.T, g.width, world.cell.finger_separation, manip, action=s["id"],
                               memo=world.cache.memo, via=via if carried else None)
    checks = _verdicts(world, cs, early)
    if not carried:
        checks.append(_reach_verdict(s["id"], False, f"{what} holds {obj} by {via}, which {obj} does not carry "
                                     f"(not mated into it)", "via_grasp"))
    q, geo, refused = _arm(world, o.pose @ g.T, what, grasped=via if via in world.unc.objects else obj,
                           width=g.width)
    if q is None:
        checks.append(_reach_verdict(s["id"], False, _no_arm(what, geo)))
    on = _stacked_on(world, obj)
    if on is not None:
        checks.append(_reach_verdict(s["id"], False, f"pickup({obj}) would leave {on} unsupported: it rests on "
                                     f"{obj}'s body, not mated into it", "supported"))
    unc = ur.pickup(world.unc, obj, g.T, manip, world.cache.memo)
    lost = retention_refusal(unc, f"pickup({obj})")
    if lost is not None:
        checks.append(_reach_verdict(s["id"], False, lost, "retention"))
    w = replace(world, refused=refused, unc=unc,
                grasps={**world.grasps, obj: label},
                joints=q if q is not None else world.joints, checked=_checked(world, cs, checks),
                complete=sum(c["kind"] == "uncertainty" for c in checks) == len(cs))
    return checks, w, geo


def _putdown(world: World, s: Step, early: bool = False) -> tuple[list[dict], World, dict]:
    obj = s["args"][0]
    place = world.placements.get(s["id"])
    if place is None:
        checks = [_reach_verdict(s["id"], False, f"no placement in the free table regions where the arm "
                                 f"reaches {obj} for this put-down and the actions after it")]
        return checks, world, {"tool_pose": None, "joints_deg": None, "placement": None}
    g = _grasp(world.cell, obj, world.grasps[obj])
    what = f"putdown({obj})"
    unc = ur.putdown(world.unc, obj, place.T, world.cache.memo)
    body = unc.body(obj)
    carried = [(c, world.cell.objects[_model(c)], unc.obj(c).pose) for c in body[1:]]
    under = [(k, world.cell.objects[_model(k)], o.pose) for k, o in unc.objects.items()
             if k not in body and o.where == ur.TABLE and k not in unc.attached]
    need = world.cell.product.sub_poses.get(obj, {}).get(place.pose) if world.cell.product is not None else None
    on = rest_of_body(world.cell, obj, place.T, surfaces_of(world.cell, under), carried,
                      combined=need is not None and set(body[1:]) == set(need))
    surface = on.surface.name if on is not None and on.surface is not None else "table"  # the step's own contact
    q, geo, refused = _arm(world, place.T @ g.T, what, held=(obj, np.linalg.inv(g.T)), width=g.width,
                           allow=[(f"held:{obj}", n) for n in dict.fromkeys(("table", surface))],
                           via=_via(world.cell, obj, world.grasps[obj]))
    geo["placement"] = place.as_dict()
    checks = [] if q is not None else [_reach_verdict(s["id"], False, _no_arm(what, geo))]
    if need is not None and set(body[1:]) != set(need):
        checks.append(_reach_verdict(s["id"], False, f"{what} in {place.pose}, a pose of {obj} with "
                                     f"{', '.join(need)} mated in, but {obj} carries "
                                     f"{', '.join(body[1:]) or 'nothing'}", "sub_pose"))
    elif on is not None and not on.ok:
        checks.append(_reach_verdict(s["id"], False, f"{what} leaves {obj} unstable: it {on.why}", "stable"))
    lost = retention_refusal(unc, what)
    if lost is not None:
        checks.append(_reach_verdict(s["id"], False, lost, "retention"))
    grasps = {k: v for k, v in world.grasps.items() if k != obj}
    w = replace(world, refused=refused, unc=unc, grasps=grasps, joints=q if q is not None else world.joints)
    return checks, w, geo


def _assemble(world: World, s: Step, early: bool = False) -> tuple[list[dict], World, dict]:
    peg, hole, faces, ta, va = s["args"][0], s["args"][1], s["args"][2], s["args"][3], s["args"][4]
    cell = world.cell
    Ta = cell.transforms[ta]
    g = _grasp(cell, peg, world.grasps[peg])
    goal_hole, goal_Ta = hole, Ta
    hole, Ta, faces = _carried_mate(world, peg, hole, faces, Ta)
    va_vec = np.asarray(cell.vectors[va], float) if isinstance(va, str) and va in cell.vectors else None
    if va_vec is not None and hole != goal_hole:  # V_a is in the goal parent's frame: into the mated part's
        va_vec = (world.unc.obj(hole).pose[:3, :3].T @ world.unc.obj(goal_hole).pose[:3, :3]) @ va_vec
    pair = _product_mate(cell, peg, hole, faces, Ta)
    if pair is None:
        fp, fh = _mate_features(cell, peg, hole, faces)
    else:
        fp, fh = pair
    cs = [] if fp is None else ur.assemble_constraints(
        world.unc, peg, hole, Ta, fp, fh, action=s["id"], memo=world.cache.memo,
        axis=va_vec)
    checks = _verdicts(world, cs, early)
    what = f"assemble({peg}, {goal_hole})"
    near = cell.product.near.get(peg, ()) if cell.product is not None else ()
    q, geo, refused = _arm(world, world.unc.obj(goal_hole).pose @ goal_Ta @ g.T, what,
                           held=(peg, np.linalg.inv(g.T)), width=g.width,
                           allow=[(f"held:{peg}", o) for o in dict.fromkeys((goal_hole, hole, *near))],
                           via=_via(cell, peg, world.grasps[peg]), touch=True)
    if q is None:
        checks.append(_reach_verdict(s["id"], False, _no_arm(what, geo)))
    grasps = {k: v for k, v in world.grasps.items() if k != peg}
    margin = 0.0 if fp is None else max(0.0, float(fh.radius) - float(fp.radius))
    retention, mate = _retention(cell, peg, hole, fh)
    unc = ur.assemble(world.unc, peg, hole, Ta, retention=retention, direction=va_vec, clearance=margin,
                      axis=None if fp is None else va_vec, mate=mate)
    # a non-product cell's goal asks for this mate as the paper's cells make it (the insertion itself
    # is not held to gravity); once made, its part is loose like any other when its body moves
    lost = retention_refusal(unc, what) if cell.product is not None else retention_refusal(
        replace(unc, attached={k: a for k, a in unc.attached.items() if k != peg}), what)
    if lost is not None:
        checks.append(_reach_verdict(s["id"], False, lost, "retention"))
    w = replace(world, refused=refused, unc=unc, grasps=grasps,
                joints=q if q is not None else world.joints, checked=_checked(world, cs, checks),
                complete=sum(c["kind"] == "uncertainty" for c in checks) == len(cs))
    return checks, w, geo


def _carried_mate(world: World, peg: str, hole: str, faces: Any, Ta: np.ndarray) -> tuple[str, np.ndarray, Any]:
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


def _retention(cell: Cell, peg: str, hole: str, fh: MatingFeature | None) -> tuple[str, str]:
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


def _product_mate(cell: Cell, held: str, fixed: str, faces: Any, Ta: np.ndarray
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


def _mate_features(cell: Cell, peg: str, hole: str, faces: Any) -> tuple[MatingFeature, MatingFeature]:
    """The peg and hole features an assemble step's ``[PegFaces, HoleFaces]`` name (the goal's own)."""
    ok = isinstance(faces, list) and len(faces) == 2 and all(isinstance(f, list) for f in faces)
    fp = cell.objects[peg].feature_on(faces[0]) if ok else None
    fh = cell.objects[hole].feature_on(faces[1]) if ok else None
    if fp is None or fh is None:
        raise SparValueError(f"assemble({peg}, {hole}): its faces {faces!r} name no peg feature of {peg} "
                             f"and hole feature of {hole}")
    return fp, fh


def _scan(world: World, s: Step, early: bool = False) -> tuple[list[dict], World, dict]:
    obj = s["args"][0]
    leaves = world.scans.get(s["name"])
    geo = {"tool_pose": None, "joints_deg": None}
    if leaves is None:
        return [_reach_verdict(s["id"], False, f"neither the cell nor a sensing rule says what {s['name']} "
                               "leaves")], world, geo
    return [], replace(world, unc=ur.dense_range_scan(world.unc, obj, leaves)), geo


def _squeeze(world: World, s: Step, early: bool = False) -> tuple[list[dict], World, dict]:
    """Squeeze ``obj`` in place with the first of its grasps the arm reaches there whose pickup
    preconditions hold (Sec. 4.3: the squeeze must meet the pickup's own preconditions).
    A grasp's constraints are checked one by one, up to the first that fails, then the arm's
    joint solution (only the chosen grasp's verdicts are reported; the arm's refusals only of
    grasps whose constraints hold)."""
    obj = s["args"][0]
    cell = world.cell
    o = world.unc.obj(obj)
    labels = tuple(_position_label(cell, obj, o))
    # the arc is the cell's alone (no other part in it): kept, a plan squeezes one part many times
    arc = world.cache.table("phase2.squeeze_arcs", SQUEEZE_ARCS).get_or_compute(
        (obj, labels), lambda: reachable_pairs(world.cache, obj, list(cell.objects[obj].grasps), list(labels)))
    refused: Refusals = tuple((r.what, r.pairs) for r in arc.refusals)
    manip = world.unc.manipulator_error()
    for label in (g for g, _ in arc.pairs):
        g = _grasp(cell, obj, label)
        # the grasp's constraints first: bounding them is cheap beside the arm's collision check
        # with every part in place, and a grasp they refuse is no candidate whatever the arm does
        cs = ur.pickup_constraints(world.unc, obj, g.T, g.width, cell.finger_separation, manip, action=s["id"],
                                   memo=world.cache.memo)
        checks = _verdicts_until_unsatisfied(world, cs)
        if not (len(checks) == len(cs) and all(c["satisfied"] for c in checks)):
            continue
        q, geo, no = _arm(world, o.pose @ g.T, f"squeeze({obj}) with {label}", grasped=obj, width=g.width,
                          hand_first=True)
        refused += no
        if q is not None:
            geo["grasp"] = label
            w = replace(world, refused=refused, unc=ur.squeeze(world.unc, obj, g.T, manip, world.cache.memo),
                        joints=q,
                        checked=_checked(world, cs, checks))
            return checks, w, geo
    return ([_reach_verdict(s["id"], False, f"no grasp of {obj} both reachable and sure to succeed for a squeeze")],
            replace(world, refused=refused), {"tool_pose": None, "joints_deg": None})


def _position_label(cell: Cell, obj: str, o: ur.ObjectState) -> list[str]:
    """The label of ``obj``'s current table pose for the reach check: its initial absolute
    position if it is still there, else the stable pose its rotation is in."""
    labels = [p.label for p in cell.positions.values() if p.obj == obj] + list(cell.objects[obj].poses)
    return [lbl for lbl in labels if _lies_at(cell, obj, lbl, o.pose)][:1]


STEPS = {
    "pickup": _pickup,
    "putdown": _putdown,
    "assemble": _assemble,
    "dense_range_scan": _scan,
    "squeeze": _squeeze,
}


# ---------------------------------------------------------------------- execution check


def sample_check(cache: CellCache, steps: list[Step], draws: int = 10_000, seed: int = 0,
                 sensing: Mapping[str, Bounds] | None = None) -> list[dict[str, Any]]:
    """Replay an instance numerically: for every uncertainty-reduction precondition checked
    along ``steps`` (in order, sensing and squeezes included), evaluate its expression at
    ``draws`` points drawn uniformly from its variables' bounds and count the draws in
    which the inequality fails. A precondition declared satisfied must never fail.
    Steps as in the plan's JSON (``id``, ``name``, ``args`` as term data); a step's
    ``source`` (which part of a stock it takes; ``from`` in a JSON written before the
    key was renamed) is honoured; ``sensing`` as
    :func:`new_world` (needed only when the cell has no sensors entry)."""
    sources = {s["id"]: s.get("source") or s["from"] for s in steps if s.get("source") or s.get("from")}
    world = new_world(cache, steps, sources, sensing)
    for s in steps:
        _, world, _ = step(world, s)
    rng = np.random.default_rng(seed)
    reg = world.unc.registry
    out = []
    for c, declared in world.checked:
        names = sorted(reg.box(c.expr))
        syms = [reg.symbol(n) for n in names]
        f = ca.Function("f", [ca.vertcat(*syms)] if syms else [ca.SX.sym("none", 0)], [c.expr])
        lo = np.array([reg.bounds(n)[0] for n in names])
        hi = np.array([reg.bounds(n)[1] for n in names])
        pts = rng.uniform(lo, hi, size=(draws, len(names))) if names else np.zeros((draws, 0))
        vals = np.asarray(f.map(draws)(pts.T)).ravel()
        bad = vals <= c.threshold if c.sense == ">" else vals >= c.threshold
        out.append({"action": c.action, "constraint": c.name, "declared_satisfied": bool(declared),
                    "failed_draws": int(bad.sum()), "min": float(vals.min()), "max": float(vals.max())})
    return out
