"""What every IK solver shares: Craig's link transform, the solver interface, turn representations.

Frames and units: a DH table is Craig's (modified) convention, one row per joint i =
1..6: ``(alpha_{i-1} rad, a_{i-1}, d_i, offset_i rad)`` with ``theta_i = q_i +
offset_i``; lengths in the robot's unit. A solver answers for poses of the flange
(frame 6) given in the world: ``T_world_tool @ inv(tool)``; it returns joint angles
``theta`` (the DH angles, not yet q) per *branch* (one distinct arm configuration),
and the robot (``spar_py.world.robot.model.Robot``) turns them into joint vectors q within
limits, so the limit and turn bookkeeping is written once for every family.
"""
from __future__ import annotations

import itertools
import math
from typing import Protocol

import numpy as np

__all__ = ["LIMIT_TOL", "Solver", "craig_links", "lowest_representation", "turn_combinations"]

LIMIT_TOL = 1e-9  # rad: a joint value this far outside its limits still counts as inside
TWO_PI = 2.0 * math.pi


class Solver(Protocol):
    """An IK solver for one arm: all the branches of n world flange poses at once."""

    #: family name shown in plan output: "puma", "ur" (closed form) or "numeric"
    family: str
    #: True when every solution is found by construction (closed form); False for numeric
    complete: bool
    #: branches per pose (8 for the closed forms; the number of starts for numeric)
    n_branches: int

    def branches(self, T_flange: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """For world flange poses (n, 4, 4): DH angles theta (6, n, B) rad and ok (n, B) bool
        (ok: branch b is a true solution of pose i; rows with ok False hold garbage)."""
        ...


def craig_links(dh: np.ndarray, q: np.ndarray) -> np.ndarray:
    """Link transforms A_1..A_6 (n, 6, 4, 4), frame i-1 -> frame i, for q (n, 6) rad.

    Craig's link transform (Introduction to Robotics, eq. 3.6):
    ``rotx(alpha_{i-1}) transx(a_{i-1}) rotz(theta_i) transz(d_i)``, theta_i = q_i + offset_i.
    """
    alpha, a, d, off = dh.T
    th = q + off
    ct, st = np.cos(th), np.sin(th)
    ca, sa = np.cos(alpha), np.sin(alpha)
    A = np.zeros(q.shape + (4, 4))
    A[..., 0, 0], A[..., 0, 1], A[..., 0, 3] = ct, -st, a
    A[..., 1, 0], A[..., 1, 1], A[..., 1, 2], A[..., 1, 3] = st * ca, ct * ca, -sa, -sa * d
    A[..., 2, 0], A[..., 2, 1], A[..., 2, 2], A[..., 2, 3] = st * sa, ct * sa, ca, ca * d
    A[..., 3, 3] = 1.0
    return A


def lowest_representation(q: np.ndarray, lo: np.ndarray) -> np.ndarray:
    """The lowest representation q + 2 pi k >= lo - LIMIT_TOL of each angle; q (6, ...) rad,
    lo (6, 1, ...) rad broadcasting against it (an angle a rounding error below lo is at lo)."""
    return q - TWO_PI * np.floor((q - lo + LIMIT_TOL) * (0.5 / math.pi))


def turn_combinations(limits: np.ndarray) -> np.ndarray:
    """(6, M) full-turn shifts 2 pi k_j: every combination of the representations q + 2 pi k
    that can lie inside each joint's range [lo, hi] (rad), row-major over the joints."""
    span = limits[:, 1] - limits[:, 0] + 2 * LIMIT_TOL
    reps = [int(s // TWO_PI) + 1 for s in span]
    k = np.array(list(itertools.product(*(range(m) for m in reps))), dtype=float)
    return TWO_PI * k.T
