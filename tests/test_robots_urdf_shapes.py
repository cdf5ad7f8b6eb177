"""A URDF arm's box collision elements become the same boxes in spar-py's model, wherever the
converted Craig frames put them (issue 15: link shapes from the URDF's <collision>).

The arm: a KUKA KR 6 R900-like chain written as URDF from its standard DH lengths (a1 25, d1 400,
a2 455, a3 35, d4 420, d6 80 mm: a shoulder offset, so the numeric solver), each link a box.
Its Craig frame 1 is the URDF's link_1 turned by pi about z, and one box's origin is turned by
0.3 rad. Each box's eight corners in the world come from yourdfpy's own FK (link pose @ the
collision origin @ the corner), not from spar_py, and must be the model's shape's corners.
A box turned to the bounding capsule used to leave the first link's capsule 110 mm under the
base (``link_1-table`` refused every pickup of a cell with this arm)."""
from __future__ import annotations

import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from paths import ROOT

DH = [(25, 400, -90), (455, 0, 0), (35, 0, -90), (0, 420, 90), (0, 0, -90), (0, 80, 0)]  # a, d (mm), alpha (deg)
LIMITS = [(-170, 170), (-190, 45), (-120, 156), (-185, 185), (-120, 120), (-350, 350)]
RADII = [75, 65, 55, 45, 40, 35]


def _origin(a: float, d: float, al: float) -> str:
    return f'<origin xyz="{a / 1000} 0 {d / 1000}" rpy="{math.radians(al)} 0 0"/>'


def write_urdf(path: Path) -> Path:
    lines = ['<?xml version="1.0"?>', '<robot name="kr6_like">', '  <link name="base_link"/>']
    for i, ((a, d, _al), r) in enumerate(zip(DH, RADII)):
        cz = d / 2000 if i else (d + r + 5) / 2000
        sz = (abs(d) + 2 * r) / 1000 if i else (d + r - 5) / 1000
        rpy = ' rpy="0 0 0.3"' if i == 2 else ""
        lines.append(f'  <link name="link_{i + 1}"><collision><origin xyz="{a / 2000} 0 {cz}"{rpy}/><geometry>'
                     f'<box size="{(abs(a) + 2 * r) / 1000} {2 * r / 1000} {sz}"/></geometry></collision></link>')
        parent = "base_link" if i == 0 else f"link_{i}"
        o = '<origin xyz="0 0 0"/>' if i == 0 else _origin(*DH[i - 1])
        lo, hi = (math.radians(v) for v in LIMITS[i])
        lines.append(f'  <joint name="a{i + 1}" type="revolute"><parent link="{parent}"/><child link="link_{i + 1}"/>'
                     f'{o}<axis xyz="0 0 1"/><limit lower="{lo}" upper="{hi}" effort="1" velocity="6"/></joint>')
    lines += ['  <link name="tool0"/>',
              '  <joint name="flange" type="fixed"><parent link="link_6"/><child link="tool0"/>'
              f'{_origin(*DH[5])}</joint>',
              '</robot>']
    path.write_text("\n".join(lines) + "\n")
    return path


@pytest.fixture(scope="module")
def arm(tmp_path_factory):
    from spar_py.world.robot.model import read_urdf_chain, robot_from_urdf

    f = write_urdf(tmp_path_factory.mktemp("urdf") / "kr6_like.urdf")
    chain = read_urdf_chain(f, "base_link", "tool0")
    robot = robot_from_urdf(chain, "kr6_like", np.eye(4), np.eye(4), 100.0, "mm", 1.0)
    return f, robot


def _own_corners(urdf, q: np.ndarray) -> dict[str, np.ndarray]:
    """Each link's box corners (8, 3) in the world (mm) by yourdfpy's FK."""
    cfg = np.zeros(len(urdf.actuated_joint_names))
    for i in range(6):
        cfg[urdf.actuated_joint_names.index(f"a{i + 1}")] = q[i]
    urdf.update_cfg(cfg)
    out = {}
    for lk in urdf.robot.links:
        for c in lk.collisions:
            T = np.asarray(urdf.get_transform(lk.name, "base_link"), float) @ np.asarray(c.origin, float)
            half = np.asarray(c.geometry.box.size, float) / 2
            P = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)]) * half
            out[lk.name] = (P @ T[:3, :3].T + T[:3, 3]) * 1000.0
    return out


def _model_corners(robot, q: np.ndarray) -> dict[str, np.ndarray]:
    F = robot.frames(q)
    out = {}
    for s in robot.links:
        assert s.kind in ("box", "hull"), f"{s.name}: a URDF box became a {s.kind}"
        if s.kind == "box":
            P = np.array([[x, y, z] for x in (s.a[0], s.b[0]) for y in (s.a[1], s.b[1]) for z in (s.a[2], s.b[2])])
        else:
            P = np.asarray(s.points, float)
        T = F[s.frame]
        out[s.name] = P @ T[:3, :3].T + T[:3, 3]
    return out


def test_urdf_boxes_are_the_same_boxes_in_the_model(arm) -> None:
    import yourdfpy

    f, robot = arm
    urdf = yourdfpy.URDF.load(str(f), build_scene_graph=True, load_meshes=False, load_collision_meshes=False)
    rng = np.random.default_rng(11)
    for q in np.vstack([np.zeros(6), rng.uniform(robot.limits[:, 0], robot.limits[:, 1], size=(20, 6))]):
        own, model = _own_corners(urdf, q), _model_corners(robot, q)
        assert set(own) == set(model)
        for name, P in own.items():
            M = model[name]
            assert len(M) == 8, name
            # the same eight points, in any order
            d = np.linalg.norm(P[:, None] - M[None], axis=2)
            assert d.min(axis=1).max() < 1e-6 and d.min(axis=0).max() < 1e-6, (name, d.min(axis=1).max())


def test_the_first_link_stays_above_the_base_plane(arm) -> None:
    """The first box starts 5 mm above base_link's plane: so does the model's shape."""
    _f, robot = arm
    M = _model_corners(robot, np.zeros(6))["link_1"]
    assert M[:, 2].min() == pytest.approx(5.0, abs=1e-6)


def _urdf_cell_with(tmp_path: Path, collision: dict) -> Path:
    """kb/problems/ur5e_urdf_peg_in_block.yaml with ``robot: collision:`` added (paths absolute)."""
    import yaml

    src = ROOT / "kb" / "problems" / "ur5e_urdf_peg_in_block.yaml"
    doc = yaml.safe_load(src.read_text())
    doc["robot"]["urdf"] = str((src.parent / doc["robot"]["urdf"]).resolve())
    doc["robot"]["collision"] = collision
    for o in doc["objects"].values():
        o["model"] = str((src.parent / o["model"]).resolve())
    out = tmp_path / "cell.yaml"
    out.write_text(yaml.safe_dump(doc, sort_keys=False))
    return out


def test_a_urdf_arm_may_allow_pairs_of_its_own_links(tmp_path: Path) -> None:
    """``collision: {allow: [[wrist_1_link, wrist_3_link]]}`` in a URDF robot keeps the URDF's
    shapes and allows that pair (UR's own collision matrix does, as kb/robots/ur5e.yaml); before,
    the URDF's link names were refused as unknown bodies, so a URDF arm whose envelopes touch two
    frames apart (a short elbow link) could not plan at all."""
    from spar_py.kb import load_problem

    cell = load_problem(_urdf_cell_with(tmp_path, {"allow": [["wrist_1_link", "wrist_3_link"]], "margin": 0.1}))
    names = [s.name for s in cell.robot.links]
    assert "wrist_1_link" in names and "forearm_link" in names  # the URDF's shapes stay
    assert frozenset(("wrist_1_link", "wrist_3_link")) in cell.robot.allowed
    assert cell.robot.margin == pytest.approx(0.1)


def test_an_unknown_body_in_a_urdf_allow_is_one_line(tmp_path: Path) -> None:
    from spar_py.core.errors import KBError
    from spar_py.kb import load_problem

    path = _urdf_cell_with(tmp_path, {"allow": [["wrist_1_link", "elbow"]]})
    with pytest.raises(KBError) as e:
        load_problem(path)
    msg = str(e.value)
    assert "\n" not in msg and "robot.collision.allow[0][1]" in msg and "'elbow'" in msg and "wrist_3_link" in msg


@pytest.mark.parametrize("damage", ["truncated", "box_without_size"])
def test_a_broken_urdf_is_one_line_on_stderr(tmp_path: Path, damage: str) -> None:
    """A URDF cut short (not well-formed XML) or with a <box> lacking its size: `spar kb check`
    writes one line naming the problem file and key and what is wrong (lxml's line and column
    for a syntax error); yourdfpy's own log lines ("Using different parsing approach.") used to
    come first, and a cut-short file ended in "KeyError: 'size'"."""
    text = write_urdf(tmp_path / "arm.urdf").read_text()
    if damage == "truncated":
        text = text[:500]
    else:
        text = text.replace('<box size="', '<box sighs="', 1)
    (tmp_path / "arm.urdf").write_text(text)
    cell = _urdf_cell_with(tmp_path, {})
    import yaml

    doc = yaml.safe_load(cell.read_text())
    doc["robot"] = {"urdf": str(tmp_path / "arm.urdf"), "base_link": "base_link", "tip_link": "tool0",
                    "gripper": {"finger_separation": 4.0}}
    cell.write_text(yaml.safe_dump(doc, sort_keys=False))
    # a process of its own: logging's last-resort handler writes to the real stderr there, as
    # for a user (under pytest, pytest's handler would take yourdfpy's lines)
    ran = subprocess.run([sys.executable, "-m", "spar_py", "kb", "check", str(cell)], capture_output=True,
                         text=True, timeout=120)
    assert ran.returncode != 0
    err = [ln for ln in ran.stderr.splitlines() if ln.strip()]
    assert len(err) == 1, err
    assert str(cell) in err[0] and "robot.urdf" in err[0]
    if damage == "truncated":
        assert "well-formed" in err[0] and "line 6" in err[0]


def test_tool_inverse_is_a_field_of_the_robot_and_follows_its_tool() -> None:
    """Robot.tool_inverse keeps inv(tool) in a declared field (not written into the instance's
    __dict__ behind the dataclass), and a new tool gives its own inverse."""
    import dataclasses

    from spar_py.kb import load_robot

    robot = load_robot(ROOT / "kb" / "robots" / "ur5e.yaml", "mm")
    assert "_tool_inv" in {f.name for f in dataclasses.fields(robot)}
    assert np.allclose(robot.tool_inverse() @ robot.tool, np.eye(4))
    robot.tool = robot.tool.copy()
    robot.tool[:3, 3] += [0.0, 0.0, 25.0]
    assert np.allclose(robot.tool_inverse() @ robot.tool, np.eye(4))
