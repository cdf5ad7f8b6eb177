"""Issue 33 item 4: a subassembly is grasped on any of its parts. Each product part gets the
grasps of the parts that can be mated into it, in its own frame (world.product.products.via_grasps),
usable only while that part is carried.

Own geometry: the product poses from the product file's numbers (xyz, rpy in degrees), the
fingers' contact points from the grasp's tool frame (tool y across the fingers, W_g apart),
checked against the pin's own cylinders read from its object file."""
from __future__ import annotations

import math

import numpy as np
import pytest
import yaml

from spar_py.core.geometry import eulerxyz
from spar_py.kb import load_problem
from spar_py.phase2 import instance as phase2
from spar_py.world.collision import CellCache

from paths import ROOT

#: Lengths' tolerance (mm).
TOL = 1e-6


def _pose(xyz, rpy_deg) -> np.ndarray:
    """T = trans(xyz) rotz(y) roty(p) rotx(r), written out here."""
    r, p, y = np.radians(rpy_deg)
    cx, sx, cy, sy, cz, sz = math.cos(r), math.sin(r), math.cos(p), math.sin(p), math.cos(y), math.sin(y)
    Rx = np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]])
    Ry = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
    Rz = np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]])
    T = np.eye(4)
    T[:3, :3] = Rz @ Ry @ Rx
    T[:3, 3] = xyz
    return T


def _on_pin(p: np.ndarray, cyls: list[dict]) -> float:
    """Distance (mm) of point p (pin frame) from the surface of the union of the pin's z-cylinders."""
    best = math.inf
    for c in cyls:
        r, (z0, z1) = c["radius"], c["z"]
        rho = math.hypot(p[0], p[1])
        dr, dz = rho - r, max(z0 - p[2], p[2] - z1, 0.0)
        if z0 <= p[2] <= z1:
            best = min(best, abs(dr))
        else:
            best = min(best, math.hypot(max(dr, 0.0), dz))
    return best


def test_block_gets_the_pins_grasps_in_its_frame() -> None:
    cell = load_problem(ROOT / "kb/problems/turn_over.yaml")
    prod = yaml.safe_load((ROOT / "kb/products/turn_over.yaml").read_text())
    cyls = [s["cylinder"] for s in yaml.safe_load((ROOT / "kb/objects/pin8.yaml").read_text())["shape"]]
    block = cell.objects["block"]
    for pin in ("pin_a", "pin_b"):
        P = prod["parts"][pin]["pose"]
        T_rel = _pose(P["xyz"], P["rpy"])  # the block's pose is the identity
        own = cell.objects[pin].grasps
        assert own
        for g in own.values():
            via = block.grasps[f"block_via_{g.label}"]
            assert cell.product.via["block"][via.label] == pin
            np.testing.assert_allclose(via.T, T_rel @ g.T, atol=TOL)
            np.testing.assert_allclose(np.asarray(eulerxyz(*via.euler), float), via.T, atol=1e-9)
            assert via.width == g.width
            # the fingers' contact points, from the block's frame into the pin's: on its surface
            for s in (1, -1):
                c_block = via.T @ np.array([0.0, s * via.width / 2, 0.0, 1.0])
                c_pin = np.linalg.inv(T_rel) @ c_block
                assert _on_pin(c_pin[:3], cyls) < 1e-6, (via.label, c_pin)
    # the pins have no part mated into them: no via-grasps
    assert not any("_via_" in k for k in cell.objects["pin_a"].grasps)


def test_non_product_cell_grasps_unchanged() -> None:
    cell = load_problem(ROOT / "kb/problems/peg_in_block.yaml")
    assert not any("_via_" in k for m in cell.objects.values() for k in m.grasps)


def test_via_grasp_refused_while_the_pin_is_not_carried() -> None:
    """A pickup of the block by pin_a's grasp before pin_a is in is infeasible, named."""
    cell = load_problem(ROOT / "kb/problems/turn_over.yaml")
    label = next(k for k in cell.objects["block"].grasps if k.startswith("block_via_pin_a_"))
    ev = phase2.evaluate(CellCache(cell), [{"id": "a1", "name": "pickup", "args": ["block", label]}])
    rec = ev.steps[0] if hasattr(ev, "steps") else ev["steps"][0]
    bad = [v for v in rec["verdicts"] if not v["satisfied"]]
    assert any(v["constraint"] == "via_grasp" and "pin_a" in v["description"] for v in bad), bad


#: pin_a into the block, then the block (pin_a in it) picked up by one of pin_a's grasps.
VIA_STEPS = [{"id": "a1", "name": "pickup", "args": ["pin_a", "pin_a_g23"]},
             {"id": "a2", "name": "assemble", "args": ["pin_a", "block", [["shaft"], ["bore_a"]], "trans_pin_a",
                                                        "vec_pin_a"]},
             {"id": "a3", "name": "pickup", "args": ["block", "block_via_pin_a_g23"]}]


def _radius(path: str, name: str) -> float:
    """A feature's radius (mm) read from an object file."""
    doc = yaml.safe_load((ROOT / path).read_text())
    return next(f["radius"] for f in doc["features"] if f["name"] == name)


def test_via_grasp_pickup_contacts_are_on_the_carried_pin_and_sound() -> None:
    """A via-grasp's pickup contacts are on pin_a at its pose composed through the mate: the
    bounds are wider than the block's own pose gives by the mate's radial clearance (read from
    the object files), and no Monte Carlo draw falls outside them (INF <= every sampled value
    of a '>' constraint, SUP >= every one of a '<')."""
    cache = CellCache(load_problem(ROOT / "kb/problems/turn_over.yaml"))
    ev = phase2.evaluate(cache, VIA_STEPS)
    steps = ev.steps if hasattr(ev, "steps") else ev["steps"]
    via = {v["constraint"]: v for v in steps[2]["verdicts"] if v["constraint"].startswith("p")}
    assert sorted(via) == ["p1_c1", "p1_c2", "p2_c1", "p2_c2"]
    assert all(v["satisfied"] for v in via.values())
    replay = {r["constraint"]: r for r in phase2.sample_check(cache, VIA_STEPS, draws=4000) if r["action"] == "a3"}
    assert sorted(replay) == sorted(via)
    for name, v in via.items():
        r = replay[name]
        assert r["failed_draws"] == 0
        if name.startswith("p1"):  # '>': the bound is the infimum
            assert v["bound"] <= r["min"] + 1e-9, (name, v["bound"], r["min"])
        else:
            assert v["bound"] >= r["max"] - 1e-9, (name, v["bound"], r["max"])
    # the same grasp, contacts taken on the block's own possible pose: narrower by the clearance
    from spar_py.phase2 import uncertainty as ur
    world = phase2.new_world(cache, VIA_STEPS, {}, None)
    for s in VIA_STEPS[:2]:
        _, world, _ = phase2.step(world, s)
    cell = cache.cell
    g = cell.objects["block"].grasps["block_via_pin_a_g23"]
    manip = world.unc.manipulator_error()
    own = {c.name: ur.evaluate(c, world.unc.registry).bound for c in ur.pickup_constraints(
        world.unc, "block", g.T, g.width, cell.finger_separation, manip)}
    clearance = _radius("kb/objects/turn_block.yaml", "bore_a") - _radius("kb/objects/pin8.yaml", "shaft")
    for name, v in via.items():
        wider = own[name] - v["bound"] if name.startswith("p1") else v["bound"] - own[name]
        assert wider == pytest.approx(clearance, abs=1e-3), (name, own[name], v["bound"])


def test_motions_hold_the_body_by_the_grasped_pin() -> None:
    """After a via-grasp pickup the motions' held body is pin_a in the hand at its own grasp
    (T_tool_pin = T_G_pin^-1, the pin's own grasp read from the cell), the block carried at
    T_tool_block = T_G_pin^-1 T_rel^-1 (T_rel the pin's product pose, from the product file);
    the pickup's stop closes the fingers on pin_a."""
    from spar_py.world.motion import paths as motion

    cell = load_problem(ROOT / "kb/problems/turn_over.yaml")
    prod = yaml.safe_load((ROOT / "kb/products/turn_over.yaml").read_text())
    P = prod["parts"]["pin_a"]["pose"]
    T_rel = _pose(P["xyz"], P["rpy"])
    T_G = cell.objects["pin_a"].grasps["pin_a_g23"].T
    cache = CellCache(cell)
    world = phase2.new_world(cache, VIA_STEPS, {}, None)
    worlds, records = [world], []
    for s in VIA_STEPS:
        rec, world, geo = phase2.step(world, s)
        worlds.append(world)
        records.append({"geometry": geo})
    parts, held = motion._world_parts(worlds[-1])
    assert held is not None and held[0] == "pin_a"
    np.testing.assert_allclose(held[1], np.linalg.inv(T_G), atol=TOL)
    assert sorted(held[2]) == ["block"]
    np.testing.assert_allclose(held[2]["block"], np.linalg.inv(T_G) @ np.linalg.inv(T_rel), atol=TOL)
    assert "pin_a" not in parts and "block" not in parts
    # the block's own grasp: held by the block, nothing carried
    _, own = motion._world_parts(worlds[1])
    assert own is not None and own[0] == "pin_a" and not own[2]
    stops = motion.stops_of(cell, VIA_STEPS, worlds, records)
    pick = next(st for st in stops if st.id == "a3")
    assert pick.fingers_on == "pin_a"
    assert next(st for st in stops if st.id == "a1").fingers_on == "pin_a"
