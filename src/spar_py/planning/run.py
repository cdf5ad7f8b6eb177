"""One planning run as Prolog sees it: the two doors to the world, and what stays in Python.

A :class:`PlanRun` is made for each :meth:`Planner.plan <spar_py.planning.planner.Planner.plan>`
from the cached, immutable cell, the cell's kept answers (world.run.CellCache) and the run's
options. The engine keeps it by problem name for the length of the query, and the two
functions Prolog calls into Python for geometry (engine.arc_pairs, engine.evaluate) are its
methods :meth:`arc_pairs` (phase 1: the world run's) and :meth:`evaluate` (phase 2).
Phase 2's evaluation is the paper's (phase2/instance.py), which sits above the world layer,
so this object lives in planning/ and holds the world run (world/run.py) rather than being
it: world/ never imports phase2/.

Every "no" is logged in the run's own log (world.run.RunLog) as data: the refusals of the
arcs and of phase 2's steps with their colliding pairs, the motions that do not exist. What
Prolog needs of a phase-2 run crosses the bridge (status, where it stopped, each step's
verdicts); each step's geometry (tool pose, joints, IK solutions, placement, poses, ...) and
the instance's motions stay here under a token, and the plan's JSON is joined from them at
the end (:meth:`join`).
"""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from spar_py.core.model import Cell
from spar_py.phase2 import instance as phase2
from spar_py.world.motion import MotionFailure
from spar_py.world.collision import CellCache
from spar_py.world.run import RunOptions, WorldRun

if TYPE_CHECKING:
    from spar_py.world.motion import InstanceMotion

__all__ = ["InstanceFailure", "PlanRun", "StepData"]

#: The fields of a step's geometry the plan's JSON shows (docs/json-schema.md).
STEP_FIELDS = ("tool_pose", "joints_deg", "ik_solutions_deg", "ik_solver", "placement", "source", "poses", "held",
               "moves", "clearance", "closest_pair", "position_bounds")
#: Those a product cell's assemble step adds where it has them (its mates, its tightest check).
PRODUCT_STEP_FIELDS = ("mates", "tightest")


@dataclass(frozen=True)
class StepData:
    """The geometry of one phase-2 run that went through, kept while Prolog decides: each
    step's display fields by step id, and the instance's motions (or None)."""

    steps: dict[str, dict[str, Any]]
    motion: InstanceMotion | None = None


@dataclass(frozen=True)
class InstanceFailure:
    """One phase-2 run of a plan instance that stopped at a step whose geometric precondition
    failed: ``instance`` names the instance (its manipulation steps' terms and its sources; the
    runs of one instance, with sensing inserted or actions given up, share it), ``step`` the
    step's id, ``term`` its action as text without the arguments an instance binds
    (``assemble(leg3, seat)``, ``pickup(leg3)``: the grasp and the position vary by instance),
    ``name`` and ``args`` the action, ``refusals`` the (what, pairs) refusals of the run (a step
    is refused only when it stops the run: those of this step), ``why`` its unmet geometric
    verdicts' descriptions."""

    instance: tuple
    step: str
    term: str
    name: str
    args: tuple[str, ...]
    refusals: tuple[tuple[str, tuple[tuple[str, str], ...]], ...]
    why: tuple[str, ...]
    grasp: str | None = None
    moved: tuple[str, ...] = ()


#: Actions whose arguments after the object are what an instance binds (a grasp, a position).
_OWN_ARG = ("pickup", "putdown")


def _text(arg: Any) -> str:
    """A step argument given as term data (foreign.pl's term_data/2) as Prolog writes it."""
    if isinstance(arg, dict) and "functor" in arg:
        return f"{arg['functor']}({', '.join(_text(a) for a in arg['args'])})"
    if isinstance(arg, list):
        return f"[{', '.join(_text(a) for a in arg)}]"
    return str(arg)


def _instance_key(steps: list[dict[str, Any]], sources: dict[str, dict[str, str]] | None) -> tuple:
    """What names a plan instance across its runs: its manipulation steps' terms and its sources
    (the runs of one instance, with sensing inserted or actions given up, share it)."""
    manip = tuple((s["id"], s["name"], tuple(_text(a) for a in s["args"])) for s in steps
                  if not str(s["id"]).startswith(("sense_", "squeeze_")))
    src = tuple(sorted((k, tuple(sorted(v.items()))) for k, v in (sources or {}).items()))
    return manip, src


def _failure(steps: list[dict[str, Any]], sources: dict[str, dict[str, str]] | None,
             ev: phase2.Evaluation) -> InstanceFailure:
    """The failure record of the infeasible run ``ev`` of the instance ``steps``."""
    at = next(s for s in steps if s["id"] == ev.at)
    args = tuple(_text(a) for a in at["args"])
    last = ev.steps[-1] if ev.steps and ev.steps[-1]["id"] == ev.at else {"verdicts": []}
    why = tuple(str(v.get("description") or v.get("constraint")) for v in last["verdicts"]
                if v.get("kind") == "geometric" and not v.get("satisfied"))
    before = [s for s in steps[:steps.index(at)] if s["name"] in ("pickup", "putdown", "assemble") and s["args"]]
    picks = [s for s in before if s["name"] == "pickup" and len(s["args"]) > 1 and _text(s["args"][0]) == args[0]]
    grasp = args[1] if at["name"] == "pickup" and len(args) > 1 else (_text(picks[-1]["args"][1]) if picks else None)
    moved = tuple(dict.fromkeys(_text(s["args"][0]) for s in before))
    term = f"{at['name']}({', '.join(args[:1 if at['name'] in _OWN_ARG else 2])})"
    return InstanceFailure(_instance_key(steps, sources), str(ev.at), term, str(at["name"]), args,
                           tuple(ev.refusals), why, grasp, moved)


class PlanRun:
    """One planning run: its world (``world``: cell cache, options, log) and phase 2's door."""

    __slots__ = ("world", "infeasible", "failures", "_refused_in")

    def __init__(self, cache: CellCache, options: RunOptions | None = None) -> None:
        self.world = WorldRun(cache, options)
        #: Why the instances that could not be executed stopped where a body's own state refused a
        #: step (phase2.STATE_CHECKS: unstable, a loose part turned, a part left unsupported), each once.
        self.infeasible: list[str] = []
        #: Every run of an instance that stopped at a step it could not execute, in order
        #: (planning.messages.phase2_digest counts them by instance).
        self.failures: list[InstanceFailure] = []
        #: Each refusal of phase 2's steps (its ``what``) -> the instances whose runs met it.
        self._refused_in: dict[str, set[tuple]] = {}

    @property
    def cell(self) -> Cell:
        """The run's cell (read only)."""
        return self.world.cell

    def arc_pairs(self, rule: str, kind: str, objects: Sequence[str], grasps: Sequence[str],
                  positions: Sequence[str], ta: str | None) -> list[list[str]]:
        """Phase 1's door: the [grasp, position] pairs of an arc (world.run.WorldRun.arc_pairs)."""
        return self.world.arc_pairs(kind, objects, grasps, positions, ta, rule)

    def evaluate(self, steps: list[dict[str, Any]], sources: dict[str, dict[str, str]] | None = None,
                 given_up: Sequence[str] = (), sensing: dict[str, dict[str, Any]] | None = None) -> dict[str, Any]:
        """Phase 2's door: run a whole plan instance (phase2.evaluate with the run's motion
        options), log its refusals and motion failure, and return what Prolog reads:
        ``{"status", "at", "steps": [{"id", "verdicts"}], "token", "nogood"}`` (``token`` names the
        run's geometry and motions, kept here; only for a run that went through; ``nogood`` only
        for an infeasible one phase2.nogood can generalise)."""
        log = self.world.log
        ev = phase2.evaluate(self.world.cache, steps, sources, given_up, sensing, self.world.options.motion)
        key = _instance_key(steps, sources)
        for what, pairs in ev.refusals:
            log.refuse(what, pairs)
            self._refused_in.setdefault(what, set()).add(key)
        if isinstance(ev.motion, MotionFailure):
            log.fail_motion(ev.motion)
        if ev.status == "infeasible" and ev.at is not None:
            self.failures.append(_failure(steps, sources, ev))
        if ev.status == "infeasible" and ev.steps:
            for v in ev.steps[-1]["verdicts"]:
                why = v.get("description") or ""
                if v.get("constraint") in phase2.STATE_CHECKS and not v.get("satisfied") and why not in self.infeasible:
                    self.infeasible.append(why)
        out: dict[str, Any] = {"status": ev.status, "at": ev.at,
                               "steps": [{"id": r["id"], "verdicts": r["verdicts"]} for r in ev.steps]}
        if ev.nogood is not None:  # what any instance meeting the same conditions fails at (phase2.nogood)
            out["nogood"] = ev.nogood
        if ev.status == "failed" and ev.steps:
            # no remedy can help where every unmet check is beyond reach of them (steps._floors)
            unmet = [v for v in ev.steps[-1]["verdicts"] if v.get("kind") == "uncertainty" and not v["satisfied"]]
            out["hopeless"] = bool(unmet) and all(v.get("remediable") is False for v in unmet)
            if out["hopeless"] and all("depends" in v for v in unmet):
                out["depends"] = list(dict.fromkeys(p for v in unmet for p in v["depends"]))
        if ev.status != "ok":
            return out
        geo = {r["id"]: {**r["geometry"], "poses": r["poses"], "held": r["held"],
                         "position_bounds": r.get("position_bounds")} for r in ev.steps}
        out["token"] = log.keep(StepData(geo, ev.motion))
        return out

    def refusal_instances(self) -> dict[str, int]:
        """Each refusal of phase 2's steps (its ``what``, as the run's log keeps it) -> the number of
        plan instances whose runs met it (planning.messages.collision_lines sums them in one line)."""
        return {what: len(keys) for what, keys in self._refused_in.items()}

    def join(self, instance: dict[str, Any]) -> Any:
        """Put the kept geometry of the chosen phase-2 run into the plan's ``instance`` (in place):
        each step's display fields (None where the step has none) and ``motion``, the summary of
        its motions (None without). The instance names its run by ``token``; returns that run's
        motions (world/motion.attach adds their waypoints) or None."""
        token = instance.pop("token", None)
        if token is None:
            return None
        data: StepData = self.world.log.kept(token)
        for st in instance.get("steps", []):
            g = data.steps.get(st["id"], {})
            for k in STEP_FIELDS:
                st[k] = g.get(k)
            st.update({k: g[k] for k in PRODUCT_STEP_FIELDS if k in g})
        instance["motion"] = None
        if data.motion is not None:
            from spar_py.world.motion import motion_summary  # a run without motions skips it

            instance["motion"] = motion_summary(data.motion)
        return data.motion

    def step_geometry(self, token: int, step: str) -> dict[str, Any]:
        """The kept geometry of step ``step`` of the phase-2 run ``token`` (empty if none)."""
        data: StepData = self.world.log.kept(token)
        return dict(data.steps.get(step, {}))
