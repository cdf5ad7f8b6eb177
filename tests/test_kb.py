"""Knowledge-base loading: the paper's cell loads; every malformed file gives its own one-line error."""
from __future__ import annotations

import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from spar_py.cli import main
from spar_py.errors import KBError
from spar_py.kb import facts, load_object, load_problem, parse_term

ROOT = Path(__file__).resolve().parent.parent
BAD = sorted((ROOT / "tests" / "bad").glob("*.yaml"))
PAPER = ROOT / "kb" / "problems" / "peg_in_block.yaml"


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
    r = subprocess.run([sys.executable, "-m", "spar_py.cli", "kb", "check", str(bad)],
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


def test_rotation_check_says_what_was_expected(tmp_path: Path) -> None:
    text = (ROOT / "kb" / "objects" / "peg.yaml").read_text()
    old = "tm: [[1, 0, 0], [0, 1, 0], [0, 0, 1], [0, 0, 0]]"
    assert old in text
    bad = tmp_path / "peg.yaml"
    bad.write_text(text.replace(old, "tm: [[1, 0, 0], [0, 1, 0], [0, 0, 1.001], [0, 0, 0]]", 1))
    with pytest.raises(KBError, match=r"orthonormal to 1e-06, det \+1; R\^T R is off I by 0\.002"):
        load_object(bad, "in")
