"""The UR5e's collision shapes (kb/robots/ur5e.yaml, kb/robots/ur5e.urdf) where the real arm is.

Independent of world/collision/scene.py and world/robot/model.py: the link frames are chained here from
ur_description's joint origins (written out with numpy, checked against UR's published
standard DH in test_ik_ur.std_fk) and the cylinders placed in them from the figures the robot
file cites (UR's offsets along the shoulder axis, the fitted radii, the 2F-85 coupling); each
link's lowest point is exact. The module's heights (its collision scene's table test) must agree
for the YAML model and for the URDF one. Lengths mm, angles rad; world = UR's base frame, z up,
table top z = 0.

The bug these would have caught: side grasps 38.1 mm above the table (the block's centre) were
refused for every IK branch. They must be: the wrist 3 axis is then 38.1 mm up and its 45 mm
housing is in the table; the cells present the block at the table's edge instead.
"""
from __future__ import annotations

import dataclasses
import math
import sys
from pathlib import Path

import numpy as np
import pytest

from spar_py.kb import load_problem
from spar_py.world.reach.workspace import ik_rows, reach_clear, requirement_clear
from spar_py.world.collision import CellCache

sys.path.insert(0, str(Path(__file__).parent))
from test_ik_ur import std_fk  # noqa: E402  (UR's published DH, written out)

PROBLEMS = Path(__file__).resolve().parent.parent / "kb" / "problems"
MM = 25.4  # the cells are in inches
TCP = 150.0


def rotx(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[1, 0, 0, 0], [0, c, -s, 0], [0, s, c, 0], [0, 0, 0, 1.0]])


def roty(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, 0, s, 0], [0, 1, 0, 0], [-s, 0, c, 0], [0, 0, 0, 1.0]])


def rotz(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s, 0, 0], [s, c, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1.0]])


def tr(x: float, y: float, z: float) -> np.ndarray:
    T = np.eye(4)
    T[:3, 3] = x, y, z
    return T


# ur_description (ur.urdf.xacro, config/ur5e/default_kinematics.yaml): each joint's origin in its
# parent link, mm; every joint turns about its own z
D1, A2, A3, D4, D5, D6 = 162.5, -425.0, -392.2, 133.3, 99.7, 99.6
JOINTS = [tr(0, 0, D1), rotx(math.pi / 2), tr(A2, 0, 0), tr(A3, 0, D4),
          tr(0, -D5, 0) @ rotx(math.pi / 2), tr(0, D6, 0) @ rotz(math.pi) @ roty(math.pi) @ rotx(math.pi / 2)]
# name: (link: 0 UR's base, 1..6 shoulder .. wrist 3 (its origin the flange, z out of it), the
# cylinder's centre pose in the link, radius, length): the figures kb/robots/ur5e.yaml cites
SHAPES = {
    "base": (0, tr(0, 0, 45), 75.0, 90.0),                          # UR5e footprint 149 mm, 90 high
    "shoulder": (1, np.eye(4), 60.0, 135.0),
    "upper_arm": (2, tr(A2 / 2, 0, 138) @ roty(math.pi / 2), 54.0, 425.0),   # 138 out along joint 2
    "forearm": (3, tr(A3 / 2, 0, 7) @ roty(math.pi / 2), 40.0, 392.2),       # 138 - 131 = 7
    "wrist_1": (4, np.eye(4), 45.0, 120.0),
    "wrist_2": (5, tr(0, 0, -7.5), 45.0, 105.0),                    # -60 .. +45 about the wrist 3 axis
    "wrist_3": (6, tr(0, 0, -20), 45.0, 40.0),                      # the 40 mm behind the flange
    "coupling": (6, tr(0, 0, 32.5), 37.5, 65.0),                    # Robotiq 2F-85: 75 dia., 65 long
}
URDF_NAMES = {"base": "base_link", "coupling": "coupling", **{n: f"{n}_link" for n in
                                                              ("shoulder", "upper_arm", "forearm", "wrist_1",
                                                               "wrist_2", "wrist_3")}}
#: UR's home (the arm straight up) and a top-down pick 400 mm in front of the base at table height
HOME = np.radians([0, -90, 0, -90, 0, 0])


def link_frames(q: np.ndarray) -> list[np.ndarray]:
    """UR's base frame, then the six links' frames (mm) at joint vector q (6,) rad."""
    out = [np.eye(4)]
    for J, qi in zip(JOINTS, q):
        out.append(out[-1] @ J @ rotz(qi))
    return out


def cylinders(q: np.ndarray) -> dict[str, tuple[np.ndarray, float, float]]:
    """Each shape's world centre pose (4x4, mm, z its axis), radius and length at q."""
    F = link_frames(q)
    return {n: (F[k] @ T, r, L) for n, (k, T, r, L) in SHAPES.items()}


def lowest(T: np.ndarray, r: float, L: float) -> float:
    """The exact lowest z (mm) of a solid cylinder: centre T[:3, 3], axis T[:3, 2]."""
    az = T[2, 2]
    return float(T[2, 3] - abs(az) * L / 2 - r * math.sqrt(max(0.0, 1 - az * az)))


def least(T: np.ndarray, r: float, L: float, axis: int) -> float:
    """The exact least world coordinate ``axis`` (mm) over the cylinder."""
    a = T[axis, 2]
    return float(T[axis, 3] - abs(a) * L / 2 - r * math.sqrt(max(0.0, 1 - a * a)))


def cell_on_open_table(name: str):
    """The cell with its table the whole plane (the geometry as it was before the edge)."""
    return dataclasses.replace(load_problem(PROBLEMS / f"{name}.yaml"), table=None)


def module_heights(cell, q: np.ndarray) -> dict[str, np.ndarray]:
    """The module's height over the table (mm) of each moving link shape at rows q (n, 6)."""
    state = CellCache(cell).scene().at({})
    H = state._table(cell.robot.frames_batch(q)) * MM
    return {state.bodies[i].name: H[:, k] for k, i in enumerate(state.table_bodies)}


def test_the_independent_arm_is_urs_published_one() -> None:
    q = np.random.default_rng(3).uniform(-math.pi, math.pi, (50, 6))
    mine = np.array([link_frames(qk)[6] @ tr(0, 0, TCP) for qk in q])
    assert np.allclose(mine, std_fk("ur5e", q), atol=1e-9)
    F = link_frames(HOME)  # UR's home: the arm straight up, every joint on the base axis
    assert np.allclose([f[:2, 3] for f in F[1:4]], 0.0, atol=1e-9)
    assert F[4][2, 3] == pytest.approx(D1 - A2 - A3)
    assert lowest(*cylinders(HOME)["shoulder"]) == pytest.approx(D1 - 135 / 2)


@pytest.mark.parametrize("name", ["ur5e_peg_in_block", "ur5e_urdf_peg_in_block"])
def test_link_heights_agree_with_the_published_geometry(name: str) -> None:
    cell = cell_on_open_table(name)
    pick = cell.robot.ik(pick_pose(cell))
    assert len(pick)
    q = np.vstack([HOME[None], pick, np.random.default_rng(7).uniform(-math.pi, math.pi, (200, 6))])
    got = module_heights(cell, q)
    names = URDF_NAMES if "urdf" in name else {n: n for n in SHAPES}
    for shape, (k, _, r, _) in SHAPES.items():
        if k == 0:
            continue  # the base does not move: not in the table test
        want = np.array([lowest(*cylinders(qk)[shape]) for qk in q])
        # the module holds a cylinder as its circumscribed 16-gon prism: up to 2 % of r lower
        slack = r * (1 / math.cos(math.pi / 16) - 1)
        h = got[names[shape]]
        assert np.all(h <= want + 1e-6) and np.all(h >= want - slack - 1e-6), shape


def pick_pose(cell) -> np.ndarray:
    """A top-down pick 400 mm in front of the base, the tool centre 38.1 mm up (a 3 in block's centre)."""
    T = np.eye(4)
    T[:3, :3] = rotx(math.pi)[:3, :3]
    T[:3, 3] = np.array([400.0, 0.0, 38.1]) / MM
    return T


def test_a_pick_in_front_at_table_height_is_clear() -> None:
    cell = cell_on_open_table("ur5e_peg_in_block")
    T = pick_pose(cell)
    assert reach_clear(CellCache(cell), T[None]).ok[0]
    Q, okb = ik_rows(cell, T[None])
    clear = CellCache(cell).scene().at({}).clear(Q[0][okb[0]])
    assert clear.any()
    margin = 2.0
    for qk, c in zip(Q[0][okb[0]], clear):
        low = min(lowest(*s) for n, s in cylinders(qk).items() if n != "base")
        assert (low > margin) == bool(c)


def test_side_grasp_at_the_blocks_centre_needs_the_table_edge() -> None:
    # on a table without an edge every branch of the paper's side grasp has a housing in it...
    cell = cell_on_open_table("ur5e_peg_in_block")
    g = cell.objects["block"].grasps["p2G1"]
    TO = cell.positions["tr2"].T
    Q, okb = ik_rows(cell, (TO @ g.T)[None])
    assert okb.any()
    for qk in Q[0][okb[0]]:
        assert min(lowest(*s) for n, s in cylinders(qk).items() if n != "base") < 0.0
    assert not requirement_clear(CellCache(cell), "block", TO[None], g.T).ok[0]
    # ...with the cell's table, ending at y = 6.5 in under the block's face, one is clear, and
    # every shape that is under the table top's level is wholly beyond the edge
    cell = load_problem(PROBLEMS / "ur5e_peg_in_block.yaml")
    edge = cell.table[3] * MM
    Q, okb = ik_rows(cell, (TO @ g.T)[None])
    clear = CellCache(cell).scene().at({}, grasped="block", width=g.width,
                                attached={"block": np.linalg.inv(g.T)}).clear(Q[0][okb[0]])
    assert clear.any()
    for qk in Q[0][okb[0]][clear]:
        for n, s in cylinders(qk).items():
            if n != "base" and lowest(*s) <= 2.0:  # the base stands on the table
                assert least(*s, axis=1) > edge, n


def main() -> None:
    """Print, for the UR5e cell's side grasps on an edgeless table (the pickups that had no
    collision-free IK), each shape's lowest point per IK branch: independent | module (mm)."""
    cell = cell_on_open_table("ur5e_peg_in_block")
    for obj, label, pos in (("block", "p2G1", "tr2"), ("peg", "p1G11", "tr1")):
        g = cell.objects[obj].grasps[label]
        Q, ok = ik_rows(cell, (cell.positions[pos].T @ g.T)[None])
        Q = Q[0][ok[0]]
        got = module_heights(cell, Q)
        print(f"pickup({obj}, {label}) at {pos}: lowest point of each shape, mm (independent | module)")
        for k, q in enumerate(Q):
            c = cylinders(q)
            print(f"  q = {np.round(np.degrees(q)).astype(int).tolist()}: "
                  + ", ".join(f"{n} {lowest(*c[n]):.1f} | {got[n][k]:.1f}" for n in c if n != "base"))


if __name__ == "__main__":
    main()
