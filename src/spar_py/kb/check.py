"""``spar kb check`` and ``spar kb derive``: one KB file of any kind validated, or an object
model written out with every entry explicit.
"""
from __future__ import annotations

import os
from pathlib import Path
from typing import Any, Iterable

import yaml

from spar_py.core.errors import KBError
from spar_py.core.units import from_mm
from spar_py.kb.node import num
from spar_py.kb.objects import DEFAULT_OPENING_MM, check_against_shape, load_object, mesh_note
from spar_py.kb.problem import load_problem
from spar_py.kb.products import load_product
from spar_py.kb.reader import MAX_INPUT_BYTES, parse_yaml
from spar_py.kb.robots import load_robot
from spar_py.kb.schema import describe, file_kind, read_kb, read_yaml
from spar_py.kb.values import units_of

__all__ = ["check_file", "derive_text", "iter_kb_files"]


def check_file(path: str | Path, max_bytes: int = MAX_INPUT_BYTES) -> str:
    """Validate one KB file of any kind (problem, object, robot, product); return a one-line summary,
    followed by a line for each mesh that loading repaired (kb.objects.mesh_note)."""
    root = read_yaml(path, max_bytes)
    kind = file_kind(root)
    if kind is None:
        raise KBError(str(path), "", "a problem, object, robot or product file", describe(root.value))
    if kind.name == "product":
        pr = load_product(path, units_of(root)[0], max_bytes)
        notes = [n for n in dict.fromkeys(mesh_note(p.model) for p in pr.parts.values()) if n]
        return "\n".join([f"{path}: ok (product {pr.name}: {len(pr.parts)} parts, "
                          f"{len(pr.mates) + len(pr.seats)} mates, {len(pr.precedence)} orderings by geometry)",
                          *_offset_notes(path, pr, units_of(root)[0]), *notes])
    if kind.name == "problem":
        cell = load_problem(path, max_bytes)
        for oname, model in cell.objects.items():
            mfile = next((f for f in cell.files if Path(f).suffix == ".yaml" and _object_name(f) == oname), None)
            if mfile is not None:
                check_against_shape(mfile, read_yaml(mfile, max_bytes), model, cell.unit, cell.finger_separation,
                                    cell.robot.gripper)
        notes = [n for n in dict.fromkeys(mesh_note(m) for m in cell.objects.values()) if n]
        return "\n".join([f"{path}: ok (problem {cell.name}: {len(cell.objects)} objects, {len(cell.goals)} goals)",
                          *notes])
    if kind.name == "object":
        o = load_object(path, units_of(root)[0], max_bytes)
        check_against_shape(path, root, o, units_of(root)[0])
        note = mesh_note(o)
        return (f"{path}: ok (object {o.name}: {len(o.faces)} faces, {len(o.poses)} stable poses, "
                f"{len(o.grasps)} grasps)") + (f"\n{note}" if note else "")
    r = load_robot(path, max_bytes=max_bytes)
    return f"{path}: ok (robot {r.name}, {r.solver_name} IK)"


def _offset_notes(path: str | Path, product: Any, unit: str) -> list[str]:
    """A line per mate whose peg stands off its hole's axis at the product poses (beyond
    world.product.AXIS_TOL_MM; the load refuses one not within the clearance): by how much, and
    the margin R_hole - R_peg that leaves to the wall (``unit``: the product file's)."""
    from spar_py.world.product import AXIS_TOL_MM, axis_offset, feature_axis

    out = []
    for m in product.mates:
        peg, hole = product.parts[m.peg], product.parts[m.hole]
        fp, fh = peg.model.feature_named(m.peg_feature), hole.model.feature_named(m.hole_feature)
        if fp.geometry is None or fh.geometry is None:
            continue
        a, b = feature_axis(peg.pose, fp), feature_axis(hole.pose, fh)
        off = axis_offset(a, b)
        if off > from_mm(unit, AXIS_TOL_MM):
            margin = b.radius - a.radius
            out.append(f"{path}: mate {m.name}: the peg's axis {num(off)} {unit} off the hole's: its margin "
                       f"R_hole - R_peg = {num(margin)} {unit} is {num(margin - off)} {unit} to the wall")
    return out


def derive_text(path: str | Path, max_bytes: int = MAX_INPUT_BYTES, robot: str | Path | None = None,
                out_dir: str | Path | None = None) -> str:
    """``spar kb derive``: the object model at ``path`` as a full explicit model file (YAML
    text): its own keys as written, then every face, stable pose and grasp, derived ones
    included, in the file's own units (grasps for ``robot``'s gripper, or DEFAULT_OPENING_MM).
    A ``mesh:`` path is rewritten relative to ``out_dir`` (where the text will be written)."""
    root = read_kb(path, "object", max_bytes)
    unit, _, rad_per = units_of(root)
    arm = load_robot(robot, unit=unit, max_bytes=max_bytes) if robot is not None else None
    opening, gripper = (arm.finger_separation, arm.gripper) if arm is not None else (None, None)
    m = load_object(path, unit, max_bytes, opening=opening, gripper=gripper)
    check_against_shape(path, root, m, unit, opening, gripper)

    def flow(v: Any) -> str:
        return yaml.safe_dump(v, default_flow_style=True, width=10**6, sort_keys=False).strip().removesuffix(
            "\n...").strip()

    def n(v: float) -> float | int:
        r = round(float(v), 9) + 0.0
        return int(r) if r.is_integer() and abs(r) < 1e15 else r

    grip = f"{num(opening)} {unit}" if opening is not None else f"{num(from_mm(unit, DEFAULT_OPENING_MM))} {unit}"
    out = [f"# Derived by `spar kb derive` from {path} (gripper opening {grip}); every entry explicit.",
           f"object: {m.name}", f"units: {flow(root.value['units'])}"]
    own = dict(root.value)
    if "mesh" in own and out_dir is not None and m.geometry is not None and m.geometry.mesh_file:
        own["mesh"] = os.path.relpath(m.geometry.mesh_file, Path(out_dir).resolve())
    out += [f"{k}: {flow(own[k])}" for k in ("mesh", "shape", "face_names", "grasp_step", "feature") if k in own]
    out.append(f"faces: {flow(list(m.faces))}")
    out.append("stable_poses:")
    for p in m.poses.values():
        rows = [[n(v) for v in p.R[:, i]] for i in range(3)] + [[0, 0, n(p.height)]]
        out.append("  - " + flow({"label": p.label, "rfaces": list(p.rfaces), "ofaces": list(p.ofaces), "tm": rows}))
    out.append("grasps:")
    for g in m.grasps.values():
        e = [n(v) for v in g.euler[:3]] + [n(a / rad_per) for a in g.euler[3:]]
        out.append("  - " + flow({"label": g.label, "gfaces": list(g.gfaces), "ofaces": list(g.ofaces),
                                  "eulerxyz": e, "width": n(g.width)}))
    return "\n".join(out) + "\n"


def _object_name(file: str) -> str | None:
    """The ``object:`` name of a KB file (None if it is not an object model)."""
    try:
        data = parse_yaml(file)
    except KBError:
        return None
    return data.get("object") if isinstance(data, dict) else None


def iter_kb_files(paths: Iterable[str | Path]) -> list[Path]:
    """Expand directories to their *.yaml files (sorted), keep files as given."""
    out: list[Path] = []
    for p in map(Path, paths):
        out += sorted(p.rglob("*.yaml")) if p.is_dir() else [p]
    return out
