"""Phase 1 against Fast Downward (lama-first) on the same operational problems (issue 18).

Run from the project root: ``.venv/bin/python -m bench.fd [--ns 1,2,5,10,20,30,40,42,43,50]``
(the generated problems need 4N actions up to N = 70: every block turned over up to 42, turned
a quarter turn from a side face above; 2N beyond 70).

For each N, ``spar_py.app.gen.generate_assembly(N)`` is planned by our phase 1 and, in the
same run, by Fast Downward on a PDDL encoding that this module writes from the loaded
cell (:func:`pddl`):

- the operational part as SPAR's templates have it (Figs. 2-4): pickup(Obj, Grasp) from
  a position, putdown(Obj, Pos) into a stable pose, assemble(Obj1, Obj2); gripper(open),
  holding, part_location, assembled;
- the geometry as static facts, from the arcs phase 1's network uses (spar_py.world.reach.arcs,
  the same IK and placement rule): ``reach ?g ?p`` for reachable(Grasp, Position) and
  ``mate ?g ?p`` for mate_reachable(Grasp, Position, T_a) of each goal's pair, the mating
  grasps and poses of Sec. 6 (their ofaces avoid the mating faces; the hole part's initial
  positions in such a pose too, as phase 1 mates a hole-up block where it stands), the grasps and
  positions of each object. A putdown keeps its grasp (the one it was picked with).

Computing those arcs for FD is not timed (phase 1 computes them itself, inside its time;
its second run finds them memoised in the cell, so ``ours_warm_s`` is the planner
without the geometry). FD's figures are its driver's (``--alias lama-first``): the
search time and the planner time (translator, preprocessing and search), and the wall
time of the driver process (Python start included).

Fast Downward comes from the ``up-fast-downward`` wheel (PyPI), an optional bench-only
dependency (``pip install -e '.[bench]'``): its ``downward`` binary and driver are run
directly, without the unified-planning framework. Without it the rows say so.
"""
from __future__ import annotations

import argparse
import importlib.util
import json
import re
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
#: The sizes of a full run (pairs of parts).
NS = (1, 2, 5, 10, 20, 30, 40, 42, 43, 50)
#: Seconds FD may take per problem.
FD_TIMEOUT = 300.0
#: Issue 18's targets for phase 1 (s).
TARGETS = {20: 0.2, 50: 1.0}

DOMAIN = """(define (domain spar-assembly)
  (:requirements :strips :typing)
  (:types obj grasp pos)
  (:predicates (gripper-open) (holding ?o - obj ?g - grasp) (at ?o - obj ?p - pos)
               (assembled ?o1 - obj ?o2 - obj)
               (grasp-of ?g - grasp ?o - obj) (pose-of ?p - pos ?o - obj)
               (reach ?g - grasp ?p - pos) (mate ?o1 - obj ?o2 - obj ?g - grasp ?p - pos))
  (:action pickup
    :parameters (?o - obj ?g - grasp ?p - pos)
    :precondition (and (gripper-open) (at ?o ?p) (grasp-of ?g ?o) (reach ?g ?p))
    :effect (and (holding ?o ?g) (not (gripper-open)) (not (at ?o ?p))))
  (:action putdown
    :parameters (?o - obj ?g - grasp ?p - pos)
    :precondition (and (holding ?o ?g) (pose-of ?p ?o) (reach ?g ?p))
    :effect (and (at ?o ?p) (gripper-open) (not (holding ?o ?g))))
  (:action assemble
    :parameters (?o1 - obj ?o2 - obj ?g - grasp ?p - pos)
    :precondition (and (holding ?o1 ?g) (at ?o2 ?p) (mate ?o1 ?o2 ?g ?p))
    :effect (and (assembled ?o1 ?o2) (gripper-open) (not (holding ?o1 ?g)))))
"""


def _name(label: str) -> str:
    """A PDDL name for a KB label (labels are letters, digits and _; PDDL names are
    case-insensitive, so an upper-case letter becomes - and the letter: p2G1 -> p2-g1)."""
    return re.sub(r"[A-Z]", lambda m: "-" + m.group().lower(), label)


def _ofaces_at(model, T) -> set:
    """The ofaces of every stable pose of ``model`` that world transform T (4x4) is in."""
    from spar_py.core.geometry import same_stable_pose

    return {f for sp in model.poses.values() if same_stable_pose(np.asarray(T)[:3, :3], sp.R) for f in sp.ofaces}


def pddl(cell) -> str:
    """The PDDL problem of ``cell`` (a loaded spar_py Cell whose goals are assembled/5), for
    :data:`DOMAIN`. Static facts from spar_py.world.reach.arcs, as phase 1's arcs (rule "reachable")."""
    from spar_py.kb import term_text
    from spar_py.world.reach.arcs import mate_reachable_pairs, reachable_pairs
    from spar_py.world.collision import CellCache

    nm = _name
    cache = CellCache(cell)

    objs = sorted(cell.objects)
    init = []
    grasps, poses = {}, {}
    for o in objs:
        m = cell.objects[o]
        grasps[o] = list(m.grasps)
        positions = [p.label for p in cell.positions.values() if p.obj == o]
        poses[o] = list(m.poses)
        init += [f"(grasp-of {nm(g)} {nm(o)})" for g in grasps[o]]
        init += [f"(pose-of {nm(p)} {nm(o)})" for p in poses[o]]
        reach = reachable_pairs(cache, o, grasps[o], positions + poses[o]).pairs
        init += [f"(reach {nm(g)} {nm(p)})" for g, p in reach]
    for t in cell.initial:
        if t == ("gripper", "open"):
            init.append("(gripper-open)")
        elif isinstance(t, tuple) and t[0] == "part_location":
            label = next(p.label for p in cell.positions.values() if p.name == t[2])
            init.append(f"(at {nm(t[1])} {nm(label)})")
    goals = []
    for t in cell.goals:
        if not (isinstance(t, tuple) and t[0] == "assembled"):
            raise ValueError(f"{cell.file}: goal {term_text(t)}: only assembled/5 goals are encoded")
        _, peg, hole, (m1, m2), ta, _va = t
        pm, hm = cell.objects[peg], cell.objects[hole]
        gs = [lbl for lbl, gr in pm.grasps.items() if not set(gr.ofaces) & set(m1)]
        ps = [lbl for lbl, sp in hm.poses.items() if not set(sp.ofaces) & set(m2)]
        # and the hole part's absolute positions in such a pose, as phase 1 has them: a block that
        # starts hole-up is mated where it stands (without these FD had to put every block down
        # first, 4N actions for the 2N-action hole-up problems: 160/200 against 80/100)
        ps += [p.label for p in cell.positions.values()
               if p.obj == hole and not _ofaces_at(hm, p.T) & set(m2)]
        init += [f"(mate {nm(peg)} {nm(hole)} {nm(a)} {nm(b)})"
                 for a, b in mate_reachable_pairs(cache, peg, hole, gs, ps, ta).pairs]
        goals.append(f"(assembled {nm(peg)} {nm(hole)})")
    pos_labels = sorted({p.label for p in cell.positions.values()} | {p for o in objs for p in poses[o]})
    objects = (" ".join(nm(o) for o in objs) + " - obj\n    "
               + " ".join(nm(g) for o in objs for g in grasps[o]) + " - grasp\n    "
               + " ".join(nm(p) for p in pos_labels) + " - pos")
    return (f"(define (problem {nm(cell.name)}) (:domain spar-assembly)\n  (:objects\n    {objects})\n"
            f"  (:init\n    " + "\n    ".join(init) + ")\n"
            "  (:goal (and " + " ".join(goals) + ")))\n")


def fd_driver() -> Path | None:
    """The Fast Downward driver script of the up-fast-downward wheel, or None."""
    spec = importlib.util.find_spec("up_fast_downward")  # found, not imported (no unified-planning)
    if spec is None or not spec.submodule_search_locations:
        return None
    path = Path(list(spec.submodule_search_locations)[0]) / "downward" / "fast-downward.py"
    return path if path.is_file() else None


def run_fd(domain: Path, problem: Path, workdir: Path, timeout: float = FD_TIMEOUT) -> dict:
    """Fast Downward lama-first on the files: ``search_s``, ``planner_s`` (the driver's
    figures), ``wall_s`` (the driver process), ``plan_length`` or ``error``."""
    driver = fd_driver()
    if driver is None:
        return {"error": "Fast Downward not installed (pip install -e '.[bench]': up-fast-downward)"}
    t = time.perf_counter()
    try:
        r = subprocess.run([sys.executable, str(driver), "--alias", "lama-first", str(domain), str(problem)],
                           cwd=workdir, capture_output=True, text=True, timeout=timeout, check=False)
    except subprocess.TimeoutExpired:
        return {"error": f"timeout after {timeout:g} s", "wall_s": time.perf_counter() - t}
    wall = time.perf_counter() - t
    out = {"wall_s": wall}
    m = re.findall(r"Search time: ([0-9.]+)s", r.stdout)
    out["search_s"] = float(m[-1]) if m else None
    m = re.findall(r"Planner time: ([0-9.]+)s", r.stdout + r.stderr)
    out["planner_s"] = float(m[-1]) if m else None
    plan = workdir / "sas_plan"
    if plan.is_file():
        out["plan_length"] = sum(1 for ln in plan.read_text().splitlines() if ln.startswith("("))
    else:
        out["error"] = (r.stderr.strip().splitlines() or [f"exit {r.returncode}"])[-1]
    return out


def ours(cell, repeats: int = 3) -> dict:
    """Our phase 1 on ``cell`` with the default options (no flag): the first run (arcs
    computed), then the median of ``repeats`` more (arcs memoised in the cell). Prolog CPU
    seconds (plan.timing's phase1_s); ``actions``; ``outcome``."""
    from spar_py.planning.planner import Planner

    p = Planner()
    first = p.plan(cell, phase1_only=True)
    again = [p.plan(cell, phase1_only=True).timing.get("phase1_s") for _ in range(repeats)]
    return {"outcome": str(first.outcome.value if hasattr(first.outcome, "value") else first.outcome),
            "actions": len(first.actions), "first_s": first.timing.get("phase1_s"),
            "warm_s": statistics.median(again) if again else None}


def row(n: int, fd_timeout: float = FD_TIMEOUT) -> dict:
    """One N: ours and FD's figures (see the module docstring)."""
    from spar_py.app.gen import generate_assembly
    from spar_py.kb import load_problem

    with tempfile.TemporaryDirectory(prefix=f"spar-fd-{n}-") as d:
        dd = Path(d)
        cell = load_problem(generate_assembly(n, dd / "kb"))
        t = time.perf_counter()
        (dd / "domain.pddl").write_text(DOMAIN)
        (dd / "problem.pddl").write_text(pddl(cell))
        encode = time.perf_counter() - t
        fd = run_fd(dd / "domain.pddl", dd / "problem.pddl", dd, fd_timeout)
        us = ours(cell)
    return {"n": n, "ours": us, "fd": fd, "encode_s": encode}


def run(ns=NS, fd_timeout: float = FD_TIMEOUT, progress=None) -> list[dict]:
    """:func:`row` for each N, in this process (our planner) and FD's subprocesses."""
    say = progress or (lambda line: None)
    rows = []
    for n in ns:
        r = row(n, fd_timeout)
        rows.append(r)
        say(f"N = {n}: ours {r['ours']['first_s']:.3f} s first, {r['ours']['warm_s']:.3f} s warm; "
            f"FD search {r['fd'].get('search_s')} s, planner {r['fd'].get('planner_s')} s")
    return rows


def table(rows: list[dict]) -> list[str]:
    """RESULTS.md lines: one row per N, ours beside FD's from the same run."""
    def f(x, fmt=".3f"):
        return "n/a" if x is None else format(x, fmt)

    out = ["| N | actions (ours / FD) | phase 1 first (s) | phase 1 warm (s) | FD search (s) | "
           "FD planner (s) | FD wall (s) | warm / FD planner |",
           "|---|---|---|---|---|---|---|---|"]
    for r in rows:
        o, fd = r["ours"], r["fd"]
        ratio = (o["warm_s"] / fd["planner_s"]) if o.get("warm_s") and fd.get("planner_s") else None
        out.append(f"| {r['n']} | {o['actions']} / {fd.get('plan_length', fd.get('error', 'n/a'))} | "
                   f"{f(o['first_s'])} | {f(o['warm_s'])} | {f(fd.get('search_s'))} | {f(fd.get('planner_s'))} | "
                   f"{f(fd.get('wall_s'))} | {f(ratio, '.2f')} |")
    return out + [""]


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(prog="python -m bench.fd", description=__doc__.splitlines()[0])
    ap.add_argument("--ns", default=",".join(map(str, NS)), help="sizes, comma-separated (default 1..50)")
    ap.add_argument("--json", action="store_true", help="print the rows as JSON too")
    a = ap.parse_args(argv)
    rows = run([int(x) for x in a.ns.split(",")], progress=print)
    print("\n".join(table(rows)))
    if a.json:
        print(json.dumps(rows))


if __name__ == "__main__":
    main()
