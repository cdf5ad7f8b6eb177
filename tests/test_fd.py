"""bench/fd.py: the PDDL encoding of a generated problem, and (where the bench extra is
installed) Fast Downward solving it with as many actions as our phase 1."""
from __future__ import annotations

import re
from pathlib import Path

import pytest

from bench import fd
from spar_py.app import gen
from spar_py.kb import load_problem
from spar_py.world.collision import CellCache
from spar_py.world.reach.arcs import reachable_pairs


def test_encoding_names_every_part_goal_and_arc(tmp_path: Path) -> None:
    cell = load_problem(gen.generate_assembly(2, tmp_path))
    text = fd.pddl(cell)
    assert "(gripper-open)" in text
    assert re.search(r"\(:goal \(and \(assembled peg1 block1\) \(assembled peg2 block2\)\)\)", text)
    for p in cell.positions.values():
        assert f"(at {p.obj} {p.label})" in text
    # the reach facts are exactly phase 1's reachable pairs for the block where it lies
    pairs = reachable_pairs(CellCache(cell), "block1", list(cell.objects["block1"].grasps), ["tr2"]).pairs
    facts = set(re.findall(r"\(reach (p2-g\d+) tr2\)", text))
    assert facts == {fd._name(g) for g, _ in pairs} and facts
    # labels that differ only in case stay apart (PDDL names are case-insensitive)
    assert fd._name("p2G1") != fd._name("p2g1")


def test_bad_goal_is_refused(tmp_path: Path) -> None:
    cell = load_problem(gen.generate_assembly(1, tmp_path))
    cell.goals.append(("gripper", "closed"))
    with pytest.raises(ValueError, match="only assembled/5"):
        fd.pddl(cell)


@pytest.mark.skipif(fd.fd_driver() is None, reason="Fast Downward (bench extra) not installed")
def test_fast_downward_finds_four_actions_per_pair(tmp_path: Path) -> None:
    cell = load_problem(gen.generate_assembly(2, tmp_path / "kb"))
    (tmp_path / "d.pddl").write_text(fd.DOMAIN)
    (tmp_path / "p.pddl").write_text(fd.pddl(cell))
    r = fd.run_fd(tmp_path / "d.pddl", tmp_path / "p.pddl", tmp_path, timeout=120)
    assert r.get("plan_length") == 8, r
    steps = (tmp_path / "sas_plan").read_text().splitlines()
    assert sum(s.startswith("(assemble ") for s in steps) == 2


def test_hole_up_block_is_mated_where_it_stands(tmp_path: Path) -> None:
    """A block that starts hole-up gets mate facts at its initial position (phase 1 mates it there);
    one that starts hole-down gets none there (its hole is on the table)."""
    up = fd.pddl(load_problem(gen.generate_assembly(2, tmp_path / "up", "hole-up")))
    assert re.search(r"\(mate peg1 block1 p1-g\d+ tr2\)", up)
    down = fd.pddl(load_problem(gen.generate_assembly(2, tmp_path / "down", "hole-down")))
    assert not re.search(r"\(mate peg1 block1 \S+ tr2\)", down)
    assert re.search(r"\(mate peg1 block1 p1-g\d+ p2-p1\)", down)


@pytest.mark.skipif(fd.fd_driver() is None, reason="Fast Downward (bench extra) not installed")
def test_fast_downward_finds_two_actions_per_hole_up_pair(tmp_path: Path) -> None:
    cell = load_problem(gen.generate_assembly(3, tmp_path / "kb", "hole-up"))
    (tmp_path / "d.pddl").write_text(fd.DOMAIN)
    (tmp_path / "p.pddl").write_text(fd.pddl(cell))
    r = fd.run_fd(tmp_path / "d.pddl", tmp_path / "p.pddl", tmp_path, timeout=120)
    assert r.get("plan_length") == 6, r
