"""Generate the mesh parts of kb/objects/meshes/ (issue 14): run from the repository root,
``.venv/bin/python scripts/make_meshes.py``; the STL files are committed, so a change here
shows in their diff.

- ``hex_shaft.stl``: a hexagonal shaft (circumradius 12 mm, 45 mm long) standing on a square
  flange 60 x 60 x 20 mm; object frame at the centre of the flange's bottom face, z up the
  shaft (the shaft's root at z = 20 mm, its tip at z = 65 mm).
- ``bracket.stl``: an L bracket: a base plate 80 x 60 x 15 mm and an upright wall 20 mm thick
  and 60 mm high at its -x end, with a blind round hole (radius 20 mm, 16 mm deep) in the wall's
  outer (-x) face at 45 mm above the bottom; object frame at the centre of the base's bottom.

Lengths in mm (the models say ``units: {length: mm}``). Binary STL, written by trimesh.
"""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import trimesh

OUT = Path(__file__).resolve().parent.parent / "kb" / "objects" / "meshes"


def prism(ring: np.ndarray, z0: float, z1: float) -> trimesh.Trimesh:
    """A closed prism over the convex CCW polygon ``ring`` (k, 2) from z0 to z1."""
    k = len(ring)
    V = np.vstack([np.column_stack([ring, np.full(k, z0)]), np.column_stack([ring, np.full(k, z1)]),
                   [[*ring.mean(0), z0], [*ring.mean(0), z1]]])
    F = []
    for i in range(k):
        j = (i + 1) % k
        F += [[i, j, k + j], [i, k + j, k + i], [2 * k, j, i], [2 * k + 1, k + i, k + j]]
    return trimesh.Trimesh(V, np.array(F), process=True)


def make_hex_shaft() -> trimesh.Trimesh:
    flange = trimesh.creation.box(bounds=[[-30, -30, 0], [30, 30, 20]])
    a = np.radians(np.arange(6) * 60.0)
    shaft = prism(np.column_stack([12 * np.cos(a), 12 * np.sin(a)]), 20, 65)
    return trimesh.boolean.union([flange, shaft], engine="manifold")


def make_bracket() -> trimesh.Trimesh:
    base = trimesh.creation.box(bounds=[[-40, -30, 0], [40, 30, 15]])
    wall = trimesh.creation.box(bounds=[[-40, -30, 15], [-20, 30, 75]])
    hole = trimesh.creation.cylinder(radius=20, segment=[[-41, 0, 45], [-40 + 16, 0, 45]], sections=64)
    return trimesh.boolean.difference([trimesh.boolean.union([base, wall], engine="manifold"), hole],
                                      engine="manifold")


def main() -> int:
    OUT.mkdir(parents=True, exist_ok=True)
    for name, mesh in (("hex_shaft", make_hex_shaft()), ("bracket", make_bracket())):
        assert mesh.is_volume, name
        mesh.export(OUT / f"{name}.stl", file_type="stl")
        print(f"{OUT / (name + '.stl')}: {len(mesh.faces)} triangles, volume {mesh.volume:.1f} mm^3")
    return 0


if __name__ == "__main__":
    sys.exit(main())
