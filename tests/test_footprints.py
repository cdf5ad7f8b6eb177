"""Issue 13 item 4: a put-down part's whole footprint lies in a free region, clear of
every other part on the table by the clearance.

Checked independently of placement.py: footprints from the object's shape here (box
corners, cylinder rims sampled finely), convex hulls by gift wrapping, containment by
the hull's vertices, distances between convex polygons from their vertices and edges
after a separating-axis overlap test."""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from spar_py.world.reach import placement as placement
from spar_py.core.units import LENGTH_UNITS
from spar_py.kb import load_problem
from spar_py.world.collision import CellCache
from spar_py.core.model import Cell, ObjectModel
from spar_py.planning.planner import Planner

from paths import ROOT

PROBLEMS = sorted((ROOT / "kb/problems").glob("*.yaml"))
CLEARANCE_MM = 25.4   # the gap the planner promises between footprints (1 in)
MARGIN_MM = 304.8     # free table without placement_regions: initial positions +- 12 in
TOL_MM = 1e-5


def _shadow(model: ObjectModel, T: np.ndarray) -> np.ndarray:
    """World xy of points of the shape at pose T: box corners, 720 points on each rim."""
    pts = []
    for s in model.shape:
        if s.kind == "cylinder":
            a = np.linspace(0, 2 * np.pi, 720, endpoint=False)
            for z in (s.lo[2], s.hi[2]):
                pts.append(np.stack([s.radius * np.cos(a), s.radius * np.sin(a), np.full_like(a, z)], axis=1))
        else:
            pts.append(np.array([[x, y, z] for x in (s.lo[0], s.hi[0]) for y in (s.lo[1], s.hi[1])
                                 for z in (s.lo[2], s.hi[2])]))
    P = np.concatenate(pts) @ T[:3, :3].T + T[:3, 3]
    return P[:, :2]


def _wrap(P: np.ndarray) -> np.ndarray:
    """Convex hull of P (n, 2) by gift wrapping (Jarvis), counter-clockwise."""
    start = int(np.lexsort((P[:, 1], P[:, 0]))[0])
    hull, cur = [start], start
    while True:
        cand = (cur + 1) % len(P)
        for j in range(len(P)):
            u, v = P[cand] - P[cur], P[j] - P[cur]
            c = u[0] * v[1] - u[1] * v[0]
            if c < -1e-12 or (abs(c) <= 1e-12 and v @ v > u @ u):
                cand = j
        cur = cand
        if cur == start:
            return P[hull]
        hull.append(cur)


def _overlap(A: np.ndarray, B: np.ndarray) -> bool:
    """Separating axes (edge normals of both): do convex polygons A and B intersect?"""
    for poly in (A, B):
        E = np.roll(poly, -1, axis=0) - poly
        for n in np.stack([-E[:, 1], E[:, 0]], axis=1):
            if (A @ n).max() < (B @ n).min() or (B @ n).max() < (A @ n).min():
                return False
    return True


def _seg_dist(p: np.ndarray, a: np.ndarray, b: np.ndarray) -> float:
    d = b - a
    t = 0.0 if d @ d == 0 else min(1.0, max(0.0, float((p - a) @ d / (d @ d))))
    return float(np.linalg.norm(p - (a + t * d)))


def _distance(A: np.ndarray, B: np.ndarray) -> float:
    """Distance between convex polygons A and B (0 if they intersect)."""
    if _overlap(A, B):
        return 0.0
    best = math.inf
    for P, Q in ((A, B), (B, A)):
        for p in P:
            for a, b in zip(Q, np.roll(Q, -1, axis=0)):
                best = min(best, _seg_dist(p, a, b))
    return best


def _regions(cell: Cell) -> list[tuple[float, float, float, float]]:
    """The free table rectangles and the tops of the box supports (issue 33: a put-down may go
    onto a support's top), each (x0, x1, y0, y1)."""
    tops = [(*b.points[:, 0].min(keepdims=True), *b.points[:, 0].max(keepdims=True),
             *b.points[:, 1].min(keepdims=True), *b.points[:, 1].max(keepdims=True))
            for o in cell.obstacles if o.support for b in o.bodies if b.kind == "box"]
    if cell.placement_regions:
        return [(*r["x"], *r["y"]) for r in cell.placement_regions] + tops
    xy = np.array([p.T[:2, 3] for p in cell.positions.values()])
    m = MARGIN_MM / LENGTH_UNITS[cell.unit]
    return [(xy[:, 0].min() - m, xy[:, 0].max() + m, xy[:, 1].min() - m, xy[:, 1].max() + m)] + tops


def _placement_T(cell: Cell, obj: str, p: dict) -> np.ndarray:
    c, s = math.cos(math.radians(p["yaw_deg"])), math.sin(math.radians(p["yaw_deg"]))
    T = np.eye(4)
    T[:3, :3] = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]]) @ cell.objects[obj].poses[p["pose"]].R
    T[:3, 3] = p["x"], p["y"], p["z"]
    return T


def check_plan_footprints(cell: Cell, steps: list[dict]) -> int:
    """Assert every put-down of ``steps`` (JSON steps) is in a region and clear of the
    parts then on the table; the number of put-downs checked."""
    tol = TOL_MM / LENGTH_UNITS[cell.unit]
    gap = CLEARANCE_MM / LENGTH_UNITS[cell.unit]
    table: list[tuple[str, str, np.ndarray]] = [(p.label, p.obj, p.T) for p in cell.positions.values()]
    n = 0
    for s in steps:
        if s["name"] == "pickup":
            obj = s["object"]
            src = (s.get("source") or {}).get(obj)
            mine = [i for i, (lab, o, _) in enumerate(table) if o == obj]
            exact = [i for i in mine if table[i][0] == src]
            placed = [i for i in mine if table[i][0].startswith("@")]
            take = exact or placed[-1:] or mine[:1]
            if take:
                table.pop(take[0])
        elif s["name"] == "putdown" and s["placement"] is not None:
            obj = s["object"]
            T = _placement_T(cell, obj, s["placement"])
            foot = _wrap(_shadow(cell.objects[obj], T))
            # a put-down onto a part's top (issue 33): the part's shadow is its region
            on = s["placement"].get("on")
            under = [(x[:, 0].min(), x[:, 0].max(), x[:, 1].min(), x[:, 1].max())
                     for x in (_wrap(_shadow(cell.objects[o], To)) for _, o, To in table if o == on)]
            assert any(foot[:, 0].min() >= x0 - tol and foot[:, 0].max() <= x1 + tol
                       and foot[:, 1].min() >= y0 - tol and foot[:, 1].max() <= y1 + tol
                       for x0, x1, y0, y1 in _regions(cell) + under), (cell.name, s["id"], "outside every region")
            for lab, o, To in table:
                if o == on:
                    continue  # resting on it: its contact, within its shadow (above)
                d = _distance(foot, _wrap(_shadow(cell.objects[o], To)))
                assert d >= gap - tol, (cell.name, s["id"], f"{d} from {o} at {lab}")
            table.append(("@" + s["id"], obj, T))
            n += 1
    return n


@pytest.mark.parametrize("path", PROBLEMS, ids=[p.stem for p in PROBLEMS])
def test_every_putdown_footprint_is_in_a_region_and_clear(path: Path) -> None:
    cell = load_problem(path)
    inst = Planner(max_instances=3).plan(cell).to_json()["instance"] or {"steps": []}
    check_plan_footprints(cell, inst["steps"])


def _edge_cell(tmp_path: Path, regions: str, block_xy: str = "30, 8") -> Path:
    """The paper's cell with its free table cut down to ``regions`` (YAML flow list)."""
    text = (ROOT / "kb/problems/peg_in_block.yaml").read_text()
    text = text.replace("../robots/", f"{ROOT}/kb/robots/").replace("../objects/", f"{ROOT}/kb/objects/")
    text = text.replace("[30, 8, 1.5]]}", f"[{block_xy}, 1.5]]}}")
    text = text.replace("gripper: open\n", f"gripper: open\nplacement_regions: {regions}\n")
    p = tmp_path / "edge.yaml"
    p.write_text(text)
    return p


def test_putdown_at_a_region_corner_stays_inside(tmp_path: Path) -> None:
    """The block was picked up at (30, 8), the free table's corner: the nearest spot for
    its origin hangs 1.5 in over two edges; the footprint must not."""
    cell = load_problem(_edge_cell(tmp_path, "[{x: [30, 40], y: [8, 20]}]"))
    inst = Planner(max_instances=3).plan(cell).to_json()["instance"]
    assert inst is not None
    assert check_plan_footprints(cell, inst["steps"]) == 1
    (p,) = [s["placement"] for s in inst["steps"] if s["name"] == "putdown"]
    assert p["x"] > 30 and p["y"] > 8


def test_footprint_clearance_is_tighter_than_bounding_circles() -> None:
    """Footprints, not bounding circles: the peg lies at (30, -8), its footprint y in
    [-10.5, -8]. The block (hole up, yaw 0: a 3 in square) wanted at (30, -6) may go
    down at (30, -4), 2.5 in from the peg's footprint ((30, -6) would leave 0.5 in, under the
    1 in clearance); with the peg known by its
    bounding circle only (radius 2.6 in) it must keep 3.6 in from the peg's origin."""
    cell = load_problem(ROOT / "kb/problems/peg_in_block.yaml")
    peg = cell.positions["tr1"]
    near = np.array([30.0, -6.0])
    X = [cell.objects["block"].grasps["p2G10"].T]  # from above
    cache = CellCache(cell)
    exact = placement.choose(cache, "block", "p2P1", X, [placement.occupant(cache, "peg", peg.T)], near)
    circle = placement.choose(CellCache(cell), "block", "p2P1", X,
                              [(peg.T[:2, 3], cell.objects["peg"].bounding_radius())], near)
    assert exact is not None and (exact.x, exact.y, exact.yaw) == (30.0, -4.0, 0.0)
    assert circle is not None and math.hypot(circle.x - 30, circle.y + 6) > 2.0
    peg_foot = _wrap(_shadow(cell.objects["peg"], peg.T))
    assert _distance(_wrap(_shadow(cell.objects["block"], exact.T)), peg_foot) == pytest.approx(2.5)
    assert _distance(_wrap(_shadow(cell.objects["block"], circle.T)), peg_foot) >= 1.0


def test_footprint_of_the_block_turned() -> None:
    """placement.footprint against this file's hull: a 3 in cube turned 30 deg."""
    cell = load_problem(ROOT / "kb/problems/peg_in_block.yaml")
    T = cell.positions["tr2"].T.copy()
    T[:3, 3] = 0
    mine = _wrap(_shadow(cell.objects["block"], T))
    theirs = placement.footprint(cell.objects["block"], T[:3, :3])
    assert len(mine) == len(theirs) == 4
    assert np.allclose(np.sort(mine, axis=0), np.sort(theirs, axis=0), atol=1e-9)
