"""The ``spar`` console script's first code: Ctrl-C and SIGTERM end the run cleanly from its
first instant, before ``spar_py.app.cli`` and its imports (numpy, the engine) are loaded.

Until the run's guard (guard.RunGuard) takes over, a signal writes one line (``spar:
interrupted`` or ``spar: terminated``) and exits 130 or 143 at once: nothing has been written
yet, so there is nothing to clean up. Python's default handler would raise KeyboardInterrupt
in whatever import was running and print a traceback.
"""
from __future__ import annotations

import os
import signal
import sys
from collections.abc import Callable
from types import FrameType
from typing import TYPE_CHECKING

from spar_py.app.gcpause import hold_collections

if TYPE_CHECKING:
    from spar_py.startup.dcimage import CodeImage

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


#: Environment variables that set the BLAS thread count; :func:`one_blas_thread` leaves a
#: count the user set alone.
BLAS_THREADS = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS")


def one_blas_thread() -> None:
    """One OpenBLAS thread for this process (and the processes it starts: ``spar regress -j``
    workers), unless the user set a count. Called before numpy is imported, by the console
    script only (never the Python API).

    The planner's numerical work is small: 4x4 transforms and batches of a few hundred rows,
    which BLAS runs on one thread anyway. numpy's OpenBLAS otherwise starts one worker per
    core as numpy loads, and the workers spin while idle, taking CPU from the planner in a
    cold ``spar plan`` (bench/coldstart.py), and N
    workers of ``spar regress -j N`` would start N pools on one machine."""
    if not any(v in os.environ for v in BLAS_THREADS):
        os.environ["OPENBLAS_NUM_THREADS"] = "1"


def keep_compiled_methods() -> CodeImage | None:
    """Dataclasses defined from now on take their generated methods' code from the cache
    (dcimage.py: compiling their source is the largest cost of importing the planner); the
    image to save at the end, or None (cache off). Console script only, never the Python API."""
    from spar_py.startup.dcimage import install  # after the early handlers

    return install()


def save_compiled_methods(image: CodeImage | None) -> None:
    """Write what this process compiled into the image (only if it compiled anything new)."""
    if image is not None:
        image.save()


def main() -> None:
    """``spar`` (and ``python -m spar_py``): early handlers, then :func:`spar_py.app.cli.main`."""
    early_signals()
    one_blas_thread()
    hold_collections()
    image = keep_compiled_methods()
    from spar_py.app.cli import exiting, main as cli_main  # after the handlers: numpy, casadi load here

    run_to_end(cli_main, exiting, image)


def run_to_end(cli_main: Callable[[list[str]], None], exiting: Callable[[object], None],
               image: CodeImage | None) -> None:
    """Run ``cli_main(sys.argv[1:])`` (spar_py.app.cli.main) and end the process as the console
    script does: the dataclass-methods image saved, then
    ``exiting`` (cli.exiting: a shutdown without the full heap's collections, or none at all)
    with the SystemExit code the run raised (``...`` if it raised none, which leaves the usual
    shutdown alone)."""
    code: object = ...
    try:
        cli_main(sys.argv[1:])
    except SystemExit as e:
        code = e.code
        raise
    finally:
        save_compiled_methods(image)
        exiting(code)
