"""Generate the product cells' meshes and the 20-hole board's files (issue 33): run from the
repository root, ``.venv/bin/python scripts/make_products.py``; the outputs are committed, so a
change here shows in their diff.

Meshes (kb/objects/meshes/, binary STL, mm; a part with round holes off its z axis, which
``shape:`` primitives cannot cut):

- ``plate2.stl``: a plate 120 x 40 x 14 mm with two blind holes (radius 5.5 mm, 8 mm deep)
  at x = -30 and 30 mm, opening on its top; frame at the centre of its bottom face.
- ``bracket2.stl``: a plate 100 x 40 x 12 mm with two through holes (radius 5.5 mm) at
  x = -35 and 35 mm; frame at the centre of its bottom face.
- ``base2.stl``: a block 120 x 50 x 30 mm with two blind holes (radius 5.5 mm, 5 mm deep)
  at x = -35 and 35 mm, opening on its top; frame at the centre of its bottom face.

The 20-hole board (kb/objects/board20.yaml, kb/objects/meshes/board20.stl, kb/products/board20.yaml,
kb/problems/board20.yaml) is what ``spar gen board 20`` writes (spar_py.app.gen.generate_board):
this script writes the same files into kb/ with kb's own pin model and robot.
"""
from __future__ import annotations

import sys
from pathlib import Path

from spar_py.app.gen import board_files, board_layout, board_mesh, holed_box

ROOT = Path(__file__).resolve().parent.parent
MESHES = ROOT / "kb" / "objects" / "meshes"
#: The task board kept in kb/ (spar gen board 20).
BOARD_N = 20


def main() -> int:
    MESHES.mkdir(parents=True, exist_ok=True)
    board = board_layout(BOARD_N)
    meshes = {
        "plate2": holed_box([-60, -20, 0], [60, 20, 14], [(-30, 0), (30, 0)], 5.5, 8),
        "bracket2": holed_box([-50, -20, 0], [50, 20, 12], [(-35, 0), (35, 0)], 5.5, None),
        "base2": holed_box([-60, -25, 0], [60, 25, 30], [(-35, 0), (35, 0)], 5.5, 5),
        board.name: board_mesh(board),
    }
    for name, mesh in meshes.items():
        assert mesh.is_volume, name
        mesh.export(MESHES / f"{name}.stl", file_type="stl")
        print(f"{MESHES / (name + '.stl')}: {len(mesh.faces)} triangles, volume {mesh.volume:.1f} mm^3")
    for rel, text in board_files(board).items():
        path = ROOT / "kb" / rel
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text, encoding="utf-8")
        print(path)
    return 0


if __name__ == "__main__":
    sys.exit(main())
