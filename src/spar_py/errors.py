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
