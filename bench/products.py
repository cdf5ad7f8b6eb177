"""Products: the task board of N insertions planned whole, against its peers (issue 33).

Run from the project root: ``.venv/bin/python -m bench.products [--ns 5,10,20,30,50] [--repeats 3]``
(or ``python -m bench --only products``, which writes the section into bench/RESULTS.md).

For each N, in the same run and interleaved (board, pairs, board, pairs, ...), so machine load
falls on both sides alike:

- the board: ``spar_py.app.gen.generate_board(N)`` (N pins into an N-hole board, the task-board
  kind) planned whole as ``spar plan`` plans it (``Planner(timeout=...)``, no other option: both
  phases, phase 2 collision-aware), each run in its own child process (its peak RSS its own)
  after a warm-up plan of the paper's cell; phase-1 and phase-2 seconds from the plan's timing,
  wall the ``plan()`` call (loading the files included), ``process`` the child from start to exit
  (Python and the engine starting, the warm-up and the generation included);
- the pairs: the same N as N separate peg-into-block pairs (``spar_py.app.gen.generate_assembly``,
  bench/planning.py's child), the same way;
- Fast Downward (lama-first) on the board's phase-1 task: bench/fd.py's encoding of the cell (the
  arcs as static facts) with the product's precedence as preconditions (:func:`pddl`), once per N.

Figures are medians of ``repeats`` runs (one at N >= SLOW_N when a first run took more than
SLOW_S). ``python -m bench.products --one N`` is the board's child: one JSON line.
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

from . import fd, planning
from .results_md import splice_section

ROOT = Path(__file__).resolve().parent.parent
#: The sizes of a full run (insertions).
NS = (5, 10, 20, 30, 50)
#: Runs per N (their median is the figure).
REPEATS = 3
#: From this N, a first board run slower than SLOW_S is not repeated.
SLOW_N, SLOW_S = 50, 30.0
#: The planner's timeout per run (s); a child is killed 30 s after it.
TIMEOUT = 300.0
#: Issue 33's targets: the board's whole plan at N (wall s, peak RSS MB or None).
TARGETS = {20: (10.0, 500.0), 50: (60.0, None)}

#: bench/fd.py's domain, the assemble action also requiring every mate the product puts before it
#: (``needs ?o1 ?o2 ?a ?b``: ?a into ?b is made before ?o1 into ?o2): precedence as preconditions.
DOMAIN = fd.DOMAIN.replace(
    "(mate ?o1 - obj ?o2 - obj ?g - grasp ?p - pos))",
    "(mate ?o1 - obj ?o2 - obj ?g - grasp ?p - pos)\n"
    "               (needs ?o1 - obj ?o2 - obj ?a - obj ?b - obj))").replace(
    ":requirements :strips :typing", ":requirements :adl :typing").replace(
    ":precondition (and (holding ?o1 ?g) (at ?o2 ?p) (mate ?o1 ?o2 ?g ?p))",
    ":precondition (and (holding ?o1 ?g) (at ?o2 ?p) (mate ?o1 ?o2 ?g ?p)\n"
    "                       (forall (?a - obj ?b - obj) (imply (needs ?o1 ?o2 ?a ?b) (assembled ?a ?b))))")


def pddl(cell) -> str:
    """The PDDL problem of a product cell for :data:`DOMAIN`: bench/fd.py's encoding (goals, arcs)
    and one ``needs`` fact per precedence of the product (Precedence(P, Q): P's insertion before
    Q's, each into its parent of the product's goals)."""
    text = fd.pddl(cell)
    product = cell.product
    if product is None or not product.precedence:
        return text
    parent = {g.part: g.parent for g in product.goals}
    facts = [f"(needs {fd._name(p.then)} {fd._name(parent[p.then])} {fd._name(p.first)} {fd._name(parent[p.first])})"
             for p in product.precedence]
    head, tail = text.split("  (:init\n    ", 1)
    return head + "  (:init\n    " + "\n    ".join(facts) + "\n    " + tail


def one(n: int, timeout: float = TIMEOUT) -> dict:
    """Plan the generated N-insertion board in this process (the board's child); figures as a dict.

    A warm-up plan of the paper's cell comes first (the engine's start and first calls are not
    the board's). Keys: ``n``, ``rows``, ``cols``, ``outcome``, ``wall_s`` (loading and planning, as
    ``spar plan`` does), ``load_s`` (``load_problem``: the files read, the product compiled), ``phase1_s``,
    ``phase2_s``, ``actions``, ``steps``, ``instances_examined``, ``error_count``, ``precedence``
    (orderings the geometry forced), ``rss_before_mb``, ``rss_peak_mb`` (sampled every 5 ms while
    planning, bench.planning._RssWatch), ``gen_s`` (writing the files)."""
    from spar_py.app.gen import board_layout, generate_board
    from spar_py.core.errors import PlanningTimeout
    from spar_py.kb import load_problem
    from spar_py.planning.planner import Planner

    Planner().plan(planning.CELL)
    rss0 = planning._rss_mb()
    b = board_layout(n)
    out: dict = {"n": n, "rows": b.rows, "cols": b.cols, "rss_before_mb": rss0}
    with tempfile.TemporaryDirectory(prefix=f"spar-board-{n}-") as d:
        t = time.perf_counter()
        path = generate_board(n, d)
        out["gen_s"] = time.perf_counter() - t
        p = Planner(timeout=timeout)
        watch = planning._RssWatch()
        t = time.perf_counter()
        try:
            with watch:  # as `spar plan`: the cell loaded (the product compiled), then planned
                cell = load_problem(path)
                out["load_s"] = time.perf_counter() - t
                plan = p.plan(cell)
        except PlanningTimeout:
            out.update(outcome="timeout", wall_s=time.perf_counter() - t)
        else:
            inst = plan.instance or {}
            out.update(outcome=str(getattr(plan.outcome, "value", plan.outcome)), wall_s=time.perf_counter() - t,
                       phase1_s=plan.timing.get("phase1_s"), phase2_s=plan.timing.get("phase2_s"),
                       actions=len(plan.actions), steps=len(plan.steps),
                       instances_examined=inst.get("instances_examined"), error_count=inst.get("error_count"),
                       precedence=len(plan.partial.get("precedence") or ()) if isinstance(plan.partial, dict)
                       else None)
        out["rss_peak_mb"] = max(watch.peak, rss0)
    return out


def _env() -> dict:
    return {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")])}


def _run_child(cmd: list[str], timeout: float) -> tuple[dict | None, float, str]:
    """(the child's last JSON line or None, its seconds from start to exit, an error line)."""
    t = time.perf_counter()
    try:
        r = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, timeout=timeout + 30, env=_env(),
                           check=False)
    except subprocess.TimeoutExpired:
        return None, time.perf_counter() - t, f"killed after {timeout + 30:g} s"
    secs = time.perf_counter() - t
    lines = [ln for ln in r.stdout.splitlines() if ln.startswith("{")]
    if r.returncode != 0 or not lines:
        return None, secs, (r.stderr.strip().splitlines() or [f"exit {r.returncode}"])[-1]
    return json.loads(lines[-1]), secs, ""


def board_child(n: int, timeout: float = TIMEOUT) -> dict:
    """:func:`one` in a fresh process; ``process_s`` its life, ``outcome`` "error" if it failed."""
    got, secs, err = _run_child([sys.executable, "-m", "bench.products", "--one", str(n),
                                 "--timeout", str(timeout)], timeout)
    return {**(got or {"n": n, "outcome": "error", "error": err}), "process_s": secs}


def pairs_child(n: int, timeout: float = TIMEOUT) -> dict:
    """bench.planning's child (N peg-into-block pairs) in a fresh process, ``process_s`` beside."""
    got, secs, err = _run_child([sys.executable, "-m", "bench.planning", "--one", str(n), "--timeout",
                                 str(timeout), "--profile", "0"], timeout)
    return {**(got or {"n": n, "outcome": "error", "error": err}), "process_s": secs}


def fd_row(n: int) -> dict:
    """Fast Downward on the N-board's phase-1 task (:func:`pddl`, :data:`DOMAIN`): bench.fd.run_fd's
    figures, ``encode_s`` (the arcs and the text; not FD's time) and the problem's ``mates``."""
    from spar_py.app.gen import generate_board
    from spar_py.kb import load_problem

    with tempfile.TemporaryDirectory(prefix=f"spar-board-fd-{n}-") as d:
        dd = Path(d)
        cell = load_problem(generate_board(n, dd / "kb"))
        t = time.perf_counter()
        (dd / "domain.pddl").write_text(DOMAIN)
        (dd / "problem.pddl").write_text(pddl(cell))
        encode = time.perf_counter() - t
        r = fd.run_fd(dd / "domain.pddl", dd / "problem.pddl", dd)
    return {**r, "encode_s": encode, "precedence": len(cell.product.precedence)}


def _median(rows: list[dict], key: str) -> float | None:
    xs = [r[key] for r in rows if r.get(key) is not None]
    return statistics.median(xs) if xs else None


def _load() -> str:
    """The load average (1, 5, 15 min) now, as text."""
    try:
        return " ".join(f"{x:.2f}" for x in os.getloadavg())
    except OSError:
        return "unknown"


KEYS = ("wall_s", "load_s", "phase1_s", "phase2_s", "rss_peak_mb", "process_s")


def run(ns=NS, repeats: int = REPEATS, timeout: float = TIMEOUT, progress=None) -> dict:
    """Every N: the board's and the pairs' runs interleaved, their medians, FD once (module docstring)."""
    say = progress or (lambda line: None)
    date, load = _dt.datetime.now().astimezone().isoformat(timespec="seconds"), _load()
    rows = []
    for n in ns:
        board, pairs = [], []
        for k in range(repeats):
            board.append(board_child(n, timeout))
            pairs.append(pairs_child(n, timeout))
            say(f"board N = {n} run {k + 1}: {board[-1].get('outcome')} {board[-1].get('wall_s', float('nan')):.2f} s,"
                f" pairs {pairs[-1].get('outcome')} {pairs[-1].get('wall_s', float('nan')):.2f} s")
            if n >= SLOW_N and (board[-1].get("wall_s") or 0) > SLOW_S:
                break
        row = {"n": n, "runs": len(board), "board": {k: _median(board, k) for k in KEYS},
               "pairs": {k: _median(pairs, k) for k in KEYS}, "board_runs": board, "pairs_runs": pairs}
        for side, rs in (("board", board), ("pairs", pairs)):
            last = rs[-1]
            row[side].update({k: last.get(k) for k in ("outcome", "actions", "steps", "instances_examined",
                                                       "error_count", "precedence", "rows", "cols", "error")})
            row[side]["outcomes"] = sorted({str(r.get("outcome")) for r in rs})
        row["fd"] = fd_row(n)
        say(f"board N = {n}: FD {row['fd'].get('planner_s')} s planner ({row['fd'].get('error', 'ok')})")
        rows.append(row)
    return {"rows": rows, "repeats": repeats, "timeout_s": timeout, "date": date, "load": load,
            "load_after": _load()}


# ---------------------------------------------------------------------- RESULTS.md


def _f(x, fmt: str = ".2f") -> str:
    return "n/a" if x is None else format(x, fmt)


def _ratio(a, b) -> str:
    return "n/a" if a is None or not b else f"{a / b:.2f}"


def verdicts(r: dict | None) -> dict:
    """Each target of :data:`TARGETS` that was run: N -> (met?, the figure as text)."""
    out = {}
    for row in (r or {}).get("rows", []):
        if row["n"] not in TARGETS:
            continue
        s_max, mb_max = TARGETS[row["n"]]
        b = row["board"]
        ok = (b.get("outcomes") == ["plan"] and b["wall_s"] is not None and b["wall_s"] <= s_max
              and (mb_max is None or (b["rss_peak_mb"] or 1e9) <= mb_max))
        out[row["n"]] = (ok, f"{b.get('outcome')}, {_f(b['wall_s'])} s (loading {_f(b['load_s'])}, phase 1 "
                                    f"{_f(b['phase1_s'])}, phase 2 "
                             f"{_f(b['phase2_s'])}), peak RSS {_f(b['rss_peak_mb'], '.0f')} MB; median of "
                             f"{row['runs']}; {row['n']} pairs same run {_f(row['pairs']['wall_s'])} s")
    return out


def target_rows(r: dict | None) -> list[list[str]]:
    """The rows of RESULTS.md's targets table (target, measured, verdict); none without figures."""
    rows = []
    for n, (ok, text) in verdicts(r).items():
        s_max, mb_max = TARGETS[n]
        goal = f"task board N = {n}, whole plan <= {s_max:g} s" + (f" and {mb_max:g} MB" if mb_max else "")
        rows.append([goal + " (issue 33)", text, "met" if ok else "NOT met"])
    return rows


def render(r: dict) -> list[str]:
    """The RESULTS.md section of :func:`run`'s dict (Markdown lines)."""
    L = ["## Products: the task board (bench/products.py)", "",
         ("`spar_py.app.gen.generate_board(N)` (`spar gen board N`: N pins into an N-hole board, default "
          "rows) planned whole as `spar plan` plans it (`Planner(timeout="
          f"{r['timeout_s']:g})`: both phases, phase 2 collision-aware), one child process per run after a "
          "warm-up plan of the paper's cell; beside it in the same run, interleaved, its peer: the same N as N "
          "separate peg-into-block pairs (bench/planning.py's generated problem and child). `wall` is the "
          "cell's loading and its `plan()` call, as `spar plan` does them, `load` the loading alone "
          "(`load_problem`: the YAML and the mesh read, the product compiled: its goals, its precedence by "
          "swept insertions, world/product/products.py; the pairs have no product), phase 1/2 the plan's timing "
          "(Prolog CPU seconds, "
          "Python called back included), `process` the child from start to exit (Python and the engine "
          "starting, the warm-up plan and the generation included), RSS peak sampled every 5 ms while "
          f"planning. Medians of {r['repeats']} runs (fewer where `runs` says so). Run on {r.get('date', '?')}, "
          f"load average {r.get('load', '?')} before, {r.get('load_after', '?')} after."), ""]
    head = ["N", "board rows x cols", "runs", "actions (board / pairs)", "board load s", "board phase 1 s",
            "board phase 2 s",
            "board wall s", "board process s", "board RSS peak MB", "pairs phase 1 s", "pairs phase 2 s",
            "pairs wall s", "pairs RSS peak MB", "wall board / pairs", "outcomes (board / pairs)"]
    L += ["| " + " | ".join(head) + " |", "|" + "|".join("---" for _ in head) + "|"]
    for row in r["rows"]:
        b, p = row["board"], row["pairs"]
        L.append("| " + " | ".join([
            str(row["n"]), f"{b.get('rows')} x {b.get('cols')}", str(row["runs"]),
            f"{b.get('actions')} / {p.get('actions')}", _f(b["load_s"], ".3f"), _f(b["phase1_s"], ".3f"),
            _f(b["phase2_s"], ".3f"),
            _f(b["wall_s"], ".3f"), _f(b["process_s"]), _f(b["rss_peak_mb"], ".0f"), _f(p["phase1_s"], ".3f"),
            _f(p["phase2_s"], ".3f"), _f(p["wall_s"], ".3f"), _f(p["rss_peak_mb"], ".0f"),
            _ratio(b["wall_s"], p["wall_s"]),
            f"{'/'.join(b['outcomes'])} / {'/'.join(p['outcomes'])}"]) + " |")
    L += ["", ("Fast Downward `--alias lama-first` on the board's phase-1 task, once per N: bench/fd.py's "
               "encoding (pickup, putdown, assemble; the arcs phase 1 uses as static facts) with the "
               "product's precedence as preconditions of assemble (`needs`, ADL); `planner` is FD's own "
               "figure (translator included), `wall` its driver process; `ours` is the board's phase 1 "
               "above (arcs computed inside it, as FD's encoding computes them outside, untimed)."), ""]
    head = ["N", "precedence", "FD plan length", "FD search s", "FD planner s", "FD wall s", "encode s (untimed)",
            "ours phase 1 s", "ours / FD planner"]
    L += ["| " + " | ".join(head) + " |", "|" + "|".join("---" for _ in head) + "|"]
    for row in r["rows"]:
        f = row["fd"]
        L.append("| " + " | ".join([
            str(row["n"]), str(f.get("precedence")), str(f.get("plan_length", f.get("error", "n/a"))),
            _f(f.get("search_s"), ".3f"), _f(f.get("planner_s"), ".3f"), _f(f.get("wall_s")),
            _f(f.get("encode_s")), _f(row["board"]["phase1_s"], ".3f"),
            _ratio(row["board"]["phase1_s"], f.get("planner_s"))]) + " |")
    return L + [""]


#: The first line of :func:`render`'s section, and of its rows in the targets table.
SECTION = "## Products: the task board (bench/products.py)"
TARGET_ROW = "| task board N = "


def splice(text: str, r: dict) -> str:
    """RESULTS.md's ``text`` with this module's section and target rows replaced by :func:`run`'s
    ``r`` (``python -m bench --only products``): the section where it was, else before the
    profiles (or at the end of the generated part); the rows at the end of the targets table."""
    return splice_section(text, render(r), SECTION, TARGET_ROW, target_rows(r))


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(prog="python -m bench.products", description=__doc__.splitlines()[0])
    ap.add_argument("--ns", default=",".join(map(str, NS)), help="sizes, comma-separated (default 5,10,20,30,50)")
    ap.add_argument("--repeats", type=int, default=REPEATS, help="runs per N (default 3)")
    ap.add_argument("--timeout", type=float, default=TIMEOUT, help="seconds per plan (default 300)")
    ap.add_argument("--one", type=int, default=None, metavar="N", help=argparse.SUPPRESS)
    a = ap.parse_args(argv)
    if a.one is not None:
        print(json.dumps(one(a.one, a.timeout)))
        return
    r = run([int(x) for x in a.ns.split(",")], a.repeats, a.timeout, progress=print)
    print("\n".join(render(r)))
    for row in target_rows(r):
        print(" | ".join(row))


if __name__ == "__main__":
    main()
