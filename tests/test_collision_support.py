"""The shortcuts of world/collision/state.py's check(), clearance() and grasp rule, against the plain
computations they stand for.

- :func:`~spar_py.world.collision.bounds.support_gap` (a lower bound of two convex bodies' distance from
  their supports) never exceeds the distance, computed here independently as a small quadratic
  programme over the bodies' vertex hulls (scipy's SLSQP), and equals it for boxes side by side.
- check() asks the library only where that bound does not already put a pair beyond the margin:
  its verdicts and named pairs are those of asking the library for every near pair
  (:func:`reference_check`, the loop as first coded).
- clearance() computes the capsule bounds only of the pairs whose spheres can be nearest: its
  distances and pairs are those of the loop over every pair in the whole row's order
  (:func:`reference_clearance`, as first coded), ties between the fingers included.
- the grasp rule's memo key makes -0.0 and 0.0 one, and its verdicts are the library's."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from scipy.optimize import minimize

from spar_py.core.geometry import rotz
from spar_py.kb import load_problem
from spar_py.world.collision.bodies import TOOL, WORLD, _box_corners, body_distance, box, capsule, convex, cylinder
from spar_py.world.collision.bounds import support_gap
from spar_py.world.collision.state import GRASP_LIMIT, SceneState
from spar_py.world.collision import CellCache
from test_collision_pairs import _cells, _states

PROBLEMS = Path(__file__).resolve().parent.parent / "kb" / "problems"


# --------------------------------------------------------------------------- the support bound


def _rotation(rng: np.random.Generator) -> np.ndarray:
    Q, R = np.linalg.qr(rng.normal(size=(3, 3)))
    Q = Q * np.sign(np.diag(R))
    return Q if np.linalg.det(Q) > 0 else -Q


def _random_body(rng: np.random.Generator, name: str):
    """A body of a random kind, size and pose (world frame), sizes 1..10."""
    kind = rng.integers(4)
    T = np.eye(4)
    T[:3, :3] = _rotation(rng)
    T[:3, 3] = rng.uniform(-12, 12, 3)
    if kind == 0:
        h = rng.uniform(0.5, 5, 3)
        return box(name, WORLD, -h, h, T)
    a, b = rng.uniform(-5, 5, 3) + T[:3, 3], rng.uniform(-5, 5, 3) + T[:3, 3]
    if kind == 1:
        return capsule(name, WORLD, a, b, rng.uniform(0.2, 3))
    if kind == 2:
        return cylinder(name, WORLD, a, b, rng.uniform(0.2, 3))
    return convex(name, WORLD, rng.uniform(-4, 4, (12, 3)) + T[:3, 3])


def _hull_distance(P: np.ndarray, Q: np.ndarray) -> float:
    """The distance between the convex hulls of points P and Q: min |P^T l - Q^T m| over the
    two simplices (SLSQP from the centroids; a feasible point, so never below the distance)."""
    n, m = len(P), len(Q)

    def f(x: np.ndarray) -> float:
        d = x[:n] @ P - x[n:] @ Q
        return float(d @ d)

    def g(x: np.ndarray) -> np.ndarray:
        d = x[:n] @ P - x[n:] @ Q
        return np.concatenate([2 * P @ d, -2 * Q @ d])

    x0 = np.concatenate([np.full(n, 1 / n), np.full(m, 1 / m)])
    cons = [{"type": "eq", "fun": lambda x: x[:n].sum() - 1}, {"type": "eq", "fun": lambda x: x[n:].sum() - 1}]
    res = minimize(f, x0, jac=g, bounds=[(0, 1)] * (n + m), constraints=cons, method="SLSQP",
                   options={"ftol": 1e-14, "maxiter": 500})
    return float(np.sqrt(max(res.fun, 0.0)))


def _gap(a, b) -> float:
    return float(support_gap(a.points[None], np.array([a.radius]), a.T[None, :3, :3],
                             b.points[None], np.array([b.radius]), b.T[None, :3, :3])[0])


def test_support_gap_never_exceeds_the_distance() -> None:
    """Random pairs of every kind: the bound is at most the hulls' distance (less the capsules'
    radii; a cylinder's prism contains it), apart pairs are often bounded within 5% of it, and
    the library agrees with the reference distance (so the reference is the library's world)."""
    rng = np.random.default_rng(11)
    apart = tight = 0
    for k in range(150):
        a, b = _random_body(rng, "a"), _random_body(rng, "b")
        d = max(_hull_distance(a.points, b.points) - a.radius - b.radius, 0.0)
        gap = _gap(a, b)
        assert gap <= d + 1e-6, (k, a.kind, b.kind, gap, d)
        if a.kind != "cylinder" and b.kind != "cylinder":  # the library's cylinder is the inscribed one
            assert body_distance(a, np.eye(4), b, np.eye(4)) == pytest.approx(d, abs=1e-4)
        if d > 0.5:
            apart += 1
            tight += gap >= 0.95 * d
    assert apart > 30 and tight > apart // 4


def test_support_gap_is_the_distance_of_boxes_side_by_side() -> None:
    """Two boxes turned alike, apart along one axis: the face normals give the distance itself."""
    rng = np.random.default_rng(5)
    for _ in range(20):
        T = np.eye(4)
        T[:3, :3] = _rotation(rng)
        shift = np.eye(4)
        shift[0, 3] = 7.5
        a = box("a", WORLD, [-2, -1, -1], [2, 1, 1], T)
        b = box("b", WORLD, [-1, -3, -0.5], [1, 3, 0.5], T @ shift)
        assert _gap(a, b) == pytest.approx(7.5 - 2 - 1, abs=1e-7)
        assert _gap(a, b) <= body_distance(a, np.eye(4), b, np.eye(4)) + 1e-9


# --------------------------------------------------------------------------- check() and clearance()


def reference_check(state, q: np.ndarray):
    """check() as first coded: the library asked for every near cell that is not two capsules."""
    m = state.scene.margin
    F, lb, tab = state._bounds(q)
    ok = np.ones(len(q), dtype=bool)
    why = [None] * len(q)
    for r, (g_ok, g_name) in enumerate(state._grasp_rows(F)):
        if not g_ok:
            ok[r], why[r] = False, (g_name, state.hand[0])
    for r, k in zip(*np.nonzero(tab <= m)):
        if ok[r]:
            ok[r], why[r] = False, (state.bodies[state.table_bodies[k]].name, "table")
    for r, p in zip(*np.nonzero(lb <= m)):
        if not ok[r]:
            continue
        d = lb[r, p] if state.exact_pair[p] else state._exact_cell(F, r, p)
        if d <= m:
            i, j = state.pairs[p]
            ok[r], why[r] = False, (state.bodies[i].name, state.bodies[j].name)
    return ok, why


def reference_clearance(state, q: np.ndarray):
    """clearance() as first coded: every pair's capsule bound, visited in the row's sort order."""
    F, lb, tab = state._bounds(q)
    out = np.full(len(q), np.inf)
    names = [("", "")] * len(q)
    for r in range(len(q)):
        if tab.shape[1]:
            k = int(np.argmin(tab[r]))
            out[r], names[r] = tab[r, k], (state.bodies[state.table_bodies[k]].name, "table")
        for p in np.argsort(lb[r]):
            if lb[r, p] >= out[r]:
                break
            d = lb[r, p] if state.exact_pair[p] else state._exact_cell(F, r, p)
            if d < out[r]:
                i, j = state.pairs[p]
                out[r], names[r] = d, (state.bodies[i].name, state.bodies[j].name)
    return out, names


def _near_rows(state, rng: np.random.Generator, n: int) -> np.ndarray:
    """n joint vectors: random ones, and IK solutions of tool poses at the parts (most of a
    plan's: the hand at a part, its fingers beside its neighbours)."""
    q = [rng.uniform(-np.pi, np.pi, (n, 6))]
    robot = state.scene.robot
    for b in state.bodies[state.n_moving:]:
        if b.frame != WORLD or len(q) > n:
            continue
        T = np.eye(4)
        T[:3, :3] = np.diag([1.0, -1.0, -1.0])  # the tool pointing down at the part
        T[:3, 3] = b.points.mean(axis=0) + [0, 0, rng.uniform(0, 3)]
        sols = robot.ik(T)
        if len(sols):
            q.append(sols)
    return np.vstack(q)


def test_check_and_clearance_are_the_plain_loops(tmp_path: Path) -> None:
    rng = np.random.default_rng(2)
    rows = clear_rows = asked = 0
    for cell in _cells(tmp_path):
        for state, *_ in _states(cell):
            q = _near_rows(state, rng, 30)
            before = state.scene.stats["exact"]
            ok, why = state.check(q)
            asked += state.scene.stats["exact"] - before
            ref_ok, ref_why = reference_check(state, q)
            assert np.array_equal(ok, ref_ok) and why == ref_why
            rows += len(q)
            for m in (state.scene.margin, 50 * state.scene.margin):  # a large margin: many near pairs
                state.scene.margin, saved = m, state.scene.margin
                try:
                    assert state.check(q)[1] == reference_check(state, q)[1]
                finally:
                    state.scene.margin = saved
            good = q[ok]
            if len(good):
                d, names = state.clearance(good)
                ref_d, ref_names = reference_clearance(state, good)
                assert np.array_equal(d, ref_d) and names == ref_names
                clear_rows += len(good)
    assert rows > 1000 and clear_rows > 100


def _ties(state, q: np.ndarray) -> int:
    """Rows of q whose least distance (below the table's) two pairs with one capsule bound share."""
    F, lb, _ = state._bounds(q)
    d_ref, names = reference_clearance(state, q)
    out = 0
    for r in range(len(q)):
        near = np.flatnonzero(lb[r] <= d_ref[r])
        at = [(float(lb[r, p]), lb[r, p] if state.exact_pair[p] else state._exact_cell(F, r, p)) for p in near]
        hits = [b for b, d in at if d == d_ref[r] and names[r][1] != "table"]
        out += len(hits) > len(set(hits))
    return out


def test_clearance_names_the_pair_the_whole_sort_names_at_a_tie(tmp_path: Path, monkeypatch) -> None:
    """Every end-point of a generated cell's plan (phase 2's clearance calls, through the
    planner): the distances and pairs are the plain loop's, ties included (at assembles, the
    two fingers at one distance from the block, with equal capsule bounds: a tie only the whole
    row's sort order decides, and the pair named is the one that order visits first)."""
    from spar_py.app.gen import generate_assembly
    from spar_py.planning.planner import Planner

    seen = {"rows": 0, "ties": 0}
    clearance = SceneState.clearance

    def checked(state, q):
        got = clearance(state, q)
        ref = reference_clearance(state, np.asarray(q, float).reshape(-1, 6))
        assert np.array_equal(got[0], ref[0]) and got[1] == ref[1]
        seen["rows"] += len(got[0])
        seen["ties"] += _ties(state, np.asarray(q, float).reshape(-1, 6))
        return got

    monkeypatch.setattr(SceneState, "clearance", checked)
    plan = Planner(timeout=600).plan(load_problem(generate_assembly(15, tmp_path / "g15")))
    assert plan.outcome == "plan"
    assert seen["rows"] >= 40 and seen["ties"] > 0


# --------------------------------------------------------------------------- the grasp rule


def test_grasp_rule_key_makes_signed_zeros_one_and_its_verdicts_are_the_library_s() -> None:
    cell = load_problem(PROBLEMS / "peg_in_block.yaml")
    scene = CellCache(cell).scene()
    g = next(iter(cell.objects["peg"].grasps.values()))
    state = scene.at({"peg": cell.positions["tr1"].T}, None, "peg", width=g.width)
    T = np.linalg.inv(g.T)
    T = np.where(T == 0.0, 0.0, T)
    signed = np.where(T == 0.0, -0.0, T)
    assert T.tobytes() != signed.tobytes()
    table = scene.memo.table("collision.grasp", GRASP_LIMIT)
    table.clear()
    first = state.grasp_ok(T)
    assert state.grasp_ok(signed) == first and len(table) == 1
    # the verdicts at shifted poses (some entering the part, some clear) are the library's
    rng = np.random.default_rng(4)
    verdicts = set()
    gripper = scene.shrunk_gripper(g.width, scene.tol)
    for _ in range(60):
        Ts = T.copy()
        Ts[:3, 3] += rng.uniform(-1.0, 1.0, 3)
        bodies = [b.placed(Ts, TOOL, "peg") for b in scene.shapes_of("peg")]
        ref = next(((False, gb.name) for gb in gripper
                    if any(body_distance(gb, np.eye(4), b, np.eye(4)) <= 0.0 for b in bodies)), (True, None))
        assert state.grasp_ok(Ts) == ref
        verdicts.add(ref[0])
    assert verdicts == {True, False}


# --------------------------------------------------------------------------- the hand before the IK


def test_hand_refusal_refuses_only_what_check_refuses_at_every_solution(tmp_path: Path) -> None:
    """SceneState.hand_refusal at a tool pose names a pair only where check() refuses every IK
    solution of that pose (so a squeeze may skip the IK), and it does refuse: tool poses at and
    beside the parts, in states of every kind of hand."""
    rng = np.random.default_rng(5)
    said = agreed = 0
    for cell in _cells(tmp_path):
        robot = cell.robot
        for state, *_ in _states(cell):
            for b in state.bodies[state.n_moving:]:
                if b.frame != WORLD:
                    continue
                for _ in range(4):
                    T = np.eye(4)
                    T[:3, :3] = rotz(rng.uniform(-np.pi, np.pi))[:3, :3] @ np.diag([1.0, -1.0, -1.0])
                    T[:3, 3] = b.points.mean(axis=0) + rng.uniform(-1.5, 1.5, 3)
                    hit = state.hand_refusal(T)
                    sols = robot.ik(T)
                    if hit is None or not len(sols):
                        continue
                    said += 1
                    ok, why = state.check(sols)
                    assert not ok.any(), (cell.name, hit)
                    agreed += hit in why
    assert said > 20 and agreed > said // 2


def test_box_corners_hold_every_vertex() -> None:
    """A body of many vertices is first bounded by a box (bodies.py's _box_corners): every vertex
    lies in it (solved for in the box's own edges, not its construction), and the support bound
    it gives two such bodies never exceeds their hulls' distance."""
    rng = np.random.default_rng(3)
    for k in range(40):
        R = _rotation(rng)
        pts = rng.normal(size=(200, 3)) * rng.uniform(0.05, 5, 3) @ R.T + rng.uniform(-10, 10, 3)
        C = _box_corners(pts)
        o = C[0]
        E = np.stack([C[4] - o, C[2] - o, C[1] - o], axis=1)  # the three edges from corner 0
        s = np.linalg.solve(E, (pts - o).T)
        assert s.min() >= -1e-9 and s.max() <= 1 + 1e-9, k
        a, b = convex("a", WORLD, pts), convex("b", WORLD, pts @ _rotation(rng).T + rng.uniform(-20, 20, 3))
        assert a.corners is not None
        box_gap = float(support_gap(a.corners[None], np.zeros(1), np.eye(3)[None],
                                    b.corners[None], np.zeros(1), np.eye(3)[None])[0])
        assert box_gap <= _hull_distance(a.points, b.points) + 1e-6, k
