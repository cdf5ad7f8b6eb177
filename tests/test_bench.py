"""The benchmarks (issue 7) run at tiny sizes and return well-formed figures; RESULTS.md
renders from them. The subprocess parts (cold start, one generated N, the whole quick run)
are slow."""
from __future__ import annotations

import math
import subprocess
import sys

import pytest
from bench import __main__ as bench_main
from bench import ik, planning, supinf

from paths import ROOT


def _positive(x: object) -> bool:
    return isinstance(x, float) and math.isfinite(x) and x > 0


@pytest.fixture(scope="module")
def ik_figures() -> dict:
    return ik.run(n=200, single=20, rtb=4, repeats=1)


@pytest.fixture(scope="module")
def supinf_figures() -> dict:
    return supinf.run(per_length=1, lengths=(1,), groups=("random",), repeats=1)


@pytest.fixture(scope="module")
def warm_figures() -> dict:
    return planning.warm(repeats=1, profile_top=40)  # Prolog's own call is somewhere in the top 40


def test_ik_figures(ik_figures: dict) -> None:
    r = ik_figures
    assert _positive(r["batch_us"]) and _positive(r["single_us"])
    assert r["solutions_per_pose"] >= 1
    if r["rtb_us"] is not None:  # Robotics Toolbox installed (the bench extra)
        assert _positive(r["rtb_us"]) and _positive(r["rtb_all8_us"])
        assert r["rtb_over_batch"] == pytest.approx(r["rtb_us"] / r["batch_us"])
    for name in ("ur5e", "ur5"):  # issue 17: the UR closed form, all 8 branches
        u = r["ur"][name]
        assert _positive(u["batch_us"]) and _positive(u["single_us"]) and 1 <= u["branches_per_pose"] <= 8
    if r["ur"]["rtb_lm_us"] is not None:
        assert r["ur"]["rtb_lm_over_batch"] == pytest.approx(r["ur"]["rtb_lm_us"] / r["ur"]["ur5"]["batch_us"])
    assert r["numeric"]["solver"] == "numeric" and r["numeric"]["solved"] > 0.9


@pytest.mark.slow
def test_supinf_figures(supinf_figures: dict) -> None:
    r = supinf_figures
    names = [m["name"] for m in r["paper"]]
    assert "Sec. 6 with +2.0" in names and any(n.startswith("pickup(peg)") for n in names)
    assert r["unsound"] == 0
    for m in r["paper"]:
        assert m["sound"] and 0 <= m["ours"] <= m["plain"] + 1e-9
        assert _positive(m["t_ours"]) and _positive(m["t_plain"])
    (row,) = r["random"]
    assert row["length"] == 1 and row["count"] == 1 and "plan_like" not in r
    assert _positive(r["evaluate_ms"])


def test_warm_paper_cell(warm_figures: dict) -> None:
    r = warm_figures
    assert r["outcome"] == "plan" and r["actions"] == 4
    assert _positive(r["phase1_s"]) and _positive(r["phase2_s"]) and _positive(r["load_s"])
    assert r["min_wall_s"] <= r["wall_s"] <= r["max_wall_s"]
    assert "by internal time" in r["profile"] and "_swipl.call" in r["profile"]


def test_max_actions_leaves_room_for_four_per_pair() -> None:
    assert all(planning.max_actions_for(n) >= 4 * n for n in range(1, 11))
    assert planning.max_actions_for(3) > 12  # phase 1's default bound is too small


def _fake_planning(warm: dict) -> dict:
    """Planning figures without the subprocesses: a cold run and two scaling rows."""
    cold = {"repeats": 1, "plan_s": 1.0, "start_s": 0.5, "plan_minus_start_s": 0.5, "ratio": 2.0,
            "plan_runs": [1.0], "start_runs": [0.5], "returncodes": [0]}
    rows = [{"n": 1, "max_actions": 7, "outcome": "plan", "phase1_s": 0.1, "phase2_s": 0.1,
             "wall_s": 0.3, "actions": 4, "instances_examined": 1, "rss_before_mb": 80.0,
             "rss_peak_mb": 80.0, "maxrss_mb": 90.0, "prolog_stack_mb": 0.5, "reason": None, "budget_spent": False,
             "profile": "1 function calls in 0.1 seconds\nby internal time:"},
            {"n": 10, "max_actions": 52, "outcome": "timeout", "wall_s": 150.0}]
    return {"warm": warm, "cold": cold, "scaling": rows, "timeout_s": 120.0}


@pytest.mark.slow
def test_render_has_every_section(ik_figures: dict, supinf_figures: dict, warm_figures: dict) -> None:
    r = {"quick": True, "date": "2025-01-01T00:00:00+00:00", "machine": bench_main.machine(),
         "versions": bench_main.versions(), "seconds": {"ik": 1.0},
         "ik": ik_figures, "supinf": supinf_figures, "planning": _fake_planning(warm_figures)}
    text = bench_main.render(r)
    for heading in ("## Machine and versions", "## Targets (issue 7)", "## Reading", "## IK",
                    "## SUP/INF", "## Planning", "### Generated problems", "## Where the time goes"):
        assert heading in text
    assert r["versions"]["swipl"] in text and r["machine"]["cpu"] in text
    assert "| 10 | 52 | timeout |" in text
    v = bench_main.verdicts(r)
    assert v["n10"] == (False, "timeout after 150.00 s")
    assert "N = 10 timeout" in bench_main.reading(r)


def test_planning_cli_child_prints_json() -> None:
    """The scaling child's command line parses (no run: --help exits 0)."""
    r = subprocess.run([sys.executable, "-m", "bench.planning", "--help"], cwd=ROOT,
                       capture_output=True, text=True, timeout=60, check=False)
    assert r.returncode == 0 and "--max-n" in r.stdout
