"""The fast paths of the kb package (issue 18: load_problem at N = 50) agree with the slow ones.

Each fast path may only ever take what its slow path takes, and give the same data:
- ``_fast_load`` (YAML from libyaml's events) against ``_full_load`` (BoundedLoader):
  equal data with the same types and key order, or ``_NotFast`` and the full loader decides;
- ``conforms`` against ``_check_shape``: True only where the walk raises nothing;
- ``Node.vector``, ``tm_node``, ``_faces``: the same arrays or the same error as the
  per-item walk below them; ``tm_node`` with a load's memo: the same transforms, copies;
- ``sanity._overlaps`` against the pairwise loop it replaced.
"""
from __future__ import annotations

import itertools
import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from spar_py import kb
from spar_py.kb import node as kbnode
from spar_py.kb import objects, reader, sanity, schema, values
from spar_py.core.errors import KBError
from spar_py.app.gen import generate_assembly
from spar_py.core.geometry import tm_rows
from spar_py.core.memo import Memo

from paths import ROOT

YAMLS = sorted(p for d in ("kb", "tests") for p in (ROOT / d).rglob("*.yaml"))


def full(text: str) -> tuple[str, Any]:
    """What the full loader makes of ``text``: ("ok", data) or ("error", type, message)."""
    try:
        return ("ok", reader._full_load(text))
    except Exception as e:  # noqa: BLE001 - compared, not handled
        return ("error", type(e).__name__, str(e))


def same(a: Any, b: Any) -> bool:
    """Equal with the same types all the way down (1 is not 1.0 nor True) and dict order."""
    if type(a) is not type(b):
        return False
    if isinstance(a, dict):
        return list(a) == list(b) and all(same(k1, k2) and same(a[k1], b[k2]) for k1, k2 in zip(a, b))
    if isinstance(a, list):
        return len(a) == len(b) and all(same(x, y) for x, y in zip(a, b))
    if isinstance(a, float):
        return math.copysign(1, a) == math.copysign(1, b) and (a == b or (math.isnan(a) and math.isnan(b)))
    return a == b


def agree(text: str) -> bool:
    """_fast_load is right about ``text``: the full loader's data, or _NotFast; True if fast."""
    try:
        got = reader._fast_load(text)
    except reader._NotFast:
        return False
    want = full(text)
    assert want[0] == "ok", f"the fast reader took what the full loader refuses: {want}"
    assert same(got, want[1]), (got, want[1])
    return True


# --------------------------------------------------------------------------- _fast_load


@pytest.mark.parametrize("path", YAMLS, ids=lambda p: str(p.relative_to(ROOT)))
def test_fast_reader_agrees_on_every_kb_and_test_file(path: Path) -> None:
    try:
        text = reader.read_text(path)
    except KBError:
        return  # not text: read_text refuses it before any YAML
    agree(text)


def test_fast_reader_takes_the_project_files() -> None:
    """Every kb/ file is read fast (else the speed-up is gone: a fallback is silent)."""
    slow = [str(p) for p in YAMLS if "kb" in p.relative_to(ROOT).parts[:1] and not agree(reader.read_text(p))]
    assert slow == []


def test_fast_reader_takes_generated_problems(tmp_path: Path) -> None:
    generate_assembly(3, tmp_path)
    files = sorted(tmp_path.rglob("*.yaml"))
    assert len(files) == 8 and all(agree(reader.read_text(f)) for f in files)


#: Documents the fast reader must refuse (the full loader refuses them or reads them in
#: a way the reader does not copy), each with what the full loader says.
REFUSED = [
    "a: 1\nb: 2\na: 3\n",                      # duplicate key, block
    "x: {k: 1, k: 2}\n",                       # duplicate key, flow, nested
    "a: {b: {c: [1, {d: 1, d: 2}]}}\n",        # duplicate key, deep
    "1: a\n1.0: b\n",                          # equal after construction
    "1: a\ntrue: b\n",                         # True == 1
    "0x1: a\n1: b\n",                          # 0x1 == 1
    "01: a\n1: b\n",                           # YAML 1.1 octal 01 == 1
    "~: a\nnull: b\n",                         # both None
    "base: &b {x: 1}\nc:\n  <<: *b\n  x: 2\n",  # merge key (an anchor, an alias)
    "c:\n  <<: {x: 1}\n  x: 2\n",              # merge key without an anchor
    "a: &a [*a]\n",                            # recursive alias
    "a: *nope\n",                              # undefined alias
    "a: " + "[" * 70 + "]" * 70 + "\n",        # deeper than MAX_DEPTH
    "a: " + "[" * 2000 + "]" * 2000 + "\n",    # deeper than libyaml takes
    "? [1, 2]\n: x\n",                         # a sequence as a key
    "? {a: 1}\n: x\n",                         # a mapping as a key
    "{[1]: x}\n",                              # flow, a sequence as a key
    "a: " + "9" * 5000 + "\n",                 # an int too long for int()
    "a: !!int 12\n",                           # explicit tags
    "a: !!str 12\n",
    "a: !!float x\n",
    "a: !foo bar\n",
    "a: ! 12\n",                               # the non-specific tag
    "a: 0x1F\n", "a: 017\n", "a: 0b101\n", "a: 1_000\n", "a: 1:30\n",  # YAML 1.1 ints
    "a: .inf\n", "a: -.inf\n", "a: .nan\n", "a: 1_0.5\n", "a: 1:30.5\n",             # floats not plain decimals
    "a: 2001-12-14\n", "a: 2001-12-14t21:59:43.10-05:00\n",                         # timestamps
    "a: =\n",                                  # the value key
    "a: 1\n---\nb: 2\n",                       # two documents
    "a: [1, 2\n",                              # syntax errors
    "a: b: c\n",
    "\ta: 1\n",
    "a: \x07\n",                               # a control character
    "a: [1, 2]]\n",
]


@pytest.mark.parametrize("text", REFUSED)
def test_fast_reader_refuses_what_it_cannot_vouch_for(text: str) -> None:
    """Fails if the fast reader builds data for any of these: each is the full loader's
    to refuse (with its message) or to read its own way (merge keys, YAML 1.1 forms)."""
    with pytest.raises(reader._NotFast):
        reader._fast_load(text)


#: Documents it must take, each exactly as the full loader reads them.
TAKEN = [
    "", "---\n", "--- \n...\n", "a: 1\n", "[1, 2.5, -3, +4, -0, -0.0, 0.0, 1e-3, 1.0e308, -2E+4, 1e400, 3.]\n",
    "a: {b: [1, {c: x}], d: ~, e: null, f: Null, g: , h: true, i: No, j: on, k: OFF, l: y, m: n}\n",
    "a: '1'\nb: \"1.5\"\nc: 'yes'\nd: \"~\"\ne: '0x1'\n",   # quoted: strings
    "1: a\n'1': b\n",                           # int 1 and str '1': two keys
    "1: a\n2.5: b\nfalse: c\n~: d\n",             # scalar keys of every kind (true would be 1 again)
    "x1e3: [x1e3, 1e3, 1E3, .5, -.5, 0o17]\n",    # -.5 and 0o17 are strings in YAML 1.1
    "a: |\n  text\n  more\nb: >\n  folded\n",     # block scalars
    "a: b # not a tag! not an anchor &\n",         # '!' and '&' in a comment
    "a: 'x&y!z'\n",
    "%YAML 1.1\n---\na: 1\n",
    "a: 1\r\nb: 2\r\n",
    "- - - 1\n    - 2\n  - 3\n- {}\n- []\n",
    "a: " + "[" * 60 + "]" * 60 + "\n",           # deep, within MAX_DEPTH
]


@pytest.mark.parametrize("text", TAKEN)
def test_fast_reader_takes_plain_documents_exactly(text: str) -> None:
    """Fails if the fast reader gives up on a plain document (the speed-up) or reads it
    otherwise than the full loader (types, -0.0, key order)."""
    assert agree(text)


def test_fast_reader_does_not_share_mutable_data() -> None:
    data = reader._fast_load("a: [1, 2]\nb: [1, 2]\nc: {x: 1}\nd: {x: 1}\n")
    assert data["a"] is not data["b"] and data["c"] is not data["d"]


def _parsed(path: Path) -> tuple[str, Any]:
    try:
        return ("ok", reader.parse_yaml(path))
    except Exception as e:  # noqa: BLE001 - compared, not handled
        return ("error", type(e).__name__, str(e))


def test_parse_yaml_says_what_it_said_without_the_fast_reader(tmp_path: Path,
                                                               monkeypatch: pytest.MonkeyPatch) -> None:
    """parse_yaml on every refused and taken document and on tests/bad/: the same data or
    the same one-line message as with the fast reader switched off (the old parse_yaml)."""
    paths = sorted((ROOT / "tests" / "bad").glob("*.yaml"))
    for i, text in enumerate(REFUSED + TAKEN):
        paths.append(tmp_path / f"doc{i}.yaml")
        paths[-1].write_text(text, newline="")
    now = [_parsed(p) for p in paths]

    def off(text: str) -> Any:
        raise reader._NotFast

    monkeypatch.setattr(reader, "_fast_load", off)
    before = [_parsed(p) for p in paths]
    for p, a, b in zip(paths, now, before):
        assert a[0] == b[0] and (same(a[1], b[1]) if a[0] == "ok" else a == b), p
    said = dict(zip(REFUSED, now[len(paths) - len(REFUSED) - len(TAKEN):]))
    for text, what in [("a: 1\nb: 2\na: 3\n", "line 3, column 1: expected the key 'a' once"),
                       ("x: {k: 1, k: 2}\n", "line 1, column 11: expected the key 'k' once"),
                       ("1: a\n1.0: b\n", "expected the key 1 once"), ("1: a\ntrue: b\n", "expected the key true once"),
                       ("0x1: a\n1: b\n", "expected the key 1 once"), ("~: a\nnull: b\n", "the key nothing once"),
                       ("a: &a [*a]\n", "an alias that does not contain itself"),
                       ("? [1, 2]\n: x\n", "a mapping key that is a plain value"),
                       ("a: " + "9" * 5000 + "\n", "an integer of at most 4300 digits"),
                       ("a: 1\n---\nb: 2\n", "valid YAML"), ("a: [1, 2\n", "valid YAML")]:
        assert said[text][0] == "error" and what in said[text][2], (text, said[text])


_LABELS = st.sampled_from(["a", "b", "label", "tm", "x1e3", "yes", "No", "null", "~", "true", "1", "01", "0x1",
                           "1.0", "1e3", "-0", "-0.0", ".5", "1_0", "1:2", ".inf", "<<", "=", "2001-01-01", ""])
_SCALARS = st.one_of(_LABELS, st.integers(-10**6, 10**6).map(str), st.floats(allow_nan=False).map(repr),
                     st.booleans().map(str))


def _render(tree: Any, flow: bool) -> str:
    """YAML text of a tree of (plain) scalar texts, lists and lists of pairs, unquoted."""
    if isinstance(tree, str):
        return tree if tree else "''"
    if isinstance(tree, list) and tree and isinstance(tree[0], tuple):
        return "{" + ", ".join(f"{k}: {_render(v, True)}" for k, v in tree) + "}"
    return "[" + ", ".join(_render(v, True) for v in tree) + "]"


_TREES = st.recursive(_SCALARS, lambda kids: st.one_of(
    st.lists(kids, max_size=4), st.lists(st.tuples(_SCALARS, kids), min_size=1, max_size=4)), max_leaves=12)


@settings(max_examples=300, deadline=None)
@given(st.lists(st.tuples(_SCALARS, _TREES), min_size=1, max_size=5))
def test_fast_reader_agrees_on_random_documents(doc: list[tuple[str, Any]]) -> None:
    """Random block mappings of flow values over tricky scalars (YAML 1.1 ints, floats,
    bools, nulls, merge keys, duplicates): fast and full agree, or fast gives up."""
    text = "".join(f"{k or chr(39) * 2}: {_render(v, True)}\n" for k, v in doc)
    agree(text)


# --------------------------------------------------------------------------- conforms


def _walk_ok(value: Any, spec: schema.Spec) -> bool:
    try:
        schema._check_shape(kbnode.Node("f", "", value), spec)
        return True
    except KBError:
        return False


@pytest.mark.parametrize("path", [p for p in YAMLS if p.parts[-3:-1] != ("tests", "bad")],
                         ids=lambda p: str(p.relative_to(ROOT)))
def test_conforms_agrees_with_the_walk(path: Path) -> None:
    """On every file of a kind: conforms says yes exactly where the walk passes."""
    try:
        data = reader.parse_yaml(path)
    except KBError:
        return
    if not isinstance(data, dict):
        return
    kind = schema.file_kind(kbnode.Node(str(path), "", data))
    if kind is None:
        return
    assert schema.conforms(data, kind.schema) == _walk_ok(data, kind.schema)


@pytest.mark.parametrize("value, spec", [
    ({"length": "in", "angle": "deg", "extra": 1}, schema.UNITS_SCHEMA),           # an unknown key
    ({"length": "in"}, schema.UNITS_SCHEMA),                                       # a missing key
    ({1: "in", "length": "in", "angle": "deg"}, schema.UNITS_SCHEMA),             # a key that is no str
    (["length", "angle"], schema.UNITS_SCHEMA),                                    # not a mapping
    ({"Bad": {"dx": 1, "dy": 1, "dz": 1, "dtheta": 1}}, schema.Named(schema.BOUNDS_SCHEMA)),  # not a label
    ({"a\n": {"dx": 1, "dy": 1, "dz": 1, "dtheta": 1}}, schema.Named(schema.BOUNDS_SCHEMA)),
    ([], schema.Each(schema.LEAF, 1)),                                                 # too short
    ({"box": {"min": 1, "max": 2}, "cylinder": {"radius": 1, "z": 1}}, schema.OBJECT_SCHEMA.optional["shape"].item),
    ({"sphere": {}}, schema.OBJECT_SCHEMA.optional["shape"].item),
    ([], schema.PROBLEM_SCHEMA.optional["objects"].value.required["initial"]),     # OneOrMany: empty list
])
def test_conforms_refuses_what_the_walk_refuses(value: Any, spec: schema.Spec) -> None:
    """Fails if conforms lets through a value the walk refuses (check_shape would then pass it)."""
    assert not _walk_ok(value, spec)
    assert not schema.conforms(value, spec)
    with pytest.raises(KBError):
        schema.check_shape(kbnode.Node("f", "", value), spec)


# --------------------------------------------------------------------------- Node fast paths


_ITEMS = [0, 1, -1, 1.5, -0.0, 1e9, -1e9, 1e9 + 1, 10**9, 10**9 + 1, 10**400, float("inf"), float("-inf"),
          float("nan"), True, False, None, "1", [1], {"a": 1}]


def _slow_vector(value: Any, n: int) -> Any:
    """Node.vector's per-item walk (elements + number), as it was: the array or the error."""
    node = kbnode.Node("f.yaml", "k", value)
    try:
        items = node.elements()
        if len(items) != n:
            raise node.fail(f"a list of {n} numbers", f"{len(items)} items")
        return np.array([e.number() for e in items])
    except KBError as e:
        return str(e)


@pytest.mark.parametrize("value", [list(c) for c in itertools.product(_ITEMS, repeat=2)]
                         + [[1, 2, 3], [], [1], 5, "x", None, (1, 2)])
def test_vector_fast_path_agrees(value: Any) -> None:
    want = _slow_vector(value, 2)
    try:
        got: Any = kbnode.Node("f.yaml", "k", value).vector(2)
    except KBError as e:
        got = str(e)
    if isinstance(want, str):
        assert got == want
    else:
        assert isinstance(got, np.ndarray) and got.dtype == want.dtype and got.tobytes() == want.tobytes()


ROWS = [[1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 2, 3]]


@pytest.mark.parametrize("rows", [
    ROWS, [[1.0, 0, 0], [0, 1, 0], [0, 0, 1], [-0.0, 0, 1.5]], [[0, 0, -1], [0, 1, 0], [1, 0, 0], [0, 0, 1.5]],
    [[1, 0, 0], [0, 1, 0], [0, 0, -1], [0, 0, 0]],          # left-handed
    [[1, 0, 0], [0, 1, 0], [0, 0, 1]],                      # 3 rows
    [[1, 0, 0], [0, 1, 0], [0, 0, 1], [0, 0]],              # a short row
    [[1, 0, 0], [0, 1, 0], [0, 0, True], [0, 0, 0]],        # a bool
    [[1, 0, 0], [0, 1, 0], [0, 0, 1], [0, 0, 1e10]],        # too large
    [[1, 0, 0], [0, 1, 0], [0, 0, 1], [0, 0, float("nan")]],
    "tm",
])
def test_tm_node_fast_path_and_memo_agree(rows: Any) -> None:
    """tm_node with and without a memo, first and second time: the same transform (a copy)
    or the same error as the per-row walk (Node.elements, Node.vector)."""
    node = kbnode.Node("f.yaml", "stable_poses[0].tm", rows)

    def walk() -> Any:
        try:
            rs = node.elements()
            if len(rs) != 4:
                raise node.fail("tm rows [[r1], [r2], [r3], [d]] (4 rows of 3 numbers)", f"{len(rs)} rows")
            m = np.array([r.vector(3) for r in rs])
        except KBError as e:
            return str(e)
        m[3] *= 2.0
        return m

    def call(memo: Memo | None) -> Any:
        try:
            return values.tm_node(node, 2.0, memo)
        except KBError as e:
            return str(e)

    memo = Memo()
    got = [call(None), call(memo), call(memo)]
    want = walk()
    if isinstance(want, str):
        assert got == [want] * 3
        return
    if isinstance(got[0], str):  # the rotation check refused the rows
        assert got == [got[0]] * 3 and "orthonormal right-handed rotation" in got[0]
        return
    assert all(g.tobytes() == got[0].tobytes() for g in got)
    assert got[0].tobytes() == tm_rows(want).tobytes()
    got[2][0, 0] = 99.0  # the caller's copy: the memo keeps its own
    assert call(memo).tobytes() == got[0].tobytes()


def test_tm_node_memo_tells_minus_zero_from_zero() -> None:
    memo = Memo()
    a = values.tm_node(kbnode.Node("f", "tm", [[1, 0, 0], [0, 1, 0], [0, 0, 1], [0.0, 0, 0]]), 1.0, memo)
    b = values.tm_node(kbnode.Node("f", "tm", [[1, 0, 0], [0, 1, 0], [0, 0, 1], [-0.0, 0, 0]]), 1.0, memo)
    assert math.copysign(1, a[0, 3]) == 1 and math.copysign(1, b[0, 3]) == -1


def test_grasp_frame_memo_gives_eulerxyz_bit_for_bit() -> None:
    """The load's memo of grasp frames: eulerxyz's own array each time (a copy; -0.0 kept apart)."""
    from spar_py.core.geometry import eulerxyz

    memo = Memo()
    for euler in [(0.0, 0.0, 0.5, -1.5707963267948966, 1.5707963267948966, 0.0),
                  (-0.0, 0.0, 0.5, -1.5707963267948966, 1.5707963267948966, -0.0), (1.0, 2.0, 3.0, 0.1, 0.2, 0.3)]:
        want = eulerxyz(*euler)
        first, again = objects._grasp_frame(euler, memo), objects._grasp_frame(euler, memo)
        assert first.tobytes() == again.tobytes() == want.tobytes() == objects._grasp_frame(euler, None).tobytes()
        first[0, 0] = 99.0
        assert objects._grasp_frame(euler, memo).tobytes() == want.tobytes()
    assert len(memo.table("eulerxyz", values.LOAD_MEMO_LIMIT)) == 3


@pytest.mark.parametrize("faces, known, min_len", [
    (["b1", "b2"], None, 1), (["b1", "b2"], {"b1", "b2"}, 1), (["b1", "b3"], {"b1", "b2"}, 1), ([], None, 1),
    ([], None, 0), ([1, 2], None, 1), ([1, 2], {1, 2}, 1), ([True], None, 1), ([True], {1}, 1), ([1.0], None, 1),
    ([10**10], None, 1), (["Bad"], None, 1), (["a\n"], None, 1), (["ok", None], None, 1), ("b1", None, 1),
    ([["b1"]], None, 1),
])
def test_faces_fast_path_agrees(faces: Any, known: set | None, min_len: int) -> None:
    node = kbnode.Node("f.yaml", "faces", faces)

    def walk() -> Any:  # _faces's loop, as it was
        out = []
        try:
            for e in node.elements(min_len):
                f = e.value
                if isinstance(f, bool) or not isinstance(f, (int, str)) or (isinstance(f, int) and abs(f) > 1e9):
                    raise e.fail("a face name or number", kbnode.show(f))
                if isinstance(f, str):
                    e.label()
                if known is not None and f not in known:
                    raise e.fail(f"a face of the object ({kbnode.cut(', '.join(map(str, sorted(known, key=str))))})",
                                 kbnode.show(f))
                out.append(f)
        except KBError as e:
            return str(e)
        return tuple(out)

    try:
        got: Any = objects._faces(node, known, min_len)
    except KBError as e:
        got = str(e)
    assert got == walk() and [type(f) for f in got] == [type(f) for f in walk()]


# --------------------------------------------------------------------------- sanity


def _old_overlaps(cell: Any) -> list[str]:
    """sanity._overlaps as it was: every pair's sphere test, then every primitive pair's depth."""
    tol = sanity.from_mm(cell.unit, sanity.OVERLAP_TOL_MM)
    pos = list(cell.positions.values())
    out = []
    for i, j in itertools.combinations(range(len(pos)), 2):
        a, b = pos[i], pos[j]
        ra, rb = cell.objects[a.obj].bounding_radius(), cell.objects[b.obj].bounding_radius()
        if np.linalg.norm(a.T[:3, 3] - b.T[:3, 3]) > ra + rb + tol:
            continue
        depth = max((sanity.overlap_depth(s1, a.T, s2, b.T) for s1 in cell.objects[a.obj].shape
                     for s2 in cell.objects[b.obj].shape), default=0.0)
        if depth > tol:
            out.append(f"{sanity._position_key(cell, a)} {b.obj} {b.name} {depth!r}")
    return out


def test_overlaps_find_what_the_pairwise_loop_found(tmp_path: Path) -> None:
    """A generated cell moved so that parts overlap (pegs slid onto their blocks by
    different amounts): the same pairs, in the same order, with the same depths."""
    cell = kb.load_problem(generate_assembly(6, tmp_path))
    assert list(sanity._overlaps(cell)) == [] == _old_overlaps(cell)
    rng = np.random.default_rng(18)
    for p in cell.positions.values():
        p.T[:2, 3] += rng.uniform(-4.0, 4.0, 2)
    found = [e for e in sanity._overlaps(cell)]
    old = _old_overlaps(cell)
    assert len(found) == len(old) > 0
    for e, line in zip(found, old):
        key, obj, name, depth = line.split(" ")
        assert e.key == key and f"clear of {obj} at {name}" in str(e)
        assert f"overlapping it by {sanity._fmt(float(depth), cell.unit)}" in str(e)


def test_overlap_depth_is_the_old_one_bit_for_bit() -> None:
    """overlap_depth (now _placed + _depth, cross products written out) against np.cross."""
    cell = kb.load_problem(ROOT / "kb" / "problems" / "peg_in_block.yaml")
    solids = [s for m in cell.objects.values() for s in m.shape]
    rng = np.random.default_rng(7)

    def pose() -> np.ndarray:
        q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
        T = np.eye(4)
        T[:3, :3], T[:3, 3] = q * np.sign(np.linalg.det(q)), rng.uniform(-2, 2, 3)
        return T

    def old(s1: Any, T1: np.ndarray, s2: Any, T2: np.ndarray) -> float:
        P1 = sanity.solid_points(s1) @ T1[:3, :3].T + T1[:3, 3]
        P2 = sanity.solid_points(s2) @ T2[:3, :3].T + T2[:3, 3]
        n1, e1 = (m @ T1[:3, :3].T for m in sanity._axes(s1))
        n2, e2 = (m @ T2[:3, :3].T for m in sanity._axes(s2))
        A = np.concatenate([n1, n2, np.cross(e1[:, None, :], e2[None, :, :]).reshape(-1, 3)])
        norm = np.linalg.norm(A, axis=1)
        A = A[norm > 1e-9] / norm[norm > 1e-9, None]
        p1, p2 = P1 @ A.T, P2 @ A.T
        return float(np.minimum(p1.max(axis=0) - p2.min(axis=0), p2.max(axis=0) - p1.min(axis=0)).min())

    for s1, s2 in itertools.product(solids, repeat=2):
        for _ in range(20):
            T1, T2 = pose(), pose()
            assert sanity.overlap_depth(s1, T1, s2, T2).hex() == old(s1, T1, s2, T2).hex()
