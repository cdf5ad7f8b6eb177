"""Robot models: a 6R arm from a DH table (Craig's or the standard convention) or a URDF chain.

One model, :class:`Robot`, whatever the source: Craig's (modified) DH table, joint
limits, base and tool frames, the gripper opening, and the IK solver its structure
allows (``spar_py.world.robot.ik``: the PUMA or UR closed form, else the numeric fallback).

- a standard-DH table (UR's published one) becomes Craig's exactly:
  :func:`standard_to_modified`;
- a URDF chain (yourdfpy reads the file) becomes Craig's by the common normals of its
  joint axes: :func:`dh_from_axes`, trying each family's sign choices so a UR or PUMA
  described in URDF gets its closed form; :func:`check_against_urdf` then compares the
  model's FK with the URDF's own FK at random configurations and names the first joint
  whose link frame differs.

Frames and units: transforms are 4x4, column vectors; ``base`` is T_world_frame0,
``tool`` T_flange_tool (frame 6, Craig's, to the tool centre point); lengths in
``Robot.unit`` (the cell's), angles in radians; joint vectors q are in the robot's
joint convention (``theta_i = q_i + offset_i``; for a URDF the URDF's own joint zero).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any
from pathlib import Path

import numpy as np

from spar_py.core.errors import SparValueError
from spar_py.core.geometry import check_transform, inv, rotx, trans
from spar_py.world.robot.gripper import Gripper
from spar_py.world.robot.ik import (FAMILY_TWISTS, LIMIT_TOL, Solver, craig_links, lowest_representation, solver_for,
                              turn_combinations)

__all__ = ["LIMIT_TOL", "LinkShape", "Robot", "UrdfChain", "check_against_urdf", "dh_from_axes", "read_urdf_chain",
           "robot_from_urdf", "standard_to_modified"]

# the twist signs each closed-form family wants for alpha_1..alpha_5 (0: parallel axes), to choose
# the free sign of a common normal when a URDF chain is converted
_FAMILY_SIGNS = {name: tuple(int(np.sign(round(a, 9))) for a in tw) for name, tw in FAMILY_TWISTS.items()}

#: Collision shape kinds of a link (:class:`LinkShape`).
LINK_KINDS = ("capsule", "cylinder", "box")


@dataclass(frozen=True)
class LinkShape:
    """A collision shape fixed to one of the arm's Craig frames (``frame`` 0 = the base frame
    T_world_frame0, 1..6 = frame i, 6 the flange), in that frame's coordinates, robot unit.

    ``kind`` "capsule" or "cylinder": the segment ``a`` -> ``b`` (its axis) and ``radius``;
    "box": the corners ``a`` (min) and ``b`` (max), axis-aligned in the frame (radius 0);
    "hull": the convex hull of ``points`` (k, 3) (a URDF's collision mesh; ``a``, ``b`` their
    bounding box)."""

    name: str
    frame: int
    kind: str
    a: np.ndarray
    b: np.ndarray
    radius: float = 0.0
    points: np.ndarray | None = None


@dataclass(eq=False)
class Robot:
    """A 6R arm: Craig DH table, joint limits, base and tool frames, gripper opening, IK solver.

    ``dh`` is (6, 4): alpha_{i-1} (rad), a_{i-1} (``unit``), d_i (``unit``), offset_i
    = theta_i - q_i (rad); ``limits`` (6, 2) rad; ``base`` is T_world_frame0 and
    ``tool`` T_flange_tool (4x4, ``unit``); ``finger_separation`` is W_m (``unit``);
    ``family`` "auto" (the first closed-form family that fits, else numeric) or a
    family name; ``joint_names`` for messages (URDF joints, or joint_1..joint_6).
    """

    name: str
    dh: np.ndarray
    limits: np.ndarray
    base: np.ndarray
    tool: np.ndarray
    finger_separation: float
    unit: str
    family: str = "auto"
    joint_names: tuple[str, ...] = ()
    #: collision shapes of the links (robot file ``collision:``), none when not given
    links: tuple[LinkShape, ...] = ()
    #: the gripper's boxes (robot file ``gripper:``); None: the default fingers at use
    #: (world.robot.gripper.gripper_for)
    gripper: Gripper | None = None
    #: pairs of body names never checked against each other (robot file ``collision: allow``)
    allowed: frozenset = frozenset()
    #: the clearance margin the robot file asks for (robot unit), None: the problem's or the default
    margin: float | None = None
    #: Motion entries (world/motion/paths.py): home joint vector (6,) rad and joint velocity
    #: limits (6,) rad/s, or None (kb.py's _robot_motion).
    home: np.ndarray | None = None
    velocity_limits: np.ndarray | None = None
    solver: Solver = field(init=False, repr=False)
    #: why each closed-form family did not fit (empty when one did)
    not_closed_form: dict[str, str] = field(init=False, repr=False)
    _shift: np.ndarray = field(init=False, repr=False)
    #: inv(tool) and the tool it was computed from (:meth:`tool_inverse`)
    _tool_inv: tuple[bytes, np.ndarray] | None = field(init=False, repr=False, default=None)

    def __post_init__(self) -> None:
        """Check shapes, choose the IK solver, precompute the per-joint turn combinations."""
        self.dh = np.array(self.dh, dtype=float)
        self.limits = np.array(self.limits, dtype=float)
        self.base = np.array(self.base, dtype=float)
        self.tool = np.array(self.tool, dtype=float)
        for what, arr, shape in (("dh", self.dh, (6, 4)), ("limits", self.limits, (6, 2)),
                                 ("base", self.base, (4, 4)), ("tool", self.tool, (4, 4))):
            if arr.shape != shape or not np.all(np.isfinite(arr)):
                raise SparValueError(f"robot {self.name}: {what} must be a finite {shape} array, got {arr.shape}")
        if np.any(self.limits[:, 0] > self.limits[:, 1]):
            raise SparValueError(f"robot {self.name}: limits need lo <= hi")
        alpha, a = self.dh[:, 0], self.dh[:, 1]
        for i in range(1, 6):  # Craig row i holds alpha_{i-1}, a_{i-1}: axes i and i+1 (1-based: rows i, i+1)
            if abs(math.sin(alpha[i])) < 1e-12 and a[i] == 0.0:
                raise SparValueError(f"robot {self.name}: joints {i} and {i + 1} turn about the same line "
                                     f"(dh[{i}].alpha = {math.degrees(alpha[i]):g} deg and dh[{i}].a = 0): "
                                     "not a 6-DOF arm")
        self.joint_names = tuple(self.joint_names) or tuple(f"joint_{i}" for i in range(1, 7))
        self.solver, self.not_closed_form = solver_for(self.dh, self.base, self.tool, self.limits,
                                                       self.unit, self.family)
        self._shift = turn_combinations(self.limits)[:, None, None, :]  # (6, 1, 1, M)

    # ------------------------------------------------------------------ which solver

    @property
    def solver_name(self) -> str:
        """The IK solver, as plan output shows it: "closed-form puma", "closed-form ur" or "numeric"."""
        return f"closed-form {self.solver.family}" if self.solver.complete else self.solver.family

    # ------------------------------------------------------------------ forward kinematics

    def fk(self, q: np.ndarray) -> np.ndarray:
        """World pose of the tool (4x4, ``unit``) for joint vector q (6,) rad: base @ A1..A6 @ tool."""
        q = np.asarray(q, float)
        if q.shape != (6,):
            raise SparValueError(f"fk takes a joint vector of shape (6,), got {q.shape}")
        return self.fk_batch(q[None])[0]

    def fk_batch(self, q: np.ndarray) -> np.ndarray:
        """World tool poses (n, 4, 4) for joint vectors q (n, 6) rad, vectorised over n."""
        q = np.asarray(q, float)
        if q.ndim != 2 or q.shape[1] != 6:
            raise SparValueError(f"fk_batch takes joint vectors of shape (n, 6), got {q.shape}")
        A = craig_links(self.dh, q)
        T = self.base @ A[:, 0]
        for i in range(1, 6):
            T = T @ A[:, i]
        return T @ self.tool

    def frames_batch(self, q: np.ndarray) -> np.ndarray:
        """World frames (n, 8, 4, 4) for joint vectors q (n, 6) rad, as :meth:`frames` row by row."""
        q = np.asarray(q, float).reshape(-1, 6)
        A = craig_links(self.dh, q)
        out = np.empty((len(q), 8, 4, 4))
        out[:, 0] = self.base
        for i in range(6):
            out[:, i + 1] = out[:, i] @ A[:, i]
        out[:, 7] = out[:, 6] @ self.tool
        return out

    def tool_inverse(self) -> np.ndarray:
        """inv(tool), T_tool_flange (4x4), computed once per value of ``tool``."""
        key = self.tool.tobytes()
        if self._tool_inv is None or self._tool_inv[0] != key:
            self._tool_inv = (key, np.linalg.inv(self.tool))
        return self._tool_inv[1]

    def frames(self, q: np.ndarray) -> np.ndarray:
        """World frames (8, 4, 4) (``unit``) of the arm at joint vector q (6,) rad.

        Row 0 is ``base`` (T_world_frame0), rows 1..6 Craig's frames T_world_frame_i =
        base @ A_1..A_i (z_i is joint i's axis; frame 6 is the flange), row 7 the tool,
        ``frames[6] @ tool`` (equal to :meth:`fk`). Craig's frames whatever the table's
        source (a standard-DH file or a URDF is converted at load).
        """
        q = np.asarray(q, float)
        if q.shape != (6,):
            raise SparValueError(f"frames takes a joint vector of shape (6,), got {q.shape}")
        A = craig_links(self.dh, q[None])[0]
        out = np.empty((8, 4, 4))
        out[0] = self.base
        for i in range(6):
            out[i + 1] = out[i] @ A[i]
        out[7] = out[6] @ self.tool
        return out

    # ------------------------------------------------------------------ limits

    def in_limits(self, q: np.ndarray) -> np.ndarray | bool:
        """True where every joint of q (..., 6) rad lies within its limits (tolerance 1e-9 rad)."""
        q = np.asarray(q, float)
        ok = np.all((q >= self.limits[:, 0] - LIMIT_TOL) & (q <= self.limits[:, 1] + LIMIT_TOL), axis=-1)
        return bool(ok) if ok.ndim == 0 else ok

    @property
    def n_candidates(self) -> int:
        """Rows per pose of :meth:`ik_batch`: the solver's branches (8 for a closed form)."""
        return self.solver.n_branches

    # ------------------------------------------------------------------ inverse kinematics

    def _lowest(self, T: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Each branch's lowest representation >= lo: (q0 (6, n, B) rad, ok (n, B): a solution in limits)."""
        T = np.asarray(T, float)
        if T.ndim != 3 or T.shape[1:] != (4, 4):
            raise SparValueError(f"ik_batch takes poses of shape (n, 4, 4), got {T.shape}")
        theta, ok = self.solver.branches(T)
        lo = self.limits[:, 0, None, None]
        q0 = lowest_representation(theta - self.dh[:, 3, None, None], lo)
        return q0, ok & (q0 <= self.limits[:, 1, None, None] + LIMIT_TOL).all(axis=0)

    def ik_batch(self, T: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Every IK branch of n world tool poses, vectorised: ``(Q (n, B, 6) rad, ok (n, B) bool)``.

        ``B = self.n_candidates``: one row per distinct arm configuration (closed forms:
        the 8 branches, e.g. UR shoulder x wrist x elbow, see the family's module; numeric:
        one row per start, duplicates off), each at its lowest representation q + 2 pi k
        >= the lower limit. ``ok[i, b]`` is True iff row b is a solution of pose i inside
        the joint limits; rows with ok False hold garbage. :meth:`ik` adds the other
        in-limit full-turn representations of each row.
        """
        q0, ok = self._lowest(T)
        return q0.transpose(1, 2, 0), ok

    def reachable_mask(self, T: np.ndarray) -> np.ndarray:
        """(n,) bool: which world tool poses T (n, 4, 4) have at least one in-limit IK solution."""
        return self._lowest(T)[1].any(axis=1)

    def ik(self, T: np.ndarray) -> np.ndarray:
        """All in-limit joint vectors (k, 6) rad reaching the world tool pose T (4x4, ``unit``); (0, 6) if none.

        Every branch of :meth:`ik_batch` (in its order) with every combination of its
        joints' in-limit full-turn representations (a UR joint's +-360 deg range holds
        two of most angles), so a configuration reaching T is among the rows exactly.
        """
        T = check_transform(T, "ik: T")
        q0, ok = self._lowest(T[None])
        Q = q0[..., None] + self._shift  # (6, 1, B, M)
        V = ok[..., None] & (Q <= self.limits[:, 1, None, None, None] + LIMIT_TOL).all(axis=0)
        return Q.transpose(1, 2, 3, 0)[V]


# --------------------------------------------------------------------------- DH conventions


def standard_to_modified(dh: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """A standard-DH table (6, 4) rows (alpha_i, a_i, d_i, offset_i) -> (Craig's table, flange).

    Standard: T = prod rotz(theta_i) transz(d_i) transx(a_i) rotx(alpha_i). Regrouped,
    each ``transx(a_{i-1}) rotx(alpha_{i-1}) rotz(theta_i) transz(d_i)`` is Craig's link
    i, so Craig's row i has alpha = alpha_{i-1}, a = a_{i-1} (alpha_0 = a_0 = 0), the
    same d_i and offset_i, and ``flange = transx(a_6) rotx(alpha_6)`` is what is left
    over: it goes before the tool (T_flange_tool of Craig's frame 6 = flange @ tool).
    """
    dh = np.asarray(dh, float)
    out = np.zeros((6, 4))
    out[1:, 0], out[1:, 1] = dh[:5, 0], dh[:5, 1]
    out[:, 2], out[:, 3] = dh[:, 2], dh[:, 3]
    return out, trans(dh[5, 1], 0.0, 0.0) @ rotx(dh[5, 0])


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v)


def dh_from_axes(points: np.ndarray, dirs: np.ndarray, signs: tuple[int, ...] = (0, 0, 0, 0, 0),
                 tol: float = 1e-9) -> tuple[np.ndarray, np.ndarray]:
    """Craig's table of a 6R chain from its joint axes at q = 0: ``(dh (6, 4), F (7, 4, 4))``.

    ``points`` (6, 3) a point on each axis, ``dirs`` (6, 3) each axis direction (the
    joint's positive sense), in one frame (lengths in any unit, ``tol`` in it). Frame i
    has z_i along axis i and x_i along the common normal to axis i+1 (Craig, Sec. 3.4);
    the free choices: x_i's sign makes alpha_i's sign ``signs[i-1]`` where given (the
    family's), else alpha_i >= 0; parallel axes take the origin where x_{i-1} meets axis
    i (d_i = 0); frame 0 is frame 1 at q = 0; frame 6 has x_6 = x_5 (offset_6 = 0) and its
    origin where x_5 meets axis 6. Returns the table and Craig's frames 0..6 at q = 0 (in the
    frame the axes were given in).
    """
    z = np.array([_unit(d) for d in dirs])
    origin = np.zeros((7, 3))
    x = np.zeros((7, 3))
    foot = np.asarray(points[0], float)  # where x_{i-1} meets axis i (for axis 1: the given point)
    for i in range(5):
        p, q, u, w = foot, np.asarray(points[i + 1], float), z[i], z[i + 1]
        c = np.cross(u, w)
        if np.linalg.norm(c) > 1e-9:  # not parallel: the unique common normal
            r = q - p
            # closest points p + s u, q + t w: solve [u.u -u.w; u.w -w.w] [s t] = [r.u r.w]
            M = np.array([[1.0, -(u @ w)], [u @ w, -1.0]])
            s, t = np.linalg.solve(M, np.array([r @ u, r @ w]))
            o, f = p + s * u, q + t * w
            xi = _unit(f - o) if np.linalg.norm(f - o) > tol else _unit(c)
        else:  # parallel: the normal through this axis's foot
            o = p
            r = q - p
            perp = r - (r @ u) * u
            if np.linalg.norm(perp) <= tol:
                raise SparValueError(f"joints {i + 1} and {i + 2} turn about the same line (not a 6R arm "
                                     "spar-py can model)")
            xi = _unit(perp)
            f = o + perp
        want = signs[i] if i < len(signs) else 0
        alpha = math.atan2(np.cross(u, w) @ xi, u @ w)
        if (want and math.copysign(1, alpha) != want and abs(alpha) > 1e-12) or (not want and alpha < -1e-12):
            xi = -xi
        origin[i + 1], x[i + 1] = o, xi
        foot = f
    origin[6], x[6] = foot, x[5] - (x[5] @ z[5]) * z[5]
    if np.linalg.norm(x[6]) <= tol:  # x_5 along axis 6 cannot happen: x_5 is normal to it
        raise SparValueError("joint 6's axis is degenerate")
    x[6] = _unit(x[6])
    F = np.zeros((7, 4, 4))
    for i in range(1, 7):
        F[i, :3, 0], F[i, :3, 2], F[i, :3, 3] = x[i], z[i - 1], origin[i]
        F[i, :3, 1] = np.cross(z[i - 1], x[i])
        F[i, 3, 3] = 1.0
    F[0] = F[1]
    dh = np.zeros((6, 4))
    for i in range(1, 7):
        R = inv(F[i - 1]) @ F[i]  # = rotx(alpha) transx(a) rotz(theta) transz(d)
        alpha = math.atan2(-R[1, 2], R[2, 2])
        dh[i - 1] = (alpha, R[0, 3], -math.sin(alpha) * R[1, 3] + math.cos(alpha) * R[2, 3],
                     math.atan2(-R[0, 1], R[0, 0]))
    # a length within tol of 0 is 0 (a URDF's calibration residue, 2e-11 m, must not cost a closed
    # form) and a twist within 1e-9 rad of a multiple of 90 deg is that multiple (URDFs write
    # pi/2 as 1.570796327): the model is the nearest arm of exact structure, and the FK check
    # against the URDF (check_against_urdf) bounds what that moves
    dh[:, 1:3][np.abs(dh[:, 1:3]) <= tol] = 0.0
    quarter = np.round(dh[:, 0] / (math.pi / 2)) * (math.pi / 2)
    dh[:, 0] = np.where(np.abs(dh[:, 0] - quarter) <= 1e-9, quarter, dh[:, 0])
    return dh, F


# --------------------------------------------------------------------------- URDF


@dataclass(frozen=True)
class UrdfChain:
    """The serial chain base_link -> tip_link of a URDF: the six revolute joints in order.

    ``origins`` (6, 4, 4) each joint's frame in its parent link frame, ``axes`` (6, 3) in
    the joint frame, ``limits`` (6, 2) rad, ``tip`` (4x4) the tip link in the last joint's
    child frame (fixed joints folded in), ``children`` each joint's child link; lengths m.
    """

    file: str
    robot_name: str
    base_link: str
    tip_link: str
    names: tuple[str, ...]
    children: tuple[str, ...]
    origins: np.ndarray
    axes: np.ndarray
    limits: np.ndarray
    tip: np.ndarray
    #: joints between base_link and tip_link whose limits were missing (continuous): +-360 deg used
    unlimited: tuple[str, ...] = ()
    #: the parsed URDF (a yourdfpy.URDF), for its own FK in check_against_urdf
    model: object = field(default=None, compare=False, repr=False)
    #: links rigid with a chain link by fixed joints (UR's base_link above ``base``, flange, tool0,
    #: a tool's links): (link, k, T) with T its pose in base_link (k = 0) or in joint k's child (m)
    fixed: tuple = field(default=(), compare=False, repr=False)

    def link_frames(self, q: np.ndarray) -> np.ndarray:
        """(7, 4, 4): each joint's child link frame in base_link, then the tip, for q (6,) rad (m)."""
        out = np.empty((7, 4, 4))
        T = np.eye(4)
        for i in range(6):
            T = T @ self.origins[i] @ _axis_rotation(self.axes[i], q[i])
            out[i] = T
        out[6] = T @ self.tip
        return out


def _axis_rotation(axis: np.ndarray, angle: float) -> np.ndarray:
    """Rotation about a unit axis by angle (Rodrigues), 4x4."""
    k = axis
    K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    T = np.eye(4)
    T[:3, :3] = np.eye(3) + math.sin(angle) * K + (1 - math.cos(angle)) * (K @ K)
    return T


def _load_urdf(path: Path):  # -> yourdfpy.URDF
    """yourdfpy's model of the file; SparValueError (one line) when it is not well-formed XML
    (lxml's message, with its line and column) or yourdfpy cannot read it. yourdfpy's own log
    lines (it retries a broken file with a recovering parser and logs each attempt) are kept
    off stderr while it reads: the error says it once."""
    import logging  # only while yourdfpy reads: a cold plan never loads it

    import yourdfpy  # lazily: only a URDF robot pays for it (and for lxml, trimesh)
    from lxml import etree

    try:
        etree.parse(str(path))
    except etree.XMLSyntaxError as e:
        raise SparValueError(f"a well-formed URDF (XML) file ({e})") from None
    log = logging.getLogger(yourdfpy.urdf.__name__)
    was = log.disabled
    log.disabled = True
    try:
        return yourdfpy.URDF.load(str(path), build_scene_graph=True, load_meshes=False,
                                  load_collision_meshes=False)
    except Exception as e:  # yourdfpy raises lxml, ValueError, its own URDFError...: one line
        raise SparValueError(f"a URDF yourdfpy can read ({type(e).__name__}: {e})") from None
    finally:
        log.disabled = was


def read_urdf_chain(path: str | Path, base_link: str, tip_link: str) -> UrdfChain:
    """The chain base_link -> tip_link of a URDF file; SparValueError (one line, naming the link or
    joint) when a link is unknown, the tip is not below the base, or the chain is not 6 revolute joints."""
    path = Path(path)
    urdf = _load_urdf(path)
    links = {lk.name for lk in urdf.robot.links}
    for what, name in (("base_link", base_link), ("tip_link", tip_link)):
        if name not in links:
            raise SparValueError(f"{what} {name!r}: a link of the URDF (it has {', '.join(sorted(links))})")
    by_child = {}
    for j in urdf.robot.joints:
        if j.child in by_child:
            raise SparValueError(f"link {j.child!r} has two parent joints: not a tree (not serial)")
        by_child[j.child] = j
    # base_link may hang off the chain by fixed joints (UR's "base" frame beside base_link):
    # the fixed links above it, with T_base_link_ancestor for each
    above = {base_link: np.eye(4)}
    link, T = base_link, np.eye(4)
    while link in by_child and by_child[link].type == "fixed":
        j = by_child[link]
        T = (np.eye(4) if j.origin is None else np.asarray(j.origin, float)) @ T  # T_parent_base_link
        link = j.parent
        above[link] = inv(T)
    chain = []
    link = tip_link
    while link not in above:
        if link not in by_child:
            raise SparValueError(f"tip_link {tip_link!r} is not below base_link {base_link!r}: no serial chain "
                                 "between them")
        chain.append(by_child[link])
        link = by_child[link].parent
    chain.reverse()
    lead = above[link]  # T_base_link_root, root the link where the chain starts
    moving = [j for j in chain if j.type != "fixed"]
    bad = [f"{j.name} ({j.type})" for j in moving if j.type not in ("revolute", "continuous")]
    if bad or len(moving) != 6:
        raise SparValueError(f"a serial arm of 6 revolute joints from {base_link} to {tip_link} (spar-py "
                             f"plans with 6R arms), not {len(moving)} moving joints"
                             + (f" with {', '.join(bad)}" if bad else ""))
    mimic = [j.name for j in moving if j.mimic is not None]
    if mimic:
        raise SparValueError(f"joint {mimic[0]!r} mimics another: not 6 independent joints")
    names, children, origins, axes, limits, unlimited = [], [], [], [], [], []
    # links rigid with base_link (k = 0) or joint k's child, T their pose there
    rigid = {name: (0, T_b) for name, T_b in above.items()}
    pending = lead  # base_link -> the chain's root, then fixed joints before the next moving one
    for j in chain:
        origin = np.eye(4) if j.origin is None else np.asarray(j.origin, float)
        if j.type == "fixed":
            pending = pending @ origin
            rigid[j.child] = (len(names), pending.copy())
            continue
        axis = np.array([1.0, 0.0, 0.0]) if j.axis is None else np.asarray(j.axis, float)
        if not np.linalg.norm(axis) > 0:
            raise SparValueError(f"joint {j.name!r}: a non-zero axis")
        lo = hi = None
        if j.type == "revolute" and j.limit is not None:
            lo, hi = j.limit.lower, j.limit.upper
        if lo is None or hi is None:
            unlimited.append(j.name)
            lo, hi = -2 * math.pi, 2 * math.pi
        names.append(j.name)
        children.append(j.child)
        origins.append(pending @ origin)
        axes.append(_unit(axis))
        limits.append((float(lo), float(hi)))
        pending = np.eye(4)
        rigid[j.child] = (len(names), pending)
    todo = list(rigid)  # and whatever hangs off those links by fixed joints only
    while todo:
        parent = todo.pop()
        for j in urdf.robot.joints:
            if j.parent == parent and j.type == "fixed" and j.child not in rigid:
                k, T_p = rigid[parent]
                rigid[j.child] = (k, T_p @ (np.eye(4) if j.origin is None else np.asarray(j.origin, float)))
                todo.append(j.child)
    fixed = tuple((name, k, T_k) for name, (k, T_k) in rigid.items() if name != base_link and name not in children)
    return UrdfChain(str(path), str(urdf.robot.name), base_link, tip_link, tuple(names), tuple(children),
                     np.array(origins), np.array(axes), np.array(limits), pending, tuple(unlimited), urdf, fixed)


def robot_from_urdf(chain: UrdfChain, name: str, base: np.ndarray, tool: np.ndarray, finger_separation: float,
                    unit: str, mm_per_unit: float, limits: np.ndarray | None = None, family: str = "auto") -> Robot:
    """The :class:`Robot` of a URDF chain: Craig's table from the joint axes (each closed-form
    family's sign choices tried first), lengths converted from metres to ``unit`` (``mm_per_unit``
    mm each); ``base`` is T_world_base_link, ``tool`` T_tip_link_tool (``unit``); ``limits``
    (rad) override the URDF's; ``family`` as for :class:`Robot`. The model's FK is then checked against the URDF's own
    (:func:`check_against_urdf`)."""
    F = chain.link_frames(np.zeros(6))
    joint_frames = [np.eye(4) if i == 0 else F[i - 1] for i in range(6)]
    joint_frames = [Fp @ chain.origins[i] for i, Fp in enumerate(joint_frames)]
    s = 1000.0 / mm_per_unit  # unit per metre
    points = np.array([Tj[:3, 3] for Tj in joint_frames]) * s
    dirs = np.array([Tj[:3, :3] @ chain.axes[i] for i, Tj in enumerate(joint_frames)])
    lim = chain.limits if limits is None else np.asarray(limits, float)
    tip0 = F[6].copy()
    tip0[:3, 3] *= s
    robot = None
    tries = [_FAMILY_SIGNS[family]] if family in _FAMILY_SIGNS else list(_FAMILY_SIGNS.values())
    for signs in tries + [(0, 0, 0, 0, 0)]:
        dh, F = dh_from_axes(points, dirs, signs, tol=1e-9 * max(1.0, float(np.abs(points).max())))
        robot = Robot(name, dh, lim, base @ F[0], inv(F[6]) @ tip0 @ tool, finger_separation, unit,
                      family=family, joint_names=chain.names)
        if robot.solver.complete:
            break
    assert robot is not None
    # each joint's child link in Craig's frame i, from the conversion's own frames at q = 0
    child0 = [Fc.copy() for Fc in chain.link_frames(np.zeros(6))[:6]]
    for Fc in child0:
        Fc[:3, 3] *= s
    offsets = np.array([inv(F[i + 1]) @ child0[i] for i in range(6)])
    check_against_urdf(robot, chain, base, tool, s, offsets)
    robot.links = _urdf_link_shapes(chain, robot, base, offsets, s)
    return robot


def _urdf_link_shapes(chain: UrdfChain, robot: Robot, base: np.ndarray, offsets: np.ndarray,
                      s: float) -> tuple[LinkShape, ...]:
    """The URDF's own collision geometry (cylinders, boxes, spheres, and meshes as the convex hulls
    of their vertices: :func:`_urdf_mesh_points`) of the
    base link, each joint's child link and the links rigid with them by fixed joints
    (``chain.fixed``: UR's base_link above ``base``, a tool's links), as :class:`LinkShape` in
    Craig's frames (``offsets`` (6, 4, 4): child link i in Craig's frame i+1; the base link is
    ``base`` in the world), in the robot's unit (``s`` unit per metre). A cylinder becomes a
    cylinder along its own axis, a box an axis-aligned box where its axes are the frame's (else
    the hull of its eight corners: exact either way), a sphere a capsule of zero length."""
    urdf = chain.model if chain.model is not None else _load_urdf(Path(chain.file))
    by_name = {lk.name: lk for lk in urdf.robot.links}
    to_frame0 = inv(robot.base) @ base
    owners = [(chain.base_link, 0, to_frame0)] + [(c, i + 1, offsets[i]) for i, c in enumerate(chain.children)]
    for link, k, T_k in chain.fixed:
        T = np.array(T_k, float)
        T[:3, 3] *= s
        owners.append((link, k, (to_frame0 if k == 0 else offsets[k - 1]) @ T))
    out: list[LinkShape] = []
    for link, frame, T_frame_link in owners:
        for k, col in enumerate(by_name[link].collisions if link in by_name else []):
            origin = np.eye(4) if col.origin is None else np.array(col.origin, float)
            origin[:3, 3] *= s
            T = T_frame_link @ origin
            g = col.geometry
            name = link if k == 0 else f"{link}_{k}"
            if g.cylinder is not None:
                h = g.cylinder.length * s / 2
                a, b = T[:3, 3] - h * T[:3, 2], T[:3, 3] + h * T[:3, 2]
                out.append(LinkShape(name, frame, "cylinder", a, b, g.cylinder.radius * s))
            elif g.sphere is not None:
                out.append(LinkShape(name, frame, "capsule", T[:3, 3], T[:3, 3], g.sphere.radius * s))
            elif g.box is not None:
                half = np.asarray(g.box.size, float) * s / 2
                corners = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)]) * half
                P = corners @ T[:3, :3].T + T[:3, 3]  # the box's corners in Craig's frame
                R = T[:3, :3]
                if np.allclose(np.abs(R).round(), np.abs(R), atol=1e-9):
                    # axes along the frame's (any turn by quarter turns, e.g. UR's base turned by
                    # pi): the same box, axis-aligned in the frame
                    out.append(LinkShape(name, frame, "box", P.min(0), P.max(0)))
                else:  # turned otherwise: the exact box as the hull of its corners
                    out.append(LinkShape(name, frame, "hull", P.min(0), P.max(0), 0.0, P))
            elif g.mesh is not None:
                P = _urdf_mesh_points(Path(chain.file), link, g.mesh) * s
                P = P @ T[:3, :3].T + T[:3, 3]
                out.append(LinkShape(name, frame, "hull", P.min(0), P.max(0), 0.0, P))
    return tuple(out)


class UrdfMeshError(SparValueError):
    """A URDF collision mesh that cannot be found or read (the message names the link)."""


def _urdf_mesh_points(urdf_file: Path, link: str, mesh: Any) -> np.ndarray:
    """The vertices (k, 3), metres, in the collision element's frame, of the convex hull of a
    URDF collision mesh (``<mesh filename=... scale=...>``: STL, OBJ or PLY, read by trimesh).
    The file is found relative to the URDF; a ``package://PKG/rest`` name as ``rest`` under the
    URDF's folder or one of its parents, or PKG/rest beside them. A mesh that cannot be found
    or read is an error naming the link: a link silently without its shape would plan through
    the table."""
    name = str(mesh.filename)
    candidates: list[Path] = []
    if name.startswith("package://"):
        pkg, _, rest = name[len("package://"):].partition("/")
        for d in [urdf_file.parent, *urdf_file.parent.parents]:
            candidates += [d / rest, d / pkg / rest]
    elif name.startswith("file://"):
        candidates.append(Path(name[len("file://"):]))
    else:
        candidates.append(urdf_file.parent / name)
    found = next((c for c in candidates if c.is_file()), None)
    if found is None:
        raise UrdfMeshError(f"link {link!r}: collision mesh {name!r} not found "
                             f"(expected a file relative to the URDF)")
    import trimesh  # lazily: only a URDF with collision meshes pays for it

    try:
        m = trimesh.load(str(found), force="mesh")
        P = np.asarray(m.convex_hull.vertices, float)
    except Exception as e:  # a format trimesh cannot read (e.g. .dae without pycollada)
        raise UrdfMeshError(f"link {link!r}: collision mesh {found.name!r} cannot be read "
                             f"({type(e).__name__}: {str(e).splitlines()[0] if str(e) else 'no detail'}); "
                             f"expected STL, OBJ or PLY") from None
    if len(P) < 4:
        raise UrdfMeshError(f"link {link!r}: collision mesh {found.name!r} has no volume")
    scale = getattr(mesh, "scale", None)
    if scale is not None:
        P = P * np.broadcast_to(np.asarray(scale, float), (3,))
    return P


def check_against_urdf(robot: Robot, chain: UrdfChain, base: np.ndarray, tool: np.ndarray, unit_per_m: float,
                       offsets: np.ndarray, n: int = 50, seed: int = 0) -> None:
    """Compare the model with the URDF's own FK (yourdfpy's scene graph) at q = 0 and n random
    in-limit configurations: joint i's child link must be Craig's frame i @ ``offsets[i]`` (the
    conversion's, (6, 4, 4)), and the tool base @ T_base_tip @ tool (``tool`` T_tip_tool). SparValueError
    names the first joint that differs (within 1e-6 of the arm's length)."""
    urdf = chain.model if chain.model is not None else _load_urdf(Path(chain.file))
    rng = np.random.default_rng(seed)
    qs = np.vstack([np.zeros(6), rng.uniform(robot.limits[:, 0], robot.limits[:, 1], size=(n, 6))])
    actuated = list(urdf.actuated_joint_names)
    scale = np.diag([unit_per_m, unit_per_m, unit_per_m, 1.0])
    tol = 1e-6 * (1.0 + float(np.abs(robot.dh[:, 1:3]).sum()))
    C = offsets
    for q in qs:
        cfg = np.zeros(len(actuated))
        for i, jn in enumerate(chain.names):
            cfg[actuated.index(jn)] = q[i]
        urdf.update_cfg(cfg)
        # the URDF's own FK, in metres, base_link frame -> world (unit)
        own = [base @ _scaled(urdf.get_transform(c, chain.base_link), scale) for c in chain.children]
        own.append(base @ _scaled(urdf.get_transform(chain.tip_link, chain.base_link), scale))
        ours = robot.frames(q)
        for i in range(6):
            err = np.abs(ours[i + 1] @ C[i] - own[i]).max()
            if err > tol:
                raise SparValueError(f"joint {chain.names[i]!r}: the converted model's link frame differs from "
                                     f"the URDF's own FK by {err:.3g} at q = {np.round(q, 4).tolist()} rad")
        err = np.abs(ours[7] - own[6] @ tool).max()
        if err > tol:
            raise SparValueError(f"tip_link {chain.tip_link!r}: the converted model's tool differs from the "
                                 f"URDF's own FK by {err:.3g} at q = {np.round(q, 4).tolist()} rad")


def _scaled(T: np.ndarray, S: np.ndarray) -> np.ndarray:
    """T (4x4, metres) with its translation in the model's unit (S = diag(s, s, s, 1))."""
    T = np.array(T, float)
    T[:3, 3] = S[:3, :3] @ T[:3, 3]
    return T
