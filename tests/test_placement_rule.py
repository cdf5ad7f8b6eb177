"""Issue 8: put-downs the arm can really reach, against the paper's stable-pose rule."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from spar_py.kb import load_problem
from spar_py.planner import Planner

ROOT = Path(__file__).resolve().parent.parent
TRAP = ROOT / "kb/problems/placement_trap.yaml"


def test_paper_rule_accepts_a_plan_the_arm_cannot_execute() -> None:
    plan = Planner(paper_placements=True, max_instances=5).plan(TRAP).to_json()
    assert plan["outcome"] == "plan" and len(plan["partial"]["actions"]) == 4
    inst = plan["instance"]
    assert inst["steps"] == [] and "no instance could be executed" in inst["reason"]


def test_reachable_rule_refuses_the_branch_and_says_why() -> None:
    plan = Planner().plan(TRAP).to_json()
    assert plan["outcome"] == "no_plan"
    assert "reachable(grasp_2,pos_1)" in plan["reason"]["goal"]


def test_every_putdown_placement_checks_out_by_fk() -> None:
    cell = load_problem(ROOT / "kb/problems/peg_in_block.yaml")
    inst = Planner().plan(cell).to_json()["instance"]
    puts = [s for s in inst["steps"] if s["name"] == "putdown"]
    assert puts
    for s in puts:
        p = s["placement"]
        assert p is not None and p["z"] == cell.objects[s["object"]].poses[p["pose"]].height
        q = np.radians(s["joints_deg"])
        assert np.allclose(cell.robot.fk(q), np.array(s["tool_pose"]), atol=1e-6)
