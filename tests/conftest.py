"""Suite-wide set-up for running on several cores (pytest-xdist, ``make test``).

``make test`` runs ``pytest -n auto --dist loadfile``: each test file runs on one worker, so
a fixture its module shares between tests (a fuzz sample, a set of planned cells, a
benchmark run) is computed once. (``--dist loadgroup`` would spread a file's other tests
too, but pytest-xdist 3.8 cannot mark the groups under pytest 9: it sets a node attribute
pytest 9 no longer reads.) The order below decides which files start first: the heaviest,
then those holding a ``slow`` test, then the rest (``--no-loadscope-reorder`` keeps it), so
a long file does not start last and leave the other cores idle at the end.

Each worker has its own temporary directories (pytest's ``tmp_path``) and its own
SWI-Prolog; the caches in ``~/.cache/spar-py`` (compiled image, saved state, dataclass
methods, derived shapes) are shared on purpose: they are keyed by content, written to a
temporary name and renamed, and the image and state are built under a file lock
(tests/test_coldstart.py checks processes starting together), so a worker never reads
another's half-written entry.
"""
from __future__ import annotations

from typing import TYPE_CHECKING

import pytest

if TYPE_CHECKING:
    from spar_py.planning.planner import Planner

#: Files whose shared fixtures cost the most (measured with --durations, heaviest first).
HEAVY_FIRST = ("test_bench", "test_fuzz", "test_bench_run", "test_signals", "test_schema", "test_motion")


def _order(item: pytest.Item, slow_modules: set[str]) -> tuple[int, int]:
    """Sort key: the heavy files in HEAVY_FIRST's order, then files with slow tests, then the rest."""
    module = item.module.__name__ if getattr(item, "module", None) else ""
    if module in HEAVY_FIRST:
        return (0, HEAVY_FIRST.index(module))
    return (1 if module in slow_modules else 2, 0)


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """Put the heavy files first (a stable sort: a file's tests stay together and in order,
    so no module fixture is built twice, with or without xdist)."""
    slow_modules = {item.module.__name__ for item in items
                    if item.get_closest_marker("slow") and getattr(item, "module", None)}
    items.sort(key=lambda it: _order(it, slow_modules))


@pytest.fixture(scope="module")
def planner() -> Planner:
    """A Planner with the default options, built once per test file and shared by its
    tests. A file needing other options defines its own
    ``planner`` (test_phase2.py: max_instances=5). The import is in the fixture (as
    test_messages.py had it), so loading this conftest imports nothing of spar_py."""
    from spar_py.planning.planner import Planner

    return Planner()
