"""A continuous position controller on the motor angle: the MSL actuator example's controller.

Loops (MSL 4.1 ``Modelica.Blocks.Examples.Noise.Utilities.Parts.Controller``)::

    measured angle   m = sensor(t, φ_m)                        noise and quantisation (.noise)
    speed estimate   ω̂ = s/(T_D s + 1) m                       derivative filter (.filters)
    speed reference  ω* = K_p (1 + 1/(T_p s)) (r − m)          position PI
    current command  i* = K_s (1 + 1/(T_s s)) (ω* − ω̂)         speed PI

r(t) is the reference (a profile, e.g. a slew-limited step).  The first-order bus delay
between i* and the motor's current belongs to the current-fed motor (.current_motor).  Initial
state as MSL's: the position integrator at 0, the derivative filter at the first measurement
(ω̂ = 0) and the speed integrator such that i* = 0.

The controller is continuous: over a communication step the block integrates its three states
with RK4 on substeps of at most ``max_substep`` (the fastest time constant, T_D = 10 ms in the
example, is a hundred substeps), with the motor angle linear over the step (value and slope
from the master) and the sensor's noise evaluated at each substep's midpoint (exact when the
noise's sample instants fall on the substep grid, which the scene check requires).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable

from .blocks import Port, PythonBlock, StepRefused
from .filters import ContinuousPI, DerivativeFilter
from .noise import Sensor

__all__ = ["ContinuousCascadeParams", "ContinuousCascade"]


@dataclass(frozen=True)
class ContinuousCascadeParams:
    """Gains and time constants of the continuous cascade, SI units.

    Defaults: MSL's ``Controller`` (position PI k = 3, T = 0.5 s; speed PI k = 10, T = 0.05 s;
    derivative filter T = 0.01 s).

    Attributes
    ----------
    position_gain : float
        K_p [(rad/s)/rad].
    position_time : float
        T_p, integral time [s].
    speed_gain : float
        K_s [A/(rad/s)].
    speed_time : float
        T_s [s].
    derivative_time : float
        T_D of the speed estimate [s].
    max_substep : float
        Largest internal step [s].
    """

    position_gain: float = 3.0
    position_time: float = 0.5
    speed_gain: float = 10.0
    speed_time: float = 0.05
    derivative_time: float = 0.01
    max_substep: float = 1e-4

    def validate(self) -> "ContinuousCascadeParams":
        """Check every field; ValueError naming the field, its value and the range."""
        for f in ("position_gain", "position_time", "speed_gain", "speed_time",
                  "derivative_time", "max_substep"):
            v = getattr(self, f)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not (math.isfinite(v) and v > 0):
                raise ValueError(f"controller.{f} = {v!r} is out of range: must be a finite number > 0")
        return self


class ContinuousCascade(PythonBlock):
    """The continuous cascade as a co-simulation block (module docstring).

    Inputs: ``angle`` [rad], the true motor angle.  Outputs: ``current_command`` [A],
    ``reference`` [rad], ``measured_angle`` [rad], ``speed_estimate`` [rad/s],
    ``speed_reference`` [rad/s].
    """

    inputs = (Port("angle", "rad", "motor angle (true; the sensor adds noise)"),)
    outputs = (Port("current_command", "A", "current command i* (speed PI output)"),
               Port("reference", "rad", "motor angle reference r"),
               Port("measured_angle", "rad", "the sensor's motor angle"),
               Port("speed_estimate", "rad/s", "speed estimated from the measured angle"),
               Port("speed_reference", "rad/s", "position PI output ω*"))
    interpolates_inputs = True
    _state_attrs = ("z", "t")

    def __init__(self, params: ContinuousCascadeParams, reference: Callable[[float], float],
                 sensor: Sensor | None = None, t0: float = 0.0, initial_angle: float = 0.0,
                 name: str = "controller") -> None:
        self.params = params.validate()
        super().__init__(name)
        self.reference = reference
        self.sensor = sensor or Sensor()
        self.t = float(t0)
        self.u = [float(initial_angle)]
        m0 = self.sensor(t0, initial_angle)
        p = params
        pos = ContinuousPI(p.position_gain, p.position_time, 0.0)
        w_ref = pos.output(reference(t0) - m0)
        #: states: position integrator, filtered angle, speed integrator (i* = 0 at t0)
        self.z = [0.0, m0, -w_ref]

    def _signals(self, t: float, z, m: float) -> tuple[float, float, float, float, float]:
        """(i*, ω*, ω̂, e_p, e_s) at time t, state z, measured angle m."""
        p = self.params
        ep = self.reference(t) - m
        w_ref = p.position_gain * (z[0] + ep)
        w_est = (m - z[1]) / p.derivative_time
        es = w_ref - w_est
        return p.speed_gain * (z[2] + es), w_ref, w_est, ep, es

    def _rhs(self, t: float, z, m: float):
        p = self.params
        _, _, _, ep, es = self._signals(t, z, m)
        return (ep / p.position_time, (m - z[1]) / p.derivative_time, es / p.speed_time)

    def do_step(self, t: float, h: float) -> None:
        if not (math.isfinite(h) and h > 0.0):
            raise StepRefused(self.name, t, h, f"step size h = {h!r} s must be a finite number > 0")
        a0, da = self.u[0], self.du[0]
        if not (math.isfinite(a0) and math.isfinite(da)):
            raise StepRefused(self.name, t, h, f"non-finite motor angle {a0!r} rad (slope {da!r})")
        n = max(1, math.ceil(h / self.params.max_substep - 1e-9))
        dt = h / n
        z = list(self.z)
        sensor, f = self.sensor, self._rhs
        for j in range(n):
            ta = t + j * dt
            tm = ta + 0.5 * dt                         # the noise sample held over this substep
            ma = sensor(tm, a0 + da * j * dt)
            mm = sensor(tm, a0 + da * (j + 0.5) * dt)
            mb = sensor(tm, a0 + da * (j + 1) * dt)
            k1 = f(ta, z, ma)
            k2 = f(tm, [a + 0.5 * dt * b for a, b in zip(z, k1)], mm)
            k3 = f(tm, [a + 0.5 * dt * b for a, b in zip(z, k2)], mm)
            k4 = f(ta + dt, [a + dt * b for a, b in zip(z, k3)], mb)
            z = [a + dt / 6.0 * (b + 2 * c + 2 * d + e) for a, b, c, d, e in zip(z, k1, k2, k3, k4)]
        if not all(math.isfinite(v) for v in z):
            raise StepRefused(self.name, t, h, f"the controller's state became non-finite: {z}")
        self.z, self.t = z, t + h
        self.u = [a0 + da * h]

    def get_outputs(self) -> list[float]:
        m = self.sensor(self.t, self.u[0])
        i_cmd, w_ref, w_est, _, _ = self._signals(self.t, self.z, m)
        return [i_cmd, self.reference(self.t), m, w_est, w_ref]
