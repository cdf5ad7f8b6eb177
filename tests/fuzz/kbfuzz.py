"""kbfuzz: the project's mutation fuzzer over the knowledge base (issue 13 item 9).

Every kb file (kb/problems, kb/objects, kb/robots) is mutated in a copy of the whole kb
directory in a temporary directory, so the other files it names still resolve. A mutant
is either structured (the parsed YAML tree is walked and one node changed: a key
deleted, duplicated or misspelt, a value of another type, nan, inf, 1e308, 10**400, -1,
0, a name that does not exist, an empty string, a trailing newline, a list emptied or an
element dropped or doubled) or byte-level (non-UTF-8 bytes, UTF-16, a NUL, a stray YAML
character, truncation). Everything is drawn from ``random.Random`` seeded with the seed,
the file and the mutant's index, so a run is the same on every machine.

Each mutant is judged by running ``python -m spar_py plan PROBLEM --timeout T`` (and
``kb check FILE`` first for object and robot mutants, with a problem that uses the file)
in a subprocess under RLIMIT_AS (:data:`MEMORY_LIMIT`), its peak RSS read from
``wait4``'s rusage. OK is exit 0, 1, 2 or 4 with exactly one stderr line for 2 and 4 (at
most one for 0 and 1); anything else is a finding: a traceback, exit 3, an empty or
multi-line message, another exit code, a signal, a run past :data:`TIME_FACTOR` times the
timeout, a peak RSS over :data:`RSS_LIMIT_MB`.

By hand, from the repository root (see tests/fuzz/README.md)::

    .venv/bin/python -m tests.fuzz.kbfuzz --count 20 --timeout 3 --jobs 2
    .venv/bin/python -m tests.fuzz.kbfuzz --paper --count 30 --save tests/fuzz/findings
    .venv/bin/python -m tests.fuzz.kbfuzz --replay tests/fuzz/findings/01-exit-3.yaml
"""
from __future__ import annotations

import argparse
import copy
import hashlib
import json
import multiprocessing
import os
import random
import re
import resource
import shutil
import signal
import subprocess
import sys
import tempfile
import threading
import time
from collections import Counter
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import ProcessPoolExecutor
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any, Union

import yaml

ROOT = Path(__file__).resolve().parents[2]
KB = ROOT / "kb"
KINDS = ("problems", "objects", "robots")
#: The paper's cell (Sec. 6): the files every sample mutates at least.
PAPER_FILES = ("problems/peg_in_block.yaml", "objects/peg.yaml", "objects/block.yaml", "robots/puma762.yaml")
PAPER_PROBLEM = PAPER_FILES[0]

MEMORY_LIMIT = 1536 * 2**20  #: RLIMIT_AS of every run (bytes): 1.5 GiB
RSS_LIMIT_MB = 1024.0  #: a peak RSS above this is a finding
TIME_FACTOR = 2.0  #: a run longer than this times the timeout is a finding
CAP_SLACK = 1.0  #: seconds past TIME_FACTOR * timeout before the run is killed
STDERR_KEEP = 64 * 1024  #: bytes of stderr kept per run

OK_CODES = (0, 1, 2, 4)
#: Mutations the strict schema (issue 13 item 1) must refuse: a key written twice, an unknown
#: key. An exit 0 or 1 for one is reported as "accepted silently" (not a finding of the judge).
MUST_REFUSE = ("duplicate_key", "typo_key")
NEEDS_ONE_LINE = (2, 4)

Key = Union[str, int]
TreePath = tuple[Key, ...]
Tree = Any  # what yaml.safe_load returns
TreeOp = Callable[[Tree, random.Random], Union[tuple[Tree, str], None]]
ByteOp = Callable[[bytes, random.Random], Union[tuple[bytes, str], None]]


# ---------------------------------------------------------------------- the tree


def walk(node: Tree, path: TreePath = ()) -> Iterator[tuple[TreePath, Tree]]:
    """Every node of a parsed YAML tree with its path, depth first, the root first."""
    yield path, node
    if isinstance(node, dict):
        for k, v in node.items():
            yield from walk(v, (*path, k))
    elif isinstance(node, list):
        for i, v in enumerate(node):
            yield from walk(v, (*path, i))


def where(path: TreePath) -> str:
    """A path as the KB's messages write it: ``objects.peg.initial.tm[3][1]``."""
    out = ""
    for k in path:
        out += f"[{k}]" if isinstance(k, int) else (f".{k}" if out else str(k))
    return out or "(top level)"


def parent_of(tree: Tree, path: TreePath) -> Tree:
    """The container holding the node at ``path`` (a non-empty path)."""
    node = tree
    for k in path[:-1]:
        node = node[k]
    return node


def is_number(v: object) -> bool:
    """An int or a float, not a bool (YAML's true is not a number here)."""
    return isinstance(v, (int, float)) and not isinstance(v, bool)


def pick(tree: Tree, rng: random.Random, want: Callable[[TreePath, Tree], bool]) -> TreePath | None:
    """A random non-root path whose node satisfies ``want``, or None if there is none."""
    sites = [p for p, v in walk(tree) if p and want(p, v)]
    return rng.choice(sites) if sites else None


def is_key_site(tree: Tree) -> Callable[[TreePath, Tree], bool]:
    """The test for "this path ends in a mapping key"."""
    return lambda p, _v: isinstance(parent_of(tree, p), dict)


class DupMap:
    """A mapping written with its pairs as given, so a key can appear twice."""

    def __init__(self, pairs: list[tuple[Key, Tree]]) -> None:
        self.pairs = pairs


class _Dumper(yaml.SafeDumper):
    """SafeDumper that writes DupMap and never makes anchors."""

    def ignore_aliases(self, data: Any) -> bool:
        return True


_Dumper.add_representer(DupMap, lambda d, m: d.represent_mapping("tag:yaml.org,2002:map", m.pairs))


def render(tree: Tree) -> bytes:
    """A tree as YAML text (UTF-8), key order kept; nan and inf as .nan and .inf."""
    text = yaml.dump(tree, Dumper=_Dumper, sort_keys=False, default_flow_style=None,
                     allow_unicode=True, width=4096)
    return text.encode("utf-8")


# ---------------------------------------------------------------------- structured mutations


def replace_at(want: Callable[[TreePath, Tree], bool], make: Callable[[Tree, random.Random], Tree]) -> TreeOp:
    """An operation replacing a random node that satisfies ``want`` by ``make(node, rng)``."""
    def op(tree: Tree, rng: random.Random) -> tuple[Tree, str] | None:
        p = pick(tree, rng, want)
        if p is None:
            return None
        parent = parent_of(tree, p)
        parent[p[-1]] = make(parent[p[-1]], rng)
        return tree, where(p)
    return op


def number_to(value: float | int) -> TreeOp:
    """Replace a random number by ``value``."""
    return replace_at(lambda _p, v: is_number(v), lambda _v, _r: value)


def other_type(v: Tree, rng: random.Random) -> Tree:
    """A value of another YAML type than ``v`` (number, string, list, mapping)."""
    if is_number(v):
        options: list[Tree] = ["seven", [v], {"value": v}]
    elif isinstance(v, str):
        options = [42, [v], {v: 1}]
    elif isinstance(v, list):
        options = ["a list", 3, {"items": v}]
    elif isinstance(v, dict):
        options = ["a mapping", 5, list(v.values())]
    else:
        options = ["x", 0, [1]]
    return rng.choice(options)


IDENT = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")


def unknown_name(v: str, rng: random.Random) -> str:
    """``v`` with one of its identifiers (a label, a name, a term's atom) made unknown."""
    names = list(IDENT.finditer(v))
    if not names:
        return "nosuch_" + v
    m = rng.choice(names)
    return v[:m.start()] + "nosuch_" + m.group() + v[m.end():]


def is_string(_p: TreePath, v: Tree) -> bool:
    return isinstance(v, str)


def is_list(_p: TreePath, v: Tree) -> bool:
    return isinstance(v, list) and bool(v)


def delete_key(tree: Tree, rng: random.Random) -> tuple[Tree, str] | None:
    """Delete a random mapping key."""
    p = pick(tree, rng, is_key_site(tree))
    if p is None:
        return None
    del parent_of(tree, p)[p[-1]]
    return tree, where(p)


def near_miss(key: str, rng: random.Random) -> str:
    """A plausible typo of ``key``: a letter dropped, doubled, swapped, or a plural."""
    i = rng.randrange(len(key)) if key else 0
    forms = [key[:i] + key[i + 1:], key[:i] + key[i:i + 1] * 2 + key[i + 1:], key + "s",
             key.replace("_", "-"), key[:i] + key[i + 1:i + 2] + key[i:i + 1] + key[i + 2:]]
    forms = [f for f in forms if f and f != key]
    return rng.choice(forms) if forms else key + "x"


def rebuild(tree: Tree, path: TreePath, mapping: Tree) -> Tree:
    """``tree`` with the mapping holding ``path``'s key replaced by ``mapping``."""
    if len(path) == 1:
        return mapping
    parent_of(tree, path[:-1])[path[-2]] = mapping
    return tree


def typo_key(tree: Tree, rng: random.Random) -> tuple[Tree, str] | None:
    """Rename a random mapping key to a near miss, in place (the order kept)."""
    p = pick(tree, rng, lambda q, v: is_key_site(tree)(q, v) and isinstance(q[-1], str))
    if p is None:
        return None
    old = parent_of(tree, p)
    new_key = near_miss(str(p[-1]), rng)
    if new_key in old:
        return None
    renamed = {(new_key if k == p[-1] else k): v for k, v in old.items()}
    return rebuild(tree, p, renamed), f"{where(p)} -> {new_key!r}"


def duplicate_key(tree: Tree, rng: random.Random) -> tuple[Tree, str] | None:
    """Write a random mapping key twice: the second with the same value or another type."""
    p = pick(tree, rng, is_key_site(tree))
    if p is None:
        return None
    old = parent_of(tree, p)
    second = copy.deepcopy(old[p[-1]]) if rng.random() < 0.5 else other_type(old[p[-1]], rng)
    pairs: list[tuple[Key, Tree]] = []
    for k, v in old.items():
        pairs.append((k, v))
        if k == p[-1]:
            pairs.append((k, second))
    return rebuild(tree, p, DupMap(pairs)), where(p)


def drop_element(tree: Tree, rng: random.Random) -> tuple[Tree, str] | None:
    """Remove a random element of a random list (a vector one short, a pose gone)."""
    p = pick(tree, rng, is_list)
    if p is None:
        return None
    items = parent_of(tree, p)[p[-1]]
    i = rng.randrange(len(items))
    del items[i]
    return tree, f"{where(p)}[{i}]"


def duplicate_element(tree: Tree, rng: random.Random) -> tuple[Tree, str] | None:
    """Double a random element of a random list (a duplicate label, a vector one long)."""
    p = pick(tree, rng, is_list)
    if p is None:
        return None
    items = parent_of(tree, p)[p[-1]]
    i = rng.randrange(len(items))
    items.insert(i + 1, copy.deepcopy(items[i]))
    return tree, f"{where(p)}[{i}]"


TREE_OPS: dict[str, TreeOp] = {
    "delete_key": delete_key,
    "retype": replace_at(lambda _p, _v: True, other_type),
    "nan": number_to(float("nan")),
    "inf": number_to(float("inf")),
    "-inf": number_to(float("-inf")),
    "1e308": number_to(1e308),
    "-1e308": number_to(-1e308),
    "10**400": number_to(10**400),
    "-10**400": number_to(-(10**400)),
    "1e9": number_to(1e9),
    "-1e7": number_to(-1e7),
    "-1": number_to(-1),
    "0": number_to(0),
    "unknown_name": replace_at(is_string, lambda v, r: unknown_name(v, r)),
    "empty_string": replace_at(is_string, lambda _v, _r: ""),
    "trailing_newline": replace_at(is_string, lambda v, _r: v + "\n"),
    "duplicate_key": duplicate_key,
    "typo_key": typo_key,
    "empty_list": replace_at(is_list, lambda _v, _r: []),
    "drop_element": drop_element,
    "duplicate_element": duplicate_element,
}


# ---------------------------------------------------------------------- byte-level mutations

BAD_UTF8 = (b"\xff", b"\xc3\x28", b"\xed\xa0\x80", b"\xfe\xfe", b"\x80")
YAML_JUNK = b":[]{}&*!|>'\"%@`\t-?,#"


def insert_bytes(choices: Sequence[bytes]) -> ByteOp:
    """Insert one of ``choices`` at a random offset."""
    def op(data: bytes, rng: random.Random) -> tuple[bytes, str]:
        i = rng.randrange(len(data) + 1)
        return data[:i] + rng.choice(choices) + data[i:], f"byte {i}"
    return op


def utf16(data: bytes, _rng: random.Random) -> tuple[bytes, str]:
    """The whole file in UTF-16 (with its BOM), as an editor on another system saves it."""
    return data.decode("utf-8").encode("utf-16"), "(file)"


def truncate(data: bytes, rng: random.Random) -> tuple[bytes, str] | None:
    """The file cut at a random byte."""
    if len(data) < 2:
        return None
    i = rng.randrange(1, len(data))
    return data[:i], f"byte {i}"


BYTE_OPS: dict[str, ByteOp] = {
    "non_utf8": insert_bytes(BAD_UTF8),
    "utf16": utf16,
    "nul_byte": insert_bytes((b"\x00",)),
    "yaml_junk": insert_bytes([bytes([c]) for c in YAML_JUNK]),
    "truncate": truncate,
}

OPS: tuple[str, ...] = (*TREE_OPS, *BYTE_OPS)


# ---------------------------------------------------------------------- mutants


@dataclass(frozen=True)
class Mutant:
    """One mutated kb file: which file it replaces, how it was made, its bytes."""

    source: str  # relative to kb/, e.g. problems/peg_in_block.yaml
    index: int
    op: str
    where: str
    data: bytes

    @property
    def ident(self) -> str:
        return f"{self.source}#{self.index}"


def apply_op(op: str, original: bytes, rng: random.Random) -> tuple[bytes, str] | None:
    """Apply the operation named ``op`` to a file's bytes; None if it has no site there."""
    if op in BYTE_OPS:
        return BYTE_OPS[op](original, rng)
    tree = yaml.safe_load(original.decode("utf-8"))
    made = TREE_OPS[op](copy.deepcopy(tree), rng)
    if made is None:
        return None
    return render(made[0]), made[1]


def op_order(seed: int, source: str) -> list[str]:
    """The operations in the order a file's mutants take them (one shuffle per seed and file)."""
    order = list(OPS)
    random.Random(f"{seed}:order:{source}").shuffle(order)
    return order


def mutants(source: str, seed: int, count: int) -> list[Mutant]:
    """``count`` distinct mutants of the kb file ``source``, cycling through every operation."""
    original = (KB / source).read_bytes()
    order = op_order(seed, source)
    seen = {hashlib.sha256(original).digest()}
    out: list[Mutant] = []
    index = 0
    while len(out) < count and index < 8 * count + len(order):
        rng = random.Random(f"{seed}:{source}:{index}")
        for k in range(len(order)):
            op = order[(index + k) % len(order)]
            made = apply_op(op, original, rng)
            if made is not None and hashlib.sha256(made[0]).digest() not in seen:
                seen.add(hashlib.sha256(made[0]).digest())
                out.append(Mutant(source, index, op, made[1], made[0]))
                break
        index += 1
    return out


def kb_files() -> list[str]:
    """Every problem, object and robot file, relative to kb/."""
    return [str(p.relative_to(KB)) for kind in KINDS for p in sorted((KB / kind).glob("*.yaml"))]


def references(problem: str) -> set[str]:
    """The kb files (relative to kb/) a problem file names as its robot and object models."""
    path = KB / problem
    tree = yaml.safe_load(path.read_text(encoding="utf-8"))
    names = [tree.get("robot")] + [o.get("model") for o in (tree.get("objects") or {}).values()]
    out = set()
    for n in names:
        if isinstance(n, str):
            ref = (path.parent / n).resolve()
            if ref.is_relative_to(KB):
                out.add(str(ref.relative_to(KB)))
    return out


def user_of(source: str) -> str:
    """A problem that uses the model file ``source``: the paper's if it does, else the first."""
    problems = [PAPER_PROBLEM] + [f for f in kb_files() if f.startswith("problems/") and f != PAPER_PROBLEM]
    return next((p for p in problems if source in references(p)), PAPER_PROBLEM)


def commands_for(source: str, timeout: float) -> list[tuple[str, ...]]:
    """The spar commands that judge a mutant of ``source`` (relative to the cell's kb/)."""
    plan = ("plan", source if source.startswith("problems/") else user_of(source), "--timeout", f"{timeout:g}")
    return [plan] if source.startswith("problems/") else [("kb", "check", source), plan]


# ---------------------------------------------------------------------- running


@dataclass(frozen=True)
class Run:
    """One spar command on one mutant and what came of it (``finding`` None: OK)."""

    mutant: str
    op: str
    where: str
    command: str
    code: int  # the exit status; -N when killed by signal N
    stderr: str
    seconds: float
    rss_mb: float
    finding: str | None

    @property
    def outcome(self) -> str:
        return f"finding: {self.finding}" if self.finding else f"ok: exit {self.code}"

    @property
    def cause(self) -> str:
        return cause_of(self)


def limit_resources() -> None:
    """In the child, before exec: cap the address space, no core files."""
    resource.setrlimit(resource.RLIMIT_AS, (MEMORY_LIMIT, MEMORY_LIMIT))
    resource.setrlimit(resource.RLIMIT_CORE, (0, 0))


def spar(args: Sequence[str]) -> list[str]:
    """The command line of ``spar ARGS`` with this interpreter (the project's venv)."""
    return [sys.executable, "-m", "spar_py", *args]


def execute(argv: Sequence[str], cwd: Path, cap: float) -> tuple[int, str, float, float]:
    """Run ``argv`` in ``cwd`` under :func:`limit_resources`: (exit status, stderr, seconds,
    peak RSS in MB). Killed (its whole process group) once it has run ``cap`` seconds."""
    with tempfile.TemporaryFile() as err:
        t0 = time.monotonic()
        # PYTHONFAULTHANDLER: a crash (one SIGSEGV at start-up so far) leaves its Python stacks on stderr
        proc = subprocess.Popen(argv, cwd=cwd, stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=err,
                                preexec_fn=limit_resources, start_new_session=True,
                                env=os.environ | {"PYTHONFAULTHANDLER": "1"})
        status, usage = wait_capped(proc.pid, t0 + cap)
        seconds = time.monotonic() - t0
        proc.returncode = os.waitstatus_to_exitcode(status)  # reaped here: Popen must not wait again
        err.seek(0)
        text = err.read(STDERR_KEEP).decode("utf-8", "replace")
    return proc.returncode, text, seconds, usage.ru_maxrss / 1024.0


def wait_capped(pid: int, deadline: float) -> tuple[int, resource.struct_rusage]:
    """Wait for ``pid`` (its status and rusage); SIGKILL its process group at ``deadline``."""
    while True:
        done, status, usage = os.wait4(pid, os.WNOHANG)
        if done:
            return status, usage
        if time.monotonic() >= deadline:
            try:
                os.killpg(pid, signal.SIGKILL)
            except ProcessLookupError:
                pass
            _, status, usage = os.wait4(pid, 0)
            return status, usage
        time.sleep(0.01)


def classify(code: int, stderr: str, seconds: float, rss_mb: float, timeout: float) -> str | None:
    """None if the run is OK, else the kind of finding (the first that applies)."""
    lines = stderr.splitlines()
    if "Traceback" in stderr:
        return "traceback"
    if seconds > TIME_FACTOR * timeout:
        return f"past {TIME_FACTOR:g}x the timeout"
    if code < 0:
        return f"killed by {signal.Signals(-code).name}"
    if rss_mb > RSS_LIMIT_MB:
        return f"RSS over {RSS_LIMIT_MB:g} MB"
    if code == 3:
        return "exit 3"
    if code not in OK_CODES:
        return f"exit {code}"
    if code in NEEDS_ONE_LINE and not lines:
        return "no message"
    if len(lines) > 1:
        return "multi-line stderr"
    if lines and is_empty_message(lines[0]):
        return "empty message"
    return None


def is_empty_message(line: str) -> bool:
    """A message that says nothing: blank, ``spar:`` alone, or ending in a colon (its text lost)."""
    text = line.strip()
    return text in ("", "spar:") or text.endswith(":")


def judge(mutant: Mutant, args: Sequence[str], cwd: Path, timeout: float) -> Run:
    """Run one command on a mutant's cell and classify what came of it."""
    code, stderr, seconds, rss = execute(spar(args), cwd, TIME_FACTOR * timeout + CAP_SLACK)
    return Run(mutant.ident, mutant.op, mutant.where, " ".join(args), code, stderr, round(seconds, 3),
               round(rss, 1), classify(code, stderr, seconds, rss, timeout))


def run_mutant(job: tuple[Mutant, float]) -> list[Run]:
    """Put a mutant in a fresh copy of kb/ and run its commands there (one worker's job)."""
    mutant, timeout = job
    with tempfile.TemporaryDirectory(prefix="kbfuzz-") as d:
        cell = Path(d) / "kb"
        shutil.copytree(KB, cell)
        (cell / mutant.source).write_bytes(mutant.data)
        return [judge(mutant, args, cell, timeout) for args in commands_for(mutant.source, timeout)]


# ---------------------------------------------------------------------- causes and the report

_TMP = re.compile(r"\S*kbfuzz-[^/\s]+/kb/")
_HEX = re.compile(r"\b0x[0-9a-f]+\b")
_NUMBER = re.compile(r"-?\b\d+(\.\d+)?([eE][-+]?\d+)?\b")
_QUOTED = re.compile(r"'[^']*'|\"[^\"]*\"")
_INDEX = re.compile(r"\[\d+\]")
_FILE_KEY = re.compile(r"^spar: \S+\.yaml: \S+: ")
_YAML_FILE = re.compile(r"\S+\.yaml\b")


def gist(text: str) -> str:
    """A message with what varies between mutants (paths, numbers, quoted values) blanked."""
    text = _TMP.sub("", text).replace(str(ROOT) + "/", "")
    text = _YAML_FILE.sub("FILE", _FILE_KEY.sub("spar: FILE: KEY: ", text))
    text = _HEX.sub("0xN", text)
    text = _QUOTED.sub("'…'", text)
    return _NUMBER.sub("N", text)[:110]


def cause_of(run: Run) -> str:
    """What a finding is about, so findings of one cause group together."""
    lines = run.stderr.strip().splitlines()
    if run.finding == "traceback":
        return f"traceback: {gist(lines[-1]) if lines else '?'}"
    if run.finding in ("exit 3", "empty message", "multi-line stderr") and lines:
        msg = lines[0].split("internal error (please report it): ", 1)[-1]
        return f"{run.finding}: {gist(msg)}"
    return f"{run.finding}: {run.op} at {_INDEX.sub('[*]', run.where)} ({run.command.split()[0]})"


@dataclass
class Report:
    """The runs of one fuzzing session and the counts the closing note quotes."""

    seed: int
    timeout: float
    files: list[str]
    mutants: int
    runs: list[Run]
    seconds: float

    def outcomes(self) -> Counter[str]:
        return Counter(r.outcome for r in self.runs)

    def findings(self) -> list[Run]:
        return [r for r in self.runs if r.finding]

    def accepted(self) -> list[Run]:
        """Runs that took a mutant of MUST_REFUSE as a good cell (exit 0 or 1)."""
        return [r for r in self.runs if r.op in MUST_REFUSE and r.code in (0, 1) and not r.finding]

    def causes(self) -> dict[str, list[Run]]:
        out: dict[str, list[Run]] = {}
        for r in self.findings():
            out.setdefault(r.cause, []).append(r)
        return dict(sorted(out.items(), key=lambda kv: -len(kv[1])))

    def summary(self) -> str:
        """The counts by outcome and one example of each cause, for a terminal or a note."""
        head = (f"kbfuzz: seed {self.seed}, {len(self.files)} files, {self.mutants} mutants, "
                f"{len(self.runs)} runs in {self.seconds:.0f} s (--timeout {self.timeout:g})")
        counts = [f"  {k}: {n}" for k, n in sorted(self.outcomes().items())]
        causes = self.causes()
        accepted = self.accepted()
        lines = [head, *counts, f"  accepted silently ({', '.join(MUST_REFUSE)}; exit 0 or 1): {len(accepted)}"
                 + "".join(f"\n      {r.mutant} {r.op} at {r.where}: spar {r.command} -> exit {r.code}"
                           for r in accepted[:12]),
                 f"  findings: {len(self.findings())} in {len(causes)} causes"]
        for c, runs in causes.items():
            r = runs[0]
            lines.append(f"  [{len(runs)}] {c}\n      e.g. {r.mutant} {r.op} at {r.where}: spar {r.command} -> "
                         f"exit {r.code}, {r.seconds:.1f} s, {r.rss_mb:.0f} MB: {first_line(r.stderr)}")
        return "\n".join(lines)


def first_line(text: str) -> str:
    """The first line of ``text`` cut to 160 characters (or its last for a traceback)."""
    lines = text.strip().splitlines()
    if not lines:
        return "(no stderr)"
    line = lines[-1] if "Traceback" in text else lines[0]
    return line[:160] + ("…" if len(line) > 160 else "")


def fuzz(seed: int = 0, count: int = 20, timeout: float = 3.0, files: Sequence[str] | None = None,
         jobs: int = 2) -> Report:
    """Fuzz ``files`` (relative to kb/; all kb files by default) with ``count`` mutants each."""
    chosen = list(files) if files is not None else kb_files()
    todo = [(m, timeout) for f in chosen for m in mutants(f, seed, count)]
    t0 = time.monotonic()
    if jobs <= 1 and threading.active_count() == 1:
        results = [run_mutant(j) for j in todo]
    else:
        # spawned workers: single-threaded, so preexec_fn is safe in them (a pytest-xdist
        # worker has threads of its own, so even one job goes to a spawned process there)
        with ProcessPoolExecutor(max(1, jobs), mp_context=multiprocessing.get_context("spawn")) as pool:
            results = list(pool.map(run_mutant, todo, chunksize=1))
    runs = [r for rs in results for r in rs]
    return Report(seed, timeout, chosen, len(todo), runs, time.monotonic() - t0)


def save_findings(report: Report, directory: Path, seed: int, count: int) -> list[Path]:
    """Write one reproducing mutant per cause into ``directory`` with an index.json to replay them
    (causes already in an index.json there are kept, not written again)."""
    directory.mkdir(parents=True, exist_ok=True)
    index_path = directory / "index.json"
    index = json.loads(index_path.read_text()) if index_path.exists() else []
    known = {e["cause"] for e in index}
    saved = []
    for cause, runs in report.causes().items():
        if cause in known:
            continue
        n = len(index) + 1
        run = runs[0]
        source, i = run.mutant.split("#")
        m = next(m for m in mutants(source, seed, count) if m.index == int(i))
        slug = re.sub(r"[^a-z0-9]+", "-", cause.lower()).strip("-")[:48]
        path = directory / f"{n:02d}-{slug}.yaml"
        path.write_bytes(m.data)
        saved.append(path)
        index.append({"file": path.name, "replaces": source, "seed": seed, "cause": cause, "count": len(runs),
                      "run": asdict(run) | {"stderr": first_line(run.stderr)}})
    index_path.write_text(json.dumps(index, indent=1, ensure_ascii=False) + "\n")
    return saved


def replay(path: Path, timeout: float) -> list[Run]:
    """Run a saved finding again (its entry in the index.json beside it says which file it replaces)."""
    entries = json.loads((path.parent / "index.json").read_text())
    entry = next(e for e in entries if e["file"] == path.name)
    m = Mutant(entry["replaces"], 0, entry["run"]["op"], entry["run"]["where"], path.read_bytes())
    return run_mutant((m, timeout))


# ---------------------------------------------------------------------- command line


def main(argv: Sequence[str] | None = None) -> int:
    """``python -m tests.fuzz.kbfuzz``: fuzz, print the summary; exit 1 if anything was found."""
    p = argparse.ArgumentParser(prog="kbfuzz", description=__doc__.split("\n\n")[0])
    p.add_argument("files", nargs="*", help="kb files relative to kb/ (default: all)")
    p.add_argument("--paper", action="store_true", help="the paper's cell files only")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--count", type=int, default=20, help="mutants per file")
    p.add_argument("--timeout", type=float, default=3.0, help="spar plan --timeout (s)")
    p.add_argument("--jobs", type=int, default=2)
    p.add_argument("--save", type=Path, help="write one mutant per cause here (with index.json)")
    p.add_argument("--json", type=Path, help="write every run here")
    p.add_argument("--replay", type=Path, help="run a saved finding again")
    a = p.parse_args(argv)
    if a.replay:
        runs = replay(a.replay, a.timeout)
        for r in runs:
            print(f"spar {r.command}: {r.outcome} ({r.seconds:.1f} s, {r.rss_mb:.0f} MB): {first_line(r.stderr)}")
        return 1 if any(r.finding for r in runs) else 0
    files = list(PAPER_FILES) if a.paper else (a.files or None)
    report = fuzz(a.seed, a.count, a.timeout, files, a.jobs)
    print(report.summary())
    if a.save:
        save_findings(report, a.save, a.seed, a.count)
    if a.json:
        a.json.write_text(json.dumps([asdict(r) for r in report.runs], indent=1) + "\n")
    return 1 if report.findings() else 0


if __name__ == "__main__":
    sys.exit(main())
