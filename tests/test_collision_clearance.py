"""Every step of every regression plan is clear of the table, the obstacles and the other parts
by the cell's margin (issue 15's first must-show), checked here on its own.

Nothing of spar_py's geometry is used: the robot, object and problem YAML files are read with
PyYAML; the arm's frames come from our own forward kinematics of the robot file's DH table
(Craig's modified convention, or standard DH for ``convention: standard``); each link's
collision shape is placed in its frame from the YAML; the gripper's boxes are built from the
robot file's ``gripper:`` sizes (docs/kb-format.md, defaults written out below); the distances
are our own analytic signed distance functions (SDFs) of boxes, cylinders, capsules, convex
hulls and the table half-space. A URDF arm (a problem's ``robot: {urdf: ...}``) is read with
yourdfpy instead: its own FK places each link, and each ``<collision>`` element (cylinder,
sphere, box; a mesh as the convex hull of its vertices, read with trimesh) is placed from the
URDF's origins, with no spar_py conversion to DH in between. From the planner only the plan JSON is read (each step's
``joints_deg``, ``tool_pose``, ``poses``, ``held``, ``moves``: a subassembly's parts go with the tool,
``args``), and from the KB loader only grasp
widths (data, for the fingers' opening).

How a distance is bounded (a certificate, not a guess): the surface of each moving body (link,
finger, palm, held part) is cut into patches, each with a centre point on the surface and a
covering radius h (every point of the patch within h of the centre); a capsule is its axis
segment cut into intervals, its radius subtracted. An SDF is 1-Lipschitz, so the distance of
the patch to the other body is at least SDF(centre) - h, and at most SDF(centre) (a point of
the surface at that distance exists). Patches start at h <= H0_MM and those whose lower bound
is under margin - TOL_MM are split in four (two for a segment) until every patch is certified
(lower bound >= margin - TOL_MM, i.e. the final sampling spacing is subtracted as a tolerance)
or a centre itself is closer than that (a collision, certain for exact SDFs). A body entirely
inside the moving one is caught by testing the other body's centre against the moving body's
own SDF. Convex hulls (mesh parts) use the largest face-plane distance: exact inside, a lower
bound outside, so their clearances err on the safe side.

Pairs checked at a step's end-point (as issue 15 states them): the arm's links (frames 1..6),
the palm and fingers and the part in the hand against the table, every obstacle and every part
where the step's ``poses`` put it; and the arm against itself: links two or more frames apart
(the static pedestal, frame 0, against links 2..6), the gripper against links 0..5, the part in
the hand against links 0..6. Not checked, being the step's own contacts: the gripper and
the part the fingers hold (pickup, put-down, assemble, squeeze); that part and the table at a
put-down; that part and the part it is inserted into at an assemble; the robot file's
``collision: allow`` pairs; the static pedestal against the world.
"""
from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml

from paths import ROOT

PROBLEMS = ROOT / "kb" / "problems"

#: Millimetres per length unit of the KB files.
MM = {"mm": 1.0, "cm": 10.0, "m": 1000.0, "in": 25.4}
#: The margin when neither the problem (``clearance``) nor the robot (``collision: margin``) gives one.
DEFAULT_MARGIN_MM = 2.0
#: Initial covering radius of a surface patch (mm).
H0_MM = 20.0
#: Certified to within this (mm): the final sampling spacing subtracted from the sampled distance.
TOL_MM = 0.01
#: A mesh body's exact distance is computed for points its hull's bound puts nearer than this (mm).
MESH_NEAR_MM = 10.0
#: Refinement levels and patches per pair at most (a guard; never reached by a clear plan).
MAX_LEVELS, MAX_PATCHES = 16, 400_000


# =========================================================================== transforms


def rot(axis: str, a: float) -> np.ndarray:
    """4x4 rotation by ``a`` rad about x, y or z."""
    c, s = math.cos(a), math.sin(a)
    T = np.eye(4)
    i, j = {"x": (1, 2), "y": (2, 0), "z": (0, 1)}[axis]
    T[i, i], T[i, j], T[j, i], T[j, j] = c, -s, s, c
    return T


def tr(x: float, y: float, z: float) -> np.ndarray:
    T = np.eye(4)
    T[:3, 3] = x, y, z
    return T


def xyz_rpy(node: dict | None, mm: float, deg: float) -> np.ndarray:
    """``{xyz, rpy}`` -> trans(xyz) rotz(yaw) roty(pitch) rotx(roll) (docs/kb-format.md), mm."""
    node = node or {}
    x, y, z = (float(v) * mm for v in node.get("xyz", (0, 0, 0)))
    r, p, w = (float(v) * deg for v in node.get("rpy", (0, 0, 0)))
    return tr(x, y, z) @ rot("z", w) @ rot("y", p) @ rot("x", r)


def inv(T: np.ndarray) -> np.ndarray:
    out = np.eye(4)
    out[:3, :3] = T[:3, :3].T
    out[:3, 3] = -T[:3, :3].T @ T[:3, 3]
    return out


# =========================================================================== the robot


@dataclass
class Body:
    """A body fixed to ``frame`` (0..6 link frames, 7 the tool, -1 the world): ``kind``
    box (``T`` its centre pose in the frame, ``half`` extents), cylinder or capsule (``a``, ``b``
    axis ends, ``r``), hull (``pts`` vertices, ``tris`` (k, 3, 3) facets, ``planes`` (f, 4)), or
    mesh (a closed mesh part that need not be convex: ``mesh`` in its own frame, at ``T``; its
    hull's ``pts``, ``tris``, ``planes`` as a hull's, for the cheap bounds and its surface when it
    moves, conservative). Lengths in mm."""

    name: str
    frame: int
    kind: str
    T: np.ndarray = field(default_factory=lambda: np.eye(4))
    half: np.ndarray = field(default_factory=lambda: np.zeros(3))
    a: np.ndarray = field(default_factory=lambda: np.zeros(3))
    b: np.ndarray = field(default_factory=lambda: np.zeros(3))
    r: float = 0.0
    pts: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    tris: np.ndarray = field(default_factory=lambda: np.zeros((0, 3, 3)))
    planes: np.ndarray = field(default_factory=lambda: np.zeros((0, 4)))
    mesh: Any = None

    def moved(self, T: np.ndarray, frame: int, name: str | None = None) -> "Body":
        """This body moved by ``T`` (its coordinates were in a frame that is at ``T``)."""
        R, t = T[:3, :3], T[:3, 3]
        planes = self.planes.copy()
        if len(planes):
            n = planes[:, :3] @ R.T
            planes = np.column_stack([n, planes[:, 3] + n @ t])
        return Body(name or self.name, frame, self.kind, T @ self.T, self.half, R @ self.a + t, R @ self.b + t,
                    self.r, self.pts @ R.T + t, self.tris @ R.T + t, planes, self.mesh)

    def centre(self) -> np.ndarray:
        if self.kind == "box":
            return self.T[:3, 3]
        if self.kind in ("hull", "mesh"):
            return self.pts.mean(axis=0)
        return (self.a + self.b) / 2


def box_body(name: str, frame: int, lo: Any, hi: Any) -> Body:
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    return Body(name, frame, "box", T=tr(*((lo + hi) / 2)), half=(hi - lo) / 2)


def hull_body(name: str, frame: int, points: np.ndarray) -> Body:
    from scipy.spatial import ConvexHull

    h = ConvexHull(points)
    # qhull's equations: n . x + c <= 0 inside, n unit
    planes = np.column_stack([h.equations[:, :3], -h.equations[:, 3]])
    return Body(name, frame, "hull", pts=points[h.vertices], tris=points[h.simplices], planes=planes)


@dataclass
class Arm:
    """A robot file, in mm and rad: DH rows (alpha, a, d, offset), the convention, base and tool,
    link bodies, allowed pairs, margin, the gripper's sizes."""

    dh: np.ndarray
    standard: bool
    base: np.ndarray
    tool: np.ndarray
    links: list[Body]
    allow: set[frozenset]
    margin: float | None
    opening: float
    finger: tuple[float, float, float]  # length, width, thickness
    palm: tuple[float, float, float]

    def frames(self, q: np.ndarray) -> np.ndarray:
        """World frames (n, 8, 4, 4) of joint vectors q (n, 6) rad: frame 0 (the base), the six
        link frames, the tool. Modified DH (Craig): A_i = rotx(alpha_{i-1}) transx(a_{i-1})
        rotz(theta_i) transz(d_i). Standard DH: A_i = rotz(theta_i) transz(d_i) transx(a_i)
        rotx(alpha_i); the link shapes of such a file are in Craig's frames of the same chain
        (docs/kb-format.md), i.e. frame i is standard frame i-1 times rotz(theta_i) transz(d_i)
        (before link i's transx(a_i) rotx(alpha_i)), and the tool follows standard frame 6."""
        q = np.atleast_2d(q)
        out = np.empty((len(q), 8, 4, 4))
        for k, qk in enumerate(q):
            T = self.base.copy()
            out[k, 0] = T
            for i, ((alpha, a, d, off), qi) in enumerate(zip(self.dh, qk), start=1):
                if self.standard:
                    out[k, i] = T @ rot("z", qi + off) @ tr(0, 0, d)
                    T = out[k, i] @ tr(a, 0, 0) @ rot("x", alpha)
                else:
                    T = T @ rot("x", alpha) @ tr(a, 0, 0) @ rot("z", qi + off) @ tr(0, 0, d)
                    out[k, i] = T
            out[k, 7] = T @ self.tool
        return out

    def gripper(self, width: float) -> list[Body]:
        """Palm and fingers in the tool frame (z the approach, y the closing axis, origin midway
        between the finger tips) with the fingers' contact faces ``width`` (mm) apart."""
        L, u, t = self.finger[0], self.finger[1] / 2, self.finger[2]
        pl, pu, pt = self.palm[0], self.palm[1] / 2, self.palm[2] / 2
        w = width / 2
        return [box_body("finger_l", 7, (-u, w, -L), (u, w + t, 0)),
                box_body("finger_r", 7, (-u, -w - t, -L), (u, -w, 0)),
                box_body("palm", 7, (-pu, -pt, -L - pl), (pu, pt, -L))]


def load_arm(path: Path) -> Arm:
    doc = yaml.safe_load(path.read_text())
    mm = MM[doc["units"]["length"]]
    deg = math.pi / 180 if doc["units"].get("angle", "deg") == "deg" else 1.0
    dh = np.array([[float(r["alpha"]) * deg, float(r["a"]) * mm, float(r["d"]) * mm, float(r.get("offset", 0)) * deg]
                   for r in doc["dh"]])
    links = []
    col = doc.get("collision") or {}
    for ln in col.get("links", []):
        name, frame = ln["name"], int(ln["frame"])
        if "box" in ln:
            links.append(box_body(name, frame, np.multiply(ln["box"]["min"], mm), np.multiply(ln["box"]["max"], mm)))
        else:
            kind = "capsule" if "capsule" in ln else "cylinder"
            s = ln[kind]
            links.append(Body(name, frame, kind, a=np.multiply(s["from"], mm), b=np.multiply(s["to"], mm),
                              r=float(s["radius"]) * mm))
    g = doc["gripper"]
    opening = float(g["finger_separation"]) * mm
    f = {"length": 60 / mm, "width": 20 / mm, "thickness": 10 / mm, **(g.get("finger") or {})}
    p = {"length": 25 / mm, "width": f["width"], "thickness": opening / mm + 2 * f["thickness"],
         **(g.get("palm") or {})}
    return Arm(dh, doc.get("convention", "modified") == "standard", xyz_rpy(doc.get("base"), mm, deg),
               xyz_rpy(doc.get("tool"), mm, deg), links, {frozenset(a) for a in col.get("allow", [])},
               None if col.get("margin") is None else float(col["margin"]) * mm, opening,
               tuple(float(f[k]) * mm for k in ("length", "width", "thickness")),
               tuple(float(p[k]) * mm for k in ("length", "width", "thickness")))


@dataclass
class UrdfArm(Arm):
    """A URDF arm (mm, rad): frame 0 is the problem's ``base_link`` in the world, frame i
    (1..6) the child link of the chain's i-th moving joint, frame 7 the tool (tip link @ the
    problem's ``tool``), all from yourdfpy's own FK. Each collision body is in the coordinates
    of the frame it rides with (a link fixed to a frame's link is moved there once, by the
    URDF's fixed joints). ``dh`` is unused (empty)."""

    urdf: Any = None
    base_link: str = ""
    tip_link: str = ""
    joints: tuple[str, ...] = ()
    owners: tuple[str, ...] = ()  # the link of frames 0..6

    def frames(self, q: np.ndarray) -> np.ndarray:
        q = np.atleast_2d(q)
        names = list(self.urdf.actuated_joint_names)
        out = np.empty((len(q), 8, 4, 4))
        for k, qk in enumerate(q):
            cfg = np.zeros(len(names))
            for j, qj in zip(self.joints, qk):
                cfg[names.index(j)] = qj
            self.urdf.update_cfg(cfg)
            for i, link in enumerate(self.owners):
                out[k, i] = self.base @ _metres_to_mm(self.urdf.get_transform(link, self.base_link))
            out[k, 7] = self.base @ _metres_to_mm(self.urdf.get_transform(self.tip_link, self.base_link)) @ self.tool
        return out


def _metres_to_mm(T: Any) -> np.ndarray:
    T = np.array(T, float)
    T[:3, 3] *= 1000.0
    return T


def load_urdf_arm(node: dict, problem_dir: Path, mm: float, deg: float) -> UrdfArm:
    """The problem's ``robot: {urdf, base_link, tip_link, base, tool, gripper, collision}``
    (lengths of base, tool and gripper in the problem's unit; the URDF's in metres)."""
    import yourdfpy

    path = (problem_dir / node["urdf"]).resolve()
    urdf = yourdfpy.URDF.load(str(path), build_scene_graph=True, load_meshes=False, load_collision_meshes=False)
    by_child = {j.child: j for j in urdf.robot.joints}
    chain, link = [], node["tip_link"]
    while link in by_child:  # up to the root: base_link may hang beside the chain by fixed joints
        chain.append(by_child[link])
        link = by_child[link].parent
    chain.reverse()
    moving = [j for j in chain if j.type != "fixed"]
    assert len(moving) == 6, "a 6R chain"
    owners = (node["base_link"], *(j.child for j in moving))
    # every link rides with frame k: the moving joints above it (0: none), through fixed joints
    frame_of = {link: 0}
    changed = True
    while changed:
        changed = False
        for j in urdf.robot.joints:
            if j.parent in frame_of and j.child not in frame_of:
                frame_of[j.child] = frame_of[j.parent] + (0 if j.type == "fixed" else 1)
                changed = True
    urdf.update_cfg(np.zeros(len(urdf.actuated_joint_names)))
    links = []
    for lk in urdf.robot.links:
        if lk.name not in frame_of:
            continue
        f = frame_of[lk.name]
        T_frame_link = _metres_to_mm(urdf.get_transform(lk.name, owners[f]))  # fixed: the same at every q
        for n, c in enumerate(lk.collisions):
            T = T_frame_link @ _metres_to_mm(np.eye(4) if c.origin is None else c.origin)
            g, name = c.geometry, lk.name if n == 0 else f"{lk.name}_{n}"
            if g.cylinder is not None:
                h = g.cylinder.length * 500.0
                links.append(Body(name, f, "cylinder", a=T[:3, 3] - h * T[:3, 2], b=T[:3, 3] + h * T[:3, 2],
                                  r=g.cylinder.radius * 1000.0))
            elif g.sphere is not None:
                links.append(Body(name, f, "capsule", a=T[:3, 3].copy(), b=T[:3, 3].copy(), r=g.sphere.radius * 1000.0))
            elif g.box is not None:
                half = np.asarray(g.box.size, float) * 500.0
                links.append(Body(name, f, "box", T=T, half=half))
            else:
                import trimesh

                mesh = trimesh.load(str(path.parent / g.mesh.filename), force="mesh")
                P = np.asarray(mesh.vertices, float) * 1000.0
                if g.mesh.scale is not None:
                    P = P * np.broadcast_to(np.asarray(g.mesh.scale, float), (3,))
                links.append(hull_body(name, f, P @ T[:3, :3].T + T[:3, 3]))
    col = node.get("collision") or {}
    g = node["gripper"]
    opening = float(g["finger_separation"]) * mm
    fs = {"length": 60 / mm, "width": 20 / mm, "thickness": 10 / mm, **(g.get("finger") or {})}
    ps = {"length": 25 / mm, "width": fs["width"], "thickness": opening / mm + 2 * fs["thickness"],
          **(g.get("palm") or {})}
    return UrdfArm(np.zeros((0, 4)), False, xyz_rpy(node.get("base"), mm, deg), xyz_rpy(node.get("tool"), mm, deg),
                   links, {frozenset(a) for a in col.get("allow", [])},
                   None if col.get("margin") is None else float(col["margin"]) * mm, opening,
                   tuple(float(fs[k]) * mm for k in ("length", "width", "thickness")),
                   tuple(float(ps[k]) * mm for k in ("length", "width", "thickness")),
                   urdf, node["base_link"], node["tip_link"], tuple(j.name for j in moving), owners)


# =========================================================================== parts, obstacles, cells


def load_part(path: Path) -> list[Body]:
    """An object file's solids in its object frame (mm): ``shape:`` boxes and z-cylinders
    (subtracted primitives left solid: conservative), else the convex hull of its ``mesh:``."""
    doc = yaml.safe_load(path.read_text())
    mm = MM[doc["units"]["length"]]
    out = []
    for s in doc.get("shape") or []:
        if "box" in s and not s["box"].get("subtract"):
            out.append(box_body("", -1, np.multiply(s["box"]["min"], mm), np.multiply(s["box"]["max"], mm)))
        elif "cylinder" in s and not s["cylinder"].get("subtract"):
            z0, z1 = (float(v) * mm for v in s["cylinder"]["z"])
            out.append(Body("", -1, "cylinder", a=np.array([0, 0, z0]), b=np.array([0, 0, z1]),
                            r=float(s["cylinder"]["radius"]) * mm))
    if not out and doc.get("mesh"):
        import trimesh

        mesh = trimesh.load(path.parent / doc["mesh"], force="mesh")
        out.append(hull_body("", -1, np.asarray(mesh.vertices, float) * mm))
    return out


def mesh_body(name: str, frame: int, mesh: Any) -> Body:
    """A closed mesh part (mm, its own frame) as a "mesh" body; an open one as its hull."""
    hull = hull_body(name, frame, np.asarray(mesh.vertices, float))
    if not mesh.is_watertight:
        return hull
    return Body(name, frame, "mesh", pts=hull.pts, tris=hull.tris, planes=hull.planes, mesh=mesh)


def obstacle_bodies(doc: dict, base: Path, mm: float, deg: float) -> list[Body]:
    out = []
    for o in doc.get("obstacles") or []:
        if "box" in o:
            out.append(box_body(o["name"], -1, np.multiply(o["box"]["min"], mm), np.multiply(o["box"]["max"], mm)))
        elif "cylinder" in o:
            c = o["cylinder"]
            x, y = (float(v) * mm for v in c.get("center", (0, 0)))
            z0, z1 = (float(v) * mm for v in c["z"])
            out.append(Body(o["name"], -1, "cylinder", a=np.array([x, y, z0]), b=np.array([x, y, z1]),
                            r=float(c["radius"]) * mm))
        else:
            import trimesh

            mesh = trimesh.load(base / o["mesh"], force="mesh")
            T = xyz_rpy(o, mm, deg)
            pts = np.asarray(mesh.vertices, float) * mm
            out.append(hull_body(o["name"], -1, pts @ T[:3, :3].T + T[:3, 3]))
    return out


@dataclass
class CellGeo:
    """What the checker knows of a problem file: the arm, the parts' solids by object, the
    obstacles, the table's extent (or None: the whole plane), the margin; all in mm. ``k``
    converts the cell's (and its plan JSON's) length unit to mm."""

    arm: Arm
    parts: dict[str, list[Body]]
    obstacles: list[Body]
    table: tuple[float, float, float, float] | None
    margin: float
    k: float
    urdf: bool = False
    #: A product cell's parts at their product poses (mm, product frame; empty otherwise): at an
    #: assemble, the held part may touch a part that is where the product puts it beside it.
    product: dict[str, np.ndarray] = field(default_factory=dict)


def load_product_poses(path: Path) -> tuple[dict[str, Path | list[Body]], dict[str, np.ndarray]]:
    """A product file's parts: each model file (or, for a ``mesh:`` part, its solid: the mesh in
    its own frame, :func:`mesh_body`) and pose (mm)."""
    doc = yaml.safe_load(path.read_text())
    mm = MM[doc["units"]["length"]]
    deg = math.pi / 180 if doc["units"].get("angle", "deg") == "deg" else 1.0
    models: dict[str, Path | list[Body]] = {}
    for n, p in doc["parts"].items():
        if "model" in p:
            models[n] = (path.parent / p["model"]).resolve()
        else:
            import trimesh

            mesh = trimesh.load(path.parent / p["mesh"], force="mesh")  # vertices merged
            mesh.apply_scale(mm)
            models[n] = [mesh_body("", -1, mesh)]
    return models, {n: xyz_rpy(p.get("pose"), mm, deg) for n, p in doc["parts"].items()}


def load_cell(path: Path) -> CellGeo:
    doc = yaml.safe_load(path.read_text())
    mm = MM[doc["units"]["length"]]
    deg = math.pi / 180 if doc["units"].get("angle", "deg") == "deg" else 1.0
    robot = doc["robot"]
    urdf = isinstance(robot, dict)
    arm = load_urdf_arm(robot, path.parent, mm, deg) if urdf else load_arm((path.parent / robot).resolve())
    models, product = load_product_poses((path.parent / doc["product"]).resolve()) if "product" in doc else ({}, {})
    objects = doc.get("objects") or {n: {} for n in models}  # `layout: auto`: the product's parts
    parts = {}
    for name, o in objects.items():
        src = models[name] if "model" not in o else (path.parent / o["model"]).resolve()
        parts[name] = src if isinstance(src, list) else load_part(src)
    table = doc.get("table")
    ext = None if table is None else tuple(float(v) * mm for v in (*table["x"], *table["y"]))
    margin = (float(doc["clearance"]) * mm if doc.get("clearance") is not None
              else arm.margin if arm.margin is not None else DEFAULT_MARGIN_MM)
    return CellGeo(arm, parts, obstacle_bodies(doc, path.parent, mm, deg), ext, margin, mm, urdf,  # type: ignore[arg-type]
                   product)


# =========================================================================== signed distances


def seg_point(p: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(k,) distances of points p (k, 3) from the segment a-b."""
    d = b - a
    L2 = float(d @ d)
    t = np.zeros(len(p)) if L2 == 0 else np.clip((p - a) @ d / L2, 0.0, 1.0)
    return np.linalg.norm(p - (a + t[:, None] * d), axis=1)


def axis_frame(a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, float]:
    """Pose (4x4) at the middle of a-b with z along it, and the half length."""
    d = b - a
    h = float(np.linalg.norm(d)) / 2
    z = d / (2 * h) if h > 0 else np.array([0.0, 0.0, 1.0])
    x = np.cross(z, [1.0, 0, 0] if abs(z[0]) < 0.9 else [0, 1.0, 0])
    x /= np.linalg.norm(x)
    T = np.eye(4)
    T[:3, 0], T[:3, 1], T[:3, 2], T[:3, 3] = x, np.cross(z, x), z, (a + b) / 2
    return T, h


def sdf(body: Body, p: np.ndarray) -> np.ndarray:
    """(k,) signed distance of world points p (k, 3) from ``body`` (world coordinates): exact
    for boxes, cylinders and capsules; for a hull the largest face-plane distance (exact
    inside, at most the distance outside); for a mesh its exact signed distance (trimesh's
    closest points) where its hull's bound is under MESH_NEAR_MM, that bound (a lower bound of
    the mesh's, which lies inside its hull) elsewhere."""
    if body.kind == "box":
        loc = (p - body.T[:3, 3]) @ body.T[:3, :3]
        q = np.abs(loc) - body.half
        return np.linalg.norm(np.maximum(q, 0.0), axis=1) + np.minimum(q.max(axis=1), 0.0)
    if body.kind == "capsule":
        return seg_point(p, body.a, body.b) - body.r
    if body.kind == "cylinder":
        T, h = axis_frame(body.a, body.b)
        loc = (p - T[:3, 3]) @ T[:3, :3]
        q = np.column_stack([np.hypot(loc[:, 0], loc[:, 1]) - body.r, np.abs(loc[:, 2]) - h])
        return np.linalg.norm(np.maximum(q, 0.0), axis=1) + np.minimum(q.max(axis=1), 0.0)
    if body.kind == "table":  # the slab below z = 0 over the extent (or the half-space)
        if body.half is None or not np.any(body.half):
            return p[:, 2]
        return sdf(Body("", -1, "box", T=body.T, half=body.half), p)
    d = (p @ body.planes[:, :3].T - body.planes[:, 3]).max(axis=1)
    if body.kind == "mesh":
        import trimesh

        near = d < MESH_NEAR_MM
        if near.any():
            loc = (p[near] - body.T[:3, 3]) @ body.T[:3, :3]
            d[near] = -trimesh.proximity.signed_distance(body.mesh, loc)  # trimesh: inside > 0
    return d


def table_body(ext: tuple[float, float, float, float] | None) -> Body:
    if ext is None:
        return Body("table", -1, "table")
    x0, x1, y0, y1 = ext
    depth = 1e6
    return Body("table", -1, "table", T=tr((x0 + x1) / 2, (y0 + y1) / 2, -depth / 2),
                half=np.array([(x1 - x0) / 2, (y1 - y0) / 2, depth / 2]))


# =========================================================================== surface patches


@dataclass
class Patches:
    """Surface patches of one body (world coordinates): per kind an array of cells.

    rect: (origin, u, v) per face and cells (s0, s1, t0, t1) in [0, 1]^2; side: a cylinder's
    (T, r, h) and cells (th0, th1, z0, z1); disc: (centre, x, y, r) and cells (rho0, rho1,
    th0, th1); seg: a capsule's axis (a, b) and cells (s0, s1), its radius ``off``; tri:
    triangles (k, 3, 3)."""

    kind: str
    geo: tuple
    cells: np.ndarray
    off: float = 0.0

    def centres(self) -> tuple[np.ndarray, np.ndarray]:
        """(centre points (k, 3), covering radii (k,))."""
        c = self.cells
        if self.kind == "rect":
            o, u, v = self.geo
            s, t = (c[:, 0] + c[:, 1]) / 2, (c[:, 2] + c[:, 3]) / 2
            h = 0.5 * np.hypot(np.linalg.norm(u) * (c[:, 1] - c[:, 0]), np.linalg.norm(v) * (c[:, 3] - c[:, 2]))
            return o + s[:, None] * u + t[:, None] * v, h
        if self.kind == "side":
            T, r = self.geo
            th, z = (c[:, 0] + c[:, 1]) / 2, (c[:, 2] + c[:, 3]) / 2
            loc = np.column_stack([r * np.cos(th), r * np.sin(th), z])
            h = 0.5 * np.hypot(r * (c[:, 1] - c[:, 0]), c[:, 3] - c[:, 2])
            return loc @ T[:3, :3].T + T[:3, 3], h
        if self.kind == "disc":
            o, x, y = self.geo
            rho, th = (c[:, 0] + c[:, 1]) / 2, (c[:, 2] + c[:, 3]) / 2
            p = o + (rho * np.cos(th))[:, None] * x + (rho * np.sin(th))[:, None] * y
            h = np.hypot((c[:, 1] - c[:, 0]) / 2, c[:, 1] * (c[:, 3] - c[:, 2]) / 2)
            return p, h
        if self.kind == "seg":
            a, b = self.geo
            s = (c[:, 0] + c[:, 1]) / 2
            return a + s[:, None] * (b - a), np.linalg.norm(b - a) * (c[:, 1] - c[:, 0]) / 2
        m = c.mean(axis=1)  # tri: cells are the triangles themselves
        return m, np.linalg.norm(c - m[:, None], axis=2).max(axis=1)

    def split(self, keep: np.ndarray) -> "Patches":
        """The kept cells each cut in four (two for a segment)."""
        c = self.cells[keep]
        if self.kind == "seg":
            m = (c[:, 0] + c[:, 1]) / 2
            return Patches("seg", self.geo, np.concatenate([np.column_stack([c[:, 0], m]),
                                                            np.column_stack([m, c[:, 1]])]), self.off)
        if self.kind == "tri":
            A, B, C = c[:, 0], c[:, 1], c[:, 2]
            ab, bc, ca = (A + B) / 2, (B + C) / 2, (C + A) / 2
            return Patches("tri", self.geo, np.concatenate([np.stack(t, axis=1) for t in
                                                            ((A, ab, ca), (ab, B, bc), (ca, bc, C), (ab, bc, ca))]))
        m1, m2 = (c[:, 0] + c[:, 1]) / 2, (c[:, 2] + c[:, 3]) / 2
        parts = [np.column_stack(x) for x in ((c[:, 0], m1, c[:, 2], m2), (m1, c[:, 1], c[:, 2], m2),
                                              (c[:, 0], m1, m2, c[:, 3]), (m1, c[:, 1], m2, c[:, 3]))]
        return Patches(self.kind, self.geo, np.concatenate(parts), self.off)


def _grid(n1: int, n2: int, lo1: float, hi1: float, lo2: float, hi2: float) -> np.ndarray:
    e1, e2 = np.linspace(lo1, hi1, n1 + 1), np.linspace(lo2, hi2, n2 + 1)
    i, j = np.meshgrid(np.arange(n1), np.arange(n2), indexing="ij")
    i, j = i.ravel(), j.ravel()
    return np.column_stack([e1[i], e1[i + 1], e2[j], e2[j + 1]])


def surface(body: Body) -> list[Patches]:
    """The initial patches (covering radius <= about H0_MM) of a world-placed body's surface."""
    def n(length: float) -> int:
        return max(1, math.ceil(length / H0_MM))

    if body.kind == "capsule":
        L = float(np.linalg.norm(body.b - body.a))
        return [Patches("seg", (body.a, body.b), np.column_stack([np.linspace(0, 1, n(L) + 1)[:-1],
                                                                  np.linspace(0, 1, n(L) + 1)[1:]]), body.r)]
    if body.kind == "box":
        R, t, hx = body.T[:3, :3], body.T[:3, 3], body.half
        out = []
        for ax in range(3):
            i, j = [k for k in range(3) if k != ax]
            u, v = 2 * hx[i] * R[:, i], 2 * hx[j] * R[:, j]
            for sgn in (-1, 1):
                o = t + sgn * hx[ax] * R[:, ax] - hx[i] * R[:, i] - hx[j] * R[:, j]
                out.append(Patches("rect", (o, u, v), _grid(n(2 * hx[i]), n(2 * hx[j]), 0, 1, 0, 1)))
        return out
    if body.kind == "cylinder":
        T, h = axis_frame(body.a, body.b)
        r = body.r
        out = [Patches("side", (T, r), _grid(n(2 * math.pi * r), n(2 * h), 0, 2 * math.pi, -h, h))]
        for sgn in (-1, 1):
            out.append(Patches("disc", (T[:3, 3] + sgn * h * T[:3, 2], T[:3, 0], T[:3, 1]),
                               _grid(n(r), n(2 * math.pi * r), 0, r, 0, 2 * math.pi)))
        return out
    return [Patches("tri", (), body.tris.copy())]


@dataclass(frozen=True)
class Bound:
    """A certified distance bound of one pair (mm): ``lower`` <= true distance <= ``upper``
    (``upper`` inf when every patch was certified without one being sampled near)."""

    moving: str
    other: str
    lower: float
    upper: float


def pair_bound(moving: Body, other: Body, margin: float) -> Bound:
    """Bound the distance of two world-placed bodies, refined until it is certified to be at
    least ``margin - TOL_MM`` or shown (or left, at the guards) below it."""
    goal = margin - TOL_MM
    lower, upper = math.inf, math.inf
    if other.kind != "table" and moving.kind not in ("hull", "mesh"):  # is the other body inside the moving one?
        inside = float(sdf(moving, other.centre()[None])[0])
        if inside < 0:
            return Bound(moving.name, other.name, inside, inside)
    for patches in surface(moving):
        for _level in range(MAX_LEVELS):
            c, h = patches.centres()
            v = sdf(other, c) - patches.off
            lb = v - h
            upper = min(upper, float(v.min()) if other.kind not in ("hull", "mesh") or v.min() < 0 else upper)
            ambiguous = lb < goal
            lower = min(lower, float(lb[~ambiguous].min()) if (~ambiguous).any() else lower)
            if not ambiguous.any():
                break
            if upper < goal or 4 * int(ambiguous.sum()) > MAX_PATCHES:
                lower = min(lower, float(lb[ambiguous].min()))
                return Bound(moving.name, other.name, lower, upper)
            patches = patches.split(ambiguous)
        else:
            c, h = patches.centres()
            lower = min(lower, float((sdf(other, c) - patches.off - h).min()))
    return Bound(moving.name, other.name, lower, upper)


# =========================================================================== a step's world


@dataclass
class StepCheck:
    """One end-point's verdict: the smallest certified bound and every pair under the goal."""

    step: str
    closest: Bound
    violations: list[Bound]


def hand_part(step: dict) -> str | None:
    """The part the fingers hold at the step's end-point (its contact with them is the grasp's)."""
    if step["name"] in ("pickup", "putdown", "assemble", "squeeze"):
        return step["object"]
    return step.get("held")


def grasp_width_mm(cell: Any, geo: CellGeo, part: str, T_part: np.ndarray, T_tool: np.ndarray) -> float:
    """The width of the grasp of ``part`` whose T_g is T_part^-1 T_tool (mm; poses in the cell
    unit), from the KB's grasp list (data)."""
    model = cell.objects[part.split("@", 1)[0]]
    Tg = inv(T_part) @ T_tool
    best = min(model.grasps.values(), key=lambda g: float(np.abs(np.asarray(g.T, float) - Tg).max()))
    err = float(np.abs(np.asarray(best.T, float) - Tg).max())
    assert err < 1e-4 * max(1.0, float(np.abs(Tg[:3, 3]).max())), f"no grasp of {part} matches the step's tool pose"
    return float(best.width) * geo.k


def _z_extent(b: Body) -> tuple[float, float]:
    """(lowest, highest) world z of a box, cylinder, capsule or hull body (mm)."""
    if b.kind == "box":
        z = (np.array([[x, y, w] for x in (-1, 1) for y in (-1, 1) for w in (-1, 1)]) * b.half) @ b.T[2, :3] + b.T[2, 3]
        return float(z.min()), float(z.max())
    if b.kind in ("hull", "mesh"):
        return float(b.pts[:, 2].min()), float(b.pts[:, 2].max())
    axis = (b.b - b.a) / max(float(np.linalg.norm(b.b - b.a)), 1e-12)
    drop = b.r if b.kind == "capsule" else b.r * math.sqrt(max(0.0, 1.0 - float(axis[2]) ** 2))
    return min(b.a[2], b.b[2]) - drop, max(b.a[2], b.b[2]) + drop


def _as_designed(geo: CellGeo, poses: dict[str, np.ndarray], held: str, other: str) -> bool:
    """Whether ``other`` sits where the product puts it relative to the ``held`` part (a
    product cell's design contact at the held part's assemble): within 1e-6 mm and rad."""
    if held not in geo.product or other not in geo.product:
        return False
    want = inv(geo.product[held]) @ geo.product[other]
    got = inv(poses[held]) @ poses[other]
    return bool(np.abs(got - want).max() < 1e-6)


def check_step(geo: CellGeo, cell: Any, step: dict, q_deg: np.ndarray | None = None) -> StepCheck:
    """The clearances of one step's end-point (its ``joints_deg``, or ``q_deg`` instead: the
    part in the hand then moves with the tool)."""
    k = geo.k
    arm = geo.arm
    q0 = np.radians(np.asarray(step["joints_deg"], float))
    q = q0 if q_deg is None else np.radians(np.asarray(q_deg, float))
    F = arm.frames(q[None])[0]
    T_tool_json = np.asarray(step["tool_pose"], float)
    T_tool_json[:3, 3] *= k
    poses = {}
    for key, P in step["poses"].items():
        P = np.asarray(P, float)
        P[:3, 3] *= k
        poses[key] = P
    hand = hand_part(step)
    held = step.get("held") if step["name"] != "pickup" else None
    if step["name"] in ("putdown", "assemble"):
        held = hand
    width = arm.opening
    if hand is not None:
        Tp = poses[hand].copy()
        Tp[:3, 3] /= k
        Tt = T_tool_json.copy()
        Tt[:3, 3] /= k
        width = grasp_width_mm(cell, geo, hand, Tp, Tt)
    moving: list[Body] = [b.moved(F[b.frame], b.frame) for b in arm.links if b.frame >= 1]
    moving += [b.moved(F[7], 7) for b in arm.gripper(width)]
    # a subassembly in the hand (issue 33): the parts the step moves with the held part go with the tool
    body = [held, *(c for c in (step.get("moves") or [])[1:] if c != held)] if held is not None else []
    for part in body:  # moves with the tool: T_world_part = T_tool(q) T_tool_part
        T_tool_part = inv(arm.frames(q0[None])[0, 7]) @ poses[part]
        moving += [b.moved(F[7] @ T_tool_part, 7, f"held:{part}") for b in geo.parts[part.split("@", 1)[0]]]
    world: list[Body] = [table_body(geo.table)] + list(geo.obstacles)
    for key, P in poses.items():
        if key not in body:
            world += [b.moved(P, -1, key) for b in geo.parts[key.split("@", 1)[0]]]
    gripper = {"palm", "finger_l", "finger_r"}
    skip = set(arm.allow)
    bounds = []
    for m in moving:
        for w in world:
            if frozenset((m.name, w.name)) in skip:
                continue
            if m.name in gripper and w.name == hand:
                continue  # the grasp's contact (a pickup's or squeeze's part on the table)
            if held is not None and m.name in {f"held:{p}" for p in body}:
                if step["name"] == "putdown" and w.name == "table":
                    continue
                if step["name"] == "putdown" and w.name == (step.get("placement") or {}).get("on"):
                    # set down on a support's top (issue 33): touching it is the step's own
                    # contact; sinking into it is not
                    low = min(_z_extent(h)[0] for h in moving if h.name == m.name)
                    top = max(_z_extent(v)[1] for v in world if v.name == w.name)
                    if low < top - TOL_MM:
                        bounds.append(Bound(m.name, w.name, low - top, low - top))
                    continue
                if step["name"] == "assemble" and (w.name == step["args"][1] or _as_designed(geo, poses, held, w.name)):
                    continue
                if step["name"] == "assemble" and w.name == "table":
                    # seated through its mate down to the plane the base rests on (a through
                    # pin's tip on the table): touching is the product's own contact; sinking is not
                    low = min(_z_extent(h)[0] for h in moving if h.name == m.name)
                    if low < -TOL_MM:
                        bounds.append(Bound(m.name, w.name, low, low))
                    continue
            bounds.append(pair_bound(m, w, geo.margin))
    # the arm against itself: links two or more frames apart (the pedestal, frame 0, with links
    # 2..6), the gripper with links 0..5 and the part in the hand with links 0..6
    arm_bodies = [b.moved(arm.base, 0) for b in arm.links if b.frame == 0] + moving
    for i, m in enumerate(arm_bodies):
        for o in arm_bodies[i + 1:]:
            if frozenset((m.name, o.name)) in skip:
                continue
            if m.frame == 7 and o.frame == 7:
                names = {m.name, o.name}
                if not (names & gripper and names - gripper - {f"held:{held}"}):
                    continue  # the gripper and the part in it (the grasp's contact), the body's parts (their mates)
                bounds.append(pair_bound(m, o, geo.margin))  # the fingers against a part the body carries
                continue
            tool, link = (m, o) if m.frame == 7 else (o, m)
            if tool.frame == 7:
                if link.frame > (5 if tool.name in gripper else 6):
                    continue
            elif abs(m.frame - o.frame) < 2:
                continue
            bounds.append(pair_bound(m, o, geo.margin))
    goal = geo.margin - TOL_MM
    closest = min(bounds, key=lambda b: b.lower)
    return StepCheck(step["id"], closest, [b for b in bounds if b.lower < goal])


# =========================================================================== the plans


def _plan_cells() -> list[str]:
    """The regression cells expected to plan (the others have no steps)."""
    out = []
    for p in sorted(PROBLEMS.glob("*.yaml")):
        exp = PROBLEMS / "expected" / f"{p.stem}.json"
        if exp.exists() and json.loads(exp.read_text()).get("outcome") == "plan":
            out.append(p.stem)
    return out


PLAN_CELLS = _plan_cells()


@pytest.fixture(scope="module")
def planned() -> dict[str, tuple[dict, Any, CellGeo]]:
    """Every plan cell's plan JSON (as spar regress plans it), loaded cell and checker geometry."""
    from spar_py.kb import load_problem
    from spar_py.planning.planner import Planner

    planner = Planner()
    out = {}
    for stem in PLAN_CELLS:
        path = PROBLEMS / f"{stem}.yaml"
        out[stem] = (planner.plan(path).to_json(), load_problem(path), load_cell(path))
    return out


def _steps(doc: dict) -> list[dict]:
    return [s for s in doc["instance"]["steps"] if s.get("joints_deg") is not None]


@pytest.mark.parametrize("stem", PLAN_CELLS)
def test_every_step_is_clear_by_the_margin(planned, stem: str) -> None:
    doc, cell, geo = planned[stem]
    assert doc["outcome"] == "plan"
    steps = _steps(doc)
    assert steps, "a plan with no arm configuration"
    for s in steps:
        T = np.asarray(s["tool_pose"], float)
        T[:3, 3] *= geo.k
        mine = geo.arm.frames(np.radians(np.asarray(s["joints_deg"], float))[None])[0, 7]
        # our forward kinematics reaches the step's tool pose (so the frames below are the arm's)
        assert np.abs(mine[:3, :3] - T[:3, :3]).max() < 1e-5 and np.abs(mine[:3, 3] - T[:3, 3]).max() < 1e-3, s["id"]
        verdict = check_step(geo, cell, s)
        assert not verdict.violations, (
            f"{stem} {s['id']} {s['term']}: closer than the margin {geo.margin:.3g} mm: "
            + ", ".join(f"{b.moving}-{b.other} >= {b.lower:.3f} mm" for b in verdict.violations))
        assert verdict.closest.lower >= geo.margin - TOL_MM
        # the step's own report (JSON clearance and closest_pair, issue 15 item 3): two named
        # bodies at least the margin apart
        assert s["clearance"] is not None and len(s["closest_pair"]) == 2, s["id"]
        assert s["clearance"] * geo.k >= geo.margin - TOL_MM, s["id"]


def test_the_checker_fails_a_step_driven_into_the_table(planned) -> None:
    """One step's joints moved (the shoulder turned down) until our own FK puts the tool below
    the table top: the checker names a pair with the table, while the step itself is clear."""
    doc, cell, geo = planned["hole_up"]
    s = _steps(doc)[0]
    assert not check_step(geo, cell, s).violations
    q = np.asarray(s["joints_deg"], float)
    for dq in np.arange(1.0, 60.0, 1.0):
        moved = q + np.array([0, dq, 0, 0, 0, 0])
        if geo.arm.frames(np.radians(moved)[None])[0, 7, 2, 3] < -20.0:
            break
    else:
        pytest.fail("turning the shoulder never brought the tool under the table")
    verdict = check_step(geo, cell, s, q_deg=moved)
    assert verdict.violations
    assert any(b.other == "table" and b.upper < 0 for b in verdict.violations)
    # a touch closer than the margin is caught too: the first shoulder angle at which the
    # fingers' lowest point is under the margin
    lows = []
    for dq in np.arange(0.0, 5.0, 0.05):
        v = check_step(geo, cell, s, q_deg=q + np.array([0, dq, 0, 0, 0, 0]))
        lows.append((dq, v))
        if v.violations:
            break
    dq, v = lows[-1]
    assert v.violations and 0 < dq < 5, "the margin was never crossed"
    assert all(not w.violations for _, w in lows[:-1])


def test_pair_bounds_against_brute_force() -> None:
    """The certified bounds of a few pairs against a brute-force distance (the closest of
    dense random points inside both bodies, scipy's k-d tree): clear by a margin 3 mm under
    it, not clear by one 0.5 mm over it."""
    from scipy.spatial import cKDTree

    rng = np.random.default_rng(7)
    box = box_body("box", -1, (-10, -20, -5), (10, 20, 5))
    cyl = Body("cyl", -1, "cylinder", a=np.array([40.0, 0, -8]), b=np.array([40.0, 5, 12]), r=6.0)
    cap = Body("cap", -1, "capsule", a=np.array([-30.0, 30, 0]), b=np.array([-25.0, 30, 40]), r=4.0)
    boxes = {"box": ((-10, -20, -5), (10, 20, 5)), "cyl": ((33, -7, -15), (47, 12, 19)),
             "cap": ((-35, 25, -5), (-20, 35, 45))}

    def inside(b: Body, n: int = 60_000) -> np.ndarray:
        lo, hi = boxes[b.name]
        p = rng.uniform(lo, hi, size=(n, 3))
        return p[sdf(b, p) <= 0]

    for m, o in ((cyl, box), (cap, box), (cap, cyl), (box, cyl), (box, cap)):
        d = float(cKDTree(inside(o)).query(inside(m))[0].min())  # >= the true distance
        assert pair_bound(m, o, margin=d - 3.0).lower >= d - 3.0 - TOL_MM, (m.name, o.name, d)
        b = pair_bound(m, o, margin=d + 0.5)
        assert b.upper < d + 0.5 and b.lower <= d, (m.name, o.name, b, d)


# =========================================================================== the obstacle cells


def _approach(geo: CellGeo, s: dict) -> np.ndarray:
    """The tool's approach axis (world) at a step, by our own FK from its joints."""
    return geo.arm.frames(np.radians(np.asarray(s["joints_deg"], float))[None])[0, 7, :3, 2]


def test_shelf_rules_out_top_grasps(planned) -> None:
    doc, cell, geo = planned["shelf"]
    pickups = [s for s in _steps(doc) if s["name"] == "pickup"]
    assert {s["object"] for s in pickups} == {"peg", "block"}
    for s in pickups:
        z = _approach(geo, s)
        assert abs(z[2]) < 1e-6, f"{s['term']}: approach {z} is not horizontal"
    # the shelf is over the peg, and the unobstructed cell picks the peg from above
    shelf = next(b for b in geo.obstacles if b.name == "shelf")
    peg = next(s for s in pickups if s["object"] == "peg")
    xy = np.asarray(peg["poses"]["peg"], float)[:2, 3] * geo.k
    assert np.all(np.abs(xy - shelf.T[:2, 3]) < shelf.half[:2])
    free_doc, free_cell, free_geo = planned["peg_in_block"]
    top = next(s for s in _steps(free_doc) if s["name"] == "pickup" and s["object"] == "peg")
    assert _approach(free_geo, top)[2] < -0.99
    # that top grasp's configuration, put in the shelf cell, collides with the shelf (our check)
    verdict = check_step(geo, cell, top)
    assert any(b.other == "shelf" for b in verdict.violations)


def test_putdown_goes_round_the_fixture(planned) -> None:
    doc, cell, geo = planned["putdown_blocked"]
    free_doc = planned["regrasp"][0]
    put = next(s for s in _steps(doc) if s["name"] == "putdown")
    free_put = next(s for s in _steps(free_doc) if s["name"] == "putdown")
    fixture = next(b for b in geo.obstacles if b.name == "fixture")
    P = np.asarray(put["poses"][put["object"]], float)
    P[:3, 3] *= geo.k
    peg = [b.moved(P, -1) for b in geo.parts[put["object"]]]
    assert min(pair_bound(b, fixture, geo.margin).lower for b in peg) >= geo.margin - TOL_MM
    # the unobstructed cell's put-down spot is where the fixture now stands
    F = np.asarray(free_put["poses"][free_put["object"]], float)
    F[:3, 3] *= geo.k
    assert min(pair_bound(b.moved(F, -1), fixture, geo.margin).upper for b in geo.parts[put["object"]]) < 0
    assert np.linalg.norm(P[:2, 3] - F[:2, 3]) > 25.4


def test_collision_no_plan_names_the_shelf(planned, capsys: pytest.CaptureFixture[str]) -> None:
    from spar_py.app.cli import main

    path = PROBLEMS / "collision_no_plan.yaml"
    with pytest.raises(SystemExit) as ended:
        main(["plan", str(path)])
    out = capsys.readouterr().out
    assert ended.value.code != 0
    lines = [ln for ln in out.splitlines() if "no collision-free IK" in ln]
    assert lines and all("-" in ln.split(":")[-1] for ln in lines)
    assert any("shelf" in ln for ln in lines)
    from spar_py.planning.planner import Planner

    plan = Planner().plan(path)
    assert not plan.ok
    said = plan.reason["collisions"]
    assert said == plan.to_json()["reason"]["collisions"]
    assert any("forearm-shelf" in s for s in said) and any("tool_mount-shelf" in s for s in said)
    # not reach: the same cell without the shelf plans (hole_up.yaml)
    assert planned["hole_up"][0]["outcome"] == "plan"


# =========================================================================== URDF arms


def test_the_urdf_checker_places_the_arm_as_its_yaml_twin(planned) -> None:
    """The URDF arm's frames come from yourdfpy, the YAML twin's from our DH FK. kb/robots/ur5e.urdf
    carries the same cylinders as kb/robots/ur5e.yaml: at every step of the URDF cell's plan and
    at 20 random configurations, each URDF link body lies where its twin's does (axis ends to
    1e-6 mm, the same radius), and both put the tool at the step's tool pose."""
    doc, cell, geo = planned["ur5e_urdf_peg_in_block"]
    twin = load_cell(PROBLEMS / "ur5e_peg_in_block.yaml")
    assert geo.urdf and isinstance(geo.arm, UrdfArm) and len(geo.arm.links) == len(twin.arm.links) == 8
    steps = _steps(doc)
    qs = np.vstack([np.radians([s["joints_deg"] for s in steps]),
                    np.random.default_rng(5).uniform(-2 * math.pi, 2 * math.pi, size=(20, 6))])
    for k, q in enumerate(qs):
        Fu, Fy = geo.arm.frames(q[None])[0], twin.arm.frames(q[None])[0]
        if k < len(steps):
            T = np.asarray(steps[k]["tool_pose"], float)
            T[:3, 3] *= geo.k
            assert np.abs(Fu[7] - T).max() < 1e-3 and np.abs(Fy[7] - T).max() < 1e-3, steps[k]["id"]
        placed = [b.moved(Fy[b.frame], b.frame) for b in twin.arm.links]
        for b in geo.arm.links:
            w = b.moved(Fu[b.frame], b.frame)
            err = min(min(max(np.abs(t.a - w.a).max(), np.abs(t.b - w.b).max()),
                          max(np.abs(t.a - w.b).max(), np.abs(t.b - w.a).max())) if t.r == w.r else math.inf
                      for t in placed)
            assert err < 1e-6, (b.name, err, q)


def test_the_checker_fails_a_urdf_step_driven_into_the_table(planned) -> None:
    """As for the DH arms: the URDF cell's first step with its shoulder turned down until
    yourdfpy's FK puts the tool 20 mm under the table top is refused, naming the table."""
    doc, cell, geo = planned["ur5e_urdf_peg_in_block"]
    s = _steps(doc)[0]
    assert not check_step(geo, cell, s).violations
    q = np.asarray(s["joints_deg"], float)
    for sign in (1.0, -1.0):
        for dq in np.arange(1.0, 90.0, 1.0):
            moved = q + sign * np.array([0, dq, 0, 0, 0, 0])
            if geo.arm.frames(np.radians(moved)[None])[0, 7, 2, 3] < -20.0:
                break
        else:
            continue
        break
    else:
        pytest.fail("turning the shoulder never brought the tool under the table")
    verdict = check_step(geo, cell, s, q_deg=moved)
    assert any(b.other == "table" and b.upper < 0 for b in verdict.violations)
