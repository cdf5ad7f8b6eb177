"""Numeric IK for any 6R serial arm: multi-start damped least squares, vectorised over poses x starts.

For an arm of neither closed-form family (an offset wrist, a skewed axis, a URDF of an
arm nobody derived a closed form for) the planner still needs "all the in-limit joint
vectors reaching T". This solver starts Gauss-Newton with damping (Levenberg-Marquardt
style damped least squares on the geometric Jacobian, Wampler 1986; Buss 2004, eq. 11:
dq = J^T (J J^T + lambda^2 I)^-1 e) from a fixed set of starts spread over the joint
ranges, keeps the runs that converge to 1e-13 (position in units of the arm's length
scale, orientation in rad), and returns the distinct solutions, modulo full turns.

It is *not complete*: a solution no start falls towards is missed (a generic 6R arm
has up to 16), so plans report these joints as ``numeric``; "unreachable" from this
solver means "no start converged", not a proof. The starts are fixed (seeded), so
runs are reproducible.

Frames and units: ``T`` arguments are ``T_world_tool`` (4x4), lengths in the robot's
unit; the angles returned are the DH angles theta_i (rad) of Craig's table.
"""
from __future__ import annotations

import math

import numpy as np

from spar_py.world.robot.ik.common import craig_links

__all__ = ["NumericSolver"]

_TOL = 1e-13  # convergence: |e_pos| / L and |e_rot| (rad); Gauss-Newton gets there in a step or two
_SAME = 1e-6  # rad: two converged solutions closer than this (mod 2 pi, every joint) are one
_MAX_STEP = 0.5  # rad: the largest joint step of one iteration (keeps the linearisation honest)


class NumericSolver:
    """Multi-start damped least squares on Craig's chain; the distinct converged solutions."""

    family = "numeric"
    complete = False

    def __init__(self, dh: np.ndarray, base: np.ndarray, tool: np.ndarray, limits: np.ndarray,
                 starts: int = 32, iterations: int = 60, seed: int = 0) -> None:
        """``starts`` joint vectors drawn (``seed``) within ``limits`` (rad; at most one turn
        either side of 0), refined by at most ``iterations`` steps each."""
        self.dh = np.asarray(dh, float)
        self.base = np.asarray(base, float)
        self.tool = np.asarray(tool, float)
        self.iterations = iterations
        alpha, a, d, off = self.dh.T
        # the length scale that makes a position error comparable to an angle (rad)
        self.L = float(np.abs(a).sum() + np.abs(d).sum() + np.abs(self.tool[:3, 3]).sum()) or 1.0
        lo = np.maximum(limits[:, 0], -math.pi)
        hi = np.minimum(limits[:, 1], math.pi)
        lo, hi = np.where(lo < hi, lo, limits[:, 0]), np.where(lo < hi, hi, limits[:, 1])
        rng = np.random.default_rng(seed)
        self.starts = rng.uniform(lo, hi, size=(starts, 6))
        self.starts[0] = np.clip(0.0, limits[:, 0], limits[:, 1])  # the zero position first
        self.n_branches = starts

    def _flange(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """World joint axes z_i (m, 6, 3), joint origins p_i (m, 6, 3), tool poses (m, 4, 4) for q (m, 6)."""
        A = craig_links(self.dh, q)
        m = len(q)
        F = np.broadcast_to(self.base, (m, 4, 4))
        z = np.empty((m, 6, 3))
        p = np.empty((m, 6, 3))
        for i in range(6):
            F = F @ A[:, i]
            z[:, i], p[:, i] = F[:, :3, 2], F[:, :3, 3]
        return z, p, F @ self.tool

    def branches(self, T: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """For n world tool poses T (n, 4, 4): theta (6, n, S) rad, ok (n, S): the distinct
        converged solutions of each pose (S = the number of starts; duplicates ok False)."""
        T = np.asarray(T, float)
        n, S = T.shape[0], len(self.starts)
        if n == 0:
            return np.zeros((6, 0, S)), np.zeros((0, S), dtype=bool)
        q = np.tile(self.starts, (n, 1))  # (n S, 6), pose-major
        goal = np.repeat(T, S, axis=0)
        done = np.zeros(n * S, dtype=bool)
        active = np.arange(n * S)
        eye = np.eye(6)
        for _ in range(self.iterations):
            if not len(active):
                break
            qa, Ga = q[active], goal[active]
            z, p, E = self._flange(qa)
            ep = (Ga[:, :3, 3] - E[:, :3, 3]) / self.L
            # orientation error, world frame: 1/2 sum_k e_k x g_k (the rotation vector for small errors)
            er = 0.5 * np.cross(E[:, :3, :3], Ga[:, :3, :3], axis=1).sum(axis=2)
            e = np.concatenate([ep, er], axis=1)
            err = np.abs(e).max(axis=1)
            conv = err < _TOL
            done[active[conv]] = True
            # stop rows that converged, and rows whose error is not a number (a pose of nan or inf)
            keep = ~conv & np.isfinite(err)
            if not keep.any():
                break
            e, z, p, E, qa = e[keep], z[keep], p[keep], E[keep], qa[keep]
            active = active[keep]
            J = np.empty((len(active), 6, 6))
            J[:, :3, :] = np.cross(z, E[:, None, :3, 3] - p).transpose(0, 2, 1) / self.L
            J[:, 3:, :] = z.transpose(0, 2, 1)
            # damping -> 0 near a solution, never below 1e-12 (J J^T + lambda^2 I stays invertible at a
            # singular configuration; its entries are O(1) with positions in units of L)
            lam2 = np.clip((e * e).sum(axis=1) * 1e-2, 1e-12, 1e-4)[:, None, None]
            y = np.linalg.solve(J @ J.transpose(0, 2, 1) + lam2 * eye, e[..., None])
            dq = (J.transpose(0, 2, 1) @ y)[..., 0]
            big = np.abs(dq).max(axis=1, keepdims=True)
            dq *= np.minimum(1.0, _MAX_STEP / np.maximum(big, 1e-300))
            q[active] = qa + dq
        # a last check of the rows still active after the last step
        if len(active):
            z, p, E = self._flange(q[active])
            Ga = goal[active]
            ep = (Ga[:, :3, 3] - E[:, :3, 3]) / self.L
            er = 0.5 * np.cross(E[:, :3, :3], Ga[:, :3, :3], axis=1).sum(axis=2)
            done[active[np.maximum(np.abs(ep).max(axis=1), np.abs(er).max(axis=1)) < _TOL]] = True

        theta = (q + self.dh[:, 3]).reshape(n, S, 6)
        ok = done.reshape(n, S)
        # distinct modulo full turns: a converged row equal to an earlier converged row is dropped
        w = np.remainder(theta + math.pi, 2 * math.pi)
        diff = np.abs(w[:, :, None, :] - w[:, None, :, :])
        same = (np.minimum(diff, 2 * math.pi - diff) < _SAME).all(axis=3)  # (n, S, S)
        earlier = np.tril(np.ones((S, S), dtype=bool), k=-1)
        dup = (same & earlier & ok[:, None, :]).any(axis=2)
        return theta.transpose(2, 0, 1), ok & ~dup
