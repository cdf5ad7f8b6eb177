"""Product files (``kb/products/*.yaml``) to a :class:`~spar_py.core.model.Product`.

A product names its parts (a model file each and a pose ``{xyz, rpy}`` in the product frame,
as a robot file's ``base``: T = trans(xyz) rpy(r, p, y); identity when left out), its base
part (``base:``, else the first), and its mates: ``{peg: P.f, hole: Q.g, retention: loose |
fixed}`` (loose by default) and seats ``{seat: P.face, on: Q.face}``. Checked here: every
``PART.FEATURE`` and seat face exists, a peg is narrower than its hole, and a mate's features
line up at the product poses (world.products.mate_misalignment); then the goals and the
precedence are compiled (world.products), each refusal one line naming the file and key.
Lengths converted to the cell's unit once, here.
"""
from __future__ import annotations

from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from spar_py.core.errors import KBError, SparValueError, WrongKindError
from spar_py.core.memo import Memo
from spar_py.core.model import Mate, ObjectModel, PartGoal, Product, ProductPart, Seat
from spar_py.core.units import LENGTH_UNITS
from spar_py.kb.node import Node, did_you_mean, show
from spar_py.kb.objects import load_object
from spar_py.kb.reader import MAX_INPUT_BYTES
from spar_py.kb.reader import parse_yaml
from spar_py.kb.schema import KINDS, check_shape, describe, file_kind
from spar_py.kb.values import units_of, xyz_rpy_frame

__all__ = ["RETENTIONS", "add_goal_frames", "goal_term", "load_product", "product_goals", "product_part"]

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


def _mate(node: Node, parts: dict[str, ProductPart], unit: str) -> Mate | Seat:
    """One entry of ``mates:``: a peg-in-hole mate or a seat, checked."""
    from spar_py.world.products import feature_axis, mate_misalignment

    keys = set(node.value)
    if keys <= {"seat", "on"} and keys:
        part, face = _part_ref(node.key("seat"), parts, "FACE")
        on, on_face = _part_ref(node.key("on"), parts, "FACE")
        for k, p, f in (("seat", part, face), ("on", on, on_face)):
            if f not in parts[p].model.faces:
                raise node.key(k).fail(f"a face of {p} ({', '.join(map(str, parts[p].model.faces))})", show(f))
        if part == on:
            raise node.fail("a seat of one part on another", f"{part} on itself")
        return Seat(part, face, on, on_face)
    if not keys <= {"peg", "hole", "retention"} or not {"peg", "hole"} <= keys:
        raise node.fail("a mate {peg: PART.FEATURE, hole: PART.FEATURE, retention: loose | fixed} "
                        "or a seat {seat: PART.FACE, on: PART.FACE}", ", ".join(sorted(keys)))
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
        raise node.fail(f"{peg}.{pf} and {hole}.{hf} lined up at the product poses (coaxial, overlapping)", why)
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


def load_product(path: str | Path, unit: str, max_bytes: int = MAX_INPUT_BYTES, memo: Memo | None = None,
                 **object_options: Any) -> Product:
    """Load ``kb/products/*.yaml`` in the cell's length ``unit``: parts (their models loaded
    with ``object_options``, as kb.problem loads a cell's), base, mates and seats, checked;
    then its goals and precedence compiled (world.products)."""
    from spar_py.world import products as wp

    path = Path(path)
    root = _read_product(path, max_bytes)
    name = root.key("product").label()
    _, mm_per, rad_per = units_of(root)
    scale = mm_per / LENGTH_UNITS[unit]
    parts: dict[str, ProductPart] = {}
    files: list[str] = []
    for pname, pnode in root.key("parts").items():
        mnode = pnode.key("model")
        mpath = path.parent / mnode.text()
        if not mpath.is_file():
            raise mnode.fail("the path of an object file", f"{show(mnode.value)} (no such file)")
        try:
            model = load_object(mpath, unit, max_bytes, memo=memo, **object_options)
        except WrongKindError as e:
            raise mnode.fail("the path of an object file", f"{show(mnode.value)}, {e.got}") from None
        pose = pnode.key("pose", required=False)
        T = xyz_rpy_frame(pose, scale, rad_per) if pose is not None else np.eye(4)
        parts[pname] = ProductPart(pname, _renamed(model, pname), T)
        files.append(str(mpath.resolve()))
    if not parts:
        raise root.key("parts").fail("at least one part", "none")
    bnode = root.key("base", required=False)
    base = bnode.label() if bnode is not None else next(iter(parts))
    if base not in parts:
        raise bnode.fail(f"a part of the product ({', '.join(parts)})", show(base))
    links = [_mate(m, parts, unit) for m in root.key("mates").elements(1)]
    product = Product(name, str(path), base, parts, tuple(m for m in links if isinstance(m, Mate)),
                      tuple(s for s in links if isinstance(s, Seat)), files=tuple(files))
    try:
        product.goals = wp.compile_goals(product)
        product.precedence = wp.precedence(product, unit)
        product.near = wp.near_parts(product, unit)
    except KBError:
        raise
    except SparValueError as e:
        raise root.key("mates").fail("mates that make an assembly", str(e)) from None
    return product


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
    goal, file order), ``mated(Peg, PegFeature, Hole, HoleFeature)`` (the goal of the part whose
    insertion makes that mate); None for any other goal."""
    if isinstance(term, tuple) and term[0] == "assembled" and len(term) == 2:
        if term[1] != product.name:
            raise node.fail(f"assembled({product.name}), the cell's product", show(term[1]))
        return [goal_term(g) for g in product.goals]
    if isinstance(term, tuple) and term[0] == "mated" and len(term) == 5:
        name = f"{term[1]}.{term[2]}->{term[3]}.{term[4]}"
        for g in product.goals:
            if name in g.mates:
                return [goal_term(g)]
        known = ", ".join(m.name for m in product.mates)
        raise node.fail(f"a mate of product {product.name} ({known})", name)
    return None
