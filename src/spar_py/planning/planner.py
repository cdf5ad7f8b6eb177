"""The Python API: load a problem, plan it (phase 1, then phase 2), get a typed Plan.

Example (runnable; docs/quickstart.md)::

    from spar_py import Planner
    planner = Planner()
    plan = planner.plan("kb/problems/peg_in_block.yaml")
    print(plan.outcome, [a.term for a in plan.actions])
    print(plan.error_count, [s.joints_deg for s in plan.steps])

Threads: one process has one embedded SWI-Prolog (engine.py). A planning run holds it
from loading the cell to unloading it, so runs from several threads (on one Planner or
on several) take turns; each sees only its own cell. A run's timeout counts from when
the run gets the engine.
"""
from __future__ import annotations

import json
import os
import re
import threading
import time
from dataclasses import dataclass, field
from enum import Enum
from pathlib import Path
from typing import Any

import numpy as np
from spar_py.planning.engine import engine
from spar_py.core.errors import ExpectedFailures, PlanningTimeout, SparValueError
from spar_py.kb import load_problem
from spar_py.core.memo import LRU
from spar_py.core.model import Bounds, Cell
from spar_py.planning.explain import Explanation, explain, timed_out
from spar_py.planning.messages import expected_failures
from spar_py.planning.run import PlanRun
from spar_py.world.motion import MotionOptions
from spar_py.world.collision import CellCache
from spar_py.world.run import RunOptions

#: The plan JSON's schema (docs/json-schema.md); :meth:`Plan.from_json` also reads :data:`READS`.
SCHEMA = 3
READS = (2, 3)

__all__ = ["Action", "Outcome", "Plan", "Planner", "SCHEMA", "Step", "Verdict", "term_text"]


class Outcome(str, Enum):
    """How a planning run ended."""

    PLAN = "plan"
    NO_PLAN = "no_plan"
    TIMEOUT = "timeout"


def term_text(data: Any) -> str:
    """Prolog-like text of a term given as data (foreign.pl's term_data/2): atoms are
    strings, compounds ``{"functor": f, "args": [...]}``, lists lists."""
    if isinstance(data, dict) and "functor" in data:
        return f"{data['functor']}({', '.join(term_text(a) for a in data['args'])})"
    if isinstance(data, dict) and "string" in data:
        return json.dumps(data["string"])
    if isinstance(data, dict) and "var" in data:
        return str(data["var"])
    if isinstance(data, list):
        return "[" + ", ".join(term_text(a) for a in data) + "]"
    return str(data)


@dataclass(frozen=True)
class Action:
    """A phase-1 plan action (Fig. 23): ``id`` (action_3), ``name`` (putdown), ``args`` as
    term data (plan variables and labels are strings), ``term`` its Prolog text."""

    id: str
    name: str
    args: tuple[Any, ...]
    term: str


@dataclass(frozen=True)
class Verdict:
    """One checked precondition of a step. ``kind`` "uncertainty" (a SUP/INF bound against
    a threshold: for sense ">" the bound is INF of the expression, for "<" its SUP) or
    "geometric" (reachability; bound and threshold None). Lengths in the cell unit."""

    action: str
    constraint: str
    kind: str
    sense: str
    bound: float | None
    threshold: float | None
    satisfied: bool
    tolerance_reached: bool
    description: str
    #: An insertion check's product mate (``pin_1.shaft->cover.ph1``), else empty.
    mate: str = ""
    #: 1 for a length, 2 for a squared length (the insertion checks): the bound's unit is the cell's to it.
    power: int = 1


@dataclass(frozen=True)
class Step:
    """A step of the chosen plan instance, in execution order.

    ``kind`` manipulation | sensing | squeeze (``serves``: the action an inserted step
    serves); ``tool_pose`` 4x4 world (cell unit) or None; ``joints_deg`` the joint
    solution used (deg, the robot file's DH zero convention) or None; ``ik_solver`` which
    solver gave the joints ("closed-form puma", "closed-form ur" or "numeric": not complete); ``poses`` every
    part's 4x4 world pose at the step's end-point (part key: the object name, or
    ``object@initial_position`` for the other parts of a stock); ``held`` the object in
    the hand after the step, or None; ``moves`` the parts the step moves (its object and the
    parts mated into it, directly or transitively: a subassembly moves as one), empty for sensing;
    ``clearance`` the least distance (cell unit) between the arm, gripper or held part and
    anything else at the joints used (at least the collision margin; None where the cell has no
    collision check), ``closest_pair`` the two bodies at that distance; ``source`` where the
    step takes an object lying on the table ({object: position label}: the part picked, the
    part mated onto) or None.

    With motions planned (``--motion``, ``Planner(motion=True)``, a file's ``motion: true``):
    ``path`` the free motion into the step (from home or the previous retreat's end),
    ``approach`` the straight tool line into its end-point (ending at ``joints_deg``),
    ``retreat`` the one out of it, each an (n, 6) float array of joint vectors (deg,
    waypoints in order); ``duration_s`` the step's estimated time (s). None without motions
    (and ``path`` None for a step that does not move the arm). The arrays are not compared
    by ``==``.

    ``position_bounds``: every part's position uncertainty at the step's end-point as phase
    2 propagated it (part keys as ``poses``), a :class:`~spar_py.core.model.Bounds`: ``dx``,
    ``dy``, ``dz`` the sound SUP/INF bounds of its origin's displacement along the world axes
    (cell unit), ``dtheta`` of its rotation about world z (radians, as every Bounds; the
    JSON's ``dtheta_deg`` in degrees). After a sensing step the scanned part has the sensor's
    bounds, while held the grasp's. None in a plan JSON written without them."""

    id: str
    kind: str
    serves: str
    name: str
    object: str
    term: str
    args: tuple[Any, ...]
    tool_pose: list[list[float]] | None
    joints_deg: list[float] | None
    ik_solutions_deg: list[list[float]]
    ik_solver: str | None
    placement: dict[str, Any] | None
    source: dict[str, str] | None
    poses: dict[str, list[list[float]]]
    held: str | None
    verdicts: tuple[Verdict, ...]
    clearance: float | None = None
    closest_pair: tuple[str, str] | None = None
    path: np.ndarray | None = field(default=None, compare=False, repr=False)
    approach: np.ndarray | None = field(default=None, compare=False, repr=False)
    retreat: np.ndarray | None = field(default=None, compare=False, repr=False)
    duration_s: float | None = None
    position_bounds: dict[str, Bounds] | None = None
    moves: tuple[str, ...] = ()
    #: A product assemble's mates and seats, those its insertion makes in this instance's order.
    mates: tuple[str, ...] = ()
    #: Its tightest insertion check as lengths: {mate, constraint, bound, threshold, satisfied}.
    tightest: dict[str, Any] | None = None


@dataclass
class Plan:
    """A planning outcome (JSON schema 3, docs/json-schema.md).

    ``outcome`` an :class:`Outcome`; ``partial`` the phase-1 partial plan (actions,
    ordering, variables, arcs, separations) as the JSON has it; ``instance`` the chosen
    phase-2 instance or None (``phase1_only``, no plan, timeout); ``explanation`` why there is
    no plan (or the timeout), a :class:`~spar_py.planning.explain.Explanation` (None for a plan);
    ``actions``, ``steps`` and ``verdicts`` the typed views.
    """

    problem: str
    outcome: Outcome
    partial: dict[str, Any] | None = None
    instance: dict[str, Any] | None = None
    explanation: Explanation | None = None
    timing: dict[str, float] = field(default_factory=dict)
    trace: str = ""
    actions: list[Action] = field(default_factory=list)
    steps: list[Step] = field(default_factory=list)

    @property
    def ok(self) -> bool:
        """True when a plan was found."""
        return self.outcome is Outcome.PLAN

    @property
    def reason(self) -> dict[str, Any] | None:
        """The JSON's ``reason``: ``explanation.to_json()``, or None for a plan."""
        return self.explanation.to_json() if self.explanation is not None else None

    @property
    def bound_actions(self) -> list[Action]:
        """The phase-1 ``actions`` with their plan variables (grasp_1, pos_1) replaced by the
        labels the chosen instance binds them to (``instance["bindings"]``): what the arm does,
        pickup(peg, p1G14) for pickup(peg, grasp_1). Variables the instance leaves unbound
        (none in a plan instance) and the actions without an instance stay as they are."""
        bindings: dict[str, str] = dict((self.instance or {}).get("bindings") or {})
        if not bindings:
            return list(self.actions)
        word = re.compile(r"(?<![\w'])(" + "|".join(map(re.escape, sorted(bindings, key=len, reverse=True)))
                          + r")(?![\w'])")
        return [Action(a.id, a.name, tuple(_bind(x, bindings) for x in a.args),
                       word.sub(lambda m: bindings[m.group(1)], a.term)) for a in self.actions]

    @property
    def verdicts(self) -> list[Verdict]:
        """Every checked precondition of the instance, in the order checked."""
        return [_verdict(c) for c in (self.instance or {}).get("constraints", [])]

    @property
    def error_count(self) -> int | None:
        """Actions planned for failure (verification + recovery), None without an instance."""
        return (self.instance or {}).get("error_count")

    def to_json(self) -> dict[str, Any]:
        """The versioned JSON document (a dict; ``json.dumps`` it to write)."""
        return {
            "schema": SCHEMA,
            "problem": self.problem,
            "outcome": self.outcome.value,
            "reason": self.reason,
            "partial": self.partial,
            "instance": self.instance,
            "timing": self.timing,
        }

    def dumps(self) -> str:
        """The JSON text, indented; a list of numbers (a waypoint, a matrix row) on one line."""
        return dumps(self.to_json())

    @classmethod
    def from_json(cls, doc: dict[str, Any]) -> Plan:
        """A Plan from its JSON document (schema 3, or 2: a step's ``from`` read as ``source``)."""
        if doc.get("schema") not in READS:
            raise SparValueError(f"plan JSON schema {doc.get('schema')!r}, not one of {', '.join(map(str, READS))}")
        return _plan(doc["problem"], doc, "")


def _flat(v: Any) -> bool:
    return isinstance(v, list) and all(x is None or isinstance(x, (int, float)) for x in v)


def dumps(doc: Any, indent: int = 2, level: int = 0) -> str:
    """``json.dumps(doc, indent=indent)``, except that lists of numbers are written on one
    line: a plan's waypoints (thousands of joint vectors) stay a line each."""
    if _flat(doc):
        return json.dumps(doc, separators=(",", ":"))
    if not isinstance(doc, (dict, list)) or not doc:
        return json.dumps(doc)
    pad, inner = " " * (indent * level), " " * (indent * (level + 1))
    if isinstance(doc, dict):
        body = ",\n".join(f"{inner}{json.dumps(str(k))}: {dumps(v, indent, level + 1)}" for k, v in doc.items())
        return "{\n" + body + "\n" + pad + "}"
    return "[\n" + ",\n".join(inner + dumps(v, indent, level + 1) for v in doc) + "\n" + pad + "]"


def _canonical(v: Any) -> Any:
    """``v`` with every dict's keys in sorted order, recursively. A SWI-Prolog dict keeps its
    keys in the order of their atoms' handles, and janus hands them over in that order: it
    depends on which atoms the process happened to create first (the planner's image loads in
    a thread while Python reads the problem), so the same plan could be written with its keys
    in another order from one run to the next."""
    if isinstance(v, dict):
        return {k: _canonical(v[k]) for k in sorted(v, key=str)}
    if isinstance(v, list):
        return [_canonical(x) for x in v]
    return v


def _verdict(c: dict[str, Any]) -> Verdict:
    return Verdict(action=c["action"], constraint=c["constraint"], kind=c["kind"], sense=c.get("sense", ""),
                   bound=c.get("bound"), threshold=c.get("threshold"), satisfied=bool(c["satisfied"]),
                   tolerance_reached=bool(c.get("tolerance_reached", True)),
                   description=c.get("description", ""), mate=str(c.get("mate") or ""),
                   power=int(c.get("power") or 1))


def _bind(data: Any, bindings: dict[str, str]) -> Any:
    """Term data (term_text's form) with every atom that is a bound plan variable replaced by its label."""
    if isinstance(data, str):
        return bindings.get(data, data)
    if isinstance(data, list):
        return [_bind(x, bindings) for x in data]
    if isinstance(data, dict) and "functor" in data:
        return {**data, "args": [_bind(x, bindings) for x in data["args"]]}
    return data


def _joints(v: Any) -> np.ndarray | None:
    """A list of joint vectors (deg) as an (n, 6) float array, or None."""
    if v is None:
        return None
    a = np.asarray(v, dtype=float)
    return a if a.ndim == 2 else a.reshape(len(v), 0)


def _bounds(d: dict[str, Any] | None) -> dict[str, Bounds] | None:
    """A step's ``position_bounds`` (JSON: dtheta in degrees) as Bounds per part (dtheta in radians)."""
    if d is None:
        return None

    def iv(v: Any, scale: float = 1.0) -> tuple[float, float]:
        return float(v[0]) * scale, float(v[1]) * scale

    rad = np.pi / 180.0
    return {str(k): Bounds(iv(b["dx"]), iv(b["dy"]), iv(b["dz"]), iv(b["dtheta_deg"], rad)) for k, b in d.items()}


def _step(s: dict[str, Any], verdicts: list[Verdict]) -> Step:
    return Step(id=s["id"], kind=s["kind"], serves=s["serves"], name=s["name"], object=s["object"],
                term=s["term"], args=tuple(s.get("args", ())), tool_pose=s.get("tool_pose"),
                joints_deg=s.get("joints_deg"), ik_solutions_deg=list(s.get("ik_solutions_deg") or []),
                ik_solver=s.get("ik_solver"),
                placement=s.get("placement"), source=s.get("source", s.get("from")),
                poses=dict(s.get("poses") or {}), held=s.get("held"), clearance=s.get("clearance"),
                path=_joints(s.get("path")), approach=_joints(s.get("approach")),
                retreat=_joints(s.get("retreat")),
                duration_s=None if s.get("duration_s") is None else float(s["duration_s"]),
                position_bounds=_bounds(s.get("position_bounds")), moves=tuple(s.get("moves") or ()),
                closest_pair=tuple(s["closest_pair"]) if s.get("closest_pair") else None,
                mates=tuple(s.get("mates") or ()), tightest=s.get("tightest"),
                verdicts=tuple(v for v in verdicts if v.action == s["id"]))


def _plan(problem: str, d: dict[str, Any], trace: str) -> Plan:
    partial, instance = d.get("partial"), d.get("instance")
    actions = [Action(a["id"], a["name"], tuple(a["args"]), a["term"]) for a in (partial or {}).get("actions", [])]
    verdicts = [_verdict(c) for c in (instance or {}).get("constraints", [])]
    steps = [_step(s, verdicts) for s in (instance or {}).get("steps", [])]
    reason = d.get("reason")
    return Plan(problem=problem, outcome=Outcome(d["outcome"]), partial=partial, instance=instance,
                explanation=Explanation.from_json(reason) if reason is not None else None,
                timing=dict(d.get("timing") or {}), trace=trace,
                actions=actions, steps=steps)


def name_mates(cell: Cell, d: dict[str, Any]) -> None:
    """A product cell's plan document (in place): each assemble of the partial plan gets
    ``mates``, the names of the mates and seats its insertion makes (``pin_a.shaft->base.bore_a``):
    the instance's, whose steps carry the mates phase 2 credited them in the order it took
    (phase2.mates.made_links); without an instance, those the partial order fixes (the other
    part never assembled, or necessarily before), and ``may_make`` those whose other part's
    assemble is unordered with it (made by whichever comes later). The partial plan gets
    ``precedence``, the orderings the product's geometry forced, ``{before, after, reason}``
    with the text the printed plan gives (``bracket before pin_a (...)``)."""
    product = cell.product
    can = {g.part: list(g.mates) for g in product.goals}
    other = {lk.name: lk.ends for lk in (*product.mates, *product.seats)}
    partial = d.get("partial") or {}
    steps = {st["id"]: st for st in (d.get("instance") or {}).get("steps", []) if st.get("name") == "assemble"}
    part_of: dict[str, str] = {}
    assembles = {a["args"][0]: a["id"] for a in partial.get("actions", [])
                 if a.get("name") == "assemble" and a.get("args") and a["args"][0] in can}
    before = _closure(partial.get("ordering", []))
    for a in partial.get("actions", []):
        if a.get("name") != "assemble" or not a.get("args") or a["args"][0] not in can:
            continue
        p = a["args"][0]
        part_of[a["id"]] = p
        if a["id"] in steps and "mates" in steps[a["id"]]:
            a["mates"] = list(steps[a["id"]]["mates"])
            continue
        sure, either = [], []
        for n in can[p]:
            q = next(x for x in other[n] if x != p)
            b = assembles.get(q)
            if b is None or (b, a["id"]) in before:
                sure.append(n)
            elif (a["id"], b) not in before:
                either.append(n)
        a["mates"] = sure
        if either:
            a["may_make"] = either
    if partial:
        reasons = {(pr.first, pr.then): f"{pr.first} before {pr.then} ({pr.reason})" for pr in product.precedence}
        partial["precedence"] = [
            {"before": a, "after": b, "reason": reasons[(part_of[a], part_of[b])]}
            for a, b in partial.get("ordering", []) if (part_of.get(a), part_of.get(b)) in reasons]


def _closure(pairs: Any) -> set[tuple[str, str]]:
    """The transitive closure of the ordering pairs ``[[a, b], ...]`` (a before b)."""
    succ: dict[str, set[str]] = {}
    for a, b in pairs:
        succ.setdefault(a, set()).add(b)
    out: set[tuple[str, str]] = set()
    for a in list(succ):
        stack, seen = list(succ[a]), set()
        while stack:
            b = stack.pop()
            if b not in seen:
                seen.add(b)
                stack.extend(succ.get(b, ()))
        out |= {(a, b) for b in seen}
    return out


#: Loaded cells a Planner keeps, by file, and cells with their kept answers (world.run.CellCache),
#: by cell: planning a cell again reuses its answers.
CELL_CACHE = 8


def _signature(files: tuple[str, ...]) -> tuple:
    """What says a cell's files are unchanged: each file's size and modification time."""
    out = []
    for f in files:
        try:
            st = os.stat(f)
            out.append((st.st_size, st.st_mtime_ns))
        except OSError:
            out.append(None)
    return tuple(out)


class Planner:
    """SPAR's two-phase planner on the embedded SWI-Prolog.

    Options (None: the planner's default, prolog/spar_defaults.pl): ``max_actions``
    (phase-1 plan-size bound; by default derived from the problem, twice its lower
    bound on the plan size and at least 12), ``max_instances`` (phase-2 cap on plan instances
    examined), ``separation`` (declobber by separation, dif/2),
    ``paper_placements`` (the paper's rule: a put-down into a stable pose is assumed
    reachable somewhere, Sec. 5.2.4; by default some placement in the free table
    regions must reach it), ``timeout`` (seconds for the whole query, None for none).

    Motions (world/motion/paths.py): ``motion`` True plans the joint paths between
    the chosen instance's end-points (home, transit and transfer motions, approach and
    retreat) and makes an instance whose motions do not exist inexecutable; False plans
    end-points only (the paper's phase 2); None (the default) follows the problem file's
    ``motion:`` key (default false: the regression suite plans motions only for the cells
    that ask, since a motion plan costs seconds where end-points cost milliseconds).
    ``motion_options`` a :class:`~spar_py.world.motion.paths.MotionOptions` (planner, time budget
    per motion, seed, approach length, simplification).

    ``strict`` True: a plan with actions planned for failure (``error_count`` > 0) raises
    :class:`~spar_py.core.errors.ExpectedFailures` (its ``plan`` the plan) instead of being
    returned like a certain one.

    A Planner keeps the last few cells it loaded from files (at most ``CELL_CACHE``,
    reloaded when a file changes) and each cell's kept answers (world.run.CellCache), so
    planning a file again reuses them; each plan is one run (planning.run.PlanRun) with a
    log of its own, from which its no-plan reason is built.
    """

    def __init__(self, max_actions: int | None = None, max_instances: int | None = None,
                 separation: bool | None = None, timeout: float | None = None,
                 paper_placements: bool = False, motion: bool | None = None,
                 motion_options: MotionOptions | None = None, strict: bool = False) -> None:
        self.engine = engine()
        defaults = self.engine.query_once("spar_defaults:default_options(D)")["D"]
        #: The bound on the plan size, or "auto" (the default): derived from the problem
        #: (prolog/spar_defaults.pl, derived_max_actions/2).
        self.max_actions: int | str = defaults["max_actions"] if max_actions is None else max_actions
        self.max_instances = defaults["max_instances"] if max_instances is None else max_instances
        self.separation = "separation" in defaults["declobber"] if separation is None else separation
        if (self.max_actions != "auto" and self.max_actions < 1) or self.max_instances < 1:
            raise SparValueError("max_actions and max_instances must be at least 1")
        if timeout is not None and timeout <= 0:
            raise SparValueError("timeout must be positive")
        self.timeout = timeout
        self.paper_placements = paper_placements
        self.motion = motion
        self.motion_options = motion_options if motion_options is not None else MotionOptions()
        self.strict = strict
        self._cells: LRU[tuple[tuple, Cell]] = LRU(CELL_CACHE)
        self._caches: LRU[CellCache] = LRU(CELL_CACHE)  # by id(cell); each holds its cell alive
        self._cells_lock = threading.Lock()
        #: The last plan this Planner made (None before the first). Keeping it also keeps
        #: its dict keys alive: janus interns every Prolog dict key it converts, and keys
        #: freed after one plan and interned again by the next make CPython's
        #: interned-string table churn and, once, double (about 1 MB; bench/memory.py).
        self.last: Plan | None = None

    def load_problem(self, path: str | Path) -> Cell:
        """Load and validate a problem file (KBError on bad input); the same cell again while
        its files are unchanged."""
        key = str(Path(path).resolve())
        with self._cells_lock:
            hit = self._cells.get(key)
        if hit is not None and _signature(hit[1].files) == hit[0]:
            return hit[1]
        cell = load_problem(path)
        with self._cells_lock:
            self._cells[key] = (_signature(cell.files), cell)
        return cell

    def options(self, phase1_only: bool = False, trace: bool = False) -> dict[str, Any]:
        """The options dict spar:plan_dict/4 reads."""
        return {
            "max_actions": self.max_actions,
            "max_instances": self.max_instances,
            "separation": self.separation,
            "placements": "paper" if self.paper_placements else "reachable",
            "phase1_only": phase1_only,
            "trace": trace,
            "timeout": self.timeout if self.timeout is not None else 0,
        }

    def cache_of(self, cell: Cell) -> CellCache:
        """The kept answers of ``cell`` (made on first use, at most ``CELL_CACHE`` cells)."""
        with self._cells_lock:
            got = self._caches.get(id(cell))
            if got is None or got.cell is not cell:
                got = self._caches[id(cell)] = CellCache(cell)
            return got

    def run_options(self, cell: Cell, phase1_only: bool = False) -> RunOptions:
        """The options of a run of ``cell``: the placement rule, and the motion options when
        motions are planned (this Planner's ``motion``, else the problem file's)."""
        wanted = cell.plan_motions if self.motion is None else self.motion
        return RunOptions(placements="paper" if self.paper_placements else "reachable",
                          motion=self.motion_options if wanted and not phase1_only else None)

    def plan(self, problem: Cell | str | Path, phase1_only: bool = False, trace: bool = False) -> Plan:
        """Plan ``problem`` (a loaded Cell or a problem file path): one run (planning.run.PlanRun)
        of the cell with this Planner's options."""
        cell = problem if isinstance(problem, Cell) else self.load_problem(problem)
        opts = self.options(phase1_only, trace)
        run = PlanRun(self.cache_of(cell), self.run_options(cell, phase1_only))
        with self.engine.session(run):
            t0 = time.perf_counter()
            try:
                ans = self.engine.query_once("spar:plan_dict(Problem, Options, Dict, Trace)",
                                             {"Problem": cell.name, "Options": opts})
            except PlanningTimeout:
                return Plan(problem=cell.name, outcome=Outcome.TIMEOUT,
                            explanation=timed_out(self.timeout),
                            timing={"total_s": round(time.perf_counter() - t0, 6)})
            raw = ans["Dict"]
            motion = run.join(raw["instance"]) if isinstance(raw.get("instance"), dict) else None
            d = _canonical(raw)
            if motion is not None:
                from spar_py.world.motion import attach  # only for an instance with motions

                attach(motion, d["instance"])
        d.setdefault("timing", {})["total_s"] = round(time.perf_counter() - t0, 6)
        if cell.product is not None:
            name_mates(cell, d)
        plan = _plan(cell.name, d, ans.get("Trace", ""))
        if plan.outcome is Outcome.NO_PLAN:  # why, in one place (planning/explain.py)
            plan.explanation = explain(cell, d.get("reason") or {}, run)
        self.last = plan
        line = expected_failures(plan.instance) if self.strict and plan.ok else None
        if line is not None:
            raise ExpectedFailures(plan, line)
        return plan
