"""Issue 35, item 3: a close-up of each assemble step in the cell pictures (the peg, the hole
and the insertion check's tolerance), and ``--animate`` framing the work without the travel
home. Speed is measured, not asserted (see the commit messages)."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from spar_py.planning.planner import Outcome, Plan

from paths import ROOT

PROBLEMS = ROOT / "kb" / "problems"


def _typed(doc: dict) -> Plan:
    """The typed Plan of a plan JSON document, or of a test's partial one (the pictures take a Plan and
    read its problem, outcome, partial plan and instance)."""
    return Plan(problem=doc.get("problem", ""), outcome=Outcome(doc["outcome"]), partial=doc.get("partial"),
                instance=doc.get("instance"))


@pytest.fixture(scope="module")
def paper() -> tuple:
    """The paper's cell planned with motions, and its plan JSON."""
    from spar_py import Planner

    pl = Planner(motion=True)
    cell = pl.load_problem(PROBLEMS / "peg_in_block.yaml")
    return cell, pl.plan(PROBLEMS / "peg_in_block.yaml").to_json()


def _blend(colour: str, alpha: float) -> np.ndarray:
    """RGB (0..1) of ``colour`` painted with ``alpha`` over white."""
    from matplotlib.colors import to_rgb

    return alpha * np.array(to_rgb(colour)) + (1 - alpha) * np.ones(3)


def _share(img: np.ndarray, rgb: np.ndarray, tol: float = 0.08) -> float:
    """The share of ``img``'s pixels within ``tol`` of ``rgb`` in every channel (0..1 scale)."""
    return float((np.abs(img[..., :3] - rgb).max(axis=2) < tol).mean())


def test_each_assemble_step_has_a_closeup_showing_the_parts(paper, tmp_path: Path) -> None:
    import matplotlib.image as mpimg

    from spar_py.pictures import write_pictures
    from spar_py.pictures.cell import OBJECT_COLOURS

    cell, doc = paper
    paths = write_pictures(cell, _typed(doc), tmp_path)
    steps = doc["instance"]["steps"]
    assembles = [k for k, st in enumerate(steps, start=1) if st.get("name") == "assemble"]
    assert assembles
    names = [p.name for p in paths]
    for k in assembles:
        closeup = f"cell_{k:02d}_assemble_closeup.png"
        assert closeup in names, names
        assert names.index(closeup) == names.index(f"cell_{k:02d}_assemble.png") + 1  # listed after its step
        img = mpimg.imread(tmp_path / closeup)
        for k_obj, obj in enumerate(cell.objects):  # both parts drawn see-through (alpha 0.5)
            share = _share(img, _blend(OBJECT_COLOURS[k_obj % len(OBJECT_COLOURS)], 0.5))
            assert share > 0.01, (obj, share)
    assert sum(n.endswith("_closeup.png") for n in names) == len(assembles)


def test_the_closeup_draws_the_tolerance_of_the_insertion_check(paper) -> None:
    from spar_py.pictures.cell import assemble_tolerance
    from spar_py.pictures.scene import scenes

    cell, doc = paper
    sc = scenes(cell, _typed(doc))
    inst = doc["instance"]
    k = next(k for k, st in enumerate(inst["steps"], start=1) if st.get("name") == "assemble")
    tol = assemble_tolerance(cell, _typed(doc), sc[k])
    check = next(c for c in inst["constraints"] + inst.get("verifications", [])
                 if c["action"] == inst["steps"][k - 1]["id"] and c["constraint"] == "centres")
    assert tol is not None and tol.hole == "block"
    assert tol.tolerance == pytest.approx(np.sqrt(check["threshold"]))
    assert tol.bound == pytest.approx(np.sqrt(check["bound"]))
    assert tol.satisfied and tol.bound < tol.tolerance
    assert all(assemble_tolerance(cell, _typed(doc), s) is None for s in sc if s.index != k)


def test_the_animation_leaves_out_the_trip_home_and_frames_the_work(paper, tmp_path: Path) -> None:
    from PIL import Image

    from spar_py.pictures.animate import MAX_FRAMES, frames_of, write_animation

    cell, doc = paper
    steps = doc["instance"]["steps"]
    def count(wp: object) -> int:
        return len(np.asarray(wp or [], float).reshape(-1, 6))

    work = sum(count(st.get(key)) for st in steps for key in ("path", "approach", "retreat"))
    home = count(doc["instance"]["motion"]["home_path"])
    assert home > 0  # there is a trip home to leave out
    frames = frames_of(cell, _typed(doc), max_frames=work + home)
    assert len(frames) == work  # every waypoint of the steps' motions, none of the home path
    assert not any("home" in f.title for f in frames)
    assert np.allclose(frames[-1].q, np.radians(steps[-1]["retreat"][-1] if steps[-1].get("retreat")
                                                else steps[-1]["path"][-1]))
    gif = write_animation(cell, _typed(doc), tmp_path / "a.gif")
    with Image.open(gif) as im:
        # Pillow merges a frame identical to the one before it (the arm still between two samples)
        assert 1 < im.n_frames <= len(frames_of(cell, _typed(doc))) == min(MAX_FRAMES, work)
    _check_framing(cell, gif)


def _check_framing(cell, gif: Path) -> None:
    """The first frame shows the parts large (solids at alpha 0.92: at least 6 % of the 480 x 480
    px, some 13,800) and whole (none of their pixels on the frame's edge)."""
    from PIL import Image

    from spar_py.pictures.cell import OBJECT_COLOURS

    with Image.open(gif) as im:
        im.seek(0)
        first = np.asarray(im.convert("RGB"), float) / 255
    masks = [np.abs(first - _blend(OBJECT_COLOURS[k], 0.92)).max(axis=2) < 0.12 for k in range(len(cell.objects))]
    parts = sum(float(m.mean()) for m in masks)
    assert parts > 0.06, parts  # measured: 11 % (the paper's cell), 21 % (UR5e)
    for m in masks:
        assert m.any() and not (m[0].any() or m[-1].any() or m[:, 0].any() or m[:, -1].any())


def test_the_animation_frames_a_ur5e_cells_work(tmp_path: Path) -> None:
    from spar_py import Planner
    from spar_py.pictures.animate import work_extent, write_animation

    pl = Planner(motion=True)
    cell = pl.load_problem(PROBLEMS / "ur5e_peg_in_block.yaml")
    doc = pl.plan(cell).to_json()
    _check_framing(cell, write_animation(cell, _typed(doc), tmp_path / "u.gif"))
    # the axes' box clips, and holds every part at every step and the tool at every step's end-point
    fr = work_extent(cell, _typed(doc))
    for st in doc["instance"]["steps"]:
        for T in st["poses"].values():
            assert np.all(fr.lo <= np.asarray(T)[:3, 3]) and np.all(np.asarray(T)[:3, 3] <= fr.hi)
        if st.get("tool_pose"):
            p = np.asarray(st["tool_pose"])[:3, 3]
            assert np.all(fr.lo <= p) and np.all(p <= fr.hi)
