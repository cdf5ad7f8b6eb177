"""Issue 8: put-downs the arm can really reach, against the paper's stable-pose rule."""
from __future__ import annotations

import numpy as np
import pytest

from spar_py.core.geometry import rotz, trans
from spar_py.kb import load_problem
from spar_py.planning.planner import Planner

from paths import ROOT


def _reaches(fk: np.ndarray, tool_pose: list) -> bool:
    """Whether forward kinematics of a step's joints gives its tool pose: rotations within 1e-6;
    positions within 1e-4 of the cell unit, since the JSON gives joints to 1e-6 deg, which moves
    a tool at 1 m reach by up to 6 x 1.7e-8 rad x 1000 mm = 1e-4 mm (more than 1e-6 of a mm)."""
    T = np.asarray(tool_pose, float)
    fk = np.asarray(fk, float)
    return bool(np.allclose(fk[..., :3, :3], T[:3, :3], atol=1e-6)
                and np.abs(fk[..., :3, 3] - T[:3, 3]).max() <= 1e-4)
TRAP = ROOT / "kb/problems/placement_trap.yaml"


def test_paper_rule_accepts_a_plan_the_arm_cannot_execute() -> None:
    """Phase 1 under the paper's rule gives Fig. 23's four actions; phase 2 can execute
    none of its instances, so the outcome is no plan, with phase 2's reason."""
    plan = Planner(paper_placements=True, max_instances=5).plan(TRAP).to_json()
    assert plan["outcome"] == "no_plan" and len(plan["partial"]["actions"]) == 4
    inst = plan["instance"]
    assert inst["steps"] == [] and "no instance could be executed" in inst["reason"]
    assert plan["reason"]["phase"] == 2 and plan["reason"]["instances_examined"] == 5
    assert plan["reason"]["why"] == inst["reason"]


def test_reachable_rule_refuses_the_branch_and_says_why() -> None:
    """No stable pose of the block has a reachable spot with its whole footprint on the
    shelf, so phase 1 cannot bring it into the hole-up classes the assembly needs."""
    plan = Planner().plan(TRAP).to_json()
    assert plan["outcome"] == "no_plan"
    assert "in_position_class(init_pos2,[p2P1,p2P2,p2P4,p2P5,p2P6])" in plan["reason"]["goal"]


def test_every_putdown_placement_checks_out_by_fk() -> None:
    cell = load_problem(ROOT / "kb/problems/peg_in_block.yaml")
    inst = Planner().plan(cell).to_json()["instance"]
    puts = [s for s in inst["steps"] if s["name"] == "putdown"]
    assert puts
    for s in puts:
        p = s["placement"]
        assert p is not None and p["z"] == cell.objects[s["object"]].poses[p["pose"]].height
        q = np.radians(s["joints_deg"])
        assert _reaches(cell.robot.fk(q), s["tool_pose"])


@pytest.mark.parametrize("name", sorted(p.stem for p in (ROOT / "kb/problems").glob("*.yaml")))
def test_every_regression_putdown_has_a_placement_checked_by_fk(name: str) -> None:
    cell = load_problem(ROOT / "kb/problems" / f"{name}.yaml")
    plan = Planner(max_instances=3).plan(cell).to_json()
    inst = plan["instance"] or {"steps": []}
    for s in inst["steps"]:
        if s["kind"] == "sensing":
            continue
        q = np.radians(s["joints_deg"])
        assert cell.robot.in_limits(q)
        assert _reaches(cell.robot.fk(q), s["tool_pose"])
        sols = np.radians(s["ik_solutions_deg"])
        assert len(sols) >= 1 and cell.robot.in_limits(sols).all()
        assert _reaches(cell.robot.fk_batch(sols), s["tool_pose"])
        if s["name"] == "putdown":
            # the tool pose is the placement's object pose times one of the object's grasps
            p, model = s["placement"], cell.objects[s["object"]]
            T_obj = trans(p["x"], p["y"], p["z"]) @ rotz(np.radians(p["yaw_deg"]))
            T_obj[:3, :3] = T_obj[:3, :3] @ model.poses[p["pose"]].R
            T_g = np.linalg.inv(T_obj) @ np.array(s["tool_pose"])
            assert any(np.allclose(T_g, g.T, atol=1e-6) for g in model.grasps.values())
