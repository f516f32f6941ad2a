"""Cost of advancing the torque-driven two-stage machine across 1 ms steps, against restarted Radau.

Scenarios: Li et al.'s (2021) two-stage PRSM, torque drive, starting at 100 rad/s with the carriers at
equilibrium; the motor torque and the load change every 1 ms step, as they do inside a closed
loop, over 100 steps; the load is F(t) = 5000 + 1000 sin(2π·25 t) N and the motor torque

* ``moving`` (the figure of merit): M(t) = 19.75 F(t)/5000 + 1.0 sin(2π·40 t) N·m, the steady
  torque of the load plus a ripple; the screw keeps turning (≈ 100…116 rad/s);
* ``stop-and-go``: M(t) = 20 + 4 sin(2π·40 t) N·m, open loop (reported, not the figure of
  merit).  Meant to stall the screw at zero speed, in the self-holding band where the
  regularised friction is stiff for every level; with the Li et al. (2021) inertias it does not: the
  screw swings between ≈ 22 and 185 rad/s without stopping, so this scenario does not reach
  the friction band.

For each fidelity level, each stepper advances the same steps with the same held inputs from
the same reference state (so errors do not accumulate from step to step and every step is the
same task for every method); a stepper keeps its memory (step-size proposal) from one step to
the next, as it does inside the FMU. The baseline is ``scipy.integrate.solve_ivp(method="Radau")``
restarted on each step at rtol 1e-6. Error (docs/accuracy.md §1): max over steps and outputs of
|y − y_ref| / max|y_ref| over the FMU's outputs (docs/fmu.md, "Variables"), against Radau at rtol 1e-12 on
the same level. Cost: CPU seconds per
step and rhs calls per step. Ratios are measured in this run, on this machine.

Run: ``python benchmarks/step_cost.py`` (about 30 s).
"""

from __future__ import annotations

import math
import time

from prsm_fmu import presets
from prsm_fmu.models import make_model
from prsm_fmu.steppers import StepFailure, make_stepper

H = 1e-3
N_STEPS = 100
#: the FMU's outputs (docs/fmu.md, "Variables") for two stages: the error is taken over all of them
OUTPUTS = ("screw_speed", "screw_angle", "rod_position", "rod_velocity", "efficiency", "friction_power") + tuple(
    f"stage[{k}].{q}" for k in (1, 2)
    for q in ("contact_force", "driven_torque", "spline_friction", "carrier_speed_ratio"))


def load(t: float) -> float:
    """Load force [N] held over the step starting at t [s]."""
    return 5000.0 + 1000.0 * math.sin(2 * math.pi * 25 * t)


SCENARIOS = {
    "moving": lambda t: (19.75 * load(t) / 5000.0 + 1.0 * math.sin(2 * math.pi * 40 * t), load(t)),
    "stop-and-go": lambda t: (20.0 + 4.0 * math.sin(2 * math.pi * 40 * t), load(t)),
}
inputs = SCENARIOS["moving"]


def reference(model):
    """States at every step start and end, from Radau at rtol 1e-12 [SI]."""
    st = make_stepper("radau", model, rtol=1e-12, atol=1e-14)
    x = model.initial_state(inputs(0.0), screw_speed=100.0, carrier_ratio=None)
    starts, ends = [], []
    for i in range(N_STEPS):
        t = i * H
        starts.append(x)
        x, _ = st.advance(t, x, inputs(t), H)
        ends.append(x)
    return starts, ends


def measure(model, name, opts, starts, ends):
    """(CPU s per step, rhs calls per step, error) of one stepper over the reference's steps;
    None when a step fails (the failure is printed)."""
    if opts.get("jacobian") == "analytic":
        # the dynamic level's analytic Jacobian (not picked up by default: models/dynamic.py)
        model = make_model(model.params, model.fidelity, model.drive)
        model.jacobian = model.analytic_jacobian
    st = make_stepper(name, model, **opts)
    results = []
    rhs = 0
    cpu0 = time.process_time()
    try:
        for i in range(N_STEPS):
            x, stats = st.advance(i * H, starts[i], inputs(i * H), H)
            results.append(x)
            rhs += stats.rhs_calls
    except StepFailure as exc:
        print(f"{'':13s} {name:28s} failed: {str(exc)[:90]}")
        return None
    cpu = (time.process_time() - cpu0) / N_STEPS
    err = 0.0
    ys = [model.outputs((i + 1) * H, results[i], inputs(i * H)) for i in range(N_STEPS)]
    yr = [model.outputs((i + 1) * H, ends[i], inputs(i * H)) for i in range(N_STEPS)]
    for name_out in OUTPUTS:
        scale = max(abs(y[name_out]) for y in yr) or 1.0
        err = max(err, max(abs(a[name_out] - b[name_out]) for a, b in zip(ys, yr)) / scale)
    return cpu, rhs / N_STEPS, err


def main() -> None:
    """Print the cost and error tables and the ratios against restarted Radau."""
    global inputs
    for scenario, fn in SCENARIOS.items():
        inputs = fn
        print(f"\n== scenario: {scenario} ==")
        table()


def table() -> None:
    """One table: every level and stepper on the current scenario."""
    params = presets.load("li2021_two_stage")
    configs = {
        "dynamic": [("rosenbrock", {"rtol": 1e-6, "atol": 1e-9}),

                    ("rosenbrock", {"rtol": 3e-6, "atol": 3e-9}),
                    # the Jacobian re-used within an advance while h·‖J‖·drift ≤ 0.1, and
                    # each advance's first step bounded to h·‖J‖ ≤ 8 (steppers.Rosenbrock)
                    ("rosenbrock", {"rtol": 2e-5, "atol": 2e-8, "jacobian_reuse": 0.1,
                                    "first_step_stiffness": 8.0}),
                    # the FMU's options (rtol 1e-6) with forward differences and with the
                    # recursion's analytic Jacobian (fewer rhs calls, more CPU in Python)
                    ("rosenbrock", {"rtol": 1e-6, "atol": 1e-8, "jacobian_reuse": 0.1,
                                    "first_step_stiffness": 8.0, "jacobian": "fd"}),
                    ("rosenbrock", {"rtol": 1e-6, "atol": 1e-8, "jacobian_reuse": 0.1,
                                    "first_step_stiffness": 8.0, "jacobian": "analytic"}),
                    ("rosenbrock", {"rtol": 1e-5, "atol": 1e-8}),
                    # exponential Rosenbrock exprb32: at the FMU's tolerance 1e-6 it runs at a
                    # tenth of it (steppers.options.TOLERANCE_FACTOR), and at the full one
                    ("exponential", {"rtol": 1e-7, "atol": 1e-9}),
                    ("exponential", {"rtol": 1e-6, "atol": 1e-8}),
                    ("explicit_adaptive", {"rtol": 1e-6, "atol": 1e-9})],
        "quasi-static": [("closed_form", {"rtol": 1e-6, "atol": 1e-9}),
                         # the former band path: Dormand-Prince 5(4) where the closed form
                         # declines (the default is the exponential Rosenbrock exprb32)
                         ("closed_form", {"rtol": 1e-6, "atol": 1e-9, "band": "explicit"}),
                         ("explicit_adaptive", {"rtol": 1e-6, "atol": 1e-9, "order": 3}),
                         ("rk4", {"substeps": 1})],
    }
    print(f"{'level':13s} {'stepper':28s} {'CPU/step':>10s} {'rhs/step':>9s} {'error':>9s} {'speed-up':>9s}")
    for fidelity, candidates in configs.items():
        model = make_model(params, fidelity, "torque")
        starts, ends = reference(model)
        base_cpu, base_rhs, base_err = measure(model, "radau", {"rtol": 1e-6, "atol": 1e-9}, starts, ends)
        # the figure of merit: the cheapest configuration at equal or smaller error
        print(f"{fidelity:13s} {'radau (baseline, restarted)':28s} {base_cpu * 1e6:8.1f}µs {base_rhs:9.1f} {base_err:9.1e} {1.0:9.1f}")
        for name, opts in candidates:
            got = measure(model, name, opts, starts, ends)
            if got is None:
                continue
            cpu, rhs, err = got
            label = name + (f" order {opts['order']}" if "order" in opts else "")
            label += f" rtol {opts['rtol']:g}" if "rtol" in opts and name != "closed_form" else ""
            label += "".join(f" {k}={opts[k]:g}" for k in ("jacobian_reuse", "first_step_stiffness") if k in opts)
            label += f" J {opts['jacobian']}" if "jacobian" in opts else ""
            label += f" band {opts['band']}" if "band" in opts else ""
            # errors below 1e-13 are round-off: equal
            verdict = "" if max(err, 1e-13) <= max(base_err, 1e-13) else "  (error above baseline)"
            print(f"{'':13s} {label:28s} {cpu * 1e6:8.1f}µs {rhs:9.1f} {err:9.1e} {base_cpu / cpu:8.1f}x{verdict}")


if __name__ == "__main__":
    main()
