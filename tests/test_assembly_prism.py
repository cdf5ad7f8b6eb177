"""Prismatic fits and cradles in the derivation (world.assembly), on meshes made here: a box
peg in a box socket, a round bar in a half-cylinder cradle. Geometry is checked against the
boxes' own numbers, not the derivation's."""
from __future__ import annotations

import numpy as np
import pytest

trimesh = pytest.importorskip("trimesh")

from spar_py.world.assembly import derive_assembly  # noqa: E402

#: The socket block: 40 x 40 x 20 mm, a 12 x 8 mm socket 12 deep from its top; the peg 11.6 x
#: 7.6 (clearance 0.2 per side) with a 20 x 20 x 5 head on the block's top.
PEG_HX, PEG_HY, GAP = 5.8, 3.8, 0.2


def _socket_block() -> "trimesh.Trimesh":
    """The block with its socket, as a closed mesh built from boxes (no boolean engine):
    the block split around the socket's footprint into four slabs and a floor."""
    hx, hy = PEG_HX + GAP, PEG_HY + GAP
    slabs = [((-20, -20, 0), (20, 20, 8)),                      # floor under the socket
             ((-20, -20, 8), (-hx, 20, 20)), ((hx, -20, 8), (20, 20, 20)),
             ((-hx, -20, 8), (hx, -hy, 20)), ((-hx, hy, 8), (hx, 20, 20))]
    boxes = []
    for lo, hi in slabs:
        lo, hi = np.asarray(lo, float), np.asarray(hi, float)
        b = trimesh.creation.box(extents=hi - lo)
        b.apply_translation((lo + hi) / 2)
        boxes.append(b)
    return _merge(boxes)


def _merge(boxes: list) -> "trimesh.Trimesh":
    """The boxes as one mesh (touching, not overlapping: the contacts sample outer faces)."""
    m = trimesh.util.concatenate(boxes)
    m.merge_vertices()
    return m


def _peg() -> "trimesh.Trimesh":
    """The peg: its shaft in the socket down to 0.0 above the floor, its head on the block."""
    shaft = trimesh.creation.box(extents=(2 * PEG_HX, 2 * PEG_HY, 12.0))
    shaft.apply_translation((0, 0, 8 + 6.0))
    head = trimesh.creation.box(extents=(20, 20, 5))
    head.apply_translation((0, 0, 22.5))
    return _merge([shaft, head])


def test_box_peg_in_box_socket_is_one_prism_mate() -> None:
    res = derive_assembly({"block": _socket_block(), "peg": _peg()}, "block", 0.1, 0.5)
    prisms = [m for m in res.mates if m.profile == "prism"]
    assert len(prisms) == 1, res.mates
    m = prisms[0]
    assert (m.peg, m.hole) == ("peg", "block")
    size = 40.0
    assert abs(abs(m.axis[2]) - 1) < 1e-3
    assert abs(m.peg_radius - PEG_HY) < 1e-3 * size
    assert abs(m.hole_radius - m.peg_radius - GAP) < 1e-3 * size
    C = np.abs(np.asarray(m.corners))
    assert C.shape == (4, 3)
    assert np.allclose(np.sort(C[:, :2], axis=1), [[PEG_HY, PEG_HX]] * 4, atol=1e-3 * size)
    assert np.allclose(np.asarray(m.origin)[:2], 0.0, atol=1e-3 * size)


def test_half_cylinder_cradle_is_no_round_mate() -> None:
    bar = trimesh.creation.cylinder(radius=10.0, height=60.0, sections=64)
    bar.apply_transform(trimesh.transformations.rotation_matrix(np.pi / 2, (1, 0, 0)))
    bar.apply_translation((0, 0, 20.0))
    # a block with a half-cylinder trough of radius 10.3 along y, its axis at z = 20 (top face)
    block = trimesh.creation.box(extents=(40, 40, 20))
    block.apply_translation((0, 0, 10.0))
    cutter = trimesh.creation.cylinder(radius=10.3, height=80.0, sections=64)
    cutter.apply_transform(trimesh.transformations.rotation_matrix(np.pi / 2, (1, 0, 0)))
    cutter.apply_translation((0, 0, 20.0))
    try:
        cradle = block.difference(cutter)
    except Exception as e:  # no boolean engine installed
        pytest.skip(f"no mesh boolean: {e}")
    res = derive_assembly({"cradle": cradle, "bar": bar}, "cradle", 0.1, 0.5)
    assert not [m for m in res.mates if m.profile == "round"], res.mates
