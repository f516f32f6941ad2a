"""The sweep master's step loop compiled: :class:`~prsm_fmu.sweep.fmu_runner.FmuRunner`'s
trials in C.

``prsm_fmu/sweep/native/fmu_track.c`` is the runner's loop over the communication steps and its
secant iteration (``FmuRunner._run`` and ``_track``) translated operation for operation: it
calls the FMU through the FMU's own FMI functions (those :mod:`~prsm_fmu.sweep.fmi_calls`
looked up in the library fmpy loaded, on the instance fmpy made), with the runner's constants,
and gives the same calls, the same trial and right-hand-side counts and the same outputs bit
for bit (tests/test_fmu_track.py, seeded random points).  What stays in Python: loading and
initializing the FMU, the t = 0 torque, the reference speed (any profile, evaluated at the
communication points before the loop) and the errors (a failed call comes back as the call,
its status, the step and the torque, :class:`LoopFailure`; the runner raises from it what its
Python loop raises).

The C is compiled with gcc on first use (the native FMU's flags: ``-std=c99 -O2
-ffp-contract=off``) and cached in a directory of the user's own in the temporary directory;
where it cannot be (no gcc), :func:`loop_library` says why and the runner takes its Python loop.
It is called holding the GIL (``ctypes.PyDLL``): a Python FMU's calls and the FMU's logger run
Python code.
"""

from __future__ import annotations

import ctypes
from pathlib import Path
from typing import Any

__all__ = ["loop_library", "CompiledLoop", "CALLS", "LoopFailure"]

#: the FMI functions the loop calls, in the order of fmu_track.c's enum
CALLS = ("fmi2SetReal", "fmi2GetReal", "fmi2GetInteger", "fmi2DoStep", "fmi2GetFMUstate",
         "fmi2SetFMUstate", "fmi2FreeFMUstate")
_SOURCE = Path(__file__).resolve().parent / "native" / "fmu_track.c"


class LoopFailure(Exception):
    """A call of the compiled loop that failed: ``error`` is fmpy's exception for it (naming
    the FMI function and its status), ``step`` the index of the communication step and
    ``torque`` the torque last set [N·m]; the runner raises what its Python loop raises."""

    def __init__(self, error: Exception, step: int, torque: float) -> None:
        super().__init__(str(error))
        self.error, self.step, self.torque = error, step, torque


class _Fmu(ctypes.Structure):
    _fields_ = [("comp", ctypes.c_void_p)] + [(name, ctypes.c_void_p) for name in CALLS] + [
        ("torque_vr", ctypes.c_uint), ("speed_vr", ctypes.c_uint), ("rhs_vr", ctypes.c_uint),
        ("out_vrs", ctypes.c_void_p), ("n_out", ctypes.c_size_t)]


class _Failure(ctypes.Structure):
    _fields_ = [("call", ctypes.c_int), ("status", ctypes.c_int), ("step", ctypes.c_long),
                ("torque", ctypes.c_double)]


_lib: Any = None
_why: str | None = None


def loop_library() -> tuple[Any, str | None]:
    """(the compiled loop's library, None), or (None, why it cannot be built here); built on
    first use, once per process."""
    global _lib, _why
    if _lib is None and _why is None:
        try:
            from ..compiled import BuildError, cached_library

            path = cached_library("fmu_track", {_SOURCE.name: _SOURCE.read_bytes()},
                                  (_SOURCE.name,))
            lib = ctypes.PyDLL(str(path))
            f = lib.fmu_track_run
            f.restype = ctypes.c_int
            f.argtypes = [ctypes.POINTER(_Fmu), ctypes.c_long, ctypes.c_double, ctypes.c_void_p,
                          ctypes.c_double, ctypes.c_double, ctypes.c_long, ctypes.c_double,
                          ctypes.c_void_p, ctypes.c_void_p, ctypes.POINTER(_Failure)]
            _lib = lib
        except (BuildError, OSError) as exc:
            _why = f"the compiled sweep loop cannot be built here: {exc}".splitlines()[0]
    return _lib, _why


class CompiledLoop:
    """The runner's step loop in C on one instance (module docstring).

    Parameters
    ----------
    lib
        From :func:`loop_library`.
    calls : prsm_fmu.sweep.fmi_calls.StepCalls
        The instance's FMI calls (its functions, instance and value references).
    """

    def __init__(self, lib: Any, calls: Any) -> None:
        self._run = lib.fmu_track_run
        self._calls = calls
        funcs, comp, (torque_vr, speed_vr, rhs_vr), out_vrs = calls.raw(CALLS)
        self._out_vrs = out_vrs              # kept alive: the struct holds its address
        self._fmu = _Fmu(comp, *(funcs[name] for name in CALLS), torque_vr, speed_vr, rhs_vr,
                         ctypes.addressof(out_vrs), len(out_vrs))
        self._counts = (ctypes.c_long * 2)()
        self._failure = _Failure()

    def run(self, n_steps: int, h: float, targets: Any, torque0: float, torque_rtol: float,
            max_trials: int, t_scale: float, rows: Any) -> tuple[int, int]:
        """Steps 0 … n_steps − 1 of ``FmuRunner._run``'s loop; (trials, right-hand-side calls).

        ``targets``: float64 array of the reference speeds at (i + 1)·h [rad/s]; ``rows``: the
        C-contiguous float64 rows of communication points 1 … n_steps of the result (one
        double per output read).

        Raises
        ------
        LoopFailure
            If an FMI call fails (status above fmi2Warning).
        """
        counts = self._counts
        counts[0] = counts[1] = 0
        fail = self._failure
        bad = self._run(ctypes.byref(self._fmu), n_steps, h, targets.ctypes.data, torque0,
                        torque_rtol, max_trials, t_scale, rows.ctypes.data, counts,
                        ctypes.byref(fail))
        if bad:
            raise LoopFailure(self._calls.failure(function=CALLS[fail.call], status=fail.status),
                              fail.step, fail.torque)
        return counts[0], counts[1]
