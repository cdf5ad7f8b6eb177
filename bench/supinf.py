"""SUP/INF tightness and speed: spar-py's bounds against plain interval evaluation and the true range.

Run from the project root: ``.venv/bin/python -m bench.supinf [--per-length 10] [--seed 0]``;
``--uniform N`` only the table by depth at +-0.1, ``--model N`` only the gradient model's
remainder by depth (why deep products need many boxes), ``--depths 6,8`` to choose depths,
``--kinks R`` only hopeless_uncertainty.yaml's own questions with ``Bounder(clarke_fabs=...)`` off
and on (R interleaved rounds).

For each expression it reports, as medians over a group of expressions:

- ``ours``: ``Bounder.bounds`` (both ends, refined to the default tolerance 1e-3 of the
  range width) — its excess over the true range as a fraction of the true width, and
  its time; ``compile`` is the one-off cost of ``Bounder(expr)`` (CasADi Function,
  gradient, instruction lists); ``one-sided`` is what ``uncertainty.evaluate`` spends
  on one constraint (INF or SUP only), compile included;
- ``plain``: one pass of interval arithmetic over the box (SUP/INF as the paper
  describes it: bounds of subexpressions combined by interval rules);
- ``true``: the extremum found by 20 000 samples plus IPOPT (bundled with CasADi)
  started from the best samples and the box centre (and our best points' values).

Groups: the paper's cell (the first pickup's four inequalities, Sec. 6's expression among
them; the assemble inequality with and without the dense range scans; the paper's printed
Sec. 6 expression, and the same with its constant's sign fixed, which gives the paper's
3.2793), plan-like expressions (random pickup / putdown / scan / squeeze plans of length
1..8 on the paper's cell, then a pickup or assemble inequality), and random products of
homogeneous transforms of plan length 1..8 (small angles, as uncertainty is), and products
of depth 8 with every variable at +-0.1 (in, rad): tolerance reached, box-cap hits, a repeated
question answered from a cell's memo, the compiled interval program (``Bounder(compiled=True)``).
"""
from __future__ import annotations

import argparse
import math
import statistics
import time
from pathlib import Path
from typing import Callable

import casadi as ca
import numpy as np

from spar_py.core import geometry
from spar_py.kb import load_problem
from spar_py.core.model import Cell
from spar_py.phase2.supinf import Bounder
from spar_py.phase2.symbolic import Chain, ChainExpr, ErrorFactor, Registry, apply, inv
from spar_py.phase2.uncertainty import (
    WorldState,
    assemble_constraints,
    dense_range_scan,
    evaluate,
    initial_world,
    pickup,
    pickup_constraints,
    putdown,
    squeeze,
)

ROOT = Path(__file__).resolve().parent.parent
CELL = ROOT / "kb" / "problems" / "peg_in_block.yaml"
IPOPT = {"ipopt.print_level": 0, "print_time": 0, "ipopt.sb": "yes", "ipopt.max_iter": 300}


# ------------------------------------------------------------------ measuring one expression


def true_range(B: Bounder, lo: np.ndarray, hi: np.ndarray, rng: np.random.Generator,
               starts: list[np.ndarray]) -> tuple[float, float]:
    """The best min and max found by dense sampling and IPOPT (inner bounds of the true range)."""
    P = np.vstack([rng.uniform(lo, hi, (20000, lo.size)), np.where(rng.random((2000, lo.size)) < 0.5, lo, hi),
                   *[s[None, :] for s in starts]])
    v = B.values(P)
    best = [float(np.nanmin(v)), float(np.nanmax(v))]
    x = ca.vertcat(*ca.symvar(B.expr))
    for k, sign in ((0, 1.0), (1, -1.0)):
        solver = ca.nlpsol("s", "ipopt", {"x": x, "f": sign * B.expr}, IPOPT)
        for x0 in (P[np.nanargmin(sign * v)], 0.5 * (lo + hi), *starts):
            xs = np.clip(np.asarray(solver(x0=x0, lbx=lo, ubx=hi)["x"]).ravel(), lo, hi)
            fx = float(B.values(xs[None, :])[0])
            best[k] = min(best[k], fx) if k == 0 else max(best[k], fx)
    return best[0], best[1]


def median_time(fn, repeats: int) -> float:
    ts = []
    for _ in range(repeats):
        t = time.perf_counter()
        fn()
        ts.append(time.perf_counter() - t)
    return statistics.median(ts)


def measure(expr: ca.SX, box: dict, rng: np.random.Generator, repeats: int = 5) -> dict:
    """Tightness (fractions of the true width) and times (ms) of ours and plain on one expression."""
    t = time.perf_counter()
    B = Bounder(expr)
    t_compile = time.perf_counter() - t
    lo = np.array([box[n][0] for n in B.names])
    hi = np.array([box[n][1] for n in B.names])
    r = B.bounds(box)
    t_ours = median_time(lambda: B.bounds(box), repeats)
    t_one = median_time(lambda: Bounder(expr).bounds(box, want="lo"), repeats)
    plain = B.interval(box)
    t_plain = median_time(lambda: B.interval(box), repeats)
    tmin, tmax = true_range(B, lo, hi, rng, [])
    tmin, tmax = min(tmin, r.lo_found), max(tmax, r.hi_found)  # values attained at our best points
    w = max(tmax - tmin, 1e-300)
    sound = r.lo <= tmin + 1e-12 * (1 + abs(tmin)) and tmax - 1e-12 * (1 + abs(tmax)) <= r.hi
    return {
        "n_vars": len(B.names),
        "ours": max(tmin - r.lo, r.hi - tmax) / w,
        "plain": max(tmin - plain[0], plain[1] - tmax) / w,
        "reached": r.tolerance_reached,
        "sound": sound,
        "lo": r.lo, "hi": r.hi, "true": (tmin, tmax), "boxes": r.boxes,
        "t_ours": t_ours * 1e3, "t_one": t_one * 1e3, "t_compile": t_compile * 1e3, "t_plain": t_plain * 1e3,
    }


# ------------------------------------------------------------------ expressions


def paper_cell_expressions(cell: Cell) -> list[tuple[str, ca.SX, Registry]]:
    """The first pickup's four inequalities (Sec. 6), the assemble inequality, Sec. 6 as printed."""
    out: list[tuple[str, ca.SX, Registry]] = []
    w = initial_world(cell)
    peg = cell.objects["peg"]
    g = peg.grasps["p1G1"]
    for c in pickup_constraints(w, "peg", g.T, g.width, cell.finger_separation, w.manipulator_error()):
        out.append((f"pickup(peg) {c.name}", c.expr, w.registry))
    for scans in (False, True):
        ws, (c,) = peg_in_block(cell, scans)
        out.append((f"assemble{' after scans' if scans else ''}", c.expr, ws.registry))
    # Sec. 6's expression as printed: INF -0.7207; with +2.0 for its -2.0 it gives the paper's 3.2793
    for const, name in ((-2.0, "Sec. 6 as printed"), (2.0, "Sec. 6 with +2.0")):
        reg = Registry()
        deg = math.pi / 180
        tg = reg.new("thetagr", -0.001 * deg, 0.001 * deg)
        dxg, dyg = reg.new("dxgr", -0.001, 0.001), reg.new("dygr", -0.001, 0.001)
        to = reg.new("theta_o", -5.5 * deg, 5.5 * deg)
        dxo, dyo = reg.new("dx_o", -0.11, 0.11), reg.new("dy_o", -0.11, 0.11)
        c, s = ca.cos, ca.sin
        printed = (const + 3.0 * c(tg) * c(to) + c(tg) * dxo + s(tg) + s(tg) * dxg - c(tg) * s(to)
                   - 1.5 * c(tg) - 3.0 * s(tg) * s(to) - c(to) * s(tg) - s(tg) * dyo - c(tg) * dyg)
        out.append((name, printed, reg))
    return out


def peg_in_block(cell: Cell, scans: bool) -> tuple[WorldState, list]:
    """The paper's plan: turn the block hole up, (scan both,) pick up the peg, assemble."""
    peg, block = cell.objects["peg"], cell.objects["block"]
    w = initial_world(cell)
    gb = next(g for g in block.grasps.values() if abs(g.T[2, 2]) < 1e-9)
    up = next(p for p in block.poses.values() if np.allclose(p.R, np.eye(3)))
    w = putdown(pickup(w, "block", gb.T, w.manipulator_error()), "block", geometry.trans(30, 0, up.height))
    if scans:
        leaves = cell.sensors["dense_range_scan"].leaves
        w = dense_range_scan(dense_range_scan(w, "block", leaves), "peg", leaves)
    w = pickup(w, "peg", peg.grasps["p1G1"].T, w.manipulator_error())
    return w, assemble_constraints(w, "peg", "block", cell.transforms["trans_1"], peg.features[0], block.features[0],
                                   axis=cell.vectors["vec_1"])


def plan_like(cell: Cell, rng: np.random.Generator, length: int) -> tuple[ca.SX, Registry]:
    """A random plan of ``length`` actions on the paper's cell, then a pickup or assemble inequality."""
    w = initial_world(cell)
    leaves = cell.sensors["dense_range_scan"].leaves
    grasps = {o: list(m.grasps.values()) for o, m in cell.objects.items()}
    held = None
    for _ in range(length - 1):
        if held is None:
            obj = str(rng.choice(sorted(cell.objects)))
            kind = rng.choice(["pickup", "pickup", "squeeze", "scan"])
            g = grasps[obj][int(rng.integers(len(grasps[obj])))]
            if kind == "pickup":
                w, held = pickup(w, obj, g.T, w.manipulator_error()), obj
            elif kind == "squeeze":
                w = squeeze(w, obj, g.T, w.manipulator_error())
            else:
                w = dense_range_scan(w, obj, leaves)
        else:
            pose = cell.objects[held].poses[str(rng.choice(sorted(cell.objects[held].poses)))]
            T = geometry.rotz(rng.uniform(-np.pi, np.pi)) @ np.eye(4)
            T[:3, :3] = T[:3, :3] @ pose.R
            T[:3, 3] = [rng.uniform(20, 35), rng.uniform(-10, 10), pose.height]
            w, held = putdown(w, held, T), None
    peg, block = cell.objects["peg"], cell.objects["block"]
    if held == "peg":
        (c,) = assemble_constraints(w, "peg", "block", cell.transforms["trans_1"], peg.features[0], block.features[0],
                                    axis=cell.vectors["vec_1"])
        return c.expr, w.registry
    if held is not None:
        w = putdown(w, held, w.obj(held).pose)
    obj = str(rng.choice(sorted(cell.objects)))
    g = grasps[obj][int(rng.integers(len(grasps[obj])))]
    cs = pickup_constraints(w, obj, g.T, g.width, cell.finger_separation, w.manipulator_error())
    return cs[int(rng.integers(4))].expr, w.registry


def _rigid(rng: np.random.Generator, scale: float) -> np.ndarray:
    a = rng.uniform(-np.pi, np.pi, 3)
    T = geometry.rotz(a[0]) @ geometry.roty(a[1]) @ geometry.rotx(a[2])
    T[:3, 3] = rng.uniform(-scale, scale, 3)
    return T


def _chain(rng: np.random.Generator, length: int,
           step_bounds: Callable[[], Callable[[], tuple[float, float]]]) -> tuple[ChainExpr, Registry]:
    """A product of ``length`` error transforms (trans + rotz, each variable bounded by the
    ``b()`` of its step: ``b = step_bounds()`` once per step) between random rigid transforms;
    then a translation component, a coordinate of T^-1 p or a squared distance (as
    tests/test_supinf.py builds them), kept as a chain expression (its ``expr`` is the SX)."""
    e, reg, _ = _chain_and_sx(rng, length, step_bounds)
    return e, reg


def _chain_and_sx(rng: np.random.Generator, length: int,
                  step_bounds: Callable[[], Callable[[], tuple[float, float]]],
                  angle: float | None = None) -> tuple[ChainExpr, Registry, ca.SX]:
    """:func:`_chain`, and the same function's SX as this bench built it before chains (and as
    a caller composing SX matrices builds it): for T^-1 p the inverse of the whole product
    (``inv`` of its SX), not the product of the factors' inverses. ``angle``: every angle
    at +-``angle`` instead of its step's bounds."""
    reg = Registry()
    T = Chain.of(_rigid(rng, 30.0))
    for _ in range(length):
        b = step_bounds()
        E = ErrorFactor(reg.new("dx", *b()), reg.new("dy", *b()), reg.new("dz", *b()),
                        reg.new("th", *((-angle, angle) if angle is not None else b())))
        if rng.random() < 0.3:
            E = E.inverted()
        T = Chain.of(T, E, _rigid(rng, 5.0)) if rng.random() < 0.7 else Chain.of(E, T, _rigid(rng, 5.0))
    kind, p = int(rng.integers(3)), rng.uniform(-3, 3, 3)
    if kind == 0:
        e = ChainExpr.coordinate(T, np.zeros(3), int(rng.integers(3)))
        return e, reg, e.expr
    if kind == 1:
        axis = int(rng.integers(3))
        return ChainExpr.coordinate(T.inverse(), p, axis), reg, apply(inv(T.matrix()), p)[axis]
    e = ChainExpr.sqdist(T, p, rng.uniform(-30, 30, 3))
    return e, reg, e.expr


def random_chain(rng: np.random.Generator, length: int) -> tuple[ChainExpr, Registry]:
    """:func:`_chain` with each step's variables in [-u, 0] x [0, u] draws, ``w`` log-uniform in
    [1e-3, 0.2] per step (up to +-0.2 in / rad)."""
    def step() -> Callable[[], tuple[float, float]]:
        w = 10 ** rng.uniform(-3, -0.7)
        return lambda: (float(rng.uniform(-w, 0)), float(rng.uniform(0, w)))

    return _chain(rng, length, step)


def uniform_chain(rng: np.random.Generator, length: int, half: float = 0.1) -> tuple[ChainExpr, Registry]:
    """As :func:`random_chain`, but every error variable bounded by +-``half`` (in and rad):
    the issue's "products of depth 8 at +-0.1 rad"."""
    return _chain(rng, length, lambda: lambda: (-half, half))


def uniform_chain_and_sx(rng: np.random.Generator, length: int, half: float = 0.1,
                         angle: float | None = None) -> tuple[ChainExpr, Registry, ca.SX]:
    """:func:`uniform_chain` with the SX built as before chains (:func:`_chain_and_sx`);
    ``angle``: the angles at +-``angle`` instead of +-``half``."""
    return _chain_and_sx(rng, length, lambda: lambda: (-half, half), angle)


def deep(rng: np.random.Generator, count: int, length: int = 8, half: float = 0.1, repeats: int = 3,
         angle: float | None = None) -> dict:
    """Products of ``length`` error transforms at +-``half`` (the angles at +-``angle`` if
    given): how many reach the tolerance,
    how many hit the box cap, boxes and times (ms, medians), and a repeated question
    answered from a cell's memo (``t_cached``: supinf.cached_bounds, a hit) and
    ``Bounder(compiled=True)`` (``t_compiled`` warm, ``t_compiled_first`` with building its
    CasADi program), beside ``t_ours`` and ``t_plain`` from the same run."""
    from spar_py.core.memo import Memo
    from spar_py.phase2.supinf import MAX_BOXES, cached_bounds

    ms, boxes, capped, cached, comp, first = [], [], 0, [], [], []
    peers: dict[str, dict[str, list]] = {p: {"gap": [], "capped": [], "t": [], "reached": []} for p in ("sx", "old")}

    def peer(name: str, expr: ca.SX, box: dict, true: tuple[float, float]) -> tuple[float, float]:
        """The search on ``expr`` alone; its figures into ``peers[name]``; the true range widened
        by the values it attained."""
        B = Bounder(expr)
        r = B.bounds(box)
        got = peers[name]
        got["t"].append(median_time(lambda: B.bounds(box), 1) * 1e3)
        tmin, tmax = min(true[0], r.lo_found), max(true[1], r.hi_found)
        got["gap"].append(max(tmin - r.lo, r.hi - tmax) / max(tmax - tmin, 1e-300))
        got["capped"].append(r.boxes >= MAX_BOXES)
        got["reached"].append(r.tolerance_reached)
        return tmin, tmax

    for _ in range(count):
        e, reg, old_sx = uniform_chain_and_sx(rng, length, half, angle)
        box = reg.box(e)
        m = measure(e, box, rng, repeats=repeats)
        ms.append(m)
        boxes.append(m["boxes"])
        capped += m["boxes"] >= MAX_BOXES
        # the peers: the same search on the chain's SX alone, without its point sets, and on
        # the SX a caller composing SX matrices builds (T^-1 as the product's inverse)
        peer("old", old_sx, box, peer("sx", e.expr, box, m["true"]))
        memo = Memo()
        cached_bounds(e, box, memo)
        cached.append(median_time(lambda: cached_bounds(e, box, memo), repeats) * 1e3)
        Bc = Bounder(e, compiled=True)
        t = time.perf_counter()
        Bc.bounds(box)  # builds the compiled program on its first small batch
        first.append((time.perf_counter() - t) * 1e3)
        comp.append(median_time(lambda: Bc.bounds(box), repeats) * 1e3)
    out = summarise(f"depth {length} at +-{half:g}" + ("" if angle is None else f", angles +-{angle:g}"), ms)
    out.update({"length": length, "half": half, "boxes_median": statistics.median(boxes),
                "boxes_max": max(boxes), "capped": capped, "max_boxes": MAX_BOXES,
                "t_cached": statistics.median(cached), "t_compiled": statistics.median(comp),
                "t_compiled_first": statistics.median(first), "unsound": sum(not m["sound"] for m in ms),
                **{k: v for p, got in peers.items() for k, v in (
                    (f"{p}_ours", statistics.median(got["gap"])), (f"{p}_worst", max(got["gap"])),
                    (f"{p}_capped", sum(got["capped"])), (f"{p}_reached", sum(got["reached"])),
                    (f"t_{p}", statistics.median(got["t"])))}})
    return out


def uniform_table(rng: np.random.Generator, count: int, lengths: tuple[int, ...] = tuple(range(1, 9)),
                  half: float = 0.1, repeats: int = 1, progress=None) -> list[dict]:
    """Products of 1..8 error transforms with every variable at +-``half`` (in, rad): per depth,
    medians over ``count`` expressions of ours/w and plain/w (excess over the sampled true range
    as a fraction of its width), the times (ms) of ours (warm bounder, both ends) and plain,
    boxes evaluated, and how many reached the tolerance / hit the box cap, all from one run."""
    from spar_py.phase2.supinf import MAX_BOXES

    say = progress or (lambda line: None)
    say(f"{'depth':<8}{'vars':>5}{'ours/w':>10}{'plain/w':>10}{'reached':>9}{'capped':>8}"
        f"{'ours ms':>10}{'plain ms':>10}{'compile':>9}{'boxes':>8}")
    rows = []
    for n in lengths:
        ms = [measure(*_box(uniform_chain(rng, n, half)), rng, repeats=repeats) for _ in range(count)]
        r = summarise(f"depth {n}", ms)
        r.update({"length": n, "boxes": statistics.median(m["boxes"] for m in ms),
                  "capped": sum(m["boxes"] >= MAX_BOXES for m in ms)})
        rows.append(r)
        say(f"{n:<8}{r['n_vars']:>5.0f}{r['ours']:>10.1e}{r['plain']:>10.1e}{r['reached']:>5}/{r['count']:<3}"
            f"{r['capped']:>8}{r['t_ours']:>10.2f}{r['t_plain']:>10.2f}{r['t_compile']:>9.1f}{r['boxes']:>8.0f}")
    return rows


def _box(er: tuple[ChainExpr, Registry]) -> tuple[ChainExpr, dict]:
    return er[0], er[1].box(er[0])


def model_table(rng: np.random.Generator, count: int, lengths: tuple[int, ...] = tuple(range(1, 9)),
                half: float = 0.1, fracs: tuple[float, ...] = (1.0, 0.5, 0.25, 0.1), progress=None) -> list[dict]:
    """Why deep products need many boxes: the gradient model's remainder (taylor.GradientModel,
    ``sum_i rd_i rho_i``: the term of its lower bound that no curvature can recover) on the
    box of a product of ``length`` error transforms at +-``half`` and on centred sub-boxes
    of ``fracs`` of its size, as fractions of the sampled range width (medians over
    ``count`` expressions); ``radius``: the share of rho that is the affine forms' radius
    row (the lumped quadratic terms of products), the rest being nonlinear operations'
    noise symbols. No search is run."""
    from spar_py.phase2.taylor import GradientModel

    say = progress or (lambda line: None)
    say(f"{'depth':<8}{'vars':>5}" + "".join(f"{'rem/w @' + format(f, 'g'):>12}" for f in fracs) + f"{'radius':>9}")
    rows = []
    for n in lengths:
        rem: dict[float, list[float]] = {f: [] for f in fracs}
        share, nv = [], []
        for _ in range(count):
            e, box = _box(uniform_chain(rng, n, half))
            B = Bounder(e)
            lo = np.array([[box[v][0] for v in B.names]])
            hi = np.array([[box[v][1] for v in B.names]])
            v = B.values(rng.uniform(lo[0], hi[0], (20000, lo.size)))
            w = max(float(np.nanmax(v) - np.nanmin(v)), 1e-300)
            AG = B.affine_gradient
            nv.append(lo.size)
            for f in fracs:
                c = 0.5 * (lo + hi)
                L, H = c - f * (c - lo), c + f * (hi - c)
                F = AG(L, H)
                M = GradientModel.from_affine(F, AG.K, L, H, np.array([False]))
                rem[f].append(float((M.rd * M.rho).sum()) / w)
                if f == fracs[0]:
                    G = F[:, 1:, 0]
                    share.append(float(G[-1].sum() / (np.abs(G[AG.K + 1:-1]).sum() + G[-1].sum())))
        r = {"length": n, "n_vars": statistics.median(nv), "radius_share": statistics.median(share),
             **{f"rem_{f:g}": statistics.median(rem[f]) for f in fracs}}
        rows.append(r)
        say(f"{n:<8}{r['n_vars']:>5.0f}" + "".join(f"{r[f'rem_{f:g}']:>12.2e}" for f in fracs)
            + f"{r['radius_share']:>9.3f}")
    return rows


# ------------------------------------------------------------------ the planner's own questions


HOPELESS = ROOT / "kb" / "problems" / "hopeless_uncertainty.yaml"


def planner_questions(problem: Path = HOPELESS) -> list[tuple[ca.SX, dict, dict]]:
    """The distinct SUP/INF questions (expression, box, options) ``spar plan problem`` asks
    (recorded around ``uncertainty.cached_bounds`` during one in-process run; its output
    is discarded), each with its variables renamed as the planner's cache keys them."""
    import contextlib
    import io

    from spar_py.app import cli
    from spar_py.phase2 import uncertainty
    from spar_py.phase2.supinf import canonical

    asked: list[tuple[ca.SX, dict, dict]] = []
    real = uncertainty.cached_bounds

    def record(expr, box, memo=None, **options):
        asked.append((expr, dict(box), dict(options)))
        return real(expr, box, memo, **options)

    uncertainty.cached_bounds = record
    try:
        with contextlib.redirect_stdout(io.StringIO()), contextlib.suppress(SystemExit):
            cli.main(["plan", str(problem)])
    finally:
        uncertainty.cached_bounds = real
    out, seen = [], set()
    for expr, box, options in asked:
        canon, names = canonical(expr)
        cbox = {f"v{i}": tuple(box[n]) for i, n in enumerate(names)}
        key = (canon.serialize(), tuple(sorted(cbox.items())), tuple(sorted(options.items())))
        if key not in seen:
            seen.add(key)
            out.append((canon, cbox, options))
    return out


def kinks_table(rounds: int = 3, problem: Path = HOPELESS, progress=None) -> dict:
    """``problem``'s distinct SUP/INF questions answered cold (Bounder built, then bounded),
    with ``clarke_fabs`` off (the search before the Clarke-gradient change: boxes
    holding a kink of fabs are only bisected) and on, interleaved over ``rounds``: total
    time (ms, median over rounds), boxes, tolerance reached, and the largest change of a
    bound the planner reads (INF for '>' , SUP for '<')."""
    say = progress or (lambda line: None)
    qs = planner_questions(problem)
    times: dict[bool, list[float]] = {False: [], True: []}
    res: dict[bool, list] = {}
    for _ in range(rounds):
        for flag in (False, True):
            t = time.perf_counter()
            res[flag] = [Bounder(e, clarke_fabs=flag).bounds(box, **opt) for e, box, opt in qs]
            times[flag].append((time.perf_counter() - t) * 1e3)
    read = [(r.lo if opt.get("want") == "lo" else r.hi) for r, (_, _, opt) in zip(res[True], qs)]
    old = [(r.lo if opt.get("want") == "lo" else r.hi) for r, (_, _, opt) in zip(res[False], qs)]
    out = {"questions": len(qs), "problem": problem.name,
           **{f"{k}_{'new' if f else 'old'}": v for f in (False, True) for k, v in
              (("ms", statistics.median(times[f])), ("boxes", sum(r.boxes for r in res[f])),
               ("reached", sum(r.tolerance_reached for r in res[f])))},
           "max_change": max(abs(a - b) for a, b in zip(read, old)),
           "changed": sum(a != b for a, b in zip(read, old))}
    say(f"{problem.name}: {out['questions']} distinct SUP/INF questions, cold (compile + bound), "
        f"median of {rounds} interleaved rounds")
    say(f"{'':<22}{'ms':>8}{'boxes':>8}{'reached':>9}")
    for f, name in ((False, "clarke_fabs off (old)"), (True, "clarke_fabs on")):
        tag = "new" if f else "old"
        say(f"{name:<22}{out['ms_' + tag]:>8.0f}{out['boxes_' + tag]:>8}{out['reached_' + tag]:>5}/{out['questions']}")
    say(f"bounds read by the planner changed: {out['changed']}, by at most {out['max_change']:.2e}")
    return out


# ------------------------------------------------------------------ report


HEADER = (f"{'expression':<26}{'vars':>5}{'ours/w':>10}{'plain/w':>10}{'reached':>9}{'ours ms':>9}"
          f"{'1-side ms':>10}{'compile':>9}{'plain ms':>9}")
#: The figures of one group, each a median over its expressions (``reached``: a count).
SUMMARY_KEYS = ("n_vars", "ours", "plain", "t_ours", "t_one", "t_compile", "t_plain")
GROUPS = ("plan_like", "random")


def summarise(name: str, ms: list[dict]) -> dict:
    """One table row: medians of ``ms``'s figures, how many reached the tolerance, all sound."""
    out: dict = {"name": name, "count": len(ms)}
    out.update({k: statistics.median(m[k] for m in ms) for k in SUMMARY_KEYS})
    out["reached"] = sum(bool(m["reached"]) for m in ms)
    out["sound"] = all(m["sound"] for m in ms)
    out["worst"] = max(m["ours"] for m in ms)
    return out


def row(name: str, ms: list[dict]) -> str:
    r = summarise(name, ms)
    return (f"{name:<26}{r['n_vars']:>5.0f}{r['ours']:>10.1e}{r['plain']:>10.1e}"
            f"{r['reached']:>5}/{r['count']:<3}{r['t_ours']:>9.2f}{r['t_one']:>10.2f}"
            f"{r['t_compile']:>9.2f}{r['t_plain']:>9.2f}")


def run(per_length: int = 6, seed: int = 0, lengths: tuple[int, ...] = tuple(range(1, 9)),
        groups: tuple[str, ...] = GROUPS, repeats: int = 5,
        progress=None, deep_count: int = 12) -> dict:
    """All the SUP/INF figures as data.

    Keys: ``paper`` (one :func:`measure` dict per expression of the paper's cell, with
    its ``name``), ``plan_like`` and ``random`` (lists of :func:`summarise` rows, one per
    plan length in ``lengths`` over ``per_length`` expressions; only the ``groups``
    asked for), ``evaluate_ms`` (``uncertainty.evaluate`` per constraint of the first
    pickup, compile included: the planner's own cost of one verdict) and ``unsound`` (how
    many bounds fell inside the sampled/optimised range: must be 0), ``deep`` (:func:`deep`
    over ``deep_count`` products of depth 8 at +-0.1; 0 skips it). ``progress``, if
    given, is called with each printable table line as it is measured.
    """
    say = progress or (lambda line: None)
    rng = np.random.default_rng(seed)
    cell = load_problem(CELL)
    out: dict = {"per_length": per_length, "seed": seed, "lengths": list(lengths),
                 "paper": [], "unsound": 0}
    say(HEADER)
    say("-- the paper's cell (Table 2 bounds; W_p = 3, W_m = 4)")
    for name, e, reg in paper_cell_expressions(cell):
        m = measure(e, reg.box(e), rng, repeats=repeats)
        out["unsound"] += not m["sound"]
        out["paper"].append({"name": name, **m})
        say(row(name, [m]) + f"   INF {m['lo']:.4f} SUP {m['hi']:.4f}")
    makers = {"plan_like": ("-- plan-like (paper's cell)", lambda n: plan_like(cell, rng, n)),
              "random": ("-- random HTM products", lambda n: random_chain(rng, n))}
    for group in groups:
        title, make = makers[group]
        say(title)
        out[group] = []
        for n in lengths:
            ms = []
            for _ in range(per_length):
                e, reg = make(n)
                ms.append(measure(e, reg.box(e), rng, repeats=min(3, repeats)))
            out["unsound"] += sum(not m["sound"] for m in ms)
            out[group].append({**summarise(f"plan length {n}", ms), "length": n})
            say(row(f"plan length {n}", ms))
    if deep_count:
        say(f"-- products of depth 8 at +-0.1 (in, rad), {deep_count} expressions")
        d = out["deep"] = deep(rng, deep_count, repeats=min(3, repeats))
        # beyond the target: wide angles, where the search alone is lost
        out["deep_wide"] = deep(rng, max(2, deep_count // 3), repeats=1, angle=1.0)
        out["unsound"] += out["deep_wide"]["unsound"]
        out["unsound"] += d["unsound"]
        say(f"{d['name']:<26}{d['n_vars']:>5.0f}{d['ours']:>10.1e}{d['plain']:>10.1e}"
            f"{d['reached']:>5}/{d['count']:<3}{d['t_ours']:>9.2f}{d['t_one']:>10.2f}"
            f"{d['t_compile']:>9.2f}{d['t_plain']:>9.2f}   boxes median {d['boxes_median']:.0f} "
            f"max {d['boxes_max']} (cap {d['max_boxes']}, hit {d['capped']}); cached {d['t_cached']:.3f} ms; "
            f"compiled {d['t_compiled']:.1f} ms (first {d['t_compiled_first']:.0f} ms)")
    # the planner's own use: one verdict per constraint (evaluate = compile + one-sided bound)
    w = initial_world(cell)
    g = cell.objects["peg"].grasps["p1G1"]
    cs = pickup_constraints(w, "peg", g.T, g.width, cell.finger_separation, w.manipulator_error())
    out["evaluate_ms"] = median_time(lambda: [evaluate(c, w.registry) for c in cs], repeats) * 1e3 / 4
    return out


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(prog="python -m bench.supinf", description=__doc__.split("\n")[0])
    ap.add_argument("--per-length", type=int, default=6, help="expressions per plan length (default 6)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--uniform", type=int, default=0, metavar="N",
                    help="only the table by depth 1-8 at +-0.1 (N expressions per depth)")
    ap.add_argument("--model", type=int, default=0, metavar="N",
                    help="only the gradient model's remainder by depth 1-8 at +-0.1 (N expressions per depth)")
    ap.add_argument("--kinks", type=int, default=0, metavar="R",
                    help="only hopeless_uncertainty.yaml's SUP/INF questions, clarke_fabs off vs on (R rounds)")
    ap.add_argument("--depths", type=str, default="1-8", help="with --uniform or --model: e.g. 1-8 or 6,8")
    args = ap.parse_args(argv)
    a, _, b = args.depths.partition("-")
    lengths = tuple(range(int(a), int(b) + 1)) if b else tuple(int(v) for v in args.depths.split(","))
    if args.kinks:
        kinks_table(args.kinks, progress=print)
        return
    if args.model:
        model_table(np.random.default_rng(args.seed), args.model, lengths=lengths, progress=print)
        return
    if args.uniform:
        rows = uniform_table(np.random.default_rng(args.seed), args.uniform, lengths=lengths, progress=print)
        print(f"unsound bounds: {sum(not r['sound'] for r in rows)} depths with any")
        return
    print("tightness: max excess of a bound over the true range, as a fraction of the true width "
          "(medians); times in ms (medians)\n")
    r = run(args.per_length, args.seed, progress=print)
    print(f"\nuncertainty.evaluate, the first pickup's 4 constraints: {r['evaluate_ms']:.2f} ms per constraint")
    print(f"unsound bounds: {r['unsound']}")


if __name__ == "__main__":
    main()
