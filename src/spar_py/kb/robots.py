"""The robot loaders: ``kb/robots/*.yaml`` (a DH table) or a problem's inline URDF, to a
:class:`~spar_py.world.robot.model.Robot`.

Kinematics (DH rows, joint limits, base and tool frames, the IK family), the gripper's
boxes, the links' collision shapes and the motion entries (home, joint speeds). Lengths
are converted to the cell's unit, angles to radians.
"""
from __future__ import annotations

import math
import re
from dataclasses import replace
from pathlib import Path
from types import MappingProxyType

import numpy as np

from spar_py.core.errors import KBError, SparValueError
from spar_py.core.units import LENGTH_UNITS
from spar_py.kb.node import LABEL_RE, Node, num, show
from spar_py.kb.reader import MAX_INPUT_BYTES
from spar_py.kb.schema import URDF_ROBOT_SCHEMA, OneOf, check_shape, keys, read_kb
from spar_py.kb.values import units_of, xyz_rpy_frame
from spar_py.world.robot import (
    TOOL_BODY,
    Gripper,
    LinkShape,
    Robot,
    ToolBody,
    UrdfMeshError,
    read_urdf_chain,
    robot_from_urdf,
    standard_to_modified,
    tool_body_behind,
)

__all__ = ["IK_CHOICES", "MAX_JOINT_RAD", "home_angles", "load_robot", "load_urdf_robot"]


#: How a robot file's `ik:` may name its solver: auto = the first closed-form family that fits, else
#: numeric (spar_py.world.robot.ik.FAMILIES)
IK_CHOICES = ("auto", "puma", "ur", "numeric")


#: The largest joint limit a robot file may give (rad): two turns either way. Beyond it
#: the turn representations IK enumerates grow without use (a limit of 1e9 took 1.3 GB).
MAX_JOINT_RAD = 4 * math.pi


def load_robot(path: str | Path, unit: str | None = None, max_bytes: int = MAX_INPUT_BYTES) -> Robot:
    """Load ``kb/robots/*.yaml`` as a :class:`~spar_py.world.robot.model.Robot`.

    Lengths (DH a and d, base and tool frames, finger separation) are converted to
    ``unit`` (default: the file's own length unit), angles (DH alpha and offset,
    limits, rpy) to radians; ``base`` is T_world_frame0 and ``tool`` T_flange_tool,
    each ``trans(xyz) @ rpy(r, p, y)``. ``convention`` says how ``dh`` reads: Craig's
    ``modified`` (default) or ``standard`` (UR's published tables; converted to Craig's
    at load, ``world.robot.model.standard_to_modified``). ``ik`` picks the solver (IK_CHOICES;
    default auto: the first closed-form family the table fits, else numeric).
    Malformed files raise :class:`KBError` naming the file, the key path and what was
    expected (``puma.yaml: dh[2].alpha: a number, not 'x'``); an unknown ``unit``
    raises SparValueError.
    """
    if unit is not None and unit not in LENGTH_UNITS:
        raise SparValueError(f"unknown length unit {unit!r} (one of {', '.join(LENGTH_UNITS)})")
    root = read_kb(path, "robot", max_bytes)
    name = root.key("name").label()
    file_unit, mm_per, rad_per = units_of(root)
    unit = file_unit if unit is None else unit
    scale = mm_per / LENGTH_UNITS[unit]

    dh_node = root.key("dh")
    rows = dh_node.elements()
    if len(rows) != 6:
        raise dh_node.fail("a list of 6 joint rows {alpha, a, d, offset} (spar-py plans with 6R arms)",
                           f"{len(rows)} rows")
    dh = np.array([[r.key("alpha").number() * rad_per, r.key("a").number() * scale,
                    r.key("d").number() * scale,
                    (o.number() if (o := r.key("offset", required=False)) is not None else 0.0) * rad_per]
                   for r in rows])
    conv = root.key("convention", required=False)
    flange = np.eye(4)
    if conv is not None and conv.choice(("modified", "standard")) == "standard":
        dh, flange = standard_to_modified(dh)
    limits = _limits(root.key("limits"), rad_per)
    base = xyz_rpy_frame(root.key("base"), scale, rad_per)
    flange_tool = xyz_rpy_frame(root.key("tool"), scale, rad_per)
    tool = flange @ flange_tool
    wm = root.key("gripper").key("finger_separation").positive() * scale
    family = _ik_choice(root)
    try:
        robot = Robot(name, dh, limits, base, tool, wm, unit, family=family)
    except SparValueError as e:
        raise KBError(str(path), "dh", f"a robot the kinematics accepts ({e})") from None
    _check_family(robot, root, path, unit, file_unit, max_bytes)
    _collision_shapes(robot, root, scale, LENGTH_UNITS[unit], flange_tool)
    _robot_motion(robot, root, rad_per)
    return robot


def _joint_vector(node: Node, rad_per: float, what: str) -> np.ndarray:
    """Six angles (the file's angle unit) as (6,) rad."""
    items = node.elements()
    if len(items) != 6:
        raise node.fail(f"a list of 6 {what}", f"{len(items)} items")
    return np.array([e.number() for e in items]) * rad_per


def home_angles(node: Node | None, robot: Robot, rad_per: float) -> np.ndarray | None:
    """``home:``: six joint angles (file angle unit) within the joint limits, as rad; None if absent."""
    if node is None:
        return None
    q = _joint_vector(node, rad_per, "joint angles")
    if not robot.in_limits(q):
        lim = ", ".join(f"[{num(lo / rad_per)}, {num(hi / rad_per)}]" for lo, hi in robot.limits)
        raise node.fail(f"joint angles within the limits {lim}", "[" + ", ".join(num(v / rad_per) for v in q) + "]")
    return q


def _robot_motion(robot: Robot, root: Node, rad_per: float) -> None:
    """The robot's motion entries (world/motion/paths.py): ``home`` (joint angles, the file's angle
    unit) and ``velocity_limits`` (six positive joint speeds, angle unit per second), in rad
    and rad/s on the Robot."""
    robot.home = home_angles(root.key("home", required=False), robot, rad_per)
    vnode = root.key("velocity_limits", required=False)
    if vnode is not None:
        v = _joint_vector(vnode, rad_per, "joint speeds (angle unit per second)")
        if not np.all(v > 0):
            raise vnode.fail("six positive joint speeds (angle unit per second)",
                             "[" + ", ".join(num(x / rad_per) for x in v) + "]")
        robot.velocity_limits = v


#: The shapes a robot file's ``gripper: body`` may give (each with an optional ``length``).
TOOL_BODY_SCHEMA = OneOf(MappingProxyType({"box": keys(["width", "thickness"], ["length"]),
                                           "cylinder": keys(["radius"], ["length"])}))


def _gripper(gnode: Node, wm: float, scale: float, mm_per_unit: float) -> Gripper:
    """The ``gripper:`` section's boxes (robot unit; Gripper's documented defaults where absent)."""
    def sizes(key: str) -> dict | None:
        n = gnode.key(key, required=False)
        return None if n is None else {k: n.key(k).positive() * scale for k in ("length", "width", "thickness")}
    return Gripper.default(wm, mm_per_unit, sizes("finger"), sizes("palm"))


def _tool_body(gnode: Node, gripper: Gripper, tool: np.ndarray, scale: float, has_collision: bool
               ) -> Gripper:
    """``gripper`` with its tool body (world.robot.model.ToolBody, robot unit): the ``gripper: body``
    the file gives (``none``: no body; a box ``{width, thickness}`` or a cylinder ``{radius}``,
    ``length`` by default from the palm back to the flange of ``tool``), else, for a robot without
    a ``collision:`` section (nothing else describes the tool), a box the palm's size from the palm
    back to the flange; a robot with one describes its tool mount among its links."""
    bnode = gnode.key("body", required=False)
    if bnode is None:
        return gripper if has_collision else gripper.with_default_body(tool)
    if bnode.value == "none":
        return gripper
    if not isinstance(bnode.value, dict):
        raise bnode.fail("none, or one shape: box: {width, thickness[, length]} or cylinder: {radius[, length]}",
                         show(bnode.value))
    check_shape(bnode, TOOL_BODY_SCHEMA)
    kind, sn = bnode.items()[0]
    behind = tool_body_behind(tool, gripper.finger_length, gripper.palm_length)
    lnode = sn.key("length", required=False)
    if lnode is not None:
        length = lnode.positive() * scale
    elif behind > 0:
        length = behind
    else:
        raise sn.fail(f"a length: the palm's back face is on or behind the flange ({num(behind / scale)} from it)")
    if kind == "box":
        body = ToolBody("box", length, sn.key("width").positive() * scale, sn.key("thickness").positive() * scale)
    else:
        body = ToolBody("cylinder", length, radius=sn.key("radius").positive() * scale)
    return replace(gripper, body=body)


def _collision_shapes(robot: Robot, root: Node, scale: float, mm_per_unit: float, flange_tool: np.ndarray) -> None:
    """Set ``robot``'s gripper boxes and tool body (:func:`_tool_body`; ``flange_tool`` the file's
    ``tool``, T_flange_tool from the real flange: a URDF's tip link, a standard table's frame 6) and its ``collision:``
    section: link shapes (capsule, cylinder: ``{radius, from, to}``; box: ``{min, max}``; lengths
    in the file's unit, in Craig's frame ``frame`` 0..6), ``allow`` (pairs of body names never
    checked), ``margin``."""
    gnode = root.key("gripper")
    cnode = root.key("collision", required=False)
    robot.gripper = _tool_body(gnode, _gripper(gnode, robot.finger_separation, scale, mm_per_unit), flange_tool,
                               scale, cnode is not None)
    if cnode is None:
        return
    known = {"palm", "finger_l", "finger_r", "table"} | ({TOOL_BODY} if robot.gripper.body is not None else set())
    lnode = cnode.key("links", required=False)
    if lnode is None:  # the shapes the robot already has (a URDF's own) stay: their names may be allowed
        known |= {s.name for s in robot.links}
    links: list[LinkShape] = []
    for ln in (lnode or Node(cnode.file, cnode.path, [])).elements():
        lname = ln.key("name").label()
        if lname == TOOL_BODY and robot.gripper.body is not None:
            raise ln.key("name").fail(f"a name other than {TOOL_BODY!r} (the gripper's body: gripper: body)",
                                      show(lname))
        fnode = ln.key("frame")
        frame = fnode.number()
        if frame != int(frame) or not 0 <= frame <= 6:
            raise fnode.fail("one of Craig's frames 0 (base) .. 6 (flange)", show(fnode.value))
        kinds = [k for k in ("capsule", "cylinder", "box") if ln.key(k, required=False) is not None]
        if len(kinds) != 1:
            raise ln.fail("exactly one shape: capsule: {radius, from, to}, cylinder: {radius, from, to} or "
                          "box: {min, max}", ", ".join(kinds) or "none")
        sn = ln.key(kinds[0])
        if kinds[0] == "box":
            lo, hi = sn.key("min").vector(3) * scale, sn.key("max").vector(3) * scale
            if np.any(lo > hi):
                raise sn.fail("min <= max in every coordinate")
            links.append(LinkShape(lname, int(frame), "box", lo, hi))
        else:
            links.append(LinkShape(lname, int(frame), kinds[0], sn.key("from").vector(3) * scale,
                                   sn.key("to").vector(3) * scale, sn.key("radius").positive() * scale))
        known.add(lname)
    allowed = []
    anode = cnode.key("allow", required=False)
    for pn in (anode.elements() if anode is not None else []):
        pair = pn.elements()
        if len(pair) != 2:
            raise pn.fail("a pair [body, body] of link or gripper names", show(pn.value))
        names = [e.label() for e in pair]
        for e, n in zip(pair, names):
            if n not in known:
                raise e.fail(f"a body name ({', '.join(sorted(known))})", show(n))
        allowed.append(frozenset(names))
    robot.links = tuple(links)
    robot.allowed = frozenset(allowed)
    mnode = cnode.key("margin", required=False)
    if mnode is not None:
        m = mnode.number()
        if m < 0:
            raise mnode.fail("a clearance margin >= 0", show(mnode.value))
        robot.margin = m * scale


def _limits(lim_node: Node, rad_per: float) -> np.ndarray:
    """Six ``[lo, hi]`` joint limits (file angles) as (6, 2) rad, each within +-MAX_JOINT_RAD."""
    lims = lim_node.elements()
    if len(lims) != 6:
        raise lim_node.fail("a list of 6 [lo, hi] joint limits", f"{len(lims)} items")
    limits = np.array([lim.interval() for lim in lims]) * rad_per
    for i, lim in enumerate(lims):
        if np.abs(limits[i]).max() > MAX_JOINT_RAD:
            raise lim.fail(f"joint limits within +-{math.degrees(MAX_JOINT_RAD):g} deg",
                           f"[{show(limits[i][0] / rad_per)}, {show(limits[i][1] / rad_per)}]")
    return limits


def _ik_choice(root: Node) -> str:
    """``ik:`` (IK_CHOICES), ``auto`` when absent."""
    node = root.key("ik", required=False)
    return "auto" if node is None else node.choice(IK_CHOICES)


def _check_family(robot: Robot, root: Node, path: str | Path, unit: str, file_unit: str, max_bytes: int) -> None:
    """An ``ik:`` family the table does not fit is the table's error, said in the file's unit."""
    family = _ik_choice(root)
    if family in ("auto", "numeric") or robot.solver.family == family:
        return
    if unit != file_unit:
        load_robot(path, file_unit, max_bytes)  # raises this error, said in the file's own unit
    raise KBError(str(path), "dh", f"a {family.upper()}-family arm (ik: {family}; docs/robots.md)",
                  f"one with {robot.not_closed_form[family]}")


def load_urdf_robot(node: Node, base_dir: Path, unit: str, rad_per: float) -> tuple[Robot, Path]:
    """A problem's inline ``robot: {urdf: FILE, base_link: NAME, tip_link: NAME, ...}`` (lengths in
    ``unit``, angles ``rad_per`` rad each, as the problem file says): the robot and the URDF's path.

    ``base`` (T_world_base_link, default identity), ``tool`` (T_tip_link_tool, default identity),
    ``limits`` (override the URDF's), ``name`` (default: the URDF's robot name), ``ik`` as in a robot
    file. The URDF is read with yourdfpy (lengths in metres) and its chain checked against its own FK.
    """
    check_shape(node, URDF_ROBOT_SCHEMA)
    unode = node.key("urdf")
    upath = base_dir / unode.text()
    if not upath.is_file():
        raise unode.fail("the path of a URDF file", f"{show(unode.value)} (no such file)")
    try:
        chain = read_urdf_chain(upath, node.key("base_link").text(), node.key("tip_link").text())
    except SparValueError as e:
        raise unode.fail(f"a URDF spar-py can plan with ({e})") from None
    def frame(key: str) -> np.ndarray:
        n = node.key(key, required=False)
        return np.eye(4) if n is None else xyz_rpy_frame(n, 1.0, rad_per)
    lnode = node.key("limits", required=False)
    limits = None if lnode is None else _limits(lnode, rad_per)
    nnode = node.key("name", required=False)
    name = nnode.label() if nnode is not None else re.sub(r"[^a-z0-9_]", "_", chain.robot_name.lower())
    if not LABEL_RE.fullmatch(name):
        name = "urdf_robot"
    wm = node.key("gripper").key("finger_separation").positive()
    try:
        robot = robot_from_urdf(chain, name, frame("base"), frame("tool"), wm, unit, LENGTH_UNITS[unit], limits,
                                family=_ik_choice(node))
    except UrdfMeshError as e:
        raise unode.fail(f"a URDF whose collision meshes spar-py can read (STL, OBJ or PLY beside it; {e})") from None
    except SparValueError as e:
        raise unode.fail(f"a URDF whose chain spar-py models exactly ({e})") from None
    family = _ik_choice(node)
    if family not in ("auto", "numeric") and robot.solver.family != family:
        raise KBError(node.file, unode.path, f"a {family.upper()}-family arm (ik: {family}; docs/robots.md)",
                      f"one with {robot.not_closed_form[family]}")
    urdf_links = robot.links
    _collision_shapes(robot, node, 1.0, LENGTH_UNITS[unit], frame("tool"))
    robot.links = robot.links or urdf_links  # the URDF's own collision shapes unless the file gives some
    _robot_motion(robot, node, rad_per)
    return robot, upath
