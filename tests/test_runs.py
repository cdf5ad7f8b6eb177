"""One planning run, one object (planning/run.py, world/run.py).

- runs of different problems, interleaved on one engine (through its doors, and plan by plan
  on one Planner), each explain their own no-plan: one's refusals never appear in the other's;
- the same problem planned again after its file changed explains the new cell, not the old;
- a no-plan planned again (the cell's answers kept) explains itself again, the same way, and a
  phase-2 step answered from the cell's kept answers logs its refusal in each run's own log;
- planning does not write onto the cached cell; a run's log starts empty.
"""
from __future__ import annotations

import copy
from dataclasses import fields, is_dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from spar_py import Planner
from spar_py.kb import load_problem
from spar_py.planning import engine as engine_module
from spar_py.planning.run import PlanRun
from spar_py.world.collision import CellCache
from spar_py.world.run import RunOptions, WorldRun

from paths import ROOT

PROBLEMS = ROOT / "kb" / "problems"


def _copy(name: str, dest: Path, edit: dict[str, str] | None = None) -> Path:
    """kb/problems/``name`` written to ``dest`` with its relative paths made absolute (and each
    ``edit`` key replaced by its value)."""
    text = (PROBLEMS / name).read_text().replace("../", f"{ROOT / 'kb'}/")
    for a, b in (edit or {}).items():
        assert a in text
        text = text.replace(a, b)
    dest.parent.mkdir(parents=True, exist_ok=True)
    dest.write_text(text)
    return dest


def _collisions(plan: Any) -> list[str]:
    return list((plan.reason or {}).get("collisions", []))


def test_interleaved_plans_on_one_planner_explain_their_own_no_plan() -> None:
    """collision_no_plan (a shelf over the peg), unreachable (no collision in the way) and
    placement_trap, planned in turn on one Planner, twice over: each no-plan names its own
    refusals only, and the second time (the cells' answers kept) the same ones."""
    p = Planner()
    names = ("collision_no_plan", "unreachable", "placement_trap")
    first = {n: p.plan(PROBLEMS / f"{n}.yaml") for n in names}
    again = {n: p.plan(PROBLEMS / f"{n}.yaml") for n in reversed(names)}
    for n in names:
        assert first[n].outcome.value == "no_plan" and again[n].outcome.value == "no_plan"
        assert _collisions(again[n]) == _collisions(first[n]), n
    shelf = _collisions(first["collision_no_plan"])
    assert shelf and all("shelf" in line or "table" in line for line in shelf)
    assert any("shelf" in line for line in shelf)
    assert _collisions(first["unreachable"]) == []
    trap = _collisions(first["placement_trap"])
    assert trap == ["no collision-free IK for pickup(peg, p1G17) at tr1: palm-table"]
    assert not any("shelf" in line for n in ("unreachable", "placement_trap") for line in _collisions(again[n]))


def test_runs_interleaved_through_the_engine_s_doors_keep_their_own_logs() -> None:
    """Two problems loaded at once, each with its run: the arc questions Prolog would ask, put
    through the engine's door (engine.arc_pairs) for one problem and then the other, turn by
    turn; each run's log holds exactly what its own questions refused."""
    eng = Planner().engine
    cells = {n: load_problem(PROBLEMS / f"{n}.yaml") for n in ("collision_no_plan", "enclosed_part")}
    runs = {n: PlanRun(CellCache(c)) for n, c in cells.items()}
    alone = {n: WorldRun(CellCache(load_problem(PROBLEMS / f"{n}.yaml"))) for n in cells}
    try:
        with eng.lock:
            for n, c in cells.items():
                eng.load_cell(c)
                eng.runs[n] = runs[n]
            for obj in ("peg", "block"):
                for n, c in cells.items():
                    grasps = sorted(c.objects[obj].grasps)
                    labels = [p.label for p in c.positions.values() if p.obj == obj]
                    got = engine_module.arc_pairs(n, "reachable", "reachable", [obj], grasps, labels, "none")
                    assert got == alone[n].arc_pairs("reachable", [obj], grasps, labels)
    finally:
        with eng.lock:
            for n in cells:
                eng.runs.pop(n, None)
                eng.unload(n)
    for n in cells:
        own = [r.text() for r in runs[n].world.log.refusals()]
        assert own and own == [r.text() for r in alone[n].log.refusals()]
    assert any("shelf" in r for r in (x.text() for x in runs["collision_no_plan"].world.log.refusals()))
    assert not any("shelf" in r.text() for r in runs["enclosed_part"].world.log.refusals())
    assert not any("wall" in r.text() for r in runs["collision_no_plan"].world.log.refusals())


def test_the_same_problem_after_its_file_changed_explains_the_new_cell(tmp_path: Path) -> None:
    """collision_no_plan copied, planned, its shelf renamed in the file, planned again by the
    same Planner: the second no-plan names the board, never the shelf the first run refused on."""
    path = _copy("collision_no_plan.yaml", tmp_path / "problems" / "collision_no_plan.yaml")
    p = Planner()
    before = p.plan(path)
    assert any("shelf" in line for line in _collisions(before))
    _copy("collision_no_plan.yaml", path, {"{name: shelf,": "{name: board,"})
    after = p.plan(path)
    lines = _collisions(after)
    assert lines and any("board" in line for line in lines)
    assert not any("shelf" in line for line in lines)
    assert [line.replace("board", "shelf") for line in lines] == _collisions(before)


def _same(a: Any, b: Any) -> bool:
    """Deep equality for a cell's field values (numpy arrays by value; the lazily derived
    values a model keeps on itself, its ``_`` fields such as a body's library shape, aside)."""
    if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        return isinstance(a, np.ndarray) and isinstance(b, np.ndarray) and a.shape == b.shape and \
            np.array_equal(a, b)
    if isinstance(a, dict):
        return isinstance(b, dict) and a.keys() == b.keys() and all(_same(a[k], b[k]) for k in a)
    if isinstance(a, (list, tuple)):
        return type(a) is type(b) and len(a) == len(b) and all(_same(x, y) for x, y in zip(a, b))
    if is_dataclass(a) and not isinstance(a, type):
        return type(a) is type(b) and all(_same(getattr(a, f.name), getattr(b, f.name)) for f in fields(a)
                                          if not f.name.startswith("_"))
    if hasattr(a, "__dict__") and not isinstance(a, type):
        return type(a) is type(b) and _same(vars(a), vars(b))
    return a == b


@pytest.mark.parametrize("problem", ["collision_no_plan", "peg_in_block", "hopeless_uncertainty"])
def test_planning_does_not_write_onto_the_cached_cell(problem: str) -> None:
    """The cell a Planner keeps is the same, field by field, before and after planning it twice,
    and gains no attribute: a run's state lives in the run."""
    p = Planner()
    cell = p.load_problem(PROBLEMS / f"{problem}.yaml")
    before = {f.name: copy.deepcopy(getattr(cell, f.name)) for f in fields(cell) if f.name != "robot"}
    robot = {k: copy.deepcopy(v) for k, v in vars(cell.robot).items() if not k.startswith("_")}
    attrs = set(vars(cell))
    p.plan(PROBLEMS / f"{problem}.yaml")
    p.plan(cell)
    assert p.load_problem(PROBLEMS / f"{problem}.yaml") is cell
    assert set(vars(cell)) == attrs
    for name, value in before.items():
        assert _same(getattr(cell, name), value), name
    # the robot's own fields (its lazily derived values, such as its tool's inverse, aside)
    assert _same({k: v for k, v in vars(cell.robot).items() if not k.startswith("_")}, robot)
    assert not hasattr(cell, "memo") and not hasattr(cell, "motion")


def test_a_run_s_log_starts_empty() -> None:
    """A new run on a cell whose answers are kept (a no-plan planned already) starts with an
    empty log, and the Planner's next plan of it logs its refusals anew."""
    p = Planner()
    cell = p.load_problem(PROBLEMS / "collision_no_plan.yaml")
    first = p.plan(cell)
    cache = p.cache_of(cell)
    assert len(cache.memo.sizes()) > 0
    run = PlanRun(cache, p.run_options(cell))
    log = run.world.log
    assert log.refused == {} and log.motion_failures == [] and len(log.tokens) == 0
    assert run.world.options == RunOptions(placements="reachable", motion=None)
    assert _collisions(p.plan(cell)) == _collisions(first)


def test_a_phase_2_no_plan_planned_again_explains_itself_again() -> None:
    """enclosed_part ends in phase 2 (the motions of its instances blocked): planned again by the
    same Planner, every step and motion answered from the cell's kept answers, its reason names
    the same refusals and motion failures."""
    p = Planner()
    first, again = (p.plan(PROBLEMS / "enclosed_part.yaml") for _ in range(2))
    for key in ("collisions", "motion_failures", "why"):
        assert again.reason[key] == first.reason[key], key
    assert again.reason["motion_failures"] and _collisions(again)


def test_a_kept_phase_2_step_logs_its_refusal_in_every_run() -> None:
    """Phase 2's door: a pickup whose every joint solution hits the shelf, evaluated by two runs
    of one cell (the second answered from the cell's kept step): each run's log names the
    refusal and its pair, and the run's answer to Prolog carries no geometry, only the nogood."""
    cache = CellCache(load_problem(PROBLEMS / "collision_no_plan.yaml"))
    steps = [{"id": "action_1", "name": "pickup", "args": ["peg", "p1G10"]}]
    answers, logs = [], []
    for _ in range(2):
        run = PlanRun(cache)
        answers.append(run.evaluate(steps))
        logs.append([r.text() for r in run.world.log.refusals()])
    assert answers[0] == answers[1] and answers[0]["status"] == "infeasible"
    assert set(answers[0]) == {"status", "at", "steps", "nogood"} and set(answers[0]["steps"][0]) == {"id", "verdicts"}
    # the shelf is an obstacle, not a part: the pickup with that grasp fails whatever else is done
    assert answers[0]["nogood"] == {"step": "action_1", "labels": [], "prefix": [], "before": []}
    assert logs[0] == logs[1] == ["no collision-free IK for pickup(peg, p1G10): tool_mount-shelf"]


def test_a_run_counts_the_instances_that_met_each_refusal() -> None:
    """Phase 2's door counts, per refusal, the instances whose runs met it: a second run of one
    instance (as after a remedy) adds none, another instance meeting it adds one; the no-plan lines
    say it once with that number."""
    from spar_py.planning.messages import collision_lines

    run = PlanRun(CellCache(load_problem(PROBLEMS / "collision_no_plan.yaml")))
    one = [{"id": "action_1", "name": "pickup", "args": ["peg", "p1G10"]}]
    other = [{"id": "action_2", "name": "pickup", "args": ["peg", "p1G10"]}]
    for steps in (one, one, other):
        assert run.evaluate(steps)["status"] == "infeasible"
    assert run.refusal_instances() == {"pickup(peg, p1G10)": 2}
    assert collision_lines(run.world.log.refusals(), run.refusal_instances()) == [
        "no collision-free IK for pickup(peg, p1G10): tool_mount-shelf (x2 instances)"]
