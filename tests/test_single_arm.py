"""Can one arm on a table build a product (world/product/single_arm.py), and the product file's
``retention:`` override of derived mates (kb/products.py).

Heights and directions are checked against the Fabrica car's PLY files read by trimesh alone
(cm, the product frame), not the project's geometry."""
from __future__ import annotations

from pathlib import Path

import pytest
import trimesh
import yaml

from spar_py.core.errors import KBError
from spar_py.kb.products import load_product
from spar_py.planning.messages import summary
from spar_py.world.product.single_arm import single_arm_report

from paths import ROOT

FABRICA = ROOT / "kb" / "products" / "fabrica"
CM = 10.0  # mm per cm
WHEELS = ("wheel0", "wheel3", "wheel4", "wheel5")


@pytest.fixture(scope="module")
def car():
    return load_product(FABRICA / "car.yaml", "mm")


@pytest.fixture(scope="module")
def pressfit():
    return load_product(FABRICA / "car_pressfit.yaml", "mm")


def _product_file(tmp_path: Path, retention: dict) -> Path:
    """The car's product file with absolute mesh paths and ``retention`` (own copy)."""
    doc = yaml.safe_load((FABRICA / "car.yaml").read_text())
    for d in doc["parts"].values():
        d["mesh"] = str(FABRICA / d["mesh"])
    doc["retention"] = retention
    f = tmp_path / "car_r.yaml"
    f.write_text(yaml.safe_dump(doc))
    return f


def test_retention_override_fixes_the_named_parts_mates(car, pressfit):
    assert {m.retention for m in car.mates} == {"loose"}
    by_part = {m.peg if m.peg != "chassis" else m.hole: m.retention for m in pressfit.mates}
    assert {p: by_part[p] for p in WHEELS} == dict.fromkeys(WHEELS, "fixed")
    assert by_part["body"] == "loose"


@pytest.mark.parametrize("retention, key, words", [
    ({"chassis": "fixed"}, "retention.chassis", "the base"),
    ({"wheel9": "fixed"}, "retention.wheel9", "did you mean"),
    ({"wheel0": "tight"}, "retention.wheel0", "one of loose, fixed"),
])
def test_retention_override_refusals(tmp_path, retention, key, words):
    with pytest.raises(KBError) as e:
        load_product(_product_file(tmp_path, retention), "mm")
    assert e.value.key == key
    assert words in str(e.value) and "\n" not in str(e.value)


def test_loose_car_refused_naming_the_wheel_and_what_it_needs(car):
    r = single_arm_report(car, "mm")
    assert r is not None and not r.ok
    assert r.blocked.part in WHEELS and r.blocked.retention == "loose"
    assert r.blocked.mate.startswith(f"{r.blocked.part}.") and "->body." in r.blocked.mate
    assert "fixture" in r.why and "second arm" in r.why and "fixed retention" in r.why
    # the wheel's direction is +-y in the product frame (own geometry: its axle's axis is the
    # PLY's y, the wheels on either side of the body's centre)
    assert abs(abs(r.blocked.direction[1]) - 1.0) < 1e-6
    json = r.to_json()
    assert json["ok"] is False and json["part"] == r.blocked.part and json["poses"]


def test_pressfit_car_only_sideways_at_the_wheels_height(pressfit):
    r = single_arm_report(pressfit, "mm")
    assert r is not None and r.ok
    assert set(r.order) == {"body", *WHEELS} and r.order[0] == "body"
    assert len(r.level) == 4
    # upright (-z down), each wheel's centre of mass above the lowest point of the car (own
    # geometry: the PLYs in cm, the product frame)
    meshes = {p: trimesh.load(FABRICA / f"car/{n}.ply", process=False) for p, n in
              (("chassis", 2), ("body", 1), ("wheel0", 0), ("wheel3", 3), ("wheel4", 4), ("wheel5", 5))}
    floor = min(float(m.vertices[:, 2].min()) for m in meshes.values()) * CM
    for line in r.level:
        part = line.split()[0]
        h = float(meshes[part].center_mass[2]) * CM - floor
        assert f"{h:.4g} mm above the table" in line and "resting -z down" in line
    # from above it would need the car on its side, turning the loose body
    assert "body" in r.why and "loose" in r.why


def test_products_that_need_no_turning_are_ok():
    for f in ("turn_over.yaml", "bracket_kit.yaml", "plate_pins.yaml"):
        r = single_arm_report(load_product(ROOT / "kb" / "products" / f, "mm"), "mm")
        assert r is None or (r.ok and not r.level), f


def test_turn_over_needs_the_fixed_pin_first():
    """turn_over: pin_b (loose) can only go in last: pin_a (fixed) goes in, the block is turned."""
    r = single_arm_report(load_product(ROOT / "kb" / "products" / "turn_over.yaml", "mm"), "mm")
    assert r is not None and r.ok and r.order == ("pin_a", "pin_b")


def test_summary_leads_with_the_single_arm_reason(car):
    from types import SimpleNamespace

    why = "one arm on a table cannot insert wheel0 (...): it needs a fixture or a second arm"
    cell = SimpleNamespace(product=car, goals=[], name="c", objects={})
    line = summary(cell, {"single_arm": {"ok": False, "why": why}, "max_actions": 11, "bound": 24}, [])
    assert line.endswith(why) and line.startswith("NO PLAN")


def _rx(deg: float):
    import numpy as np

    c, s = np.cos(np.radians(deg)), np.sin(np.radians(deg))
    return np.array([[1.0, 0, 0], [0, c, -s], [0, s, c]])


def test_layout_turns_the_base_to_make_the_most_insertions_from_above():
    """world.product.layout._base_pose: upright (-z down) unless another stable pose of the base lets
    more insertions in from above, counted in an order the precedence allows."""
    from types import SimpleNamespace

    import numpy as np

    from spar_py.world.product.layout import _base_pose

    upright = SimpleNamespace(label="up", R=np.eye(3))
    side = SimpleNamespace(label="side", R=_rx(90.0))       # the product's -y down
    assert np.allclose(side.R @ [0, -1, 0], [0, 0, -1])
    model = SimpleNamespace(poses={"side": side, "up": upright})
    z, y = np.array([0, 0, -1.0]), np.array([0, -1.0, 0])
    one_each = [("a", z, frozenset()), ("b", y, frozenset({"a"})), ("c", y, frozenset())]
    assert _base_pose(model, np.eye(4), one_each).label == "up"           # 1 against 1: upright
    two_side = [*one_each, ("d", y, frozenset())]
    assert _base_pose(model, np.eye(4), two_side).label == "side"         # 1 against 2
    chained = [("a", z, frozenset()), ("b", y, frozenset({"a"})), ("c", y, frozenset({"a"}))]
    assert _base_pose(model, np.eye(4), chained).label == "up"            # b, c wait for a
    assert _base_pose(model).label == "up"                                # no insertions: upright
