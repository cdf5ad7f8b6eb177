"""The collision room: one collision scene per cell (python-fcl and our own bounds): robot links, gripper and tool
body, held part, parts, obstacles and the table; clearance, the closest pair, and the
cell's kept answers (CellCache).

This is the room's door: code outside world/collision/ imports these names from here, never
from the modules behind it.
"""

from spar_py.world.collision.bodies import (
    TOOL, WORLD, Body, Obstacle, body_distance, box, bvh, convex, cylinder, fcl_transform, solid_bodies,
)
from spar_py.world.collision.cache import CellCache
from spar_py.world.collision.scene import DEFAULT_MARGIN_MM, CollisionScene, scene_for, solids_key
from spar_py.world.collision.state import SceneState, bound_columns, clearance_bounds

__all__ = [
    "Body", "body_distance", "bound_columns", "box", "bvh", "CellCache", "clearance_bounds", "CollisionScene",
    "convex", "cylinder", "DEFAULT_MARGIN_MM", "fcl_transform", "Obstacle", "scene_for", "SceneState",
    "solid_bodies", "solids_key", "TOOL", "WORLD",
]
