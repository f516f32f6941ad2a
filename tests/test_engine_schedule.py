"""simulate() hands a whole run of known inputs to the engine in one call
(NativeStepper.advance_schedule, prsm_api_advance_schedule) and gets the outputs back computed
in C, equal bit for bit to the engine stepped advance by advance with Model.outputs after each
interval (the per-step path) and to the Python reference.

Seeded random runs: mechanism (PRSM1: the friction-torque article's preset with its viscous
and differential-sliding terms; PRSM2; PRSM3), level, drive, speed profile (constant, ramp, a
table whose corners fall inside output intervals, so that an interval is split in pieces),
torque and load signals of time, output interval and length.  The counts are printed.
"""

from __future__ import annotations

import importlib
import math
import random
import shutil
import struct

import numpy as np
import pytest

from fmu_build.mechanisms import FMUS
from fmu_build.native_stepper import NativeStepper
from prsm_fmu.profiles import ConstantSpeed, RampSpeed, TableSpeed
from prsm_fmu.simulate import simulate

#: the module (prsm_fmu.simulate the name is the function, which the package exports)
simulate_module = importlib.import_module("prsm_fmu.simulate")

pytestmark = pytest.mark.skipif(shutil.which("gcc") is None, reason="needs gcc")

SEED = 20261126
RUNS = 60
LEVELS = ("kinematic", "quasi-static", "dynamic")


def _bits(a: np.ndarray) -> bytes:
    """The array's bytes: equal bit for bit, a NaN equal to the same NaN."""
    return np.ascontiguousarray(a, dtype=np.float64).tobytes()


def _case(rng: random.Random) -> tuple[str, dict]:
    name = rng.choice(("PRSM1", "PRSM2", "PRSM3"))
    h = rng.choice((1e-6, 1e-5, 1e-4))
    n = rng.randint(5, 120)
    kw = dict(fidelity=rng.choice(LEVELS), t_end=n * h, output_interval=h)
    f0, f1 = rng.uniform(-6000.0, 6000.0), rng.uniform(-1e6, 1e6)
    kw["load_force"] = (lambda t, f0=f0, f1=f1: f0 + f1 * t) if rng.random() < 0.5 else f0
    if rng.random() < 0.6:
        kw["drive"] = "speed"
        kind = rng.choice(("constant", "ramp", "table"))
        w = rng.choice((-1.0, 1.0)) * rng.uniform(1.0, 200.0)
        if kind == "constant":
            kw["screw_speed"] = ConstantSpeed(w)
        elif kind == "ramp":
            kw["screw_speed"] = RampSpeed(0.0, w, rng.uniform(0.2, 1.5) * n * h)
        else:      # corners at random times: most fall inside an interval (split in pieces)
            times = sorted(rng.uniform(0.0, n * h) for _ in range(4))
            kw["screw_speed"] = TableSpeed(times, [rng.uniform(-200.0, 200.0) for _ in times])
    else:
        kw["drive"] = "torque"
        t0, t1 = rng.uniform(-20.0, 20.0), rng.uniform(-1e4, 1e4)
        kw["screw_torque"] = lambda t, t0=t0, t1=t1: t0 + t1 * t
        kw["initial_screw_speed"] = rng.uniform(-150.0, 150.0)
    return name, kw


def _per_step(monkeypatch, params, kw) -> dict:
    """The engine stepped advance by advance (the schedule's one call switched off)."""
    with monkeypatch.context() as m:
        m.setattr(simulate_module, "_run_in_engine", lambda *a: None)
        return simulate(params, **kw)


def test_one_call_equals_the_per_step_engine_and_the_reference(monkeypatch, capsys):
    rng = random.Random(SEED)
    counts = {"runs": 0, "split intervals": 0, "failed alike": 0, "samples": 0}
    for i in range(RUNS):
        name, kw = _case(rng)
        params = FMUS[name][0]()
        results = []
        for how in ("one call", "per step", "python"):
            try:
                if how == "one call":
                    res = simulate(params, **kw)
                elif how == "per step":
                    res = _per_step(monkeypatch, params, kw)
                else:
                    res = simulate(params, engine="python", **kw)
                results.append(res)
            except Exception as exc:  # noqa: BLE001 - must fail alike in every path
                results.append(f"{type(exc).__name__}: {exc}")
        if isinstance(results[0], str):
            assert results[0] == results[1], (i, name, kw)
            counts["failed alike"] += 1
            continue
        assert results[0]["engine"] == "native", results[0]["engine_fallback"]
        for other in results[1:]:
            assert not isinstance(other, str), (i, other)
            assert other["rhs_calls"] == results[0]["rhs_calls"], (i, name)
            for key, value in results[0].items():
                if isinstance(value, np.ndarray):
                    assert _bits(value) == _bits(other[key]), (i, name, kw["fidelity"],
                                                               kw["drive"], key)
        counts["runs"] += 1
        counts["samples"] += len(results[0]["time"])
        profile = kw.get("screw_speed")
        if isinstance(profile, TableSpeed):
            h = kw["output_interval"]
            counts["split intervals"] += sum(1 for t in profile.times
                                             if 0.0 < t < kw["t_end"] and t % h != 0.0)
    with capsys.disabled():
        print(f"\n{RUNS} seeded runs: {counts['runs']} equal bit for bit in the three paths "
              f"({counts['samples']} samples, {counts['split intervals']} profile corners "
              f"inside an interval), {counts['failed alike']} failing alike")
    assert counts["runs"] >= RUNS * 0.8
    assert counts["split intervals"] > 0


def test_the_run_is_one_call_into_the_engine(monkeypatch):
    """Li et al. (2021) §3.1's start-up (100 rad/s, 5 kN, dynamic, 1 ms in 1 µs steps): no
    advance of the stepper is called from Python."""
    params = FMUS["PRSM2"][0]()
    kw = dict(fidelity="dynamic", drive="speed", screw_speed=100.0, load_force=5000.0,
              t_end=1e-3, output_interval=1e-6)
    expected = _per_step(monkeypatch, params, kw)

    def refuse(*args, **kwargs):
        raise AssertionError("a per-step advance was called")

    monkeypatch.setattr(NativeStepper, "advance", refuse)
    monkeypatch.setattr(NativeStepper, "advance_many", refuse)
    got = simulate(params, **kw)
    assert got["engine"] == "native"
    assert len(got["time"]) == 1001
    for key in ("screw_speed", "stage[2].carrier_speed", "efficiency", "screw_torque"):
        assert _bits(got[key]) == _bits(expected[key]), key


def test_a_failing_run_raises_what_the_per_step_path_raises(monkeypatch):
    """One internal step allowed per advance at the dynamic level: the engine's one call stops
    at the first refused advance and the per-step path runs the run again to name the cause,
    the same error and message."""
    params = FMUS["PRSM2"][0]()
    kw = dict(fidelity="dynamic", drive="speed", screw_speed=100.0, load_force=5000.0,
              t_end=1e-4, output_interval=1e-5, stepper_options={"max_substeps": 1})
    messages = []
    for run in (lambda: simulate(params, **kw), lambda: _per_step(monkeypatch, params, kw)):
        with pytest.raises(Exception) as info:
            run()
        messages.append(f"{type(info.value).__name__}: {info.value}")
    assert messages[0] == messages[1]
    assert "StepFailure" in messages[0]


def test_advance_schedule_refuses_bad_arrays_naming_them():
    from prsm_fmu.engine import engine_stepper
    from prsm_fmu.models import make_model

    params = FMUS["PRSM2"][0]()
    model = make_model(params, "dynamic", "speed")
    st, why = engine_stepper(model, "dynamic", "rosenbrock", 1e-8, 1e-10)
    assert st is not None, why
    x = model.initial_state((0.0, 0.0), screw_speed=1.0)
    with pytest.raises(ValueError, match=r"length = 0\.0 is out of range: must be a finite "
                                         r"number > 0 \[s\]"):
        st.advance_schedule(x, [0.0, 1e-6], [1e-6, 0.0], [(0.0, 0.0)] * 2, [True, True])
    with pytest.raises(ValueError, match=r"length = nan is out of range"):
        st.advance_schedule(x, [0.0], [math.nan], [(0.0, 0.0)], [True])
    with pytest.raises(ValueError, match=r"must have 2 rows"):
        st.advance_schedule(x, [0.0, 1e-6], [1e-6], [(0.0, 0.0)] * 2, [True, True])
    # the refused calls changed nothing: a valid one runs from a fresh memory
    y, x_end, stats, done, reason = st.advance_schedule(x, [0.0], [1e-6], [(0.0, 0.0)], [True])
    assert done == 1 and reason == "" and y.shape == (1, len(st.output_names))
    assert all(math.isfinite(v) for v in x_end) and stats.rhs_calls > 0
    assert struct.pack("<d", y[0][st.output_names.index("screw_speed")]) == \
        struct.pack("<d", 1.0)          # speed held: acceleration 0 over the step


def test_a_constant_speed_splits_an_interval_as_the_general_profile(capsys):
    """ConstantSpeed.pieces (one piece, acceleration 0.0, no calls) equals the base class's
    (ω₀ − ω₀)/(t1 − t0) bit for bit, the sign of the zero included, on seeded random cases."""
    from prsm_fmu.profiles import SpeedProfile

    rng = random.Random(f"{SEED}-constant")
    cases = 2000
    for _ in range(cases):
        w = rng.choice((-1.0, 1.0)) * 10.0 ** rng.uniform(-6.0, 4.0) if rng.random() > 0.05 \
            else rng.choice((0.0, -0.0))
        t0 = rng.uniform(0.0, 10.0)
        t1 = t0 + 10.0 ** rng.uniform(-9.0, 0.0)
        profile = ConstantSpeed(w)
        got, ref = profile.pieces(t0, t1), SpeedProfile.pieces(profile, t0, t1)
        assert len(got) == len(ref) == 1
        assert [struct.pack("<d", v) for v in got[0]] == [struct.pack("<d", v) for v in ref[0]]
    with capsys.disabled():
        print(f"\n{cases} seeded (speed, interval) cases: one piece, equal bit for bit")


@pytest.mark.parametrize("drive", ["speed", "torque"])
def test_a_run_listed_in_blocks_equals_the_run_listed_at_once(monkeypatch, drive):
    """A long run's advances go to the engine in blocks (simulate.SCHEDULE_BLOCK intervals):
    with blocks of 7 intervals (a ramp's corner inside one, so a block holds a split interval)
    the engine's and the per-step path's results equal the run in one block bit for bit."""
    params = FMUS["PRSM2"][0]()
    kw = dict(fidelity="dynamic", drive=drive, load_force=lambda t: 5000.0 - 1e6 * t,
              t_end=100 * 1e-5, output_interval=1e-5)
    if drive == "speed":
        kw["screw_speed"] = RampSpeed(0.0, 100.0, 33.3e-5)      # corner inside interval 33
    else:
        kw["screw_torque"] = lambda t: 3.0 + 2e3 * t
    whole = simulate(params, **kw)
    monkeypatch.setattr(simulate_module, "SCHEDULE_BLOCK", 7)
    blocks = simulate(params, **kw)
    blocks_per_step = _per_step(monkeypatch, params, kw)
    assert blocks["engine"] == whole["engine"] == "native"
    for key, value in whole.items():
        if isinstance(value, np.ndarray):
            assert _bits(blocks[key]) == _bits(value), key
            assert _bits(blocks_per_step[key]) == _bits(value), key
    assert blocks["rhs_calls"] == whole["rhs_calls"] == blocks_per_step["rhs_calls"]
