"""The vectorised placement grid (issue 18): every grid placement kept or refused as the
footprints' distances say, checked one placement at a time with polygon distances
computed here (test_footprints' separating-axis and vertex-edge code), and its memo
tables giving the answers a fresh cell gives."""
from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
from test_footprints import _distance, _wrap

from spar_py.world.reach import placement as placement
from spar_py.core.geometry import rotz
from spar_py.kb import load_problem
from spar_py.world.collision import CellCache

from paths import ROOT

CELL = ROOT / "kb/problems/peg_in_block.yaml"
GAP = 1.0  # CLEARANCE_MM in the paper cell's inches
BAND = 1e-6  # placements this close to the clearance either way are not judged


def _layout(cell, seed: int, n: int) -> list[tuple]:
    """The cell's initial parts and ``n`` more at random spots in its free table, as
    ``occupied`` entries (every third one by its bounding disc only)."""
    rng = np.random.default_rng(seed)
    (x0, x1), (y0, y1) = placement.default_regions(cell)[0]["x"], placement.default_regions(cell)[0]["y"]
    cache = CellCache(cell)
    occ = [placement.occupant(cache, p.obj, p.T) for p in cell.positions.values()]
    for i in range(n):
        obj = ("peg", "block")[i % 2]
        sp = list(cell.objects[obj].poses.values())[int(rng.integers(len(cell.objects[obj].poses)))]
        T = np.eye(4)
        T[:3, :3] = rotz(rng.uniform(0, 2 * np.pi))[:3, :3] @ sp.R
        T[:3, 3] = rng.uniform(x0, x1), rng.uniform(y0, y1), sp.height
        occ.append((T[:2, 3].copy(), cell.objects[obj].bounding_radius()) if i % 3 == 2
                   else placement.occupant(cache, obj, T))
    return occ


def _polygon(entry: tuple) -> np.ndarray:
    if len(entry) >= 3:
        return np.asarray(entry[2], float)
    # the disc's circumscribed 16-gon, the polygon the planner promises to keep clear of
    c, r = np.asarray(entry[0], float), float(entry[1])
    a = 2 * np.pi * np.arange(16) / 16
    return c + r / math.cos(math.pi / 16) * np.stack([np.cos(a), np.sin(a)], axis=1)


@pytest.mark.parametrize("obj,pose,seed", [("block", "p2P1", 0), ("block", "p2P3", 1), ("peg", "p1P5", 2)])
def test_grid_keeps_exactly_the_placements_clear_of_every_part(obj: str, pose: str, seed: int) -> None:
    cell = load_problem(CELL)
    occ = _layout(cell, seed, 10)
    step, yaws = 3.0, 8
    kept = {(round(p.x, 9), round(p.y, 9), round(p.yaw, 9))
            for p in placement.candidates(CellCache(cell), obj, pose, occ, step, yaws)}
    sp = cell.objects[obj].poses[pose]
    reg = placement.default_regions(cell)[0]
    (x0, x1), (y0, y1) = reg["x"], reg["y"]
    others = [_wrap(_polygon(e)) for e in occ]
    # bounding circles, only to skip the polygon distance where it cannot be below 2 * GAP
    circles = [(W.mean(axis=0), float(np.linalg.norm(W - W.mean(axis=0), axis=1).max())) for W in others]
    judged = refused = 0
    for x in x0 + step * np.arange(math.floor((x1 - x0) / step + 1e-9) + 1):
        for y in y0 + step * np.arange(math.floor((y1 - y0) / step + 1e-9) + 1):
            for k in range(yaws):
                w = 2 * np.pi * k / yaws
                R = rotz(w)[:3, :3] @ sp.R
                foot = _wrap(placement.footprint(cell.objects[obj], R) + [x, y])
                inside = (foot[:, 0].min() >= x0 - 1e-9 and foot[:, 0].max() <= x1 + 1e-9
                          and foot[:, 1].min() >= y0 - 1e-9 and foot[:, 1].max() <= y1 + 1e-9)
                c = foot.mean(axis=0)
                r = float(np.linalg.norm(foot - c, axis=1).max())
                near = [W for W, (cw, rw) in zip(others, circles) if np.linalg.norm(c - cw) - r - rw < 2 * GAP]
                d = min((_distance(foot, W) for W in near), default=math.inf)
                if inside and abs(d - GAP) < BAND:
                    continue
                want = inside and d > GAP
                assert ((round(x, 9), round(y, 9), round(w, 9)) in kept) == want, (x, y, k, d)
                judged += 1
                refused += inside and not want
    assert judged > 1000 and refused > 100  # the layout does crowd the table


def test_memoised_answers_are_a_fresh_cells() -> None:
    """Placements among partly the same parts, asked in turn of one cell (its cache's tables
    filling), equal those a fresh cell gives each time; a cell copied with other regions
    (sharing the cache's tables) gets its own grid's answers."""
    warm = CellCache(load_problem(CELL))
    occ = _layout(warm.cell, 5, 12)
    for i in range(4):
        part = occ[i:i + 10]
        a = placement._grid_arrays(warm, "block", "p2P1", part, 2.0, 12)
        b = placement._grid_arrays(CellCache(load_problem(CELL)), "block", "p2P1", part, 2.0, 12)
        assert all(np.array_equal(u, v) for u, v in zip(a, b))
    assert warm.memo.sizes()["placement.blocks"] > 0
    moved = CellCache(replace(warm.cell, placement_regions=[{"x": (20.0, 40.0), "y": (-15.0, 5.0)}]))
    moved.memo = warm.memo
    fresh = CellCache(replace(load_problem(CELL), placement_regions=moved.cell.placement_regions))
    a = placement._grid_arrays(moved, "block", "p2P1", occ, 2.0, 12)
    b = placement._grid_arrays(fresh, "block", "p2P1", occ, 2.0, 12)
    assert all(np.array_equal(u, v) for u, v in zip(a, b))


def _convex(rng: np.random.Generator, n: int, scale: tuple[float, float]) -> np.ndarray:
    """A strictly convex CCW n-gon: n points at sorted random angles on an ellipse, shifted."""
    t = np.sort(rng.uniform(0, 2 * np.pi, n))
    return np.stack([scale[0] * np.cos(t), scale[1] * np.sin(t)], axis=1) + rng.uniform(-5, 5, 2)


def test_minkowski_batch_is_the_hull_of_all_vertex_sums() -> None:
    """Each sum of a batch: the convex hull of every vertex of P plus every vertex of Q."""
    rng = np.random.default_rng(3)
    for a, c in ((4, 4), (5, 16), (1, 7)):
        Ps = [_convex(rng, a, (3.0, 2.0)) for _ in range(6)]
        Qs = [_convex(rng, c, (1.0, 1.5)) for _ in range(6)]
        M = placement._minkowski_batch(np.stack(Ps), np.stack(Qs))
        assert M.shape == (6, a + c, 2)
        for m, p, q in zip(M, Ps, Qs):
            want = _wrap((p[:, None, :] + q[None, :, :]).reshape(-1, 2))
            got = _wrap(m)
            assert len(got) == len(want)
            assert np.allclose(np.sort(got, axis=0), np.sort(want, axis=0), atol=1e-9)
