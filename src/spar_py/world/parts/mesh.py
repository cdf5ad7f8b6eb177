"""Object geometry: a part's mesh from ``mesh: FILE`` or ``shape:`` primitives, its faces,
the mating feature's geometry and the assembly transform T_a.

The one door for other modules is :func:`part_mesh`::

    part_mesh(model: ObjectModel) -> trimesh.Trimesh

the part's closed triangle mesh in its **object frame**, lengths in the **cell unit** (the
unit the model was loaded in). A model with ``mesh:`` gives that file scaled from the
model's length unit; a model with ``shape:`` gives the union of its boxes and z-cylinders
less the primitives marked ``subtract: true`` (booleans by manifold3d); a model with
neither gives None. The mesh is built once per model (kept on the model's
:class:`Geometry`, freed with it) and must not be modified by callers (copy it first).

Derived faces (:func:`derive_faces`): triangles of each mating feature's surfaces (the
shaft's side and tip, or the hole's wall and bottom) form the face the feature names;
the others are joined across edges where coplanar (planar facets) or where the surface
bends by less than SMOOTH_DEG (a tessellated curved surface), and planar facets on one
plane are merged. Names, in order of precedence: the features' ``name``; ``face_names:``
(a name -> a point on the face); ``px nx py ny pz nz`` for a planar face whose outward
normal is that axis when no other face has it; ``f1, f2, ...`` for the rest, numbered in
a deterministic order (by centroid, then normal).

Stable poses are in :mod:`spar_py.world.parts.poses`, grasps and the checks of hand-written
entries in :mod:`spar_py.world.parts.grasps` (with the modules it draws on: hand, clip, shafts,
facets, antipodal); the content-hash cache of derivations in :mod:`spar_py.world.parts.cache`.

Frames: object frame as the model file gives it; T_a is the peg's frame in the hole's
frame (4x4, column vectors). Units: lengths in the cell unit, the tolerances below in mm
(converted with :func:`spar_py.core.units.from_mm`), angles in radians unless a name says deg.
trimesh and manifold3d are imported inside the functions that need them.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from spar_py.core.model import FeatureGeometry
from spar_py.core.units import from_mm

if TYPE_CHECKING:
    import trimesh

    from spar_py.core.model import ObjectModel

__all__ = [
    "Face", "FeatureGeometry", "Geometry", "Primitive", "Repair", "assembly_transforms", "axis_basis",
    "derive_faces", "face_of_point", "minimal_rotation", "part_mesh", "poses_clear_of_table", "repair_mesh",
]

#: Sides of the polygon a cylinder primitive is tessellated with.
CYL_SECTIONS = 64
#: Adjacent triangles whose normals differ by less than this are coplanar (deg).
COPLANAR_DEG = 0.05
#: Adjacent triangles bending by less than this belong to one curved surface (deg).
SMOOTH_DEG = 20.0
#: Points closer than this to a surface are on it (mm).
ON_SURFACE_MM = 0.01
#: Two unit normals within this of each other name the same axis (no unit).
AXIS_TOL = 1e-6
#: The largest mesh file read (bytes): a 10^6-triangle binary STL is 50 MB.
MAX_MESH_BYTES = 64_000_000
#: Vertices closer than this fraction of the part's size are one (a CAD export's seams), when
#: merging the exact duplicates leaves the mesh open.
MERGE_REL = 1e-5
#: Holes (loops of open edges) at most this fraction of the part's size across are filled.
FILL_REL = 0.02
#: Unnamed faces are numbered by their centroids to this fraction of the largest coordinate, then
#: their areas to ORDER_AREA_DIGITS significant digits: coarser than a mesh file's float32
#: vertices (6e-8 of a coordinate, a few times over between two faces and two files), which
#: differ by file unit, so a part in metres gets the names it gets in mm (a gear's rim and bore
#: share a centroid; a closed round face's mean normal is noise).
ORDER_REL = 2e-6
ORDER_AREA_DIGITS = 4


@dataclass(frozen=True)
class Repair:
    """What loading a mesh had to repair (counts; all zero for a clean mesh)."""

    merged: int = 0
    degenerate: int = 0
    duplicate: int = 0
    holes: int = 0
    flipped: bool = False
    inverted: bool = False

    def line(self) -> str:
        """One line of what was done (empty when nothing was)."""
        done = []
        if self.merged:
            done.append(f"merged {self.merged:,} seam vertices within {MERGE_REL:g} of the part's size")
        if self.degenerate or self.duplicate:
            done.append(f"removed {self.degenerate + self.duplicate:,} degenerate or duplicate triangles")
        if self.holes:
            done.append(f"filled {self.holes:,} hole{'s' if self.holes > 1 else ''}")
        if self.flipped:
            done.append("fixed winding")
        if self.inverted:
            done.append("turned the normals outward")
        return ", ".join(done)


# =========================================================================== declarations


@dataclass(frozen=True)
class Primitive:
    """A ``shape:`` primitive in the object frame (cell unit): a box (``lo``, ``hi`` corners)
    or a cylinder about the object z axis (``radius``, z from ``lo[2]`` to ``hi[2]``);
    ``subtract`` removes it from the union of the others (a hole, a pocket)."""

    kind: str
    lo: np.ndarray
    hi: np.ndarray
    radius: float = 0.0
    subtract: bool = False

    def spec(self) -> list:
        """Plain data for the content hash."""
        return [self.kind, [round(float(v), 12) for v in (*self.lo, *self.hi)], round(self.radius, 12),
                self.subtract]


@dataclass
class Geometry:
    """What a model file declares of its shape: ``mesh_file`` (scaled by ``scale`` from the
    model's unit to the cell ``unit``) or ``primitives``, and its ``face_names``; the built
    mesh is kept in ``_mesh``."""

    unit: str
    primitives: tuple[Primitive, ...] = ()
    mesh_file: str | None = None
    scale: float = 1.0
    #: ``face_names:`` of the model: a name -> a point on the face (object frame, cell unit).
    face_names: dict = field(default_factory=dict)
    #: ``grasp_step:`` of the model, the quantum of grasp approaches and assembly turns (rad).
    step: float = math.radians(45.0)
    #: The vertices of the mesh's convex hull (object frame, cell unit) once a derivation gave
    #: them (enough for the lowest point of the part in any orientation), else None.
    hull: np.ndarray | None = field(default=None, compare=False, repr=False)
    #: What loading the mesh file repaired (:class:`Repair`'s line; "" for none), once the mesh
    #: was built or a cached derivation said so.
    repair: str = field(default="", compare=False)
    #: Why the derivation found no grasp (world.parts.grasps.derive_grasps's line), or "".
    no_grasp: str = field(default="", compare=False)
    _mesh: Any = field(default=None, compare=False, repr=False)
    _digest: str | None = field(default=None, compare=False, repr=False)

    def digest(self) -> str:
        """SHA-256 of the geometry's content (the mesh file's bytes, or the primitives) and scale."""
        if self._digest is None:
            import hashlib  # here: its import (OpenSSL, _blake2) is ms of a cold plan that never asks

            h = hashlib.sha256()
            if self.mesh_file is not None:
                h.update(b"mesh:" + Path(self.mesh_file).read_bytes())
            else:
                h.update(repr([p.spec() for p in self.primitives]).encode())
            h.update(f"|scale={self.scale!r}|unit={self.unit}".encode())
            self._digest = h.hexdigest()
        return self._digest

    def mesh(self) -> "trimesh.Trimesh":
        """The part's mesh (object frame, cell unit), built on first use."""
        if self._mesh is None:
            if self.mesh_file:
                self._mesh, done = load_mesh(self.mesh_file, self.scale)
                self.repair = done.line()
            else:
                self._mesh = _primitives_mesh(self.primitives)
        return self._mesh


def part_mesh(model: "ObjectModel") -> "trimesh.Trimesh | None":
    """The part's closed mesh in its object frame, lengths in the cell unit (see the module
    docstring); None for a model without ``mesh:`` or ``shape:``. Do not modify it."""
    geo = getattr(model, "geometry", None)
    return None if geo is None else geo.mesh()


def load_mesh(path: str, scale: float) -> "tuple[trimesh.Trimesh, Repair]":
    """Read an STL, OBJ or PLY file as one mesh, scaled by ``scale``, and repair what a CAD
    export leaves open (:func:`repair_mesh`). ValueError (one line) if it cannot be read or
    is not a closed volume once repaired. A file read before in this process (same path, size,
    modification time and scale) is not read again: the caller gets its own copy of the
    repaired mesh (a product's load reads each part's file for the assembly's derivation and
    again for the part's own)."""
    p = Path(path)
    st = p.stat()
    if st.st_size > MAX_MESH_BYTES:
        raise ValueError(f"a mesh file of at most {MAX_MESH_BYTES} bytes, not {st.st_size} bytes")
    key = (str(p.resolve()), st.st_size, st.st_mtime_ns, float(scale))
    if key not in _READ:
        while len(_READ) >= READ_MEMO:
            del _READ[next(iter(_READ))]
        m, done = _read_mesh(p, scale)
        _READ[key] = (m.copy(include_cache=True), done)
    m, done = _READ[key]
    return m.copy(include_cache=True), done


READ_MEMO = 64
"""How many repaired meshes :func:`load_mesh` keeps (the oldest read is dropped first)."""
_READ: "dict[tuple[str, int, int, float], tuple[trimesh.Trimesh, Repair]]" = {}


def _read_mesh(p: Path, scale: float) -> "tuple[trimesh.Trimesh, Repair]":
    """:func:`load_mesh`'s read and repair of file ``p``."""
    import trimesh  # only a mesh or primitives model pays for it

    try:
        m = trimesh.load(str(p), force="mesh", process=True)
    except Exception as e:  # trimesh raises many kinds for a bad file
        raise ValueError(f"a readable STL, OBJ or PLY mesh ({type(e).__name__}: {str(e)[:60]})") from None
    if not isinstance(m, trimesh.Trimesh) or len(m.faces) == 0:
        raise ValueError("a mesh with at least one triangle")
    if scale != 1.0:
        m.apply_scale(scale)
    m.merge_vertices()
    return m, repair_mesh(m)


def _open_edges(m: "trimesh.Trimesh") -> np.ndarray:
    """(k, 2) the directed edges (as their triangles run) that no other triangle shares."""
    from trimesh.grouping import group_rows

    return np.asarray(m.edges)[group_rows(m.edges_sorted, require_count=1)]


def repair_mesh(m: "trimesh.Trimesh") -> Repair:
    """Close ``m`` in place where a CAD export left it open, and say what was done.

    A mesh that is closed and consistently oriented once exact duplicate vertices are merged
    is left as it is (only turned outward if its volume is negative). Otherwise, in order:
    vertices within MERGE_REL of the part's size (its bounding box's largest side) are merged
    (seams of near-duplicates), triangles left with a repeated corner and duplicates removed, holes (loops of open
    edges) of 3 or 4 edges or at most FILL_REL of the part's size across filled,
    and the winding made consistent. ValueError (one line: the open edges left, and where)
    when the mesh is still open, or not one oriented volume."""
    import trimesh

    merged = degenerate = duplicate = holes = 0
    flipped = False
    if not (m.is_watertight and m.is_winding_consistent):
        part = float(np.ptp(m.vertices, axis=0).max())
        if not m.is_watertight:
            merged = _merge_near(m, MERGE_REL * part)
        F = np.asarray(m.faces)
        keep = (F[:, 0] != F[:, 1]) & (F[:, 1] != F[:, 2]) & (F[:, 2] != F[:, 0])  # a corner merged away
        degenerate = int((~keep).sum())
        if degenerate:
            m.update_faces(keep)
        uniq = m.unique_faces()
        duplicate = int(len(m.faces) - uniq.sum())
        if duplicate:
            m.update_faces(uniq)
        m.remove_unreferenced_vertices()
        if not m.is_watertight:
            holes = _fill_small_holes(m, FILL_REL * part)
        if m.is_watertight and not m.is_winding_consistent:
            trimesh.repair.fix_winding(m)
            flipped = True
        if not m.is_watertight:
            E = _open_edges(m)
            P = np.asarray(m.vertices)[E.ravel()]
            lo, hi = (np.where(np.abs(v) < 1e-9 * part, 0.0, v) for v in (P.min(0), P.max(0)))
            done = Repair(merged, degenerate, duplicate, holes, flipped).line()
            raise ValueError(
                f"a closed (watertight) mesh: {len(E):,} edges stay open"
                f"{' after repair (' + done + ')' if done else ''}, around "
                f"[{', '.join(f'{v:.4g}' for v in (lo + hi) / 2)}] (from [{', '.join(f'{v:.4g}' for v in lo)}] to "
                f"[{', '.join(f'{v:.4g}' for v in hi)}], the part's frame, cell unit); holes wider than "
                f"{FILL_REL:g} of the part's size are not filled")
        if not m.is_winding_consistent:
            raise ValueError("a mesh whose triangles can be oriented consistently (a closed, two-sided surface)")
    inverted = bool(m.volume < 0)
    if inverted:
        m.invert()
    if not m.is_volume:
        raise ValueError("a mesh that bounds a volume")
    return Repair(merged, degenerate, duplicate, holes, flipped, inverted)


def _merge_near(m: "trimesh.Trimesh", tol: float) -> int:
    """Merge the vertices of ``m`` within ``tol`` of each other (clusters joined through such
    pairs; each to its lowest-numbered vertex, which keeps its place); the number removed."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components
    from scipy.spatial import cKDTree

    V = np.asarray(m.vertices)
    pairs = cKDTree(V).query_pairs(tol, output_type="ndarray")
    if not len(pairs):
        return 0
    n = len(V)
    g = coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(n, n))
    _, comp = connected_components(g, directed=False)
    first = np.full(comp.max() + 1, n)
    np.minimum.at(first, comp, np.arange(n))
    target = first[comp]
    m.faces = target[np.asarray(m.faces)]
    before = n
    m.remove_unreferenced_vertices()
    return before - len(m.vertices)


def _fill_small_holes(m: "trimesh.Trimesh", max_across: float) -> int:
    """Fill each simple loop of open edges that is a missing triangle or quad, or at most
    ``max_across`` across (its bounding box's diagonal): a triangle's with one triangle, the
    others with a fan from a new vertex at the loop's centroid, each wound against the open
    edges' triangles; the number of holes filled. A wide loop is a cut, left open."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    E = _open_edges(m)
    if not len(E):
        return 0
    V = np.asarray(m.vertices)
    n = len(V)
    g = coo_matrix((np.ones(len(E)), (E[:, 0], E[:, 1])), shape=(n, n))
    _, comp = connected_components(g, directed=False)
    loop = comp[E[:, 0]]
    faces = set(map(tuple, np.sort(np.asarray(m.faces), axis=1).tolist()))
    new_v: list[np.ndarray] = []
    new_f: list[np.ndarray] = []
    for k in np.unique(loop):
        e = E[loop == k]
        ids = np.unique(e)
        if len(e) < 3 or len(ids) != len(e) or (len(e) > 4 and np.linalg.norm(np.ptp(V[ids], axis=0)) > max_across):
            continue  # not one simple loop, or wide: a cut, not a hole
        if len(e) == 3:
            if tuple(ids) not in faces:  # else the loop is a lone triangle's own rim: no hole to fill
                new_f.append(np.array([[e[0, 1], e[0, 0], next(int(v) for v in ids if v not in e[0])]]))
            continue
        pts = V[ids]
        c = n + len(new_v)
        new_v.append(pts.mean(0))
        new_f.append(np.column_stack([e[:, 1], e[:, 0], np.full(len(e), c)]))
    if not new_f:
        return 0
    if new_v:
        m.vertices = np.vstack([V, np.array(new_v)])
    m.faces = np.vstack([np.asarray(m.faces), *new_f])
    return len(new_f)


def _primitives_mesh(prims: tuple[Primitive, ...]) -> "trimesh.Trimesh":
    """The union of the positive primitives less the union of the subtracted ones."""
    import trimesh  # only a mesh or primitives model pays for it

    def solid(p: Primitive) -> trimesh.Trimesh:
        if p.kind == "box":
            return trimesh.creation.box(bounds=np.array([p.lo, p.hi], float))
        return trimesh.creation.cylinder(radius=p.radius, segment=[[0, 0, p.lo[2]], [0, 0, p.hi[2]]],
                                         sections=CYL_SECTIONS)

    pos = [solid(p) for p in prims if not p.subtract]
    neg = [solid(p) for p in prims if p.subtract]
    if not pos:
        raise ValueError("at least one primitive that is not subtracted")
    m = pos[0] if len(pos) == 1 else trimesh.boolean.union(pos, engine="manifold")
    if neg:
        m = trimesh.boolean.difference([m, *neg], engine="manifold")
    if len(m.faces) == 0:
        raise ValueError("primitives that leave some material once the subtracted ones are removed")
    return m


# =========================================================================== faces


@dataclass(frozen=True)
class Face:
    """A derived face: its ``name``, triangle indices ``tris`` into the part mesh, area-weighted
    outward unit ``normal``, ``planar`` (and then its plane ``offset`` = normal . p), ``area``,
    ``centroid`` (object frame, cell unit) and whether it is a mating feature's (then ``name`` is
    the feature's)."""

    name: str
    tris: np.ndarray
    normal: np.ndarray
    planar: bool
    offset: float
    area: float
    centroid: np.ndarray
    feature: bool = False


def _feature_triangles(mesh: "trimesh.Trimesh", f: FeatureGeometry, tol: float, through: bool = False
                       ) -> np.ndarray:
    """(n,) bool: the triangles on the feature's surfaces (its cylinder's side between root and
    end, and the end cap: the peg's tip or the hole's bottom; a ``through`` hole has none)."""
    V = mesh.vertices[mesh.faces] - f.origin                        # (n, 3, 3)
    t = V @ f.direction                                             # axial coordinate
    radial = np.linalg.norm(V - t[..., None] * f.direction, axis=2)
    along = (t > -tol).all(1) & (t < f.length + tol).all(1)
    if f.profile == "prism" and f.corners is not None:
        side = _prism_walls(mesh, f, V, tol) & along
    else:
        side = (np.abs(radial - f.radius) < tol).all(1) & along
    if through:
        return side
    cap = (np.abs(t - f.length) < tol).all(1) & (radial < f.reach + tol).all(1)
    return side | cap


def _prism_walls(mesh: "trimesh.Trimesh", f: FeatureGeometry, V: np.ndarray, tol: float) -> np.ndarray:
    """(n,) bool: the triangles of a prism feature's walls: normal to the axis within 0.1 (a
    tapered wall, a draft, leans a little), and whose plane, at its widest across the axis over
    the feature's length, lies between the inscribed half-width (``radius``) and the profile's
    support distance along the wall's normal (the farthest corner), within a tenth of the
    radius, and no farther from the axis than the farthest corner (not another feature's wall
    in line with it). ``V`` (n, 3, 3): the triangles' corners relative to the feature's origin."""
    d = f.direction
    n = mesh.face_normals * (1.0 if f.kind == "peg" else -1.0)  # away from the axis
    tilt = n @ d
    across = np.sqrt(np.clip(1.0 - tilt ** 2, 1e-12, None))
    n_perp = (n - tilt[:, None] * d) / across[:, None]
    h = np.einsum("ij,ij->i", V.mean(1), n)  # the wall plane: n . x = h
    # where the plane is across the axis at the feature's two ends (t = 0, t = length)
    widest = np.maximum(h, h - f.length * tilt) / across
    support = (n_perp @ np.asarray(f.corners, float).T).max(1)
    slack = max(tol, 0.1 * f.radius)
    C = V.mean(1)
    off = np.linalg.norm(C - np.outer(C @ d, d), axis=1)  # the triangle's distance from the axis
    return ((np.abs(tilt) < 0.1) & (widest > f.radius - slack) & (widest < support + slack)
            & (off < f.reach + slack))


def derive_faces(mesh: "trimesh.Trimesh", features: "tuple[FeatureGeometry, ...]", face_names: dict[str, np.ndarray],
                 unit: str) -> list[Face]:
    """The faces of ``mesh`` (module docstring), named: each of ``features`` gives one face
    (its triangles, named by the feature; a ``through`` hole has no bottom cap). ``face_names``
    maps a name to a point on the face (object frame, cell unit); ValueError naming the entry
    if the point is on no face, on a feature's face under another name, or two names share a
    face; or if two features claim one triangle.
    Derived once per mesh and arguments: kept in the mesh's own trimesh cache, which trimesh
    empties when the mesh's vertices or faces change (a part's faces are asked for by its
    derivation, its subassembly poses and its seats). A new list of the same Faces each time:
    do not modify their arrays."""
    import hashlib
    import pickle

    key = "spar_faces_" + hashlib.sha256(pickle.dumps((features, list(face_names.items()), unit))).hexdigest()
    cache = mesh._cache  # noqa: SLF001 - trimesh's property cache, checked against the mesh's data
    cache.verify()
    if key not in cache.cache:
        cache.cache[key] = _derive_faces(mesh, features, face_names, unit)
    return list(cache.cache[key])


def _derive_faces(mesh: "trimesh.Trimesh", features: "tuple[FeatureGeometry, ...]", face_names: dict[str, np.ndarray],
                  unit: str) -> list[Face]:
    """:func:`derive_faces` computed."""
    tol = from_mm(unit, ON_SURFACE_MM)
    n = len(mesh.faces)
    N = mesh.face_normals
    label = np.full(n, -1)
    groups: list[np.ndarray] = []
    owners: list[FeatureGeometry] = []
    for feature in features:
        ft = _feature_triangles(mesh, feature, tol, feature.through)
        if (ft & (label >= 0)).any():
            other = owners[int(label[np.flatnonzero(ft & (label >= 0))[0]])].name
            raise ValueError(f"features: expected features on distinct surfaces, not {feature.name} on "
                             f"{other}'s")
        if ft.any():
            label[ft] = len(groups)
            groups.append(np.flatnonzero(ft))
            owners.append(feature)
    # connected components over edges between non-feature triangles: coplanar or smoothly
    # bent; each component's triangles ascending, the components in the order of their first
    comps = _smooth_components(mesh, label < 0)
    area = mesh.area_faces
    # planar components on one plane are merged ("merged where coplanar")
    cos_tol = math.cos(math.radians(COPLANAR_DEG))
    planes: list[tuple[np.ndarray, float, list[int]]] = []
    curved: list[list[int]] = []
    for tris in comps:
        t = np.asarray(tris)
        nrm = (N[t] * area[t, None]).sum(0)
        nrm /= max(np.linalg.norm(nrm), 1e-300)
        if (N[t] @ nrm > cos_tol).all():
            off = float(np.median(mesh.vertices[mesh.faces[t]].reshape(-1, 3) @ nrm))
            for k, (pn, po, pt) in enumerate(planes):
                if pn @ nrm > cos_tol and abs(po - off) < tol:
                    pt.extend(tris)
                    break
            else:
                planes.append((nrm, off, list(tris)))
        else:
            curved.append(tris)
    n_feat = len(groups)
    groups += [np.asarray(sorted(p[2])) for p in planes] + [np.asarray(sorted(c)) for c in curved]
    faces = [_face(owners[k].name if k < n_feat else "", g, mesh, k < n_feat) for k, g in enumerate(groups)]
    return _name_faces(faces, mesh, face_names, tol, from_mm(unit, 1.0))


def _smooth_components(mesh: "trimesh.Trimesh", free: np.ndarray) -> list[list[int]]:
    """The triangles of ``free`` (a mask) joined across edges bent less than SMOOTH_DEG, as
    lists of ascending indices, ordered by their lowest index."""
    import scipy.sparse as sp
    from scipy.sparse.csgraph import connected_components

    n = len(mesh.faces)
    adj = np.asarray(mesh.face_adjacency, int).reshape(-1, 2)
    ang = np.asarray(mesh.face_adjacency_angles, float)
    e = adj[(ang < math.radians(SMOOTH_DEG)) & free[adj[:, 0]] & free[adj[:, 1]]]
    g = sp.coo_matrix((np.ones(len(e)), (e[:, 0], e[:, 1])), shape=(n, n))
    _, lab = connected_components(g, directed=False)
    first = np.full(lab.max() + 1 if n else 0, n)
    np.minimum.at(first, lab, np.arange(n))
    idx = np.flatnonzero(free)
    key = first[lab[idx]]
    idx = idx[np.argsort(key, kind="stable")]
    cuts = np.flatnonzero(np.diff(np.sort(key))) + 1
    return [c.tolist() for c in np.split(idx, cuts)] if len(idx) else []


def _face(name: str, tris: np.ndarray, mesh: "trimesh.Trimesh", is_feature: bool) -> Face:
    area = mesh.area_faces[tris]
    N = mesh.face_normals[tris]
    nrm = (N * area[:, None]).sum(0)
    nrm = nrm / max(np.linalg.norm(nrm), 1e-300)
    planar = bool((N @ nrm > math.cos(math.radians(COPLANAR_DEG))).all())
    cen = (mesh.triangles_center[tris] * area[:, None]).sum(0) / max(area.sum(), 1e-300)
    return Face(name, tris, nrm, planar and not is_feature, float(cen @ nrm), float(area.sum()), cen, is_feature)


def face_of_point(faces: list[Face], mesh: "trimesh.Trimesh", p: np.ndarray, tol: float) -> int | None:
    """The index of the face ``p`` lies on (within ``tol``), or None."""
    import trimesh  # only a mesh or primitives model pays for it

    tri = mesh.triangles
    closest = trimesh.triangles.closest_point(tri, np.repeat(np.asarray(p, float)[None], len(tri), 0))
    d = np.linalg.norm(closest - p, axis=1)
    i = int(np.argmin(d))
    if d[i] > tol:
        return None
    return next(k for k, f in enumerate(faces) if i in set(f.tris.tolist()))


_AXES = {"px": (1, 0, 0), "nx": (-1, 0, 0), "py": (0, 1, 0), "ny": (0, -1, 0), "pz": (0, 0, 1), "nz": (0, 0, -1)}


def _name_faces(faces: list[Face], mesh: "trimesh.Trimesh", face_names: dict[str, np.ndarray], tol: float,
                mm: float = 1.0) -> list[Face]:
    """Names by precedence: features' (already on their faces), face_names, axis names where
    unique, then f1, f2, ... in the order of their centroids to ORDER_REL of the largest coordinate, then
    their areas in mm^2 (ORDER_AREA_DIGITS; ``mm``: one mm in the cell unit), then their normals:
    the same names whatever the file's length unit."""
    names: dict[int, str] = {k: f.name for k, f in enumerate(faces) if f.feature}
    for name, p in face_names.items():
        k = face_of_point(faces, mesh, p, tol)
        if k is None:
            raise ValueError(f"face_names.{name}: expected a point on a face of the shape, not "
                             f"[{', '.join(f'{v:.6g}' for v in p)}] (on no face)")
        if k in names:
            raise ValueError(f"face_names.{name}: expected a point on a face not named before, not one on "
                             f"{names[k]}")
        names[k] = name
    used = set(names.values())
    for ax, v in _AXES.items():
        hits = [k for k, f in enumerate(faces) if f.planar and np.abs(f.normal - v).max() < AXIS_TOL]
        if len(hits) == 1 and hits[0] not in names and ax not in used:
            names[hits[0]] = ax
            used.add(ax)
    grid = ORDER_REL * float(np.abs(mesh.vertices).max())
    order = sorted((k for k in range(len(faces)) if k not in names),
                   key=lambda k: (*np.round(faces[k].centroid / grid),
                                  float(f"{faces[k].area / mm ** 2:.{ORDER_AREA_DIGITS}g}"),
                                  *np.round(faces[k].normal, 6)))
    i = 0
    for k in order:
        i += 1
        while f"f{i}" in used:
            i += 1
        names[k] = f"f{i}"
    out = [replace(f, name=names[k]) for k, f in enumerate(faces)]
    return sorted(out, key=lambda f: _name_key(f.name))


def _name_key(name: str) -> tuple:
    """Axis names first (px, nx, py, ny, pz, nz), then f1, f2, ... numerically, then the rest."""
    if name in _AXES:
        return (0, list(_AXES).index(name), "")
    if name[:1] == "f" and name[1:].isdigit():
        return (2, int(name[1:]), "")
    return (1, 0, name)


# =========================================================================== frames


def cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The cross product over the last axis (np.cross's per-call overhead dominates on 3-vectors)."""
    a, b = np.asarray(a, float), np.asarray(b, float)
    return np.stack([a[..., 1] * b[..., 2] - a[..., 2] * b[..., 1], a[..., 2] * b[..., 0] - a[..., 0] * b[..., 2],
                     a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]], axis=-1)


def axis_basis(d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two unit vectors (e1, e2) completing the unit ``d`` to a right-handed frame: e1 is the
    object axis least aligned with d (the first such), made normal to d; e2 = d x e1."""
    d = np.asarray(d, float) / np.linalg.norm(d)
    e = np.eye(3)[int(np.argmin(np.abs(d) + 1e-12 * np.arange(3)))]
    e1 = e - (e @ d) * d
    e1 /= np.linalg.norm(e1)
    return e1, cross(d, e1)


def minimal_rotation(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The 3x3 rotation of least angle taking unit ``a`` to unit ``b``; for b = -a, the half
    turn about :func:`axis_basis`'s e1 of a (so +z to -z is the half turn about x)."""
    a = np.asarray(a, float) / np.linalg.norm(a)
    b = np.asarray(b, float) / np.linalg.norm(b)
    c = float(a @ b)
    if c < -1 + 1e-12:
        k = axis_basis(a)[0]
        return 2 * np.outer(k, k) - np.eye(3)
    v = cross(a, b)
    K = np.array([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0]])
    return np.eye(3) + K + K @ K / (1 + c)


def clean(M: np.ndarray, eps: float = 1e-12) -> np.ndarray:
    """``M`` with entries within eps of an integer snapped to it (exact axes, exact zeros)."""
    M = np.asarray(M, float).copy()
    r = np.round(M)
    near = np.abs(M - r) < eps
    M[near] = r[near]
    M[M == 0] = 0.0
    return M


# =========================================================================== assembly


def assembly_transforms(peg: FeatureGeometry, hole: FeatureGeometry,
                        step_rad: float = math.radians(45.0)) -> tuple[list[np.ndarray], np.ndarray, float]:
    """T_a candidates, V_a and the insertion depth for ``assembled(peg, hole)``.

    T_a (4x4) is the peg's frame in the hole's frame with the peg's axis on the hole's, its
    direction into the hole, pushed in by ``min(peg length, hole depth)``: the tip at the
    hole's bottom, or the shoulder on the hole's face if that comes first. The candidates are
    the turns about the hole's axis by multiples of ``step_rad`` (first the minimal rotation,
    :func:`minimal_rotation`). V_a, the mating motion in the hole's frame, is the hole's
    direction. Lengths in the cell unit.
    """
    if peg.kind != "peg" or hole.kind != "hole":
        raise ValueError(f"a peg feature and a hole feature, not {peg.kind} and {hole.kind}")
    depth = min(peg.length, hole.length)
    R0 = minimal_rotation(peg.direction, hole.direction)
    tip_goal = hole.origin + depth * hole.direction
    n_turns = max(1, int(round(2 * math.pi / step_rad)))
    out = []
    for k in range(n_turns):
        a = k * 2 * math.pi / n_turns
        d = hole.direction
        K = np.array([[0, -d[2], d[1]], [d[2], 0, -d[0]], [-d[1], d[0], 0]])
        Rk = np.eye(3) + math.sin(a) * K + (1 - math.cos(a)) * K @ K
        R = clean(Rk @ R0)
        T = np.eye(4)
        T[:3, :3] = R
        T[:3, 3] = tip_goal - R @ peg.end
        out.append(clean(T))
    return out, clean(hole.direction.copy()), depth


#: A mated part may reach this far below the table top and still count as clear of it (mm).
TABLE_CLEAR_MM = 0.01


def poses_clear_of_table(peg_vertices: np.ndarray, T_a: np.ndarray, hole_poses: list[tuple[np.ndarray, float]],
                         unit: str) -> list[bool]:
    """For each stable pose (R, height) of the hole part, whether the peg mated by ``T_a``
    (the peg's frame in the hole's frame, 4x4) stays above the table top (z = 0) with the
    hole part resting in that pose: its lowest vertex at most TABLE_CLEAR_MM below it.

    ``peg_vertices`` (n, 3) are the peg's mesh vertices in its object frame; R (3x3) takes the
    hole part's object frame to the world's and ``height`` is its origin's height above the
    table (the pose's x and y do not matter). Lengths in the cell unit ``unit``.
    """
    if not hole_poses:
        return []
    V = np.asarray(peg_vertices, float) @ T_a[:3, :3].T + T_a[:3, 3]   # peg in the hole's frame
    R = np.stack([np.asarray(r, float) for r, _ in hole_poses])       # (k, 3, 3)
    h = np.array([float(z) for _, z in hole_poses])
    low = (R[:, 2, :] @ V.T).min(1) + h                                # each pose's lowest peg point
    return [bool(z > -from_mm(unit, TABLE_CLEAR_MM)) for z in low]
