"""spar regress: green on expected outcomes; a changed expectation fails with a readable diff."""
from __future__ import annotations

import json
from pathlib import Path

import pytest

from spar_py.regress import run_regression

ROOT = Path(__file__).resolve().parent.parent
KB = ROOT / "kb"


def _copy_problem(name: str, dest: Path) -> None:
    text = (KB / "problems" / f"{name}.yaml").read_text()
    text = text.replace("../robots/", f"{KB}/robots/").replace("../objects/", f"{KB}/objects/")
    (dest / f"{name}.yaml").write_text(text)
    (dest / "expected").mkdir(exist_ok=True)
    exp = KB / "problems" / "expected" / f"{name}.json"
    (dest / "expected" / exp.name).write_text(exp.read_text())


def test_regression_passes_then_fails_on_a_changed_expectation(tmp_path: Path,
                                                               capsys: pytest.CaptureFixture[str]) -> None:
    for name in ("hole_up", "placement_trap"):
        _copy_problem(name, tmp_path)
    assert run_regression(tmp_path) == 0
    out = capsys.readouterr().out
    assert "2 of 2 passed" in out and "PASS" in out

    exp = tmp_path / "expected" / "hole_up.json"
    doc = json.loads(exp.read_text())
    doc["actions"] = doc["actions"][:1]  # pretend we expected one action only
    exp.write_text(json.dumps(doc))
    assert run_regression(tmp_path) == 1
    out = capsys.readouterr().out
    assert "FAIL" in out and "1 of 2 passed" in out
    assert "--- expected" in out and "+++ got" in out
    assert '+  "assemble(peg,block,[[peg_face],[block_face]],trans_1,vec_1)",' in out


def test_every_problem_has_an_expected_outcome() -> None:
    problems = {p.stem for p in (KB / "problems").glob("*.yaml")}
    expected = {p.stem for p in (KB / "problems" / "expected").glob("*.json")}
    assert problems == expected
