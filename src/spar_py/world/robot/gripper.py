"""The gripper: one parallel-jaw gripper type for the whole world layer, and its default.

:class:`Gripper` holds what both its users need: the boxes of its fingers, palm and tool body
(collision scene, reach, grasp reports) and the sizes grasps are derived and checked for
(world.parts), with the plain data the derivation cache hashes (:meth:`Gripper.spec`).
A cell whose robot file gives no ``gripper:`` boxes gets the default fingers at the cell's
opening: :func:`gripper_for` is the one place that chooses it.

Tool frame: z the approach, y the closing axis, origin the tool centre point midway between the
finger tips. Lengths in the robot's (the cell's) unit.
"""
from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from spar_py.core.units import from_mm, mm_per

__all__ = ["Gripper", "TOOL_BODY", "ToolBody", "gripper_for", "tool_body_behind"]

#: The collision body name of the tool between the palm and the flange (:class:`ToolBody`).
TOOL_BODY = "tool"


@dataclass(frozen=True)
class ToolBody:
    """The tool's body from the palm's back face to the flange, along the tool axis (robot unit):
    a ``kind`` "box" ``width`` (tool x) by ``thickness`` (tool y), or a "cylinder" of ``radius``
    about tool z, ``length`` long from the palm's back face (z = -(finger_length + palm_length))
    back towards the flange (-z). The gripper's own mount and housing: without it, a grasp under a
    shelf would put the tool through the shelf unchecked."""

    kind: str
    length: float
    width: float = 0.0
    thickness: float = 0.0
    radius: float = 0.0


def tool_body_behind(tool: np.ndarray, finger_length: float, palm_length: float) -> float:
    """How far the flange lies behind the palm's back face along the tool axis (robot unit; <= 0:
    the palm is on or behind the flange): the depth of the flange's origin along -z of the tool
    frame (``tool`` is T_flange_tool, 4x4) less the fingers' and palm's lengths."""
    T = np.asarray(tool, float)
    depth = float(T[:3, 2] @ T[:3, 3])  # -(flange origin's z in the tool frame) = z_tool . t
    return depth - finger_length - palm_length


@dataclass(frozen=True)
class Gripper:
    """A parallel-jaw gripper's boxes in the tool frame (robot unit).

    Tool frame: z the approach, y the closing axis, origin the tool centre point midway between
    the finger tips. Each finger is a box ``finger_length`` along z (from the TCP plane z = 0 back
    to z = -finger_length), ``finger_width`` along x (centred), ``finger_thickness`` along y
    (outward from its contact face at y = +-width/2); the palm a box ``palm_length`` along z behind
    the fingers (z from -finger_length - palm_length to -finger_length), ``palm_width`` along x,
    ``palm_thickness`` along y (centred). Defaults (:meth:`default`, :meth:`of_unit`): fingers
    60 x 20 x 10 mm, a palm 25 mm deep, as wide as a finger and as thick as the open fingers' span
    (finger_separation + 2 finger thicknesses), a common industrial jaw. ``body`` the tool behind
    the palm (:class:`ToolBody`; the loader gives a robot without ``collision:`` the default,
    :meth:`with_default_body`); the grasps derived for a gripper do not depend on it.
    """

    finger_separation: float
    finger_length: float
    finger_width: float
    finger_thickness: float
    palm_length: float
    palm_width: float
    palm_thickness: float
    #: the tool's body behind the palm (:class:`ToolBody`), None: none is checked
    body: ToolBody | None = None

    @classmethod
    def default(cls, finger_separation: float, mm_per_unit: float, finger: dict | None = None,
                palm: dict | None = None) -> "Gripper":
        """The gripper of opening ``finger_separation`` (robot unit) with the given ``finger`` /
        ``palm`` sizes ({length, width, thickness}, robot unit), the documented defaults elsewhere."""
        mm = 1.0 / mm_per_unit
        f = {"length": 60.0 * mm, "width": 20.0 * mm, "thickness": 10.0 * mm, **(finger or {})}
        p = {"length": 25.0 * mm, "width": f["width"], "thickness": finger_separation + 2 * f["thickness"],
             **(palm or {})}
        return cls(float(finger_separation), float(f["length"]), float(f["width"]), float(f["thickness"]),
                   float(p["length"]), float(p["width"]), float(p["thickness"]))

    @classmethod
    def of_unit(cls, unit: str, opening: float) -> "Gripper":
        """The default fingers and palm at ``opening`` (``unit``), each size converted by
        core.units.from_mm (rounded to 12 significant digits): the gripper object models are
        derived and checked for without a robot. Its sizes, hence derivation cache keys and derived
        grasps, are those such derivations always had (:meth:`default` multiplies by 1 / mm per
        unit, which differs in the last digits in inches)."""
        fl, fw, ft, pl = (from_mm(unit, v) for v in (60.0, 20.0, 10.0, 25.0))
        return cls(opening, fl, fw, ft, pl, fw, opening + 2 * ft)

    def palm_half(self) -> tuple[float, float]:
        """The palm's half sizes along tool x and tool y."""
        return self.palm_width / 2, self.palm_thickness / 2

    def spec(self) -> list:
        """Plain data for the derivation's content hash (world.parts.cache): the opening, the
        fingers' sizes and the palm's depth, and the palm's width and thickness only where they
        are not the default (a finger's width, the open fingers' span), so cache keys written
        before the robot's palm was read stay valid. The tool body is left out: grasps do not
        depend on it."""
        base = [round(v, 12) for v in (self.finger_separation, self.finger_length, self.finger_width,
                                       self.finger_thickness, self.palm_length)]
        px, py = self.palm_half()
        if (round(px, 12), round(py, 12)) != (round(self.finger_width / 2, 12),
                                              round(self.finger_separation / 2 + self.finger_thickness, 12)):
            base += [round(2 * px, 12), round(2 * py, 12)]
        return base

    def boxes(self, width: float | None = None) -> list[tuple[str, np.ndarray, np.ndarray]]:
        """(name, lo, hi) boxes in the tool frame: "finger_l" (+y), "finger_r" (-y) with their contact
        faces ``width`` apart (default the open ``finger_separation``), and "palm"."""
        w = (self.finger_separation if width is None else float(width)) / 2
        u, L, t = self.finger_width / 2, self.finger_length, self.finger_thickness
        pu, pt = self.palm_width / 2, self.palm_thickness / 2
        return [("finger_l", np.array([-u, w, -L]), np.array([u, w + t, 0.0])),
                ("finger_r", np.array([-u, -w - t, -L]), np.array([u, -w, 0.0])),
                ("palm", np.array([-pu, -pt, -L - self.palm_length]), np.array([pu, pt, -L]))]

    def hand_boxes(self, width: float | None = None) -> list[tuple[np.ndarray, np.ndarray]]:
        """(lo, hi) boxes in the tool frame of the whole hand closed to ``width``: :meth:`boxes`
        and the tool body (:meth:`body_shape`; a cylinder by its bounding box)."""
        out = [(lo, hi) for _, lo, hi in self.boxes(width)]
        body = self.body_shape()
        if body is not None:
            _, kind, a, b, r = body
            out.append((np.minimum(a, b) - [r, r, 0.0], np.maximum(a, b) + [r, r, 0.0]) if kind == "cylinder"
                       else (np.minimum(a, b), np.maximum(a, b)))
        return out

    def body_shape(self) -> tuple[str, str, np.ndarray, np.ndarray, float] | None:
        """The tool body in the tool frame as (name, kind, a, b, radius): a "box" with corners
        ``a`` (min) and ``b`` (max), or a "cylinder" of axis a -> b (from the palm's back face
        towards the flange); None without a body or one of no length."""
        b = self.body
        if b is None or not b.length > 0:
            return None
        z0 = -self.finger_length - self.palm_length
        if b.kind == "cylinder":
            return (TOOL_BODY, "cylinder", np.array([0.0, 0.0, z0]), np.array([0.0, 0.0, z0 - b.length]), b.radius)
        return (TOOL_BODY, "box", np.array([-b.width / 2, -b.thickness / 2, z0 - b.length]),
                np.array([b.width / 2, b.thickness / 2, z0]), 0.0)

    def with_default_body(self, tool: np.ndarray) -> "Gripper":
        """This gripper with the default tool body (when it has none): a box the palm's size
        (palm_width x palm_thickness) from the palm's back face to the flange of ``tool``
        (T_flange_tool, 4x4); unchanged when the palm reaches the flange."""
        if self.body is not None:
            return self
        length = tool_body_behind(tool, self.finger_length, self.palm_length)
        if not length > 1e-9 * (1.0 + self.finger_length):
            return self
        return replace(self, body=ToolBody("box", length, self.palm_width, self.palm_thickness))


def gripper_for(cell: Any) -> Gripper:
    """The gripper of ``cell`` (core.model.Cell, or anything with its ``robot``, ``finger_separation``
    and ``unit``): its robot's, else the default fingers and palm (:meth:`Gripper.default`) at the
    cell's opening W_m, cell unit. The one place that default is chosen."""
    return cell.robot.gripper or Gripper.default(cell.finger_separation, mm_per(cell.unit))
