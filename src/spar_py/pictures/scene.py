"""The work cell at each step of a plan instance, as the cell pictures draw it.

A :class:`Scene` is read, not computed: each step of ``instance.steps`` in the plan JSON
carries ``poses`` (part key -> 4x4 world pose at the step's end-point), ``held`` (the
object in the hand after the step, or null) and ``joints_deg``; the scene takes those
and the arm's frames ``robot.frames(q)``. Nothing here replays the plan; a step without
``poses`` (a plan JSON older than schema 2) is a SparValueError.

Frames and units: world Z up, table top z = 0, ``T_world_part`` 4x4 with column vectors,
lengths in the cell's unit (``cell.unit``); ``joints_deg`` in degrees in the robot file's
DH zero convention, ``Scene.q`` in radians. A part key is the object's name, or
``"<object>@<initial position name>"`` for the other parts of a stock of identical parts.
"""
from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from spar_py.core.errors import SparValueError
from spar_py.core.units import from_mm
from spar_py.pictures.plandoc import instance, pretty_term

if TYPE_CHECKING:
    from spar_py.core.model import Cell
    from spar_py.planning.planner import Plan

__all__ = ["Scene", "World", "initial_poses", "part_model", "scenes", "step_world"]

GRASP_TOL = 1e-4  # relative to the object's bounding radius: T_part @ T_g within this of the tool pose
#: The least object size GRASP_TOL is taken of (mm; 25.4 mm = 1 in), for tiny or shapeless objects.
MIN_SIZE_MM = 25.4


@dataclass(frozen=True)
class World:
    """Where the parts are after one step: part key -> T_world_part (4x4, cell unit), and the held object."""

    poses: dict[str, np.ndarray]
    held: str | None


@dataclass
class Scene:
    """The work cell at one step (index 0 = before the plan): titles, the parts' world poses
    (4x4, cell unit), the held object and the grasp it is held by, the arm's joints q (6,)
    rad and its 8 world frames (``robot.frames(q)``; None when no configuration is known),
    and a note on the arm (``"home"`` (at rest: :func:`_home`), ``"unchanged"`` or "")."""

    index: int
    title: str
    detail: str
    poses: dict[str, np.ndarray]
    held: str | None = None
    grasp: str | None = None
    q: np.ndarray | None = None
    frames: np.ndarray | None = None
    arm_note: str = ""

    @property
    def tool(self) -> np.ndarray | None:
        """The tool's world pose T_world_tool (4x4, cell unit), the last of ``frames``."""
        return None if self.frames is None else self.frames[-1]


def part_model(key: str) -> str:
    """The object (model) a part key draws: ``peg`` for a stock's part ``peg@init_pos1``."""
    return key.split("@", 1)[0]


def initial_poses(cell: Cell) -> dict[str, np.ndarray]:
    """Every part's world pose before the plan (from ``cell.positions``); a stock's further
    parts keyed ``"<object>@<position name>"``."""
    poses: dict[str, np.ndarray] = {}
    for p in cell.positions.values():
        poses[p.obj if p.obj not in poses else f"{p.obj}@{p.name}"] = np.array(p.T, float)
    return poses


def _pose(value: Any, where: str) -> np.ndarray:
    T = np.asarray(value, float)
    if T.shape != (4, 4) or not np.all(np.isfinite(T)):
        raise SparValueError(f"{where}: a 4x4 world pose, got shape {T.shape}")
    return T


def step_world(step: Mapping[str, Any], index: int) -> World:
    """The world after step ``index`` (1-based, for messages) as the step gives it: ``poses``, ``held``."""
    poses = {str(k): _pose(v, f"step {index}: poses[{k!r}]") for k, v in step["poses"].items()}
    held = step.get("held")
    if held is not None and str(held) not in poses:
        raise SparValueError(f"step {index}: held object {held!r} has no pose in poses")
    return World(poses, None if held is None else str(held))


def _worlds(cell: Cell, plan: Plan, steps: Sequence[Mapping[str, Any]]) -> list[World]:
    """Each step's world from its ``poses`` and ``held`` (plan JSON schema 2)."""
    out = []
    for k, step in enumerate(steps):
        if not step.get("poses"):
            raise SparValueError(f"step {k + 1}: no poses (a plan JSON of schema 2 gives every part's pose)")
        out.append(step_world(step, k + 1))
    return out


def held_grasp(cell: Cell, held: str | None, T_part: np.ndarray | None, tool: np.ndarray | None) -> str | None:
    """The grasp label of ``held`` whose T_part @ T_g is the tool pose (GRASP_TOL), else None."""
    if held is None or T_part is None or tool is None or part_model(held) not in cell.objects:
        return None
    model = cell.objects[part_model(held)]
    tol = GRASP_TOL * max(model.bounding_radius(), from_mm(cell.unit, MIN_SIZE_MM))
    for label, g in model.grasps.items():
        if np.abs(T_part @ np.asarray(g.T, float) - tool).max() <= tol:
            return str(label)
    return None


def _joints(cell: Cell, step: Mapping[str, Any] | None) -> tuple[np.ndarray | None, np.ndarray | None]:
    """(q rad, robot.frames(q)) of a step's ``joints_deg``; (None, None) when it has none."""
    if step is None or step.get("joints_deg") is None:
        return None, None
    q = np.radians(np.asarray(step["joints_deg"], float))
    return q, cell.robot.frames(q)


#: The arm note of a scene with the arm at rest (:func:`_home`).
AT_REST = "home"


def _home(cell: Cell, plan: Plan) -> tuple[np.ndarray, np.ndarray]:
    """(q rad, robot.frames(q)) of the arm at rest: the home the plan's motions start from
    (``instance.motion.home_deg``), else the cell's ``home``, else the documented default home,
    the middle of the joint ranges (world.motion.paths.default_home)."""
    motion = instance(plan).get("motion") or {}
    if motion.get("home_deg") is not None:
        q = np.radians(np.asarray(motion["home_deg"], float))
    elif cell.home is not None:
        q = np.asarray(cell.home, float)
    else:
        q = np.asarray(cell.robot.limits, float).mean(axis=1)
    return q, cell.robot.frames(q)


def _detail(s: Scene, step: Mapping[str, Any]) -> str:
    """The picture's subtitle: step kind (unless a manipulation), held object, joints (deg), placement."""
    kind = step.get("kind", "")
    parts = [str(kind)] if kind and kind != "manipulation" else []
    if s.held:
        parts.append(f"holding {s.held}" + (f" ({s.grasp})" if s.grasp else ""))
    if s.q is not None:
        parts.append("q = (" + ", ".join(f"{v:.0f}" for v in np.degrees(s.q)) + ") deg"
                     + (f" ({s.arm_note})" if s.arm_note else ""))
    pl = step.get("placement")
    if pl:
        obj = pl.get("object") or step.get("object") or ""
        parts.append(f"placed {obj} {pl.get('pose', '')} at ({pl.get('x', 0):.3g}, {pl.get('y', 0):.3g})"
                     f" yaw {pl.get('yaw_deg', 0):.3g} deg")
    return "; ".join(parts)


def _step_scene(cell: Cell, step: Mapping[str, Any], world: World, before: Scene, index: int,
                rest: tuple[np.ndarray, np.ndarray]) -> Scene:
    """The scene after step ``index``: its world, its joints (a sensing step: the arm at ``rest``,
    (q, frames); another step without joints: the arm where it was)."""
    q, frames = _joints(cell, step)
    note = ""
    if q is None and step.get("kind") == "sensing":
        q, frames, note = rest[0], rest[1], AT_REST
    elif q is None:
        q, frames, note = before.q, before.frames, "unchanged"
    title = f"step {index}: {pretty_term(str(step.get('term') or step.get('name') or ''))}"
    s = Scene(index, title, "", world.poses, world.held, None, q, frames, note)
    s.grasp = held_grasp(cell, s.held, s.poses.get(s.held) if s.held else None, s.tool)
    s.detail = _detail(s, step)
    return s


def scenes(cell: Cell, plan: Plan) -> list[Scene]:
    """The work cell before the plan (index 0) and after each step of the plan instance (1..n).

    Initial part poses come from ``cell.positions``; the initial picture and the sensing steps
    show the arm at rest (:func:`_home`).
    """
    steps = list(instance(plan).get("steps") or [])
    rest = _home(cell, plan)
    out = [Scene(0, "initial state", "arm at rest (home)", initial_poses(cell), q=rest[0], frames=rest[1],
                 arm_note=AT_REST)]
    for k, (step, world) in enumerate(zip(steps, _worlds(cell, plan, steps)), start=1):
        out.append(_step_scene(cell, step, world, out[-1], k, rest))
    return out
