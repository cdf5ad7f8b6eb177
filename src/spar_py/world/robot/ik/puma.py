"""The PUMA family (any 6R arm of the PUMA 560 family: spherical wrist): all eight closed-form branches.

The CMS checks condition 2 of a reachable constraint (Sec. 5.2.4) by asking "does
the arm have an in-limit inverse kinematic solution for T = T_O T_g?". The paper
points to Paul's book [21] for the PUMA; we follow the same closed form as given
in Craig, *Introduction to Robotics*, Sec. 4.7 ("The PUMA 560"), in Craig's
(modified) Denavit-Hartenberg convention. Equation numbers differ between Craig's
editions, so each step below quotes the equation it implements.

Frames and units: ``T`` arguments are ``T_world_tool`` (4x4, column vectors), with
lengths in the robot's unit; the angles returned are the DH angles theta_i (rad);
the robot subtracts the offsets and applies the joint limits (common.py).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from spar_py.core.geometry import inv, rotx, trans

__all__ = ["PUMA_TWISTS", "PumaSolver", "puma_structure"]

_EPS = np.finfo(float).eps
_SING_S5 = 1e-12  # |sin theta5| below this: wrist singular (axes 4 and 6 aligned)
# Craig's PUMA 560 twists alpha_1..alpha_5 (rows 2..6 of the table), radians.
PUMA_TWISTS = (-math.pi / 2, 0.0, -math.pi / 2, math.pi / 2, -math.pi / 2)


@dataclass(frozen=True)
class _Puma:
    """The table reduced to Craig's PUMA 560 parameters, plus the constant frames absorbed."""

    a2: float
    a3: float
    d3: float  # d2 + d3 (z2 and z3 are parallel, the two offsets add)
    d4: float
    base_inv: np.ndarray  # inv(base @ rotx(alpha0) @ trans(a0, 0, d1))
    tool_inv: np.ndarray  # inv(trans(0, 0, d6) @ tool)
    offset: np.ndarray  # (6,) theta_i - q_i
    tol_sq: float  # length^2 below which a discriminant counts as zero


def puma_structure(dh: np.ndarray, base: np.ndarray, tool: np.ndarray, unit: str = "") -> _Puma | str:
    """Craig's PUMA parameters of a DH table, or the reason the table is not of that family
    (lengths in ``unit``, the table's)."""
    alpha, a, d, off = dh.T
    for i, want in enumerate(PUMA_TWISTS, start=1):
        if abs(math.remainder(alpha[i] - want, 2 * math.pi)) > 1e-9:
            return (f"alpha_{i} (dh[{i}].alpha) = {math.degrees(alpha[i]):g} deg where the family has "
                    f"{math.degrees(want):g}")
    for what, v in (("a_1 (dh[1].a)", a[1]), ("a_4 (dh[4].a)", a[4]), ("a_5 (dh[5].a)", a[5]),
                    ("d_5 (dh[4].d)", d[4])):
        if v != 0.0:
            return (f"{what} = {v:g} {unit} where the family has 0 (an offset the spherical-wrist closed "
                    "form does not handle)").replace("  ", " ")
    if a[2] == 0.0:
        return "a_2 (dh[2].a) = 0 where the family needs an upper arm"
    scale = abs(a[2]) + abs(a[3]) + abs(d[1] + d[2]) + abs(d[3])
    return _Puma(
        a2=float(a[2]), a3=float(a[3]), d3=float(d[1] + d[2]), d4=float(d[3]),
        # rotx(alpha0) transx(a0) rotz(theta1) transz(d1): the constant parts commute out
        base_inv=inv(base @ rotx(alpha[0]) @ trans(a[0], 0.0, d[0])),
        # rotz(theta6) transz(d6): transz(d6) moves into the tool transform
        tool_inv=inv(trans(0.0, 0.0, d[5]) @ tool),
        offset=off.copy(),
        tol_sq=64 * _EPS * scale * scale,
    )



class PumaSolver:
    """Craig's closed form for the PUMA 560 family: 8 branches (shoulder x elbow x wrist flip)."""

    family = "puma"
    complete = True
    n_branches = 8

    def __init__(self, p: _Puma) -> None:
        self.p = p

    @classmethod
    def make(cls, dh: np.ndarray, base: np.ndarray, tool: np.ndarray, unit: str = "") -> "PumaSolver | str":
        """The solver for a DH table of the family, or the reason the table is not of it."""
        p = puma_structure(dh, base, tool, unit)
        return p if isinstance(p, str) else cls(p)

    def branches(self, T: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The eight closed-form branches of n world tool poses T (n, 4, 4): (theta (6, n, 8) rad, ok (n, 8)).

        Branch = 4*shoulder + 2*elbow + flip (0 = Craig's "+" root, 1 = "-").
        Singularities (documented choices, every ok row is a true solution):
        - wrist (|sin theta5| < 1e-12, axes 4 and 6 aligned): q4 = 0 and the whole
          rotation goes on q6; the flipped wrist is dropped (it is the same family).
        - shoulder (wrist centre on the z0 axis, only possible when d3 = 0): q1 = 0.
        - coinciding roots (shoulder with r = 0, elbow at full stretch): the second
          root is dropped, so no row is listed twice. A discriminant within 64 eps L^2
          of zero (L the arm's length scale) counts as zero, so a pose beyond full
          stretch by float rounding (~1e-13 L) is still solved.
        """
        k = self.p
        T = np.asarray(T, float)
        n = T.shape[0]
        a2, a3, d3, d4, tol = k.a2, k.a3, k.d3, k.d4, k.tol_sq

        # Frame 6 (flange, d6 removed) in frame 0: 0T6 = base^-1 T tool^-1. With a spherical
        # wrist the origins of frames 4, 5 and 6 coincide: (px, py, pz) is the wrist centre.
        T06 = k.base_inv @ T @ k.tool_inv
        px, py, pz = T06[:, 0, 3], T06[:, 1, 3], T06[:, 2, 3]
        R = T06[:, :3, :3]

        # --- theta1:  theta1 = Atan2(py, px) - Atan2(d3, +-sqrt(px^2 + py^2 - d3^2))
        rho2 = px * px + py * py
        disc1 = rho2 - d3 * d3
        ok1 = disc1 >= -tol
        root1 = np.sqrt(np.where(disc1 > tol, disc1, 0.0))
        sign = np.array([1.0, -1.0])
        th1 = np.arctan2(py, px)[:, None] - np.arctan2(d3, sign * root1[:, None])  # (n, 2)
        # shoulder singularity (d3 = 0 and the wrist centre on z0): theta1 is free; take q1 = 0
        th1 = np.where((rho2 <= tol)[:, None], k.offset[0], th1)
        ok_sh = np.empty((n, 2), dtype=bool)
        ok_sh[:, 0], ok_sh[:, 1] = ok1, ok1 & (disc1 > tol)  # equal roots: keep one

        # --- theta3:  K = (px^2 + py^2 + pz^2 - a2^2 - a3^2 - d3^2 - d4^2) / (2 a2)
        #              theta3 = Atan2(a3, d4) - Atan2(K, +-sqrt(a3^2 + d4^2 - K^2))
        K = (rho2 + pz * pz - a2 * a2 - a3 * a3 - d3 * d3 - d4 * d4) / (2.0 * a2)
        disc3 = a3 * a3 + d4 * d4 - K * K
        ok3 = disc3 >= -tol
        root3 = np.sqrt(np.where(disc3 > tol, disc3, 0.0))
        th3 = math.atan2(a3, d4) - np.arctan2(K[:, None], sign * root3[:, None])  # (n, 2)
        ok_el = np.empty((n, 2), dtype=bool)
        ok_el[:, 0], ok_el[:, 1] = ok3, ok3 & (disc3 > tol)

        # --- theta2 via theta23 (shoulder x elbow -> axes (n, 2, 2)):
        #   s23 = [(-a3 - a2 c3) pz + (c1 px + s1 py)(a2 s3 - d4)] / (pz^2 + (c1 px + s1 py)^2)
        #   c23 = [(a2 s3 - d4) pz + (a3 + a2 c3)(c1 px + s1 py)] / (pz^2 + (c1 px + s1 py)^2)
        #   theta23 = Atan2(s23, c23) (the common positive denominator drops), theta2 = theta23 - theta3
        c1, s1 = np.cos(th1)[:, :, None], np.sin(th1)[:, :, None]
        c3, s3 = np.cos(th3)[:, None, :], np.sin(th3)[:, None, :]
        r = c1 * px[:, None, None] + s1 * py[:, None, None]
        A = a3 + a2 * c3
        B = a2 * s3 - d4
        pzb = pz[:, None, None]
        th23 = np.arctan2(-A * pzb + r * B, B * pzb + A * r)
        th2 = th23 - th3[:, None, :]
        c23, s23 = np.cos(th23), np.sin(th23)

        # --- wrist: 3R6 = 0R3^T 0R6 (W). Columns of 0R3: x3 = (c1 c23, s1 c23, -s23),
        # y3 = (-c1 s23, -s1 s23, -c23), z3 = (-s1, c1, 0). Only W's columns 0 and 2 are needed.
        x3 = (c1 * c23, s1 * c23, -s23)
        y3 = (-c1 * s23, -s1 * s23, -c23)
        z3 = (-s1, c1, 0.0)

        def dot(u: tuple, col: int) -> np.ndarray:
            return (u[0] * R[:, 0, col, None, None] + u[1] * R[:, 1, col, None, None]
                    + u[2] * R[:, 2, col, None, None])

        W00, W10, W20 = dot(x3, 0), dot(y3, 0), dot(z3, 0)
        W02, W12, W22 = dot(x3, 2), dot(y3, 2), dot(z3, 2)

        # theta4 = Atan2(-r13 s1 + r23 c1, -r13 c1 c23 - r23 s1 c23 + r33 s23) = Atan2(W22, -W02)
        sing = np.hypot(W02, W22) < _SING_S5
        th4 = np.where(sing, k.offset[3], np.arctan2(W22, -W02))  # wrist singular: q4 = 0
        c4, s4 = np.cos(th4), np.sin(th4)
        # theta5 = Atan2(s5, c5) with (from 4R6, computed with theta4 found above)
        #   s5 = -[r13(c1 c23 c4 + s1 s4) + r23(s1 c23 c4 - c1 s4) - r33 s23 c4] = -(c4 W02 - s4 W22)
        #   c5 = r13(-c1 s23) + r23(-s1 s23) + r33(-c23) = W12
        s5v = -(c4 * W02 - s4 * W22)
        th5 = np.arctan2(s5v, W12)
        c5, s5 = np.cos(th5), np.sin(th5)
        # theta6 = Atan2(s6, c6) with (from 5R6, computed with theta4, theta5 found above)
        #   s6 = -r11(c1 c23 s4 - s1 c4) - r21(s1 c23 s4 + c1 c4) + r31 s23 s4 = -(s4 W00 + c4 W20)
        #   c6 = r11[(c1 c23 c4 + s1 s4) c5 - c1 s23 s5] + r21[(s1 c23 c4 - c1 s4) c5 - s1 s23 s5]
        #        - r31 (s23 c4 c5 + c23 s5) = c5 (c4 W00 - s4 W20) + s5 W10
        th6 = np.arctan2(-(s4 * W00 + c4 * W20), c5 * (c4 * W00 - s4 * W20) + s5 * W10)

        # --- the flipped wrist: theta4' = theta4 + pi, theta5' = -theta5, theta6' = theta6 + pi.
        # Assemble joint-major, (6, n, shoulder, elbow, flip): every write is contiguous.
        theta = np.empty((6, n, 2, 2, 2))
        theta[0] = th1[:, :, None, None]
        theta[1] = th2[..., None]
        theta[2] = th3[:, None, :, None]
        theta[3, ..., 0], theta[3, ..., 1] = th4, th4 + math.pi
        theta[4, ..., 0], theta[4, ..., 1] = th5, -th5
        theta[5, ..., 0], theta[5, ..., 1] = th6, th6 + math.pi
        ok = np.empty((n, 2, 2, 2), dtype=bool)
        ok[..., 0] = ok_sh[:, :, None] & ok_el[:, None, :]
        ok[..., 1] = ok[..., 0] & ~sing  # wrist singular: the flip is the same family
        return theta.reshape(6, n, 8), ok.reshape(n, 8)

