"""Tolerance tube around a baseline signal (the CSV-compare / Modelica regression style).

Value tolerance: half-width w(t) = abs + rel·|y_b(t)|.  Time tolerance: the tube at t is the
envelope of the value tubes over the window [t − Δt, t + Δt], so a signal that is merely shifted
by at most Δt in time (an event, a friction reversal, one communication step later) stays
inside it.  A run passes an output when every one of its samples, interpolated linearly onto the
baseline's times, lies inside the tube.

Undefined values: an output may be NaN where it is not defined (the efficiency where no power
flows, docs/model.md).  A baseline NaN gives no tube edge (the time tolerance still spreads its
defined neighbours' edges over it); where the tube has no edge the run is not compared, and
where it has one the run must have a finite value inside it — a NaN there fails unless the
baseline too is undefined within ±dt.

This needs numpy only, so anyone who unpacks an FMU can run it on the baselines in its
``extra/`` folder (docs/regression.md says why this is used rather than pyfunnel).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["Tolerance", "TubeResult", "tube", "compare"]


@dataclass(frozen=True)
class Tolerance:
    """Tolerances of one output: ``abs`` in the output's unit, ``rel`` [-], ``dt`` [s]."""

    abs: float
    rel: float
    dt: float


@dataclass
class TubeResult:
    """The verdict on one output.

    ``excess``: largest distance outside the tube (output unit, 0 if inside); ``t_worst``: the
    time of the largest ``excess`` (or of the smallest margin if inside); ``ratio``: largest
    |y − y_b| / (tube half-width there), > 1 means outside only where the time tolerance does
    not help either; ``n_out``: samples outside; ``first_out``: first time outside (NaN if
    none).
    """

    name: str
    passed: bool
    excess: float
    t_worst: float
    value: float
    baseline: float
    max_abs_diff: float
    n_out: int
    first_out: float
    reason: str = ""


def tube(time: np.ndarray, y: np.ndarray, tol: Tolerance) -> tuple[np.ndarray, np.ndarray]:
    """Lower and upper edge of the tube around ``y`` on ``time`` (module docstring)."""
    t = np.asarray(time, dtype=float)
    y = np.asarray(y, dtype=float)
    w = tol.abs + tol.rel * np.abs(y)
    lo0, hi0 = y - w, y + w
    lo, hi = lo0.copy(), hi0.copy()
    if tol.dt > 0.0 and t.size > 1:
        eps = 1e-9 * max(tol.dt, float(t[-1] - t[0]))
        first = np.searchsorted(t, t - tol.dt - eps, side="left")
        last = np.searchsorted(t, t + tol.dt + eps, side="right") - 1
        idx = np.arange(t.size)
        span = int(max(np.max(idx - first), np.max(last - idx)))
        for k in range(1, span + 1):
            # neighbour k samples later (i + k ≤ last[i]) and earlier (i − k ≥ first[i]);
            # fmin/fmax: a NaN (undefined) sample adds no edge
            j = idx + k
            ok = (j < t.size) & (j <= last)
            jj = np.where(ok, j, idx)
            lo = np.where(ok, np.fmin(lo, lo0[jj]), lo)
            hi = np.where(ok, np.fmax(hi, hi0[jj]), hi)
            j = idx - k
            ok = (j >= 0) & (j >= first)
            jj = np.where(ok, j, idx)
            lo = np.where(ok, np.fmin(lo, lo0[jj]), lo)
            hi = np.where(ok, np.fmax(hi, hi0[jj]), hi)
    return lo, hi


def _interp_undefined(tb: np.ndarray, tr: np.ndarray, yr: np.ndarray) -> np.ndarray:
    """The run on the baseline's times: linear between its defined samples, NaN where the run
    sample nearest in time is NaN (a NaN neighbour does not spoil the interpolation when the
    times differ by the CSV's rounding)."""
    undefined = np.isnan(yr)
    if undefined.all():
        return np.full(tb.shape, np.nan)
    yi = np.interp(tb, tr[~undefined], yr[~undefined])
    if undefined.any():
        if tr.size == 1:
            nearest = np.zeros(tb.shape, int)
        else:
            j = np.clip(np.searchsorted(tr, tb), 1, tr.size - 1)
            nearest = np.where(np.abs(tr[j - 1] - tb) <= np.abs(tr[j] - tb), j - 1, j)
        yi[undefined[nearest]] = np.nan
    return yi


def compare(name: str, t_base: np.ndarray, y_base: np.ndarray, t_run: np.ndarray,
            y_run: np.ndarray, tol: Tolerance) -> tuple[TubeResult, np.ndarray, np.ndarray,
                                                        np.ndarray]:
    """Compare a run with its baseline; returns the verdict, the run on the baseline's times and
    the tube's lower and upper edges (for the plot)."""
    tb = np.asarray(t_base, dtype=float)
    yb = np.asarray(y_base, dtype=float)
    tr = np.asarray(t_run, dtype=float)
    yr = np.asarray(y_run, dtype=float)
    lo, hi = tube(tb, yb, tol)
    span = max(1e-12, float(tb[-1] - tb[0]))
    if tr.size == 0 or tr[-1] < tb[-1] - 1e-9 * span or tr[0] > tb[0] + 1e-9 * span:
        end = float(tr[-1]) if tr.size else float("nan")
        return (TubeResult(name, False, float("inf"), end, float("nan"), float("nan"),
                           float("inf"), tb.size, end,
                           f"the run covers {tr[0] if tr.size else float('nan'):g} … {end:g} s, "
                           f"the baseline {tb[0]:g} … {tb[-1]:g} s"), np.full_like(yb, np.nan),
                lo, hi)
    yi = _interp_undefined(tb, tr, yr)
    rated = np.isfinite(lo) & np.isfinite(hi)      # the tube has edges there
    # a NaN of the run is allowed where the baseline is undefined within ±dt (nowhere if the
    # baseline is defined everywhere: no second tube then)
    undefined = np.isnan(yb)
    near_undefined = (tube(tb, undefined.astype(float), Tolerance(0.0, 0.0, tol.dt))[1] > 0.0
                      if undefined.any() else undefined)
    lost = rated & ~np.isfinite(yi) & ~near_undefined
    rated &= np.isfinite(yi)
    if lost.any():
        bad = int(np.argmax(lost))
        return (TubeResult(name, False, float("inf"), float(tb[bad]), float(yi[bad]),
                           float(yb[bad]), float("inf"), int(np.sum(lost)),
                           float(tb[bad]), "non-finite value where the baseline has one"),
                yi, lo, hi)
    with np.errstate(invalid="ignore"):
        excess = np.where(rated, np.maximum(yi - hi, lo - yi), 0.0)     # > 0 outside
        both = rated & np.isfinite(yb)
        diff = float(np.max(np.abs(yi[both] - yb[both]))) if both.any() else 0.0
    out = excess > 0.0
    i = int(np.argmax(excess))
    return (TubeResult(name, not bool(out.any()), float(max(excess[i], 0.0)), float(tb[i]),
                       float(yi[i]), float(yb[i]), diff,
                       int(out.sum()), float(tb[int(np.argmax(out))]) if out.any() else
                       float("nan")), yi, lo, hi)
