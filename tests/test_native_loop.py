"""The actuator loop's macro steps in C (system_models.native_loop.NativeMaster).

The C loop is a translation of the Python master's step and of the controller, motor and load,
so the expected values are the Python loop's own, bit for bit: every recorded output at every
communication point, the master's statistics and the blocks' end states.  The runs cover the
scenes' controller modes (position with and without velocity feed-forward, speed), both
coupling orders and extrapolation orders, the native FMU and the Python FMU, a step the FMU
refuses (with and without retries), a doStep that fails (fmi2Error) and a step the motor
refuses (overcurrent trip).
"""

from __future__ import annotations

import dataclasses
import shutil
import sys

import numpy as np
import pytest

pytest.importorskip("fmpy")
pytest.importorskip("pythonfmu")
if sys.platform != "linux" or shutil.which("gcc") is None:
    pytest.skip("the native loop is compiled here with gcc on Linux", allow_module_level=True)

from test_fmu import built_fmus  # noqa: E402
from test_native_fmu import built_native  # noqa: E402

from system_models import cli  # noqa: E402
from system_models.ema import CONNECTIONS, build_system  # noqa: E402
from system_models.fmu import FMUError  # noqa: E402
from system_models.load import SpringDamperLoad  # noqa: E402
from system_models.master import CoSimulationError, RetryPolicy  # noqa: E402
from system_models.native_loop import NativeMaster  # noqa: E402
from system_models.scenes import load_scene  # noqa: E402
from text_numbers import number_after, same_message, same_table  # noqa: E402


def native_fmu():
    return built_native()["PRSM2"]


def both(scene, fmu=None, **options):
    """The scene run by the Python master and by the native loop: (results, systems)."""
    fmu = fmu or native_fmu()
    systems = {loop: build_system(scene, prsm="fmu", fmu_path=fmu, loop=loop, **options)
               for loop in ("python", "native")}
    return {loop: s.run() for loop, s in systems.items()}, systems


def assert_same_run(results, systems) -> None:
    a, b = results["python"], results["native"]
    assert np.array_equal(a.time, b.time)
    assert a.names() == b.names()
    # equal_nan: the efficiency is NaN where no power passes through, in both
    differ = [n for n in a.names() if not np.array_equal(a[n], b[n], equal_nan=True)]
    assert differ == [], f"outputs differ: {differ}"
    for key in ("macro_steps", "substeps", "retries", "refusals", "max_coupling_error"):
        assert a.stats[key] == b.stats[key], key
    pa, pb = systems["python"].master.blocks, systems["native"].master.blocks
    assert pa[0].j == pb[0].j and pa[0].cmd == pb[0].cmd and pa[0].integrals == pb[0].integrals
    assert pa[1].x == pb[1].x
    assert pa[3].t == pb[3].t


@pytest.mark.parametrize("name", ["position_step", "sine_tracking", "speed_reversal"])
def test_the_native_loop_equals_the_python_loop_bit_for_bit(name):
    """position_step (position mode, a step), sine_tracking (velocity feed-forward: the
    reference read at t ± T_p), speed_reversal (speed mode, external force), shortened."""
    sc = load_scene(name)
    sc = dataclasses.replace(sc, t_end=min(sc.t_end, 0.1))
    assert_same_run(*both(sc))


@pytest.mark.parametrize("order,extrapolation", [("jacobi", 0), ("jacobi", 1),
                                                 ("gauss-seidel", 0)])
def test_every_coupling_order_and_extrapolation_is_translated(order, extrapolation):
    sc = dataclasses.replace(load_scene("position_step"), t_end=0.03)
    assert_same_run(*both(sc, order=order, extrapolation=extrapolation))


def test_the_python_fmu_and_recorded_subset_run_the_same_in_the_native_loop():
    """The pythonfmu FMU (its doStep calls back into Python from the C loop) and a recording
    of a few outputs (the FMU then reads fewer variables)."""
    sc = dataclasses.replace(load_scene("load_step"), t_end=0.02)
    assert_same_run(*both(sc, fmu=built_fmus()["PRSM2"]))
    record = ["prsm.rod_position", "motor.current", "load.force", "prsm.step_rhs_calls"]
    assert_same_run(*both(sc, record=record))


def test_the_dynamic_level_runs_the_same_in_the_native_loop():
    sc = dataclasses.replace(load_scene("position_step"), t_end=0.02, fidelity="dynamic")
    assert_same_run(*both(sc))


@pytest.mark.parametrize("retry", [RetryPolicy(), RetryPolicy(max_halvings=2)])
def test_a_step_the_fmu_refuses_is_handed_to_the_python_master_with_the_same_error(retry):
    """The external force turns NaN at 5 ms: the FMU refuses the step (fmi2Discard); the C hands
    the step back and the Python master stops with its message, the same partial result."""
    sc = dataclasses.replace(load_scene("position_step"), t_end=0.02, load={
        "external_force": {"kind": "points", "time": [0.0, 0.005, 0.005, 1.0],
                           "value": [0.0, 0.0, float("nan"), float("nan")]}})
    errors = {}
    for loop in ("python", "native"):
        with pytest.raises(CoSimulationError) as info:
            build_system(sc, prsm="fmu", fmu_path=native_fmu(), retry=retry, loop=loop).run()
        errors[loop] = info.value
    a, b = errors["python"], errors["native"]
    assert same_message(str(a), str(b)) and a.block == b.block == "prsm" and a.time == b.time
    assert np.array_equal(a.partial.time, b.partial.time)
    # the load force is NaN at the step's start (that is the point): equal NaNs count as equal
    assert all(np.array_equal(a.partial[n], b.partial[n], equal_nan=True)
               for n in a.partial.names())


def test_a_motor_trip_is_handed_to_the_python_master_with_the_same_error():
    """The motor trips at 1.5 × 5 A = 7.5 A while the controller allows 20 A (its own limit
    overridden): the same overcurrent message at the same step from both loops."""
    sc = dataclasses.replace(load_scene("position_step"), t_end=0.03,
                             motor={"current_limit": 5.0},
                             controller={**load_scene("position_step").controller,
                                         "current_limit": 20.0})
    errors = {}
    for loop in ("python", "native"):
        with pytest.raises(CoSimulationError) as info:
            build_system(sc, prsm="fmu", fmu_path=native_fmu(), loop=loop).run()
        errors[loop] = info.value
    a, b = errors["python"], errors["native"]
    assert "overcurrent" in a.reason and a.block == "motor"
    assert same_message(str(a), str(b))
    assert all(np.array_equal(a.partial[n], b.partial[n], equal_nan=True)
               for n in a.partial.names())


class _DllWith:
    """An FMU's library with one function replaced (what the C loop takes its pointers from)."""

    def __init__(self, dll, **functions):
        self._dll = dll
        self.__dict__.update(functions)

    def __getattr__(self, name):
        return getattr(self._dll, name)


def test_an_fmu_error_in_the_c_loop_stops_the_run_with_the_python_loops_error():
    """doStep returning fmi2Error (3) from t = 12 ms on (neither FMU does so from its inputs, so
    a wrapper around the FMU's own fmi2DoStep returns it, in both loops): the C loop stops the
    run with the FMU block's own error (FMUError, not retried: not a refusal), the same message
    after the same doStep calls as the Python master's."""
    import ctypes

    proto = ctypes.CFUNCTYPE(ctypes.c_int, ctypes.c_void_p, ctypes.c_double, ctypes.c_double,
                             ctypes.c_int)
    sc = dataclasses.replace(load_scene("position_step"), t_end=0.02)
    errors, calls, systems = {}, {}, {}
    for loop in ("python", "native"):
        system = systems[loop] = build_system(sc, prsm="fmu", fmu_path=native_fmu(), loop=loop)
        blk = next(b for b in system.master.blocks if b.name == "prsm")
        dll, real = blk.fmu.dll, blk.fmu.dll.fmi2DoStep
        seen = calls[loop] = []

        def do_step(component, t, h, no_prior, real=real, seen=seen):
            seen.append(t)
            return 3 if t >= 0.012 - 1e-12 else real(component, t, h, no_prior)

        wrapper = proto(do_step)
        blk._c_do_step = wrapper                          # the Python master's call
        blk.fmu.dll = _DllWith(dll, fmi2DoStep=wrapper)   # the C loop's, read at its set-up
        try:
            with pytest.raises(FMUError) as info:
                system.run()
        finally:
            blk.fmu.dll = dll
        errors[loop] = str(info.value)
    # 12 ms / 0.1 ms: the 121st doStep, at t = 12 ms, fails and is not tried again
    assert calls["python"] == calls["native"] and len(calls["native"]) == 121
    assert same_message(errors["python"], errors["native"])
    assert errors["native"].startswith("prsm: doStep(t = ") and "(error)" in errors["native"]
    assert number_after(errors["native"], "prsm: doStep(t = ") == pytest.approx(0.012, rel=1e-12)
    # the C puts the Python blocks back to the failing step's start, as for a refused step: the
    # controller has taken its 120 samples of 0 … 11.9 ms (the Python master, which stops
    # inside the step, leaves it after its 121st)
    assert systems["native"].master.blocks[0].j == 120
    for s in systems.values():
        s.master.terminate()


def test_progress_is_reported_up_to_the_end():
    sc = dataclasses.replace(load_scene("position_step"), t_end=0.5)
    seen = []
    system = build_system(sc, prsm="fmu", fmu_path=native_fmu(), loop="native")
    system.run(lambda t, t_end: seen.append((t, t_end)))
    # 5000 steps in chunks: more than one report, increasing, the last at t_end = 0.5 s
    assert len(seen) >= 2 and all(a[0] < b[0] for a, b in zip(seen, seen[1:]))
    assert seen[-1] == (pytest.approx(0.5, abs=1e-12), 0.5)


def test_what_the_native_loop_cannot_run_is_refused_naming_the_option():
    sc = dataclasses.replace(load_scene("position_step"), t_end=0.01)
    with pytest.raises(ValueError, match="retry.tolerance"):
        build_system(sc, prsm="fmu", fmu_path=native_fmu(), loop="native",
                     retry=RetryPolicy(max_halvings=2, tolerance=0.05))
    with pytest.raises(ValueError, match="loop = 'fast' is not allowed"):
        build_system(sc, prsm="fmu", fmu_path=native_fmu(), loop="fast")
    with pytest.raises(ValueError, match="PythonPRSM"):
        build_system(sc, prsm="python", loop="native")
    # a subclass of a block may step differently from the block the C translates
    class Load(SpringDamperLoad):
        pass

    python = build_system(sc, prsm="fmu", fmu_path=native_fmu())
    blocks = python.master.blocks
    blocks[3] = Load(blocks[3].params, blocks[3].external)
    with pytest.raises(ValueError, match="block 'load' \\(Load\\) has no C translation"):
        NativeMaster(blocks, CONNECTIONS, sc.step)
    python.master.terminate()
    system = build_system(sc, prsm="fmu", fmu_path=native_fmu(), loop="native")
    system.master.blocks[1].integrator = "exponential"
    with pytest.raises(ValueError, match="motor.integrator"):
        system.run()


def test_cli_refuses_the_native_loop_for_the_python_prsm_and_the_geared_topology(capsys, tmp_path):
    for extra in (["--scene", "position_step", "--prsm", "python"],
                  ["--scene", "msl_actuator_with_noise"]):
        code = cli.main(["run", *extra, "--loop", "native", "--out", str(tmp_path)])
        err = capsys.readouterr().err
        assert code == 2 and "loop = 'native'" in err, err


def test_cli_run_with_the_native_loop_writes_the_same_csv_as_the_python_loop(capsys, tmp_path):
    """`prsm-ema run --loop native` passes the scene's checks and writes the CSV byte for byte
    as the Python master does."""
    csv = {}
    for loop in ("python", "native"):
        out = tmp_path / loop
        code = cli.main(["run", "--scene", "position_step", "--prsm", "native", "--fmu",
                         str(native_fmu()), "--loop", loop, "--no-plots", "--out", str(out)])
        assert code == 0, capsys.readouterr().err
        csv[loop] = (out / "position_step.csv").read_text(encoding="utf-8")
    assert same_table(csv["python"], csv["native"])      # every number equal as a double
