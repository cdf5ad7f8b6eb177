"""The one place that says whether the arm reaches a tool pose: "the arm has an in-limit
joint solution for T, with its wrist above the table top".

Phase 1's reach arcs (reach.py), the put-down placement search (placement.py) and
phase 2's steps (phase2.py) all ask here, so the rule is written once. The paper's
condition 2 of a reachable constraint (Sec. 5.2.4) looks at joint limits only; a tool
pose whose wrist (the flange origin) would be under the table top (z = 0), e.g. a
grasp from below, is refused too, so the CMS stays conservative (Sec. 7.1).

Frames and units: ``T`` is ``T_world_tool`` (4x4, or a batch (n, 4, 4)), lengths in the
robot's unit (the cell's); joint vectors in radians, in the robot file's DH zero
convention; world Z up, table top z = 0.
"""
from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from .world.robots import Robot

__all__ = ["reaches", "solutions", "wrist_above_table", "wrist_height"]


def wrist_height(robot: Robot, T: np.ndarray) -> np.ndarray:
    """(n,): the height above the table top of the flange (wrist) origin for world tool
    poses T (n, 4, 4)."""
    return (np.asarray(T, float) @ robot.tool_inverse())[:, 2, 3]


def wrist_above_table(robot: Robot, T: np.ndarray) -> np.ndarray:
    """(n,) bool: for world tool poses T (n, 4, 4), the flange (wrist) origin lies above z = 0."""
    return wrist_height(robot, T) > 0.0


def reaches(robot: Robot, T: np.ndarray) -> np.ndarray:
    """(n,) bool: the arm reaches each world tool pose of T (n, 4, 4) within its joint
    limits, wrist above the table; one batched IK call."""
    T = np.asarray(T, float)
    if not len(T):
        return np.zeros(0, dtype=bool)
    return robot.reachable_mask(T) & wrist_above_table(robot, T)


def solutions(robot: Robot, T: np.ndarray) -> np.ndarray:
    """(k, 6): every in-limit joint vector (rad) reaching world tool pose T (4x4), none
    (k = 0) when the wrist would be under the table."""
    T = np.asarray(T, float)
    if not wrist_above_table(robot, T[None])[0]:
        return np.zeros((0, 6))
    sols = np.asarray(robot.ik(T), float)
    return sols.reshape(-1, 6)
