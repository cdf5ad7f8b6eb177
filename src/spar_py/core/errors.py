"""One exception family for spar-py; Prolog ``error(...)`` terms are translated in engine.py."""
from __future__ import annotations


class SparError(Exception):
    """Base class of every error spar-py raises on purpose."""


class SparValueError(SparError, ValueError):
    """A value (a knowledge-base entry, an argument) is not what was expected."""


class KBError(SparValueError):
    """A knowledge-base file is malformed. ``str()`` is one line:
    ``FILE: KEY: expected EXPECTED, not GOT`` (``FILE: expected ...`` when no key is at fault,
    e.g. the file is not UTF-8); ``got`` is already shown for reading (cut, rounded) or None."""

    def __init__(self, file: str, key: str, expected: str, got: str | None = None) -> None:
        expected = expected.removeprefix("expected ")
        self.file, self.key, self.expected, self.got = file, key, expected, got
        where = f"{file}: {key}: " if key else f"{file}: "
        text = f"{where}expected {expected}" + (f", not {got}" if got is not None else "")
        super().__init__(" ".join(text.splitlines()))  # one line, whatever a name holds


class UnknownKeyError(KBError):
    """A key no schema knows: ``FILE: KEY: unknown key; did you mean NEAR?``."""

    def __init__(self, file: str, key: str, near: str | None) -> None:
        self.file, self.key, self.near = file, key, near
        self.expected, self.got = "a known key", key.rsplit(".", 1)[-1]
        hint = f"; did you mean {near}?" if near else ""
        SparValueError.__init__(self, f"{file}: {key}: unknown key{hint}")


class WrongKindError(KBError):
    """A KB file of another kind than wanted (an object model given as a problem):
    ``FILE: expected a problem file, not an object model (it has `object:`)``."""


class PrologError(SparError):
    """A Prolog exception raised inside a query: ``message`` the first line of Prolog's own
    rendering, ``term`` the exception term as written by write_canonical, ``formal`` the
    formal part of an ISO error term as data (foreign.pl's term_data/2), or None."""

    def __init__(self, term: str, message: str, formal: object = None) -> None:
        self.term, self.message, self.formal = term, message, formal
        super().__init__(message)


class InternalError(SparError):
    """A bug: an exception spar-py did not raise on purpose (its class and message, one line)."""


class PlanningTimeout(SparError):
    """A planning query ran past its time limit."""


class ExpectedFailures(SparError):
    """A plan with actions planned for failure (error count > 0) where a certain plan was asked
    for (``Planner(strict=True)``, ``spar plan --strict``); ``plan`` is the plan, ``line`` what
    the text plan's first line says of it."""

    def __init__(self, plan: object, line: str) -> None:
        self.plan, self.line = plan, line
        super().__init__(line)
