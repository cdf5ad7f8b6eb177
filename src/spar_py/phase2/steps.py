"""One step of a phase 2 plan instance (:func:`step`): its preconditions' verdicts, the world
after it and its geometry for display, memoised in the cell cache by everything that determines
the world before it. A step is plain data from Prolog (instance.py's module doc); names: pickup,
putdown, assemble, dense_range_scan, squeeze (:data:`STEPS`).
"""
from __future__ import annotations

import math
from dataclasses import replace
from typing import Any

import numpy as np

from spar_py.phase2 import uncertainty as ur
from spar_py.core.errors import SparValueError
from spar_py.core.model import Cell
from spar_py.world.reach import reachable_pairs, rest_of_body, surfaces_of
from spar_py.phase2.arm import arm_for, no_arm, via_part
from spar_py.phase2.mates import (
    carried_mate, made_links, mate_constraints, mate_features, mate_retention, product_mate,
    wrong_way,
)
from spar_py.phase2.rest import retention_refusal, stacked_on
from spar_py.phase2.state import MEMO_LIMIT, Refusals, Step, World, grasp_of, hashable, lies_at, model_of, step_key

#: Entries of the cell cache's table of a squeezed part's reach arc at its position (:func:`_squeeze`).
SQUEEZE_ARCS = 64


def step(world: World, s: Step, early: bool = False) -> tuple[list[dict[str, Any]], World, dict[str, Any]]:
    """The verdicts of step ``s``'s preconditions in ``world``, the world after it, and its
    geometry for display (tool pose, joint angles in degrees, placement).

    ``early``: the caller stops at this step if one of its uncertainty-reduction
    preconditions fails (instance.py's evaluate unless the step is given up), so its verdicts
    may end at the first unsatisfied one (in order): the run's outcome is the same and
    the rest are never bounded. A memoised step so cut short is computed again, whole,
    when a later run needs every verdict (the step given up)."""
    handler = STEPS.get(s["name"])
    if handler is None:
        raise SparValueError(f"phase 2 cannot execute {s['name']!r}")
    place = world.placements.get(s["id"]) if s["name"] == "putdown" else None
    key = world.key + ((step_key(s), hashable(world.sources.get(s["id"], {})),
                        None if place is None else (place.pose, place.T.tobytes())),)

    def run() -> tuple[list[dict[str, Any]], World, dict[str, Any], bool]:
        before = replace(_activate(world, s), refused=())
        checks, after, geo = handler(before, s, early)
        if s["id"] in world.sources:
            geo["source"] = dict(world.sources[s["id"]])
        geo["moves"] = moves(before, s)
        return checks, replace(after, key=key), geo, not (early and not after.complete)

    table = world.cache.table("phase2.steps", MEMO_LIMIT)
    hit = table.get(key)
    if hit is None or not (early or hit[3]):
        hit = table[key] = run()
    checks, after, geo, _ = hit
    # a world from the memo may come from another instance: keep this instance's plan data
    return checks, replace(after, placements=world.placements, sources=world.sources, complete=True), geo


def moves(world: World, s: Step) -> list[str]:
    """The parts step ``s`` moves in ``world`` (the world before it): the body of its object (the
    object, then every part mated into it, directly or transitively); none for a sensing step."""
    if s["name"] not in ("pickup", "putdown", "assemble", "squeeze"):
        return []
    obj = str(s["args"][0])
    return world.unc.body(obj) if obj in world.unc.objects else [obj]


def _activate(world: World, s: Step) -> World:
    """``world`` with the parts step ``s`` takes (its sources) made the active parts of
    their stock objects; the part they replace keeps its state under ``obj@origin``."""
    for obj, label in world.sources.get(s["id"], {}).items():
        if obj not in world.active:
            continue
        key = _part_at(world, obj, label)
        if key is None or key == obj:
            continue
        objs = dict(world.unc.objects)
        retired = f"{obj}@{world.active[obj]}"
        objs[retired] = replace(objs.pop(obj), name=retired)
        objs[obj] = replace(objs.pop(key), name=obj)
        names = {obj: retired, key: obj}  # the mates follow their parts
        attached = {names.get(c, c): replace(a, parent=names.get(a.parent, a.parent))
                    for c, a in world.unc.attached.items()}
        world = replace(world, unc=replace(world.unc, objects=objs, attached=attached),
                        active={**world.active, obj: key.split("@", 1)[1]})
    return world


def _part_at(world: World, obj: str, label: str) -> str | None:
    """The world key of the part of stock object ``obj`` lying at position ``label`` (an
    initial position's label, or a stable pose): the active part if it is there."""
    parts = world.unc.objects
    keys = [obj] + [k for k in parts if k.startswith(f"{obj}@")]
    return next((k for k in keys if parts[k].where == ur.TABLE and lies_at(world.cell, obj, label, parts[k].pose)),
                None)


def _reach_verdict(action: str, ok: bool, what: str, constraint: str = "reachable") -> dict[str, Any]:
    return {"action": action, "constraint": constraint, "kind": "geometric", "sense": "",
            "bound": None, "threshold": None, "satisfied": ok, "tolerance_reached": True,
            "description": what}


def _verdicts(world: World, cs: list[ur.Constraint], early: bool = False) -> list[dict[str, Any]]:
    """The verdicts of ``cs`` in order; with ``early`` up to the first unsatisfied one."""
    if early:
        return _verdicts_until_unsatisfied(world, cs)
    out = []
    for v in ur.evaluate_all(cs, world.unc.registry, memo=world.cache.memo, decide=True):
        d = v.as_dict()
        d["kind"] = "uncertainty"
        out.append(d)
    return out


def _verdicts_until_unsatisfied(world: World, cs: list[ur.Constraint]) -> list[dict[str, Any]]:
    """The verdicts of ``cs`` in order, up to and including the first unsatisfied one."""
    out = []
    for c in cs:
        d = ur.evaluate(c, world.unc.registry, memo=world.cache.memo, decide=True).as_dict()
        d["kind"] = "uncertainty"
        out.append(d)
        if not d["satisfied"]:
            break
    return out


def _checked(world: World, cs: list[ur.Constraint], checks: list[dict[str, Any]]) -> tuple:
    """``world.checked`` extended by this step's constraints and their verdicts."""
    ur_checks = [c for c in checks if c["kind"] == "uncertainty"]
    return world.checked + tuple((c, v["satisfied"]) for c, v in zip(cs, ur_checks))


def _pickup(world: World, s: Step, early: bool = False) -> tuple[list[dict], World, dict]:
    obj, label = s["args"][0], s["args"][1]
    g = grasp_of(world.cell, obj, label)
    o = world.unc.obj(obj)
    manip = world.unc.manipulator_error()
    what = f"pickup({obj}, {label})"
    via = via_part(world.cell, obj, label)
    carried = via is None or via in world.unc.body(obj)[1:]
    cs = ur.pickup_constraints(world.unc, obj, g.T, g.width, world.cell.finger_separation, manip, action=s["id"],
                               memo=world.cache.memo, via=via if carried else None)
    checks = _verdicts(world, cs, early)
    if not carried:
        checks.append(_reach_verdict(s["id"], False, f"{what} holds {obj} by {via}, which {obj} does not carry "
                                     f"(not mated into it)", "via_grasp"))
    q, geo, refused = arm_for(world, o.pose @ g.T, what, grasped=via if via in world.unc.objects else obj,
                           width=g.width)
    if q is None:
        checks.append(_reach_verdict(s["id"], False, no_arm(what, geo)))
    on = stacked_on(world, obj)
    if on is not None:
        checks.append(_reach_verdict(s["id"], False, f"pickup({obj}) would leave {on} unsupported: it rests on "
                                     f"{obj}'s body, not mated into it", "supported"))
    unc = ur.pickup(world.unc, obj, g.T, manip, world.cache.memo)
    lost = retention_refusal(unc, f"pickup({obj})")
    if lost is not None:
        checks.append(_reach_verdict(s["id"], False, lost, "retention"))
    w = replace(world, refused=refused, unc=unc,
                grasps={**world.grasps, obj: label},
                joints=q if q is not None else world.joints, checked=_checked(world, cs, checks),
                complete=sum(c["kind"] == "uncertainty" for c in checks) == len(cs))
    return checks, w, geo


def _putdown(world: World, s: Step, early: bool = False) -> tuple[list[dict], World, dict]:
    obj = s["args"][0]
    place = world.placements.get(s["id"])
    if place is None:
        checks = [_reach_verdict(s["id"], False, f"no placement in the free table regions where the arm "
                                 f"reaches {obj} for this put-down and the actions after it")]
        return checks, world, {"tool_pose": None, "joints_deg": None, "placement": None}
    g = grasp_of(world.cell, obj, world.grasps[obj])
    what = f"putdown({obj})"
    unc = ur.putdown(world.unc, obj, place.T, world.cache.memo)
    body = unc.body(obj)
    carried = [(c, world.cell.objects[model_of(c)], unc.obj(c).pose) for c in body[1:]]
    under = [(k, world.cell.objects[model_of(k)], o.pose) for k, o in unc.objects.items()
             if k not in body and o.where == ur.TABLE and k not in unc.attached]
    need = world.cell.product.sub_poses.get(obj, {}).get(place.pose) if world.cell.product is not None else None
    on = rest_of_body(world.cell, obj, place.T, surfaces_of(world.cell, under), carried,
                      combined=need is not None and set(body[1:]) == set(need))
    surface = on.surface.name if on is not None and on.surface is not None else "table"  # the step's own contact
    q, geo, refused = arm_for(world, place.T @ g.T, what, held=(obj, np.linalg.inv(g.T)), width=g.width,
                           allow=[(f"held:{obj}", n) for n in dict.fromkeys(("table", surface))],
                           via=via_part(world.cell, obj, world.grasps[obj]))
    geo["placement"] = place.as_dict()
    checks = [] if q is not None else [_reach_verdict(s["id"], False, no_arm(what, geo))]
    if need is not None and set(body[1:]) != set(need):
        checks.append(_reach_verdict(s["id"], False, f"{what} in {place.pose}, a pose of {obj} with "
                                     f"{', '.join(need)} mated in, but {obj} carries "
                                     f"{', '.join(body[1:]) or 'nothing'}", "sub_pose"))
    elif on is not None and not on.ok:
        checks.append(_reach_verdict(s["id"], False, f"{what} leaves {obj} unstable: it {on.why}", "stable"))
    lost = retention_refusal(unc, what)
    if lost is not None:
        checks.append(_reach_verdict(s["id"], False, lost, "retention"))
    grasps = {k: v for k, v in world.grasps.items() if k != obj}
    w = replace(world, refused=refused, unc=unc, grasps=grasps, joints=q if q is not None else world.joints)
    return checks, w, geo


def _assemble(world: World, s: Step, early: bool = False) -> tuple[list[dict], World, dict]:
    peg, hole, faces, ta, va = s["args"][0], s["args"][1], s["args"][2], s["args"][3], s["args"][4]
    cell = world.cell
    Ta = cell.transforms[ta]
    g = grasp_of(cell, peg, world.grasps[peg])
    goal_hole, goal_Ta = hole, Ta
    goal_va = np.asarray(cell.vectors[va], float) if isinstance(va, str) and va in cell.vectors else None
    made = made_links(world, peg, goal_hole)
    hole, Ta, faces = carried_mate(world, peg, hole, faces, Ta)
    va_vec = goal_va
    if va_vec is not None and hole != goal_hole:  # V_a is in the goal parent's frame: into the mated part's
        va_vec = (world.unc.obj(hole).pose[:3, :3].T @ world.unc.obj(goal_hole).pose[:3, :3]) @ va_vec
    pair = product_mate(cell, peg, hole, faces, Ta)
    if pair is None:
        fp, fh = mate_features(cell, peg, hole, faces)
    else:
        fp, fh = pair
    if cell.product is not None and cell.product.goal_of(peg) is not None:
        # every peg-hole mate the insertion makes, each where its peg meets its mouth
        cs = mate_constraints(world, peg, goal_hole, goal_Ta, made, goal_va, s["id"])
    else:
        cs = [] if fp is None else ur.assemble_constraints(
            world.unc, peg, hole, Ta, fp, fh, action=s["id"], memo=world.cache.memo, axis=va_vec)
    checks = _verdicts(world, cs, early)
    _floors(world, cs, checks)
    what = f"assemble({peg}, {goal_hole})"
    for why in wrong_way(world, made, goal_hole, goal_va):
        checks.append(_reach_verdict(s["id"], False, f"{what} cannot make {why}", "direction"))
    near = cell.product.near.get(peg, ()) if cell.product is not None else ()
    q, geo, refused = arm_for(world, world.unc.obj(goal_hole).pose @ goal_Ta @ g.T, what,
                           held=(peg, np.linalg.inv(g.T)), width=g.width,
                           allow=[(f"held:{peg}", o) for o in dict.fromkeys((goal_hole, hole, *near))],
                           via=via_part(cell, peg, world.grasps[peg]), touch=True)
    if q is None:
        checks.append(_reach_verdict(s["id"], False, no_arm(what, geo)))
    if cell.product is not None:
        geo["mates"] = [m.link.name for m in made]
        tight = tightest(checks)
        if tight is not None:
            geo["tightest"] = tight
    grasps = {k: v for k, v in world.grasps.items() if k != peg}
    margin = 0.0 if fp is None else max(0.0, float(fh.radius) - float(fp.radius))
    retention, mate = mate_retention(cell, peg, hole, fh, made)
    unc = ur.assemble(world.unc, peg, hole, Ta, retention=retention, direction=va_vec, clearance=margin,
                      axis=None if fp is None else va_vec, mate=mate)
    # a non-product cell's goal asks for this mate as the paper's cells make it (the insertion itself
    # is not held to gravity); once made, its part is loose like any other when its body moves
    lost = retention_refusal(unc, what) if cell.product is not None else retention_refusal(
        replace(unc, attached={k: a for k, a in unc.attached.items() if k != peg}), what)
    if lost is not None:
        checks.append(_reach_verdict(s["id"], False, lost, "retention"))
    w = replace(world, refused=refused, unc=unc, grasps=grasps,
                joints=q if q is not None else world.joints, checked=_checked(world, cs, checks),
                complete=sum(c["kind"] == "uncertainty" for c in checks) == len(cs))
    return checks, w, geo


def _floors(world: World, cs: list[ur.Constraint], checks: list[dict[str, Any]]) -> None:
    """Each unsatisfied insertion check of ``checks`` (in place, in ``cs``'s order) with its
    ``floor`` (uncertainty.clearance_floor: what the mates' clearances alone make it reach) and
    ``remediable``: False when the floor is not below the threshold, so no scan or squeeze can
    make it hold (phase 2 gives the step up without trying them), and then ``depends``: the
    parts whose mates the floor reads (the mate's two parts, each up its body to the root): a
    plan instance with those parts mated the same way before the step meets the same failure."""
    offsets = [v for a in world.unc.attached.values() for v in a.offsets]
    product = world.cell.product
    for c, d in zip(cs, checks):
        if d["satisfied"] or not offsets:
            continue
        floor = ur.clearance_floor(c, world.unc.registry, offsets)
        if floor is None:
            continue
        d["floor"] = floor
        d["remediable"] = floor < float(d["threshold"])
        mate = next((m for m in (product.mates if product is not None else ()) if m.name == c.mate), None)
        if mate is not None and not d["remediable"]:
            # what the floor reads: the mate's two parts and the chain of mates that carries each
            # (their attachments' relative poses, axes and clearances), not any grasp or position
            d["depends"] = list(dict.fromkeys(world.unc.path_to_root(mate.peg) + world.unc.path_to_root(mate.hole)))


def tightest(checks: list[dict[str, Any]]) -> dict[str, Any] | None:
    """The insertion check of ``checks`` with the least room: the largest bound over threshold,
    as lengths (a squared check's square roots): ``{"mate", "constraint", "bound", "threshold",
    "satisfied"}`` (cell unit), or None without an insertion check."""
    best, key = None, -math.inf
    for c in checks:
        if c.get("kind") != "uncertainty" or c.get("sense") != "<" or not c.get("mate"):
            continue
        p = int(c.get("power") or 1)
        b = max(float(c["bound"]), 0.0) ** (1.0 / p)
        t = max(float(c["threshold"]), 0.0) ** (1.0 / p)
        r = b / t if t > 0 else math.inf
        if r > key:
            best, key = {"mate": c["mate"], "constraint": c["constraint"], "bound": b, "threshold": t,
                         "satisfied": bool(c["satisfied"])}, r
    return best


def _scan(world: World, s: Step, early: bool = False) -> tuple[list[dict], World, dict]:
    obj = s["args"][0]
    leaves = world.scans.get(s["name"])
    geo = {"tool_pose": None, "joints_deg": None}
    if leaves is None:
        return [_reach_verdict(s["id"], False, f"neither the cell nor a sensing rule says what {s['name']} "
                               "leaves")], world, geo
    return [], replace(world, unc=ur.dense_range_scan(world.unc, obj, leaves)), geo


def _squeeze(world: World, s: Step, early: bool = False) -> tuple[list[dict], World, dict]:
    """Squeeze ``obj`` in place with the first of its grasps the arm reaches there whose pickup
    preconditions hold (Sec. 4.3: the squeeze must meet the pickup's own preconditions).
    A grasp's constraints are checked one by one, up to the first that fails, then the arm's
    joint solution (only the chosen grasp's verdicts are reported; the arm's refusals only of
    grasps whose constraints hold)."""
    obj = s["args"][0]
    cell = world.cell
    o = world.unc.obj(obj)
    labels = tuple(_position_label(cell, obj, o))
    # the arc is the cell's alone (no other part in it): kept, a plan squeezes one part many times
    arc = world.cache.table("phase2.squeeze_arcs", SQUEEZE_ARCS).get_or_compute(
        (obj, labels), lambda: reachable_pairs(world.cache, obj, list(cell.objects[obj].grasps), list(labels)))
    refused: Refusals = tuple((r.what, r.pairs) for r in arc.refusals)
    manip = world.unc.manipulator_error()
    for label in (g for g, _ in arc.pairs):
        g = grasp_of(cell, obj, label)
        # the grasp's constraints first: bounding them is cheap beside the arm's collision check
        # with every part in place, and a grasp they refuse is no candidate whatever the arm does
        cs = ur.pickup_constraints(world.unc, obj, g.T, g.width, cell.finger_separation, manip, action=s["id"],
                                   memo=world.cache.memo)
        checks = _verdicts_until_unsatisfied(world, cs)
        if not (len(checks) == len(cs) and all(c["satisfied"] for c in checks)):
            continue
        q, geo, no = arm_for(world, o.pose @ g.T, f"squeeze({obj}) with {label}", grasped=obj, width=g.width,
                          hand_first=True)
        refused += no
        if q is not None:
            geo["grasp"] = label
            w = replace(world, refused=refused, unc=ur.squeeze(world.unc, obj, g.T, manip, world.cache.memo),
                        joints=q,
                        checked=_checked(world, cs, checks))
            return checks, w, geo
    return ([_reach_verdict(s["id"], False, f"no grasp of {obj} both reachable and sure to succeed for a squeeze")],
            replace(world, refused=refused), {"tool_pose": None, "joints_deg": None})


def _position_label(cell: Cell, obj: str, o: ur.ObjectState) -> list[str]:
    """The label of ``obj``'s current table pose for the reach check: its initial absolute
    position if it is still there, else the stable pose its rotation is in."""
    labels = [p.label for p in cell.positions.values() if p.obj == obj] + list(cell.objects[obj].poses)
    return [lbl for lbl in labels if lies_at(cell, obj, lbl, o.pose)][:1]


STEPS = {
    "pickup": _pickup,
    "putdown": _putdown,
    "assemble": _assemble,
    "dense_range_scan": _scan,
    "squeeze": _squeeze,
}
