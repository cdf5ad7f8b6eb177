"""Issue 35, item 1: each step of a plan carries every part's position uncertainty as phase 2
propagated it (``position_bounds``), and the viewer draws those bounds.

The bounds are checked against the error itself, sampled: the error variables drawn from their
boxes (corners and uniform draws), each part's possible pose built here from the paper's
Eqs. 2 and 4 with numpy, and its origin's displacement and its turn about world z (the rotation
vector's z component, read off the rotation matrix by scipy) measured; no sample may fall
outside the bounds SUP/INF gave."""
from __future__ import annotations

import itertools
import json
import math

import numpy as np
import pytest

from spar_py import Planner
from spar_py.core.model import Bounds
from spar_py.phase2 import instance as phase2
from spar_py.phase2.positions import BOUNDS_LIMIT
from spar_py.phase2 import uncertainty as ur
from spar_py.world.collision import CellCache
from spar_py.planning.planner import Outcome, Plan

from paths import ROOT

PROBLEMS = ROOT / "kb" / "problems"
#: Cells whose plans sense (large_uncertainty), squeeze (squeeze), turn a part over and insert.
CELLS = ("large_uncertainty", "squeeze", "peg_in_block", "ur5e_peg_in_block")
KEYS = ("dx", "dy", "dz", "dtheta_deg")


def _typed(doc: dict) -> Plan:
    """The typed Plan of a plan JSON document, or of a test's partial one (the pictures take a Plan and
    read its problem, outcome, partial plan and instance)."""
    return Plan(problem=doc.get("problem", ""), outcome=Outcome(doc["outcome"]), partial=doc.get("partial"),
                instance=doc.get("instance"))


@pytest.fixture(scope="module")
def plans(planner: Planner) -> dict:
    """Each cell of CELLS with its plan, and its plan's JSON as written and read back."""
    out = {}
    for name in CELLS:
        cell = planner.load_problem(PROBLEMS / f"{name}.yaml")
        plan = planner.plan(cell)
        assert plan.ok, name
        out[name] = (cell, plan, json.loads(plan.dumps()))
    return out


def test_a_sensing_step_leaves_no_more_than_the_sensors_bounds(plans) -> None:
    cell, plan, doc = plans["large_uncertainty"]
    leaves = cell.sensors["dense_range_scan"].leaves
    sensed = [s for s in doc["instance"]["steps"] if s["kind"] == "sensing"]
    assert sensed
    for s in sensed:
        b = s["position_bounds"][s["object"]]
        for k in ("dx", "dy", "dz"):
            lo, hi = getattr(leaves, k)
            assert lo <= b[k][0] <= b[k][1] <= hi, (s["id"], k, b[k], (lo, hi))
        lo, hi = (math.degrees(v) for v in leaves.dtheta)
        slack = 4 * math.ulp(hi)  # radians to degrees and back, each rounded
        assert lo - slack <= b["dtheta_deg"][0] <= b["dtheta_deg"][1] <= hi + slack
        # and smaller than what the part had before it was scanned (the cell's declared bounds)
        declared = cell.object_bounds[s["object"]]
        assert b["dx"][1] - b["dx"][0] < declared.dx[1] - declared.dx[0]
    # the typed Step has them as Bounds (dtheta in radians)
    typed = next(st for st in plan.steps if st.kind == "sensing")
    got = typed.position_bounds[typed.object]
    assert isinstance(got, Bounds) and got.dx == leaves.dx and got.dtheta == pytest.approx(leaves.dtheta, rel=1e-14)


def test_every_step_has_every_parts_bounds(plans) -> None:
    for name, (_, plan, doc) in plans.items():
        for s, st in zip(doc["instance"]["steps"], plan.steps):
            assert set(s["position_bounds"]) == set(s["poses"]), (name, s["id"])
            for b in s["position_bounds"].values():
                assert all(b[k][0] <= b[k][1] for k in ("dx", "dy", "dz", "dtheta_deg"))
            assert set(st.position_bounds or {}) == set(s["poses"])


def test_held_parts_have_the_grasps_bounds(plans) -> None:
    """Picked up, a part's error across the fingers is the manipulator's (Sec. 3.2.3): after the
    paper's cell's pickup of the peg, its bounds along the fingers' axis are about the
    manipulator's 0.001 in, far below the 0.11 in it had on the table."""
    cell, _, doc = plans["peg_in_block"]
    s = next(s for s in doc["instance"]["steps"] if s["name"] == "pickup" and s["object"] == "peg")
    before = cell.object_bounds["peg"]
    b = s["position_bounds"]["peg"]
    widths = sorted(b[k][1] - b[k][0] for k in ("dx", "dy", "dz"))
    assert widths[0] < 0.01 < before.dx[1] - before.dx[0]


def _samples(reg, names: list[str], rng: np.random.Generator, draws: int) -> np.ndarray:
    """Points (n, len(names)) of the variables' box: every corner (up to 2^10) and uniform draws."""
    lo = np.array([reg.bounds(n)[0] for n in names])
    hi = np.array([reg.bounds(n)[1] for n in names])
    pts = [rng.uniform(lo, hi, size=(draws, len(names)))]
    if len(names) <= 10:
        pts.append(np.array([[b if c else a for c, a, b in zip(bits, lo, hi)]
                             for bits in itertools.product((0, 1), repeat=len(names))]).reshape(-1, len(names)))
    return np.vstack(pts)


def _trans(v: np.ndarray) -> np.ndarray:
    T = np.eye(4)
    T[:3, 3] = v
    return T


def _rotz(t: float) -> np.ndarray:
    T = np.eye(4)
    T[:2, :2] = [[math.cos(t), -math.sin(t)], [math.sin(t), math.cos(t)]]
    return T


def _pose(o: ur.ObjectState, err: np.ndarray) -> np.ndarray:
    """The possible pose of ``o`` for its error entries ``err`` = (theta, dx, dy, dz): Eq. 2 on the
    table (``trans(d) Tr_O rotz(theta) R_O``), Eq. 4 held or assembled (``T_O T_G E T_G^-1``)."""
    theta, d = err[0], err[1:]
    if o.where == ur.TABLE:
        R_O = o.pose.copy()
        R_O[:3, 3] = 0
        return _trans(d) @ _trans(o.pose[:3, 3]) @ _rotz(theta) @ R_O
    return o.pose @ o.grasp @ _trans(d) @ _rotz(theta) @ np.linalg.inv(o.grasp)


@pytest.mark.parametrize("name", CELLS)
def test_bounds_hold_every_sampled_pose(plans, name: str) -> None:
    """Property: at every step, for every part, every sampled possible pose's origin displacement
    and turn about world z lie within the step's bounds."""
    import casadi as ca
    from scipy.spatial.transform import Rotation

    cell, _, doc = plans[name]
    steps = doc["instance"]["steps"]
    cache = CellCache(cell)
    sources = {s["id"]: s["source"] for s in steps if s.get("source")}
    world = phase2.new_world(cache, steps, sources)
    rng = np.random.default_rng(35)
    checked = 0
    for s in steps:
        _, world, _ = phase2.step(world, s)
        got = phase2.position_bounds(cache, world)
        assert got == s["position_bounds"]  # the plan's are this world's
        reg = world.unc.registry
        for key, o in world.unc.objects.items():
            entries = ca.vertcat(o.error.theta, o.error.dx, o.error.dy, o.error.dz)
            names = sorted(reg.box(entries))
            syms = [reg.symbol(n) for n in names]
            f = ca.Function("e", [ca.vertcat(*syms)], [entries])
            pts = _samples(reg, names, rng, 400)
            errs = np.asarray(f.map(len(pts))(pts.T)).T
            b = got[key]
            seen = []
            for e in errs:
                T = _pose(o, e)
                d = T[:3, 3] - o.pose[:3, 3]
                turn = math.degrees(Rotation.from_matrix(T[:3, :3] @ o.pose[:3, :3].T).as_rotvec()[2])
                seen.append((*d, turn))
                for k, v in zip(KEYS, (*d, turn)):
                    # the sample is computed in floats: a few ulps of the part's size
                    eps = 1e-12 * max(1.0, float(np.abs(o.pose[:3, 3]).max()))
                    assert b[k][0] - eps <= v <= b[k][1] + eps, (name, s["id"], key, k, v, b[k])
                checked += 1
            # and not loose: the samples (the box's corners among them) come near both ends
            lo, hi = np.min(seen, axis=0), np.max(seen, axis=0)
            for i, k in enumerate(KEYS):
                width = b[k][1] - b[k][0]
                assert hi[i] - lo[i] >= 0.9 * width - 1e-12, (name, s["id"], key, k, (lo[i], hi[i]), b[k])
    assert checked > 1000


def test_bounds_are_cached_per_structure(plans) -> None:
    """Parts alike in how their error came about are bounded once: a second cache-sharing run of the
    same instance asks SUP/INF nothing new."""
    cell, _, doc = plans["large_uncertainty"]
    steps = doc["instance"]["steps"]
    cache = CellCache(cell)
    first = [phase2.position_bounds(cache, w) for w in _worlds(cache, steps)]
    table = cache.table("phase2.position_bounds", BOUNDS_LIMIT)
    n = len(table)
    assert n > 0
    again = [phase2.position_bounds(cache, w) for w in _worlds(cache, steps)]
    assert again == first and len(table) == n


def _worlds(cache: CellCache, steps: list[dict]) -> list:
    world = phase2.new_world(cache, steps, {s["id"]: s["source"] for s in steps if s.get("source")})
    out = []
    for s in steps:
        _, world, _ = phase2.step(world, s)
        out.append(world)
    return out


def test_the_viewer_draws_each_steps_propagated_bounds(plans) -> None:
    from spar_py.pictures.viewer import viewer_data

    cell, plan, doc = plans["large_uncertainty"]
    data = viewer_data(cell, _typed(doc))
    assert data["states"][0]["uncertainty_from"] == "declared"
    assert data["states"][0]["uncertainty"]["peg"][:2] == list(cell.object_bounds["peg"].dx)
    for k, s in enumerate(doc["instance"]["steps"], start=1):
        st = data["states"][k]
        assert st["uncertainty_from"] == "propagated"
        for part, b in s["position_bounds"].items():
            drawn = st["uncertainty"][part]
            for i, key in enumerate(("dx", "dy", "dz", "dtheta_deg")):
                lo, hi = b[key]
                assert drawn[2 * i] <= lo and drawn[2 * i + 1] >= hi  # rounded outwards
                assert hi - lo == pytest.approx(drawn[2 * i + 1] - drawn[2 * i], abs=2.1e-5)
