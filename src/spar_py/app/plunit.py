"""Run the plunit suites (tests/prolog/*.plt) inside the embedded SWI-Prolog.

``python -m spar_py.app.plunit tests/prolog`` loads the planner as the package does,
then each .plt file, runs all tests and prints plunit's summary; the exit code is
0 only if every test passed.
"""
from __future__ import annotations

import sys
from pathlib import Path

from spar_py.planning.engine import engine
from spar_py.core.errors import SparError


def run(paths: list[str]) -> int:
    """Load every .plt under ``paths`` and run their tests; return the process exit code."""
    files: list[Path] = []
    for p in map(Path, paths):
        files += sorted(p.glob("*.plt")) if p.is_dir() else [p]
    if not files:
        print("plunit: no .plt files found", file=sys.stderr)
        return 1
    eng = engine()
    for f in files:
        eng.query_once("load_files(File, [])", {"File": str(f.resolve())})
    ok = eng.query_once("run_tests")["truth"]
    return 0 if ok else 1


def main() -> None:
    """Entry point of ``python -m spar_py.app.plunit``."""
    try:
        sys.exit(run(sys.argv[1:] or ["tests/prolog"]))
    except SparError as e:
        print(f"plunit: error: {e}", file=sys.stderr)
        sys.exit(1)


if __name__ == "__main__":
    main()
