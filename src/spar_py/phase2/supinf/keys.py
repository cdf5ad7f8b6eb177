"""Memo keys of expressions, and bounds kept under them in a cell's memo (:func:`cached_bounds`).

An expression's key is its structure up to the names of its variables
(:func:`expression_key`), so a constraint built again in another registry, with other
variable names, finds the compiled bounder and the results of the first. The tables are
bounded LRUs in a :class:`~spar_py.core.memo.Memo` (world.run.CellCache.memo): nothing is
kept at module level.
"""
from __future__ import annotations

from collections.abc import Mapping

import casadi as ca

from spar_py.core.errors import SparValueError
from spar_py.core.memo import Memo
from spar_py.phase2.supinf.bounder import Bounder, Box, as_scalar, check_box
from spar_py.phase2.supinf.search import ABS_TOL, MAX_BOXES, REL_TOL, BoundResult, branch_and_bound, check_options
from spar_py.phase2.symbolic import ChainExpr

#: Bounds of the memo tables :func:`cached_bounds` keeps in a cell's cache (world.run.CellCache.memo): compiled
#: bounders (CasADi Functions and instruction lists: about 0.2 MB for a pickup constraint,
#: 1-2 MB for a product of 8 transforms, so at most some 100 MB) and bound results (a few
#: hundred bytes each).
BOUNDER_LIMIT = 64
RESULT_LIMIT = 8192


def canonical(expr: ca.SX | float | ChainExpr) -> tuple[ca.SX | ChainExpr, list[str]]:
    """``expr`` with its free symbols renamed ``v0, v1, ...`` in CasADi's order of appearance,
    and their original names in that order (a chain expression stays one, renamed)."""
    e = as_scalar(expr)
    syms = ca.symvar(e)
    canon = [ca.SX.sym(f"v{i}") for i in range(len(syms))]
    names = [v.name() for v in syms]
    if len(set(names)) != len(names):
        raise SparValueError("supinf: two different symbols share a name in the expression")
    if isinstance(expr, ChainExpr):
        return expr.substitute(dict(zip(names, canon))), names
    if syms:
        e = ca.substitute(e, ca.vertcat(*syms), ca.vertcat(*canon))
    return e, names


def _key(canon: ca.SX | ChainExpr) -> bytes:
    if isinstance(canon, ChainExpr):
        return canon.expr.serialize().encode() + b"|chain|" + canon.structure_key()
    return canon.serialize().encode()


def expression_key(expr: ca.SX | float | ChainExpr) -> bytes:
    """A key equal for expressions equal up to the names of their variables (the same
    operations and constants, the variables met in the same order): CasADi's exact
    serialisation of the graph with its symbols renamed by order of appearance (and, for
    a chain expression, its chain's structure)."""
    return _key(canonical(expr)[0])


def cached_bounds(expr: ca.SX | float | ChainExpr, box: Box, memo: Memo | None = None,
                  **options: object) -> BoundResult:
    """``Bounder.bounds(box, **options)`` of ``expr``, with the compiled bounder and the result
    remembered in ``memo``'s tables ``supinf.bounders`` (at most :data:`BOUNDER_LIMIT`
    entries) and ``supinf.results`` (at most :data:`RESULT_LIMIT`), least recently used
    dropped first. Both are keyed by :func:`expression_key`, so a constraint built again
    in another registry, with other variable names, finds them; the result's key adds
    the box (by position) and the options: bounding is deterministic, so an equal
    question gets the equal answer. Without ``memo``, computed afresh.

    A search that stopped on ``beat`` is kept (``supinf.searches``, at most
    :data:`SEARCH_LIMIT`) and resumed by the next question on the same expression, box
    and other options: the full refinement asked later goes on from where the decision
    stopped (the same steps, so the same result as one made from the start), and a
    search that ran to its end answers the full refinement too."""
    if memo is None:
        return Bounder(expr).bounds(box, **options)  # type: ignore[arg-type]
    canon, names, k = _canonical_key(expr, memo)
    lo, hi = check_box(names, box)
    beat = options.pop("beat", None)
    full_key = (k, lo.tobytes(), hi.tobytes(), tuple(sorted(options.items())))
    rkey = full_key if beat is None else full_key + (("beat", beat),)
    results = memo.table("supinf.results", RESULT_LIMIT)
    r = results.get(rkey)
    if r is None and beat is not None:
        r = results.get(full_key)  # the full refinement answers every beat
    if r is None:
        o = _search_options(options)
        check_options(o["want"], o["rel_tol"], o["abs_tol"], beat)  # type: ignore[arg-type]
        B = memo.table("supinf.bounders", BOUNDER_LIMIT).get_or_compute(k, lambda: Bounder(canon))
        # (made by the first search with a beat: bounding without one never needs it)
        searches = memo.table("supinf.searches", SEARCH_LIMIT) if beat is not None else memo.existing("supinf.searches")
        S0 = searches.pop(full_key, None) if searches is not None else None
        if S0 is not None:
            S0.B = B  # (kept without it: the table of bounders alone bounds what they hold)
        r, S = branch_and_bound(B, lo, hi, beat=beat, search=S0, **o)  # type: ignore[arg-type]
        if r.decided and searches is not None and S is not None:
            S.B = None  # type: ignore[assignment]  # the same bounder again on resuming: it is deterministic
            searches[full_key] = S
        else:  # the search ran to its end: the full answer
            results[full_key] = r
        results[rkey] = r
    return r


def _canonical_key(expr: ca.SX | float | ChainExpr, memo: Memo) -> tuple[ca.SX | ChainExpr, list[str], bytes]:
    """:func:`canonical` of ``expr`` and its :func:`_key`, kept in ``memo``'s table
    ``supinf.canonical`` (at most :data:`CANONICAL_LIMIT`) by the expression object itself:
    one object asked again (a constraint decided, then refined; the core two pickup
    constraints share) is renamed and serialised once. The entry holds the object, so its
    id cannot be another's while it is there."""
    table = memo.table("supinf.canonical", CANONICAL_LIMIT)
    hit = table.get(id(expr))
    if hit is not None and hit[0] is expr:
        return hit[1], hit[2], hit[3]
    canon, names = canonical(expr)
    k = _key(canon)
    table[id(expr)] = (expr, canon, names, k)
    return canon, names, k


#: Bound of the table of canonical forms by expression object (:func:`_canonical_key`): each
#: holds a renamed copy of its expression (kB for a pickup constraint, about 1 MB for a
#: product of 8 transforms).
CANONICAL_LIMIT = 128

#: Bound of the table of searches stopped on ``beat`` (:func:`cached_bounds`): each holds
#: its pool of boxes (a few kB), not its bounder.
SEARCH_LIMIT = 512


def _search_options(options: Mapping[str, object]) -> dict[str, object]:
    """Bounder.bounds' options (without beat) with their defaults; SparValueError for an
    option it does not take (their values: :func:`check_options`)."""
    o = {"rel_tol": REL_TOL, "abs_tol": ABS_TOL, "max_boxes": MAX_BOXES, "max_time": None, "want": "both", **options}
    unknown = sorted(set(o) - {"rel_tol", "abs_tol", "max_boxes", "max_time", "want"})
    if unknown:
        raise SparValueError(f"supinf: unknown bounding options {unknown}")
    return o
