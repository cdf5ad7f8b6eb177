"""Collision checking speed (issue 15's must-show), each figure beside its peer from the same run.

Run from the project root: ``.venv/bin/python -m bench.collision [--repeats 5] [--quick]``.

- ``per solution``: time per IK solution checked, batched (SceneState.check on every in-limit IK
  solution of every block grasp at every point of a 1 in grid over the cell's free table, the
  block grasped where the tool is, as phase 1's reach arcs and placements ask): the paper's
  cell, and a generated cell of MAX_PARTS pairs (the world layer's heaviest scene here).
  Goal: at most 20 us.
- ``warm``: Planner().plan of kb/problems/peg_in_block.yaml in this process (median of the
  repeats after one warm-up), against the same cell with ``collision: false`` (a copy written
  to a temporary directory). Goal: at most 50 ms.
- ``cold``: ``spar plan`` of each as a fresh process (median). Goal: at most 0.6 s.

- ``libraries`` (with ``--coal-python PY``, a Python with both ``coal`` and ``python-fcl``, e.g.
  a throwaway venv under /tmp: coal is a 300 MB install and never a project dependency): the
  exact queries the paper cell's per-solution run sends to the library (recorded from
  world.collision.bodies.body_distance: the body shapes and their world poses) replayed with python-fcl and
  with coal in that interpreter, us per query (collide, then distance when apart, as
  body_distance asks) and the largest difference of their distances.
"""
from __future__ import annotations

import argparse
import json
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
CELL = ROOT / "kb" / "problems" / "peg_in_block.yaml"
BIN = Path(sys.executable).parent
GOALS = {"per_solution_us": 20.0, "warm_ms": 50.0, "cold_s": 0.6}


def _no_collision_copy(tmp: Path) -> Path:
    """The paper's cell with ``collision: false``, its KB files beside it as they resolve."""
    kb = tmp / "kb"
    shutil.copytree(ROOT / "kb", kb)
    p = kb / "problems" / "peg_in_block_nocol.yaml"
    p.write_text(CELL.read_text(encoding="utf-8").replace("problem: peg_in_block", "problem: peg_in_block_nocol")
                 + "\ncollision: false\n", encoding="utf-8")
    return p


def per_solution(cell, obj: str, repeats: int) -> dict[str, float]:
    """Median us per IK solution checked: every grasp of ``obj`` at a 1 in grid of xy over the
    cell's first free region, in its first stable pose, the part grasped (one batched check)."""
    from spar_py.world.reach.workspace import ik_rows
    from spar_py.world.collision import CellCache

    model = cell.objects[obj]
    pose = next(iter(model.poses.values()))
    reg = (cell.placement_regions or [{"x": [-20, 20], "y": [-20, 20]}])[0]
    step = 1.0 if cell.unit == "in" else 25.4
    xs = np.arange(reg["x"][0], reg["x"][1], step)
    ys = np.arange(reg["y"][0], reg["y"][1], step)
    TO = np.tile(np.eye(4), (len(xs) * len(ys), 1, 1))
    TO[:, :3, :3] = pose.R
    TO[:, 0, 3], TO[:, 1, 3] = np.repeat(xs, len(ys)), np.tile(ys, len(xs))
    TO[:, 2, 3] = pose.height
    scene = CellCache(cell).scene()
    work = []  # per grasp: its state (the part in the hand where the tool is) and its IK rows
    for g in model.grasps.values():
        Q, ok = ik_rows(cell, TO @ g.T)
        work.append((scene.at({}, None, obj, width=g.width, attached={obj: np.linalg.inv(g.T)}), Q[ok]))
    for state, q in work:
        state.check(q[:10])  # warm the library import and the grasp memo
    n = sum(len(q) for _, q in work)
    times = []
    for _ in range(repeats):
        t = time.perf_counter()
        for state, q in work:
            state.check(q)
        times.append(time.perf_counter() - t)
    # the peer, same rows: the capsule bound on every (row, pair) cell (no sphere broad phase)
    from spar_py.world.collision.state import SceneState

    plain = []
    near = SceneState._near_bounds
    try:
        SceneState._near_bounds = lambda self, q, m: self._bounds(q)
        for _ in range(repeats):
            t = time.perf_counter()
            for state, q in work:
                state.check(q)
            plain.append(time.perf_counter() - t)
    finally:
        SceneState._near_bounds = near
    return {"solutions": n, "us": 1e6 * statistics.median(times) / max(n, 1),
            "us_no_broad_phase": 1e6 * statistics.median(plain) / max(n, 1)}


def record_queries(cell, obj: str, limit: int = 2000) -> list[dict]:
    """The exact (library) queries of one per-solution run of ``cell``, as plain data: each body's
    kind, size, local vertices and world pose (4x4 of its shape)."""
    from spar_py.world.collision import state as col  # the module whose checks ask the library

    out: list[dict] = []
    real = col.body_distance

    def spy(b1, T1, b2, T2):
        if len(out) < limit:
            out.append({"a": _body(b1, T1 @ b1.T), "b": _body(b2, T2 @ b2.T)})
        return real(b1, T1, b2, T2)

    col.body_distance = spy
    try:
        per_solution(cell, obj, 1)
    finally:
        col.body_distance = real
    return out


def _body(b, T: np.ndarray) -> dict:
    Tinv = np.linalg.inv(b.T)
    local = b.points @ Tinv[:3, :3].T + Tinv[:3, 3]
    return {"kind": b.kind, "size": list(b.size), "points": local.tolist(), "T": T.tolist()}


# replayed in the --coal-python interpreter: python-fcl and coal on the same queries
_LIBS = r"""
import json, math, sys, time
import numpy as np
from scipy.spatial import ConvexHull
import coal, fcl
Q = json.load(sys.stdin)
SIDES = 16

def geom(lib, b):
    k, s = b["kind"], b["size"]
    if k == "box":
        return lib.Box(*(2 * np.asarray(s)))
    if k == "capsule":
        return lib.Capsule(s[0], 2 * s[1])
    if k == "cylinder":
        return lib.Cylinder(s[0] * math.cos(math.pi / SIDES), 2 * s[1])
    pts = np.asarray(b["points"], float)
    if lib is coal:
        return coal.Convex.convexHull(pts, False, None)
    h = ConvexHull(pts)
    idx = {int(v): i for i, v in enumerate(h.vertices)}
    faces = np.array([[3, idx[int(a)], idx[int(c)], idx[int(d)]] for a, c, d in h.simplices])
    return fcl.Convex(pts[h.vertices], len(faces), faces.ravel())

def run_fcl(pairs):
    out = []
    for g1, T1, g2, T2 in pairs:
        o1 = fcl.CollisionObject(g1, fcl.Transform(T1[:3, :3], T1[:3, 3]))
        o2 = fcl.CollisionObject(g2, fcl.Transform(T2[:3, :3], T2[:3, 3]))
        if fcl.collide(o1, o2, fcl.CollisionRequest(), fcl.CollisionResult()):
            out.append(0.0)
        else:
            out.append(max(float(fcl.distance(o1, o2, fcl.DistanceRequest(), fcl.DistanceResult())), 0.0))
    return out

def run_coal(pairs):
    out = []
    for g1, T1, g2, T2 in pairs:
        t1, t2 = coal.Transform3s(T1[:3, :3], T1[:3, 3]), coal.Transform3s(T2[:3, :3], T2[:3, 3])
        r = coal.CollisionResult()
        if coal.collide(g1, t1, g2, t2, coal.CollisionRequest(), r):
            out.append(0.0)
        else:
            d = coal.DistanceResult()
            out.append(max(float(coal.distance(g1, t1, g2, t2, coal.DistanceRequest(), d)), 0.0))
    return out

res = {}
for name, lib, fn in (("python-fcl", fcl, run_fcl), ("coal", coal, run_coal)):
    pairs = [(geom(lib, q["a"]), np.asarray(q["a"]["T"]), geom(lib, q["b"]), np.asarray(q["b"]["T"])) for q in Q]
    fn(pairs[:20])
    best = None
    for _ in range(3):
        t = time.perf_counter()
        d = fn(pairs)
        dt = time.perf_counter() - t
        best = dt if best is None or dt < best else best
    res[name] = {"us": 1e6 * best / max(len(pairs), 1), "d": d}
t = time.perf_counter(); import importlib; res["queries"] = len(Q)
a, b = np.array(res["python-fcl"].pop("d")), np.array(res["coal"].pop("d"))
res["max_abs_diff"] = float(np.abs(a - b).max()) if len(a) else 0.0
res["verdict_differs"] = int(((a <= 0) != (b <= 0)).sum())
print(json.dumps(res))
"""


def libraries(coal_python: str) -> dict:
    """python-fcl against coal on the paper cell's own exact queries (see the module notes)."""
    from spar_py.kb import load_problem

    qs = record_queries(load_problem(CELL), "block")
    r = subprocess.run([coal_python, "-c", _LIBS], input=json.dumps(qs), capture_output=True, text=True,
                       timeout=600, check=False)
    if r.returncode:
        return {"error": r.stderr.strip().splitlines()[-1] if r.stderr.strip() else f"exit {r.returncode}"}
    return json.loads(r.stdout)


def warm(path: Path, repeats: int) -> float:
    from spar_py.planning.planner import Planner

    planner = Planner()
    planner.plan(path)
    times = []
    for _ in range(repeats):
        t = time.perf_counter()
        planner.plan(path)
        times.append(time.perf_counter() - t)
    return 1e3 * statistics.median(times)


def cold(path: Path, repeats: int) -> float:
    times = []
    for _ in range(repeats):
        t = time.perf_counter()
        subprocess.run([str(BIN / "spar"), "plan", str(path)], capture_output=True, check=True, cwd=ROOT, timeout=300)
        times.append(time.perf_counter() - t)
    return statistics.median(times)


def run(repeats: int = 5, quick: bool = False, coal_python: str | None = None) -> dict:
    from spar_py.app import gen
    from spar_py.kb import load_problem

    out: dict = {"goals": GOALS}
    with tempfile.TemporaryDirectory() as d:
        tmp = Path(d)
        nocol = _no_collision_copy(tmp)
        out["per_solution"] = {"paper": per_solution(load_problem(CELL), "block", repeats)}
        if not quick:
            big = load_problem(gen.generate_assembly(gen.MAX_PARTS, tmp / "gen"))
            out["per_solution"][f"assembly_{gen.MAX_PARTS}"] = per_solution(big, "block1", repeats)
        out["warm_ms"] = {"collision": warm(CELL, repeats), "no collision": warm(nocol, repeats)}
        k = max(1, repeats // 2)
        out["cold_s"] = {"collision": cold(CELL, k), "no collision": cold(nocol, k)}
    if coal_python:
        out["libraries"] = libraries(coal_python)
    return out


def render(r: dict) -> list[str]:
    L = ["## Collision checking (bench/collision.py)", "", "| measure | collision | peer | goal |", "|---|---|---|---|"]
    for k, v in r["per_solution"].items():
        L.append(f"| us per IK solution checked, {k} ({v['solutions']} solutions) | {v['us']:.1f} | "
                 f"{v['us_no_broad_phase']:.1f} (no sphere broad phase) | "
                 f"<= {GOALS['per_solution_us']:g} |")
    w, c = r["warm_ms"], r["cold_s"]
    L.append(f"| paper cell warm (ms) | {w['collision']:.1f} | {w['no collision']:.1f} (collision: false) | "
             f"<= {GOALS['warm_ms']:g} |")
    L.append(f"| paper cell cold spar plan (s) | {c['collision']:.2f} | {c['no collision']:.2f} (collision: false) | "
             f"<= {GOALS['cold_s']:g} |")
    lib = r.get("libraries")
    if lib and "error" not in lib:
        L += ["", f"Exact queries of the paper cell's per-solution run ({lib['queries']}), replayed:", "",
              "| library | us per query |", "|---|---|",
              f"| python-fcl | {lib['python-fcl']['us']:.1f} |", f"| coal | {lib['coal']['us']:.1f} |", "",
              f"Largest distance difference {lib['max_abs_diff']:.2g} (cell unit); touching verdicts that "
              f"differ: {lib['verdict_differs']}."]
    elif lib:
        L += ["", f"Library comparison failed: {lib['error']}"]
    return L + [""]


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m bench.collision")
    p.add_argument("--repeats", type=int, default=5)
    p.add_argument("--quick", action="store_true")
    p.add_argument("--json", action="store_true")
    p.add_argument("--coal-python", default=None, metavar="PY",
                   help="a Python with coal and python-fcl installed (a throwaway venv): compare the libraries")
    a = p.parse_args(argv)
    r = run(a.repeats, a.quick, a.coal_python)
    print(json.dumps(r, indent=1) if a.json else "\n".join(render(r)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
