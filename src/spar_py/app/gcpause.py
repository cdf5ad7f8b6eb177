"""The console script's pause of the cyclic garbage collector: held from the first instant of
``spar`` until its problem is read (startup.entry holds it, the command resumes it).

Imports nothing of the planner, so the start-up code can hold the collector before numpy loads.
"""
from __future__ import annotations

import gc

__all__ = ["YOUNG_THRESHOLD", "hold_collections", "resume_collections"]

#: Whether :func:`hold_collections` disabled the cyclic garbage collector (and
#: :func:`resume_collections` has not enabled it again).
_held = False


def hold_collections() -> None:
    """No cyclic garbage collections until :func:`resume_collections`: a cold ``spar plan``
    imports numpy, casadi and the planner and reads its problem first, allocating some
    hundreds of thousands of objects that all stay alive; the collector's passes over them
    (about 90 in that run, some 3% of its time) find nothing to free. Called by the console
    script before its imports, never by the Python API."""
    global _held
    if gc.isenabled():
        gc.disable()
        _held = True


#: The youngest generation's collection threshold of a console-script run (Python's default is
#: 700): a plan's work allocates tens of thousands of short-lived containers, and 23 young
#: collections (and 2 older ones) of the paper's cell's first plan become one. Cyclic garbage
#: waits for at most this many allocations: some thousands of objects, a few MB at most.
YOUNG_THRESHOLD = 10_000


def resume_collections() -> None:
    """The command's own work starts (cli.py calls this once the problem is read, or before
    any other command): what was allocated until now is moved to the collector's permanent
    generation (gc.freeze: the run's full collections need not go over it again) and the
    collector runs from here, its youngest generation collected every :data:`YOUNG_THRESHOLD`
    allocations. A no-op unless :func:`hold_collections` disabled it."""
    global _held
    if _held:
        _held = False
        gc.freeze()
        gc.set_threshold(YOUNG_THRESHOLD, *gc.get_threshold()[1:])
        gc.enable()
