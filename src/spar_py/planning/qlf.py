"""The compiled planner: a cache of SWI-Prolog quick-load files (.qlf) keyed by content.

Consulting prolog/*.pl and kb/templates/*.pl from source costs every process tens of
milliseconds; loading them from one .qlf (SWI-Prolog's ``qcompile/2`` with
``include(user)``: every planner file in one image) costs a few. The image is kept in a
cache directory under a key that is the SHA-256 of

- every ``*.pl`` file of the source directories (prolog/, kb/templates/): name and
  content, so an edit, an added or a removed file gives a new key;
- the SWI-Prolog version and home (a .qlf is only valid for the VM that wrote it);
- the files' absolute paths (the image records its source files by path, and
  prolog/spar_paths.pl's file search path ``spar`` as the checkout it was compiled in:
  two checkouts with the same sources must not share one);
- :data:`FORMAT`, this module's own layout version.

A process computes the key from the files as they are now, before it loads anything,
and loads the image only if an entry under that very key is complete (its ``manifest``
is written last, atomically). A stale image is therefore never loaded: a developer who
edits a .pl file gets a new key, and the next run compiles and loads the edited code.
Files the image turns out to contain beyond those directories (none today) are listed
with their hashes in the manifest and checked on every load.

Beside the image, the cache keeps a **saved state** of SWI-Prolog (``qsave_program/2``)
taken just after a process started janus and loaded the image: the Prolog system,
library(janus) and the planner, in one file. A process that finds it starts SWI-Prolog from
it (``-x``, engine.py's ``_import_janus``), where janus' own start compiles library(janus)
and its libraries from source before the image can even load. Its key is computed before
Prolog runs, so it cannot ask SWI-Prolog its version: it holds the sources' key parts, the
SWI-Prolog home with the size and mtime of its boot file, and janus' own files (the
``_swipl`` extension's size and mtime, the hash of janus.pl, which the state holds
compiled). A state is published only once a fresh process has started from it (a state
SWI-Prolog cannot read aborts the process that tries), and it is used only if its bytes
still hash to what its manifest says.
``SPAR_SAVED_STATE=off`` keeps janus' own start (and the image).

The cache is filled at set-up (``spar cache``, run by scripts/setup.sh) and
otherwise by the first run after a change. ``SPAR_QLF_CACHE`` names the cache directory
(default ``$XDG_CACHE_HOME/spar-py/qlf``, else ``~/.cache/spar-py/qlf``); set it to
``off`` to consult the sources every time. At most :data:`KEEP` entries are kept, the
least recently used are removed.

This module does the file work only; engine.py does the Prolog side (compile, load).
"""
from __future__ import annotations

import json
import os
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

try:  # hashlib.sha256 without hashlib: its import loads OpenSSL's libcrypto and _blake2,
    # a cost of every cold start for a few dozen small files (the digests are the same)
    from _sha256 import sha256  # CPython 3.11
except ImportError:  # pragma: no cover - other versions and implementations
    try:
        from _sha2 import sha256  # CPython 3.12+
    except ImportError:
        from hashlib import sha256

#: Layout version of a cache entry; part of every key.
FORMAT = 1
#: Entries (compiled images) kept in the cache directory; older ones are removed.
KEEP = 16
ENV = "SPAR_QLF_CACHE"
LOADER = "planner.pl"
IMAGE = "planner.qlf"
STATE = "planner.state"
MANIFEST = "manifest.json"
#: ``off`` (or 0, no, false): start SWI-Prolog as janus does, never from a saved state.
STATE_ENV = "SPAR_SAVED_STATE"


def _says_off(value: str) -> bool:
    """True for a setting that turns a feature off: off, 0, no, false or empty."""
    return value.strip().lower() in ("off", "0", "no", "false", "")


def cache_dir() -> Path | None:
    """The cache directory (``$SPAR_QLF_CACHE``, ``$XDG_CACHE_HOME/spar-py/qlf`` or
    ``~/.cache/spar-py/qlf``), or None when ``SPAR_QLF_CACHE=off`` (or there is no home)."""
    env = os.environ.get(ENV)
    if env is not None and _says_off(env):
        return None
    if env:
        return Path(env).expanduser()
    xdg = os.environ.get("XDG_CACHE_HOME")
    try:
        base = Path(xdg).expanduser() if xdg else Path.home() / ".cache"
    except (RuntimeError, KeyError):  # no home directory to be found: no cache
        return None
    return base / "spar-py" / "qlf"


def file_digest(path: Path) -> str:
    """SHA-256 of the bytes of ``path`` (hex)."""
    return sha256(path.read_bytes()).hexdigest()


@dataclass(frozen=True)
class Sources:
    """The planner's source files as they are now: ``roots`` the files a process loads
    (in that order), ``hashes`` every ``*.pl`` of ``dirs`` by absolute path (hex SHA-256)."""

    roots: tuple[Path, ...]
    dirs: tuple[Path, ...]
    hashes: dict[str, str]

    @classmethod
    def scan(cls, roots: list[Path], dirs: list[Path]) -> "Sources":
        """Hash every ``*.pl`` under ``dirs`` (not recursive) now."""
        hashes: dict[str, str] = {}
        for d in dirs:
            for f in sorted(d.glob("*.pl")):
                hashes[str(f.resolve())] = file_digest(f)
        return cls(tuple(p.resolve() for p in roots), tuple(d.resolve() for d in dirs), hashes)

    def covers(self, path: str) -> bool:
        """True if ``path`` lies in one of the scanned directories (so its hash is in the key)."""
        return Path(path).parent in self.dirs


def key(sources: Sources, swi_version: int, swi_home: str) -> str:
    """The cache key of ``sources`` compiled by SWI-Prolog ``swi_version`` at ``swi_home``."""
    return _key_of(sources, swi=[swi_version, swi_home])


def _key_of(sources: Sources, **parts: object) -> str:
    """A key of ``sources`` (their roots and every file's hash), :data:`FORMAT` and ``parts``."""
    doc = {"format": FORMAT, **parts, "roots": [str(p) for p in sources.roots],
           "files": sorted(sources.hashes.items())}
    return sha256(json.dumps(doc, sort_keys=True).encode()).hexdigest()[:32]


def saved_state_on() -> bool:
    """False when ``SPAR_SAVED_STATE`` says off (the cache itself may still be on)."""
    v = os.environ.get(STATE_ENV)
    return v is None or not _says_off(v)


def _stat(path: Path) -> list:
    st = path.stat()
    return [str(path), st.st_size, st.st_mtime_ns]


def swi_identity(home: str, janus_dir: Path) -> dict | None:
    """What a saved state depends on beyond the sources, known before SWI-Prolog starts:
    the home (with its boot file's size and mtime: a rebuilt SWI-Prolog rewrites it) and
    janus' C extension (size, mtime) and janus.pl (hash; the state holds it compiled).
    None if one of them is missing (no saved state then)."""
    try:
        ext = sorted(janus_dir.glob("_swipl*"))
        if not ext:
            return None
        return {"home": str(Path(home).resolve()), "boot": _stat(Path(home) / "boot.prc"),
                "janus_ext": [_stat(p) for p in ext], "janus_pl": file_digest(janus_dir / "janus.pl")}
    except OSError:
        return None


def state_key(sources: Sources, identity: dict) -> str:
    """The cache key of the saved state of ``sources`` started by the SWI-Prolog and janus
    of ``identity`` (:func:`swi_identity`)."""
    return _key_of(sources, kind="state", swi=identity)


def loader_text(roots: tuple[Path, ...]) -> str:
    """The Prolog file the image is compiled from: one ``use_module/1`` per root file,
    each written as a quoted atom (a path is never read as code)."""
    lines = ["% spar-py: the planner's files, compiled into one image by spar_py.planning.qlf.", ""]
    lines += [f":- use_module({_quoted(str(p))})." for p in roots]
    return "\n".join(lines) + "\n"


def _quoted(text: str) -> str:
    """``text`` as a Prolog quoted atom."""
    return "'" + text.replace("\\", "\\\\").replace("'", "\\'") + "'"


@dataclass(frozen=True)
class Entry:
    """One cache entry: ``directory`` holds the loader, the image (``image_name``: the .qlf,
    or a saved state) and the manifest."""

    directory: Path
    image_name: str = IMAGE

    @property
    def loader(self) -> Path:
        return self.directory / LOADER

    @property
    def image(self) -> Path:
        return self.directory / self.image_name

    @property
    def manifest(self) -> Path:
        return self.directory / MANIFEST

    def ready(self) -> bool:
        """True if the entry is complete, its image is the one published, and every extra
        file it lists is unchanged."""
        try:
            doc = json.loads(self.manifest.read_text())
            if (doc.get("format") != FORMAT or doc.get("image") != self.image_name
                    or file_digest(self.image) != doc.get("sha256")):
                return False  # damaged, truncated or replaced since it was published
            for path, digest in doc.get("extra", {}).items():
                if file_digest(Path(path)) != digest:
                    return False
        except (OSError, ValueError, AttributeError):
            return False
        return True

    def extra(self) -> dict[str, str]:
        """The files beyond the scanned directories the published image holds, with their
        hashes (from the manifest; {} if there is none)."""
        try:
            return dict(json.loads(self.manifest.read_text()).get("extra", {}))
        except (OSError, ValueError, AttributeError):
            return {}

    def touch(self) -> None:
        """Mark the entry as just used (its manifest's mtime orders eviction)."""
        try:
            os.utime(self.manifest)
        except OSError:
            pass

    def publish(self, extra: dict[str, str]) -> None:
        """Write the manifest (atomically, last): the entry is complete from now on. It holds
        the image's own hash and ``extra``: the files the image holds beyond the scanned
        directories, with their hashes."""
        import tempfile  # only when a manifest is written

        doc = {"format": FORMAT, "image": self.image_name, "sha256": file_digest(self.image), "extra": extra}
        fd, tmp = tempfile.mkstemp(dir=self.directory, prefix=".manifest.", suffix=".tmp")
        with os.fdopen(fd, "w") as f:
            json.dump(doc, f, sort_keys=True)
        os.replace(tmp, self.manifest)


def entry(base: Path, cache_key: str) -> Entry:
    """The entry of ``cache_key`` under ``base`` (it may not exist yet)."""
    return Entry(base / cache_key)


def state_entry(base: Path, cache_key: str) -> Entry:
    """The saved-state entry of ``cache_key`` (:func:`state_key`) under ``base``."""
    return Entry(base / f"state-{cache_key}", STATE)


@contextmanager
def building(e: Entry, wait: bool = True) -> Iterator[bool]:
    """Hold the entry's build lock; yield True if this process must build the entry (False if
    another process completed it while this one waited). With ``wait`` False the lock is not
    waited for: False at once if another process holds it (that one is building the entry;
    this one goes on without it). Raises OSError if the cache directory cannot be written
    (the caller then does without the entry)."""
    e.directory.mkdir(parents=True, exist_ok=True)
    lock = e.directory.parent / f"{e.directory.name}.lock"
    with open(lock, "a+") as fh:
        try:
            import fcntl  # POSIX only: the except below is the other systems' path
        except ImportError:  # pragma: no cover - not POSIX: no lock; build only when asked to wait
            yield wait and not e.ready()
            return
        try:
            fcntl.flock(fh, fcntl.LOCK_EX if wait else fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:  # (only without waiting) another process is building it
            yield False
            return
        try:
            yield not e.ready()
        finally:
            fcntl.flock(fh, fcntl.LOCK_UN)


def evict(base: Path, keep: int = KEEP, spare: str | None = None) -> list[Path]:
    """Remove all but the ``keep`` most recently used entries under ``base`` (never
    ``spare``); return the removed directories. Best effort: errors are ignored."""
    import shutil  # only when entries are evicted

    entries: list[tuple[float, Path]] = []
    try:
        for d in base.iterdir():
            if d.is_dir() and d.name != spare:
                m = d / MANIFEST
                entries.append((m.stat().st_mtime if m.exists() else d.stat().st_mtime, d))
    except OSError:
        return []
    entries.sort(reverse=True)
    removed = []
    for _, d in entries[max(keep - (spare is not None), 0):]:
        shutil.rmtree(d, ignore_errors=True)
        try:
            (base / f"{d.name}.lock").unlink()
        except OSError:
            pass
        removed.append(d)
    return removed
