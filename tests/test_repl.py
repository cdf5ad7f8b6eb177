"""The toplevel (`spar repl`) as a user scripts it: load problems, plan, help, errors."""
from __future__ import annotations

import subprocess

from paths import ROOT, SPAR


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
    assert "L = [peg_in_block, two_pegs]." in out
    assert "X = 1." in out and "X = 3." in out
    # plans and partial plans answer as one line, not as a term of several kB
    assert "P = <plan peg_in_block: 4 actions, 4 steps, 0 expected failures>." in out
    assert "Partial = <partial plan: 6 actions, 6 orderings>." in out
    assert "partial(" not in out and "cms(" not in out and "PLAN ACTIONS" not in out
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


def test_the_plan_prints_once() -> None:
    """The quick start's `plan(..., P), print_plan(P)`: print_plan/1 prints the plan, the
    answer shows P as one line."""
    r = session("plan(peg_in_block, P), print_plan(P).\n")
    assert r.returncode == 0, r.stderr
    out = r.stdout
    assert out.count("PLAN ACTIONS") == 1 and out.count("PLAN INSTANCE") == 1, out
    assert out.rstrip().endswith("P = <plan peg_in_block: 4 actions, 4 steps, 0 expected failures>."), out


def test_help_shows_the_pldoc() -> None:
    """help/1 prints the PlDoc of the exported predicates, not blank lines."""
    r = session("help(plan/2).\nhelp(load_problem/1).\nhelp(print_plan/1).\nhelp(plan_step/3).\n"
                "help(step_joints/2).\nhelp(plan_actions/2).\n")
    assert r.returncode == 0, r.stderr
    out = r.stdout
    for head in ("plan(+Problem, -Plan) is semidet.", "load_problem(+File) is det.", "print_plan(+Plan) is det.",
                 "plan_step(+Plan, ?N:positive_integer, -Step) is nondet.",
                 "step_joints(+Step, -JointsDeg:list(float)) is semidet.",
                 "The phase-1 actions of Plan as action(Id, Term)"):
        assert head in out, out
    assert "set_actions_of_plan" not in out, out  # plan_state's plan_actions/2 is not the user's
    assert "No documentation" not in out, out


def test_the_plan_accessors() -> None:
    """plan_actions/2, plan_outcome/2, plan_step/3 and the step_*/2 readers, each in a query."""
    r = session(
        "plan(peg_in_block, P), plan_actions(P, As), length(As, NA).\n"
        "plan(peg_in_block, P), plan_outcome(P, O).\n"
        "plan(peg_in_block, P), findall(N, plan_step(P, N, _), Ns).\n"
        "plan(peg_in_block, P), plan_step(P, 3, S), step_id(S, Id), step_action(S, A).\n"
        "plan(peg_in_block, P), plan_step(P, 3, S), step_joints(S, Q), length(Q, NQ), "
        "maplist(float, Q).\n"
        "plan(peg_in_block, P), plan_step(P, 4, S), step_verdicts(S, [V]), "
        "get_dict(constraint, V, C), get_dict(satisfied, V, Sat).\n"
        "plan(peg_in_block, P), plan_step(P, 5, _).\n"
        "plan_step(not_a_plan, 1, _).\n"
        "plan(peg_in_block, P), plan_step(P, 0, _).\n")
    out, err = r.stdout, r.stderr
    assert r.returncode == 0, err
    assert "NA = 4." in out and "As = [action(action_4, pickup(block, grasp_2))," in out, out
    assert "O = certain." in out, out
    assert "Ns = [1, 2, 3, 4]." in out, out
    assert "S = <step 3 action_2: pickup(peg, p1G10)>," in out, out
    assert "Id = action_2," in out and "A = pickup(peg, p1G10)." in out, out
    assert "NQ = 6." in out and "Q = [-29.69" in out, out
    assert "C = centres," in out and "Sat = @true." in out, out
    assert out.count("false.") == 1, out               # no fifth step
    assert "Type error: `plan' expected, found `not_a_plan' (an atom)" in err, err
    assert "Type error: `positive_integer' expected, found `0' (an integer)" in err, err
