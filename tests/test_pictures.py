"""spar_py.pictures: the ordering graph and constraint network of Sec. 6 (Figs. 23-25), drawn by
Graphviz's dot, and the cell pictures drawn from each step's world.

The plan dicts are built by hand in the planner's JSON shape: the paper's own partial plan
(Fig. 23 actions, Fig. 24 ordering, Fig. 25 label sets and arcs) and an instance of it on
the paper's cell (kb/problems/peg_in_block.yaml) whose joint vectors come from the
closed-form IK, so every picture shows a configuration the arm can take. Each step carries
``poses`` and ``held`` as the planner writes them.
"""
from __future__ import annotations

import json
import math
import struct
import subprocess
import sys
from itertools import product
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from spar_py.core.errors import SparError, SparValueError
from spar_py.core.geometry import rotz, trans
from spar_py.kb import load_problem
from spar_py.core.model import Cell
from spar_py.pictures import cell_png, network_dot, ordering_dot, render_png, scenes, write_pictures
from spar_py.pictures import graphs
from spar_py.pictures.cell import arm_polyline, gripper_segments, hole_mouth, object_points, solid_points
from spar_py.pictures.graphs import DPI, implied_edges
from spar_py.pictures.scene import held_grasp, step_world
from spar_py.planning.planner import Outcome, Plan

from paths import ROOT

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
VARIABLES = {"grasp_1": GRASP_1, "grasp_2": GRASP_2, "pos_1": POS_1, "init_pos1": ["tr1"], "init_pos2": ["tr2"]}
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


def _typed(doc: dict) -> Plan:
    """The typed Plan of a plan JSON document, or of a test's partial one (the pictures take a Plan and
    read its problem, outcome, partial plan and instance)."""
    return Plan(problem=doc.get("problem", ""), outcome=Outcome(doc["outcome"]), partial=doc.get("partial"),
                instance=doc.get("instance"))


def paper_partial() -> dict[str, Any]:
    """The partial plan of Figs. 23-25 in the planner's JSON shape."""
    actions = []
    for aid, term in ACTIONS.items():
        name, rest = term.split("(", 1)
        actions.append({"id": aid, "term": term, "name": name, "args": rest[:-1].split(",")})
    arcs = [
        {"vars": ["grasp_1", "pos_1"], "pairs": [[g, p] for g, p in product(GRASP_1, POS_1)]},
        {"vars": ["pos_1", "grasp_2"], "pairs": [[f"p2P{p}", f"p2G{g}"] for g, p in G2_POS1]},  # position first
        {"vars": ["grasp_2", "init_pos2"], "pairs": [[g, "tr2"] for g in G2_TR2]},
        {"vars": ["grasp_1", "init_pos1"], "pairs": [[g, "tr1"] for g in G1_TR1]},
    ]
    return {"actions": actions, "ordering": [list(e) for e in ORDERING], "variables": VARIABLES,
            "arcs": arcs, "separations": []}


def graph_plan(**partial: Any) -> dict[str, Any]:
    return {"problem": "peg_in_block", "outcome": "plan", "partial": paper_partial() | partial,
            "instance": {"bindings": {"grasp_1": PEG_GRASP}}}


def _q_deg(cell: Cell, T: np.ndarray) -> list[float]:
    sols = cell.robot.ik(T)
    assert len(sols) > 0, "the test instance must be reachable"
    return [float(v) for v in np.degrees(sols[0])]


def _step(cell: Cell, kind: str, term: str, obj: str, T: np.ndarray | None, poses: dict[str, np.ndarray],
          held: str | None, placement: dict[str, Any] | None = None) -> dict[str, Any]:
    return {"kind": kind, "term": term, "name": term.split("(")[0], "object": obj,
            "joints_deg": None if T is None else _q_deg(cell, T),
            "tool_pose": None if T is None else T.tolist(), "placement": placement,
            "poses": {k: v.tolist() for k, v in poses.items()}, "held": held}


def paper_plan(cell: Cell) -> dict[str, Any]:
    """The paper's plan with an instance on the loaded cell (tool poses = T_obj @ T_g) whose
    steps carry each part's world pose at the step's end-point, as the planner writes them."""
    block, peg = cell.objects["block"], cell.objects["peg"]
    Tg2, Tg1 = block.grasps[BLOCK_GRASP].T, peg.grasps[PEG_GRASP].T
    T_block0, T_peg0 = cell.positions["tr2"].T, cell.positions["tr1"].T
    R_place = np.eye(4)
    R_place[:3, :3] = block.poses[PLACEMENT["pose"]].R
    T_place = trans(PLACEMENT["x"], PLACEMENT["y"], PLACEMENT["z"]) @ R_place  # hole up, on the table
    T_mate = T_place @ cell.transforms["trans_1"]
    start = {"block": T_block0, "peg": T_peg0}
    placed = {"block": T_place, "peg": T_peg0}
    steps = [
        _step(cell, "manipulation", f"pickup(block, {BLOCK_GRASP})", "block", T_block0 @ Tg2, start, "block"),
        _step(cell, "manipulation", "putdown(block, p2P1)", "block", T_place @ Tg2, placed, None, PLACEMENT),
        _step(cell, "sensing", "dense_range_scan(peg)", "peg", None, placed, None),
        _step(cell, "manipulation", f"pickup(peg, {PEG_GRASP})", "peg", T_peg0 @ Tg1, placed, "peg"),
        _step(cell, "manipulation", "assemble(peg, block, [[peg_face], [block_face]], trans_1, vec_1)", "peg",
              T_mate @ Tg1, {"block": T_place, "peg": T_mate}, None),
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


def png_size(path: Path) -> tuple[int, int]:
    """(width, height) in pixels of a PNG file, from its IHDR chunk; fails for anything else."""
    data = path.read_bytes()
    assert data[:8] == PNG_MAGIC and data[12:16] == b"IHDR" and len(data) > 2000
    return struct.unpack(">II", data[16:24])


def assert_png(path: Path, min_w: int = 200, min_h: int = 100) -> tuple[int, int]:
    """The file is a PNG of at least min_w x min_h that is not a blank page; returns (width, height)."""
    import matplotlib.image as mpimg

    w, h = png_size(path)
    assert w >= min_w and h >= min_h
    assert float(np.ptp(mpimg.imread(path)[..., :3])) > 0.3
    return w, h


def dot_json(dot_source: str) -> dict[str, Any]:
    """Graphviz's own reading and layout of DOT text (``dot -Tjson``): the test checks what dot
    understood, with no DOT parser of ours."""
    r = subprocess.run([graphs.dot_executable(), "-Tjson"], input=dot_source.encode(), capture_output=True,
                       check=True, timeout=60)
    return json.loads(r.stdout)


def _nodes_edges(g: dict[str, Any]) -> tuple[dict[str, dict[str, Any]], list[tuple[str, str, dict[str, Any]]]]:
    objs = g.get("objects", [])
    names = [o["name"] for o in objs]
    return ({o["name"]: o for o in objs},
            [(names[e["tail"]], names[e["head"]], e) for e in g.get("edges", [])])


def _xy(node: dict[str, Any]) -> tuple[float, float]:
    x, y = node["pos"].split(",")
    return float(x), float(y)


# --------------------------------------------------------------------------- ordering graph (Fig. 24, bottom)


def test_fig24_ordering_dot_has_every_action_and_prior_to_edge() -> None:
    dot = ordering_dot(_typed(graph_plan()))
    assert dot.startswith("digraph ordering {")
    assert '"action_3" [label="action_3\\lputdown(block, pos_1)\\l"];' in dot
    nodes, edges = _nodes_edges(dot_json(dot))
    assert set(nodes) == set(ACTIONS)
    assert nodes["action_4"]["label"] == "action_4\\lpickup(block, grasp_2)\\l"
    # the long assemble term is wrapped, its text unchanged
    assert nodes["action_1"]["label"].replace("\\l", " ").split() == \
        "action_1 assemble(peg, block, [[peg_face], [block_face]], trans_1, vec_1)".split()
    assert sorted((u, v) for u, v, _ in edges) == sorted(ORDERING)
    # prior_to(action_3, action_1) is implied by action_3 -> action_2 -> action_1: dashed, no rank constraint
    style = {(u, v): (e.get("style"), e.get("constraint")) for u, v, e in edges}
    assert style.pop(("action_3", "action_1")) == ("dashed", "false")
    assert set(style.values()) == {(None, None)}
    assert implied_edges(ORDERING) == {("action_3", "action_1")}


def test_ordering_layout_puts_each_action_below_the_ones_prior_to_it() -> None:
    nodes, edges = _nodes_edges(dot_json(ordering_dot(_typed(graph_plan()))))
    for u, v, _ in edges:
        assert _xy(nodes[u])[1] > _xy(nodes[v])[1]  # dot's y grows upwards: Before above After
    assert sorted(nodes, key=lambda n: -_xy(nodes[n])[1]) == ["action_4", "action_3", "action_2", "action_1"]


def test_ordering_nodes_for_actions_known_only_from_the_ordering() -> None:
    dot = ordering_dot(_typed({"outcome": "plan", "partial": {"ordering": [["action_10", "action_9"]]}}))
    nodes, edges = _nodes_edges(dot_json(dot))
    assert set(nodes) == {"action_9", "action_10"} and [(u, v) for u, v, _ in edges] == [("action_10", "action_9")]
    assert dot.index('"action_9" [') < dot.index('"action_10" [')  # natural order


# --------------------------------------------------------------------------- constraint network (Fig. 24 top, 25)


def test_fig25_network_has_one_node_per_variable_with_its_label_count() -> None:
    dot = network_dot(_typed(graph_plan()))
    assert dot.startswith("graph network {")
    nodes, edges = _nodes_edges(dot_json(dot))
    assert set(nodes) == set(VARIABLES)
    for var, labels in VARIABLES.items():
        assert nodes[var]["label"].startswith(f"{var} ({len(labels)}):\\l")
    assert nodes["grasp_1"]["label"] == \
        "grasp_1 (14):\\lp1G1 p1G3 p1G6 p1G7\\lp1G8 p1G9 p1G11 p1G12\\l... (6 more)\\lchosen: p1G11\\l"
    assert nodes["pos_1"]["label"] == "pos_1 (5):\\lp2P1 p2P2 p2P4 p2P5\\lp2P6\\l"
    assert {n: nodes[n]["fillcolor"] for n in nodes} == {
        "grasp_1": graphs.GRASP_FILL, "grasp_2": graphs.GRASP_FILL, "pos_1": graphs.POSITION_FILL,
        "init_pos1": graphs.POSITION_FILL, "init_pos2": graphs.POSITION_FILL}


def test_fig25_network_has_an_edge_per_arc_with_its_pair_count() -> None:
    nodes, edges = _nodes_edges(dot_json(network_dot(_typed(graph_plan()))))
    assert {(u, v): e["label"] for u, v, e in edges} == {k: f"{n} pairs" for k, n in ARC_COUNTS.items()}
    # grasps are written first, so dot ranks them left of the positions
    for u, v, _ in edges:
        assert _xy(nodes[u])[0] < _xy(nodes[v])[0]


def test_network_arc_kind_and_a_single_pair() -> None:
    partial = {"variables": {"grasp_1": ["g"], "pos_1": ["p"]},
               "arcs": [{"vars": ["grasp_1", "pos_1"], "pairs": [["g", "p"]], "kind": "reachable"}]}
    _, edges = _nodes_edges(dot_json(network_dot(_typed({"outcome": "plan", "partial": partial}))))
    assert [e["label"] for *_, e in edges] == ["reachable\\n1 pair"]


def test_separations_are_drawn_when_present() -> None:
    dot = network_dot(_typed(graph_plan(separations=[{"vars": ["pos_1", "init_pos1"]}, {"junk": 1}])))
    _, edges = _nodes_edges(dot_json(dot))
    seps = [(u, v, e["style"], e["constraint"]) for u, v, e in edges if e["label"] == "separated (dif)"]
    assert seps == [("pos_1", "init_pos1", "dotted", "false")]


def test_separations_as_the_plan_json_gives_them(tmp_path: Path) -> None:
    """The JSON lists a separation as the two terms of its dif/2, as term data; the edge
    joins the plan variables they differ in."""
    sep = {"deleted": {"functor": "part_location", "args": ["peg", "pos_1"]},
           "condition": {"functor": "part_location", "args": ["peg", "init_pos1"]},
           "text": ["part_location(peg,pos_1)", "part_location(peg,init_pos1)"]}
    dot = network_dot(_typed(graph_plan(separations=[sep])))
    assert '"pos_1" -- "init_pos1" [label="separated (dif)", style="dotted", constraint="false"];' in dot
    assert "part_location" not in dot
    assert_png(render_png(dot, tmp_path / "n.png"))


def test_quotes_and_backslashes_in_names_reach_dot_intact() -> None:
    """A quote closes no string early and a backslash stays one (dot keeps escStrings raw: ``\\\\``)."""
    partial = {"actions": [{"id": 'a"1', "term": "say('x\\y')"}], "ordering": []}
    nodes, _ = _nodes_edges(dot_json(ordering_dot(_typed({"outcome": "plan", "partial": partial}))))
    assert list(nodes) == ['a"1'] and nodes['a"1']["label"] == "a\"1\\lsay('x\\\\y')\\l"


# --------------------------------------------------------------------------- rendering with dot


@pytest.mark.parametrize("which", ["ordering", "network"])
def test_png_is_dots_drawing_at_the_set_resolution(tmp_path: Path, which: str) -> None:
    """The PNG is dot's layout drawn at DPI: its size is dot's bounding box (points) plus the pad."""
    dot = (ordering_dot if which == "ordering" else network_dot)(_typed(graph_plan()))
    path = render_png(dot, tmp_path / f"{which}.png")
    w, h = assert_png(path)
    g = dot_json(dot)
    _, _, bw, bh = (float(v) for v in g["bb"].split(","))
    pad = float(g["pad"])
    assert abs(w - (bw / 72 + 2 * pad) * DPI) <= 2 and abs(h - (bh / 72 + 2 * pad) * DPI) <= 2


def test_missing_dot_is_a_one_line_spar_error(cell: Cell, plan: dict[str, Any], tmp_path: Path,
                                              monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(graphs.shutil, "which", lambda name: None)
    with pytest.raises(SparError, match="install the graphviz package") as e:
        render_png(ordering_dot(_typed(plan)), tmp_path / "o.png")
    assert "\n" not in str(e.value) and not (tmp_path / "o.png").exists()
    out = tmp_path / "pics"
    with pytest.raises(SparError, match="graphviz"):
        write_pictures(cell, _typed(plan), out)
    assert not out.exists()  # checked before anything is written


def test_cli_without_dot_says_so_in_one_line(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                            capsys: pytest.CaptureFixture[str]) -> None:
    from spar_py.app import cli

    monkeypatch.setattr(graphs.shutil, "which", lambda name: None)
    with pytest.raises(SystemExit) as e:
        cli.main(["plan", str(PROBLEM), "--png", str(tmp_path / "pics")])
    err = capsys.readouterr().err
    assert e.value.code != 0 and "Traceback" not in err
    lines = [ln for ln in err.splitlines() if "graphviz" in ln]
    assert len(lines) == 1 and "install the graphviz package" in lines[0]


def test_dot_failure_is_a_spar_error_with_dots_reason(tmp_path: Path) -> None:
    with pytest.raises(SparError, match=r"dot -Tpng failed drawing bad\.png: .*syntax error"):
        render_png("digraph { a -> ", tmp_path / "bad.png")


# --------------------------------------------------------------------------- scenes from the plan's poses


def test_initial_objects_rest_on_the_table_where_the_problem_puts_them(cell: Cell, plan: dict[str, Any]) -> None:
    s0 = scenes(cell, _typed(plan))[0]
    for pos in cell.positions.values():
        T = s0.poses[pos.obj]
        assert np.allclose(T, pos.T)
        pts = object_points(cell.objects[pos.obj], T)
        assert math.isclose(pts[:, 2].min(), 0.0, abs_tol=1e-9)  # resting on z = 0
    block = object_points(cell.objects["block"], s0.poses["block"])
    assert np.allclose(block[:, :2].mean(axis=0), [30, 8])
    assert s0.arm_note == "home" and s0.held is None
    # no home in the cell, no motions in the plan: the documented default home, mid-range
    assert np.allclose(s0.q, cell.robot.limits.mean(axis=1))


def test_scenes_draw_the_poses_and_held_the_plan_gives(cell: Cell, plan: dict[str, Any]) -> None:
    sc = scenes(cell, _typed(plan))
    steps = plan["instance"]["steps"]
    assert len(sc) == len(steps) + 1
    for s, st in zip(sc[1:], steps):
        assert set(s.poses) == set(st["poses"]) and s.held == st["held"]
        for key, T in st["poses"].items():
            assert np.array_equal(s.poses[key], np.asarray(T))
    assert [s.grasp for s in sc] == [None, BLOCK_GRASP, None, None, PEG_GRASP, None]
    assert sc[2].detail.endswith("placed block p2P1 at (24, 0) yaw 0 deg")
    assert sc[1].detail.startswith(f"holding block ({BLOCK_GRASP}); q = (")


def test_scenes_do_not_replay_the_plan(cell: Cell) -> None:
    """A pose the replay would never give (the peg far off, the block upside down at the assemble)
    is drawn as given: the scene is the step's world, not a replay."""
    p = paper_plan(cell)
    odd = {"peg": trans(100, -40, 0.5).tolist(), "block": (trans(1, 2, 3) @ rotz(1.0)).tolist()}
    p["instance"]["steps"][-1]["poses"] = odd
    last = scenes(cell, _typed(p))[-1]
    assert np.array_equal(last.poses["peg"], np.asarray(odd["peg"]))
    assert np.array_equal(last.poses["block"], np.asarray(odd["block"]))


def test_the_arm_is_drawn_from_the_steps_joints(cell: Cell, plan: dict[str, Any]) -> None:
    sc = scenes(cell, _typed(plan))
    steps = plan["instance"]["steps"]
    for s, st in zip(sc[1:], steps):
        if st["joints_deg"] is not None:
            assert np.allclose(np.degrees(s.q), st["joints_deg"])
            assert np.allclose(s.frames, cell.robot.frames(s.q)) and s.arm_note == ""
            assert np.allclose(s.tool, st["tool_pose"], atol=1e-6)  # fk of the IK solution
    # sensing: no joints, the arm at rest (home), as in the initial state
    assert steps[2]["joints_deg"] is None
    assert np.array_equal(sc[3].q, sc[0].q) and sc[3].arm_note == "home"
    assert "(home)" in sc[3].detail and sc[3].detail.startswith("sensing")


def test_held_grasp_is_the_one_that_puts_the_tool_where_it_is(cell: Cell) -> None:
    block = cell.objects["block"]
    T = cell.positions["tr2"].T
    for label in ("p2G1", "p2G7"):
        assert held_grasp(cell, "block", T, T @ block.grasps[label].T) == label
    assert held_grasp(cell, "block", T, trans(0, 0, 0.1) @ T @ block.grasps["p2G1"].T) is None
    assert held_grasp(cell, None, T, T) is None and held_grasp(cell, "block", T, None) is None


def test_a_malformed_step_world_is_a_value_error() -> None:
    with pytest.raises(SparValueError, match=r"step 3: poses\['peg'\]: a 4x4 world pose"):
        step_world({"poses": {"peg": [[1, 0, 0], [0, 1, 0]]}, "held": None}, 3)
    with pytest.raises(SparValueError, match="step 2: held object 'peg' has no pose"):
        step_world({"poses": {"block": np.eye(4).tolist()}, "held": "peg"}, 2)


def test_stock_parts_keep_keys_of_their_own(cell: Cell) -> None:
    """A stock's other parts are keyed ``obj@init_position``; each is drawn from its object's model."""
    p = paper_plan(cell)
    spare = (trans(20, -10, 0) @ cell.positions["tr1"].T).tolist()
    for st in p["instance"]["steps"]:
        st["poses"]["peg@tr9"] = spare
    last = scenes(cell, _typed(p))[-1]
    assert np.array_equal(last.poses["peg@tr9"], np.asarray(spare))


# --------------------------------------------------------------------------- the planner's own plan


def test_the_planners_plan_draws_the_peg_seated_in_the_hole(cell: Cell) -> None:
    """The scenes of a real plan (poses from phase 2): after the assemble, the peg's tip
    F_p sits at the hole's bottom centre F_h, computed here from the object models."""
    from spar_py.planning.planner import Planner

    doc = Planner().plan(PROBLEM).to_json()
    sc = scenes(cell, _typed(doc))
    peg, block = cell.objects["peg"], cell.objects["block"]
    tip = sc[-1].poses["peg"] @ np.append(peg.features[0].vector, 1)
    bottom = sc[-1].poses["block"] @ np.append(block.features[0].vector, 1)
    assert np.allclose(tip, bottom, atol=1e-9)
    assert [s.held for s in sc] == [None, "block", None, "peg", None]


def test_a_step_without_poses_is_a_value_error(cell: Cell, plan: dict[str, Any]) -> None:
    p = paper_plan(cell)
    del p["instance"]["steps"][1]["poses"]
    with pytest.raises(SparValueError, match="step 2: no poses"):
        scenes(cell, _typed(p))


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


def test_arm_polyline_runs_through_the_robots_frames(cell: Cell) -> None:
    rng = np.random.default_rng(6)
    robot = cell.robot
    links = np.abs(robot.dh[:, 1]).sum() + np.abs(robot.dh[:, 2]).sum()
    for q in rng.uniform(robot.limits[:, 0], robot.limits[:, 1], size=(20, 6)):
        F = robot.frames(q)
        line = arm_polyline(robot, F)
        assert np.allclose(line[0], robot.base[:3, 3]) and np.allclose(line[-1], F[6][:3, 3])
        for i in range(1, 7):  # every frame origin is a vertex of the skeleton
            assert np.min(np.linalg.norm(line - F[i][:3, 3], axis=1)) < 1e-9
        # the skeleton's length is the sum of the link lengths |a| + |d|
        assert math.isclose(np.linalg.norm(np.diff(line, axis=0), axis=1).sum(), links)


def test_gripper_fingertips_straddle_the_tool_centre() -> None:
    T = trans(5, 6, 7) @ rotz(0.3)
    left, right, palm = gripper_segments(T, width=3.0, length=2.0)
    assert np.allclose((left[1] + right[1]) / 2, [5, 6, 7])
    assert math.isclose(np.linalg.norm(left[1] - right[1]), 3.0)
    assert math.isclose(np.linalg.norm(palm[0] - left[1]), math.hypot(2.0, 0.0))


# --------------------------------------------------------------------------- files


def test_write_pictures_on_the_paper_cell(cell: Cell, plan: dict[str, Any], tmp_path: Path) -> None:
    paths = write_pictures(cell, _typed(plan), tmp_path / "pics")
    names = [p.name for p in paths]
    assert names == ["ordering.dot", "ordering.png", "network.dot", "network.png", "cell_00_initial.png",
                     "cell_01_pickup.png", "cell_02_putdown.png", "cell_03_dense_range_scan.png",
                     "cell_04_pickup.png", "cell_05_assemble.png"]
    assert paths[0].read_text() == ordering_dot(_typed(plan))
    assert paths[2].read_text() == network_dot(_typed(plan))
    for p in paths:
        if p.suffix == ".png":
            assert_png(p)
    assert [png_size(p) for p in paths[4:]] == [(1200, 720)] * 6


def test_no_plan_writes_nothing(cell: Cell, tmp_path: Path) -> None:
    out = tmp_path / "none"
    assert write_pictures(cell, _typed({"schema": 1, "outcome": "no_plan", "partial": None}), out) == []
    assert not out.exists()


def test_cell_png_step_titles_and_range(cell: Cell, plan: dict[str, Any], tmp_path: Path) -> None:
    sc = scenes(cell, _typed(plan))
    assert sc[0].title == "initial state"
    assert sc[4].title == f"step 4: pickup(peg, {PEG_GRASP})"
    assert_png(cell_png(cell, _typed(plan), 4, tmp_path / "s4.png"))
    with pytest.raises(ValueError, match="step_index"):
        cell_png(cell, _typed(plan), 6, tmp_path / "s6.png")


def test_no_matplotlib_import_at_package_import() -> None:
    code = "import sys, spar_py.pictures; print('matplotlib' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"


# --------------------------------------------------------------------------- collision shapes and obstacles

SHELF = ROOT / "kb" / "problems" / "shelf.yaml"
ROBOT_YAML = ROOT / "kb" / "robots" / "puma762.yaml"
GRIPPER_GIDS = ("gripper:palm", "gripper:finger_l", "gripper:finger_r")


def _gids(ax: Any) -> list[str]:
    return [a.get_gid() for a in [*ax.collections, *ax.patches] if a.get_gid()]


def test_each_link_shape_the_gripper_and_each_obstacle_is_drawn_in_every_panel(plan: dict[str, Any]) -> None:
    """The shelf cell at the peg's pickup: every link shape the robot file lists, the palm and
    both fingers, and the shelf are one artist each in the 3-D, top and side panels; the shelf's
    top-view outline is the problem file's box."""
    import matplotlib.pyplot as plt
    import yaml

    from spar_py.pictures.cell import draw_figure, extent

    links = [ln["name"] for ln in yaml.safe_load(ROBOT_YAML.read_text())["collision"]["links"]]
    shelf_box = yaml.safe_load(SHELF.read_text())["obstacles"][0]["box"]
    shelf = load_problem(SHELF)
    sc = scenes(shelf, _typed(plan))
    fig = draw_figure(shelf, sc[4], extent(shelf, sc))
    try:
        panels = fig.axes[:3]
        for ax in panels:
            gids = _gids(ax)
            assert all(gids.count(f"link:{n}") == 1 for n in links), gids
            assert all(gids.count(g) == 1 for g in GRIPPER_GIDS), gids
            assert gids.count("obstacle:shelf") == 1
        top = next(p for p in panels[1].patches if p.get_gid() == "obstacle:shelf")
        xy = np.asarray(top.get_xy())
        assert np.allclose(xy.min(axis=0), shelf_box["min"][:2]) and np.allclose(xy.max(axis=0), shelf_box["max"][:2])
    finally:
        plt.close(fig)


def test_fingers_at_the_grasp_width_and_links_in_their_frames(plan: dict[str, Any]) -> None:
    """The drawn fingers, in the tool frame, are the robot file's boxes with their contact faces
    the held grasp's width apart; the forearm is drawn round its capsule's axis in frame 3."""
    import yaml

    from spar_py.pictures.cell import robot_shapes

    doc = yaml.safe_load(ROBOT_YAML.read_text())
    mm = 1 / 25.4  # the cell is in inches, the robot file in mm
    f = doc["gripper"]["finger"]
    fore = next(ln for ln in doc["collision"]["links"] if ln["name"] == "forearm")
    cell_ = load_problem(SHELF)
    s = scenes(cell_, _typed(plan))[4]  # after pickup(peg, p1G11): 3 in wide
    w = cell_.objects["peg"].grasps[PEG_GRASP].width
    shapes = {sh.gid: sh for sh in robot_shapes(cell_, s)}
    T = np.linalg.inv(s.tool)
    left = shapes["gripper:finger_l"].points @ T[:3, :3].T + T[:3, 3]
    assert np.allclose(left.min(axis=0), [-f["width"] / 2 * mm, w / 2, -f["length"] * mm])
    assert np.allclose(left.max(axis=0), [f["width"] / 2 * mm, w / 2 + f["thickness"] * mm, 0])
    F3 = np.linalg.inv(s.frames[3])
    p = shapes["link:forearm"].points @ F3[:3, :3].T + F3[:3, 3]
    a, b = np.multiply(fore["capsule"]["from"], mm), np.multiply(fore["capsule"]["to"], mm)
    t = np.clip((p - a) @ (b - a) / ((b - a) @ (b - a)), 0, 1)
    r = np.linalg.norm(p - (a + t[:, None] * (b - a)), axis=1)
    assert np.allclose(r, fore["capsule"]["radius"] * mm)


def test_a_cell_with_an_obstacle_is_drawn_differently(plan: dict[str, Any], tmp_path: Path) -> None:
    """The same scene and extents with and without the shelf: different pictures, the shelf's
    artist only in the first."""
    import dataclasses

    import matplotlib.image as mpimg
    import matplotlib.pyplot as plt

    from spar_py.pictures.cell import cell_figure, draw_figure, extent

    shelf = load_problem(SHELF)
    bare = dataclasses.replace(shelf, obstacles=())
    sc = scenes(shelf, _typed(plan))
    fr = extent(shelf, sc)
    with_it = mpimg.imread(cell_figure(shelf, sc[4], fr, tmp_path / "shelf.png"))
    without = mpimg.imread(cell_figure(bare, sc[4], fr, tmp_path / "bare.png"))
    assert with_it.shape == without.shape
    assert float(np.abs(with_it - without).max()) > 0.2
    fig = draw_figure(bare, sc[4], fr)
    try:
        assert not any(g.startswith("obstacle:") for ax in fig.axes for g in _gids(ax))
        assert any(g.startswith("link:") for ax in fig.axes for g in _gids(ax))
    finally:
        plt.close(fig)
