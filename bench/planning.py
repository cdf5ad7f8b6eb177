"""Planning time: the paper's cell warm and cold, and generated N-peg problems (issue 7).

Run from the project root: ``.venv/bin/python -m bench.planning [--quick] [--max-n 10]``.

- warm: ``Planner().plan("kb/problems/peg_in_block.yaml")`` repeated in one process after
  one warm-up; phase-1 and phase-2 times (Prolog CPU seconds, ``plan.timing``) and the
  wall time of the call (loading the YAML included);
- cold: ``spar plan kb/problems/peg_in_block.yaml`` as a subprocess, and beside it, in
  the same run and interleaved, the bare cost of a process that starts the engine
  (``python -c "import spar_py.planning.engine as e; e.engine()"``);
- hopeless: ``spar plan kb/problems/hopeless_uncertainty.yaml`` as a subprocess, beside the
  same file ``--phase1-only`` and the paper's cell, interleaved (phase 2 at its worst);
- scaling: ``spar_py.app.gen.generate_assembly(N)`` for N = 1..10, 20, 30, 40, 42, 43 and 50, each planned
  in its own subprocess (so its peak RSS is its own) after a warm-up plan of the paper's
  cell, with ``Planner(timeout=...)`` and no other option: the generated problem needs 4N
  actions up to N = 70 (its blocks turned over up to 42, turned a quarter turn from a side face
  above; ``blocks`` says which) and 2N above (hole-up), and phase 1's default bound is derived
  from the problem (max_actions_for).

``python -m bench.planning --one N`` is the child of the scaling run: it prints one JSON
line with that N's figures.
"""
from __future__ import annotations

import argparse
import cProfile
import io
import json
import os
import pstats
import resource
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
CELL = ROOT / "kb" / "problems" / "peg_in_block.yaml"
BIN = Path(sys.executable).parent
SPAR = BIN / "spar"
ENGINE_ONLY = "import spar_py.planning.engine as e; e.engine()"
#: Time limit of one scaling run (s): the planner's own timeout; the child is killed 30 s later.
TIMEOUT = 120.0


#: The sizes of the scaling run beyond N = 1..max_n (issue 18's targets are at 20 and 50): all
#: 4N problems (spar_py.app.gen: blocks turned over up to 42 pairs, turned a quarter turn from a side
#: face up to 70), 42 the largest of the half turn, 43 the first of the quarter turn.
EXTRA_NS = (20, 30, 40, 42, 43, 50)


def max_actions_for(n: int) -> int:
    """Phase 1's default plan-size bound for N pairs, as max_actions(auto) derives it
    (spar_defaults:derived_max_actions/2, twice the lower bound, at least 12): the lower bound
    is 4N for blocks turned over (hole-down or on-side: N <= spar_py.app.gen.MAX_SIDE), 2N for blocks
    hole-up."""
    from spar_py.app.gen import blocks_for

    per_pair = 2 if blocks_for(n).startswith("hole-up") else 4
    return max(12, 2 * per_pair * n)


def _median(xs: list[float]) -> float | None:
    return statistics.median(xs) if xs else None


# ---------------------------------------------------------------------- the paper's cell


def warm(repeats: int = 20, profile_top: int = 0) -> dict:
    """The paper's cell planned ``repeats`` times in this process after one warm-up.

    Keys: ``repeats``, ``outcome``, ``actions``, ``instances_examined``, medians
    ``phase1_s``, ``phase2_s`` (Prolog CPU time, plan.timing), ``wall_s`` (the
    ``plan`` call), ``load_s`` (``load_problem`` alone, timed between the plans: the
    YAML reading and checking inside each wall time), ``min_wall_s``, ``max_wall_s``, and with ``profile_top`` > 0
    ``profile``: cProfile's top entries by internal time of one more plan (text).
    """
    from spar_py.planning.planner import Planner

    p = Planner()
    plan = p.plan(CELL)  # warm-up: engine start, imports, first CasADi compiles
    p1, p2, wall, load = [], [], [], []
    for _ in range(repeats):
        t = time.perf_counter()
        plan = p.plan(CELL)
        wall.append(time.perf_counter() - t)
        t = time.perf_counter()
        p.load_problem(CELL)
        load.append(time.perf_counter() - t)
        p1.append(plan.timing.get("phase1_s", float("nan")))
        p2.append(plan.timing.get("phase2_s", float("nan")))
    out = {
        "repeats": repeats, "outcome": plan.outcome, "actions": len(plan.actions),
        "instances_examined": (plan.instance or {}).get("instances_examined"),
        "phase1_s": _median(p1), "phase2_s": _median(p2), "wall_s": _median(wall),
        "load_s": _median(load), "min_wall_s": min(wall), "max_wall_s": max(wall),
    }
    if profile_top:
        out["profile"] = profile(lambda: p.plan(CELL), profile_top)
    return out


def profile(fn, top: int) -> str:
    """cProfile's ``top`` entries by internal time of one ``fn()``, as text.

    Time spent inside SWI-Prolog shows as the internal time of janus's ``query_once``
    (Python called back from Prolog is counted under its own functions).
    """
    pr = cProfile.Profile()
    pr.enable()
    fn()
    pr.disable()
    s = io.StringIO()
    st = pstats.Stats(pr, stream=s)
    st.sort_stats("tottime").print_stats(top)
    by_self = table(s.getvalue())
    s.seek(0)
    s.truncate()
    st.sort_stats("cumulative").print_stats("spar_py|janus", top)
    return (f"{by_self[0]}\n\nby internal time:\n" + "\n".join(by_self[1:])
            + "\n\nspar-py and janus functions by cumulative time:\n" + "\n".join(table(s.getvalue())[1:]))


def table(text: str) -> list[str]:
    """pstats' output without its preamble: the totals line, then the table."""
    lines = [ln.rstrip().replace(str(ROOT) + "/", "") for ln in text.splitlines()]
    lines = [ln.replace(str(Path(sys.prefix)) + "/", "") for ln in lines]
    first = next((i for i, ln in enumerate(lines) if ln.lstrip().startswith("ncalls")), 0)
    total = next((ln.strip() for ln in lines if "function calls" in ln), "")
    return [total, *[ln for ln in lines[first:] if ln.strip()]]


def _time_process(cmd: list[str], timeout: float = 120.0) -> tuple[float, int]:
    t = time.perf_counter()
    r = subprocess.run(cmd, cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                       timeout=timeout, check=False)
    return time.perf_counter() - t, r.returncode


def cold(repeats: int = 7) -> dict:
    """``spar plan`` on the paper's cell as a fresh process, and the engine start alone.

    Runs alternate (plan, start, plan, start, ...) so both see the same machine load.
    Keys: ``repeats``, medians ``plan_s`` and ``start_s``, ``plan_minus_start_s``,
    ``ratio`` (plan / start), all runs in ``plan_runs``/``start_runs`` and
    ``returncodes`` (0 expected from every run).
    """
    plan_cmd = [str(SPAR), "plan", str(CELL.relative_to(ROOT))]
    start_cmd = [sys.executable, "-c", ENGINE_ONLY]
    plan_t, start_t, codes = [], [], set()
    for _ in range(repeats):
        t, rc = _time_process(plan_cmd)
        plan_t.append(t)
        codes.add(rc)
        t, rc = _time_process(start_cmd)
        start_t.append(t)
        codes.add(rc)
    mp, ms = _median(plan_t), _median(start_t)
    return {"repeats": repeats, "plan_s": mp, "start_s": ms, "plan_minus_start_s": mp - ms,
            "ratio": mp / ms, "plan_runs": plan_t, "start_runs": start_t,
            "returncodes": sorted(codes)}


HOPELESS = ROOT / "kb" / "problems" / "hopeless_uncertainty.yaml"


def hopeless(repeats: int = 5) -> dict:
    """``spar plan kb/problems/hopeless_uncertainty.yaml`` (phase 2 examines its 50 instances
    and gives up on uncertainty reduction) as a fresh process, interleaved in the same run
    with its peers: the same file ``--phase1-only`` and the paper's cell. Keys: medians
    ``plan_s``, ``phase1_only_s``, ``paper_s``, ``phase2_s`` (plan minus phase 1 only),
    all runs and the return codes (0 expected: the plan exists)."""
    rel = str(HOPELESS.relative_to(ROOT))
    cmds = {"plan": [str(SPAR), "plan", rel], "phase1_only": [str(SPAR), "plan", "--phase1-only", rel],
            "paper": [str(SPAR), "plan", str(CELL.relative_to(ROOT))]}
    runs: dict[str, list[float]] = {k: [] for k in cmds}
    codes = set()
    for _ in range(repeats):
        for k, cmd in cmds.items():
            t, rc = _time_process(cmd)
            runs[k].append(t)
            codes.add(rc)
    med = {k: _median(v) for k, v in runs.items()}
    return {"repeats": repeats, "plan_s": med["plan"], "phase1_only_s": med["phase1_only"],
            "paper_s": med["paper"], "phase2_s": med["plan"] - med["phase1_only"], "runs": runs,
            "returncodes": sorted(codes)}


# ---------------------------------------------------------------------- generated problems


def one(n: int, timeout: float = TIMEOUT, profile_top: int = 0) -> dict:
    """Plan the generated N-pair problem in this process (the scaling child); figures as a dict.

    A warm-up plan of the paper's cell comes first, so the figures exclude the engine's
    start and first-call costs. Keys: ``n``, ``max_actions``, ``outcome`` ("plan",
    "no_plan" or "timeout"), ``reason`` (phase 1's, for no_plan), ``budget_spent``
    (phase 1 stopped by its step budget), ``phase1_s``, ``phase2_s``, ``wall_s``,
    ``actions``, ``instances_examined``, ``rss_before_mb`` (resident set after the warm-up),
    ``rss_peak_mb`` (the largest resident set sampled every 5 ms while planning: Python and
    the embedded Prolog), ``maxrss_mb`` (getrusage's high-water mark; on Linux it includes the
    parent's at fork, so read it with care), ``prolog_stack_mb`` (SWI-Prolog's stacks in use at the end). With
    ``profile_top`` the plan runs under cProfile instead and only ``profile`` is returned.
    """
    from spar_py.planning.engine import engine
    from spar_py.core.errors import PlanningTimeout
    from spar_py.app.gen import blocks_for, generate_assembly
    from spar_py.planning.planner import Planner

    Planner().plan(CELL)
    rss0 = _rss_mb()
    out: dict = {"n": n, "blocks": blocks_for(n), "max_actions": max_actions_for(n), "rss_before_mb": rss0}
    with tempfile.TemporaryDirectory(prefix=f"spar-bench-{n}-") as d:
        path = generate_assembly(n, d)
        p = Planner(timeout=timeout)  # the default bound: derived from the problem
        if profile_top:  # a separate child: profile the first (unmemoised) plan, no figures
            out["profile"] = profile(lambda: p.plan(path), profile_top)
            return out
        watch = _RssWatch()
        t = time.perf_counter()
        try:
            with watch:
                plan = p.plan(path)
        except PlanningTimeout:
            out.update(outcome="timeout", wall_s=time.perf_counter() - t)
        else:
            out.update(
                outcome=plan.outcome, wall_s=time.perf_counter() - t,
                phase1_s=plan.timing.get("phase1_s"), phase2_s=plan.timing.get("phase2_s"),
                actions=len(plan.actions),
                instances_examined=(plan.instance or {}).get("instances_examined"),
                reason=plan.reason,
                # phase 1 reports the last bound it searched completely: below max_actions
                # only when its step budget ran out first
                budget_spent=plan.outcome == "no_plan"
                and (plan.reason or {}).get("max_actions", max_actions_for(n)) < max_actions_for(n))
        out["rss_peak_mb"] = max(watch.peak, rss0)
    out["maxrss_mb"] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    stack = engine().query_once("statistics(stack, S)")
    out["prolog_stack_mb"] = stack["S"] / 2**20 if stack.get("truth") else None
    return out


def _rss_mb() -> float:
    """This process's resident set now (MB), from /proc (0 where there is none)."""
    try:
        for line in Path("/proc/self/status").read_text().splitlines():
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024
    except OSError:
        pass
    return 0.0


class _RssWatch:
    """A thread that samples the resident set every 5 ms while the ``with`` block runs."""

    def __init__(self) -> None:
        self.peak = 0.0
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)

    def _run(self) -> None:
        while not self._stop.is_set():
            self.peak = max(self.peak, _rss_mb())
            self._stop.wait(0.005)

    def __enter__(self) -> None:
        self._thread.start()

    def __exit__(self, *exc: object) -> None:
        self._stop.set()
        self._thread.join()
        self.peak = max(self.peak, _rss_mb())


def scaling(ns: range | list[int] = range(1, 11), timeout: float = TIMEOUT,
            profile_top: int = 0, progress=None) -> list[dict]:
    """:func:`one` for each N, each in a fresh subprocess; a child past ``timeout`` + 30 s is
    killed and reported as a timeout. With ``profile_top``, the largest N that finished
    (any outcome but a timeout) is planned once more under cProfile (``profile`` key)."""
    say = progress or (lambda line: None)
    rows = []
    for n in ns:
        r = _child(n, timeout, 0)
        rows.append(r)
        say(f"N = {n}: {r.get('outcome')} wall {r.get('wall_s', float('nan')):.2f} s")
    done = [r for r in rows if r.get("outcome") not in ("timeout", "error")]
    if profile_top and done:
        last = max(done, key=lambda r: r["n"])
        last["profile"] = _child(last["n"], timeout, profile_top).get("profile", "(no profile)")
    return rows


def _child(n: int, timeout: float, profile_top: int) -> dict:
    cmd = [sys.executable, "-m", "bench.planning", "--one", str(n), "--timeout", str(timeout),
           "--profile", str(profile_top)]
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")])}
    t = time.perf_counter()
    try:
        r = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, timeout=timeout + 30,
                           env=env, check=False)
    except subprocess.TimeoutExpired:
        return {"n": n, "max_actions": max_actions_for(n), "outcome": "timeout",
                "wall_s": time.perf_counter() - t}
    lines = [ln for ln in r.stdout.splitlines() if ln.startswith("{")]
    if r.returncode != 0 or not lines:
        return {"n": n, "max_actions": max_actions_for(n), "outcome": "error",
                "error": (r.stderr.strip().splitlines() or [f"exit {r.returncode}"])[-1]}
    return json.loads(lines[-1])


# ---------------------------------------------------------------------- all of it


def run(quick: bool = False, max_n: int = 10, timeout: float = TIMEOUT, progress=None,
        extra_ns: tuple[int, ...] | None = None) -> dict:
    """warm, cold and scaling (N = 1..max_n and ``extra_ns``, by default EXTRA_NS unless
    ``quick``), with repeats cut down when ``quick``; profiles of the warm paper cell and of
    the largest N that finished (top 15 entries, 8 when quick)."""
    top = 8 if quick else 15
    extra = (() if quick else EXTRA_NS) if extra_ns is None else extra_ns
    ns = list(range(1, max_n + 1)) + [n for n in extra if n > max_n]
    return {
        "warm": warm(repeats=3 if quick else 20, profile_top=top),
        "cold": cold(repeats=2 if quick else 7),
        "hopeless": hopeless(repeats=2 if quick else 5),
        "scaling": scaling(ns, timeout=timeout, profile_top=top, progress=progress),
        "timeout_s": timeout,
    }


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(prog="python -m bench.planning", description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="fewer repeats, N = 1..2")
    ap.add_argument("--max-n", type=int, default=None, help="largest N of the scaling run (default 10)")
    ap.add_argument("--timeout", type=float, default=TIMEOUT, help="seconds per N (default 120)")
    ap.add_argument("--one", type=int, default=None, metavar="N", help=argparse.SUPPRESS)
    ap.add_argument("--profile", type=int, default=0, help=argparse.SUPPRESS)
    a = ap.parse_args(argv)
    if a.one is not None:
        print(json.dumps(one(a.one, a.timeout, a.profile)))
        return
    max_n = a.max_n if a.max_n is not None else (2 if a.quick else 10)
    r = run(a.quick, max_n, a.timeout, progress=print)
    w, c = r["warm"], r["cold"]
    print(f"warm paper cell: phase 1 {w['phase1_s'] * 1e3:.1f} ms, phase 2 {w['phase2_s'] * 1e3:.1f} ms, "
          f"wall {w['wall_s'] * 1e3:.1f} ms (median of {w['repeats']})")
    print(f"cold spar plan : {c['plan_s']:.3f} s; engine start alone {c['start_s']:.3f} s "
          f"(ratio {c['ratio']:.2f}, median of {c['repeats']})")
    h = r["hopeless"]
    print(f"hopeless_uncertainty.yaml: {h['plan_s']:.2f} s (--phase1-only {h['phase1_only_s']:.2f} s, "
          f"paper's cell {h['paper_s']:.2f} s; median of {h['repeats']})")
    for s in r["scaling"]:
        print(json.dumps({k: v for k, v in s.items() if k != "profile"}))
    print(w["profile"])


if __name__ == "__main__":
    main()
