"""Stable poses of a rigid body on a plane: ``trimesh.poses.compute_stable_poses`` (sigma 0, one
sample, threshold 0) with its topple graph built from arrays.

trimesh builds the topple graph face by face in Python (networkx, a static probability and a
cross product per face), slow for a hull of a few thousand faces, and a derivation asks
for many (each part, each subassembly, each partial product). :func:`stable_poses` returns
the same transforms and probabilities: the same faces topple to the same neighbours in the same
order, the probabilities flow to the sinks in trimesh's breadth-first order and the poses are
sorted by the same ``argsort``. Where the hull's adjacency is not the plain manifold one, or
the centre of mass is not strictly inside the hull, it calls trimesh itself.
"""
from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    import trimesh

__all__ = ["stable_poses"]


def stable_poses(mesh: "trimesh.Trimesh", com: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The stable poses of ``mesh`` about the centre of mass ``com`` (the mesh's frame and
    unit), as ``trimesh.poses.compute_stable_poses(mesh, center_mass=com, sigma=0.0,
    n_samples=1)`` returns them: (n, 4, 4) transforms placing the body on the plane z = 0
    and their probabilities, the most probable first."""
    import trimesh

    cvh = mesh.convex_hull
    com = np.asarray(com, float)
    graph = _topple_graph(cvh, com)
    if graph is None:
        return trimesh.poses.compute_stable_poses(mesh, center_mass=com, sigma=0.0, n_samples=1)
    prob, succ = graph
    p = _flow(prob, succ, len(mesh.faces))
    N = np.asarray(cvh.face_normals, float)
    keyed: dict[tuple[float, ...], list] = {}  # rounded normal -> [summed prob, first normal]
    for i in np.flatnonzero(np.asarray(p) > 0.0):
        key = tuple(np.around(N[i], decimals=3))
        if key in keyed:
            keyed[key][0] += p[i]
        else:
            keyed[key] = [p[i], N[i]]
    V = np.asarray(cvh.vertices, float)[cvh.referenced_vertices]
    transforms, probs = [], []
    for pr, normal in keyed.values():
        tf = np.eye(4)
        z = -1.0 * normal
        x = np.array([-z[1], z[0], 0])
        x = np.array([1, 0, 0]) if np.linalg.norm(x) == 0.0 else x / np.linalg.norm(x)
        y = np.cross(z, x)
        y = y / np.linalg.norm(y)
        tf[:3, :3] = np.array([x, y, z])
        placed = trimesh.transformations.transform_points(V, tf)
        tf[:3, 3] = np.array([0, 0, -placed.min(axis=0)[2]])
        transforms.append(tf)
        probs.append(pr)
    T, P = np.array(transforms), np.array(probs)
    order = np.argsort(-P)
    return T[order], P[order]


def _topple_graph(cvh: "trimesh.Trimesh", com: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
    """Each hull face's static probability (L'Huilier's formula on the unit sphere about com)
    and the face it topples to (-1 for a stable face), as trimesh's _create_topple_graph: an
    unstable face topples to the first neighbour (in face_adjacency order) across whose edge
    the projected com lies, else to its last neighbour. None where trimesh must decide."""
    from trimesh.triangles import points_to_barycentric

    tri = np.asarray(cvh.triangles, float)
    N = np.asarray(cvh.face_normals, float)
    n = len(tri)
    if not np.all(np.einsum("ij,ij->i", com - cvh.triangles_center, N) < 0):
        return None
    pairs = np.asarray(cvh.face_adjacency, int)
    edges = np.asarray(cvh.face_adjacency_edges, int)
    repeated = len(np.unique(np.sort(pairs, axis=1), axis=0)) != len(pairs)
    if repeated or np.bincount(pairs.ravel(), minlength=n).min() == 0:
        return None
    sv = tri - com
    sv = sv / np.linalg.norm(sv, axis=2)[..., None]
    with np.errstate(all="ignore"):
        a = np.arccos(np.clip(_dot(sv[:, 0], sv[:, 1]), -1, 1))
        b = np.arccos(np.clip(_dot(sv[:, 1], sv[:, 2]), -1, 1))
        c = np.arccos(np.clip(_dot(sv[:, 2], sv[:, 0]), -1, 1))
        s = (a + b + c) / 2.0
        prob = 1.0 / np.pi * np.arctan(np.sqrt(np.tan(s / 2) * np.tan((s - a) / 2) * np.tan((s - b) / 2)
                                                * np.tan((s - c) / 2)))
    proj = com - np.einsum("ij,ij->i", N, com - tri[:, 0])[:, None] * N
    with np.errstate(all="ignore"):
        unstable = np.any(points_to_barycentric(tri, proj) < 0, axis=1)
    rows = np.concatenate([np.arange(len(pairs)), np.arange(len(pairs))])
    face = np.concatenate([pairs[:, 0], pairs[:, 1]])
    other = np.concatenate([pairs[:, 1], pairs[:, 0]])
    order = np.lexsort((rows, face))
    face, other, rows = face[order], other[order], rows[order]
    keep = unstable[face]
    face, other, rows = face[keep], other[keep], rows[keep]
    cen = np.asarray(cvh.triangles_center, float)[face]
    nrm, pc = N[face], proj[face]
    V = np.asarray(cvh.vertices, float)
    v1, v2 = V[edges[rows, 0]], V[edges[rows, 1]]
    swap = np.einsum("ij,ij->i", np.cross(v1 - cen, v2 - cen), nrm) < 0
    v1, v2 = np.where(swap[:, None], v2, v1), np.where(swap[:, None], v1, v2)
    ok = (_orient3d(cen, v1, v1 + nrm, pc) >= 0) & (_orient3d(cen, v2 + nrm, v2, pc) >= 0)
    succ = np.full(n, -1)
    last = np.r_[face[1:] != face[:-1], True] if len(face) else np.zeros(0, bool)
    succ[face[last]] = other[last]
    hit = np.flatnonzero(ok)
    first = hit[np.r_[True, face[hit][1:] != face[hit][:-1]]] if len(hit) else hit
    succ[face[first]] = other[first]
    return prob, succ


def _dot(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Row-wise dot products of (n, 3) arrays summed left to right, as np.dot sums one pair:
    the static probabilities then equal trimesh's to the last bit."""
    return x[:, 0] * y[:, 0] + x[:, 1] * y[:, 1] + x[:, 2] * y[:, 2]


def _flow(prob: np.ndarray, succ: np.ndarray, max_iters: int) -> list[float]:
    """The probabilities moved along the topple edges to the sinks, breadth first from the
    faces nothing topples onto, in trimesh's order and for at most its number of rounds."""
    p = prob.tolist()
    nxt = succ.tolist()
    indeg = np.bincount(succ[succ >= 0], minlength=len(succ))
    nodes = np.flatnonzero(indeg == 0).tolist()
    it = 0
    while nodes and it <= max_iters:
        new = []
        for u in nodes:
            v = nxt[u]
            if v < 0:
                continue
            p[v] += p[u]
            p[u] = 0.0
            new.append(v)
        nodes = new
        it += 1
    return p


def _orient3d(pa: np.ndarray, pb: np.ndarray, pc: np.ndarray, pd: np.ndarray) -> np.ndarray:
    """Row-wise orientation of point pd against the plane through pa, pb, pc (trimesh.poses'
    _orient3dfast): positive above, negative below, zero on it."""
    ad, bd, cd = pa - pd, pb - pd, pc - pd
    return (ad[:, 0] * (bd[:, 1] * cd[:, 2] - bd[:, 2] * cd[:, 1])
            + bd[:, 0] * (cd[:, 1] * ad[:, 2] - cd[:, 2] * ad[:, 1])
            + cd[:, 0] * (ad[:, 1] * bd[:, 2] - ad[:, 2] * bd[:, 1]))
