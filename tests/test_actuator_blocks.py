"""The actuator's new blocks against their closed forms (no FMU, no simulation of the loop).

Every expected value is worked out by hand in the comment beside it from the law the module
docstring states (MSL 4.1's LossyGear, ElastoBacklash, ElastoGap, SlewRateLimiter, FirstOrder,
Derivative), not from the code.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from system_models.contact import ContactParams, GapContactLoad, end_stop_force, gap_contact_force
from system_models.current_motor import CurrentFedMotor, CurrentFedMotorParams
from system_models.filters import ContinuousPI, DerivativeFilter, lag_step
from system_models.gear import (GearParams, RigidGear, elasto_backlash_torque, mesh_input_torque,
                                mesh_loss, play)
from system_models.noise import SampledNoise, Sensor, quantise
from system_models.signals import make_profile
from system_models.slew import SlewRateLimiter

#: the MSL example's gearbox: N = 10, η_f = 0.85, η_b = 0.8, τ_bf = 0.1 N·m
MSL_GEAR = GearParams(ratio=10.0, efficiency_forward=0.85, efficiency_backward=0.8,
                      bearing_torque=0.1, backlash=0.002, stiffness=1e6, damping=1e4,
                      stick_speed=0.01)


# ---- gear ------------------------------------------------------------------------------------
@pytest.mark.parametrize("tau_a, w_a, out", [
    (5.0, 10.0, 41.5),     # motor drives forward: N (η_f τ_a − τ_bf) = 10 (0.85·5 − 0.1) = 41.5
    (-4.0, 10.0, -51.0),   # load drives (back-driven, ω > 0): N (τ_a/η_b − τ_bf) = 10 (−5 − 0.1)
    (-5.0, -10.0, -41.5),  # motor drives backward: N (η_f τ_a + τ_bf) = 10 (−4.25 + 0.1)
    (4.0, -10.0, 51.0),    # load drives, ω < 0: N (τ_a/η_b + τ_bf) = 10 (5 + 0.1)
])
def test_gear_efficiency_forward_and_backward_in_all_four_quadrants(tau_a, w_a, out):
    loss = mesh_loss(tau_a, w_a, MSL_GEAR)
    assert MSL_GEAR.ratio * (tau_a - loss) == pytest.approx(out, rel=1e-14)
    # and the inverse: the mesh torque that delivers that output torque
    assert mesh_input_torque(out, w_a, MSL_GEAR) == pytest.approx(tau_a, rel=1e-14)


def test_a_stuck_gear_holds_every_output_torque_between_its_two_efficiency_limits():
    # τ_a = 4 N·m at rest: the output may be anywhere between N (η_f τ_a − τ_bf) = 33 N·m
    # (rolling forward) and N (τ_a/η_b + τ_bf) = 51 N·m (rolling backward); inside the stick
    # band the loss moves linearly between them, so at ω = 0 the midpoint 42 N·m
    n, tau_a, ws = 10.0, 4.0, MSL_GEAR.stick_speed
    out = [n * (tau_a - mesh_loss(tau_a, w, MSL_GEAR)) for w in (-ws, -0.5 * ws, 0.0, 0.5 * ws, ws)]
    assert out[0] == pytest.approx(51.0, rel=1e-14) and out[-1] == pytest.approx(33.0, rel=1e-14)
    assert out[2] == pytest.approx(42.0, rel=1e-14)
    assert out[1] == pytest.approx(46.5, rel=1e-14) and out[3] == pytest.approx(37.5, rel=1e-14)


def test_backlash_dead_zone_elastic_flanks_and_damping_that_never_pulls():
    b, c, d = 0.002, 1e6, 1e4
    assert elasto_backlash_torque(0.0009, 5.0, b, c, d) == 0.0          # inside ±b/2 = ±1e-3
    assert elasto_backlash_torque(-0.001, -5.0, b, c, d) == 0.0         # on the edge
    assert elasto_backlash_torque(0.0015, 0.0, b, c, d) == pytest.approx(500.0)   # 1e6·5e-4
    assert elasto_backlash_torque(-0.0015, 0.0, b, c, d) == pytest.approx(-500.0)
    assert elasto_backlash_torque(0.0011, 0.001, b, c, d) == pytest.approx(110.0)  # 100 + 10
    assert elasto_backlash_torque(0.0011, -1.0, b, c, d) == 0.0          # 100 − 1e4: no pull
    # the play: the flank follows the sign of the transmitted torque, holds at zero torque
    side = 0.0
    seen = []
    for torque in (0.0, 3.0, 0.0, -2.0, -1.0, 0.0, 4.0):
        side = play(side, torque, b)
        seen.append(side)
    assert seen == [0.0, -0.001, -0.001, 0.001, 0.001, 0.001, -0.001]


def test_rigid_gear_block_holds_the_load_through_the_back_driven_mesh():
    # the MSL example at rest after start: 10 kN pulls the rod out (load_force = −1e4 N),
    # c = 1/300 m/rad: the mesh must give the screw τ_out = c F = −33.33 N·m (holds it back);
    # screw turning forward slowly (ω_a = N ω_s = 1 rad/s > stick speed): the load drives, so
    # τ_a = η_b (τ_out/N + τ_bf) = 0.8 (−3.3333 + 0.1) = −2.58667 N·m and the loss is
    # τ_a − τ_out/N = −2.58667 + 3.33333 = 0.74667 N·m; the lumped screw gets N (T_m − loss)
    c = 1.0 / 300.0
    g = RigidGear(MSL_GEAR, input_inertia=0.58, output_inertia=0.0, lead_per_radian=c,
                  initial_side=1, initial_deflection=0.0)
    g.set_inputs([1.0, 0.0, 0.1, 0.0, -1e4])
    g.update_outputs(0.0)
    out = dict(zip(g.output_names(), g.get_outputs()))
    tau_t = -1e4 / 300.0
    tau_a = 0.8 * (tau_t / 10.0 + 0.1)
    loss = tau_a - tau_t / 10.0
    assert out["output_torque"] == pytest.approx(tau_t, rel=1e-14)
    assert out["loss_torque"] == pytest.approx(loss, rel=1e-12)
    assert out["screw_torque"] == pytest.approx(10.0 * (1.0 - loss), rel=1e-12)
    assert out["phi_rel"] == pytest.approx(0.001)                 # on the +b/2 flank
    # the deflection relaxes to −τ_out/c_gear = 3.333e-5 rad with time constant d/c = 10 ms:
    # after 20 ms (held inputs) δ = 3.333e-5 (1 − e^(−2))
    for k in range(100):
        g.do_step(k * 2e-4, 2e-4)
    assert g.delta == pytest.approx(-tau_t / 1e6 * (1.0 - math.exp(-2.0)), rel=1e-12)


# ---- current-fed motor and its bus delay -----------------------------------------------------
def test_bus_delay_step_and_ramp_responses_are_the_first_order_closed_forms():
    p = CurrentFedMotorParams(torque_constant=2.0, rotor_inertia=0.1, bus_delay=1e-3)
    m = CurrentFedMotor(p)
    m.set_inputs([10.0, 0.0])                      # a 10 A step at t = 0, held
    for k in range(5):
        m.do_step(k * 3e-4, 3e-4)
    i, torque, _ = m.get_outputs()
    assert i == pytest.approx(10.0 * (1.0 - math.exp(-1.5)), rel=1e-13)     # t = 1.5 ms = 1.5 T
    assert torque == pytest.approx(2.0 * i, rel=1e-15)
    # a ramp i* = a t from rest: i = a (t − T (1 − e^(−t/T))), exact whatever the step
    m2 = CurrentFedMotor(p)
    a, h = 2000.0, 7e-4
    for k in range(3):
        m2.set_inputs([a * k * h, 0.0], [a, 0.0])
        m2.do_step(k * h, h)
    t = 3 * h
    assert m2.get_outputs()[0] == pytest.approx(a * (t - 1e-3 * (1 - math.exp(-t / 1e-3))), rel=1e-12)


def test_lag_and_integral_updates_are_exact_for_linear_inputs():
    # T y' = u − y, u = 1 + 2τ, y(0) = 0, T = 0.5, h = 0.3: y = u − 2T + (0 − 1 + 2T) e^(−h/T)
    assert lag_step(0.0, 1.0, 2.0, 0.3, 0.5) == pytest.approx(1.6 - 1.0 + 0.0 * math.exp(-0.6))
    pi = ContinuousPI(gain=3.0, time_constant=0.5)
    pi.advance(1.0, 2.0, 0.3)                       # x = (1·0.3 + 2·0.09/2)/0.5 = 0.78
    assert pi.x == pytest.approx(0.78, rel=1e-15) and pi.output(1.6) == pytest.approx(3 * 2.38)


def test_derivative_filter_on_a_ramp_lags_the_rate_by_its_time_constant():
    # u = a t from x(0) = u(0) = 0: y = a (1 − e^(−t/T)); T = 0.01 s, a = 50 rad/s
    f = DerivativeFilter(0.01)
    a, h = 50.0, 3e-3
    for k in range(10):
        f.advance(a * k * h, a, h)
    t = 10 * h
    assert f.output(a * t) == pytest.approx(a * (1.0 - math.exp(-t / 0.01)), rel=1e-12)


# ---- slew-rate limited reference --------------------------------------------------------------
def test_slew_limiter_ramps_at_its_rate_then_settles_exponentially():
    # MSL example: step 0 -> 50 at 0.5 s, Rising = 50/s, Td = 1e-3 s.  Ramp at 50/s until
    # u − y = R Td = 0.05, i.e. y = 49.95 at t1 = 0.5 + 49.95/50 = 1.499 s; then
    # y = 50 − 0.05 e^(−(t − t1)/Td).  MSL's published reference has slewRateLimiter.y(1.5 s)
    # = 49.981606 = 50 − 0.05/e.
    r = make_profile({"kind": "slew", "rising": 50.0, "time_constant": 1e-3,
                      "input": {"kind": "step", "initial": 0.0, "final": 50.0, "time": 0.5}})
    assert r(0.4) == 0.0
    assert r(1.0) == pytest.approx(25.0, rel=1e-12)
    assert r(1.499) == pytest.approx(49.95, rel=1e-12)
    assert r(1.5) == pytest.approx(50.0 - 0.05 * math.exp(-1.0), rel=1e-12)
    assert r(1.5) == pytest.approx(49.981606, abs=1e-6)
    assert r(1.51) == pytest.approx(50.0 - 0.05 * math.exp(-11.0), rel=1e-12)
    lim = SlewRateLimiter(rising=2.0, falling=-1.0, time_constant=0.1)
    # falling from 5 to 0 at −1/s: until y = 0 + 1·0.1 = 0.1 after 4.9 s; at 3 s y = 2
    assert lim.advance(5.0, 0.0, 3.0) == pytest.approx(2.0, rel=1e-14)
    assert lim.advance(5.0, 0.0, 5.0) == pytest.approx(0.1 * math.exp(-1.0), rel=1e-12)


# ---- noise and quantisation ---------------------------------------------------------------------
def test_quantiser_rounds_to_the_nearest_step_and_its_error_stays_within_half_a_step():
    assert quantise(0.123, 0.01) == pytest.approx(0.12) and quantise(-0.127, 0.01) == pytest.approx(-0.13)
    assert quantise(0.3, 0.0) == 0.3
    x = np.linspace(-3.0, 3.0, 10001)
    err = np.array([quantise(v, 2 * math.pi / 4096) for v in x]) - x
    assert np.max(np.abs(err)) <= 0.5 * 2 * math.pi / 4096 * (1 + 1e-12)


def test_noise_is_reproducible_whatever_the_query_order_and_has_its_distribution():
    a = SampledNoise("uniform", 0.005, seed=7, low=-0.01, high=0.01)
    b = SampledNoise("uniform", 0.005, seed=7, low=-0.01, high=0.01)
    times = np.arange(0.0, 50.0, 0.005) + 0.0025
    forward = np.array([a(t) for t in times])
    backward = np.array([b(t) for t in times[::-1]])[::-1]
    assert np.array_equal(forward, backward)                    # same seed: same signal
    other = np.array([SampledNoise("uniform", 0.005, seed=8, low=-0.01, high=0.01)(t) for t in times])
    assert not np.allclose(forward, other)
    assert a(0.0051) == a(0.0099) == a(0.0075)                  # held over its period
    n = forward.size                                            # 10000 samples
    # uniform on [−0.01, 0.01]: mean 0, variance 0.02²/12 = 3.333e-5; the sample mean's
    # standard error is sqrt(3.333e-5/n) = 5.8e-5: 4 of them; the variance to 5 %
    assert abs(forward.mean()) < 4 * math.sqrt(0.02 ** 2 / 12 / n)
    assert forward.var() == pytest.approx(0.02 ** 2 / 12, rel=0.05)
    assert forward.min() >= -0.01 and forward.max() <= 0.01
    g = SampledNoise("normal", 1e-3, seed=3, std=0.5)
    s = np.array([g((k + 0.5) * 1e-3) for k in range(20000)])
    assert s.std() == pytest.approx(0.5, rel=0.03) and abs(s.mean()) < 4 * 0.5 / math.sqrt(20000)
    sensor = Sensor(SampledNoise("uniform", 0.005, seed=7, low=-0.01, high=0.01), resolution=0.001)
    assert sensor(0.0075, 1.0) == pytest.approx(quantise(1.0 + forward[1], 0.001))


# ---- gap contact and end stops ------------------------------------------------------------------
def test_gap_contact_pushes_only_and_the_spring_damper_also_pulls():
    k, d = 1e8, 1e5
    assert gap_contact_force(-1e-4, 0.0, k, d) == pytest.approx(1e4)      # compressed 0.1 mm
    assert gap_contact_force(1e-5, -1.0, k, d) == 0.0                      # apart: nothing
    assert gap_contact_force(-1e-5, -0.005, k, d) == pytest.approx(1500.0)  # 1000 + 1e5·0.005
    assert gap_contact_force(-1e-5, 1.0, k, d) == 0.0                      # 1000 − 1e5: no pull
    assert gap_contact_force(2e-3, 0.0, k, d, gap=1e-3) == 0.0            # 1 mm gap not closed
    assert gap_contact_force(0.5e-3, 0.0, k, d, gap=1e-3) == pytest.approx(5e4)
    assert gap_contact_force(1e-4, 0.0, k, d, bilateral=True) == pytest.approx(-1e4)
    # end stops at ±0.1 m, k_s = 1e7 N/m
    assert end_stop_force(0.0, 1.0, -0.1, 0.1, 1e7, 1e4) == 0.0
    assert end_stop_force(0.1001, 0.0, -0.1, 0.1, 1e7, 1e4) == pytest.approx(1e3)
    assert end_stop_force(-0.1001, 0.0, -0.1, 0.1, 1e7, 1e4) == pytest.approx(-1e3)
    assert end_stop_force(0.1001, -1.0, -0.1, 0.1, 1e7, 1e4) == 0.0        # leaving: no pull


def test_load_behind_the_contact_oscillates_at_sqrt_k_over_m():
    # rod held at 0, bilateral spring k = 1e6 N/m, no damping, m = 100 kg: x_L = x0 cos(ω t),
    # ω = sqrt(1e6/100) = 100 rad/s; after 0.05 s (5 rad) x_L = 1e-3 cos 5
    p = ContactParams(mass=100.0, stiffness=1e6, damping=0.0, bilateral=True, max_substep=2e-5)
    load = GapContactLoad(p, lambda t: 0.0, load_position=1e-3)
    load.set_inputs([0.0, 0.0], [0.0, 0.0])
    for k in range(50):
        load.do_step(k * 1e-3, 1e-3)
    xl, vl = load.x
    assert xl == pytest.approx(1e-3 * math.cos(5.0), abs=1e-12)
    assert vl == pytest.approx(-0.1 * math.sin(5.0), abs=1e-10)
    load.update_outputs(0.05)
    out = dict(zip(load.output_names(), load.get_outputs()))
    assert out["force"] == pytest.approx(-1e6 * xl, rel=1e-12)            # the spring pulls the rod
