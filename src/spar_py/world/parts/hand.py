"""The parallel-jaw hand against the part: its boxes in the tool frame, whether they enter the
mesh (python-fcl over the mesh's BVH), which faces a grasp covers, grasps backed off to clear the
table, and the tool frames grasps are written in (approaches, Z-Y-Z Euler angles).

Units: lengths in the cell unit, constants in mm (converted with spar_py.core.units.from_mm);
angles in radians. Frames: object frame; tool frames T_g are 4x4 in the object frame.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from spar_py.core.units import from_mm
from spar_py.world.parts.arrays import MeshArrays, mesh_arrays
from spar_py.world.parts.mesh import Face, FeatureGeometry, axis_basis, clean, cross
from spar_py.world.parts.support import DerivedPose, feature_face

if TYPE_CHECKING:
    import trimesh
    from spar_py.world.robot import Gripper

__all__ = [
    "DerivedGrasp", "approaches", "canonical", "covered_faces", "euler_zyz_of", "grasp_problem", "swept_boxes",
    "table_clear", "tool_frame"
]

#: Fingers touching a face are not inside it: boxes are shrunk by this (mm).
TOUCH_MM = 0.02
#: A facet grasp from above whose fingers or palm come nearer the table than this in a stable pose
#: of the part is offered backed off along its approach until they clear it (mm): more than the
#: collision margin (world.collision.scene's DEFAULT_MARGIN_MM, 2 mm) ...
TABLE_CLEAR_MM = 3.0
#: ... in steps of this (mm) ...
TABLE_STEP_MM = 1.0
#: ... where the approach descends at least this steeply (deg below the horizontal).
TABLE_APPROACH_DEG = 15.0


@dataclass(frozen=True)
class DerivedGrasp:
    """A derived grasp: T (4x4, tool frame in the object frame), ``euler`` (X, Y, Z in the cell
    unit, Z-Y-Z phi, theta, psi in radians: geometry.eulerxyz(*euler) == T), ``width`` W_g,
    the gripped faces and the faces the gripper covers."""

    label: str
    gfaces: tuple[str, ...]
    ofaces: tuple[str, ...]
    T: np.ndarray
    euler: tuple[float, float, float, float, float, float]
    width: float


def _tri_box(tri: np.ndarray, lo: np.ndarray, hi: np.ndarray,
             bbox: tuple[np.ndarray, np.ndarray] | None = None) -> np.ndarray:
    """(n,) bool: triangles (n, 3, 3) that meet the axis-aligned box [lo, hi] (separating axes:
    the box's 3 axes, the triangle's normal, the 9 edge cross products); ``bbox`` the
    triangles' (min, max) corners if already known."""
    c = (lo + hi) / 2
    h = (hi - lo) / 2
    tmin, tmax = bbox if bbox is not None else (tri.min(1), tri.max(1))
    keep = ((tmin <= hi) & (tmax >= lo)).all(1)
    if not keep.any():
        return keep
    idx = np.flatnonzero(keep)
    t = tri[idx] - c
    e = np.stack([t[:, 1] - t[:, 0], t[:, 2] - t[:, 1], t[:, 0] - t[:, 2]], axis=1)  # (m, 3, 3)
    n = cross(e[:, 0], e[:, 1])
    ok = np.abs(np.einsum("ij,ij->i", n, t[:, 0])) <= np.abs(n) @ h + 1e-15
    zero = np.zeros(e.shape[:2])
    ex, ey, ez = e[..., 0], e[..., 1], e[..., 2]
    for a in (np.stack([zero, -ez, ey], -1), np.stack([ez, zero, -ex], -1), np.stack([-ey, ex, zero], -1)):
        # a: (m, 3 edges, 3), the cross product of a box axis with each edge
        p = np.einsum("mjd,mvd->mjv", a, t)  # (m, edges, vertices)
        r = np.abs(a) @ h
        ok &= ~((p.min(2) > r + 1e-15) | (p.max(2) < -r - 1e-15)).any(1)
    keep[idx] = ok
    return keep


def swept_boxes(g: Gripper, width: float, reach: float, shrink: float) -> list[tuple[str, np.ndarray, np.ndarray]]:
    """(what, lo, hi) boxes in the tool frame: the closed fingers at ``width``, the open fingers
    and the palm swept in along the approach from ``reach`` away, each shrunk by ``shrink``."""
    u, L, t = g.finger_width / 2, g.finger_length, g.finger_thickness
    o, w = g.finger_separation / 2, width / 2
    px, py = g.palm_half()
    boxes = [
        ("a finger", np.array([-u, w, -L]), np.array([u, w + t, 0.0])),
        ("a finger", np.array([-u, -w - t, -L]), np.array([u, -w, 0.0])),
        ("an open finger on the approach", np.array([-u, o, -reach]), np.array([u, o + t, 0.0])),
        ("an open finger on the approach", np.array([-u, -o - t, -reach]), np.array([u, -o, 0.0])),
        ("the palm", np.array([-px, -py, -reach]), np.array([px, py, -L])),
    ]
    return [(what, lo + shrink, hi - shrink) for what, lo, hi in boxes if np.all(hi - lo > 2 * shrink)]


class _BVH:
    """A mesh's python-fcl collision object, kept in its metadata with the arrays it was built
    from; a copy of the mesh (trimesh deep-copies metadata; fcl's objects cannot be) gets none."""

    def __init__(self, of: MeshArrays, obj: Any) -> None:
        self.of, self.obj = of, obj

    def __deepcopy__(self, memo: dict) -> None:
        return None


def _bvh(mesh: "trimesh.Trimesh") -> Any:
    """The mesh's triangles as a python-fcl collision object (a BVH, object frame)."""
    A = mesh_arrays(mesh)
    c = mesh.metadata.get("_spar_bvh")
    if c is not None and c.of is A:
        return c.obj
    import fcl  # on a derivation only (a cache miss); world.product.assembly's sweeps import it too
    from spar_py.world.collision import bvh

    obj = fcl.CollisionObject(bvh(A.V, A.F), fcl.Transform())
    mesh.metadata["_spar_bvh"] = _BVH(A, obj)
    return obj


def grasp_problem(mesh: "trimesh.Trimesh", T: np.ndarray, width: float, g: Gripper, unit: str) -> str | None:
    """Why the gripper at tool pose T (object frame) with fingers ``width`` apart cannot hold the
    part, or None: wider than the opening, or a finger or the palm inside the part (a box of
    :func:`swept_boxes` meets one of its triangles: python-fcl's box-triangle test over the
    mesh's BVH; the boxes are shrunk by TOUCH_MM, so a finger resting on a face is not in it)."""
    if width > g.finger_separation * (1 + 1e-9):
        return f"{width:.4g} {unit} wide, more than the gripper's opening {g.finger_separation:.4g} {unit}"
    import fcl

    A = mesh_arrays(mesh)
    reach = 2 * A.diag + g.finger_length + g.palm_length
    part = _bvh(mesh)
    R, o = np.asarray(T, float)[:3, :3], np.asarray(T, float)[:3, 3]
    request = fcl.CollisionRequest()
    for what, lo, hi in swept_boxes(g, width, reach, from_mm(unit, TOUCH_MM)):
        box = fcl.CollisionObject(fcl.Box(*(hi - lo)), fcl.Transform(R, R @ ((lo + hi) / 2) + o))
        if fcl.collide(box, part, request, fcl.CollisionResult()):
            return f"{what} enters the part"
    return None


def euler_zyz_of(T: np.ndarray) -> tuple[float, float, float, float, float, float]:
    """(X, Y, Z, phi, theta, psi) with geometry.eulerxyz(...) == T (Paul's Z-Y-Z, radians)."""
    R = T[:3, :3]
    theta = math.acos(max(-1.0, min(1.0, float(R[2, 2]))))
    if abs(math.sin(theta)) > 1e-9:
        phi = math.atan2(R[1, 2], R[0, 2])
        psi = math.atan2(R[2, 1], -R[2, 0])
    elif R[2, 2] > 0:
        phi, psi = 0.0, math.atan2(R[1, 0], R[0, 0])
    else:
        phi, psi = 0.0, math.atan2(R[0, 1], R[1, 1])

    def tidy(a: float) -> float:
        d = round(math.degrees(a), 9)
        d = 180.0 if d == -180.0 else d
        return math.radians(d) + 0.0

    x, y, z = (float(v) + 0.0 for v in T[:3, 3])
    return (x, y, z, tidy(phi), tidy(theta), tidy(psi))


def canonical(c: np.ndarray) -> np.ndarray:
    """The closing direction with its largest component (the first of equals) positive."""
    i = int(np.argmax(np.round(np.abs(c), 9) - 1e-12 * np.arange(3)))
    return c if c[i] > 0 else -c


def tool_frame(p: np.ndarray, c: np.ndarray, a: np.ndarray) -> np.ndarray:
    """The tool frame at p with y = c (closing) and z = a (approach)."""
    T = np.eye(4)
    T[:3, 0], T[:3, 1], T[:3, 2], T[:3, 3] = cross(c, a), c, a, p
    return clean(T, 1e-9)


def approaches(c: np.ndarray, step: float) -> list[np.ndarray]:
    e1, e2 = axis_basis(c)
    n = max(1, int(round(2 * math.pi / step)))
    return [clean(math.cos(2 * math.pi * k / n) * e1 + math.sin(2 * math.pi * k / n) * e2, 1e-12) for k in range(n)]


def covered_faces(mesh: "trimesh.Trimesh", faces: list[Face], features: tuple[FeatureGeometry, ...], T: np.ndarray,
                  width: float, g: Gripper, unit: str) -> set[int]:
    """The faces the gripper at T covers: a planar face if the palm or a closed finger reaches
    beyond its plane (the part could not rest on that face while held); a feature's face if
    they enter the space the mating part needs (a peg: the prism of half-width r about the shaft
    from its root outwards; a hole: that about the hole's axis out of its mouth)."""
    s = from_mm(unit, TOUCH_MM)
    reach = g.finger_length + g.palm_length
    boxes = [b for b in swept_boxes(g, width, reach, s) if "open" not in b[0]]
    corners = np.concatenate([np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1])
                                        for z in (lo[2], hi[2])]) for _, lo, hi in boxes])
    P = corners @ T[:3, :3].T + T[:3, 3]  # gripper corners in the object frame
    out = {k for k, f in enumerate(faces) if f.planar and (P @ f.normal > f.offset + s).any()}
    for feature in features:
        k = feature_face(faces, feature)
        if k is not None:
            e1, e2 = axis_basis(feature.direction)
            F = np.eye(4)
            F[:3, 0], F[:3, 1], F[:3, 2], F[:3, 3] = e1, e2, feature.direction, feature.origin
            big = 10 * mesh_arrays(mesh).diag + reach
            r = feature.reach
            lo, hi = (np.array([-r, -r, 0.0]), np.array([r, r, big])) if feature.kind == "peg" else (
                np.array([-r, -r, -big]), np.array([r, r, 0.0]))
            M = np.linalg.inv(F) @ T  # tool frame in the feature's frame
            for _, blo, bhi in boxes:
                c = np.array([[x, y, z] for x in (blo[0], bhi[0]) for y in (blo[1], bhi[1]) for z in (blo[2], bhi[2])])
                quads = c[[0, 1, 3, 2, 4, 5, 7, 6]] @ M[:3, :3].T + M[:3, 3]
                tri = quads[np.array([[0, 1, 2], [0, 2, 3], [4, 5, 6], [4, 6, 7], [0, 1, 5], [0, 5, 4],
                                      [2, 3, 7], [2, 7, 6], [1, 2, 6], [1, 6, 5], [0, 3, 7], [0, 7, 4]])]
                inside = ((quads > lo) & (quads < hi)).all(1).any()
                if inside or _tri_box(tri, lo + s, hi - s).any():
                    out.add(k)
                    break
    return out


def table_clear(T: np.ndarray, width: float, g: Gripper, poses: "list[DerivedPose]", unit: str) -> list[np.ndarray]:
    """Shallower versions of the grasp at T (fingers ``width`` apart) for a part lying in its
    stable ``poses``: where the approach points down (at least TABLE_APPROACH_DEG below the
    horizontal) and the closed fingers or the palm come nearer the table than TABLE_CLEAR_MM (a
    part lower than the fingers' reach, gripped with its contact centre near the table), the
    tool backed off along its approach until they clear it by that, in whole TABLE_STEP_MM
    (at most the finger length: deeper the pads would leave the part). One per distinct
    back-off, shallowest first; the caller keeps those whose pads still touch the part."""
    clear, step = from_mm(unit, TABLE_CLEAR_MM), from_mm(unit, TABLE_STEP_MM)
    boxes = [b for b in swept_boxes(g, width, g.finger_length + g.palm_length, 0.0) if "open" not in b[0]]
    corners = np.concatenate([np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1])
                                        for z in (lo[2], hi[2])]) for _, lo, hi in boxes])
    P = corners @ T[:3, :3].T + T[:3, 3]  # object frame
    a = T[:3, 2]
    down = math.sin(math.radians(TABLE_APPROACH_DEG))
    backs: set[int] = set()
    for pose in poses:
        up = np.asarray(pose.R, float)[2]  # world z of object directions
        fall = -float(up @ a)  # how fast the tool descends along its approach
        low = float((P @ up).min()) + pose.height
        if fall < down or low >= clear:
            continue
        k = math.ceil((clear - low) / fall / step - 1e-9)
        if k * step <= g.finger_length:
            backs.add(k)
    out = []
    for k in sorted(backs):
        Ts = T.copy()
        Ts[:3, 3] = T[:3, 3] - k * step * a
        out.append(clean(Ts, 1e-9))
    return out
