"""Phase 2's cost per action, and where it goes (issue 18).

Run from the project root: ``.venv/bin/python -m bench.phase2 [--parts 10 30 50] [--repeats 3]``.

Each problem is planned in its own fresh process (a warm-up plan of the paper's cell
first, so the engine and the imports are paid), ``--repeats`` times; the figures are
medians of CPU seconds (the machine may be shared). The paper's cell row is a first
plan of that cell in a fresh process (its cold phase 2, the engine already started).

- ``phase 2``: plan.timing's phase2_s (Prolog CPU time, Python called back included);
- ``Python``: phase2.evaluate, one call per run of an instance;
- ``placements``: phase2/placements.py's choose_placements (placement.choose per put-down);
- ``arm``: phase2/arm.py's arm_for (as phase2/steps.py calls it), IK and the collision check of
  every end-point (world/collision/scene.py);
- ``uncertainty``: the rest of the Python side (constraints, SUP/INF, propagation,
  per-step poses);
- ``Prolog``: phase 2 less Python: uncertainty.pl's own work and the janus conversions.
"""
from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
CELL = "kb/problems/peg_in_block.yaml"

_CHILD = r"""
import json, sys, time
from spar_py.planning.planner import Planner, load_problem
from spar_py.phase2 import instance, placements, steps
acc = {}
def wrap(mod, name, key):  # in the module that calls it: its global is what the call looks up
    f = getattr(mod, name)
    def g(*a, **k):
        t = time.process_time()
        try:
            return f(*a, **k)
        finally:
            acc[key] = acc.get(key, 0.0) + time.process_time() - t
    setattr(mod, name, g)
for m, n, key in ((instance, "evaluate", "evaluate"), (placements, "choose_placements", "choose_placements"),
                  (steps, "arm_for", "arm")):
    wrap(m, n, key)
path, warm = sys.argv[1], sys.argv[2] == "1"
if warm:
    Planner().plan(load_problem(sys.argv[3]))
acc.clear()
cell = load_problem(path)
r = Planner(timeout=600).plan(cell)
inst = r.to_json().get("instance") or {}
print(json.dumps({"phase2": r.timing["phase2_s"], "total": r.timing["total_s"],
                  "actions": sum(1 for s in inst.get("steps", []) if s.get("kind") == "manipulation"),
                  "steps": len(inst.get("steps", [])), **acc}))
"""


def _run(path: Path, warm: bool) -> dict[str, float]:
    out = subprocess.run([sys.executable, "-c", _CHILD, str(path), "1" if warm else "0", str(ROOT / CELL)],
                         cwd=ROOT, capture_output=True, text=True, timeout=900, check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--parts", type=int, nargs="*", default=[10, 30, 34, 50], help="generated problems' N")
    ap.add_argument("--repeats", type=int, default=3)
    args = ap.parse_args(argv)
    from spar_py.app.gen import generate_assembly

    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        cases = [("paper's cell (first plan)", ROOT / CELL, False)]
        for n in args.parts:
            cases.append((f"generated N = {n}", generate_assembly(n, Path(tmp) / f"g{n}"), True))
        for label, path, warm in cases:
            runs = [_run(path, warm) for _ in range(args.repeats)]

            def med(k: str) -> float:
                return statistics.median(r.get(k, 0.0) for r in runs)

            p2, py = med("phase2"), med("evaluate")
            pl, arm = med("choose_placements"), med("arm")
            rows.append((label, int(runs[0]["actions"]), p2, py, pl, arm, py - pl - arm, p2 - py))
    print("| problem | actions | phase 2 s | ms/action | Python s | placements s | arm s | uncertainty s | Prolog s |")
    print("|---|---|---|---|---|---|---|---|---|")
    for label, a, p2, py, pl, arm, unc, pro in rows:
        per = f"{1e3 * p2 / a:.1f}" if a else "-"
        print(f"| {label} | {a} | {p2:.3f} | {per} | {py:.3f} | {pl:.3f} | {arm:.3f} | {unc:.3f} | {pro:.3f} |")


if __name__ == "__main__":
    main()
