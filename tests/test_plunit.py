"""The plunit suites (tests/prolog/*.plt) as one pytest test, so `make test` runs them on a
core pytest-xdist has free instead of after the whole Python suite.

They run in a process of their own (``python -m spar_py.app.plunit tests/prolog``, as a
developer runs them): the suites load fixtures into the planner's modules, which must not
leak into this process's engine. On failure the assertion shows plunit's whole output.
"""
from __future__ import annotations

import subprocess
import sys

from paths import ROOT


def test_plunit_suites_pass() -> None:
    r = subprocess.run([sys.executable, "-m", "spar_py.app.plunit", "tests/prolog"], cwd=ROOT,
                       capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, f"plunit failed (exit {r.returncode}):\n{r.stdout}\n{r.stderr}"
