"""The reach room: "the arm reaches T, clear of the world": the workspace checks, phase 1's reach arcs
(Sec. 5.2.4), put-down placements on the free table, and what a part rests on (supports).

This is the room's door: code outside world/reach/ imports these names from here, never
from the modules behind it.
"""

from spar_py.world.reach.arcs import RULES, arc, hand_above_table, reachable_pairs
from spar_py.world.reach.placement import (
    GRID_STEP_MM, Level, Occupant, Placement, choose, footprint, occupant, part_level,
)
from spar_py.world.reach.supports import (
    REST_TOL_MM, lowest, part_surface, rest_of, rest_of_body, solid_points, surfaces_of,
)
from spar_py.world.reach.workspace import (
    Refusal, arm_at, assembled_touch, pair_text, reach_clear, reachable_ignoring_collisions, wrist_above_table,
)

__all__ = [
    "arc", "arm_at", "assembled_touch", "choose", "footprint", "GRID_STEP_MM", "hand_above_table", "Level",
    "lowest", "Occupant", "occupant", "pair_text", "part_level", "part_surface", "Placement", "reach_clear",
    "reachable_ignoring_collisions", "reachable_pairs", "Refusal", "rest_of", "rest_of_body", "REST_TOL_MM",
    "RULES", "solid_points", "surfaces_of", "wrist_above_table",
]
