"""The object-model loader: ``kb/objects/*.yaml`` to a validated :class:`~spar_py.core.model.ObjectModel`.

Faces, stable poses (Fig. 18), grasps (Fig. 19) and the mating feature, hand-written or
(left out of a model with ``mesh:`` or ``shape:``) derived from its geometry by the world
layer (world.parts.mesh); :func:`check_against_shape` checks hand-written entries against the
geometry. Lengths are converted to the cell's unit, angles to radians.
"""
from __future__ import annotations

import math
import struct
from pathlib import Path
from typing import Any

import numpy as np

from spar_py.core.errors import KBError
from spar_py.core.geometry import eulerxyz
from spar_py.core.memo import Memo
from spar_py.core.model import Face, Grasp, MatingFeature, ObjectModel, Solid, StablePose
from spar_py.core.units import LENGTH_UNITS, from_mm
from spar_py.kb.node import LABEL_RE, MAX_MAGNITUDE, Node, cut, show
from spar_py.kb.reader import MAX_INPUT_BYTES
from spar_py.kb.schema import read_kb
from spar_py.kb.values import LOAD_MEMO_LIMIT, tm_node, units_of
from spar_py.world.robot import Gripper

__all__ = ["DEFAULT_OPENING_MM", "DERIVABLE", "PART_SIZE_MM", "REACH_RATIO", "check_against_shape", "holdable",
           "load_object", "mesh_note", "part_size"]


#: The entries an object model may leave out when it gives its geometry (derived: world.parts.mesh).
DERIVABLE = ("faces", "stable_poses", "grasps")


#: The sizes (mm) a part's largest extent must lie between: a part outside them is almost
#: always a file whose length unit is not its mesh's or shape's (a mesh in metres read as mm).
PART_SIZE_MM = (1.0, 10_000.0)
#: A part may be at most this many times smaller or larger than the arm's reach.
REACH_RATIO = 1000.0


#: The gripper opening assumed when an object model is derived without a robot (mm: the
#: PUMA 762's 4 in, kb/robots/puma762.yaml).
DEFAULT_OPENING_MM = 101.6


def _faces(node: Node, known: set[Face] | None, min_len: int = 1) -> tuple[Face, ...]:
    """A list of at least ``min_len`` face names (labels) or numbers, each one of ``known``
    (when given)."""
    v = node.value
    if type(v) is list and len(v) >= min_len and all(
            (LABEL_RE.fullmatch(f) is not None if type(f) is str else type(f) is int and abs(f) <= MAX_MAGNITUDE)
            and (known is None or f in known) for f in v):
        return tuple(v)  # every face as the loop below takes it: no Nodes
    out = []
    for e in node.elements(min_len):
        f = e.value
        if isinstance(f, bool) or not isinstance(f, (int, str)) or (isinstance(f, int) and abs(f) > MAX_MAGNITUDE):
            raise e.fail("a face name or number", show(f))
        if isinstance(f, str):
            e.label()
        if known is not None and f not in known:
            raise e.fail(f"a face of the object ({cut(', '.join(map(str, sorted(known, key=str))))})", show(f))
        out.append(f)
    return tuple(out)


def load_object(path: str | Path, unit: str, max_bytes: int = MAX_INPUT_BYTES, opening: float | None = None,
                use_cache: bool = True, gripper: Gripper | None = None,
                memo: Memo | None = None, reach: float | None = None) -> ObjectModel:
    """Load ``kb/objects/*.yaml`` converting lengths to ``unit``.

    ``faces``, ``stable_poses`` and ``grasps`` left out of a model with ``mesh:`` or
    ``shape:`` are derived from its geometry (world.parts.mesh, cached by content hash:
    world.parts.cache) for the robot's ``gripper`` (its opening, fingers and palm, cell unit)
    or, without one, a gripper of opening ``opening`` (cell unit; DEFAULT_OPENING_MM without a
    robot) with the default fingers; hand-written ones take precedence. Only a derivation
    imports trimesh. ``memo``: the tables of a load reading many files (:func:`tm_node`,
    :func:`_grasp_frame`); the model is the same without. A model with a mesh or shape whose
    largest extent is out of proportion (PART_SIZE_MM, or REACH_RATIO times the arm's
    ``reach``, cell unit, when given) is refused before anything is derived: its file's
    length unit is likely not its geometry's.
    """
    root = read_kb(path, "object", max_bytes)
    name = root.key("object").label()
    _, mm_per, rad_per = units_of(root)
    scale = mm_per / LENGTH_UNITS[unit]
    geometry, solids = _geometry(root, Path(path), unit, scale)
    face_names = {k: n.vector(3) * scale for k, n in (root.key("face_names", False) or Node("", "", {})).items()}
    fnodes = _feature_nodes(root)
    feature_geos = tuple(g for g in (_feature_geometry(n, scale) for n in fnodes) if g is not None)
    if geometry is not None:
        _check_size(root, Path(path), name, geometry, solids, unit, reach)
        geometry.face_names = face_names
        geometry.step = _grasp_step(root, rad_per)
    missing = [k for k in DERIVABLE if k not in root.value]
    derived = None
    if missing:
        if geometry is None:
            root.key(missing[0])  # raises: key missing
        step = geometry.step
        from spar_py.world.parts import derive_part  # on first use: a derivation only

        grip = _derive_gripper(unit, opening, gripper)
        try:
            derived = derive_part(name, geometry, feature_geos, face_names, grip, step, need_hull=True,
                             use_cache=use_cache)
        except KBError:
            raise
        except Exception as e:  # trimesh, manifold3d, scipy: a shape they cannot take is bad input
            raise _geometry_error(path, geometry, e) from None
        geometry.hull = np.asarray(derived["hull"], float)
        geometry.repair = geometry.repair or str(derived.get("repair", ""))
        geometry.no_grasp = str(derived.get("no_grasp", ""))
        if geometry.mesh_file is not None:
            pts = geometry.hull
            solids = (Solid("hull", pts.min(0), pts.max(0), 0.0, pts),)
    elif face_names and geometry is None:
        raise root.key("face_names").fail("a model with mesh: or shape: (face_names name the faces of its geometry)")

    faces_node = root.key("faces", required=False)
    if faces_node is not None:
        faces = _faces(faces_node, None)
        if len(set(faces)) != len(faces):
            raise faces_node.fail("distinct face names")
    else:
        faces = tuple(derived["faces"])
    known = set(faces)

    poses: dict[str, StablePose] = {}
    if "stable_poses" in root.value:
        for p in root.key("stable_poses").elements(1):
            label = p.key("label").label()
            if label in poses:
                raise p.key("label").fail("a label not used before", show(label))
            T = tm_node(p.key("tm"), scale, memo)
            poses[label] = StablePose(
                label, _faces(p.key("rfaces"), known), _faces(p.key("ofaces"), known, 0),
                T[:3, :3].copy(), float(T[2, 3]),
            )
    else:
        for d in derived["poses"]:
            _known(root, faces_node, d["label"], d["rfaces"] + d["ofaces"], known, "stable pose")
            poses[d["label"]] = StablePose(d["label"], tuple(d["rfaces"]), tuple(d["ofaces"]),
                                           np.array(d["R"], float).reshape(3, 3), float(d["height"]))
        if not poses:
            raise KBError(str(path), "mesh" if geometry.mesh_file else "shape",
                          "a part with at least one stable pose (resting on a face, its centre of mass over it)")

    grasps: dict[str, Grasp] = {}
    if "grasps" in root.value:
        for g in root.key("grasps").elements(1):
            label = g.key("label").label()
            if label in grasps:
                raise g.key("label").fail("a label not used before", show(label))
            e = g.key("eulerxyz").vector(6)
            euler = (e[0] * scale, e[1] * scale, e[2] * scale, e[3] * rad_per, e[4] * rad_per, e[5] * rad_per)
            grasps[label] = Grasp(
                label,
                _faces(g.key("gfaces"), known),
                _faces(g.key("ofaces"), known, 0),
                euler,
                g.key("width").positive() * scale,
                _grasp_frame(euler, memo),
            )
    else:
        for d in derived["grasps"]:
            _known(root, faces_node, d["label"], d["gfaces"] + d["ofaces"], known, "grasp")
            euler = tuple(float(v) for v in d["euler"])
            grasps[d["label"]] = Grasp(d["label"], tuple(d["gfaces"]), tuple(d["ofaces"]), euler,  # type: ignore[arg-type]
                                       float(d["width"]), eulerxyz(*euler))
    clash = set(poses) & set(grasps)
    if clash:
        raise root.key("grasps").fail(f"labels distinct from stable pose labels ({', '.join(sorted(clash))})")

    features = _features(fnodes, known, scale)
    return ObjectModel(name, faces, poses, grasps, features, solids, geometry)


def _feature_nodes(root: Node) -> list[Node]:
    """The nodes of the model's features: ``features:`` (a list) or ``feature:`` (one, or a list
    as ``features:`` is)."""
    one, many = root.key("feature", required=False), root.key("features", required=False)
    if one is not None and many is not None:
        raise many.fail("feature: or features:, not both")
    if many is not None:
        return many.elements(1)
    if one is None:
        return []
    return one.elements(1) if isinstance(one.value, list) else [one]


def _features(fnodes: list[Node], known: set[Face], scale: float) -> tuple[MatingFeature, ...]:
    """The model's mating features, each checked against the part's faces: names unique (a
    ``name:`` required when there are several), ``through:`` only on a hole."""
    out: list[MatingFeature] = []
    for fnode in fnodes:
        geo = _feature_geometry(fnode, scale)
        if len(fnodes) > 1 and "name" not in fnode.value:
            raise fnode.fail("a name: for each feature of a part with several")
        through = _through(fnode)
        if geo is not None:
            if geo.name not in known:
                raise fnode.key("name").fail("the name of a face on the shape at the feature (its axis, radius and "
                                             "length place it)", show(geo.name))
            corners = None if geo.corners is None else geo.end + np.asarray(geo.corners, float)
            f = MatingFeature(geo.kind, (geo.name,), geo.radius, geo.end, geo, geo.name, through, geo.profile, corners)
        else:
            nnode = fnode.key("name", required=False)
            f = MatingFeature(
                fnode.key("kind").choice(("peg", "hole")),
                _faces(fnode.key("faces"), known),
                fnode.key("radius").positive() * scale,
                fnode.key("vector").vector(3) * scale,
                name=nnode.label() if nnode is not None else "",
                through=through,
            )
        if any(o.name == f.name for o in out):
            raise (fnode.key("name", required=False) or fnode).fail("a feature name not used before in the part",
                                                                    show(f.name))
        out.append(f)
    return tuple(out)


def holdable(path: str | Path, model: ObjectModel) -> None:
    """Refuse ``model`` (loaded from ``path``) as a part some goal moves when the gripper cannot
    hold it: derived grasps may be none (a base, a board no action moves loads with none), a part
    to be moved must have one. KBError naming the file and its ``mesh`` or ``shape`` key."""
    if model.grasps:
        return
    geo = model.geometry
    key = "mesh" if geo is not None and geo.mesh_file else "shape"
    why = (geo.no_grasp if geo is not None and geo.no_grasp
           else "no pair of opposite faces or round surface within its opening")
    raise KBError(str(path), key, f"a part the gripper can hold, as a goal moves it ({why})")


def mesh_note(model: ObjectModel) -> str | None:
    """One line saying what loading the model's mesh file repaired (world.parts.mesh.repair_mesh),
    ``FILE: repaired: ...`` (the file relative to the working directory where it is under it),
    or None when nothing was (or the model has no mesh, or its mesh was not loaded)."""
    geo = model.geometry
    if geo is None or geo.mesh_file is None or not geo.repair:
        return None
    f = Path(geo.mesh_file)
    try:
        f = f.relative_to(Path.cwd())
    except ValueError:
        pass
    return f"{f}: repaired: {geo.repair}"


def _grasp_frame(euler: tuple[float, ...], memo: Memo | None) -> np.ndarray:
    """geometry.eulerxyz of a grasp's (X, Y, Z, phi, theta, psi) (cell unit, rad), kept in
    ``memo`` (one load's tables) by the six numbers' bits; a hit is a copy."""
    if memo is None:
        return eulerxyz(*euler)
    table = memo.table("eulerxyz", LOAD_MEMO_LIMIT)
    key = struct.pack("6d", *euler)
    T = table.get(key)
    if T is None:
        T = table[key] = eulerxyz(*euler)
    return T.copy()


def part_size(geometry: Any, solids: tuple[Solid, ...]) -> float:
    """The largest side of a part's axis-aligned bounding box (object frame, cell unit): from
    the mesh file's vertices (world.parts.mesh.mesh_bounds) or the positive primitives."""
    if geometry.mesh_file is not None:
        lo, hi = _mesh_bounds(Path(geometry.mesh_file))
        return float((hi - lo).max()) * geometry.scale
    lo = np.min([s.lo - (s.radius if s.kind == "cylinder" else 0.0) for s in solids], axis=0)
    hi = np.max([s.hi + (s.radius if s.kind == "cylinder" else 0.0) for s in solids], axis=0)
    return float((hi - lo).max())


def _mesh_bounds(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """(min, max) of a mesh file's vertices (its own unit), read without building the mesh: a
    binary or ASCII STL or an OBJ by their vertex records, any other through trimesh."""
    data = path.read_bytes()
    suffix = path.suffix.lower()
    pts: np.ndarray | None = None
    if suffix == ".stl" and len(data) >= 84:
        n = int.from_bytes(data[80:84], "little")
        if len(data) == 84 + 50 * n and n > 0:  # binary: 50-byte records, normal then 3 vertices
            rec = np.frombuffer(data, dtype=np.dtype([("n", "<f4", 3), ("v", "<f4", (3, 3)), ("a", "<u2")]),
                                count=n, offset=84)
            pts = rec["v"].reshape(-1, 3).astype(float)
    if pts is None and suffix in (".stl", ".obj"):
        word = b"vertex" if suffix == ".stl" else b"v"
        rows = [line.split()[1:4] for line in data.splitlines() if line.split()[:1] == [word]]
        try:
            pts = np.array(rows, float) if rows else None
        except ValueError:
            pts = None
    if pts is None or pts.ndim != 2 or pts.shape[1] != 3:
        import trimesh  # a PLY, or a file the readers above do not take (trimesh then says why)

        try:
            return tuple(np.asarray(trimesh.load(str(path), force="mesh").bounds, float))  # type: ignore[return-value]
        except Exception as e:  # trimesh raises many kinds for a bad file
            raise KBError(str(path), "", f"a readable STL, OBJ or PLY mesh ({type(e).__name__})") from None
    return pts.min(axis=0), pts.max(axis=0)


def _check_size(root: Node, path: Path, name: str, geometry: Any, solids: tuple[Solid, ...], unit: str,
                reach: float | None) -> None:
    """KBError when the part is under 1 mm or over 10 m (PART_SIZE_MM), or REACH_RATIO times
    smaller or larger than the arm's ``reach`` (cell unit): naming the file, the part, its
    size and the file's length unit, and asking whether that unit is right."""
    size = part_size(geometry, solids)
    mm = size * LENGTH_UNITS[unit]
    lo_mm, hi_mm = PART_SIZE_MM
    why = None
    if mm < lo_mm:
        why = f"under {lo_mm:g} mm"
    elif mm > hi_mm:
        why = f"over {hi_mm / 1000:g} m"
    elif reach and size < reach / REACH_RATIO:
        why = f"{REACH_RATIO:g}x smaller than the arm's reach ({reach:.4g} {unit})"
    elif reach and size > reach * REACH_RATIO:
        why = f"{REACH_RATIO:g}x larger than the arm's reach ({reach:.4g} {unit})"
    if why is None:
        return
    file_unit = root.key("units").key("length").value
    key = "mesh" if geometry.mesh_file is not None else "shape"
    raise KBError(str(path), key, f"a part of a size in proportion to the cell: {name} is {size:.3g} {unit} across, "
                  f"{why}; is the file's length unit ({file_unit}, units: {{length: {file_unit}}}) "
                  f"the unit its {key} is drawn in?")


def _geometry_error(path: str | Path, geometry: Any, e: Exception) -> KBError:
    """A derivation's failure as one line naming the key: ``face_names.NAME`` for a point off
    the shape, else ``mesh`` or ``shape`` with what was expected (world.parts.mesh raises
    ValueError("expected ...") for the cases it knows; any other exception is named)."""
    key = "mesh" if geometry.mesh_file is not None else "shape"
    msg = " ".join(str(e).split())
    if isinstance(e, ValueError) and msg.startswith("face_names."):
        key, _, msg = msg.partition(": ")
    elif not isinstance(e, ValueError) or not msg:
        msg = f"a shape spar can derive a model from ({type(e).__name__}: {msg[:80]})"
    return KBError(str(path), key, msg.removeprefix("expected "))


def _known(root: Node, faces_node: Node | None, label: str, used: list, known: set, what: str) -> None:
    """A derived entry may only use faces the model lists (when it lists them by hand)."""
    for f in used:
        if f not in known:
            raise (faces_node or root).fail(f"every face the derived {what} {label} uses (add {f}, or leave "
                                            "faces: out to derive them)")


def _grasp_step(root: Node, rad_per: float) -> float:
    """``grasp_step``: the quantum of grasp approaches and assembly turns (file angle unit; 45 deg)."""
    n = root.key("grasp_step", required=False)
    if n is None:
        return math.radians(45.0)
    step = n.positive() * rad_per
    if not (math.radians(1.0) - 1e-12 <= step <= 2 * math.pi + 1e-12):
        raise n.fail("an angle from 1 deg to a full turn", show(n.value))
    return step


def _geometry(root: Node, path: Path, unit: str, scale: float) -> tuple[Any, tuple[Solid, ...]]:
    """The model's declared geometry (world.parts.mesh.Geometry, or None) and its positive solids."""
    mnode, snode = root.key("mesh", required=False), root.key("shape", required=False)
    if mnode is not None and snode is not None:
        raise mnode.fail("mesh: or shape:, not both")
    if mnode is None and snode is None:
        return None, ()
    from spar_py.world.parts import Geometry, Primitive  # only a model with a shape needs it

    if mnode is not None:
        ref = path.parent / mnode.text()
        if ref.suffix.lower() not in (".stl", ".obj", ".ply"):
            raise mnode.fail("the path of an STL, OBJ or PLY file", show(mnode.value))
        if not ref.is_file():
            raise mnode.fail("the path of a mesh file", f"{show(mnode.value)} (no such file)")
        return Geometry(unit, (), str(ref.resolve()), scale), ()
    prims = []
    for n in snode.elements():
        sol = _solid(n, scale)
        kind = "box" if "box" in n.value else "cylinder"
        sub = n.key(kind).key("subtract", required=False)
        subtract = sub is not None and _flag(sub)
        prims.append((Primitive(sol.kind, sol.lo, sol.hi, sol.radius, subtract), sol))
    if prims and all(p.subtract for p, _ in prims):
        raise snode.fail("at least one primitive that is not subtracted")
    return (Geometry(unit, tuple(p for p, _ in prims)) if prims else None,
            tuple(sol for p, sol in prims if not p.subtract))


def _flag(node: Node) -> bool:
    """A ``true`` / ``false`` value."""
    if not isinstance(node.value, bool):
        raise node.fail("true or false", show(node.value))
    return node.value


def _through(fnode: Node) -> bool:
    """A feature's ``through:`` (default false): true only on a hole."""
    tnode = fnode.key("through", required=False)
    if tnode is None or not _flag(tnode):
        return False
    if fnode.key("kind").choice(("peg", "hole")) != "hole":
        raise tnode.fail("through: only on a hole (a peg has one tip)", show(tnode.value))
    return True


def _feature_geometry(fnode: Node, scale: float) -> Any:
    """The geometric form of a feature (world.parts.mesh.FeatureGeometry), or None for the paper's
    form ``{kind, faces, radius, vector}`` (``name:`` then only names the feature); mixing the
    two is an error."""
    if not isinstance(fnode.value, dict):
        raise fnode.fail("a feature {kind, faces, radius, vector} or {kind, name, radius, axis, length}",
                         show(fnode.value))
    geo_keys = [k for k in ("axis", "length") if k in fnode.value]
    old_keys = [k for k in ("faces", "vector") if k in fnode.value]
    if geo_keys and old_keys:
        raise fnode.fail("either {kind, faces, radius, vector} or {kind, name, radius, axis, length}, "
                         f"not {', '.join(old_keys)} with {', '.join(geo_keys)}")
    if not geo_keys:
        fnode.key("faces")
        fnode.key("vector")
        return None
    from spar_py.core.model import FeatureGeometry

    kind = fnode.key("kind").choice(("peg", "hole"))
    name = fnode.key("name").label()
    through = _through(fnode)
    axis = fnode.key("axis")
    d = axis.key("direction").vector(3)
    if np.linalg.norm(d) < 1e-9:
        raise axis.key("direction").fail("a non-zero direction", "[0, 0, 0]")
    d = d / np.linalg.norm(d)
    profile, corners = _profile(fnode, d, scale)
    return FeatureGeometry(kind, name, fnode.key("radius").positive() * scale, axis.key("origin").vector(3) * scale,
                           d, fnode.key("length").positive() * scale, through, profile, corners)


def _profile(fnode: Node, d: np.ndarray, scale: float) -> tuple[str, np.ndarray | None]:
    """A geometric feature's ``profile:`` ('round' by default, or 'prism') and a prism's
    ``corners:`` (at least three offsets from the axis, normal to it, none nearer the axis
    than the radius), scaled to the cell unit."""
    pnode = fnode.key("profile", required=False)
    profile = pnode.choice(("round", "prism")) if pnode is not None else "round"
    cnode = fnode.key("corners", required=False)
    if profile == "round":
        if cnode is not None:
            raise cnode.fail("corners: only with profile: prism")
        return profile, None
    cnode = fnode.key("corners")
    items = list(cnode.elements(3))
    C = np.array([c.vector(3) for c in items], float) * scale
    radius = fnode.key("radius").positive() * scale
    for c, node in zip(C, items):
        if abs(float(c @ d)) > 1e-6 * max(1.0, float(np.linalg.norm(c))) or np.linalg.norm(c) < radius * (1 - 1e-6):
            raise node.fail("a corner offset from the axis, normal to it, at least the radius from it",
                            show(node.value))
    return profile, C


def _solid(node: Node, scale: float) -> Solid:
    """One shape primitive: ``{box: {min: [x,y,z], max: [x,y,z]}}`` or
    ``{cylinder: {radius: r, z: [z0, z1]}}`` (axis = object z)."""
    if isinstance(node.value, dict) and "box" in node.value:
        b = node.key("box")
        lo, hi = b.key("min").vector(3) * scale, b.key("max").vector(3) * scale
        if np.any(lo >= hi):
            raise b.fail("min < max in every coordinate")
        return Solid("box", lo, hi)
    if isinstance(node.value, dict) and "cylinder" in node.value:
        c = node.key("cylinder")
        r = c.key("radius").positive() * scale
        z0, z1 = c.key("z").interval()
        return Solid("cylinder", np.array([-r, -r, z0 * scale]), np.array([r, r, z1 * scale]), r)
    raise node.fail("a shape primitive {box: {min, max}} or {cylinder: {radius, z}}", show(node.value))


def _derive_gripper(unit: str, opening: float | None, gripper: Gripper | None) -> Gripper:
    """The gripper grasps are derived and checked for: the robot's own where given, else the
    default fingers at ``opening`` (or DEFAULT_OPENING_MM) sized as such derivations always were
    (world.robot.Gripper.of_unit)."""
    if gripper is not None:
        return gripper
    return Gripper.of_unit(unit, opening if opening is not None else from_mm(unit, DEFAULT_OPENING_MM))


def check_against_shape(path: str | Path, root: Node, model: ObjectModel, unit: str,
                        opening: float | None = None, gripper: Gripper | None = None) -> None:
    """``spar kb check``: the hand-written faces, stable poses and grasps of a model that also
    gives its geometry must agree with it (world.parts.check_entries); the first
    disagreement is a KBError naming the entry. ``gripper`` is the robot's (cell unit), else the
    default fingers at ``opening`` (cell unit; DEFAULT_OPENING_MM without a robot)."""
    hand = tuple(k for k in DERIVABLE if k in root.value)
    if model.geometry is None or not hand:
        return
    from spar_py.world.parts import check_entries  # on first use: `spar kb check` of a shape only

    grip = _derive_gripper(unit, opening, gripper)
    try:
        problems = check_entries(model, grip, unit, hand)
    except KBError:
        raise
    except Exception as e:  # the shape itself cannot be built or searched
        raise _geometry_error(path, model.geometry, e) from None
    for key, expected, got in problems:
        raise KBError(str(path), key, expected, got)
