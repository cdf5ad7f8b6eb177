"""The layout of the generated N-pegs-into-N-blocks problems (assembly.py): where the pair
cells go and which of them, with which grasps, the PUMA 762 can work.

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
"""
from __future__ import annotations

import math
import tempfile
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from spar_py.app.gen.models import BLOCK_MODEL, PEG_MODEL, ROBOT, robot_text, scaled_model
from spar_py.core.errors import SparValueError
from spar_py.core.memo import Memo
from spar_py.core.units import from_mm
from spar_py.kb import load_object, load_robot
from spar_py.world.collision import DEFAULT_MARGIN_MM, CollisionScene, solid_bodies
from spar_py.world.reach import footprint, reachable_ignoring_collisions, wrist_above_table

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
# T_a of the paper's cell (in): the peg upside down in the hole, its tip at the bottom.
TA = [[1, 0, 0], [0, -1, 0], [0, 0, -1], [0, 0, 2.5]]


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
            blk_T = np.stack([_pose_T(rotz(c.yaw) @ sp_blk.R, *c.block, sp_blk.height) for c in cells])
            up_T = np.stack([_pose_T(sp_up.R, *c.block, sp_up.height) for c in cells])
            cells = [c for c, v in zip(cells, _grasp_ok(robot, [g.T for g in free], blk_T, up_T)) if v]
        cells = [replace(c, pose=sp_blk.label) for c in cells]
    else:  # the dense lattice, the blocks never moved
        cells = [replace(c, pose=BLOCK_UP_POSE) for c in peg_reach(lattice(*LAYOUT[blocks][:2]))]
    usable = _usable(peg, block, robot, cells, free, mate, sp_blk, list(range(len(cells))), T_a)
    good = [replace(c, block_grasps=b, peg_grasps=p) for c, (b, p) in zip(cells, usable)
            if p and (b or c.pose == BLOCK_UP_POSE)]
    return sorted(good, key=lambda c: (round(c.distance, 9), math.atan2(c.block[1] - base[1], c.block[0] - base[0])))


def rotz(deg: int) -> np.ndarray:
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
            f"block@{k}": _pose_T(rotz(c.yaw) @ sp_blk.R, *c.block, sp_blk.height), f"peg@a{k}": up @ T_a}


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


def cells_for(n_parts: int, blocks: str | None) -> list[Slot]:
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
    return [(c.peg, c.block) for c in cells_for(n_parts, blocks)]


def _check_n(n_parts: int) -> None:
    if isinstance(n_parts, bool) or not isinstance(n_parts, int) or not 1 <= n_parts <= MAX_PARTS:
        raise SparValueError(f"n_parts must be an integer from 1 to {MAX_PARTS}, not {n_parts!r}")
