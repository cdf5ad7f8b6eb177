"""Derive a model's faces, stable poses, grasps (and a mesh part's convex hull) once per content.

:func:`derive` returns the derivation as plain data, from a content-hash cache on disk when
it has one: the key is the SHA-256 of everything the result depends on (the geometry's
content and scale, the feature, ``face_names``, the gripper, the approach step, the
labels' prefix, DERIVE_VERSION and the source of the modules that derive: every module of world/parts/),
so an edited mesh or model is derived again and an unchanged one never is, across runs, cells
and processes, and a derivation changed without a bump of DERIVE_VERSION (a branch's earlier
code under the same number) is never read back as the new one's. The cache lives in the user's
cache directory (``$SPAR_CACHE_DIR``, else ``$XDG_CACHE_HOME/spar-py/derive``, else
``~/.cache/spar-py/derive``), not per cell, because the same part file serves many cells
and its derivation does not depend on the cell; it is bounded: at most MAX_ENTRIES files
(the least recently used are removed when a new one is written). An unreadable or corrupt
entry is derived again; an unwritable cache directory only costs the derivation.

Units: lengths in the cell unit, angles in radians (as in the models).
"""
from __future__ import annotations

import json
import math
import os
from pathlib import Path
from typing import Any

import numpy as np

from spar_py.world.parts.mesh import FeatureGeometry, Geometry, derive_faces

__all__ = ["DERIVE_VERSION", "MAX_ENTRIES", "cache_dir", "derive", "source_digest"]

#: Bumped whenever the derivation's results change for the same inputs.
DERIVE_VERSION = 12
#: The modules whose source is part of the key (world/, beside this file).
#: Derivations kept on disk at most.
MAX_ENTRIES = 256


def cache_dir() -> Path:
    """Where derivations are kept (module docstring)."""
    if os.environ.get("SPAR_CACHE_DIR"):
        return Path(os.environ["SPAR_CACHE_DIR"])
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base) / "spar-py" / "derive"


def source_digest() -> str:
    """SHA-256 of the derivation's source (every module of this room, by name); "" where none
    can be read (an installation without sources: DERIVE_VERSION alone). Read at each call:
    a few hundred kB, small beside the derivation it keys."""
    import hashlib  # here: the parts door loads this module, and a plan that derives nothing never hashes

    h = hashlib.sha256()
    files = sorted(Path(__file__).resolve().parent.glob("*.py"))
    try:
        for f in files:
            h.update(f.name.encode() + b"\0" + f.read_bytes())
    except OSError:
        return ""
    return h.hexdigest() if files else ""


def derive(name: str, geometry: Geometry, features: tuple[FeatureGeometry, ...], face_names: dict[str, np.ndarray],
           gripper: Any, step: float, need_hull: bool, use_cache: bool = True) -> dict[str, Any]:
    """The derivation of a part as plain data: ``faces`` (names), ``poses`` (label, rfaces,
    ofaces, R as 9 numbers row-major, height, probability), ``grasps`` (label, gfaces,
    ofaces, euler: X, Y, Z, phi, theta, psi in radians, width), ``repair`` (what loading the
    mesh repaired, world.parts.mesh.Repair's line, "" for nothing), ``no_grasp`` (with no grasps:
    the sizes and opening compared, else "") and, if ``need_hull``, ``hull``
    (the convex hull's vertices). ``features``: the part's features declared by geometry.
    ValueError (one line, naming the key) for bad geometry."""
    key_data = [DERIVE_VERSION, source_digest(), name, geometry.digest(), [f.spec() for f in features],
                sorted((k, [round(float(v), 12) for v in p]) for k, p in face_names.items()),
                gripper.spec(), round(step, 12), need_hull]
    import hashlib

    key = hashlib.sha256(json.dumps(key_data).encode()).hexdigest()
    path = cache_dir() / f"{key}.json"
    if use_cache and (data := load(path, key)) is not None:
        return data
    data = _compute(name, geometry, features, face_names, gripper, step, need_hull)
    data["key"] = key
    if use_cache:
        store(path, data)
    return data


def _compute(name: str, geometry: Geometry, features: tuple[FeatureGeometry, ...], face_names: dict[str, np.ndarray],
             gripper: Any, step: float, need_hull: bool) -> dict[str, Any]:
    from spar_py.world.parts.grasps import derive_grasps  # a cache miss only
    from spar_py.world.parts.poses import derive_poses

    mesh = geometry.mesh()
    faces = derive_faces(mesh, features, face_names, geometry.unit)
    poses = derive_poses(mesh, faces, features, geometry.unit, f"{name}_p", prims=geometry.primitives)
    why: list[str] = []
    grasps = derive_grasps(mesh, faces, features, geometry.primitives, gripper, geometry.unit, f"{name}_g", step,
                           why, poses)
    out: dict[str, Any] = {
        "faces": [f.name for f in faces],
        "poses": [{"label": p.label, "rfaces": list(p.rfaces), "ofaces": list(p.ofaces),
                   "R": [float(v) for v in p.R.ravel()], "height": p.height, "probability": p.probability}
                  for p in poses],
        "grasps": [{"label": g.label, "gfaces": list(g.gfaces), "ofaces": list(g.ofaces),
                    "euler": [float(v) for v in g.euler], "width": g.width} for g in grasps],
        "repair": geometry.repair,
        "no_grasp": why[0] if why else "",
    }
    if need_hull:
        from spar_py.world.parts.support import hull_vertices  # a cache miss only (see _compute)

        V = np.asarray(mesh.vertices, float)
        out["hull"] = [[float(v) for v in p] for p in V[hull_vertices(mesh)]]
    return out


def load(path: Path, key: str) -> dict[str, Any] | None:
    """The entry at ``path`` if it holds ``key`` (its use refreshed: least recently used goes
    first), else None (missing, unreadable or another key's)."""
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
        if isinstance(data, dict) and data.get("key") == key:
            os.utime(path)
            return data
    except (OSError, ValueError):
        pass
    return None


def store(path: Path, data: dict[str, Any]) -> None:
    """Write atomically, then drop the least recently used entries beyond MAX_ENTRIES."""
    try:
        text = json.dumps(data, allow_nan=False)  # one shot: the C encoder (json.dump streams in Python)
        path.parent.mkdir(parents=True, exist_ok=True)
        import tempfile  # only a derivation written to disk

        fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=".tmp-", suffix=".json")
        with os.fdopen(fd, "w", encoding="utf-8") as fh:
            fh.write(text)
        os.replace(tmp, path)
        entries = sorted(path.parent.glob("*.json"), key=lambda p: p.stat().st_mtime)
        for old in entries[: max(0, len(entries) - MAX_ENTRIES)]:
            old.unlink(missing_ok=True)
    except (OSError, ValueError):
        pass  # a read-only cache only costs the derivation next time


def degrees(euler: list[float]) -> list[float]:
    """An ``euler`` list with its angles in degrees (for writing a model file)."""
    return [*euler[:3], *(round(math.degrees(a), 9) + 0.0 for a in euler[3:])]
