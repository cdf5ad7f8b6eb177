"""The two-shaft gearbox of issue 43 as meshes: ``python -m spar_py.app.gen gearbox OUTDIR``
writes the mesh-only product (one binary STL per part, in the product frame, mates derived
at load), its problem for the UR5e, and the housing's and cover's meshes in their own frames
that the declared product's models (kb/objects/gearbox_*.yaml) use.

The geometry (mm; product frame: the housing's bottom face centred at the origin, z up), the
same as the declared product kb/products/gearbox.yaml gives with primitives and features:

- housing: a block 120 x 80 x 40 with two blind bores (radius 6.02, 18 deep) at x = -20 and
  20 (40 apart) and four blind pin holes ph1..ph4 (radius 3.1, 10 deep) at (+-50, +-30);
- shaft_a, shaft_b: stepped shafts, bottom to top a journal (radius 6, 16 long: 0.02 in its
  bore, its tip 2 above the bore's bottom), a shoulder (radius 10, 4 thick) that seats on the
  housing's top, a gear seat (radius 7.5, 14 long) and an upper end (radius 5, 7 long);
- gear_a, gear_b: discs of radius 18, 12 thick, bored through (radius 8: 0.5 on the gear seat),
  resting on the shoulders (4 apart between the two gears);
- cover: a plate 120 x 80 x 8 on four corner columns 20 x 20 x 20 standing on the housing's top
  (the plate 4 above the gears), two blind bores (radius 5.2, 6 deep) from its underside over
  the shafts' upper ends (0.2; the shafts' tops 1 short of the bores' bottoms) and four through
  holes ph1..ph4 (radius 3.1) down the columns;
- pin_1..pin_4: plain dowel pins, radius 3, 50 long, standing on the pin holes' bottoms, through
  the cover's corners (0.1 in both), 12 proud of the cover's top.

Every cylinder is trimesh's 64-sided prism about its part's z axis (as the loader meshes a
``shape:`` cylinder, world/parts/mesh.py), unrotated, so concentric fits nest polygon in polygon.
"""
from __future__ import annotations

import shutil
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from spar_py.app.gen.models import KB_DIR

#: Segments of every round surface (the loader's CYL_SECTIONS for ``shape:`` cylinders).
SECTIONS = 64

#: Housing (mm): its extent, the shafts' bores and the pin holes (all from its top, blind).
HOUSING_SIZE = (120.0, 80.0, 40.0)
SHAFT_X = 20.0                  # the shafts' axes at x = -SHAFT_X and +SHAFT_X, y = 0
BORE_RADIUS, BORE_DEPTH = 6.02, 18.0
PIN_XY = ((-50.0, -30.0), (50.0, -30.0), (50.0, 30.0), (-50.0, 30.0))   # ph1..ph4
PIN_HOLE_RADIUS, PIN_HOLE_DEPTH = 3.1, 10.0

#: Shaft (mm, its frame at the journal's tip, z up): (radius, z0, z1) of each step.
JOURNAL = (6.0, 0.0, 16.0)
SHOULDER = (10.0, 16.0, 20.0)
GEAR_SEAT = (7.5, 20.0, 34.0)
UPPER = (5.0, 34.0, 41.0)

#: Gear (mm, its frame at its bottom face's centre): outer radius, bore radius, thickness.
GEAR_RADIUS, GEAR_BORE, GEAR_THICK = 18.0, 8.0, 12.0

#: Cover (mm, its frame at the columns' bottom plane, centred): the columns' side and height,
#: the plate's thickness, the shaft bores' radius and depth up from the plate's underside.
COLUMN_SIDE, COLUMN_HEIGHT, PLATE_THICK = 20.0, 20.0, 8.0
COVER_BORE_RADIUS, COVER_BORE_DEPTH = 5.2, 6.0

#: Dowel pin (mm, its frame at its bottom end's centre, z up).
PIN_RADIUS, PIN_LENGTH = 3.0, 50.0

#: Where each part's frame sits in the product frame (mm; no part is rotated).
TOP = HOUSING_SIZE[2]
SHAFT_Z = TOP - JOURNAL[2]            # the journal below the housing's top, shoulder on it
GEAR_Z = SHAFT_Z + SHOULDER[2]        # on the shoulder
COVER_Z = TOP
PIN_Z = TOP - PIN_HOLE_DEPTH          # on the pin hole's bottom

#: The problem's uncertainty bounds (mm, deg): fabrica_beam's.
MANIPULATOR_BOUNDS = "{dx: [-0.01, 0.01], dy: [-0.01, 0.01], dz: [-0.01, 0.01], dtheta: [-0.01, 0.01]}"
PART_BOUNDS = "{dx: [-0.05, 0.05], dy: [-0.05, 0.05], dz: [-0.05, 0.05], dtheta: [-0.05, 0.05]}"
ROBOT_FILE = "ur5e.yaml"


@dataclass(frozen=True)
class GearboxPart:
    """A part of the gearbox: its ``name`` in both products, the ``model`` it shares with the
    declared product (kb/objects/gearbox_<model>.yaml) and ``xyz``, its frame's origin in the
    product frame (mm; the part frame's axes are the product's)."""

    name: str
    model: str
    xyz: tuple[float, float, float]

    def pose(self) -> np.ndarray:
        """The part's frame in the product frame, 4x4 (mm)."""
        T = np.eye(4)
        T[:3, 3] = self.xyz
        return T


PARTS = (
    GearboxPart("housing", "housing", (0.0, 0.0, 0.0)),
    GearboxPart("shaft_a", "shaft", (-SHAFT_X, 0.0, SHAFT_Z)),
    GearboxPart("shaft_b", "shaft", (SHAFT_X, 0.0, SHAFT_Z)),
    GearboxPart("gear_a", "gear", (-SHAFT_X, 0.0, GEAR_Z)),
    GearboxPart("gear_b", "gear", (SHAFT_X, 0.0, GEAR_Z)),
    GearboxPart("cover", "cover", (0.0, 0.0, COVER_Z)),
    *(GearboxPart(f"pin_{k}", "pin", (x, y, PIN_Z)) for k, (x, y) in enumerate(PIN_XY, 1)),
)


def _cylinder(radius: float, z0: float, z1: float, x: float = 0.0, y: float = 0.0):
    """trimesh's SECTIONS-sided cylinder of ``radius`` about the vertical line (x, y), z0 to z1."""
    import trimesh

    return trimesh.creation.cylinder(radius=radius, segment=[[x, y, z0], [x, y, z1]], sections=SECTIONS)


def _solid(add: list, cut: list):
    """The union of ``add`` less the union of ``cut`` (manifold3d), a closed mesh."""
    import trimesh

    body = add[0] if len(add) == 1 else trimesh.boolean.union(add, engine="manifold")
    if cut:
        body = trimesh.boolean.difference([body, *cut], engine="manifold")
    return body


def housing_mesh():
    """The housing in its frame (= the product frame), mm: the block less its six blind holes; the
    cutting cylinders reach 1 mm above the top so no face is coplanar with it."""
    import trimesh

    w, d, h = HOUSING_SIZE
    block = trimesh.creation.box(bounds=[[-w / 2, -d / 2, 0.0], [w / 2, d / 2, h]])
    cuts = [_cylinder(BORE_RADIUS, h - BORE_DEPTH, h + 1, x, 0.0) for x in (-SHAFT_X, SHAFT_X)]
    cuts += [_cylinder(PIN_HOLE_RADIUS, h - PIN_HOLE_DEPTH, h + 1, x, y) for x, y in PIN_XY]
    return _solid([block], cuts)


def shaft_mesh():
    """A stepped shaft in its frame (the journal's tip at the origin, z up), mm."""
    return _solid([_cylinder(*step) for step in (JOURNAL, SHOULDER, GEAR_SEAT, UPPER)], [])


def gear_mesh():
    """A gear blank in its frame (its bottom face's centre, z up), mm: a disc less its bore."""
    return _solid([_cylinder(GEAR_RADIUS, 0.0, GEAR_THICK)], [_cylinder(GEAR_BORE, 0.0, GEAR_THICK)])


def cover_mesh():
    """The cover in its frame (the columns' bottom plane, centred), mm: the plate on four corner
    columns, less the two blind shaft bores from the plate's underside and the four through pin
    holes (the cutting cylinders reach 1 mm past the faces they open)."""
    import trimesh

    w, d, _ = HOUSING_SIZE
    top = COLUMN_HEIGHT + PLATE_THICK
    plate = trimesh.creation.box(bounds=[[-w / 2, -d / 2, COLUMN_HEIGHT], [w / 2, d / 2, top]])
    columns = []
    for sx in (-1.0, 1.0):
        for sy in (-1.0, 1.0):
            x0, x1 = sorted((sx * w / 2, sx * (w / 2 - COLUMN_SIDE)))
            y0, y1 = sorted((sy * d / 2, sy * (d / 2 - COLUMN_SIDE)))
            columns.append(trimesh.creation.box(bounds=[[x0, y0, 0.0], [x1, y1, COLUMN_HEIGHT]]))
    cuts = [_cylinder(COVER_BORE_RADIUS, COLUMN_HEIGHT - 1, COLUMN_HEIGHT + COVER_BORE_DEPTH, x, 0.0)
            for x in (-SHAFT_X, SHAFT_X)]
    cuts += [_cylinder(PIN_HOLE_RADIUS, -1.0, top + 1, x, y) for x, y in PIN_XY]
    return _solid([plate, *columns], cuts)


def pin_mesh():
    """A dowel pin in its frame (its bottom end's centre, z up), mm."""
    return _cylinder(PIN_RADIUS, 0.0, PIN_LENGTH)


#: Each model's mesh in its own frame.
MODEL_MESHES = {"housing": housing_mesh, "shaft": shaft_mesh, "gear": gear_mesh, "cover": cover_mesh, "pin": pin_mesh}


def gearbox_meshes() -> dict:
    """Each part's mesh in the product frame (mm), by part name, in :data:`PARTS`' order."""
    made = {m: f() for m, f in MODEL_MESHES.items()}
    out = {}
    for p in PARTS:
        m = made[p.model].copy()
        m.apply_translation(p.xyz)
        out[p.name] = m
    return out


def gearbox_texts() -> dict[str, str]:
    """The mesh product's and its problem's text by path relative to a KB root:
    ``products/gearbox_mesh.yaml`` (mesh parts only, the housing the base) and
    ``problems/gearbox_mesh.yaml`` (the UR5e, ``layout: auto``)."""
    parts = "\n".join(f"  {p.name}: {{mesh: gearbox_mesh/{p.name}.stl}}" for p in PARTS)
    product = (
        "# Generated by `python -m spar_py.app.gen gearbox kb` (spar_py.app.gen.gearbox): the two-shaft\n"
        "# gearbox of issue 43 as meshes only, each part's STL in its assembled pose (product frame, mm),\n"
        "# the same geometry as the declared kb/products/gearbox.yaml. Mates, seats and the order are\n"
        "# derived (docs/deriving.md); expected: 14 peg-hole mates (2 shaft-housing 0.02 mm, 2 gear-shaft\n"
        "# 0.5 mm, 2 shaft-cover 0.2 mm, 4 pin-cover and 4 pin-housing 0.1 mm; the housing's holes and the\n"
        "# cover's shaft bores blind, the cover's pin holes through) and the cover seated on the housing.\n"
        "product: gearbox_mesh\nunits: {length: mm, angle: deg}\nbase: housing\n"
        f"parts:\n{parts}\n")
    unc = "\n".join(f"    {p.name}: {PART_BOUNDS}" for p in PARTS)
    problem = (
        "# Generated by `python -m spar_py.app.gen gearbox kb` (spar_py.app.gen.gearbox): the mesh-only\n"
        "# gearbox (products/gearbox_mesh.yaml) with the UR5e, laid out at load (`layout: auto`: the\n"
        "# housing where the product is built, the other parts in their most probable stable poses).\n"
        "# Expected (issue 43): a plan of the 10 insertions in an order the geometry allows (the shafts\n"
        "# before their gears, both before the cover), every mate credited to the step that makes it.\n"
        f"problem: gearbox_mesh\nunits: {{length: mm, angle: deg}}\nrobot: ../robots/{ROBOT_FILE}\n"
        "product: ../products/gearbox_mesh.yaml\nlayout: auto\ngripper: open\n"
        f"uncertainty:\n  manipulator: {MANIPULATOR_BOUNDS}\n  objects:\n{unc}\n"
        "goals:\n  - assembled(gearbox_mesh)\n")
    return {"products/gearbox_mesh.yaml": product, "problems/gearbox_mesh.yaml": problem}


def generate_gearbox(out_dir: str | Path) -> Path:
    """Write the gearbox into ``out_dir`` (a KB root, e.g. kb/); return the mesh problem's path.

    Files: ``products/gearbox_mesh/<part>.stl`` (binary STL, product frame), ``products/
    gearbox_mesh.yaml``, ``problems/gearbox_mesh.yaml`` (:func:`gearbox_texts`), the declared
    models' meshes ``objects/meshes/gearbox_housing.stl`` and ``gearbox_cover.stl`` (their own
    frames), and ``robots/ur5e.yaml`` copied from kb/ unless ``out_dir`` has it already, so the
    directory stands alone. Existing files of those names are overwritten."""
    out = Path(out_dir)
    meshes = gearbox_meshes()
    (out / "products" / "gearbox_mesh").mkdir(parents=True, exist_ok=True)
    for name, m in meshes.items():
        m.export(out / "products" / "gearbox_mesh" / f"{name}.stl", file_type="stl")
    (out / "objects" / "meshes").mkdir(parents=True, exist_ok=True)
    for model in ("housing", "cover"):
        MODEL_MESHES[model]().export(out / "objects" / "meshes" / f"gearbox_{model}.stl", file_type="stl")
    for rel, text in gearbox_texts().items():
        (out / rel).parent.mkdir(parents=True, exist_ok=True)
        (out / rel).write_text(text, encoding="utf-8")
    robot = out / "robots" / ROBOT_FILE
    if not robot.exists():
        robot.parent.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(KB_DIR / "robots" / ROBOT_FILE, robot)
    return out / "problems" / "gearbox_mesh.yaml"

