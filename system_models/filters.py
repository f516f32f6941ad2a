"""Linear continuous-time filters advanced exactly over a step with a linear input.

Each function advances one state over ``h`` [s] with the input ``u(τ) = u0 + du·τ`` (value
[unit] and slope [unit/s] over the step, the co-simulation master's first-order view of an
input); the update is the exact solution of the ODE, not a numerical integration, so a filter's
response does not depend on the step (tests/test_actuator_blocks.py checks it against the
closed forms).

=====================  ====================================  =======================================
filter                 equations                              module use
=====================  ====================================  =======================================
first-order lag        T y' = k u − y                          bus delay of the current-fed motor
derivative filter      y = (k/T)(u − x),  T x' = u − x         speed estimated from a measured angle
PI                     y = k (x + u),  T x' = u                the continuous cascade's loops
=====================  ====================================  =======================================
"""

from __future__ import annotations

import math

__all__ = ["lag_step", "integral_step", "DerivativeFilter", "ContinuousPI"]


def lag_step(y0: float, u0: float, du: float, h: float, time_constant: float,
             gain: float = 1.0) -> float:
    """Exact solution after ``h`` [s] of T y' = k u − y with u = u0 + du·τ.

    With v = k u: y(h) = v(h) − k du T + (y0 − v0 + k du T) e^(−h/T).

    Parameters
    ----------
    y0 : float
        Output at the start of the step.
    u0, du : float
        Input at the start [unit] and its slope [unit/s].
    h : float
        Step [s], >= 0.
    time_constant : float
        T [s], > 0.
    gain : float
        Static gain k [-].
    """
    e = math.exp(-h / time_constant)
    kdt = gain * du * time_constant
    return gain * (u0 + du * h) - kdt + (y0 - gain * u0 + kdt) * e


def integral_step(x0: float, u0: float, du: float, h: float, time_constant: float) -> float:
    """Exact x(h) of T x' = u with u = u0 + du·τ: x0 + (u0 h + du h²/2)/T."""
    return x0 + (u0 * h + 0.5 * du * h * h) / time_constant


class DerivativeFilter:
    """Approximate derivative y = k s/(T s + 1) u: speed estimated from a measured angle.

    State x (the filtered input): T x' = u − x; output y = (k/T)(u − x).  For a ramp u = a t
    from rest (x(0) = u(0)) the output is y = k a (1 − e^(−t/T)): the estimate lags the true rate
    by T.  MSL ``Modelica.Blocks.Continuous.Derivative`` has the same equations.

    Parameters
    ----------
    time_constant : float
        T [s], > 0.
    gain : float
        k [-].
    x0 : float
        Initial state [unit of u]; ``x0 = u(0)`` starts with zero output.
    """

    __slots__ = ("T", "k", "x")

    def __init__(self, time_constant: float, gain: float = 1.0, x0: float = 0.0) -> None:
        if not (math.isfinite(time_constant) and time_constant > 0.0):
            raise ValueError(f"derivative filter time_constant = {time_constant!r} s is out of "
                             "range: must be a finite number > 0")
        self.T, self.k, self.x = float(time_constant), float(gain), float(x0)

    def output(self, u: float) -> float:
        """y = (k/T)(u − x) [unit of u per s]."""
        return self.k * (u - self.x) / self.T

    def advance(self, u0: float, du: float, h: float) -> None:
        """Advance the state exactly over ``h`` [s] with u = u0 + du·τ."""
        self.x = lag_step(self.x, u0, du, h, self.T)


class ContinuousPI:
    """PI controller y = k (x + u), T x' = u (MSL ``Modelica.Blocks.Continuous.PI``).

    Parameters
    ----------
    gain : float
        k [output unit / input unit].
    time_constant : float
        T [s], > 0 (integral time).
    x0 : float
        Initial integrator state [input unit].
    """

    __slots__ = ("k", "T", "x")

    def __init__(self, gain: float, time_constant: float, x0: float = 0.0) -> None:
        if not (math.isfinite(time_constant) and time_constant > 0.0):
            raise ValueError(f"PI time_constant = {time_constant!r} s is out of range: must be a "
                             "finite number > 0")
        if not math.isfinite(gain):
            raise ValueError(f"PI gain = {gain!r} is out of range: must be finite")
        self.k, self.T, self.x = float(gain), float(time_constant), float(x0)

    def output(self, u: float) -> float:
        """y = k (x + u)."""
        return self.k * (self.x + u)

    def advance(self, u0: float, du: float, h: float) -> None:
        """Advance the integrator exactly over ``h`` [s] with u = u0 + du·τ."""
        self.x = integral_step(self.x, u0, du, h, self.T)
