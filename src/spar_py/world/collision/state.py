"""A collision scene with its parts placed (:class:`SceneState`, made by scene.py's
CollisionScene.at): "is this joint vector clear by the margin", the first pair that is not, the
clearance and the closest pair, the grasp rule, the refusals a tool pose alone decides; and the
per-pair lower bounds the motions ask (:func:`clearance_bounds`).

How: every body has a bounding capsule in its frame (exact for capsules). One vectorised numpy
pass gives each (row, pair) cell's capsule distance (bounds.py), a lower bound of its true
distance, and each body's height over the table. Only the cells within the margin, not both
capsules, and not put beyond it by the separating-axis bound go to the collision library.
"""
from __future__ import annotations

from collections.abc import Mapping
from dataclasses import replace
from typing import TYPE_CHECKING, Protocol

import numpy as np

from spar_py.core.errors import SparValueError
from spar_py.world.collision.bodies import TOOL, WORLD, Body, body_columns, body_distance, joined_columns
from spar_py.world.collision.bounds import (
    gap_of_extents, near_all, over_table, segment_distance, slab_gap, support_directions,
)
from spar_py.world.collision.pairs import GRIPPER_NAMES, PairRules, pair_structure, part_of

if TYPE_CHECKING:
    from spar_py.world.robot import Robot

__all__ = ["GRASP_LIMIT", "Scene", "SceneState", "bound_columns", "clearance_bounds"]

#: Bound of the cell cache's table of the grasp rule's verdicts per (part, grasp pose, width).
GRASP_LIMIT = 4096


class Scene(PairRules, Protocol):
    """What a scene state reads of its scene (scene.py's CollisionScene, which makes the states:
    typed here so that this module need not import the one importing it)."""

    robot: Robot
    links: list[Body]
    margin: float
    tol: float
    table: tuple[float, float, float, float] | None
    stats: dict[str, int]

    def slab(self) -> Body: ...

    def gripper_bodies(self, width: float | None) -> list[Body]: ...

    def shrunk_gripper(self, width: float | None, tol: float) -> list[Body]: ...

    def enters_mesh(self, part: str, g: Body, T_tool_part: np.ndarray) -> bool: ...

    def shapes_of(self, part: str) -> list[Body]: ...

    def shape_key(self, part: str) -> tuple: ...


class SceneState:
    """The scene with its parts placed: answers "clear?" and "how clear?" for joint vectors."""

    def __init__(self, scene: Scene, world: list[Body], tool: list[Body],
                 hand: tuple[str, str, np.ndarray] | None, width: float | None, allow: frozenset,
                 attached: frozenset = frozenset(), world_columns: tuple | None = None) -> None:
        """``world_columns``: the :func:`group_columns` of ``world`` when the caller has them (at())."""
        self.scene = scene
        self.hand = hand  # (part, "tool" | "world", its pose there) for the grasp rule
        self.width = width
        gripper = scene.gripper_bodies(width)
        links = scene.links
        static = [b for b in links if b.frame == 0]
        moving = [b for b in links if b.frame != 0] + gripper + tool
        self.bodies = moving + static + world
        self.n_moving = len(moving)
        hand_part = hand[0] if hand is not None else None
        wc = body_columns(world) if world_columns is None else world_columns
        cap_a, cap_b, cap_r, names, frames, is_cap = joined_columns([body_columns(moving + static), wc])
        struct = pair_structure(scene, self.bodies, len(moving), hand_part, allow, attached,
                                columns=(names, frames, is_cap))
        self.pairs, self.table_bodies, self.exact_pair, rigid = struct
        self._rigid: dict[int, float | None] = dict.fromkeys(rigid)
        self._is_rigid = np.zeros(len(self.pairs), dtype=bool)
        self._is_rigid[list(rigid)] = True
        # the library's distances of the last check(), by (pair, that row's frames): clearance()
        # of a row check() measured reads them instead of asking the library again
        self._measured: dict[tuple[int, bytes], float] = {}
        self._refusal: tuple[tuple[str, str] | None] | None = None  # tool_rigid_refusal's answer
        self._cap_a, self._cap_b, self._cap_r = cap_a, cap_b, cap_r
        # the broad phase of check(): each body's bounding sphere radius (its centre: the
        # middle of its capsule's axis)
        self._sph_r = np.linalg.norm(self._cap_b - self._cap_a, axis=1) / 2 + self._cap_r
        # made on first use by _world_caps: each moving body's frame, the static ends in the world
        self._body_frames = np.zeros(0, dtype=int)
        self._static: tuple[np.ndarray, np.ndarray] | None = None
        self._table_pts: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None  # by _plane_heights
        #: per table-checked body, whether CollisionScene.at was told it may touch the table (None:
        #: none may): :meth:`table_margin`
        self.table_touch: np.ndarray | None = None

    def table_margin(self) -> float | np.ndarray:
        """The least height each table-checked body keeps over the table: the scene's margin, and
        none for the bodies that may touch it (down to GRASP_TOL_MM of rounding)."""
        if self.table_touch is None:
            return self.scene.margin
        return np.where(self.table_touch, -self.scene.tol, self.scene.margin)

    def renamed(self, names: Mapping[str, str]) -> SceneState | None:
        """The state :meth:`CollisionScene.at` makes for this state's world with every part name n
        read as ``names.get(n, n)`` (the parts, ``held``, ``grasped``, ``attached`` and ``allow``
        of its call renamed alike; a held part's bodies are "held:<name>", so both are mapped),
        made without placing anything or deciding the pairs again: the same bodies renamed, the
        same pairs, and the library's distances measured anew where the copy first asks (none
        are shared). None where a renaming could change which pairs are checked: ``names`` not
        one to one, or an old or a new name that is also another body's, the table's, a gripper
        body's or in the robot's allowed pairs, or a held part's two names not mapped alike."""
        olds, news = set(names), set(names.values())
        if len(olds) != len(news):
            return None
        touched = olds | news
        reserved = {"table"} | set(GRIPPER_NAMES) | {n for p in self.scene.allowed for n in p}
        if touched & reserved:
            return None
        for old, new in names.items():  # "held:a" -> "held:b" exactly where a -> b
            if old.startswith("held:") != new.startswith("held:"):
                return None
            if old.startswith("held:") and names.get(part_of(old), part_of(old)) != part_of(new):
                return None
            if not old.startswith("held:") and f"held:{old}" in names and names[f"held:{old}"] != f"held:{new}":
                return None
        for b in self.bodies:
            if b.name not in names and (b.name in touched or part_of(b.name) in touched):
                return None
        if self.hand is not None and self.hand[0] not in names and self.hand[0] in touched:
            return None
        new = object.__new__(SceneState)
        new.__dict__.update(self.__dict__)
        new.bodies = [replace(b, name=names[b.name]) if b.name in names else b for b in self.bodies]
        if self.hand is not None:
            new.hand = (names.get(self.hand[0], self.hand[0]), *self.hand[1:])
        new._rigid = dict.fromkeys(self._rigid)
        new._measured = {}
        new._refusal = None
        return new

    # ------------------------------------------------------------------ frames and bounds

    def _frames(self, q: np.ndarray) -> np.ndarray:
        q = np.asarray(q, float)
        if q.ndim != 2 or q.shape[1] != 6:
            raise SparValueError(f"joint vectors must be of shape (n, 6), got {q.shape}")
        return self.scene.robot.frames_batch(q)

    def _world_caps(self, F: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """World ends (n, N, 3) of every body's bounding capsule."""
        n, m = len(F), self.n_moving
        if self._static is None:
            self._body_frames = np.array([b.frame for b in self.bodies[:m]], dtype=int)
            base = self.scene.robot.base
            sa, sb = self._cap_a[m:].copy(), self._cap_b[m:].copy()
            on_base = np.array([b.frame == 0 for b in self.bodies[m:]], dtype=bool)
            sa[on_base] = sa[on_base] @ base[:3, :3].T + base[:3, 3]
            sb[on_base] = sb[on_base] @ base[:3, :3].T + base[:3, 3]
            self._static = (sa, sb)
        A = np.empty((n, len(self.bodies), 3))
        B = np.empty_like(A)
        A[:, m:], B[:, m:] = self._static
        Fm = F[:, self._body_frames]                                 # (n, m, 4, 4) each body's frame
        R, t = Fm[..., :3, :3], Fm[..., :3, 3]
        A[:, :m] = (R @ self._cap_a[:m, :, None])[..., 0] + t
        B[:, :m] = (R @ self._cap_b[:m, :, None])[..., 0] + t
        return A, B

    def moving_spheres(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Bounding spheres of the moving bodies (links 1..6, gripper, tool parts) for joint
        vectors q (n, 6) rad: centres (n, M, 3), world frame, and radii (M,), cell unit. A
        caller's broad phase: a body farther than every sphere plus the margin is never near."""
        F = self._frames(q)
        A, B = self._world_caps(F)
        m = self.n_moving
        return (A[:, :m] + B[:, :m]) / 2, self._sph_r[:m]

    def _frame_pose(self, F: np.ndarray, row: int, b: Body) -> np.ndarray:
        if b.frame == WORLD:
            return np.eye(4)
        if b.frame == 0:
            return self.scene.robot.base
        return F[row, b.frame]

    def _plane_heights(self, F: np.ndarray) -> np.ndarray:
        """(n, m) each table-checked moving body's height above the plane z = 0 (exact, signed):
        the z row of its frame times its vertices, less its radius."""
        if self._table_pts is None:  # every table-checked body's vertices, padded by repeating one
            bodies = [self.bodies[i] for i in self.table_bodies]
            k = max((len(b.points) for b in bodies), default=1)
            pts = np.empty((len(bodies), k, 3))
            for j, b in enumerate(bodies):
                pts[j, :len(b.points)] = b.points
                pts[j, len(b.points):] = b.points[0]
            self._table_pts = (pts, np.array([b.frame for b in bodies], dtype=int),
                               np.array([b.radius for b in bodies]))
        pts, frames, radius = self._table_pts
        Fb = F[:, frames]                                             # (n, m, 4, 4)
        return (pts @ Fb[:, :, 2, :3, None])[..., 0].min(axis=2) + Fb[:, :, 2, 3] - radius

    def _table(self, F: np.ndarray) -> np.ndarray:
        """(n, m) each table-checked moving body's height above the table (exact, signed); for a
        body wholly off a table with an extent but within the margin of its footprint, its
        distance to the slab (a lower bound, :func:`slab_gap`, made exact where it is within the
        margin), else +inf."""
        ext = self.scene.table
        if ext is None:
            return self._plane_heights(F)
        n = len(F)
        out = np.full((n, len(self.table_bodies)), np.inf)
        for k, i in enumerate(self.table_bodies):
            b = self.bodies[i]
            Fb = F[:, b.frame]
            P = b.points @ np.swapaxes(Fb[:, :3, :3], 1, 2) + Fb[:, None, :3, 3]
            h = P[..., 2].min(axis=1) - b.radius
            out[:, k] = np.where(over_table(P, b.radius, ext), h, np.inf)
            # off the footprint but within the margin of it: the distance to the slab's edge
            band = np.isinf(out[:, k]) & over_table(P, b.radius + self.scene.margin, ext)
            if band.any():
                rows = np.nonzero(band)[0]
                g = slab_gap(P[rows], b.radius, ext)
                for j in np.nonzero(g <= self.scene.margin)[0].tolist():  # within it: the exact distance
                    g[j] = body_distance(b, self._frame_pose(F, int(rows[j]), b), self.scene.slab(), np.eye(4))
                out[rows, k] = g
        return out

    def tool_rigid_on_table(self, T_tool: np.ndarray) -> tuple[str, str] | None:
        """The first body rigid with the flange (frames 6 and 7: gripper, tool mount, the part
        attached to the tool) within the margin of an unbounded table at world tool pose T_tool
        (4x4), as (body, "table"), or None; None whenever the table has an extent. Its height does
        not change when the tool pose turns about world z or shifts in x, y, so a refusal here
        refuses every such pose (a placement grid's) before any IK is solved."""
        if self.scene.table is not None or not len(self.table_bodies):
            return None
        T_tool = np.asarray(T_tool, float)
        frames = {TOOL: T_tool, 6: T_tool @ self.scene.robot.tool_inverse()}
        margin = np.broadcast_to(self.table_margin(), (len(self.table_bodies),))
        for k, i in enumerate(self.table_bodies.tolist()):  # as _plane_heights, for the bodies on frames 6 and 7
            b = self.bodies[i]
            Fb = frames.get(b.frame)
            if Fb is not None and (b.points @ Fb[2, :3]).min() + Fb[2, 3] - b.radius <= margin[k]:
                return (b.name, "table")
        return None

    def _tool_frames(self, T_tool: np.ndarray) -> np.ndarray:
        """Frames (1, 8, 4, 4) with only what a tool pose fixes: the robot's base (0), the flange
        (6) and the tool (TOOL) at world tool pose ``T_tool``; the links' frames NaN."""
        F = np.full((1, 8, 4, 4), np.nan)
        F[0, 0] = self.scene.robot.base
        F[0, TOOL] = T_tool
        F[0, 6] = np.asarray(T_tool, float) @ self.scene.robot.tool_inverse()
        return F

    def hand_refusal(self, T_tool: np.ndarray) -> tuple[str, str] | None:
        """The first pair :meth:`check` would find within the margin between a body rigid with the
        flange (frames 6 and 7: the hand, the tool mount, the part in the hand) and a body fixed in
        the world (a part, an obstacle) with the tool at world pose ``T_tool`` (4x4), or None.
        Every joint vector reaching T_tool puts those two bodies there, so :meth:`check` refuses
        each for it: a caller trying many tool poses may skip their IK (the table, the grasp rule
        and the links are :meth:`check`'s alone)."""
        F = self._tool_frames(T_tool)
        with np.errstate(invalid="ignore"):
            A, B = self._world_caps(F)
        m, moving = self.scene.margin, self.n_moving
        hand = np.zeros(len(self.bodies), bool)
        hand[:moving] = np.isin(self._body_frames, (6, TOOL))
        pi, pj = self.pairs[:, 0], self.pairs[:, 1]
        ps = np.flatnonzero((hand[pi] & (pj >= moving)) | (hand[pj] & (pi >= moving)))
        if not len(ps):
            return None
        i, j = self.pairs[ps, 0], self.pairs[ps, 1]
        lb = segment_distance(A[0, i], B[0, i], A[0, j], B[0, j]) - self._cap_r[i] - self._cap_r[j]
        near = ps[lb <= m]
        lbs = lb[lb <= m]
        if not len(near):
            return None
        ask = ~self.exact_pair[near]
        sup = np.full(len(near), -np.inf)
        if ask.any():
            sup[ask] = self._support_bounds(F, np.zeros(int(ask.sum()), int), near[ask])
        for p, lb_p, a, g in zip(near.tolist(), lbs.tolist(), ask.tolist(), sup.tolist()):
            if a and g > m:
                continue
            d = lb_p if not a else self._exact_cell(F, 0, p)
            if d <= m:
                a_, b_ = self.pairs[p]
                return (self.bodies[a_].name, self.bodies[b_].name)
        return None

    def tool_rigid_refusal(self, T_tool: np.ndarray) -> tuple[str, str] | None:
        """What refuses every joint vector of this state whatever the tool pose, as the pair
        :meth:`check` would name, or None: the grasp rule when the part in the hand is given in
        the tool frame, else the first checked pair of two bodies rigid with the flange (frames 6
        and 7) within the margin. Their relative pose does not depend on q, so :meth:`check`
        refuses every row for it; ``T_tool`` (4x4, world) is any tool pose (the distances are the
        same at all of them): the answer is kept with the state."""
        if self._refusal is None:
            self._refusal = (self._tool_rigid_refusal(T_tool),)
        return self._refusal[0]

    def _tool_rigid_refusal(self, T_tool: np.ndarray) -> tuple[str, str] | None:
        if self.hand is not None and self.hand[1] == "tool":
            g_ok, g_name = self.grasp_ok(self.hand[2])
            if not g_ok:
                return (g_name, self.hand[0])
        if not self._rigid:
            return None
        F = self._tool_frames(T_tool)
        with np.errstate(invalid="ignore"):
            A, B = self._world_caps(F)
        m = self.scene.margin
        rigid = list(self._rigid)
        i, j = self.pairs[rigid, 0], self.pairs[rigid, 1]
        lbs = segment_distance(A[0, i], B[0, i], A[0, j], B[0, j]) - self._cap_r[i] - self._cap_r[j]
        for p, lb in zip(rigid, lbs.tolist()):
            if lb > m:
                continue
            d = lb if self.exact_pair[p] else self._exact_cell(F, 0, p)
            if d <= m:
                a, b = self.pairs[p]
                return (self.bodies[a].name, self.bodies[b].name)
        return None

    def _bounds(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        F = self._frames(q)
        A, B = self._world_caps(F)
        pi, pj = self.pairs[:, 0], self.pairs[:, 1]
        lb = segment_distance(A[:, pi], B[:, pi], A[:, pj], B[:, pj]) - self._cap_r[pi] - self._cap_r[pj]
        return F, lb, self._table(F)

    def _near_bounds(self, q: np.ndarray, m: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """As :meth:`_bounds`, but the capsule bound is computed only for the (row, pair) cells
        whose bounding spheres come within ``m``; the others are +inf (their capsule bound, which
        the spheres' contain, is beyond ``m`` too). Same answers as :meth:`_bounds` wherever a bound
        is <= m, at a few flops per cell instead of the segment distance's tens, which pays in
        scenes of many parts (generated cells: hundreds of part bodies, most far from the arm)."""
        F = self._frames(q)
        A, B = self._world_caps(F)
        pi, pj = self.pairs[:, 0], self.pairs[:, 1]
        C = (A + B) / 2                                          # (n, N, 3) sphere centres, world
        lb = np.full((len(q), len(pi)), np.inf)
        # first per pair over all rows at once: each body's spheres lie in their box over the rows
        # (``box_lo``, ``box_hi``), so two boxes apart by more than m (and rounding) along an axis
        # have every row's gap beyond m; only the other pairs' gaps are computed, row by row
        sr = self._sph_r
        box_lo, box_hi = C.min(axis=0) - sr[:, None], C.max(axis=0) + sr[:, None]
        reach = m + 1e-9 * (1.0 + float(np.abs(C).max(initial=0.0)) + float(sr.max(initial=0.0)))
        maybe = np.flatnonzero(np.all((box_lo[pi] <= box_hi[pj] + reach) & (box_lo[pj] <= box_hi[pi] + reach),
                                      axis=1))
        si, sj = pi[maybe], pj[maybe]
        gap = np.sqrt(((C[:, si] - C[:, sj]) ** 2).sum(-1)) - sr[si] - sr[sj]
        r, k = np.nonzero(gap <= m)
        if len(r):
            p = maybe[k]
            i, j = pi[p], pj[p]
            lb[r, p] = segment_distance(A[r, i], B[r, i], A[r, j], B[r, j]) - self._cap_r[i] - self._cap_r[j]
        return F, lb, self._table(F)

    def _exact_cell(self, F: np.ndarray, row: int, p: int) -> float:
        """The library's distance of pair ``p`` at row ``row``; a pair of two bodies rigid with
        the flange (frame 6, the tool) is measured once per state (it does not depend on q)."""
        if p in self._rigid:
            return self._rigid[p] if self._rigid[p] is not None else self._rigid_once(F, row, p)
        i, j = self.pairs[p]
        bi, bj = self.bodies[i], self.bodies[j]
        self.scene.stats["exact"] += 1
        return body_distance(bi, self._frame_pose(F, row, bi), bj, self._frame_pose(F, row, bj))

    def _support_bounds(self, F: np.ndarray, rows: np.ndarray, ps: np.ndarray) -> np.ndarray:
        """(c,) :func:`support_gap` of pair ps[k] at row rows[k] (frames F (n, 8, 4, 4)): a lower
        bound of the distance the library would measure there, all c cells in one pass of the
        directions, then one pass per body over its own vertices (a mesh part's thousands of hull
        vertices are projected only for the cells it is in, not padded into every cell)."""
        i, j = self.pairs[ps, 0], self.pairs[ps, 1]
        ub, inv = np.unique(np.concatenate([i, j]), return_inverse=True)
        used = [self.bodies[u] for u in ub.tolist()]
        axes = np.stack([b.T[:3, :3] for b in used])
        radius = np.array([b.radius for b in used])
        centre = np.stack([b.points.mean(axis=0) for b in used])
        frame = np.array([8 if b.frame == WORLD else b.frame for b in used], dtype=int)
        Fx = np.concatenate([F, np.broadcast_to(np.eye(4), (len(F), 1, 4, 4))], axis=1)  # 8: the world
        ia, ib = inv[:len(i)], inv[len(i):]
        Ga, Gb = Fx[rows, frame[ia]], Fx[rows, frame[ib]]           # (c, 4, 4) the frames' poses
        Ra, Rb = Ga[:, :3, :3], Gb[:, :3, :3]
        Ca = np.einsum("cij,cj->ci", Ra, centre[ia]) + Ga[:, :3, 3]
        Cb = np.einsum("cij,cj->ci", Rb, centre[ib]) + Gb[:, :3, 3]
        U, valid = support_directions(Ra @ axes[ia], Rb @ axes[ib], Cb - Ca)
        cheap = [b.points if b.corners is None else b.corners for b in used]
        extent = np.array([b.extent for b in used])
        gap = self._gap_pass(U, valid, ia, ib, Ga, Gb, Ra, Rb, cheap, radius, extent)
        big = np.array([b.corners is not None for b in used])
        again = np.flatnonzero((big[ia] | big[ib]) & (gap <= self.scene.margin))
        if len(again):
            full = [b.points for b in used]
            gap[again] = self._gap_pass(U[again], valid[again], ia[again], ib[again], Ga[again], Gb[again],
                                        Ra[again], Rb[again], full, radius, extent)
        return gap

    @staticmethod
    def _gap_pass(U: np.ndarray, valid: np.ndarray, ia: np.ndarray, ib: np.ndarray, Ga: np.ndarray, Gb: np.ndarray,
                  Ra: np.ndarray, Rb: np.ndarray, points: list[np.ndarray], radius: np.ndarray,
                  extent: np.ndarray) -> np.ndarray:
        """:func:`support_gap` of c cells along directions U (c, 16, 3), the bodies ia, ib (c,) of
        ``points`` (vertices each, its frame; ``extent`` each body's Body.extent) at frame poses Ga,
        Gb (c, 4, 4): each body's vertices are projected only for the cells it is in."""
        ext = []
        for side, G, R in ((ia, Ga, Ra), (ib, Gb, Rb)):
            lo, hi, big = np.empty((len(side), 16)), np.empty((len(side), 16)), np.empty(len(side))
            for n in np.unique(side).tolist():
                at = np.flatnonzero(side == n)
                pts = points[n]
                local = U[at] @ R[at]                               # (k, 16, 3): u in the body's frame
                off = np.einsum("kdj,kj->kd", U[at], G[at, :3, 3])
                proj = np.einsum("pj,kdj->kpd", pts, local) + off[:, None, :]
                lo[at], hi[at] = proj.min(axis=1), proj.max(axis=1)
                big[at] = np.abs(G[at, :3, 3]).max(axis=1) + extent[n]
            ext.append((lo, hi, big))
        (alo, ahi, abig), (blo, bhi, bbig) = ext
        return gap_of_extents(alo, ahi, radius[ia], abig, blo, bhi, radius[ib], bbig, valid)

    def _rigid_once(self, F: np.ndarray, row: int, p: int) -> float:
        i, j = self.pairs[p]
        bi, bj = self.bodies[i], self.bodies[j]
        self.scene.stats["exact"] += 1
        d = self._rigid[p] = body_distance(bi, self._frame_pose(F, row, bi), bj, self._frame_pose(F, row, bj))
        return d

    # ------------------------------------------------------------------ the grasp rule

    def _hand_in_tool(self, F: np.ndarray) -> np.ndarray | None:
        """(n, 4, 4) T_tool_part of the part in the hand per row, or None."""
        if self.hand is None:
            return None
        part, where, T = self.hand
        if where == "tool":
            return np.broadcast_to(T, (len(F), 4, 4))
        Ti = F[:, 7]
        R = np.swapaxes(Ti[:, :3, :3], 1, 2)
        inv = np.zeros_like(Ti)
        inv[:, :3, :3] = R
        inv[:, :3, 3] = -np.einsum("nij,nj->ni", R, Ti[:, :3, 3])
        inv[:, 3, 3] = 1.0
        return inv @ T

    def grasp_ok(self, T_tool_part: np.ndarray) -> tuple[bool, str | None]:
        """The grasp rule for the part in the hand at T_tool_part (4x4): no finger enters the
        part beyond its contact face and the palm does not enter it (each shrunk by GRASP_TOL_MM
        so touching counts as clear); (ok, the gripper body that enters it or None). Memoised."""
        part = self.hand[0]
        # rounded to 1e-9 and signed zeros made one (+ 0.0): a part grasped on the table, whose
        # pose in the tool each IK solution's frames give with its own rounding, finds the
        # verdict of the same grasp decided before (a -0.0 would otherwise make another key); the
        # part by its geometry (the verdict names a gripper body, never the part): renamed copies
        # of one model share it
        key = (self.scene.shape_key(part), (np.round(T_tool_part, 9) + 0.0).tobytes(),
               None if self.width is None else round(self.width, 9))
        table = self.scene.memo.table("collision.grasp", GRASP_LIMIT) if self.scene.memo is not None else None
        if table is not None and key in table:
            return table[key]
        tol = self.scene.tol
        verdict: tuple[bool, str | None] = (True, None)
        bodies = [b.placed(T_tool_part, TOOL, part) for b in self.scene.shapes_of(part)]
        gripper = self.scene.shrunk_gripper(self.width, tol)
        near = near_all(gripper, bodies, 0.0)  # (gripper box, part body): bounding capsules touch
        for gi, g in enumerate(gripper):
            if any(body_distance(g, np.eye(4), b, np.eye(4)) <= 0.0 for bi, b in enumerate(bodies) if near[gi, bi]):
                # a mesh part's body is its convex hull: the gripper in the hull may still be
                # out of the part (fingers on a peg beside its shoulder), so the mesh decides
                if self.scene.enters_mesh(part, g, T_tool_part):
                    verdict = (False, g.name)
                    break
        if table is not None:
            table[key] = verdict
        return verdict

    def _grasp_rows(self, F: np.ndarray) -> list[tuple[bool, str | None]]:
        if self.hand is None:
            return [(True, None)] * len(F)
        if self.hand[1] == "tool":  # the same relative pose on every row: decided once
            return [self.grasp_ok(self.hand[2])] * len(F)
        Th = self._hand_in_tool(F)
        return [self.grasp_ok(Th[r]) for r in range(len(F))]

    # ------------------------------------------------------------------ answers

    def clear(self, q: np.ndarray) -> np.ndarray:
        """q (n, 6) joint vectors, rad -> (n,) bool: arm, gripper and held part clear of the
        table, obstacles, other parts and each other (non-adjacent links) by the margin."""
        return self.check(q)[0]

    def check(self, q: np.ndarray) -> tuple[np.ndarray, list[tuple[str, str] | None]]:
        """As :meth:`clear`, with the first pair found closer than the margin per row (None where clear)."""
        q = np.asarray(q, float).reshape(-1, 6)
        n = len(q)
        ok = np.ones(n, dtype=bool)
        why: list[tuple[str, str] | None] = [None] * n
        if not n:
            return ok, why
        m = self.scene.margin
        F, lb, tab = self._near_bounds(q, m)
        self.scene.stats["pairs"] += lb.size + tab.size
        for r, (g_ok, g_name) in enumerate(self._grasp_rows(F)):
            if not g_ok:
                ok[r], why[r] = False, (g_name, self.hand[0])
        low = tab <= self.table_margin()
        for r, k in zip(*np.nonzero(low)):
            if ok[r]:
                ok[r], why[r] = False, (self.bodies[self.table_bodies[k]].name, "table")
        rows, ps = np.nonzero(lb <= m)
        # the library is asked only where the support bound does not already put the pair beyond
        # the margin (its distance is at least that bound: the same verdict); a pair rigid with the
        # flange is measured once per state, not here
        ask = ~self.exact_pair[ps] & ~self._is_rigid[ps] & ok[rows]
        if ask.any():
            at = np.flatnonzero(ask)
            ask[at] = self._support_bounds(F, rows[at], ps[at]) <= m
        measured: dict[tuple[int, bytes], float] = {}
        keys: dict[int, bytes] = {}
        for r, p, a in zip(rows.tolist(), ps.tolist(), ask.tolist()):
            if not ok[r]:
                continue
            if self.exact_pair[p]:
                d = lb[r, p]
            elif a or self._is_rigid[p]:
                d = self._exact_cell(F, r, p)
                if a:
                    key = keys.get(r)
                    if key is None:
                        key = keys[r] = F[r].tobytes()
                    measured[(p, key)] = d
            else:
                continue
            if d <= m:
                i, j = self.pairs[p]
                ok[r], why[r] = False, (self.bodies[i].name, self.bodies[j].name)
        self._measured = measured
        return ok, why

    def clearance(self, q: np.ndarray) -> tuple[np.ndarray, list[tuple[str, str]]]:
        """(n,) minimum distance (cell length unit; <= 0 when touching/penetrating) and, per
        row, the closest pair of named bodies, e.g. ("forearm", "shelf"). The part in the hand
        and the gripper are not a pair here (their contact is the grasp's: :meth:`grasp_ok`),
        nor a body that may touch the table and the table (``table_touch``: a part seated
        through its mate onto the plane the base rests on; :meth:`check` keeps it from sinking)."""
        q = np.asarray(q, float).reshape(-1, 6)
        F = self._frames(q)
        A, B = self._world_caps(F)
        tab = self._table(F)
        if self.table_touch is not None and tab.shape[1]:
            tab = np.where(self.table_touch[None, :], np.inf, tab)
        out = np.full(len(q), np.inf)
        names: list[tuple[str, str]] = [("", "")] * len(q)
        for r in range(len(q)):
            if tab.shape[1] and np.isfinite(tab[r]).any():
                k = int(np.argmin(tab[r]))
                out[r], names[r] = tab[r, k], (self.bodies[self.table_bodies[k]].name, "table")
            got = self._closest_pair(F, A, B, r, float(out[r]))
            if got is not None:
                out[r], names[r] = got
        return out, names

    def _closest_pair(self, F: np.ndarray, A: np.ndarray, B: np.ndarray, r: int,
                      best: float) -> tuple[float, tuple[str, str]] | None:
        """Row ``r``'s checked pair of least distance if below ``best`` (the table's), as (its
        distance, its names), else None: the pairs visited in order of their capsule bound
        (world capsule ends A, B (n, N, 3)) while that is below the least distance found, the
        library asked for the pairs that are not two capsules (its answers of the last
        :meth:`check` at these frames reused); the first pair visited at the least distance wins.

        Only the pairs whose bounding spheres come within ``best`` (and rounding) can be visited (a
        capsule bound is at least its spheres' gap), so only theirs are computed; where two of those visited
        (or the one the visit stops at) have equal bounds, the order of the whole row's sort
        decides which comes first, and the row is visited as the whole sort has it."""
        pi, pj = self.pairs[:, 0], self.pairs[:, 1]
        if np.isfinite(best):
            C = (A[r] + B[r]) / 2
            d = C[pi] - C[pj]
            reach = best + 1e-9 * (1.0 + float(np.abs(C).max(initial=0.0)) + float(self._sph_r.max(initial=0.0)))
            sub = np.flatnonzero(np.sqrt((d * d).sum(-1)) - self._sph_r[pi] - self._sph_r[pj] < reach)
        else:
            sub = np.arange(len(pi))
        i, j = pi[sub], pj[sub]
        lb = segment_distance(A[r, i], B[r, i], A[r, j], B[r, j]) - self._cap_r[i] - self._cap_r[j]
        done: dict[int, float] = {}  # the library's distances at this row, for a second visit
        tie, found = self._visit(F, r, sub, lb, best, done)
        if tie:  # a tie the order of equal bounds decides: the whole row's order
            i, j = pi, pj
            lb = segment_distance(A[r, i], B[r, i], A[r, j], B[r, j]) - self._cap_r[i] - self._cap_r[j]
            _, found = self._visit(F, r, np.arange(len(pi)), lb, best, done, ties=True)
        return found

    def _visit(self, F: np.ndarray, r: int, sub: np.ndarray, lb: np.ndarray, best: float,
               done: dict[int, float], ties: bool = False) -> tuple[bool, tuple[float, tuple[str, str]] | None]:
        """:meth:`_closest_pair`'s visit of pairs ``sub`` (their capsule bounds ``lb``) at row r:
        (a tie, the pair found below ``best`` or None).

        The least distance it finds is the row's whatever the order of equal bounds; only which
        pair is named can depend on it, where another pair with the winner's bound is at the
        winner's distance too: a tie (never with ``ties``: ``sub`` is then every pair, in the
        whole row's order)."""
        order = np.argsort(lb)
        lbs = lb[order].tolist()
        key = F[r].tobytes()
        found = None
        win = -1
        for n, p in enumerate(sub[order].tolist()):
            if lbs[n] >= best:
                break
            d = self._pair_distance(F, r, p, lbs[n], key, done)
            if d < best:
                i, j = self.pairs[p]
                best, found, win = d, (d, (self.bodies[i].name, self.bodies[j].name)), n
        if not ties and found is not None:
            p_win = int(sub[order[win]])
            for k in np.flatnonzero(lb == lbs[win]).tolist():
                p = int(sub[k])
                if p != p_win and self._pair_distance(F, r, p, float(lb[k]), key, done) == found[0]:
                    return True, found
        return False, found

    def _pair_distance(self, F: np.ndarray, r: int, p: int, lb: float, key: bytes, done: dict[int, float]) -> float:
        """Pair p's distance at row r (frames F, ``key`` their bytes): its capsule bound ``lb``
        for two capsules, else the library's (its answer of the last :meth:`check` at these
        frames, or of this row's visits ``done``, reused)."""
        if self.exact_pair[p]:
            return lb
        d = self._measured.get((p, key), done.get(p))
        if d is None:
            d = done[p] = self._exact_cell(F, r, p)
        return d


def bound_columns(state: SceneState) -> np.ndarray:
    """The columns of :func:`clearance_bounds` as body indices into ``state.bodies``: (P + T, 2),
    one row per checked pair (its two bodies), then one per table-checked body (the body, -1)."""
    tab = np.column_stack([state.table_bodies, np.full(len(state.table_bodies), -1)]).astype(int)
    return np.vstack([state.pairs.reshape(-1, 2), tab.reshape(-1, 2)])


def clearance_bounds(state: SceneState, q: np.ndarray, rate: np.ndarray | None = None,
                     want: np.ndarray | None = None) -> np.ndarray:
    """(n, P + T) sound lower bounds (cell unit) of the distance of each checked pair
    (:func:`bound_columns`) and of each table-checked body's height over the plane z = 0, for
    joint vectors q (n, 6) rad: the bounding capsules' distance, and the lowest vertex (the
    table's footprint ignored, so the bound holds wherever the body goes). The gripper and the
    part in the hand are not a column (the grasp rule decides them: :meth:`SceneState.check`).

    With ``rate`` (P + T,) (cell unit per step) and ``want`` (n,) (steps): per row, the pair
    columns are replaced by the library's exact distance (0 when touching) lazily, in order
    of (bound - margin) / rate, while that is below ``want`` and below the smallest
    (exact - margin) / rate found so far: the row's smallest ratio is then exact (or at least
    ``want``), with as few library queries as that needs."""
    q = np.asarray(q, float).reshape(-1, 6)
    F = state._frames(q)
    A, B = state._world_caps(F)
    pi, pj = state.pairs[:, 0], state.pairs[:, 1]
    lb = segment_distance(A[:, pi], B[:, pi], A[:, pj], B[:, pj]) - state._cap_r[pi] - state._cap_r[pj]
    out = np.hstack([lb, state._plane_heights(F)])
    if rate is None or want is None or not lb.size:
        return out
    m = state.scene.margin
    n_pairs = lb.shape[1]
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = np.where(rate > 0, (out - m) / rate, np.where(out > m, np.inf, -np.inf))
    for r in range(len(q)):
        best = min(float(want[r]), float(ratio[r, n_pairs:].min(initial=np.inf)))
        for p in np.argsort(ratio[r, :n_pairs]):
            if ratio[r, p] >= best:
                break
            if state.exact_pair[p]:
                best = float(ratio[r, p])
                continue
            d = out[r, p] = max(float(out[r, p]), state._exact_cell(F, r, int(p)))
            x = (d - m) / rate[p] if rate[p] > 0 else (np.inf if d > m else -np.inf)
            best = min(best, x)
            if best <= 0:
                break
    return out
