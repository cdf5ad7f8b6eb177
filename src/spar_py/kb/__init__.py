"""Knowledge-base loading: YAML files -> validated models (model.py) -> Prolog facts.

Every malformed input raises :class:`~spar_py.core.errors.KBError`, whose message is one
line: ``FILE: KEY.PATH: expected ..., not ...``. Reading is bounded before anything
is parsed: a file must be a regular file (never a FIFO or a device), at most
``max_bytes`` (MAX_INPUT_BYTES by default), UTF-8, and its YAML at most MAX_NODES
nodes once aliases are expanded, without duplicate keys (a document with no anchor, tag or
duplicate is built straight from libyaml's events, :func:`_fast_load`; any other goes to the
full loader, whose data and messages stand). Each file kind (problem,
object, robot) has one schema (PROBLEM_SCHEMA, OBJECT_SCHEMA, ROBOT_SCHEMA): unknown
keys are errors with a did-you-mean. Units are converted once, here: lengths to the
problem file's length unit, angles to radians.

The formats are documented in docs/kb-format.md.
"""
from __future__ import annotations

import math
import os
import re
import stat
import struct
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from types import MappingProxyType
from typing import Any, Iterable, Iterator, Mapping, Union

import numpy as np
import yaml

from spar_py.kb import sanity
from spar_py.core.memo import Memo
from spar_py.core.units import from_mm
from spar_py.core.errors import KBError, SparError, SparValueError, UnknownKeyError, WrongKindError
from spar_py.core.geometry import ORTHO_TOL, eulerxyz, rotation_problem, rpy, same_stable_pose, tm_rows, trans
from spar_py.world.robots import (
    GripperGeometry,
    LinkShape,
    Robot,
    UrdfMeshError,
    read_urdf_chain,
    robot_from_urdf,
    standard_to_modified,
)
from spar_py.core.model import (
    Bounds,
    Cell,
    Face,
    Grasp,
    MatingFeature,
    ObjectModel,
    Position,
    Sensor,
    Solid,
    StablePose,
)

LENGTH_UNITS = MappingProxyType({"mm": 1.0, "m": 1000.0, "in": 25.4, "cm": 10.0})
ANGLE_UNITS = MappingProxyType({"deg": math.pi / 180.0, "rad": 1.0})
LABEL_RE = re.compile(r"[a-z][A-Za-z0-9_]*")  # used with fullmatch: no trailing newline
MAX_INPUT_BYTES = 1_000_000  # per file; `spar plan/kb check --max-input-bytes N` raises it
MAX_NODES = 100_000  # YAML nodes of one file with every alias expanded (a billion-laughs bomb)
MAX_DEPTH = 64  # nesting of YAML collections
MAX_MAGNITUDE = 1e9  # any number in a KB file, in the file's units
# The sensing actions kb/templates/sensing.pl defines: the names `sensors:` may use.
SENSOR_NAMES = ("dense_range_scan",)
SHOW_CHARS = 40  # a value quoted in a message is cut to this many characters
#: Entries of each memo table one problem's load keeps (load_problem: transforms by their
#: tm rows, stable-pose tests by their rotations), the least recently used dropped first.
LOAD_MEMO_LIMIT = 4096


# --------------------------------------------------------------------------- schemas


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

OBJECT_SCHEMA = keys(
    {"object": LEAF, "units": UNITS_SCHEMA},
    {"faces": LEAF,
     "stable_poses": Each(keys(["label", "rfaces", "ofaces", "tm"]), 1),
     "grasps": Each(keys(["label", "gfaces", "ofaces", "eulerxyz", "width"]), 1),
     # the paper's form {kind, faces, radius, vector} or by geometry {kind, name, radius, axis, length}
     "feature": keys(["kind", "radius"], {"faces": LEAF, "vector": LEAF, "name": LEAF, "length": LEAF,
                                          "axis": keys(["origin", "direction"])}),
     "shape": Each(OneOf(MappingProxyType({"box": keys(["min", "max"], ["subtract"]),
                                           "cylinder": keys(["radius", "z"], ["subtract"])}))),
     "mesh": LEAF, "face_names": Named(LEAF), "grasp_step": LEAF},
)
#: The entries an object model may leave out when it gives its geometry (derived: world.shapes).
DERIVABLE = ("faces", "stable_poses", "grasps")
#: The gripper opening assumed when an object model is derived without a robot (mm: the
#: PUMA 762's 4 in, kb/robots/puma762.yaml).
DEFAULT_OPENING_MM = 101.6

#: A gripper box's sizes (robot file ``gripper: finger`` and ``palm``).
GRIPPER_BOX_SCHEMA = keys(["length", "width", "thickness"])
GRIPPER_SCHEMA = keys(["finger_separation"], {"finger": GRIPPER_BOX_SCHEMA, "palm": GRIPPER_BOX_SCHEMA})
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
#: A problem's obstacle: a named box, z-cylinder or mesh in the world frame.
OBSTACLE_SCHEMA = keys(["name"], {"box": keys(["min", "max"]), "cylinder": keys(["radius", "z", "center"]),
                                  "mesh": LEAF, "xyz": LEAF, "rpy": LEAF})
#: How a robot file's `ik:` may name its solver: auto = the first closed-form family that fits, else
#: numeric (spar_py.world.ik.FAMILIES)
IK_CHOICES = ("auto", "puma", "ur", "numeric")

PROBLEM_SCHEMA = keys(
    {"problem": LEAF, "units": UNITS_SCHEMA, "robot": LEAF,
     "objects": Named(keys({"model": LEAF, "initial": OneOrMany(keys(["name", "label", "tm"]))})),
     "gripper": LEAF,
     "uncertainty": keys({"manipulator": BOUNDS_SCHEMA, "objects": Named(BOUNDS_SCHEMA)}),
     "goals": LEAF},
    {"sensors": Named(BOUNDS_SCHEMA), "transforms": Named(keys(["tm"])), "vectors": Named(LEAF),
     "placement_regions": Each(keys(["x", "y"])),
     "obstacles": Each(OBSTACLE_SCHEMA), "table": keys(["x", "y"]), "clearance": LEAF, "collision": LEAF,
     "home": LEAF, "motion": LEAF},
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


# --------------------------------------------------------------------------- messages


def show(v: Any) -> str:
    """A value for a message: numbers rounded for reading (``0.16``), strings quoted, cut to
    SHOW_CHARS characters; collections by size only (never a whole structure, never a file)."""
    if v is None:
        return "nothing"
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v) if abs(v) < 10**15 else f"an integer of about {int(v.bit_length() * 0.30103) + 1} digits"
    if isinstance(v, float):
        return f"{v:.6g}"
    if isinstance(v, str):
        return _cut(repr(v[: SHOW_CHARS + 2]))
    if isinstance(v, list):
        if len(v) <= 6 and all(isinstance(x, (int, float, str)) for x in v):
            return _cut("[" + ", ".join(show(x) for x in v) + "]")
        return f"a list of {len(v)} items"
    if isinstance(v, dict):
        return f"a mapping of {len(v)} keys"
    return _cut(type(v).__name__)


def num(x: float) -> str:
    """A number rounded for reading in a message (6 significant digits)."""
    return f"{x:.6g}"


def _cut(s: str) -> str:
    return s if len(s) <= SHOW_CHARS else s[: SHOW_CHARS - 3] + "..."


def _did_you_mean(name: str, choices: Iterable[str]) -> str | None:
    import difflib  # only for an unknown name's message: a cold plan of a good file never needs it

    close = difflib.get_close_matches(name, list(choices), n=1, cutoff=0.6)
    return close[0] if close else None


# --------------------------------------------------------------------------- reading


@dataclass(frozen=True)
class Node:
    """A YAML value with the file and key path it came from, for one-line errors."""

    file: str
    path: str
    value: Any

    def fail(self, expected: str, got: str | None = None) -> KBError:
        """The error for this node: ``FILE: PATH: expected EXPECTED, not GOT``."""
        return KBError(self.file, self.path or "(top level)", expected, got)

    def key(self, name: str, required: bool = True) -> "Node | None":
        """The child ``name`` of a mapping (None if absent and not required)."""
        if not isinstance(self.value, dict):
            raise self.fail("a mapping", show(self.value))
        if name not in self.value:
            if required:
                raise Node(self.file, self._join(name), None).fail("a value (key missing)")
            return None
        return Node(self.file, self._join(name), self.value[name])

    def items(self) -> list[tuple[str, "Node"]]:
        """The (key, child) pairs of a mapping."""
        if not isinstance(self.value, dict):
            raise self.fail("a mapping", show(self.value))
        return [(str(k), Node(self.file, self._join(str(k)), v)) for k, v in self.value.items()]

    def elements(self, min_len: int = 0) -> list["Node"]:
        """The children of a sequence (at least ``min_len`` of them)."""
        if not isinstance(self.value, list) or len(self.value) < min_len:
            raise self.fail((f"a list of at least {min_len} item" + "s" * (min_len > 1)) if min_len else "a list",
                            show(self.value))
        return [Node(self.file, f"{self.path}[{i}]", v) for i, v in enumerate(self.value)]

    def number(self) -> float:
        """A finite real number of magnitude at most MAX_MAGNITUDE."""
        v = self.value
        if isinstance(v, bool) or not isinstance(v, (int, float)):
            raise self.fail("a number", show(v))
        if isinstance(v, float) and not math.isfinite(v):
            raise self.fail("a finite number", show(v))
        if abs(v) > MAX_MAGNITUDE:
            raise self.fail(f"a number of magnitude at most {num(MAX_MAGNITUDE)}", show(v))
        return float(v)

    def positive(self) -> float:
        """A number > 0."""
        v = self.number()
        if v <= 0:
            raise self.fail("a positive number", num(v))
        return v

    def label(self) -> str:
        """A Prolog-atom-like label (lower-case start, letters, digits, underscores), exactly."""
        v = self.value
        if not isinstance(v, str) or not LABEL_RE.fullmatch(v):
            raise self.fail("a label (letters, digits, _; lower-case first)", show(v))
        return v

    def text(self) -> str:
        """A non-empty string."""
        if not isinstance(self.value, str) or not self.value.strip():
            raise self.fail("a non-empty string", show(self.value))
        return self.value

    def choice(self, options: Iterable[str]) -> str:
        """One of the strings ``options``."""
        opts = tuple(options)
        if not isinstance(self.value, str) or self.value not in opts:
            raise self.fail(f"one of {', '.join(opts)}", show(self.value))
        return self.value

    def vector(self, n: int) -> np.ndarray:
        """A list of ``n`` numbers (each as :meth:`number` takes it), as an (n,) float array."""
        v = self.value
        if type(v) is list and len(v) == n:  # every item an int or float number() takes: no Nodes
            xs = [float(x) for x in v if (type(x) is float or type(x) is int) and abs(x) <= MAX_MAGNITUDE]
            if len(xs) == n:
                return np.array(xs)
        items = self.elements()
        if len(items) != n:
            raise self.fail(f"a list of {n} numbers", f"{len(items)} items")
        return np.array([e.number() for e in items])

    def interval(self) -> tuple[float, float]:
        """A ``[lo, hi]`` pair with lo <= hi."""
        lo, hi = self.vector(2)
        if lo > hi:
            raise self.fail("[lo, hi] with lo <= hi", f"[{num(lo)}, {num(hi)}]")
        return float(lo), float(hi)

    def _join(self, name: str) -> str:
        return f"{self.path}.{name}" if self.path else name


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
            raise UnknownKeyError(node.file, child.path, _did_you_mean(k, spec.choices))
        _check_shape(child, spec.choices[k])


def _check_keys(node: Node, spec: Keys) -> None:
    allowed = {**spec.required, **spec.optional}
    children = node.items()
    for k, child in children:
        if k not in allowed:
            raise UnknownKeyError(node.file, child.path, _did_you_mean(k, allowed))
    present = {k for k, _ in children}
    for k in spec.required:
        if k not in present:
            node.key(k)  # raises: key missing
    for k, child in children:
        _check_shape(child, allowed[k])


_FILE_TYPES = ((stat.S_ISDIR, "a directory"), (stat.S_ISFIFO, "a FIFO"), (stat.S_ISCHR, "a character device"),
               (stat.S_ISBLK, "a block device"), (stat.S_ISSOCK, "a socket"))


def read_text(path: str | Path, max_bytes: int = MAX_INPUT_BYTES) -> str:
    """The text of a KB file: a regular file (checked with os.stat before it is opened, so a
    FIFO or /dev/zero is refused at once) of at most ``max_bytes``, in UTF-8."""
    f = str(path)
    try:
        st = os.stat(path)
    except OSError as e:
        raise KBError(f, "", f"a readable file ({e.strerror})") from None
    if not stat.S_ISREG(st.st_mode):
        what = next((w for test, w in _FILE_TYPES if test(st.st_mode)), "a special file")
        raise KBError(f, "", "a regular file", what)
    too_big = f"a file of at most {max_bytes} bytes (--max-input-bytes raises the limit)"
    if st.st_size > max_bytes:
        raise KBError(f, "", too_big, f"{st.st_size} bytes")
    try:
        with open(path, "rb") as fh:
            data = fh.read(max_bytes + 1)
    except OSError as e:
        raise KBError(f, "", f"a readable file ({e.strerror})") from None
    if len(data) > max_bytes:
        raise KBError(f, "", too_big, "a file that grew while read")
    if data.startswith((b"\xff\xfe", b"\xfe\xff")):
        raise KBError(f, "", "a UTF-8 text file", "UTF-16 (it starts with a UTF-16 byte-order mark)")
    try:
        return data.decode("utf-8").removeprefix("\ufeff")
    except UnicodeDecodeError as e:
        raise KBError(f, "", "a UTF-8 text file", f"one with byte 0x{data[e.start]:02x} at offset {e.start}") from None


#: PyYAML's safe loader, libyaml's where PyYAML has it (the same data, parsed in C).
SAFE_LOADER: type = getattr(yaml, "CSafeLoader", yaml.SafeLoader)


class Refused(yaml.YAMLError):
    """The loader refuses a document (a duplicate key, an alias bomb): where, expected, not what."""

    def __init__(self, mark: Any, expected: str, got: str | None = None) -> None:
        self.mark, self.expected, self.got = mark, expected, got
        super().__init__(expected)


class BoundedLoader(SAFE_LOADER):  # type: ignore[misc, valid-type]
    """PyYAML's safe loader that refuses duplicate keys and, in a document with anchors,
    more than MAX_NODES nodes with aliases expanded, nesting deeper than MAX_DEPTH and
    recursive aliases, before it builds any Python object. (Without an anchor there is no
    alias: the node count is bounded by the file size; read_yaml bounds the nesting.)"""

    def get_single_data(self) -> Any:
        """The document, once its node graph passed :func:`_check_graph` (if it has anchors)."""
        node = self.get_single_node()
        if node is None:
            return None
        if getattr(self, "has_anchors", True):
            _check_graph(node)
        return self.construct_document(node)

    def construct_mapping(self, node: yaml.MappingNode, deep: bool = False) -> dict:
        """A mapping, refusing a key given twice (merge keys ``<<`` may be overridden)."""
        seen: set[Any] = set()
        for key_node, _ in node.value:
            if key_node.tag == "tag:yaml.org,2002:merge":
                continue
            key = self.construct_object(key_node, deep=True)
            try:
                dup = key in seen
                seen.add(key)
            except TypeError:
                raise Refused(key_node.start_mark, "a mapping key that is a plain value", show(key)) from None
            if dup:
                raise Refused(key_node.start_mark, f"the key {show(key)} once in its mapping", "a second time")
        return super().construct_mapping(node, deep=deep)

    def construct_bounded_int(self, node: yaml.ScalarNode) -> int:
        """An integer; one too long for Python's int parser is a YAML error, not a ValueError."""
        try:
            return self.construct_yaml_int(node)
        except ValueError:
            raise Refused(node.start_mark, "an integer of at most 4300 digits", "a longer one") from None


BoundedLoader.add_constructor("tag:yaml.org,2002:int", BoundedLoader.construct_bounded_int)
# YAML 1.2 floats PyYAML (YAML 1.1) reads as strings: 1e-3, 1.0e308 (1.1 wants a dot and a signed exponent)
BoundedLoader.add_implicit_resolver("tag:yaml.org,2002:float", re.compile(r"^[-+]?[0-9]+(\.[0-9]*)?[eE][-+]?[0-9]+$"),
                                    list("-+0123456789"))


def _children(node: yaml.Node) -> Iterator[yaml.Node]:
    if isinstance(node, yaml.SequenceNode):
        yield from node.value
    elif isinstance(node, yaml.MappingNode):
        for k, v in node.value:
            yield k
            yield v


def _check_graph(root: yaml.Node) -> None:
    """Refuse a YAML node graph whose alias-expanded size exceeds MAX_NODES, whose nesting
    exceeds MAX_DEPTH, or with a recursive alias; linear in the graph (sizes memoised)."""
    sizes: dict[int, int] = {}
    open_: set[int] = set()  # the ancestors of the node being visited
    stack: list[tuple[yaml.Node, bool]] = [(root, False)]
    while stack:
        node, closing = stack.pop()
        k = id(node)
        if closing:
            open_.discard(k)
            sizes[k] = 1 + sum(sizes[id(c)] for c in _children(node))
            if sizes[k] > MAX_NODES:
                raise Refused(node.start_mark, f"at most {MAX_NODES} YAML nodes with aliases expanded",
                              "more (an alias bomb?)")
            continue
        if k in sizes:
            continue
        if k in open_:
            raise Refused(node.start_mark, "an alias that does not contain itself", "a recursive one")
        if len(open_) >= MAX_DEPTH:
            raise Refused(node.start_mark, f"at most {MAX_DEPTH} levels of nesting", "more")
        open_.add(k)
        stack.append((node, True))
        stack.extend((c, False) for c in _children(node) if id(c) not in sizes)


def parse_yaml(path: str | Path, max_bytes: int = MAX_INPUT_BYTES) -> Any:
    """The YAML data of a file, bounded (read_text, BoundedLoader); every reading, decoding
    or YAML problem is a one-line KBError."""
    text = read_text(path, max_bytes)
    try:
        data = _load(text)
    except yaml.reader.ReaderError as e:
        raise KBError(str(path), "", "a UTF-8 text file of printable characters",
                      f"one with character #x{e.character:04x} at offset {e.position}"
                      if isinstance(e.character, int) else "one with a control character") from None
    except Refused as e:
        raise KBError(str(path), _where(e.mark), e.expected, e.got) from None
    except RecursionError:
        raise KBError(str(path), "", f"at most {MAX_DEPTH} levels of nesting", "far more") from None
    except yaml.YAMLError as e:
        mark = getattr(e, "problem_mark", None)
        problem = str(getattr(e, "problem", None) or "valid YAML")
        raise KBError(str(path), _where(mark), f"valid YAML ({problem[:80]})") from None
    return data


def read_yaml(path: str | Path, max_bytes: int = MAX_INPUT_BYTES) -> Node:
    """Parse a KB file of any kind into a root :class:`Node`; the top level must be a mapping."""
    data = parse_yaml(path, max_bytes)
    if not isinstance(data, dict):
        raise KBError(str(path), "", "a mapping of keys (a problem, object or robot file)", describe(data))
    return Node(str(path), "", data)


class _NotFast(Exception):
    """:func:`_fast_load` cannot vouch for a document: BoundedLoader's full path decides."""


_TAG = "tag:yaml.org,2002:"
_FAST_INT = re.compile(r"[-+]?(?:0|[1-9][0-9]*)")  # decimal, no '_': int() reads it as YAML 1.1 does
_FAST_FLOAT = re.compile(r"[-+]?[0-9]*\.?[0-9]*(?:[eE][-+]?[0-9]+)?")  # no '_', ':', inf or nan


_NOT_YET = object()  # a plain scalar not constructed yet


def _fast_scalar(loader: Any, value: str, implicit: tuple[bool, bool]) -> Any:
    """A plain (untagged, unquoted) scalar as BoundedLoader constructs it, for the tags whose
    construction is one builtin call: str, null, bool, decimal int, decimal float; any other
    tag or form (0x1, 012, 1_000, 1:30, .inf, a timestamp, ``<<``, an int too long) is _NotFast."""
    tag = loader.resolve(yaml.ScalarNode, value, implicit)
    if tag == _TAG + "str":
        return value
    if tag == _TAG + "int" and _FAST_INT.fullmatch(value):
        try:
            return int(value)
        except ValueError:  # more digits than int() reads: construct_bounded_int's message
            raise _NotFast from None
    if tag == _TAG + "float" and _FAST_FLOAT.fullmatch(value):
        return float(value)  # == construct_yaml_float's sign * float(unsigned), bit for bit
    if tag == _TAG + "bool":
        return BoundedLoader.bool_values[value.lower()]
    if tag == _TAG + "null":
        return None
    raise _NotFast


def _fast_load(text: str) -> Any:
    """The document of ``text`` built straight from libyaml's events, or _NotFast.

    The data is what BoundedLoader builds (equal, same types, same key order) for the
    documents this reader takes: one document, no anchor, alias or explicit tag, scalar keys
    each once in its mapping, nesting at most MAX_DEPTH, scalars as :func:`_fast_scalar`
    takes them. Anything else, and every error, is _NotFast, and the caller reads the text
    again with the full loader, whose message (or data) stands: so the fast path can only
    ever agree with it. It skips building the node graph and constructing every key twice
    (the full loader's duplicate check), and resolves each distinct plain scalar once.
    """
    if BoundedLoader.yaml_path_resolvers:
        raise _NotFast  # a resolver by path would see nodes this reader never builds
    loader = BoundedLoader(text)
    plain: dict[str, Any] = {}  # this text's plain scalars, constructed (immutable values)
    not_yet = _NOT_YET
    props = "!" in text or "&" in text  # a tag or an anchor is possible (each starts so)
    scalar_event, seq_start, map_start = yaml.ScalarEvent, yaml.SequenceStartEvent, yaml.MappingStartEvent
    seq_end, map_end = yaml.SequenceEndEvent, yaml.MappingEndEvent
    try:
        get = loader.get_event
        if type(get()) is not yaml.StreamStartEvent:
            raise _NotFast
        ev = get()
        if type(ev) is yaml.StreamEndEvent:
            return None
        if type(ev) is not yaml.DocumentStartEvent:
            raise _NotFast
        root: list[Any] = []
        no_key: Any = root  # sentinel: the open mapping awaits a key
        top: Any = root  # the open collection (a list or a dict)
        in_map = False  # top is a dict
        key: Any = no_key  # the open mapping's key awaiting its value
        stack: list[tuple[Any, bool, Any]] = []  # the enclosing collections with their pending keys
        while True:
            ev = get()
            cls = type(ev)
            if cls is scalar_event:
                if props and (ev.tag is not None or ev.anchor is not None):
                    raise _NotFast
                value = ev.value
                if ev.implicit[0]:  # plain: resolved by the loader's own resolvers (by the text alone)
                    v = plain.get(value, not_yet)
                    if v is not_yet:
                        v = plain[value] = _fast_scalar(loader, value, ev.implicit)
                    value = v
            elif cls is map_start or cls is seq_start:
                if (props and (ev.tag is not None or ev.anchor is not None)) or len(stack) >= MAX_DEPTH or (
                        in_map and key is no_key):
                    raise _NotFast  # ... or a collection as a key
                stack.append((top, in_map, key))
                in_map = cls is map_start
                top, key = ({} if in_map else []), no_key
                continue
            elif (cls is map_end or cls is seq_end) and stack:
                value = top
                top, in_map, key = stack.pop()
            elif cls is yaml.DocumentEndEvent and not stack and len(root) == 1:
                break
            else:
                raise _NotFast
            if not in_map:
                top.append(value)
            elif key is no_key:
                key = value
            elif key in top:  # a duplicate (1, 1.0 and true are one key): the full loader's message
                raise _NotFast
            else:
                top[key] = value
                key = no_key
        if type(get()) is not yaml.StreamEndEvent:
            raise _NotFast  # a second document
        return root[0]
    except _NotFast:
        raise
    except Exception:  # a syntax or reader error, anything unforeseen: the full loader says it
        raise _NotFast from None
    finally:
        loader.dispose()


def _load(text: str) -> Any:
    """``yaml.load(text)`` with :class:`BoundedLoader`: by :func:`_fast_load` where it can
    vouch for the document (every KB file the project writes), else :func:`_full_load`."""
    try:
        return _fast_load(text)
    except _NotFast:
        return _full_load(text)


def _full_load(text: str) -> Any:
    """``yaml.load(text)`` with :class:`BoundedLoader`, the alias-graph check only where an
    alias can be (an anchor ``&`` in the text): it costs a third of a load."""
    loader = BoundedLoader(text)
    loader.has_anchors = "&" in text
    try:
        return loader.get_single_data()
    finally:
        loader.dispose()


def _where(mark: Any) -> str:
    """'line L, column C' of a YAML mark ('' without one)."""
    return f"line {mark.line + 1}, column {mark.column + 1}" if mark is not None else ""


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


def _units(root: Node) -> tuple[str, float, float]:
    """(length unit name, mm per unit, radians per unit) from a ``units`` block."""
    u = root.key("units")
    length = u.key("length").choice(LENGTH_UNITS)
    angle = u.key("angle").choice(ANGLE_UNITS)
    return length, LENGTH_UNITS[length], ANGLE_UNITS[angle]


def tm_node(node: Node, length_scale: float, memo: Memo | None = None) -> np.ndarray:
    """A 4x4 transform from the paper's row form ``[[r1], [r2], [r3], [d]]`` (Fig. 18).

    The rows r1..r3 are the images of the frame's x, y, z axes (row-vector
    convention, as the paper prints its matrices), d the displacement, in the file's
    length unit (multiplied by ``length_scale``). The rotation must pass geometry's
    check (orthonormal to ``ORTHO_TOL``, det +1). With ``memo`` (one load's tables,
    :func:`load_problem`) the transform of rows already read is a copy of the one built
    then: the same numbers, the same transform.
    """
    v = node.value
    flat = [float(x) for r in v if type(r) is list and len(r) == 3
            for x in r if (type(x) is float or type(x) is int) and abs(x) <= MAX_MAGNITUDE
            ] if type(v) is list and len(v) == 4 else []
    table = memo.table("tm_node", LOAD_MEMO_LIMIT) if memo is not None and len(flat) == 12 else None
    if table is not None:  # the key: the 12 numbers' and the scale's bits (-0.0 is not 0.0)
        key = struct.pack("13d", *flat, length_scale)
        known = table.get(key)
        if known is not None:
            return known.copy()
    if len(flat) == 12:  # 4 rows of 3 numbers as Node.vector takes them: no Nodes
        m = np.array(flat).reshape(4, 3)
    else:
        rows = node.elements()
        if len(rows) != 4:
            raise node.fail("tm rows [[r1], [r2], [r3], [d]] (4 rows of 3 numbers)", f"{len(rows)} rows")
        m = np.array([r.vector(3) for r in rows])
    m[3] *= length_scale
    T = tm_rows(m)
    why = rotation_problem(T[:3, :3])
    if why is not None:
        hint = ("; write exact values or more digits, e.g. 0.70710678118655 for sqrt(1/2), not 0.7071"
                if why.startswith("R^T R") else "")
        raise node.fail(f"an orthonormal right-handed rotation in rows 1-3 "
                        f"(orthonormal to {ORTHO_TOL:g}, det +1; {why}{hint})")
    if table is not None:
        table[key] = T.copy()
    return T


# --------------------------------------------------------------------------- objects


def _faces(node: Node, known: set[Face] | None, min_len: int = 1) -> tuple[Face, ...]:
    """A list of at least ``min_len`` face names (labels) or numbers, each one of ``known``
    (when given)."""
    v = node.value
    if type(v) is list and len(v) >= min_len and all(
            (LABEL_RE.fullmatch(f) is not None if type(f) is str else type(f) is int and abs(f) <= MAX_MAGNITUDE)
            and (known is None or f in known) for f in v):
        return tuple(v)  # every face as the loop below takes it: no Nodes
    out = []
    for e in node.elements(min_len):
        f = e.value
        if isinstance(f, bool) or not isinstance(f, (int, str)) or (isinstance(f, int) and abs(f) > MAX_MAGNITUDE):
            raise e.fail("a face name or number", show(f))
        if isinstance(f, str):
            e.label()
        if known is not None and f not in known:
            raise e.fail(f"a face of the object ({_cut(', '.join(map(str, sorted(known, key=str))))})", show(f))
        out.append(f)
    return tuple(out)


def load_object(path: str | Path, unit: str, max_bytes: int = MAX_INPUT_BYTES, opening: float | None = None,
                use_cache: bool = True, gripper: GripperGeometry | None = None,
                memo: Memo | None = None) -> ObjectModel:
    """Load ``kb/objects/*.yaml`` converting lengths to ``unit``.

    ``faces``, ``stable_poses`` and ``grasps`` left out of a model with ``mesh:`` or
    ``shape:`` are derived from its geometry (world.shapes, cached by content hash:
    world.shapes_cache) for the robot's ``gripper`` (its opening, fingers and palm, cell unit)
    or, without one, a gripper of opening ``opening`` (cell unit; DEFAULT_OPENING_MM without a
    robot) with the default fingers; hand-written ones take precedence. Only a derivation
    imports trimesh. ``memo``: the tables of a load reading many files (:func:`tm_node`,
    :func:`_grasp_frame`); the model is the same without.
    """
    root = read_kb(path, "object", max_bytes)
    name = root.key("object").label()
    _, mm_per, rad_per = _units(root)
    scale = mm_per / LENGTH_UNITS[unit]
    geometry, solids = _geometry(root, Path(path), unit, scale)
    face_names = {k: n.vector(3) * scale for k, n in (root.key("face_names", False) or Node("", "", {})).items()}
    fnode = root.key("feature", required=False)
    feature_geo = _feature_geometry(fnode, scale) if fnode is not None else None
    if geometry is not None:
        geometry.face_names = face_names
        geometry.step = _grasp_step(root, rad_per)
    missing = [k for k in DERIVABLE if k not in root.value]
    derived = None
    if missing:
        if geometry is None:
            root.key(missing[0])  # raises: key missing
        step = geometry.step
        from spar_py.world.shapes_cache import derive

        grip = _derive_gripper(unit, opening, gripper)
        try:
            derived = derive(name, geometry, feature_geo, face_names, grip, step, need_hull=True,
                             use_cache=use_cache)
        except KBError:
            raise
        except Exception as e:  # trimesh, manifold3d, scipy: a shape they cannot take is bad input
            raise _geometry_error(path, geometry, e) from None
        geometry.hull = np.asarray(derived["hull"], float)
        if geometry.mesh_file is not None:
            pts = geometry.hull
            solids = (Solid("hull", pts.min(0), pts.max(0), 0.0, pts),)
    elif face_names and geometry is None:
        raise root.key("face_names").fail("a model with mesh: or shape: (face_names name the faces of its geometry)")

    faces_node = root.key("faces", required=False)
    if faces_node is not None:
        faces = _faces(faces_node, None)
        if len(set(faces)) != len(faces):
            raise faces_node.fail("distinct face names")
    else:
        faces = tuple(derived["faces"])
    known = set(faces)

    poses: dict[str, StablePose] = {}
    if "stable_poses" in root.value:
        for p in root.key("stable_poses").elements(1):
            label = p.key("label").label()
            if label in poses:
                raise p.key("label").fail("a label not used before", show(label))
            T = tm_node(p.key("tm"), scale, memo)
            poses[label] = StablePose(
                label, _faces(p.key("rfaces"), known), _faces(p.key("ofaces"), known, 0),
                T[:3, :3].copy(), float(T[2, 3]),
            )
    else:
        for d in derived["poses"]:
            _known(root, faces_node, d["label"], d["rfaces"] + d["ofaces"], known, "stable pose")
            poses[d["label"]] = StablePose(d["label"], tuple(d["rfaces"]), tuple(d["ofaces"]),
                                           np.array(d["R"], float).reshape(3, 3), float(d["height"]))
        if not poses:
            raise KBError(str(path), "mesh" if geometry.mesh_file else "shape",
                          "a part with at least one stable pose (resting on a face, its centre of mass over it)")

    grasps: dict[str, Grasp] = {}
    if "grasps" in root.value:
        for g in root.key("grasps").elements(1):
            label = g.key("label").label()
            if label in grasps:
                raise g.key("label").fail("a label not used before", show(label))
            e = g.key("eulerxyz").vector(6)
            euler = (e[0] * scale, e[1] * scale, e[2] * scale, e[3] * rad_per, e[4] * rad_per, e[5] * rad_per)
            grasps[label] = Grasp(
                label,
                _faces(g.key("gfaces"), known),
                _faces(g.key("ofaces"), known, 0),
                euler,
                g.key("width").positive() * scale,
                _grasp_frame(euler, memo),
            )
    else:
        for d in derived["grasps"]:
            _known(root, faces_node, d["label"], d["gfaces"] + d["ofaces"], known, "grasp")
            euler = tuple(float(v) for v in d["euler"])
            grasps[d["label"]] = Grasp(d["label"], tuple(d["gfaces"]), tuple(d["ofaces"]), euler,  # type: ignore[arg-type]
                                       float(d["width"]), eulerxyz(*euler))
        if not grasps:
            raise KBError(str(path), "mesh" if geometry.mesh_file else "shape",
                          "a part the gripper can hold (no pair of opposite faces or shaft within its opening)")
    clash = set(poses) & set(grasps)
    if clash:
        raise root.key("grasps").fail(f"labels distinct from stable pose labels ({', '.join(sorted(clash))})")

    feature = None
    if fnode is not None:
        if feature_geo is not None:
            if feature_geo.name not in known:
                raise fnode.key("name").fail("the name of a face on the shape at the feature (its axis, radius and "
                                             "length place it)", show(feature_geo.name))
            feature = MatingFeature(feature_geo.kind, (feature_geo.name,), feature_geo.radius, feature_geo.end,
                                    feature_geo)
        else:
            feature = MatingFeature(
                fnode.key("kind").choice(("peg", "hole")),
                _faces(fnode.key("faces"), known),
                fnode.key("radius").positive() * scale,
                fnode.key("vector").vector(3) * scale,
            )
    return ObjectModel(name, faces, poses, grasps, feature, solids, geometry)


def _grasp_frame(euler: tuple[float, ...], memo: Memo | None) -> np.ndarray:
    """geometry.eulerxyz of a grasp's (X, Y, Z, phi, theta, psi) (cell unit, rad), kept in
    ``memo`` (one load's tables) by the six numbers' bits; a hit is a copy."""
    if memo is None:
        return eulerxyz(*euler)
    table = memo.table("eulerxyz", LOAD_MEMO_LIMIT)
    key = struct.pack("6d", *euler)
    T = table.get(key)
    if T is None:
        T = table[key] = eulerxyz(*euler)
    return T.copy()


def _geometry_error(path: str | Path, geometry: Any, e: Exception) -> KBError:
    """A derivation's failure as one line naming the key: ``face_names.NAME`` for a point off
    the shape, else ``mesh`` or ``shape`` with what was expected (world.shapes raises
    ValueError("expected ...") for the cases it knows; any other exception is named)."""
    key = "mesh" if geometry.mesh_file is not None else "shape"
    msg = " ".join(str(e).split())
    if isinstance(e, ValueError) and msg.startswith("face_names."):
        key, _, msg = msg.partition(": ")
    elif not isinstance(e, ValueError) or not msg:
        msg = f"a shape spar can derive a model from ({type(e).__name__}: {msg[:80]})"
    return KBError(str(path), key, msg.removeprefix("expected "))


def _known(root: Node, faces_node: Node | None, label: str, used: list, known: set, what: str) -> None:
    """A derived entry may only use faces the model lists (when it lists them by hand)."""
    for f in used:
        if f not in known:
            raise (faces_node or root).fail(f"every face the derived {what} {label} uses (add {f}, or leave "
                                            "faces: out to derive them)")


def _grasp_step(root: Node, rad_per: float) -> float:
    """``grasp_step``: the quantum of grasp approaches and assembly turns (file angle unit; 45 deg)."""
    n = root.key("grasp_step", required=False)
    if n is None:
        return math.radians(45.0)
    step = n.positive() * rad_per
    if not (math.radians(1.0) - 1e-12 <= step <= 2 * math.pi + 1e-12):
        raise n.fail("an angle from 1 deg to a full turn", show(n.value))
    return step


def _geometry(root: Node, path: Path, unit: str, scale: float) -> tuple[Any, tuple[Solid, ...]]:
    """The model's declared geometry (world.shapes.Geometry, or None) and its positive solids."""
    mnode, snode = root.key("mesh", required=False), root.key("shape", required=False)
    if mnode is not None and snode is not None:
        raise mnode.fail("mesh: or shape:, not both")
    if mnode is None and snode is None:
        return None, ()
    from spar_py.world.shapes import Geometry, Primitive

    if mnode is not None:
        ref = path.parent / mnode.text()
        if ref.suffix.lower() not in (".stl", ".obj", ".ply"):
            raise mnode.fail("the path of an STL, OBJ or PLY file", show(mnode.value))
        if not ref.is_file():
            raise mnode.fail("the path of a mesh file", f"{show(mnode.value)} (no such file)")
        return Geometry(unit, (), str(ref.resolve()), scale), ()
    prims = []
    for n in snode.elements():
        sol = _solid(n, scale)
        kind = "box" if "box" in n.value else "cylinder"
        sub = n.key(kind).key("subtract", required=False)
        subtract = sub is not None and _flag(sub)
        prims.append((Primitive(sol.kind, sol.lo, sol.hi, sol.radius, subtract), sol))
    if prims and all(p.subtract for p, _ in prims):
        raise snode.fail("at least one primitive that is not subtracted")
    return (Geometry(unit, tuple(p for p, _ in prims)) if prims else None,
            tuple(sol for p, sol in prims if not p.subtract))


def _flag(node: Node) -> bool:
    if not isinstance(node.value, bool):
        raise node.fail("true or false", show(node.value))
    return node.value


def _feature_geometry(fnode: Node, scale: float) -> Any:
    """The geometric form of ``feature:`` (world.shapes.FeatureGeometry), or None for the
    paper's form ``{kind, faces, radius, vector}``; mixing the two is an error."""
    geo_keys = [k for k in ("name", "axis", "length") if k in fnode.value]
    old_keys = [k for k in ("faces", "vector") if k in fnode.value]
    if geo_keys and old_keys:
        raise fnode.fail("either {kind, faces, radius, vector} or {kind, name, radius, axis, length}, "
                         f"not {', '.join(old_keys)} with {', '.join(geo_keys)}")
    if not geo_keys:
        fnode.key("faces")
        fnode.key("vector")
        return None
    from spar_py.world.shapes import FeatureGeometry

    kind = fnode.key("kind").choice(("peg", "hole"))
    name = fnode.key("name").label()
    axis = fnode.key("axis")
    d = axis.key("direction").vector(3)
    if np.linalg.norm(d) < 1e-9:
        raise axis.key("direction").fail("a non-zero direction", "[0, 0, 0]")
    return FeatureGeometry(kind, name, fnode.key("radius").positive() * scale, axis.key("origin").vector(3) * scale,
                           d / np.linalg.norm(d), fnode.key("length").positive() * scale)


# --------------------------------------------------------------------------- robots


def _robot_frame(node: Node, length_scale: float, rad_per: float) -> np.ndarray:
    """``{xyz: [x, y, z], rpy: [r, p, y]}`` (file units; rpy optional) as ``trans(xyz) @ rpy(r, p, y)``."""
    xyz = node.key("xyz").vector(3) * length_scale
    r = node.key("rpy", required=False)
    ang = r.vector(3) * rad_per if r is not None else np.zeros(3)
    return trans(*xyz) @ rpy(*ang)


#: The largest joint limit a robot file may give (rad): two turns either way. Beyond it
#: the turn representations IK enumerates grow without use (a limit of 1e9 took 1.3 GB).
MAX_JOINT_RAD = 4 * math.pi


def load_robot(path: str | Path, unit: str | None = None, max_bytes: int = MAX_INPUT_BYTES) -> Robot:
    """Load ``kb/robots/*.yaml`` as a :class:`~spar_py.world.robots.Robot`.

    Lengths (DH a and d, base and tool frames, finger separation) are converted to
    ``unit`` (default: the file's own length unit), angles (DH alpha and offset,
    limits, rpy) to radians; ``base`` is T_world_frame0 and ``tool`` T_flange_tool,
    each ``trans(xyz) @ rpy(r, p, y)``. ``convention`` says how ``dh`` reads: Craig's
    ``modified`` (default) or ``standard`` (UR's published tables; converted to Craig's
    at load, ``world.robots.standard_to_modified``). ``ik`` picks the solver (IK_CHOICES;
    default auto: the first closed-form family the table fits, else numeric).
    Malformed files raise :class:`KBError` naming the file, the key path and what was
    expected (``puma.yaml: dh[2].alpha: a number, not 'x'``); an unknown ``unit``
    raises SparValueError.
    """
    if unit is not None and unit not in LENGTH_UNITS:
        raise SparValueError(f"unknown length unit {unit!r} (one of {', '.join(LENGTH_UNITS)})")
    root = read_kb(path, "robot", max_bytes)
    name = root.key("name").label()
    file_unit, mm_per, rad_per = _units(root)
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
    base = _robot_frame(root.key("base"), scale, rad_per)
    tool = flange @ _robot_frame(root.key("tool"), scale, rad_per)
    wm = root.key("gripper").key("finger_separation").positive() * scale
    family = _ik_choice(root)
    try:
        robot = Robot(name, dh, limits, base, tool, wm, unit, family=family)
    except SparValueError as e:
        raise KBError(str(path), "dh", f"a robot the kinematics accepts ({e})") from None
    _check_family(robot, root, path, unit, file_unit, max_bytes)
    _collision_shapes(robot, root, scale, LENGTH_UNITS[unit])
    _robot_motion(robot, root, rad_per)
    return robot


def _joint_vector(node: Node, rad_per: float, what: str) -> np.ndarray:
    """Six angles (the file's angle unit) as (6,) rad."""
    items = node.elements()
    if len(items) != 6:
        raise node.fail(f"a list of 6 {what}", f"{len(items)} items")
    return np.array([e.number() for e in items]) * rad_per


def _home(node: Node | None, robot: Robot, rad_per: float) -> np.ndarray | None:
    """``home:``: six joint angles (file angle unit) within the joint limits, as rad; None if absent."""
    if node is None:
        return None
    q = _joint_vector(node, rad_per, "joint angles")
    if not robot.in_limits(q):
        lim = ", ".join(f"[{num(lo / rad_per)}, {num(hi / rad_per)}]" for lo, hi in robot.limits)
        raise node.fail(f"joint angles within the limits {lim}", "[" + ", ".join(num(v / rad_per) for v in q) + "]")
    return q


def _robot_motion(robot: Robot, root: Node, rad_per: float) -> None:
    """The robot's motion entries (world/motion.py): ``home`` (joint angles, the file's angle
    unit) and ``velocity_limits`` (six positive joint speeds, angle unit per second), in rad
    and rad/s on the Robot."""
    robot.home = _home(root.key("home", required=False), robot, rad_per)
    vnode = root.key("velocity_limits", required=False)
    if vnode is not None:
        v = _joint_vector(vnode, rad_per, "joint speeds (angle unit per second)")
        if not np.all(v > 0):
            raise vnode.fail("six positive joint speeds (angle unit per second)",
                             "[" + ", ".join(num(x / rad_per) for x in v) + "]")
        robot.velocity_limits = v


def _gripper(gnode: Node, wm: float, scale: float, mm_per_unit: float) -> GripperGeometry:
    """The ``gripper:`` section's boxes (robot unit; GripperGeometry's documented defaults where absent)."""
    def sizes(key: str) -> dict | None:
        n = gnode.key(key, required=False)
        return None if n is None else {k: n.key(k).positive() * scale for k in ("length", "width", "thickness")}
    return GripperGeometry.default(wm, mm_per_unit, sizes("finger"), sizes("palm"))


def _collision_shapes(robot: Robot, root: Node, scale: float, mm_per_unit: float) -> None:
    """Set ``robot``'s gripper boxes and its ``collision:`` section: link shapes (capsule,
    cylinder: ``{radius, from, to}``; box: ``{min, max}``; lengths in the file's unit, in Craig's
    frame ``frame`` 0..6), ``allow`` (pairs of body names never checked), ``margin``."""
    robot.gripper = _gripper(root.key("gripper"), robot.finger_separation, scale, mm_per_unit)
    cnode = root.key("collision", required=False)
    if cnode is None:
        return
    known = {"palm", "finger_l", "finger_r", "table"}
    lnode = cnode.key("links", required=False)
    if lnode is None:  # the shapes the robot already has (a URDF's own) stay: their names may be allowed
        known |= {s.name for s in robot.links}
    links: list[LinkShape] = []
    for ln in (lnode or Node(cnode.file, cnode.path, [])).elements():
        lname = ln.key("name").label()
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
        return np.eye(4) if n is None else _robot_frame(n, 1.0, rad_per)
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
    _collision_shapes(robot, node, 1.0, LENGTH_UNITS[unit])
    robot.links = robot.links or urdf_links  # the URDF's own collision shapes unless the file gives some
    _robot_motion(robot, node, rad_per)
    return robot, upath


def _solid(node: Node, scale: float) -> Solid:
    """One shape primitive: ``{box: {min: [x,y,z], max: [x,y,z]}}`` or
    ``{cylinder: {radius: r, z: [z0, z1]}}`` (axis = object z)."""
    if isinstance(node.value, dict) and "box" in node.value:
        b = node.key("box")
        lo, hi = b.key("min").vector(3) * scale, b.key("max").vector(3) * scale
        if np.any(lo >= hi):
            raise b.fail("min < max in every coordinate")
        return Solid("box", lo, hi)
    if isinstance(node.value, dict) and "cylinder" in node.value:
        c = node.key("cylinder")
        r = c.key("radius").positive() * scale
        z0, z1 = c.key("z").interval()
        return Solid("cylinder", np.array([-r, -r, z0 * scale]), np.array([r, r, z1 * scale]), r)
    raise node.fail("a shape primitive {box: {min, max}} or {cylinder: {radius, z}}", show(node.value))


# --------------------------------------------------------------------------- terms

_TOKEN = re.compile(
    r"\s*(?:(?P<num>-?\d+(?:\.\d+)?(?:[eE][-+]?\d+)?)|(?P<atom>[a-z][A-Za-z0-9_]*)"
    r"|(?P<var>[A-Z_][A-Za-z0-9_]*)|(?P<punct>[()\[\],]))"
)


def parse_term(text: str) -> Any:
    """Parse a ground Prolog term of atoms, numbers, lists and compounds.

    Returns nested Python data: atoms as ``str``, numbers as ``float``/``int``,
    lists as ``list``, compounds as ``tuple`` (functor, arg1, ...). Raises
    ValueError with the position of the first unexpected character.
    """
    tokens: list[tuple[str, str, int]] = []
    pos = 0
    text = text.strip()
    while pos < len(text):
        m = _TOKEN.match(text, pos)
        if not m or m.end() == pos:
            raise ValueError(f"unexpected {text[pos]!r} at column {pos + 1}")
        kind = m.lastgroup or ""
        if kind == "var":
            raise ValueError(f"variable {m.group(kind)} at column {m.start(kind) + 1}: goals must be ground")
        tokens.append((kind, m.group(kind), m.start(kind)))
        pos = m.end()
        while pos < len(text) and text[pos].isspace():
            pos += 1
    i = 0

    def expect(p: str) -> None:
        nonlocal i
        if i >= len(tokens) or tokens[i][1] != p:
            where = f"column {tokens[i][2] + 1}" if i < len(tokens) else "the end"
            raise ValueError(f"expected {p!r} at {where}")
        i += 1

    def term() -> Any:
        nonlocal i
        if i >= len(tokens):
            raise ValueError("unexpected end of term")
        kind, val, _ = tokens[i]
        i += 1
        if kind == "num":
            return float(val) if any(c in val for c in ".eE") else int(val)
        if kind == "atom":
            if i < len(tokens) and tokens[i][1] == "(":
                i += 1
                args = [term()]
                while i < len(tokens) and tokens[i][1] == ",":
                    i += 1
                    args.append(term())
                expect(")")
                return (val, *args)
            return val
        if val == "[":
            items: list[Any] = []
            if i < len(tokens) and tokens[i][1] == "]":
                i += 1
                return items
            items.append(term())
            while i < len(tokens) and tokens[i][1] == ",":
                i += 1
                items.append(term())
            expect("]")
            return items
        raise ValueError(f"unexpected {val!r} at column {tokens[i - 1][2] + 1}")

    t = term()
    if i != len(tokens):
        raise ValueError(f"unexpected {tokens[i][1]!r} at column {tokens[i][2] + 1}")
    return t


def term_text(t: Any) -> str:
    """Write parsed term data back as Prolog text (quoted where needed)."""
    if isinstance(t, tuple):
        return f"{t[0]}({', '.join(term_text(a) for a in t[1:])})"
    if isinstance(t, list):
        return "[" + ", ".join(term_text(a) for a in t) + "]"
    return str(t)


# --------------------------------------------------------------------------- problems


def _bounds(node: Node, len_scale: float, rad_per: float) -> Bounds:
    def iv(k: str, s: float) -> tuple[float, float]:
        lo, hi = node.key(k).interval()
        return lo * s, hi * s

    return Bounds(iv("dx", len_scale), iv("dy", len_scale), iv("dz", len_scale), iv("dtheta", rad_per))


GOAL_SHAPES: dict[str, tuple[int, ...]] = {"assembled": (5, 2), "part_location": (2,)}


def _check_goal(node: Node, goal: Any, cell_objects: dict[str, ObjectModel], transforms: dict, vectors: dict,
                positions: dict[str, Position]) -> None:
    """Validate a parsed goal against the cell (known objects, faces, transforms, positions)."""
    if not isinstance(goal, tuple) or goal[0] not in GOAL_SHAPES or len(goal) - 1 not in GOAL_SHAPES[goal[0]]:
        raise node.fail("a goal assembled(Peg, Hole), assembled(Peg, Hole, [[PegFaces], [HoleFaces]], Ta, Va) "
                        "or part_location(Object, InitialPosition)")
    if goal[0] == "part_location":
        _, obj, pos = goal
        if obj not in cell_objects:
            raise node.fail(f"a known object in part_location/2 ({', '.join(sorted(cell_objects))})", show(obj))
        names = sorted(p.name for p in positions.values() if p.obj == obj)
        if pos not in names:
            raise node.fail(f"an initial position of {obj} in part_location/2 ({', '.join(names)})", show(pos))
        return
    _, held, fixed, faces, ta, va = goal
    for role, obj in (("first", held), ("second", fixed)):
        if obj not in cell_objects:
            raise node.fail(f"a known object as {role} argument ({', '.join(sorted(cell_objects))})", show(obj))
    if not (isinstance(faces, list) and len(faces) == 2 and all(isinstance(f, list) for f in faces)):
        raise node.fail("mating faces as [[PegFaces], [HoleFaces]]")
    for obj, fl in ((held, faces[0]), (fixed, faces[1])):
        for f in fl:
            if f not in cell_objects[obj].faces:
                raise node.fail(f"faces of {obj} in the mating faces", show(f))
    if not isinstance(ta, str) or ta not in transforms:
        raise node.fail(f"Ta naming a transform under transforms: ({_names(transforms)})", show(ta))
    if not isinstance(va, str) or va not in vectors:
        raise node.fail(f"Va naming a vector under vectors: ({_names(vectors)})", show(va))


def _names(table: Mapping[str, Any]) -> str:
    """The names of a table for a message (cut), or 'none'."""
    return _cut(", ".join(table)) if table else "none"


def _ref_path(node: Node, base: Path, kind: str) -> Path:
    """The file a ``robot:`` or ``model:`` reference names, relative to the problem file."""
    ref = base / node.text()
    if not os.path.lexists(ref):
        raise node.fail(f"the path of {KINDS[kind].wanted}", f"{show(node.value)} (no such file)")
    return ref


@contextmanager
def _referenced(node: Node, kind: str) -> Iterator[None]:
    """Load the file a reference names: a file of another kind is the reference's error
    (``robot: expected the path of a robot file, not '/etc/passwd', a plain text file``)."""
    try:
        yield
    except WrongKindError as e:
        raise node.fail(f"the path of {KINDS[kind].wanted}", f"{show(node.value)}, {e.got}") from None


def _positions(onode: Node, oname: str, model: ObjectModel, taken: dict[str, Position],
               memo: Memo | None = None) -> list[Position]:
    """An object's initial position, or the list of them (a stock of identical parts:
    part_location(Obj, Pos) holds for each; "the peg" is whichever is taken). ``memo``:
    the load's tables (:func:`tm_node`, :func:`_same_stable_pose`)."""
    inode = onode.key("initial")
    inits = inode.elements(1) if isinstance(inode.value, list) else [inode]
    out: list[Position] = []
    names = {p.name for p in taken.values()}
    for init in inits:
        pname, plabel = init.key("name").label(), init.key("label").label()
        if plabel in taken or pname in names or any(plabel == p.label or pname == p.name for p in out):
            raise init.fail("a position name and label not used before", f"{pname}, {plabel}")
        T = tm_node(init.key("tm"), 1.0, memo)
        if not any(_same_stable_pose(T[:3, :3], p.R, memo) for p in model.poses.values()):
            raise init.key("tm").fail(f"an orientation of one of {oname}'s stable poses")
        out.append(Position(pname, plabel, oname, T))
    return out


def _same_stable_pose(R_abs: np.ndarray, R_pose: np.ndarray, memo: Memo | None) -> bool:
    """geometry.same_stable_pose of two (3, 3) float rotations, kept in ``memo`` (the load's
    tables) by their bytes: the same rotations, the same answer."""
    if memo is None:
        return same_stable_pose(R_abs, R_pose)
    return memo.table("same_stable_pose", LOAD_MEMO_LIMIT).get_or_compute(
        (R_abs.tobytes(), R_pose.tobytes()), lambda: same_stable_pose(R_abs, R_pose))


def _derive_gripper(unit: str, opening: float | None, gripper: GripperGeometry | None) -> Any:
    """The gripper grasps are derived and checked for (world.shapes_derive.Gripper): the robot's
    own where given, else the default fingers at ``opening`` (or DEFAULT_OPENING_MM)."""
    from spar_py.world.shapes_derive import Gripper

    if gripper is not None:
        return Gripper.of_robot(gripper)
    return Gripper.default(unit, opening if opening is not None else from_mm(unit, DEFAULT_OPENING_MM))


def _objects(root: Node, base: Path, unit: str, max_bytes: int, opening: float | None = None,
             gripper: GripperGeometry | None = None, memo: Memo | None = None
             ) -> tuple[dict[str, ObjectModel], dict[str, Position], list[Path]]:
    """The problem's objects (models loaded), their initial positions and the model files
    (``memo``: the load's tables, :func:`load_object`)."""
    objects: dict[str, ObjectModel] = {}
    positions: dict[str, Position] = {}
    files: list[Path] = []
    for oname, onode in root.key("objects").items():
        mnode = onode.key("model")
        mpath = _ref_path(mnode, base, "object")
        with _referenced(mnode, "object"):
            model = load_object(mpath, unit, max_bytes, opening=opening, gripper=gripper, memo=memo)
        if model.name != oname:
            raise mnode.fail(f"the model of {oname}", f"the model of {model.name}")
        objects[oname] = model
        files.append(mpath)
        for pos in _positions(onode, oname, model, positions, memo):
            positions[pos.label] = pos
    if not objects:
        raise root.key("objects").fail("at least one object", "none")
    return objects, positions, files


def _object_bounds(unc: Node, objects: Mapping[str, ObjectModel], rad_per: float) -> dict[str, Bounds]:
    """``uncertainty.objects``: bounds for every object of the cell, and only for them."""
    onodes = unc.key("objects")
    out: dict[str, Bounds] = {}
    for oname, bnode in onodes.items():
        if oname not in objects:
            near = _did_you_mean(oname, objects)
            raise bnode.fail(f"bounds of a known object ({', '.join(sorted(objects))})",
                             show(oname) + (f"; did you mean {near}?" if near else ""))
        out[oname] = _bounds(bnode, 1.0, rad_per)
    for oname in objects:
        if oname not in out:
            raise onodes.fail(f"bounds for every object (missing {oname})")
    return out


def _sensors(root: Node, rad_per: float) -> dict[str, Sensor]:
    """``sensors``: each named after a sensing action of kb/templates/sensing.pl (SENSOR_NAMES)."""
    snode = root.key("sensors", required=False)
    out: dict[str, Sensor] = {}
    for sname, s in snode.items() if snode is not None else []:
        if sname not in SENSOR_NAMES:
            near = _did_you_mean(sname, SENSOR_NAMES)
            raise UnknownKeyError(s.file, s.path, near) if near else s.fail(
                f"a sensing action ({', '.join(SENSOR_NAMES)})", show(sname))
        out[sname] = Sensor(sname, _bounds(s, 1.0, rad_per))
    return out


def _goals(root: Node, objects: dict[str, ObjectModel], transforms: dict, vectors: dict,
           positions: dict[str, Position], turns: dict) -> list[str]:
    """The goals, parsed and checked against the cell, as Prolog text; an ``assembled(Peg,
    Hole)`` goal adds its derived T_a turns to ``transforms`` and ``turns`` (_derived_assembly)."""
    goals: list[str] = []
    for g in root.key("goals").elements(1):
        text = g.text()  # outside the try: a KBError is a ValueError too, and must not nest
        try:
            term = parse_term(text)
        except ValueError as e:
            raise g.fail(f"a Prolog term ({e})", show(text)) from None
        if isinstance(term, tuple) and term[0] == "assembled" and len(term) == 3:
            term = _derived_assembly(g, term, objects, transforms, vectors, turns)
        _check_goal(g, term, objects, transforms, vectors, positions)
        goals.append(term_text(term))
    return goals


def _derived_assembly(node: Node, goal: tuple, objects: dict[str, ObjectModel], transforms: dict,
                      vectors: dict, turns: dict) -> tuple:
    """``assembled(Peg, Hole)`` as the paper's five-argument goal: the mating faces are the two
    features' faces, T_a and V_a derived from their geometry (world.shapes.assembly_transforms).

    T_a is a choice among the turns about the hole's axis, quantised by the finer of the two
    models' ``grasp_step`` (45 deg by default): the first turn (the least rotation of the
    peg's axis onto the hole's) is added to the cell's transforms as trans_K, turn J (J = 2,
    3, ...; turned by (J - 1) steps) as trans_K_tJ, and V_a as vec_K (the first K not taken).
    The goal names trans_K; ``turns[trans_K]`` lists every turn with the hole part's stable
    poses in which the mated peg stays clear of the table (world.shapes.poses_clear_of_table;
    every pose when the peg has no shape). The planner chooses the turn (kb/templates/actions.pl).
    """
    from spar_py.world.shapes import assembly_transforms, part_mesh, poses_clear_of_table

    _, peg, hole = goal
    feats = []
    for role, obj, kind in (("first", peg, "peg"), ("second", hole, "hole")):
        if obj not in objects:
            raise node.fail(f"a known object as {role} argument ({', '.join(sorted(objects))})", show(obj))
        f = objects[obj].feature
        if f is None or f.geometry is None or f.kind != kind:
            raise node.fail(f"{obj} with a {kind} feature declared by geometry (feature: {{kind: {kind}, name, "
                            "radius, axis, length}) for assembled/2, or the five-argument goal")
        feats.append(f)
    steps = [m.geometry.step for m in (objects[peg], objects[hole]) if m.geometry is not None]
    Tas, Va, _ = assembly_transforms(feats[0].geometry, feats[1].geometry, min(steps, default=math.radians(45.0)))
    k = 1
    while f"trans_{k}" in transforms or f"vec_{k}" in vectors or any(
            f"trans_{k}_t{j}" in transforms for j in range(2, len(Tas) + 1)):
        k += 1
    name = f"trans_{k}"
    pgeo = objects[peg].geometry
    pts = None
    if pgeo is not None:  # the hull a derivation gave, else (all entries hand-written) the mesh's vertices
        pts = pgeo.hull if pgeo.hull is not None else np.asarray(part_mesh(objects[peg]).vertices)
    poses = list(objects[hole].poses.values())
    alternatives = []
    for j, T in enumerate(Tas, start=1):
        tname = name if j == 1 else f"{name}_t{j}"
        transforms[tname] = T
        clear = ([True] * len(poses) if pts is None else poses_clear_of_table(
            pts, T, [(p.R, p.height) for p in poses], pgeo.unit))
        alternatives.append((tname, tuple(p.label for p, ok in zip(poses, clear) if ok)))
    vectors[f"vec_{k}"] = Va
    turns[name] = tuple(alternatives)
    return ("assembled", peg, hole, [list(feats[0].faces), list(feats[1].faces)], name, f"vec_{k}")


def _regions(root: Node) -> list[dict[str, tuple[float, float]]]:
    """``placement_regions``: the free table rectangles ``{x: [lo, hi], y: [lo, hi]}``."""
    rnode = root.key("placement_regions", required=False)
    return [{"x": r.key("x").interval(), "y": r.key("y").interval()}
            for r in (rnode.elements() if rnode is not None else [])]


def _obstacles(root: Node, base: Path, rad_per: float) -> list:
    """``obstacles:``: named shapes in the world frame (cell unit): ``box: {min, max}``,
    ``cylinder: {radius, z: [lo, hi], center: [x, y]}`` (axis along world z) or ``mesh: FILE``
    placed at ``xyz``, ``rpy`` (its convex hull: a conservative stand-in for a concave fixture)."""
    from spar_py.world.collision import Obstacle, box, convex, cylinder

    onode = root.key("obstacles", required=False)
    out: list = []
    seen: set[str] = set()
    for on in (onode.elements() if onode is not None else []):
        name = on.key("name").label()
        if name in seen or name == "table":
            raise on.key("name").fail("a name no other obstacle (nor the table) has", name)
        seen.add(name)
        kinds = [k for k in ("box", "cylinder", "mesh") if on.key(k, required=False) is not None]
        if len(kinds) != 1:
            raise on.fail("exactly one of box: {min, max}, cylinder: {radius, z, center}, mesh: FILE",
                          ", ".join(kinds) or "none")
        k = kinds[0]
        if k == "box":
            b = on.key("box")
            lo, hi = b.key("min").vector(3), b.key("max").vector(3)
            if np.any(lo >= hi):
                raise b.fail("min < max in every coordinate")
            bodies = (box(name, -1, lo, hi),)
        elif k == "cylinder":
            c = on.key("cylinder")
            r = c.key("radius").positive()
            z0, z1 = c.key("z").interval()
            if not z0 < z1:
                raise c.key("z").fail("[lo, hi] with lo < hi")
            cx, cy = c.key("center").vector(2)
            bodies = (cylinder(name, -1, [cx, cy, z0], [cx, cy, z1], r),)
        else:
            mnode = on.key("mesh")
            mpath = base / mnode.text()
            if not mpath.is_file():
                raise mnode.fail("the path of a mesh file (STL, OBJ, PLY)", f"{show(mnode.value)} (no such file)")
            try:
                import trimesh

                mesh = trimesh.load(str(mpath), force="mesh")
                pts = np.asarray(mesh.convex_hull.vertices, float)
            except Exception as e:  # trimesh's many loader errors: one line
                raise mnode.fail(f"a mesh trimesh can read ({type(e).__name__}: {str(e)[:80]})") from None
            T = _robot_frame(on, 1.0, rad_per) if on.key("xyz", required=False) is not None else np.eye(4)
            bodies = (convex(name, -1, pts @ T[:3, :3].T + T[:3, 3]),)
        out.append(Obstacle(name, bodies))
    return out


def _table(root: Node) -> tuple[float, float, float, float] | None:
    """``table: {x: [lo, hi], y: [lo, hi]}``: the table top's extent (cell unit), None: the whole plane."""
    tnode = root.key("table", required=False)
    if tnode is None:
        return None
    (x0, x1), (y0, y1) = tnode.key("x").interval(), tnode.key("y").interval()
    if not (x0 < x1 and y0 < y1):
        raise tnode.fail("x: [lo, hi] and y: [lo, hi] with lo < hi")
    return (x0, x1, y0, y1)


def _collision_switch(root: Node) -> bool:
    """``collision: false`` turns the collision check off for a cell (a user's opt-out: every
    reach is then decided by IK and the wrist height alone); default true."""
    node = root.key("collision", required=False)
    if node is None:
        return True
    if not isinstance(node.value, bool):
        raise node.fail("true or false", show(node.value))
    return node.value


def _clearance(root: Node) -> float | None:
    """``clearance:`` the collision margin (cell unit, >= 0), None when not given."""
    cnode = root.key("clearance", required=False)
    if cnode is None:
        return None
    m = cnode.number()
    if m < 0:
        raise cnode.fail("a clearance margin >= 0", show(cnode.value))
    return m


def load_problem(path: str | Path, max_bytes: int = MAX_INPUT_BYTES) -> Cell:
    """Load and validate ``kb/problems/*.yaml`` with the robot and object files it names
    (each file at most ``max_bytes``)."""
    path = Path(path)
    root = read_kb(path, "problem", max_bytes)
    name = root.key("problem").label()
    unit, _, rad_per = _units(root)
    base = path.parent

    rnode = root.key("robot")
    if isinstance(rnode.value, dict):  # inline, from a URDF
        robot, rpath = load_urdf_robot(rnode, base, unit, rad_per)
    else:
        rpath = _ref_path(rnode, base, "robot")
        with _referenced(rnode, "robot"):
            robot = load_robot(rpath, unit=unit, max_bytes=max_bytes)
    memo = Memo()  # this load's tables: the object files of a problem repeat their transforms
    objects, positions, model_files = _objects(root, base, unit, max_bytes, robot.finger_separation, robot.gripper,
                                               memo)
    grip = root.key("gripper").choice(("open", "closed"))
    unc = root.key("uncertainty")
    man = _bounds(unc.key("manipulator"), 1.0, rad_per)
    obj_bounds = _object_bounds(unc, objects, rad_per)
    sensors = _sensors(root, rad_per)
    transforms = {k: tm_node(n.key("tm"), 1.0, memo)
                  for k, n in (root.key("transforms", False) or Node("", "", {})).items()}
    vectors = {k: n.vector(3) for k, n in (root.key("vectors", False) or Node("", "", {})).items()}
    turns: dict[str, tuple[tuple[str, tuple[str, ...]], ...]] = {}
    goals = _goals(root, objects, transforms, vectors, positions, turns)
    initial = [f"gripper({grip})"] + [f"part_location({p.obj}, {p.name})" for p in positions.values()]
    meshes = [m.geometry.mesh_file for m in objects.values() if m.geometry is not None and m.geometry.mesh_file]
    files = tuple(dict.fromkeys(str(Path(u).resolve()) for u in [path, rpath, *model_files, *meshes]))
    cell = Cell(
        files=files,
        name=name,
        file=str(path),
        unit=unit,
        robot=robot,
        finger_separation=robot.finger_separation,
        objects=objects,
        positions=positions,
        transforms=transforms,
        vectors=vectors,
        turns=turns,
        initial=initial,
        goals=goals,
        manipulator_bounds=man,
        object_bounds=obj_bounds,
        sensors=sensors,
        placement_regions=_regions(root),
        obstacles=tuple(_obstacles(root, base, rad_per)),
        table=_table(root),
        clearance=_clearance(root),
        collisions=_collision_switch(root),
        home=_home(root.key("home", required=False), robot, rad_per),
    )
    if cell.home is None:
        cell.home = robot.home
    mnode = root.key("motion", required=False)
    if mnode is not None and not isinstance(mnode.value, bool):
        raise mnode.fail("true or false (plan the motions between the end-points)", show(mnode.value))
    cell.plan_motions = bool(mnode is not None and mnode.value)
    sanity.check_cell(cell)  # physically possible: parts apart, on the table, in reach (sanity.py)
    return cell


# --------------------------------------------------------------------------- facts


def _tm(T: np.ndarray) -> tuple:
    rows = [[_num(v) for v in T[:3, i]] for i in range(3)] + [[_num(v) for v in T[:3, 3]]]
    return ("tm", rows)


def _num(v: float) -> float:
    r = round(float(v), 12)
    return 0.0 if r == 0 else r


def position_class(cell: Cell, pos: Position) -> str:
    """The stable pose an absolute position rests in (Sec. 5.2.3)."""
    for label, pose in cell.objects[pos.obj].poses.items():
        if same_stable_pose(pos.T[:3, :3], pose.R):
            return label
    raise SparError(f"{cell.file}: objects.{pos.obj}.initial.tm: an orientation of a stable pose")


def facts(cell: Cell) -> list[tuple]:
    """The Prolog facts of a cell (module kb), as term data for the bridge.

    Shapes follow Figs. 18-19: pose/5, grasp/6, plus object/1, face/2, position/4,
    position_class/2, initial/1, goal/1, transform/2, vector/2, problem/1, and turn/3 for
    a derived T_a: turn(Ta, Turn, HolePoses), in order, each turn the planner may assemble
    with and the hole part's stable poses in which the mated peg clears the table.
    """
    out: list[tuple] = [("problem", cell.name)]
    for o in cell.objects.values():
        out.append(("object", o.name))
        out += [("face", o.name, f) for f in o.faces]
        for p in o.poses.values():
            T = np.eye(4)
            T[:3, :3] = p.R
            T[2, 3] = p.height
            out.append(("pose", o.name, p.label, ("rfaces", list(p.rfaces)), ("ofaces", list(p.ofaces)), _tm(T)))
        for g in o.grasps.values():
            x, y, z, a, b, c = g.euler
            e = ("eulerxyz", _num(x), _num(y), _num(z),
                 _num(math.degrees(a)), _num(math.degrees(b)), _num(math.degrees(c)))
            out.append(("grasp", o.name, g.label, ("gfaces", list(g.gfaces)), ("ofaces", list(g.ofaces)), e,
                        ("width", g.width)))
    for p in cell.positions.values():
        out.append(("position", p.name, p.obj, p.label, _tm(p.T)))
        out.append(("position_class", p.label, position_class(cell, p)))
    out += [("transform", k, _tm(T)) for k, T in cell.transforms.items()]
    out += [("vector", k, [_num(v) for v in vec]) for k, vec in cell.vectors.items()]
    out += [("turn", ta, t, list(poses)) for ta, alts in cell.turns.items() for t, poses in alts]
    out += [("initial", parse_term(f)) for f in cell.initial]
    out += [("goal", parse_term(g)) for g in cell.goals]
    return out


# --------------------------------------------------------------------------- checking


def check_file(path: str | Path, max_bytes: int = MAX_INPUT_BYTES) -> str:
    """Validate one KB file of any kind (problem, object, robot); return a one-line summary."""
    root = read_yaml(path, max_bytes)
    kind = file_kind(root)
    if kind is None:
        raise KBError(str(path), "", "a problem, object or robot file", describe(root.value))
    if kind.name == "problem":
        cell = load_problem(path, max_bytes)
        for oname, model in cell.objects.items():
            mfile = next((f for f in cell.files if Path(f).suffix == ".yaml" and _object_name(f) == oname), None)
            if mfile is not None:
                check_against_shape(mfile, read_yaml(mfile, max_bytes), model, cell.unit, cell.finger_separation,
                                    cell.robot.gripper)
        return f"{path}: ok (problem {cell.name}: {len(cell.objects)} objects, {len(cell.goals)} goals)"
    if kind.name == "object":
        o = load_object(path, _units(root)[0], max_bytes)
        check_against_shape(path, root, o, _units(root)[0])
        return (f"{path}: ok (object {o.name}: {len(o.faces)} faces, {len(o.poses)} stable poses, "
                f"{len(o.grasps)} grasps)")
    r = load_robot(path, max_bytes=max_bytes)
    return f"{path}: ok (robot {r.name}, {r.solver_name} IK)"


def derive_text(path: str | Path, max_bytes: int = MAX_INPUT_BYTES, robot: str | Path | None = None,
                out_dir: str | Path | None = None) -> str:
    """``spar kb derive``: the object model at ``path`` as a full explicit model file (YAML
    text): its own keys as written, then every face, stable pose and grasp, derived ones
    included, in the file's own units (grasps for ``robot``'s gripper, or DEFAULT_OPENING_MM).
    A ``mesh:`` path is rewritten relative to ``out_dir`` (where the text will be written)."""
    root = read_kb(path, "object", max_bytes)
    unit, _, rad_per = _units(root)
    arm = load_robot(robot, unit=unit, max_bytes=max_bytes) if robot is not None else None
    opening, gripper = (arm.finger_separation, arm.gripper) if arm is not None else (None, None)
    m = load_object(path, unit, max_bytes, opening=opening, gripper=gripper)
    check_against_shape(path, root, m, unit, opening, gripper)

    def flow(v: Any) -> str:
        return yaml.safe_dump(v, default_flow_style=True, width=10**6, sort_keys=False).strip().removesuffix(
            "\n...").strip()

    def n(v: float) -> float | int:
        r = round(float(v), 9) + 0.0
        return int(r) if r.is_integer() and abs(r) < 1e15 else r

    grip = f"{num(opening)} {unit}" if opening is not None else f"{num(from_mm(unit, DEFAULT_OPENING_MM))} {unit}"
    out = [f"# Derived by `spar kb derive` from {path} (gripper opening {grip}); every entry explicit.",
           f"object: {m.name}", f"units: {flow(root.value['units'])}"]
    own = dict(root.value)
    if "mesh" in own and out_dir is not None and m.geometry is not None and m.geometry.mesh_file:
        own["mesh"] = os.path.relpath(m.geometry.mesh_file, Path(out_dir).resolve())
    out += [f"{k}: {flow(own[k])}" for k in ("mesh", "shape", "face_names", "grasp_step", "feature") if k in own]
    out.append(f"faces: {flow(list(m.faces))}")
    out.append("stable_poses:")
    for p in m.poses.values():
        rows = [[n(v) for v in p.R[:, i]] for i in range(3)] + [[0, 0, n(p.height)]]
        out.append("  - " + flow({"label": p.label, "rfaces": list(p.rfaces), "ofaces": list(p.ofaces), "tm": rows}))
    out.append("grasps:")
    for g in m.grasps.values():
        e = [n(v) for v in g.euler[:3]] + [n(a / rad_per) for a in g.euler[3:]]
        out.append("  - " + flow({"label": g.label, "gfaces": list(g.gfaces), "ofaces": list(g.ofaces),
                                  "eulerxyz": e, "width": n(g.width)}))
    return "\n".join(out) + "\n"


def _object_name(file: str) -> str | None:
    """The ``object:`` name of a KB file (None if it is not an object model)."""
    try:
        data = parse_yaml(file)
    except KBError:
        return None
    return data.get("object") if isinstance(data, dict) else None


def check_against_shape(path: str | Path, root: Node, model: ObjectModel, unit: str,
                        opening: float | None = None, gripper: GripperGeometry | None = None) -> None:
    """``spar kb check``: the hand-written faces, stable poses and grasps of a model that also
    gives its geometry must agree with it (world.shapes_derive.check_entries); the first
    disagreement is a KBError naming the entry. ``gripper`` is the robot's (cell unit), else the
    default fingers at ``opening`` (cell unit; DEFAULT_OPENING_MM without a robot)."""
    hand = tuple(k for k in DERIVABLE if k in root.value)
    if model.geometry is None or not hand:
        return
    from spar_py.world.shapes_derive import check_entries

    grip = _derive_gripper(unit, opening, gripper)
    try:
        problems = check_entries(model, grip, unit, hand)
    except KBError:
        raise
    except Exception as e:  # the shape itself cannot be built or searched
        raise _geometry_error(path, model.geometry, e) from None
    for key, expected, got in problems:
        raise KBError(str(path), key, expected, got)


def iter_kb_files(paths: Iterable[str | Path]) -> list[Path]:
    """Expand directories to their *.yaml files (sorted), keep files as given."""
    out: list[Path] = []
    for p in map(Path, paths):
        out += sorted(p.rglob("*.yaml")) if p.is_dir() else [p]
    return out

