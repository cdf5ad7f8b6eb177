"""Products: parts at their poses in the product frame, their mates and seats, the assembly
tree, the goals it compiles to, and precedence from geometry (swept insertions).

Frames: a part's pose is T_product_part (4x4, column vectors); a feature's origin and
direction are in its part's frame. Units: the cell unit throughout (the product file's
lengths converted at load).

- :func:`mate_misalignment`: whether a mate's features line up (coaxial within the clearance,
  overlapping); :func:`axis_offset`, how far off centre the peg is.
- :func:`compile_goals`: the assembly tree rooted at the base part and one
  :class:`~spar_py.core.model.PartGoal` per other part (T_a = T_parent^-1 T_part, V_a the
  insertion direction in the parent's frame), the parent the nearest ancestor not known to
  be in place before the part (:func:`goal_parents`).
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
from collections.abc import Collection, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from spar_py.core.errors import SparValueError
from spar_py.core.model import Grasp, Mate, PartGoal, Precedence, Product, Seat, Solid
from spar_py.core.units import from_mm

if TYPE_CHECKING:
    from spar_py.core.model import MatingFeature, ObjectModel

__all__ = ["AXIS_TOL_MM", "NEAR_MM", "SUB", "SWEEP_MARGIN_MM", "VIA", "Axis", "SubPose", "axis_offset", "compile_goals",
           "feature_axis", "goal_parents", "insertion_directions", "insertion_pairs", "link_directions", "makers",
           "mate_misalignment", "near_parts", "no_cycle", "precedence", "resting_faces", "seat_direction",
           "subassembly_poses", "through_precedence", "unmakeable",
           "subtree", "via_grasps"]

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


def axis_offset(peg: Axis, hole: Axis) -> float:
    """How far the peg's axis passes from the hole's, across the hole's axis, at the peg's root
    (the mate's units): the nominal peg sits off centre by this, and its margin R_hole - R_peg
    is less by as much."""
    d = hole.direction
    off = peg.origin - hole.origin
    return float(np.linalg.norm(off - (off @ d) * d))


def mate_misalignment(peg: Axis, hole: Axis, through: bool, unit: str) -> str | None:
    """Why a peg's axis and a hole's do not line up (None if they do): the angle between
    them, the peg axis's offset from the hole's (:func:`axis_offset`) when it is not within the
    clearance R_hole - R_peg (beyond AXIS_TOL_MM: a peg off centre but clear of the wall fits,
    with that much less margin), or their lengths not overlapping along it. The peg enters the
    hole along the hole's direction, or either way through a through hole."""
    cos = float(peg.direction @ hole.direction)
    if not (cos > math.cos(math.radians(AXIS_TOL_DEG)) or (through and -cos > math.cos(math.radians(AXIS_TOL_DEG)))):
        return f"axes {math.degrees(math.acos(max(-1.0, min(1.0, cos)))):.3g} deg apart"
    d = hole.direction
    off = peg.origin - hole.origin
    radial = axis_offset(peg, hole)
    margin = hole.radius - peg.radius
    if radial > from_mm(unit, AXIS_TOL_MM) and radial >= margin:
        return (f"axes {radial:.4g} {unit} apart, as much as the clearance R_hole - R_peg = {margin:.4g} {unit} "
                f"or more (the peg in the hole's wall)")
    p0, p1 = sorted((float(off @ d), float((peg.end - hole.origin) @ d)))
    if min(p1, hole.length) - max(p0, 0.0) <= 0:
        return (f"no overlap along the axis (peg from {p0:.4g} to {p1:.4g} {unit}, hole from 0 to "
                f"{hole.length:.4g} {unit} from its mouth)")
    return None


def seat_direction(product: Product, seat: Seat) -> np.ndarray:
    """The direction (product frame, unit) the seated part moves to its seat: a curved seat's
    own ``direction``; else into the planar surface it rests on, against that face's outward
    normal."""
    from spar_py.world.parts import part_mesh

    if seat.direction is not None:
        d = np.asarray(seat.direction, float)
        return d / np.linalg.norm(d)
    part = product.parts[seat.on]
    mesh = part_mesh(part.model)
    if mesh is None:
        raise SparValueError(f"seat {seat.name}: {seat.on} needs a shape (mesh: or shape:) for its face normal")
    n = _face_normal(part.model, seat.on_face)
    return -(part.pose[:3, :3] @ n)


def _face_normal(model: "ObjectModel", face: str) -> np.ndarray:
    """The outward normal of a planar face of a part's shape (object frame, unit)."""
    from spar_py.world.parts import derive_faces, part_mesh

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


def link_directions(product: Product, link: Mate | Seat, mover: str) -> list[np.ndarray]:
    """The directions (product frame, unit) ``mover`` (one of ``link``'s two parts) may move along
    to make ``link``: the peg toward its tip; the hole part against it, or either way when the
    hole is through (it slides over a peg from the peg's root end: a dowel standing in a base
    takes a plate coming down over it); a seat's part into its seat, the part it rests on the
    opposite way."""
    d = _direction(product, link, mover)
    if isinstance(link, Mate) and mover == link.hole:
        f = product.parts[link.hole].model.feature_named(link.hole_feature)
        if f.through or (f.geometry is not None and f.geometry.through):
            return [d, -d]
    return [d]


def _agrees(d: np.ndarray, allowed: Sequence[np.ndarray]) -> bool:
    """Whether direction ``d`` is one of ``allowed`` (unit vectors, within 1e-6)."""
    return any(float(a @ d) > 1 - 1e-6 for a in allowed)


def insertion_directions(product: Product, parents: dict[str, str] | None = None,
                         given: dict[str, np.ndarray] | None = None) -> dict[str, np.ndarray]:
    """Each non-base part's insertion direction (product frame, unit): one the link to its tree
    parent (:func:`_parents`; its first in file order) allows, the one most of the part's links
    with parts no deeper in the tree allow (those it may be inserted after: a cover over two
    shafts and four dowels through holes comes down, as both shafts need; a collar that will
    rest on a bushing later has no say in the bushing's way), ties to the first allowed (for a
    hole part, against the peg: the way it was always taken). ``given``: directions known
    otherwise (a derived product's disassembly), which win where given."""
    parents = _parents(product) if parents is None else parents
    links = _links(product)

    def depth(p: str) -> int:
        n = 0
        while p in parents:
            p, n = parents[p], n + 1
        return n
    out: dict[str, np.ndarray] = {}
    for p, parent in parents.items():
        own = [lk for q, lk in links[p] if depth(q) <= depth(p)]
        tree = next(lk for q, lk in links[p] if q == parent)
        cands = link_directions(product, tree, p)
        out[p] = max(cands, key=lambda d: sum(_agrees(d, link_directions(product, lk, p)) for lk in own))
    for p, d in (given or {}).items():
        if p in out:
            out[p] = np.asarray(d, float) / np.linalg.norm(d)
    return out


def makers(product: Product, parents: dict[str, str] | None = None,
           dirs: dict[str, np.ndarray] | None = None) -> dict[str, tuple[str, ...]]:
    """For each mate and seat (by name), the parts whose own insertion can make it: of its two
    parts, those not the base whose insertion direction (:func:`insertion_directions`) the link
    allows. Which one does in a plan is the order's: the later of the two (a pin set into the
    housing first makes its housing mate; the cover coming down over it later makes the cover's).
    A mate neither part can make is made, if at all, when a subassembly carrying one of them
    goes in (:func:`unmakeable`)."""
    parents = _parents(product) if parents is None else parents
    dirs = insertion_directions(product, parents) if dirs is None else dirs
    out: dict[str, tuple[str, ...]] = {}
    for lk in (*product.mates, *product.seats):
        pair = lk.ends
        out[lk.name] = tuple(p for p in pair if p in dirs and _agrees(dirs[p], link_directions(product, lk, p)))
    return out


def unmakeable(product: Product, parents: dict[str, str] | None = None,
               dirs: dict[str, np.ndarray] | None = None) -> list[str]:
    """The mates and seats no insertion in any order can make: neither part's own insertion, nor
    that of a subassembly carrying one part and not the other (an ancestor in the assembly tree
    below both parts' common ancestor, moving along its own direction with the part riding on it),
    moves that part the way the link allows."""
    parents = _parents(product) if parents is None else parents
    dirs = insertion_directions(product, parents) if dirs is None else dirs

    def chain(p: str) -> list[str]:
        out = [p]
        while out[-1] in parents:
            out.append(parents[out[-1]])
        return out
    bad = []
    for lk in (*product.mates, *product.seats):
        a, b = lk.ends
        ca_, cb = chain(a), chain(b)
        common = next(x for x in ca_ if x in cb)
        ok = False
        for side, ch in ((a, ca_), (b, cb)):
            for mover in ch[:ch.index(common)]:  # the side's part and its ancestors below the common one
                # a subassembly keeps its parts' product-relative poses: one frame for every direction
                ok = ok or _agrees(dirs[mover], link_directions(product, lk, side))
        if not ok:
            bad.append(lk.name)
    return bad


def compile_goals(product: Product, first: Collection[tuple[str, str]] = (),
                  directions: dict[str, np.ndarray] | None = None) -> tuple[PartGoal, ...]:
    """One goal per non-base part (file order): into its goal parent (:func:`goal_parents`),
    along its insertion direction (:func:`insertion_directions`), with the part's faces of the
    mates and seats its insertion can make (:func:`makers`) with that parent and the parts
    between them and the parent's faces of those with it, T_a from the product poses and V_a the
    direction in the goal parent's frame; ``mates`` the names of the mates and seats the
    insertion can make (which it does make in a plan is the order's: phase2.mates). ``first``
    the pairs (A, B) with A in place before B is inserted;
    ``directions`` a derived product's insertion directions (its disassembly's, product frame),
    which win. A product whose mates cannot all be made by any order is a SparValueError naming
    them."""
    parents = _parents(product)
    dirs = insertion_directions(product, parents, directions)
    bad = unmakeable(product, parents, dirs)
    if bad:
        raise SparValueError(f"product {product.name}: no order of insertions makes {', '.join(bad)} (each "
                             "part's insertion goes the way its mate with the part nearer the base needs, "
                             "and neither part of these goes the way they need)")
    can = makers(product, parents, dirs)
    links = _links(product)
    into = goal_parents(product, first)
    goals = []
    for p in parents:
        made = [lk for _, lk in links[p] if p in can[lk.name]]
        parent = into[p]
        chain = set(_ancestors(parents, p, parent))
        own, other = [], []
        for lk in made:
            a, b = lk.ends
            q = b if a == p else a
            if q not in chain:
                continue
            if isinstance(lk, Mate):
                pf, qf = (lk.peg_feature, lk.hole_feature) if lk.peg == p else (lk.hole_feature, lk.peg_feature)
                own += list(product.parts[p].model.feature_named(pf).faces)
                if q == parent:
                    other += list(product.parts[parent].model.feature_named(qf).faces)
            else:
                own.append(lk.face if lk.part == p else lk.on_face)
                if q == parent:
                    other.append(lk.on_face if lk.part == p else lk.face)
        Tp, Tq = product.parts[p].pose, product.parts[parent].pose
        Ta = np.linalg.inv(Tq) @ Tp
        Va = Tq[:3, :3].T @ dirs[p]
        goals.append(PartGoal(p, parent, tuple(dict.fromkeys(own)), tuple(dict.fromkeys(other)), Ta, Va,
                              f"trans_{p}", f"vec_{p}", tuple(dict.fromkeys(lk.name for lk in made))))
    return tuple(goals)


def _ancestors(parents: dict[str, str], p: str, upto: str) -> list[str]:
    """P's ancestors in the assembly tree from its parent up to ``upto`` (included)."""
    out = [parents[p]]
    while out[-1] != upto:
        out.append(parents[out[-1]])
    return out


def goal_parents(product: Product, first: Collection[tuple[str, str]] = ()) -> dict[str, str]:
    """Each non-base part's goal parent: the part its insertion goes into, the one that still
    has a location where it was put when the part is inserted. That is its tree parent
    (:func:`_parents`) unless the parent is known to be in place first (``first`` holds
    (parent, part)): an assembled part has no location of its own (its pickup deleted it), so
    the goal goes up the tree, through each ancestor known to be in place before the part, to
    the first one that is not (or the base). T_a is then relative to that part, and phase 2
    checks the insertion against the carried part it mates with at its composed pose."""
    parents = _parents(product)
    known = set(first)
    out: dict[str, str] = {}
    for p, a in parents.items():
        while a != product.base and (a, p) in known:
            a = parents[a]
        out[p] = a
    return out


def through_precedence(product: Product, first: Collection[tuple[str, str]] = ()) -> tuple[Precedence, ...]:
    """The orderings a goal into an ancestor beyond its tree parent relies on
    (:func:`goal_parents`): each part between the goal parent and the part is inserted first."""
    parents = _parents(product)
    into = goal_parents(product, first)
    out = []
    for p, q in into.items():
        for a in _ancestors(parents, p, q)[:-1]:
            out.append(Precedence(a, p, f"{p} goes into {q} with {a} in place (it mates with {parents[p]})"))
    return tuple(out)


def insertion_pairs(insertions: Sequence[Sequence[str]]) -> tuple[tuple[str, str], ...]:
    """The pairs (A, B) of an insertion order (groups of parts inserted together, in order)
    with A's group before B's: A is in place before B is inserted."""
    return tuple((a, b) for i, ga in enumerate(insertions) for gb in insertions[i + 1:] for a in ga for b in gb)


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
    """P's solids as tested against Q: without P's peg feature solids of mates with Q, nor P's
    other cylinders on that peg's axis thin enough to pass through Q's hole (a stepped shaft's
    thinner end goes through the gear slid onto its middle: primitive shapes do not cut their
    holes, so Q's solid fills that hole); None when such a peg is not a separate solid (the pair
    is not tested)."""
    model = product.parts[p].model
    tol = from_mm(unit, AXIS_TOL_MM) * 10
    drop = set()
    for m in product.mates:
        if m.peg == p and m.hole == q:
            f = model.feature_named(m.peg_feature)
            i = _feature_solid(model, f, unit)
            if i is None:
                return None
            drop.add(i)
            r_hole = float(product.parts[q].model.feature_named(m.hole_feature).radius)
            drop |= {k for k, sk in enumerate(model.shape) if sk.kind == "cylinder" and sk.radius <= r_hole + tol}
    return [s for i, s in enumerate(model.shape) if i not in drop]


def _bodies(solids: list[Solid], T: np.ndarray, m: float) -> list:
    """Collision bodies of ``solids`` shrunk by ``m``, placed at ``T`` (product frame)."""
    from spar_py.world.collision import solid_bodies

    return [b.placed(T, b.frame) for b in solid_bodies("", [_shrunk(s, m) for s in solids])]


def _object(b) -> Any:
    """A placed convex body as a python-fcl collision object."""
    import fcl

    from spar_py.world.collision import fcl_transform

    return fcl.CollisionObject(b.fcl_geometry(), fcl_transform(b.T))


def _mesh_object(part) -> Any:
    """A mesh part's own triangle mesh at its product pose, as a python-fcl collision object
    (a mesh part's collision solid is its convex hull, which fills its holes and pockets)."""
    import fcl

    from spar_py.world.collision import fcl_transform
    from spar_py.world.parts import part_mesh

    mesh = part_mesh(part.model)
    bvh = fcl.BVHModel()
    bvh.beginModel(len(mesh.vertices), len(mesh.faces))
    bvh.addSubModel(np.asarray(mesh.vertices, float), np.asarray(mesh.faces, np.int32))
    bvh.endModel()
    return fcl.CollisionObject(bvh, fcl_transform(part.pose))


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
    boxes = {q: _part_box(part) for q, part in product.parts.items()}
    meshes: dict[str, Any] = {}  # a mesh part's fcl object, built once
    solids: dict[tuple[str, str], list] = {}  # (part, against) -> its fcl objects, built once
    out: list[Precedence] = []
    for p, g in goals.items():
        Tq = product.parts[g.parent].pose
        d = Tq[:3, :3] @ g.V_a
        travel = float(np.abs(hi - lo) @ np.abs(d)) * 2 + from_mm(unit, 1.0)
        blo, bhi = boxes[p]
        # the box the sweep stays in: P's box from where it starts to where it seats
        slo, shi = np.minimum(blo, blo - travel * d), np.maximum(bhi, bhi - travel * d)
        if _is_mesh(product.parts[p]):
            # a mesh part's convex hull would fill its bores: its own mesh, stepped
            # a hole part P's peg goes into whose model does not cut its holes (the paper's form:
            # a solid block) would meet P at the mate itself: left out, as the solids' test does
            uncut = {mt.hole for mt in product.mates if mt.peg == p and not _holes_cut(product.parts[mt.hole])}
            hits = _mesh_sweep(product, p, d, m, unit, [q for q in product.parts
                                                        if q != p and q not in uncut
                                                        and _boxes_meet(slo, shi, *boxes[q])])
            for q in (q for q in product.parts if q in hits):
                _blocked(product, p, q, out, lambda: _hit_feature(product, p, q, _swept(
                    _bodies(list(product.parts[p].model.shape), product.parts[p].pose, m), d, travel)))
            continue
        for q, part in product.parts.items():
            if q == p or not _boxes_meet(slo, shi, *boxes[q]):
                continue  # the sweep's box misses Q's: no collision test can find one
            mine = _solids_against(product, p, q, unit)
            if not mine:
                continue
            swept = _swept(_bodies(mine, product.parts[p].pose, m), d, travel)
            if part.model.geometry is not None and part.model.geometry.mesh_file is not None:
                if q not in meshes:
                    meshes[q] = _mesh_object(part)  # its own surface: its holes are cut
                others = [meshes[q]]
            else:
                if (q, p) not in solids:
                    theirs = _solids_against(product, q, p, unit)
                    solids[q, p] = [_object(o) for o in _bodies(theirs, part.pose, m)] if theirs else []
                others = solids[q, p]
                if not others:
                    continue
            if not any(_collide_objects(_object(s), o) for s in swept for o in others):
                continue
            _blocked(product, p, q, out, lambda: _hit_feature(product, p, q, swept))
    no_cycle(product, out)
    return tuple(out)


def _blocked(product: Product, p: str, q: str, out: list[Precedence], feature: Any) -> None:
    """Record that P's insertion passes through Q (``feature()``: the feature of Q it passes
    through, or None); SparValueError if Q is the base part (P could never be inserted)."""
    what = feature() or q
    if q == product.base:
        raise SparValueError(f"product {product.name}: {p}'s insertion passes through the base part {what}: "
                             "it can never be inserted")
    out.append(Precedence(p, q, f"{p}'s insertion would pass through {what}"))


def _holes_cut(part: Any) -> bool:
    """Whether a part's mesh has its holes: a mesh part, or primitives with a subtracted one."""
    g = part.model.geometry
    return g is not None and (g.mesh_file is not None or any(pr.subtract for pr in g.primitives))


def _is_mesh(part: Any) -> bool:
    """Whether a product part's model is a mesh (its collision solid a convex hull)."""
    return part.model.geometry is not None and part.model.geometry.mesh_file is not None


def _mesh_sweep(product: Product, p: str, d: np.ndarray, m: float, unit: str, others: list[str]) -> set[str]:
    """The parts of ``others`` that mesh part P's own mesh (shrunk by ``m``) meets on its way out
    of its product pose against ``d`` (the insertion reversed), in steps no longer than the
    product's smallest mate clearance (at least 0.1 mm); every part as its mesh at its pose."""
    from spar_py.world.product.assembly import Sweeper
    from spar_py.world.parts import part_mesh

    if not others:
        return set()
    clear = [f_h.radius - f_p.radius for mt in product.mates
             for f_p, f_h in [(product.parts[mt.peg].model.feature_named(mt.peg_feature),
                               product.parts[mt.hole].model.feature_named(mt.hole_feature))]]
    step = max(min(clear, default=from_mm(unit, 1.0)), from_mm(unit, 0.1))
    meshes = {}
    for q in [p, *others]:
        mesh = part_mesh(product.parts[q].model)
        if mesh is None:
            continue
        meshes[q] = mesh.copy()
        meshes[q].apply_transform(product.parts[q].pose)
    return Sweeper(meshes, m, step).hits((p,), -d, [q for q in others if q in meshes], first_only=False)


#: Parts nearer than this at their product poses are near by design (mm): a part's insertion
#: may bring it within the collision margin of them (:func:`near_parts`).
NEAR_MM = 10.0


def near_parts(product: Product, unit: str) -> dict[str, tuple[str, ...]]:
    """Each part's neighbours in the product: the parts whose solids come within NEAR_MM of its
    own at the product poses (a mesh part's solid is its convex hull: nearer, never farther).
    Phase 2 lets an insertion's held part touch them at its end-point (its product pose)."""
    from spar_py.world.collision import body_distance

    gap = from_mm(unit, NEAR_MM)
    bodies = {p: _bodies(list(part.model.shape), part.pose, 0.0) for p, part in product.parts.items()}
    out: dict[str, list[str]] = {p: [] for p in product.parts}
    names = list(product.parts)
    eye = np.eye(4)
    boxes = {p: _part_box(part) for p, part in product.parts.items()}
    for i, p in enumerate(names):
        for q in names[i + 1:]:
            if not _boxes_meet(*boxes[p], *boxes[q], gap):
                continue  # farther apart than the gap already by their boxes
            if any(body_distance(a, eye, b, eye) < gap for a in bodies[p] for b in bodies[q]):
                out[p].append(q)
                out[q].append(p)
    return {p: tuple(qs) for p, qs in out.items()}


def _part_box(part: Any) -> tuple[np.ndarray, np.ndarray]:
    """The bounding box (lo, hi) of a part's solids at its product pose (product frame)."""
    pts = [np.asarray(s.points, float) if s.points is not None else np.array(
        [[x, y, z] for x in (s.lo[0], s.hi[0]) for y in (s.lo[1], s.hi[1]) for z in (s.lo[2], s.hi[2])])
        for s in part.model.shape]
    if not pts:
        return part.pose[:3, 3].copy(), part.pose[:3, 3].copy()
    allp = np.vstack(pts) @ part.pose[:3, :3].T + part.pose[:3, 3]
    return allp.min(0), allp.max(0)


def _boxes_meet(alo: np.ndarray, ahi: np.ndarray, blo: np.ndarray, bhi: np.ndarray, gap: float = 0.0) -> bool:
    """Whether two axis-aligned boxes come within ``gap`` of each other."""
    return bool(np.all(alo <= bhi + gap) and np.all(blo <= ahi + gap))


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


def no_cycle(product: Product, prec: Sequence[Precedence]) -> None:
    """SparValueError naming a cycle among the orderings, if there is one: each ordering of it
    and why it holds (``a before b (the product file orders them), b before a (...)``)."""
    succ: dict[str, list[str]] = {}
    for pr in prec:
        succ.setdefault(pr.first, []).append(pr.then)
    state: dict[str, int] = {}

    def visit(p: str, path: list[str]) -> None:
        state[p] = 1
        for q in succ.get(p, []):
            if state.get(q) == 1:
                loop = path[path.index(q):] + [q] if q in path else [p, q]
                why = {(pr.first, pr.then): pr.reason for pr in prec}
                said = ", ".join(f"{a} before {b} ({why[a, b]})" for a, b in zip(loop, loop[1:]))
                raise SparValueError(f"product {product.name}: the orderings form a cycle: {said}")
            if q not in state:
                visit(q, path + [q])
        state[p] = 2
    for p in list(succ):
        if p not in state:
            visit(p, [p])


#: What joins a part's name and a carried part's grasp label in a via-grasp's label
#: (``block_via_pin_a_G3``).
VIA = "_via_"


def subtree(product: Product, part: str) -> list[str]:
    """The parts that can be mated into ``part``, directly or through others (its descendants in
    the assembly tree of the product's goals), breadth first, file order within a level."""
    children: dict[str, list[str]] = {}
    for g in product.goals:
        children.setdefault(g.parent, []).append(g.part)
    out, queue = [], deque(children.get(part, ()))
    while queue:
        c = queue.popleft()
        out.append(c)
        queue.extend(children.get(c, ()))
    return out


def _euler_zyz(T: np.ndarray) -> tuple[float, float, float, float, float, float]:
    """(X, Y, Z, phi, theta, psi) of T = trans(X, Y, Z) rotz(phi) roty(theta) rotz(psi) (radians;
    phi = 0 where theta is 0 or pi and only phi + psi or phi - psi is defined)."""
    R = np.asarray(T, float)[:3, :3]
    s = math.hypot(R[0, 2], R[1, 2])
    theta = math.atan2(s, R[2, 2])
    if s > 1e-9:
        phi, psi = math.atan2(R[1, 2], R[0, 2]), math.atan2(R[2, 1], -R[2, 0])
    else:
        # theta 0: R = rotz(psi); theta pi: R = roty(pi) rotz(psi), whose column 1 is (s, c, 0)
        phi, psi = 0.0, math.atan2(R[1, 0], R[0, 0]) if R[2, 2] > 0 else math.atan2(R[1, 0], R[1, 1])
    return (float(T[0, 3]), float(T[1, 3]), float(T[2, 3]), phi, theta, psi)


def via_grasps(product: Product) -> dict[str, dict[str, tuple[str, Grasp]]]:
    """For each part with parts that can be mated into it, the grasps of those parts in its
    frame: {part: {label: (carried part, grasp)}}, each grasp T_G' = T_rel T_G with T_rel the
    carried part's product pose relative to the part's (T_part^-1 T_child), labelled
    ``PART_via_LABEL`` after the carried part's own label; its faces and width are the carried
    part's grasp's (the fingers hold that part). Such a grasp holds the body only while it
    carries that part (phase 2 refuses it otherwise)."""
    out: dict[str, dict[str, tuple[str, Grasp]]] = {}
    for name, pp in product.parts.items():
        inv_p = np.linalg.inv(pp.pose)
        got: dict[str, tuple[str, Grasp]] = {}
        for c in subtree(product, name):
            T_rel = inv_p @ product.parts[c].pose
            for g in product.parts[c].model.grasps.values():
                label = f"{name}{VIA}{g.label}"
                T = T_rel @ g.T
                got[label] = (c, Grasp(label, g.gfaces, g.ofaces, _euler_zyz(T), g.width, T))
        if got:
            out[name] = got
    return out


#: What joins a part's name and a subassembly's stable pose number (``block_sub_p1``).
SUB = "_sub_p"
#: Subassembly stable poses less probable than this (trimesh's quasi-static estimate, summed
#: over the poses merged into it) are left out.
SUB_PROB_FLOOR = 0.02
#: At most this many subassembly stable poses per part, the most probable first.
SUB_POSES_MAX = 4
#: Stable poses whose down directions differ by less than this (degrees) are one pose, the
#: most probable of them standing for all (a mesh's facets split one rest into several).
SUB_MERGE_DEG = 5.0
#: A part touches the table in a subassembly's rest when within this fraction of the root's size.
CONTACT_EPS = 1e-6


#: Bumped whenever subassembly_poses's results change for the same inputs (part of its cache key).
SUB_VERSION = 1


@dataclass(frozen=True)
class SubPose:
    """A stable pose of a part with its whole product subtree mated into it (the union of their
    shapes at their product poses): ``label`` (``PART_sub_pK``), ``R`` the part's orientation
    (3x3, world), ``height`` the part's frame's height above the table (cell unit), ``prob``
    trimesh's estimate of how often it lands so (summed over the poses merged into it),
    ``rfaces`` the part's own faces touching the table there (:func:`resting_faces`)."""

    label: str
    R: np.ndarray
    height: float
    prob: float
    rfaces: tuple[str, ...] = ()


def subassembly_poses(product: Product, unit: str, use_cache: bool = True) -> dict[str, list[SubPose]]:
    """For each part with a product subtree, the stable poses of the union of its shape and its
    subtree's at their product poses, in the part's frame: trimesh
    compute_stable_poses on the union's convex hull about the union's centre of mass, keeping
    those where a subtree part touches the table (the rest is a face of the union's hull, so a
    part on it touches it exactly: within CONTACT_EPS of the root's size; else the root carries
    the body alone) in a down direction none of the part's own poses has, merged within
    SUB_MERGE_DEG, the most probable SUB_POSES_MAX above SUB_PROB_FLOOR, labelled
    ``PART_sub_p1, ...``, with the part's faces resting on the table in each. Parts without a
    shape (or with a subtree part without one) are left out. Kept on disk by content
    (:func:`_sub_key`): a hit builds no mesh."""
    out: dict[str, list[SubPose]] = {}
    for name, pp in product.parts.items():
        kids = subtree(product, name)
        if not kids or any(product.parts[p].model.geometry is None for p in (name, *kids)):
            continue
        got = _sub_poses_cached(product, name, kids, unit, use_cache)
        if got:
            out[name] = got
    return out


def _sub_key(product: Product, name: str, kids: list[str], unit: str) -> str:
    """SHA-256 of everything a part's subassembly poses depend on: SUB_VERSION, the derivation
    modules' source (faces), the selection constants, the cell unit, the part's own poses'
    down directions and, for the part and each subtree part, its name, its geometry's content,
    features and face names and its pose relative to the part."""
    import hashlib
    import json

    from spar_py.world.parts import source_digest
    from spar_py.world.reach import REST_TOL_MM

    pp = product.parts[name]
    inv_p = np.linalg.inv(pp.pose)
    owned = sorted([round(float(v), 9) for v in np.asarray(p.R, float)[2]]
                   for k, p in pp.model.poses.items() if SUB not in k)
    data: list[Any] = [SUB_VERSION, source_digest(), SUB_PROB_FLOOR, SUB_POSES_MAX, SUB_MERGE_DEG, CONTACT_EPS,
                       REST_TOL_MM, unit, name, owned]
    for p in (name, *kids):
        g = product.parts[p].model.geometry
        data.append([p, g.digest(), [f.geometry.spec() for f in product.parts[p].model.features
                                      if f.geometry is not None],
                     sorted((k, [round(float(v), 12) for v in pt]) for k, pt in g.face_names.items()),
                     [round(float(v), 9) for v in (inv_p @ product.parts[p].pose).ravel()]])
    return hashlib.sha256(json.dumps(data).encode()).hexdigest()


def _sub_poses_cached(product: Product, name: str, kids: list[str], unit: str, use_cache: bool) -> list[SubPose]:
    """Part ``name``'s subassembly poses, from the derivations' cache directory
    (world.parts.cache.cache_dir, ``subposes-KEY.json``) when it has them, else computed and kept."""
    from spar_py.world.parts import cache_dir, load_derivation, store_derivation

    key = _sub_key(product, name, kids, unit)
    path = cache_dir() / f"subposes-{key}.json"
    if use_cache and (data := load_derivation(path, key)) is not None:
        try:
            return [SubPose(d["label"], np.asarray(d["R"], float).reshape(3, 3), float(d["height"]),
                            float(d["probability"]), tuple(d["rfaces"])) for d in data["poses"]]
        except (KeyError, TypeError, ValueError):
            pass  # an entry of an older form: computed again
    got = _sub_poses(product, name, kids, unit)
    if use_cache:
        store_derivation(path, {"key": key, "poses": [{"label": sp.label, "R": [float(v) for v in sp.R.ravel()],
                                             "height": sp.height, "probability": sp.prob,
                                             "rfaces": list(sp.rfaces)} for sp in got]})
    return got


def _sub_poses(product: Product, name: str, kids: list[str], unit: str) -> list[SubPose]:
    """Part ``name``'s subassembly poses computed (:func:`subassembly_poses`)."""
    from spar_py.world.parts import part_mesh

    pp = product.parts[name]
    own = part_mesh(pp.model)
    inv_p = np.linalg.inv(pp.pose)
    meshes = [own.copy()]
    for c in kids:
        meshes.append(part_mesh(product.parts[c].model).copy().apply_transform(inv_p @ product.parts[c].pose))
    owned = [np.asarray(p.R, float)[2] for k, p in pp.model.poses.items() if SUB not in k]
    got = _sub_rests(meshes, owned, CONTACT_EPS * float(np.ptp(own.vertices, axis=0).max()))
    return [SubPose(f"{name}{SUB}{i}", R, h, p, resting_faces(pp.model, R, h, unit))
            for i, (R, h, p) in enumerate(got, 1)]


def _sub_rests(meshes: list, owned: list[np.ndarray], tol: float) -> list[tuple[np.ndarray, float, float]]:
    """The selected stable rests (R, height, summed probability) of the rigid union of
    ``meshes`` (the root's first, all in the root's frame), as :func:`subassembly_poses` says."""
    import trimesh  # a derivation only

    from spar_py.world.parts import stable_poses

    union = trimesh.util.concatenate(meshes)
    com = np.sum([m.center_mass * m.volume for m in meshes], axis=0) / sum(m.volume for m in meshes)
    Ts, probs = stable_poses(union.convex_hull, com)
    cos_merge = np.cos(np.radians(SUB_MERGE_DEG))
    rests: list[list] = []  # [R, height, prob], most probable first
    for T, p in sorted(zip(Ts, probs), key=lambda tp: -tp[1]):
        R = np.asarray(T, float)[:3, :3]
        if any(np.allclose(R[2], r, atol=1e-6) for r in owned):
            continue
        height = -float((union.vertices @ R.T)[:, 2].min())
        if min(float((m.vertices @ R[2]).min()) for m in meshes[1:]) + height > tol:
            continue  # the subtree is off the table: the root rests on itself alone
        same = next((r for r in rests if float(r[0][2] @ R[2]) >= cos_merge), None)
        if same is not None:
            same[2] += float(p)
            continue
        rests.append([R, height, float(p)])
    rests.sort(key=lambda r: -r[2])
    return [(R, h, p) for R, h, p in rests if p >= SUB_PROB_FLOOR][:SUB_POSES_MAX]


def resting_faces(model: ObjectModel, R: np.ndarray, height: float, unit: str) -> tuple[str, ...]:
    """The names of the faces of ``model``'s shape (as its derivation names them) that touch the
    table when the part is turned by R (3x3) with its frame ``height`` above the table (cell
    unit): a vertex of the face within REST_TOL_MM of it."""
    from spar_py.world.parts import derive_faces, part_mesh
    from spar_py.world.reach import REST_TOL_MM

    mesh = part_mesh(model)
    if mesh is None or model.geometry is None:
        return ()
    feats = tuple(f.geometry for f in model.features if f.geometry is not None)
    faces = derive_faces(mesh, feats, dict(model.geometry.face_names), model.geometry.unit)
    z = (np.asarray(mesh.vertices, float) @ np.asarray(R, float).T)[:, 2] + height
    low = z[mesh.faces] <= from_mm(unit, REST_TOL_MM)  # (triangles, 3)
    return tuple(f.name for f in faces if low[f.tris].any())
