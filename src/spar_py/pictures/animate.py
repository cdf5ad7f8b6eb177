"""`spar plan --animate FILE.gif`: the whole plan replayed from its motions.

Read from the plan JSON, not recomputed: each step's ``path``, ``approach`` and
``retreat`` (waypoints in degrees, world/motion/paths.py) give the arm's joints frame by frame
(the travel home after the last step, ``motion.home_path``, is left out: it shows no work);
the parts stand where the step before left them (``poses``), the held part moves with the tool
(its grasp). Each frame is the cell
pictures' 3-D panel (pictures/cell.py: table, parts, the arm's skeleton and gripper), the
arm's link geometry (the collision scene's bodies, world/collision/scene.py: the robot file's
link capsules, cylinders and boxes, and the gripper's palm and fingers at the frame's
opening, drawn as their hulls at the frame's joints) and the cell's obstacles, within a view
of the work (:func:`work_extent`: the parts and the tool's working path over them, the
approach and retreat lines, not the transit from and to home nor the whole arm) that fills
the frame (:func:`_fit`; the axes are not drawn, a line under the picture states what is
framed, in the cell's unit). One figure and one 3-D axes serve every frame: only the artists of the
parts and the arm are replaced.

Units: the cell's length unit, joints in degrees in the JSON (radians inside).
"""
from __future__ import annotations

from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from spar_py.core.errors import SparValueError
from spar_py.core.model import Cell
from spar_py.pictures.cell import Extent, draw_3d, finger_length, part_points, table_extent, extent
from spar_py.pictures.plandoc import instance
from spar_py.pictures.scene import Scene, held_grasp, part_model, scenes
from spar_py.world.collision import TOOL, CollisionScene, scene_for

if TYPE_CHECKING:
    from spar_py.planning.planner import Plan

__all__ = ["arm_faces", "frames_of", "obstacle_faces", "work_extent", "write_animation"]

#: At most this many frames in a GIF (waypoints are sampled evenly beyond it).
MAX_FRAMES = 60
#: Milliseconds per frame.
FRAME_MS = 100
#: The GIF's size (inches) and resolution (dots per inch): 480 x 480 px.
FIGSIZE_IN, DPI = 6.0, 80
#: Points per circle of a capsule's drawn hull (its end spheres sampled on a grid of
#: this many longitudes and half as many latitudes).
CAPSULE_SIDES = 12
#: Colour of the link geometry.
LINK_COLOUR = "#c8a040"
#: The work box is padded on every side by this many times the largest part's bounding radius.
WORK_PAD_SIZES = 0.5
#: The work box's picture fills the frame but for this margin (figure fraction) on each side,
#: with room kept at the top for the caption and at the bottom for the line stating the box.
MARGIN, TOP, BOTTOM = 0.02, 0.05, 0.04


def _tool_points(cell: Cell, steps: list[dict[str, Any]]) -> np.ndarray:
    """The tool's working path (k, 3), world, cell unit: the tool point and the gripper's palm
    (a finger length behind it) at each step's end-point and along its approach and retreat
    lines (the straight motions over the parts; the transit paths between them are left out)."""
    pts = []
    for st in steps:
        rows = [st.get("joints_deg")] if st.get("joints_deg") is not None else []
        rows += list(st.get("approach") or []) + list(st.get("retreat") or [])
        for q in np.radians(np.asarray(rows, float)).reshape(-1, 6):
            T = cell.robot.frames(q)[-1]
            pts += [T[:3, 3], T[:3, :3] @ [0.0, 0.0, -finger_length(cell)] + T[:3, 3]]
    return np.array(pts, float).reshape(-1, 3)


def _work_points(cell: Cell, plan: Plan) -> np.ndarray:
    """What the animation shows (k, 3), world, cell unit: the parts' points in every scene and
    the tool's working path (:func:`_tool_points`)."""
    steps = list(instance(plan).get("steps") or [])
    allp = np.vstack(part_points(cell, scenes(cell, plan)) + [_tool_points(cell, steps)])
    if not len(allp):
        raise SparValueError("the plan has no parts and no tool path to frame")
    return allp


def work_extent(cell: Cell, plan: Plan, work: np.ndarray | None = None) -> Extent:
    """The 3-D axes' box (cell unit), which only clips: the work (``work``, else
    :func:`_work_points`) padded by WORK_PAD_SIZES part sizes, joined with the cell pictures'
    view (pictures/cell.py ``extent``: the parts, the obstacles, the arm's reach over them), so
    the arm above the work and an obstacle beside it are drawn where the frame (fitted to the
    work, :func:`_fit`) shows them."""
    allp = _work_points(cell, plan) if work is None else work
    size = max((m.bounding_radius() for m in cell.objects.values()), default=0.0)
    pad = max(WORK_PAD_SIZES * size, 1e-3 * float(np.ptp(allp, axis=0).max()), 1e-9)
    view = extent(cell, scenes(cell, plan))
    lo = np.minimum(np.append(allp.min(axis=0)[:2] - pad, min(0.0, float(allp[:, 2].min()))), view.lo)
    hi = np.maximum(allp.max(axis=0) + pad, view.hi)
    return Extent(table_extent(cell, lo, hi), lo, hi)


def _fit(fig: Any, ax: Any, pts: np.ndarray) -> None:
    """Move and scale the 3-D axes (its projection scales with it) so that the picture of the
    points ``pts`` (k, 3; the work, :func:`_work_points`) fills the figure but for the margins,
    centred; its own axes, ticks and panes are not drawn (they would be cut off)."""
    from mpl_toolkits.mplot3d import proj3d

    ax.set_axis_off()
    px, py, _ = proj3d.proj_transform(pts[:, 0], pts[:, 1], pts[:, 2], ax.get_proj())
    disp = ax.transData.transform(np.column_stack([px, py]))
    f = fig.transFigure.inverted().transform(disp)  # figure fraction
    pos = ax.get_position()
    u = (f - [pos.x0, pos.y0]) / [pos.width, pos.height]  # axes fraction: unchanged by a uniform scaling
    width, height = 1 - 2 * MARGIN, 1 - TOP - BOTTOM
    k = min(width / max(np.ptp(f[:, 0]), 1e-9), height / max(np.ptp(f[:, 1]), 1e-9))
    w, h = pos.width * k, pos.height * k
    uc = (u.min(axis=0) + u.max(axis=0)) / 2
    ax.set_position((0.5 - w * uc[0], BOTTOM + height / 2 - h * uc[1], w, h))


def frames_of(cell: Cell, plan: Plan, max_frames: int = MAX_FRAMES) -> list[Scene]:
    """The scenes of the animation: for each arm step, its path, approach and retreat
    waypoints in the world before (path, approach) and after (retreat) the step (not the
    path home after the last step); sampled evenly to at most ``max_frames``. SparValueError if the plan has
    no motions (planned with --no-motion)."""
    inst = instance(plan)
    motion = inst.get("motion")
    if not motion:
        raise SparValueError("the plan has no motions to animate (it was planned with --no-motion)")
    steps = list(inst.get("steps") or [])
    sc = scenes(cell, plan)
    seq: list[tuple[Scene, np.ndarray, str, tuple[str, ...]]] = []  # (world scene, q rad, caption, carried)
    for k, st in enumerate(steps, start=1):
        before, after = sc[k - 1], sc[k]
        carried = tuple(str(c) for c in (st.get("moves") or [])[1:])  # mated into the part the step moves
        for key, world in (("path", before), ("approach", before), ("retreat", after)):
            for q in np.radians(np.asarray(st.get(key) or [], float)).reshape(-1, 6):
                seq.append((world, q, f"{st['id']}: {key} ({st['term']})", carried))
    if not seq:
        raise SparValueError("the plan's motions have no waypoints")
    pick = np.unique(np.linspace(0, len(seq) - 1, min(max_frames, len(seq))).round().astype(int))
    out = []
    for i in pick:
        world, q, caption, carried = seq[i]
        out.append(_at(cell, world, q, caption, int(i), carried))
    return out


def _at(cell: Cell, world: Scene, q: np.ndarray, caption: str, index: int, carried: tuple[str, ...] = ()) -> Scene:
    """``world`` with the arm at ``q`` and the held part carried by the tool, with ``carried``, the
    parts mated into it (a subassembly), where they are relative to it."""
    F = cell.robot.frames(q)
    poses = dict(world.poses)
    grasp = world.grasp
    if world.held is not None:
        grasp = grasp or held_grasp(cell, world.held, poses.get(world.held), world.tool)
        if grasp is not None:
            g = cell.objects[part_model(world.held)].grasps[grasp]
            old = np.asarray(poses[world.held], float)
            poses[world.held] = F[-1] @ np.linalg.inv(np.asarray(g.T, float))
            moved = poses[world.held] @ np.linalg.inv(old)
            for c in carried:
                if c in poses and c != world.held:
                    poses[c] = moved @ np.asarray(poses[c], float)
    return replace(world, index=index, title=caption, detail="", poses=poses, grasp=grasp, q=q, frames=F,
                   arm_note="")


def _local_points(body: Any) -> np.ndarray:
    """Points (k, 3), in the body's frame, whose hull is the drawn body: a capsule's two end
    spheres (sampled), a cylinder's circumscribed prism, a box's corners, a hull's vertices."""
    if body.kind != "capsule":
        return np.asarray(body.points, float)
    r = body.size[0]
    lon = np.linspace(0, 2 * np.pi, CAPSULE_SIDES, endpoint=False)
    lat = np.linspace(-np.pi / 2, np.pi / 2, CAPSULE_SIDES // 2 + 1)
    sphere = np.array([[np.cos(b) * np.cos(a), np.cos(b) * np.sin(a), np.sin(b)] for b in lat for a in lon]) * r
    return np.vstack([c + sphere for c in np.asarray(body.points, float)])


def arm_faces(cell: Cell, q: np.ndarray, width: float | None = None, scene: CollisionScene | None = None,
              hulls: dict | None = None) -> list[tuple[str, list[np.ndarray]]]:
    """The arm's link geometry at joints ``q`` (6,) rad: per collision body (the robot file's
    links, then the gripper's palm and fingers with their contact faces ``width`` apart, None:
    open), its name and its hull's triangles (each (3, 3) world points, cell unit). ``scene``
    the cell's collision scene and ``hulls`` each body's hull in its own frame, when the caller
    keeps them for many frames (bounded by the arm's bodies and the grasp widths)."""
    from scipy.spatial import ConvexHull  # only when a GIF is drawn

    scene = scene if scene is not None else scene_for(cell)
    F = cell.robot.frames(np.asarray(q, float))
    table = hulls if hulls is not None else {}
    out = []
    for b in list(scene.links) + list(scene.gripper_bodies(width)):
        key = (b.name, b.frame, np.asarray(b.points).tobytes())
        if key not in table:
            pts = _local_points(b)
            table[key] = (pts, ConvexHull(pts).simplices)
        pts, tri = table[key]
        T = F[7] if b.frame == TOOL else F[b.frame]
        world = pts @ T[:3, :3].T + T[:3, 3]
        out.append((b.name, [world[t] for t in tri]))
    return out


def obstacle_faces(cell: Cell) -> list[np.ndarray]:
    """Triangles (each (3, 3) world points, cell unit) of the hulls of the cell's obstacle
    bodies (world.collision.Obstacle, world/collision/bodies.py: a body's vertices in the world)."""
    from scipy.spatial import ConvexHull  # only when a GIF is drawn

    faces = []
    for ob in getattr(cell, "obstacles", None) or ():
        for b in getattr(ob, "bodies", ()):
            pts = np.asarray(b.points, float)
            if len(pts) >= 4:
                faces += [pts[t] for t in ConvexHull(pts).simplices]
    return faces


def _width(cell: Cell, s: Scene) -> float | None:
    """The fingers' opening in scene ``s``: the held part's grasp width, else None (open)."""
    if s.held is not None and s.grasp is not None:
        return float(cell.objects[part_model(s.held)].grasps[s.grasp].width)
    return None


def write_animation(cell: Cell, plan: Plan, path: str | Path, max_frames: int = MAX_FRAMES) -> Path:
    """Write the GIF of the plan's motions to ``path`` (Pillow writer); returns the path. The
    view is the work's (:func:`work_extent`), filling the frame (:func:`_fit`); each frame
    replaces the previous frame's artists in one reused 3-D axes."""
    import matplotlib  # only when a GIF is drawn; Agg is chosen before pyplot loads

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.animation import PillowWriter
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection

    frames = frames_of(cell, plan, max_frames)
    scene, hulls = scene_for(cell), {}  # one scene and one hull per body for every frame
    obstacles = obstacle_faces(cell)
    work = _work_points(cell, plan)
    fr = work_extent(cell, plan, work)
    fig = plt.figure(figsize=(FIGSIZE_IN, FIGSIZE_IN), dpi=DPI)
    ax = fig.add_axes((0.02, 0.05, 0.94, 0.89), projection="3d")
    draw_3d(ax, cell, frames[0], fr)  # the view (limits, box, angle) is every frame's
    _fit(fig, ax, work)
    title = fig.text(0.5, 0.98, "", ha="center", va="top", fontsize=8)
    (x0, y0, z0), (x1, y1, z1) = work.min(axis=0), work.max(axis=0)
    fig.text(0.5, 0.01, f"framed: the parts and the tool's work, x {x0:.4g}..{x1:.4g}, y {y0:.4g}..{y1:.4g}, "
             f"z {z0:.4g}..{z1:.4g} {cell.unit}", ha="center", va="bottom", fontsize=7, color="#555555")
    writer = PillowWriter(fps=max(1, round(1000 / FRAME_MS)))
    path = Path(path)
    try:
        with writer.saving(fig, str(path), dpi=DPI):
            for s in frames:
                for artist in list(ax.collections) + list(ax.lines):
                    artist.remove()
                draw_3d(ax, cell, s, fr)
                if obstacles:
                    ax.add_collection3d(Poly3DCollection(obstacles, facecolor="#9a9a9a", alpha=0.45,
                                                         edgecolor="none", axlim_clip=True), autolim=False)
                if s.q is not None:
                    links = [t for _, tris in arm_faces(cell, s.q, _width(cell, s), scene, hulls) for t in tris]
                    ax.add_collection3d(Poly3DCollection(links, facecolor=LINK_COLOUR, alpha=0.55,
                                                         edgecolor="none", zorder=4, axlim_clip=True),
                                        autolim=False)
                title.set_text(s.title)
                writer.grab_frame()
    finally:
        plt.close(fig)
    return path
