"""Phase 2's nogoods (phase2/nogood.py, prolog/partial_plan.pl's next_instance/3): an infeasible
run of a plan instance says on what condition any instance of the same partial plan fails at the
same step, and the instance search skips those instances without running them.

Checked here on the run itself, not on the code that derives the condition: the instance a
nogood came from is run again with the steps before the failing one in other orders that keep
the nogood's order (``before``), and each run that gets that far must stop there, infeasible.
tests/test_phase2_search.py checks the nogoods against every instance of small cells.
"""
from __future__ import annotations

import random

import pytest

from spar_py.core.errors import SparValueError
from spar_py.phase2 import instance as phase2
from spar_py.planning import run as planning_run
from spar_py.kb import load_problem
from spar_py.planning.planner import Planner
from spar_py.world.product.grasp_report import seat_order

from paths import ROOT


@pytest.fixture(scope="module")
def stool_nogoods():
    """The stool's plan, and every (steps, sources, nogood) of its infeasible runs, with the run's cache."""
    got: list[tuple[list, dict, dict]] = []
    caches = []
    orig = planning_run.PlanRun.evaluate

    def evaluate(self, steps, sources=None, given_up=(), sensing=None):
        out = orig(self, steps, sources, given_up, sensing)
        if out.get("nogood") is not None:
            got.append(([dict(s) for s in steps], dict(sources or {}), out["nogood"]))
            caches.append(self.world.cache)
        return out

    planning_run.PlanRun.evaluate = evaluate
    try:
        plan = Planner().plan(ROOT / "kb" / "problems" / "fabrica_stool_circular.yaml")
    finally:
        planning_run.PlanRun.evaluate = orig
    return plan, got, caches


def _blocks(steps: list[dict]) -> list[list[dict]]:
    """The manipulation steps as blocks: a part's pickup with the steps up to its assemble."""
    out: list[list[dict]] = []
    for s in steps:
        if str(s["id"]).startswith(("sense", "squeeze")) or not isinstance(s["id"], str):
            continue
        if s["name"] == "pickup" or not out:
            out.append([s])
        else:
            out[-1].append(s)
    return out


def _random_order(blocks: list[list[dict]], part: dict[int, str], before: dict[str, set[str]],
                  rng: random.Random) -> list[list[dict]]:
    """The blocks in a random order that keeps every part after the parts the product puts before
    it (its tree and its precedence: grasp_report.seat_order), among those in ``blocks``."""
    left, out, done = blocks[:], [], set()
    names = {part[id(b)] for b in blocks}
    while left:
        ready = [b for b in left if (before.get(part[id(b)], set()) & names) <= done]
        b = rng.choice(ready or left)
        out.append(b)
        done.add(part[id(b)])
        left.remove(b)
    return out


def test_the_stool_plans_and_learns_nogoods(stool_nogoods):
    plan, got, _ = stool_nogoods
    assert plan.outcome.value == "plan"
    assert got, "no infeasible run gave a nogood"
    for _, _, ng in got:
        assert ng["step"] and set(ng) == {"step", "labels", "prefix", "before"}


def test_every_nogood_holds_in_other_orders_of_its_prefix(stool_nogoods):
    """The prefix's blocks shuffled (the failing step's own block stays last), keeping the nogood's
    ``before`` pairs: each run that gets to the nogood's step is infeasible there."""
    _, got, caches = stool_nogoods
    rng = random.Random(7)
    cell = load_problem(ROOT / "kb" / "problems" / "fabrica_stool_circular.yaml")
    before = seat_order(cell.product)[1]
    confirmed = 0
    for (steps, sources, ng), cache in zip(got, caches):
        assert not ng["prefix"], "the stool has no put-down: its nogoods need no prefix"
        blocks = _blocks(steps)
        at = next(i for i, b in enumerate(blocks) if any(s["id"] == ng["step"] for s in b))
        head, own = blocks[:at], blocks[at]
        own = own[:next(k for k, s in enumerate(own) if s["id"] == ng["step"]) + 1]
        part = {id(b): str(b[0]["args"][0]) for b in head}
        for _ in range(60):
            order = _random_order(head, part, before, rng)
            trial = [s for b in order for s in b] + own
            pos = {s["id"]: i for i, s in enumerate(trial)}
            if any(a in pos and b in pos and pos[a] > pos[b] for a, b in ng["before"]):
                continue  # an order the nogood does not speak of
            assert all(a in pos for a, b in ng["before"] if b == ng["step"])
            try:
                ev = phase2.evaluate(cache, trial, sources, given_up=[s["id"] for s in trial])
            except SparValueError:
                continue  # an order the product refuses (a foot before its leg)
            if ev.status == "infeasible" and ev.at != ng["step"]:
                continue  # stopped earlier, for a reason of that order
            assert ev.status == "infeasible" and ev.at == ng["step"], (ng, [s["id"] for s in trial])
            confirmed += 1
    assert confirmed >= 2
