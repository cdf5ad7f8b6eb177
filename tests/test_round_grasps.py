"""Grasps on round surfaces (issue 33, item 7): a part's cylinders found on its mesh are closed
on across their diameter, and a part no goal moves may have no grasp.

The stepped shafts are made here with trimesh (a revolved profile: no flats within the opening);
the checks of the grasps are our own arithmetic on the profile's numbers: both pads' contact
points at the cylinder's radius from the axis and within its length, the width its diameter.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import yaml

from spar_py.core.errors import KBError
from spar_py.kb.objects import load_object
from spar_py.kb.problem import load_problem
from spar_py.world.robot import Gripper

from paths import ROOT

#: The stepped shaft's profile (radius, z) mm: a D30 shoulder 20 mm long, a D16 shaft 100 mm long.
PROFILE = [(0, 0), (15, 0), (15, 20), (8, 20), (8, 120), (0, 120)]
#: Each cylinder of it: (radius, z from, z to).
CYLINDERS = [(15.0, 0.0, 20.0), (8.0, 20.0, 120.0)]


def _stepped_stl(d: Path, sections: int = 48) -> Path:
    import trimesh

    m = trimesh.creation.revolve(np.array(PROFILE, float), sections=sections)
    assert m.is_watertight
    path = d / "stepped.stl"
    m.export(path)
    (d / "stepped.yaml").write_text("object: stepped\nunits: {length: mm, angle: deg}\nmesh: stepped.stl\n")
    return d / "stepped.yaml"


def _gripper(opening: float) -> Gripper:
    return Gripper.default(opening, 1.0)


def _on_which_cylinder(g) -> tuple[float, float, float]:
    """The profile's cylinder both pads of grasp ``g`` touch (our own check), or a failed assert."""
    T = g.T
    pads = [T[:3, 3] + s * g.width / 2 * T[:3, 1] for s in (1, -1)]
    for r, z0, z1 in CYLINDERS:
        ok = all(abs(np.hypot(p[0], p[1]) - r) < 1e-6 and z0 < p[2] < z1 for p in pads)
        if ok and abs(g.width - 2 * r) < 1e-6:
            return r, z0, z1
    raise AssertionError(f"{g.label}: pads at {np.round(pads, 3).tolist()} are not on one cylinder")


def test_stepped_shaft_mesh_cylinders(tmp_path: Path) -> None:
    import trimesh

    from spar_py.world.parts.mesh import derive_faces
    from spar_py.world.parts.shafts import mesh_cylinders

    mesh = trimesh.load(_stepped_stl(tmp_path).with_suffix(".stl"), force="mesh")
    faces = derive_faces(mesh, (), {}, "mm")
    found = sorted((c.radius, float(c.root[2]), float(c.root[2] + c.length), *np.abs(c.axis), *c.root[:2])
                   for c in mesh_cylinders(mesh, faces, "mm"))
    # the D16 shaft (z 20..120) and the D30 shoulder (z 0..20), both about the z axis (the STL: float32)
    assert found == [pytest.approx((8.0, 20.0, 120.0, 0, 0, 1, 0, 0), abs=1e-5),
                     pytest.approx((15.0, 0.0, 20.0, 0, 0, 1, 0, 0), abs=1e-5)]


def test_stepped_shaft_mesh_has_round_grasps(tmp_path: Path) -> None:
    """No pair of flats within an 80 mm opening (its ends are 120 mm apart): every grasp is across
    the shoulder (D30) or the shaft (D16), from approaches around it."""
    model = load_object(_stepped_stl(tmp_path), "mm", gripper=_gripper(80.0), use_cache=False)
    assert model.grasps
    held = {}
    for g in model.grasps.values():
        r, _, _ = _on_which_cylinder(g)
        held.setdefault(r, []).append(g.T[:3, 2])  # the approach
    assert set(held) == {8.0, 15.0}
    # approaches all round the D16 shaft: from both sides across and along it
    A = np.array(held[8.0])
    assert (A @ [0, 0, 1.0]).min() < -0.99 and any(abs(a[2]) < 1e-9 for a in A)
    side = [a for a in A if abs(a[2]) < 1e-9]
    assert max(a @ b for a in side for b in side) > 0.99 and min(a @ b for a in side for b in side) < -0.99
    # a 15 mm opening holds neither (the load does not refuse: nothing says it must move)
    narrow = load_object(_stepped_stl(tmp_path), "mm", gripper=_gripper(15.0), use_cache=False)
    assert not narrow.grasps


def test_stepped_shaft_primitives_has_round_grasps(tmp_path: Path) -> None:
    (tmp_path / "p.yaml").write_text(yaml.safe_dump({
        "object": "stepped", "units": {"length": "mm", "angle": "deg"},
        "shape": [{"cylinder": {"radius": r, "z": [z0, z1]}} for r, z0, z1 in CYLINDERS]}))
    model = load_object(tmp_path / "p.yaml", "mm", gripper=_gripper(80.0), use_cache=False)
    assert {_on_which_cylinder(g)[0] for g in model.grasps.values()} == {8.0, 15.0}


def test_part_no_goal_moves_may_have_no_grasp(tmp_path: Path) -> None:
    """A base too big for the fingers loads with no grasps when nothing moves it; the same part
    as a goal's moving part is refused, naming its file."""
    (tmp_path / "base.yaml").write_text(yaml.safe_dump({
        "object": "base", "units": {"length": "mm", "angle": "deg"},
        "shape": [{"box": {"min": [-100, -100, 0], "max": [100, 100, 150]}},
                  {"cylinder": {"radius": 12, "z": [120, 150], "subtract": True}}],
        "feature": {"kind": "hole", "name": "bore", "radius": 12, "length": 30,
                    "axis": {"origin": [0, 0, 150], "direction": [0, 0, -1]}}}))
    (tmp_path / "pin.yaml").write_text(yaml.safe_dump({
        "object": "pin", "units": {"length": "mm", "angle": "deg"},
        "shape": [{"cylinder": {"radius": 11, "z": [0, 60]}}],
        "feature": {"kind": "peg", "name": "shank", "radius": 11, "length": 60,
                    "axis": {"origin": [0, 0, 0], "direction": [0, 0, 1]}}}))
    cell = {
        "problem": "pin_in_base", "units": {"length": "mm", "angle": "deg"},
        "robot": str(ROOT / "kb" / "robots" / "puma762.yaml"),
        "objects": {"pin": {"model": "pin.yaml", "initial": {"name": "init_pos1", "label": "tr1",
                                                            "tm": [[1, 0, 0], [0, 1, 0], [0, 0, 1], [700, -200, 0]]}},
                    "base": {"model": "base.yaml", "initial": {"name": "init_pos2", "label": "tr2",
                                                              "tm": [[1, 0, 0], [0, 1, 0], [0, 0, 1], [700, 200, 0]]}}},
        "gripper": "open",
        "uncertainty": {"manipulator": {k: [-0.01, 0.01] for k in ("dx", "dy", "dz", "dtheta")},
                        "objects": {o: {k: [-0.01, 0.01] for k in ("dx", "dy", "dz", "dtheta")}
                                    for o in ("pin", "base")}},
        "goals": ["assembled(pin, base)"],
    }
    (tmp_path / "ok.yaml").write_text(yaml.safe_dump(cell))
    loaded = load_problem(tmp_path / "ok.yaml")
    assert loaded.objects["base"].grasps == {} and loaded.objects["pin"].grasps
    # a part a goal moves needs a grasp: a D120 pin 120 mm long (the PUMA opens 101.6 mm: too wide
    # across its round, 119.9 mm across the flats of its polygon, and between its ends) into a D124 bore
    (tmp_path / "wide_base.yaml").write_text(yaml.safe_dump({
        "object": "base", "units": {"length": "mm", "angle": "deg"},
        "shape": [{"box": {"min": [-100, -100, 0], "max": [100, 100, 150]}},
                  {"cylinder": {"radius": 62, "z": [120, 150], "subtract": True}}],
        "feature": {"kind": "hole", "name": "bore", "radius": 62, "length": 30,
                    "axis": {"origin": [0, 0, 150], "direction": [0, 0, -1]}}}))
    (tmp_path / "fat_pin.yaml").write_text(yaml.safe_dump({
        "object": "pin", "units": {"length": "mm", "angle": "deg"},
        "shape": [{"cylinder": {"radius": 60, "z": [0, 120]}}],
        "feature": {"kind": "peg", "name": "shank", "radius": 60, "length": 120,
                    "axis": {"origin": [0, 0, 0], "direction": [0, 0, 1]}}}))
    cell["objects"]["pin"]["model"] = "fat_pin.yaml"
    cell["objects"]["base"]["model"] = "wide_base.yaml"
    (tmp_path / "bad.yaml").write_text(yaml.safe_dump(cell))
    with pytest.raises(KBError, match=r"fat_pin\.yaml: shape: expected a part the gripper can hold, as a goal "
                                      r"moves it \(its narrowest width across opposite surfaces \(within 12 deg\) "
                                      r"is 119\.9 mm, more than the gripper's opening 101\.6 mm\)"):
        load_problem(tmp_path / "bad.yaml")


# =========================================================================== a shaft grasp for the mate

#: The mate cell's numbers (mm): a D30 pin 110 long (no flats within the 101.6 mm opening), a
#: 200 x 200 x 120 base (too big for the fingers) on its side, a D31 bore 20 deep in it.
PIN_R, PIN_L, BORE_DEPTH = 15.0, 110.0, 20.0
#: The PUMA's fingers (kb/robots/puma762.yaml): length, width, thickness; the palm's depth.
FINGER, PALM_DEPTH = (60.0, 20.0, 10.0), 25.0


def _pin_cell(d: Path) -> Path:
    (d / "base.yaml").write_text(yaml.safe_dump({
        "object": "base", "units": {"length": "mm", "angle": "deg"},
        "shape": [{"box": {"min": [-100, -100, 0], "max": [100, 100, 120]}},
                  {"cylinder": {"radius": PIN_R + 0.5, "z": [120 - BORE_DEPTH, 120], "subtract": True}}],
        "feature": {"kind": "hole", "name": "bore", "radius": PIN_R + 0.5, "length": BORE_DEPTH,
                    "axis": {"origin": [0, 0, 120], "direction": [0, 0, -1]}}}))
    (d / "pin.yaml").write_text(yaml.safe_dump({
        "object": "pin", "units": {"length": "mm", "angle": "deg"},
        "shape": [{"cylinder": {"radius": PIN_R, "z": [0, PIN_L]}}],
        "feature": {"kind": "peg", "name": "shank", "radius": PIN_R, "length": PIN_L,
                    "axis": {"origin": [0, 0, 0], "direction": [0, 0, 1]}}}))
    small = {k: [-0.01, 0.01] for k in ("dx", "dy", "dz", "dtheta")}
    cell = {
        "problem": "pin_outer_grasp", "units": {"length": "mm", "angle": "deg"},
        "robot": str(ROOT / "kb" / "robots" / "puma762.yaml"),
        "objects": {
            "pin": {"model": "pin.yaml", "initial": {"name": "init_pos1", "label": "tr1",
                                                    "tm": [[1, 0, 0], [0, 1, 0], [0, 0, 1], [700, -200, 0]]}},
            # on its side: its z (the bore's axis, outwards) along the world's +x, the bore 100 mm up
            "base": {"model": "base.yaml", "initial": {"name": "init_pos2", "label": "tr2",
                                                      "tm": [[0, 0, -1], [0, 1, 0], [1, 0, 0], [600, 250, 100]]}}},
        "gripper": "open",
        "uncertainty": {"manipulator": small, "objects": {"pin": small, "base": small}},
        "goals": ["assembled(pin, base)"],
    }
    (d / "pin_outer.yaml").write_text(yaml.safe_dump(cell))
    return d / "pin_outer.yaml"


def test_shaft_grasp_holding_the_outer_length_makes_the_mate(tmp_path: Path) -> None:
    """Every grasp of the pin is on its shaft (the feature's face), so the rule by ofaces leaves
    none for the insertion; the grasps whose fingers stay on the 90 mm that stays out of the bore
    are usable, and the plan inserts the pin with one. Our own check at the assemble step: the
    fingers' and palm's corners (the robot file's sizes, placed by the step's tool pose) lie on
    the outer side of the bore's mouth plane, and the pads on the pin's outer length."""
    from spar_py.kb.prolog_facts import facts
    from spar_py.planning.planner import Planner

    cell = load_problem(_pin_cell(tmp_path))
    pin = cell.objects["pin"]
    assert pin.grasps and all("shank" in g.ofaces for g in pin.grasps.values())  # the ofaces rule: none
    usable = next(f[3] for f in facts(cell) if f[0] == "mate_grasps")
    assert usable and set(usable) < set(pin.grasps)
    plan = Planner().plan(cell)
    assert plan.ok, plan.reason
    asm = next(s for s in plan.steps if s.name == "assemble")
    pick = [s for s in plan.steps if s.name == "pickup" and s.object == "pin"][-1]
    assert pick.args[1] in usable
    T = np.asarray(asm.tool_pose, float)
    base = next(p.T for p in cell.positions.values() if p.obj == "base")
    mouth = base[:3, :3] @ [0, 0, 120.0] + base[:3, 3]
    inward = base[:3, :3] @ [0, 0, -1.0]
    width = pin.grasps[pick.args[1]].width
    assert width == pytest.approx(2 * PIN_R)
    L, u, t = FINGER
    w = width / 2
    boxes = [((-u / 2, w, -L), (u / 2, w + t, 0)), ((-u / 2, -w - t, -L), (u / 2, -w, 0)),
             ((-u / 2, -w - t, -L - PALM_DEPTH), (u / 2, w + t, -L))]
    for lo, hi in boxes:
        corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
        depth = (corners @ T[:3, :3].T + T[:3, 3] - mouth) @ inward
        assert depth.max() <= 0.05, depth
    # the pads: the TCP +- half the width across, +- half a finger's width along the pin's axis
    for s in (1, -1):
        for a in (-u / 2, u / 2):
            p = T[:3, 3] + s * w * T[:3, 1] + a * T[:3, 0]
            outside = -(p - mouth) @ inward  # how far out of the bore along its axis
            radial = np.linalg.norm((p - mouth) - ((p - mouth) @ inward) * inward)
            assert 0 <= outside <= PIN_L - BORE_DEPTH + 1e-6 and radial == pytest.approx(PIN_R, abs=1e-6)
