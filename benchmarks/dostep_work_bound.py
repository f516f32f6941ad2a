"""The work of one doStep at its bound: every stepper forced to its limit, engine and Python.

One ``doStep`` of the FMU takes at most ``max_substeps`` internal steps, and where the Python
reference model steps (not the compiled engine) at most ``PYTHON_MAX_SUBSTEPS`` (docs/fmu.md,
"Work of one doStep").  This script takes PRSM3 (the largest FMU), with its carriers as given
and with stiff carriers (carrier mass and inertia 10^-6 of PRSM3's: a carrier time constant a
million times shorter), at the smallest ``tolerance`` 1e-12 and the largest ``max_substeps``
100 000, and takes one communication step of 100 s from rest under 40 N.m and 3 kN with each
stepper, on the engine and on the Python model (``configure``, the FMU's own path).  It prints
the CPU time of that one doStep measured in this run, the rhs calls of the Python model, and
how it ended (refused at the limit, or finished).  The worst line is the bound of one doStep
on this machine.

    python benchmarks/dostep_work_bound.py
"""

from __future__ import annotations

import time

from fmu_build.mechanisms import three_stage
from prsm_fmu.configure import MAX_SUBSTEPS_RANGE, PYTHON_MAX_SUBSTEPS, configure

MOST = MAX_SUBSTEPS_RANGE[1]
#: (fidelity, stepper, fixed substeps: 0 adaptive); rk4 has only fixed substeps
CASES = (("dynamic", "rosenbrock", 0), ("dynamic", "explicit_adaptive", 0),
         ("dynamic", "exponential", 0), ("dynamic", "radau", 0),
         ("dynamic", "rk4", PYTHON_MAX_SUBSTEPS), ("dynamic", "rosenbrock", MOST),
         ("dynamic", "rosenbrock", PYTHON_MAX_SUBSTEPS),
         ("quasi-static", "closed_form", 0), ("quasi-static", "closed_form", MOST),
         ("quasi-static", "closed_form_explicit", 0), ("auto", "default", 0))


def _stiff(params):
    for k, st in enumerate(params.stages, start=1):
        params = params.with_stage(k, carrier_mass=st.carrier_mass * 1e-6,
                                   carrier_inertia=st.carrier_inertia * 1e-6)
    return params


def main() -> None:
    """Print the CPU time of one doStep at the bound, per stepper, engine and carriers."""
    u = (40.0, 3000.0)
    print(f"max_substeps = {MOST}, tolerance = 1e-12, one step of 100 s from rest, PRSM3")
    print(f"{'carriers':9s} {'engine':7s} {'fidelity':13s} {'stepper':21s} {'substeps':>8s} "
          f"{'CPU s':>7s} {'rhs calls':>10s}  result")
    worst = (0.0, "")
    for carriers, params in (("as given", three_stage()), ("stiff", _stiff(three_stage()))):
        for engine in ("native", "python"):
            for fidelity, stepper, substeps in CASES:
                solver = dict(tolerance=1e-12, max_substeps=MOST, kinematic_efficiency=1.0,
                              initial_screw_speed=0.0, initial_screw_angle=0.0,
                              initial_carrier_equilibrium=False, fidelity=fidelity,
                              stepper=stepper, substeps=substeps)
                head = f"{carriers:9s} {engine:7s} {fidelity:13s} {stepper:21s} {substeps:8d}"
                try:
                    model, st, x, _level, _name = configure(params, solver, u, engine=engine)
                except ValueError as exc:    # substeps above the Python model's bound
                    print(f"{head} {'-':>7s} {'-':>10s}  refused at initialization: "
                          f"{str(exc)[:60]}")
                    continue
                ran = "native" if st.name == "native" else "python"
                if ran != engine:
                    continue             # the engine does not run this stepper: Python's line
                calls = [0]
                rhs = model.rhs

                def counted(t, x_, u_, _rhs=rhs):
                    calls[0] += 1
                    return _rhs(t, x_, u_)

                model.rhs = counted
                t0 = time.process_time()
                try:
                    st.advance(0.0, x, u, 100.0)
                    result = "finished"
                except Exception as exc:  # noqa: BLE001 - StepFailure at the limit is the point
                    result = "refused: " + str(exc).split(" at t =")[0]
                cpu = time.process_time() - t0
                worst = max(worst, (cpu, f"{carriers} carriers, {ran}, {fidelity}, {stepper}"))
                shown = str(calls[0]) if calls[0] else "-"     # the engine's are in C
                print(f"{head} {cpu:7.2f} {shown:>10s}  {result[:90]}")
    print(f"worst: {worst[0]:.2f} CPU s ({worst[1]})")


if __name__ == "__main__":
    main()
