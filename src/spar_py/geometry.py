"""Homogeneous transforms on numpy arrays (the numeric half of the paper's Sec. 3.2 and 5.2).

Conventions (DESIGN.md): 4x4 homogeneous matrices with column vectors,
``T_world_obj`` maps points given in the object frame to the world frame; world Z is
up. Lengths are in whatever unit the caller uses (the functions never convert);
angles are in radians. Every function that builds a transform also accepts arrays of
angles/lengths of one shape ``s`` and then returns ``s + (4, 4)`` (the batch form),
so ``rotz(np.linspace(0, 1, 5))`` is a ``(5, 4, 4)`` stack.

The paper prints transforms in the row-vector convention, ``tm([[r1], [r2], [r3],
[d]])`` with r1..r3 the images of the frame's x, y, z axes: :func:`tm_rows` and
:func:`to_tm_rows` convert to and from it.
"""
from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from .errors import SparValueError

__all__ = [
    "check_rotation",
    "check_transform",
    "compose",
    "euler_zyz",
    "eulerxyz",
    "inv",
    "is_orthonormal",
    "rot",
    "rotx",
    "roty",
    "rotz",
    "rpy",
    "same_stable_pose",
    "tm_rows",
    "to_tm_rows",
    "trans",
    "transl",
    "up_vectors",
    "yaw_about_world_z",
]

ORTHO_TOL = 1e-6
_I3 = np.eye(3)
_LAST_ROW = np.array([0.0, 0.0, 0.0, 1.0])


# ------------------------------------------------------------------ elementary transforms


def _frame(shape: tuple[int, ...]) -> np.ndarray:
    T = np.zeros(shape + (4, 4))
    T[..., 3, 3] = 1.0
    return T


def trans(x: ArrayLike, y: ArrayLike, z: ArrayLike) -> np.ndarray:
    """Pure translation by (x, y, z) (caller's length unit); (4,4), or (..., 4, 4) for arrays."""
    x, y, z = np.broadcast_arrays(np.asarray(x, float), np.asarray(y, float), np.asarray(z, float))
    T = _frame(x.shape)
    T[..., 0, 0] = T[..., 1, 1] = T[..., 2, 2] = 1.0
    T[..., 0, 3], T[..., 1, 3], T[..., 2, 3] = x, y, z
    return T


def _rot(axis: int, angle: ArrayLike) -> np.ndarray:
    a = np.asarray(angle, float)
    c, s = np.cos(a), np.sin(a)
    i, j = (axis + 1) % 3, (axis + 2) % 3
    T = _frame(a.shape)
    T[..., axis, axis] = 1.0
    T[..., i, i] = c
    T[..., j, j] = c
    T[..., i, j] = -s
    T[..., j, i] = s
    return T


def rotx(angle: ArrayLike) -> np.ndarray:
    """Rotation by ``angle`` (rad, right hand) about x; (4,4) or (..., 4, 4)."""
    return _rot(0, angle)


def roty(angle: ArrayLike) -> np.ndarray:
    """Rotation by ``angle`` (rad, right hand) about y; (4,4) or (..., 4, 4)."""
    return _rot(1, angle)


def rotz(angle: ArrayLike) -> np.ndarray:
    """Rotation by ``angle`` (rad, right hand) about z; (4,4) or (..., 4, 4)."""
    return _rot(2, angle)


def rpy(roll: ArrayLike, pitch: ArrayLike, yaw: ArrayLike) -> np.ndarray:
    """Roll-pitch-yaw (rad) about the fixed x, y, z axes: ``rotz(yaw) @ roty(pitch) @ rotx(roll)``."""
    return rotz(yaw) @ roty(pitch) @ rotx(roll)


def transl(T: np.ndarray) -> np.ndarray:
    """The translation part (..., 3) of a transform (a view, in the transform's unit)."""
    return np.asarray(T)[..., :3, 3]


def rot(T: np.ndarray) -> np.ndarray:
    """The rotation part (..., 3, 3) of a transform (a view)."""
    return np.asarray(T)[..., :3, :3]


def inv(T: np.ndarray) -> np.ndarray:
    """Closed-form inverse of a rigid transform: ``[R.T, -R.T t]``; works on (..., 4, 4)."""
    T = np.asarray(T, float)
    R = T[..., :3, :3]
    Rt = np.swapaxes(R, -1, -2)
    out = _frame(T.shape[:-2])
    out[..., :3, :3] = Rt
    out[..., :3, 3] = -np.einsum("...ij,...j->...i", Rt, T[..., :3, 3])
    return out


def compose(*Ts: np.ndarray) -> np.ndarray:
    """The product ``Ts[0] @ Ts[1] @ ...`` (frames chained left to right); identity if none."""
    out = np.eye(4)
    for T in Ts:
        out = out @ np.asarray(T, float)
    return out


# ------------------------------------------------------------------ Euler angles (Fig. 19)


def euler_zyz(phi: ArrayLike, theta: ArrayLike, psi: ArrayLike) -> np.ndarray:
    """Z-Y-Z Euler rotation (rad): ``rotz(phi) @ roty(theta) @ rotz(psi)``; (4,4) or (..., 4, 4)."""
    return rotz(phi) @ roty(theta) @ rotz(psi)


def eulerxyz(X: ArrayLike, Y: ArrayLike, Z: ArrayLike,
             phi: ArrayLike, theta: ArrayLike, psi: ArrayLike) -> np.ndarray:
    """The paper's ``eulerxyz(X,Y,Z,phi,theta,psi)`` (Fig. 19) as a 4x4 transform.

    ``T = trans(X, Y, Z) @ rotz(phi) @ roty(theta) @ rotz(psi)``: a displacement
    (caller's length unit) followed by Paul's Z-Y-Z Euler angles, in RADIANS (the KB
    stores degrees; kb.py converts). This is the Euler convention of Paul's "Robot
    Manipulators" that the Purdue PUMA work used; "xyz" in the name refers to the
    displacement, not to the rotation axes. For a grasp, T is T_g: the tool frame in
    the object frame, so the tool's approach axis (tool z) is
    ``(cos phi sin theta, sin phi sin theta, cos theta)`` in the object frame.
    """
    return trans(X, Y, Z) @ euler_zyz(phi, theta, psi)


# ------------------------------------------------------------------ the paper's row form


def tm_rows(rows: ArrayLike) -> np.ndarray:
    """4x4 transform from the paper's row form ``tm([[r1], [r2], [r3], [d]])`` (Figs. 11, 18).

    The paper writes transforms in the row-vector convention: r1..r3 are the images
    of the frame's x, y, z axes (so ``R = array(rows[:3]).T``) and d is the
    translation. Accepts (4, 3) or a batch (..., 4, 3); does not check orthonormality
    (see :func:`check_transform`).
    """
    m = np.asarray(rows, float)
    if m.shape[-2:] != (4, 3):
        raise SparValueError(f"tm rows must be [[r1], [r2], [r3], [d]] (4 rows of 3 numbers), got shape {m.shape}")
    T = _frame(m.shape[:-2])
    T[..., :3, :3] = np.swapaxes(m[..., :3, :], -1, -2)
    T[..., :3, 3] = m[..., 3, :]
    return T


def to_tm_rows(T: np.ndarray) -> list[list[float]]:
    """The paper's row form ``[[r1], [r2], [r3], [d]]`` of one 4x4 transform (inverse of :func:`tm_rows`)."""
    T = np.asarray(T, float)
    if T.shape != (4, 4):
        raise SparValueError(f"to_tm_rows takes one 4x4 transform, got shape {T.shape}")
    return [[float(v) for v in T[:3, i]] for i in range(3)] + [[float(v) for v in T[:3, 3]]]


# ------------------------------------------------------------------ checks


def is_orthonormal(R: ArrayLike, tol: float = ORTHO_TOL) -> bool:
    """True iff R (3x3) is a proper rotation: ``R.T R = I`` within ``tol`` (max abs entry) and det R > 0."""
    R = np.asarray(R, float)
    if R.shape != (3, 3) or not np.isfinite(R).all():
        return False
    (a, b, c), (d, e, f), (g, h, i) = R.tolist()
    det = a * (e * i - f * h) - b * (d * i - f * g) + c * (d * h - e * g)
    return bool(det > 0 and np.abs(R.T @ R - _I3).max() <= tol)


def check_rotation(R: ArrayLike, what: str = "rotation", tol: float = ORTHO_TOL) -> np.ndarray:
    """Return R as a float (3,3) array, or raise SparValueError naming ``what`` if it is no rotation."""
    R = np.asarray(R, float)
    if not is_orthonormal(R, tol):
        raise SparValueError(f"{what}: not an orthonormal right-handed 3x3 rotation (tolerance {tol})")
    return R


def check_transform(T: ArrayLike, what: str = "transform", tol: float = ORTHO_TOL) -> np.ndarray:
    """Return T as a float (4,4) array, or raise SparValueError naming ``what`` if it is no rigid transform."""
    T = np.asarray(T, float)
    if T.shape != (4, 4) or not np.isfinite(T).all():
        raise SparValueError(f"{what}: not a finite 4x4 matrix")
    if np.abs(T[3] - _LAST_ROW).max() > tol:
        raise SparValueError(f"{what}: last row is not [0, 0, 0, 1]")
    check_rotation(T[:3, :3], what, tol)
    return T


# ------------------------------------------------------------------ stable poses (Sec. 5.2.3)


def yaw_about_world_z(R_abs: ArrayLike, R_pose: ArrayLike) -> float:
    """The yaw (rad, in (-pi, pi]) about world z that best maps R_pose onto R_abs (``R_abs ~ rotz(yaw) R_pose``).

    Least squares over the rotations about z (exact when :func:`same_stable_pose`
    holds): with ``M = R_abs @ R_pose.T``, ``yaw = atan2(M[1,0] - M[0,1], M[0,0] + M[1,1])``.
    """
    M = np.asarray(R_abs, float)[..., :3, :3] @ np.swapaxes(np.asarray(R_pose, float)[..., :3, :3], -1, -2)
    return float(np.arctan2(M[..., 1, 0] - M[..., 0, 1], M[..., 0, 0] + M[..., 1, 1]))


def same_stable_pose(R_abs: ArrayLike, R_pose: ArrayLike, tol: float = ORTHO_TOL) -> bool:
    """True iff the orientation R_abs (3x3, world) is the stable pose R_pose turned about world z.

    A stable pose fixes two rotational degrees of freedom (Sec. 5.2.3): R_abs =
    rotz(yaw) @ R_pose for some yaw iff both put the same object-frame vector
    straight up, i.e. ``R_abs.T @ ez == R_pose.T @ ez`` (their third rows agree)
    within ``tol``. Accepts 3x3 or 4x4 (the rotation part is used).
    """
    a = np.asarray(R_abs, float)[:3, :3]
    b = np.asarray(R_pose, float)[:3, :3]
    return bool(np.allclose(a[2], b[2], rtol=0.0, atol=tol))


def up_vectors(Rs: ArrayLike) -> np.ndarray:
    """The object-frame vector pointing up (world +z) for each rotation of a (..., 3, 3) stack."""
    return np.asarray(Rs, float)[..., 2, :3]
