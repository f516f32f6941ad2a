"""Prescribed screw-speed profiles for the speed drive: ω(t) [rad/s] with its acceleration.

The speed drive integrates a prescribed acceleration held over each step (models/base.py), so
a profile is followed exactly wherever it is piecewise linear in time and its corners fall on
step boundaries: :func:`prsm_fmu.simulate` splits every output interval at the profile's
:meth:`SpeedProfile.breakpoints` and drives each piece with the exact mean acceleration
(ω(b) − ω(a)) / (b − a).  Ramps and tables are therefore followed exactly; a smooth user
function is followed as the piecewise-linear interpolant of its values at the output times
(speed exact at every output time, acceleration the mean over each interval: an error of order
h²·|ω̈| in speed between output times).

A speed that jumps (a step) is possible only at t = 0, as the initial condition: a jump later
would be an impulsive acceleration, which a rigid model with Coulomb contacts cannot carry
(infinite contact and friction forces).  Model a fast change as a short ramp instead.
"""

from __future__ import annotations

import bisect
import math
from typing import Callable, Sequence, Union


def _finite(name: str, value: float) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise ValueError(f"{name} = {value!r} is out of range: must be a finite number")
    return float(value)


class SpeedProfile:
    """A prescribed screw speed ω(t) [rad/s] for t ≥ 0 [s] (see module docstring)."""

    #: what the profile is, for messages and result metadata
    kind: str = "profile"

    def speed(self, t: float) -> float:
        """Prescribed screw speed at time t [s], in rad/s."""
        raise NotImplementedError

    def breakpoints(self, t0: float, t1: float) -> list[float]:
        """Times strictly inside (t0, t1) [s] where the acceleration may jump."""
        return []

    def pieces(self, t0: float, t1: float) -> list[tuple[float, float, float]]:
        """The interval [t0, t1] split at the breakpoints, each piece as (start [s], duration
        [s], mean acceleration [rad/s²])."""
        edges = [t0, *self.breakpoints(t0, t1), t1]
        out = []
        for a, b in zip(edges, edges[1:]):
            out.append((a, b - a, (self.speed(b) - self.speed(a)) / (b - a)))
        return out


class ConstantSpeed(SpeedProfile):
    """ω(t) = ω₀ [rad/s] from t = 0 (a step from rest at t = 0 when the run starts from rest,
    Li et al.'s (2021) start-up)."""

    kind = "constant"

    def __init__(self, speed: float) -> None:
        self.value = _finite("screw_speed", speed)

    def speed(self, t: float) -> float:
        return self.value

    def pieces(self, t0: float, t1: float) -> list[tuple[float, float, float]]:
        """One piece of acceleration 0.0: the base class's (ω₀ − ω₀)/(t1 − t0) (+0.0 for a finite
        ω₀ and t1 > t0), without its calls (simulate lists one per output interval)."""
        return [(t0, t1 - t0, 0.0)]


class TableSpeed(SpeedProfile):
    """Piecewise-linear ω(t) through (times [s], speeds [rad/s]); constant before the first
    and after the last point.

    Parameters
    ----------
    times : sequence of float
        Strictly increasing times [s], the first ≥ 0.
    speeds : sequence of float
        Screw speeds at those times [rad/s].
    """

    kind = "table"

    def __init__(self, times: Sequence[float], speeds: Sequence[float]) -> None:
        ts = [_finite(f"times[{i}]", v) for i, v in enumerate(times)]
        ws = [_finite(f"speeds[{i}]", v) for i, v in enumerate(speeds)]
        if len(ts) < 1 or len(ts) != len(ws):
            raise ValueError(f"times and speeds have {len(ts)} and {len(ws)} points: must be the "
                             "same number, at least 1")
        if ts[0] < 0.0:
            raise ValueError(f"times[0] = {ts[0]!r} s is out of range: must be >= 0")
        for i in range(1, len(ts)):
            if not ts[i] > ts[i - 1]:
                raise ValueError(f"times[{i}] = {ts[i]!r} s is out of range: must be > "
                                 f"times[{i - 1}] = {ts[i - 1]!r} s (strictly increasing)")
        self.times, self.speeds = ts, ws

    def speed(self, t: float) -> float:
        ts, ws = self.times, self.speeds
        if t <= ts[0]:
            return ws[0]
        if t >= ts[-1]:
            return ws[-1]
        i = bisect.bisect_right(ts, t)
        a, b = ts[i - 1], ts[i]
        return ws[i - 1] + (ws[i] - ws[i - 1]) * (t - a) / (b - a)

    def breakpoints(self, t0: float, t1: float) -> list[float]:
        return [t for t in self.times if t0 < t < t1]


class RampSpeed(TableSpeed):
    """ω(t) rising linearly from ω₀ to ω₁ [rad/s] over [t_start, t_start + duration] [s], constant
    before and after (the friction-torque article's 0 → 1 rad/s in t_a).

    Parameters
    ----------
    start_speed, end_speed : float
        ω₀ and ω₁ [rad/s].
    duration : float
        Ramp time t_a [s], > 0.
    t_start : float
        Start of the ramp [s], ≥ 0.
    """

    kind = "ramp"

    def __init__(self, start_speed: float, end_speed: float, duration: float,
                 t_start: float = 0.0) -> None:
        d = _finite("duration", duration)
        if d <= 0.0:
            raise ValueError(f"duration = {duration!r} s is out of range: must be > 0")
        t0 = _finite("t_start", t_start)
        super().__init__((t0, t0 + d), (start_speed, end_speed))


class FunctionSpeed(SpeedProfile):
    """ω(t) from a user function of time [s] returning rad/s, followed as its piecewise-linear
    interpolant between output times (module docstring)."""

    kind = "function"

    def __init__(self, function: Callable[[float], float]) -> None:
        if not callable(function):
            raise ValueError(f"screw_speed = {function!r} is not callable")
        self.function = function

    def speed(self, t: float) -> float:
        v = self.function(t)
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
            raise ValueError(f"screw_speed({t!r}) = {v!r} is out of range: the profile must return "
                             "a finite number [rad/s]")
        return float(v)


SpeedLike = Union[float, Callable[[float], float], SpeedProfile]


def as_speed_profile(value: SpeedLike) -> SpeedProfile:
    """A :class:`SpeedProfile` from a constant [rad/s], a function of time, or a profile."""
    if isinstance(value, SpeedProfile):
        return value
    if callable(value):
        return FunctionSpeed(value)
    return ConstantSpeed(value)


__all__ = ["SpeedProfile", "ConstantSpeed", "TableSpeed", "RampSpeed", "FunctionSpeed",
           "as_speed_profile"]
