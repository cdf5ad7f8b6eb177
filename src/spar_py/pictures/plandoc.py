"""Reading the plan JSON (the dict the planner emits) for the pictures: its parts and its term texts.

Every picture function takes the plan document itself or anything with a ``to_json()``
that returns one (``planner.Plan``); :func:`as_doc` makes the two one.
"""
from __future__ import annotations

import re
from collections.abc import Mapping
from typing import Any

from spar_py.kb import parse_term, term_text

__all__ = ["PlanDoc", "as_doc", "instance", "is_plan", "partial", "pretty_term", "term_parts"]

PlanDoc = Mapping[str, Any]  # the plan JSON document


def as_doc(plan: Any) -> PlanDoc:
    """The plan JSON dict of ``plan``: the dict itself, or ``plan.to_json()`` (planner.Plan)."""
    return plan.to_json() if hasattr(plan, "to_json") else plan


def partial(plan: PlanDoc) -> Mapping[str, Any]:
    """The partial plan (actions, ordering, variables, arcs, separations); {} if none."""
    return plan.get("partial") or {}


def instance(plan: PlanDoc) -> Mapping[str, Any]:
    """The chosen plan instance (bindings, steps, ...); {} if none."""
    return plan.get("instance") or {}


def is_plan(plan: PlanDoc) -> bool:
    """True when the planner found a plan (outcome ``"plan"``)."""
    return plan.get("outcome") == "plan"


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
