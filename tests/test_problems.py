"""The regression problems of kb/problems/ (issue 6): every file loads and says what it
tests; phase 1 gives each the outcome its header promises (through the embedded Prolog)."""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from spar_py.world.reach import placement as placement
from spar_py.planning.engine import engine
from spar_py.kb import load_problem
from spar_py.world.collision import CellCache

from paths import ROOT

PROBLEMS = sorted((ROOT / "kb" / "problems").glob("*.yaml"))

ASSEMBLE = "assemble(peg,block,[[peg_face],[block_face]],trans_1,vec_1)"
ASSEMBLE2 = "assemble(peg2,block2,[[peg_face],[block_face]],trans_1,vec_1)"
PAPER_ACTIONS = ["pickup(block,grasp_2)", "putdown(block,pos_1)", "pickup(peg,grasp_1)", ASSEMBLE]
PAPER_ORDER = ["prior_to(action_2,action_1)", "prior_to(action_3,action_1)",
               "prior_to(action_3,action_2)", "prior_to(action_4,action_3)"]

# Phase 1 on the loaded problem: the outcome's kind, the actions (newest first) and
# the ordering as ~q text, the label sets after arc consistency; for no_plan the
# bound reached and the unmet goal.
PHASE1 = (
    "spar:phase1(Name, [max_actions(Max)], _O), "
    "(   _O = plan(_P) "
    "->  Kind = plan, Bound = 0, Unmet = \"\", "
    "    spar:partial_actions(_P, _As), "
    "    findall(_S, (member(action(_, _T), _As), format(string(_S), '~q', [_T])), Actions), "
    "    spar:partial_ordering(_P, _Os), "
    "    findall(_S, (member(_X, _Os), format(string(_S), '~q', [_X])), Order), "
    "    spar:partial_dict(_P, _D), get_dict(variables, _D, Labels) "
    ";   _O = no_plan(Bound, _G), Kind = no_plan, Actions = [], Order = [], Labels = [], "
    "    format(string(Unmet), '~q', [_G]) "
    ")"
)


@dataclass(frozen=True)
class Outcome:
    """What phase 1 gave: ``kind`` plan | no_plan and its details."""

    kind: str
    actions: list[str]
    order: list[str]
    labels: dict[str, Any]
    bound: int
    unmet: str


def phase1(name: str, max_actions: int = 12) -> Outcome:
    """Load kb/problems/<name>.yaml into the engine and run phase 1."""
    cell = load_problem(ROOT / "kb" / "problems" / f"{name}.yaml")
    e = engine()
    e.load_cell(cell)
    a = e.query_once(PHASE1, {"Name": cell.name, "Max": max_actions})
    assert a["truth"], a
    return Outcome(a["Kind"], list(a["Actions"]), list(a["Order"]),
                   {str(k): sorted(map(str, v)) for k, v in dict(a["Labels"] or {}).items()},
                   int(a["Bound"]), str(a["Unmet"]))


# ---------------------------------------------------------------------- the files


def test_corpus_has_the_regression_problems() -> None:
    names = {p.stem for p in PROBLEMS}
    assert {"hole_up", "large_uncertainty", "hopeless_uncertainty", "regrasp", "two_pegs",
            "unreachable", "second_base", "separation", "placement_trap"} <= names


@pytest.mark.parametrize("path", PROBLEMS, ids=[p.stem for p in PROBLEMS])
def test_problem_loads_and_has_a_header(path: Path) -> None:
    cell = load_problem(path)
    assert cell.name == path.stem
    assert cell.goals
    assert path.read_text(encoding="utf-8").startswith("#"), "a header comment saying what it tests"


def test_problem_names_are_distinct() -> None:
    names = [load_problem(p).name for p in PROBLEMS]
    assert len(set(names)) == len(names)


# ---------------------------------------------------------------------- phase 1


def test_hole_up_needs_two_actions() -> None:
    o = phase1("hole_up")
    assert o.kind == "plan"
    assert o.actions == ["pickup(peg,grasp_1)", ASSEMBLE]
    assert o.order == ["prior_to(action_2,action_1)"]
    assert o.labels["init_pos2"] == ["tr2"]


def test_unreachable_ends_without_plan_naming_the_goal() -> None:
    o = phase1("unreachable", max_actions=6)
    assert o.kind == "no_plan"
    assert o.bound <= 6
    assert o.unmet.startswith("geo(") and "reachable(" in o.unmet and "init_pos" in o.unmet


@pytest.mark.parametrize("name", ["peg_in_block", "large_uncertainty", "hopeless_uncertainty",
                                  "second_base"])
def test_paper_plan(name: str) -> None:
    o = phase1(name)
    assert o.kind == "plan"
    assert o.actions == PAPER_ACTIONS
    assert o.order == PAPER_ORDER


def test_second_base_gives_the_paper_network() -> None:
    """The cell moved with the arm: the same arcs survive, so the same label sets."""
    assert phase1("second_base").labels == phase1("peg_in_block").labels


def test_regrasp_picks_the_peg_twice() -> None:
    o = phase1("regrasp")
    assert o.actions == ["pickup(peg,grasp_2)", "putdown(peg,pos_1)", "pickup(peg,grasp_1)", ASSEMBLE]
    assert o.order == ["prior_to(action_2,action_1)", "prior_to(action_3,action_2)",
                       "prior_to(action_4,action_3)"]
    assert o.labels["grasp_2"] == ["p1G17", "p1G7"]  # only shaft-covering grasps reach the peg
    cell = load_problem(ROOT / "kb" / "problems" / "regrasp.yaml")
    peg = cell.objects["peg"]
    assert all("peg_face" in peg.grasps[g].ofaces for g in o.labels["grasp_2"])
    assert not any("peg_face" in peg.grasps[g].ofaces for g in o.labels["grasp_1"])


def test_two_pegs_has_two_assembles() -> None:
    o = phase1("two_pegs")
    assert o.kind == "plan"
    assert sorted(o.actions) == sorted([ASSEMBLE, ASSEMBLE2, "pickup(peg,grasp_1)", "pickup(peg2,grasp_3)",
                                        "pickup(block,grasp_2)", "putdown(block,pos_1)"])


def test_separation_stock_of_two_pegs() -> None:
    """One object with two initial positions: the pickup for the assembly is kept off the
    spare at init_pos1 by a separation and takes the peg at init_pos5."""
    o = phase1("separation")
    assert o.kind == "plan"
    assert sorted(o.actions) == sorted([ASSEMBLE, "pickup(peg,grasp_1)"])


# ---------------------------------------------------------------------- placements


def test_placement_trap_has_no_placement() -> None:
    """Phase 1 accepts the trap's plan; no put-down spot on the shelf is reachable."""
    cell = load_problem(ROOT / "kb" / "problems" / "placement_trap.yaml")
    block, peg = cell.objects["block"], cell.objects["peg"]
    occupied = [(cell.positions["tr1"].T[:2, 3], peg.bounding_radius())]
    for pose in ("p2P1", "p2P2", "p2P4", "p2P5", "p2P6"):
        for g in ("p2G1", "p2G3", "p2G7", "p2G9"):
            assert placement.choose(CellCache(cell), "block", pose, [block.grasps[g].T], occupied) is None


def test_regrasp_has_a_placement() -> None:
    """The regrasp's put-down region has a spot where the arm reaches the peg lying on its
    side (p1P2) with the shaft-covering grasp and again with a grasp leaving the shaft free.
    Standing (p1P1) it has none: the side grasp p1G1 is then 0.5 in above the table and puts
    the gripper and wrist through it (collision-aware reach, issue 15)."""
    cell = load_problem(ROOT / "kb" / "problems" / "regrasp.yaml")
    peg = cell.objects["peg"]
    occupied = [(cell.positions["tr2"].T[:2, 3], cell.objects["block"].bounding_radius())]
    p = placement.choose(CellCache(cell), "peg", "p1P2", [peg.grasps["p1G17"].T, peg.grasps["p1G1"].T], occupied)
    assert p is not None
    assert 20 <= p.x <= 40 and -20 <= p.y <= 0
    assert np.isclose(p.z, cell.objects["peg"].poses["p1P2"].height)
    assert placement.choose(CellCache(cell), "peg", "p1P1", [peg.grasps["p1G7"].T, peg.grasps["p1G1"].T],
                            occupied) is None
