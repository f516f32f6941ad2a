"""The native FMU (``python -m fmu_build --native``): one source of truth with the Python FMU.

The native FMUs are built once per session in a child process (as the Python FMUs are,
tests/test_fmu.py).  Expected values are the Python FMU's outputs on the same inputs (the C
translation must add nothing: 1e-12 of each output's largest magnitude, docs/accuracy.md §1), FMI's
rules for refused calls, and the FMU's own outputs before a refused call or a saved state.
"""

from __future__ import annotations

import functools
import math
import os
import random
import shutil
import subprocess
import sys
import tempfile
import xml.etree.ElementTree as ET
import zipfile
from pathlib import Path

import pytest

fmpy = pytest.importorskip("fmpy")
pytest.importorskip("pythonfmu")

from fmpy import read_model_description  # noqa: E402
from fmpy.validation import validate_fmu  # noqa: E402

from conftest import shared_build  # noqa: E402
from test_fmu import OK, DISCARD, Host, built_fmus, max_relative_difference, subprocess_env  # noqa: E402
from test_fmu_c_host import STEPS as HOST_STEPS, c_host  # noqa: E402,F401 - fixture
from text_numbers import number_after  # noqa: E402
from zig_skip import skip_without_ziglang  # noqa: E402

#: the standard FMUs, PRSM1 (the friction-torque article's preset, with its viscous and
#: differential-sliding terms) included
NATIVE = ("PRSM1", "PRSM2", "PRSM3")
ERROR = 3
H = 1e-3
#: the Python FMU's stepper that runs the native FMU's default method: ``closed_form``, the
#: friction band stepped by the scalar exponential step (prsm_band.c in C)
PY_SAME_METHOD = {"stepper": "closed_form"}

#: the per-stage parameters the contact geometry is computed from (the C solves it at
#: initialization; tests/test_native_geometry.py)
GEOMETRY = ("screw_radius", "roller_radius", "nut_radius", "screw_lead", "screw_starts",
            "flank_angle")


@functools.cache
def built_native(platforms: tuple[str, ...] = ("linux64",)) -> dict[str, Path]:
    """Build PRSM1/2/3-native.fmu once per test session for ``platforms`` (shared by
    pytest-xdist's workers: tests/conftest.py), in a child process.  By default for linux64
    only, the binary the tests run: the cross-compiled win64 and darwin64 ones (on a fresh
    machine Zig first builds its runtimes for them, minutes) are built and read by
    tests/test_platform_binaries.py alone."""
    def build(dest: Path) -> None:
        chosen = [a for p in platforms for a in ("--platform", p)]
        proc = subprocess.run([sys.executable, "-m", "fmu_build", "--native", *chosen, *NATIVE,
                               "--dest", str(dest)], env=subprocess_env(), capture_output=True,
                              text=True, timeout=600)
        assert proc.returncode == 0, \
            f"python -m fmu_build --native failed:\n{proc.stdout}\n{proc.stderr}"

    dest = shared_build("prsm_native_" + "_".join(platforms), build)
    return {n: dest / f"{n}-native.fmu" for n in NATIVE}


@pytest.fixture(scope="module")
def native() -> dict[str, Path]:
    if sys.platform != "linux":
        pytest.skip("the native FMU is built here for Linux only")
    skip_without_ziglang(module_level=False)
    return built_native()


def same(a: list[list], b: list[list]) -> bool:
    """Rows equal value for value, a NaN (the efficiency where no power passes through)
    equal to a NaN in the same place (Python's == says NaN != NaN)."""
    def key(rows):
        return [["NaN" if isinstance(x, float) and math.isnan(x) else x for x in r] for r in rows]
    return key(a) == key(b)


def native_host(name: str = "PRSM2", **kw) -> Host:
    return Host(name, path=built_native()[name], **kw)


def loop(host: Host, n: int, load: float, names, k0: int = 0, state=(0.0, None)):
    """The PI speed loop of test_fmu.controller (reference 100 -> -60 rad/s at step 150) with
    load ``load`` [N]; outputs ``names`` after each step and the loop's (integral, speed)."""
    integral, speed = state
    if speed is None:
        speed = host.get_real(["screw_speed"])[0]
    vr_in = [host.vars["screw_torque"].valueReference, host.vars["load_force"].valueReference]
    rows = []
    for k in range(k0, k0 + n):
        ref = 100.0 if k < 150 else -60.0
        err = ref - speed
        integral = integral + err * H
        torque = min(40.0, max(-40.0, 0.05 * err + 2.0 * integral))
        host.fmu.setReal(vr_in, [torque, load])
        assert host.step(k * H) == OK, host.messages
        rows.append(host.get(names))
        speed = host.get_real(["screw_speed"])[0]
    return rows, (integral, speed)


def all_outputs(host: Host) -> list[str]:
    return [v.name for v in host.md.modelVariables if v.causality == "output"]


def both_loops(name: str, py_start: dict, native_start: dict, load: float, n: int = 400):
    """:func:`loop` through the Python and the native FMU ``name``: (Python rows, native rows,
    output names)."""
    runs = []
    for host in (Host(name, start=py_start), native_host(name, start=native_start)):
        try:
            names = all_outputs(host)
            runs.append(loop(host, n, load, names)[0])
        finally:
            host.free()
    return runs[0], runs[1], names


# ---- the modelDescription -----------------------------------------------------------------------

@pytest.mark.parametrize("name", NATIVE)
def test_model_description_mirrors_the_python_fmu_and_validates(native, name):
    fmu = native[name]
    assert validate_fmu(str(fmu)) == []
    md, py = read_model_description(str(fmu)), read_model_description(str(built_fmus()[name]))
    assert md.coSimulation.modelIdentifier == f"{name}_native" and md.guid != py.guid
    assert not md.coSimulation.needsExecutionTool
    assert md.coSimulation.canGetAndSetFMUstate and md.coSimulation.canSerializeFMUstate
    # model exchange adds, after the Python FMU's variables, the carrier states' derivatives
    stages = int(name[-1])
    assert [(v.name, v.causality, v.unit) for v in md.modelVariables[len(py.modelVariables):]] \
        == [(f"stage[{k}].carrier_acceleration", "local", "rad/s2") for k in range(1, stages + 1)]
    for v, p in zip(md.modelVariables, py.modelVariables):
        assert (v.name, v.valueReference, v.type, v.unit, v.description, v.start) == \
               (p.name, p.valueReference, p.type, p.unit, p.description, p.start)
        # the geometry too: tunable at initialization, its contact solved then
        assert (v.causality, v.variability) == (p.causality, p.variability), v.name
    with zipfile.ZipFile(fmu) as z:
        names = set(z.namelist())
        listed = [f.get("name") for f in ET.fromstring(z.read("modelDescription.xml"))
                  .iterfind("CoSimulation/SourceFiles/File")]
        assert listed and all(f"sources/{f}" in names for f in listed)
        # the compile lines of the sources' README name every listed source
        readme = z.read("sources/README.txt").decode()
        assert all(f in line for f in listed for line in readme.splitlines()
                   if line.strip().startswith(("Linux", "macOS", "Windows")))
        so = z.read(f"binaries/linux64/{name}_native.so")
        assert not any(n.startswith("resources/") for n in names)      # no Python inside
    lib = Path(tempfile.mkdtemp()) / "lib.so"
    lib.write_bytes(so)
    if shutil.which("readelf"):
        dyn = subprocess.run(["readelf", "-d", str(lib)], capture_output=True, text=True).stdout
        needed = {line.split("[")[1].split("]")[0] for line in dyn.splitlines() if "(NEEDED)" in line}
        assert needed <= {"libc.so.6", "libm.so.6"}, needed


# ---- one source of truth ------------------------------------------------------------------------

@pytest.mark.parametrize("fidelity,load,stepper", [("quasi-static", 3000.0, None),
                                                   ("quasi-static", -3000.0, None),
                                                   ("kinematic", 3000.0, None),
                                                   ("quasi-static", 3000.0, "closed_form_explicit")])
def test_closed_loop_with_reversal_equals_python_fmu_to_1e_12(native, fidelity, load, stepper):
    """The native FMU's default (``closed_form``) and its ``closed_form_explicit`` against the
    Python FMU's same stepper."""
    start = {"fidelity": fidelity}
    if fidelity == "kinematic":
        start["kinematic_efficiency"] = 0.85
    method = PY_SAME_METHOD if stepper is None else {"stepper": stepper}
    py, nat, names = both_loops("PRSM2", {**start, **method}, {**start, **method} if stepper else start,
                                load)
    assert same(nat, py)                                          # bit for bit
    i_speed, i_calls = names.index("screw_speed"), names.index("step_rhs_calls")
    speeds = [r[i_speed] for r in py]
    assert min(speeds) < -50.0 < 90.0 < max(speeds)              # it reversed
    assert max(r[i_calls] for r in py) > 1                        # the band's numerical steps ran
    assert [r[i_calls] for r in nat] == [r[i_calls] for r in py]  # ... the same ones


@pytest.mark.parametrize("name,start,load", [
    ("PRSM2", {"tolerance": 1e-3}, 3000.0),
    ("PRSM2", {"tolerance": 1e-2, "initial_screw_speed": 50.0,
               "initial_carrier_equilibrium": True}, -1000.0),
    ("PRSM3", {"tolerance": 1e-3}, 2000.0),
    ("PRSM1", {"tolerance": 1e-2}, 500.0)])
def test_auto_equals_the_python_fmu_bit_for_bit_and_switches(native, name, start, load):
    """fidelity = auto in the speed loop with a reversal: the native FMU (prsm_auto.c) chooses
    the same start level and the same level at every step as the Python FMU (whose engine runs
    the same C; the start level is chosen in Python there), and every output is equal, the rhs
    calls and step_fidelity among them; the run switches between the dynamic and the
    quasi-static level."""
    start = {"fidelity": "auto", **start}
    py, nat, names = both_loops(name, start, start, load)
    assert same(nat, py)                                          # bit for bit
    i_speed, i_level = names.index("screw_speed"), names.index("step_fidelity")
    speeds = [r[i_speed] for r in py]
    assert min(speeds) < -50.0 < 90.0 < max(speeds)              # it reversed
    levels = [r[i_level] for r in py]
    assert set(levels) == {1, 2}, levels                          # both levels ran
    print(f"{name} {start}: {sum(a != b for a, b in zip(levels, levels[1:]))} level switches "
          f"in {len(levels)} steps")


@pytest.mark.parametrize("fidelity,stepper", [("quasi-static", None), ("kinematic", None),
                                              ("quasi-static", "closed_form_explicit"),
                                              ("dynamic", None)])
def test_friction_preset_prsm1_equals_the_python_fmu_bit_for_bit(native, fidelity, stepper):
    """PRSM1, the friction-torque article's single stage with its viscous (mu_1) and
    differential-sliding (mu_3) terms: the native FMU's outputs, the per-term friction powers
    among them, equal the Python FMU's with the same stepper in the speed loop with a reversal."""
    start = {"fidelity": fidelity, **({"stepper": stepper} if stepper else {})}
    py, nat, names = both_loops("PRSM1", {**start, **({} if stepper or fidelity == "dynamic"
                                                        else PY_SAME_METHOD)}, start, 500.0,
                                n=300)
    assert same(nat, py)
    i_visc, i_diff = names.index("friction_power_viscous"), names.index("friction_power_differential")
    assert max(abs(r[i_visc]) for r in py) > 0.0 and max(abs(r[i_diff]) for r in py) > 0.0


@pytest.mark.parametrize("name,load,start", [
    ("PRSM2", 3000.0, {}), ("PRSM2", -3000.0, {"tolerance": 1e-8}),
    # three stages: four unknowns in the iteration matrix (the general LU, not the unrolled one)
    ("PRSM3", -2000.0, {"initial_carrier_equilibrium": True}),
    ("PRSM2", 3000.0, {"substeps": 3})])
def test_dynamic_level_equals_python_fmu_step_for_step(native, name, load, start):
    """ROS34PW2 in C against the Python FMU's: the same outputs and the same rhs calls in every
    step of a speed loop that accelerates the screw, reverses it (zero-speed crossing, the
    friction band) and holds it; adaptive (continuation, Jacobian reuse, rejections) and fixed
    substeps."""
    start = {"fidelity": "dynamic", **start}
    py, nat, names = both_loops(name, start, start, load)
    assert same(nat, py)                                          # bit for bit
    i_speed, i_calls = names.index("screw_speed"), names.index("step_rhs_calls")
    i_carrier = names.index("stage[1].carrier_speed_ratio")
    speeds = [r[i_speed] for r in py]
    assert min(speeds) < -50.0 < 90.0 < max(speeds)              # it reversed
    assert len({r[i_carrier] for r in py}) > 100                  # the carriers are states
    assert [r[i_calls] for r in nat] == [r[i_calls] for r in py]  # the same internal steps


def test_dynamic_level_with_inputs_changing_every_step_equals_python_fmu_bit_for_bit(native):
    """1000 steps of 1 ms from 100 rad/s, carriers at equilibrium, with a new torque and load in
    every step (load 5000 + 1000 sin(2 pi 25 t) N, torque 19.75 N.m per 5000 N of it plus
    sin(2 pi 40 t) N.m): every output equal.  (Where C computed x ** 2 as x * x, which rounds
    differently from libm's pow in about 1 of 1000 cases, an error norm, then a step size,
    differed in the last bit from step 130 on.)"""
    import math

    start = {"fidelity": "dynamic", "initial_screw_speed": 100.0,
             "initial_carrier_equilibrium": True}
    runs = []
    for host in (Host("PRSM2", start=start), native_host(start=start)):
        try:
            names = all_outputs(host)
            vr_in = [host.vars["screw_torque"].valueReference, host.vars["load_force"].valueReference]
            rows = []
            for k in range(1000):
                t = k * H
                load = 5000.0 + 1000.0 * math.sin(2 * math.pi * 25 * t)
                host.fmu.setReal(vr_in, [19.75 * load / 5000.0 + math.sin(2 * math.pi * 40 * t), load])
                assert host.step(t) == OK, host.messages
                rows.append(host.get(names))
            runs.append(rows)
        finally:
            host.free()
    py, nat = runs
    assert same(nat, py)


@pytest.mark.parametrize("torque,load", [(1e6, 0.0), (40.0, -1e8)])
def test_dynamic_level_at_the_inputs_bounds_steps_as_the_python_fmu(native, torque, load):
    """Inputs at their bounds (1e6 N.m; 1e8 N pulling) for 1 ms: the screw ends near 2e6 and
    6e5 rad/s, far below the speed bound the kinetic energy allows (about 1e76 rad/s for
    PRSM2's inertias: docs/fmu.md, bounds of the state), and both FMUs take the step with the
    same, finite outputs.  (Before the speed bound followed from the inertias, a constant
    1e5 rad/s refused both steps in both FMUs.)"""
    rows = []
    for host in (Host("PRSM2", start={"fidelity": "dynamic"}),
                 native_host(start={"fidelity": "dynamic"})):
        try:
            vr = [host.vars["screw_torque"].valueReference, host.vars["load_force"].valueReference]
            host.fmu.setReal(vr, [torque, load])
            assert host.step(0.0) == OK
            rows.append(host.get_real(host.outputs))
            names = host.outputs
        finally:
            host.free()
    py, nat = rows
    speed = py[names.index("screw_speed")]
    print(f"  screw speed after 1 ms: {speed} rad/s")
    assert abs(speed) > 1e5                      # beyond the constant bound of before
    assert all(math.isfinite(v) for n, v in zip(names, py) if n != "efficiency")
    assert same([nat], [py])


def test_random_states_both_flanks_both_load_directions_equal_python_fmu(native):
    rnd = random.Random(16)
    flank_signs = set()
    for case in range(10):
        fidelity = ("quasi-static", "kinematic")[case % 2]
        speed0 = rnd.choice([rnd.uniform(-0.05, 0.05), rnd.uniform(-150.0, 150.0)])
        start = {"fidelity": fidelity, "initial_screw_speed": speed0,
                 "initial_screw_angle": rnd.uniform(-10.0, 10.0),
                 "mu_screw_roller": rnd.uniform(0.02, 0.15), "mu_spline": rnd.uniform(0.0, 0.3),
                 "kinematic_efficiency": rnd.uniform(0.6, 1.0)}
        inputs = [(rnd.uniform(-30.0, 30.0), rnd.choice([-1.0, 1.0]) * rnd.uniform(0.0, 8000.0))
                  for _ in range(25)]
        runs = []
        for host in (Host("PRSM2", start={**start, **PY_SAME_METHOD}), native_host(start=start)):
            try:
                names = all_outputs(host)
                vr_in = [host.vars["screw_torque"].valueReference,
                         host.vars["load_force"].valueReference]
                rows = []
                for k, u in enumerate(inputs):
                    host.fmu.setReal(vr_in, list(u))
                    assert host.step(k * H) == OK, host.messages
                    rows.append(host.get(names))
                runs.append(rows)
            finally:
                host.free()
        assert same(runs[1], runs[0]), (case, start)              # bit for bit
        i = names.index("stage[2].contact_force")
        flank_signs |= {r[i] > 0.0 for r in runs[0]}
    assert flank_signs == {True, False}          # both flanks carried the load


# ---- refusals and the state machine ------------------------------------------------------------

def _last(host: Host) -> str:
    return host.messages[-1][1] if host.messages else ""


def test_refused_calls_are_logged_and_change_nothing(native):
    from fmpy.fmi1 import FMICallException

    host = native_host(initialize=False)
    try:
        assert host.step(0.0) == ERROR and "before fmi2ExitInitializationMode" in _last(host)
        host.fmu.exitInitializationMode()
        names = all_outputs(host)
        loop(host, 20, 3000.0, names)
        before = host.state_bytes()
        y0 = host.get(names)
        vr_t = host.vars["screw_torque"].valueReference
        torque = host.get_real(["screw_torque"])
        host.fmu.setReal([vr_t], [float("nan")])
        assert host.step(20 * H) == DISCARD and "screw_torque" in _last(host)
        host.fmu.setReal([vr_t], [1.0])
        assert host.step(20 * H, 0.0) == DISCARD and "step size" in _last(host)
        assert host.step(21 * H) == ERROR and "currentCommunicationPoint" in _last(host)
        for call in (lambda: host.fmu.getInteger([host.vars["screw_speed"].valueReference]),
                     lambda: host.fmu.setReal([host.vars["screw_speed"].valueReference], [1.0]),
                     lambda: host.fmu.setReal([host.vars["stage[1].screw_lead"].valueReference], [0.02]),
                     lambda: host.fmu.setReal([host.vars["mu_screw_roller"].valueReference], [0.1])):
            with pytest.raises(FMICallException) as exc:
                call()
            assert exc.value.status == ERROR and host.messages[-1][0] == ERROR
        assert "Real" in host.messages[-4][1]
        assert "'stage[1].screw_lead' is a fixed parameter" in host.messages[-2][1]
        host.fmu.setReal([vr_t], torque)           # the input as it was: the state is too
        assert host.get(names) == y0 and host.state_bytes() == before
        host.fmu.terminate()
        assert host.step(20 * H) == ERROR and "after fmi2Terminate" in _last(host)
        host.fmu.freeInstance()
    except BaseException:
        host.free()
        raise


@pytest.mark.parametrize("start,word", [({"fidelity": "auto", "stepper": "closed_form"},
                                         "stepper"),
                                        ({"stepper": "rosenbrock"}, "stepper"),
                                        # the dynamic level runs ROS34PW2 only
                                        ({"fidelity": "dynamic", "stepper": "explicit_adaptive"},
                                         "stepper"),
                                        ({"stepper": "exponential"}, "stepper"),
                                        ({"mu_screw_roller": 0.9}, "mu_screw_roller"),
                                        # the friction-torque article's terms' bounds (1e5, 1e-3)
                                        ({"mu_viscous": 2e5}, "mu_viscous"),
                                        ({"mu_differential": 2e-3}, "mu_differential"),
                                        ({"stage[2].nut_mass": -1.0}, "stage[2].nut_mass")])
def test_initialization_refuses_what_it_does_not_run(native, start, word):
    from fmpy.fmi1 import FMICallException

    host = native_host(start=start, initialize=False)
    with pytest.raises(FMICallException) as exc:
        host.fmu.exitInitializationMode()
    assert exc.value.status == ERROR
    assert word in _last(host) and _last(host).startswith("initialization failed")
    host.fmu.freeInstance()


def test_generator_pins_unmodelled_parameters_to_zero_and_refuses_unknown_outputs(native):
    from fmu_build import BuildError
    from fmu_build.native import variables_header
    from prsm_fmu import presets

    with zipfile.ZipFile(built_fmus()["PRSM2"]) as z:
        md = z.read("modelDescription.xml")
    params = presets.load("li2021_two_stage")

    def with_variable(name: str, causality: str, start: str | None) -> bytes:
        root = ET.fromstring(md)
        mv = root.find("ModelVariables")
        sv = ET.SubElement(mv, "ScalarVariable", name=name, valueReference="999",
                           causality=causality, variability="fixed" if start else "continuous",
                           description="x")
        ET.SubElement(sv, "Real", {"start": start} if start else {})
        return ET.tostring(root)

    # every parameter of the real FMU is modelled (the viscous and differential-sliding terms
    # too); a parameter added to it is pinned to its start value
    base = variables_header(md, params, "X", "g")
    assert '#define N_UNMODELLED 0' in base
    header = variables_header(with_variable("mu_new_term", "parameter", "0.0"), params, "X", "g")
    assert '#define N_UNMODELLED 1' in header and '"mu_new_term"' in header
    with pytest.raises(BuildError, match="mu_new_term"):
        variables_header(with_variable("mu_new_term", "parameter", "0.1"), params, "X", "g")
    with pytest.raises(BuildError, match="viscous_torque"):
        variables_header(with_variable("viscous_torque", "output", None), params, "X", "g")


# ---- FMU state -------------------------------------------------------------------------------------

@pytest.mark.parametrize("fidelity", ["quasi-static", "dynamic", "auto"])
def test_fmu_state_round_trip_is_bit_exact_and_checked_whole(native, fidelity):
    from fmpy.fmi1 import FMICallException

    # auto at a tolerance where it switches (the level is part of the state)
    start = {"fidelity": fidelity, **({"tolerance": 1e-3} if fidelity == "auto" else {})}
    a = native_host(start=start)
    b = native_host(start=start)
    try:
        names = all_outputs(a)
        _, lp = loop(a, 140, 3000.0, names)              # state saved before the reversal
        state = a.fmu.getFMUstate()
        data = bytes(a.fmu.serializeFMUstate(state))
        ref, _ = loop(a, 60, 3000.0, names, k0=140, state=lp)
        a.fmu.setFMUstate(state)                         # rewind the same instance
        again, _ = loop(a, 60, 3000.0, names, k0=140, state=lp)
        b.fmu.setFMUstate(b.fmu.deSerializeFMUstate(data))   # another instance, from bytes
        other, _ = loop(b, 60, 3000.0, names, k0=140, state=lp)
        assert same(again, ref) and same(other, ref)
        bad = bytearray(data)
        bad[0] ^= 0xFF
        for junk in (bytes(bad), data[:-8]):
            before = b.state_bytes()
            with pytest.raises(FMICallException):
                b.fmu.deSerializeFMUstate(junk)
            assert b.messages[-1][0] == ERROR and b.state_bytes() == before
        a.fmu.freeFMUstate(state)
    finally:
        a.free()
        b.free()


# ---- a host without Python --------------------------------------------------------------------------

def test_c_host_runs_the_native_fmu_without_python_equal_to_python_fmu(native, c_host):
    from test_fmu import run_fmu
    from test_fmu_c_host import OUTPUTS

    ref = Host("PRSM2", start={"fidelity": "quasi-static", **PY_SAME_METHOD})
    try:
        expected = run_fmu(ref, HOST_STEPS, OUTPUTS)
    finally:
        ref.free()
    nat = native_host(initialize=False)
    vr = {n: v.valueReference for n, v in nat.vars.items()}
    guid = nat.md.guid
    nat.fmu.freeInstance()
    from test_fmu import unzipped_path

    unzip = unzipped_path(built_native()["PRSM2"])
    env = {k: v for k, v in os.environ.items() if not k.startswith(("PYTHON", "LD_"))}
    args = [str(c_host), str(unzip / "binaries" / "linux64" / "PRSM2_native.so"),
            (unzip / "resources").as_uri(), guid, "1", str(HOST_STEPS),  # fidelity 1: quasi-static
            str(vr["screw_torque"]), str(vr["load_force"]), str(vr["fidelity"]),
            str(vr["screw_speed"])] + [str(vr[n]) for n in OUTPUTS]
    proc = subprocess.run(args, env=env, capture_output=True, text=True, timeout=60)
    assert proc.returncode == 0, proc.stderr[-3000:]
    got = [[float(v) for v in line.split()] for line in proc.stdout.splitlines()]
    assert len(got) == HOST_STEPS
    assert max_relative_difference(got, expected) <= 1e-12
    assert min(r[0] for r in got) < -50.0 < 90.0 < max(r[0] for r in got)   # it did reverse


# ---- the regression suite and the actuator loop ---------------------------------------------------

@pytest.mark.parametrize("case", ["startup_li2021_quasi-static", "startup_li2021_dynamic"])
def test_regression_case_passes_with_the_native_fmu(native, case):
    from prsm_fmu.regress import core

    (result,) = core.check(built_native()["PRSM2"], core.DEFAULT_DIR, cases=[case])
    assert result.passed, result.error or [r for r in result.results if not r.passed]
    assert len(result.results) >= 10          # every stored output was compared


def test_actuator_loop_with_the_native_fmu_equals_the_python_fmu(native, tmp_path, capsys):
    """``prsm-ema run --prsm native``: the position-step loop (quasi-static) through the native
    FMU equals the same loop through the Python FMU running the native FMU's method
    (``closed_form``) to 1e-9 of each output's largest magnitude.  Independent reason:
    both take the same steps with the same arithmetic (1e-12 per step in the tests above); the
    loop (PI controller, motor, load) only passes the values on, over 300 steps here."""
    import numpy as np

    from system_models.cli import main
    from system_models.run import run_scene
    from system_models.scenes import load_scene
    from test_fmu import built_fmus

    text = load_scene("position_step").path.read_text(encoding="utf-8")
    # 30 ms of the scene, without its checks (they judge the whole 0.25 s response)
    short = text.replace("t_end = 0.25 ", "t_end = 0.03 ").split("[[check]]")[0]
    assert "t_end = 0.03 " in short
    scene_native = tmp_path / "step_native.toml"
    scene_native.write_text(short, encoding="utf-8")
    scene_python = tmp_path / "step_python.toml"
    scene_python.write_text(short + '\n[prsm]\nparameters = { stepper = "closed_form" }\n',
                            encoding="utf-8")
    out = tmp_path / "out"
    status = main(["run", "--scene", str(scene_native), "--prsm", "native", "--fmu",
                   str(built_native()["PRSM2"]), "--no-plots", "--out", str(out)])
    assert status == 0, capsys.readouterr()
    assert "PRSM2-native.fmu" in capsys.readouterr().out
    a = run_scene(str(scene_native), prsm="fmu", fmu_path=built_native()["PRSM2"]).result
    b = run_scene(str(scene_python), prsm="fmu", fmu_path=built_fmus()["PRSM2"]).result
    names = [n for n in b.names() if n.startswith("prsm.")]
    assert len(names) >= 20
    for n in names:
        # the efficiency is NaN where no power passes through: at the same samples in both
        defined = ~np.isnan(b[n])
        assert np.array_equal(defined, ~np.isnan(a[n])), n
        scale = float(np.max(np.abs(b[n][defined]))) if defined.any() else 1.0
        assert float(np.max(np.abs(a[n] - b[n])[defined], initial=0.0)) <= 1e-9 * (scale or 1.0), n
