"""Cold start: the planner loaded from its compiled image (.qlf) or SWI-Prolog started
from its saved state, never a stale one.

Each test runs a copy of the checkout's package and Prolog sources in a fresh process
(its own cache directory), so it can edit a .pl file without touching the checkout. The
image's tests run with the saved state off (``SPAR_SAVED_STATE=off``), so each run shows
what the image alone does; the state's tests turn it on.
"""
from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import pytest

from spar_py.planning import qlf

from paths import ROOT


#: Run in the copy: load the planner, report how, and ask it two questions (the default
#: action bound from spar_defaults.pl and whether a probe predicate exists).
PROBE = """
import json
from spar_py.planning.engine import Engine
e = Engine()
bound = e.query_once("spar_defaults:default_option(max_actions_floor, N)")["N"]
probe = e.query_once("catch(spar_defaults:coldstart_probe(X), _, fail)")
print(json.dumps({"how": e.loaded_from, "bound": bound, "probe": probe.get("X") if probe["truth"] else None,
                  "state": e.state_status}))
"""


@pytest.fixture()
def tree(tmp_path: Path) -> Path:
    """A copy of src/spar_py, prolog/ and kb/templates/ (the package finds its sources
    beside itself, two levels up)."""
    dest = tmp_path / "tree"
    shutil.copytree(ROOT / "src" / "spar_py", dest / "src" / "spar_py",
                    ignore=shutil.ignore_patterns("__pycache__"))
    shutil.copytree(ROOT / "prolog", dest / "prolog")
    shutil.copytree(ROOT / "kb" / "templates", dest / "kb" / "templates")
    return dest


def _run(tree: Path, cache: Path | str, code: str = PROBE, state: bool = False) -> dict:
    """The probe's answer in a fresh process of ``tree`` (without the "state" status
    unless ``state``: the saved state on)."""
    env = {**os.environ, "PYTHONPATH": str(tree / "src"), qlf.ENV: str(cache),
           qlf.STATE_ENV: "on" if state else "off"}
    r = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=120,
                       cwd=tree)
    assert r.returncode == 0, r.stderr
    doc = json.loads(r.stdout.strip().splitlines()[-1])
    if not state:
        assert doc.pop("state", "") == ""
    return doc


def _defaults(tree: Path) -> Path:
    return tree / "prolog" / "spar_defaults.pl"


def test_compiled_once_then_loaded_from_the_image(tree: Path, tmp_path: Path) -> None:
    cache = tmp_path / "cache"
    first = _run(tree, cache)
    assert first["how"] == "compiled"
    second = _run(tree, cache)
    assert second == {**first, "how": "qlf"}
    images = list(cache.glob("*/planner.qlf"))
    assert len(images) == 1 and (images[0].parent / qlf.MANIFEST).is_file()


def test_an_edited_source_is_loaded_on_the_next_run(tree: Path, tmp_path: Path) -> None:
    """A developer edits prolog/*.pl: the next run compiles and loads the edited code, even
    when the edit keeps the file's size and modification time (the key is the content)."""
    cache = tmp_path / "cache"
    assert _run(tree, cache)["probe"] is None
    assert _run(tree, cache)["how"] == "qlf"
    f = _defaults(tree)
    st = f.stat()
    f.write_text(f.read_text() + "\ncoldstart_probe(1).\n")
    got = _run(tree, cache)
    assert got["how"] == "compiled" and got["probe"] == 1
    assert _run(tree, cache)["probe"] == 1

    # the same length, the old timestamp: a timestamp check would load the image of "1"
    f.write_text(f.read_text().replace("coldstart_probe(1).", "coldstart_probe(2)."))
    os.utime(f, ns=(st.st_atime_ns, st.st_mtime_ns))
    got = _run(tree, cache)
    assert got["how"] == "compiled" and got["probe"] == 2

    # back to the first edit: its image is still in the cache and is loaded again
    f.write_text(f.read_text().replace("coldstart_probe(2).", "coldstart_probe(1)."))
    assert _run(tree, cache) == {"how": "qlf", "bound": got["bound"], "probe": 1}


def test_an_edit_to_a_module_loaded_by_another_is_seen(tree: Path, tmp_path: Path) -> None:
    """kb/templates/spar_actions.pl is loaded through use_module from prolog/ files; changing it
    (here: a new clause of a predicate the planner reads) gives a new image."""
    cache = tmp_path / "cache"
    code = PROBE.replace('"spar_defaults:default_option(max_actions_floor, N)"',
                         '"catch(spar_actions:coldstart_marker(N), _, N = none)"')
    assert _run(tree, cache, code)["bound"] == "none"
    f = tree / "kb" / "templates" / "spar_actions.pl"
    f.write_text(f.read_text() + "\ncoldstart_marker(seen).\n")
    got = _run(tree, cache, code)
    assert got["how"] == "compiled" and got["bound"] == "seen"


def test_a_changed_default_is_what_the_planner_uses(tree: Path, tmp_path: Path) -> None:
    cache = tmp_path / "cache"
    before = _run(tree, cache)["bound"]
    f = _defaults(tree)
    text = f.read_text()
    assert f"default_option(max_actions_floor, {before})" in text
    f.write_text(text.replace(f"default_option(max_actions_floor, {before})",
                              f"default_option(max_actions_floor, {before + 7})"))
    assert _run(tree, cache)["bound"] == before + 7


def test_a_damaged_image_is_rebuilt(tree: Path, tmp_path: Path) -> None:
    """An image that is not the one published (its hash is in the manifest) is compiled again."""
    cache = tmp_path / "cache"
    good = _run(tree, cache)
    (image,) = cache.glob("*/planner.qlf")
    image.write_bytes(image.read_bytes()[:1000])  # truncated
    assert _run(tree, cache) == {**good, "how": "compiled"}
    assert _run(tree, cache)["how"] == "qlf"


def test_an_image_prolog_refuses_is_not_trusted(tree: Path, tmp_path: Path) -> None:
    """An image whose hash matches but which SWI-Prolog does not load (another VM, say):
    this run consults the sources, the next one compiles it again."""
    cache = tmp_path / "cache"
    good = _run(tree, cache)
    (image,) = cache.glob("*/planner.qlf")
    image.write_bytes(b"not a qlf file\n" * 10)
    manifest = image.parent / qlf.MANIFEST
    doc = json.loads(manifest.read_text())
    manifest.write_text(json.dumps({**doc, "sha256": qlf.file_digest(image)}))
    assert _run(tree, cache) == {**good, "how": "source"}
    assert _run(tree, cache) == {**good, "how": "compiled"}
    assert _run(tree, cache)["how"] == "qlf"


def test_cache_off_or_unwritable_consults_the_sources(tree: Path, tmp_path: Path) -> None:
    assert _run(tree, "off")["how"] == "source"
    blocker = tmp_path / "a-file"
    blocker.write_text("")
    assert _run(tree, blocker / "cache")["how"] == "source"


def test_processes_starting_together_share_one_image(tree: Path, tmp_path: Path) -> None:
    cache = tmp_path / "cache"
    with ThreadPoolExecutor(4) as pool:
        got = list(pool.map(lambda _: _run(tree, cache), range(4)))
    assert {g["how"] for g in got} <= {"compiled", "qlf"}
    assert sum(g["how"] == "compiled" for g in got) == 1  # the others waited on the lock
    assert len({(g["bound"], g["probe"]) for g in got}) == 1
    assert len(list(cache.glob("*/planner.qlf"))) == 1


def test_two_checkouts_with_the_same_sources_do_not_share_an_image(tree: Path, tmp_path: Path) -> None:
    """The image records its files by path; a second copy gets its own entry, and its
    modules are its own files."""
    cache = tmp_path / "cache"
    other = tmp_path / "other"
    shutil.copytree(tree, other)
    code = PROBE.replace('"spar_defaults:default_option(max_actions_floor, N)"',
                         '"module_property(spar_toplevel, file(N))"')
    a, b = _run(tree, cache, code), _run(other, cache, code)
    assert a["how"] == b["how"] == "compiled"
    assert a["bound"].startswith(str(tree)) and b["bound"].startswith(str(other))


def test_the_spar_path_is_the_checkout_however_loaded(tree: Path, tmp_path: Path) -> None:
    """prolog/spar_paths.pl's file search path spar names the copy's own templates from the
    sources, the image it compiled, the image loaded again and the saved state; a second
    copy sharing the cache gets its own."""
    cache = tmp_path / "cache"
    code = PROBE.replace('"spar_defaults:default_option(max_actions_floor, N)"',
                         '"absolute_file_name(spar(kb/templates/spar_actions), N, '
                         '[file_type(prolog), access(read)])"')
    want = str(tree / "kb" / "templates" / "spar_actions.pl")
    runs = [_run(tree, "off", code), _run(tree, cache, code), _run(tree, cache, code),
            _run(tree, cache, code, state=True), _run(tree, cache, code, state=True)]
    assert [r["how"] for r in runs] == ["source", "compiled", "qlf", "qlf", "state"]
    assert {r["bound"] for r in runs} == {want}
    other = tmp_path / "other"
    shutil.copytree(tree, other)
    assert _run(other, cache, code)["bound"] == str(other / "kb" / "templates" / "spar_actions.pl")


def test_eviction_keeps_the_most_recently_used(tmp_path: Path) -> None:
    for i in range(5):
        d = tmp_path / f"k{i}"
        d.mkdir()
        (d / qlf.MANIFEST).write_text("{}")
        os.utime(d / qlf.MANIFEST, (1000 + i, 1000 + i))
    removed = qlf.evict(tmp_path, keep=3, spare="k0")
    assert sorted(p.name for p in removed) == ["k1", "k2"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["k0", "k3", "k4"]


def test_the_key_changes_with_every_part() -> None:
    roots = [ROOT / "prolog" / "spar.pl"]
    s = qlf.Sources.scan(roots, [ROOT / "prolog"])
    k = qlf.key(s, 90209, "/swi")
    assert k == qlf.key(qlf.Sources.scan(roots, [ROOT / "prolog"]), 90209, "/swi")
    assert k != qlf.key(s, 90210, "/swi") and k != qlf.key(s, 90209, "/other")
    one = next(iter(s.hashes))
    changed = qlf.Sources(s.roots, s.dirs, {**s.hashes, one: "0" * 64})
    fewer = qlf.Sources(s.roots, s.dirs, {p: h for p, h in s.hashes.items() if p != one})
    assert len({k, qlf.key(changed, 90209, "/swi"), qlf.key(fewer, 90209, "/swi")}) == 3


def test_loader_quotes_paths() -> None:
    text = qlf.loader_text((Path("/a b/it's.pl"),))
    assert ":- use_module('/a b/it\\'s.pl')." in text


def test_the_benchmark_measures_plan_and_floor_in_one_run() -> None:
    """bench/coldstart.py at its smallest: every command ran, the figures are positive, the
    cold plan imports none of the heavy libraries but the collision library (python-fcl: the
    paper's cell's fingers come near its parts, and those pairs are measured exactly; issue
    15), and the section renders."""
    sys.path.insert(0, str(ROOT))
    try:
        from bench import coldstart
    finally:
        sys.path.remove(str(ROOT))
    r = coldstart.run(repeats=1, importtime_runs=1)
    assert set(r["median"]) == {"floor", "floor, frozen exit", "plan", "plan, image", "plan, sources", "engine",
                                "engine, image", "engine, sources"}
    assert all(v > 0 for v in r["median"].values())
    assert r["ratio"] == pytest.approx(r["median"]["plan"] / r["median"]["floor"])
    assert r["ratio_frozen"] == pytest.approx(r["median"]["plan"] / r["median"]["floor, frozen exit"])
    assert set(r["imports"]["heavy"]) <= {"fcl"}
    assert any(g.startswith("spar_py.") for g, _ in r["imports"]["beyond_floor"])
    assert r["breakdown"]["loaded_from"] == ["state"]  # the cache filled first: the plan starts from the state
    steps = r["breakdown"]["steps"]
    again = [k for k in steps if k.startswith("Planner.plan again")]
    assert len(again) == 1 and steps[again[0]] > 0  # the warm plan, apart from the cold run's steps
    text = "\n".join(coldstart.render(r))
    assert "## Cold start" in text and "x the floor" in text
    assert coldstart.target_rows(r)[0][2] in ("met", "NOT met") and coldstart.target_rows(None) == []


def test_spar_plan_after_an_edit_compiles_in_its_loading_thread(tree: Path, tmp_path: Path) -> None:
    """`spar plan` loads the Prolog in a background thread: after an edit that thread
    compiles the new image, and the plan is the same as from the sources."""
    cache = tmp_path / "cache"
    env = {**os.environ, "PYTHONPATH": str(tree / "src")}
    cmd = [sys.executable, "-m", "spar_py", "plan", str(ROOT / "kb" / "problems" / "peg_in_block.yaml"),
           "--json"]

    def plan(cache_setting: str) -> dict:
        r = subprocess.run(cmd, env={**env, qlf.ENV: cache_setting}, capture_output=True, text=True,
                           timeout=120, cwd=tree)
        assert r.returncode == 0 and r.stderr == "", r.stderr
        doc = json.loads(r.stdout)
        doc.pop("timing", None)
        return doc

    from_sources = plan("off")
    f = tree / "prolog" / "ordering.pl"
    f.write_text(f.read_text() + "\n% an edit that changes no behaviour\n")
    assert not list(cache.glob("*/planner.qlf"))
    assert plan(str(cache)) == from_sources
    # the image, and the saved state taken in that thread once it loaded
    assert len(list(cache.glob("*/" + qlf.MANIFEST))) == 2 and _state(cache).is_file()
    assert plan(str(cache)) == from_sources  # started from the state


# ---------------------------------------------------------------------- the saved state


def _state(cache: Path) -> Path:
    (image,) = cache.glob("state-*/" + qlf.STATE)
    return image


def test_the_saved_state_is_written_once_then_started_from(tree: Path, tmp_path: Path) -> None:
    """The first run compiles the image and saves the state (published once a fresh process
    started from it); the next runs start SWI-Prolog from it, the planner already loaded,
    and answer as the sources do."""
    cache = tmp_path / "cache"
    sources = _run(tree, "off")
    first = _run(tree, cache, state=True)
    assert first == {**sources, "how": "compiled", "state": "written"}
    assert (_state(cache).parent / qlf.MANIFEST).is_file()
    assert not list(cache.glob("state-*/.*.tmp"))  # the staged file was moved into place
    for _ in range(2):
        assert _run(tree, cache, state=True) == {**sources, "how": "state", "state": "used"}


def test_an_edit_is_never_answered_from_an_old_state(tree: Path, tmp_path: Path) -> None:
    """The state's key holds the sources' hashes: after an edit the next run compiles (the old
    state is not started from) and saves a state of its own, which the run after uses."""
    cache = tmp_path / "cache"
    assert _run(tree, cache, state=True)["state"] == "written"
    f = _defaults(tree)
    f.write_text(f.read_text() + "\ncoldstart_probe(3).\n")
    got = _run(tree, cache, state=True)
    assert got["how"] == "compiled" and got["probe"] == 3 and got["state"] == "written"
    assert _run(tree, cache, state=True) == {**got, "how": "state", "state": "used"}
    assert len(list(cache.glob("state-*/" + qlf.STATE))) == 2


def test_a_damaged_state_is_not_started_from(tree: Path, tmp_path: Path) -> None:
    """A state whose bytes are not the published ones (SWI-Prolog aborts the process that
    starts from a state it cannot read) is never used: the run loads the image and saves
    the state again."""
    cache = tmp_path / "cache"
    _run(tree, cache, state=True)
    image = _state(cache)
    image.write_bytes(image.read_bytes()[:5000])
    got = _run(tree, cache, state=True)
    assert got["how"] == "qlf" and got["state"] == "written"
    assert _run(tree, cache, state=True)["how"] == "state"


def test_a_state_that_does_not_start_is_never_published(tmp_path: Path) -> None:
    """The check a state passes before it is published runs in another process: a file
    SWI-Prolog cannot start from fails it, and this process lives on."""
    from spar_py.planning.engine import _roots, _starts_from

    bad = tmp_path / "bad.state"
    bad.write_bytes(b"#!/bin/sh\n# not a state\n" * 50)
    assert _starts_from(bad, _roots()) is False


def test_the_saved_state_off_keeps_janus_own_start(tree: Path, tmp_path: Path) -> None:
    cache = tmp_path / "cache"
    assert _run(tree, cache)["how"] == "compiled"
    assert _run(tree, cache)["how"] == "qlf"
    assert not list(cache.glob("state-*"))


def test_processes_starting_together_write_one_state(tree: Path, tmp_path: Path) -> None:
    """Processes that find no state and load the planner together: one writes the state, the
    others do not wait for it (their status is "busy" or "ready")."""
    cache = tmp_path / "cache"
    _run(tree, cache)  # the image alone, so the four do not also wait on its compile
    with ThreadPoolExecutor(4) as pool:
        got = list(pool.map(lambda _: _run(tree, cache, state=True), range(4)))
    assert sum(g["state"] == "written" for g in got) == 1
    assert {g["state"] for g in got} <= {"written", "busy", "ready", "used"}
    assert len({(g["bound"], g["probe"]) for g in got}) == 1
    assert _run(tree, cache, state=True)["how"] == "state"


def test_the_state_key_changes_with_swi_prolog_and_janus(tmp_path: Path) -> None:
    s = qlf.Sources.scan([ROOT / "prolog" / "spar.pl"], [ROOT / "prolog"])
    home, janus = tmp_path / "home", tmp_path / "janus"
    home.mkdir()
    janus.mkdir()
    (home / "boot.prc").write_bytes(b"boot")
    (janus / "_swipl.so").write_bytes(b"ext")
    (janus / "janus.pl").write_text(":- module(janus, []).\n")
    ident = qlf.swi_identity(str(home), janus)
    k = qlf.state_key(s, ident)
    assert k == qlf.state_key(s, qlf.swi_identity(str(home), janus)) and k != qlf.key(s, 90209, str(home))
    (janus / "janus.pl").write_text(":- module(janus, [py_call/2]).\n")
    k2 = qlf.state_key(s, qlf.swi_identity(str(home), janus))
    (home / "boot.prc").write_bytes(b"boot, rebuilt")
    k3 = qlf.state_key(s, qlf.swi_identity(str(home), janus))
    assert len({k, k2, k3}) == 3
    (janus / "_swipl.so").unlink()
    assert qlf.swi_identity(str(home), janus) is None


def test_no_home_directory_means_no_cache(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv(qlf.ENV, raising=False)
    monkeypatch.delenv("XDG_CACHE_HOME", raising=False)
    monkeypatch.setattr(Path, "home", classmethod(lambda cls: (_ for _ in ()).throw(RuntimeError("no home"))))
    assert qlf.cache_dir() is None
    monkeypatch.setenv(qlf.ENV, "off")
    assert qlf.cache_dir() is None


def test_a_plan_with_motions_ends_without_a_word_on_stderr() -> None:
    """`spar` ends with the shutdown collections skipped (cli.exiting, gc.freeze) only when no
    library that reports live objects at exit as leaks is loaded: a plan with motions loads OMPL
    (nanobind), and its run still ends with nothing on stderr and exit code 0."""
    problem = str(ROOT / "kb" / "problems" / "wall_detour.yaml")
    r = subprocess.run([sys.executable, "-m", "spar_py", "plan", problem], capture_output=True, text=True,
                       timeout=300, cwd=ROOT)
    assert r.returncode == 0 and r.stderr == "", r.stderr[-500:]


#: Modules a plain `spar plan` of the paper's cell has no use for (each was once imported by
#: it, costing its cold start a few ms): hashlib loads OpenSSL's libcrypto and _blake2 (the
#: planner image's key needs SHA-256 only: qlf.py takes _sha256 itself).
NOT_FOR_A_PLAIN_PLAN = ("hashlib", "_hashlib", "_blake2")


def test_a_plain_plan_does_not_import_what_it_does_not_use() -> None:
    code = ("import contextlib, io, json, sys\nfrom spar_py.app import cli\n"
            "with contextlib.redirect_stdout(io.StringIO()) as out:\n"
            "    try:\n        cli.main(['plan', 'kb/problems/peg_in_block.yaml', '--json'])\n"
            "    except SystemExit as e:\n        code = e.code\n"
            f"print(json.dumps([code, json.loads(out.getvalue())['outcome'], "
            f"sorted(m for m in {NOT_FOR_A_PLAIN_PLAN!r} if m in sys.modules)]))\n")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120, cwd=ROOT)
    assert r.returncode == 0, r.stderr[-500:]
    assert json.loads(r.stdout.strip().splitlines()[-1]) == [0, "plan", []]


def test_collections_are_held_until_the_problem_is_read() -> None:
    """The console script holds the cyclic collector off while it imports and reads the
    problem (entry.hold_collections) and resumes it before planning; `cli.main` called from
    Python leaves the collector as it found it (never disabled, nothing frozen)."""
    code = ("import contextlib, gc, io, json, sys\nfrom spar_py.app import cli\nfrom spar_py.startup import entry\n"
            "from spar_py.planning import planner\n"
            "seen = {}\nplan = planner.Planner.plan\n"
            "def spy(self, *a, **k):\n    seen.setdefault('enabled', gc.isenabled()); return plan(self, *a, **k)\n"
            "planner.Planner.plan = spy\n"
            "def run():\n    with contextlib.redirect_stdout(io.StringIO()):\n        try:\n"
            "            cli.main(['plan', 'kb/problems/peg_in_block.yaml'])\n"
            "        except SystemExit as e:\n            return e.code\n"
            "api = [run(), seen.pop('enabled'), gc.isenabled(), gc.get_freeze_count()]\n"
            "entry.hold_collections()\nheld = gc.isenabled()\n"
            "script = [run(), seen.pop('enabled'), gc.isenabled(), gc.get_freeze_count() > 0]\n"
            "print(json.dumps([api, held, script]))\n")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120, cwd=ROOT)
    assert r.returncode == 0, r.stderr[-500:]
    assert json.loads(r.stdout.strip().splitlines()[-1]) == [[0, True, True, 0], False, [0, True, True, True]]


#: Run in a fresh process: write to stdout (unflushed), maybe start a thread that is still
#: running, then call cli.exiting(code) as the console script does, and write again.
EXITING = """
import sys, threading, time
from spar_py.app import cli
sys.stdout.write("before\\n")
if sys.argv[2] == "thread":
    threading.Thread(target=time.sleep, args=(0.3,)).start()
cli.exiting(eval(sys.argv[1]))
print("after")
"""


@pytest.mark.parametrize("code, thread, ends_at_once", [
    ("0", "", True), ("1", "", True), ("None", "", True),
    ("2", "", False), ("130", "", False), ("...", "", False), ("0", "thread", False)])
def test_exiting_ends_at_once_only_when_nothing_is_left_to_do(code: str, thread: str, ends_at_once: bool) -> None:
    """cli.exiting: a run that ended with a plan or without one (exit 0 or 1) ends at once
    (os._exit), its output flushed first; an error's exit, no SystemExit at all (``...``), or a
    thread still running leaves the usual shutdown to do its work."""
    r = subprocess.run([sys.executable, "-c", EXITING, code, thread], capture_output=True, text=True,
                       timeout=60, cwd=ROOT)
    assert r.stderr == ""
    assert r.stdout == ("before\n" if ends_at_once else "before\nafter\n")
    assert r.returncode == (int(eval(code) or 0) if ends_at_once else 0)


@pytest.mark.skipif(not Path("/proc/self/task").is_dir(), reason="counts threads in /proc")
@pytest.mark.parametrize("user", [None, "2"])
def test_the_console_script_runs_one_blas_thread_unless_told(user: str | None) -> None:
    """entry.one_blas_thread, as the spar script calls it before numpy loads: numpy's OpenBLAS
    then starts no worker thread (the process has one thread), and a count the user set is kept
    (its workers are there)."""
    code = ("import os\nfrom spar_py.startup.entry import one_blas_thread\none_blas_thread()\nimport numpy\n"
            "print(os.environ.get('OPENBLAS_NUM_THREADS'), len(os.listdir('/proc/self/task')))\n")
    env = {k: v for k, v in os.environ.items() if k not in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS")}
    if user is not None:
        env["OPENBLAS_NUM_THREADS"] = user
    r = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=60)
    assert r.returncode == 0, r.stderr
    value, threads = r.stdout.split()
    assert value == (user or "1")
    if user is None:
        assert threads == "1"
    elif (os.cpu_count() or 1) > 1:
        assert int(threads) == 2  # the main thread and the one worker asked for


def test_the_plan_json_is_the_same_text_however_the_planner_was_loaded(tmp_path: Path) -> None:
    """SWI-Prolog dicts keep their keys in atom-handle order, which depends on what the process
    created first; the image (.qlf) and the sources create atoms in another order. The JSON
    text must not depend on it (planner._canonical)."""
    def plan(env: dict[str, str]) -> str:
        r = subprocess.run([sys.executable, "-m", "spar_py", "plan", "kb/problems/peg_in_block.yaml", "--json"],
                           cwd=ROOT, env={**os.environ, **env}, capture_output=True, text=True, timeout=300)
        assert r.returncode == 0, r.stderr
        doc = json.loads(r.stdout)
        doc.pop("timing")
        return json.dumps(doc)  # the keys in the order the plan gave them

    assert plan({}) == plan({qlf.ENV: "off"}) == plan({qlf.STATE_ENV: "off"})
