"""Motion planning time (issue 16): the paper's cell and the wall cell with motions, warm
(the cell loaded and planned once with --no-motion first, so phase 1 and the end-points
are memoised and only the motions are planned again), one run per OMPL seed; the median
over the seeds, the end-point-only plan as the peer measured in the same run; path length
(joint space, rad) before and after OMPL's simplification; the plan JSON's size.

Goal (issue 16): the paper's cell with motions at most 1 s warm, median over 10 seeds."""
from __future__ import annotations

import statistics
import time

CELLS = ("kb/problems/peg_in_block.yaml", "kb/problems/wall_detour.yaml")


def one_cell(path: str, seeds: int, budget: float) -> dict:
    from spar_py import Planner
    from spar_py.world.motion import MotionOptions

    peer = Planner(motion=False)
    peer.plan(path)
    t = time.perf_counter()
    peer.plan(path)
    endpoints_s = time.perf_counter() - t
    times, outcome, raw, simp, size, why, ompl = [], "", [], [], 0, "", []
    pl = Planner(motion=True)
    pl.plan(path, phase1_only=True)  # load the cell, phase 1 memoised
    for seed in range(seeds):
        pl.motion_options = MotionOptions(seed=seed, time_budget_s=budget)
        t = time.perf_counter()
        p = pl.plan(path)
        times.append(time.perf_counter() - t)
        outcome = p.outcome.value
        m = (p.instance or {}).get("motion") or {}
        if m:
            raw.append(m["length_before_simplification_rad"])
            simp.append(m["length_after_simplification_rad"])
            ompl.append(m["ompl_motions"])
            size = len(p.dumps())
        else:
            why = (p.reason or {}).get("why", "")
    med = statistics.median
    return {"cell": path, "outcome": outcome, "seeds": seeds, "median_s": med(times), "max_s": max(times),
            "endpoints_s": endpoints_s, "length_raw_rad": med(raw) if raw else None,
            "length_simplified_rad": med(simp) if simp else None, "ompl_motions": med(ompl) if ompl else None,
            "json_bytes": size, "why": why}


def run(seeds: int = 10, budget: float = 1.0, cells: tuple[str, ...] = CELLS) -> dict:
    return {"cells": [one_cell(c, seeds, budget) for c in cells], "goal_s": 1.0}


def render(r: dict) -> list[str]:
    L = ["## Motions (bench/motion.py)", "",
         ("Warm plan with motions, one run per OMPL seed (median, max), against the end-point plan "
          "measured in the same run; path length in joint space before/after simplification (median); "
          "the plan JSON's size. Goal: the paper's cell at most 1 s."), "",
         "| cell | outcome | median s | max s | end-points s | length raw / simplified rad | OMPL motions "
         "| JSON bytes |", "|---|---|---|---|---|---|---|---|"]
    for c in r["cells"]:
        ln = "-" if c["length_raw_rad"] is None else f"{c['length_raw_rad']:.3f} / {c['length_simplified_rad']:.3f}"
        L.append(f"| {c['cell']} | {c['outcome']} | {c['median_s']:.2f} | {c['max_s']:.2f} | {c['endpoints_s']:.3f} "
                 f"| {ln} | {c['ompl_motions']} | {c['json_bytes']} |")
        if c["why"]:
            L.append(f"|  | why: {c['why'][:150]} | | | | | | |")
    return L + [""]


if __name__ == "__main__":
    import json
    import sys

    n = int(sys.argv[1]) if len(sys.argv) > 1 else 10
    res = run(seeds=n)
    print("\n".join(render(res)))
    print(json.dumps(res, indent=1))
