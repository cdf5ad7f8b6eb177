"""Fabrica's assemblies derived from their meshes and planned (issue 34).

Run from the project root: ``.venv/bin/python -m bench.fabrica [--names car,stool_circular]
[--repeats 3]`` (or ``python -m bench --only fabrica``, which writes the section into
bench/RESULTS.md).

For each assembly of kb/products/fabrica/ (one PLY per part in its assembled pose, cm), its
product file (kb/products/fabrica/NAME.yaml when there is one, else one written for the run:
every part ``mesh:``, nothing declared, the first part the base) is loaded as ``spar plan``
loads a product (kb.products.load_product_derived, cell unit mm) in a child process of its own
with an empty derivation cache (``SPAR_CACHE_DIR``): the cold derivation, i.e. the contacts,
mates, seats, sweeps and precedence (world/product/assembly.py) and every part's object model (stable
poses, grasps, faces: world/parts/poses.py, grasps.py). Recorded: the load's wall and CPU seconds, the
assembly derivation's own seconds, the mates (each with its axis), the seats, the insertion
order and the child's peak RSS. Then, when ``kb/problems/fabrica_NAME.yaml`` exists, ``spar
plan`` on it in a child with its own empty cache: its outcome and wall seconds ("no cell"
otherwise). Figures are medians of ``repeats`` runs; what was derived is the last run's (a
derivation is seeded: every run derives the same). ``--one NAME PRODUCT`` is the derivation's
child: one JSON line.
"""
from __future__ import annotations

import argparse
import datetime as _dt
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from .results_md import splice_section

ROOT = Path(__file__).resolve().parent.parent
FABRICA = ROOT / "kb" / "products" / "fabrica"
PROBLEMS = ROOT / "kb" / "problems"
#: Runs per assembly (their median is the figure).
REPEATS = 3
#: Seconds a child may take before it is killed.
TIMEOUT = 300.0
#: Issue 34's goals per assembly on the 2-core machine: the derivation and the whole plan (wall s).
DERIVE_S, PLAN_S = 5.0, 30.0

SECTION = "## Fabrica: products derived from meshes (bench/fabrica.py)"
TARGET_ROW = "| Fabrica assemblies, "


def names() -> list[str]:
    """The assemblies vendored under kb/products/fabrica/ (a directory of PLY parts each)."""
    return sorted(d.name for d in FABRICA.iterdir() if d.is_dir() and any(d.glob("*.ply")))


def product_file(name: str, where: Path) -> Path:
    """The assembly's product file: kb/products/fabrica/NAME.yaml, else one written in ``where``
    naming every part's mesh (cm) and nothing else."""
    own = FABRICA / f"{name}.yaml"
    if own.is_file():
        return own
    parts = sorted((FABRICA / name).glob("*.ply"), key=lambda p: (len(p.stem), p.stem))
    text = (f"product: {name}\nunits: {{length: cm, angle: deg}}\nparts:\n"
            + "".join(f"  p{p.stem}: {{mesh: {p}}}\n" for p in parts))
    path = where / f"{name}.yaml"
    path.write_text(text, encoding="utf-8")
    return path


def one(name: str, product: Path) -> dict:
    """The derivation's child: load the product cold (the caller gives an empty cache), and what
    was derived."""
    import resource

    t_imp = time.perf_counter()
    import spar_py.world.product.assembly as wa
    from spar_py.core.errors import KBError
    from spar_py.kb.products import load_product_derived
    imports = time.perf_counter() - t_imp
    seen: list = []  # the derivation, kept for a product refused after it (kb.products calls it by name)
    derive = wa.derive_assembly_cached

    def keep(*args: object, **kw: object) -> object:
        seen.append(derive(*args, **kw))  # type: ignore[arg-type]
        return seen[-1]
    wa.derive_assembly_cached = keep  # type: ignore[assignment]
    c0, t0 = time.process_time(), time.perf_counter()
    out: dict = {"name": name, "imports_s": imports}
    try:
        lp = load_product_derived(product, "mm")
        out["outcome"] = "derived"
    except KBError as e:
        lp = None
        out["outcome"], out["reason"] = "refused", str(e).split(": ", 1)[-1]
    out["derive_s"], out["cpu_s"] = time.perf_counter() - t0, time.process_time() - c0
    out["rss_peak_mb"] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
    d = lp.derived if lp is not None else (seen[-1] if seen else None)
    if d is not None:
        out["assembly_s"] = d.seconds
        out["parts"] = len({p for i in d.insertions for p in i.parts} | set(d.unremovable))
        out["mates"] = [{"peg": m.peg, "hole": m.hole, "axis": [round(float(v), 3) + 0.0 for v in m.axis],
                         "radius_mm": round(m.peg_radius, 3), "through": m.through} for m in d.mates]
        out["seats"] = [{"part": s.part, "on": s.on} for s in d.seats]
        out["order"] = [{"parts": list(i.parts), "direction": [round(float(v), 3) + 0.0 for v in i.direction],
                         "fixture": i.needs_fixture} for i in d.insertions]
        out["precedence"] = len(d.precedence)
    return out


def _child(cmd: list[str], env: dict, timeout: float) -> tuple[int | None, str, str, float, float]:
    """Run ``cmd``: (exit code or None if killed, stdout, stderr, wall s, peak RSS MB)."""
    with tempfile.TemporaryFile("w+") as fo, tempfile.TemporaryFile("w+") as fe:
        t = time.perf_counter()
        p = subprocess.Popen(cmd, cwd=ROOT, stdout=fo, stderr=fe, env=env, text=True)
        deadline = t + timeout
        rc, rss = None, 0.0
        while True:
            pid, status, ru = os.wait4(p.pid, os.WNOHANG)
            if pid:
                rc, rss = os.waitstatus_to_exitcode(status), ru.ru_maxrss / 1024.0
                p.returncode = rc
                break
            if time.perf_counter() > deadline:
                p.kill()
                _, _, ru = os.wait4(p.pid, 0)
                p.returncode = -9
                break
            time.sleep(0.02)
        wall = time.perf_counter() - t
        fo.seek(0)
        fe.seek(0)
        return rc, fo.read(), fe.read(), wall, rss


def _env(cache: str) -> dict:
    """This checkout's sources first on the path; the derivation cache at ``cache``."""
    path = os.pathsep.join([str(ROOT / "src"), str(ROOT), os.environ.get("PYTHONPATH", "")])
    return {**os.environ, "PYTHONPATH": path, "SPAR_CACHE_DIR": cache}


def derive_child(name: str, product: Path, timeout: float = TIMEOUT) -> dict:
    """:func:`one` in a fresh process with an empty cache; ``process_s`` its life."""
    with tempfile.TemporaryDirectory(prefix=f"spar-fabrica-{name}-") as cache:
        rc, so, se, wall, rss = _child([sys.executable, "-m", "bench.fabrica", "--one", name, str(product)],
                                       _env(cache), timeout)
    lines = [ln for ln in so.splitlines() if ln.startswith("{")]
    if rc != 0 or not lines:
        return {"name": name, "outcome": "error", "reason": (se.strip().splitlines() or [f"exit {rc}"])[-1],
                "process_s": wall}
    return {**json.loads(lines[-1]), "process_s": wall}


def plan_child(name: str, timeout: float = TIMEOUT) -> dict:
    """``spar plan kb/problems/fabrica_NAME.yaml`` in a fresh process with an empty cache: its
    outcome (the exit code, the last line of its output) and wall seconds; "no cell" without
    that file."""
    cell = PROBLEMS / f"fabrica_{name}.yaml"
    if not cell.is_file():
        return {"plan": "no cell"}
    with tempfile.TemporaryDirectory(prefix=f"spar-fabrica-plan-{name}-") as cache:
        rc, so, se, wall, rss = _child([sys.executable, "-m", "spar_py", "plan", str(cell)], _env(cache), timeout)
    last = ((so.strip() + "\n" + se.strip()).strip().splitlines() or [""])[-1]
    outcome = "killed" if rc is None else ("plan" if rc == 0 else f"exit {rc}")
    return {"plan": outcome, "plan_s": wall, "plan_rss_mb": rss, "plan_last": last[:200]}


def _median(rows: list[dict], key: str) -> float | None:
    xs = [r[key] for r in rows if isinstance(r.get(key), (int, float))]
    return statistics.median(xs) if xs else None


def _load() -> str:
    try:
        return " ".join(f"{x:.2f}" for x in os.getloadavg())
    except OSError:
        return "unknown"


def run(which: list[str] | None = None, repeats: int = REPEATS, timeout: float = TIMEOUT, progress=None) -> dict:
    """Every assembly: ``repeats`` cold derivations and plans, interleaved; their medians."""
    say = progress or (lambda line: None)
    date, load = _dt.datetime.now().astimezone().isoformat(timespec="seconds"), _load()
    rows = []
    with tempfile.TemporaryDirectory(prefix="spar-fabrica-products-") as d:
        for name in which or names():
            product = product_file(name, Path(d))
            runs, plans = [], []
            for k in range(repeats):
                runs.append(derive_child(name, product, timeout))
                plans.append(plan_child(name, timeout))
                say(f"{name} run {k + 1}: {runs[-1].get('outcome')} {runs[-1].get('derive_s', float('nan')):.2f} s, "
                    f"plan {plans[-1].get('plan')} {plans[-1].get('plan_s', float('nan')):.2f} s")
            row = {**runs[-1], "runs": len(runs), "product": str(product.relative_to(ROOT)) if
                   product.is_relative_to(ROOT) else "written for the run"}
            for k in ("derive_s", "cpu_s", "assembly_s", "rss_peak_mb", "process_s", "imports_s"):
                row[k] = _median(runs, k)
            row.update({k: plans[-1].get(k) for k in ("plan", "plan_last")})
            row["plan_s"], row["plan_rss_mb"] = _median(plans, "plan_s"), _median(plans, "plan_rss_mb")
            row["derive_runs"] = [r.get("derive_s") for r in runs]
            rows.append(row)
    return {"rows": rows, "repeats": repeats, "date": date, "load": load, "load_after": _load()}


# ---------------------------------------------------------------------- RESULTS.md


def _f(x: float | None, fmt: str = ".2f") -> str:
    return "-" if x is None else format(x, fmt)


def _axis(v: list[float]) -> str:
    names = {(1, 0, 0): "+x", (-1, 0, 0): "-x", (0, 1, 0): "+y", (0, -1, 0): "-y", (0, 0, 1): "+z", (0, 0, -1): "-z"}
    key = tuple(int(round(c)) if abs(abs(c) - 1) < 1e-3 or abs(c) < 1e-3 else None for c in v)
    return names.get(key, "[" + ", ".join(f"{c:.3f}" for c in v) + "]")  # type: ignore[call-overload]


def render(r: dict) -> list[str]:
    """The RESULTS.md section of :func:`run`'s dict (Markdown lines)."""
    L = [SECTION, "",
         ("Each Fabrica assembly (kb/products/fabrica/NAME/*.ply, cm; its product file "
          "kb/products/fabrica/NAME.yaml, else one naming every part's mesh and nothing else, the first "
          "part the base) loaded as `spar plan` loads a product (`load_product_derived`, mm) in a child "
          "process with an empty derivation cache: `derive` is that cold load's wall time (contacts, mates, "
          "seats, sweeps, precedence, and every part's stable poses, grasps and faces; Python's start and "
          "imports not included), `cpu` its CPU time, `assembly` world/assembly.derive_assembly's own share, "
          "RSS the child's peak. `plan` is `spar plan kb/problems/fabrica_NAME.yaml` from start to exit with "
          "an empty cache (\"no cell\" where that file does not exist yet). Medians of "
          f"{r['repeats']} runs. Run on {r.get('date', '?')}, load average {r.get('load', '?')} before, "
          f"{r.get('load_after', '?')} after (2 cores shared: wall times above the CPU times are other "
          "processes' share)."), ""]
    head = ["assembly", "parts", "derive s", "cpu s", "assembly s", "RSS MB", "outcome", "mates (peg -> hole, axis)",
            "seats", "insertion order (direction)", "plan", "plan s"]
    L += ["| " + " | ".join(head) + " |", "|" + "|".join("---" for _ in head) + "|"]
    for row in r["rows"]:
        mates = row.get("mates") or []
        mtxt = f"{len(mates)}: " + ", ".join(f"{m['peg']}->{m['hole']} {_axis(m['axis'])}" for m in mates) \
            if mates else "0"
        order = row.get("order") or []
        otxt = ", ".join("+".join(i["parts"]) + ("" if k == 0 else f" {_axis(i['direction'])}")
                         + (" (fixture)" if i.get("fixture") else "") for k, i in enumerate(order)) or "-"
        outcome = row.get("outcome", "?")
        if outcome != "derived":
            outcome += f": {row.get('reason', '')}"
        L.append("| " + " | ".join([
            row["name"], str(row.get("parts", "-")), _f(row.get("derive_s")), _f(row.get("cpu_s")),
            _f(row.get("assembly_s")), _f(row.get("rss_peak_mb"), ".0f"), outcome.replace("|", "/"), mtxt,
            str(len(row.get("seats") or [])), otxt, str(row.get("plan", "-")), _f(row.get("plan_s"))]) + " |")
    L.append("")
    return L


def target_rows(r: dict | None) -> list[list[str]]:
    """The rows of RESULTS.md's targets table: the derivation and the whole plan per assembly."""
    if not r or not r.get("rows"):
        return []
    rows = r["rows"]
    worst = max(rows, key=lambda x: x.get("derive_s") or 0.0)
    over = [x["name"] for x in rows if (x.get("derive_s") or 0.0) > DERIVE_S]
    out = [[f"Fabrica assemblies, cold derivation <= {DERIVE_S:g} s each (issue 34)",
            f"{worst.get('derive_s', 0):.2f} s at worst ({worst['name']}, CPU {_f(worst.get('cpu_s'))} s)",
            "met" if not over else f"NOT met ({', '.join(over)})"]]
    planned = [x for x in rows if x.get("plan_s") is not None]
    if planned:
        w = max(planned, key=lambda x: x["plan_s"])
        late = [x["name"] for x in planned if x["plan_s"] > PLAN_S]
        made = [x for x in planned if x.get("plan") == "plan"]
        status = ("met" if not late else f"NOT met ({', '.join(late)})") if len(made) == len(rows) else (
            f"NOT met: {len(rows) - len(made)} of {len(rows)} end in NO PLAN (spar plan's exit 1)"
            + (f"; over time: {', '.join(late)}" if late else ""))
        out.append([f"Fabrica assemblies, whole plan <= {PLAN_S:g} s each (issue 34)",
                    f"{w['plan_s']:.2f} s at worst ({w['name']}); {len(planned)} of {len(rows)} have a cell, "
                    f"{len(made)} of them plan", status])
    else:
        out.append([f"Fabrica assemblies, whole plan <= {PLAN_S:g} s each (issue 34)",
                    "no kb/problems/fabrica_*.yaml cell yet", "not measured"])
    return out


def splice(text: str, r: dict) -> str:
    """RESULTS.md's ``text`` with this module's section and target rows replaced by :func:`run`'s
    ``r`` (``python -m bench --only fabrica``): the section where it was, else before the
    profiles (or at the end of the generated part); the rows at the end of the targets table."""
    return splice_section(text, render(r), SECTION, TARGET_ROW, target_rows(r))


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(prog="python -m bench.fabrica", description=__doc__.splitlines()[0])
    ap.add_argument("--names", default="", help="assemblies, comma-separated (default: all)")
    ap.add_argument("--repeats", type=int, default=REPEATS, help="runs per assembly (default 3)")
    ap.add_argument("--timeout", type=float, default=TIMEOUT, help="seconds per child (default 300)")
    ap.add_argument("--one", nargs=2, default=None, metavar=("NAME", "PRODUCT"), help=argparse.SUPPRESS)
    a = ap.parse_args(argv)
    if a.one is not None:
        print(json.dumps(one(a.one[0], Path(a.one[1]))))
        return
    r = run([n for n in a.names.split(",") if n] or None, a.repeats, a.timeout,
            lambda line: print(line, file=sys.stderr, flush=True))
    print("\n".join(render(r)))


if __name__ == "__main__":
    main()
