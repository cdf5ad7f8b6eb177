"""One collision scene per run: the arm's links, the gripper, the held part, the parts, the
obstacles and the table; "is this joint vector clear by the margin", the clearance and the
closest pair.

What is in the scene (:func:`scene_for`, built once per cell and kept by its world.run.CellCache):

- the robot's link shapes (robot file ``collision: links``): capsules, cylinders and boxes,
  each fixed to one of Craig's frames 0..6 (0 is the base: it does not move);
- the gripper (robot file ``gripper:``, :class:`~spar_py.world.robot.Gripper`): the
  palm and two fingers whose contact faces are the grasp's width apart (the open
  finger_separation when no part is in the hand), and the tool body "tool" from the palm back to
  the flange (``gripper: body``; by default, for a robot without ``collision:``, a box the palm's
  size), which counts as the gripper wherever the gripper does;
- the parts (each object's ``shape:`` solids: boxes, z-cylinders; a mesh part: its mesh, as
  its convex hull where that is the mesh within HULL_EXCESS_MM, else as its triangles, bounded
  by the hull either way), placed by :meth:`CollisionScene.at`;
- the obstacles (problem file ``obstacles:``), and the table: the half-space z < 0 over its
  extent (problem file ``table:``; the whole plane when not given).

Which pairs are checked, and with which margin (``margin``: robot file ``collision: margin``,
problem file ``clearance:``, else DEFAULT_MARGIN_MM):

- every moving body (links 1..6, palm, fingers, tool body, held part) against the table, the obstacles
  and every part in the world, by the margin;
- links against links whose frames are two or more apart (self-collision of non-adjacent
  links), the gripper against links 0..5 and the held part against links 0..6, by the margin;
  the robot file's ``collision: allow`` pairs are never checked (bodies that touch by design);
- the gripper and the part in the hand (``grasped``: the part the fingers are closing on, or
  ``held``): not by distance but by the grasp rule, :meth:`SceneState.grasp_ok`: no finger may
  enter the part beyond its contact face, and the palm may not enter it (contact allowed,
  within GRASP_TOL_MM); the part is checked against the links like any other;
- ``allow`` pairs of :meth:`CollisionScene.at`: the step's own contacts, e.g. the held part and
  the part it is inserted into at an assemble, the held part and the table at a put-down.

How: every body has a bounding capsule in its frame (exact for capsules). One vectorised numpy
pass gives each (row, pair) cell's capsule distance, a lower bound of its true distance, and each
body's height over the table. Only the cells within the margin, not both capsules, and not put
beyond it by a second bound (:func:`support_gap`, the separating-axis bound) go to the collision
library. The grasp rule is decided once per grasp and kept in the cell's cache. The closest pair
of a clear row (:meth:`SceneState.clearance`) is sought among the pairs whose bounding spheres
come within the table's distance, in order of their capsule bounds.

The library: python-fcl, imported on first use (the choice: bench/RESULTS.md). Its signed
distance can abort the process on touching shapes, so it is never asked for: a near pair is
tested with ``collide`` (clearance 0) and only a separated pair measured with ``distance``.

Frames and units: world Z up, table top z = 0; all lengths in the cell's unit (the robot is
loaded in it); joint vectors in radians; a body's pose is its frame's world pose times its
fixed local transform.

Here: the scene and its making (:class:`CollisionScene`, :func:`scene_for`). Beside it:
bodies.py (the bodies, their builders, the library's distance), bounds.py (the vectorised
distance bounds), pairs.py (which pairs a state checks), state.py (:class:`SceneState`: the
answers per joint vector, and the bounds the motions ask).
"""
from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import replace
from typing import TYPE_CHECKING, Any

import numpy as np

from spar_py.core.errors import SparValueError
from spar_py.core.units import from_mm
from spar_py.world.collision.bodies import (
    TOOL, WORLD, Body, Obstacle, Placed, box, cylinder, fcl_transform, group_columns, link_body, mesh_body,
    solid_bodies,
)
from spar_py.world.collision.state import SceneState
from spar_py.world.robot import Gripper, gripper_for

if TYPE_CHECKING:
    from spar_py.core.model import Cell, Solid
    from spar_py.world.robot import Robot

__all__ = ["CollisionScene", "DEFAULT_MARGIN_MM", "GRASP_TOL_MM", "PLACED_LIMIT", "REST_TOL_MM", "scene_for",
           "solids_key"]

#: The clearance margin when neither the robot nor the problem file gives one: 2 mm.
DEFAULT_MARGIN_MM = 2.0
#: A part's lowest vertex this near a support's top rests on it (mm; world.reach.supports' tolerance).
REST_TOL_MM = 0.5
#: Contact between the fingers (or palm) and the part in the hand: allowed up to this overlap
#: (rounding, not geometry): 0.05 mm.
GRASP_TOL_MM = 0.05
#: Bound of the cell cache's table of placed part bodies per (part, frame, pose): phase 2 places
#: every part on the table at every step, most of them where they were at the step before.
PLACED_LIMIT = 2048


class CollisionScene:
    """The run's collision world: link and gripper shapes, part shapes, obstacles, the table,
    the clearance ``margin`` (cell unit). Place the parts with :meth:`at`."""

    def __init__(self, robot: Robot, gripper: Gripper, parts: Mapping[str, list[Body]],
                 obstacles: Iterable[Obstacle], margin: float, table: tuple[float, float, float, float] | None,
                 unit: str, memo: Any = None, meshes: Mapping[str, Any] | None = None) -> None:
        """``meshes``: {model: world.parts.mesh.Geometry} of the mesh parts (``parts`` bodies of kind
        "mesh", or convex hulls where made by hand); the grasp rule tests the gripper against the
        mesh itself."""
        self.robot = robot
        self.meshes = dict(meshes or {})
        self._mesh_fcl: dict[str, Any] = {}  # by model: bounded by the cell's parts
        self.gripper = gripper
        self.parts = dict(parts)
        self.obstacles = tuple(obstacles)
        self.margin = float(margin)
        #: the table's extent (x0, x1, y0, y1) or None: the whole plane
        self.table = table
        self.unit = unit
        self.tol = from_mm(unit, GRASP_TOL_MM)
        self.memo = memo
        self.links = [link_body(s) for s in robot.links]
        self.allowed = frozenset(frozenset(p) for p in robot.allowed)
        self._grippers: dict = {}  # bounded by the cell's grasp widths
        self._slab: Body | None = None
        self._obstacle_bodies: Placed | None = None  # made on first use by at()
        self._shape_keys: dict[str, tuple] = {}  # by model name: bounded by the cell's parts
        self.stats = {"pairs": 0, "exact": 0}

    def slab(self) -> Body:
        """The table of a table with an extent as a box (world): its footprint, from the top
        z = 0 down as deep as the footprint is wide (for exact distances beside its edge)."""
        if self._slab is None:
            x0, x1, y0, y1 = self.table
            depth = max(x1 - x0, y1 - y0, 1.0)
            self._slab = box("table", WORLD, np.array([x0, y0, -depth]), np.array([x1, y1, 0.0]))
        return self._slab

    def resting_on(self, part: str, T: np.ndarray) -> list[str]:
        """The supports (obstacles marked ``support``) ``part`` at world pose T (4x4) rests on:
        its lowest vertex within REST_TOL_MM of a support's highest and their footprints' boxes
        overlapping. A part lifted straight up off such a support, or set straight down onto
        it, touches it by design (as the table): callers allow that pair."""
        tol = from_mm(self.unit, REST_TOL_MM)
        P = np.concatenate([b.points for b in self.placed(part, T, WORLD)])
        low, lo, hi = P[:, 2].min(), P[:, :2].min(axis=0), P[:, :2].max(axis=0)
        out = []
        for o in self.obstacles:
            if not o.support:
                continue
            Q = np.concatenate([b.points for b in o.bodies])
            over = np.all(Q[:, :2].min(axis=0) <= hi) and np.all(lo <= Q[:, :2].max(axis=0))
            if over and abs(Q[:, 2].max() - low) <= tol:
                out.append(o.name)
        return out

    def gripper_bodies(self, width: float | None) -> list[Body]:
        """The palm and fingers (TOOL frame) with the fingers' contact faces ``width`` apart (default
        open), and the tool body behind the palm when the gripper has one (body "tool"), made once
        per width (a handful of widths per cell)."""
        key = None if width is None else round(float(width), 9)
        if key not in self._grippers:
            self._grippers[key] = ([box(n, TOOL, lo, hi) for n, lo, hi in self.gripper.boxes(width)]
                                   + self._tool_body(0.0))
        return self._grippers[key]

    def shrunk_gripper(self, width: float | None, tol: float) -> list[Body]:
        """The palm, fingers and tool body as :meth:`gripper_bodies`, each shrunk by ``tol`` on every
        side (the grasp rule's: touching counts as clear), made once per width and tolerance."""
        key = ("shrunk", None if width is None else round(float(width), 9), round(float(tol), 12))
        if key not in self._grippers:
            self._grippers[key] = ([box(n, TOOL, lo + tol, hi - tol) for n, lo, hi in self.gripper.boxes(width)]
                                   + self._tool_body(tol))
        return self._grippers[key]

    def enters_mesh(self, part: str, g: Body, T_tool_part: np.ndarray) -> bool:
        """Whether gripper body ``g`` (TOOL frame) meets ``part`` at T_tool_part (4x4): its mesh's
        surface (python-fcl's BVH against the body) or, wholly inside it, the body's centre in the
        mesh; True for a part without a mesh (its bodies are exact)."""
        import fcl  # lazily: see Body.fcl_geometry

        model = part.split("@", 1)[0]
        geo = self.meshes.get(model)
        if geo is None:
            return True
        mesh = geo.mesh()
        bvh = self._mesh_fcl.get(model)
        if bvh is None:
            V, F = np.asarray(mesh.vertices, float), np.asarray(mesh.faces, int)
            bvh = self._mesh_fcl[model] = fcl.BVHModel()
            bvh.beginModel(len(V), len(F))
            bvh.addSubModel(V, F)
            bvh.endModel()
        o1 = fcl.CollisionObject(g.fcl_geometry(), fcl_transform(g.T))
        o2 = fcl.CollisionObject(bvh, fcl_transform(np.asarray(T_tool_part, float)))
        if fcl.collide(o1, o2, fcl.CollisionRequest(), fcl.CollisionResult()):
            return True
        centre = np.linalg.inv(np.asarray(T_tool_part, float)) @ np.append(g.T[:3, 3], 1.0)
        return bool(mesh.contains(centre[None, :3])[0])

    def _tool_body(self, shrink: float) -> list[Body]:
        """The gripper's tool body (world.robot.Gripper.body_shape) as a body in the TOOL frame,
        shrunk by ``shrink`` on every side; [] without one."""
        shape = self.gripper.body_shape()
        if shape is None:
            return []
        name, kind, a, b, r = shape
        if kind == "cylinder":
            u = (b - a) / np.linalg.norm(b - a)
            return [cylinder(name, TOOL, a + shrink * u, b - shrink * u, r - shrink)]
        return [box(name, TOOL, a + shrink, b - shrink)]

    def shapes_of(self, part: str) -> list[Body]:
        """The bodies of ``part`` (an object, or a stock part ``obj@pos``) in its object frame."""
        model = part.split("@", 1)[0]
        if model not in self.parts:
            raise SparValueError(f"no shape known for part {part!r}")
        return self.parts[model]

    def shape_key(self, part: str) -> tuple:
        """The collision geometry of ``part`` (:meth:`shapes_of`: each body's kind, size, pose in
        the object frame and vertices, exactly), not its name: equal for renamed copies of one
        model, so answers that depend on the geometry alone can be shared by them."""
        model = part.split("@", 1)[0]
        key = self._shape_keys.get(model)
        if key is None:
            key = self._shape_keys[model] = tuple(
                (b.kind, np.asarray(b.size, float).tobytes(), np.ascontiguousarray(b.T, float).tobytes(),
                 np.ascontiguousarray(b.points, float).tobytes()) for b in self.shapes_of(part))
        return key

    def placed(self, part: str, T: np.ndarray, frame: int, name: str | None = None) -> Placed:
        """The bodies of ``part`` (:meth:`shapes_of`) moved by T (4x4, the part's pose in
        ``frame``: the world or the tool) and named ``name`` (default the part's), memoised on
        the cell by (part, name, frame, pose): the same Body objects each time (read-only)."""
        T = np.ascontiguousarray(T, dtype=float)
        label = part if name is None else name

        def place() -> Placed:
            return Placed(b.placed(T, frame, label) for b in self.shapes_of(part))

        if self.memo is None:
            return place()
        table = self.memo.table("collision.placed", PLACED_LIMIT)
        return table.get_or_compute((part, label, frame, T.tobytes()), place)

    def at(self, parts: Mapping[str, np.ndarray], held: tuple[str, np.ndarray] | None = None,
           grasped: str | None = None, *, width: float | None = None,
           allow: Iterable[tuple[str, str]] = (), attached: Mapping[str, np.ndarray] | None = None,
           carried: Mapping[str, np.ndarray] | None = None, touch: Iterable[str] = ()) -> SceneState:
        """The world at one point of a plan: ``parts`` = {name: T_world_part 4x4} for every part
        on the table or assembled; ``held`` = (name, T_tool_part) for the part in the hand (it
        moves with the gripper, body name "held:<name>"); ``grasped`` = the part the fingers are
        closing on (its contact with the fingers' contact faces is allowed: the grasp rule).

        Added: ``width`` the fingers' contact faces' distance (cell unit; default the open
        finger separation, or with a part in the hand the rule's own); ``allow`` pairs of body
        names not checked at this point (the step's own contacts: ("held:peg", "block") at an
        assemble, ("held:peg", "table") at a put-down); ``attached`` = {name: T_tool_part}
        parts that are where the tool is (a batch of tool poses with one relative geometry,
        e.g. the part being grasped at every candidate placement), checked as ``parts``;
        ``carried`` = {name: T_tool_part} the parts mated into the held part (a subassembly in
        the hand: one rigid body), bodies "held:<name>" moving with the tool and checked as the
        held part is, except against the gripper (by distance: the fingers may not touch a part
        they do not hold) and against each other (their contacts are the mates'; the caller
        allows none of them: at() does, and gives each carried part the contacts ``allow`` gives
        the held part). ``touch``: bodies checked against the table for contact only, not by the
        margin, up to GRASP_TOL_MM of rounding (a part the product seats on the table or within
        the margin of it: a post's end flush with the bottom of the bar it stands in)."""
        held_name = held[0] if held is not None else None
        if carried and held_name is not None:
            allow = _body_allow(held_name, list(carried), list(allow))
        if self._obstacle_bodies is None:
            self._obstacle_bodies = Placed(b for o in self.obstacles for b in o.bodies)
        groups: list[Placed] = [self._obstacle_bodies]
        table = self.memo.table("collision.placed", PLACED_LIMIT) if self.memo is not None else None
        for name, T in parts.items():  # placed() inlined: the table looked up once, a hit read directly
            if name == held_name or carried and name in carried:
                continue
            T = np.ascontiguousarray(T, dtype=float)
            g = table.get((name, name, WORLD, T.tobytes())) if table is not None else None
            groups.append(g if g is not None else self.placed(name, T, WORLD))
        world: list[Body] = [b for g in groups for b in g]
        tool: list[Body] = []
        for name, T in (attached or {}).items():
            tool += self.placed(name, T, TOOL)
        if held is not None:
            tool += self.placed(held[0], held[1], TOOL, f"held:{held[0]}")
        for name, T in (carried or {}).items():
            tool += self.placed(name, np.ascontiguousarray(T, dtype=float), TOOL, f"held:{name}")
        hand = None
        if held is not None:
            hand = (held[0], "tool", np.asarray(held[1], float))
        elif grasped is not None:
            if attached and grasped in attached:
                hand = (grasped, "tool", np.asarray(attached[grasped], float))
            elif grasped in parts:
                hand = (grasped, "world", np.asarray(parts[grasped], float))
            else:
                raise SparValueError(f"grasped part {grasped!r} is neither in parts nor attached")
        state = SceneState(self, world, tool, hand, width, frozenset(frozenset(p) for p in allow),
                           frozenset(attached or ()), group_columns(groups))
        touch = frozenset(touch)
        if touch:
            state.table_touch = np.array([state.bodies[i].name in touch for i in state.table_bodies.tolist()],
                                         dtype=bool)
        return state


def _body_allow(root: str, carried: list[str], allow: list[tuple[str, str]]) -> list[tuple[str, str]]:
    """``allow`` for a held body (``root`` in the hand carrying ``carried``): its parts' contacts
    with each other (their mates') and, for each carried part, the contacts allowed to the root."""
    mine = f"held:{root}"
    out = list(allow)
    for a, b in allow:
        other = b if a == mine else a if b == mine else None
        if other is not None:
            out += [(f"held:{c}", other) for c in carried]
    names = [mine, *(f"held:{c}" for c in carried)]
    out += [(x, y) for i, x in enumerate(names) for y in names[i + 1:]]
    return out


def scene_for(cell: Cell, memo: Any = None) -> CollisionScene:
    """A new collision scene of ``cell``: robot link and gripper shapes, part shapes, obstacles,
    the table; the clearance margin (cell's length unit). ``memo`` (core.memo.Memo) keeps the
    scene's derived answers; a planning run's scene is its cell cache's (world.run.CellCache.scene)."""
    robot = cell.robot
    gripper = gripper_for(cell)
    margin = getattr(cell, "clearance", None)
    if margin is None:
        margin = robot.margin if robot.margin is not None else from_mm(cell.unit, DEFAULT_MARGIN_MM)
    parts = _part_bodies(cell.objects, cell.unit)
    scene = CollisionScene(robot, gripper, parts, getattr(cell, "obstacles", ()), margin,
                           getattr(cell, "table", None), cell.unit, memo, _part_meshes(cell.objects))
    return scene


def _part_meshes(objects: Mapping[str, Any]) -> dict[str, Any]:
    """{name: its world.parts.mesh.Geometry} of the objects given by a mesh file (their shape is its
    convex hull); the mesh (object frame) is read on first use (Geometry.mesh())."""
    out = {}
    for name, m in objects.items():
        geo = getattr(m, "geometry", None)
        if geo is not None and getattr(geo, "mesh_file", None) is not None:
            out[name] = geo
    return out


def solids_key(solids: Iterable[Solid]) -> tuple:
    """What bodies made from an object's ``shape:`` solids depend on: the primitives, exactly (not
    the object's name)."""
    return tuple(s.key() for s in solids)


def _part_bodies(objects: Mapping[str, Any], unit: str) -> dict[str, list[Body]]:
    """Each object's :func:`solid_bodies` (a mesh part's: its :func:`mesh_body`), made once per
    distinct shape: the objects of one shape (generated cells: N copies of one peg and one block)
    get copies renamed, sharing the arrays and the library's geometry (bodies are read-only)."""
    made: dict[tuple, list[Body]] = {}
    out: dict[str, list[Body]] = {}
    meshes = _part_meshes(objects)
    for name, m in objects.items():
        geo = meshes.get(name)
        key = solids_key(m.shape) + (((str(geo.mesh_file), float(geo.scale)),) if geo is not None else ())
        first = made.get(key)
        if first is None:
            if geo is not None and len(m.shape) == 1 and m.shape[0].kind == "hull":
                made[key] = [mesh_body(name, WORLD, m.shape[0].points, geo, unit)]
            else:
                made[key] = solid_bodies(name, m.shape)
            out[name] = made[key]
        else:
            out[name] = [replace(b, name=name) for b in first]
    return out
