"""A slew-rate-limited reference: the output follows its input at a bounded rate.

Model (MSL ``Modelica.Blocks.Nonlinear.SlewRateLimiter``, non-strict)::

    y' = clamp((u − y)/T_d, falling, rising)

with the rates ``rising`` > 0 and ``falling`` < 0 [unit/s] and the time constant T_d [s] with
which the output settles once the remaining distance is small (|u − y| < rate·T_d).  For a
constant input the solution is piecewise closed-form: a ramp at the limiting rate until
|u − y| = rate·T_d, then the exponential y = u − (u − y₁) e^(−(t − t₁)/T_d);
:meth:`SlewRateLimiter.advance` uses it, so the result does not depend on the step.
:func:`slew_limited` wraps a profile (system_models.signals) into its slew-limited version.
"""

from __future__ import annotations

import math
from typing import Callable

__all__ = ["SlewRateLimiter", "slew_limited"]


class SlewRateLimiter:
    """The rate limiter's law (module docstring), advanced exactly for a constant input.

    Parameters
    ----------
    rising : float
        Largest rate [unit/s], > 0.
    falling : float, optional
        Most negative rate [unit/s], < 0 (default −rising).
    time_constant : float
        T_d [s], > 0 (MSL's default 1e-3 s).
    """

    def __init__(self, rising: float, falling: float | None = None,
                 time_constant: float = 1e-3) -> None:
        falling = -rising if falling is None else falling
        for name, v, ok in (("rising", rising, rising > 0), ("falling", falling, falling < 0),
                            ("time_constant", time_constant, time_constant > 0)):
            if not (isinstance(v, (int, float)) and math.isfinite(v) and ok):
                raise ValueError(f"slew.{name} = {v!r} is out of range: must be a finite number "
                                 + ("< 0" if name == "falling" else "> 0"))
        self.rising, self.falling, self.td = float(rising), float(falling), float(time_constant)

    def advance(self, y: float, u: float, h: float) -> float:
        """y after ``h`` [s] under the constant input ``u`` (exact)."""
        e = u - y
        rate = self.rising if e > 0 else self.falling
        band = abs(rate) * self.td                 # |u − y| below which the limit is off
        if abs(e) > band:
            t_sat = (abs(e) - band) / abs(rate)    # time at the limiting rate
            if h <= t_sat:
                return y + rate * h
            y, h = u - math.copysign(band, e), h - t_sat
        return u - (u - y) * math.exp(-h / self.td)


def slew_limited(profile: Callable[[float], float], limiter: SlewRateLimiter, t0: float = 0.0,
                 y0: float | None = None, resolution: float | None = None) -> Callable[[float], float]:
    """The slew-limited version of ``profile`` as a function of time [s].

    The input is sampled on a grid of ``resolution`` (default T_d/10) and held over each cell at
    its value at the cell's midpoint, and the limiter is advanced exactly over each cell; the
    result is exact for piecewise-constant inputs whose jumps fall on the grid (steps at
    multiples of the resolution from ``t0``).  Evaluations are cached: queries in increasing
    time cost one cell each.
    """
    dt = limiter.td / 10.0 if resolution is None else float(resolution)
    grid = [profile(t0) if y0 is None else float(y0)]      # y at t0 + j dt

    def at(t: float) -> float:
        if t <= t0:
            return grid[0]
        j = int((t - t0) / dt)
        while len(grid) <= j + 1:
            k = len(grid) - 1
            grid.append(limiter.advance(grid[k], profile(t0 + (k + 0.5) * dt), dt))
        tau = t - (t0 + j * dt)
        return limiter.advance(grid[j], profile(t0 + (j + 0.5) * dt), tau) if tau > 0 else grid[j]

    return at
