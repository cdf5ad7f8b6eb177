"""Grasps of parts lying on the table, checked on Fabrica's stool (kb/problems/
fabrica_stool_circular.yaml): its legs are hexagonal bars 18 mm high lying on a flat with a
round peg at each end, its feet rounded blocks lying on their rounded side.

- the grasp rule judges a mesh part by its mesh, not its convex hull (fingers on a peg beside
  its shoulder are in the hull, not in the part);
- a lying round shaft is offered a grasp straight down across it, its fingers above the table;
- condition 1 of a reach arc refuses a grasp on a face the part rests on only where a contact
  is on the table (a rounded side touches it along a line);
- at an assemble the part in the hand may come within the margin of the table, not below it.

The geometry is checked with our own code: the PLY files read by trimesh alone (cm, the product
frame, which is a mesh part's object frame), the gripper's boxes from the robot file's sizes."""
from __future__ import annotations

import numpy as np
import pytest
import trimesh

from spar_py.kb.problem import load_problem
from spar_py.world.reach import arcs as arcs
from spar_py.world.collision import CellCache
from spar_py.world.reach.workspace import Requirement, assembled_touch, requirement_clear

from paths import ROOT

STOOL = ROOT / "kb" / "products" / "fabrica" / "stool_circular"
CM = 10.0  # mm per cm
#: The UR5e file's gripper (kb/robots/ur5e.yaml: a 2F-85, the loader's default finger boxes): mm.
FINGER_LENGTH, FINGER_WIDTH, FINGER_THICKNESS = 60.0, 20.0, 10.0
MARGIN_MM = 2.0  # kb/robots/ur5e.yaml collision: margin


@pytest.fixture(scope="module")
def stool():
    cell = load_problem(ROOT / "kb" / "problems" / "fabrica_stool_circular.yaml")
    return cell, CellCache(cell)


def _mesh(ply: str) -> trimesh.Trimesh:
    m = trimesh.load(STOOL / ply, process=False)
    m.apply_scale(CM)
    return m


def _finger_points(T: np.ndarray, width: float, n: int = 7) -> np.ndarray:
    """Points filling both closed fingers' boxes (1 mm inside their faces) of the tool at T
    (object frame): x across the finger, y out from the contact face, z from the tip back."""
    u = np.linspace(-FINGER_WIDTH / 2 + 1, FINGER_WIDTH / 2 - 1, n)
    v = np.linspace(1, FINGER_THICKNESS - 1, n)
    w = np.linspace(-FINGER_LENGTH + 1, -1, n)
    X, Y, Z = np.meshgrid(u, v, w, indexing="ij")
    pts = []
    for side in (1.0, -1.0):
        local = np.column_stack([X.ravel(), side * (width / 2 + Y.ravel()), Z.ravel()])
        pts.append(local @ T[:3, :3].T + T[:3, 3])
    return np.concatenate(pts)


def _finger_corners(T: np.ndarray, width: float) -> np.ndarray:
    """The closed fingers' box corners of the tool at T (T's frame's coordinates)."""
    out = []
    for side in (1.0, -1.0):
        for x in (-FINGER_WIDTH / 2, FINGER_WIDTH / 2):
            for y in (width / 2, width / 2 + FINGER_THICKNESS):
                for z in (-FINGER_LENGTH, 0.0):
                    out.append(T[:3, :3] @ np.array([x, side * y, z]) + T[:3, 3])
    return np.array(out)


def _peg_grasps_straight_down(cell, part: str, T_O: np.ndarray) -> list:
    """The part's grasps whose approach points straight down at world pose T_O."""
    return [g for g in cell.objects[part].grasps.values()
            if "via" not in g.label and (T_O[:3, :3] @ np.asarray(g.T)[:3, 2])[2] < -1 + 1e-9]


def test_lying_leg_has_a_grasp_straight_down_with_fingers_above_the_table(stool):
    cell, _ = stool
    T_O = np.asarray(cell.positions["tr_leg1"].T, float)
    down = _peg_grasps_straight_down(cell, "leg1", T_O)
    assert down, "no grasp straight down onto the lying leg"
    for g in down:
        W = T_O @ np.asarray(g.T, float)
        low = _finger_corners(W, g.width)[:, 2].min()
        assert low > MARGIN_MM, (g.label, low)


def test_grasp_rule_judges_the_mesh_not_its_hull(stool):
    cell, cache = stool
    T_O = np.asarray(cell.positions["tr_leg1"].T, float)
    g = _peg_grasps_straight_down(cell, "leg1", T_O)[0]
    T = np.asarray(g.T, float)
    mesh = _mesh("1.ply")
    pts = _finger_points(T, g.width)
    assert not mesh.contains(pts).any()  # the fingers stay out of the leg ...
    assert mesh.convex_hull.contains(pts).any()  # ... but not out of its hull
    state = cache.scene().at({}, grasped="leg1", attached={"leg1": np.linalg.inv(T)}, width=g.width)
    assert state.grasp_ok(np.linalg.inv(T))[0]
    # slid 6 mm along the peg towards the hexagonal body, the fingers enter the leg
    d = np.asarray(cell.objects["leg1"].feature_named("peg1").geometry.direction, float)
    for s in (6.0, -6.0):
        Ts = T.copy()
        Ts[:3, 3] += s * d
        if mesh.contains(_finger_points(Ts, g.width)).any():
            break
    else:
        pytest.fail("neither slide puts a finger into the leg")
    assert not state.grasp_ok(np.linalg.inv(Ts))[0]


def test_lying_leg_is_picked_up_clear(stool):
    cell, cache = stool
    A = arcs.reachable_pairs(cache, "leg1", list(cell.objects["leg1"].grasps), ["tr_leg1"])
    assert A.pairs


def test_rounded_side_lying_on_the_table_is_gripped_above_it(stool):
    cell, cache = stool
    foot = cell.objects["foot0"]
    T_O = np.asarray(cell.positions["tr_foot0"].T, float)
    rests = set(arcs.resting_faces(cell, "foot0", "tr_foot0"))
    ok = {g for g, _ in arcs.reachable_pairs(cache, "foot0", list(foot.grasps), ["tr_foot0"]).pairs}
    on_resting = [g for g in ok if rests & set(foot.grasps[g].gfaces)]
    assert on_resting, "no grasp on the rounded side it lies on"
    mesh = _mesh("0.ply")
    for label in on_resting:
        g = foot.grasps[label]
        T = T_O @ np.asarray(g.T, float)
        # where the closing line meets the foot's surface: both contacts above the table
        inv = np.linalg.inv(T_O)
        centre = inv[:3, :3] @ T[:3, 3] + inv[:3, 3]
        c = inv[:3, :3] @ T[:3, 1]
        loc, _, _ = mesh.ray.intersects_location(np.array([centre, centre]), np.array([c, -c]))
        assert len(loc) >= 2
        z = (loc @ T_O[:3, :3].T + T_O[:3, 3])[:, 2]
        assert z.min() > 1.0, (label, z)
    # standing on its planar end, the grasps across the ends are refused (the paper's condition 1)
    stand = next(p for p in foot.poses.values() if p.rfaces == ("nz",))
    held = {g for g, _ in arcs.reachable_pairs(cache, "foot0", list(foot.grasps), [stand.label],
                                               rule="paper").pairs}
    assert held and not any("nz" in foot.grasps[g].gfaces for g in held)


def test_assemble_may_come_near_the_table_not_below_it(stool):
    cell, cache = stool
    T_seat = np.asarray(cell.positions["tr_seat"].T, float)
    Ta = np.asarray(cell.transforms["trans_leg1"], float)
    leg = _mesh("1.ply")
    low = (leg.vertices @ (T_seat @ Ta)[:3, :3].T + (T_seat @ Ta)[:3, 3])[:, 2].min()
    assert 0.0 < low < MARGIN_MM  # the product seats the leg's end within the margin of the table
    T_O = np.asarray(cell.positions["tr_leg1"].T, float)
    g = _peg_grasps_straight_down(cell, "leg1", T_O)
    g = next(x for x in g if "peg2" in x.gfaces)
    req = Requirement(Ta @ np.asarray(g.T, float), ("leg1", np.linalg.inv(np.asarray(g.T, float))), g.width)
    assert requirement_clear(cache, "seat", T_seat[None], req).ok[0]
    lower = T_seat.copy()
    lower[2, 3] -= 2 * low  # the seat sunk: the leg's end would go below the table top
    r = requirement_clear(cache, "seat", lower[None], req)
    assert not r.ok[0] and ("held:leg1", "table") in r.pairs[0]


def test_only_a_product_seats_a_part_near_the_table(stool):
    cell, _ = stool
    assert assembled_touch(cell, ["leg1"]) == ["held:leg1"]
    paper = load_problem(ROOT / "kb" / "problems" / "peg_in_block.yaml")
    assert assembled_touch(paper, ["peg"]) == []
