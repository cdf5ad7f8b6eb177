"""A part fitted onto a part that is itself already fitted: a block, a stud standing in it and a
cap on the stud's top (this file's own primitives; the cap is kb/objects/collar.yaml). The cap in
place blocks the stud's way down, so the stud goes first; the cap's goal then goes into the
block (the stud, once assembled, has no location of its own), its insertion checked against
the stud at its composed pose. Poses are checked with this file's own arithmetic.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from spar_py.kb import load_problem
from spar_py.planning.planner import Planner
from spar_py.world.product import products as wp

from paths import ROOT


BLOCK = """object: block
units: {length: mm, angle: deg}
shape:
  - {box: {min: [-30, -30, 0], max: [30, 30, 40]}}
  - {cylinder: {radius: 8.2, z: [20, 40], subtract: true}}
features:
  - {kind: hole, name: bore, radius: 8.2, axis: {origin: [0, 0, 40], direction: [0, 0, -1]}, length: 20}
"""
STUD = """object: stud
units: {length: mm, angle: deg}
shape:
  - {cylinder: {radius: 8, z: [0, 20]}}
  - {cylinder: {radius: 10, z: [20, 30]}}
  - {cylinder: {radius: 6, z: [30, 46]}}
features:
  - {kind: peg, name: low, radius: 8, axis: {origin: [0, 0, 20], direction: [0, 0, -1]}, length: 20}
  - {kind: peg, name: high, radius: 6, axis: {origin: [0, 0, 30], direction: [0, 0, 1]}, length: 16}
"""
PRODUCT = f"""product: chain
units: {{length: mm, angle: deg}}
parts:
  block: {{model: block.yaml}}
  stud: {{model: stud.yaml, pose: {{xyz: [0, 0, 20]}}}}
  cap: {{model: {ROOT}/kb/objects/collar.yaml, pose: {{xyz: [0, 0, 50]}}}}
mates:
  - {{peg: stud.low, hole: block.bore}}
  - {{peg: stud.high, hole: cap.bore}}
"""
ERR = "{dx: [-0.05, 0.05], dy: [-0.05, 0.05], dz: [-0.05, 0.05], dtheta: [-0.05, 0.05]}"
CELL = f"""problem: chain_cell
units: {{length: mm, angle: deg}}
robot: {ROOT}/kb/robots/puma762.yaml
product: chain.yaml
objects:
  block:
    initial: {{name: init_block, label: tr_block, tm: [[1, 0, 0], [0, 1, 0], [0, 0, 1], [762, 203, 0]]}}
  stud:
    initial: {{name: init_stud, label: tr_stud, tm: [[1, 0, 0], [0, 1, 0], [0, 0, 1], [700, -203, 0]]}}
  cap:
    initial: {{name: init_cap, label: tr_cap, tm: [[1, 0, 0], [0, 1, 0], [0, 0, 1], [820, -203, 0]]}}
gripper: open
uncertainty:
  manipulator: {{dx: [-0.01, 0.01], dy: [-0.01, 0.01], dz: [-0.01, 0.01], dtheta: [-0.01, 0.01]}}
  objects: {{block: {ERR}, stud: {ERR}, cap: {ERR}}}
goals:
  - assembled(chain)
"""
#: Each part's product pose as the product file gives it (pure translations), mm.
POSES = {"block": (0.0, 0.0, 0.0), "stud": (0.0, 0.0, 20.0), "cap": (0.0, 0.0, 50.0)}


def _trans(xyz: tuple[float, float, float]) -> np.ndarray:
    T = np.eye(4)
    T[:3, 3] = xyz
    return T


@pytest.fixture(scope="module")
def cell_file(tmp_path_factory: pytest.TempPathFactory) -> Path:
    d = tmp_path_factory.mktemp("chain")
    for name, text in (("block", BLOCK), ("stud", STUD), ("chain", PRODUCT), ("cell", CELL)):
        (d / f"{name}.yaml").write_text(text)
    return d / "cell.yaml"


def test_cap_goal_goes_into_the_block(cell_file: Path) -> None:
    """The stud is in place before the cap (precedence), so the cap's goal is into the block with
    T_a the cap's pose relative to the block's; without that order known it goes into the stud."""
    product = load_problem(cell_file).product
    assert [(p.first, p.then) for p in product.precedence] == [("stud", "cap")]
    goals = {g.part: g for g in product.goals}
    assert goals["stud"].parent == "block" and goals["cap"].parent == "block"
    assert np.allclose(goals["cap"].T_a, _trans(POSES["cap"]))
    assert np.allclose(goals["cap"].V_a, [0, 0, -1])
    assert goals["cap"].parent_faces == () and goals["cap"].mates == ("stud.high->cap.bore",)
    free = {g.part: g for g in wp.compile_goals(product)}
    assert free["cap"].parent == "stud"
    assert np.allclose(free["cap"].T_a, np.linalg.inv(_trans(POSES["stud"])) @ _trans(POSES["cap"]))


def test_chain_plans_with_every_part_at_its_product_pose(cell_file: Path) -> None:
    """Four actions (no put-down of a stud-in-block body): the stud into the block, then the cap
    onto it, its insertion checked against the stud's high peg; the last step leaves every part
    at its product pose relative to the block, within 1e-6 of the cell's size."""
    plan = Planner().plan(cell_file)
    assert plan.ok, plan.reason
    j = plan.to_json()
    steps = j["instance"]["steps"]
    assert [(s["name"], s["args"][0]) for s in steps] == [
        ("pickup", "stud"), ("assemble", "stud"), ("pickup", "cap"), ("assemble", "cap")]
    assert steps[3]["args"][1] == "block"
    cap_checks = [c for c in j["instance"]["constraints"] if c["action"] == steps[3]["id"]]
    assert cap_checks and all(c["satisfied"] for c in cap_checks)
    assert any("stud's high" in c["description"] for c in cap_checks)
    final = {k: np.array(v, float) for k, v in steps[-1]["poses"].items()}
    tol = 1e-6 * max(float(np.abs(T[:3, 3]).max()) for T in final.values())
    for part, xyz in POSES.items():
        want = np.linalg.inv(_trans(POSES["block"])) @ _trans(xyz)
        got = np.linalg.inv(final["block"]) @ final[part]
        assert np.abs(got - want).max() < tol, (part, got.round(6), want)
