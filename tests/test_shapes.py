"""Object models from shapes and meshes (issue 14): derived faces, stable poses, grasps and
T_a; hand-written entries checked against the shape; the derivation cache; `spar kb derive`.

The physics of the derived stable poses is checked here with code of its own (a centre of
mass by the divergence theorem, a monotone-chain hull, point-in-polygon), not with
world.parts.poses' support_check or trimesh's centre of mass."""
from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from spar_py.core.errors import KBError
from spar_py.core.geometry import eulerxyz
from spar_py.kb import check_file, load_object, load_problem
from spar_py.world.parts import cache as shapes_cache
from spar_py.world.parts.mesh import part_mesh

from test_problems import PAPER_ACTIONS, PAPER_ORDER, PHASE1, Outcome, phase1
from paths import ROOT, SPAR

OBJ = ROOT / "kb" / "objects"


@pytest.fixture(autouse=True)
def _own_cache(tmp_path_factory: pytest.TempPathFactory, monkeypatch: pytest.MonkeyPatch) -> None:
    """Every test derives into a cache of its own (never the user's)."""
    monkeypatch.setenv("SPAR_CACHE_DIR", str(tmp_path_factory.mktemp("derive-cache")))


def _shape_parts() -> list[Path]:
    """Every kb/objects model that gives a mesh or a shape."""
    out = []
    for p in sorted(OBJ.glob("*.yaml")):
        text = p.read_text(encoding="utf-8")
        if "\nmesh:" in text or "\nshape:" in text:
            out.append(p)
    return out


# ---------------------------------------------------------------------- the paper's cell from shapes


def test_paper_cell_from_shapes_plans_fig23_with_fig24_orderings() -> None:
    o = phase1("peg_in_block_shapes")
    assert o.kind == "plan"
    assert o.actions == PAPER_ACTIONS
    assert o.order == PAPER_ORDER  # the white knight prior_to(action_3, action_2) included


def test_assembled_2_derives_the_papers_ta_and_va() -> None:
    """assembled(peg, block) gives T_a = trans_1 and V_a = vec_1 of peg_in_block.yaml."""
    paper = load_problem(ROOT / "kb" / "problems" / "peg_in_block.yaml")
    shapes = load_problem(ROOT / "kb" / "problems" / "peg_in_block_shapes.yaml")
    assert shapes.goals == paper.goals
    np.testing.assert_allclose(shapes.transforms["trans_1"], paper.transforms["trans_1"], atol=1e-12)
    np.testing.assert_allclose(shapes.vectors["vec_1"], paper.vectors["vec_1"], atol=1e-12)


# the hand-written face names of peg.yaml/block.yaml and the derived names of the same faces
PEG_FACES = {"base_bottom": "nz", "base_top": "pz", "base_xp": "px", "base_xn": "nx", "base_yp": "py",
             "base_yn": "ny", "peg_face": "peg_face"}
BLOCK_FACES = {"b1": "nz", "b2": "px", "block_face": "pz", "b4": "nx", "b5": "py", "b6": "ny"}


@pytest.mark.parametrize("hand, derived, names", [("peg.yaml", "peg_shape.yaml", PEG_FACES),
                                                   ("block.yaml", "block_shape.yaml", BLOCK_FACES)])
def test_derived_poses_and_grasps_contain_the_hand_written(hand: str, derived: str, names: dict) -> None:
    h, d = load_object(OBJ / hand, "in"), load_object(OBJ / derived, "in")
    for p in h.poses.values():
        same = [q for q in d.poses.values() if np.allclose(q.R, p.R, atol=1e-9) and abs(q.height - p.height) < 1e-9]
        assert same, f"{p.label} not derived"
        assert {names[f] for f in p.rfaces} == set(same[0].rfaces)
    for g in h.grasps.values():
        same = [q for q in d.grasps.values() if np.allclose(q.T, g.T, atol=1e-9)]
        assert same, f"{g.label} not derived"
        assert same[0].width == pytest.approx(g.width)
        assert {names[f] for f in g.gfaces} == set(same[0].gfaces)
        # every planar face the hand-written grasp covers is covered (peg.yaml also marks the
        # shaft covered from the diagonal approaches above the base, which keep clear of it)
        assert {names[f] for f in g.ofaces if f != "peg_face"} <= set(same[0].ofaces)


# ---------------------------------------------------------------------- physics, independently


def _com(V: np.ndarray, F: np.ndarray) -> np.ndarray:
    """Centre of mass of a closed triangle mesh of uniform density (signed tetrahedra)."""
    a, b, c = V[F[:, 0]], V[F[:, 1]], V[F[:, 2]]
    vol = np.einsum("ij,ij->i", a, np.cross(b, c)) / 6
    return ((a + b + c) / 4 * vol[:, None]).sum(0) / vol.sum()


def _cross2(a: np.ndarray, b: np.ndarray) -> float:
    return float(a[0] * b[1] - a[1] * b[0])


def _hull(P: np.ndarray) -> np.ndarray:
    """Andrew's monotone chain, counter-clockwise."""
    P = np.unique(np.round(P, 12), axis=0)
    if len(P) < 3:
        return P

    def half(pts: np.ndarray) -> list:
        h: list = []
        for p in pts:
            while len(h) >= 2 and _cross2(h[-1] - h[-2], p - h[-2]) <= 0:
                h.pop()
            h.append(p)
        return h

    lower, upper = half(P), half(P[::-1])
    return np.array(lower[:-1] + upper[:-1])


def _depth_inside(poly: np.ndarray, c: np.ndarray) -> float:
    """How far c lies inside the CCW polygon (negative outside)."""
    a, b = poly, np.roll(poly, -1, axis=0)
    e = b - a
    return float(((e[:, 0] * (c[1] - a[:, 1]) - e[:, 1] * (c[0] - a[:, 0])) / np.linalg.norm(e, axis=1)).min())


def _tilted(R: np.ndarray, axis: np.ndarray, t: float) -> np.ndarray:
    K = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return (np.eye(3) + math.sin(t) * K + (1 - math.cos(t)) * K @ K) @ R


#: A part on a round side rolls with its centre of mass within this fraction of its height of
#: where it was: the polygon of a tessellated round (a 64-gon's lines and flats differ by 0.12 %).
ROLL_REL = 0.01


@pytest.mark.parametrize("path", _shape_parts(), ids=lambda p: p.stem)
def test_every_derived_stable_pose_is_physically_stable(path: Path) -> None:
    """Dropped in each derived pose the part stays: at the pose's height, on a flat patch of its
    own (at least 3 non-collinear lowest points) with its centre of mass over the support
    polygon, every orientation tilted 5 deg off it raising the centre of mass (a local minimum of
    potential energy); or on a line (a round side) with its centre of mass over it, every tilt
    but the roll about that line raising it and the roll leaving it where it was (within
    ROLL_REL: the family's neutral roll) or raising it (a centre of mass off the axis)."""
    m = load_object(path, "in")
    mesh = part_mesh(m)
    V, F = np.asarray(mesh.vertices), np.asarray(mesh.faces)
    com = _com(V, F)
    assert m.poses
    for p in m.poses.values():
        W = V @ p.R.T
        low = W[:, 2].min()
        assert -low == pytest.approx(p.height, abs=1e-6), p.label
        support = W[W[:, 2] < low + 1e-6, :2]
        poly = _hull(support)
        c = (p.R @ com)[:2]
        z0 = (p.R @ com)[2] - low
        roll = None
        if len(poly) >= 3:
            assert _depth_inside(poly, c) > 0, f"{p.label}: centre of mass outside the support polygon"
        else:
            assert len(poly) == 2, f"{p.label} rests on a point"
            u = (poly[1] - poly[0]) / np.linalg.norm(poly[1] - poly[0])
            s = float((c - poly[0]) @ u)
            assert 0 < s < float(np.linalg.norm(poly[1] - poly[0])), f"{p.label}: centre of mass beyond its line"
            assert abs(_cross2(u, c - poly[0])) < 1e-6, f"{p.label}: centre of mass beside its line"
            roll = np.array([u[0], u[1], 0.0])
        for ang in np.radians(np.arange(0, 360, 30)):
            axis = np.array([math.cos(ang), math.sin(ang), 0.0])
            Rt = _tilted(p.R, axis, math.radians(5))
            dz = (Rt @ com)[2] - (V @ Rt.T)[:, 2].min() - z0
            if roll is not None and abs(axis @ roll) > math.cos(math.radians(1)):
                continue  # the roll, below
            assert dz > -1e-9, f"{p.label} tips over about {axis}"
        if roll is not None:
            for t in (-5.0, 5.0):
                Rt = _tilted(p.R, roll, math.radians(t))
                dz = (Rt @ com)[2] - (V @ Rt.T)[:, 2].min() - z0
                assert dz > -ROLL_REL * z0, f"{p.label} rolls off its side by {t:g} deg"


#: Known: a derived grasp of the gearbox's cover (a lid on four corner columns) closes on a
#: column while the lid runs on past the fingers' outer side, which this rule (the part's
#: extent across the finger band equals the width) reads as not touching; not yet judged.
KNOWN_NOT_TOUCHING = {"gearbox_cover"}


@pytest.mark.parametrize("path", [pytest.param(p, marks=pytest.mark.xfail(strict=True, reason="KNOWN_NOT_TOUCHING"))
                                  if p.stem in KNOWN_NOT_TOUCHING else p for p in _shape_parts()],
                         ids=lambda p: p.stem)
def test_derived_grasps_touch_the_part_and_keep_the_fingers_out(path: Path) -> None:
    """For each derived grasp: the part lies between the fingers (some surface point at tool
    x = z = 0 on each side of the tool centre along y), the width fits the 4 in opening, and
    no surface sample lies strictly inside a closed finger."""
    m = load_object(path, "in")
    mesh = part_mesh(m)
    rng = np.random.default_rng(7)
    pts, _ = __import__("trimesh").sample.sample_surface_even(mesh, 4000, seed=rng)
    fw, fl, ft = 20 / 25.4, 60 / 25.4, 10 / 25.4
    for g in m.grasps.values():
        assert g.width <= 4.0 + 1e-9
        T = eulerxyz(*g.euler)
        np.testing.assert_allclose(T, g.T, atol=1e-9)
        q = (pts - T[:3, 3]) @ T[:3, :3]
        eps = 0.02
        for s in (1, -1):
            inside = ((np.abs(q[:, 0]) < fw / 2 - eps) & (q[:, 2] < -eps) & (q[:, 2] > -fl + eps)
                      & (s * q[:, 1] > g.width / 2 + eps) & (s * q[:, 1] < g.width / 2 + ft - eps))
            assert not inside.any(), f"{g.label}: a finger enters the part"
        extent = np.abs(q[(np.abs(q[:, 0]) < fw / 2) & (q[:, 2] > -fl) & (q[:, 2] < 0), 1])
        assert extent.max() == pytest.approx(g.width / 2, abs=0.02), f"{g.label}: the fingers do not touch"


def test_shaft_grasps_are_the_same_from_either_side() -> None:
    """A round shaft is symmetric about its axis: for every grasp across it with the approach
    normal to the axis, the grasp with the opposite approach (the same closing line) is derived
    too. Its contact line then lies on the pads' tip edge, which the sign of a rounding error
    decided before (34 grasps of the paper's peg on one CPU, 36 on another)."""
    m = load_object(OBJ / "peg_shape.yaml", "in")
    d = m.features[0].geometry.direction
    side = [(g.T[:3, 1], g.T[:3, 2]) for g in m.grasps.values()
            if "peg_face" in g.gfaces and abs(g.T[:3, 2] @ d) < 1e-9]
    assert len(side) == 8  # 4 closing lines at 45 deg steps, each from both sides
    for c, a in side:
        assert any(abs(abs(c @ c2) - 1) < 1e-9 and np.allclose(a2, -a, atol=1e-9) for c2, a2 in side), (c, a)


def test_line_contact_on_the_pads_edge_does_not_hang_on_rounding() -> None:
    """A contact line parallel to the pad's tip edge, a rounding error either side of it, has
    the same contact length (world.parts.shafts.line_contact)."""
    from spar_py.world.parts.shafts import line_contact
    from spar_py.world.robot import Gripper

    g = Gripper.default(4.0, 25.4)
    T = np.eye(4)  # pad: tool x within +-finger_width/2, z from -finger_length to 0
    d = np.array([1.0, 0.0, 0.0])
    got = [line_contact(np.array([-0.1, 0.0, w]), d, 0.2, T, g) for w in (-1e-15, 0.0, 1e-15)]
    assert got == pytest.approx([0.2] * 3)
    assert line_contact(np.array([-0.1, 0.0, 1e-3]), d, 0.2, T, g) == 0.0  # off the pad: none


def test_ofaces_name_the_face_the_gripper_comes_from() -> None:
    d = load_object(OBJ / "peg_shape.yaml", "in")
    approach_x = next(g for g in d.grasps.values() if np.allclose(g.T[:3, 2], [1, 0, 0]) and g.gfaces == ("py", "ny"))
    assert approach_x.ofaces == ("py", "ny", "nx")  # the palm is on the -x side


def test_hole_down_hides_the_hole() -> None:
    d = load_object(OBJ / "block_shape.yaml", "in")
    down = next(p for p in d.poses.values() if p.rfaces == ("pz",))
    assert "block_face" in down.ofaces
    up = next(p for p in d.poses.values() if p.rfaces == ("nz",))
    assert "block_face" not in up.ofaces


def test_mesh_part_faces_poses_and_units() -> None:
    mm = load_object(OBJ / "hex_shaft.yaml", "mm")
    inch = load_object(OBJ / "hex_shaft.yaml", "in")
    assert "shaft" in mm.faces and "nz" in mm.faces
    assert mm.features[0].radius == pytest.approx(12) and inch.features[0].radius == pytest.approx(12 / 25.4)
    assert [p.label for p in mm.poses.values()] == [p.label for p in inch.poses.values()]
    for a, b in zip(mm.poses.values(), inch.poses.values()):
        assert a.height == pytest.approx(b.height * 25.4)
    # the flange is gripped across its flats, never the hexagon as a cylinder
    assert all(set(g.gfaces) <= {"px", "nx", "py", "ny"} for g in mm.grasps.values())


def test_meshes_only_cell_plans_with_no_hand_written_entry() -> None:
    """The shaft stands on its flange, and the grasps are across the flange's flats: with the
    fingers checked against the table (issue 15) none of them reaches the standing shaft in a
    way that also fits the side hole, so the shaft is laid down and grasped again."""
    o = phase1("shaft_in_bracket")
    assert o.kind == "plan"
    assert o.actions == ["pickup(hex_shaft,grasp_2)", "putdown(hex_shaft,pos_1)",
                         "pickup(hex_shaft,grasp_1)",
                         "assemble(hex_shaft,bracket,[[shaft],[socket]],trans_1,vec_1)"]
    text = (ROOT / "kb" / "problems" / "shaft_in_bracket.yaml").read_text()
    assert "transforms:" not in text and "vectors:" not in text
    for f in ("hex_shaft.yaml", "bracket.yaml"):
        t = (OBJ / f).read_text()
        assert "mesh:" in t and not any(f"\n{k}:" in t for k in ("faces", "stable_poses", "grasps"))


# ---------------------------------------------------------------------- the turns of T_a


def _rot(axis: np.ndarray, angle: float) -> np.ndarray:
    """Rodrigues: the rotation by ``angle`` (rad) about unit ``axis`` (written here, not imported)."""
    x, y, z = axis / np.linalg.norm(axis)
    K = np.array([[0, -z, y], [z, 0, -x], [-y, x, 0]])
    return np.eye(3) + math.sin(angle) * K + (1 - math.cos(angle)) * K @ K


def _box_corners(lo: list[float], hi: list[float]) -> np.ndarray:
    return np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])], float)


# tab_peg.yaml's solid, from its numbers (mm): flange, tab, and the shaft's two end circles
TAB_PEG_POINTS = np.vstack([
    _box_corners([-25, -25, 0], [25, 25, 20]), _box_corners([25, -8, 0], [80, 8, 20]),
    *[np.column_stack([12 * np.cos(a), 12 * np.sin(a), np.full_like(a, z)])
      for z in (20.0, 60.0) for a in [np.radians(np.arange(0, 360, 5.0))]]])


def _phase1_cell(cell: object, max_actions: int = 6) -> Outcome:
    from spar_py.planning.engine import engine

    e = engine()
    e.load_cell(cell)
    try:
        a = e.query_once(PHASE1, {"Name": cell.name, "Max": max_actions})  # type: ignore[attr-defined]
    finally:
        e.unload(cell.name)  # type: ignore[attr-defined]
    assert a["truth"], a
    return Outcome(a["Kind"], list(a["Actions"]), list(a["Order"]), {}, int(a["Bound"]), str(a["Unmet"]))


def test_assembled_2_gives_every_turn_about_the_holes_axis() -> None:
    """Eight turns 45 deg apart; each seats the peg (its axis on the hole's, its tip at the
    hole's bottom) and is the first turned about the hole's axis."""
    cell = load_problem(ROOT / "kb" / "problems" / "tab_peg_sideways.yaml")
    names = [t for t, _ in cell.turns["trans_1"]]
    assert names == ["trans_1"] + [f"trans_1_t{j}" for j in range(2, 9)]
    T1 = cell.transforms["trans_1"]
    for j, name in enumerate(names):
        T = cell.transforms[name]
        np.testing.assert_allclose(T[:3, :3] @ [0, 0, 1], [0, 0, -1], atol=1e-12)  # peg axis into the hole
        np.testing.assert_allclose(T[:3, :3] @ [0, 0, 60] + T[:3, 3], [0, 0, 20], atol=1e-9)  # tip at the bottom
        np.testing.assert_allclose(T[:3, :3], _rot(np.array([0, 0, -1.0]), j * math.pi / 4) @ T1[:3, :3],
                                   atol=1e-12)


@pytest.mark.parametrize("steps, n", [((90, 90), 4), ((90, None), 8), ((120, 90), 4)])
def test_grasp_step_sets_the_quantum_of_turns(tmp_path: Path, steps: tuple, n: int) -> None:
    """The turns are quantised by the finer grasp_step of the two models (45 deg if unsaid)."""
    cell_src = (ROOT / "kb" / "problems" / "tab_peg_sideways.yaml").read_text().replace(
        "../robots/", f"{ROOT}/kb/robots/")
    for f, step in zip(("tab_peg", "socket_block"), steps):
        src = (OBJ / f"{f}.yaml").read_text()
        (tmp_path / f"{f}.yaml").write_text(src + (f"grasp_step: {step}\n" if step else ""))
        cell_src = cell_src.replace(f"../objects/{f}.yaml", str(tmp_path / f"{f}.yaml"))
    p = tmp_path / "cell.yaml"
    p.write_text(cell_src)
    assert [t for t, _ in load_problem(p).turns["trans_1"]] == ["trans_1"] + [f"trans_1_t{j}" for j in range(2, n + 1)]


def test_the_planner_chooses_a_turn_that_keeps_the_tab_out_of_the_table() -> None:
    """tab_peg_sideways: in the first turn (and 45 deg either side of it) the tab would go
    into the table; the planner backtracks over the turns and assembles with one in which
    every point of the peg is above the table (checked here from the model's own numbers)."""
    cell = load_problem(ROOT / "kb" / "problems" / "tab_peg_sideways.yaml")
    o = _phase1_cell(cell)
    assert o.kind == "plan"
    assert len(o.actions) == 2 and o.actions[0] == "pickup(tab_peg,grasp_1)"
    turn = o.actions[1].split(",")[-2]
    assert o.actions[1] == f"assemble(tab_peg,socket_block,[[shaft],[socket]],{turn},vec_1)"
    assert turn != "trans_1"
    T_block = cell.positions["tr2"].T

    def lowest(name: str) -> float:
        T = T_block @ cell.transforms[name]
        return float((TAB_PEG_POINTS @ T[:3, :3].T + T[:3, 3])[:, 2].min())

    assert lowest(turn) > -1e-6
    assert lowest("trans_1") < -10  # the tab's end 30 mm under the table top
    assert lowest("trans_1_t2") < 0 and lowest("trans_1_t8") < 0


def test_with_the_first_turn_alone_the_block_must_be_turned_over() -> None:
    """The counterfactual: the same cell offering only the first turn needs the block picked
    up and put down in a pose where that turn clears the table: four actions, not two."""
    cell = load_problem(ROOT / "kb" / "problems" / "tab_peg_sideways.yaml")
    cell.turns["trans_1"] = cell.turns["trans_1"][:1]
    o = _phase1_cell(cell)
    assert o.kind == "plan"
    assert o.actions == ["pickup(socket_block,grasp_2)", "putdown(socket_block,pos_1)", "pickup(tab_peg,grasp_1)",
                         "assemble(tab_peg,socket_block,[[shaft],[socket]],trans_1,vec_1)"]


# ---------------------------------------------------------------------- checks of hand-written entries


def _model(tmp: Path, body: str) -> Path:
    p = tmp / "part.yaml"
    p.write_text("object: part\nunits: {length: in, angle: deg}\n"
                 "shape:\n  - {box: {min: [-1, -1, 0], max: [1, 1, 1]}}\n" + body)
    return p


GRASP = "grasps:\n  - {label: g1, gfaces: [py, ny], ofaces: [py, ny], eulerxyz: [0, 0, 0.5, 0, 90, 0], width: 2}\n"
POSE = "stable_poses:\n  - {label: s1, rfaces: [nz], ofaces: [nz], tm: [[1, 0, 0], [0, 1, 0], [0, 0, 1], [0, 0, 0]]}\n"


def test_check_accepts_entries_that_agree_with_the_shape(tmp_path: Path) -> None:
    assert ": ok" in check_file(_model(tmp_path, POSE + GRASP))


def test_check_names_an_unstable_pose(tmp_path: Path) -> None:
    tilted = POSE.replace("[[1, 0, 0], [0, 1, 0], [0, 0, 1], [0, 0, 0]]",
                          "[[1, 0, 0], [0, 0.8, 0.6], [0, -0.6, 0.8], [0, 0, 0]]")
    with pytest.raises(KBError, match=r"stable_poses\[0\]: expected a stable pose of the shape, not s1: it rests on"):
        check_file(_model(tmp_path, tilted + GRASP))


def test_check_names_a_pose_that_tips_over_on_a_small_tilt(tmp_path: Path) -> None:
    """tab_peg upside down on its shaft's tip: its centre of mass is over the tip (1.2 mm inside
    its edge) but 44 mm above it, so a 1.6 deg tilt topples it."""
    src = (OBJ / "tab_peg.yaml").read_text()
    p = tmp_path / "tab_peg.yaml"
    p.write_text(src + "stable_poses:\n  - {label: tip, rfaces: [shaft], ofaces: [shaft], "
                 "tm: [[1, 0, 0], [0, -1, 0], [0, 0, -1], [0, 0, 60]]}\n")
    with pytest.raises(KBError, match=r"stable_poses\[0\]: expected a stable pose of the shape, not tip: it tips "
                                      r"over on a tilt of 1\.59 deg"):
        check_file(p)


def test_check_names_a_pose_at_the_wrong_height(tmp_path: Path) -> None:
    with pytest.raises(KBError, match=r"stable_poses\[0\]\.tm: expected the height"):
        check_file(_model(tmp_path, POSE.replace("[0, 0, 0]]}", "[0, 0, 0.5]]}") + GRASP))


def test_check_names_a_grasp_whose_finger_enters_the_part(tmp_path: Path) -> None:
    narrow = GRASP.replace("width: 2", "width: 1.5")
    with pytest.raises(KBError, match=r"grasps\[0\]: expected a grasp the gripper can make, not g1: a finger enters"):
        check_file(_model(tmp_path, POSE + narrow))


def test_check_names_a_grasp_wider_than_the_opening(tmp_path: Path) -> None:
    with pytest.raises(KBError, match=r"grasps\[0\]: .*more than the gripper's opening 4 in"):
        check_file(_model(tmp_path, POSE + GRASP.replace("width: 2", "width: 4.5")))


def test_check_names_a_face_not_on_the_shape(tmp_path: Path) -> None:
    body = "faces: [py, ny, nz, top]\n" + POSE + GRASP
    with pytest.raises(KBError, match=r"faces\[3\]: expected a face of the shape .*, not 'top'"):
        check_file(_model(tmp_path, body))


def test_face_names_take_precedence_and_must_be_on_the_shape(tmp_path: Path) -> None:
    m = load_object(_model(tmp_path, "face_names: {top: [0, 0, 1]}\n"), "in")
    assert "top" in m.faces and "pz" not in m.faces
    with pytest.raises(KBError, match=r"face_names\.top: expected a point on a face of the shape"):
        load_object(_model(tmp_path, "face_names: {top: [0, 0, 3]}\n"), "in")


def test_subtract_makes_a_hole_and_its_wall_a_face(tmp_path: Path) -> None:
    body = ("  - {cylinder: {radius: 0.5, z: [0.5, 1], subtract: true}}\n"
            "feature: {kind: hole, name: bore, radius: 0.5, axis: {origin: [0, 0, 1], direction: [0, 0, -1]}, "
            "length: 0.5}\n")
    m = load_object(_model(tmp_path, body), "in")
    assert part_mesh(m).volume == pytest.approx(4 - math.pi * 0.25 * 0.5, rel=2e-3)
    assert "bore" in m.faces
    np.testing.assert_allclose(m.features[0].vector, [0, 0, 0.5])


def test_assembled_2_needs_geometric_features(tmp_path: Path) -> None:
    src = (ROOT / "kb" / "problems" / "peg_in_block.yaml").read_text()
    p = tmp_path / "cell.yaml"
    p.write_text(src.replace("../", f"{ROOT}/kb/").replace(
        "assembled(peg, block, [[peg_face], [block_face]], trans_1, vec_1)", "assembled(peg, block)"))
    with pytest.raises(KBError, match=r"goals\[0\]: expected peg with a peg feature declared by geometry"):
        load_problem(p)


def test_mesh_errors_are_one_line(tmp_path: Path) -> None:
    (tmp_path / "open.stl").write_text("solid x\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 1 0 0\n"
                                       "vertex 0 1 0\nendloop\nendfacet\nendsolid x\n")
    p = tmp_path / "m.yaml"
    p.write_text("object: m\nunits: {length: mm, angle: deg}\nmesh: open.stl\n")
    with pytest.raises(KBError, match=r"m\.yaml: mesh: expected a closed \(watertight\) mesh: 3 edges stay open, "
                                      r"around \[0\.5, 0\.5, 0\] \(from \[0, 0, 0\] to \[1, 1, 0\], [^\n]*\)[^\n]*$"):
        load_object(p, "mm")
    p.write_text("object: m\nunits: {length: mm, angle: deg}\nmesh: none.stl\n")
    with pytest.raises(KBError, match=r"mesh: expected the path of a mesh file, not 'none.stl' \(no such file\)"):
        load_object(p, "mm")


def test_rotation_message_says_the_tolerance(tmp_path: Path) -> None:
    pose = ("stable_poses:\n  - {label: s1, rfaces: [nz], ofaces: [nz], "
            "tm: [[0.7071, 0.7071, 0], [-0.7071, 0.7071, 0], [0, 0, 1], [0, 0, 0]]}\n")
    with pytest.raises(KBError, match=r"stable_poses\[0\]\.tm: expected an orthonormal .*orthonormal to 1e-06, .*"
                                      r"off I by 1\.92e-05; write exact values or more digits, e\.g\. "
                                      r"0\.70710678118655 for sqrt\(1/2\)"):
        load_object(_model(tmp_path, pose + GRASP), "in")


# ---------------------------------------------------------------------- cache and `spar kb derive`


def test_derivation_is_cached_by_content(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    p = _model(tmp_path, "")
    first = load_object(p, "in")
    files = list(shapes_cache.cache_dir().glob("*.json"))
    assert len(files) == 1

    def boom(*a: object, **k: object) -> None:
        raise AssertionError("derived twice")

    monkeypatch.setattr(shapes_cache, "_compute", boom)
    again = load_object(p, "in")
    assert list(again.grasps) == list(first.grasps)
    p.write_text(p.read_text().replace("max: [1, 1, 1]", "max: [1, 1, 1.5]"))  # new content: derived again
    with pytest.raises(KBError, match="derived twice"):  # any failure of a derivation is a KBError
        load_object(p, "in")


def test_cache_is_bounded(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(shapes_cache, "MAX_ENTRIES", 2)
    for h in (1, 1.25, 1.5, 1.75):
        p = tmp_path / f"p{h}.yaml"
        p.write_text(f"object: part\nunits: {{length: in, angle: deg}}\nshape:\n  - {{box: {{min: [-1, -1, 0], "
                     f"max: [1, 1, {h}]}}}}\n")
        load_object(p, "in")
    assert len(list(shapes_cache.cache_dir().glob("*.json"))) == 2


def test_a_corrupt_cache_entry_is_derived_again(tmp_path: Path) -> None:
    p = _model(tmp_path, "")
    load_object(p, "in")
    (f,) = shapes_cache.cache_dir().glob("*.json")
    f.write_text("{not json")
    assert load_object(p, "in").grasps
    assert json.loads(f.read_text())["grasps"]


def test_kb_derive_writes_a_model_that_loads_to_the_same(tmp_path: Path) -> None:
    out = tmp_path / "hex_full.yaml"
    r = subprocess.run([*SPAR, "kb", "derive", str(OBJ / "hex_shaft.yaml"), "-o", str(out)], capture_output=True,
                       text=True, cwd=ROOT)
    assert r.returncode == 0, r.stderr
    a, b = load_object(OBJ / "hex_shaft.yaml", "mm"), load_object(out, "mm")
    assert a.faces == b.faces and list(a.poses) == list(b.poses) and list(a.grasps) == list(b.grasps)
    for g in a.grasps:
        np.testing.assert_allclose(a.grasps[g].T, b.grasps[g].T, atol=1e-8)
    for p in a.poses:
        np.testing.assert_allclose(a.poses[p].R, b.poses[p].R, atol=1e-8)
    assert ": ok" in check_file(out)  # and every entry agrees with the mesh


def test_kb_derive_bad_input_is_one_line(tmp_path: Path) -> None:
    p = tmp_path / "m.yaml"
    p.write_text("object: m\nunits: {length: mm, angle: deg}\n")
    r = subprocess.run([*SPAR, "kb", "derive", str(p)], capture_output=True, text=True, cwd=ROOT)
    assert r.returncode == 2
    assert r.stderr.count("\n") == 1 and "faces: expected a value (key missing)" in r.stderr


def test_planning_does_not_import_the_geometry_libraries_it_does_not_need(tmp_path: Path) -> None:
    """The paper's cell (hand-written models) never imports trimesh; a mesh cell whose
    derivations are cached does not either."""
    code = ("import sys\nfrom spar_py.kb import load_problem\nload_problem(sys.argv[1])\n"
            "print(sorted(m for m in ('trimesh', 'scipy', 'networkx', 'manifold3d') if m in sys.modules))\n")
    env = {**__import__("os").environ, "SPAR_CACHE_DIR": str(tmp_path)}
    run = [sys.executable, "-c", code]
    paper = subprocess.run([*run, str(ROOT / "kb/problems/peg_in_block.yaml")], capture_output=True, text=True,
                           env=env)
    assert paper.stdout.strip() == "[]", paper.stderr
    mesh_cell = str(ROOT / "kb/problems/shaft_in_bracket.yaml")
    first = subprocess.run([*run, mesh_cell], capture_output=True, text=True, env=env)
    assert "trimesh" in first.stdout, first.stderr
    again = subprocess.run([*run, mesh_cell], capture_output=True, text=True, env=env)
    assert again.stdout.strip() == "[]", again.stderr


def test_bench_derive_renders() -> None:
    from bench import derive

    r = {"repeats": 1, "rows": [
        {"model": "peg (paper, shape)", "triangles": 270, "faces": 7, "poses": 6, "grasps": 36,
         "derive_ms": 80.0, "cached_ms": 1.0, "hand_ms": 5.0},
        {"model": "10k-triangle part (mesh)", "triangles": 9998, "faces": 7, "poses": 6, "grasps": 36,
         "derive_ms": 1500.0, "cached_ms": 5.0, "hand_ms": None}]}
    text = "\n".join(derive.markdown(r))
    assert "| peg (paper, shape) | 270 |" in text and "16x" in text
    assert "80 ms at worst (met)" in text and "1500 ms (9998 triangles) (NOT met)" in text


# ---------------------------------------------------------------------- the robot's own fingers


def test_grasps_are_derived_for_the_robots_own_fingers() -> None:
    """The robot file's finger and palm boxes (not the default jaw) decide which grasps exist:
    the paper's peg's shaft is 1.5 in long above a 3 in base, so fingers 200 mm wide (along the
    shaft) meet the base in every grasp of the shaft across its axis; the default 20 mm fingers
    fit. The default-sized robot gripper derives exactly the default grasps."""
    from spar_py.world.robot import Gripper

    default = load_object(OBJ / "peg_shape.yaml", "in", opening=4.0)
    same = load_object(OBJ / "peg_shape.yaml", "in", gripper=Gripper.default(4.0, 25.4))
    wide = Gripper.default(4.0, 25.4, finger={"length": 60 / 25.4, "width": 200 / 25.4,
                                                       "thickness": 10 / 25.4})
    got = load_object(OBJ / "peg_shape.yaml", "in", gripper=wide)

    def shaft_grasps(m) -> set:
        return {k for k, g in m.grasps.items() if "peg_face" in g.gfaces}

    assert {k: g.T.tolist() for k, g in same.grasps.items()} == {k: g.T.tolist() for k, g in default.grasps.items()}
    assert shaft_grasps(got) < shaft_grasps(default)
    assert all(abs(abs(got.grasps[k].T[2, 2]) - 1) < 1e-9 for k in shaft_grasps(got))  # approach along z
    assert any(abs(default.grasps[k].T[2, 2]) < 1e-9 for k in shaft_grasps(default))  # side grasps there
    assert 0 < len(got.grasps) < len(default.grasps)
