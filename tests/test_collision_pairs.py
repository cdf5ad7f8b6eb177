"""The checked pairs of a collision state (world/collision/pairs.py's pair_structure), set for the
world's bodies a name at a time, are the pairs of the rule written out as one loop over every
(moving body, body) pair (:func:`reference_pairs`, the module notes' rule as it was first
coded); and the placed bodies the scene keeps on the cell are the bodies placed afresh.

States of real cells (the PUMA's allowed link pairs, the UR's, a shelf obstacle, a generated
cell of many parts) with every kind of hand: empty, a part held, a part being grasped on the
table, a part attached to the tool, and allowed contacts (the step's own, and one between a
gripper body and a part on the table)."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from spar_py.app.gen import generate_assembly
from spar_py.kb import load_problem
from spar_py.world.collision import bounds
from spar_py.world.collision.bodies import TOOL, WORLD
from spar_py.world.collision.pairs import pair_structure
from spar_py.world.collision import CellCache

PROBLEMS = Path(__file__).resolve().parent.parent / "kb" / "problems"


def reference_pairs(scene, bodies, n_moving, hand_part, allow, attached):
    """The pair rule as a plain loop over every (moving body i, body j > i) pair."""
    moving = bodies[:n_moving]
    skip = scene.allowed | allow
    pairs: list[tuple[int, int]] = []
    gripper_names = {"palm", "finger_l", "finger_r"}

    def part_of(b):
        return b.name[5:] if b.name.startswith("held:") else b.name

    fixed_in_tool = {i for i, b in enumerate(moving) if b.frame == TOOL and b.name in attached}
    for i, bi in enumerate(moving):
        for j, bj in enumerate(bodies):
            if j <= i and j < len(moving):
                continue
            if frozenset((bi.name, bj.name)) in skip or bi.name == bj.name:
                continue
            if i in fixed_in_tool and (bj.frame == WORLD or j in fixed_in_tool):
                continue
            if bj.frame == WORLD or bj.frame == 0 and bi.frame >= 2:
                if bi.name in gripper_names and part_of(bj) == hand_part and bj.frame == WORLD:
                    continue
                pairs.append((i, j))
                continue
            if bj.frame == WORLD or bj.frame == 0:
                continue
            fi, fj = bi.frame, bj.frame
            ti, tj = bi.frame == TOOL, bj.frame == TOOL
            if ti and tj:
                ni, nj = part_of(bi), part_of(bj)
                if ni in gripper_names and nj in gripper_names or ni == nj:
                    continue
                if hand_part in (ni, nj) and (ni in gripper_names or nj in gripper_names):
                    continue
                pairs.append((i, j))
                continue
            if ti or tj:
                link = bj if ti else bi
                other = bi if ti else bj
                limit = 5 if other.name in gripper_names else 6
                if link.frame <= limit:
                    pairs.append((i, j))
                continue
            if abs(fi - fj) >= 2:
                pairs.append((i, j))
    pairs_arr = np.array(pairs, dtype=int).reshape(-1, 2)
    table_bodies = np.array([i for i, b in enumerate(moving)
                             if frozenset((b.name, "table")) not in skip and i not in fixed_in_tool], dtype=int)
    exact_pair = np.array([bodies[i].kind == "capsule" and bodies[j].kind == "capsule"
                           for i, j in pairs_arr], dtype=bool)
    rigid = [p for p, (i, j) in enumerate(pairs_arr.tolist())
             if bodies[i].frame in (6, TOOL) and bodies[j].frame in (6, TOOL)]
    return pairs_arr, table_bodies, exact_pair, tuple(rigid)


def _cells(tmp: Path) -> list:
    names = ["peg_in_block.yaml", "shelf.yaml", "ur5e_peg_in_block.yaml", "two_pegs.yaml"]
    return [load_problem(PROBLEMS / n) for n in names] + [load_problem(generate_assembly(3, tmp / "g3"))]


def _states(cell):
    """States of every kind of hand in ``cell``: (state, its n_moving, hand part, allow, attached)."""
    scene = CellCache(cell).scene()
    parts = {p.obj if p.obj not in seen else f"{p.obj}@{p.name}": p.T
             for seen in [set()] for p in cell.positions.values() if not seen.add(p.obj)}
    names = list(parts)
    a, b = names[0], names[-1]
    grip = np.eye(4)
    grip[2, 3] = 1.0
    out = [(scene.at(parts), None, (), ()),
           (scene.at({k: v for k, v in parts.items() if k != a}, (a, grip)), a, (), ()),
           (scene.at(parts, (a, grip), allow=[(f"held:{a}", b), (f"held:{a}", "table")]), a,
            [(f"held:{a}", b), (f"held:{a}", "table")], ()),
           (scene.at(parts, None, b), b, (), ()),
           (scene.at(parts, None, b, allow=[("palm", a), ("finger_l", "table")]), b,
            [("palm", a), ("finger_l", "table")], ()),
           (scene.at({k: v for k, v in parts.items() if k != b}, None, b, attached={b: grip}), b, (), (b,)),
           (scene.at({}, (a, grip), attached={b: grip}), a, (), (b,))]
    return [(s, h, frozenset(frozenset(p) for p in al), frozenset(at)) for s, h, al, at in out]


def test_pair_structure_is_the_plain_loops(tmp_path: Path) -> None:
    checked = with_world = 0
    for cell in _cells(tmp_path):
        for state, hand, allow, attached in _states(cell):
            ref = reference_pairs(state.scene, state.bodies, state.n_moving, hand, allow, attached)
            got = pair_structure(state.scene, state.bodies, state.n_moving, hand, allow, attached)
            for g, r in zip(got[:3], ref[:3]):
                assert g.dtype == r.dtype and np.array_equal(g, r)
            assert got[3] == ref[3]
            assert np.array_equal(state.pairs, ref[0])
            checked += len(ref[0])
            with_world += sum(state.bodies[j].frame == WORLD for j in ref[0][:, 1].tolist())
    assert checked > 1000 and with_world > 500


def test_pair_structure_without_a_memo_is_the_same(tmp_path: Path) -> None:
    cell = _cells(tmp_path)[1]  # the shelf: an obstacle
    for state, hand, allow, attached in _states(cell):
        ref = reference_pairs(state.scene, state.bodies, state.n_moving, hand, allow, attached)
        memo, state.scene.memo = state.scene.memo, None
        try:
            got = pair_structure(state.scene, state.bodies, state.n_moving, hand, allow, attached)
        finally:
            state.scene.memo = memo
        assert np.array_equal(got[0], ref[0]) and got[3] == ref[3]


@pytest.mark.parametrize("frame", [WORLD, TOOL])
def test_placed_bodies_are_placed_afresh_per_pose(frame: int) -> None:
    cell = load_problem(PROBLEMS / "peg_in_block.yaml")
    scene = CellCache(cell).scene()
    T = cell.positions["tr1"].T.copy()
    first = scene.placed("peg", T, frame)
    assert scene.placed("peg", T.copy(), frame) is first  # kept on the cell
    T2 = T.copy()
    T2[0, 3] += 0.5
    moved = scene.placed("peg", T2, frame)
    assert moved is not first
    for got, T_ in ((first, T), (moved, T2)):
        fresh = [b.placed(T_, frame, "peg") for b in scene.shapes_of("peg")]
        assert len(got) == len(fresh)
        for g, f in zip(got, fresh):
            assert g.name == f.name and g.frame == f.frame == frame
            assert np.array_equal(g.points, f.points) and np.array_equal(g.T, f.T)
            assert all(np.array_equal(x, y) for x, y in zip(g.cap, f.cap))
    held = scene.placed("peg", T, TOOL, "held:peg")
    assert {b.name for b in held} == {"held:peg"} and held is not first


def test_near_bounds_keep_every_bound_within_the_margin(tmp_path: Path) -> None:
    """_near_bounds (the pairs' boxes over all rows first, then the rows' spheres) gives the
    capsule bound of _bounds wherever that is within the margin (and so never misses a near
    pair), and +inf or that same bound elsewhere; on random arm configurations, in cells with
    obstacles and many parts, and with a large margin so that many pairs are near."""
    rng = np.random.default_rng(3)
    near_cells = 0
    for cell in _cells(tmp_path):
        for state, *_ in _states(cell)[:4]:
            q = rng.uniform(-np.pi, np.pi, (40, 6))
            for m in (state.scene.margin, 10 * state.scene.margin, 1e9):
                _, full, tab = state._bounds(q)
                _, near, tab2 = state._near_bounds(q, m)
                assert np.array_equal(tab, tab2)
                within = full <= m
                assert np.array_equal(near[within], full[within])
                assert np.all(np.isinf(near[~within]) | (near[~within] == full[~within]))
                near_cells += int(within.sum())
    assert near_cells > 1000


def test_segment_distance_few_pairs_same_bits_as_vectorised() -> None:
    """segment_distance computes up to FEW_SEGMENTS pairs in Python floats: the same values to
    the bit as the vectorised branch on random, degenerate (a point), parallel and overlapping
    segments and on broadcast shapes, and both agree with a brute-force minimum over points of
    the two segments (an independent check of the formula)."""
    rng = np.random.default_rng(7)
    few = bounds.FEW_SEGMENTS

    def vectorised(*P):
        bounds.FEW_SEGMENTS = -1
        try:
            return bounds.segment_distance(*P)
        finally:
            bounds.FEW_SEGMENTS = few

    for trial in range(3000):
        n = int(rng.integers(1, few + 1))
        P = [rng.normal(size=(n, 3)) * rng.choice([1e-9, 1.0, 100.0]) for _ in range(4)]
        kind = trial % 5
        if kind == 1:
            P[1] = P[0].copy()  # the first segment a point
        elif kind == 2:
            P[1], P[3] = P[0].copy(), P[2].copy()  # both points
        elif kind == 3:
            P[2], P[3] = P[0] + 0.5 * (P[1] - P[0]), P[0] + 1.5 * (P[1] - P[0])  # collinear, overlapping
        elif kind == 4:
            P[3] = P[2] + 2.0 * (P[1] - P[0])  # parallel
        got = bounds.segment_distance(*P)
        assert np.array_equal(got, vectorised(*P), equal_nan=True)
        if trial % 100 == 0:  # brute force: the least distance between 401 points on each
            u = np.linspace(0.0, 1.0, 401)[:, None]
            for k in range(n):
                a = P[0][k] + u * (P[1][k] - P[0][k])
                b = P[2][k] + u * (P[3][k] - P[2][k])
                brute = np.sqrt(((a[:, None] - b[None]) ** 2).sum(-1)).min()
                scale = 1.0 + np.abs(np.concatenate([p[k] for p in P])).max()
                assert got[k] <= brute + 1e-9 * scale
                assert brute - got[k] <= 0.01 * scale
    A, B = rng.normal(size=(2, 3, 3)), rng.normal(size=(2, 3, 3))
    C, D = rng.normal(size=(1, 3, 3)), rng.normal(size=(2, 1, 3))
    assert bounds.segment_distance(A, B, C, D).shape == (2, 3)
    assert np.array_equal(bounds.segment_distance(A, B, C, D), vectorised(A, B, C, D))
    assert bounds.segment_distance(np.zeros(3), np.ones(3), np.full(3, 2.0), np.full(3, 3.0)).shape == ()
