"""One point of a study on the torque-driven FMU, with the screw speed prescribed by the master.

The FMU (``PRSM<n>.fmu``, docs/fmu.md) takes the motor torque as its input; the papers' studies
prescribe the screw speed (a step at t = 0, or a linear ramp).  :class:`FmuRunner` is the
master that closes that gap exactly, without a controller's lag: on every communication step
[t, t + h] it finds the torque T, held over the step, for which the FMU's screw speed at t + h
equals the reference ω_ref(t + h).  It saves the FMU state (``fmi2GetFMUstate``), steps with a
trial torque, reads the speed, restores the state and steps again with the secant correction,
until the correction is below ``torque_rtol`` of the torque (the speed at the end of a step is
an affine function of the held torque wherever the friction directions do not change, so one
or two trials suffice; a bracket guards the steps where they do).  The speed therefore meets
the reference at every communication point; inside a step it deviates by O(h²·dT/dt / J).

The sample at t = 0 is found the same way in initialization mode, where the outputs are
previews of the start state: the torque for which ``screw_acceleration`` equals the
reference's initial acceleration (0 for a step), so that the t = 0 row holds the driven
torques, contact forces and efficiency of the prescribed motion, as the speed-driven model
gives them.

An instance loads the FMU once (extract, read the model description, instantiate) and runs
any number of points on it, resetting it (``fmi2Reset``) between them; every parameter of
the point's mechanism is set in initialization mode, so no value leaks from one point into
the next.  After a failure inside the FMU (fmi2Error, fmi2Fatal) the instance is freed and a
new one is made for the next point.  The FMU is instantiated with logging on and its messages
are kept (:class:`~prsm_fmu.fmu_log.FmuLog`): a point that fails says the FMU's own reason.

The step loop runs compiled by default (``loop = "auto"``: ``prsm_fmu/sweep/native/fmu_track.c``,
:mod:`~prsm_fmu.sweep.native_track`, built with gcc on first use), the loop below translated
operation for operation: the same FMI calls with the same arguments, so the same results bit
for bit (tests/test_fmu_track.py); :meth:`FmuRunner._python_loop` is its readable reference and
runs where the C cannot be built.

Imports fmpy (only when a runner is made); never imported by the physics.
"""

from __future__ import annotations

import ctypes
import math
from dataclasses import fields
from typing import Callable

import numpy as np

from ..fmi_enum import enumeration_value
from ..fmu_log import FmuLog
from ..params import MECHANISM_FIELD_NAMES, MechanismParams, StageParams
from ..profiles import ConstantSpeed
from .fmi_calls import StepCalls

#: mechanism-level parameters of the FMU (fields of MechanismParams that are FMU parameters)
MECHANISM_PARAMETERS = MECHANISM_FIELD_NAMES

#: relative tolerance of the tracked torque: the secant iteration stops when its correction is
#: below torque_rtol·(|T| + torque scale)
TORQUE_RTOL = 1e-10

#: most trials per communication step before the best one is taken (and its error recorded)
MAX_TRIALS = 30

#: the step loops a runner can take: ``native`` the compiled one
#: (:mod:`prsm_fmu.sweep.native_track`: the same calls and results), ``python`` this module's,
#: ``auto`` the compiled one where it can be built (gcc), else this module's
LOOPS = ("auto", "native", "python")


class FmuPointError(RuntimeError):
    """The FMU refused a step or failed; the message says where and why."""


def fmu_parameter_values(params: MechanismParams) -> dict[str, object]:
    """Every physical parameter of ``params`` under its FMU name (``stage[k].<field>`` etc.)."""
    values: dict[str, object] = {}
    for k, st in enumerate(params.stages, start=1):
        for f in fields(StageParams):
            values[f"stage[{k}].{f.name}"] = getattr(st, f.name)
    for name in MECHANISM_PARAMETERS:
        values[name] = getattr(params, name)
    return values


class FmuRunner:
    """A loaded FMU that runs speed-prescribed points (module docstring).

    Parameters
    ----------
    fmu_path : str
        Path of ``PRSM<n>.fmu``.
    tolerance : float
        The FMU's ``tolerance`` parameter (rtol of its adaptive steppers; atol = 0.01·tolerance),
        default 1e-8, the tolerances of :func:`prsm_fmu.simulate`.
    loop : {"auto", "native", "python"}
        The step loop (:data:`LOOPS`): the compiled one or this module's; the same results.
        ``native`` raises where it cannot be built; ``auto`` then takes this module's (and
        :attr:`loop_note` says why).
    """

    def __init__(self, fmu_path: str, tolerance: float = 1e-8, loop: str = "auto") -> None:
        from fmpy import extract, read_model_description

        if loop not in LOOPS:
            raise ValueError(f"loop = {loop!r} is not allowed: must be one of {', '.join(LOOPS)}")
        self._lib = None
        #: why the compiled loop is not used (None where it is, or where loop = "python")
        self.loop_note: str | None = None
        if loop != "python":
            from .native_track import loop_library

            self._lib, self.loop_note = loop_library()
            if self._lib is None and loop == "native":
                raise RuntimeError(self.loop_note)
        self._loop = None           # the instance's compiled loop (CompiledLoop), if any
        self.fmu_path = str(fmu_path)
        self.tolerance = float(tolerance)
        self.md = read_model_description(self.fmu_path)
        self.unzipdir = extract(self.fmu_path)
        self.vars = {v.name: v for v in self.md.modelVariables}
        self.vr = {name: v.valueReference for name, v in self.vars.items()}
        self.output_names = tuple(v.name for v in self.md.modelVariables
                                  if v.causality == "output" and v.type == "Real")
        self._out_vrs = [self.vr[n] for n in self.output_names]
        self._i_speed = self.output_names.index("screw_speed")
        self.n_stages = sum(1 for n in self.output_names if n.endswith(".contact_force"))
        self.fmu = None
        self._calls: StepCalls | None = None      # the step loop's calls into the instance
        self.log = FmuLog()           # the FMU's messages of the current point
        self.points_run = 0
        self.instances_made = 0

    # ---- instance life cycle ------------------------------------------------------------
    def _instance(self):
        from fmpy.fmi2 import FMU2Slave

        if self.fmu is None:
            self.fmu = FMU2Slave(guid=self.md.guid, unzipDirectory=self.unzipdir,
                                 modelIdentifier=self.md.coSimulation.modelIdentifier,
                                 instanceName="prsm_sweep")
            self.fmu.instantiate(callbacks=self.log.callbacks, loggingOn=True)
            self._calls = StepCalls(self.fmu, self.vr["screw_torque"], self.vr["screw_speed"],
                                    self.vr["step_rhs_calls"], self._out_vrs)
            if self._lib is not None:
                from .native_track import CompiledLoop

                self._loop = CompiledLoop(self._lib, self._calls)
            self.instances_made += 1
            self._fresh = True
        elif not self._fresh:
            self.fmu.reset()
        self._fresh = False
        return self.fmu

    def discard(self) -> None:
        """Free the instance (after a failure); the next point makes a new one."""
        if self.fmu is not None:
            try:
                self.fmu.freeInstance()
            except Exception:  # noqa: BLE001 - a failed instance may refuse; it is dropped anyway
                pass
        self.fmu = None
        self._calls = None
        self._loop = None

    def close(self) -> None:
        """Free the instance and forget the FMU."""
        self.discard()

    def _set_parameters(self, fmu, values: dict[str, object]) -> None:
        reals, ints, bools, strings = ([], []), ([], []), ([], []), ([], [])
        for name, value in values.items():
            var = self.vars.get(name)
            if var is None:
                raise ValueError(f"parameter {name!r} is not a variable of {self.fmu_path}")
            if var.type == "Enumeration":          # fidelity, stepper: item name -> value
                value = enumeration_value(var, value)
            bucket = {"Real": reals, "Integer": ints, "Enumeration": ints, "Boolean": bools,
                      "String": strings}[var.type]
            bucket[0].append(var.valueReference)
            bucket[1].append(value)
        if reals[0]:
            fmu.setReal(reals[0], [float(v) for v in reals[1]])
        if ints[0]:
            fmu.setInteger(ints[0], [int(v) for v in ints[1]])
        if bools[0]:
            fmu.setBoolean(bools[0], [bool(v) for v in bools[1]])
        if strings[0]:
            fmu.setString(strings[0], [str(v) for v in strings[1]])

    # ---- one point ------------------------------------------------------------------------
    def run(self, params: MechanismParams, fidelity: str, speed: Callable[[float], float],
            acceleration0: float, load_force: float, t_end: float,
            output_interval: float) -> dict[str, np.ndarray]:
        """Simulate one point with the screw speed prescribed at every communication point.

        Parameters
        ----------
        params : MechanismParams
            The mechanism (validated by the caller); its stage count must be the FMU's.
        fidelity : str
            The FMU's ``fidelity`` parameter.
        speed : callable
            Reference screw speed ω_ref(t) [rad/s]; ω_ref(0) is the initial speed (carriers at
            rest).
        acceleration0 : float
            Reference screw acceleration at t = 0⁺ [rad/s²] (0 for a step).
        load_force : float
            Constant load on the last nut [N].
        t_end, output_interval : float
            End time and communication step [s]; t_end a whole multiple of the step.

        Returns
        -------
        dict
            ``time`` and every Real output of the FMU as arrays (samples at the communication
            points, t = 0 included), plus ``speed_reference`` [rad/s], ``trials`` (doStep
            calls, int) and ``rhs_calls`` (right-hand-side evaluations of the accepted steps).

        Raises
        ------
        FmuPointError
            If the FMU refuses a step or fails; the instance is discarded.
        ValueError
            If the FMU has another stage count than ``params``.
        """
        if params.n_stages != self.n_stages:
            raise ValueError(f"the mechanism has {params.n_stages} stages but "
                             f"{self.fmu_path} has {self.n_stages}")
        n_steps = round(t_end / output_interval)
        self.log.clear()
        try:
            return self._run(params, fidelity, speed, acceleration0, load_force, n_steps,
                             output_interval)
        except FmuPointError as exc:
            self.discard()
            raise FmuPointError(f"{exc}{self._fmu_says()}") from exc
        except Exception as exc:  # FMICallException and friends
            self.discard()
            raise FmuPointError(f"the FMU failed: {type(exc).__name__}: {exc}"
                                f"{self._fmu_says()}") from exc
        finally:
            self.points_run += 1

    def _fmu_says(self) -> str:
        """The FMU's warnings and errors of this point, as ``": the FMU says: ..."``."""
        reason = self.log.reason(problems_only=True)
        return f": the FMU says: {reason}" if reason else " (the FMU logged no reason)"

    def _run(self, params, fidelity, speed, acceleration0, load_force, n_steps, h):
        fmu = self._instance()
        vr = self.vr
        vr_load = vr["load_force"]
        w0 = float(speed(0.0))
        fmu.setupExperiment(startTime=0.0)
        fmu.enterInitializationMode()
        values = fmu_parameter_values(params)
        values.update(fidelity=fidelity, tolerance=self.tolerance, initial_screw_speed=w0,
                      initial_screw_angle=0.0, initial_carrier_equilibrium=False)
        self._set_parameters(fmu, values)
        fmu.setReal([vr_load], [float(load_force)])
        # torque scale: the ideal torque of the load (never 0, so relative tolerances work)
        t_scale = abs(load_force) * params.total_lead / (2.0 * math.pi) + 1e-6

        # t = 0: the torque whose preview acceleration is the reference's (the same calls as
        # fmpy's setReal and getReal, straight into the library: StepCalls)
        calls = self._calls
        vr_acc = (ctypes.c_uint * 1)(vr["screw_acceleration"])

        def preview_acc(torque: float) -> float:
            calls.set_torque(torque)
            return calls.real(vr_acc) - acceleration0

        torque = _secant_root(preview_acc, 0.0, t_scale, TORQUE_RTOL * 1e-2)
        calls.set_torque(torque)
        out = np.empty((n_steps + 1, len(self.output_names)))
        calls.outputs_into(out.ctypes.data)         # row 0
        fmu.exitInitializationMode()

        ref = np.empty(n_steps + 1)
        ref[0] = w0
        if self._loop is not None:              # the same loop, compiled
            ref[1:] = _reference(speed, n_steps, h)
            from .native_track import LoopFailure

            try:
                trials, rhs_calls = self._loop.run(n_steps, h, ref[1:], torque, TORQUE_RTOL,
                                                   MAX_TRIALS, t_scale, out[1:])
            except LoopFailure as fail:                 # as the Python loop raises it
                self._raise_failed_step(fail.error, fail.step * h, fail.torque)
        else:
            trials, rhs_calls = self._python_loop(speed, n_steps, h, torque, t_scale, ref, out)
        fmu.terminate()
        res = {"time": np.arange(n_steps + 1) * h}
        res.update({name: out[:, j] for j, name in enumerate(self.output_names)})
        res["speed_reference"] = ref
        res["trials"] = trials
        res["rhs_calls"] = rhs_calls
        return res

    def _python_loop(self, speed, n_steps, h, torque, t_scale, ref, out) -> tuple[int, int]:
        """Steps 0 … n_steps − 1: each step's torque tracked, the reference speeds into
        ``ref[1:]`` and the outputs into ``out[1:]``; (trials, right-hand-side calls).  The
        readable reference of the compiled loop (:mod:`~prsm_fmu.sweep.native_track`)."""
        trials = 0
        rhs_calls = 0
        last, before = torque, None     # the tracked torques of the last two steps [N·m]
        gain = None           # d(speed at t + h)/d(torque) [rad/s per N·m], learnt on the way
        calls = self._calls
        track = self._track
        # each communication point's outputs straight into its row of ``out``
        row0, row_bytes = out.ctypes.data, out.strides[0]
        for i in range(n_steps):
            t = i * h
            target = float(speed((i + 1) * h))
            ref[i + 1] = target
            # guess: linear extrapolation of the tracked torque
            guess = last if before is None else 2.0 * last - before
            state = calls.get_state()
            try:
                torque, gain, n_trials = track(calls, state, t, h, target, guess, gain, t_scale)
            finally:
                calls.free_state(state)
            trials += n_trials
            last, before = torque, last
            calls.outputs_into(row0 + (i + 1) * row_bytes)
            rhs_calls += calls.rhs_calls()
        return trials, rhs_calls

    @staticmethod
    def _trial(calls: StepCalls, state, restore: bool, t: float, h: float,
               torque: float) -> float:
        """Step from the saved state with ``torque`` held; the screw speed at t + h."""
        if restore:
            calls.set_state(state)
        calls.set_torque(torque)
        try:
            calls.do_step(t, h)
        except calls.failure as exc:
            FmuRunner._raise_failed_step(exc, t, torque)
        return calls.speed()

    @staticmethod
    def _raise_failed_step(exc, t: float, torque: float):
        """Raise for fmpy's ``exc`` of a trial at ``t`` [s] with ``torque`` [N·m]: a refused
        ``fmi2DoStep`` as :class:`FmuPointError` naming both, any other call as it is."""
        if exc.function != "fmi2DoStep":
            raise exc
        raise FmuPointError(f"the FMU refused the step at t = {t:.9g} s with screw_torque "
                            f"= {torque!r} N.m (status {exc.status})") from exc

    def _track(self, calls, state, t, h, target, guess, gain, t_scale):
        """Torque held over [t, t + h] that ends the step at ``target``; leaves the FMU there.

        Returns (torque, gain, trials).
        """
        torque = guess
        err = self._trial(calls, state, False, t, h, torque) - target
        n = 1
        lo = hi = None                      # bracket: (torque, error) with error < 0 / > 0
        best = (abs(err), torque)
        while True:
            if err < 0.0:
                lo = (torque, err)
            elif err > 0.0:
                hi = (torque, err)
            else:
                return torque, gain, n
            if gain is None or not gain > 0.0:
                # first step: probe the slope with a small torque change
                step = 1e-3 * (abs(torque) + t_scale)
                new = torque + (step if err < 0.0 else -step)
            else:
                new = torque - err / gain
                if lo is not None and hi is not None and not (min(lo[0], hi[0]) < new
                                                              < max(lo[0], hi[0])):
                    new = 0.5 * (lo[0] + hi[0])          # secant left the bracket: bisect
            if abs(new - torque) <= TORQUE_RTOL * (abs(torque) + t_scale):
                return torque, gain, n
            if n >= MAX_TRIALS:
                # keep the best trial: restore it (its error stays in the speed output)
                torque = best[1]
                self._trial(calls, state, True, t, h, torque)
                return torque, gain, n + 1
            new_err = self._trial(calls, state, True, t, h, new) - target
            n += 1
            if new != torque and new_err != err:
                slope = (new_err - err) / (new - torque)
                if slope > 0.0:
                    gain = slope
            torque, err = new, new_err
            if abs(err) < best[0]:
                best = (abs(err), torque)


def _reference(speed: Callable[[float], float], n_steps: int, h: float) -> float | list[float]:
    """The reference speeds at the communication points h, 2h, ..., n_steps·h [rad/s], for
    ``ref[1:]``: ``float(speed((i + 1) * h))`` each, as the Python loop reads them; for a
    :class:`~prsm_fmu.profiles.ConstantSpeed` its value once (the same double at every point:
    numpy fills the row with it) instead of n_steps calls."""
    if getattr(speed, "__func__", None) is ConstantSpeed.speed:       # a ConstantSpeed's .speed
        return speed.__self__.value
    return [float(speed((i + 1) * h)) for i in range(n_steps)]


def _secant_root(f: Callable[[float], float], x0: float, scale: float, rtol: float) -> float:
    """Root of a (nearly) affine, increasing function by the secant method from x0."""
    f0 = f(x0)
    x1 = x0 + scale
    f1 = f(x1)
    for _ in range(50):
        if f1 == f0:
            break
        x2 = x1 - f1 * (x1 - x0) / (f1 - f0)
        x0, f0 = x1, f1
        x1 = x2
        f1 = f(x1)
        if abs(x1 - x0) <= rtol * (abs(x1) + scale) or f1 == 0.0:
            break
    return x1
