"""The janus bridge: the recorded SWI-Prolog, typed errors, surviving failed queries, the toplevel."""
from __future__ import annotations

import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

import pytest

from spar_py.planning.engine import engine, swipl_record
from spar_py.core.errors import PrologError
from spar_py.planning.planner import Outcome, Planner

from paths import ROOT, SPAR


def test_runs_the_recorded_swi_prolog() -> None:
    rec = swipl_record()
    assert rec["version"] >= 90112
    assert engine().query_once("current_prolog_flag(version, V)")["V"] == rec["version"]


def test_prolog_exception_is_typed_with_its_message() -> None:
    with pytest.raises(PrologError) as e:
        engine().query_once("atom_length(X, Y)")
    assert "instantiated" in e.value.message


def test_engine_survives_a_failed_query() -> None:
    eng = engine()
    with pytest.raises(PrologError):
        eng.query_once("spar:phase1(no_such_problem, [], _)")
    plan = Planner().plan(ROOT / "kb/problems/hole_up.yaml", phase1_only=True)
    assert plan.ok and len(plan.actions) == 2


def test_timeout_ends_the_search_cleanly(tmp_path: Path) -> None:
    from spar_py.app.gen import generate_assembly

    big = generate_assembly(10, tmp_path)  # 40 actions
    # a quarter of what the whole plan takes on this machine (a fixed 0.3 s came after the end of
    # the plan once the planner got faster); a new Planner loads the cell afresh, empty memo tables
    whole = Planner(max_actions=42).plan(big)
    assert whole.ok
    t0 = time.perf_counter()
    plan = Planner(max_actions=42, timeout=whole.timing["total_s"] / 4).plan(big)
    assert plan.outcome is Outcome.TIMEOUT and not plan.ok and plan.instance is None
    assert time.perf_counter() - t0 < 5.0
    assert Planner().plan(ROOT / "kb/problems/hole_up.yaml", phase1_only=True).ok


def test_repl_answers_with_the_built_version() -> None:
    r = subprocess.run(SPAR + ["repl"], input="current_prolog_flag(version, V).\n",
                       capture_output=True, text=True, timeout=120, cwd=ROOT)
    assert f"V = {swipl_record()['version']}." in r.stdout
    assert "plan(peg_in_block, P)." in r.stdout


def _old_swipl() -> str | None:
    """A swipl older than janus's floor on this machine (Debian's 9.0.4), if any."""
    exe = shutil.which("swipl", path="/usr/bin")
    if not exe:
        return None
    out = subprocess.run([exe, "--dump-runtime-variables"], capture_output=True, text=True).stdout
    v = next((int(line.split('"')[1]) for line in out.splitlines() if line.startswith("PLVERSION=")), 0)
    return exe if v < 90112 else None


@pytest.mark.skipif(_old_swipl() is None, reason="no SWI-Prolog older than 9.1.12 in /usr/bin to mix in")
def test_old_swipl_first_on_path_does_not_break_the_engine() -> None:
    env = {**os.environ, "PATH": f"/usr/bin:{os.environ['PATH']}"}
    r = subprocess.run([sys.executable, "-c",
                        "from spar_py.planning.engine import engine; "
                        "print(engine().query_once('current_prolog_flag(version, V)')['V'])"],
                       capture_output=True, text=True, timeout=120, env=env)
    assert r.returncode == 0, r.stderr
    assert r.stdout.strip() == str(swipl_record()["version"])


def test_the_planner_takes_its_defaults_from_prolog() -> None:
    d = engine().query_once("spar_defaults:default_options(D)")["D"]
    p = Planner()
    assert (p.max_actions, p.max_instances, p.separation) == (d["max_actions"], d["max_instances"],
                                                               "separation" in d["declobber"])
    assert Planner(max_actions=3, separation=False).max_actions == 3


def test_the_package_imports_cheaply_and_exports_the_api() -> None:
    code = ("import sys, spar_py; heavy = [m for m in ('numpy', 'janus_swi', 'casadi', 'yaml') if m in sys.modules]; "
            "print(heavy); from spar_py import Planner, Plan, load_problem, Outcome; "
            "print(Planner.__name__, Plan.__name__, load_problem.__name__, Outcome.PLAN.value)")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    assert r.stdout.split("\n")[:2] == ["[]", "Planner Plan load_problem plan"]


def test_a_run_asks_python_each_arc_question_once(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """One oracle memo per phase-1 run (goals:run_oracle/2): the mate_reachable questions the
    lower bound asks about blocks on their side are the search's own, and are not asked again."""
    import spar_py.planning.engine as bridge
    from spar_py.app.gen import generate_assembly

    asked: list[tuple] = []
    real = bridge.arc_pairs

    def logging(*args):  # called by Prolog through py_call, looked up at each call
        asked.append(tuple(tuple(a) if isinstance(a, list) else a for a in args))
        return real(*args)

    monkeypatch.setattr(bridge, "arc_pairs", logging)
    plan = Planner().plan(generate_assembly(2, tmp_path / "kb", blocks="on-side"), phase1_only=True)
    assert plan.ok and len(plan.actions) == 8
    assert any(a[2] == "mate_reachable" and len(a[5]) == 1 and a[5][0].startswith("tr") for a in asked)
    assert len(asked) == len(set(asked)), [a for a in set(asked) if asked.count(a) > 1]
