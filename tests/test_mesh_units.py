"""A mesh part written in metres, centimetres, millimetres or inches derives the same faces and
grasps, up to the unit (issue 43: a pin in metres got '36 grasps, 0 usable for the mate').

The same mesh (trimesh, here) is written as a binary STL in each unit: float32 vertices, so
the files differ by 1e-7 of a coordinate, not only by the scale. The shapes are ones where that
noise picked the result before: a gear blank (its rim and bore share a centroid: face names by
noise), a block with two bores (a pad backed off to exactly half its contact) and a rim closed
on from its end (exactly MIN_CONTACT_MM under the pad). Loaded in a mm cell and, for metres, also in a metre cell.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from spar_py.kb.objects import load_object

pytest.importorskip("trimesh")

#: mm per unit, as the units the files are written in.
UNITS = {"mm": 1.0, "cm": 10.0, "m": 1000.0, "in": 25.4}


def _cyl(r: float, z0: float, z1: float, x: float = 0.0):
    import trimesh

    return trimesh.creation.cylinder(radius=r, segment=[[x, 0, z0], [x, 0, z1]], sections=64)


def _gear():
    """A gear blank: a disc of radius 20, 10 thick, with a bore of radius 6.5."""
    return _cyl(20, 0, 10).difference(_cyl(6.5, -1, 11))


def _housing():
    """A block 120 x 80 x 40 with two blind bores of radius 8.01, 30 deep, 40 mm apart."""
    import trimesh

    b = trimesh.creation.box(bounds=[[-60, -40, 0], [60, 40, 40]])
    return b.difference(_cyl(8.01, 10, 41, x=-20)).difference(_cyl(8.01, 10, 41, x=20))


SHAPES = {"gear": _gear, "housing": _housing}


def _write(tmp: Path, name: str, mesh, unit: str) -> Path:
    """The mesh (mm) as ``name_UNIT.stl`` in ``unit`` and an object file declaring that unit."""
    m = mesh.copy()
    m.apply_scale(1.0 / UNITS[unit])
    m.export(tmp / f"{name}_{unit}.stl")
    out = tmp / f"{name}_{unit}.yaml"
    out.write_text(f"object: {name}\nunits: {{length: {unit}, angle: deg}}\nmesh: {name}_{unit}.stl\n")
    return out


def _same(a, b, scale: float) -> None:
    """Models ``a`` (mm) and ``b`` (lengths times ``scale`` give mm) have the same faces and grasps."""
    assert b.faces == a.faces
    assert [(g.label, g.gfaces, g.ofaces) for g in b.grasps.values()] == [
        (g.label, g.gfaces, g.ofaces) for g in a.grasps.values()]
    for ga, gb in zip(a.grasps.values(), b.grasps.values()):
        assert gb.width * scale == pytest.approx(ga.width, abs=1e-4)
        assert np.allclose(gb.T[:3, 3] * scale, ga.T[:3, 3], atol=1e-4)
        assert np.allclose(gb.T[:3, :3], ga.T[:3, :3], atol=1e-6)


@pytest.mark.parametrize("shape", sorted(SHAPES))
def test_a_mesh_part_gets_the_same_grasps_in_any_unit(tmp_path: Path, shape: str) -> None:
    mesh = SHAPES[shape]()
    models = {u: load_object(_write(tmp_path, shape, mesh, u), "mm", use_cache=False) for u in UNITS}
    ref = models["mm"]
    assert ref.grasps
    for u, m in models.items():
        _same(ref, m, 1.0)
    in_m = load_object(tmp_path / f"{shape}_m.yaml", "m", use_cache=False)  # a cell in metres
    _same(ref, in_m, 1000.0)


def test_the_gear_is_closed_on_across_its_rim_from_every_side(tmp_path: Path) -> None:
    """The gear's grasps, in any unit: across its faces (10 mm) and across its rim (a round of
    radius 20: 40 mm), the rim also from above and below (a pad on 5 mm of the 10 mm rim,
    MIN_CONTACT_MM: lost in metres and inches before)."""
    for u in UNITS:
        m = load_object(_write(tmp_path, "gear", _gear(), u), "mm", use_cache=False)
        widths = sorted({round(g.width, 3) for g in m.grasps.values()})
        assert widths == [10.0, 40.0], (u, widths)
        rim = [g for g in m.grasps.values() if abs(g.width - 40.0) < 1e-3]
        assert any(abs(g.T[2, 2]) > 1 - 1e-9 for g in rim), u  # tool z (the approach) along the axis
