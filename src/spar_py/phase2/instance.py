"""Phase 2's world along a plan instance: geometry (placements, tool poses, joint angles)
and uncertainty (uncertainty.py), evaluated a whole instance at a time.

prolog/uncertainty.pl makes every decision (which remedy, where to insert it, giving up,
verification and recovery) and, through the bridge, calls :func:`evaluate` once per run
of an instance: Python runs the whole step list and returns plain data (dicts, lists,
numbers, strings; no Python objects): each step's verdicts, its geometry, the world at
its end-point (every part's pose, the held part) and where the run stopped (ok, failed
at a step, infeasible at a step). A step is plain data from Prolog: ``{"id":
"action_2", "name": "pickup", "args": ["peg", "p1G11"]}``, the arguments as term data
(foreign.pl's term_data/2: atoms are strings, lists lists, compounds
``{"functor", "args"}``); names: pickup, putdown, assemble, dense_range_scan, squeeze.

Step results are kept in the cell's cache (world.run.CellCache), keyed by everything
that determines the world before the step, so a re-run after a remedy reuses the
prefix it shares with earlier runs, and instances (and later runs of the cell) reuse
each other's prefixes. A kept step keeps its refusals (:attr:`World.refused`), so every
run that meets it again hears why its arm did not reach.

The bounds a sensing action leaves (Fig. 11) come from the problem file's ``sensors``
entry where it has one, else from the sensing rule's bounds that Prolog passes with
the call (kb/templates/spar_sensing.pl's sensing_rule/5, in its own units, converted here by
:func:`sensing_bounds`).

An object may have several initial positions (a stock of identical parts, kb-format.md).
The world then holds one state per part: the part the plan is working with under the
object's name, each other under ``"<object>@<its initial position name>"``. Which part an
action takes comes from the plan: the *sources* of an instance (uncertainty.pl's
instance_sources/2) give, per action id, the label of the position each
``part_location(Obj, Pos)`` precondition was established at (``{"action_2": {"peg": "tr5"}}``).

Units: lengths in the cell unit, angles in radians inside, degrees in the dicts
returned for display; world frame, table top z = 0.
"""
from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import casadi as ca
import numpy as np

from spar_py.phase2 import uncertainty as ur
from spar_py.core.errors import SparValueError
from spar_py.core.model import Bounds, Cell
from spar_py.core.units import ANGLE_UNITS, LENGTH_UNITS
from spar_py.world.motion import MotionFailure, MotionOptions
from spar_py.world.collision import CellCache
from spar_py.phase2.nogood import exact_prefix, nogood
from spar_py.phase2.placements import choose_placements, placements_for
from spar_py.phase2.positions import poses, position_bounds
from spar_py.phase2.rest import STATE_CHECKS, retention_refusal
from spar_py.phase2.state import Step, World, stock_of
from spar_py.phase2.steps import moves, step
from spar_py.phase2.symbolic import Registry

if TYPE_CHECKING:
    from spar_py.world.motion import InstanceMotion

#: The instance's run is this module's; one step, the placements, the arm, the mates, the rests
#: and the parts' positions are its neighbours' (steps.py, placements.py, arm.py, mates.py,
#: rest.py, positions.py), named here too for the callers of the run.
__all__ = [
    "STATE_CHECKS",
    "Evaluation",
    "Sources",
    "Step",
    "World",
    "choose_placements",
    "evaluate",
    "moves",
    "new_world",
    "nogood",
    "poses",
    "position_bounds",
    "retention_refusal",
    "sample_check",
    "sensing_bounds",
    "step",
]

@dataclass
class Evaluation:
    """One run of a plan instance (:func:`evaluate`): ``status`` ok | failed | infeasible, ``at``
    the step id where it stopped (None if ok), ``steps`` the step records, ``refusals`` what
    its steps refused with the colliding pairs (in order), ``motion`` the instance's motions
    (world/motion/paths.py InstanceMotion), or the MotionFailure that made it infeasible, or None."""

    status: str
    at: str | None
    steps: list[dict[str, Any]]
    refusals: list[tuple[str, tuple[tuple[str, str], ...]]] = field(default_factory=list)
    motion: InstanceMotion | MotionFailure | None = None
    #: An infeasible run's nogood (phase2/nogood.py), or None.
    nogood: dict[str, Any] | None = None


def new_world(cache: CellCache, steps: list[Step], sources: Sources | None = None,
              sensing: Mapping[str, Bounds] | None = None, motion: MotionOptions | None = None) -> World:
    """The initial world for an instance whose steps (in order) are ``steps``; chooses
    every put-down placement now, knowing the later actions on the object (Sec. 5.2.4).
    ``sources`` says where each action takes its objects from (module doc), step id ->
    {obj: label}; needed only where an object has several initial positions.
    ``sensing``: the bounds each sensing action's rule leaves (cell units,
    :func:`sensing_bounds`); the cell's own ``sensors`` entries take precedence; ``motion``
    the run's motion options (their approach length shapes the placements)."""
    cell = cache.cell
    src = _inherit_sources(steps, {str(k): dict(v) for k, v in (sources or {}).items()})
    key, placements = placements_for(cache, steps, src, motion)
    active = _first_parts(cell, steps, src)
    scans = {**(sensing or {}), **{n: sn.leaves for n, sn in cell.sensors.items()}}
    unc = ur.initial_world(cell, Registry(), active=active)
    scan_key = tuple(sorted(scans.items()))
    # the key holds what the world depends on before any step; step() adds each step's own
    # inputs (its placement, its sources), so instances that agree on a prefix share it
    return World(cache, unc, placements, sources=src, active=active, scans=scans,
                 key=(tuple(sorted(active.items())), scan_key))


def sensing_bounds(cell: Cell, rules: Mapping[str, Mapping[str, Any]] | None) -> dict[str, Bounds]:
    """The bounds each sensing rule leaves, in the cell's units: ``rules`` maps a sensing
    action's name to ``{"dx": [lo, hi], "dy": ..., "dz": ..., "dtheta": [lo, hi],
    "units": {"length": "in", "angle": "deg"}}`` (uncertainty.pl's sensing data, from
    kb/templates/spar_sensing.pl's sensing_rule/5, in the units the templates state)."""
    out: dict[str, Bounds] = {}
    for name, r in (rules or {}).items():
        units = r.get("units", {})
        try:
            length = LENGTH_UNITS[str(units["length"])] / LENGTH_UNITS[cell.unit]
            angle = ANGLE_UNITS[str(units["angle"])]
        except KeyError:
            raise SparValueError(f"sensing rule {name}: units must name a length ({', '.join(LENGTH_UNITS)}) "
                                 f"and an angle ({', '.join(ANGLE_UNITS)}), got {units!r}") from None

        def iv(k: str, scale: float) -> tuple[float, float]:
            lo, hi = (float(v) for v in r[k])
            if not lo <= hi:
                raise SparValueError(f"sensing rule {name}: {k} bounds [{lo}, {hi}] are not an interval")
            return lo * scale, hi * scale

        out[str(name)] = Bounds(iv("dx", length), iv("dy", length), iv("dz", length), iv("dtheta", angle))
    return out


Sources = dict[str, dict[str, str]]


def _inherit_sources(steps: list[Step], src: dict[str, dict[str, str]]) -> dict[str, dict[str, str]]:
    """Sensing and squeezes inserted by phase 2 act on the part the next action on their
    object takes: they get that action's source."""
    out = dict(src)
    for i, s in enumerate(steps):
        if s["name"] in ("dense_range_scan", "squeeze") and s["id"] not in out:
            obj = s["args"][0]
            nxt = next((src[t["id"]][obj] for t in steps[i + 1:] if obj in src.get(t["id"], {})), None)
            if nxt is not None:
                out[s["id"]] = {obj: nxt}
    return out


def _first_parts(cell: Cell, steps: list[Step], src: dict[str, dict[str, str]]) -> dict[str, str]:
    """For each stock object, the initial position name of the part the plan takes first
    (the first position listed if the plan never says)."""
    out = {}
    for obj, ps in stock_of(cell).items():
        names = {p.label: p.name for p in ps}
        first = next((names[src[s["id"]][obj]] for s in steps
                      if obj in src.get(s["id"], {}) and src[s["id"]][obj] in names), None)
        out[obj] = first if first is not None else ps[0].name
    return out


def _all_satisfied(checks: list[dict[str, Any]], kind: str) -> bool:
    return all(c["satisfied"] for c in checks if c["kind"] == kind)


def evaluate(cache: CellCache, steps: Sequence[Step], sources: Sources | None = None,
             given_up: Sequence[str] = (), sensing: Mapping[str, Mapping[str, Any]] | None = None,
             motion: MotionOptions | None = None) -> Evaluation:
    """Run the plan instance ``steps`` (in order) of the cell of ``cache`` from its initial
    world: one call per run (planning/run.py's PlanRun.evaluate, for Prolog).

    ``sources`` as :func:`new_world`; ``given_up`` the ids of steps whose unmet
    uncertainty-reduction preconditions the run goes past (they count as errors);
    ``sensing`` the sensing rules' bounds in their own units (:func:`sensing_bounds`);
    ``motion`` the run's motion options (None: end-points only). The run stops at the first
    step whose uncertainty-reduction preconditions are not all satisfied and that is not in
    ``given_up`` (failed) or at the first whose geometric precondition fails (infeasible: no
    placement, no joint solution, no motion); each step record, up to and including that
    one, is ``{"id", "verdicts": [verdict dicts], "geometry": {"tool_pose", "joints_deg",
    "ik_solutions_deg", "placement", "source", ...}, "poses": poses(world after it), "held":
    the object in the hand after it or None}``, and in a run that went through (status ok)
    ``"position_bounds"``: :func:`position_bounds` of the world after it. Lengths in the cell
    unit, angles in degrees, world frame."""
    cell = cache.cell
    world = new_world(cache, list(steps), sources, sensing_bounds(cell, sensing), motion)
    skip = set(given_up)
    out: list[dict[str, Any]] = []
    refused: list[tuple[str, tuple[tuple[str, str], ...]]] = []
    worlds = [world]
    seen: dict[int, tuple[ur.ObjectState, list[list[float]]]] = {}
    for i, s in enumerate(steps):
        checks, world, geo = step(world, s, early=s["id"] not in skip)
        worlds.append(world)
        refused += world.refused
        out.append({"id": s["id"], "verdicts": checks, "geometry": geo,
                    "poses": poses(world, seen), "held": world.unc.holding})
        if not _all_satisfied(checks, "geometric"):
            return Evaluation("infeasible", s["id"], out, refused, nogood=nogood(worlds[-2], world, steps, i, checks))
        if not _all_satisfied(checks, "uncertainty") and s["id"] not in skip:
            return Evaluation("failed", s["id"], out, refused)
    out = _refined(cache, out, worlds)
    # a run that went through is one Prolog may report: its parts' propagated bounds, per step
    bseen: dict[int, tuple[ur.ObjectState, dict[str, list[float]]]] = {}
    out = [{**rec, "position_bounds": position_bounds(cache, w, bseen)} for rec, w in zip(out, worlds[1:])]
    if motion is not None:  # the end-points are fixed: the motions between them (world/motion/paths.py)
        from spar_py.world.motion import run_motions  # here: motion.py weighs on a cold start

        records, got = run_motions(cache, steps, worlds, out, motion)
        if isinstance(got, MotionFailure):
            at = records[-1]["id"]
            return Evaluation("infeasible", at, records, refused, got, nogood=_motion_nogood(steps, at))
        return Evaluation("ok", None, records, refused, got)
    return Evaluation("ok", None, out, refused)


def _motion_nogood(steps: Sequence[Step], at: str) -> dict[str, Any] | None:
    """The nogood of a run whose motions stop at step ``at``: the motions are planned stop after
    stop from the one before (world/motion/paths.py's plan_stops, seeded), each from the worlds
    of the steps so far, so the prefix fixes them (nogood.exact_prefix). None at a step a remedy
    inserted, and after a squeeze: a squeeze moves the arm, and a remedy may put one before the
    step for the sake of a later one (before the pickup of a part whose insertion comes later)."""
    k = next((i for i, t in enumerate(steps) if t["id"] == at), None)
    if k is None or any(t["name"] == "squeeze" for t in steps[:k + 1]):
        return None
    manip = [t for t in steps if t["name"] in ("pickup", "putdown", "assemble")]
    j = next((i for i, t in enumerate(manip) if t["id"] == at), None)
    return None if j is None else exact_prefix(manip, j)


def _refined(cache: CellCache, out: list[dict[str, Any]], worlds: list[World]) -> list[dict[str, Any]]:
    """The step records of a run that went through, with each uncertainty-reduction
    verdict's bound refined to SUP/INF's tolerance.

    The steps decide their constraints with ``decide`` (uncertainty.evaluate): SUP/INF
    stops once the verdict is settled. A run that went through is one Prolog may report,
    so its bounds are refined here, as they would have been without ``decide`` (the
    verdicts do not change). Step i's constraints are the last entries of the world after
    it, ``worlds[i + 1].checked`` (steps.py's _checked), in the order of its verdicts, and are
    bounded in that world's registry (variables' bounds never change)."""
    records = []
    for i, rec in enumerate(out):
        k = sum(1 for v in rec["verdicts"] if v["kind"] == "uncertainty")
        if not k:
            records.append(rec)
            continue
        after = worlds[i + 1]
        pairs = iter(after.checked[len(after.checked) - k:])
        verdicts = []
        for v in rec["verdicts"]:
            if v["kind"] == "uncertainty":
                c, satisfied = next(pairs)
                unit = cache.cell.unit if c.power == 1 else f"{cache.cell.unit}^{c.power}"
                v = {**ur.evaluate(c, after.unc.registry, memo=cache.memo).as_dict(), "kind": "uncertainty",
                     "unit": unit}
                if v["satisfied"] != satisfied:  # cannot happen (Bounder.bounds' beat): say so if it does
                    raise AssertionError(f"phase 2: {c.action} {c.name}: the refined verdict differs")
            verdicts.append(v)
        records.append({**rec, "verdicts": verdicts})
    return records


def sample_check(cache: CellCache, steps: list[Step], draws: int = 10_000, seed: int = 0,
                 sensing: Mapping[str, Bounds] | None = None) -> list[dict[str, Any]]:
    """Replay an instance numerically: for every uncertainty-reduction precondition checked
    along ``steps`` (in order, sensing and squeezes included), evaluate its expression at
    ``draws`` points drawn uniformly from its variables' bounds and count the draws in
    which the inequality fails. A precondition declared satisfied must never fail.
    Steps as in the plan's JSON (``id``, ``name``, ``args`` as term data); a step's
    ``source`` (which part of a stock it takes; ``from`` in a JSON written before the
    key was renamed) is honoured; ``sensing`` as
    :func:`new_world` (needed only when the cell has no sensors entry)."""
    sources = {s["id"]: s.get("source") or s["from"] for s in steps if s.get("source") or s.get("from")}
    world = new_world(cache, steps, sources, sensing)
    for s in steps:
        _, world, _ = step(world, s)
    rng = np.random.default_rng(seed)
    reg = world.unc.registry
    out = []
    for c, declared in world.checked:
        names = sorted(reg.box(c.expr))
        syms = [reg.symbol(n) for n in names]
        f = ca.Function("f", [ca.vertcat(*syms)] if syms else [ca.SX.sym("none", 0)], [c.expr])
        lo = np.array([reg.bounds(n)[0] for n in names])
        hi = np.array([reg.bounds(n)[1] for n in names])
        pts = rng.uniform(lo, hi, size=(draws, len(names))) if names else np.zeros((draws, 0))
        vals = np.asarray(f.map(draws)(pts.T)).ravel()
        bad = vals <= c.threshold if c.sense == ">" else vals >= c.threshold
        out.append({"action": c.action, "constraint": c.name, "declared_satisfied": bool(declared),
                    "failed_draws": int(bad.sum()), "min": float(vals.min()), "max": float(vals.max())})
    return out
