"""Prismatic fits and cradles in the derivation (world.product.assembly), on meshes made here: a box
peg in a box socket, a round bar in a half-cylinder cradle. Geometry is checked against the
boxes' own numbers, not the derivation's."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

trimesh = pytest.importorskip("trimesh")

from spar_py.world.product.assembly import derive_assembly  # noqa: E402

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


def _bar_in_cradle() -> dict[str, "trimesh.Trimesh"]:
    """A round bar (radius 10) lying in a block's half-cylinder trough (radius 10.3)."""
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
    return {"cradle": cradle, "bar": bar}


def test_half_cylinder_cradle_is_no_round_mate_but_a_curved_seat() -> None:
    res = derive_assembly(_bar_in_cradle(), "cradle", 0.1, 0.5)
    assert not [m for m in res.mates if m.profile == "round"], res.mates
    assert res.blocking == []
    (seat,) = res.seats
    assert (seat.part, seat.on) == ("bar", "cradle")
    assert seat.direction is not None and np.allclose(seat.direction, (0, 0, -1), atol=1e-9)


def test_a_part_held_only_by_a_cradle_loads_with_its_curved_seat(tmp_path: Path) -> None:
    from spar_py.kb.products import load_product

    for name, m in _bar_in_cradle().items():
        m.export(tmp_path / f"{name}.stl")
    (tmp_path / "p.yaml").write_text("product: cradled\nunits: {length: mm, angle: deg}\nparts:\n"
                                     "  cradle: {mesh: cradle.stl}\n  bar: {mesh: bar.stl}\n")
    product = load_product(tmp_path / "p.yaml", "mm", use_cache=False)
    (goal,) = product.goals
    assert (goal.part, goal.parent) == ("bar", "cradle")
    assert np.allclose(product.parts["cradle"].pose[:3, :3] @ goal.V_a, (0, 0, -1), atol=1e-9)


# --------------------------------------------------------------------------- Fabrica's beam

BEAM = Path(__file__).resolve().parents[1] / "kb" / "products" / "fabrica" / "beam"
#: The beam's parts (Fabrica's file stems): plates 0, 1 on top, posts 2, 3, the beam 6 below.
POSTS, SOCKETS = ("p2", "p3"), ("p0", "p1", "p6")


def _beam() -> dict[str, "trimesh.Trimesh"]:
    """Fabrica's beam as trimesh reads its files, in mm (the files are in cm)."""
    out = {}
    for f in sorted(BEAM.glob("*.ply")):
        m = trimesh.load(str(f), force="mesh", process=True)
        m.apply_scale(10.0)
        out[f"p{f.stem}"] = m
    return out


def _section_points(mesh: "trimesh.Trimesh", z: float) -> np.ndarray:
    """The points where the plane at height ``z`` cuts the mesh's triangles (k, 2: x, y)."""
    seg = trimesh.intersections.mesh_plane(mesh, (0, 0, 1), (0, 0, z))
    return np.asarray(seg, float).reshape(-1, 3)[:, :2]


def _measured_fit(post: "trimesh.Trimesh", block: "trimesh.Trimesh") -> tuple[np.ndarray, float]:
    """Our own measure of a post's tenon in a block's socket, from plane sections across the
    vertical at levels inside their overlap (1.5 mm clear of each end: the lead-in chamfers):
    the socket's centre (x, y) and the least gap of a tenon side to the socket's wall."""
    lo = max(post.bounds[0, 2], block.bounds[0, 2]) + 1.5
    hi = min(post.bounds[1, 2], block.bounds[1, 2]) - 1.5
    centres, gaps = [], []
    for z in np.linspace(lo, hi, 7):
        tenon = _section_points(post, z)
        c = (tenon.min(0) + tenon.max(0)) / 2
        S = _section_points(block, z)
        S = S[np.all(np.abs(S - c) < (tenon.max(0) - tenon.min(0)) / 2 + 1.5, axis=1)]  # the socket's walls
        centres.append((S.min(0) + S.max(0)) / 2)
        gaps += list(S.max(0) - tenon.max(0)) + list(tenon.min(0) - S.min(0))
    return np.mean(centres, axis=0), float(min(gaps))


def test_beam_derives_a_prism_mate_per_post_socket() -> None:
    meshes = _beam()
    res = derive_assembly(meshes, "p0", 0.1, 0.5)
    size = float(np.max(meshes["p2"].extents))  # the post's length, 76.2 mm
    found = {}
    for m in res.mates:
        assert m.profile == "prism" and m.peg in POSTS and m.hole in SOCKETS, m
        found[m.peg, m.hole] = m
    assert set(found) == {("p2", "p0"), ("p2", "p6"), ("p3", "p1"), ("p3", "p6")}
    for (post, block), m in found.items():
        centre, gap = _measured_fit(meshes[post], meshes[block])
        assert 0.2 < gap < 0.35  # the sections' own number: a clearance fit of about 0.27 mm
        assert abs(abs(m.axis[2]) - 1) < 1e-3
        assert np.allclose(np.asarray(m.origin)[:2], centre, atol=1e-3 * size), (post, block)
        assert abs((m.hole_radius - m.peg_radius) - gap) < 1e-3 * size, (post, block, m, gap)


# --------------------------------------------------------------------------- the corner check


def _key_in_slot(turn_deg: float) -> tuple[list, list[bool]]:
    """A flat key (4 x 1, tip 2 from its origin) held over a slot 0.1 wider on each side, the
    only error the grasp's turn about the tool's z (the key's axis: the fingers re-seat the
    key, the manipulator's angle error stays), up to ``turn_deg``: the insertion constraints
    (tip centre, then the four tip corners) and their verdicts."""
    from spar_py.core import geometry
    from spar_py.core.model import Bounds, MatingFeature
    from spar_py.phase2.symbolic import Registry
    from spar_py.phase2.uncertainty import ObjectState, WorldState, assemble_constraints, evaluate, pickup, table_error

    zero = Bounds((0, 0), (0, 0), (0, 0), (0, 0))
    turn = Bounds((0, 0), (0, 0), (0, 0), (-np.radians(turn_deg), np.radians(turn_deg)))
    reg = Registry()
    objs = {"block": ObjectState("block", "table", geometry.trans(20, 0, 1), table_error(reg, "block", zero)),
            "key": ObjectState("key", "table", geometry.trans(20, 10, 1), table_error(reg, "key", zero))}
    w = WorldState(reg, turn, objs)
    w = pickup(w, "key", geometry.rotx(np.pi), w.manipulator_error())
    tip = np.array([0.0, 0.0, 2.0])
    corners = tip + np.array([[KEY_HX, KEY_HY, 0], [-KEY_HX, KEY_HY, 0], [-KEY_HX, -KEY_HY, 0], [KEY_HX, -KEY_HY, 0]])
    key = MatingFeature("peg", ("tip",), KEY_HY, tip, profile="prism", corners=corners)
    slot = MatingFeature("hole", ("top",), KEY_HY + SLOT_GAP, np.zeros(3), profile="prism",
                         corners=np.array([[KEY_HX + SLOT_GAP, KEY_HY + SLOT_GAP, 0]]))
    cs = assemble_constraints(w, "key", "block", geometry.trans(0, 0, -2), key, slot, axis=np.array([0.0, 0, -1]))
    return cs, [bool(evaluate(c, w.registry).satisfied) for c in cs]


KEY_HX, KEY_HY, SLOT_GAP = 2.0, 0.5, 0.1


def _corner_leaves_slot(turn_deg: float) -> bool:
    """Our own geometry: the key's tip corner (KEY_HX, KEY_HY) turned about the axis by
    ``turn_deg`` lies outside the slot (half-widths KEY_HX + gap, KEY_HY + gap)."""
    a = np.radians(turn_deg)
    x, y = np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]]) @ (KEY_HX, KEY_HY)
    return bool(abs(x) > KEY_HX + SLOT_GAP or abs(y) > KEY_HY + SLOT_GAP)


def test_a_turn_about_the_axis_alone_fails_the_corners_not_the_centre() -> None:
    assert _corner_leaves_slot(5.0) and not _corner_leaves_slot(0.5)
    cs, ok = _key_in_slot(5.0)
    assert len(cs) == 5 and cs[0].name == "centres" and all(c.name.startswith("corner") for c in cs[1:])
    assert ok[0], "the tip centre is on the axis: a turn about it does not move it"
    assert not all(ok[1:]), "a corner turned 5 deg leaves the slot"
    cs, ok = _key_in_slot(0.5)
    assert all(ok), "turned 0.5 deg the corners stay inside"


# --------------------------------------------------------------------------- guides


def _box(lo: tuple[float, float, float], hi: tuple[float, float, float]) -> "trimesh.Trimesh":
    lo_, hi_ = np.asarray(lo, float), np.asarray(hi, float)
    b = trimesh.creation.box(extents=hi_ - lo_)
    b.apply_translation((lo_ + hi_) / 2)
    return b


def test_a_plane_the_insertion_slides_along_is_no_seat() -> None:
    """A slider put down on a plate beside a guide block it touches: it seats on the plate;
    the guide's side, parallel to its way down, is a blocking contact, not a seat."""
    meshes = {"base": _box((-40, -20, -5), (40, 20, 0)), "guide": _box((-30, -10, 0), (0, 10, 15)),
              "slider": _box((0, -10, 0), (20, 10, 10))}
    res = derive_assembly(meshes, "base", 0.1, 0.5)
    order = [p for i in res.insertions for p in i.parts]
    assert order.index("slider") > order.index("guide")
    d = {p: np.asarray(i.direction) for i in res.insertions for p in i.parts}
    assert abs(d["slider"][2] + 1) < 1e-9  # put down, along -z: parallel to the guide's side
    seats = {(s.part, s.on): np.asarray(s.normal) for s in res.seats}
    assert ("slider", "guide") not in seats and ("guide", "slider") not in seats
    assert np.allclose(seats["slider", "base"], (0, 0, 1)) and np.allclose(seats["guide", "base"], (0, 0, 1))
    assert ("guide", "slider") in {(a, b) for a, b, _ in res.blocking}
