"""draw.py: the ordering graph and constraint network of Sec. 6 (Figs. 23-25) and the cell pictures.

The plan dicts are built by hand in the planner's JSON schema 1: the paper's own partial
plan (Fig. 23 actions, Fig. 24 ordering, Fig. 25 label sets and arcs) and an instance of
it on the paper's cell (kb/problems/peg_in_block.yaml) whose joint vectors come from the
closed-form IK, so every picture shows a configuration the arm can take.
"""
from __future__ import annotations

import math
from itertools import product
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from spar_py import draw
from spar_py.draw import (
    arm_polyline,
    bipartite_layout,
    cell_png,
    dh_frames,
    gripper_segments,
    hole_mouth,
    implied_edges,
    layered_layout,
    network_dot,
    object_points,
    ordering_dot,
    parse_dot,
    placement_pose,
    render_png,
    scenes,
    solid_points,
    write_pictures,
)
from spar_py.geometry import inv, rotz, trans
from spar_py.kb import load_problem
from spar_py.model import Cell

ROOT = Path(__file__).resolve().parent.parent
PROBLEM = ROOT / "kb" / "problems" / "peg_in_block.yaml"
PNG_MAGIC = b"\x89PNG\r\n\x1a\n"

# Fig. 25 of the paper: label sets and arcs of the constraint network.
GRASP_1 = ["p1G1", "p1G3", "p1G6", "p1G7", "p1G8", "p1G9", "p1G11", "p1G12", "p1G13", "p1G14",
           "p1G15", "p1G17", "p1G18", "p1G20"]
GRASP_2 = [f"p2G{i}" for i in range(1, 17)]
POS_1 = ["p2P1", "p2P2", "p2P4", "p2P5", "p2P6"]
G2_POS1 = [  # (grasp, pose) numbers of the arc grasp_2-pos_1, in the paper's order
    (1, 1), (1, 4), (10, 2), (10, 4), (11, 2), (11, 6), (12, 2), (12, 5), (13, 1), (13, 5),
    (13, 6), (14, 1), (14, 6), (15, 1), (15, 5), (16, 5), (2, 1), (3, 4), (4, 5), (4, 6),
    (5, 5), (5, 6), (6, 5), (6, 6), (7, 6), (8, 1), (8, 2), (8, 4), (9, 1), (9, 2),
]
G2_TR2 = ["p2G1", "p2G16", "p2G2", "p2G3", "p2G4", "p2G5", "p2G6", "p2G7"]
G1_TR1 = ["p1G12", "p1G3", "p1G7", "p1G8"]
ARC_COUNTS = {("grasp_1", "pos_1"): 70, ("grasp_2", "pos_1"): 30, ("grasp_2", "init_pos2"): 8,
              ("grasp_1", "init_pos1"): 4}
ORDERING = [("action_2", "action_1"), ("action_3", "action_1"), ("action_4", "action_3"),
            ("action_3", "action_2")]
ACTIONS = {
    "action_1": "assemble(peg,block,[[peg_face],[block_face]],trans_1,vec_1)",
    "action_2": "pickup(peg,grasp_1)",
    "action_3": "putdown(block,pos_1)",
    "action_4": "pickup(block,grasp_2)",
}

# The instance drawn on the paper's cell: grasp the hole-down block from its side (p2G1),
# turn it hole-up (p2P1) at (24, 0) in, take the lying peg by its base (p1G11), insert it.
BLOCK_GRASP, PEG_GRASP = "p2G1", "p1G11"
PLACEMENT = {"x": 24.0, "y": 0.0, "z": 1.5, "yaw_deg": 0.0, "pose": "p2P1"}


def paper_partial() -> dict[str, Any]:
    """The partial plan of Figs. 23-25 in the planner's JSON shape."""
    actions = []
    for aid, term in ACTIONS.items():
        name, rest = term.split("(", 1)
        actions.append({"id": aid, "term": term, "name": name, "args": rest[:-1].split(",")})
    arcs = [
        {"vars": ["grasp_1", "pos_1"], "pairs": [[g, p] for g, p in product(GRASP_1, POS_1)]},
        {"vars": ["grasp_2", "pos_1"], "pairs": [[f"p2G{g}", f"p2P{p}"] for g, p in G2_POS1]},
        {"vars": ["grasp_2", "init_pos2"], "pairs": [[g, "tr2"] for g in G2_TR2]},
        {"vars": ["grasp_1", "init_pos1"], "pairs": [[g, "tr1"] for g in G1_TR1]},
    ]
    return {
        "actions": actions,
        "ordering": [list(e) for e in ORDERING],
        "variables": {"grasp_1": GRASP_1, "grasp_2": GRASP_2, "pos_1": POS_1, "init_pos1": ["tr1"],
                      "init_pos2": ["tr2"]},
        "arcs": arcs,
        "separations": [],
    }


def _q_deg(cell: Cell, T: np.ndarray) -> list[float]:
    sols = cell.robot.ik(T)
    assert len(sols) > 0, "the test instance must be reachable"
    return [float(v) for v in np.degrees(sols[0])]


def _step(cell: Cell, kind: str, action: str | None, term: str, obj: str, T: np.ndarray | None,
          placement: dict[str, Any] | None = None) -> dict[str, Any]:
    return {"kind": kind, "action": action, "term": term, "name": term.split("(")[0], "object": obj,
            "joints_deg": None if T is None else _q_deg(cell, T),
            "tool_pose": None if T is None else T.tolist(), "placement": placement}


def paper_plan(cell: Cell) -> dict[str, Any]:
    """The paper's plan with an instance on the loaded cell (tool poses = T_obj @ T_g)."""
    block, peg = cell.objects["block"], cell.objects["peg"]
    Tg2, Tg1 = block.grasps[BLOCK_GRASP].T, peg.grasps[PEG_GRASP].T
    T_place = placement_pose(cell, "block", PLACEMENT)
    T_mate = T_place @ cell.transforms["trans_1"]
    steps = [
        _step(cell, "manipulation", "action_4", f"pickup(block, {BLOCK_GRASP})", "block",
              cell.positions["tr2"].T @ Tg2),
        _step(cell, "manipulation", "action_3", "putdown(block, p2P1)", "block", T_place @ Tg2, PLACEMENT),
        _step(cell, "sensing", None, "dense_range_scan(peg)", "peg", None),
        _step(cell, "manipulation", "action_2", f"pickup(peg, {PEG_GRASP})", "peg",
              cell.positions["tr1"].T @ Tg1),
        _step(cell, "manipulation", "action_1",
              "assemble(peg, block, [[peg_face], [block_face]], trans_1, vec_1)", "peg", T_mate @ Tg1),
    ]
    return {
        "schema": 1, "problem": "peg_in_block", "outcome": "plan", "partial": paper_partial(),
        "instance": {"bindings": {"grasp_1": PEG_GRASP, "grasp_2": BLOCK_GRASP, "pos_1": "p2P1",
                                  "init_pos1": "tr1", "init_pos2": "tr2"},
                     "steps": steps, "constraints": [], "verifications": [], "recoveries": [],
                     "error_count": 0},
    }


@pytest.fixture(scope="module")
def cell() -> Cell:
    return load_problem(PROBLEM)


@pytest.fixture(scope="module")
def plan(cell: Cell) -> dict[str, Any]:
    return paper_plan(cell)


def assert_png(path: Path, min_w: int = 200, min_h: int = 100) -> tuple[int, int]:
    """The file is a non-empty PNG that matplotlib reads; returns (width, height) in pixels."""
    import matplotlib.image as mpimg

    data = path.read_bytes()
    assert data[:8] == PNG_MAGIC and len(data) > 2000
    img = mpimg.imread(path)
    h, w = img.shape[:2]
    assert w >= min_w and h >= min_h
    assert float(np.ptp(img[..., :3])) > 0.3  # not a blank page
    return w, h


# --------------------------------------------------------------------------- DOT text


def test_fig24_ordering_dot_has_every_action_and_prior_to_edge() -> None:
    plan = {"problem": "peg_in_block", "outcome": "plan", "partial": paper_partial()}
    dot = ordering_dot(plan)
    assert dot.startswith("digraph ordering {")
    assert '"action_3" [label="action_3\\nputdown(block, pos_1)"]' in dot
    assert '"action_1" [label="action_1\\nassemble(peg, block, [[peg_face], [block_face]], trans_1, vec_1)"]' in dot
    for before, after in ORDERING:
        assert f'"{before}" -> "{after}"' in dot
    # prior_to(action_3, action_1) is implied by action_3 -> action_2 -> action_1: dashed
    assert '"action_3" -> "action_1" [style="dashed", constraint="false"];' in dot
    assert '"action_4" -> "action_3";' in dot
    assert implied_edges(ORDERING) == {("action_3", "action_1")}


def test_fig25_network_dot_has_every_variable_and_pair_count() -> None:
    plan = {"problem": "peg_in_block", "outcome": "plan", "partial": paper_partial(),
            "instance": {"bindings": {"grasp_1": "p1G11"}}}
    dot = network_dot(plan)
    assert dot.startswith("graph network {")
    for var in ("grasp_1", "grasp_2", "pos_1", "init_pos1", "init_pos2"):
        assert f'"{var}" [label="{var} (' in dot
    for (a, b), n in ARC_COUNTS.items():
        assert f'"{a}" -- "{b}" [label="{n} pairs"];' in dot
    assert 'label="grasp_1 (14):\\np1G1 p1G3 p1G6 p1G7\\np1G8 p1G9 p1G11 p1G12\\n... (6 more)\\nchosen: p1G11"' in dot
    assert 'label="pos_1 (5):\\np2P1 p2P2 p2P4 p2P5\\np2P6"' in dot


def test_dot_text_parses_back() -> None:
    plan = {"problem": "peg_in_block", "outcome": "plan", "partial": paper_partial()}
    g = parse_dot(ordering_dot(plan))
    assert g.directed and set(g.nodes) == set(ACTIONS)
    assert g.nodes["action_4"]["label"] == "action_4\npickup(block, grasp_2)"
    assert [(u, v) for u, v, _ in g.edges] == ORDERING
    assert [a.get("style") for *_, a in g.edges] == [None, "dashed", None, None]
    n = parse_dot(network_dot(plan))
    assert not n.directed and len(n.nodes) == 5
    assert sorted(a["label"] for *_, a in n.edges) == ["30 pairs", "4 pairs", "70 pairs", "8 pairs"]


def test_parse_dot_reads_chains_comments_and_defaults() -> None:
    g = parse_dot('/* c */ digraph G { rankdir=LR; edge [color=red]\n # x\n a -> b -> "c d" [label="x\\"y"]; }')
    assert g.attrs["rankdir"] == "LR" and list(g.nodes) == ["a", "b", "c d"]
    assert g.edges == [("a", "b", {"color": "red", "label": 'x"y'}), ("b", "c d", {"color": "red", "label": 'x"y'})]
    with pytest.raises(ValueError, match="DOT"):
        parse_dot("digraph { a -> ")


def test_separations_are_drawn_when_present() -> None:
    partial = paper_partial() | {"separations": [{"vars": ["pos_1", "init_pos1"]}, {"junk": 1}]}
    dot = network_dot({"outcome": "plan", "partial": partial})
    assert '"pos_1" -- "init_pos1" [label="separated (dif)", style="dotted"];' in dot


def test_separations_as_the_plan_json_gives_them(tmp_path: Path) -> None:
    """The JSON lists a separation as the two terms of its dif/2; the edge joins the plan
    variables they differ in, and the picture lays out (two position nodes in one column,
    joined only by the dotted edge, once made the layout's sort fail)."""
    partial = paper_partial() | {"separations": [["part_location(peg,pos_1)", "part_location(peg,init_pos1)"]]}
    dot = network_dot({"outcome": "plan", "partial": partial})
    assert '"pos_1" -- "init_pos1" [label="separated (dif)", style="dotted"];' in dot
    assert "part_location" not in dot
    render_png(dot, tmp_path / "n.png", use_graphviz=False)
    assert (tmp_path / "n.png").stat().st_size > 0


# --------------------------------------------------------------------------- layouts


def test_ordering_layers_by_longest_path() -> None:
    lay = layered_layout(sorted(ACTIONS), ORDERING)
    assert {n: p[0] for n, p in lay.items()} == {"action_4": 0, "action_3": 1, "action_2": 2, "action_1": 3}
    # a cycle (never in a valid plan) is broken, not looped on
    cyc = layered_layout(["a", "b", "c"], [("a", "b"), ("b", "c"), ("c", "a")])
    assert sorted(p[0] for p in cyc.values()) == [0, 1, 2]


def test_long_edges_get_a_lane_in_every_layer_they_cross() -> None:
    lay = draw._layering(sorted(ACTIONS), ORDERING)
    assert [[n for n in row if not draw._is_dummy(n)] for row in lay.layers] == [
        ["action_4"], ["action_3"], ["action_2"], ["action_1"]]
    chain = lay.chains[ORDERING.index(("action_3", "action_1"))]
    assert chain[0] == "action_3" and chain[-1] == "action_1" and len(chain) == 3
    assert lay.layer_of[chain[1]] == 2 and chain[1] in lay.layers[2]
    # a back edge is drawn against the layering, its chain still from its source to its target
    cyc = draw._layering(["a", "b", "c", "d"], [("a", "b"), ("b", "c"), ("c", "d"), ("d", "a")])
    back = cyc.chains[3]
    assert back[0] == "d" and back[-1] == "a" and len(back) == 4  # d (layer 3) up to a (layer 0)


def test_network_columns_grasps_left_positions_right() -> None:
    cols = bipartite_layout(["grasp_1", "grasp_2", "pos_1", "init_pos1", "init_pos2"], list(ARC_COUNTS))
    assert cols is not None
    assert {n for n, (c, _) in cols.items() if c == 0} == {"grasp_1", "grasp_2"}
    # rows follow the neighbours: grasp_1's init_pos1 above pos_1 above grasp_2's init_pos2, or mirrored
    rows = sorted(["init_pos1", "pos_1", "init_pos2"], key=lambda n: cols[n][1])
    assert rows[1] == "pos_1"
    assert bipartite_layout(["a", "b", "c"], [("a", "b"), ("b", "c"), ("c", "a")]) is None


def test_render_png_without_graphviz(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(draw.shutil, "which", lambda name: None)
    plan = {"problem": "peg_in_block", "outcome": "plan", "partial": paper_partial()}
    w, h = assert_png(render_png(ordering_dot(plan), tmp_path / "o.png", use_graphviz=True))
    assert h > w  # four layers stacked top to bottom
    w, h = assert_png(render_png(network_dot(plan), tmp_path / "n.png"))
    assert w > h  # two columns side by side
    assert_png(render_png('graph { a -- b -- c -- a [label="3"] }', tmp_path / "tri.png"), 100, 100)


# --------------------------------------------------------------------------- cell geometry


def test_hole_mouth_from_the_goal_approach_vector(cell: Cell) -> None:
    # vec_1 = [0, 0, -1] runs down the hole, so the hole opens along the block's +z,
    # on block_face (z = 1.5 in), above its bottom centre F_h = (0, 0, 0)
    centre, axis, r = hole_mouth(cell, "block")
    assert np.allclose(centre, [0, 0, 1.5]) and np.allclose(axis, [0, 0, 1]) and r == 0.9
    assert hole_mouth(cell, "peg") is None
    # initially the block rests on block_face (p2P3): the mouth faces the table
    T0 = cell.positions["tr2"].T
    assert np.allclose(T0[:3, :3] @ axis, [0, 0, -1])
    assert np.isclose((T0[:3, :3] @ centre + T0[:3, 3])[2], 0.0)


def test_box_corners_follow_the_pose(cell: Cell) -> None:
    box = cell.objects["block"].shape[0]
    T = trans(1, 2, 3) @ rotz(math.pi / 2)
    pts = solid_points(box, T)
    # object corner (x, y, z) -> world (1 - y, 2 + x, 3 + z)
    want = [[1 - y, 2 + x, 3 + z] for x in (-1.5, 1.5) for y in (-1.5, 1.5) for z in (-1.5, 1.5)]
    assert np.allclose(pts, want)
    cyl = cell.objects["peg"].shape[1]
    rim = solid_points(cyl, np.eye(4), segments=12)
    assert rim.shape == (24, 3) and np.allclose(np.hypot(rim[:, 0], rim[:, 1]), 0.5)
    assert np.allclose(sorted(set(np.round(rim[:, 2], 9))), [1.0, 2.5])


def test_initial_objects_rest_on_the_table_where_the_problem_puts_them(cell: Cell, plan: dict[str, Any]) -> None:
    s0 = scenes(cell, plan)[0]
    for pos in cell.positions.values():
        T = s0.poses[pos.obj]
        assert np.allclose(T, pos.T)
        pts = object_points(cell.objects[pos.obj], T)
        assert math.isclose(pts[:, 2].min(), 0.0, abs_tol=1e-9)  # resting on z = 0
    block = object_points(cell.objects["block"], s0.poses["block"])
    assert np.allclose(block[:, :2].mean(axis=0), [30, 8])


def test_objects_move_with_the_steps(cell: Cell, plan: dict[str, Any]) -> None:
    sc = scenes(cell, plan)
    assert [s.held for s in sc] == [None, "block", None, None, "peg", None]
    # pickup: the grasped block has not moved; T_obj = T_tool @ inv(T_g)
    assert np.allclose(sc[1].poses["block"], cell.positions["tr2"].T)
    assert np.allclose(sc[1].poses["block"], sc[1].tool @ inv(cell.objects["block"].grasps[BLOCK_GRASP].T))
    # putdown: hole up at the placement, resting on the table
    T_place = sc[2].poses["block"]
    assert np.allclose(T_place[:3, 3], [24, 0, 1.5]) and np.allclose(T_place[:3, 2], [0, 0, 1])
    assert math.isclose(object_points(cell.objects["block"], T_place)[:, 2].min(), 0.0, abs_tol=1e-9)
    # sensing: nothing moves, the arm stays where it was
    assert np.allclose(sc[3].q, sc[2].q) and sc[3].arm_note == "unchanged"
    # assemble: the peg's tip F_p sits at the hole's bottom centre F_h
    peg, block = cell.objects["peg"], cell.objects["block"]
    tip = sc[5].poses["peg"] @ np.append(peg.feature.vector, 1)
    bottom = sc[5].poses["block"] @ np.append(block.feature.vector, 1)
    assert np.allclose(tip, bottom)
    # the peg went in with the tool (the step's tool pose), which agrees with T_block @ T_a
    assert np.allclose(sc[5].poses["peg"], T_place @ cell.transforms["trans_1"])


def test_assemble_without_a_tool_pose_uses_ta(cell: Cell, plan: dict[str, Any]) -> None:
    p = paper_plan(cell)
    p["instance"]["steps"][-1].update(joints_deg=None, tool_pose=None)
    last = scenes(cell, p)[-1]
    assert np.allclose(last.poses["peg"], last.poses["block"] @ cell.transforms["trans_1"])


def test_placement_pose_turns_the_stable_pose_about_world_z(cell: Cell) -> None:
    T = placement_pose(cell, "peg", {"x": 1, "y": 2, "yaw_deg": 90, "pose": "p1P5"})
    R = cell.objects["peg"].poses["p1P5"].R
    assert np.allclose(T[:3, :3], rotz(math.pi / 2)[:3, :3] @ R)
    assert np.allclose(T[:3, 3], [1, 2, 1.5])  # z defaults to the pose's resting height
    assert np.allclose(placement_pose(cell, "peg", {"pose": "tr1"}), cell.positions["tr1"].T)


def test_dh_frames_agree_with_forward_kinematics(cell: Cell) -> None:
    rng = np.random.default_rng(6)
    robot = cell.robot
    for q in rng.uniform(robot.limits[:, 0], robot.limits[:, 1], size=(20, 6)):
        frames = dh_frames(robot, q)
        assert len(frames) == 8 and np.allclose(frames[0], robot.base)
        assert np.allclose(frames[-1], robot.fk(q), atol=1e-9)
        line = arm_polyline(robot, q)
        assert np.allclose(line[0], robot.base[:3, 3]) and np.allclose(line[-1], frames[6][:3, 3])
        # the skeleton's length is the sum of the link lengths |a| + |d|
        links = np.abs(robot.dh[:, 1]).sum() + np.abs(robot.dh[:, 2]).sum()
        assert math.isclose(np.linalg.norm(np.diff(line, axis=0), axis=1).sum(), links)


def test_gripper_fingertips_straddle_the_tool_centre() -> None:
    T = trans(5, 6, 7) @ rotz(0.3)
    left, right, palm = gripper_segments(T, width=3.0, length=2.0)
    assert np.allclose((left[1] + right[1]) / 2, [5, 6, 7])
    assert math.isclose(np.linalg.norm(left[1] - right[1]), 3.0)
    assert math.isclose(np.linalg.norm(palm[0] - left[1]), math.hypot(2.0, 0.0))


# --------------------------------------------------------------------------- files


def test_write_pictures_on_the_paper_cell(cell: Cell, plan: dict[str, Any], tmp_path: Path) -> None:
    paths = write_pictures(cell, plan, tmp_path / "pics")
    names = [p.name for p in paths]
    assert names == ["ordering.dot", "ordering.png", "network.dot", "network.png", "cell_00_initial.png",
                     "cell_01_pickup.png", "cell_02_putdown.png", "cell_03_dense_range_scan.png",
                     "cell_04_pickup.png", "cell_05_assemble.png"]
    assert paths[0].read_text() == ordering_dot(plan)
    assert paths[2].read_text() == network_dot(plan)
    for p in paths:
        if p.suffix == ".png":
            assert_png(p)
    w, h = assert_png(paths[4])
    assert w > h


def test_a_plan_object_with_to_json_is_accepted(cell: Cell, plan: dict[str, Any]) -> None:
    class PlanLike:  # the planner's Plan: to_json() gives the schema-1 document
        def to_json(self) -> dict[str, Any]:
            return plan

    assert ordering_dot(PlanLike()) == ordering_dot(plan)
    assert network_dot(PlanLike()) == network_dot(plan)
    assert len(scenes(cell, PlanLike())) == len(plan["instance"]["steps"]) + 1


def test_no_plan_writes_nothing(cell: Cell, tmp_path: Path) -> None:
    out = tmp_path / "none"
    assert write_pictures(cell, {"schema": 1, "outcome": "no_plan", "partial": None}, out) == []
    assert not out.exists()


def test_cell_png_step_titles_and_range(cell: Cell, plan: dict[str, Any], tmp_path: Path) -> None:
    sc = scenes(cell, plan)
    assert sc[0].title == "initial state"
    assert sc[4].title == f"step 4: pickup(peg, {PEG_GRASP})"
    assert_png(cell_png(cell, plan, 4, tmp_path / "s4.png"))
    with pytest.raises(ValueError, match="step_index"):
        cell_png(cell, plan, 6, tmp_path / "s6.png")


def test_no_matplotlib_import_at_module_import() -> None:
    import subprocess
    import sys

    code = "import sys, spar_py.draw; print('matplotlib' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"
