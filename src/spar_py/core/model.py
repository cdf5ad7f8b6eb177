"""The validated in-memory models of a work cell (what the kb package builds from YAML).

Units inside: lengths in the problem file's length unit (the paper's cell: inches),
angles in radians. Frames: world Z up, table top at z = 0, 4x4 homogeneous
transforms with column vectors, ``T_world_obj``.
"""
from __future__ import annotations

import re
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Protocol, Sequence, Union

import numpy as np

from spar_py.core.errors import SparValueError

if TYPE_CHECKING:
    from spar_py.world.robot import Robot

Face = Union[int, str]
#: A ground Prolog term as data: an atom (str), a number, a list of terms, or a compound as a
#: tuple (functor, arg1, ...), the form the bridge sends to Prolog (kb.terms renders it as text).
Term = Union[str, int, float, list["Term"], tuple["Term", ...]]


def natural_key(label: str) -> tuple[int | str, ...]:
    """Sort key putting p1G2 before p1G10 and action_2 before action_10 (digit runs compare as
    numbers), as partial_plan.pl's natural_key/2 does."""
    return tuple(int(t) if t.isdigit() else t for t in re.split(r"(\d+)", label))


@dataclass(frozen=True)
class StablePose:
    """A stable pose (Fig. 18): the faces it rests on, the faces it hides, its orientation R
    (3x3, world) and ``height``, the object frame's height above the table top (cell unit)."""

    label: str
    rfaces: tuple[Face, ...]
    ofaces: tuple[Face, ...]
    R: np.ndarray
    height: float = 0.0


@dataclass(frozen=True)
class Grasp:
    """A grasping configuration (Fig. 19).

    ``euler`` is (X, Y, Z, phi, theta, psi): lengths in the cell unit, angles in radians;
    ``T`` is the characteristic T_g, the tool frame in the object frame (4x4);
    ``width`` is W_g, the object's width along the fingers' sliding axis (tool y).
    """

    label: str
    gfaces: tuple[Face, ...]
    ofaces: tuple[Face, ...]
    euler: tuple[float, float, float, float, float, float]
    width: float
    T: np.ndarray


@dataclass(frozen=True)
class FeatureGeometry:
    """A mating feature declared by geometry (object frame, cell unit): ``kind`` peg or hole,
    the face ``name`` its surfaces get, ``radius``, ``origin`` (a peg's root, a hole's mouth
    centre), unit ``direction`` (to the peg's tip, into the hole) and ``length`` (the shaft's
    length, the hole's depth); ``through``: a hole open at both ends (no bottom)."""

    kind: str
    name: str
    radius: float
    origin: np.ndarray
    direction: np.ndarray
    length: float
    through: bool = False
    #: 'round', or 'prism': plane walls normal to the axis, ``radius`` the profile's inscribed
    #: half-width and ``corners`` (k, 3) its bounding rectangle's corners as offsets from the
    #: axis, across it (object frame, cell unit).
    profile: str = "round"
    corners: np.ndarray | None = None

    @property
    def end(self) -> np.ndarray:
        """The peg's tip centre F_p or the hole's bottom centre F_h (object frame)."""
        return self.origin + self.length * self.direction

    @property
    def reach(self) -> float:
        """The farthest the feature's wall gets from its axis: the radius, a prism's corners."""
        if self.profile == "prism" and self.corners is not None and len(self.corners):
            return float(np.linalg.norm(self.corners, axis=1).max())
        return self.radius

    def spec(self) -> list:
        """Plain data for the content hash."""
        out = [self.kind, self.name, round(self.radius, 12), [round(float(v), 12) for v in self.origin],
               [round(float(v), 12) for v in self.direction], round(self.length, 12), self.through]
        if self.profile != "round":
            out += [self.profile, np.round(np.asarray(self.corners, float), 12).tolist()]
        return out


class DeclaredShape(Protocol):
    """What a model knows of its declared geometry (``mesh:`` or ``shape:``); the world's
    parts room implements it (world.parts.Geometry) and builds the mesh from it."""

    unit: str
    mesh_file: str | None

    def digest(self) -> str:
        """SHA-256 of the geometry's content."""
        ...

    def mesh(self) -> Any:
        """The part's mesh (a trimesh.Trimesh; object frame, cell unit), built on first use."""
        ...


@dataclass(frozen=True)
class MatingFeature:
    """A peg or hole (Sec. 3.2.2): ``kind`` 'peg' or 'hole', the part's faces on it, its
    radius, and its vector in the object frame (F_p, the peg tip centre; F_h, the hole's bottom
    centre). ``name`` is unique in its part (an empty name becomes the geometric form's face
    name, else the kind); ``through``: a hole open at both ends (a peg may enter either mouth).
    ``profile`` 'round' (the paper's), or 'prism' (plane walls along the axis): its radius is
    the profile's inscribed half-width, a hole's that plus the clearance (R_h - R_p is the
    clearance wherever used), and ``corners`` (k, 3) the profile's corners at the tip (object
    frame; a prism peg's, for the insertion check)."""

    kind: str
    faces: tuple[Face, ...]
    radius: float
    vector: np.ndarray
    #: The feature declared by geometry (axis origin, direction, length), or None (the
    #: paper's form: faces and vector only).
    geometry: FeatureGeometry | None = None
    name: str = ""
    through: bool = False
    profile: str = "round"
    corners: np.ndarray | None = None

    def __post_init__(self) -> None:
        if not self.name:
            object.__setattr__(self, "name", self.geometry.name if self.geometry is not None else self.kind)


@dataclass(frozen=True)
class Solid:
    """A primitive of an object's shape, in the object frame (cell unit): a box
    (``lo``, ``hi`` corners), a z-axis cylinder (``radius``, ``lo``/``hi`` as z range
    in ``lo[2]``, ``hi[2]``, centred on the z axis) or a convex ``hull`` (its vertices
    ``points`` (k, 3), ``lo``/``hi`` their bounding box: a mesh part). Used for pictures and
    clearances; subtracted primitives are not among them (world.parts.mesh keeps them)."""

    kind: str
    lo: np.ndarray
    hi: np.ndarray
    radius: float = 0.0
    points: np.ndarray | None = None

    def key(self) -> tuple:
        """What the primitive is, exactly (kind and numbers' bits): equal keys, the same primitive
        (renamed copies of one model share what is made from it)."""
        return (self.kind, np.asarray(self.lo, float).tobytes(), np.asarray(self.hi, float).tobytes(),
                float(self.radius), None if self.points is None else np.asarray(self.points, float).tobytes())


@dataclass
class ObjectModel:
    """An object model: faces, stable poses, grasps, mating features and shape."""

    name: str
    faces: tuple[Face, ...]
    poses: dict[str, StablePose]
    grasps: dict[str, Grasp]
    #: The part's mating features (``features:``, or ``feature:`` as a list of one), names unique.
    features: tuple[MatingFeature, ...] = ()
    shape: tuple[Solid, ...] = ()
    #: The declared geometry (``mesh:`` or ``shape:``) the part's mesh is built from
    #: (world.parts.mesh.part_mesh), or None.
    geometry: DeclaredShape | None = field(default=None, compare=False, repr=False)

    def bounding_radius(self) -> float:
        """Radius of a sphere about the object origin containing the shape (0 without one)."""
        r = 0.0
        for s in self.shape:
            corners = np.array([[x, y, z] for x in (s.lo[0], s.hi[0]) for y in (s.lo[1], s.hi[1])
                                for z in (s.lo[2], s.hi[2])])
            r = max(r, float(np.linalg.norm(corners, axis=1).max()))
        return r

    @property
    def mating_faces(self) -> tuple[Face, ...]:
        """Faces that must stay free for assembly: every feature's, in order (empty without one)."""
        return tuple(dict.fromkeys(f for feat in self.features for f in feat.faces))

    def feature_named(self, name: str) -> MatingFeature:
        """The feature called ``name``; SparValueError naming the part's features if none is."""
        for f in self.features:
            if f.name == name:
                return f
        known = ", ".join(f.name for f in self.features) or "none"
        raise SparValueError(f"{self.name} has no feature {name!r} (its features: {known})")

    def feature_on(self, faces: "Sequence[Face]") -> MatingFeature | None:
        """The feature whose faces the goal's face list ``faces`` names: the one sharing the
        most faces with it (the first of equals), or None if it names no feature's face."""
        want = set(faces)
        best, hits = None, 0
        for f in self.features:
            n = len(want & set(f.faces))
            if n > hits:
                best, hits = f, n
        return best


@dataclass(frozen=True)
class Position:
    """An absolute position (Sec. 5.2.3): plan-variable name (``init_pos1``), label (``tr1``),
    the object resting there and its 4x4 world transform."""

    name: str
    label: str
    obj: str
    T: np.ndarray


@dataclass(frozen=True)
class Bounds:
    """Uncertainty bounds (Table 2): lengths in the cell unit, angles in radians."""

    dx: tuple[float, float]
    dy: tuple[float, float]
    dz: tuple[float, float]
    dtheta: tuple[float, float]


@dataclass(frozen=True)
class Sensor:
    """A sensing action (Fig. 11) and the bounds it leaves on the object it scans."""

    name: str
    leaves: Bounds


@dataclass(frozen=True)
class Cell:
    """A whole problem: robot, objects, initial positions, uncertainty, sensors and goals.

    Frozen: loading reads and validates the files, derives what is geometric, then builds the
    cell once (kb.problem.load_problem); a planning run keeps its own state (world.run.WorldRun)
    and the answers worth keeping across runs sit beside the cell (world.collision.CellCache)."""

    name: str
    file: str
    unit: str
    robot: "Robot"
    finger_separation: float  # W_m, cell unit
    objects: dict[str, ObjectModel]
    positions: dict[str, Position]  # by label (tr1, ...)
    transforms: dict[str, np.ndarray]  # named constant transforms (trans_1: T_a)
    vectors: dict[str, np.ndarray]  # named vectors (vec_1: V_a)
    initial: list[Term]  # initial-state facts as terms: ("gripper", "open"), ("part_location", obj, pos)
    goals: list[Term]  # goals as terms: ("assembled", peg, hole, [[pf], [hf]], ta, va), ...
    manipulator_bounds: Bounds
    object_bounds: dict[str, Bounds]
    sensors: dict[str, Sensor]
    placement_regions: list[dict] = field(default_factory=list)
    #: Derived T_a (assembled/2 goals): the goal's transform name -> its turns about the hole's
    #: axis, each (transform name, the hole part's stable poses the mated peg clears the table in).
    turns: dict[str, tuple[tuple[str, tuple[str, ...]], ...]] = field(default_factory=dict)
    #: Obstacles (world.collision.Obstacle: named bodies, world frame), the table top's extent
    #: (x0, x1, y0, y1) or None (the whole plane), the collision margin or None (the robot's or
    #: the default): the problem file's ``obstacles:``, ``table:``, ``clearance:`` (cell unit).
    obstacles: tuple = ()
    table: tuple[float, float, float, float] | None = None
    clearance: float | None = None
    #: Whether reach checks ask the collision scene (world.collision.scene) at all: on unless the
    #: problem file says ``collision: false`` (see workspace.reach_clear).
    collisions: bool = True
    #: The files the cell was loaded from (resolved paths: problem, robot, models).
    files: tuple[str, ...] = ()
    #: Home joint vector (6,) rad: the problem's ``home:``, else the robot file's, else None
    #: (world/motion/paths.py's default).
    home: np.ndarray | None = None
    #: The problem file's ``motion: true``: plan motions unless the Planner says otherwise
    #: (the regression suite plans motions for these cells only).
    plan_motions: bool = False
    #: The product the problem's ``product:`` names (its goals compiled), or None.
    product: "Product | None" = None
    #: A product cell's grasps no plan can seat each part with (world.product.access.hand_access): the
    #: assemble of that part does not offer them (kb.prolog_facts' mate_grasps).
    blocked_grasps: dict[str, frozenset[str]] = field(default_factory=dict)


@dataclass(frozen=True)
class ProductPart:
    """A part of a product: its ``model`` and ``pose``, T_product_part (4x4, cell unit)."""

    name: str
    model: ObjectModel
    pose: np.ndarray


#: A loose mate (held by gravity) stays while its insertion direction is within this angle of
#: world down (deg): the retention check (phase2.rest), the one-arm search (world.product.single_arm)
#: and the layout's insertions "from above" (world.product.layout) all use it.
LOOSE_MAX_DEG = 30.0


@dataclass(frozen=True)
class Mate:
    """A peg feature of one part in a hole feature of another (``PART.FEATURE`` each);
    ``retention`` 'loose' (held by gravity) or 'fixed' (press fit, snap, screw)."""

    peg: str
    peg_feature: str
    hole: str
    hole_feature: str
    retention: str = "loose"

    @property
    def name(self) -> str:
        """How messages and the plan name the mate: ``pin_a.shaft->bracket.bore_a``."""
        return f"{self.peg}.{self.peg_feature}->{self.hole}.{self.hole_feature}"

    @property
    def ends(self) -> tuple[str, str]:
        """The mate's two parts: (peg part, hole part)."""
        return self.peg, self.hole


@dataclass(frozen=True)
class Seat:
    """Face ``face`` of ``part`` rests on face ``on_face`` of ``on``: a planar contact, which
    ``part`` reaches moving against ``on_face``'s normal; or, with ``direction`` (unit, product
    frame: the way ``part`` moves into it), a curved one, as a shaft lying in a cradle."""

    part: str
    face: str
    on: str
    on_face: str
    direction: tuple[float, float, float] | None = None

    @property
    def name(self) -> str:
        """How messages and the plan name the seat: ``bracket.bottom->base.top``."""
        return f"{self.part}.{self.face}->{self.on}.{self.on_face}"

    @property
    def ends(self) -> tuple[str, str]:
        """The seat's two parts: (the part seated, the part it rests on)."""
        return self.part, self.on


@dataclass(frozen=True)
class PartGoal:
    """What a non-base part's insertion must achieve: ``part`` into ``parent`` with the
    mating faces (``part_faces``, ``parent_faces``), T_a = T_parent^-1 T_part (the product
    poses) and V_a, the insertion direction in the parent's frame (unit), named ``ta``,
    ``va``; ``mates`` the mates and seats that insertion makes (their names, file order)."""

    part: str
    parent: str
    part_faces: tuple[Face, ...]
    parent_faces: tuple[Face, ...]
    T_a: np.ndarray
    V_a: np.ndarray
    ta: str
    va: str
    mates: tuple[str, ...]


@dataclass(frozen=True)
class Precedence:
    """``first`` must be inserted before ``then``: ``then`` in place blocks ``first``'s
    insertion; ``reason`` says how, for the plan's text."""

    first: str
    then: str
    reason: str


@dataclass(frozen=True)
class Product:
    """A product (kb/products/*.yaml): its parts at their poses in the product frame, the base
    part, the mates and seats, and what they compile to: one :class:`PartGoal` per non-base
    part (the assembly tree) and the :class:`Precedence` the geometry forces."""

    name: str
    file: str
    base: str
    parts: dict[str, ProductPart]
    mates: tuple[Mate, ...]
    seats: tuple[Seat, ...] = ()
    goals: tuple[PartGoal, ...] = ()
    precedence: tuple[Precedence, ...] = ()
    #: The parts' model files (resolved paths).
    files: tuple[str, ...] = ()
    #: Each part's neighbours at the product poses (world.product.products.near_parts).
    near: dict[str, tuple[str, ...]] = field(default_factory=dict)
    #: Each part's via-grasps (grasps of a part mated into it): {part: {label: the part held}}.
    via: dict[str, dict[str, str]] = field(default_factory=dict)
    #: Each part's subassembly stable poses (world.product.products.subassembly_poses): {part: {label:
    #: the parts mated into it that the pose needs, its subtree}}.
    sub_poses: dict[str, dict[str, tuple[str, ...]]] = field(default_factory=dict)

    def goal_of(self, part: str) -> PartGoal | None:
        """The goal of a non-base part (None for the base)."""
        return next((g for g in self.goals if g.part == part), None)
