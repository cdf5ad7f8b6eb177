"""A mesh's arrays (vertices, faces, triangles, normals, centres, size, centre of mass) read once
and kept with the mesh: every derivation module reads a mesh through them.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np


if TYPE_CHECKING:
    import trimesh

__all__ = ["MeshArrays", "mesh_arrays"]

@dataclass(frozen=True)
class MeshArrays:
    """A mesh's arrays read once (trimesh re-checks its content hash on every property read):
    vertices V, faces F, triangles (n, 3, 3), normals N, centres C, bounding-box diagonal and
    centre of mass."""

    V: np.ndarray
    F: np.ndarray
    tri: np.ndarray
    N: np.ndarray
    C: np.ndarray
    diag: float
    com: np.ndarray


def mesh_arrays(mesh: "trimesh.Trimesh") -> MeshArrays:
    """The arrays of ``mesh``, kept in its metadata (they live and die with the mesh)."""
    a = mesh.metadata.get("_spar_arrays")
    if a is None:
        V = np.asarray(mesh.vertices, float)
        F = np.asarray(mesh.faces)
        a = MeshArrays(V, F, V[F], np.asarray(mesh.face_normals, float), np.asarray(mesh.triangles_center, float),
                       float(np.linalg.norm(V.max(0) - V.min(0))), np.asarray(mesh.center_mass, float))
        mesh.metadata["_spar_arrays"] = a
    return a
