"""Can one arm on a table build a product? A search over the orders of insertion and the poses
the partial product rests in, by gravity alone, for a refusal that names the mate and what it
needs.

One arm puts a part in while the partial product rests on the table in one of its stable poses
(trimesh's, of the placed parts' convex hull as one body), and may turn the partial product over
between insertions (pick it up, put it down in another stable pose). A loose mate (held by
gravity: phase2.rest.retention_refusal) stays only while its insertion direction is within
LOOSE_MAX_DEG of world down, from its insertion on, in every pose the product rests in after;
an insertion whose direction points up (more than 90 deg from down) needs the product held
above the part. The search finds an order and poses that keep every loose mate, or says which
mate no pose keeps and what it needs (a fixture, a second arm, or a fixed retention). It is a
necessary condition only: a "yes" still leaves grasps, reach and collisions to the planner.

Directions and down vectors are unit vectors in the product frame; a stable pose is named by the
product-frame vector that points down in it (the outward normal of the face it rests on).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from spar_py.core.model import LOOSE_MAX_DEG, Product

__all__ = ["Insertion", "SingleArmReport", "insertions", "single_arm_report"]

#: How many poses a refusal's line names (those where the insertion points nearest down; the
#: report's ``poses`` has them all).
WHY_POSES = 3
#: Two down vectors closer than this (deg) are one pose.
SAME_POSE_DEG = 5.0


@dataclass(frozen=True)
class Insertion:
    """A non-base part's insertion: into ``parent``, along ``direction`` (product frame),
    ``retention`` 'loose' or 'fixed', ``mate`` as messages name it."""

    part: str
    parent: str
    direction: tuple[float, float, float]
    retention: str
    mate: str


@dataclass
class SingleArmReport:
    """The search's answer: ``ok`` when some order and poses keep every loose mate (``level``
    the insertions it can make only sideways); otherwise
    ``blocked`` the insertion no reachable state could make, ``why`` one line naming it and
    what it needs, ``poses`` what each stable pose of the partial product said."""

    ok: bool
    order: tuple[str, ...] = ()
    blocked: Insertion | None = None
    why: str = ""
    poses: list[str] = field(default_factory=list)
    #: When ``ok`` only with insertions more than LOOSE_MAX_DEG from down (a level tool: fixed
    #: mates put in sideways): each such insertion, its pose and its height; ``why`` then says
    #: why no order makes every insertion from above.
    level: list[str] = field(default_factory=list)

    def to_json(self) -> dict[str, Any]:
        """As plain data (the plan's JSON ``reason.single_arm``)."""
        out: dict[str, Any] = {"ok": self.ok}
        if self.ok:
            out["order"] = list(self.order)
            if self.level:
                out.update(level=self.level, why=self.why)
        else:
            out.update(part=self.blocked.part if self.blocked else None,
                       mate=self.blocked.mate if self.blocked else None, why=self.why, poses=self.poses)
        return out


def insertions(product: Product) -> list[Insertion]:
    """Each goal's insertion, its direction turned from the parent's frame into the product's."""
    by_name = {m.name: m for m in product.mates}
    out = []
    for g in product.goals:
        R = np.asarray(product.parts[g.parent].pose, float)[:3, :3]
        d = R @ np.asarray(g.V_a, float)
        d = d / max(float(np.linalg.norm(d)), 1e-300)
        mates = [by_name[n] for n in g.mates if n in by_name]
        fixed = any(m.retention == "fixed" for m in mates)
        name = mates[0].name if mates else f"{g.part} on {g.parent}"
        out.append(Insertion(g.part, g.parent, tuple(float(x) for x in d), "fixed" if fixed else "loose", name))
    return out


def _hulls(product: Product) -> dict[str, tuple[np.ndarray, float, np.ndarray]]:
    """Each part's convex hull vertices at its product pose, its volume and centre of mass
    (product frame): a partial product's hull is the hull of its parts' hull vertices."""
    from spar_py.world.parts import part_mesh

    out = {}
    for p, pp in product.parts.items():
        m = part_mesh(pp.model).copy().apply_transform(np.asarray(pp.pose, float))
        out[p] = (np.asarray(m.convex_hull.vertices, float), abs(float(m.volume)), np.asarray(m.center_mass, float))
    return out


def _downs(hulls: dict[str, tuple[np.ndarray, float, np.ndarray]], parts: frozenset[str],
           cache: dict) -> list[np.ndarray]:
    """The down vectors (product frame) of the poses ``parts`` can rest in as one body."""
    if parts not in cache:
        names = sorted(parts)  # one order whatever the hash seed: qhull's facet order follows the points'
        V = np.vstack([hulls[p][0] for p in names])
        vol = np.array([hulls[p][1] for p in names])
        com = np.sum([hulls[p][2] * v for p, v in zip(names, vol)], axis=0) / max(float(vol.sum()), 1e-300)
        cache[parts] = _rest_planes(V, com)
    return cache[parts]


def _rest_planes(V: np.ndarray, com: np.ndarray) -> list[np.ndarray]:
    """The outward normals of the convex hull of points ``V`` on whose plane the body rests: the
    centre of mass ``com`` projects into a hull face there (within a thousandth of the body's
    size); every pose it can be put down in, not only those a random drop ends in."""
    from scipy.spatial import ConvexHull, QhullError

    try:
        h = ConvexHull(V)
    except (QhullError, ValueError):
        return []
    tol = 1e-3 * float(np.ptp(V, axis=0).max())
    N = h.equations[:, :3]
    T = V[h.simplices]                                      # (m, 3, 3) the hull's triangles
    p = com - ((com - T[:, 0]) * N).sum(1)[:, None] * N     # com projected on each triangle's plane
    inside = np.ones(len(T), bool)
    for i in range(3):
        a, b, c = T[:, i], T[:, (i + 1) % 3], T[:, (i + 2) % 3]
        m = np.cross(N, b - a)
        m /= np.maximum(np.linalg.norm(m, axis=1), 1e-300)[:, None]
        m *= np.where(((c - a) * m).sum(1) < 0, -1.0, 1.0)[:, None]   # towards the third vertex
        inside &= ((p - a) * m).sum(1) >= -tol
    out: list[np.ndarray] = []
    for n in N[inside]:
        n = n / np.linalg.norm(n)
        if all(math.degrees(math.acos(max(-1.0, min(1.0, float(n @ k))))) > SAME_POSE_DEG for k in out):
            out.append(n)
    return out


def _from_down(d: tuple[float, float, float], down: np.ndarray) -> float:
    """The angle (deg) between direction ``d`` and down in the pose that rests on ``down``."""
    return math.degrees(math.acos(max(-1.0, min(1.0, float(np.asarray(d) @ down)))))


def _lost(done: list[Insertion], down: np.ndarray) -> Insertion | None:
    """The first loose insertion of ``done`` that the pose resting on ``down`` turns from down."""
    return next((i for i in done if i.retention == "loose" and _from_down(i.direction, down) > LOOSE_MAX_DEG + 1e-6),
                None)


def _pose_text(down: np.ndarray) -> str:
    """A pose named by the product axis that points down in it: 'resting on -z', 'on (0.7, 0, -0.7)'."""
    for k, axis in enumerate("xyz"):
        for s in (1.0, -1.0):
            if float(down[k]) * s > math.cos(math.radians(SAME_POSE_DEG)):
                return f"{'+' if s > 0 else '-'}{axis} down"
    return "(" + ", ".join(f"{round(float(x), 2) + 0.0:.2g}" for x in down) + ") down"


def single_arm_report(product: Product, unit: str = "") -> SingleArmReport | None:
    """None when a part has no mesh or shape (no stable pose to judge by). Otherwise: search the
    orders of insertion (the goals' parents and the product's precedence first) and the stable
    poses of each partial product for one that makes every insertion with its loose mates kept
    (module docstring); the base rests first in any of its poses. ``unit``: the product's length
    unit, for the heights the report names."""
    from spar_py.world.parts import part_mesh

    if any(part_mesh(pp.model) is None for pp in product.parts.values()):
        return None
    ins = insertions(product)
    hulls = _hulls(product)
    by_part = {i.part: i for i in ins}
    before: dict[str, set[str]] = {i.part: {i.parent} for i in ins}
    for pr in product.precedence:
        if pr.then in by_part:
            before[pr.then].add(pr.first)
    cache: dict = {}
    full = _search(product.base, ins, hulls, before, cache, 90.0)
    if full[0] is None:
        return _refusal(full[1])
    above = _search(product.base, ins, hulls, before, cache, LOOSE_MAX_DEG)
    path = above[0] if above[0] is not None else full[0]
    level = [] if above[0] is not None else [
        f"{i.part} along {_dir_text(i.direction)} resting {_pose_text(dn)}, {_from_down(i.direction, dn):.0f} deg "
        f"from down, its centre {_height(hulls, placed, i.part, dn):.4g} {unit} above the table".replace("  ", " ")
        for i, dn, placed in full[0] if _from_down(i.direction, dn) > LOOSE_MAX_DEG + 1e-6]
    return SingleArmReport(True, tuple(i.part for i, _, _ in path), level=level,
                           why="" if above[0] is not None else _refusal(above[1], "from above").why)


def _height(hulls: dict, placed: frozenset[str], part: str, down: np.ndarray) -> float:
    """How high ``part``'s centre of mass is above the table (cell unit) when ``placed`` and it
    rest on the plane whose outward normal is ``down``."""
    V = np.vstack([hulls[p][0] for p in (*placed, part)])
    return float((V @ down).max() - hulls[part][2] @ down)


def _search(base: str, ins: list[Insertion], hulls: dict, before: dict[str, set[str]], cache: dict,
            max_deg: float) -> tuple[list | None, dict[str, Any]]:
    """Depth first over (parts placed, pose): an insertion is made in a pose where its direction is
    at most ``max_deg`` from down and every loose mate made (and its own) stays; between insertions
    the partial product may rest in any pose that keeps them. (The insertions made, each with its
    pose's down vector and the parts placed before it; or None and the deepest failure.)"""
    seen: set = set()
    stuck: dict[str, Any] = {"depth": -1}

    def explain(placed: frozenset[str], nxt: Insertion, downs: list[np.ndarray], done: list[Insertion]) -> None:
        if len(placed) <= stuck["depth"]:
            return
        lines = []
        for dn in sorted(downs, key=lambda dn: (round(_from_down(nxt.direction, dn), 6), *np.round(dn, 6))):
            lost = _lost([*done, nxt], dn)
            a = _from_down(nxt.direction, dn)
            if a > max_deg + 1e-6:
                lines.append(f"{_pose_text(dn)}: {nxt.part}'s insertion points "
                             f"{'up' if a > 90.0 + 1e-6 else 'sideways'} ({a:.0f} deg from down)")
            elif lost is not None:
                lines.append(f"{_pose_text(dn)}: {lost.part} ({lost.mate}, loose) would be turned "
                             f"{_from_down(lost.direction, dn):.0f} deg from down")
        stuck.update(depth=len(placed), ins=nxt, lines=lines)

    def search(placed: frozenset[str], done: list, down: np.ndarray | None) -> list | None:
        key = (placed, None if down is None else tuple(np.round(down, 3)))
        if key in seen:
            return None
        seen.add(key)
        if len(done) == len(ins):
            return done
        made = [i for i, _, _ in done]
        downs = [dn for dn in _downs(hulls, placed, cache) if _lost(made, dn) is None]
        ready = [i for i in ins if i.part not in placed and before.get(i.part, set()) <= placed]
        for nxt in ready:
            ok = [dn for dn in downs if _from_down(nxt.direction, dn) <= max_deg + 1e-6
                  and _lost([*made, nxt], dn) is None]
            for dn in ok:
                got = search(placed | {nxt.part}, [*done, (nxt, dn, placed)], dn)
                if got is not None:
                    return got
            if not ok:
                explain(placed, nxt, _downs(hulls, placed, cache), made)
        return None

    return search(frozenset({base}), [], None), stuck


def _refusal(stuck: dict[str, Any], how: str = "") -> SingleArmReport:
    """The report of a failed search from its deepest failure (``how``: 'from above' when only
    insertions within LOOSE_MAX_DEG of down were tried)."""
    nxt = stuck.get("ins")
    if nxt is None:
        return SingleArmReport(False, why="no order of insertion respects the product's precedence")
    loose = nxt.retention == "loose" or any("loose" in ln for ln in stuck["lines"])
    needs = ("a fixed retention (a press fit: retention: in the product file), a fixture or a second arm"
             if loose else "a fixture or a second arm")
    why = (f"one arm on a table cannot insert {nxt.part} ({nxt.mate}, {nxt.retention}) along "
           f"{_dir_text(nxt.direction)}{' ' + how if how else ''}: in no stable pose of the partial product is it "
           f"made with every loose mate kept ({'; '.join(stuck['lines'][:WHY_POSES]) or 'no stable pose known'}"
           f"{'; ...' if len(stuck['lines']) > WHY_POSES else ''}): it needs {needs}")
    return SingleArmReport(False, blocked=nxt, why=why, poses=list(stuck["lines"]))


def _dir_text(d: tuple[float, float, float]) -> str:
    """A direction as the product axis it is, else its components."""
    for k, axis in enumerate("xyz"):
        for s in (1.0, -1.0):
            if d[k] * s > 1 - 1e-6:
                return f"{'+' if s > 0 else '-'}{axis}"
    return "(" + ", ".join(f"{x:.3g}" for x in d) + ")"
