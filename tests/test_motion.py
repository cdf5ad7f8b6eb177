"""Motions between the end-points (issue 16): resolution, free motions (straight and OMPL),
tool lines, the robot file's motion keys, and the Planner's motion output.

The geometry is checked with code independent of world/motion/paths.py: Craig FK written out
in tests/craig_reference.py and tests/motion_fake.py (a small scene of points along the
links, the table and world boxes)."""
from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np
import pytest

from spar_py.core.errors import KBError, SparValueError
from spar_py.kb import load_robot
from spar_py.world.motion import paths as mo
from spar_py.world.collision import CellCache

sys.path.insert(0, str(Path(__file__).parent))
from craig_reference import craig_fk  # noqa: E402
from motion_fake import FakeScene, arm_points  # noqa: E402
from paths import ROOT  # noqa: E402

PUMA = ROOT / "kb" / "robots" / "puma762.yaml"
MARGIN = 0.1  # in


@pytest.fixture(scope="module")
def puma():
    return load_robot(PUMA, unit="in")


def _stage(puma):
    """Two configurations whose tool points are well above the table, and the midpoint of
    their tool positions (a wall there blocks the straight joint segment)."""
    a = np.radians([0.0, -60.0, 30.0, 0.0, 30.0, 0.0])
    b = np.radians([90.0, -60.0, 30.0, 0.0, 30.0, 0.0])
    pa, pb = craig_fk(puma, a[None])[0][:3, 3], craig_fk(puma, b[None])[0][:3, 3]
    return a, b, (pa + pb) / 2


def test_resolution_keeps_every_point_within_the_margin(puma) -> None:
    """Independent check: random configurations, random joint steps no larger than the
    resolution in any joint; the tool and points up to ``extent`` beyond it move by at most
    the margin (Craig FK written out, not the code under test)."""
    extent = 3.0
    res = mo.resolution(puma.dh, puma.tool, MARGIN, extent)
    rng = np.random.default_rng(1)
    q = rng.uniform(puma.limits[:, 0], puma.limits[:, 1], size=(300, 6))
    dq = rng.choice([-1.0, 1.0], size=q.shape) * res  # the worst case: every joint at the step
    T0, T1 = craig_fk(puma, q), craig_fk(puma, q + dq)
    offsets = extent * np.array([[1, 0, 0], [0, 1, 0], [0, 0, 1], [-1, 0, 0], [0, -1, 0], [0, 0, -1],
                                 [0.577, 0.577, 0.577]])
    moved = []
    for off in np.vstack([np.zeros((1, 3)), offsets]):
        p0 = np.einsum("nij,j->ni", T0[:, :3, :3], off) + T0[:, :3, 3]
        p1 = np.einsum("nij,j->ni", T1[:, :3, :3], off) + T1[:, :3, 3]
        moved.append(np.linalg.norm(p1 - p0, axis=1))
    assert max(m.max() for m in moved) <= MARGIN
    # and it is not needlessly fine: ten times the step moves something by more than the margin
    T2 = craig_fk(puma, q + 10 * dq)
    assert np.linalg.norm(T2[:, :3, 3] - T0[:, :3, 3], axis=1).max() > MARGIN


def test_densify_steps_and_ends() -> None:
    v = np.radians([[0, 0, 0, 0, 0, 0], [10, -5, 0, 0, 0, 1], [10, -5, 3, 0, 0, 1]])
    res = math.radians(0.3)
    d = mo.densify(v, res)
    assert np.abs(np.diff(d, axis=0)).max() <= res + 1e-12
    assert np.array_equal(d[0], v[0]) and np.array_equal(d[-1], v[-1])
    assert any(np.allclose(r, v[1]) for r in d)  # the polyline passes through its vertices


def test_straight_segment_first(puma) -> None:
    a, b, _ = _stage(puma)
    scene = FakeScene(puma, MARGIN)
    res = mo.resolution(puma.dh, puma.tool, MARGIN, 3.0)
    seg = mo.free_motion(scene.at({}), a, b, puma.limits, res, mo.MotionOptions(), "transit", "t")
    assert isinstance(seg, mo.Segment) and seg.how == "straight"
    assert scene.calls <= 3  # both ends and the whole segment, each one batched call


def _wall(puma, mid):
    return FakeScene(puma, MARGIN, {"wall": (mid - [4.0, 4.0, 40.0], mid + [4.0, 4.0, 40.0])})


def _own_clear(puma, scene, q) -> np.ndarray:
    """The test's own clearance: every arm point above the table and outside the grown boxes."""
    p, _ = arm_points(puma, q)
    ok = p[..., 2].min(axis=1) >= scene.margin
    for lo, hi in scene.boxes.values():
        inside = np.all((p >= lo - scene.margin) & (p <= hi + scene.margin), axis=-1)
        ok &= ~inside.any(axis=1)
    return ok


def test_ompl_detour_around_a_wall_is_clear_and_reproducible(puma) -> None:
    a, b, mid = _stage(puma)
    scene = _wall(puma, mid)
    res = mo.resolution(puma.dh, puma.tool, MARGIN, 3.0)
    assert not _own_clear(puma, scene, mo.densify(np.array([a, b]), res)).all()  # the straight line is blocked
    opts = mo.MotionOptions(seed=3, time_budget_s=5.0)
    seg = mo.free_motion(scene.at({}), a, b, puma.limits, res, opts, "transit", "t")
    assert isinstance(seg, mo.Segment), seg
    assert seg.how == "RRTConnect"
    w = seg.waypoints
    assert np.array_equal(w[0], a) and np.array_equal(w[-1], b)
    assert np.abs(np.diff(w, axis=0)).max() <= res + 1e-12
    assert _own_clear(puma, scene, w).all()
    assert np.all((w >= puma.limits[:, 0]) & (w <= puma.limits[:, 1]))
    assert seg.length <= seg.length_raw + 1e-9  # simplification never lengthens
    again = mo.free_motion(_wall(puma, mid).at({}), a, b, puma.limits, res, opts, "transit", "t")
    assert np.array_equal(again.waypoints, w)  # same seed, same path


def test_no_motion_names_the_blocking_pair(puma) -> None:
    a, b, mid = _stage(puma)
    pb = craig_fk(puma, b[None])[0][:3, 3]
    scene = FakeScene(puma, MARGIN, {"cage": (pb - 1.0, pb + 1.0)})  # the goal's tool point is inside
    res = mo.resolution(puma.dh, puma.tool, MARGIN, 3.0)
    got = mo.free_motion(scene.at({}), a, b, puma.limits, res, mo.MotionOptions(time_budget_s=0.2), "transit",
                         "transit motion to the approach of action_1")
    assert isinstance(got, mo.MotionFailure)
    assert got.pair is not None and "cage" in got.pair
    assert "transit motion to the approach of action_1" in got.text() and "cage" in got.text()


def test_tool_line_is_straight_with_fixed_orientation(puma) -> None:
    q = np.radians([10.0, -50.0, 20.0, 5.0, 40.0, -10.0])
    T = craig_fk(puma, q[None])[0]
    scene = FakeScene(puma, MARGIN)
    res = mo.resolution(puma.dh, puma.tool, MARGIN, 3.0)
    d = -T[:3, 2]
    seg = mo.line_motion(puma, scene.at({}), T, q, d, 2.0, res, MARGIN, "approach", "approach", reverse=True)
    assert isinstance(seg, mo.Segment), seg
    w = seg.waypoints
    assert np.allclose(w[-1], q)  # an approach ends at the end-point
    assert np.abs(np.diff(w, axis=0)).max() <= res + 1e-12
    Ts = craig_fk(puma, w)
    assert np.allclose(Ts[:, :3, :3], T[:3, :3], atol=1e-9)  # orientation fixed
    off = Ts[:, :3, 3] - T[:3, 3]
    along = off @ d
    assert np.allclose(off, np.outer(along, d), atol=1e-8)  # on the line
    assert along[0] == pytest.approx(2.0, abs=1e-9) and along[-1] == pytest.approx(0.0, abs=1e-9)
    assert np.all(np.diff(along) <= 1e-12)  # monotone towards the end-point


def test_tool_line_out_of_reach_fails_with_a_reason(puma) -> None:
    q = np.radians([0.0, -10.0, -90.0, 0.0, 10.0, 0.0])  # nearly stretched out
    T = craig_fk(puma, q[None])[0]
    out = T[:3, 3] - puma.base[:3, 3]
    got = mo.line_motion(puma, FakeScene(puma, MARGIN).at({}), T, q, out, 40.0, math.radians(0.05), MARGIN,
                         "retreat", "retreat from action_1", reverse=False)
    assert isinstance(got, mo.MotionFailure) and "reach" in got.detail


def test_durations_from_velocity_limits() -> None:
    q = np.radians([[0, 0, 0, 0, 0, 0], [10, 0, 0, 0, 0, 0], [10, 20, 0, 0, 0, 0]])
    v = np.radians([10.0, 40.0, 10, 10, 10, 10])
    assert mo.durations(q, v) == pytest.approx(1.0 + 0.5)
    assert mo.durations(q, None) is None


def test_options_are_checked() -> None:
    with pytest.raises(SparValueError, match="planner"):
        mo.MotionOptions(planner="astar")
    with pytest.raises(SparValueError, match="budget"):
        mo.MotionOptions(time_budget_s=0)


def _robot_file(tmp_path: Path, extra: str) -> Path:
    own = [ln for ln in PUMA.read_text().splitlines()
           if not ln.startswith(tuple(k.split(":")[0] + ":" for k in extra.splitlines()))]
    text = "\n".join(own) + "\n" + extra + "\n"  # the test's keys replace the file's own
    p = tmp_path / "arm.yaml"
    p.write_text(text)
    return p


def test_robot_home_and_velocity_limits(tmp_path: Path) -> None:
    r = load_robot(_robot_file(tmp_path, "home: [0, -90, -90, 0, 0, 0]\nvelocity_limits: [90, 90, 90, 180, 180, 180]"))
    assert np.allclose(np.degrees(r.home), [0, -90, -90, 0, 0, 0])
    assert np.allclose(np.degrees(r.velocity_limits), [90, 90, 90, 180, 180, 180])


@pytest.mark.parametrize("extra, key", [
    ("home: [0, 0, 0]", "home"),
    ("home: [0, -90, -90, 0, 0, 999]", "home"),
    ("velocity_limits: [90, 90, 0, 180, 180, 180]", "velocity_limits"),
])
def test_bad_motion_keys_are_one_line(tmp_path: Path, extra: str, key: str) -> None:
    with pytest.raises(KBError) as e:
        load_robot(_robot_file(tmp_path, extra))
    msg = str(e.value)
    assert "\n" not in msg and "arm.yaml" in msg and key in msg


# ---------------------------------------------------------------------- regression plans


def _motion_cells() -> list[Path]:
    """The regression cells that plan motions (problem key ``motion: true``)."""
    import yaml

    return sorted(p for p in (ROOT / "kb" / "problems").glob("*.yaml")
                  if (yaml.safe_load(p.read_text()) or {}).get("motion") is True)


def _frames(robot, q: np.ndarray) -> np.ndarray:
    """World frames 0..6 (n, 7, 4, 4) by Craig's link transform written out (not the package's FK)."""
    from motion_fake import _links

    A = _links(robot.dh, q)
    out = np.empty((len(q), 7, 4, 4))
    out[:, 0] = robot.base
    for i in range(6):
        out[:, i + 1] = out[:, i] @ A[:, i]
    return out


def _lowest(robot, F: np.ndarray) -> tuple[np.ndarray, list[str]]:
    """Per row, the lowest height of each link shape (exact: a capsule's lowest end less its
    radius, a cylinder's lowest rim point, a box's lowest corner), and the shapes' names."""
    lows, names = [], []
    for s in robot.links:
        if s.frame == 0:
            continue
        R, t = F[:, s.frame, :3, :3], F[:, s.frame, :3, 3]
        if s.kind == "box":
            c = np.array([[x, y, z] for x in (s.a[0], s.b[0]) for y in (s.a[1], s.b[1]) for z in (s.a[2], s.b[2])])
            z = np.einsum("nj,kj->nk", R[:, 2, :], c) + t[:, 2:3]
            lows.append(z.min(axis=1))
        else:
            za = R[:, 2, :] @ s.a + t[:, 2]
            zb = R[:, 2, :] @ s.b + t[:, 2]
            if s.kind == "capsule":
                lows.append(np.minimum(za, zb) - s.radius)
            else:
                u = (s.b - s.a) / max(np.linalg.norm(s.b - s.a), 1e-12)
                uz = R[:, 2, :] @ u
                lows.append(np.minimum(za, zb) - s.radius * np.sqrt(np.clip(1 - uz ** 2, 0, 1)))
        names.append(s.name)
    return np.array(lows).T, names


def _axis_points(robot, F: np.ndarray) -> np.ndarray:
    """(n, m, 3) points on the links' axes (capsules, cylinders) and the tool point."""
    pts = []
    for s in robot.links:
        if s.frame == 0 or s.kind == "box":
            continue
        for t in np.linspace(0, 1, 5):
            p = s.a * (1 - t) + s.b * t
            pts.append(np.einsum("nij,j->ni", F[:, s.frame, :3, :3], p) + F[:, s.frame, :3, 3])
    pts.append((F[:, 6] @ robot.tool)[:, :3, 3])
    return np.stack(pts, axis=1)


def _boxes(path: Path) -> list[tuple[str, np.ndarray, np.ndarray]]:
    """The problem file's box obstacles, read from the YAML here (world frame, file unit)."""
    import yaml

    doc = yaml.safe_load(Path(path).read_text())
    return [(o["name"], np.asarray(o["box"]["min"], float), np.asarray(o["box"]["max"], float))
            for o in doc.get("obstacles") or [] if "box" in o]


@pytest.fixture(scope="module")
def motion_plans():
    from spar_py import Planner

    # and the paper's cell, planned here with motions (its file does not ask), and the arm on its
    # second base, whose put-down is at the edge of reach (the placement must leave its retreat reachable)
    pl = Planner(motion=True)
    cells = _motion_cells() + [ROOT / "kb" / "problems" / f"{n}.yaml" for n in ("peg_in_block", "second_base")]
    return [(p, pl.load_problem(p), pl.plan(p)) for p in cells]


@pytest.mark.slow
def test_every_path_of_every_regression_plan(motion_plans) -> None:
    """Every path of every regression plan that plans motions, checked on its own: consecutive
    waypoints within path_resolution_deg in every joint, joint limits, the paths' ends equal
    to the steps' joints and to each other, home at both ends, and every waypoint clear of the
    table (each link shape's exact lowest point above z = 0) and of the obstacle boxes (the
    links' axes and the tool point outside them), computed here, not by world/collision/scene.py."""
    planned = [(path, cell, plan) for path, cell, plan in motion_plans if plan.ok]
    assert {"wall_detour", "peg_in_block", "second_base"} <= {Path(p).stem for p, _, _ in planned}
    for path, cell, plan in planned:
        inst = plan.instance
        m = inst["motion"]
        res = m["path_resolution_deg"]
        home = np.asarray(m["home_deg"])
        robot = cell.robot
        lo, hi = np.degrees(robot.limits[:, 0]), np.degrees(robot.limits[:, 1])
        prev = home
        chain = []
        for st in inst["steps"]:
            if st.get("path") is None:
                continue
            p, a, r = (np.asarray(st[k]) for k in ("path", "approach", "retreat"))
            assert np.allclose(p[0], prev, atol=2e-4), (path, st["id"])
            assert np.allclose(p[-1], a[0], atol=2e-4) and np.allclose(a[-1], st["joints_deg"], atol=2e-4)
            assert np.allclose(r[0], st["joints_deg"], atol=2e-4)
            chain += [p, a, r]
            prev = r[-1]
        back = np.asarray(m["home_path"])
        assert np.allclose(back[0], prev, atol=2e-4) and np.allclose(back[-1], home, atol=2e-4)
        chain.append(back)
        for w in chain:
            assert np.abs(np.diff(w, axis=0)).max(initial=0.0) <= res + 2e-4, path
            assert np.all((w >= lo - 1e-6) & (w <= hi + 1e-6)), path
            F = _frames(robot, np.radians(w))
            low, names = _lowest(robot, F)
            assert low.min() > 0.0, (path, names[int(low.min(axis=0).argmin())])
            pts = _axis_points(robot, F)
            for name, blo, bhi in _boxes(path):
                assert not np.all((pts >= blo) & (pts <= bhi), axis=-1).any(), (path, name)


@pytest.mark.slow
def test_enclosed_part_has_no_plan_and_names_the_enclosure(motion_plans) -> None:
    """The part in a box whose lid's hole passes the gripper's mount but not the gripper: the
    top grasp's end-point is clear (it is not among the end-point refusals), no motion reaches
    it, and the reason names that motion (the approach to the pickup) and a gripper body and
    a lid slab as the pair that blocks it."""
    got = {Path(p).stem: plan for p, _, plan in motion_plans}
    plan = got["enclosed_part"]
    assert not plan.ok
    assert not any("p1G10" in t for t in plan.reason.get("collisions") or [])  # its end-point is clear
    fails = [f for f in plan.reason.get("motion_failures") or [] if "pickup(peg, p1G10)" in f["motion"]]
    assert fails, plan.reason
    f = fails[0]
    assert f["motion"].startswith("approach to ")
    pair = set(f["pair"])
    assert pair & {"palm", "finger_l", "finger_r"} and pair & {"lid_w", "lid_e", "lid_n", "lid_s"}, f
    assert "lid_" in f["text"] and "approach" in f["text"]


@pytest.mark.slow
def test_animation_replays_the_motions(motion_plans, tmp_path: Path) -> None:
    from PIL import Image

    from spar_py.pictures.animate import frames_of, write_animation

    path, cell, plan = next(x for x in motion_plans if Path(x[0]).stem == "wall_detour")
    frames = frames_of(cell, plan, max_frames=6)
    assert len(frames) == 6 and all(f.frames is not None for f in frames)
    assert np.allclose(np.degrees(frames[0].q), plan.instance["motion"]["home_deg"], atol=1e-3)
    gif = write_animation(cell, plan, tmp_path / "plan.gif", max_frames=4)
    with Image.open(gif) as im:
        assert im.n_frames == 4


@pytest.mark.slow
def test_animation_needs_motions(motion_plans) -> None:
    from spar_py.pictures.animate import frames_of
    from spar_py.planning.planner import Plan

    _, cell, plan = next(x for x in motion_plans if Path(x[0]).stem == "wall_detour")
    doc = plan.to_json()
    doc["instance"] = {**doc["instance"], "motion": None}
    with pytest.raises(SparValueError, match="no-motion"):
        frames_of(cell, Plan.from_json(doc))


@pytest.mark.slow
def test_certified_segments_agree_with_checking_every_waypoint() -> None:
    """certify (clearance bounds, bisection) says a segment is clear exactly when
    SceneState.check finds every waypoint at the resolution clear, and a blocked index it
    names is a waypoint the check refuses. Segments of the wall cell: through a blocked
    configuration (the arm in the table, the wall or a part) with both ends just clear of it,
    so only the interior decides, and random short segments with clear ends."""
    from spar_py import Planner

    cell = Planner(motion=True).load_problem(ROOT / "kb" / "problems" / "wall_detour.yaml")
    scene = CellCache(cell).scene()
    state = scene.at({p.obj: np.asarray(p.T, float) for p in cell.positions.values()})
    res = mo.resolution(cell.robot.dh, cell.robot.tool, scene.margin, mo.extent(cell))
    rng = np.random.default_rng(7)
    lo, hi = cell.robot.limits[:, 0], cell.robot.limits[:, 1]
    segments = []
    t = np.linspace(-1.0, 1.0, 201)
    while len(segments) < 12:  # grazing chords: the line through a blocked q, shifted until nearly clear
        q = rng.uniform(lo, hi)
        if state.clear(q[None])[0]:
            continue
        u, v = rng.normal(size=6), rng.normal(size=6)
        u /= np.linalg.norm(u)
        v -= (v @ u) * u
        v /= np.linalg.norm(v)
        last = None
        for shift in np.arange(0.0, 1.0, 0.02):
            line = q + shift * v + np.outer(t, u)
            if np.any((line < lo) | (line > hi)):
                break
            ok = state.clear(line)
            if ok.all():
                break
            last = (line, ok)
        if last is None or not last[1][0] or not last[1][-1]:
            continue
        line, ok = last
        segments.append([line[0], line[-1]])
    while len(segments) < 28:
        a = rng.uniform(lo, hi)
        b = np.clip(a + rng.normal(0, 0.3, 6), lo, hi)
        if state.clear(np.array([a, b])).all():
            segments.append([a, b])
    verdicts = []
    for a, b in segments:
        w = mo.densify(np.array([a, b]), res)
        every = state.clear(w)
        k, pair = mo.certify(state, w)
        assert (k < 0) == bool(every.all())
        if k >= 0:
            assert not every[k] and pair is not None
        verdicts.append(k < 0)
    assert sum(verdicts) >= 8 and len(verdicts) - sum(verdicts) >= 6  # both answers exercised


@pytest.mark.slow
def test_animation_draws_the_link_shapes(motion_plans) -> None:
    """The animation's link geometry is each robot-file shape where the test's own Craig FK
    puts it: every drawn vertex of a capsule within its radius of the capsule's axis (and
    the radius reached), every box corner the robot file's corner moved by that frame."""
    from spar_py.pictures.animate import arm_faces

    _, cell, _ = next(x for x in motion_plans if Path(x[0]).stem == "wall_detour")
    robot = cell.robot
    q = np.radians([20.0, -70.0, 30.0, 10.0, 40.0, -20.0])
    F = _frames(robot, q[None])[0]
    faces = dict(arm_faces(cell, q))
    assert {s.name for s in robot.links} | {"palm", "finger_l", "finger_r"} <= set(faces)
    for s in robot.links:
        pts = np.concatenate(faces[s.name])
        a = F[s.frame, :3, :3] @ s.a + F[s.frame, :3, 3]
        b = F[s.frame, :3, :3] @ s.b + F[s.frame, :3, 3]
        if s.kind == "capsule":
            u = b - a
            t = np.clip((pts - a) @ u / max(u @ u, 1e-12), 0, 1) if u @ u > 0 else np.zeros(len(pts))
            d = np.linalg.norm(pts - (a + t[:, None] * u), axis=1)
            assert d.max() <= s.radius * (1 + 1e-9) and d.max() >= 0.95 * s.radius, s.name
        elif s.kind == "box":
            corners = np.array([[x, y, z] for x in (s.a[0], s.b[0]) for y in (s.a[1], s.b[1])
                                for z in (s.a[2], s.b[2])]) @ F[s.frame, :3, :3].T + F[s.frame, :3, 3]
            assert all(np.isclose(np.linalg.norm(pts - c, axis=1).min(), 0, atol=1e-9) for c in corners), s.name


@pytest.mark.slow
def test_cli_animate_writes_the_gif(tmp_path: Path, capsys) -> None:
    """`spar plan CELL --animate FILE.gif` writes a GIF of several frames (and nothing else
    is needed on the command line: --animate plans the motions)."""
    from PIL import Image

    from spar_py.app import cli

    gif = tmp_path / "out" / "wall.gif"
    with pytest.raises(SystemExit) as e:
        cli.main(["plan", str(ROOT / "kb" / "problems" / "wall_detour.yaml"), "--animate", str(gif)])
    assert e.value.code == 0
    with Image.open(gif) as im:
        assert im.n_frames > 10


@pytest.mark.slow
def test_durations_of_regression_plans_from_the_robot_file(motion_plans) -> None:
    """Every arm step of every regression plan with motions has a duration: its path,
    approach and retreat at the robot file's velocity_limits (read from the YAML here), each
    waypoint interval at its slowest joint's pace; the plan's total is their sum plus home."""
    import yaml

    for path, cell, plan in motion_plans:
        if not plan.ok:
            continue
        robot_file = ROOT / "kb" / "robots" / f"{cell.robot.name}.yaml"  # the cell's robot file (name = stem)
        doc = yaml.safe_load(robot_file.read_text())
        assert doc["name"] == cell.robot.name
        v = np.asarray(doc["velocity_limits"], float)  # deg/s

        def own(w) -> float:
            w = np.asarray(w or [], float).reshape(-1, 6)
            return float((np.abs(np.diff(w, axis=0)) / v).max(axis=1, initial=0.0).sum()) if len(w) > 1 else 0.0

        total = 0.0
        for st in plan.instance["steps"]:
            if st.get("path") is None:
                continue
            want = sum(own(st[k]) for k in ("path", "approach", "retreat"))
            assert st["duration_s"] is not None and st["duration_s"] == pytest.approx(want, rel=1e-3, abs=1e-3)
            total += want
        total += own(plan.instance["motion"]["home_path"])
        assert plan.instance["motion"]["duration_s"] == pytest.approx(total, rel=1e-3, abs=1e-3)
        assert total > 0.5  # seconds: a real plan's motions take time


def test_body_reach_bounds_how_far_a_body_moves(puma) -> None:
    """body_reach (what certify's rates are made of): a point within ``radius`` of frame f's
    origin moves by at most sum_i R_i |dq_i| when the joints move by dq, on random
    configurations and steps (the test's own Craig FK), and the bound is not loose by more
    than a few times for the tool frame."""
    rng = np.random.default_rng(3)
    q = rng.uniform(puma.limits[:, 0], puma.limits[:, 1], size=(200, 6))
    dq = rng.normal(0, 0.02, size=q.shape)
    F0, F1 = _frames(puma, q), _frames(puma, q + dq)
    ratios = []
    for frame in (2, 3, 5, 6, 7):
        radius = 4.0
        R = mo.body_reach(puma.dh, puma.tool, frame, radius)
        assert np.all(R[min(frame, 6):] == 0)  # joints past the frame do not move it
        off = rng.normal(size=(200, 3))
        off *= radius * rng.uniform(0, 1, (200, 1)) / np.linalg.norm(off, axis=1, keepdims=True)
        if frame == 7:
            T0, T1 = F0[:, 6] @ puma.tool, F1[:, 6] @ puma.tool
        else:
            T0, T1 = F0[:, frame], F1[:, frame]
        p0 = np.einsum("nij,nj->ni", T0[:, :3, :3], off) + T0[:, :3, 3]
        p1 = np.einsum("nij,nj->ni", T1[:, :3, :3], off) + T1[:, :3, 3]
        moved = np.linalg.norm(p1 - p0, axis=1)
        bound = np.abs(dq) @ R
        assert np.all(moved <= bound * (1 + 1e-9)), frame
        ratios.append((moved / bound).max())
    assert ratios[-1] > 0.2  # the tool's bound is within a factor 5 of the worst move seen


def test_certify_keeps_what_it_learns_in_the_motion_memo_not_on_the_state() -> None:
    """certify's rates and its "some row is clear" live in the motion's CertifyMemo (one per
    scene state), not stored behind the state's back: the state's attributes are the same
    after certify as before, a memo passed in is filled and gives the same verdicts when
    reused, and a memo of another state is refused."""
    from spar_py import Planner

    cell = Planner(motion=True).load_problem(ROOT / "kb" / "problems" / "wall_detour.yaml")
    scene = CellCache(cell).scene()
    parts = {p.obj: np.asarray(p.T, float) for p in cell.positions.values()}
    state = scene.at(parts)
    res = mo.resolution(cell.robot.dh, cell.robot.tool, scene.margin, mo.extent(cell))
    rng = np.random.default_rng(3)
    lo, hi = cell.robot.limits[:, 0], cell.robot.limits[:, 1]
    segs = []
    while len(segs) < 6:
        a = rng.uniform(lo, hi)
        b = np.clip(a + rng.normal(0, 0.2, 6), lo, hi)
        if state.clear(np.array([a, b])).all():
            segs.append(mo.densify(np.array([a, b]), res))
    before = set(vars(state))
    fresh = [mo.certify(state, w)[0] for w in segs]
    assert set(vars(state)) == before
    memo = mo.CertifyMemo(state)
    assert [mo.certify(state, w, memo)[0] for w in segs] == fresh
    assert memo.rates is not None and memo.some_clear
    assert [mo.certify(state, w, memo)[0] for w in segs] == fresh
    assert set(vars(state)) == before
    with pytest.raises(ValueError, match="another scene state"):
        mo.certify(scene.at(parts), segs[0], memo)


@pytest.mark.parametrize("robot_file", ["puma762.yaml", "ur5e.yaml"])
def test_the_fast_line_walk_is_the_exact_nearest_previous_walk(robot_file: str, monkeypatch) -> None:
    """_walk (the tool lines' IK continuity, branch choice by integer lookups) returns exactly
    what the point-by-point nearest-previous rule (_walk_exact) returns, bit for bit, on random
    tool lines from random configurations (some with the wrist or elbow nearly straight, where
    branches meet), sampled densely and coarsely; and it walks point by point on few of them."""
    from spar_py.world.reach.workspace import wrist_above_table

    robot = load_robot(ROOT / "kb" / "robots" / robot_file, "in")
    rng = np.random.default_rng(17)
    exact_lengths: list[int] = []
    real_exact = mo._walk_exact

    def counted(Q, ok, q0, limits):
        exact_lengths.append(len(Q))
        return real_exact(Q, ok, q0, limits)

    cases = by_point = 0
    for k in range(60):
        q0 = rng.uniform(robot.limits[:, 0], robot.limits[:, 1])
        if k % 3 == 1:
            q0[4] = rng.normal(0, 1e-3)  # wrist nearly straight
        if k % 3 == 2:
            q0[2] = rng.normal(0, 1e-3) + (-math.pi / 2 if robot_file.startswith("puma") else 0.0)
        T0 = robot.fk(q0)
        d = rng.normal(size=3)
        d /= np.linalg.norm(d)
        s = np.linspace(0.0, 1.0, int(rng.choice([5, 50, 400])))
        T = np.repeat(T0[None], len(s), axis=0)
        T[:, :3, 3] += np.outer(s * rng.uniform(0.5, 4.0), d)
        Q, ok = robot.ik_batch(T)
        ok = ok & wrist_above_table(robot, T)[:, None]
        monkeypatch.setattr(mo, "_walk_exact", counted)
        exact_lengths.clear()
        fast = mo._walk(Q, ok, q0, robot.limits)
        walked = bool(exact_lengths)
        monkeypatch.setattr(mo, "_walk_exact", real_exact)
        ref = real_exact(Q, ok, q0, robot.limits)
        assert (fast is None) == (ref is None), k
        if ref is not None:
            assert np.array_equal(fast, ref), (k, np.abs(fast - ref).max())
            cases += 1
            by_point += walked
    assert cases >= 20
    # the fast path (no point-by-point walk) on most lines that exist
    assert by_point <= cases // 4, (by_point, cases)


def test_subdivide_is_linspace_per_interval() -> None:
    """The tool lines' vectorised subdivision gives linspace's values bit for bit."""
    rng = np.random.default_rng(4)
    for _ in range(50):
        s = np.concatenate([[0.0], np.sort(rng.uniform(0, 1, rng.integers(1, 30))), [1.0]])
        k = rng.integers(1, 40, len(s) - 1)
        k[rng.uniform(size=len(k)) < 0.3] = 1
        ref = np.concatenate([np.linspace(s[i], s[i + 1], k[i] + 1)[:-1] for i in range(len(k))] + [s[-1:]])
        assert np.array_equal(mo._subdivide(s, k), ref)


@pytest.mark.parametrize("kind", ["pickup", "putdown", "assemble"])
def test_line_ends_are_where_the_tool_lines_end(kind: str) -> None:
    """line_ends (what phase 2's placements ask the arm to reach) in the world: the far ends of
    the lines the motions take (module doc), written out here: a pickup approaches along the
    tool's z and lifts the part straight up; a put-down sets it down from straight above and
    backs off along tool z; an assemble inserts along V_a and backs off."""
    from spar_py.core.geometry import rotz

    rng = np.random.default_rng(3)

    def rotation() -> np.ndarray:
        Q = np.linalg.qr(rng.normal(size=(3, 3)))[0]
        return Q if np.linalg.det(Q) > 0 else -Q

    R_pose, X = np.eye(4), np.eye(4)
    R_pose[:3, :3], X[:3, :3] = rotation(), rotation()
    X[:3, 3] = rng.normal(size=3)
    v_obj = rng.normal(size=3)
    L = 2.5
    up_obj = R_pose[:3, :3].T @ np.array([0.0, 0.0, 1.0])
    ends = mo.line_ends(kind, X, up_obj, L, v_obj if kind == "assemble" else None)
    for yaw in (0.0, 1.1, -2.7):  # any placement of the pose: a turn about world z and a shift
        T_O = rotz(yaw) @ R_pose
        T_O[:3, 3] = (rng.normal(), rng.normal(), 1.5)
        T = T_O @ X
        z, up = T[:3, 2], np.array([0.0, 0.0, 1.0])
        insert = T_O[:3, :3] @ v_obj / np.linalg.norm(v_obj)
        want = {"pickup": (T[:3, 3] - L * z, T[:3, 3] + L * up), "putdown": (T[:3, 3] + L * up, T[:3, 3] - L * z),
                "assemble": (T[:3, 3] - L * insert, T[:3, 3] - L * z)}[kind]
        for E, p in zip(ends, want):
            W = T_O @ E
            assert np.allclose(W[:3, :3], T[:3, :3]) and np.allclose(W[:3, 3], p), (kind, yaw)
