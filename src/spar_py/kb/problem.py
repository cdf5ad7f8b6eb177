"""Problem assembly: ``kb/problems/*.yaml`` with the robot and object files it names, to a
:class:`~spar_py.core.model.Cell`.

Objects and their initial positions, uncertainty bounds, sensors, goals (parsed to term
data and checked against the cell; ``assembled(Peg, Hole)`` and ``mated(Peg, PegFeature,
Hole, HoleFeature)`` completed from the features' geometry; every mate checked: clearance,
the peg's tip on the hole's axis), placement regions, obstacles, the table and the switches; the loaded cell is
checked for physical sanity (kb.sanity) last. Lengths in the problem's unit, angles in radians.
"""
from __future__ import annotations

import math
import os
from contextlib import contextmanager
from pathlib import Path
from typing import Any, Iterator, Mapping

import numpy as np

from spar_py.core.errors import SparValueError, UnknownKeyError, WrongKindError
from spar_py.core.geometry import same_stable_pose
from spar_py.core.memo import Memo
from spar_py.core.model import Bounds, Cell, MatingFeature, ObjectModel, Position, Product, Sensor, Term
from spar_py.kb.node import Node, cut, did_you_mean, show
from spar_py.kb.objects import holdable, load_object
from spar_py.kb.products import add_goal_frames, load_product, product_goals, product_part
from spar_py.kb.reader import MAX_INPUT_BYTES
from spar_py.kb.robots import home_angles, load_robot, load_urdf_robot
from spar_py.kb.sanity import check_cell
from spar_py.kb.schema import KINDS, read_kb
from spar_py.kb.terms import parse_term
from spar_py.kb.values import LOAD_MEMO_LIMIT, tm_node, units_of, xyz_rpy_frame
from spar_py.world.robot import Gripper

__all__ = ["COAXIAL_TOL", "GOAL_SHAPES", "SENSOR_NAMES", "check_mate", "derived_mate", "goal_features", "hole_axis",
           "load_problem", "mate_goal"]


# The sensing actions kb/templates/spar_sensing.pl defines: the names `sensors:` may use.
SENSOR_NAMES = ("dense_range_scan",)


#: An angle bound beyond this (rad: 90 deg) in a file whose angle unit is rad is refused unless
#: the file says ``allow_large_angles: true``: it is almost always degrees written as radians.
LARGE_ANGLE = math.pi / 2


def _bounds(node: Node, len_scale: float, rad_per: float, large_ok: bool = True) -> Bounds:
    """An uncertainty box ``{dx, dy, dz, dtheta}`` (each ``[lo, hi]``), lengths times ``len_scale``, angles in
    rad. Without ``large_ok``, a ``dtheta`` end beyond LARGE_ANGLE in a file in radians is a KBError."""
    def iv(k: str, s: float) -> tuple[float, float]:
        lo, hi = node.key(k).interval()
        return lo * s, hi * s

    dtheta = iv("dtheta", rad_per)
    big = max(abs(v) for v in dtheta)
    if not large_ok and rad_per == 1.0 and big > LARGE_ANGLE:
        n = node.key("dtheta")
        raise n.fail(f"an angle bound within 90 deg (the file's angle unit is rad: {big:g} rad is "
                     f"{math.degrees(big):.0f} deg; were degrees meant? allow_large_angles: true allows it)",
                     show(n.value))
    return Bounds(iv("dx", len_scale), iv("dy", len_scale), iv("dz", len_scale), dtheta)


GOAL_SHAPES: dict[str, tuple[int, ...]] = {"assembled": (5, 2), "part_location": (2,), "mated": (4,)}

#: T_a must put the peg's tip on the hole's axis within this fraction of the cell's size.
COAXIAL_TOL = 1e-6


def _check_goal(node: Node, goal: Any, cell_objects: dict[str, ObjectModel], transforms: dict, vectors: dict,
                positions: dict[str, Position]) -> None:
    """Validate a parsed goal against the cell (known objects, faces, transforms, positions)."""
    if not isinstance(goal, tuple) or goal[0] not in GOAL_SHAPES or len(goal) - 1 not in GOAL_SHAPES[goal[0]]:
        raise node.fail("a goal assembled(Peg, Hole), mated(Peg, PegFeature, Hole, HoleFeature), "
                        "assembled(Peg, Hole, [[PegFaces], [HoleFaces]], Ta, Va) "
                        "or part_location(Object, InitialPosition)")
    if goal[0] == "part_location":
        _, obj, pos = goal
        if obj not in cell_objects:
            raise node.fail(f"a known object in part_location/2 ({', '.join(sorted(cell_objects))})", show(obj))
        names = sorted(p.name for p in positions.values() if p.obj == obj)
        if pos not in names:
            raise node.fail(f"an initial position of {obj} in part_location/2 ({', '.join(names)})", show(pos))
        return
    _, held, fixed, faces, ta, va = goal
    for role, obj in (("first", held), ("second", fixed)):
        if obj not in cell_objects:
            raise node.fail(f"a known object as {role} argument ({', '.join(sorted(cell_objects))})", show(obj))
    if not (isinstance(faces, list) and len(faces) == 2 and all(isinstance(f, list) for f in faces)):
        raise node.fail("mating faces as [[PegFaces], [HoleFaces]]")
    for obj, fl in ((held, faces[0]), (fixed, faces[1])):
        for f in fl:
            if f not in cell_objects[obj].faces:
                raise node.fail(f"faces of {obj} in the mating faces", show(f))
    if not isinstance(ta, str) or ta not in transforms:
        raise node.fail(f"Ta naming a transform under transforms: ({_names(transforms)})", show(ta))
    if not isinstance(va, str) or va not in vectors:
        raise node.fail(f"Va naming a vector under vectors: ({_names(vectors)})", show(va))
    fp, fh = goal_features(node, goal, cell_objects)
    check_mate(node, _goal_text(goal), (held, fp), (fixed, fh), transforms[ta], vectors[va],
               _cell_size(cell_objects))


def _goal_text(goal: tuple) -> str:
    """A goal's head for a message: ``assembled(peg, block, ...)``."""
    return f"{goal[0]}({', '.join(str(a) for a in goal[1:3])}, ...)"


def _cell_size(objects: Mapping[str, ObjectModel]) -> float:
    """The cell's size for tolerances (cell unit): the largest part's bounding radius and feature
    vector, at least 1."""
    sizes = [m.bounding_radius() for m in objects.values()]
    sizes += [float(np.abs(f.vector).max()) for m in objects.values() for f in m.features]
    return max([1.0, *sizes])


def goal_features(node: Node, goal: tuple, objects: Mapping[str, ObjectModel]
                  ) -> tuple[MatingFeature, MatingFeature]:
    """The peg and hole features an ``assembled/5`` goal's face lists name
    (ObjectModel.feature_on); a KBError if a list names no feature of its part, or the kinds
    are not a peg and a hole."""
    _, peg, hole, faces, _, _ = goal
    out = []
    for obj, fl, kind in ((peg, faces[0], "peg"), (hole, faces[1], "hole")):
        m = objects[obj]
        f = m.feature_on(fl)
        if f is None:
            known = "; ".join(f"{x.name}: {', '.join(map(str, x.faces))}" for x in m.features) or "none"
            raise node.fail(f"{kind} faces naming a feature of {obj} (its features' faces: {known})",
                            show(", ".join(map(str, fl)) or "[]"))
        if f.kind != kind:
            raise node.fail(f"{obj}'s faces of a {kind} feature", f"those of {f.name}, a {f.kind}")
        out.append(f)
    return out[0], out[1]


def hole_axis(hole: MatingFeature, va: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """A point on the hole's axis and its unit direction into the hole (the hole's object frame):
    the declared axis of a hole given by geometry, else the bottom centre F_h and the goal's
    mating motion V_a (the paper's form gives no axis). ValueError if neither is known."""
    if hole.geometry is not None:
        return np.asarray(hole.geometry.origin, float), np.asarray(hole.geometry.direction, float)
    if va is None or not np.linalg.norm(va) > 0:
        raise ValueError(f"hole {hole.name} has no axis: give it by geometry, or a nonzero V_a")
    v = np.asarray(va, float)
    return np.asarray(hole.vector, float), v / np.linalg.norm(v)


def check_mate(node: Node, what: str, peg: tuple[str, MatingFeature], hole: tuple[str, MatingFeature],
               T_a: np.ndarray, va: np.ndarray | None, size: float) -> None:
    """A mate the planner can make: a peg feature into a hole feature with positive clearance
    R_h - R_p, and T_a (the peg's frame in the hole's, 4x4) putting the peg's tip F_p on the
    hole's axis (:func:`hole_axis`) within COAXIAL_TOL of ``size`` (the cell's size, cell unit).
    A KBError at ``node`` naming the goal ``what`` and what is wrong otherwise."""
    (pobj, fp), (hobj, fh) = peg, hole
    if fp.kind != "peg" or fh.kind != "hole":
        raise node.fail(f"a peg feature into a hole feature in {what}",
                        f"{pobj}.{fp.name} ({fp.kind}) into {hobj}.{fh.name} ({fh.kind})")
    if not fh.radius > fp.radius:
        raise node.fail(f"a hole wider than its peg in {what}",
                        f"{pobj}.{fp.name} of radius {fp.radius:g} into {hobj}.{fh.name} of radius {fh.radius:g} "
                        f"(clearance {fh.radius - fp.radius:g})")
    try:
        a0, u = hole_axis(fh, va)
    except ValueError:
        return  # a zero V_a: kb.sanity names the vector
    T = np.asarray(T_a, float)
    tip = T[:3, :3] @ np.asarray(fp.vector, float) + T[:3, 3]
    r = tip - a0
    off = float(np.linalg.norm(r - (r @ u) * u))
    if off > COAXIAL_TOL * size:
        raise node.fail(f"T_a putting {pobj}'s tip on the axis of {hobj}.{fh.name} in {what}",
                        f"a tip {off:.6g} off that axis")
    if fp.geometry is not None:  # the peg's axis along the hole's, into it (either way through a through hole)
        d = T[:3, :3] @ np.asarray(fp.geometry.direction, float)
        c = float(d @ u)
        if abs(c) < 1 - COAXIAL_TOL or (c < 0 and not fh.through):
            raise node.fail(f"T_a pointing {pobj}.{fp.name} into {hobj}.{fh.name} along its axis in {what}",
                            f"{math.degrees(math.acos(max(-1.0, min(1.0, c)))):.6g} deg from the way in")


def _names(table: Mapping[str, Any]) -> str:
    """The names of a table for a message (cut), or 'none'."""
    return cut(", ".join(table)) if table else "none"


def _ref_path(node: Node, base: Path, kind: str) -> Path:
    """The file a ``robot:`` or ``model:`` reference names, relative to the problem file."""
    ref = base / node.text()
    if not os.path.lexists(ref):
        raise node.fail(f"the path of {KINDS[kind].wanted}", f"{show(node.value)} (no such file)")
    return ref


@contextmanager
def _referenced(node: Node, kind: str) -> Iterator[None]:
    """Load the file a reference names: a file of another kind is the reference's error
    (``robot: expected the path of a robot file, not '/etc/passwd', a plain text file``)."""
    try:
        yield
    except WrongKindError as e:
        raise node.fail(f"the path of {KINDS[kind].wanted}", f"{show(node.value)}, {e.got}") from None


def _positions(onode: Node, oname: str, model: ObjectModel, taken: dict[str, Position],
               memo: Memo | None = None) -> list[Position]:
    """An object's initial position, or the list of them (a stock of identical parts:
    part_location(Obj, Pos) holds for each; "the peg" is whichever is taken). ``memo``:
    the load's tables (:func:`tm_node`, :func:`_same_stable_pose`)."""
    inode = onode.key("initial")
    inits = inode.elements(1) if isinstance(inode.value, list) else [inode]
    out: list[Position] = []
    names = {p.name for p in taken.values()}
    for init in inits:
        pname, plabel = init.key("name").label(), init.key("label").label()
        if plabel in taken or pname in names or any(plabel == p.label or pname == p.name for p in out):
            raise init.fail("a position name and label not used before", f"{pname}, {plabel}")
        T = tm_node(init.key("tm"), 1.0, memo)
        if not any(_same_stable_pose(T[:3, :3], p.R, memo) for p in model.poses.values()):
            raise init.key("tm").fail(f"an orientation of one of {oname}'s stable poses")
        out.append(Position(pname, plabel, oname, T))
    return out


def _same_stable_pose(R_abs: np.ndarray, R_pose: np.ndarray, memo: Memo | None) -> bool:
    """geometry.same_stable_pose of two (3, 3) float rotations, kept in ``memo`` (the load's
    tables) by their bytes: the same rotations, the same answer."""
    if memo is None:
        return same_stable_pose(R_abs, R_pose)
    return memo.table("same_stable_pose", LOAD_MEMO_LIMIT).get_or_compute(
        (R_abs.tobytes(), R_pose.tobytes()), lambda: same_stable_pose(R_abs, R_pose))


def _objects(root: Node, base: Path, unit: str, max_bytes: int, opening: float | None = None,
             gripper: Gripper | None = None, memo: Memo | None = None, reach: float | None = None,
             product: Product | None = None, layout: Any = None
             ) -> tuple[dict[str, ObjectModel], dict[str, Position], list[Path]]:
    """The problem's objects (models loaded; a part of ``product`` takes its model from it), their
    initial positions and the model files (``memo``: the load's tables, ``reach`` the arm's
    length: :func:`load_object`). With ``layout`` (``layout: auto``: a world.product.layout.Layout),
    the product's parts are at its placements (position ``init_PART``, label ``tr_PART``) and
    ``objects:`` holds only the other objects, if any."""
    objects: dict[str, ObjectModel] = {}
    positions: dict[str, Position] = {}
    files: list[Path] = []
    if layout is not None and product is not None:
        for pl in layout.placements:
            objects[pl.part] = product.parts[pl.part].model
            positions[f"tr_{pl.part}"] = Position(f"init_{pl.part}", f"tr_{pl.part}", pl.part, pl.T)
    onodes = root.key("objects", required=layout is None)
    for oname, onode in (onodes.items() if onodes is not None else []):
        if oname in objects:
            raise onode.fail(f"no entry for {oname} (layout: auto places the parts of product {product.name})")
        if product is not None and oname in product.parts:
            model = product_part(onode, product, oname)
        else:
            mnode = onode.key("model")
            mpath = _ref_path(mnode, base, "object")
            with _referenced(mnode, "object"):
                model = load_object(mpath, unit, max_bytes, opening=opening, gripper=gripper, memo=memo,
                                    reach=reach)
            if model.name != oname:
                raise mnode.fail(f"the model of {oname}", f"the model of {model.name}")
            files.append(mpath)
        objects[oname] = model
        for pos in _positions(onode, oname, model, positions, memo):
            positions[pos.label] = pos
    if not objects:
        raise root.key("objects").fail("at least one object", "none")
    if onodes is None:
        return objects, positions, files
    missing = [p for p in (product.parts if product is not None else ()) if p not in objects]
    if missing:
        raise root.key("objects").fail(f"an initial position for every part of product {product.name}",
                                       f"none for {', '.join(missing)}")
    return objects, positions, files


def _object_bounds(unc: Node, objects: Mapping[str, ObjectModel], rad_per: float,
                   large_ok: bool = True) -> dict[str, Bounds]:
    """``uncertainty.objects``: bounds for every object of the cell, and only for them (``large_ok``:
    :func:`_bounds`)."""
    onodes = unc.key("objects")
    out: dict[str, Bounds] = {}
    for oname, bnode in onodes.items():
        if oname not in objects:
            near = did_you_mean(oname, objects)
            raise bnode.fail(f"bounds of a known object ({', '.join(sorted(objects))})",
                             show(oname) + (f"; did you mean {near}?" if near else ""))
        out[oname] = _bounds(bnode, 1.0, rad_per, large_ok)
    for oname in objects:
        if oname not in out:
            raise onodes.fail(f"bounds for every object (missing {oname})")
    return out


def _sensors(root: Node, rad_per: float, large_ok: bool = True) -> dict[str, Sensor]:
    """``sensors``: each named after a sensing action of kb/templates/spar_sensing.pl (SENSOR_NAMES; ``large_ok``:
    :func:`_bounds`)."""
    snode = root.key("sensors", required=False)
    out: dict[str, Sensor] = {}
    for sname, s in snode.items() if snode is not None else []:
        if sname not in SENSOR_NAMES:
            near = did_you_mean(sname, SENSOR_NAMES)
            raise UnknownKeyError(s.file, s.path, near) if near else s.fail(
                f"a sensing action ({', '.join(SENSOR_NAMES)})", show(sname))
        out[sname] = Sensor(sname, _bounds(s, 1.0, rad_per, large_ok))
    return out


def _goals(root: Node, objects: dict[str, ObjectModel], transforms: dict, vectors: dict,
           positions: dict[str, Position], turns: dict, product: Product | None = None) -> list[Term]:
    """The goals, parsed and checked against the cell, as term data (kb.terms); an ``assembled(Peg,
    Hole)`` goal adds its derived T_a turns to ``transforms`` and ``turns`` (_derived_assembly);
    a product's goals (``assembled(KIT)``, ``mated/4``) are its compiled ones (kb.products)."""
    goals: list[Term] = []
    for g in root.key("goals").elements(1):
        text = g.text()  # outside the try: a KBError is a ValueError too, and must not nest
        try:
            term = parse_term(text)
        except ValueError as e:
            raise g.fail(f"a Prolog term ({e})", show(text)) from None
        if product is not None and (compiled := product_goals(g, term, product)) is not None:
            goals += [t for t in compiled if t not in goals]
            continue
        if isinstance(term, tuple) and term[0] == "assembled" and len(term) == 3:
            term = _derived_assembly(g, term, objects, transforms, vectors, turns)
        elif isinstance(term, tuple) and term[0] == "mated" and len(term) == 5:
            term = _mated(g, term, objects, transforms, vectors, turns)
        _check_goal(g, term, objects, transforms, vectors, positions)
        goals.append(term)
    return goals


def _known_object(node: Node, obj: Any, role: str, objects: Mapping[str, ObjectModel]) -> ObjectModel:
    """The model of a goal's argument ``obj`` (a KBError naming the known objects if none)."""
    if not isinstance(obj, str) or obj not in objects:
        raise node.fail(f"a known object as {role} argument ({', '.join(sorted(objects))})", show(obj))
    return objects[obj]


def _derived_assembly(node: Node, goal: tuple, objects: dict[str, ObjectModel], transforms: dict,
                      vectors: dict, turns: dict) -> tuple:
    """``assembled(Peg, Hole)``: Peg's only peg feature into Hole's only hole feature (refused,
    pointing to mated/4, when either part has several or none), as :func:`derived_mate`."""
    _, peg, hole = goal
    feats = []
    for role, obj, kind in (("first", peg, "peg"), ("second", hole, "hole")):
        m = _known_object(node, obj, role, objects)
        fs = [f for f in m.features if f.kind == kind]
        if len(fs) > 1:
            raise node.fail(f"{obj} with one {kind} feature for assembled/2; it has {len(fs)} "
                            f"({', '.join(f.name for f in fs)}): name them with mated(Peg, PegFeature, Hole, "
                            "HoleFeature)")
        if not fs or fs[0].geometry is None:
            raise node.fail(f"{obj} with a {kind} feature declared by geometry (feature: {{kind: {kind}, name, "
                            "radius, axis, length}) for assembled/2, or the five-argument goal")
        feats.append(fs[0])
    return derived_mate(node, f"assembled({peg}, {hole})", objects, (peg, feats[0]), (hole, feats[1]),
                        transforms, vectors, turns)


def _mated(node: Node, goal: tuple, objects: dict[str, ObjectModel], transforms: dict, vectors: dict,
           turns: dict) -> tuple:
    """``mated(Peg, PegFeature, Hole, HoleFeature)``: the named features, as :func:`derived_mate`."""
    _, peg, pf, hole, hf = goal
    what = f"mated({peg}, {pf}, {hole}, {hf})"
    feats = []
    for role, obj, fname, kind in (("first", peg, pf, "peg"), ("third", hole, hf, "hole")):
        m = _known_object(node, obj, role, objects)
        names = ", ".join(f"{f.name} ({f.kind})" for f in m.features) or "none"
        f = next((f for f in m.features if f.name == fname), None)
        if f is None:
            raise node.fail(f"a feature of {obj} in {what} ({names})", show(fname))
        if f.kind != kind:
            raise node.fail(f"a {kind} feature of {obj} in {what} ({names})", f"{fname}, a {f.kind}")
        if f.geometry is None:
            raise node.fail(f"{obj}.{fname} declared by geometry ({{kind, name, radius, axis, length}}) for "
                            "mated/4, or the five-argument assembled goal")
        feats.append(f)
    return derived_mate(node, what, objects, (peg, feats[0]), (hole, feats[1]), transforms, vectors, turns)


def _free_index(transforms: Mapping[str, Any], vectors: Mapping[str, Any], n_turns: int) -> int:
    """The first K with trans_K, its turns trans_K_tJ (J <= n_turns) and vec_K all free."""
    k = 1
    while f"trans_{k}" in transforms or f"vec_{k}" in vectors or any(
            f"trans_{k}_t{j}" in transforms for j in range(2, n_turns + 1)):
        k += 1
    return k


def derived_mate(node: Node, what: str, objects: Mapping[str, ObjectModel], peg: tuple[str, MatingFeature],
                 hole: tuple[str, MatingFeature], transforms: dict, vectors: dict, turns: dict) -> tuple:
    """The ``assembled/5`` goal of a mate whose T_a is derived from the features' geometry
    (world.parts.mesh.assembly_transforms): the mating faces are the two features' faces.

    T_a is a choice among the turns about the hole's axis, quantised by the finer of the two
    models' ``grasp_step`` (45 deg by default): the first turn (the least rotation of the
    peg's axis onto the hole's) is added to the cell's transforms as trans_K, turn J (J = 2,
    3, ...; turned by (J - 1) steps) as trans_K_tJ, and V_a as vec_K (the first K not taken).
    The goal names trans_K; ``turns[trans_K]`` lists every turn with the hole part's stable
    poses in which the mated peg stays clear of the table (world.parts.mesh.poses_clear_of_table;
    every pose when the peg has no shape). The planner chooses the turn (kb/templates/spar_actions.pl).
    The mate is checked (:func:`check_mate`; ``what`` names it in messages).
    """
    from spar_py.world.parts import assembly_transforms, part_mesh, poses_clear_of_table  # derived T_a only

    (pobj, fp), (hobj, fh) = peg, hole
    if fp.geometry is None or fh.geometry is None:
        raise node.fail(f"features declared by geometry for {what}")
    steps = [m.geometry.step for m in (objects[pobj], objects[hobj]) if m.geometry is not None]
    Tas, Va, _ = assembly_transforms(fp.geometry, fh.geometry, min(steps, default=math.radians(45.0)))
    check_mate(node, what, peg, hole, Tas[0], Va, _cell_size(objects))
    k = _free_index(transforms, vectors, len(Tas))
    name = f"trans_{k}"
    pgeo = objects[pobj].geometry
    pts = None
    if pgeo is not None:  # the hull a derivation gave, else (all entries hand-written) the mesh's vertices
        pts = pgeo.hull if pgeo.hull is not None else np.asarray(part_mesh(objects[pobj]).vertices)
    poses = list(objects[hobj].poses.values())
    alternatives = []
    for j, T in enumerate(Tas, start=1):
        tname = name if j == 1 else f"{name}_t{j}"
        transforms[tname] = T
        clear = ([True] * len(poses) if pts is None else poses_clear_of_table(
            pts, T, [(p.R, p.height) for p in poses], pgeo.unit))
        alternatives.append((tname, tuple(p.label for p, ok in zip(poses, clear) if ok)))
    vectors[f"vec_{k}"] = Va
    turns[name] = tuple(alternatives)
    return ("assembled", pobj, hobj, [list(fp.faces), list(fh.faces)], name, f"vec_{k}")


def mate_goal(node: Node, what: str, objects: Mapping[str, ObjectModel], peg: tuple[str, MatingFeature],
              hole: tuple[str, MatingFeature], T_a: np.ndarray, transforms: dict, vectors: dict) -> tuple:
    """The ``assembled/5`` goal of a mate with a given T_a (the peg's frame in the hole's, 4x4,
    cell unit: a product's poses give it), checked (:func:`check_mate`): T_a is added to the
    cell's transforms as trans_K and the insertion direction V_a (hole frame: the peg's axis
    turned by T_a, so either mouth of a through hole; the hole's direction for a peg in the
    paper's form) as vec_K."""
    (pobj, fp), (hobj, fh) = peg, hole
    try:
        _, va = hole_axis(fh, None)
    except ValueError as e:
        raise node.fail(f"a hole declared by geometry in {what}", str(e)) from None
    T = np.asarray(T_a, float)
    check_mate(node, what, peg, hole, T, va, _cell_size(objects))
    if fp.geometry is not None:
        va = T[:3, :3] @ np.asarray(fp.geometry.direction, float)
    k = _free_index(transforms, vectors, 1)
    transforms[f"trans_{k}"] = T
    vectors[f"vec_{k}"] = va
    return ("assembled", pobj, hobj, [list(fp.faces), list(fh.faces)], f"trans_{k}", f"vec_{k}")


def _regions(root: Node) -> list[dict[str, tuple[float, float]]]:
    """``placement_regions``: the free table rectangles ``{x: [lo, hi], y: [lo, hi]}``."""
    rnode = root.key("placement_regions", required=False)
    return [{"x": r.key("x").interval(), "y": r.key("y").interval()}
            for r in (rnode.elements() if rnode is not None else [])]


def _obstacles(root: Node, base: Path, rad_per: float) -> list:
    """``obstacles:``: named shapes in the world frame (cell unit): ``box: {min, max}``,
    ``cylinder: {radius, z: [lo, hi], center: [x, y]}`` (axis along world z) or ``mesh: FILE``
    placed at ``xyz``, ``rpy`` (its convex hull: a conservative stand-in for a concave fixture);
    ``support: true`` marks one parts may rest on (its top: a nest, a riser, a fixture plate)."""
    from spar_py.world.collision import Obstacle, box, convex, cylinder  # paid by a load, not by the import

    onode = root.key("obstacles", required=False)
    out: list = []
    seen: set[str] = set()
    for on in (onode.elements() if onode is not None else []):
        name = on.key("name").label()
        if name in seen or name == "table":
            raise on.key("name").fail("a name no other obstacle (nor the table) has", name)
        seen.add(name)
        kinds = [k for k in ("box", "cylinder", "mesh") if on.key(k, required=False) is not None]
        if len(kinds) != 1:
            raise on.fail("exactly one of box: {min, max}, cylinder: {radius, z, center}, mesh: FILE",
                          ", ".join(kinds) or "none")
        k = kinds[0]
        if k == "box":
            b = on.key("box")
            lo, hi = b.key("min").vector(3), b.key("max").vector(3)
            if np.any(lo >= hi):
                raise b.fail("min < max in every coordinate")
            bodies = (box(name, -1, lo, hi),)
        elif k == "cylinder":
            c = on.key("cylinder")
            r = c.key("radius").positive()
            z0, z1 = c.key("z").interval()
            if not z0 < z1:
                raise c.key("z").fail("[lo, hi] with lo < hi")
            cx, cy = c.key("center").vector(2)
            bodies = (cylinder(name, -1, [cx, cy, z0], [cx, cy, z1], r),)
        else:
            mnode = on.key("mesh")
            mpath = base / mnode.text()
            if not mpath.is_file():
                raise mnode.fail("the path of a mesh file (STL, OBJ, PLY)", f"{show(mnode.value)} (no such file)")
            try:
                import trimesh  # on first use: a mesh obstacle only

                mesh = trimesh.load(str(mpath), force="mesh")
                pts = np.asarray(mesh.convex_hull.vertices, float)
            except Exception as e:  # trimesh's many loader errors: one line
                raise mnode.fail(f"a mesh trimesh can read ({type(e).__name__}: {str(e)[:80]})") from None
            T = xyz_rpy_frame(on, 1.0, rad_per) if on.key("xyz", required=False) is not None else np.eye(4)
            bodies = (convex(name, -1, pts @ T[:3, :3].T + T[:3, 3]),)
        snode = on.key("support", required=False)
        if snode is not None and not isinstance(snode.value, bool):
            raise snode.fail("true or false (parts may rest on its top)", show(snode.value))
        out.append(Obstacle(name, bodies, support=bool(snode is not None and snode.value)))
    return out


def _table(root: Node) -> tuple[float, float, float, float] | None:
    """``table: {x: [lo, hi], y: [lo, hi]}``: the table top's extent (cell unit), None: the whole plane."""
    tnode = root.key("table", required=False)
    if tnode is None:
        return None
    (x0, x1), (y0, y1) = tnode.key("x").interval(), tnode.key("y").interval()
    if not (x0 < x1 and y0 < y1):
        raise tnode.fail("x: [lo, hi] and y: [lo, hi] with lo < hi")
    return (x0, x1, y0, y1)


def _collision_switch(root: Node) -> bool:
    """``collision: false`` turns the collision check off for a cell (a user's opt-out: every
    reach is then decided by IK and the wrist height alone); default true."""
    node = root.key("collision", required=False)
    if node is None:
        return True
    if not isinstance(node.value, bool):
        raise node.fail("true or false", show(node.value))
    return node.value


def _clearance(root: Node) -> float | None:
    """``clearance:`` the collision margin (cell unit, >= 0), None when not given."""
    cnode = root.key("clearance", required=False)
    if cnode is None:
        return None
    m = cnode.number()
    if m < 0:
        raise cnode.fail("a clearance margin >= 0", show(cnode.value))
    return m


def _product(root: Node, base: Path, unit: str, max_bytes: int, robot: Any, memo: Memo, reach: float
             ) -> tuple[Product | None, list[Path]]:
    """The product ``product:`` names (kb.products), loaded for the robot's gripper, and its files."""
    pnode = root.key("product", required=False)
    if pnode is None:
        return None, []
    ppath = _ref_path(pnode, base, "product")
    with _referenced(pnode, "product"):
        product = load_product(ppath, unit, max_bytes, memo, opening=robot.finger_separation,
                               gripper=robot.gripper, reach=reach)
    return product, [ppath, *map(Path, product.files)]


def _layout(root: Node, product: Product | None, robot: Any, unit: str) -> Any:
    """``layout: auto``: the product's parts laid out on the table for the robot
    (world.product.layout.layout_product); None without the key. A KBError at the key when there is no
    ``product:`` or the parts do not fit within reach."""
    lnode = root.key("layout", required=False)
    if lnode is None:
        return None
    if lnode.value != "auto":
        raise lnode.fail("auto (the product's parts laid out on the table at load)", show(lnode.value))
    if product is None:
        raise lnode.fail("a problem with product: (layout: auto lays out a product's parts)")
    from spar_py.world.product import layout_product  # trimesh and the IK: a laid-out cell only

    try:
        return layout_product(product, robot, unit)
    except SparValueError as e:
        raise lnode.fail(str(e)[len("expected "):] if str(e).startswith("expected ") else str(e)) from None


def load_problem(path: str | Path, max_bytes: int = MAX_INPUT_BYTES) -> Cell:
    """Load and validate ``kb/problems/*.yaml`` with the robot and object files it names
    (each file at most ``max_bytes``)."""
    path = Path(path)
    root = read_kb(path, "problem", max_bytes)
    name = root.key("problem").label()
    unit, _, rad_per = units_of(root)
    base = path.parent

    rnode = root.key("robot")
    if isinstance(rnode.value, dict):  # inline, from a URDF
        robot, rpath = load_urdf_robot(rnode, base, unit, rad_per)
    else:
        rpath = _ref_path(rnode, base, "robot")
        with _referenced(rnode, "robot"):
            robot = load_robot(rpath, unit=unit, max_bytes=max_bytes)
    memo = Memo()  # this load's tables: the object files of a problem repeat their transforms
    arm = float(np.abs(robot.dh[:, 1]).sum() + np.abs(robot.dh[:, 2]).sum() + np.linalg.norm(robot.tool[:3, 3]))
    product, product_files = _product(root, base, unit, max_bytes, robot, memo, arm)
    layout = _layout(root, product, robot, unit)
    objects, positions, model_files = _objects(root, base, unit, max_bytes, robot.finger_separation, robot.gripper,
                                               memo, arm, product, layout)
    model_files += product_files
    grip = root.key("gripper").choice(("open", "closed"))
    unc = root.key("uncertainty")
    lnode = root.key("allow_large_angles", required=False)
    if lnode is not None and not isinstance(lnode.value, bool):
        raise lnode.fail("true or false (allow angle bounds over 90 deg in a file in radians)", show(lnode.value))
    large_ok = bool(lnode is not None and lnode.value)
    man = _bounds(unc.key("manipulator"), 1.0, rad_per, large_ok)
    obj_bounds = _object_bounds(unc, objects, rad_per, large_ok)
    sensors = _sensors(root, rad_per, large_ok)
    transforms = {k: tm_node(n.key("tm"), 1.0, memo)
                  for k, n in (root.key("transforms", False) or Node("", "", {})).items()}
    vectors = {k: n.vector(3) for k, n in (root.key("vectors", False) or Node("", "", {})).items()}
    turns: dict[str, tuple[tuple[str, tuple[str, ...]], ...]] = {}
    if product is not None:
        add_goal_frames(root.key("product"), product, transforms, vectors)
    goals = _goals(root, objects, transforms, vectors, positions, turns, product)
    moved = {g[1] for g in goals if isinstance(g, tuple) and g[0] in ("assembled", "part_location")}
    for (oname, model), mfile in zip(objects.items(), model_files):
        if oname in moved:
            holdable(mfile, model)  # only a part a goal moves must have a grasp
    initial: list[Term] = [("gripper", grip)] + [("part_location", p.obj, p.name) for p in positions.values()]
    meshes = [m.geometry.mesh_file for m in objects.values() if m.geometry is not None and m.geometry.mesh_file]
    files = tuple(dict.fromkeys(str(Path(u).resolve()) for u in [path, rpath, *model_files, *meshes]))
    home = home_angles(root.key("home", required=False), robot, rad_per)
    mnode = root.key("motion", required=False)
    if mnode is not None and not isinstance(mnode.value, bool):
        raise mnode.fail("true or false (plan the motions between the end-points)", show(mnode.value))
    cell = Cell(
        files=files,
        name=name,
        file=str(path),
        unit=unit,
        robot=robot,
        finger_separation=robot.finger_separation,
        objects=objects,
        positions=positions,
        transforms=transforms,
        vectors=vectors,
        turns=turns,
        initial=initial,
        goals=goals,
        manipulator_bounds=man,
        object_bounds=obj_bounds,
        sensors=sensors,
        placement_regions=_regions(root),
        obstacles=tuple(_obstacles(root, base, rad_per)),
        table=_table(root),
        clearance=_clearance(root),
        collisions=_collision_switch(root),
        home=home if home is not None else robot.home,
        product=product,
        plan_motions=bool(mnode is not None and mnode.value),
    )
    if product is not None:  # the grasps no plan seats a part with, the orders the hand needs
        from spar_py.world.product import with_hand_access  # the IK and the collision scene: products only

        cell = with_hand_access(cell, layout.held if layout is not None else None)
    check_cell(cell)  # physically possible: parts apart, on the table, in reach (kb.sanity)
    return cell
