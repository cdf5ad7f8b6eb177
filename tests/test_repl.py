"""The toplevel (`spar repl`) as a user scripts it: load problems, plan, help, errors."""
from __future__ import annotations

import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
SPAR = [sys.executable, "-m", "spar_py"]


def session(script: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(SPAR + ["repl"], input=script, capture_output=True, text=True, timeout=180, cwd=ROOT)


def test_a_scripted_session() -> None:
    r = session(
        "load_problem('kb/problems/two_pegs.yaml', Q).\n"
        "loaded_problems(L).\n"
        "member(X, [1, 2]).\n"          # nondeterministic: must not swallow the next query
        "X = 3.\n"
        "plan(peg_in_block, P).\n"      # planned with another problem loaded
        "phase1(two_pegs, [], plan(Partial)).\n"
        "help(plan/2).\n"
        "no_such_predicate(1).\n"
        "fail.\n")
    assert r.returncode == 0, r.stderr
    out = r.stdout
    assert "loaded: peg_in_block." in out
    assert "Q = two_pegs." in out
    assert "L = [peg_in_block,two_pegs]." in out
    assert "X = 1." in out and "X = 3." in out
    # plans print as print_plan/1 prints them, not as a term of several kB
    plan_part = out[out.index("P = "):]
    assert "PLAN ACTIONS" in plan_part and "PLAN INSTANCE" in plan_part
    assert "partial(" not in out and "cms(" not in out
    assert "action(action_1, assemble(peg, block" in plan_part
    assert out.count("PLAN ACTIONS") == 2  # the plan and the partial plan of two_pegs
    # help/1 shows the PlDoc of the exported predicates
    assert "plan(+Problem, -Plan) is semidet." in out
    assert "Unknown procedure: no_such_predicate/1" in r.stderr
    assert out.rstrip().endswith("false.")


def test_loading_a_bad_file_is_one_line() -> None:
    r = session("load_problem('kb/objects/peg.yaml').\nloaded_problems(L).\n")
    assert r.returncode == 0
    errors = [ln for ln in r.stderr.splitlines() if ln.strip()]
    assert errors == ["ERROR: kb/objects/peg.yaml: expected a problem file, not an object model (it has `object:`)"], \
        r.stderr
    assert "L = [peg_in_block]." in r.stdout


def test_unload_problem() -> None:
    r = session("load_problem('kb/problems/hole_up.yaml', Q).\nunload_problem(hole_up).\nloaded_problems(L).\n"
                "plan(hole_up, _).\n")
    assert "L = [peg_in_block]." in r.stdout
    assert "problem `hole_up' does not exist" in r.stderr
