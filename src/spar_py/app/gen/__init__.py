"""Generated problems (``spar gen``), each kind in a module of its own; this door names what
the callers use:

- N pegs into N blocks for scaling runs (issues 7, 18): :func:`generate_assembly` (assembly.py),
  the pair cells' layout (cells.py), the template models' rewriting (models.py);
- task boards (issue 33): :func:`generate_board` (board.py), N pins into an N-hole board;
- a product's parts laid out on the table for a robot (issue 34): :func:`layout_problem_text`
  (product_layout.py);
- the two-shaft gearbox of issue 43 as meshes (its mesh-only product and problem, the declared
  models' meshes): :func:`generate_gearbox` (gearbox.py).

``main`` is the body of ``spar gen assembly --parts N [-o DIR]`` and ``spar gen board N``, and of
``python -m spar_py.app.gen gearbox [OUTDIR]``.
"""
from __future__ import annotations

import argparse
import sys

from spar_py.app.gen.assembly import generate_assembly
from spar_py.app.gen.board import Board, board_files, board_layout, board_mesh, board_rows, generate_board, holed_box
from spar_py.app.gen.cells import (CAPACITY, MAX_PARTS, MAX_PARTS_FULL, MAX_SIDE, MAX_TURNED, SIDE, Slot, blocks_for,
                                   layout, slots)
from spar_py.app.gen.gearbox import gearbox_meshes, generate_gearbox
from spar_py.app.gen.models import keep_grasps, renamed_model, robot_text, scaled_model
from spar_py.app.gen.product_layout import layout_problem_text
from spar_py.core.errors import SparValueError

__all__ = [
    "Board",
    "CAPACITY",
    "MAX_PARTS",
    "MAX_PARTS_FULL",
    "MAX_SIDE",
    "MAX_TURNED",
    "blocks_for",
    "board_files",
    "board_layout",
    "board_mesh",
    "board_rows",
    "generate_board",
    "holed_box",
    "Slot",
    "gearbox_meshes",
    "generate_assembly",
    "generate_gearbox",
    "layout",
    "layout_problem_text",
    "main",
    "keep_grasps",
    "renamed_model",
    "robot_text",
    "scaled_model",
    "slots",
]


def main(argv: list[str]) -> int:
    """``spar gen assembly --parts N [-o DIR]``, ``spar gen board N [--rows R] [-o DIR]`` or
    ``gearbox [OUTDIR]``: write the problem, print its path.

    ``argv`` are the arguments after ``gen``. Exit codes as the ``spar`` command's:
    0 written, 2 bad arguments.
    """
    p = argparse.ArgumentParser(prog="spar gen", description="generate knowledge bases")
    sub = p.add_subparsers(dest="kind", required=True)
    a = sub.add_parser("assembly", help=f"N pegs into N blocks (N = 1..{MAX_PARTS})")
    a.add_argument("--parts", "-n", type=int, required=True, metavar="N")
    a.add_argument("--blocks", choices=tuple(CAPACITY), default=None,
                   help=f"the blocks' start (default: hole-down up to {MAX_TURNED} pairs, {SIDE} up to "
                        f"{MAX_SIDE}, hole-up up to {MAX_PARTS_FULL}, else hole-up-small)")
    a.add_argument("-o", "--out", default=None, metavar="DIR",
                   help="output directory (default: ./assembly_N)")
    b = sub.add_parser("board", help="a task board: N pins into N holes of one board")
    b.add_argument("n", type=int, metavar="N")
    b.add_argument("--rows", type=int, default=None, metavar="R", help="the board's rows (default about 0.9 sqrt(N))")
    b.add_argument("-o", "--out", default=None, metavar="DIR", help="output directory (default: ./board_N)")
    g = sub.add_parser("gearbox", help="issue 43's two-shaft gearbox as meshes, into a KB root")
    g.add_argument("out", nargs="?", default="gearbox", metavar="OUTDIR",
                   help="the KB root to write into (default: ./gearbox; kb to refresh the committed files)")
    try:
        args = p.parse_args(argv)
    except SystemExit as e:  # argparse has printed its message
        return 0 if e.code == 0 else 2
    try:
        if args.kind == "gearbox":
            path = generate_gearbox(args.out)
        elif args.kind == "board":
            path = generate_board(args.n, args.out or f"board_{args.n}", args.rows)
        else:
            path = generate_assembly(args.parts, args.out or f"assembly_{args.parts}", args.blocks)
    except SparValueError as e:
        print(f"spar: gen {args.kind}: {e}", file=sys.stderr)
        return 2
    print(path)
    return 0
