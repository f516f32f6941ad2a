"""Run a model over time: the ``simulate`` entry point (docs/architecture.md §3).

Inputs are held constant over each output interval (zero-order hold, like a co-simulation
communication step); output times are t_k = k·h (no accumulated drift).
"""

from __future__ import annotations

import math
import time as _time
from typing import Callable, Iterable, Union

import numpy as np

from .engine import check_engine, default_engine, engine_stepper, is_engine
from .models import make_model
from .models.base import is_finite_state
from .params import MechanismParams
from .profiles import SpeedLike, as_speed_profile
from .schedule import Schedule, input_schedule
from .steppers import StepFailure, StepStats, make_stepper
from .steppers.options import TUNED_OPTIONS, tuned_stepper_options

Signal = Union[float, Callable[[float], float]]

#: default stepper per fidelity level (used by simulate and the FMU); ``auto``'s ``default``
#: chooses explicit, exponential or linearly implicit dynamic steps from the communication
#: step, the carriers' time constant and the screw speed's sign (prsm_fmu/models/adaptive.py)
#: The dynamic level keeps ROS34PW2: the exponential stepper (exprb32) needs half its rhs calls on
#: smooth 1 ms steps, but through a zero-speed crossing (scene speed_reversal, where the band's
#: friction law is only once differentiable) it took 1117 rhs calls in one step against the
#: scene's bound of 500; it is a choice (``stepper = "exponential"``), not the default.
DEFAULT_STEPPER = {"dynamic": "rosenbrock", "quasi-static": "closed_form",
                   "kinematic": "closed_form", "auto": "default"}

#: output intervals listed and handed to the engine at a time: a long run's list of advances
#: stays small (~10 MB) beside its outputs, and one call per 65536 intervals costs nothing
SCHEDULE_BLOCK = 65536


def _signal(value: Signal, name: str) -> Callable[[float], float]:
    if callable(value):
        return value
    v = float(value)
    if not math.isfinite(v):
        raise ValueError(f"{name} = {value!r} is out of range: must be finite")
    return lambda t: v


def simulate(params: MechanismParams, fidelity: str = "dynamic", drive: str = "torque", *,
             screw_torque: Signal = 0.0, screw_speed: SpeedLike = 0.0, load_force: Signal = 0.0,
             t_end: float, output_interval: float, stepper: str | None = None,
             rtol: float = 1e-8, atol: float = 1e-10, initial_screw_speed: float = 0.0,
             initial_carrier_ratio: float | None = 0.0, model_options: dict | None = None,
             stepper_options: dict | None = None,
             engine: str | None = None) -> dict[str, np.ndarray]:
    """Simulate the mechanism and return its outputs on a regular time grid.

    Parameters
    ----------
    params : MechanismParams
        The mechanism (e.g. ``presets.load("li2021_two_stage")``).
    fidelity : {"kinematic", "quasi-static", "dynamic", "auto"}
        Model level.  ``auto`` chooses once per run, at its start, the cheapest level whose
        estimated model error is ≤ ``rtol`` (operating point: the inputs at t = 0, the initial
        screw speed and carrier ratio; the communication step is ``output_interval``;
        :func:`prsm_fmu.models.auto.choose_for_start`, docs/accuracy.md §4).  The result's
        ``fidelity`` says which; the default stepper is that level's.
    drive : {"torque", "speed"}
        ``torque``: ``screw_torque`` [N·m] drives screw 1 and the screw speed is a state;
        ``speed``: ``screw_speed`` [rad/s] is prescribed with its acceleration, so the driven
        torques carry every inertia term (a constant is a step at t = 0 from the initial
        state; :mod:`prsm_fmu.profiles` for ramps, tables and functions).
    screw_torque, load_force : float or callable
        Inputs, constants or functions of time [s]; sampled at the start of each output
        interval and held over it.  ``load_force`` [N] acts on the last nut, positive
        resisting extension.
    screw_speed : float, callable or SpeedProfile
        Speed drive: the prescribed screw speed [rad/s]: a constant, a
        :class:`~prsm_fmu.profiles.SpeedProfile` (followed exactly where piecewise linear), or
        a function of time (followed as its piecewise-linear interpolant between output
        times).
    t_end : float
        End time [s], > 0.
    output_interval : float
        Output (and input-hold) interval h [s], > 0.
    stepper : str, optional
        ``rk4``, ``explicit_adaptive``, ``rosenbrock``, ``exponential``, ``radau`` or ``closed_form``
        (slaved-carrier levels only); default by fidelity (:data:`DEFAULT_STEPPER`).
    rtol, atol : float
        Tolerances of adaptive steppers [-], [state units].
    initial_screw_speed : float
        Torque drive: screw speed at t = 0 [rad/s] (the speed drive starts at the profile's).
    initial_carrier_ratio : float or None
        Dynamic level: carrier speeds at t = 0 as a fraction of the screw speed; ``None`` puts
        them at equilibrium.  Default 0 (carriers at rest, Li et al.'s (2021) start).
    model_options, stepper_options : dict, optional
        Passed to the model (e.g. ``efficiency``) and the stepper (e.g. ``substeps``).
    engine : {"native", "python"}, optional
        Default: :func:`prsm_fmu.engine.default_engine` (``native`` unless the environment
        variable ``PRSM_FMU_ENGINE`` says otherwise).  ``native``: the compiled engine steps
        the model where it can (:mod:`prsm_fmu.engine`: the level's engine method, e.g.
        ``closed_form`` at the quasi-static level when ``stepper`` is None; only
        ``max_substeps`` and ``fixed_substeps`` among ``stepper_options``), else the Python
        stepper;
        ``python``: the Python reference.  The result's ``engine`` says which ran and
        ``engine_fallback`` why not the engine.

    Returns
    -------
    dict
        ``time`` [s] and every output of the model as arrays, plus ``rhs_calls`` (total
        right-hand-side evaluations), ``cpu_time`` [s] of the run, ``engine`` and
        ``engine_fallback`` (above); with ``auto`` also
        ``fidelity`` (the level run) and ``auto_choice`` (:class:`~prsm_fmu.models.AutoChoice`).

    Raises
    ------
    ValueError
        For out-of-range arguments, naming them.
    prsm_fmu.steppers.StepFailure
        If a step cannot be completed; the message gives the time.
    """
    for name, v in (("t_end", t_end), ("output_interval", output_interval)):
        if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
            raise ValueError(f"{name} = {v!r} is out of range: must be a finite number > 0")
    n_steps = int(round(t_end / output_interval))
    if n_steps < 1 or abs(n_steps * output_interval - t_end) > 1e-9 * t_end:
        raise ValueError(f"t_end = {t_end!r} must be a whole multiple of output_interval = "
                         f"{output_interval!r}")
    load_signal = _signal(load_force, "load_force")
    if drive == "speed":
        profile = as_speed_profile(screw_speed)
        speed0 = profile.speed(0.0)
        first = profile.pieces(0.0, output_interval)[0]
        u0 = (first[2], load_signal(0.0))
    else:
        torque_signal = _signal(screw_torque, "screw_torque")
        speed0 = float(initial_screw_speed)
        u0 = (torque_signal(0.0), load_signal(0.0))
    mopts = dict(model_options or {})
    if fidelity == "auto":
        mopts.update(tolerance=rtol, inputs=u0, comm_step=output_interval, screw_speed=speed0,
                     carrier_ratio=initial_carrier_ratio)
    model = make_model(params, fidelity, drive, **mopts)
    fidelity = model.fidelity
    engine = default_engine() if engine is None else check_engine(engine)
    name = stepper or DEFAULT_STEPPER[fidelity]
    opts = tuned_stepper_options(name, rtol, atol)
    opts.update(stepper_options or {})
    if "fixed_substeps" in opts:
        for key in TUNED_OPTIONS.get(name, {}):
            opts.pop(key, None)
    st = why = None
    if engine == "native":
        extra = sorted(set(stepper_options or {}) - {"max_substeps", "fixed_substeps"})
        extra += sorted(set(model_options or {}) - {"efficiency"})
        if extra:
            why = f"the engine takes no option {', '.join(map(repr, extra))}"
        else:
            so = stepper_options or {}
            st, why = engine_stepper(model, fidelity, stepper or "default", rtol, atol,
                                     so.get("max_substeps", 100000), so.get("fixed_substeps"))
    if st is None:
        st = make_stepper(name, model, **opts)

    x = model.initial_state(u0, screw_speed=speed0, carrier_ratio=initial_carrier_ratio)
    names = model.output_names
    out = np.empty((n_steps + 1, len(names)))
    y = model.outputs(0.0, x, u0)
    out[0] = [y[k] for k in names]
    cpu0 = _time.process_time()

    def plans():
        """The run's advances (prsm_fmu.schedule) in blocks of SCHEDULE_BLOCK intervals."""
        for first in range(0, n_steps, SCHEDULE_BLOCK):
            yield input_schedule(min(SCHEDULE_BLOCK, n_steps - first), output_interval,
                                 load_signal, torque=None if drive == "speed" else torque_signal,
                                 profile=profile if drive == "speed" else None, first=first)

    rhs_calls = _run_in_engine(st, model, x, plans(), out) if is_engine(st) else None
    if rhs_calls is None:
        rhs_calls = _run_in_python(st, model, x, plans(), out, output_interval)
    cpu = _time.process_time() - cpu0
    res = {"time": np.arange(n_steps + 1) * output_interval}
    res.update({k: out[:, j] for j, k in enumerate(names)})
    res["rhs_calls"] = rhs_calls
    res["cpu_time"] = cpu
    res["engine"] = "native" if is_engine(st) else "python"
    res["engine_fallback"] = why
    if hasattr(model, "auto_choice"):
        res["fidelity"] = fidelity
        res["auto_choice"] = model.auto_choice
    return res


def _run_in_python(st, model, x: list[float], plans: Iterable[Schedule], out: np.ndarray,
                   output_interval: float) -> int:
    """Step through the blocks ``plans`` advance by advance from ``x``, the outputs after each
    output interval into ``out[1:]``; the rhs calls of the run."""
    names = model.output_names
    rhs_calls = 0
    row = 0
    for plan in plans:
        for start, length, u, record in zip(plan.start, plan.length, plan.u, plan.record):
            x, stats = _advance(st, model, start, x, u, length)
            rhs_calls += stats.rhs_calls
            if record:
                # outputs at the end of the interval with the inputs that were held over it
                row += 1
                y = model.outputs(row * output_interval, x, u)
                out[row] = [y[k] for k in names]
    return rhs_calls


def _run_in_engine(st, model, x: list[float], plans: Iterable[Schedule],
                   out: np.ndarray) -> int | None:
    """Step through the blocks ``plans`` in one call into the engine each
    (NativeStepper.advance_schedule), the outputs computed in C (equal to the model's bit for
    bit); the rhs calls of the run.  None (the stepper's memory reset, ``out[1:]`` to be
    filled again) where the engine cannot run the whole run: a library without the call or
    without one of the model's outputs, or an advance that fails or ends in a non-finite
    state (the Python loop then runs the run from its start and raises with the cause it
    names)."""
    names = model.output_names
    position = {name: i for i, name in enumerate(getattr(st, "output_names", ()))}
    if not hasattr(st, "advance_schedule") or any(n not in position for n in names):
        return None
    columns = [position[n] for n in names]
    rhs_calls = 0
    row = 1
    for plan in plans:
        try:
            y, x, stats, done, _ = st.advance_schedule(x, plan.start, plan.length, plan.u,
                                                       plan.record)
        except ValueError:           # a library without the call
            st.reset()
            return None
        if done < len(plan.start):
            st.reset()               # as new: the Python loop starts over
            return None
        out[row:row + len(y)] = y[:, columns]
        row += len(y)
        rhs_calls += stats.rhs_calls
    return rhs_calls


def _advance(st, model, t: float, x: list[float], u: tuple, h: float) -> tuple:
    """One advance that never fails silently: a failure or a non-finite state raises
    :class:`~prsm_fmu.steppers.StepFailure` with the time and, where the rigid contact has no
    solution, the named cause (:meth:`prsm_fmu.models.base.Model.contact_diagnosis`)."""
    try:
        x1, stats = st.advance(t, x, u, h)
    except StepFailure as exc:
        cause = model.contact_diagnosis(x, u)
        if cause is None:
            raise
        raise StepFailure(f"step from t = {t!r} s over {h!r} s refused: {cause}") from exc
    if not is_finite_state(x1):
        cause = model.contact_diagnosis(x, u) or "the stepper returned a non-finite state"
        raise StepFailure(f"step from t = {t!r} s over {h!r} s refused: {cause}")
    return x1, stats


__all__ = ["simulate", "StepStats", "DEFAULT_STEPPER", "TUNED_OPTIONS", "tuned_stepper_options"]
