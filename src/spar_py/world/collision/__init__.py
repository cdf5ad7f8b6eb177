"""The collision room: one collision scene per cell (python-fcl and our own bounds): robot links, gripper and tool
body, held part, parts, obstacles and the table; clearance, the closest pair, and the
cell's kept answers (CellCache).

This is the room's door: code outside world/collision/ imports these names from here, never
from the modules behind it.
"""

from spar_py.world.collision.cache import CellCache
from spar_py.world.collision.scene import (
    TOOL, WORLD, Body, CollisionScene, DEFAULT_MARGIN_MM, Obstacle, SceneState, body_distance, bound_columns, box,
    bvh, clearance_bounds, convex, cylinder, fcl_transform, scene_for, solid_bodies, solids_key,
)

__all__ = [
    "Body", "body_distance", "bound_columns", "box", "bvh", "CellCache", "clearance_bounds", "CollisionScene",
    "convex", "cylinder", "DEFAULT_MARGIN_MM", "fcl_transform", "Obstacle", "scene_for", "SceneState",
    "solid_bodies", "solids_key", "TOOL", "WORLD",
]
