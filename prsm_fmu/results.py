"""What the tools read off a run's result: the settling time of a signal and the energy balance
of a :func:`prsm_fmu.simulate` result (and, re-exported, :func:`prsm_fmu.units.unit_of`).

Shared by the ``prsm-fmu`` command line, the sweeps (:mod:`prsm_fmu.sweep`) and the paper report
(:mod:`prsm_fmu.report`), so it lives below all three.  All quantities are SI.
"""

from __future__ import annotations

import math
from typing import Mapping, Sequence

import numpy as np

from .units import unit_of

__all__ = ["SETTLING_BAND", "unit_of", "settling_time", "is_settled", "energy_balance_residual"]

#: relative band of the settling time (1 % of the final value)
SETTLING_BAND = 0.01

def settling_time(time: Sequence[float], value: Sequence[float],
                  band: float = SETTLING_BAND) -> float:
    """First time after which a signal stays within ``band`` of its final value.

    The final value is the last sample, ζ_f.  The settling time is the first t_s such that
    |ζ(t) − ζ_f| ≤ band·|ζ_f| for every sample t ≥ t_s; between the last sample outside the
    band and the next one it is interpolated linearly, so it is not quantised to the output
    grid.

    Parameters
    ----------
    time : sequence of float
        Sample times [s], increasing.
    value : sequence of float
        The signal at those times (e.g. a carrier speed ratio [-]).
    band : float
        Relative half-width of the band [-], default 0.01 (1 %).

    Returns
    -------
    float
        Settling time [s]; ``time[0]`` if the signal starts inside the band; NaN if the final
        value is 0 or not finite (the relative band is undefined).
    """
    t = np.asarray(time, dtype=float)
    z = np.asarray(value, dtype=float)
    z_f = z[-1]
    tol = band * abs(z_f)
    if not math.isfinite(z_f) or tol == 0.0:
        return math.nan
    excess = np.abs(z - z_f) - tol
    outside = np.nonzero(excess > 0.0)[0]
    if outside.size == 0:
        return float(t[0])
    i = int(outside[-1])          # < len - 1, because the last sample is inside the band
    e0, e1 = excess[i], excess[i + 1]
    frac = e0 / (e0 - e1) if e0 != e1 else 1.0
    return float(t[i] + frac * (t[i + 1] - t[i]))


def is_settled(time: Sequence[float], value: Sequence[float],
               band: float = SETTLING_BAND) -> bool:
    """Whether a signal has reached its final value within the run.

    True if it varies by at most a tenth of the settling band (0.1·band·|final value|) over
    the last 20 % of the run, so that the final sample is a fair stand-in for the steady value
    that :func:`settling_time` measures against.

    Parameters
    ----------
    time, value : sequence of float
        Sample times [s] and the signal, as for :func:`settling_time`.
    band : float
        Relative band [-].

    Returns
    -------
    bool
    """
    t = np.asarray(time, dtype=float)
    z = np.asarray(value, dtype=float)
    tail = z[t >= t[0] + 0.8 * (t[-1] - t[0])]
    if tail.size == 0 or not np.all(np.isfinite(tail)):
        return False
    return float(np.max(tail) - np.min(tail)) <= 0.1 * band * abs(z[-1])


def energy_balance_residual(res: Mapping[str, np.ndarray]) -> float:
    """Relative energy-balance residual |W_in − W_out − W_f − ΔT| / W_in at the end of a run.

    Parameters
    ----------
    res : mapping
        The result of :func:`prsm_fmu.simulate` (needs ``input_work``, ``output_work``,
        ``friction_work`` [J] and ``kinetic_energy`` [J]).

    Returns
    -------
    float
        The residual [-]; the absolute residual [J] if W_in = 0.
    """
    w_in = float(res["input_work"][-1])
    w_out = float(res["output_work"][-1])
    w_f = float(res["friction_work"][-1])
    d_t = float(res["kinetic_energy"][-1] - res["kinetic_energy"][0])
    err = abs(w_in - w_out - w_f - d_t)
    return err / abs(w_in) if w_in != 0.0 else err
