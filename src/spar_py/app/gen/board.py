"""Task boards (issue 33): :func:`generate_board` writes N pins into an N-hole board, the
task-board kind (the NIST assembly task board 1 has twenty insertions on one board), as
product, object, mesh and problem files; ``spar gen board N [--rows R]``.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from spar_py.app.gen.cells import PEDESTAL_RADIUS
from spar_py.app.gen.models import KB_DIR, ROBOT, num
from spar_py.core.errors import SparValueError
from spar_py.kb import load_robot
from spar_py.world.reach import reachable_ignoring_collisions

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
    return num(_r(v))


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
