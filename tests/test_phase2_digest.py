"""The phase-2 failure digest (planning.messages.phase2_digest): where the examined plan
instances became infeasible, the blocking pairs and what it needs; on a cell whose phase 2
fails, and never on a plan."""
from __future__ import annotations

from pathlib import Path

import pytest

from spar_py.kb import load_problem
from spar_py.planning.messages import phase2_digest
from spar_py.planning.planner import Planner
from spar_py.planning.run import InstanceFailure

KB = Path(__file__).resolve().parents[1] / "kb"


def _fail(order: tuple[str, ...], term: str, pairs: tuple[tuple[str, str], ...], moved: tuple[str, ...],
          grasp: str = "p1G3") -> InstanceFailure:
    name, rest = term.rstrip(")").split("(")
    args = (*(a.strip() for a in rest.split(",")), *((grasp,) if name == "pickup" else ()))
    refusals = ((term, pairs),) if pairs else ()
    return InstanceFailure((order, ()), "action_2", term, name, args, refusals,
                           (f"no collision-free IK for {term}",), grasp, moved)


def test_digest_counts_each_instance_once_at_its_last_run_and_names_what_it_needs() -> None:
    cell = load_problem(KB / "problems" / "peg_in_block.yaml")
    a, b, c = ("a",), ("b",), ("c",)
    failures = [
        _fail(a, "pickup(block)", (("fingers", "table"),), ()),  # a remedy's run; the instance went on
        _fail(a, "pickup(peg)", (("finger_l", "block"), ("forearm", "table")), ("block",)),
        _fail(b, "pickup(peg)", (("finger_l", "block"),), ("block",), grasp="p1G7"),
        _fail(c, "pickup(block)", (("upper_arm", "table"),), ()),
    ]
    d = phase2_digest(cell, failures, 3, 3, complete=False)
    assert d is not None
    assert d.steps == [("pickup(peg)", 2), ("pickup(block)", 1)]
    assert d.step == "pickup(peg)" and d.grasps == ["p1G3", "p1G7"]
    assert d.pairs[0] == ("fingers-block", 2)
    assert any(n.startswith("another order (block in place blocks peg's grasps: fingers-block)") for n in d.needs)
    assert any(n.startswith("another placement") for n in d.needs)
    assert any("larger instance search (3 examined" in n for n in d.needs)
    assert "2 of the 3 became infeasible at pickup(peg)" in d.text()
    # a search that saw every instance, a part never moved and no table: none of those needs
    d2 = phase2_digest(cell, [_fail(b, "assemble(peg, block)", (("finger_l", "block"),), ())], 1, 50, complete=True)
    assert d2 is not None and d2.needs == []
    assert phase2_digest(cell, [], 5, 50, complete=True) is None


def test_a_phase2_no_plan_gets_the_digest_naming_its_step() -> None:
    """enclosed_part: every instance stops at a pickup whose approach the lid blocks (its
    expected summary names the pickup); the digest counts the instances per step."""
    plan = Planner().plan(str(KB / "problems" / "enclosed_part.yaml"))
    r = plan.reason
    assert plan.outcome.value == "no_plan" and r["phase"] == 2
    d = r["phase2"]
    assert sum(s["instances"] for s in d["steps"]) == r["instances_examined"]
    assert d["step"] == "pickup(peg)" and d["steps"][0]["step"] == d["step"]
    assert any("lid_e" in w for w in d["why"])
    assert d["text"] and d["examined"] == r["instances_examined"]


def test_a_putdown_without_a_placement_is_named_with_the_capped_search() -> None:
    """placement_trap under the paper's placement rule: phase 1 plans a put-down of the block
    no spot serves (tests/test_placement_rule.py); with a cap of 5 instances, every one stops
    there, and more instances were left."""
    plan = Planner(paper_placements=True, max_instances=5).plan(str(KB / "problems" / "placement_trap.yaml"))
    r = plan.reason
    d = r["phase2"]
    assert d["steps"] == [{"step": "putdown(block)", "instances": 5}] and d["pairs"] == []
    assert r["complete"] is False and r["instance_cap"] == 5
    assert any("larger instance search (5 examined" in n for n in d["needs"])
    assert any(n.startswith("a spot to put block down") for n in d["needs"])
    assert "5 of the 5 became infeasible at putdown(block)" in r["summary"]


@pytest.mark.parametrize("name", ["peg_in_block", "putdown_blocked"])
def test_no_digest_on_a_plan(name: str) -> None:
    plan = Planner().plan(str(KB / "problems" / f"{name}.yaml"))
    assert plan.ok
    assert "phase2" not in (plan.reason or {})
