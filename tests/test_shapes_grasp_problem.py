"""world.shapes_derive.grasp_problem (python-fcl's box-triangle test over the mesh's BVH) gives
the answer of a separating-axis test of each gripper box against every triangle, written here."""
from __future__ import annotations

import numpy as np
import pytest
import trimesh
from scipy.spatial.transform import Rotation

from spar_py.world import shapes_derive as sd


def _meshes() -> list[trimesh.Trimesh]:
    sphere = trimesh.creation.icosphere(subdivisions=4, radius=30.0)
    rod = trimesh.creation.cylinder(radius=6.0, height=120.0, sections=400)
    bar = trimesh.creation.box((80.0, 20.0, 10.0)).subdivide().subdivide().subdivide()
    return [sphere, rod, bar]


def _problem_unfiltered(mesh: trimesh.Trimesh, T: np.ndarray, width: float, g: sd.Gripper) -> str | None:
    """The first gripper box that meets a triangle, over every triangle."""
    A = sd._arrays(mesh)
    R, o = T[:3, :3], T[:3, 3]
    reach = 2 * A.diag + g.finger_length + g.palm_depth
    for what, lo, hi in sd._gripper_boxes(g, width, reach, sd.from_mm("mm", sd.TOUCH_MM)):
        tri = (A.tri - o) @ R
        if ((tri >= lo) & (tri <= hi)).all(2).any() or sd._tri_box(tri, lo, hi).any():
            return f"{what} enters the part"
    return None


@pytest.mark.parametrize("k", range(3))
def test_grasp_problem_agrees_with_every_triangle_tested(k: int) -> None:
    mesh = _meshes()[k]
    g = sd.Gripper.default("mm", 90.0)
    rng = np.random.default_rng(10 + k)
    answers = set()
    for _ in range(60):
        T = np.eye(4)
        T[:3, :3] = Rotation.random(random_state=rng).as_matrix()
        T[:3, 3] = rng.normal(0.0, 40.0, 3)
        width = float(rng.uniform(5.0, 85.0))
        got = sd.grasp_problem(mesh, T, width, g, "mm")
        assert got == _problem_unfiltered(mesh, T, width, g)
        answers.add(got)
    assert None in answers and len(answers) > 1  # both outcomes were tried


def test_fingers_resting_on_the_faces_hold_the_part() -> None:
    """Across the bar's 20 mm: fingers 20 mm apart rest on its faces (the boxes are shrunk by
    TOUCH_MM), 19 mm apart they are in it; from the end of a 80 mm bar the palm meets it."""
    bar = trimesh.creation.box((80.0, 20.0, 10.0))
    g = sd.Gripper.default("mm", 90.0)
    T = np.eye(4)  # closing along y, approach along z: down onto the bar's top
    T[2, 3] = 5.0  # the finger tips at the bar's top face
    assert sd.grasp_problem(bar, T, 20.0, g, "mm") is None
    assert sd.grasp_problem(bar, T, 19.0, g, "mm") == "a finger enters the part"
    T[2, 3] = -3.0  # 8 mm down its sides: still clear
    assert sd.grasp_problem(bar, T, 20.0, g, "mm") is None
    assert sd.grasp_problem(bar, T, 95.0, g, "mm").startswith("95 mm wide")
    end = np.eye(4)  # approach along the bar (+x) from its -x end, closing across it
    end[:3, :3] = np.column_stack([[0.0, 0.0, -1.0], [0.0, 1.0, 0.0], [1.0, 0.0, 0.0]])
    end[0, 3] = 20.0  # the tips 60 mm (the finger length) in: the palm on the end face
    assert sd.grasp_problem(bar, end, 20.0, g, "mm") is None
    end[0, 3] = 25.0
    assert sd.grasp_problem(bar, end, 20.0, g, "mm") == "the palm enters the part"
