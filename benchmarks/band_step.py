"""The slaved levels' friction band: the exponential path of ``closed_form`` against its former
Dormand-Prince 5(4) path, cost and error on the same steps.

Cases (quasi-static level, torque drive, the FMU's tolerance: rtol 1e-6, atol 1e-8):

* ``position_step``: the PRSM block's held inputs of every 0.1 ms step of the actuator scene
  (system_models/scenes/position_step.toml, the Python block; the rod creeps inside the spline
  friction band for ~40 % of the steps), replayed open loop from the scene's start;
* ``holding``: Li et al. (2021), 6 N·m against 2 kN from rest, 0.1 ms and 10 ms steps (the screw creeps
  back-driven at the speed where the friction holds the load, near zero: the stiffest point);
* ``reversal``: Li et al. (2021), 5 N·m against 5 kN from 30 rad/s: brakes through zero speed, then
  back-driven (1 ms steps);
* ``viscous reversal``: the friction-torque article (viscous term: no closed form anywhere), −2 N·m against 3 kN
  from 20 rad/s (1 ms steps).

Error (docs/accuracy.md §1): max over the step ends and the states of |x − x_ref| / max|x_ref|, the
reference Radau at rtol 1e-12 on the same steps.  Cost: rhs calls per step and CPU per step,
and their ratios (former / exponential), measured in this run.

Run: ``python benchmarks/band_step.py`` (about 20 s).
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from prsm_fmu import presets  # noqa: E402
from prsm_fmu.models import make_model  # noqa: E402
from prsm_fmu.steppers import ClosedForm, make_stepper  # noqa: E402

OPTS = {"rtol": 1e-6, "atol": 1e-8}


def scene_steps() -> tuple:
    """(params, [(t, u, h)], x0) of the PRSM block in the position_step loop (Python block)."""
    from system_models.ema import build_system
    from system_models.scenes import load_scene

    system = build_system(load_scene("position_step"), prsm="python")
    blk = system.master.blocks[system.master.index["prsm"]]
    steps, start = [], []
    advance = blk.stepper.advance

    def recording(t, x, u, h):
        if not start:
            start.append(list(x))
        steps.append((t, tuple(u), h))
        return advance(t, x, u, h)

    blk.stepper.advance = recording
    system.run()
    return blk.model, steps, start[0]


def run(stepper, x0, steps) -> tuple:
    """States at every step end, rhs calls per step and CPU s per step."""
    x, xs, rhs = list(x0), [list(x0)], 0
    c0 = time.process_time()
    for t, u, h in steps:
        x, st = stepper.advance(t, x, u, h)
        xs.append(x)
        rhs += st.rhs_calls
    return xs, rhs / len(steps), (time.process_time() - c0) / len(steps)


def error(xs, ref) -> float:
    worst = 0.0
    for i in range(len(ref[0])):
        scale = max(abs(r[i]) for r in ref) or 1.0
        worst = max(worst, max(abs(a[i] - b[i]) for a, b in zip(xs, ref)) / scale)
    return worst


def cases():
    model, steps, x0 = scene_steps()
    yield "position_step (0.1 ms)", model, steps, x0
    s000 = make_model(presets.load("li2021_two_stage"), "quasi-static", "torque")
    s003 = make_model(presets.load("friction_single_stage"), "quasi-static", "torque")
    rest = [0.0] * 5
    for h, n in ((1e-4, 300), (1e-2, 3)):
        yield f"holding ({h * 1e3:g} ms)", s000, [(k * h, (6.0, 2000.0), h) for k in range(n)], rest
    yield "reversal (1 ms)", s000, [(k * 1e-3, (5.0, 5000.0), 1e-3) for k in range(4)], \
        [0.0, 30.0, 0.0, 0.0, 0.0]
    yield "viscous reversal (1 ms)", s003, [(k * 1e-3, (-2.0, 3000.0), 1e-3) for k in range(4)], \
        [0.0, 20.0, 0.0, 0.0, 0.0]


def main() -> None:
    print(f"closed_form at rtol {OPTS['rtol']:g}, atol {OPTS['atol']:g}: band path exponential "
          "(exprb32) against the former Dormand-Prince 5(4); error vs Radau rtol 1e-12")
    print(f"{'case':26s} {'path':12s} {'rhs/step':>9s} {'CPU/step':>10s} {'error':>9s}"
          f" {'rhs ratio':>10s} {'CPU ratio':>10s}")
    for name, model, steps, x0 in cases():
        ref, _, _ = run(make_stepper("radau", model, rtol=1e-12, atol=1e-14), x0, steps)
        rows = {band: run(ClosedForm(model, band=band, **OPTS), x0, steps)
                for band in ("explicit", "exponential")}
        _, r_old, c_old = rows["explicit"]
        for band, (xs, r, c) in rows.items():
            ratios = f" {r_old / r:9.2f}x {c_old / c:9.2f}x" if band == "exponential" else ""
            print(f"{name:26s} {band:12s} {r:9.2f} {c * 1e6:8.1f}µs {error(xs, ref):9.1e}{ratios}")


if __name__ == "__main__":
    main()
