"""Bounds on a ``spar`` command as a whole: its time limit, Ctrl-C and SIGTERM.

The planner's own time limit (Prolog's ``call_with_time_limit``) stops Prolog work, but
a signal or an alarm reaches Python code only between bytecodes, and Prolog code only
when control returns to Prolog. A :class:`RunGuard` makes the bound hold whatever is
running: a watchdog thread waits on the signal wake-up descriptor (written by the
interpreter's C-level handler the moment a signal arrives) and on the deadline; when one
comes, it removes the command's temporary outputs, prints one line and ends the process
with ``os._exit``: within a few milliseconds, never with half-written outputs, since
outputs are written to temporary files and moved into place under the guard's lock
(:meth:`RunGuard.commit`).

Exit codes (also in the README and ``spar --help``): 4 for the time limit, 130 for
SIGINT (Ctrl-C), 143 for SIGTERM.
"""
from __future__ import annotations

import os
import select
import signal
import sys
import threading
import time
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path

EXIT_TIMEOUT, EXIT_SIGINT, EXIT_SIGTERM = 4, 130, 143

#: The signals a guard turns into a clean stop.
SIGNALS = (signal.SIGINT, signal.SIGTERM)

#: Time after the deadline the guard leaves the planner to stop by itself (s).
GRACE_S = 0.25

__all__ = ["EXIT_SIGINT", "EXIT_SIGTERM", "EXIT_TIMEOUT", "GRACE_S", "RunGuard"]


class RunGuard:
    """Watch one command: its deadline (``timeout`` seconds from now, None for none) and
    SIGINT/SIGTERM. The watchdog ends the process ``grace`` seconds after the deadline
    (leave some when the work has a time limit of its own that should end it first).
    Use as a context manager in the main thread."""

    def __init__(self, timeout: float | None = None, *, grace: float = GRACE_S,
                 exit: Callable[[int], None] = os._exit) -> None:
        self.start = time.monotonic()
        self.grace = grace
        self.deadline = None if timeout is None else self.start + timeout
        self.timeout = timeout
        self.lock = threading.Lock()
        self._temporaries: list[Path] = []
        self._committed = False
        self._exit = exit
        self._old_fd = -1
        self._r = self._w = -1
        self._thread: threading.Thread | None = None
        self._done = threading.Event()

    # ------------------------------------------------------------------ set-up

    def __enter__(self) -> RunGuard:
        self._r, self._w = os.pipe()
        os.set_blocking(self._w, False)
        for sig in SIGNALS:
            # a Python-level handler, so the interpreter writes the wake-up byte; the
            # watchdog does the rest (the handler itself may never get to run)
            signal.signal(sig, lambda *_: None)
        self._old_fd = signal.set_wakeup_fd(self._w, warn_on_full_buffer=False)
        self._thread = threading.Thread(target=self._watch, name="spar-guard", daemon=True)
        self._thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self._done.set()
        os.write(self._w, b"\0")  # wake the watchdog so it sees _done
        if self._thread is not None:
            self._thread.join()
        signal.set_wakeup_fd(self._old_fd)
        for sig in SIGNALS:
            # the command's work is done and its outputs are in place: a signal now, while
            # the process exits, changes nothing (and must not kill it half-way out)
            signal.signal(sig, signal.SIG_IGN)
        os.close(self._r)
        os.close(self._w)
        self.cleanup()

    # ------------------------------------------------------------------ outputs

    def staging(self, final: Path) -> Path:
        """A new, registered directory beside ``final`` (``.<name>.XXXXXXXX``, same file
        system, so a rename moves its contents into place) in which to make ``final``.

        Made and registered under the lock, so a stop can never fall between the two;
        removed by :meth:`cleanup` (a stop, or the end of the command)."""
        import tempfile  # only for commands with outputs (cold start)

        parent = final.absolute().parent
        parent.mkdir(parents=True, exist_ok=True)
        with self.lock:
            path = Path(tempfile.mkdtemp(dir=parent, prefix=f".{final.name}."))
            self._temporaries.append(path)
        return path

    @contextmanager
    def commit(self) -> Iterator[None]:
        """Hold off the watchdog while outputs move into place (a few renames). Once they
        are in place the command's work is done: a later signal or deadline is ignored,
        so a stop's exit code always means "no outputs"."""
        with self.lock:
            yield
            self._committed = True

    def write_text(self, final: Path, text: str) -> None:
        """Write ``final`` whole or not at all: made in a staging directory and moved into
        place under the lock (a stop before that leaves nothing; the run goes on after)."""
        self.write_all([(final, text)])

    def write_all(self, files: Sequence[tuple[Path, str]]) -> None:
        """Write every (path, text) of ``files``, all or none: each made in a staging
        directory beside its path, then all moved into place under the lock (a stop before
        that leaves none of them; one that comes during it waits for the last)."""
        staged = []
        for final, text in files:
            stage = self.staging(final)
            (stage / final.name).write_text(text, encoding="utf-8")
            staged.append((stage, final))
        with self.lock:
            for stage, final in staged:
                os.replace(stage / final.name, final)
        for stage, _ in staged:
            self._discard(stage)

    def move_tree(self, stage: Path, root: Path) -> None:
        """Move every file under the staging directory ``stage`` (:meth:`staging`) to the same
        place under ``root``, all under the lock: a stop sees all of them moved or none."""
        files = [p for p in sorted(stage.rglob("*")) if p.is_file()]
        with self.lock:
            for p in files:
                dest = root / p.relative_to(stage)
                dest.parent.mkdir(parents=True, exist_ok=True)
                os.replace(p, dest)
        self._discard(stage)

    def _discard(self, stage: Path) -> None:
        """Remove the (emptied) staging directory ``stage`` and forget it."""
        import shutil  # loaded already: a staging directory is made with tempfile, which imports it

        with self.lock:
            self._temporaries = [p for p in self._temporaries if p != stage]
        shutil.rmtree(stage, ignore_errors=True)

    def cleanup(self) -> None:
        """Remove every registered temporary that is still there.

        A directory is first renamed to a name nobody else knows, then removed: writers
        that are still running (the main thread, a ``dot`` child) make their files by
        path, and after the rename no such path leads into it, so the removal cannot race
        with them and leave a half-emptied directory behind.

        shutil is imported only here and in :meth:`_discard` (a plan without outputs never
        needs it), and only once a temporary exists, when staging's
        tempfile has imported it: a stop on the watchdog's thread never runs an import."""
        if not self._temporaries:
            return
        import shutil  # loaded already once a temporary exists (tempfile imports it): see _discard

        for p in self._temporaries:
            try:
                if p.is_dir() and not p.is_symlink():
                    gone = p.with_name(f"{p.name}.{os.getpid()}.gone")
                    try:
                        os.rename(p, gone)
                    except OSError:
                        gone = p
                    shutil.rmtree(gone, ignore_errors=True)
                else:
                    p.unlink(missing_ok=True)
            except OSError:
                pass
        self._temporaries.clear()

    # ------------------------------------------------------------------ the watchdog

    def _watch(self) -> None:
        while True:
            wait = None
            if self.deadline is not None:
                wait = max(self.deadline + self.grace - time.monotonic(), 0.0)
            ready, _, _ = select.select([self._r], [], [], wait)
            if self._done.is_set():
                return
            if not ready:
                self._stop(EXIT_TIMEOUT, f"timeout: no result within {self.timeout:g} s")
                return
            data = os.read(self._r, 64)
            sigs = set(data) & {int(signal.SIGINT), int(signal.SIGTERM)}
            if sigs:
                code = EXIT_SIGINT if int(signal.SIGINT) in sigs else EXIT_SIGTERM
                self._stop(code, "interrupted" if code == EXIT_SIGINT else "terminated")
                return

    def _stop(self, code: int, message: str) -> None:
        with self.lock:  # never in the middle of a commit
            if self._done.is_set() or self._committed:
                return
            self.cleanup()
            try:
                sys.stdout.flush()
            except Exception:
                pass
            try:
                os.write(2, f"spar: {message}\n".encode())
            except OSError:
                pass
            self._exit(code)
