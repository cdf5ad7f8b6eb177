"""One exception family for spar-py; Prolog ``error(...)`` terms are translated in engine.py."""
from __future__ import annotations


class SparError(Exception):
    """Base class of every error spar-py raises on purpose."""


class SparValueError(SparError, ValueError):
    """A value (a knowledge-base entry, an argument) is not what was expected."""


class KBError(SparValueError):
    """A knowledge-base file is malformed; ``str()`` is one line naming file, key path and expectation."""

    def __init__(self, file: str, key: str, expected: str) -> None:
        self.file, self.key, self.expected = file, key, expected
        super().__init__(f"{file}: {key}: {expected}")


class PrologError(SparError):
    """A Prolog exception raised inside a query; ``message`` is Prolog's own rendering of it."""

    def __init__(self, term: str, message: str) -> None:
        self.term, self.message = term, message
        super().__init__(message)


class PlanningTimeout(SparError):
    """A planning query ran past its time limit."""
