"""Craig's (modified DH) forward kinematics written out, for the IK tests to check against:
independent of spar_py.world.robot.ik (only the robot's table, base and tool are read)."""
from __future__ import annotations

import numpy as np

from spar_py.core.geometry import rotx, rotz, trans


def craig_fk(robot, q: np.ndarray) -> np.ndarray:
    """World tool poses (n, 4, 4) from Craig's link transform written out (eq. 3.6), one joint at a time."""
    out = np.empty((len(q), 4, 4))
    for k, qk in enumerate(q):
        T = robot.base.copy()
        for (alpha, a, d, off), qi in zip(robot.dh, qk):
            T = T @ rotx(alpha) @ trans(a, 0.0, 0.0) @ rotz(qi + off) @ trans(0.0, 0.0, d)
        out[k] = T @ robot.tool
    return out
