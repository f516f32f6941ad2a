"""The native FMU's guards: status queries, communication points, Enumerations, state pointers.

Each case is one the bad-input sweep found accepted or answered wrongly; the expected answers
are FMI 2.0's rules and docs/fmu.md's error table, not the FMU's own output:

* after a refused ``doStep`` a retry may succeed, so ``fmi2GetBooleanStatus(fmi2Terminated)``
  answers fmi2OK and false; after the same call refused twice in a row (a deterministic FMU
  cannot take it) and after ``fmi2Terminate`` it answers true, so that fmpy's
  ``simulate_fmu``, which retries a refused step unchanged, stops instead of looping;
* a ``currentCommunicationPoint`` farther than 1e-12·max(1 s, |t|) from the FMU's time is
  refused whatever the step size (1e6 s away at t = 0.01 s with h = 1e16 s was accepted: the
  window scaled with h), and so is a step too small to change the time (h = 1e-20 s at
  t = 0.005 s: 0.005 + 1e-20 == 0.005 in doubles, as 1e-20 < ulp(0.005)/2 ≈ 4.3e-19);
* an Enumeration value that is no item names the value and the items;
* a state made by another FMU or instance is refused before anything reads or writes it.
"""

from __future__ import annotations

import ctypes

import pytest

pytest.importorskip("fmpy")
pytest.importorskip("pythonfmu")

from test_fmu import DISCARD, OK  # noqa: E402
from test_native_fmu import ERROR, H, native, native_host  # noqa: E402,F401 - fixture

FMI2_TERMINATED = 3     # fmi2StatusKind of the FMI 2.0 headers


def _terminated(host) -> tuple[int, int]:
    value = ctypes.c_int(7)             # neither true nor false: it must be written
    status = host.fmu.dll.fmi2GetBooleanStatus(ctypes.c_void_p(host.fmu.component), FMI2_TERMINATED,
                                               ctypes.byref(value))
    return status, value.value


def test_a_refused_step_does_not_read_as_terminated(native):
    host = native_host()
    verdicts = []
    try:
        assert host.step(0.0, -1.0) == DISCARD
        verdicts.append(("after a refused step", _terminated(host), (OK, 0)))
        assert host.step(0.0, -1.0) == DISCARD         # the same call again cannot succeed
        verdicts.append(("after the same call refused twice", _terminated(host), (OK, 1)))
        assert host.step(0.0, H) == OK                 # a retry with another step succeeds
        verdicts.append(("after a good step", _terminated(host), (OK, 0)))
        host.fmu.terminate()
        verdicts.append(("after fmi2Terminate", _terminated(host), (OK, 1)))
    finally:
        host.fmu.freeInstance()
    for what, got, want in verdicts:
        print(f"  fmi2Terminated {what}: (status, value) = {got}, expected {want}")
    assert all(got == want for _, got, want in verdicts)


def test_communication_point_and_step_size_are_checked_strictly(native):
    host = native_host()
    try:
        for k in range(10):
            assert host.step(k * H) == OK
        t = host.fmu.getRealStatus(2)                  # fmi2LastSuccessfulTime: 0.01 s
        assert abs(t - 0.01) < 1e-15
        assert host.step(1e6, 1e16) == ERROR and "currentCommunicationPoint" in host.messages[-1][1]
        # the window at t = 0.01 s: 1e-12 * max(1, 0.01) = 1e-12 s; 2e-12 s away is outside it
        assert host.step(t + 2e-12) == ERROR
        assert host.fmu.getRealStatus(2) == t
        assert host.step(t + 1e-13) == OK              # within the window: the same point
        t = host.fmu.getRealStatus(2)
        assert host.step(t, 1e-20) == DISCARD and "advances the time" in host.messages[-1][1]
        assert host.fmu.getRealStatus(2) == t
    finally:
        host.fmu.freeInstance()


@pytest.mark.parametrize("name,value,items", [
    ("fidelity", 9, "0 (kinematic), 1 (quasi-static), 2 (dynamic), 3 (auto)"),
    ("stepper", -1, "0 (default), 1 (closed_form)")])
def test_an_enumeration_value_that_is_no_item_is_named_with_the_items(native, name, value, items):
    from fmpy.fmi1 import FMICallException

    host = native_host(start={name: value}, initialize=False)
    try:
        with pytest.raises(FMICallException):
            host.fmu.exitInitializationMode()
        msg = host.messages[-1][1]
        assert f"{name} = {value} is not allowed: must be one of {items}" in msg, msg
    finally:
        host.fmu.freeInstance()


def test_a_state_of_another_fmu_or_instance_is_refused_before_it_is_used(native):
    a = native_host("PRSM2")
    b = native_host("PRSM3")
    c = native_host("PRSM2", instance="other")
    try:
        state = ctypes.c_void_p()
        assert a.fmu.dll.fmi2GetFMUstate(ctypes.c_void_p(a.fmu.component), ctypes.byref(state)) == OK
        before = ctypes.string_at(state.value, 64)
        cases = []
        for host in (b, c):
            reuse = ctypes.c_void_p(state.value)
            cases.append(host.fmu.dll.fmi2GetFMUstate(ctypes.c_void_p(host.fmu.component), ctypes.byref(reuse)))
            buf = ctypes.create_string_buffer(1 << 16)
            cases.append(host.fmu.dll.fmi2SerializeFMUstate(ctypes.c_void_p(host.fmu.component), state, buf,
                                                            ctypes.c_size_t(1 << 16)))
            cases.append(host.fmu.dll.fmi2SetFMUstate(ctypes.c_void_p(host.fmu.component), state))
        print(f"  {len(cases)} calls with a state of another FMU or instance: statuses {cases}")
        assert cases == [ERROR] * 6
        assert ctypes.string_at(state.value, 64) == before        # nothing written into it
        assert "not made by this instance" in b.messages[-1][1]
        assert a.fmu.dll.fmi2FreeFMUstate(ctypes.c_void_p(a.fmu.component), ctypes.byref(state)) == OK
    finally:
        for h in (a, b, c):
            h.fmu.freeInstance()


def test_fmpy_simulate_fmu_stops_at_a_step_it_cannot_take(native):
    """fmpy's simulate_fmu retries a refused step unchanged while fmi2Terminated is false; the
    second identical refusal reads true, so the run ends at the last good time (0 s here: the
    start torque 1e7 N.m is beyond its bound) instead of looping until the timeout."""
    import time

    from fmpy import simulate_fmu

    t0 = time.monotonic()
    res = simulate_fmu(str(native["PRSM2"]), start_values={"screw_torque": 1e7}, stop_time=0.01,
                       output_interval=1e-3, timeout=60.0)
    took = time.monotonic() - t0
    print(f"  simulate_fmu ended at t = {res['time'][-1]} s after {took:.2f} s")
    assert res["time"][-1] == 0.0 and took < 30.0
