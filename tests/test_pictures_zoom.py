"""Issue 35, item 3: the cell pictures zoom to the work (the paper's cell's parts at least 60 px
across in the whole-cell view), draw the table at its ``table:`` extent, and the same picture
is the same bytes (``make demo`` leaves a clean checkout)."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from spar_py.kb import load_problem

from paths import ROOT

PROBLEMS = ROOT / "kb" / "problems"
#: The 3-D (whole-cell) panel of a 1200 x 720 px cell picture: rows, columns (draw_figure's axes
#: at (0, 0.09, 0.6, 0.82) of the figure, the legend below it left out).
PANEL_3D = np.s_[65:650, :720]


@pytest.fixture(scope="module")
def paper() -> tuple:
    from spar_py.planning.planner import Planner

    cell = load_problem(PROBLEMS / "peg_in_block.yaml")
    return cell, Planner().plan(cell)


def _extent_px(img: np.ndarray, colour: str) -> tuple[int, int]:
    """(width, height) in px of the pixels within 0.15 of ``colour`` (each RGB channel)."""
    from matplotlib.colors import to_rgb

    m = np.abs(img[..., :3] - np.array(to_rgb(colour))).max(axis=2) < 0.15
    ys, xs = np.nonzero(m)
    assert len(xs), f"no pixel of {colour}"
    return int(xs.max() - xs.min() + 1), int(ys.max() - ys.min() + 1)


def test_the_paper_cells_parts_are_at_least_60_px_across_in_the_whole_cell_view(paper, tmp_path: Path) -> None:
    import matplotlib.image as mpimg

    from spar_py.pictures.cell import _colour, cell_figure, extent
    from spar_py.pictures.scene import scenes

    cell, plan = paper
    sc = scenes(cell, plan)
    fr = extent(cell, sc)
    img = mpimg.imread(cell_figure(cell, sc[0], fr, tmp_path / "initial.png"))[PANEL_3D]
    for part in ("peg", "block"):
        w, h = _extent_px(img, _colour(cell, part))
        assert w >= 60 and h >= 60, (part, w, h)


def test_the_view_is_the_work_not_the_whole_arm(paper) -> None:
    from spar_py.pictures.cell import part_points, extent
    from spar_py.pictures.scene import scenes

    cell, plan = paper
    sc = scenes(cell, plan)
    fr = extent(cell, sc)
    parts = np.vstack(part_points(cell, sc))
    assert np.all(fr.lo <= parts.min(axis=0)) and np.all(parts.max(axis=0) <= fr.hi)
    # the robot's base (the PUMA's waist at the origin) is outside: the view is the parts' box, padded
    assert not np.all((fr.lo[:2] <= 0) & (0 <= fr.hi[:2]))
    assert float(max(fr.hi[:2] - fr.lo[:2])) < 2 * float(max(parts.max(axis=0)[:2] - parts.min(axis=0)[:2]))


def test_the_table_is_drawn_at_its_extent() -> None:
    from spar_py.pictures.cell import Extent, extent, table_extent
    from spar_py.pictures.scene import Scene, initial_poses

    cell = load_problem(PROBLEMS / "ur5e_peg_in_block.yaml")
    assert cell.table == (-12.0, 30.0, -20.0, 6.5)
    fr = extent(cell, [Scene(0, "initial state", "", initial_poses(cell))])
    x0, x1, y0, y1 = fr.table
    # the table's +y edge (6.5 in) is inside the view: drawn there, not past it
    assert fr.hi[1] > 6.5 and y1 == 6.5
    assert x0 == max(-12.0, fr.lo[0]) and x1 == min(30.0, fr.hi[0]) and y0 == max(-20.0, fr.lo[1])
    # without table: the table is the whole plane: the whole view
    paper = load_problem(PROBLEMS / "peg_in_block.yaml")
    assert paper.table is None
    lo, hi = np.array([0.0, -5.0, 0.0]), np.array([10.0, 5.0, 3.0])
    assert table_extent(paper, lo, hi) == (0.0, 10.0, -5.0, 5.0)
    assert isinstance(fr, Extent)


def test_the_same_picture_is_the_same_bytes(paper, tmp_path: Path) -> None:
    from spar_py.pictures.cell import cell_figure, extent
    from spar_py.pictures.scene import scenes

    cell, plan = paper
    sc = scenes(cell, plan)
    fr = extent(cell, sc)
    a = cell_figure(cell, sc[-1], fr, tmp_path / "a.png").read_bytes()
    b = cell_figure(cell, sc[-1], fr, tmp_path / "b.png").read_bytes()
    assert a == b
    assert b"Matplotlib" not in a  # no version stamp: another matplotlib draws the same bytes


def test_painting_order_does_not_hang_on_the_last_bits_of_a_depth() -> None:
    from spar_py.pictures.cell import _depth_key

    assert _depth_key(8.0, 3.0) == _depth_key(8.0 + 1e-13, 3.0) == _depth_key(8.0 - 1e-13, 3.0)
    assert _depth_key(8.0, 3.0) < _depth_key(8.01, 3.0)


def test_animate_says_the_file_it_wrote(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from spar_py.app import cli

    gif = tmp_path / "wall.gif"
    with pytest.raises(SystemExit) as e:
        cli.main(["plan", str(PROBLEMS / "wall_detour.yaml"), "--animate", str(gif)])
    assert e.value.code == 0 and gif.is_file()
    assert f"spar: wrote the animation to {gif}\n" in capsys.readouterr().err
