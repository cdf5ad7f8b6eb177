"""A bar lying in a block's half-cylinder cradle under a cap (world/product/assembly.py's curved seats).

The meshes are built here (shapely profiles extruded along y, mm): a block 60 x 40 x 30 with a
cradle of radius 10.3 about the line x = 0, z = 30 (its top face), a round bar of radius 10,
60 long, on that line (0.3 mm clear of the cradle all round), and a cap 60 x 40 x 15 on the
block with the same cradle turned down over the bar. The derivation must make the bar's
cradle a curved seat it goes down into (-z, from this file's own geometry: the mean outward
normal of the bar's lower half), the cap a planar seat on the block, and the cap's cradle over
the bar a contact; the bar's path down is checked free here with trimesh's containment, and a
path across the cradle is caught.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from spar_py.kb.products import load_product_derived
from spar_py.world.product.products import seat_direction

R_CRADLE, R_BAR = 10.3, 10.0


def _extruded(outline: list[tuple[float, float]], y0: float, y1: float):
    """The prism of an (x, z) outline between y = y0 and y = y1 (trimesh)."""
    import trimesh
    from shapely.geometry import Polygon

    m = trimesh.creation.extrude_polygon(Polygon(outline), y1 - y0)  # outline in x, y; height along z
    m.apply_transform(trimesh.transformations.rotation_matrix(np.pi / 2, [1, 0, 0]))  # z -> -y, y -> z
    m.apply_translation([0, y1, 0])
    assert m.is_watertight
    return m


def _arc(r: float, z0: float, a0: float, a1: float, n: int = 64) -> list[tuple[float, float]]:
    """Points of a circle of radius r about (0, z0) from angle a0 to a1 (x = r cos, z = z0 + r sin)."""
    return [(r * np.cos(a), z0 + r * np.sin(a)) for a in np.linspace(a0, a1, n)]


def _meshes() -> dict:
    """The block, bar and cap in the product frame (mm)."""
    import trimesh

    block = _extruded([(-30, 0), (30, 0), (30, 30), *_arc(R_CRADLE, 30, 0, -np.pi), (-30, 30)], -20, 20)
    cap = _extruded([(-30, 45), (-30, 30), *_arc(R_CRADLE, 30, np.pi, 0), (30, 30), (30, 45)], -20, 20)
    bar = trimesh.creation.cylinder(R_BAR, 60, sections=128)
    bar.apply_transform(trimesh.transformations.rotation_matrix(np.pi / 2, [1, 0, 0]))
    bar.apply_translation([0, 0, 30])
    return {"block": block, "bar": bar, "cap": cap}


@pytest.fixture(scope="module")
def cradle(tmp_path_factory: pytest.TempPathFactory):
    tmp = tmp_path_factory.mktemp("cradle")
    meshes = _meshes()
    lines = ["product: cradle", "units: {length: mm, angle: deg}", "base: block", "parts:"]
    for p, m in meshes.items():
        m.export(tmp / f"{p}.stl")
        lines.append(f"  {p}: {{mesh: {p}.stl}}")
    (tmp / "cradle.yaml").write_text("\n".join(lines) + "\n")
    return load_product_derived(tmp / "cradle.yaml", "mm", use_cache=False), meshes


def _lower_half_normal(bar) -> np.ndarray:
    """The mean outward normal (area-weighted) of the bar's wall below its axis: into the cradle."""
    c = bar.triangles_center
    wall = (np.abs(bar.face_normals[:, 1]) < 0.1) & (c[:, 2] < 30)
    n = (bar.face_normals[wall] * bar.area_faces[wall, None]).sum(0)
    return n / np.linalg.norm(n)


def _penetrates(mover, fixed, d: np.ndarray, travel: float, step: float, depth: float) -> bool:
    """Whether ``mover``'s surface samples pulled ``depth`` inward, moved from its pose back
    against ``d`` in steps of ``step`` up to ``travel``, ever lie inside ``fixed``."""
    import trimesh

    pts, tri = trimesh.sample.sample_surface(mover, 3000, seed=7)
    pts = pts - depth * mover.face_normals[tri]
    return any(fixed.contains(pts - t * d).any() for t in np.arange(0.0, travel + step, step))


def test_the_bar_goes_down_into_its_cradle_as_a_curved_seat(cradle) -> None:
    got, meshes = cradle
    seats = {(s.part, s.on): s for s in got.derived.seats}
    assert set(seats) == {("bar", "block"), ("cap", "block")}
    own = _lower_half_normal(meshes["bar"])
    assert np.allclose(own, [0, 0, -1], atol=1e-6)
    curved = seats["bar", "block"]
    assert curved.direction is not None and float(np.dot(curved.direction, own)) > 1 - 1e-6
    assert seats["cap", "block"].direction is None
    assert ("bar", "cap") in {tuple(sorted(b[:2])) for b in got.derived.blocking}
    order = [p for i in got.derived.insertions for p in i.parts]
    assert order == ["block", "bar", "cap"]
    assert ("bar", "cap") in {(a, b) for a, b, _ in got.derived.precedence}


def test_the_product_seat_carries_the_direction_and_the_goal_uses_it(cradle) -> None:
    got, meshes = cradle
    product = got.product
    seat = next(s for s in product.seats if s.part == "bar")
    assert seat.on == "block" and seat.face in product.parts["bar"].model.faces
    assert np.allclose(seat_direction(product, seat), _lower_half_normal(meshes["bar"]), atol=1e-6)
    goal = next(g for g in product.goals if g.part == "bar")
    assert goal.parent == "block"
    Rq = product.parts["block"].pose[:3, :3]
    assert np.allclose(Rq @ goal.V_a, [0, 0, -1], atol=1e-6)


def test_the_path_down_is_free_and_one_across_is_caught(cradle) -> None:
    got, meshes = cradle
    d = np.asarray(next(s for s in got.derived.seats if s.part == "bar").direction, float)
    assert not _penetrates(meshes["bar"], meshes["block"], d, 25.0, 0.25, 0.05)
    assert _penetrates(meshes["bar"], meshes["block"], np.array([1.0, 0, 0]), 25.0, 0.25, 0.05)


def test_kb_derive_writes_the_seat_direction_and_it_loads_back(cradle, tmp_path: Path) -> None:
    from spar_py.kb.products import derive_product_text

    got, _ = cradle
    src = Path(got.product.file)
    text = derive_product_text(src)
    assert "direction: [0.0, 0.0, -1.0]" in text
    out = src.parent / "written.yaml"
    out.write_text(text)
    again = load_product_derived(out, "mm", use_cache=False).product
    assert {(s.part, s.on, s.direction) for s in again.seats} == {(s.part, s.on, s.direction)
                                                                  for s in got.product.seats}


def test_plumbers_block_derives_with_the_bearing_down_in_its_cradle() -> None:
    """Fabrica's plumber's block: the bearing seats down in the block's cradle (the direction
    checked against the mean outward normal of the bearing's wall under its axis, read here),
    the cap on the block, the bolts through the cap into the block."""
    import trimesh

    fab = Path(__file__).resolve().parents[1] / "kb" / "products" / "fabrica"
    got = load_product_derived(fab / "plumbers_block.yaml", "mm")
    res = got.derived
    assert [p for i in res.insertions for p in i.parts] == ["block", "bearing", "cap", "bolt1", "bolt4"]
    seats = {(s.part, s.on): s for s in res.seats}
    assert set(seats) == {("bearing", "block"), ("cap", "block")}
    assert seats["cap", "block"].direction is None
    bearing = trimesh.load(fab / "plumbers_block" / "0.ply", force="mesh")
    bearing.apply_scale(10.0)  # cm -> mm
    zc = bearing.bounds.mean(0)[2]
    c, n = bearing.triangles_center, bearing.face_normals
    under = (np.abs(n[:, 1]) < 0.05) & (c[:, 2] < zc - 15.0) & (np.abs(c[:, 1]) < 15.0)
    own = (n[under] * bearing.area_faces[under, None]).sum(0)
    own /= np.linalg.norm(own)
    assert float(np.dot(seats["bearing", "block"].direction, own)) > 1 - 1e-3
    assert {(m.peg, m.hole) for m in res.mates} == {("bolt1", "block"), ("bolt1", "cap"), ("bolt4", "block"),
                                                   ("bolt4", "cap")}
    assert ("bearing", "cap") in {(a, b) for a, b, _ in res.precedence}
    assert ("bearing", "cap") in {(a, b) for a, b, _ in res.blocking}
    goal = next(g for g in got.product.goals if g.part == "bearing")
    assert goal.parent == "block"
    assert np.allclose(got.product.parts["block"].pose[:3, :3] @ goal.V_a, own, atol=1e-2)
