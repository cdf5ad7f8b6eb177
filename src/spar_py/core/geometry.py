"""Homogeneous transforms for numbers and symbols, one code path (the paper's Sec. 3.2 and 5.2).

Conventions (DESIGN.md): 4x4 homogeneous matrices with column vectors,
``T_world_obj`` maps points given in the object frame to the world frame; world Z is
up. Lengths are in whatever unit the caller uses (the functions never convert);
angles are in radians.

Every transform function is written once, against a tiny backend (:class:`_Numpy`
or :class:`_Casadi`: sin/cos, building a matrix from entries, transposing, products)
chosen by the arguments' type, the way spatialmath shims ``sym.cos``:

- plain numbers and numpy arrays give float numpy arrays. Angles/lengths given as
  arrays of one shape ``s`` give ``s + (4, 4)`` (the batch form), so
  ``rotz(np.linspace(0, 1, 5))`` is a ``(5, 4, 4)`` stack;
- as soon as one argument is a CasADi ``SX`` (or ``DM``) the result is a 4x4 ``SX``
  (no batch form), e.g. ``trans(dx, 0, 0)`` with ``dx`` an uncertainty variable.

This module never imports CasADi itself: a CasADi value can only reach it once the
caller has imported CasADi, so numeric users (the kb loaders, world/robot/) do not pay for it.

The paper prints transforms in the row-vector convention, ``tm([[r1], [r2], [r3],
[d]])`` with r1..r3 the images of the frame's x, y, z axes: :func:`tm_rows` and
:func:`to_tm_rows` convert to and from it.
"""
from __future__ import annotations

import sys
from collections.abc import Iterable, Sequence
from typing import TYPE_CHECKING, Any, Protocol, Union

import numpy as np
from numpy.typing import ArrayLike

from spar_py.core.errors import SparValueError

if TYPE_CHECKING:
    import casadi as ca

    Scalar = Union[float, np.ndarray, ca.SX]
    Matrix = Union[np.ndarray, ca.SX]

__all__ = [
    "ORTHO_TOL",
    "apply",
    "as_sx",
    "check_rotation",
    "check_transform",
    "compose",
    "convex_hull_2d",
    "euler_zyz",
    "eulerxyz",
    "inv",
    "is_orthonormal",
    "is_symbolic",
    "rot",
    "rotation_problem",
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

ORTHO_TOL = 1e-6  # max |R^T R - I| entry a rotation read from data may show


# ------------------------------------------------------------------ numbers or symbols


_PLAIN = (float, int, np.ndarray, np.generic)  # never CasADi: the common case, decided fast
_NUMBER = frozenset({float, int, np.float64})  # types of one number (shape ())


def _is_casadi(x: object) -> bool:
    if isinstance(x, _PLAIN):
        return False
    ca = sys.modules.get("casadi")  # not imported: no value can be a CasADi one
    return ca is not None and isinstance(x, (ca.SX, ca.MX, ca.DM))


def is_symbolic(*xs: object) -> bool:
    """True if any argument is a CasADi SX/MX/DM value (then the transforms build SX)."""
    for x in xs:  # a loop, not any(): this runs for every factor of every transform
        if not isinstance(x, _PLAIN) and _is_casadi(x):
            return True
    return False


def _entries_symbolic(x: object) -> bool:
    """True if ``x`` or an entry of a (nested) list/tuple ``x`` is a CasADi value."""
    if isinstance(x, (list, tuple)):
        return any(_entries_symbolic(v) for v in x)
    return _is_casadi(x)


def as_sx(M: Any) -> ca.SX:
    """``M`` as a CasADi SX matrix (numbers become constant entries; MX is refused)."""
    import casadi as ca  # only a symbolic caller pays for it

    if isinstance(M, ca.SX):
        return M
    if isinstance(M, ca.DM):
        return ca.SX(M)
    if isinstance(M, ca.MX):
        raise SparValueError("as_sx: MX expressions are not supported (build with SX)")
    if isinstance(M, (list, tuple)) and _entries_symbolic(M):
        rows = [list(r) if isinstance(r, (list, tuple)) else [r] for r in M]
        return ca.vertcat(*[ca.horzcat(*r) for r in rows])
    A = np.asarray(M, float)
    if A.ndim > 2:
        raise SparValueError(f"as_sx: a batch of shape {A.shape} has no SX form (one matrix at a time)")
    return ca.SX(ca.DM(A))


class _Ops(Protocol):
    """What the transforms need of a backend (numbers and lengths pass through unchanged in unit).

    A "matrix" is (..., m, n) in numpy and m x n in SX; a "vector" is (..., 3) in
    numpy and a 3x1 column in SX.
    """

    @staticmethod
    def cos(a: Any) -> Any:
        """cos of an angle (rad), elementwise."""

    @staticmethod
    def sin(a: Any) -> Any:
        """sin of an angle (rad), elementwise."""

    @staticmethod
    def matrix(rows: Sequence[Sequence[Any]], *args: Any) -> Any:
        """The matrix with these rows of entries; ``args`` are the parameters the entries came from."""

    @staticmethod
    def asarray(M: Any) -> Any:
        """M as this backend's matrix (float array, or SX)."""

    @staticmethod
    def shape(M: Any) -> tuple[int, ...]:
        """The shape of a matrix (batch axes first in numpy)."""

    @staticmethod
    def block(M: Any, rows: slice, cols: slice) -> Any:
        """The sub-matrix ``M[rows, cols]`` (of each matrix of a batch)."""

    @staticmethod
    def row(M: Any, i: int, cols: slice) -> Any:
        """Row i of M, restricted to ``cols``, as a vector."""

    @staticmethod
    def col(M: Any, rows: slice, j: int) -> Any:
        """Column j of M, restricted to ``rows``, as a vector."""

    @staticmethod
    def transpose(M: Any) -> Any:
        """M transposed (each matrix of a batch)."""

    @staticmethod
    def matvec(M: Any, v: Any) -> Any:
        """The product M v of a 3x3 matrix and a vector."""

    @staticmethod
    def frame(R: Any, t: Any) -> Any:
        """The 4x4 transform ``[[R, t], [0 0 0 1]]`` from a rotation block R and a translation vector t."""

    @staticmethod
    def product(*Ts: Any) -> Any:
        """``Ts[0] @ Ts[1] @ ...``, left to right (the factors made by this backend's constructors)."""


class _Numpy:
    """The float backend: numpy arrays, batched over leading axes."""

    @staticmethod
    def cos(a: ArrayLike) -> np.ndarray:
        return np.cos(np.asarray(a, float))

    @staticmethod
    def sin(a: ArrayLike) -> np.ndarray:
        return np.sin(np.asarray(a, float))

    @staticmethod
    def matrix(rows: Sequence[Sequence[ArrayLike]], *args: ArrayLike) -> np.ndarray:
        """(..., m, n) from m rows of n entries: float constants, or values of ``args`` (numbers or
        arrays), which give the batch shape (their broadcast shape)."""
        shapes = {np.shape(a) for a in args if type(a) not in _NUMBER}
        if shapes <= {()}:  # one matrix: numpy builds it fastest from the rows themselves
            return np.array(rows, dtype=float)
        out = np.zeros(np.broadcast_shapes(*shapes) + (len(rows), len(rows[0])))
        for i, r in enumerate(rows):
            for j, v in enumerate(r):
                if not (type(v) is float and v == 0.0):
                    out[..., i, j] = v
        return out

    @staticmethod
    def asarray(M: ArrayLike) -> np.ndarray:
        return np.asarray(M, float)

    @staticmethod
    def shape(M: np.ndarray) -> tuple[int, ...]:
        return M.shape

    @staticmethod
    def block(M: np.ndarray, rows: slice, cols: slice) -> np.ndarray:
        return M[..., rows, cols]

    @staticmethod
    def row(M: np.ndarray, i: int, cols: slice) -> np.ndarray:
        return M[..., i, cols]

    @staticmethod
    def col(M: np.ndarray, rows: slice, j: int) -> np.ndarray:
        return M[..., rows, j]

    @staticmethod
    def transpose(M: np.ndarray) -> np.ndarray:
        return np.swapaxes(M, -1, -2)

    @staticmethod
    def matvec(M: np.ndarray, v: np.ndarray) -> np.ndarray:
        return np.einsum("...ij,...j->...i", M, v)

    @staticmethod
    def frame(R: np.ndarray, t: np.ndarray) -> np.ndarray:
        out = np.zeros(R.shape[:-2] + (4, 4))  # R (..., 3, 3) and t (..., 3) share the batch shape
        out[..., 3, 3] = 1.0
        out[..., :3, :3] = R
        out[..., :3, 3] = t
        return out

    @staticmethod
    def product(*Ts: np.ndarray) -> np.ndarray:
        out = Ts[0]
        for T in Ts[1:]:
            out = out @ T
        return out


class _Casadi:
    """The symbolic backend: one CasADi SX matrix (no batch form)."""

    @staticmethod
    def cos(a: Any) -> Any:
        import casadi as ca  # lazy: see as_sx

        return ca.cos(a)

    @staticmethod
    def sin(a: Any) -> Any:
        import casadi as ca  # lazy: see as_sx

        return ca.sin(a)

    @staticmethod
    def matrix(rows: Sequence[Sequence[Any]], *args: Any) -> ca.SX:
        """A 4x4 (m x n) SX from m rows of n entries (numbers or SX scalars); ``args`` are not needed.

        The numbers first, as one dense numeric matrix, then the symbolic entries set in
        place: the same dense SX as concatenating the rows (the same entries and constants),
        made in a third of the time (each concatenation converts its numbers one by one)."""
        import casadi as ca  # lazy: see as_sx

        M = ca.SX(ca.DM([[0.0 if isinstance(x, ca.SX) else float(x) for x in r] for r in rows]))
        for i, r in enumerate(rows):
            for j, x in enumerate(r):
                if isinstance(x, ca.SX):
                    M[i, j] = x
        return M

    @staticmethod
    def asarray(M: Any) -> ca.SX:
        return as_sx(M)

    @staticmethod
    def shape(M: ca.SX) -> tuple[int, ...]:
        return tuple(M.shape)

    @staticmethod
    def block(M: ca.SX, rows: slice, cols: slice) -> ca.SX:
        return M[rows, cols]

    @staticmethod
    def row(M: ca.SX, i: int, cols: slice) -> ca.SX:
        return M[i, cols].T

    @staticmethod
    def col(M: ca.SX, rows: slice, j: int) -> ca.SX:
        return M[rows, j]

    @staticmethod
    def transpose(M: ca.SX) -> ca.SX:
        return M.T

    @staticmethod
    def matvec(M: ca.SX, v: ca.SX) -> ca.SX:
        import casadi as ca  # lazy: see as_sx

        return ca.mtimes(M, v)

    @staticmethod
    def frame(R: ca.SX, t: ca.SX) -> ca.SX:
        import casadi as ca  # lazy: see as_sx

        return ca.vertcat(ca.horzcat(R, t), ca.horzcat(ca.SX.zeros(1, 3), ca.SX(1.0)))

    @staticmethod
    def product(*Ts: Any) -> ca.SX:
        return compose(*Ts)  # folds the numeric factors among the symbolic ones


def _ops(*xs: object) -> type[_Ops]:
    """The backend for these arguments: CasADi if any (or any entry of a list) is symbolic, else numpy."""
    for x in xs:
        if not isinstance(x, _PLAIN) and _entries_symbolic(x):
            return _Casadi
    return _Numpy


# ------------------------------------------------------------------ elementary transforms


def trans(x: Scalar, y: Scalar, z: Scalar) -> Matrix:
    """Pure translation by (x, y, z) (caller's length unit), the paper's ``trans(X, Y, Z)``; (4,4) or (..., 4, 4)."""
    return _ops(x, y, z).matrix([[1.0, 0.0, 0.0, x],
                                 [0.0, 1.0, 0.0, y],
                                 [0.0, 0.0, 1.0, z],
                                 [0.0, 0.0, 0.0, 1.0]], x, y, z)


def rotx(angle: Scalar) -> Matrix:
    """Rotation by ``angle`` (rad, right hand) about x; (4,4) or (..., 4, 4)."""
    b = _ops(angle)
    c, s = b.cos(angle), b.sin(angle)
    return b.matrix([[1.0, 0.0, 0.0, 0.0],
                     [0.0, c, -s, 0.0],
                     [0.0, s, c, 0.0],
                     [0.0, 0.0, 0.0, 1.0]], angle)


def roty(angle: Scalar) -> Matrix:
    """Rotation by ``angle`` (rad, right hand) about y; (4,4) or (..., 4, 4)."""
    b = _ops(angle)
    c, s = b.cos(angle), b.sin(angle)
    return b.matrix([[c, 0.0, s, 0.0],
                     [0.0, 1.0, 0.0, 0.0],
                     [-s, 0.0, c, 0.0],
                     [0.0, 0.0, 0.0, 1.0]], angle)


def rotz(angle: Scalar) -> Matrix:
    """Rotation by ``angle`` (rad, right hand) about z; (4,4) or (..., 4, 4)."""
    b = _ops(angle)
    c, s = b.cos(angle), b.sin(angle)
    return b.matrix([[c, -s, 0.0, 0.0],
                     [s, c, 0.0, 0.0],
                     [0.0, 0.0, 1.0, 0.0],
                     [0.0, 0.0, 0.0, 1.0]], angle)


def rpy(roll: Scalar, pitch: Scalar, yaw: Scalar) -> Matrix:
    """Roll-pitch-yaw (rad) about the fixed x, y, z axes: ``rotz(yaw) @ roty(pitch) @ rotx(roll)``."""
    return _ops(roll, pitch, yaw).product(rotz(yaw), roty(pitch), rotx(roll))


def transl(T: Matrix) -> Matrix:
    """The translation part of a transform (its length unit): (..., 3) numpy (a view) or 3x1 SX."""
    return T[:3, 3] if is_symbolic(T) else np.asarray(T)[..., :3, 3]


def rot(T: Matrix) -> Matrix:
    """The rotation part of a transform: (..., 3, 3) numpy (a view) or 3x3 SX."""
    return T[:3, :3] if is_symbolic(T) else np.asarray(T)[..., :3, :3]


def inv(T: Matrix | ArrayLike) -> Matrix:
    """Closed-form inverse of a rigid transform, ``[R.T, -R.T t]`` (no general inverse); (..., 4, 4) or SX."""
    b = _ops(T)
    T = b.asarray(T)
    Rt = b.transpose(b.block(T, slice(0, 3), slice(0, 3)))
    return b.frame(Rt, -b.matvec(Rt, b.col(T, slice(0, 3), 3)))


def compose(*Ts: Matrix | ArrayLike) -> Matrix:
    """The product ``Ts[0] @ Ts[1] @ ...`` (frames chained left to right); a fresh identity if none.

    Numeric factors next to each other are multiplied in numpy first (batches
    broadcast), so a symbolic chain only grows where a symbolic factor enters; the
    result is SX as soon as one factor is.
    """
    acc: list[Any] = []  # the factors, runs of numeric ones multiplied out
    numeric_last = False
    for T in Ts:
        if is_symbolic(T):
            acc.append(as_sx(T))
            numeric_last = False
        elif numeric_last:
            acc[-1] = acc[-1] @ np.asarray(T, float)
        else:
            acc.append(np.array(T, float))
            numeric_last = True
    if not acc:
        return np.eye(4)
    if len(acc) == 1:
        return acc[0]
    import casadi as ca  # a symbolic factor is present, so CasADi is loaded

    out = as_sx(acc[0])
    for T in acc[1:]:
        out = ca.mtimes(out, as_sx(T))
    return out


def apply(T: Matrix, p: Iterable[Scalar] | Matrix) -> Matrix:
    """The point ``p`` (3 coordinates in T's source frame) mapped by ``T``: ``(T @ [p, 1])[:3]``.

    Returns a (..., 3) numpy array (batched over T), or a 3x1 SX column when anything is symbolic.
    """
    if is_symbolic(p):
        pl: list[Any] = [as_sx(p)[k] for k in range(3)]
    else:
        pl = list(np.asarray(p, dtype=object).reshape(-1))
        if len(pl) != 3:
            raise SparValueError(f"apply: a point has 3 coordinates, got {len(pl)}")
    if is_symbolic(T, *pl):
        import casadi as ca  # lazy: see as_sx

        return ca.mtimes(as_sx(T), ca.vertcat(*pl, 1.0))[:3]
    return (np.asarray(T, float) @ np.array([*pl, 1.0], dtype=float))[..., :3]


# ------------------------------------------------------------------ Euler angles (Fig. 19)


def euler_zyz(phi: Scalar, theta: Scalar, psi: Scalar) -> Matrix:
    """Z-Y-Z Euler rotation (rad): ``rotz(phi) @ roty(theta) @ rotz(psi)``; (4,4), (..., 4, 4) or SX."""
    return _ops(phi, theta, psi).product(rotz(phi), roty(theta), rotz(psi))


def eulerxyz(X: Scalar, Y: Scalar, Z: Scalar, phi: Scalar, theta: Scalar, psi: Scalar) -> Matrix:
    """The paper's ``eulerxyz(X,Y,Z,phi,theta,psi)`` (Fig. 19) as a 4x4 transform.

    ``T = trans(X, Y, Z) @ rotz(phi) @ roty(theta) @ rotz(psi)``: a displacement
    (caller's length unit) followed by Paul's Z-Y-Z Euler angles, in RADIANS (the KB
    stores degrees; kb.py converts). This is the Euler convention of Paul's "Robot
    Manipulators" that the Purdue PUMA work used; "xyz" in the name refers to the
    displacement, not to the rotation axes. For a grasp, T is T_g: the tool frame in
    the object frame, so the tool's approach axis (tool z) is
    ``(cos phi sin theta, sin phi sin theta, cos theta)`` in the object frame.
    """
    return _ops(X, Y, Z, phi, theta, psi).product(trans(X, Y, Z), euler_zyz(phi, theta, psi))


# ------------------------------------------------------------------ the paper's row form


def tm_rows(rows: ArrayLike | Sequence[Sequence[Scalar]] | Matrix) -> Matrix:
    """4x4 transform from the paper's row form ``tm([[r1], [r2], [r3], [d]])`` (Figs. 11, 18).

    The paper writes transforms in the row-vector convention: r1..r3 are the images
    of the frame's x, y, z axes (so ``R = array(rows[:3]).T``) and d is the
    translation. Accepts (4, 3), a numeric batch (..., 4, 3), or rows with symbolic
    entries (then SX); does not check orthonormality (see :func:`check_transform`).
    """
    b = _ops(rows)
    m = b.asarray(rows)
    if b.shape(m)[-2:] != (4, 3):
        raise SparValueError(f"tm rows must be [[r1], [r2], [r3], [d]] (4 rows of 3 numbers), "
                             f"got shape {b.shape(m)}")
    return b.frame(b.transpose(b.block(m, slice(0, 3), slice(0, 3))), b.row(m, 3, slice(0, 3)))


def to_tm_rows(T: Matrix | ArrayLike) -> list[list[Any]]:
    """The paper's row form ``[[r1], [r2], [r3], [d]]`` of one 4x4 transform (inverse of :func:`tm_rows`).

    Entries are floats for a numeric T, SX scalars for a symbolic one.
    """
    if is_symbolic(T):
        T = as_sx(T)
        entry = T.__getitem__
    else:
        T = np.asarray(T, float)
        entry = lambda ij: float(T[ij])  # noqa: E731
    if tuple(T.shape) != (4, 4):
        raise SparValueError(f"to_tm_rows takes one 4x4 transform, got shape {tuple(T.shape)}")
    return [[entry((j, i)) for j in range(3)] for i in range(3)] + [[entry((j, 3)) for j in range(3)]]


# ------------------------------------------------------------------ checks (numeric)


def rotation_problem(R: ArrayLike, tol: float = ORTHO_TOL) -> str | None:
    """Why R is not a proper rotation (3x3, ``R.T R = I`` to ``tol`` per entry, det +1), or None if it is."""
    R = np.asarray(R, float)
    if R.shape != (3, 3):
        return f"shape {R.shape}, not (3, 3)"
    if not np.isfinite(R).all():
        return "entries not all finite"
    (a, b, c), (d, e, f), (g, h, i) = R.tolist()
    det = a * (e * i - f * h) - b * (d * i - f * g) + c * (d * h - e * g)
    err = float(np.abs(R.T @ R - np.eye(3)).max())
    if err > tol:
        return f"R^T R is off I by {err:.3g}"
    if not det > 0:
        return f"det {det:.3g} (a reflection)" if det < 0 else f"det {det:.3g}"
    return None


def is_orthonormal(R: ArrayLike, tol: float = ORTHO_TOL) -> bool:
    """True iff R (3x3) is a proper rotation: ``R.T R = I`` within ``tol`` (max abs entry) and det R > 0."""
    return rotation_problem(R, tol) is None


def check_rotation(R: ArrayLike, what: str = "rotation", tol: float = ORTHO_TOL) -> np.ndarray:
    """Return R as a float (3,3) array, or raise SparValueError naming ``what`` and what was expected."""
    why = rotation_problem(R, tol)
    if why is not None:
        raise SparValueError(f"{what}: not a right-handed 3x3 rotation "
                             f"(expected orthonormal to {tol:g}, det +1; {why})")
    return np.asarray(R, float)


def check_transform(T: ArrayLike, what: str = "transform", tol: float = ORTHO_TOL) -> np.ndarray:
    """Return T as a float (4,4) array, or raise SparValueError naming ``what`` if it is no rigid transform."""
    T = np.asarray(T, float)
    if T.shape != (4, 4) or not np.isfinite(T).all():
        raise SparValueError(f"{what}: not a finite 4x4 matrix")
    if np.abs(T[3] - [0.0, 0.0, 0.0, 1.0]).max() > tol:
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
    return bool(same_stable_poses(R_abs, np.asarray(R_pose, float)[None], tol)[0])


def same_stable_poses(R_abs: ArrayLike, R_poses: ArrayLike, tol: float = ORTHO_TOL) -> np.ndarray:
    """(k,) :func:`same_stable_pose` of R_abs (3x3 or 4x4) against each of the stable poses
    R_poses (k, 3, 3) or (k, 4, 4), in one comparison."""
    a = up_vectors(np.asarray(R_abs, float)[:3, :3])
    b = up_vectors(np.asarray(R_poses, float)[:, :3, :3])
    return np.isclose(a, b, rtol=0.0, atol=tol).all(axis=-1)


def up_vectors(Rs: ArrayLike) -> np.ndarray:
    """The object-frame vector pointing up (world +z) for each rotation of a (..., 3, 3) stack."""
    return np.asarray(Rs, float)[..., 2, :3]


def convex_hull_2d(P: ArrayLike) -> np.ndarray:
    """(k, 2) the convex hull of points P (n, 2), counter-clockwise, no repeated or
    collinear vertices (Andrew's monotone chain; points equal to 12 decimals are one);
    the points themselves when there are at most two. Any length unit."""
    pts = sorted(set(map(tuple, np.round(np.asarray(P, float), 12).tolist())))
    if len(pts) <= 2:
        return np.array(pts, float)

    def half(seq: list) -> list:
        out: list = []
        for p in seq:
            while len(out) >= 2 and ((out[-1][0] - out[-2][0]) * (p[1] - out[-2][1])
                                     - (out[-1][1] - out[-2][1]) * (p[0] - out[-2][0])) <= 0:
                out.pop()
            out.append(p)
        return out

    lower, upper = half(pts), half(pts[::-1])
    return np.array(lower[:-1] + upper[:-1], float)
