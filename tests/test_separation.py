"""Declobbering by separation (issue 8; Sec. 4.1): kb/problems/separation.yaml, whose
only plans need separation, end to end through the CLI, and through the embedded Prolog
the fixture cell of the plunit suite (tests/prolog/fixtures/separation_cell.pl;
tests/prolog/separation.plt goes into detail).

The problem: two identical pegs (one object, two initial positions), the spare at
init_pos1 out of the arm's reach, the other at init_pos5; goals: the spare stays put,
a peg goes into the block. The pickup for the assembly may clobber the first goal
until its position is established; only a separation lets phase 1 go on.
"""
from __future__ import annotations

import json
import subprocess

import numpy as np
import pytest

from spar_py.planning.engine import engine
from spar_py.kb import load_problem

from paths import ROOT, SPAR

PROBLEM = ROOT / "kb" / "problems" / "separation.yaml"
FIXTURE = ROOT / "tests" / "prolog" / "fixtures" / "separation_cell.pl"
TWO = ["pickup(peg,grasp_1)", "assemble(peg,block,[[peg_face],[block_face]],trans_1,vec_1)"]


def spar(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([*SPAR, "plan", str(PROBLEM), *args],
                          capture_output=True, text=True, cwd=ROOT, timeout=300)


def test_separation_gives_the_two_action_plan() -> None:
    r = spar("--json")
    assert r.returncode == 0, r.stderr
    d = json.loads(r.stdout)
    assert d["outcome"] == "plan"
    assert sorted(a["term"] for a in d["partial"]["actions"]) == sorted(TWO)
    (sep,) = d["partial"]["separations"]
    assert sep["text"] == ["part_location(peg,init_pos5)", "part_location(peg,init_pos1)"]
    assert sep["deleted"] == {"functor": "part_location", "args": ["peg", "init_pos5"]}
    assert sep["condition"] == {"functor": "part_location", "args": ["peg", "init_pos1"]}
    assert d["instance"]["error_count"] == 0


def test_phase2_takes_the_part_the_separation_leaves() -> None:
    """The pickup takes the peg at init_pos5 (label tr5): the JSON says so, and its tool
    pose is a grasp of that peg, not of the spare 30 in further out."""
    d = json.loads(spar("--json").stdout)
    pick = next(s for s in d["instance"]["steps"] if s["name"] == "pickup")
    assert pick["source"] == {"peg": "tr5"}
    cell = load_problem(PROBLEM)
    g = cell.objects["peg"].grasps[d["instance"]["bindings"]["grasp_1"]]
    np.testing.assert_allclose(np.array(pick["tool_pose"]), cell.positions["tr5"].T @ g.T, atol=1e-6)


def test_paper_planner_finds_no_plan() -> None:
    """--no-separation is the paper's planner: promotion cannot help (the goal is the initial
    state's, needed by finish) and the white knight, a putdown into the spare's place, is
    out of reach; it says no plan, with that reason, and exits 1. The bound it searched
    completely is well past the 2 actions separation needs."""
    r = spar("--json", "--no-separation")
    assert r.returncode == 1, r.stderr
    d = json.loads(r.stdout)
    assert d["outcome"] == "no_plan"
    assert "reachable(" in d["reason"]["goal"] and "init_pos1" in d["reason"]["goal"]
    assert d["reason"]["max_actions"] >= 4


def test_cli_trace_separation_switch() -> None:
    on = spar("--phase1-only", "--trace")
    off = spar("--phase1-only", "--trace", "--no-separation")
    assert on.returncode == 0 and off.returncode == 1
    assert ": separation [" in on.stdout
    assert ": separation [" not in off.stdout


# The fixture cell, through the embedded Prolog: phase 1 with the paper's methods and
# with separation; the outcome's kind and the partial plan's separations.
PHASE1 = (
    "fixture_separation_cell:load_separation_cell, "
    "spar:phase1(peg_in_block, [max_actions(4), declobber(Ms), "
    "  oracle(fixture_separation_cell:all_pairs_oracle)], _O), "
    "(   _O = plan(_P) "
    "->  Kind = plan, spar:partial_dict(_P, _D), get_dict(separations, _D, Seps) "
    ";   Kind = no_plan, Seps = [] )"
)


@pytest.fixture(scope="module")
def prolog():
    eng = engine()
    eng.query_once("use_module(F)", {"F": str(FIXTURE)})
    return eng


def test_fixture_needs_separation(prolog) -> None:
    a = prolog.query_once(PHASE1.replace("Ms", "[promotion, separation, white_knight]"))
    assert a["Kind"] == "plan"
    assert [x["text"] for x in a["Seps"]] == [["part_location(peg,init_pos5)", "part_location(peg,init_pos1)"]]


def test_fixture_paper_planner_no_plan(prolog) -> None:
    a = prolog.query_once(PHASE1.replace("Ms", "[promotion, white_knight]"))
    assert a["Kind"] == "no_plan"
