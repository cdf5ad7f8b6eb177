"""The documentation's Python example runs as written."""
from __future__ import annotations

import os
import re
import struct
from pathlib import Path
from spar_py.planning.planner import Outcome, Plan

from paths import ROOT


def _typed(doc: dict) -> Plan:
    """The typed Plan of a plan JSON document, or of a test's partial one (the pictures take a Plan and
    read its problem, outcome, partial plan and instance)."""
    return Plan(problem=doc.get("problem", ""), outcome=Outcome(doc["outcome"]), partial=doc.get("partial"),
                instance=doc.get("instance"))


def test_quickstart_python_example(capsys) -> None:
    text = (ROOT / "docs" / "quickstart.md").read_text()
    code = re.search(r"```python\n(.*?)```", text, re.S).group(1)
    cwd = os.getcwd()
    os.chdir(ROOT)
    try:
        exec(compile(code, "quickstart.md", "exec"), {})
    finally:
        os.chdir(cwd)
    out = capsys.readouterr().out
    assert "pickup(block,grasp_2)" in out and "assemble(peg,block" in out
    assert "centres" in out


def _png_size(path: Path) -> tuple[int, int]:
    data = path.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n", f"{path} is not a PNG"
    return struct.unpack(">II", data[16:24])


def test_demo_graphs_are_current(tmp_path: Path) -> None:
    """docs/demo holds what `make demo` writes for the paper's cell: its DOT files must be
    the planner's current output (a stale demo shows arcs the planner no longer gives), its
    graph PNGs dot's drawing of those files (same pixel size as drawn now), and its cell
    pictures one per step of the plan and a close-up per assemble step, named as write_pictures
    names them."""
    from spar_py.pictures import network_dot, ordering_dot, render_png
    from spar_py.planning.planner import Planner

    plan = Planner().plan(ROOT / "kb" / "problems" / "peg_in_block.yaml").to_json()
    demo = ROOT / "docs" / "demo"
    for stem, text in (("network", network_dot(_typed(plan))), ("ordering", ordering_dot(_typed(plan)))):
        assert (demo / f"{stem}.dot").read_text() == text
        assert _png_size(demo / f"{stem}.png") == _png_size(render_png(text, tmp_path / f"{stem}.png"))
    steps = plan["instance"]["steps"]
    closeups = sorted(p.name for p in demo.glob("cell_*_closeup.png"))
    cells = sorted(p.name for p in demo.glob("cell_*.png") if not p.name.endswith("_closeup.png"))
    assert len(cells) == len(steps) + 1 and cells[0] == "cell_00_initial.png"
    assert [c.split("_", 2)[2][:-4] for c in cells[1:]] == [st["name"] for st in steps]
    # one close-up per assemble step, named after its step's picture
    assert closeups == [c[:-4] + "_closeup.png" for c, st in zip(cells[1:], steps) if st["name"] == "assemble"]
