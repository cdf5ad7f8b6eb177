"""The documentation's Python example runs as written."""
from __future__ import annotations

import os
import re
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


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


def test_demo_graphs_are_current() -> None:
    """docs/demo holds what `make demo` writes for the paper's cell; its DOT files must be
    the planner's current output (a stale demo shows arcs the planner no longer gives)."""
    from spar_py.pictures import network_dot, ordering_dot
    from spar_py.planner import Planner

    plan = Planner().plan(ROOT / "kb" / "problems" / "peg_in_block.yaml").to_json()
    assert (ROOT / "docs" / "demo" / "network.dot").read_text() == network_dot(plan)
    assert (ROOT / "docs" / "demo" / "ordering.dot").read_text() == ordering_dot(plan)
