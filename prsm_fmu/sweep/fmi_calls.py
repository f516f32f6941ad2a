"""The few FMI 2.0 calls of :class:`~prsm_fmu.sweep.fmu_runner.FmuRunner`'s step loop (and of
its t = 0 torque), made straight into the FMU's library.

fmpy's :class:`fmpy.fmi2.FMU2Slave` builds ctypes arrays, converts every argument and wraps
every call in Python on each call: about 3 µs per call, a third or more of what a pythonfmu
FMU's call costs in all.  The runner's loop makes about 13 calls per communication step (save
the state, per trial set the torque, step and read the speed, restore the state, read the
outputs and the step's right-hand-side count, free the state), so :class:`StepCalls` makes
them with the library's own functions (looked up by name in the library fmpy loaded), without
declared argument types (ctypes then converts nothing: the arrays, made once, pass as their
pointers; the doubles and the instance's address are wrapped here), into arrays made once, and
without releasing the GIL (a pythonfmu FMU would take it back at once to run its slave; a
native FMU's calls are short).
The calls and their order are the runner's; only the way into the library changes.  A status
above fmi2Warning raises fmpy's own :class:`fmpy.fmi1.FMICallException` naming the function,
as fmpy's call would.

Imports fmpy (only when a runner is made); never imported by the physics.
"""

from __future__ import annotations

import ctypes
from typing import Any, Sequence

#: the largest status that is not a failure (fmi2Warning)
_WARNING = 1


class StepCalls:
    """The step loop's FMI calls on one instance of a loaded fmpy ``FMU2Slave``.

    Parameters
    ----------
    fmu : fmpy.fmi2.FMU2Slave
        An instantiated FMU (its ``dll`` and ``component``).
    torque_vr, speed_vr, rhs_vr : int
        Value references of the input ``screw_torque``, the output ``screw_speed`` and the
        Integer output ``step_rhs_calls``.
    output_vrs : sequence of int
        Value references of the Real outputs read at every communication point, in order.
    """

    def __init__(self, fmu: Any, torque_vr: int, speed_vr: int, rhs_vr: int,
                 output_vrs: Sequence[int]) -> None:
        from fmpy.fmi1 import FMICallException

        #: the exception a failed call raises (fmpy's)
        self.failure = FMICallException
        # the library fmpy loaded, its functions called without releasing the GIL: a pythonfmu
        # FMU takes it back at once to run its slave (a wait for it saved on every call)
        lib = ctypes.PyDLL(fmu.dll._name, handle=fmu.dll._handle)

        def raw(name: str):
            f = type(lib[name])((name, lib))
            f.restype = ctypes.c_int
            return f

        self._get_real, self._set_real = raw("fmi2GetReal"), raw("fmi2SetReal")
        self._get_integer, self._do_step = raw("fmi2GetInteger"), raw("fmi2DoStep")
        self._get_state, self._set_state = raw("fmi2GetFMUstate"), raw("fmi2SetFMUstate")
        self._free_state = raw("fmi2FreeFMUstate")
        self._lib = lib
        self._c = ctypes.c_void_p(fmu.component)
        self._double = ctypes.c_double
        uint = ctypes.c_uint
        # one-element arrays: they pass as their pointers
        self._torque_vr, self._speed_vr, self._rhs_vr = ((uint * 1)(vr) for vr in
                                                         (torque_vr, speed_vr, rhs_vr))
        self._n_out = len(output_vrs)
        self._out_vrs = (uint * self._n_out)(*output_vrs)
        self._one = (ctypes.c_double * 1)()
        self._torque = (ctypes.c_double * 1)()
        self._int = (ctypes.c_int * 1)()

    def raw(self, names: Sequence[str]) -> tuple[dict[str, int], int, tuple[int, int, int],
                                                 ctypes.Array]:
        """What a compiled master needs to make these calls itself
        (:mod:`prsm_fmu.sweep.native_track`): the addresses of the FMI functions ``names`` in
        the FMU's library, the instance's address, the value references of the torque, the
        speed and the right-hand-side count, and the array of the outputs' value references."""
        addresses = {name: ctypes.cast(self._lib[name], ctypes.c_void_p).value for name in names}
        vrs = (self._torque_vr[0], self._speed_vr[0], self._rhs_vr[0])
        return addresses, self._c.value, vrs, self._out_vrs

    def _failed(self, name: str, status: int):
        return self.failure(function=name, status=status)

    def set_torque(self, torque: float) -> None:
        """fmi2SetReal of ``screw_torque`` [N.m]."""
        self._torque[0] = torque
        status = self._set_real(self._c, self._torque_vr, 1, self._torque)
        if status > _WARNING:
            raise self._failed("fmi2SetReal", status)

    def do_step(self, t: float, h: float) -> None:
        """fmi2DoStep from ``t`` over ``h`` [s] (noSetFMUStatePriorCurrentPoint = fmi2False)."""
        double = self._double
        status = self._do_step(self._c, double(t), double(h), 0)
        if status > _WARNING:
            raise self._failed("fmi2DoStep", status)

    def speed(self) -> float:
        """fmi2GetReal of ``screw_speed`` [rad/s]."""
        return self.real(self._speed_vr)

    def real(self, vr: ctypes.Array) -> float:
        """fmi2GetReal of the one Real variable whose value reference ``vr`` holds (a
        one-element ``c_uint`` array, made once by the caller)."""
        status = self._get_real(self._c, vr, 1, self._one)
        if status > _WARNING:
            raise self._failed("fmi2GetReal", status)
        return self._one[0]

    def outputs_into(self, address: int) -> None:
        """fmi2GetReal of the outputs read at every communication point, in their order, into
        the doubles at ``address`` (a row of a C-contiguous float64 array, kept alive by the
        caller)."""
        status = self._get_real(self._c, self._out_vrs, self._n_out, ctypes.c_void_p(address))
        if status > _WARNING:
            raise self._failed("fmi2GetReal", status)

    def rhs_calls(self) -> int:
        """fmi2GetInteger of ``step_rhs_calls``."""
        status = self._get_integer(self._c, self._rhs_vr, 1, self._int)
        if status > _WARNING:
            raise self._failed("fmi2GetInteger", status)
        return self._int[0]

    def get_state(self) -> ctypes.c_void_p:
        """fmi2GetFMUstate: a new state (free it with :meth:`free_state`)."""
        state = ctypes.c_void_p()
        status = self._get_state(self._c, ctypes.byref(state))
        if status > _WARNING:
            raise self._failed("fmi2GetFMUstate", status)
        return state

    def set_state(self, state: ctypes.c_void_p) -> None:
        """fmi2SetFMUstate of a state from :meth:`get_state`."""
        status = self._set_state(self._c, state)
        if status > _WARNING:
            raise self._failed("fmi2SetFMUstate", status)

    def free_state(self, state: ctypes.c_void_p) -> None:
        """fmi2FreeFMUstate of a state from :meth:`get_state`."""
        status = self._free_state(self._c, ctypes.byref(state))
        if status > _WARNING:
            raise self._failed("fmi2FreeFMUstate", status)
