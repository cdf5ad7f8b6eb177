"""Knowledge-base loading: YAML files -> validated models (model.py) -> Prolog facts.

Every malformed input raises :class:`~spar_py.errors.KBError`, whose message is one
line: ``FILE: KEY.PATH: what was expected``. Units are converted once, here: lengths
to the problem file's length unit, angles to radians.

The formats are documented in docs/kb-format.md.
"""
from __future__ import annotations

import hashlib
import math
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Iterable

import numpy as np
import yaml

from . import sanity
from .errors import KBError, SparError, SparValueError
from .geometry import ORTHO_TOL, eulerxyz, rotation_problem, rpy, same_stable_pose, tm_rows, trans
from .kinematics import Robot
from .model import (
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

LENGTH_UNITS = {"mm": 1.0, "m": 1000.0, "in": 25.4, "cm": 10.0}
ANGLE_UNITS = {"deg": math.pi / 180.0, "rad": 1.0}
LABEL_RE = re.compile(r"^[a-z][A-Za-z0-9_]*$")


# --------------------------------------------------------------------------- reading


@dataclass(frozen=True)
class Node:
    """A YAML value with the file and key path it came from, for one-line errors."""

    file: str
    path: str
    value: Any

    def fail(self, expected: str) -> KBError:
        """The error for this node: ``FILE: PATH: EXPECTED``."""
        return KBError(self.file, self.path or "(top level)", expected)

    def key(self, name: str, required: bool = True) -> "Node | None":
        """The child ``name`` of a mapping (None if absent and not required)."""
        if not isinstance(self.value, dict):
            raise self.fail("a mapping")
        if name not in self.value:
            if required:
                raise Node(self.file, self._join(name), None).fail("a value (key missing)")
            return None
        return Node(self.file, self._join(name), self.value[name])

    def items(self) -> list[tuple[str, "Node"]]:
        """The (key, child) pairs of a mapping."""
        if not isinstance(self.value, dict):
            raise self.fail("a mapping")
        return [(str(k), Node(self.file, self._join(str(k)), v)) for k, v in self.value.items()]

    def elements(self, min_len: int = 0) -> list["Node"]:
        """The children of a sequence (at least ``min_len`` of them)."""
        if not isinstance(self.value, list) or len(self.value) < min_len:
            raise self.fail(f"a list of at least {min_len} items" if min_len else "a list")
        return [Node(self.file, f"{self.path}[{i}]", v) for i, v in enumerate(self.value)]

    def number(self) -> float:
        """A finite real number."""
        v = self.value
        if isinstance(v, bool) or not isinstance(v, (int, float)):
            raise self.fail(f"a number, not {_show(v)}")
        if not math.isfinite(v):
            raise self.fail(f"a finite number, not {v}")
        return float(v)

    def positive(self) -> float:
        """A number > 0."""
        v = self.number()
        if v <= 0:
            raise self.fail(f"a positive number, not {v}")
        return v

    def label(self) -> str:
        """A Prolog-atom-like label (lower-case start, letters, digits, underscores)."""
        v = self.value
        if not isinstance(v, str) or not LABEL_RE.match(v):
            raise self.fail(f"a label (letters, digits, _; lower-case first), not {_show(v)}")
        return v

    def text(self) -> str:
        """A non-empty string."""
        if not isinstance(self.value, str) or not self.value.strip():
            raise self.fail(f"a non-empty string, not {_show(self.value)}")
        return self.value

    def vector(self, n: int) -> np.ndarray:
        """A list of ``n`` numbers."""
        items = self.elements()
        if len(items) != n:
            raise self.fail(f"a list of {n} numbers, not {len(items)} items")
        return np.array([e.number() for e in items])

    def interval(self) -> tuple[float, float]:
        """A ``[lo, hi]`` pair with lo <= hi."""
        lo, hi = self.vector(2)
        if lo > hi:
            raise self.fail(f"[lo, hi] with lo <= hi, not [{lo}, {hi}]")
        return float(lo), float(hi)

    def _join(self, name: str) -> str:
        return f"{self.path}.{name}" if self.path else name


def _show(v: Any) -> str:
    if v is None:
        return "nothing"
    s = repr(v)
    return s if len(s) <= 40 else s[:37] + "..."


def _fingerprint(files: Iterable[str]) -> str:
    """SHA-1 over the bytes of ``files`` (the files a cell was loaded from)."""
    h = hashlib.sha1()
    for f in files:
        try:
            h.update(hashlib.sha1(Path(f).read_bytes()).digest())
        except OSError:
            h.update(b"?")
    return h.hexdigest()


def read_yaml(path: str | Path) -> Node:
    """Parse a YAML file into a root :class:`Node`; syntax errors become one-line KBErrors."""
    p = Path(path)
    try:
        text = p.read_text(encoding="utf-8")
    except OSError as e:
        raise KBError(str(path), "(file)", f"a readable file ({e.strerror})") from None
    try:
        data = yaml.load(text, Loader=getattr(yaml, "CSafeLoader", yaml.SafeLoader))
    except yaml.YAMLError as e:
        mark = getattr(e, "problem_mark", None)
        where = f"line {mark.line + 1}, column {mark.column + 1}" if mark else "(file)"
        problem = getattr(e, "problem", None) or "valid YAML"
        raise KBError(str(path), where, f"valid YAML ({problem})") from None
    if not isinstance(data, dict):
        raise KBError(str(path), "(top level)", "a mapping of keys")
    return Node(str(path), "", data)


def _units(root: Node) -> tuple[str, float, float]:
    """(length unit name, mm per unit, radians per unit) from a ``units`` block."""
    u = root.key("units")
    length = u.key("length")
    angle = u.key("angle")
    if length.value not in LENGTH_UNITS:
        raise length.fail(f"one of {', '.join(LENGTH_UNITS)}, not {_show(length.value)}")
    if angle.value not in ANGLE_UNITS:
        raise angle.fail(f"one of {', '.join(ANGLE_UNITS)}, not {_show(angle.value)}")
    return length.value, LENGTH_UNITS[length.value], ANGLE_UNITS[angle.value]


def tm_node(node: Node, length_scale: float) -> np.ndarray:
    """A 4x4 transform from the paper's row form ``[[r1], [r2], [r3], [d]]`` (Fig. 18).

    The rows r1..r3 are the images of the frame's x, y, z axes (row-vector
    convention, as the paper prints its matrices), d the displacement, in the file's
    length unit (multiplied by ``length_scale``). The rotation must pass geometry's
    check (orthonormal to ``ORTHO_TOL``, det +1).
    """
    rows = node.elements()
    if len(rows) != 4:
        raise node.fail("tm rows [[r1], [r2], [r3], [d]] (4 rows of 3 numbers)")
    m = np.array([r.vector(3) for r in rows])
    m[3] *= length_scale
    T = tm_rows(m)
    why = rotation_problem(T[:3, :3])
    if why is not None:
        raise node.fail(f"an orthonormal right-handed rotation in rows 1-3 "
                        f"(orthonormal to {ORTHO_TOL:g}, det +1; {why})")
    return T


# --------------------------------------------------------------------------- objects


def _faces(node: Node, known: set[Face] | None, min_len: int = 1) -> tuple[Face, ...]:
    out = []
    for e in node.elements(min_len):
        f = e.value
        if isinstance(f, bool) or not isinstance(f, (int, str)):
            raise e.fail(f"a face name or number, not {_show(f)}")
        if known is not None and f not in known:
            raise e.fail(f"a face of the object ({', '.join(map(str, sorted(known, key=str)))}), not {_show(f)}")
        out.append(f)
    return tuple(out)


def load_object(path: str | Path, unit: str) -> ObjectModel:
    """Load ``kb/objects/*.yaml`` converting lengths to ``unit``."""
    root = read_yaml(path)
    name = root.key("object").label()
    _, mm_per, rad_per = _units(root)
    scale = mm_per / LENGTH_UNITS[unit]
    faces_node = root.key("faces")
    faces = _faces(faces_node, None)
    if len(set(faces)) != len(faces):
        raise faces_node.fail("distinct face names")
    known = set(faces)

    poses: dict[str, StablePose] = {}
    for p in root.key("stable_poses").elements(1):
        label = p.key("label").label()
        if label in poses:
            raise p.key("label").fail(f"a label not used before, not {label}")
        T = tm_node(p.key("tm"), scale)
        poses[label] = StablePose(
            label, _faces(p.key("rfaces"), known), _faces(p.key("ofaces"), known, 0),
            T[:3, :3].copy(), float(T[2, 3]),
        )

    grasps: dict[str, Grasp] = {}
    for g in root.key("grasps").elements(1):
        label = g.key("label").label()
        if label in grasps:
            raise g.key("label").fail(f"a label not used before, not {label}")
        e = g.key("eulerxyz").vector(6)
        euler = (e[0] * scale, e[1] * scale, e[2] * scale, e[3] * rad_per, e[4] * rad_per, e[5] * rad_per)
        grasps[label] = Grasp(
            label,
            _faces(g.key("gfaces"), known),
            _faces(g.key("ofaces"), known, 0),
            euler,
            g.key("width").positive() * scale,
            eulerxyz(*euler),
        )
    clash = set(poses) & set(grasps)
    if clash:
        raise root.key("grasps").fail(f"labels distinct from stable pose labels ({', '.join(sorted(clash))})")

    feature = None
    fnode = root.key("feature", required=False)
    if fnode is not None:
        kind = fnode.key("kind")
        if kind.value not in ("peg", "hole"):
            raise kind.fail(f"peg or hole, not {_show(kind.value)}")
        feature = MatingFeature(
            kind.value,
            _faces(fnode.key("faces"), known),
            fnode.key("radius").positive() * scale,
            fnode.key("vector").vector(3) * scale,
        )
    shape = tuple(_solid(n, scale) for n in (root.key("shape", required=False) or Node("", "", [])).elements())
    return ObjectModel(name, faces, poses, grasps, feature, shape)


# --------------------------------------------------------------------------- robots


def _robot_frame(node: Node, length_scale: float, rad_per: float) -> np.ndarray:
    """``{xyz: [x, y, z], rpy: [r, p, y]}`` (file units; rpy optional) as ``trans(xyz) @ rpy(r, p, y)``."""
    xyz = node.key("xyz").vector(3) * length_scale
    r = node.key("rpy", required=False)
    ang = r.vector(3) * rad_per if r is not None else np.zeros(3)
    return trans(*xyz) @ rpy(*ang)


def load_robot(path: str | Path, unit: str | None = None) -> Robot:
    """Load ``kb/robots/*.yaml`` as a :class:`~spar_py.kinematics.Robot`.

    Lengths (DH a and d, base and tool frames, finger separation) are converted to
    ``unit`` (default: the file's own length unit), angles (DH alpha and offset,
    limits, rpy) to radians; ``base`` is T_world_frame0 and ``tool`` T_flange_tool,
    each ``trans(xyz) @ rpy(r, p, y)``. Malformed files raise :class:`KBError` naming
    the file, the key path and what was expected (``puma.yaml: dh[2].alpha: a number,
    not 'x'``); an unknown ``unit`` raises SparValueError.
    """
    if unit is not None and unit not in LENGTH_UNITS:
        raise SparValueError(f"unknown length unit {unit!r} (one of {', '.join(LENGTH_UNITS)})")
    root = read_yaml(path)
    name = root.key("name").label()
    file_unit, mm_per, rad_per = _units(root)
    unit = file_unit if unit is None else unit
    scale = mm_per / LENGTH_UNITS[unit]

    dh_node = root.key("dh")
    rows = dh_node.elements()
    if len(rows) != 6:
        raise dh_node.fail(f"a list of 6 joint rows {{alpha, a, d, offset}}, not {len(rows)}")
    dh = np.array([[r.key("alpha").number() * rad_per, r.key("a").number() * scale,
                    r.key("d").number() * scale,
                    (o.number() if (o := r.key("offset", required=False)) is not None else 0.0) * rad_per]
                   for r in rows])
    lim_node = root.key("limits")
    lims = lim_node.elements()
    if len(lims) != 6:
        raise lim_node.fail(f"a list of 6 [lo, hi] joint limits, not {len(lims)}")
    limits = np.array([lim.interval() for lim in lims]) * rad_per

    base = _robot_frame(root.key("base"), scale, rad_per)
    tool = _robot_frame(root.key("tool"), scale, rad_per)
    wm = root.key("gripper").key("finger_separation").positive() * scale
    try:
        return Robot(name, dh, limits, base, tool, wm, unit)
    except SparValueError as e:
        raise KBError(str(path), "(robot)", str(e)) from None


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
    raise node.fail("a shape primitive {box: {min, max}} or {cylinder: {radius, z}}")


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


GOAL_SHAPES: dict[str, int] = {"assembled": 5, "part_location": 2}


def _check_goal(node: Node, goal: Any, cell_objects: dict[str, ObjectModel], transforms: dict, vectors: dict,
                positions: dict[str, Position]) -> None:
    """Validate a parsed goal against the cell (known objects, faces, transforms, positions)."""
    if not isinstance(goal, tuple) or goal[0] not in GOAL_SHAPES or len(goal) - 1 != GOAL_SHAPES[goal[0]]:
        raise node.fail("a goal assembled(Peg, Hole, [[PegFaces], [HoleFaces]], Ta, Va) "
                        "or part_location(Object, InitialPosition)")
    if goal[0] == "part_location":
        _, obj, pos = goal
        if obj not in cell_objects:
            raise node.fail(f"a known object in part_location/2 ({', '.join(sorted(cell_objects))}), not {_show(obj)}")
        names = sorted(p.name for p in positions.values() if p.obj == obj)
        if pos not in names:
            raise node.fail(f"an initial position of {obj} in part_location/2 ({', '.join(names)}), not {_show(pos)}")
        return
    _, held, fixed, faces, ta, va = goal
    for role, obj in (("first", held), ("second", fixed)):
        if obj not in cell_objects:
            raise node.fail(f"a known object as {role} argument ({', '.join(sorted(cell_objects))}), not {_show(obj)}")
    if not (isinstance(faces, list) and len(faces) == 2 and all(isinstance(f, list) for f in faces)):
        raise node.fail("mating faces as [[PegFaces], [HoleFaces]]")
    for obj, fl in ((held, faces[0]), (fixed, faces[1])):
        for f in fl:
            if f not in cell_objects[obj].faces:
                raise node.fail(f"faces of {obj} in the mating faces, not {_show(f)}")
    if ta not in transforms:
        raise node.fail(f"Ta naming a transform under transforms:, not {_show(ta)}")
    if va not in vectors:
        raise node.fail(f"Va naming a vector under vectors:, not {_show(va)}")


def load_problem(path: str | Path) -> Cell:
    """Load and validate ``kb/problems/*.yaml`` with the robot and object files it names."""
    path = Path(path)
    root = read_yaml(path)
    name = root.key("problem").label()
    unit, mm_per, rad_per = _units(root)
    base = path.parent

    rnode = root.key("robot")
    rpath = base / rnode.text()
    if not rpath.is_file():
        raise rnode.fail(f"a robot file (no file {rpath})")
    robot = load_robot(rpath, unit=unit)

    objects: dict[str, ObjectModel] = {}
    positions: dict[str, Position] = {}
    names: set[str] = set()
    for oname, onode in root.key("objects").items():
        mnode = onode.key("model")
        mpath = base / mnode.text()
        if not mpath.is_file():
            raise mnode.fail(f"an object file (no file {mpath})")
        model = load_object(mpath, unit)
        if model.name != oname:
            raise mnode.fail(f"the model of {oname}, not of {model.name}")
        objects[oname] = model
        inode = onode.key("initial")
        # one position, or a list of them: a stock of identical parts of this model
        # (part_location(Obj, Pos) holds for each; "the peg" is whichever is taken)
        inits = inode.elements(1) if isinstance(inode.value, list) else [inode]
        for init in inits:
            pname, plabel = init.key("name").label(), init.key("label").label()
            if plabel in positions or pname in names:
                raise init.fail(f"a position name and label not used before ({pname}, {plabel})")
            T = tm_node(init.key("tm"), 1.0)
            if not any(same_stable_pose(T[:3, :3], p.R) for p in model.poses.values()):
                raise init.key("tm").fail(f"an orientation of one of {oname}'s stable poses")
            positions[plabel] = Position(pname, plabel, oname, T)
            names.add(pname)
    if not objects:
        raise root.key("objects").fail("at least one object")

    grip = root.key("gripper")
    if grip.value not in ("open", "closed"):
        raise grip.fail(f"open or closed, not {_show(grip.value)}")

    unc = root.key("uncertainty")
    len_scale = 1.0
    man = _bounds(unc.key("manipulator"), len_scale, rad_per)
    obj_bounds: dict[str, Bounds] = {}
    onodes = unc.key("objects")
    for oname, bnode in onodes.items():
        if oname not in objects:
            raise bnode.fail(f"bounds of a known object ({', '.join(sorted(objects))})")
        obj_bounds[oname] = _bounds(bnode, len_scale, rad_per)
    for oname in objects:
        if oname not in obj_bounds:
            raise onodes.fail(f"bounds for every object (missing {oname})")

    sensors: dict[str, Sensor] = {}
    snode = root.key("sensors", required=False)
    for sname, s in snode.items() if snode is not None else []:
        sensors[sname] = Sensor(sname, _bounds(s, len_scale, rad_per))

    transforms = {k: tm_node(n.key("tm"), 1.0) for k, n in (root.key("transforms", False) or Node("", "", {})).items()}
    vectors = {k: n.vector(3) for k, n in (root.key("vectors", False) or Node("", "", {})).items()}

    goals: list[str] = []
    for g in root.key("goals").elements(1):
        try:
            term = parse_term(g.text())
        except ValueError as e:
            raise g.fail(f"a Prolog term ({e})") from None
        _check_goal(g, term, objects, transforms, vectors, positions)
        goals.append(term_text(term))

    initial = [f"gripper({grip.value})"] + [f"part_location({p.obj}, {p.name})" for p in positions.values()]
    regions = []
    rnode2 = root.key("placement_regions", required=False)
    for r in rnode2.elements() if rnode2 is not None else []:
        lo, hi = r.key("x").interval(), r.key("y").interval()
        regions.append({"x": lo, "y": hi})
    used = [path, rpath] + [base / n.key("model").text() for _, n in root.key("objects").items()]
    files = tuple(dict.fromkeys(str(Path(u).resolve()) for u in used))
    cell = Cell(
        fingerprint=_fingerprint(files),
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
        initial=initial,
        goals=goals,
        manipulator_bounds=man,
        object_bounds=obj_bounds,
        sensors=sensors,
        placement_regions=regions,
    )
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
    position_class/2, initial/1, goal/1, transform/2, vector/2, problem/1.
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
    out += [("initial", parse_term(f)) for f in cell.initial]
    out += [("goal", parse_term(g)) for g in cell.goals]
    return out


# --------------------------------------------------------------------------- checking


def check_file(path: str | Path) -> str:
    """Validate one KB file of any kind (problem, object, robot); return a one-line summary."""
    root = read_yaml(path)
    v = root.value
    if "problem" in v:
        cell = load_problem(path)
        return f"{path}: ok (problem {cell.name}: {len(cell.objects)} objects, {len(cell.goals)} goals)"
    if "object" in v:
        unit = _units(root)[0]
        o = load_object(path, unit)
        return (f"{path}: ok (object {o.name}: {len(o.faces)} faces, {len(o.poses)} stable poses, "
                f"{len(o.grasps)} grasps)")
    if "dh" in v:
        r = load_robot(path)
        return f"{path}: ok (robot {r.name})"
    raise root.fail("a problem (key problem), object (key object) or robot (key dh) file")


def iter_kb_files(paths: Iterable[str | Path]) -> list[Path]:
    """Expand directories to their *.yaml files (sorted), keep files as given."""
    out: list[Path] = []
    for p in map(Path, paths):
        out += sorted(p.rglob("*.yaml")) if p.is_dir() else [p]
    return out

