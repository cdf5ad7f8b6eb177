"""Why there is no plan, as a typed value: built here, in one place, and written as the plan JSON's ``reason``.

A no plan's :class:`Explanation` has its ``cause`` (phase 1: the goal that could not be met,
:class:`GoalFailure`; phase 2: no instance examined could be executed, :class:`NoInstance`; or the
run's :class:`Timeout`) and what the run saw on the way: the motions that did not exist
(:class:`MotionStop`), the steps refused for a reason of their own (``infeasible``), a product's
single-arm report (:class:`SingleArm`) and grasp report (world.product's ``GraspReport``, which
reads and writes its own JSON), the phase-2 digest (planning.messages.Phase2Digest), the collision
lines and the summary line.
:func:`explain` builds it from a run; :meth:`Explanation.to_json` writes the ``reason`` dict of
docs/json-schema.md (its keys in the order the plan JSON has always had them) and
:meth:`Explanation.from_json` reads it back.
"""
from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING, Any

import numpy as np

from spar_py.core.model import Cell
from spar_py.planning.messages import Phase2Digest, collision_lines, phase2_digest, summary
from spar_py.planning.run import PlanRun
from spar_py.world.collision import CellCache
from spar_py.world.motion import MotionFailure

if TYPE_CHECKING:
    from spar_py.world.product import GraspReport

__all__ = ["Cause", "Explanation", "GoalFailure", "MotionStop", "NoInstance",
           "SingleArm", "Timeout", "explain", "timed_out"]


@dataclass(frozen=True)
class GoalFailure:
    """Phase 1 found no plan of at most ``max_actions`` actions (the last bound searched completely;
    ``bound`` the bound on the plan size): ``goal`` the goal that failed deepest as Prolog text,
    ``goal_data`` the same term as data (foreign.pl's term_data/2)."""

    max_actions: int | None
    bound: int | None
    goal: str
    goal_data: Any

    def to_json(self) -> dict[str, Any]:
        """The reason's phase-1 keys."""
        return {"bound": self.bound, "goal": self.goal, "goal_data": self.goal_data, "max_actions": self.max_actions}


@dataclass(frozen=True)
class NoInstance:
    """Phase 2 could execute none of the ``examined`` plan instances (``cap`` the cap on them,
    ``complete`` True when the partial plan has no further instance); ``why`` the line saying why
    (phase 2's, or the first motion that did not exist)."""

    examined: int | None
    cap: int | None
    complete: bool
    why: str

    def to_json(self) -> dict[str, Any]:
        """The reason's phase-2 keys."""
        return {"complete": self.complete, "instance_cap": self.cap, "instances_examined": self.examined,
                "phase": 2, "why": self.why}


@dataclass(frozen=True)
class Timeout:
    """The run ran out of its ``seconds`` (None: no timeout was set)."""

    seconds: float | None

    def to_json(self) -> dict[str, Any]:
        """The reason of a timeout."""
        return {"timeout_s": self.seconds}


Cause = GoalFailure | NoInstance | Timeout


@dataclass(frozen=True)
class MotionStop:
    """A motion that does not exist (world.motion.MotionFailure as data): ``motion`` names it, ``at``
    the step whose motion it is (None: home), ``pair`` the bodies that blocked it, ``detail`` one
    line, ``text`` the line for the user."""

    motion: str
    at: str | None
    pair: tuple[str, str] | None
    detail: str
    text: str

    @classmethod
    def of(cls, f: MotionFailure) -> MotionStop:
        """The record of ``f``."""
        return cls(f.motion, f.at, (f.pair[0], f.pair[1]) if f.pair else None, f.detail, f.text())

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> MotionStop:
        """From ``reason.motion`` (or an entry of ``reason.motion_failures``)."""
        pair = d.get("pair")
        return cls(d["motion"], d.get("at"), (pair[0], pair[1]) if pair else None, d.get("detail", ""),
                   d.get("text", ""))

    def to_json(self) -> dict[str, Any]:
        """As the plan JSON has it."""
        return {"motion": self.motion, "at": self.at, "pair": list(self.pair) if self.pair else None,
                "detail": self.detail, "text": self.text}


@dataclass(frozen=True)
class SingleArm:
    """A product's single-arm report (``reason.single_arm``, world.product.single_arm_report): ``ok``
    when some order and poses keep every loose mate, ``order`` that order and ``level`` the
    insertions it makes only sideways (``why`` then why none makes every one from above); when not
    ``ok``: ``part`` and ``mate`` of the insertion no reachable state makes, ``why`` and ``poses``
    what each stable pose of the partial product said."""

    ok: bool
    order: tuple[str, ...] = ()
    level: tuple[str, ...] = ()
    why: str = ""
    part: str | None = None
    mate: str | None = None
    poses: tuple[str, ...] = ()

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> SingleArm:
        """From ``reason.single_arm`` (the report's ``to_json()``)."""
        return cls(bool(d["ok"]), tuple(d.get("order") or ()), tuple(d.get("level") or ()), d.get("why", ""),
                   d.get("part"), d.get("mate"), tuple(d.get("poses") or ()))

    def to_json(self) -> dict[str, Any]:
        """As the plan JSON has it."""
        out: dict[str, Any] = {"ok": self.ok}
        if self.ok:
            out["order"] = list(self.order)
            if self.level:
                out.update(level=list(self.level), why=self.why)
        else:
            out.update(part=self.part, mate=self.mate, why=self.why, poses=list(self.poses))
        return out


#: The keys of a reason that a cause writes.
_CAUSE_KEYS = {"bound", "goal", "goal_data", "max_actions", "complete", "instance_cap", "instances_examined",
               "phase", "why", "timeout_s"}
#: The keys of a reason the other fields of an Explanation write.
_OWN_KEYS = {"motion", "motion_failures", "infeasible", "single_arm", "grasps", "phase2", "collisions", "summary"}


@dataclass(frozen=True)
class Explanation:
    """Why a run has no plan (or timed out): its ``cause``; ``motions`` the distinct motion
    failures of the instances examined (the first is the one ``why`` names); ``infeasible`` the
    steps refused for a reason of their own (stability, retention, support), each once in the order
    met; ``single_arm`` and ``grasps`` a product's reports when they say something; ``phase2`` the
    digest of where phase 2's instances stopped; ``collisions`` the lines of the run's collision
    refusals; ``summary`` the one line ``spar plan`` ends with (None for a timeout). ``extra`` keys
    of a read reason this type does not know, kept as they were."""

    cause: Cause | None
    motions: tuple[MotionStop, ...] = ()
    infeasible: tuple[str, ...] = ()
    single_arm: SingleArm | None = None
    grasps: GraspReport | None = None
    phase2: Phase2Digest | None = None
    collisions: tuple[str, ...] = ()
    summary: str | None = None
    extra: tuple[tuple[str, Any], ...] = ()

    @property
    def phase(self) -> int | None:
        """1 (no plan of phase 1), 2 (no executable instance), None (a timeout)."""
        return 1 if isinstance(self.cause, GoalFailure) else 2 if isinstance(self.cause, NoInstance) else None

    def to_json(self) -> dict[str, Any]:
        """The plan JSON's ``reason`` (docs/json-schema.md)."""
        out: dict[str, Any] = self.cause.to_json() if self.cause is not None else {}
        out.update(self.extra)
        if self.motions:
            out["motion"] = self.motions[0].to_json()
            out["motion_failures"] = [m.to_json() for m in self.motions]
        if self.infeasible:
            out["infeasible"] = list(self.infeasible)
        if self.single_arm is not None:
            out["single_arm"] = self.single_arm.to_json()
        if self.grasps is not None:
            out["grasps"] = self.grasps.to_json()
        if self.phase2 is not None:
            out["phase2"] = self.phase2.to_json()
        if self.collisions:
            out["collisions"] = list(self.collisions)
        if self.summary is not None:
            out["summary"] = self.summary
        return out

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> Explanation:
        """From a plan JSON's ``reason``."""
        cause: Cause | None = None
        if "timeout_s" in d:
            cause = Timeout(d["timeout_s"])
        elif d.get("phase") == 2:
            cause = NoInstance(d.get("instances_examined"), d.get("instance_cap"), d.get("complete") is True,
                               d.get("why", ""))
        elif "goal" in d:
            cause = GoalFailure(d.get("max_actions"), d.get("bound"), d["goal"], d.get("goal_data"))
        known = _OWN_KEYS | (_CAUSE_KEYS if cause is not None else set())
        return cls(cause=cause,
                   motions=tuple(MotionStop.from_json(m) for m in d.get("motion_failures") or ()),
                   infeasible=tuple(d.get("infeasible") or ()),
                   single_arm=SingleArm.from_json(d["single_arm"]) if d.get("single_arm") else None,
                   grasps=_grasp_report_of(d["grasps"]) if d.get("grasps") else None,
                   phase2=Phase2Digest.from_json(d["phase2"]) if d.get("phase2") else None,
                   collisions=tuple(d.get("collisions") or ()), summary=d.get("summary"),
                   extra=tuple((k, v) for k, v in d.items() if k not in known))


def _grasp_report_of(d: Mapping[str, Any]) -> GraspReport:
    """A read reason's grasp report (the product room on first use: only a product's no plan has one)."""
    from spar_py.world.product import GraspReport

    return GraspReport.from_json(d)


def timed_out(seconds: float | None) -> Explanation:
    """The explanation of a run that ran out of its ``seconds``."""
    return Explanation(Timeout(seconds))


def _cause(reason: Mapping[str, Any]) -> tuple[Cause | None, tuple[tuple[str, Any], ...]]:
    """The cause the planner's (Prolog's) reason gives, and its keys no cause knows."""
    read = Explanation.from_json(reason)
    return read.cause, read.extra


def _grasp_report(cell: Cell, cache: CellCache, placements: str) -> Any:
    """world.product.grasp_report for a product cell: its robot's gripper (else the default for its
    finger separation), the parts' initial positions for the reach counts, the run's
    collision scene (world.reach.workspace.reach_clear: the arm, the hand closing on the part, the
    other parts) for the arm at pickups and insertions, and phase 1's put-down arcs under the
    run's ``placements`` rule (world.reach.arcs.reachable_pairs) for a regrasp; None without a mesh."""
    from spar_py.world.product import arm_clear_of, grasp_report
    from spar_py.world.reach import reachable_pairs
    from spar_py.world.robot import gripper_for

    assert cell.product is not None
    gripper = gripper_for(cell)
    at: dict[str, np.ndarray] = {}
    for p in cell.positions.values():
        at.setdefault(p.obj, np.asarray(p.T, float))

    def put_down(part: str, grasps: list[Any]) -> set[str]:
        poses = list(cell.objects[part].poses)  # phase 1's put-down: in_position_class(Pos, every pose)
        return {g for g, _ in reachable_pairs(cache, part, [g.label for g in grasps], poses, placements).pairs}

    return grasp_report(cell.product, gripper, cell.unit, cell.robot, at, arm_clear_of(cache), cache.scene().margin,
                        put_down)


def explain(cell: Cell, reason: Mapping[str, Any], run: PlanRun) -> Explanation:
    """Why ``run`` of ``cell`` found no plan. ``reason`` the planner's own (spar.pl: the goal phase 1
    could not meet, or phase 2's count of instances), to which the run adds what it saw: a phase-2
    no plan whose instances failed for want of a motion says which motion (of the first instance
    that got that far) and which pair of bodies blocked it; the steps refused for a reason of their
    own; a product one arm on a table cannot build, which mate and why; a product's first mate no
    grasp serves, and what it needs; where phase 2's instances stopped, the blocking pairs and what
    it needs; the colliding pairs that stood in the way; and the summary line."""
    cause, extra = _cause(reason)
    log = run.world.log
    failures = log.motion_failures
    motions = tuple(MotionStop.of(f) for f in failures) if isinstance(cause, NoInstance) else ()
    if motions and isinstance(cause, NoInstance):
        cause = replace(cause, why=motions[0].text)
    single = grasps = None
    if cell.product is not None:  # a product one arm on a table cannot build: say which mate and why
        from spar_py.world.product import single_arm_report

        sa = single_arm_report(cell.product, cell.unit)
        if sa is not None and (not sa.ok or sa.level):
            single = SingleArm.from_json(sa.to_json())
        if sa is None or sa.ok:  # the grasps: the first mate no grasp serves, and what it needs
            gr = _grasp_report(cell, run.world.cache, run.world.options.placements)
            if gr is not None and not gr.ok:
                grasps = gr
    digest = None
    if isinstance(cause, NoInstance):  # where the instances stopped, the blocking pairs, what it needs
        digest = phase2_digest(cell, run.failures, cause.examined, cause.cap, cause.complete)
    refusals = log.refusals()
    out = Explanation(cause, motions, tuple(run.infeasible), single, grasps, digest,
                      tuple(collision_lines(refusals, run.refusal_instances())), None, extra)
    return replace(out, summary=summary(cell, out.to_json(), refusals))
