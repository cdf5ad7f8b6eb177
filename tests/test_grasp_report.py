"""The grasp-feasibility report (world/product/grasp_report.py): a plain pin seated flush in a blind hole
has no grasp its mate can use, and the report, the plan's JSON and its summary name that mate;
products that plan keep a grasp through every filter.

The hand-made product: a 60 mm cube with a round blind hole (radius 10 mm, 40 deg deep) from its
top face, and a pin (radius 9.5 mm, 40 mm long) seated to its bottom: its top end is flush with
the cube's top, so every grasp holds it on length that goes into the hole. The headed variant
(the same pin with a 30 mm head standing 20 mm above the cube) can be held by its head."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from spar_py.core.units import mm_per
from spar_py.kb.products import load_product
from spar_py.world.product.grasp_report import grasp_report
from spar_py.world.robot import Gripper

from paths import ROOT


CUBE = """object: cube
units: {length: mm, angle: deg}
shape:
  - {box: {min: [-30, -30, -30], max: [30, 30, 30]}}
  - {cylinder: {radius: 10, z: [-10, 30], subtract: true}}
feature: {kind: hole, name: bore, radius: 10, axis: {origin: [0, 0, 30], direction: [0, 0, -1]}, length: 40}
"""
PIN = """object: plain_pin
units: {length: mm, angle: deg}
shape:
  - {cylinder: {radius: 9.5, z: [0, 40]}}
feature: {kind: peg, name: shaft, radius: 9.5, axis: {origin: [0, 0, 40], direction: [0, 0, -1]}, length: 40}
"""
HEADED = """object: headed_pin
units: {length: mm, angle: deg}
shape:
  - {cylinder: {radius: 9.5, z: [0, 40]}}
  - {box: {min: [-15, -15, 40], max: [15, 15, 60]}}
feature: {kind: peg, name: shaft, radius: 9.5, axis: {origin: [0, 0, 40], direction: [0, 0, -1]}, length: 40}
"""
PRODUCT = """product: {name}
units: {{length: mm, angle: deg}}
base: cube
parts:
  cube: {{model: cube.yaml}}
  pin: {{model: {pin}.yaml, pose: {{xyz: [0, 0, -10], rpy: [0, 0, 0]}}}}
mates:
  - {{peg: pin.shaft, hole: cube.bore}}
"""
PROBLEM = """problem: {name}
units: {{length: mm, angle: deg}}
robot: {robot}
product: {name}.yaml
layout: auto
gripper: open
uncertainty:
  manipulator: {{dx: [-0.01, 0.01], dy: [-0.01, 0.01], dz: [-0.01, 0.01], dtheta: [-0.01, 0.01]}}
  objects:
    cube: {{dx: [-0.05, 0.05], dy: [-0.05, 0.05], dz: [-0.05, 0.05], dtheta: [-0.05, 0.05]}}
    pin: {{dx: [-0.05, 0.05], dy: [-0.05, 0.05], dz: [-0.05, 0.05], dtheta: [-0.05, 0.05]}}
goals:
  - assembled({name})
"""


@pytest.fixture(scope="module")
def kb(tmp_path_factory) -> Path:
    d = tmp_path_factory.mktemp("grasp_report")
    (d / "cube.yaml").write_text(CUBE)
    (d / "plain_pin.yaml").write_text(PIN)
    (d / "headed_pin.yaml").write_text(HEADED)
    for name, pin in (("flush", "plain_pin"), ("headed", "headed_pin")):
        (d / f"{name}.yaml").write_text(PRODUCT.format(name=name, pin=pin))
        (d / f"{name}_cell.yaml").write_text(PROBLEM.format(name=name, robot=ROOT / "kb" / "robots" / "ur5e.yaml"))
    return d


def _gripper() -> Gripper:
    return Gripper.default(101.6, mm_per("mm"))


def _mouth_depth(T_tool_prod: np.ndarray, g: Gripper, width: float) -> float:
    """How far (mm) the hand's deepest corner goes below the cube's top (z = 30, product frame):
    the test's own reading of 'the hand past the hole's mouth'."""
    C = np.array([[x, y, z] for _, lo, hi in g.boxes(width) for x in (lo[0], hi[0]) for y in (lo[1], hi[1])
                  for z in (lo[2], hi[2])])
    return float(30.0 - (C @ T_tool_prod[:3, :3].T + T_tool_prod[:3, 3])[:, 2].min())


def test_flush_pin_names_its_mate_and_other_faces(kb):
    p = load_product(kb / "flush.yaml", "mm")
    g = _gripper()
    pin = p.parts["pin"]
    assert pin.model.grasps, "the pin must have grasps for the report to judge"
    # the test's own check: every grasp puts some corner of the hand below the mouth (a flush pin)
    for gr in pin.model.grasps.values():
        assert _mouth_depth(np.asarray(pin.pose) @ gr.T, g, gr.width) > 1.0, gr.label
    r = grasp_report(p, g, "mm")
    assert r is not None and not r.ok
    assert r.blocked is not None and r.blocked.part == "pin" and r.blocked.mate == "pin.shaft->cube.bore"
    assert r.blocked.grasps == len(pin.model.grasps) and r.blocked.usable == 0
    assert "pin.shaft->cube.bore" in r.why and "grasps on other faces" in r.needs
    assert r.to_json()["mate"] == "pin.shaft->cube.bore"


def test_headed_pin_keeps_a_grasp(kb):
    p = load_product(kb / "headed.yaml", "mm")
    g = _gripper()
    r = grasp_report(p, g, "mm")
    assert r is not None and r.ok, r.why
    row = r.parts[0]
    assert row.part == "pin" and row.usable > 0 and row.clear > 0 and row.pickup > 0
    # some grasp the test itself finds above the mouth: the head is held
    pin = p.parts["pin"]
    assert any(_mouth_depth(np.asarray(pin.pose) @ gr.T, g, gr.width) <= 0.05 for gr in pin.model.grasps.values())


@pytest.mark.parametrize("f", ["bracket_kit.yaml", "plate_pins.yaml", "turn_over.yaml", "shaft_stack.yaml",
                               "board20.yaml"])
def test_shipped_products_that_plan_are_not_refused(f):
    p = load_product(ROOT / "kb" / "products" / f, "mm")
    r = grasp_report(p, _gripper(), "mm")
    assert r is None or r.ok, r.why


def test_plan_summary_and_json_name_the_mate(kb):
    from spar_py import Planner

    plan = Planner().plan(kb / "flush_cell.yaml")
    assert plan.outcome.name == "NO_PLAN"
    grasps = plan.reason["grasps"]
    assert grasps["ok"] is False and grasps["mate"] == "pin.shaft->cube.bore" and grasps["part"] == "pin"
    assert "no grasp of pin serves pin.shaft->cube.bore" in plan.reason["summary"]
    assert "grasps on other faces" in plan.reason["summary"]


def test_derive_prints_the_report(kb):
    from spar_py.kb.products import derive_product_text

    text = derive_product_text(kb / "flush.yaml")
    assert "# grasps (default gripper, no robot): no grasp of pin serves pin.shaft->cube.bore" in text
    assert "every part keeps one usable" in derive_product_text(kb / "headed.yaml")


def _outside_count(p, g, peg: str, hole: str, origin: np.ndarray, direction: np.ndarray) -> int:
    """How many grasps of ``peg`` keep every corner of the gripper's boxes (fingers and palm,
    closed to the grasp's width) on the outer side of the plane through ``origin`` with normal
    ``direction`` (into ``hole``'s part, its frame, mm) when seated, within 0.05 mm: the test's
    own count of grasps usable at that mouth."""
    T_a = np.linalg.inv(np.asarray(p.parts[hole].pose)) @ np.asarray(p.parts[peg].pose)
    own = 0
    for gr in p.parts[peg].model.grasps.values():
        C = np.array([[x, y, z] for _, lo, hi in g.boxes(gr.width) for x in (lo[0], hi[0]) for y in (lo[1], hi[1])
                      for z in (lo[2], hi[2])])
        M = T_a @ gr.T
        own += int(float(((C @ M[:3, :3].T + M[:3, 3] - origin) @ direction).max()) <= 0.05)
    return own


def _usable_counted_at_the_mouth(product: str, part: str, parent: str, mouth, mate: str) -> None:
    """The report's usable count for ``part``'s mate is the count of grasps keeping the whole hand
    on its own side of the mouth plane ``mouth(p)`` = (point, normal), counted from the gripper's
    boxes alone, and it is not zero."""
    p = load_product(ROOT / "kb" / "products" / "fabrica" / f"{product}.yaml", "mm")
    g = _gripper()
    own = _outside_count(p, g, part, parent, *mouth(p))
    assert own > 0
    r = grasp_report(p, g, "mm")
    assert r is not None
    row = next(m for m in r.parts if m.part == part)
    assert row.mate == mate and row.usable == own


def test_through_hole_entered_from_its_far_mouth():
    """Fabrica's car: wheel4 enters the body's through hole2 from the end away from its declared
    mouth (along +y in the body's frame, the mouth declared at y = +25 mm facing -y). Its usable
    grasps are those keeping the whole hand on its own side of the far mouth (body y <= -25 mm)."""
    _usable_counted_at_the_mouth("car_pressfit", "wheel4", "body",
                                 lambda p: (np.array([0.0, -25.0, 0.0]), np.array([0.0, 1.0, 0.0])),
                                 "wheel4.peg1->body.hole2")


def test_duct_upper_usable_grasps_counted_at_the_mouth():
    """Fabrica's duct: the upper shell's grasps usable for upper.peg1->lower.hole1 are those keeping
    every corner of the hand on its own side of the plane of the hole's mouth when seated (the
    hole's axis alone). The grasps across its shell from above are among them, so the count is
    not zero."""
    def mouth(p):
        hf = p.parts["lower"].model.feature_named("hole1").geometry
        return hf.origin, hf.direction

    _usable_counted_at_the_mouth("duct", "upper", "lower", mouth, "upper.peg1->lower.hole1")


def test_hand_above_table_keeps_the_margin():
    """A hand closing straight down with its finger tips 1.25 mm over the table is above it, but
    not by a 2 mm collision margin (the clearance phase 2 keeps): the report and the layout must
    refuse it as phase 2 does. The tips' height is computed here from the finger length."""
    from spar_py.world.reach.arcs import hand_above_table

    g = Gripper.default(50.0, mm_per("mm"))
    T = np.diag([1.0, -1.0, -1.0, 1.0])  # tool z (the approach) pointing down
    T[2, 3] = 1.25                        # the finger tips (tool z = 0; the fingers run back to -finger_length)
    tips = min(float((T @ np.array([0.0, 0.0, z, 1.0]))[2]) for z in (-g.finger_length, 0.0))
    assert tips == pytest.approx(1.25)
    assert hand_above_table(g, T, 20.0, "mm")
    assert not hand_above_table(g, T, 20.0, "mm", clearance=2.0)
    assert hand_above_table(g, T, 20.0, "mm", clearance=1.2)


@pytest.mark.slow
@pytest.mark.parametrize("cell", ["fabrica_plumbers_block", "fabrica_beam"])
def test_layout_lays_each_part_where_the_report_reaches_a_grasp(cell):
    """`layout: auto` lays every non-base part out in a pose and yaw where the report counts a
    grasp it keeps (with the robot's collision margin over the table) reached by the arm."""
    from spar_py.kb.problem import load_problem

    c = load_problem(ROOT / "kb" / "problems" / f"{cell}.yaml")
    at = {p.obj: np.asarray(p.T, float) for p in c.positions.values()}
    r = grasp_report(c.product, c.robot.gripper, c.unit, c.robot, at, margin=c.robot.margin)
    assert r is not None
    assert all(row.at_cell > 0 for row in r.parts), [(row.part, row.at_cell) for row in r.parts]


@pytest.mark.parametrize("name", ["beam", "plumbers_block"])
def test_a_regrasp_is_offered_only_where_one_would_serve(name):
    """A part reached where the cell lays it but seated by none of those grasps: the report asks the
    grasps free in any stable pose too, and of those that seat it, the ones the arm reaches after a
    put-down on the table (phase 1's own put-down arc). The beam's bar1 has none that seats it (two
    put a finger in post3, the others are out of reach); the plumber's block's bolt1 has 14 (phase
    1's), but none is free at pickup in a stable pose of its model (only '-z down', a pose its
    model does not keep, freed them) and the arm reaches none of them clear of the table after
    any put-down, so neither is offered a regrasp: both need the product built elsewhere."""
    from spar_py.planning.planner import Planner
    from spar_py.world.reach.arcs import reachable_pairs
    from spar_py.world.collision import CellCache

    planner = Planner()
    plan = planner.plan(ROOT / "kb" / "problems" / f"fabrica_{name}.yaml")
    gr = plan.reason["grasps"]
    row = next(r for r in gr["parts"] if r["part"] == gr["part"])
    assert row["held"] == 0
    assert "regrasp of" not in gr["needs"] and "no regrasp on the table helps" in gr["needs"]
    assert gr["needs"].startswith("the product built elsewhere")
    if name == "beam":
        assert row["seat_any"] == 0 and row["placed_any"] == -1 and "post3" in gr["needs"]
        return
    assert row["seat_any"] == 0 and row["placed_any"] == -1 and "-z down" not in row["pose_ok"]
    # phase 1 stopped at the grasps that make the mate (hand access keeps those that seat it clear):
    # the put-down arc over every stable pose reaches none of them
    member = plan.reason["goal_data"]["args"][2]
    assert member["functor"] == "member"
    labels = member["args"][1]
    assert len(labels) == 14 and all(g.startswith("bolt1_") for g in labels)
    cell = planner.load_problem(ROOT / "kb" / "problems" / f"fabrica_{name}.yaml")
    cache = CellCache(cell)
    arc = reachable_pairs(cache, "bolt1", labels, list(cell.objects["bolt1"].poses), "reachable")
    assert arc.pairs == []
    some = reachable_pairs(cache, "bolt1", list(cell.objects["bolt1"].grasps), ["bolt1_p7"], "reachable")
    assert some.pairs  # the arc does reach other grasps after a put-down: these 14 are the ones it cannot
