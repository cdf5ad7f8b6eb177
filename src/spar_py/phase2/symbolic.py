"""Uncertainty variables (CasADi SX): their registry, and the symbolic helpers around geometry's transforms.

The paper represents every uncertain quantity as an expression in *uncertainty
variables*, each a bounded real (Sec. 3.2.1), whose bounds are recorded once, as
``supinf_variable(V)`` and ``supinf_less(Lo, V)``, ``supinf_less(V, Hi)`` facts, when the
variable is made (Fig. 11, Sec. 5.3). Bounds never change: reducing uncertainty means
re-expressing a quantity in *new* variables with tighter bounds. :class:`Registry` is
that global store, one per planning run.

The transforms themselves (:func:`trans`, :func:`rotz`, :func:`compose`, :func:`inv`,
:func:`apply`, ...) are geometry.py's, re-exported here: one code path that returns
numpy arrays when every argument is a plain number or array, and CasADi ``SX``
matrices as soon as one argument is symbolic. Conventions are DESIGN.md's: 4x4
homogeneous matrices, column vectors, ``T_world_obj``; lengths in the caller's unit
(the paper's cell: inches), angles in radians.
"""
from __future__ import annotations

import functools
import math
import re
from collections.abc import Iterator, Mapping
from dataclasses import dataclass

import casadi as ca
import numpy as np
from numpy.typing import ArrayLike

from spar_py.core.errors import SparValueError
from spar_py.core.geometry import (
    apply,
    as_sx,
    compose,
    euler_zyz,
    eulerxyz,
    inv,
    is_symbolic,
    rot,
    rotx,
    roty,
    rotz,
    rpy,
    tm_rows,
    trans,
    transl,
)

__all__ = [
    "Chain",
    "ChainExpr",
    "ErrorFactor",
    "Matrix",
    "Registry",
    "Scalar",
    "apply",
    "as_sx",
    "compose",
    "cse",
    "euler_zyz",
    "eulerxyz",
    "free_names",
    "inv",
    "is_symbolic",
    "n_nodes",
    "rot",
    "rotx",
    "roty",
    "rotz",
    "rpy",
    "snap",
    "tm_rows",
    "to_function",
    "trans",
    "transl",
]

Scalar = float | ca.SX  # a number or an SX expression in uncertainty variables
Matrix = np.ndarray | ca.SX  # a numeric 4x4 (numpy) or a symbolic one (SX)

_NAME = re.compile(r"[A-Za-z_][A-Za-z0-9_]*\Z")
SNAP_TOL = 1e-12


# ------------------------------------------------------------------ simplification


def snap(T: ArrayLike, tol: float = SNAP_TOL) -> np.ndarray:
    """A numeric matrix with entries within ``tol`` of 0, +1 or -1 set exactly to them.

    Rotation matrices built from degrees carry noise such as cos(90 deg) = 6e-17; left
    in, every such entry multiplies an uncertainty variable into a useless term. Snapping
    the *data* (the ideal poses, grasps) before it enters a symbolic product lets CasADi
    drop those terms structurally (0 * x is folded at construction). It moves the modelled
    pose by less than ``tol`` per entry; it is never applied to symbolic expressions.
    """
    A = np.array(T, dtype=float)
    for v in (0.0, 1.0, -1.0):
        A[np.abs(A - v) <= tol] = v
    return A


def cse(expr: ca.SX) -> ca.SX:
    """Common-subexpression elimination (CasADi's ``cse``): equal subtrees become one node."""
    return ca.cse(expr)


def n_nodes(expr: ca.SX) -> int:
    """Number of nodes of an SX expression graph (a size measure for reports)."""
    return int(ca.n_nodes(expr))


def free_names(expr: ca.SX) -> list[str]:
    """Names of the free symbols of ``expr``, in CasADi's order (first appearance)."""
    return [v.name() for v in ca.symvar(as_sx(expr))]


def to_function(expr: ca.SX, names: list[str], registry: Registry, label: str = "f") -> ca.Function:
    """A CasADi Function of one input vector (the variables ``names``, in that order) giving ``expr``.

    Called with a (len(names), N) array it evaluates N points at once (CasADi's
    automatic mapping); raises SparValueError if ``expr`` uses a symbol not in ``names``.
    """
    syms = [registry.symbol(n) for n in names]
    missing = set(free_names(expr)) - set(names)
    if missing:
        raise SparValueError(f"to_function: expression uses symbols not listed: {sorted(missing)}")
    return ca.Function(label, [ca.vertcat(*syms) if syms else ca.SX(0, 1)], [as_sx(expr)])


# ------------------------------------------------------------------ the registry


class Registry:
    """The bounded uncertainty variables of one planning run (Fig. 11's supinf facts).

    ``new(hint, lo, hi)`` makes a fresh SX symbol whose bounds are fixed for good; the
    first variable with a hint takes the hint as its name (``dx_peg``, ``thetagr``), later
    ones get ``_1``, ``_2``, ... (``dx_peg_1``). Bounds are in the unit the caller uses
    (lengths in the cell unit, angles in radians).
    """

    def __init__(self) -> None:
        self._syms: dict[str, ca.SX] = {}
        self._bounds: dict[str, tuple[float, float]] = {}
        self._count: dict[str, int] = {}
        self._nodes: dict[int, str] = {}  # element_hash (the SX node) -> name

    def new(self, name_hint: str, lo: float, hi: float) -> ca.SX:
        """A fresh variable bounded by ``lo <= v <= hi`` (finite, lo <= hi); SparValueError otherwise."""
        if not isinstance(name_hint, str) or not _NAME.match(name_hint):
            raise SparValueError(f"uncertainty variable name {name_hint!r}: must be an identifier "
                                 "([A-Za-z_][A-Za-z0-9_]*)")
        try:
            lo_f, hi_f = float(lo), float(hi)
        except (TypeError, ValueError):
            raise SparValueError(f"uncertainty variable {name_hint}: bounds must be numbers, "
                                 f"got {lo!r}, {hi!r}") from None
        if not (math.isfinite(lo_f) and math.isfinite(hi_f)):
            raise SparValueError(f"uncertainty variable {name_hint}: bounds must be finite, "
                                 f"got [{lo_f}, {hi_f}]")
        if lo_f > hi_f:
            raise SparValueError(f"uncertainty variable {name_hint}: lower bound {lo_f} > upper bound {hi_f}")
        name = name_hint
        k = self._count.get(name_hint, 0)
        while name in self._syms:
            k += 1
            name = f"{name_hint}_{k}"
        self._count[name_hint] = k
        sym = ca.SX.sym(name)
        self._syms[name] = sym
        self._bounds[name] = (lo_f, hi_f)
        self._nodes[sym.element_hash()] = name
        return sym

    def symbol(self, name: str) -> ca.SX:
        """The symbol called ``name`` (SparValueError if none)."""
        try:
            return self._syms[name]
        except KeyError:
            raise SparValueError(f"no uncertainty variable named {name!r}") from None

    def bounds(self, name: str) -> tuple[float, float]:
        """The fixed bounds (lo, hi) of the variable ``name`` (SparValueError if none)."""
        try:
            return self._bounds[name]
        except KeyError:
            raise SparValueError(f"no uncertainty variable named {name!r}") from None

    def box(self, expr: ca.SX | Matrix | ChainExpr) -> dict[str, tuple[float, float]]:
        """``{name: (lo, hi)}`` for the free symbols of ``expr`` (SparValueError for unknown ones)."""
        if isinstance(expr, ChainExpr):
            expr = expr.expr
        if not is_symbolic(expr):
            return {}
        out: dict[str, tuple[float, float]] = {}
        for v in ca.symvar(as_sx(expr)):
            name = self._nodes.get(v.element_hash())  # the very node this registry made
            if name is None:
                raise SparValueError(f"expression uses {v.name()!r}, which is not a variable of this registry")
            out[name] = self._bounds[name]
        return out

    def facts(self) -> list[tuple]:
        """The registry as the paper's facts: ``('supinf_variable', V)``, ``('supinf_less', A, B)``."""
        out: list[tuple] = []
        for name, (lo, hi) in self._bounds.items():
            out += [("supinf_variable", name), ("supinf_less", lo, name), ("supinf_less", name, hi)]
        return out

    def __contains__(self, name: object) -> bool:
        return name in self._syms

    def __len__(self) -> int:
        return len(self._syms)

    def __iter__(self) -> Iterator[str]:
        return iter(self._syms)

    def items(self) -> Mapping[str, tuple[float, float]]:
        """A read-only view ``{name: (lo, hi)}`` of every variable made so far."""
        return dict(self._bounds)

    def __repr__(self) -> str:
        return f"Registry({len(self)} variables)"


# ------------------------------------------------------------------ transform chains


Entry = float | ca.SX  # a number or one uncertainty variable (an SX symbol)


def _entry(v: object, what: str) -> Entry:
    """``v`` as a chain entry: a finite float, or an SX scalar symbol (SparValueError otherwise)."""
    if isinstance(v, ca.SX):
        if v.numel() == 1 and v.is_constant():
            v = float(v)
        elif v.numel() == 1 and v.is_symbolic():
            return v
        else:
            raise SparValueError(f"chain: {what} must be a number or one variable, got {v}")
    try:
        f = float(v)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        raise SparValueError(f"chain: {what} must be a number or one variable, got {v!r}") from None
    if not math.isfinite(f):
        raise SparValueError(f"chain: {what} must be finite, got {f}")
    return f


@dataclass(frozen=True)
class ErrorFactor:
    """The error transform ``trans(dx, dy, dz) @ rotz(theta)`` (``inverse``: its inverse) of a
    :class:`Chain`: each entry a number or one uncertainty variable (lengths in the cell unit,
    ``theta`` in radians)."""

    dx: Entry
    dy: Entry
    dz: Entry
    theta: Entry
    inverse: bool = False

    def matrix(self) -> Matrix:
        """The 4x4 transform (SX if an entry is a variable)."""
        E = compose(trans(self.dx, self.dy, self.dz), rotz(self.theta))
        return inv(E) if self.inverse else E

    def inverted(self) -> ErrorFactor:
        return ErrorFactor(self.dx, self.dy, self.dz, self.theta, not self.inverse)

    def symbols(self) -> list[ca.SX]:
        return [e for e in (self.dx, self.dy, self.dz, self.theta) if isinstance(e, ca.SX)]


Factor = np.ndarray | ErrorFactor


def _affine(M: ArrayLike) -> np.ndarray:
    A = np.array(M, dtype=float)
    if A.shape != (4, 4) or not np.isfinite(A).all() or not np.array_equal(A[3], [0.0, 0.0, 0.0, 1.0]):
        raise SparValueError("chain: a constant factor must be a finite 4x4 affine transform (last row 0 0 0 1)")
    return A


@dataclass(frozen=True, eq=False)
class Chain:
    """A product of transforms kept as its factors, left to right: constant 4x4 arrays and
    :class:`ErrorFactor` s. Its :meth:`matrix` is ``compose`` of the factors; the factor list
    is what :mod:`spar_py.phase2.hulls` propagates point sets through (supinf's bound on deep
    products).

    Adjacent constants are multiplied on construction exactly as :func:`compose` does (left
    to right, in numpy), and an error factor whose entries are all numbers is a constant, so
    the SX of :meth:`matrix` is, operation for operation, the product of the stored factors.
    """

    factors: tuple[Factor, ...]

    @classmethod
    def of(cls, *items: Chain | ErrorFactor | ArrayLike) -> Chain:
        """The chain of ``items`` in order (chains are flattened)."""
        out: list[Factor] = []
        for it in items:
            for f in (it.factors if isinstance(it, Chain) else (it,)):
                if isinstance(f, ErrorFactor):
                    if not isinstance(it, Chain):  # (a chain's own factors were checked when it was made)
                        f = ErrorFactor(*(_entry(getattr(f, k), k) for k in ("dx", "dy", "dz", "theta")), f.inverse)
                    if f.symbols():
                        out.append(f)
                        continue
                    f = np.asarray(f.matrix(), float)
                A = _affine(f)
                if out and isinstance(out[-1], np.ndarray):
                    out[-1] = out[-1] @ A
                else:
                    out.append(A)
        return cls(tuple(out))

    def __matmul__(self, other: Chain | ErrorFactor | ArrayLike) -> Chain:
        return Chain.of(self, other)

    def inverse(self) -> Chain:
        """The chain of the inverse: factors reversed, each inverted (constants by :func:`inv`,
        the closed-form rigid inverse, as numbers)."""
        return Chain.of(*(f.inverted() if isinstance(f, ErrorFactor) else np.asarray(inv(f), float)
                          for f in reversed(self.factors)))

    def matrix(self) -> Matrix:
        """The product as a 4x4 (SX when a factor has a variable)."""
        return compose(*(f.matrix() if isinstance(f, ErrorFactor) else f for f in self.factors))

    def symbols(self) -> list[ca.SX]:
        """The variables of the factors (first appearance, each once)."""
        seen: dict[int, ca.SX] = {}
        for f in self.factors:
            if isinstance(f, ErrorFactor):
                for s in f.symbols():
                    seen.setdefault(s.element_hash(), s)
        return list(seen.values())

    def substitute(self, to: Mapping[str, ca.SX]) -> Chain:
        """The chain with variables renamed (``to``: old name -> new symbol)."""
        def sub(e: Entry) -> Entry:
            return to.get(e.name(), e) if isinstance(e, ca.SX) else e

        return Chain(tuple(ErrorFactor(sub(f.dx), sub(f.dy), sub(f.dz), sub(f.theta), f.inverse)
                           if isinstance(f, ErrorFactor) else f for f in self.factors))


@dataclass(frozen=True, eq=False)
class ChainExpr:
    """A scalar function of the point ``chain @ point`` (x, in the chain's output frame):
    ``kind`` 'linear': ``c . x + offset`` (``vector`` = c); 'sqdist': ``|x - q|^2`` (``vector``
    = q). :attr:`expr` is its SX; supinf bounds it with the chain's structure too."""

    chain: Chain
    point: tuple[float, float, float]
    kind: str
    vector: tuple[float, float, float]
    offset: float = 0.0

    def __post_init__(self) -> None:
        if self.kind not in ("linear", "sqdist"):
            raise SparValueError(f"chain expression: kind must be 'linear' or 'sqdist', got {self.kind!r}")
        for what in ("point", "vector"):
            v = np.asarray(getattr(self, what), float)
            if v.shape != (3,) or not np.isfinite(v).all():
                raise SparValueError(f"chain expression: {what} must be 3 finite numbers")
            object.__setattr__(self, what, tuple(float(x) for x in v))
        if not math.isfinite(self.offset):
            raise SparValueError("chain expression: offset must be finite")

    @classmethod
    def coordinate(cls, chain: Chain, point: ArrayLike, axis: int) -> ChainExpr:
        """Coordinate ``axis`` (0, 1, 2) of ``chain @ point``."""
        if axis not in (0, 1, 2):
            raise SparValueError(f"chain expression: axis must be 0, 1 or 2, got {axis!r}")
        return cls(chain, tuple(np.asarray(point, float)), "linear", tuple(np.eye(3)[axis]))

    @classmethod
    def sqdist(cls, chain: Chain, point: ArrayLike, target: ArrayLike) -> ChainExpr:
        """``|chain @ point - target|^2``."""
        return cls(chain, tuple(np.asarray(point, float)), "sqdist", tuple(np.asarray(target, float)))

    @functools.cached_property
    def expr(self) -> ca.SX:
        """The SX of the function."""
        x = apply(self.chain.matrix(), self.point)
        x = as_sx(x) if is_symbolic(x) else ca.SX(np.asarray(x, float).reshape(3, 1))
        if self.kind == "linear":
            c = self.vector
            out = ca.SX(self.offset)
            for k in range(3):
                if c[k]:
                    out = out + c[k] * x[k]
            return out
        return ca.sumsqr(x - ca.DM(self.vector))

    def substitute(self, to: Mapping[str, ca.SX]) -> ChainExpr:
        """The same function of renamed variables (``to``: old name -> new symbol)."""
        return ChainExpr(self.chain.substitute(to), self.point, self.kind, self.vector, self.offset)

    def structure_key(self) -> bytes:
        """Bytes equal for chain expressions of equal structure (factors, entries' variable
        positions by first appearance, numbers, kind); with :func:`supinf.expression_key`
        of :attr:`expr` it keys a bounder."""
        order = {s.element_hash(): i for i, s in enumerate(self.chain.symbols())}
        parts: list[bytes] = [self.kind.encode(), np.array(self.point + self.vector + (self.offset,)).tobytes()]
        for f in self.chain.factors:
            if isinstance(f, ErrorFactor):
                parts.append(repr(tuple(f"v{order[e.element_hash()]}" if isinstance(e, ca.SX) else float(e)
                                        for e in (f.dx, f.dy, f.dz, f.theta)) + (f.inverse,)).encode())
            else:
                parts.append(f.tobytes())
        return b"|".join(parts)
