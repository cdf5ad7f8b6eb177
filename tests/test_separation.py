"""Declobbering by separation (issue 8; Sec. 4.1): the CLI's `separations` field and
`--no-separation` switch, end to end, and through the embedded Prolog the fixture cell
whose only plan within the bound needs a separation (tests/prolog/fixtures/
separation_cell.pl; the plunit suite tests/prolog/separation.plt goes into detail).

kb/problems/separation.yaml does not need separation (its header says why: with the
real rule base a separated clobberer would need one object in two places or two
grasps at once), so on it both switches give the same 6-action plan and no
separation survives in the partial plan; the trace shows that separation was tried.
"""
from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from spar_py.engine import engine

ROOT = Path(__file__).resolve().parent.parent
PROBLEM = ROOT / "kb" / "problems" / "separation.yaml"
SPAR = [sys.executable, "-m", "spar_py.cli"]
FIXTURE = ROOT / "tests" / "prolog" / "fixtures" / "separation_cell.pl"
SIX = ["pickup(peg2,grasp_3)", "putdown(peg2,pos_1)", "pickup(peg2,grasp_2)",
       "assemble(peg2,block2,[[peg_face],[block_face]],trans_1,vec_1)",
       "pickup(peg,grasp_1)", "assemble(peg,block,[[peg_face],[block_face]],trans_1,vec_1)"]


def spar(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([*SPAR, "plan", str(PROBLEM), "--phase1-only", *args],
                          capture_output=True, text=True, cwd=ROOT, timeout=300)


@pytest.mark.parametrize("switch", [[], ["--no-separation"]])
def test_cli_json_separations_field(switch: list[str]) -> None:
    r = spar("--json", *switch)
    assert r.returncode == 0, r.stderr
    d = json.loads(r.stdout)
    assert d["outcome"] == "plan"
    assert [a["term"] for a in d["partial"]["actions"]] == SIX
    assert d["partial"]["separations"] == []


def test_cli_trace_separation_switch() -> None:
    on = spar("--trace")
    off = spar("--trace", "--no-separation")
    assert on.returncode == off.returncode == 0
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
    assert a["Seps"] == [["part_location(peg,init_pos5)", "part_location(peg,init_pos1)"]]


def test_fixture_paper_planner_no_plan(prolog) -> None:
    a = prolog.query_once(PHASE1.replace("Ms", "[promotion, white_knight]"))
    assert a["Kind"] == "no_plan"
