"""One planning run, one state: threads sharing the engine get the plans they would alone.

The engine serialises planning runs (engine.Engine.session): each run loads its cell,
plans and unloads it while holding the engine, and every call from Prolog into Python
names its problem, so a thread never plans with another thread's cell.
"""
from __future__ import annotations

import threading
from pathlib import Path
from typing import Any

from spar_py.planning.planner import Outcome, Plan, Planner

from paths import ROOT

A = ROOT / "kb/problems/peg_in_block.yaml"
B = ROOT / "kb/problems/separation.yaml"
CALLS = 100


def _key(plan: Plan) -> dict[str, Any]:
    """Everything of a plan but its timings."""
    doc = plan.to_json()
    doc.pop("timing")
    return doc


def _hammer(planners: list[Planner], paths: list[Path], calls: int) -> dict[Path, list[Any]]:
    """Plan ``paths[i]`` ``calls`` times with ``planners[i]``, each in its own thread."""
    out: dict[Path, list[Any]] = {p: [] for p in paths}
    start = threading.Barrier(len(paths))

    def work(planner: Planner, path: Path) -> None:
        start.wait()
        for _ in range(calls):
            try:
                out[path].append(_key(planner.plan(path)))
            except Exception as e:  # recorded, so the assertion shows it
                out[path].append(repr(e))

    threads = [threading.Thread(target=work, args=(pl, p)) for pl, p in zip(planners, paths)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    return out


def test_two_threads_one_planner_get_the_sequential_plans() -> None:
    planner = Planner()
    want = {p: _key(planner.plan(p)) for p in (A, B)}
    assert want[A]["partial"]["actions"] != want[B]["partial"]["actions"]
    got = _hammer([planner, planner], [A, B], CALLS)
    for p in (A, B):
        assert len(got[p]) == CALLS
        bad = [g for g in got[p] if g != want[p]]
        assert not bad, f"{p.name}: {len(bad)} of {CALLS} differ, first: {str(bad[0])[:300]}"


def test_two_threads_two_planners_get_the_sequential_plans() -> None:
    want = {p: _key(Planner().plan(p)) for p in (A, B)}
    got = _hammer([Planner(), Planner()], [A, B], CALLS)
    for p in (A, B):
        bad = [g for g in got[p] if g != want[p]]
        assert not bad, f"{p.name}: {len(bad)} of {CALLS} differ, first: {str(bad[0])[:300]}"


def test_a_thread_that_times_out_does_not_disturb_the_other(tmp_path: Path) -> None:
    from spar_py.app.gen import generate_assembly

    big = generate_assembly(10, tmp_path)  # 40 actions
    # a quarter of the whole plan on this machine (a fixed 0.3 s could outlast a faster plan)
    limit = Planner(max_actions=42).plan(big).timing["total_s"] / 4
    want = _key(Planner().plan(A))
    slow: list[Plan] = []
    fast: list[Any] = []

    def slow_work() -> None:
        for _ in range(3):
            slow.append(Planner(max_actions=42, timeout=limit).plan(big))

    def fast_work() -> None:
        planner = Planner()
        for _ in range(30):
            fast.append(_key(planner.plan(A)))

    threads = [threading.Thread(target=slow_work), threading.Thread(target=fast_work)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert [p.outcome for p in slow] == [Outcome.TIMEOUT] * 3
    assert len(fast) == 30 and all(f == want for f in fast)
    # and the engine is fine afterwards
    assert _key(Planner().plan(A)) == want
