"""Write the paper's cell (kb/problems/peg_in_block.yaml, its robot and its objects) in
another length unit: every length is scaled, every angle, direction and label kept.

Used by tests/test_units.py (into a temporary directory); ``python tests/units_fixture.py
mm DIR`` writes a copy by hand. Lengths written rounded to 12 significant digits, as a
person converting the file would write them (762 mm, not 761.9999999999999).
"""
from __future__ import annotations

import sys
from pathlib import Path
from typing import Any

import yaml

from paths import ROOT

MM_PER = {"mm": 1.0, "m": 1000.0, "in": 25.4, "cm": 10.0}


def _len(v: float, k: float) -> float:
    """A length times ``k``, rounded to 12 significant digits."""
    return float(f"{v * k:.12g}")


def _tm(rows: list, k: float) -> list:
    """The paper's row-form tm with its displacement row scaled."""
    return [list(rows[0]), list(rows[1]), list(rows[2]), [_len(v, k) for v in rows[3]]]


def _bounds(b: dict, k: float) -> dict:
    return {key: ([_len(v, k) for v in iv] if key in ("dx", "dy", "dz") else list(iv)) for key, iv in b.items()}


def convert_object(data: dict, k: float, unit: str) -> dict:
    """An object file's data with lengths times ``k`` and ``units.length`` set to ``unit``."""
    out = dict(data, units={"length": unit, "angle": data["units"]["angle"]})
    if "feature" in data:
        f = data["feature"]
        out["feature"] = dict(f, radius=_len(f["radius"], k), vector=[_len(v, k) for v in f["vector"]])
    shape: list[dict[str, Any]] = []
    for s in data.get("shape", []):
        if "box" in s:
            shape.append({"box": {"min": [_len(v, k) for v in s["box"]["min"]],
                                  "max": [_len(v, k) for v in s["box"]["max"]]}})
        else:
            c = s["cylinder"]
            shape.append({"cylinder": {"radius": _len(c["radius"], k), "z": [_len(v, k) for v in c["z"]]}})
    out["shape"] = shape
    out["stable_poses"] = [dict(p, tm=_tm(p["tm"], k)) for p in data["stable_poses"]]
    out["grasps"] = [dict(g, eulerxyz=[_len(v, k) for v in g["eulerxyz"][:3]] + list(g["eulerxyz"][3:]),
                          width=_len(g["width"], k)) for g in data["grasps"]]
    return out


def convert_robot(data: dict, k: float, unit: str) -> dict:
    """A robot file's data with lengths times ``k``."""
    out = dict(data, units={"length": unit, "angle": data["units"]["angle"]})
    out["dh"] = [dict(r, a=_len(r["a"], k), d=_len(r["d"], k)) for r in data["dh"]]
    for key in ("base", "tool"):
        out[key] = dict(data[key], xyz=[_len(v, k) for v in data[key]["xyz"]])
    g = data["gripper"]
    out["gripper"] = dict(g, finger_separation=_len(g["finger_separation"], k))
    for box in ("finger", "palm"):
        if box in g:
            out["gripper"][box] = {key: _len(v, k) for key, v in g[box].items()}
    if "collision" in data:
        out["collision"] = _scaled_lengths(data["collision"], k)
    return out


_NOT_LENGTHS = {"name", "frame", "allow", "link"}


def _scaled_lengths(v: Any, k: float, key: str = "") -> Any:
    """A collision section with every number scaled by ``k`` (they are all lengths: margins,
    radii, end-points, box corners), names, frame numbers and allowed pairs kept."""
    if key in _NOT_LENGTHS:
        return v
    if isinstance(v, dict):
        return {kk: _scaled_lengths(vv, k, kk) for kk, vv in v.items()}
    if isinstance(v, list):
        return [_scaled_lengths(x, k, key) for x in v]
    if isinstance(v, (int, float)) and not isinstance(v, bool):
        return _len(v, k)
    return v


def convert_problem(data: dict, k: float, unit: str, robot: str, models: dict[str, str]) -> dict:
    """A problem file's data with lengths times ``k``, naming the converted robot and models."""
    out = dict(data, units={"length": unit, "angle": data["units"]["angle"]}, robot=robot)
    objs = {}
    for name, o in data["objects"].items():
        inits = o["initial"] if isinstance(o["initial"], list) else [o["initial"]]
        new = [dict(i, tm=_tm(i["tm"], k)) for i in inits]
        objs[name] = dict(o, model=models[name], initial=new if isinstance(o["initial"], list) else new[0])
    out["objects"] = objs
    unc = data["uncertainty"]
    out["uncertainty"] = {"manipulator": _bounds(unc["manipulator"], k),
                          "objects": {n: _bounds(b, k) for n, b in unc["objects"].items()}}
    if "sensors" in data:
        out["sensors"] = {n: _bounds(b, k) for n, b in data["sensors"].items()}
    if "transforms" in data:
        out["transforms"] = {n: dict(t, tm=_tm(t["tm"], k)) for n, t in data["transforms"].items()}
    if "placement_regions" in data:
        out["placement_regions"] = [{a: [_len(v, k) for v in r[a]] for a in ("x", "y")}
                                    for r in data["placement_regions"]]
    return out


def write_cell(problem: Path, unit: str, out: Path) -> Path:
    """Write ``problem`` (with its robot and objects) in ``unit`` into ``out``; the new problem's path."""
    out.mkdir(parents=True, exist_ok=True)
    p = yaml.safe_load(problem.read_text())
    k = MM_PER[p["units"]["length"]] / MM_PER[unit]
    rpath = (problem.parent / p["robot"]).resolve()
    r = yaml.safe_load(rpath.read_text())
    rk = MM_PER[r["units"]["length"]] / MM_PER[unit]
    (out / f"robot_{unit}.yaml").write_text(yaml.safe_dump(convert_robot(r, rk, unit), sort_keys=False))
    models = {}
    for name, o in p["objects"].items():
        mpath = (problem.parent / o["model"]).resolve()
        m = yaml.safe_load(mpath.read_text())
        mk = MM_PER[m["units"]["length"]] / MM_PER[unit]
        fname = f"{mpath.stem}_{unit}.yaml"
        (out / fname).write_text(yaml.safe_dump(convert_object(m, mk, unit), sort_keys=False))
        models[name] = fname
    dest = out / f"{problem.stem}_{unit}.yaml"
    dest.write_text(yaml.safe_dump(convert_problem(p, k, unit, f"robot_{unit}.yaml", models), sort_keys=False))
    return dest


if __name__ == "__main__":
    print(write_cell(ROOT / "kb/problems/peg_in_block.yaml", sys.argv[1], Path(sys.argv[2])))
