"""Put-down placements: feasible ones check out by forward kinematics; unreachable regions give none."""
from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np

from spar_py.world.reach import placement as placement
from spar_py.kb import load_problem
from spar_py.world.collision import CellCache

CELL = load_problem(Path(__file__).resolve().parent.parent / "kb/problems/peg_in_block.yaml")


def _occupied() -> list[tuple[np.ndarray, float]]:
    return [(CELL.positions["tr1"].T[:2, 3], CELL.objects["peg"].bounding_radius())]


def test_chosen_placement_is_reachable_by_fk() -> None:
    blk, peg = CELL.objects["block"], CELL.objects["peg"]
    # (p2G9 with p1G11, the pair this test used before the collision check, has no placement
    # now: p1G11's wrist then passes 0.14 in through the table)
    reqs = [blk.grasps["p2G1"].T, CELL.transforms["trans_1"] @ peg.grasps["p1G10"].T]
    p = placement.choose(CellCache(CELL), "block", "p2P5", reqs, _occupied())
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
    assert placement.choose(CellCache(far), "block", "p2P1", reqs, []) is None


def test_feasible_matches_single_ik_queries() -> None:
    blk = CELL.objects["block"]
    cands = placement.candidates(CellCache(CELL), "block", "p2P1", _occupied())[:200]
    X = blk.grasps["p2G3"].T
    ok = placement.feasible(CellCache(CELL), cands, [X])
    for c, f in zip(cands[:60], ok[:60]):
        T = c.T @ X
        single = len(CELL.robot.ik(T)) > 0
        flange_up = (T @ np.linalg.inv(CELL.robot.tool))[2, 3] > 0
        assert f == (single and flange_up)


def test_default_region_stays_on_a_table_with_edges() -> None:
    """Without placement_regions, the free region grown round the initial positions is cut to
    the table top (``table:``): a put-down never hangs over the edge. The paper's block sits at
    y = 8 in; a table ending at y = 10 in leaves a strip beyond it, and the chosen placement's
    whole footprint (computed here from the block's box, not by the module) is on the table."""
    edge = 10.0
    cell = replace(CELL, table=(-100.0, 100.0, -100.0, edge))
    cache = CellCache(cell)
    (r,) = placement.default_regions(cell)
    assert r["y"][1] == edge and r["y"][0] == placement.default_regions(CELL)[0]["y"][0]
    assert placement.default_regions(replace(cell, table=(-100.0, 100.0, 50.0, 60.0))) == []
    blk = CELL.objects["block"]
    p = placement.choose(cache, "block", "p2P5", [blk.grasps["p2G1"].T], _occupied())
    assert p is not None
    (box,) = [s for s in blk.shape if s.kind == "box"]
    corners = np.array([[x, y, z, 1.0] for x in (box.lo[0], box.hi[0]) for y in (box.lo[1], box.hi[1])
                        for z in (box.lo[2], box.hi[2])])
    assert (corners @ p.T.T)[:, 1].max() <= edge + 1e-9


def test_tool_on_table_prune_refuses_only_what_the_full_check_refuses() -> None:
    """The grid prune (workspace.tool_on_table): where the gripper, tool mount or part in the
    hand meets the (unbounded) table at the grid's first placement, the full check, IK and
    every solution, refuses every placement of the grid too. Some grasps are pruned, some not."""
    from spar_py.world.reach.workspace import Requirement, requirement_clear, tool_on_table

    cache = CellCache(CELL)
    cell = cache.cell
    pruned = kept = 0
    for obj in ("peg", "block"):
        m = cell.objects[obj]
        for pose in m.poses:
            grid = placement._grid(cache, obj, pose)
            for g in m.grasps.values():
                req = Requirement(g.T, width=g.width)
                if tool_on_table(cache, obj, grid[0] @ g.T, req) is not None:
                    pruned += 1
                    assert not requirement_clear(cache, obj, grid, req).ok.any(), (obj, pose, g.label)
                else:
                    kept += 1
    assert pruned and kept
    assert tool_on_table(CellCache(replace(cell, table=(-100.0, 100.0, -100.0, 100.0))), "peg",
                         placement._grid(cache, "peg", "p1P1")[0] @ CELL.objects["peg"].grasps["p1G17"].T,
                         Requirement(CELL.objects["peg"].grasps["p1G17"].T)) is None


def _mate_requirements(cell):  # the mate_reachable arc's: the peg held by each grasp, onto the block
    from spar_py.world.reach.workspace import Requirement

    Ta = cell.transforms["trans_1"]
    return [(g.label, Requirement(Ta @ g.T, ("peg", np.linalg.inv(g.T)), g.width))
            for g in cell.objects["peg"].grasps.values()]


def test_rigid_refusal_refuses_only_what_the_full_check_refuses() -> None:
    """The prune before IK (workspace.tool_refusal, table=False): where two bodies rigid with the
    flange clash (a finger or the tool mount in the block the held peg is mated onto) or the grasp
    rule fails, the full check, IK and every solution, refuses every placement of the grid. Some
    mate requirements are pruned, some not."""
    from spar_py.world.reach.workspace import requirement_clear, requirement_state, tool_refusal

    cache = CellCache(CELL)
    cell = cache.cell
    pruned = kept = 0
    for pose in cell.objects["block"].poses:
        grid = placement._grid(cache, "block", pose)
        for label, req in _mate_requirements(cell):
            why = tool_refusal(cache, "block", grid[0] @ req.X, req, table=False)
            if why is None:
                kept += 1
                continue
            pruned += 1
            full = requirement_clear(cache, "block", grid, req, state=requirement_state(cache, "block", req))
            assert not full.ok.any(), (pose, label, why)
    assert pruned and kept


def test_somewhere_is_the_whole_grid_answer() -> None:
    """some_placement_reaches (first placement alone, then chunks; prunes before IK), a pose at a time
    and every pose at once (some_placement_reaches_each), answers, for every grasp of either object
    and every mate requirement, what one check of the whole grid answers."""
    from spar_py.world.reach.workspace import Requirement, requirement_clear

    cache = CellCache(CELL)
    cell = cache.cell
    reqs = {"block": [Requirement(g.T, None, g.width) for g in cell.objects["block"].grasps.values()]
            + [r for _, r in _mate_requirements(cell)],
            "peg": [Requirement(g.T, None, g.width) for g in cell.objects["peg"].grasps.values()]}
    answers = set()
    for obj, rs in reqs.items():
        poses = list(cell.objects[obj].poses)
        # every pose at once, as an arc asks (one batch per requirement), on a cell of its own
        each = placement.some_placement_reaches_each(CellCache(cell), obj,
                                                      [(p, rs) for p in poses])
        for pose, together in zip(poses, each):
            got = placement.some_placement_reaches(cache, obj, pose, rs)
            grid = placement._grid(cache, obj, pose)
            fresh = CellCache(cell)
            want = [requirement_clear(fresh, obj, grid, r).ok.any() for r in rs]
            assert got.tolist() == want, (obj, pose)
            assert together.tolist() == want, (obj, pose)
            answers |= set(want)
    assert answers == {True, False}


def test_placements_do_not_keep_the_grid_alive() -> None:
    """A placement owns its pose: a view into the grid's (n, 4, 4) poses would keep the whole
    grid alive wherever the placement is kept (phase 2's memo tables held 62 MB so at N = 50)."""
    blk, peg = CELL.objects["block"], CELL.objects["peg"]
    reqs = [blk.grasps["p2G1"].T, CELL.transforms["trans_1"] @ peg.grasps["p1G10"].T]
    chosen = placement.choose(CellCache(CELL), "block", "p2P5", reqs, _occupied())
    assert chosen is not None
    cands = placement.candidates(CellCache(CELL), "block", "p2P5", _occupied())
    assert len(cands) > 1
    for p in [chosen, *cands[:3]]:
        assert p.T.shape == (4, 4)
        assert p.T.base is None or p.T.base.nbytes <= p.T.nbytes


def test_nearest_order_is_the_sorted_python_round_order() -> None:
    """choose's order (least distance rounded to ROUND_MM, then yaw, then grid order) computed
    on arrays is the order of Python's sorted with ``round``, on distances at and next to
    halves of the last digit (where ``np.round`` alone differs from ``round``: 1022.2729595
    and many more below), exact halves (multiples of 1/128) and many ties."""
    rng = np.random.default_rng(7)
    k = rng.integers(0, 2_000_000_000, 3000)
    half = (k + 0.5) / 1e6
    d = np.concatenate([half, np.nextafter(half, 0), np.nextafter(half, np.inf), rng.integers(0, 40, 3000) / 128,
                        np.round(rng.uniform(0, 5, 3000), 3), [1022.2729595, 0.0, 2.0 ** 60]])
    yaw = rng.integers(0, 4, len(d)) * (np.pi / 2)
    dl, yl = d.tolist(), yaw.tolist()
    assert any(float(np.round(v, 6)) != round(v, 6) for v in dl)  # the case the fix-up is for
    assert placement.round_like_python(d, 6).tolist() == [round(v, 6) for v in dl]
    ref = sorted(range(len(dl)), key=lambda i: (round(dl[i], 6), yl[i]))
    assert placement.nearest_order(d, yaw, 6).tolist() == ref
    assert placement.nearest_order(np.zeros(0), np.zeros(0), 6).tolist() == []


def test_nearest_head_is_the_start_of_the_sorted_order() -> None:
    """choose reads the order's first chunks from _nearest_head: at least the first m entries of
    Python's sorted order (rounded distance, yaw, index), on keys with many ties (the m-th
    least shared by several candidates) and fewer candidates than m."""
    rng = np.random.default_rng(8)
    for n, m in ((3000, 97), (500, 97), (60, 97), (1, 1), (200, 1)):
        key = rng.integers(0, 40, n) / 8.0
        yaw = rng.integers(0, 3, n) * (np.pi / 6)
        ref = sorted(range(n), key=lambda i: (key[i], yaw[i]))
        head = placement._nearest_head(key, yaw, m).tolist()
        assert len(head) >= min(m, n) and head == ref[:len(head)]
