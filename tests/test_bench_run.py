"""The benchmarks' subprocess runs (issue 7): the cold start, one generated N and the whole
quick run. A file of their own so that pytest-xdist (--dist loadfile) runs them beside
test_bench.py's in-process figures instead of after them."""
from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest
from bench import planning

from paths import ROOT


@pytest.mark.slow
def test_cold_and_one_generated_n() -> None:
    c = planning.cold(repeats=1)
    assert c["returncodes"] == [0] and c["plan_s"] > 0 and c["start_s"] > 0
    (row,) = planning.scaling([1], timeout=60)
    assert row["outcome"] == "plan" and row["actions"] == 4 and row["rss_peak_mb"] >= row["rss_before_mb"] > 0


@pytest.mark.slow
def test_quick_run_end_to_end(tmp_path: Path) -> None:
    out = tmp_path / "RESULTS.md"
    r = subprocess.run([sys.executable, "-m", "bench", "--quick", "--out", str(out)], cwd=ROOT,
                       capture_output=True, text=True, timeout=600, check=False)
    assert r.returncode == 0, r.stderr[-2000:]
    text = out.read_text()
    assert "a QUICK run" in text and "## Reading" in text
