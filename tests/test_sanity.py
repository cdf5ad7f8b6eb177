"""Issue 13 item 2: physically impossible cells are one-line errors at load, naming the
file, the key and both parties (sanity.py)."""
from __future__ import annotations

import time
from pathlib import Path

import numpy as np
import pytest

from spar_py.kb import sanity
from spar_py.core.errors import KBError
from spar_py.kb import load_problem
from spar_py.core.model import Solid

from paths import ROOT

PEG_AT = "[30, -8, 1.5]]}"


def _cell(tmp_path: Path, *subs: tuple[str, str], peg_model: str | None = None) -> Path:
    """peg_in_block.yaml with text substitutions, written into tmp_path (absolute KB paths)."""
    text = (ROOT / "kb/problems/peg_in_block.yaml").read_text()
    text = text.replace("../robots/", f"{ROOT}/kb/robots/").replace("../objects/", f"{ROOT}/kb/objects/")
    for old, new in subs:
        assert old in text, old
        text = text.replace(old, new)
    if peg_model is not None:
        m = tmp_path / "peg.yaml"
        m.write_text(peg_model)
        text = text.replace(f"{ROOT}/kb/objects/peg.yaml", str(m))
    p = tmp_path / "cell.yaml"
    p.write_text(text)
    return p


def _error(path: Path) -> str:
    with pytest.raises(KBError) as e:
        load_problem(path)
    msg = str(e.value)
    assert "\n" not in msg
    return msg


@pytest.mark.parametrize("path", sorted((ROOT / "kb/problems").glob("*.yaml")), ids=lambda p: p.stem)
def test_every_regression_cell_is_sane(path: Path) -> None:
    sanity.check_cell(load_problem(path))


def test_two_parts_at_the_same_spot(tmp_path: Path) -> None:
    msg = _error(_cell(tmp_path, (PEG_AT, "[30, 8, 1.5]]}")))
    assert msg.startswith(f"{tmp_path}/cell.yaml: objects.peg.initial: expected a part clear of block at init_pos2, "
                          "not overlapping it by ")
    assert msg.endswith(" in")


def test_overlap_depth_is_reported(tmp_path: Path) -> None:
    # the peg lying shaft to -y spans y in [y0 - 2.5, y0]; the block turned 30 deg reaches
    # down to y = 8 - 2.05 = 5.95 (a corner near x = 30.5): the peg at y0 = 6.5 reaches in
    msg = _error(_cell(tmp_path, (PEG_AT, "[30, 6.5, 1.5]]}")))
    assert "expected a part clear of block at init_pos2, not overlapping it by" in msg


def test_parts_side_by_side_are_fine(tmp_path: Path) -> None:
    load_problem(_cell(tmp_path, (PEG_AT, "[30, 0, 1.5]]}")))


def test_part_above_the_table(tmp_path: Path) -> None:
    msg = _error(_cell(tmp_path, (PEG_AT, "[30, -8, 21.5]]}")))
    assert msg == (f"{tmp_path}/cell.yaml: objects.peg.initial: expected peg at init_pos1 resting on the table, "
                   "a support or another part (its lowest point on the surface, its centre of mass over it); "
                   "it floats 20 in above the table")


def test_part_sunk_into_the_table(tmp_path: Path) -> None:
    msg = _error(_cell(tmp_path, (PEG_AT, "[30, -8, 0.5]]}")))
    assert msg.endswith("it sinks 1 in into the table")


def test_grasp_wider_than_the_gripper(tmp_path: Path) -> None:
    model = (ROOT / "kb/objects/peg.yaml").read_text()
    grasp = "eulerxyz: [0, 0, 0.5, 0.0, 0.0, 0.0], width: "
    model = model.replace(grasp + "3}", grasp + "5}")
    msg = _error(_cell(tmp_path, peg_model=model))
    assert msg == (f"{tmp_path}/peg.yaml: grasps[2].width: expected a grasp that fits puma762's gripper "
                   f"(finger separation W_m = 4 in, {ROOT}/kb/robots/puma762.yaml: gripper.finger_separation), "
                   "not peg's p1G3 5 in wide")


def test_zero_approach_vector(tmp_path: Path) -> None:
    msg = _error(_cell(tmp_path, ("vec_1: [0, 0, -1]", "vec_1: [0, 0, 0]")))
    assert msg == (f"{tmp_path}/cell.yaml: vectors.vec_1: expected a non-zero approach vector "
                   "(used by goals[0] assembled), not [0, 0, 0]")


def test_far_coordinates_fail_fast(tmp_path: Path) -> None:
    t0 = time.perf_counter()
    msg = _error(_cell(tmp_path, (PEG_AT, "[30, -1.0e+7, 1.5]]}")))
    assert "objects.peg.initial: expected peg at init_pos1 within 133.1 in of puma762's base" in msg
    assert msg.endswith("not y = -1e+07 in")
    regions = "gripper: open\nplacement_regions:\n  - {x: [-1.0e+5, 1.0e+5], y: [-1.0e+5, 1.0e+5]}\n"
    msg = _error(_cell(tmp_path, ("gripper: open\n", regions)))
    assert "placement_regions[0].x: expected a free table region within 133.1 in of puma762's base" in msg
    assert time.perf_counter() - t0 < 2.0


def _box(lo: list[float], hi: list[float]) -> Solid:
    return Solid("box", np.array(lo, float), np.array(hi, float))


def _at(x: float, y: float, z: float, yaw_deg: float = 0.0) -> np.ndarray:
    c, s = np.cos(np.radians(yaw_deg)), np.sin(np.radians(yaw_deg))
    T = np.eye(4)
    T[:3, :3] = [[c, -s, 0], [s, c, 0], [0, 0, 1]]
    T[:3, 3] = x, y, z
    return T


def test_overlap_depth_of_boxes() -> None:
    b = _box([-1, -1, -1], [1, 1, 1])
    assert sanity.overlap_depth(b, _at(0, 0, 0), b, _at(1.5, 0, 0)) == pytest.approx(0.5)
    assert sanity.overlap_depth(b, _at(0, 0, 0), b, _at(2.5, 0, 0)) < 0
    # turned 45 deg: a corner 1.414 out; at 2.3 apart it reaches 0.114 into the other
    assert sanity.overlap_depth(b, _at(0, 0, 0), b, _at(2.3, 0, 0, 45)) == pytest.approx(np.sqrt(2) + 1 - 2.3)
    # diagonal offset clear along x + y only (an edge-edge axis in 3D is not needed here)
    assert sanity.overlap_depth(b, _at(0, 0, 0), b, _at(2.01, 2.01, 0, 0)) < 0


def test_overlap_depth_of_cylinders() -> None:
    c = Solid("cylinder", np.array([-1.0, -1.0, 0.0]), np.array([1.0, 1.0, 2.0]), 1.0)
    # axes 1.9 apart: 0.1 deep (the inscribed 16-gon is at least cos(pi/16) r out)
    d = sanity.overlap_depth(c, _at(0, 0, 0), c, _at(1.9, 0, 0))
    assert 0 < d <= 0.1 + 1e-9
    # corners of the bounding squares overlap, the cylinders do not: no false overlap
    assert sanity.overlap_depth(c, _at(0, 0, 0), c, _at(1.6, 1.6, 0)) < 0
    # stacked, touching end to end: not overlapping
    assert sanity.overlap_depth(c, _at(0, 0, 0), c, _at(0, 0, 2.0)) <= 1e-12
