"""Product files (``kb/products/*.yaml``) to a :class:`~spar_py.core.model.Product`.

A product names its parts (a model file each and a pose ``{xyz, rpy}`` in the product frame,
as a robot file's ``base``: T = trans(xyz) rpy(r, p, y); identity when left out), its base
part (``base:``, else the first), and its mates: ``{peg: P.f, hole: Q.g, retention: loose |
fixed}`` (loose by default) and seats ``{seat: P.face, on: Q.face}``. Checked here: every
``PART.FEATURE`` and seat face exists, a peg is narrower than its hole, and a mate's features
line up at the product poses (world.product.products.mate_misalignment); then the goals and the
precedence are compiled (world.product.products), each refusal one line naming the file and key.
Derived mates are loose unless ``retention: {PART: fixed}`` says the mates PART goes in by hold.
Lengths converted to the cell's unit once, here.
"""
from __future__ import annotations

import math
import os
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import yaml

from spar_py.core.errors import KBError, SparValueError, WrongKindError
from spar_py.core.memo import Memo
from spar_py.core.model import Mate, ObjectModel, PartGoal, Product, ProductPart, Seat
from spar_py.core.units import LENGTH_UNITS, from_mm
from spar_py.kb.node import Node, did_you_mean, show
from spar_py.kb.objects import load_object
from spar_py.kb.reader import MAX_INPUT_BYTES
from spar_py.kb.reader import parse_yaml
from spar_py.kb.schema import KINDS, check_shape, describe, file_kind
from spar_py.kb.values import units_of, xyz_rpy_frame

if TYPE_CHECKING:
    from spar_py.world.product import AssemblyResult

__all__ = ["RETENTIONS", "LoadedProduct", "add_goal_frames", "goal_term", "load_product", "load_product_derived",
           "derive_product_text", "is_product_file", "product_goals", "product_part"]

#: A mate's ``retention:`` values, the default first.
RETENTIONS = ("loose", "fixed")


def _part_ref(node: Node, parts: dict[str, ProductPart], what: str) -> tuple[str, str]:
    """``PART.NAME`` split and checked: PART a part of the product."""
    text = node.text()
    part, dot, name = text.partition(".")
    if not dot or not part or not name:
        raise node.fail(f"PART.{what} (a part of the product, a dot, its {what.lower()})", show(text))
    if part not in parts:
        near = did_you_mean(part, parts)
        raise node.fail(f"PART.{what} with a part of the product ({', '.join(parts)})",
                        show(text) + (f"; did you mean {near}?" if near else ""))
    return part, name


def _feature(node: Node, parts: dict[str, ProductPart], kind: str) -> tuple[str, str, Any]:
    """A mate's ``PART.FEATURE``: the part's feature of that name, of ``kind``."""
    part, name = _part_ref(node, parts, "FEATURE")
    model = parts[part].model
    try:
        f = model.feature_named(name)
    except SparValueError:
        known = ", ".join(f.name for f in model.features) or "none"
        raise node.fail(f"a feature of {part} ({known})", show(name)) from None
    if f.kind != kind:
        raise node.fail(f"a {kind} feature of {part}", f"{name}, a {f.kind}")
    if f.geometry is None:
        raise node.fail(f"a feature of {part} declared by geometry (axis, length)", show(name))
    return part, name, f


def _seat_direction(node: Node) -> tuple[float, float, float] | None:
    """A seat's optional ``direction: [x, y, z]`` (product frame; a curved seat's way in), unit."""
    dnode = node.key("direction", required=False)
    if dnode is None:
        return None
    v = dnode.value
    if (not isinstance(v, list) or len(v) != 3 or not all(isinstance(x, (int, float)) and not isinstance(x, bool)
                                                           and math.isfinite(x) for x in v)
            or math.hypot(*v) < 1e-9):
        raise dnode.fail("a direction [x, y, z] of three finite numbers, not all zero", show(v))
    n = math.hypot(*v)
    return (v[0] / n, v[1] / n, v[2] / n)


def _mate(node: Node, parts: dict[str, ProductPart], unit: str) -> Mate | Seat:
    """One entry of ``mates:``: a peg-in-hole mate or a seat, checked."""
    from spar_py.world.product import feature_axis, mate_misalignment

    keys = set(node.value)
    if {"seat", "on"} <= keys <= {"seat", "on", "direction"}:
        part, face = _part_ref(node.key("seat"), parts, "FACE")
        on, on_face = _part_ref(node.key("on"), parts, "FACE")
        for k, p, f in (("seat", part, face), ("on", on, on_face)):
            if f not in parts[p].model.faces:
                raise node.key(k).fail(f"a face of {p} ({', '.join(map(str, parts[p].model.faces))})", show(f))
        if part == on:
            raise node.fail("a seat of one part on another", f"{part} on itself")
        return Seat(part, face, on, on_face, _seat_direction(node))
    if not keys <= {"peg", "hole", "retention"} or not {"peg", "hole"} <= keys:
        raise node.fail("a mate {peg: PART.FEATURE, hole: PART.FEATURE, retention: loose | fixed} "
                        "or a seat {seat: PART.FACE, on: PART.FACE, direction: [X, Y, Z] (optional)}",
                        ", ".join(sorted(keys)))
    peg, pf, fp = _feature(node.key("peg"), parts, "peg")
    hole, hf, fh = _feature(node.key("hole"), parts, "hole")
    if peg == hole:
        raise node.fail("a mate between two parts", f"{peg} with itself")
    rnode = node.key("retention", required=False)
    retention = rnode.choice(RETENTIONS) if rnode is not None else RETENTIONS[0]
    if fp.radius >= fh.radius:
        raise node.fail(f"a peg narrower than its hole (peg {peg}.{pf} radius {fp.radius:.4g} {unit}, "
                        f"hole {hole}.{hf} radius {fh.radius:.4g} {unit})")
    why = mate_misalignment(feature_axis(parts[peg].pose, fp), feature_axis(parts[hole].pose, fh),
                            bool(getattr(fh, "through", False)), unit)
    if why is not None:
        raise node.fail(f"{peg}.{pf} and {hole}.{hf} lined up at the product poses (coaxial within the clearance, "
                        "overlapping)", why)
    return Mate(peg, pf, hole, hf, retention)


def _renamed(model: ObjectModel, name: str) -> ObjectModel:
    """The model as part ``name``: its name, and its stable pose and grasp labels that start
    with the model's name (derived ones) starting with the part's instead (labels name one
    part's entries: two pins from one model are two parts)."""
    if model.name == name:
        return model

    def label(s: str) -> str:
        return name + s[len(model.name):] if s.startswith(model.name) else f"{name}_{s}"
    poses = {label(k): replace(p, label=label(k)) for k, p in model.poses.items()}
    grasps = {label(k): replace(g, label=label(k)) for k, g in model.grasps.items()}
    return replace(model, name=name, poses=poses, grasps=grasps)


def _read_product(path: Path, max_bytes: int) -> Node:
    """The product file's root, checked against its schema (kb.schema.read_kb), with a seat's
    ``on:`` key read as written: YAML 1.1 reads a bare ``on`` as the boolean true."""
    data = parse_yaml(path, max_bytes)
    if isinstance(data, dict) and isinstance(data.get("mates"), list):
        data["mates"] = [{("on" if k is True else k): v for k, v in m.items()} if isinstance(m, dict) else m
                         for m in data["mates"]]
    root = Node(str(path), "", data)
    got = file_kind(root) if isinstance(data, dict) else None
    want = KINDS["product"]
    if got is not want:
        what = f"a mapping without `{want.marker}:`" if isinstance(data, dict) and got is None else describe(data)
        raise WrongKindError(str(path), "", want.wanted, what)
    check_shape(root, want.schema)
    return root


@dataclass(frozen=True)
class _MeshPart:
    """A part given by ``mesh:``: its node, the mesh file, its length unit (the part's
    ``units:``, else the product's: mm per unit) and its pose (cell unit)."""

    node: Node
    file: Path
    unit: str
    mm_per: float
    pose: np.ndarray


def _tolerance(root: Node, key: str, default_mm: float, scale: float, unit: str) -> float:
    """A product's ``contact_tol`` or ``clearance_max`` (product units) in the cell unit."""
    node = root.key(key, required=False)
    return node.positive() * scale if node is not None else from_mm(unit, default_mm)


def _derived_objects(path: Path, unit: str, meshparts: dict[str, _MeshPart], derived: AssemblyResult | None,
                     declared_pairs: set[frozenset[str]], plane_tol: float, raw: dict[str, Any]
                     ) -> tuple[dict[str, str], dict[tuple[int, str], str]]:
    """The object YAML text of each mesh part (its mesh, its declared ``features:`` and
    ``face_names:``, and the derived features and seat faces it lacks) and the name of the
    feature each derived mate uses on each part, keyed (mate index, part), and of the face
    each derived seat uses, keyed (-1 - seat index, part); coplanar seat faces share a name."""
    texts: dict[str, str] = {}
    names: dict[tuple[int, str], str] = {}
    for pname, mp in meshparts.items():
        k = LENGTH_UNITS[unit] / mp.mm_per  # cell unit -> the part's unit
        inv = np.linalg.inv(mp.pose)
        own = [dict(f) for f in (mp.node.value.get("features") or [])]
        face_names = dict(mp.node.value.get("face_names") or {})
        feats: list[dict[str, Any]] = []
        for i, m in enumerate(derived.mates if derived else []):
            if pname not in (m.peg, m.hole) or frozenset((m.peg, m.hole)) in declared_pairs:
                continue
            peg = pname == m.peg
            d = np.asarray(m.axis, float)
            t0, length = (m.peg_t0, m.peg_len) if peg else (m.hole_t0, m.hole_len)
            axis_at = np.asarray(m.origin, float) + (0.0 if peg else np.asarray(m.hole_shift, float))  # its own axis
            o = inv[:3, :3] @ (axis_at + t0 * d) + inv[:3, 3]
            dd = inv[:3, :3] @ d
            f = {"kind": "peg" if peg else "hole", "radius": _num(k * (m.peg_radius if peg else m.hole_radius)),
                 "axis": {"origin": [_num(k * x) for x in o], "direction": [_num(x) for x in dd]},
                 "length": _num(k * length)}
            if not peg and m.through:
                f["through"] = True
            if m.profile != "round":
                f["profile"] = m.profile
                f["corners"] = [[_num(k * x) for x in inv[:3, :3] @ np.asarray(c, float)]
                                for c in (m.corners if peg else m.hole_corners)]
            same = next((g for g in feats + own if _same_feature(g, f, k)), None)
            if same is None:
                f = {"kind": f["kind"], "name": f"{f['kind']}{sum(g['kind'] == f['kind'] for g in feats) + 1}",
                     **{x: f[x] for x in f if x != "kind"}}
                feats.append(f)
                same = f
            names[i, pname] = str(same["name"])
        seats = [(j, s) for j, s in enumerate(derived.seats if derived else [])
                 if pname in (s.part, s.on) and frozenset((s.part, s.on)) not in declared_pairs]
        if seats:
            from spar_py.world.parts import derive_faces, face_of_point

            mesh = _raw_mesh(pname, mp, unit, raw)
            faces = derive_faces(mesh, (), {}, unit)
            named: dict[int, str] = {}
            for j, s in seats:
                other = s.on if pname == s.part else s.part
                pt = inv[:3, :3] @ np.asarray(s.point, float) + inv[:3, 3]
                fi = face_of_point(faces, mesh, pt, plane_tol + s.gap / 2)
                if fi is None or (s.direction is None and not faces[fi].planar):
                    continue  # a planar seat on a face that is not one plane: a contact only
                if fi not in named:
                    named[fi] = f"on_{other}" if pname == s.part else f"under_{other}"
                    if s.gap > 0:  # a curved seat's point lies midway across its fit: onto the face
                        pt = _onto(mesh, faces[fi].tris, pt)
                    face_names.setdefault(named[fi], [_num(k * x) for x in pt])
                names[-1 - j, pname] = named[fi]
        data: dict[str, Any] = {"object": pname, "units": {"length": mp.unit, "angle": "deg"},
                                "mesh": str(mp.file)}
        if face_names:
            data["face_names"] = face_names
        if own or feats:
            data["features"] = own + feats
        texts[pname] = yaml.safe_dump(data, sort_keys=False, default_flow_style=None)
    return texts, names


def _onto(mesh: Any, tris: np.ndarray, p: np.ndarray) -> np.ndarray:
    """The point of the mesh's triangles ``tris`` nearest ``p``."""
    import trimesh

    T = mesh.triangles[tris]
    c = trimesh.triangles.closest_point(T, np.repeat(np.asarray(p, float)[None], len(T), 0))
    return c[int(np.argmin(np.linalg.norm(c - p, axis=1)))]


def _num(v: float) -> float:
    """A length or component for a written file: 9 decimals, no negative zero."""
    return round(float(v), 9) + 0.0


def _same_feature(g: dict[str, Any], f: dict[str, Any], k: float) -> bool:
    """Whether feature dicts ``g`` and ``f`` (one part's, its units) are one: same kind,
    radius (within 1e-4 of it) and axis line (within 1e-2 of the radius: one shaft fitted
    against two parts' samples), and spans along it that overlap."""
    if g.get("kind") != f["kind"] or "axis" not in g:
        return False
    tol = 1e-6 * max(float(f["radius"]), 1.0) + 1e-3 * k * 1e-3
    if abs(float(g["radius"]) - float(f["radius"])) > max(tol, 1e-4 * float(f["radius"])):
        return False
    d1 = np.asarray(g["axis"]["direction"], float)
    d2 = np.asarray(f["axis"]["direction"], float)
    d1, d2 = d1 / np.linalg.norm(d1), d2 / np.linalg.norm(d2)
    off = np.asarray(g["axis"]["origin"], float) - np.asarray(f["axis"]["origin"], float)
    if abs(float(d1 @ d2)) <= 1 - 1e-6 or float(np.linalg.norm(off - (off @ d2) * d2)) >= 1e-2 * float(f["radius"]):
        return False
    if "length" not in g:
        return True
    # one line, but apart along it (a post's two tenons, one at each end) is two features
    og, of = np.asarray(g["axis"]["origin"], float) @ d2, np.asarray(f["axis"]["origin"], float) @ d2
    sg = sorted((og, og + float(g["length"]) * float(d1 @ d2)))
    sf = sorted((of, of + float(f["length"])))
    return min(sg[1], sf[1]) - max(sg[0], sf[0]) > tol


def _generated(text: str) -> Path:
    """Where a mesh part's object YAML is kept: by its content, beside the derivations."""
    import hashlib  # OpenSSL's hashes load at import: only a mesh part's model needs them

    from spar_py.world.parts import cache_dir

    out = cache_dir() / "parts" / f"{hashlib.sha256(text.encode()).hexdigest()[:32]}.yaml"
    if not out.is_file() or out.read_text(encoding="utf-8") != text:
        out.parent.mkdir(parents=True, exist_ok=True)
        tmp = out.with_suffix(f".tmp{os.getpid()}")
        tmp.write_text(text, encoding="utf-8")
        os.replace(tmp, out)
    return out


@dataclass
class LoadedProduct:
    """A product with what was derived for it (None when every part gives ``model:``) and
    the derived names of each derived mate's features."""

    product: Product
    derived: AssemblyResult | None
    objects: dict[str, str]
    unit: str


def load_product(path: str | Path, unit: str, max_bytes: int = MAX_INPUT_BYTES, memo: Memo | None = None,
                 **object_options: Any) -> Product:
    """Load ``kb/products/*.yaml`` in the cell's length ``unit``: parts (their models loaded
    with ``object_options``, as kb.problem loads a cell's), base, mates and seats, checked;
    then its goals and precedence compiled (world.product.products). Parts given by ``mesh:`` have
    their features, mates, seats and precedence derived (world.product.assembly)."""
    return load_product_derived(path, unit, max_bytes, memo, **object_options).product


def load_product_derived(path: str | Path, unit: str, max_bytes: int = MAX_INPUT_BYTES, memo: Memo | None = None,
                         **object_options: Any) -> LoadedProduct:
    """:func:`load_product` with what was derived (``spar kb derive`` writes it out)."""
    from spar_py.world.product import compile_product  # the world layer on first use

    path = Path(path)
    root = _read_product(path, max_bytes)
    name = root.key("product").label()
    _, mm_per, rad_per = units_of(root)
    scale = mm_per / LENGTH_UNITS[unit]
    parts: dict[str, ProductPart] = {}
    files: list[str] = []
    meshparts: dict[str, _MeshPart] = {}
    pnodes = dict(root.key("parts").items())
    if not pnodes:
        raise root.key("parts").fail("at least one part", "none")
    for pname, pnode in pnodes.items():
        has = [k for k in ("model", "mesh") if k in pnode.value]
        if len(has) != 1:
            raise pnode.fail("a part with model: FILE or mesh: FILE (one of them)",
                             "both" if has else ", ".join(pnode.value) or "neither")
        pose = pnode.key("pose", required=False)
        if "mesh" in pnode.value:
            mnode = pnode.key("mesh")
            mpath = path.parent / mnode.text()
            if not mpath.is_file():
                raise mnode.fail("the path of a mesh file (STL, OBJ or PLY)", f"{show(mnode.value)} (no such file)")
            if "units" in pnode.value:
                punit, pmm, _ = units_of(pnode)
            else:
                punit, pmm = root.key("units").key("length").text(), mm_per
            T = xyz_rpy_frame(pose, scale, rad_per) if pose is not None else np.eye(4)
            meshparts[pname] = _MeshPart(pnode, mpath.resolve(), punit, pmm, T)
            continue
        for k in ("features", "face_names", "units"):
            if k in pnode.value:
                raise pnode.key(k).fail(f"no {k}: beside model: (the object file gives them)")
        mnode = pnode.key("model")
        mpath = path.parent / mnode.text()
        if not mpath.is_file():
            raise mnode.fail("the path of an object file", f"{show(mnode.value)} (no such file)")
        try:
            model = load_object(mpath, unit, max_bytes, memo=memo, **object_options)
        except WrongKindError as e:
            raise mnode.fail("the path of an object file", f"{show(mnode.value)}, {e.got}") from None
        T = xyz_rpy_frame(pose, scale, rad_per) if pose is not None else np.eye(4)
        parts[pname] = ProductPart(pname, _renamed(model, pname), T)
        files.append(str(mpath.resolve()))
    bnode = root.key("base", required=False)
    base = bnode.label() if bnode is not None else next(iter(pnodes))
    if base not in pnodes:
        raise bnode.fail(f"a part of the product ({', '.join(pnodes)})", show(base))
    mates_node = root.key("mates", required=False)
    mate_nodes = list(mates_node.elements(1)) if mates_node is not None else []
    if mates_node is None and not meshparts:
        root.key("mates")  # raises: a product of models declares its mates
    declared_pairs = set()
    for m in mate_nodes:
        ends = [str(m.value.get(k, "")).partition(".")[0] for k in ("peg", "hole", "seat", "on") if k in m.value]
        declared_pairs.add(frozenset(ends))
    derived = None
    objects: dict[str, str] = {}
    dnames: dict[tuple[int, str], str] = {}
    if meshparts:
        raw: dict[str, Any] = {}  # each mesh part's file read once, in its own frame (cell unit)
        derived = _derive(root, unit, scale, base, meshparts, parts, raw, bool(object_options.get("use_cache", True)))
        _refuse_stuck(root, unit, scale, derived, meshparts, parts)
        objects, dnames = _derived_objects(path, unit, meshparts, derived, declared_pairs,
                                           2 * _tolerance(root, "contact_tol", 0.1, scale, unit), raw)
        for pname, text in objects.items():
            mp = meshparts[pname]
            try:
                model = load_object(_generated(text), unit, max_bytes, memo=memo, **object_options)
            except KBError as e:
                why = f"{e.key}: expected {e.expected}" + (f", not {e.got}" if e.got is not None else "")
                raise mp.node.key("mesh").fail("a mesh part the planner can use", why) from None
            parts[pname] = ProductPart(pname, model, mp.pose)
            files.append(str(mp.file))
        parts = {p: parts[p] for p in pnodes}
    links = [_mate(m, parts, unit) for m in mate_nodes]
    held = _retention_overrides(root, base, derived)
    if derived is not None:
        for i, dm in enumerate(derived.mates):
            pf, hf = dnames.get((i, dm.peg)), dnames.get((i, dm.hole))
            if pf is not None and hf is not None:
                links.append(Mate(dm.peg, pf, dm.hole, hf, held.get(_inserted_by(dm, derived), RETENTIONS[0])))
        for j, s in enumerate(derived.seats):
            sf, of = dnames.get((-1 - j, s.part)), dnames.get((-1 - j, s.on))
            if sf is not None and of is not None:
                links.append(Seat(s.part, sf, s.on, of, s.direction))
    product = Product(name, str(path), base, parts, tuple(m for m in links if isinstance(m, Mate)),
                      tuple(s for s in links if isinstance(s, Seat)), files=tuple(files))
    where = root.key("mates") if mates_node is not None else root.key("parts")
    given = _given_precedence(root, pnodes)
    if given:
        where = root.key("precedence")
    try:
        product = compile_product(product, unit, derived, given)  # the one geometric step (world.product)
    except KBError:
        raise
    except SparValueError as e:
        raise where.fail("mates that make an assembly", str(e) + _unlinked_contacts(product, derived)) from None
    return LoadedProduct(product, derived, objects, unit)


def _given_precedence(root: Node, parts: Any) -> tuple[tuple[str, str], ...]:
    """The product file's ``precedence: [[A, B], ...]``: A in place before B arrives (part names);
    a KBError naming the pair if it is not two different parts of the product."""
    node = root.key("precedence", required=False)
    if node is None:
        return ()
    out = []
    for pair in node.elements(1):
        items = pair.elements(2)
        names = [i.label() for i in items]
        for i, n in zip(items, names):
            if n not in parts:
                raise i.fail(f"a part of the product ({', '.join(parts)})", show(n))
        if len(names) != 2 or names[0] == names[1]:
            raise pair.fail("a pair [A, B] of two different parts (A in place before B is inserted)",
                            show(pair.value))
        out.append((names[0], names[1]))
    return tuple(out)


def _inserted_by(dm: Any, derived: AssemblyResult) -> str:
    """The part whose insertion makes derived mate ``dm``: of its two parts, the later one in the
    derived order (the base is never inserted)."""
    order = {p: i for i, ins in enumerate(derived.insertions) for p in ins.parts}
    return max((dm.peg, dm.hole), key=lambda p: order.get(p, -1))


def _retention_overrides(root: Node, base: str, derived: AssemblyResult | None) -> dict[str, str]:
    """The product file's ``retention: {PART: loose | fixed}``: the retention of the derived mates
    PART is put in by (a press fit, a snap: ``fixed``); derived mates are loose otherwise. Each
    key a mesh part other than the base, each value one of RETENTIONS."""
    rnode = root.key("retention", required=False)
    if rnode is None:
        return {}
    inserted = {p for ins in (derived.insertions[1:] if derived is not None else ()) for p in ins.parts}
    out: dict[str, str] = {}
    for part, v in rnode.items():
        if part not in inserted:
            near = did_you_mean(part, inserted)
            what = ("the base (never inserted: the mates into it are its parts')" if part == base
                    else f"{show(part)}" + (f"; did you mean {near}?" if near else ""))
            raise v.fail(f"a mesh part inserted by a derived mate ({', '.join(sorted(inserted)) or 'none'})", what)
        out[part] = v.choice(RETENTIONS)
    return out


def _unlinked_contacts(product: Product, derived: AssemblyResult | None) -> str:
    """For a refusal: the derived contacts between the parts linked to the base (by mates and
    seats) and the rest, each neither a mate nor a seat the planner can use ('' if none)."""
    if derived is None:
        return ""
    linked = {product.base}
    pairs = [(m.peg, m.hole) for m in product.mates] + [(s.part, s.on) for s in product.seats]
    grew = True
    while grew:
        grew = False
        for a, b in pairs:
            if (a in linked) != (b in linked):
                linked |= {a, b}
                grew = True
    cut = [f"{a} - {b}" for a, b, _ in derived.blocking if (a in linked) != (b in linked)]
    if not cut:
        return ""
    return (f"; they touch the rest only in contacts that are neither a mate nor a planar seat "
            f"(a cradle, a guide, a fit that is neither round nor prism): {', '.join(cut)}")


def _raw_mesh(pname: str, mp: _MeshPart, unit: str, raw: dict[str, Any]) -> Any:
    """Mesh part ``pname`` as its file gives it, in its own frame and the cell unit, read once
    per load into ``raw`` (its repair is said when the part's model loads); KBError naming the
    file's key if it cannot be read or closed."""
    from spar_py.world.parts import load_mesh

    if pname not in raw:
        try:
            raw[pname] = load_mesh(str(mp.file), mp.mm_per / LENGTH_UNITS[unit])[0]
        except ValueError as e:
            raise mp.node.key("mesh").fail(str(e), show(mp.node.value["mesh"])) from None
    return raw[pname]


def _derive(root: Node, unit: str, scale: float, base: str, meshparts: dict[str, _MeshPart],
            parts: dict[str, ProductPart], raw: dict[str, Any], use_cache: bool = True) -> AssemblyResult:
    """The derivation (world.product.assembly, cached) over every part's mesh at its product pose,
    the mesh parts read from their files in the cell unit (kept in ``raw``, :func:`_raw_mesh`)."""
    from spar_py.world.product import AXIS_TOL_MM, derive_assembly_cached
    from spar_py.world.parts import part_mesh

    contact_tol = _tolerance(root, "contact_tol", 0.1, scale, unit)
    clearance_max = _tolerance(root, "clearance_max", 0.5, scale, unit)
    meshes = {}
    for pname in root.key("parts").value:
        if pname in meshparts:
            mp = meshparts[pname]
            m = _raw_mesh(pname, mp, unit, raw).copy()
            m.apply_transform(mp.pose)
        else:
            pm = part_mesh(parts[pname].model)
            if pm is None:
                continue  # a part without a shape takes no part in the derivation
            m = pm.copy()
            m.apply_transform(parts[pname].pose)
        meshes[pname] = m
    return derive_assembly_cached(meshes, base, contact_tol, clearance_max, use_cache, from_mm(unit, AXIS_TOL_MM))


def _refuse_stuck(root: Node, unit: str, scale: float, derived: AssemblyResult, meshparts: dict[str, _MeshPart],
                  parts: dict[str, ProductPart]) -> None:
    """One line naming the parts the derivation found overlapping as placed (the largest overlap,
    what meets where, the others' pairs), or stuck (no way out found); lengths and volumes in
    the product file's unit (``scale``: cell units per product unit)."""
    pu = root.key("units").key("length").text()
    if derived.overlaps:
        tol = _tolerance(root, "contact_tol", 0.1, scale, unit)
        o, *more = derived.overlaps
        sides = [(o.a, o.wall_a), (o.b, o.wall_b)]
        if o.wall_a.kind == "hole" and o.wall_b.kind == "peg":
            sides.reverse()  # the peg's part first
        line = (f"{sides[0][0]} and {sides[1][0]} overlap by {o.volume / scale ** 3:.3g} {pu}^3 where "
                + _overlap_where(*sides, _declared_axes(meshparts, parts, unit), tol, scale, pu))
        if more:
            line += "; also " + ", ".join(f"{x.a} and {x.b} ({x.volume / scale ** 3:.3g} {pu}^3)" for x in more)
        raise root.key("parts").fail("parts that touch without overlapping as placed", line)
    if derived.unremovable:
        raise root.key("parts").fail(
            "parts that each have a way out of the assembled product",
            f"{', '.join(derived.unremovable)} without one (none found alone or with the parts they touch, along "
            f"the product frame's axes and the fits' axes)")


def _declared_axes(meshparts: dict[str, _MeshPart], parts: dict[str, ProductPart], unit: str
                   ) -> dict[str, list[tuple[str, str, float, np.ndarray, np.ndarray]]]:
    """Each part's declared round features as (name, kind, radius, a point on the axis, unit
    direction), product frame and cell unit: a model part's from its model, a mesh part's from
    its ``features:`` as written (its unit and frame; an entry that does not read is left out,
    its model's load says what is wrong with it)."""
    out: dict[str, list[tuple[str, str, float, np.ndarray, np.ndarray]]] = {}
    for p, mp in meshparts.items():
        out[p] = []
        k = mp.mm_per / LENGTH_UNITS[unit]  # the part's unit -> the cell unit
        for f in mp.node.value.get("features") or []:
            try:
                o = np.asarray(f["axis"]["origin"], float).reshape(3) * k
                d = np.asarray(f["axis"]["direction"], float).reshape(3)
                r, name, kind = float(f["radius"]) * k, str(f["name"]), str(f["kind"])
            except (KeyError, TypeError, ValueError):
                continue
            if np.linalg.norm(d) > 0 and f.get("profile", "round") == "round":
                out[p].append((name, kind, r, mp.pose[:3, :3] @ o + mp.pose[:3, 3],
                               mp.pose[:3, :3] @ d / np.linalg.norm(d)))
    for p, part in parts.items():
        out[p] = []
        for f in part.model.features:
            g = f.geometry
            if g is not None and g.profile == "round":
                out[p].append((f.name, g.kind, float(g.radius), part.pose[:3, :3] @ g.origin + part.pose[:3, 3],
                               part.pose[:3, :3] @ g.direction))
    return out


def _overlap_where(a: tuple[str, Any], b: tuple[str, Any], axes: dict[str, list[tuple[str, str, float, np.ndarray,
                                                                                     np.ndarray]]],
                   tol: float, scale: float, pu: str) -> str:
    """Where two parts overlap, for the one line: ``a`` and ``b`` each a part and its wall inside
    the other (world.product.overlap.Wall, cell unit); each wall by the part's declared feature's
    name (same kind, radius and axis within ``tol``) or by its kind and radius, else the surface
    by a point; then the axes."""
    def n(x: float) -> str:
        return f"{round(x / scale, 6) + 0.0:.4g}"

    def vec(v: Any, s: float = 1.0) -> str:
        return "(" + ", ".join(f"{round(x / s, 6) + 0.0:.4g}" for x in v) + ")"

    def name(part: str, w: Any) -> str:
        if w.kind == "surface":
            return f"{part}'s surface near {vec(w.point, scale)}"
        p, d = np.asarray(w.point, float), np.asarray(w.axis, float)
        for fname, kind, r, fo, fd in axes.get(part, []):
            off = p - fo
            if (kind == w.kind and abs(r - w.radius) <= tol and abs(float(fd @ d)) > math.cos(math.radians(1.0))
                    and float(np.linalg.norm(off - (off @ fd) * fd)) <= tol):
                return f"{part}'s {fname}"
        return f"{part}'s {w.kind} (r {n(w.radius)} {pu})"
    (pa_name, wa), (pb_name, wb) = a, b
    text = f"{name(pa_name, wa)} meets {name(pb_name, wb)}"
    if wa.kind == "surface" or wb.kind == "surface":
        return text
    pa, pb, d = np.asarray(wa.point, float), np.asarray(wb.point, float), np.asarray(wa.axis, float)
    off = pb - pa
    apart = float(np.linalg.norm(off - (off @ d) * d))
    if abs(float(d @ np.asarray(wb.axis, float))) < math.cos(math.radians(1.0)):
        return text + f", axes along {vec(d)} and {vec(wb.axis)}"
    if apart <= tol:
        return text + f" about the axis through {vec(pa, scale)} along {vec(d)}"
    return text + f", axes {n(apart)} {pu} apart (through {vec(pa, scale)} and {vec(pb, scale)} along {vec(d)})"


def product_part(onode: Node, product: Product, name: str) -> ObjectModel:
    """A problem's object that is a part of ``product``: its model is the product's (a
    ``model:`` beside it is refused: one model per part)."""
    mnode = onode.key("model", required=False)
    if mnode is not None:
        raise mnode.fail(f"no model: for {name}, a part of product {product.name} (its model comes from the product)",
                         show(mnode.value))
    return product.parts[name].model


def add_goal_frames(node: Node, product: Product, transforms: dict, vectors: dict) -> None:
    """Put each part goal's T_a and V_a (``trans_PART``, ``vec_PART``) among the cell's named
    transforms and vectors; a name the problem file already uses is refused."""
    for g in product.goals:
        for name, table, value in ((g.ta, transforms, g.T_a), (g.va, vectors, g.V_a)):
            if name in table:
                raise node.fail(f"transforms: and vectors: free of the product's names ({name} is taken)")
            table[name] = value


def goal_term(g: PartGoal) -> tuple:
    """A part goal as the planner's ``assembled(Part, Parent, [[PartFaces], [ParentFaces]], Ta, Va)``."""
    return ("assembled", g.part, g.parent, [list(g.part_faces), list(g.parent_faces)], g.ta, g.va)


def product_goals(node: Node, term: Any, product: Product) -> list[tuple] | None:
    """A problem goal about the product as the planner's goals: ``assembled(KIT)`` (every part
    goal, file order), ``mated(Peg, PegFeature, Hole, HoleFeature)`` (the goal of the part that
    goes into the other, else the goals of both parts, file order: the mate is made once both
    are in place, by whichever insertion comes later); None for any other goal."""
    if isinstance(term, tuple) and term[0] == "assembled" and len(term) == 2:
        if term[1] != product.name:
            raise node.fail(f"assembled({product.name}), the cell's product", show(term[1]))
        return [goal_term(g) for g in product.goals]
    if isinstance(term, tuple) and term[0] == "mated" and len(term) == 5:
        name = f"{term[1]}.{term[2]}->{term[3]}.{term[4]}"
        mate = next((m for m in product.mates if m.name == name), None)
        if mate is None:
            known = ", ".join(m.name for m in product.mates)
            raise node.fail(f"a mate of product {product.name} ({known})", name)
        # a goal into the other part makes the mate by itself; else it holds once both parts are in place
        ends = {mate.peg, mate.hole}
        direct = next((g for g in product.goals if {g.part, g.parent} == ends), None)
        return [goal_term(direct)] if direct is not None else [goal_term(g) for g in product.goals if g.part in ends]
    return None


def is_product_file(path: str | Path, max_bytes: int = MAX_INPUT_BYTES) -> bool:
    """Whether ``path`` is a product file (a mapping with ``product:``); False for anything else."""
    try:
        data = parse_yaml(Path(path), max_bytes)
    except (KBError, OSError):
        return False
    return isinstance(data, dict) and "product" in data


def derive_product_text(path: str | Path, max_bytes: int = MAX_INPUT_BYTES, out_dir: str | Path | None = None) -> str:
    """``spar kb derive PRODUCT.yaml``: the product in the declared form, in the file's units:
    each mesh part with its features and face names (derived ones included), every mate
    with its retention and every seat; the derived insertions (order, direction, whether a
    fixture is needed), precedence and whether one arm on a table can build it
    (world.product.single_arm) as comments. Mesh paths relative to ``out_dir``."""
    path = Path(path)
    root = _read_product(path, max_bytes)
    unit = root.key("units").key("length").text()
    lp = load_product_derived(path, unit, max_bytes)
    p = lp.product
    base_dir = Path(out_dir).resolve() if out_dir is not None else path.parent.resolve()

    def flow(v: Any) -> str:
        return yaml.safe_dump(v, default_flow_style=True, width=10**6, sort_keys=False).strip().removesuffix(
            "\n...").strip()
    out = [f"# Derived by `spar kb derive` from {path}: features, mates and seats explicit.",
           f"product: {p.name}", f"units: {flow(root.value['units'])}"]
    out += [f"{k}: {flow(root.value[k])}" for k in ("base", "contact_tol", "clearance_max") if k in root.value]
    out.append("parts:")
    for pname, pnode in root.key("parts").items():
        own = dict(pnode.value)
        if pname in lp.objects:
            obj = yaml.safe_load(lp.objects[pname])
            own["mesh"] = os.path.relpath(obj["mesh"], base_dir)
            for k in ("face_names", "features"):
                if k in obj:
                    own[k] = obj[k]
        else:
            own["model"] = os.path.relpath((path.parent / own["model"]).resolve(), base_dir)
        out.append(f"  {pname}: {flow(own)}")
    out.append("mates:")
    for m in p.mates:
        out.append("  - " + flow({"peg": f"{m.peg}.{m.peg_feature}", "hole": f"{m.hole}.{m.hole_feature}",
                                  "retention": m.retention}))
    for s in p.seats:
        seat: dict[str, Any] = {"seat": f"{s.part}.{s.face}", "on": f"{s.on}.{s.on_face}"}
        if s.direction is not None:
            seat["direction"] = [_num(x) for x in s.direction]
        out.append("  - " + flow(seat))
    d = lp.derived
    if d is not None:
        out.append(f"# derived in {d.seconds:.2f} s; insertions in order (direction in the product frame):")
        for i, ins in enumerate(d.insertions):
            what = " + ".join(ins.parts)
            if i == 0:
                out.append(f"#   {what}: the base, placed first")
                continue
            extra = "; points up in every stable pose of the partial product: needs a fixture or a second arm" \
                if ins.needs_fixture else ""
            out.append(f"#   {what}: along {[_num(x) for x in ins.direction]}{extra}")
        for a, b, why in d.precedence:
            out.append(f"# precedence: {a} before {b} ({why})")
        for a, b, n in d.blocking:
            out.append(f"# contact {a} - {b} ({n} samples): neither a mate nor a seat; blocking only")
        if d.unremovable:
            out.append(f"# no free direction found for: {', '.join(d.unremovable)}")
    from spar_py.world.product import single_arm_report

    sa = single_arm_report(p, unit)
    if sa is not None:
        order = f"# one arm on a table builds it in order {', '.join(sa.order)}"
        out.append(f"# {sa.why}" if not sa.ok else order + (f", sideways: {'; '.join(sa.level)}" if sa.level else ""))
    if sa is None or sa.ok:
        from spar_py.core.units import mm_per
        from spar_py.kb.objects import DEFAULT_OPENING_MM
        from spar_py.world.product import grasp_report
        from spar_py.world.robot import Gripper

        gr = grasp_report(p, Gripper.default(from_mm(unit, DEFAULT_OPENING_MM), mm_per(unit)), unit)
        if gr is not None:
            out.append(f"# grasps (default gripper, no robot): {gr.why}" if not gr.ok else
                       "# grasps (default gripper, no robot): every part keeps one usable for its mate, clear of the "
                       "parts in place and free at pickup")
    return "\n".join(out) + "\n"
