"""`spar plan --html FILE` and `spar view PLAN.json`: the plan in 3-D, one HTML page that works offline.

The page (viewer.html beside this module, three.js vendored under vendor/three/) draws
what this module computes; it never recomputes kinematics. :func:`viewer_data` reads the
plan JSON and the cell and gives the page, as data:

- meshes, each in its own frame: every part's (its mesh, or its shape's primitives), every
  arm collision body's (world.collision.scene: the robot file's link shapes in their Craig frame
  0..6, the gripper's palm and fingers in the tool frame, one set per finger opening), the
  obstacles' (world frame);
- states: the initial one (the arm at home when the plan or the cell gives one) and one per
  step of the instance: each part's pose, the arm's 8 world frames (``robot.frames(q)``),
  the held part, the finger opening, the parts' position uncertainty (each part's bounds as
  phase 2 propagated them to the step, the plan JSON's ``position_bounds``; before the plan,
  the cell's declared bounds);
- per step: its verdicts (the instance's constraints that serve it), clearance and closest
  pair, the insertion check's tolerance at the hole's mouth (assemble), and its motions
  (``path``, ``approach``, ``retreat``: waypoints sampled to at most MAX_WAYPOINTS each,
  the arm's frames and the held part's pose at each, and their times in seconds);
- the partial order (the partial plan's actions and prior_to pairs) and the table.

Frames and units: world Z up, table top z = 0, 4x4 poses ``T_world_x`` with column vectors,
sent row-major (16 numbers); lengths in the cell's unit (``cell.unit``, which the page
states), angles in degrees in the JSON (radians inside), times in seconds.
"""
from __future__ import annotations

import base64
import json
import math
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from spar_py.core.errors import SparValueError
from spar_py.core.model import Solid
from spar_py.core.units import from_mm
from spar_py.pictures.cell import OBJECT_COLOURS, body_faces, hole_mouth, obstacle_shapes, solid_faces
from spar_py.pictures.plandoc import instance, is_plan, partial, pretty_term
from spar_py.pictures.scene import Scene, held_grasp, part_model, scenes
from spar_py.world.collision import TOOL, scene_for
from spar_py.world.motion import interval_seconds
from spar_py.world.parts import part_mesh

if TYPE_CHECKING:
    from spar_py.core.model import Bounds, Cell, ObjectModel
    from spar_py.planning.planner import Plan

__all__ = ["MAX_WAYPOINTS", "ViewerPage", "render_html", "viewer_data", "write_viewer"]

#: At most this many waypoints of each motion segment are sent to the page (evenly sampled,
#: the first and last always): the JSON's paths run at a fraction of a degree per waypoint.
MAX_WAYPOINTS = 48
#: Digits kept of every number sent to the page (lengths in the cell unit, matrix entries).
DIGITS = 5
#: Width (mm) of the cube a part without a shape is drawn as.
MARKER_MM = 10.0
#: Joint pace (rad/s) the page plays a motion at when the robot gives no velocity limits.
DEFAULT_PACE = 1.0
HERE = Path(__file__).parent
TEMPLATE = HERE / "viewer.html"
VENDOR = HERE / "vendor" / "three"
#: The vendored three.js files, inlined in the page in this order (see vendor/three/README.md).
THREE_FILES = ("three.core.min.js", "three.module.min.js", "OrbitControls.js")


@dataclass(frozen=True)
class ViewerPage:
    """A written viewer page: its path, its number of steps and of parts drawn, its size in bytes."""

    path: Path
    steps: int
    parts: int
    size: int


# =========================================================================== meshes


def _b64(a: np.ndarray, dtype: str) -> str:
    return base64.b64encode(np.ascontiguousarray(a, dtype=dtype).tobytes()).decode("ascii")


def _triangles(faces: Sequence[np.ndarray]) -> np.ndarray:
    """Triangles (n, 3, 3) of convex polygons (each (m, 3), in order round the face), as fans."""
    tris = [np.array([f[0], f[i], f[i + 1]]) for f in faces if len(f) >= 3 for i in range(1, len(f) - 1)]
    return np.array(tris, float).reshape(-1, 3, 3)


def _mesh(tris: np.ndarray) -> dict[str, Any]:
    """A mesh for the page: its triangles' corners as base64 float32 (x, y, z per corner)."""
    return {"positions": _b64(np.asarray(tris, float).reshape(-1), "<f4"), "triangles": int(len(tris))}


def part_triangles(model: ObjectModel, unit: str) -> np.ndarray:
    """A part's triangles (n, 3, 3) in its object frame (``unit``, the cell's): its mesh
    (world.parts.mesh.part_mesh) when it has ``mesh:`` or ``shape:``, else its primitives' faces; a
    part without a shape is drawn as a cube MARKER_MM wide about its origin."""
    mesh = part_mesh(model) if model.geometry is not None else None
    if mesh is not None:
        return np.asarray(mesh.vertices, float)[np.asarray(mesh.faces)]
    solids = list(model.shape)
    if not solids:
        h = from_mm(unit, MARKER_MM) / 2
        solids = [Solid("box", np.full(3, -h), np.full(3, h))]
    return _triangles([f for s in solids for f in solid_faces(s, np.eye(4), 32)])


def _body_triangles(body: Any) -> np.ndarray:
    """A collision body's triangles (n, 3, 3) in its frame (pictures.cell.body_faces at the identity)."""
    faces, _ = body_faces(body, np.eye(4))
    return _triangles(faces)


# =========================================================================== states


def _r(x: Any) -> Any:
    """Numbers rounded to DIGITS decimals (nested lists), for a compact JSON."""
    return np.round(np.asarray(x, float), DIGITS).tolist()


def _flat(T: np.ndarray) -> list[float]:
    """A 4x4 pose as 16 numbers, row-major (three.js's Matrix4.set order)."""
    return _r(np.asarray(T, float).reshape(-1))


def _width(cell: Cell, held: str | None, grasp: str | None) -> float:
    """The fingers' opening (cell unit): the held grasp's width, else the open gripper's."""
    if held is not None and grasp is not None:
        return float(cell.objects[part_model(held)].grasps[grasp].width)
    return float(cell.finger_separation)


def _outward(lo: float, hi: float) -> list[float]:
    """[lo, hi] rounded to DIGITS decimals away from each other (the drawn box holds the bound)."""
    q = 10.0 ** DIGITS
    return [math.floor(lo * q) / q, math.ceil(hi * q) / q]


def _bounds_list(b: Bounds) -> list[float]:
    """Bounds as [dx0, dx1, dy0, dy1, dz0, dz1, dtheta0, dtheta1] (cell unit; dtheta in degrees),
    rounded outwards."""
    return [*_outward(*b.dx), *_outward(*b.dy), *_outward(*b.dz),
            *_outward(math.degrees(b.dtheta[0]), math.degrees(b.dtheta[1]))]


def _propagated(d: Mapping[str, Mapping[str, Sequence[float]]]) -> dict[str, list[float]]:
    """A step's ``position_bounds`` (the plan JSON: dx, dy, dz cell unit, dtheta_deg) as the
    page's lists per part key, rounded outwards."""
    return {str(k): [v for key in ("dx", "dy", "dz", "dtheta_deg") for v in _outward(*map(float, b[key]))]
            for k, b in d.items()}


def _home(cell: Cell, plan: Plan) -> np.ndarray | None:
    """The arm's rest configuration (rad): the plan's motion home, the cell's, the robot file's, or None."""
    motion = instance(plan).get("motion") or {}
    if motion.get("home_deg") is not None:
        return np.radians(np.asarray(motion["home_deg"], float))
    for q in (getattr(cell, "home", None), getattr(cell.robot, "home", None)):
        if q is not None:
            return np.asarray(q, float)
    return None


class _Widths:
    """The finger openings the page draws a gripper for (cell unit), by index."""

    def __init__(self) -> None:
        self.values: list[float] = []

    def index(self, w: float) -> int:
        for k, v in enumerate(self.values):
            if abs(v - w) <= 1e-9 * max(1.0, abs(w)):
                return k
        self.values.append(w)
        return len(self.values) - 1


def _state(cell: Cell, s: Scene, q: np.ndarray | None, widths: _Widths,
           bounds: Mapping[str, list[float]], propagated: bool) -> dict[str, Any]:
    """One state for the page: part poses, arm frames (None: no arm drawn but the pedestal), held part,
    gripper opening index, position uncertainty per part key (``bounds``: as phase 2 propagated it
    to this state when ``propagated``, else the cell's declared bounds)."""
    frames = None if q is None else cell.robot.frames(np.asarray(q, float))
    return {"parts": {k: _flat(T) for k, T in s.poses.items()},
            "frames": None if frames is None else [_flat(F) for F in frames],
            "held": s.held, "grasp": s.grasp, "gripper": widths.index(_width(cell, s.held, s.grasp)),
            "uncertainty": {k: bounds[k] for k in s.poses if k in bounds},
            "uncertainty_from": "propagated" if propagated else "declared"}


def _sample(k: int, n: int = MAX_WAYPOINTS) -> np.ndarray:
    """The indices of at most ``n`` of ``k`` waypoints, evenly spread, the first and last kept."""
    return np.unique(np.linspace(0, k - 1, min(n, k)).round().astype(int))


def _times(q: np.ndarray, velocity: np.ndarray | None) -> np.ndarray:
    """Seconds from the first waypoint to each of ``q`` (k, 6) rad at the joint velocity limits
    (world.motion.paths.interval_seconds), or DEFAULT_PACE."""
    if len(q) < 2:
        return np.zeros(len(q))
    v = np.full(6, DEFAULT_PACE) if velocity is None else velocity
    return np.concatenate([[0.0], np.cumsum(interval_seconds(q, v))])


def _segment(cell: Cell, kind: str, rows: Any, world: Scene, widths: _Widths,
             carried: Sequence[str] = ()) -> dict[str, Any] | None:
    """A motion segment for the page: its waypoints' times (s), arm frames, held part's pose (the
    tool carries it by its grasp) and the poses of ``carried``, the parts mated into it (they keep
    their pose relative to it), gripper opening; None without waypoints."""
    q_all = np.radians(np.asarray(rows or [], float)).reshape(-1, 6)
    if len(q_all) == 0:
        return None
    velocity = getattr(cell.robot, "velocity_limits", None)
    t_all = _times(q_all, velocity)
    keep = _sample(len(q_all))
    q, t = q_all[keep], t_all[keep]
    F = cell.robot.frames_batch(q)
    held_pose = None
    carried_pose: dict[str, list] = {}
    grasp = world.grasp
    if world.held is not None:
        grasp = grasp or held_grasp(cell, world.held, world.poses.get(world.held), world.tool)
        if grasp is not None:
            g_inv = np.linalg.inv(np.asarray(cell.objects[part_model(world.held)].grasps[grasp].T, float))
            held_pose = [_flat(Fk[7] @ g_inv) for Fk in F]
            at = np.linalg.inv(np.asarray(world.poses[world.held], float))
            rel = {c: at @ np.asarray(world.poses[c], float) for c in carried if c in world.poses and c != world.held}
            carried_pose = {c: [_flat(Fk[7] @ g_inv @ R) for Fk in F] for c, R in rel.items()}
    return {"kind": kind, "t": _r(t), "frames": [[_flat(T) for T in Fk] for Fk in F],
            "held": world.held if held_pose is not None else None, "held_pose": held_pose,
            "carried": carried_pose,
            "gripper": widths.index(_width(cell, world.held, grasp)), "waypoints": int(len(q_all))}


# =========================================================================== steps


def _verdicts(inst: Mapping[str, Any], step: Mapping[str, Any], sid: str) -> list[dict[str, Any]]:
    """The instance's constraints checked at step ``sid`` (an arm step; a sensing step has none)."""
    out = []
    if step.get("kind") == "sensing":
        return out
    for c in list(inst.get("constraints") or []) + list(inst.get("verifications") or []):
        if c.get("action") == sid:
            out.append({k: c.get(k) for k in ("constraint", "description", "kind", "bound", "sense", "threshold",
                                               "satisfied", "tolerance_reached", "mate", "power")})
    return out


def _tolerances(cell: Cell, step: Mapping[str, Any], verdicts: Sequence[Mapping[str, Any]],
                poses: Mapping[str, np.ndarray]) -> list[dict[str, Any]]:
    """The insertion checks of an assemble step, each drawn at its hole's mouth: the mouth's world
    centre and outward axis, the hole's radius, the tolerance R_h - R_p (the square root of the
    check's threshold) and the bound reached (the square root of its bound), cell unit, and the
    mate it checks. A product step has one per peg-hole mate it makes (the verdict names the
    mate: its hole part's hole feature); a plain cell's its goal hole's only hole."""
    args = step.get("args") or []
    if step.get("name") != "assemble" or len(args) < 2:
        return []
    out = []
    for check in verdicts:
        if not str(check.get("constraint", "")).startswith("centres") or check.get("threshold") is None:
            continue
        mate = next((m for m in (cell.product.mates if cell.product is not None else ())
                     if m.name == check.get("mate")), None)
        hole = mate.hole if mate is not None else str(args[1])
        model = cell.objects.get(hole)
        feature = model.feature_named(mate.hole_feature) if mate is not None and model is not None else None
        mouth = hole_mouth(cell, hole, feature)
        T = poses.get(hole)
        if mouth is None or T is None:
            continue
        T = np.asarray(T, float)
        c, n, radius = mouth
        out.append({"hole": hole, "mate": check.get("mate") or "", "centre": _r(T[:3, :3] @ c + T[:3, 3]),
                    "axis": _r(T[:3, :3] @ n), "hole_radius": radius,
                    "tolerance": math.sqrt(max(float(check["threshold"]), 0.0)),
                    "bound": math.sqrt(max(float(check["bound"]), 0.0)), "satisfied": bool(check.get("satisfied"))})
    return out


def _partial(plan: Plan) -> dict[str, Any]:
    """The partial order: the partial plan's actions (id, term) and its prior_to pairs (before, after)."""
    p = partial(plan)
    return {"actions": [{"id": a.get("id"), "term": pretty_term(str(a.get("term", "")))}
                        for a in p.get("actions") or []],
            "ordering": [[str(a), str(b)] for a, b in p.get("ordering") or []]}


def _focus(cell: Cell, part_tris: Mapping[str, np.ndarray], states: Sequence[Mapping[str, Any]],
           steps: Sequence[Mapping[str, Any]]) -> dict[str, Any]:
    """What the camera frames: every part at every state and the tool at each step (cell unit);
    and the side it looks from, away from the arm's base across the work."""
    pts = []
    for st in states:
        for k, flat in st["parts"].items():
            T = np.asarray(flat, float).reshape(4, 4)
            tri = part_tris.get(part_model(k))
            local = tri.reshape(-1, 3) if tri is not None and len(tri) else np.zeros((1, 3))
            pts.append(local @ T[:3, :3].T + T[:3, 3])
        if st["frames"] is not None and st is not states[0]:
            pts.append(np.asarray(st["frames"][7], float).reshape(4, 4)[:3, 3][None])
    for s in steps:
        for t in s.get("tolerances") or ():
            pts.append(np.asarray(t["centre"], float)[None])
    allp = np.vstack(pts) if pts else np.zeros((1, 3))
    lo, hi = allp.min(axis=0), allp.max(axis=0)
    centre = (lo + hi) / 2
    base = np.asarray(cell.robot.base, float)[:3, 3]
    away = centre[:2] - base[:2]
    away = away / np.linalg.norm(away) if np.linalg.norm(away) > 1e-9 else np.array([1.0, 0.0])
    return {"lo": _r(lo), "hi": _r(hi), "centre": _r(centre),
            "radius": float(max(np.linalg.norm(hi - lo) / 2, 1e-6)), "away": _r(away)}


def _table(cell: Cell, focus: Mapping[str, Any]) -> dict[str, Any]:
    """The table top at z = 0: the cell's ``table:`` extent, else the work's box padded by half its
    size and the arm's base (declared: false)."""
    if cell.table is not None:
        return {"extent": _r(cell.table), "declared": True}
    lo, hi = np.asarray(focus["lo"], float), np.asarray(focus["hi"], float)
    base = np.asarray(cell.robot.base, float)[:3, 3]
    pad = 0.5 * float(max(hi[:2] - lo[:2])) + 1e-6
    x0, x1 = min(lo[0] - pad, base[0] - pad), max(hi[0] + pad, base[0] + pad)
    y0, y1 = min(lo[1] - pad, base[1] - pad), max(hi[1] + pad, base[1] + pad)
    return {"extent": _r([x0, x1, y0, y1]), "declared": False}


def viewer_data(cell: Cell, plan: Plan) -> dict[str, Any]:
    """Everything the page draws, as JSON-ready data (see the module docstring). SparValueError
    (one line) if ``plan`` is not a plan (its outcome is not ``"plan"``) or its steps carry no poses."""
    if not is_plan(plan):
        raise SparValueError(f"expected a plan to view, not outcome {plan.outcome.value!r} (no steps to show)")
    inst = instance(plan)
    steps = list(inst.get("steps") or [])
    sc = scenes(cell, plan)
    widths = _Widths()
    part_tris = {name: part_triangles(m, cell.unit) for name, m in cell.objects.items()}
    colours = {name: OBJECT_COLOURS[k % len(OBJECT_COLOURS)] for k, name in enumerate(cell.objects)}

    declared = {o: _bounds_list(b) for o, b in cell.object_bounds.items()}  # by object model

    def per_part(by_model: Mapping[str, list[float]], keys: Any) -> dict[str, list[float]]:
        return {key: by_model[part_model(key)] for key in keys if part_model(key) in by_model}

    # before the plan every part has its declared bounds (phase 2's initial world); after a step,
    # what phase 2 propagated to it
    home = _home(cell, plan)
    states = [_state(cell, sc[0], home if home is not None else sc[0].q, widths, per_part(declared, sc[0].poses),
                     False)]
    states[0]["arm_note"] = "home" if home is not None or sc[0].q is not None else ""  # scenes: the arm at rest
    out_steps = []
    for k, step in enumerate(steps, start=1):
        s = sc[k]
        propagated = step.get("position_bounds") is not None
        if propagated:
            bounds = _propagated(step["position_bounds"])
        else:  # a plan JSON written without them: the declared bounds, a sensed object the sensor's
            if step.get("kind") == "sensing" and step.get("name") in cell.sensors and step.get("object"):
                declared = {**declared, str(step["object"]): _bounds_list(cell.sensors[str(step["name"])].leaves)}
            bounds = per_part(declared, s.poses)
        st = _state(cell, s, s.q if step.get("joints_deg") is not None else None, widths, bounds, propagated)
        if st["frames"] is None:  # a step without arm motion (sensing): the arm stays where it was
            st["frames"] = states[-1]["frames"]
            st["gripper"] = states[-1]["gripper"]
        states.append(st)
        sid = str(step.get("id", f"step_{k}"))
        verdicts = _verdicts(inst, step, sid)
        moves = [str(m) for m in (step.get("moves") or [])[1:]]
        segs = [_segment(cell, key, step.get(key), world, widths, moves)
                for key, world in (("path", sc[k - 1]), ("approach", sc[k - 1]), ("retreat", s))]
        out_steps.append({
            "id": sid, "name": step.get("name"), "kind": step.get("kind"), "object": step.get("object"),
            "term": pretty_term(str(step.get("term", ""))), "clearance": step.get("clearance"),
            "closest_pair": step.get("closest_pair"), "joints_deg": step.get("joints_deg"),
            "duration_s": step.get("duration_s"), "verdicts": verdicts,
            "tolerances": _tolerances(cell, step, verdicts, s.poses),
            "motion": [g for g in segs if g is not None]})
    home_seg = None
    motion = inst.get("motion") or {}
    if motion.get("home_path"):
        home_seg = _segment(cell, "home", motion["home_path"], sc[-1], widths)

    scene = scene_for(cell)
    meshes: dict[str, dict[str, Any]] = {}
    parts = []
    for key in sc[0].poses:
        model = part_model(key)
        if model not in cell.objects:
            continue
        meshes.setdefault(f"part:{model}", _mesh(part_tris[model]))
        parts.append({"key": key, "model": model, "mesh": f"part:{model}", "colour": colours[model]})
    links = []
    for b in scene.links:
        meshes[f"link:{b.name}"] = _mesh(_body_triangles(b))
        links.append({"name": b.name, "frame": 7 if b.frame == TOOL else int(b.frame), "mesh": f"link:{b.name}"})
    grippers = []
    for k, w in enumerate(widths.values):
        bodies = []
        for b in scene.gripper_bodies(w):
            meshes[f"gripper{k}:{b.name}"] = _mesh(_body_triangles(b))
            bodies.append({"name": b.name, "mesh": f"gripper{k}:{b.name}"})
        grippers.append({"width": w, "bodies": bodies})
    obstacles = []
    for sh in obstacle_shapes(cell):
        mid = f"{sh.gid}#{len(obstacles)}"
        meshes[mid] = _mesh(_triangles(sh.faces))
        obstacles.append({"name": sh.gid.split(":", 1)[-1], "mesh": mid})
    focus = _focus(cell, part_tris, states, out_steps)
    return {
        "problem": plan.problem, "unit": cell.unit, "robot": cell.robot.name,
        "base": _flat(cell.robot.base), "table": _table(cell, focus), "focus": focus,
        "meshes": meshes, "parts": parts, "links": links, "grippers": grippers, "obstacles": obstacles,
        "states": states, "steps": out_steps, "home_motion": home_seg, "partial": _partial(plan),
        "motion": {k: motion.get(k) for k in ("planner", "duration_s", "path_resolution_deg")} if motion else None,
        "hole_colour": "#1a1a1a",
    }


# =========================================================================== the page


def _script_text(text: str) -> str:
    """JavaScript or JSON text safe inside a <script> element: any ``</script`` (which can only be
    inside a string there) written ``<\\/script``, the same string to JavaScript and JSON."""
    return re.sub(r"</(script)", r"<\\/\1", text, flags=re.IGNORECASE)


def _page(cell: Cell, plan: Plan) -> tuple[str, dict[str, Any]]:
    """The viewer page's text and the data in it."""
    data = viewer_data(cell, plan)
    template = TEMPLATE.read_text(encoding="utf-8")
    libs = "\n".join(f'<script type="text/plain" id="lib:{name}">{_script_text((VENDOR / name).read_text("utf-8"))}'
                     "</script>" for name in THREE_FILES)
    title = f"spar-py viewer: {data['problem']}"
    fill = {"TITLE": title.replace("&", "&amp;").replace("<", "&lt;"), "LIBS": libs,
            "DATA": _script_text(json.dumps(data, separators=(",", ":"), allow_nan=False))}
    return re.sub(r"\{\{(TITLE|LIBS|DATA)\}\}", lambda m: fill[m.group(1)], template), data


def render_html(cell: Cell, plan: Plan) -> str:
    """The whole viewer page (one HTML document: three.js, the page's code and the plan's data inline)."""
    return _page(cell, plan)[0]


def write_viewer(cell: Cell, plan: Plan, path: str | Path) -> ViewerPage:
    """Write the viewer page of ``plan`` to ``path`` (the caller stages it: spar plan/view write it
    whole or not at all) and say what it holds."""
    text, data = _page(cell, plan)
    path = Path(path)
    path.write_bytes(text.encode("utf-8"))
    return ViewerPage(path, len(data["steps"]), len(data["parts"]), len(text.encode("utf-8")))
