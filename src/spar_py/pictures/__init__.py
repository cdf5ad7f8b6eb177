"""Pictures of a plan: the paper's Fig. 24 (ordering graph, constraint network) and the work
cell at every step.

- :mod:`.graphs`: DOT text from the plan JSON, laid out and drawn by Graphviz's ``dot``;
- :mod:`.precedence`: a derived product's precedence graph, drawn the same way (``spar kb
  derive --dot/--png``);
- :mod:`.scene`: the world at each step, read from the plan JSON's per-step ``poses``;
- :mod:`.cell`: the cell picture of one scene (matplotlib).

:func:`write_pictures` writes them all; it is what ``spar plan --png/--dot`` calls.
Nothing is computed at import time, and matplotlib is imported only when a cell is drawn.
"""
from __future__ import annotations

import re
from pathlib import Path
from typing import TYPE_CHECKING

from spar_py.pictures.cell import cell_figure, cell_png, closeup_png, extent
from spar_py.pictures.graphs import dot_executable, network_dot, ordering_dot, render_png
from spar_py.pictures.plandoc import instance, is_plan
from spar_py.pictures.scene import Scene, scenes

if TYPE_CHECKING:
    from spar_py.core.model import Cell
    from spar_py.planning.planner import Plan

__all__ = ["Scene", "cell_png", "network_dot", "ordering_dot", "render_png", "scenes", "write_pictures"]


def _slug(name: str) -> str:
    return re.sub(r"[^A-Za-z0-9_]+", "_", name).strip("_") or "step"


def _step_names(plan: Plan) -> list[str]:
    """File-name stems of the cell pictures: ``initial``, then each step's action name."""
    steps = instance(plan).get("steps") or []
    return ["initial"] + [_slug(str(st.get("name") or str(st.get("term", "")).split("(")[0])) for st in steps]


def write_pictures(cell: Cell, plan: Plan, outdir: str | Path) -> list[Path]:
    """Write every picture of a plan into ``outdir`` and return their paths, in this order:
    ordering.dot, ordering.png, network.dot, network.png, cell_00_initial.png,
    cell_01_<name>.png, ... (one per step of the instance, named by the step's action name), each
    assemble step's followed by its close-up cell_<k>_assemble_closeup.png (the peg, the hole
    and the insertion check's tolerance: pictures.cell.closeup_png).

    ``plan`` a ``planner.Plan`` (a plan JSON read from a file: ``Plan.from_json``). A plan whose
    outcome is not ``"plan"`` writes nothing and returns []. Raises SparError (one line) before writing anything
    when Graphviz's ``dot`` is not installed.
    """
    if not is_plan(plan):
        return []
    dot_executable()
    out = Path(outdir)
    out.mkdir(parents=True, exist_ok=True)
    paths: list[Path] = []
    for stem, text in (("ordering", ordering_dot(plan)), ("network", network_dot(plan))):
        dot = out / f"{stem}.dot"
        dot.write_text(text, encoding="utf-8")
        paths += [dot, render_png(text, out / f"{stem}.png")]
    all_scenes = scenes(cell, plan)
    fr = extent(cell, all_scenes)
    for s, name in zip(all_scenes, _step_names(plan)):
        paths.append(cell_figure(cell, s, fr, out / f"cell_{s.index:02d}_{name}.png"))
        closeup = closeup_png(cell, plan, s, out / f"cell_{s.index:02d}_{name}_closeup.png")
        if closeup is not None:
            paths.append(closeup)
    return paths
