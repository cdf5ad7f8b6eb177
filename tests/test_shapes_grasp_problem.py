"""world.parts.hand.grasp_problem (python-fcl's box-triangle test over the mesh's BVH) gives
the answer of a separating-axis test of each gripper box against every triangle, written here."""
from __future__ import annotations

import numpy as np
import pytest
import trimesh
from scipy.spatial.transform import Rotation

from spar_py.core.units import from_mm
from spar_py.world.parts import hand as sd
from spar_py.world.robot import Gripper


def _meshes() -> list[trimesh.Trimesh]:
    sphere = trimesh.creation.icosphere(subdivisions=4, radius=30.0)
    rod = trimesh.creation.cylinder(radius=6.0, height=120.0, sections=400)
    bar = trimesh.creation.box((80.0, 20.0, 10.0)).subdivide().subdivide().subdivide()
    return [sphere, rod, bar]


def _meets_box(tri: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """(n,) bool: triangles (n, 3, 3) that meet the box [lo, hi], by the separating-axis theorem:
    they are apart exactly when the projections on one of 13 axes (the box's 3, the triangle's
    normal, the 9 cross products of a box axis with an edge) do not overlap."""
    c, h = (lo + hi) / 2, (hi - lo) / 2
    t = tri - c
    edges = np.roll(t, -1, axis=1) - t  # (n, 3 edges, 3)
    axes = [np.broadcast_to(e, (len(t), 3)) for e in np.eye(3)]
    axes.append(np.cross(edges[:, 0], edges[:, 1]))
    axes += [np.cross(np.broadcast_to(e, (len(t), 3)), edges[:, k]) for e in np.eye(3) for k in range(3)]
    meets = np.ones(len(t), bool)
    for a in axes:
        p = np.einsum("nvd,nd->nv", t, a)  # the triangle's vertices on the axis
        r = np.abs(a) @ h  # the box's half-extent on it
        meets &= ~((p.min(1) > r + 1e-12) | (p.max(1) < -r - 1e-12))
    return meets


def _problem_unfiltered(mesh: trimesh.Trimesh, T: np.ndarray, width: float, g: Gripper) -> str | None:
    """The first gripper box that meets a triangle, over every triangle (:func:`_meets_box`)."""
    tri = np.asarray(mesh.triangles, float)
    R, o = T[:3, :3], T[:3, 3]
    reach = 2 * float(np.linalg.norm(np.ptp(mesh.vertices, axis=0))) + g.finger_length + g.palm_length
    for what, lo, hi in sd.swept_boxes(g, width, reach, from_mm("mm", sd.TOUCH_MM)):
        if _meets_box((tri - o) @ R, lo, hi).any():
            return f"{what} enters the part"
    return None


@pytest.mark.parametrize("k", range(3))
def test_grasp_problem_agrees_with_every_triangle_tested(k: int) -> None:
    mesh = _meshes()[k]
    g = Gripper.of_unit("mm", 90.0)
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
    g = Gripper.of_unit("mm", 90.0)
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
