"""Issue 43's two-shaft gearbox as inputs, checked with trimesh and numpy from the files alone (not
the planner's loader or derivation): the meshes are closed, every declared mate's peg and hole
are coaxial with the stated clearance both as declared and as the meshes' cylinders, blind and
through holes are what they say, the parts touch where they rest and never overlap, and the
mesh-only product is the declared one, part by part, at the same poses (kb/products/gearbox.yaml,
gearbox_mesh.yaml and its STLs, written by ``python -m spar_py.app.gen gearbox kb``)."""
from __future__ import annotations

import itertools
import math
from functools import cache
from pathlib import Path

import numpy as np
import pytest
import trimesh
import yaml

from paths import ROOT

PRODUCTS = ROOT / "kb" / "products"
DECLARED = PRODUCTS / "gearbox.yaml"
MESHED = PRODUCTS / "gearbox_mesh.yaml"
PARTS = ("housing", "shaft_a", "shaft_b", "gear_a", "gear_b", "cover", "pin_1", "pin_2", "pin_3", "pin_4")

#: The issue's mates (peg part.feature, hole part.feature) and their radial clearances (mm).
MATES = {
    **{(f"shaft_{s}.journal", f"housing.bore_{s}"): 0.02 for s in "ab"},
    **{(f"shaft_{s}.middle", f"gear_{s}.bore"): 0.5 for s in "ab"},
    **{(f"shaft_{s}.upper", f"cover.bore_{s}"): 0.2 for s in "ab"},
    **{(f"pin_{k}.shaft", f"cover.ph{k}"): 0.1 for k in range(1, 5)},
    **{(f"pin_{k}.shaft", f"housing.ph{k}"): 0.1 for k in range(1, 5)},
}
#: What each part but the base rests on in the product (gravity down the product's -z).
RESTS_ON = {"shaft_a": "housing", "shaft_b": "housing", "gear_a": "shaft_a", "gear_b": "shaft_b",
            "cover": "housing", **{f"pin_{k}": "housing" for k in range(1, 5)}}
AXIS_TOL = 1e-6      # mm: axes coincide, radii as declared (the STLs' float32 corners included)
VOLUME_TOL = 1e-3    # mm^3: an overlap or a difference this small is rounding


def _load(path: Path) -> dict:
    return yaml.safe_load(path.read_text(encoding="utf-8"))


def _pose(pose: dict | None) -> np.ndarray:
    """trans(xyz) rpy(r, p, y) (deg), as a product file writes a part's pose: Rz(y) Ry(p) Rx(r)."""
    pose = pose or {}
    r, p, y = np.radians(pose.get("rpy", [0, 0, 0]))
    cx, sx, cy, sy, cz, sz = math.cos(r), math.sin(r), math.cos(p), math.sin(p), math.cos(y), math.sin(y)
    T = np.eye(4)
    T[:3, :3] = (np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]]) @ np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
                 @ np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]]))
    T[:3, 3] = pose.get("xyz", [0, 0, 0])
    return T


def _solid(prim: dict) -> trimesh.Trimesh:
    """A ``shape:`` primitive as a mesh: a box, or a 64-sided cylinder about the object's z."""
    if "box" in prim:
        return trimesh.creation.box(bounds=[prim["box"]["min"], prim["box"]["max"]])
    c = prim["cylinder"]
    return trimesh.creation.cylinder(radius=c["radius"], segment=[[0, 0, c["z"][0]], [0, 0, c["z"][1]]], sections=64)


@cache
def _model(rel: str) -> tuple[dict, trimesh.Trimesh]:
    """An object file (path relative to kb/products) and its solid in its own frame: its mesh, or
    the union of its primitives less the subtracted ones."""
    path = (PRODUCTS / rel).resolve()
    doc = _load(path)
    if "mesh" in doc:
        return doc, trimesh.load(path.parent / doc["mesh"], force="mesh")
    add = [_solid(p) for p in doc["shape"] if not list(p.values())[0].get("subtract")]
    cut = [_solid(p) for p in doc["shape"] if list(p.values())[0].get("subtract")]
    body = add[0] if len(add) == 1 else trimesh.boolean.union(add, engine="manifold")
    return doc, trimesh.boolean.difference([body, *cut], engine="manifold") if cut else body


@cache
def _declared() -> tuple[dict, dict[str, np.ndarray], dict[str, dict]]:
    """The declared product, each part's pose and each part's features by name (product frame:
    ``o`` the axis origin, ``d`` its unit direction, ``r``, ``length``, ``through``)."""
    doc = _load(DECLARED)
    poses = {n: _pose(p.get("pose")) for n, p in doc["parts"].items()}
    feats: dict[str, dict] = {}
    for n, p in doc["parts"].items():
        model, _ = _model(p["model"])
        T = poses[n]
        for f in model["features"]:
            d = T[:3, :3] @ np.asarray(f["axis"]["direction"], float)
            feats[f"{n}.{f['name']}"] = {"kind": f["kind"], "o": T[:3, :3] @ np.asarray(f["axis"]["origin"], float)
                                         + T[:3, 3], "d": d / np.linalg.norm(d), "r": float(f["radius"]),
                                         "length": float(f["length"]), "through": bool(f.get("through", False))}
    return doc, poses, feats


@cache
def _meshes() -> dict[str, trimesh.Trimesh]:
    """The mesh-only product's parts as their STLs give them (product frame)."""
    doc = _load(MESHED)
    return {n: trimesh.load(PRODUCTS / p["mesh"], force="mesh") for n, p in doc["parts"].items()}


def _volume(m: trimesh.Trimesh) -> float:
    """A boolean's result's volume (mm^3), 0 when it is empty (a touching pair's intersection may be
    a flat mesh of no volume: trimesh's mass properties then divide by zero, harmlessly)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        return 0.0 if m.is_empty else float(m.volume)


def _overlap(a: trimesh.Trimesh, b: trimesh.Trimesh) -> float:
    """The volume two closed meshes share (mm^3; manifold3d's boolean)."""
    if (a.bounds[1] < b.bounds[0]).any() or (b.bounds[1] < a.bounds[0]).any():
        return 0.0
    return _volume(trimesh.boolean.intersection([a, b], engine="manifold"))


def _rings(mesh: trimesh.Trimesh, f: dict) -> list[tuple[float, np.ndarray, float]]:
    """The mesh's vertices near the feature's cylinder (within 10 % of its radius from its axis,
    along its length) grouped in rings by height along the axis: for each ring (t, the fitted
    circle's centre in 3-D, its radius), by a least-squares circle fit (Kasa) in the plane
    normal to the declared axis."""
    V = np.asarray(mesh.vertices, float)
    o, d = f["o"], f["d"]
    t = (V - o) @ d
    radial = V - o - np.outer(t, d)
    near = (np.abs(np.linalg.norm(radial, axis=1) - f["r"]) < 0.1 * f["r"]) & (t > -1e-3) & (t < f["length"] + 1e-3)
    u = np.cross(d, [1.0, 0, 0] if abs(d[0]) < 0.9 else [0, 1.0, 0])
    u /= np.linalg.norm(u)
    w = np.cross(d, u)
    rings = []
    for level in np.unique(np.round(t[near], 4)):
        sel = near & (np.abs(t - level) < 1e-3)
        P = np.column_stack([radial[sel] @ u, radial[sel] @ w])
        A = np.column_stack([2 * P, np.ones(len(P))])
        cx, cy, k = np.linalg.lstsq(A, (P ** 2).sum(axis=1), rcond=None)[0]
        rings.append((float(level), o + level * d + cx * u + cy * w, math.sqrt(k + cx * cx + cy * cy)))
    return rings


def test_meshes_are_closed_binary_stls_of_modest_size() -> None:
    files = sorted((PRODUCTS / "gearbox_mesh").glob("*.stl"))
    files += sorted((ROOT / "kb/objects/meshes").glob("gearbox_*.stl"))
    assert [f.stem for f in files[:10]] == sorted(PARTS) and len(files) == 12
    for f in files:
        m = trimesh.load(f, force="mesh")
        assert m.is_watertight and m.is_winding_consistent and m.volume > 0, f
        assert f.stat().st_size == 84 + 50 * len(m.faces), f"{f}: not a binary STL of its triangles"
        assert len(m.faces) <= 2000, f


def test_declared_mates_are_the_issues_coaxial_with_their_clearances() -> None:
    doc, _, feats = _declared()
    declared = [(m["peg"], m["hole"]) for m in doc["mates"]]
    assert sorted(declared) == sorted(MATES) and len(declared) == 14
    assert all("seat" not in m and m.get("retention", "loose") == "loose" for m in doc["mates"])
    for peg, hole in declared:
        p, h = feats[peg], feats[hole]
        assert p["kind"] == "peg" and h["kind"] == "hole", (peg, hole)
        assert h["r"] - p["r"] == pytest.approx(MATES[peg, hole], abs=1e-9), (peg, hole)
        assert np.linalg.norm(np.cross(p["d"], h["d"])) < 1e-9 and p["d"] @ h["d"] > 0, (peg, hole)
        off = p["o"] - h["o"]
        assert np.linalg.norm(off - (off @ h["d"]) * h["d"]) < AXIS_TOL, (peg, hole)
        # along the hole's axis: the peg's span [root, tip] overlaps the hole's [mouth, far end]
        a, b = sorted([(p["o"] - h["o"]) @ h["d"], (p["o"] + p["length"] * p["d"] - h["o"]) @ h["d"]])
        assert min(b, h["length"]) - max(a, 0.0) > 1.0, (peg, hole)


def test_mesh_cylinders_are_the_declared_features() -> None:
    _, _, feats = _declared()
    meshes = _meshes()
    fitted: dict[str, float] = {}
    for name in {n for mate in MATES for n in mate}:
        f = feats[name]
        rings = _rings(meshes[name.split(".")[0]], f)
        assert len(rings) >= 2, f"{name}: {len(rings)} rings of vertices on its cylinder"
        for t, c, r in rings:
            off = c - f["o"] - ((c - f["o"]) @ f["d"]) * f["d"]
            assert np.linalg.norm(off) < AXIS_TOL, f"{name}: ring at {t:g} mm off the axis by {np.linalg.norm(off):.2e}"
            assert abs(r - f["r"]) < AXIS_TOL, f"{name}: ring at {t:g} mm of radius {r:.7f}, not {f['r']}"
        fitted[name] = float(np.mean([r for _, _, r in rings]))
    for (peg, hole), clearance in MATES.items():
        assert fitted[hole] - fitted[peg] == pytest.approx(clearance, abs=2 * AXIS_TOL), (peg, hole)


@pytest.mark.parametrize("hole", sorted({h for _, h in MATES}))
def test_holes_are_blind_or_through_as_declared(hole: str) -> None:
    """Just past a hole's far end on its axis: inside the part if the hole is blind, outside if
    it goes through (the mesh's own inside test); and the hole itself is empty."""
    f = _declared()[2][hole]
    mesh = _meshes()[hole.split(".")[0]]
    beyond, mid = f["o"] + (f["length"] + 0.5) * f["d"], f["o"] + 0.5 * f["length"] * f["d"]
    assert not mesh.contains([mid])[0], hole
    assert mesh.contains([beyond])[0] != f["through"], hole


def test_parts_rest_where_they_sit_and_never_overlap() -> None:
    meshes = _meshes()
    for a, b in itertools.combinations(PARTS, 2):
        assert _overlap(meshes[a], meshes[b]) < VOLUME_TOL, f"{a} and {b} overlap"
    for part, support in RESTS_ON.items():
        lowered = meshes[part].copy()
        lowered.apply_translation([0, 0, -0.01])
        assert _overlap(lowered, meshes[support]) > VOLUME_TOL, f"{part} does not rest on {support}"


def test_the_mesh_product_is_the_declared_one_at_the_same_poses() -> None:
    doc, poses, _ = _declared()
    meshed = _load(MESHED)
    assert list(doc["parts"]) == list(meshed["parts"]) == list(PARTS)
    assert doc.get("base", PARTS[0]) == meshed.get("base", PARTS[0]) == "housing"
    assert doc["units"]["length"] == meshed["units"]["length"] == "mm"
    assert "mates" not in meshed and all(set(p) == {"mesh"} for p in meshed["parts"].values())
    for name, part in doc["parts"].items():
        _, model = _model(part["model"])
        placed = model.copy()
        placed.apply_transform(poses[name])
        mesh = _meshes()[name]
        assert mesh.volume == pytest.approx(placed.volume, abs=VOLUME_TOL), name
        diff = _volume(trimesh.boolean.difference([mesh, placed], engine="manifold")) + \
            _volume(trimesh.boolean.difference([placed, mesh], engine="manifold"))
        assert diff < VOLUME_TOL, f"{name}: the mesh and the declared part differ by {diff:.3g} mm^3"


@pytest.mark.parametrize("stem", ["gearbox", "gearbox_mesh"])
def test_problems_are_the_ur5e_laying_the_parts_out(stem: str) -> None:
    doc = _load(ROOT / "kb" / "problems" / f"{stem}.yaml")
    product = _load((ROOT / "kb" / "problems" / doc["product"]).resolve())
    assert doc["robot"] == "../robots/ur5e.yaml" and doc["layout"] == "auto" and "objects" not in doc
    assert doc["goals"] == [f"assembled({product['product']})"]
    assert list(doc["uncertainty"]["objects"]) == list(PARTS) == list(product["parts"])
    for bounds in [doc["uncertainty"]["manipulator"], *doc["uncertainty"]["objects"].values()]:
        assert all(lo < 0 < hi for lo, hi in bounds.values())


def test_the_generator_writes_the_committed_files(tmp_path: Path) -> None:
    from spar_py.app.gen import generate_gearbox

    problem = generate_gearbox(tmp_path)
    assert problem == tmp_path / "problems" / "gearbox_mesh.yaml"
    written = sorted(p.relative_to(tmp_path) for p in tmp_path.rglob("*") if p.is_file())
    assert len(written) == 15  # 10 part STLs, 2 model STLs, product, problem, the robot
    for rel in written:
        assert (tmp_path / rel).read_bytes() == (ROOT / "kb" / rel).read_bytes(), rel
