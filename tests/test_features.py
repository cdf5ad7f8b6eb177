"""Parts with several features (issue 33, item 1), goals that name features (item 2) and the
insertion check at the right points (item 6).

Cells are written here (millimetres, the PUMA 762): a plate with two through bores 80 mm
apart and two headed pins; a block with one bore, as deep as the pin's shaft, 5 mm deeper,
or with a 5 mm relief at its bottom. Geometry is checked with plain numpy from the numbers
written below, not with the planner's code.
"""
from __future__ import annotations

import math
from pathlib import Path

import casadi as ca
import numpy as np
import pytest

from spar_py.core import geometry
from spar_py.core.errors import KBError, SparValueError
from spar_py.core.model import Bounds, MatingFeature
from spar_py.kb import load_problem
from spar_py.phase2.supinf import Bounder
from spar_py.phase2.symbolic import Registry
from spar_py.phase2.uncertainty import (
    ObjectState,
    WorldState,
    assemble_constraints,
    evaluate,
    pickup,
    table_error,
)
from spar_py.planning.planner import Planner

from paths import ROOT

PUMA = ROOT / "kb" / "robots" / "puma762.yaml"
DEG = math.pi / 180

#: The pins: a 50 x 50 x 40 head, a shaft of radius 8 from z = 40 to z = 70 (its tip).
PIN = """object: {name}
units: {{length: mm, angle: deg}}
shape:
  - {{box: {{min: [-25, -25, 0], max: [25, 25, 40]}}}}
  - {{cylinder: {{radius: 8, z: [40, 70]}}}}
feature: {{kind: peg, name: shaft, radius: {radius}, axis: {{origin: [0, 0, 40], direction: [0, 0, 1]}}, length: 30}}
"""
PIN_TIP = np.array([0.0, 0.0, 70.0])
#: The plate: 200 x 80 x 60, bores of radius 8.5 through it at x = -40 and x = +40.
BORES = {"bore_a": -40.0, "bore_b": 40.0}
PLATE = """object: plate
units: {length: mm, angle: deg}
mesh: plate.stl
features:
  - {kind: hole, name: bore_a, radius: 8.5, axis: {origin: [-40, 0, 60], direction: [0, 0, -1]}, length: 60,
     through: true}
  - {kind: hole, name: bore_b, radius: 8.5, axis: {origin: [40, 0, 60], direction: [0, 0, -1]}, length: 60,
     through: true}
"""
UNCERTAINTY = """uncertainty:
  manipulator: {dx: [-0.025, 0.025], dy: [-0.025, 0.025], dz: [-0.025, 0.025], dtheta: [-0.001, 0.001]}
  objects:
"""
BOUNDS = "{dx: [-0.1, 0.1], dy: [-0.1, 0.1], dz: [-0.1, 0.1], dtheta: [-0.2, 0.2]}"
#: A pin lying on a side face of its head, shaft along world -y (as the paper's peg lies).
LYING = "[[1, 0, 0], [0, 0, 1], [0, -1, 0], [{x}, -250, 25]]"


def _plate_stl(path: Path) -> None:
    """The plate's mesh: a box less two cylinders (trimesh + manifold3d)."""
    import trimesh

    box = trimesh.creation.box(bounds=[[-100, -40, 0], [100, 40, 60]])
    holes = [trimesh.creation.cylinder(radius=8.5, segment=[[x, 0, -1], [x, 0, 61]], sections=64)
             for x in BORES.values()]
    trimesh.boolean.difference([box, *holes], engine="manifold").export(str(path))


def _problem(path: Path, objects: dict[str, tuple[str, str]], goals: list[str], extra: str = "") -> Path:
    """A problem file: ``objects`` name -> (model file, initial tm), the goals, and ``extra`` keys."""
    lines = ["problem: features_cell", "units: {length: mm, angle: deg}", f"robot: {PUMA}", "objects:"]
    for k, (name, (model, tm)) in enumerate(objects.items(), start=1):
        lines += [f"  {name}:", f"    model: {model}",
                  f"    initial: {{name: init_pos{k}, label: tr{k}, tm: {tm}}}"]
    lines += ["gripper: open", UNCERTAINTY.rstrip()]
    lines += [f"    {name}: {BOUNDS}" for name in objects]
    lines += ["goals:"] + [f"  - {g}" for g in goals]
    path.write_text("\n".join(lines) + "\n" + extra)
    return path


@pytest.fixture(scope="module")
def plate_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    d = tmp_path_factory.mktemp("plate")
    _plate_stl(d / "plate.stl")
    (d / "plate.yaml").write_text(PLATE)
    for name in ("pin_a", "pin_b"):
        (d / f"{name}.yaml").write_text(PIN.format(name=name, radius=8))
    return d


def _two_pins(d: Path, goals: list[str], name: str = "two_pins.yaml") -> Path:
    return _problem(d / name, {"pin_a": ("pin_a.yaml", LYING.format(x=700)),
                               "pin_b": ("pin_b.yaml", LYING.format(x=820)),
                               "plate": ("plate.yaml", "[[1, 0, 0], [0, 1, 0], [0, 0, 1], [762, 150, 0]]")}, goals)


# ---------------------------------------------------------------------- the model (item 1)


def test_a_part_with_two_named_through_bores(plate_dir: Path) -> None:
    cell = load_problem(_two_pins(plate_dir, ["mated(pin_a, shaft, plate, bore_a)"]))
    plate = cell.objects["plate"]
    assert [f.name for f in plate.features] == ["bore_a", "bore_b"]
    assert all(f.kind == "hole" and f.through for f in plate.features)
    # each feature's face is a derived face of its own, named by the feature
    assert plate.feature_named("bore_b").faces == ("bore_b",) and {"bore_a", "bore_b"} <= set(plate.faces)
    assert plate.feature_on(["bore_b"]) is plate.feature_named("bore_b")
    assert plate.feature_on(["pz"]) is None
    assert plate.mating_faces == ("bore_a", "bore_b")
    # F_h of each is its bore's exit centre (origin + length * direction), from the file's numbers
    for f in plate.features:
        np.testing.assert_allclose(f.vector, [BORES[f.name], 0, 0], atol=1e-12)
    with pytest.raises(SparValueError, match=r"plate has no feature 'bore_c' \(its features: bore_a, bore_b\)"):
        plate.feature_named("bore_c")
    # a through bore's face is its wall only: every triangle 8.5 from its axis (no bottom cap)
    from spar_py.world.parts.mesh import derive_faces, part_mesh

    mesh = part_mesh(plate)
    faces = {f.name: f for f in derive_faces(mesh, tuple(f.geometry for f in plate.features), {}, "mm")}
    for name, x in BORES.items():
        V = np.asarray(mesh.vertices)[np.asarray(mesh.faces)[faces[name].tris]].reshape(-1, 3)
        assert len(V) and np.allclose(np.hypot(V[:, 0] - x, V[:, 1]), 8.5, atol=1e-6)


def test_feature_may_be_a_list_as_features(plate_dir: Path) -> None:
    from spar_py.kb.objects import load_object

    (plate_dir / "plate_list.yaml").write_text(PLATE.replace("features:", "feature:"))
    a, b = load_object(plate_dir / "plate.yaml", "mm"), load_object(plate_dir / "plate_list.yaml", "mm")
    assert [(f.name, f.faces, f.through) for f in a.features] == [(f.name, f.faces, f.through) for f in b.features]
    assert len(b.features) == 2


def test_a_single_feature_is_named_by_its_face_or_kind() -> None:
    paper = MatingFeature("hole", ("block_face",), 0.9, np.zeros(3))
    assert paper.name == "hole" and not paper.through
    cell = load_problem(ROOT / "kb" / "problems" / "peg_in_block_shapes.yaml")
    assert [f.name for f in cell.objects["peg"].features] == ["peg_face"]
    assert load_problem(ROOT / "kb" / "problems" / "peg_in_block.yaml").objects["peg"].features[0].name == "peg"


def _object_error(tmp_path: Path, text: str) -> str:
    from spar_py.kb.objects import load_object

    p = tmp_path / "part.yaml"
    p.write_text(text)
    with pytest.raises(KBError) as e:
        load_object(p, "mm")
    return str(e.value)


SHAPE = """object: part
units: {length: mm, angle: deg}
shape:
  - {box: {min: [-30, -30, 0], max: [30, 30, 40]}}
  - {cylinder: {radius: 8, z: [10, 41], subtract: true}}
"""


def test_features_refused_in_one_line(tmp_path: Path) -> None:
    hole = "{kind: hole, name: bore, radius: 8, axis: {origin: [0, 0, 40], direction: [0, 0, -1]}, length: 30}"
    unnamed = "{kind: hole, radius: 8, faces: [pz], vector: [0, 0, 10]}"
    msg = _object_error(tmp_path, SHAPE + f"features:\n  - {hole}\n  - {unnamed}\n")
    assert msg.endswith("features[1]: expected a name: for each feature of a part with several")
    msg = _object_error(tmp_path, SHAPE + f"features:\n  - {hole}\n  - {hole}\n")
    assert "features" in msg and "distinct surfaces" in msg  # one surface claimed twice
    msg = _object_error(tmp_path, SHAPE + f"feature: {hole}\nfeatures:\n  - {hole}\n")
    assert msg.endswith("features: expected feature: or features:, not both")
    peg = ("{kind: peg, name: bore, radius: 8, axis: {origin: [0, 0, 40], direction: [0, 0, -1]}, length: 30, "
           "through: true}")
    msg = _object_error(tmp_path, SHAPE + f"feature: {peg}\n")
    assert msg.endswith("feature.through: expected through: only on a hole (a peg has one tip), not true")
    assert "\n" not in msg


# ---------------------------------------------------------------------- goals (item 2)


def _tip_on_axis(T_plate: np.ndarray, T_pin: np.ndarray, x: float) -> float:
    """How far (mm) the pin's tip is from the axis of the plate's bore at x, across it (numpy)."""
    tip = (T_pin @ np.append(PIN_TIP, 1.0))[:3]
    local = np.linalg.inv(T_plate) @ np.append(tip, 1.0)
    return float(math.hypot(local[0] - x, local[1]))


def test_two_pins_each_checked_against_its_own_bore(plate_dir: Path) -> None:
    """The issue's bug: the second pin's verdict was measured against the first bore, 80 mm
    away (bound 6400 and more). Each assemble now names its bore, ends with the pin's tip on
    that bore's axis, and its check is against that bore: both satisfied."""
    path = _two_pins(plate_dir, ["mated(pin_a, shaft, plate, bore_a)", "mated(pin_b, shaft, plate, bore_b)"])
    plan = Planner().plan(path)
    assert plan.ok, plan.reason
    assembles = [s for s in plan.steps if s.name == "assemble"]
    assert sorted((s.args[0], s.args[2][1][0]) for s in assembles) == [("pin_a", "bore_a"), ("pin_b", "bore_b")]
    last = plan.steps[-1].poses
    size = 200.0
    for pin, bore in (("pin_a", "bore_a"), ("pin_b", "bore_b")):
        assert _tip_on_axis(np.array(last["plate"]), np.array(last[pin]), BORES[bore]) < 1e-6 * size
    checks = [v for s in assembles for v in s.verdicts if v.constraint == "centres"]
    assert len(checks) == 2
    for s in assembles:
        (v,) = [v for v in s.verdicts if v.constraint == "centres"]
        bore = s.args[2][1][0]
        assert v.satisfied and v.bound < v.threshold == pytest.approx(0.5 ** 2)
        assert bore in v.description
    # Monte Carlo replay: no draw of the uncertainty variables breaks a satisfied verdict
    from spar_py.phase2.instance import sample_check
    from spar_py.world.collision import CellCache

    steps = [{"id": s.id, "name": s.name, "args": list(s.args)} | ({"source": s.source} if s.source else {})
             for s in plan.steps]
    replay = sample_check(CellCache(load_problem(path)), steps, draws=5000)
    assert len(replay) == 10 and all(r["declared_satisfied"] and r["failed_draws"] == 0 for r in replay)


def test_assembled_2_is_ambiguous_with_two_bores(plate_dir: Path) -> None:
    path = _two_pins(plate_dir, ["assembled(pin_a, plate)"], "ambiguous.yaml")
    with pytest.raises(KBError) as e:
        load_problem(path)
    assert str(e.value) == (f"{path}: goals[0]: expected plate with one hole feature for assembled/2; it has 2 "
                            "(bore_a, bore_b): name them with mated(Peg, PegFeature, Hole, HoleFeature)")


def test_five_argument_goal_must_name_a_feature(plate_dir: Path) -> None:
    path = _two_pins(plate_dir, ["assembled(pin_a, plate, [[shaft], [pz]], trans_9, vec_9)"], "faces.yaml")
    text = path.read_text() + ("transforms:\n  trans_9: {tm: [[1, 0, 0], [0, -1, 0], [0, 0, -1], [-40, 0, 90]]}\n"
                               "vectors:\n  vec_9: [0, 0, -1]\n")
    path.write_text(text)
    with pytest.raises(KBError) as e:
        load_problem(path)
    assert str(e.value) == (f"{path}: goals[0]: expected hole faces naming a feature of plate (its features' faces: "
                            "bore_a: bore_a; bore_b: bore_b), not 'pz'")
    # the same goal naming bore_a is taken: T_a puts the tip (0, 0, 70) at (-40, 0, 20), on bore_a's axis
    path.write_text(text.replace("[pz]", "[bore_a]"))
    cell = load_problem(path)
    assert cell.goals[0][3] == [["shaft"], ["bore_a"]]
    # ... and naming bore_b with that T_a (40 mm + 40 mm off bore_b's axis) is refused with the offset
    path.write_text(text.replace("[pz]", "[bore_b]"))
    with pytest.raises(KBError) as e:
        load_problem(path)
    assert str(e.value) == (f"{path}: goals[0]: expected T_a putting pin_a's tip on the axis of plate.bore_b in "
                            "assembled(pin_a, plate, ...), not a tip 80 off that axis")


def test_mated_is_assembled_2_for_the_named_features() -> None:
    """mated/4 compiles to the assembled/5 goal assembled/2 gives for the same features."""
    src = ROOT / "kb" / "problems" / "peg_in_block_shapes.yaml"
    a = load_problem(src)
    tmp = src.parent / "_mated_test.yaml"
    try:
        tmp.write_text(src.read_text().replace("assembled(peg, block)", "mated(peg, peg_face, block, block_face)"))
        m = load_problem(tmp)
    finally:
        tmp.unlink()
    assert m.goals == a.goals and m.turns == a.turns
    assert all(np.array_equal(m.transforms[k], a.transforms[k]) for k in a.transforms)
    assert all(np.array_equal(m.vectors[k], a.vectors[k]) for k in a.vectors)


def test_mated_names_unknown_features(plate_dir: Path) -> None:
    path = _two_pins(plate_dir, ["mated(pin_a, shaft, plate, bore_c)"], "unknown.yaml")
    with pytest.raises(KBError) as e:
        load_problem(path)
    assert str(e.value) == (f"{path}: goals[0]: expected a feature of plate in mated(pin_a, shaft, plate, bore_c) "
                            "(bore_a (hole), bore_b (hole)), not 'bore_c'")


def test_a_peg_wider_than_its_hole_is_an_input_error(plate_dir: Path) -> None:
    (plate_dir / "fat_pin.yaml").write_text(PIN.format(name="fat_pin", radius=8.5))
    path = _problem(plate_dir / "fat.yaml", {
        "fat_pin": ("fat_pin.yaml", LYING.format(x=700)),
        "plate": ("plate.yaml", "[[1, 0, 0], [0, 1, 0], [0, 0, 1], [762, 150, 0]]")},
        ["mated(fat_pin, shaft, plate, bore_a)"])
    with pytest.raises(KBError) as e:
        load_problem(path)
    assert str(e.value) == (f"{path}: goals[0]: expected a hole wider than its peg in mated(fat_pin, shaft, plate, "
                            "bore_a), not fat_pin.shaft of radius 8.5 into plate.bore_a of radius 8.5 (clearance 0)")


# ---------------------------------------------------------------------- the insertion check (item 6)


BLOCK = """object: block
units: {{length: mm, angle: deg}}
shape:
  - {{box: {{min: [-50, -50, 0], max: [50, 50, 60]}}}}
  - {{cylinder: {{radius: 8.5, z: [{bottom}, 61], subtract: true}}}}
{relief}feature: {{kind: hole, name: bore, radius: 8.5, axis: {{origin: [0, 0, 60], direction: [0, 0, -1]}},
           length: {depth}}}
"""


def _block_cell(d: Path, depth: float, relief: bool = False) -> Path:
    """The pin and a block with one bore ``depth`` deep (the shaft is 30 long); ``relief``: the
    bore is 30 deep and a wider relief (radius 10) takes it to ``depth``."""
    d.mkdir(parents=True, exist_ok=True)
    (d / "pin.yaml").write_text(PIN.format(name="pin", radius=8))
    rel = f"  - {{cylinder: {{radius: 10, z: [{60 - depth}, {60 - 30 + 1e-9}], subtract: true}}}}\n" if relief else ""
    (d / "block.yaml").write_text(BLOCK.format(bottom=60 - (30 if relief else depth), depth=depth, relief=rel))
    return _problem(d / "cell.yaml", {"pin": ("pin.yaml", LYING.format(x=700)),
                                      "block": ("block.yaml", "[[1, 0, 0], [0, 1, 0], [0, 0, 1], [762, 150, 0]]")},
                    ["assembled(pin, block)"])


def _centres(plan: object) -> object:
    (v,) = [v for v in plan.verdicts if v.constraint == "centres"]  # type: ignore[attr-defined]
    return v


def test_a_shaft_seated_on_its_shoulder_is_not_misaligned_by_the_gap(tmp_path: Path) -> None:
    """The shaft seats on its shoulder 5 mm above the bore's bottom: the bound is the one of
    the same cell with the bore exactly as deep (it was larger by the whole gap); a relief at
    the bottom leaves a satisfied insertion satisfied."""
    planner = Planner()
    exact = _centres(planner.plan(_block_cell(tmp_path / "exact", 30)))
    deeper = _centres(planner.plan(_block_cell(tmp_path / "deeper", 35)))
    relief = _centres(planner.plan(_block_cell(tmp_path / "relief", 35, relief=True)))
    assert exact.satisfied and exact.tolerance_reached
    # the same expression (T_a, the seated tip and the errors alike): the same bound
    assert deeper.bound == pytest.approx(exact.bound, rel=1e-9)
    assert relief.satisfied and relief.bound == pytest.approx(exact.bound, rel=1e-9)
    # a 5 mm gap, had it counted, alone would exceed the threshold (0.5 mm squared)
    assert 5.0 ** 2 > exact.threshold


def _world(hole_pose: np.ndarray, bounds: Bounds) -> WorldState:
    """The block at ``hole_pose`` and the peg on the table, both with ``bounds``."""
    reg = Registry()
    objs = {n: ObjectState(n, "table", T, table_error(reg, n, bounds))
            for n, T in (("block", hole_pose), ("peg", geometry.trans(0, 400, 20)))}
    return WorldState(reg, Bounds((-0.01, 0.01), (-0.01, 0.01), (-0.01, 0.01), (-0.001, 0.001)), objs)


def _sampled_max(expr: ca.SX, reg: Registry, n: int = 20000, seed: int = 1) -> float:
    B = Bounder(expr)
    box = reg.box(expr)
    lo = np.array([box[k][0] for k in B.names])
    hi = np.array([box[k][1] for k in B.names])
    rng = np.random.default_rng(seed)
    P = np.vstack([rng.uniform(lo, hi, (n, lo.size)), np.where(rng.random((4000, lo.size)) < 0.5, lo, hi)])
    return float(B.values(P).max())


@pytest.mark.parametrize("yaw_deg, tilt", [(0.0, False), (30.0, False), (0.0, True), (30.0, True)])
def test_the_insertion_check_is_sound_and_tight(yaw_deg: float, tilt: bool) -> None:
    """SUP of the new expression covers every sampled value (sound) and is within 1 % of the
    sampled maximum (tight), for a vertical and a horizontal hole, square or turned on the table."""
    from spar_py.world.parts.mesh import FeatureGeometry, assembly_transforms

    axis = np.array([1.0, 0.0, 0.0]) if tilt else np.array([0.0, 0.0, -1.0])
    origin = np.array([-40.0, 0, 45]) if tilt else np.array([0.0, 0, 60])
    hg = FeatureGeometry("hole", "bore", 8.5, origin, axis, 35.0)
    pg = FeatureGeometry("peg", "shaft", 8.0, np.array([0.0, 0, 40]), np.array([0.0, 0, 1]), 30.0)
    hole = MatingFeature("hole", ("bore",), 8.5, hg.end, hg)
    peg = MatingFeature("peg", ("shaft",), 8.0, pg.end, pg)
    Ta = assembly_transforms(pg, hg)[0][0]
    w = _world(geometry.trans(700, 100, 0) @ geometry.rotz(yaw_deg * DEG),
               Bounds((-0.1, 0.1), (-0.1, 0.1), (-0.1, 0.1), (-0.2 * DEG, 0.2 * DEG)))
    w = pickup(w, "peg", geometry.trans(0, 0, 20) @ geometry.rotx(math.pi / 2), w.manipulator_error())
    (c,) = assemble_constraints(w, "peg", "block", Ta, peg, hole)
    v = evaluate(c, w.registry)
    smax = _sampled_max(c.expr, w.registry)
    assert smax <= v.bound
    assert v.bound - smax <= 0.01 * smax
    if not tilt:  # the block's dz moves the seated point along the bore's axis only: no misalignment
        syms = ca.symvar(c.expr)
        names = [s.name() for s in syms]
        if "dz_block" in names:  # present (not folded away): its value must not matter
            f = ca.Function("f", [ca.vertcat(*syms)], [c.expr])
            rng = np.random.default_rng(3)
            for _ in range(20):
                x = np.array([rng.uniform(*w.registry.bounds(n)) for n in names])
                y = x.copy()
                y[names.index("dz_block")] *= -1
                assert float(f(x)) == pytest.approx(float(f(y)), rel=1e-12, abs=1e-15)


# ---------------------------------------------------------------------- a mate with a given T_a


def test_a_mate_with_a_given_transform(plate_dir: Path) -> None:
    """kb.problem.mate_goal (a product's poses give T_a): the goal names the features' faces,
    T_a and V_a are added as trans_K, vec_K; a through bore may be entered from either mouth
    (V_a is then the way in), a blind one only from its mouth, and the peg's axis must lie
    along the hole's."""
    from spar_py.kb.node import Node
    from spar_py.kb.problem import mate_goal

    cell = load_problem(_two_pins(plate_dir, ["mated(pin_a, shaft, plate, bore_a)"], "mate_goal.yaml"))
    objs = cell.objects
    node = Node("product.yaml", "mates[0]", {})
    peg, bore_a = ("pin_a", objs["pin_a"].feature_named("shaft")), ("plate", objs["plate"].feature_named("bore_a"))
    transforms, vectors = dict(cell.transforms), dict(cell.vectors)
    # from the top: shaft down, its tip (0, 0, 70) at (-40, 0, 20) on bore_a's axis
    top = geometry.trans(-40, 0, 90) @ geometry.rotx(math.pi)
    goal = mate_goal(node, "pin_a.shaft into plate.bore_a", objs, peg, bore_a, top, transforms, vectors)
    assert goal[:4] == ("assembled", "pin_a", "plate", [["shaft"], ["bore_a"]])
    np.testing.assert_allclose(transforms[goal[4]], top)
    np.testing.assert_allclose(vectors[goal[5]], [0, 0, -1], atol=1e-12)
    # from below, through the other mouth: shaft up, the way in is +z
    below = geometry.trans(-40, 0, -30)
    goal = mate_goal(node, "from below", objs, peg, bore_a, below, transforms, vectors)
    np.testing.assert_allclose(vectors[goal[5]], [0, 0, 1], atol=1e-12)
    assert len({goal[4], "trans_1"}) == 2 and goal[4] in transforms
    # tilted by 1 deg about the tip (which stays on the axis): not along the axis
    tilted = top @ geometry.trans(0, 0, 70) @ geometry.roty(1 * DEG) @ geometry.trans(0, 0, -70)
    with pytest.raises(KBError, match=r"mates\[0\]: expected T_a pointing pin_a.shaft into plate.bore_a along its "
                                      r"axis in tilted, not 1 deg from the way in"):
        mate_goal(node, "tilted", objs, peg, bore_a, tilted, transforms, vectors)
    # a blind bore entered from its closed end
    blind = load_problem(_block_cell(plate_dir / "blind", 30))
    with pytest.raises(KBError, match=r"expected T_a pointing pin.shaft into block.bore along its axis in upwards, "
                                      r"not 180 deg from the way in"):
        mate_goal(node, "upwards", blind.objects, ("pin", blind.objects["pin"].features[0]),
                  ("block", blind.objects["block"].features[0]), geometry.trans(0, 0, -40), {}, {})


def test_the_close_up_shows_each_pins_own_bore(plate_dir: Path) -> None:
    """pictures.cell: the plate has two mouths (both painted), and each assemble's close-up is
    at its own bore's mouth (world point from the plate's pose and the file's numbers)."""
    from spar_py.pictures.cell import assemble_tolerance, hole_mouth, hole_mouths
    from spar_py.pictures.scene import scenes

    path = _two_pins(plate_dir, ["mated(pin_a, shaft, plate, bore_a)", "mated(pin_b, shaft, plate, bore_b)"],
                     "closeup.yaml")
    cell = load_problem(path)
    assert sorted(float(c[0]) for c, _, _ in hole_mouths(cell, "plate")) == [-40.0, 40.0]
    assert hole_mouth(cell, "plate") is None  # two holes: name one
    plan = Planner().plan(cell)
    assert plan.ok
    sc = scenes(cell, plan)
    seen = set()
    for k, step in enumerate(plan.steps, start=1):
        if step.name != "assemble":
            continue
        tol = assemble_tolerance(cell, plan, sc[k])
        bore = step.args[2][1][0]
        T = np.array(sc[k].poses["plate"])
        want = T[:3, :3] @ np.array([BORES[bore], 0.0, 60.0]) + T[:3, 3]
        assert tol is not None and np.allclose(tol.centre, want, atol=1e-9) and tol.satisfied
        seen.add(bore)
    assert seen == {"bore_a", "bore_b"}
