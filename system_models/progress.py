"""A text progress bar that appears only when a run takes longer than a few seconds.

``Progress(delay=2.0)`` stays silent for the first ``delay`` seconds of wall time, then draws
``[#########...........]  45 %  t = 0.1125 s  elapsed 2.3 s  left 2.8 s`` on the stream
(redrawn in place on a terminal, a new line every 10 % otherwise), at most every
``interval`` seconds.  :meth:`close` ends the line.  The clock can be injected for tests.
"""

from __future__ import annotations

import sys
import time
from typing import Callable, TextIO

__all__ = ["Progress"]


class Progress:
    """Callable ``progress(t, t_end)`` for :meth:`system_models.master.Master.run`."""

    def __init__(self, t_start: float = 0.0, delay: float = 2.0, interval: float = 0.2,
                 stream: TextIO | None = None, clock: Callable[[], float] = time.monotonic,
                 width: int = 30) -> None:
        self.t_start = t_start
        self.delay, self.interval, self.width = delay, interval, width
        self.stream = sys.stderr if stream is None else stream
        self.clock = clock
        self.wall0 = clock()
        self.last = -1e300
        self.shown = False
        self.last_decile = -1
        self.tty = bool(getattr(self.stream, "isatty", lambda: False)())

    def __call__(self, t: float, t_end: float) -> None:
        now = self.clock()
        elapsed = now - self.wall0
        if elapsed < self.delay or (now - self.last < self.interval and t < t_end):
            return
        span = t_end - self.t_start
        frac = min(1.0, max(0.0, (t - self.t_start) / span)) if span > 0 else 1.0
        decile = int(10 * frac)
        if not self.tty and decile == self.last_decile and t < t_end:
            return
        self.last, self.last_decile = now, decile
        n = int(round(self.width * frac))
        left = elapsed * (1.0 - frac) / frac if frac > 0 else float("inf")
        line = (f"[{'#' * n}{'.' * (self.width - n)}] {100 * frac:3.0f} %  t = {t:.6g} s  "
                f"elapsed {elapsed:.1f} s  left {left:.1f} s")
        self.stream.write(("\r" + line) if self.tty else (line + "\n"))
        self.stream.flush()
        self.shown = True

    def close(self) -> None:
        """End the bar's line (if one was drawn on a terminal)."""
        if self.shown and self.tty:
            self.stream.write("\n")
            self.stream.flush()
