"""Fabrica cells (issue 34 item 6): the product files, the parts laid out on the table
(world/product/layout.py: ``spar gen layout``, a problem's ``layout: auto``).

The geometry is checked with our own code: the parts' PLY files read by trimesh alone (cm,
the product frame: a mesh part's object frame), placed by the loaded positions, against the
table, each other and the robot's base."""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
import trimesh

from spar_py.core.errors import KBError
from spar_py.kb.problem import load_problem

from paths import ROOT

FABRICA = ROOT / "kb" / "products" / "fabrica"
#: UR5e's published reach (mm, from the base axis to the flange) plus its tool's 150 mm.
UR5E_REACH_MM = 850.0 + 150.0
CM = 10.0  # mm per cm


def _ply_of(product: str) -> dict[str, Path]:
    """Part name -> its PLY file, read from the product file's ``parts:`` (own parse)."""
    import yaml

    doc = yaml.safe_load((FABRICA / f"{product}.yaml").read_text())
    return {p: FABRICA / d["mesh"] for p, d in doc["parts"].items()}


@pytest.fixture(scope="module")
def car():
    return load_problem(ROOT / "kb" / "problems" / "fabrica_car.yaml")


def _placed(cell, product: str) -> dict[str, np.ndarray]:
    """Each part's mesh vertices at its initial position (world, mm), from the PLY alone."""
    out = {}
    for part, f in _ply_of(product).items():
        V = np.asarray(trimesh.load(f, process=False).vertices, float) * CM
        T = cell.positions[f"tr_{part}"].T
        out[part] = V @ T[:3, :3].T + T[:3, 3]
    return out


def test_layout_auto_loads_every_part(car):
    assert set(car.objects) == set(_ply_of("car"))
    assert {p.name for p in car.positions.values()} == {f"init_{p}" for p in car.objects}


def test_parts_in_stable_poses_on_the_table(car):
    placed = _placed(car, "car")
    for pos in car.positions.values():
        R = pos.T[:3, :3]
        poses = car.objects[pos.obj].poses.values()
        # a stable pose turned about the vertical (the layout tries YAWS yaws): the same row 3
        assert any(np.allclose(R[2], p.R[2], atol=1e-9) and math.isclose(pos.T[2, 3], p.height, abs_tol=1e-6)
                   for p in poses), pos.obj
        assert placed[pos.obj][:, 2].min() == pytest.approx(0.0, abs=1e-3), pos.obj


def test_base_keeps_the_product_upright_and_others_most_probable(car):
    base = car.product.base
    R = car.positions[f"tr_{base}"].T[:3, :3]
    assert np.allclose(R[2], [0, 0, 1])
    for pos in car.positions.values():
        if pos.obj != base:
            first = next(iter(car.objects[pos.obj].poses.values()))
            assert np.allclose(pos.T[2, :3], first.R[2])  # turned about the vertical at most


def _gap(A: np.ndarray, B: np.ndarray, n: int = 2880) -> float:
    """The widest projected gap between point sets A and B (k, 2) over n directions."""
    a = np.linspace(0, np.pi, n, endpoint=False)
    D = np.stack([np.cos(a), np.sin(a)], axis=1)
    pa, pb = A @ D.T, B @ D.T
    return float(np.maximum(pb.min(0) - pa.max(0), pa.min(0) - pb.max(0)).max())


def test_footprints_apart_and_within_reach(car):
    placed = _placed(car, "car")
    names = list(placed)
    for i, a in enumerate(names):
        for b in names[i + 1:]:
            assert _gap(placed[a][:, :2], placed[b][:, :2]) > 40.0, (a, b)  # room for a finger
    o = car.robot.base[:2, 3]
    for part, V in placed.items():
        r = np.linalg.norm(V[:, :2] - o, axis=1)
        assert r.min() > 150.0 and r.max() < UR5E_REACH_MM, part


def test_gen_layout_writes_the_same_positions(car, tmp_path):
    from spar_py.app.gen import layout_problem_text

    out = tmp_path / "car_layout.yaml"
    out.write_text(layout_problem_text(FABRICA / "car.yaml", ROOT / "kb" / "robots" / "ur5e.yaml", out))
    cell = load_problem(out)
    for label, pos in car.positions.items():
        assert np.allclose(cell.positions[label].T, pos.T, atol=1e-6)


def _problem(tmp_path: Path, extra: str) -> Path:
    f = tmp_path / "p.yaml"
    f.write_text(f"""problem: p
units: {{length: mm, angle: deg}}
robot: {ROOT / 'kb' / 'robots' / 'ur5e.yaml'}
{extra}
gripper: open
uncertainty:
  manipulator: {{dx: [0, 0], dy: [0, 0], dz: [0, 0], dtheta: [0, 0]}}
  objects: {{}}
goals:
  - part_location(a, b)
""")
    return f


def test_layout_refusals_are_one_line(tmp_path):
    with pytest.raises(KBError, match=r"layout: expected auto"):
        load_problem(_problem(tmp_path, f"product: {FABRICA / 'car.yaml'}\nlayout: yes_please"))
    with pytest.raises(KBError, match=r"layout: expected a problem with product:"):
        load_problem(_problem(tmp_path, "layout: auto"))


# ---------------------------------------------------------------------------- planned cells

#: The UR5e's gripper as its robot file leaves it to the defaults (mm): fingers 60 long (tool z,
#: tips at the tool origin), 20 wide (tool x), 10 thick (tool y, outward of the contact face).
FINGER_L, FINGER_W, FINGER_T = 60.0, 20.0, 10.0
MARGIN_MM = 2.0  # kb/robots/ur5e.yaml collision: margin


#: The Fabrica assemblies one arm on a table builds (the others are refused, naming the mate).
PLANNED = ("cooling_manifold", "duct", "stool_circular")


@pytest.fixture(scope="module", params=PLANNED)
def fabrica_plan(request) -> tuple[str, dict]:
    from spar_py.planning.planner import Planner

    return request.param, Planner().plan(ROOT / "kb" / "problems" / f"fabrica_{request.param}.yaml").to_json()


def _meshes(product: str) -> dict[str, trimesh.Trimesh]:
    """Each part's mesh in its own frame, mm (the PLY alone)."""
    out = {}
    for part, f in _ply_of(product).items():
        m = trimesh.load(f, process=False)
        m.apply_scale(CM)
        out[part] = m
    return out


def test_plan_ends_at_product_poses(fabrica_plan):
    """Every part ends where the product puts it relative to the base: the meshes are in the
    product frame, so each part's final pose equals the base's (within 0.5 mm and 0.5 deg)."""
    name, plan = fabrica_plan
    assert plan["outcome"] == "plan", (plan.get("reason") or {}).get("summary")
    final = {k: np.array(v, float) for k, v in plan["instance"]["steps"][-1]["poses"].items()}
    assert set(final) == set(_ply_of(name))
    import yaml

    Tb = final[yaml.safe_load((FABRICA / f"{name}.yaml").read_text())["base"]]
    for part, T in final.items():
        rel = np.linalg.inv(Tb) @ T
        assert np.abs(rel[:3, 3]).max() < 0.5, part
        angle = math.degrees(math.acos(min(1.0, (np.trace(rel[:3, :3]) - 1) / 2)))
        assert angle < 0.5, part


def _width_at(mesh: trimesh.Trimesh, T_part: np.ndarray, tool: np.ndarray) -> float:
    """The width the two fingers close to, centred on the tool origin: twice the part's
    farthest vertex from the tool's x-z plane among those within the pads' window (tool x
    within half the finger's width, tool z from -finger length to 0; world, mm)."""
    V = (mesh.vertices @ T_part[:3, :3].T + T_part[:3, 3] - tool[:3, 3]) @ tool[:3, :3]
    window = (np.abs(V[:, 0]) <= FINGER_W / 2) & (V[:, 2] >= -FINGER_L) & (V[:, 2] <= 0.0)
    assert window.any(), "no part between the pads"
    return 2.0 * float(np.abs(V[window, 1]).max())


def _finger_boxes(tool: np.ndarray, width: float, shrink: float = 0.0) -> list[trimesh.Trimesh]:
    """Both closed fingers of the tool at world pose ``tool`` (mm): boxes FINGER_W across (tool x),
    FINGER_T out from the contact faces ``width`` apart (tool y), from the tip (the tool centre's
    plane) FINGER_L back along -z; each face moved in by ``shrink``."""
    out = []
    for s in (1.0, -1.0):
        c = np.array([0.0, s * (width / 2 + FINGER_T / 2), -FINGER_L / 2])
        box = trimesh.creation.box(extents=[FINGER_W - 2 * shrink, FINGER_T - 2 * shrink, FINGER_L - 2 * shrink])
        box.apply_transform(tool @ trimesh.transformations.translation_matrix(c))
        out.append(box)
    return out


def test_grasps_clear(fabrica_plan):
    """At every pickup and insertion the closed fingers (at the part's own width along the
    closing axis) stay above the table and out of every part, the held one included (0.05 mm
    touch allowed), by trimesh/fcl on the PLY meshes at the step's poses."""
    name, plan = fabrica_plan
    meshes = _meshes(name)
    steps = [s for s in plan["instance"]["steps"] if s["name"] in ("pickup", "assemble")]
    assert len(steps) == 2 * (len(meshes) - 1)
    for st in steps:
        tool = np.array(st["tool_pose"], float)
        poses = {k: np.array(v, float) for k, v in st["poses"].items()}
        held = st["object"]
        width = _width_at(meshes[held], poses[held], tool)
        assert 0 < width <= 85.0, st["term"]
        fingers = _finger_boxes(tool, width, 0.05)
        for b in fingers:
            assert b.vertices[:, 2].min() > 0.0, st["term"]
        cm = trimesh.collision.CollisionManager()
        for part, m in meshes.items():
            cm.add_object(part, m, transform=poses[part])
        for b in fingers:
            hit, names = cm.in_collision_single(b, return_names=True)
            assert not hit, (st["term"], names)


def test_plumbers_block_cap_has_a_grasp_clear_of_the_seated_bearing():
    """The cap goes on over the bearing, whose top stands 11.7 mm above the block: a grasp of
    the cap from above whose fingers hold only the cap's upper half keeps them off the bearing
    and the block as the cap is seated, and above the table where the cap lies (own check: the
    PLY meshes in their product poses, the finger boxes, python-fcl through trimesh)."""
    cell = load_problem(ROOT / "kb" / "problems" / "fabrica_plumbers_block.yaml")
    ply = _ply_of("plumbers_block")
    mesh = {p: trimesh.load(f, process=False) for p, f in ply.items()}
    for m in mesh.values():
        m.apply_scale(CM)
    seated = trimesh.collision.CollisionManager()
    for p in ("block", "bearing"):
        seated.add_object(p, mesh[p])
    cap = trimesh.collision.CollisionManager()
    cap.add_object("cap", mesh["cap"])
    T_lying = cell.positions["tr_cap"].T
    ok = []
    for label, g in cell.objects["cap"].grasps.items():
        T = np.asarray(g.T, float)  # the cap's frame is the product frame: seated, it is T
        fingers = _finger_boxes(T, g.width)
        if T[2, 2] > -0.5:  # not from above as seated
            continue
        if any(seated.min_distance_single(f) < MARGIN_MM for f in fingers):
            continue
        # the pads touch the cap: each finger grown by 0.5 mm towards the part meets it
        touch = [_finger_boxes(T, g.width - 1.0)[k] for k in range(2)]
        if not all(cap.in_collision_single(f) for f in touch):
            continue
        on_table = _finger_boxes(T_lying @ T, g.width)
        if min(float(f.vertices[:, 2].min()) for f in on_table) < MARGIN_MM:
            continue
        ok.append(label)
    assert ok, "no grasp of the cap from above clear of the seated bearing and the block"


def _assembles(plan: dict) -> dict[str, tuple[int, str | None]]:
    """Each part's assemble: its index in the plan's steps and the grasp its pickup used."""
    steps = plan["instance"]["steps"]
    out, grasp = {}, {}
    for i, st in enumerate(steps):
        if st["name"] == "pickup":
            grasp[st["object"]] = st["args"][1] if len(st["args"]) > 1 else None
        if st["name"] == "assemble":
            out[st["object"]] = (i, grasp.get(st["object"]))
    return out


def test_plan_keeps_every_precedence_and_no_blocked_grasp(fabrica_plan):
    """The plan inserts each part before every part its precedence puts after it (the sweeps' and
    the hand's: world.product.access), and seats no part with a grasp hand access found blocked."""
    name, plan = fabrica_plan
    cell = load_problem(ROOT / "kb" / "problems" / f"fabrica_{name}.yaml")
    at = _assembles(plan)
    for pr in cell.product.precedence:
        assert at[pr.first][0] < at[pr.then][0], (pr.first, pr.then, pr.reason)
    for part, (_, grasp) in at.items():
        assert grasp not in cell.blocked_grasps.get(part, frozenset()), (part, grasp)


def test_stool_legs_wait_for_the_hand():
    """The stool's legs are held across their sides: one seated next to a leg already in place
    meets it, so hand access orders some legs first and names the pair; every part keeps grasps."""
    cell = load_problem(ROOT / "kb" / "problems" / "fabrica_stool_circular.yaml")
    hand = [pr for pr in cell.product.precedence if "blocks the arm" in pr.reason]
    assert any(pr.first.startswith("leg") and pr.then.startswith("leg") for pr in hand), hand
    for pr in hand:
        assert f"-{pr.then}" in pr.reason or f"{pr.then}-" in pr.reason, pr.reason
    for part, blocked in cell.blocked_grasps.items():
        assert set(cell.objects[part].grasps) - blocked, part


def test_a_product_turned_on_the_way_gets_no_hand_access():
    """turn_over's second pin goes in from below where the block lies: the product is not built in
    place, so hand access blocks no grasp and orders nothing (its checks assume the base's pose)."""
    cell = load_problem(ROOT / "kb" / "problems" / "turn_over.yaml")
    assert not cell.blocked_grasps
    assert not [pr for pr in cell.product.precedence if "blocks the arm" in pr.reason]
