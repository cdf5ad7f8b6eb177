"""Python's goals into Prolog module kb call only its exports (prolog/kb.pl's export list).

The Prolog side (every ``kb:G`` in prolog/, kb/templates/ and tests/prolog) is checked by
tests/prolog/modules.plt; this checks the goal strings of the Python sources
(``query_once("kb:unload_facts(P)", ...)``), read as text.
"""
from __future__ import annotations

import re
from pathlib import Path

from spar_py.planning.engine import engine

from paths import ROOT

CALL = re.compile(r"(?<![\w.])kb:([a-z]\w*)\(")


def arity(text: str, start: int) -> int:
    """The number of arguments of the call whose ``(`` is at ``text[start]``: commas at depth
    one outside quotes, up to the matching ``)``."""
    depth, args, quote = 0, 1, ""
    for i in range(start, len(text)):
        c = text[i]
        if quote:
            quote = "" if c == quote else quote
        elif c in "'\"":
            quote = c
        elif c in "([{":
            depth += 1
        elif c in ")]}":
            depth -= 1
            if depth == 0:
                return 0 if text[start + 1:i].strip() == "" else args
        elif c == "," and depth == 1:
            args += 1
    raise ValueError(f"no closing parenthesis: {text[start:start + 40]!r}")


def kb_calls(text: str) -> set[tuple[str, int]]:
    """(name, arity) of every ``kb:name(...)`` in ``text``."""
    return {(m.group(1), arity(text, m.end() - 1)) for m in CALL.finditer(text)}


def kb_exports() -> set[tuple[str, int]]:
    """Module kb's exports as the loaded planner has them."""
    got = engine().query_once("module_property(kb, exports(_L)), findall([_N, _A], member(_N/_A, _L), Ps)")
    return {(n, a) for n, a in got["Ps"]}


def test_kb_calls_are_read_with_their_arity() -> None:
    text = 'q("kb:unload_facts(P)"); q("findall(G, kb:grasp(O, G, _, f(a, b), [x, y], \'a,b\'), Gs)"); okb: x'
    assert kb_calls(text) == {("unload_facts", 1), ("grasp", 6)}


def test_an_unexported_kb_predicate_is_caught() -> None:
    """What the next test would report: kb's internal stored/3 is not exported."""
    assert kb_calls('query_once("kb:stored(F, P, S)")') - kb_exports() == {("stored", 3)}


def test_python_calls_into_kb_are_to_its_exports() -> None:
    calls: dict[tuple[str, int], list[str]] = {}
    for d in ("src", "tests", "bench"):
        for f in sorted((ROOT / d).rglob("*.py")):
            if f == Path(__file__).resolve():
                continue  # its examples above call kb:stored/3 on purpose
            for call in kb_calls(f.read_text(encoding="utf-8")):
                calls.setdefault(call, []).append(str(f.relative_to(ROOT)))
    assert ("unload_facts", 1) in calls  # engine.py's: the scan sees it
    unexported = {c: fs for c, fs in calls.items() if c not in kb_exports()}
    assert unexported == {}
