"""The closed-form step of the slaved-carrier levels equals a tight numerical integration.

Expected values: scipy's Radau at rtol 1e-13 on the same right-hand side (an independent
integration); the closed form must agree to 1e-11 wherever it answers, and decline (None)
where its premise fails (zero speed crossed, friction band entered).
"""

from __future__ import annotations

import random

import pytest

from prsm_fmu import presets
from prsm_fmu.models import make_model
from prsm_fmu.steppers import make_stepper

LI2021 = presets.load("li2021_two_stage")
ASSEMBLY = presets.load("assembly_two_stage")   # with thrust-bearing friction


@pytest.mark.parametrize("params", [LI2021, ASSEMBLY], ids=["li2021", "assembly_article"])
@pytest.mark.parametrize("fidelity,opts", [("quasi-static", {}), ("kinematic", {"efficiency": 0.9})])
@pytest.mark.parametrize("drive", ["torque", "speed"])
def test_closed_form_step_equals_tight_integration(params, fidelity, opts, drive):
    model = make_model(params, fidelity, drive, **opts)
    ref = make_stepper("radau", model, rtol=1e-13, atol=1e-15)
    rng = random.Random(7)
    answered = 0
    for _ in range(60):
        w = rng.choice([-1.0, 1.0]) * rng.uniform(2.0, 200.0)
        load = rng.uniform(-8000.0, 8000.0)
        x = [0.3, w, 1.0, 2.0, 3.0]
        if drive == "torque":
            u = (rng.uniform(-40.0, 40.0), load)
        else:   # prescribed acceleration: constant speed in one case of three
            u = (rng.choice([0.0, rng.uniform(-5e3, 5e3)]), load)
        h = rng.choice([1e-4, 1e-3])
        got = model.closed_form_advance(0.0, x, u, h)
        if got is None:
            continue
        answered += 1
        want, _ = ref.advance(0.0, x, u, h)
        for a, b in zip(got, want):
            assert a == pytest.approx(b, rel=1e-11, abs=1e-11)
    assert answered >= 10


def test_closed_form_declines_a_step_through_zero_speed():
    model = make_model(LI2021, "quasi-static", "torque")
    # 5 N·m against 5 kN (≈ 19.7 N·m needed at η ≈ 0.8) decelerates at ~3e4 rad/s² on an inertia
    # of ~4.3e-4 kg·m² (screws 55 + 170 kg·mm² = 2.25e-4; nut 2's 18 kg at c_2 = 20 mm/2π:
    # 18 × (3.18e-3)² = 1.8e-4): from 30 rad/s, zero is reached after ~1 ms
    assert model.closed_form_advance(0.0, [0.0, 30.0, 0.0, 0.0, 0.0], (5.0, 5000.0), 2e-3) is None
    assert model.closed_form_advance(0.0, [0.0, 30.0, 0.0, 0.0, 0.0], (5.0, 5000.0), 1e-4) is not None
    assert model.closed_form_advance(0.0, [0.0, 1e-3, 0.0, 0.0, 0.0], (30.0, 5000.0), 1e-6) is None


def test_dynamic_level_offers_no_closed_form():
    assert not hasattr(make_model(LI2021, "dynamic"), "closed_form_advance")


def test_closed_form_stepper_falls_back_through_zero_speed_and_conserves_energy():
    from prsm_fmu import simulate
    r = simulate(LI2021, "quasi-static", "torque", screw_torque=5.0, load_force=5000.0,
                 t_end=2e-3, output_interval=1e-4, initial_screw_speed=30.0, stepper="closed_form",
                 rtol=1e-9, atol=1e-12)
    assert r["screw_speed"][0] > 0 > r["screw_speed"][-1]
    ref = simulate(LI2021, "quasi-static", "torque", screw_torque=5.0, load_force=5000.0,
                   t_end=2e-3, output_interval=1e-4, initial_screw_speed=30.0, stepper="radau",
                   rtol=1e-12, atol=1e-14)
    assert r["screw_speed"] == pytest.approx(ref["screw_speed"], rel=1e-6, abs=1e-6)
    balance = r["input_work"] - r["output_work"] - r["friction_work"] - (r["kinetic_energy"] - r["kinetic_energy"][0])
    assert max(abs(balance)) <= 1e-6 * max(abs(r["input_work"]))


def test_closed_form_stepper_refuses_a_model_without_a_closed_form():
    from prsm_fmu.steppers import make_stepper as mk
    with pytest.raises(ValueError, match="closed_form_advance"):
        mk("closed_form", make_model(LI2021, "dynamic"))
