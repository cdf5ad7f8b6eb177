"""Issue 35, item 5: each message a newcomer meets is one line that says what is wrong in the
user's terms (a part out of proportion, a large angle in radians, why there is no plan,
the unit of a bound, a plan with expected failures)."""
from __future__ import annotations

import shutil
from pathlib import Path

import pytest

from spar_py.core.errors import KBError
from spar_py.kb import load_problem

from paths import ROOT

KB = ROOT / "kb"


def _metres_mesh_cell(tmp: Path) -> Path:
    """shaft_in_bracket with the shaft's mesh rewritten in metres, its model still saying mm."""
    import trimesh

    (tmp / "objects" / "meshes").mkdir(parents=True)
    (tmp / "robots").mkdir()
    (tmp / "problems").mkdir()
    m = trimesh.load(str(KB / "objects/meshes/hex_shaft.stl"), force="mesh")
    m.apply_scale(0.001)
    m.export(str(tmp / "objects/meshes/hex_shaft.stl"))
    shutil.copy(KB / "objects/meshes/bracket.stl", tmp / "objects/meshes/bracket.stl")
    shutil.copy(KB / "objects/bracket.yaml", tmp / "objects/bracket.yaml")
    (tmp / "objects/hex_shaft.yaml").write_text((KB / "objects/hex_shaft.yaml").read_text()
                                               .replace("radius: 12", "radius: 0.012"))
    shutil.copy(KB / "robots/puma762.yaml", tmp / "robots/puma762.yaml")
    prob = tmp / "problems/shaft_in_bracket.yaml"
    shutil.copy(KB / "problems/shaft_in_bracket.yaml", prob)
    return prob


def test_part_out_of_proportion_names_file_part_size_and_asks_for_the_unit(tmp_path: Path) -> None:
    prob = _metres_mesh_cell(tmp_path)
    with pytest.raises(KBError) as e:
        load_problem(prob)
    msg = str(e.value)
    assert "\n" not in msg
    assert "objects/hex_shaft.yaml: mesh: expected a part of a size in proportion to the cell" in msg
    assert "hex_shaft is 0.065 mm across, under 1 mm" in msg
    assert "is the file's length unit (mm" in msg
    assert "stable pose" not in msg


def test_part_sizes_of_the_kb_pass() -> None:
    for name in ("shaft_in_bracket", "peg_in_block_shapes", "ur5e_peg_in_block"):
        assert load_problem(KB / "problems" / f"{name}.yaml").objects


def _rad_cell(tmp: Path, allow: bool) -> Path:
    """The paper's cell in radians, its peg's dtheta written as [-3, 3] (degrees meant)."""
    text = (KB / "problems/peg_in_block.yaml").read_text()
    text = text.replace("units: {length: in, angle: deg}", "units: {length: in, angle: rad}")
    text = text.replace("../robots/", str(KB / "robots") + "/").replace("../objects/", str(KB / "objects") + "/")
    lines = text.splitlines()
    for i, line in enumerate(lines):
        if "dtheta" in line:  # every bound: the cell's few degrees read as that many radians
            lines[i] = line[:line.index("dtheta")] + "dtheta: [-0.01, 0.01]}"
    peg = next(i for i, line in enumerate(lines) if line.strip().startswith("peg:") and "dtheta" in line)
    lines[peg] = lines[peg].replace("dtheta: [-0.01, 0.01]", "dtheta: [-3, 3]")
    if allow:
        lines.append("allow_large_angles: true")
    p = tmp / "rad.yaml"
    p.write_text("\n".join(lines) + "\n")
    return p


def test_large_angle_in_radians_is_an_error_unless_allowed(tmp_path: Path) -> None:
    with pytest.raises(KBError) as e:
        load_problem(_rad_cell(tmp_path, allow=False))
    msg = str(e.value)
    assert "\n" not in msg
    assert "uncertainty.objects.peg.dtheta: expected an angle bound within 90 deg" in msg
    assert "3 rad is 172 deg" in msg and "allow_large_angles: true" in msg
    cell = load_problem(_rad_cell(tmp_path, allow=True))
    assert cell.object_bounds["peg"].dtheta == (-3.0, 3.0)


# ---------------------------------------------------------------- no plan, in the user's terms

NO_PLAN_LINES = {
    "unreachable": "NO PLAN within 12 actions "
                   "(the bound on the plan size; --max-actions raises it) for assembled(peg, block): "
                   "peg at init_pos1 (tr1) is out of the arm's reach: no grasp of it has a joint solution "
                   "within puma762's limits (102.7 in from its base)",
    "collision_no_plan": "NO PLAN within 7 actions "
                         "(the last bound searched completely before the step budget ran out; the bound was 12) "
                         "for assembled(peg, block): "
                         "every grasp of peg at init_pos1 (tr1) "
                         "that the arm reaches collides: 6 refused, most often tool_mount-shelf (4), "
                         "forearm-shelf (1), palm-table (1)",
    "placement_trap": "NO PLAN within 12 actions "
                      "(the bound on the plan size; --max-actions raises it) for assembled(peg, block): "
                      "a placement is missing: block has to be put down in one of its stable poses "
                      "p2P1, p2P2, p2P4, p2P5, p2P6, and no spot in the free table (placement_regions) is one the "
                      "arm reaches",
    "enclosed_part": "NO PLAN for assembled(peg, block): none of the 8 plan instances examined can be executed: no "
                     "approach to action_2 (pickup(peg, p1G10)), blocked by finger_l and lid_e: the tool line is "
                     "blocked 2 along it",
}


@pytest.mark.parametrize("name", sorted(NO_PLAN_LINES))
def test_no_plan_ends_with_one_line_in_the_users_terms(planner, name: str) -> None:
    plan = planner.plan(KB / "problems" / f"{name}.yaml")
    assert plan.outcome.value == "no_plan"
    assert plan.reason["summary"] == NO_PLAN_LINES[name]
    assert "goal" in plan.reason or "why" in plan.reason  # the JSON keeps its keys
    assert "geo(" not in plan.trace  # the Prolog goal term is --trace's


def test_the_prolog_goal_term_is_in_the_trace(planner) -> None:
    plan = planner.plan(KB / "problems/unreachable.yaml", trace=True)
    assert "the goal that could not be met: geo(goal_8,action_2,reachable(grasp_1,init_pos1)" in plan.trace


def test_a_pair_every_refusal_shares_is_said_once() -> None:
    from spar_py.planning.messages import collision_lines
    from spar_py.world.reach.workspace import Refusal

    lines = collision_lines([Refusal("pickup(peg, p1G1) at tr1", (("upper_arm", "table"), ("palm", "block"))),
                             Refusal("pickup(peg, p1G2) at tr1", (("finger_l", "block"), ("upper_arm", "table"))),
                             Refusal("pickup(block, p2G1) at tr2", (("upper_arm", "table"),))])
    assert lines == ["every refused IK solution of this cell collides with upper_arm-table; "
                     "the other pairs of each refusal:",
                     "no collision-free IK for pickup(peg, p1G1) at tr1: palm-block",
                     "no collision-free IK for pickup(peg, p1G2) at tr1: fingers-block",
                     "no collision-free IK for pickup(block, p2G1) at tr2: only the shared pairs"]
    assert sum("upper_arm-table" in line for line in lines) == 1


def test_a_refusal_many_instances_met_is_one_line_with_their_number() -> None:
    from spar_py.planning.messages import collision_lines
    from spar_py.world.reach.workspace import Refusal

    refusals = [Refusal("assemble(gear_a, shaft_a)", (("fingers", "gear_b"),)),
                Refusal("pickup(gear_a, gear_a_g15)", (("palm", "housing"),))]
    lines = collision_lines(refusals, {"assemble(gear_a, shaft_a)": 37, "pickup(gear_a, gear_a_g15)": 1})
    assert lines == ["no collision-free IK for assemble(gear_a, shaft_a): fingers-gear_b (x37 instances)",
                     "no collision-free IK for pickup(gear_a, gear_a_g15): palm-housing"]


# ---------------------------------------------------------------- units of the bounds

@pytest.mark.parametrize("name, unit", [("peg_in_block", "in"), ("shaft_in_bracket", "mm")])
def test_every_bound_is_printed_with_its_unit(planner, name: str, unit: str) -> None:
    import re

    plan = planner.plan(KB / "problems" / f"{name}.yaml")
    lines = [ln for ln in plan.trace.splitlines() if ": bound " in ln]
    assert lines
    for ln in lines:
        squared = " centres:" in ln
        u = f"{unit}^2" if squared else unit
        assert re.search(rf": bound -?[0-9.]+ {re.escape(u)} [<>] -?[0-9.e-]+ {re.escape(u)}: ", ln), ln
    assert any(" centres:" in ln for ln in lines)
    assert all(v["unit"] in (unit, f"{unit}^2") for v in plan.instance["constraints"] if v["kind"] == "uncertainty")


# ---------------------------------------------------------------- expected failures, --strict

def test_strict_planner_raises_on_expected_failures_and_the_plan_says_how_many(planner) -> None:
    from spar_py.core.errors import ExpectedFailures, SparError
    from spar_py.planning.planner import Planner

    hopeless = KB / "problems/hopeless_uncertainty.yaml"
    plan = planner.plan(hopeless)  # not strict: returned, like a certain plan
    assert plan.ok and plan.error_count == 3
    strict = Planner(strict=True)
    with pytest.raises(ExpectedFailures) as e:
        strict.plan(hopeless)
    assert isinstance(e.value, SparError) and e.value.plan.error_count == 3
    assert str(e.value).startswith("EXPECTED FAILURES: 1 insertion and 2 other actions of this plan are expected "
                                   "to fail (error count 3)")
    assert strict.plan(KB / "problems/peg_in_block.yaml").error_count == 0  # a certain plan: returned


def test_strict_cli_exits_1_and_the_first_line_counts_the_insertions() -> None:
    import subprocess
    import sys

    def spar(*args: str) -> subprocess.CompletedProcess:
        return subprocess.run([sys.executable, "-m", "spar_py", "plan", *args], capture_output=True, text=True,
                              cwd=ROOT, timeout=300, check=False)

    for strict, code in ((False, 0), (True, 1)):
        r = spar("kb/problems/hopeless_uncertainty.yaml", *(["--strict"] if strict else []))
        assert r.returncode == code, r.stderr
        assert r.stdout.splitlines()[0].startswith("EXPECTED FAILURES: 1 insertion and 2 other actions")
    assert r.stderr == "spar: --strict: a plan with expected failures (error count 3)\n"
    r = spar("kb/problems/peg_in_block.yaml", "--strict")
    assert r.returncode == 0 and r.stdout.startswith("PLAN ACTIONS")


def _geo(kind: str, args: list, context: list) -> dict:
    """A phase-1 reason for a failed geometric goal, as spar.pl writes it (term data)."""
    return {"max_actions": 6, "bound": 6, "goal": "geo(...)",
            "goal_data": {"functor": "geo", "args": ["goal_9", "action_3", {"functor": kind, "args": args},
                                                     [{"functor": f, "args": a} for f, a in context]]}}


def test_each_kind_of_failed_goal_has_its_cause_in_the_users_terms() -> None:
    from spar_py.planning.messages import summary
    from spar_py.world.reach.workspace import Refusal

    cell = load_problem(KB / "problems/peg_in_block.yaml")
    putdown = summary(cell, _geo("reachable", ["grasp_1", "pos_1"], [("holding", ["block", "grasp_1"])]), [])
    assert putdown.endswith(": a placement is missing: no spot to put block down at pos_1 that the arm reaches "
                            "with it in the hand")
    member = summary(cell, _geo("member", ["grasp_2", ["p1G1"]], [("holding", ["peg", "grasp_2"])]), [])
    assert member.endswith(": peg is held by none of the grasps the assembly leaves free")
    refused = [Refusal("assemble(peg, block) with p1G17 at tr2", (("fingers", "block"),)),
               Refusal("assemble(peg, block) with p1G19 at tr2", (("fingers", "block"), ("palm", "table")))]
    mate = summary(cell, _geo("mate_reachable", ["grasp_2", "init_pos2", "trans_1"],
                              [("holding", ["peg", "grasp_2"]), ("part_location", ["block", "init_pos2"])]), refused)
    assert mate.endswith(": the arm cannot reach the assembly of peg with block: every solution collides, "
                         "2 refused, most often fingers-block (2), palm-table (1)")
    for line in (putdown, member, mate):
        assert line.startswith("NO PLAN within 6 actions (the bound on the plan size; --max-actions raises it) "
                               "for assembled(peg, block): ")
        assert "geo(" not in line and "\n" not in line
