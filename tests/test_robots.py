"""world/robot/model.py: DH conventions, URDF import (kb/robots/ur5e.urdf), the FK check, the same plan."""
from __future__ import annotations

import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from spar_py import Planner
from spar_py.core.errors import KBError, SparValueError
from spar_py.kb import load_problem, load_robot
from spar_py.world.robot.model import Robot, check_against_urdf, read_urdf_chain, robot_from_urdf, standard_to_modified

from paths import ROOT

URDF = ROOT / "kb" / "robots" / "ur5e.urdf"
UR5E = ROOT / "kb" / "robots" / "ur5e.yaml"
PROBLEMS = ROOT / "kb" / "problems"
sys.path.insert(0, str(Path(__file__).parent))
from test_ik_ur import std_fk  # noqa: E402  (the published UR5e, written out)


def test_standard_to_modified_is_exact() -> None:
    rng = np.random.default_rng(0)
    std = np.column_stack([rng.uniform(-3, 3, 6), rng.uniform(-500, 500, 6), rng.uniform(-500, 500, 6),
                           rng.uniform(-3, 3, 6)])
    dh, flange = standard_to_modified(std)
    robot = Robot("r", dh, [[-6, 6]] * 6, np.eye(4), flange, 1.0, "mm")
    for q in rng.uniform(-3, 3, size=(20, 6)):
        T = np.eye(4)
        for (alpha, a, d, off), qi in zip(std, q):  # rotz(theta) transz(d) transx(a) rotx(alpha)
            c, s, ca, sa = math.cos(qi + off), math.sin(qi + off), math.cos(alpha), math.sin(alpha)
            T = T @ np.array([[c, -s * ca, s * sa, a * c], [s, c * ca, -c * sa, a * s], [0, sa, ca, d], [0, 0, 0, 1]])
        assert np.allclose(robot.fk(q), T, atol=1e-9)


def test_the_shipped_urdf_is_the_published_ur5e() -> None:
    # the URDF's own FK (yourdfpy), from UR's base frame to tool0, against the published DH written out
    import yourdfpy

    urdf = yourdfpy.URDF.load(str(URDF), load_meshes=False, build_scene_graph=True)
    rng = np.random.default_rng(1)
    for q in rng.uniform(-math.pi, math.pi, size=(20, 6)):
        urdf.update_cfg(q)
        T = np.array(urdf.get_transform("tool0", "base"))
        T[:3, 3] *= 1000.0
        want = std_fk("ur5e", q)[0]
        tool = np.eye(4)
        tool[2, 3] = 150.0
        assert np.allclose(T @ tool, want, atol=1e-5)  # the URDF writes pi/2 as 1.570796327


def urdf_robot(unit: str = "mm", **kw: object) -> Robot:
    chain = read_urdf_chain(URDF, str(kw.pop("base_link", "base")), str(kw.pop("tip_link", "tool0")))
    tool = np.eye(4)
    tool[2, 3] = 150.0 if unit == "mm" else 150.0 / 25.4
    return robot_from_urdf(chain, "ur5e", np.eye(4), tool, 85.0, unit, 1.0 if unit == "mm" else 25.4)


def test_urdf_ur5e_is_recognised_and_matches_its_dh_file() -> None:
    r, y = urdf_robot(), load_robot(UR5E)
    assert r.solver_name == "closed-form ur"
    assert r.joint_names[0] == "shoulder_pan_joint" and r.joint_names[-1] == "wrist_3_joint"
    assert np.allclose(r.limits, [[-TWO_PI, TWO_PI]] * 6)
    q = np.random.default_rng(2).uniform(-6, 6, size=(100, 6))
    assert np.abs(r.fk_batch(q) - y.fk_batch(q)).max() < 1e-6  # mm: 1.570796327 vs pi/2 in the URDF
    T = y.fk_batch(q)
    Q, ok = r.ik_batch(T)
    assert ok.any(axis=1).all()
    assert np.abs(r.fk_batch(Q[ok]) - T[np.nonzero(ok)[0]]).max() < 1e-9


TWO_PI = 2 * math.pi


def test_urdf_from_base_link_is_turned_half_a_turn() -> None:
    # ROS's base_link is UR's base turned by pi about z: the same arm, its world frame turned
    a, b = urdf_robot(base_link="base_link"), urdf_robot()
    q = np.random.default_rng(3).uniform(-3, 3, size=(10, 6))
    Rz = np.diag([-1.0, -1.0, 1.0, 1.0])
    assert np.allclose(a.fk_batch(q), Rz @ b.fk_batch(q), atol=1e-6)


def test_the_fk_check_names_the_joint_that_differs() -> None:
    chain = read_urdf_chain(URDF, "base", "tool0")
    r = urdf_robot()
    bad = Robot(r.name, r.dh.copy(), r.limits, r.base, r.tool, 85.0, "mm", joint_names=r.joint_names)
    bad.dh[3, 1] += 1.0  # the forearm 1 mm too long: the link after elbow_joint (wrist_1) moves
    tool = np.eye(4)
    tool[2, 3] = 150.0
    # Craig's frame i vs joint i's child link, from the conversion (as robot_from_urdf has them)
    offsets = np.array([np.linalg.inv(F) @ C for F, C in zip(r.frames(np.zeros(6))[1:7],
                                                          [_child(chain, i) for i in range(6)])])
    with pytest.raises(SparValueError, match="joint 'wrist_1_joint'"):
        check_against_urdf(bad, chain, np.eye(4), tool, 1000.0, offsets)
    check_against_urdf(r, chain, np.eye(4), tool, 1000.0, offsets)  # the real one passes


def _child(chain, i: int) -> np.ndarray:
    F = chain.link_frames(np.zeros(6))[i].copy()
    F[:3, 3] *= 1000.0
    return F


def _without_collisions(tmp_path, name: str):
    """A copy of kb/problems/NAME.yaml with ``collision: false`` (its files by absolute path)."""
    text = (PROBLEMS / f"{name}.yaml").read_text().replace("../", f"{PROBLEMS.parent}/")
    out = tmp_path / f"{name}.yaml"
    out.write_text(text + "\ncollision: false\n")
    return out


#: The paper's plan (Sec. 6): turn the block over with a side grasp, then pick up the peg and insert it.
PAPER_STEPS = ["pickup(block,p2G1)", "putdown(block,p2P1)", "pickup(peg,p1G10)",
               "assemble(peg,block,[[peg_face],[block_face]],trans_1,vec_1)"]


def _same_plan(a, b) -> None:
    assert a.outcome.value == b.outcome.value == "plan", (a.reason, b.reason)
    assert [x.term for x in a.actions] == [x.term for x in b.actions]
    assert [s.term for s in a.steps] == [s.term for s in b.steps]
    assert a.partial["ordering"] == b.partial["ordering"]
    for sa, sb in zip(a.steps, b.steps):
        assert sa.ik_solver == sb.ik_solver == "closed-form ur"
        assert np.allclose(sa.joints_deg, sb.joints_deg, atol=1e-6)
        assert sa.placement == sb.placement


def test_urdf_cell_gives_the_same_plan_with_collisions() -> None:
    # collision checking on (the cells' default): the UR5e turns the block over with the paper's
    # side grasp at the table's edge (the table: key), and the URDF's collision cylinders give the
    # DH file's plan, step for step, joint for joint
    planner = Planner(timeout=60)
    a = planner.plan(str(PROBLEMS / "ur5e_peg_in_block.yaml"))
    b = planner.plan(str(PROBLEMS / "ur5e_urdf_peg_in_block.yaml"))
    _same_plan(a, b)
    assert [s.term for s in a.steps] == PAPER_STEPS
    put = a.steps[1].placement
    assert put["y"] == pytest.approx(5.0) and round(put["yaw_deg"]) % 360 == 180  # flush with the +y edge


def test_urdf_cell_gives_the_same_plan_as_the_dh_cell(tmp_path) -> None:
    # the kinematics alone (collision: false): the URDF's converted chain plans as the DH table does
    planner = Planner(timeout=60)
    a = planner.plan(str(_without_collisions(tmp_path, "ur5e_peg_in_block")))
    b = planner.plan(str(_without_collisions(tmp_path, "ur5e_urdf_peg_in_block")))
    _same_plan(a, b)
    cell = load_problem(PROBLEMS / "ur5e_urdf_peg_in_block.yaml")
    assert cell.robot.name == "ur5e" and str(URDF.resolve()) in cell.files


def test_ur_files_give_urs_published_joint_speeds() -> None:
    # UR's technical specifications: UR5e 180 deg/s on every joint; UR10e 120 on base and shoulder
    for name, want in (("ur5e", [180] * 6), ("ur10e", [120, 120, 180, 180, 180, 180])):
        r = load_robot(ROOT / "kb" / "robots" / f"{name}.yaml")
        assert np.allclose(np.degrees(r.velocity_limits), want)
    cell = load_problem(PROBLEMS / "ur5e_urdf_peg_in_block.yaml")
    assert np.allclose(np.degrees(cell.robot.velocity_limits), [180] * 6)


def test_urdf_links_fixed_to_the_chain_carry_their_collision_shapes() -> None:
    # UR's base_link hangs above the chain's base_link (`base`) by a fixed joint, the coupling
    # below tool0: their cylinders count, placed where the URDF puts them (world mm)
    robot = load_problem(PROBLEMS / "ur5e_urdf_peg_in_block.yaml").robot
    shapes = {s.name: s for s in robot.links}
    assert {"base_link", "coupling"} <= set(shapes)
    base, coupling = shapes["base_link"], shapes["coupling"]
    assert base.frame == 0 and coupling.frame == 6
    ends = sorted((robot.base @ np.append(p, 1.0))[2] * 25.4 for p in (base.a, base.b))
    assert np.allclose(ends, [0.0, 90.0]) and base.radius * 25.4 == pytest.approx(75.0)
    q = np.radians([10, -80, 70, -30, 40, 20])  # the coupling: 0..65 mm out of the flange, on its axis
    T = std_fk("ur5e", q[None])[0]  # the published arm's tool (150 mm out of the flange)
    F = robot.frames(q)[6]
    flange, z = T[:3, 3] - 150.0 * T[:3, 2], T[:3, 2]
    along = []
    for p in (coupling.a, coupling.b):
        v = (F @ np.append(p, 1.0))[:3] * 25.4 - flange
        along.append(v @ z)
        assert np.linalg.norm(v - (v @ z) * z) < 1e-6  # on the flange's axis
    assert np.allclose(sorted(along), [0.0, 65.0], atol=1e-6)


def write_cell(tmp_path: Path, robot_block: str) -> Path:
    text = (PROBLEMS / "ur5e_urdf_peg_in_block.yaml").read_text()
    start = text.index("robot:\n")
    end = text.index("objects:")
    out = tmp_path / "cell.yaml"
    body = text[:start] + robot_block + text[end:]
    out.write_text(body.replace("../objects/", str(ROOT / "kb" / "objects") + "/"))
    return out


@pytest.mark.parametrize("block, key, expected", [
    (f"robot: {{urdf: {URDF}, base_link: base, tip_link: nowhere, gripper: {{finger_separation: 3}}}}\n",
     "robot.urdf", "tip_link 'nowhere': a link of the URDF"),
    (f"robot: {{urdf: {URDF}, base_link: tool0, tip_link: base, gripper: {{finger_separation: 3}}}}\n",
     "robot.urdf", "is not below base_link 'tool0'"),
    (f"robot: {{urdf: {URDF}, base_link: base, tip_link: wrist_2_link, gripper: {{finger_separation: 3}}}}\n",
     "robot.urdf", "6 revolute joints from base to wrist_2_link (spar-py plans with 6R arms), not 5"),
    ("robot: {urdf: nothing.urdf, base_link: base, tip_link: tool0, gripper: {finger_separation: 3}}\n",
     "robot.urdf", "the path of a URDF file"),
    (f"robot: {{urdf: {URDF}, base_link: base, tip_link: tool0, gripper: {{finger_separation: 3}}, "
     "ik: puma}\n", "robot.urdf", "a PUMA-family arm"),
    (f"robot: {{urdf: {URDF}, base_lnk: base, tip_link: tool0, gripper: {{finger_separation: 3}}}}\n",
     "robot.base_lnk", "unknown key; did you mean base_link?"),
])
def test_bad_urdf_robot_is_one_line(tmp_path: Path, block: str, key: str, expected: str) -> None:
    path = write_cell(tmp_path, block)
    with pytest.raises(KBError) as exc:
        load_problem(path)
    msg = str(exc.value)
    assert "\n" not in msg and str(path) in msg and f": {key}: " in msg and expected in msg, msg


def test_prismatic_joint_and_cli_exit(tmp_path: Path) -> None:
    bad = tmp_path / "slide.urdf"
    bad.write_text(URDF.read_text().replace('<joint name="elbow_joint" type="revolute">',
                                            '<joint name="elbow_joint" type="prismatic">'))
    path = write_cell(tmp_path, f"robot: {{urdf: {bad}, base_link: base, tip_link: tool0, "
                                "gripper: {finger_separation: 3}}\n")
    out = subprocess.run([sys.executable, "-m", "spar_py", "plan", str(path)], capture_output=True, text=True)
    assert out.returncode == 2, out.stderr
    assert out.stderr.count("\n") == 1 and "elbow_joint (prismatic)" in out.stderr and "Traceback" not in out.stderr


def test_a_dh_cell_does_not_import_the_urdf_reader() -> None:
    # yourdfpy (and lxml, trimesh) are imported only when a cell names a URDF
    code = ("import sys; from spar_py.kb import load_problem; "
            f"load_problem({str(PROBLEMS / 'ur5e_peg_in_block.yaml')!r}); "
            "print(sorted(m for m in ('yourdfpy', 'trimesh', 'lxml') if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]", out.stdout + out.stderr


def _urdf_with_forearm_mesh(tmp_path: Path, filename: str, write_mesh: bool = True) -> Path:
    """kb/robots/ur5e.urdf with the forearm's collision cylinder replaced by a mesh of that
    cylinder (a 64-sided trimesh cylinder, STL, in the collision element's frame, metres)."""
    import trimesh

    text = URDF.read_text()
    old = '<cylinder radius="0.04" length="0.3922"/>'
    assert text.count(old) == 1
    out = tmp_path / "ur5e_mesh.urdf"
    out.write_text(text.replace(old, f'<mesh filename="{filename}"/>'))
    if write_mesh:
        (tmp_path / "meshes").mkdir(exist_ok=True)
        trimesh.creation.cylinder(radius=0.04, height=0.3922, sections=64).export(tmp_path / "meshes" / "forearm.stl")
    return out


@pytest.mark.parametrize("filename", ["meshes/forearm.stl", "package://ur_description/meshes/forearm.stl"])
def test_urdf_collision_meshes_are_their_convex_hulls(tmp_path: Path, filename: str) -> None:
    """A URDF link whose collision geometry is a mesh (as UR's and most vendors' are) gets the
    mesh's convex hull, placed where the URDF's cylinder of the same size is: every hull vertex
    within the cylinder's radius of its axis, the hull spanning it; relative and package:// names."""
    urdf = _urdf_with_forearm_mesh(tmp_path, filename)
    chain = read_urdf_chain(urdf, "base", "tool0")
    tool = np.eye(4)
    tool[2, 3] = 150.0
    mesh_robot = robot_from_urdf(chain, "ur5e", np.eye(4), tool, 85.0, "mm", 1.0)
    (hull,) = [s for s in mesh_robot.links if s.name == "forearm_link"]
    (cyl,) = [s for s in urdf_robot().links if s.name == "forearm_link"]
    assert hull.kind == "hull" and cyl.kind == "cylinder" and hull.frame == cyl.frame
    axis = (cyl.b - cyl.a) / np.linalg.norm(cyl.b - cyl.a)
    t = (hull.points - cyl.a) @ axis
    radial = np.linalg.norm((hull.points - cyl.a) - t[:, None] * axis, axis=1)
    tol = 1e-4  # mm: STL stores single-precision vertices
    assert radial.max() <= cyl.radius + tol and radial.max() > 0.99 * cyl.radius
    assert t.min() == pytest.approx(0.0, abs=tol) and t.max() == pytest.approx(np.linalg.norm(cyl.b - cyl.a), abs=tol)


def test_urdf_collision_mesh_not_found_is_one_line(tmp_path: Path) -> None:
    urdf = _urdf_with_forearm_mesh(tmp_path, "package://ur_description/meshes/missing.stl", write_mesh=False)
    path = write_cell(tmp_path, f"robot: {{urdf: {urdf}, base_link: base, tip_link: tool0, "
                                "gripper: {finger_separation: 3}}\n")
    with pytest.raises(KBError) as exc:
        load_problem(path)
    msg = str(exc.value)
    assert "\n" not in msg and "forearm_link" in msg and "missing.stl" in msg and "not found" in msg, msg
