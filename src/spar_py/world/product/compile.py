"""A product's geometric compilation: one step from the product as loaded (its parts at their
poses, its mates and seats) to the product the planner uses.

:func:`compile_product` gives the product its goals (the assembly tree), its precedence (the
derivation's disassembly order for a product of meshes, else swept insertions), the
precedence a through-mate adds, each part's neighbours, the via-grasps of the parts mated
into each part and the stable poses of each part with its subtree mated in. The kb loader
reads and validates the product file and calls it once; the product it returns is not
written afterwards.

Lengths in the cell unit; part poses in the product frame.
"""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace
from typing import TYPE_CHECKING

import numpy as np

from spar_py.core.model import Precedence, Product, StablePose
from spar_py.world.product.products import (
    compile_goals, insertion_pairs, near_parts, no_cycle, precedence, subassembly_poses, subtree, through_precedence,
    via_grasps,
)

if TYPE_CHECKING:
    from spar_py.world.product.assembly import AssemblyResult

__all__ = ["compile_product"]


def compile_product(product: Product, unit: str, derived: AssemblyResult | None = None,
                    given: Sequence[tuple[str, str]] = ()) -> Product:
    """``product`` compiled (module docstring); ``derived`` the assembly derivation of a product
    of meshes (its insertion order and precedence), None for declared mates; ``given`` the
    product file's own orderings (A, B): A in place before B arrives, merged with the
    geometry's. SparValueError (one line) where the mates do not make an assembly or the
    orderings form a cycle (naming each ordering of it and why it holds)."""
    dirs = None if derived is None else {p: np.asarray(i.direction, float) for i in derived.insertions for p in i.parts}
    product = replace(product, goals=compile_goals(product, directions=dirs))
    # a derived product's precedence is the disassembly's (exact meshes both ways; the
    # declared products' sweep moves a mesh part's hull, which fills its bores)
    prec = (precedence(product, unit) if derived is None else
            tuple(Precedence(a, b, why) for a, b, why in derived.precedence))
    known = {(pr.first, pr.then) for pr in prec}
    prec += tuple(Precedence(a, b, "the product file orders them") for a, b in dict.fromkeys(given)
                  if (a, b) not in known)
    no_cycle(product, prec)
    # a part whose tree parent is in place first goes into the part that still has a location
    # (the order's pairs where known, else the precedence's; the sweeps do not depend on it)
    first = tuple(dict.fromkeys(
        (insertion_pairs([i.parts for i in derived.insertions]) if derived is not None else ())
        + tuple((pr.first, pr.then) for pr in prec)))
    product = replace(product, goals=compile_goals(product, first, dirs))
    have = {(pr.first, pr.then) for pr in prec}
    product = replace(product, precedence=prec + tuple(pr for pr in through_precedence(product, first)
                                                       if (pr.first, pr.then) not in have))
    product = replace(product, near=near_parts(product, unit))
    return _with_sub_poses(_with_via_grasps(product), unit)


def _with_via_grasps(product: Product) -> Product:
    """Each part with the grasps of the parts that can be mated into it (:func:`via_grasps`),
    and ``via``: which part each such grasp holds by."""
    via = via_grasps(product)
    parts = dict(product.parts)
    for name, got in via.items():
        pp = parts[name]
        grasps = {**pp.model.grasps, **{label: g for label, (_, g) in got.items()}}
        parts[name] = replace(pp, model=replace(pp.model, grasps=grasps))
    return replace(product, parts=parts,
                   via={name: {label: c for label, (c, _) in got.items()} for name, got in via.items()})


def _with_sub_poses(product: Product, unit: str) -> Product:
    """Each part with the stable poses of itself with its product subtree mated in
    (:func:`subassembly_poses`), resting on the part's faces that touch the table there, and
    ``sub_poses``: which parts each such pose needs."""
    subs = subassembly_poses(product, unit)
    parts = dict(product.parts)
    for name, got in subs.items():
        pp = parts[name]
        known = set(pp.model.faces)
        poses = dict(pp.model.poses)
        for sp in got:
            rfaces = tuple(f for f in sp.rfaces if f in known)
            poses[sp.label] = StablePose(sp.label, rfaces, (), sp.R, sp.height)
        parts[name] = replace(pp, model=replace(pp.model, poses=poses))
    sub_poses = {name: {sp.label: tuple(subtree(product, name)) for sp in got} for name, got in subs.items()}
    return replace(product, parts=parts, sub_poses=sub_poses)
