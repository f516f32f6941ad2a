"""The work of one doStep at its bound: time per internal step with every stepper at the limit.

One ``doStep`` of the FMU takes at most ``max_substeps`` internal steps (docs/fmu.md, "Work of
one doStep").  This script forces each stepper of PRSM3 (the largest FMU) to that limit --
a communication step of 100 s at ``tolerance = 1e-12`` with ``max_substeps = 2000`` -- and
prints the CPU time per internal step measured in this run and the resulting bound of one
doStep at the default ``max_substeps`` of 100 000.

    python benchmarks/dostep_work_bound.py
"""

from __future__ import annotations

import time

from fmu_build.mechanisms import three_stage
from prsm_fmu.configure import MAX_SUBSTEPS_RANGE, configure

LIMIT = 2000
CASES = (("dynamic", "rosenbrock"), ("dynamic", "explicit_adaptive"), ("dynamic", "radau"),
         ("quasi-static", "closed_form"), ("auto", "default"))


def main() -> None:
    """Print ms per internal step and the implied bound of one doStep, per stepper."""
    params = three_stage()
    solver = dict(tolerance=1e-12, substeps=0, max_substeps=LIMIT, kinematic_efficiency=1.0,
                  initial_screw_speed=0.0, initial_screw_angle=0.0,
                  initial_carrier_equilibrium=False)
    u = (40.0, 3000.0)
    most = MAX_SUBSTEPS_RANGE[1]
    print(f"{'fidelity':13s} {'stepper':18s} {'ms/step':>8s} {'bound at ' + str(most):>16s}  result")
    for fidelity, stepper in CASES:
        model, st, x, _level, _name = configure(params, dict(solver, fidelity=fidelity,
                                                              stepper=stepper), u)
        t0 = time.process_time()
        try:
            st.advance(0.0, x, u, 100.0)
            result = "finished within the limit"
        except Exception as exc:  # noqa: BLE001 - StepFailure at the limit is the point
            result = str(exc).split(" at t =")[0]
        per_step = (time.process_time() - t0) / LIMIT
        print(f"{fidelity:13s} {stepper:18s} {per_step * 1e3:8.3f} {per_step * most:14.1f} s  "
              f"{result}")


if __name__ == "__main__":
    main()
