"""What keeps phase 2's parts where they are between steps: loose mates kept by gravity
(:func:`retention_refusal`) and parts resting on a body that is about to move
(:func:`stacked_on`); the names of the verdicts of a body's own state (:data:`STATE_CHECKS`).
"""
from __future__ import annotations

import math

import numpy as np

from spar_py.phase2 import uncertainty as ur
from spar_py.core.model import LOOSE_MAX_DEG
from spar_py.core.units import from_mm
from spar_py.world.reach import REST_TOL_MM, part_surface, rest_of, surfaces_of
from spar_py.phase2.state import World, model_of

#: The geometric verdicts of a body's own state (not of the arm's reach): a put-down body at rest,
#: loose mates kept, no part left unsupported; a no plan names them (planning/run.py).
STATE_CHECKS = ("stable", "retention", "supported")


def retention_refusal(unc: ur.WorldState, what: str) -> str | None:
    """Why the state ``unc`` (after step ``what``) loses a part, or None: the first loose mate
    whose insertion direction (the child's way into its parent, the parent's frame, turned by the
    parent's ideal pose into the world) is more than LOOSE_MAX_DEG from world down: ``pickup(block)
    would turn pin_b (loose in block.bore_b) 90 deg from down``."""
    for child, a in unc.attached.items():
        if a.retention != "loose" or a.direction is None:
            continue
        d = unc.obj(a.parent).pose[:3, :3] @ a.direction
        n = float(np.linalg.norm(d))
        if not n > 0:
            continue
        angle = math.degrees(math.acos(max(-1.0, min(1.0, -float(d[2]) / n))))
        if angle > LOOSE_MAX_DEG + 1e-6:
            return f"{what} would turn {child} ({a.mate}) {angle:.0f} deg from down"
    return None


def stacked_on(world: World, obj: str) -> str | None:
    """A part resting on ``obj``'s body (on its top, not mated into it), or None: picking ``obj`` up
    would leave it unsupported. A part rests on it when its lowest point is at the top's height
    (world.reach.supports' tolerance) over the top's polygon (world.reach.supports.rest_of)."""
    cell, unc = world.cell, world.unc
    body = unc.body(obj)
    tol = from_mm(cell.unit, REST_TOL_MM)
    tops = [part_surface(k, cell.objects[model_of(k)], unc.obj(k).pose, tol) for k in body
            if cell.objects[model_of(k)].shape]
    if not tops:
        return None
    for k, o in unc.objects.items():
        if k in body or o.where != ur.TABLE or k in unc.attached:
            continue
        r = rest_of(cell, model_of(k), o.pose, [*surfaces_of(cell), *tops])
        if r is not None and r.surface is not None and r.surface.name in body:
            return k
    return None
