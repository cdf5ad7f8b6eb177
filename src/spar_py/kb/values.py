"""The compound values several kinds of KB file write, read from a :class:`~spar_py.kb.node.Node`.

A ``units`` block (length and angle units, converted once, here), the paper's ``tm`` rows
of a transform (Fig. 18) and a ``{xyz, rpy}`` frame, in the file's units scaled to the
cell's. Units: lengths as ``length_scale`` says, angles in radians.
"""
from __future__ import annotations

import struct

import numpy as np

from spar_py.core.geometry import ORTHO_TOL, rotation_problem, rpy, tm_rows, trans
from spar_py.core.memo import Memo
from spar_py.core.units import ANGLE_UNITS, LENGTH_UNITS
from spar_py.kb.node import MAX_MAGNITUDE, Node

__all__ = ["LOAD_MEMO_LIMIT", "tm_node", "units_of", "xyz_rpy_frame"]


#: Entries of each memo table one problem's load keeps (load_problem: transforms by their
#: tm rows, stable-pose tests by their rotations), the least recently used dropped first.
LOAD_MEMO_LIMIT = 4096


def units_of(root: Node) -> tuple[str, float, float]:
    """(length unit name, mm per unit, radians per unit) from a ``units`` block."""
    u = root.key("units")
    length = u.key("length").choice(LENGTH_UNITS)
    angle = u.key("angle").choice(ANGLE_UNITS)
    return length, LENGTH_UNITS[length], ANGLE_UNITS[angle]


def tm_node(node: Node, length_scale: float, memo: Memo | None = None) -> np.ndarray:
    """A 4x4 transform from the paper's row form ``[[r1], [r2], [r3], [d]]`` (Fig. 18).

    The rows r1..r3 are the images of the frame's x, y, z axes (row-vector
    convention, as the paper prints its matrices), d the displacement, in the file's
    length unit (multiplied by ``length_scale``). The rotation must pass geometry's
    check (orthonormal to ``ORTHO_TOL``, det +1). With ``memo`` (one load's tables,
    :func:`load_problem`) the transform of rows already read is a copy of the one built
    then: the same numbers, the same transform.
    """
    v = node.value
    flat = [float(x) for r in v if type(r) is list and len(r) == 3
            for x in r if (type(x) is float or type(x) is int) and abs(x) <= MAX_MAGNITUDE
            ] if type(v) is list and len(v) == 4 else []
    table = memo.table("tm_node", LOAD_MEMO_LIMIT) if memo is not None and len(flat) == 12 else None
    if table is not None:  # the key: the 12 numbers' and the scale's bits (-0.0 is not 0.0)
        key = struct.pack("13d", *flat, length_scale)
        known = table.get(key)
        if known is not None:
            return known.copy()
    if len(flat) == 12:  # 4 rows of 3 numbers as Node.vector takes them: no Nodes
        m = np.array(flat).reshape(4, 3)
    else:
        rows = node.elements()
        if len(rows) != 4:
            raise node.fail("tm rows [[r1], [r2], [r3], [d]] (4 rows of 3 numbers)", f"{len(rows)} rows")
        m = np.array([r.vector(3) for r in rows])
    m[3] *= length_scale
    T = tm_rows(m)
    why = rotation_problem(T[:3, :3])
    if why is not None:
        hint = ("; write exact values or more digits, e.g. 0.70710678118655 for sqrt(1/2), not 0.7071"
                if why.startswith("R^T R") else "")
        raise node.fail(f"an orthonormal right-handed rotation in rows 1-3 "
                        f"(orthonormal to {ORTHO_TOL:g}, det +1; {why}{hint})")
    if table is not None:
        table[key] = T.copy()
    return T


def xyz_rpy_frame(node: Node, length_scale: float, rad_per: float) -> np.ndarray:
    """``{xyz: [x, y, z], rpy: [r, p, y]}`` (file units; rpy optional) as ``trans(xyz) @ rpy(r, p, y)``."""
    xyz = node.key("xyz").vector(3) * length_scale
    r = node.key("rpy", required=False)
    ang = r.vector(3) * rad_per if r is not None else np.zeros(3)
    return trans(*xyz) @ rpy(*ang)
