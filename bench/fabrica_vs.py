"""Cold derivation of the Fabrica assemblies, this checkout's source against another's, in one run.

``python -m bench.fabrica_vs --before SRC [--names a,b] [--repeats 3]``: SRC is another
checkout's ``src`` directory (e.g. ``mkdir /tmp/base && git archive COMMIT src | tar -x -C
/tmp/base`` and copy ``src/spar_py/_swipl.json`` in; this checkout's venv runs both). Each
assembly is loaded as bench/fabrica.py's child loads it (``--one``: ``load_product_derived`` in
mm, an empty cache, imports of spar_py before the clock), the two trees alternating run by
run. Prints a Markdown table of medians (wall and CPU seconds) and the CPU ratio before/after:
on a shared machine the CPU time is the fair figure, both columns suffering the same load.
"""
from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

HERE = Path(__file__).resolve().parent.parent
NAMES = ("beam", "car", "cooling_manifold", "duct", "gamepad", "plumbers_block", "stool_circular")


def load(src: Path, name: str) -> tuple[float, float]:
    """(wall s, CPU s) of one cold load of kb/products/fabrica/NAME.yaml with source tree ``src``."""
    with tempfile.TemporaryDirectory() as cache:
        env = dict(os.environ, PYTHONPATH=f"{src}{os.pathsep}{HERE}", SPAR_CACHE_DIR=cache, XDG_CACHE_HOME=cache)
        out = subprocess.run([sys.executable, "-m", "bench.fabrica", "--one", name,
                              str(HERE / "kb/products/fabrica" / f"{name}.yaml")],
                             env=env, cwd=HERE, capture_output=True, text=True, check=True)
    d = json.loads([line for line in out.stdout.splitlines() if line.startswith("{")][-1])
    return float(d["derive_s"]), float(d["cpu_s"])


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(prog="python -m bench.fabrica_vs", description=__doc__.splitlines()[0])
    ap.add_argument("--before", required=True, type=Path, help="the other checkout's src directory")
    ap.add_argument("--names", default=",".join(NAMES), help="assemblies, comma-separated (default: all)")
    ap.add_argument("--repeats", type=int, default=3, help="runs per assembly and tree (default 3)")
    a = ap.parse_args(argv)
    trees = {"before": a.before.resolve(), "after": HERE / "src"}
    names = [n for n in a.names.split(",") if n]
    got: dict[tuple[str, str], list[tuple[float, float]]] = {(n, t): [] for n in names for t in trees}
    for _ in range(a.repeats):
        for n in names:
            for t, src in trees.items():
                got[n, t].append(load(src, n))
                print(f"{n} {t}: wall {got[n, t][-1][0]:.2f} s, CPU {got[n, t][-1][1]:.2f} s", file=sys.stderr)
    print("| assembly | before wall s | before CPU s | after wall s | after CPU s | CPU ratio |")
    print("|---|---|---|---|---|---|")
    for n in names:
        bw, bc = (statistics.median(x) for x in zip(*got[n, "before"]))
        aw, ac = (statistics.median(x) for x in zip(*got[n, "after"]))
        print(f"| {n} | {bw:.2f} | {bc:.2f} | {aw:.2f} | {ac:.2f} | {bc / ac:.2f}x |")


if __name__ == "__main__":
    main()
