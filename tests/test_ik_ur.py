"""world/robot/ik/ur.py via Robot: the UR5e and UR10e closed form (Hawkins 2013): round trips, singularities.

Poses are computed with an FK written here straight from Universal Robots' published
standard-DH tables (T = prod rotz(theta_i) transz(d_i) transx(a_i) rotx(alpha_i)), not
from the robot files, their conversion to Craig's table, or the code under test.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from spar_py.kb import load_robot
from spar_py.world.robot.model import Robot

from paths import ROOT

TWO_PI = 2 * math.pi
# Universal Robots' published standard DH (mm, deg): (alpha_i, a_i, d_i) per joint
PUBLISHED = {
    "ur5e": [(90, 0, 162.5), (0, -425, 0), (0, -392.2, 0), (90, 0, 133.3), (-90, 0, 99.7), (0, 0, 99.6)],
    "ur10e": [(90, 0, 180.7), (0, -612.7, 0), (0, -571.55, 0), (90, 0, 174.15), (-90, 0, 119.85), (0, 0, 116.55)],
}
TCP = 150.0  # mm: the files' tool, along the flange z


def std_fk(name: str, q: np.ndarray) -> np.ndarray:
    """World tool poses (n, 4, 4) mm of the published arm at q (n, 6) rad, base at the world origin."""
    q = np.atleast_2d(q)
    T = np.broadcast_to(np.eye(4), (len(q), 4, 4)).copy()
    for i, (alpha, a, d) in enumerate(PUBLISHED[name]):
        ct, st = np.cos(q[:, i]), np.sin(q[:, i])
        ca, sa = math.cos(math.radians(alpha)), math.sin(math.radians(alpha))
        A = np.zeros((len(q), 4, 4))  # rotz(theta) transz(d) transx(a) rotx(alpha), written out
        A[:, 0, 0], A[:, 0, 1], A[:, 0, 2], A[:, 0, 3] = ct, -st * ca, st * sa, a * ct
        A[:, 1, 0], A[:, 1, 1], A[:, 1, 2], A[:, 1, 3] = st, ct * ca, -ct * sa, a * st
        A[:, 2, 1], A[:, 2, 2], A[:, 2, 3] = sa, ca, d
        A[:, 3, 3] = 1.0
        T = T @ A
    tool = np.eye(4)
    tool[2, 3] = TCP
    return T @ tool


@pytest.fixture(scope="module", params=["ur5e", "ur10e"])
def ur(request: pytest.FixtureRequest) -> Robot:
    return load_robot(ROOT / "kb" / "robots" / f"{request.param}.yaml")


def random_q(robot: Robot, n: int, seed: int = 0) -> np.ndarray:
    return np.random.default_rng(seed).uniform(robot.limits[:, 0], robot.limits[:, 1], size=(n, 6))


def check_round_trip(robot: Robot, q: np.ndarray, tol_len: float = 1e-9, tol_q: float = 1e-6,
                     exact: int = 200) -> None:
    """fk(ik(fk(q))) = fk(q) to tol_len (mm) for every returned solution, all in limits, q among
    them (modulo full turns in ik_batch's branches; exactly in ik()'s rows for the first ``exact``)."""
    T = std_fk(robot.name, q)
    Q, ok = robot.ik_batch(T)
    assert Q.shape == (len(q), 8, 6) and ok.shape == (len(q), 8)
    assert ok.any(axis=1).all()
    sols, which = Q[ok], np.nonzero(ok)[0]
    assert robot.in_limits(sols).all()
    err = np.abs(std_fk(robot.name, sols) - T[which]).max(axis=(1, 2))
    assert err.max() < tol_len, f"worst |fk(ik(T)) - T|: {err.max()} mm"
    d = np.abs(np.remainder(Q - q[:, None, :] + np.pi, TWO_PI) - np.pi).max(axis=2)
    found = ((d < tol_q) & ok).any(axis=1)
    assert found.all(), f"{(~found).sum()} configurations not recovered, e.g. {q[~found][:2]}"
    for qi, Ti in zip(q[:exact], T[:exact]):
        rows = robot.ik(Ti)
        assert robot.in_limits(rows).all()
        assert (np.abs(rows - qi).max(axis=1) < tol_q).any()
        assert len(np.unique(np.round(rows, 9), axis=0)) == len(rows)  # no row twice


def test_the_files_are_the_published_arms(ur: Robot) -> None:
    assert ur.solver_name == "closed-form ur"
    assert np.allclose(np.degrees(ur.limits), [[-360, 360]] * 6)
    q = random_q(ur, 200, seed=5)
    assert np.abs(ur.fk_batch(q) - std_fk(ur.name, q)).max() < 1e-9
    for qi in q[:20]:  # frames: Craig's, the tool last
        F = ur.frames(qi)
        assert np.allclose(F[7], std_fk(ur.name, qi)[0], atol=1e-9)


def test_round_trip_10000_random(ur: Robot) -> None:
    check_round_trip(ur, random_q(ur, 10_000))


def test_ur_lists_every_turn_representation(ur: Robot) -> None:
    # +-360 deg on every joint: a generic pose has 8 branches x 2^6 representations
    q = np.radians([10, -60, 80, -100, 40, 100])
    rows = ur.ik(std_fk(ur.name, q)[0])
    assert len(rows) == 8 * 64
    for other in (q, q - TWO_PI * (q > 0), q + TWO_PI * (q < 0)):  # each the same arm, in limits
        assert np.any(np.abs(rows - other).max(axis=1) < 1e-9)
    # a joint at exactly -360 deg has three representations inside [-360, 360]: -360, 0 and 360
    q2 = q.copy()
    q2[5] = -TWO_PI
    rows = ur.ik(std_fk(ur.name, q2)[0])
    assert {round(v, 6) for v in np.degrees(rows[:, 5]) if abs(abs(v) - 360) < 1e-6 or abs(v) < 1e-6} == \
        {-360.0, 0.0, 360.0}


def near(base: np.ndarray, joint: int, values: list[float], n: int, seed: int) -> np.ndarray:
    """n random in-limit configurations per value, with ``joint`` set to each value (rad)."""
    rng = np.random.default_rng(seed)
    out = []
    for v in values:
        q = rng.uniform(-TWO_PI, TWO_PI, size=(n, 6))
        q[:, joint] = v
        out.append(q)
    return np.vstack(out)


def test_near_wrist_singularity(ur: Robot) -> None:
    # theta5 near 0 or pi: axis 6 nearly parallel to axes 2, 3, 4. The pose still comes back to
    # 1e-9 mm; the joints only to ~eps / |sin theta5| (theta4 and theta6 trade off there)
    vals = [s * e + c for c in (0.0, math.pi) for e in (1e-7, 1e-6, 1e-5, 1e-4) for s in (1, -1)]
    check_round_trip(ur, near(np.zeros(6), 4, vals, 100, seed=1), tol_q=1e-4)


def test_near_elbow_singularity(ur: Robot) -> None:
    # theta3 near 0 (full stretch) or pi (folded back; still a pose the arm reaches)
    vals = [s * e + c for c in (0.0, math.pi) for e in (1e-7, 1e-6, 1e-5, 1e-4) for s in (1, -1)]
    check_round_trip(ur, near(np.zeros(6), 2, vals, 100, seed=2), tol_len=1e-8, tol_q=1e-5)


def shoulder_singular_q(robot: Robot, n: int, seed: int) -> np.ndarray:
    """Configurations whose wrist point lies at distance |D| from axis 1 (the two theta1 roots meet),
    found by bisection on q2 of the published FK's wrist point (independent of the solver): the
    wrist point p5 is always |D| off axis 1 sideways, so r = |D| where its component along x1 =
    (cos q1, sin q1, 0), the arm's reach direction, changes sign."""
    d6 = PUBLISHED[robot.name][5][2]
    rng = np.random.default_rng(seed)
    out = []
    while len(out) < n:
        q = rng.uniform(-math.pi, math.pi, size=6)

        def excess(q2: float) -> float:
            qq = q.copy()
            qq[1] = q2
            T = std_fk(robot.name, qq)[0]
            p5 = T[:3, 3] - (TCP + d6) * T[:3, 2]
            return p5[0] * math.cos(q[0]) + p5[1] * math.sin(q[0])
        grid = np.linspace(-math.pi, math.pi, 73)
        vals = [excess(g) for g in grid]
        for lo, hi, flo, fhi in zip(grid, grid[1:], vals, vals[1:]):
            if flo * fhi < 0:  # the reach crosses zero: bisect to it
                for _ in range(80):
                    mid = 0.5 * (lo + hi)
                    if (excess(mid) < 0) == (flo < 0):
                        lo = mid
                    else:
                        hi = mid
                q = q.copy()
                q[1] = hi
                out.append(q)
                break
    return np.array(out)


def test_shoulder_singularity(ur: Robot) -> None:
    q = shoulder_singular_q(ur, 40, seed=3)
    check_round_trip(ur, q, tol_len=1e-8, tol_q=1e-5)
    nearby = q.copy()
    nearby[:, 1] += np.tile([1e-6, 1e-4], len(q) // 2)
    check_round_trip(ur, nearby, tol_len=1e-8, tol_q=1e-5)


def test_exactly_wrist_singular_still_solved(ur: Robot) -> None:
    # theta5 = 0: only theta2 + theta3 + theta4 + theta6 is determined; q6 = 0 is the documented choice
    q = np.radians([25, -70, 60, -40, 0, 30])
    T = std_fk(ur.name, q)[0]
    rows = ur.ik(T)
    assert len(rows) and ur.in_limits(rows).all()
    assert np.abs(std_fk(ur.name, rows) - T).max() < 1e-9
    Q, ok = ur.ik_batch(T[None])
    branches = Q[0][ok[0]]
    singular = np.abs(np.sin(branches[:, 4])) < 1e-9  # this shoulder's branches (the other is not singular)
    assert singular.sum() == 2  # one wrist root (the second is the same family) x two elbows
    assert np.allclose(np.cos(branches[singular, 5]), 1.0, atol=1e-12)  # q6 = 0 mod 2 pi
    assert len(np.unique(np.round(rows, 9), axis=0)) == len(rows)


def test_out_of_reach_and_batch_agrees_with_single(ur: Robot) -> None:
    rng = np.random.default_rng(4)
    q = random_q(ur, 60, seed=4)
    T = std_fk(ur.name, q)
    T[::4, :3, 3] += rng.uniform(-1500, 1500, size=(len(T[::4]), 3))  # some out of reach
    T[3, :3, 3] = [3000.0, 0.0, 0.0]
    Q, ok = ur.ik_batch(T)
    assert not ok[3].any()
    assert ur.ik(T[3]).shape == (0, 6)
    assert np.array_equal(ur.reachable_mask(T), ok.any(axis=1))
    for i in range(len(T)):
        rows = ur.ik(T[i])
        assert (len(rows) > 0) == bool(ok[i].any())
        for r in Q[i][ok[i]]:
            assert (np.abs(rows - r).max(axis=1) < 1e-12).any()
        if len(rows):
            assert np.abs(std_fk(ur.name, rows) - T[i]).max() < 1e-9
