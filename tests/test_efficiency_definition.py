"""The efficiency is NaN where no power passes through the PRSM, the same in the model, the
pythonfmu FMU and the native C FMU (docs/model.md, "Efficiency").

Definition: η = P_out/P_in driving (P_in > 0, P_out ≥ 0), P_in/P_out back-driven (P_out < 0,
P_in ≤ 0), NaN otherwise: at standstill |ω| ≤ ω_0 and where both sides deliver or both absorb.
ω_0, worked out by hand: 4 · eps · (largest screw speed the FMUs take, 1e4 rad/s)
= 4 × 2.220446049250313e-16 × 1e4 = 8.881784197001252e-12 rad/s.
(Before: 1.0 at a loop's hold, ω = −2e-17 rad/s, rounding noise of 0/0; 0 elsewhere.)
"""

from __future__ import annotations

import math
import sys

import pytest

from prsm_fmu import presets
from prsm_fmu.models import make_model

#: ω_0 by hand (module docstring)
OMEGA_0 = 8.881784197001252e-12
LI2021 = presets.load("li2021_two_stage")


def _outputs(level: str, speed: float, torque: float, load: float) -> dict:
    m = make_model(LI2021, level, "torque")
    u = (torque, load)
    return m.outputs(0.0, m.initial_state(u, screw_speed=speed, carrier_ratio=None), u)


@pytest.mark.parametrize("level", ["kinematic", "quasi-static", "dynamic"])
def test_no_power_flows_gives_nan_and_power_flowing_gives_the_ratio(level):
    # a loop holding position: ω = −2e-17 rad/s (rounding), 5 N.m against 3 kN
    assert math.isnan(_outputs(level, -2e-17, 5.0, 3000.0)["efficiency"])
    # at rest with no torque and no load
    assert math.isnan(_outputs(level, 0.0, 0.0, 0.0)["efficiency"])
    # just below and just above ω_0 (8.88e-12 rad/s)
    assert math.isnan(_outputs(level, 8.8e-12, 30.0, 5000.0)["efficiency"])
    y = _outputs(level, 9.0e-12, 30.0, 5000.0)
    assert y["efficiency"] == pytest.approx(y["output_power"] / y["input_power"], rel=1e-12)
    # driving at 100 rad/s: P_out / P_in in (0, 1]
    y = _outputs(level, 100.0, 30.0, 5000.0)
    assert 0.0 < y["efficiency"] <= 1.0
    assert y["efficiency"] == pytest.approx(y["output_power"] / y["input_power"], rel=1e-12)
    # both sides deliver power (torque drives, the load pulls along): nothing passes through
    y = _outputs(level, 100.0, 30.0, -5000.0)
    assert y["input_power"] > 0.0 and y["output_power"] < 0.0
    assert math.isnan(y["efficiency"])
    # back-driven with the motor absorbing nothing (0 N.m): 0 / P_out = 0, not −0
    y = _outputs(level, 100.0, 0.0, -5000.0)
    assert y["efficiency"] == 0.0 and math.copysign(1.0, y["efficiency"]) == 1.0


def test_the_threshold_is_the_rounding_of_the_speed_range():
    """ω_0 of the module docstring: 4 eps × 1e4 rad/s (the FMUs' speed range)."""
    from prsm_fmu.models.base import STANDSTILL_SPEED

    assert STANDSTILL_SPEED == pytest.approx(4 * sys.float_info.epsilon * 1e4, rel=1e-15)
    assert STANDSTILL_SPEED == pytest.approx(OMEGA_0, rel=1e-15)


def _fmu_rows(host, steps: int, torque: float, load: float) -> list[tuple[float, float]]:
    """(screw_speed, efficiency) after each of ``steps`` 1 ms steps with held inputs."""
    vr = [host.vars["screw_torque"].valueReference, host.vars["load_force"].valueReference]
    host.fmu.setReal(vr, [torque, load])
    rows = []
    for k in range(steps):
        assert host.step(k * 1e-3, 1e-3) == 0, host.messages
        rows.append(tuple(host.get_real(["screw_speed", "efficiency"])))
    return rows


@pytest.mark.parametrize("native_fmu", [False, True], ids=["pythonfmu", "native"])
def test_both_fmus_give_nan_at_standstill_and_accept_it(native_fmu):
    """FMU at rest, no torque, no load: it instantiates (its start check allows this NaN),
    steps, and reads efficiency NaN through fmpy; driven, it reads P_out / P_in."""
    pytest.importorskip("fmpy")
    pytest.importorskip("pythonfmu")
    from test_fmu import Host

    if native_fmu:
        if sys.platform != "linux":
            pytest.skip("the native FMU is built here for Linux only")
        from test_native_fmu import native_host
        make = lambda **kw: native_host(**kw)          # noqa: E731
    else:
        make = lambda **kw: Host(**kw)                 # noqa: E731
    host = make(start={"fidelity": "quasi-static"})
    try:
        assert math.isnan(host.get_real(["efficiency"])[0])       # at the start, ω = 0
        rows = _fmu_rows(host, 3, 0.0, 0.0)
        assert all(w == 0.0 and math.isnan(e) for w, e in rows), rows
    finally:
        host.free()
    host = make(start={"fidelity": "quasi-static", "initial_screw_speed": 100.0})
    try:
        vr = [host.vars["screw_torque"].valueReference, host.vars["load_force"].valueReference]
        rows = _fmu_rows(host, 2, 30.0, 5000.0)
        p = host.get_real(["input_power", "output_power"])
        assert 0.0 < rows[-1][1] <= 1.0 and rows[-1][1] == pytest.approx(p[1] / p[0], rel=1e-12)
        host.fmu.setReal(vr, [30.0, -5000.0])                     # both sides deliver
        assert host.step(2e-3, 1e-3) == 0
        assert math.isnan(host.get_real(["efficiency"])[0])
    finally:
        host.free()


def test_python_and_native_fmu_give_nan_at_the_same_steps_of_a_reversal():
    """The speed loop of test_native_fmu (100 -> −60 rad/s) with a 3 kN load that pulls: a few
    steps have both sides delivering or both absorbing power (NaN; 5 of 400 when written);
    NaN at the same steps in both FMUs, bit-equal elsewhere."""
    pytest.importorskip("fmpy")
    if sys.platform != "linux":
        pytest.skip("the native FMU is built here for Linux only")
    from test_native_fmu import PY_SAME_METHOD, both_loops

    py, nat, names = both_loops("PRSM2", {"fidelity": "quasi-static", **PY_SAME_METHOD},
                                {"fidelity": "quasi-static"}, -3000.0)
    i = names.index("efficiency")
    e_py, e_nat = [r[i] for r in py], [r[i] for r in nat]
    undefined = [math.isnan(e) for e in e_py]
    assert undefined == [math.isnan(e) for e in e_nat]
    assert 0 < sum(undefined) < len(undefined), sum(undefined)
    assert all(a == b for a, b, u in zip(e_py, e_nat, undefined) if not u)
    print(f"{sum(undefined)} of {len(undefined)} steps without power through the PRSM")


@pytest.mark.parametrize("native_fmu", [False, True], ids=["pythonfmu", "native"])
def test_libcosim_steps_an_fmu_at_standstill_and_reads_the_nan(native_fmu):
    """A third-party host (libcosim) accepts the NaN output: at rest with no torque and no load
    every step succeeds and the efficiency it observes is NaN, the speed 0."""
    pytest.importorskip("libcosimpy")
    from test_fmu import built_fmus
    from test_fmu_hosts import LIBCOSIM, child

    if native_fmu:
        if sys.platform != "linux":
            pytest.skip("the native FMU is built here for Linux only")
        from test_native_fmu import built_native
        fmu = built_native()["PRSM2"]
    else:
        fmu = built_fmus()["PRSM2"]
    status, data, err = child(LIBCOSIM.format(fmu=str(fmu), h_ns=1_000_000, u=(0.0, 0.0),
                                              start={}, steps=3,
                                              outputs=("screw_speed", "efficiency")))
    assert status == 0 and data, err[-2000:]
    assert all(data["ok"]) and data["state"] != "ERROR", data
    assert all(w == 0.0 and math.isnan(e) for w, e in data["rows"]), data["rows"]
