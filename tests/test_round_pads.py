"""Pads on small rounds, and grasps on a curved face a part rests on (the gamepad's thumbstick).

A flat pad holds a round along a line: a 12 mm round (a thumbstick's cap) sags 0.55 mm across
its axis over a 5 mm patch, more than the pad depth, but not along it. The checks here are our
own arithmetic: contacts on a cylinder made with trimesh, the stick's cap grasp against the
hole's mouth plane and the table plane from the gripper's box corners.
"""
from __future__ import annotations

import numpy as np

from spar_py.kb.problem import load_problem
from spar_py.world.parts.antipodal import _pads_on_surface

from paths import ROOT


def test_pads_hold_a_12mm_round_along_its_axis() -> None:
    import trimesh

    m = trimesh.creation.cylinder(radius=6.0, height=20.0, sections=64)
    # a contact pair across the middle, closing along x; another across the flat ends (a plane)
    P = np.array([[-6.0, 0.0, 0.0], [0.0, 0.0, -10.0]])
    Q = np.array([[6.0, 0.0, 0.0], [0.0, 0.0, 10.0]])
    C = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    assert _pads_on_surface(m, P, Q, C, "mm").tolist() == [True, True]
    # a 4 mm round is too sharp across and 2.5 mm from the contact it has no surface at all
    thin = trimesh.creation.cylinder(radius=2.0, height=1.0, sections=64)
    assert not _pads_on_surface(thin, P[:1] / 3, Q[:1] / 3, C[:1], "mm")[0]


def _corners(g: object, width: float) -> np.ndarray:
    return np.concatenate([np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1])
                                     for z in (lo[2], hi[2])]) for _, lo, hi in g.boxes(width)])


def test_thumbstick_cap_is_held_above_the_mouth_and_the_table() -> None:
    cell = load_problem(ROOT / "kb/problems/fabrica_gamepad.yaml")
    stick = cell.objects["stick0"]
    goal = next(g for g in cell.goals if isinstance(g, tuple) and g[0] == "assembled" and g[1] == "stick0")
    T_a = np.asarray(cell.transforms[goal[4]], float)
    gripper = cell.robot.gripper
    # the hole's mouth: z = 25 mm in the housing's frame, the hole going down (product file, cm)
    mouth_z = 25.0
    pose = stick.poses["stick0_p1"]  # upside down on its cap, the layout's pose
    T_pose = np.eye(4)
    T_pose[:3, :3], T_pose[2, 3] = pose.R, pose.height
    seated_ok, lying_ok, low = [], [], []
    for g in stick.grasps.values():
        C = _corners(gripper, g.width)
        seated = C @ (T_a @ g.T)[:3, :3].T + (T_a @ g.T)[:3, 3]
        lying = C @ (T_pose @ g.T)[:3, :3].T + (T_pose @ g.T)[:3, 3]
        if seated[:, 2].min() >= mouth_z - 0.05:
            seated_ok.append(g.label)
        if set(g.gfaces) & set(pose.rfaces):
            (lying_ok if lying[:, 2].min() >= -0.05 else low).append(g)
    assert seated_ok, "no grasp of stick0 keeps the hand above the housing's mouth when seated"
    # on the cap only: the stick's largest round face that is not its peg (named by its derived order)
    from spar_py.world.parts import derive_faces, part_mesh

    feats = tuple(f.geometry for f in stick.features if f.geometry is not None)
    faces = derive_faces(part_mesh(stick), feats, dict(stick.geometry.face_names), "mm")
    cap = max((f for f in faces if not f.planar and not f.feature), key=lambda f: f.area)
    assert cap.centroid[2] > mouth_z + 10  # well above the mouth: the cap
    assert all(set(stick.grasps[label].gfaces) == {cap.name} for label in seated_ok)
    # the planner's rules take them: usable for the mate; condition 1 at the lying pose takes a
    # grasp on the face it rests on whose hand is above the table, and refuses the others
    from spar_py.kb.prolog_facts import _mate_grasps
    from spar_py.world.reach.arcs import _hand_clear, _part_on_table
    from spar_py.world.robot import gripper_for

    usable = next(f[3] for f in _mate_grasps(cell) if f[2] == "stick0")
    assert set(seated_ok) <= set(usable)
    T_lying, gripper = _part_on_table(stick, "stick0_p1", None), gripper_for(cell)
    assert lying_ok and all(_hand_clear(cell, stick, g, T_lying, gripper) for g in lying_ok)
    assert low and not any(_hand_clear(cell, stick, g, T_lying, gripper) for g in low)


def _world(C: np.ndarray, T: np.ndarray) -> np.ndarray:
    return C @ T[:3, :3].T + T[:3, 3]


def test_button_peg_is_held_at_its_root_clear_of_the_housing() -> None:
    """button1's peg is 20 mm long and 10 mm of it goes into the housing (mouth at z = 25 mm,
    the peg from z = 15 to 35 in the product frame): a grasp holds at least 5 mm of the outer
    10 mm with every finger and palm corner 2 mm (the collision margin) above the mouth."""
    cell = load_problem(ROOT / "kb/problems/fabrica_gamepad.yaml")
    button = cell.objects["button1"]
    goal = next(g for g in cell.goals if isinstance(g, tuple) and g[0] == "assembled" and g[1] == "button1")
    T_a = np.asarray(cell.transforms[goal[4]], float)
    gripper = cell.robot.gripper
    clear = []
    for g in button.grasps.values():
        M = T_a @ g.T
        if _world(_corners(gripper, g.width), M)[:, 2].min() < 25.0 + 2.0:
            continue
        # the pads' extent along the peg's axis (world z here), against the peg's outer 10 mm
        _, lo, hi = gripper.boxes(g.width)[0]
        pad = _world(np.array([[x, 0.0, z] for x in (lo[0], hi[0]) for z in (lo[2], hi[2])]), M)[:, 2]
        if min(pad.max(), 35.0) - max(pad.min(), 25.0) >= 5.0 - 1e-6 and abs(g.width - 23.0) < 0.01:
            clear.append(g.label)
    assert clear, "no grasp of button1 holds its peg above the housing by the collision margin"


def test_layout_lays_mated_parts_where_a_usable_grasp_is_above_the_table() -> None:
    """The sticks and button1 rest on their caps or tops in their most probable poses, where
    every grasp their mates can use comes from below; the layout stands them the other way."""
    cell = load_problem(ROOT / "kb/problems/fabrica_gamepad.yaml")
    gripper = cell.robot.gripper
    for part in ("stick0", "stick5", "button1"):
        model = cell.objects[part]
        T = next(p.T for p in cell.positions.values() if p.obj == part)
        goal = next(g for g in cell.goals if isinstance(g, tuple) and g[0] == "assembled" and g[1] == part)
        T_a = np.asarray(cell.transforms[goal[4]], float)
        mouth = float(model.feature_on(tuple(goal[3][0])).geometry.origin[2])  # the peg's root: z of the mouth or above
        hole_mouth = float(cell.objects["housing"].feature_on(tuple(goal[3][1])).geometry.origin[2])
        assert mouth >= hole_mouth - 1e-6
        ok = [g.label for g in model.grasps.values()
              if _world(_corners(gripper, g.width), T_a @ g.T)[:, 2].min() >= hole_mouth - 0.05
              and _world(_corners(gripper, g.width), T @ g.T)[:, 2].min() >= -0.05]
        assert ok, f"{part}: no grasp usable when seated keeps the hand above the table where it lies"
