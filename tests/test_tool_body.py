"""The gripper is the whole tool (issue 33, item 7): without a robot file's ``collision:`` section
the tool's body from the palm back to the flange is a collision body ("tool"), a box the palm's
size; ``gripper: body`` gives another shape or none.

The independent checks: the body's length from the robot file's numbers (the PUMA's 250 mm tool
less 60 mm of fingers and 25 mm of palm), and where the body is in the world at a grasp by our
own box arithmetic (a separating-axis test of two boxes), not the collision scene's.
"""
from __future__ import annotations

import itertools
from pathlib import Path

import numpy as np
import pytest
import yaml

from spar_py.core.errors import KBError
from spar_py.kb.problem import load_problem
from spar_py.kb.robots import load_robot
from spar_py.planning.planner import Planner
from spar_py.world.collision.scene import scene_for

from paths import ROOT

PUMA = ROOT / "kb" / "robots" / "puma762.yaml"
SHELF = ROOT / "kb" / "problems" / "shelf.yaml"
MM_PER_IN = 25.4
#: The top grasps of the peg lying under the shelf (kb/problems/shelf.yaml's comment).
TOP = ("p1G10", "p1G14", "p1G16", "p1G20")


def _bare_puma(d: Path, body: str | None = None) -> Path:
    """kb/robots/puma762.yaml without its collision: section (and with ``gripper: body`` when given)."""
    doc = yaml.safe_load(PUMA.read_text())
    del doc["collision"]
    doc["name"] = "puma762_bare"
    if body is not None:
        doc["gripper"]["body"] = yaml.safe_load(body)
    path = d / "puma_bare.yaml"
    path.write_text(yaml.safe_dump(doc, sort_keys=False))
    return path


def _shelf_cell(d: Path, body: str | None = None) -> Path:
    """kb/problems/shelf.yaml (a 0.5 in board at z = 6 in over the peg) with the bare PUMA."""
    doc = yaml.safe_load(SHELF.read_text())
    doc["problem"] = "shelf_bare" if body is None else "shelf_bare_" + "".join(c for c in body if c.isalnum())
    doc["robot"] = str(_bare_puma(d, body))
    for o in doc["objects"].values():
        o["model"] = str((SHELF.parent / o["model"]).resolve())
    path = d / f"{doc['problem']}.yaml"
    path.write_text(yaml.safe_dump(doc, sort_keys=False))
    return path


def _obb_overlap(Ta: np.ndarray, ha: np.ndarray, Tb: np.ndarray, hb: np.ndarray) -> bool:
    """Two boxes (centre poses T 4x4, half sizes h (3,)) overlap: no separating axis among the 15."""
    Ra, Rb = Ta[:3, :3], Tb[:3, :3]
    t = Tb[:3, 3] - Ta[:3, 3]
    axes = [Ra[:, i] for i in range(3)] + [Rb[:, i] for i in range(3)]
    axes += [np.cross(Ra[:, i], Rb[:, j]) for i, j in itertools.product(range(3), range(3))]
    for u in axes:
        n = np.linalg.norm(u)
        if n < 1e-9:
            continue
        u = u / n
        ra = sum(ha[i] * abs(Ra[:, i] @ u) for i in range(3))
        rb = sum(hb[i] * abs(Rb[:, i] @ u) for i in range(3))
        if abs(t @ u) > ra + rb:
            return False
    return True


def test_puma_tool_body_is_the_165_mm_behind_fingers_and_palm(tmp_path: Path) -> None:
    doc = yaml.safe_load(PUMA.read_text())
    fingers_palm = doc["gripper"]["finger"]["length"] + doc["gripper"]["palm"]["length"]
    assert (doc["tool"]["xyz"][2], fingers_palm) == (250, 85)
    robot = load_robot(_bare_puma(tmp_path), "mm")
    body = robot.gripper.body
    assert body is not None and body.kind == "box"
    assert body.length == pytest.approx(250 - 85)
    assert (body.width, body.thickness) == pytest.approx((doc["gripper"]["palm"]["width"],
                                                         doc["gripper"]["palm"]["thickness"]))
    # in the scene: the body "tool" spans tool z -250 .. -85 (the flange .. the palm's back face)
    robot.links = ()
    shape = robot.gripper.body_shape()
    assert shape is not None and shape[0] == "tool"
    lo, hi = shape[2], shape[3]
    assert (lo[2], hi[2]) == pytest.approx((-250.0, -85.0))
    # a robot file with a collision: section describes its tool mount itself: no default body
    assert load_robot(PUMA, "mm").gripper.body is None


def test_tool_body_refuses_top_grasps_under_a_shelf(tmp_path: Path) -> None:
    cell = load_problem(_shelf_cell(tmp_path))
    scene = scene_for(cell)
    peg = cell.objects["peg"]
    poses = {p.obj: p.T for p in cell.positions.values()}
    shelf_doc = yaml.safe_load(SHELF.read_text())["obstacles"][0]["box"]
    s_lo, s_hi = np.array(shelf_doc["min"]), np.array(shelf_doc["max"])
    T_shelf = np.eye(4)
    T_shelf[:3, 3] = (s_lo + s_hi) / 2
    body = cell.robot.gripper.body
    behind = 85 / MM_PER_IN  # fingers and palm, the robot file's numbers
    for label in TOP:
        g = peg.grasps[label]
        T_tool = poses["peg"] @ g.T
        # our own geometry: the tool body's box (tool z from -85 mm back by its length) meets the
        # shelf, and the fingers and palm (tool z -85 mm .. 0) do not
        T_body = T_tool.copy()
        T_body[:3, 3] = T_tool[:3, :3] @ [0.0, 0.0, -behind - body.length / 2] + T_tool[:3, 3]
        half = np.array([body.width, body.thickness, body.length]) / 2
        assert _obb_overlap(T_body, half, T_shelf, (s_hi - s_lo) / 2), label
        T_hand = T_tool.copy()
        T_hand[:3, 3] = T_tool[:3, :3] @ [0.0, 0.0, -behind / 2] + T_tool[:3, 3]
        hand = np.array([121.6 / MM_PER_IN, 121.6 / MM_PER_IN, behind]) / 2  # a box holding fingers and palm
        assert not _obb_overlap(T_hand, hand, T_shelf, (s_hi - s_lo) / 2), label
        # the scene refuses every IK solution of the grasp, naming the tool body and the shelf
        Q = cell.robot.ik(T_tool)
        assert len(Q)
        ok, why = scene.at(poses, grasped="peg", width=g.width).check(Q)
        assert not ok.any() and set(why) == {("tool", "shelf")}, (label, set(why))
    plan = Planner().plan(cell)
    assert plan.ok
    pickup = next(s for s in plan.steps if s.name == "pickup" and s.object == "peg")
    assert pickup.args[1] not in TOP
    # the tool body is what refuses them: without it (body: none) the peg is picked from above
    bare = Planner().plan(load_problem(_shelf_cell(tmp_path, "none")))
    assert bare.ok
    assert next(s for s in bare.steps if s.name == "pickup" and s.object == "peg").args[1] in TOP


def test_gripper_body_key(tmp_path: Path) -> None:
    cyl = load_robot(_bare_puma(tmp_path, "{cylinder: {radius: 40}}"), "mm").gripper
    assert (cyl.body.kind, cyl.body.radius, cyl.body.length) == ("cylinder", 40.0, pytest.approx(165.0))
    name, kind, a, b, r = cyl.body_shape()
    assert (kind, r) == ("cylinder", 40.0) and a[2] == pytest.approx(-85.0) and b[2] == pytest.approx(-250.0)
    short = load_robot(_bare_puma(tmp_path, "{box: {width: 30, thickness: 50, length: 100}}"), "mm").gripper
    assert (short.body.width, short.body.thickness, short.body.length) == (30.0, 50.0, 100.0)
    # given with a collision: section too, it counts
    doc = yaml.safe_load(PUMA.read_text())
    doc["gripper"]["body"] = {"cylinder": {"radius": 25, "length": 50}}
    (tmp_path / "p.yaml").write_text(yaml.safe_dump(doc))
    assert load_robot(tmp_path / "p.yaml", "mm").gripper.body.length == 50.0
    with pytest.raises(KBError, match=r"gripper\.body\.sphere: unknown key"):
        load_robot(_bare_puma(tmp_path, "{sphere: {radius: 3}}"), "mm")
    with pytest.raises(KBError, match=r"gripper\.body\.box\.width"):
        load_robot(_bare_puma(tmp_path, "{box: {width: -3, thickness: 2}}"), "mm")
