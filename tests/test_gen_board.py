"""`spar gen board N` (issue 33): the generated task board loads and plans, every pin ends seated in
its own bore (checked from the files' own YAML and the plan JSON's poses with numpy, not the
planner's code), kb/'s board20 is what the generator writes, and an N the cell cannot hold is
refused in one line; bench/products.py's PDDL carries a product's precedence."""
from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml

from spar_py.app import gen
from spar_py.app.gen import board as board_gen

from paths import ROOT


def _spar(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "spar_py", *args], cwd=ROOT, capture_output=True, text=True,
                          timeout=600, check=False)


def _T(rows: list[list[float]]) -> np.ndarray:
    T = np.asarray(rows, float)
    assert T.shape == (4, 4)
    return T


def _axis_ends(feature: dict) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(the feature's mouth, its far end, its unit direction) in its part's frame, from the YAML."""
    o = np.asarray(feature["axis"]["origin"], float)
    d = np.asarray(feature["axis"]["direction"], float)
    d = d / np.linalg.norm(d)
    return o, o + feature["length"] * d, d


@pytest.fixture(scope="module")
def board7(tmp_path_factory) -> tuple[Path, dict]:
    out = tmp_path_factory.mktemp("board7") / "kb"
    r = _spar("gen", "board", "7", "-o", str(out))
    assert r.returncode == 0, r.stderr
    problem = out / "problems" / "board7.yaml"
    assert Path(r.stdout.strip()) == problem
    plan_json = out.parent / "plan.json"
    r = _spar("plan", "--json", "-o", str(plan_json), str(problem))
    assert r.returncode == 0, r.stderr
    return out, json.loads(plan_json.read_text())


def test_board7_files_stand_alone(board7) -> None:
    out, _ = board7
    for rel in ("problems/board7.yaml", "products/board7.yaml", "objects/board7.yaml", "objects/meshes/board7.stl",
                "objects/bpin.yaml", "robots/puma762.yaml"):
        assert (out / rel).is_file(), rel
    product = yaml.safe_load((out / "products/board7.yaml").read_text())
    assert len(product["mates"]) == 7 and len(product["parts"]) == 8


def test_board7_plans_every_pin_into_its_own_bore(board7) -> None:
    out, plan = board7
    assert plan["outcome"] == "plan"
    steps = plan["instance"]["steps"]
    assert [s["name"] for s in steps].count("assemble") == 7 and len(steps) == 14
    final = steps[-1]["poses"]
    board = yaml.safe_load((out / "objects/board7.yaml").read_text())
    holes = {f["name"]: f for f in board["features"]}
    pin = yaml.safe_load((out / "objects/bpin.yaml").read_text())
    shaft = next(f for f in pin["features"] if f["name"] == "shaft")
    root, tip, d_pin = _axis_ends(shaft)
    product = yaml.safe_load((out / "products/board7.yaml").read_text())
    size = max(np.ptp(np.asarray([h["axis"]["origin"] for h in holes.values()], float), axis=0).max(), 1.0)
    Tb = _T(final["board"])
    seen = set()
    for mate in product["mates"]:
        p, h = mate["peg"].split(".")[0], mate["hole"].split(".")[1]
        mouth, bottom, d_hole = _axis_ends(holes[h])
        T = np.linalg.inv(Tb) @ _T(final[p])  # the pin in the board's frame, from the plan's own poses
        at = lambda x: (T @ np.append(x, 1.0))[:3]  # noqa: E731
        assert np.allclose(at(tip), bottom, atol=1e-6 * size), (p, h)      # tip at the bore's bottom
        assert np.allclose(at(root), mouth, atol=1e-6 * size), (p, h)      # shaft root at its mouth
        assert np.allclose(T[:3, :3] @ d_pin, d_hole, atol=1e-9), (p, h)    # coaxial, going in
        seen.add(h)
    assert len(seen) == 7  # seven pins, seven different bores


def test_kb_board20_is_what_the_generator_writes(tmp_path: Path) -> None:
    b = gen.board_layout(20)
    for rel, text in gen.board_files(b).items():
        assert (ROOT / "kb" / rel).read_text(encoding="utf-8") == text, rel
    gen.board_mesh(b).export(tmp_path / "board20.stl", file_type="stl")
    assert (tmp_path / "board20.stl").read_bytes() == (ROOT / "kb/objects/meshes/board20.stl").read_bytes()


def test_layout_rows_columns_and_spacing() -> None:
    b = gen.board_layout(10, rows=2)
    assert (b.rows, b.cols) == (2, 5) and len(b.holes) == len(b.pins) == 10
    xy = np.asarray(b.pins)
    gaps = np.linalg.norm(xy[:, None] - xy[None], axis=-1) + np.eye(10) * 1e9
    assert gaps.min() == pytest.approx(board_gen.PIN_PITCH)
    hole_xy = np.asarray(b.holes)
    assert np.all(np.abs(hole_xy) + (board_gen.HOLE_RADIUS, board_gen.HOLE_RADIUS) < np.asarray(b.size) / 2)


@pytest.mark.parametrize("args, words", [
    (["200"], "onto the board's edge"),          # the pins' grid grows into the board
    (["60", "--rows", "1"], "reach"),            # one row of 60: pins beyond the reach from above
    (["30", "--rows", "40"], "--rows must be"),
])
def test_an_n_the_cell_cannot_hold_is_one_line(args: list[str], words: str, tmp_path: Path) -> None:
    r = subprocess.run([sys.executable, "-m", "spar_py.app.gen", "board", *args, "-o", str(tmp_path / "x")],
                       cwd=ROOT, capture_output=True, text=True, timeout=120, check=False)
    assert r.returncode == 2
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and words in lines[0] and "Traceback" not in r.stderr
    assert not (tmp_path / "x").exists()


def test_bench_pddl_has_precedence_as_preconditions() -> None:
    from bench import products
    from spar_py.kb import load_problem

    assert ":adl" in products.DOMAIN and "(imply (needs ?o1 ?o2 ?a ?b) (assembled ?a ?b))" in products.DOMAIN
    cell = load_problem(ROOT / "kb/problems/bracket_kit.yaml")
    text = products.pddl(cell)
    # the bracket's insertion passes through the pins' places: each pin's assemble needs the bracket in
    assert "(needs pin_a base bracket base)" in text and "(needs pin_b base bracket base)" in text
