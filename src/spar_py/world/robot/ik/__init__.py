"""Inverse kinematics: closed-form families (PUMA, UR) and a numeric fallback, behind one interface.

A solver (:class:`~spar_py.world.robot.ik.common.Solver`) answers, for n world tool poses at
once, every *branch* (distinct arm configuration) as DH angles with a flag saying it
is a true solution; the robot (``spar_py.world.robot.model.Robot``) turns those into joint
vectors within limits, every full-turn representation included. :func:`solver_for`
picks the solver for a Craig (modified) DH table: the first closed-form family in
:data:`FAMILIES` whose structure the table has, else the numeric fallback.

Families: ``puma`` (Craig, Sec. 4.7: spherical wrist, PUMA 560 twists; puma.py),
``ur`` (Hawkins 2013: three parallel middle axes, wrist offsets; ur.py) and
``numeric`` (multi-start damped least squares, any 6R arm, not complete; numeric.py).
"""
from __future__ import annotations

from collections.abc import Callable

import numpy as np

from spar_py.world.robot.ik.common import LIMIT_TOL, Solver, craig_links, lowest_representation, turn_combinations
from spar_py.world.robot.ik.numeric import NumericSolver
from spar_py.world.robot.ik.puma import PUMA_TWISTS, PumaSolver
from spar_py.world.robot.ik.ur import UR_TWISTS, URSolver

__all__ = ["FAMILIES", "FAMILY_TWISTS", "LIMIT_TOL", "NumericSolver", "PumaSolver", "Solver", "URSolver", "craig_links",
           "lowest_representation", "solver_for", "turn_combinations"]

#: Closed-form families by name, in the order they are tried: each ``make(dh, base, tool, unit)``
#: returns its solver or the reason the table is not of the family.
FAMILIES: dict[str, Callable[..., Solver | str]] = {
    "puma": PumaSolver.make,
    "ur": URSolver.make,
}
#: Each closed-form family's Craig twists alpha_1..alpha_5 (rad), for converting URDF chains
FAMILY_TWISTS: dict[str, tuple[float, ...]] = {"puma": PUMA_TWISTS, "ur": UR_TWISTS}


def solver_for(dh: np.ndarray, base: np.ndarray, tool: np.ndarray, limits: np.ndarray, unit: str = "",
               family: str = "auto") -> tuple[Solver, dict[str, str]]:
    """The IK solver for a Craig DH table (6, 4) with base, tool (4x4) and limits (6, 2) rad.

    ``family`` "auto" tries :data:`FAMILIES` in order and falls back to the numeric
    solver; a family name tries that family only (the numeric solver if it does not
    fit: the caller decides whether that is an error) and "numeric" forces the fallback.
    Returns (solver, reasons): why each closed-form family tried did not fit, by name.
    """
    reasons: dict[str, str] = {}
    names = list(FAMILIES) if family == "auto" else ([family] if family in FAMILIES else [])
    for name in names:
        s = FAMILIES[name](dh, base, tool, unit)
        if not isinstance(s, str):
            return s, reasons
        reasons[name] = s
    return NumericSolver(dh, base, tool, limits), reasons
