"""The FMUs in FMI hosts nobody here wrote: libcosim (libcosimpy), fmu-manipulation-toolbox's
container (run by fmpy) and Ecos (ecospy).

Each host runs in a child process of its own (a host that ends the process on an error cannot
take the test run with it).  A run is compared with fmpy's ``FMU2Slave`` fed the same
communication times as the host computes them -- libcosim counts time in integer nanoseconds,
t_k = k·10^6 / 10^9 s, and passes h_k = t_(k+1) − t_k; the container and Ecos pass
t_k = k·h or the accumulated sum, h = 10^-3 s -- and must be bit for bit equal.  Then each host
meets the error classes of docs/fmu.md ("Errors") and must behave as documented there.

libcosim and Ecos cannot set an FMI 2.0 Enumeration (libcosim ignores the variables, Ecos
has no property for them): they run ``PRSM2`` built with ``--start fidelity=dynamic``, the
documented work-around.
"""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

pytest.importorskip("fmpy")
pytest.importorskip("pythonfmu")

from fmpy import extract, read_model_description  # noqa: E402
from fmpy.fmi2 import FMU2Slave  # noqa: E402

from test_fmu import NAMES, built_fmus, built_prsm2_dynamic, subprocess_env  # noqa: E402
from text_numbers import number_after  # noqa: E402

OUTPUTS = ("screw_speed", "rod_position", "stage[1].contact_force", "friction_work",
           "kinetic_energy")
STEPS = 40
H_NS = 1_000_000             # communication step [ns] = 1 ms
U = (15.0, 1000.0)           # screw_torque [N.m], load_force [N]


def child(code: str, timeout: float = 300) -> tuple[int, dict | None, str]:
    """Run ``code`` in a fresh process; (exit status, its last JSON line or None, everything
    it printed: the hosts log to stdout or stderr)."""
    proc = subprocess.run([sys.executable, "-c", textwrap.dedent(code)], env=subprocess_env(),
                          capture_output=True, text=True, timeout=timeout)
    lines = proc.stdout.strip().splitlines()
    data = json.loads(lines[-1]) if lines and lines[-1].startswith("{") else None
    return proc.returncode, data, proc.stdout + proc.stderr


def fmpy_run(fmu: Path, times: list[tuple[float, float]], start: dict) -> list[list[float]]:
    """The outputs after each doStep(t, h) of ``times`` in fmpy, with ``start`` set first."""
    md = read_model_description(str(fmu))
    v = {x.name: x for x in md.modelVariables}
    f = FMU2Slave(guid=md.guid, unzipDirectory=extract(str(fmu)),
                  modelIdentifier=md.coSimulation.modelIdentifier, instanceName="ref")
    f.instantiate()
    f.setupExperiment(startTime=0.0)
    f.enterInitializationMode()
    for name, value in start.items():
        setter = f.setReal if v[name].type == "Real" else f.setInteger
        setter([v[name].valueReference], [value])
    f.setReal([v["screw_torque"].valueReference, v["load_force"].valueReference], list(U))
    f.exitInitializationMode()
    rows = []
    for t, h in times:
        f.doStep(t, h)
        rows.append(f.getReal([v[n].valueReference for n in OUTPUTS]))
    f.terminate()
    f.freeInstance()
    return rows


@pytest.fixture(scope="module")
def dynamic_prsm2() -> Path:
    """PRSM2 built with the start value fidelity = dynamic (hosts without Enumerations)."""
    return built_prsm2_dynamic()


# ---- libcosim ---------------------------------------------------------------------------------

LIBCOSIM = """
    import json
    from libcosimpy.CosimExecution import CosimExecution
    from libcosimpy.CosimSlave import CosimLocalSlave
    from libcosimpy.CosimObserver import CosimObserver
    from libcosimpy.CosimLogging import log_output_level, CosimLogLevel
    from libcosimpy.CosimEnums import CosimExecutionState
    log_output_level(CosimLogLevel.WARNING)
    ex = CosimExecution.from_step_size(step_size={h_ns})
    i = ex.add_local_slave(local_slave=CosimLocalSlave(fmu_path={fmu!r}, instance_name="prsm"))
    v = {{x.name.decode(): x.reference for x in ex.slave_variables(i)}}
    obs = CosimObserver.create_last_value()
    ex.add_observer(obs)
    ex.real_initial_value(i, v["screw_torque"], {u[0]!r})
    ex.real_initial_value(i, v["load_force"], {u[1]!r})
    for name, value in {start!r}.items():
        assert ex.real_initial_value(i, v[name], value)
    rows, ok = [], []
    for k in range({steps}):
        ok.append(bool(ex.step()))
        rows.append(obs.last_real_values(i, [v[n] for n in {outputs!r}]))
    print(json.dumps({{"rows": rows, "ok": ok, "enumerations": sorted(
        n for n in ("fidelity", "stepper", "step_fidelity") if n in v),
        "state": CosimExecutionState(ex.status().state).name}}))
"""


def _libcosim_times(n: int) -> list[tuple[float, float]]:
    """libcosim's doStep arguments: time in ns converted as ns / 1e9, h as a difference."""
    t = [k * H_NS / 1e9 for k in range(n + 1)]
    return [(t[k], t[k + 1] - t[k]) for k in range(n)]


@pytest.fixture(scope="module")
def dynamic_native(tmp_path_factory) -> Path:
    """The native PRSM2 built with the start value fidelity = dynamic."""
    import importlib.util

    if importlib.util.find_spec("ziglang") is None or sys.platform != "linux":
        pytest.skip("the native FMU is built here with ziglang's C compiler, run on Linux")
    dest = tmp_path_factory.mktemp("prsm2_native_dynamic")
    proc = subprocess.run([sys.executable, "-m", "fmu_build", "PRSM2", "--native", "--platform",
                           "linux64", "--dest", str(dest), "--start", "fidelity=dynamic"],
                          env=subprocess_env(),
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    return dest / "PRSM2-native.fmu"


@pytest.mark.parametrize("name", NAMES + ("PRSM2 dynamic", "PRSM2 native dynamic"))
def test_libcosim_runs_the_fmus_bit_for_bit_as_fmpy(name, request):
    pytest.importorskip("libcosimpy")
    dynamic = name.endswith("dynamic")
    fmu = (request.getfixturevalue("dynamic_native" if "native" in name else "dynamic_prsm2")
           if dynamic else built_fmus()[name])
    status, data, err = child(LIBCOSIM.format(fmu=str(fmu), h_ns=H_NS, u=U, start={},
                                              steps=STEPS, outputs=OUTPUTS))
    assert status == 0 and data, err[-2000:]
    assert all(data["ok"]) and data["enumerations"] == []      # libcosim drops Enumerations
    # fmpy sets fidelity 2 (dynamic) as well: the same steps as the start value gave libcosim
    assert data["rows"] == fmpy_run(fmu, _libcosim_times(STEPS), {"fidelity": 2} if dynamic else {})
    assert data["rows"][-1][0] > 0.0                                  # it moved


def test_libcosim_meets_a_bad_parameter_with_a_refused_step_not_an_abort():
    """docs/fmu.md: initialization logs the parameter and its range as an error (fmi2OK), the
    first doStep is fmi2Discard; libcosim stops the execution (state ERROR, step() False) and
    the process goes on (with fmi2Fatal, libcosim would end it)."""
    pytest.importorskip("libcosimpy")
    status, data, err = child(LIBCOSIM.format(
        fmu=str(built_fmus()["PRSM2"]), h_ns=H_NS, u=U,
        start={"stage[2].spline_radius": 1e-30}, steps=2, outputs=OUTPUTS))
    assert status == 0 and data, err[-2000:]
    assert data["ok"] == [False, False] and data["state"] == "ERROR"
    assert number_after(err, "stage[2].spline_radius = ") == 1e-30 and " m is out of range" in err


# ---- fmu-manipulation-toolbox's container ------------------------------------------------------

def _container(fmu: Path, dest: Path) -> Path:
    """A container FMU holding ``fmu`` (parameters exposed as <name lower>.<parameter>)."""
    dest.mkdir(parents=True, exist_ok=True)
    (dest / fmu.name).write_bytes(fmu.read_bytes())
    name = f"{fmu.stem}_container.fmu"
    (dest / "container.json").write_text(json.dumps({
        "name": name, "fmu": [fmu.name], "auto_input": True, "auto_output": True,
        "auto_parameter": True, "step_size": 1e-3}))
    tool = Path(sys.executable).parent / "fmucontainer"
    proc = subprocess.run([str(tool), "-container", "container.json", "-fmu-directory",
                           str(dest), "-auto-parameter"], cwd=dest, capture_output=True,
                          text=True, timeout=300)
    assert proc.returncode == 0 and (dest / name).is_file(), proc.stdout + proc.stderr
    return dest / name


CONTAINER = """
    import json
    from fmpy import simulate_fmu
    from fmpy.fmi1 import FMICallException
    try:
        r = simulate_fmu({fmu!r}, start_values={start!r}, stop_time={stop!r},
                         output_interval=1e-3, output={outputs!r})
    except FMICallException as exc:
        print(json.dumps({{"status": exc.status, "function": exc.function}}))
    else:
        print(json.dumps({{"time": [float(t) for t in r["time"]], "status": 0,
                          "rows": [[float(x) for x in list(row)[1:]] for row in r][1:]}}))
"""


@pytest.mark.parametrize("name", NAMES)
def test_the_container_runs_the_fmus_bit_for_bit_as_fmpy(name, tmp_path):
    pytest.importorskip("fmu_manipulation_toolbox")
    fmu = built_fmus()[name]
    container = _container(fmu, tmp_path)
    prefix = name.lower()
    # the container exposes the Enumeration as an Integer parameter: it sets it by value
    start = {f"{prefix}.fidelity": 2, "screw_torque": U[0], "load_force": U[1]}
    status, data, err = child(CONTAINER.format(fmu=str(container), start=start,
                                               stop=STEPS * 1e-3, outputs=list(OUTPUTS)))
    assert status == 0 and data, err[-2000:]
    assert data["rows"] == fmpy_run(fmu, [(k * 1e-3, 1e-3) for k in range(STEPS)],
                                    {"fidelity": 2})


def test_the_container_passes_a_refused_step_to_its_host_as_an_error(tmp_path):
    """A bad parameter set through the container: the embedded FMU refuses the first doStep
    (fmi2Discard, the reason logged); the container reports that to its host as fmi2Error
    ("Container: FMU 'PRSM2.fmu' failed doStep"), so fmpy raises instead of ending quietly."""
    pytest.importorskip("fmu_manipulation_toolbox")
    container = _container(built_fmus()["PRSM2"], tmp_path)
    start = {"prsm2.stage[2].spline_radius": 1e-30, "screw_torque": U[0]}
    status, data, err = child(CONTAINER.format(fmu=str(container), start=start, stop=0.01,
                                               outputs=list(OUTPUTS)))
    assert status == 0 and data, err[-2000:]
    assert data == {"status": 3, "function": "fmi2DoStep"}
    assert "failed doStep" in err


# ---- Ecos -------------------------------------------------------------------------------------

ECOS = """
    import ctypes, json, os, sys
    # Ecos's library needs libtbb.so.12: PyPI's tbb wheel puts it in the environment's lib
    ctypes.CDLL(os.path.join(sys.prefix, "lib", "libtbb.so.12"), mode=ctypes.RTLD_GLOBAL)
    from ecospy.EcosSimulationStructure import EcosSimulationStructure
    from ecospy.EcosSimulation import EcosSimulation
    ss = EcosSimulationStructure()
    ss.add_model("prsm", {fmu!r})
    out = {{"rows": [], "error": None}}
    with EcosSimulation(structure=ss, step_size=1e-3) as sim:
        sim.set_real("prsm::screw_torque", {u[0]!r})
        sim.set_real("prsm::load_force", {u[1]!r})
        for name, value in {start!r}.items():
            sim.set_real("prsm::" + name, value)
        try:
            sim.init()
            for k in range({steps}):
                sim.step()
                out["rows"].append([sim.get_real("prsm::" + n) for n in {outputs!r}])
        except Exception as exc:
            out["error"] = str(exc)
        out["time"] = sim.get_time()
        sim.terminate()
    print(json.dumps(out))
"""


def _ecos_ready() -> None:
    import importlib.util

    if importlib.util.find_spec("ecospy") is None:      # importing it needs libtbb first
        pytest.skip("ecospy is not installed")
    lib = Path(sys.prefix) / "lib" / "libtbb.so.12"
    if not lib.is_file():
        pytest.fail("libtbb.so.12 is missing: install the test extra (it brings PyPI's tbb)")


def test_ecos_runs_prsm2_bit_for_bit_as_fmpy(dynamic_prsm2):
    _ecos_ready()
    status, data, err = child(ECOS.format(fmu=str(dynamic_prsm2), u=U, start={}, steps=STEPS,
                                          outputs=OUTPUTS))
    assert status == 0 and data and data["error"] is None, err[-2000:]
    times, t = [], 0.0
    for _ in range(STEPS):                      # Ecos accumulates its time: t += h
        times.append((t, 1e-3))
        t += 1e-3
    assert data["rows"] == fmpy_run(dynamic_prsm2, times, {"fidelity": 2})


def test_ecos_goes_on_past_a_refused_step_with_nan_outputs():
    _ecos_ready()
    status, data, err = child(ECOS.format(fmu=str(built_fmus()["PRSM2"]), u=U,
                                          start={"stage[2].spline_radius": 1e-30}, steps=2,
                                          outputs=OUTPUTS))
    assert status == 0 and data, err[-2000:]
    # Ecos does not stop on fmi2Discard: its time runs on, while the FMU refuses every step
    # and its outputs stay NaN; it prints none of the FMU's messages (docs/fmu.md, "Hosts")
    assert data["error"] is None and data["time"] == pytest.approx(2e-3)
    assert len(data["rows"]) == 2 and all(math.isnan(x) for r in data["rows"] for x in r)
