"""The planner's lines in the user's terms: why there is no plan, and what a plan expects to fail.

The planner's reason names the Prolog goal that failed deepest (``geo(goal_8, action_2,
reachable(grasp_1, init_pos1), [part_location(peg, init_pos1)])``) or, in phase 2, the
instance failure. :func:`summary` turns it into one line that says which of the cell's goals
could not be met and the nearest cause: a part out of the arm's reach, every grasp refused by
collisions (with the pairs seen most often), no placement for a put-down. :func:`collision_lines`
writes the run's collision refusals, a pair that every refusal shares said once, a refusal many
plan instances met once with their number.
:func:`expected_failures` is the first line of a plan with actions planned for failure.
"""
from __future__ import annotations

import re
from collections import Counter
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from spar_py.core.model import Cell
from spar_py.world.reach import Refusal, pair_text

__all__ = ["Phase2Digest", "collision_lines", "expected_failures", "phase2_digest", "shared_pairs", "summary"]

#: Pairs named in a summary line at most.
PAIRS_SHOWN = 3

#: A refusal's ``what`` for a pickup (world/reach/arcs.py): ``pickup(peg, p1G11) at tr1``.
_PICKUP = re.compile(r"pickup\((?P<obj>[^,]+), (?P<grasp>[^)]+)\) at (?P<label>\S+)$")


def _goal_text(cell: Cell) -> str:
    """The cell's goals as the problem file writes them, short (``assembled(peg, block)``)."""
    return "; ".join(f"{g[0]}({', '.join(str(a) for a in g[1:3])})" for g in cell.goals)


def shared_pairs(refusals: Sequence[Refusal]) -> list[tuple[str, str]]:
    """The pairs every one of ``refusals`` names (none unless there are at least two)."""
    if len(refusals) < 2:
        return []
    common = set(refusals[0].pairs)
    for r in refusals[1:]:
        common &= set(r.pairs)
    return [p for p in refusals[0].pairs if p in common]


def collision_lines(refusals: Sequence[Refusal], instances: Mapping[str, int] | None = None) -> list[str]:
    """One line per refusal; a pair that every refusal shares is said once, first, and left out
    of the lines below it (``upper_arm-table`` on every refused grasp says nothing per grasp).
    ``instances``: for a refusal of phase 2's steps, the number of plan instances whose runs met
    it, said once at the end of its line (``(x37 instances)``) instead of a line per instance."""
    counts = instances or {}
    shared = shared_pairs(refusals)
    out = []
    if shared:
        names = ", ".join(dict.fromkeys(pair_text(p) for p in shared))
        out.append(f"every refused IK solution of this cell collides with {names}; "
                   f"the other pairs of each refusal:")
    for r in refusals:
        rest = list(dict.fromkeys(pair_text(p) for p in r.pairs if p not in shared))
        n = counts.get(r.what, 1)
        times = f" (x{n} instances)" if n > 1 else ""
        out.append(f"no collision-free IK for {r.what}: {', '.join(rest) if rest else 'only the shared pairs'}{times}")
    return out


def _pairs_counted(refusals: Sequence[Refusal]) -> str:
    """The pairs of ``refusals`` most frequent first, with the number of refusals naming each."""
    counts: Counter[str] = Counter()
    for r in refusals:
        counts.update(list(dict.fromkeys(pair_text(p) for p in r.pairs)))
    return ", ".join(f"{p} ({n})" for p, n in counts.most_common(PAIRS_SHOWN))


def _args(term: Any) -> tuple[str, list[Any]]:
    """(functor, args) of a term given as data (foreign.pl's term_data/2); atoms have no args."""
    if isinstance(term, dict) and "functor" in term:
        return str(term["functor"]), list(term["args"])
    return str(term), []


def _refused_line(here: Sequence[Refusal]) -> str:
    """``N refused, most often PAIR (n), ...``."""
    return f"{len(here)} refused, most often {_pairs_counted(here)}"


def _cause(cell: Cell, goal_data: Any, refusals: Sequence[Refusal]) -> str | None:
    """The nearest cause of a phase-1 no plan from the failed goal's term (its constraint, of
    kb/templates/spar_actions.pl, and its context), or None when the term is not a geometric goal."""
    functor, args = _args(goal_data)
    if functor != "geo" or len(args) < 4:
        return None
    kind, cargs = _args(args[2])
    context = [_args(c) for c in args[3]] if isinstance(args[3], list) else []
    where = {str(a[1]): str(a[0]) for f, a in context if f == "part_location" and len(a) == 2}
    held = next((str(a[0]) for f, a in context if f == "holding" and a), None)
    if kind == "reachable" and len(cargs) == 2 and held is not None:  # a put-down
        return (f"a placement is missing: no spot to put {held} down at {cargs[1]} that the arm reaches "
                f"with it in the hand")
    if kind == "reachable" and len(cargs) == 2:  # a pickup
        posname = str(cargs[1])
        obj = where.get(posname)
        pos = next((p for p in cell.positions.values() if p.name == posname), None)
        if pos is None or obj is None:
            return f"no grasp of {obj or 'the part'} at {posname} is reachable"
        here = [r for r in refusals if (m := _PICKUP.match(r.what)) and m["obj"] == obj and m["label"] == pos.label]
        if here:
            return (f"every grasp of {obj} at {posname} ({pos.label}) that the arm reaches collides: "
                    f"{_refused_line(here)}")
        dist = float(np.linalg.norm(pos.T[:3, 3] - cell.robot.base[:3, 3]))
        return (f"{obj} at {posname} ({pos.label}) is out of the arm's reach: no grasp of it has a joint "
                f"solution within {cell.robot.name}'s limits ({dist:.4g} {cell.unit} from its base)")
    if kind == "in_position_class" and len(cargs) == 2:
        posname, poses = str(cargs[0]), [str(p) for p in cargs[1]] if isinstance(cargs[1], list) else []
        obj = where.get(posname) or next((p.obj for p in cell.positions.values() if p.name == posname), posname)
        regions = "placement_regions" if cell.placement_regions else "the table around the parts"
        return (f"a placement is missing: {obj} has to be put down in one of its stable poses "
                f"{', '.join(poses)}, and no spot in the free table ({regions}) is one the arm reaches")
    if kind == "member" and held is not None:
        return f"{held} is held by none of the grasps the assembly leaves free"
    if kind == "mate_reachable" and held is not None:
        fixed = next(iter(where.values()), "the other part")
        here = [r for r in refusals if r.what.startswith(f"assemble({held}, {fixed})")]
        tail = f": every solution collides, {_refused_line(here)}" if here else ""
        return f"the arm cannot reach the assembly of {held} with {fixed}{tail}"
    return f"the geometric condition {kind} of {args[1]} could not be met"


def summary(cell: Cell, reason: dict[str, Any], refusals: Sequence[Refusal]) -> str:
    """One line: ``NO PLAN within N actions (...) for GOALS: CAUSE`` (phase 1: the goal that could not be met and its
    nearest cause; phase 2: why no instance examined could be executed; a product one arm on a table cannot build,
    world.product.single_arm: the insertion and what it needs; a part no grasp serves for its mate,
    world.product.grasp_report: the mate and what it needs)."""
    goals = f"for {_goal_text(cell)}"
    single = reason.get("single_arm") or {}
    if single.get("ok") is False:  # no order and poses keep the loose mates: the cause, whatever the search hit
        return f"NO PLAN {goals}: {single['why']}"
    level = (f"; {single['why']}; the only way left inserts sideways (a level tool): {'; '.join(single['level'])}"
             if single.get("level") else "")
    grasps = reason.get("grasps") or {}
    if grasps.get("ok") is False:  # a part no grasp serves for its mate (world.product.grasp_report): the cause
        return f"NO PLAN {goals}: {grasps['why']}{level}"
    if reason.get("phase") == 2:
        n = reason.get("instances_examined")
        why = reason.get("why", "")
        own = reason.get("infeasible") or []
        digest = reason.get("phase2") or {}
        if own:  # steps refused for a reason of their own (a loose part turned, an unstable body): say those
            why = "; ".join(own[:3]) + (f" (and {len(own) - 3} more)" if len(own) > 3 else "")
        elif digest and "motion" not in reason:  # no joint solution or placement: where, what blocked, what it needs
            why = digest["text"]
        return f"NO PLAN {goals}: none of the {n} plan instances examined can be executed: {why}{level}"
    cause = _cause(cell, reason.get("goal_data"), refusals)
    n, bound = reason.get("max_actions"), reason.get("bound")
    size = f" within {n} actions" if n is not None else ""
    if isinstance(n, int) and isinstance(bound, int):
        size += (f" (the last bound searched completely before the step budget ran out; the bound was {bound})"
                 if n < bound else " (the bound on the plan size; --max-actions raises it)")
    if cause is None:  # not a geometric goal: say so, the term is in --trace and reason.goal
        return f"NO PLAN{size} {goals}: a goal could not be met (--trace names it){level}"
    return f"NO PLAN{size} {goals}: {cause}{level}"


def expected_failures(instance: dict[str, Any] | None) -> str | None:
    """The first line of a plan instance (its JSON) with actions planned for failure (error
    count > 0): how many insertions (assemble actions) and other actions are expected to fail;
    None for a certain plan or without an instance."""
    if not instance or not instance.get("error_count"):
        return None
    names = {s["id"]: s["name"] for s in instance.get("steps", [])}
    failing = [names.get(v["action"], "") for v in instance.get("verifications", [])]
    k = sum(1 for n in failing if n == "assemble")
    others = len(failing) - k
    what = f"{k} insertion{'' if k == 1 else 's'}"
    if others:
        what += f" and {others} other action{'' if others == 1 else 's'}"
    return (f"EXPECTED FAILURES: {what} of this plan {'is' if len(failing) == 1 else 'are'} expected to fail "
            f"(error count {instance['error_count']}): each is verified and has a recovery (below); "
            f"--strict exits 1 on such a plan")


#: Bodies of the cell that are not parts: a pair of one with the table says the spot is wrong.
_FIXED = ("table",)


@dataclass(frozen=True)
class Phase2Digest:
    """Why phase 2 found no executable instance: ``steps`` each step (action text) at which an
    examined instance became infeasible, with the number of instances, most first; at the
    step most failed at (``step``): its ``mate`` (an assemble of a product part, as the grasp
    report names it; None otherwise), the ``grasps`` tried there, the blocking ``pairs``
    (``finger_l-leg5``) each with the number of refusals naming it, most first, the unmet
    conditions ``why``, and ``needs``, what would get past it."""

    examined: int
    steps: list[tuple[str, int]]
    step: str
    mate: str | None
    grasps: list[str]
    pairs: list[tuple[str, int]]
    why: list[str]
    needs: list[str]

    def text(self) -> str:
        """One clause for the summary line."""
        n = self.steps[0][1]
        mate = f" ({self.mate})" if self.mate else ""
        out = f"{n} of the {self.examined} became infeasible at {self.step}{mate}"
        if self.grasps:
            out += f" with {len(self.grasps)} grasp{'' if len(self.grasps) == 1 else 's'} ({', '.join(self.grasps[:4])}"
            out += ", ...)" if len(self.grasps) > 4 else ")"
        if self.pairs:
            out += f" blocked by {', '.join(f'{p} ({k})' for p, k in self.pairs[:PAIRS_SHOWN])}"
        elif self.why:
            out += f": {self.why[0]}"
        others = [f"{s} ({k})" for s, k in self.steps[1:3]]
        if others:
            out += f"; others at {', '.join(others)}" + (", ..." if len(self.steps) > 3 else "")
        if self.needs:
            out += f"; it needs {' or '.join(self.needs)}"
        return out

    @classmethod
    def from_json(cls, d: dict[str, Any]) -> Phase2Digest:
        """From the plan's ``reason.phase2`` (its ``text`` is said again by :meth:`text`)."""
        return cls(d["examined"], [(s["step"], s["instances"]) for s in d.get("steps") or []], d["step"],
                   d.get("mate"), list(d.get("grasps") or []),
                   [(p["pair"], p["refusals"]) for p in d.get("pairs") or []], list(d.get("why") or []),
                   list(d.get("needs") or []))

    def to_json(self) -> dict[str, Any]:
        """The digest as the plan's ``reason.phase2``."""
        return {"examined": self.examined, "steps": [{"step": s, "instances": k} for s, k in self.steps],
                "step": self.step, "mate": self.mate, "grasps": self.grasps,
                "pairs": [{"pair": p, "refusals": k} for p, k in self.pairs], "why": self.why,
                "needs": self.needs, "text": self.text()}


def phase2_digest(cell: Cell, failures: Sequence[Any], examined: int | None, cap: int | None,
                  complete: bool) -> Phase2Digest | None:
    """The digest of phase 2's infeasible runs ``failures`` (planning.run.InstanceFailure, in
    order): each instance's last run says where it stopped. None without any. ``examined``,
    ``cap`` and ``complete`` as the phase-2 reason gives them (a search that hit its cap and
    was not complete may find an instance with a larger cap)."""
    last: dict[Any, Any] = {}
    for f in failures:
        last.pop(f.instance, None)
        last[f.instance] = f
    if not last:
        return None
    ends = list(last.values())
    by_step = Counter(f.term for f in ends)
    step, _ = by_step.most_common(1)[0]
    here = [f for f in ends if f.term == step]
    grasps = list(dict.fromkeys(f.grasp for f in here if f.grasp))
    counts: Counter[str] = Counter()
    blockers: dict[str, set[str]] = {}
    for f in here:
        for _, pairs in f.refusals:
            seen = list(dict.fromkeys(pair_text(p) for p in pairs))
            counts.update(seen)
            for a, b in pairs:
                for body, other in ((a, b), (b, a)):
                    if body in cell.objects and body not in f.args[:2] and body in f.moved:
                        blockers.setdefault(body, set()).add(pair_text((a, b)))
    why = list(dict.fromkeys(w for f in here for w in f.why))
    first = here[0]
    mate = None
    if first.name == "assemble" and cell.product is not None:
        made = {g.part: list(g.mates) for g in cell.product.goals}
        mate = ", ".join(made.get(first.args[0], [])) or None
    needs: list[str] = []
    if blockers:
        held = first.args[0] if first.args else "the part"
        said = "; ".join(f"{b} in place blocks {held}'s grasps: {', '.join(sorted(ps))}" for b, ps in blockers.items())
        needs.append(f"another order ({said})")
    if any(x in _FIXED or y in _FIXED for f in here for _, pairs in f.refusals for x, y in pairs):
        needs.append("another placement or build spot (the arm or hand meets the table)")
    if first.name == "putdown" and not counts and first.args:  # no spot at all, not a blocked one
        needs.append(f"a spot to put {first.args[0]} down that the arm reaches (placement_regions, another pose)")
    n = examined if examined is not None else len(last)
    if cap is not None and n >= cap and not complete:
        needs.append(f"a larger instance search ({n} examined, the cap; more remain: --max-instances raises it)")
    return Phase2Digest(n, by_step.most_common(), step, mate, grasps, counts.most_common(), why, needs)
