"""The engine's outputs in C (prsm_api_outputs, what the pythonfmu FMU reads through
EngineStepper.output_reader) equal the Python model's Model.outputs bit for bit.

Per mechanism (PRSM1: the friction-torque article's preset with its viscous and
differential-sliding terms; PRSM2; PRSM3), level (kinematic, quasi-static, dynamic) and drive
(the torque drive, the FMU's; the speed drive, whose u[0] is the prescribed acceleration, the
sweeps' and simulate's),
STATES random states and inputs (seeded): the screw at exact standstill (the efficiency's NaN,
compared by its bits), creeping inside the friction band, or moving either way; the carriers
around their slaved ratio; the works of either sign or zero; inputs of either sign or zero.
The counts are printed.  A state where the Python model raises (none expected) is counted and
must be one where the rigid contact has no solution.
"""

from __future__ import annotations

import math
import random
import shutil
import struct

import pytest

from fmu_build.mechanisms import FMUS
from fmu_build.native import api_outputs
from prsm_fmu.engine import engine_stepper, is_engine
from prsm_fmu.models import make_model
from prsm_fmu.slave import output_names

pytestmark = pytest.mark.skipif(shutil.which("gcc") is None, reason="needs gcc")

SEED = 20261126
STATES = 500
LEVELS = ("kinematic", "quasi-static", "dynamic")
ENGINE_STEPPER = {"kinematic": "closed_form", "quasi-static": "closed_form",
                  "dynamic": "rosenbrock"}


def _params(name: str):
    params = FMUS[name][0]()
    if name == "PRSM1":      # the friction preset: both of the article's terms act
        assert params.mu_viscous > 0.0 and params.mu_differential > 0.0
    return params


def _bits(values) -> list[bytes]:
    return [struct.pack("<d", float(v)) for v in values]


def _state(rng: random.Random, model, v_eps: float) -> list[float]:
    kind = rng.random()
    if kind < 0.2:
        speed = 0.0
    elif kind < 0.45:
        speed = rng.uniform(-3.0, 3.0) * v_eps
    else:
        speed = rng.choice((-1.0, 1.0)) * math.exp(rng.uniform(math.log(1e-3), math.log(500.0)))
    x = [rng.uniform(-50.0, 50.0), speed]
    for name in model.state_names[2:]:
        if name.startswith("carrier"):
            x.append(speed * rng.uniform(0.2, 0.6) + rng.uniform(-1.0, 1.0))
        else:
            x.append(0.0 if rng.random() < 0.2 else rng.uniform(-100.0, 1000.0))
    return x


def _inputs(rng: random.Random) -> tuple[float, float]:
    def draw(scale: float) -> float:
        return 0.0 if rng.random() < 0.1 else rng.uniform(-scale, scale)

    return draw(30.0), draw(6000.0)


@pytest.mark.parametrize("name", ("PRSM1", "PRSM2", "PRSM3"))
def test_engine_outputs_equal_the_model_bit_for_bit(name, capsys):
    params = _params(name)
    names = output_names(params.n_stages)
    # the C computes every output of the FMU (and it maps them by name)
    assert set(names) <= {n for n, _, _ in api_outputs(params.n_stages)}
    rng = random.Random(f"{SEED}-{name}")
    report = []
    for level in LEVELS:
        for drive in ("torque", "speed"):
            model = make_model(params, level, drive)
            st, why = engine_stepper(model, level, ENGINE_STEPPER[level], 1e-6, 1e-8)
            assert st is not None and is_engine(st), why
            assert st.output_names == tuple(n for n, _, _ in api_outputs(params.n_stages))
            read = st.output_reader(names)
            assert read is not None
            v_eps = params.slip_velocity_scale / abs(model.mechanism.c_out)
            n_equal = n_nan = n_raised = 0
            for i in range(STATES):
                x, u = _state(rng, model, v_eps), _inputs(rng)
                t = rng.uniform(0.0, 10.0)
                try:
                    y = model.outputs(t, x, u)
                except Exception:  # noqa: BLE001 - counted; only where no rigid contact exists
                    assert model.contact_diagnosis(x, u) is not None, (level, drive, x, u)
                    n_raised += 1
                    continue
                ref = [y[n] for n in names]
                got = read(t, x, u)
                if _bits(got) != _bits(ref):
                    bad = [(n, a, b) for n, a, b in zip(names, got, ref)
                           if _bits([a]) != _bits([b])]
                    pytest.fail(f"{name} {level} {drive} state {i} x={x} u={u}: engine != "
                                f"model for {bad}")
                every = st.outputs(t, x, u)
                assert _bits(every[n] for n in names) == _bits(ref)
                n_equal += 1
                n_nan += math.isnan(y["efficiency"])
            assert n_equal >= STATES - n_raised
            report.append(f"{name} {level:12s} {drive:6s}: {n_equal}/{STATES} states bit for "
                          f"bit ({n_nan} with efficiency NaN), {n_raised} where the model raises")
    with capsys.disabled():
        print("\n" + "\n".join(report))


@pytest.mark.parametrize("fidelity", ["kinematic", "quasi-static", "dynamic"])
def test_the_slave_reads_the_engine_outputs_equal_to_the_reference_slave(monkeypatch, fidelity):
    """The pythonfmu slave (in-process, PRSM2) computes its outputs in C where the engine runs
    (one ctypes call per fmi2GetReal after a step) and with Model.outputs where the Python
    reference runs; after the same steps with inputs new every step, all its Real outputs are
    equal bit for bit."""
    from prsm_fmu.engine import ENGINE_ENV
    from prsm_fmu.slave import PRSMSlave

    slaves = {}
    for engine in ("native", "python"):
        monkeypatch.setenv(ENGINE_ENV, engine)
        s = PRSMSlave(instance_name=engine, resources=None, visible=False, logger=None)
        s._par["fidelity"] = LEVELS.index(fidelity)     # the enumeration's codes 0, 1, 2
        s._par["initial_screw_speed"] = 100.0
        s.setup_experiment(0.0)
        s.enter_initialization_mode()
        s.exit_initialization_mode()
        assert s._phase == "stepping", s._init_error
        slaves[engine] = s
    assert slaves["native"]._engine_outputs is not None
    assert slaves["python"]._engine_outputs is None
    vrs = list(slaves["native"]._out_index)
    rng = random.Random(f"{SEED}-slave-{fidelity}")
    for k in range(200):
        u = (rng.uniform(-30.0, 30.0), rng.uniform(-6000.0, 6000.0))
        got = []
        for s in slaves.values():
            s._u[0], s._u[1] = u
            assert s.do_step(k * 1e-3, 1e-3)
            got.append(s.get_real(vrs))
        assert _bits(got[0]) == _bits(got[1]), k
