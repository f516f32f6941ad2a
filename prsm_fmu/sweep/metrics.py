"""The numbers a point's run is reduced to: one row of the result table.

A metric is named ``<signal>@<reduction>``:

* signals: ``efficiency`` (NaN at standstill, where it is undefined), ``friction_torque`` (friction power / screw speed: the torque the
  friction costs at the input shaft, N·m; NaN at standstill), ``screw_torque`` (the motor's),
  and per stage ``stage[k].carrier_speed_ratio``, ``stage[k].contact_force``,
  ``stage[k].driven_torque``, ``stage[k].spline_friction``; on the model backend also
  ``screw_friction_torque`` (the friction-torque article's M_f, the friction's generalized force on the screw
  angle: the motor torque less the load's and the slaved parts' inertial torque, N·m; it also
  carries the torque that drives the carriers through friction) and
  ``friction_power_<term>`` (coulomb, viscous, differential, joints, W);
* reductions: ``start`` (t = 0), ``end`` (t = t_end), ``min``, ``max``, ``settle`` (the first
  time after which the signal stays within 1 % of its final value, NaN if it has not settled
  within the run, see :func:`settle`), and a time in seconds (the sample nearest to it).

Besides those, ``efficiency@overall`` = W_out / W_in over the run (the friction-torque article's overall
efficiency), ``speed_error@max`` (largest |ω − ω_ref| / max|ω_ref| at the samples: 0 for the
speed-driven model, the FMU master's tracking error otherwise), ``energy_residual``
(|W_in − W_out − W_f − ΔT| / W_in at the end) and ``rhs_calls``.
"""

from __future__ import annotations

import math
from typing import Mapping, Sequence

import numpy as np

from ..results import SETTLING_BAND, energy_balance_residual, is_settled, settling_time

__all__ = ["settle", "value_at", "standard_metrics", "compute_metrics", "derive_series",
           "SERIES_KEEP", "stage_signals"]

#: global signals with their start/end metrics
GLOBAL_SIGNALS = ("efficiency", "friction_torque", "screw_torque")
#: per-stage signals (spline friction only for k ≥ 2)
STAGE_SIGNALS = ("carrier_speed_ratio", "contact_force", "driven_torque", "spline_friction")

#: series kept per point (for the figures); per-stage names use "stage[k]."
SERIES_KEEP = ("time", "screw_speed", "speed_reference", "screw_torque", "efficiency",
               "friction_power", "friction_torque", "input_work", "output_work",
               "friction_work", "kinetic_energy", "screw_friction_torque",
               "friction_power_coulomb", "friction_power_viscous",
               "friction_power_differential", "friction_power_joints")

#: below this fraction of the largest screw speed the friction torque is not defined (NaN)
STANDSTILL = 1e-6


def stage_signals(k: int) -> tuple[str, ...]:
    """The per-stage signals of stage k."""
    return tuple(f"stage[{k}].{s}" for s in STAGE_SIGNALS if k >= 2 or s != "spline_friction")


def settle(time: Sequence[float], value: Sequence[float], band: float = SETTLING_BAND) -> float:
    """Settling time [s] of a signal (band about its final value, default 1 %); NaN if not
    settled.

    Samples before the first finite one are skipped (e.g. the friction torque at standstill).
    The band and the test of having settled are :func:`prsm_fmu.results.settling_time` and
    :func:`prsm_fmu.results.is_settled` (shared with ``prsm-fmu startup`` and the paper report).
    """
    t = np.asarray(time, dtype=float)
    z = np.asarray(value, dtype=float)
    finite = np.nonzero(np.isfinite(z))[0]
    if finite.size < 2:
        return math.nan
    t, z = t[finite[0]:], z[finite[0]:]
    if not np.all(np.isfinite(z)) or not is_settled(t, z, band):
        return math.nan
    return settling_time(t, z, band)


def value_at(res: Mapping[str, np.ndarray], name: str, t: float) -> float:
    """Value of a series at the sample nearest to time t [s]."""
    i = int(np.argmin(np.abs(np.asarray(res["time"]) - t)))
    return float(res[name][i])


def derive_series(res: Mapping[str, np.ndarray], n_stages: int) -> dict[str, np.ndarray]:
    """The series a point keeps, from a run of the model or of the FMU (same output names).

    Adds ``screw_torque`` (= ``stage[1].driven_torque``, the FMU has no output of that name),
    ``friction_torque`` and ``speed_reference`` (the screw speed itself where none was given).
    """
    out: dict[str, np.ndarray] = {}
    w = np.asarray(res["screw_speed"], dtype=float)
    for name in SERIES_KEEP:
        if name in res:
            out[name] = np.asarray(res[name], dtype=float)
    out["screw_torque"] = np.asarray(res["stage[1].driven_torque"], dtype=float)
    out.setdefault("speed_reference", w.copy())
    wmax = float(np.max(np.abs(w))) if w.size else 0.0
    moving = np.abs(w) > STANDSTILL * wmax if wmax > 0 else np.zeros(w.shape, bool)
    with np.errstate(divide="ignore", invalid="ignore"):
        out["friction_torque"] = np.where(moving, out["friction_power"] / np.where(moving, w, 1.0),
                                          np.nan)
    # the efficiency is undefined where no power passes through (the models report NaN
    # there); below STANDSTILL of the largest speed it is not rated either
    out["efficiency"] = np.where(moving, out["efficiency"], np.nan)
    for k in range(1, n_stages + 1):
        for s in STAGE_SIGNALS:
            name = f"stage[{k}].{s}"
            out[name] = np.asarray(res[name], dtype=float)
    return out


def standard_metrics(n_stages: int, sample_times: Sequence[float] = ()) -> tuple[str, ...]:
    """The metric columns of a study whose points have at most ``n_stages`` stages."""
    signals = list(GLOBAL_SIGNALS)
    for k in range(1, n_stages + 1):
        signals += stage_signals(k)
    names = []
    for s in signals:
        names += [f"{s}@start", f"{s}@end"]
        names += [f"{s}@{t:g}" for t in sample_times]
    names += ["efficiency@min", "efficiency@overall", "friction_torque@max",
              "friction_torque@settle", "screw_torque@max"]
    names += [f"stage[{k}].carrier_speed_ratio@settle" for k in range(1, n_stages + 1)]
    names += [f"stage[{k}].contact_force@max" for k in range(1, n_stages + 1)]
    names += ["speed_error@max", "energy_residual", "rhs_calls"]
    return tuple(names)


def _reduce(series: Mapping[str, np.ndarray], signal: str, how: str) -> float:
    if signal not in series:
        return math.nan
    y = np.asarray(series[signal], dtype=float)
    t = np.asarray(series["time"], dtype=float)
    if how == "start":
        return float(y[0])
    if how == "end":
        return float(y[-1])
    if how in ("min", "max"):
        # the t = 0 sample of a step start is not a dynamic state reached in the run (its
        # torque, efficiency and contact forces belong to the carriers at rest): include it
        finite = y[np.isfinite(y)]
        if finite.size == 0:
            return math.nan
        return float(finite.min() if how == "min" else finite.max())
    if how == "settle":
        return settle(t, y)
    try:
        at = float(how)
    except ValueError:
        raise ValueError(f"unknown reduction {how!r} in metric {signal}@{how}: must be start, "
                         "end, min, max, settle, overall or a time [s]") from None
    return float(y[int(np.argmin(np.abs(t - at)))])


def metric(series: Mapping[str, np.ndarray], name: str) -> float:
    """One metric of a point's series (module docstring)."""
    if name == "efficiency@overall":
        w_in = float(series["input_work"][-1])
        return float(series["output_work"][-1]) / w_in if w_in > 0 else math.nan
    if name == "speed_error@max":
        ref = np.asarray(series["speed_reference"], dtype=float)
        scale = float(np.max(np.abs(ref))) or 1.0
        return float(np.max(np.abs(np.asarray(series["screw_speed"]) - ref)) / scale)
    if name == "energy_residual":
        return energy_balance_residual(series)
    signal, sep, how = name.rpartition("@")
    if not sep:
        raise ValueError(f"metric {name!r} is not <signal>@<reduction>")
    return _reduce(series, signal, how)


def compute_metrics(series: Mapping[str, np.ndarray], names: Sequence[str],
                    rhs_calls: int) -> dict[str, float]:
    """Every metric in ``names`` (``rhs_calls`` given by the run)."""
    out = {}
    for n in names:
        out[n] = float(rhs_calls) if n == "rhs_calls" else metric(series, n)
    return out
