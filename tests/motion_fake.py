"""A small stand-in for world/collision/scene.py's scene (tests only): the arm as points along
its links (Craig FK written out here, vectorised), the table top z = 0 and axis-aligned
world boxes as obstacles. Clear means every point is at least ``margin`` above the table
and outside every box grown by ``margin``. Parts are not modelled; the calls made are
recorded so tests can see which world each motion was checked in.

Units: the cell's length unit; joint vectors in radians."""
from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np


def _links(dh: np.ndarray, q: np.ndarray) -> np.ndarray:
    """(n, 6, 4, 4) Craig link transforms rotx(alpha) transx(a) rotz(theta) transz(d)."""
    n = len(q)
    A = np.zeros((n, 6, 4, 4))
    for i, (alpha, a, d, off) in enumerate(dh):
        th = q[:, i] + off
        ca, sa, ct, st = np.cos(alpha), np.sin(alpha), np.cos(th), np.sin(th)
        A[:, i, 0, 0], A[:, i, 0, 1], A[:, i, 0, 3] = ct, -st, a
        A[:, i, 1, 0], A[:, i, 1, 1], A[:, i, 1, 2], A[:, i, 1, 3] = st * ca, ct * ca, -sa, -sa * d
        A[:, i, 2, 0], A[:, i, 2, 1], A[:, i, 2, 2], A[:, i, 2, 3] = st * sa, ct * sa, ca, ca * d
        A[:, i, 3, 3] = 1.0
    return A


def arm_points(robot, q: np.ndarray, per_link: int = 4) -> tuple[np.ndarray, list[str]]:
    """World points (n, m, 3) along the arm from frame 2's origin to the tool, and each point's body name."""
    q = np.atleast_2d(np.asarray(q, float))
    A = _links(robot.dh, q)
    T = np.repeat(robot.base[None], len(q), axis=0)
    origins = []
    for i in range(6):
        T = T @ A[:, i]
        origins.append(T[:, :3, 3])
    origins.append((T @ robot.tool)[:, :3, 3])
    pts, names = [], []
    for i in range(1, 6):  # frame i+1 -> frame i+2 (the last: flange -> tool)
        for t in np.linspace(0.0, 1.0, per_link, endpoint=i == 5):
            pts.append(origins[i] * (1 - t) + origins[i + 1] * t)
            names.append("gripper" if i == 5 else f"link_{i + 1}")
    return np.stack(pts, axis=1), names


@dataclass
class FakeState:
    scene: "FakeScene"
    parts: dict
    held: tuple | None
    grasped: str | None

    def clearance(self, q: np.ndarray) -> tuple[np.ndarray, list[tuple[str, str]]]:
        p, names = arm_points(self.scene.robot, q)
        self.scene.calls += 1
        d = p[..., 2]  # to the table top
        best = d.min(axis=1)
        arg = d.argmin(axis=1)
        who = [("table", names[j]) for j in arg]
        for name, (lo, hi) in self.scene.boxes.items():
            out = np.maximum(np.maximum(lo - p, p - hi), 0.0)
            inside = np.all((p >= lo) & (p <= hi), axis=-1)
            dist = np.where(inside, -1.0, np.linalg.norm(out, axis=-1))
            m, j = dist.min(axis=1), dist.argmin(axis=1)
            for r in np.nonzero(m < best)[0]:
                who[r] = (names[j[r]], name)
            best = np.minimum(best, m)
        return best, who

    def clear(self, q: np.ndarray) -> np.ndarray:
        return self.clearance(q)[0] >= self.scene.margin


@dataclass
class FakeScene:
    robot: object
    margin: float = 0.1
    boxes: Mapping[str, tuple[np.ndarray, np.ndarray]] = field(default_factory=dict)
    calls: int = 0
    worlds: list = field(default_factory=list)

    def at(self, parts, held=None, grasped=None) -> FakeState:
        self.worlds.append((dict(parts), held, grasped))
        return FakeState(self, dict(parts), held, grasped)
