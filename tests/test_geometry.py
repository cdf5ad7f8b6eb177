"""geometry.py: transforms, the paper's row form (Figs. 11, 18), Euler angles (Fig. 19), stable poses."""
from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from spar_py.errors import SparValueError
from spar_py.geometry import (
    check_rotation,
    check_transform,
    compose,
    euler_zyz,
    eulerxyz,
    inv,
    is_orthonormal,
    rot,
    rotx,
    roty,
    rotz,
    rpy,
    same_stable_pose,
    tm_rows,
    to_tm_rows,
    trans,
    transl,
    up_vectors,
    yaw_about_world_z,
)

ex, ey, ez = np.eye(3)
angle = st.floats(-2 * math.pi, 2 * math.pi, allow_nan=False)
length = st.floats(-100, 100, allow_nan=False)


def test_rotations_are_right_handed() -> None:
    assert np.allclose(rot(rotz(math.pi / 2)) @ ex, ey)
    assert np.allclose(rot(rotx(math.pi / 2)) @ ey, ez)
    assert np.allclose(rot(roty(math.pi / 2)) @ ez, ex)
    assert np.allclose(transl(trans(1, 2, 3)), [1, 2, 3])


def test_compose_chains_left_to_right() -> None:
    T = compose(trans(1, 0, 0), rotz(math.pi / 2), trans(1, 0, 0))
    # move 1 along x, turn, move 1 along the turned x (= world y)
    assert np.allclose(transl(T), [1, 1, 0])
    assert np.allclose(compose(), np.eye(4))


def test_rpy_is_fixed_axes_xyz() -> None:
    r, p, y = 0.1, -0.2, 0.3
    assert np.allclose(rpy(r, p, y), rotz(y) @ roty(p) @ rotx(r))


@settings(max_examples=50, deadline=None)
@given(angle, angle, angle, length, length, length)
def test_inv_is_closed_form_inverse(a: float, b: float, c: float, x: float, y: float, z: float) -> None:
    T = trans(x, y, z) @ rpy(a, b, c)
    assert np.allclose(inv(T) @ T, np.eye(4), atol=1e-12)
    assert np.allclose(inv(T), np.linalg.inv(T), atol=1e-9)


def test_batches_have_leading_shape() -> None:
    a = np.linspace(0, 1, 5)
    Ts = rotz(a) @ trans(a, 2 * a, 0)
    assert Ts.shape == (5, 4, 4)
    assert np.allclose(Ts[3], rotz(a[3]) @ trans(a[3], 2 * a[3], 0))
    assert np.allclose(inv(Ts) @ Ts, np.eye(4))
    assert eulerxyz(a, a, a, a, a, a).shape == (5, 4, 4)
    assert up_vectors(rot(Ts)).shape == (5, 3)


# ---------------------------------------------------------------- Fig. 19: eulerxyz


def test_eulerxyz_is_trans_then_zyz() -> None:
    X, Y, Z, phi, theta, psi = 1.0, -2.0, 3.0, 0.3, 1.1, -0.7
    T = eulerxyz(X, Y, Z, phi, theta, psi)
    assert np.allclose(T, trans(X, Y, Z) @ rotz(phi) @ roty(theta) @ rotz(psi))
    assert np.allclose(T, trans(X, Y, Z) @ euler_zyz(phi, theta, psi))
    # the tool's approach axis (tool z) in the object frame
    assert np.allclose(T[:3, 2], [math.cos(phi) * math.sin(theta), math.sin(phi) * math.sin(theta), math.cos(theta)])


def test_eulerxyz_fig19_theta_minus_90() -> None:
    # Fig. 19: eulerxyz(8.0, 1.75, 2.0, 0.0, -90.0, 0.0). By hand: rotz(0) = I, and
    # roty(-90 deg) sends z = (0,0,1) to (sin(-90), 0, cos(-90)) = (-1, 0, 0) and
    # x = (1,0,0) to (cos(-90), 0, -sin(-90)) = (0, 0, 1); y stays. So the tool's
    # approach (z) points along the object's -x, the tool x along the object's +z,
    # and the tool centre sits at (8, 1.75, 2) in the object frame.
    T = eulerxyz(8.0, 1.75, 2.0, 0.0, math.radians(-90.0), 0.0)
    assert np.allclose(T[:3, 2], -ex)
    assert np.allclose(T[:3, 0], ez)
    assert np.allclose(T[:3, 1], ey)
    assert np.allclose(T[:3, 3], [8.0, 1.75, 2.0])


def test_eulerxyz_phi_turns_the_approach_about_object_z() -> None:
    # (phi, theta) = (90, 90) deg: roty(90) sends z to +x, then rotz(90) sends +x to +y:
    # the block's grasp p2G1 (90, 90, 180) is commented "approach +y" in kb/objects/block.yaml.
    T = eulerxyz(0, 0, 0, math.radians(90), math.radians(90), math.radians(180))
    assert np.allclose(T[:3, 2], ey)


# ---------------------------------------------------------------- the paper's row form


def test_tm_rows_fig18_is_a_proper_rotation() -> None:
    # Fig. 18: pose(part1, part1_p2, rfaces([5]), ofaces([5,6]), tm([[0,0,1],[1,0,0],[0,1,0],[0,0,0]]))
    rows = [[0, 0, 1], [1, 0, 0], [0, 1, 0], [0, 0, 0]]
    T = tm_rows(rows)
    assert is_orthonormal(T[:3, :3])
    assert np.linalg.det(T[:3, :3]) == pytest.approx(1.0)
    # rows are the images of the object's axes: x -> world z, y -> world x, z -> world y
    assert np.allclose(T[:3, 0], ez) and np.allclose(T[:3, 1], ex) and np.allclose(T[:3, 2], ey)
    assert to_tm_rows(T) == [[0, 0, 1], [1, 0, 0], [0, 1, 0], [0, 0, 0]]
    check_transform(T, "Fig. 18")


def test_tm_rows_fig11_errtm_is_rotz_plus_translation() -> None:
    # Fig. 11: ErrTm = tm([[cos t, sin t, 0], [-sin t, cos t, 0], [0,0,1], [Dx,Dy,Dz]])
    t, dx, dy, dz = math.radians(0.5), 0.05, -0.03, 0.01
    rows = [[math.cos(t), math.sin(t), 0], [-math.sin(t), math.cos(t), 0], [0, 0, 1], [dx, dy, dz]]
    assert np.allclose(tm_rows(rows), trans(dx, dy, dz) @ rotz(t))


def test_tm_rows_round_trip_and_batch() -> None:
    T = trans(1, 2, 3) @ rpy(0.3, -0.4, 0.5)
    assert np.allclose(tm_rows(to_tm_rows(T)), T)
    batch = np.stack([to_tm_rows(T), to_tm_rows(np.eye(4))])
    assert np.allclose(tm_rows(batch)[0], T)
    with pytest.raises(SparValueError):
        tm_rows([[1, 0, 0], [0, 1, 0], [0, 0, 1]])


# ---------------------------------------------------------------- checks


def test_orthonormal_checks() -> None:
    R = rot(rpy(0.1, 0.2, 0.3))
    assert is_orthonormal(R)
    assert not is_orthonormal(R * 1.01)
    assert not is_orthonormal(np.diag([1.0, 1.0, -1.0]))  # a reflection
    assert not is_orthonormal(np.eye(4))
    assert not is_orthonormal(np.full((3, 3), np.nan))
    assert is_orthonormal(R + 1e-8) and not is_orthonormal(R + 1e-8, tol=1e-10)
    with pytest.raises(SparValueError, match="block pose"):
        check_rotation(np.diag([1.0, -1.0, 1.0]), "block pose")
    bad = np.eye(4)
    bad[3, 0] = 1
    with pytest.raises(SparValueError, match="last row"):
        check_transform(bad)
    with pytest.raises(SparValueError, match="4x4"):
        check_transform(np.eye(3))


# ---------------------------------------------------------------- stable poses (Sec. 5.2.3)


@settings(max_examples=30, deadline=None)
@given(angle, angle, angle, angle)
def test_same_stable_pose_up_to_yaw(yaw: float, a: float, b: float, c: float) -> None:
    R_pose = rot(rpy(a, b, c))
    R_abs = rot(rotz(yaw)) @ R_pose
    assert same_stable_pose(R_abs, R_pose)
    assert same_stable_pose(rotz(yaw) @ rpy(a, b, c), rpy(a, b, c))  # 4x4 accepted
    assert math.isclose(math.remainder(yaw_about_world_z(R_abs, R_pose) - yaw, 2 * math.pi), 0, abs_tol=1e-9)


def test_tilted_is_another_stable_pose() -> None:
    R_pose = np.eye(3)
    assert not same_stable_pose(rot(rotx(0.01)), R_pose)
    assert not same_stable_pose(rot(rotx(math.pi)), R_pose)  # upside down
    assert same_stable_pose(rot(rotx(1e-9)), R_pose)
