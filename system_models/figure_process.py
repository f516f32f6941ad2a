"""A forked drawing process: matplotlib imported while the run goes, the figures drawn beside
the CSV.

Started (:func:`early_drawer`) first thing in ``prsm-ema run``, the process is a ``fork`` of
the command: it copies the interpreter (a few ms, against ~0.8 s CPU for a spawned one), imports
matplotlib while the parent checks and runs the scene, then makes the figures' frames (axes,
labels, ticks: :func:`system_models.output.frame`, none needs the run) until the run's result
arrives (:func:`_ahead`).  Given it (:meth:`ForkedDrawer.draw`), it forks once more after its import
(the second process inherits matplotlib, imported once) and the two draw half the figures each,
while the parent writes the CSV.  The CPU is the work the command would do in its own process
plus the forks, so the drawer is used on a busy machine too.

Only where ``fork`` is safe to use (Linux); elsewhere :func:`available` is False and the caller
draws another way.  The processes ignore Ctrl-C (the parent ends them) and write every file
whole (:func:`prsm_fmu.figures.save`), so an interrupted run leaves no half-written PNG.
"""

from __future__ import annotations

import os
import sys
from contextlib import contextmanager
from pathlib import Path
from typing import Any, Iterator

__all__ = ["available", "processes", "early_drawer", "ForkedDrawer", "long_lived_imports"]


@contextmanager
def long_lived_imports() -> Iterator[None]:
    """Imports whose objects live as long as the process: Python's cyclic garbage collector
    paused for the block, and everything made so far then moved out of its reach
    (``gc.freeze``) before it resumes (if it ran before).  Large imports make many objects and
    almost no garbage: the collector's passes over them are wasted (numpy and
    system_models.output: ~15 % of their import's CPU; matplotlib's: ~10-20 %, five and six runs
    on the shared machine).  Frozen, they stay out of every later pass too, in this process and
    in its forks (without the freeze, the paused imports' objects were still young at the
    fork: each drawing process spent ~35 ms more in the collector, ``gc.callbacks``)."""
    import gc

    running = gc.isenabled()
    gc.disable()
    try:
        yield
    finally:
        gc.freeze()
        if running:
            gc.enable()


def available() -> bool:
    """True where the drawer can start: on Linux (macOS and Windows have no safe ``fork``) and
    from a process running no other Python thread (a lock another thread holds would stay held
    in the copy; numpy's BLAS threads are stopped and restarted around a fork by the BLAS's own
    ``pthread_atfork`` handlers)."""
    import threading

    return sys.platform.startswith("linux") and threading.active_count() == 1


def processes() -> int:
    """Processes to draw in where the drawer is forked: 2 on a machine of two cores or more, 1
    on one, busy or not (a fork copies the command's imports: the processes' CPU is the drawing
    the command would do itself)."""
    return 2 if (os.cpu_count() or 1) >= 2 else 1


def early_drawer() -> "ForkedDrawer | None":
    """A started :class:`ForkedDrawer` of :func:`processes` processes, or None where it cannot
    start.  This module imports no numpy; ``prsm-ema run`` calls this once numpy and
    :mod:`system_models.output` are imported (the drawer inherits them instead of importing
    them again), before anything else, so that its matplotlib import overlaps the command's
    own imports, check and run."""
    return ForkedDrawer(processes()).start() if available() else None


def _ignore_interrupts() -> None:
    """Ctrl-C (the terminal's SIGINT reaches the whole process group) ignored here: the parent
    ends the run and this process.  SIGINT arrives blocked (:meth:`ForkedDrawer.start`), so
    none lands before it is ignored."""
    import signal

    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT})


def _draw(names: list[str], job: tuple, frames: dict[str, tuple]) -> list[Path]:
    from .output import _save_figures

    res, out_dir, scene, reference, mode, current_limit, kw = job
    return _save_figures(res, out_dir, scene, reference, mode, current_limit, kw, only=names,
                         frames={n: frames[n] for n in names if n in frames})


def _ahead(conn) -> dict[str, tuple]:
    """What the figures need but the run does not, done until the job arrives on ``conn``:
    the figures' frames (:func:`system_models.output.frame`) one after another, then one small
    figure drawn (:func:`system_models.output._warm`: the fonts loaded, ~5-9 ms of each drawing
    process's first draw, for ~35 ms here).  Whatever is left when the job arrives, the
    processes that draw do themselves, in parallel; so a drawer that is ready only after the
    run (its matplotlib import is the longer path on a busy machine) starts drawing at once."""
    from .output import FRAMED, _warm, frame

    made: dict[str, tuple] = {}
    for name in FRAMED:
        if conn.poll():
            return made
        made[name] = frame(name)
    if not conn.poll():
        _warm()
    return made


def _half(conn, names: list[str], job: tuple, frames: dict[str, tuple]) -> None:
    """The second process: its figures' paths, or the error, on ``conn``."""
    _ignore_interrupts()
    try:
        conn.send(("ok", _draw(names, job, frames)))
    except BaseException as exc:  # noqa: BLE001 - reported to the parent, which draws instead
        conn.send(("error", f"{type(exc).__name__}: {exc}"))
    conn.close()


def _main(conn, split: int) -> None:
    """The drawing process: import matplotlib, make the figures' frames while it waits for a
    job, draw it (in ``split`` processes), answer ``("ok", paths)`` or ``("error", text)``; end
    on EOF (no figures wanted)."""
    _ignore_interrupts()
    with long_lived_imports():
        import matplotlib.figure  # noqa: F401 - what this process is for: imported as the run goes
        from matplotlib.backends import backend_agg  # noqa: F401

    try:
        frames = _ahead(conn)
        job = conn.recv()
    except EOFError:
        return
    try:
        import multiprocessing

        from .output import DRAW_ORDER

        parts = [list(DRAW_ORDER[i::split]) for i in range(split)]
        ctx = multiprocessing.get_context("fork")
        others = []
        for names in parts[1:]:
            here, there = ctx.Pipe(duplex=False)
            sys.stdout.flush()
            sys.stderr.flush()
            pid = os.fork()             # (a daemonic multiprocessing process has no children)
            if pid == 0:
                try:
                    here.close()
                    _half(there, names, job, frames)
                finally:
                    os._exit(0)
            there.close()
            others.append((pid, here))
        done = _draw(parts[0], job, frames)
        for pid, here in others:
            status, value = here.recv()
            os.waitpid(pid, 0)
            if status != "ok":
                raise RuntimeError(value)
            done += value
        conn.send(("ok", done))
    except BaseException as exc:  # noqa: BLE001 - reported to the parent, which draws instead
        conn.send(("error", f"{type(exc).__name__}: {exc}"))


class ForkedDrawer:
    """The forked drawing process of the module docstring.

    Parameters
    ----------
    split : int
        Processes that draw the figures (1: the drawer alone; 2: it and one more fork).
    """

    def __init__(self, split: int = 2) -> None:
        self.split = max(1, int(split))
        self.process = None
        self.conn = None
        self.sent = False

    def start(self) -> "ForkedDrawer | None":
        """Fork the drawer now; None if no process can start here."""
        import multiprocessing
        import signal
        import warnings

        if not available():
            return None
        try:
            ctx = multiprocessing.get_context("fork")
            self.conn, theirs = ctx.Pipe()
            self.process = ctx.Process(target=_main, args=(theirs, self.split), daemon=True)
            # SIGINT blocked across the fork: the child ignores it before it unblocks it, and
            # one sent meanwhile reaches this process when unblocked here
            blocked = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
            try:
                with warnings.catch_warnings():
                    # Python >= 3.12 warns of any other thread: here only the BLAS's (above)
                    warnings.filterwarnings("ignore", "This process .* is multi-threaded",
                                            DeprecationWarning)
                    self.process.start()
            finally:
                signal.pthread_sigmask(signal.SIG_SETMASK, blocked)
            theirs.close()
        except (OSError, ValueError, RuntimeError):
            self.process = self.conn = None
            return None
        return self

    def draw(self, res, out_dir: str | Path, scene: str, reference, mode: str,
             current_limit: float | None, kw: dict[str, Any]) -> list[Path] | None:
        """The figures' paths (their order: whichever process drew them), or None if the
        drawer failed (the caller then draws them itself)."""
        if self.conn is None or self.sent:
            return None
        try:
            self.sent = True
            self.conn.send((res, out_dir, scene, reference, mode, current_limit, kw))
            status, value = self.conn.recv()
        except (OSError, EOFError):
            return None
        return value if status == "ok" else None

    def close(self) -> None:
        """End the drawer: at once if it was given nothing (it may still be importing)."""
        if self.process is None:
            return
        if self.conn is not None:
            self.conn.close()
        if not self.sent and self.process.is_alive():
            self.process.terminate()
        self.process.join()
        self.process = self.conn = None
