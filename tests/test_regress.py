"""spar regress: green on expected outcomes; a changed expectation fails with a readable diff."""
from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest

from spar_py.app.guard import RunGuard
from spar_py.app.regress import run_regression

from paths import ROOT

KB = ROOT / "kb"


def _copy_problem(name: str, dest: Path) -> None:
    text = (KB / "problems" / f"{name}.yaml").read_text()
    text = text.replace("../robots/", f"{KB}/robots/").replace("../objects/", f"{KB}/objects/")
    (dest / f"{name}.yaml").write_text(text)
    (dest / "expected").mkdir(exist_ok=True)
    exp = KB / "problems" / "expected" / f"{name}.json"
    (dest / "expected" / exp.name).write_text(exp.read_text())


def test_regression_passes_then_fails_on_a_changed_expectation(tmp_path: Path,
                                                               capsys: pytest.CaptureFixture[str]) -> None:
    for name in ("hole_up", "placement_trap"):
        _copy_problem(name, tmp_path)
    assert run_regression(tmp_path) == 0
    out = capsys.readouterr().out
    assert "2 of 2 passed" in out and "PASS" in out

    exp = tmp_path / "expected" / "hole_up.json"
    doc = json.loads(exp.read_text())
    doc["actions"] = doc["actions"][:1]  # pretend we expected one action only
    exp.write_text(json.dumps(doc))
    assert run_regression(tmp_path) == 1
    out = capsys.readouterr().out
    assert "FAIL" in out and "1 of 2 passed" in out
    assert "--- expected" in out and "+++ got" in out
    assert '+  "assemble(peg,block,[[peg_face],[block_face]],trans_1,vec_1)",' in out


def test_every_problem_has_an_expected_outcome() -> None:
    problems = {p.stem for p in (KB / "problems").glob("*.yaml")}
    expected = {p.stem for p in (KB / "problems" / "expected").glob("*.json")}
    assert problems == expected


# ---------------------------------------------------------------------- on a Dask cluster

distributed = pytest.importorskip("distributed")

#: Problems that plan in well under a second each (kept small: each test starts a cluster).
CLUSTER_SUITE = ("hole_up", "peg_in_block", "placement_trap", "separation", "two_pegs")


@pytest.fixture()
def suite(tmp_path: Path) -> Path:
    for name in CLUSTER_SUITE:
        _copy_problem(name, tmp_path)
    return tmp_path


@pytest.fixture(params=[None])
def cluster(request):
    """A LocalCluster of two single-threaded worker processes (each its own Prolog), and a
    client that is not made the process's default; ``request.param``: the scheduler's
    ``allowed-failures`` (None: Dask's default)."""
    import dask

    config = {} if request.param is None else {"distributed.scheduler.allowed-failures": request.param}
    with dask.config.set(config), \
            distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                     dashboard_address=None) as c, \
            distributed.Client(c, set_as_default=False) as client:
        yield client


def _table_rows(out: str) -> list[tuple[str, str]]:
    """(problem, result) of each table row printed by run_regression."""
    lines = out.splitlines()
    start = next(i for i, ln in enumerate(lines) if ln.startswith("problem "))
    rows = []
    for ln in lines[start + 1:]:
        parts = ln.split()
        if len(parts) < 2 or parts[1] not in ("PASS", "FAIL", "ERROR", "NEW", "UPDATED"):
            break
        rows.append((parts[0], parts[1]))
    return rows


@pytest.mark.slow
def test_cluster_run_gives_every_result_in_the_problems_order(suite: Path, cluster,
                                                              capsys: pytest.CaptureFixture[str]) -> None:
    assert run_regression(suite, client=cluster) == 0
    out = capsys.readouterr().out
    assert _table_rows(out) == [(n, "PASS") for n in sorted(CLUSTER_SUITE)]
    assert f"{len(CLUSTER_SUITE)} of {len(CLUSTER_SUITE)} passed" in out

    # a changed expectation fails on the cluster as it does here, with the same diff
    exp = suite / "expected" / "hole_up.json"
    doc = json.loads(exp.read_text())
    exp.write_text(json.dumps({**doc, "actions": doc["actions"][:1]}))
    assert run_regression(suite, client=cluster) == 1
    on_cluster = capsys.readouterr().out
    assert run_regression(suite) == 1
    here = capsys.readouterr().out
    assert _table_rows(on_cluster) == _table_rows(here)
    assert on_cluster.split("planning\n", 1)[1] == here.split("planning\n", 1)[1]  # the diffs


@pytest.mark.slow
def test_a_problem_that_does_not_load_is_an_error_row(suite: Path, cluster,
                                                      capsys: pytest.CaptureFixture[str]) -> None:
    (suite / "broken.yaml").write_text("problem: broken\nrobot: nowhere.yaml\n")
    assert run_regression(suite, client=cluster) == 1
    rows = dict(_table_rows(capsys.readouterr().out))
    assert rows.pop("broken") == "ERROR" and set(rows.values()) == {"PASS"}


@pytest.mark.slow
@pytest.mark.parametrize("cluster", [None, 0], indirect=True, ids=["dask-reschedules", "spar-resubmits"])
def test_a_worker_killed_mid_run_loses_no_result(suite: Path, cluster,
                                                 capsys: pytest.CaptureFixture[str]) -> None:
    """SIGKILL the worker running a problem: its task runs again on a worker that is
    alive (the nanny restarts the killed one) and every problem still has its result.
    Rescheduled by Dask (its default allowed-failures) or, where Dask gives up at once
    (allowed-failures 0: KilledWorker), submitted again by run_on_cluster."""
    import os
    import signal
    import threading
    import time

    done: dict[str, int] = {}
    run = threading.Thread(target=lambda: done.update(code=run_regression(suite, client=cluster)), daemon=True)
    run.start()
    victim = None
    deadline = time.monotonic() + 60
    while victim is None and time.monotonic() < deadline:
        for worker, keys in cluster.processing().items():
            ours = [k for k in keys if str(k).startswith("spar-regress-")]
            if ours:
                victim = (worker, ours)
                break
        time.sleep(0.005)
    assert victim is not None, "no task was seen processing"
    worker, keys = victim
    pid = cluster.run(os.getpid, workers=[worker])[worker]
    os.kill(pid, signal.SIGKILL)
    run.join(timeout=180)
    assert not run.is_alive()
    assert done["code"] == 0
    out = capsys.readouterr().out
    assert _table_rows(out) == [(n, "PASS") for n in sorted(CLUSTER_SUITE)]

    # the killed worker's task went to processing again after the kill (the scheduler's story)
    def processing_count(key: str):
        def count(dask_scheduler) -> int:
            return sum(1 for t in dask_scheduler.story(key) if t[0] == key and t[2] == "processing")
        return count

    counts = [cluster.run_on_scheduler(processing_count(k)) for k in keys]
    if cluster.run_on_scheduler(lambda dask_scheduler: dask_scheduler.allowed_failures) > 0:
        assert max(counts) >= 2  # the same task, rescheduled
    else:
        assert max(counts) == 1  # Dask gave up on it: the result came from a new task


def test_scheduler_and_jobs_exclude_each_other_and_a_bad_address_is_one_line(suite: Path) -> None:
    import subprocess
    import sys

    spar = [sys.executable, "-m", "spar_py", "regress", str(suite)]
    r = subprocess.run(spar + ["-j", "2", "--scheduler", "tcp://127.0.0.1:8786"], capture_output=True,
                       text=True, timeout=60)
    assert r.returncode == 2 and r.stderr.count("\n") == 1 and "-j" in r.stderr and "--scheduler" in r.stderr
    r = subprocess.run(spar + ["--scheduler", "bogus://x:1"], capture_output=True, text=True, timeout=60)
    assert r.returncode == 2 and r.stderr.count("\n") == 1
    assert r.stderr.startswith("spar: regress: --scheduler bogus://x:1: expected an address")


def test_update_writes_every_expected_outcome_and_then_the_suite_passes(tmp_path: Path,
                                                                        capsys: pytest.CaptureFixture[str]) -> None:
    for name in ("hole_up", "placement_trap"):
        _copy_problem(name, tmp_path)
    shutil.rmtree(tmp_path / "expected")
    assert run_regression(tmp_path) == 1  # nothing expected yet: NEW
    assert "NEW" in capsys.readouterr().out
    written: list[list[Path]] = []

    def write_all(files: list[tuple[Path, str]]) -> None:
        written.append([p for p, _ in files])
        for p, text in files:
            p.write_text(text)

    assert run_regression(tmp_path, update=True, write_all=write_all) == 0
    # one call with both files, after both problems ran: all or none (the guard's write_all)
    assert written == [[tmp_path / "expected" / "hole_up.json", tmp_path / "expected" / "placement_trap.json"]]
    for name in ("hole_up", "placement_trap"):
        got = json.loads((tmp_path / "expected" / f"{name}.json").read_text())
        assert got == json.loads((KB / "problems" / "expected" / f"{name}.json").read_text())
    assert run_regression(tmp_path) == 0
    assert "2 of 2 passed" in capsys.readouterr().out


def test_the_guards_write_all_writes_all_or_none(tmp_path: Path) -> None:
    """A file that cannot be staged (its directory is a file) stops the set before any file
    is replaced; a stop (cleanup) before the commit leaves the old files and no staging."""
    a, b = tmp_path / "a.json", tmp_path / "b.json"
    a.write_text("old a")
    blocker = tmp_path / "blocker"
    blocker.write_text("")
    exits: list[int] = []
    with RunGuard(exit=exits.append) as guard:
        with pytest.raises(OSError):
            guard.write_all([(a, "new a"), (blocker / "c.json", "new c")])
        guard.cleanup()
    assert a.read_text() == "old a" and not [p for p in tmp_path.glob(".*")]
    with RunGuard(exit=exits.append) as guard:
        guard.write_all([(a, "new a"), (b, "new b")])
    assert a.read_text() == "new a" and b.read_text() == "new b"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.json", "b.json", "blocker"]
