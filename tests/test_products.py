"""Products (issue 33, items 2-3): product files, the goals they compile to, precedence from the
parts' geometry, and the plans of the product cells, checked with this file's own geometry.

The independent checks read the YAML files themselves (poses as trans(xyz) Rz Ry Rx, the shapes'
primitives with their subtracted holes, the mesh parts' STL files through trimesh) and never ask
spar_py's geometry: every plan ends with each part at its product pose relative to the base part
(composed from the plan JSON's final poses), and no insertion's sweep, sampled along its way
down, passes through a part already in place.
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
import yaml

from spar_py.core.errors import KBError
from spar_py.kb import load_problem
from spar_py.kb.products import load_product
from spar_py.planning.planner import Planner

from paths import ROOT

PROBLEMS = ROOT / "kb" / "problems"
PRODUCTS = ROOT / "kb" / "products"
CELLS = ("plate_pins", "bracket_kit", "shaft_stack", "board20")


# --------------------------------------------------------------------------- own geometry


def _pose(node: dict | None) -> np.ndarray:
    """trans(xyz) @ Rz(yaw) @ Ry(pitch) @ Rx(roll), degrees (the product files' form)."""
    T = np.eye(4)
    if not node:
        return T
    r, p, y = (math.radians(a) for a in node.get("rpy", [0, 0, 0]))
    cx, sx, cy, sy, cz, sz = math.cos(r), math.sin(r), math.cos(p), math.sin(p), math.cos(y), math.sin(y)
    Rx = np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]])
    Ry = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
    Rz = np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]])
    T[:3, :3] = Rz @ Ry @ Rx
    T[:3, 3] = node["xyz"]
    return T


def _product(name: str) -> tuple[str, dict[str, np.ndarray], dict[str, dict]]:
    """A product file read as plain YAML: its base part, each part's pose and model file's data."""
    doc = yaml.safe_load((PRODUCTS / f"{name}.yaml").read_text())
    poses, models = {}, {}
    for part, spec in doc["parts"].items():
        poses[part] = _pose(spec.get("pose"))
        mpath = (PRODUCTS / spec["model"]).resolve()
        models[part] = {**yaml.safe_load(mpath.read_text()), "_dir": mpath.parent}
    return doc.get("base", next(iter(doc["parts"]))), poses, models


class Shape:
    """A part's solid for point tests, in its object frame: a mesh part's STL (trimesh), or the
    union of its box and z-cylinder primitives less the subtracted ones."""

    def __init__(self, model: dict) -> None:
        self.mesh = None
        self.prims: list[tuple[str, np.ndarray, np.ndarray, float, bool]] = []
        if "mesh" in model:
            import trimesh

            self.mesh = trimesh.load(str(model["_dir"] / model["mesh"]), force="mesh")
            self.lo, self.hi = self.mesh.bounds
            return
        for item in model["shape"]:
            if "box" in item:
                b = item["box"]
                self.prims.append(("box", np.array(b["min"], float), np.array(b["max"], float), 0.0,
                                   bool(b.get("subtract"))))
            else:
                c = item["cylinder"]
                r = float(c["radius"])
                self.prims.append(("cyl", np.array([-r, -r, c["z"][0]], float), np.array([r, r, c["z"][1]], float),
                                   r, bool(c.get("subtract"))))
        solid = [p for p in self.prims if not p[4]]
        self.lo = np.min([p[1] for p in solid], axis=0)
        self.hi = np.max([p[2] for p in solid], axis=0)

    def depth(self, P: np.ndarray) -> np.ndarray:
        """How far each point (k, 3) lies inside the solid (negative: outside), primitives only."""
        def inside(kind: str, lo: np.ndarray, hi: np.ndarray, r: float) -> np.ndarray:
            dz = np.minimum(P[:, 2] - lo[2], hi[2] - P[:, 2])
            if kind == "box":
                return np.minimum(dz, np.minimum(P[:, :2] - lo[:2], hi[:2] - P[:, :2]).min(1))
            return np.minimum(dz, r - np.hypot(P[:, 0], P[:, 1]))
        d = np.full(len(P), -np.inf)
        for kind, lo, hi, r, sub in self.prims:
            if not sub:
                d = np.maximum(d, inside(kind, lo, hi, r))
        for kind, lo, hi, r, sub in self.prims:
            if sub:
                d = np.minimum(d, -inside(kind, lo, hi, r))
        return d

    def contains(self, P: np.ndarray, depth: float) -> np.ndarray:
        """Which points (k, 3) lie more than ``depth`` inside the solid (a mesh: inside at all)."""
        if self.mesh is not None:
            return self.mesh.contains(P)
        return self.depth(P) > depth

    def interior(self, step: float, depth: float) -> np.ndarray:
        """Grid points ``step`` apart lying more than ``depth`` inside the solid."""
        axes = [np.arange(a + step / 2, b, step) for a, b in zip(self.lo, self.hi)]
        G = np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, 3)
        if self.mesh is None:
            return G[self.depth(G) > depth]
        import trimesh

        inside = G[self.mesh.contains(G)]
        return inside[-trimesh.proximity.signed_distance(self.mesh, inside) < -depth] if len(inside) else inside


def _apply(T: np.ndarray, P: np.ndarray) -> np.ndarray:
    return P @ T[:3, :3].T + T[:3, 3]


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


# --------------------------------------------------------------------------- plans


@pytest.mark.parametrize("name", CELLS)
def test_plan_ends_at_product_poses(plans: dict[str, dict], name: str) -> None:
    """The last step leaves every part at its product pose relative to the base part, within
    1e-6 of the cell's size (the product's extent)."""
    base, poses, _ = _product(name)
    final = {k: np.array(v, float) for k, v in plans[name]["instance"]["steps"][-1]["poses"].items()}
    size = max(float(np.abs(T[:3, 3]).max()) for T in final.values())
    tol = 1e-6 * size
    Tb = final[base]
    for part, T in poses.items():
        want = np.linalg.inv(poses[base]) @ T
        got = np.linalg.inv(Tb) @ final[part]
        assert np.abs(got - want).max() < tol, (name, part, got.round(6), want)


@pytest.mark.parametrize("name", CELLS)
def test_no_insertion_sweeps_through_a_placed_part(plans: dict[str, dict], name: str) -> None:
    """Each part inserted, sampled inside (0.2 mm in from its surface on a 1.5 mm grid) and moved
    back up along the base's z (every insertion of these cells goes straight down) in steps of
    0.25 mm, from its seated pose until it is clear, never enters a part already in place (the
    base and the parts assembled before it), whose holes are cut."""
    base, _, models = _product(name)
    shapes = {p: Shape(m) for p, m in models.items()}
    placed = {base}
    for st in plans[name]["instance"]["steps"]:
        if st["name"] != "assemble":
            continue
        part = st["args"][0]
        world = {k: np.array(v, float) for k, v in st["poses"].items()}
        assert _sweep_hits(shapes, world, part, placed, world[base][:3, 2]) == [], (name, part)
        placed.add(part)


def _sweep_hits(shapes: dict[str, Shape], world: dict[str, np.ndarray], part: str, placed: set[str],
                up: np.ndarray) -> list[str]:
    """The parts of ``placed`` that ``part`` (at its pose in ``world``) enters when moved back
    along ``up`` from there until clear (0.25 mm steps, 150 mm)."""
    pts = _apply(world[part], shapes[part].interior(1.5, 0.2))
    hits = []
    for other in sorted(placed):
        Ti = np.linalg.inv(world[other])
        lo, hi = shapes[other].lo - 1, shapes[other].hi + 1
        for t in np.arange(0.0, 150.0, 0.25):
            local = _apply(Ti, pts + t * up)
            near = ((local > lo) & (local < hi)).all(1)
            if near.any() and shapes[other].contains(local[near], 0.0).any():
                hits.append(other)
                break
    return hits


def test_sweep_check_sees_a_blocked_insertion() -> None:
    """The check above can fail: with the pins in place first (product poses), the bracket's
    way down passes through their heads, and a pin's own way down passes through nothing."""
    base, poses, models = _product("bracket_kit")
    shapes = {p: Shape(m) for p, m in models.items()}
    assert _sweep_hits(shapes, poses, "bracket", {base, "pin_a", "pin_b"}, np.array([0.0, 0, 1])) == [
        "pin_a", "pin_b"]
    assert _sweep_hits(shapes, poses, "pin_a", {base, "bracket", "pin_b"}, np.array([0.0, 0, 1])) == []


def test_precedence_is_an_ordering_of_the_plan(plans: dict[str, dict]) -> None:
    """The geometry's orderings are in the partial plan and its steps keep them: the bracket's
    assemble before each pin's, the bushing's before the collar's, with the printed reasons."""
    for name, first, thens in (("bracket_kit", "bracket", ("pin_a", "pin_b")), ("shaft_stack", "bushing", ("collar",))):
        doc = plans[name]
        ids = {a["args"][0]: a["id"] for a in doc["partial"]["actions"] if a["name"] == "assemble"}
        prec = {(p["before"], p["after"]): p["reason"] for p in doc["partial"]["precedence"]}
        order = [s["id"] for s in doc["instance"]["steps"]]
        for then in thens:
            assert [ids[first], ids[then]] in doc["partial"]["ordering"]
            assert prec[(ids[first], ids[then])].startswith(f"{first} before {then} ({first}'s insertion")
            assert order.index(ids[first]) < order.index(ids[then])
    assert plans["plate_pins"]["partial"]["precedence"] == []


def test_the_plan_names_the_mates_each_assemble_makes(plans: dict[str, dict]) -> None:
    """A pin through the bracket into the base makes both its mates with one assemble."""
    steps = {s["args"][0]: s for s in plans["bracket_kit"]["instance"]["steps"] if s["name"] == "assemble"}
    assert steps["pin_a"]["mates"] == ["pin_a.shaft->bracket.bore_a", "pin_a.shaft->base.bore_a"]
    assert steps["bracket"]["mates"] == ["bracket.bottom->base.top"]


def test_printed_plan_gives_the_reason() -> None:
    """The text plan prints each ordering the geometry forced with its reason, and the mates."""
    plan = Planner().plan(PROBLEMS / "shaft_stack.yaml", trace=False)
    text = plan.trace or ""
    if not text:  # the text plan comes with the trace option's printing
        plan = Planner().plan(PROBLEMS / "shaft_stack.yaml", trace=True)
        text = plan.trace
    assert "bushing before collar (bushing's insertion would pass through collar" in text
    assert "makes shaft.shaft->bushing.bore" in text


# --------------------------------------------------------------------------- compiled goals


def test_goals_compile_from_product_poses() -> None:
    """Each goal's T_a is T_parent^-1 T_part of the product (own poses) and V_a points down in
    the parent's frame; assembled(KIT) asks for every part's goal."""
    cell = load_problem(PROBLEMS / "bracket_kit.yaml")
    base, poses, _ = _product("bracket_kit")
    goals = {g[1]: g for g in cell.goals}
    assert set(goals) == {"bracket", "pin_a", "pin_b"}
    for part, g in goals.items():
        parent = g[2]
        np.testing.assert_allclose(cell.transforms[g[4]], np.linalg.inv(poses[parent]) @ poses[part], atol=1e-9)
        np.testing.assert_allclose(cell.vectors[g[5]], [0, 0, -1], atol=1e-12)
    assert goals["pin_a"][3] == [["shaft"], ["bore_a"]] and goals["pin_a"][4] == "trans_pin_a"


def _write_product(tmp_path: Path, text: str) -> Path:
    p = tmp_path / "product.yaml"
    p.write_text(text.replace("OBJ/", str(ROOT / "kb" / "objects") + "/"))
    return p


def _one_line(e: pytest.ExceptionInfo) -> str:
    msg = str(e.value)
    assert "\n" not in msg
    return msg


def test_misaligned_mate_refused(tmp_path: Path) -> None:
    p = _write_product(tmp_path, """product: bad
units: {length: mm, angle: deg}
parts:
  plate: {model: OBJ/plate2.yaml}
  pin_a: {model: OBJ/pin8.yaml, pose: {xyz: [-29, 0, 26], rpy: [180, 0, 0]}}
mates:
  - {peg: pin_a.shaft, hole: plate.bore_a}
""")
    with pytest.raises(KBError) as e:
        load_product(p, "mm")
    msg = _one_line(e)
    assert "mates[0]" in msg and "pin_a.shaft and plate.bore_a" in msg and "axes 1 mm apart" in msg


def test_wide_peg_refused(tmp_path: Path) -> None:
    (tmp_path / "fat_pin.yaml").write_text("""object: fat_pin
units: {length: mm, angle: deg}
shape:
  - {cylinder: {radius: 8, z: [0, 20]}}
  - {cylinder: {radius: 5.6, z: [20, 28]}}
features:
  - {kind: peg, name: shaft, radius: 5.6, axis: {origin: [0, 0, 20], direction: [0, 0, 1]}, length: 8}
""")
    p = _write_product(tmp_path, f"""product: bad
units: {{length: mm, angle: deg}}
parts:
  plate: {{model: OBJ/plate2.yaml}}
  pin_a: {{model: {tmp_path}/fat_pin.yaml, pose: {{xyz: [-30, 0, 34], rpy: [180, 0, 0]}}}}
mates:
  - {{peg: pin_a.shaft, hole: plate.bore_a}}
""")
    with pytest.raises(KBError) as e:
        load_product(p, "mm")
    msg = _one_line(e)
    assert "pin_a.shaft radius 5.6 mm" in msg and "plate.bore_a radius 5.5 mm" in msg


def test_precedence_cycle_refused(tmp_path: Path) -> None:
    """A bushing and a collar that overlap at their product poses block each other both ways."""
    p = _write_product(tmp_path, """product: bad
units: {length: mm, angle: deg}
parts:
  shaft: {model: OBJ/stepped_shaft.yaml}
  bushing: {model: OBJ/bushing.yaml, pose: {xyz: [0, 0, 10]}}
  collar: {model: OBJ/collar.yaml, pose: {xyz: [0, 0, 30]}}
mates:
  - {peg: shaft.shaft, hole: bushing.bore}
  - {peg: shaft.shaft, hole: collar.bore}
""")
    with pytest.raises(KBError) as e:
        load_product(p, "mm")
    msg = _one_line(e)
    assert "cycle" in msg and "bushing" in msg and "collar" in msg


def test_unknown_feature_refused(tmp_path: Path) -> None:
    p = _write_product(tmp_path, """product: bad
units: {length: mm, angle: deg}
parts:
  plate: {model: OBJ/plate2.yaml}
  pin_a: {model: OBJ/pin8.yaml, pose: {xyz: [-30, 0, 26], rpy: [180, 0, 0]}}
mates:
  - {peg: pin_a.shaft, hole: plate.bore_c}
""")
    with pytest.raises(KBError) as e:
        load_product(p, "mm")
    msg = _one_line(e)
    assert "mates[0].hole" in msg and "bore_a" in msg and "bore_c" in msg


def test_mated_goal_is_the_goal_of_the_insertion_that_makes_it(tmp_path: Path) -> None:
    """mated(pin_a, shaft, bracket, bore_a) in the bracket kit: pin_a goes into the base, not the
    bracket, so the mate holds once both are in place: the bracket's goal and pin_a's (whichever
    insertion comes later makes it); an unknown mate is refused naming the known ones."""
    text = (PROBLEMS / "bracket_kit.yaml").read_text().replace("../", f"{ROOT}/kb/")
    p = tmp_path / "kit.yaml"
    p.write_text(text.replace("assembled(bracket_kit)", "mated(pin_a, shaft, bracket, bore_a)"))
    cell = load_problem(p)
    assert cell.goals == [("assembled", "bracket", "base", [["bottom"], ["top"]], "trans_bracket", "vec_bracket"),
                          ("assembled", "pin_a", "base", [["shaft"], ["bore_a"]], "trans_pin_a", "vec_pin_a")]
    p.write_text(text.replace("assembled(bracket_kit)", "mated(pin_a, shaft, bracket, bore_b)"))
    with pytest.raises(KBError) as e:
        load_problem(p)
    msg = _one_line(e)
    assert "goals[0]" in msg and "pin_a.shaft->bracket.bore_b" in msg and "pin_b.shaft->base.bore_b" in msg


def _mesh_model(tmp_path: Path, name: str, mesh, features: list[dict]) -> None:
    """A mesh model (STL written by trimesh) with the given features; poses and grasps derived."""
    mesh.export(tmp_path / f"{name}.stl")
    (tmp_path / f"{name}.yaml").write_text(yaml.safe_dump({
        "object": name, "units": {"length": "mm", "angle": "deg"}, "mesh": f"{name}.stl", "features": features}))


def test_mesh_parts_sweep_their_own_bores(tmp_path: Path) -> None:
    """shaft_stack with every part a mesh export (the bushing and collar bored): the meshes' own
    bores let the sleeves pass down the shaft (their convex hulls would fill them, and the
    bushing's way would pass through the base part: refused), and the collar in place blocks
    the bushing's way, so the bushing comes first, as with the declared primitives."""
    import trimesh

    def tube(r_out: float, r_in: float, z0: float, z1: float, blind_to: float | None = None):
        outer = trimesh.creation.cylinder(radius=r_out, segment=[[0, 0, z0], [0, 0, z1]], sections=48)
        bore = trimesh.creation.cylinder(radius=r_in, segment=[[0, 0, z0 - 1], [0, 0, blind_to or z1 + 1]],
                                         sections=48)
        return outer.difference(bore)

    shaft = trimesh.boolean.union([
        trimesh.creation.cylinder(radius=20, segment=[[0, 0, 0], [0, 0, 10]], sections=48),
        trimesh.creation.cylinder(radius=6, segment=[[0, 0, 9.9], [0, 0, 62]], sections=48)])
    _mesh_model(tmp_path, "m_shaft", shaft, [{"kind": "peg", "name": "shaft", "radius": 6, "length": 52,
                                              "axis": {"origin": [0, 0, 10], "direction": [0, 0, 1]}}])
    _mesh_model(tmp_path, "m_bushing", tube(12, 6.5, 0, 36), [
        {"kind": "hole", "name": "bore", "radius": 6.5, "length": 36, "through": True,
         "axis": {"origin": [0, 0, 0], "direction": [0, 0, 1]}}])
    _mesh_model(tmp_path, "m_collar", tube(10, 6.5, 0, 24, blind_to=16), [
        {"kind": "hole", "name": "bore", "radius": 6.5, "length": 16,
         "axis": {"origin": [0, 0, 0], "direction": [0, 0, 1]}}])
    p = tmp_path / "stack.yaml"
    p.write_text("""product: mesh_stack
units: {length: mm, angle: deg}
parts:
  shaft: {model: m_shaft.yaml}
  bushing: {model: m_bushing.yaml, pose: {xyz: [0, 0, 10]}}
  collar: {model: m_collar.yaml, pose: {xyz: [0, 0, 46]}}
mates:
  - {peg: shaft.shaft, hole: bushing.bore}
  - {peg: shaft.shaft, hole: collar.bore}
""")
    product = load_product(p, "mm")
    pairs = {(pr.first, pr.then) for pr in product.precedence}
    assert pairs == {("bushing", "collar")}
    assert not any(pr.first == "collar" for pr in product.precedence)  # nothing blocks the collar's way
