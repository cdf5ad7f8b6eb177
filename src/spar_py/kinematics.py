"""PUMA 762 kinematics (any 6R arm of the PUMA 560 family): forward and all closed-form inverse solutions.

The CMS checks condition 2 of a reachable constraint (Sec. 5.2.4) by asking "does
the arm have an in-limit inverse kinematic solution for T = T_O T_g?". The paper
points to Paul's book [21] for the PUMA; we follow the same closed form as given
in Craig, *Introduction to Robotics*, Sec. 4.7 ("The PUMA 560"), in Craig's
(modified) Denavit-Hartenberg convention. Equation numbers differ between Craig's
editions, so each step below quotes the equation it implements.

Frames and units: ``T`` arguments are ``T_world_tool`` (4x4, column vectors), with
lengths in ``Robot.unit`` (the unit the robot was loaded in); joint vectors ``q``
are in radians, in the DH zero convention of the robot file (``theta_i = q_i +
offset_i``). Limits are checked with a tolerance of 1e-9 rad.

This module is the model only: reading a robot file (``kb/robots/*.yaml``) is
:func:`spar_py.kb.load_robot`'s job, so kinematics knows nothing of YAML or the KB.
"""
from __future__ import annotations

import itertools
import math
from dataclasses import dataclass, field

import numpy as np

from .errors import SparValueError
from .geometry import check_transform, inv, rotx, trans

__all__ = ["LIMIT_TOL", "Robot"]

LIMIT_TOL = 1e-9  # rad: a joint value this far outside its limits still counts as inside
_EPS = np.finfo(float).eps
_SING_S5 = 1e-12  # |sin theta5| below this: wrist singular (axes 4 and 6 aligned)
# Craig's PUMA 560 twists alpha_1..alpha_5 (rows 2..6 of the table), radians.
_PUMA_ALPHAS = (-math.pi / 2, 0.0, -math.pi / 2, math.pi / 2, -math.pi / 2)


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


def _puma_structure(dh: np.ndarray, base: np.ndarray, tool: np.ndarray, unit: str = "") -> _Puma | str:
    """Craig's PUMA parameters of a DH table, or the reason the table is not of that family
    (lengths in ``unit``, the table's)."""
    alpha, a, d, off = dh.T
    for i, want in enumerate(_PUMA_ALPHAS, start=1):
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


@dataclass(eq=False)
class Robot:
    """A 6R arm: Craig DH table, joint limits, base and tool frames, gripper opening.

    ``dh`` is (6, 4): alpha_{i-1} (rad), a_{i-1} (``unit``), d_i (``unit``), offset_i
    = theta_i - q_i (rad); ``limits`` (6, 2) rad; ``base`` is T_world_frame0 and
    ``tool`` T_flange_tool (4x4, ``unit``); ``finger_separation`` is W_m (``unit``).
    """

    name: str
    dh: np.ndarray
    limits: np.ndarray
    base: np.ndarray
    tool: np.ndarray
    finger_separation: float
    unit: str
    _puma: _Puma | str = field(init=False, repr=False)
    _reps: tuple[int, ...] = field(init=False, repr=False)
    _turns: tuple[np.ndarray, np.ndarray, np.ndarray] = field(init=False, repr=False)

    def __post_init__(self) -> None:
        """Check shapes, precompute the closed-form parameters and the per-joint turn counts."""
        self.dh = np.array(self.dh, dtype=float)
        self.limits = np.array(self.limits, dtype=float)
        self.base = np.array(self.base, dtype=float)
        self.tool = np.array(self.tool, dtype=float)
        for what, arr, shape in (("dh", self.dh, (6, 4)), ("limits", self.limits, (6, 2)),
                                 ("base", self.base, (4, 4)), ("tool", self.tool, (4, 4))):
            if arr.shape != shape or not np.all(np.isfinite(arr)):
                raise SparValueError(f"robot {self.name}: {what} must be a finite {shape} array, got {arr.shape}")
        if np.any(self.limits[:, 0] > self.limits[:, 1]):
            raise SparValueError(f"robot {self.name}: limits need lo <= hi")
        self._puma = _puma_structure(self.dh, self.base, self.tool, self.unit)
        # how many representations q + 2 pi k of one angle can lie inside each joint's range
        span = self.limits[:, 1] - self.limits[:, 0] + 2 * LIMIT_TOL
        self._reps = tuple(int(s // (2 * math.pi)) + 1 for s in span)
        # turn combinations, row-major over the joints: k[c, j] full turns added to joint j
        k = np.array(list(itertools.product(*(range(m) for m in self._reps))), dtype=float)
        self._turns = ((self.limits[:, 0] - LIMIT_TOL)[:, None, None],
                       (self.limits[:, 1] + LIMIT_TOL)[:, None, None],
                       (2 * math.pi * k.T)[:, None, None, :])

    # ------------------------------------------------------------------ forward kinematics

    def fk(self, q: np.ndarray) -> np.ndarray:
        """World pose of the tool (4x4, ``unit``) for joint vector q (6,) rad: base @ A1..A6 @ tool."""
        q = np.asarray(q, float)
        if q.shape != (6,):
            raise SparValueError(f"fk takes a joint vector of shape (6,), got {q.shape}")
        return self.fk_batch(q[None])[0]

    def fk_batch(self, q: np.ndarray) -> np.ndarray:
        """World tool poses (n, 4, 4) for joint vectors q (n, 6) rad, vectorised over n."""
        q = np.asarray(q, float)
        if q.ndim != 2 or q.shape[1] != 6:
            raise SparValueError(f"fk_batch takes joint vectors of shape (n, 6), got {q.shape}")
        A = self._links(q)
        T = self.base @ A[:, 0]
        for i in range(1, 6):
            T = T @ A[:, i]
        return T @ self.tool

    def tool_inverse(self) -> np.ndarray:
        """inv(tool), T_tool_flange (4x4), computed once per value of ``tool``."""
        key = self.tool.tobytes()
        cached = self.__dict__.get("_tool_inv")
        if cached is None or cached[0] != key:
            cached = self.__dict__["_tool_inv"] = (key, np.linalg.inv(self.tool))
        return cached[1]

    # ------------------------------------------------------------------ limits

    def in_limits(self, q: np.ndarray) -> np.ndarray | bool:
        """True where every joint of q (..., 6) rad lies within its limits (tolerance 1e-9 rad)."""
        q = np.asarray(q, float)
        ok = np.all((q >= self.limits[:, 0] - LIMIT_TOL) & (q <= self.limits[:, 1] + LIMIT_TOL), axis=-1)
        return bool(ok) if ok.ndim == 0 else ok

    @property
    def n_candidates(self) -> int:
        """Candidate rows per pose in :meth:`ik_batch`: 8 branches x the in-limit turn representations."""
        return 8 * math.prod(self._reps)

    # ------------------------------------------------------------------ inverse kinematics

    @property
    def unsupported(self) -> str | None:
        """Why the closed-form IK cannot solve this arm (which DH entry breaks the PUMA 560
        family's structure), or None when it can."""
        return self._puma if isinstance(self._puma, str) else None

    def _structure(self) -> _Puma:
        if isinstance(self._puma, str):
            raise SparValueError(f"robot {self.name}: no closed-form IK: not a PUMA 560 family arm ({self._puma})")
        return self._puma

    def ik(self, T: np.ndarray) -> np.ndarray:
        """All in-limit joint vectors (k, 6) rad reaching the world tool pose T (4x4, ``unit``); (0, 6) if none.

        Rows come in the order of :meth:`ik_batch`'s candidates (shoulder, elbow,
        wrist flip, then turn representations); see there for singular poses.
        """
        T = check_transform(T, "ik: T")
        Q, ok = self.ik_batch(T[None])
        return Q[0][ok[0]]

    def reachable_mask(self, T: np.ndarray) -> np.ndarray:
        """(n,) bool: which world tool poses T (n, 4, 4) have at least one in-limit IK solution.

        The same answer as ``ik_batch(T)[1].any(axis=1)`` without listing the turn
        representations: the candidates of a branch are every combination of per-joint
        representations q + 2 pi k, each joint's lowest one (>= its lower limit) among
        them, so some combination is in limits iff every joint's lowest one is.
        """
        theta, ok, offset = self._branches(T)
        lo, hi, _ = self._turns
        q = theta - offset[:, None, None]
        q0 = q - (2 * math.pi) * np.floor((q - lo + LIMIT_TOL) * (0.5 / math.pi))
        return (ok & (q0 <= hi + LIMIT_TOL).all(axis=0)).any(axis=1)

    def ik_batch(self, T: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """All closed-form IK candidates for n world tool poses, vectorised: ``(Q (n, C, 6) rad, ok (n, C) bool)``.

        ``C = self.n_candidates`` (32 for the PUMA 762: 8 branches x 2 wrist-roll x
        2 swivel representations). Candidate ``c`` is branch ``c // M`` (``M = C //
        8``), branch = 4*shoulder + 2*elbow + flip (0 = Craig's "+" root, 1 = "-"),
        then the ``c % M``-th combination of turn representations q + 2 pi k of the
        multi-turn joints. ``ok[i, c]`` is True iff candidate c is a solution for
        pose i inside the joint limits; rows with ok False hold garbage. A caller
        that only needs reachability uses ``ok.any(axis=1)``.

        Singularities (documented choices, every returned row is a true solution):
        - wrist (|sin theta5| < 1e-12, axes 4 and 6 aligned): q4 = 0 and the whole
          rotation goes on q6; the flipped wrist is dropped (it is the same family).
          Conservative: were q6's range under a full turn, a pose whose rotation q6
          cannot take alone would be reported unreachable (not so for the PUMA 762).
        - shoulder (wrist centre on the z0 axis, only possible when d3 = 0): q1 = 0.
        - coinciding roots (shoulder with r = 0, elbow at full stretch): the second
          root is dropped, so no row is listed twice. A discriminant within 64 eps L^2
          of zero (L the arm's length scale) counts as zero, so a pose beyond full
          stretch by float rounding (~1e-13 L) is still solved.
        """
        return self._representations(*self._branches(T))

    def _branches(self, T: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The eight closed-form branches of n poses: (theta (6, n, 8) rad, ok (n, 8), offsets (6,))."""
        k = self._structure()
        T = np.asarray(T, float)
        if T.ndim != 3 or T.shape[1:] != (4, 4):
            raise SparValueError(f"ik_batch takes poses of shape (n, 4, 4), got {T.shape}")
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
        return theta.reshape(6, n, 8), ok.reshape(n, 8), k.offset

    def _representations(self, theta: np.ndarray, ok: np.ndarray,
                         offset: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Joint angles theta (6, n, 8) -> every in-limit q + 2 pi k: ((n, 8 M, 6), (n, 8 M)), M turn combinations."""
        n = theta.shape[1]
        lo, hi, shift = self._turns
        q = theta - offset[:, None, None]
        # the lowest representation >= lo of each angle (these lie within a few turns of 0)
        # (within LIMIT_TOL: an angle a rounding error below lo is at lo, not a turn above it)
        q0 = q - (2 * math.pi) * np.floor((q - lo + LIMIT_TOL) * (0.5 / math.pi))
        Q = q0[..., None] + shift  # (6, n, 8, M): combination c adds 2 pi k_j(c) to joint j
        V = ok[..., None] & (Q <= hi[..., None] + LIMIT_TOL).all(axis=0)
        M = shift.shape[-1]
        return Q.transpose(1, 2, 3, 0).reshape(n, 8 * M, 6), V.reshape(n, 8 * M)

    # ------------------------------------------------------------------ frames (drawing)

    def _links(self, q: np.ndarray) -> np.ndarray:
        """Link transforms A_1..A_6 (n, 6, 4, 4), frame i-1 -> frame i (``unit``), for q (n, 6) rad."""
        alpha, a, d, off = self.dh.T
        th = q + off
        ct, st = np.cos(th), np.sin(th)
        ca, sa = np.cos(alpha), np.sin(alpha)
        # Craig's link transform (3.6): rotx(alpha_{i-1}) transx(a_{i-1}) rotz(theta_i) transz(d_i)
        A = np.zeros(q.shape + (4, 4))
        A[..., 0, 0], A[..., 0, 1], A[..., 0, 3] = ct, -st, a
        A[..., 1, 0], A[..., 1, 1], A[..., 1, 2], A[..., 1, 3] = st * ca, ct * ca, -sa, -sa * d
        A[..., 2, 0], A[..., 2, 1], A[..., 2, 2], A[..., 2, 3] = st * sa, ct * sa, ca, ca * d
        A[..., 3, 3] = 1.0
        return A

    def frames(self, q: np.ndarray) -> np.ndarray:
        """World frames (8, 4, 4) (``unit``) of the arm at joint vector q (6,) rad, DH zero convention.

        Row 0 is ``base`` (T_world_frame0), rows 1..6 T_world_frame_i = base @ A_1..A_i
        (frame 6 is the flange), row 7 the tool, ``frames[6] @ tool`` (equal to :meth:`fk`).
        The link transforms are :meth:`fk_batch`'s own.
        """
        q = np.asarray(q, float)
        if q.shape != (6,):
            raise SparValueError(f"frames takes a joint vector of shape (6,), got {q.shape}")
        A = self._links(q[None])[0]
        out = np.empty((8, 4, 4))
        out[0] = self.base
        for i in range(6):
            out[i + 1] = out[i] @ A[i]
        out[7] = out[6] @ self.tool
        return out
