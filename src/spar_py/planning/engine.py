"""The janus bridge, Python side: start the embedded SWI-Prolog, load the planner, run queries.

This is the only Python module that imports janus. Prolog reaches Python through
the functions at the bottom of this file (called from prolog/foreign.pl with
``py_call(spar_py.planning.engine:...)``); the geometric ones (arc_pairs, evaluate) are
answered by the planning run of their problem (planning/run.py: PlanRun), the others
delegate to the loaders.

SWI-Prolog is located from ``_swipl.json`` beside this file, written by ``make setup``
with the home directory janus-swi was compiled against. Setting ``SWI_HOME_DIR``
before janus starts makes the embedded Prolog use that home even when an older
``swipl`` (whose boot file would abort with "incompatible VM-signature") is first on
PATH.
"""
from __future__ import annotations

import importlib
import importlib.util
import json
import os
import sys
import threading
import time
from contextlib import contextmanager
from pathlib import Path
from typing import Any, Iterator

from spar_py.core.errors import InternalError, PlanningTimeout, PrologError, SparError
from spar_py.planning import qlf

PACKAGE_DIR = Path(__file__).resolve().parent.parent  # src/spar_py
ROOT = PACKAGE_DIR.parent.parent  # the checkout: prolog/, kb/ live here
PROLOG_DIR = ROOT / "prolog"
TEMPLATES_DIR = ROOT / "kb" / "templates"
RECORD = PACKAGE_DIR / "_swipl.json"

_lock = threading.Lock()
_engine: "Engine | None" = None
#: The loaded problems when Prolog hosts Python (a bare ``swipl`` loading prolog/spar.pl, janus
#: importing this module): there is no Engine then, and the toplevel's load_problem/1 keeps its
#: cells and runs here.
_hosted: "ProblemRegistry | None" = None


#: Problems a session keeps loaded after its run (the last ones planned), so planning one
#: again does not reload its facts.
KEEP_LOADED = 8


def _malloc_trim() -> Any:
    """glibc's malloc_trim(3), or None where the C library has none."""
    try:
        import ctypes  # only a run that trims needs it

        return ctypes.CDLL(None).malloc_trim
    except (OSError, AttributeError):
        return None




def _one_line(text: str) -> str:
    """The first non-empty line of ``text``, stripped."""
    return next((ln.strip() for ln in text.splitlines() if ln.strip()), "")


def swipl_record() -> dict[str, Any]:
    """The SWI-Prolog recorded at set-up: ``{"home": ..., "version": ..., "swipl": ...}`` or {}."""
    try:
        return json.loads(RECORD.read_text())
    except (OSError, ValueError):
        return {}


def _swi_home() -> str | None:
    """The SWI-Prolog home janus is to use (``SPAR_SWIPL_HOME``, else the set-up record)."""
    return os.environ.get("SPAR_SWIPL_HOME") or swipl_record().get("home")


def _roots() -> list[Path]:
    """The planner's files in load order: prolog/spar.pl, then kb/templates/*.pl."""
    return [PROLOG_DIR / "spar.pl", *sorted(TEMPLATES_DIR.glob("*.pl"))]


def _root_names(roots: list[Path]) -> list[str]:
    """``roots`` as the absolute paths Prolog's source_file/1 names them by."""
    return [str(p.resolve()) for p in roots]


def _import_janus(state: Path | None = None) -> tuple[Any, bool]:
    """(janus_swi imported, True if SWI-Prolog started from the saved state ``state``).

    A state is used only by the import that starts SWI-Prolog (janus not imported yet)."""
    home = _swi_home()
    if home:
        os.environ["SWI_HOME_DIR"] = home
    try:
        if state is not None and "janus_swi" not in sys.modules:
            return _janus_from_state(state)
        import janus_swi as janus  # its import starts SWI-Prolog: only here, once the state is settled
    except ImportError as e:  # pragma: no cover - set-up problem, not a planner one
        raise SparError(f"janus-swi is not importable ({e}); run `make setup`") from None
    return janus, False


def _janus_from_state(state: Path) -> tuple[Any, bool]:
    """Import janus_swi with SWI-Prolog started from the saved state ``state``.

    janus' package ``__init__`` starts SWI-Prolog with ``_swipl.initialize(argv...)``; it
    runs here as it is, with ``initialize`` wrapped for the call to put ``-x state`` after
    the program name. janus.py is imported first, as ``__init__`` itself does first: it
    loads the C extension with RTLD_GLOBAL, which the foreign libraries a state reloads
    need. (janus, False) if ``__init__`` did not start SWI-Prolog through ``initialize``
    (a janus of another shape): it then started as janus does, without the state."""
    spec = importlib.util.find_spec("janus_swi")
    if spec is None or spec.loader is None:
        raise ImportError("no module named 'janus_swi'")
    package = importlib.util.module_from_spec(spec)
    sys.modules["janus_swi"] = package
    try:
        importlib.import_module("janus_swi.janus")
        ext = sys.modules["janus_swi._swipl"]
        real = ext.initialize
        used: list[bool] = []

        def initialize(*argv: str) -> Any:
            used.append(True)
            return real(*argv[:1], "-x", str(state), *argv[1:])

        ext.initialize = initialize
        try:
            spec.loader.exec_module(package)
        finally:
            ext.initialize = real
    except BaseException:
        for name in [m for m in sys.modules if m == "janus_swi" or m.startswith("janus_swi.")]:
            del sys.modules[name]
        raise
    return package, bool(used)


#: The query true when every file named in ``Fs`` (:func:`_root_names`) is loaded. member/2
#: by its module: the query runs in ``user``, which does not import library(lists), and a
#: bare member/2 there is autoloaded, which reads SWI-Prolog's library index first (a cost
#: of every start from the saved state; the planner's modules import what they use).
ROOTS_LOADED = "forall(lists:member(_S, Fs), (atom_string(_F, _S), source_file(_F)))"
#: The query a process started from a saved state answers before the state is published
#: (:meth:`Engine._save_state`) or used: every planner file loaded, the planner's entry
#: point defined, and Python reachable from Prolog.
STATE_PROBE = ROOTS_LOADED + ", current_predicate(spar:plan_dict/4), py_call(math:sqrt(4.0), _R), _R =:= 2.0"

_CHECK_STATE = """\
import json, sys
sys.path.insert(0, sys.argv[1])
from spar_py.planning.engine import _import_janus, STATE_PROBE
janus, used = _import_janus(__import__("pathlib").Path(sys.argv[2]))
ok = used and janus.query_once(STATE_PROBE, {"Fs": json.loads(sys.argv[3])})["truth"]
print("state ok" if ok else "state refused")
"""


def _starts_from(state: Path, roots: list[Path]) -> bool:
    """True if a fresh process starts SWI-Prolog from ``state`` and finds the planner there
    (a state SWI-Prolog cannot read aborts the process that tries: never this one)."""
    import subprocess  # only when a saved state is tested (numpy loads it later anyway)

    try:
        r = subprocess.run([sys.executable, "-c", _CHECK_STATE, str(PACKAGE_DIR.parent), str(state),
                            json.dumps(_root_names(roots))],
                           capture_output=True, text=True, timeout=120)
    except (OSError, subprocess.SubprocessError):
        return False
    return r.returncode == 0 and r.stdout.strip().endswith("state ok")


class ProblemRegistry:
    """The problems loaded in this process, by name: their cells, the kept answers of cells the
    Prolog toplevel loaded (world.run.CellCache) and the planning run of each problem being
    planned (planning.run.PlanRun). Every call from Prolog into Python names its problem and is
    answered by that problem's run."""

    def __init__(self) -> None:
        self.cells: dict[str, Any] = {}
        #: the planning run of each problem a query is planning now (planning.run.PlanRun)
        self.runs: dict[str, Any] = {}
        #: the kept answers of cells loaded by the Prolog toplevel (world.run.CellCache), by name
        self.caches: dict[str, Any] = {}

    def cell(self, name: str) -> Any:
        """The loaded cell of problem ``name`` (SparError if it is not loaded)."""
        try:
            return self.cells[name]
        except KeyError:
            raise SparError(f"problem {name!r} is not loaded") from None

    def run(self, name: str) -> Any:
        """The planning run of problem ``name``: the one a session holds, else (a problem the
        Prolog toplevel loaded) a run with the default options, kept until the problem is
        loaded again or forgotten (SparError if the problem is not loaded)."""
        got = self.runs.get(name)
        if got is not None:
            return got
        # planning.run imports phase 2, world.run numpy and the collision layer: not for a bare engine
        from spar_py.planning.run import PlanRun
        from spar_py.world.collision import CellCache

        cell = self.cell(name)
        cache = self.caches.get(name)
        if cache is None or cache.cell is not cell:
            cache = self.caches[name] = CellCache(cell)
        got = self.runs[name] = PlanRun(cache)
        return got


class Engine(ProblemRegistry):
    """The embedded SWI-Prolog with prolog/spar.pl and kb/templates/ consulted (one per process).

    Loaded problems are kept by name (:meth:`load_cell`): their facts in Prolog's kb
    module, their cells here in :attr:`cells`, the planning run of each problem being
    planned in :attr:`runs`; every call from Prolog into Python says which problem it is
    about, and is answered by that problem's run (planning/run.py). Queries are
    serialised: the engine holds one re-entrant lock for each query, and :meth:`session`
    holds it for a whole planning run (load, plan), so threads sharing an engine take turns and never see each other's
    problem.
    """

    def __init__(self, background: bool = False) -> None:
        """Start SWI-Prolog (in this thread) and consult the planner: here, or with
        ``background`` in a thread of its own, so the caller can go on (importing numpy,
        reading the problem) while Prolog compiles; every query waits for it first.

        With a saved state of these very sources in the cache (spar_py/planning/qlf.py), SWI-Prolog
        starts from it, the planner already loaded, and there is nothing left to load."""
        t0 = time.perf_counter()
        super().__init__()
        self._kept: dict[str, None] = {}  # problems sessions keep loaded, oldest first
        self.lock = threading.RLock()
        self._loader: threading.Thread | None = None
        self._trim: Any = False  # glibc's malloc_trim once looked up (None: there is none)
        #: how the planner was loaded: "state" (SWI-Prolog started from the saved state),
        #: "qlf", "compiled" or "source"
        self.loaded_from = ""
        self.load_s = 0.0  # seconds that took (wall, in the thread that loaded it)
        #: the saved state: "used", "written" (by this process), "ready" (published by
        #: another process meanwhile), "busy" (another process is writing it), "refused"
        #: (not saved, or a fresh process could not start from it), "unwritable" (the
        #: cache could not be written), "" (none: cache or state off)
        self.state_status = ""
        self._load_error: BaseException | None = None
        self._sources: Any = None  # qlf.Sources of this start, scanned once
        self._image_extra: dict[str, str] = {}  # the loaded image's files beyond its directories
        self._roots = _roots()
        self._state: Any = self._state_entry()
        ready = self._state is not None and self._state.ready()
        if ready:  # the most recently used entry from now: qlf.evict, run by another process, spares it
            self._state.touch()
        fresh = "janus_swi" not in sys.modules
        self.janus, from_state = _import_janus(self._state.image if ready else None)
        #: SWI-Prolog was started here as janus does, so its state after loading the
        #: planner is the planner's alone, and may be saved
        self._may_save = fresh and not from_state
        if from_state and self._query_once(STATE_PROBE, {"Fs": _root_names(self._roots)})["truth"]:
            self.loaded_from, self.state_status = "state", "used"
            self.load_s = time.perf_counter() - t0
            return
        if background:
            self._loader = threading.Thread(target=self._load_in_thread, name="spar-consult")
            self._loader.start()
        else:
            self._load()

    def _load(self) -> None:
        """Load the planner (prolog/spar.pl, then kb/templates/*.pl): from its compiled
        image when the cache has one for these very sources (spar_py/planning/qlf.py), compiling
        it there first when not, and from the sources when there is no usable cache.
        :attr:`loaded_from` says which ("qlf", "compiled" or "source")."""
        t0 = time.perf_counter()
        roots = self._roots
        how = self._load_image(roots)
        if how is None:
            for f in roots:
                self._consult(f)
            how = "source"
        self.loaded_from = how
        self.load_s = time.perf_counter() - t0
        if how in ("qlf", "compiled") and self._may_save and self._state is not None:
            self._save_state(roots)

    def _state_entry(self) -> Any:
        """The cache entry of the saved state of the planner's sources as they are now
        (qlf.state_entry), or None: cache or saved state off, no SWI-Prolog home or janus
        known before it starts."""
        base = qlf.cache_dir()
        home = _swi_home()
        if base is None or not home or not qlf.saved_state_on():
            return None
        spec = importlib.util.find_spec("janus_swi")
        if spec is None or not spec.origin:
            return None
        identity = qlf.swi_identity(home, Path(spec.origin).parent)
        if identity is None:
            return None
        self._sources = qlf.Sources.scan(self._roots, [PROLOG_DIR, TEMPLATES_DIR])
        return qlf.state_entry(base, qlf.state_key(self._sources, identity))

    def _save_state(self, roots: list[Path]) -> None:
        """Save SWI-Prolog's state now (janus and the planner just loaded, nothing else) as
        the saved-state entry, published once a fresh process started from it. Best
        effort: a busy or unwritable cache, or a state that does not start, leaves the
        entry unpublished (:attr:`state_status` says which)."""
        entry = self._state
        try:
            with qlf.building(entry, wait=False) as must:
                if not must:
                    self.state_status = "ready" if entry.ready() else "busy"
                    return
                tmp = entry.directory / f".{qlf.STATE}.{os.getpid()}.tmp"
                try:
                    self._query_once("qsave_program(F, [stand_alone(false), autoload(false), class(development)])",
                                     {"F": str(tmp)})
                    if not _starts_from(tmp, roots):
                        self.state_status = "refused"
                        return
                    os.replace(tmp, entry.image)
                finally:
                    tmp.unlink(missing_ok=True)
                entry.publish(self._image_extra)
                self.state_status = "written"
        except OSError:  # an unwritable cache: the .qlf image alone, no state
            self.state_status = "unwritable"
        except SparError:  # qsave_program refused (Prolog said why): the image alone
            self.state_status = "refused"

    def _load_image(self, roots: list[Path]) -> str | None:
        """Load the planner from the .qlf cache (see :mod:`spar_py.planning.qlf`); "qlf" if loaded
        from an image, "compiled" if this process compiled (and so loaded) it, None if the
        cache is off or unusable (nothing loaded)."""
        base = qlf.cache_dir()
        if base is None:
            return None
        sources = self._sources or qlf.Sources.scan(roots, [PROLOG_DIR, TEMPLATES_DIR])
        swi = self._query_once("current_prolog_flag(version, V), current_prolog_flag(home, H)")
        entry = qlf.entry(base, qlf.key(sources, int(swi["V"]), str(swi["H"])))
        if entry.ready():
            return self._load_qlf(entry, roots)
        try:
            with qlf.building(entry) as must:
                if not must:
                    return self._load_qlf(entry, roots)
                return self._compile_qlf(entry, sources, str(swi["H"]))
        except OSError:  # an unwritable cache: consult the sources
            return None

    def _load_qlf(self, entry: Any, roots: list[Path]) -> str | None:
        """Load ``entry``'s image; None if SWI-Prolog refuses it or it did not load every
        root file (the caller then consults the sources, and the next run rebuilds it)."""
        try:
            self._query_once("load_files(File, [silent(true)])", {"File": str(entry.image)})
            ok = self._query_once(ROOTS_LOADED, {"Fs": _root_names(roots)})["truth"]
        except SparError:
            ok = False
        if not ok:
            entry.manifest.unlink(missing_ok=True)
            return None
        entry.touch()
        self._image_extra = entry.extra()  # (a state saved later holds what the image holds)
        return "qlf"

    def _compile_qlf(self, entry: Any, sources: Any, swi_home: str) -> str:
        """Compile the planner into ``entry`` (qcompile/2 with include(user): every planner
        file in one image), which also loads it here; publish the entry only if no file it
        holds changed while it was compiled."""
        for stale in (entry.image, entry.manifest):
            stale.unlink(missing_ok=True)
        entry.loader.write_text(qlf.loader_text(sources.roots))
        before = set(self._query_once("findall(_F, source_file(_F), Fs)")["Fs"])
        self._query_once("qcompile(File, [include(user)])", {"File": str(entry.loader)})
        after = set(self._query_once("findall(_F, source_file(_F), Fs)")["Fs"])
        extra: dict[str, str] = {}
        for f in sorted(after - before - {str(entry.loader)}):
            if f.startswith(swi_home.rstrip("/") + "/"):
                continue  # SWI-Prolog's own library: the version is in the key
            digest = qlf.file_digest(Path(f))
            if sources.covers(f):
                if sources.hashes.get(f) != digest:  # edited while compiling: do not keep it
                    entry.image.unlink(missing_ok=True)
                    self._may_save = False  # (nor a state of it)
                    return "compiled"
            else:
                extra[f] = digest
        entry.publish(extra)
        self._image_extra = extra
        qlf.evict(entry.directory.parent, spare=entry.directory.name)
        return "compiled"

    def _load_in_thread(self) -> None:
        try:
            self._load()
        except BaseException as e:  # re-raised in the thread that next queries
            self._load_error = e

    def wait_loaded(self) -> None:
        """Return once the planner's files are consulted (re-raising what stopped that)."""
        loader = self._loader
        if loader is not None and loader is not threading.current_thread():
            loader.join()
            self._loader = None
        if self._load_error is not None:
            raise self._load_error

    def _consult(self, path: Path) -> None:
        self._query_once("consult(File)", {"File": str(path)})

    # ------------------------------------------------------------------ queries

    def query_once(self, goal: str, bindings: dict[str, Any] | None = None) -> dict[str, Any]:
        """Run ``goal`` once with input ``bindings``; the answer dict has ``truth`` and outputs.

        Prolog exceptions are raised as :class:`PrologError` with Prolog's message.
        """
        self.wait_loaded()
        with self.lock:
            return self._query_once(goal, bindings)

    def _query_once(self, goal: str, bindings: dict[str, Any] | None = None) -> dict[str, Any]:
        try:
            return self.janus.query_once(goal, bindings or {})
        except self.janus.PrologError as e:
            raise self._translate(e) from None

    def _translate(self, e: Any) -> BaseException:
        """The exception to raise for a janus PrologError ``e``: the one place Prolog's
        error terms become the SparError family (foreign:error_info/2 classifies them).

        A time limit is :class:`PlanningTimeout`; an abort is KeyboardInterrupt; an
        exception a Python function raised under py_call is raised again as itself when
        it is a SparError (its own one-line message, no Python stack), else as an
        :class:`InternalError` naming its class; any other Prolog error is a
        :class:`PrologError` with the first line of Prolog's message."""
        if getattr(e, "term", None) is None:
            return PrologError("", str(getattr(e, "message", "") or "Prolog error"))
        try:
            info = self.janus.query_once("foreign:error_info(E, Info)", {"E": e.term})["Info"]
        except Exception:  # the classification itself failed: keep what janus says
            return PrologError(repr(e), _one_line(str(e)))
        kind = info["kind"]
        if kind == "timeout":
            return PlanningTimeout("no result within the time limit")
        if kind == "interrupted":
            return KeyboardInterrupt()
        if kind == "python":
            value = info["value"]
            if isinstance(value, (SparError, KeyboardInterrupt, MemoryError)):
                return value
            return InternalError(f"{info['class']}: {_one_line(str(value)) or '(no message)'}")
        return PrologError(repr(e), _one_line(info["message"]), formal=info["formal"])

    # ------------------------------------------------------------------ knowledge

    def load_cell(self, cell: Any) -> None:
        """Load ``cell`` as problem ``cell.name``: its facts replace that problem's in Prolog
        (other loaded problems stay), and Python calls about that problem get ``cell``."""
        from spar_py.kb import facts  # kb imports numpy: the engine starts before it (cli.cmd_plan)

        with self.lock:
            self.query_once("foreign:spar_load_facts(Facts)", {"Facts": facts(cell)})
            self.cells[cell.name] = cell

    def unload(self, name: str) -> None:
        """Forget problem ``name`` (its Prolog facts and its cell); a no-op if not loaded."""
        with self.lock:
            self.cells.pop(name, None)
            self.caches.pop(name, None)
            self.runs.pop(name, None)
            self._kept.pop(name, None)
            self.query_once("kb:unload_facts(P)", {"P": name})

    @contextmanager
    def session(self, run: Any) -> Iterator[None]:
        """Hold the engine for one planning ``run`` (planning.run.PlanRun) of its cell: load the
        cell (unless this very cell is loaded already), make the run the one Prolog's calls
        about that problem reach, yield, and keep the cell loaded for the next run of it; the
        engine keeps the last ``KEEP_LOADED`` cells planned this way and unloads older ones."""
        cell = run.cell
        self.wait_loaded()
        with self.lock:
            if self.cells.get(cell.name) is not cell:
                self.load_cell(cell)
            self.runs[cell.name] = run
            try:
                yield
            finally:
                if self.runs.get(cell.name) is run:
                    del self.runs[cell.name]
                self._keep(cell.name)
                self._give_back()

    def _keep(self, name: str) -> None:
        """Remember ``name`` as kept loaded by a session; unload the oldest beyond the bound."""
        self._kept.pop(name, None)
        self._kept[name] = None
        while len(self._kept) > KEEP_LOADED:
            old = next(iter(self._kept))
            del self._kept[old]
            self.unload(old)

    def _give_back(self) -> None:
        """After a run: shrink this thread's Prolog stacks to what they hold, and hand the
        C heap's free memory back to the system (glibc's malloc_trim, where there is one),
        so a long-lived process planning again and again stays at one size
        (bench/memory.py)."""
        self._query_once("trim_stacks")
        if self._trim is False:  # looked up after the first run: a cold start need not import ctypes
            self._trim = _malloc_trim()
        if self._trim is not None:
            self._trim(0)


def engine() -> Engine:
    """The process's engine, started on first use."""
    global _engine
    with _lock:
        if _engine is None:
            _engine = Engine()
        return _engine


def start_engine() -> None:
    """Start the process's engine now and consult the planner in the background (a
    command line calls this first: Prolog compiles the planner while Python imports
    numpy and reads the problem). A no-op once the engine exists."""
    global _engine
    with _lock:
        if _engine is None:
            _engine = Engine(background=True)


def _problems() -> ProblemRegistry:
    """The loaded problems of this process: the engine's when Python embeds Prolog, else (a bare
    ``swipl`` that loaded prolog/spar.pl and calls Python through janus) the hosted registry."""
    global _hosted
    if _engine is not None:
        return _engine
    with _lock:
        if _hosted is None:
            _hosted = ProblemRegistry()
        return _hosted


def _run(problem: str) -> Any:
    """The planning run of loaded problem ``problem`` (for the calls from Prolog below)."""
    return _problems().run(problem)


# ---------------------------------------------------------------------- called from Prolog


def load_problem_file(path: str) -> list[Any]:
    """The toplevel's load_problem/1,2: load and check ``path``, keep its cell by name, and
    return ``[name, facts]`` for Prolog to assert (foreign:load_problem_file/2)."""
    from spar_py.kb import facts, load_problem  # kb imports numpy: the engine starts before it

    cell = load_problem(path)
    problems = _problems()
    problems.cells[cell.name] = cell
    problems.runs.pop(cell.name, None)
    return [cell.name, facts(cell)]


def is_spar_error(value: Any) -> bool:
    """True if ``value`` is an exception spar-py raises on purpose (a SparError)."""
    return isinstance(value, SparError)


def forget_cell(problem: str) -> None:
    """The toplevel's unload_problem/1: drop the cell of ``problem`` (if loaded)."""
    problems = _problems()
    problems.cells.pop(problem, None)
    problems.caches.pop(problem, None)
    problems.runs.pop(problem, None)


def arc_pairs(problem: str, rule: str, kind: str, objects: list[str], grasps: list[str],
              positions: list[str], ta: str) -> list[list[str]]:
    """All grasp/position pairs of loaded problem ``problem`` satisfying ``kind``
    (reachable | mate_reachable), Sec. 5.2.4; ``rule`` for stable-pose labels (arcs.RULES).
    Phase 1's door: the problem's run answers (planning.run.PlanRun.arc_pairs)."""
    return _run(problem).arc_pairs(rule, kind, objects, grasps, positions, None if ta == "none" else ta)


def evaluate(problem: str, steps: list[dict[str, Any]], sources: dict[str, dict[str, str]] | None = None,
             given_up: list[str] | None = None, sensing: dict[str, dict[str, Any]] | None = None) -> dict[str, Any]:
    """Phase 2: run a whole plan instance of loaded problem ``problem`` in one call: status, the
    step where it stopped, each step's verdicts and a token naming its geometry (phase 2's
    door, planning.run.PlanRun.evaluate)."""
    return _run(problem).evaluate(steps, sources, given_up or (), sensing)


def step_geometry(problem: str, token: int, step: str) -> dict[str, Any]:
    """The geometry of step ``step`` of the phase-2 run ``token`` of ``problem``'s run (tool
    pose, joints, placement, ...; empty if the step has none), for printing an instance."""
    return _run(problem).step_geometry(token, step)
