"""Bytes crossing the janus bridge in phase 2 of one problem, on this checkout or an older one.

    python -m bench.bridge_bytes kb/problems/hopeless_uncertainty.yaml

Counts, as ``len(json.dumps(...))``, every phase-2 ``evaluate`` call's arguments (Prolog ->
Python) and result (Python -> Prolog), and the plan dict Prolog returns at the end, for a plan
of a freshly loaded cell in a warm process (the engine started by a first plan). Uses the public
``Planner`` and the bridge module under either layout (``spar_py.planning.engine`` now,
``spar_py.engine`` before the packages), so the same script measures before and after.
"""
from __future__ import annotations

import importlib
import json
import sys
from typing import Any


def _bridge() -> Any:
    for name in ("spar_py.planning.engine", "spar_py.engine"):
        try:
            return importlib.import_module(name)
        except ImportError:
            continue
    raise SystemExit("no spar_py bridge module found")


def measure(problem: str) -> dict[str, Any]:
    """The byte counts of one plan of ``problem`` (see the module docstring)."""
    from spar_py import Planner

    eng = _bridge()
    calls = {"n": 0, "args": 0, "result": 0}
    real = eng.evaluate

    def counted(*a: Any, **k: Any) -> Any:
        r = real(*a, **k)
        calls["n"] += 1
        calls["args"] += len(json.dumps([a, k], default=str))
        calls["result"] += len(json.dumps(r, default=str))
        return r

    eng.evaluate = counted
    planner = Planner()
    planner.plan(problem)  # the engine started and the planner loaded
    calls.update(n=0, args=0, result=0)
    real_query = planner.engine.query_once
    size: dict[str, int] = {}

    def query(goal: str, bindings: dict[str, Any] | None = None) -> dict[str, Any]:
        ans = real_query(goal, bindings)
        if "plan_dict" in goal:
            size["dict"] = len(json.dumps(ans["Dict"], default=str))
        return ans

    planner.engine.query_once = query  # type: ignore[method-assign]
    planner._cells = type(planner._cells)(8)  # a freshly loaded cell: nothing kept from the first plan
    if hasattr(planner, "_caches"):
        planner._caches = type(planner._caches)(8)
    plan = planner.plan(problem)
    return {"evaluate_calls": calls["n"], "results_python_to_prolog": calls["result"],
            "arguments_prolog_to_python": calls["args"], "plan_dict_prolog_to_python": size.get("dict"),
            "outcome": plan.outcome.value}


if __name__ == "__main__":
    print(json.dumps(measure(sys.argv[1] if len(sys.argv) > 1 else "kb/problems/hopeless_uncertainty.yaml")))
