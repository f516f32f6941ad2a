"""What a run shows: step-response figures, tracking errors, power bookkeeping, chatter.

Each scene lists its requirements as ``[[check]]`` tables; :func:`evaluate` runs them on a
:class:`~system_models.master.Result` and returns :class:`CheckResult` objects that print as
one line each (measured value, the scene's limit, PASS/FAIL).

Check kinds (fields in SI; ``signal`` is a recorded output ``"block.port"``):

``step_response``   ``initial``, ``target``, ``time`` (of the step), ``band`` (relative, default
                    0.02), ``overshoot_max`` (fraction of the step), ``settling_time_max`` [s
                    after the step], ``final_error_max`` (absolute, at the end).
``tracking``        ``after`` [s], ``max_error`` and optional ``rms_error_max``: signal against
                    the scene's reference profile at the same times.
``disturbance``     ``time`` (onset), ``target``, ``deviation_max``, ``recovery_band``,
                    ``recovery_time_max`` [s after onset].
``final_value``     ``target`` (a number, or ``"steady_state"``: the value of the same output in
                    :func:`prsm_fmu.steady_state` at the final screw speed and load force, an
                    independent solver), ``rtol``, ``atol``, optional ``window`` [s] to average.
``range``           ``min``, ``max``, optional ``after`` [s].
``zero_crossings``  ``count``: sign changes of the signal (excluding exact zeros).
``no_chatter``      ``signals`` (list), ``max_direction_changes``: local extrema of each signal
                    larger than ``noise`` (relative to its range, default 1e-3), and no
                    step-to-step alternation (:func:`zigzags`); optional ``from``/``to`` [s].
``step_work``       ``max_rhs_calls_per_step``, ``max_total_rhs_calls``: the PRSM's work.
``energy_balance``  ``max_relative``: |residual| / electrical input (see :func:`energy_balance`).
``kinematics``      ``max_relative``: rod position against Σ L_k θ_S / 2π (docs/model.md).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Callable

import numpy as np

from prsm_fmu.kinematics import rod_displacement
from prsm_fmu.models.base import undefined_allowed

from .master import Result

__all__ = ["CheckResult", "evaluate", "validate_check", "CHECK_FIELDS", "energy_balance",
           "step_metrics", "direction_changes", "zigzags", "zero_crossings", "CHECKS"]


@dataclass
class CheckResult:
    """One requirement: what was measured, against which limit, whether it holds."""

    kind: str
    signal: str
    passed: bool
    measured: dict[str, float] = field(default_factory=dict)
    limits: dict[str, float] = field(default_factory=dict)
    text: str = ""

    def line(self) -> str:
        return f"[{'PASS' if self.passed else 'FAIL'}] {self.kind} {self.signal}: {self.text}"


# ---- figures -------------------------------------------------------------------------------
def step_metrics(time: np.ndarray, y: np.ndarray, initial: float, target: float, t_step: float,
                 band: float = 0.02) -> dict[str, float]:
    """Overshoot, settling and rise time and final error of a step response.

    Overshoot: the largest excursion beyond the target after the step, as a fraction of the
    step (target − initial), 0 if none.  Settling time: from the step to the first sample after
    which |y − target| ≤ band·|target − initial| holds to the end (NaN if it never does).  Rise
    time: 10 % to 90 % of the step.  Final error: |y(end) − target|.
    """
    t = np.asarray(time, float)
    y = np.asarray(y, float)
    d = target - initial
    after = t >= t_step
    ya, ta = y[after], t[after]
    sign = 1.0 if d >= 0 else -1.0
    over = max(0.0, float(np.max(sign * (ya - target)))) / abs(d) if d else 0.0
    outside = np.nonzero(np.abs(ya - target) > band * abs(d))[0]
    if outside.size == 0:
        settle = 0.0
    elif outside[-1] == ya.size - 1:
        settle = math.nan
    else:
        settle = float(ta[outside[-1] + 1] - t_step)
    frac = sign * (ya - initial) / abs(d) if d else np.zeros_like(ya)
    i10 = np.nonzero(frac >= 0.1)[0]
    i90 = np.nonzero(frac >= 0.9)[0]
    rise = float(ta[i90[0]] - ta[i10[0]]) if i10.size and i90.size else math.nan
    return {"overshoot": over, "settling_time": settle, "rise_time": rise,
            "final_error": float(abs(y[-1] - target)), "peak": float(ya[np.argmax(sign * ya)])}


def zero_crossings(y: np.ndarray) -> int:
    """Sign changes of a signal, exact zeros skipped."""
    s = np.sign(np.asarray(y, float))
    s = s[s != 0]
    return int(np.count_nonzero(s[1:] != s[:-1]))


def direction_changes(y: np.ndarray, noise: float = 1e-3) -> int:
    """Direction reversals of a signal, counted with hysteresis: a reversal is a retreat from
    the running extremum by more than ``noise`` × the signal's range (so a monotonic signal
    gives 0, one hump 1, and a signal that chatters between two values many)."""
    y = np.asarray(y, float)
    if y.size < 3:
        return 0
    thr = noise * float(np.max(y) - np.min(y))
    if thr == 0.0:
        return 0
    count, direction = 0, 0
    lo = hi = ext = float(y[0])
    for v in y[1:]:
        v = float(v)
        if direction == 0:
            lo, hi = min(lo, v), max(hi, v)
            if v - lo > thr:
                direction, ext = 1, v
            elif hi - v > thr:
                direction, ext = -1, v
        elif direction == 1:
            if v > ext:
                ext = v
            elif ext - v > thr:
                count, direction, ext = count + 1, -1, v
        else:
            if v < ext:
                ext = v
            elif v - ext > thr:
                count, direction, ext = count + 1, 1, v
    return count


def zigzags(y: np.ndarray, rel: float = 1e-6) -> int:
    """Step-to-step alternations of a signal: samples k where four consecutive differences
    y[k+1] − y[k], …, y[k+4] − y[k+3] alternate in sign (each larger than ``rel`` × the range),
    the period-two oscillation of a force that chatters at the communication step.  A single
    jump in a monotonic trend (a friction force reversing) gives three alternating
    differences and is not counted."""
    y = np.asarray(y, float)
    if y.size < 5:
        return 0
    d = np.diff(y)
    thr = rel * float(np.max(y) - np.min(y))
    sg = np.where(np.abs(d) > thr, np.sign(d), 0.0)
    alt = sg[:-1] * sg[1:] < 0
    return int(np.count_nonzero(alt[:-2] & alt[1:-1] & alt[2:]))


def energy_balance(res: Result) -> dict[str, float]:
    """Power bookkeeping of a run, integrated: every term [J] and the residuals.

    Electrical input = copper losses + friction work + load work + Δ(magnetic + kinetic energy):

    * E_el, E_cu: the motor's integrals of 1.5 (v_d i_d + v_q i_q) and 1.5 R |i|²;
    * W_f, W_load: the PRSM's friction work and the work done on the load force (spring,
      damper and external force, the load mass being part of the PRSM's kinetic energy);
    * ΔE_mag = Δ 0.75 L |i|², ΔE_kin: the PRSM's kinetic energy (rotor and load mass included).

    The residual splits exactly into the motor's own balance (E_el − E_cu − ΔE_mag − W_airgap,
    its integrator's error), the PRSM's own balance (W_in − W_load − W_f − ΔE_kin, its
    stepper's), and the coupling term W_airgap − W_in: the air-gap work the motor computes with
    its extrapolated view of the speed against the work the PRSM receives from the torque held
    over each step — the co-simulation's error, which vanishes as h → 0.
    """
    def end(name):
        return float(res[name][-1])

    def delta(name):
        return float(res[name][-1] - res[name][0])

    e_el, e_cu = end("motor.electrical_energy"), end("motor.copper_energy")
    d_mag, w_ag = delta("motor.magnetic_energy"), end("motor.airgap_energy")
    w_in, w_load = end("prsm.input_work"), end("prsm.output_work")
    w_f, d_kin = end("prsm.friction_work"), delta("prsm.kinetic_energy")
    residual = e_el - e_cu - w_f - w_load - d_mag - d_kin
    scale = max(abs(e_el), e_cu + w_f + abs(w_load) + abs(d_mag) + abs(d_kin), 1e-300)
    out = {"electrical_input": e_el, "copper_losses": e_cu, "friction_work": w_f,
           "load_work": w_load, "delta_magnetic_energy": d_mag, "delta_kinetic_energy": d_kin,
           "residual": residual, "relative_residual": residual / scale, "scale": scale,
           "motor_residual": e_el - e_cu - d_mag - w_ag,
           "prsm_residual": w_in - w_load - w_f - d_kin,
           "coupling_residual": w_ag - w_in}
    if "load.spring_energy" in res:
        out["load_spring_energy_change"] = delta("load.spring_energy")
    return out


# ---- checks ----------------------------------------------------------------------------------
def _fmt(v: float, unit: str = "") -> str:
    if isinstance(v, float) and math.isnan(v):
        return "nan"
    return f"{v:.4g}{(' ' + unit) if unit else ''}"


def _series(res: Result, name: str) -> np.ndarray:
    if name not in res:
        raise ValueError(f"check: no recorded output {name!r}")
    return np.asarray(res[name], float)


def _check_step(res, c, ctx):
    sig = c.get("signal", "prsm.rod_position")
    m = step_metrics(res.time, _series(res, sig), float(c.get("initial", 0.0)), float(c["target"]),
                     float(c["time"]), float(c.get("band", 0.02)))
    lim = {k: float(c[k]) for k in ("overshoot_max", "settling_time_max", "final_error_max") if k in c}
    ok = all([m["overshoot"] <= lim.get("overshoot_max", math.inf),
              m["settling_time"] <= lim.get("settling_time_max", math.inf),
              m["final_error"] <= lim.get("final_error_max", math.inf)])
    unit = res.units.get(sig, "")
    text = (f"overshoot {100 * m['overshoot']:.3g} % (≤ {100 * lim.get('overshoot_max', math.inf):.3g} %), "
            f"settling time ({100 * float(c.get('band', 0.02)):.3g} % band) {_fmt(1e3 * m['settling_time'])} ms "
            f"(≤ {_fmt(1e3 * lim.get('settling_time_max', math.inf))} ms), rise time "
            f"{_fmt(1e3 * m['rise_time'])} ms, final error {_fmt(m['final_error'], unit)} "
            f"(≤ {_fmt(lim.get('final_error_max', math.inf), unit)})")
    return CheckResult("step_response", sig, ok, m, lim, text)


def _check_tracking(res, c, ctx):
    sig = c.get("signal", "prsm.rod_position")
    ref = ctx["reference"]
    t = res.time
    sel = t >= float(c.get("after", 0.0))
    if not np.any(sel):          # a run cut before the window (e.g. a shortened scene)
        return CheckResult("tracking", sig, False, {}, {},
                           f"not evaluated: the run ends at t = {t[-1]:g} s, before the "
                           f"window after t = {c.get('after', 0.0)} s")
    e = _series(res, sig)[sel] - np.array([ref(x) for x in t[sel]])
    m = {"max_error": float(np.max(np.abs(e))), "rms_error": float(np.sqrt(np.mean(e * e)))}
    lim = {k: float(c[k]) for k in ("max_error", "rms_error_max") if k in c}
    ok = m["max_error"] <= lim.get("max_error", math.inf) and \
        m["rms_error"] <= lim.get("rms_error_max", math.inf)
    unit = res.units.get(sig, "")
    return CheckResult("tracking", sig, ok, m, lim,
                       f"after t = {c.get('after', 0.0)} s: max error {_fmt(m['max_error'], unit)} "
                       f"(≤ {_fmt(lim.get('max_error', math.inf), unit)}), rms "
                       f"{_fmt(m['rms_error'], unit)}")


def _check_disturbance(res, c, ctx):
    sig = c.get("signal", "prsm.rod_position")
    t, y = res.time, _series(res, sig)
    t1, target = float(c["time"]), float(c.get("target", 0.0))
    sel = t >= t1
    dev = np.abs(y[sel] - target)
    band = float(c.get("recovery_band", 0.0))
    outside = np.nonzero(dev > band)[0]
    if outside.size == 0:
        rec = 0.0
    elif outside[-1] == dev.size - 1:
        rec = math.nan
    else:
        rec = float(t[sel][outside[-1] + 1] - t1)
    m = {"max_deviation": float(np.max(dev)), "recovery_time": rec,
         "final_deviation": float(dev[-1])}
    lim = {k: float(c[k]) for k in ("deviation_max", "recovery_time_max") if k in c}
    ok = m["max_deviation"] <= lim.get("deviation_max", math.inf) and \
        rec <= lim.get("recovery_time_max", math.inf)
    unit = res.units.get(sig, "")
    return CheckResult("disturbance", sig, ok, m, lim,
                       f"max deviation {_fmt(m['max_deviation'], unit)} (≤ "
                       f"{_fmt(lim.get('deviation_max', math.inf), unit)}), back within "
                       f"{_fmt(band, unit)} after {_fmt(1e3 * rec)} ms (≤ "
                       f"{_fmt(1e3 * lim.get('recovery_time_max', math.inf))} ms)")


def _check_final(res, c, ctx):
    sig = c["signal"]
    t, y = res.time, _series(res, sig)
    window = float(c.get("window", 0.0))
    value = float(np.mean(y[t >= t[-1] - window])) if window > 0 else float(y[-1])
    target = c["target"]
    source = "scene"
    if target == "steady_state":
        from prsm_fmu import steady_state

        port = sig.split(".", 1)[1]
        speed = float(res["prsm.screw_speed"][-1])
        load = float(res["load.force"][-1])
        ss = steady_state(ctx["params"], screw_speed=speed, load_force=load)
        if port not in ss:
            raise ValueError(f"check final_value: prsm_fmu.steady_state has no output {port!r}")
        target = float(ss[port])
        source = f"steady_state at {speed:.4g} rad/s, {load:.4g} N"
    target = float(target)
    rtol, atol = float(c.get("rtol", 0.0)), float(c.get("atol", 0.0))
    err = abs(value - target)
    ok = err <= atol + rtol * abs(target)
    m = {"value": value, "target": target, "error": err}
    return CheckResult("final_value", sig, ok, m, {"rtol": rtol, "atol": atol},
                       f"{_fmt(value)} vs {_fmt(target)} ({source}): error {_fmt(err)} "
                       f"(≤ {_fmt(atol + rtol * abs(target))})")


def _check_range(res, c, ctx):
    sig = c["signal"]
    t, y = res.time, _series(res, sig)
    y = y[t >= float(c.get("after", -math.inf))]
    lo, hi = float(c.get("min", -math.inf)), float(c.get("max", math.inf))
    m = {"min": float(np.min(y)), "max": float(np.max(y))}
    ok = bool(np.all(np.isfinite(y))) and m["min"] >= lo and m["max"] <= hi
    unit = res.units.get(sig, "")
    return CheckResult("range", sig, ok, m, {"min": lo, "max": hi},
                       f"[{_fmt(m['min'])}, {_fmt(m['max'])}] {unit} within [{_fmt(lo)}, {_fmt(hi)}]")


def _check_crossings(res, c, ctx):
    sig = c["signal"]
    n = zero_crossings(_series(res, sig))
    ok = n == int(c["count"])
    return CheckResult("zero_crossings", sig, ok, {"count": n}, {"count": int(c["count"])},
                       f"{n} sign change(s) (required {int(c['count'])})")


def _check_chatter(res, c, ctx):
    t = res.time
    sel = (t >= float(c.get("from", -math.inf))) & (t <= float(c.get("to", math.inf)))
    noise = float(c.get("noise", 1e-3))
    limit = int(c["max_direction_changes"])
    counts = {s: direction_changes(_series(res, s)[sel], noise) for s in c["signals"]}
    zz = {s: zigzags(_series(res, s)[sel]) for s in c["signals"]}
    finite = all(bool(np.all(np.isfinite(_series(res, s)))) for s in c["signals"])
    ok = finite and max(counts.values()) <= limit and max(zz.values()) == 0
    worst = max(counts, key=counts.get)
    return CheckResult("no_chatter", f"{len(counts)} force outputs", ok,
                       {"max_direction_changes": float(counts[worst]),
                        "zigzags": float(max(zz.values()))}, {"max": limit, "zigzags": 0},
                       f"at most {counts[worst]} direction change(s) larger than {noise:g} of the "
                       f"range ({worst}; limit {limit}), {max(zz.values())} step-to-step "
                       f"alternations (limit 0), all finite: {finite}")


def _check_work(res, c, ctx):
    calls = _series(res, "prsm.step_rhs_calls")[1:]
    m = {"max_rhs_calls_per_step": float(np.max(calls)), "total_rhs_calls": float(np.sum(calls)),
         "macro_steps": float(res.stats.get("macro_steps", len(calls))),
         "retries": float(res.stats.get("retries", 0))}
    lim = {k: float(c[k]) for k in ("max_rhs_calls_per_step", "max_total_rhs_calls") if k in c}
    ok = bool(np.all(np.isfinite(calls))) and \
        m["max_rhs_calls_per_step"] <= lim.get("max_rhs_calls_per_step", math.inf) and \
        m["total_rhs_calls"] <= lim.get("max_total_rhs_calls", math.inf)
    return CheckResult("step_work", "prsm", ok, m, lim,
                       f"{int(m['macro_steps'])} macro steps, {int(m['retries'])} retries, "
                       f"PRSM rhs calls: at most {int(m['max_rhs_calls_per_step'])} per step "
                       f"(≤ {_fmt(lim.get('max_rhs_calls_per_step', math.inf))}), "
                       f"{int(m['total_rhs_calls'])} in all")


def _check_energy(res, c, ctx):
    e = energy_balance(res)
    lim = float(c["max_relative"])
    ok = abs(e["relative_residual"]) <= lim
    return CheckResult("energy_balance", "", ok, e, {"max_relative": lim},
                       f"electrical input {_fmt(e['electrical_input'], 'J')} = copper "
                       f"{_fmt(e['copper_losses'], 'J')} + friction {_fmt(e['friction_work'], 'J')} "
                       f"+ load {_fmt(e['load_work'], 'J')} + Δstored "
                       f"{_fmt(e['delta_magnetic_energy'] + e['delta_kinetic_energy'], 'J')}; "
                       f"residual {_fmt(e['residual'], 'J')} = {_fmt(e['relative_residual'])} "
                       f"relative (≤ {_fmt(lim)}; coupling {_fmt(e['coupling_residual'], 'J')}, "
                       f"motor {_fmt(e['motor_residual'], 'J')}, PRSM {_fmt(e['prsm_residual'], 'J')})")


def _check_kinematics(res, c, ctx):
    x = _series(res, "prsm.rod_position")
    pred = np.array([rod_displacement(ctx["params"], a) for a in _series(res, "prsm.screw_angle")])
    scale = max(float(np.max(np.abs(pred))), 1e-300)
    err = float(np.max(np.abs(x - pred))) / scale
    lim = float(c.get("max_relative", 1e-9))
    return CheckResult("kinematics", "prsm.rod_position", err <= lim, {"relative_error": err},
                       {"max_relative": lim},
                       f"rod position vs Σ L_k θ_S / 2π: {_fmt(err)} relative (≤ {_fmt(lim)})")


CHECKS: dict[str, Callable[[Result, dict, dict], CheckResult]] = {
    "step_response": _check_step, "tracking": _check_tracking, "disturbance": _check_disturbance,
    "final_value": _check_final, "range": _check_range, "zero_crossings": _check_crossings,
    "no_chatter": _check_chatter, "step_work": _check_work, "energy_balance": _check_energy,
    "kinematics": _check_kinematics,
}


#: fields each check kind accepts (besides ``kind``)
CHECK_FIELDS: dict[str, set[str]] = {
    "step_response": {"signal", "initial", "target", "time", "band", "overshoot_max",
                      "settling_time_max", "final_error_max"},
    "tracking": {"signal", "after", "max_error", "rms_error_max"},
    "disturbance": {"signal", "time", "target", "deviation_max", "recovery_band",
                    "recovery_time_max"},
    "final_value": {"signal", "target", "rtol", "atol", "window"},
    "range": {"signal", "min", "max", "after"},
    "zero_crossings": {"signal", "count"},
    "no_chatter": {"signals", "max_direction_changes", "noise", "from", "to"},
    "step_work": {"max_rhs_calls_per_step", "max_total_rhs_calls"},
    "energy_balance": {"max_relative"},
    "kinematics": {"max_relative"},
}
_REQUIRED = {"step_response": {"target", "time"}, "final_value": {"signal", "target"},
             "range": {"signal"}, "zero_crossings": {"signal", "count"},
             "no_chatter": {"signals", "max_direction_changes"}, "energy_balance": {"max_relative"},
             "disturbance": {"time"}}


def validate_check(c: dict[str, Any], where: str = "check") -> None:
    """ValueError naming the check and the field if a ``[[check]]`` table is not valid."""
    kind = c.get("kind")
    if kind not in CHECKS:
        raise ValueError(f"{where}: kind = {kind!r} is not known: must be one of {', '.join(CHECKS)}")
    extra = set(c) - CHECK_FIELDS[kind] - {"kind"}
    if extra:
        raise ValueError(f"{where} ({kind}): unknown field(s) {sorted(extra)} (allowed: "
                         f"{sorted(CHECK_FIELDS[kind])})")
    missing = _REQUIRED.get(kind, set()) - set(c)
    if missing:
        raise ValueError(f"{where} ({kind}): missing field(s) {sorted(missing)}")


def evaluate(res: Result, checks: list[dict[str, Any]], context: dict[str, Any]) -> list[CheckResult]:
    """Run the scene's checks.  ``context``: ``reference`` (the profile), ``params`` (the PRSM's
    MechanismParams as simulated).  Every run is also checked for non-finite outputs."""
    out = []
    # NaN is allowed where an output is undefined: the efficiency where no power flows
    bad = []
    for n in res.names():
        a = np.asarray(res[n], dtype=float)
        ok = np.isfinite(a) | np.isnan(a) if undefined_allowed(n, math.nan) else np.isfinite(a)
        if not ok.all():
            bad.append(n)
    out.append(CheckResult("finite", "all outputs", not bad, {"non_finite": float(len(bad))}, {},
                           "every output finite (the efficiency NaN where no power flows)"
                           if not bad else f"non-finite: {', '.join(bad[:5])}"))
    for c in checks:
        validate_check(c)
        out.append(CHECKS[c["kind"]](res, c, context))
    return out
