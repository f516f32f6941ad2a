"""A motor fed by an ideal current source through a first-order bus delay.

The drive's current loop is taken as ideal (an ideal current source imposes the phase currents),
but the command reaches it through a first-order lag, the bus delay T_b (communication and PWM
update)::

    T_b i' = clamp(i*, ±I_max) − i            T_e = k_t i

For a permanent-magnet synchronous machine without damper cage fed with d current 0 and q
current i (RMS), k_t = m p ψ_rms with m = 3 phases, p pole pairs and ψ_rms = V_oc/(2π f) the
magnet's RMS flux linkage per phase from the open-circuit voltage V_oc at frequency f; the MSL
machine of ``Modelica.Blocks.Examples.Noise.ActuatorWithNoise`` (p = 2, V_oc = 112.3 V at 50 Hz)
gives k_t = 3·2·112.3/(2π·50) = 2.1447 N·m/A.  The electrical side (voltages, copper losses) is
not modelled: the source supplies whatever voltage the current needs.

The rotor's inertia is not a state here: it is rigidly coupled (through a gear, module
:mod:`.gear`, or directly) to the screw and lumped into the PRSM.  The lag is advanced exactly
for a command linear over the step (:func:`system_models.filters.lag_step`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from .blocks import Port, PythonBlock, StepRefused
from .filters import lag_step

__all__ = ["CurrentFedMotorParams", "CurrentFedMotor"]


@dataclass(frozen=True)
class CurrentFedMotorParams:
    """Data of the current-fed motor, SI units.

    Attributes
    ----------
    torque_constant : float
        k_t [N·m/A], > 0.
    rotor_inertia : float
        J_m, rotor and everything rigid on the motor shaft [kg·m²], >= 0.
    bus_delay : float
        T_b, time constant of the first-order bus delay [s], > 0.
    current_limit : float
        I_max, the source's largest current [A], > 0 (``inf``: none).
    """

    torque_constant: float = 2.1447
    rotor_inertia: float = 0.58
    bus_delay: float = 1e-3
    current_limit: float = math.inf

    def validate(self) -> "CurrentFedMotorParams":
        """Check every field; ValueError naming the field, its value and the range."""
        for f, lo, finite in (("torque_constant", 0.0, True), ("bus_delay", 0.0, True),
                              ("current_limit", 0.0, False)):
            v = getattr(self, f)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or math.isnan(v) \
                    or not v > lo or (finite and not math.isfinite(v)):
                raise ValueError(f"motor.{f} = {v!r} is out of range: must be a "
                                 f"{'finite ' if finite else ''}number > 0")
        v = self.rotor_inertia
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not (math.isfinite(v) and v >= 0):
            raise ValueError(f"motor.rotor_inertia = {v!r} is out of range: must be a finite "
                             "number >= 0")
        return self


class CurrentFedMotor(PythonBlock):
    """The current-fed motor as a co-simulation block (module docstring).

    Inputs: ``current_command`` [A] (i*), ``speed`` [rad/s] (the rotor's, for the air-gap power).
    Outputs: ``current`` [A], ``torque`` [N.m], ``airgap_power`` [W].
    """

    inputs = (Port("current_command", "A", "current command i* (before the bus delay)"),
              Port("speed", "rad/s", "rotor speed"))
    outputs = (Port("current", "A", "current after the bus delay"),
               Port("torque", "N.m", "electromagnetic torque k_t i"),
               Port("airgap_power", "W", "air-gap power T_e ω"))
    interpolates_inputs = True
    _state_attrs = ("i",)

    def __init__(self, params: CurrentFedMotorParams = CurrentFedMotorParams(),
                 name: str = "motor", current: float = 0.0) -> None:
        self.params = params.validate()
        super().__init__(name)
        self.i = float(current)

    def _clamped(self, v: float) -> float:
        lim = self.params.current_limit
        return min(lim, max(-lim, v))

    def do_step(self, t: float, h: float) -> None:
        if not (math.isfinite(h) and h > 0.0):
            raise StepRefused(self.name, t, h, f"step size h = {h!r} s must be a finite number > 0")
        u0, du = self.u[0], self.du[0]
        if not (math.isfinite(u0) and math.isfinite(du)):
            raise StepRefused(self.name, t, h, f"non-finite current command {u0!r} A "
                              f"(slope {du!r} A/s)")
        lim = self.params.current_limit
        if math.isinf(lim) or (abs(u0) <= lim and abs(u0 + du * h) <= lim):
            self.i = lag_step(self.i, u0, du, h, self.params.bus_delay)
        else:                     # the clamp bends the command: piecewise-linear cells
            n = 16
            dt = h / n
            for j in range(n):
                a, b = self._clamped(u0 + du * j * dt), self._clamped(u0 + du * (j + 1) * dt)
                self.i = lag_step(self.i, a, (b - a) / dt, dt, self.params.bus_delay)

    def get_outputs(self) -> list[float]:
        kt = self.params.torque_constant
        return [self.i, kt * self.i, kt * self.i * self.u[1]]
