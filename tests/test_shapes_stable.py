"""world.parts.stable's stable poses against trimesh's own compute_stable_poses (the
reference it reimplements with arrays): the same transforms and probabilities, bit for bit, on
boxes, cylinders, spheres, an off-centre mass, unions of shapes and a Fabrica part's hull."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import trimesh

from spar_py.world.parts.stable import stable_poses

FABRICA = Path(__file__).resolve().parents[1] / "kb" / "products" / "fabrica"


def _bodies() -> list[tuple[trimesh.Trimesh, np.ndarray]]:
    box = trimesh.creation.box((1.0, 2.0, 3.0))
    cyl = trimesh.creation.cylinder(1.0, 2.0, sections=48)
    sph = trimesh.creation.icosphere(3)
    lshape = trimesh.util.concatenate([box, trimesh.creation.box((3.0, 0.5, 0.5)).apply_translation((1.5, 0, -1.25))])
    out = [(m, m.center_mass) for m in (box, cyl, sph, lshape, trimesh.creation.capsule(2.0, 0.5))]
    out.append((cyl, cyl.center_mass + np.array([0.3, 0.1, 0.4])))
    return out


def _fabrica(name: str) -> tuple[trimesh.Trimesh, np.ndarray]:
    hull = trimesh.load(FABRICA / name, force="mesh").convex_hull
    return hull, hull.center_mass


@pytest.mark.parametrize("k", range(6))
def test_stable_poses_match_trimesh(k: int) -> None:
    body, com = _bodies()[k]
    hull = body.convex_hull
    T_ref, P_ref = trimesh.poses.compute_stable_poses(hull, center_mass=com, sigma=0.0, n_samples=1)
    T, P = stable_poses(hull, com)
    assert len(T) > 0
    assert np.array_equal(T, T_ref)
    assert np.array_equal(P, P_ref)


@pytest.mark.parametrize("name", ["stool_circular/0.ply", "gamepad/1.ply"])
def test_stable_poses_match_trimesh_on_a_scanned_hull(name: str) -> None:
    hull, com = _fabrica(name)
    T_ref, P_ref = trimesh.poses.compute_stable_poses(hull, center_mass=com, sigma=0.0, n_samples=1)
    T, P = stable_poses(hull, com)
    assert len(T) > 1
    assert np.array_equal(T, T_ref)
    assert np.array_equal(P, P_ref)
