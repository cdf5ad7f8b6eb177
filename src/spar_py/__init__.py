"""spar-py: SPAR, the assembly task planner of Hutchinson & Kak, on embedded SWI-Prolog.

Public API (see docs/quickstart.md)::

    from spar_py import Planner
    planner = Planner()
    cell = planner.load_problem("kb/problems/peg_in_block.yaml")
    plan = planner.plan(cell)
"""
from .errors import KBError, PlanningTimeout, PrologError, SparError, SparValueError

__version__ = "0.1.0"

__all__ = [
    "KBError",
    "PlanningTimeout",
    "PrologError",
    "SparError",
    "SparValueError",
    "__version__",
]
