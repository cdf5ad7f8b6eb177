"""The typed plan of the Python API: a step's motions (path, approach, retreat, duration),
where it takes its part from (``source``, the JSON's key too), the bound actions, and the
quick start's inspection of a plan."""
from __future__ import annotations

import json
import os
import re

import numpy as np
import pytest

from spar_py import Planner
from spar_py.planning.planner import Plan, Step

from paths import ROOT

PROBLEMS = ROOT / "kb" / "problems"


@pytest.fixture(scope="module")
def with_motions(planner: Planner) -> Plan:
    """wall_detour: its file asks for motions (motion: true)."""
    plan = planner.plan(str(PROBLEMS / "wall_detour.yaml"))
    assert plan.ok and plan.instance and plan.instance["motion"] is not None
    return plan


@pytest.fixture(scope="module")
def without_motions(planner: Planner) -> Plan:
    plan = planner.plan(str(PROBLEMS / "peg_in_block.yaml"))
    assert plan.ok and plan.instance and plan.instance.get("motion") is None
    return plan


def _check_waypoints(a: np.ndarray | None, n_joints: int) -> np.ndarray:
    assert isinstance(a, np.ndarray) and a.dtype == np.float64
    assert a.ndim == 2 and a.shape[1] == n_joints and a.shape[0] >= 2
    return a


def test_step_motions_are_typed_arrays(with_motions: Plan) -> None:
    """With motions, every arm step has its path, approach and retreat as (n, 6) float
    arrays in degrees, as the JSON's steps have them, the approach ending and the retreat
    starting at the step's joints; duration_s a float."""
    raw = {s["id"]: s for s in with_motions.instance["steps"]}
    for s in with_motions.steps:
        assert isinstance(s, Step)
        q = np.asarray(s.joints_deg)
        for name in ("path", "approach", "retreat"):
            a = _check_waypoints(getattr(s, name), len(q))
            np.testing.assert_array_equal(a, np.asarray(raw[s.id][name]))
        np.testing.assert_allclose(s.approach[-1], q, atol=1e-3)
        np.testing.assert_allclose(s.retreat[0], q, atol=1e-3)
        assert isinstance(s.duration_s, float) and s.duration_s > 0
        assert s.duration_s == raw[s.id]["duration_s"]


def test_step_motions_are_none_without_motions(without_motions: Plan) -> None:
    for s in without_motions.steps:
        assert (s.path, s.approach, s.retreat, s.duration_s) == (None, None, None, None), s.id


def test_source_is_one_name(without_motions: Plan) -> None:
    """The JSON's steps and the dataclass say `source`; a JSON of before the rename
    (`from`) still reads."""
    steps = without_motions.instance["steps"]
    assert all("source" in s and "from" not in s for s in steps)
    picks = [s for s in without_motions.steps if s.name == "pickup"]
    assert [s.source for s in picks] == [{"block": "tr2"}, {"peg": "tr1"}]
    old = json.loads(json.dumps(without_motions.to_json()))
    for s in old["instance"]["steps"]:
        s["from"] = s.pop("source")
    again = Plan.from_json(old)
    assert [s.source for s in again.steps] == [s.source for s in without_motions.steps]


def test_json_round_trip_keeps_the_motions(with_motions: Plan) -> None:
    again = Plan.from_json(json.loads(with_motions.dumps()))
    for a, b in zip(again.steps, with_motions.steps):
        for name in ("path", "approach", "retreat"):
            np.testing.assert_array_equal(getattr(a, name), getattr(b, name))
        assert a.duration_s == b.duration_s


def test_bound_actions(without_motions: Plan) -> None:
    """The phase-1 actions with the instance's bindings in place of the plan variables:
    none left where the instance binds them all; the bound pickups are the steps'."""
    plan = without_motions
    bindings = plan.instance["bindings"]
    assert {"grasp_1", "grasp_2", "pos_1"} <= set(bindings)
    assert any("grasp_1" in a.term for a in plan.actions)       # phase 1's terms keep them
    bound = plan.bound_actions
    assert [a.id for a in bound] == [a.id for a in plan.actions]
    for a in bound:
        assert not any(re.search(rf"\b{v}\b", a.term) for v in bindings), a.term
        assert not any(v in json.dumps(a.args) for v in ('"grasp_1"', '"grasp_2"', '"pos_1"')), a.args
    by_id = {s.id: s for s in plan.steps}
    for a in bound:
        if a.name in ("pickup", "putdown"):
            assert a.term == by_id[a.id].term and list(a.args) == list(by_id[a.id].args)


def test_bound_actions_without_an_instance(planner: Planner) -> None:
    """Without phase 2 (phase1_only) nothing is bound: the actions as phase 1 left them."""
    plan = planner.plan(str(PROBLEMS / "peg_in_block.yaml"), phase1_only=True)
    assert plan.instance is None and plan.actions
    assert plan.bound_actions == plan.actions


def test_quickstart_inspects_a_plan(capsys: pytest.CaptureFixture[str]) -> None:
    """docs/quickstart.md's Python blocks, run in order as written: the second inspects a
    plan with motions in five lines."""
    text = (ROOT / "docs" / "quickstart.md").read_text()
    blocks = re.findall(r"```python\n(.*?)```", text, re.S)
    assert len(blocks) >= 2 and len(blocks[1].strip().splitlines()) == 5, blocks
    cwd, env = os.getcwd(), {}
    os.chdir(ROOT)
    try:
        for code in blocks[:2]:
            exec(compile(code, "quickstart.md", "exec"), env)
    finally:
        os.chdir(cwd)
    out = capsys.readouterr().out
    assert "['pickup(peg,p1G" in out and "grasp_1" not in out.split("['pickup(peg,p1G", 1)[1].split("]")[0]
    assert re.search(r"path \(\d+, 6\) approach \(\d+, 6\) retreat \(\d+, 6\)", out), out
