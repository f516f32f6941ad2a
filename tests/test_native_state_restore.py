"""Restoring an FMU state of the native FMU: the cheap restore equals the general one.

A master that saves the FMU state, tries a step and restores the state (the sweep master of
prsm_fmu/sweep/fmu_runner.py, iterative co-simulation masters) restores a state this instance
made with the parameters its model was built from: fmi2SetFMUstate keeps that model instead of
building it again (prsm_fmi2.c, model_built_from).  Every other state (one saved under other
parameters before fmi2Reset, one read from bytes) is built from its own parameters.  The
expected values here are not the FMU's own restores but a second instance that runs the same
accepted steps without any restore, or one built with the state's parameters:

* seeded random sequences of steps with random inputs and step sizes, states saved at random
  points, trial steps with other inputs, restores of a recent saved state and the accepted steps
  run again from there: after every accepted step the outputs, the counters and the serialized
  state equal the second instance's bit for bit;
* a state saved under parameters P1, restored after fmi2Reset and an initialization with other
  parameters P2 (or with P1 again but without initialization), runs as P1 says;
* a state of another instance with the same parameters is still refused, naming the cause,
  and changes nothing.
"""

from __future__ import annotations

import math
import random

import pytest

pytest.importorskip("fmpy")
pytest.importorskip("pythonfmu")

from test_fmu import DISCARD, OK  # noqa: E402
from test_native_fmu import ERROR, native, native_host  # noqa: E402,F401 - fixture

SEED = 20261127
#: step sizes [s] of the random sequences: communication steps of 0.1 ms to 2 ms
STEP_SIZES = (1e-4, 5e-4, 1e-3, 2e-3)
#: the levels the native FMU runs, auto at a tolerance where it switches along a run
STARTS = {"quasi-static": {"fidelity": "quasi-static"},
          "dynamic": {"fidelity": "dynamic"},
          "auto": {"fidelity": "auto", "tolerance": 1e-3}}
#: other parameters than the starts (friction coefficient 0.1 -> 0.05, first lead 10 -> 12 mm:
#: the contact is solved again), both in their ranges (docs/fmu.md, "Parameters")
OTHER = {"mu_screw_roller": 0.05, "stage[1].screw_lead": 0.012}


def _plan(rng: random.Random, n: int) -> list[tuple[float, float, float]]:
    """n steps: (screw torque [N.m], load [N], step size [s])."""
    return [(rng.uniform(-40.0, 40.0), rng.uniform(-2000.0, 5000.0), rng.choice(STEP_SIZES))
            for _ in range(n)]


def _times(plan) -> list[float]:
    """The communication point of each step: the sum of the step sizes before it, added in
    the order the FMU adds them (its time is t + h after each step)."""
    t, out = 0.0, []
    for _, _, h in plan:
        out.append(t)
        t = t + h
    return out


class _Run:
    """One instance with the names it reads after each step."""

    def __init__(self, start: dict) -> None:
        self.host = native_host(start=start)
        md = self.host.md
        self.reals = [v.name for v in md.modelVariables
                      if v.causality == "output" and v.type == "Real"]
        self.ints = [v.name for v in md.modelVariables
                     if v.causality == "output" and v.type != "Real"]
        self.vr_in = [self.host.vars["screw_torque"].valueReference,
                      self.host.vars["load_force"].valueReference]

    def step(self, t: float, torque: float, load: float, h: float) -> int:
        self.host.fmu.setReal(self.vr_in, [torque, load])
        return self.host.step(t, h)

    def record(self) -> tuple[list[float], list[int], bytes]:
        """Real outputs, Integer outputs, the serialized state."""
        return (self.host.get_real(self.reals), self.host.get(self.ints),
                self.host.state_bytes())


def _same(a: tuple, b: tuple) -> bool:
    """Records equal: floats as numbers (a NaN efficiency, where no power passes, equal to a
    NaN in the same place), integers and state bytes exactly."""
    ra, rb = a[0], b[0]
    floats = len(ra) == len(rb) and all(
        x == y or (math.isnan(x) and math.isnan(y)) for x, y in zip(ra, rb))
    return floats and a[1] == b[1] and a[2] == b[2]


def _reference(start: dict, plan) -> list[tuple]:
    """The accepted steps of plan run straight through, no state saved or restored."""
    run = _Run(start)
    try:
        out = []
        for t, (torque, load, h) in zip(_times(plan), plan):
            assert run.step(t, torque, load, h) == OK, run.host.messages[-3:]
            out.append(run.record())
        return out
    finally:
        run.host.free()


@pytest.mark.parametrize("level", list(STARTS))
def test_random_saves_trials_and_restores_equal_a_run_without_restores(native, level):
    rng = random.Random(f"{SEED}-{level}")
    n_seq, n_steps = 3, 60
    counts = {"accepted steps compared": 0, "states saved": 0, "trial steps": 0,
              "refused trial steps": 0, "restores": 0, "steps run again": 0}
    levels = set()          # step_fidelity of the reference's steps
    for _ in range(n_seq):
        plan = _plan(rng, n_steps)
        times = _times(plan)
        ref = _reference(STARTS[level], plan)
        run = _Run(STARTS[level])
        fmu = run.host.fmu
        levels |= {r[1][run.ints.index("step_fidelity")] for r in ref}
        saved: dict[int, object] = {}       # accepted steps done -> the state then
        try:
            k = 0
            while k < n_steps:
                if rng.random() < 0.4:       # save here (into a handle reused at random)
                    reuse = rng.choice(list(saved.values())) if saved and rng.random() < 0.3 \
                        else None
                    if reuse is not None:
                        saved = {j: s for j, s in saved.items() if s is not reuse}
                    saved[k] = fmu.getFMUstate() if reuse is None else _get_into(fmu, reuse)
                    counts["states saved"] += 1
                    while len(saved) > 4:                 # keep the four most recent
                        fmu.freeFMUstate(saved.pop(min(saved)))
                if saved and rng.random() < 0.5:  # trial steps with other inputs, undone
                    t = times[k]
                    for _ in range(rng.randint(1, 3)):
                        torque, load, h = _plan(rng, 1)[0]
                        status = run.step(t, torque, load, h)
                        counts["trial steps"] += 1
                        if status == OK:
                            t = t + h
                        else:
                            assert status == DISCARD, run.host.messages[-3:]
                            counts["refused trial steps"] += 1
                    j = rng.choice(list(saved))
                    fmu.setFMUstate(saved[j])
                    counts["restores"] += 1
                    counts["steps run again"] += k - j
                    k = j
                torque, load, h = plan[k]
                assert run.step(times[k], torque, load, h) == OK, run.host.messages[-3:]
                got = run.record()
                assert _same(got, ref[k]), f"step {k} of {level}: {got[:2]} != {ref[k][:2]}"
                counts["accepted steps compared"] += 1
                k += 1
        finally:
            for s in saved.values():
                fmu.freeFMUstate(s)
            run.host.free()
    print(f"  {level}: {n_seq} sequences of {n_steps} steps (seed {SEED}-{level}): {counts}, "
          f"step_fidelity seen {sorted(levels)}")
    assert counts["restores"] >= 10 and counts["steps run again"] >= 1
    # auto switched between the quasi-static (1) and the dynamic level (2) along the runs
    assert levels == ({1, 2} if level == "auto" else {1 if level == "quasi-static" else 2})


def _get_into(fmu, state):
    """fmi2GetFMUstate into an existing state (FMI 2.0: the FMU overwrites it, same handle)."""
    import ctypes

    handle = state.value
    fmu.fmi2GetFMUstate(fmu.component, ctypes.byref(state))     # fmpy raises unless fmi2OK
    assert state.value == handle
    return state


@pytest.mark.parametrize("level", list(STARTS))
@pytest.mark.parametrize("how", ["own state", "deserialized bytes"])
@pytest.mark.parametrize("then", ["other parameters", "same parameters, not initialized"])
def test_state_saved_before_a_reset_runs_as_its_own_parameters(native, level, how, then):
    """Saved after 30 steps under the start parameters P1; fmi2Reset; then either P2 (OTHER),
    initialization and 10 steps, or P1 again left in initialization mode; the state restored
    must run steps 30..59 as an instance of P1 that never stopped."""
    rng = random.Random(f"{SEED}-reset-{level}")
    plan = _plan(rng, 60)
    times = _times(plan)
    ref = _reference(STARTS[level], plan)
    run = _Run(STARTS[level])
    fmu = run.host.fmu
    try:
        for k in range(30):
            assert run.step(times[k], *plan[k]) == OK
        state = fmu.getFMUstate()
        data = bytes(fmu.serializeFMUstate(state))
        fmu.reset()
        fmu.setupExperiment(startTime=0.0)
        fmu.enterInitializationMode()
        run.host.set(STARTS[level])
        if then == "other parameters":
            run.host.set(OTHER)
            fmu.exitInitializationMode()
            for k in range(10):
                assert run.step(times[k], *plan[k]) == OK
            # the other parameters act: the outputs of the 10th step are not P1's
            outputs = run.record()[:2]
            assert not _same((*outputs, b""), (*ref[9][:2], b""))
        if how == "deserialized bytes":
            fmu.freeFMUstate(state)
            state = fmu.deSerializeFMUstate(data)
        fmu.setFMUstate(state)
        assert run.host.state_bytes() == data
        for k in range(30, 60):
            assert run.step(times[k], *plan[k]) == OK, run.host.messages[-3:]
            got = run.record()
            assert _same(got, ref[k]), f"step {k}: {got[:2]} != {ref[k][:2]}"
        fmu.freeFMUstate(state)
    finally:
        run.host.free()


def test_state_of_another_instance_with_the_same_parameters_is_refused(native):
    from fmpy.fmi1 import FMICallException

    plan = _plan(random.Random(f"{SEED}-other"), 5)
    a, b = _Run(STARTS["dynamic"]), _Run(STARTS["dynamic"])
    try:
        for run in (a, b):
            for t, step in zip(_times(plan), plan):
                assert run.step(t, *step) == OK
        state = a.host.fmu.getFMUstate()
        before = b.record()
        with pytest.raises(FMICallException) as exc:
            b.host.fmu.setFMUstate(state)
        assert exc.value.status == ERROR
        assert b.host.messages[-1][0] == ERROR
        assert "fmi2SetFMUstate: the FMU state" in b.host.messages[-1][1]
        assert "was not made by this instance (prsm)" in b.host.messages[-1][1]
        assert _same(b.record(), before)
        a.host.fmu.freeFMUstate(state)
    finally:
        a.host.free()
        b.host.free()
