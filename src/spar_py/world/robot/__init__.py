"""The robot room: robot models (DH tables, URDF import), the one gripper type and its collision shapes, and
the inverse kinematics (ik/: closed-form PUMA and UR families, a numeric fallback, one interface).

This is the room's door: code outside world/robot/ imports these names from here, never
from the modules behind it.
"""

from spar_py.world.robot.gripper import TOOL_BODY, Gripper, ToolBody, gripper_for, tool_body_behind
from spar_py.world.robot.model import (
    LinkShape, Robot, UrdfMeshError, read_urdf_chain, robot_from_urdf, standard_to_modified,
)

__all__ = [
    "Gripper", "gripper_for", "LinkShape", "read_urdf_chain", "Robot", "robot_from_urdf", "standard_to_modified",
    "TOOL_BODY", "tool_body_behind", "ToolBody", "UrdfMeshError",
]
