"""Knowledge-base loading: the paper's cell loads; every malformed file gives its own one-line error."""
from __future__ import annotations

import ast
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from spar_py.app.cli import main
from spar_py.core.errors import KBError, SparValueError
from spar_py.kb import facts, load_object, load_problem, load_robot, parse_term, term_text

from paths import ROOT

BAD = sorted((ROOT / "tests" / "bad").glob("*.yaml"))
PAPER = ROOT / "kb" / "problems" / "peg_in_block.yaml"
PUMA = ROOT / "kb" / "robots" / "puma762.yaml"


def expected_message(path: Path) -> str:
    """The substring a bad file's error must contain (its first line: ``# expect: ...``)."""
    first = path.read_text().splitlines()[0]
    assert first.startswith("# expect: "), f"{path.name} lacks its expectation line"
    return first[len("# expect: "):]


def run_cli(args: list[str], capsys: pytest.CaptureFixture[str]) -> tuple[int, str, str]:
    with pytest.raises(SystemExit) as exc:
        main(args)
    out, err = capsys.readouterr()
    return int(exc.value.code), out, err


def test_corpus_is_large_enough() -> None:
    assert len(BAD) >= 12


@pytest.mark.parametrize("path", BAD, ids=[p.stem for p in BAD])
def test_bad_file_one_line_error(path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    code, out, err = run_cli(["kb", "check", str(path)], capsys)
    assert code == 2
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert str(path) in lines[0]
    assert expected_message(path) in lines[0]
    assert "Traceback" not in err and out == ""


def test_bad_messages_are_distinct() -> None:
    messages = [expected_message(p) for p in BAD]
    assert len(set(messages)) == len(messages)


def test_every_kb_file_checks(capsys: pytest.CaptureFixture[str]) -> None:
    code, out, err = run_cli(["kb", "check", str(ROOT / "kb")], capsys)
    assert code == 0, err
    assert out.count(": ok (") == len(list((ROOT / "kb").rglob("*.yaml")))


def test_cli_process_exit_code_and_no_traceback() -> None:
    bad = ROOT / "tests" / "bad" / "bounds_lo_gt_hi.yaml"
    r = subprocess.run([sys.executable, "-m", "spar_py", "kb", "check", str(bad)],
                       capture_output=True, text=True, timeout=120)
    assert r.returncode == 2
    assert r.stderr.count("\n") == 1 and "Traceback" not in r.stderr


def test_paper_cell_contents() -> None:
    cell = load_problem(PAPER)
    assert cell.unit == "in"
    peg, block = cell.objects["peg"], cell.objects["block"]
    assert list(peg.grasps) == [f"p1G{i}" for i in range(1, 21)]
    assert list(block.poses) == [f"p2P{i}" for i in range(1, 7)]
    assert list(block.grasps) == [f"p2G{i}" for i in range(1, 17)]
    # p2P3 is the only stable pose that hides the hole
    hiding = [p.label for p in block.poses.values() if "block_face" in p.ofaces]
    assert hiding == ["p2P3"]
    # Table 2 in radians, W_m = 4 in, the robot converted from mm to inches
    assert cell.object_bounds["peg"].dtheta == pytest.approx((-math.radians(5.5), math.radians(5.5)))
    assert cell.finger_separation == pytest.approx(4.0)
    assert peg.grasps["p1G1"].width == 3


def test_facts_shapes() -> None:
    cell = load_problem(PAPER)
    fs = facts(cell)
    poses = [f for f in fs if f[0] == "pose"]
    grasps = [f for f in fs if f[0] == "grasp"]
    assert len(poses) == 11 and len(grasps) == 36
    assert ("position_class", "tr2", "p2P3") in fs
    assert ("position_class", "tr1", "p1P5") in fs
    assert ("initial", ("part_location", "block", "init_pos2")) in fs
    g = next(f for f in grasps if f[2] == "p1G3")
    assert g[5][0] == "eulerxyz" and g[6] == ("width", 3.0)


def test_parse_term_roundtrip() -> None:
    t = parse_term("assembled(peg, block, [[peg_face], [block_face]], trans_1, vec_1)")
    assert t == ("assembled", "peg", "block", [["peg_face"], ["block_face"]], "trans_1", "vec_1")
    assert parse_term("f(-1.5e2, [], g(x))") == ("f", -150.0, [], ("g", "x"))
    for bad in ["f(", "f(X)", "f(a,,b)", "f(a) g"]:
        with pytest.raises(ValueError):
            parse_term(bad)


def test_tm_rows_are_images_of_axes() -> None:
    cell = load_problem(PAPER)
    T = cell.positions["tr2"].T
    # block hole-down, turned 30 deg: its z axis points down, its x axis at 30 deg
    assert np.allclose(T[:3, 2], [0, 0, -1])
    assert np.allclose(T[:3, 0], [math.cos(math.radians(30)), 0.5, 0])
    assert np.allclose(T[:3, 3], [30, 8, 1.5])


# ---------------------------------------------------------------- robots (kb/robots/*.yaml)


def test_load_puma762_in_mm_and_inches() -> None:
    puma = load_robot(PUMA)  # millimetres
    assert puma.name == "puma762" and puma.unit == "mm"
    assert puma.dh[2, 1] == 650 and puma.dh[2, 2] == 190 and puma.dh[3, 2] == 600
    assert np.allclose(np.degrees(puma.dh[:, 0]), [0, -90, 0, -90, 90, -90])
    assert np.allclose(np.degrees(puma.limits[3]), [-266, 266])
    assert puma.finger_separation == pytest.approx(101.6)
    r_in = load_robot(PUMA, unit="in")
    assert r_in.unit == "in"
    assert r_in.dh[2, 1] == pytest.approx(650 / 25.4)
    assert r_in.finger_separation == pytest.approx(4.0)
    assert r_in.base[2, 3] == pytest.approx(600 / 25.4) and r_in.tool[2, 3] == pytest.approx(250 / 25.4)
    assert np.allclose(r_in.limits, puma.limits)
    assert puma.n_candidates == 8 and puma.solver_name == "closed-form puma"  # ik_batch: one row per branch
    with pytest.raises(SparValueError, match="unknown length unit"):
        load_robot(PUMA, unit="furlong")


@pytest.mark.parametrize("old, new, key, expected", [
    ("- {alpha: 0,   a: 650, d: 190", "- {alpha: x,   a: 650, d: 190", "dh[2].alpha", "a number"),
    ("  - [-200, 20]\n", "  - [20, -200]\n", "limits[1]", "lo <= hi"),
    ("  - {alpha: -90, a: 0,   d: 0,   offset: 0}   # 6 wrist swivel\n", "", "dh", "6 joint rows"),
    ("finger_separation: 101.6", "finger_separation: -1", "gripper.finger_separation", "a positive number"),
    ("units: {length: mm, angle: deg}", "units: {length: mm, angle: grad}", "units.angle", "one of"),
    ("base: {xyz: [0, 0, 600], rpy: [0, 0, 0]}", "base: {rpy: [0, 0, 0]}", "base.xyz", "key missing"),
])
def test_bad_robot_file_one_line_error(tmp_path: Path, old: str, new: str, key: str, expected: str) -> None:
    text = PUMA.read_text()
    assert old in text
    bad = tmp_path / "bad_robot.yaml"
    bad.write_text(text.replace(old, new))
    with pytest.raises(KBError) as exc:
        load_robot(bad)
    msg = str(exc.value)
    assert msg.count("\n") == 0 and str(bad) in msg and f": {key}: " in msg and expected in msg


@pytest.mark.parametrize("module", [
    "spar_py.world.robot.model", "spar_py.world.robot.ik.puma", "spar_py.world.robot.ik.ur",
                                    "spar_py.world.robot.ik.numeric", "spar_py.core.model", "spar_py.core.geometry",
                                    "spar_py.core.units"])
def test_the_model_does_not_import_the_kb(module: str) -> None:
    # kb -> model -> kinematics -> kb was an import circle: the robot loader lives in kb now
    code = f"import sys, {module}; print(sorted(m for m in ('spar_py.kb', 'yaml') if m in sys.modules))"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]", out.stdout + out.stderr
    # nor lazily, inside a function (as Robot.from_yaml did): no import of kb or yaml anywhere in the file
    path = ROOT / "src" / Path(*module.split(".")).with_suffix(".py")
    imported = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom):
            imported.add("." * node.level + (node.module or ""))
        elif isinstance(node, ast.Import):
            imported.update(a.name for a in node.names)
    assert not imported & {".kb", "spar_py.kb", "yaml"}, imported


def test_rotation_check_says_what_was_expected(tmp_path: Path) -> None:
    text = (ROOT / "kb" / "objects" / "peg.yaml").read_text()
    old = "tm: [[1, 0, 0], [0, 1, 0], [0, 0, 1], [0, 0, 0]]"
    assert old in text
    bad = tmp_path / "peg.yaml"
    bad.write_text(text.replace(old, "tm: [[1, 0, 0], [0, 1, 0], [0, 0, 1.001], [0, 0, 0]]", 1))
    with pytest.raises(KBError, match=r"orthonormal to 1e-06, det \+1; R\^T R is off I by 0\.002"):
        load_object(bad, "in")


#: The kb package's modules, each importing only modules before it in this list (kb/__init__.py).
KB_ORDER = ["node", "reader", "schema", "values", "terms", "objects", "robots", "products", "sanity", "problem",
            "prolog_facts", "check"]


def test_the_kb_modules_import_one_way() -> None:
    """Every module of src/spar_py/kb/ (imports at any depth, inside functions too) imports only
    modules before it in KB_ORDER, never the package itself; only __init__ imports them all."""
    pkg = ROOT / "src" / "spar_py" / "kb"
    assert sorted(p.stem for p in pkg.glob("*.py") if p.stem != "__init__") == sorted(KB_ORDER)
    for i, name in enumerate(KB_ORDER):
        used = set()
        for node in ast.walk(ast.parse((pkg / f"{name}.py").read_text())):
            if isinstance(node, ast.ImportFrom) and node.module and node.module.startswith("spar_py.kb"):
                assert node.module != "spar_py.kb", f"kb/{name}.py imports the kb package itself"
                used.add(node.module.removeprefix("spar_py.kb."))
            elif isinstance(node, ast.Import):
                assert not any(a.name.startswith("spar_py.kb") for a in node.names), name
        assert used <= set(KB_ORDER[:i]), f"kb/{name}.py imports {sorted(used - set(KB_ORDER[:i]))} from above it"


def test_goals_and_initial_facts_are_term_data_from_the_yaml_to_the_facts() -> None:
    """The goals are parsed once, at load, and kept as terms (no text round trip); the initial
    state is built as terms; facts() sends both as they are."""
    cell = load_problem(PAPER)
    goal = ("assembled", "peg", "block", [["peg_face"], ["block_face"]], "trans_1", "vec_1")
    assert cell.goals == [goal]
    assert cell.initial == [("gripper", "open"), ("part_location", "peg", "init_pos1"),
                            ("part_location", "block", "init_pos2")]
    sent = [f for f in facts(cell) if f[0] in ("initial", "goal")]
    assert sent == [("initial", t) for t in cell.initial] + [("goal", goal)]
    assert term_text(goal) == "assembled(peg, block, [[peg_face], [block_face]], trans_1, vec_1)"
    assert parse_term(term_text(goal)) == goal
