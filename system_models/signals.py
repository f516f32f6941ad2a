"""Time profiles that scenes describe as data: references, external forces.

A profile is a plain mapping (a TOML inline table) turned into a function of time [s]:

=============  ==============================================  =================================
kind           fields (SI)                                     value
=============  ==============================================  =================================
``constant``   ``value``                                       value
``step``       ``initial``, ``final``, ``time``, ``rise``=0    initial before ``time``; a linear
                                                               ramp of duration ``rise``; final
``sine``       ``offset``, ``amplitude``, ``frequency`` [Hz],  offset before ``start``, then
               ``start``=0, ``phase``=0 [rad]                  offset + A sin(2π f (t − start) + φ)
               ``ramp_periods``=0                              − A sin φ, the amplitude ramped
                                                               linearly over the first periods
``points``     ``time`` (increasing), ``value`` (same length)  piecewise linear, held outside
``slew``       ``input`` (a profile), ``rising`` [unit/s],     the input through a slew-rate
               ``falling`` = −rising, ``time_constant``=1e-3   limiter (system_models.slew)
=============  ==============================================  =================================

A bare number is a constant.  Every profile is continuous unless ``rise = 0`` (a true step) or
the ``points`` repeat a time (a jump).
"""

from __future__ import annotations

import bisect
import math
from typing import Any, Callable, Mapping

__all__ = ["make_profile", "PROFILE_KINDS"]

PROFILE_KINDS = ("constant", "step", "sine", "points", "slew")

Profile = Callable[[float], float]


def _num(spec: Mapping[str, Any], key: str, where: str, default: float | None = None) -> float:
    if key not in spec:
        if default is None:
            raise ValueError(f"{where}.{key} is missing")
        return default
    value = spec[key]
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ValueError(f"{where}.{key} = {value!r} is not a number")
    return float(value)


def make_profile(spec: Any, where: str = "profile") -> Profile:
    """A function of time from a profile description (module docstring).

    Parameters
    ----------
    spec : float or mapping
        The description.
    where : str
        Name of the field in the scene, for error messages.

    Returns
    -------
    callable
        ``f(t) -> float``.

    Raises
    ------
    ValueError
        Naming the field and what is wrong with it.
    """
    if isinstance(spec, (int, float)) and not isinstance(spec, bool):
        c = float(spec)
        return lambda t: c
    if not isinstance(spec, Mapping):
        raise ValueError(f"{where} = {spec!r} is neither a number nor a table with 'kind'")
    kind = spec.get("kind", "constant")
    known = {"constant": {"kind", "value"},
             "step": {"kind", "initial", "final", "time", "rise"},
             "sine": {"kind", "offset", "amplitude", "frequency", "start", "phase", "ramp_periods"},
             "points": {"kind", "time", "value"},
             "slew": {"kind", "input", "rising", "falling", "time_constant"}}
    if kind not in known:
        raise ValueError(f"{where}.kind = {kind!r} is not allowed: must be one of "
                         f"{', '.join(PROFILE_KINDS)}")
    extra = set(spec) - known[kind]
    if extra:
        raise ValueError(f"{where}: unknown field(s) {sorted(extra)} for kind {kind!r} "
                         f"(allowed: {sorted(known[kind])})")
    if kind == "slew":
        from .slew import SlewRateLimiter, slew_limited

        if "input" not in spec:
            raise ValueError(f"{where}.input is missing (the profile to limit)")
        rising = _num(spec, "rising", where)
        falling = _num(spec, "falling", where, -rising)
        limiter = SlewRateLimiter(rising, falling, _num(spec, "time_constant", where, 1e-3))
        return slew_limited(make_profile(spec["input"], f"{where}.input"), limiter)
    if kind == "constant":
        c = _num(spec, "value", where)
        return lambda t: c
    if kind == "step":
        a, b = _num(spec, "initial", where, 0.0), _num(spec, "final", where)
        t0, rise = _num(spec, "time", where), _num(spec, "rise", where, 0.0)
        if rise < 0.0:
            raise ValueError(f"{where}.rise = {rise!r} is out of range: must be >= 0")

        def step(t: float) -> float:
            if t < t0:
                return a
            if rise > 0.0 and t < t0 + rise:
                return a + (b - a) * (t - t0) / rise
            return b
        return step
    if kind == "sine":
        off, amp = _num(spec, "offset", where, 0.0), _num(spec, "amplitude", where)
        f, start = _num(spec, "frequency", where), _num(spec, "start", where, 0.0)
        phase, ramp = _num(spec, "phase", where, 0.0), _num(spec, "ramp_periods", where, 0.0)
        if f <= 0.0:
            raise ValueError(f"{where}.frequency = {f!r} is out of range: must be > 0")
        if ramp < 0.0:
            raise ValueError(f"{where}.ramp_periods = {ramp!r} is out of range: must be >= 0")
        w, s0, t_ramp = 2.0 * math.pi * f, math.sin(phase), ramp / f

        def sine(t: float) -> float:
            if t <= start:
                return off
            tau = t - start
            gain = min(1.0, tau / t_ramp) if t_ramp > 0.0 else 1.0
            return off + gain * amp * (math.sin(w * tau + phase) - s0)
        return sine
    ts, vs = spec.get("time"), spec.get("value")
    if not (isinstance(ts, list) and isinstance(vs, list) and len(ts) == len(vs) and ts):
        raise ValueError(f"{where}: 'time' and 'value' must be lists of the same, non-zero length")
    ts = [float(x) for x in ts]
    vs = [float(x) for x in vs]
    if any(b < a for a, b in zip(ts, ts[1:])):
        raise ValueError(f"{where}.time = {ts!r} must not decrease")

    def points(t: float) -> float:
        i = bisect.bisect_right(ts, t)
        if i == 0:
            return vs[0]
        if i == len(ts):
            return vs[-1]
        t0, t1 = ts[i - 1], ts[i]
        return vs[i - 1] + (vs[i] - vs[i - 1]) * (t - t0) / (t1 - t0)
    return points
