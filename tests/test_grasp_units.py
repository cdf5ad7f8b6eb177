"""The derived grasps of a part do not depend on the length unit its file is written in: a headed
pin (two cylinder primitives, booleans by manifold3d in float32) written in mm and in inches gets
the same grasps, positions and widths scaled by 25.4, for heads of any height."""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from spar_py.kb.objects import load_object

pytest.importorskip("trimesh")

MM_PER_IN = 25.4


def _pin(tmp_path: Path, head_mm: float, unit: str) -> Path:
    """A pin: head radius 8 mm, ``head_mm`` high from z = 0; shaft radius 5 mm, 17 mm long on it."""
    s = 1.0 if unit == "mm" else 1.0 / MM_PER_IN
    h, top = head_mm * s, (head_mm + 17.0) * s
    axis = f"{{origin: [0, 0, {h!r}], direction: [0, 0, 1]}}"
    p = tmp_path / f"pin_{unit}_{head_mm:g}.yaml"
    p.write_text(f"""object: pin
units: {{length: {unit}, angle: deg}}
shape:
  - {{cylinder: {{radius: {8 * s!r}, z: [0, {h!r}]}}}}
  - {{cylinder: {{radius: {5 * s!r}, z: [{h!r}, {top!r}]}}}}
features:
  - {{kind: peg, name: shaft, radius: {5 * s!r}, axis: {axis}, length: {17 * s!r}}}
""")
    return p


@pytest.mark.parametrize("head_mm", [12.0, 16.0, 20.0])
def test_a_headed_pin_gets_the_same_grasps_in_mm_and_in_inches(tmp_path: Path, head_mm: float) -> None:
    mm = load_object(_pin(tmp_path, head_mm, "mm"), "mm")
    inch = load_object(_pin(tmp_path, head_mm, "in"), "in")
    # both the head (16 mm across) and the shaft (10 mm across) are closed on, in either unit
    for m, s in ((mm, 1.0), (inch, MM_PER_IN)):
        widths = sorted({round(g.width * s, 6) for g in m.grasps.values()})
        assert widths == [10.0, 16.0], widths
        for g in m.grasps.values():
            y, p = g.T[:3, 1], g.T[:3, 3] * s  # closing direction, tool centre in mm
            assert abs(y[2]) < 1e-9  # closing across the axis (own check: the pin's axis is z)
            if round(g.width * s, 6) == 10.0:
                assert head_mm < p[2] < head_mm + 17.0 and math.hypot(p[0], p[1]) < 1e-6
    assert [g.label for g in mm.grasps.values()] == [g.label for g in inch.grasps.values()]
    for a, b in zip(mm.grasps.values(), inch.grasps.values()):
        assert a.gfaces == b.gfaces and a.ofaces == b.ofaces
        assert b.width * MM_PER_IN == pytest.approx(a.width, abs=1e-5)
        assert np.allclose(b.T[:3, 3] * MM_PER_IN, a.T[:3, 3], atol=1e-5)
        assert np.allclose(b.T[:3, :3], a.T[:3, :3], atol=1e-9)


@pytest.mark.xfail(strict=True, reason="a round side's grasp from above (world.parts.shafts.shaft_from_above) "
                   "slides to a different place along car_0's axle in inches than in mm, and one grasp "
                   "more is found in mm: a unit-dependent tolerance not yet found")
def test_a_fabrica_part_gets_the_same_faces_and_grasps_in_mm_and_in_inches(tmp_path: Path) -> None:
    """Car part 0 (a wheel on an axle, every face's centroid on one axis, so their order is
    decided by rounding) names its faces alike and gets the same grasps in either cell unit."""
    ply = Path(__file__).resolve().parents[1] / "kb" / "products" / "fabrica" / "car" / "0.ply"
    p = tmp_path / "car_0.yaml"
    p.write_text(f"object: car_0\nunits: {{length: cm, angle: deg}}\nmesh: {ply}\n")
    mm = load_object(p, "mm", opening=100.0)
    inch = load_object(p, "in", opening=100.0 / MM_PER_IN)
    assert mm.faces == inch.faces
    assert [(g.label, g.gfaces, g.ofaces) for g in mm.grasps.values()] == [
        (g.label, g.gfaces, g.ofaces) for g in inch.grasps.values()]
    for a, b in zip(mm.grasps.values(), inch.grasps.values()):
        assert b.width * MM_PER_IN == pytest.approx(a.width, abs=1e-5)
        assert np.allclose(b.T[:3, 3] * MM_PER_IN, a.T[:3, 3], atol=1e-5)
    for a, b in zip(mm.poses.values(), inch.poses.values()):
        assert (a.label, a.rfaces, a.ofaces) == (b.label, b.rfaces, b.ofaces)
