"""Cold start: `spar plan` of the paper's cell as a fresh process, against the import floor (issue 18).

Run from the project root: ``.venv/bin/python -m bench.coldstart [--repeats 15] [--quick]``.

Each round runs these fresh processes one after the other, so all see the same machine
load (the order rotates from round to round); the figures are medians over the rounds:

- ``floor``: ``python -c "import numpy, casadi, janus_swi"`` (importing janus starts
  the embedded SWI-Prolog): what any process of this design pays before planning;
- ``plan``: ``spar plan kb/problems/peg_in_block.yaml``, SWI-Prolog started from the
  planner's saved state (spar_py/planning/qlf.py: janus and the planner in one file; the cache is
  filled first, and the package's bytecode brought up to date, so no process compiles an
  edited module);
- ``plan, image``: the same with ``SPAR_SAVED_STATE=off``: SWI-Prolog started as janus
  does, the planner loaded from its compiled .qlf image in a thread meanwhile;
- ``plan, sources``: the same with ``SPAR_QLF_CACHE=off``: the Prolog consulted from
  prolog/*.pl and kb/templates/*.pl at every start, as before the image;
- ``floor, frozen exit``: the floor ending as ``spar`` does (cli.exiting: ``gc.freeze()``, so
  the shutdown collections skip the heap, then ``os._exit``, without the interpreter's
  teardown), the like-for-like floor of a process that exits so;
- ``engine``, ``engine, image`` and ``engine, sources``: ``python -c "import spar_py.planning.engine
  as e; e.engine()"``, the engine start alone, each way;
- with ``--peer DIR`` (another checkout of spar-py, e.g. ``git archive`` of an older commit
  unpacked there): ``plan, peer``, the same ``spar plan`` with ``DIR/src`` first on
  PYTHONPATH (this venv's libraries, that checkout's spar_py, prolog/ and kb/templates/),
  so a change is measured against its base in the same rounds.

Beside them, from ``python -X importtime`` of cold plans: what the plan imports beyond
the floor (self time by top-level package, medians), and which heavy libraries a cold
plan of the paper's cell imports at all (trimesh, fcl, coal, ompl, yourdfpy, scipy,
matplotlib, distributed, ...).
"""
from __future__ import annotations

import argparse
import collections
import json
import os
import resource
import statistics
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
CELL = "kb/problems/peg_in_block.yaml"
BIN = Path(sys.executable).parent
FLOOR = "import numpy, casadi, janus_swi"
ENGINE = "import spar_py.planning.engine as e; e.engine()"
#: The target of issue 18: cold `spar plan` of the paper's cell over the floor.
TARGET_RATIO = 1.5
#: Libraries the world layer and the tools may bring; a cold plan of the paper's cell
#: should import none of them.
HEAVY = ("trimesh", "fcl", "coal", "hppfcl", "ompl", "yourdfpy", "scipy", "matplotlib", "networkx",
         "manifold3d", "distributed", "dask", "roboticstoolbox", "spatialmath", "PIL", "pandas", "sympy")


def _peer_env(peer: str | Path) -> dict[str, str]:
    """The environment that runs checkout ``peer``'s spar_py with this venv."""
    return {"PYTHONPATH": os.pathsep.join([str(Path(peer).resolve() / "src"), *filter(None, [
        os.environ.get("PYTHONPATH")])])}


def _commands(peer: str | Path | None = None) -> dict[str, tuple[list[str], dict[str, str]]]:
    """Name -> (argv, extra environment) of each timed process."""
    py = sys.executable
    off = {"SPAR_QLF_CACHE": "off"}
    image = {"SPAR_SAVED_STATE": "off"}
    plan = [str(BIN / "spar"), "plan", CELL]
    cmds = {"floor": ([py, "-c", FLOOR], {}),
            "floor, frozen exit": ([py, "-c", FLOOR + "; import gc, os; gc.freeze(); os._exit(0)"], {}),
            "plan": (plan, {}),
            "plan, image": (plan, image),
            "plan, sources": (plan, off),
            "engine": ([py, "-c", ENGINE], {}),
            "engine, image": ([py, "-c", ENGINE], image),
            "engine, sources": ([py, "-c", ENGINE], off)}
    if peer is not None:
        cmds["plan, peer"] = (plan, _peer_env(peer))
    return cmds


def _time(argv: list[str], env: dict[str, str]) -> tuple[float, float]:
    """(wall seconds, CPU seconds user + system) of one run of ``argv`` (its only child)."""
    c0 = resource.getrusage(resource.RUSAGE_CHILDREN)
    t = time.perf_counter()
    r = subprocess.run(argv, cwd=ROOT, env={**os.environ, **env}, stdout=subprocess.DEVNULL,
                       stderr=subprocess.PIPE, timeout=120, check=False)
    dt = time.perf_counter() - t
    c1 = resource.getrusage(resource.RUSAGE_CHILDREN)
    if r.returncode != 0:
        raise RuntimeError(f"{' '.join(argv)} exited {r.returncode}: {r.stderr.decode()[-300:]}")
    return dt, (c1.ru_utime - c0.ru_utime) + (c1.ru_stime - c0.ru_stime)


def _compile_bytecode(src: Path) -> None:
    """Bring the package's bytecode (__pycache__) up to date, as an installed package has it:
    with PYTHONDONTWRITEBYTECODE set, a module edited since set-up would otherwise be compiled
    again by every timed process (tens of ms on the figures)."""
    import compileall

    compileall.compile_dir(str(src), quiet=1)


def _fill_cache(env: dict[str, str] | None = None) -> str:
    """Make sure the planner's image is in the cache (as set-up does); how it was loaded."""
    code = "from spar_py.planning.engine import Engine; print(Engine().loaded_from)"
    out = subprocess.run([sys.executable, "-c", code],
                         cwd=ROOT, capture_output=True, text=True, check=True, env={**os.environ, **(env or {})})
    return out.stdout.strip()


def importtime(runs: int = 5) -> dict:
    """``-X importtime`` of ``runs`` cold plans and as many floor processes.

    Keys: ``beyond_floor`` [(package, median ms)] of the modules a plan imports that the
    floor does not (self time summed by top-level package; spar_py by module), largest
    first; ``beyond_floor_ms`` their sum; ``heavy`` the HEAVY libraries a cold plan imported;
    ``modules`` how many modules a plan imports beyond the floor."""
    def imported(argv: list[str]) -> dict[str, int]:
        r = subprocess.run([sys.executable, "-X", "importtime", *argv], cwd=ROOT, capture_output=True, text=True,
                           timeout=120, check=False)
        us: dict[str, int] = {}
        for line in r.stderr.splitlines():
            if line.startswith("import time:") and "self [us]" not in line:
                parts = line.split("|")
                us[parts[2].strip()] = int(parts[0].split(":")[1])
        return us

    floor_mods: set[str] = set()
    per: dict[str, list[float]] = collections.defaultdict(list)
    heavy: set[str] = set()
    counts = []
    for _ in range(runs):
        floor_mods |= set(imported(["-c", FLOOR]))
        plan = imported(["-m", "spar_py", "plan", CELL])
        heavy |= {m.split(".")[0] for m in plan if m.split(".")[0] in HEAVY}
        extra = {m: t for m, t in plan.items() if m not in floor_mods}
        counts.append(len(extra))
        groups: collections.Counter[str] = collections.Counter()
        for m, t in extra.items():
            top = m.split(".")[0]
            groups[".".join(m.split(".")[:2]) if top == "spar_py" else top] += t
        for g, t in groups.items():
            per[g].append(t / 1000)
    med = sorted(((g, statistics.median(v + [0.0] * (runs - len(v)))) for g, v in per.items()),
                 key=lambda x: -x[1])
    return {"runs": runs, "beyond_floor": med, "beyond_floor_ms": sum(t for _, t in med),
            "heavy": sorted(heavy), "modules": statistics.median(counts)}


#: The child of :func:`breakdown`: ``spar plan`` (cli.main itself) with its steps timed.
CHILD = r"""
import importlib.abc, importlib.machinery, json, os, sys, time
t0 = time.perf_counter()
marks = {}
def timed(name, fn):
    def run(*a, **k):
        t = time.perf_counter()
        try:
            return fn(*a, **k)
        finally:
            marks[name] = marks.get(name, 0.0) + time.perf_counter() - t
    return run
PATCH = {"spar_py.kb": ("load_problem", "load_problem (YAML, checks)"),
         "spar_py.planning.planner": ("Planner.plan", "Planner.plan (first plan: lazy imports, compute)"),
         "spar_py.planning.engine": ("start_engine",
                            "start engine (import janus: SWI-Prolog from the saved state, else the loader started)")}
class Patcher(importlib.abc.MetaPathFinder):
    # wrap a function of a module once the module has run (so imports keep their real order)
    def find_spec(self, name, path, target=None):
        if name not in PATCH:
            return None
        spec = importlib.machinery.PathFinder.find_spec(name, path)
        run = spec.loader.exec_module
        def exec_module(module):
            run(module)
            attr, label = PATCH[name]
            owner, _, fn = attr.rpartition(".")
            obj = getattr(module, owner) if owner else module
            setattr(obj, fn, timed(label, getattr(obj, fn)))
        spec.loader.exec_module = exec_module
        return spec
sys.meta_path.insert(0, Patcher())
from spar_py.startup.entry import hold_collections, keep_compiled_methods  # as the spar script (entry.main)
hold_collections()
keep_compiled_methods()
import spar_py.app.cli as cli
marks["import spar_py.app.cli"] = time.perf_counter() - t0
out = sys.stdout
sys.stdout = open(os.devnull, "w")
try:
    cli.main(["plan", sys.argv[1]])
except SystemExit:
    pass
total = time.perf_counter() - t0
eng = sys.modules["spar_py.planning.engine"]._engine
# the same plan again in this warm process, on a freshly loaded cell: what is not one-off
kept = dict(marks)
from spar_py.kb import load_problem
from spar_py.planning.planner import Planner
cell = load_problem(sys.argv[1])
t = time.perf_counter()
Planner().plan(cell)
again = time.perf_counter() - t
out.write(json.dumps({"marks": kept, "total": total, "load_s": eng.load_s, "loaded_from": eng.loaded_from,
                      "again": again, "elapsed": time.perf_counter() - t0}) + "\n")
out.flush()
cli.exiting(0)  # as the spar script ends (its code: the plan ran)
"""


def breakdown(runs: int = 5) -> dict:
    """Where a cold ``spar plan`` spends its wall time: ``runs`` children running cli.main
    with its steps timed; medians (s) of each step, of "interpreter start and exit" (the
    parent's wall time minus the child's own) and of "other" (the rest of the child's time:
    the imports between the steps, printing); "planner loaded": the time until the planner
    was loaded, within the engine start when SWI-Prolog starts from the saved state, else
    the loading thread's (overlapping the steps); "Planner.plan again": the same plan once more in that process on
    a freshly loaded cell, after the cold run (what the first plan costs beyond one-off work)."""
    per: dict[str, list[float]] = collections.defaultdict(list)
    loaded = set()
    for _ in range(runs):
        t = time.perf_counter()
        r = subprocess.run([sys.executable, "-c", CHILD, CELL], cwd=ROOT, capture_output=True, text=True,
                           timeout=120, check=True)
        wall = time.perf_counter() - t
        doc = json.loads(r.stdout.strip().splitlines()[-1])
        steps = dict(doc["marks"])
        per["interpreter start and exit"].append(wall - doc["elapsed"])
        for k, v in steps.items():
            per[k].append(v)
        per["other (imports between the steps, output)"].append(doc["total"] - sum(steps.values()))
        per["planner loaded (engine start from the state, else the loading thread; overlaps)"].append(doc["load_s"])
        per["Planner.plan again (not in the cold run: same process, fresh cell)"].append(doc["again"])
        loaded.add(doc["loaded_from"])
    return {"runs": runs, "steps": {k: statistics.median(v) for k, v in per.items()}, "loaded_from": sorted(loaded)}


def run(repeats: int = 15, importtime_runs: int = 5, peer: str | Path | None = None) -> dict:
    """The cold-start figures: medians (s) by command name in ``median`` (wall) and ``cpu``
    (user + system), every wall time in ``runs``, ``ratio`` plan/floor (wall), ``ratio_cpu``,
    ``ratio_sources`` plan from sources/floor, ``engine_saving_s``, ``plan_saving_s``, the
    import breakdown in ``imports``; with ``peer`` (a checkout), ``peer`` its directory and
    ``ratio_peer`` its plan over the floor."""
    _compile_bytecode(ROOT / "src")
    first = _fill_cache()
    if peer is not None:
        _compile_bytecode(Path(peer) / "src")
        _fill_cache(_peer_env(peer))
    cmds = _commands(peer)
    names = list(cmds)
    runs: dict[str, list[float]] = {n: [] for n in names}
    cpu: dict[str, list[float]] = {n: [] for n in names}
    for n in names:  # one unrecorded round: the OS file cache, bytecode
        _time(*cmds[n])
    for i in range(repeats):
        for n in names[i % len(names):] + names[:i % len(names)]:
            wall, c = _time(*cmds[n])
            runs[n].append(wall)
            cpu[n].append(c)
    med = {n: statistics.median(v) for n, v in runs.items()}
    med_cpu = {n: statistics.median(v) for n, v in cpu.items()}
    extra = {} if peer is None else {"peer": str(peer), "ratio_peer": med["plan, peer"] / med["floor"]}
    return {**extra, "repeats": repeats, "cache_before": first, "median": med, "runs": runs, "cpu": med_cpu,
            "ratio_cpu": med_cpu["plan"] / med_cpu["floor"],
            "ratio": med["plan"] / med["floor"], "ratio_sources": med["plan, sources"] / med["floor"],
            "ratio_image": med["plan, image"] / med["floor"],
            "ratio_frozen": med["plan"] / med["floor, frozen exit"],
            "engine_saving_s": med["engine, sources"] - med["engine, image"],
            "plan_saving_s": med["plan, sources"] - med["plan, image"],
            "state_engine_saving_s": med["engine, image"] - med["engine"],
            "state_plan_saving_s": med["plan, image"] - med["plan"],
            "target": TARGET_RATIO, "imports": importtime(importtime_runs),
            "breakdown": breakdown(max(importtime_runs, 1))}


def target_rows(r: dict | None) -> list[list[str]]:
    """The row of RESULTS.md's targets table (target, measured, verdict); none without figures."""
    if not r:
        return []
    m = r["median"]
    text = f"{r['ratio']:.2f}x ({m['plan'] * 1e3:.0f} ms against {m['floor'] * 1e3:.0f} ms)"
    steps = (r.get("breakdown") or {}).get("steps", {})
    first = next((v for k, v in steps.items() if k.startswith("Planner.plan (")), None)
    if first is not None:  # how much of the excess is the plan's own work, not starting up
        text += (f"; the first plan itself (Planner.plan: {first * 1e3:.0f} ms, breakdown below) taken out, "
                 f"{(m['plan'] - first) / m['floor']:.2f}x")
    return [[f"cold `spar plan` <= {r['target']:g}x the import floor (issue 18)", text,
             "met" if r["ratio"] <= r["target"] else "NOT met"]]


def render(r: dict) -> list[str]:
    """The RESULTS.md section of :func:`run`'s dict (Markdown lines)."""
    m, f = r["median"], r["median"]["floor"]
    L = ["## Cold start (bench/coldstart.py)", "",
         (f"Fresh processes, {r['repeats']} rounds, each round running every command once (rotating "
          "order); medians. `floor` = `python -c \"import numpy, casadi, janus_swi\"` (janus starts "
          "SWI-Prolog); `plan` = `spar plan kb/problems/peg_in_block.yaml` (SWI-Prolog started from the "
          "planner's saved state); `image` = the same with `SPAR_SAVED_STATE=off` (SWI-Prolog started as "
          "janus does, the planner loaded from its .qlf image meanwhile); `sources` = the same with "
          "`SPAR_QLF_CACHE=off` (the Prolog consulted at every start); `engine` = "
          "`python -c \"import spar_py.planning.engine as e; e.engine()\"`."), ""]
    rows = []
    for name in [n for n in ("floor", "floor, frozen exit", "plan", "plan, image", "plan, sources", "engine",
                             "engine, image", "engine, sources", "plan, peer")
                 if n in m]:
        c = r["cpu"][name]
        rows.append([name, f"{m[name] * 1e3:.0f} ms", f"{m[name] / f:.2f}",
                     f"{min(r['runs'][name]) * 1e3:.0f}-{max(r['runs'][name]) * 1e3:.0f} ms",
                     f"{c * 1e3:.0f} ms", f"{c / r['cpu']['floor']:.2f}"])
    L += ["| process | wall, median | x floor | wall, range | CPU, median | CPU x floor |",
          "|---|---|---|---|---|---|",
          *["| " + " | ".join(x) + " |" for x in rows], ""]
    ok = r["ratio"] <= r["target"]
    L += [(f"Cold `spar plan` is {r['ratio']:.2f}x the floor in wall time (target <= {r['target']:g}x: "
           f"{'met' if ok else 'NOT met'}) and {r['ratio_cpu']:.2f}x in CPU time; with the image alone it "
           f"is {r['ratio_image']:.2f}x, from sources {r['ratio_sources']:.2f}x; against the floor ending as "
           f"`spar` does (gc.freeze() and os._exit) {r['ratio_frozen']:.2f}x. Starting from the saved state "
           f"instead of janus' own start and the image changes the engine start by "
           f"{-r['state_engine_saving_s'] * 1e3:+.0f} ms and the whole plan by "
           f"{-r['state_plan_saving_s'] * 1e3:+.0f} ms; loading the image instead of the sources changes them "
           f"by {-r['engine_saving_s'] * 1e3:+.0f} and {-r['plan_saving_s'] * 1e3:+.0f} ms (differences of "
           "medians; without the state `spar plan` loads the Prolog in a thread while Python imports numpy "
           "and reads the problem)."), ""]
    if "ratio_peer" in r:
        L += [(f"`plan, peer` = the same `spar plan` running the spar_py of {r['peer']} (its src/ first on "
               f"PYTHONPATH) in the same rounds: {r['ratio_peer']:.2f}x the floor, against {r['ratio']:.2f}x "
               f"here ({(m['plan'] - m['plan, peer']) * 1e3:+.0f} ms)."), ""]
    b = r.get("breakdown")
    if b:
        L += [(f"Where a cold `spar plan` spends its wall time ({b['runs']} runs of `cli.main` with its steps "
               f"timed, medians; the Prolog loaded from: {', '.join(b['loaded_from'])}): "
               + "; ".join(f"{k} {v * 1e3:.0f} ms" for k, v in b["steps"].items()) + "."), ""]
    imp = r["imports"]
    top = ", ".join(f"{g} {t:.1f}" for g, t in imp["beyond_floor"][:14])
    L += [(f"Imports beyond the floor (`-X importtime`, {imp['runs']} runs, median self time in ms, "
           f"{imp['modules']:.0f} modules, {imp['beyond_floor_ms']:.0f} ms in all): {top}. "
           "Heavy libraries a cold plan of the paper's cell imports: "
           f"{', '.join(imp['heavy']) if imp['heavy'] else 'none'} (of {', '.join(HEAVY)})."), ""]
    return L


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(prog="python -m bench.coldstart", description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=15)
    ap.add_argument("--quick", action="store_true", help="3 rounds, 1 importtime run")
    ap.add_argument("--peer", metavar="DIR", help="another checkout of spar-py: time its `spar plan` too")
    a = ap.parse_args(argv)
    r = run(3, 1, a.peer) if a.quick else run(a.repeats, peer=a.peer)
    print("\n".join(render(r)))


if __name__ == "__main__":
    main()
