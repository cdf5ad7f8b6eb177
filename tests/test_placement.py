"""Put-down placements: feasible ones check out by forward kinematics; unreachable regions give none."""
from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np

from spar_py import placement
from spar_py.kb import load_problem

CELL = load_problem(Path(__file__).resolve().parent.parent / "kb/problems/peg_in_block.yaml")


def _occupied() -> list[tuple[np.ndarray, float]]:
    return [(CELL.positions["tr1"].T[:2, 3], CELL.objects["peg"].bounding_radius())]


def test_chosen_placement_is_reachable_by_fk() -> None:
    blk, peg = CELL.objects["block"], CELL.objects["peg"]
    # (p2G9 with p1G11, the pair this test used before the collision check, has no placement
    # now: p1G11's wrist then passes 0.14 in through the table)
    reqs = [blk.grasps["p2G1"].T, CELL.transforms["trans_1"] @ peg.grasps["p1G10"].T]
    p = placement.choose(CELL, "block", "p2P5", reqs, _occupied())
    assert p is not None
    assert p.z == blk.poses["p2P5"].height
    for X in reqs:
        T = p.T @ X
        sols = CELL.robot.ik(T)
        assert len(sols) > 0
        for q in sols:
            assert np.allclose(CELL.robot.fk(q), T, atol=1e-9)
    # clear of the peg's bounding circle
    c, r = _occupied()[0]
    assert np.hypot(p.x - c[0], p.y - c[1]) >= r + blk.bounding_radius()


def test_region_out_of_reach_gives_no_placement() -> None:
    far = replace(CELL, placement_regions=[{"x": (200.0, 210.0), "y": (0.0, 10.0)}])
    reqs = [CELL.objects["block"].grasps["p2G9"].T]
    assert placement.choose(far, "block", "p2P1", reqs, []) is None


def test_feasible_matches_single_ik_queries() -> None:
    blk = CELL.objects["block"]
    cands = placement.candidates(CELL, "block", "p2P1", _occupied())[:200]
    X = blk.grasps["p2G3"].T
    ok = placement.feasible(CELL, cands, [X])
    for c, f in zip(cands[:60], ok[:60]):
        T = c.T @ X
        single = len(CELL.robot.ik(T)) > 0
        flange_up = (T @ np.linalg.inv(CELL.robot.tool))[2, 3] > 0
        assert f == (single and flange_up)
