"""Where phase 2's parts are after a step: their ideal poses (:func:`poses`) and the bounds of
their position uncertainty as phase 2 propagated it (:func:`position_bounds`), for a run's
records.
"""
from __future__ import annotations

import math
from typing import Any

import casadi as ca
import numpy as np

from spar_py.phase2 import uncertainty as ur
from spar_py.world.collision import CellCache
from spar_py.phase2.state import World
from spar_py.phase2.supinf import cached_bounds
from spar_py.phase2.symbolic import Registry, is_symbolic, snap

def poses(world: World, seen: dict[int, tuple[ur.ObjectState, list[list[float]]]] | None = None
          ) -> dict[str, list[list[float]]]:
    """Every part's ideal 4x4 world pose (cell unit) in ``world``, keyed by object name or
    ``"<object>@<initial position name>"`` for the other parts of a stock. A held part's
    pose is where it was grasped, an assembled one's where it was inserted.

    ``seen`` (one run's, by the state's id; the state is kept with its rows so the id
    stays its own) reuses the rows of a part whose state a step left as it was: a step
    moves one part, so a run of n steps over m parts rounds n poses, not n * m."""
    if seen is None:
        return {k: np.round(o.pose, 9).tolist() for k, o in sorted(world.unc.objects.items())}
    out = {}
    for k, o in sorted(world.unc.objects.items()):
        hit = seen.get(id(o))
        if hit is None or hit[0] is not o:
            hit = seen[id(o)] = (o, np.round(o.pose, 9).tolist())
        out[k] = hit[1]
    return out


#: Entries of the cell cache's table of parts' position bounds (:func:`position_bounds`), one
#: per error structure and variables' bounds.
BOUNDS_LIMIT = 4096


def _displacement(o: ur.ObjectState) -> list[Any]:
    """Part ``o``'s error as four expressions in its error variables: the displacement of its
    origin from the ideal one along world x, y, z (cell unit) and its turn about world z (rad).

    On the table (Eq. 2, ``trans(d) Tr_O rotz(theta) R_O``) the origin moves by ``d`` and turns
    by ``theta``. Held or assembled (Eq. 4, ``T_O T_G E T_G^-1`` with ``E = trans(t_E) rotz(theta)``)
    the origin, at ``p = -R_G^T t_G`` in the tool frame, goes to ``E p``: it moves by
    ``R_M ((rotz(theta) - I) p + t_E)`` with ``R_M = R_O R_G`` (the constant parts cancel
    exactly), and it turns by ``theta`` about the tool z axis, whose world-z component
    ``R_M[2, 2]`` times ``theta`` is the rotation vector's z component (as a put-down maps
    it, Sec. 3.2.3)."""
    e = o.error
    if o.where == ur.TABLE:
        return [e.dx, e.dy, e.dz, e.theta]
    G = snap(np.asarray(o.grasp, float))
    R_M = snap(o.pose[:3, :3] @ G[:3, :3])
    p = [float(v) for v in -G[:3, :3].T @ G[:3, 3]]
    c, s = ca.cos(e.theta) - 1.0, ca.sin(e.theta)
    local = [c * p[0] - s * p[1] + e.dx, s * p[0] + c * p[1] + e.dy, e.dz]  # (rotz(theta) - I) p + t_E
    world = [sum((float(R_M[i, j]) * local[j] for j in range(3) if R_M[i, j] != 0.0), ca.SX(0.0))
             for i in range(3)]
    return [*world, float(R_M[2, 2]) * e.theta]


def _degrees(lo: float, hi: float) -> list[float]:
    """[lo, hi] rad in degrees, each nonzero end moved two floats outwards (the product's
    rounding), so the interval in degrees holds the one in radians."""
    out = []
    for x, way in ((lo, -math.inf), (hi, math.inf)):
        d = math.degrees(x)
        if d != 0.0:
            d = math.nextafter(math.nextafter(d, way), way)
        out.append(d)
    return out


def _part_bounds(cache: CellCache, reg: Registry, o: ur.ObjectState) -> tuple[tuple[float, float], ...]:
    """SUP/INF of :func:`_displacement` over the error variables' registry box: four
    (lo, hi), sound (lo <= min, hi >= max). Kept in the cell cache by the error's structure
    (ErrorTm.shape), the numbers the expressions use and the variables' bounds: parts alike
    in how their error came about are bounded once."""
    vs = o.error.vars
    key = None
    if o.error.shape and len({v.element_hash() for v in vs}) == len(vs):
        R = snap(o.pose[:3, :3])
        G = None if o.grasp is None else snap(np.asarray(o.grasp, float)).tobytes()
        key = (o.where, R.tobytes(), G, o.error.shape, tuple(reg.bounds(v.name()) for v in vs))
        hit = cache.table("phase2.position_bounds", BOUNDS_LIMIT).get(key)
        if hit is not None:
            return hit

    def bound(e: Any) -> tuple[float, float]:
        if not is_symbolic(e):
            return float(e), float(e)
        if isinstance(e, ca.SX) and e.is_symbolic():  # one variable (a fresh error): its own bounds, exactly
            return reg.bounds(e.name())
        r = cached_bounds(e, reg.box(e), cache.memo, want="both")
        return float(r.lo), float(r.hi)

    got = tuple(bound(e) for e in _displacement(o))
    if key is not None:
        cache.table("phase2.position_bounds", BOUNDS_LIMIT)[key] = got
    return got


def position_bounds(cache: CellCache, world: World,
                    seen: dict[int, tuple[ur.ObjectState, dict[str, list[float]]]] | None = None
                    ) -> dict[str, dict[str, list[float]]]:
    """Every part's position uncertainty in ``world`` as phase 2 propagated it (the parts keyed
    as :func:`poses`): ``{"dx", "dy", "dz": [lo, hi]}`` the displacement of its origin from its
    ideal pose along the world axes (cell unit) and ``"dtheta_deg": [lo, hi]`` its rotation
    about world z (degrees; :func:`_displacement`: a part held by a side grasp turns about a
    level axis, not about z), each SUP/INF's sound bound (not rounded: a sensor's bounds
    are given exactly). After a sensing step a part has the sensor's bounds, held the
    grasp's, after a put-down or a squeeze what the hand left. ``seen`` as :func:`poses` (a
    step changes one part's state)."""
    reg = world.unc.registry
    out = {}
    for k, o in sorted(world.unc.objects.items()):
        hit = None if seen is None else seen.get(id(o))
        if hit is None or hit[0] is not o:
            x, y, z, t = _part_bounds(cache, reg, o)
            hit = (o, {"dx": list(x), "dy": list(y), "dz": list(z), "dtheta_deg": _degrees(*t)})
            if seen is not None:
                seen[id(o)] = hit
        out[k] = hit[1]
    return out
