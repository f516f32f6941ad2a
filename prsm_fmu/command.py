"""How every console script ends when it cannot finish: one line, never a traceback.

:func:`run_command` runs a command's body and turns

* Ctrl-C (``KeyboardInterrupt``) into ``PROG: interrupted`` and exit status 130 (128 + SIGINT,
  as shells report it); outputs are written whole or not at all (:mod:`prsm_fmu.atomic`), so
  nothing half-written is left;
* a missing optional extra (:mod:`prsm_fmu.extras`) into ``PROG: error: ... install the 'fmu'
  extra ...`` and exit status 1.
"""

from __future__ import annotations

import os
import signal
import sys
import threading
from contextlib import contextmanager
from typing import Callable, Iterator, NoReturn

from .extras import missing_extra_message

__all__ = ["run_command", "child_failure", "deferred_interrupt", "end_process", "INTERRUPTED"]

#: exit status after Ctrl-C: 128 + SIGINT (2)
INTERRUPTED = 130


def run_command(prog: str, body: Callable[[], int]) -> int:
    """Run ``body`` and return its exit status, or 130 after Ctrl-C, 1 for a missing extra.

    Parameters
    ----------
    prog : str
        The console script's name, first word of the message.
    body : callable
        The command; returns its exit status.
    """
    try:
        return int(body())
    except KeyboardInterrupt:
        print(f"{prog}: interrupted (Ctrl-C): stopped; files already written are complete, "
              "none is half-written", file=sys.stderr)
        return INTERRUPTED
    except ImportError as exc:
        message = missing_extra_message(exc)
        if message is None:
            raise
        print(f"{prog}: error: {message}", file=sys.stderr)
        return 1


def end_process(status: int) -> NoReturn:
    """End this process now with exit status ``status``, its stdout and stderr flushed: for a
    console script whose work is done (every file it wrote closed, its child processes ended).

    The interpreter's own teardown is skipped: freeing every module and object, and the
    libraries' exit-time destructors, took ~0.05-0.1 s of the user's wait after ``prsm-ema
    run`` had written everything (and pythonfmu's destructors are those that
    :mod:`prsm_fmu.fmu_exit` guards; skipped, they cannot misbehave).  Python's ``atexit``
    handlers are skipped too: none that such a command registers has work left by then.
    """
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (OSError, ValueError, AttributeError):   # a closed pipe, a closed or no stream
            pass
    os._exit(status)


def child_failure(what: str, returncode: int, stderr: str, stdout: str = "") -> str:
    """One line for a child process that failed: ``what`` (the command), its exit status and
    the last line it wrote on stderr (the child's own one-line error; a traceback's last line
    names the exception), or on stdout if stderr is empty.

    Parameters
    ----------
    what : str
        What was run, e.g. ``"python -m fmu_build PRSM2"``.
    returncode : int
        Its exit status.
    stderr, stdout : str
        What it wrote.
    """
    lines = [ln.strip() for ln in (stderr or stdout or "").splitlines() if ln.strip()]
    return f"{what} failed (exit status {returncode}): {lines[-1] if lines else 'no output'}"


@contextmanager
def deferred_interrupt() -> Iterator[Callable[[], None]]:
    """Hold Ctrl-C back to safe points: yields ``check()``, which raises KeyboardInterrupt if
    SIGINT came since the block began.

    For code that calls into an FMU: a KeyboardInterrupt raised inside the FMU's own Python
    (pythonfmu) is a fatal error of the FMU, not an interruption; with this the signal is
    only noted, and ``check()`` between two steps raises it.  Outside the main thread (no
    signal handler can be set there) ``check()`` never raises.
    """
    if threading.current_thread() is not threading.main_thread():
        yield lambda: None
        return
    caught: list[int] = []

    def note(signum, frame) -> None:
        caught.append(signum)

    previous = signal.signal(signal.SIGINT, note)

    def check() -> None:
        if caught:
            caught.clear()
            raise KeyboardInterrupt

    try:
        yield check
    finally:
        signal.signal(signal.SIGINT, previous)
    if caught:
        raise KeyboardInterrupt

