"""Cost of ``fidelity = "auto"`` on the compiled engine against the Python reference, in-process.

Two runs of :func:`prsm_fmu.simulate.simulate` on Li et al.'s (2021) two-stage PRSM, each three
ways: the engine (its default at ``auto``: the switching of prsm_fmu/models/adaptive.py in C,
every dynamic step ROS34PW2's), the Python reference with the same method
(``stepper = "rosenbrock"``: equal to the engine bit for bit, checked here), and the Python
reference's own default (its dynamic steps Dormand–Prince, exponential or ROS34PW2 per step):

* ``startup``: Li et al.'s (2021) §3.1 start-up, 100 rad/s held (speed drive), 5 kN, carriers
  at rest, 20 ms in 0.1 ms steps (dynamic while the carriers spin up, quasi-static after);
* ``reversal``: torque drive from 100 rad/s, carriers at equilibrium, 3 kN, +2 N·m for 20 ms
  then -8 N·m for 30 ms (the screw reverses through the friction band), 0.1 ms steps.

Printed per run and way: the process CPU time of the stepping loop (``cpu_time``: the steps and
the Python model's outputs after each), the rhs calls and the ratios reference / engine measured
in this run; and the largest difference of the engine's outputs from the reference default's,
relative to each output's largest magnitude (docs/accuracy.md §1's measure; two solutions of
the same switching with other dynamic steps, each aiming at the tolerance: printed, not
required).  Tolerance 1e-6.  Each way runs ``ROUNDS`` times; the median CPU time is printed.

With ``--accuracy``: the error of ``auto`` on the engine (its default) at tolerance 1e-4 … 1e-7
on the work-precision loop scenes (benchmarks/work_precision.py: load step, sine tracking, speed
reversal, position step; docs/accuracy.md §1's measure over each scene's outputs), against the
dynamic level stepped by the engine's ROS34PW2 at rtol 1e-11 (a converged solution, not the
Radau reference of the charts, which takes hours in Python), with the error over the tolerance.

Run: ``python benchmarks/auto_engine_cost.py`` (about a minute; needs gcc), ``--accuracy``
(a few minutes more).
"""

from __future__ import annotations

import statistics

import numpy as np

from prsm_fmu import presets
from prsm_fmu.simulate import simulate

ROUNDS = 3
TOL = 1e-6
H = 1e-4
OUTPUTS = ("screw_speed", "screw_torque", "stage[1].carrier_speed", "stage[2].carrier_speed",
           "stage[1].contact_force", "stage[2].contact_force", "friction_power")


def _runs() -> dict[str, dict]:
    return {
        "startup": dict(drive="speed", screw_speed=100.0, load_force=5000.0, t_end=20e-3,
                        initial_screw_speed=100.0, initial_carrier_ratio=0.0),
        "reversal": dict(drive="torque", screw_torque=lambda t: 2.0 if t < 20e-3 else -8.0,
                         load_force=3000.0, t_end=50e-3, initial_screw_speed=100.0,
                         initial_carrier_ratio=None),
    }


WAYS = {"engine": dict(engine="native"),
        "reference rosenbrock": dict(engine="python", stepper="rosenbrock"),
        "reference default": dict(engine="python")}


def main() -> None:
    params = presets.load("li2021_two_stage")
    for run, kw in _runs().items():
        res, cpu = {}, {}
        for _ in range(ROUNDS):
            for way, opts in WAYS.items():
                r = simulate(params, "auto", output_interval=H, rtol=TOL, atol=1e-2 * TOL,
                             **kw, **opts)
                res[way] = r
                cpu.setdefault(way, []).append(r["cpu_time"])
        eng = res["engine"]
        assert eng["engine"] == "native" and eng["engine_fallback"] is None, eng["engine_fallback"]
        same = all(np.array_equal(eng[n], res["reference rosenbrock"][n], equal_nan=True)
                   for n in OUTPUTS)
        print(f"{run}: {len(eng['time']) - 1} steps of {H:g} s, tolerance {TOL:g}; engine equal "
              f"to the reference with rosenbrock bit for bit: {same}")
        median = {w: statistics.median(v) for w, v in cpu.items()}
        for way, r in res.items():
            print(f"  {way:22s} CPU {median[way] * 1e3:9.2f} ms  rhs calls {r['rhs_calls']:8d}"
                  f"  ratio to engine {median[way] / median['engine']:7.1f}")
        ref = res["reference default"]
        worst = max(np.max(np.abs(eng[n] - ref[n])) / (np.max(np.abs(ref[n])) or 1.0)
                    for n in OUTPUTS)
        print(f"  engine vs reference default: largest relative difference {worst:.2e} "
              f"over {', '.join(OUTPUTS)}")


def accuracy() -> None:
    """The ``--accuracy`` table (module docstring)."""
    import sys
    from pathlib import Path

    sys.path.insert(0, str(Path(__file__).resolve().parent))
    import work_precision as wp

    for name in ("load_step", "sine_tracking", "speed_reversal", "position_step"):
        scene = wp.SCENES[name]
        ref = scene.run(wp.Config("dynamic", "rosenbrock", "rtol", 1e-11), time_it=False)
        print(f"{name} (reference: the dynamic level, ROS34PW2 at rtol 1e-11 on the engine)")
        for tol in (1e-4, 1e-5, 1e-6, 1e-7):
            p = wp.measure(scene, wp.Config("auto", "default", "rtol", tol), ref)
            print(f"  auto on the engine at tolerance {tol:g}: {p.status}, error {p.error:.3g} "
                  f"= {p.error / tol:.2f} x the tolerance, {p.rhs_calls} rhs calls")


if __name__ == "__main__":
    import sys

    accuracy() if "--accuracy" in sys.argv[1:] else main()
