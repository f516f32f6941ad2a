"""The native FMU as FMI 2.0 model exchange, run by fmpy's model-exchange path (CVode), against
the same FMU's co-simulation.

The FMU is the one tests/test_native_fmu.py builds once per session.  The co-simulation
reference holds each input over its communication step (what both interfaces then integrate is
the same piecewise-constant input); its outputs at the quasi-static level come from the exact
closed-form step with Dormand-Prince 5(4) inside the friction band, at the dynamic level from
ROS34PW2, both at ``tolerance`` = 1e-8.  Model exchange: fmpy's CVode at relative tolerance
1e-9 (1e-10 for the position step).  Compared at every communication point: max |ME - CS| <= 1e-6 of the output's largest
magnitude over the run (CS and ME are independent integrations of the same right-hand side; the
differences measured are printed: at most ~1e-7 here).
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

fmpy = pytest.importorskip("fmpy")
pytest.importorskip("pythonfmu")
from zig_skip import skip_without_ziglang  # noqa: E402

skip_without_ziglang()
if sys.platform != "linux":
    pytest.skip("the tests run the native FMU's linux64 binary", allow_module_level=True)

from fmpy import extract, read_model_description  # noqa: E402
from fmpy.fmi2 import (FMU2Model, FMU2Slave, calloc, fmi2CallbackAllocateMemoryTYPE,  # noqa: E402
                        fmi2CallbackFreeMemoryTYPE, fmi2CallbackFunctions,
                        fmi2CallbackLoggerTYPE, free)

from test_native_fmu import built_native  # noqa: E402

OUTPUTS = ["screw_speed", "rod_position", "friction_work", "stage[1].contact_force",
           "stage[2].carrier_speed", "efficiency"]
#: the largest relative difference accepted between the two interfaces' runs: both integrate the
#: same equations, the co-simulation at tolerance = 1e-8 and CVode at rtol 1e-9 … 1e-10 per
#: step, over up to 1 000 steps; 100 x the co-simulation's requested tolerance leaves room for
#: that accumulation (the measured differences are ~1e-7 at most, each test's docstring)
ME_CS_AGREEMENT = 1e-6
ROOT = Path(__file__).resolve().parent.parent


@pytest.fixture(scope="module")
def fmu():
    path = built_native()["PRSM2"]
    md = read_model_description(str(path))
    return md, extract(str(path))


def _set(inst, vr, values: dict) -> None:
    for name, v in values.items():
        if isinstance(v, bool):
            inst.setBoolean([vr[name]], [v])
        elif isinstance(v, int):
            inst.setInteger([vr[name]], [v])
        else:
            inst.setReal([vr[name]], [v])


def _logged_instance(fmu, name: str, messages: list) -> FMU2Model:
    """A model-exchange instance of ``fmu`` named ``name`` whose log messages go to
    ``messages`` (instantiated, not yet set up)."""
    md, unzip = fmu

    def logger(env, inst, status, category, message):
        messages.append(message.decode())

    m = FMU2Model(guid=md.guid, unzipDirectory=unzip,
                  modelIdentifier=md.modelExchange.modelIdentifier, instanceName=name)
    cb = fmi2CallbackFunctions()
    cb.logger = fmi2CallbackLoggerTYPE(logger)
    cb.allocateMemory = fmi2CallbackAllocateMemoryTYPE(calloc)
    cb.freeMemory = fmi2CallbackFreeMemoryTYPE(free)
    m._prsm_logger = cb          # (the callbacks must outlive the instance)
    m.instantiate(loggingOn=True, callbacks=cb)
    return m


def co_simulation(fmu, start: dict, torque, load, h: float) -> np.ndarray:
    """Rows (t, outputs...) at t = 0, h, 2h, ... with input i held over step i."""
    md, unzip = fmu
    vr = {v.name: v.valueReference for v in md.modelVariables}
    s = FMU2Slave(guid=md.guid, unzipDirectory=unzip,
                  modelIdentifier=md.coSimulation.modelIdentifier, instanceName="cs")
    s.instantiate()
    try:
        s.setupExperiment(startTime=0.0)
        s.enterInitializationMode()
        _set(s, vr, start)
        s.setReal([vr["screw_torque"], vr["load_force"]], [torque[0], load[0]])
        s.exitInitializationMode()
        out = [vr[n] for n in OUTPUTS]
        rows = [[0.0] + s.getReal(out)]
        for i in range(len(torque)):
            s.setReal([vr["screw_torque"], vr["load_force"]], [torque[i], load[i]])
            s.doStep(i * h, h)          # fmpy raises on a status other than OK
            rows.append([(i + 1) * h] + s.getReal(out))
        s.terminate()
    finally:
        s.freeInstance()
    return np.array(rows)


def model_exchange(fmu, start: dict, torque, load, h: float, rtol: float = 1e-9):
    """fmpy's model-exchange run (CVode) of the same inputs; the rows at the communication
    points and the host's counts (events handled, derivative evaluations)."""
    md, unzip = fmu
    m = FMU2Model(guid=md.guid, unzipDirectory=unzip,
                  modelIdentifier=md.modelExchange.modelIdentifier, instanceName="me")
    m.instantiate()
    counts = {"events": 0, "derivative evaluations": 0}
    enter, derivatives = m.enterEventMode, m.getDerivatives

    def counted_enter(*a):
        counts["events"] += 1
        return enter(*a)

    def counted_derivatives(*a):
        counts["derivative evaluations"] += 1
        return derivatives(*a)

    m.enterEventMode, m.getDerivatives = counted_enter, counted_derivatives
    n = len(torque)
    starts = dict(start)
    kw = {}
    if np.all(torque == torque[0]) and np.all(load == load[0]):
        starts.update(screw_torque=float(torque[0]), load_force=float(load[0]))
    else:   # steps at k h: the value before and after each change (fmpy: an input event)
        t = np.repeat(np.arange(n + 1) * h, 2)[1:-1]
        kw["input"] = np.array(list(zip(t, np.repeat(torque, 2), np.repeat(load, 2))),
                               dtype=[("time", float), ("screw_torque", float),
                                      ("load_force", float)])
    r = fmpy.simulate_fmu(unzip, model_description=md, fmu_instance=m,
                          fmi_type="ModelExchange", stop_time=n * h, relative_tolerance=rtol,
                          start_values=starts, output=OUTPUTS, output_interval=h, **kw)
    m.freeInstance()
    # the first row at each communication point: before the input event there, the inputs of
    # the step that ends there (as the co-simulation's outputs after doStep)
    grid = np.arange(n + 1) * h
    k = np.rint(r["time"] / h).astype(int)
    on_grid = np.abs(r["time"] - grid[np.clip(k, 0, n)]) <= 1e-9 * h
    rows = {}
    for row, kk, ok in zip(r, k, on_grid):
        if ok and kk not in rows:
            rows[kk] = [row[name] for name in OUTPUTS]
    assert sorted(rows) == list(range(n + 1))
    return np.array([[grid[i]] + rows[i] for i in range(n + 1)]), counts


def compare(label: str, cs: np.ndarray, me: np.ndarray, counts: dict, tol: float = ME_CS_AGREEMENT) -> None:
    print(f"\n{label}: {len(cs) - 1} communication steps; host handled {counts['events']} "
          f"events, {counts['derivative evaluations']} derivative evaluations")
    worst = []
    for j, name in enumerate(OUTPUTS, start=1):
        scale = np.max(np.abs(cs[:, j]))
        d = np.max(np.abs(me[:, j] - cs[:, j])) / (scale if scale > 0 else 1.0)
        print(f"  {name}: max |ME - CS| = {d:.2e} of {scale:.4g}")
        worst.append((d, name))
    assert max(worst)[0] <= tol, max(worst)


def test_li_et_al_startup_model_exchange_equals_co_simulation(fmu):
    """Li et al. (2021) §3.1 start-up at the dynamic level: the screw at 100 rad/s, the
    carriers at rest, 5 kN on the rod, 1 ms; 20 N.m on the screw (about the torque that keeps
    it turning)."""
    n, h = 100, 1e-5
    start = {"fidelity": 2, "initial_screw_speed": 100.0, "tolerance": 1e-8}
    tq, ld = np.full(n, 20.0), np.full(n, 5000.0)
    cs = co_simulation(fmu, start, tq, ld, h)
    me, counts = model_exchange(fmu, start, tq, ld, h)
    compare("start-up (dynamic)", cs, me, counts)
    # the carriers spin up from rest towards their equilibrium ratio (~0.37, docs/model.md §4)
    ratio = me[-1, 5] / me[-1, 1]
    assert me[0, 5] == 0.0 and 0.2 < ratio < 0.5


@pytest.mark.parametrize("fidelity", [0, 1, 2])
def test_reversal_through_zero_speed_model_exchange_equals_co_simulation(fmu, fidelity):
    """-20 N.m against the screw turning at 100 rad/s, 5 kN pulling back: the screw stops
    and reverses within 1.3 ms; the host must see the events at the band's edges and at zero."""
    n, h = 500, 1e-4
    start = {"fidelity": fidelity, "initial_screw_speed": 100.0, "tolerance": 1e-8,
             "initial_carrier_equilibrium": True}
    tq, ld = np.full(n, -20.0), np.full(n, 5000.0)
    cs = co_simulation(fmu, start, tq, ld, h)
    me, counts = model_exchange(fmu, start, tq, ld, h)
    compare(f"reversal ({('kinematic', 'quasi-static', 'dynamic')[fidelity]})", cs, me, counts)
    assert cs[0, 1] == 100.0 and cs[-1, 1] < -1000.0
    assert counts["events"] >= 3      # upper band edge, zero speed, lower band edge


def test_position_step_torque_history_model_exchange_equals_co_simulation(fmu):
    """The position_step scene's torque and rod force history (baselines/position_step.csv),
    its first 0.1 s (1000 steps of 0.1 ms: the step at 10 ms, the acceleration at the current
    limit, the settling), held per step, at the quasi-static level.  Every step is an input
    event that restarts CVode; at its relative tolerance 1e-10 the differences were ~1e-7 of
    rod_position and friction_work (and ~8e-7 at 1e-9, ~1e-8 at 1e-11: CVode's error, shrinking
    with its tolerance)."""
    import csv

    with open(ROOT / "baselines" / "position_step.csv", newline="") as f:
        rows = list(csv.reader(f))
    head = rows[0]
    data = np.array([[float(v) for v in r] for r in rows[1:]])
    tq = data[:1000, head.index("motor.torque [N.m]")]
    ld = data[:1000, head.index("load.force [N]")]
    h = float(data[1, 0] - data[0, 0])
    start = {"fidelity": 1, "tolerance": 1e-8, "initial_carrier_equilibrium": True}
    cs = co_simulation(fmu, start, tq, ld, h)
    me, counts = model_exchange(fmu, start, tq, ld, h, rtol=1e-10)
    compare("position_step torque history (quasi-static)", cs, me, counts)
    assert counts["events"] >= 1000        # one per input change at least


def test_fmu_state_round_trip_in_model_exchange(fmu):
    md, unzip = fmu
    vr = {v.name: v.valueReference for v in md.modelVariables}
    m = FMU2Model(guid=md.guid, unzipDirectory=unzip,
                  modelIdentifier=md.modelExchange.modelIdentifier, instanceName="me")
    m.instantiate()
    try:
        m.setupExperiment(startTime=0.0)
        m.enterInitializationMode()
        _set(m, vr, {"fidelity": 2, "initial_screw_speed": 50.0, "screw_torque": 10.0})
        m.exitInitializationMode()
        m.newDiscreteStates()
        m.enterContinuousTimeMode()
        nx = md.numberOfContinuousStates
        assert nx == 7          # angle, speed, 2 carriers, 3 works
        x0 = np.zeros(nx)
        m.getContinuousStates(x0.ctypes.data_as(fmpy.fmi2.POINTER(fmpy.fmi2.fmi2Real)), nx)
        state = m.getFMUstate()
        x1 = x0 + 1.0
        m.setTime(0.5)
        m.setContinuousStates(x1.ctypes.data_as(fmpy.fmi2.POINTER(fmpy.fmi2.fmi2Real)), nx)
        moved = m.getReal([vr["screw_speed"]])[0]
        m.setFMUstate(state)
        m.freeFMUstate(state)
        back = np.zeros(nx)
        m.getContinuousStates(back.ctypes.data_as(fmpy.fmi2.POINTER(fmpy.fmi2.fmi2Real)), nx)
        assert moved == 51.0 and list(back) == list(x0) and x0[1] == 50.0
        m.terminate()
    finally:
        m.freeInstance()


def test_no_rigid_contact_solution_is_an_error_naming_the_cause(fmu):
    """The state of tests/test_fmu.py's Painlevé case (Li et al. (2021) with every inertia 1000x too
    small, dynamic level, -1 rad/s, carriers at rest, +20 N.m against 500 N): no acceleration
    balances the torque.  The event indicator of the rigid contact reads -1, and the host's
    first event update (and any derivative) is refused with fmi2Error, the cause logged; with
    the preset's inertias the same start has a solution (+1)."""
    import ctypes

    md, unzip = fmu
    vr = {v.name: v.valueReference for v in md.modelVariables}
    light = {"stage[1].screw_inertia": 55e-9, "stage[1].roller_inertia": 0.08e-9,
             "stage[1].carrier_inertia": 3e-9, "stage[2].screw_inertia": 170e-9,
             "stage[2].roller_inertia": 0.48e-9, "stage[2].carrier_inertia": 12e-9}
    start = {"fidelity": 2, "initial_screw_speed": -1.0, "screw_torque": 20.0, "load_force": 500.0}
    messages = []

    for inertias, indicator in ((light, -1.0), ({}, 1.0)):
        m = _logged_instance(fmu, "painleve", messages)
        try:
            m.setupExperiment(startTime=0.0)
            m.enterInitializationMode()
            _set(m, vr, {**start, **inertias})
            m.exitInitializationMode()
            z, dx = (ctypes.c_double * 4)(), (ctypes.c_double * md.numberOfContinuousStates)()
            m.getEventIndicators(z, 4)
            assert z[3] == indicator and z[0] == -1.0
            if indicator < 0:
                with pytest.raises(Exception, match="status 3"):
                    m.newDiscreteStates()
                assert "no solution" in messages[-1] and "screw_torque = 20 N.m" in messages[-1]
                with pytest.raises(Exception, match="status 3"):
                    m.getDerivatives(dx, len(dx))
            else:
                m.newDiscreteStates()
                m.enterContinuousTimeMode()
                m.getDerivatives(dx, len(dx))
                assert all(np.isfinite(list(dx))) and dx[1] != 0.0
        finally:
            m.freeInstance()


def test_auto_is_refused_for_model_exchange_naming_the_fidelity(fmu):
    """fidelity = auto chooses the level per communication step: a model-exchange instance
    (no communication steps of its own) refuses it at fmi2ExitInitializationMode with
    fmi2Error, the reason logged; the co-simulation of the same FMU runs it
    (tests/test_native_fmu.py)."""
    md, unzip = fmu
    vr = {v.name: v.valueReference for v in md.modelVariables}
    messages = []

    m = _logged_instance(fmu, "auto", messages)
    try:
        m.setupExperiment(startTime=0.0)
        m.enterInitializationMode()
        _set(m, vr, {"fidelity": 3})
        with pytest.raises(Exception, match="status 3"):
            m.exitInitializationMode()
        assert "fidelity = 'auto' is not available for model exchange" in messages[-1]
    finally:
        m.freeInstance()
