"""What a plan asks of its motions and what it hears when one does not exist (world/motion/paths.py).

The options and the failure record of the motion planner, apart from the planner itself so
that a plan without motions (a cell that does not ask for them, ``--no-motion``, phase 1
alone) need not import it; the room's door exports both.
"""
from __future__ import annotations

from dataclasses import dataclass

from spar_py.core.errors import SparValueError

__all__ = ["FAILURES_KEPT", "PLANNERS", "MotionFailure", "MotionOptions"]

#: OMPL geometric planners by option name.
PLANNERS = {"rrtconnect": "RRTConnect", "rrt": "RRT", "rrtstar": "RRTstar", "prm": "PRM",
            "kpiece": "KPIECE1", "bkpiece": "BKPIECE1", "bitstar": "BITstar"}
#: Distinct motion failures a run keeps for its no-plan reason.
FAILURES_KEPT = 8


@dataclass(frozen=True)
class MotionOptions:
    """How motions are planned: ``planner`` (a key of :data:`PLANNERS`), ``time_budget_s``
    (OMPL seconds per free motion), ``seed`` (OMPL's RNG, for reproducible paths),
    ``approach_length`` (cell unit; None: 2 in), ``simplify`` (OMPL's path simplifier)."""

    planner: str = "rrtconnect"
    time_budget_s: float = 1.0
    seed: int = 0
    approach_length: float | None = None
    simplify: bool = True

    def __post_init__(self) -> None:
        if self.planner not in PLANNERS:
            raise SparValueError(f"motion planner {self.planner!r}: expected one of {', '.join(PLANNERS)}")
        if not self.time_budget_s > 0:
            raise SparValueError(f"motion time budget {self.time_budget_s!r}: expected a positive number of seconds")
        if self.approach_length is not None and not self.approach_length > 0:
            raise SparValueError(f"approach length {self.approach_length!r}: expected a positive length")


@dataclass(frozen=True)
class MotionFailure:
    """Why a motion does not exist: ``motion`` names it ("transit to the approach of
    action_2"), ``pair`` the bodies that blocked it (closest pair at the first blocked
    waypoint; None when nothing collides, e.g. no continuous IK), ``detail`` one line."""

    motion: str
    pair: tuple[str, str] | None
    detail: str
    at: str | None = None  # the step id whose motion failed (None: home)

    def text(self) -> str:
        """One line for the user."""
        by = f", blocked by {self.pair[0]} and {self.pair[1]}" if self.pair else ""
        return f"no {self.motion}{by}: {self.detail}"
