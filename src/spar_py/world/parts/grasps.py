"""Parallel-jaw grasps derived from a part's mesh, and the checks of hand-written ones against it.

Grasps (Fig. 19) for a parallel-jaw gripper (world.robot.Gripper): the tool frame's z axis is
the approach, y the closing direction, the tool centre the midpoint between the finger tips.
Candidates: pairs of opposite parallel planar faces (the part between them), and round shafts
(the peg feature's, a cylinder primitive's) across their diameter at quantised closing
directions; the width at most the opening; the faces' overlap (projected on their mid-plane)
at least MIN_CONTACT_MM2, the tool centre at the overlap's centroid (on a shaft: its middle);
approaches quantised in the plane normal to the closing direction (``step``, 45 deg by
default), each kept only if the finger pads touch the overlap by MIN_CONTACT_MM2 (a shaft:
MIN_CONTACT_MM along its side) and neither the closed fingers nor the open gripper (fingers
at the opening and palm, swept in along the approach) enter the part. ``ofaces``: the gripped
faces, every planar face whose plane the palm or a closed finger reaches beyond (the part
cannot rest on it while held) and the feature's face if they enter the space its mate needs.
Each facet grasp kept is also offered at half depth (facets.half_depth, listed after the others):
backed off along its approach while its pads keep half their contact, so the fingers hold the
part's outer half and stay off what lies beside the rest (a mated part's neighbours, the table).

Then the antipodal grasps (:func:`antipodal_grasps`): contact pairs sampled on the surface,
planar or curved, within a friction cone; all of them for a part the candidates above leave
with none, and on a mesh part those on curved faces the candidates above do not close on.

Units: lengths in the cell unit, constants in mm (converted with spar_py.core.units.from_mm);
angles in radians. Frames: object frame; tool frames T_g are 4x4 in the object frame.
"""
from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any

import numpy as np

from spar_py.core.units import from_mm
from spar_py.world.parts.antipodal import ANTIPODAL_SAMPLES, FRICTION_DEG, PAD_PATCH_MM, antipodal_grasps
from spar_py.world.parts.clip import area_centroid_many, face_overlap, pack
from spar_py.world.parts.facets import (
    MIN_CONTACT_MM2, PARALLEL_DEG, face_at, facet_grasps, flatten, half_depth, pad_contact
)
from spar_py.world.parts.hand import (
    DerivedGrasp, approaches, canonical, covered_faces, euler_zyz_of, grasp_problem, table_clear, tool_frame
)
from spar_py.world.parts.mesh import (
    ON_SURFACE_MM, Face, FeatureGeometry, Primitive, axis_basis, clean, cross, derive_faces,
)
from spar_py.world.parts.poses import rest_check
from spar_py.world.parts.support import DerivedPose
from spar_py.world.parts.shafts import (
    MIN_CONTACT_MM, is_round, line_contact, mesh_cylinders, pads_find, shaft_from_above, shafts_of
)

if TYPE_CHECKING:
    import trimesh
    from spar_py.world.robot import Gripper

__all__ = ["check_entries", "derive_grasps", "mate_grasp_usable"]

def derive_grasps(mesh: "trimesh.Trimesh", faces: list[Face], features: tuple[FeatureGeometry, ...],
                  prims: tuple[Primitive, ...], g: Gripper, unit: str, prefix: str,
                  step: float = math.radians(45.0), why: list[str] | None = None,
                  poses: "list[DerivedPose] | None" = None) -> list[DerivedGrasp]:
    """The grasps of the part (module docstring), labelled ``{prefix}1, {prefix}2, ...``: those
    across opposite planar faces and round shafts, then the antipodal grasps found on the
    surface (:func:`antipodal_grasps`): all of them where the first give none; otherwise, on a
    mesh part (no ``prims``), those with a contact on a curved face that no facet or shaft grasp
    closes on and no feature claims (a wheel's tyre beside its axle's grasps; a declared peg is
    the shaft grasps' to close on), while a part of primitives keeps exactly its facet and
    shaft grasps. With none at all, ``why`` (when given) receives one line
    saying which sizes and opening were compared. With the part's stable ``poses``, the
    shallower facet grasps that keep the fingers above the table (:func:`table_clear`) follow
    the others; the facet grasps at half depth (:func:`half_depth`) come last."""
    min_area = from_mm(unit, math.sqrt(MIN_CONTACT_MM2)) ** 2
    cos_par = math.cos(math.radians(PARALLEL_DEG))
    cands: list[tuple[tuple[str, ...], float, np.ndarray]] = []  # (gfaces, width, T)
    shallow: list[tuple[tuple[str, ...], float, np.ndarray]] = []  # the same, backed off (table_clear)
    pending: list[tuple[tuple[str, ...], float, np.ndarray, tuple]] = []  # facet candidates, their pieces
    planar = [k for k, f in enumerate(faces) if f.planar]
    for i in planar:
        for j in planar:
            fa, fb = faces[i], faces[j]
            if j <= i or fa.normal @ fb.normal > -cos_par:
                continue
            width = fa.offset + fb.offset  # n_b = -n_a: the part lies between the planes
            if width <= 0 or width > g.finger_separation * (1 + 1e-9):
                continue
            c = canonical(fa.normal)
            e1, e2 = axis_basis(c)
            pieces = face_overlap(mesh, fa, fb, e1, e2)
            areas, cens = area_centroid_many(*pack(pieces))
            area = float(areas.sum())
            if area < min_area:
                continue
            cen2 = sum(float(a) * q for a, q in zip(areas, cens)) / area
            mid = (fa.offset - width / 2) * fa.normal
            p = clean(mid + cen2[0] * e1 + cen2[1] * e2, 1e-9)
            names = tuple(sorted((fa.name, fb.name), key=lambda n: [f.name for f in faces].index(n)))
            flat = flatten(pieces)
            for a in approaches(c, step):
                T = tool_frame(p, c, a)
                if pad_contact(flat, areas, e1, e2, T, g, min_area) >= min_area:
                    cands.append((names, width, T))
                    for Ts in table_clear(T, width, g, poses or [], unit):
                        if pad_contact(flat, areas, e1, e2, Ts, g, min_area) >= min_area:
                            shallow.append((names, width, Ts))
                    pending.append((names, width, T, (flat, areas, e1, e2)))
    min_len = from_mm(unit, MIN_CONTACT_MM)
    # at least MIN_CONTACT_MM up to ON_SURFACE_MM: a 10 mm shaft closed on from its end has
    # exactly 5 mm under the pad, which a mesh file's float32 vertices (1e-7 of a coordinate)
    # put either side of it, differently in each file unit
    contact_least = min_len - from_mm(unit, ON_SURFACE_MM)
    cyl_normals = {c.face: c.normals for c in mesh_cylinders(mesh, faces, unit)}
    n_pegs = sum(1 for f in features if f.kind == "peg" and f.profile == "round")  # shafts_of lists them first
    at_root: list[tuple[tuple[str, ...], float, np.ndarray]] = []  # a peg's shaft held at its root end
    for k_shaft, (root, d, r, length, fname) in enumerate(shafts_of(faces, features, prims, mesh, unit)):
        if not is_round(mesh, root, d, r, length, unit):
            continue  # a prismatic shaft (a hexagon): its flats are not a cylinder to close on
        normals = cyl_normals.get(fname) if fname is not None else None  # a mesh cylinder's; else a whole round
        name = fname if fname is not None else face_at(faces, mesh, root + d * length / 2 + axis_basis(d)[0] * r,
                                                       unit)
        if name is None or 2 * r > g.finger_separation * (1 + 1e-9):
            continue
        p = clean(root + d * length / 2, 1e-9)
        e1, e2 = axis_basis(d)
        n_dirs = max(1, int(round(math.pi / step)))
        for m in range(n_dirs):
            c = canonical(clean(math.cos(math.pi * m / n_dirs) * e1 + math.sin(math.pi * m / n_dirs) * e2, 1e-12))
            if not pads_find(normals, c):
                continue
            for a in approaches(c, step):
                T = tool_frame(p, c, a)
                if line_contact(root + c * r, d, length, T, g) >= contact_least:
                    cands.append(((name,), 2 * r, T))
                if k_shaft >= n_pegs or float(a @ d) < -1e-9:
                    continue
                # a peg's also at its root end: the pad's far edge along the shaft MIN_CONTACT_MM
                # from the root (the hand beyond the root, clear of the hole the rest goes into)
                t_root = min_len - g.finger_width / 2 * abs(float(cross(c, a) @ d))
                if t_root < length / 2 - 1e-9 * (1.0 + length):
                    T = tool_frame(clean(root + d * t_root, 1e-9), c, a)
                    if line_contact(root + c * r, d, length, T, g) >= contact_least:
                        at_root.append(((name,), 2 * r, T))
        for T in shaft_from_above(mesh, root, d, r, length, g, unit, poses or [], min_len):
            if pads_find(normals, T[:3, 1]):
                shallow.append(((name,), 2 * r, T))
    cands += at_root
    out = facet_grasps(mesh, faces, features, g, unit, prefix, cands, [], unique=False)
    kept = np.array([d.T for d in out]).reshape(-1, 4, 4)
    half: list[tuple[tuple[str, ...], float, np.ndarray]] = []  # the kept facet grasps at half depth
    for names, width, T, pieces in pending:
        if len(kept) and np.abs(kept - T).max(axis=(1, 2)).min() <= 1e-9:
            Th = half_depth(T, *pieces, g, unit, min_area)
            if Th is not None:
                half.append((names, width, Th))
    owner = np.full(len(mesh.faces), -1)
    for k, f in enumerate(faces):
        owner[f.tris] = k
    allowed = None  # triangles one contact of an added antipodal grasp must lie on (None: any)
    if out:
        if prims:  # a part of primitives keeps exactly its facet and shaft grasps
            return facet_grasps(mesh, faces, features, g, unit, prefix, shallow + half, out)
        held = {n for d in out for n in d.gfaces}
        free = [k for k, f in enumerate(faces) if not (f.planar or f.feature) and f.name not in held]
        if not free:
            return facet_grasps(mesh, faces, features, g, unit, prefix, shallow + half, out)
        allowed = np.isin(owner, free)
    found, least, n_pairs = antipodal_grasps(mesh, g, unit, step, allowed)
    order = [f.name for f in faces]
    for T, width, a in found:
        names = tuple(dict.fromkeys(faces[k].name for k in (owner[a.tp], owner[a.tq]) if k >= 0))
        cover = {faces[k].name for k in covered_faces(mesh, faces, features, T, width, g, unit)}
        ofaces = names + tuple(sorted(cover - set(names), key=order.index))
        out.append(DerivedGrasp(f"{prefix}{len(out) + 1}", names, ofaces, T, euler_zyz_of(T), float(round(width, 12))))
    out = facet_grasps(mesh, faces, features, g, unit, prefix, shallow + half, out)
    if not out and why is not None:
        if least is None:
            why.append(f"no two points of its surface face each other within {FRICTION_DEG:g} deg (a sample of "
                       f"{ANTIPODAL_SAMPLES} surface points)")
        elif least > g.finger_separation:
            why.append(f"its narrowest width across opposite surfaces (within {FRICTION_DEG:g} deg) is {least:.4g} "
                       f"{unit}, more than the gripper's opening {g.finger_separation:.4g} {unit}")
        elif not n_pairs:
            why.append(f"its narrowest width across opposite surfaces is {least:.4g} {unit}, within the gripper's "
                       f"opening {g.finger_separation:.4g} {unit}, but no pad finds a {PAD_PATCH_MM:g} mm line of "
                       "surface there")
        else:
            why.append(f"{n_pairs} contact pairs from {least:.4g} {unit} wide are within the gripper's opening "
                       f"{g.finger_separation:.4g} {unit}, but at each the fingers or palm enter the part")
    return out


def check_entries(model: "object", gripper: Gripper, unit: str, which: tuple[str, ...],
                  step: float = math.radians(45.0)) -> list[tuple[str, str, str]]:
    """Hand-written entries of ``model`` (an ObjectModel with a geometry) checked against its
    shape: ``which`` names the lists written by hand ('faces', 'stable_poses', 'grasps').
    Returns (key, expected, got) for each problem, in file order: a face that is not on the
    shape, a stable pose that is not stable (or rests at another height, or on other faces),
    a grasp wider than the opening or whose fingers or palm enter the part."""
    geo = model.geometry  # type: ignore[attr-defined]
    mesh = geo.mesh()
    feats = tuple(f.geometry for f in model.features if f.geometry is not None)  # type: ignore[attr-defined]
    faces = derive_faces(mesh, feats, geo.face_names, unit)
    own = {f.name: k for k, f in enumerate(faces)}
    out: list[tuple[str, str, str]] = []
    tol = max(from_mm(unit, 0.05), 1e-6)
    if "faces" in which:
        for i, f in enumerate(model.faces):  # type: ignore[attr-defined]
            if f not in own:
                out.append((f"faces[{i}]", f"a face of the shape ({', '.join(own)}; face_names: names a face by a "
                            "point on it)", repr(f)))
    if "stable_poses" in which:
        for i, p in enumerate(model.poses.values()):  # type: ignore[attr-defined]
            why, height, lying = rest_check(mesh, p.R, faces, feats, geo.primitives, unit)
            key = f"stable_poses[{i}]"
            if why is not None:
                out.append((key, "a stable pose of the shape", f"{p.label}: {why}"))
            elif abs(height - p.height) > tol:
                out.append((f"{key}.tm", f"the height the shape rests at in {p.label}, {height:.6g} {unit}",
                            f"{p.height:.6g}"))
            else:
                down = {faces[k].name for k in lying}
                bad = [f for f in p.rfaces if f in own and f not in down]
                if bad:
                    out.append((f"{key}.rfaces", f"faces {p.label} rests on ({', '.join(sorted(down))})",
                                ", ".join(map(str, bad))))
    if "grasps" in which:
        for i, g in enumerate(model.grasps.values()):  # type: ignore[attr-defined]
            why = grasp_problem(mesh, g.T, g.width, gripper, unit)
            if why is not None:
                out.append((f"grasps[{i}]", "a grasp the gripper can make", f"{g.label}: {why}"))
    return out


#: A gripper body may reach this far past the hole's mouth plane into the hole side (mm):
#: touching the mouth's plane is outside it.
MOUTH_TOL_MM = 0.05


def mate_grasp_usable(T_grasp: np.ndarray, width: float, gripper: Any, T_a: np.ndarray, hole: FeatureGeometry,
                      unit: str) -> bool:
    """Whether a grasp of the peg (tool frame ``T_grasp`` in the peg's frame, fingers ``width``
    apart) can make the mate seated at ``T_a`` (the peg's frame in the hole part's frame, 4x4):
    every corner of the fingers, the palm and the tool body (``gripper``, a
    world.robot.Gripper: the finger's size, not only its pad) stays on the outer side of
    the plane of the hole's mouth (``hole``: origin the mouth's centre, direction into the part),
    within MOUTH_TOL_MM, so the hand holds only the length that stays out of the hole when seated.
    Cell unit throughout."""
    corners = np.concatenate([np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1])
                                        for z in (lo[2], hi[2])]) for lo, hi in gripper.hand_boxes(width)])
    M = np.asarray(T_a, float) @ np.asarray(T_grasp, float)  # tool frame in the hole part's frame
    depth = (corners @ M[:3, :3].T + M[:3, 3] - hole.origin) @ hole.direction
    return bool(depth.max() <= from_mm(unit, MOUTH_TOL_MM))
