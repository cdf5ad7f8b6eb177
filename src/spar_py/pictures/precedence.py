"""A derived product's precedence graph as Graphviz DOT text (drawn as the plan's ordering graph).

One node per insertion of :class:`~spar_py.world.product.assembly.AssemblyResult` (its parts, its place
in the derived order, its direction in the product frame and the parts it mates with), the
base on top; an edge ``first -> then`` per precedence, labelled and tooltipped with its reason.
As in :func:`~spar_py.pictures.graphs.ordering_dot`: solid edges form the transitive reduction,
edges a longer chain implies are dashed. An insertion that needs a fixture or a second arm
(it points up in every stable pose of the partial product) is filled red and says so; the
base is filled grey. Rendering is :func:`~spar_py.pictures.graphs.render_png` (``dot -Tpng``).
"""
from __future__ import annotations

import textwrap
from typing import TYPE_CHECKING

from spar_py.pictures.graphs import ACTION_FILL, dot_attrs, dot_header, dot_id, implied_edges

if TYPE_CHECKING:
    from spar_py.world.product import AssemblyResult, Insertion

__all__ = ["BASE_FILL", "FIXTURE_FILL", "insertion_node", "precedence_dot"]

BASE_FILL = "#e4e4e4"
FIXTURE_FILL = "#f6c6c0"
WRAP = 22  # characters per line of an edge's reason


def insertion_node(ins: "Insertion") -> str:
    """The node name of an insertion: its parts joined by ``+`` (one part: the part's name)."""
    return "+".join(ins.parts)


def _direction(d: tuple[float, ...]) -> str:
    """``"[0, 0, -1]"``: a unit direction with components rounded to 3 decimals, -0 as 0."""
    return "[" + ", ".join(f"{round(x, 3) + 0.0:g}" for x in d) + "]"


def _mates_line(res: "AssemblyResult", parts: tuple[str, ...]) -> str | None:
    """``"peg in p2, p6"`` / ``"hole of p1"``: the parts ``parts``' mates join them to, or None."""
    pegs = sorted({m.hole for m in res.mates if m.peg in parts and m.hole not in parts})
    holes = sorted({m.peg for m in res.mates if m.hole in parts and m.peg not in parts})
    seats = sorted({s.on for s in res.seats if s.part in parts and s.on not in parts})
    bits = [f"peg in {', '.join(pegs)}"] * bool(pegs) + [f"hole for {', '.join(holes)}"] * bool(holes) \
        + [f"rests on {', '.join(seats)}"] * bool(seats)
    return "; ".join(bits) or None


def precedence_dot(res: "AssemblyResult", name: str) -> str:
    """The precedence graph of product ``name`` as DOT text, base on top.

    Nodes: ``"3. p3"`` (the insertion's place in the derived order and its parts), ``"along
    [0, 0, -1]"`` (the insertion direction, product frame), the mates it makes; the base
    ``"1. p0"`` with ``"base, placed first"``. Edges: ``first -> then`` for each precedence,
    label and tooltip its reason; an edge into a part of the same insertion is left out.
    """
    owner = {p: insertion_node(ins) for ins in res.insertions for p in ins.parts}
    edges: dict[tuple[str, str], list[str]] = {}
    for first, then, why in res.precedence:
        u, v = owner.get(first, first), owner.get(then, then)
        if u != v:
            edges.setdefault((u, v), []).append(why)
    implied = implied_edges(list(edges))
    fixtures = sum(ins.needs_fixture for ins in res.insertions)
    title = (f"precedence graph: {name} (derived from the meshes)\n"
             "edge first -> then: then in place blocks first's insertion\n"
             "solid: transitive reduction; dashed: implied by a longer chain"
             + (f"\nred: {fixtures} insertion(s) need a fixture or a second arm" if fixtures else ""))
    out = dot_header("digraph", "precedence", title, "TB", fillcolor=ACTION_FILL)
    for i, ins in enumerate(res.insertions):
        node = insertion_node(ins)
        lines = [f"{i + 1}. {' + '.join(ins.parts)}"]
        fill = ACTION_FILL
        if i == 0:
            lines.append("base, placed first")
            fill = BASE_FILL
        else:
            lines.append(f"along {_direction(ins.direction)}")
        mates = _mates_line(res, ins.parts)
        if mates:
            lines.append(mates)
        if ins.needs_fixture:
            lines.append("needs a fixture or a second arm")
            fill = FIXTURE_FILL
        out.append(f"  {dot_id(node)} {dot_attrs(True, label=chr(10).join(lines), fillcolor=fill)};")
    for (u, v), whys in edges.items():
        why = "; ".join(whys)
        style = {"style": "dashed", "constraint": "false"} if (u, v) in implied else {}
        out.append(f"  {dot_id(u)} -> {dot_id(v)} {dot_attrs(label=_label(whys), tooltip=why, **style)};")
    for p in res.unremovable:
        out.append(f"  {dot_id(p)} {dot_attrs(label=f'{p}: no free direction found', fillcolor=FIXTURE_FILL)};")
    out.append("}")
    return "\n".join(out) + "\n"


def _label(whys: list[str]) -> str:
    """An edge's label: its reasons, each wrapped at WRAP characters."""
    return "\n".join(line for w in whys for line in textwrap.wrap(w, WRAP, break_long_words=False))
