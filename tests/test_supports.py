"""Issue 33 item 5: supports other than the table. Parts rest on the table, on an obstacle
marked ``support: true`` or on another part, initially and after every step; put-downs may
go onto a support's top; a floating or unstable part is refused in one line.

The checks of resting are the test's own geometry (world.reach.supports is the code under test):
a part's vertices from its box and cylinder primitives (a cylinder's rims sampled densely),
its centre of mass from the primitives' volumes, the supports' tops from the problem file's
own ``box:`` numbers, and point-in-polygon by scipy's convex hull.
"""
from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import yaml
from scipy.spatial import ConvexHull

from spar_py import Planner
from spar_py.core.errors import KBError
from spar_py.kb import load_problem
from spar_py.phase2 import instance as phase2
from spar_py.world.reach import placement as pl
from spar_py.world.collision import CellCache
from spar_py.world.reach.supports import support_surfaces

from paths import ROOT

PROBLEMS = ROOT / "kb" / "problems"
#: The checks' tolerance on heights (cell unit: in or mm, well under either's rounding).
TOL = 1e-6


# --------------------------------------------------------------------------- own geometry


def _points(model, T: np.ndarray) -> np.ndarray:
    """The part's surface points at world pose T: box corners, cylinder rims at 720 points each."""
    pts = []
    for s in model.shape:
        if s.kind == "box":
            pts.append(np.array([[x, y, z] for x in (s.lo[0], s.hi[0]) for y in (s.lo[1], s.hi[1])
                                 for z in (s.lo[2], s.hi[2])]))
        else:
            assert s.kind == "cylinder"
            a = np.linspace(0, 2 * math.pi, 720, endpoint=False)
            for z in (s.lo[2], s.hi[2]):
                pts.append(np.column_stack([s.radius * np.cos(a), s.radius * np.sin(a), np.full(len(a), z)]))
    P = np.concatenate(pts)
    return P @ T[:3, :3].T + T[:3, 3]


def _com(model, T: np.ndarray) -> np.ndarray:
    """Centre of mass (world) of a model of boxes and z-cylinders, uniform density."""
    m, c = [], []
    for s in model.shape:
        if s.kind == "box":
            m.append(float(np.prod(np.subtract(s.hi, s.lo))))
            c.append((np.asarray(s.lo) + np.asarray(s.hi)) / 2)
        else:
            m.append(math.pi * s.radius ** 2 * (s.hi[2] - s.lo[2]))
            c.append(np.array([0, 0, (s.lo[2] + s.hi[2]) / 2]))
    local = np.average(c, axis=0, weights=m)
    return T[:3, :3] @ local + T[:3, 3]


def _in_hull(poly_pts: np.ndarray, p: np.ndarray, tol: float) -> bool:
    """p (xy) inside the convex hull of poly_pts (k, 2), within tol."""
    h = ConvexHull(poly_pts)
    return bool(np.all(h.equations[:, :2] @ p + h.equations[:, 2] <= tol))


def _surfaces(path: Path, cell, world: dict[str, np.ndarray]) -> list[tuple[str, float, np.ndarray | None]]:
    """(name, height, top rectangle corners or None) of the table, the problem file's support boxes
    (read from the file) and every part in ``world`` (its highest points' hull)."""
    data = yaml.safe_load(path.read_text())
    out: list[tuple[str, float, np.ndarray | None]] = [("table", 0.0, None)]
    for ob in data.get("obstacles", []):
        if ob.get("support"):
            (x0, y0, _), (x1, y1, z1) = ob["box"]["min"], ob["box"]["max"]
            out.append((ob["name"], float(z1), np.array([[x0, y0], [x1, y0], [x1, y1], [x0, y1]], float)))
    for name, T in world.items():
        P = _points(cell.objects[name.split("@")[0]], T)
        top = P[:, 2].max()
        out.append((name, float(top), P[P[:, 2] >= top - TOL][:, :2]))
    return out


def _rests(path: Path, cell, name: str, T: np.ndarray, others: dict[str, np.ndarray]) -> str | None:
    """None if the part ``name`` at T rests on a surface (its lowest point on it, its centre of
    mass over its contact face and over the surface), else why not."""
    model = cell.objects[name.split("@")[0]]
    P = _points(model, T)
    low = P[:, 2].min()
    face = P[P[:, 2] <= low + TOL][:, :2]
    c = _com(model, T)[:2]
    for s, z, top in _surfaces(path, cell, others):
        if abs(low - z) <= TOL and (top is None or _in_hull(top, c, TOL)):
            return None if _in_hull(face, c, TOL) else f"{name} tips over on {s}"
    return f"{name} at z = {low} rests on nothing"


def _plan(problem: str) -> dict:
    plan = Planner(max_instances=5).plan(PROBLEMS / f"{problem}.yaml")
    assert plan.outcome.value == "plan", plan.to_json().get("reason")
    return plan.to_json()


# --------------------------------------------------------------------------- cells


@pytest.mark.parametrize("problem", ["fixture_pickup", "riser_putdown", "stack_putdown"])
def test_every_part_rests_after_every_step(problem: str) -> None:
    """After every step each part not in the hand, nor inserted into another, rests on the
    table, a support's top or another part (the test's own geometry)."""
    path = PROBLEMS / f"{problem}.yaml"
    cell = load_problem(path)
    initial = {p.obj: p.T for p in cell.positions.values()}
    for name, T in initial.items():
        assert _rests(path, cell, name, T, {k: v for k, v in initial.items() if k != name}) is None
    inserted: set[str] = set()
    steps = _plan(problem)["instance"]["steps"]
    assert steps
    for s in steps:
        if s["name"] == "assemble":
            inserted.add(s["args"][0])
        world = {k: np.array(v, float) for k, v in s["poses"].items() if k != s.get("held") and k not in inserted}
        for name, T in world.items():
            why = _rests(path, cell, name, T, {k: v for k, v in world.items() if k != name})
            assert why is None, f"after {s['id']} ({s['term']}): {why}"


def test_fixture_cell_takes_the_peg_off_the_plate() -> None:
    """fixture_pickup: the peg starts on the plate, 100 mm up, is picked from there and inserted."""
    cell = load_problem(PROBLEMS / "fixture_pickup.yaml")
    peg = cell.positions["tr1"].T
    assert _points(cell.objects["peg"], peg)[:, 2].min() == pytest.approx(100.0, abs=TOL)
    j = _plan("fixture_pickup")
    terms = [s["term"] for s in j["instance"]["steps"]]
    assert terms[-1].startswith("assemble(peg,block")
    pick = next(s for s in j["instance"]["steps"] if s["name"] == "pickup" and s["args"][0] == "peg")
    assert pick["joints_deg"] is not None
    np.testing.assert_allclose(np.array(pick["poses"]["peg"], float), peg, atol=1e-6)
    assert all(v["satisfied"] for v in j["instance"]["constraints"])


def test_riser_cell_puts_the_block_on_the_riser() -> None:
    """riser_putdown: the table region is too small, so the block is put down on the riser's top,
    2 in up, wholly on it."""
    cell = load_problem(PROBLEMS / "riser_putdown.yaml")
    j = _plan("riser_putdown")
    put = next(s for s in j["instance"]["steps"] if s["name"] == "putdown")
    assert put["placement"]["on"] == "riser"
    T = np.array(put["poses"]["block"], float)
    P = _points(cell.objects["block"], T)
    assert P[:, 2].min() == pytest.approx(2.0, abs=TOL)
    assert np.all((P[:, 0] >= 27 - TOL) & (P[:, 0] <= 33 + TOL) & (P[:, 1] >= -3 - TOL) & (P[:, 1] <= 3 + TOL))


def test_stack_cell_puts_the_block_on_the_slab() -> None:
    """stack_putdown: the slab covers the whole free table, so the turned-over block goes onto the
    slab's top (1 in up), wholly on it, its centre of mass over the top; the slab's box and pose
    are read from the files, not from the planner."""
    path = PROBLEMS / "stack_putdown.yaml"
    cell = load_problem(path)
    slab = yaml.safe_load((ROOT / "kb" / "objects" / "slab.yaml").read_text())["shape"][0]["box"]
    x, y = yaml.safe_load(path.read_text())["objects"]["slab"]["initial"]["tm"][3][:2]
    (x0, y0, _), (x1, y1, z1) = slab["min"], slab["max"]
    j = _plan("stack_putdown")
    put = next(s for s in j["instance"]["steps"] if s["name"] == "putdown")
    assert put["placement"]["on"] == "slab"
    T = np.array(put["poses"]["block"], float)
    P = _points(cell.objects["block"], T)
    assert P[:, 2].min() == pytest.approx(z1, abs=TOL)
    assert np.all((P[:, 0] >= x + x0 - TOL) & (P[:, 0] <= x + x1 + TOL)
                  & (P[:, 1] >= y + y0 - TOL) & (P[:, 1] <= y + y1 + TOL))
    c = _com(cell.objects["block"], T)[:2]
    assert x + x0 < c[0] < x + x1 and y + y0 < c[1] < y + y1
    assert np.array(put["poses"]["slab"], float) == pytest.approx(cell.positions["tr3"].T, abs=TOL)


def test_a_part_moved_later_is_no_put_down_top() -> None:
    """A part's top is a put-down target only while no later step moves it: with a later pickup
    of the slab in the steps, the block's put-down finds no place (the slab covers the table)."""
    cell = load_problem(PROBLEMS / "stack_putdown.yaml")
    steps = [{"id": "a1", "name": "pickup", "args": ["block", "p2G1"]},
             {"id": "a2", "name": "putdown", "args": ["block", "p2P1"]}]
    assert phase2.choose_placements(CellCache(cell), steps)["a2"].on == "slab"
    later = [*steps, {"id": "a3", "name": "pickup", "args": ["slab", "none"]}]
    assert phase2.choose_placements(CellCache(cell), later)["a2"] is None


# --------------------------------------------------------------------------- refusals at load


def _cell(tmp_path: Path, problem: str, *subs: tuple[str, str]) -> Path:
    text = (PROBLEMS / f"{problem}.yaml").read_text()
    text = text.replace("../robots/", f"{ROOT}/kb/robots/").replace("../objects/", f"{ROOT}/kb/objects/")
    for old, new in subs:
        assert old in text, old
        text = text.replace(old, new)
    p = tmp_path / "cell.yaml"
    p.write_text(text)
    return p


def _error(path: Path) -> str:
    with pytest.raises(KBError) as e:
        load_problem(path)
    msg = str(e.value)
    assert "\n" not in msg
    return msg


PEG_ON_PLATE = "[762, -203.2, 138.1]]}"
WHY = ("objects.peg.initial: expected peg at init_pos1 resting on the table, a support or another part "
       "(its lowest point on the surface, its centre of mass over it); it ")


def test_floating_part_names_the_support_and_the_gap(tmp_path: Path) -> None:
    msg = _error(_cell(tmp_path, "fixture_pickup", (PEG_ON_PLATE, "[762, -203.2, 150.1]]}")))
    assert msg == f"{tmp_path}/cell.yaml: {WHY}floats 12 mm above fixture_plate's top"


def test_part_sunk_into_a_support(tmp_path: Path) -> None:
    msg = _error(_cell(tmp_path, "fixture_pickup", (PEG_ON_PLATE, "[762, -203.2, 130.1]]}")))
    assert msg == f"{tmp_path}/cell.yaml: {WHY}sinks 8 mm into fixture_plate's top"


def test_part_over_the_edge_of_a_support(tmp_path: Path) -> None:
    # the peg lying along -y from y = -100: its base (y -125.4..-100) straddles the plate's edge
    # at y = -120 and its centre of mass (16.4 mm along) is short of it
    msg = _error(_cell(tmp_path, "fixture_pickup", (PEG_ON_PLATE, "[762, -100, 138.1]]}")))
    assert msg.startswith(f"{tmp_path}/cell.yaml: {WHY}tips over the edge of fixture_plate's top: its centre of "
                          "mass is ")
    cell_free = load_problem(PROBLEMS / "fixture_pickup.yaml")
    T = cell_free.positions["tr1"].T.copy()
    T[1, 3] = -100
    assert _com(cell_free.objects["peg"], T)[1] > -120


def test_part_stacked_on_another_part_loads(tmp_path: Path) -> None:
    """The peg standing (p1P1) on the block's top (the block hole down, 3 in high) rests on it."""
    path = _cell(tmp_path, "riser_putdown",
                 ("tm: [[1, 0, 0], [0, 0, 1], [0, -1, 0], [30, -8, 1.5]]}",
                  "tm: [[1, 0, 0], [0, 1, 0], [0, 0, 1], [30, 8, 3]]}"))
    cell = load_problem(path)
    peg, block = cell.positions["tr1"].T, cell.positions["tr2"].T
    assert _rests(path, cell, "peg", peg, {"block": block}) is None
    assert _rests(path, cell, "peg", peg, {}) is not None  # without the block under it, it floats


def test_stacked_part_off_centre_tips(tmp_path: Path) -> None:
    path = _cell(tmp_path, "riser_putdown",
                 ("tm: [[1, 0, 0], [0, 0, 1], [0, -1, 0], [30, -8, 1.5]]}",
                  "tm: [[1, 0, 0], [0, 1, 0], [0, 0, 1], [32.2, 8, 3]]}"))
    msg = _error(path)
    assert "it tips over the edge of block's top" in msg


def test_obstacle_support_flag_must_be_boolean(tmp_path: Path) -> None:
    msg = _error(_cell(tmp_path, "riser_putdown", ("support: true", "support: yes please")))
    assert msg.startswith(f"{tmp_path}/cell.yaml: obstacles[0].support: expected true or false")


# --------------------------------------------------------------------------- the tops and the put-down


def test_cylinder_support_top_is_inscribed(tmp_path: Path) -> None:
    """A cylinder support's top polygon lies within its true disc and reaches its rim."""
    path = _cell(tmp_path, "riser_putdown", ("box: {min: [27, -3, 0], max: [33, 3, 2]}",
                                             "cylinder: {radius: 3, z: [0, 2], center: [30, 0]}"))
    (top,) = support_surfaces(load_problem(path))
    assert top.z == pytest.approx(2.0)
    r = np.hypot(top.polygon[:, 0] - 30, top.polygon[:, 1])
    assert np.all(r <= 3 + 1e-9) and r.max() == pytest.approx(3.0)


def test_table_placements_keep_off_the_riser() -> None:
    """Every table placement's footprint keeps the clearance from the riser's footprint; every
    riser placement lies within its top at its height."""
    cell = load_problem(PROBLEMS / "riser_putdown.yaml")
    cache = CellCache(replace(cell, placement_regions=[{"x": (20.0, 40.0), "y": (-6.0, 6.0)}]))
    cands = pl.candidates(cache, "block", "p2P1", [])
    assert {c.on for c in cands} == {"table", "riser"}
    for c in cands:
        P = _points(cell.objects["block"], c.T)
        if c.on == "table":
            assert P[:, 2].min() == pytest.approx(0.0, abs=TOL)
            gap_x = max(27 - P[:, 0].max(), P[:, 0].min() - 33)
            gap_y = max(-3 - P[:, 1].max(), P[:, 1].min() - 3)
            assert max(gap_x, gap_y) >= 1.0 - 1e-6  # 25.4 mm
        else:
            assert P[:, 2].min() == pytest.approx(2.0, abs=TOL)
            assert P[:, 0].min() >= 27 - TOL and P[:, 0].max() <= 33 + TOL


def _putdown_world(placement: pl.Placement):
    cell = load_problem(PROBLEMS / "riser_putdown.yaml")
    steps = [{"id": "action_4", "name": "pickup", "args": ["block", "p2G7"]},
             {"id": "action_3", "name": "putdown", "args": ["block", "p2P1"]}]
    w = phase2.new_world(CellCache(cell), steps)
    _, w, _ = phase2.step(w, steps[0])
    w = replace(w, placements={**w.placements, "action_3": placement})
    return phase2.step(w, steps[1])


def _on_riser(x: float, y: float, z: float, yaw_deg: float = 300.0) -> pl.Placement:
    """The block hole up (p2P1: its frame's rotation is a turn about z) at (x, y, z)."""
    a = math.radians(yaw_deg)
    T = np.eye(4)
    T[:2, :2] = [[math.cos(a), -math.sin(a)], [math.sin(a), math.cos(a)]]
    T[:3, 3] = [x, y, z]
    return pl.Placement("block", "p2P1", x, y, z, a, T, "riser")


def test_putdown_on_the_riser_is_clear() -> None:
    """The held block's contact with the riser's top is the put-down's own, not a collision: the
    arm's joint vector there is clear; the same state allowing only the table's contact (the
    block touching the riser counted) is not, and names the pair."""
    checks, world, geo = _putdown_world(_on_riser(30.0, 0.0, 3.5))
    assert geo["joints_deg"] is not None and not checks
    g = world.cell.objects["block"].grasps["p2G7"]
    scene = world.cache.scene()
    q = np.radians(geo["joints_deg"])[None]
    parts = {"peg": world.cell.positions["tr1"].T}
    held = ("block", np.linalg.inv(g.T))
    ok, _ = scene.at(parts, held, width=g.width, allow=[("held:block", "table"), ("held:block", "riser")]).check(q)
    assert ok[0]
    ok, why = scene.at(parts, held, width=g.width, allow=[("held:block", "table")]).check(q)
    assert not ok[0] and set(why[0]) == {"held:block", "riser"}


@pytest.mark.parametrize("x, y, z, why", [
    (30.0, 3.2, 3.5, "tips over the edge of riser's top"),   # its centre 0.2 in past the top's edge at y = 3
    (30.0, 0.0, 3.0, "sinks 0.5 in into riser's top"),       # real penetration still counts
    (30.0, 0.0, 4.0, "floats 0.5 in above riser's top"),
])
def test_unstable_putdown_is_refused(x: float, y: float, z: float, why: str) -> None:
    checks, _, _ = _putdown_world(_on_riser(x, y, z))
    refused = [c for c in checks if not c["satisfied"]]
    assert any(why in c["description"] and "leaves block unstable" in c["description"] for c in refused), checks


def test_scene_knows_what_a_part_rests_on() -> None:
    """CollisionScene.resting_on: the riser under the block on its top; nothing for the block on
    the table, beside the riser at its height, or 1 in above it."""
    cell = load_problem(PROBLEMS / "riser_putdown.yaml")
    scene = CellCache(cell).scene()
    assert scene.resting_on("block", _on_riser(30.0, 0.0, 3.5).T) == ["riser"]
    assert scene.resting_on("block", _on_riser(30.0, 0.0, 4.5).T) == []
    assert scene.resting_on("block", _on_riser(40.0, 0.0, 3.5).T) == []
    assert scene.resting_on("block", _on_riser(30.0, 8.0, 1.5).T) == []
