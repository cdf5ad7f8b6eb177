"""Derive a product from its parts' meshes in their assembled poses: contacts, mates, seats,
insertion directions and precedence by disassembly.

Frames and units: every mesh is given in the product frame (its part's pose applied), all
lengths in one unit (the caller's; the tolerances in the same unit). Nothing here reads a
file: kb.products builds the meshes and turns the result into features and mates.

- Overlaps: parts whose meshes overlap as placed (world.product.overlap) are found first; when
  any do, they are the result (:attr:`AssemblyResult.overlaps`) and nothing else is derived.

- Contacts: points sampled on each part's surface (seeded, so a derivation is repeatable)
  within ``clearance_max + contact_tol`` of another part whose nearest point there has an
  antiparallel normal (the two surfaces face each other).
- Mates: a pair's contact triangles whose normals are all normal to one axis (the least
  eigenvector of sum n n^T) and whose vertices lie on circles about it: a peg on the part
  whose normals point away from the axis, a hole on the other; radii fitted on each part's
  own vertices (exact for a tessellated cylinder), depth the overlap along the axis, blind
  when a ray along the axis inside the hole meets the hole part again.
- Seats: planar contacts (antiparallel normals, coplanar points, gap within ``contact_tol``)
  that the later part's insertion runs into; one it slides along (a guide) is not a seat.
  A cradle (a cylindrical fit whose normals do not wrap the axis: a half cylinder) is a
  curved seat when the part inserted later moves along the mean of its own outward normals
  there (within COS_FACING: a shaft down into its cradle, or a cradle onto a shaft placed
  first) and rests on no plane already; the seat carries that insertion's direction. What is
  neither stays a contact: it constrains the directions only.
- Directions: candidates are the product frame's six axes, the mates' axes (both senses) and
  the ways out of the cradles; a part (or a set of parts) may leave along d when d . n <= eps
  for every outward normal n of its contacts with the rest that touch (gap within
  ``contact_tol``) or are a fit's own walls (a mate's or a cradle's: a surface merely within
  reach, as a socket's lead-in chamfer near a tenon's tip, does not hold the part; the sweep
  finds what it meets) (local), and its meshes, shrunk by SHRINK of the tolerance, swept
  along d in steps no longer than the smallest radial clearance until clear of the others'
  bounding box, collide with none of them (python-fcl, global).
- Precedence: remove parts (or sets of two or three that must leave together) one at a time,
  preferring a removal that leaves a stable remainder (its centre of mass over the hull of its
  lowest points, the product frame's -z down) and a removal upwards; the reverse is the
  insertion order. ``first`` before ``then`` when ``then`` in place blocks ``first``'s sweep.
  An insertion that points up in every stable pose of the partial product needs a fixture or
  a second arm (:attr:`Insertion.needs_fixture`).
- :func:`derive_assembly_cached` keeps the result on disk by content (world.parts.cache's
  directory and pattern).
"""
from __future__ import annotations

import itertools
import json
import math
import time
from dataclasses import asdict, dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from spar_py.world.product.overlap import Overlap, Wall, overlaps

if TYPE_CHECKING:
    import trimesh

__all__ = ["ASSEMBLY_VERSION", "AssemblyResult", "Contact", "DerivedMate", "DerivedSeat", "Insertion",
           "derive_assembly", "derive_assembly_cached"]

#: Bumped whenever the derivation's results change for the same inputs.
ASSEMBLY_VERSION = 6
#: Surface samples per part (at most; fewer for a small area at the sample spacing).
SAMPLES = 6000
#: Normals of facing surfaces: n_a . n_b below -COS_FACING.
COS_FACING = math.cos(math.radians(20.0))
#: A contact's triangles are normal to an axis when |n . d| is below this (sin 3 deg).
SIN_AXIS = math.sin(math.radians(3.0))
#: A vertex lies on a fitted circle within this fraction of the radius.
CIRCLE_REL = 0.01
#: Wall normals wrap an axis when no angular gap across it reaches this (a half cylinder's or
#: a two-sided guide's gap is 180 deg; 10 deg of slack for the normals of a tessellation).
WRAP_GAP = math.radians(170.0)
#: A prismatic fit's clearance: this percentile of the peg's wall samples' gaps (a low one:
#: the tightest wall sets the fit, a few samples' mesh noise does not).
CLEARANCE_PCT = 5.0
#: Local freedom: d . n <= EPS_LOCAL for every outward contact normal n of the moving part.
EPS_LOCAL = 0.02
#: The moving meshes are shrunk by this fraction of contact_tol (touching is not blocking).
SHRINK = 0.5
#: Subassemblies tried when no single part can leave: up to this many parts.
MAX_GROUP = 3
#: An insertion direction "points up" when its z component exceeds this (30 deg above horizontal).
UP_Z = 0.5


@dataclass(frozen=True)
class Contact:
    """Parts ``a`` and ``b`` face each other: ``points`` samples on a, ``normals`` a's outward
    normals there, ``gaps`` the distances to b (product frame)."""

    a: str
    b: str
    points: np.ndarray
    normals: np.ndarray
    gaps: np.ndarray


@dataclass(frozen=True)
class DerivedMate:
    """A peg of part ``peg`` in a hole of part ``hole``: the common ``axis`` (unit, the way the
    peg moves into the hole), a point ``origin`` on it, the radii, the peg's root and length
    along the axis (``peg_t0``, ``peg_len``: t measured from origin), the hole's mouth and
    depth (``hole_t0``, ``hole_len``), ``depth`` the overlap and ``through``."""

    peg: str
    hole: str
    origin: tuple[float, float, float]
    axis: tuple[float, float, float]
    peg_radius: float
    hole_radius: float
    peg_t0: float
    peg_len: float
    hole_t0: float
    hole_len: float
    depth: float
    through: bool
    #: 'round', or 'prism': the walls are planes normal to the axis, the radii the peg profile's
    #: inscribed half-width and that plus the clearance.
    profile: str = "round"
    #: A prism peg's profile across the axis (its bounding rectangle's corners) as offsets from
    #: the axis, product frame (empty for a round peg).
    corners: tuple[tuple[float, float, float], ...] = ()
    #: A prism hole's profile (its walls' bounding rectangle), the same way.
    hole_corners: tuple[tuple[float, float, float], ...] = ()
    #: The hole's axis less the peg's, across them (product frame): zero when the fitted axes are
    #: one (within axis_tol, ``origin`` then midway between them); else ``origin`` is on the peg's
    #: axis and the peg stands this far off the hole's centre, less than the clearance.
    hole_shift: tuple[float, float, float] = (0.0, 0.0, 0.0)


@dataclass(frozen=True)
class DerivedSeat:
    """Part ``part`` rests on part ``on`` across a plane: ``point`` on it, ``normal`` the
    outward normal of ``on`` there (unit, product frame), the contact ``area`` estimate.
    A curved seat (a cradle) has a ``direction``: the way ``part`` moves into it (unit,
    product frame); ``point`` lies midway across the fit's ``gap`` there, ``normal`` is the
    mean outward normal of ``on`` over the cradle."""

    part: str
    on: str
    point: tuple[float, float, float]
    normal: tuple[float, float, float]
    area: float
    direction: tuple[float, float, float] | None = None
    gap: float = 0.0


@dataclass(frozen=True)
class Insertion:
    """One step of the derived assembly: ``parts`` (one, or a subassembly that goes in
    together) move along ``direction`` (unit, product frame) into place; ``needs_fixture``
    when that direction points up in every stable pose of the partial product."""

    parts: tuple[str, ...]
    direction: tuple[float, float, float]
    needs_fixture: bool = False


@dataclass
class AssemblyResult:
    """What :func:`derive_assembly` found: the mates, seats, the contacts that are neither
    (as ``(a, b, count)``), the insertions in order (the base part's first, alone), the
    precedence ``(first, then, reason)``, the free directions of each part at the start of
    its removal, and the seconds it took."""

    base: str
    mates: list[DerivedMate] = field(default_factory=list)
    seats: list[DerivedSeat] = field(default_factory=list)
    blocking: list[tuple[str, str, int]] = field(default_factory=list)
    insertions: list[Insertion] = field(default_factory=list)
    precedence: list[tuple[str, str, str]] = field(default_factory=list)
    seconds: float = 0.0
    unremovable: tuple[str, ...] = ()
    #: Parts that overlap as placed (world.product.overlap): when any do, nothing else is derived.
    overlaps: list[Overlap] = field(default_factory=list)

    def to_json(self) -> dict[str, Any]:
        """As plain data (the cache's form)."""
        return {"base": self.base, "mates": [asdict(m) for m in self.mates], "seats": [asdict(s) for s in self.seats],
                "blocking": [list(b) for b in self.blocking], "insertions": [asdict(i) for i in self.insertions],
                "precedence": [list(p) for p in self.precedence], "seconds": self.seconds,
                "unremovable": list(self.unremovable), "overlaps": [asdict(o) for o in self.overlaps]}

    @classmethod
    def from_json(cls, d: dict[str, Any]) -> "AssemblyResult":
        """Back from :meth:`to_json`."""
        def tup(x: Any) -> Any:
            return tuple(x) if isinstance(x, list) else x

        def mate(m: dict[str, Any]) -> DerivedMate:
            m = {k: tup(v) for k, v in m.items()}
            for k in ("corners", "hole_corners"):
                m[k] = tuple(tuple(c) for c in m.get(k, ()))
            return DerivedMate(**m)
        def wall(w: dict[str, Any]) -> Wall:
            return Wall(w["kind"], tuple(w["point"]), tup(w["axis"]), w["radius"])
        return cls(d["base"], [mate(m) for m in d["mates"]],
                   [DerivedSeat(**{k: tup(v) for k, v in s.items()}) for s in d["seats"]],
                   [tuple(b) for b in d["blocking"]],  # type: ignore[misc]
                   [Insertion(tuple(i["parts"]), tuple(i["direction"]), i["needs_fixture"]) for i in d["insertions"]],
                   [tuple(p) for p in d["precedence"]], d["seconds"], tuple(d.get("unremovable", ())),  # type: ignore[misc]
                   [Overlap(o["a"], o["b"], o["volume"], wall(o["wall_a"]), wall(o["wall_b"])) for o in d["overlaps"]])


# --------------------------------------------------------------------------- contacts


def _samples(name: str, mesh: "trimesh.Trimesh", spacing: float) -> tuple[np.ndarray, np.ndarray]:
    """Points on the surface (seeded by the part's name) and their triangles."""
    import hashlib  # here: the product door loads this module for plans that derive nothing

    import trimesh

    n = int(min(SAMPLES, max(500, mesh.area / spacing ** 2)))
    seed = int(hashlib.sha256(name.encode()).hexdigest()[:8], 16)
    pts, tri = trimesh.sample.sample_surface(mesh, n, seed=seed)
    return np.asarray(pts, float), np.asarray(tri, int)


def _contacts(meshes: dict[str, "trimesh.Trimesh"], reach: float, spacing: float
              ) -> dict[tuple[str, str], tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """For each ordered pair (a, b) whose boxes come within ``reach``: a's samples within
    ``reach`` of b facing it, as (points, triangles of a, gaps)."""
    import trimesh

    names = list(meshes)
    samples = {p: _samples(p, m, spacing) for p, m in meshes.items()}
    out = {}
    for a, b in itertools.permutations(names, 2):
        ma, mb = meshes[a], meshes[b]
        if np.any(ma.bounds[0] > mb.bounds[1] + reach) or np.any(mb.bounds[0] > ma.bounds[1] + reach):
            continue
        pts, tri = samples[a]
        lo, hi = mb.bounds[0] - reach, mb.bounds[1] + reach
        near = np.all((pts >= lo) & (pts <= hi), axis=1)
        if not near.any():
            continue
        near[near] = _within(mb, pts[near], reach)
        if not near.any():
            continue
        P, T = pts[near], tri[near]
        _, dist, tb = trimesh.proximity.closest_point(mb, P)
        facing = (ma.face_normals[T] * mb.face_normals[tb]).sum(1) < -COS_FACING
        keep = (dist <= reach) & facing
        if keep.any():
            out[a, b] = (P[keep], T[keep], np.asarray(dist)[keep])
    return out


def triangles_tree(mesh: "trimesh.Trimesh") -> Any:
    """The mesh's ``triangles_tree`` (an R-tree of its triangles' bounding boxes), bulk-loaded
    from numpy arrays and kept in the mesh's own cache, where trimesh's proximity queries find
    it. trimesh loads the same tree through a Python callback per triangle (most of the
    contacts' time on a fine mesh); both are rtree's bulk load of the same boxes in the same
    order, so queries answer the same ids in the same order (bench/fabrica_dump's results are
    unchanged)."""
    import rtree

    cache = mesh._cache  # noqa: SLF001 - trimesh's property cache, checked against the mesh's data
    cache.verify()
    if "triangles_tree" not in cache.cache:
        tri = np.asarray(mesh.triangles, float)
        cache.cache["triangles_tree"] = rtree.index.Index(
            (np.arange(len(tri), dtype=np.int64), tri.min(axis=1), tri.max(axis=1)),
            properties=rtree.index.Property(dimension=3))
    return mesh.triangles_tree


def _within(mesh: "trimesh.Trimesh", P: np.ndarray, reach: float) -> np.ndarray:
    """A mask of the points ``P`` that may lie within ``reach`` of the mesh's surface: those
    whose cube of half-side ``reach`` meets a triangle's bounding box (a superset of the points
    within reach; the points outside it are farther). trimesh's closest_point searches a box
    out to each point's nearest vertex, which on a coarse mesh holds most of its triangles:
    the points far from the mesh, most of a bounding-box overlap's, are dropped here first."""
    if len(P) == 0:
        return np.zeros(0, bool)
    tree = triangles_tree(mesh)
    r = reach * (1 + 1e-9) + 1e-12
    boxes = np.column_stack((P - r, P + r))
    _, counts = tree.intersection_v(boxes[:, :3].copy(), boxes[:, 3:].copy())
    return np.asarray(counts) > 0


# --------------------------------------------------------------------------- mates and seats


def _axis_of(normals: np.ndarray, weights: np.ndarray) -> np.ndarray | None:
    """The axis all ``normals`` are normal to (least eigenvector of sum w n n^T), or None."""
    vals, vecs = np.linalg.eigh((normals * weights[:, None]).T @ normals)
    d = vecs[:, 0]
    if np.abs(normals @ d).max() > SIN_AXIS or vals[1] < 1e-3 * vals[2]:
        return None
    return d / np.linalg.norm(d)


def _circle(V: np.ndarray, d: np.ndarray) -> tuple[np.ndarray, float] | None:
    """The least-squares circle of points ``V`` about an axis along ``d``: a point on the axis
    and the radius, or None if the points are not on one circle (CIRCLE_REL)."""
    from spar_py.world.parts import fit_circle

    return fit_circle(V, d, CIRCLE_REL)


def _wall_extent(mesh: "trimesh.Trimesh", o: np.ndarray, d: np.ndarray, r: float, t0: float, t1: float,
                 tol: float) -> tuple[float, float]:
    """The extent along the axis (o, d) of the mesh's triangles on the cylinder of radius r
    (normals normal to d, vertices at r) that joins the interval [t0, t1] (t from o)."""
    N = mesh.face_normals
    on = np.abs(N @ d) < SIN_AXIS
    V = mesh.vertices[mesh.faces[on]]  # (k, 3, 3)
    rel = V - o
    t = rel @ d
    radial = np.linalg.norm(rel - t[..., None] * d, axis=2)
    ok = np.all(np.abs(radial - r) < max(CIRCLE_REL * r, tol), axis=1)
    spans = sorted((float(a.min()), float(a.max())) for a in t[ok])
    lo, hi = t0, t1
    changed = True
    while changed:
        changed = False
        for a, b in spans:
            if a <= hi + tol and b >= lo - tol and (a < lo - 1e-12 or b > hi + 1e-12):
                lo, hi, changed = min(lo, a), max(hi, b), True
    return lo, hi


def _wraps(normals: np.ndarray, d: np.ndarray) -> bool:
    """Whether ``normals`` (unit, normal to the axis ``d``) wrap the axis: no angular gap of
    WRAP_GAP or more among their directions across it, so the walls they belong to stop
    motion across the axis in every direction."""
    from spar_py.world.parts import axis_basis

    if len(normals) < 3:
        return False
    e1, e2 = axis_basis(np.asarray(d, float))
    ang = np.sort(np.arctan2(normals @ e2, normals @ e1))
    gaps = np.diff(np.concatenate([ang, [ang[0] + 2 * math.pi]]))
    return bool(gaps.max() < WRAP_GAP)


def _prism(meshes: dict[str, "trimesh.Trimesh"], a: str, b: str, ta: np.ndarray, tb: np.ndarray,
           sample_normals: np.ndarray, sample_gaps: np.ndarray, contact_tol: float) -> DerivedMate | None:
    """A prismatic mate from a's contact triangles ``ta`` and b's ``tb``: for an axis d (each
    distinct normal of the contact, the end faces' among them), the triangles normal to d are
    the walls; they make a peg in a hole when a's and b's walls wrap d (:func:`_wraps`) and a's
    normals point away from the walls' centre (a the peg). Across the axis, in a basis whose
    first vector is a wall normal: the axis passes through the centre of the bounding rectangle
    of a's wall vertices, whose corners are the profile; the peg's radius is the inscribed
    half-width (the least distance of a wall plane from the axis), the clearance the
    CLEARANCE_PCT percentile of the gaps of a's wall samples (``sample_normals``,
    ``sample_gaps``: a's contact samples in this component); None if no axis fits or the
    clearance is below ``contact_tol`` (a touching fit stays a contact)."""
    ma, mb = meshes[a], meshes[b]
    Na, Nb = ma.face_normals[ta], mb.face_normals[tb]
    best = None
    seen: list[np.ndarray] = []
    for d in _by_count(Na):
        if any(abs(float(d @ u)) > 1 - 1e-6 for u in seen):
            continue
        seen.append(d)
        ka = np.abs(Na @ d) < SIN_AXIS
        kb = np.abs(Nb @ d) < SIN_AXIS
        if ka.sum() < 3 or kb.sum() < 3 or not _wraps(Na[ka], d):
            continue
        facing = (Nb[kb] @ Na[ka].T).min(axis=1) < -COS_FACING  # b's walls facing one of a's
        kb[np.flatnonzero(kb)[~facing]] = False
        if kb.sum() < 3 or not _wraps(Nb[kb], d):
            continue
        area = float(ma.area_faces[ta[ka]].sum())
        if best is None or area > best[0]:
            best = (area, d, ta[ka], tb[kb])
        if len(seen) > 50:
            break
    if best is None:
        return None
    _, d, wa, wb = best
    d = d / np.linalg.norm(d)
    u = ma.face_normals[wa[0]] - (ma.face_normals[wa[0]] @ d) * d
    u /= np.linalg.norm(u)
    v = np.cross(d, u)
    Va = ma.vertices[np.unique(ma.faces[wa])]
    cu, cv = Va @ u, Va @ v
    mid_u, mid_v = (cu.min() + cu.max()) / 2, (cv.min() + cv.max()) / 2
    o = mid_u * u + mid_v * v + float(np.mean(Va @ d)) * d
    C = ma.triangles_center[wa] - o
    h = np.einsum("ij,ij->i", C, ma.face_normals[wa])
    if (h <= 0).any():
        return None  # a's walls face the centre: a is the hole
    walls = np.abs(sample_normals @ d) < SIN_AXIS
    if walls.sum() < 3:
        return None
    clearance = float(np.percentile(sample_gaps[walls], CLEARANCE_PCT))
    if clearance < contact_tol:
        return None
    ra = float(h.min())
    hu, hv = (cu.max() - cu.min()) / 2, (cv.max() - cv.min()) / 2
    Vb = mb.vertices[np.unique(mb.faces[wb])] - o
    gu, gv = np.abs(Vb @ u).max(), np.abs(Vb @ v).max()
    signs = ((1, 1), (-1, 1), (-1, -1), (1, -1))
    corners = tuple(tuple(float(x) for x in su * hu * u + sv * hv * v) for su, sv in signs)
    hole_corners = tuple(tuple(float(x) for x in su * gu * u + sv * gv * v) for su, sv in signs)
    tva = (Va - o) @ d
    tvb = Vb @ d
    lo, hi = max(tva.min(), tvb.min()), min(tva.max(), tvb.max())
    if hi <= lo:
        return None
    return DerivedMate(a, b, tuple(float(x) for x in o), tuple(float(x) for x in d), ra, ra + clearance,
                       float(tva.min()), float(tva.max() - tva.min()), float(tvb.min()), float(tvb.max() - tvb.min()),
                       float(hi - lo), False, "prism", corners, hole_corners)


def _components(P: np.ndarray, link: float) -> list[np.ndarray]:
    """Index sets of the points connected by steps shorter than ``link``."""
    from scipy.sparse.csgraph import connected_components
    from scipy.spatial import cKDTree

    pairs = cKDTree(P).query_pairs(link, output_type="ndarray")
    import scipy.sparse as sp

    g = sp.coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(len(P), len(P)))
    n, lab = connected_components(g, directed=False)
    return [np.flatnonzero(lab == i) for i in range(n)]


def _cylinder(meshes: dict[str, "trimesh.Trimesh"], a: str, b: str, ta: np.ndarray, tb: np.ndarray, tol: float,
              cradle: bool = False, axis_tol: float = 0.0) -> DerivedMate | None:
    """A mate from a's contact triangles ``ta`` and b's ``tb`` facing them, if both are
    cylindrical about parallel axes with a's normals pointing away from its own (a the peg) and
    a's normals wrap it; with ``cradle``, the same fit when they do not (a lying in b's half
    cylinder: b a cradle, not a hole). The axes are one within ``axis_tol``; farther apart, the
    peg stands off the hole's centre (:attr:`DerivedMate.hole_shift`), by less than the clearance
    (else it would be in the wall: no fit)."""
    ma, mb = meshes[a], meshes[b]
    Na, Nb = ma.face_normals[ta], mb.face_normals[tb]
    d = _axis_of(np.vstack([Na, Nb]), np.concatenate([ma.area_faces[ta], mb.area_faces[tb]]))
    if d is None:
        return None
    ca = _circle(ma.vertices[np.unique(ma.faces[ta])], d)
    cb = _circle(mb.vertices[np.unique(mb.faces[tb])], d)
    if ca is None or cb is None:
        return None
    (oa, ra), (ob, rb) = ca, cb
    shift = float(np.linalg.norm(oa - ob))  # both on the plane through the origin normal to d
    if rb <= ra or (shift > axis_tol and shift >= rb - ra):
        return None
    Ca = ma.triangles_center[ta]
    radial = Ca - oa - np.outer((Ca - oa) @ d, d)
    if (np.einsum("ij,ij->i", radial, Na) <= 0).any():
        return None  # a's normals towards the axis: a is not the peg
    if _wraps(Na, d) == cradle:
        return None  # a cradle (half a cylinder) stops motion across the axis one way only: no mate
    o = (oa + ob) / 2 if shift <= axis_tol else oa
    ho = o if shift <= axis_tol else ob  # the hole's own axis (the same t along it: both on one plane)
    tva = (ma.vertices[np.unique(ma.faces[ta])] - o) @ d
    tvb = (mb.vertices[np.unique(mb.faces[tb])] - o) @ d
    lo, hi = max(tva.min(), tvb.min()), min(tva.max(), tvb.max())
    p0, p1 = _wall_extent(ma, o, d, ra, lo, hi, tol)
    h0, h1 = _wall_extent(mb, ho, d, rb, lo, hi, tol)
    return DerivedMate(a, b, tuple(o), tuple(d), ra, rb, p0, p1 - p0, h0, h1 - h0, hi - lo, False,
                       hole_shift=tuple(float(x) for x in ho - o))


def _orient(m: DerivedMate, meshes: dict[str, "trimesh.Trimesh"], sense: np.ndarray, tol: float) -> DerivedMate:
    """The mate with its axis along ``sense`` (the way the peg moves into the hole): the peg's
    root and the hole's mouth at their ends against it; through unless a ray along the axis
    from inside the hole meets the hole part's surface beyond."""
    d = np.asarray(m.axis, float)
    o = np.asarray(m.origin, float)
    p0, p1, h0, h1 = m.peg_t0, m.peg_t0 + m.peg_len, m.hole_t0, m.hole_t0 + m.hole_len
    if float(sense @ d) < 0:
        d, p0, p1, h0, h1 = -d, -p1, -p0, -h1, -h0
    mb = meshes[m.hole]
    start = o + np.asarray(m.hole_shift, float) + d * (h1 - 2 * tol)
    hits = mb.ray.intersects_location([start], [d])[0]
    far = float(np.linalg.norm(mb.extents))
    blind = len(hits) > 0 and float(np.min((hits - start) @ d)) < min(3 * tol, far)
    return DerivedMate(m.peg, m.hole, tuple(float(x) for x in o), tuple(float(x) for x in d), m.peg_radius,
                       m.hole_radius, float(p0), float(p1 - p0), float(h0), float(h1 - h0), m.depth, not blind,
                       m.profile, m.corners, m.hole_corners, m.hole_shift)


def _seats(P: np.ndarray, N: np.ndarray, gaps: np.ndarray, contact_tol: float, spacing: float
           ) -> list[tuple[np.ndarray, np.ndarray, float]]:
    """Planar clusters of one part's contact points with another (one normal, one plane, gaps
    within ``contact_tol``): (a point on it, the part's outward normal, an area estimate)."""
    out = []
    left = np.ones(len(P), bool)
    while left.any():
        n0 = N[np.flatnonzero(left)[0]]
        group = left & (N @ n0 > math.cos(math.radians(2.0)))
        left &= ~group
        rest = group.copy()
        while rest.sum() >= 3:
            h0 = float(P[np.flatnonzero(rest)[0]] @ n0)
            sel = rest & (np.abs(P @ n0 - h0) <= contact_tol)
            rest &= ~sel
            if sel.sum() >= 3 and np.all(gaps[sel] <= contact_tol):
                c = P[sel].mean(0)  # a ring's mean is in its hole: take the sample nearest it
                out.append((P[sel][np.argmin(np.linalg.norm(P[sel] - c, axis=1))], n0, float(sel.sum()) * spacing ** 2))
    return out


# --------------------------------------------------------------------------- directions


def _fcl_mesh(mesh: "trimesh.Trimesh", shrink: float) -> Any:
    """The mesh as a python-fcl BVH (vertices pulled ``shrink`` inward along their normals)."""
    from spar_py.world.collision import bvh

    V = np.asarray(mesh.vertices, float)
    if shrink:
        V = V - shrink * np.asarray(mesh.vertex_normals, float)
    return bvh(V, np.asarray(mesh.faces))


class Sweeper:
    """Sweeps of parts along directions against the other parts (python-fcl)."""

    def __init__(self, meshes: dict[str, "trimesh.Trimesh"], shrink: float, step: float) -> None:
        self.meshes = meshes
        self.step = step
        self.shrink = shrink
        self._moving: dict[str, Any] = {}
        self._fixed: dict[str, Any] = {}
        self.bounds = {p: np.asarray(m.bounds, float) for p, m in meshes.items()}

    def moving(self, p: str) -> Any:
        """Part ``p``'s BVH as it moves (shrunk), built on first use: a part that is never swept
        or never met on a sweep costs no BVH build."""
        if p not in self._moving:
            self._moving[p] = _fcl_mesh(self.meshes[p], self.shrink)
        return self._moving[p]

    def fixed(self, p: str) -> Any:
        """Part ``p`` standing at its pose (an fcl CollisionObject), built on first use."""
        import fcl

        if p not in self._fixed:
            self._fixed[p] = fcl.CollisionObject(_fcl_mesh(self.meshes[p], 0.0), fcl.Transform())
        return self._fixed[p]

    def hits(self, parts: tuple[str, ...], d: np.ndarray, others: list[str], first_only: bool) -> set[str]:
        """The parts of ``others`` that ``parts`` swept along ``d`` (from their poses until
        clear of the others' bounding box) collide with: at each of the n steps, each moving
        part against each other part whose box meets the moving parts' box there. With
        ``first_only`` the first one found (the answer's truth is all that is asked)."""
        import fcl

        if not others:
            return set()
        lo = np.min([self.bounds[q][0] for q in others], axis=0)
        hi = np.max([self.bounds[q][1] for q in others], axis=0)
        mlo = np.min([self.bounds[p][0] for p in parts], axis=0)
        mhi = np.max([self.bounds[p][1] for p in parts], axis=0)
        travel = float(np.abs(d) @ (np.maximum(hi, mhi) - np.minimum(lo, mlo))) + self.step
        n = max(1, int(math.ceil(travel / self.step)))
        offs = d[None, :] * (travel * np.arange(1, n + 1, dtype=float) / n)[:, None]  # (n, 3), step k at row k-1
        slo, shi = mlo + offs, mhi + offs
        found: set[str] = set()
        req = fcl.CollisionRequest()
        for q in others:
            b = self.bounds[q]
            steps = np.flatnonzero(~(np.any(slo > b[1], axis=1) | np.any(b[0] > shi, axis=1)))
            if not len(steps):
                continue
            if self._collides(parts, offs[steps], q, req):
                found.add(q)
                if first_only:
                    return found
        return found

    def _collides(self, parts: tuple[str, ...], offs: np.ndarray, q: str, req: Any) -> bool:
        """Whether a part of ``parts`` moved by one of ``offs`` collides with part ``q``."""
        import fcl

        for off in offs:
            for p in parts:
                if fcl.collide(fcl.CollisionObject(self.moving(p), fcl.Transform(off)), self.fixed(q), req,
                               fcl.CollisionResult()):
                    return True
        return False


def _stable(meshes: dict[str, "trimesh.Trimesh"], parts: list[str], tol: float) -> bool:
    """Whether ``parts`` rest on the table in the product's orientation: their centre of mass
    (volume-weighted) inside the convex hull of their lowest vertices (within tol), in x, y."""
    from scipy.spatial import ConvexHull, QhullError

    V = np.vstack([meshes[p].vertices for p in parts])
    vols = np.array([abs(meshes[p].volume) for p in parts])
    com = np.sum([meshes[p].center_mass * v for p, v in zip(parts, vols)], axis=0) / max(vols.sum(), 1e-300)
    low = V[V[:, 2] <= V[:, 2].min() + tol][:, :2]
    try:
        h = ConvexHull(low)
    except (QhullError, ValueError):
        return False
    return bool(np.all(h.equations[:, :2] @ com[:2] + h.equations[:, 2] <= 1e-9))


def _up_in_every_pose(meshes: dict[str, "trimesh.Trimesh"], parts: list[str], d: np.ndarray) -> bool:
    """Whether insertion direction ``d`` points up (z > UP_Z) in every stable pose of ``parts``
    as one body (trimesh's stable poses of their union's hull: a pose rests on a hull face of
    outward normal n and turns d's z component into -n . d)."""
    import trimesh

    from spar_py.world.parts import stable_poses

    body = trimesh.util.concatenate([meshes[p] for p in parts])
    try:
        T, _ = stable_poses(body.convex_hull, body.center_mass)
        normals = -np.asarray(T, float)[:, 2, :3].reshape(-1, 3)
    except Exception:  # qhull on a degenerate body: judge the product's orientation alone
        return bool(d[2] > UP_Z)
    if len(normals) == 0:
        return bool(d[2] > UP_Z)
    return all(float(-n @ d) > UP_Z for n in normals)


# --------------------------------------------------------------------------- the derivation


def derive_assembly(meshes: dict[str, "trimesh.Trimesh"], base: str, contact_tol: float = 0.1,
                    clearance_max: float = 0.5, axis_tol: float = 0.01) -> AssemblyResult:
    """Derive mates, seats, insertions and precedence of the parts ``meshes`` (product frame,
    one length unit, ``contact_tol``, ``clearance_max`` and ``axis_tol`` in it: a round fit's
    two axes closer than ``axis_tol`` are one); ``base`` is never removed. See the module
    docstring."""
    t_start = time.perf_counter()
    size = float(np.linalg.norm(np.max([m.bounds[1] for m in meshes.values()], axis=0)
                                - np.min([m.bounds[0] for m in meshes.values()], axis=0)))
    spacing = size / 150.0
    reach = clearance_max + contact_tol
    tol = max(contact_tol, 1e-6 * size)
    res = AssemblyResult(base)
    res.overlaps = overlaps(meshes, contact_tol)
    if res.overlaps:  # parts that cannot be where they are placed: no contacts, fits or ways out to find
        res.seconds = time.perf_counter() - t_start
        return res
    con = _contacts(meshes, reach, spacing)
    # a's contact samples with b that hold it: touching, or on a fit's walls (marked below)
    holds = {ab: gaps <= contact_tol for ab, (_, _, gaps) in con.items()}
    outward = {ab: meshes[ab[0]].face_normals[T] for ab, (_, T, _) in con.items()}  # a's normals there
    mates: list[DerivedMate] = []
    cradles: list[tuple[DerivedMate, np.ndarray, np.ndarray]] = []  # the fit, each side's wall samples
    planes: list[tuple[str, str, np.ndarray, np.ndarray, float]] = []
    for (a, b), (P, T, gaps) in con.items():
        N = meshes[a].face_normals[T]
        if a < b:
            for s_pt, s_n, area in _seats(P, N, gaps, contact_tol, spacing):
                planes.append((a, b, s_pt, s_n, area))  # a's outward normal s_n
        if len(P) < 6 or (b, a) not in con:
            continue
        Pb, Tb, _ = con[b, a]
        for comp in _components(P, 3 * spacing):
            ta = np.unique(T[comp])
            cpts = P[comp]
            lo, hi = cpts.min(0) - reach - spacing, cpts.max(0) + reach + spacing
            tb = np.unique(Tb[np.all((Pb >= lo) & (Pb <= hi), axis=1)])
            if len(ta) < 3 or len(tb) < 3:
                continue
            m = _cylinder_filtered(meshes, a, b, ta, tb, tol, axis_tol=axis_tol)
            if m is None:
                m = _prism(meshes, a, b, ta, tb, N[comp], gaps[comp], contact_tol)
            cradle = None
            if m is None:
                cradle = m = _cylinder_filtered(meshes, a, b, ta, tb, tol, cradle=True, axis_tol=axis_tol)
            if m is None:
                continue
            d = np.asarray(m.axis, float)
            wall_a = comp[np.abs(N[comp] @ d) < SIN_AXIS]
            wall_b = np.flatnonzero(np.all((Pb >= lo) & (Pb <= hi), axis=1)
                                    & (np.abs(meshes[b].face_normals[Tb] @ d) < SIN_AXIS))
            if cradle is not None:  # each side's walls where the other's are (not past a cradle's rim)
                wall_a, wall_b = (wall_a[_within_span(P[wall_a], Pb[wall_b], m)],
                                  wall_b[_within_span(Pb[wall_b], P[wall_a], m)])
            holds[a, b][wall_a] = True
            holds[b, a][wall_b] = True
            if m.profile == "round":  # a round wall's normal is radial (a facet's leans up to half its angle)
                outward[a, b][wall_a] = _radial(P[wall_a], m)
                outward[b, a][wall_b] = -_radial(Pb[wall_b], m)
            if cradle is not None:
                cradles.append((cradle, wall_a, wall_b))
            elif not any(_same_mate(m, x, tol) for x in mates):
                mates.append(m)
    normals = {ab: outward[ab][holds[ab]] for ab in con}
    mated = {(m.peg, m.hole) for m in mates} | {(m.hole, m.peg) for m in mates}
    seated = {(a, b) for a, b, *_ in planes if (a, b) not in mated}
    for (a, b), (P, _, _) in con.items():
        if a < b and (a, b) not in seated and (a, b) not in mated:
            res.blocking.append((a, b, int(len(P) + len(con.get((b, a), ((),))[0]))))

    # insertion directions and the disassembly
    gaps = [m.hole_radius - m.peg_radius - float(np.linalg.norm(m.hole_shift)) for m in mates]  # nearest walls
    step = max(min([clearance_max, *gaps]), size / 400.0)
    sweeper = Sweeper(meshes, SHRINK * contact_tol, step)
    cands = [np.eye(3)[i] * s for i in (2, 0, 1) for s in (1, -1)]
    for m in mates:
        for s in (1, -1):
            cands.append(s * np.asarray(m.axis, float))
    for c, walls, _ in cradles:  # out of a cradle and off its inner part: its mean normal's two senses
        P, T, _ = con[c.peg, c.hole]
        mean = meshes[c.peg].face_normals[T[walls]].sum(0)
        if np.linalg.norm(mean) > 1e-9:
            cands += [s * mean / np.linalg.norm(mean) for s in (-1, 1)]
    uniq: list[np.ndarray] = []
    for c in cands:
        if not any(float(c @ u) > 1 - 1e-9 for u in uniq):
            uniq.append(c)
    present = list(meshes)
    removed: list[tuple[tuple[str, ...], np.ndarray]] = []
    blocked_by: dict[str, set[str]] = {}
    while len(present) > 1:
        choice = None
        for k in range(1, MAX_GROUP + 1):
            options = []
            for group in itertools.combinations([p for p in present if p != base], k):
                if k > 1 and not _connected(group, con):
                    continue
                rest = [q for q in present if q not in group]
                local = [normals[a, b] for a in group for b in rest if (a, b) in normals]
                Nl = np.vstack(local) if local else np.zeros((0, 3))
                for d in uniq:
                    if Nl.size and float((Nl @ d).max()) > EPS_LOCAL:
                        continue
                    if sweeper.hits(group, d, rest, first_only=True):
                        continue
                    stable = _stable(meshes, rest, tol)
                    options.append(((not stable, -float(d[2]), present.index(group[0]) * -1), group, d))
                    break
            if options:
                choice = min(options, key=lambda o: o[0])
                break
        if choice is None:
            res.unremovable = tuple(p for p in present if p != base)
            break
        _, group, d = choice
        for p in group:
            others = [q for q in meshes if q not in group]
            blocked_by[p] = sweeper.hits((p,), d, others, first_only=False)
        removed.append((group, d))
        present = [q for q in present if q not in group]
    # the insertions: reverse of the removals
    order = [base] + [p for g, _ in reversed(removed) for p in g]
    res.insertions.append(Insertion((base,), (0.0, 0.0, -1.0), False))
    placed = [base]
    for group, d in reversed(removed):
        ins = -d
        fixture = bool(ins[2] > UP_Z) and _up_in_every_pose(meshes, placed, ins)
        res.insertions.append(Insertion(group, tuple(float(x) for x in ins), fixture))
        placed += list(group)
    pos = {p: i for i, p in enumerate(order)}
    for p, qs in blocked_by.items():
        for q in sorted(qs, key=lambda x: pos.get(x, 0)):
            if pos.get(q, -1) > pos[p]:
                res.precedence.append((p, q, f"{q} in place blocks {p}'s insertion"))
    # the mates' senses: the way the peg moves into the hole, from the later part's insertion
    direction = {p: np.asarray(i.direction, float) for i in res.insertions for p in i.parts}
    for m in mates:
        # a part left unremovable has no insertion (nor a place in the order): its mates keep
        # their fitted axis, as the base's do
        sense = np.asarray(m.axis, float)
        if m.peg in pos and m.hole in pos:
            later = m.peg if pos[m.peg] > pos[m.hole] else m.hole
            if later != base:
                sense = direction[later] if later == m.peg else -direction[later]
        res.mates.append(_orient(m, meshes, sense, tol))
    # seats between parts without a mate: the later inserted part rests on the earlier one
    res.seats.extend(_seats_of(planes, mated, pos, res.insertions))
    res.seats.extend(_cradle_seats(cradles, con, meshes, mated, pos, res.insertions, list(res.seats)))
    sat = {frozenset((s.part, s.on)) for s in res.seats}
    res.blocking = [x for x in res.blocking if frozenset(x[:2]) not in sat]
    for a, b in sorted(seated):
        if frozenset((a, b)) not in sat:  # sliding guides only: a contact that blocks
            res.blocking.append((a, b, int(len(con[a, b][0]) + len(con.get((b, a), ((),))[0]))))
    res.seconds = time.perf_counter() - t_start
    return res


def _seats_of(planes: list[tuple[str, str, np.ndarray, np.ndarray, float]], mated: set[tuple[str, str]],
              pos: dict[str, int], insertions: list[Insertion]) -> list[DerivedSeat]:
    """The seats among planar contacts ``planes`` (a, b, point, a's outward normal, area) of
    pairs without a mate: the later inserted part on the earlier one, the largest plane per
    pair whose normal the part's insertion runs into (within COS_FACING of antiparallel). A
    plane the insertion slides along (a guide, a keyway's flank) does not stop it: no seat."""
    ins = {p: (k, np.asarray(i.direction, float)) for k, i in enumerate(insertions) for p in i.parts}
    best: dict[tuple[str, str], tuple] = {}
    for a, b, pt, n, area in planes:
        if (a, b) in mated or pos.get(a) is None or pos.get(b) is None:
            continue
        part, on, n_on = (a, b, -n) if pos[a] > pos[b] else (b, a, n)
        (k_part, d), (k_on, _) = ins[part], ins[on]
        if k_part != k_on and float(d @ n_on) > -COS_FACING:
            continue  # n_on points at the part: the insertion must run against it to rest on it
        if (part, on) not in best or area > best[part, on][4]:
            best[part, on] = (part, on, pt, n_on, area)
    return [DerivedSeat(part, on, tuple(map(float, pt)), tuple(map(float, n_on)), float(area))
            for part, on, pt, n_on, area in best.values()]


def _radial(P: np.ndarray, m: DerivedMate) -> np.ndarray:
    """The unit directions from the axis of round fit ``m`` out to the points ``P``."""
    o, d = np.asarray(m.origin, float), np.asarray(m.axis, float)
    v = P - o
    v = v - np.outer(v @ d, d)
    return v / np.maximum(np.linalg.norm(v, axis=1, keepdims=True), 1e-300)


def _within_span(P: np.ndarray, Q: np.ndarray, m: DerivedMate) -> np.ndarray:
    """A mask of the points ``P`` whose direction about fit ``m``'s axis lies within the angular
    span of the points ``Q`` (a cradle's: less than a full turn; angles measured from their
    mean direction)."""
    if not len(P) or not len(Q):
        return np.zeros(len(P), bool)
    u, v = _radial(P, m), _radial(Q, m)
    mid = v.sum(0)
    if np.linalg.norm(mid) < 1e-9:
        return np.ones(len(P), bool)
    e1 = mid / np.linalg.norm(mid)
    e2 = np.cross(np.asarray(m.axis, float), e1)
    a, b = np.arctan2(u @ e2, u @ e1), np.arctan2(v @ e2, v @ e1)
    return (a >= b.min() - 1e-9) & (a <= b.max() + 1e-9)


def _cradle_seats(cradles: list[tuple[DerivedMate, np.ndarray, np.ndarray]], con: dict,
                  meshes: dict[str, "trimesh.Trimesh"], mated: set[tuple[str, str]], pos: dict[str, int],
                  insertions: list[Insertion], planar: list[DerivedSeat]) -> list[DerivedSeat]:
    """The curved seats among ``cradles`` (each a fit of its inner part, ``peg``, in the half
    cylinder of ``hole``, with each side's wall samples in ``con[peg, hole]`` and ``con[hole,
    peg]``) of pairs with neither a mate nor a planar seat: where the later inserted part
    moves along the mean of its outward normals on the walls (within COS_FACING: into the
    other), it rests there (a shaft in its cradle, or a cradle onto a shaft placed first); the
    seat takes that insertion's direction. A part that already rests on a plane (a cap on its
    block) is held there: its cradle over another part is a contact only."""
    ins = {p: np.asarray(i.direction, float) for i in insertions for p in i.parts}
    seated = {frozenset((s.part, s.on)) for s in planar}
    on_plane = {s.part for s in planar}
    out: dict[tuple[str, str], DerivedSeat] = {}
    for c, wall_in, wall_out in cradles:
        if c.peg not in pos or c.hole not in pos or (c.peg, c.hole) in mated:
            continue
        part, on, walls = (c.peg, c.hole, wall_in) if pos[c.peg] > pos[c.hole] else (c.hole, c.peg, wall_out)
        if frozenset((part, on)) in seated or part in on_plane or not len(walls):
            continue
        P, T, gaps = con[part, on]
        N = meshes[part].face_normals[T[walls]]
        mean = N.sum(0)
        if np.linalg.norm(mean) < 1e-9:
            continue
        mean /= np.linalg.norm(mean)
        d = ins[part]
        if float(d @ mean) < COS_FACING:
            continue  # the insertion slides along the cradle (or leaves it): not resting in it
        k = int(np.argmin(np.linalg.norm(P[walls] - P[walls].mean(0), axis=1)))
        i = walls[k]
        pt = P[i] + 0.5 * gaps[i] * meshes[part].face_normals[T[i]]  # midway across the fit
        area = float(meshes[part].area_faces[np.unique(T[walls])].sum())
        if (part, on) not in out or area > out[part, on].area:
            out[part, on] = DerivedSeat(part, on, tuple(map(float, pt)), tuple(float(-x) for x in mean), area,
                                        tuple(float(x) for x in d), float(gaps[i]))
    return list(out.values())


def _cylinder_filtered(meshes: dict[str, "trimesh.Trimesh"], a: str, b: str, ta: np.ndarray, tb: np.ndarray,
                       tol: float, cradle: bool = False, axis_tol: float = 0.0) -> DerivedMate | None:
    """:func:`_cylinder` on the triangles of ``ta`` and ``tb`` that are not normal to the
    axis fitted on the rest (an end face or shoulder among a cylinder's contacts)."""
    m = _cylinder(meshes, a, b, ta, tb, tol, cradle, axis_tol)
    if m is not None:
        return m
    Na, Nb = meshes[a].face_normals[ta], meshes[b].face_normals[tb]
    # an end face's or shoulder's normal is the axis: try each distinct normal as the axis
    seen: list[np.ndarray] = []
    for d in _by_count(np.vstack([Na, Nb])):
        if any(abs(float(d @ u)) > 1 - 1e-6 for u in seen):
            continue
        seen.append(d)
        ka, kb = np.abs(Na @ d) < SIN_AXIS, np.abs(Nb @ d) < SIN_AXIS
        if ka.sum() >= 3 and kb.sum() >= 3:
            m = _cylinder(meshes, a, b, ta[ka], tb[kb], tol, cradle, axis_tol)
            if m is not None:
                return m
        if len(seen) > 50:
            break
    return None


def _by_count(normals: np.ndarray) -> np.ndarray:
    """The distinct ``normals`` (rounded to 1e-3), the most frequent first (a planar face's
    many triangles before a curved wall's one each): the candidate axes in the order tried."""
    keys, first, counts = np.unique(np.round(normals, 3), axis=0, return_index=True, return_counts=True)
    order = np.lexsort((first, -counts))
    return normals[first[order]]


def _same_mate(m: DerivedMate, x: DerivedMate, tol: float) -> bool:
    """Whether two fitted mates are one: the same parts and the same axis."""
    if (m.peg, m.hole) != (x.peg, x.hole) or abs(float(np.dot(m.axis, x.axis))) < 1 - 1e-6:
        return False
    off = np.asarray(m.origin) - np.asarray(x.origin)
    d = np.asarray(x.axis)
    return float(np.linalg.norm(off - (off @ d) * d)) < tol


def _connected(group: tuple[str, ...], con: dict) -> bool:
    """Whether the parts of ``group`` touch each other as a connected graph."""
    seen = {group[0]}
    frontier = [group[0]]
    while frontier:
        p = frontier.pop()
        for q in group:
            if q not in seen and ((p, q) in con or (q, p) in con):
                seen.add(q)
                frontier.append(q)
    return len(seen) == len(group)


# --------------------------------------------------------------------------- cache


def derive_assembly_cached(meshes: dict[str, "trimesh.Trimesh"], base: str, contact_tol: float = 0.1,
                           clearance_max: float = 0.5, use_cache: bool = True, axis_tol: float = 0.01
                           ) -> AssemblyResult:
    """:func:`derive_assembly`, kept on disk by content: the key is the SHA-256 of every part's
    name, vertices and faces (as placed), the base, the tolerances and ASSEMBLY_VERSION; kept
    beside the object models' derivations (world.parts.cache.cache_dir)."""
    from spar_py.world.parts import cache_dir, load_derivation, store_derivation

    import hashlib

    h = hashlib.sha256(json.dumps([ASSEMBLY_VERSION, base, round(contact_tol, 12), round(clearance_max, 12),
                                   round(axis_tol, 12)]).encode())
    for p, m in meshes.items():
        h.update(p.encode())
        h.update(np.ascontiguousarray(np.round(m.vertices, 9), float).tobytes())
        h.update(np.ascontiguousarray(m.faces, np.int64).tobytes())
    key = h.hexdigest()
    path = cache_dir() / f"assembly-{key}.json"
    if use_cache and (data := load_derivation(path, key)) is not None:
        try:
            return AssemblyResult.from_json(data)
        except (KeyError, TypeError):
            pass  # an entry of an older form: derived again
    res = derive_assembly(meshes, base, contact_tol, clearance_max, axis_tol)
    if use_cache:
        data = res.to_json()
        data["key"] = key
        store_derivation(path, data)
    return res
