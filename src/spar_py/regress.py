"""Batch regression runs: every problem of a knowledge base against its expected outcome.

For each problem file under DIR (a ``*.yaml`` whose top-level mapping has ``problem:``,
at any depth) the expected outcome lives beside it in ``expected/<stem>.json``: the
summary of its plan (outcome, actions, orderings, sensing inserted, error count, the
bindings that are unique). Object and robot models are skipped with a note line (so
``spar regress kb`` works). ``spar regress DIR``
plans every problem (``-j N`` worker processes, each with its own embedded Prolog),
prints a table of pass/fail and times, a readable diff for each failure, and exits 1
if anything failed; ``--update`` writes the new outcomes as the expected ones.
"""
from __future__ import annotations

import concurrent.futures as cf
import difflib
import json
import multiprocessing
import sys
import time
from pathlib import Path
from typing import Any

from .errors import SparError


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


def _plan_one(path: str) -> tuple[str, dict[str, Any] | None, str, float]:
    """Plan one problem file; (path, summary or None, error text, seconds)."""
    from .planner import Planner

    t0 = time.perf_counter()
    try:
        plan = Planner().plan(Path(path))
        return path, summarize(plan.to_json()), "", time.perf_counter() - t0
    except SparError as e:
        return path, None, str(e).splitlines()[0], time.perf_counter() - t0


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
    from .kb import KINDS, file_kind, read_yaml

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


def run_regression(directory: Path, jobs: int = 1, update: bool = False) -> int:
    """Run every problem under ``directory``; print the table; return the exit code (0/1)."""
    problems, notes = problem_files(directory)
    for note in notes:
        print(note)
    if not problems:
        print(f"spar: regress: no problem files (*.yaml with `problem:`) in {directory}", file=sys.stderr)
        return 2
    names = {str(p): _row_name(directory, p) for p in problems}
    results: list[tuple[str, dict | None, str, float]] = []
    if jobs == 1:
        for i, p in enumerate(problems):
            _progress(i, len(problems), p.stem)
            results.append(_plan_one(str(p)))
    else:
        ctx = multiprocessing.get_context("spawn")
        with cf.ProcessPoolExecutor(max_workers=jobs, mp_context=ctx) as pool:
            futs = {pool.submit(_plan_one, str(p)): p for p in problems}
            for i, f in enumerate(cf.as_completed(futs)):
                _progress(i, len(problems), futs[f].stem)
                results.append(f.result())
        results.sort()
    _progress(len(problems), len(problems), "")

    failed = 0
    rows = []
    diffs: list[str] = []
    for path, got, err, secs in results:
        stem, expected_dir = names[path], Path(path).parent / "expected"
        exp_path = expected_dir / f"{Path(path).stem}.json"
        if got is None:
            status, note = "ERROR", err
            failed += 1
        elif update:
            expected_dir.mkdir(exist_ok=True)
            exp_path.write_text(json.dumps(got, indent=1, sort_keys=True) + "\n")
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

    w = max(len(r[0]) for r in rows)
    print(f"{'problem':{w}}  result   time/s  note")
    for stem, status, secs, note in rows:
        print(f"{stem:{w}}  {status:7}  {secs}  {note}")
    total = sum(r[3] for r in results)
    print(f"{len(rows) - failed} of {len(rows)} passed, {total:.2f} s of planning")
    if diffs:
        print("\n".join(diffs))
    return 1 if failed else 0


def _note(s: dict[str, Any]) -> str:
    if s["outcome"] != "plan":
        return f"no plan ({(s.get('reason') or {}).get('goal', '')})"
    return (f"{len(s['actions'])} actions, {len(s.get('sensing', []))} sensing/squeeze, "
            f"errors {s.get('error_count')}")
