"""Phase 2's nogoods: what a run of a plan instance that stopped at a step it could not execute
says about every other instance of the same partial plan (prolog/partial_plan.pl's instance search
skips the instances it rules out, and tries first another label for the failing step).

A nogood is a dict ``{"step", "labels", "prefix", "before"}`` of action ids: any instance that binds
the network variables of ``step`` and of each action of ``labels`` as this one did, whose order
starts with ``prefix`` and puts ``a`` before ``b`` for each ``[a, b]`` of ``before``, stops at
``step`` too, or earlier (Prolog turns the ids into variable bindings, partial_plan:instance_nogood/4).

Two kinds, the first wherever it is sure (:func:`nogood`), the second otherwise:

- *The parts it depends on* (:func:`_history`): the step's verdict is a function of its own labels
  (the grasp, where the part is taken from), the ideal poses of a few parts and the make-up of the
  moving body; those poses follow from the moves of those parts and of the parts they rest in, in
  their order. ``before`` fixes that order and keeps every other move of them after the step;
  nothing else about the instance matters.
- *The whole prefix* (:func:`exact_prefix`): the steps before it, in order, with their labels, and
  what a put-down in it waits for (its placement is chosen knowing the later uses of the part).

Steps a remedy inserts (sensing, squeezes) move no part's ideal pose and are left out.
"""
from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from spar_py.phase2 import uncertainty as ur
from spar_py.phase2.rest import stacked_on
from spar_py.phase2.state import Step, World, stock_of

__all__ = ["exact_prefix", "nogood"]

#: Steps a remedy inserts: they change uncertainties, never an ideal pose.
_INSERTED = ("dense_range_scan", "squeeze")


def nogood(before: World, after: World, steps: Sequence[Step], at: int, checks: list[dict[str, Any]]
           ) -> dict[str, Any] | None:
    """The nogood of the run of ``steps`` that stopped at ``steps[at]`` (``s``), infeasible: ``before``
    and ``after`` the worlds around it, ``checks`` its verdicts. None if ``s`` is a step a remedy
    inserted (it is no action of the partial plan) or none of its geometric verdicts failed.

    Each failed geometric verdict alone makes the step infeasible, so the nogood of any one of them
    is sound; the one with the fewest order conditions is kept. Per verdict, the parts it reads:

    - ``reachable`` (the arm): with no joint solution at all, only the tool pose, hence the pose of
      the part picked (pickup) or of the part mated onto (assemble) and the grasp. With solutions
      that all collide, each collides with a pair the refusal names: those parts at the same poses
      refuse every solution again (the solutions are the tool pose's, workspace.arm_at), and a part
      elsewhere frees none; the moving body too, whole (its parts are carried, and decide which
      may touch the table), and at an assemble the body it goes into, whole (it decides which part
      the held body may touch, the one its mate is checked against).
    - ``via_grasp``: the make-up of the part's body (is the part held by the grasp in it).
    - ``supported``: the body and the part resting on it (more parts never lift it).
    - ``retention``: the moving body and the body it goes into (the mate turned is one of theirs,
      at their poses after the step).
    - any other (a put-down: its placement, stability, sub-pose), or a part of a stock, or a body
      lying where a put-down left it: the whole prefix (:func:`exact_prefix`).

    A pickup or assemble of a part that is itself mated into another is left to the prefix too."""
    s = steps[at]
    if s["name"] in _INSERTED:
        return None
    bad = [c for c in checks if c["kind"] == "geometric" and not c["satisfied"]]
    if not bad:
        return None
    manip = [t for t in steps if t["name"] not in _INSERTED]
    k = next(i for i, t in enumerate(manip) if t["id"] == s["id"])
    best: dict[str, Any] | None = None
    for c in bad:
        reads = _reads(before, after, s, str(c.get("constraint")))
        got = None if reads is None else _history(before, manip, k, *reads)
        if got is not None and (best is None or len(got["before"]) < len(best["before"])):
            best = got
    return best if best is not None else exact_prefix(manip, k)


def _reads(before: World, after: World, s: Step, kind: str) -> tuple[set[str], set[str]] | None:
    """(the parts whose poses the verdict ``kind`` of step ``s`` reads, the roots of the bodies whose
    make-up it reads), or None where it reads a placement or more (:func:`nogood`'s list)."""
    unc = before.unc
    obj = str(s["args"][0])
    if s["name"] not in ("pickup", "assemble") or obj not in unc.objects or unc.root(obj) != obj:
        return None
    body = set(unc.body(obj))
    hole = {str(s["args"][1])} if s["name"] == "assemble" else set()
    if hole and not hole <= set(unc.objects):
        return None
    into = set(unc.body(unc.root(next(iter(hole))))) if hole else set()
    if kind == "reachable":
        if not after.refused:  # no joint solution: the tool pose alone
            return (hole or {obj}), set()
        named = {n.removeprefix("held:") for _, pairs in after.refused for pair in pairs for n in pair}
        # an assemble's allowed contacts are with the part its mate is checked against, which its
        # goal's mates and the body it goes into decide (phase2/mates.py's carried_mate)
        return body | hole | into | (named & set(unc.objects)), ({obj} | {unc.root(h) for h in hole})
    if kind == "via_grasp":
        return body, {obj}
    if kind == "supported":
        on = stacked_on(before, obj)
        return None if on is None else (body | {on}, {obj})
    if kind == "retention":
        return body | hole | into, {obj} | {unc.root(h) for h in hole}
    return None


def _history(before: World, manip: list[Step], k: int, parts: set[str], exact: set[str]) -> dict[str, Any] | None:
    """The nogood of step ``manip[k]`` whose verdict reads the ideal poses of ``parts`` and the make-up
    of the bodies rooted at ``exact`` (besides its own labels); None where a pose is a put-down's
    placement or a part is of a stock (the run's names of a stock's parts follow the plan).

    A part's ideal pose before the step follows from its moves (pickups, put-downs, assembles of it:
    ``args[0]``) and those of the parts it rests in: its parent and the part its assemble named,
    and theirs, up to a body's root on the table or in the hand (``R``, the closure). A part is
    mated once and, once mated, moves only with its root (no pickup of a mated part); a root never
    moved lies where the cell lays it; an assembled part lies at the mated part's pose times T_a
    whatever its grasp. So the same moves of ``R`` in the same order each part to its ancestors,
    none of the other moves of ``R`` before the step, and no root of ``R`` lying at a placement,
    give each part of ``R`` the same pose; and no assemble into a body of ``exact`` other than
    the run's gives it the same make-up. That is ``before``; the step's own labels bind its grasp
    and where its part is taken from."""
    unc, cell = before.unc, before.cell
    s, prefix, rest = manip[k], manip[:k], manip[k + 1:]
    stock = stock_of(cell)
    made = {str(t["args"][0]): str(t["args"][1]) for t in prefix if t["name"] == "assemble"}
    deps: dict[str, set[str]] = {}
    todo = list(parts)
    while todo:
        p = todo.pop()
        if p in deps:
            continue
        if p not in unc.objects or "@" in p or p in stock:
            return None
        up = {unc.attached[p].parent} if p in unc.attached else set()
        up |= {made[p]} if p in made else set()
        deps[p] = up
        todo += sorted(up)
    moves = {p: [i for i, t in enumerate(prefix) if str(t["args"][0]) == p] for p in deps}
    for p in deps:
        r = unc.root(p)
        if unc.obj(r).where != ur.HAND and moves[r] and prefix[moves[r][-1]]["name"] == "putdown":
            return None  # it lies at a placement, chosen knowing the whole plan
    ids = [t["id"] for t in prefix]
    pairs: set[tuple[str, str]] = set()
    for p in deps:
        own = moves[p]
        pairs |= {(ids[i], ids[j]) for i, j in zip(own, own[1:])}
        if own:
            pairs.add((ids[own[-1]], s["id"]))
        for q in _ancestors(deps, p):
            pairs |= {(ids[min(i, j)], ids[max(i, j)]) for i in own for j in moves[q]}
    grow = {x for r in exact for x in unc.body(r)}
    later = [t["id"] for t in rest
             if str(t["args"][0]) in deps or (t["name"] == "assemble" and str(t["args"][1]) in grow)]
    pairs |= {(s["id"], t) for t in later}
    return {"step": s["id"], "labels": [], "prefix": [], "before": [list(p) for p in sorted(pairs)]}


def _ancestors(deps: dict[str, set[str]], p: str) -> set[str]:
    """The parts ``p``'s pose follows from: its parent and mated part, and theirs (``deps``)."""
    out: set[str] = set()
    todo = list(deps[p])
    while todo:
        q = todo.pop()
        if q not in out:
            out.add(q)
            todo += deps.get(q, ())
    return out


def exact_prefix(manip: Sequence[Step], k: int) -> dict[str, Any]:
    """The nogood of step ``manip[k]`` that fixes everything before it (``manip``: an instance's
    manipulation steps in order): the world before a step, and its verdict, are a function of the
    steps before it, in order, with their labels (their grasps, positions, the parts they take),
    and of the placement of each put-down among them and it (phase2/placements.py). A placement is
    chosen knowing what the part's later uses need until it is picked up again: the assembles onto
    it, the grasps their pegs are held by (the pegs' pickups) and the grasp of that pickup, in
    their order; the part tops it may go on depend only on which parts are picked up later (the
    prefix says). So a put-down the prefix leaves on the table adds those steps after it, in the
    run's order, with their labels. ``step`` goes right after the prefix (it is in ``prefix``)."""
    s, prefix, rest = manip[k], list(manip[:k]), list(manip[k + 1:])
    done = prefix + [s]
    labels = [t["id"] for t in prefix]
    pairs: list[list[str]] = []
    for i, t in enumerate(done):
        x = str(t["args"][0])
        if t["name"] != "putdown" or any(u["name"] == "pickup" and str(u["args"][0]) == x for u in done[i + 1:]):
            continue
        pegs = {str(u["args"][0]) for u in rest if u["name"] == "assemble" and str(u["args"][1]) == x}
        uses = [u for u in rest if (u["name"] == "pickup" and str(u["args"][0]) in pegs | {x})
                or (u["name"] == "assemble" and str(u["args"][1]) == x)]
        labels += [u["id"] for u in uses if u["id"] not in labels]
        pairs += [[a["id"], b["id"]] for a, b in zip(uses, uses[1:])]
    return {"step": s["id"], "labels": labels, "prefix": [t["id"] for t in done], "before": pairs}
