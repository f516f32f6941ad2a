"""Keep what an FMU logs, so that a failed call can be reported with the FMU's own reason.

An FMI 2.0 FMU explains a refused step (fmi2Discard) or a failed call (fmi2Error, fmi2Fatal)
only through the logger callback the host passes to ``fmi2Instantiate``, and only if the host
instantiates it with ``loggingOn``.  :class:`FmuLog` is that callback for fmpy's ``FMU2Slave``:
it keeps every message with its status, and :meth:`FmuLog.reason` returns those logged since a
mark, ready to append to an error message.  Used by the co-simulation block
(:class:`system_models.fmu.FMUBlock`) and the sweep's FMU master
(:class:`prsm_fmu.sweep.fmu_runner.FmuRunner`).

Imports fmpy when a log is made; never imported by the physics.
"""

from __future__ import annotations

__all__ = ["FmuLog", "STATUS"]

#: FMI 2.0 status names by value (fmi2OK ... fmi2Pending)
STATUS = ("ok", "warning", "discard", "error", "fatal", "pending")


class FmuLog:
    """fmpy logger callbacks that keep the FMU's messages (module docstring).

    Pass :attr:`callbacks` to ``FMU2Slave.instantiate(callbacks=..., loggingOn=True)`` and
    keep this object alive as long as the instance: the ctypes callbacks live here.

    Attributes
    ----------
    messages : list of (str, str)
        (status name, message) in the order the FMU logged them.
    """

    def __init__(self) -> None:
        from fmpy.fmi2 import (calloc, fmi2CallbackAllocateMemoryTYPE,
                               fmi2CallbackFreeMemoryTYPE, fmi2CallbackFunctions,
                               fmi2CallbackLoggerTYPE, free)

        self.messages: list[tuple[str, str]] = []
        cb = fmi2CallbackFunctions()
        cb.logger = fmi2CallbackLoggerTYPE(self._log)
        cb.allocateMemory = fmi2CallbackAllocateMemoryTYPE(calloc)
        cb.freeMemory = fmi2CallbackFreeMemoryTYPE(free)
        self.callbacks = cb

    def _log(self, env, instance, status, category, message) -> None:
        label = STATUS[status] if 0 <= status < len(STATUS) else str(status)
        text = message.decode("utf-8", "replace") if message is not None else ""
        self.messages.append((label, text))

    def mark(self) -> int:
        """Position of the next message (pass it to :meth:`reason`)."""
        return len(self.messages)

    def clear(self) -> None:
        """Forget the messages kept so far (e.g. between the points of a sweep)."""
        self.messages.clear()

    def reason(self, start: int = 0, problems_only: bool = False) -> str:
        """The messages logged since ``start``, joined with ``"; "`` ("" if there are none).

        Parameters
        ----------
        start : int
            A :meth:`mark`; default: every message kept.
        problems_only : bool
            Leave out messages logged with status ok (progress notes).
        """
        msgs = [m for s, m in self.messages[start:] if not (problems_only and s == "ok")]
        return "; ".join(msgs)
