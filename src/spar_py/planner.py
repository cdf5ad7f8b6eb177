"""The Python API: load a problem, plan it (phase 1, then phase 2), get a Plan.

Example (runnable; docs/quickstart.md)::

    from spar_py.planner import Planner
    planner = Planner()
    cell = planner.load_problem("kb/problems/peg_in_block.yaml")
    plan = planner.plan(cell)
    print([a["term"] for a in plan.actions])
    print(plan.to_json()["instance"]["error_count"])
"""
from __future__ import annotations

import json
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from .engine import engine
from .errors import PlanningTimeout, PrologError, SparValueError
from .kb import load_problem
from .model import Cell

SCHEMA = 1


@dataclass
class Plan:
    """A planning outcome (JSON schema 1, docs/json-schema.md).

    ``outcome`` is "plan" or "no_plan"; ``partial`` the phase-1 partial plan (actions,
    ordering, variables, arcs, separations); ``instance`` the chosen phase-2 instance
    (steps with joint angles, constraint verdicts, verifications, recoveries, error
    count) or None with ``phase1_only``; ``reason`` why there is no plan.
    """

    problem: str
    outcome: str
    partial: dict[str, Any] | None = None
    instance: dict[str, Any] | None = None
    reason: dict[str, Any] | None = None
    timing: dict[str, float] = field(default_factory=dict)
    trace: str = ""

    @property
    def ok(self) -> bool:
        """True when a plan was found."""
        return self.outcome == "plan"

    @property
    def actions(self) -> list[dict[str, Any]]:
        """The phase-1 actions (id, term, name, args), [] without a plan."""
        return list(self.partial["actions"]) if self.partial else []

    def to_json(self) -> dict[str, Any]:
        """The versioned JSON document (a dict; ``json.dumps`` it to write)."""
        return {
            "schema": SCHEMA,
            "problem": self.problem,
            "outcome": self.outcome,
            "reason": self.reason,
            "partial": self.partial,
            "instance": self.instance,
            "timing": self.timing,
        }

    def dumps(self) -> str:
        """The JSON text, indented."""
        return json.dumps(self.to_json(), indent=2)


class Planner:
    """SPAR's two-phase planner on the embedded SWI-Prolog.

    Options: ``max_actions`` (phase-1 plan-size bound), ``max_instances`` (phase-2
    cap on plan instances examined), ``separation`` (declobber by separation, dif/2),
    ``paper_placements`` (the paper's rule: a put-down into a stable pose is assumed
    reachable somewhere, Sec. 5.2.4; by default some placement in the free table
    regions must reach it), ``timeout`` (seconds for the whole query, None for none).
    """

    def __init__(self, max_actions: int = 12, max_instances: int = 50,
                 separation: bool = True, timeout: float | None = None,
                 paper_placements: bool = False) -> None:
        if max_actions < 1 or max_instances < 1:
            raise SparValueError("max_actions and max_instances must be at least 1")
        if timeout is not None and timeout <= 0:
            raise SparValueError("timeout must be positive")
        self.max_actions = max_actions
        self.max_instances = max_instances
        self.separation = separation
        self.timeout = timeout
        self.paper_placements = paper_placements
        self.engine = engine()

    def load_problem(self, path: str | Path) -> Cell:
        """Load and validate a problem file (KBError on bad input)."""
        return load_problem(path)

    def plan(self, problem: Cell | str | Path, phase1_only: bool = False, trace: bool = False) -> Plan:
        """Plan ``problem`` (a loaded Cell or a problem file path)."""
        cell = problem if isinstance(problem, Cell) else self.load_problem(problem)
        cell.stable_pose_rule = "paper" if self.paper_placements else "reachable"
        t0 = time.perf_counter()
        self.engine.load_cell(cell)
        opts = {
            "max_actions": self.max_actions,
            "max_instances": self.max_instances,
            "separation": self.separation,
            "phase1_only": phase1_only,
            "trace": trace,
            "timeout": self.timeout if self.timeout is not None else 0,
        }
        try:
            ans = self.engine.query_once("spar:plan_dict(Problem, Options, Dict, Trace)",
                                         {"Problem": cell.name, "Options": opts})
        except PrologError as e:
            if "time_limit_exceeded" in e.term:
                raise PlanningTimeout(f"{cell.name}: no result within {self.timeout} s") from None
            raise
        d = ans["Dict"]
        d.setdefault("timing", {})["total_s"] = round(time.perf_counter() - t0, 6)
        return Plan(problem=cell.name, outcome=d["outcome"], partial=d.get("partial"),
                    instance=d.get("instance"), reason=d.get("reason"), timing=d["timing"],
                    trace=ans.get("Trace", ""))
