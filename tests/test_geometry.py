"""geometry.py: transforms, the paper's row form (Figs. 11, 18), Euler angles (Fig. 19), stable poses."""
from __future__ import annotations

import math
import subprocess
import sys

import casadi as ca
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from spar_py.core.errors import SparValueError
from spar_py.core.geometry import (
    apply,
    check_rotation,
    check_transform,
    compose,
    euler_zyz,
    eulerxyz,
    inv,
    is_orthonormal,
    is_symbolic,
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


# ---------------------------------------------------------------- one code path: floats and CasADi SX

TWO_PI = 2 * math.pi
# constructor -> the ranges of its parameters (lengths in any unit, angles in rad)
CONSTRUCTORS = {
    "trans": (trans, [100.0] * 3),
    "rotx": (rotx, [TWO_PI]),
    "roty": (roty, [TWO_PI]),
    "rotz": (rotz, [TWO_PI]),
    "rpy": (rpy, [TWO_PI] * 3),
    "euler_zyz": (euler_zyz, [TWO_PI] * 3),
    "eulerxyz": (eulerxyz, [100.0] * 3 + [TWO_PI] * 3),
}


def sx_function(name: str, n: int) -> tuple[ca.Function, list[ca.SX]]:
    """The constructor ``name`` built on n SX symbols, as a Function of the parameter vector."""
    f, _ = CONSTRUCTORS[name]
    syms = [ca.SX.sym(f"p{i}") for i in range(n)]
    T = f(*syms)
    assert isinstance(T, ca.SX) and T.shape == (4, 4)
    return ca.Function(name, [ca.vertcat(*syms)], [T]), syms


def random_params(rng: np.random.Generator, scales: list[float]) -> np.ndarray:
    return rng.uniform(-1.0, 1.0, len(scales)) * np.array(scales)


@pytest.mark.parametrize("name", sorted(CONSTRUCTORS))
def test_sx_constructor_evaluates_to_the_float_one(name: str) -> None:
    f, scales = CONSTRUCTORS[name]
    F, _ = sx_function(name, len(scales))
    rng = np.random.default_rng(sum(map(ord, name)))
    for _ in range(50):
        p = random_params(rng, scales)
        Tf = f(*p)
        assert isinstance(Tf, np.ndarray) and Tf.shape == (4, 4)
        np.testing.assert_allclose(np.asarray(F(p)), Tf, rtol=0.0, atol=1e-12)


@pytest.mark.parametrize("name", sorted(CONSTRUCTORS))
def test_mixed_numbers_and_symbols_build_sx(name: str) -> None:
    # only the first parameter symbolic, the others plain floats: still SX, same values
    f, scales = CONSTRUCTORS[name]
    rng = np.random.default_rng(1 + sum(map(ord, name)))
    p = random_params(rng, scales)
    x = ca.SX.sym("x")
    T = f(x, *p[1:])
    assert isinstance(T, ca.SX)
    np.testing.assert_allclose(np.asarray(ca.Function("f", [x], [T])(p[0])), f(*p), rtol=0.0, atol=1e-12)


def test_sx_products_inverses_points_agree_with_floats() -> None:
    Fa, _ = sx_function("eulerxyz", 6)
    a_sym = ca.SX.sym("a", 6)
    A_sym = eulerxyz(*[a_sym[i] for i in range(6)])
    B_sym = compose(trans(a_sym[0], 1.5, -2.0), rotx(a_sym[4]))
    p_sym = [a_sym[1], 0.25, a_sym[2]]
    exprs = {
        "inv": inv(A_sym),
        "compose": compose(A_sym, B_sym),
        "compose_numeric_between": compose(A_sym, rpy(0.1, 0.2, 0.3), trans(1.0, 2.0, 3.0), B_sym),
        "inv_of_product": inv(compose(A_sym, B_sym)),
        "A_invA": compose(A_sym, inv(A_sym)),
        "apply": apply(compose(A_sym, B_sym), p_sym),
        "tm_rows": tm_rows(to_tm_rows(A_sym)),
        "rot": rot(A_sym),
        "transl": transl(A_sym),
    }
    for e in exprs.values():
        assert isinstance(e, ca.SX)
    F = ca.Function("all", [a_sym], list(exprs.values()))
    rng = np.random.default_rng(12)
    scales = CONSTRUCTORS["eulerxyz"][1]
    for _ in range(50):
        a = random_params(rng, scales)
        A = eulerxyz(*a)
        B = compose(trans(a[0], 1.5, -2.0), rotx(a[4]))
        want = {
            "inv": inv(A),
            "compose": compose(A, B),
            "compose_numeric_between": compose(A, rpy(0.1, 0.2, 0.3), trans(1.0, 2.0, 3.0), B),
            "inv_of_product": inv(compose(A, B)),
            "A_invA": np.eye(4),
            "apply": apply(compose(A, B), [a[1], 0.25, a[2]]).reshape(3, 1),
            "tm_rows": A,
            "rot": rot(A),
            "transl": transl(A).reshape(3, 1),
        }
        got = F(a)
        for (name, w), g in zip(want.items(), got):
            np.testing.assert_allclose(np.asarray(g), w, rtol=0.0, atol=1e-12, err_msg=name)
        np.testing.assert_allclose(inv(A), np.linalg.inv(A), rtol=0.0, atol=1e-10)


def test_batch_equals_single_bit_for_bit() -> None:
    rng = np.random.default_rng(3)
    a = rng.uniform(-TWO_PI, TWO_PI, (7, 6))
    for name, (f, scales) in CONSTRUCTORS.items():
        args = [a[:, i] * (s / TWO_PI) for i, s in enumerate(scales)]
        batch = f(*args)
        assert batch.shape == (7, 4, 4), name
        for k in range(7):
            assert np.array_equal(batch[k], f(*[x[k] for x in args])), name
    Ts = eulerxyz(*a.T)
    assert all(np.array_equal(inv(Ts)[k], inv(Ts[k])) for k in range(7))


def test_numeric_results_are_fresh_float_arrays() -> None:
    T = np.eye(4)
    out = compose(T)
    assert out is not T and out.dtype == float
    out[0, 3] = 5.0
    assert T[0, 3] == 0.0
    assert trans(1, 2, 3).dtype == float and not is_symbolic(trans(1, 2, 3))
    with pytest.raises(SparValueError, match="batch"):
        compose(ca.SX.sym("x"), rotz(np.zeros(3)))


def test_importing_geometry_and_kinematics_does_not_load_casadi() -> None:
    code = "import sys, spar_py.core.geometry, spar_py.world.robot.model; print('casadi' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False", out.stdout + out.stderr
