"""The planner in a bare ``swipl`` (not the engine embedded in Python): prolog/spar.pl
loaded alone, Python reached through janus. The embedded engine consults the templates
into ``user``, which can hide a call that resolves only there; a bare swipl cannot.

janus in the bare swipl finds the packages through the environment: PYTHONPATH names
src/ and VIRTUAL_ENV the venv this test runs in (janus puts its site-packages on
sys.path)."""
from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

from spar_py.planning.engine import swipl_record

from paths import ROOT

BARE_PLT = ROOT / "tests" / "prolog" / "bare" / "spar.plt"
QUICKSTART = ROOT / "docs" / "quickstart.md"


def _swipl() -> str:
    """The SWI-Prolog binary of the set-up (``swipl`` of src/spar_py/_swipl.json, else
    the home's bin)."""
    rec = swipl_record()
    path = rec.get("swipl") or str(Path(rec["home"]).parent.parent / "bin" / "swipl")
    assert Path(path).is_file(), f"no SWI-Prolog binary at {path} (run make setup)"
    return path


def _env() -> dict[str, str]:
    """This process's environment with src/ first on PYTHONPATH and this venv active."""
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(p for p in (str(ROOT / "src"), env.get("PYTHONPATH")) if p)
    env["VIRTUAL_ENV"] = sys.prefix
    env.pop("SWI_HOME_DIR", None)
    return env


def _run(args: list[str], stdin: str = "") -> subprocess.CompletedProcess[str]:
    """Run the bare swipl with ``args`` in the checkout (stdout and stderr together)."""
    return subprocess.run([_swipl(), *args], input=stdin, cwd=ROOT, env=_env(), text=True,
                          stdout=subprocess.PIPE, stderr=subprocess.STDOUT, timeout=300)


def test_bare_swipl_reaches_the_venv_and_src() -> None:
    """janus in the bare swipl imports the bridge from this checkout's src/ and numpy from the venv."""
    r = _run(["-q", "-g", "py_call('spar_py.planning.engine':'__file__', F), print(F), nl, "
              "py_call(numpy:'__file__', N), print(N), nl", "-t", "halt"])
    assert r.returncode == 0, r.stdout
    bridge, numpy = r.stdout.split()[:2]
    assert bridge.strip("'").startswith(str(ROOT / "src")), r.stdout
    assert "site-packages" in numpy, r.stdout


def test_bare_plunit() -> None:
    """tests/prolog/bare/spar.plt: no undefined call in the planner, the paper's cell
    planned with the default options, the sideways hole of tab_peg_sideways."""
    r = _run(["-g", "run_tests", "-t", "halt", str(BARE_PLT)])
    assert r.returncode == 0, r.stdout
    assert re.search(r"All \d+ tests passed", r.stdout), r.stdout


def _quickstart_goals() -> list[str]:
    """The toplevel goals docs/quickstart.md shows (its ``?- `` lines)."""
    goals = [line[3:].strip() for line in QUICKSTART.read_text().splitlines() if line.startswith("?- ")]
    assert goals, "docs/quickstart.md shows no toplevel goal"
    return goals


def test_bare_toplevel_quickstart() -> None:
    """`swipl prolog/spar.pl` at its toplevel: load the paper's cell, then the quick-start
    goals each give an answer, shown as a one-line summary (the portray hook), the plan
    printed once (by print_plan/1), no error."""
    goals = _quickstart_goals()
    script = "load_problem('kb/problems/peg_in_block.yaml').\n" + "".join(g + "\n" for g in goals)
    r = _run(["prolog/spar.pl"], stdin=script)
    out = r.stdout
    assert r.returncode == 0, out
    assert "ERROR" not in out and "Warning:" not in out, out
    assert "false." not in out, out
    assert re.search(r"^P = <plan peg_in_block: 4 actions, 4 steps, 0 expected failures>", out, flags=re.M), out
    assert re.search(r"^P = <partial plan: 4 actions, 4 orderings>", out, flags=re.M), out
    assert out.count("PLAN INSTANCE") == 1, out  # print_plan/1's only


def test_bare_toplevel_help() -> None:
    """help/1 in a bare swipl (no collect_docs/0) reads the planner's PlDoc from its sources."""
    r = _run(["prolog/spar.pl"], stdin="help(plan/2).\nhelp(plan_step/3).\n")
    assert r.returncode == 0, r.stdout
    assert "plan(+Problem, -Plan) is semidet." in r.stdout, r.stdout
    assert "plan_step(+Plan, ?N:positive_integer, -Step) is nondet." in r.stdout, r.stdout
    assert "No documentation" not in r.stdout, r.stdout
