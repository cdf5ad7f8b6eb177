"""One internal length unit for the lengths written in the code: millimetres.

A constant in the code (a grid step, a clearance, a reach margin) is stated in mm
(``*_MM``) and converted to the cell's own length unit (``Cell.unit``, a key of
:data:`LENGTH_UNITS`, mm per unit) where it is used, so the same cell written in
inches, millimetres or metres is planned on the same physical grid.
"""
from __future__ import annotations

import math
from types import MappingProxyType

__all__ = ["ANGLE_UNITS", "INTERNAL_UNIT", "LENGTH_UNITS", "from_mm", "mm_per"]

#: The unit of every length constant in src/spar_py.
INTERNAL_UNIT = "mm"
#: The length units a KB file may name (``units: {length: ...}``): millimetres per unit.
LENGTH_UNITS = MappingProxyType({"mm": 1.0, "m": 1000.0, "in": 25.4, "cm": 10.0})
#: The angle units a KB file may name (``units: {angle: ...}``): radians per unit.
ANGLE_UNITS = MappingProxyType({"deg": math.pi / 180.0, "rad": 1.0})


def mm_per(unit: str) -> float:
    """Millimetres per ``unit`` (:data:`LENGTH_UNITS`; KeyError for an unknown unit)."""
    return LENGTH_UNITS[unit]


def from_mm(unit: str, mm: float) -> float:
    """``mm`` millimetres expressed in ``unit``, rounded to 12 significant digits, so a
    constant chosen in round inches is exact in inches (152.4 mm is 6.0 in, not
    6.000000000000001 in) and the conversion adds no noise of its own."""
    return float(f"{mm / mm_per(unit):.12g}")
