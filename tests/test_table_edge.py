"""The clearance margin holds at the table's edge, not only over it (issue 15: "clear of the table
by the margin"). A body just beyond the edge of a table with an extent (problem ``table:``) and
lower than the margin above its top is closer to the table than the margin: its distance to the
slab's top edge is the hypotenuse of its horizontal and vertical gaps.

Found by an independent check (python-fcl) of a UR3e cell: the assembled peg's base hung
0 mm beyond the +y edge with its bottom at table height, and the plan reported it clear.
The gaps here are computed by hand from the tool pose: no spar_py geometry decides them."""
from __future__ import annotations

import math

import numpy as np
import pytest

from paths import ROOT


@pytest.fixture(scope="module")
def edge_cell():
    from spar_py import Planner
    from spar_py.world.collision import CellCache

    cell = Planner().load_problem(ROOT / "kb" / "problems" / "ur5e_peg_in_block.yaml")
    scene = CellCache(cell).scene()
    return cell, scene, scene.at({})  # no parts: only the table (y <= 6.5 in) and the arm


def _tool_down(x: float, y: float, z: float) -> np.ndarray:
    """Tool pose (cell unit, in) with tool z pointing down and tool y along world y: the fingers
    hang below the palm, their lowest points at the TCP's height z."""
    T = np.eye(4)
    T[:3, :3] = np.diag([1.0, -1.0, -1.0])
    T[:3, 3] = x, y, z
    return T


def q(cell, T: np.ndarray) -> np.ndarray:
    sols = cell.robot.ik(T)
    assert len(sols), "the test's tool pose is out of the UR5e's reach"
    return sols


def test_a_gripper_just_past_the_edge_below_the_margin_is_refused(edge_cell) -> None:
    cell, scene, state = edge_cell
    margin = float(scene.margin)  # 2 mm in inches
    y_edge = 6.5  # the cell's table: {y: [-20, 6.5]} (in)
    g = cell.robot.gripper
    reach = cell.robot.finger_separation / 2 + g.finger_thickness  # the fingers' outer faces, +-y of the TCP
    gap = 0.5 * margin  # horizontal and vertical gaps: distance gap * sqrt(2) = 0.71 margin
    # the whole gripper beyond the edge (its nearest face gap past it), its lowest points gap
    # above the table top
    T_past = _tool_down(18.0, y_edge + reach + gap, gap)
    assert math.hypot(gap, gap) < margin
    rows = q(cell, T_past)
    ok = state.clear(rows)
    assert not ok.any(), (f"{int(ok.sum())} of {len(rows)} IK rows with the fingers {gap * 25.4:.2f} mm past the "
                          f"table's edge and {gap * 25.4:.2f} mm above its top are called clear")


def test_the_same_gripper_a_margin_past_the_edge_is_clear_of_the_table(edge_cell) -> None:
    """The control: moved out until its distance to the edge exceeds the margin, some IK row is
    clear (so the refusal above is the table's, not the arm's)."""
    cell, scene, state = edge_cell
    margin = float(scene.margin)
    y_edge = 6.5
    g = cell.robot.gripper
    reach = cell.robot.finger_separation / 2 + g.finger_thickness
    T_far = _tool_down(18.0, y_edge + reach + 1.5 * margin, 0.5 * margin)
    assert state.clear(q(cell, T_far)).any()


def test_the_edge_gap_is_a_lower_bound_close_to_the_distance() -> None:
    """slab_gap against the exact distance of a point to the slab (clamping, by hand): never
    above it, and within 2% of it plus 1e-9 for points beside the edge at every height."""
    from spar_py.world.collision.bounds import slab_gap

    ext = (-20.0, 10.0, -20.0, 6.5)
    rng = np.random.default_rng(3)
    pts = np.column_stack([rng.uniform(-25, 15, 4000), rng.uniform(-25, 11, 4000), rng.uniform(-3, 3, 4000)])
    off = (pts[:, 0] < ext[0]) | (pts[:, 0] > ext[1]) | (pts[:, 1] < ext[2]) | (pts[:, 1] > ext[3])
    pts = pts[off]
    dx = np.maximum(np.maximum(ext[0] - pts[:, 0], pts[:, 0] - ext[1]), 0)
    dy = np.maximum(np.maximum(ext[2] - pts[:, 1], pts[:, 1] - ext[3]), 0)
    exact = np.sqrt(dx ** 2 + dy ** 2 + np.maximum(pts[:, 2], 0) ** 2)
    lb = slab_gap(pts[:, None, :], 0.0, ext)
    assert (lb <= exact + 1e-12).all()
    assert (lb >= 0.98 * exact - 1e-9).all(), float((exact - lb).max())
