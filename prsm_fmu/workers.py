"""Worker processes started ahead of their work: fresh interpreters that import what the work
needs while this process does something else (a run, a build).

``spawn``: a worker copies nothing of this process (no FMU, fmpy or matplotlib state); it
imports what it needs itself, in ``initializer``, at once: :func:`started_pool` starts every
process now instead of at the first task.  Used by ``prsm-ema run`` (the figures drawn while
the CSV is written).
"""

from __future__ import annotations

from concurrent.futures import ProcessPoolExecutor
from typing import Callable

__all__ = ["started_pool", "idle_cores", "IDLE_CORE"]

#: idle cores (:func:`idle_cores`) from which worker processes beside this one pay: each one's
#: own start (a Python, numpy and what the work imports: ~0.8 s CPU) is paid back only by a
#: core that would otherwise idle; on a busy machine the work ends sooner in this process
IDLE_CORE = 1.5


def idle_cores() -> float:
    """The cores less the 1-minute load average (the cores not busy lately; all of them where
    the system keeps no load average, e.g. Windows)."""
    import os

    cores = os.cpu_count() or 1
    try:
        load = os.getloadavg()[0]
    except (OSError, AttributeError):
        load = 0.0
    return cores - load


def started_pool(n: int, initializer: Callable[[], None] | None = None
                 ) -> ProcessPoolExecutor | None:
    """``n`` spawned worker processes, started, each running ``initializer`` first; None if
    processes cannot start here (the caller then works in its own process)."""
    import multiprocessing

    try:
        pool = ProcessPoolExecutor(n, mp_context=multiprocessing.get_context("spawn"),
                                   initializer=initializer)
        for _ in range(n):                  # start the workers now, not at the first task
            pool.submit(int)
    except (OSError, RuntimeError, ImportError):
        return None
    return pool
