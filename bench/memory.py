"""Memory per plan (issue 12): RSS growth over many plans of one cell in one process.

Run from the project root: ``.venv/bin/python -m bench.memory [--plans 1000] [--warmup 50]``.

For the paper's cell and a generated N = 3 cell (``spar_py.app.gen.generate_assembly(3)``,
planned with ``Planner(max_actions=14)``), each in a fresh subprocess: ``warmup`` plans,
then ``plans`` more; the figure is (RSS after - RSS after the warm-up) / plans, in kB,
with RSS read from /proc/self/statm after a ``gc.collect()``. Planning by path, as a
user would, so every plan goes through the Planner's cell cache. Beside it, in the same
child, the count of live spar-py objects (Cell, World) after the run, which must not grow
with the number of plans.

Each cell is measured in ``processes`` children (3 by default) and the median is the
figure, the largest beside it: what growth is left comes in rare one-time steps of about
0.9 MB (a table reaching its steady size: glibc's in-use bytes are flat before and after
it), and whether a run of 1,000 plans sees one depends on the process's hash seed.
"""
from __future__ import annotations

import argparse
import gc
import json
import os
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
CELL = ROOT / "kb" / "problems" / "peg_in_block.yaml"
#: The growth per plan issue 12 allows (kB).
LIMIT_KB = 1.0


def _rss_kb() -> float:
    gc.collect()
    with open("/proc/self/statm") as f:
        pages = int(f.read().split()[1])
    return pages * os.sysconf("SC_PAGE_SIZE") / 1024.0


def _live(cls_names: tuple[str, ...]) -> dict[str, int]:
    gc.collect()
    counts = dict.fromkeys(cls_names, 0)
    for o in gc.get_objects():
        n = type(o).__name__
        if n in counts and type(o).__module__.startswith("spar_py"):
            counts[n] += 1
    return counts


def child(which: str, plans: int, warmup: int) -> dict:
    """One measurement in this process (the child side)."""
    from spar_py.planning.planner import Planner

    if which == "paper":
        path, planner = CELL, Planner()
    else:
        from spar_py.app.gen import generate_assembly

        path = generate_assembly(3, Path(tempfile.mkdtemp(prefix="spar-mem-")))
        planner = Planner(max_actions=14)
    for _ in range(warmup):
        assert planner.plan(path).ok
    before = _rss_kb()
    for _ in range(plans):
        planner.plan(path)
    after = _rss_kb()
    return {"cell": which, "plans": plans, "warmup": warmup, "rss_before_kb": round(before),
            "rss_after_kb": round(after), "kb_per_plan": round((after - before) / plans, 3),
            "live": _live(("Cell", "World"))}


def run(plans: int = 1000, warmup: int = 50, processes: int = 3) -> list[dict]:
    """Both cells, each in ``processes`` subprocesses; one dict per cell: the median
    child's figures (see :func:`child`), with every child's ``kb_per_plan`` in ``runs``
    and the largest in ``max_kb_per_plan``."""
    rows = []
    for which in ("paper", "n3"):
        kids = []
        for _ in range(processes):
            out = subprocess.run([sys.executable, "-m", "bench.memory", "--child", which, "--plans", str(plans),
                                  "--warmup", str(warmup)], capture_output=True, text=True, cwd=ROOT, check=True)
            kids.append(json.loads(out.stdout.strip().splitlines()[-1]))
        kids.sort(key=lambda k: k["kb_per_plan"])
        row = dict(kids[len(kids) // 2])
        row["kb_per_plan"] = statistics.median(k["kb_per_plan"] for k in kids)
        row["runs"] = [k["kb_per_plan"] for k in kids]
        row["max_kb_per_plan"] = kids[-1]["kb_per_plan"]
        rows.append(row)
    return rows


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--plans", type=int, default=1000)
    ap.add_argument("--warmup", type=int, default=50)
    ap.add_argument("--processes", type=int, default=3)
    ap.add_argument("--child", choices=("paper", "n3"))
    a = ap.parse_args(argv)
    if a.child:
        print(json.dumps(child(a.child, a.plans, a.warmup)))
        return
    for row in run(a.plans, a.warmup, a.processes):
        print(json.dumps(row))


if __name__ == "__main__":
    main()
