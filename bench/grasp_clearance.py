"""Which grasps of a part the arm can use where it lies and where it is mated: a diagnosis aid.

Run from the project root:
``.venv/bin/python -m bench.grasp_clearance kb/problems/fabrica_plumbers_block.yaml bolt1 [--done cap,bearing]``.

For each grasp of PART (a product cell's part) it prints two verdicts, each the set of outcomes of
the arm's in-limit IK branches (``ok`` or the first colliding pair of that branch):
- ``pickup``: the tool at the part's initial position (every other part where the cell puts it),
  the fingers closing on the part;
- ``mate``: the part held at its product pose on the base's initial position, the parts named by
  ``--done`` already there (their product poses), the rest where the cell puts them; the held part
  may touch the base and those parts.
A grasp ``ok`` in both is one a direct pickup-and-insert can use; none such means the part needs a
regrasp (another stable pose) or a grasp the derivation does not list, and the pairs say which link
meets which body.
"""
from __future__ import annotations

import argparse
from collections.abc import Mapping
from pathlib import Path

import numpy as np

from spar_py.kb.problem import load_problem
from spar_py.world.collision import CellCache
from spar_py.world.reach.workspace import ik_rows


def _outcomes(cache: CellCache, T: np.ndarray, parts: Mapping[str, np.ndarray], **at: object) -> list[str]:
    """The distinct outcomes of the IK branches reaching world tool pose T (4x4): ``ok`` or the
    branch's colliding pair ``a-b``; empty when no branch is in limits with the wrist above the table."""
    Q, okb = ik_rows(cache.cell, T[None])
    state = cache.scene().at(dict(parts), **at)
    out = []
    for b in np.flatnonzero(okb[0]):
        clear, why = state.check(Q[0, b][None])
        out.append("ok" if clear[0] else "-".join(why[0]))
    return sorted(set(out))


def report(problem: Path, part: str, done: list[str]) -> list[str]:
    """One line per grasp of ``part`` in the product cell ``problem``: its width, its approach in
    the part's frame and the pickup and mate verdicts (module docstring)."""
    cell = load_problem(problem)
    if cell.product is None:
        raise SystemExit(f"{problem}: not a product cell (no product:)")
    cache = CellCache(cell)
    at = {p.obj: p.T for p in cell.positions.values()}
    T_base = at[cell.product.base]
    inv_base = np.linalg.inv(np.asarray(cell.product.parts[cell.product.base].pose, float))
    rel = {n: inv_base @ np.asarray(p.pose, float) for n, p in cell.product.parts.items()}
    mated = {**at, **{d: T_base @ rel[d] for d in done}}
    mated.pop(part)
    T_part = T_base @ rel[part]
    allow = [(f"held:{part}", n) for n in (cell.product.base, *done)]
    lines = []
    for g in cell.objects[part].grasps.values():
        Tg = np.asarray(g.T, float)
        pick = _outcomes(cache, at[part] @ Tg, at, held=None, grasped=part, width=g.width)
        mate = _outcomes(cache, T_part @ Tg, mated, held=(part, np.linalg.inv(Tg)), grasped=None,
                         width=g.width, allow=allow)
        a = np.round(Tg[:3, 2], 2) + 0.0
        lines.append(f"{g.label:16s} width {g.width:6.1f}  approach(part) {a}  pickup {pick}  mate {mate}")
    return lines


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("problem", type=Path)
    ap.add_argument("part")
    ap.add_argument("--done", default="", help="parts already mated (comma-separated)")
    args = ap.parse_args(argv)
    done = [d for d in args.done.split(",") if d]
    for line in report(args.problem, args.part, done):
        print(line)


if __name__ == "__main__":
    main()
