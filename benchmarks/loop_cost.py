"""CPU cost of the actuator loop through the PRSM FMU, per simulated second, with its breakdown.

The loop of ``prsm-ema run --scene position_step`` (system_models/scenes/position_step.toml:
controller, motor, the PRSM2 FMU through fmpy, load; Gauss–Seidel, 0.1 ms communication steps,
every output recorded), run ``ROUNDS`` times in this process.  Printed per configuration, as
medians over the rounds:

* the loop's CPU seconds (``time.process_time`` around ``System.run``) per simulated second;
* its breakdown: PRSM block, motor, controller, load, and master + recording (the rest).  The
  master times every block's calls (set_inputs, do_step, get_outputs, the feedthrough update)
  with ``perf_counter``; each part is its share of the run's wall time applied to the run's
  CPU time, so the parts add up to the total and are measured in the same run;
* the PRSM FMU's right-hand-side calls per step (its ``step_rhs_calls`` output).

Configurations: the default loop (the motor's RK4 reference integrator) and the motor's exact
exponential step (``Motor(integrator="exponential")``), with the largest difference of any
recorded output between the two, relative to the output's largest magnitude (DESIGN.md §5).
The issue's target for the loop is ≤ 0.35 CPU s per simulated second (floor ≤ 0.7).

Run: ``python benchmarks/loop_cost.py [--scene position_step] [--rounds 3]`` (builds the FMU in
a child process first; about 30 s).
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from system_models.ema import build_system  # noqa: E402
from system_models.scenes import load_scene  # noqa: E402

PARTS = ("prsm", "motor", "controller", "load", "master+recording")
CONFIGS = {"default (motor RK4)": "rk4", "motor exponential": "exponential"}
TARGET, FLOOR = 0.35, 0.7


def build_fmu(dest: Path) -> Path:
    """PRSM2.fmu built in a child process (a process must not load an FMU it built)."""
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(ROOT)] + [p for p in [env.get("PYTHONPATH")] if p])
    subprocess.run([sys.executable, "-m", "fmu_build", "PRSM2", "--dest", str(dest)], check=True,
                   env=env, stdout=subprocess.DEVNULL)
    return dest / "PRSM2.fmu"


def run_once(scene, fmu: Path, integrator: str) -> tuple[dict[str, float], float, object]:
    """One run: (CPU s per simulated s by part and "total", rhs calls per step, result)."""
    system = build_system(scene, prsm="fmu", fmu_path=fmu)
    master = system.master
    master.blocks[master.index["motor"]].integrator = integrator
    c0 = time.process_time()
    res = system.run()
    cpu = (time.process_time() - c0) / scene.t_end
    wall = res.stats["wall_time"]
    share = {name: t / wall for name, t in res.stats["block_time"].items()}
    share["master+recording"] = 1.0 - sum(share.values())
    cost = {name: cpu * share.get(name, 0.0) for name in PARTS}
    cost["total"] = cpu
    rhs = float(np.mean(res["prsm.step_rhs_calls"][1:]))
    return cost, rhs, res


def max_difference(a, b) -> tuple[float, str]:
    """max over outputs of max|a − b| / max|b|, and the output where it is reached."""
    worst, where = 0.0, ""
    for name in b.names():
        ref = float(np.max(np.abs(b[name]))) or 1.0
        d = float(np.max(np.abs(a[name] - b[name]))) / ref
        if d > worst:
            worst, where = d, name
    return worst, where


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scene", default="position_step")
    ap.add_argument("--rounds", type=int, default=3)
    args = ap.parse_args()
    scene = load_scene(args.scene)
    samples: dict[str, list[dict[str, float]]] = {c: [] for c in CONFIGS}
    rhs: dict[str, list[float]] = {c: [] for c in CONFIGS}
    results = {}
    with tempfile.TemporaryDirectory(prefix="loop_cost_") as tmp:
        fmu = build_fmu(Path(tmp))
        run_once(scene, fmu, "rk4")                          # warm-up (imports, FMU unpacking)
        for _ in range(args.rounds):
            for label, integrator in CONFIGS.items():        # interleaved rounds
                cost, r, res = run_once(scene, fmu, integrator)
                samples[label].append(cost)
                rhs[label].append(r)
                results[label] = res
    print(f"actuator loop, scene {scene.name}: {scene.t_end:g} s simulated in steps of "
          f"{scene.step:g} s, PRSM2 FMU through fmpy; medians of {args.rounds} rounds")
    print(f"{'CPU s per simulated s':<24}{'total':>8}" + "".join(f"{p:>18}" for p in PARTS)
          + f"{'rhs/step':>10}")
    for label, rows in samples.items():
        med = {k: statistics.median(r[k] for r in rows) for k in rows[0]}
        parts = "".join(f"{med[p]:>9.3f} ({100 * med[p] / med['total']:>4.1f} %)" for p in PARTS)
        print(f"{label:<24}{med['total']:>8.3f}{parts}{statistics.median(rhs[label]):>10.1f}")
    default = statistics.median(r["total"] for r in samples["default (motor RK4)"])
    print(f"loop / real time = {default:.3f} (target <= {TARGET}: "
          f"{'met' if default <= TARGET else 'NOT met'}; floor <= {FLOOR}: "
          f"{'met' if default <= FLOOR else 'NOT met'})")
    labels = list(CONFIGS)
    d, where = max_difference(results[labels[1]], results[labels[0]])
    print(f"{labels[1]} against {labels[0]}: largest output difference {d:.2e} of the output's "
          f"maximum ({where})")


if __name__ == "__main__":
    main()
