"""Motion planning time (issue 16): the paper's cell and the wall cell with motions, warm
(the cell loaded and planned once with --no-motion first, so phase 1 and the end-points
are memoised and only the motions are planned again), one run per OMPL seed; the median
over the seeds, the end-point-only plan as the peer measured in the same run; path length
(joint space, rad) before and after OMPL's simplification; the plan JSON's size and its
waypoints (medians over the seeds).

Goal (issue 16): the paper's cell with motions at most 1 s warm, median over 10 seeds.

BEFORE: the same measurement at commit e9a0a9b, when every waypoint of every segment (about
10,000 per motion at the 0.02 deg resolution) went through SceneState.check; since then a
segment is certified by clearance (world/motion/paths.py ``certify``) and only waypoints the bound
cannot decide are checked one by one. Those runs took minutes, so they are recorded here, not
re-run: ``git archive e9a0a9b src prolog kb`` into a directory and run this module with
PYTHONPATH pointing at it to reproduce them."""
from __future__ import annotations

import statistics
import time

CELLS = ("kb/problems/peg_in_block.yaml", "kb/problems/wall_detour.yaml")
#: At commit e9a0a9b (per-waypoint checks, simplifyMax): warm seconds with motions, the median
#: over the seeds that were run (paper cell: seeds 0, 1; wall cell: seeds 0-2) and their range,
#: and the plan JSON's size (bytes) and simplified length (rad) at seed 0 (the paper cell's from
#: the first certified-checking commit, whose paths are e9a0a9b's: same seeds, same verdicts).
BEFORE = {"kb/problems/peg_in_block.yaml": {"median_s": 23.0, "range_s": (19.7, 26.2), "seeds": 2,
                                            "json_bytes": 2354279, "length_simplified_rad": 18.49},
          "kb/problems/wall_detour.yaml": {"median_s": 4.74, "range_s": (4.27, 5.66), "seeds": 3,
                                           "json_bytes": 1419381, "length_simplified_rad": 10.90}}


def one_cell(path: str, seeds: int, budget: float) -> dict:
    from spar_py import Planner
    from spar_py.world.motion.paths import MotionOptions

    peer = Planner(motion=False)
    peer.plan(path)
    t = time.perf_counter()
    peer.plan(path)
    endpoints_s = time.perf_counter() - t
    times, outcome, raw, simp, sizes, why, ompl, points = [], "", [], [], [], "", [], []
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
            sizes.append(len(p.dumps()))
            steps = p.instance.get("steps") or []
            points.append(sum(len(st.get(k) or []) for st in steps for k in ("path", "approach", "retreat"))
                          + len(m.get("home_path") or []))
        else:
            why = (p.reason or {}).get("why", "")
    med = statistics.median
    return {"cell": path, "outcome": outcome, "seeds": seeds, "median_s": med(times), "max_s": max(times),
            "endpoints_s": endpoints_s, "length_raw_rad": med(raw) if raw else None,
            "length_simplified_rad": med(simp) if simp else None, "ompl_motions": med(ompl) if ompl else None,
            "json_bytes": med(sizes) if sizes else 0, "waypoints": med(points) if points else 0, "why": why}


def run(seeds: int = 10, budget: float = 1.0, cells: tuple[str, ...] = CELLS) -> dict:
    return {"cells": [one_cell(c, seeds, budget) for c in cells], "goal_s": 1.0}


def render(r: dict) -> list[str]:
    L = ["## Motions (bench/motion.py)", "",
         ("Warm plan with motions, one run per OMPL seed (median, max), against the end-point plan "
          "measured in the same run; path length in joint space before/after simplification (median); "
          "the plan JSON's size. Goal: the paper's cell at most 1 s."), "",
         "| cell | outcome | median s | max s | end-points s | length raw / simplified rad | OMPL motions "
         "| JSON bytes | waypoints | before: median s (range, seeds), JSON bytes, simplified rad |",
         "|---|---|---|---|---|---|---|---|---|---|"]
    for c in r["cells"]:
        b = BEFORE.get(c["cell"])
        was = "-" if b is None else (f"{b['median_s']:.2f} ({b['range_s'][0]:.2f}-{b['range_s'][1]:.2f}, "
                                     f"{b['seeds']}), {b['json_bytes']}, {b['length_simplified_rad']:.2f}")
        ln = "-" if c["length_raw_rad"] is None else f"{c['length_raw_rad']:.3f} / {c['length_simplified_rad']:.3f}"
        L.append(f"| {c['cell']} | {c['outcome']} | {c['median_s']:.2f} | {c['max_s']:.2f} | {c['endpoints_s']:.3f} "
                 f"| {ln} | {c['ompl_motions']} | {c['json_bytes']:.0f} | {c['waypoints']:.0f} | {was} |")
        if c["why"]:
            L.append(f"|  | why: {c['why'][:150]} | | | | | | | | |")
    return L + [""]


if __name__ == "__main__":
    import json
    import sys

    n = int(sys.argv[1]) if len(sys.argv) > 1 else 10
    res = run(seeds=n)
    print("\n".join(render(res)))
    print(json.dumps(res, indent=1))
