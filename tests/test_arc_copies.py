"""Phase 1's arcs share answers between renamed copies of one model (generated cells: N identical
pegs and blocks), and only between them.

- CollisionScene.shape_key is the same for copies and differs for another shape; the copies'
  bodies are built once (the same arrays, their own names).
- SceneState.renamed is the state CollisionScene.at makes for the renamed world: the same bodies
  under the new names, the same pairs, a fresh cache of the library's distances, and the same
  verdicts and named pairs from check(); it refuses a renaming onto a link's or gripper's name.
- workspace.requirement_state of a copy is such a renamed state, and its check() equals that of
  a state at() builds for the copy itself.
- placement.some_placement_reaches_each answers a copy from its twin's memo entry: the same answers
  as a fresh cell asked about the copy alone.
- arcs.arc on every copy of a generated cell, asked in a run that shares all of this, gives the
  answers and refusals of a fresh cell per question (nothing shared)."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from spar_py.world.reach import arcs as arcs
from spar_py.world.reach import workspace as workspace
from spar_py.app.gen import generate_assembly
from spar_py.kb import load_problem
from spar_py.world.reach.placement import some_placement_reaches_each
from spar_py.world.collision import CellCache
from spar_py.world.run import WorldRun

PROBLEMS = Path(__file__).resolve().parent.parent / "kb" / "problems"


@pytest.fixture(scope="module")
def g3(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return generate_assembly(3, tmp_path_factory.mktemp("g3"))


def _random_q(robot, rng: np.random.Generator, n: int) -> np.ndarray:
    lo, hi = np.asarray(robot.limits, float).T
    return rng.uniform(lo, hi, size=(n, 6))


def test_copies_share_a_shape_key_and_their_bodies_but_not_their_names(g3: Path) -> None:
    cell = load_problem(g3)
    scene = CellCache(cell).scene()
    assert scene.shape_key("peg1") == scene.shape_key("peg2") == scene.shape_key("peg3")
    assert scene.shape_key("block1") == scene.shape_key("block3")
    assert scene.shape_key("peg1") != scene.shape_key("block1")
    for a, b in zip(scene.shapes_of("peg1"), scene.shapes_of("peg2")):
        assert (a.name, b.name) == ("peg1", "peg2")
        assert a.points is b.points and a.T is b.T and a._fcl is b._fcl
    paper = CellCache(load_problem(PROBLEMS / "peg_in_block.yaml")).scene()
    assert paper.shape_key("peg") != paper.shape_key("block")


def _same_state(a, b) -> None:
    assert [x.name for x in a.bodies] == [x.name for x in b.bodies]
    for x, y in zip(a.bodies, b.bodies):
        assert (x.kind, x.frame, x.size) == (y.kind, y.frame, y.size)
        assert np.array_equal(x.points, y.points) and np.array_equal(x.T, y.T)
    assert np.array_equal(a.pairs, b.pairs) and np.array_equal(a.table_bodies, b.table_bodies)
    assert np.array_equal(a.exact_pair, b.exact_pair) and list(a._rigid) == list(b._rigid)
    assert (a.hand is None) == (b.hand is None)
    if a.hand is not None:
        assert a.hand[:2] == b.hand[:2] and np.array_equal(a.hand[2], b.hand[2])


def test_renamed_state_is_the_state_at_makes_for_the_renamed_world(g3: Path) -> None:
    cell = load_problem(g3)
    scene = CellCache(cell).scene()
    rng = np.random.default_rng(7)
    g = next(iter(cell.objects["peg1"].grasps.values()))
    inv = np.linalg.inv(g.T)
    worlds = [  # (world of copy 1, the renaming to copy 2)
        (dict(grasped="peg1", attached={"peg1": inv}, width=g.width), {"peg1": "peg2"}),
        (dict(held=("peg1", inv), attached={"block1": inv}, width=g.width, allow=[("held:peg1", "block1")]),
         {"peg1": "peg2", "held:peg1": "held:peg2", "block1": "block2"}),
        (dict(parts={"block1": cell.positions["tr2"].T, "peg3": cell.positions["tr5"].T}, held=("peg1", inv)),
         {"peg1": "peg2", "held:peg1": "held:peg2", "block1": "block3", "peg3": "peg1"}),
    ]
    q = _random_q(cell.robot, rng, 200)
    for kw, names in worlds:
        kw2 = dict(kw)
        parts = kw2.pop("parts", {})
        first = scene.at(parts, **kw2)
        first.check(q)  # fills the first state's caches: the copy must not take them
        ren = {names.get(k, k): v for k, v in parts.items()}
        kw_b = dict(kw2)
        if "held" in kw_b:
            kw_b["held"] = (names[kw_b["held"][0]], kw_b["held"][1])
        if "grasped" in kw_b:
            kw_b["grasped"] = names[kw_b["grasped"]]
        if "attached" in kw_b:
            kw_b["attached"] = {names[k]: v for k, v in kw_b["attached"].items()}
        if "allow" in kw_b:
            kw_b["allow"] = [tuple(names.get(n, n) for n in p) for p in kw_b["allow"]]
        fresh = scene.at(ren, **kw_b)
        copy = first.renamed(names)
        assert copy is not None
        _same_state(copy, fresh)
        assert all(v is None for v in copy._rigid.values()) and copy._measured == {}
        assert copy.check(q)[0].tolist() == fresh.check(q)[0].tolist()
        assert copy.check(q)[1] == fresh.check(q)[1]
    state = scene.at({}, grasped="peg1", attached={"peg1": inv}, width=g.width)
    assert state.renamed({"peg1": "forearm"}) is None   # a link's name
    assert state.renamed({"peg1": "palm"}) is None      # a gripper body's
    assert state.renamed({"peg1": "table"}) is None
    assert state.renamed({"peg1": "x", "peg2": "x"}) is None  # not one to one


def test_a_copy_s_requirement_state_is_renamed_and_checks_as_its_own(g3: Path) -> None:
    cell = load_problem(g3)
    cache = CellCache(cell)
    scene = cache.scene()
    rng = np.random.default_rng(3)
    q = _random_q(cell.robot, rng, 300)
    for k in (1, 2, 3):
        g1 = next(iter(cell.objects["peg1"].grasps.values()))
        for gk in cell.objects[f"peg{k}"].grasps.values():
            if np.array_equal(gk.T, g1.T):
                break
        else:
            continue
        req = workspace.Requirement(gk.T, None, gk.width)
        state = workspace.requirement_state(cache, f"peg{k}", req)
        own = scene.at({}, **workspace._requirement_world(f"peg{k}", req))
        _same_state(state, own)
        assert state.check(q)[1] == own.check(q)[1]
    assert len(cache.table("workspace.requirement_proto", workspace.STATE_LIMIT)) >= 1


def _arcs(cell) -> list[tuple]:
    out = []
    for name, model in cell.objects.items():
        init = [p.label for p in cell.positions.values() if p.obj == name]
        out.append(("reachable", [name], sorted(model.grasps), sorted(model.poses) + init, None))
    for k in (1, 2, 3):
        held, fixed = cell.objects[f"peg{k}"], cell.objects[f"block{k}"]
        init = [p.label for p in cell.positions.values() if p.obj == f"block{k}"]
        out.append(("mate_reachable", [f"peg{k}", f"block{k}"], sorted(held.grasps), sorted(fixed.poses) + init,
                    next(iter(cell.transforms))))
    return out


def test_arcs_of_copies_are_those_of_a_fresh_cell_per_question(g3: Path) -> None:
    shared = WorldRun(CellCache(load_problem(g3)))
    asks = _arcs(shared.cell)
    got = [shared.arc_pairs(kind, objs, gs, ps, ta) for kind, objs, gs, ps, ta in asks]
    for (kind, objs, gs, ps, ta), pairs in zip(asks, got):
        fresh = CellCache(load_problem(g3))
        assert arcs.arc(fresh, kind, objs, gs, ps, ta).pairs == pairs
    assert any(got)
    # the refusals, each asked alone, are the shared run's
    alone: list[str] = []
    for kind, objs, gs, ps, ta in asks:
        run = WorldRun(CellCache(load_problem(g3)))
        run.arc_pairs(kind, objs, gs, ps, ta)
        alone += [r.text() for r in run.log.refusals()]
    assert sorted(r.text() for r in shared.log.refusals()) == sorted(alone)


def test_somewhere_answers_a_copy_from_its_twin_as_a_fresh_cell_would(g3: Path) -> None:
    shared = CellCache(load_problem(g3))
    for k in (1, 2, 3):
        name = f"block{k}"
        model = shared.cell.objects[name]
        asks = [(p, [workspace.Requirement(g.T, None, g.width) for g in model.grasps.values()]) for p in model.poses]
        got = some_placement_reaches_each(shared, name, asks)
        ref = some_placement_reaches_each(CellCache(load_problem(g3)), name, asks)
        assert [a.tolist() for a in got] == [r.tolist() for r in ref]
    memo = shared.table("placement.somewhere", 100_000)
    n_poses = len(shared.cell.objects["block1"].poses)
    distinct = {g.T.tobytes() for k in (1, 2, 3) for g in shared.cell.objects[f"block{k}"].grasps.values()}
    assert len(memo) == n_poses * len(distinct)  # one entry per geometry, not per copy


def test_stable_poses_at_once_are_same_stable_pose_one_by_one() -> None:
    from spar_py.core.geometry import ORTHO_TOL, same_stable_pose, same_stable_poses

    def rule(R_abs: np.ndarray, R_pose: np.ndarray) -> bool:  # Sec. 5.2.3: the third rows agree
        return bool(np.allclose(R_abs[2, :3], R_pose[2, :3], rtol=0.0, atol=ORTHO_TOL))

    rng = np.random.default_rng(11)
    cell = load_problem(PROBLEMS / "peg_in_block.yaml")
    poses = np.stack([p.R for m in cell.objects.values() for p in m.poses.values()])
    seen = set()
    for _ in range(300):
        T = np.eye(4)
        R = np.asarray(poses[rng.integers(len(poses))], float).copy()
        # nudged by about the tolerance, some inside it and some beyond
        R[2] += rng.choice([0.0, 1.0]) * rng.uniform(-2, 2, 3) * ORTHO_TOL
        T[:3, :3] = R
        got = same_stable_poses(T, poses).tolist()
        ref = [rule(R, P) for P in poses]
        assert got == ref == [same_stable_pose(T, P) for P in poses]
        seen.update(ref)
    assert seen == {True, False}
    assert same_stable_poses(np.eye(4), np.zeros((0, 3, 3))).tolist() == []
    assert same_stable_poses(np.eye(4), np.eye(3)[None]).tolist() == [True]
