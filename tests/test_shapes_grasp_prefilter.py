"""world.shapes_derive's cluster prefilter for grasp_problem: the triangles it keeps are a superset
of those whose bounding sphere meets the gripper boxes' union (checked against every triangle,
computed here), and grasp_problem's answer is the one the unfiltered test gives."""
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


def _union_rows(A: sd._Arrays, R: np.ndarray, o: np.ndarray, lo: np.ndarray, hi: np.ndarray,
                slack: float) -> np.ndarray:
    """Every triangle whose sphere meets the box [lo, hi] (tool frame), tested one by one."""
    keep = []
    for i in range(len(A.S)):
        s = (A.S[i] - o) @ R
        if np.all(np.abs(s - (lo + hi) / 2) <= (hi - lo) / 2 + A.rad[i] + slack):
            keep.append(i)
    return np.asarray(keep, int)


def _problem_unfiltered(mesh: trimesh.Trimesh, T: np.ndarray, width: float, g: sd.Gripper) -> str | None:
    """grasp_problem's test over every triangle (no clusters)."""
    A = sd._arrays(mesh)
    R, o = T[:3, :3], T[:3, 3]
    reach = 2 * A.diag + g.finger_length + g.palm_depth
    for what, lo, hi in sd._gripper_boxes(g, width, reach, sd.from_mm("mm", sd.TOUCH_MM)):
        tri = (A.tri - o) @ R
        if ((tri >= lo) & (tri <= hi)).all(2).any() or sd._tri_box(tri, lo, hi).any():
            return f"{what} enters the part"
    return None


@pytest.mark.parametrize("k", range(3))
def test_prefilter_keeps_every_triangle_near_the_union(k: int) -> None:
    mesh = _meshes()[k]
    A = sd._arrays(mesh)
    rng = np.random.default_rng(k)
    kept_fewer = 0
    for _ in range(40):
        R = Rotation.random(random_state=rng).as_matrix()
        o = rng.normal(0.0, 25.0, 3)
        half = rng.uniform(1.0, 30.0, 3)
        lo, hi = -half, half * rng.uniform(0.2, 1.0, 3)
        got = sd._near_box(mesh, A, R, o, lo, hi, 1e-9)
        want = _union_rows(A, R, o, lo, hi, 1e-9)
        assert np.all(np.diff(got) > 0)
        assert set(want.tolist()) <= set(got.tolist())
        kept_fewer += len(got) < len(A.S)
    assert kept_fewer > 0  # the filter drops something on these meshes


@pytest.mark.parametrize("k", range(3))
def test_grasp_problem_agrees_with_the_unfiltered_test(k: int) -> None:
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
