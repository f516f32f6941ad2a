"""Cost of one ``doStep`` of the PRSM2 FMU over the cost of one ``doStep`` of an empty FMU.

Both FMUs are built in child processes the same way (pythonfmu 0.7's ``FmuBuilder``, the same
binary, loaded through fmpy's ``FMU2Slave`` in this process): the empty one is an
``Fmi2Slave`` whose ``do_step`` returns True, so its cost is the fixed price of the FMI call
path (ctypes → C++ → Python and back).  The ratio is the cost the mechanism adds, in units
of that price.  Target (issue 3): ≤ 5 for the quasi-static level at a 1 ms step.

Scenarios: Li et al.'s (2021) two-stage PRSM (``PRSM2``), 1 ms communication steps, start at 100 rad/s
with the carriers at equilibrium; the inputs of ``benchmarks/step_cost.py``'s "moving" scenario
(load F(t) = 5000 + 1000 sin(2π·25 t) N, motor torque 19.75 F(t)/5000 + sin(2π·40 t) N·m, new
values every step: the screw keeps turning at ≈ 100…116 rad/s), and the operating point itself
with the inputs held (19.75 N·m, 5000 N), where the dynamic steppers' error against Radau at
rtol 1e-12 is printed too (the same stepping in-process).  Each FMU is stepped in rounds of
``N_STEPS`` steps; the inputs are set before each step and all Real outputs read after it,
outside the timed call; every ``doStep`` is timed on its own (perf_counter_ns).  The cost per
step is the median over ``ROUNDS`` interleaved rounds of the mean over a round.

Levels: quasi-static and dynamic with their default steppers (run by the compiled engine
in-process: its closed form with the Dormand-Prince band fallback; ROS34PW2), and the dynamic
level with the exponential Rosenbrock stepper (``dyn exponential``, which the engine does not
have: the Python stepper); each dynamic row's doStep is also printed over the quasi-static
doStep.  The same FMU built with ``--engine python`` (``QS reference``, ``dyn reference``: the
Python model and steppers) is measured beside it.  At the operating point with the inputs held
the pythonfmu FMU's goals are printed: dynamic doStep ≤ 3× its quasi-static doStep (floor 5×),
quasi-static doStep ≤ 1.5× the empty FMU's (floor 2×).

The native C FMU of the same mechanism (``PRSM2-native.fmu``, fmu_build.native: the same
model and steppers translated into C, equal to the Python FMU's outputs bit for bit) is measured
beside it: ``native QS`` (quasi-static, its default closed form with the Dormand-Prince band
fallback) and ``native dynamic`` (ROS34PW2); the native dynamic doStep is printed over the
native quasi-static doStep as well, and the outputs of the native and the Python dynamic FMU
after the same steps are compared (they must be equal: the error printed for ``dynamic`` is
theirs).

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


def moving_inputs(t: float) -> tuple[float, float]:
    f = load_force(t)
    return 19.75 * f / 5000.0 + 1.0 * math.sin(2 * math.pi * 40 * t), f


def constant_inputs(t: float) -> tuple[float, float]:
    """The operating point itself: 19.75 N·m against 5000 N, held (the screw gains 0.6 rad/s
    in 0.1 s)."""
    return 19.75, 5000.0


#: scenario name -> inputs (torque [N·m], load [N]) held over the step that starts at t [s]
SCENARIOS = {"moving": moving_inputs, "constant": constant_inputs}
#: the dynamic level's steppers compared: row label -> FMU parameter ``stepper``
DYNAMIC = {"dynamic": "rosenbrock", "dyn exponential": "exponential"}


def constant_input_errors(n_steps: int = 100) -> dict[str, tuple[float, float]]:
    """At the constant inputs, the dynamic level stepped as the FMU steps it (its model and
    stepper options, in-process: tests/test_fmu.py checks the FMU's outputs equal them), 1 ms
    steps from 100 rad/s with the carriers at equilibrium: row label -> (largest |y − y_ref| /
    max|y_ref| over the FMU's outputs of benchmarks/step_cost.py and the steps, rhs calls per
    step), against Radau at rtol 1e-12 along the same trajectory."""
    from prsm_fmu import presets
    from prsm_fmu.models import make_model
    from prsm_fmu.simulate import tuned_stepper_options
    from prsm_fmu.steppers import make_stepper

    sys.path.insert(0, str(ROOT / "benchmarks"))
    from step_cost import OUTPUTS

    model = make_model(presets.load("li2021_two_stage"), "dynamic", "torque")
    u = constant_inputs(0.0)

    def trajectory(name: str, opts: dict) -> tuple[list[dict], float]:
        st = make_stepper(name, model, **opts)
        x = model.initial_state(u, screw_speed=100.0, carrier_ratio=None)
        out, rhs = [], 0
        for i in range(n_steps):
            x, stats = st.advance(i * H, x, u, H)
            rhs += stats.rhs_calls
            out.append(model.outputs((i + 1) * H, x, u))
        return out, rhs / n_steps

    ref, _ = trajectory("radau", {"rtol": 1e-12, "atol": 1e-14})
    errors = {}
    for label, stepper in DYNAMIC.items():
        out, rhs = trajectory(stepper, tuned_stepper_options(stepper, 1e-6, 1e-8))
        err = max(max(abs(a[n] - r[n]) for a, r in zip(out, ref))
                  / (max(abs(r[n]) for r in ref) or 1.0) for n in OUTPUTS)
        errors[label] = (err, rhs)
    return errors


def build(dest: Path) -> tuple[Path, Path, Path, Path]:
    """Build Empty.fmu, PRSM2.fmu, PRSM2-native.fmu and the reference PRSM2.fmu (``--engine
    python``: the Python model only) in child processes; return their paths."""
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
    subprocess.run([sys.executable, "-m", "fmu_build", "--native", "PRSM2", "--dest", str(dest)],
                   check=True, env=env, stdout=subprocess.DEVNULL)
    subprocess.run([sys.executable, "-m", "fmu_build", "PRSM2", "--engine", "python", "--dest",
                    str(dest / "reference")], check=True, env=env, stdout=subprocess.DEVNULL)
    return (dest / "Empty.fmu", dest / "PRSM2.fmu", dest / "PRSM2-native.fmu",
            dest / "reference" / "PRSM2.fmu")


class Instance:
    """An initialized FMU instance with its step loop."""

    def __init__(self, fmu: Path, start: dict | None = None, inputs=moving_inputs) -> None:
        self.inputs = inputs
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
        fmu, u, out, inputs = self.fmu, self.u, self.out, self.inputs
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


def measure(empty_fmu: Path, prsm_fmu: Path, native_fmu: Path, reference_fmu: Path,
            inputs) -> tuple[dict[str, tuple[float, float, float]], float]:
    """Row label -> (doStep [s], doStep + getReal [s], rhs calls per step), medians of
    ``ROUNDS`` interleaved rounds of ``N_STEPS`` steps with ``inputs``; and the largest relative
    difference between the native and the Python dynamic FMU's outputs after the last step."""
    start = {"initial_screw_speed": 100.0, "initial_carrier_equilibrium": True}
    instances = {"empty": Instance(empty_fmu),
                 "quasi-static": Instance(prsm_fmu, dict(start, fidelity="quasi-static"), inputs)}
    for label, stepper in DYNAMIC.items():
        instances[label] = Instance(prsm_fmu, dict(start, fidelity="dynamic", stepper=stepper),
                                    inputs)
    instances["QS reference"] = Instance(reference_fmu, dict(start, fidelity="quasi-static"),
                                         inputs)
    instances["dyn reference"] = Instance(reference_fmu, dict(start, fidelity="dynamic"), inputs)
    instances["native QS"] = Instance(native_fmu, dict(start, fidelity="quasi-static"), inputs)
    instances["native dynamic"] = Instance(native_fmu, dict(start, fidelity="dynamic"), inputs)
    for inst in instances.values():
        inst.run(WARM_UP)
    samples = {name: [] for name in instances}
    for _ in range(ROUNDS):
        for name, inst in instances.items():
            samples[name].append(inst.run(N_STEPS))
    py, nat = (instances[n].fmu.getReal(instances[n].out) for n in ("dynamic", "native dynamic"))
    diff = max(abs(a - b) / max(abs(a), abs(b)) if a != b else 0.0 for a, b in zip(py, nat))
    for inst in instances.values():
        inst.free()
    return ({name: tuple(statistics.median(s[i] for s in rows) for i in range(3))
             for name, rows in samples.items()}, diff)


def main() -> None:
    with tempfile.TemporaryDirectory(prefix="fmu_step_cost_") as tmp:
        fmus = build(Path(tmp))
        measured = {name: measure(*fmus, inputs) for name, inputs in SCENARIOS.items()}
    costs = {name: m[0] for name, m in measured.items()}
    cost = costs["moving"]
    e_step, e_all, _ = cost["empty"]
    print(f"PRSM2 FMU, {N_STEPS} x {ROUNDS} steps of {H * 1e3:g} ms per level "
          f"(median of round means), fmpy FMU2Slave, pythonfmu 0.7; inputs changing every step")
    print(f"{'level':<14}{'doStep [us]':>12}{'ratio':>8}{'+getReal [us]':>15}{'ratio':>8}"
          f"{'rhs/step':>10}")
    for name, (step, both, rhs) in cost.items():
        print(f"{name:<14}{step * 1e6:>12.2f}{step / e_step:>8.2f}{both * 1e6:>15.2f}"
              f"{both / e_all:>8.2f}{rhs:>10.1f}")
    ratio = cost["quasi-static"][0] / e_step
    print(f"quasi-static doStep / empty doStep = {ratio:.2f} (target <= 5: "
          f"{'met' if ratio <= 5 else 'NOT met'}); dynamic: {cost['dynamic'][0] / e_step:.2f}")
    qs = cost["quasi-static"][0]
    for name in DYNAMIC:
        print(f"{name} doStep / quasi-static doStep = {cost[name][0] / qs:.1f} "
              "(goal <= 5, floor <= 10)")
    print(f"native dynamic doStep / native QS doStep = "
          f"{cost['native dynamic'][0] / cost['native QS'][0]:.1f} (goal <= 5, floor <= 10); "
          f"native dynamic / Python quasi-static doStep = {cost['native dynamic'][0] / qs:.2f}; "
          f"native dynamic outputs against the Python dynamic FMU's after the same steps: "
          f"largest relative difference {measured['moving'][1]:.1e}")
    const = costs["constant"]
    errors = constant_input_errors()
    qs = const["quasi-static"][0]
    print(f"at the operating point with the inputs held ({constant_inputs(0.0)[0]:g} N·m, "
          f"{constant_inputs(0.0)[1]:g} N): quasi-static doStep {qs * 1e6:.2f} us")
    for name in DYNAMIC:
        err, rhs = errors[name]
        print(f"  {name:<16} doStep {const[name][0] * 1e6:8.2f} us, {const[name][2]:.1f} rhs/step, "
              f"/ quasi-static = {const[name][0] / qs:.1f} (goal <= 5, floor <= 10); error against "
              f"Radau rtol 1e-12 {err:.1e} ({rhs:.1f} rhs/step in-process)")
    nqs, ndyn = const["native QS"][0], const["native dynamic"][0]
    print(f"  native dynamic   doStep {ndyn * 1e6:8.2f} us, {const['native dynamic'][2]:.1f} "
          f"rhs/step, / native QS ({nqs * 1e6:.2f} us) = {ndyn / nqs:.1f} (goal <= 5, floor <= 10); "
          f"outputs equal to the Python dynamic FMU's within {measured['constant'][1]:.1e}, so its "
          f"error is the dynamic row's {errors['dynamic'][0]:.1e}")
    e_const = const["empty"][0]
    dyn_ratio = const["dynamic"][0] / qs
    qs_ratio = qs / e_const
    print("the pythonfmu FMU's goals at the operating point with the inputs held (engine: the "
          "compiled core in-process; reference: the same FMU built with --engine python):")
    print(f"  dynamic doStep / quasi-static doStep = {dyn_ratio:.2f} (goal <= 3, floor <= 5: "
          f"{'goal met' if dyn_ratio <= 3 else 'floor met' if dyn_ratio <= 5 else 'NOT met'}); "
          f"reference {const['dyn reference'][0] / const['QS reference'][0]:.1f}")
    print(f"  quasi-static doStep / empty doStep = {qs_ratio:.2f} (goal <= 1.5, floor <= 2: "
          f"{'goal met' if qs_ratio <= 1.5 else 'floor met' if qs_ratio <= 2 else 'NOT met'}); "
          f"reference {const['QS reference'][0] / e_const:.2f} (empty doStep "
          f"{e_const * 1e6:.2f} us)")
    print(f"  dynamic doStep: engine {const['dynamic'][0] * 1e6:.2f} us, reference "
          f"{const['dyn reference'][0] * 1e6:.2f} us "
          f"({const['dyn reference'][0] / const['dynamic'][0]:.0f}x)")


if __name__ == "__main__":
    main()
