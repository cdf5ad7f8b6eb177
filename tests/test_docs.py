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
