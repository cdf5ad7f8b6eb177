"""world/robot/ik/numeric.py via Robot: the multi-start DLS fallback on arms outside both closed-form families.

The arm of issue 17: a copy of the PUMA 762 with d5 = 95 mm (joint 5 offset along its axis:
no spherical wrist, not the UR's structure either). Poses come from Craig's FK written out
here (eq. 3.6), not from the code under test.
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from spar_py.core.geometry import rotx, trans
from spar_py.kb import load_robot
from spar_py.world.robot.model import Robot
from craig_reference import craig_fk
from paths import ROOT

PUMA = ROOT / "kb" / "robots" / "puma762.yaml"
TWO_PI = 2 * math.pi


@pytest.fixture(scope="module")
def offset_puma(tmp_path_factory: pytest.TempPathFactory) -> Robot:
    text = PUMA.read_text()
    old = "  - {alpha: -90, a: 0,   d: 600, offset: 0}   # 4 wrist roll\n  - {alpha: 90,  a: 0,   d: 0,"
    assert old in text
    path = tmp_path_factory.mktemp("robots") / "puma_d5.yaml"
    path.write_text(text.replace(old, old.replace("d: 0,", "d: 95,")))
    return load_robot(path)


def test_offset_wrist_gets_the_numeric_solver_and_says_why(offset_puma: Robot) -> None:
    assert offset_puma.dh[4, 2] == 95.0
    assert offset_puma.solver_name == "numeric" and not offset_puma.solver.complete
    assert "d_5 (dh[4].d) = 95 mm" in offset_puma.not_closed_form["puma"]
    assert "alpha_1" in offset_puma.not_closed_form["ur"]


def test_numeric_round_trip(offset_puma: Robot) -> None:
    r = offset_puma
    q = np.random.default_rng(0).uniform(r.limits[:, 0], r.limits[:, 1], size=(300, 6))
    T = craig_fk(r, q)
    Q, ok = r.ik_batch(T)
    assert Q.shape == (300, r.n_candidates, 6)
    # every solution returned is one: in limits and reaching the pose to 1e-9 mm
    sols, which = Q[ok], np.nonzero(ok)[0]
    assert r.in_limits(sols).all()
    assert np.abs(craig_fk(r, sols) - T[which]).max() < 1e-9
    # not complete, but a pose the arm reaches almost always gets a solution, and usually q's own
    assert ok.any(axis=1).mean() > 0.97
    d = np.abs(np.remainder(Q - q[:, None, :] + np.pi, TWO_PI) - np.pi).max(axis=2)
    assert ((d < 1e-6) & ok).any(axis=1).mean() > 0.6
    # distinct modulo full turns: no configuration is listed twice
    for i in range(len(q)):
        rows = np.remainder(Q[i][ok[i]], TWO_PI)
        diff = np.abs(rows[:, None] - rows[None])
        diff = np.minimum(diff, TWO_PI - diff).max(axis=2)
        assert (diff + np.eye(len(rows)) * 10 > 1e-6).all()
    # several branches per pose, as an arm of this kind has (shoulder x elbow x wrist)
    assert ok.sum(axis=1).mean() > 3


def test_numeric_out_of_reach_and_single_agrees(offset_puma: Robot) -> None:
    r = offset_puma
    far = trans(5000, 0, 0) @ rotx(math.pi)
    assert r.ik(far).shape == (0, 6)
    q = np.radians([10, -60, -30, 200, 40, 100])
    T = craig_fk(r, q[None])[0]
    rows = r.ik(T)
    assert len(rows) and r.in_limits(rows).all()
    assert np.abs(craig_fk(r, rows) - T).max() < 1e-9
    assert (np.abs(rows - q).max(axis=1) < 1e-6).any()  # multi-turn representations listed too
    assert np.array_equal(r.reachable_mask(np.stack([far, T])), [False, True])


def test_numeric_is_reproducible(offset_puma: Robot) -> None:
    r = offset_puma
    T = craig_fk(r, np.random.default_rng(1).uniform(r.limits[:, 0], r.limits[:, 1], size=(20, 6)))
    a, b = r.ik_batch(T), r.ik_batch(T)
    assert np.array_equal(a[1], b[1]) and np.array_equal(a[0][a[1]], b[0][b[1]])


def test_forcing_a_family_the_table_lacks_is_a_one_line_error(tmp_path: Path) -> None:
    from spar_py.core.errors import KBError

    path = tmp_path / "puma_as_ur.yaml"
    path.write_text(PUMA.read_text().replace("name: puma762", "name: puma762\nik: ur"))
    with pytest.raises(KBError) as exc:
        load_robot(path, unit="in")
    msg = str(exc.value)
    assert "\n" not in msg and str(path) in msg and ": dh: expected a UR-family arm" in msg
    assert "alpha_1 (dh[1].alpha) = -90 deg" in msg
    # ik: numeric forces the fallback on an arm that has a closed form
    path.write_text(PUMA.read_text().replace("name: puma762", "name: puma762\nik: numeric"))
    assert load_robot(path).solver_name == "numeric"
