"""The schema language of KB files, the schemas of the three file kinds, and reading a file of a kind.

A schema is data (:class:`Keys`, :class:`Each`, :class:`Named`, :class:`OneOf`,
:class:`OneOrMany`, :data:`LEAF`): :func:`check_shape` checks a file's structure against
it (unknown keys are errors with a did-you-mean, required keys present, user names are
labels) and leaves the leaves to the loaders. Each file kind (problem, object, robot) has
one schema and a marker key (:data:`KINDS`); :func:`read_kb` reads a file that must be of
a kind. The formats are documented in docs/kb-format.md.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from types import MappingProxyType
from typing import Any, Iterable, Mapping, Union

from spar_py.core.errors import KBError, UnknownKeyError, WrongKindError
from spar_py.kb.node import LABEL_RE, Node, did_you_mean
from spar_py.kb.reader import MAX_INPUT_BYTES, parse_yaml

__all__ = ["BOUNDS_SCHEMA", "FEATURE_SCHEMA", "KINDS", "LEAF", "OBJECT_SCHEMA", "PROBLEM_SCHEMA", "ROBOT_SCHEMA",
           "UNITS_SCHEMA", "URDF_ROBOT_SCHEMA", "Each", "Keys", "Kind", "Leaf", "Named", "OneOf", "OneOrMany", "Spec",
           "check_shape", "conforms", "describe", "file_kind", "keys", "read_kb", "read_yaml", "schema_keys"]


@dataclass(frozen=True)
class Leaf:
    """A value the loader checks itself (a number, label, list of numbers, tm rows, ...)."""


@dataclass(frozen=True)
class Keys:
    """A mapping with fixed keys: each required or optional key with the spec of its value."""

    required: Mapping[str, "Spec"]
    optional: Mapping[str, "Spec"]


@dataclass(frozen=True)
class Each:
    """A list whose items all follow ``item`` (at least ``min_len`` of them)."""

    item: "Spec"
    min_len: int = 0


@dataclass(frozen=True)
class Named:
    """A mapping from the user's labels (object, sensor, transform names) to ``value`` specs."""

    value: "Spec"


@dataclass(frozen=True)
class OneOf:
    """A mapping with exactly one key, one of ``choices`` (a shape primitive)."""

    choices: Mapping[str, "Spec"]


@dataclass(frozen=True)
class OneOrMany:
    """Either one ``item`` or a non-empty list of them (an initial position or a stock)."""

    item: "Spec"


Spec = Union[Leaf, Keys, Each, Named, OneOf, OneOrMany]


LEAF = Leaf()


def keys(required: Iterable[str] | Mapping[str, Spec], optional: Iterable[str] | Mapping[str, Spec] = ()) -> Keys:
    """A :class:`Keys` spec; a plain iterable of names means leaf values."""
    def table(ks: Iterable[str] | Mapping[str, Spec]) -> Mapping[str, Spec]:
        return MappingProxyType(dict(ks) if isinstance(ks, Mapping) else dict.fromkeys(ks, LEAF))
    return Keys(table(required), table(optional))


UNITS_SCHEMA = keys(["length", "angle"])


BOUNDS_SCHEMA = keys(["dx", "dy", "dz", "dtheta"])


FRAME_SCHEMA = keys(["xyz"], ["rpy"])


#: A mating feature: the paper's form {kind, faces, radius, vector} or by geometry {kind, name,
#: radius, axis, length}; ``name`` (required among several) and ``through`` (a hole) in either;
#: ``profile`` and ``corners`` (a prism) by geometry.
FEATURE_SCHEMA = keys(["kind", "radius"], {"faces": LEAF, "vector": LEAF, "name": LEAF, "length": LEAF,
                                           "axis": keys(["origin", "direction"]), "through": LEAF,
                                           "profile": LEAF, "corners": LEAF})


OBJECT_SCHEMA = keys(
    {"object": LEAF, "units": UNITS_SCHEMA},
    {"faces": LEAF,
     "stable_poses": Each(keys(["label", "rfaces", "ofaces", "tm"]), 1),
     "grasps": Each(keys(["label", "gfaces", "ofaces", "eulerxyz", "width"]), 1),
     # the paper's form {kind, faces, radius, vector} or by geometry {kind, name, radius, axis, length}
     "feature": OneOrMany(FEATURE_SCHEMA), "features": Each(FEATURE_SCHEMA, 1),
     "shape": Each(OneOf(MappingProxyType({"box": keys(["min", "max"], ["subtract"]),
                                           "cylinder": keys(["radius", "z"], ["subtract"])}))),
     "mesh": LEAF, "face_names": Named(LEAF), "grasp_step": LEAF},
)


#: A gripper box's sizes (robot file ``gripper: finger`` and ``palm``).
GRIPPER_BOX_SCHEMA = keys(["length", "width", "thickness"])


GRIPPER_SCHEMA = keys(["finger_separation"], {"finger": GRIPPER_BOX_SCHEMA, "palm": GRIPPER_BOX_SCHEMA,
                                              "body": LEAF})  # body: none, or a shape (kb.robots._tool_body)


#: A link's collision shape (robot file ``collision: links``): a capsule or cylinder from one
#: point to another, or a box, in one of Craig's frames 0..6.
AXIS_SHAPE_SCHEMA = keys(["radius", "from", "to"])


COLLISION_SCHEMA = keys(
    {},
    {"margin": LEAF,
     "links": Each(keys(["name", "frame"], {"capsule": AXIS_SHAPE_SCHEMA, "cylinder": AXIS_SHAPE_SCHEMA,
                                            "box": keys(["min", "max"])})),
     "allow": Each(LEAF)},
)


ROBOT_SCHEMA = keys(
    {"name": LEAF, "units": UNITS_SCHEMA, "dh": Each(keys(["alpha", "a", "d"], ["offset"])),
     "limits": LEAF, "base": FRAME_SCHEMA, "tool": FRAME_SCHEMA, "gripper": GRIPPER_SCHEMA},
    {"convention": LEAF, "ik": LEAF, "collision": COLLISION_SCHEMA,
     **{"home": LEAF, "velocity_limits": LEAF}},  # motion keys: _robot_motion
)


# a problem's `robot:` given inline from a URDF (lengths and angles in the problem's units)
URDF_ROBOT_SCHEMA = keys(
    {"urdf": LEAF, "base_link": LEAF, "tip_link": LEAF, "gripper": GRIPPER_SCHEMA},
    {"name": LEAF, "base": FRAME_SCHEMA, "tool": FRAME_SCHEMA, "limits": LEAF, "ik": LEAF,
     "collision": COLLISION_SCHEMA, **{"home": LEAF, "velocity_limits": LEAF}},  # motion keys: _robot_motion
)


#: A problem's obstacle: a named box, z-cylinder or mesh in the world frame (a support: parts may rest on it).
OBSTACLE_SCHEMA = keys(["name"], {"box": keys(["min", "max"]), "cylinder": keys(["radius", "z", "center"]),
                                  "mesh": LEAF, "xyz": LEAF, "rpy": LEAF, "support": LEAF})


PROBLEM_SCHEMA = keys(
    {"problem": LEAF, "units": UNITS_SCHEMA, "robot": LEAF,
     "gripper": LEAF,
     "uncertainty": keys({"manipulator": BOUNDS_SCHEMA, "objects": Named(BOUNDS_SCHEMA)}),
     "goals": LEAF},
    {"sensors": Named(BOUNDS_SCHEMA), "transforms": Named(keys(["tm"])), "vectors": Named(LEAF),
     "placement_regions": Each(keys(["x", "y"])),
     "obstacles": Each(OBSTACLE_SCHEMA), "table": keys(["x", "y"]), "clearance": LEAF, "collision": LEAF,
     "home": LEAF, "motion": LEAF, "allow_large_angles": LEAF, "product": LEAF, "layout": LEAF,
     # required unless layout: auto places a product's parts (kb.problem._objects)
     "objects": Named(keys({"initial": OneOrMany(keys(["name", "label", "tm"]))}, ["model"]))},
)


#: A product file (kb/products): parts at their poses, mates ({peg, hole, retention}) and
#: seats ({seat, on}) in one list, the base part (kb.products checks which keys go together).
#: A part gives ``model:`` or ``mesh:`` (its features and mates then derived: world.product.assembly);
#: ``retention: {PART: loose | fixed}`` sets the retention of the derived mates PART is put in by.
PRODUCT_SCHEMA = keys(
    {"product": LEAF, "units": UNITS_SCHEMA,
     "parts": Named(keys({}, {"model": LEAF, "pose": FRAME_SCHEMA, "mesh": LEAF, "units": UNITS_SCHEMA,
                             "features": Each(FEATURE_SCHEMA, 1), "face_names": Named(LEAF)}))},
    {"base": LEAF, "mates": Each(keys({}, ["peg", "hole", "retention", "seat", "on", "direction"]), 1),
     "contact_tol": LEAF, "clearance_max": LEAF, "retention": Named(LEAF), "precedence": Each(Each(LEAF, 2), 1)},
)


@dataclass(frozen=True)
class Kind:
    """A file kind: the top-level key that marks it, its schema, and what a reader calls it."""

    name: str
    marker: str
    schema: Keys
    called: str

    @property
    def wanted(self) -> str:
        """How a message asks for a file of this kind: 'an object file'."""
        return self.called.replace(" model", " file")


KINDS = MappingProxyType({
    "problem": Kind("problem", "problem", PROBLEM_SCHEMA, "a problem file"),
    "object": Kind("object", "object", OBJECT_SCHEMA, "an object model"),
    "robot": Kind("robot", "dh", ROBOT_SCHEMA, "a robot model"),
    "product": Kind("product", "product", PRODUCT_SCHEMA, "a product file"),
})


def schema_keys(spec: Spec) -> set[str]:
    """Every key name a schema accepts, at any depth (docs/kb-format.md must mention each)."""
    if isinstance(spec, Keys):
        subs = {**spec.required, **spec.optional}
        return set(subs).union(*(schema_keys(s) for s in subs.values()))
    if isinstance(spec, OneOf):
        return set(spec.choices).union(*(schema_keys(s) for s in spec.choices.values()))
    if isinstance(spec, (Each, OneOrMany)):
        return schema_keys(spec.item)
    if isinstance(spec, Named):
        return schema_keys(spec.value)
    return set()


def check_shape(node: Node, spec: Spec) -> None:
    """Check ``node`` against a schema: mappings, lists, no unknown key (with a did-you-mean),
    every required key present, user names are labels. Leaves are left to the loaders.

    A value :func:`conforms` to passes at once; any other is walked by :func:`_check_shape`,
    which raises the first problem's error."""
    if not conforms(node.value, spec):
        _check_shape(node, spec)


def conforms(value: Any, spec: Spec) -> bool:
    """True only if :func:`check_shape` passes ``value`` against ``spec`` (it may be False
    where check_shape passes: a dict or list subclass, a key that is no str), without the
    Nodes, paths and messages check_shape builds for its errors."""
    t = type(spec)
    if t is Leaf:
        return True
    if t is Keys:
        if type(value) is not dict:
            return False
        req, opt = spec.required, spec.optional  # type: ignore[union-attr]
        for k, child in value.items():
            if type(k) is not str:
                return False
            sub = opt.get(k)  # optional first: _check_keys's {**required, **optional}
            if sub is None:
                sub = req.get(k)
                if sub is None:
                    return False
            if type(sub) is not Leaf and not conforms(child, sub):
                return False
        return all(k in value for k in req)
    if t is Each:
        return (type(value) is list and len(value) >= spec.min_len  # type: ignore[union-attr]
                and all(conforms(e, spec.item) for e in value))  # type: ignore[union-attr]
    if t is OneOrMany:
        if type(value) is list:
            return len(value) >= 1 and all(conforms(e, spec.item) for e in value)  # type: ignore[union-attr]
        return not isinstance(value, list) and conforms(value, spec.item)  # type: ignore[union-attr]
    if t is Named:
        return type(value) is dict and all(
            type(k) is str and LABEL_RE.fullmatch(k) is not None and conforms(c, spec.value)  # type: ignore[union-attr]
            for k, c in value.items())
    if t is OneOf:
        if type(value) is not dict or len(value) != 1:
            return False
        (k, child), = value.items()
        sub = spec.choices.get(k) if type(k) is str else None  # type: ignore[union-attr]
        return sub is not None and conforms(child, sub)
    return False


def _check_shape(node: Node, spec: Spec) -> None:
    """check_shape's walk: raises the first problem's error (KBError, UnknownKeyError)."""
    if isinstance(spec, Keys):
        _check_keys(node, spec)
    elif isinstance(spec, Each):
        for e in node.elements(spec.min_len):
            _check_shape(e, spec.item)
    elif isinstance(spec, OneOrMany):
        _check_shape(node, Each(spec.item, 1) if isinstance(node.value, list) else spec.item)
    elif isinstance(spec, Named):
        for k, child in node.items():
            Node(node.file, child.path, k).label()
            _check_shape(child, spec.value)
    elif isinstance(spec, OneOf):
        children = node.items()
        if len(children) != 1:
            raise node.fail(f"one of {', '.join(spec.choices)}", f"{len(children)} keys")
        (k, child), = children
        if k not in spec.choices:
            raise UnknownKeyError(node.file, child.path, did_you_mean(k, spec.choices))
        _check_shape(child, spec.choices[k])


def _check_keys(node: Node, spec: Keys) -> None:
    """check_shape of a :class:`Keys` mapping: no unknown key, every required key, each value by its spec."""
    allowed = {**spec.required, **spec.optional}
    children = node.items()
    for k, child in children:
        if k not in allowed:
            raise UnknownKeyError(node.file, child.path, did_you_mean(k, allowed))
    present = {k for k, _ in children}
    for k in spec.required:
        if k not in present:
            node.key(k)  # raises: key missing
    for k, child in children:
        _check_shape(child, allowed[k])


def describe(data: Any) -> str:
    """What a parsed file is, in a few words, never quoting it: 'an object model (it has `object:`)'."""
    if isinstance(data, dict):
        for kind in KINDS.values():
            if kind.marker in data:
                return f"{kind.called} (it has `{kind.marker}:`)"
        return f"a mapping with none of {', '.join(f'`{k.marker}:`' for k in KINDS.values())}"
    if data is None:
        return "an empty file"
    if isinstance(data, str):
        return "a plain text file"
    if isinstance(data, list):
        return "a YAML list"
    return f"a single {type(data).__name__} value"


def file_kind(root: Node) -> Kind | None:
    """The kind of a parsed KB file, by its marker key (None if it has none)."""
    return next((k for k in KINDS.values() if k.marker in root.value), None)


def read_yaml(path: str | Path, max_bytes: int = MAX_INPUT_BYTES) -> Node:
    """Parse a KB file of any kind into a root :class:`Node`; the top level must be a mapping."""
    data = parse_yaml(path, max_bytes)
    if not isinstance(data, dict):
        raise KBError(str(path), "", "a mapping of keys (a problem, object or robot file)", describe(data))
    return Node(str(path), "", data)


def read_kb(path: str | Path, kind: str, max_bytes: int = MAX_INPUT_BYTES) -> Node:
    """Read a KB file that must be of ``kind`` ('problem', 'object' or 'robot') and check it
    against that kind's schema; a file of another kind is named for what it is."""
    want = KINDS[kind]
    data = parse_yaml(path, max_bytes)
    root = Node(str(path), "", data)
    got = file_kind(root) if isinstance(data, dict) else None
    if got is not want:
        what = f"a mapping without `{want.marker}:`" if isinstance(data, dict) and got is None else describe(data)
        raise WrongKindError(str(path), "", want.wanted, what)
    check_shape(root, want.schema)
    return root
