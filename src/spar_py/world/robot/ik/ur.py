"""The UR family (three parallel middle axes, wrist offsets d4, d5, d6): all eight closed-form branches.

Universal Robots' arms (UR3e, UR5e, UR10e, UR16e and their CB3 forebears) and their
clones have no spherical wrist: joints 2, 3 and 4 are parallel, axis 5 is offset by
d5 along axis 4 and the flange by d6 along axis 6. The closed form follows K. P.
Hawkins, *Analytic Inverse Kinematics for the Universal Robots UR-5/UR-10 Arms*
(Georgia Tech, 2013), whose steps are quoted below (his eqs. are written for UR's
standard DH table; ours is the same arm in Craig's modified table, see
``robots.standard_to_modified``, so each step is stated in both forms):

    theta1 (2 roots: shoulder left/right), then theta5 (2 roots: wrist up/down), then
    theta6 (unique given theta1, theta5), then theta2..theta4 as a planar 3R arm
    (2 roots of theta3: elbow up/down) -- 2 x 2 x 2 = 8 branches.

The family, in Craig's table (row i: alpha_{i-1}, a_{i-1}, d_i): alpha_1 = +90,
alpha_2 = alpha_3 = 0, alpha_4 = +90, alpha_5 = -90 deg; a_1 = a_4 = a_5 = 0, a_2, a_3
non-zero; alpha_0, a_0, d_1 (the base) and d_6 (the flange) are absorbed into the
constant frames; d_2 + d_3 + d_4 = D is the lateral offset along the parallel axes.

Frames and units: ``T`` arguments are ``T_world_tool`` (4x4, column vectors), lengths
in the robot's unit; the angles returned are the DH angles theta_i (rad).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from spar_py.core.geometry import inv, rotx, trans

__all__ = ["UR_TWISTS", "URSolver", "ur_structure"]

_EPS = np.finfo(float).eps
_SING_S5 = 1e-12  # |sin theta5| below this: wrist singular (axis 6 parallel to axes 2, 3, 4)
_HALF_PI = math.pi / 2
# the family's twists alpha_1..alpha_5 (rows 2..6 of Craig's table), radians
UR_TWISTS = (_HALF_PI, 0.0, 0.0, _HALF_PI, -_HALF_PI)


@dataclass(frozen=True)
class _UR:
    """The table reduced to the family's parameters, plus the constant frames absorbed."""

    a2: float  # a_2 (upper arm, UR's standard a2)
    a3: float  # a_3 (forearm, UR's standard a3)
    D: float  # d_2 + d_3 + d_4: the offset along the parallel axes (UR's d4)
    d5: float  # UR's d5
    base_inv: np.ndarray  # inv(base @ rotx(alpha0) @ trans(a0, 0, d1))
    tool_inv: np.ndarray  # inv(trans(0, 0, d6) @ tool)
    offset: np.ndarray  # (6,) theta_i - q_i
    tol_sq: float  # length^2 below which a discriminant counts as zero
    tol_4: float  # length^4 likewise (the elbow's discriminant)


def ur_structure(dh: np.ndarray, base: np.ndarray, tool: np.ndarray, unit: str = "") -> _UR | str:
    """The UR-family parameters of a Craig DH table, or the reason the table is not of that family."""
    alpha, a, d, off = dh.T
    for i, want in enumerate(UR_TWISTS, start=1):
        if abs(math.remainder(alpha[i] - want, 2 * math.pi)) > 1e-9:
            return (f"alpha_{i} (dh[{i}].alpha) = {math.degrees(alpha[i]):g} deg where the UR family has "
                    f"{math.degrees(want):g}")
    for what, v in (("a_1 (dh[1].a)", a[1]), ("a_4 (dh[4].a)", a[4]), ("a_5 (dh[5].a)", a[5])):
        if v != 0.0:
            return f"{what} = {v:g} {unit} where the UR family has 0".replace("  ", " ")
    if a[2] == 0.0 or a[3] == 0.0:
        return "a_2 or a_3 = 0 where the UR family needs an upper arm and a forearm"
    scale = abs(a[2]) + abs(a[3]) + abs(d[1] + d[2] + d[3]) + abs(d[4])
    return _UR(
        a2=float(a[2]), a3=float(a[3]), D=float(d[1] + d[2] + d[3]), d5=float(d[4]),
        # rotx(alpha0) transx(a0) rotz(theta1) transz(d1): the constant parts commute out
        base_inv=inv(base @ rotx(alpha[0]) @ trans(a[0], 0.0, d[0])),
        # rotx(alpha5) rotz(theta6) transz(d6): transz(d6) moves into the tool transform
        tool_inv=inv(trans(0.0, 0.0, d[5]) @ tool),
        offset=off.copy(),
        tol_sq=64 * _EPS * scale * scale,
        tol_4=64 * _EPS * scale ** 4,
    )


class URSolver:
    """Hawkins's closed form for the UR family: 8 branches (shoulder x wrist x elbow)."""

    family = "ur"
    complete = True
    n_branches = 8

    def __init__(self, p: _UR) -> None:
        self.p = p

    @classmethod
    def make(cls, dh: np.ndarray, base: np.ndarray, tool: np.ndarray, unit: str = "") -> "URSolver | str":
        """The solver for a DH table of the family, or the reason the table is not of it."""
        p = ur_structure(dh, base, tool, unit)
        return p if isinstance(p, str) else cls(p)

    def branches(self, T: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The eight closed-form branches of n world tool poses T (n, 4, 4): (theta (6, n, 8) rad, ok (n, 8)).

        Branch = 4*shoulder + 2*wrist + elbow (0 = the "+" root, 1 = the "-" root).
        Singularities (documented choices, every ok row is a true solution):
        - wrist (|sin theta5| < 1e-12: axis 6 parallel to axes 2, 3, 4): theta6 is free
          (it trades with theta2 + theta3 + theta4); q6 = 0 and the second wrist root,
          the same family, is dropped;
        - shoulder (the wrist point at distance |D| from axis 1: the two theta1 roots
          coincide) and elbow (full stretch or fold: the two theta3 roots coincide): the
          second root is dropped, so no row is listed twice. A discriminant within 64 eps
          of zero (in L^2, L^4 with L the arm's length scale) counts as zero.
        - D = 0 and the wrist point on axis 1 (not a real UR): theta1 is free; q1 = 0.
        """
        k = self.p
        T = np.asarray(T, float)
        n = T.shape[0]
        a2, a3, D, d5 = k.a2, k.a3, k.D, k.d5
        sign = np.array([1.0, -1.0])

        # Flange frame (d6 removed) in frame 0: 0T6 = base^-1 T tool^-1. Its origin is the
        # wrist point p5 (Hawkins's P05 = T06 (0, 0, -d6, 1)^T, his first step).
        T06 = k.base_inv @ T @ k.tool_inv
        px, py = T06[:, 0, 3], T06[:, 1, 3]
        R = T06[:, :3, :3]

        # --- theta1. Axes 2..4 point along n = z2 = (s1, -c1, 0) and every point of the
        # arm past joint 1 lies at n.p = D on them: s1 px - c1 py = D, i.e.
        #   theta1 = Atan2(py, px) + Atan2(D, +-sqrt(px^2 + py^2 - D^2))
        # (Hawkins: theta1 = atan2(p05y, p05x) +- acos(d4 / sqrt(p05x^2 + p05y^2)) + pi/2, the same
        # roots: acos(x) = pi/2 - asin(x)).
        rho2 = px * px + py * py
        disc1 = rho2 - D * D
        ok1 = disc1 >= -k.tol_sq
        root1 = np.sqrt(np.where(disc1 > k.tol_sq, disc1, 0.0))
        th1 = np.arctan2(py, px)[:, None] + np.arctan2(D, sign * root1[:, None])  # (n, 2)
        th1 = np.where((rho2 <= k.tol_sq)[:, None], k.offset[0], th1)  # D = 0 on axis 1: q1 = 0
        ok_sh = np.empty((n, 2), dtype=bool)
        ok_sh[:, 0], ok_sh[:, 1] = ok1, ok1 & (disc1 > k.tol_sq)
        c1, s1 = np.cos(th1), np.sin(th1)

        # --- theta5. z6 = y5 = -s5 x4 + c5 n, so c5 = n . z6:
        #   theta5 = Atan2(+-sqrt(1 - c5^2), c5)
        # (Hawkins: theta5 = +-acos((p06x s1 - p06y c1 - d4) / d6), n . p6 = d4 + d6 c5 there).
        c5 = np.clip(s1 * R[:, None, 0, 2] - c1 * R[:, None, 1, 2], -1.0, 1.0)  # (n, 2)
        # --- theta6. n in the flange frame is w = 0R6^T n = (s5 c6, -s5 s6, c5):
        #   theta6 = Atan2(-wy / s5, wx / s5)
        # (Hawkins: theta6 = atan2((-X60y s1 + Y60y c1) / s5, (X60x s1 - Y60x c1) / s5), his X60, Y60
        # being the rows of 0R6 these dot products read).
        wx = s1 * R[:, None, 0, 0] - c1 * R[:, None, 1, 0]
        wy = s1 * R[:, None, 0, 1] - c1 * R[:, None, 1, 1]
        s5abs = np.hypot(wx, wy)  # = |s5|, better conditioned than sqrt(1 - c5^2) near c5 = +-1
        sing = s5abs < _SING_S5
        th5 = np.empty((n, 2, 2))
        th5[..., 0], th5[..., 1] = np.arctan2(s5abs, c5), np.arctan2(-s5abs, c5)
        th6p = np.where(sing, k.offset[5], np.arctan2(-wy, wx))  # s5 > 0; wrist singular: q6 = 0
        th6 = np.empty((n, 2, 2))
        th6[..., 0] = th6p
        th6[..., 1] = np.where(sing, th6p, th6p + math.pi)  # s5 < 0: both signs of the Atan2 flip
        s5 = np.sin(th5)
        c5b = np.cos(th5)
        c6, s6 = np.cos(th6), np.sin(th6)

        # --- frame 4 from the flange: 4R6^T e_x = (c5 c6, -c5 s6, -s5), 4R6^T e_y = (s6, c6, 0), so
        #   x4 = 0R6 (c5 c6, -c5 s6, -s5),  y4 = 0R6 (s6, c6, 0),  p4 = p5 + d5 y4
        # (Hawkins: T14 = T10 T06 T65 T54, with T46 = A5 A6 known once theta5, theta6 are).
        def col(j: int) -> np.ndarray:
            return R[:, None, None, :, j]  # (n, 1, 1, 3)
        ex = (c5b * c6)[..., None] * col(0) - (c5b * s6)[..., None] * col(1) - s5[..., None] * col(2)
        ey = s6[..., None] * col(0) + c6[..., None] * col(1)
        p4 = T06[:, None, None, :3, 3] + d5 * ey  # (n, 2, 2, 3)

        # --- theta2, theta3, theta4: in frame 1' = rotz(theta1) rotx(90) (x = (c1, s1, 0), y = z0,
        # z = n) the links 2..4 are a planar 3R arm: (X, Y) = (a2 c2 + a3 c23, a2 s2 + a3 s23) and
        # theta234 = Atan2(y1' . x4, x1' . x4).
        C1, S1 = c1[:, :, None], s1[:, :, None]
        X = C1 * p4[..., 0] + S1 * p4[..., 1]
        Y = p4[..., 2]
        th234 = np.arctan2(ex[..., 2], C1 * ex[..., 0] + S1 * ex[..., 1])
        #   c3 = (X^2 + Y^2 - a2^2 - a3^2) / (2 a2 a3),  theta3 = Atan2(+-sqrt(1 - c3^2), c3)
        # (Hawkins: theta3 = +-acos((|P14xz|^2 - a2^2 - a3^2) / (2 a2 a3))), written with lengths so
        # the tolerance is one of L^4:
        m = 2.0 * a2 * a3
        Kl = X * X + Y * Y - a2 * a2 - a3 * a3
        disc3 = m * m - Kl * Kl
        ok3 = disc3 >= -k.tol_4
        root3 = np.sqrt(np.where(disc3 > k.tol_4, disc3, 0.0))
        sm = math.copysign(1.0, m)
        th3 = np.arctan2(sign * root3[..., None] * sm, (Kl * sm)[..., None])  # (n, 2, 2, 2)
        #   theta2 = Atan2(Y, X) - Atan2(a3 s3, a2 + a3 c3)
        # (Hawkins: theta2 = -atan2(P14z, -P14x) + asin(a3 sin theta3 / |P14xz|), the same angle in
        # his frame signs), and theta4 = theta234 - theta2 - theta3.
        s3, c3 = np.sin(th3), np.cos(th3)
        th2 = np.arctan2(Y, X)[..., None] - np.arctan2(a3 * s3, a2 + a3 * c3)
        th4 = th234[..., None] - th2 - th3
        ok_el = np.empty((n, 2, 2, 2), dtype=bool)
        ok_el[..., 0], ok_el[..., 1] = ok3, ok3 & (disc3 > k.tol_4)

        # Assemble joint-major, (6, n, shoulder, wrist, elbow).
        theta = np.empty((6, n, 2, 2, 2))
        theta[0] = th1[:, :, None, None]
        theta[1], theta[2], theta[3] = th2, th3, th4
        theta[4] = th5[..., None]
        theta[5] = th6[..., None]
        ok = np.empty((n, 2, 2, 2), dtype=bool)
        ok[:] = ok_sh[:, :, None, None] & ok_el
        ok[:, :, 1, :] &= ~sing[:, :, None]  # wrist singular: the second root is the same family
        return theta.reshape(6, n, 8), ok.reshape(n, 8)
