"""Suite-wide set-up for running on several cores (pytest-xdist, ``make test``).

Two things decide how the suite splits over workers (``--dist loadgroup``):

- a test that uses a fixture its module shares between tests (``scope="module"`` or wider:
  a fuzz sample, a set of planned cells, a benchmark run) is put in its module's group, so
  one worker computes that fixture once; every other test is scheduled on its own;
- the heaviest groups start first, then the modules that hold a ``slow`` test, then the rest
  (collection order, which ``--no-loadscope-reorder`` keeps): a long group that started
  last would leave the other cores idle at the end.

Each worker has its own temporary directories (pytest's ``tmp_path``) and its own
SWI-Prolog; the caches in ``~/.cache/spar-py`` (compiled image, saved state, dataclass
methods, derived shapes) are shared on purpose: they are keyed by content, written to a
temporary name and renamed, and the image and state are built under a file lock
(tests/test_coldstart.py checks processes starting together), so a worker never reads
another's half-written entry.
"""
from __future__ import annotations

import os

import pytest

#: Fixture scopes that one worker should compute once for all of a module's tests.
SHARED_SCOPES = frozenset({"module", "package", "session"})


def _shares_a_module_fixture(item: pytest.Item) -> bool:
    """True if the test uses a fixture of module scope or wider that its own module or a
    conftest of the suite defines (pytest's and plugins' own fixtures do not count)."""
    info = getattr(item, "_fixtureinfo", None)
    if info is None:
        return False
    tests_dir = os.path.dirname(__file__)
    for defs in info.name2fixturedefs.values():
        for d in defs:
            where = getattr(d.func, "__code__", None)
            if d.scope in SHARED_SCOPES and where is not None and where.co_filename.startswith(tests_dir):
                return True
    return False


#: Modules whose shared fixtures cost the most (measured with --durations, heaviest first):
#: their groups start at once, each on its own worker, instead of after the quick tests.
HEAVY_FIRST = ("test_fuzz", "test_bench", "test_signals", "test_schema", "test_motion")


def _order(item: pytest.Item, slow_modules: set[str]) -> tuple[int, int]:
    """Sort key: the heavy modules' grouped tests first (in HEAVY_FIRST's order), then the
    modules with slow tests, then the rest."""
    module = item.module.__name__ if getattr(item, "module", None) else ""
    grouped = item.get_closest_marker("xdist_group") is not None
    if grouped and module in HEAVY_FIRST:
        return (0, HEAVY_FIRST.index(module))
    return (1 if module in slow_modules else 2, 0)


@pytest.hookimpl(tryfirst=True)  # before xdist's own hook reads the groups
def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """Group the tests that share a module fixture, then order (a stable sort, so a module's
    grouped tests stay together and in their order, and no shared fixture is built twice)."""
    slow_modules = {item.module.__name__ for item in items
                    if item.get_closest_marker("slow") and getattr(item, "module", None)}
    for item in items:
        if _shares_a_module_fixture(item) and getattr(item, "module", None):
            item.add_marker(pytest.mark.xdist_group(item.module.__name__))
    items.sort(key=lambda it: _order(it, slow_modules))
