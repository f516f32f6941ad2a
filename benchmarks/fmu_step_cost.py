"""Cost of one ``doStep`` of the PRSM2 FMU over the cost of one ``doStep`` of an empty FMU.

Both FMUs are built in child processes the same way (pythonfmu 0.7's ``FmuBuilder``, the same
binary, loaded through fmpy's ``FMU2Slave`` in this process): the empty one is an
``Fmi2Slave`` whose ``do_step`` returns True, so its cost is the fixed price of the FMI call
path (ctypes → C++ → Python and back).  The ratio is the cost the mechanism adds, in units
of that price.  Target (issue 3): ≤ 5 for the quasi-static level at a 1 ms step.

Scenario: seed 000's two-stage PRSM (``PRSM2``), 1 ms communication steps, the inputs of
``benchmarks/step_cost.py``'s "moving" scenario (load F(t) = 5000 + 1000 sin(2π·25 t) N, motor
torque 19.75 F(t)/5000 + sin(2π·40 t) N·m, new values every step; start at 100 rad/s, carriers
at equilibrium): the screw keeps turning at ≈ 100…116 rad/s.  Each FMU is stepped in rounds of
``N_STEPS`` steps; the inputs are set before each step and all Real outputs read after it,
outside the timed call; every ``doStep`` is timed on its own (perf_counter_ns).  The cost per
step is the median over ``ROUNDS`` interleaved rounds of the mean over a round.

Levels: quasi-static and dynamic with their default steppers (closed form; ROS34PW2), and the
dynamic level with the exponential Rosenbrock stepper (``dyn exponential``); each dynamic row's
doStep is also printed over the quasi-static doStep (the issue's goal ≤ 5, floor ≤ 10).

Also printed: ``doStep`` + ``getReal`` of every output (what a master that reads all outputs
pays each step) over ``doStep`` + ``getReal`` of the empty FMU's one output, and the rhs calls
per step the FMU reports (``step_rhs_calls``).  Ratios are measured in one run, on this machine.

Run: ``python benchmarks/fmu_step_cost.py`` (about 20 s, builds included).
"""

from __future__ import annotations

import math
import os
import statistics
import subprocess
import sys
import tempfile
import textwrap
import time
from pathlib import Path

from fmpy import extract, read_model_description
from fmpy.fmi2 import FMU2Slave
from prsm_fmu.fmi_enum import enumeration_value

ROOT = Path(__file__).resolve().parents[1]
H = 1e-3
N_STEPS = 2000
ROUNDS = 5
WARM_UP = 100

EMPTY_SLAVE = '''
from pythonfmu import Fmi2Causality, Fmi2Slave, Real


class Empty(Fmi2Slave):
    """An FMU that does nothing: the price of the FMI call path."""

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.y = 0.0
        self.register_variable(Real("y", causality=Fmi2Causality.output))

    def do_step(self, current_time, step_size):
        return True
'''


def load_force(t: float) -> float:
    return 5000.0 + 1000.0 * math.sin(2 * math.pi * 25 * t)


def inputs(t: float) -> tuple[float, float]:
    f = load_force(t)
    return 19.75 * f / 5000.0 + 1.0 * math.sin(2 * math.pi * 40 * t), f


def build(dest: Path) -> tuple[Path, Path]:
    """Build Empty.fmu and PRSM2.fmu in child processes; return their paths."""
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(ROOT)] + [p for p in [env.get("PYTHONPATH")] if p])
    (dest / "src").mkdir()
    (dest / "src" / "empty.py").write_text(textwrap.dedent(EMPTY_SLAVE))
    subprocess.run([sys.executable, "-c",
                    "from pythonfmu import FmuBuilder; import sys; "
                    "FmuBuilder.build_FMU(sys.argv[1], dest=sys.argv[2], canGetAndSetFMUstate=True, "
                    "canSerializeFMUstate=True)", str(dest / "src" / "empty.py"), str(dest)],
                   check=True, env=env)
    subprocess.run([sys.executable, "-m", "fmu_build", "PRSM2", "--dest", str(dest)], check=True,
                   env=env, stdout=subprocess.DEVNULL)
    return dest / "Empty.fmu", dest / "PRSM2.fmu"


class Instance:
    """An initialized FMU instance with its step loop."""

    def __init__(self, fmu: Path, start: dict | None = None) -> None:
        md = read_model_description(str(fmu))
        self.vr = {v.name: v.valueReference for v in md.modelVariables}
        types = {v.name: v.type for v in md.modelVariables}
        variables = {v.name: v for v in md.modelVariables}
        self.out = [v.valueReference for v in md.modelVariables
                    if v.causality == "output" and v.type == "Real"]
        self.fmu = FMU2Slave(guid=md.guid, unzipDirectory=extract(str(fmu)),
                             modelIdentifier=md.coSimulation.modelIdentifier, instanceName="bench")
        self.fmu.instantiate()
        self.fmu.setupExperiment(startTime=0.0)
        self.fmu.enterInitializationMode()
        for name, value in (start or {}).items():
            if types[name] == "Enumeration":       # fidelity, stepper: by item name
                self.fmu.setInteger([self.vr[name]], [enumeration_value(variables[name], value)])
            elif types[name] == "Boolean":
                self.fmu.setBoolean([self.vr[name]], [value])
            else:
                self.fmu.setReal([self.vr[name]], [value])
        self.u = [self.vr[n] for n in ("screw_torque", "load_force") if n in self.vr]
        self.fmu.exitInitializationMode()
        self.k = 0
        self.rhs = self.vr.get("step_rhs_calls")

    def run(self, n: int) -> tuple[float, float, float]:
        """n steps; (mean doStep [s], mean doStep + getReal(all outputs) [s], rhs calls/step)."""
        fmu, u, out = self.fmu, self.u, self.out
        clock = time.perf_counter_ns
        step_ns = get_ns = 0
        rhs = 0
        for _ in range(n):
            t = self.k * H
            if u:
                fmu.setReal(u, list(inputs(t)))
            t0 = clock()
            fmu.doStep(t, H)
            t1 = clock()
            fmu.getReal(out)
            t2 = clock()
            step_ns += t1 - t0
            get_ns += t2 - t1
            if self.rhs is not None:
                rhs += fmu.getInteger([self.rhs])[0]
            self.k += 1
        return step_ns * 1e-9 / n, (step_ns + get_ns) * 1e-9 / n, rhs / n

    def free(self) -> None:
        self.fmu.terminate()
        self.fmu.freeInstance()


def main() -> None:
    with tempfile.TemporaryDirectory(prefix="fmu_step_cost_") as tmp:
        empty_fmu, prsm_fmu = build(Path(tmp))
        start = {"initial_screw_speed": 100.0, "initial_carrier_equilibrium": True}
        instances = {
            "empty": Instance(empty_fmu),
            "quasi-static": Instance(prsm_fmu, dict(start, fidelity="quasi-static")),
            "dynamic": Instance(prsm_fmu, dict(start, fidelity="dynamic")),
            "dyn exponential": Instance(prsm_fmu, dict(start, fidelity="dynamic",
                                                       stepper="exponential")),
        }
        for inst in instances.values():
            inst.run(WARM_UP)
        samples = {name: [] for name in instances}
        for _ in range(ROUNDS):
            for name, inst in instances.items():
                samples[name].append(inst.run(N_STEPS))
        for inst in instances.values():
            inst.free()
    cost = {name: tuple(statistics.median(s[i] for s in rows) for i in range(3))
            for name, rows in samples.items()}
    e_step, e_all, _ = cost["empty"]
    print(f"PRSM2 FMU, {N_STEPS} x {ROUNDS} steps of {H * 1e3:g} ms per level "
          f"(median of round means), fmpy FMU2Slave, pythonfmu 0.7")
    print(f"{'level':<14}{'doStep [us]':>12}{'ratio':>8}{'+getReal [us]':>15}{'ratio':>8}"
          f"{'rhs/step':>10}")
    for name, (step, both, rhs) in cost.items():
        print(f"{name:<14}{step * 1e6:>12.2f}{step / e_step:>8.2f}{both * 1e6:>15.2f}"
              f"{both / e_all:>8.2f}{rhs:>10.1f}")
    ratio = cost["quasi-static"][0] / e_step
    print(f"quasi-static doStep / empty doStep = {ratio:.2f} (target <= 5: "
          f"{'met' if ratio <= 5 else 'NOT met'}); dynamic: {cost['dynamic'][0] / e_step:.2f}")
    qs = cost["quasi-static"][0]
    for name in ("dynamic", "dyn exponential"):
        print(f"{name} doStep / quasi-static doStep = {cost[name][0] / qs:.1f} "
              "(goal <= 5, floor <= 10)")


if __name__ == "__main__":
    main()
