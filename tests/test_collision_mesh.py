"""A placed concave mesh part collides as its mesh, not its convex hull: a box in the recess of
a U-shaped part is clear (the hull would cover it), a box pressed into the U's wall is not.
The geometry is checked independently by sampling the U's surface against the box."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import trimesh
from shapely.geometry import Polygon

from spar_py.core.units import from_mm
from spar_py.kb import load_problem
from spar_py.world.collision.bodies import WORLD, body_distance, box, convex, mesh_body
from spar_py.world.collision.scene import CollisionScene, scene_for

PROBLEMS = Path(__file__).resolve().parents[1] / "kb" / "problems"

#: The U (mm; scaled to the cell's unit): 100 wide (x), 60 deep (y), 40 high (z); a recess 40 wide, 40 deep.
U_OUTLINE = [(-50, 0), (50, 0), (50, 60), (20, 60), (20, 20), (-20, 20), (-20, 60), (-50, 60)]
HALF = 10.0  # the box's half extent


class _MeshGeometry:
    """A stand-in for world.parts.mesh.Geometry: the mesh, given."""

    def __init__(self, mesh: trimesh.Trimesh) -> None:
        self._mesh = mesh
        self.mesh_file, self.scale = "u", 1.0

    def mesh(self) -> trimesh.Trimesh:
        return self._mesh


def _u_mesh(s: float = 1.0) -> trimesh.Trimesh:
    """The U, lengths times ``s`` (cell unit per mm)."""
    u = trimesh.creation.extrude_polygon(Polygon(U_OUTLINE), 40.0)
    u.apply_scale(s)
    return u


def _scene(cell, u: trimesh.Trimesh) -> CollisionScene:
    s = from_mm(cell.unit, 1.0)
    base = scene_for(cell)
    parts = {"u": [mesh_body("u", WORLD, np.asarray(u.convex_hull.vertices), _MeshGeometry(u), cell.unit)],
             "blk": [box("blk", WORLD, -np.full(3, HALF * s), np.full(3, HALF * s))]}
    return CollisionScene(base.robot, base.gripper, parts, (), base.margin, None, cell.unit)


def _box_to_u(u: trimesh.Trimesh, centre: np.ndarray) -> float:
    """The least distance (mm) from the U's surface (dense samples; the U in mm) to the box at
    ``centre`` (U frame, mm, axis-aligned), negative when a sample is inside the box: analytic,
    not the library's."""
    pts, _ = trimesh.sample.sample_surface_even(u, 40000, seed=1)
    pts = np.vstack([pts, u.vertices])
    d = np.abs(pts - centre) - HALF
    outside = np.linalg.norm(np.maximum(d, 0.0), axis=1)
    inside = np.minimum(d.max(axis=1), 0.0)
    return float((outside + inside).min())


def _state_and_q(cell, scene: CollisionScene, centre: np.ndarray):
    """The box held by the tool 250 mm ahead of it, the U placed in the world so that the box
    is at ``centre`` (mm) of the U's frame; a joint vector with the tool level, above the table."""
    s = from_mm(cell.unit, 1.0)
    q = np.array([0.0, -0.5, 0.5, 0.0, -1.57, 0.0])
    F = scene.at({})._frames(q[None])[0]
    T_tool_box = np.eye(4)
    T_tool_box[2, 3] = 250.0 * s
    T_world_box = F[7] @ T_tool_box
    T_u_box = np.eye(4)
    T_u_box[:3, 3] = centre * s
    T_world_u = T_world_box @ np.linalg.inv(T_u_box)
    return scene.at({"u": T_world_u}, ("blk", T_tool_box)), q, T_world_u


def test_box_in_the_recess_of_a_u_is_clear_and_one_in_its_wall_collides() -> None:
    cell = load_problem(PROBLEMS / "peg_in_block.yaml")
    u = _u_mesh()
    assert u.is_watertight
    scene = _scene(cell, _u_mesh(from_mm(cell.unit, 1.0)))
    inside = np.array([0.0, 40.0, 20.0])          # the recess's middle: 10 mm from its walls
    assert _box_to_u(u, inside) > 5.0             # free by the samples
    assert u.convex_hull.contains(inside[None])[0]  # and the hull covers it
    state, q, T_world_u = _state_and_q(cell, scene, inside)
    assert T_world_u[2, 3] > from_mm(cell.unit, 60.0)  # above the table: the U is the only obstacle
    ok, why = state.check(q[None])
    assert ok[0], why
    # the hull would refuse it: the same scene with the U as its convex hull
    hull_scene = CollisionScene(scene.robot, scene.gripper,
                                {"u": [convex("u", WORLD, scene.parts["u"][0].points)],
                                 "blk": scene.parts["blk"]}, (), scene.margin, None, cell.unit)
    hs, _, _ = _state_and_q(cell, hull_scene, inside)
    ok_h, why_h = hs.check(q[None])
    assert not ok_h[0] and set(why_h[0]) == {"u", "held:blk"}
    # the box pressed 0.5 mm into the recess's wall (x = 20): colliding
    wall = np.array([20.0 - HALF + 0.5, 40.0, 20.0])
    assert _box_to_u(u, wall) < 0.0
    state, q, _ = _state_and_q(cell, scene, wall)
    ok, why = state.check(q[None])
    assert not ok[0] and set(why[0]) == {"u", "held:blk"}
    # within the margin (1 mm from the wall, margin 2 mm): colliding too, the margin's semantics
    near = np.array([20.0 - HALF - 1.0, 40.0, 20.0])
    assert 0.5 < _box_to_u(u, near) < scene.margin / from_mm(cell.unit, 1.0)
    state, q, _ = _state_and_q(cell, scene, near)
    ok, _ = state.check(q[None])
    assert not ok[0]


def test_a_box_wholly_inside_a_mesh_collides() -> None:
    """A BVH is a surface: the containment test catches a body meeting none of its triangles."""
    u = _u_mesh()
    m = mesh_body("u", WORLD, np.asarray(u.convex_hull.vertices), _MeshGeometry(u), "mm")
    small = box("s", WORLD, -np.full(3, 2.0), np.full(3, 2.0))
    T = np.eye(4)
    T[:3, 3] = [-35.0, 30.0, 20.0]  # in the U's left arm (x -50..-20), 13 mm from its faces
    assert u.contains(T[:3, 3][None])[0]
    assert body_distance(small, T, m, np.eye(4)) == 0.0
    assert body_distance(m, np.eye(4), small, T) == 0.0


def test_placed_copies_share_the_mesh_geometry_in_the_object_frame() -> None:
    """The library's geometry, made once by whichever copy asks first, is the part's own: a copy
    placed 100 mm away asking first must not move the original (a convex mesh: the hull branch)."""
    cube = trimesh.creation.box(extents=(20.0, 20.0, 20.0))
    m = mesh_body("c", WORLD, np.asarray(cube.vertices), _MeshGeometry(cube), "mm")
    T = np.eye(4)
    T[0, 3] = 100.0
    far = m.placed(T, WORLD)
    probe = box("p", WORLD, np.array([15.0, -5.0, -5.0]), np.array([25.0, 5.0, 5.0]))
    eye = np.eye(4)
    assert body_distance(far, eye, probe, eye) > 60.0   # asked first: 75 mm apart
    assert abs(body_distance(m, eye, probe, eye) - 5.0) < 1e-6  # the cube's face x = 10, the probe's 15
