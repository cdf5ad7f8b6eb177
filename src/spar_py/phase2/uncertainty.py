"""World uncertainty, its propagation by actions, and the uncertainty-reduction preconditions.

This is the numeric side of the paper's Secs. 3.2 and 4.3 (phase 2 of planning; the
planner's control is prolog/uncertainty.pl). Conventions: world Z up, table top z = 0;
4x4 homogeneous transforms with column vectors (``T_world_obj``); lengths in the cell
unit (the paper's cell: inches), angles in radians.

Uncertain quantities are CasADi SX expressions in bounded uncertainty variables made
by a :class:`~spar_py.phase2.symbolic.Registry` (Fig. 11's supinf facts). An object's error is
an :class:`ErrorTm`, ``trans(dx, dy, dz) @ rotz(theta)`` (Fig. 11's ErrTm), read

* on the table, in the world frame: ``dx, dy, dz`` is ``Tr_dO`` and ``theta`` the rotation
  about the world z axis through the object's origin (``R_dO``), so the possible pose is
  Eq. 2: ``T_{O+d} = Tr_dO Tr_O R_dO R_O``;
* in the hand, in the tool (manipulator) frame: the paper's ``T_dO``, so the possible
  pose is Eq. 4: ``T_{O+d} = T_M T_dO T_G^-1`` with ``T_M = T_O T_G`` the ideal tool pose.

The manipulator's own error ``T_dM`` (Sec. 3.2.1) is an ErrorTm in the tool frame:
rotation by ``thetagr`` about tool z and the tool-centre offset ``dxgr, dygr, dzgr``;
each manipulation gets fresh manipulator variables (one motion's error is independent
of another's), shared by that action's preconditions and its effect.

:class:`WorldState` is immutable; the actions (:func:`pickup`, :func:`putdown`,
:func:`squeeze`, :func:`dense_range_scan`, :func:`assemble`) return updated copies.
:func:`pickup_constraints` and :func:`assemble_constraints` build the inequalities of
Sec. 3.2.2 as :class:`Constraint` records; :func:`evaluate` decides one with SUP/INF.

Built once per structure: every error transform the actions make records how it was
made (``ErrorTm.shape``, plain data) and from which fresh variables (``ErrorTm.vars``).
Given a cell cache's memo, the constraint builders make a structure's expressions once and,
for the next part alike in its history (many identical pegs), evaluate that first
build on the new variables: the same graph node for node, so SUP/INF's answers are
unchanged, at a fraction of the CasADi products' cost (:func:`_built`).
"""
from __future__ import annotations

import math
import re
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from types import MappingProxyType
from typing import Any

import casadi as ca
import numpy as np

from spar_py.core.errors import SparValueError
from spar_py.core.model import Bounds, Cell, MatingFeature
from spar_py.core.memo import Memo
from spar_py.phase2.supinf import cached_bounds
from spar_py.phase2.symbolic import Matrix, Registry, Scalar, apply, as_sx, compose, inv, rotz, snap, trans

__all__ = [
    "Attachment",
    "Constraint",
    "ErrorTm",
    "ObjectState",
    "Verdict",
    "WorldState",
    "assemble",
    "assemble_constraints",
    "dense_range_scan",
    "evaluate",
    "evaluate_all",
    "initial_world",
    "manipulator_error",
    "pickup",
    "pickup_constraints",
    "putdown",
    "squeeze",
    "table_error",
]

TABLE, HAND, ASSEMBLED = "table", "hand", "assembled"
_IDENT = re.compile(r"[^A-Za-z0-9_]")


# ------------------------------------------------------------------ error transforms


@dataclass(frozen=True)
class ErrorTm:
    """An error transform ``trans(dx, dy, dz) @ rotz(theta)`` (Fig. 11's ErrTm).

    Entries are SX expressions (or numbers) in uncertainty variables; lengths in the cell
    unit, ``theta`` in radians. The frame it is read in depends on its use (module doc).
    """

    theta: Scalar
    dx: Scalar
    dy: Scalar
    dz: Scalar
    #: How the entries were made from ``vars`` (nested tuples of plain data; () unknown):
    #: two errors of equal ``shape`` are the same expressions up to a one-to-one renaming
    #: of their ``vars``, so what is built from them can be built once (:class:`_Recipes`).
    shape: tuple = field(default=(), compare=False, repr=False)
    #: The distinct variables (SX symbols) the entries are made of, in a fixed order.
    vars: tuple = field(default=(), compare=False, repr=False)

    def matrix(self) -> Matrix:
        """The 4x4 transform ``trans(dx, dy, dz) @ rotz(theta)``."""
        return compose(trans(self.dx, self.dy, self.dz), rotz(self.theta))

    def offset(self) -> Matrix:
        """The displacement (dx, dy, dz) as a 3x1 SX column."""
        return ca.vertcat(self.dx, self.dy, self.dz)

    def tm_rows(self) -> list[list[Scalar]]:
        """The paper's row form ``[[r1], [r2], [r3], [d]]`` of Fig. 11 (rows: images of x, y, z; offset)."""
        c, s = ca.cos(self.theta), ca.sin(self.theta)
        return [[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0], [self.dx, self.dy, self.dz]]


def _hint(obj: str) -> str:
    """An identifier fragment for an object name (variable names must be identifiers)."""
    return _IDENT.sub("_", obj) or "o"


def table_error(registry: Registry, obj: str, bounds: Bounds) -> ErrorTm:
    """Fresh world-frame error variables ``dx_<obj>, dy_<obj>, dz_<obj>, theta_<obj>`` with ``bounds``."""
    h = _hint(obj)
    return _fresh(registry.new(f"theta_{h}", *bounds.dtheta), registry.new(f"dx_{h}", *bounds.dx),
                  registry.new(f"dy_{h}", *bounds.dy), registry.new(f"dz_{h}", *bounds.dz))


def manipulator_error(registry: Registry, bounds: Bounds) -> ErrorTm:
    """Fresh manipulator error variables ``dxgr, dygr, dzgr, thetagr`` (Table 2's names): T_dM."""
    return _fresh(registry.new("thetagr", *bounds.dtheta), registry.new("dxgr", *bounds.dx),
                  registry.new("dygr", *bounds.dy), registry.new("dzgr", *bounds.dz))


def _fresh(theta: ca.SX, dx: ca.SX, dy: ca.SX, dz: ca.SX) -> ErrorTm:
    """An error transform whose entries are four fresh variables."""
    return ErrorTm(theta, dx, dy, dz, shape=("fresh",), vars=(theta, dx, dy, dz))


# ------------------------------------------------------------------ world state


@dataclass(frozen=True)
class ObjectState:
    """One object's ideal pose and error.

    ``where`` is 'table', 'hand' or 'assembled'. ``pose`` is the ideal ``T_world_obj``
    (4x4). ``error`` is world-frame on the table, tool-frame otherwise (the paper's
    ``T_dO``). ``grasp`` is ``T_G``, the tool frame in the object frame, while the error
    is tool-frame (held or assembled), else None.
    """

    name: str
    where: str
    pose: np.ndarray
    error: ErrorTm
    grasp: np.ndarray | None = None

    def possible(self) -> Matrix:
        """The possible pose ``T_{O+d}`` (4x4 SX, world): Eq. 2 on the table, Eq. 4 otherwise."""
        if self.where == TABLE:
            e = self.error
            Tr_O = trans(*self.pose[:3, 3])
            R_O = snap(self.pose).copy()
            R_O[:3, 3] = 0.0
            return compose(trans(e.dx, e.dy, e.dz), Tr_O, rotz(e.theta), R_O)
        T_G = self.grasp
        return compose(self.pose, T_G, self.error.matrix(), inv(T_G))

    def possible_rel(self) -> Matrix:
        """:meth:`possible` with the ideal pose's translation ``t_O`` taken out (4x4 SX):
        ``trans(-t_O) @ T_{O+d}``, built so that ``t_O`` never enters the expression
        (translations commute: on the table ``trans(d) Tr_O X = Tr_O trans(d) X``).

        Differences and relative poses of points of this object and of frames given
        relative to its ideal pose are then free of where the object stands, so two
        objects alike up to their places give equal expressions (and share SUP/INF
        results by supinf.cached_bounds), and no large world constant cancels in floats.
        """
        if self.where == TABLE:
            e = self.error
            R_O = snap(self.pose).copy()
            R_O[:3, 3] = 0.0
            return compose(trans(e.dx, e.dy, e.dz), rotz(e.theta), R_O)
        T_G = self.grasp
        return compose(_rotation_only(self.pose), T_G, self.error.matrix(), inv(T_G))


@dataclass(frozen=True)
class Attachment:
    """A part mated into another: ``parent`` the part it went into (or onto), ``rel`` its pose
    relative to the parent, T_parent_child (4x4: the assemble's T_a), ``retention`` 'loose' (held
    by gravity) or 'fixed', ``direction`` the insertion direction in the parent's frame (unit: the
    way the child moved into the parent, V_a), ``clearance`` the mate's radial clearance R_h - R_p
    (cell unit, >= 0; the child's pose error across the axis relative to the parent, bounded by
    it), ``axis`` the mate's axis in the parent's frame (unit; None: no insertion, a seat) and
    ``mate`` how messages name it (``pin_b in block.bore_b``)."""

    parent: str
    rel: np.ndarray
    retention: str = "loose"
    direction: np.ndarray | None = None
    clearance: float = 0.0
    axis: np.ndarray | None = None
    mate: str = ""
    #: The clearance's error variables (across the axis, parent frame), fresh per assemble.
    offsets: tuple = field(default=(), compare=False, repr=False)


@dataclass(frozen=True)
class WorldState:
    """The uncertainty part of the world description: every object's :class:`ObjectState`.

    ``registry`` is the run's variable store (shared by all copies: bounds never change);
    ``manipulator`` the bounds of a fresh T_dM (Table 2: dxgr ... thetagr); ``attached`` the
    mates made so far, child -> :class:`Attachment`: mated parts are one rigid body, whose root
    (the part mated into nothing) is what the hand picks up and puts down, and every part of it
    moves with the root (its ideal pose is the root's times the attachments' ``rel`` down the
    tree).
    """

    registry: Registry
    manipulator: Bounds
    objects: Mapping[str, ObjectState] = field(default_factory=dict)
    attached: Mapping[str, Attachment] = field(default_factory=dict)

    def __post_init__(self) -> None:
        object.__setattr__(self, "objects", MappingProxyType(dict(self.objects)))
        object.__setattr__(self, "attached", MappingProxyType(dict(self.attached)))
        # asked at every step of a run: found once per state, not by a scan per question
        object.__setattr__(self, "_holding", next((n for n, o in self.objects.items() if o.where == HAND), None))

    def root(self, name: str) -> str:
        """The root of the body part ``name`` belongs to (itself when mated into nothing)."""
        while name in self.attached:
            name = self.attached[name].parent
        return name

    def children(self, name: str) -> list[str]:
        """The parts mated directly into ``name``, in the order they were mated."""
        return [c for c, a in self.attached.items() if a.parent == name]

    def body(self, name: str) -> list[str]:
        """Every part of the rigid body whose root is ``name``: the root first, then the parts
        mated into it (directly or transitively), depth first in the order they were mated."""
        out = [name]
        for c in self.children(name):
            out += self.body(c)
        return out

    def path_to_root(self, name: str) -> list[str]:
        """``name`` and the parts it is mated into, up to its body's root (that last)."""
        out = [name]
        while out[-1] in self.attached:
            out.append(self.attached[out[-1]].parent)
        return out

    def carried(self, name: str) -> list[str]:
        """The parts that move with ``name``'s body other than its root (``body`` less the root)."""
        return self.body(self.root(name))[1:]

    def moved(self, root: str, pose: np.ndarray) -> dict[str, ObjectState]:
        """The states of ``root``'s body with the root at ideal pose ``pose`` (4x4 world): each
        carried part at its parent's pose times its relative pose (their errors unchanged)."""
        out = {root: replace(self.obj(root), pose=pose)}
        for c in self.body(root)[1:]:
            a = self.attached[c]
            out[c] = replace(self.obj(c), pose=snap(out[a.parent].pose @ a.rel))
        return out

    def possible_rel(self, name: str) -> Matrix:
        """``name``'s possible pose with its ideal translation taken out (ObjectState.possible_rel),
        composed through the mates for a carried part: its parent's possible pose times
        ``trans(c)`` (the mate's clearance, across the mate's axis in the parent's frame, its own
        bounded error variables) times the relative pose T_a. Relative to the ideal translation
        t_X: ``trans(t_P - t_X) possible_rel(P) trans(c) T_a``."""
        a = self.attached.get(name)
        if a is None:
            return self.obj(name).possible_rel()
        P = self.possible_rel(a.parent)
        shift = trans(*(self.obj(a.parent).pose[:3, 3] - self.obj(name).pose[:3, 3]))
        clr = _clearance_offset(a)
        return compose(shift, P, clr, a.rel)

    def errors_of(self, name: str) -> tuple[ErrorTm, ...]:
        """The error transforms :meth:`possible_rel` of ``name`` is built from (the root's, each
        mate's clearance variables as a transform's), for the structure memo."""
        a = self.attached.get(name)
        if a is None:
            return (self.obj(name).error,)
        return self.errors_of(a.parent) + ((_clearance_error(a),) if a.offsets else ())

    def obj(self, name: str) -> ObjectState:
        """The state of object ``name`` (SparValueError if unknown)."""
        try:
            return self.objects[name]
        except KeyError:
            raise SparValueError(f"no object {name!r} in the world state "
                                 f"(known: {', '.join(sorted(self.objects))})") from None

    def with_object(self, o: ObjectState) -> WorldState:
        """A copy with ``o`` replacing the state of the object of the same name."""
        return replace(self, objects={**self.objects, o.name: o})

    def manipulator_error(self) -> ErrorTm:
        """Fresh manipulator error variables for one motion (see :func:`manipulator_error`)."""
        return manipulator_error(self.registry, self.manipulator)

    @property
    def holding(self) -> str | None:
        """The name of the object in the hand, or None."""
        return self._holding  # type: ignore[attr-defined]


def initial_world(cell: Cell, registry: Registry | None = None,
                  active: Mapping[str, str] | None = None) -> WorldState:
    """The initial world of ``cell``: each object on the table at its initial position with
    fresh error variables bounded by the cell's object bounds (Table 2).

    An object with several initial positions (a stock of identical parts) has one state
    per part: the part at initial position ``active[obj]`` (default: the first listed)
    under the object's name, every other under ``"<obj>@<position name>"``.
    """
    reg = registry if registry is not None else Registry()
    active = dict(active or {})
    objs: dict[str, ObjectState] = {}
    for pos in cell.positions.values():
        if pos.obj not in cell.object_bounds:
            raise SparValueError(f"no uncertainty bounds for object {pos.obj!r}")
        active.setdefault(pos.obj, pos.name)
        key = pos.obj if active[pos.obj] == pos.name else f"{pos.obj}@{pos.name}"
        objs[key] = ObjectState(key, TABLE, _pose(pos.T, pos.name),
                                table_error(reg, key, cell.object_bounds[pos.obj]))
    return WorldState(reg, cell.manipulator_bounds, objs)


def _clearance_offset(a: Attachment) -> Matrix:
    """trans(c) of attachment ``a``'s clearance variables (parent frame), identity without them."""
    if not a.offsets:
        return np.eye(4)
    u, v = _across(np.asarray(a.axis, float))
    c = [u[i] * a.offsets[0] + v[i] * a.offsets[1] for i in range(3)]
    return trans(*c)


def _clearance_error(a: Attachment) -> ErrorTm:
    """Attachment ``a``'s clearance variables as an error transform (only its ``shape`` and
    ``vars`` are read: the structure memo's key)."""
    cx, cy = a.offsets
    return ErrorTm(0.0, cx, cy, 0.0, shape=("clearance", np.asarray(a.axis, float).tobytes()), vars=(cx, cy))


def _pose(T: Any, what: str) -> np.ndarray:
    A = np.asarray(T, float)
    if A.shape != (4, 4) or not np.isfinite(A).all():
        raise SparValueError(f"{what}: a pose must be a finite 4x4 transform")
    return snap(A)


def _on_table(state: WorldState, obj: str, action: str) -> ObjectState:
    o = state.obj(obj)
    if o.where != TABLE:
        raise SparValueError(f"{action}({obj}): the object must be on the table, it is {o.where}")
    return o


def _in_hand(state: WorldState, obj: str, action: str) -> ObjectState:
    o = state.obj(obj)
    if o.where != HAND:
        raise SparValueError(f"{action}({obj}): the object must be held, it is {o.where}")
    return o


def _rotation_only(T: np.ndarray) -> np.ndarray:
    """A copy of the 4x4 transform ``T`` with its translation set to zero."""
    A = np.array(T, float)
    A[:3, 3] = 0.0
    return A


def _vec(R: np.ndarray, v: Matrix) -> list[Scalar]:
    """R (3x3 numeric) times the SX column v, as three scalars."""
    w = ca.mtimes(as_sx(R), as_sx(v))
    return [w[i] for i in range(3)]


# ------------------------------------------------------------------ propagation (Sec. 3.2.3)


def pickup(state: WorldState, obj: str, grasp_T: np.ndarray, manip: ErrorTm, memo: Memo | None = None) -> WorldState:
    """The world after ``pickup(obj, grasp)`` with T_G ``grasp_T`` and the motion's error ``manip``.

    Sec. 3.2.3: the world displacement error is taken into the tool frame,
    ``[D_x, D_y, D_z] = (R_O R_G)^-1 Tr_dO [0, 0, 0, 1]^t``; the fingers then limit the y
    component to the manipulator's, and the rotation to the manipulator's:
    ``T_dO = trans(D_x + dxgr, dygr, D_z + dzgr) @ rotz(thetagr)``. The paper prints the
    rotation block as [[cos, sin], [sin, cos]], which is no rotation (a typo); we use
    the proper rotation [[cos, -sin], [sin, cos]], the same as its T_dM. As in the paper,
    the object's own angle error and its lever arm are dropped (the grasp re-seats it).
    ``memo`` (world.run.CellCache.memo): the entries are built once per structure (:func:`_built`).
    """
    o = _on_table(state, obj, "pickup")
    if state.holding is not None:
        raise SparValueError(f"pickup({obj}): the hand already holds {state.holding}")
    T_G = _pose(grasp_T, f"pickup({obj}) grasp")
    R = snap(o.pose[:3, :3] @ T_G[:3, :3])

    def build() -> list[ca.SX]:
        D = _vec(R.T, o.error.offset())
        return [manip.theta, D[0] + manip.dx, manip.dy, D[2] + manip.dz]

    step = ("pickup", R.tobytes())
    (theta, dx, dy, dz), _ = _built(state.registry, memo, ("effect", *step), (o.error, manip), build, key_out=False)
    err = ErrorTm(theta=theta, dx=dx, dy=dy, dz=dz, **_derived(step, o.error, manip))
    return state.with_object(ObjectState(obj, HAND, o.pose, err, T_G))


def putdown(state: WorldState, obj: str, pose: np.ndarray, memo: Memo | None = None) -> WorldState:
    """The world after ``putdown(obj, position)``, ``pose`` the position's ideal T_world_obj.

    Sec. 3.2.3: the held (tool-frame) displacement error goes to the world frame,
    ``D = (R_O R_G) [dx, dy, dz]`` with R_O the new orientation; the rotation error
    about tool z becomes one about world z, ``dtheta = Z * thetagr`` with Z the world-z
    component of the tool z axis, ``(R_O R_G)[2, 2]``. ``memo`` as :func:`pickup`.
    """
    o = _in_hand(state, obj, "putdown")
    T = _pose(pose, f"putdown({obj}) position")
    R = snap(T[:3, :3] @ o.grasp[:3, :3])

    def build() -> list[ca.SX]:
        D = _vec(R, o.error.offset())
        Z = float(R[2, 2])
        return [Z * o.error.theta, D[0], D[1], D[2]]

    step = ("putdown", R.tobytes())
    (theta, dx, dy, dz), _ = _built(state.registry, memo, ("effect", *step), (o.error,), build, key_out=False)
    err = ErrorTm(theta=theta, dx=dx, dy=dy, dz=dz, **_derived(step, o.error))
    body = state.moved(obj, T)
    body[obj] = ObjectState(obj, TABLE, T, err, None)
    return replace(state, objects={**state.objects, **body})


def squeeze(state: WorldState, obj: str, grasp_T: np.ndarray, manip: ErrorTm, memo: Memo | None = None) -> WorldState:
    """The world after squeezing ``obj`` between the fingers in place (grasp, then release).

    Sec. 4.3: the reduction is the pickup's; the object stays at its ideal pose on the
    table, with the reduced error mapped back to the world as a putdown does. ``memo`` as
    :func:`pickup`.
    """
    o = _on_table(state, obj, "squeeze")
    return putdown(pickup(state, obj, grasp_T, manip, memo), obj, o.pose, memo)


def dense_range_scan(state: WorldState, obj: str, leaves: Bounds) -> WorldState:
    """The world after ``dense_range_scan(obj)`` (Fig. 11): fresh error variables bounded by ``leaves``."""
    o = _on_table(state, obj, "dense_range_scan")
    return state.with_object(replace(o, error=table_error(state.registry, obj, leaves)))


def assemble(state: WorldState, peg: str, hole: str, T_a: np.ndarray, *, retention: str = "loose",
             direction: np.ndarray | None = None, clearance: float = 0.0, axis: np.ndarray | None = None,
             mate: str = "") -> WorldState:
    """The world after ``assemble(peg, hole, ..., T_a, ...)``: uncertainty unchanged (Sec. 3.2.3).

    The peg (the held part, with every part it carries) leaves the hand and is mated into
    ``hole`` (resting, or itself carried by a resting body): its ideal pose becomes ``T_H T_a``,
    its carried parts move with it, it keeps its tool-frame error and grasp (Eq. 4 at the
    assembled pose) and the world records the :class:`Attachment` (``retention``,
    ``direction``, ``clearance``, ``axis``, ``mate`` as there); with a clearance and an axis the
    mate gets two fresh error variables across the axis, bounded by the clearance
    (:meth:`WorldState.possible_rel`).
    """
    _in_hand(state, peg, "assemble")
    h = state.obj(hole)
    if h.where == HAND or state.objects[state.root(hole)].where != TABLE:
        raise SparValueError(f"assemble({peg}, {hole}): {hole} must rest (or be mated into a resting part), "
                             f"it is {h.where}")
    Ta = _pose(T_a, f"assemble({peg}, {hole}) T_a")
    offsets: tuple = ()
    if axis is not None and clearance > 0:
        hint = _hint(peg)
        offsets = (state.registry.new(f"cx_{hint}", -clearance, clearance),
                   state.registry.new(f"cy_{hint}", -clearance, clearance))
    att = Attachment(hole, Ta, retention, None if direction is None else np.asarray(direction, float),
                     float(clearance), None if axis is None else np.asarray(axis, float), mate, offsets)
    placed = replace(state, attached={**state.attached, peg: att})
    body = placed.moved(peg, snap(h.pose @ Ta))
    body[peg] = replace(body[peg], where=ASSEMBLED)
    return replace(placed, objects={**state.objects, **body})


# ------------------------------------------------------------------ preconditions (Sec. 3.2.2)


@dataclass(frozen=True)
class Constraint:
    """An uncertainty-reduction precondition ``expr <sense> threshold`` (Sec. 4.3).

    ``sense`` is '>' (needs INF(expr) > threshold) or '<' (needs SUP(expr) < threshold);
    ``action`` names the action it belongs to, ``name`` the inequality. ``bounding``
    (optional) is an expression with the same SUP (sense '<') or INF (sense '>') as
    ``expr`` over the registry box, in fewer variables, with its box: SUP/INF bounds it
    instead for the side its sense needs (see :func:`_sup_sumsqr`).
    """

    action: str
    name: str
    expr: ca.SX
    sense: str
    threshold: float
    description: str
    bounding: tuple[ca.SX, Mapping[str, tuple[float, float]]] | None = None
    #: What determines ``expr`` and ``bounding`` up to a renaming of their variables, and
    #: those variables' bounds in order (None: unknown): equal keys, equal SUP/INF answers.
    key: tuple | None = field(default=None, compare=False, repr=False)
    #: ``(h, c)`` when ``expr`` is ``h + c`` for a constant c (built so): SUP/INF bounds
    #: ``h`` on both sides at once and shifts the end it needs (:func:`evaluate`), so
    #: constraints that differ by a constant (the pickup pairs p1_ci, p2_ci) share one
    #: compiled bounder and one search
    core: tuple[ca.SX, float] | None = field(default=None, compare=False, repr=False)
    #: The power of the length ``expr`` is: 1 a length (the pickup contacts), 2 a squared
    #: length (the assemble check's |C_h - C_p|^2); its bound's unit is the cell's to it.
    power: int = 1
    #: The product mate an insertion check is of (``pin_1.shaft->cover.ph1``; empty otherwise).
    mate: str = field(default="", compare=False)

    def __post_init__(self) -> None:
        if self.sense not in (">", "<"):
            raise SparValueError(f"constraint {self.name}: sense must be '>' or '<', got {self.sense!r}")


def pickup_constraints(state: WorldState, obj: str, grasp_T: np.ndarray, width: float,
                       finger_separation: float, manip: ErrorTm, action: str = "pickup",
                       memo: Memo | None = None, via: str | None = None) -> list[Constraint]:
    """The four pickup inequalities of Sec. 3.2.2: both contact points between the fingers.

    Finger frames ``P_1,2 = T_O T_G T_dM trans(0, -+W_m/2, 0)`` (T_O the ideal pose, the
    arm is sent there); contact points ``C_1,2 = T_{O+d} T_G trans(0, +-W_g/2, 0) [0,0,0,1]^t``
    (Eq. 2). Needs ``y(P_1^-1 C_i) > 0`` and ``y(P_2^-1 C_i) < 0``. ``width`` is W_g,
    ``finger_separation`` W_m (cell unit); ``manip`` the pickup motion's T_dM. ``memo``
    (world.run.CellCache.memo): the expressions are built once per structure (:func:`_built`).
    ``via``: a via-grasp, the fingers on this part carried by ``obj``'s body (``grasp_T`` still
    in ``obj``'s frame): the contacts are on that part at its possible pose composed through
    the mates (:meth:`WorldState.possible_rel`: the root's error, each mate's clearance, its
    relative pose), ``C_i = T_{V+d} T_V^-1 T_O T_G trans(0, +-W_g/2, 0)``.
    """
    o = _on_table(state, obj, "pickup")
    T_G = _pose(grasp_T, f"pickup({obj}) grasp")
    Wg, Wm = _positive(width, "grasp width W_g"), _positive(finger_separation, "finger separation W_m")
    R_O = _rotation_only(o.pose)
    names = [(k, i) for k in (1, 2) for i in (1, 2)]
    if via is not None and via not in state.body(obj)[1:]:
        raise SparValueError(f"pickup({obj}): the grasp holds {via}, which {obj}'s body does not carry")
    held = obj if via is None else via
    # the grasp in the held part's frame (T_G itself for the part's own grasp) and the offset of
    # that part's ideal position from obj's (zero for its own)
    T_Gv = T_G if via is None else snap(np.linalg.inv(state.obj(via).pose) @ o.pose @ T_G)
    shift = state.obj(held).pose[:3, 3] - o.pose[:3, 3]

    def build() -> list[ca.SX]:
        # both the contacts and the finger frames are taken relative to the object's ideal
        # position t_O (trans(-t_O) on the left of each), which cancels in P_k^-1 C_i
        T_M = snap(R_O @ T_G)
        contact = compose(o.possible_rel(), T_G) if via is None else compose(
            trans(*shift), state.possible_rel(via), T_Gv)
        # P_k^-1 = trans(0, -+W_m/2, 0)^-1 T_dM^-1 (T_O T_G)^-1, inverted factor by factor; the
        # translation on the left adds its y to the y of every point, so y(P_k^-1 C_i) is
        # y(T_dM^-1 (T_O T_G)^-1 C_i) plus a constant: one expression per contact
        Q = compose(inv(manip.matrix()), inv(T_M))
        return [ca.cse(apply(Q, apply(contact, [0.0, s * Wg / 2, 0.0]))[1]) for s in (1.0, -1.0)]

    key = ("pickup", o.where, R_O.tobytes(), T_G.tobytes(), Wg, Wm)
    if via is not None:
        key += ("via", *_chain_key(state, via), T_Gv.tobytes(), shift.tobytes())
    errors = (o.error, manip) if via is None else (*state.errors_of(via), manip)
    cores, ckey = _built(state.registry, memo, key, errors, build)
    out = []
    for k, i in names:
        sense = ">" if k == 1 else "<"
        side = "positive" if sense == ">" else "negative"
        shift = Wm / 2 if k == 1 else -Wm / 2  # the y of trans(0, -+W_m/2, 0)^-1
        h = cores[i - 1]
        out.append(Constraint(action, f"p{k}_c{i}", h + shift, sense, 0.0,
                              f"contact C{i} of {obj} on the {side} y side of finger frame P{k}",
                              key=None if ckey is None else (ckey, f"p{k}_c{i}"), core=(h, shift)))
    return out


def assemble_constraints(state: WorldState, peg: str, hole: str, T_a: np.ndarray,
                         peg_feature: MatingFeature, hole_feature: MatingFeature,
                         action: str = "assemble", motion: ErrorTm | None = None,
                         memo: Memo | None = None, axis: np.ndarray | None = None) -> list[Constraint]:
    """The assemble inequality of Sec. 3.2.2: the peg's tip on the hole's axis within R_h - R_p.

    The peg's tip ``C_p = T_H T_a T_G T_dP T_G^-1 F_p`` (Eqs. 5, 6) is compared with the
    point of the hole's axis where that tip sits when seated, ``C_t = T_{H+d} T_a F_p``
    (Eq. 2; T_a puts the tip on the axis), not with the hole's bottom F_h (a shaft that seats
    on its shoulder, or a bore with relief below the tip, would be misaligned by the gap),
    and across the axis only: ``d = N (C_t - C_p)`` with N's two rows the unit directions
    normal to the hole's axis at its nominal pose (numeric constants; world frame: the
    hole's axis turned by R_H; the hole's error turns it about world z, so for a vertical axis
    the plane is exact). The axis is ``hole_feature``'s declared direction, else ``axis`` (the
    goal's V_a, hole frame: the paper's form gives no axis); SparValueError without either.
    The paper prints ``|C_h - C_p|^2 - (R_h - R_p) > 0``, which has the wrong sense (and
    mixes a squared length with a length); success needs ``|d| < R_h - R_p``, built as
    ``|d|^2 < (R_h - R_p)^2`` (smooth, so SUP bounds it tightly). If R_h <= R_p no position
    fits: the threshold is 0, which SUP of a square never beats (kb.problem refuses such a
    mate at load). ``motion`` (optional, not in the paper) is the assemble motion's own
    T_dM, inserted after T_G to account for the arm's error when it goes to T_H T_a T_G.
    ``memo`` (world.run.CellCache.memo): the expressions are built once per structure
    (:func:`_built`). A prism peg (``peg_feature.profile == 'prism'``) adds one constraint per
    corner of its profile at the tip (``peg_feature.corners``), built the same way with the
    corner for F_p: the rotation about the axis now matters. Sound for the whole profile: the
    displacement ``C_t - C_p`` is affine in the point (both are fixed transforms of it), so
    its size across the axis is convex in the point and every profile point, inside the
    corners' convex hull, is displaced no more than the worst corner.
    """
    _in_hand(state, peg, "assemble")
    h = state.obj(hole)
    if h.where == HAND or state.objects[state.root(hole)].where != TABLE:
        raise SparValueError(f"assemble({peg}, {hole}): {hole} must rest (or be mated into a resting part), "
                             f"it is {h.where}")
    if peg_feature.kind != "peg" or hole_feature.kind != "hole":
        raise SparValueError(f"assemble({peg}, {hole}): needs a peg feature and a hole feature, got "
                             f"{peg_feature.kind} and {hole_feature.kind}")
    Ta = _pose(T_a, f"assemble({peg}, {hole}) T_a")
    N = _across(_rotation_only(h.pose)[:3, :3] @ _hole_direction(peg, hole, hole_feature, axis))
    points = [("centres", np.asarray(peg_feature.vector, float), "tip")]
    if peg_feature.profile == "prism" and peg_feature.corners is not None:
        points += [(f"corner{i + 1}", np.asarray(c, float), f"tip corner {i + 1}")
                   for i, c in enumerate(peg_feature.corners)]
    return [_insertion_constraint(state, peg, hole, Ta, F_p, N, peg_feature, hole_feature, action, motion, memo,
                                  label, what) for label, F_p, what in points]


def _insertion_constraint(state: WorldState, peg: str, hole: str, Ta: np.ndarray, F_p: np.ndarray, N: np.ndarray,
                          peg_feature: MatingFeature, hole_feature: MatingFeature, action: str,
                          motion: ErrorTm | None, memo: Memo | None, label: str, what: str) -> Constraint:
    """One point ``F_p`` of the peg (object frame) across the hole's axis (rows of ``N``)
    within R_h - R_p of where it sits when seated (:func:`assemble_constraints`)."""
    p = _in_hand(state, peg, "assemble")
    h = state.obj(hole)
    T_G = p.grasp
    seated = Ta[:3, :3] @ F_p + Ta[:3, 3]  # where the point sits when seated, hole frame
    where = "the axis of" if label == "centres" else "its seated place in"

    def build() -> list[ca.SX]:
        # both points relative to the hole's ideal position t_H, which cancels in C_t - C_p:
        # the expression depends on the pair only through the hole's orientation, T_a and T_G
        chain: list[Matrix] = [snap(_rotation_only(h.pose) @ Ta @ T_G)]
        if motion is not None:
            chain.append(motion.matrix())
        chain += [p.error.matrix(), inv(T_G)]
        C_p = apply(compose(*chain), F_p)
        C_t = apply(state.possible_rel(hole), seated)  # composed through the mates if hole is carried
        d3 = C_t - C_p
        d = ca.vertcat(*[sum((float(n[j]) * d3[j] for j in range(3) if n[j] != 0.0), ca.SX(0.0)) for n in N])
        sup = _sup_sumsqr(d, state.registry)
        return [ca.cse(ca.sumsqr(d))] + ([] if sup is None else [sup])

    errors = (p.error, *state.errors_of(hole)) + (() if motion is None else (motion,))
    # _sup_sumsqr's closed form holds the variables' bounds: they are part of the structure
    bounds = tuple(state.registry.bounds(v.name()) for e in errors for v in e.vars)
    chain = _chain_key(state, hole)
    key = ("assemble", h.where, _rotation_only(h.pose).tobytes(), *chain, Ta.tobytes(), T_G.tobytes(),
           F_p.tobytes(), N.tobytes(), motion is not None, bounds)
    exprs, ckey = _built(state.registry, memo, key, errors, build)
    d2 = exprs[0]
    bounding = None if len(exprs) == 1 else (exprs[1], state.registry.box(exprs[1]))
    margin = float(hole_feature.radius) - float(peg_feature.radius)
    threshold = margin * margin if margin > 0 else 0.0
    note = "" if margin > 0 else f" (impossible: hole radius {hole_feature.radius} <= peg radius {peg_feature.radius})"
    return Constraint(action, label, d2, "<", threshold,
                      f"|d|^2 < (R_h - R_p)^2: {peg}'s {what} ({peg_feature.name}) within {margin:g} of "
                      f"{where} {hole}'s {hole_feature.name}, across it{note}", bounding, key=ckey, power=2)


def _chain_key(state: WorldState, name: str) -> tuple:
    """The numbers :meth:`WorldState.possible_rel` of ``name`` uses beyond its own pose's rotation
    (empty for a part mated into nothing): each mate's relative pose and the offsets between
    the parts' ideal positions, down from the root."""
    a = state.attached.get(name)
    if a is None:
        return ()
    shift = state.obj(a.parent).pose[:3, 3] - state.obj(name).pose[:3, 3]
    return (*_chain_key(state, a.parent), _rotation_only(state.obj(a.parent).pose).tobytes(),
            np.asarray(a.rel, float).tobytes(), shift.tobytes(), bool(a.offsets))


def _hole_direction(peg: str, hole: str, feature: MatingFeature, axis: np.ndarray | None) -> np.ndarray:
    """The unit direction of ``feature``'s axis in the hole part's frame: its declared one, else
    ``axis`` (the goal's V_a); SparValueError if neither is known or it is zero."""
    v = feature.geometry.direction if feature.geometry is not None else axis
    n = float(np.linalg.norm(v)) if v is not None else 0.0
    if not n > 0:
        raise SparValueError(f"assemble({peg}, {hole}): the axis of {hole}'s {feature.name} is unknown: declare "
                             "the hole by geometry or give the goal's V_a")
    return np.asarray(v, float) / n


def _across(w: np.ndarray) -> np.ndarray:
    """(2, 3): two orthonormal rows normal to the unit ``w`` (world): the world axes least
    aligned with w made normal to it (exactly the world's x and y for a vertical w)."""
    w = np.asarray(w, float) / np.linalg.norm(w)
    order = np.argsort(np.abs(w), kind="stable")
    e1 = np.eye(3)[order[0]] - w[order[0]] * w
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(w, e1)
    rows = snap(np.array([e1, e2]))
    return rows


#: Entries of a cell cache's memo table ``uncertainty.built`` (:func:`_built`) and
#: ``uncertainty.verdicts`` (:func:`evaluate`).
BUILT_LIMIT = 1024
VERDICT_LIMIT = 4096


def _built(registry: Registry, memo: Memo | None, key: tuple, errors: Sequence[ErrorTm],
           build: Callable[[], list[ca.SX]], *, key_out: bool = True) -> tuple[list[ca.SX], tuple | None]:
    """``build()``'s expressions, made once per structure: ``key`` (the numbers the build
    uses) and the ``shape`` of each error transform it reads determine them up to a
    one-to-one renaming of the errors' ``vars``, so a later build of an equal structure
    (the same action on a part alike in how its error came about, e.g. the next of many
    identical pegs) renames the first build's variables instead of repeating its CasADi
    products. The renamed graph is the build's own, node for node, so SUP/INF sees the
    same expression. Also returns the constraints' key (:attr:`Constraint.key`: the
    structure and the variables' bounds in order), or None when an error's structure is
    unknown or no memo is given (then built directly), or if not ``key_out``."""
    vs = tuple(v for e in errors for v in e.vars)
    if memo is None or not all(e.shape for e in errors) or len({v.element_hash() for v in vs}) != len(vs):
        return build(), None
    skey = key + tuple(e.shape for e in errors)
    table = memo.table("uncertainty.built", BUILT_LIMIT)
    hit = table.get(skey)
    if hit is None:
        exprs = build()
        table[skey] = [exprs, vs, None]
    else:
        exprs, old, f = hit
        if any(a.element_hash() != b.element_hash() for a, b in zip(old, vs)):
            if f is None:  # the build as a function of its variables, evaluated on the new ones
                f = hit[2] = ca.Function("built", [ca.vertcat(*old)], exprs)
            exprs = list(f.call([ca.vertcat(*vs)]))
    return exprs, (skey, tuple(registry.bounds(v.name()) for v in vs)) if key_out else None


def _derived(step: tuple, *parents: ErrorTm) -> dict[str, tuple]:
    """The ``shape`` and ``vars`` of an error transform made by ``step`` (plain data: the
    step's name and the numbers it uses) from ``parents``' entries; none if a parent's
    structure is unknown."""
    if not all(e.shape for e in parents):
        return {}
    return {"shape": (step, *(e.shape for e in parents)), "vars": tuple(v for e in parents for v in e.vars)}


def _axis_offsets(d: Matrix, registry: Registry) -> tuple[ca.SX, dict[int, tuple[float, float]]] | None:
    """``d`` (an SX column) split as ``d0 + w``: the variables that move it along one axis.

    A variable ``s`` whose Jacobian column ``∂d/∂s`` is a constant with one nonzero
    entry ``c`` (row r) enters ``d`` only as ``c s e_r``: the offsets of the assemble
    centres (the hole's world-frame dx, dy, dz, the held part's tool-frame offset mapped
    by an axis-aligned rotation). Those of axis r sum to ``w_r = sum_j c_j s_j``, whose
    range over the registry box is exactly the sum of the terms' ranges (the terms are
    independent), here rounded outwards; the ``w_r`` of different axes are independent
    of each other and of the rest. Returns ``d0`` (``d`` with those variables set to 0)
    and ``{r: (lo, hi)}`` of each ``w_r``, or None if no variable is of that kind.
    """
    syms = ca.symvar(as_sx(d))
    if not syms:
        return None
    allv = ca.vertcat(*syms)
    axes: dict[int, list[tuple[ca.SX, float]]] = {}
    for v in syms:
        J = ca.jacobian(d, v)
        if ca.depends_on(J, allv):
            continue
        c = np.asarray(ca.evalf(J), float).ravel()
        nz = np.flatnonzero(c)
        if len(nz) == 1 and np.isfinite(c[nz[0]]):
            axes.setdefault(int(nz[0]), []).append((v, float(c[nz[0]])))
    if not axes:
        return None
    gone = [v for members in axes.values() for v, _ in members]
    d0 = ca.substitute(as_sx(d), ca.vertcat(*gone), ca.SX.zeros(len(gone)))
    ranges: dict[int, tuple[float, float]] = {}
    for r, members in axes.items():
        los, his = [], []
        for v, c in members:
            lo, hi = registry.bounds(v.name())
            a, b = c * lo, c * hi  # each product rounded: one ulp outwards covers it
            los.append(math.nextafter(min(a, b), -math.inf))
            his.append(math.nextafter(max(a, b), math.inf))
        ranges[r] = (math.nextafter(math.fsum(los), -math.inf), math.nextafter(math.fsum(his), math.inf))
    return d0, ranges


def _sup_sumsqr(d: Matrix, registry: Registry) -> ca.SX | None:
    """An expression whose SUP over the registry box is SUP ``|d|^2`` (d a column), in
    fewer variables, or None. With ``d = d0 + w`` (:func:`_axis_offsets`), the axis sums
    ``w_r`` in ``[m_r - rho_r, m_r + rho_r]`` free and independent, the supremum over
    them is in closed form: ``sup_w (d0_r + w_r)^2 = (|d0_r + m_r| + rho_r)^2``, so
    ``SUP |d|^2 = SUP sum_r (|d0_r + m_r| + rho_r)^2`` over the other variables (m_r
    and rho_r rounded so that the interval covers w_r's range; the bound stays sound)."""
    split = _axis_offsets(d, registry)
    if split is None:
        return None
    d0, ranges = split
    terms = []
    for r in range(as_sx(d).numel()):
        if r in ranges:
            lo, hi = ranges[r]
            m = 0.5 * (lo + hi)
            rho = math.nextafter(max(hi - m, m - lo), math.inf)
            terms.append(ca.power(ca.fabs(d0[r] + m) + rho, 2))
        else:
            terms.append(ca.power(d0[r], 2))
    return ca.cse(sum(terms[1:], terms[0]))


def _positive(v: float, what: str) -> float:
    x = float(v)
    if not (math.isfinite(x) and x > 0):
        raise SparValueError(f"{what} must be a positive number, got {v!r}")
    return x


# ------------------------------------------------------------------ evaluation (Sec. 5.3)


@dataclass(frozen=True)
class Verdict:
    """The decision on one :class:`Constraint`: ``bound`` is INF (sense '>') or SUP (sense '<')
    of its expression; ``satisfied`` iff the bound strictly beats ``threshold``."""

    constraint: Constraint
    bound: float
    threshold: float
    satisfied: bool
    tolerance_reached: bool

    def as_dict(self) -> dict[str, Any]:
        """Plain data for the Prolog bridge: action, constraint, sense, bound, threshold, ..."""
        c = self.constraint
        return {"action": c.action, "constraint": c.name, "sense": c.sense, "bound": self.bound,
                "threshold": self.threshold, "satisfied": self.satisfied,
                "tolerance_reached": self.tolerance_reached, "description": c.description,
                "power": c.power, **({"mate": c.mate} if c.mate else {})}


def evaluate(constraint: Constraint, registry: Registry, *, memo: Memo | None = None, decide: bool = False,
             **options: Any) -> Verdict:
    """Decide ``constraint`` with SUP/INF over its variables' registry bounds (options: Bounder.bounds).

    ``memo`` (world.run.CellCache.memo) keeps compiled bounders and results by the
    expression's structure and box (supinf.cached_bounds): phase 2 meets the same
    constraint in many plan instances and after every remedy it tries.

    ``decide``: only the verdict is wanted, and SUP/INF stops as soon as it is settled
    (Bounder.bounds' ``beat``, the threshold). ``satisfied`` is the one the full
    refinement gives; ``bound`` is sound but may be looser than that refinement's (phase
    2 refines the verdicts it reports: phase2.evaluate). A constraint with a ``core``
    (``h + c``) is always refined: its one search of both ends of h answers it and its
    sibling, at about the cost of one decision."""
    if decide:
        options = {**options, "beat": float(constraint.threshold)}
    vkey = None
    if memo is not None and constraint.key is not None:
        # an equal key is the same expression and box up to the variables' names: the
        # answer cached_bounds would give (it is deterministic), without canonicalising
        vkey = (constraint.key, tuple(sorted(options.items())))
        hit = memo.table("uncertainty.verdicts", VERDICT_LIMIT).get(vkey)
        if hit is not None:
            return _verdict(constraint, *hit)
    want = "lo" if constraint.sense == ">" else "hi"
    if constraint.core is not None and constraint.bounding is None:
        bound, reached = _core_bound(constraint, registry, memo, want, options)
    else:
        if constraint.bounding is not None:
            expr, box = constraint.bounding[0], dict(constraint.bounding[1])
        else:
            expr, box = constraint.expr, registry.box(constraint.expr)
        r = cached_bounds(expr, box, memo, want=want, **options)
        bound, reached = (r.lo if want == "lo" else r.hi), r.tolerance_reached
    if vkey is not None:
        memo.table("uncertainty.verdicts", VERDICT_LIMIT)[vkey] = (float(bound), reached)  # type: ignore[union-attr]
    return _verdict(constraint, float(bound), reached)


def _core_bound(constraint: Constraint, registry: Registry, memo: Memo | None, want: str,
                options: Mapping[str, Any]) -> tuple[float, bool]:
    """INF (``want`` 'lo') or SUP ('hi') of ``constraint.expr = h + c`` (its ``core``) and
    whether SUP/INF's tolerance was reached: both ends of h bounded in one search to the
    tolerance (a ``beat`` is not used: the sibling constraint, h plus another constant, asks
    the other end, and phase 2 reports the refined bound anyway), the end wanted shifted by
    c and moved one float outward (the sum's rounding), so the bound stays sound. The
    tolerance is the same as the expression's own: h + c has h's spread of values."""
    h, c = constraint.core  # type: ignore[misc]
    opts = {k: v for k, v in options.items() if k != "beat"}
    r = cached_bounds(h, registry.box(h), memo, want="both", **opts)
    if want == "lo":
        return (math.nextafter(r.lo + c, -math.inf) if math.isfinite(r.lo) else r.lo), r.tolerance_reached
    return (math.nextafter(r.hi + c, math.inf) if math.isfinite(r.hi) else r.hi), r.tolerance_reached


def _verdict(constraint: Constraint, bound: float, tolerance_reached: bool) -> Verdict:
    ok = bound > constraint.threshold if constraint.sense == ">" else bound < constraint.threshold
    return Verdict(constraint, bound, float(constraint.threshold), bool(ok), tolerance_reached)


def evaluate_all(constraints: Sequence[Constraint], registry: Registry, *, memo: Memo | None = None,
                 **options: Any) -> list[Verdict]:
    """:func:`evaluate` each constraint, in order."""
    return [evaluate(c, registry, memo=memo, **options) for c in constraints]


#: At most this many clearance offsets are searched corner by corner (2**n evaluations) by
#: :func:`clearance_floor`; a constraint with more gets no floor.
FLOOR_MAX_OFFSETS = 10


def clearance_floor(constraint: Constraint, registry: Registry, offsets: Sequence[ca.SX]) -> float | None:
    """A value ``constraint``'s expression takes in its box, with every variable but the mates'
    clearance ``offsets`` (Attachment.offsets: what a part may move within the clearance its
    mate leaves) at 0 and those at the corner of their box (``registry``'s bounds) where it is
    largest. SUP is never below it. The remedies (kb/templates/spar_sensing.pl: scans of the
    parts on the table, a squeeze) give parts fresh error boxes about 0 and leave a mate's
    clearance alone, so a '<' constraint whose floor is not below its threshold fails after any
    of them: phase 2 need not try them. None for a '>' constraint, without offsets in the
    expression, or with more than FLOOR_MAX_OFFSETS of them. Cell unit to the constraint's power."""
    if constraint.sense != "<":
        return None
    names = {v.name() for v in offsets}
    xs = ca.symvar(constraint.expr)
    free = [i for i, v in enumerate(xs) if v.name() in names]
    if not free or len(free) > FLOOR_MAX_OFFSETS:
        return None
    f = ca.Function("floor", [ca.vertcat(*xs)], [constraint.expr])
    grid = np.array(np.meshgrid(*[registry.bounds(xs[i].name()) for i in free], indexing="ij"))
    corners = grid.reshape(len(free), -1)
    X = np.zeros((len(xs), corners.shape[1]))
    X[free, :] = corners
    return float(np.max(np.asarray(f.map(corners.shape[1])(X)).ravel()))
