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
from conftest import shared_build  # noqa: E402
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
from text_numbers import number_after  # noqa: E402
TOLERANCE = 1e-6              # the FMU's default ``tolerance``: rtol = tol, atol = 0.01 tol
#: the Python steppers the compiled engine translates (docs/fmu.md, "One engine"), which the
#: FMU's ``default`` runs where the engine runs (PRSM2, PRSM3: Coulomb friction only)
ENGINE_REFERENCE = {"kinematic": "closed_form", "quasi-static": "closed_form",
                    "dynamic": "rosenbrock"}


def subprocess_env() -> dict:
    """Environment of child processes: this checkout first on the path."""
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(ROOT), str(TESTS)]
                                        + ([env["PYTHONPATH"]] if env.get("PYTHONPATH") else []))
    return env


def _shared_fmu_build(name: str, *args: str) -> Path:
    """The directory ``python -m fmu_build ARGS --dest DIR`` filled once per test session,
    in a child process, shared by pytest-xdist's workers (tests/conftest.py)."""
    def build(dest: Path) -> None:
        proc = subprocess.run([sys.executable, "-m", "fmu_build", *args, "--dest", str(dest)],
                              env=subprocess_env(), capture_output=True, text=True, timeout=300)
        assert proc.returncode == 0, f"python -m fmu_build failed:\n{proc.stdout}\n{proc.stderr}"

    return shared_build(name, build)


@functools.cache
def built_fmus() -> dict[str, Path]:
    """Build PRSM1..3 once per test session (shared by pytest-xdist's workers: tests/conftest.py),
    in a child process; name -> FMU path."""
    dest = _shared_fmu_build("prsm_fmus", "--all")
    return {n: dest / f"{n}.fmu" for n in NAMES}


@functools.cache
def built_prsm2_dynamic() -> Path:
    """PRSM2 built with the start value fidelity = dynamic (for hosts that cannot set an
    Enumeration, and to load beside the plain build), once per test session like
    :func:`built_fmus`."""
    return _shared_fmu_build("prsm2_dynamic", "PRSM2", "--start", "fidelity=dynamic") / "PRSM2.fmu"


@functools.cache
def built_prsm2_reference() -> Path:
    """PRSM2 built with ``--engine python`` (the Python reference model, no engine packed), once
    per test session like :func:`built_fmus`."""
    return _shared_fmu_build("prsm2_reference", "PRSM2", "--engine", "python") / "PRSM2.fmu"


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
        """Set by name with the setter of each variable's type; an Enumeration takes an item
        name (looked up in the modelDescription's TypeDefinitions) or its value."""
        for name, value in values.items():
            v = self.vars[name]
            if v.type == "Enumeration" and isinstance(value, str):
                value = {i.name: int(i.value) for i in v.declaredType.items}[value]
            setter = {"Real": self.fmu.setReal, "Integer": self.fmu.setInteger,
                      "Enumeration": self.fmu.setInteger, "Boolean": self.fmu.setBoolean,
                      "String": self.fmu.setString}[v.type]
            setter([v.valueReference], [value])

    def get(self, names) -> list:
        out = []
        for name in names:
            v = self.vars[name]
            getter = {"Real": self.fmu.getReal, "Integer": self.fmu.getInteger,
                      "Enumeration": self.fmu.getInteger, "Boolean": self.fmu.getBoolean,
                      "String": self.fmu.getString}[v.type]
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
    """Max over outputs of max |a - b| / max |b| (docs/accuracy.md §1)."""
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
    assert float(v["mu_spline"].min) == 0.0 and float(v["mu_spline"].max) == 1.0
    assert v["stage[2].screw_starts"].type == "Integer" and int(v["stage[2].screw_starts"].min) == 1
    assert v["initial_carrier_equilibrium"].variability == "fixed"
    outputs = {x.name for x in md.modelVariables if x.causality == "output"}
    assert {u.variable.name for u in md.outputs} == outputs
    assert {u.variable.name for u in md.initialUnknowns} == outputs
    assert all(u.dependencies == [] for u in md.outputs)     # no direct feedthrough
    assert md.coSimulation.canGetAndSetFMUstate and md.coSimulation.canSerializeFMUstate
    with zipfile.ZipFile(fmus["PRSM3"]) as z:
        names = z.namelist()
        pycs = {n: z.read(n)[:16] for n in names if "__pycache__" in n}
    assert "resources/prsm_fmu/models/dynamic.py" in names       # the physics is packed whole
    # bytecode only beside a packed source, for this interpreter, and checked against the
    # source's hash at import (PEP 552: flags word 0b11 = hash-based, checked), never stale
    tag = sys.implementation.cache_tag
    sources = {n for n in names if n.startswith("resources/") and n.endswith(".py")}
    assert pycs and len(pycs) == len(sources)
    for n, head in pycs.items():
        folder, _, file = n.rpartition("/__pycache__/")
        assert file.endswith(f".{tag}.pyc") and f"{folder}/{file.split('.')[0]}.py" in sources, n
        assert int.from_bytes(head[4:8], "little") == 0b11, n


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


# The FMU runs the compiled engine where it can (docs/fmu.md, "One engine"): with ``default``
# its method of the level, the Python stepper it translates (closed_form at the kinematic and
# quasi-static levels, rosenbrock at the dynamic one: the Python defaults), and
# closed_form_explicit when asked for; PRSM1 (viscous and differential-sliding friction) too.  ``reference``: the Python stepper each case must equal.
@pytest.mark.parametrize("name,fidelity,stepper,reference", [
    ("PRSM2", "quasi-static", "default", "closed_form"),
    ("PRSM2", "dynamic", "default", "rosenbrock"),
    ("PRSM2", "kinematic", "default", "closed_form"),
    ("PRSM2", "quasi-static", "closed_form_explicit", "closed_form_explicit"),
    ("PRSM2", "quasi-static", "explicit_adaptive", "explicit_adaptive"),
    ("PRSM2", "quasi-static", "closed_form", "closed_form"),
    ("PRSM1", "quasi-static", "default", "closed_form"),
    ("PRSM3", "dynamic", "default", "rosenbrock"),
])
def test_fmu_outputs_equal_the_python_model_over_the_same_steps_to_1e_12(name, fidelity, stepper,
                                                                         reference):
    from fmu_build.mechanisms import FMUS

    host = Host(name, start={"fidelity": fidelity, "stepper": stepper})
    names = host.outputs
    try:
        got = run_fmu(host, 300, names)
    finally:
        host.free()
    ref = run_python(FMUS[name][0](), fidelity, 300, names, reference)
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
    model = make_model(presets.load("li2021_two_stage"), fidelity, "torque")
    name = ENGINE_REFERENCE[fidelity]          # the engine runs PRSM2's default
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
    ref = run_python(presets.load("li2021_two_stage"), "dynamic", 20, ["screw_speed"], "rk4",
                     substeps=50)
    assert [r[0] for r in got] == [r[0] for r in ref]
    assert all(r[1:] == [200, 50] for r in got)                     # 4 rhs calls per RK4 step


def test_two_instances_in_one_process_do_not_share_state():
    params = presets.load("li2021_two_stage")
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
    assert rows_a == run_python(params, "quasi-static", 120, names,
                                ENGINE_REFERENCE["quasi-static"])
    assert rows_b == run_python(params.with_stage(1, nut_mass=5.0), "dynamic", 120, names,
                                ENGINE_REFERENCE["dynamic"])


@pytest.mark.stress
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
    assert bits(again) == bits(first)
    assert bits(elsewhere) == bits(first)
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
        assert "not allowed before fmi2ExitInitializationMode" in a.messages[-1][1]
        a.fmu.exitInitializationMode()
        assert run_fmu(a, 5, ["screw_speed"]) == run_python(
            presets.load("li2021_two_stage"), "dynamic", 5, ["screw_speed"])
    finally:
        a.free()


def _bad_states(good: bytes) -> dict[str, bytes]:
    """Corruptions of the serialized state ``good`` (b"PRSMFMU2" + a pickle of a 12-tuple):
    foreign bytes, cut or extended bytes, and well-framed states whose fields are wrong."""
    import pickle

    magic, state = good[:8], pickle.loads(good[8:])
    fields = dict(zip(("tag", "model", "n", "par", "u", "phase", "t", "x", "u_held", "memory",
                       "counters", "init_error"), state))

    def framed(**changes) -> bytes:
        return magic + pickle.dumps(tuple({**fields, **changes}.values()), protocol=4)

    x = fields["x"]
    return {
        "junk": b"junk" * 10, "empty": b"", "header only": magic, "truncated": good[:40],
        "trailing junk": good + b"junk", "trailing zero byte": good + b"\0",
        "a class reference": magic + pickle.dumps(ValueError("x")),
        "tuple too short": magic + pickle.dumps(state[:-1]),
        "x one value short": framed(x=x[:-1]), "x one value long": framed(x=x + (0.0,)),
        "x with nan": framed(x=(math.nan,) + x[1:]), "x with inf": framed(x=x[:-1] + (math.inf,)),
        "x with a string": framed(x=("1.0",) + x[1:]), "x a list": framed(x=list(x)),
        "x None while stepping": framed(x=None),
        "time nan": framed(t=math.nan), "time a string": framed(t="0.1"),
        "phase unknown": framed(phase="running"),
        "inputs held nan": framed(u_held=(math.nan, 0.0)),
        "parameter of wrong type": framed(par=("0.01",) + fields["par"][1:]),
        "parameters one short": framed(par=fields["par"][:-1]),
        "parameter out of range": framed(par=(-1.0,) + fields["par"][1:]),
        "memory with nan": framed(memory=(math.nan,) * 2),
        "memory of another stepper": framed(memory=(1.0, 2.0, 3.0)),
        "counters negative": framed(counters=(-1, 0, 1)),
        "model PRSM3": framed(model="PRSM3", n=3),
    }


def test_every_corrupt_or_foreign_state_is_refused_and_nothing_is_restored():
    """Each corruption of a valid state: fmi2SetFMUstate logs an error naming it (pythonfmu can
    only return fmi2OK or fmi2Fatal there), restores nothing (the serialized state is the same
    bytes after the call), the next doStep is refused (fmi2Discard) naming fmi2SetFMUstate, and
    the one after it goes on as if the bad call had not happened."""
    host = Host("PRSM2", "corrupt", start={"fidelity": "dynamic"})
    twin = Host("PRSM2", "twin", start={"fidelity": "dynamic"})
    tried = 0
    try:
        run_fmu(host, 20, ["screw_speed"])
        run_fmu(twin, 20, ["screw_speed"])
        cases = _bad_states(host.state_bytes())
        for k, (case, data) in enumerate(cases.items()):
            before = host.state_bytes()
            n = len(host.messages)
            state = host.fmu.deSerializeFMUstate(data)
            host.fmu.setFMUstate(state)                     # fmi2OK, the refusal is logged
            host.fmu.freeFMUstate(state)
            logged = [m for st, m in host.messages[n:] if st == 3]
            assert any(m.startswith("fmi2SetFMUstate: the state is refused") for m in logged), \
                (case, host.messages[n:])
            assert host.state_bytes() == before, case
            assert host.step((20 + k) * H) == DISCARD, case
            assert "fmi2SetFMUstate" in host.messages[-1][1], case
            assert run_fmu(host, 1, ["screw_speed"], 20 + k, host.loop) == \
                run_fmu(twin, 1, ["screw_speed"], 20 + k, twin.loop), case
            tried += 1
    finally:
        host.free()
        twin.free()
    print(f"corrupt or foreign FMU states refused: {tried}")
    assert tried == len(cases) == 26


# ---- bad input: refused, logged, state unchanged ----------------------------------------------


def bits(rows: list) -> list:
    """Rows (or one row) of values compared by their bits: the efficiency is NaN where no
    power passes through the PRSM, and NaN != NaN."""
    def one(x):
        return x.hex() if isinstance(x, float) else (bits(x) if isinstance(x, list) else x)
    return [one(x) for x in rows]


def _refused_unchanged(host: Host, t: float, h: float, fragment: str) -> None:
    before = host.state_bytes()
    outputs = host.get_real(host.outputs)
    n = len(host.messages)
    assert host.step(t, h) == DISCARD
    assert any(fragment in m for s, m in host.messages[n:]), host.messages[n:]
    assert host.state_bytes() == before
    assert bits(host.get_real(host.outputs)) == bits(outputs)


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
        assert bits(run_fmu(host, 10, host.outputs, 30, host.loop)) == \
            bits(run_fmu(twin, 10, twin.outputs, 30, twin.loop))
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
    # dynamic level, explicit stepper, at most 10 internal steps: the stiff carriers need more
    host = Host("PRSM2", start={"fidelity": "dynamic", "stepper": "explicit_adaptive",
                                "max_substeps": 10, "screw_torque": 20.0, "load_force": 3000.0})
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
        assert host.get(["stage[1].nut_mass", "fidelity"]) == [2.5, 1]    # 1: quasi-static
        assert any("fixed parameter" in m and "stage[1].nut_mass" in m for _, m in host.messages)
        host.set({"stage[1].nut_mass": 2.5})          # the same value again: not a change
        host.set({"screw_speed": 5.0, "step_substeps": 3})           # outputs: logged, ignored
        assert host.fmu.getInteger([host.vars["screw_speed"].valueReference]) == [0]  # wrong type
        errors = [m for s, m in host.messages if s == 3]
        assert sum("cannot be set" in m for m in errors) == 2
        assert "fmi2GetInteger" in errors[-1] and "'screw_speed', of type Real" in errors[-1]
        assert host.step(0.0) == DISCARD               # the refused calls, reported once
        assert "5 earlier call(s) since the last step were refused" in host.messages[-1][1]
        assert run_fmu(host, 5, ["screw_speed"]) == \
            run_python(presets.load("li2021_two_stage"), "quasi-static", 5, ["screw_speed"],
                       ENGINE_REFERENCE["quasi-static"])
    finally:
        host.free()


#: values tried for every parameter of its type: non-finite, zero, negative, extreme
BAD_VALUES = {
    "Real": [math.nan, math.inf, -math.inf, 0.0, -1.0, -1e308, 1e308, 1e-300],
    "Integer": [0, -1, -(2**31), 2**31 - 1],
    "Enumeration": [-1, 4, 8, -(2**31), 2**31 - 1],   # 8: past both (Fidelity 0..3, Stepper 0..7)
    "Boolean": [],
}


def test_every_parameter_value_is_refused_at_initialization_or_steps():
    """Every parameter of PRSM2 set to each value of BAD_VALUES (in a loaded run: 15 N.m,
    1 kN).  Either initialization refuses it -- exitInitializationMode returns fmi2OK (a Python
    exception would be fmi2Fatal), logs the reason, and every doStep is then refused with
    fmi2Discard naming the parameter and its range, until fmi2Reset -- or the value is
    accepted and then 1 ms steps succeed: no accepted value makes a step fail.  Non-finite
    values and every Enumeration value outside its items are always refused."""
    md = read_model_description(str(built_fmus()["PRSM2"]))
    params = [v for v in md.modelVariables if v.causality == "parameter"]
    tried = refused = ran = 0
    accepted = []
    host = Host("PRSM2", "bad", initialize=False)
    try:
        for v in params:
            for value in BAD_VALUES[v.type]:
                host.fmu.reset()
                host.fmu.setupExperiment(startTime=0.0)
                host.fmu.enterInitializationMode()
                host.set({v.name: value, "screw_torque": 15.0, "load_force": 1000.0})
                n = len(host.messages)
                host.fmu.exitInitializationMode()           # fmi2OK: an exception would be fatal
                status = [host.step(k * H) for k in range(3)]
                text = " ".join(m for _, m in host.messages[n:])
                tried += 1
                if status == [OK] * 3:
                    assert not (isinstance(value, float) and not math.isfinite(value)), v.name
                    assert v.type != "Enumeration", (v.name, value)
                    accepted.append(f"{v.name}={value!r}")
                    ran += 1
                    continue
                assert status == [DISCARD] * 3, (v.name, value, status, text)
                # the parameter is named, or (a consistency condition between the fields of
                # one stage, e.g. r_N = r_S + 2 r_R) a field of the same stage, with its index
                named = v.name if v.name in text else v.name.split(".")[0] + "."
                assert "initialization failed" in text and named in text, (v.name, value, text)
                assert "out of range" in text or "not allowed" in text or \
                    "inconsistent" in text or "no screw-roller contact" in text, (v.name, text)
                refused += 1
        host.fmu.reset()                                  # a good configuration runs again
        host.fmu.setupExperiment(startTime=0.0)
        host.fmu.enterInitializationMode()
        host.fmu.exitInitializationMode()
        assert host.step(0.0) == OK
    finally:
        host.free()
    print(f"parameter values tried: {tried}, refused at initialization: {refused}, "
          f"accepted and stepped: {ran} ({', '.join(accepted)})")
    assert tried == refused + ran == sum(len(BAD_VALUES[v.type]) for v in params)


def test_the_state_machine_is_enforced():
    """Calls out of FMI 2.0's order are refused with a message naming the call: logged as
    errors (the status is fmi2OK, pythonfmu cannot return fmi2Error), the FMU's state and time
    unchanged, the next doStep refused naming them; doStep itself is refused (fmi2Discard)."""
    cases = 0
    host = Host("PRSM2", "order", initialize=False)
    try:
        assert host.step(0.0) == DISCARD                  # before exitInitializationMode
        assert "before fmi2ExitInitializationMode" in host.messages[-1][1]
        cases += 1
        host.fmu.exitInitializationMode()
        run_fmu(host, 10, ["screw_speed"])
        before = host.state_bytes()
        for call, fragment in ((lambda: host.fmu.enterInitializationMode(),
                                "fmi2EnterInitializationMode is not allowed in phase stepping"),
                               (lambda: host.fmu.exitInitializationMode(),
                                "fmi2ExitInitializationMode is not allowed in phase stepping"),
                               (lambda: host.fmu.setupExperiment(startTime=5.0),
                                "fmi2SetupExperiment is not allowed in phase stepping")):
            n = len(host.messages)
            call()
            assert any(fragment in m for s, m in host.messages[n:] if s == 3), host.messages[n:]
            assert host.state_bytes() == before
            assert host.step(10 * H) == DISCARD and fragment in host.messages[-1][1]
            cases += 1
        for t in (9 * H, 11 * H, 10 * H + 1e-9, 0.0, math.nan):   # not the FMU's time 0.01 s
            assert host.step(t) == DISCARD, t
            assert number_after(host.messages[-1][1], "is not the FMU's time ") == \
                pytest.approx(10 * H, rel=1e-12)
            assert host.state_bytes() == before
            cases += 1
        # a host that counts in integer nanoseconds: 10_000_000 ns -> 0.01 in the last bits
        assert host.step(10_000_000 * 1e-9) == OK
        host.fmu.terminate()
        assert host.step(11 * H) == DISCARD and "after fmi2Terminate" in host.messages[-1][1]
        n = len(host.messages)
        host.set({"screw_torque": 1.0})
        assert "cannot be set after fmi2Terminate" in host.messages[n][1]
        cases += 2
    finally:
        host.fmu.freeInstance()
    print(f"out-of-order calls refused: {cases}")
    assert cases == 11


def test_access_through_the_wrong_type_is_refused_naming_the_call_and_the_variable():
    """Every variable of PRSM2 read and written through each accessor of another type."""
    host = Host("PRSM2", "types")
    tried = 0
    access = {"Real": "Real", "Integer": "Integer", "Enumeration": "Integer",
              "Boolean": "Boolean"}
    try:
        for v in host.md.modelVariables:
            for typ in ("Real", "Integer", "Boolean", "String"):
                if typ == access[v.type]:
                    continue
                n = len(host.messages)
                value = getattr(host.fmu, f"get{typ}")([v.valueReference])[0]
                assert value in (0, False, b"", "") or math.isnan(value)
                getattr(host.fmu, f"set{typ}")([v.valueReference],
                                               [{"Real": 1.0, "Integer": 1, "Boolean": True,
                                                 "String": "x"}[typ]])
                msgs = [m for s, m in host.messages[n:] if s == 3]
                assert len(msgs) == 2 and f"fmi2Get{typ}" in msgs[0] and \
                    f"fmi2Set{typ}" in msgs[1] and all(repr(v.name) in m for m in msgs), msgs
                tried += 2
        assert host.step(0.0) == DISCARD and "earlier call(s)" in host.messages[-1][1]
        assert host.step(0.0) == OK                        # reported once, then it goes on
    finally:
        host.free()
    print(f"wrong-type accesses refused: {tried}")
    assert tried == 6 * len(host.md.modelVariables)


def test_one_read_of_outputs_parameters_and_inputs_gives_what_reads_one_by_one_give():
    """The slave's batched paths (outputs by position, counters by getter) and its per-variable
    path return the same values, in the order asked, with the values set coming back."""
    host = Host("PRSM2", "batched", start={"tolerance": 1e-8, "screw_torque": 1.25,
                                           "load_force": 300.0})
    try:
        for k in range(3):
            assert host.step(k * H) == OK
        host.set({"screw_torque": 2.5})
        names = host.outputs + ["tolerance", "screw_torque", "load_force"]
        batch = host.get_real(names)
        assert batch[-3:] == [1e-8, 2.5, 300.0]
        assert batch == [host.get_real([n])[0] for n in names]
        assert host.get_real(names[::-1]) == batch[::-1]
        assert host.get_real(host.outputs[:4]) == batch[:4]
        counters = [v.name for v in host.md.modelVariables
                    if v.causality == "output" and v.type != "Real"]
        ints = host.fmu.getInteger([host.vars[n].valueReference for n in counters])
        assert ints == [host.get([n])[0] for n in counters]
        assert dict(zip(counters, ints))["step_rhs_calls"] >= 1       # a step took place
        assert host.fmu.getInteger([host.vars["substeps"].valueReference,
                                    host.vars[counters[0]].valueReference])[0] == 0
    finally:
        host.free()


def test_auto_fidelity_runs_the_documented_level():
    """At the default start auto starts with the documented level and then switches along the
    run exactly as the Python model does (prsm_fmu/models/adaptive.py), its dynamic steps by
    ROS34PW2 as the FMU's compiled engine takes them (docs/fmu.md, "What the engine runs")."""
    host = Host("PRSM2", start={"fidelity": "auto"})
    try:
        got = run_fmu(host, 50, ["screw_speed", "stage[1].contact_force", "step_fidelity"])
        assert any(f"starts with '{AUTO_FIDELITY}'" in m for _, m in host.messages)
    finally:
        host.free()
    want = run_python(presets.load("li2021_two_stage"), "auto", 50,
                      ["screw_speed", "stage[1].contact_force", "mode"], stepper="rosenbrock")
    codes = {"quasi-static": 1, "dynamic": 2}
    assert [r[:2] for r in got] == [r[:2] for r in want]
    # the level reported after each step is the Python model's, and this run switches
    assert [r[2] for r in got] == [codes[r[2]] for r in want]
    assert {r[2] for r in got} == {1, 2}


# ---- process exit (pythonfmu 0.7's exit-time use-after-free, prsm_fmu/fmu_exit.py) ------------


def test_the_fmu_library_in_this_process_is_guarded_for_exit():
    """Instantiating an FMU registers pythonfmu's library for the exit-time reset (fmu_exit):
    the FMU's binary is the status wrapper (docs/fmu.md, Errors), pythonfmu's library lies
    beside it."""
    from prsm_fmu import fmu_exit

    host = Host("PRSM2", "exit")
    host.free()
    lib = unzipped("PRSM2") / "binaries" / "linux64" / "pythonfmu-export.so"
    if sys.platform.startswith("linux"):
        assert str(lib) in fmu_exit.guarded()


def test_a_state_without_rigid_contact_solution_is_refused_and_flagged():
    """Li et al. (2021) with every inertia 1000x too small (kg·mm² taken as 1e-9 kg·m²: J_S = 55e-9 and
    170e-9, J_R = 0.08e-9 and 0.48e-9, J_P = 3e-9 and 12e-9 kg·m²), torque-driven from −1 rad/s
    with the carriers at rest, +20 N·m against 500 N: no acceleration balances the torque
    (Painlevé).  The FMU refuses the step with the cause named, its state unchanged, and
    contact_status reads 1; with the preset's inertias the same start steps and reads 0."""
    light = {"stage[1].screw_inertia": 55e-9, "stage[1].roller_inertia": 0.08e-9,
             "stage[1].carrier_inertia": 3e-9, "stage[2].screw_inertia": 170e-9,
             "stage[2].roller_inertia": 0.48e-9, "stage[2].carrier_inertia": 12e-9}
    start = {"fidelity": 2, "initial_screw_speed": -1.0, "screw_torque": 20.0, "load_force": 500.0}
    host = Host("PRSM2", "painleve", start={**start, **light})
    try:
        before = host.get_real(["screw_speed", "screw_angle"])
        assert host.get(["contact_status"]) == [1]
        assert host.step(0.0) == DISCARD
        text = host.messages[-1][1]
        assert "state unchanged" in text and "no solution" in text
        assert "effective inertia dM_S1/dα" in text and "<= 0" in text
        assert host.get_real(["screw_speed", "screw_angle"]) == before
    finally:
        host.free()
    host = Host("PRSM2", "consistent", start=start)
    try:
        assert host.get(["contact_status"]) == [0]
        assert host.step(0.0) == OK
    finally:
        host.free()
