"""Issue 13 item 3: one internal length unit. The paper's cell written in in, mm and m
(tests/units_fixture.py converts kb/problems/peg_in_block.yaml, its robot and objects)
gives the same plan, in planning times within 20 % of each other."""
from __future__ import annotations

import statistics
import time
from pathlib import Path

import numpy as np
import pytest

from spar_py.world.reach import placement as placement
from spar_py.core.units import LENGTH_UNITS
from spar_py.kb import load_problem
from spar_py.world.collision import CellCache
from spar_py.planning.planner import Planner

from units_fixture import ROOT, write_cell

UNITS = ("in", "mm", "m")


@pytest.fixture(scope="module")
def cells(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    out = tmp_path_factory.mktemp("units")
    return {u: write_cell(ROOT / "kb/problems/peg_in_block.yaml", u, out) for u in UNITS}


@pytest.fixture(scope="module")
def plans(cells: dict[str, Path]) -> dict[str, dict]:
    return {u: Planner().plan(load_problem(p)).to_json() for u, p in cells.items()}


def test_files_really_are_in_their_unit(cells: dict[str, Path]) -> None:
    for u, p in cells.items():
        cell = load_problem(p)
        assert cell.unit == u
        x_mm = cell.positions["tr1"].T[0, 3] * LENGTH_UNITS[u]
        assert x_mm == pytest.approx(762.0)


def test_constants_are_the_same_lengths_in_every_unit(cells: dict[str, Path]) -> None:
    """The free regions and phase 1's grid are the same physical places."""
    loaded = {u: load_problem(p) for u, p in cells.items()}
    ref = loaded["mm"]
    for u, cell in loaded.items():
        k = LENGTH_UNITS[u]
        for a, b in zip(placement.default_regions(cell), placement.default_regions(ref)):
            assert np.allclose(np.array([a["x"], a["y"]]) * k, np.array([b["x"], b["y"]]), atol=1e-9)
        for obj, m in cell.objects.items():
            for pose in m.poses:
                g, g0 = placement._grid(CellCache(cell), obj, pose), placement._grid(CellCache(ref), obj, pose)
                assert g.shape == g0.shape, (u, obj, pose)
                assert np.allclose(g[:, :3, 3] * k, g0[:, :3, 3], atol=1e-6)


def test_same_plan_in_every_unit(plans: dict[str, dict]) -> None:
    ref = plans["in"]
    assert ref["outcome"] == "plan"
    for u in ("mm", "m"):
        got = plans[u]
        k = LENGTH_UNITS[u] / LENGTH_UNITS["in"]  # a length in u times k: the same length in inches
        assert got["outcome"] == ref["outcome"]
        for key in ("variables", "actions", "ordering", "arcs", "separations"):
            assert got["partial"][key] == ref["partial"][key], (u, key)
        gi, ri = got["instance"], ref["instance"]
        assert gi["bindings"] == ri["bindings"]
        assert gi["error_count"] == ri["error_count"]
        assert gi["instances_examined"] == ri["instances_examined"]
        assert len(gi["steps"]) == len(ri["steps"])
        for s, r in zip(gi["steps"], ri["steps"]):
            for key in ("id", "name", "term", "kind", "object", "serves", "source"):
                assert s.get(key) == r.get(key), (u, key)
            assert np.allclose(s["joints_deg"], r["joints_deg"], rtol=0, atol=1e-6)
            assert np.allclose(s["ik_solutions_deg"], r["ik_solutions_deg"], rtol=0, atol=1e-6)
            T, R = np.array(s["tool_pose"]), np.array(r["tool_pose"])
            assert np.allclose(T[:3, :3], R[:3, :3], atol=1e-9)
            assert np.allclose(T[:3, 3] * k, R[:3, 3], rtol=0, atol=1e-9)  # lengths, in inches
            if r["placement"] is not None:
                p, q = s["placement"], r["placement"]
                assert (p["object"], p["pose"]) == (q["object"], q["pose"])
                assert p["yaw_deg"] == pytest.approx(q["yaw_deg"], abs=1e-9)
                for ax in "xyz":
                    assert p[ax] * k == pytest.approx(q[ax], abs=1e-6)
        assert [c["satisfied"] for c in gi["constraints"]] == [c["satisfied"] for c in ri["constraints"]]


#: Planning-time medians may differ by 20 %, plus this much (s) for timer and load noise.
TIME_FLOOR_S = 0.05
RUNS = 5


def test_planning_times_within_20_percent(cells: dict[str, Path]) -> None:
    """Medians of 5 cold plans each (a fresh cell: empty memo tables), runs interleaved
    so a burst of load on the machine hits every unit alike."""
    planner = Planner()
    planner.plan(load_problem(cells["in"]))  # warm the engine and imports
    times: dict[str, list[float]] = {u: [] for u in UNITS}
    for _ in range(RUNS):
        for u in UNITS:
            cell = load_problem(cells[u])
            t0 = time.perf_counter()
            assert planner.plan(cell).outcome.value == "plan"
            times[u].append(time.perf_counter() - t0)
    med = {u: statistics.median(t) for u, t in times.items()}
    assert max(med.values()) <= 1.2 * min(med.values()) + TIME_FLOOR_S, med
