"""The shortcuts taken for speed (issue 7) give the answers of the plain computations they replace."""
from __future__ import annotations

import numpy as np

from spar_py.world.reach import placement as placement
from spar_py.kb import load_problem
from spar_py.world.collision import CellCache

from paths import ROOT

CELL = load_problem(ROOT / "kb/problems/peg_in_block.yaml")


def test_reachable_mask_is_any_ik_candidate() -> None:
    r = CELL.robot
    rng = np.random.default_rng(7)
    q = rng.uniform(r.limits[:, 0] - 0.5, r.limits[:, 1] + 0.5, size=(20000, 6))
    T = r.fk_batch(q)
    T[:, :3, 3] += rng.normal(scale=5.0, size=(len(T), 3))  # some out of reach
    for j in range(6):  # and some with one joint exactly at a limit
        qq = rng.uniform(r.limits[:, 0], r.limits[:, 1], size=(2000, 6))
        qq[:, j] = r.limits[j, rng.integers(0, 2, len(qq))]
        T = np.concatenate([T, r.fk_batch(qq)])
    want = r.ik_batch(T)[1].any(axis=1)
    assert 0 < want.sum() < len(want)
    assert np.array_equal(r.reachable_mask(T), want)


def _reach_everywhere(cell, obj: str, cands: np.ndarray, X: np.ndarray) -> np.ndarray:
    """(m,) bool by brute force: some placement of cands reaches T_O @ X clear of the world
    (no pruning, no chunks: every placement at once)."""
    from spar_py.world.reach.workspace import requirement_clear

    return np.array([requirement_clear(CellCache(cell), obj, cands, x).ok.any() for x in X])


def test_some_placement_reaches_matches_the_whole_grid() -> None:
    cache = CellCache(CELL)
    for obj, model in CELL.objects.items():
        X = [g.T for g in model.grasps.values()]
        X += [CELL.transforms["trans_1"] @ g.T for g in CELL.objects["peg"].grasps.values()]
        for pose in model.poses:
            got = placement.some_placement_reaches(cache, obj, pose, X)
            grid = placement._grid(cache, obj, pose)
            assert np.array_equal(got, _reach_everywhere(CELL, obj, grid, np.stack(X))), (obj, pose)
            # a grasp from below the table is among them, so the prune is exercised
            assert not got.all()


def test_choose_is_the_nearest_feasible_of_all_candidates() -> None:
    blk, peg = CELL.objects["block"], CELL.objects["peg"]
    occupied = [(CELL.positions["tr1"].T[:2, 3], peg.bounding_radius())]
    cases = [("block", "p2P5", [blk.grasps["p2G9"].T, CELL.transforms["trans_1"] @ peg.grasps["p1G11"].T]),
             ("block", "p2P1", [blk.grasps["p2G3"].T]),
             ("peg", "p1P1", [peg.grasps["p1G7"].T, peg.grasps["p1G1"].T])]
    for obj, pose, reqs in cases:
        cache = CellCache(CELL)
        cands = placement.candidates(cache, obj, pose, occupied)
        ok = placement.feasible(cache, cands, reqs)
        regs = placement.default_regions(CELL)
        near = np.mean([[(r["x"][0] + r["x"][1]) / 2, (r["y"][0] + r["y"][1]) / 2] for r in regs], axis=0)
        good = [c for c, f in zip(cands, ok) if f]
        want = min(good, key=lambda p: (round(float(np.hypot(p.x - near[0], p.y - near[1])), 9), p.yaw),
                   default=None)
        got = placement.choose(cache, obj, pose, reqs, occupied)
        if want is None:
            assert got is None
        else:
            assert (got.x, got.y, got.yaw) == (want.x, want.y, want.yaw)
            assert np.array_equal(got.T, want.T)
