"""One engine under every door: the compiled core (fmu_build/native, in-process through ctypes)
runs configure() (and so the loop's Python PRSM block), simulate() and the pythonfmu FMU by
default, equal to the Python reference it translates; the Python model runs, and says why,
wherever the engine cannot.  The FMU packs what runs inside it, and two builds of one
modelIdentifier keep their own start values in one process."""

from __future__ import annotations

import random
import shutil
import struct
import subprocess
import sys
import tempfile
import zipfile
from dataclasses import replace
from pathlib import Path

import pytest

from prsm_fmu import presets
from prsm_fmu.configure import configure
from prsm_fmu.engine import fallback_reason, is_engine
from prsm_fmu.simulate import simulate

TESTS = Path(__file__).resolve().parent
sys.path.insert(0, str(TESTS))
from test_fmu import (OK, Host, built_fmus, built_prsm2_dynamic,  # noqa: E402
                      built_prsm2_reference)

pytestmark = pytest.mark.skipif(shutil.which("gcc") is None, reason="needs gcc")

SOLVER = {"fidelity": "quasi-static", "tolerance": 1e-6, "stepper": "default", "substeps": 0,
          "max_substeps": 100000, "kinematic_efficiency": 1.0, "initial_screw_speed": 0.0,
          "initial_screw_angle": 0.0, "initial_carrier_equilibrium": False}
#: the Python stepper the engine translates at each level (docs/fmu.md, "The native FMU")
REFERENCE = {"kinematic": "closed_form", "quasi-static": "closed_form",
             "dynamic": "rosenbrock", "auto": "rosenbrock"}


def _bits(values: list[float]) -> list[bytes]:
    """Each float by its bytes: equal bit for bit, a NaN (the efficiency where no power passes
    through) equal to the same NaN (Python's == says NaN != NaN)."""
    return [struct.pack("<d", v) for v in values]


# ---- configure(): the engine by default, equal to the reference ------------------------------

def _run(level: str, engine: str, stepper: str, rng: random.Random, n: int, **solver):
    """n advances of 1 ms with random inputs (torque in [-30, 30] N·m, load in [-6, 6] kN,
    new every step; the screw crosses zero speed) from a random start speed."""
    params = presets.load("li2021_two_stage")
    speed0 = rng.uniform(-150.0, 150.0)
    s = dict(SOLVER, fidelity=level, stepper=stepper, initial_screw_speed=speed0, **solver)
    model, st, x, _lvl, _name = configure(params, s, (0.0, 0.0), engine=engine)
    rows = []
    for k in range(n):
        u = (rng.uniform(-30.0, 30.0), rng.uniform(-6000.0, 6000.0))
        x, stats = st.advance(k * 1e-3, x, u, 1e-3)
        rows.append((list(x), stats.rhs_calls, stats.substeps, getattr(model, "mode", level)))
    return st, rows


@pytest.mark.parametrize("level", ["kinematic", "quasi-static", "dynamic", "auto"])
@pytest.mark.parametrize("substeps", [0, 7])
def test_configure_runs_the_engine_equal_to_the_reference_on_random_cases(level, substeps):
    """20 seeded random runs of 30 steps per level, adaptive and with 7 fixed substeps: the
    default door (engine) and the reference (engine="python" with the method the engine
    translates) give equal states and work, bit for bit; for auto (at tolerance 1e-3, where
    it switches) also the level of every step."""
    cases = 20
    tol = {"tolerance": 1e-3} if level == "auto" else {}
    switches = 0
    for case in range(cases):
        st, a = _run(level, "native", "default", random.Random(case), 30, substeps=substeps,
                     **tol)
        ref, b = _run(level, "python", REFERENCE[level], random.Random(case), 30,
                      substeps=substeps, **tol)
        assert is_engine(st) and not is_engine(ref), (st.name, ref.name)
        assert a == b, (level, substeps, case)
        if level == "auto":
            modes_a, modes_b = (tuple(r[3] for r in rows) for rows in (a, b))
            assert modes_a == modes_b, (substeps, case)
            switches += sum(m != n for m, n in zip(modes_b, modes_b[1:]))
    if level == "auto":
        assert switches > 0      # the random inputs make it switch (else this tests one level)
    print(f"{cases} random cases x 30 steps equal at {level}, substeps = {substeps}"
          + (f", {switches} level switches" if level == "auto" else ""))


@pytest.mark.parametrize("change", [{"mu_viscous": 10.0}, {"mu_differential": 1e-5}])
def test_configure_runs_the_engine_with_every_friction_term(change):
    """The viscous and differential-sliding terms are in the engine (its equality with the
    reference on random mechanisms with each term: tests/test_engine_differential.py)."""
    params = replace(presets.load("li2021_two_stage"), **change)
    _m, st, _x, _l, name = configure(params, SOLVER, (0.0, 0.0))
    assert is_engine(st) and fallback_reason(st) is None
    assert name == "closed_form"             # the reference's default at the level, translated


def test_configure_falls_back_for_a_stepper_or_level_the_engine_lacks():
    params = presets.load("li2021_two_stage")
    _m, st, *_ = configure(params, dict(SOLVER, fidelity="dynamic", stepper="exponential"),
                           (0.0, 0.0))
    assert st.name == "exponential" and "'exponential' is not the engine's" in fallback_reason(st)
    _m, st, *_ = configure(params, dict(SOLVER, fidelity="auto", stepper="explicit_adaptive"),
                           (0.0, 0.0))
    assert st.name == "auto(explicit_adaptive)"
    assert "'explicit_adaptive' is not the engine's" in fallback_reason(st)
    # the reference asked for: no engine, no reason
    _m, st, *_ = configure(params, SOLVER, (0.0, 0.0), engine="python")
    assert st.name == "closed_form" and fallback_reason(st) is None


def test_configure_runs_auto_on_the_engine():
    """fidelity = auto runs on the engine (its dynamic steps ROS34PW2's), without fallback."""
    params = presets.load("li2021_two_stage")
    model, st, _x, level, name = configure(params, dict(SOLVER, fidelity="auto"), (0.0, 0.0))
    assert level == "auto" and model.fidelity == "auto"
    assert is_engine(st) and fallback_reason(st) is None
    assert name == "rosenbrock"


def test_configure_refuses_an_unknown_engine():
    with pytest.raises(ValueError, match=r"engine = 'c' is not allowed: must be one of "
                                         r"'native', 'python'"):
        configure(presets.load("li2021_two_stage"), SOLVER, (0.0, 0.0), engine="c")


def test_simulate_runs_the_engine_equal_to_the_reference():
    """Li et al. (2021) §3.1's start-up (100 rad/s held, carriers at rest, 5 kN) at the dynamic
    level over 2 ms in 10 µs steps: engine and reference equal bit for bit."""
    p = presets.load("li2021_two_stage")
    kw = dict(fidelity="dynamic", drive="speed", screw_speed=100.0, load_force=5000.0,
              t_end=2e-3, output_interval=1e-5, rtol=1e-6, atol=1e-8)
    a = simulate(p, **kw)
    b = simulate(p, engine="python", **kw)
    assert a["engine"] == "native" and b["engine"] == "python"
    for name in ("screw_speed", "stage[1].carrier_speed", "stage[2].carrier_speed",
                 "stage[1].contact_force"):
        assert list(a[name]) == list(b[name]), name
    assert a["rhs_calls"] == b["rhs_calls"]


# ---- the pythonfmu FMU ------------------------------------------------------------------------

@pytest.fixture(scope="module")
def builds() -> dict[str, Path]:
    """PRSM2 three ways, each built in a child process once per session (tests/test_fmu.py):
    plain, ``--start fidelity=dynamic`` and ``--engine python`` (the reference)."""
    return {"plain": built_fmus()["PRSM2"], "dynamic": built_prsm2_dynamic(),
            "reference": built_prsm2_reference()}


def test_the_fmu_packs_the_physics_engine_and_slave_not_the_tools(builds):
    with zipfile.ZipFile(builds["plain"]) as z:
        names = set(z.namelist())
    res = "resources/"
    for needed in ("prsm_fmu/slave.py", "prsm_fmu/engine.py", "prsm_fmu/mechanics.py",
                   "prsm_fmu/models/dynamic.py", "prsm_fmu/steppers/rosenbrock.py",
                   "prsm_fmu/presets/li2021.py", "prsm_engine_interface.py",
                   "binaries/linux64/prsm_engine.so", "prsm_engine.json",
                   "prsm_start_values.json", "prsm2_slave.py"):
        assert res + needed in names, needed
    assert "extra/baselines/tolerances.toml" in names          # the baselines, by design
    tools = [n for n in names if n.startswith(res + "prsm_fmu/") and (
        n.endswith(("/cli.py", "/arguments.py", "/report.py", "/result_plot.py", "/results.py"))
        or "/sweep/" in n or "/regress/" in n)]
    assert tools == []
    assert not [n for n in names if n.startswith(res + "fmu_build/")]      # the builders
    with zipfile.ZipFile(builds["reference"]) as z:
        assert not any(n.endswith(("prsm_engine.so", "prsm_engine.json")) for n in z.namelist())


def _start(host: Host, fidelity: int | None = None) -> None:
    values = {"screw_torque": 19.747, "load_force": 5000.0, "initial_screw_speed": 100.0,
              "initial_carrier_equilibrium": True}
    if fidelity is not None:
        values["fidelity"] = fidelity
    host.set(values)
    host.fmu.exitInitializationMode()


NAMES = ["screw_speed", "stage[1].carrier_speed", "stage[2].contact_force", "friction_power"]


def test_a_plain_and_a_start_build_in_one_process_keep_their_own_start_values(builds):
    """Loaded side by side (one modelIdentifier, one slave module in the process), the
    ``--start fidelity=dynamic`` build runs the dynamic level and the plain one quasi-static,
    each equal to the plain build set to that level."""
    plain = Host(path=builds["plain"], instance="plain", initialize=False)
    dyn = Host(path=builds["dynamic"], instance="dyn", initialize=False)
    plain_as_dyn = Host(path=builds["plain"], instance="plain2", initialize=False)
    _start(plain)
    _start(dyn)
    _start(plain_as_dyn, fidelity=2)
    assert dyn.get(["fidelity"]) == [2] and plain.get(["fidelity"]) == [1]
    for k in range(50):
        for h in (plain, dyn, plain_as_dyn):
            assert h.step(k * 1e-3) == OK, h.messages
    assert plain.get(["step_fidelity"]) == [1] and dyn.get(["step_fidelity"]) == [2]
    assert dyn.get_real(NAMES) == plain_as_dyn.get_real(NAMES)
    assert dyn.get_real(NAMES) != plain.get_real(NAMES)
    for h in (plain, dyn, plain_as_dyn):
        h.free()


@pytest.mark.parametrize("fidelity,stepper", [(1, "closed_form"), (2, "rosenbrock")])
def test_the_fmu_runs_the_engine_equal_to_the_reference_fmu(builds, fidelity, stepper):
    """The engine FMU (default stepper) against the ``--engine python`` build with the method
    the engine translates: 300 steps with new inputs every step (a torque reversal through
    zero speed), outputs equal bit for bit; nothing logged about a fallback."""
    a = Host(path=builds["plain"], instance="engine", initialize=False)
    b = Host(path=builds["reference"], instance="reference", initialize=False)
    a.set({"fidelity": fidelity})
    b.set({"fidelity": fidelity, "stepper": stepper})
    for h in (a, b):
        h.fmu.exitInitializationMode()
    vr = [a.vars[n].valueReference for n in ("screw_torque", "load_force")]
    for k in range(300):
        u = [25.0 if k < 150 else -25.0, 3000.0]
        for h in (a, b):
            h.fmu.setReal(vr, u)
            assert h.step(k * 1e-3) == OK, h.messages
        assert _bits(a.get_real(a.outputs)) == _bits(b.get_real(b.outputs)), k
        assert a.get(["step_rhs_calls"]) == b.get(["step_rhs_calls"]), k
    assert not [m for _s, m in a.messages if "Python reference" in m]
    a.free()
    b.free()


@pytest.mark.parametrize("change,reason", [
    ({"stepper": "explicit_adaptive"}, "stepper = 'explicit_adaptive' is not the engine's"),
])
def test_the_fmu_logs_why_the_python_model_runs(builds, change, reason):
    h = Host(path=builds["plain"], instance="fallback", start=change)
    logged = [m for _s, m in h.messages if "the Python reference model runs" in m]
    assert len(logged) == 1 and reason in logged[0], h.messages
    assert h.step(0.0) == OK
    h.free()


@pytest.mark.parametrize("change", [
    {"stage[1].screw_lead": 0.0021},
    # a thinner stage 1 that meshes (r_N = r_S + 2 r_R = n_S r_R = 15 mm), a steeper flank 2
    {"stage[1].screw_radius": 0.009, "stage[1].roller_radius": 0.003,
     "stage[1].nut_radius": 0.015, "stage[2].flank_angle": 0.7},
])
def test_geometry_set_at_initialization_runs_in_the_engine(builds, change):
    """A geometry parameter set before exitInitializationMode (the library was built for the
    preset's) runs in the engine, which solves the contact of the new geometry: no fallback
    logged, outputs equal bit for bit to the ``--engine python`` FMU's with the same geometry
    over 100 steps, and different from the preset geometry's."""
    a = Host(path=builds["plain"], instance="geo-engine", start=change)
    b = Host(path=builds["reference"], instance="geo-reference",
             start={**change, "stepper": "closed_form"})
    c = Host(path=builds["plain"], instance="geo-preset")
    vr = [a.vars[n].valueReference for n in ("screw_torque", "load_force")]
    for k in range(100):
        for h in (a, b, c):
            h.fmu.setReal(vr, [20.0, 3000.0])
            assert h.step(k * 1e-3) == OK, h.messages
        assert _bits(a.get_real(a.outputs)) == _bits(b.get_real(b.outputs)), k
    assert a.get_real(a.outputs) != c.get_real(c.outputs)
    assert not [m for _s, m in a.messages if "Python reference" in m], a.messages
    for h in (a, b, c):
        h.free()


def test_the_reference_fmu_logs_that_it_has_no_engine(builds):
    h = Host(path=builds["reference"], instance="ref")
    assert any("built without the engine library" in m for _s, m in h.messages), h.messages
    h.free()


def test_fmu_state_round_trip_and_a_refused_step_with_the_engine(builds):
    """Dynamic level through the engine (carriers at equilibrium, 10 µs steps, at most 10
    internal steps each): get -> 20 steps -> set -> the same 20 steps repeat bit for bit, also
    in another instance from the serialized bytes; a step the engine refuses (50 ms after a
    jump to 40 N·m against -8 kN: more than max_substeps internal steps) leaves the serialized
    state exactly as before it."""
    start = {"fidelity": 2, "max_substeps": 10, "initial_screw_speed": 100.0,
             "initial_carrier_equilibrium": True}
    a = Host(path=builds["plain"], instance="a", start=start)
    vr = [a.vars[n].valueReference for n in ("screw_torque", "load_force")]
    a.fmu.setReal(vr, [19.747, 5000.0])
    for k in range(5):
        assert a.step(k * 1e-5, 1e-5) == OK, a.messages
    saved = a.fmu.getFMUstate()
    data = a.state_bytes()

    def twenty(h):
        rows = []
        for k in range(5, 25):
            assert h.step(k * 1e-5, 1e-5) == OK, h.messages
            rows.append(h.get_real(h.outputs))
        return rows

    first = twenty(a)
    a.fmu.setFMUstate(saved)
    assert twenty(a) == first
    b = Host(path=builds["plain"], instance="b", start=start)
    b.fmu.setFMUstate(b.fmu.deSerializeFMUstate(data))
    assert twenty(b) == first
    b.fmu.setReal(vr, [40.0, -8000.0])
    before = b.state_bytes()
    assert b.step(25 * 1e-5, 0.05) != OK
    assert any("max_substeps" in m or "internal steps" in m for _s, m in b.messages), b.messages
    assert b.state_bytes() == before
    a.fmu.freeFMUstate(saved)
    a.free()
    b.free()


STANDALONE = """
import site, sys
sys.path.append({site!r})            # fmpy, numpy, scipy, pythonfmu; not the project (no .pth)
from fmpy import simulate_fmu
messages = []
res = simulate_fmu({fmu!r}, start_values={{"screw_torque": 19.747, "load_force": 5000.0,
                                         "initial_screw_speed": 100.0, "fidelity": 2}},
                   stop_time=0.01, output_interval=1e-3, output=["screw_speed"],
                   debug_logging=True, logger=lambda *a: messages.append(a[-1].decode()))
import prsm_fmu, prsm_engine_interface
print(prsm_fmu.__file__)
print(prsm_engine_interface.__file__)
print(repr(float(res["screw_speed"][-1])))
print("FALLBACK" if any("Python reference" in m for m in messages) else "ENGINE")
"""


def test_the_fmu_runs_its_engine_where_only_the_fmu_provides_the_package(builds):
    """A process without the project installed (``python -S``: no .pth files, so no editable
    install; the third-party packages added by hand): the FMU imports prsm_fmu and the engine's
    interface from its own resources, loads its packed engine library and steps 10 ms at the
    dynamic level without falling back (from 100 rad/s with the carriers at rest: the screw
    slows while they spin up, Li et al. (2021) §3.1)."""
    import site

    code = STANDALONE.format(site=site.getsitepackages()[0], fmu=str(builds["plain"]))
    proc = subprocess.run([sys.executable, "-S", "-c", code], capture_output=True, text=True,
                          timeout=120, cwd=tempfile.gettempdir())
    assert proc.returncode == 0, proc.stderr
    lines = proc.stdout.strip().splitlines()
    assert "/resources/prsm_fmu/" in lines[-4] and "/resources/" in lines[-3], lines
    assert 80.0 < float(lines[-2]) < 100.0 and lines[-1] == "ENGINE", lines


@pytest.mark.parametrize("fidelity", [0, 1, 2, 3])
def test_outputs_read_alone_from_the_state_equal_the_outputs_read_together(builds, fidelity):
    """fmi2GetReal of screw_speed and screw_angle alone reads the state; read after every
    step of a torque reversal (0 kinematic, 1 quasi-static, 2 dynamic, 3 auto), before the
    other outputs, they equal the same outputs read with all the others (Model.outputs)."""
    h = Host(path=builds["plain"], instance=f"alone{fidelity}", start={"fidelity": fidelity})
    vr = [h.vars[n].valueReference for n in ("screw_torque", "load_force")]
    pair = ["screw_speed", "screw_angle"]
    for k in range(200):
        h.fmu.setReal(vr, [25.0 if k < 100 else -25.0, 3000.0])
        assert h.step(k * 1e-3) == OK, h.messages
        alone = h.get_real(pair)
        together = h.get_real(h.outputs)
        assert alone == [together[h.outputs.index(n)] for n in pair], k
    assert h.get_real(["screw_speed"])[0] < 0.0          # the reversal went through zero
    h.free()


def test_the_environment_selects_the_reference_for_every_door_given_no_engine(monkeypatch):
    params = presets.load("li2021_two_stage")
    monkeypatch.setenv("PRSM_FMU_ENGINE", "python")
    _m, st, *_ = configure(params, SOLVER, (0.0, 0.0))
    assert st.name == "closed_form" and fallback_reason(st) is None
    _m, st, *_ = configure(params, SOLVER, (0.0, 0.0), engine="native")   # the argument wins
    assert is_engine(st)
    res = simulate(params, fidelity="quasi-static", screw_torque=20.0, t_end=1e-3,
                   output_interval=1e-4)
    assert res["engine"] == "python"
    monkeypatch.setenv("PRSM_FMU_ENGINE", "C")
    with pytest.raises(ValueError, match=r"PRSM_FMU_ENGINE = 'C' is not allowed: must be one "
                                         r"of 'native', 'python'"):
        configure(params, SOLVER, (0.0, 0.0))


def test_the_command_lines_take_engine(monkeypatch, capsys):
    from prsm_fmu.cli import main

    # setenv first, so that monkeypatch records the variable's absence and restores it: the
    # command sets it for the rest of the process, which would leak into the worker's next tests
    monkeypatch.setenv("PRSM_FMU_ENGINE", "native")
    monkeypatch.delenv("PRSM_FMU_ENGINE")
    assert main(["--engine", "cuda", "presets"]) == 2
    assert "argument --engine: invalid choice: 'cuda'" in capsys.readouterr().err
    assert main(["--engine", "python", "presets"]) == 0
    import os

    assert os.environ["PRSM_FMU_ENGINE"] == "python"
