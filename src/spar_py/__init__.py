"""spar-py: SPAR, the assembly task planner of Hutchinson & Kak, on embedded SWI-Prolog.

Public API (see docs/quickstart.md)::

    from spar_py import Planner
    planner = Planner()
    plan = planner.plan("kb/problems/peg_in_block.yaml")
    print(plan.outcome, [a.term for a in plan.actions])

Importing the package is cheap: the planner (numpy, janus, the embedded Prolog) is
imported on first use of ``Planner``, ``Plan``, ``load_problem`` and the rest.
"""
from __future__ import annotations

from importlib import import_module
from typing import Any

from spar_py.core.errors import (ExpectedFailures, InternalError, KBError, PlanningTimeout, PrologError, SparError,
                                 SparValueError)

__version__ = "0.1.0"

#: Lazily imported names -> the module that defines them.
_LAZY = {
    "Planner": "planning.planner", "Plan": "planning.planner", "Outcome": "planning.planner",
    "Action": "planning.planner", "Step": "planning.planner", "Verdict": "planning.planner",
    "load_problem": "kb", "Cell": "core.model",
}

__all__ = [
    "Action", "Cell", "ExpectedFailures", "InternalError", "KBError", "Outcome", "Plan", "Planner", "PlanningTimeout",
    "PrologError", "SparError", "SparValueError", "Step", "Verdict", "__version__", "load_problem",
]


def __getattr__(name: str) -> Any:
    """Import ``Planner`` and friends on first use (PEP 562)."""
    module = _LAZY.get(name)
    if module is None:
        raise AttributeError(f"module 'spar_py' has no attribute {name!r}")
    value = getattr(import_module(f".{module}", __name__), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(__all__)
