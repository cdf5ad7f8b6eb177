"""Generated problems for scaling runs (issues 7, 18): N pegs into N blocks, N = 1..MAX_PARTS.

:func:`generate_assembly` writes a self-contained knowledge base: the problem file,
one object file per part and a copy of the robot file. Every block starts hole-down
(p2P3 in the paper's model), so each pair needs the paper's four actions (Sec. 6,
Fig. 23): pickup(block), putdown(block), pickup(peg), assemble; N pairs need 4N.

The parts are copies of the paper's models (kb/objects/peg.yaml, block.yaml) under
new object names with their own label prefixes (``peg3`` gets grasps ``p5G1..``, poses
``p5P1..``), so labels in the constraint network say which part they belong to.

Layout (world frame, inches, the table top z = 0; the PUMA 762 as kb/robots/puma762.yaml
places it): the table is divided into pair cells PITCH_X by PITCH_Y, each holding a
block and, PEG_GAP to its -x side, its peg (lying on its -y base face, p1P5), both
footprints centred on the cell's row line. :func:`slots` keeps the cells that

- keep every footprint at least PEDESTAL_RADIUS from the robot's base axis (the
  pedestal stands there), and
- the arm can work: some block grasp reaches the block where it starts (hole-down)
  *and*, with the same grasp, hole-up at the same spot (the put-down: phase 2 puts a
  part down nearest its previous spot, and every block centre lies on the
  placement grid, see below); some peg grasp that leaves the peg's mating face free
  reaches the peg where it lies *and* mates it into the hole-up block there
  (reachable and mate_reachable, Sec. 5.2.4, by the planner's own IK: workspace.reaches),

and takes the first N of them by distance from the base axis (ties by angle), so the
parts gather as rings of cells around the robot. Neighbouring cells' footprints are
CELL_GAP apart and the peg's is PEG_GAP from its block's, both more than the put-down
clearance (placement.CLEARANCE_MM), so a block put down hole-up where it stood is clear
of everything. The free table (``placement_regions``) is one rectangle around the
layout grown by MARGIN, its corner on the placement grid (placement.GRID_STEP_MM) of the
block centres.

Planning them needs no flag: phase 1's default bound and step budget are derived
from the problem (spar_defaults.pl: the bound twice the lower bound, 8N here; 100 steps
per action of it), and iterative deepening starts at its lower bound, 4N here.

``main`` is the body of ``spar gen assembly --parts N [-o DIR]``.
"""
from __future__ import annotations

import argparse
import math
import re
import shutil
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .errors import SparValueError

__all__ = [
    "MAX_PARTS",
    "Slot",
    "generate_assembly",
    "layout",
    "main",
    "renamed_model",
    "slots",
]

KB_DIR = Path(__file__).resolve().parent.parent.parent / "kb"
PEG_MODEL = KB_DIR / "objects" / "peg.yaml"
BLOCK_MODEL = KB_DIR / "objects" / "block.yaml"
ROBOT = KB_DIR / "robots" / "puma762.yaml"

#: The most pairs :func:`generate_assembly` accepts: as many cells as :func:`slots` finds
#: for the PUMA 762 (checked by tests/test_gen.py).
MAX_PARTS = 100
#: Gap between the footprints of a peg and its block, and between neighbouring cells (in).
PEG_GAP = 2.0
CELL_GAP = 2.0
#: Pair cells (in): a multiple of the placement grid (2 in) each way, so every block
#: centre is a grid point of the free region.
PITCH_X = 10.0
PITCH_Y = 6.0
#: No footprint nearer the robot's base axis than this (in): the pedestal.
PEDESTAL_RADIUS = 12.0
#: Free table around the layout for the put-downs (in), a multiple of the grid step.
MARGIN = 6.0
#: How far out cells are looked for (in): past the PUMA 762's reach (about 54 in here).
SEARCH_HALF_WIDTH = 70.0
#: Where the lattice of block centres sits (in, from the grid point nearest the base axis):
#: the offset of the multiples of 2 in that fits the most cells round the PUMA 762.
OFFSET = (2.0, 0.0)

# The paper's poses in its row form (Fig. 18): the peg lying on its -y base face
# (p1P5), the block hole-down (p2P3) and hole-up (p2P1, after the put-down).
PEG_POSE, BLOCK_POSE, BLOCK_UP_POSE = "p1P5", "p2P3", "p2P1"
PEG_TM = [[1, 0, 0], [0, 0, 1], [0, -1, 0]]
BLOCK_TM = [[1, 0, 0], [0, -1, 0], [0, 0, -1]]

# Table 2 and Fig. 11 of the paper (in, deg).
MANIPULATOR_BOUNDS = "{dx: [-0.001, 0.001], dy: [-0.001, 0.001], dz: [-0.001, 0.001], dtheta: [-0.001, 0.001]}"
OBJECT_BOUNDS = "{dx: [-0.11, 0.11], dy: [-0.11, 0.11], dz: [-0.11, 0.11], dtheta: [-5.5, 5.5]}"
SCAN_BOUNDS = "{dx: [-0.05, 0.05], dy: [-0.05, 0.05], dz: [-0.05, 0.05], dtheta: [-0.5, 0.5]}"
# T_a of the paper's cell (in): the peg upside down in the hole, its tip at the bottom.
TA = [[1, 0, 0], [0, -1, 0], [0, 0, -1], [0, 0, 2.5]]

_LABEL = re.compile(r"\bp(\d+)([GP]\d+)\b")


def renamed_model(text: str, name: str, prefix: int, source: str) -> str:
    """An object file's text with the object called ``name`` and every grasp and pose
    label ``p<k>G<i>``/``p<k>P<i>`` renumbered to ``p<prefix>...``; comments are kept.

    ``source`` (the template's path, for the header comment) is not read.
    """
    if not re.fullmatch(r"[a-z][A-Za-z0-9_]*", name):
        raise SparValueError(f"object name {name!r} is not a label")
    text, n = re.subn(r"(?m)^object: .*$", f"object: {name}", text, count=1)
    if n != 1:
        raise SparValueError(f"{source}: no `object:` line to rename")
    text = _LABEL.sub(lambda m: f"p{prefix}{m.group(2)}", text)
    header = (f"# Generated by spar_py.gen from {source}: the same model as object {name},\n"
              f"# its grasp and pose labels renumbered p{prefix}G*/p{prefix}P*.\n")
    return header + text


@dataclass(frozen=True)
class Slot:
    """One pair cell of the layout (world frame, inches): the object-frame origins of the
    peg (``peg``, lying, p1P5) and of the block (``block``, hole-down, p2P3), and the
    axis-aligned box ``(xmin, ymin, xmax, ymax)`` holding both footprints."""

    peg: tuple[float, float]
    block: tuple[float, float]
    box: tuple[float, float, float, float]

    @property
    def distance(self) -> float:
        """The block centre's distance from the world z axis (in)."""
        return math.hypot(*self.block)


def _models():
    """The peg and block models and the robot, in inches (kb.load_object, kb.load_robot)."""
    from .kb import load_object, load_robot

    return load_object(PEG_MODEL, "in"), load_object(BLOCK_MODEL, "in"), load_robot(ROBOT, "in")


def _pose_T(R: np.ndarray, x: float, y: float, z: float) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = R
    T[:3, 3] = (x, y, z)
    return T


def _grasp_ok(robot, grasps, first: np.ndarray, second: np.ndarray) -> np.ndarray:
    """(n,) bool: for each pair i of object poses first[i], second[i] (world, 4x4), some
    grasp of ``grasps`` (each a 4x4 tool-in-object) reaches both: one batched IK call."""
    if not grasps:
        return np.zeros(len(first), dtype=bool)
    from .workspace import reaches

    G = np.stack(grasps)                                            # (g, 4, 4)
    A = np.einsum("nij,gjk->ngik", first, G).reshape(-1, 4, 4)
    B = np.einsum("nij,gjk->ngik", second, G).reshape(-1, 4, 4)
    ok = reaches(robot, np.concatenate([A, B])).reshape(2, len(first), len(G))
    return (ok[0] & ok[1]).any(axis=1)


def slots() -> list[Slot]:
    """Every usable pair cell of the layout (see the module docstring), nearest the base
    axis first (ties by angle about it, from -x round)."""
    from .placement import footprint

    peg, block, robot = _models()
    sp_peg, sp_blk, sp_up = peg.poses[PEG_POSE], block.poses[BLOCK_POSE], block.poses[BLOCK_UP_POSE]
    fp_peg, fp_blk = footprint(peg, sp_peg.R), footprint(block, sp_blk.R)
    (plo, phi), (blo, bhi) = (fp_peg.min(0), fp_peg.max(0)), (fp_blk.min(0), fp_blk.max(0))
    width = (phi[0] - plo[0]) + PEG_GAP + (bhi[0] - blo[0]) + CELL_GAP
    height = max(phi[1] - plo[1], bhi[1] - blo[1]) + CELL_GAP
    if width > PITCH_X + 1e-9 or height > PITCH_Y + 1e-9:  # pragma: no cover - fixed models
        raise SparValueError(f"a pair needs {width:g} x {height:g} in, more than the cell")
    base = robot.base[:2, 3]
    k = int(SEARCH_HALF_WIDTH // PITCH_X), int(SEARCH_HALF_WIDTH // PITCH_Y)
    cells = []
    for i in range(-k[0], k[0] + 1):
        for j in range(-k[1], k[1] + 1):
            bx = round(base[0] / 2) * 2 + OFFSET[0] + PITCH_X * i
            by = round(base[1] / 2) * 2 + OFFSET[1] + PITCH_Y * j
            bcx, bcy = bx + (blo[0] + bhi[0]) / 2, by + (blo[1] + bhi[1]) / 2
            px = bx + blo[0] - PEG_GAP - phi[0]                     # peg's box PEG_GAP left of the block's
            py = bcy - (plo[1] + phi[1]) / 2                        # both boxes centred on one line
            box = (px + plo[0], min(py + plo[1], by + blo[1]), bx + bhi[0], max(py + phi[1], by + bhi[1]))
            near = np.clip(base, box[:2], box[2:])                  # the box's point nearest the axis
            if math.hypot(*(near - base)) >= PEDESTAL_RADIUS and math.hypot(bcx - base[0], bcy - base[1]) > 0:
                cells.append(Slot((px, py), (bx, by), box))
    if not cells:  # pragma: no cover
        return []
    peg_T = np.stack([_pose_T(sp_peg.R, *c.peg, sp_peg.height) for c in cells])
    blk_T = np.stack([_pose_T(sp_blk.R, *c.block, sp_blk.height) for c in cells])
    up_T = np.stack([_pose_T(sp_up.R, *c.block, sp_up.height) for c in cells])
    free = [g for g in block.grasps.values()
            if not set(g.gfaces) & (set(sp_blk.rfaces) | set(sp_up.rfaces))]
    ok = _grasp_ok(robot, [g.T for g in free], blk_T, up_T)
    Ta = np.asarray(TA[:3], float).T
    T_a = _pose_T(Ta, *TA[3])
    mate = [g for g in peg.grasps.values()
            if not set(g.ofaces) & set(peg.mating_faces) and not set(g.gfaces) & set(sp_peg.rfaces)]
    ok &= _grasp_ok(robot, [g.T for g in mate], peg_T, up_T @ T_a)
    good = [c for c, v in zip(cells, ok) if v]
    return sorted(good, key=lambda c: (round(c.distance, 9), math.atan2(c.block[1] - base[1], c.block[0] - base[0])))


def layout(n_parts: int) -> list[tuple[tuple[float, float], tuple[float, float]]]:
    """The (x, y) of each pair's peg and block (in, world frame): the first ``n_parts``
    cells of :func:`slots`, nearest the robot first."""
    _check_n(n_parts)
    cells = slots()[:n_parts]
    if len(cells) < n_parts:  # pragma: no cover - MAX_PARTS is checked against slots()
        raise SparValueError(f"only {len(cells)} pairs fit within the arm's reach, not {n_parts}")
    return [(c.peg, c.block) for c in cells]


def _check_n(n_parts: int) -> None:
    if isinstance(n_parts, bool) or not isinstance(n_parts, int) or not 1 <= n_parts <= MAX_PARTS:
        raise SparValueError(f"n_parts must be an integer from 1 to {MAX_PARTS}, not {n_parts!r}")


def _tm(rows: list[list[int]], x: float, y: float, z: float) -> str:
    r = ", ".join(f"[{a}, {b}, {c}]" for a, b, c in rows)
    return f"[{r}, [{_num(x)}, {_num(y)}, {_num(z)}]]"


def _num(v: float) -> str:
    return str(int(v)) if float(v).is_integer() else f"{v:g}"


def _region(cells: list[Slot]) -> tuple[tuple[float, float], tuple[float, float]]:
    """The free table: the layout's box grown by MARGIN, its corner on the placement grid
    through the block centres (so a block can go down again exactly where it stood)."""
    from .placement import GRID_STEP_MM

    step = GRID_STEP_MM / 25.4
    box = np.array([c.box for c in cells])
    lo, hi = box[:, :2].min(0) - MARGIN, box[:, 2:].max(0) + MARGIN
    anchor = np.array(cells[0].block)
    lo = anchor - step * np.ceil((anchor - lo) / step - 1e-9)
    return (float(lo[0]), float(hi[0])), (float(lo[1]), float(hi[1]))


def _problem_text(n_parts: int, robot_rel: str) -> str:
    cells = slots()[:n_parts]
    if len(cells) < n_parts:  # pragma: no cover
        raise SparValueError(f"only {len(cells)} pairs fit within the arm's reach, not {n_parts}")
    (x0, x1), (y0, y1) = _region(cells)
    lines = [
        f"# Generated by spar_py.gen: {n_parts} peg(s) into {n_parts} block(s) (issues 7, 18).",
        "# Tests: phase 1 at scale. Every block rests hole-down (p2P3 in the paper's",
        "# model), so each pair needs pickup(block), putdown(block), pickup(peg),",
        f"# assemble: {4 * n_parts} actions in all (phase 1's default bound allows them).",
        "# Pair cells around the PUMA 762 (waist axis at the origin), nearest first: each",
        "# peg lying on its -y base face (p1P5) beside its block; every cell checked",
        "# reachable for the pickups, the put-down where the block stands and the mate.",
        f"problem: assembly_{n_parts}",
        "units: {length: in, angle: deg}",
        f"robot: {robot_rel}",
        "objects:",
    ]
    for k, c in enumerate(cells, start=1):
        lines += [
            f"  peg{k}:",
            f"    model: objects/peg{k}.yaml",
            f"    initial: {{name: init_pos{2 * k - 1}, label: tr{2 * k - 1}, tm: {_tm(PEG_TM, *c.peg, 1.5)}}}",
            f"  block{k}:",
            f"    model: objects/block{k}.yaml",
            f"    initial: {{name: init_pos{2 * k}, label: tr{2 * k}, tm: {_tm(BLOCK_TM, *c.block, 1.5)}}}",
        ]
    lines += [
        "gripper: open",
        "# Free table for the put-downs: the layout's box and a margin all round.",
        "placement_regions:",
        f"  - {{x: [{_num(x0)}, {_num(x1)}], y: [{_num(y0)}, {_num(y1)}]}}",
        "# Table 2 of the paper for the manipulator and every part.",
        "uncertainty:",
        f"  manipulator: {MANIPULATOR_BOUNDS}",
        "  objects:",
    ]
    for k in range(1, n_parts + 1):
        for obj in (f"peg{k}", f"block{k}"):
            lines.append(f"    {obj}: {OBJECT_BOUNDS}")
    lines += [
        "# Fig. 11: a dense range scan leaves +-0.05 in and +-0.5 deg.",
        "sensors:",
        f"  dense_range_scan: {SCAN_BOUNDS}",
        "# T_a and V_a of the paper's cell, shared by every pair: the peg upside down in",
        "# the hole, its tip at the hole's bottom centre; the approach down the hole.",
        "transforms:",
        f"  trans_1: {{tm: {_tm(TA[:3], *TA[3])}}}",
        "vectors:",
        "  vec_1: [0, 0, -1]",
        "goals:",
    ]
    lines += [f"  - assembled(peg{k}, block{k}, [[peg_face], [block_face]], trans_1, vec_1)"
              for k in range(1, n_parts + 1)]
    return "\n".join(lines) + "\n"


def generate_assembly(n_parts: int, out_dir: str | Path) -> Path:
    """Write the N-pegs-into-N-blocks problem into ``out_dir``; return the problem file.

    Files: ``assembly_<N>.yaml``, ``objects/peg<k>.yaml`` and ``objects/block<k>.yaml``
    for k = 1..N, ``robots/puma762.yaml`` (a copy, so the directory stands alone).
    Existing files of those names are overwritten. Raises SparValueError for N outside
    1..MAX_PARTS.
    """
    _check_n(n_parts)
    out = Path(out_dir)
    (out / "objects").mkdir(parents=True, exist_ok=True)
    (out / "robots").mkdir(parents=True, exist_ok=True)
    shutil.copyfile(ROBOT, out / "robots" / ROBOT.name)
    peg_text, block_text = PEG_MODEL.read_text(encoding="utf-8"), BLOCK_MODEL.read_text(encoding="utf-8")
    for k in range(1, n_parts + 1):
        (out / "objects" / f"peg{k}.yaml").write_text(
            renamed_model(peg_text, f"peg{k}", 2 * k - 1, "kb/objects/peg.yaml"), encoding="utf-8")
        (out / "objects" / f"block{k}.yaml").write_text(
            renamed_model(block_text, f"block{k}", 2 * k, "kb/objects/block.yaml"), encoding="utf-8")
    problem = out / f"assembly_{n_parts}.yaml"
    problem.write_text(_problem_text(n_parts, f"robots/{ROBOT.name}"), encoding="utf-8")
    return problem


def main(argv: list[str]) -> int:
    """``spar gen assembly --parts N [-o DIR]``: write the problem, print its path.

    ``argv`` are the arguments after ``gen``. Exit codes as the ``spar`` command's:
    0 written, 2 bad arguments.
    """
    p = argparse.ArgumentParser(prog="spar gen", description="generate knowledge bases")
    sub = p.add_subparsers(dest="kind", required=True)
    a = sub.add_parser("assembly", help=f"N pegs into N hole-down blocks (N = 1..{MAX_PARTS})")
    a.add_argument("--parts", "-n", type=int, required=True, metavar="N")
    a.add_argument("-o", "--out", default=None, metavar="DIR",
                   help="output directory (default: ./assembly_N)")
    try:
        args = p.parse_args(argv)
    except SystemExit as e:  # argparse has printed its message
        return 0 if e.code == 0 else 2
    try:
        path = generate_assembly(args.parts, args.out or f"assembly_{args.parts}")
    except SparValueError as e:
        print(f"spar: gen assembly: {e}", file=sys.stderr)
        return 2
    print(path)
    return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main(sys.argv[1:]))
