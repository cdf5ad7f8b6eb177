"""LEGACY, to be deleted: the parts' poses of plans whose steps carry no ``poses``.

Until the planner writes each step's world (issue 12, item 2), a plan step has no
``poses`` / ``held``; :func:`legacy_poses` works them out by replaying the steps as
draw.py used to. Nothing else may use this module: when every plan carries ``poses``,
delete this file and the one branch of ``scene._worlds`` that imports it.

Frames and units as in :mod:`spar_py.pictures.scene` (``T_world_part``, cell unit).
"""
from __future__ import annotations

import math
from collections.abc import Mapping
from typing import TYPE_CHECKING, Any

import numpy as np

from ..geometry import inv, rotz, trans
from .plandoc import instance, term_parts
from .scene import World, initial_poses

if TYPE_CHECKING:
    from ..model import Cell

__all__ = ["legacy_poses", "placement_pose"]


def placement_pose(cell: Cell, obj: str, placement: Mapping[str, Any]) -> np.ndarray:
    """World pose (4x4) of a putdown placement ``{"x", "y", "z", "yaw_deg", "pose"}``.

    ``pose`` names a stable pose of ``obj`` (its orientation, turned ``yaw_deg`` degrees
    about world z: ``T = trans(x, y, z) @ rotz(yaw) @ R_pose``; ``z`` defaults to the
    pose's resting height) or an absolute position label of the cell (its transform).
    """
    label = placement.get("pose")
    if label in cell.positions:
        return np.array(cell.positions[label].T, float)
    R = np.eye(4)
    height = 0.0
    pose = cell.objects[obj].poses.get(label) if obj in cell.objects else None
    if pose is not None:
        R[:3, :3] = pose.R
        height = pose.height
    z = placement.get("z")
    return (trans(float(placement.get("x", 0.0)), float(placement.get("y", 0.0)),
                  height if z is None else float(z))
            @ rotz(math.radians(float(placement.get("yaw_deg", 0.0)))) @ R)


def _take_parts(cell: Cell, poses: dict[str, np.ndarray], sources: Mapping[str, str]) -> None:
    """Make the stock part a step takes (``from``: object -> initial position label) the one
    keyed by the object's name, as phase 2 does; the part it replaces keeps a key of its own."""
    for obj, label in sources.items():
        pos = cell.positions.get(label)
        key = f"{obj}@{pos.name}" if pos is not None else None
        if key in poses and obj in poses:
            poses[obj], poses[key] = poses[key], poses[obj]


def _tool(cell: Cell, step: Mapping[str, Any]) -> np.ndarray | None:
    """The step's world tool pose: ``tool_pose``, else the FK of ``joints_deg``, else None."""
    if step.get("tool_pose") is not None:
        return np.asarray(step["tool_pose"], float)
    if step.get("joints_deg") is not None:
        return cell.robot.fk(np.radians(np.asarray(step["joints_deg"], float)))
    return None


def _grasp_T(cell: Cell, obj: str | None, label: str | None) -> np.ndarray | None:
    if obj is None or label is None or obj not in cell.objects:
        return None
    g = cell.objects[obj].grasps.get(label)
    return None if g is None else np.asarray(g.T, float)


def legacy_poses(cell: Cell, plan: Mapping[str, Any]) -> list[World]:
    """The world after each step of the instance, by replay: held parts follow the tool
    (T_part = T_tool @ inv(T_g)); pickup grasps, putdown places (at ``placement``) and
    releases, assemble mates (at T_fixed @ T_a when the tool pose is unknown) and
    releases; sensing moves nothing."""
    bindings = instance(plan).get("bindings") or {}
    poses, held, grasp = initial_poses(cell), None, None
    out: list[World] = []
    for step in instance(plan).get("steps") or []:
        name, args = term_parts(str(step.get("term") or step.get("name") or ""))
        args = [str(bindings.get(a, a)) for a in args]
        poses = dict(poses)
        tool = _tool(cell, step)
        obj = step.get("object") or (args[0] if args else None)
        _take_parts(cell, poses, step.get("from") or {})
        if name == "pickup" and len(args) >= 2:
            held, grasp = args[0], args[1]
        Tg = _grasp_T(cell, held, grasp)
        moved_by_tool = held is not None and Tg is not None and tool is not None
        if moved_by_tool:
            poses[str(held)] = tool @ inv(Tg)
        if name == "putdown" and obj is not None:
            if step.get("placement"):
                poses[obj] = placement_pose(cell, obj, step["placement"])
            held = grasp = None
        elif name == "assemble" and len(args) >= 4:
            part, fixed, ta = args[0], args[1], args[3]
            if not (moved_by_tool and held == part) and fixed in poses and ta in cell.transforms:
                poses[part] = poses[fixed] @ np.asarray(cell.transforms[ta], float)
            held = grasp = None
        out.append(World(poses, held))
    return out
