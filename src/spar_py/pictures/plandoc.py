"""Reading a plan (planning.planner.Plan) for the pictures: its parts and its term texts.

Every picture function takes the typed ``Plan``; a plan JSON document read from a file is
one by ``Plan.from_json``.
"""
from __future__ import annotations

import re
from collections.abc import Mapping
from typing import TYPE_CHECKING, Any

from spar_py.kb import parse_term, term_text

if TYPE_CHECKING:
    from spar_py.planning.planner import Plan

__all__ = ["instance", "is_plan", "partial", "pretty_term", "term_parts"]


def partial(plan: Plan) -> Mapping[str, Any]:
    """The partial plan (actions, ordering, variables, arcs, separations) as the JSON has it; {} if none."""
    return plan.partial or {}


def instance(plan: Plan) -> Mapping[str, Any]:
    """The chosen plan instance (bindings, steps, ...) as the JSON has it; {} if none."""
    return plan.instance or {}


def is_plan(plan: Plan) -> bool:
    """True when the planner found a plan (outcome ``"plan"``)."""
    return plan.ok


def pretty_term(term: str) -> str:
    """Prolog term text with one space after each comma, as the paper prints its actions."""
    return re.sub(r",\s*", ", ", term.strip())


def term_parts(term: str) -> tuple[str, list[str]]:
    """Functor and argument texts of a ground term (``("pickup", ["peg", "p1G10"])``)."""
    try:
        t = parse_term(term)
    except ValueError:
        m = re.match(r"\s*([a-z]\w*)", term)
        return (m.group(1) if m else term.strip()), []
    if isinstance(t, tuple):
        return str(t[0]), [term_text(a) for a in t[1:]]
    return term_text(t), []
