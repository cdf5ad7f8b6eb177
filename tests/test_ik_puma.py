"""world/robot/ik/puma.py via Robot: the PUMA 762 table, FK, all closed-form IK solutions, singularities,
batch = single.

The round trips check poses with an FK written here from Craig's link transform (eq. 3.6),
not the code under test."""
from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from spar_py.core.errors import SparValueError
from spar_py.core.geometry import inv, rotx, rotz, rpy, trans
from spar_py.kb import load_robot
from spar_py.world.robot.model import LIMIT_TOL, Robot
from craig_reference import craig_fk
from paths import ROOT

PUMA = ROOT / "kb" / "robots" / "puma762.yaml"
TWO_PI = 2 * math.pi


@pytest.fixture(scope="module")
def puma() -> Robot:
    return load_robot(PUMA)  # millimetres


def random_q(robot: Robot, n: int, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return rng.uniform(robot.limits[:, 0], robot.limits[:, 1], size=(n, 6))


def generic_robot() -> Robot:
    """A PUMA-family table with every constant the closed form must carry: a3, d2 + d3,
    offsets, d1 and d6, a tilted base (alpha0, a0) and a tool with a rotation."""
    deg = math.radians
    dh = [[deg(10), 50.0, 300.0, deg(20)],
          [deg(-90), 0.0, 40.0, deg(-30)],
          [0.0, 430.0, -190.0, deg(15)],
          [deg(-90), 20.0, 430.0, deg(-40)],
          [deg(90), 0.0, 0.0, deg(5)],
          [deg(-90), 0.0, 60.0, deg(90)]]
    limits = [[-deg(170), deg(170)], [-deg(225), deg(45)], [-deg(250), deg(75)],
              [-deg(300), deg(300)], [-deg(120), deg(120)], [-deg(400), deg(400)]]
    return Robot("generic", dh, limits, trans(100, -50, 20) @ rpy(0.1, -0.05, 0.3),
                 trans(10, 5, 120) @ rpy(0.2, 0.1, -0.4), 80.0, "mm")


# ---------------------------------------------------------------- the model (loading: test_kb.py)


def test_post_init_checks_shapes_and_family() -> None:
    with pytest.raises(SparValueError, match="dh must be"):
        Robot("r", np.zeros((5, 4)), np.zeros((6, 2)), np.eye(4), np.eye(4), 1.0, "mm")
    with pytest.raises(SparValueError, match="lo <= hi"):
        Robot("r", generic_robot().dh, [[1, 0]] * 6, np.eye(4), np.eye(4), 1.0, "mm")
    assert generic_robot().solver_name == "closed-form puma"
    # a table outside the PUMA 560 family (and the UR's): the numeric fallback, and why not closed form
    dh = generic_robot().dh.copy()
    dh[4, 0] = 0.3  # a skewed wrist
    odd = Robot("odd", dh, [[-3, 3]] * 6, np.eye(4), np.eye(4), 1.0, "mm")
    assert odd.fk(np.zeros(6)).shape == (4, 4)
    assert odd.solver_name == "numeric"
    assert "alpha_4" in odd.not_closed_form["puma"]
    # two joints about one line is no 6-DOF arm at all
    dh[4, 0] = 0.0
    with pytest.raises(SparValueError, match="joints 4 and 5 turn about the same line"):
        Robot("flat", dh, [[-3, 3]] * 6, np.eye(4), np.eye(4), 1.0, "mm")


# ---------------------------------------------------------------- forward kinematics


def test_fk_at_zero_by_hand(puma: Robot) -> None:
    # q = 0: Craig's wrist centre 0P4 = (c1(a2 c2 + a3 c23 - d4 s23) - d3 s1, ..., -a2 s2 - a3 s23 - d4 c23)
    # = (650, 190, -600) in frame 0, i.e. (650, 190, 0) in the world (frame 0 is 600 mm up).
    # 0R6 = Rx(-90) (from 0R3) Rx(-90) (3R6 = Rx(-90) Rz(0) Rx(90) Rz(0) Rx(-90)) = Rx(180):
    # the tool z points down, so the tool centre is 250 mm below the wrist centre.
    T = puma.fk(np.zeros(6))
    assert np.allclose(T[:3, 3], [650, 190, -250])
    assert np.allclose(T[:3, :3], np.diag([1.0, -1.0, -1.0]))


def test_fk_batch_matches_fk(puma: Robot) -> None:
    q = random_q(puma, 20, seed=1)
    Ts = puma.fk_batch(q)
    for qi, Ti in zip(q, Ts):
        assert np.allclose(puma.fk(qi), Ti, atol=1e-12)
    with pytest.raises(SparValueError):
        puma.fk(np.zeros(5))


@pytest.mark.parametrize("which", ["puma", "generic"])
def test_frames_run_from_the_base_to_the_tool(puma: Robot, which: str) -> None:
    """frames(q): base, frames 1..6 by Craig's link transform one joint at a time, fk(q) last."""
    robot = puma if which == "puma" else generic_robot()
    for q in random_q(robot, 20, seed=7):
        F = robot.frames(q)
        assert F.shape == (8, 4, 4)
        assert np.array_equal(F[0], robot.base)
        assert np.allclose(F[-1], robot.fk(q), atol=1e-9)
        for i, (alpha, a, d, off) in enumerate(robot.dh):  # written out, not fk_batch's code
            want = F[i] @ rotx(alpha) @ trans(a, 0.0, 0.0) @ rotz(q[i] + off) @ trans(0.0, 0.0, d)
            assert np.allclose(F[i + 1], want, atol=1e-9)
        assert np.allclose(F[7], F[6] @ robot.tool, atol=1e-12)
    with pytest.raises(SparValueError, match="frames"):
        robot.frames(np.zeros((1, 6)))


# ---------------------------------------------------------------- inverse kinematics


def check_round_trip(robot: Robot, q: np.ndarray, tol_len: float, exact: int = 300) -> None:
    """Every returned solution is in limits and reproduces fk(q) (Craig's FK written out, above);
    q is among the branches modulo full turns, and exactly among ik()'s rows (first ``exact``)."""
    T = craig_fk(robot, q)
    assert np.abs(T - robot.fk_batch(q)).max() < tol_len
    Q, ok = robot.ik_batch(T)
    assert Q.shape == (len(q), robot.n_candidates, 6) and ok.shape == Q.shape[:2]
    assert robot.n_candidates == 8
    assert ok.any(axis=1).all()
    sols, which = Q[ok], np.nonzero(ok)[0]
    assert robot.in_limits(sols).all()
    err = np.abs(robot.fk_batch(sols) - T[which]).max(axis=(1, 2))
    assert err.max() < tol_len, f"worst fk(ik(T)) - T: {err.max()}"
    d = np.abs(np.remainder(Q - q[:, None, :] + np.pi, TWO_PI) - np.pi).max(axis=2)
    found = ((d < 1e-6) & ok).any(axis=1)
    assert found.all(), f"{(~found).sum()} configurations not recovered, e.g. {q[~found][:3]}"
    # ik() lists every in-limit turn representation, so q matches exactly, not just modulo turns
    for qi, Ti in zip(q[:exact], T[:exact]):
        rows = robot.ik(Ti)
        assert robot.in_limits(rows).all()
        assert (np.abs(rows - qi).max(axis=1) < 1e-6).any()


def test_round_trip_10000_random(puma: Robot) -> None:
    check_round_trip(puma, random_q(puma, 10_000), tol_len=1e-9)  # mm


def test_round_trip_generic_a3_d3_offsets() -> None:
    robot = generic_robot()
    check_round_trip(robot, random_q(robot, 3000, seed=2), tol_len=1e-9)


def test_multi_turn_joints_list_each_representation(puma: Robot) -> None:
    # wrist roll at 200 deg: -160 deg is the same angle and also inside [-266, 266]
    q = np.radians([10, -60, -30, 200, 40, 100])
    sols = puma.ik(puma.fk(q))
    q4s = np.degrees(sols[:, 3])
    assert np.any(np.isclose(q4s, 200)) and np.any(np.isclose(q4s, -160))
    assert np.any(np.isclose(sols, q, atol=1e-9).all(axis=1))


def test_beyond_reach_gives_empty(puma: Robot) -> None:
    far = trans(3000, 0, 600) @ rotx(math.pi)  # 3 m from the waist axis, arm reach is ~1.5 m
    assert puma.ik(far).shape == (0, 6)
    # wrist centre on the waist axis: inside the d3 = 190 mm cylinder no shoulder angle works
    T06 = trans(0, 0, 300)
    T = puma.base @ T06 @ puma.tool
    assert puma.ik(T).shape == (0, 6)
    assert not puma.reachable_mask(np.stack([far, T])).any()


def test_wrist_singular_still_solved(puma: Robot) -> None:
    q = np.radians([25, -70, -20, 40, 0, 30])  # q5 = 0: axes 4 and 6 aligned
    T = puma.fk(q)
    sols = puma.ik(T)
    assert len(sols) > 0
    assert np.abs(puma.fk_batch(sols) - T).max() < 1e-9
    assert puma.in_limits(sols).all()
    same_arm = sols[np.all(np.isclose(sols[:, :3], q[:3], atol=1e-9), axis=1)]
    # the documented choice: q4 = 0, the whole roll on q6 (q4 + q6 = 70 deg, mod 360)
    assert len(same_arm) == 1
    assert same_arm[0, 3] == 0 and abs(same_arm[0, 4]) < 1e-9
    assert math.isclose(math.remainder(same_arm[0, 5] - math.radians(70), TWO_PI), 0, abs_tol=1e-9)


def test_shoulder_singular_still_solved(puma: Robot) -> None:
    # arm straight up (q2 = q3 = -90 deg): r = a2 c2 + a3 c23 - d4 s23 = 0, the two
    # shoulder roots coincide; one copy is returned, and it reproduces the pose
    q = np.radians([30, -90, -90, 10, 50, -20])
    T = puma.fk(q)
    sols = puma.ik(T)
    assert len(sols) > 0 and puma.in_limits(sols).all()
    assert np.abs(puma.fk_batch(sols) - T).max() < 1e-9
    assert len(np.unique(np.round(sols, 9), axis=0)) == len(sols)
    assert np.any(np.isclose(sols, q, atol=1e-7).all(axis=1))


def test_shoulder_singular_without_offset_picks_q1_zero() -> None:
    # d3 = 0: a wrist centre on the z0 axis leaves theta1 free; the documented choice is q1 = 0
    r = generic_robot()
    dh = r.dh.copy()
    dh[1, 2] = dh[2, 2] = 0.0
    robot = Robot("no_offset", dh, r.limits, r.base, r.tool, 80.0, "mm")
    # wrist centre on z0: 0P4 = (c1 R, s1 R, -a2 s2 - a3 s23 - d4 c23) with R = a2 c2 + a3 c23 - d4 s23;
    # theta2 = -90 deg makes c2 = 0, and R = a3 c23 - d4 s23 = 0 for theta23 = atan2(a3, d4) (- pi):
    # theta23 = atan2(a3, d4) - pi = theta2 + theta3 gives theta3 = atan2(a3, d4) - pi/2 (in limits)
    a2, a3, d4 = dh[2, 1], dh[3, 1], dh[3, 2]
    th2, th3 = -math.pi / 2, math.atan2(a3, d4) - math.pi / 2
    assert abs(a2 * math.cos(th2) + a3 * math.cos(th2 + th3) - d4 * math.sin(th2 + th3)) < 1e-9
    q = np.array([0.7, th2 - dh[1, 3], th3 - dh[2, 3], 0.3, 0.8, -0.2])
    T = robot.fk(q)
    sols = robot.ik(T)
    assert len(sols) > 0 and robot.in_limits(sols).all()
    assert np.abs(robot.fk_batch(sols) - T).max() < 1e-9
    assert np.allclose(sols[:, 0], 0.0)


def test_ik_batch_agrees_with_ik_row_for_row(puma: Robot) -> None:
    rng = np.random.default_rng(3)
    T = puma.fk_batch(random_q(puma, 150, seed=3))
    T[::5, :3, 3] += rng.uniform(-900, 900, size=(len(T[::5]), 3))  # some out of reach
    T[7] = trans(3000, 0, 0)
    Q, ok = puma.ik_batch(T)
    for i in range(len(T)):
        single = puma.ik(T[i])
        # ik = the in-limit branches of ik_batch (each row of it exactly), each with its other
        # in-limit turn representations: the same configurations modulo full turns
        assert len(single) >= ok[i].sum()
        for row in Q[i][ok[i]]:
            assert (np.abs(single - row).max(axis=1) < 1e-12).any()
        wrapped = {tuple(np.round(np.remainder(r, TWO_PI), 7) % round(TWO_PI, 7)) for r in single}
        assert wrapped == {tuple(np.round(np.remainder(r, TWO_PI), 7) % round(TWO_PI, 7)) for r in Q[i][ok[i]]}
    assert np.array_equal(puma.reachable_mask(T), ok.any(axis=1))
    assert not ok[7].any()


def test_in_limits_tolerance(puma: Robot) -> None:
    q = puma.limits[:, 1].copy()
    assert puma.in_limits(q)
    assert puma.in_limits(q + 0.5 * LIMIT_TOL)
    assert not puma.in_limits(q + 10 * LIMIT_TOL)
    assert puma.in_limits(np.stack([q, q + 1.0])).tolist() == [True, False]


def test_ik_rejects_bad_input(puma: Robot) -> None:
    with pytest.raises(SparValueError):
        puma.ik(np.eye(3))
    with pytest.raises(SparValueError):
        puma.ik(np.diag([1.0, 1.0, -1.0, 1.0]))  # a reflection is no pose
    with pytest.raises(SparValueError):
        puma.ik_batch(np.eye(4))
    bad = np.full((1, 4, 4), np.nan)
    assert not puma.ik_batch(bad)[1].any()


def test_base_frame_moves_the_workspace(puma: Robot) -> None:
    q = np.radians([10, -50, -40, 20, 30, 40])
    moved = Robot(puma.name, puma.dh, puma.limits, rotz(0.5) @ trans(100, 0, 0) @ puma.base,
                  puma.tool, puma.finger_separation, puma.unit)
    T = moved.fk(q)
    assert np.allclose(inv(rotz(0.5) @ trans(100, 0, 0)) @ T, puma.fk(q))
    assert np.any(np.isclose(moved.ik(T), q, atol=1e-9).all(axis=1))


@settings(max_examples=300, deadline=None, derandomize=True)
@given(st.lists(st.floats(0.0, 1.0, allow_nan=False), min_size=6, max_size=6))
def test_round_trip_property(puma: Robot, u: list[float]) -> None:
    """Hypothesis: for any in-limit q (a point of the limit box), every solution of ik(fk(q))
    is in limits and reaches fk(q), and q is among them unless the wrist is singular."""
    lo, hi = puma.limits[:, 0], puma.limits[:, 1]
    q = lo + np.array(u) * (hi - lo)
    if abs(np.sin(q[4])) > 1e-6:
        check_round_trip(puma, q[None], 1e-9)
        return
    # wrist singular (q5 = 0): only q4 + q6 is determined, so q itself need not be listed;
    # the solutions must still be in limits and reach the pose (test_wrist_singular_still_solved)
    T = puma.fk(q)
    sols = puma.ik(T)
    assert len(sols) and puma.in_limits(sols).all()
    assert np.abs(puma.fk_batch(sols) - T).max() < 1e-9
