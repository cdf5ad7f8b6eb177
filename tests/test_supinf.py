"""supinf: SUP/INF (Sec. 5.3) — interval operations, soundness on random HTM products, tightness.

Soundness: ``lo <= f(x) <= hi`` at every sampled point x of the box, for random
expressions built like the planner's (products of homogeneous transforms with bounded
translations and rotations about z, plan lengths 1..8). Tightness: the bounds are within
1% of the range width of the true extremum, found by dense sampling plus local
optimisation (CasADi's bundled IPOPT) started from many points.
"""
from __future__ import annotations

import math
from dataclasses import replace
from fractions import Fraction
from pathlib import Path

import casadi as ca
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from spar_py.core import geometry
from spar_py.core.errors import SparValueError
from spar_py.kb import load_problem
from spar_py.core.memo import Memo
from spar_py.phase2.supinf import (
    AffineProgram,
    Bounder,
    BoundResult,
    IntervalProgram,
    cached_bounds,
    bounds,
    inf,
    interval,
    iv_add,
    iv_atan2,
    iv_cos,
    iv_div,
    iv_exp,
    iv_fabs,
    iv_log,
    iv_mul,
    iv_neg,
    iv_pow_const,
    iv_scale,
    iv_sin,
    iv_sq,
    iv_sqrt,
    iv_sub,
    iv_tan,
    sup,
)
from spar_py.phase2.symbolic import Registry, apply, compose, inv, rotz, trans
from spar_py.phase2.uncertainty import (
    assemble_constraints,
    dense_range_scan,
    initial_world,
    pickup,
    pickup_constraints,
    putdown,
)

# ------------------------------------------------------------------ helpers


def iv(lo: float, hi: float) -> np.ndarray:
    """A batch of one interval."""
    return np.array([[lo], [hi]], float)


def ends(r: np.ndarray) -> tuple[float, float]:
    return float(r[0, 0]), float(r[1, 0])


def contains(r: np.ndarray, x: float | Fraction) -> bool:
    """lo <= x <= hi, exactly (x may be a rational; infinite ends hold everything beyond)."""
    lo, hi = ends(r)
    X = Fraction(x)
    return (lo == -math.inf or Fraction(lo) <= X) and (hi == math.inf or X <= Fraction(hi))


finite = st.floats(-1e6, 1e6, allow_nan=False, allow_infinity=False)


def rand_rigid(rng: np.random.Generator, scale: float) -> np.ndarray:
    a = rng.uniform(-np.pi, np.pi, 3)
    T = geometry.rotz(a[0]) @ geometry.roty(a[1]) @ geometry.rotx(a[2])
    T[:3, 3] = rng.uniform(-scale, scale, 3)
    return T


def rand_bounds(rng: np.random.Generator, half_width: float) -> tuple[float, float]:
    """Bounds around 0 (as uncertainty is), sometimes off-centre or not containing 0."""
    if rng.random() < 0.2:
        a, b = sorted(rng.uniform(-half_width, half_width, 2))
        return float(a), float(b)
    return float(rng.uniform(-half_width, 0)), float(rng.uniform(0, half_width))


def random_chain(rng: np.random.Generator, n_actions: int, reg: Registry, big_angles: float = 0.15) -> ca.SX:
    """A scalar from a product of homogeneous transforms, as a plan of n_actions would build it.

    Each action contributes an error transform trans(dx, dy, dz) rotz(theta) with fresh
    bounded variables (lengths up to +-0.2, angles up to +-0.2 rad, or with probability
    ``big_angles`` up to +-3 rad), sometimes inverted, between random rigid transforms.
    The scalar is a translation component, a coordinate of T^-1 p (a pickup-like
    inequality) or a squared distance (an assemble-like one).
    """
    T = rand_rigid(rng, 30.0)
    for _ in range(n_actions):
        w = 10 ** rng.uniform(-3, -0.7)
        th = 3.0 if rng.random() < big_angles else w
        E = compose(trans(reg.new("dx", *rand_bounds(rng, w)), reg.new("dy", *rand_bounds(rng, w)),
                          reg.new("dz", *rand_bounds(rng, w))), rotz(reg.new("th", *rand_bounds(rng, th))))
        if rng.random() < 0.3:
            E = inv(E)
        N = rand_rigid(rng, 5.0)
        T = compose(T, E, N) if rng.random() < 0.7 else compose(E, T, N)
    kind = int(rng.integers(3))
    p = rng.uniform(-3, 3, 3)
    if kind == 0:
        return T[int(rng.integers(3)), 3]
    if kind == 1:
        return apply(inv(T), p)[int(rng.integers(3))]
    return ca.sumsqr(apply(T, p) - rng.uniform(-30, 30, 3))


def box_arrays(B: Bounder, box: dict) -> tuple[np.ndarray, np.ndarray]:
    return (np.array([box[n][0] for n in B.names]), np.array([box[n][1] for n in B.names]))


def check_sound(e: ca.SX, box: dict, rng: np.random.Generator, n_points: int, clarke_fabs: bool = True,
                **opts: object) -> BoundResult:
    """Bound e over box and check lo <= f <= hi at random points, corners and the found optima."""
    B = Bounder(e, clarke_fabs=clarke_fabs)
    r = B.bounds(box, **opts)
    lo, hi = box_arrays(B, box)
    P = np.vstack([rng.uniform(lo, hi, (n_points, lo.size)), lo, hi,
                   np.where(rng.random((64, lo.size)) < 0.5, lo, hi)])
    v = B.values(P)
    v = v[np.isfinite(v)]
    slack = 1e-12 * (1.0 + np.abs(v).max())  # CasADi's float evaluation rounds to nearest
    assert r.lo <= v.min() + slack, (r, v.min())
    assert v.max() - slack <= r.hi, (r, v.max())
    assert r.lo <= r.lo_found and r.hi_found <= r.hi
    return r


def true_extrema(e: ca.SX, box: dict, rng: np.random.Generator, starts: list[np.ndarray]) -> tuple[float, float]:
    """Best min and max of e over box by dense sampling then IPOPT from the best points and ``starts``."""
    B = Bounder(e)
    lo, hi = box_arrays(B, box)
    P = np.vstack([rng.uniform(lo, hi, (20000, lo.size)), np.where(rng.random((2000, lo.size)) < 0.5, lo, hi)])
    v = B.values(P)
    x = ca.vertcat(*ca.symvar(e))
    best = [float(v.min()), float(v.max())]
    opts = {"ipopt.print_level": 0, "print_time": 0, "ipopt.sb": "yes", "ipopt.max_iter": 200}
    for k, sign in ((0, 1.0), (1, -1.0)):
        solver = ca.nlpsol("s", "ipopt", {"x": x, "f": sign * e}, opts)
        seeds = [P[np.argmin(sign * v)], 0.5 * (lo + hi), *starts]
        for x0 in seeds:
            sol = solver(x0=x0, lbx=lo, ubx=hi)
            xs = np.clip(np.asarray(sol["x"]).ravel(), lo, hi)
            fx = float(B.values(xs[None, :])[0])
            best[k] = min(best[k], fx) if k == 0 else max(best[k], fx)
    return best[0], best[1]


# ------------------------------------------------------------------ interval operations


@given(finite, finite, finite, finite)
def test_add_sub_mul_contain_exact_results(a: float, b: float, c: float, d: float) -> None:
    A, Bv = iv(*sorted((a, b))), iv(*sorted((c, d)))
    for x in {a, b}:
        for y in {c, d}:
            X, Y = Fraction(x), Fraction(y)
            assert contains(iv_add(A, Bv), X + Y)
            assert contains(iv_sub(A, Bv), X - Y)
            assert contains(iv_mul(A, Bv), X * Y)
            assert contains(iv_scale(A, y), X * Y)
            if y != 0 and not (min(c, d) <= 0 <= max(c, d)):
                assert contains(iv_div(A, Bv), X / Y)


def test_outward_rounding_is_strict() -> None:
    r = iv_add(iv(0.1, 0.1), iv(0.2, 0.2))
    lo, hi = ends(r)
    assert lo < 0.1 + 0.2 < hi  # the float sum is one of many reals the interval must cover
    assert hi - lo <= 4 * math.ulp(0.3)
    lo, hi = ends(iv_mul(iv(1 / 3, 1 / 3), iv(3.0, 3.0)))
    assert lo < 1.0 <= hi or lo <= 1.0 < hi
    assert ends(iv_neg(iv(1.0, 2.0))) == (-2.0, -1.0)


@given(st.floats(0, 1e6), st.floats(0, 1e6))
def test_sqrt_and_sq_contain_exact_results(a: float, b: float) -> None:
    lo, hi = sorted((a, b))
    r = iv_sqrt(iv(lo, hi))
    assert Fraction(ends(r)[0]) ** 2 <= Fraction(lo) and Fraction(hi) <= Fraction(ends(r)[1]) ** 2
    s = iv_sq(iv(-lo, hi))
    assert ends(s)[0] == 0.0 and Fraction(ends(s)[1]) >= Fraction(max(lo, hi)) ** 2


def test_division_by_an_interval_holding_zero_is_unbounded() -> None:
    assert ends(iv_div(iv(1, 2), iv(-1, 1))) == (-math.inf, math.inf)
    assert ends(iv_div(iv(1, 2), iv(0, 1))) == (-math.inf, math.inf)
    lo, hi = ends(iv_div(iv(1, 2), iv(4, 8)))
    assert lo <= 0.125 and hi >= 0.5


@pytest.mark.parametrize("lo, hi, want_lo, want_hi", [
    (-0.1, 0.1, None, 1.0),                     # max of cos at 0 inside
    (3.0, 3.3, -1.0, None),                     # min at pi inside
    (-7.0, 0.0, -1.0, 1.0),                     # a whole period
    (0.1, 0.2, math.cos(0.2), math.cos(0.1)),   # monotone piece
    (2 * math.pi - 1e-3, 2 * math.pi + 1e-3, None, 1.0),
])
def test_cos_exact_over_intervals(lo: float, hi: float, want_lo: float | None, want_hi: float | None) -> None:
    r = iv_cos(iv(lo, hi))
    xs = np.linspace(lo, hi, 2001)
    assert ends(r)[0] <= np.cos(xs).min() and np.cos(xs).max() <= ends(r)[1]
    if want_lo is not None:
        assert ends(r)[0] == pytest.approx(want_lo, abs=1e-13)
    if want_hi is not None:
        assert ends(r)[1] == pytest.approx(want_hi, abs=1e-13)


def test_sin_exact_over_intervals() -> None:
    assert ends(iv_sin(iv(1.0, 2.0)))[1] == 1.0
    assert ends(iv_sin(iv(-2.0, -1.0)))[0] == -1.0
    lo, hi = ends(iv_sin(iv(-0.1, 0.1)))
    assert lo == pytest.approx(math.sin(-0.1), abs=1e-14) and hi == pytest.approx(math.sin(0.1), abs=1e-14)
    assert lo <= math.sin(-0.1) and math.sin(0.1) <= hi
    lo, hi = ends(iv_sin(iv(1e-3, 1e-3)))  # a point: tight but outward
    assert lo <= math.sin(1e-3) <= hi and hi - lo < 1e-17


@given(st.floats(-50, 50), st.floats(0, 7))
def test_trig_contain_samples(a: float, w: float) -> None:
    xs = np.linspace(a, a + w, 257)
    for f, F in ((np.sin, iv_sin), (np.cos, iv_cos)):
        r = F(iv(a, a + w))
        v = f(xs)
        assert ends(r)[0] <= v.min() and v.max() <= ends(r)[1]
        assert -1.0 <= ends(r)[0] and ends(r)[1] <= 1.0


@given(st.floats(-1.4, 1.4), st.floats(0, 1.4))
def test_trig_fast_paths_contain_samples(a: float, w: float) -> None:
    """Small angles (the planner's case) take the fast paths: still exact and outward."""
    lo, hi = a, min(a + w, 2.9)
    xs = np.append(np.linspace(lo, hi, 257), [0.0] if lo <= 0 <= hi else [])  # with cos's maximum
    rc, rs = iv_cos(iv(lo, hi)), iv_sin(iv(lo, hi))
    assert ends(rc)[0] <= np.cos(xs).min() and np.cos(xs).max() <= ends(rc)[1] <= 1.0
    assert ends(rc)[1] - np.cos(xs).max() < 1e-12 and np.cos(xs).min() - ends(rc)[0] < 1e-12
    if hi < 1.5:
        assert ends(rs)[0] <= math.sin(lo) and math.sin(hi) <= ends(rs)[1]
        assert ends(rs)[1] - math.sin(hi) < 1e-14 and math.sin(lo) - ends(rs)[0] < 1e-14


def test_tan_poles_and_pieces() -> None:
    assert ends(iv_tan(iv(1.5, 1.6))) == (-math.inf, math.inf)
    assert ends(iv_tan(iv(-1.0, 5.0))) == (-math.inf, math.inf)
    lo, hi = ends(iv_tan(iv(-1.0, 1.0)))
    assert lo <= math.tan(-1.0) and math.tan(1.0) <= hi and hi - math.tan(1.0) < 1e-13


def test_atan2_corners_and_branch_cut() -> None:
    lo, hi = ends(iv_atan2(iv(1.0, 2.0), iv(1.0, 2.0)))
    assert lo <= math.atan2(1, 2) and math.atan2(2, 1) <= hi and hi - math.atan2(2, 1) < 1e-13
    lo, hi = ends(iv_atan2(iv(-1.0, 1.0), iv(-2.0, -1.0)))  # crosses the cut
    assert lo <= -math.pi and math.pi <= hi
    lo, hi = ends(iv_atan2(iv(0.0, 1.0), iv(-2.0, -1.0)))  # touches it (atan2(+0, x<0) = pi)
    assert hi >= math.pi


def test_pow_fabs_exp_log() -> None:
    assert ends(iv_pow_const(iv(-2, 1), 2))[0] == 0.0
    lo, hi = ends(iv_pow_const(iv(-2, 1), 3))
    assert lo <= -8 and 1 <= hi
    lo, hi = ends(iv_pow_const(iv(1, 4), 0.5))
    assert lo <= 1 and 2 <= hi
    assert ends(iv_pow_const(iv(-1, 1), -1)) == (-math.inf, math.inf)
    assert ends(iv_fabs(iv(-3, 2))) == (0.0, 3.0)
    assert ends(iv_fabs(iv(-3, -2))) == (2.0, 3.0)
    lo, hi = ends(iv_exp(iv(0, 1)))
    assert lo <= 1 and math.e <= hi
    lo, hi = ends(iv_log(iv(1, math.e)))
    assert lo <= 0 and 1 <= hi
    assert np.isnan(iv_log(iv(-2, -1))).all()


def test_program_reports_unknown_as_unbounded() -> None:
    reg = Registry()
    x = reg.new("x", -2.0, -1.0)
    assert interval(ca.sqrt(x), reg.box(x)) == (-math.inf, math.inf)  # outside the domain: unknown
    y = reg.new("y", -1.0, 1.0)
    assert interval(1 / y, reg.box(y)) == (-math.inf, math.inf)


def test_affine_arithmetic_keeps_correlations() -> None:
    reg = Registry()
    th, d = reg.new("th", -0.1, 0.1), reg.new("d", -1, 1)
    e = (30 + d) * ca.cos(th) - 30 * ca.cos(th)  # = d cos(th), in [-1, 1]
    B = Bounder(e)
    lo, hi = box_arrays(B, reg.box(e))
    A = B.affine.enclosure(B.affine(lo[None], hi[None])[:, 0, :])[:, 0]
    plain = B.interval(reg.box(e))
    assert A[0] <= -1.0 and 1.0 <= A[1]
    assert A[1] - A[0] < 2.05  # the two cos(th) share one noise symbol: the 30s cancel
    assert plain[1] - plain[0] > 2.2  # intervals lose that: [29, 31] [0.995, 1] - [29.85, 30]


# ------------------------------------------------------------------ the bounder


def test_constants_points_and_errors() -> None:
    assert bounds(ca.SX(2.5), {}) == (2.5, 2.5)
    assert bounds(3.0, {}) == (3.0, 3.0)
    reg = Registry()
    x = reg.new("x", 1.0, 1.0)
    lo, hi = bounds(ca.sin(x), reg.box(x))
    assert lo <= math.sin(1.0) <= hi and hi - lo < 1e-14
    with pytest.raises(SparValueError):
        bounds(x, {})  # no bounds for x
    with pytest.raises(SparValueError):
        bounds(x, {"x": (2, 1)})
    with pytest.raises(SparValueError):
        bounds(x, {"x": (0, math.inf)})
    with pytest.raises(SparValueError):
        bounds(ca.vertcat(x, x), reg.box(x))
    with pytest.raises(SparValueError):
        bounds(ca.floor(x), reg.box(x))  # no interval rule for floor
    with pytest.raises(SparValueError):
        bounds("x", {})  # type: ignore[arg-type]
    with pytest.raises(SparValueError):
        Bounder(x).bounds(reg.box(x), want="middle")
    with pytest.raises(SparValueError):
        Bounder(x).bounds(reg.box(x), rel_tol=0, abs_tol=0)


def test_inf_sup_one_sided() -> None:
    reg = Registry()
    x, y = reg.new("x", -1, 2), reg.new("y", -0.5, 0.7)
    e = ca.sin(x) * y + x ** 2 - ca.cos(3 * y) * x
    box = reg.box(e)
    lo, hi = bounds(e, box)
    assert inf(e, box) == pytest.approx(lo, abs=2e-3 * (hi - lo))
    assert sup(e, box) == pytest.approx(hi, abs=2e-3 * (hi - lo))
    r = Bounder(e).bounds(box)
    assert r.tolerance_reached and r.gap <= 1e-3 * (r.hi_found - r.lo_found) + 1e-12


def test_budget_exhausted_is_still_sound() -> None:
    rng = np.random.default_rng(6)
    reg = Registry()
    e = random_chain(rng, 6, reg, big_angles=1.0)
    r = check_sound(e, reg.box(e), rng, 2000, max_boxes=8)
    assert not r.tolerance_reached and r.boxes <= 8 + 2 * 256
    r2 = check_sound(e, reg.box(e), rng, 2000, max_time=1e-4)
    assert r2.lo <= r2.lo_found


def test_discontinuous_atan2_no_monotonicity_shortcut() -> None:
    reg = Registry()
    y, x = reg.new("y", -0.5, 0.5), reg.new("x", -2.0, -1.0)
    e = ca.atan2(y, x) + 0.01 * y  # jumps from pi to -pi across y = 0
    r = check_sound(e, reg.box(e), np.random.default_rng(0), 20000)
    assert r.hi >= math.pi - 1e-9 and r.lo <= -math.pi + 1e-9


def test_monotone_expression_is_exact_at_a_corner() -> None:
    reg = Registry()
    a, b = reg.new("a", 0.1, 0.2), reg.new("b", 1.0, 3.0)
    e = ca.exp(a) * b + ca.sqrt(b)
    r = Bounder(e).bounds(reg.box(e))
    assert r.lo == pytest.approx(math.exp(0.1) + 1.0, abs=1e-12)
    assert r.hi == pytest.approx(math.exp(0.2) * 3 + math.sqrt(3), abs=1e-12)
    assert r.lo <= math.exp(0.1) + 1.0 and math.exp(0.2) * 3 + math.sqrt(3) <= r.hi


def test_program_rejects_multi_input_functions() -> None:
    x, y = ca.SX.sym("x"), ca.SX.sym("y")
    with pytest.raises(SparValueError):
        IntervalProgram(ca.Function("f", [x, y], [x + y]))
    with pytest.raises(SparValueError):
        AffineProgram(ca.Function("f", [x, y], [x + y]))


# ------------------------------------------------------------------ soundness on random HTM products


def _random_case(seed: int, n: int) -> None:
    rng = np.random.default_rng(seed)
    reg = Registry()
    e = random_chain(rng, n, reg)
    check_sound(e, reg.box(e), rng, N_POINTS, max_boxes=MAX_BOXES)


N_POINTS = 2_000
MAX_BOXES = 600


@settings(max_examples=100, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.integers(0, 2**32 - 1), st.integers(1, 8))
def test_sound_on_random_htm_products(seed: int, n: int) -> None:
    """Fast default sample: 100 expressions, 2000 points each (the slow test does 200 x 10^5)."""
    _random_case(seed, n)


@pytest.mark.slow
@settings(max_examples=200, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.integers(0, 2**32 - 1), st.integers(1, 8))
def test_sound_on_random_htm_products_dense(seed: int, n: int) -> None:
    """200 random HTM-product expressions, 10^5 random points of the box each."""
    rng = np.random.default_rng(seed)
    reg = Registry()
    e = random_chain(rng, n, reg)
    check_sound(e, reg.box(e), rng, 100_000, max_boxes=MAX_BOXES)


# ------------------------------------------------------------------ tightness


@pytest.mark.parametrize("seed", range(6))
def test_tight_on_small_uncertainty_chains(seed: int) -> None:
    """Plan-like chains with small angles: within 1% of the true range (sampling + IPOPT)."""
    rng = np.random.default_rng(100 + seed)
    reg = Registry()
    e = random_chain(rng, 1 + seed % 4, reg, big_angles=0.0)
    box = reg.box(e)
    B = Bounder(e)
    r = B.bounds(box)
    tmin, tmax = true_extrema(e, box, rng, [])
    width = tmax - tmin
    assert r.lo <= tmin + 1e-9 * (1 + abs(tmin)) and tmax - 1e-9 * (1 + abs(tmax)) <= r.hi
    assert tmin - r.lo <= 0.01 * width and r.hi - tmax <= 0.01 * width
    plain = B.interval(box)
    assert plain[0] <= r.lo + 1e-12 and r.hi <= plain[1] + 1e-12


def paper_expressions() -> list[tuple[str, ca.SX, Registry]]:
    """The paper's cell: the peg's first pickup (Sec. 6: W_p = 3, W_m = 4, Table 2) and the
    assemble inequality after turning the block hole up, with and without the range scans."""
    cell = load_problem(Path(__file__).resolve().parent.parent / "kb" / "problems" / "peg_in_block.yaml")
    peg, block = cell.objects["peg"], cell.objects["block"]
    w = initial_world(cell)
    g = peg.grasps["p1G1"]
    out = [(f"pickup {c.name}", c.expr, w.registry)
           for c in pickup_constraints(w, "peg", g.T, g.width, cell.finger_separation, w.manipulator_error())]
    gb = next(gr for gr in block.grasps.values() if abs(gr.T[2, 2]) < 1e-9)
    up = next(p for p in block.poses.values() if np.allclose(p.R, np.eye(3)))
    w = putdown(pickup(w, "block", gb.T, w.manipulator_error()), "block", geometry.trans(30, 0, up.height))
    for scans in (False, True):
        ws = w
        if scans:
            leaves = cell.sensors["dense_range_scan"].leaves
            ws = dense_range_scan(dense_range_scan(ws, "block", leaves), "peg", leaves)
        ws = pickup(ws, "peg", g.T, ws.manipulator_error())
        (c,) = assemble_constraints(ws, "peg", "block", cell.transforms["trans_1"], peg.features[0], block.features[0],
                                    axis=cell.vectors["vec_1"])
        out.append((f"assemble scans={scans}", c.expr, ws.registry))
    return out


def test_tight_on_the_paper_cell(capsys: pytest.CaptureFixture[str]) -> None:
    """Within 1% of the true range width (sampling + IPOPT) on the paper's pickup and assemble
    expressions; the plain interval evaluation's gap is reported (``pytest -s``)."""
    rng = np.random.default_rng(7)
    lines = []
    for name, e, reg in paper_expressions():
        box = reg.box(e)
        B = Bounder(e)
        r = B.bounds(box)
        tmin, tmax = true_extrema(e, box, rng, [])
        width = tmax - tmin
        assert r.lo <= tmin + 1e-12 and tmax - 1e-12 <= r.hi, name
        ours = max(tmin - r.lo, r.hi - tmax) / width
        plain = B.interval(box)
        gap = max(tmin - plain[0], plain[1] - tmax) / width
        assert ours <= 0.01 and r.tolerance_reached, name
        assert ours <= gap + 1e-12
        lines.append(f"{name:<22} true [{tmin:.6f}, {tmax:.6f}]  ours {ours:.1e}  plain {gap:.1e} of the width")
    with capsys.disabled():
        print("\n" + "\n".join(lines))


# ------------------------------------------------------------------ compiled program, depth 8, caches


def _uniform_chain(rng: np.random.Generator, n_actions: int, reg: Registry, half: float = 0.1) -> ca.SX:
    """A product of n_actions error transforms, every variable within +-half (in, rad)."""
    T = rand_rigid(rng, 30.0)
    for _ in range(n_actions):
        E = compose(trans(reg.new("dx", -half, half), reg.new("dy", -half, half), reg.new("dz", -half, half)),
                    rotz(reg.new("th", -half, half)))
        if rng.random() < 0.3:
            E = inv(E)
        T = compose(T, E, rand_rigid(rng, 5.0))
    p = rng.uniform(-3, 3, 3)
    return apply(inv(T), p)[int(rng.integers(3))] if rng.random() < 0.5 else T[int(rng.integers(3)), 3]


@settings(max_examples=6, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.integers(0, 2**32 - 1), st.sampled_from([1, 4, 8]))
def test_compiled_program_encloses_the_interpreted_one(seed: int, n: int) -> None:
    """The compiled interval program (value and gradient) contains the interpreted program's
    enclosure on random sub-boxes, and the sampled values; it is at most a hair wider."""
    from spar_py.phase2.supinf import CompiledIntervalProgram

    rng = np.random.default_rng(seed)
    reg = Registry()
    e = random_chain(rng, n, reg)
    B = Bounder(e)
    C, P = CompiledIntervalProgram(B.value_gradient), IntervalProgram(B.value_gradient)
    lo, hi = box_arrays(B, reg.box(e))
    a, b = rng.uniform(lo, hi, (40, lo.size)), rng.uniform(lo, hi, (40, lo.size))
    L, H = np.minimum(a, b), np.maximum(a, b)
    (cf, cg), cd = C(L, H)
    (pf, pg), pd = P(L, H)
    for c, p in ((cf, pf), (cg, pg)):
        assert (c[0] <= p[0]).all() and (c[1] >= p[1]).all()
        fin = np.isfinite(p)
        scale = 1.0 + np.abs(p[fin])
        assert (np.abs(c[fin] - p[fin]) <= 1e-9 * scale).all()
    assert (cd == pd).all()
    x = rng.uniform(L[0], H[0], (500, lo.size))  # the first box: values inside its enclosure
    v = B.values(x)
    assert cf[0, 0, 0] <= v.min() and v.max() <= cf[1, 0, 0]


def test_compiled_program_falls_back_off_its_domain() -> None:
    """Division by an interval holding 0, log of a box reaching 0, atan2 on its cut: the
    compiled program hands those boxes to the interpreted rules and agrees with them."""
    from spar_py.phase2.supinf import CompiledIntervalProgram

    x, y = ca.SX.sym("x"), ca.SX.sym("y")
    v = ca.vertcat(x, y)
    fn = ca.Function("f", [v], [ca.vertcat(x / y, ca.log(x), ca.atan2(y, x), ca.sin(x) * y)])
    C, P = CompiledIntervalProgram(fn), IntervalProgram(fn)
    L = np.array([[1.0, -1.0], [0.0, 0.5], [-2.0, -0.1], [0.5, 1.0]])
    H = np.array([[2.0, 1.0], [1.0, 1.5], [-1.0, 0.1], [0.6, 2.0]])
    (c,), cd = C(L, H)
    (p,), pd = P(L, H)
    assert np.array_equal(np.isinf(c), np.isinf(p))
    assert c[0, 0, 0] == -math.inf and c[1, 0, 0] == math.inf  # x / y, y holds 0
    assert c[0, 1, 1] == -math.inf  # log over [0, 1]
    assert (cd == pd).all() and cd[0] and cd[2] and not cd[3]
    fin = np.isfinite(p)
    assert (c[0][fin[0]] <= p[0][fin[0]]).all() and (c[1][fin[1]] >= p[1][fin[1]]).all()


def test_compiled_bounder_is_sound_and_agrees() -> None:
    """Bounder(compiled=True) sends small batches to the compiled program: sound, and within
    the tolerance of the interpreted bounder's answer."""
    rng = np.random.default_rng(5)
    reg = Registry()
    e = random_chain(rng, 3, reg, big_angles=0.0)
    box = reg.box(e)
    Bc, Bi = Bounder(e, compiled=True), Bounder(e)
    rc, ri = Bc.bounds(box), Bi.bounds(box)
    assert Bc.gradient is not None and Bc.gradient.compiled is not None
    assert Bi.gradient is not None and Bi.gradient.compiled is None
    assert rc.lo <= ri.lo_found and rc.hi >= ri.hi_found and ri.lo <= rc.lo_found and ri.hi >= rc.hi_found
    w = ri.hi_found - ri.lo_found
    assert abs(rc.lo - ri.lo) <= 2e-3 * w and abs(rc.hi - ri.hi) <= 2e-3 * w
    lo, hi = box_arrays(Bc, box)
    v = Bc.values(rng.uniform(lo, hi, (5000, lo.size)))
    assert rc.lo <= v.min() and v.max() <= rc.hi


@pytest.mark.parametrize("seed", range(4))
def test_sound_at_depth_8_small_angles(seed: int) -> None:
    """Products of 8 error transforms at +-0.1 (in, rad), 32 variables: sound however the
    budget ends, and never looser than plain interval arithmetic."""
    rng = np.random.default_rng(800 + seed)
    reg = Registry()
    e = _uniform_chain(rng, 8, reg)
    box = reg.box(e)
    r = check_sound(e, box, rng, 20_000, max_boxes=1500)
    plain = Bounder(e).interval(box)
    assert plain[0] <= r.lo + 1e-12 * (1 + abs(r.lo)) and r.hi <= plain[1] + 1e-12 * (1 + abs(r.hi))


def test_cached_bounds_by_structure_not_names() -> None:
    """The same constraint rebuilt in another registry (other variable numbering) is one
    cache entry with the same answer; another constant or another box is a new one; the
    tables keep their bounds."""
    from spar_py.phase2.supinf import BOUNDER_LIMIT, RESULT_LIMIT, cached_bounds, expression_key

    def build(skip: int, c: float = 2.0) -> tuple[ca.SX, dict]:
        reg = Registry()
        for _ in range(skip):
            reg.new("th", -1, 1)  # shifts the numbering: th_1, th_2, ...
        th, d = reg.new("th", -0.1, 0.1), reg.new("d", -0.2, 0.3)
        e = (c + d) * ca.cos(th) - 30 * ca.sin(th)
        return e, reg.box(e)

    memo = Memo()
    e1, b1 = build(0)
    e2, b2 = build(3)
    assert sorted(b1) != sorted(b2)
    assert expression_key(e1) == expression_key(e2) != expression_key(build(0, 2.5)[0])
    r1 = cached_bounds(e1, b1, memo)
    r2 = cached_bounds(e2, b2, memo)
    assert r1 == r2 == Bounder(e1).bounds(b1)
    # (two expression objects: two canonical forms, by object, of one structure)
    assert memo.sizes() == {"supinf.results": 1, "supinf.bounders": 1, "supinf.canonical": 2}
    wider = {k: (2 * lo, 2 * hi) for k, (lo, hi) in b1.items()}
    r3 = cached_bounds(e1, wider, memo)
    assert r3.lo <= r1.lo and r3.hi >= r1.hi
    assert memo.sizes() == {"supinf.results": 2, "supinf.bounders": 1, "supinf.canonical": 2}
    assert cached_bounds(e1, b1, memo, want="lo").lo == cached_bounds(e1, b1, None, want="lo").lo
    assert memo.table("supinf.results", RESULT_LIMIT).limit == RESULT_LIMIT
    assert memo.table("supinf.bounders", BOUNDER_LIMIT).limit == BOUNDER_LIMIT
    # an expression object asked again reads its canonical form (e1 above: still two); another
    # object, even of an equal structure, is renamed anew and finds the same bounder
    from spar_py.phase2.supinf import CANONICAL_LIMIT

    before = memo.sizes()
    e3, b3 = build(0)
    assert cached_bounds(e3, b3, memo) == r1
    assert memo.sizes() == {**before, "supinf.canonical": before["supinf.canonical"] + 1}
    assert memo.table("supinf.canonical", CANONICAL_LIMIT).limit == CANONICAL_LIMIT


def test_affine_division_contains_samples() -> None:
    """Affine arithmetic of a quotient (1/b gets its own noise symbol) encloses sampled values."""
    x, y = ca.SX.sym("x"), ca.SX.sym("y")
    A = AffineProgram(ca.Function("f", [ca.vertcat(x, y)], [(x + y) / (y * y + 1.0) - x / y]))
    lo, hi = np.array([[-1.0, 0.5]]), np.array([[2.0, 1.5]])
    r = A.enclosure(A(lo, hi)[:, 0, :])
    P = np.random.default_rng(0).uniform(lo[0], hi[0], (20000, 2))
    v = (P[:, 0] + P[:, 1]) / (P[:, 1] ** 2 + 1.0) - P[:, 0] / P[:, 1]
    assert r[0, 0] <= v.min() and v.max() <= r[1, 0]


# ------------------------------------------------------------------ grouped schedule, gradient model


def _sub_boxes(rng: np.random.Generator, lo: np.ndarray, hi: np.ndarray, m: int) -> tuple[np.ndarray, np.ndarray]:
    """m random sub-boxes of [lo, hi], some of them thin in a few coordinates (fixed variables)."""
    a, b = rng.uniform(lo, hi, (m, lo.size)), rng.uniform(lo, hi, (m, lo.size))
    L, H = np.minimum(a, b), np.maximum(a, b)
    thin = rng.random((m, lo.size)) < 0.2
    return L, np.where(thin, L, H)


@settings(max_examples=8, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.integers(0, 2**32 - 1), st.sampled_from([2, 5, 8]))
def test_grouped_programs_enclose_every_output_at_samples(seed: int, n: int) -> None:
    """The levelled, grouped interval and affine programs of (f, gradient) — many outputs,
    registers reused — hold CasADi's own float values of every output at sampled points of
    each box; at points (thin boxes) the interval is within a hair of the value."""
    rng = np.random.default_rng(seed)
    reg = Registry()
    e = _uniform_chain(rng, n, reg) if rng.random() < 0.5 else random_chain(rng, n, reg, big_angles=0.0)
    B = Bounder(e)
    lo, hi = box_arrays(B, reg.box(e))
    L, H = _sub_boxes(rng, lo, hi, 6)
    (f, g), _ = IntervalProgram(B.value_gradient)(L, H)
    F = B.affine_gradient(L, H)  # (rows, 1 + nv, m): forms of f and each df/dx_i
    K = B.affine_gradient.K
    for b in range(L.shape[0]):
        x = rng.uniform(L[b], H[b], (300, lo.size))
        vf, vg = B.value_gradient(x.T)
        vals = np.vstack((np.asarray(vf), np.asarray(vg).reshape(-1, lo.size).T))  # (1 + nv, 300)
        slack = 1e-11 * (1.0 + np.abs(vals))
        ivl = np.concatenate((f[:, :, b], g[:, :, b]), axis=1)  # (2, 1 + nv)
        assert (ivl[0][:, None] <= vals + slack).all() and (vals - slack <= ivl[1][:, None]).all()
        # affine forms, pointwise: value in centre + sum_j coef_j s_j +- (other symbols + radius)
        mid = np.minimum(np.maximum(0.5 * (L[b] + H[b]), L[b]), H[b])
        rd = np.maximum(np.nextafter(H[b] - mid, np.inf), np.nextafter(mid - L[b], np.inf))
        s = (x - mid) / rd
        Fb = F[:, :, b]
        centre = Fb[0][:, None] + Fb[1:K + 1].T @ s.T
        rad = (np.abs(Fb[K + 1:-1]).sum(0) + Fb[-1])[:, None]
        assert (np.abs(vals - centre) <= rad + slack + 1e-12 * np.abs(centre)).all()
    P = rng.uniform(lo, hi, (5, lo.size))
    (fp, gp), _ = IntervalProgram(B.value_gradient)(P, P)
    vf = np.asarray(B.value_gradient(P.T)[0]).ravel()
    assert (fp[0, 0] <= vf).all() and (vf <= fp[1, 0]).all()
    assert (fp[1, 0] - fp[0, 0] <= 1e-9 * (1 + np.abs(vf))).all()


@settings(max_examples=6, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.integers(0, 2**32 - 1), st.sampled_from([2, 8]))
def test_affine_forms_of_a_box_do_not_depend_on_its_batch(seed: int, n: int) -> None:
    """The affine program's register-major work array keeps boxes apart: each box's forms
    (f and gradient) evaluated alone, in a batch of 7 and at the other end of a batch of 2
    agree (to the few ulps the SIMD libm may differ by between batch sizes), and the
    zeroed input registers hold no noise symbol but their own."""
    rng = np.random.default_rng(seed)
    reg = Registry()
    e = _uniform_chain(rng, n, reg)
    B = Bounder(e)
    lo, hi = box_arrays(B, reg.box(e))
    L, H = _sub_boxes(rng, lo, hi, 7)
    AG = B.affine_gradient
    F7 = AG(L, H)
    for b in (0, 3, 6):
        F1 = AG(L[b:b + 1], H[b:b + 1])[:, :, 0]
        F2 = AG(np.vstack((L[b - 1], L[b])), np.vstack((H[b - 1], H[b])))[:, :, 1]
        scale = 1e-12 * (1.0 + np.abs(F1).max(0))
        assert (np.abs(F7[:, :, b] - F1) <= scale).all() and (np.abs(F2 - F1) <= scale).all()
    x = ca.SX.sym("x", 3)  # the inputs' own forms, x_j = mid_j + rd_j e_j, nothing else
    F = AffineProgram(ca.Function("id", [x], [x]))(L[:, :3], H[:, :3])  # (rows, 3, 7)
    mid = np.minimum(np.maximum(0.5 * (L[:, :3] + H[:, :3]), L[:, :3]), H[:, :3])
    rd = np.maximum(np.nextafter(H[:, :3] - mid, np.inf), np.nextafter(mid - L[:, :3], np.inf))
    assert np.array_equal(F[0], mid.T) and (F[-1] == 0).all()
    assert np.array_equal(F[1:4], np.eye(3)[:, :, None] * rd.T[None, :, :])


@settings(max_examples=8, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.integers(0, 2**32 - 1), st.sampled_from([1, 3, 6]), st.booleans())
def test_gradient_model_bound_and_monotone_faces_are_sound(seed: int, n: int, upper: bool) -> None:
    """taylor.GradientModel from the affine gradient: (1) its quadratic lower bound of g over
    the face it reduces a box to is below g at every sampled point of the whole box; (2) the
    reduction is a true monotonicity: moving a point's fixed coordinates onto the face never
    raises g; (3) its gradient enclosure holds the sampled gradients (g = f, or -f)."""
    from spar_py.phase2.taylor import GradientModel

    rng = np.random.default_rng(seed)
    reg = Registry()
    e = _uniform_chain(rng, n, reg, half=float(rng.choice([0.02, 0.1]))) if rng.random() < 0.6 \
        else random_chain(rng, n, reg, big_angles=0.0)
    B = Bounder(e)
    lo, hi = box_arrays(B, reg.box(e))
    L, H = _sub_boxes(rng, lo, hi, 5)
    m = L.shape[0]
    neg = np.full(m, upper)
    sign = -1.0 if upper else 1.0
    M = GradientModel.from_affine(B.affine_gradient(L, H), B.affine_gradient.K, L, H, neg)
    assert M.finite.all()
    c = M.mid
    fc = B.enclose(c, c)  # rigorous values at the centres
    gc = -fc[1] if upper else fc[0]
    nl, nh, fixed = M.fix_monotone(L, H, np.ones(m, bool))
    LQ = M.lower(gc, nl, nh)
    gl, gh = M.gradient(*M.coords(L, H))
    for b in range(m):
        x = np.vstack((rng.uniform(L[b], H[b], (2000, lo.size)),
                       np.where(rng.random((200, lo.size)) < 0.5, L[b], H[b])))
        vf, vg = B.value_gradient(x.T)
        g = sign * np.asarray(vf).ravel()
        slack = 1e-11 * (1.0 + np.abs(g))
        assert (LQ[b] <= g + slack).all(), (LQ[b], g.min())
        proj = np.where(fixed[b], nl[b], x)  # fixed coordinates moved onto the face
        gp = sign * B.values(proj)
        assert (gp <= g + slack).all()
        grad = sign * np.asarray(vg).reshape(-1, lo.size)  # (points, nv): a row per point
        gs = 1e-11 * (1.0 + np.abs(grad))
        assert (gl[b] <= grad + gs).all() and (grad - gs <= gh[b]).all()
    assert np.isfinite(LQ).all()


def test_gradient_model_is_exact_on_a_quadratic() -> None:
    """On f = (x - 0.3)^2 + 2 x y the gradient is linear, so the model's remainder is rounding
    only, and its bound is below the true minimum -0.4 (by hand: df/dx = 0 at x = 0.3 - y,
    inside [-1, 1]; there f = 0.6 y - y^2, concave, least at y = 1 of [0.5, 1])."""
    from spar_py.phase2.taylor import GradientModel

    x, y = ca.SX.sym("x"), ca.SX.sym("y")
    e = (x - 0.3) ** 2 + 2 * x * y
    B = Bounder(e)
    L, H = np.array([[-1.0, 0.5]]), np.array([[1.0, 1.0]])
    order = [B.names.index("x"), B.names.index("y")]
    L, H = L[:, order], H[:, order]
    M = GradientModel.from_affine(B.affine_gradient(L, H), 2, L, H, np.array([False]))
    assert float(M.rho.max()) < 1e-12
    fc = B.enclose(M.mid, M.mid)[0]
    true_min = -0.4
    LQ = float(M.lower(fc, L, H)[0])
    assert LQ <= true_min
    P = np.random.default_rng(0).uniform(L[0], H[0], (20000, 2))
    assert B.values(P).min() >= true_min - 1e-12
    assert LQ >= true_min - 1.5


# ------------------------------------------------------------------ kinks of fabs (Clarke gradient)


def _kinked(rng: np.random.Generator, reg: Registry) -> ca.SX:
    """A random sum of squares of |linear + trig| + c, the shape of the planner's 'centres'
    constraint: kinks along planes and curves that cross the box, often through a corner."""
    v = [reg.new(f"k{i}", *rand_bounds(rng, 0.3)) for i in range(4)]
    e = ca.SX(0)
    for _ in range(3):
        a = sum(float(rng.uniform(-1, 1)) * x for x in v) + float(rng.uniform(-0.2, 0.2)) * ca.cos(v[0])
        e = e + (ca.fabs(a + float(rng.uniform(-0.05, 0.05))) + float(rng.uniform(0, 2))) ** 2
    return e + 0.3 * ca.sin(v[1]) * ca.fabs(v[2] - v[3])


@pytest.mark.parametrize("seed", range(8))
def test_fabs_kinks_bounds_sound_against_dense_sampling(seed: int) -> None:
    rng = np.random.default_rng(seed)
    reg = Registry()
    e = _kinked(rng, reg)
    box = reg.box(e)
    check_sound(e, box, rng, 40000)
    B = Bounder(e)
    lo, hi = box_arrays(B, box)
    for _ in range(4):  # random sub-boxes too: kinks at their faces and corners
        a, b = np.sort(rng.uniform(lo, hi, (2, lo.size)), axis=0)
        sub = {n: (float(x), float(y)) for n, x, y in zip(B.names, a, b)}
        check_sound(e, sub, rng, 20000)


def test_fabs_kinks_keep_the_gradient_and_need_few_boxes() -> None:
    # the planner's assemble 'centres' shape: the maximum sits on a kink of |v1 - v2|
    reg = Registry()
    th = reg.new("th", -math.pi / 180, math.pi / 180)
    a, b = reg.new("a", -0.05, 0.05), reg.new("b", -0.05, 0.05)
    s = 0.5 ** 0.5
    e = ((ca.fabs(-1.41421 * ca.sin(th)) + 0.1) ** 2 + (ca.fabs(s * a + s * b + 1.5 * (1 - ca.cos(th))) + 3.6) ** 2
         + (ca.fabs(s * a - s * b + 0.25 * (ca.cos(th) - 1)) + 3.05) ** 2)
    B = Bounder(e)
    assert B.gradient is not None and B.gradient.sign_continuous
    r = check_sound(e, reg.box(e), np.random.default_rng(1), 40000, want="hi")
    assert r.tolerance_reached and r.boxes < 500  # 2,500 boxes when every kink blocked the gradient


def test_sign_of_its_own_keeps_the_discontinuity() -> None:
    reg = Registry()
    x, y = reg.new("x", -1.0, 1.0), reg.new("y", 0.0, 1.0)
    e = ca.sign(x) + 0.01 * x + ca.fabs(y - 0.5)  # a jump at x = 0: no derivative reasoning there
    B = Bounder(e)
    assert B.gradient is not None and not B.gradient.sign_continuous
    r = check_sound(e, reg.box(e), np.random.default_rng(2), 20000)
    assert r.lo <= -1.01 + 1e-9 and r.hi >= 1.51 - 1e-9


def test_clarke_fabs_off_restores_the_bisection_only_search() -> None:
    reg = Registry()
    a, b = reg.new("a", -0.05, 0.05), reg.new("b", -0.05, 0.05)
    e = (ca.fabs(a - b) + 3.0) ** 2 + (ca.fabs(a + b) + 3.6) ** 2
    on = check_sound(e, reg.box(e), np.random.default_rng(3), 20000, want="hi")
    assert Bounder(e).gradient.sign_continuous and not Bounder(e, clarke_fabs=False).gradient.sign_continuous
    off = check_sound(e, reg.box(e), np.random.default_rng(3), 20000, clarke_fabs=False, want="hi")
    assert on.boxes < off.boxes


@pytest.mark.parametrize("lo,hi", [(0.0, 1.0), (0.3, 1.0), (-1.0, 0.3), (-0.5, 0.5)])
def test_fabs_extremum_on_the_kink_is_enclosed(lo: float, hi: float) -> None:
    # minimum and maximum exactly at kinks (also at a face of the box): known values
    reg = Registry()
    x, y = reg.new("x", lo, hi), reg.new("y", -0.5, 0.5)
    for e, want_lo, want_hi in (
            (ca.fabs(x - 0.3) + ca.fabs(y + 0.2), min(abs(v - 0.3) for v in (lo, hi, min(max(0.3, lo), hi))),
             max(abs(lo - 0.3), abs(hi - 0.3)) + 0.7),
            (-ca.fabs(x - 0.3) - ca.fabs(y + 0.2), -(max(abs(lo - 0.3), abs(hi - 0.3)) + 0.7),
             -min(abs(v - 0.3) for v in (lo, hi, min(max(0.3, lo), hi))))):
        r = Bounder(e).bounds(reg.box(e))
        assert r.lo <= want_lo + 1e-15 and want_hi - 1e-15 <= r.hi
        assert r.tolerance_reached and want_lo - r.lo <= 1e-3 and r.hi - want_hi <= 1e-3


# ------------------------------------------------------------------ deciding a threshold (beat)


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.integers(0, 2**32 - 1), st.integers(1, 5), st.floats(0.0, 1.0), st.sampled_from(["lo", "hi"]))
def test_beat_gives_the_verdict_of_the_full_refinement(seed: int, n: int, q: float, want: str) -> None:
    """``beat`` stops SUP/INF once ``INF > beat`` (``SUP < beat``) is settled: the verdict is the
    one the full refinement gives, the bound stays sound against sampled values, and on
    thresholds well away from the range's end it does stop early. Thresholds are drawn across
    the true range, ends included, so both "proved" and "refuted" are met."""
    rng = np.random.default_rng(seed)
    reg = Registry()
    e = random_chain(rng, n, reg)
    box = reg.box(e)
    B = Bounder(e)
    full = B.bounds(box, want=want, max_boxes=MAX_BOXES)
    lo_s, hi_s = full.lo, full.hi
    t = float(lo_s + q * (hi_s - lo_s)) if math.isfinite(hi_s - lo_s) else 0.0
    fast = B.bounds(box, want=want, max_boxes=MAX_BOXES, beat=t)
    if want == "lo":
        assert (fast.lo > t) == (full.lo > t), (t, fast, full)
        assert fast.lo <= full.lo
    else:
        assert (fast.hi < t) == (full.hi < t), (t, fast, full)
        assert fast.hi >= full.hi
    assert fast.boxes <= full.boxes
    names = list(box)
    lo = np.array([box[k][0] for k in names])
    hi = np.array([box[k][1] for k in names])
    v = B.values(lo + rng.random((500, len(names))) * (hi - lo))
    assert fast.lo <= v.min() + 1e-9 and fast.hi >= v.max() - 1e-9


def test_beat_stops_at_once_when_the_question_is_easy() -> None:
    """A threshold far below the minimum (or a centre far above it) is settled by the first
    pass; the full refinement needs more boxes."""
    x, y = ca.SX.sym("x"), ca.SX.sym("y")
    e = ca.sin(3 * x) * ca.cos(2 * y) + x * y
    box = {"x": (-1.0, 1.0), "y": (-1.0, 1.0)}
    B = Bounder(e)
    full = B.bounds(box, want="lo")
    assert full.boxes > 3 and not full.decided
    for t in (-10.0, 5.0):  # proved (the whole box's bound is above -10); refuted (f(0, 0) = 0 <= 5)
        r = B.bounds(box, want="lo", beat=t)
        assert r.decided and r.boxes <= 3 and (r.lo > t) == (full.lo > t)
    with pytest.raises(SparValueError):
        B.bounds(box, beat=0.0)  # want 'both' has no single question
    with pytest.raises(SparValueError):
        B.bounds(box, want="hi", beat=math.inf)


@pytest.mark.parametrize("seed", range(8))
def test_a_search_stopped_on_beat_goes_on_to_the_full_answer(seed: int) -> None:
    """cached_bounds keeps a search that stopped on ``beat`` and resumes it: the full refinement
    asked afterwards is, field for field, the one made from the start (the same boxes in the
    same order), whatever questions came before it."""
    rng = np.random.default_rng(700 + seed)
    reg = Registry()
    e = random_chain(rng, 1 + seed % 4, reg)
    box = reg.box(e)
    want = "lo" if seed % 2 else "hi"
    fresh = Bounder(e).bounds(box, want=want)
    end = fresh.lo if want == "lo" else fresh.hi
    memo = Memo()
    for t in (end - 10.0, end + 10.0, end - 1e-3, end + 1e-3):  # proved, refuted, and two close calls
        r = cached_bounds(e, box, memo, want=want, beat=t)
        assert ((r.lo > t) if want == "lo" else (r.hi < t)) == ((fresh.lo > t) if want == "lo" else (fresh.hi < t))
    assert replace(cached_bounds(e, box, memo, want=want), decided=False) == fresh
    assert cached_bounds(e, box, memo, want=want, beat=end - 20.0).boxes == fresh.boxes  # answered by the full one
