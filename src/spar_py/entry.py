"""The ``spar`` console script's first code: Ctrl-C and SIGTERM end the run cleanly from its
first instant, before ``spar_py.cli`` and its imports (numpy, the engine) are loaded.

Until the run's guard (guard.RunGuard) takes over, a signal writes one line (``spar:
interrupted`` or ``spar: terminated``) and exits 130 or 143 at once: nothing has been written
yet, so there is nothing to clean up. Python's default handler would raise KeyboardInterrupt
in whatever import was running and print a traceback.
"""
from __future__ import annotations

import os
import signal
import sys
from types import FrameType

#: Exit code and line per signal (cli.py's EXIT_CODES).
_EARLY = {signal.SIGINT: (130, b"spar: interrupted\n"), signal.SIGTERM: (143, b"spar: terminated\n")}


def _stop(sig: int, _frame: FrameType | None) -> None:
    code, line = _EARLY[signal.Signals(sig)]
    os.write(2, line)
    os._exit(code)


def early_signals() -> None:
    """Install the early handlers (the guard replaces them while a command runs)."""
    for sig in _EARLY:
        signal.signal(sig, _stop)


def main() -> None:
    """``spar``: early handlers, then :func:`spar_py.cli.main`."""
    early_signals()
    from .cli import exiting, main as cli_main

    try:
        cli_main(sys.argv[1:])
    finally:
        exiting()  # the process ends here: a shutdown without the full heap's collections
