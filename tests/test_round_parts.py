"""Round parts lie down (issue 43, item 5): a part whose convex hull has a round side (a
cylinder, a cone from a head's rim to a shaft's tip) gets that side as one stable pose family,
counted once, its probability summed over the hull's facets, beside its end poses (those whose
basin passes the model's 1 % floor); a lying pin has a grasp from above there; `layout: auto`
and the grasp report offer only poses the model keeps (the 5 deg tilt rule).

Every check here is our own geometry: the mesh's vertices placed by a pose, the table contact
read off them, the tilt rule computed on that contact (a polygon, or a line along which the
part must not tip and across which it must roll without rising), trimesh's own
compute_stable_poses for the probabilities, the gripper's finger boxes built from its sizes."""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
import trimesh
import yaml

from spar_py.kb.objects import load_object
from spar_py.world.robot import Gripper

from paths import ROOT
from test_grasp_report import PROBLEM  # the pinned cell's problem file, one template

MARGIN_MM, TILT_DEG = 0.5, 5.0  # the model's rule, stated here independently (world.parts.poses)


def _write(d: Path, name: str, mesh: trimesh.Trimesh, extra: str = "") -> Path:
    mesh.export(d / f"{name}.stl")
    (d / f"{name}.yaml").write_text(f"object: {name}\nunits: {{length: mm, angle: deg}}\nmesh: {name}.stl\n{extra}")
    return d / f"{name}.yaml"


def _dowel(d: Path) -> Path:
    """A dowel pin r 3 x 50 mm as trimesh makes it (32 sides, centred on the origin, axis z)."""
    return _write(d, "dowel", trimesh.creation.cylinder(3.0, 50.0))


def _shaft(d: Path) -> Path:
    """A stepped shaft without flats: D24 z 0..30, D16 z 30..60 (64 sides)."""
    parts = [trimesh.creation.cylinder(r, segment=[[0, 0, z0], [0, 0, z1]], sections=64)
             for r, z0, z1 in ((12, 0, 30), (8, 30, 60))]
    return _write(d, "shaft", trimesh.boolean.union(parts, engine="manifold"))


def _long_pin(d: Path) -> Path:
    """A headed pin too slender to stand: head r 3.5 x 2, shaft r 3 x 80 (48 sides), the shaft
    declared as a peg; on its head it tips over at about 4.9 deg, on its tip at about 4.4."""
    parts = [trimesh.creation.cylinder(3.5, segment=[[0, 0, 0], [0, 0, 2]], sections=48),
             trimesh.creation.cylinder(3.0, segment=[[0, 0, 2], [0, 0, 82]], sections=48)]
    feature = ("features:\n  - {kind: peg, name: shaft, radius: 3, axis: {origin: [0, 0, 2], direction: [0, 0, 1]}, "
               "length: 80}\n")
    return _write(d, "long_pin", trimesh.boolean.union(parts, engine="manifold"), feature)


def _mesh_of(model) -> trimesh.Trimesh:
    return model.geometry.mesh()


def _placed(V: np.ndarray, R: np.ndarray, h: float) -> np.ndarray:
    return V @ np.asarray(R, float).T + np.array([0.0, 0.0, h])


def _rot(axis: np.ndarray, a: float) -> np.ndarray:
    """Rodrigues' rotation by ``a`` (rad) about unit ``axis``."""
    k = np.asarray(axis, float) / np.linalg.norm(axis)
    K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + math.sin(a) * K + (1 - math.cos(a)) * K @ K


def _tilt_problem(mesh: trimesh.Trimesh, R: np.ndarray, h: float, axis: np.ndarray | None = None) -> str | None:
    """Why the part at (R, frame height h) is not kept on the table, or None, by our own reading:
    it must touch the table (lowest point at z 0); on a polygon of contact its centre of mass
    projects MARGIN_MM inside every edge and tips on no edge under TILT_DEG; on a line of
    contact the same along the line, and across it the part rolls about its own ``axis``
    (object frame) without its centre of mass rising or falling (a round side) by more than
    the mesh's tessellation."""
    V = _placed(np.asarray(mesh.vertices, float), R, h)
    c = np.asarray(R, float) @ np.asarray(mesh.center_mass, float) + [0, 0, h]
    if abs(V[:, 2].min()) > 1e-6:
        return f"its lowest point is at {V[:, 2].min():.6g}, not on the table"
    low = V[V[:, 2] < 1e-6][:, :2]
    centred = low - low.mean(0)
    _, s, vt = np.linalg.svd(centred, full_matrices=False)
    if len(low) >= 3 and s[-1] > 1e-6 * max(s[0], 1.0):
        from scipy.spatial import ConvexHull

        hull = ConvexHull(low)
        margin = float(-(hull.equations[:, :2] @ c[:2] + hull.equations[:, 2]).max())
    else:
        u = vt[0]
        t = centred @ u
        tc = float((c[:2] - low.mean(0)) @ u)
        if abs(float((c[:2] - low.mean(0)) @ np.array([-u[1], u[0]]))) > 1e-6:
            return "on a line with its centre of mass beside it"
        margin = min(tc - t.min(), t.max() - tc)
        if axis is None:
            return "on a line, and no axis to roll about"
        w = np.asarray(R, float) @ np.asarray(axis, float)
        for a in (-20.0, -5.0, 5.0, 20.0):  # rolled about its axis through the centre of mass
            Q = _rot(w, math.radians(a))
            rise = float(((V - c) @ Q.T)[:, 2].min() + (c[2]))
            if abs(rise) > 0.05:
                return f"rolled {a:g} deg about its axis its centre of mass moves {rise:.3g} mm up or down"
    if margin < MARGIN_MM:
        return f"its centre of mass is only {margin:.3g} mm inside its contact"
    tilt = math.degrees(math.atan2(margin, c[2]))
    return None if tilt >= TILT_DEG else f"it tips on a tilt of {tilt:.3g} deg"


def _axis_horizontal(R: np.ndarray, d: np.ndarray) -> bool:
    return abs(float((np.asarray(R, float) @ d)[2])) < 1e-9


Z = np.array([0.0, 0.0, 1.0])


def _gripper() -> Gripper:
    return Gripper.default(85.0, 1.0)


# ----------------------------------------------------------------------------- the families


def test_mesh_dowel_lies_on_its_side_once(tmp_path: Path) -> None:
    """One pose for its 32 side facets, at its radius, with their summed probability; its ends
    (standing by the tilt rule, 6.8 deg) have 0.4 % each, under the model's 1 % floor."""
    from spar_py.world.parts.cache import derive

    model = load_object(_dowel(tmp_path), "mm", gripper=_gripper(), use_cache=False)
    mesh = _mesh_of(model)
    poses = list(model.poses.values())
    lying = [p for p in poses if _axis_horizontal(p.R, Z)]
    assert len(lying) == 1 and len(poses) == 1
    assert lying[0].height == pytest.approx(3.0, abs=1e-6)
    for p in poses:
        assert _tilt_problem(mesh, p.R, p.height, Z) is None, p.label
    # its probability is trimesh's summed over every pose on the side (the hull's side facets)
    d = derive("dowel", model.geometry, (), {}, _gripper(), math.radians(45), False, use_cache=False)
    T, P = trimesh.poses.compute_stable_poses(mesh.convex_hull, center_mass=mesh.center_mass, sigma=0.0,
                                              n_samples=1)
    side = float(sum(p for t, p in zip(T, P) if abs(t[2, :3] @ Z) < 1e-6))
    assert side > 0.9
    got = {tuple(np.round(np.asarray(x["R"]).reshape(3, 3)[2], 6)): x["probability"] for x in d["poses"]}
    up = tuple(np.round(np.asarray(lying[0].R)[2], 6))
    assert got[up] == pytest.approx(side, abs=1e-6)
    ends = [p for t, p in zip(T, P) if abs(abs(t[2, :3] @ Z) - 1) < 1e-6]
    assert len(ends) == 2 and max(ends) < 0.01 and len(d["poses"]) == 1


def test_mesh_shaft_without_flats_lies_on_its_widest_side(tmp_path: Path) -> None:
    """On its D24 collar (the cone down to the D16 end would roll it off), and standing on that
    collar's end (24 mm of it under a centre of mass 24 mm up)."""
    model = load_object(_shaft(tmp_path), "mm", gripper=_gripper(), use_cache=False)
    mesh = _mesh_of(model)
    poses = list(model.poses.values())
    lying = [p for p in poses if _axis_horizontal(p.R, Z)]
    assert len(lying) == 1 and lying[0].height == pytest.approx(12.0, abs=1e-6)
    assert any(np.allclose(p.R, np.eye(3)) and abs(p.height) < 1e-6 for p in poses)  # on the collar's end
    assert len(poses) < 5  # not one per side facet (64 of them)
    for p in poses:
        assert _tilt_problem(mesh, p.R, p.height, Z) is None, p.label


def test_primitive_pin_lies_on_its_head_and_a_long_pin_on_its_rim_and_tip(tmp_path: Path) -> None:
    """pin17 (head r 8 x 12, shaft r 5 x 17) lies on its head's side, its axis level (the
    shaft's side 3 mm over the table; on the cone from the head's rim to the tip it would tip
    at 4 deg); the long pin lies on that cone, its axis not level; neither has any other lying pose."""
    pin17 = load_object(ROOT / "kb" / "objects" / "pin17.yaml", "mm", gripper=_gripper(), use_cache=False)
    lying = [p for p in pin17.poses.values() if _axis_horizontal(p.R, Z)]
    assert len(lying) == 1 and lying[0].height == pytest.approx(8.0, abs=1e-6)
    for p in pin17.poses.values():
        assert _tilt_problem(_mesh_of(pin17), p.R, p.height, Z) is None, p.label
    long_pin = load_object(_long_pin(tmp_path), "mm", gripper=_gripper(), use_cache=False)
    poses = list(long_pin.poses.values())
    assert len(poses) == 1  # on neither end: both tip under 5 deg
    R = np.asarray(poses[0].R)
    # the axis tilted by the cone's half angle, atan((3.5 - 3) / 80)
    assert abs(float((R @ Z)[2])) == pytest.approx(math.sin(math.atan(0.5 / 80)), abs=1e-6)
    assert _tilt_problem(_mesh_of(long_pin), R, poses[0].height, Z) is None


def test_the_independent_tilt_check_refuses_what_it_should(tmp_path: Path) -> None:
    """Our check refuses the long pin on its head (about 4.9 deg) and a dowel on one flat of its side."""
    long_pin = load_object(_long_pin(tmp_path), "mm", gripper=_gripper(), use_cache=False)
    mesh = _mesh_of(long_pin)
    assert "tips" in (_tilt_problem(mesh, np.eye(3), 0.0, Z) or "")
    dowel = trimesh.creation.cylinder(3.0, 50.0)
    R = _rot(np.array([0.0, 1.0, 0.0]), math.pi / 2) @ _rot(Z, math.pi / 32)  # a side facet down
    h = -float(_placed(np.asarray(dowel.vertices), R, 0.0)[:, 2].min())
    assert _tilt_problem(dowel, R, h, Z) is not None


# ----------------------------------------------------------------------------- grasps there


def _finger_corners(T: np.ndarray, width: float, g: Gripper) -> np.ndarray:
    """The corners of both closed fingers' boxes of the tool at T: x across the finger, y out from
    the contact face, z from the tip (the tool centre's plane) back along the approach."""
    out = []
    for side in (1.0, -1.0):
        for x in (-g.finger_width / 2, g.finger_width / 2):
            for y in (width / 2, width / 2 + g.finger_thickness):
                for z in (-g.finger_length, 0.0):
                    out.append(T[:3, :3] @ np.array([x, side * y, z]) + T[:3, 3])
    return np.array(out)


@pytest.mark.parametrize("which", ["pin17", "dowel"])
def test_a_lying_pin_has_a_grasp_from_above(tmp_path: Path, which: str) -> None:
    """Some grasp, in the lying pose, comes straight down, closes across the diameter (both pads
    on the cylinder, opposite), and keeps both fingers over the table."""
    path = ROOT / "kb" / "objects" / "pin17.yaml" if which == "pin17" else _dowel(tmp_path)
    model = load_object(path, "mm", gripper=_gripper(), use_cache=False)
    r = 5.0 if which == "pin17" else 3.0
    pose = next(p for p in model.poses.values() if _axis_horizontal(p.R, Z))
    Tp = np.eye(4)
    Tp[:3, :3], Tp[2, 3] = pose.R, pose.height
    axis_w = np.asarray(pose.R) @ Z
    good = []
    for gr in model.grasps.values():
        T = Tp @ gr.T
        if T[2, 2] > -math.cos(math.radians(1.0)):
            continue  # not straight down
        pads = [T[:3, 3] + s * gr.width / 2 * T[:3, 1] for s in (1.0, -1.0)]
        o = Tp[:3, 3]  # the axis passes through the object origin for both parts
        dist = [np.linalg.norm(np.cross(p - o, axis_w)) for p in pads]
        mid = (pads[0] + pads[1]) / 2
        if not (np.allclose(dist, r, atol=1e-6) and np.linalg.norm(np.cross(mid - o, axis_w)) < 1e-6):
            continue  # not across the diameter
        if _finger_corners(T, gr.width, _gripper())[:, 2].min() <= 0.0:
            continue
        good.append(gr.label)
    assert good


# ----------------------------------------------------------------------------- layout and report


CUBE = """object: cube
units: {length: mm, angle: deg}
shape:
  - {box: {min: [-30, -30, -30], max: [30, 30, 30]}}
  - {cylinder: {radius: 3.1, z: [-10, 30], subtract: true}}
features:
  - {kind: hole, name: bore, radius: 3.1, axis: {origin: [0, 0, 30], direction: [0, 0, -1]}, length: 40}
"""
PRODUCT = """product: pinned
units: {length: mm, angle: deg}
base: cube
parts:
  cube: {model: cube.yaml}
  pin: {model: long_pin.yaml, pose: {xyz: [0, 0, 72], rpy: [180, 0, 0]}}
mates:
  - {peg: pin.shaft, hole: cube.bore}
"""


@pytest.fixture(scope="module")
def pinned(tmp_path_factory) -> Path:
    d = tmp_path_factory.mktemp("pinned")
    _long_pin(d)
    (d / "cube.yaml").write_text(CUBE)
    (d / "pinned.yaml").write_text(PRODUCT)
    (d / "problem.yaml").write_text(PROBLEM.format(name="pinned", robot=ROOT / "kb" / "robots" / "ur5e.yaml"))
    return d


def test_layout_auto_lays_a_headed_pin_only_as_its_model_keeps_it(pinned: Path) -> None:
    from spar_py.kb.problem import load_problem

    cell = load_problem(pinned / "problem.yaml")
    placed = {p.obj: np.asarray(p.T, float) for p in cell.positions.values()}
    assert set(placed) == {"cube", "pin"}
    for part, T in placed.items():
        model = cell.objects[part]
        R = T[:3, :3]
        yaw = math.atan2(R[1, 0] - R[0, 1], R[0, 0] + R[1, 1])
        R0 = _rot(Z, -yaw) @ R  # the pose itself, turned back about the vertical
        assert any(np.allclose(R0, p.R, atol=1e-6) and abs(T[2, 3] - p.height) < 1e-6
                   for p in model.poses.values()), part
        axis = Z if part == "pin" else None
        assert _tilt_problem(_mesh_of(model), R0, T[2, 3], axis) is None, part
    assert not _axis_horizontal(placed["pin"][:3, :3], Z)  # lying on its rim and tip: the only way it stays


def _pose_name(R: np.ndarray) -> str:
    """How the report names a pose: the object axis pointing down, within 5 deg, else the vector."""
    d = -np.asarray(R, float)[2]
    for k, axis in enumerate("xyz"):
        for s in (1.0, -1.0):
            if d[k] * s > math.cos(math.radians(5.0)):
                return f"{'+' if s > 0 else '-'}{axis} down"
    return "(" + ", ".join(f"{round(float(x), 2) + 0.0:.2g}" for x in d) + ") down"


def test_grasp_report_counts_the_models_poses_once(pinned: Path) -> None:
    """The report tries the pin's own poses (the family once; not trimesh's 60-odd facets, not the
    refused '-z down') and names only those."""
    from spar_py.kb.problem import load_problem
    from spar_py.world.product.grasp_report import grasp_report

    cell = load_problem(pinned / "problem.yaml")
    at = {p.obj: np.asarray(p.T, float) for p in cell.positions.values()}
    report = grasp_report(cell.product, cell.robot.gripper, cell.unit, cell.robot, at, margin=cell.robot.margin)
    assert report is not None
    row = next(r for r in report.parts if r.part == "pin")
    model = cell.product.parts["pin"].model
    assert row.poses == len(model.poses) == 1
    assert set(row.pose_ok) <= {_pose_name(p.R) for p in model.poses.values()}
    assert "-z down" not in row.pose_ok


@pytest.mark.parametrize("f", ["plate_pins.yaml", "bracket_kit.yaml"])
def test_grasp_report_counts_only_poses_the_model_keeps_on_shipped_products(f: str) -> None:
    """Every row's pose count is its part's own stable poses (the round side once, none that
    needs its subtree mated) and every pose it names is one of them."""
    from spar_py.kb.products import load_product
    from spar_py.world.product.grasp_report import grasp_report

    p = load_product(ROOT / "kb" / "products" / f, "mm")
    report = grasp_report(p, _gripper(), "mm")
    assert report is not None and report.parts
    for row in report.parts:
        model = p.parts[row.part].model
        own = [q for q in model.poses.values() if q.label not in p.sub_poses.get(row.part, {})]
        assert row.poses == len(own), row.part
        assert set(row.pose_ok) <= {_pose_name(q.R) for q in own}, row.part


def test_kb_check_keeps_a_lying_pose_at_any_roll_and_refuses_a_tipping_one(tmp_path: Path) -> None:
    """`spar kb derive`'s own lying pose passes `spar kb check`, as does the same pose rolled a
    quarter turn about the dowel's axis (a family: any roll); the long pin written standing on
    its head (tips at 4.9 deg) is refused, naming the pose."""
    from spar_py.core.errors import KBError
    from spar_py.kb.check import check_file, derive_text

    text = derive_text(_dowel(tmp_path), out_dir=tmp_path)
    full = yaml.safe_load(text)
    (tmp_path / "full.yaml").write_text(text)
    assert "1 stable poses" in check_file(tmp_path / "full.yaml")
    lying = next(p for p in full["stable_poses"] if abs(np.asarray(p["tm"][:3], float).T[2] @ Z) < 1e-9)
    R = np.asarray(lying["tm"][:3], float).T @ _rot(Z, math.pi / 2)
    lying["tm"] = [[round(float(v), 12) for v in R[:, i]] for i in range(3)] + [lying["tm"][3]]
    (tmp_path / "rolled.yaml").write_text(yaml.safe_dump(full, sort_keys=False))
    assert "ok" in check_file(tmp_path / "rolled.yaml")
    _long_pin(tmp_path)
    (tmp_path / "standing.yaml").write_text((tmp_path / "long_pin.yaml").read_text() + "stable_poses:\n"
                                            "  - {label: up, rfaces: [nz], ofaces: [nz], tm: [[1, 0, 0], [0, 1, 0], "
                                            "[0, 0, 1], [0, 0, 0]]}\n")
    with pytest.raises(KBError, match="up: it tips over"):
        check_file(tmp_path / "standing.yaml")
