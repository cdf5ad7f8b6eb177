"""The motion room: motions between the end-points: transit and transfer joint paths (OMPL), approach and
retreat lines, and the options and failures of a motion run.

This is the room's door: code outside world/motion/ imports these names from here, never
from the modules behind it.
"""

from spar_py.world.motion.options import FAILURES_KEPT, MotionFailure, MotionOptions, PLANNERS
from spar_py.world.motion.paths import (
    InstanceMotion, approach_length, attach, interval_seconds, line_ends, motion_summary, run_motions,
)

__all__ = [
    "approach_length", "attach", "FAILURES_KEPT", "InstanceMotion", "interval_seconds", "line_ends",
    "motion_summary", "MotionFailure", "MotionOptions", "PLANNERS", "run_motions",
]
