"""Ground Prolog terms as data: the goals and initial facts of a problem file.

A term is an atom (``str``), a number, a list of terms, or a compound as a tuple
``(functor, arg1, ...)`` (:data:`~spar_py.core.model.Term`), the form the bridge sends to
Prolog. :func:`parse_term` reads a term a KB file writes; :func:`term_text` is the one
place a term becomes text again, for display.
"""
from __future__ import annotations

import re
from typing import Iterator

from spar_py.core.model import Term

__all__ = ["atoms", "parse_term", "term_text"]


_TOKEN = re.compile(
    r"\s*(?:(?P<num>-?\d+(?:\.\d+)?(?:[eE][-+]?\d+)?)|(?P<atom>[a-z][A-Za-z0-9_]*)"
    r"|(?P<var>[A-Z_][A-Za-z0-9_]*)|(?P<punct>[()\[\],]))"
)


def parse_term(text: str) -> Term:
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

    def term() -> Term:
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
            items: list[Term] = []
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


def term_text(t: Term) -> str:
    """A term as Prolog text, for display: ``assembled(peg, block, [[1], [2]], trans_1, vec_1)``
    (its atoms are labels, :func:`parse_term`'s, which need no quotes)."""
    if isinstance(t, tuple):
        return f"{t[0]}({', '.join(term_text(a) for a in t[1:])})"
    if isinstance(t, list):
        return "[" + ", ".join(term_text(a) for a in t) + "]"
    return str(t)


def atoms(t: Term) -> Iterator[str]:
    """Every atom among the arguments of ``t``, at any depth (list items included, functors not)."""
    if isinstance(t, tuple):
        for a in t[1:]:
            yield from atoms(a)
    elif isinstance(t, list):
        for a in t:
            yield from atoms(a)
    elif isinstance(t, str):
        yield t
