"""Issue 13, items 1, 7, 8, 10: strict schemas, bounded reading, one flat line per bad input.

Every loading finding of issue 13 is a case here, run through the real command line
(``python -m spar_py``): exit 2, exactly one line on stderr, no traceback. The
cases are the files of tests/bad/ (``kb check``) and the ones a file cannot hold
(not UTF-8, UTF-16, a FIFO, a symlink to /dev/zero, the wrong kind given to ``plan``).
"""
from __future__ import annotations

import concurrent.futures as cf
import os
import re
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import pytest
import yaml

from spar_py.core.errors import KBError
from spar_py.kb import KINDS, MAX_INPUT_BYTES, check_file, load_problem, read_yaml
from spar_py.kb.node import show
from spar_py.kb.problem import SENSOR_NAMES
from spar_py.kb.reader import MAX_NODES, BoundedLoader
from spar_py.kb.schema import schema_keys

from paths import ROOT

BAD = ROOT / "tests" / "bad"
PAPER = ROOT / "kb" / "problems" / "peg_in_block.yaml"
PEG = ROOT / "kb" / "objects" / "peg.yaml"
PUMA = ROOT / "kb" / "robots" / "puma762.yaml"


@dataclass(frozen=True)
class Case:
    """One bad input: the command's arguments and a substring of its one stderr line."""

    name: str
    args: tuple[str, ...]
    expect: str
    file: str


@dataclass(frozen=True)
class Result:
    """What the command did: exit code, stdout, stderr, seconds."""

    code: int
    out: str
    err: str
    secs: float


def _expect(path: Path) -> str:
    return path.read_text().splitlines()[0].removeprefix("# expect: ")


def _generated(tmp: Path) -> list[Case]:
    """The cases a committed file cannot hold, made in ``tmp``."""
    paper = PAPER.read_text().replace("../", f"{ROOT}/kb/")
    (tmp / "not_utf8.yaml").write_bytes(b"problem: \xff\n")
    (tmp / "utf16.yaml").write_bytes(paper.encode("utf-16"))
    (tmp / "zero.yaml").symlink_to("/dev/zero")
    os.mkfifo(tmp / "fifo.yaml")
    (tmp / "a_directory.yaml").mkdir()
    (tmp / "big.yaml").write_text(paper + "# " + "x" * MAX_INPUT_BYTES + "\n")
    (tmp / "nul.yaml").write_text(paper.replace("gripper: open", "gripper: op\0en"))
    cases = [
        ("not_utf8", "kb", "expected a UTF-8 text file, not one with byte 0xff at offset 9"),
        ("utf16", "kb", "expected a UTF-8 text file, not UTF-16"),
        ("zero", "plan", "expected a regular file, not a character device"),
        ("fifo", "plan", "expected a regular file, not a FIFO"),
        ("a_directory", "plan", "expected a regular file, not a directory"),
        ("big", "kb", f"expected a file of at most {MAX_INPUT_BYTES} bytes (--max-input-bytes raises the limit)"),
        ("nul", "kb", "expected a UTF-8 text file of printable characters, not one with character #x0000"),
    ]
    out = [Case(f"gen_{n}", (("kb", "check") if cmd == "kb" else ("plan",)) + (str(tmp / f"{n}.yaml"),), e,
                str(tmp / f"{n}.yaml")) for n, cmd, e in cases]
    rel = lambda p: str(p.relative_to(ROOT))  # noqa: E731
    out += [
        Case("plan_object_file", ("plan", rel(PEG)), f"{rel(PEG)}: expected a problem file, not an object model "
             "(it has `object:`)", rel(PEG)),
        Case("plan_robot_file", ("plan", rel(PUMA)), "expected a problem file, not a robot model (it has `dh:`)",
             rel(PUMA)),
    ]
    return out


def _run(args: tuple[str, ...]) -> Result:
    t0 = time.perf_counter()
    r = subprocess.run([sys.executable, "-m", "spar_py", *args], capture_output=True, text=True,
                       timeout=60, cwd=ROOT)
    return Result(r.returncode, r.stdout, r.stderr, time.perf_counter() - t0)


FILE_CASES = [Case(p.stem, ("kb", "check", str(p)), _expect(p), str(p)) for p in sorted(BAD.glob("*.yaml"))]
GEN_NAMES = ["gen_not_utf8", "gen_utf16", "gen_zero", "gen_fifo", "gen_a_directory", "gen_big", "gen_nul",
             "plan_object_file", "plan_robot_file"]


@pytest.fixture(scope="module")
def results(tmp_path_factory: pytest.TempPathFactory) -> dict[str, tuple[Case, Result]]:
    """Every case run once through the CLI, in parallel (each is its own process)."""
    cases = FILE_CASES + _generated(tmp_path_factory.mktemp("gen"))
    assert sorted(c.name for c in cases[len(FILE_CASES):]) == sorted(GEN_NAMES)
    with cf.ThreadPoolExecutor(max_workers=8) as pool:
        runs = list(pool.map(lambda c: _run(c.args), cases))
    return {c.name: (c, r) for c, r in zip(cases, runs)}


@pytest.mark.parametrize("name", [c.name for c in FILE_CASES] + GEN_NAMES)
def test_bad_input_is_one_line_exit_2(name: str, results: dict[str, tuple[Case, Result]]) -> None:
    case, r = results[name]
    assert r.code == 2, r.err
    lines = r.err.splitlines()
    assert len(lines) == 1 and r.err.endswith("\n"), r.err
    assert "Traceback" not in r.err and r.out == ""
    assert lines[0].startswith(f"spar: {case.file}: ") or case.name == "model_is_a_robot", lines[0]
    assert case.expect in lines[0]


def test_the_findings_of_issue_13_are_all_cases() -> None:
    names = {c.name for c in FILE_CASES} | set(GEN_NAMES)
    assert {"huge_integer", "number_1e308", "nan_position", "units_list", "label_trailing_newline",
            "alias_bomb", "duplicate_goals", "typo_placement_region", "typo_dense_range_scn",
            "goal_unknown_transform", "goal_unknown_vector", "unknown_sensor", "robot_etc_passwd",
            "gen_not_utf8", "gen_utf16", "gen_zero", "gen_fifo", "plan_object_file"} <= names


def test_fast_refusals(results: dict[str, tuple[Case, Result]]) -> None:
    # /dev/zero, a FIFO, the bomb: refused at once (a process start is most of it)
    for name in ("gen_zero", "gen_fifo", "alias_bomb"):
        assert results[name][1].secs < 10, name


def test_etc_passwd_is_never_quoted(results: dict[str, tuple[Case, Result]]) -> None:
    err = results["robot_etc_passwd"][1].err
    assert "root:" not in err and "/bin/" not in err


def test_alias_bomb_fails_fast_in_process() -> None:
    t0 = time.perf_counter()
    with pytest.raises(KBError, match=f"at most {MAX_NODES} YAML nodes"):
        read_yaml(BAD / "alias_bomb.yaml")
    assert time.perf_counter() - t0 < 2.0


def test_a_shared_anchor_within_bounds_still_loads() -> None:
    doc = "a: &v [1, 2, 3]\nb: *v\nbase: &b {x: 1}\nc:\n  <<: *b\n  x: 2\n"
    assert yaml.load(doc, Loader=BoundedLoader) == {"a": [1, 2, 3], "b": [1, 2, 3], "base": {"x": 1}, "c": {"x": 2}}


@pytest.mark.parametrize("doc, expected", [
    ("a: 1\nb: 2\na: 3\n", "line 3, column 1: expected the key 'a' once"),
    ("x: {k: 1, k: 2}\n", "line 1, column 11: expected the key 'k' once"),
    ("a: &a [*a]\n", "expected an alias that does not contain itself"),
    ("b: &x 1\na: " + "[" * 70 + "]" * 70 + "\n", "expected at most 64 levels of nesting"),
    ("a: " + "9" * 5000 + "\n", "expected an integer of at most 4300 digits"),
])
def test_loader_refusals(tmp_path: Path, doc: str, expected: str) -> None:
    f = tmp_path / "f.yaml"
    f.write_text(doc)
    with pytest.raises(KBError, match=re.escape(expected)):
        read_yaml(f)


def test_yaml12_floats_are_numbers() -> None:
    assert yaml.load("[1e-3, 1.0e308, -2E+4, x1e3]", Loader=BoundedLoader) == [0.001, 1e308, -20000.0, "x1e3"]


def test_max_input_bytes_raises_the_limit(tmp_path: Path) -> None:
    with pytest.raises(KBError, match="expected a file of at most 100 bytes"):
        load_problem(PAPER, max_bytes=100)
    assert load_problem(PAPER, max_bytes=10**6).name == "peg_in_block"
    small = _run(("kb", "check", "--max-input-bytes", "100", str(PEG)))
    assert small.code == 2 and "at most 100 bytes" in small.err
    assert _run(("kb", "check", "--max-input-bytes", "100000", str(PEG))).code == 0


def test_help_states_the_default_limit() -> None:
    from spar_py.app.cli import build_parser

    sub = build_parser()._subparsers._group_actions[0].choices  # type: ignore[union-attr]
    assert f"(default {MAX_INPUT_BYTES})" in sub["plan"].format_help().replace("\n", " ").replace("  ", " ")


@pytest.mark.parametrize("value, text", [
    (0.16000000000000003, "0.16"), (1e308, "1e+308"), (float("nan"), "nan"),
    (10**400, "an integer of about 401 digits"),
    ("x" * 100, "'" + "x" * 36 + "..."), ("init_pos1\n", "'init_pos1\\n'"), (["mm"], "['mm']"),
    ({"a": 1}, "a mapping of 1 keys"), (list(range(100)), "a list of 100 items"), (True, "true"), (None, "nothing"),
])
def test_show_rounds_cuts_and_never_dumps(value: object, text: str) -> None:
    assert show(value) == text and len(show(value)) <= 40


def test_every_schema_key_is_documented() -> None:
    doc = (ROOT / "docs" / "kb-format.md").read_text()
    for kind in KINDS.values():
        keys = schema_keys(kind.schema)
        assert kind.marker in keys
        missing = sorted(k for k in keys if not re.search(rf"`{re.escape(k)}(`|:|\[)", doc))
        assert not missing, f"{kind.name} keys not in docs/kb-format.md: {missing}"
    for needed in ("shape", "placement_regions", "units", "--max-input-bytes"):
        assert f"`{needed}" in doc


def test_schema_keys_follow_the_schema() -> None:
    assert {"placement_regions", "x", "y", "dense_range_scan"} - schema_keys(KINDS["problem"].schema) == \
        {"dense_range_scan"}  # sensor names are names, not keys
    assert {"box", "cylinder", "min", "max", "radius", "z"} <= schema_keys(KINDS["object"].schema)


def test_sensor_names_are_the_templates_sensing_actions() -> None:
    text = (ROOT / "kb" / "templates" / "spar_sensing.pl").read_text()
    assert set(SENSOR_NAMES) == set(re.findall(r"^sensing_rule\((\w+)\(", text, re.M))


def test_every_kb_file_still_checks() -> None:
    for p in sorted((ROOT / "kb").rglob("*.yaml")):
        assert ": ok (" in check_file(p)


def test_regress_skips_object_and_robot_files(tmp_path: Path) -> None:
    text = (ROOT / "kb" / "problems" / "hole_up.yaml").read_text().replace("../", f"{ROOT}/kb/")
    (tmp_path / "hole_up.yaml").write_text(text)
    (tmp_path / "expected").mkdir()
    (tmp_path / "expected" / "hole_up.json").write_text(
        (ROOT / "kb" / "problems" / "expected" / "hole_up.json").read_text())
    (tmp_path / "objects").mkdir()
    (tmp_path / "objects" / "peg.yaml").write_text(PEG.read_text())
    (tmp_path / "puma.yaml").write_text(PUMA.read_text())
    r = _run(("regress", str(tmp_path)))
    assert r.code == 0, r.out + r.err
    assert "skipped objects/peg.yaml: an object model" in r.out
    assert "skipped puma.yaml: a robot model" in r.out
    assert "1 of 1 passed" in r.out and "Traceback" not in r.err
