"""The bounded, safe YAML reader: a KB file's bytes to plain Python data.

Reading is bounded before anything is parsed: a regular file (never a FIFO or a device)
of at most ``max_bytes`` (MAX_INPUT_BYTES by default), UTF-8, and YAML of at most
MAX_NODES nodes once aliases are expanded, nesting at most MAX_DEPTH, without duplicate
keys. A document with no anchor, tag or duplicate is built straight from libyaml's events
(:func:`_fast_load`); any other goes to the full loader (:class:`BoundedLoader`), whose
data and messages stand. Every problem is a one-line KBError.
"""
from __future__ import annotations

import os
import re
import stat
from pathlib import Path
from typing import Any, Iterator

import yaml

from spar_py.core.errors import KBError
from spar_py.kb.node import show

__all__ = ["MAX_DEPTH", "MAX_INPUT_BYTES", "MAX_NODES", "SAFE_LOADER", "BoundedLoader", "Refused", "parse_yaml",
           "read_text"]


MAX_INPUT_BYTES = 1_000_000  # per file; `spar plan/kb check --max-input-bytes N` raises it
MAX_NODES = 100_000  # YAML nodes of one file with every alias expanded (a billion-laughs bomb)
MAX_DEPTH = 64  # nesting of YAML collections


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
    """A YAML node's children (a sequence's items, a mapping's keys and values)."""
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
