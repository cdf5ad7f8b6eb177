"""Warm and cold planning of the paper's cell, this checkout against another, in one run.

``python -m bench.before_after --before DIR [--repeats 15]``: DIR is another checkout of
spar-py with its own ``.venv`` (e.g. ``git worktree add /tmp/before <commit>`` and
``make -C /tmp/before setup``). Cold: ``spar plan kb/problems/peg_in_block.yaml`` as a
fresh process, the two checkouts alternating; warm: one process per checkout plans the
cell ``repeats`` times after one warm-up and reports the median wall time of a plan.
Prints a Markdown table of medians and the ratio after/before; both columns are measured
in the same run, so machine noise affects them alike.
"""
from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent.parent
CELL = "kb/problems/peg_in_block.yaml"
WARM = ("import json, statistics, time; from spar_py import Planner; p = Planner(); "
        "p.plan({cell!r}); ts = []\n"
        "for _ in range({n}):\n"
        "    t = time.perf_counter(); p.plan({cell!r}); ts.append(time.perf_counter() - t)\n"
        "print(json.dumps(statistics.median(ts)))")


def cold(root: Path) -> float:
    """Seconds of one ``spar plan`` process in checkout ``root``."""
    t = time.perf_counter()
    subprocess.run([str(root / ".venv/bin/spar"), "plan", CELL], cwd=root, capture_output=True, check=True)
    return time.perf_counter() - t


def warm(root: Path, n: int) -> float:
    """Median seconds of a warm plan in checkout ``root``."""
    out = subprocess.run([str(root / ".venv/bin/python"), "-c", WARM.format(cell=CELL, n=n)], cwd=root,
                         capture_output=True, text=True, check=True)
    return float(json.loads(out.stdout.strip().splitlines()[-1]))


def run(before: Path, repeats: int = 15) -> dict[str, dict[str, float]]:
    """Medians {figure: {"before": s, "after": s}}."""
    colds: dict[str, list[float]] = {"before": [], "after": []}
    for _ in range(repeats):
        for side, root in (("before", before), ("after", HERE)):
            colds[side].append(cold(root))
    warms: dict[str, list[float]] = {"before": [], "after": []}
    for _ in range(3):
        for side, root in (("before", before), ("after", HERE)):
            warms[side].append(warm(root, repeats))
    return {"cold `spar plan`": {k: statistics.median(v) for k, v in colds.items()},
            "warm `Planner.plan`": {k: statistics.median(v) for k, v in warms.items()}}


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--before", type=Path, required=True)
    ap.add_argument("--repeats", type=int, default=15)
    a = ap.parse_args(argv)
    r = run(a.before.resolve(), a.repeats)
    print("| figure | before | after | after/before |\n|---|---|---|---|")
    for name, v in r.items():
        print(f"| {name} | {v['before'] * 1e3:.1f} ms | {v['after'] * 1e3:.1f} ms | {v['after'] / v['before']:.2f} |")


if __name__ == "__main__":
    main()
