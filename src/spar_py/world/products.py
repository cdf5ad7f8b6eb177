"""Products: parts at their poses in the product frame, their mates and seats, the assembly
tree, the goals it compiles to, and precedence from geometry (swept insertions).

Frames: a part's pose is T_product_part (4x4, column vectors); a feature's origin and
direction are in its part's frame. Units: the cell unit throughout (the product file's
lengths converted at load).

- :func:`mate_misalignment`: whether a mate's features line up (coaxial, overlapping).
- :func:`compile_goals`: the assembly tree rooted at the base part and one
  :class:`~spar_py.core.model.PartGoal` per other part (T_a = T_parent^-1 T_part, V_a the
  insertion direction in the parent's frame).
- :func:`precedence`: for each non-base part P, P's solids swept along its insertion
  direction from clear of everything to its seated pose, against every other part Q at its
  product pose; a hit means Q in place blocks P, so P goes first. The sweep of a convex body
  along a line is exactly the convex hull of the body at the two ends, so each solid's sweep
  is one convex body (exact: no step to choose) tested with python-fcl's ``collide``. Every
  body is shrunk by SWEEP_MARGIN_MM first, so parts that only touch (a seat, a shoulder) do
  not block. A mated pair is tested without the peg part's feature solid (primitive shapes
  do not cut their holes: the shaft in its bore is the mate, not a collision); where the peg
  is not a separate solid (a mesh's hull) the pair is not tested. A mesh part in place is
  tested as its own triangle mesh (its holes cut), not its convex hull; a mesh part moving
  sweeps its hull (conservative).
"""
from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from spar_py.core.errors import SparValueError
from spar_py.core.model import Mate, PartGoal, Precedence, Product, Seat, Solid
from spar_py.core.units import from_mm

if TYPE_CHECKING:
    from spar_py.core.model import MatingFeature, ObjectModel

__all__ = ["AXIS_TOL_MM", "NEAR_MM", "SWEEP_MARGIN_MM", "Axis", "compile_goals", "feature_axis", "mate_misalignment",
           "near_parts", "precedence", "seat_direction"]

#: A mate's axes are coaxial when the peg's axis passes within this of the hole's (mm) and
#: their directions differ by less than AXIS_TOL_DEG.
AXIS_TOL_MM = 0.01
AXIS_TOL_DEG = 0.01
#: Bodies are shrunk by this before the sweep test (mm): touching is not blocking.
SWEEP_MARGIN_MM = 0.05


@dataclass(frozen=True)
class Axis:
    """A feature's axis in the product frame: ``origin`` (a peg's root, a hole's mouth),
    unit ``direction`` (to the peg's tip, into the hole), ``length`` and ``radius``."""

    origin: np.ndarray
    direction: np.ndarray
    length: float
    radius: float

    @property
    def end(self) -> np.ndarray:
        """The peg's tip or the hole's bottom (product frame)."""
        return self.origin + self.length * self.direction


def feature_axis(T: np.ndarray, f: "MatingFeature") -> Axis:
    """The axis of feature ``f`` (declared by geometry) of a part at pose ``T`` (product frame)."""
    g = f.geometry
    if g is None:
        raise SparValueError(f"feature {f.name}: a mate needs a feature declared by geometry (axis, length)")
    return Axis(T[:3, :3] @ g.origin + T[:3, 3], T[:3, :3] @ g.direction, float(g.length), float(g.radius))


def mate_misalignment(peg: Axis, hole: Axis, through: bool, unit: str) -> str | None:
    """Why a peg's axis and a hole's do not line up (None if they do): the angle between
    them, the peg axis's offset from the hole's, or their lengths not overlapping along it.
    The peg enters the hole along the hole's direction, or either way through a through hole."""
    cos = float(peg.direction @ hole.direction)
    if not (cos > math.cos(math.radians(AXIS_TOL_DEG)) or (through and -cos > math.cos(math.radians(AXIS_TOL_DEG)))):
        return f"axes {math.degrees(math.acos(max(-1.0, min(1.0, cos)))):.3g} deg apart"
    d = hole.direction
    off = peg.origin - hole.origin
    radial = float(np.linalg.norm(off - (off @ d) * d))
    if radial > from_mm(unit, AXIS_TOL_MM):
        return f"axes {radial:.4g} {unit} apart"
    p0, p1 = sorted((float(off @ d), float((peg.end - hole.origin) @ d)))
    if min(p1, hole.length) - max(p0, 0.0) <= 0:
        return (f"no overlap along the axis (peg from {p0:.4g} to {p1:.4g} {unit}, hole from 0 to "
                f"{hole.length:.4g} {unit} from its mouth)")
    return None


def seat_direction(product: Product, seat: Seat) -> np.ndarray:
    """The direction (product frame, unit) the seated part moves to its seat: into the surface
    it rests on, against that face's outward normal."""
    from spar_py.world.shapes import part_mesh

    part = product.parts[seat.on]
    mesh = part_mesh(part.model)
    if mesh is None:
        raise SparValueError(f"seat {seat.name}: {seat.on} needs a shape (mesh: or shape:) for its face normal")
    n = _face_normal(part.model, seat.on_face)
    return -(part.pose[:3, :3] @ n)


def _face_normal(model: "ObjectModel", face: str) -> np.ndarray:
    """The outward normal of a planar face of a part's shape (object frame, unit)."""
    from spar_py.world.shapes import derive_faces, part_mesh

    mesh = part_mesh(model)
    feats = tuple(f.geometry for f in model.features if f.geometry is not None)
    faces = derive_faces(mesh, feats, dict(model.geometry.face_names), model.geometry.unit)
    for f in faces:
        if f.name == face:
            if not f.planar:
                raise SparValueError(f"face {model.name}.{face}: a seat needs a planar face")
            return np.asarray(f.normal, float)
    raise SparValueError(f"face {model.name}.{face}: no such face on the shape")


def _mate_direction(product: Product, m: Mate, mover: str) -> np.ndarray:
    """The direction (product frame) ``mover`` (the mate's peg or hole part) moves to make mate ``m``:
    the peg along its own axis toward its tip, the hole part the opposite way."""
    peg = product.parts[m.peg]
    d = peg.pose[:3, :3] @ peg.model.feature_named(m.peg_feature).geometry.direction
    return d if mover == m.peg else -d


def _links(product: Product) -> dict[str, list[tuple[str, Mate | Seat]]]:
    """Each part's mates and seats with the other part: its mates in file order, then its seats."""
    out: dict[str, list[tuple[str, Mate | Seat]]] = {p: [] for p in product.parts}
    for m in product.mates:
        out[m.peg].append((m.hole, m))
        out[m.hole].append((m.peg, m))
    for s in product.seats:
        out[s.part].append((s.on, s))
        out[s.on].append((s.part, s))
    return out


def _direction(product: Product, link: Mate | Seat, mover: str) -> np.ndarray:
    """The direction ``mover`` moves to make ``link`` (product frame)."""
    if isinstance(link, Seat):
        d = seat_direction(product, link)
        return d if mover == link.part else -d
    return _mate_direction(product, link, mover)


def _parents(product: Product) -> dict[str, str]:
    """The assembly tree: each non-base part's parent, the part mated with it nearest the base
    in the mate graph (breadth first from the base; ties in file order). A pin through a
    bracket into the base goes into the base: the planner's assemble needs its parent where
    it was put (part_location), which an assembled bracket no longer has (a subassembly's
    location is not modelled), and the same insertion makes the pin's mate with the bracket."""
    links = _links(product)
    depth = {product.base: 0}
    queue = deque([product.base])
    while queue:
        p = queue.popleft()
        for q, _ in links[p]:
            if q not in depth:
                depth[q] = depth[p] + 1
                queue.append(q)
    loose = [p for p in product.parts if p not in depth]
    if loose:
        raise SparValueError(f"product {product.name}: parts mated with nothing that leads to the base "
                             f"{product.base}: {', '.join(loose)}")
    parents: dict[str, str] = {}
    for p in product.parts:
        if p == product.base:
            continue
        near = min((depth[q] for q, _ in links[p]))  # depth[p] - 1: the tree has no loop
        parents[p] = next(q for q, _ in links[p] if depth[q] == near)
    return parents


def _made_by(product: Product, parents: dict[str, str]) -> dict[str, list[Mate | Seat]]:
    """The part whose insertion makes each mate or seat: the child of a tree edge, else the
    part deeper in the tree (the later of the file's two for equals)."""
    def depth(p: str) -> int:
        n = 0
        while p != product.base:
            p, n = parents[p], n + 1
        return n
    order = list(product.parts)
    out: dict[str, list[Mate | Seat]] = {p: [] for p in parents}
    for lk in (*product.mates, *product.seats):
        a, b = (lk.peg, lk.hole) if isinstance(lk, Mate) else (lk.part, lk.on)
        if parents.get(a) == b:
            mover = a
        elif parents.get(b) == a:
            mover = b
        else:
            mover = max((a, b), key=lambda p: (depth(p), order.index(p)))
        out[mover].append(lk)
    return out


def compile_goals(product: Product) -> tuple[PartGoal, ...]:
    """One goal per non-base part (file order): into its parent, with the faces of the mates
    and seats between them, T_a from the product poses and V_a its insertion direction in the
    parent's frame. Every mate or seat the part's insertion makes must agree on the direction
    (SparValueError naming them otherwise)."""
    parents = _parents(product)
    made = _made_by(product, parents)
    goals = []
    for p, parent in parents.items():
        links = made[p]
        d = None
        for lk in links:
            dk = _direction(product, lk, p)
            if d is None:
                d, first = dk, lk
            elif float(dk @ d) < 1 - 1e-6:
                raise SparValueError(f"product {product.name}: {first.name} and {lk.name} are made by one insertion "
                                     f"of {p} but need different directions")
        own, other = [], []
        for lk in links:
            if isinstance(lk, Mate) and {lk.peg, lk.hole} == {p, parent}:
                pf = lk.peg_feature if lk.peg == p else lk.hole_feature
                qf = lk.hole_feature if lk.peg == p else lk.peg_feature
                own += list(product.parts[p].model.feature_named(pf).faces)
                other += list(product.parts[parent].model.feature_named(qf).faces)
            elif isinstance(lk, Seat) and {lk.part, lk.on} == {p, parent}:
                own.append(lk.face if lk.part == p else lk.on_face)
                other.append(lk.on_face if lk.part == p else lk.face)
        Tp, Tq = product.parts[p].pose, product.parts[parent].pose
        Ta = np.linalg.inv(Tq) @ Tp
        Va = Tq[:3, :3].T @ d
        goals.append(PartGoal(p, parent, tuple(dict.fromkeys(own)), tuple(dict.fromkeys(other)), Ta, Va,
                              f"trans_{p}", f"vec_{p}", tuple(lk.name for lk in links)))
    return tuple(goals)


# --------------------------------------------------------------------------- precedence


def _shrunk(s: Solid, m: float) -> Solid:
    """A solid shrunk by ``m`` on every side (a hull: its points pulled ``m`` toward their centre)."""
    if s.kind == "hull":
        c = s.points.mean(0)
        v = s.points - c
        n = np.linalg.norm(v, axis=1, keepdims=True)
        pts = c + v * np.clip(1 - m / np.maximum(n, 1e-300), 0.0, 1.0)
        return Solid("hull", pts.min(0), pts.max(0), 0.0, pts)
    lo, hi = s.lo + m, s.hi - m
    return Solid(s.kind, lo, hi, max(s.radius - m, 0.0), s.points)


def _feature_solid(model: "ObjectModel", f: "MatingFeature", unit: str) -> int | None:
    """The index of the cylinder solid that is peg feature ``f`` (its axis, radius), or None."""
    g = f.geometry
    tol = from_mm(unit, AXIS_TOL_MM) * 10
    for i, s in enumerate(model.shape):
        if (s.kind == "cylinder" and abs(s.radius - g.radius) < tol and abs(abs(g.direction[2]) - 1) < 1e-9
                and abs(g.origin[0]) < tol and abs(g.origin[1]) < tol):
            return i
    return None


def _solids_against(product: Product, p: str, q: str, unit: str) -> list[Solid] | None:
    """P's solids as tested against Q: without P's peg feature solids of mates with Q; None
    when such a peg is not a separate solid (the pair is not tested)."""
    model = product.parts[p].model
    drop = set()
    for m in product.mates:
        if m.peg == p and m.hole == q:
            i = _feature_solid(model, model.feature_named(m.peg_feature), unit)
            if i is None:
                return None
            drop.add(i)
    return [s for i, s in enumerate(model.shape) if i not in drop]


def _bodies(solids: list[Solid], T: np.ndarray, m: float) -> list:
    """Collision bodies of ``solids`` shrunk by ``m``, placed at ``T`` (product frame)."""
    from spar_py.world.collision import solid_bodies

    return [b.placed(T, b.frame) for b in solid_bodies("", [_shrunk(s, m) for s in solids])]


def _object(b) -> Any:
    """A placed convex body as a python-fcl collision object."""
    import fcl

    from spar_py.world.collision import _fcl_transform

    return fcl.CollisionObject(b.fcl_geometry(), _fcl_transform(b.T))


def _mesh_object(part) -> Any:
    """A mesh part's own triangle mesh at its product pose, as a python-fcl collision object
    (a mesh part's collision solid is its convex hull, which fills its holes and pockets)."""
    import fcl

    from spar_py.world.collision import _fcl_transform
    from spar_py.world.shapes import part_mesh

    mesh = part_mesh(part.model)
    bvh = fcl.BVHModel()
    bvh.beginModel(len(mesh.vertices), len(mesh.faces))
    bvh.addSubModel(np.asarray(mesh.vertices, float), np.asarray(mesh.faces, np.int32))
    bvh.endModel()
    return fcl.CollisionObject(bvh, _fcl_transform(part.pose))


def _collide_objects(a: Any, b: Any) -> bool:
    """Whether two python-fcl collision objects overlap."""
    import fcl

    return bool(fcl.collide(a, b, fcl.CollisionRequest(), fcl.CollisionResult()))


def _collide(a, b) -> bool:
    """Whether two placed convex bodies overlap (python-fcl)."""
    return _collide_objects(_object(a), _object(b))


def _swept(bodies: list, d: np.ndarray, travel: float) -> list:
    """Each body swept from ``travel`` back along ``d`` to where it is: the hull of both ends."""
    from spar_py.world.collision import WORLD, convex

    return [convex("", WORLD, np.concatenate([b.points, b.points - travel * d])) for b in bodies]


def _hit_feature(product: Product, p: str, q: str, swept: list) -> str | None:
    """The first feature of Q (file order of its model) whose volume P's sweep passes through,
    leaving out Q's features in mates with P (their overlap is the mate)."""
    from spar_py.world.collision import WORLD, cylinder

    part = product.parts[q]
    mated = {m.peg_feature if m.peg == q else m.hole_feature for m in product.mates if {m.peg, m.hole} == {p, q}}
    for f in part.model.features:
        if f.geometry is None or f.name in mated:
            continue
        ax = feature_axis(part.pose, f)
        body = cylinder("", WORLD, ax.origin, ax.end, ax.radius)
        if any(_collide(s, body) for s in swept):
            return f"{q}.{f.name}"
    return None


def precedence(product: Product, unit: str) -> tuple[Precedence, ...]:
    """The orderings the geometry forces (module docstring): Precedence(P, Q) when P's sweep
    from clear of everything to its seated pose passes through Q at its product pose. A
    cycle among them is a SparValueError naming the parts; so is a part blocked by the base
    (it can never be inserted)."""
    m = from_mm(unit, SWEEP_MARGIN_MM)
    goals = {g.part: g for g in product.goals}
    lo, hi = _extent(product)
    out: list[Precedence] = []
    for p, g in goals.items():
        Tq = product.parts[g.parent].pose
        d = Tq[:3, :3] @ g.V_a
        travel = float(np.abs(hi - lo) @ np.abs(d)) * 2 + from_mm(unit, 1.0)
        for q, part in product.parts.items():
            if q == p:
                continue
            mine = _solids_against(product, p, q, unit)
            if not mine:
                continue
            swept = _swept(_bodies(mine, product.parts[p].pose, m), d, travel)
            if part.model.geometry is not None and part.model.geometry.mesh_file is not None:
                others = [_mesh_object(part)]  # its own surface: its holes are cut
            else:
                theirs = _solids_against(product, q, p, unit)
                if not theirs:
                    continue
                others = [_object(o) for o in _bodies(theirs, part.pose, m)]
            if not any(_collide_objects(_object(s), o) for s in swept for o in others):
                continue
            what = _hit_feature(product, p, q, swept) or q
            if q == product.base:
                raise SparValueError(f"product {product.name}: {p}'s insertion passes through the base part {what}: "
                                     "it can never be inserted")
            out.append(Precedence(p, q, f"{p}'s insertion would pass through {what}"))
    _no_cycle(product, out)
    return tuple(out)


#: Parts nearer than this at their product poses are near by design (mm): a part's insertion
#: may bring it within the collision margin of them (:func:`near_parts`).
NEAR_MM = 10.0


def near_parts(product: Product, unit: str) -> dict[str, tuple[str, ...]]:
    """Each part's neighbours in the product: the parts whose solids come within NEAR_MM of its
    own at the product poses (a mesh part's solid is its convex hull: nearer, never farther).
    Phase 2 lets an insertion's held part touch them at its end-point (its product pose)."""
    from spar_py.world.collision import _exact

    gap = from_mm(unit, NEAR_MM)
    bodies = {p: _bodies(list(part.model.shape), part.pose, 0.0) for p, part in product.parts.items()}
    out: dict[str, list[str]] = {p: [] for p in product.parts}
    names = list(product.parts)
    eye = np.eye(4)
    for i, p in enumerate(names):
        for q in names[i + 1:]:
            if any(_exact(a, eye, b, eye) < gap for a in bodies[p] for b in bodies[q]):
                out[p].append(q)
                out[q].append(p)
    return {p: tuple(qs) for p, qs in out.items()}


def _extent(product: Product) -> tuple[np.ndarray, np.ndarray]:
    """The bounding box of every part's solids at its product pose (product frame)."""
    pts = [np.zeros(3)]
    for part in product.parts.values():
        for s in part.model.shape:
            c = s.points if s.points is not None else np.array(
                [[x, y, z] for x in (s.lo[0], s.hi[0]) for y in (s.lo[1], s.hi[1]) for z in (s.lo[2], s.hi[2])])
            pts.append(c @ part.pose[:3, :3].T + part.pose[:3, 3])
    allp = np.vstack(pts)
    return allp.min(0), allp.max(0)


def _no_cycle(product: Product, prec: list[Precedence]) -> None:
    """SparValueError naming the parts of a cycle among the orderings, if there is one."""
    succ: dict[str, list[str]] = {}
    for pr in prec:
        succ.setdefault(pr.first, []).append(pr.then)
    state: dict[str, int] = {}

    def visit(p: str, path: list[str]) -> None:
        state[p] = 1
        for q in succ.get(p, []):
            if state.get(q) == 1:
                loop = path[path.index(q):] + [q] if q in path else [p, q]
                raise SparValueError(f"product {product.name}: the parts block each other's insertions in a cycle "
                                     f"({' before '.join(loop)})")
            if q not in state:
                visit(q, path + [q])
        state[p] = 2
    for p in list(succ):
        if p not in state:
            visit(p, [p])
