"""Phase 2's put-down placements (Sec. 5.2.4): for each put-down of a plan instance, chosen
before its first step, knowing the later actions on the object, where on the free table (or on
another part's top) the arm reaches it for the put-down and for every later grasp and mate
until it is picked up again. Kept in the cell cache per manipulation sequence.
"""
from __future__ import annotations

import numpy as np

from spar_py.core.model import Cell
from spar_py.core.units import from_mm
from spar_py.world import reach
from spar_py.world.collision import CellCache
from spar_py.world.motion import MotionOptions
from spar_py.world.reach import REST_TOL_MM, part_surface
from spar_py.phase2.state import MEMO_LIMIT, Step, grasp_of, lies_at, step_key, stock_of

def placements_for(cache: CellCache, steps: list[Step], src: dict[str, dict[str, str]],
                motion: MotionOptions | None) -> tuple[tuple, dict[str, reach.Placement | None]]:
    """choose_placements memoised per cell, manipulation sequence (sensing moves nothing),
    the parts those manipulations take and the motions' approach length (None without them)."""
    manip = [s for s in steps if s["name"] in ("pickup", "putdown", "assemble")]
    length = _approach_length(cache.cell, motion)
    key = (tuple(step_key(s) for s in manip), tuple(sorted((k, tuple(sorted(v.items()))) for k, v in src.items())),
           length)
    memo = cache.table("phase2.placements", MEMO_LIMIT)
    return key, memo.get_or_compute(key, lambda: choose_placements(cache, manip, src, length))


def _approach_length(cell: Cell, motion: MotionOptions | None) -> float | None:
    """The motions' approach length (cell unit; world/motion.approach_length), None without motions."""
    if motion is None:
        return None
    from spar_py.world.motion import approach_length  # here: motion.py weighs on a cold start

    return approach_length(cell, motion)


def choose_placements(cache: CellCache, steps: list[Step], sources: dict[str, dict[str, str]] | None = None,
                      length: float | None = None) -> dict[str, reach.Placement | None]:
    """For each putdown into a stable pose, the placement nearest the object's previous spot
    at which the arm reaches the put-down grasp and every later grasp and mate on the object
    until it is picked up again, clear of every part on the table; None where no placement
    in the free regions works. ``sources`` (see instance.py's new_world) says which part of a
    stock a pickup takes; ``length`` the motions' approach length (cell unit), None without
    motions (with motions, each put-down's tool lines must be reachable too)."""
    cell = cache.cell
    src = sources or {}
    # parts on the table: initial position name or putdown id -> (object, pose)
    on_table: dict[str, tuple[str, np.ndarray]] = {p.name: (p.obj, p.T) for p in cell.positions.values()}
    last: dict[str, np.ndarray] = {}  # object -> where the part in the hand was picked from
    held: dict[str, str] = {}
    out: dict[str, reach.Placement | None] = {}
    for i, s in enumerate(steps):
        name, args = s["name"], s["args"]
        if name == "pickup":
            held[args[0]] = args[1]
            k = _taken(cell, on_table, args[0], src.get(s["id"], {}).get(args[0]))
            if k is not None:
                last[args[0]] = on_table.pop(k)[1]
        elif name == "putdown":
            obj, pos = args[0], args[1]
            prev = last.pop(obj, None)
            if pos in cell.positions:
                T = cell.positions[pos].T
                out[s["id"]] = reach.Placement(obj, cell.positions[pos].label, *T[:3, 3], 0.0, T)
            else:
                uses = [("putdown", grasp_of(cell, obj, held[obj]).T, None),
                        *_later_requirements(cell, steps[i + 1:], obj, held)]
                occupied = [reach.occupant(cache, o, T) for o, T in on_table.values()]
                near = prev[:2, 3] if prev is not None else None
                tops = _part_tops(cell, on_table, occupied, obj, steps, i)
                out[s["id"]] = reach.choose(cache, obj, pos, [X for _, X, _ in uses], occupied, near,
                                         reach=[] if length is None else _line_ends(cell, obj, pos, uses, length),
                                         tops=tops)
            held.pop(obj, None)
            if out[s["id"]] is not None:
                on_table[s["id"]] = (obj, out[s["id"]].T)
        elif name == "assemble":
            held.pop(args[0], None)
    return out


def _part_tops(cell: Cell, on_table: dict[str, tuple[str, np.ndarray]], occupied: list[reach.Occupant],
               obj: str, steps: list[Step], i: int) -> list[reach.Level]:
    """The tops of the parts on the table a put-down of ``obj`` at step ``i`` may go onto
    (placement.part_level): parts with a shape, not of ``obj``, not of a stock (a part's top is
    named by its object), that no step after ``i`` picks up and no step of the plan mates
    anything into (so the top stays where it is, bare of carried parts, while ``obj`` rests there
    until it is moved again). ``occupied``: the occupants of ``on_table``, in its order."""
    stock = stock_of(cell)
    later = {s["args"][0] for s in steps[i + 1:] if s["name"] == "pickup"}
    mated = {s["args"][1] for s in steps if s["name"] == "assemble"}
    tol = from_mm(cell.unit, REST_TOL_MM)
    out = []
    for k, (o, T) in enumerate(on_table.values()):
        model = cell.objects[o]
        if o == obj or o in stock or o in later or o in mated or not model.shape:
            continue
        top = part_surface(o, model, T, tol)
        if len(top.polygon) >= 3:
            out.append(reach.part_level(o, top.polygon, top.z, occupied[:k] + occupied[k + 1:]))
    return out


def _taken(cell: Cell, on_table: dict[str, tuple[str, np.ndarray]], obj: str, label: str | None) -> str | None:
    """The key in ``on_table`` of the part of ``obj`` a pickup from ``label`` takes: the
    part lying there, the one put down last first; else the one put down last, else the
    first part of ``obj``."""
    keys = [k for k, (o, _) in on_table.items() if o == obj]
    if label is not None:
        fit = [k for k in keys if lies_at(cell, obj, label, on_table[k][1])]
        keys = fit or keys
    initial = {p.name for p in cell.positions.values()}
    placed = [k for k in keys if k not in initial]
    if placed:
        return placed[-1]
    return keys[0] if keys else None


def _later_requirements(cell: Cell, rest: list[Step], obj: str,
                        held: dict[str, str]) -> list[tuple[str, np.ndarray, np.ndarray | None]]:
    """What later steps need of ``obj`` while it stays put: (step name, the tool transform
    relative to ``obj``'s frame, for an assemble onto it the insertion direction V_a in it)."""
    reqs: list[tuple[str, np.ndarray, np.ndarray | None]] = []
    grasps = dict(held)
    for s in rest:
        name, args = s["name"], s["args"]
        if name == "pickup":
            grasps[args[0]] = args[1]
            if args[0] == obj:
                reqs.append(("pickup", grasp_of(cell, obj, args[1]).T, None))
                break
        elif name == "assemble" and args[1] == obj and args[0] in grasps:
            reqs.append(("assemble", cell.transforms[args[3]] @ grasp_of(cell, args[0], grasps[args[0]]).T,
                         np.asarray(cell.vectors[args[4]], float)))
    return reqs


def _line_ends(cell: Cell, obj: str, pose: str, uses: list[tuple[str, np.ndarray, np.ndarray | None]],
               length: float) -> list[np.ndarray]:
    """The far ends of the approach and retreat lines of each use of ``obj`` put down in stable
    pose ``pose`` (world/motion/paths.py's line_ends), relative to its frame: world z in that frame
    is the same at every placement of the pose (they differ by a turn about world z)."""
    from spar_py.world.motion import line_ends  # here: motion.py weighs on a cold start

    up = cell.objects[obj].poses[pose].R.T @ np.array([0.0, 0.0, 1.0])
    return [T for kind, X, v in uses for T in line_ends(kind, X, up, length, v)]
