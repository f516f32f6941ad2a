"""The pythonfmu slave's doStep in one engine call equals its checked doStep, refusals included.

Where the compiled engine runs a fixed level, :meth:`prsm_fmu.slave.PRSMSlave.do_step` takes
the step in one C call (``prsm_api_step``: the time, step size and input checks, the advance
and the state's bounds in C) and falls back to the checked step (every check in Python,
through the engine's ``advance``) wherever that call does not take it.  Two in-process slaves
of the same PRSM2, one stepping that way and one whose every step is the checked one, are
driven through the same calls: their results (return value, time, state, counters, outputs,
the whole FMU state with the stepper's memory) must be equal bit for bit, and a refused step
must log the same message and leave everything as it was.
"""

from __future__ import annotations

import math
import random
import struct

import pytest

from prsm_fmu.engine import ENGINE_ENV
from prsm_fmu.slave import PRSMSlave

SEED = 20261126
#: the Fidelity enumeration's values (docs/fmu.md, "Variables")
FIDELITY = {"kinematic": 0, "quasi-static": 1, "dynamic": 2}
H = 1e-3
STEPS = 300


def _bits(value):
    """Floats as their bit patterns (so that -0.0 != 0.0 and NaN == NaN), recursively."""
    if isinstance(value, float):
        return struct.pack("<d", value)
    if isinstance(value, (list, tuple)):
        return tuple(_bits(v) for v in value)
    return value


def _slave(name: str, fidelity: str, one_call: bool) -> PRSMSlave:
    s = PRSMSlave(instance_name=name, resources=None, visible=False, logger=None)
    s._par["fidelity"] = FIDELITY[fidelity]
    s._par["initial_screw_speed"] = 100.0
    s.setup_experiment(0.0)
    s.enter_initialization_mode()
    s.exit_initialization_mode()
    assert s._phase == "stepping", s._init_error
    if one_call:
        assert s._engine_step is not None, "the engine's one-call step is not armed"
    else:
        s._engine_step = None          # every doStep the checked one
    return s


def _refs(s: PRSMSlave) -> tuple[list[int], list[int], list[int]]:
    """Value references of the inputs, of every Real output and of the Integer outputs."""
    by_name = {v.name: vr for vr, v in s.vars.items()}
    inputs = [by_name["screw_torque"], by_name["load_force"]]
    counters = [by_name[n] for n in ("step_rhs_calls", "step_substeps", "step_fidelity",
                                     "contact_status")]
    return inputs, list(s._out_index), counters


def _observed(s: PRSMSlave, outputs: list[int], counters: list[int]) -> tuple:
    """What a host and a restore see: time, state, counters, every output, the FMU state.
    The step counters are read as a host's step loop reads them (``get_integer``'s own path)
    and through the generic one (by variable, with contact_status), which must agree."""
    state = s._get_fmu_state()
    read = s.get_integer(counters[:3])
    assert read == s._get_integer(counters)[:3]
    return _bits((s._t, list(s._x), s.get_integer(counters), read, s.get_real(outputs), state))


@pytest.fixture()
def engine(monkeypatch):
    monkeypatch.setenv(ENGINE_ENV, "native")


@pytest.mark.parametrize("fidelity", list(FIDELITY))
def test_one_call_step_equals_the_checked_step(engine, fidelity):
    """``STEPS`` steps of 1 ms from 100 rad/s, inputs new at random (seeded) or held, at the
    communication points k·H a host computes (which differ from the FMU's summed time in the
    last bits, within its time match); an FMU state taken halfway, 20 steps, the state restored
    and the same 20 steps again: both slaves equal bit for bit after every call."""
    fast, checked = (_slave(f"{fidelity}-{k}", fidelity, k == "fast") for k in ("fast", "checked"))
    inputs, outputs, counters = _refs(fast)
    rng = random.Random(f"{SEED}-{fidelity}")
    u = [19.747, 5000.0]
    one_call = off_grid = 0
    for k in range(STEPS):
        if rng.random() < 0.7:       # else held
            u = [rng.uniform(-30.0, 30.0), rng.uniform(-6000.0, 6000.0)]
        t = k * H
        off_grid += t != fast._t
        results = []
        fast.set_real(inputs, u)              # the host loop's path
        checked._set_real(inputs, u)          # the generic one, by variable
        for s in (fast, checked):
            results.append(s.do_step(t, H))
        one_call += fast._stats is None
        assert results == [True, True], (k, fast.log_queue[-1:], checked.log_queue[-1:])
        assert _observed(fast, outputs, counters) == _observed(checked, outputs, counters), k
        if k == STEPS // 2:
            saved = [s._get_fmu_state() for s in (fast, checked)]
            first = []
            for j in range(20):
                for s in (fast, checked):
                    s.set_real(inputs, [10.0 + j, 4000.0])
                    assert s.do_step(s._t, H)
                first.append(_observed(fast, outputs, counters))
                assert first[-1] == _observed(checked, outputs, counters), (k, j)
            for s, state in zip((fast, checked), saved):
                s._set_fmu_state(state)
            for j in range(20):
                for s in (fast, checked):
                    s.set_real(inputs, [10.0 + j, 4000.0])
                    assert s.do_step(s._t, H)
                again = _observed(fast, outputs, counters)
                assert again == _observed(checked, outputs, counters), (k, j)
                # the FMU states differ only in being taken later: compare the rest
                assert again[:5] == first[j][:5], (k, j)
            for s in (fast, checked):
                s._set_fmu_state(saved[0] if s is fast else saved[1])
    print(f"\n{fidelity}: {STEPS} steps + 40 after a restore, {one_call} of the {STEPS} in one "
          f"engine call ({off_grid} at a point off the FMU's summed time), equal bit for bit")
    assert one_call == STEPS


#: (what is wrong, communication point(t) [s], step size [s], inputs): each refused; the inputs'
#: bounds are docs/fmu.md's (0 or |T| in [1e-150, 1e6] N.m, 0 or |F| in [1e-150, 1e8] N), the
#: state's speed bound 1e5 rad/s
BAD_STEPS = [
    ("point off the FMU's time", lambda t: t + 1e-6, H, (19.747, 5000.0)),
    ("point before the FMU's time", lambda t: t - 1e-3, H, (19.747, 5000.0)),
    ("zero step", lambda t: t, 0.0, (19.747, 5000.0)),
    ("negative step", lambda t: t, -H, (19.747, 5000.0)),
    ("NaN step", lambda t: t, math.nan, (19.747, 5000.0)),
    ("infinite step", lambda t: t, math.inf, (19.747, 5000.0)),
    ("step that does not advance the time", lambda t: t, 1e-300, (19.747, 5000.0)),
    ("NaN torque", lambda t: t, H, (math.nan, 5000.0)),
    ("infinite load", lambda t: t, H, (19.747, -math.inf)),
    ("torque beyond its bound", lambda t: t, H, (2e6, 5000.0)),
    ("load beyond its bound", lambda t: t, H, (19.747, -2e8)),
    ("torque below the smallest magnitude", lambda t: t, H, (1e-200, 5000.0)),
    # 1e5 N.m for 1e70 s: the speed bound follows from the kinetic energy's 1e150 J (of the
    # order of 1e76-1e77 rad/s for PRSM2, docs/fmu.md); the closed form ends at about
    # (T / J) h = 1e5 / (~1e-4 kg m2) * 1e70 s ~ 1e79 rad/s, beyond it (or, at the dynamic level,
    # the integration gives up first)
    ("state beyond its bounds", lambda t: t, 1e70, (1e5, 0.0)),
]


@pytest.mark.parametrize("fidelity", list(FIDELITY))
def test_one_call_step_refuses_as_the_checked_step(engine, fidelity):
    """Every step of :data:`BAD_STEPS`, from the state after 20 good steps: both slaves refuse
    it (False) with the same logged message, every observable (the FMU state with the
    stepper's memory included) as before the call; the next good step is equal bit for bit."""
    fast, checked = (_slave(f"{fidelity}-{k}", fidelity, k == "fast") for k in ("fast", "checked"))
    inputs, outputs, counters = _refs(fast)
    for s in (fast, checked):
        for k in range(20):
            s.set_real(inputs, [19.747, 5000.0])
            assert s.do_step(s._t, H)
    refused = 0
    for what, point, h, u in BAD_STEPS:
        before = [_observed(s, outputs, counters) for s in (fast, checked)]
        assert before[0] == before[1], what
        logs = []
        for s in (fast, checked):
            s.set_real(inputs, list(u))
            n0 = len(s.log_queue)
            assert s.do_step(point(s._t), h) is False, what
            logs.append([(m.status, m.msg) for m in s.log_queue[n0:]])
        assert logs[0] == logs[1] and logs[0], (what, logs)
        assert "refused, state unchanged" in logs[0][-1][1], (what, logs[0])
        after = [_observed(s, outputs, counters) for s in (fast, checked)]
        # everything as before but the FMU state's inputs (the refused ones are still set)
        assert [a[:5] for a in after] == [b[:5] for b in before], what
        assert [a[5][5:] for a in after] == [b[5][5:] for b in before], what
        refused += 1
        for s in (fast, checked):
            s.set_real(inputs, [19.747, 5000.0])
            assert s.do_step(s._t, H), what
        assert fast._stats is None, what       # the good step after it: in one call again
        assert _observed(fast, outputs, counters) == _observed(checked, outputs, counters), what
    print(f"\n{fidelity}: {refused} refused steps, each the same message and nothing changed")
    assert refused == len(BAD_STEPS)
