"""The co-simulation FMUs (issue 3): valid, equal to the Python model, stateful, robust.

The FMUs are built once per session in a separate process (``python -m fmu_build --all``):
pythonfmu imports the generated slave module while building, and a process that later loads
a rebuilt FMU with the same module name would run the stale module.  The tests then load the
FMUs with fmpy, in this process (its ``prsm_fmu`` is the code that was packed) or, where an
FMU ends in fmi2Fatal or where memory is measured, in a fresh process.

Expected values come from the Python model run over the same steps (the FMU must add no
error), from the FMU itself before a refused step (state unchanged), and from FMI's rules.
"""

from __future__ import annotations

import functools
import json
import math
import os
import subprocess
import sys
import tempfile
import textwrap
import zipfile
from pathlib import Path

import pytest

fmpy = pytest.importorskip("fmpy")
pytest.importorskip("pythonfmu")

from fmpy import extract, read_model_description, simulate_fmu  # noqa: E402
from fmpy.fmi1 import FMICallException  # noqa: E402
from fmpy.fmi2 import (  # noqa: E402
    FMU2Slave,
    calloc,
    fmi2CallbackAllocateMemoryTYPE,
    fmi2CallbackFreeMemoryTYPE,
    fmi2CallbackFunctions,
    fmi2CallbackLoggerTYPE,
    free,
)
from fmpy.validation import validate_fmu  # noqa: E402

import prsm_fmu  # noqa: E402,F401 - the FMUs in this process import this very package
from prsm_fmu import presets  # noqa: E402
from prsm_fmu.models import make_model  # noqa: E402
from prsm_fmu.params import stage_field_names  # noqa: E402
from prsm_fmu.steppers import make_stepper  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
TESTS = Path(__file__).resolve().parent
NAMES = ("PRSM1", "PRSM2", "PRSM3")
H = 1e-3                      # communication step [s]
OK, DISCARD = 0, 2

#: the steppers the FMU documents as its defaults (docs/fmu.md), and its tolerance mapping
from prsm_fmu.configure import AUTO_FIDELITY  # noqa: E402
from prsm_fmu.simulate import DEFAULT_STEPPER, tuned_stepper_options  # noqa: E402 - as the FMU
TOLERANCE = 1e-6              # the FMU's default ``tolerance``: rtol = tol, atol = 0.01 tol


def subprocess_env() -> dict:
    """Environment of child processes: this checkout first on the path."""
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(ROOT), str(TESTS)]
                                        + ([env["PYTHONPATH"]] if env.get("PYTHONPATH") else []))
    return env


@functools.cache
def built_fmus() -> dict[str, Path]:
    """Build PRSM1..3 once per test process, in a child process; name -> FMU path."""
    dest = Path(tempfile.mkdtemp(prefix="prsm_fmus_"))
    proc = subprocess.run([sys.executable, "-m", "fmu_build", "--all", "--dest", str(dest)],
                          env=subprocess_env(), capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, f"python -m fmu_build failed:\n{proc.stdout}\n{proc.stderr}"
    return {n: dest / f"{n}.fmu" for n in NAMES}


@functools.cache
def unzipped(name: str) -> Path:
    """The FMU extracted once per process (fmpy loads the binary from there)."""
    return Path(extract(str(built_fmus()[name])))


@functools.cache
def unzipped_path(path: Path) -> Path:
    """Any FMU file extracted once per process."""
    return Path(extract(str(path)))


@pytest.fixture(scope="session")
def fmus() -> dict[str, Path]:
    return built_fmus()


class Host:
    """One FMU instance driven through fmpy's FMU2Slave; records every logged message."""

    def __init__(self, name: str = "PRSM2", instance: str = "prsm", start: dict | None = None,
                 initialize: bool = True, path: Path | None = None) -> None:
        fmu = built_fmus()[name] if path is None else path
        self.md = read_model_description(str(fmu))
        self.vars = {v.name: v for v in self.md.modelVariables}
        self.outputs = [v.name for v in self.md.modelVariables
                        if v.causality == "output" and v.type == "Real"]
        self.messages: list[tuple[int, str]] = []
        cb = fmi2CallbackFunctions()
        cb.logger = fmi2CallbackLoggerTYPE(self._log)
        cb.allocateMemory = fmi2CallbackAllocateMemoryTYPE(calloc)
        cb.freeMemory = fmi2CallbackFreeMemoryTYPE(free)
        self._callbacks = cb
        where = unzipped(name) if path is None else unzipped_path(path)
        self.fmu = FMU2Slave(guid=self.md.guid, unzipDirectory=str(where),
                             modelIdentifier=self.md.coSimulation.modelIdentifier,
                             instanceName=instance)
        self.fmu.instantiate(callbacks=cb, loggingOn=True)
        self.fmu.setupExperiment(startTime=0.0)
        self.fmu.enterInitializationMode()
        self.set(start or {})
        if initialize:
            self.fmu.exitInitializationMode()

    def _log(self, env, instance, status, category, message) -> None:
        self.messages.append((status, message.decode("utf-8")))

    def set(self, values: dict) -> None:
        for name, value in values.items():
            v = self.vars[name]
            setter = {"Real": self.fmu.setReal, "Integer": self.fmu.setInteger,
                      "Boolean": self.fmu.setBoolean, "String": self.fmu.setString}[v.type]
            setter([v.valueReference], [value])

    def get(self, names) -> list:
        out = []
        for name in names:
            v = self.vars[name]
            getter = {"Real": self.fmu.getReal, "Integer": self.fmu.getInteger,
                      "Boolean": self.fmu.getBoolean, "String": self.fmu.getString}[v.type]
            value = getter([v.valueReference])[0]
            out.append(value.decode("utf-8") if isinstance(value, bytes) else value)
        return out

    def get_real(self, names) -> list[float]:
        return self.fmu.getReal([self.vars[n].valueReference for n in names])

    def step(self, t: float, h: float = H) -> int:
        """doStep; the FMI status (0 OK, 2 discard, ...)."""
        try:
            self.fmu.doStep(t, h)
        except FMICallException as exc:
            return exc.status
        return OK

    def state_bytes(self) -> bytes:
        s = self.fmu.getFMUstate()
        try:
            return bytes(self.fmu.serializeFMUstate(s))
        finally:
            self.fmu.freeFMUstate(s)

    def free(self) -> None:
        self.fmu.terminate()
        self.fmu.freeInstance()


# ---- the closed torque-speed loop every comparison runs (also the C host's, same order of
# ---- floating-point operations)

def controller(k: int, speed: float, integral: float) -> tuple[float, float, float]:
    """PI speed controller: (screw_torque [N.m], load_force [N], new integral) for step k."""
    ref = 100.0 if k < 150 else -60.0
    err = ref - speed
    integral = integral + err * H
    torque = 0.05 * err + 2.0 * integral
    torque = min(40.0, max(-40.0, torque))
    return torque, 3000.0, integral


def run_fmu(host: Host, n: int, names, k0: int = 0, loop: tuple = (0.0, None)) -> list[list]:
    """n steps of the closed loop starting at step k0; outputs ``names`` after each step."""
    integral, speed = loop
    if speed is None:
        speed = host.get_real(["screw_speed"])[0]
    rows = []
    vr_in = [host.vars["screw_torque"].valueReference, host.vars["load_force"].valueReference]
    for k in range(k0, k0 + n):
        torque, load, integral = controller(k, speed, integral)
        host.fmu.setReal(vr_in, [torque, load])
        assert host.step(k * H) == OK, host.messages
        rows.append(host.get(names))
        speed = host.get_real(["screw_speed"])[0]
    host.loop = (integral, speed)
    return rows


def run_python(params, fidelity: str, n: int, names, stepper: str | None = None,
               **stepper_opts) -> list[list]:
    """The same loop on the Python model with the stepper the FMU documents."""
    auto = dict(tolerance=TOLERANCE, carrier_ratio=0.0) if fidelity == "auto" else {}
    model = make_model(params, fidelity, "torque", **auto)
    name = stepper or DEFAULT_STEPPER[fidelity]
    opts = stepper_opts or tuned_stepper_options(name, TOLERANCE, 0.01 * TOLERANCE)
    st = make_stepper(name, model, **opts)
    x = model.initial_state((0.0, 0.0), screw_speed=0.0, carrier_ratio=0.0)
    speed, integral = model.outputs(0.0, x, (0.0, 0.0))["screw_speed"], 0.0
    rows = []
    for k in range(n):
        torque, load, integral = controller(k, speed, integral)
        u = (torque, load)
        x, _ = st.advance(k * H, x, u, H)
        y = model.outputs((k + 1) * H, x, u)
        y["mode"] = getattr(model, "mode", model.fidelity)
        rows.append([y[name] for name in names])
        speed = y["screw_speed"]
    return rows


def max_relative_difference(a: list[list], b: list[list]) -> float:
    """Max over outputs of max |a - b| / max |b| (DESIGN.md §5)."""
    worst = 0.0
    for j in range(len(b[0])):
        ref = max(abs(r[j]) for r in b) or 1.0
        worst = max(worst, max(abs(x[j] - y[j]) for x, y in zip(a, b)) / ref)
    return worst


def run_child(code: str, timeout: float = 120) -> dict:
    """Run ``code`` in a fresh Python process (test_fmu importable); return its JSON output."""
    proc = subprocess.run([sys.executable, "-c", textwrap.dedent(code)], env=subprocess_env(),
                          capture_output=True, text=True, timeout=timeout)
    assert proc.returncode == 0, f"child failed ({proc.returncode}):\n{proc.stdout}\n{proc.stderr}"
    return json.loads(proc.stdout.strip().splitlines()[-1])


# ---- the modelDescription -------------------------------------------------------------------


@pytest.mark.parametrize("name", NAMES)
def test_fmpy_validate_reports_no_problem(fmus, name):
    assert validate_fmu(str(fmus[name])) == []


def test_fmpy_validate_command_prints_no_problem(fmus):
    proc = subprocess.run([sys.executable, "-m", "fmpy.cli", "validate", str(fmus["PRSM2"])],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0 and "No problems found" in proc.stdout, proc.stdout + proc.stderr


@pytest.mark.parametrize("name", NAMES)
def test_every_physical_quantity_of_the_preset_is_a_parameter_with_its_value(fmus, name):
    from fmu_build.mechanisms import FMUS

    params = FMUS[name][0]()
    md = read_model_description(str(fmus[name]))
    par = {v.name: v for v in md.modelVariables if v.causality == "parameter"}
    for k, st in enumerate(params.stages, start=1):
        for f in stage_field_names():
            v = par[f"stage[{k}].{f}"]
            assert v.variability == "fixed" and v.description
            assert float(v.start) == getattr(st, f), v.name          # exact: written with repr
    for f in ("mu_screw_roller", "mu_spline", "mu_nut_screw", "slip_velocity_scale"):
        assert float(par[f].start) == getattr(params, f)
    assert {"fidelity", "tolerance", "stepper", "substeps"} <= set(par)
    assert md.defaultExperiment.stopTime and md.defaultExperiment.stepSize


def test_model_description_has_units_bounds_variability_and_structure(fmus):
    md = read_model_description(str(fmus["PRSM3"]))
    defined = {u.name for u in md.unitDefinitions}
    for v in md.modelVariables:
        assert v.description, v.name
        assert v.variability is not None, v.name
        if v.type == "Real":
            assert v.unit in defined, v.name
    v = {v.name: v for v in md.modelVariables}
    assert v["stage[3].contact_force"].unit == "N" and v["screw_torque"].unit == "N.m"
    assert v["mu_spline"].min == "0.0" and v["mu_spline"].max == "1.0"
    assert v["stage[2].screw_starts"].type == "Integer" and v["stage[2].screw_starts"].min == "1"
    assert v["initial_carrier_equilibrium"].variability == "fixed"
    outputs = {x.name for x in md.modelVariables if x.causality == "output"}
    assert {u.variable.name for u in md.outputs} == outputs
    assert {u.variable.name for u in md.initialUnknowns} == outputs
    assert all(u.dependencies == [] for u in md.outputs)     # no direct feedthrough
    assert md.coSimulation.canGetAndSetFMUstate and md.coSimulation.canSerializeFMUstate
    with zipfile.ZipFile(fmus["PRSM3"]) as z:
        names = z.namelist()
    assert "resources/prsm_fmu/models/dynamic.py" in names       # the physics is packed whole
    assert not any("__pycache__" in n for n in names)


# ---- running it ---------------------------------------------------------------------------


def test_fmpy_simulate_runs_the_default_experiment(fmus, tmp_path):
    out = tmp_path / "out.csv"
    proc = subprocess.run([sys.executable, "-m", "fmpy.cli", "simulate", str(fmus["PRSM2"]),
                           "--output-file", str(out)],
                          capture_output=True, text=True, timeout=120, cwd=tmp_path)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    lines = out.read_text().splitlines()
    assert len(lines) == 1 + 101 and float(lines[-1].split(",")[0]) == pytest.approx(0.1)


def test_fmpy_simulate_fmu_with_start_values_moves_and_closes_the_energy_balance(fmus):
    res = simulate_fmu(str(fmus["PRSM2"]), start_values={"screw_torque": 15.0,
                                                         "load_force": 1000.0})
    last = res[-1]
    assert res["time"][-1] == pytest.approx(0.1) and len(res) == 101
    assert last["screw_speed"] > 0.0 and last["rod_position"] > 0.0
    # work in = work out + friction + kinetic energy (started at rest)
    balance = last["input_work"] - last["output_work"] - last["friction_work"] - last["kinetic_energy"]
    assert abs(balance) <= 1e-9 * last["input_work"]


@pytest.mark.parametrize("name,fidelity,stepper", [
    ("PRSM2", "quasi-static", "default"),
    ("PRSM2", "dynamic", "default"),
    ("PRSM2", "kinematic", "default"),
    ("PRSM2", "quasi-static", "explicit_adaptive"),
    ("PRSM1", "quasi-static", "default"),
    ("PRSM3", "dynamic", "default"),
])
def test_fmu_outputs_equal_the_python_model_over_the_same_steps_to_1e_12(name, fidelity, stepper):
    from fmu_build.mechanisms import FMUS

    host = Host(name, start={"fidelity": fidelity, "stepper": stepper})
    names = host.outputs
    try:
        got = run_fmu(host, 300, names)
    finally:
        host.free()
    ref = run_python(FMUS[name][0](), fidelity, 300, names,
                     None if stepper == "default" else stepper)
    assert max_relative_difference(got, ref) <= 1e-12
    assert any(r[names.index("screw_speed")] < 0.0 for r in ref)      # the loop reverses
    assert any(r[names.index("screw_speed")] > 90.0 for r in ref)


@pytest.mark.parametrize("fidelity", ["quasi-static", "dynamic"])
def test_variable_communication_steps_equal_the_python_model(fidelity):
    steps = [1e-3, 5e-4, 2e-3, 1e-4, 3e-3, 7e-4] * 10
    inputs = [(14.0 + 3.0 * math.sin(0.3 * k), 2000.0 + 500.0 * math.cos(0.2 * k))
              for k in range(len(steps))]
    host = Host("PRSM2", start={"fidelity": fidelity})
    got, t = [], 0.0
    try:
        for (torque, load), h in zip(inputs, steps):
            host.set({"screw_torque": torque, "load_force": load})
            assert host.step(t, h) == OK
            t += h
            got.append(host.get_real(host.outputs))
    finally:
        host.free()
    model = make_model(presets.load("seed000_two_stage"), fidelity, "torque")
    name = DEFAULT_STEPPER[fidelity]
    st = make_stepper(name, model, **tuned_stepper_options(name, TOLERANCE, 0.01 * TOLERANCE))
    x, ref, t = model.initial_state((0.0, 0.0)), [], 0.0
    for u, h in zip(inputs, steps):
        x, _ = st.advance(t, x, u, h)
        t += h
        y = model.outputs(t, x, u)
        ref.append([y[n] for n in host.outputs])
    assert max_relative_difference(got, ref) <= 1e-12


def test_fixed_substeps_are_passed_to_the_stepper():
    host = Host("PRSM2", start={"fidelity": "dynamic", "stepper": "rk4", "substeps": 50})
    try:
        got = run_fmu(host, 20, ["screw_speed", "step_rhs_calls", "step_substeps"])
    finally:
        host.free()
    ref = run_python(presets.load("seed000_two_stage"), "dynamic", 20, ["screw_speed"], "rk4",
                     substeps=50)
    assert [r[0] for r in got] == [r[0] for r in ref]
    assert all(r[1:] == [200, 50] for r in got)                     # 4 rhs calls per RK4 step


def test_two_instances_in_one_process_do_not_share_state():
    params = presets.load("seed000_two_stage")
    names = ["screw_speed", "rod_position", "stage[2].contact_force", "friction_work"]
    a = Host("PRSM2", "a")
    b = Host("PRSM2", "b", start={"fidelity": "dynamic", "stage[1].nut_mass": 5.0})
    try:
        rows_a, rows_b = [], []
        for k in range(0, 120, 10):     # interleaved: 10 steps of a, then 10 of b
            rows_a += run_fmu(a, 10, names, k, getattr(a, "loop", (0.0, None)))
            rows_b += run_fmu(b, 10, names, k, getattr(b, "loop", (0.0, None)))
    finally:
        a.free()
        b.free()
    assert rows_a == run_python(params, "quasi-static", 120, names)
    assert rows_b == run_python(params.with_stage(1, nut_mass=5.0), "dynamic", 120, names)


def test_1e5_steps_leave_memory_flat():
    """A fresh process steps 10^5 times (inputs set, outputs read, a state taken and freed
    every 100 steps).  Between step 2·10^4 and 10^5 the count of Python memory blocks
    (every object the FMU's Python code or pythonfmu's C layer creates) may grow by at most
    500 -- a leak of one object per 160 steps would exceed it -- and the resident set size
    by at most 1 MiB, about 13 bytes per step: less than one heap allocation per step."""
    res = run_child("""
        import gc, json, os, sys
        from test_fmu import Host, controller, H
        def rss():
            with open("/proc/self/statm") as f:
                return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE")
        host = Host("PRSM2")
        vr_in = [host.vars[n].valueReference for n in ("screw_torque", "load_force")]
        vr_out = [host.vars[n].valueReference for n in ("screw_speed", "stage[2].contact_force",
                                                       "efficiency", "friction_work")]
        speed, integral, marks = 0.0, 0.0, {}
        for k in range(100_000):
            if k in (20_000, 99_999):
                gc.collect()
                marks[k] = (sys.getallocatedblocks(), rss())
            torque, load, integral = controller(k % 300, speed, integral)
            host.fmu.setReal(vr_in, [torque, load])
            host.fmu.doStep(k * H, H)
            speed = host.fmu.getReal(vr_out)[0]
            if k % 100 == 0:
                host.fmu.freeFMUstate(host.fmu.getFMUstate())
        host.free()
        print(json.dumps({"blocks": marks[99_999][0] - marks[20_000][0],
                          "rss": marks[99_999][1] - marks[20_000][1]}))
    """, timeout=600)
    assert res["blocks"] <= 500, res
    assert res["rss"] <= 1 << 20, res


# ---- FMU state --------------------------------------------------------------------------------


@pytest.mark.parametrize("fidelity", ["quasi-static", "dynamic", "auto"])
def test_state_round_trip_repeats_the_steps_bit_for_bit(fidelity):
    names = ["screw_speed", "screw_angle", "rod_position", "stage[1].contact_force",
             "stage[2].carrier_speed", "efficiency", "friction_work", "step_fidelity",
             "step_rhs_calls"]
    a = Host("PRSM2", "a", start={"fidelity": fidelity})
    b = Host("PRSM2", "b")          # default parameters: the state brings its own
    try:
        run_fmu(a, 140, names)                  # through start-up and the reversal at k = 150
        loop = a.loop
        state = a.fmu.getFMUstate()
        first = run_fmu(a, 40, names, 140, loop)
        a.fmu.setFMUstate(state)
        again = run_fmu(a, 40, names, 140, loop)
        data = bytes(a.fmu.serializeFMUstate(state))
        a.fmu.freeFMUstate(state)
        restored = b.fmu.deSerializeFMUstate(data)
        b.fmu.setFMUstate(restored)
        b.fmu.freeFMUstate(restored)
        elsewhere = run_fmu(b, 40, names, 140, loop)
    finally:
        a.free()
        b.free()
    assert again == first
    assert elsewhere == first
    assert [r.hex() for r in map(float, (x for row in elsewhere for x in row[:-1]))] == \
        [r.hex() for r in map(float, (x for row in first for x in row[:-1]))]


def test_a_state_taken_before_initialization_brings_the_instance_back_there():
    a = Host("PRSM2", "a", start={"fidelity": "dynamic"}, initialize=False)
    try:
        state = a.fmu.getFMUstate()          # in initialization mode: parameters and inputs
        a.fmu.exitInitializationMode()
        run_fmu(a, 5, ["screw_speed"])
        a.fmu.setFMUstate(state)             # back to before initialization
        a.fmu.freeFMUstate(state)
        assert a.step(0.0) == DISCARD         # no model until exitInitializationMode
        assert "before a successful exitInitializationMode" in a.messages[-1][1]
        a.fmu.exitInitializationMode()
        assert run_fmu(a, 5, ["screw_speed"]) == run_python(
            presets.load("seed000_two_stage"), "dynamic", 5, ["screw_speed"])
    finally:
        a.free()


def test_foreign_or_corrupt_state_bytes_fail_visibly():
    """In a fresh process: bytes that are not a PRSM state, and a PRSM3 state offered to PRSM2,
    make fmi2SetFMUstate fail (fmi2Fatal) with the reason logged; freeing is safe."""
    res = run_child("""
        import json
        from fmpy.fmi1 import FMICallException
        from test_fmu import Host
        out = {}
        three = Host("PRSM3", "three")
        foreign = three.state_bytes()
        three.free()
        for case, data in (("junk", b"junk" * 10), ("truncated", foreign[:40]),
                           ("PRSM3 into PRSM2", foreign)):
            host = Host("PRSM2", case)
            state = host.fmu.deSerializeFMUstate(data)
            try:
                host.fmu.setFMUstate(state)
                status = 0
            except FMICallException as exc:
                status = exc.status
            host.fmu.freeInstance()
            out[case] = [status, [m for s, m in host.messages if s >= 3]]
        print(json.dumps(out))
    """)
    for case, (status, messages) in res.items():
        assert status >= 3, case
        assert any("fmi2SetFMUstate" in m for m in messages), (case, messages)
    assert "PRSM3" in " ".join(res["PRSM3 into PRSM2"][1])


# ---- bad input: refused, logged, state unchanged ----------------------------------------------


def _refused_unchanged(host: Host, t: float, h: float, fragment: str) -> None:
    before = host.state_bytes()
    outputs = host.get_real(host.outputs)
    n = len(host.messages)
    assert host.step(t, h) == DISCARD
    assert any(fragment in m for s, m in host.messages[n:]), host.messages[n:]
    assert host.state_bytes() == before
    assert host.get_real(host.outputs) == outputs


@pytest.mark.parametrize("torque,load", [(math.nan, 3000.0), (10.0, math.inf),
                                         (-math.inf, 0.0), (math.nan, math.nan)])
def test_non_finite_inputs_are_refused_and_the_state_is_unchanged(torque, load):
    host = Host("PRSM2")
    twin = Host("PRSM2", "twin")
    try:
        run_fmu(host, 30, ["screw_speed"])
        run_fmu(twin, 30, ["screw_speed"])
        host.set({"screw_torque": torque, "load_force": load})
        _refused_unchanged(host, 30 * H, H, "every input must be finite")
        # the master corrects the inputs and retries: as if the bad call never happened
        assert run_fmu(host, 10, host.outputs, 30, host.loop) == \
            run_fmu(twin, 10, twin.outputs, 30, twin.loop)
    finally:
        host.free()
        twin.free()


@pytest.mark.parametrize("h", [0.0, -1e-3, math.nan, math.inf])
def test_non_positive_or_non_finite_step_sizes_are_refused(h):
    host = Host("PRSM2")
    try:
        run_fmu(host, 5, ["screw_speed"])
        _refused_unchanged(host, 5 * H, h, "communication step size")
    finally:
        host.free()


def test_a_step_whose_integration_fails_is_refused_and_the_state_is_unchanged():
    # dynamic level, explicit stepper, at most 5 internal steps: the stiff carriers need more
    host = Host("PRSM2", start={"fidelity": "dynamic", "stepper": "explicit_adaptive",
                                "max_substeps": 5, "screw_torque": 20.0, "load_force": 3000.0})
    try:
        _refused_unchanged(host, 0.0, H, "more than max_substeps")
        assert "integration failed" in host.messages[-1][1]
    finally:
        host.free()
    # quasi-static level, an absurd step: the closed form overflows
    host = Host("PRSM2")
    try:
        run_fmu(host, 60, ["screw_speed"])
        _refused_unchanged(host, 60 * H, 1e300, "non-finite")
        assert run_fmu(host, 3, ["screw_speed"], 60, host.loop)      # and it goes on
    finally:
        host.free()


def test_fmpy_simulate_fmu_stops_silently_at_a_refused_step(fmus):
    """What docs/fmu.md warns about: fmpy's simulate_fmu ends the run on fmi2Discard without
    an exception; only the time column shows it (and the log, with debug_logging=True)."""
    res = simulate_fmu(str(fmus["PRSM2"]), start_values={"screw_torque": math.nan},
                       stop_time=0.01, output_interval=H)
    assert res["time"][-1] == 0.0 < 0.01


def test_a_parameter_cannot_change_after_initialization_nor_an_output_be_set():
    host = Host("PRSM2")
    try:
        host.set({"stage[1].nut_mass": 100.0, "fidelity": "dynamic"})
        assert host.get(["stage[1].nut_mass", "fidelity"]) == [2.5, "quasi-static"]
        assert any("fixed parameter" in m and "stage[1].nut_mass" in m for _, m in host.messages)
        host.set({"screw_speed": 5.0, "step_substeps": 3})           # outputs: logged, ignored
        assert host.fmu.getInteger([host.vars["screw_speed"].valueReference]) == [0]  # wrong type
        errors = [m for s, m in host.messages if s == 3]
        assert sum("cannot be set" in m for m in errors) == 2 and "not of type Integer" in errors[-1]
        assert run_fmu(host, 5, ["screw_speed"]) == \
            run_python(presets.load("seed000_two_stage"), "quasi-static", 5, ["screw_speed"])
    finally:
        host.free()


def test_out_of_range_parameters_fail_initialization_with_the_message_logged():
    """Each case in one fresh process: exitInitializationMode fails (pythonfmu reports a Python
    exception as fmi2Fatal), the logger receives the ValueError naming the parameter and its
    range, the failed instance can be freed, and a good instance still works afterwards."""
    res = run_child("""
        import json, math
        from fmpy.fmi1 import FMICallException
        from test_fmu import Host, run_fmu
        cases = {
            "stage[1].screw_radius": -1.0,
            "stage[2].nut_radius": 0.03,
            "mu_screw_roller": 1.5,
            "stage[2].flank_angle": math.nan,
            "stage[1].screw_starts": 0,
            "stage[2].carriers": -2,
            "fidelity": "bogus",
            "stepper": "euler",
            "tolerance": 0.0,
            "substeps": -1,
            "max_substeps": 0,
        }
        out = {}
        for name, value in cases.items():
            host = Host("PRSM2", name, start={name: value}, initialize=False)
            try:
                host.fmu.exitInitializationMode()
                status = 0
            except FMICallException as exc:
                status = exc.status
            host.fmu.freeInstance()
            out[name] = [status, [m for s, m in host.messages if s >= 3]]
        good = Host("PRSM2", "good")
        out["good"] = run_fmu(good, 3, ["screw_speed"])
        good.free()
        print(json.dumps(out))
    """)
    assert len(res.pop("good")) == 3
    for name, (status, messages) in res.items():
        assert status >= 3, name                                      # error or fatal
        text = " ".join(messages)
        assert "initialization failed" in text and name in text, (name, messages)
        assert "out of range" in text or "not allowed" in text or "inconsistent" in text


def test_auto_fidelity_runs_the_documented_level():
    """At the default start auto starts with the documented level and then switches along the
    run exactly as the Python model does (prsm_fmu/models/adaptive.py)."""
    host = Host("PRSM2", start={"fidelity": "auto"})
    try:
        got = run_fmu(host, 50, ["screw_speed", "stage[1].contact_force", "step_fidelity"])
        assert any(f"starts with '{AUTO_FIDELITY}'" in m for _, m in host.messages)
    finally:
        host.free()
    want = run_python(presets.load("seed000_two_stage"), "auto", 50,
                      ["screw_speed", "stage[1].contact_force", "mode"])
    codes = {"quasi-static": 1, "dynamic": 2}
    assert [r[:2] for r in got] == [r[:2] for r in want]
    # the level reported after each step is the Python model's, and this run switches
    assert [r[2] for r in got] == [codes[r[2]] for r in want]
    assert {r[2] for r in got} == {1, 2}
