"""Phase 2 end to end (Secs. 3.2, 4.3): verdicts, sensing, squeezes, verification, the
execution check, one bridge call per run of an instance, the per-step world."""
from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from spar_py.planning import engine as engine_module
from spar_py.phase2 import instance as phase2
from spar_py.core.geometry import rotz
from spar_py.kb import load_problem
from spar_py.planning.planner import Planner
from spar_py.world.collision import CellCache

from paths import ROOT

PROBLEMS = ROOT / "kb" / "problems"


@pytest.fixture(scope="module")
def planner() -> Planner:
    return Planner(max_instances=5)


def _steps(instance: dict) -> list[dict]:
    """The instance's steps as phase2 takes them: id, name, args (term data, as the JSON
    has them), source."""
    return [{"id": s["id"], "name": s["name"], "args": s["args"]} | ({"source": s["source"]} if s.get("source") else {})
            for s in instance["steps"]]


def _execution_check(problem: str, instance: dict) -> list[dict]:
    """Replay the instance at 10^4 draws of its uncertainty variables (issue 5's execution check)."""
    return phase2.sample_check(CellCache(load_problem(PROBLEMS / f"{problem}.yaml")), _steps(instance), draws=10_000)


def test_paper_cell_all_constraints_hold(planner: Planner) -> None:
    plan = planner.plan(PROBLEMS / "peg_in_block.yaml").to_json()
    inst = plan["instance"]
    assert [s["name"] for s in inst["steps"]] == ["pickup", "putdown", "pickup", "assemble"]
    assert inst["error_count"] == 0 and inst["verifications"] == [] and inst["recoveries"] == []
    # four pickup inequalities for each pickup, one for the assemble, each with its bound
    names = [(c["action"], c["constraint"]) for c in inst["constraints"]]
    assert names.count(("action_1", "centres")) == 1
    assert sum(1 for a, _ in names if a in ("action_2", "action_4")) == 8
    assert all(c["satisfied"] and isinstance(c["bound"], float) for c in inst["constraints"])
    checks = _execution_check("peg_in_block", inst)
    assert len(checks) == 9 and all(c["failed_draws"] == 0 for c in checks)


def test_joint_angles_check_out_by_forward_kinematics(planner: Planner) -> None:
    cell = load_problem(PROBLEMS / "peg_in_block.yaml")
    inst = planner.plan(cell).to_json()["instance"]
    for s in inst["steps"]:
        if s["kind"] != "manipulation":
            continue
        q = np.radians(s["joints_deg"])
        assert cell.robot.in_limits(q)
        assert np.allclose(cell.robot.fk(q), np.array(s["tool_pose"]), atol=1e-6)
    put = next(s for s in inst["steps"] if s["name"] == "putdown")
    assert put["placement"]["pose"] == inst["bindings"]["pos_1"]
    assert put["placement"]["z"] == cell.objects["block"].poses[put["placement"]["pose"]].height


def test_larger_uncertainty_gets_a_scan_before_the_pickup(planner: Planner) -> None:
    inst = planner.plan(PROBLEMS / "large_uncertainty.yaml").to_json()["instance"]
    kinds = [(s["kind"], s["name"], s["object"]) for s in inst["steps"]]
    first_pickup = next(i for i, k in enumerate(kinds) if k[1] == "pickup")
    assert kinds[first_pickup - 1] == ("sensing", "dense_range_scan", kinds[first_pickup][2])
    assert inst["error_count"] == 0
    checks = _execution_check("large_uncertainty", inst)
    assert all(c["failed_draws"] == 0 for c in checks if c["declared_satisfied"])


def test_hopeless_uncertainty_plans_for_failure(planner: Planner) -> None:
    plan = planner.plan(PROBLEMS / "hopeless_uncertainty.yaml").to_json()
    inst = plan["instance"]
    assert plan["outcome"] == "plan"
    assert inst["error_count"] >= 1
    assert len(inst["verifications"]) == inst["error_count"] == len(inst["recoveries"])
    failed = {c["action"] for c in inst["constraints"] if not c["satisfied"]}
    assert {v["action"] for v in inst["verifications"]} <= failed
    checks = _execution_check("hopeless_uncertainty", inst)
    assert all(c["failed_draws"] == 0 for c in checks if c["declared_satisfied"])
    # the check can fail: some precondition declared unsatisfied does fail in some draws
    assert any(c["failed_draws"] > 0 for c in checks if not c["declared_satisfied"])


# ---------------------------------------------------------------------- stocks of identical parts


def _two_part_stock(tmp: Path) -> Path:
    """kb/problems/separation.yaml with the spare brought into reach (x = 38 in) and a second
    block: both pegs of the stock go into blocks, so phase 2 must switch parts."""
    kb = ROOT / "kb"
    s = (PROBLEMS / "separation.yaml").read_text()
    s = s[s.index("problem:"):].replace("../robots/", f"{kb}/robots/").replace("../objects/", f"{kb}/objects/")
    s = s.replace("[60, -8, 1.5]", "[38, -8, 1.5]")
    s = s.replace("  block:\n", f"  block2:\n    model: {kb}/objects/block2.yaml\n"
                  "    initial: {name: init_pos4, label: tr4, tm: [[1, 0, 0], [0, 1, 0], [0, 0, 1], [38, 8, 1.5]]}\n"
                  "  block:\n")
    s = s.replace("    block: {dx", "    block2: {dx: [-0.11, 0.11], dy: [-0.11, 0.11], dz: [-0.11, 0.11], "
                  "dtheta: [-5.5, 5.5]}\n    block: {dx")
    s = s.replace("  - part_location(peg, init_pos1)\n",
                  "  - assembled(peg, block2, [[peg_face], [block_face]], trans_1, vec_1)\n")
    path = tmp / "two_part_stock.yaml"
    path.write_text(s)
    return path


def test_stock_parts_each_picked_where_they_lie(planner: Planner, tmp_path: Path) -> None:
    """Two pegs of one stock into two blocks: each pickup takes a different part (its
    ``from``), grasps it where that part lies, and the replay at 10^4 draws agrees."""
    path = _two_part_stock(tmp_path)
    cell = load_problem(path)
    plan = planner.plan(path).to_json()
    assert plan["outcome"] == "plan"
    inst = plan["instance"]
    picks = [s for s in inst["steps"] if s["name"] == "pickup"]
    assert sorted(s["source"]["peg"] for s in picks) == ["tr1", "tr5"]
    for s in picks:
        g = cell.objects["peg"].grasps[s["args"][1]]
        np.testing.assert_allclose(np.array(s["tool_pose"]), cell.positions[s["source"]["peg"]].T @ g.T, atol=1e-6)
    mates = {s["args"][1]: s for s in inst["steps"] if s["name"] == "assemble"}
    assert mates["block"]["source"] == {"block": "tr2"} and mates["block2"]["source"] == {"block2": "tr4"}
    report = phase2.sample_check(CellCache(cell), _steps(inst), draws=10_000)
    assert report and all(r["failed_draws"] == 0 for r in report if r["declared_satisfied"])


def test_stock_world_keeps_the_spare() -> None:
    """The initial world of kb/problems/separation.yaml: the part the plan takes first is
    'peg', the spare keeps its own state at its own place."""
    cell = load_problem(PROBLEMS / "separation.yaml")
    steps = [{"id": "action_2", "name": "pickup", "args": ["peg", "p1G10"]}]
    w = phase2.new_world(CellCache(cell), steps, {"action_2": {"peg": "tr5"}})
    assert set(w.unc.objects) == {"peg", "peg@init_pos1", "block"}
    np.testing.assert_allclose(w.unc.objects["peg"].pose, cell.positions["tr5"].T)
    np.testing.assert_allclose(w.unc.objects["peg@init_pos1"].pose, cell.positions["tr1"].T)
    _, after, _ = phase2.step(w, steps[0])
    assert after.unc.objects["peg"].where == "hand" and after.unc.objects["peg@init_pos1"].where == "table"


# ---------------------------------------------------------------------- one bridge call per run


@pytest.fixture
def evaluations(monkeypatch: pytest.MonkeyPatch) -> list[dict[str, Any]]:
    """Every call Prolog makes to spar_py.planning.engine.evaluate, and how many steps phase 2
    executed in it (each call's arguments and result recorded)."""
    calls: list[dict[str, Any]] = []
    real = engine_module.evaluate

    def counted(problem: str, steps: list, *rest: Any) -> dict[str, Any]:
        out = real(problem, steps, *rest)
        calls.append({"steps": [s["id"] for s in steps], "status": out["status"], "ran": len(out["steps"])})
        return out

    monkeypatch.setattr(engine_module, "evaluate", counted)
    return calls


def test_no_per_step_bridge_functions_left() -> None:
    assert not hasattr(engine_module, "ur_step") and not hasattr(engine_module, "ur_world")


def test_paper_cell_is_one_bridge_call(planner: Planner, evaluations: list[dict[str, Any]]) -> None:
    """The paper's cell: one instance, no remedy: one call to Python runs all four steps."""
    inst = planner.plan(PROBLEMS / "peg_in_block.yaml").to_json()["instance"]
    assert inst["instances_examined"] == 1
    assert evaluations == [{"steps": ["action_4", "action_3", "action_2", "action_1"], "status": "ok", "ran": 4}]


def test_large_uncertainty_is_one_bridge_call_per_run(planner: Planner, evaluations: list[dict[str, Any]]) -> None:
    """large_uncertainty: each run of the instance (the first, then one per remedy tried)
    is one call with the whole step list; 14 steps executed in 3 calls, not 14 calls."""
    inst = planner.plan(PROBLEMS / "large_uncertainty.yaml").to_json()["instance"]
    final = [s["id"] for s in inst["steps"]]
    assert [c["status"] for c in evaluations] == ["failed", "failed", "ok"]
    assert evaluations[-1]["steps"] == final and evaluations[-1]["ran"] == len(final)
    # each run is the instance so far: the first the bare instance, each later one more remedies
    assert [len(c["steps"]) for c in evaluations] == [4, 5, 7]
    assert all(c["ran"] <= len(c["steps"]) for c in evaluations)
    assert sum(c["ran"] for c in evaluations) > len(evaluations)


# ---------------------------------------------------------------------- the world at each step


def test_paper_cell_poses_at_each_step(planner: Planner) -> None:
    """Every step's ``poses`` and ``held`` agree with an independent computation: a picked
    part is where it lay (and the tool is at pose @ grasp), the put-down block is at its
    placement (x, y, z, yaw of a stable pose), the assembled peg at block @ T_a."""
    cell = load_problem(PROBLEMS / "peg_in_block.yaml")
    inst = planner.plan(cell).to_json()["instance"]
    by_name = {s["name"]: [] for s in inst["steps"]}
    for s in inst["steps"]:
        by_name[s["name"]].append(s)
        assert set(s["poses"]) == {"peg", "block"}
    (pick_block, pick_peg), (put,), (mate,) = by_name["pickup"], by_name["putdown"], by_name["assemble"]
    P = {k: {o: np.array(T) for o, T in s["poses"].items()} for k, s in
         (("pb", pick_block), ("put", put), ("pp", pick_peg), ("mate", mate))}
    # pickups: where the part lay; the tool at part @ grasp; the part in the hand after
    np.testing.assert_allclose(P["pb"]["block"], cell.positions["tr2"].T, atol=1e-9)
    np.testing.assert_allclose(P["pp"]["peg"], cell.positions["tr1"].T, atol=1e-9)
    for s, obj in ((pick_block, "block"), (pick_peg, "peg")):
        g = cell.objects[obj].grasps[s["args"][1]]
        np.testing.assert_allclose(np.array(s["tool_pose"]), np.array(s["poses"][obj]) @ g.T, atol=1e-6)
        assert s["held"] == obj
    # put-down: x, y, z and yaw about world z of the stable pose
    pl = put["placement"]
    R = rotz(math.radians(pl["yaw_deg"]))[:3, :3] @ cell.objects["block"].poses[pl["pose"]].R
    np.testing.assert_allclose(P["put"]["block"][:3, :3], R, atol=1e-9)
    np.testing.assert_allclose(P["put"]["block"][:3, 3], [pl["x"], pl["y"], pl["z"]], atol=1e-6)
    assert put["held"] is None and pick_peg["poses"]["block"] == put["poses"]["block"]
    # assemble: the peg inserted at block @ T_a (trans_1); the block has not moved
    np.testing.assert_allclose(P["mate"]["peg"], P["put"]["block"] @ cell.transforms["trans_1"], atol=1e-9)
    np.testing.assert_allclose(P["mate"]["block"], P["put"]["block"], atol=1e-12)
    assert mate["held"] is None
    # the args are term data, not text: the assemble's mating faces are a list of lists
    assert mate["args"] == ["peg", "block", [["peg_face"], ["block_face"]], "trans_1", "vec_1"]


# ---------------------------------------------------------------------- the squeeze (Sec. 4.3)


def test_squeeze_is_the_remedy_that_works(planner: Planner) -> None:
    """kb/problems/squeeze.yaml: the two scans before the peg's pickup leave the assemble
    unmet; with a squeeze of the block after them it holds; error count 0."""
    cell = load_problem(PROBLEMS / "squeeze.yaml")
    inst = planner.plan(cell).to_json()["instance"]
    kinds = [(s["kind"], s["name"], s["object"]) for s in inst["steps"]]
    assert ("squeeze", "squeeze", "block") in kinds
    assert inst["error_count"] == 0 and inst["verifications"] == []
    sq = next(s for s in inst["steps"] if s["kind"] == "squeeze")
    assert sq["serves"] == "action_1" and sq["held"] is None
    assert sq["poses"]["block"] == inst["steps"][inst["steps"].index(sq) - 1]["poses"]["block"]  # squeezed in place
    steps = _steps(inst)
    sources = {s["id"]: s["source"] for s in steps if s.get("source")}
    ok = phase2.evaluate(CellCache(cell), steps, sources)
    assert ok.status == "ok"
    # sensing alone: the same instance without the squeeze fails at the assemble
    alone = phase2.evaluate(CellCache(cell), [s for s in steps if s["name"] != "squeeze"], sources)
    assert (alone.status, alone.at) == ("failed", "action_1")
    centres = [v for v in alone.steps[-1]["verdicts"] if v["constraint"] == "centres"]
    assert centres and not centres[0]["satisfied"]


def test_squeeze_cell_replay_never_fails_a_satisfied_precondition(planner: Planner) -> None:
    inst = planner.plan(PROBLEMS / "squeeze.yaml").to_json()["instance"]
    checks = _execution_check("squeeze", inst)
    assert any(c["action"] == "squeeze_action_1" for c in checks)
    assert checks and all(c["failed_draws"] == 0 for c in checks if c["declared_satisfied"])


# ---------------------------------------------------------------------- Fig. 11's bounds as data


FIG11 = {"dense_range_scan": {"dx": [-0.05, 0.05], "dy": [-0.05, 0.05], "dz": [-0.05, 0.05],
                              "dtheta": [-0.5, 0.5], "units": {"length": "in", "angle": "deg"}}}


def test_sensing_rule_bounds_are_converted_to_the_cell_unit() -> None:
    cell = load_problem(PROBLEMS / "peg_in_block.yaml")
    b = phase2.sensing_bounds(cell, FIG11)["dense_range_scan"]
    assert b.dx == pytest.approx((-0.05, 0.05)) and b.dtheta == pytest.approx((-math.radians(0.5), math.radians(0.5)))
    mm = phase2.sensing_bounds(replace(cell, unit="mm"), FIG11)["dense_range_scan"]
    assert mm.dz == pytest.approx((-1.27, 1.27))


def test_scan_without_a_sensors_entry_uses_the_sensing_rule() -> None:
    """A cell with no sensors entry: a scan leaves Fig. 11's bounds (the rule's data that
    Prolog passes); with one, the cell's entry takes precedence."""
    cell = load_problem(PROBLEMS / "large_uncertainty.yaml")
    steps = [{"id": "sense_action_4_1", "name": "dense_range_scan", "args": ["block"]},
             {"id": "action_4", "name": "pickup", "args": ["block", "p2G1"]}]
    bare = replace(cell, sensors={})
    assert phase2.evaluate(CellCache(bare), steps).status == "infeasible"  # no bounds at all
    w = phase2.new_world(CellCache(bare), steps, None, phase2.sensing_bounds(bare, FIG11))
    _, after, _ = phase2.step(w, steps[0])
    e = after.unc.obj("block").error
    assert after.unc.registry.bounds(e.dx.name()) == pytest.approx((-0.05, 0.05))
    own = phase2.new_world(CellCache(cell), steps, None, phase2.sensing_bounds(cell, {"dense_range_scan": {
        **FIG11["dense_range_scan"], "dx": [-9, 9]}}))
    assert own.scans["dense_range_scan"] == cell.sensors["dense_range_scan"].leaves


def test_stock_spare_keeps_its_own_key_in_poses(planner: Planner) -> None:
    """kb/problems/separation.yaml: the plan takes the peg at init_pos5 (tr5); the spare
    stays at init_pos1 and is keyed ``peg@init_pos1`` in every step's poses."""
    cell = load_problem(PROBLEMS / "separation.yaml")
    inst = planner.plan(cell).to_json()["instance"]
    for s in inst["steps"]:
        assert set(s["poses"]) == {"peg", "peg@init_pos1", "block"}
        np.testing.assert_allclose(np.array(s["poses"]["peg@init_pos1"]), cell.positions["tr1"].T, atol=1e-9)
    pick = next(s for s in inst["steps"] if s["name"] == "pickup")
    np.testing.assert_allclose(np.array(pick["poses"]["peg"]), cell.positions["tr5"].T, atol=1e-9)


# ---------------------------------------------------------------------- runs that stop at a failing step


def test_a_run_stops_bounding_at_its_failing_precondition(planner: Planner) -> None:
    """A run that stops at a step (an unmet precondition, the step not given up) bounds its
    constraints only up to the first unsatisfied one; when a later run gives that step up
    and goes on, the memoised step is computed whole: its verdicts are those of a fresh
    cell's, every constraint of the action bounded."""
    inst = planner.plan(PROBLEMS / "hopeless_uncertainty.yaml").to_json()["instance"]
    bare = [s for s in _steps(inst) if s["name"] in ("pickup", "putdown", "assemble")]
    cache = CellCache(load_problem(PROBLEMS / "hopeless_uncertainty.yaml"))
    first = phase2.evaluate(cache, bare)
    assert first.status == "failed"
    at = first.at
    cut = next(r["verdicts"] for r in first.steps if r["id"] == at)
    assert not cut[-1]["satisfied"] and all(v["satisfied"] for v in cut[:-1])
    later = phase2.evaluate(cache, bare, given_up=[at])
    fresh = phase2.evaluate(CellCache(load_problem(PROBLEMS / "hopeless_uncertainty.yaml")), bare, given_up=[at])
    whole = next(r["verdicts"] for r in later.steps if r["id"] == at)
    assert whole == next(r["verdicts"] for r in fresh.steps if r["id"] == at)
    assert len(whole) > len(cut) and whole[:len(cut)] == cut  # it was cut short, and is whole now
    assert later.status == fresh.status and later.at == fresh.at


@pytest.mark.parametrize("problem", ["peg_in_block", "hopeless_uncertainty", "large_uncertainty", "squeeze"])
def test_deciding_verdicts_changes_no_plan(problem: str, monkeypatch: pytest.MonkeyPatch) -> None:
    """Phase 2 decides each constraint with SUP/INF's ``beat`` (it stops once the verdict is
    settled) and refines the bounds of the runs that go through: the plan, every reported
    bound included, is the one bounding everything to the tolerance gives, and each
    reported bound reached it."""
    from spar_py.phase2 import uncertainty as ur

    def strip(d: dict) -> dict:
        return {k: v for k, v in d.items() if k != "timing"}

    fast = Planner(max_instances=5).plan(PROBLEMS / f"{problem}.yaml").to_json()
    full_evaluate = ur.evaluate

    def never_decide(c: Any, registry: Any, *, memo: Any = None, decide: bool = False, **options: Any) -> Any:
        return full_evaluate(c, registry, memo=memo, **options)

    monkeypatch.setattr(ur, "evaluate", never_decide)
    full = Planner(max_instances=5).plan(PROBLEMS / f"{problem}.yaml").to_json()
    assert strip(fast) == strip(full)
    reported = [c for c in fast["instance"]["constraints"] if c["kind"] == "uncertainty"]
    assert reported and all(c["tolerance_reached"] for c in reported)
