"""What a part rests on: the table, a support's top or another part's top, and whether it
rests there stably.

A *surface* is a horizontal convex polygon at a height: the table top (z = 0, over its extent
or the whole plane), the top of an obstacle marked ``support: true`` (its highest face), or the
top of a part (the highest face of its shape where it lies). A part *rests* on a surface when
its lowest point is at the surface's height (within a tolerance) and its centre of mass (the
shape's, uniform density) projects inside its *support polygon*: the contact face (the hull of
its points at its lowest height) intersected with the surface's polygon, both convex, so the
centre must lie in each.

Units: the cell unit; world frame, Z up, table top z = 0. The tolerances are mm
(units.INTERNAL_UNIT) converted where used.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Iterable, Sequence

import numpy as np

from spar_py.core.geometry import convex_hull_2d, same_stable_pose
from spar_py.core.model import ObjectModel, Solid
from spar_py.core.units import from_mm

if TYPE_CHECKING:
    from spar_py.core.model import Cell
    from spar_py.world.collision import Obstacle

__all__ = ["REST_TOL_MM", "Rest", "Surface", "centre_of_mass", "contact", "inside", "lowest", "part_points",
           "mass_properties", "part_surface", "rest", "rest_of", "rest_of_body", "solid_points", "support_surfaces",
           "surfaces_of", "table_surface"]

#: A part's lowest point may be this far from a surface to rest on it (mm).
REST_TOL_MM = 0.5
#: Sides of the polygon inscribed in a cylinder's rim, for a part's points (inscribed: a
#: contact face or top is never overstated, so a centre found inside it is inside the true one).
RIM_SIDES = 16
#: A cylinder body of an obstacle is held (world/collision/bodies.py) as its circumscribed prism of this many
#: sides; its top polygon is shrunk to the inscribed one.
OBSTACLE_SIDES = 16


@dataclass(frozen=True)
class Surface:
    """A horizontal surface a part may rest on: ``name`` ("table", a support's or a part's name),
    its height ``z`` and its ``polygon`` ((k, 2) world xy, CCW, convex), None: the whole plane."""

    name: str
    z: float
    polygon: np.ndarray | None

    def describe(self) -> str:
        """How a message names it: "the table", "fixture_plate's top"."""
        return "the table" if self.name == "table" else f"{self.name}'s top"


@dataclass(frozen=True)
class Rest:
    """What a part at a pose rests on: the ``surface`` (None: none under its lowest point within
    the tolerance), its lowest height ``low``, the ``gap`` to the nearest surface under its centre
    (> 0 floating above it, < 0 sunk into it; 0 when it rests), that surface (``nearest``), and
    ``why`` it is not at rest (None when it rests stably)."""

    surface: Surface | None
    low: float
    gap: float
    nearest: Surface | None
    why: str | None

    @property
    def ok(self) -> bool:
        return self.why is None


def table_surface(cell: "Cell") -> Surface:
    """The table top: z = 0 over the problem's ``table:`` extent (None: the whole plane)."""
    t = cell.table
    if t is None:
        return Surface("table", 0.0, None)
    x0, x1, y0, y1 = t
    return Surface("table", 0.0, np.array([[x0, y0], [x1, y0], [x1, y1], [x0, y1]], float))


def _top(points: np.ndarray, tol: float) -> tuple[float, np.ndarray]:
    """(height, CCW polygon) of the highest face of points (k, 3): their highest z and the hull of
    the points within ``tol`` of it."""
    z = float(points[:, 2].max())
    return z, convex_hull_2d(points[points[:, 2] >= z - tol][:, :2])


def _obstacle_points(ob: "Obstacle") -> list[np.ndarray]:
    """Each body's vertices (world), a cylinder's shrunk from its circumscribed prism to the
    inscribed one (about its axis), so its top never overstates the true one."""
    out = []
    for b in ob.bodies:
        P = np.asarray(b.points, float)
        if b.kind == "cylinder":
            c, axis = b.T[:3, 3], b.T[:3, 2]
            along = (P - c) @ axis
            radial = P - c - along[:, None] * axis
            P = c + along[:, None] * axis + radial * math.cos(math.pi / OBSTACLE_SIDES)
        out.append(P)
    return out


def support_surfaces(cell: "Cell") -> list[Surface]:
    """The tops of the cell's obstacles marked ``support: true``, in the file's order."""
    tol = from_mm(cell.unit, REST_TOL_MM)
    out = []
    for ob in cell.obstacles:
        if getattr(ob, "support", False):
            z, poly = _top(np.concatenate(_obstacle_points(ob)), tol)
            out.append(Surface(ob.name, z, poly))
    return out


def obstacle_footprint(ob: "Obstacle") -> np.ndarray:
    """(k, 2) CCW: the obstacle's shadow on the table (the hull of its bodies' vertices' xy; a
    cylinder's by its circumscribed prism: a superset)."""
    return convex_hull_2d(np.concatenate([np.asarray(b.points, float) for b in ob.bodies])[:, :2])


def solid_points(s: Solid, sides: int = RIM_SIDES) -> np.ndarray:
    """(k, 3) vertices of a primitive in the object frame: a box's corners, a hull's points, a
    z-cylinder's inscribed prism."""
    if s.kind == "hull":
        return np.asarray(s.points, float)
    if s.kind == "cylinder":
        a = 2 * np.pi * np.arange(sides) / sides
        ring = s.radius * np.stack([np.cos(a), np.sin(a)], axis=1)
        return np.concatenate([np.column_stack([ring, np.full(sides, z)]) for z in (s.lo[2], s.hi[2])])
    return np.array([[x, y, z] for x in (s.lo[0], s.hi[0]) for y in (s.lo[1], s.hi[1])
                     for z in (s.lo[2], s.hi[2])], float)


def part_points(model: ObjectModel, T: np.ndarray) -> np.ndarray:
    """(k, 3) the vertices of ``model``'s shape at world pose T (4x4): boxes' corners, hulls'
    points, cylinders' inscribed prisms; a model without a shape: its frame's origin."""
    T = np.asarray(T, float)
    if not model.shape:
        return T[:3, 3][None].copy()
    P = np.concatenate([solid_points(s) for s in model.shape])
    return P @ T[:3, :3].T + T[:3, 3]


def lowest(model: ObjectModel, T: np.ndarray) -> float:
    """The lowest world z of the shape at T, cylinders exactly (a rim of radius r about axis a
    reaches r sqrt(1 - a_z^2) below its centre)."""
    T = np.asarray(T, float)
    low = math.inf
    for s in model.shape:
        if s.kind == "cylinder":
            a = T[:3, 2]
            drop = s.radius * math.sqrt(max(0.0, 1.0 - float(a[2]) ** 2))
            low = min(low, *(float((T @ np.array([0.0, 0.0, z, 1.0]))[2]) - drop for z in (s.lo[2], s.hi[2])))
        else:
            low = min(low, float((solid_points(s) @ T[:3, :3].T + T[:3, 3])[:, 2].min()))
    return low


def part_surface(name: str, model: ObjectModel, T: np.ndarray, tol: float) -> Surface:
    """The top of a part (``name``) of ``model`` at world pose T: its highest face."""
    z, poly = _top(part_points(model, T), tol)
    return Surface(name, z, poly)


def contact(model: ObjectModel, T: np.ndarray, tol: float) -> tuple[float, np.ndarray]:
    """(lowest z, CCW contact polygon (k, 2)) of ``model`` at world pose T: the hull of its points
    within ``tol`` of its lowest point (a segment or a point where it touches along a line)."""
    P = part_points(model, T)
    low = lowest(model, T) if model.shape else float(P[:, 2].min())
    return low, convex_hull_2d(P[P[:, 2] <= low + tol][:, :2])


def centre_of_mass(model: ObjectModel) -> np.ndarray:
    """(3,) the shape's centre of mass (object frame, uniform density): the mesh's (trimesh) when
    the model declares its geometry, else the volume-weighted centres of its primitives (boxes and
    cylinders exactly, hulls by their tetrahedra; overlaps counted twice), else the frame's origin."""
    return mass_properties(model)[1]


def mass_properties(model: ObjectModel) -> tuple[float, np.ndarray]:
    """(volume (cell unit^3), centre of mass (3,), object frame) of the shape, uniform density, as
    :func:`centre_of_mass` finds it; a shapeless model: (0, its frame's origin)."""
    if model.geometry is not None:
        from spar_py.world.parts import part_mesh  # trimesh: only a model with geometry

        mesh = part_mesh(model)
        return float(abs(mesh.volume)), np.asarray(mesh.center_mass, float)
    vols, cents = [], []
    for s in model.shape:
        lo, hi = np.asarray(s.lo, float), np.asarray(s.hi, float)
        if s.kind == "box":
            vols.append(float(np.prod(hi - lo)))
            cents.append((lo + hi) / 2)
        elif s.kind == "cylinder":
            vols.append(math.pi * s.radius ** 2 * (hi[2] - lo[2]))
            cents.append(np.array([0.0, 0.0, (lo[2] + hi[2]) / 2]))
        else:
            v, c = _hull_mass(np.asarray(s.points, float))
            vols.append(v)
            cents.append(c)
    if not vols or sum(vols) <= 0:
        return 0.0, np.zeros(3)
    return float(sum(vols)), np.average(np.array(cents), axis=0, weights=np.array(vols))


def _hull_mass(P: np.ndarray) -> tuple[float, np.ndarray]:
    """(volume, centroid) of the convex hull of P (k, 3): its tetrahedra from an interior point."""
    from scipy.spatial import ConvexHull  # only a hull primitive without a mesh

    h = ConvexHull(P)
    o = P[h.vertices].mean(axis=0)
    tri = P[h.simplices]
    v = np.abs(np.einsum("ij,ij->i", tri[:, 0] - o, np.cross(tri[:, 1] - o, tri[:, 2] - o))) / 6
    c = (tri.sum(axis=1) + o) / 4
    return float(v.sum()), (c * v[:, None]).sum(axis=0) / v.sum()


def inside(poly: np.ndarray | None, p: np.ndarray, tol: float) -> float:
    """How far point p (xy) lies inside the convex CCW polygon ``poly`` (> 0 inside, < 0 outside,
    cell unit; a segment or a point counts its distance as outside, widened by ``tol``); inf for
    None (the whole plane)."""
    if poly is None:
        return math.inf
    P = np.asarray(poly, float)
    p = np.asarray(p, float)[:2]
    if len(P) < 3:  # a point or a segment: inside within tol of it
        a, b = P[0], P[-1]
        e = b - a
        u = float(np.clip((p - a) @ e / (e @ e), 0.0, 1.0)) if e @ e > 0 else 0.0
        return tol - float(np.linalg.norm(p - a - u * e))
    E = np.roll(P, -1, axis=0) - P
    D = p - P
    cross = (E[:, 0] * D[:, 1] - E[:, 1] * D[:, 0]) / np.linalg.norm(E, axis=1)
    return float(cross.min())


def _on_surface(surfaces: Sequence[Surface], low: float, face: np.ndarray, c: np.ndarray, tol: float, unit: str,
                contact: str, edge_gap: bool) -> Rest | None:
    """The rest of a part or body whose lowest point is at ``low`` and centre of mass at ``c``
    (world) on the highest surface at that height: under its centre (tipping over if the centre
    is outside ``face``, its ``contact`` in the message), else over that surface's edge (with the
    centre's distance outside it if ``edge_gap``); None if no surface is at that height."""
    at = [s for s in surfaces if abs(low - s.z) <= tol]
    under = [s for s in at if inside(s.polygon, c, tol) >= -tol]
    if under:
        s = max(under, key=lambda s: s.z)
        if inside(face, c, tol) < -tol:
            return Rest(s, low, 0.0, s, f"tips over on {s.describe()}: its centre of mass is "
                        f"{-inside(face, c, tol):.4g} {unit} outside {contact}")
        return Rest(s, low, 0.0, s, None)
    if at:
        s = max(at, key=lambda s: s.z)
        gap = f": its centre of mass is {-inside(s.polygon, c, tol):.4g} {unit} outside it" if edge_gap else ""
        return Rest(s, low, 0.0, s, f"tips over the edge of {s.describe()}{gap}")
    return None


def rest(model: ObjectModel, T: np.ndarray, surfaces: Sequence[Surface], unit: str,
         com: np.ndarray | None = None, stable: bool = False) -> Rest:
    """What a part of ``model`` at world pose T rests on among ``surfaces``: the surface at its
    lowest point's height (within REST_TOL_MM) under its centre of mass, the highest such; else
    the nearest surface under its centre (the gap, for the message). ``com`` its centre of mass
    (object frame; default :func:`centre_of_mass`). ``stable``: T's rotation is one of the
    model's stable poses, whose centre of mass lies over its contact face (kb checks it), so a
    part whose whole contact face lies on a surface rests there without the centre computed
    (a mesh's centre needs trimesh)."""
    tol = from_mm(unit, REST_TOL_MM)
    T = np.asarray(T, float)
    low, face = contact(model, T, tol)
    if stable:
        whole = [s for s in surfaces if abs(low - s.z) <= tol
                 and (s.polygon is None or all(inside(s.polygon, p, tol) >= -tol for p in face))]
        if whole:
            s = max(whole, key=lambda s: s.z)
            return Rest(s, low, 0.0, s, None)
    c = T[:3, :3] @ (centre_of_mass(model) if com is None else com) + T[:3, 3]
    on = _on_surface(surfaces, low, face, c, tol, unit, "its contact face", edge_gap=True)
    if on is not None:
        return on
    below = [s for s in surfaces if inside(s.polygon, c, tol) >= -tol]
    if not below:
        below = list(surfaces)
    s = min(below, key=lambda s: (abs(low - s.z), s.z))
    gap = low - s.z
    how = (f"floats {gap:.4g} {unit} above {s.describe()}" if gap > 0
           else f"sinks {-gap:.4g} {unit} into {s.describe()}")
    return Rest(None, low, gap, s, how)


def rest_of(cell: "Cell", obj: str, T: np.ndarray, surfaces: Sequence[Surface]) -> Rest | None:
    """:func:`rest` of a part of ``obj`` at world pose T; a model without a shape by its frame at
    its stable pose's height over its lowest point; None when T's rotation is none of its stable
    poses (nothing to say of a shapeless part then)."""
    model = cell.objects[obj]
    sp = next((p for p in model.poses.values() if same_stable_pose(np.asarray(T, float)[:3, :3], p.R)), None)
    if model.shape:
        return rest(model, T, surfaces, cell.unit, stable=sp is not None)
    if sp is None:
        return None
    low = np.array(T, float)
    low[2, 3] -= sp.height
    return rest(model, low, surfaces, cell.unit, stable=True)


def rest_of_body(cell: "Cell", obj: str, T: np.ndarray, surfaces: Sequence[Surface],
                 carried: Sequence[tuple[str, ObjectModel, np.ndarray]] = (), combined: bool = False) -> Rest | None:
    """:func:`rest_of` of a rigid body: root part ``obj`` at world pose T carrying ``carried``
    ((name, model, world pose) each, the parts mated into it). It rests where the root's resting
    face does, so no carried part may reach below that face (else it rests on that part: refused,
    naming it), and the body's centre of mass (every part's, uniform density, weighted by their
    volumes) must lie over the root's contact face and its surface. ``combined`` (a subassembly's
    own stable pose): it rests on the lowest points of all its parts together, its centre of mass
    over their hull. Without carried parts, the root's own :func:`rest_of`."""
    if not carried:
        return rest_of(cell, obj, T, surfaces)
    model = cell.objects[obj]
    if not model.shape:
        return rest_of(cell, obj, T, surfaces)
    tol = from_mm(cell.unit, REST_TOL_MM)
    T = np.asarray(T, float)
    if combined:
        return _rest_combined(cell, [(obj, model, T), *carried], surfaces)
    low, _ = contact(model, T, tol)
    for name, m, Tc in carried:
        if m.shape and lowest(m, Tc) < low - tol:
            return Rest(None, low, 0.0, None, f"would rest on {name}, which reaches {low - lowest(m, Tc):.4g} "
                        f"{cell.unit} below {obj}'s resting face")
    vols, cents = [], []
    for m, Tp in [(model, T), *((m, np.asarray(Tc, float)) for _, m, Tc in carried)]:
        v, c = mass_properties(m)
        vols.append(v)
        cents.append(Tp[:3, :3] @ c + Tp[:3, 3])
    if sum(vols) <= 0:
        return rest_of(cell, obj, T, surfaces)
    com_world = np.average(np.array(cents), axis=0, weights=np.array(vols))
    com = T[:3, :3].T @ (com_world - T[:3, 3])
    return rest(model, T, surfaces, cell.unit, com=com)


def _rest_combined(cell: "Cell", parts: Sequence[tuple[str, ObjectModel, np.ndarray]],
                   surfaces: Sequence[Surface]) -> Rest:
    """What a rigid body of ``parts`` ((name, model, world pose) each) rests on: the surface at
    the lowest point of them all, its centre of mass (volume-weighted) over the hull of every
    part's points within REST_TOL_MM of that height and over the surface."""
    tol = from_mm(cell.unit, REST_TOL_MM)
    shaped = [(m, np.asarray(Tp, float)) for _, m, Tp in parts if m.shape]
    low = min(lowest(m, Tp) for m, Tp in shaped)
    P = np.concatenate([part_points(m, Tp) for m, Tp in shaped])
    face = convex_hull_2d(P[P[:, 2] <= low + tol][:, :2])
    vols, cents = [], []
    for m, Tp in shaped:
        v, c = mass_properties(m)
        vols.append(v)
        cents.append(Tp[:3, :3] @ c + Tp[:3, 3])
    c = np.average(np.array(cents), axis=0, weights=np.array(vols)) if sum(vols) > 0 else shaped[0][1][:3, 3]
    on = _on_surface(surfaces, low, face, c, tol, cell.unit, "the body's contact", edge_gap=False)
    if on is not None:
        return on
    s = min(surfaces, key=lambda s: (abs(low - s.z), s.z))
    gap = low - s.z
    return Rest(None, low, gap, s, f"floats {gap:.4g} {cell.unit} above {s.describe()}" if gap > 0
                else f"sinks {-gap:.4g} {cell.unit} into {s.describe()}")


def surfaces_of(cell: "Cell", parts: Iterable[tuple[str, ObjectModel, np.ndarray]] = ()) -> list[Surface]:
    """The table, the supports' tops and the tops of ``parts`` ((name, model, world pose) each)."""
    tol = from_mm(cell.unit, REST_TOL_MM)
    return [table_surface(cell), *support_surfaces(cell),
            *(part_surface(n, m, T, tol) for n, m, T in parts if m.shape)]
