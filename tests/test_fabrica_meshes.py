"""Fabrica's vendored parts (kb/products/fabrica): each loads closed, with a positive volume,
and gets grasps checked by our own ray casting; a mesh open along a cut is refused in one line,
a mesh with seams, a missing triangle and a flipped one is repaired and says so."""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from spar_py.core.errors import KBError
from spar_py.kb.objects import load_object, mesh_note
from spar_py.world.parts.mesh import load_mesh

trimesh = pytest.importorskip("trimesh")

ROOT = Path(__file__).resolve().parents[1] / "kb" / "products" / "fabrica"
PARTS = sorted(ROOT.glob("*/*.ply"))
OPENING_MM = 100.0


def _model(tmp_path: Path, mesh: Path, unit: str = "cm") -> Path:
    p = tmp_path / f"{mesh.parent.name}_{mesh.stem}.yaml"
    p.write_text(f"object: {mesh.parent.name}_{mesh.stem}\nunits: {{length: {unit}, angle: deg}}\nmesh: {mesh}\n")
    return p


def _raw(path: Path) -> "trimesh.Trimesh":
    """The file as trimesh reads it, exact duplicates merged, in mm (cm files scaled)."""
    m = trimesh.load(str(path), force="mesh", process=True)
    m.apply_scale(10.0)
    return m


def _plainly_holdable(m: "trimesh.Trimesh", opening: float) -> bool:
    """Our own test: some width across the part, between two opposite surface points whose
    normals are antiparallel within 15 deg, is below the opening, with a 5 mm patch of surface on
    both sides (rays along the closing line, plain numpy triangle intersection)."""
    from trimesh.ray.ray_triangle import RayMeshIntersector

    rays = RayMeshIntersector(m)
    P, fi = trimesh.sample.sample_surface(m, 400, seed=7)
    n = m.face_normals[fi]
    loc, ri, ti = rays.intersects_location(P - 1e-6 * n, -n, multiple_hits=False)
    for k, r in enumerate(ri):
        w = float(np.linalg.norm(loc[k] - P[r]))
        if 1.0 < w < opening and m.face_normals[ti[k]] @ -n[r] > math.cos(math.radians(15)):
            return True
    return False


#: The default gripper's fingers are 10 mm thick (kb.objects; world.robot.Gripper.of_unit).
FINGER_THICKNESS_MM = 10.0
#: The default gripper's pad (kb.objects: fingers 20 mm wide, 60 mm long), probed on a grid of
#: (across, from the tip) offsets in the tool frame, mm: 1 mm apart over the 20 mm nearest the
#: tip (a contact on a 1.5 mm rim is found), 2 mm beyond.
PAD_ACROSS_MM = np.arange(-9.5, 10.0, 1.0)
PAD_ALONG_MM = -np.r_[np.arange(0.5, 20.0, 1.0), np.arange(21.0, 60.0, 2.0)]


def _pads_touch(m: "trimesh.Trimesh", grasps: list, tol: float = 0.5) -> list[str]:
    """Independent check of grasps (label, T, width): lines along the closing axis (tool y)
    through a grid of points of each pad (PAD_ACROSS_MM x PAD_ALONG_MM) meet no surface inside
    the finger (from width/2 + tol to width/2 + FINGER_THICKNESS_MM out from the centre), and
    some of them meet the surface nearest the pad within tol of it (width/2), where its normal
    faces that pad within 25 deg: both pads touch surface squarely, with nothing through them.
    Plain numpy: each line against every triangle under the pad, in the tool's (x, z) plane by
    barycentric coordinates. Returns the labels of the grasps that fail."""
    V0, F, N0 = np.asarray(m.vertices, float), np.asarray(m.faces), np.asarray(m.face_normals, float)
    gx, gz = np.meshgrid(PAD_ACROSS_MM, PAD_ALONG_MM, indexing="ij")
    gx, gz = gx.ravel(), gz.ravel()
    cos25 = math.cos(math.radians(25))
    bad = []
    for label, T, width in grasps:
        R, o = T[:3, :3], T[:3, 3]
        tri = ((V0 - o) @ R)[F]  # (n, 3, 3) in the tool frame
        lo, hi = tri.min(1), tri.max(1)
        near = np.flatnonzero((hi[:, 0] >= gx.min()) & (lo[:, 0] <= gx.max()) & (hi[:, 2] >= gz.min())
                              & (lo[:, 2] <= gz.max()))
        t = tri[near]
        a, b, c = t[:, 0], t[:, 1], t[:, 2]
        det = (b[:, 0] - a[:, 0]) * (c[:, 2] - a[:, 2]) - (c[:, 0] - a[:, 0]) * (b[:, 2] - a[:, 2])
        keep = np.abs(det) > 1e-12  # triangles seen edge-on along y are met by no line
        a, b, c, det, near = a[keep], b[keep], c[keep], det[keep], near[keep]
        px, pz = gx[:, None] - a[None, :, 0], gz[:, None] - a[None, :, 2]  # (probes, triangles)
        u = (px * (c[:, 2] - a[:, 2]) - pz * (c[:, 0] - a[:, 0])) / det
        v = (pz * (b[:, 0] - a[:, 0]) - px * (b[:, 2] - a[:, 2])) / det
        inside = (u >= -1e-9) & (v >= -1e-9) & (u + v <= 1 + 1e-9)
        y = a[:, 1] + u * (b[:, 1] - a[:, 1]) + v * (c[:, 1] - a[:, 1])
        ok = True
        for sign in (1.0, -1.0):
            out = np.where(inside, sign * y, -np.inf)  # distance out from the centre towards this pad
            if ((out > width / 2 + tol) & (out < width / 2 + FINGER_THICKNESS_MM)).any():
                ok = False  # the part inside the finger
                continue
            out[out > width / 2 + tol] = -np.inf  # surface beyond the finger's back
            k = out.argmax(1)  # the surface each line meets first coming from the pad
            d = out[np.arange(len(gx)), k]
            met = np.isfinite(d)
            n = N0[near[k[met]]] @ R[:, 1] * sign
            on = np.abs(d[met] - width / 2) <= tol
            if not (n[on] > cos25).any():
                ok = False
        if not ok:
            bad.append(label)
    return bad


def test_there_are_the_seven_assemblies() -> None:
    counts = {d.name: len(list(d.glob("*.ply"))) for d in ROOT.iterdir() if d.is_dir()}
    assert counts == {"beam": 5, "plumbers_block": 5, "car": 6, "gamepad": 6, "cooling_manifold": 7, "duct": 8,
                      "stool_circular": 9}
    assert (ROOT / "LICENSE").read_text().startswith("MIT License")


@pytest.mark.slow
@pytest.mark.parametrize("part", PARTS, ids=[f"{p.parent.name}/{p.stem}" for p in PARTS])
def test_part_loads_closed_and_holdable_parts_get_checked_grasps(tmp_path: Path, part: Path) -> None:
    small, _ = load_mesh(str(part), 1.0)  # the file's cm read as mm: 10x smaller, repaired alike
    assert small.is_watertight and small.volume == pytest.approx(abs(_raw(part).volume) / 1000, rel=1e-6)
    model = load_object(_model(tmp_path, part), "mm", opening=OPENING_MM)
    mesh = model.geometry.mesh()
    assert mesh.is_watertight and mesh.is_winding_consistent and mesh.volume > 0
    raw = _raw(part)
    assert mesh.volume == pytest.approx(abs(raw.volume), rel=1e-6)  # nothing repaired away
    if _plainly_holdable(raw, OPENING_MM):
        assert model.grasps, f"{part}: {model.geometry.no_grasp}"
    for g in model.grasps.values():
        assert g.width <= OPENING_MM + 1e-9
    bad = _pads_touch(raw, [(g.label, g.T, g.width) for g in model.grasps.values()])
    assert not bad, f"{part}: pads off the surface in {bad}"


def test_beam_gets_a_grasp_across_its_12_7_mm_faces(tmp_path: Path) -> None:
    beam = load_object(_model(tmp_path, ROOT / "beam" / "0.ply"), "mm", opening=OPENING_MM)
    assert any(abs(g.width - 12.7) < 0.05 for g in beam.grasps.values())


def test_car_part_0_gets_grasps_across_its_35_mm_round(tmp_path: Path) -> None:
    """Car part 0 is a 35 mm wheel on a 10 mm axle along y: beside the axle's shaft grasps it
    gets grasps across the wheel's diameter (own check: closing normal to the axle, both pads
    on the tyre, 35 mm apart within 0.5 mm: a chord as long as the diameter)."""
    part = ROOT / "car" / "0.ply"
    car = load_object(_model(tmp_path, part), "mm", opening=OPENING_MM)
    raw = _raw(part)
    assert np.allclose(raw.extents, 35.0, atol=0.1)
    across = [g for g in car.grasps.values() if abs(g.width - 35.0) < 0.5 and abs(g.T[1, 1]) < 0.02]
    assert across and any(abs(g.width - 10.0) < 1e-3 for g in car.grasps.values())
    assert _pads_touch(raw, [(g.label, g.T, g.width) for g in across]) == []
    # the axle's shaft grasps come first, those across the tyre after them (a shaft
    # grasp straight down onto the axle with the wheel lying on its tyre is among the last, as
    # every grasp backed off the table for a pose is)
    shaft = sorted(int(g.label.rsplit("g", 1)[1]) for g in car.grasps.values() if abs(g.width - 10.0) < 1e-3)
    lead = [n for i, n in enumerate(shaft, 1) if n == i]  # g1, g2, ...: the candidates' pass
    nums = [int(g.label.rsplit("g", 1)[1]) for g in across]
    assert lead and all(n > lead[-1] for n in nums) and all(n > max(nums) for n in shaft[len(lead):])


def test_the_pad_check_refuses_a_grasp_moved_off_the_part(tmp_path: Path) -> None:
    """The independent check fails on a real grasp shifted 2 mm along its closing axis (one pad
    in the part, the other off it), opened 2 mm wider, or turned 30 deg about its approach."""
    part = ROOT / "beam" / "0.ply"
    beam = load_object(_model(tmp_path, part), "mm", opening=OPENING_MM)
    raw = _raw(part)
    g = next(g for g in beam.grasps.values() if abs(g.width - 12.7) < 0.05)
    assert _pads_touch(raw, [(g.label, g.T, g.width)]) == []
    shifted = g.T.copy()
    shifted[:3, 3] += 2.0 * g.T[:3, 1]
    c, s = math.cos(math.radians(30)), math.sin(math.radians(30))
    turned = g.T.copy()
    turned[:3, :3] = g.T[:3, :3] @ np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    assert _pads_touch(raw, [("shifted", shifted, g.width), ("wider", g.T, g.width + 2.0),
                             ("turned", turned, g.width)]) == ["shifted", "wider", "turned"]


def test_seams_a_hole_and_a_flipped_triangle_are_repaired_and_said(tmp_path: Path) -> None:
    box = trimesh.creation.box(extents=[40.0, 30.0, 20.0])
    cyl = trimesh.creation.cylinder(radius=10.0, height=30.0, sections=48)
    # seams: every triangle its own corners, moved by up to 1e-6 of the size (not exact duplicates)
    V = cyl.vertices[cyl.faces].reshape(-1, 3)
    V = V + np.random.default_rng(1).uniform(-3e-5, 3e-5, V.shape)
    F = np.arange(len(V)).reshape(-1, 3)
    F = np.delete(F, 7, axis=0)                 # a missing triangle
    F[11] = F[11][::-1]                         # a flipped one
    path = tmp_path / "seams.ply"
    trimesh.Trimesh(V, F, process=False).export(path)
    model = load_object(_model(tmp_path, path, "mm"), "mm")
    mesh = model.geometry.mesh()
    assert mesh.is_watertight and mesh.is_winding_consistent
    assert mesh.volume == pytest.approx(cyl.volume, rel=1e-3)
    note = mesh_note(model)
    merged = 3 * (len(cyl.faces) - 1) - len(cyl.vertices)  # every corner kept once per triangle, less the originals
    assert note is not None and note.endswith(f"seams.ply: repaired: merged {merged:,} seam vertices within 1e-05 of "
                                              "the part's size, filled 1 hole, fixed winding")
    box.export(tmp_path / "box.stl")
    assert mesh_note(load_object(_model(tmp_path, tmp_path / "box.stl", "mm"), "mm")) is None


def test_a_cut_mesh_is_refused_in_one_line(tmp_path: Path) -> None:
    cyl = trimesh.creation.cylinder(radius=10.0, height=30.0, sections=48)
    half = trimesh.Trimesh(cyl.vertices, cyl.faces[cyl.triangles_center[:, 0] > 0], process=True)
    path = tmp_path / "half.stl"
    half.export(path)
    with pytest.raises(KBError) as e:
        load_object(_model(tmp_path, path, "mm"), "mm")
    msg = str(e.value)
    assert "\n" not in msg
    assert msg.endswith("half.yaml: mesh: expected a closed (watertight) mesh: 6 edges stay open, around [0, 0, 0] "
                        "(from [0, -10, -15] to [0, 10, 15], the part's frame, cell unit); holes wider than 0.02 of "
                        "the part's size are not filled")


def test_a_part_too_wide_says_its_width_and_the_opening(tmp_path: Path) -> None:
    from spar_py.kb.objects import holdable

    trimesh.creation.box(extents=[150.0, 160.0, 170.0]).export(tmp_path / "big.stl")
    p = _model(tmp_path, tmp_path / "big.stl", "mm")
    model = load_object(p, "mm", opening=100.0)
    assert not model.grasps
    with pytest.raises(KBError, match=r"big\.yaml: mesh: expected a part the gripper can hold, as a goal moves it "
                                      r"\(its narrowest width across opposite surfaces \(within 12 deg\) is 150 mm, "
                                      r"more than the gripper's opening 100 mm\)$"):
        holdable(p, model)
