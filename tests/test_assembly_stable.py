"""world.assembly's stable resting faces against trimesh's own compute_stable_poses (the
reference it reimplements with arrays): the same normals on boxes, cylinders, spheres, an
off-centre mass and unions of shapes."""
from __future__ import annotations

import numpy as np
import pytest
import trimesh

from spar_py.world.assembly import _stable_normals


def _bodies() -> list[tuple[trimesh.Trimesh, np.ndarray]]:
    box = trimesh.creation.box((1.0, 2.0, 3.0))
    cyl = trimesh.creation.cylinder(1.0, 2.0, sections=48)
    sph = trimesh.creation.icosphere(3)
    lshape = trimesh.util.concatenate([box, trimesh.creation.box((3.0, 0.5, 0.5)).apply_translation((1.5, 0, -1.25))])
    out = [(m, m.center_mass) for m in (box, cyl, sph, lshape, trimesh.creation.capsule(2.0, 0.5))]
    out.append((cyl, cyl.center_mass + np.array([0.3, 0.1, 0.4])))
    return out


@pytest.mark.parametrize("k", range(6))
def test_stable_normals_match_trimesh(k: int) -> None:
    body, com = _bodies()[k]
    hull = body.convex_hull
    T, _ = trimesh.poses.compute_stable_poses(hull, center_mass=com)
    ref = sorted(tuple(np.round(-t[2, :3], 9)) for t in T)
    mine = sorted(tuple(np.round(n, 9)) for n in _stable_normals(hull, com))
    assert mine == ref
    assert len(mine) > 0
