"""The pythonfmu slave's short paths of a master's trial loop equal its general ones.

A master that prescribes the screw speed (prsm_fmu/sweep/fmu_runner.py) saves the FMU state,
steps with a trial torque, reads the speed, restores the state and steps again.  The slave
serves those calls on short paths: a state it made right after an engine step is restored
without the checks and rebuilding of the general restore (:meth:`PRSMSlave._restore_own`), one
input is set alone without the guarded setter, and fmi2GetReal keeps where the values of each
list of outputs it reads are.  Here every short path is checked against the general one on
the same calls: bit for bit equal states, outputs and counters, and the general path taken
wherever the short one does not hold (a state made before any step).
"""

from __future__ import annotations

import random

from prsm_fmu import fmu_state
from prsm_fmu.slave import READ_PLANS, PRSMSlave
from test_slave_step import _bits, engine  # noqa: F401 - fixture

SEED = 20261126
H = 1e-6
#: the Fidelity enumeration's value of the dynamic level (docs/fmu.md, "Variables")
DYNAMIC = 2


def _slave(name: str) -> tuple[PRSMSlave, dict[str, int]]:
    s = PRSMSlave(instance_name=name, resources=None, visible=False, logger=None)
    s._par["fidelity"] = DYNAMIC
    s._par["initial_screw_speed"] = 100.0
    s._par["tolerance"] = 1e-8
    s.setup_experiment(0.0)
    s.enter_initialization_mode()
    s.exit_initialization_mode()
    assert s._phase == "stepping", s._init_error
    assert s._engine_step is not None, "the engine's one-call step is not armed"
    by_name = {v.name: vr for vr, v in s.vars.items()}
    s.set_real([by_name["screw_torque"], by_name["load_force"]], [20.0, 5000.0])
    return s, by_name


class _Spy:
    """Counts the general restores of a slave."""

    def __init__(self, s: PRSMSlave) -> None:
        self.general = 0
        restore = s._restore

        def counted(f):
            self.general += 1
            return restore(f)

        s._restore = counted


def test_own_state_restores_as_its_serialized_copy(engine):
    """A trial loop of ``LOOPS`` steps at 1 µs with seeded random trial torques: each step's
    state is saved after an engine step, one to three trials are stepped from it, and it is
    restored by the short path (the state object itself) on one slave and by the general path
    (its serialized copy, which the slave never made) on the other; after every restore and
    trial both slaves hold equal states, outputs and counters, bit for bit."""
    loops = 200
    short, by_name = _slave("short")
    general, _ = _slave("general")
    outputs = [by_name[n] for n in short._out_names]
    torque_vr, rhs_vr = by_name["screw_torque"], by_name["step_rhs_calls"]
    spy_short, spy_general = _Spy(short), _Spy(general)
    rng = random.Random(SEED)
    for s in (short, general):               # one step: the states now follow engine steps
        assert s.do_step(0.0, H)
    restores = 0
    for k in range(loops):
        saved = short._get_fmu_state()
        copy = fmu_state.from_bytes(fmu_state.to_bytes(general._get_fmu_state()))
        assert _bits(saved) == _bits(copy), k
        for trial in range(rng.randint(1, 3)):
            torque = rng.uniform(15.0, 25.0)
            if trial:
                short._set_fmu_state(saved)
                general._set_fmu_state(copy)
                restores += 1
            for s in (short, general):
                s.set_real([torque_vr], [torque])
                assert s.do_step(s._t, H), s.log_queue[-1:]
            seen = [_bits((s._t, s.get_real(outputs), s.get_integer([rhs_vr]),
                           s._get_fmu_state()[3:])) for s in (short, general)]
            assert seen[0] == seen[1], (k, trial)
    print(f"\n{loops} saved states, {restores} restores: short path {spy_short.general} general "
          f"restores, the copy's {spy_general.general}; equal bit for bit")
    assert restores > loops // 2
    assert spy_short.general == 0                # every restore took the short path
    assert spy_general.general == restores       # a copy is never the slave's own


def test_state_before_any_step_takes_the_general_path(engine):
    """The start state's vector comes from the parameters, not from a checked step: its
    restore is the general one (which checks it), and gives the same as a copy's."""
    s, by_name = _slave("start")
    spy = _Spy(s)
    start = s._get_fmu_state()
    assert s.do_step(0.0, H)
    s._set_fmu_state(start)
    assert spy.general == 1
    assert s._t == 0.0 and _bits(tuple(s._x)) == _bits(start[fmu_state.FIELDS.index("x")])


def test_one_input_set_alone_equals_the_generic_setter(engine):
    """``set_real`` of the torque or the load alone (seeded random values, ``CASES``) writes what
    the generic setter by variable writes, and the other input stays."""
    cases = 50
    a, by_name = _slave("alone")
    b, _ = _slave("generic")
    rng = random.Random(SEED + 1)
    for k in range(cases):
        name = rng.choice(["screw_torque", "load_force"])
        value = rng.uniform(-1e3, 1e3)
        a.set_real([by_name[name]], [value])
        b._set_real([by_name[name]], [value])
        assert _bits(a._u) == _bits(b._u), k
    print(f"\n{cases} single inputs set: equal")


def test_read_plans_of_alternating_lists_equal_the_generic_getters(engine):
    """fmi2GetReal of lists that alternate (the speed, every output) and of more lists than it
    keeps plans of (``READ_PLANS`` + 3 single outputs in turn) reads what each output's own
    getter reads, after each of 20 steps."""
    s, by_name = _slave("plans")
    outputs = [by_name[n] for n in s._out_names]
    lists = [[by_name["screw_speed"]], outputs] + [[vr] for vr in outputs[:READ_PLANS + 3]]
    reads = 0
    for k in range(20):
        assert s.do_step(s._t, H)
        for vrs in lists:
            got = s.get_real(vrs)
            want = [s._rget[vr]() for vr in vrs]
            assert _bits(got) == _bits(want), (k, vrs)
            reads += 1
    print(f"\n{reads} reads of {len(lists)} lists: equal")
