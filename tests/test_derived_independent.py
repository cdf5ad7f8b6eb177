"""Derived products checked with this file's own geometry (issue 34's independent test).

For each Fabrica assembly that derives (a refusal skips it with the refusal's text, so the test
covers an assembly as soon as it derives) and issue 33's declared products with their
declarations removed, the derivation (world/product/assembly.py through kb/products.py) is checked
against the meshes read and repaired here, with numpy and trimesh's ray-test containment only:

- (a) every insertion is free: the inserted part (or group), moved from its product pose against
  its insertion direction in steps no longer than the smallest mate clearance until its box
  clears the placed parts' box, never has a surface sample inside a part already in place
  deeper than the contact tolerance, nor a placed part's sample inside it;
- (b) every mate's axis and radii match the meshes: a cylinder fitted here to each part's
  wall (faces normal to the derived axis, vertices near the derived radius) has the same
  axis (direction and line) and radius within 1e-3 of the part's size;
- (c) the insertion order puts ``first`` before ``then`` for every precedence, and each
  precedence is real: ``first`` cannot leave with ``then`` in place.

Companions show the checks can fail: a peg moved across its axis, or along the reverse of its
insertion, is caught, a precedence's order reversed is caught, and a mate's radius or axis
perturbed by 1e-2 of the part's size is caught.
"""
from __future__ import annotations

import itertools
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest

from spar_py.core.errors import KBError
from spar_py.kb.products import load_product, load_product_derived

from paths import ROOT

FABRICA = ROOT / "kb" / "products" / "fabrica"
ASSEMBLIES = sorted(p.name for p in FABRICA.iterdir() if p.is_dir() and any(p.glob("*.ply")))
DECLARED = ("plate_pins", "bracket_kit", "shaft_stack")
#: Surface samples per part for the sweeps (area-weighted, seeded).
SAMPLES = 4000
#: Face normals count as normal to an axis when |n . d| is below this (a cylinder's wall).
SIN_WALL = 0.05
#: Relative band about the derived radius in which a wall's vertices are taken for the fit.
BAND = 0.1


@dataclass
class Case:
    """One derived product and this file's own view of it: meshes in the product frame (one
    length unit), the contact tolerance and the sweep step in that unit."""

    name: str
    res: object  # world.product.assembly.AssemblyResult
    meshes: dict
    tol: float
    step: float


# --------------------------------------------------------------------------- own geometry


def _own_mesh(path: Path, scale: float = 1.0):
    """A mesh file read as its triangles (no processing), scaled, and closed as a CAD seam needs:
    vertices within 1e-5 of the diagonal merged, triangles left degenerate dropped, holes
    filled. Refuses (assert) a mesh still open, so containment is meaningful."""
    import trimesh

    raw = trimesh.load(str(path), force="mesh", process=False)
    V = np.asarray(raw.vertices, float) * scale
    F = np.asarray(raw.faces, int)
    m = trimesh.Trimesh(V, F, process=False)
    if not m.is_watertight:
        q = 1e-5 * float(np.linalg.norm(np.ptp(V, axis=0)))
        keys, inv = np.unique(np.round(V / q).astype(np.int64), axis=0, return_inverse=True)
        F = inv.ravel()[F]
        F = F[(F[:, 0] != F[:, 1]) & (F[:, 1] != F[:, 2]) & (F[:, 0] != F[:, 2])]
        m = trimesh.Trimesh(keys * q, F, process=False)
        if not m.is_watertight:
            trimesh.repair.fill_holes(m)
    assert m.is_watertight, f"{path}: still open after merging seams"
    if m.volume < 0:
        m.invert()
    return m


def _normals(m) -> np.ndarray:
    """Unit outward face normals from the corners' cross product."""
    T = np.asarray(m.vertices, float)[np.asarray(m.faces)]
    n = np.cross(T[:, 1] - T[:, 0], T[:, 2] - T[:, 0])
    return n / np.maximum(np.linalg.norm(n, axis=1), 1e-300)[:, None]


def _surface_points(m, n: int, seed: int) -> np.ndarray:
    """``n`` points on the surface, uniform by area (seeded)."""
    T = np.asarray(m.vertices, float)[np.asarray(m.faces)]
    area = np.linalg.norm(np.cross(T[:, 1] - T[:, 0], T[:, 2] - T[:, 0]), axis=1)
    rng = np.random.default_rng(seed)
    i = rng.choice(len(T), size=n, p=area / area.sum())
    u, v = rng.random(n), rng.random(n)
    flip = u + v > 1
    u[flip], v[flip] = 1 - u[flip], 1 - v[flip]
    t = T[i]
    return t[:, 0] + u[:, None] * (t[:, 1] - t[:, 0]) + v[:, None] * (t[:, 2] - t[:, 0])


def _depth(m, pts: np.ndarray) -> np.ndarray:
    """Distance of each point to the surface of ``m`` (its depth, for points known inside)."""
    import trimesh

    return np.asarray(trimesh.proximity.closest_point(m, pts)[1], float)


def _box(meshes: list) -> tuple[np.ndarray, np.ndarray]:
    return (np.min([m.bounds[0] for m in meshes], axis=0), np.max([m.bounds[1] for m in meshes], axis=0))


def _travel(mover_box: tuple[np.ndarray, np.ndarray], other_box: tuple[np.ndarray, np.ndarray], d: np.ndarray
            ) -> float:
    """How far the box ``mover_box`` moves along unit ``d`` before it is disjoint from ``other_box``."""
    (lo_m, hi_m), (lo_o, hi_o) = mover_box, other_box
    out = []
    for i in range(3):
        if d[i] > 1e-12:
            out.append((hi_o[i] - lo_m[i]) / d[i])
        elif d[i] < -1e-12:
            out.append((lo_o[i] - hi_m[i]) / d[i])
    return max(0.0, min(out))


def penetration(movers: list, placed: list, d: np.ndarray, step: float, tol: float
                ) -> tuple[float, float] | None:
    """The first (offset, depth) at which ``movers``, moved along unit ``d`` in steps of at most
    ``step`` until their box clears ``placed``'s box, have a surface sample inside a placed part
    deeper than ``tol``, or a placed part's sample inside them deeper than ``tol``; None when the
    way is free."""
    if not placed:
        return None
    d = np.asarray(d, float) / np.linalg.norm(d)
    mine = np.vstack([_surface_points(m, SAMPLES, 11 + i) for i, m in enumerate(movers)])
    theirs = [_surface_points(q, SAMPLES, 101 + i) for i, q in enumerate(placed)]
    T = _travel(_box(movers), _box(placed), d) + step
    for k in range(int(np.ceil(T / step)) + 1):
        off = d * min(k * step, T)
        for q, tp in zip(placed, theirs):
            # the movers' points in a placed part, then the placed part's points in each mover
            depths = itertools.chain([_deepest_inside(q, mine + off)], (_deepest_inside(m, tp - off) for m in movers))
            for deep in depths:
                if deep > tol:
                    return float(off @ d), deep
    return None


def _deepest_inside(m, P: np.ndarray) -> float:
    """How deep the deepest of points P lies inside mesh ``m`` (0 when none is inside)."""
    lo, hi = m.bounds
    P = P[np.all((P >= lo) & (P <= hi), axis=1)]
    if not len(P):
        return 0.0
    inside = P[m.contains(P)]
    return float(_depth(m, inside).max()) if len(inside) else 0.0


def fit_cylinder(m, o: np.ndarray, d: np.ndarray, r: float, t0: float, t1: float
                 ) -> tuple[np.ndarray, np.ndarray, float] | None:
    """A cylinder fitted to ``m``'s wall near the line (o, d) at radius about ``r`` between
    t0 and t1 along d: the faces normal to d whose corners all lie within BAND r of radius r;
    the axis is the least eigenvector of their area-weighted normals' scatter, the circle a
    Gauss-Newton least-squares fit to their vertices across it. (point, unit axis, radius)."""
    V = np.asarray(m.vertices, float)
    F = np.asarray(m.faces)
    N = _normals(m)
    rel = V - o
    t = rel @ d
    rad = np.linalg.norm(rel - np.outer(t, d), axis=1)
    near = (np.abs(rad - r) < BAND * r) & (t > t0 - BAND * r) & (t < t1 + BAND * r)
    wall = np.all(near[F], axis=1) & (np.abs(N @ d) < SIN_WALL)
    if wall.sum() < 3:
        return None
    Tw = V[F[wall]]
    area = np.linalg.norm(np.cross(Tw[:, 1] - Tw[:, 0], Tw[:, 2] - Tw[:, 0]), axis=1)
    Nw = N[wall]
    vals, vecs = np.linalg.eigh((Nw * area[:, None]).T @ Nw)
    axis = vecs[:, 0] * (1.0 if vecs[:, 0] @ d >= 0 else -1.0)
    e1 = np.cross(axis, [1.0, 0.0, 0.0] if abs(axis[0]) < 0.9 else [0.0, 1.0, 0.0])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(axis, e1)
    W = V[np.unique(F[wall])]
    P = np.column_stack([W @ e1, W @ e2])
    c = P.mean(axis=0)
    rr = float(np.linalg.norm(P - c, axis=1).mean())
    for _ in range(50):  # Gauss-Newton on sum (|p - c| - rr)^2
        diff = P - c
        dist = np.linalg.norm(diff, axis=1)
        J = np.column_stack([-diff / dist[:, None], -np.ones(len(P))])
        step = np.linalg.lstsq(J, -(dist - rr), rcond=None)[0]
        c, rr = c + step[:2], rr + step[2]
        if np.linalg.norm(step) < 1e-14 * max(rr, 1.0):
            break
    return c[0] * e1 + c[1] * e2, axis, float(rr)


def order_violations(order: list[str], precedence: list[tuple[str, str, str]]) -> list[tuple[str, str]]:
    """The precedence pairs (first, then) that ``order`` puts the wrong way round."""
    pos = {p: i for i, p in enumerate(order)}
    return [(a, b) for a, b, *_ in precedence if pos[a] > pos[b]]


def _line_distance(p: np.ndarray, o: np.ndarray, d: np.ndarray) -> float:
    v = p - o
    return float(np.linalg.norm(v - (v @ d) * d))


def _size(m) -> float:
    return float(np.linalg.norm(np.ptp(np.asarray(m.vertices), axis=0)))


# --------------------------------------------------------------------------- the cases


def _fabrica(name: str, tmp: Path) -> Case:
    """Fabrica assembly ``name`` as a mesh-only product (cm) with its product file's tolerances
    (kb/products/fabrica/NAME.yaml: they are the meshes' data), derived; skipped with the refusal."""
    import yaml

    plys = sorted(FABRICA.joinpath(name).glob("*.ply"), key=lambda p: p.stem)
    own = yaml.safe_load(FABRICA.joinpath(f"{name}.yaml").read_text(encoding="utf-8"))
    tols = {k: float(own[k]) for k in ("contact_tol", "clearance_max") if k in own}
    text = f"product: {name}\nunits: {{length: cm, angle: deg}}\n" + "".join(
        f"{k}: {v}\n" for k, v in tols.items()) + "parts:\n" + "".join(f"  p{p.stem}: {{mesh: {p}}}\n" for p in plys)
    path = tmp / f"{name}.yaml"
    path.write_text(text)
    try:
        got = load_product_derived(path, "cm")
    except KBError as e:
        pytest.skip(f"{name} does not derive: {e}")
    if got.derived.unremovable:
        pytest.skip(f"{name}: no free direction found for {', '.join(got.derived.unremovable)}")
    meshes = {f"p{p.stem}": _own_mesh(p) for p in plys}
    return Case(name, got.derived, meshes, tols.get("contact_tol", 0.01),
                _step(got.derived, tols.get("clearance_max", 0.05)))


def _declared(name: str, tmp: Path) -> Case:
    """Declared product ``name`` written as STL meshes at its poses (mm) and derived from them."""
    import trimesh

    declared = load_product(ROOT / "kb" / "products" / f"{name}.yaml", "mm")
    lines = [f"product: {name}_meshes", "units: {length: mm, angle: deg}", "parts:"]
    for p, part in declared.parts.items():
        m = part.model.geometry.mesh().copy()
        m.apply_transform(part.pose)
        assert isinstance(m, trimesh.Trimesh)
        m.export(tmp / f"{p}.stl")
        lines.append(f"  {p}: {{mesh: {p}.stl}}")
    (tmp / "product.yaml").write_text("\n".join(lines) + "\n")
    got = load_product_derived(tmp / "product.yaml", "mm")
    meshes = {p: _own_mesh(tmp / f"{p}.stl") for p in declared.parts}
    return Case(name, got.derived, meshes, 0.1, _step(got.derived, 0.5))


def _step(res, clearance_max: float) -> float:
    """The sweep step: the smallest radial clearance of a mate, else the widest clearance fit."""
    gaps = [m.hole_radius - m.peg_radius for m in res.mates]
    return min(gaps) if gaps else clearance_max


@pytest.fixture(scope="module", params=[f"fabrica/{n}" for n in ASSEMBLIES] + [f"declared/{n}" for n in DECLARED])
def case(request: pytest.FixtureRequest, tmp_path_factory: pytest.TempPathFactory) -> Case:
    kind, name = request.param.split("/")
    tmp = tmp_path_factory.mktemp(name)
    return _fabrica(name, tmp) if kind == "fabrica" else _declared(name, tmp)


def _placed_before(res) -> list[tuple[object, list[str]]]:
    """Each insertion after the base's with the parts placed before it."""
    placed = list(res.insertions[0].parts)
    out = []
    for ins in res.insertions[1:]:
        out.append((ins, list(placed)))
        placed += list(ins.parts)
    return out


# --------------------------------------------------------------------------- the checks


def test_every_insertion_direction_is_free(case: Case) -> None:
    for ins, placed in _placed_before(case.res):
        movers = [case.meshes[p] for p in ins.parts]
        hit = penetration(movers, [case.meshes[q] for q in placed], -np.asarray(ins.direction, float),
                          case.step, case.tol)
        assert hit is None, f"{case.name}: {ins.parts} along {ins.direction} penetrates {hit} (offset, depth)"


def mate_mismatch(mesh, o: np.ndarray, d: np.ndarray, r: float, t0: float, t1: float) -> list[str]:
    """How a mate's axis (o, d) and radius r disagree with the cylinder fitted to ``mesh``'s wall
    there, beyond 1e-3 of the part's size (the direction's sine against 1e-3); empty when they agree."""
    k = 1e-3 * _size(mesh)
    got = fit_cylinder(mesh, o, d, r, t0, t1)
    if got is None:
        return [f"no wall about {d} at radius {r:.6g}"]
    c, axis, rr = got
    out = []
    if float(np.linalg.norm(np.cross(axis, d))) > 1e-3:
        out.append(f"axis {axis} not {d}")
    if _line_distance(c, o, d) > k:
        out.append(f"axis through {c}, {_line_distance(c, o, d):.3g} off")
    if abs(rr - r) > k:
        out.append(f"radius {rr:.6g} not {r:.6g}")
    return out


def _section_points(mesh, o: np.ndarray, d: np.ndarray, t: float) -> list[np.ndarray]:
    """The polylines (k, 3) where the plane through o + t d normal to d cuts ``mesh``."""
    sec = mesh.section(plane_origin=o + t * d, plane_normal=d)
    return [] if sec is None else [np.asarray(x, float) for x in sec.discrete]


def _point_segment_distance(P: np.ndarray, A: np.ndarray, B: np.ndarray) -> np.ndarray:
    """For each point of P (n, 3), its distance to the nearest segment A[i] B[i] (m, 3 each)."""
    AB = B - A
    L2 = np.maximum(np.einsum("ij,ij->i", AB, AB), 1e-300)
    u = np.clip(np.einsum("nmj,mj->nm", P[:, None, :] - A[None], AB) / L2, 0.0, 1.0)
    Q = A[None] + u[..., None] * AB[None]
    return np.linalg.norm(P[:, None, :] - Q, axis=2).min(axis=1)


def prism_mismatch(peg, hole, m) -> list[str]:
    """How a prism mate disagrees with plane sections of its meshes across the axis, at seven
    heights inside the overlap of the peg's and the hole's walls: the peg's section centred on
    the axis (its bounding rectangle in the corners' frame, within 1e-3 of the peg's size),
    inside the corners' rectangle (what the insertion check's corner constraints rely on), and
    the clearance (hole radius - peg radius) the least gap between the two sections."""
    k = 1e-3 * _size(peg)
    o, d = np.asarray(m.origin, float), np.asarray(m.axis, float)
    C = np.asarray(m.corners, float)
    if len(C) != 4:
        return [f"{len(C)} corners, not 4"]
    e1 = C[0] - C[1] if np.linalg.norm(C[0] - C[1]) > 1e-12 else C[0] - C[2]
    e1 = e1 - (e1 @ d) * d
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(d, e1)
    cu, cv = C @ e1, C @ e2
    lo = max(m.peg_t0, m.hole_t0)
    hi = min(m.peg_t0 + m.peg_len, m.hole_t0 + m.hole_len)
    out, gaps = [], []
    for t in np.linspace(lo + 0.15 * (hi - lo), hi - 0.15 * (hi - lo), 7):
        reach = 2.0 * float(np.abs(C).max()) + m.hole_radius
        near = [x[np.linalg.norm((x - o) - np.outer((x - o) @ d, d), axis=1) < reach]
                for x in _section_points(peg, o, d, t)]
        pp = np.vstack([x for x in near if len(x)]) if any(len(x) for x in near) else np.zeros((0, 3))
        if len(pp) < 3:
            out.append(f"no peg section at t {t:.4g}")
            continue
        rel = pp - o
        u, v = rel @ e1, rel @ e2
        centre = np.array([(u.min() + u.max()) / 2, (v.min() + v.max()) / 2])
        if np.linalg.norm(centre) > k:
            out.append(f"peg section at t {t:.4g} centred {np.linalg.norm(centre):.3g} off the axis")
        if u.min() < cu.min() - k or u.max() > cu.max() + k or v.min() < cv.min() - k or v.max() > cv.max() + k:
            out.append(f"peg section at t {t:.4g} outside the corners' rectangle")
        segs = [np.stack([x[:-1], x[1:]], axis=1) for x in _section_points(hole, o, d, t) if len(x) > 1]
        if segs:
            S = np.vstack(segs)
            mid = (S[:, 0] + S[:, 1]) / 2 - o
            S = S[np.linalg.norm(mid - np.outer(mid @ d, d), axis=1) < reach]
            if len(S):
                gaps.append(float(_point_segment_distance(pp, S[:, 0], S[:, 1]).min()))
    if not gaps:
        out.append("no hole section in the overlap")
    elif abs(min(gaps) - (m.hole_radius - m.peg_radius)) > k:
        out.append(f"clearance {m.hole_radius - m.peg_radius:.6g}, sections' least gap {min(gaps):.6g}")
    return out


def test_every_mate_matches_the_meshes(case: Case) -> None:
    for m in case.res.mates:
        o, d = np.asarray(m.origin, float), np.asarray(m.axis, float)
        if m.profile == "prism":
            bad = prism_mismatch(case.meshes[m.peg], case.meshes[m.hole], m)
            assert not bad, f"{case.name}: {m.peg} in {m.hole} (prism): {'; '.join(bad)}"
            continue
        for part, r, t0, ln in ((m.peg, m.peg_radius, m.peg_t0, m.peg_len),
                                (m.hole, m.hole_radius, m.hole_t0, m.hole_len)):
            bad = mate_mismatch(case.meshes[part], o, d, r, t0, t0 + ln)
            assert not bad, f"{case.name}: {m.peg} in {m.hole}, on {part}: {'; '.join(bad)}"


def test_the_order_respects_the_precedence(case: Case) -> None:
    order = [p for ins in case.res.insertions for p in ins.parts]
    assert sorted(order) == sorted(case.meshes)
    assert order_violations(order, case.res.precedence) == []
    # each precedence is real: first cannot leave along its direction with then in place
    direction = {p: -np.asarray(i.direction, float) for i in case.res.insertions for p in i.parts}
    for first, then, _ in case.res.precedence:
        hit = penetration([case.meshes[first]], [case.meshes[then]], direction[first], case.step, case.tol)
        assert hit is not None, f"{case.name}: {first} leaves freely with {then} in place"


# --------------------------------------------------------------------------- the checks can fail


def test_a_wrong_direction_is_caught(case: Case) -> None:
    """Across the axis of a mate with a part in place, and (a peg into a blind hole) further
    along its insertion, the sweep meets the placed parts."""
    mates = case.res.mates
    if not mates:
        pytest.skip(f"{case.name}: no mate")
    tried = 0
    for ins, placed in _placed_before(case.res):
        for m in mates:
            ends = {m.peg, m.hole}
            if not (ends & set(ins.parts) and ends & set(placed)):
                continue
            d = np.asarray(m.axis, float)
            side = np.cross(d, [1.0, 0.0, 0.0] if abs(d[0]) < 0.9 else [0.0, 1.0, 0.0])
            movers, others = [case.meshes[p] for p in ins.parts], [case.meshes[q] for q in placed]
            assert penetration(movers, others, side, case.step, case.tol) is not None, (case.name, m.peg, m.hole)
            if not m.through and m.peg in ins.parts:
                assert penetration(movers, others, np.asarray(ins.direction, float), case.step, case.tol) is not None
            tried += 1
            break
    assert tried, f"{case.name}: no insertion makes a mate with a placed part"


def test_a_wrong_order_is_caught(case: Case) -> None:
    if not case.res.precedence:
        pytest.skip(f"{case.name}: no precedence")
    order = [p for ins in case.res.insertions for p in ins.parts]
    first, then, _ = case.res.precedence[0]
    i, j = order.index(first), order.index(then)
    order[i], order[j] = order[j], order[i]
    assert (first, then) in order_violations(order, case.res.precedence)


def test_a_wrong_mate_is_caught(case: Case) -> None:
    """A radius, an axis line or an axis direction off by 1e-2 (of the part's size, or radians)."""
    if not case.res.mates:
        pytest.skip(f"{case.name}: no mate")
    rounds = [m for m in case.res.mates if m.profile == "round"]
    if not rounds:
        _a_wrong_prism_is_caught(case)
        return
    m = rounds[0]
    mesh = case.meshes[m.peg]
    k = 1e-2 * _size(mesh)
    o, d = np.asarray(m.origin, float), np.asarray(m.axis, float)
    side = np.cross(d, [1.0, 0.0, 0.0] if abs(d[0]) < 0.9 else [0.0, 1.0, 0.0])
    side /= np.linalg.norm(side)
    t0, t1 = m.peg_t0, m.peg_t0 + m.peg_len
    assert mate_mismatch(mesh, o, d, m.peg_radius, t0, t1) == []
    assert any("radius" in x for x in mate_mismatch(mesh, o, d, m.peg_radius + k, t0, t1))
    assert any("off" in x for x in mate_mismatch(mesh, o + 0.5 * m.peg_radius * BAND * side, d, m.peg_radius, t0, t1))
    tilted = d + 1e-2 * side
    assert any("axis" in x for x in mate_mismatch(mesh, o, tilted / np.linalg.norm(tilted), m.peg_radius, t0, t1))


def _a_wrong_prism_is_caught(case: Case) -> None:
    """A prism mate's clearance off by 1e-2 of the part's size, or its corners shrunk by it."""
    from dataclasses import replace

    m = case.res.mates[0]
    peg, hole = case.meshes[m.peg], case.meshes[m.hole]
    k = 1e-2 * _size(peg)
    assert prism_mismatch(peg, hole, m) == []
    assert any("clearance" in x for x in prism_mismatch(peg, hole, replace(m, hole_radius=m.hole_radius + k)))
    C = np.asarray(m.corners, float)
    shrunk = tuple(tuple(c * (1 - k / np.linalg.norm(c))) for c in C)
    assert any("corners" in x for x in prism_mismatch(peg, hole, replace(m, corners=shrunk)))


# --------------------------------------------------------------------------- the precedence picture


def _dot_graph(text: str) -> tuple[dict[str, str], dict[tuple[str, str], str]]:
    """Nodes (name -> label) and edges ((u, v) -> tooltip) of DOT text as precedence_dot writes it."""
    import re

    nodes = {m[1]: m[2] for m in re.finditer(r'^  "([^"]+)" \[label="([^"]*)"', text, re.M)}
    edges = {(m[1], m[2]): m[3] for m in re.finditer(r'^  "([^"]+)" -> "([^"]+)" \[.*tooltip="([^"]*)"', text, re.M)}
    return nodes, edges


def test_the_precedence_picture_has_every_part_and_edge(case: Case) -> None:
    from spar_py.pictures.precedence import insertion_node, precedence_dot

    nodes, edges = _dot_graph(precedence_dot(case.res, case.name))
    drawn = {p for n in nodes for p in n.split("+")}
    assert drawn == set(case.meshes)
    owner = {p: insertion_node(i) for i in case.res.insertions for p in i.parts}
    for i, ins in enumerate(case.res.insertions[1:], start=2):
        assert nodes[insertion_node(ins)].startswith(f"{i}. ")
        assert "along [" in nodes[insertion_node(ins)]
    for first, then, why in case.res.precedence:
        if owner[first] != owner[then]:
            assert why in edges[owner[first], owner[then]]
    assert len(edges) <= len(case.res.precedence)


def test_kb_derive_draws_the_stool_precedence(tmp_path: Path) -> None:
    """``spar kb derive --dot --png`` on Fabrica's stool: the DOT has its nine parts and four
    precedence edges, and the PNG is a picture."""
    import subprocess
    import sys

    plys = sorted(FABRICA.joinpath("stool_circular").glob("*.ply"), key=lambda p: p.stem)
    (tmp_path / "stool.yaml").write_text("product: stool_circular\nunits: {length: cm, angle: deg}\nparts:\n" + "".join(
        f"  p{p.stem}: {{mesh: {p}}}\n" for p in plys))
    cmd = [sys.executable, "-m", "spar_py", "kb", "derive", str(tmp_path / "stool.yaml"), "--dot",
           str(tmp_path / "s.dot"), "--png", str(tmp_path / "s.png")]
    r = subprocess.run(cmd, capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    precedence = [ln for ln in r.stdout.splitlines() if ln.startswith("# precedence: ")]
    nodes, edges = _dot_graph((tmp_path / "s.dot").read_text())
    assert set(nodes) == {f"p{i}" for i in range(9)}
    assert len(precedence) == len(edges) > 0
    for ln in precedence:  # "# precedence: p5 before p8 (p8 in place blocks p5's insertion)"
        a, _, rest = ln.removeprefix("# precedence: ").partition(" before ")
        b, _, why = rest.partition(" (")
        assert edges[a, b] == why.removesuffix(")")
    assert (tmp_path / "s.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
