"""Generated problems for scaling runs (issues 7, 18): N pegs into N blocks, N = 1..MAX_PARTS.

:func:`generate_assembly` writes a self-contained knowledge base: the problem file,
one object file per part and a copy of the robot file. Up to MAX_TURNED pairs every block
starts hole-down (p2P3 in the paper's model), so each pair needs the paper's four actions
(Sec. 6, Fig. 23): pickup(block), putdown(block), pickup(peg), assemble; N pairs need 4N.
Above MAX_TURNED, up to MAX_SIDE, every block starts on its side (p2P5, the hole facing
sideways) in a dense layout and is turned a quarter turn to hole-up: the same four actions a
pair, 4N. Above MAX_SIDE (up to MAX_PARTS) every block starts hole-up (p2P1) and each pair needs
two: pickup(peg), assemble; above MAX_PARTS_FULL the parts are smaller (:func:`blocks_for`;
``blocks=`` chooses: "hole-down", "on-side", "hole-up", "hole-up-small").

The parts are copies of the paper's models (kb/objects/peg.yaml, block.yaml) under
new object names with their own label prefixes (``peg3`` gets grasps ``p5G1..``, poses
``p5P1..``), so labels in the constraint network say which part they belong to.

Layout (world frame, inches, the table top z = 0; the PUMA 762 as kb/robots/puma762.yaml
places it), blocks hole-down: pair cells in columns on either side of the robot
(x = +-(COLUMN0 + k PITCH_X)),
PITCH_Y apart along each column; each holds a block and, PEG_GAP beyond it on the side away
from the robot, its peg (lying on its -y base face, p1P5), both footprints centred on the
cell's line. Turning a block over (hole-down p2P3 to hole-up p2P1, a half turn about its x
axis) needs a grasp whose approach stays horizontal at both ends, i.e. along x (p2G7, p2G8):
the wrist and forearm then come in level with the parts, from the robot's side, so the aisle
between columns (PITCH_X less the pair's width) is what makes them usable. The columns stop at
|y| <= COLUMNS_Y (the inner pair sooner); beyond them, rows at y = +-ROWS_Y along x (ROW_PITCH
apart, |x| <= ROWS_X) hold the same cells turned a quarter turn about the robot: the peg beyond
the block in y, the block hole-down yawed 180 deg (tm rows [-1 0 0; 0 1 0; 0 0 -1]), so that
a half turn about world y, by a grasp approaching along y from the robot's side (p2G1, p2G2),
leaves it hole-up at yaw 0 where it stood, exactly as a column's half turn about x does (phase
2 puts it down at the least yaw first). Blocks hole-up:
the same columns DENSE_PITCH_X apart (no aisles: the pegs are taken from above). :func:`slots`
keeps the cells that

- keep every footprint at least PEDESTAL_RADIUS from the robot's base axis (the
  pedestal stands there), and
- the arm can work, by the planner's own IK (workspace.reachable_ignoring_collisions) and then the world layer's
  collision scene (world.collision.scene, as phase 2 checks each step; :func:`_usable`): some block
  grasp (hole-down only) with which the block is picked up where it starts and put down hole-up at
  the same spot (phase 2 puts a part down nearest its previous spot, and every block centre
  lies on the placement grid, see below), and some peg grasp that leaves the mating face free
  with which the peg is picked up where it lies and mated into the hole-up block there, each
  by a solution clear of the table, of the part in the hand beyond the fingers' contact faces,
  and of every part any cell may hold at any step (all cells' lying pegs, blocks and
  assembled pegs at once: conservative for every N and every order of actions),

and takes the first N of them by distance from the base axis (ties by angle). Each generated
part's model keeps only its cell's usable grasps (:func:`keep_grasps`): phase 1 does not know
where the other parts will be, and phase 2 runs one assignment of the network in every order
before it tries the next, so one grasp that only collides with a neighbour would exhaust its
instance cap. Neighbouring footprints are at least CELL_GAP apart and the peg's is PEG_GAP from
its block's, both more than the put-down clearance (placement.CLEARANCE_MM), so a block put
down hole-up where it stood is clear of everything. The free table (``placement_regions``)
is one rectangle around the layout grown by MARGIN, its corner on the placement grid
(placement.GRID_STEP_MM) of the block centres.

MAX_TURNED (42) and MAX_PARTS_FULL (72) are what this check leaves for one PUMA 762 and the
paper's 3 in parts. Turn-over cells: 84 candidates, 46 within reach of the peg's grasps (its
pickup beyond the block and its mate, the limit), 42 clear (columns alone gave 34; no other
pitch, first column, row distance, mirrored columns sharing an aisle, or raised or lowered
pedestal tried gave more than 42: each cell needs its 10 x 6 in and an aisle of about 12 in on
the robot's side, and the ring the pegs are reached in holds about 45 such). Scaled parts cannot
be turned over: a horizontal grasp at a small block's centre (0.75 in up at half size, 1.2 in at
0.8) brings the wrist into the table (the collision scene refuses every IK solution, the block
alone). Hole-up cells: on a 10 x 6 in pitch the IK
alone finds 100 cells within reach and the
collision check keeps 72 (at the edge of reach the stretched arm's wrist comes down on the
neighbours). Above MAX_PARTS_FULL, up to MAX_PARTS (100; 130 cells pass), the parts are scaled
by SMALL_SCALE in every length (:func:`scaled_model`: shapes, pose heights, grasps and widths,
the features; the problem's T_a and uncertainty alike) and so is the gripper of the robot copy
(:func:`robot_text`: a full-size finger is wider than a small peg's base and enters the block
it mates into), on an 8 x 4 in pitch. A block started on a side face (on-side) needs only a
quarter turn, by a 45-degree grasp from above, so its cells need no aisle: the hole-up lattice
(10 x 6 in) keeps 70 of them (MAX_SIDE). Phase 1's lower bound counts such a pair as 4 actions
since it asks the oracle whether the peg can be mated into the block where it lies (it cannot:
the mated peg would enter the table; goals.pl, lower_bound/2); before, it counted 2 and the
rounds of iterative deepening below 4N spent the step budget (no plan at N = 2).

Planning them needs no flag: phase 1's default bound and step budget are derived
from the problem (spar_defaults.pl: the bound twice the lower bound; 100 steps per action of
it), iterative deepening starts at its lower bound (4N or 2N here, each exact), and phase 2's
first instance is executable (every grasp left in the models works where its part lies).

Task boards (issue 33): :func:`generate_board` writes N pins into an N-hole board, the task-board
kind (the NIST assembly task board 1 has twenty insertions on one board), as product, object,
mesh and problem files; ``spar gen board N [--rows R]``.

``main`` is the body of ``spar gen assembly --parts N [-o DIR]`` and ``spar gen board N``.
"""
from __future__ import annotations

import argparse
import math
import re
import sys
import tempfile
from collections.abc import Iterable
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
import yaml

from spar_py.core.errors import SparValueError
from spar_py.core.memo import Memo
from spar_py.core.units import from_mm
from spar_py.kb import SAFE_LOADER, load_object, load_robot
from spar_py.world.collision import DEFAULT_MARGIN_MM, CollisionScene, solid_bodies
from spar_py.world.reach import GRID_STEP_MM, footprint
from spar_py.world.reach import reachable_ignoring_collisions, wrist_above_table

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
    "generate_assembly",
    "layout",
    "main",
    "keep_grasps",
    "renamed_model",
    "robot_text",
    "scaled_model",
    "slots",
]

KB_DIR = Path(__file__).resolve().parents[3] / "kb"
PEG_MODEL = KB_DIR / "objects" / "peg.yaml"
BLOCK_MODEL = KB_DIR / "objects" / "block.yaml"
ROBOT = KB_DIR / "robots" / "puma762.yaml"

#: The most pairs :func:`generate_assembly` accepts: as many cells as :func:`slots` finds
#: clear for the PUMA 762 (checked by tests/test_gen.py).
MAX_PARTS = 100
#: The most pairs of full-size parts (blocks hole-up); above, the parts are scaled down.
MAX_PARTS_FULL = 72
#: The most pairs whose blocks start hole-down (each turned over: 4 actions a pair); above it
#: the blocks start hole-up (2 actions a pair: pickup(peg), assemble), see :func:`blocks_for`.
MAX_TURNED = 42
#: The most pairs whose blocks start on a side face (each turned a quarter turn to hole-up by a
#: 45-degree grasp from above: 4 actions a pair as well, no aisles), see :func:`blocks_for`.
MAX_SIDE = 70
SIDE = "on-side"
#: The two layouts and the most pairs each holds (checked by tests/test_gen.py).
CAPACITY = {"hole-down": MAX_TURNED, SIDE: MAX_SIDE, "hole-up": MAX_PARTS_FULL, "hole-up-small": MAX_PARTS}
#: Gap between the footprints of a peg and its block, and between neighbouring cells (in).
PEG_GAP = 2.0
CELL_GAP = 2.0
#: Columns of pair cells (in): PITCH_X apart (a pair is 10 in wide, the rest the aisle that
#: the block's horizontal turn-over grasp needs: 20 to 22 leave the most cells clear), the first
#: COLUMN0 from the base axis, cells PITCH_Y apart along a column. Multiples of the placement
#: grid (2 in), so every block centre is a grid point of the free region.
PITCH_X = 22.0
PITCH_Y = 6.0
COLUMN0 = 12.0
#: Blocks hole-up (never moved): no aisles, columns 10 in apart (a pair's width).
DENSE_PITCH_X = 10.0
DENSE_COLUMN0 = 4.0
#: Above MAX_PARTS_FULL pairs: the parts scaled by SMALL_SCALE in every length (a 1.5 in block,
#: the peg's tolerances and the cell's uncertainty alike), columns 8 in apart, cells 4 in.
SMALL_SCALE = 0.5
SMALL_PITCH_X, SMALL_PITCH_Y = 8.0, 4.0
#: Each layout's (column pitch, first column, cell pitch along a column) in inches, and scale.
LAYOUT = {"hole-down": (PITCH_X, COLUMN0, PITCH_Y), SIDE: (DENSE_PITCH_X, DENSE_COLUMN0, PITCH_Y),
          "hole-up": (DENSE_PITCH_X, DENSE_COLUMN0, PITCH_Y),
          "hole-up-small": (SMALL_PITCH_X, DENSE_COLUMN0, SMALL_PITCH_Y)}
#: Blocks hole-down, beyond the columns' ends: ROWS_Y[k] is the |y| (in) of a row of cells along
#: x (ROW_PITCH apart, |x| at most ROWS_X) whose blocks start hole-down turned 180 degrees about
#: z, so a half turn about world y (a grasp approaching along y, from the robot's side: p2G1,
#: p2G2) leaves them hole-up at yaw 0, as the columns' half turn about x does; the columns keep
#: |y| <= COLUMNS_Y, so each row's aisle (towards the robot) is clear of their cells.
ROWS_Y: tuple[float, ...] = (32.0,)
ROWS_X = 30.0
ROW_PITCH = 6.0
COLUMNS_Y: tuple[float, ...] = (18.0, 24.0)
SCALE = {"hole-down": 1.0, SIDE: 1.0, "hole-up": 1.0, "hole-up-small": SMALL_SCALE}
#: No footprint nearer the robot's base axis than this (in): the pedestal.
PEDESTAL_RADIUS = 12.0
#: Free table around the layout for the put-downs (in), a multiple of the grid step.
MARGIN = 6.0
#: How far out cells are looked for (in): past the PUMA 762's reach (about 54 in here).
SEARCH_HALF_WIDTH = 70.0

# The paper's poses in its row form (Fig. 18): the peg lying on its -y base face
# (p1P5), the block hole-down (p2P3) and hole-up (p2P1, after the put-down).
PEG_POSE, BLOCK_UP_POSE = "p1P5", "p2P1"
#: The block's start pose in a turn-over cell (hole-down: a half turn to hole-up, which only a
#: horizontal grasp at table height makes, hence the aisles) and in an extra cell (hole-up, the
#: block never moves). A block started on a side face would need only a quarter turn (a
#: 45-degree grasp from above at both ends, no aisle), but phase 1's lower bound counts such a
#: pair as two actions and iterative deepening then spends its step budget below 4N.
BLOCK_POSE = "p2P3"
#: The block's start pose in an on-side cell: resting on b5 (its +y face), the hole facing -y.
SIDE_POSE = "p2P5"
PEG_TM = [[1, 0, 0], [0, 0, 1], [0, -1, 0]]

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
    header = (f"# Generated by spar_py.app.gen from {source}: the same model as object {name},\n"
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
    #: The template models' grasp labels (p2G*, p1G*) usable in this cell with every other
    #: cell's parts in place (:func:`_usable`): the generated part models keep only these.
    block_grasps: tuple[str, ...] = ()
    peg_grasps: tuple[str, ...] = ()
    #: The block's start pose (a label of the template model: BLOCK_POSE or BLOCK_UP_POSE).
    pose: str = ""
    #: The block's start turned this much about world z (deg): 0 in a column, 180 in a row.
    yaw: int = 0

    @property
    def distance(self) -> float:
        """The block centre's distance from the world z axis (in)."""
        return math.hypot(*self.block)


def scaled_model(text: str, k: float) -> str:
    """An object file's text with every length multiplied by ``k`` (shape, stable-pose heights,
    grasp positions and widths, the feature's radius and vector, face points); angles and
    labels kept. The YAML is rewritten (its comments are dropped); ``k`` = 1 returns it as is."""
    if k == 1:
        return text
    d = yaml.load(text, Loader=SAFE_LOADER)

    def sc(v):
        return [sc(x) for x in v] if isinstance(v, list) else float(v) * k

    for solid in d.get("shape", []):
        for kind in solid.values():
            for key in ("min", "max", "radius", "z", "center"):
                if key in kind:
                    kind[key] = sc(kind[key])
    for pose in d.get("stable_poses", []):
        pose["tm"][3] = sc(pose["tm"][3])
    for g in d.get("grasps", []):
        g["eulerxyz"][:3] = sc(g["eulerxyz"][:3])
        g["width"] = sc(g["width"])
    feat = d.get("feature")
    if feat:
        for key in ("radius", "vector"):
            if key in feat:
                feat[key] = sc(feat[key])
    if "face_names" in d:
        d["face_names"] = {f: sc(v) for f, v in d["face_names"].items()}
    return yaml.safe_dump(d, sort_keys=False, default_flow_style=None, width=200)


def robot_text(text: str, k: float) -> str:
    """The robot file's text with its gripper (finger separation, finger and palm boxes) scaled
    by ``k``: the tooling for parts scaled by ``k`` (a full-size finger is wider than a small
    peg's base and would enter the block it is mated into). The arm is unchanged."""
    if k == 1:
        return text

    def nums(m: re.Match) -> str:
        return m.group(1) + re.sub(r"\d+(?:\.\d+)?", lambda v: f"{float(v.group(0)) * k:g}", m.group(2))

    text, n = re.subn(r"(?m)^(  finger_separation: )([\d.]+)", nums, text, count=1)
    text, n2 = re.subn(r"(?m)^(  (?:finger|palm): )(\{[^}]*\})", nums, text)
    if n != 1 or n2 != 2:  # pragma: no cover - the fixed robot file
        raise SparValueError(f"{ROBOT}: no gripper lines to scale")
    return f"# Generated by spar_py.app.gen: kb/robots/{ROBOT.name} with its gripper scaled by {k:g}.\n" + text


def _models(scale: float = 1.0):
    """The peg and block models (lengths times ``scale``) and the robot, in inches
    (kb.load_object, kb.load_robot)."""
    if scale == 1:
        return load_object(PEG_MODEL, "in"), load_object(BLOCK_MODEL, "in"), load_robot(ROBOT, "in")
    with tempfile.TemporaryDirectory(prefix="spar-gen-") as d:
        out = []
        for src in (PEG_MODEL, BLOCK_MODEL):
            path = Path(d) / src.name
            path.write_text(scaled_model(src.read_text(encoding="utf-8"), scale), encoding="utf-8")
            out.append(load_object(path, "in"))
        path = Path(d) / ROBOT.name
        path.write_text(robot_text(ROBOT.read_text(encoding="utf-8"), scale), encoding="utf-8")
        robot = load_robot(path, "in")
    return out[0], out[1], robot


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
    G = np.stack(grasps)                                            # (g, 4, 4)
    A = np.einsum("nij,gjk->ngik", first, G).reshape(-1, 4, 4)
    B = np.einsum("nij,gjk->ngik", second, G).reshape(-1, 4, 4)
    ok = reachable_ignoring_collisions(robot, np.concatenate([A, B])).reshape(2, len(first), len(G))
    return (ok[0] & ok[1]).any(axis=1)


def slots(blocks: str = "hole-down") -> list[Slot]:
    """Every usable pair cell of the layout for blocks starting ``blocks`` ("hole-down": a turn
    over each, "hole-up": never moved; see the module docstring), nearest the base axis first
    (ties by angle about it, from -x round)."""
    if blocks not in CAPACITY:
        raise SparValueError(f"blocks must be one of {', '.join(CAPACITY)}, not {blocks!r}")
    scale, pitch_y = SCALE[blocks], LAYOUT[blocks][2]
    peg, block, robot = _models(scale)
    sp_peg, sp_blk, sp_up = peg.poses[PEG_POSE], block.poses[BLOCK_POSE], block.poses[BLOCK_UP_POSE]
    fp_peg, fp_blk = footprint(peg, sp_peg.R), footprint(block, sp_blk.R)
    (plo, phi), (blo, bhi) = (fp_peg.min(0), fp_peg.max(0)), (fp_blk.min(0), fp_blk.max(0))
    width = (phi[0] - plo[0]) + PEG_GAP + (bhi[0] - blo[0]) + CELL_GAP
    depth = max(phi[1] - plo[1], bhi[1] - blo[1]) + CELL_GAP
    if width > LAYOUT[blocks][0] + 1e-9 or depth > pitch_y + 1e-9:  # pragma: no cover - fixed models
        raise SparValueError(f"a pair needs {width:g} x {depth:g} in, more than the cell")
    base = robot.base[:2, 3]
    gx, gy = round(base[0] / 2) * 2, round(base[1] / 2) * 2   # the grid point nearest the axis

    def lattice(pitch_x: float, column0: float, ymax: tuple[float, ...] = (math.inf,)) -> list[Slot]:
        """Cells in columns x = +-(column0 + k pitch_x), PITCH_Y apart, the peg on the far side,
        column k's blocks within ymax[k] (the last for the rest) of the base axis in y."""
        out = []
        kx, ky = int(SEARCH_HALF_WIDTH // pitch_x), int(SEARCH_HALF_WIDTH // pitch_y)
        for side in (-1, 1):
            for i in range(kx + 1):
                bx = gx + side * (column0 + pitch_x * i)
                for j in range(-ky, ky + 1):
                    by = gy + pitch_y * j
                    bcy = by + (blo[1] + bhi[1]) / 2
                    py = bcy - (plo[1] + phi[1]) / 2                    # both boxes centred on one line
                    px = bx + bhi[0] + PEG_GAP - plo[0] if side > 0 else bx + blo[0] - PEG_GAP - phi[0]
                    box = (min(px + plo[0], bx + blo[0]), min(py + plo[1], by + blo[1]),
                           max(px + phi[0], bx + bhi[0]), max(py + phi[1], by + bhi[1]))
                    near = np.clip(base, box[:2], box[2:])              # the box's point nearest the axis
                    if (math.hypot(*(near - base)) >= PEDESTAL_RADIUS
                            and abs(by - gy) <= ymax[min(i, len(ymax) - 1)]):
                        out.append(Slot((px, py), (bx, by), box))
        return out

    def rows() -> list[Slot]:
        """Cells in rows y = +-ROWS_Y[k] along x, ROW_PITCH apart, the peg beyond the block
        (further from the base axis), centred on the block's x; the block turned 180 deg."""
        out = []
        kx = int(ROWS_X // ROW_PITCH)
        for side in (-1, 1):
            for ry in ROWS_Y:
                by = gy + side * ry
                for i in range(-kx, kx + 1):
                    bx = gx + ROW_PITCH * i
                    px = bx + (blo[0] + bhi[0]) / 2 - (plo[0] + phi[0]) / 2
                    py = by + bhi[1] + PEG_GAP - plo[1] if side > 0 else by + blo[1] - PEG_GAP - phi[1]
                    box = (min(px + plo[0], bx + blo[0]), min(py + plo[1], by + blo[1]),
                           max(px + phi[0], bx + bhi[0]), max(py + phi[1], by + bhi[1]))
                    out.append(Slot((px, py), (bx, by), box, yaw=180))
        return out

    T_a = _pose_T(np.asarray(TA[:3], float).T, *(np.asarray(TA[3], float) * scale))
    mate = [g for g in peg.grasps.values()
            if not set(g.ofaces) & set(peg.mating_faces) and not set(g.gfaces) & set(sp_peg.rfaces)]

    def peg_reach(cells: list[Slot]) -> list[Slot]:
        if not cells:
            return []
        peg_T = np.stack([_pose_T(sp_peg.R, *c.peg, sp_peg.height) for c in cells])
        up_T = np.stack([_pose_T(sp_up.R, *c.block, sp_up.height) for c in cells])
        return [c for c, v in zip(cells, _grasp_ok(robot, [g.T for g in mate], peg_T, up_T @ T_a)) if v]

    free = [g for g in block.grasps.values() if not set(g.gfaces) & (set(sp_blk.rfaces) | set(sp_up.rfaces))]
    if blocks in ("hole-down", SIDE):  # each block turned where it lies: a grasp reaching both ends
        if blocks == SIDE:  # a quarter turn: the dense lattice (grasps from above, no aisles)
            sp_blk = block.poses[SIDE_POSE]
            free = [g for g in block.grasps.values()
                    if not set(g.gfaces) & (set(sp_blk.rfaces) | set(sp_up.rfaces))]
            cells = peg_reach(lattice(*LAYOUT[blocks][:2]))
        else:  # columns with aisles and rows beyond them, for the half turn's horizontal grasp
            cells = peg_reach(lattice(*LAYOUT[blocks][:2], COLUMNS_Y) + rows())
        if cells:
            blk_T = np.stack([_pose_T(_rotz(c.yaw) @ sp_blk.R, *c.block, sp_blk.height) for c in cells])
            up_T = np.stack([_pose_T(sp_up.R, *c.block, sp_up.height) for c in cells])
            cells = [c for c, v in zip(cells, _grasp_ok(robot, [g.T for g in free], blk_T, up_T)) if v]
        cells = [replace(c, pose=sp_blk.label) for c in cells]
    else:  # the dense lattice, the blocks never moved
        cells = [replace(c, pose=BLOCK_UP_POSE) for c in peg_reach(lattice(*LAYOUT[blocks][:2]))]
    usable = _usable(peg, block, robot, cells, free, mate, sp_blk, list(range(len(cells))), T_a)
    good = [replace(c, block_grasps=b, peg_grasps=p) for c, (b, p) in zip(cells, usable)
            if p and (b or c.pose == BLOCK_UP_POSE)]
    return sorted(good, key=lambda c: (round(c.distance, 9), math.atan2(c.block[1] - base[1], c.block[0] - base[0])))


def _rotz(deg: int) -> np.ndarray:
    """3x3 rotation by ``deg`` (a multiple of 90) degrees about z, exact."""
    c, s = {0: (1, 0), 90: (0, 1), 180: (-1, 0), 270: (0, -1)}[deg % 360]
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]], float)


def _cell_parts(c: Slot, k: int, poses: tuple) -> dict[str, np.ndarray]:
    """What cell ``c`` (index k) may hold at any point of a plan (world poses, in): its peg
    lying, its block (hole-down and hole-up share one cube), and the peg assembled into it.
    Names ``peg@<k>``, ``block@<k>``, ``peg@a<k>`` (the collision scene reads the model name
    before the @)."""
    sp_peg, sp_blk, sp_up, T_a = poses
    up = _pose_T(sp_up.R, *c.block, sp_up.height)
    return {f"peg@{k}": _pose_T(sp_peg.R, *c.peg, sp_peg.height),
            f"block@{k}": _pose_T(_rotz(c.yaw) @ sp_blk.R, *c.block, sp_blk.height), f"peg@a{k}": up @ T_a}


def _usable(peg, block, robot, cells: list[Slot], free: list, mate: list, start, todo: list[int],
            T_a: np.ndarray) -> list[tuple[tuple[str, ...], tuple[str, ...]]]:
    """For each cell of ``cells`` whose index is in ``todo``, the block grasps (of ``free``) with
    which the arm picks the block up where it lies in stable pose ``start`` and puts it down
    hole-up there, and the peg grasps (of ``mate``) with which it picks
    the peg up and mates it into the block, each by an IK solution clear of the table, the part
    in the hand (the grasp rule) and every part any cell may hold at any step (this cell's other
    part included, every other cell's lying peg, block and assembled peg at once): the collision
    scene of world.collision.scene, as phase 2 checks each step. The union over every point of a plan
    is conservative, so any subset of the cells, in any order of actions, stays clear.

    Why prune grasps at all: a side grasp at table height puts the wrist and forearm level with
    the parts around (the tool mount is 4 to 8 in behind the grasp point, the forearm's axis
    10 in), so in a layout of many parts most side grasps hit a neighbour. Phase 1 does not know
    where the other parts will be, so it would keep those grasps, and phase 2 examines the
    instances of one assignment in every order before it tries another: one bad grasp of one
    part exhausts the instance cap. A generated part's model lists only what works where it lies.
    """

    margin = robot.margin if robot.margin is not None else from_mm("in", DEFAULT_MARGIN_MM)
    scene = CollisionScene(robot, robot.gripper, {"peg": solid_bodies("peg", peg.shape),
                                                  "block": solid_bodies("block", block.shape)},
                           (), margin, None, "in", Memo())
    poses = (peg.poses[PEG_POSE], start, block.poses[BLOCK_UP_POSE], T_a)
    contents = [_cell_parts(c, k, poses) for k, c in enumerate(cells)]
    names = [n for d in contents for n in d]
    where = {n: T for d in contents for n, T in d.items()}
    # every part body's bounding sphere, world frame: the broad phase below
    sph_c, sph_r, owner = [], [], []
    for n in names:
        for b in scene.shapes_of(n):
            bb = b.placed(where[n], -1, n)
            a, e, r = bb.cap
            sph_c.append((a + e) / 2)
            sph_r.append(np.linalg.norm(e - a) / 2 + r)
            owner.append(n)
    sph_c, sph_r, owner = np.array(sph_c), np.array(sph_r), np.array(owner)

    def works(TO: np.ndarray, own: str, grasps: list, absent: set[str]) -> np.ndarray:
        """(g,) bool: some clear IK solution for the tool at TO @ g.T, ``own`` being grasped,
        every part but ``absent`` (the same peg elsewhere) in place."""
        out = np.zeros(len(grasps), dtype=bool)
        for w in sorted({g.width for g in grasps}):
            idx = [i for i, g in enumerate(grasps) if g.width == w]
            T = np.stack([TO @ grasps[i].T for i in idx])
            Q, okb = robot.ik_batch(T)
            rows, cols = np.nonzero(okb & wrist_above_table(robot, T)[:, None])
            if not len(rows):
                continue
            q = Q[rows, cols]
            C, R = scene.at({own: TO}, None, own, width=w).moving_spheres(q)
            gap = (np.sqrt(((C[:, :, None] - sph_c) ** 2).sum(-1)) - R[:, None] - sph_r).min(axis=(0, 1))
            near = set(owner[gap <= margin].tolist()) - {own} - absent
            clear = scene.at({own: TO, **{n: where[n] for n in near}}, None, own, width=w).clear(q)
            out[np.array(idx)[np.unique(rows[clear])]] = True
        return out

    result = []
    for k in todo:
        c, own = cells[k], contents[k]
        Tp, Tb, Tm = own[f"peg@{k}"], own[f"block@{k}"], own[f"peg@a{k}"]
        Tu = _pose_T(poses[2].R, *c.block, poses[2].height)
        lying, fitted = f"peg@{k}", f"peg@a{k}"
        if c.pose == BLOCK_UP_POSE:  # never moved: no block grasp needed
            b_ok = np.zeros(len(free), dtype=bool)
        else:
            b_ok = works(Tb, f"block@{k}", free, {fitted}) & works(Tu, f"block@{k}", free, {fitted})
        p_ok = works(Tp, lying, mate, {fitted}) & works(Tm, fitted, mate, {lying})
        result.append((tuple(g.label for g, v in zip(free, b_ok) if v),
                       tuple(g.label for g, v in zip(mate, p_ok) if v)))
    return result


def blocks_for(n_parts: int) -> str:
    """The blocks' start for N pairs: "hole-down" (each turned over) up to MAX_TURNED pairs,
    "on-side" (each turned a quarter turn; 4 actions a pair too) up to MAX_SIDE, "hole-up" up to
    MAX_PARTS_FULL, "hole-up-small" above (the layout that holds MAX_PARTS)."""
    if n_parts <= MAX_TURNED:
        return "hole-down"
    if n_parts <= MAX_SIDE:
        return SIDE
    return "hole-up" if n_parts <= MAX_PARTS_FULL else "hole-up-small"


def _cells(n_parts: int, blocks: str | None) -> list[Slot]:
    _check_n(n_parts)
    blocks = blocks or blocks_for(n_parts)
    if blocks not in CAPACITY:
        raise SparValueError(f"blocks must be one of {', '.join(CAPACITY)}, not {blocks!r}")
    if n_parts > CAPACITY[blocks]:
        raise SparValueError(f"at most {CAPACITY[blocks]} pairs with the blocks {blocks}, not {n_parts}")
    cells = slots(blocks)[:n_parts]
    if len(cells) < n_parts:  # pragma: no cover - CAPACITY is checked against slots()
        raise SparValueError(f"only {len(cells)} pairs fit within the arm's reach, not {n_parts}")
    return cells


def layout(n_parts: int, blocks: str | None = None) -> list[tuple[tuple[float, float], tuple[float, float]]]:
    """The (x, y) of each pair's peg and block (in, world frame): the first ``n_parts``
    cells of :func:`slots` (``blocks`` default :func:`blocks_for`), nearest the robot first."""
    return [(c.peg, c.block) for c in _cells(n_parts, blocks)]


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
    step = GRID_STEP_MM / 25.4
    box = np.array([c.box for c in cells])
    lo, hi = box[:, :2].min(0) - MARGIN, box[:, 2:].max(0) + MARGIN
    anchor = np.array(cells[0].block)
    lo = anchor - step * np.ceil((anchor - lo) / step - 1e-9)
    return (float(lo[0]), float(hi[0])), (float(lo[1]), float(hi[1]))


def keep_grasps(text: str, labels: Iterable[str]) -> str:
    """An object file's text with only the grasp lines (``- {label: ...}``) whose label is in
    ``labels``; a comment line says which were dropped and why."""
    keep, dropped, out = set(labels), [], []
    for line in text.splitlines(keepends=True):
        m = re.match(r"\s*- \{label: (p\d+G\d+),", line)
        if m and m.group(1) not in keep:
            dropped.append(m.group(1))
            continue
        out.append(line)
    if not dropped:
        return "".join(out)
    note = (f"# Grasps {', '.join(dropped)} dropped by spar_py.app.gen: where this part lies, the arm\n"
            "# cannot use them clear of the other parts (see spar_py.app.gen._usable).\n")
    return note + "".join(out)


def _bounds(text: str, k: float) -> str:
    """A bounds line's text with its dx, dy, dz intervals times ``k`` (dtheta kept)."""
    def one(m: re.Match) -> str:
        lo, hi = float(m.group(2)) * k, float(m.group(3)) * k
        return f"{m.group(1)}: [{lo:g}, {hi:g}]"

    return re.sub(r"\b(d[xyz]): \[([-\d.]+), ([-\d.]+)\]", one, text)


def _problem_text(cells: list[Slot], robot_rel: str, scale: float = 1.0) -> str:
    n_parts = len(cells)
    (x0, x1), (y0, y1) = _region(cells)
    block = load_object(BLOCK_MODEL, "in")

    def rows(c: Slot) -> list[list[int]]:  # the block's start rotation in the tm's row form
        return [[int(round(v)) for v in r] for r in (_rotz(c.yaw) @ block.poses[c.pose].R).T]
    turned = all(c.pose == BLOCK_POSE for c in cells)
    side = all(c.pose == SIDE_POSE for c in cells)
    lines = [
        f"# Generated by spar_py.app.gen: {n_parts} peg(s) into {n_parts} block(s) (issues 7, 18).",
        *(["# Tests: phase 1 at scale. Every block rests hole-down (p2P3 in the paper's",
           "# model), so each pair needs pickup(block), putdown(block) hole-up, pickup(peg),",
           f"# assemble: {4 * n_parts} actions in all."] if turned else
          ["# Tests: phase 1 at scale. Every block rests on its side b5 (p2P5: the hole's axis",
           "# horizontal), so each pair needs pickup(block), putdown(block) hole-up (a quarter",
           f"# turn), pickup(peg), assemble: {4 * n_parts} actions in all."] if side else
          [f"# Tests: phase 1 at scale. More than {MAX_TURNED} pairs: every block rests hole-up",
           "# (p2P1), so each pair needs pickup(peg), assemble: "
           f"{2 * n_parts} actions in all (spar_py.app.gen.blocks_for)."]),
        *([f"# More than {MAX_PARTS_FULL} pairs: every length of the parts, of T_a, of the uncertainty",
           f"# and of the gripper (robots/ copy) scaled by {scale:g}."] if scale != 1 else []),
        "# Pair cells around the PUMA 762 (waist axis at the origin), nearest first: each",
        "# peg lying on its -y base face (p1P5) beside its block; every cell checked, with",
        "# the collision scene and every other part in place, for the pickups, the put-down",
        "# where the block stands and the mate; each part's model keeps the grasps that work.",
        f"problem: assembly_{n_parts}",
        "units: {length: in, angle: deg}",
        f"robot: {robot_rel}",
        "objects:",
    ]
    for k, c in enumerate(cells, start=1):
        lines += [
            f"  peg{k}:",
            f"    model: objects/peg{k}.yaml",
            f"    initial: {{name: init_pos{2 * k - 1}, label: tr{2 * k - 1}, tm: {_tm(PEG_TM, *c.peg, 1.5 * scale)}}}",
            f"  block{k}:",
            f"    model: objects/block{k}.yaml",
            f"    initial: {{name: init_pos{2 * k}, label: tr{2 * k}, tm: {_tm(rows(c), *c.block, 1.5 * scale)}}}",
        ]
    lines += [
        "gripper: open",
        "# Free table for the put-downs: the layout's box and a margin all round.",
        "placement_regions:",
        f"  - {{x: [{_num(x0)}, {_num(x1)}], y: [{_num(y0)}, {_num(y1)}]}}",
        "# Table 2 of the paper for the manipulator and every part.",
        "uncertainty:",
        f"  manipulator: {_bounds(MANIPULATOR_BOUNDS, scale)}",
        "  objects:",
    ]
    for k in range(1, n_parts + 1):
        for obj in (f"peg{k}", f"block{k}"):
            lines.append(f"    {obj}: {_bounds(OBJECT_BOUNDS, scale)}")
    lines += [
        "# Fig. 11: a dense range scan leaves +-0.05 in and +-0.5 deg.",
        "sensors:",
        f"  dense_range_scan: {_bounds(SCAN_BOUNDS, scale)}",
        "# T_a and V_a of the paper's cell, shared by every pair: the peg upside down in",
        "# the hole, its tip at the hole's bottom centre; the approach down the hole.",
        "transforms:",
        f"  trans_1: {{tm: {_tm(TA[:3], *(np.asarray(TA[3], float) * scale))}}}",
        "vectors:",
        "  vec_1: [0, 0, -1]",
        "goals:",
    ]
    lines += [f"  - assembled(peg{k}, block{k}, [[peg_face], [block_face]], trans_1, vec_1)"
              for k in range(1, n_parts + 1)]
    return "\n".join(lines) + "\n"


def generate_assembly(n_parts: int, out_dir: str | Path, blocks: str | None = None) -> Path:
    """Write the N-pegs-into-N-blocks problem into ``out_dir``; return the problem file.
    ``blocks``: "hole-down" (each block turned over: 4 actions a pair, N <= MAX_TURNED), "on-side"
    (each turned a quarter turn: 4 actions a pair, N <= MAX_SIDE),
    "hole-up" (2 actions a pair, N <= MAX_PARTS_FULL) or "hole-up-small" (the same with parts
    and gripper scaled by SMALL_SCALE, N <= MAX_PARTS); default :func:`blocks_for`.

    Files: ``assembly_<N>.yaml``, ``objects/peg<k>.yaml`` and ``objects/block<k>.yaml``
    for k = 1..N, ``robots/puma762.yaml`` (a copy, so the directory stands alone).
    Existing files of those names are overwritten. Raises SparValueError for N outside
    1..MAX_PARTS or above the layout's capacity.
    """
    blocks = blocks or blocks_for(n_parts)
    cells = _cells(n_parts, blocks)
    scale = SCALE[blocks]
    out = Path(out_dir)
    (out / "objects").mkdir(parents=True, exist_ok=True)
    (out / "robots").mkdir(parents=True, exist_ok=True)
    (out / "robots" / ROBOT.name).write_text(robot_text(ROBOT.read_text(encoding="utf-8"), scale), encoding="utf-8")
    peg_text, block_text = PEG_MODEL.read_text(encoding="utf-8"), BLOCK_MODEL.read_text(encoding="utf-8")
    scaled_texts: dict[str, str] = {}  # this call's: the cells share a few grasp subsets

    def scaled(text: str) -> str:
        if text not in scaled_texts:
            scaled_texts[text] = scaled_model(text, scale)
        return scaled_texts[text]

    for k, c in enumerate(cells, start=1):
        text = scaled(keep_grasps(peg_text, c.peg_grasps))
        (out / "objects" / f"peg{k}.yaml").write_text(
            renamed_model(text, f"peg{k}", 2 * k - 1, "kb/objects/peg.yaml"), encoding="utf-8")
        # a hole-up block is never moved: its model keeps the template's grasps (none is needed)
        text = block_text if c.pose == BLOCK_UP_POSE else keep_grasps(block_text, c.block_grasps)
        (out / "objects" / f"block{k}.yaml").write_text(
            renamed_model(scaled(text), f"block{k}", 2 * k, "kb/objects/block.yaml"), encoding="utf-8")
    problem = out / f"assembly_{n_parts}.yaml"
    problem.write_text(_problem_text(cells, f"robots/{ROBOT.name}", scale), encoding="utf-8")
    return problem


# ---------------------------------------------------------------------- task boards (issue 33)

#: A task board's layout (mm, world frame; the PUMA 762 of kb/robots/puma762.yaml at the origin):
#: holes BOARD_PITCH apart in x and y (a row's pins are gripped across y, so the rows' pitch is
#: what keeps the open fingers clear of the next row's heads), BOARD_MARGIN from the board's
#: edges to the outer holes' axes, the board BOARD_THICK thick with blind holes HOLE_DEPTH deep
#: of radius HOLE_RADIUS (the pin's shaft 3 mm: 0.4 mm clearance), its centre at BOARD_AT.
BOARD_PITCH = (25.0, 24.0)
BOARD_MARGIN = (20.0, 9.0)
BOARD_THICK = 14.0
HOLE_DEPTH = 8.0
HOLE_RADIUS = 3.4
BOARD_AT = (700.0, 250.0)
#: The pins on the table: standing on their tips, PIN_PITCH apart in a grid of the board's
#: columns, centred on the board's x, the first row at PINS_Y0 and the rows growing towards it.
PIN_PITCH = 40.0
PINS_Y0 = -330.0
#: The pin model (kb/objects/bpin.yaml: a head of radius 5 mm and 12 mm, a shaft of radius 3 mm
#: and 8 mm; frame at the head's far face, z along the shaft): its length and head radius (mm).
PIN_MODEL = KB_DIR / "objects" / "bpin.yaml"
PIN_LENGTH, PIN_HEAD = 20.0, 5.0
#: Kept between a pin's footprint and the board's, and between a pin and the pedestal (mm).
BOARD_GAP = 20.0


@dataclass(frozen=True)
class Board:
    """A task board of ``n`` insertions (mm, world frame): ``holes`` the hole axes' (x, y) in the
    board frame (its bottom face's centre), row by row; ``pins`` each pin's (x, y) on the table,
    pin k for hole k; ``size`` the board's (x, y) extent. Build with :func:`board_layout`."""

    n: int
    rows: int
    cols: int
    holes: tuple[tuple[float, float], ...]
    pins: tuple[tuple[float, float], ...]
    size: tuple[float, float]

    @property
    def name(self) -> str:
        """The board's name, its product's and its problem's: ``board<N>``."""
        return f"board{self.n}"


def board_rows(n: int) -> int:
    """The default rows of an N-hole board: about 0.9 sqrt(N) (4 for 20: five columns by four)."""
    return max(1, min(n, round(0.9 * math.sqrt(n))))


def board_layout(n: int, rows: int | None = None) -> Board:
    """The holes and pins of an N-insertion board of ``rows`` rows (default :func:`board_rows`),
    ceil(N / rows) columns, the last row filled from the left. Raises SparValueError for N or rows
    out of range, for pins that would stand on the board or the robot's pedestal, and for a hole
    or pin the PUMA 762 cannot reach from above (:func:`_board_reach`)."""
    if isinstance(n, bool) or not isinstance(n, int) or n < 1:
        raise SparValueError(f"the number of insertions must be a positive integer, not {n!r}")
    rows = board_rows(n) if rows is None else rows
    if isinstance(rows, bool) or not isinstance(rows, int) or not 1 <= rows <= n:
        raise SparValueError(f"--rows must be an integer from 1 to N = {n}, not {rows!r}")
    cols = -(-n // rows)
    (px, py), (mx, my) = BOARD_PITCH, BOARD_MARGIN
    xs = [px * (c - (cols - 1) / 2) for c in range(cols)]
    ys = [py * (r - (rows - 1) / 2) for r in range(rows)]
    holes = tuple((_r(xs[k % cols]), _r(ys[k // cols])) for k in range(n))
    size = (px * (cols - 1) + 2 * mx, py * (rows - 1) + 2 * my)
    pins = tuple((_r(BOARD_AT[0] + PIN_PITCH * (k % cols - (cols - 1) / 2)), _r(PINS_Y0 + PIN_PITCH * (k // cols)))
                 for k in range(n))
    board = Board(n, rows, cols, holes, pins, size)
    _board_fits(board)
    return board


def _r(v: float) -> float:
    """``v`` rounded to 1e-6 mm (so a layout's figures print as written)."""
    return round(float(v), 6)


def _board_fits(b: Board) -> None:
    """SparValueError unless every pin stands clear of the board and of the pedestal, and the arm
    reaches every pin on the table and every hole from above."""
    top = BOARD_AT[1] - b.size[1] / 2
    last = max(y for _, y in b.pins)
    if last + PIN_HEAD + BOARD_GAP > top:
        raise SparValueError(
            f"{b.n} insertions in {b.rows} rows: the pins' grid ({b.cols} x {-(-b.n // b.cols)} at "
            f"{PIN_PITCH:g} mm) reaches y = {last + PIN_HEAD:g} mm, onto the board's edge at y = {top:g} mm "
            f"(the board is {b.size[0]:g} x {b.size[1]:g} mm); fewer insertions or fewer rows")
    ped = PEDESTAL_RADIUS * 25.4 + PIN_HEAD + BOARD_GAP
    for k, (x, y) in enumerate(b.pins, 1):
        if math.hypot(x, y) < ped:
            raise SparValueError(f"pin{k} at ({x:g}, {y:g}) mm would stand on the robot's pedestal")
    _board_reach(b)


def _board_reach(b: Board) -> None:
    """SparValueError naming the first pin or hole whose pin the PUMA 762 cannot hold from above:
    the tool pointing down at the head's middle, at any of 8 yaws (workspace.reachable_ignoring_collisions,
    the planner's IK; collisions are phase 2's)."""
    robot = load_robot(ROBOT, "mm")
    head_mid = PIN_LENGTH - 6.0  # the head's middle above the table: the pin stands on its tip
    where = [(f"pin{k}", x, y, head_mid) for k, (x, y) in enumerate(b.pins, 1)]
    where += [(f"hole h{k}", BOARD_AT[0] + x, BOARD_AT[1] + y, BOARD_THICK + 6.0)
              for k, (x, y) in enumerate(b.holes, 1)]
    yaws = np.radians(np.arange(8) * 45.0)
    down = np.diag([1.0, -1.0, -1.0])
    T = np.zeros((len(where), len(yaws), 4, 4))
    T[..., 3, 3] = 1
    for j, a in enumerate(yaws):
        T[:, j, :3, :3] = np.array([[math.cos(a), -math.sin(a), 0], [math.sin(a), math.cos(a), 0], [0, 0, 1]]) @ down
    T[..., :3, 3] = np.array([w[1:] for w in where])[:, None, :]
    ok = reachable_ignoring_collisions(robot, T.reshape(-1, 4, 4)).reshape(len(where), len(yaws)).any(axis=1)
    if not ok.all():
        what, x, y, _ = where[int(np.argmin(ok))]
        raise SparValueError(
            f"{b.n} insertions do not fit the PUMA 762's reach: {what} at ({x:g}, {y:g}) mm cannot "
            f"be reached from above (the board is {b.size[0]:g} x {b.size[1]:g} mm, {b.cols} x {b.rows} holes)")


def board_mesh(b: Board):
    """The board's mesh (trimesh, mm, frame at its bottom face's centre): a box less its blind holes."""
    w, d = b.size
    return holed_box([-w / 2, -d / 2, 0], [w / 2, d / 2, BOARD_THICK], list(b.holes), HOLE_RADIUS, HOLE_DEPTH)


def holed_box(lo: list[float], hi: list[float], holes: list[tuple[float, float]], radius: float,
              depth: float | None):
    """A box lo..hi less round holes down from its top at (x, y): ``depth`` deep, or through (None)."""
    import trimesh

    body = trimesh.creation.box(bounds=[lo, hi])
    z1 = hi[2] + 1
    z0 = lo[2] - 1 if depth is None else hi[2] - depth
    cuts = [trimesh.creation.cylinder(radius=radius, segment=[[x, y, z0], [x, y, z1]], sections=64) for x, y in holes]
    return trimesh.boolean.difference([body, *cuts], engine="manifold")


def _n(v: float) -> str:
    """A length as the files write it: an integer without its point, else %g."""
    return _num(_r(v))


def board_files(b: Board) -> dict[str, str]:
    """The board's text files by path relative to a KB root (kb/'s layout): ``objects/<name>.yaml``
    (the holes as features h1 .. hN), ``products/<name>.yaml`` (pin k in hole k, every pin a copy
    of objects/bpin.yaml) and ``problems/<name>.yaml`` (the pins on their tips in a grid on the
    table, the board beside them; the PUMA 762 of robots/puma762.yaml). The mesh is :func:`board_mesh`."""
    name, n = b.name, b.n
    w, d = b.size
    seated = BOARD_THICK + PIN_LENGTH - HOLE_DEPTH  # the pin's frame (its head's far face) when seated
    feats = "\n".join(f"  - {{kind: hole, name: h{i}, radius: {_n(HOLE_RADIUS)}, axis: {{origin: [{_n(x)}, {_n(y)}, "
                      f"{_n(BOARD_THICK)}], direction: [0, 0, -1]}}, length: {_n(HOLE_DEPTH)}}}"
                      for i, (x, y) in enumerate(b.holes, 1))
    gen = f"spar gen board {n}" + ("" if b.rows == board_rows(n) else f" --rows {b.rows}")
    obj = (f"# Generated by `{gen}` (spar_py.app.gen): a board {_n(w)} x {_n(d)} x {_n(BOARD_THICK)} mm with\n"
           f"# {n} blind holes (radius {_n(HOLE_RADIUS)} mm, {_n(HOLE_DEPTH)} mm deep) from its top; frame at "
           "the centre of its bottom face.\n"
           f"object: {name}\nunits: {{length: mm, angle: deg}}\nmesh: meshes/{name}.stl\nfeatures:\n{feats}\n")
    parts = "\n".join(f"  pin{i}: {{model: ../objects/bpin.yaml, pose: {{xyz: [{_n(x)}, {_n(y)}, {_n(seated)}], "
                      "rpy: [180, 0, 0]}}" for i, (x, y) in enumerate(b.holes, 1))
    mates = "\n".join(f"  - {{peg: pin{i}.shaft, hole: board.h{i}}}" for i in range(1, n + 1))
    product = (f"# Generated by `{gen}` (spar_py.app.gen): the task-board kind, {n} pins in {n} holes\n"
               f"# of one board (objects/{name}.yaml); each pin's shaft root on the board's top, its tip at\n"
               "# the hole's bottom.\n"
               f"product: {name}\nunits: {{length: mm, angle: deg}}\nparts:\n"
               f"  board: {{model: ../objects/{name}.yaml}}\n{parts}\nmates:\n{mates}\n")
    bx, by = BOARD_AT
    objs = [f"  board:\n    initial: {{name: init_board, label: tr_board, "
            f"tm: [[1, 0, 0], [0, 1, 0], [0, 0, 1], [{_n(bx)}, {_n(by)}, 0]]}}"]
    unc = ["    board: {dx: [-0.05, 0.05], dy: [-0.05, 0.05], dz: [-0.05, 0.05], dtheta: [-0.02, 0.02]}"]
    for i, (x, y) in enumerate(b.pins, 1):
        objs.append(f"  pin{i}:\n    initial: {{name: init_pin{i}, label: tr_pin{i}, "
                    f"tm: [[1, 0, 0], [0, -1, 0], [0, 0, -1], [{_n(x)}, {_n(y)}, {_n(PIN_LENGTH)}]]}}")
        unc.append(f"    pin{i}: {{dx: [-0.02, 0.02], dy: [-0.02, 0.02], dz: [-0.02, 0.02], dtheta: [-0.05, 0.05]}}")
    pin_rows = -(-n // b.cols)
    problem = (f"# Generated by `{gen}` (spar_py.app.gen): the {n}-pin board (products/{name}.yaml)\n"
               f"# with the PUMA 762. The pins stand on their tips in a {b.cols} x {pin_rows} grid, the board "
               "lies beside them.\n"
               f"# Expected: a plan of {2 * n} actions (a pickup and an assemble per pin), no ordering forced by\n"
               "# the geometry (no pin's insertion passes through another).\n"
               f"problem: {name}\nunits: {{length: mm, angle: deg}}\nrobot: ../robots/{ROBOT.name}\n"
               f"product: ../products/{name}.yaml\nobjects:\n" + "\n".join(objs) + "\ngripper: open\n"
               "uncertainty:\n  manipulator: {dx: [-0.01, 0.01], dy: [-0.01, 0.01], dz: [-0.01, 0.01], "
               "dtheta: [-0.01, 0.01]}\n  objects:\n" + "\n".join(unc) + f"\ngoals:\n  - assembled({name})\n")
    return {f"objects/{name}.yaml": obj, f"products/{name}.yaml": product, f"problems/{name}.yaml": problem}


def generate_board(n: int, out_dir: str | Path, rows: int | None = None) -> Path:
    """Write an N-insertion task board into ``out_dir`` as a KB of its own; return the problem file.

    Files: ``problems/board<N>.yaml``, ``products/board<N>.yaml``, ``objects/board<N>.yaml`` and
    ``objects/meshes/board<N>.stl`` (:func:`board_files`, :func:`board_mesh`), and copies of
    ``objects/bpin.yaml`` and ``robots/puma762.yaml`` so the directory stands alone. Existing files
    of those names are overwritten. Raises SparValueError for an N the cell cannot hold
    (:func:`board_layout`)."""
    b = board_layout(n, rows)
    out = Path(out_dir)
    for rel, text in {**board_files(b), f"objects/{PIN_MODEL.name}": PIN_MODEL.read_text(encoding="utf-8"),
                      f"robots/{ROBOT.name}": ROBOT.read_text(encoding="utf-8")}.items():
        (out / rel).parent.mkdir(parents=True, exist_ok=True)
        (out / rel).write_text(text, encoding="utf-8")
    (out / "objects" / "meshes").mkdir(parents=True, exist_ok=True)
    board_mesh(b).export(out / "objects" / "meshes" / f"{b.name}.stl", file_type="stl")
    return out / "problems" / f"{b.name}.yaml"


def main(argv: list[str]) -> int:
    """``spar gen assembly --parts N [-o DIR]`` or ``spar gen board N [--rows R] [-o DIR]``: write
    the problem, print its path.

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
    try:
        args = p.parse_args(argv)
    except SystemExit as e:  # argparse has printed its message
        return 0 if e.code == 0 else 2
    try:
        if args.kind == "board":
            path = generate_board(args.n, args.out or f"board_{args.n}", args.rows)
        else:
            path = generate_assembly(args.parts, args.out or f"assembly_{args.parts}", args.blocks)
    except SparValueError as e:
        print(f"spar: gen {args.kind}: {e}", file=sys.stderr)
        return 2
    print(path)
    return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main(sys.argv[1:]))


# ---------------------------------------------------------------------- layout (issue 34)

#: The uncertainty bounds a generated layout problem gives (cell unit mm, rad): as plate_pins'.
LAYOUT_MANIPULATOR = "{dx: [-0.01, 0.01], dy: [-0.01, 0.01], dz: [-0.01, 0.01], dtheta: [-0.01, 0.01]}"
LAYOUT_PART = "{dx: [-0.05, 0.05], dy: [-0.05, 0.05], dz: [-0.05, 0.05], dtheta: [-0.05, 0.05]}"


def layout_problem_text(product_path: str | Path, robot_path: str | Path, out_path: str | Path) -> str:
    """``spar gen layout``: the problem of the product's parts laid out on the table for the
    robot (world.product.layout), in mm and deg, its ``robot:`` and ``product:`` relative to
    ``out_path``'s folder. SparValueError (one line) when they do not fit within reach."""
    import os

    from spar_py.kb.products import load_product
    from spar_py.world.product import layout_product

    product_path, robot_path = Path(product_path), Path(robot_path)
    robot = load_robot(robot_path, unit="mm")
    arm = float(np.abs(robot.dh[:, 1]).sum() + np.abs(robot.dh[:, 2]).sum() + np.linalg.norm(robot.tool[:3, 3]))
    product = load_product(product_path, "mm", opening=robot.finger_separation, gripper=robot.gripper, reach=arm)
    lay = layout_product(product, robot, "mm")
    here = Path(out_path).resolve().parent
    rel = {k: Path(os.path.relpath(Path(v).resolve(), here)).as_posix()
           for k, v in (("robot", robot_path), ("product", product_path))}
    name = re.sub(r"\W", "_", Path(out_path).stem)
    lines = [f"# Generated by `spar gen layout {product_path.name} --robot {robot_path.name}` (spar_py.app.gen):",
             f"# the parts of product {product.name} laid out on the table for the {robot.name}, each in",
             f"# its most probable stable pose, the base ({product.base}) where the product is built",
             "# (world/product/layout.py; a problem's `layout: auto` places them alike at load).",
             f"problem: {name}", "units: {length: mm, angle: deg}",
             f"robot: {rel['robot']}", f"product: {rel['product']}", "objects:"]
    for pl in lay.placements:
        R, d = pl.T[:3, :3].T, pl.T[:3, 3]  # tm rows: the images of the frame's axes, then d
        rows = ", ".join("[" + ", ".join(_fig(float(v)) for v in r) + "]" for r in [*R, d])
        lines += [f"  {pl.part}:", f"    # {pl.pose}",
                  f"    initial: {{name: init_{pl.part}, label: tr_{pl.part}, tm: [{rows}]}}"]
    lines += ["gripper: open", "uncertainty:", f"  manipulator: {LAYOUT_MANIPULATOR}", "  objects:"]
    lines += [f"    {pl.part}: {LAYOUT_PART}" for pl in lay.placements]
    lines += ["goals:", f"  - assembled({product.name})", ""]
    return "\n".join(lines)


def _fig(v: float) -> str:
    """A layout figure as written: rounded to 1e-9 (a rotation's entries stay orthonormal to
    the loader's tolerance), an integer without its point, no -0."""
    v = round(v, 9) + 0.0
    return str(int(v)) if v.is_integer() else repr(v)
