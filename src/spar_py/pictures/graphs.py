"""The paper's Fig. 24 as Graphviz DOT text, drawn by Graphviz's ``dot``.

- :func:`ordering_dot`: the ordering graph (Fig. 24, bottom), one node per action, an
  edge per ``prior_to``;
- :func:`network_dot`: the geometric constraint network (Fig. 24 top, Fig. 25), one node
  per plan variable with its pruned label set, an edge per arc with its pair count;
- :func:`render_png`: ``dot -Tpng``, which does all layout and drawing.

DOT text is written from the plan JSON only (no Graphviz needed for it); rendering needs
the ``dot`` program (the distribution's graphviz package; ``make setup`` installs it) and
raises :class:`SparError` with a one-line message when it is missing or fails.
"""
from __future__ import annotations

import shutil
import subprocess
import textwrap
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

from spar_py.core.errors import SparError
from spar_py.core.model import natural_key
from spar_py.pictures.plandoc import instance, partial, pretty_term

if TYPE_CHECKING:
    from spar_py.planning.planner import Plan

__all__ = ["dot_executable", "implied_edges", "label_summary", "network_dot", "ordering_dot", "render_png"]

MAX_SHOWN = 8  # labels of a label set shown in a network node
PER_LINE = 4  # labels per line in a network node
WRAP = 40  # characters per line of an action term in an ordering node
DPI = 110  # pixels per inch of the PNG (dot's own default is 96)
DOT_TIMEOUT = 60.0  # s

GRASP_FILL = "#dbe9f6"
POSITION_FILL = "#fde9d9"
ACTION_FILL = "#e8f3e0"
FONT = "monospace"
INSTALL_HINT = "install the graphviz package (apt-get install graphviz; `make setup` does it)"


# =========================================================================== DOT text


def dot_id(s: str, left: bool = False) -> str:
    """A DOT double-quoted string. A newline becomes ``\\n`` (lines centred) or, with
    ``left``, every line ends in ``\\l`` (lines left-justified, as in a listing)."""
    body = s.replace("\\", "\\\\").replace('"', '\\"')
    return '"' + (body.replace("\n", "\\l") + "\\l" if left else body.replace("\n", "\\n")) + '"'


def dot_attrs(left_label: bool = False, **kw: str) -> str:
    """A DOT attribute list; ``left_label`` left-justifies the lines of ``label`` (node texts)."""
    return "[" + ", ".join(f"{k}={dot_id(v, left_label and k == 'label')}" for k, v in kw.items()) + "]"


def dot_header(kind: str, name: str, title: str, rankdir: str, **node: str) -> list[str]:
    """The opening lines of a graph: title on top, monospace text, white page, node defaults."""
    graph = dot_attrs(label=title, labelloc="t", rankdir=rankdir, fontname=FONT, fontsize="12", bgcolor="white",
                   pad="0.25", nodesep="0.35", ranksep="0.45")
    return [
        f"{kind} {name} {{",
        f"  graph {graph};",
        f"  node {dot_attrs(shape='box', style='rounded,filled', fontname=FONT, fontsize='10', **node)};",
        f"  edge {dot_attrs(fontname=FONT, fontsize='10')};",
    ]


def _action_nodes(plan: Plan) -> dict[str, str]:
    """Action id -> its term text (paper spacing), for every action in actions or ordering."""
    nodes: dict[str, str] = {}
    for a in partial(plan).get("actions") or []:
        nodes[str(a.get("id"))] = pretty_term(str(a.get("term") or a.get("name") or ""))
    for edge in partial(plan).get("ordering") or []:
        for n in edge[:2]:
            nodes.setdefault(str(n), "")
    return dict(sorted(nodes.items(), key=lambda kv: natural_key(kv[0])))


def _action_label(action: str, term: str) -> str:
    """``"action_3\\nputdown(block, pos_1)"``; a long term wrapped at WRAP, continuations indented."""
    lines = textwrap.wrap(term, WRAP, break_long_words=False, break_on_hyphens=False, subsequent_indent="  ")
    return "\n".join([action, *lines])


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
    """The ordering graph (Fig. 24, bottom) as Graphviz DOT text, first action on top.

    Nodes are the plan's actions labelled ``"action_3\\lputdown(block, pos_1)\\l"``; an
    edge Before -> After for each ``prior_to(Before, After)`` of ``partial.ordering``.
    Every given edge is present: solid when it belongs to the transitive reduction,
    dashed (``constraint=false``, so it does not stretch the ranks) when a longer chain
    of prior_to already implies it.
    """
    edges = [(str(e[0]), str(e[1])) for e in partial(plan).get("ordering") or []]
    implied = implied_edges(edges)
    title = (f"ordering graph: {plan.problem}\n"
             "solid: prior_to (transitive reduction)\ndashed: implied by a longer chain")
    out = dot_header("digraph", "ordering", title, "TB", fillcolor=ACTION_FILL)
    for n, t in _action_nodes(plan).items():
        out.append(f"  {dot_id(n)} {dot_attrs(True, label=_action_label(n, t) if t else n)};")
    for u, v in dict.fromkeys(edges):
        extra = " " + dot_attrs(style="dashed", constraint="false") if (u, v) in implied else ""
        out.append(f"  {dot_id(u)} -> {dot_id(v)}{extra};")
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
    ``{"vars": [a, b]}``, or, as the plan JSON gives it, ``{"deleted": data, "condition":
    data}``: the two terms of its ``dif/2`` as term data (``{"functor": "part_location",
    "args": ["peg", "init_pos5"]}``); then the first argument pair in which they differ,
    where both are ``variables``."""
    if not isinstance(sep, Mapping):
        return None
    if "vars" in sep:
        vs = sep["vars"]
        ok = isinstance(vs, (list, tuple)) and len(vs) == 2 and all(isinstance(v, str) for v in vs)
        return [vs[0], vs[1]] if ok else None
    if "deleted" not in sep or "condition" not in sep or variables is None:
        return None
    for x, y in _differing(sep["deleted"], sep["condition"]):
        if isinstance(x, str) and isinstance(y, str) and x in variables and y in variables:
            return [x, y]
    return None


def _differing(a: Any, b: Any) -> list[tuple[Any, Any]]:
    """The pairs of corresponding subterms of term data ``a`` and ``b`` that differ,
    innermost first."""
    if a == b:
        return []
    if isinstance(a, Mapping) and isinstance(b, Mapping) and a.get("functor") == b.get("functor") \
            and len(a.get("args", ())) == len(b.get("args", ())):
        return [d for x, y in zip(a["args"], b["args"]) for d in _differing(x, y)] + [(a, b)]
    if isinstance(a, list) and isinstance(b, list) and len(a) == len(b):
        return [d for x, y in zip(a, b) for d in _differing(x, y)] + [(a, b)]
    return [(a, b)]


def _pairs_label(arc: Mapping[str, Any]) -> str:
    """``"42 pairs"`` (``"1 pair"``), under the arc's ``kind`` when the plan gives one."""
    n = len(arc.get("pairs") or [])
    count = f"{n} pair" if n == 1 else f"{n} pairs"
    return f"{arc['kind']}\n{count}" if arc.get("kind") else count


def network_dot(plan: Plan) -> str:
    """The geometric constraint network (Fig. 24, top; Fig. 25) as Graphviz DOT text.

    Nodes are the plan variables with their pruned label sets (abbreviated, see
    :func:`label_summary`), grasps blue, positions orange; an undirected edge per arc,
    labelled ``"N pairs"`` (with the arc's ``kind`` above it when the plan gives one),
    written grasp first so that ``dot`` puts grasps left of positions; separations, if
    any, dotted (``constraint=false``).
    """
    part = partial(plan)
    variables: dict[str, list[str]] = {str(k): list(v or []) for k, v in (part.get("variables") or {}).items()}
    arcs = [a for a in part.get("arcs") or [] if len(a.get("vars") or []) == 2]
    for a in arcs:
        for v in a["vars"]:
            variables.setdefault(str(v), [])
    seps = [s for s in (_separation_vars(x, variables) for x in part.get("separations") or []) if s]
    bindings = instance(plan).get("bindings") or {}
    out = dot_header("graph", "network", f"constraint network: {plan.problem}", "LR")
    for v in sorted(variables, key=natural_key):
        label = label_summary(v, variables[v], bindings.get(v))
        out.append(f"  {dot_id(v)} {dot_attrs(True, label=label, fillcolor=_fill_of(v))};")
    for a in arcs:
        u, v = sorted((str(x) for x in a["vars"]), key=lambda n: (not n.startswith("grasp"), natural_key(n)))
        out.append(f"  {dot_id(u)} -- {dot_id(v)} {dot_attrs(label=_pairs_label(a))};")
    for s in seps:
        out.append(f"  {dot_id(s[0])} -- {dot_id(s[1])} "
                   f"{dot_attrs(label='separated (dif)', style='dotted', constraint='false')};")
    out.append("}")
    return "\n".join(out) + "\n"


# =========================================================================== rendering


def dot_executable() -> str:
    """The path of Graphviz's ``dot``; SparError (one line, how to install it) if it is not on PATH."""
    exe = shutil.which("dot")
    if exe is None:
        raise SparError(f"Graphviz's `dot` is not on PATH, needed to draw the plan's graphs: {INSTALL_HINT}")
    return exe


def render_png(dot_source: str, path: str | Path) -> Path:
    """Lay out and draw DOT text with ``dot -Tpng`` into the PNG ``path`` (DPI pixels per inch).

    Raises SparError with a one-line message when ``dot`` is missing, fails, or runs
    past DOT_TIMEOUT seconds.
    """
    path = Path(path)
    cmd = [dot_executable(), "-Tpng", f"-Gdpi={DPI}", "-o", str(path)]
    try:
        r = subprocess.run(cmd, input=dot_source.encode(), capture_output=True, timeout=DOT_TIMEOUT, check=False)
    except subprocess.TimeoutExpired:
        raise SparError(f"dot -Tpng ran past {DOT_TIMEOUT:g} s drawing {path.name}") from None
    except OSError as e:
        raise SparError(f"dot -Tpng could not run ({e.strerror}): {INSTALL_HINT}") from None
    if r.returncode != 0 or not path.is_file() or path.stat().st_size == 0:
        why = next((ln for ln in r.stderr.decode(errors="replace").splitlines() if ln.strip()), "no output")
        raise SparError(f"dot -Tpng failed drawing {path.name}: {why}")
    return path
