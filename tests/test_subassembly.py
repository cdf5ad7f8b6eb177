"""Subassemblies (issue 33, item 4): mated parts move as one body, loose mates stay only while
their way in points down, put-down bodies rest stably, and each step names what it moves.

The independent checks read the product and model YAML files themselves (test_products' own
geometry: poses as trans(xyz) Rz Ry Rx, the primitives, the mesh parts' STL through trimesh) and
the plan JSON's per-step poses; they never ask spar_py's geometry. After every step of every
product cell: each mated part sits at its parent's pose times its product pose relative to it
(1e-6 of the cell's size), each loose mate's way in is within 30 deg of world down, and each body
that is not held rests: its lowest point on the table or on a part's top, its centre of mass (all
its parts, uniform density) over the hull of its lowest points.
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
import yaml
from test_products import PROBLEMS, PRODUCTS, Shape, _apply, _pose

from spar_py.kb import load_problem
from spar_py.phase2.instance import sample_check
from spar_py.planning.planner import Planner
from spar_py.world.collision import CellCache

CELLS = ("plate_pins", "bracket_kit", "shaft_stack", "board20", "turn_over")
#: A part's lowest point this near a surface rests on it (mm; the cells are in mm).
REST_TOL = 0.5


# --------------------------------------------------------------------------- own geometry


def _product(name: str) -> dict:
    """The product file as plain data: parts' poses, models (with their directory), mates."""
    doc = yaml.safe_load((PRODUCTS / f"{name}.yaml").read_text())
    parts = {}
    for part, spec in doc["parts"].items():
        mpath = (PRODUCTS / spec["model"]).resolve()
        parts[part] = {"pose": _pose(spec.get("pose")), "model": {**yaml.safe_load(mpath.read_text()),
                                                                  "_dir": mpath.parent}}
    return {"parts": parts, "mates": [m for m in doc["mates"] if "peg" in m],
            "seats": [m for m in doc["mates"] if "seat" in m]}


def _features(model: dict) -> dict[str, dict]:
    feats = model.get("features") or ([model["feature"]] if "feature" in model else [])
    return {f["name"]: f for f in feats}


class Part:
    """A part's points (object frame) and volume-weighted centre, from its own file: a mesh's
    vertices and trimesh's centre, else the primitives' corners and rims and their centres less
    the subtracted ones'."""

    def __init__(self, model: dict) -> None:
        shape = Shape(model)
        if shape.mesh is not None:
            self.points = np.asarray(shape.mesh.vertices, float)
            self.volume = float(shape.mesh.volume)
            self.centre = np.asarray(shape.mesh.center_mass, float)
            return
        pts, vols, cents = [], [], []
        a = np.linspace(0, 2 * math.pi, 64, endpoint=False)
        for kind, lo, hi, r, sub in shape.prims:
            if kind == "box":
                v = float(np.prod(hi - lo))
                c = (lo + hi) / 2
                corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
            else:
                v = math.pi * r * r * (hi[2] - lo[2])
                c = np.array([0.0, 0.0, (lo[2] + hi[2]) / 2])
                ring = np.column_stack([r * np.cos(a), r * np.sin(a)])
                corners = np.vstack([np.column_stack([ring, np.full(len(a), z)]) for z in (lo[2], hi[2])])
            vols.append(-v if sub else v)
            cents.append(c)
            if not sub:
                pts.append(corners)
        self.points = np.vstack(pts)
        self.volume = float(sum(vols))
        self.centre = np.sum([v * c for v, c in zip(vols, cents)], axis=0) / self.volume


def _hull(P: np.ndarray) -> np.ndarray:
    """CCW convex hull of 2-D points (monotone chain)."""
    pts = sorted({(round(float(x), 9), round(float(y), 9)) for x, y in P})
    if len(pts) < 3:
        return np.array(pts)

    def half(seq: list) -> list:
        out: list = []
        for p in seq:
            while len(out) >= 2 and ((out[-1][0] - out[-2][0]) * (p[1] - out[-2][1])
                                     - (out[-1][1] - out[-2][1]) * (p[0] - out[-2][0])) <= 0:
                out.pop()
            out.append(p)
        return out

    return np.array(half(pts)[:-1] + half(pts[::-1])[:-1])


def _inside(poly: np.ndarray, p: np.ndarray) -> float:
    """How far p lies inside the CCW polygon (negative outside; a segment or point: -distance)."""
    if len(poly) < 3:
        a, b = poly[0], poly[-1]
        e = b - a
        u = float(np.clip((p - a) @ e / (e @ e), 0, 1)) if e @ e > 0 else 0.0
        return -float(np.linalg.norm(p - a - u * e))
    E = np.roll(poly, -1, axis=0) - poly
    D = p - poly
    return float(((E[:, 0] * D[:, 1] - E[:, 1] * D[:, 0]) / np.linalg.norm(E, axis=1)).min())


def _tree(steps: list[dict]) -> list[dict[str, str]]:
    """After each step, the mates made so far: child -> parent (the assembles' arguments)."""
    out, cur = [], {}
    for s in steps:
        if s["name"] == "assemble":
            cur = {**cur, s["args"][0]: s["args"][1]}
        out.append(dict(cur))
    return out


def _root(tree: dict[str, str], p: str) -> str:
    while p in tree:
        p = tree[p]
    return p


def _way_in(prod: dict, child: str, parent: str) -> np.ndarray | None:
    """The child's insertion direction in the parent's frame, from the model files: a peg into a
    hole moves along the hole's axis direction (into the part), a hole slid onto a peg against the
    peg's (its direction points to the tip). None for a seat."""
    for m in prod["mates"]:
        (pp, pf), (hp, hf) = m["peg"].split("."), m["hole"].split(".")
        if (pp, hp) == (child, parent):
            return np.asarray(_features(prod["parts"][hp]["model"])[hf]["axis"]["direction"], float)
        if (pp, hp) == (parent, child):
            return -np.asarray(_features(prod["parts"][pp]["model"])[pf]["axis"]["direction"], float)
    return None


def _retention(prod: dict, child: str) -> str:
    ms = [m for m in prod["mates"] if child in (m["peg"].split(".")[0], m["hole"].split(".")[0])]
    return "fixed" if any(m.get("retention") == "fixed" for m in ms if m["peg"].startswith(child + ".")) else "loose"


def _check_state(name: str, prod: dict, parts: dict[str, Part], step: dict, tree: dict[str, str]) -> list[str]:
    """What is wrong in the world after ``step`` (the module doc's checks), as messages."""
    bad = []
    poses = {k: np.asarray(v, float) for k, v in step["poses"].items()}
    rel = {c: np.linalg.inv(prod["parts"][p]["pose"]) @ prod["parts"][c]["pose"] for c, p in tree.items()}
    for c, p in tree.items():
        if not np.allclose(poses[c], poses[p] @ rel[c], atol=1e-6 * 200):
            bad.append(f"{c} is not at {p}'s pose times its product pose relative to it")
        way = _way_in(prod, c, p)
        if way is not None and _retention(prod, c) == "loose":
            d = poses[p][:3, :3] @ way
            angle = math.degrees(math.acos(np.clip(-d[2] / np.linalg.norm(d), -1, 1)))
            if angle > 30 + 1e-6:
                bad.append(f"{c} (loose in {p}) is {angle:.0f} deg from down")
    held = step.get("held")
    held_body = {k for k in poses if held is not None and _root(tree, k) == held}
    roots = [k for k in poses if k not in tree and k not in held_body]
    for r in roots:
        body = [k for k in poses if _root(tree, k) == r]
        P = np.vstack([_apply(poses[k], parts[k].points) for k in body])
        low = P[:, 2].min()
        own_low = _apply(poses[r], parts[r].points)[:, 2].min()
        if own_low > low + REST_TOL:
            bad.append(f"{r}'s body rests on a carried part below it")
        # on the table, or on the top of another body's part under it
        tops = [0.0] + [float(_apply(poses[k], parts[k].points)[:, 2].max()) for k in poses
                        if k not in body and k not in held_body]
        if not any(abs(low - t) <= REST_TOL for t in tops):
            bad.append(f"{r} is not on a surface: its lowest point is at z = {low:.3f}")
        foot = _hull(P[P[:, 2] <= low + REST_TOL][:, :2])
        vols = np.array([parts[k].volume for k in body])
        com = np.sum([v * _apply(poses[k], parts[k].centre[None])[0] for v, k in zip(vols, body)], axis=0) / vols.sum()
        if _inside(foot, com[:2]) < -1e-6:
            bad.append(f"{r}'s body tips over: its centre of mass is outside its contact face")
    return bad


@pytest.fixture(scope="module")
def plans() -> dict[str, dict]:
    """Each product cell's plan JSON (both phases)."""
    planner = Planner()
    out = {}
    for name in CELLS:
        plan = planner.plan(PROBLEMS / f"{name}.yaml")
        assert plan.ok, (name, plan.reason)
        out[name] = plan.to_json()
    return out


# --------------------------------------------------------------------------- every product cell


@pytest.mark.parametrize("name", CELLS)
def test_every_state_is_supported_stable_and_retained(plans: dict[str, dict], name: str) -> None:
    prod = _product(name)
    parts = {k: Part(v["model"]) for k, v in prod["parts"].items()}
    steps = plans[name]["instance"]["steps"]
    for step, tree in zip(steps, _tree(steps)):
        assert _check_state(name, prod, parts, step, tree) == [], step["term"]


@pytest.mark.parametrize("name", CELLS)
def test_each_step_names_the_body_it_moves(plans: dict[str, dict], name: str) -> None:
    steps = plans[name]["instance"]["steps"]
    for step, tree in zip(steps, [{}] + _tree(steps)[:-1]):  # the mates made before the step
        if step["name"] in ("pickup", "putdown", "assemble"):
            obj = step["args"][0]
            assert sorted(step["moves"]) == sorted(k for k in step["poses"] if _root(tree, k) == obj), step["term"]
            assert step["moves"][0] == obj


@pytest.mark.parametrize("name", CELLS)
def test_verdicts_sound_under_monte_carlo(plans: dict[str, dict], name: str) -> None:
    cache = CellCache(load_problem(PROBLEMS / f"{name}.yaml"))
    got = sample_check(cache, plans[name]["instance"]["steps"], draws=2000)
    assert got
    assert all(r["failed_draws"] == 0 for r in got if r["declared_satisfied"]), got


def test_state_check_sees_a_turned_loose_pin_and_a_floating_part(plans: dict[str, dict]) -> None:
    """The independent check can fail: pin_b turned head up with the block, a part lifted."""
    prod = _product("turn_over")
    parts = {k: Part(v["model"]) for k, v in prod["parts"].items()}
    last = plans["turn_over"]["instance"]["steps"][-1]
    tree = _tree(plans["turn_over"]["instance"]["steps"])[-1]
    assert _check_state("turn_over", prod, parts, last, tree) == []
    flip = np.diag([1.0, -1.0, -1.0, 1.0])
    turned = {k: (np.asarray(T) @ flip).tolist() for k, T in last["poses"].items()}
    assert any("from down" in m for m in _check_state("turn_over", prod, parts, {**last, "poses": turned}, tree))
    up = np.eye(4)
    up[2, 3] = 5.0
    lifted = {k: (up @ np.asarray(T)).tolist() for k, T in last["poses"].items()}
    assert any("not on a surface" in m for m in _check_state("turn_over", prod, parts, {**last, "poses": lifted},
                                                              tree))


# --------------------------------------------------------------------------- the turn_over cell


def test_turn_over_turns_the_block_with_pin_a_in_it(plans: dict[str, dict]) -> None:
    steps = plans["turn_over"]["instance"]["steps"]
    assert [(s["name"], s["args"][0]) for s in steps] == [
        ("pickup", "pin_a"), ("assemble", "pin_a"), ("pickup", "block"), ("putdown", "block"),
        ("pickup", "pin_b"), ("assemble", "pin_b")]
    prod = _product("turn_over")
    rel = np.linalg.inv(prod["parts"]["block"]["pose"]) @ prod["parts"]["pin_a"]["pose"]
    before, after = (np.asarray(steps[i]["poses"]["block"]) for i in (2, 3))
    assert before[2, 2] == pytest.approx(1.0) and after[2, 2] == pytest.approx(-1.0)  # turned over
    for s in steps[1:]:  # pin_a moves with the block once in it
        assert np.allclose(np.asarray(s["poses"]["pin_a"]), np.asarray(s["poses"]["block"]) @ rel, atol=1e-6)
    assert not np.allclose(np.asarray(steps[3]["poses"]["pin_a"]), np.asarray(steps[1]["poses"]["pin_a"]))
    assert steps[2]["moves"] == ["block", "pin_a"] and steps[3]["moves"] == ["block", "pin_a"]
    # pin_b goes in from above: its bore's axis points down in the world once the block is turned
    bore_b = np.asarray(_features(prod["parts"]["block"]["model"])["bore_b"]["axis"]["direction"], float)
    assert after[:3, :3] @ bore_b == pytest.approx([0, 0, -1], abs=1e-9)


def test_turn_over_printed_plan_names_the_subassembly(capsys: pytest.CaptureFixture) -> None:
    from spar_py.app.cli import main

    with pytest.raises(SystemExit) as done:
        main(["plan", str(PROBLEMS / "turn_over.yaml")])
    assert done.value.code == 0
    out = capsys.readouterr().out
    lines = [ln for ln in out.splitlines() if "moves block + pin_a" in ln]
    assert [ln.split(": ", 1)[1].split("(")[0] for ln in lines] == ["pickup", "putdown"]
    assert "pin_a" not in next(ln for ln in out.splitlines() if ": assemble(pin_b" in ln).split(")  ", 1)[-1]


def _loose_cell(tmp_path: Path) -> Path:
    """turn_over with pin_a loose too: turning the block over would turn one pin head down."""
    text = (PRODUCTS / "turn_over.yaml").read_text().replace("retention: fixed", "retention: loose")
    text = text.replace("../objects/", f"{(PRODUCTS / '../objects').resolve()}/")
    (tmp_path / "turn_over_loose.yaml").write_text(text)
    prob = (PROBLEMS / "turn_over.yaml").read_text()
    prob = prob.replace("../robots/", f"{(PROBLEMS / '../robots').resolve()}/")
    prob = prob.replace("product: ../products/turn_over.yaml", f"product: {tmp_path / 'turn_over_loose.yaml'}")
    (tmp_path / "turn_over_loose_cell.yaml").write_text(prob)
    return tmp_path / "turn_over_loose_cell.yaml"


def test_a_loose_pin_is_never_turned_over(tmp_path: Path) -> None:
    plan = Planner().plan(_loose_cell(tmp_path))
    assert not plan.ok
    why = plan.reason["infeasible"]
    assert any("pickup(block" not in w and "would turn pin_a (loose in block.bore_a) 180 deg from down" in w
               for w in why), why


# --------------------------------------------------------------------------- the parts of it


def _turn_over_world() -> tuple:
    """The turn_over cell's world after pin_a is pressed into the block (a fresh cell cache)."""
    from spar_py.phase2 import instance as phase2

    cell = load_problem(PROBLEMS / "turn_over.yaml")
    cache = CellCache(cell)
    steps = [{"id": "action_2", "name": "pickup", "args": ["pin_a", "pin_a_g23"]},
             {"id": "action_1", "name": "assemble",
              "args": ["pin_a", "block", [["shaft"], ["bore_a"]], "trans_pin_a", "vec_pin_a"]}]
    world = phase2.new_world(cache, steps)
    for s in steps:
        checks, world, _ = phase2.step(world, s)
        assert all(c["satisfied"] for c in checks), checks
    return cell, cache, world


def test_carried_hole_composes_its_pose_through_the_mate() -> None:
    """An insertion into a part mated into another is checked at the composed pose: the parent's
    error plus the mate's clearance (sound: no draw beats SUP)."""
    import casadi as ca

    from spar_py.phase2 import uncertainty as ur

    cell, _, world = _turn_over_world()
    unc = world.unc
    att = unc.attached["pin_a"]
    assert att.parent == "block" and att.retention == "fixed" and att.clearance == pytest.approx(0.5)
    bore = cell.objects["block"].feature_named("bore_b")
    held = ur.pickup(unc, "pin_b", cell.objects["pin_b"].grasps["pin_b_g23"].T, unc.manipulator_error())
    peg = cell.objects["pin_b"].feature_named("shaft")
    Ta = np.eye(4)
    Ta[2, 3] = -20.0
    into_block = ur.assemble_constraints(held, "pin_b", "block", Ta, peg, bore)[0]
    into_pin = ur.assemble_constraints(held, "pin_b", "pin_a", Ta, peg, bore)[0]
    reg = unc.registry
    b_block = ur.evaluate(into_block, reg).bound
    b_pin = ur.evaluate(into_pin, reg).bound
    assert b_pin > b_block  # the clearance adds to the block's own error
    names = sorted(reg.box(into_pin.expr))
    assert any(n.startswith("cx_pin_a") for n in names)
    f = ca.Function("f", [ca.vertcat(*[reg.symbol(n) for n in names])], [into_pin.expr])
    lo, hi = (np.array([reg.bounds(n)[i] for n in names]) for i in (0, 1))
    rng = np.random.default_rng(1)
    pts = np.vstack([rng.uniform(lo, hi, (3000, len(names))), lo, hi])
    vals = np.asarray(f.map(len(pts))(pts.T)).ravel()
    assert vals.max() <= b_pin


def test_a_grasp_whose_fingers_meet_a_carried_part_is_refused_naming_it() -> None:
    from spar_py.world.reach.workspace import arm_at

    cell, cache, world = _turn_over_world()
    parts = {k: o.pose for k, o in world.unc.objects.items()}
    g = cell.objects["pin_a"].grasps["pin_a_g23"]
    # the block "grasped" where pin_a's grasp holds pin_a's head: the fingers close on pin_a
    got = arm_at(cache, parts["pin_a"] @ g.T, None, parts=parts, grasped="block", width=g.width)
    assert got.q is None and any("pin_a" in p for p in got.collisions), got.collisions


def test_a_body_resting_on_a_carried_part_or_tipping_is_refused() -> None:
    from spar_py.world.reach.supports import rest_of_body, surfaces_of

    cell, _, world = _turn_over_world()
    T = np.eye(4)
    T[:2, 3] = [762, 203]
    pin = cell.objects["pin_a"]
    low = np.eye(4)
    low[:3, :3] = np.diag([1.0, -1.0, -1.0])
    low[:3, 3] = [762, 203, 10]  # a pin reaching 10 mm below the block's bottom face
    r = rest_of_body(cell, "block", T, surfaces_of(cell), [("pin_a", pin, low)])
    assert not r.ok and "pin_a" in r.why
    beside = T.copy()
    beside[0, 3] += 100  # a second block mated beside it, over nothing
    r = rest_of_body(cell, "block", T, surfaces_of(cell), [("other", cell.objects["block"], beside)])
    assert not r.ok and "tips over" in r.why
    r = rest_of_body(cell, "block", T, surfaces_of(cell), [("pin_a", pin, world.unc.obj("pin_a").pose)])
    assert r.ok


def test_a_part_resting_on_another_is_not_left_unsupported() -> None:
    from spar_py.phase2 import instance as phase2
    from spar_py.phase2 import uncertainty as ur

    cell, cache, world = _turn_over_world()
    on_top = np.eye(4)
    on_top[:3, 3] = [762 + 35, 203, 156]  # pin_b standing on its head's face on a rib's top
    unc = world.unc.with_object(ur.replace(world.unc.obj("pin_b"), pose=on_top))
    world = ur.replace(world, unc=unc, key=world.key + ("pin_b on the block",))
    s = {"id": "action_6", "name": "pickup", "args": ["block", "block_g1"]}
    checks, _, _ = phase2.step(world, s)
    assert any(not c["satisfied"] and "would leave pin_b unsupported" in c["description"] for c in checks), checks


def test_motions_and_animation_carry_the_subassembly() -> None:
    """With motions the turn_over plan exists (the carried pin_a checked along every path), and
    every animation frame while the block is held shows pin_a where the block carries it."""
    from spar_py.pictures.animate import frames_of

    plan = Planner(motion=True).plan(PROBLEMS / "turn_over.yaml")
    assert plan.ok, plan.reason
    prod = _product("turn_over")
    rel = np.linalg.inv(prod["parts"]["block"]["pose"]) @ prod["parts"]["pin_a"]["pose"]
    cell = load_problem(PROBLEMS / "turn_over.yaml")
    frames = frames_of(cell, plan, max_frames=400)
    carried = [f for f in frames if f.held == "block"]
    assert carried
    for f in carried:
        assert np.allclose(np.asarray(f.poses["pin_a"]), np.asarray(f.poses["block"]) @ rel, atol=1e-6), f.title
    # the 3-D viewer's motion segments carry pin_a the same way (poses flat, row by row, rounded)
    from spar_py.pictures.viewer import viewer_data

    segs = [g for st in viewer_data(cell, plan)["steps"] for g in st["motion"] if g["held"] == "block"]
    assert segs and all("pin_a" in g["carried"] for g in segs)
    for g in segs:
        for hp, cp in zip(g["held_pose"], g["carried"]["pin_a"]):
            assert np.allclose(np.reshape(cp, (4, 4)), np.reshape(hp, (4, 4)) @ rel, atol=1e-2)
