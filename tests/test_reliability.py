"""Bad input to `spar plan`: one clear line, a stable exit code, no traceback, no partial output file."""
from __future__ import annotations

import json
import subprocess
from pathlib import Path

import pytest

from paths import ROOT, SPAR

BAD = sorted((ROOT / "tests" / "bad").glob("*.yaml"))


def spar(*args: str, timeout: float = 300) -> subprocess.CompletedProcess[str]:
    return subprocess.run(SPAR + list(args), capture_output=True, text=True, timeout=timeout, cwd=ROOT)


@pytest.mark.parametrize("path", BAD, ids=[p.stem for p in BAD])
def test_bad_file_to_plan(path: Path, tmp_path: Path) -> None:
    out = tmp_path / "plan.json"
    r = spar("plan", str(path), "--json", "-o", str(out))
    assert r.returncode == 2, r.stderr
    assert r.stderr.count("\n") == 1 and r.stderr.startswith("spar: ") and str(path) in r.stderr
    assert "Traceback" not in r.stderr + r.stdout
    assert not out.exists() and list(tmp_path.iterdir()) == []


def test_unreachable_goal_is_a_no_plan_outcome_with_its_reason(tmp_path: Path) -> None:
    out = tmp_path / "plan.json"
    r = spar("plan", "kb/problems/unreachable.yaml", "--json", "-o", str(out))
    assert r.returncode == 1
    doc = json.loads(out.read_text())
    assert doc["outcome"] == "no_plan" and "reachable" in doc["reason"]["goal"]
    r = spar("plan", "kb/problems/unreachable.yaml")
    assert r.returncode == 1 and "NO PLAN within" in r.stdout


def test_timeout_is_a_clean_exit(tmp_path: Path) -> None:
    from spar_py.app.gen import generate_assembly

    big = generate_assembly(10, tmp_path / "gen")  # 40 actions
    out = tmp_path / "plan.json"
    whole = spar("plan", str(big), "--max-actions", "42", "--json")  # how long it takes on this machine
    limit = json.loads(whole.stdout)["timing"]["total_s"] / 4  # (a fixed 0.3 s could outlast a faster plan)
    r = spar("plan", str(big), "--max-actions", "42", "--timeout", f"{limit:.3f}", "--json", "-o", str(out))
    assert r.returncode == 4
    assert r.stderr.count("\n") == 1 and "timeout" in r.stderr and "Traceback" not in r.stderr
    assert not out.exists()


@pytest.mark.parametrize("args, what", [
    (["plan", "kb/problems/peg_in_block.yaml", "--max-actions", "0"], "positive integer"),
    (["plan", "kb/problems/peg_in_block.yaml", "--timeout", "nan"], "positive number of seconds"),
    (["plan", "kb/problems/peg_in_block.yaml", "--approach-length", "-1"], "positive number of the cell's length unit"),
    (["plan", "no/such/file.yaml"], "a readable file"),
])
def test_bad_arguments(args: list[str], what: str) -> None:
    r = spar(*args)
    assert r.returncode == 2 and what in r.stderr and "Traceback" not in r.stderr
