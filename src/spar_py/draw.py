"""Pictures of a plan (issue 6): the paper's Fig. 24 and the work cell at every step.

Two kinds of picture are drawn from the plan JSON (schema 1, the dict the planner emits):

- the ordering graph (Fig. 24, bottom) and the geometric constraint network (Fig. 24
  top, with the label sets and pair counts of Fig. 25): :func:`ordering_dot` and
  :func:`network_dot` write Graphviz DOT text; :func:`render_png` draws DOT text with
  matplotlib using a layout computed here (layered by longest path for a digraph,
  two columns for a bipartite graph, a circle otherwise), so no Graphviz install is
  needed; Graphviz's ``dot`` is used only when asked for and present.
- the work cell at one step of the plan instance (:func:`cell_png`): the table, each
  object drawn from its shape (``ObjectModel.shape``) at its world pose at that step,
  and the arm as a polyline through its Denavit-Hartenberg frame origins.

Frames and units: world Z up, table top at z = 0, 4x4 homogeneous transforms with
column vectors (``T_world_obj``), lengths in the cell's unit (``cell.unit``, which is
also the unit the robot was loaded in). Plan joint vectors ``joints_deg`` are in
degrees in the robot file's DH zero convention; functions here take radians.

Nothing is computed at import time; matplotlib is imported (with the Agg backend)
inside the drawing functions only.
"""
from __future__ import annotations

import math
import re
import shutil
import subprocess
import textwrap
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from itertools import pairwise, product
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from .errors import SparValueError
from .geometry import inv, rotx, rotz, trans
from .reach import natural_key

if TYPE_CHECKING:
    from matplotlib.axes import Axes

    from .kinematics import Robot
    from .model import Cell, ObjectModel, Solid

__all__ = [
    "DotGraph",
    "Scene",
    "arm_polyline",
    "bipartite_layout",
    "cell_png",
    "dh_frames",
    "gripper_segments",
    "hole_mouth",
    "implied_edges",
    "layered_layout",
    "network_dot",
    "object_points",
    "ordering_dot",
    "parse_dot",
    "placement_pose",
    "render_png",
    "scenes",
    "solid_faces",
    "solid_points",
    "write_pictures",
]

Plan = Mapping[str, Any]  # the plan JSON document (or anything with ``to_json()`` returning one)

# Graph pictures are laid out in inches (data unit = 1 in on the page) with a monospace
# font, so a label's box size is known before drawing.
FONT_PT = 9.0
CHAR_W = 0.61 * FONT_PT / 72.0  # in: advance of DejaVu Sans Mono
LINE_H = 1.3 * FONT_PT / 72.0  # in
BOX_PAD = 0.09  # in, inside a node box
WRAP = 34  # characters per line in a node box
LAYER_GAP = 0.55  # in, between layers of the ordering graph
NODE_GAP = 0.45  # in, between nodes of one layer or column
MARGIN = 0.35  # in, around a graph picture
MAX_SHOWN = 8  # labels of a label set shown in a network node
PER_LINE = 4  # labels per line in a network node
DPI = 120

GRASP_FILL = "#dbe9f6"
POSITION_FILL = "#fde9d9"
ACTION_FILL = "#e8f3e0"
OBJECT_COLOURS = ("#4c72b0", "#dd8452", "#55a868", "#c44e52", "#8172b3", "#937860", "#da8bc3")
TABLE_COLOUR = "#c8b48a"
ARM_COLOUR = "#3a3a3a"
GRIPPER_COLOUR = "#b22222"


# =========================================================================== plan access


def _doc(plan: Any) -> Mapping[str, Any]:
    """The plan JSON dict of ``plan``: the dict itself, or ``plan.to_json()`` (planner.Plan)."""
    return plan.to_json() if hasattr(plan, "to_json") else plan


def _partial(plan: Plan) -> Mapping[str, Any]:
    return plan.get("partial") or {}


def _instance(plan: Plan) -> Mapping[str, Any]:
    return plan.get("instance") or {}


def _is_plan(plan: Plan) -> bool:
    return plan.get("outcome") == "plan"


def pretty_term(term: str) -> str:
    """Prolog term text with one space after each comma, as the paper prints its actions."""
    return re.sub(r",\s*", ", ", term.strip())


def _term_parts(term: str) -> tuple[str, list[str]]:
    """Functor and argument texts of a ground term (``("pickup", ["peg", "p1G10"])``)."""
    from .kb import parse_term, term_text

    try:
        t = parse_term(term)
    except ValueError:
        m = re.match(r"\s*([a-z]\w*)", term)
        return (m.group(1) if m else term.strip()), []
    if isinstance(t, tuple):
        return str(t[0]), [term_text(a) for a in t[1:]]
    return term_text(t), []


# =========================================================================== DOT text


def _q(s: str) -> str:
    """A DOT double-quoted string; newlines become DOT's ``\\n`` escape."""
    return '"' + s.replace("\\", "\\\\").replace('"', '\\"').replace("\n", "\\n") + '"'


def _attrs(**kw: str) -> str:
    return "[" + ", ".join(f"{k}={_q(v)}" for k, v in kw.items()) + "]"


def _action_nodes(plan: Plan) -> dict[str, str]:
    """Action id -> its term text (paper spacing), for every action in actions or ordering."""
    nodes: dict[str, str] = {}
    for a in _partial(plan).get("actions") or []:
        nodes[str(a.get("id"))] = pretty_term(str(a.get("term") or a.get("name") or ""))
    for edge in _partial(plan).get("ordering") or []:
        for n in edge[:2]:
            nodes.setdefault(str(n), "")
    return dict(sorted(nodes.items(), key=lambda kv: natural_key(kv[0])))


def implied_edges(edges: Sequence[tuple[str, str]]) -> set[tuple[str, str]]:
    """The edges (u, v) also implied by a longer path u -> w -> ... -> v of the same edge set.

    The others form the transitive reduction (of an acyclic set); an edge inside a cycle
    is implied too, which is harmless: it is only drawn dashed.
    """
    succ: dict[str, set[str]] = {}
    for u, v in edges:
        succ.setdefault(u, set()).add(v)

    def reaches(start: str, goal: str, skip: tuple[str, str]) -> bool:
        seen, stack = {start}, [start]
        while stack:
            n = stack.pop()
            for m in succ.get(n, ()):
                if (n, m) == skip or m in seen:
                    continue
                if m == goal:
                    return True
                seen.add(m)
                stack.append(m)
        return False

    return {(u, v) for u, v in set(edges) if reaches(u, v, (u, v))}


def ordering_dot(plan: Plan) -> str:
    """The ordering graph (Fig. 24, bottom) as Graphviz DOT text.

    Nodes are the plan's actions labelled ``"action_3\\nputdown(block, pos_1)"``; an edge
    Before -> After for each ``prior_to(Before, After)`` of ``partial.ordering``. Every
    given edge is present: solid when it belongs to the transitive reduction, dashed
    (``constraint=false``) when a longer chain of prior_to already implies it.
    """
    plan = _doc(plan)
    nodes = _action_nodes(plan)
    edges = [(str(e[0]), str(e[1])) for e in _partial(plan).get("ordering") or []]
    implied = implied_edges(edges)
    title = (f"ordering graph: {plan.get('problem', '')}\n"
             "solid: prior_to (transitive reduction)\ndashed: implied by a longer chain")
    out = [
        "digraph ordering {",
        f"  graph {_attrs(label=title, labelloc='t', rankdir='TB')};",
        f"  node {_attrs(shape='box', style='rounded,filled', fillcolor=ACTION_FILL, fontname='monospace')};",
    ]
    for n, t in nodes.items():
        label = f"{n}\n{t}" if t else n
        out.append(f"  {_q(n)} {_attrs(label=label)};")
    for u, v in dict.fromkeys(edges):
        extra = " [style=\"dashed\", constraint=\"false\"]" if (u, v) in implied else ""
        out.append(f"  {_q(u)} -> {_q(v)}{extra};")
    out.append("}")
    return "\n".join(out) + "\n"


def label_summary(name: str, labels: Sequence[str], chosen: str | None = None) -> str:
    """A network node's label: ``"grasp_1 (14):\\np1G1 p1G3 p1G6 p1G7\\n... (6 more)"``.

    At most ``MAX_SHOWN`` labels, ``PER_LINE`` a line; the instance's value, if any, last.
    """
    shown = [str(x) for x in labels[:MAX_SHOWN]]
    lines = [f"{name} ({len(labels)}):"]
    lines += [" ".join(shown[i:i + PER_LINE]) for i in range(0, len(shown), PER_LINE)]
    if len(labels) > MAX_SHOWN:
        lines.append(f"... ({len(labels) - MAX_SHOWN} more)")
    if not labels:
        lines.append("(empty)")
    if chosen is not None:
        lines.append(f"chosen: {chosen}")
    return "\n".join(lines)


def _fill_of(var: str) -> str:
    return GRASP_FILL if var.startswith("grasp") else POSITION_FILL


def _separation_vars(sep: Any, variables: Mapping[str, Any] | None = None) -> list[str] | None:
    """The two plan variables a separation keeps apart, else None. An entry is
    ``{"vars": [a, b]}``, ``[a, b]`` of variables, or, as the plan JSON gives it, the two
    terms of its ``dif/2`` (``["part_location(peg,init_pos5)", "part_location(peg,init_pos1)"]``):
    then the first argument pair in which they differ, where both are ``variables``."""
    vs = sep.get("vars") if isinstance(sep, Mapping) else sep
    if not (isinstance(vs, (list, tuple)) and len(vs) == 2 and all(isinstance(v, str) for v in vs)):
        return None
    if variables is None or (vs[0] in variables and vs[1] in variables):
        return [vs[0], vs[1]]
    from .kb import parse_term

    try:
        a, b = parse_term(vs[0]), parse_term(vs[1])
    except ValueError:
        return None
    for x, y in _differing(a, b):
        if isinstance(x, str) and isinstance(y, str) and x in variables and y in variables:
            return [x, y]
    return None


def _differing(a: Any, b: Any) -> list[tuple[Any, Any]]:
    """The pairs of corresponding subterms of ``a`` and ``b`` that differ, outermost last."""
    if a == b:
        return []
    if isinstance(a, (tuple, list)) and isinstance(b, (tuple, list)) and len(a) == len(b) \
            and type(a) is type(b) and (isinstance(a, list) or a[0] == b[0]):
        return [d for x, y in zip(a, b) for d in _differing(x, y)] + [(a, b)]
    return [(a, b)]


def network_dot(plan: Plan) -> str:
    """The geometric constraint network (Fig. 24, top; Fig. 25) as Graphviz DOT text.

    Nodes are the plan variables with their pruned label sets (abbreviated, see
    :func:`label_summary`); an undirected edge per arc, labelled ``"N pairs"`` (with the
    arc's ``kind`` above it when the plan gives one); separations, if any, dotted.
    """
    plan = _doc(plan)
    part = _partial(plan)
    variables: dict[str, list[str]] = {str(k): list(v or []) for k, v in (part.get("variables") or {}).items()}
    arcs = part.get("arcs") or []
    for a in arcs:
        for v in a.get("vars", [])[:2]:
            variables.setdefault(str(v), [])
    seps = [s for s in (_separation_vars(x, variables) for x in part.get("separations") or []) if s]
    bindings = _instance(plan).get("bindings") or {}
    title = f"constraint network: {plan.get('problem', '')}"
    out = [
        "graph network {",
        f"  graph {_attrs(label=title, labelloc='t', rankdir='LR')};",
        f"  node {_attrs(shape='box', style='rounded,filled', fontname='monospace')};",
    ]
    for v in sorted(variables, key=natural_key):
        label = label_summary(v, variables[v], bindings.get(v))
        out.append(f"  {_q(v)} {_attrs(label=label, fillcolor=_fill_of(v))};")
    for a in arcs:
        vs = [str(x) for x in a.get("vars", [])]
        if len(vs) != 2:
            continue
        n = len(a.get("pairs") or [])
        count = f"{n} pair" if n == 1 else f"{n} pairs"
        label = f"{a['kind']}\n{count}" if a.get("kind") else count
        out.append(f"  {_q(vs[0])} -- {_q(vs[1])} {_attrs(label=label)};")
    for s in seps:
        out.append(f"  {_q(s[0])} -- {_q(s[1])} {_attrs(label='separated (dif)', style='dotted')};")
    out.append("}")
    return "\n".join(out) + "\n"


# =========================================================================== DOT reading


@dataclass
class DotGraph:
    """A parsed DOT graph: enough of the language for :func:`render_png` (no subgraph edges, no ports)."""

    directed: bool
    name: str = ""
    attrs: dict[str, str] = field(default_factory=dict)
    nodes: dict[str, dict[str, str]] = field(default_factory=dict)
    edges: list[tuple[str, str, dict[str, str]]] = field(default_factory=list)


_DOT_TOKEN = re.compile(
    r"""(?P<skip>\s+|//[^\n]*|/\*.*?\*/)
      |(?P<str>"(?:[^"\\]|\\.)*")
      |(?P<op>->|--|[\[\]{}=;,:])
      |(?P<id>-?(?:\.\d+|\d+(?:\.\d*)?)|[A-Za-z_\x80-\uffff][\w\x80-\uffff]*)""",
    re.VERBOSE | re.DOTALL,
)


def _unescape(s: str) -> str:
    """DOT escString -> text: ``\\"`` -> ", ``\\\\`` -> \\, ``\\n`` ``\\l`` ``\\r`` -> newline."""
    return re.sub(r"\\(.)", lambda m: {"n": "\n", "l": "\n", "r": "\n"}.get(m.group(1), m.group(1)), s)


def _dot_tokens(src: str) -> list[tuple[str, str]]:
    out: list[tuple[str, str]] = []
    src = re.sub(r"(?m)^[ \t]*#[^\n]*", "", src)  # preprocessor lines
    pos = 0
    while pos < len(src):
        m = _DOT_TOKEN.match(src, pos)
        if not m:
            line = src.count("\n", 0, pos) + 1
            raise SparValueError(f"DOT: unexpected {src[pos]!r} on line {line}")
        pos = m.end()
        kind = m.lastgroup or ""
        if kind == "str":
            out.append(("id", _unescape(m.group(kind)[1:-1])))
        elif kind != "skip":
            out.append((kind, m.group(kind)))
    return out


def parse_dot(source: str) -> DotGraph:
    """Parse simple DOT text (the kind :func:`ordering_dot` and :func:`network_dot` write).

    Supported: ``[strict] graph|digraph [name] { ... }`` with graph/node/edge default
    attributes, ``key=value`` graph attributes, node statements and edge chains
    (``a -> b -> c [attrs]``). Subgraph braces are flattened. Raises SparValueError.
    """
    toks = _dot_tokens(source)
    i = 0

    def peek(k: int = 0) -> tuple[str, str]:
        return toks[i + k] if i + k < len(toks) else ("eof", "")

    def take(value: str | None = None) -> str:
        nonlocal i
        kind, val = peek()
        if kind == "eof" or (value is not None and val.lower() != value):
            raise SparValueError(f"DOT: expected {value or 'a token'}, found {val or 'the end'!r}")
        i += 1
        return val

    def attr_list() -> dict[str, str]:
        out: dict[str, str] = {}
        while peek()[1] == "[":
            take("[")
            while peek()[1] != "]":
                key = take()
                if peek()[1] == "=":
                    take("=")
                    out[key] = take()
                else:
                    out[key] = "true"
                if peek()[1] in (",", ";"):
                    take()
            take("]")
        return out

    if peek()[1].lower() == "strict":
        take()
    kind = take().lower()
    if kind not in ("graph", "digraph"):
        raise SparValueError(f"DOT: expected graph or digraph, found {kind!r}")
    g = DotGraph(directed=kind == "digraph")
    if peek()[1] != "{":
        g.name = take()
    take("{")
    node_defaults: dict[str, str] = {}
    edge_defaults: dict[str, str] = {}
    depth = 1
    while depth:
        kind_, val = peek()
        if kind_ == "eof":
            raise SparValueError("DOT: missing closing '}'")
        low = val.lower()
        if val in ("{", "}"):
            take()
            depth += 1 if val == "{" else -1
        elif val == ";" or low == "subgraph":
            take()
            if low == "subgraph" and peek()[1] != "{":
                take()
        elif low in ("graph", "node", "edge") and peek(1)[1] == "[":
            take()
            a = attr_list()
            {"graph": g.attrs, "node": node_defaults, "edge": edge_defaults}[low].update(a)
        elif peek(1)[1] == "=":
            key = take()
            take("=")
            g.attrs[key] = take()
        else:
            chain = [take()]
            while peek()[1] in ("->", "--", ":"):
                op = take()
                if op == ":":  # a port: ignored
                    take()
                    continue
                chain.append(take())
            a = attr_list()
            for n in chain:
                g.nodes.setdefault(n, dict(node_defaults))
            if len(chain) == 1:
                g.nodes[chain[0]].update(a)
            for u, v in pairwise(chain):
                g.edges.append((u, v, {**edge_defaults, **a}))
    return g


# =========================================================================== graph layout


def _back_edges(nodes: Sequence[str], edges: Sequence[tuple[str, str]]) -> set[tuple[str, str]]:
    """Edges closing a cycle in a depth-first search from ``nodes`` in order."""
    succ: dict[str, list[str]] = {n: [] for n in nodes}
    for u, v in edges:
        succ.setdefault(u, []).append(v)
        succ.setdefault(v, [])
    state: dict[str, int] = {}  # 1 on the stack, 2 done
    back: set[tuple[str, str]] = set()
    for root, out in succ.items():
        if root in state:
            continue
        stack = [(root, iter(out))]
        state[root] = 1
        while stack:
            n, it = stack[-1]
            m = next(it, None)
            if m is None:
                state[n] = 2
                stack.pop()
            elif state.get(m) == 1:
                back.add((n, m))
            elif m not in state:
                state[m] = 1
                stack.append((m, iter(succ[m])))
    return back


@dataclass
class _Layers:
    """A layered drawing plan: layers top to bottom (names; long edges add dummy names), the
    layer of every name, and per edge index the chain of names the edge runs through."""

    layers: list[list[str]]
    layer_of: dict[str, int]
    chains: dict[int, list[str]]


def _dummy(edge: int, layer: int) -> str:
    return f"\x00{edge}:{layer}"


def _is_dummy(name: str) -> bool:
    return name.startswith("\x00")


def _layering(nodes: Sequence[str], edges: Sequence[tuple[str, str]]) -> _Layers:
    """Sugiyama-style layering: cycles broken by reversing back edges, layer = longest path
    from a source, a dummy per layer an edge skips, then barycentre sweeps (down, up, ...)
    order each layer to keep crossings few. Loops (u, u) get no chain."""
    back = _back_edges(nodes, edges)
    oriented: dict[int, tuple[str, str, bool]] = {}
    for k, (u, v) in enumerate(edges):
        if u != v:
            oriented[k] = (v, u, True) if (u, v) in back else (u, v, False)
    dag = list(dict.fromkeys((a, b) for a, b, _ in oriented.values()))
    allnodes = list(dict.fromkeys([*nodes, *[n for e in edges for n in e]]))
    indeg = {n: 0 for n in allnodes}
    for _, v in dag:
        indeg[v] += 1
    layer = {n: 0 for n in allnodes}
    ready = [n for n in allnodes if indeg[n] == 0]
    while ready:
        n = ready.pop(0)
        for u, v in dag:
            if u == n:
                layer[v] = max(layer[v], layer[n] + 1)
                indeg[v] -= 1
                if indeg[v] == 0:
                    ready.append(v)
    chains: dict[int, list[str]] = {}
    for k, (a, b, rev) in oriented.items():
        chain = [a, *[_dummy(k, m) for m in range(layer[a] + 1, layer[b])], b]
        layer.update({d: layer[a] + i for i, d in enumerate(chain[1:-1], start=1)})
        chains[k] = chain[::-1] if rev else chain
    depth = max(layer.values(), default=-1) + 1
    layers = [[n for n in layer if layer[n] == m] for m in range(depth)]
    up: dict[str, list[str]] = {n: [] for n in layer}
    down: dict[str, list[str]] = {n: [] for n in layer}
    for k, (a, _, rev) in oriented.items():
        chain = chains[k][::-1] if rev else chains[k]
        for x, y in pairwise(chain):
            down[x].append(y)
            up[y].append(x)
    for sweep in range(4):
        order = range(1, depth) if sweep % 2 == 0 else range(depth - 2, -1, -1)
        for m in order:
            pos = {n: i for i, n in enumerate(layers[m - 1 if sweep % 2 == 0 else m + 1])}
            nbrs = up if sweep % 2 == 0 else down
            here = {n: i for i, n in enumerate(layers[m])}

            def key(n: str, pos: dict[str, int] = pos, nbrs: dict[str, list[str]] = nbrs,
                    here: dict[str, int] = here) -> float:
                ps = [pos[p] for p in nbrs[n] if p in pos]
                return sum(ps) / len(ps) if ps else here[n]

            layers[m].sort(key=key)
    return _Layers(layers, layer, chains)


def layered_layout(nodes: Sequence[str], edges: Sequence[tuple[str, str]]) -> dict[str, tuple[int, int]]:
    """Layer and rank in layer of each node: layer = longest path from a source (cycles broken).

    Within a layer, nodes are ordered by barycentre sweeps (the same order the picture uses).
    """
    lay = _layering(nodes, edges)
    out: dict[str, tuple[int, int]] = {}
    for m, names in enumerate(lay.layers):
        out.update({n: (m, i) for i, n in enumerate(x for x in names if not _is_dummy(x))})
    return out


def bipartite_layout(nodes: Sequence[str], edges: Sequence[tuple[str, str]]) -> dict[str, tuple[int, int]] | None:
    """Column (0 left, 1 right) and row of each node if the graph is bipartite, else None.

    The column holding the busiest node goes left; rows follow the barycentre of the
    neighbours in the other column, which keeps crossings few.
    """
    adj: dict[str, list[str]] = {n: [] for n in nodes}
    for u, v in edges:
        adj.setdefault(u, []).append(v)
        adj.setdefault(v, []).append(u)
    colour: dict[str, int] = {}
    for root, nbrs in adj.items():
        if root in colour or not nbrs:
            continue
        colour[root] = 0
        todo = [root]
        while todo:
            n = todo.pop()
            for m in adj[n]:
                if m not in colour:
                    colour[m] = 1 - colour[n]
                    todo.append(m)
                elif colour[m] == colour[n]:
                    return None
    if colour:
        hub = max(colour, key=lambda n: (len(adj[n]), -list(adj).index(n)))
        if colour[hub] == 1:
            colour = {n: 1 - c for n, c in colour.items()}
    for n in adj:  # isolated nodes fill the shorter column
        if n not in colour:
            colour[n] = int(sum(colour.values()) * 2 < len(colour))
    cols = [[n for n in adj if colour[n] == c] for c in (0, 1)]
    for _ in range(2):
        for c in (1, 0):
            other = {n: i for i, n in enumerate(cols[1 - c])}
            here = {n: i for i, n in enumerate(cols[c])}  # list.sort empties the list meanwhile
            def key(n: str, here: dict[str, int] = here, other: dict[str, int] = other) -> float:
                ns = [other[m] for m in adj[n] if m in other]
                return sum(ns) / len(ns) if ns else here[n]
            cols[c].sort(key=key)
    return {n: (c, r) for c in (0, 1) for r, n in enumerate(cols[c])}


# =========================================================================== graph drawing


@dataclass
class _Box:
    """A node on the page: centre and size in inches, its text lines and fill."""

    x: float
    y: float
    w: float
    h: float
    lines: list[str]
    fill: str


def _wrap(label: str) -> list[str]:
    out: list[str] = []
    for line in label.split("\n"):
        out += textwrap.wrap(line, WRAP, break_long_words=False, break_on_hyphens=False,
                             subsequent_indent="  ") or [""]
    return out


def _box_size(lines: Sequence[str]) -> tuple[float, float]:
    """Width and height (in) of a box holding ``lines`` in the monospace font."""
    return max(len(s) for s in lines) * CHAR_W + 2 * BOX_PAD, len(lines) * LINE_H + 2 * BOX_PAD


def _boxes(g: DotGraph) -> dict[str, _Box]:
    out = {}
    for n, a in g.nodes.items():
        lines = _wrap(a.get("label", n))
        w, h = _box_size(lines)
        out[n] = _Box(0.0, 0.0, w, h, lines, a.get("fillcolor", "#eeeeee"))
    return out


DUMMY_W = 0.3  # in: the lane a long edge reserves in each layer it crosses


def _place_layered(g: DotGraph, boxes: dict[str, _Box]) -> tuple[_Layers, dict[str, tuple[float, float, float]]]:
    """Top-to-bottom layers (first action on top), centred on x = 0.

    Returns the layering and, per dummy, its lane: (x, top y, bottom y) of its layer's band.
    """
    lay = _layering(list(g.nodes), [(u, v) for u, v, _ in g.edges])
    lanes: dict[str, tuple[float, float, float]] = {}
    y = 0.0
    for row in lay.layers:
        h = max((boxes[n].h for n in row if n in boxes), default=LINE_H)
        widths = [boxes[n].w if n in boxes else DUMMY_W for n in row]
        x = -(sum(widths) + NODE_GAP * (len(row) - 1)) / 2
        for n, w in zip(row, widths):
            if n in boxes:
                boxes[n].x, boxes[n].y = x + w / 2, y - h / 2
            else:
                lanes[n] = (x + w / 2, y, y - h)
            x += w + NODE_GAP
        y -= h + LAYER_GAP
    return lay, lanes


def _exit_point(b: _Box, toward: tuple[float, float]) -> tuple[float, float]:
    """Where the ray from the centre of box ``b`` towards ``toward`` leaves the box."""
    dx, dy = toward[0] - b.x, toward[1] - b.y
    s = min(b.w / 2 / abs(dx) if dx else math.inf, b.h / 2 / abs(dy) if dy else math.inf)
    s = 0.0 if math.isinf(s) else s
    return b.x + s * dx, b.y + s * dy


def _chain_path(chain: Sequence[str], boxes: dict[str, _Box],
                lanes: dict[str, tuple[float, float, float]]) -> list[tuple[float, float]]:
    """Way points of an edge through its dummies' lanes, from box edge to box edge."""
    pts: list[tuple[float, float]] = []
    going_down = boxes[chain[0]].y > boxes[chain[-1]].y
    for d in chain[1:-1]:
        x, top, bottom = lanes[d]
        pts += [(x, top), (x, bottom)] if going_down else [(x, bottom), (x, top)]
    return [_exit_point(boxes[chain[0]], pts[0]), *pts, _exit_point(boxes[chain[-1]], pts[-1])]


def _smooth(points: Sequence[tuple[float, float]]) -> Any:
    """A matplotlib Path through ``points``' ends, corners rounded by quadratic Beziers
    (each inner point is a control point; the curve passes the midpoints between them)."""
    from matplotlib.path import Path as MplPath

    verts = [points[0]]
    codes = [MplPath.MOVETO]
    inner = points[1:-1]
    if not inner:
        return MplPath([points[0], points[-1]], [MplPath.MOVETO, MplPath.LINETO])
    first_mid = ((points[0][0] + inner[0][0]) / 2, (points[0][1] + inner[0][1]) / 2)
    verts.append(first_mid)
    codes.append(MplPath.LINETO)
    for i, c in enumerate(inner):
        nxt = inner[i + 1] if i + 1 < len(inner) else points[-1]
        end = ((c[0] + nxt[0]) / 2, (c[1] + nxt[1]) / 2) if i + 1 < len(inner) else points[-1]
        verts += [c, end]
        codes += [MplPath.CURVE3, MplPath.CURVE3]
    return MplPath(verts, codes)


def _place_columns(boxes: dict[str, _Box], cols: dict[str, tuple[int, int]], gap: float) -> None:
    """Two columns ``gap`` inches apart (box edge to box edge), each centred on y = 0."""
    widths = [max((boxes[n].w for n in cols if cols[n][0] == c), default=0.0) for c in (0, 1)]
    xs = (0.0, widths[0] / 2 + gap + widths[1] / 2)
    for c in (0, 1):
        col = sorted((n for n in cols if cols[n][0] == c), key=lambda n: cols[n][1])
        total = sum(boxes[n].h for n in col) + NODE_GAP * 1.4 * (len(col) - 1)
        y = total / 2
        for n in col:
            boxes[n].x, boxes[n].y = xs[c], y - boxes[n].h / 2
            y -= boxes[n].h + NODE_GAP * 1.4


def _place_circle(boxes: dict[str, _Box], edges: Sequence[tuple[str, str]]) -> None:
    """Nodes round an ellipse in breadth-first order from the busiest node, so that
    neighbours tend to sit side by side."""
    adj: dict[str, list[str]] = {n: [] for n in boxes}
    for u, v in edges:
        adj[u].append(v)
        adj[v].append(u)
    order: list[str] = []
    for root in sorted(boxes, key=lambda n: -len(adj[n])):
        if root in order:
            continue
        todo = [root]
        order.append(root)
        while todo:
            n = todo.pop(0)
            for m in sorted(adj[n], key=natural_key):
                if m not in order:
                    order.append(m)
                    todo.append(m)
    r = max(1.2, sum(max(b.w, b.h) + NODE_GAP for b in boxes.values()) / (2 * math.pi))
    for i, n in enumerate(order):
        a = math.pi / 2 - 2 * math.pi * i / max(1, len(order))
        boxes[n].x, boxes[n].y = r * math.cos(a) * 1.3, r * math.sin(a)


def _side_arc(a: _Box, b: _Box, boxes: Sequence[_Box], column: int) -> tuple[float, tuple[float, float]]:
    """arc3 ``rad`` and peak point of an edge between two boxes of one column, bulging outwards
    (left of column 0, right of column 1) round every box of the column in between.

    arc3's control point is ``M + rad (dy, -dx)`` (M the chord's midpoint); the quadratic
    curve is 4 t (1 - t) of the way to its peak (half-way to the control point) at t.
    """
    lo, hi = sorted((a.y, b.y))
    need = max(a.w, b.w) / 2 + 0.3
    for c in boxes:
        if c.x == a.x and lo < c.y < hi:
            t = (c.y - lo) / (hi - lo)
            need = max(need, (c.w / 2 + 0.3) / (4 * t * (1 - t)))
    dx, dy = b.x - a.x, b.y - a.y
    outward = 1.0 if column == 1 else -1.0
    # the peak's x offset is 0.5 rad dy; make it outward * need
    rad = outward * 2 * need / dy if dy else 0.0
    return rad, ((a.x + b.x) / 2 + 0.5 * rad * dy, (a.y + b.y) / 2 - 0.5 * rad * dx)


def _label_spot(a: _Box, b: _Box, text: str, taken: list[tuple[float, float, float, float]],
                boxes: Sequence[_Box]) -> tuple[float, float]:
    """A point on the segment a-b for an edge label that overlaps no box and no earlier label."""
    lines = text.split("\n")
    w, h = _box_size(lines)

    def clear(x: float, y: float) -> bool:
        rects = taken + [(c.x, c.y, c.w, c.h) for c in boxes]
        gap = 0.08  # in between a label and anything else
        return all(abs(x - rx) * 2 >= w + rw + gap or abs(y - ry) * 2 >= h + rh + gap
                   for rx, ry, rw, rh in rects)

    spots = [(a.x + t * (b.x - a.x), a.y + t * (b.y - a.y)) for t in (0.5, 0.35, 0.65, 0.25, 0.75, 0.42, 0.58)]
    x, y = next((p for p in spots if clear(*p)), spots[0])
    taken.append((x, y, w, h))
    return x, y


@dataclass
class _GraphLayout:
    """A graph placed on the page (inches): node boxes, routed long edges (way points) and
    same-column edges (arc3 rad, peak point), both by edge index."""

    boxes: dict[str, _Box]
    routes: dict[int, list[tuple[float, float]]]
    arcs: dict[int, tuple[float, tuple[float, float]]]


def _layout(g: DotGraph) -> _GraphLayout:
    """Layers for a digraph; for an undirected graph two columns if its solid edges are
    bipartite (dotted ones, the separations, may then join one column), else a circle."""
    boxes = _boxes(g)
    out = _GraphLayout(boxes, {}, {})
    if g.directed:
        lay, lanes = _place_layered(g, boxes)
        out.routes = {k: _chain_path(c, boxes, lanes) for k, c in lay.chains.items() if len(c) > 2}
        return out
    solid = [(u, v) for u, v, a in g.edges if a.get("style") != "dotted"]
    cols = bipartite_layout(list(g.nodes), solid)
    if cols is None:
        _place_circle(boxes, [(u, v) for u, v, _ in g.edges])
        return out
    longest = max((_box_size(a.get("label", "").split("\n"))[0] for *_, a in g.edges), default=0.0)
    _place_columns(boxes, cols, max(2.0, longest + 1.2))
    out.arcs = {k: _side_arc(boxes[u], boxes[v], list(boxes.values()), cols[u][0])
                for k, (u, v, _) in enumerate(g.edges) if u != v and cols[u][0] == cols[v][0]}
    return out


def _page(g: DotGraph, lay: _GraphLayout) -> tuple[float, float, float, float]:
    """The page (x0, x1, y0, y1 in inches) holding the boxes, edges, labels and the title."""
    xs = [b.x + s * b.w / 2 for b in lay.boxes.values() for s in (-1, 1)]
    ys = [b.y + s * b.h / 2 for b in lay.boxes.values() for s in (-1, 1)]
    for pts in [*lay.routes.values(), [peak for _, peak in lay.arcs.values()]]:
        xs += [p[0] for p in pts]
        ys += [p[1] for p in pts]
    for k, (_, (px, py)) in lay.arcs.items():  # the label sits outside the peak
        w, h = _box_size(g.edges[k][2].get("label", "").split("\n"))
        xs.append(px + math.copysign(w + 0.1, px - lay.boxes[g.edges[k][0]].x))
        ys += [py - h / 2, py + h / 2]
    title = g.attrs.get("label", "").split("\n") if g.attrs.get("label") else []
    x0, x1 = min(xs, default=0) - MARGIN, max(xs, default=1) + MARGIN
    y0, y1 = min(ys, default=0) - MARGIN, max(ys, default=1) + MARGIN + len(title) * LINE_H * 1.15
    tw = max((len(t) for t in title), default=0) * CHAR_W * 1.1 + 2 * MARGIN
    if tw > x1 - x0:
        x0, x1 = (x0 + x1 - tw) / 2, (x0 + x1 + tw) / 2
    return x0, x1, y0, y1


def _draw_boxes(ax: Axes, boxes: dict[str, _Box]) -> dict[str, Any]:
    """Node boxes, first line bold, one Text per line (exact, font-independent spacing)."""
    from matplotlib.patches import FancyBboxPatch

    patches = {}
    for n, b in boxes.items():
        patches[n] = FancyBboxPatch((b.x - b.w / 2, b.y - b.h / 2), b.w, b.h, fc=b.fill, ec="#333333", lw=1.0,
                                    boxstyle="round,pad=0,rounding_size=0.06", zorder=2)
        ax.add_patch(patches[n])
        top = b.y + b.h / 2 - BOX_PAD
        for k, line in enumerate(b.lines):
            ax.text(b.x - b.w / 2 + BOX_PAD, top - k * LINE_H, line, ha="left", va="top", family="monospace",
                    fontsize=FONT_PT, weight="bold" if k == 0 else "normal", zorder=3)
    return patches


def _draw_edges(ax: Axes, g: DotGraph, lay: _GraphLayout, patches: dict[str, Any]) -> None:
    """Edges (arrows for a digraph; dashed/dotted styles) and their labels; loops are skipped."""
    from matplotlib.patches import FancyArrowPatch

    boxes, taken = lay.boxes, []
    styles = {"dashed": "--", "dotted": ":"}
    for k, (u, v, a) in enumerate(g.edges):
        if u == v:
            continue
        ls = styles.get(a.get("style", ""), "-")
        style = {"arrowstyle": "-|>,head_length=6,head_width=3" if g.directed else "-", "linestyle": ls,
                 "lw": 1.2, "color": "#555555" if ls != "-" else "#222222", "zorder": 1}
        if k in lay.routes:
            arrow = FancyArrowPatch(path=_smooth(lay.routes[k]), shrinkA=0, shrinkB=2, **style)
        else:
            rad = lay.arcs[k][0] if k in lay.arcs else 0.0
            arrow = FancyArrowPatch((boxes[u].x, boxes[u].y), (boxes[v].x, boxes[v].y), patchA=patches[u],
                                    patchB=patches[v], shrinkA=2, shrinkB=2,
                                    connectionstyle=f"arc3,rad={rad:.4f}", **style)
        ax.add_patch(arrow)
        if not a.get("label"):
            continue
        ha = "center"
        if k in lay.routes:
            x, y = lay.routes[k][len(lay.routes[k]) // 2]
        elif k in lay.arcs:  # beside the peak, away from the column
            x, y = lay.arcs[k][1]
            ha = "left" if x > boxes[u].x else "right"
            x += 0.08 if ha == "left" else -0.08
        else:
            x, y = _label_spot(boxes[u], boxes[v], a["label"], taken, list(boxes.values()))
        ax.text(x, y, a["label"], ha=ha, va="center", family="monospace", fontsize=FONT_PT, zorder=4,
                bbox={"boxstyle": "round,pad=0.2", "fc": "white", "ec": "#999999", "lw": 0.6})


def _draw_graph(g: DotGraph, path: Path) -> None:
    """Lay out and draw a parsed graph with matplotlib into the PNG ``path`` (1 data unit = 1 in)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    lay = _layout(g)
    x0, x1, y0, y1 = _page(g, lay)
    fig = plt.figure(figsize=(x1 - x0, y1 - y0), dpi=DPI)
    ax = fig.add_axes((0, 0, 1, 1))
    ax.set_xlim(x0, x1)
    ax.set_ylim(y0, y1)
    ax.axis("off")
    if g.attrs.get("label"):
        ax.text((x0 + x1) / 2, y1 - MARGIN / 2, g.attrs["label"], ha="center", va="top",
                family="monospace", fontsize=FONT_PT + 1, weight="bold")
    _draw_edges(ax, g, lay, _draw_boxes(ax, lay.boxes))
    fig.savefig(path, dpi=DPI, facecolor="white")
    plt.close(fig)


def render_png(dot_source: str, path: str | Path, use_graphviz: bool = False) -> Path:
    """Draw DOT text into the PNG ``path`` and return the path.

    By default the layout is computed here and drawn with matplotlib (see the module
    docstring), so the picture does not depend on Graphviz. With ``use_graphviz`` and
    a ``dot`` binary on PATH, ``dot -Tpng`` draws it instead (falling back to
    matplotlib if dot fails).
    """
    path = Path(path)
    exe = shutil.which("dot") if use_graphviz else None
    if exe:
        r = subprocess.run([exe, "-Tpng", "-o", str(path)], input=dot_source.encode(), capture_output=True,
                           timeout=60, check=False)
        if r.returncode == 0 and path.is_file() and path.stat().st_size > 0:
            return path
    _draw_graph(parse_dot(dot_source), path)
    return path


# =========================================================================== cell geometry


def solid_points(solid: Solid, T: np.ndarray, segments: int = 24) -> np.ndarray:
    """World points (k, 3) outlining a Solid placed by ``T`` (4x4, T_world_obj, cell unit).

    A box gives its 8 corners (x slowest, z fastest: lo/hi per axis); a cylinder its two
    rim circles, ``segments`` points each (bottom rim first).
    """
    if solid.kind == "cylinder":
        a = np.linspace(0.0, 2 * math.pi, segments, endpoint=False)
        rim = np.stack([solid.radius * np.cos(a), solid.radius * np.sin(a)], axis=1)
        local = np.vstack([np.column_stack([rim, np.full(segments, z)]) for z in (solid.lo[2], solid.hi[2])])
    else:
        local = np.array(list(product(*zip(solid.lo, solid.hi))), float)
    return local @ np.asarray(T, float)[:3, :3].T + np.asarray(T, float)[:3, 3]


def _faces_of_points(p: np.ndarray) -> list[np.ndarray]:
    """Faces of a solid from its :func:`solid_points` outline (8 box corners or two rims)."""
    if len(p) == 8:
        quads = [(0, 1, 3, 2), (4, 5, 7, 6), (0, 1, 5, 4), (2, 3, 7, 6), (0, 2, 6, 4), (1, 3, 7, 5)]
        return [p[list(q)] for q in quads]
    n = len(p) // 2
    bottom, top = p[:n], p[n:]
    return [bottom, top, *[np.array([bottom[i], bottom[(i + 1) % n], top[(i + 1) % n], top[i]]) for i in range(n)]]


def solid_faces(solid: Solid, T: np.ndarray, segments: int = 24) -> list[np.ndarray]:
    """The faces (each (m, 3) world points, in order round the face) of a Solid placed by ``T``."""
    return _faces_of_points(solid_points(solid, T, segments))


def object_points(model: ObjectModel, T: np.ndarray) -> np.ndarray:
    """All outline points (k, 3) of an object's shape at world pose ``T``; its origin if it has no shape."""
    if not model.shape:
        return np.asarray(T, float)[:3, 3][None]
    return np.vstack([solid_points(s, T) for s in model.shape])


def placement_pose(cell: Cell, obj: str, placement: Mapping[str, Any]) -> np.ndarray:
    """World pose (4x4) of a putdown placement ``{"x", "y", "z", "yaw_deg", "pose"}``.

    ``pose`` names a stable pose of ``obj`` (its orientation, turned ``yaw_deg`` degrees
    about world z: ``T = trans(x, y, z) @ rotz(yaw) @ R_pose``; ``z`` defaults to the
    pose's resting height) or an absolute position label of the cell (its transform).
    """
    label = placement.get("pose")
    if label in cell.positions:
        return np.array(cell.positions[label].T, float)
    R = np.eye(4)
    height = 0.0
    pose = cell.objects[obj].poses.get(label) if obj in cell.objects else None
    if pose is not None:
        R[:3, :3] = pose.R
        height = pose.height
    z = placement.get("z")
    return (trans(float(placement.get("x", 0.0)), float(placement.get("y", 0.0)),
                  height if z is None else float(z))
            @ rotz(math.radians(float(placement.get("yaw_deg", 0.0)))) @ R)


def dh_frames(robot: Robot, q: np.ndarray) -> list[np.ndarray]:
    """World frames (4x4, robot unit) of the arm at joints ``q`` (6,) rad: [frame 0, frames 1..6, tool].

    Modified (Craig) DH, rows of ``robot.dh`` = (alpha_{i-1}, a_{i-1}, d_i, offset_i):
    ``A_i = rotx(alpha_{i-1}) @ trans(a_{i-1}, 0, 0) @ rotz(theta_i) @ trans(0, 0, d_i)``,
    ``theta_i = q_i + offset_i``; frame 0 is ``robot.base``, the last ``frame 6 @ robot.tool``.
    """
    T = np.array(robot.base, float)
    frames = [T]
    for (alpha, a, d, off), qi in zip(np.asarray(robot.dh, float), np.asarray(q, float)):
        T = T @ rotx(alpha) @ trans(a, 0.0, 0.0) @ rotz(qi + off) @ trans(0.0, 0.0, d)
        frames.append(T)
    frames.append(T @ np.asarray(robot.tool, float))
    return frames


def arm_polyline(robot: Robot, q: np.ndarray) -> np.ndarray:
    """World points (k, 3) of the arm's skeleton at joints ``q`` rad: frame 0, then per link the
    corner after its a_{i-1} (along x_{i-1}) and the frame origin after d_i, up to frame 6 (the flange).

    Repeated points (zero-length links) are dropped.
    """
    T = np.array(robot.base, float)
    pts = [T[:3, 3]]
    for (alpha, a, d, off), qi in zip(np.asarray(robot.dh, float), np.asarray(q, float)):
        K = T @ rotx(alpha) @ trans(a, 0.0, 0.0)
        T = K @ rotz(qi + off) @ trans(0.0, 0.0, d)
        pts += [K[:3, 3], T[:3, 3]]
    out = [pts[0]]
    for p in pts[1:]:
        if np.linalg.norm(p - out[-1]) > 1e-9:
            out.append(p)
    return np.array(out)


def gripper_segments(tool: np.ndarray, width: float, length: float) -> list[np.ndarray]:
    """Line segments (each (2, 3) world points) of a parallel gripper at tool pose ``tool``.

    The tool centre point is midway between the finger tips (Sec. 3.2.2); fingers lie
    at tool y = +-width/2 and run ``length`` back along -z to the palm, which is joined
    by the palm bar. Lengths in the cell unit.
    """
    T = np.asarray(tool, float)
    w = width / 2

    def world(p: Sequence[float]) -> np.ndarray:
        return T[:3, :3] @ np.asarray(p, float) + T[:3, 3]

    return [np.array([world((0, s * w, -length)), world((0, s * w, 0))]) for s in (-1, 1)] + [
        np.array([world((0, -w, -length)), world((0, w, -length))])
    ]


# =========================================================================== scenes


@dataclass
class Scene:
    """The work cell at one step: title, object world poses (4x4, cell unit), the held object
    with its grasp, the arm's joints (rad; None when unknown) and tool pose, and a note on the arm."""

    index: int
    title: str
    detail: str
    poses: dict[str, np.ndarray]
    held: str | None = None
    grasp: str | None = None
    q: np.ndarray | None = None
    tool: np.ndarray | None = None
    arm_note: str = ""


def _grasp_T(cell: Cell, obj: str | None, label: str | None) -> np.ndarray | None:
    if obj is None or label is None or obj not in cell.objects:
        return None
    g = cell.objects[obj].grasps.get(label)
    return None if g is None else np.asarray(g.T, float)


def _step_arm(cell: Cell, step: Mapping[str, Any]) -> tuple[np.ndarray | None, np.ndarray | None]:
    """(q rad, world tool pose) of a step; the tool pose from the plan, else by FK of q."""
    q = None if step.get("joints_deg") is None else np.radians(np.asarray(step["joints_deg"], float))
    tool = None if step.get("tool_pose") is None else np.asarray(step["tool_pose"], float)
    if tool is None and q is not None:
        tool = cell.robot.fk(q)
    return q, tool


def _apply_step(cell: Cell, plan: Plan, step: Mapping[str, Any], before: Scene, index: int) -> Scene:
    """The scene after ``step``: held objects follow the tool (T_obj = T_tool @ inv(T_g)),
    pickup grasps, putdown places (at ``placement``) and releases, assemble mates (at
    T_fixed @ T_a when the tool pose is unknown) and releases; sensing moves nothing."""
    bindings = _instance(plan).get("bindings") or {}
    term = pretty_term(str(step.get("term") or step.get("name") or ""))
    name, args = _term_parts(term)
    args = [str(bindings.get(a, a)) for a in args]
    q, tool = _step_arm(cell, step)
    s = Scene(index, f"step {index}: {term}", "", dict(before.poses), before.held, before.grasp)
    s.q, s.tool, s.arm_note = (q, tool, "") if q is not None else (before.q, before.tool, "unchanged")
    obj = step.get("object") or (args[0] if args else None)
    _take_parts(cell, s.poses, step.get("from") or {})
    if name == "pickup" and len(args) >= 2:
        s.held, s.grasp = args[0], args[1]
    Tg = _grasp_T(cell, s.held, s.grasp)
    moved_by_tool = s.held is not None and Tg is not None and tool is not None
    if moved_by_tool:
        s.poses[str(s.held)] = tool @ inv(Tg)
    if name == "putdown" and obj is not None:
        if step.get("placement"):
            s.poses[obj] = placement_pose(cell, obj, step["placement"])
        s.held = s.grasp = None
    elif name == "assemble" and len(args) >= 4:
        held, fixed, ta = args[0], args[1], args[3]
        if not (moved_by_tool and s.held == held) and fixed in s.poses and ta in cell.transforms:
            s.poses[held] = s.poses[fixed] @ np.asarray(cell.transforms[ta], float)
        s.held = s.grasp = None
    s.detail = _step_detail(s, step, obj)
    return s


def _model(key: str) -> str:
    """The object (model) a scene key draws: ``peg`` for a stock's part ``peg@init_pos1``."""
    return key.split("@", 1)[0]


def _take_parts(cell: Cell, poses: dict[str, np.ndarray], sources: Mapping[str, str]) -> None:
    """Make the stock part a step takes (``from``: object -> initial position label) the one
    drawn under the object's name, as phase 2 does; the part it replaces keeps a key of its own."""
    for obj, label in sources.items():
        pos = cell.positions.get(label)
        key = f"{obj}@{pos.name}" if pos is not None else None
        if key in poses and obj in poses:
            poses[obj], poses[key] = poses[key], poses[obj]


def _step_detail(s: Scene, step: Mapping[str, Any], obj: str | None) -> str:
    """The picture's subtitle: step kind (unless a manipulation), held object, joints (deg), placement."""
    kind = step.get("kind", "")
    parts = [str(kind)] if kind and kind != "manipulation" else []
    if s.held:
        parts.append(f"holding {s.held} ({s.grasp})")
    if s.q is not None:
        parts.append("q = (" + ", ".join(f"{v:.0f}" for v in np.degrees(s.q)) + ") deg"
                     + (" (unchanged)" if s.arm_note else ""))
    pl = step.get("placement")
    if pl:
        parts.append(f"placed {obj} {pl.get('pose', '')} at ({pl.get('x', 0):.3g}, {pl.get('y', 0):.3g})"
                     f" yaw {pl.get('yaw_deg', 0):.3g} deg")
    return "; ".join(parts)


def scenes(cell: Cell, plan: Plan) -> list[Scene]:
    """The work cell before the plan (index 0) and after each step of the plan instance (1..n).

    Initial object poses come from ``cell.positions``; the initial picture shows the arm,
    greyed, in the first configuration the plan uses (the plan gives no rest pose).
    """
    plan = _doc(plan)
    poses: dict[str, np.ndarray] = {}
    for p in cell.positions.values():  # a stock's further parts as "<obj>@<position name>"
        poses[p.obj if p.obj not in poses else f"{p.obj}@{p.name}"] = np.array(p.T, float)
    steps = list(_instance(plan).get("steps") or [])
    first = next((st for st in steps if st.get("joints_deg") is not None), None)
    q0, tool0 = _step_arm(cell, first) if first is not None else (None, None)
    out = [Scene(0, "initial state", "arm drawn in the plan's first configuration" if q0 is not None else "",
                 poses, q=q0, tool=tool0, arm_note="first configuration" if q0 is not None else "")]
    for k, step in enumerate(steps, start=1):
        out.append(_apply_step(cell, plan, step, out[-1], k))
    return out


# =========================================================================== cell drawing


def _hull(points: np.ndarray) -> np.ndarray:
    """Convex hull (counter-clockwise, (m, 2)) of 2-D points: Andrew's monotone chain."""
    pts = sorted(set(map(tuple, np.round(points, 9))))
    if len(pts) <= 2:
        return np.array(pts)

    def half(seq: list[tuple[float, float]]) -> list[tuple[float, float]]:
        h: list[tuple[float, float]] = []
        for p in seq:
            while len(h) >= 2 and ((h[-1][0] - h[-2][0]) * (p[1] - h[-2][1])
                                   - (h[-1][1] - h[-2][1]) * (p[0] - h[-2][0])) <= 0:
                h.pop()
            h.append(p)
        return h

    lower, upper = half(pts), half(pts[::-1])
    return np.array(lower[:-1] + upper[:-1])


@dataclass
class _Frame:
    """Shared extents of a picture series: the table rectangle and the axis box (cell unit)."""

    table: tuple[float, float, float, float]  # x0, x1, y0, y1 at z = 0
    lo: np.ndarray
    hi: np.ndarray


def _arm_points(cell: Cell, s: Scene) -> np.ndarray | None:
    if s.q is None:
        return None
    pts = arm_polyline(cell.robot, s.q)
    if s.tool is not None:
        pts = np.vstack([pts, s.tool[:3, :3] @ [0.0, 0.0, -_finger_length(cell)] + s.tool[:3, 3]])
    return pts


def _finger_length(cell: Cell) -> float:
    return 0.5 * cell.finger_separation


def _table(cell: Cell, all_scenes: Sequence[Scene]) -> tuple[float, float, float, float]:
    """The table top (x0, x1, y0, y1 at z = 0, cell unit): every object of every scene, padded
    by a fifth of their spread or the largest object's bounding radius, whichever is more."""
    objs = [object_points(cell.objects[_model(o)], T) for s in all_scenes for o, T in s.poses.items()
            if _model(o) in cell.objects]
    op = np.vstack(objs) if objs else np.zeros((1, 3))
    span = float(max(np.ptp(op[:, 0]), np.ptp(op[:, 1])))
    pad = max(0.2 * span, max((m.bounding_radius() for m in cell.objects.values()), default=1.0), 1e-6)
    return (float(op[:, 0].min() - pad), float(op[:, 0].max() + pad),
            float(op[:, 1].min() - pad), float(op[:, 1].max() + pad))


def _extent(cell: Cell, all_scenes: Sequence[Scene]) -> _Frame:
    """Table and axis box shared by all pictures of a plan: objects, table, pedestal and
    every arm configuration, with a 5 % margin (cell unit)."""
    table = _table(cell, all_scenes)
    base = np.asarray(cell.robot.base, float)[:3, 3]
    pts = [np.array([[table[0], table[2], 0.0], [table[1], table[3], 0.0], base, [base[0], base[1], 0.0]])]
    pts += [object_points(cell.objects[_model(o)], T) for s in all_scenes for o, T in s.poses.items()
            if _model(o) in cell.objects]
    pts += [p for s in all_scenes if (p := _arm_points(cell, s)) is not None]
    allp = np.vstack(pts)
    lo, hi = allp.min(axis=0), allp.max(axis=0)
    m = 0.05 * float(max(hi - lo))
    return _Frame(table, lo - m, hi + m)


def _colour(cell: Cell, obj: str) -> str:
    names = list(cell.objects)
    return OBJECT_COLOURS[names.index(obj) % len(OBJECT_COLOURS)] if obj in names else "#777777"


def hole_mouth(cell: Cell, obj: str) -> tuple[np.ndarray, np.ndarray, float] | None:
    """The mouth of ``obj``'s hole in its object frame: (centre (3,), outward axis (3,), radius), or None.

    The model gives the hole's bottom centre F_h and radius (Sec. 3.2.2) but not its
    axis; a goal ``assembled(P, obj, _, Ta, Va)`` does: the mating motion Va (obj's
    frame) runs down the hole, so the mouth is where the ray F_h - t Va leaves obj's
    boxes. None for an object with no hole or no such goal.
    """
    model = cell.objects.get(obj)
    if model is None or model.feature is None or model.feature.kind != "hole":
        return None
    axis = None
    for g in cell.goals:
        name, args = _term_parts(g)
        if name == "assembled" and len(args) == 5 and args[1] == obj and args[4] in cell.vectors:
            va = np.asarray(cell.vectors[args[4]], float)
            if np.linalg.norm(va) > 0:
                axis = -va / np.linalg.norm(va)
                break
    if axis is None:
        return None
    origin = np.asarray(model.feature.vector, float)
    exits = [0.0]
    for sd in model.shape:
        with np.errstate(divide="ignore", invalid="ignore"):
            t1, t2 = (np.asarray(sd.lo) - origin) / axis, (np.asarray(sd.hi) - origin) / axis
        lo = np.where(axis != 0, np.minimum(t1, t2), -np.inf)
        hi = np.where(axis != 0, np.maximum(t1, t2), np.inf)
        inside_other = np.all((axis != 0) | ((sd.lo <= origin) & (origin <= sd.hi)))
        if inside_other and lo.max() <= 1e-9 <= hi.min():
            exits.append(float(hi.min()))
    return origin + max(exits) * axis, axis, float(model.feature.radius)


def _disc(centre: np.ndarray, normal: np.ndarray, radius: float, segments: int = 24) -> np.ndarray:
    """Points (segments, 3) of a circle of ``radius`` about ``centre`` in the plane normal to ``normal``."""
    n = normal / np.linalg.norm(normal)
    u = np.cross(n, [1.0, 0.0, 0.0] if abs(n[0]) < 0.9 else [0.0, 1.0, 0.0])
    u /= np.linalg.norm(u)
    v = np.cross(n, u)
    a = np.linspace(0.0, 2 * math.pi, segments, endpoint=False)
    return centre + radius * (np.outer(np.cos(a), u) + np.outer(np.sin(a), v))


def _paint_list(cell: Cell, s: Scene, eye: Sequence[float]) -> list[tuple[str, np.ndarray, str]]:
    """What to paint for the objects, far to near along ``eye`` (unit vector towards the viewer):
    (kind 'solid' | 'hole', world points, colour). Hole mouths facing away are left out."""
    eye = np.asarray(eye, float)
    items: list[tuple[float, str, np.ndarray, str]] = []
    size = max((m.bounding_radius() for m in cell.objects.values()), default=1.0)
    for key, T in s.poses.items():
        o = _model(key)
        if o not in cell.objects:
            continue
        for sd in cell.objects[o].shape:
            p = solid_points(sd, T, 24)
            items.append((float(p.mean(axis=0) @ eye), "solid", p, _colour(cell, o)))
        mouth = hole_mouth(cell, o)
        if mouth is not None:
            c, n, r = mouth
            nw = T[:3, :3] @ n
            if float(nw @ eye) > 1e-6:
                cw = T[:3, :3] @ c + T[:3, 3] + 1e-3 * size * nw
                items.append((float(cw @ eye), "hole", _disc(cw, nw, r), "#1a1a1a"))
    items.sort(key=lambda t: t[0])
    return [(k, p, col) for _, k, p, col in items]


def _view_eye(elev_deg: float, azim_deg: float) -> np.ndarray:
    """Unit vector from the scene towards a 3-D axes' viewer at (elev, azim) degrees."""
    e, a = math.radians(elev_deg), math.radians(azim_deg)
    return np.array([math.cos(e) * math.cos(a), math.cos(e) * math.sin(a), math.sin(e)])


VIEW_3D = (22.0, -58.0)  # elevation, azimuth (deg) of the 3-D panel
TOP_EYE = (0.0, 0.0, 1.0)  # the top view looks down from +z
SIDE_EYE = (0.0, -1.0, 0.0)  # the side view looks from -y


def _draw_3d(ax: Any, cell: Cell, s: Scene, fr: _Frame) -> None:
    """The 3-D panel; painted in a fixed order (table, objects far to near, arm on top)."""
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection

    ax.computed_zorder = False
    x0, x1, y0, y1 = fr.table
    ax.add_collection3d(Poly3DCollection([np.array([[x0, y0, 0], [x1, y0, 0], [x1, y1, 0], [x0, y1, 0]])],
                                         facecolor=TABLE_COLOUR, alpha=0.35, edgecolor="#8a7a5a", zorder=1),
                         autolim=False)
    for k, (kind, p, colour) in enumerate(_paint_list(cell, s, _view_eye(*VIEW_3D))):
        faces = [p] if kind == "hole" else _faces_of_points(p)
        ax.add_collection3d(Poly3DCollection(faces, facecolor=colour, alpha=0.92 if kind == "solid" else 1.0,
                                             edgecolor="#222222", linewidths=0.3, zorder=2 + k * 1e-3),
                             autolim=False)
    _draw_arm(ax, cell, s, lambda p: (p[:, 0], p[:, 1], p[:, 2]), zorder=3)
    c, h = (fr.lo + fr.hi) / 2, float(max(fr.hi - fr.lo)) / 2
    ax.set_xlim(c[0] - h, c[0] + h)
    ax.set_ylim(c[1] - h, c[1] + h)
    z0 = max(c[2] - h, fr.lo[2])
    ax.set_zlim(z0, z0 + 2 * h)
    ax.set_box_aspect((1, 1, 1), zoom=1.0)
    ax.view_init(elev=VIEW_3D[0], azim=VIEW_3D[1])
    u = cell.unit
    ax.set_xlabel(f"x ({u})")
    ax.set_ylabel(f"y ({u})")
    ax.set_zlabel(f"z ({u})")


def _draw_arm(ax: Any, cell: Cell, s: Scene, proj: Any, zorder: float = 3) -> None:
    """The pedestal, the arm skeleton and the gripper on ``ax``; ``proj`` maps (k, 3) to plot args."""
    base = np.asarray(cell.robot.base, float)[:3, 3]
    ax.plot(*proj(np.array([[base[0], base[1], 0.0], base])), color="#888888", lw=7, solid_capstyle="butt",
            zorder=zorder)
    pts = _arm_points(cell, s)
    if pts is None:
        return
    alpha = 0.35 if s.arm_note == "first configuration" else 1.0
    ax.plot(*proj(pts), color=ARM_COLOUR, lw=3.5, alpha=alpha, marker="o", ms=4, solid_capstyle="round",
            zorder=zorder)
    if s.tool is not None:
        width = cell.finger_separation
        if s.held is not None and _grasp_T(cell, s.held, s.grasp) is not None:
            width = cell.objects[s.held].grasps[str(s.grasp)].width
        for seg in gripper_segments(s.tool, width, _finger_length(cell)):
            ax.plot(*proj(seg), color=GRIPPER_COLOUR, lw=2.4, alpha=alpha, zorder=zorder + 0.1)


def _draw_2d(ax: Axes, cell: Cell, s: Scene, fr: _Frame, axes: tuple[int, int], eye: Sequence[float]) -> None:
    """An orthographic view onto world axes ``axes`` (0 x, 1 y, 2 z) seen from ``eye``, far to near."""
    from matplotlib.patches import Polygon, Rectangle

    i, j = axes
    x0, x1, y0, y1 = fr.table
    if axes == (0, 1):
        ax.add_patch(Rectangle((x0, y0), x1 - x0, y1 - y0, fc=TABLE_COLOUR, alpha=0.35, ec="#8a7a5a"))
    else:
        lo, hi = (x0, x1) if i == 0 else (y0, y1)
        ax.plot([lo, hi], [0, 0], color="#8a7a5a", lw=4, solid_capstyle="butt")
    for kind, p, colour in _paint_list(cell, s, eye):
        ax.add_patch(Polygon(_hull(p[:, [i, j]]), closed=True, fc=colour, ec="#222222",
                             lw=0.6 if kind == "solid" else 0.0, alpha=0.92 if kind == "solid" else 1.0))
    _draw_arm(ax, cell, s, lambda p: (p[:, i], p[:, j]))
    ax.set_xlim(fr.lo[i], fr.hi[i])
    ax.set_ylim(fr.lo[j], fr.hi[j])
    ax.set_aspect("equal", adjustable="box", anchor="W")
    names = "xyz"
    ax.set_xlabel(f"{names[i]} ({cell.unit})")
    ax.set_ylabel(f"{names[j]} ({cell.unit})")
    ax.grid(True, lw=0.3, alpha=0.5)


def _cell_figure(cell: Cell, s: Scene, fr: _Frame, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch

    fig = plt.figure(figsize=(12, 7.2), dpi=100)
    ax3 = fig.add_axes((0.0, 0.09, 0.6, 0.82), projection="3d")
    _draw_3d(ax3, cell, s, fr)
    top = fig.add_axes((0.6, 0.56, 0.38, 0.32))
    _draw_2d(top, cell, s, fr, (0, 1), TOP_EYE)
    top.set_title("top view (looking down)", fontsize=9)
    side = fig.add_axes((0.6, 0.13, 0.38, 0.32))
    _draw_2d(side, cell, s, fr, (0, 2), SIDE_EYE)
    side.set_title("side view (from -y)", fontsize=9)
    fig.text(0.5, 0.975, s.title, ha="center", va="top", fontsize=13, weight="bold", family="monospace")
    if s.detail:
        fig.text(0.5, 0.935, s.detail, ha="center", va="top", fontsize=9, family="monospace")
    handles: list[Any] = [Patch(fc=_colour(cell, o), ec="#222222",
                                label=o + (f" (held, {s.grasp})" if o == s.held else ""))
                          for o in cell.objects if o in s.poses]
    eyes = (_view_eye(*VIEW_3D), TOP_EYE, SIDE_EYE)
    if any(kind == "hole" for e in eyes for kind, *_ in _paint_list(cell, s, e)):
        handles.append(Patch(fc="#1a1a1a", label="hole mouth"))
    handles += [Patch(fc=TABLE_COLOUR, alpha=0.35, ec="#8a7a5a", label="table (z = 0)"),
                Line2D([], [], color=ARM_COLOUR, lw=3.5, marker="o", ms=4,
                       alpha=0.35 if s.arm_note == "first configuration" else 1.0,
                       label=f"{cell.robot.name} DH frames" + (f" ({s.arm_note})" if s.arm_note else "")),
                Line2D([], [], color=GRIPPER_COLOUR, lw=2.4, label="gripper")]
    fig.legend(handles=handles, loc="lower center", ncol=len(handles), fontsize=9, frameon=False)
    fig.savefig(path, dpi=100, facecolor="white")
    plt.close(fig)


def cell_png(cell: Cell, plan: Plan, step_index: int, path: str | Path) -> Path:
    """Draw the work cell at step ``step_index`` (0 = initial state, k = after step k) into ``path``.

    Three panels: a 3-D view, a top view and a side view, all with equal axis scaling
    in the cell unit and the same extents for every step of the plan. Raises
    SparValueError for a step index outside 0..n.
    """
    all_scenes = scenes(cell, plan)
    if not 0 <= step_index < len(all_scenes):
        raise SparValueError(f"step_index {step_index} outside 0..{len(all_scenes) - 1}")
    path = Path(path)
    _cell_figure(cell, all_scenes[step_index], _extent(cell, all_scenes), path)
    return path


def _slug(name: str) -> str:
    return re.sub(r"[^A-Za-z0-9_]+", "_", name).strip("_") or "step"


def write_pictures(cell: Cell, plan: Plan, outdir: str | Path, use_graphviz: bool = False) -> list[Path]:
    """Write every picture of a plan into ``outdir`` and return their paths, in this order:
    ordering.dot, ordering.png, network.dot, network.png, cell_00_initial.png,
    cell_01_<name>.png, ... (one per step of the instance, named by the step's action name).

    A plan whose outcome is not ``"plan"`` writes nothing and returns []. ``use_graphviz``
    as for :func:`render_png`.
    """
    plan = _doc(plan)
    if not _is_plan(plan):
        return []
    out = Path(outdir)
    out.mkdir(parents=True, exist_ok=True)
    paths: list[Path] = []
    for stem, text in (("ordering", ordering_dot(plan)), ("network", network_dot(plan))):
        dot = out / f"{stem}.dot"
        dot.write_text(text, encoding="utf-8")
        paths += [dot, render_png(text, out / f"{stem}.png", use_graphviz)]
    all_scenes = scenes(cell, plan)
    fr = _extent(cell, all_scenes)
    steps = list(_instance(plan).get("steps") or [])
    names = ["initial"] + [_slug(str(st.get("name") or _term_parts(str(st.get("term", "")))[0])) for st in steps]
    for k, s in enumerate(all_scenes):
        p = out / f"cell_{k:02d}_{names[k]}.png"
        _cell_figure(cell, s, fr, p)
        paths.append(p)
    return paths
