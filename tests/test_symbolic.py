"""symbolic.py: SX homogeneous transforms (one code path with numpy) and the variable registry (Fig. 11)."""
from __future__ import annotations

import math

import casadi as ca
import numpy as np
import pytest

from spar_py.core import geometry
from spar_py.core.errors import SparValueError
from spar_py.phase2.symbolic import (
    Registry,
    apply,
    as_sx,
    compose,
    free_names,
    inv,
    is_symbolic,
    n_nodes,
    rotz,
    snap,
    to_function,
    trans,
)


def substitute(M: ca.SX, values: dict[str, float]) -> np.ndarray:
    """Numeric value of an SX matrix with its free symbols replaced by ``values``."""
    syms = ca.symvar(M)
    f = ca.Function("f", syms, [M])
    return np.asarray(f(*[values[s.name()] for s in syms]), float)


# ------------------------------------------------------------------ transforms


def test_transforms_are_geometrys_one_code_path() -> None:
    from spar_py.phase2 import symbolic

    for name in ("trans", "rotx", "roty", "rotz", "rpy", "euler_zyz", "eulerxyz", "compose", "inv", "apply",
                 "tm_rows", "rot", "transl", "is_symbolic", "as_sx"):
        assert getattr(symbolic, name) is getattr(geometry, name), name


def test_numeric_path_matches_geometry() -> None:
    assert isinstance(trans(1, 2, 3), np.ndarray)
    np.testing.assert_allclose(trans(1, 2, 3), geometry.trans(1, 2, 3))
    np.testing.assert_allclose(rotz(0.7), geometry.rotz(0.7))
    T = compose(trans(1, 2, 3), rotz(0.3), trans(-1, 0, 2))
    np.testing.assert_allclose(T, geometry.trans(1, 2, 3) @ geometry.rotz(0.3) @ geometry.trans(-1, 0, 2))
    np.testing.assert_allclose(inv(T), geometry.inv(T))
    np.testing.assert_allclose(apply(T, [1, 2, 3]), (T @ [1, 2, 3, 1])[:3])
    np.testing.assert_allclose(compose(), np.eye(4))


def test_symbolic_path_matches_numeric_path() -> None:
    reg = Registry()
    th, dx = reg.new("th", -1, 1), reg.new("dx", -1, 1)
    T = compose(geometry.eulerxyz(1, 2, 3, 0.3, 0.4, 0.5), trans(dx, 0.5, 0), rotz(th), trans(0, 1, 2))
    assert is_symbolic(T) and T.shape == (4, 4)
    vals = {"th": 0.37, "dx": -0.2}
    Tn = compose(geometry.eulerxyz(1, 2, 3, 0.3, 0.4, 0.5), trans(-0.2, 0.5, 0), rotz(0.37), trans(0, 1, 2))
    np.testing.assert_allclose(substitute(T, vals), Tn, atol=1e-12)
    np.testing.assert_allclose(substitute(inv(T), vals), np.linalg.inv(Tn), atol=1e-12)
    np.testing.assert_allclose(substitute(compose(T, inv(T)), vals), np.eye(4), atol=1e-12)
    p = apply(T, [1.0, -2.0, 0.5])
    assert p.shape == (3, 1)
    np.testing.assert_allclose(substitute(p, vals).ravel(), (Tn @ [1.0, -2.0, 0.5, 1.0])[:3], atol=1e-12)


def test_apply_symbolic_point_and_checks() -> None:
    reg = Registry()
    x = reg.new("x", 0, 1)
    p = apply(trans(1, 2, 3), [x, 0.0, 0.0])
    np.testing.assert_allclose(substitute(p, {"x": 0.5}).ravel(), [1.5, 2, 3])
    with pytest.raises(SparValueError):
        apply(np.eye(4), [1.0, 2.0])


def test_numeric_factors_fold_before_symbols() -> None:
    reg = Registry()
    th = reg.new("th", -0.1, 0.1)
    # trans(1,0,0) @ trans(2,0,0) is folded in numpy: the chain has two factors, not three
    a = compose(trans(1, 0, 0), trans(2, 0, 0), rotz(th))
    b = compose(trans(3, 0, 0), rotz(th))
    assert n_nodes(a) == n_nodes(b)


def test_snap_cleans_degree_noise_only() -> None:
    R = geometry.rotz(math.pi / 2)
    assert R[0, 0] != 0.0
    S = snap(R)
    assert S[0, 0] == 0.0 and S[1, 0] == 1.0 and S[0, 1] == -1.0
    assert snap([[0.5, 1e-9]])[0, 1] == 1e-9  # only noise below the tolerance goes
    reg = Registry()
    dx = reg.new("dx", -1, 1)
    assert "dx" not in str(compose(snap(R), trans(dx, 0, 0))[0, 3])  # 0 * dx folded away


def test_as_sx_and_free_names() -> None:
    reg = Registry()
    a, b = reg.new("a", 0, 1), reg.new("b", 0, 1)
    assert free_names(a * b + a) == ["a", "b"]
    assert as_sx(np.eye(2)).shape == (2, 2)
    assert isinstance(as_sx(ca.DM([1.0])), ca.SX)
    with pytest.raises(SparValueError):
        as_sx(ca.MX.sym("m"))


def test_to_function_evaluates_many_points() -> None:
    reg = Registry()
    a, b = reg.new("a", 0, 1), reg.new("b", 0, 1)
    f = to_function(a * b, ["a", "b"], reg)
    P = np.array([[1.0, 2.0, 3.0], [4.0, 5.0, 6.0]])
    np.testing.assert_allclose(np.asarray(f(P)).ravel(), [4.0, 10.0, 18.0])
    with pytest.raises(SparValueError):
        to_function(a * b, ["a"], reg)


# ------------------------------------------------------------------ the registry (Fig. 11, Sec. 5.3)


def test_registry_names_and_fixed_bounds() -> None:
    reg = Registry()
    t0 = reg.new("thetagr", -0.001, 0.001)
    t1 = reg.new("thetagr", -0.002, 0.002)
    d1 = reg.new("dx_o_1", -1, 1)
    assert [t0.name(), t1.name(), d1.name()] == ["thetagr", "thetagr_1", "dx_o_1"]
    assert reg.bounds("thetagr") == (-0.001, 0.001)
    assert reg.bounds("thetagr_1") == (-0.002, 0.002)
    assert len(reg) == 3 and "thetagr_1" in reg and list(reg) == ["thetagr", "thetagr_1", "dx_o_1"]
    assert ca.is_equal(reg.symbol("thetagr"), t0)
    assert reg.box(t0 * t1 + 2) == {"thetagr": (-0.001, 0.001), "thetagr_1": (-0.002, 0.002)}
    assert reg.box(np.eye(4)) == {}
    # new variables never change old bounds: reducing uncertainty means new variables
    reg.new("thetagr", -5, 5)
    assert reg.bounds("thetagr") == (-0.001, 0.001)
    assert reg.items()["thetagr_2"] == (-5.0, 5.0)


def test_registry_facts_are_the_papers() -> None:
    reg = Registry()
    reg.new("dx", -0.05, 0.05)
    assert reg.facts() == [("supinf_variable", "dx"), ("supinf_less", -0.05, "dx"), ("supinf_less", "dx", 0.05)]


@pytest.mark.parametrize("lo, hi", [(1.0, 0.0), (math.nan, 1.0), (0.0, math.nan), (-math.inf, 0.0),
                                    (0.0, math.inf), ("a", 1.0), (None, 1.0)])
def test_registry_rejects_bad_bounds(lo: object, hi: object) -> None:
    with pytest.raises(SparValueError):
        Registry().new("x", lo, hi)  # type: ignore[arg-type]


@pytest.mark.parametrize("name", ["", "1x", "a b", "x-y", "f(x)", 3])
def test_registry_rejects_bad_names(name: object) -> None:
    with pytest.raises(SparValueError):
        Registry().new(name, 0, 1)  # type: ignore[arg-type]


def test_registry_point_variable_allowed() -> None:
    reg = Registry()
    reg.new("z", 0.5, 0.5)
    assert reg.bounds("z") == (0.5, 0.5)


def test_registry_rejects_foreign_symbols() -> None:
    reg, other = Registry(), Registry()
    x = other.new("x", 0, 1)
    with pytest.raises(SparValueError):
        reg.box(x + 1)
    reg.new("x", 0, 1)  # same name, different symbol
    with pytest.raises(SparValueError):
        reg.box(x + 1)
    with pytest.raises(SparValueError):
        reg.bounds("nope")
    with pytest.raises(SparValueError):
        reg.symbol("nope")
