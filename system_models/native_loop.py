"""The actuator loop's macro steps compiled: a master whose step loop runs in C.

:class:`NativeMaster` is a :class:`~system_models.master.Master` for the loop of
:mod:`system_models.ema` (the cascade controller, the motor, the PRSM FMU and the load): set-up,
start values, recording and results are the Python master's; the macro steps are taken by
``system_models/native/ema_loop.c``, the Python master's step and the three Python blocks'
arithmetic translated operation for operation, which calls the FMU through its own FMI
functions (the instance fmpy created and initialized).  The outputs are the Python loop's bit
for bit (tests/test_native_loop.py); only the cost differs.

What stays in Python: the controller's reference and the load's external force (profiles of
any kind, evaluated once per run at the instants the blocks would evaluate them), and every step
a block refuses: the C puts the Python blocks back to the step's start and the Python master
takes that step, with its retry policy and its error message.  A retry policy with a coupling
``tolerance`` (every step rolled back on a large coupling error) needs the Python master.

The C is compiled with gcc on first use (``-std=c99 -O2 -ffp-contract=off``, as the native FMU)
and cached in a directory of the user's own in the temporary directory.
"""

from __future__ import annotations

import ctypes
import math
from array import array
from pathlib import Path
from typing import Any

from .controller import CascadeController
from .fmu import FMUBlock
from .load import SpringDamperLoad
from .master import Master
from .motor import Motor

__all__ = ["NativeMaster", "LOOPS", "check_native_loop"]

#: the masters ``build_system(loop=...)`` and ``prsm-ema run --loop`` accept
LOOPS = ("python", "native")
_SOURCE = Path(__file__).resolve().parent / "native" / "ema_loop.c"
#: block kinds of the C (ema_loop.c)
_KINDS = ((CascadeController, 0), (Motor, 1), (FMUBlock, 2), (SpringDamperLoad, 3))
_MODES = {"position": 0, "speed": 1, "current": 2}
#: return codes of ema_loop_run
_DONE, _REFUSED, _FMU_ERROR, _PROFILE_END = 0, 1, 2, 3
_FMU_CALLS = ("setReal", "doStep", "getReal", "getInteger")
#: macro steps per call into the C (the progress callback is called between calls)
CHUNK = 2048
_lib: ctypes.CDLL | None = None


def loop_library() -> ctypes.CDLL:
    """The compiled step loop, loaded (built on first use).

    Raises
    ------
    prsm_fmu.compiled.BuildError
        When gcc is missing or fails (the class :mod:`fmu_build` re-exports).
    """
    global _lib
    if _lib is not None:
        return _lib
    from prsm_fmu.compiled import cached_library

    path = cached_library("ema_loop", {_SOURCE.name: _SOURCE.read_bytes()}, (_SOURCE.name,))
    dll = ctypes.CDLL(str(path))
    vp, dbl, i32 = ctypes.c_void_p, ctypes.POINTER(ctypes.c_double), ctypes.POINTER(ctypes.c_int)
    dll.ema_loop_new.restype = vp
    dll.ema_loop_free.argtypes = [vp]
    dll.ema_loop_set_plan.argtypes = [vp, i32, dbl]
    dll.ema_loop_set_controller.argtypes = [vp, dbl, i32, dbl, dbl, dbl, ctypes.c_long]
    dll.ema_loop_set_motor.argtypes = [vp, dbl]
    dll.ema_loop_set_load.argtypes = [vp, dbl, dbl, ctypes.c_long]
    dll.ema_loop_set_fmu.argtypes = [vp, vp, vp, vp, vp, vp, i32]
    dll.ema_loop_set_state.argtypes = [vp, dbl]
    dll.ema_loop_get_state.argtypes = [vp, dbl]
    dll.ema_loop_run.argtypes = [vp, ctypes.c_long, ctypes.c_long, dbl, dbl, dbl]
    _lib = dll
    return dll


def check_native_loop(topology: str = "direct", prsm: str = "fmu",
                      tolerance: float | None = None) -> None:
    """ValueError naming the option that ``loop = "native"`` cannot run with: a topology other
    than ``direct``, the PRSM as the plain Python model, a retry policy with a coupling
    ``tolerance``."""
    if topology != "direct":
        raise ValueError(f"loop = 'native': topology = {topology!r} is not supported: the native "
                         "loop runs the direct topology (controller, motor, PRSM FMU, load); use "
                         "loop = 'python'")
    if prsm == "python":
        raise ValueError("loop = 'native': prsm = 'python' is not supported: the native loop "
                         "steps the PRSM as an FMU (prsm 'fmu' or 'native'); use loop = 'python'")
    if tolerance is not None:
        raise ValueError(f"loop = 'native': retry.tolerance = {tolerance!r} is not supported "
                         "(rolling every step back on the coupling error needs the Python "
                         "master): must be None, or use loop = 'python'")


def _doubles(values) -> ctypes.Array:
    values = [float(v) for v in values]
    return (ctypes.c_double * max(1, len(values)))(*values)


def _ints(values) -> ctypes.Array:
    values = [int(v) for v in values]
    return (ctypes.c_int * max(1, len(values)))(*values)


class NativeMaster(Master):
    """The Python master with its macro steps taken in C (module docstring); same parameters
    and results as :class:`~system_models.master.Master`.

    Raises
    ------
    ValueError
        If the blocks are not the actuator loop's four (controller, motor, FMU, load) or the
        retry policy has a coupling ``tolerance`` (naming which).
    """

    def __init__(self, blocks, connections, step, **kwargs) -> None:
        super().__init__(blocks, connections, step, **kwargs)
        kinds = []
        for b in self.blocks:
            # the exact classes: a subclass may change what a step does, which the C would not
            kind = next((k for cls, k in _KINDS if type(b) is cls), None)
            if kind is None:
                raise ValueError(f"loop = 'native': block {b.name!r} ({type(b).__name__}) has no "
                                 "C translation; the native loop runs the controller, motor, "
                                 "PRSM FMU and load of system_models.ema (use loop = 'python')")
            kinds.append(kind)
        if sorted(kinds) != [0, 1, 2, 3]:
            raise ValueError("loop = 'native' needs exactly one controller, motor, FMU and load "
                             f"block, got {[type(b).__name__ for b in self.blocks]} "
                             "(use loop = 'python')")
        check_native_loop(tolerance=self.retry.tolerance)
        self._kinds = kinds
        self._lib = loop_library()
        self._handle = None

    # ---- set-up of one run -------------------------------------------------------------------
    def _block(self, kind: int) -> Any:
        return self.blocks[self._kinds.index(kind)]

    def _setup(self, n: int) -> None:
        """The C loop for a run of ``n`` macro steps: plan, block parameters, profiles."""
        lib = self._lib
        if self._handle is None:
            self._handle = ctypes.c_void_p(lib.ema_loop_new())
        motor: Motor = self._block(1)
        if motor.integrator != "rk4":
            raise ValueError(f"loop = 'native': motor.integrator = {motor.integrator!r} is not "
                             "supported: must be 'rk4', or use loop = 'python'")
        gs = self.order == "gauss-seidel"
        ints: list[int] = [int(gs), self.extrapolation]
        reals: list[float] = [self.t0, self.step]
        for i, b in enumerate(self.blocks):
            ints += [self._kinds[i], len(b.inputs), len(self.y[i]), int(b.interpolates_inputs),
                     int(b.feedthrough), int(self._read_after_step[i])]
            for kind, s, p, discrete in self._plan[i]:
                ints += [kind, 0 if kind == 0 else s, 0 if kind == 0 else p, int(discrete)]
                reals.append(s if kind == 0 else 0.0)
        ints.append(len(self._watched))
        for s, p in self._watched:
            ints += [s, p]
        ints.append(len(self._record))
        for i, p, _, _ in self._record:
            ints += [i, p]
        if lib.ema_loop_set_plan(self._handle, _ints(ints), _doubles(reals)) < 0:
            raise ValueError("loop = 'native': a block has more ports than the C loop holds")
        #: the arrays the C reads during the run (profiles)
        self._keep: list[ctypes.Array] = []
        self._set_controller(n)
        r, ell, p, psi, kt = motor._c
        lib.ema_loop_set_motor(self._handle, _doubles([r, ell, p, psi, kt, motor.max_substep,
                                                       motor._vmax, motor._trip]))
        load: SpringDamperLoad = self._block(3)
        lp = load.params
        h, t0 = self.step, self.t0
        # the load's time after macro step k is t + (t_next − t), as the master computes it
        ext = [load.external((t0 + k * h) + ((t0 + (k + 1) * h) - (t0 + k * h)))
               for k in range(n)]
        self._keep.append(_doubles(ext))
        lib.ema_loop_set_load(self._handle, _doubles([lp.preload, lp.stiffness, lp.damping]),
                              self._keep[-1], n)
        self._set_fmu()

    def _set_controller(self, n: int) -> None:
        ctl: CascadeController = self._block(0)
        p, m = ctl.params, ctl.motor
        ts = p.sample_time
        # the samples of the run (t_j = t0 + j T_s before its end) and two more
        count = int(math.floor((self.t0 + n * self.step - ctl.t0) / ts)) + 2
        j0 = ctl.j
        ref = [0.0] * j0 + [ctl.reference(ctl.t0 + j * ts) for j in range(j0, count)]
        plus, minus = [0.0] * count, [0.0] * count
        if ctl.mode == "position" and p.velocity_feedforward > 0.0:
            tp = ts * p.position_divider
            for j in range(j0, count):
                if j % p.position_divider == 0:
                    t = ctl.t0 + j * ts
                    plus[j], minus[j] = ctl.reference(t + tp), ctl.reference(t - tp)
        arrays = [_doubles(ref), _doubles(plus), _doubles(minus)]
        self._keep += arrays
        reals = [ts, p.current_kp, p.current_ki, p.speed_kp, p.speed_ki, p.position_kp,
                 p.position_ki, p.velocity_feedforward, p.current_limit, p.voltage_limit,
                 p.speed_limit, ctl._kaw_position, ctl._kaw_speed, ctl._kaw_current,
                 m.pole_pairs, m.inductance, m.flux_linkage, ctl.c, ctl.t0]
        ints = [p.speed_divider, p.position_divider, int(p.decoupling), _MODES[ctl.mode]]
        self._lib.ema_loop_set_controller(self._handle, _doubles(reals), _ints(ints), *arrays,
                                          count)

    def _set_fmu(self) -> None:
        fmu: FMUBlock = self._block(2)
        dll = fmu.fmu.dll

        def addr(f) -> int:
            return ctypes.cast(f, ctypes.c_void_p).value

        vr_real = list(fmu._arr_real)
        ints = [len(fmu._vr_in), *fmu._vr_in, len(vr_real), *vr_real, len(fmu._vr_int),
                *fmu._vr_int]
        ints += [0] if fmu._order is None else [1, *fmu._order]
        if self._lib.ema_loop_set_fmu(self._handle, fmu.fmu.component, addr(dll.fmi2SetReal),
                                      addr(dll.fmi2GetReal), addr(dll.fmi2GetInteger),
                                      addr(dll.fmi2DoStep), _ints(ints)) < 0:
            raise ValueError("loop = 'native': the FMU has more ports than the C loop holds")

    # ---- state between Python and C ----------------------------------------------------------
    def _state(self) -> list[float]:
        """The Python blocks' and the master's state in ema_loop.c's layout (state_io)."""
        ctl, motor, load = self._block(0), self._block(1), self._block(3)
        s = [float(ctl.j), *ctl.cmd, *ctl.integrals, *motor.x, load.t]
        for b in self.blocks:
            u = getattr(b, "u", None) or [0.0] * len(b.inputs)
            du = getattr(b, "du", None) or [0.0] * len(b.inputs)
            for v, d in zip(u, du):
                s += [v, d]
        prev = self.y_prev
        for i, row in enumerate(self.y):
            for p, v in enumerate(row):
                s += [v, prev[i][p] if prev is not None else 0.0, self.scale[i][p]]
        s += [float(prev is not None), self.t_prev if self.t_prev is not None else 0.0]
        return s

    def _push(self) -> None:
        state = self._state()
        self._buf = _doubles(state)
        self._lib.ema_loop_set_state(self._handle, self._buf)

    def _pull(self) -> None:
        """The C's state into the Python blocks and the master."""
        buf = self._buf
        self._lib.ema_loop_get_state(self._handle, buf)
        s = list(buf)
        ctl, motor, load = self._block(0), self._block(1), self._block(3)
        ctl.j = int(s[0])
        ctl.cmd, ctl.integrals, motor.x = s[1:7], s[7:11], s[11:16]
        load.t = s[16]
        a = 17
        for b in self.blocks:
            n = len(b.inputs)
            if isinstance(b, FMUBlock):
                a += 2 * n
                continue
            b.u, b.du = s[a:a + 2 * n:2], s[a + 1:a + 2 * n:2]
            a += 2 * n
        y, prev, scale = [], [], []
        for row in self.y:
            m = len(row)
            y.append(s[a:a + 3 * m:3])
            prev.append(s[a + 1:a + 3 * m:3])
            scale.append(s[a + 2:a + 3 * m:3])
            a += 3 * m
        has_prev = s[a] != 0.0
        self.y, self.scale = y, scale
        self.y_prev = prev if has_prev else None
        self.t_prev = s[a + 1] if has_prev else None

    # ---- stepping ----------------------------------------------------------------------------
    def _advance(self, k: int, n: int, times: list[float], rows: array, wall0: float) -> int:
        """Macro steps from ``k`` in C, up to :data:`CHUNK` at a time; a step the C hands back
        is taken by the Python master."""
        if k == 0:                       # a run's first step: the C loop for its n steps
            self._setup(n)
        k1 = min(n, k + CHUNK)
        nrec = len(self._record)
        out = (ctypes.c_double * max(1, (k1 - k) * nrec))()
        info = (ctypes.c_double * 4)()
        timers = _doubles(self._block_time)
        fmu = self._block(2)
        n0 = len(fmu.messages)
        self._push()
        code = self._lib.ema_loop_run(self._handle, k, k1, out, info, timers)
        self._pull()
        done = int(info[0])
        self._block_time = list(timers)[:len(self.blocks)]
        rows.frombytes(bytes(out)[:8 * done * nrec])
        h, t0 = self.step, self.t0
        times.extend(t0 + (j + 1) * h for j in range(k, k + done))
        stats = self._stats
        stats["macro_steps"] += done
        stats["substeps"] += done
        stats["max_coupling_error"] = max(stats["max_coupling_error"], info[1])
        if code == _DONE:
            return k1
        if code == _FMU_ERROR:
            call, status = _FMU_CALLS[int(info[3])], int(info[2])
            if call == "doStep":
                t = t0 + (k + done) * h
                raise fmu.step_error(t, (t0 + (k + done + 1) * h) - t, status, n0)
            fmu._check(call, status, n0)
        # _REFUSED or _PROFILE_END (a sample past the references given): the Python master
        # takes the step
        return self._steps(k + done, k + done + 1, n, times, rows, wall0)

    def terminate(self) -> None:
        super().terminate()
        if self._handle is not None:
            self._lib.ema_loop_free(self._handle)
            self._handle = None
