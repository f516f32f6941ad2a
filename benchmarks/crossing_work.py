"""Work of the doStep through zero speed: rhs calls of the speed reversal's dearest step per
tolerance, and how they grow as the tolerance tightens.

The actuator loop's speed reversal (system_models/scenes/speed_reversal.toml) with the PRSM as
the plain Python block at the dynamic level, ROS34PW2 (the engine's, equal to the Python one
bit for bit) at every tolerance the FMU offers, 1e-1 to 1e-12.  Printed per tolerance: the largest
``prsm.step_rhs_calls`` of a communication step and when, the run's total, and the ratio of the
largest to the one a decade looser, against the analysis of docs/accuracy.md ("Work of the
crossing step"): inside the friction band the steps are set by the error estimate alone, the
embedded order 2 makes the local error ∝ h³, so the steps across the band shrink as
tolerance^(1/3) and their count grows by at most 10^(1/3) = 2.154 per decade, plus the fixed
work of the rest of the step.

    python benchmarks/crossing_work.py            # ~3 min
    python benchmarks/crossing_work.py --stepper default --fidelity auto
"""

from __future__ import annotations

import argparse
from dataclasses import replace

import numpy as np

TOLERANCES = (1e-1, 1e-2, 1e-3, 1e-4, 1e-5, 1e-6, 1e-7, 1e-8, 1e-9, 1e-10, 1e-11, 1e-12)
#: the growth of the band's step count per decade of tolerance (error ∝ h³)
DECADE = 10.0 ** (1.0 / 3.0)


def crossing(tolerance: float, fidelity: str = "dynamic", stepper: str = "rosenbrock",
             scene_name: str = "speed_reversal") -> tuple[int, float, int]:
    """(largest rhs calls of one communication step, its start time [s], the run's total)."""
    from system_models.run import run_scene
    from system_models.scenes import load_scene

    sc = load_scene(scene_name)
    par = dict(sc.prsm.get("parameters", {}))
    par.update(stepper=stepper, tolerance=tolerance, substeps=0)
    sc = replace(sc, prsm={**sc.prsm, "parameters": par})
    res = run_scene(sc, prsm="python", fidelity=fidelity).result
    calls = np.asarray(res["prsm.step_rhs_calls"], float)
    k = int(np.argmax(calls))
    # the counter at output k is the step that ended there: it started one step before
    return int(calls[k]), float(res.time[k] - sc.step), int(calls.sum())


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--fidelity", default="dynamic")
    ap.add_argument("--stepper", default="rosenbrock")
    args = ap.parse_args(argv)
    print(f"speed reversal, {args.fidelity}, {args.stepper}: the dearest doStep per tolerance")
    print(f"{'tolerance':>9s} {'rhs calls':>9s} {'at t [ms]':>9s} {'run total':>9s} "
          f"{'x decade':>8s}  (analysis: <= {DECADE:.3f} for the band's part)")
    prev = None
    for tol in TOLERANCES:
        most, t, total = crossing(tol, args.fidelity, args.stepper)
        ratio = f"{most / prev:8.3f}" if prev else f"{'':8s}"
        print(f"{tol:9.0e} {most:9d} {t * 1e3:9.1f} {total:9d} {ratio}")
        prev = most


if __name__ == "__main__":
    main()
