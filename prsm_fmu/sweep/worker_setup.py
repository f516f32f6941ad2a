"""Dask worker preload of a local study's cluster: the worker ignores Ctrl-C.

A terminal's Ctrl-C reaches the whole process group, the worker processes included; only the
study's own process is to handle it (it closes the cluster and ends in one line,
:mod:`prsm_fmu.command`), not every worker with a traceback.  Dask calls :func:`dask_setup` in
each worker process as it starts (``LocalCluster(preload=[...])``).
"""

from __future__ import annotations

import signal
import threading

__all__ = ["dask_setup"]


def dask_setup(worker) -> None:
    """Ignore SIGINT in this worker process (where the call runs on its main thread)."""
    if threading.current_thread() is threading.main_thread():
        signal.signal(signal.SIGINT, signal.SIG_IGN)
