"""world/reach/arcs.py: the CMS's reachable / mate_reachable pairs (Sec. 5.2.4) on a small hand-built cell."""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from spar_py.core.errors import SparValueError
from spar_py.core.geometry import eulerxyz, rot, rotx, rotz, trans
from spar_py.kb import load_problem, load_robot
from spar_py.core.model import Bounds, Cell, Grasp, ObjectModel, Position, StablePose, natural_key
from spar_py.world.collision import CellCache
from spar_py.world.run import WorldRun
from spar_py.world.reach.arcs import (
    arc,
    mate_reachable_pairs,
    reachable_pairs,
    resting_faces,
    solutions_for,
)

from paths import ROOT

PUMA = ROOT / "kb" / "robots" / "puma762.yaml"
FACES = ("top", "bottom", "xp", "xn", "yp", "yn")
GRASPS = ["g1", "g2", "g10"]


def grasp(label: str, gfaces: tuple[str, ...], phi: float, theta: float, psi: float) -> Grasp:
    e = (0.0, 0.0, 0.0, phi, theta, psi)
    return Grasp(label, gfaces, gfaces, e, 2.0, eulerxyz(*e))


def box(name: str) -> ObjectModel:
    """A 2 in cube, frame at its centre, resting upright (on bottom) or upside down (on top)."""
    poses = {
        f"{name}_up": StablePose(f"{name}_up", ("bottom",), ("bottom",), np.eye(3), 1.0),
        f"{name}_down": StablePose(f"{name}_down", ("top",), ("top",), rot(rotx(math.pi)), 1.0),
    }
    grasps = {
        # from above (tool z = object -z), fingers along the object's y: on yp / yn
        "g1": grasp("g1", ("yp", "yn"), 0.0, math.pi, 0.0),
        # from the -x side (tool z = object +x), fingers along the object's z: on top / bottom
        "g2": grasp("g2", ("top", "bottom"), 0.0, math.pi / 2, math.pi / 2),
        # from above, fingers along the object's x: on xp / xn
        "g10": grasp("g10", ("xp", "xn"), 0.0, math.pi, math.pi / 2),
    }
    return ObjectModel(name, FACES, poses, grasps)


def at(x: float, y: float, z: float, R: np.ndarray | None = None) -> np.ndarray:
    T = trans(x, y, z)
    if R is not None:
        T[:3, :3] = rot(R)
    return T


@pytest.fixture(scope="module")
def cell() -> Cell:
    robot = load_robot(PUMA, unit="in")
    positions = {
        "tr1": Position("init_pos1", "tr1", "box", at(30, 0, 1, rotz(-math.pi / 2))),  # upright, turned
        "tr_far": Position("far_pos", "tr_far", "box", at(118, 0, 1)),  # 3 m out
        "tr_yaw": Position("yaw_pos", "tr_yaw", "box", at(25, 10, 1, rotz(math.radians(30)))),
        "tr_down": Position("down_pos", "tr_down", "box", at(30, 0, 1, rotx(math.pi))),
        "tr_tilt": Position("tilt_pos", "tr_tilt", "box", at(30, 0, 1, rotx(math.radians(45)))),
        "trp": Position("plate_pos", "trp", "plate", at(30, 0, 1)),
        "trp_far": Position("plate_far", "trp_far", "plate", at(118, 0, 1)),
    }
    b = Bounds((-0.1, 0.1), (-0.1, 0.1), (-0.1, 0.1), (-0.01, 0.01))
    return Cell(
        name="test_cell", file="(test)", unit="in", robot=robot, finger_separation=robot.finger_separation,
        objects={"box": box("box"), "plate": box("plate")}, positions=positions,
        transforms={"on_top": trans(0, 0, 2)}, vectors={}, initial=[], goals=[],
        manipulator_bounds=b, object_bounds={"box": b, "plate": b}, sensors={},
    )


def test_grasp_fixtures_touch_the_faces_they_claim() -> None:
    g = box("box").grasps
    # fingers close along tool y: g1 along object y, g2 along object z, g10 along object x
    assert np.allclose(abs(g["g1"].T[:3, 1]), [0, 1, 0])
    assert np.allclose(abs(g["g2"].T[:3, 1]), [0, 0, 1])
    assert np.allclose(abs(g["g10"].T[:3, 1]), [1, 0, 0])
    assert np.allclose(g["g2"].T[:3, 2], [1, 0, 0])


def test_front_pose_is_reachable_by_hand(cell: Cell) -> None:
    # The box upright at (30, 0, 1) in, gripped from above (g1): tool centre at (30, 0, 1) in, tool z down,
    # so the wrist centre is 250 mm = 9.84 in higher: (762, 0, 275) mm in the world, (762, 0, -325)
    # mm in frame 0 (600 mm up). Its distance from the shoulder axis, sqrt(762^2 - d3^2 + 325^2)
    # = sqrt(580644 - 36100 + 105625) = 806 mm, lies inside [d4 - a2, a2 + d4] = [-50, 1250] mm,
    # and 762 mm > d3 = 190 mm: the arm reaches it; the IK must find it within the limits.
    T = cell.positions["tr1"].T @ cell.objects["box"].grasps["g1"].T
    assert np.allclose(T[:3, 3], [30, 0, 1]) and np.allclose(T[:3, 2], [0, 0, -1])
    assert reachable_pairs(CellCache(cell), "box", ["g1"], ["tr1"]).pairs == [["g1", "tr1"]]
    sols = solutions_for(cell, T)
    assert sols and all(len(s) == 6 and all(isinstance(v, float) for v in s) for s in sols)
    for s in sols:  # degrees, for display
        assert np.allclose(cell.robot.fk(np.radians(s)), T, atol=1e-9)


def test_three_metres_away_is_not_reachable(cell: Cell) -> None:
    assert reachable_pairs(CellCache(cell), "box", GRASPS, ["tr_far"]).pairs == []
    assert solutions_for(cell, cell.positions["tr_far"].T @ cell.objects["box"].grasps["g1"].T) == []


def test_gfaces_on_the_resting_face_never_reachable(cell: Cell) -> None:
    # g2 holds the box by its top and bottom faces, approaching along the box's +x, which tr1 turns
    # to the world's -y (a sideways approach); the arm can reach that tool pose at tr1 ...
    T = cell.positions["tr1"].T @ cell.objects["box"].grasps["g2"].T
    assert np.allclose(T[:3, 2], [0, -1, 0])
    assert len(cell.robot.ik(T)) > 0
    # ... but the box rests on its bottom (tr1, box_up) or top (tr_down, box_down): condition 1 fails
    labels = ["tr1", "tr_down", "tr_yaw", "box_up", "box_down"]
    pairs = reachable_pairs(CellCache(cell), "box", GRASPS, labels).pairs
    assert not [p for p in pairs if p[0] == "g2"]
    # stable-pose labels under the paper's rule: condition 1 only, so every other grasp passes
    paper = reachable_pairs(CellCache(cell), "box", GRASPS, labels, rule="paper").pairs
    assert ["g1", "box_up"] in paper and ["g10", "box_down"] in paper
    # our rule asks for a placement the arm reaches: a subset of the paper's pairs
    assert set(map(tuple, pairs)) <= set(map(tuple, paper)) and ["g1", "box_up"] in pairs


def test_absolute_positions_are_classified_into_stable_poses(cell: Cell) -> None:
    assert resting_faces(cell, "box", "tr1") == ("bottom",)
    assert resting_faces(cell, "box", "tr_yaw") == ("bottom",)  # turned about world z only
    assert resting_faces(cell, "box", "tr_down") == ("top",)
    assert resting_faces(cell, "box", "box_down") == ("top",)
    with pytest.raises(SparValueError, match="tr_tilt"):
        reachable_pairs(CellCache(cell), "box", GRASPS, ["tr_tilt"]).pairs


def test_pairs_are_sorted_string_lists(cell: Cell) -> None:
    pairs = reachable_pairs(CellCache(cell), "box", ["g10", "g1", "g1"], ["box_up", "tr1"]).pairs
    assert pairs == [["g1", "box_up"], ["g1", "tr1"], ["g10", "box_up"], ["g10", "tr1"]]
    assert all(isinstance(x, str) for p in pairs for x in p)
    assert sorted(["p1G10", "p1G2", "p1G1"], key=natural_key) == ["p1G1", "p1G2", "p1G10"]


def test_all_pairs_in_one_batched_ik_call(cell: Cell, monkeypatch: pytest.MonkeyPatch) -> None:
    calls: list[int] = []
    real = cell.robot.ik_batch

    def counting(T: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        calls.append(len(T))
        return real(T)

    cache = CellCache(cell)
    reachable_pairs(cache, "box", GRASPS, ["box_up"])  # the stable pose's placement search, kept
    monkeypatch.setattr(cell.robot, "ik_batch", counting)
    reachable_pairs(cache, "box", GRASPS, ["tr1", "tr_far", "tr_yaw", "box_up"])
    # g2 fails condition 1 at every one of the three absolute positions: 2 grasps x 3 positions
    assert calls == [6]


def test_mate_reachable(cell: Cell) -> None:
    # a stable-pose label of the fixed object under the paper's rule: condition 2 is assumed
    # satisfiable, all pairs pass; ours keeps those some placement of the plate lets the arm reach
    pairs = mate_reachable_pairs(CellCache(cell), "box", "plate", GRASPS, ["plate_up", "plate_down"],
                                 cell.transforms["on_top"], rule="paper").pairs
    assert len(pairs) == 6
    ours = mate_reachable_pairs(CellCache(cell), "box", "plate", GRASPS, ["plate_up", "plate_down"],
                                cell.transforms["on_top"]).pairs
    assert 0 < len(ours) < 6 and set(map(tuple, ours)) <= set(map(tuple, pairs))
    # absolute: T = T_O T_a T_g; the box on the plate at (30, 0, 3) in is reachable from above,
    # and condition 1 does not apply (g2's faces are not checked)
    pairs = mate_reachable_pairs(CellCache(cell), "box", "plate", GRASPS, ["trp", "trp_far"], "on_top").pairs
    assert ["g1", "trp"] in pairs and ["g10", "trp"] in pairs
    assert not [p for p in pairs if p[1] == "trp_far"]
    T = cell.positions["trp"].T @ cell.transforms["on_top"] @ cell.objects["box"].grasps["g1"].T
    assert np.allclose(T[:3, 3], [30, 0, 3])
    with pytest.raises(SparValueError, match="holds box"):
        mate_reachable_pairs(CellCache(cell), "box", "plate", GRASPS, ["tr1"], "on_top").pairs


def test_arc_dispatch_and_errors(cell: Cell) -> None:
    assert arc(CellCache(cell), "reachable", ["box"], GRASPS, ["tr1"]).pairs == \
        reachable_pairs(CellCache(cell), "box", GRASPS, ["tr1"]).pairs
    assert arc(CellCache(cell), "mate_reachable", ["box", "plate"], GRASPS, ["trp"], "on_top").pairs == \
        mate_reachable_pairs(CellCache(cell), "box", "plate", GRASPS, ["trp"], "on_top").pairs
    with pytest.raises(SparValueError, match="unknown geometric constraint"):
        arc(CellCache(cell), "near", ["box"], GRASPS, ["tr1"]).pairs
    with pytest.raises(SparValueError, match="not a grasp"):
        reachable_pairs(CellCache(cell), "box", ["g7"], ["tr1"]).pairs
    with pytest.raises(SparValueError, match="neither a stable pose"):
        reachable_pairs(CellCache(cell), "box", GRASPS, ["nowhere"]).pairs
    with pytest.raises(SparValueError, match="unknown object"):
        reachable_pairs(CellCache(cell), "ball", GRASPS, ["tr1"]).pairs
    assert reachable_pairs(CellCache(cell), "box", [], ["tr1"]).pairs == []


def test_paper_cell_pairs_are_sound() -> None:
    # Sec. 6's cell: every returned absolute pair has a verified joint solution, every
    # omitted one fails condition 1, has none, or every one collides and the refusal names
    # the pair of bodies (the CMS is exact on its own model)
    cell = load_problem(ROOT / "kb" / "problems" / "peg_in_block.yaml")
    run = WorldRun(CellCache(cell))
    for obj, pos in (("peg", "tr1"), ("block", "tr2")):
        model = cell.objects[obj]
        pairs = run.arc_pairs("reachable", [obj], list(model.grasps), [pos])
        assert pairs, f"no grasp of the {obj} is reachable at {pos}"
        rfaces = set(resting_faces(cell, obj, pos))
        said = [r.text() for r in run.log.refusals()]
        for g in model.grasps.values():
            T = cell.positions[pos].T @ g.T
            expected = not (rfaces & set(g.gfaces)) and len(cell.robot.ik(T)) > 0
            refused = any(r.startswith(f"no collision-free IK for pickup({obj}, {g.label}) at {pos}: ") for r in said)
            assert ([g.label, pos] in pairs) == (expected and not refused)
            if expected and not refused:
                sol = np.radians(solutions_for(cell, T)[0])
                assert np.allclose(cell.robot.fk(sol), T, atol=1e-9)


def test_wrist_under_the_table_is_not_reachable() -> None:
    """A tool pose pointing up from under the table top fails condition 2, whatever IK says."""
    from spar_py.core.geometry import roty, trans
    from spar_py.kb import load_problem
    from spar_py.world.reach.workspace import wrist_above_table

    cell = load_problem(Path(__file__).resolve().parent.parent / "kb/problems/peg_in_block.yaml")
    down = trans(30, 0, 1.0) @ roty(np.pi)   # tool z pointing down: flange above
    up = trans(30, 0, 1.0)                   # tool z pointing up: flange ~9.8 in under the top
    assert wrist_above_table(cell.robot, np.stack([down, up])).tolist() == [True, False]
