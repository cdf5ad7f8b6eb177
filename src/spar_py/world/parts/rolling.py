"""Round sides of a part's convex hull: the one pose family of a part lying on a cylinder or a
cone (a pin, a shaft, a headed pin on its head's rim and shaft's tip, a gear on its rim).

A round side is found about an axis line (origin o, unit d) of the part: the convex hull's
vertices seen in the half-plane (t, rho) = (along d, distance from the line) make the
profile; an edge of the profile's upper convex hull that is not an end (its normal not along
d) is a cylinder (the edge parallel to d) or a cone about the line, and the side is round
where the hull's vertices on that edge (within SUPPORT_TOL_MM) come at most ROUND_GAP_DEG
apart in azimuth about d, over the whole turn or an arc of it: a tessellated cylinder, a
gear's tooth tips; a hexagonal or octagonal bar keeps its flats (trimesh's poses and
poses.support_check judge those one by one). The axes tried: the round features', the
cylinder primitives', the mesh's cylinders (shafts.mesh_cylinders) and the principal axes of
inertia through the centre of mass (a body of revolution's axis is one).

On a round side the part touches the table along a line (a generator of the side) and rolls:
every roll about d is a rest, one family. The part keeps it by the rule poses.support_check
applies to a face, read along that line: the centre of mass projects on it STABLE_MARGIN_MM
inside its ends, and a tilt of STABLE_TILT_DEG about either end does not topple it. Across the
line it rolls: neutrally where the centre of mass is on the axis (within SUPPORT_TOL_MM), back
to where it is lowest otherwise; either way a roll of STABLE_TILT_DEG must keep it on the side
(an arc ending at a flat that near is left).

One member stands for the family, as the rest of the planner knows a stable pose: one
orientation, turned about the vertical at will. Its roll: with the centre of mass on the axis,
the side's vertex line nearest the azimuth of axis_basis(d)'s e1 (so a tessellated cylinder
rests on a line of its vertices, at its true radius; the mid-azimuth of the longest arc for a
side that is not a whole turn); off the axis, the azimuth where the centre of mass is lowest.

Units: lengths in the cell unit, constants in mm (converted with spar_py.core.units.from_mm);
angles in radians. Frames: the object frame.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from spar_py.core.geometry import convex_hull_2d
from spar_py.core.units import from_mm
from spar_py.world.parts.arrays import mesh_arrays
from spar_py.world.parts.hand import canonical
from spar_py.world.parts.mesh import Face, FeatureGeometry, Primitive, axis_basis, clean, minimal_rotation
from spar_py.world.parts.support import STABLE_MARGIN_MM, STABLE_TILT_DEG, SUPPORT_TOL_MM
from spar_py.world.parts.shafts import mesh_cylinders

if TYPE_CHECKING:
    import trimesh

__all__ = ["ROUND_GAP_DEG", "RoundSide", "round_sides", "side_of", "touching_faces"]

#: A side is round where its vertices come at most this far apart in azimuth about its axis (deg):
#: a 32-gon (11.25 deg) or a 20-tooth gear's tips (18 deg) roll, a 16-gon's flats (22.5 deg) stay.
ROUND_GAP_DEG = 20.0
#: A resting direction belongs to a round side when it is within this of the side's normals (deg).
MATCH_DEG = 2.0


@dataclass(frozen=True)
class RoundSide:
    """A round side of the part's convex hull (module docstring), object frame, cell unit.

    ``origin`` and unit ``axis``: the axis line; the side runs from ``t = ends[0]`` to
    ``ends[1]`` along it with radii ``radii``; ``sin_beta``: the axis component of its outward
    normals (0 on a cylinder); ``arcs``: the azimuth ranges (rad, about axis_basis(axis), lo <=
    hi, lo in [-pi, pi)) it covers, or () for the whole turn. ``down``: the outward normal at the
    member standing for the family (pointing down when it rests), ``roll`` that member's azimuth;
    ``why``: why the part does not keep the family (None: it keeps it); ``on``: the indices of
    the hull's vertices on the side (into the ``hull`` :func:`round_sides` was given);
    ``neutral``: the centre of mass is on the axis (every roll rests; else only ``roll``)."""

    origin: np.ndarray
    axis: np.ndarray
    ends: tuple[float, float]
    radii: tuple[float, float]
    sin_beta: float
    arcs: tuple[tuple[float, float], ...]
    roll: float
    down: np.ndarray
    why: str | None
    on: np.ndarray
    neutral: bool = True

    @property
    def full(self) -> bool:
        """Whether the side goes all round the axis."""
        return not self.arcs

    def member_problem(self, down: np.ndarray) -> str | None:
        """Why the part resting on this side with ``down`` (object frame, unit) pointing down is
        not kept there, or None: the family's verdict, and the roll: any one ``STABLE_TILT_DEG``
        inside the side's arcs where the centre of mass is on the axis, else ``roll`` (MATCH_DEG)."""
        if self.why is not None:
            return self.why
        e1, e2 = axis_basis(self.axis)
        psi = float(_azimuth(np.asarray(down, float), e1, e2))
        if not self.neutral:
            off = abs((psi - self.roll + math.pi) % (2 * math.pi) - math.pi)
            if off > math.radians(MATCH_DEG):
                return (f"it rolls on its round side to where its centre of mass is lowest, {math.degrees(off):.3g} "
                        "deg away")
            return None
        inside = _in_arcs(psi, self.arcs, 1e-9)
        if inside < math.radians(STABLE_TILT_DEG) - 1e-9:
            return (f"it rolls off its round side: the side ends {math.degrees(max(inside, 0.0)):.3g} deg from where "
                    f"it rests (at least {STABLE_TILT_DEG:g} deg needed)")
        return None

    def rest(self, mesh: "trimesh.Trimesh") -> tuple[np.ndarray, float]:
        """The member standing for the family: R (object to world, ``down`` to world -z, the
        least rotation) and the object frame's height above the table (the mesh's lowest point)."""
        R = clean(minimal_rotation(self.down, np.array([0.0, 0.0, -1.0])), 1e-9)
        return R, float(round(-float((mesh_arrays(mesh).V @ R[2]).min()), 12))


def _azimuth(v: np.ndarray, e1: np.ndarray, e2: np.ndarray) -> np.ndarray:
    return np.arctan2(v @ e2, v @ e1)


def _in_arcs(psi: float, arcs: tuple[tuple[float, float], ...], slack: float) -> float:
    """How far inside the nearest covering arc azimuth ``psi`` is (rad; the whole turn: inf), or
    -inf when no arc covers it within ``slack``."""
    if not arcs:
        return math.inf
    best = -math.inf
    for lo, hi in arcs:
        for p in (psi, psi + 2 * math.pi, psi - 2 * math.pi):
            if lo - slack <= p <= hi + slack:
                best = max(best, min(p - lo, hi - p))
    return best


def _axes(mesh: "trimesh.Trimesh", faces: list[Face], features: tuple[FeatureGeometry, ...],
          prims: tuple[Primitive, ...], unit: str, tol: float) -> list[tuple[np.ndarray, np.ndarray]]:
    """The axis lines tried (module docstring), each once: (a point on it, canonical unit direction)."""
    cands = [(f.origin, f.direction) for f in features if f.profile == "round"]
    cands += [(np.zeros(3), np.array([0.0, 0.0, 1.0])) for p in prims if p.kind == "cylinder" and not p.subtract]
    cands += [(c.root, c.axis) for c in mesh_cylinders(mesh, faces, unit)]
    com = mesh_arrays(mesh).com
    _, vecs = np.linalg.eigh(np.asarray(mesh.moment_inertia, float))
    cands += [(com, vecs[:, k]) for k in range(3)]
    out: list[tuple[np.ndarray, np.ndarray]] = []
    for o, d in cands:
        d = canonical(clean(np.asarray(d, float) / np.linalg.norm(d), 1e-12))
        o = np.asarray(o, float)
        if any(abs(float(d @ e)) > 1 - 1e-9 and np.linalg.norm(np.cross(o - p, e)) < tol for p, e in out):
            continue
        out.append((o, d))
    return out


def round_sides(mesh: "trimesh.Trimesh", hull: np.ndarray, faces: list[Face], features: tuple[FeatureGeometry, ...],
                prims: tuple[Primitive, ...], unit: str) -> list[RoundSide]:
    """The round sides of the part whose convex hull has vertices ``hull`` (k, 3) (module
    docstring), kept or not (``why``), each once."""
    tol = from_mm(unit, SUPPORT_TOL_MM)
    com = mesh_arrays(mesh).com
    gap = math.radians(ROUND_GAP_DEG)
    tilt = math.radians(STABLE_TILT_DEG)
    out: list[RoundSide] = []
    for o, d in _axes(mesh, faces, features, prims, unit, tol):
        e1, e2 = axis_basis(d)
        P = hull - o
        t = P @ d
        W = P - np.outer(t, d)
        rho = np.linalg.norm(W, axis=1)
        prof = convex_hull_2d(np.vstack([np.column_stack([t, rho]), [[t.min(), 0.0], [t.max(), 0.0]]]))
        for a, b in zip(prof, np.roll(prof, -1, axis=0)):
            e = b - a
            L = float(np.linalg.norm(e))
            if L <= tol:
                continue
            n = np.array([e[1], -e[0]]) / L  # outward: the profile is counter-clockwise
            if n[1] < math.sin(math.radians(1.0)):
                continue  # an end (normal along the axis) or the axis itself
            TR = np.column_stack([t, rho])
            on = (np.abs(TR @ n - float(a @ n)) <= tol) & (rho > tol)
            # the lines it rests on run from one end's ring to the other's: both rings dense there
            rings = [np.unique(np.round(_azimuth(W[on & (np.linalg.norm(TR - q, axis=1) <= tol)], e1, e2), 9))
                     for q in (a, b)]
            arcs = _meet(_arcs(rings[0], gap), _arcs(rings[1], gap), gap)
            if arcs is None:
                continue
            psi = np.intersect1d(*rings)
            psi = psi if len(psi) else rings[0]
            out.append(_side(o, d, e1, e2, a, b, n, arcs, psi, com, tol, tilt, unit, np.flatnonzero(on)))
    # one side found about two axes (a fitted cylinder's and the principal one, a hair apart): once
    out.sort(key=lambda s: (s.why is not None, -len(s.on)))
    kept: list[RoundSide] = []
    for side in out:
        if not any(abs(float(side.axis @ k.axis)) > math.cos(math.radians(MATCH_DEG))
                   and abs(side.sin_beta * float(side.axis @ k.axis) - k.sin_beta) < math.sin(math.radians(MATCH_DEG))
                   and len(np.intersect1d(side.on, k.on)) for k in kept):
            kept.append(side)
    return kept


def _arcs(psi: np.ndarray, gap: float) -> tuple[tuple[float, float], ...] | None:
    """The runs of sorted azimuths ``psi`` whose steps are at most ``gap``: () for the whole turn,
    else the runs at least twice ``gap`` wide (lo, hi; hi may pass pi: a flat face or two seen
    across less are no round side), None when there are none."""
    if len(psi) < 2:
        return None
    steps = np.diff(np.r_[psi, psi[0] + 2 * math.pi])
    breaks = np.flatnonzero(steps > gap + 1e-12)
    if not len(breaks):
        return ()
    runs = []
    for k, j in enumerate(breaks):
        start = (j + 1) % len(psi)
        stop = breaks[(k + 1) % len(breaks)]
        lo = float(psi[start])
        hi = float(psi[stop]) + (2 * math.pi if stop < start else 0.0)
        if hi - lo >= 2 * gap - 1e-9:
            runs.append((lo, hi))
    return tuple(runs) or None


def _meet(A: tuple[tuple[float, float], ...] | None, B: tuple[tuple[float, float], ...] | None,
          gap: float) -> tuple[tuple[float, float], ...] | None:
    """The azimuths both arc sets cover (:func:`_arcs`' form), runs narrower than twice ``gap`` left out."""
    if A is None or B is None:
        return None
    if not A or not B:
        return A or B

    def pieces(arcs: tuple[tuple[float, float], ...]) -> list[tuple[float, float]]:
        out = []
        for lo, hi in arcs:  # lo in [-pi, pi), hi < lo + 2 pi: at most two pieces within [-pi, pi]
            out += [(lo, min(hi, math.pi))] + ([(-math.pi, hi - 2 * math.pi)] if hi > math.pi else [])
        return sorted(out)

    both = sorted((max(a0, b0), min(a1, b1)) for a0, a1 in pieces(A) for b0, b1 in pieces(B)
                  if min(a1, b1) > max(a0, b0))
    if both and len(both) > 1 and both[0][0] <= -math.pi + 1e-12 and both[-1][1] >= math.pi - 1e-12:
        both = [(both[-1][0], both[0][1] + 2 * math.pi)] + both[1:-1]  # one run across the half turn
    runs = tuple((lo, hi) for lo, hi in both if hi - lo >= 2 * gap - 1e-9)
    return runs or None


def _side(o: np.ndarray, d: np.ndarray, e1: np.ndarray, e2: np.ndarray, a: np.ndarray, b: np.ndarray,
          n: np.ndarray, arcs: tuple[tuple[float, float], ...], psi: np.ndarray, com: np.ndarray, tol: float,
          tilt: float, unit: str, on: np.ndarray) -> RoundSide:
    """The side on profile edge a -> b (outward normal n) with its member and verdict."""
    c = com - o
    ct = float(c @ d)
    cp = c - ct * d
    off_axis = float(np.linalg.norm(cp)) > tol
    if off_axis:
        roll = float(math.atan2(float(cp @ e2), float(cp @ e1)))  # where the centre of mass is lowest
    elif not arcs:
        roll = float(psi[np.argmin(np.abs((psi + math.pi) % (2 * math.pi) - math.pi))])
    else:
        lo, hi = max(arcs, key=lambda r: r[1] - r[0])
        mid = (lo + hi) / 2
        pick = psi[np.argmin(np.abs((psi - mid + math.pi) % (2 * math.pi) - math.pi))]
        roll = float((pick + math.pi) % (2 * math.pi) - math.pi)
    er = math.cos(roll) * e1 + math.sin(roll) * e2
    down = clean(n[0] * d + n[1] * er, 1e-12)
    down = down / np.linalg.norm(down)
    ends = (float(a[0]), float(b[0]))
    radii = (float(a[1]), float(b[1]))
    why = None
    inside = _in_arcs(roll, arcs, 1e-9)
    if inside < tilt - 1e-9:
        why = (f"it rolls off its round side: the side ends {math.degrees(max(inside, 0.0)):.3g} deg from where it "
               f"rests (at least {STABLE_TILT_DEG:g} deg needed)")
    else:
        p1, p2 = o + ends[0] * d + radii[0] * er, o + ends[1] * d + radii[1] * er
        L = float(np.linalg.norm(p2 - p1))
        s = float((com - p1) @ (p2 - p1)) / L
        margin = min(s, L - s)
        high = float((p1 - com) @ down)
        need = from_mm(unit, STABLE_MARGIN_MM)
        if margin < need:
            where = "outside" if margin < 0 else "only"
            why = (f"lying on its round side its centre of mass is {where} {abs(margin):.4g} {unit} "
                   f"{'from' if margin < 0 else 'inside'} the end of the line it rests on (at least {need:.4g} "
                   f"{unit} inside needed)")
        elif math.degrees(math.atan2(margin, max(high, 1e-300))) < STABLE_TILT_DEG:
            why = (f"lying on its round side it tips over on a tilt of "
                   f"{math.degrees(math.atan2(margin, high)):.3g} deg (its centre of mass {high:.4g} {unit} high, "
                   f"{margin:.4g} {unit} inside the end of the line it rests on; at least {STABLE_TILT_DEG:g} deg "
                   "needed)")
    return RoundSide(o, d, ends, radii, float(n[0]), arcs, roll, down, why, on, not off_axis)


def side_of(sides: list[RoundSide], hull: np.ndarray, down: np.ndarray, unit: str) -> int | None:
    """The index of the side among ``sides`` (found on ``hull``) the part rests on when
    ``down`` (object frame, unit) points down, or None: ``down`` within MATCH_DEG of the side's
    normals at an azimuth it covers, and every hull vertex lowest then (within SUPPORT_TOL_MM)
    one of the side's (a flat end whose normal a shallow cone's comes near is not the cone)."""
    v = np.asarray(down, float)
    z = np.asarray(hull, float) @ v
    low = np.flatnonzero(z >= z.max() - from_mm(unit, SUPPORT_TOL_MM))
    near = math.sin(math.radians(MATCH_DEG))
    for k, side in enumerate(sides):
        if abs(float(v @ side.axis) - side.sin_beta) > near:
            continue
        e1, e2 = axis_basis(side.axis)
        if (_in_arcs(float(_azimuth(v, e1, e2)), side.arcs, math.radians(MATCH_DEG)) > -math.inf
                and np.isin(low, side.on).all()):
            return k
    return None


def touching_faces(mesh: "trimesh.Trimesh", faces: list[Face], R: np.ndarray, unit: str) -> list[int]:
    """Indices of the faces a part turned by R rests on when it lies on a line: those with a
    triangle edge on the table (two vertices within SUPPORT_TOL_MM of the lowest point), and
    the curved ones touching it at a vertex (a headed pin on its head's rim and its shaft's tip
    touches at two points); a planar end touching the line at its rim only is not one."""
    tol = from_mm(unit, SUPPORT_TOL_MM)
    A = mesh_arrays(mesh)
    z = A.V @ np.asarray(R, float)[2]
    low = z < z.min() + tol
    on = low[A.F]
    return [k for k, f in enumerate(faces)
            if (on[f.tris].sum(axis=1) >= 2).any() or (not f.planar and on[f.tris].any())]
