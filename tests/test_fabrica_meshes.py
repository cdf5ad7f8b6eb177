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


def _pads_touch(m: "trimesh.Trimesh", T: np.ndarray, width: float) -> bool:
    """Independent check of one grasp: from each finger's side, rays along the closing axis
    (tool y) through points of the pad near the tool centre meet the surface about width/2 from
    the centre, with normals antiparallel to each other within 15 deg."""
    from trimesh.ray.ray_triangle import RayMeshIntersector

    rays = RayMeshIntersector(m)
    y, z, o = T[:3, 1], T[:3, 2], T[:3, 3]
    far = 2 * float(np.linalg.norm(m.extents)) + width
    got = []
    for sign in (1.0, -1.0):
        hits = []
        for dz in (-0.5, -1.0, -2.0, -3.0, -5.0):  # along the pad, from the tip towards the palm
            start = o + dz * z + sign * far * y
            loc, _, ti = rays.intersects_location(start[None], (-sign * y)[None], multiple_hits=False)
            if len(loc) and abs(float((loc[0] - o) @ y) * sign - width / 2) < 0.05 * width + 0.6:
                hits.append(m.face_normals[ti[0]])
        if not hits:
            return False
        got.append(hits[0])
    return bool(got[0] @ -got[1] > math.cos(math.radians(25)) and got[0] @ y > 0.8 and got[1] @ -y > 0.8)


def test_there_are_the_seven_assemblies() -> None:
    counts = {d.name: len(list(d.glob("*.ply"))) for d in ROOT.iterdir() if d.is_dir()}
    assert counts == {"beam": 5, "plumbers_block": 5, "car": 6, "gamepad": 6, "cooling_manifold": 7, "duct": 8,
                      "stool_circular": 9}
    assert (ROOT / "LICENSE").read_text().startswith("MIT License")


@pytest.mark.slow
@pytest.mark.parametrize("part", PARTS, ids=[f"{p.parent.name}/{p.stem}" for p in PARTS])
def test_part_loads_closed_and_holdable_parts_get_checked_grasps(tmp_path: Path, part: Path) -> None:
    m = load_object(_model(tmp_path, part, "mm"), "mm", opening=OPENING_MM)  # the file's cm read as mm: 10x smaller
    del m
    model = load_object(_model(tmp_path, part), "mm", opening=OPENING_MM)
    mesh = model.geometry.mesh()
    assert mesh.is_watertight and mesh.is_winding_consistent and mesh.volume > 0
    raw = _raw(part)
    assert mesh.volume == pytest.approx(abs(raw.volume), rel=1e-6)  # nothing repaired away
    if _plainly_holdable(raw, OPENING_MM):
        assert model.grasps, f"{part}: {model.geometry.no_grasp}"
    for g in model.grasps.values():
        assert g.width <= OPENING_MM + 1e-9
    checked = [g for g in model.grasps.values()]
    bad = [g.label for g in checked if not _pads_touch(raw, g.T, g.width)]
    assert not bad, f"{part}: pads off the surface in {bad}"


def test_beam_gets_a_grasp_across_its_12_7_mm_faces(tmp_path: Path) -> None:
    beam = load_object(_model(tmp_path, ROOT / "beam" / "0.ply"), "mm", opening=OPENING_MM)
    assert any(abs(g.width - 12.7) < 0.05 for g in beam.grasps.values())


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
