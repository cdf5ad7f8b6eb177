"""Issue 35, item 5: each message a newcomer meets is one line that says what is wrong in the
user's terms (a part out of proportion, a large angle in radians, why there is no plan,
the unit of a bound, a plan with expected failures)."""
from __future__ import annotations

import shutil
from pathlib import Path

import pytest

from spar_py.core.errors import KBError
from spar_py.kb import load_problem

ROOT = Path(__file__).resolve().parent.parent
KB = ROOT / "kb"


def _metres_mesh_cell(tmp: Path) -> Path:
    """shaft_in_bracket with the shaft's mesh rewritten in metres, its model still saying mm."""
    import trimesh

    (tmp / "objects" / "meshes").mkdir(parents=True)
    (tmp / "robots").mkdir()
    (tmp / "problems").mkdir()
    m = trimesh.load(str(KB / "objects/meshes/hex_shaft.stl"), force="mesh")
    m.apply_scale(0.001)
    m.export(str(tmp / "objects/meshes/hex_shaft.stl"))
    shutil.copy(KB / "objects/meshes/bracket.stl", tmp / "objects/meshes/bracket.stl")
    shutil.copy(KB / "objects/bracket.yaml", tmp / "objects/bracket.yaml")
    (tmp / "objects/hex_shaft.yaml").write_text((KB / "objects/hex_shaft.yaml").read_text()
                                               .replace("radius: 12", "radius: 0.012"))
    shutil.copy(KB / "robots/puma762.yaml", tmp / "robots/puma762.yaml")
    prob = tmp / "problems/shaft_in_bracket.yaml"
    shutil.copy(KB / "problems/shaft_in_bracket.yaml", prob)
    return prob


def test_part_out_of_proportion_names_file_part_size_and_asks_for_the_unit(tmp_path: Path) -> None:
    prob = _metres_mesh_cell(tmp_path)
    with pytest.raises(KBError) as e:
        load_problem(prob)
    msg = str(e.value)
    assert "\n" not in msg
    assert "objects/hex_shaft.yaml: mesh: expected a part of a size in proportion to the cell" in msg
    assert "hex_shaft is 0.065 mm across, under 1 mm" in msg
    assert "is the file's length unit (mm" in msg
    assert "stable pose" not in msg


def test_part_sizes_of_the_kb_pass() -> None:
    for name in ("shaft_in_bracket", "peg_in_block_shapes", "ur5e_peg_in_block"):
        assert load_problem(KB / "problems" / f"{name}.yaml").objects
