"""Batch regression runs: every problem of a knowledge base against its expected outcome.

For each problem file under DIR (a ``*.yaml`` whose top-level mapping has ``problem:``,
at any depth) the expected outcome lives beside it in ``expected/<stem>.json``: the
summary of its plan (outcome, actions, orderings, sensing inserted, error count, the
bindings that are unique). Object and robot models are skipped with a note line (so
``spar regress kb`` works). ``spar regress DIR``
plans every problem (``-j N`` worker processes on this machine, each with its own
embedded Prolog; or ``--scheduler ADDRESS``, the workers of a Dask cluster), prints a
table of pass/fail and times in the problems' order, a readable diff for each failure,
and exits 1 if anything failed; ``--update`` writes the new outcomes as the expected ones.

On a cluster (:func:`run_on_cluster`) each problem is one task. The problem is loaded
and checked here and its validated cell is sent to the task, so the workers need
spar-py installed (the same version) but not the knowledge-base files. A task whose
worker is lost (killed, crashed, cut off) is run again on another worker: the
scheduler reschedules it (Dask's ``distributed.scheduler.allowed-failures``), and if
it still gives up (``KilledWorker``) the task is submitted again, up to
:data:`CLUSTER_RETRIES` times, before its row says ERROR.
"""
from __future__ import annotations

import concurrent.futures as cf
import difflib
import json
import multiprocessing
import sys
import time
import uuid
from collections.abc import Callable
from pathlib import Path
from typing import Any

from spar_py.core.errors import SparError
from spar_py.kb import KINDS, file_kind, load_problem, read_yaml


def summarize(plan: dict[str, Any]) -> dict[str, Any]:
    """The parts of a plan's JSON a regression compares (stable under label-set order)."""
    out: dict[str, Any] = {"outcome": plan["outcome"]}
    if plan["outcome"] != "plan":
        reason = plan.get("reason")
        # the text of the unmet goal is compared; its term data (goal_data) says the same
        out["reason"] = {k: v for k, v in reason.items() if not k.endswith("_data")} if reason else reason
        return out
    partial = plan["partial"]
    out["actions"] = sorted(a["term"] for a in partial["actions"])
    out["ordering"] = sorted(partial["ordering"])
    out["unique_bindings"] = {v: ls[0] for v, ls in sorted(partial["variables"].items()) if len(ls) == 1}
    if partial.get("separations"):
        out["separations"] = sorted(list(s["text"]) for s in partial["separations"])
    inst = plan.get("instance")
    if inst:
        out["steps"] = [s["term"] for s in inst["steps"]]
        out["sensing"] = [s["term"] for s in inst["steps"] if s["kind"] != "manipulation"]
        out["error_count"] = inst["error_count"]
        out["verified"] = sorted(v["action"] for v in inst["verifications"])
    return out


#: One row of a run: (problem path, summary or None, error text, seconds).
Result = tuple[str, "dict[str, Any] | None", str, float]

#: Times a task lost with its workers is submitted again on a cluster (after the
#: scheduler's own rescheduling gave up on it).
CLUSTER_RETRIES = 1
#: Seconds to wait for the scheduler of ``--scheduler ADDRESS`` to answer.
CONNECT_TIMEOUT_S = 10.0


def _plan_one(path: str, cell: Any = None) -> Result:
    """Plan one problem file (here, in a -j worker process, or as a cluster task given its
    loaded ``cell``); (path, summary or None, error text, seconds)."""
    from spar_py.planning.planner import Planner  # in the process that plans (a -j worker, a cluster task)

    t0 = time.perf_counter()
    try:
        plan = Planner().plan(Path(path) if cell is None else cell)
        return path, summarize(plan.to_json()), "", time.perf_counter() - t0
    except SparError as e:
        return path, None, str(e).splitlines()[0], time.perf_counter() - t0


def run_on_cluster(paths: list[str], client: Any, progress: Any = None) -> list[Result]:
    """Plan every problem file of ``paths`` on the Dask cluster of ``client`` (a
    ``distributed.Client``), one task each; the rows in the order of ``paths``.

    A problem that does not load is an ERROR row at once (no task). A task lost with its
    worker is rescheduled by Dask; one that Dask gives up on (``KilledWorker``) is
    submitted again, at most :data:`CLUSTER_RETRIES` times; any other failure of a task
    (not a SparError, which its row reports) is an ERROR row naming it."""
    # distributed: imported on first use, an optional extra (spar-py[cluster]): --scheduler only
    from distributed import as_completed
    from distributed.scheduler import KilledWorker

    rows: dict[str, Result] = {}
    futures: dict[Any, str] = {}
    load_s: dict[str, float] = {}  # loading here, added to the task's time as -j 1 counts it

    def submit(path: str) -> Any:
        """Load ``path`` here and submit its cell as a task (None if it does not load)."""
        t0 = time.perf_counter()
        try:
            cell = load_problem(path)
        except SparError as e:
            rows[path] = (path, None, _first_line(e), time.perf_counter() - t0)
            return None
        load_s[path] = time.perf_counter() - t0
        # pure=False and a fresh key: a suite run twice plans twice; the key names the problem
        fut = client.submit(_plan_one, path, cell, pure=False,
                            key=f"spar-regress-{Path(path).stem}-{uuid.uuid4().hex[:12]}")
        futures[fut] = path
        return fut

    queue = as_completed([f for f in map(submit, paths) if f is not None], loop=client.loop)
    tries = dict.fromkeys(paths, 0)
    for fut in queue:
        path = futures.pop(fut)
        try:
            p, summary, err, secs = fut.result()
            rows[path] = (p, summary, err, secs + load_s[path])
        except KilledWorker as e:
            if tries[path] < CLUSTER_RETRIES:
                tries[path] += 1
                again = submit(path)
                if again is not None:
                    queue.add(again)
                    continue
            else:
                rows[path] = (path, None, f"lost with its workers {tries[path] + 1} times ({_first_line(e)})", 0.0)
        except Exception as e:  # a task that failed another way: its row says how
            rows[path] = (path, None, f"task failed: {type(e).__name__}: {_first_line(e)}", 0.0)
        if progress is not None:
            progress(len(rows), len(paths), Path(path).stem)
    return [rows[p] for p in paths]


def _first_line(e: BaseException) -> str:
    return (str(e).splitlines() or [""])[0]


def connect(address: str) -> Any:
    """A ``distributed.Client`` of the scheduler at ``address``; SparError (one line) if
    distributed is not installed or the scheduler does not answer."""
    try:
        from distributed import Client  # optional (spar-py[cluster]): the except is its absence
    except ImportError:
        raise SparError("regress: --scheduler needs Dask's distributed (pip install 'spar-py[cluster]')") from None
    from distributed.comm import parse_address  # imported with Client above
    from distributed.comm.registry import backends

    try:
        scheme = parse_address(address)[0]
    except (ValueError, TypeError) as e:
        scheme, why = "", _first_line(e)
    else:
        why = f"unknown scheme {scheme!r}"
    if scheme not in backends:  # refused before a Client exists: a half-made one hangs at exit
        raise SparError(f"regress: --scheduler {address}: expected an address such as tcp://host:8786 "
                        f"(schemes {', '.join(sorted(backends))}), not one with {why}")
    try:
        return Client(address, timeout=CONNECT_TIMEOUT_S, set_as_default=False)
    except (OSError, TimeoutError, ValueError) as e:
        raise SparError(f"regress: --scheduler {address}: expected a Dask scheduler that answers within "
                        f"{CONNECT_TIMEOUT_S:g} s, not ({type(e).__name__}: {_first_line(e)})") from None


def _progress(done: int, total: int, name: str) -> None:
    if not sys.stderr.isatty():
        return
    width = 30
    filled = width * done // max(total, 1)
    sys.stderr.write(f"\r[{'#' * filled}{'.' * (width - filled)}] {done}/{total} {name[:30]:30}")
    sys.stderr.flush()
    if done == total:
        sys.stderr.write("\r" + " " * (width + 45) + "\r")


def diff(expected: dict[str, Any], got: dict[str, Any]) -> list[str]:
    """A unified diff of two summaries' pretty JSON."""
    a = json.dumps(expected, indent=1, sort_keys=True).splitlines()
    b = json.dumps(got, indent=1, sort_keys=True).splitlines()
    return list(difflib.unified_diff(a, b, "expected", "got", lineterm="", n=1))


def problem_files(directory: Path) -> tuple[list[Path], list[str]]:
    """The problem files under ``directory`` (sorted) and a note line for each other KB file.

    A file that cannot be read or parsed counts as a problem: planning it reports why."""
    problems: list[Path] = []
    notes: list[str] = []
    for p in sorted(directory.rglob("*.yaml")):
        try:
            kind = file_kind(read_yaml(p))
        except SparError:
            problems.append(p)
            continue
        if kind is KINDS["problem"]:
            problems.append(p)
        else:
            what = kind.called if kind is not None else "not a problem file (no `problem:`)"
            notes.append(f"skipped {p.relative_to(directory)}: {what}")
    return problems, notes


def _row_name(directory: Path, problem: Path) -> str:
    """A problem's name in the table: its stem, with its folder below DIR if any."""
    rel = problem.relative_to(directory).with_suffix("")
    return rel.name if rel.parent == Path(".") else str(rel)


def run_regression(directory: Path, jobs: int = 1, update: bool = False, scheduler: str | None = None,
                   client: Any = None, write_all: Callable[[list[tuple[Path, str]]], None] | None = None) -> int:
    """Run every problem under ``directory``; print the table; return the exit code (0/1).

    ``write_all([(path, text), ...])`` writes the expected results with ``--update``, once
    every problem has run (the ``spar`` command passes its run guard's: all of them or,
    after a Ctrl-C, none, and none half written); default: each by ``Path.write_text``.

    ``jobs`` > 1: that many worker processes here. ``scheduler`` (an address such as
    ``tcp://host:8786``) or ``client`` (a ``distributed.Client``): the problems run as
    tasks on that Dask cluster (:func:`run_on_cluster`). The table is in the problems'
    order whichever way they ran."""
    problems, notes = problem_files(directory)
    for note in notes:
        print(note)
    if not problems:
        print(f"spar: regress: no problem files (*.yaml with `problem:`) in {directory}", file=sys.stderr)
        return 2
    names = {str(p): _row_name(directory, p) for p in problems}
    paths = [str(p) for p in problems]
    results: list[Result] = []
    if client is not None or scheduler is not None:
        own = client is None
        client = connect(scheduler) if own else client
        try:
            results = run_on_cluster(paths, client, _progress)
        finally:
            if own:
                client.close()
    elif jobs == 1:
        for i, p in enumerate(problems):
            _progress(i, len(problems), p.stem)
            results.append(_plan_one(str(p)))
    else:
        ctx = multiprocessing.get_context("spawn")
        with cf.ProcessPoolExecutor(max_workers=jobs, mp_context=ctx) as pool:
            futs = {pool.submit(_plan_one, p): p for p in paths}
            for i, f in enumerate(cf.as_completed(futs)):
                _progress(i, len(problems), Path(futs[f]).stem)
                results.append(f.result())
        order = {p: i for i, p in enumerate(paths)}
        results.sort(key=lambda r: order[r[0]])
    _progress(len(problems), len(problems), "")

    failed = 0
    rows = []
    diffs: list[str] = []
    updates: list[tuple[Path, str]] = []
    for path, got, err, secs in results:
        stem, expected_dir = names[path], Path(path).parent / "expected"
        exp_path = expected_dir / f"{Path(path).stem}.json"
        if got is None:
            status, note = "ERROR", err
            failed += 1
        elif update:
            updates.append((exp_path, json.dumps(got, indent=1, sort_keys=True) + "\n"))
            status, note = "UPDATED", got["outcome"]
        elif not exp_path.exists():
            status, note = "NEW", f"no {exp_path} (run with --update to accept)"
            failed += 1
        else:
            expected = json.loads(exp_path.read_text())
            if expected == got:
                status, note = "PASS", _note(got)
            else:
                status, note = "FAIL", f"differs from {exp_path}"
                failed += 1
                diffs += [f"--- {stem}"] + diff(expected, got)
        rows.append((stem, status, f"{secs:7.2f}", note))

    if updates:
        for p, _ in updates:
            p.parent.mkdir(exist_ok=True)
        (write_all or _write_each)(updates)
    w = max(len(r[0]) for r in rows)
    print(f"{'problem':{w}}  result   time/s  note")
    for stem, status, secs, note in rows:
        print(f"{stem:{w}}  {status:7}  {secs}  {note}")
    total = sum(r[3] for r in results)
    print(f"{len(rows) - failed} of {len(rows)} passed, {total:.2f} s of planning")
    if diffs:
        print("\n".join(diffs))
    return 1 if failed else 0


def _write_each(files: list[tuple[Path, str]]) -> None:
    for path, text in files:
        path.write_text(text, encoding="utf-8")


def _note(s: dict[str, Any]) -> str:
    if s["outcome"] != "plan":
        return f"no plan ({(s.get('reason') or {}).get('goal', '')})"
    return (f"{len(s['actions'])} actions, {len(s.get('sensing', []))} sensing/squeeze, "
            f"errors {s.get('error_count')}")
